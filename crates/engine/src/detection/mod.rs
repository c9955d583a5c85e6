//! Contact detection at the beginning of a step: world geometry of every body, broad phase on a
//! uniform grid, narrow phase per candidate pair (in parallel, in a deterministic order).

pub mod broad;
pub mod narrow;

pub use broad::{Aabb, BroadPhase};
pub use narrow::{FaceHint, Manifold, ManifoldPoint, WorldPolyhedron};

use crate::bodies::{BodyKind, BodySet};
use crate::math::DVec3;
use crate::shapes::Shape;
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
    /// Face hints of the previous step's polyhedron pairs, sorted by pair (temporal coherence;
    /// they speed the narrow phase up and never change its results).
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
        // Per-body transforms, in parallel over disjoint chunks of the flat arrays.
        let mut vchunks: Vec<&mut [DVec3]> = Vec::with_capacity(bodies.len());
        let mut rest = c.vertices.as_mut_slice();
        for i in 0..bodies.len() {
            let (a, b) = rest.split_at_mut(c.vertex_start[i + 1] - c.vertex_start[i]);
            vchunks.push(a);
            rest = b;
        }
        let mut nchunks: Vec<(&mut [DVec3], &mut [f64])> = Vec::with_capacity(bodies.len());
        let (mut rn, mut ro) = (c.normals.as_mut_slice(), c.offsets.as_mut_slice());
        for i in 0..bodies.len() {
            let k = c.face_start[i + 1] - c.face_start[i];
            let (a, b) = rn.split_at_mut(k);
            let (x, y) = ro.split_at_mut(k);
            nchunks.push((a, x));
            rn = b;
            ro = y;
        }
        vchunks
            .into_par_iter()
            .zip(nchunks.into_par_iter())
            .enumerate()
            .with_min_len(64)
            .for_each(|(i, (v, (n, o)))| {
                if let Shape::Polyhedron(p) = &bodies.shape[i] {
                    let (x, q) = (bodies.position[i], bodies.orientation[i]);
                    for (w, b) in v.iter_mut().zip(&p.vertices) {
                        *w = x + q * *b;
                    }
                    for f in 0..p.face_normals.len() {
                        n[f] = q * p.face_normals[f];
                        o[f] = p.face_offsets[f] + n[f].dot(x);
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
        self.margins.clear();
        self.margins
            .extend((0..n).map(|i| match (&bodies.shape[i], bodies.kind[i]) {
                (_, BodyKind::Fixed) | (Shape::Plane { .. }, _) => 0.0,
                (Shape::Polyhedron(p), _) => {
                    dt * (bodies.velocity[i].length()
                        + bodies.angular_velocity[i].length() * p.radius)
                }
            }));
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
        pairs.sort_unstable();
        // Last step's hint of each pair, by a merge of the two sorted lists.
        let mut previous = self.hints.iter().peekable();
        let mut hints = std::mem::take(&mut self.pair_hints);
        hints.clear();
        hints.extend(pairs.iter().map(|pair| {
            while previous.next_if(|(p, _)| p < pair).is_some() {}
            previous
                .next_if(|(p, _)| p == pair)
                .map_or(FaceHint::NONE, |&(_, h)| h)
        }));
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
        self.hints.clear();
        self.hints.extend(
            pairs
                .iter()
                .zip(&results)
                .filter(|(_, r)| r.3 != FaceHint::NONE)
                .map(|(&p, r)| (p, r.3)),
        );
        for (b1, b2, m, _) in &results {
            let (b1, b2) = (*b1, *b2);
            if let Some(m) = m {
                for p in &m.points {
                    out.push(RawContact {
                        body1: b1,
                        body2: b2,
                        point: p.point,
                        normal: m.normal,
                        gap: p.gap,
                    });
                }
            }
        }
        self.pairs = pairs;
        self.pair_hints = hints;
        self.results = results;
    }
}

/// World normal and offset (`n·x = offset` on the boundary) of half-space body `i`.
fn plane_world(bodies: &BodySet, i: usize) -> (DVec3, f64) {
    let Shape::Plane { normal } = &bodies.shape[i] else {
        unreachable!("plane_world called on a polyhedron")
    };
    let n = bodies.orientation[i] * *normal;
    (n, n.dot(bodies.position[i]))
}
