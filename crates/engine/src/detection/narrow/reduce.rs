//! Manifold reduction: merge coincident points, then keep at most four.
//!
//! The four kept points follow the Bullet/Rapier heuristic, weighted by how far each point is
//! into the contact (as Jolt weights its pruning by penetration): the deepest point (it carries
//! the penetration), then the point maximising its squared distance from it, the triangle area,
//! and the area added outside that triangle, each times the point's weight `reach − gap`
//! (`reach` the largest gap a point may have, the alert distance). Unweighted, a point just
//! inside the alert distance could displace a deep one beside it: a grain's steep corner then
//! loses its deepest point for a step, the contact gives way and the grain is driven in by a
//! millimetre. Distances and areas are measured in the plane orthogonal to the normal, and
//! ties go to the lowest index, so the result depends only on the input order.

use super::ManifoldPoint;
use crate::math::DVec3;

/// Points closer than this fraction of the manifold's extent are merged. Clipping produces
/// such near-twins when an incident vertex lies on a side plane; keeping both would only make
/// the contact Delassus block singular.
const MERGE_RELATIVE: f64 = 1e-6;
/// Floor of the merge distance relative to the coordinates' magnitude (a few ulps), so that
/// points differing only by round-off are merged even in a tiny manifold.
const MERGE_ULPS: f64 = 1e-13;
/// Twice the triangle area below which the points count as collinear, relative to the squared
/// length of the first chord.
const COLLINEAR: f64 = 1e-12;

/// Reduces `points` in place to at most four pairwise distinct points.
///
/// Points closer than a tiny tolerance (`1e-6` of the manifold's extent, at least a few ulps of
/// the coordinates) are merged, keeping the deepest (smallest gap). If more than four remain, the
/// deepest is kept, then the point maximising its weight `reach − gap` times, in turn, its
/// squared distance from the deepest, the area of the triangle it makes with the first two, and
/// the area it adds outside that triangle. `reach` is the largest gap a point may have (the
/// alert distance): a point at it weighs nothing beside a touching one. Distances and areas are
/// measured in the plane orthogonal to `normal` (a unit vector). Deterministic: ties go to the
/// lowest index.
pub fn reduce_to_four(points: &mut Vec<ManifoldPoint>, normal: DVec3, reach: f64) {
    merge_duplicates(points);
    if points.len() <= 4 {
        return;
    }

    let tangential = |d: DVec3| d - normal * normal.dot(d);
    // A floor keeps every weight positive, so that a point distinct from the first always
    // beats it, even when every other point lies at `reach`.
    let floor = 1e-9 * reach.abs() + f64::MIN_POSITIVE;
    let weight = |p: &ManifoldPoint| (reach - p.gap).max(0.0) + floor;

    // 1. Deepest point.
    let (i0, _) = argmax(points, |p| -p.gap);
    let p0 = points[i0].point;
    // 2. Farthest from it.
    let (i1, _) = argmax(points, |p| {
        tangential(p.point - p0).length_squared() * weight(p)
    });
    let p1 = points[i1].point;
    // 3. Largest triangle (p0, p1, p).
    let e01 = p1 - p0;
    let area = |p: &ManifoldPoint| e01.cross(p.point - p0).dot(normal).abs();
    let (i2, _) = argmax(points, |p| area(p) * weight(p));
    if area(&points[i2]) <= COLLINEAR * e01.length_squared() {
        // All points on the line through p0 and p1: keep the deepest and both extremes.
        let (i2, _) = argmax(points, |p| tangential(p.point - p1).length_squared());
        keep(points, &[i0, i1, i2]);
        return;
    }
    let p2 = points[i2].point;
    // 4. Farthest outside the triangle: the largest area added beyond one of its edges.
    let orient = e01.cross(p2 - p0).dot(normal).signum();
    let tri = [p0, p1, p2];
    let (i3, _) = argmax(points, |p| {
        let mut best = f64::NEG_INFINITY;
        for k in 0..3 {
            let a = tri[k];
            let b = tri[(k + 1) % 3];
            // Positive when `p` lies outside edge (a, b) of the triangle.
            best = best.max(-orient * (b - a).cross(p.point - a).dot(normal));
        }
        best * weight(p)
    });
    keep(points, &[i0, i1, i2, i3]);
}

/// Replaces `points` by the points at `idx`, in that order, skipping repeated indices.
fn keep(points: &mut Vec<ManifoldPoint>, idx: &[usize]) {
    let mut kept = [ManifoldPoint {
        point: DVec3::ZERO,
        gap: 0.0,
    }; 4];
    let mut n = 0;
    for (k, &i) in idx.iter().enumerate() {
        if !idx[..k].contains(&i) {
            kept[n] = points[i];
            n += 1;
        }
    }
    points.clear();
    points.extend_from_slice(&kept[..n]);
}

/// Index and value of the first maximum of `key` (NaN keys never win).
fn argmax(points: &[ManifoldPoint], key: impl Fn(&ManifoldPoint) -> f64) -> (usize, f64) {
    let mut best = 0;
    let mut best_key = f64::NEG_INFINITY;
    for (i, p) in points.iter().enumerate() {
        let k = key(p);
        if k > best_key {
            best_key = k;
            best = i;
        }
    }
    (best, best_key)
}

/// Merges points closer than the merge tolerance, keeping the deepest of each cluster, in the
/// order of first appearance.
fn merge_duplicates(points: &mut Vec<ManifoldPoint>) {
    if points.len() < 2 {
        return;
    }
    let mut lo = points[0].point;
    let mut hi = lo;
    for p in points.iter() {
        lo = lo.min(p.point);
        hi = hi.max(p.point);
    }
    let extent = (hi - lo).length();
    let magnitude = lo.abs().max(hi.abs()).max_element();
    let tol = (MERGE_RELATIVE * extent).max(MERGE_ULPS * magnitude);
    let tol2 = tol * tol;

    let mut n = 0;
    for i in 0..points.len() {
        let p = points[i];
        match points[..n]
            .iter()
            .position(|q| (q.point - p.point).length_squared() <= tol2)
        {
            Some(j) => {
                if p.gap < points[j].gap {
                    points[j] = p;
                }
            }
            None => {
                points[n] = p;
                n += 1;
            }
        }
    }
    points.truncate(n);
}
