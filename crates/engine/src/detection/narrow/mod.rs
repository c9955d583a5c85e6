//! Narrow phase: contact manifolds between convex polyhedra and half-spaces.
//!
//! A manifold holds at most 4 points on a common plane with a common unit normal pointing from
//! body 1 to body 2. Each point carries its gap (signed distance between the surfaces along the
//! normal, negative when they overlap); only points whose gap is within the alert distance are
//! kept, and no two points coincide.

mod plane;
mod polyhedra;
mod reduce;

pub use plane::plane_polyhedron;
pub use polyhedra::{polyhedron_polyhedron, polyhedron_polyhedron_hinted, FaceHint};
pub use reduce::reduce_to_four;

use crate::math::DVec3;
use crate::shapes::ConvexPolyhedron;

/// A polyhedron placed in the world: its topology plus world-frame vertices and face planes,
/// computed once per step per body.
#[derive(Clone, Copy, Debug)]
pub struct WorldPolyhedron<'a> {
    /// Topology (faces, edges) and body-frame data.
    pub shape: &'a ConvexPolyhedron,
    /// World position of the centre of mass.
    pub center: DVec3,
    /// World vertices, same indexing as `shape.vertices`.
    pub vertices: &'a [DVec3],
    /// World outward unit face normals.
    pub face_normals: &'a [DVec3],
    /// World face offsets: `face_normals[f] · x = face_offsets[f]` on face `f`.
    pub face_offsets: &'a [f64],
}

/// One contact point of a manifold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ManifoldPoint {
    /// World position, midway between the two surfaces.
    pub point: DVec3,
    /// Signed distance between the surfaces along the normal (negative = overlap).
    pub gap: f64,
}

/// A contact manifold: common normal (from body 1 to body 2) and up to 4 points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Manifold {
    /// Unit normal from body 1 toward body 2.
    pub normal: DVec3,
    /// Points, at most 4, pairwise distinct.
    pub points: Vec<ManifoldPoint>,
}
