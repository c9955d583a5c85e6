//! Shapes: closed convex polyhedra (grains, blocks, boxes) and half-spaces (walls, floors).

pub mod mass;
pub mod polyhedron;
pub mod random;

pub use mass::MassProperties;
pub use polyhedron::{ConvexPolyhedron, PolyhedronBuild, ShapeError};

use crate::math::DVec3;
use std::sync::Arc;

/// The geometric shape of a body, in the body frame.
#[derive(Clone, Debug)]
pub enum Shape {
    /// A closed convex polyhedron whose body frame is its centre of mass and principal axes.
    Polyhedron(Arc<ConvexPolyhedron>),
    /// The half-space `{x : n·x ≤ 0}` in the body frame (`n` is the outward unit normal, the
    /// solid lies below the plane through the body origin).
    Plane { normal: DVec3 },
}
