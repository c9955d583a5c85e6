//! Half-space against convex polyhedron.
//!
//! Every vertex of the polyhedron whose signed distance to the plane is within the alert distance
//! is a candidate point; the candidates are reduced to four. Vertices are the only possible
//! deepest points of a polyhedron against a plane, so this is exact.

use super::{reduce_to_four, Manifold, ManifoldPoint, WorldPolyhedron};
use crate::math::DVec3;

/// Contact manifold between the half-space `{x : n·x ≤ offset}` (body 1) and polyhedron `b`
/// (body 2), or `None` when every vertex of `b` is farther than `alert` from the plane.
///
/// `plane_normal` must be a unit vector; it is the manifold normal (from the half-space toward
/// the polyhedron). Each vertex `v` with gap `g = n·v − offset ≤ alert` gives the point
/// `v − g/2·n`, midway between the vertex and the plane; the points are then reduced with
/// [`reduce_to_four`].
pub fn plane_polyhedron(
    plane_normal: DVec3,
    plane_point_offset: f64,
    b: &WorldPolyhedron,
    alert: f64,
) -> Option<Manifold> {
    let n = plane_normal;
    // Count first so that the result vector is allocated once, at its final capacity.
    let count = b
        .vertices
        .iter()
        .filter(|v| n.dot(**v) - plane_point_offset <= alert)
        .count();
    if count == 0 {
        return None;
    }
    let mut points = Vec::with_capacity(count);
    for &v in b.vertices {
        let gap = n.dot(v) - plane_point_offset;
        if gap <= alert {
            points.push(ManifoldPoint {
                point: v - 0.5 * gap * n,
                gap,
            });
        }
    }
    reduce_to_four(&mut points, n, alert);
    Some(Manifold { normal: n, points })
}
