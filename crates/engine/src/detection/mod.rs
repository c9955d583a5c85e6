//! Contact detection at the beginning of a step: world geometry of every body, broad phase on a
//! uniform grid, narrow phase per candidate pair (in parallel, in a deterministic order).

pub mod broad;
pub mod narrow;

pub use broad::{Aabb, BroadPhase};
pub use narrow::{FaceHint, Manifold, ManifoldPoint, WorldPolyhedron};

use crate::bodies::{BodyKind, BodySet};
use crate::math::DVec3;
use crate::shapes::Shape;
use crate::slices::split_lengths;
use rayon::prelude::*;

/// One detected contact point, before the contact frame and the law are attached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawContact {
    pub body1: u32,
    pub body2: u32,
    /// World position.
    pub point: DVec3,
    /// Unit normal from body 1 toward body 2.
    pub normal: DVec3,
    /// Signed gap (negative = overlap).
    pub gap: f64,
}

/// World-frame geometry of all polyhedra, refreshed each step.
#[derive(Default, Debug)]
struct GeometryCache {
    vertices: Vec<DVec3>,
    vertex_start: Vec<usize>,
    normals: Vec<DVec3>,
    offsets: Vec<f64>,
    face_start: Vec<usize>,
}

/// Contact detection with reusable buffers.
#[derive(Default, Debug)]
pub struct Detector {
    broad: BroadPhase,
    cache: GeometryCache,
    aabbs: Vec<Aabb>,
    margins: Vec<f64>,
    pairs: Vec<(u32, u32)>,
    /// Scratch for merging the half-space pairs into the (sorted) broad-phase pairs.
    merged: Vec<(u32, u32)>,
    /// Face hints of the previous step's pairs (`FaceHint::NONE` where none), sorted by pair
    /// (temporal coherence; they speed the narrow phase up and never change its results).
    hints: Vec<((u32, u32), FaceHint)>,
    /// This step's hint per pair, and the narrow phase's results (buffers kept across steps:
    /// megabytes allocated afresh every step cost page faults).
    pair_hints: Vec<FaceHint>,
    results: Vec<NarrowResult>,
}

/// A pair's narrow-phase outcome: bodies (body 1 first), manifold, and the hint for next step.
type NarrowResult = (u32, u32, Option<Manifold>, FaceHint);

impl Detector {
    /// World view of polyhedron `i` (valid after [`Detector::detect`] refreshed the cache).
    fn world_poly<'a>(&'a self, bodies: &'a BodySet, i: usize) -> Option<WorldPolyhedron<'a>> {
        match &bodies.shape[i] {
            Shape::Polyhedron(p) => {
                let c = &self.cache;
                Some(WorldPolyhedron {
                    shape: p,
                    center: bodies.position[i],
                    vertices: &c.vertices[c.vertex_start[i]..c.vertex_start[i + 1]],
                    face_normals: &c.normals[c.face_start[i]..c.face_start[i + 1]],
                    face_offsets: &c.offsets[c.face_start[i]..c.face_start[i + 1]],
                })
            }
            Shape::Plane { .. } => None,
        }
    }

    fn refresh_geometry(&mut self, bodies: &BodySet) {
        let c = &mut self.cache;
        c.vertex_start.clear();
        c.face_start.clear();
        let (mut nv, mut nf) = (0, 0);
        for s in &bodies.shape {
            c.vertex_start.push(nv);
            c.face_start.push(nf);
            if let Shape::Polyhedron(p) = s {
                nv += p.vertices.len();
                nf += p.face_normals.len();
            }
        }
        c.vertex_start.push(nv);
        c.face_start.push(nf);
        c.vertices.resize(nv, DVec3::ZERO);
        c.normals.resize(nf, DVec3::ZERO);
        c.offsets.resize(nf, 0.0);
        // Per-body transforms, in parallel over runs of bodies (disjoint, contiguous pieces of
        // the flat arrays; a few hundred pieces, so that cutting them costs nothing).
        const RUN: usize = 64;
        let n = bodies.len();
        let run = |k: usize| k * RUN..((k + 1) * RUN).min(n);
        let (vertex_start, face_start) = (&c.vertex_start, &c.face_start);
        // Lengths of the runs' pieces of an array indexed by `start` (per-body offsets).
        fn cut(start: &[usize], n: usize) -> impl Iterator<Item = usize> + '_ {
            (0..n.div_ceil(RUN)).map(move |k| start[((k + 1) * RUN).min(n)] - start[k * RUN])
        }
        let (v_pieces, _) = split_lengths(&mut c.vertices, cut(vertex_start, n));
        let (n_pieces, _) = split_lengths(&mut c.normals, cut(face_start, n));
        let (o_pieces, _) = split_lengths(&mut c.offsets, cut(face_start, n));
        let pieces: Vec<_> = v_pieces.into_iter().zip(n_pieces).zip(o_pieces).collect();
        pieces
            .into_par_iter()
            .enumerate()
            .for_each(|(k, ((v, n), o))| {
                let range = run(k);
                let (v0, f0) = (vertex_start[range.start], face_start[range.start]);
                for i in range {
                    if let Shape::Polyhedron(p) = &bodies.shape[i] {
                        let (x, q) = (bodies.position[i], bodies.orientation[i]);
                        let v = &mut v[vertex_start[i] - v0..vertex_start[i + 1] - v0];
                        for (w, b) in v.iter_mut().zip(&p.vertices) {
                            *w = x + q * *b;
                        }
                        let f = face_start[i] - f0;
                        for j in 0..p.face_normals.len() {
                            n[f + j] = q * p.face_normals[j];
                            o[f + j] = p.face_offsets[j] + n[f + j].dot(x);
                        }
                    }
                }
            });
    }

    /// Detects all contact points within the alert distance of touching, appended to `out`
    /// (cleared first) sorted by pair `(body1, body2)`. Pairs of two non-dynamic bodies are
    /// skipped.
    ///
    /// Speculative margin: a body whose points can move by `m = dt (|v| + |ω| ρ)` (ρ its radius)
    /// within the step has its box inflated by `m`, and a pair's alert distance becomes
    /// `alert + m₁ + m₂`. So no approaching pair is missed however fast it moves (a grain
    /// spinning at 100 rad/s sweeps several alert distances per step); the extra contacts have
    /// positive gaps and carry no impulse unless they would close within the step.
    pub fn detect(&mut self, bodies: &BodySet, alert: f64, dt: f64, out: &mut Vec<RawContact>) {
        out.clear();
        self.refresh_geometry(bodies);
        let n = bodies.len();
        (0..n)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| match (&bodies.shape[i], bodies.kind[i]) {
                (_, BodyKind::Fixed) | (Shape::Plane { .. }, _) => 0.0,
                (Shape::Polyhedron(p), _) => {
                    dt * (bodies.velocity[i].length()
                        + bodies.angular_velocity[i].length() * p.radius)
                }
            })
            .collect_into_vec(&mut self.margins);
        let (cache, margins) = (&self.cache, &self.margins);
        (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| match &bodies.shape[i] {
                Shape::Polyhedron(_) => {
                    let v = &cache.vertices[cache.vertex_start[i]..cache.vertex_start[i + 1]];
                    let (lo, hi) = v.iter().fold(
                        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
                    );
                    let half = DVec3::splat(0.5 * alert + margins[i]);
                    Aabb {
                        min: lo - half,
                        max: hi + half,
                    }
                }
                Shape::Plane { .. } => Aabb {
                    min: DVec3::ZERO,
                    max: DVec3::ZERO,
                },
            })
            .collect_into_vec(&mut self.aabbs);
        let is_plane = |i: usize| matches!(bodies.shape[i], Shape::Plane { .. });
        let polys: Vec<u32> = (0..n as u32).filter(|&i| !is_plane(i as usize)).collect();
        let planes: Vec<u32> = (0..n as u32).filter(|&i| is_plane(i as usize)).collect();
        let dynamic = |i: u32| bodies.kind[i as usize] == BodyKind::Dynamic;
        let mut pairs = std::mem::take(&mut self.pairs);
        self.broad.find_pairs(
            &self.aabbs,
            &polys,
            |i, j| !dynamic(i) && !dynamic(j),
            &mut pairs,
        );
        // Half-spaces against every dynamic polyhedron whose box reaches within `alert`.
        let from_broad = pairs.len();
        for &p in &planes {
            let (nrm, off) = plane_world(bodies, p as usize);
            for &i in &polys {
                if !dynamic(i) {
                    continue;
                }
                let b = &self.aabbs[i as usize];
                // Lowest corner of the box along the normal.
                let lowest = DVec3::select(nrm.cmpge(DVec3::ZERO), b.min, b.max);
                if nrm.dot(lowest) - off <= 0.5 * alert {
                    pairs.push((p.min(i), p.max(i)));
                }
            }
        }
        // The broad phase's pairs come sorted: sort the half-space pairs alone, then merge.
        pairs[from_broad..].sort_unstable();
        if from_broad > 0 && from_broad < pairs.len() && pairs[from_broad] < pairs[from_broad - 1] {
            merge_sorted(&pairs[..from_broad], &pairs[from_broad..], &mut self.merged);
            std::mem::swap(&mut pairs, &mut self.merged);
        }
        // Last step's hint of each pair (a binary search per pair: parallel, no serial merge).
        let previous = &self.hints;
        let mut hints = std::mem::take(&mut self.pair_hints);
        pairs
            .par_iter()
            .with_min_len(1024)
            .map(|pair| {
                previous
                    .binary_search_by_key(pair, |&(p, _)| p)
                    .map_or(FaceHint::NONE, |k| previous[k].1)
            })
            .collect_into_vec(&mut hints);
        let mut results = std::mem::take(&mut self.results);
        let this = &*self;
        let margins = &self.margins;
        pairs
            .par_iter()
            .zip(hints.par_iter())
            .with_min_len(32)
            .map(|(&(i, j), &hint)| {
                let (iu, ju) = (i as usize, j as usize);
                let alert = alert + margins[iu] + margins[ju];
                match (this.world_poly(bodies, iu), this.world_poly(bodies, ju)) {
                    (Some(a), Some(b)) => {
                        let (m, hint) = narrow::polyhedron_polyhedron_hinted(&a, &b, alert, hint);
                        (i, j, m, hint)
                    }
                    (None, Some(b)) => {
                        let (nrm, off) = plane_world(bodies, iu);
                        (
                            i,
                            j,
                            narrow::plane_polyhedron(nrm, off, &b, alert),
                            FaceHint::NONE,
                        )
                    }
                    (Some(a), None) => {
                        let (nrm, off) = plane_world(bodies, ju);
                        (
                            j,
                            i,
                            narrow::plane_polyhedron(nrm, off, &a, alert),
                            FaceHint::NONE,
                        )
                    }
                    (None, None) => (i, j, None, FaceHint::NONE),
                }
            })
            .collect_into_vec(&mut results);
        pairs
            .par_iter()
            .zip(results.par_iter())
            .with_min_len(1024)
            .map(|(&p, r)| (p, r.3))
            .collect_into_vec(&mut self.hints);
        write_points(&results, out);
        self.pairs = pairs;
        self.pair_hints = hints;
        self.results = results;
    }
}

/// Merges two sorted lists into `out` (cleared first).
fn merge_sorted<T: Copy + Ord>(a: &[T], b: &[T], out: &mut Vec<T>) {
    out.clear();
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if b[j] < a[i] {
            out.push(b[j]);
            j += 1;
        } else {
            out.push(a[i]);
            i += 1;
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
}

/// The manifolds' points, in pair order, written into `out` in parallel: each chunk of
/// results knows where its points start from the counts of the chunks before it.
fn write_points(results: &[NarrowResult], out: &mut Vec<RawContact>) {
    const CHUNK: usize = 1024;
    let count = |r: &NarrowResult| r.2.as_ref().map_or(0, |m| m.points.len());
    let counts: Vec<usize> = results
        .par_chunks(CHUNK)
        .map(|c| c.iter().map(count).sum())
        .collect();
    let blank = RawContact {
        body1: 0,
        body2: 0,
        point: DVec3::ZERO,
        normal: DVec3::ZERO,
        gap: 0.0,
    };
    out.resize(counts.iter().sum(), blank);
    let (slices, _) = split_lengths(out, counts.iter().copied());
    slices
        .into_par_iter()
        .zip(results.par_chunks(CHUNK))
        .for_each(|(dst, chunk)| {
            let points = chunk.iter().filter_map(|(b1, b2, m, _)| {
                m.as_ref().map(|m| {
                    m.points.iter().map(move |p| RawContact {
                        body1: *b1,
                        body2: *b2,
                        point: p.point,
                        normal: m.normal,
                        gap: p.gap,
                    })
                })
            });
            for (d, p) in dst.iter_mut().zip(points.flatten()) {
                *d = p;
            }
        });
}

/// World normal and offset (`n·x = offset` on the boundary) of half-space body `i`.
fn plane_world(bodies: &BodySet, i: usize) -> (DVec3, f64) {
    let Shape::Plane { normal } = &bodies.shape[i] else {
        unreachable!("plane_world called on a polyhedron")
    };
    let n = bodies.orientation[i] * *normal;
    (n, n.dot(bodies.position[i]))
}

#[cfg(test)]
mod tests {
    use super::merge_sorted;
    use proptest::prelude::*;

    proptest! {
        /// Merging two sorted lists gives the sorted concatenation.
        #[test]
        fn merge_is_the_sorted_concatenation(
            mut a in proptest::collection::vec((0u32..50, 0u32..50), 0..40),
            mut b in proptest::collection::vec((0u32..50, 0u32..50), 0..40),
        ) {
            a.sort_unstable();
            b.sort_unstable();
            let mut out = vec![(7, 7)];
            merge_sorted(&a, &b, &mut out);
            let mut expected = [a, b].concat();
            expected.sort_unstable();
            prop_assert_eq!(out, expected);
        }
    }
}
