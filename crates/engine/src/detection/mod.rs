//! Contact detection at the beginning of a step: world geometry of every body, broad phase on a
//! uniform grid, narrow phase per candidate pair (in parallel, in a deterministic order), with
//! the manifolds of pairs whose bodies have barely moved reused from the previous step (see
//! [`coherence`]).

mod broad;
pub mod coherence;
pub(crate) mod ghosts;
mod outcomes;
mod ranks;
// Narrow-phase routines, exposed for the crate's tests and benches; not part of the supported
// API.
#[doc(hidden)]
pub mod narrow;

pub(crate) use broad::{Aabb, BroadPhase};
pub(crate) use coherence::Anchors;
pub use narrow::{FaceHint, Manifold, ManifoldPoint, WorldPolyhedron};
use outcomes::Outcomes;

use crate::bodies::{BodyKind, BodySet};
use crate::math::{DQuat, DVec3};
use crate::shapes::{ConvexPolyhedron, Shape};
use crate::slices::{reserve_total, split_lengths};
use crate::solver::exchange::PairOwners;
use crate::solver::Exchange;
use rayon::prelude::*;
use std::sync::Arc;

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

/// World-frame geometry of the polyhedra, refreshed each step: of every one, or on a rank that
/// holds its pairs of those its pairs may join (see [`ranks::bodies_needed`]).
#[derive(Default, Debug)]
struct GeometryCache {
    vertices: Vec<DVec3>,
    /// Body `i`'s vertices are `vertices[vertex_start[i]..vertex_start[i + 1]]` (none when
    /// it is not placed); the same for its faces.
    vertex_start: Vec<usize>,
    normals: Vec<DVec3>,
    offsets: Vec<f64>,
    face_start: Vec<usize>,
    /// Each body's vertex and face counts.
    sizes: Vec<[usize; 2]>,
    /// The bodies whose geometry the arrays hold.
    placed: Vec<bool>,
    /// The shapes the layout was computed for (held, so that none of them is freed and its
    /// address reused while compared), and each body's circumradius (∞ for a half-space).
    shapes: Vec<Option<Arc<ConvexPolyhedron>>>,
    radii: Vec<f64>,
}

/// Contact detection with reusable buffers.
#[derive(Default, Debug)]
pub struct Detector {
    broad: BroadPhase,
    cache: GeometryCache,
    aabbs: Vec<Aabb>,
    margins: Vec<f64>,
    /// Anchor poses: the world geometry is computed there (temporal coherence).
    anchors: Anchors,
    /// The world geometry of bodies that were not re-anchored is not at their anchors (anchors
    /// restored from a checkpoint): the next detection recomputes it for every body.
    geometry_stale: bool,
    /// Bit patterns of the `(alert, reuse)` the cached manifolds were computed with: other
    /// values invalidate them.
    cached_for: Option<(u64, u64)>,
    /// This step's candidate pairs, sorted, and their outcomes: at the next step, the cache.
    pairs: Vec<(u32, u32)>,
    results: Outcomes,
    /// Scratch for the next step's pairs and outcomes (buffers kept across steps: megabytes
    /// allocated afresh every step cost page faults), and for merging the half-space pairs.
    spare_pairs: Vec<(u32, u32)>,
    spare_results: Outcomes,
    merged: Vec<(u32, u32)>,
    /// The body kinds of the last detection (the broad phase's skip rule depends on them).
    kinds: Vec<BodyKind>,
    /// The ranks that share the narrow phase in a distributed run (see [`ranks`]).
    pub(crate) exchange: Option<Arc<dyn Exchange>>,
    /// Seconds the last detection spent sharing between ranks.
    pub(crate) shared_seconds: f64,
    /// The rank that tests each pair in a domain-decomposed distributed run (set before its
    /// first detection, then by each solve).
    pub(crate) owners: Option<PairOwners>,
    /// The bodies up to date on this rank this step when the ranks share the bodies (its
    /// own, the ghosts it was sent, the bodies that are not dynamic; see [`ghosts`]); empty:
    /// every body.
    pub(crate) fresh: Vec<bool>,
    /// Each subdomain's extent as its owner bounds it this step (see [`ghosts`]); empty:
    /// found from every body's bound.
    pub(crate) extents: Vec<Aabb>,
    /// Whether this rank of a distributed run holds its pairs: it tests and keeps the
    /// outcomes of its own pairs only, and writes only their points (see [`ranks`]); else
    /// every rank gets every outcome.
    pub(crate) hold: bool,
}

/// A pair's narrow-phase outcome at the anchor poses: bodies (body 1 first), manifold (`len`
/// points, none when apart), the face hint for the pair's next test, whether it was reused,
/// and whether it may be: only a manifold computed with both bodies' margins at the slow-body
/// value is a function of the anchors alone. A value passed around while a step's outcomes
/// are assembled; they are kept in [`Outcomes`].
#[derive(Clone, Copy, Debug)]
struct PairGeometry {
    body1: u32,
    body2: u32,
    normal: DVec3,
    points: [ManifoldPoint; 4],
    len: u8,
    hint: FaceHint,
    reused: bool,
    reusable: bool,
}

impl PairGeometry {
    fn new(body1: u32, body2: u32, manifold: Option<Manifold>, hint: FaceHint) -> Self {
        let blank = ManifoldPoint {
            point: DVec3::ZERO,
            gap: 0.0,
        };
        let mut g = PairGeometry {
            body1,
            body2,
            normal: DVec3::ZERO,
            points: [blank; 4],
            len: 0,
            hint,
            reused: false,
            reusable: false,
        };
        if let Some(m) = manifold {
            g.normal = m.normal;
            // The narrow phase reduces every manifold to at most four points.
            for (slot, p) in g.points.iter_mut().zip(&m.points) {
                *slot = *p;
                g.len += 1;
            }
        }
        g
    }

    fn points(&self) -> &[ManifoldPoint] {
        &self.points[..self.len as usize]
    }
}

/// How far beyond its margin a body's pairs are looked for: the reuse distance's slack.
fn reach_of(reuse: f64) -> impl Fn(f64) -> f64 + Sync + Copy {
    move |m: f64| if reuse > 0.0 { reuse + m.max(reuse) } else { m }
}

/// Half-side of a body's bound (circumradius `radius`, growth `0.5 alert + reach`), widened
/// by a hair for rounding.
fn bound_half(radius: f64, alert: f64, reach: f64) -> f64 {
    (radius + 0.5 * alert + reach) * (1.0 + 1e-9) + 1e-9
}

impl Detector {
    /// World view of polyhedron `i` at its anchor pose (valid after [`Detector::detect`]
    /// refreshed the cache).
    fn world_poly<'a>(&'a self, bodies: &'a BodySet, i: usize) -> Option<WorldPolyhedron<'a>> {
        match &bodies.shape[i] {
            Shape::Polyhedron(p) => {
                let c = &self.cache;
                Some(WorldPolyhedron {
                    shape: p,
                    center: self.anchors.position[i],
                    vertices: &c.vertices[c.vertex_start[i]..c.vertex_start[i + 1]],
                    face_normals: &c.normals[c.face_start[i]..c.face_start[i + 1]],
                    face_offsets: &c.offsets[c.face_start[i]..c.face_start[i + 1]],
                })
            }
            Shape::Plane { .. } => None,
        }
    }

    /// The anchor poses (see [`coherence`]), stored in checkpoints.
    pub(crate) fn anchors(&self) -> &Anchors {
        &self.anchors
    }

    /// Restores anchor poses saved with [`Detector::anchors`] (a resumed run): the first
    /// detection then computes at these anchors what the interrupted run had cached.
    pub(crate) fn set_anchors(&mut self, position: Vec<DVec3>, orientation: Vec<DQuat>) {
        self.anchors = Anchors {
            position,
            orientation,
            ..Anchors::default()
        };
        self.pairs.clear();
        self.results.clear();
        self.geometry_stale = true;
    }

    /// Bodies whose world geometry the last detection placed.
    pub(crate) fn placed_bodies(&self) -> usize {
        self.cache.placed.iter().filter(|&&p| p).count()
    }

    /// Each body's circumradius (∞ for a half-space), as of the last detection.
    pub(crate) fn radii(&self) -> &[f64] {
        &self.cache.radii
    }

    /// Pairs whose manifold the last detection reused, and candidate pairs in all.
    pub fn reuse_counts(&self) -> (usize, usize) {
        let reused = self.results.heads().par_iter().filter(|r| r.reused).count();
        (reused, self.results.len())
    }

    /// Recomputes the per-body offsets into the flat geometry arrays; true if they changed since
    /// the last detection (bodies or shapes replaced: every anchor is then stale).
    fn refresh_layout(&mut self, bodies: &BodySet) -> bool {
        let c = &mut self.cache;
        // A first detection has no layout to compare with (anchors restored from a checkpoint
        // are then kept).
        let first = c.sizes.is_empty();
        let n = bodies.len();
        // The same shapes as last time: the same layout (comparing the shared shapes' addresses
        // reads no shape, where recounting their vertices would visit every one).
        fn polyhedron(s: &Shape) -> Option<&Arc<ConvexPolyhedron>> {
            match s {
                Shape::Polyhedron(p) => Some(p),
                Shape::Plane { .. } => None,
            }
        }
        let same = |(s, held): (&Shape, &Option<Arc<ConvexPolyhedron>>)| match (polyhedron(s), held)
        {
            (Some(p), Some(q)) => Arc::ptr_eq(p, q),
            (None, None) => true,
            _ => false,
        };
        if !first && c.shapes.len() == n && bodies.shape.iter().zip(&c.shapes).all(same) {
            return false;
        }
        c.shapes.clear();
        c.shapes
            .extend(bodies.shape.iter().map(|s| polyhedron(s).cloned()));
        c.radii.clear();
        c.radii.extend(
            c.shapes
                .iter()
                .map(|p| p.as_ref().map_or(f64::INFINITY, |p| p.radius)),
        );
        let sizes: Vec<[usize; 2]> = bodies
            .shape
            .iter()
            .map(|s| match s {
                Shape::Polyhedron(p) => [p.vertices.len(), p.face_normals.len()],
                Shape::Plane { .. } => [0, 0],
            })
            .collect();
        let changed = sizes != c.sizes;
        c.sizes = sizes;
        !first && changed
    }

    /// Places the world geometry of the bodies `active` marks (every body when empty) in the
    /// flat arrays, keeping what they held of bodies placed before unless `discard` (the
    /// layout changed); returns the bodies whose geometry is to be computed afresh.
    fn place(&mut self, active: &[bool], discard: bool) -> Vec<bool> {
        let c = &mut self.cache;
        let n = c.sizes.len();
        let want = |i: usize| active.is_empty() || active[i];
        if discard {
            c.placed.clear();
        }
        c.placed.resize(n, false);
        let fresh: Vec<bool> = (0..n).map(|i| want(i) && !c.placed[i]).collect();
        if c.vertex_start.len() == n + 1 && (0..n).all(|i| want(i) == c.placed[i]) {
            return fresh;
        }
        let (mut vertex_start, mut face_start) =
            (Vec::with_capacity(n + 1), Vec::with_capacity(n + 1));
        let (mut nv, mut nf) = (0, 0);
        for (i, [v, f]) in c.sizes.iter().enumerate() {
            vertex_start.push(nv);
            face_start.push(nf);
            if want(i) {
                nv += v;
                nf += f;
            }
        }
        vertex_start.push(nv);
        face_start.push(nf);
        let mut vertices = Vec::with_capacity(nv);
        let mut normals = Vec::with_capacity(nf);
        let mut offsets = Vec::with_capacity(nf);
        for (i, &[v, f]) in c.sizes.iter().enumerate().filter(|&(i, _)| want(i)) {
            if c.placed[i] {
                let (vs, fs) = (c.vertex_start[i], c.face_start[i]);
                vertices.extend_from_slice(&c.vertices[vs..vs + v]);
                normals.extend_from_slice(&c.normals[fs..fs + f]);
                offsets.extend_from_slice(&c.offsets[fs..fs + f]);
            } else {
                vertices.resize(vertices.len() + v, DVec3::ZERO);
                normals.resize(normals.len() + f, DVec3::ZERO);
                offsets.resize(offsets.len() + f, 0.0);
            }
        }
        c.vertices = vertices;
        c.normals = normals;
        c.offsets = offsets;
        c.vertex_start = vertex_start;
        c.face_start = face_start;
        c.placed = (0..n).map(want).collect();
        fresh
    }

    /// World vertices and face planes, at their anchor pose, of the placed bodies (`active`, as
    /// in [`Detector::place`]) that were re-anchored or are `fresh` (every placed body with
    /// `all`).
    fn refresh_geometry(&mut self, bodies: &BodySet, all: bool, active: &[bool], fresh: &[bool]) {
        let c = &mut self.cache;
        let anchors = &self.anchors;
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
                    let placed = active.is_empty() || active[i];
                    if !(placed && (all || anchors.moved[i] || fresh[i])) {
                        continue;
                    }
                    if let Shape::Polyhedron(p) = &bodies.shape[i] {
                        let (x, q) = (anchors.position[i], anchors.orientation[i]);
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

    /// The bodies whose geometry this rank places, when it holds its pairs; empty (every
    /// body) otherwise. They include every body its pairs may join ([`ranks::bodies_needed`]),
    /// each with a bound: the cube about its anchor position of half-side its circumradius
    /// plus its detection box's growth (`0.5 alert + reach(margin)`), which holds its box at
    /// the anchor pose, widened by a hair for rounding. The last placement is kept while it
    /// holds every needed body; else the bodies needed with every bound grown by half the
    /// median half-side (a slack of about a grain's circumradius) are placed, so that a
    /// placement lasts the many steps bodies take to move that far (a new placement moves
    /// the flat arrays and makes the broad phase enter the joining bodies).
    fn bodies_to_place(&self, alert: f64, reach: impl Fn(f64) -> f64 + Sync) -> Vec<bool> {
        let ex = self.exchange.as_deref().filter(|e| e.size() > 1);
        let (Some(ex), Some(owners), true) = (ex, self.owners.as_ref(), self.hold) else {
            return Vec::new();
        };
        let (radii, margins, anchors) = (&self.cache.radii, &self.margins, &self.anchors);
        let half: Vec<f64> = (0..radii.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| bound_half(radii[i], alert, reach(margins[i])))
            .collect();
        let bounds = |grow: f64| -> Vec<Aabb> {
            half.par_iter()
                .zip(&anchors.position)
                .with_min_len(1024)
                .map(|(&h, &x)| Aabb {
                    min: x - DVec3::splat(h + grow),
                    max: x + DVec3::splat(h + grow),
                })
                .collect()
        };
        let extents = &self.extents;
        let needed = ranks::bodies_needed(owners, ex.rank(), &bounds(0.0), extents);
        let placed = &self.cache.placed;
        if needed.is_empty() {
            return needed;
        }
        if placed.len() == needed.len() && needed.par_iter().zip(placed).all(|(&n, &p)| !n || p) {
            return placed.clone();
        }
        let mut finite: Vec<f64> = half.iter().copied().filter(|h| h.is_finite()).collect();
        let slack = match finite.is_empty() {
            true => 0.0,
            false => 0.5 * broad::median(&mut finite),
        };
        // Growing every bound and every subdomain's bound grows every region: a superset of
        // the needed bodies (a placement, whatever it holds beyond them, changes no result).
        let grown: Vec<Aabb> = extents
            .iter()
            .map(|e| match e.is_empty() {
                true => *e,
                false => Aabb {
                    min: e.min - DVec3::splat(slack),
                    max: e.max + DVec3::splat(slack),
                },
            })
            .collect();
        ranks::bodies_needed(owners, ex.rank(), &bounds(slack), &grown)
    }

    /// Body `i`'s bound for [`Detector::bodies_to_place`] (grown by nothing): the cube about
    /// its anchor position that holds its detection box.
    pub(crate) fn bound(&self, i: usize, alert: f64, reuse: f64) -> Aabb {
        let h = bound_half(self.cache.radii[i], alert, reach_of(reuse)(self.margins[i]));
        let x = self.anchors.position[i];
        Aabb {
            min: x - DVec3::splat(h),
            max: x + DVec3::splat(h),
        }
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
    ///
    /// Reuse distance `reuse` (m; 0 = every pair computed anew at the current poses, the exact
    /// method): the narrow phase runs at the bodies' anchor poses and a pair's manifold is
    /// reused while neither body is re-anchored (see [`coherence`]). Each body's margin is then
    /// `reuse + max(m, reuse)`: the distance its points may have moved since the anchor, plus
    /// a speed margin that is the same for every slow body (so a cached manifold depends on the
    /// anchors alone).
    pub fn detect(
        &mut self,
        bodies: &BodySet,
        alert: f64,
        dt: f64,
        reuse: f64,
        out: &mut Vec<RawContact>,
    ) {
        let layout_changed = self.begin(bodies, alert, dt, reuse);
        self.finish(bodies, alert, reuse, layout_changed, out);
    }

    /// The first part of [`Detector::detect`]: the margins and the anchors (each body's own);
    /// returns whether the bodies' layout changed.
    pub(crate) fn begin(&mut self, bodies: &BodySet, alert: f64, dt: f64, reuse: f64) -> bool {
        let n = bodies.len();
        let layout_changed = self.refresh_layout(bodies);
        let radii = &self.cache.radii;
        (0..n)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                // Fixed bodies and half-spaces (infinite radius) get no margin.
                if bodies.kind[i] == BodyKind::Fixed || radii[i] == f64::INFINITY {
                    0.0
                } else {
                    dt * (bodies.velocity[i].length()
                        + bodies.angular_velocity[i].length() * radii[i])
                }
            })
            .collect_into_vec(&mut self.margins);
        // The cached manifolds were computed with the alert distance and margins of these
        // settings; the anchors themselves stay valid whatever they are.
        let key = (alert.to_bits(), reuse.to_bits());
        if self.cached_for != Some(key) || layout_changed {
            self.pairs.clear();
            self.results.clear();
            self.cached_for = Some(key);
        }
        self.anchors.update(
            bodies,
            &self.cache.radii,
            &self.margins,
            reuse,
            layout_changed,
        );
        layout_changed
    }

    /// The rest of [`Detector::detect`], after [`Detector::begin`]: placement, the broad and
    /// the narrow phase.
    pub(crate) fn finish(
        &mut self,
        bodies: &BodySet,
        alert: f64,
        reuse: f64,
        layout_changed: bool,
        out: &mut Vec<RawContact>,
    ) {
        out.clear();
        let n = bodies.len();
        let reach = reach_of(reuse);
        let mut active = self.bodies_to_place(alert, reach);
        // Only the bodies up to date on this rank are placed: the others are not read.
        if !self.fresh.is_empty() {
            if active.is_empty() {
                active.clone_from(&self.fresh);
            } else {
                active
                    .iter_mut()
                    .zip(&self.fresh)
                    .for_each(|(a, f)| *a &= f);
            }
        }
        self.extents.clear();
        let fresh = self.place(&active, layout_changed);
        let all = std::mem::take(&mut self.geometry_stale);
        self.refresh_geometry(bodies, all, &active, &fresh);
        let placed = |i: usize| active.is_empty() || active[i];
        let (cache, margins) = (&self.cache, &self.margins);
        (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| match &bodies.shape[i] {
                _ if !placed(i) => Aabb::EMPTY,
                Shape::Polyhedron(_) => {
                    let v = &cache.vertices[cache.vertex_start[i]..cache.vertex_start[i + 1]];
                    let (lo, hi) = v.iter().fold(
                        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
                    );
                    let half = DVec3::splat(0.5 * alert + reach(margins[i]));
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
        let polys: Vec<u32> = (0..n as u32)
            .filter(|&i| !is_plane(i as usize) && placed(i as usize))
            .collect();
        let planes: Vec<u32> = (0..n as u32).filter(|&i| is_plane(i as usize)).collect();
        let dynamic = |i: u32| bodies.kind[i as usize] == BodyKind::Dynamic;
        let mut pairs = std::mem::take(&mut self.spare_pairs);
        // Which pairs are skipped depends on the kinds (a released body becomes dynamic).
        let same_kinds = self.kinds == bodies.kind;
        self.broad.update_pairs(
            &self.aabbs,
            &polys,
            |i, j| !dynamic(i) && !dynamic(j),
            same_kinds,
            &mut pairs,
        );
        if !same_kinds {
            self.kinds.clone_from(&bodies.kind);
        }
        // Half-spaces against every dynamic polyhedron whose box reaches within `alert`.
        let from_broad = pairs.len();
        let walls: Vec<(u32, DVec3, f64)> = planes
            .iter()
            .map(|&p| {
                let (nrm, off) = plane_world(&self.anchors, bodies, p as usize);
                (p, nrm, off)
            })
            .collect();
        let aabbs = &self.aabbs;
        // In parallel over the grains (the pairs are sorted below whatever their order).
        pairs.par_extend(
            polys
                .par_iter()
                .with_min_len(1024)
                .filter(|&&i| dynamic(i))
                .flat_map_iter(|&i| {
                    let b = aabbs[i as usize];
                    walls.iter().filter_map(move |&(p, nrm, off)| {
                        // Lowest corner of the box along the normal.
                        let lowest = DVec3::select(nrm.cmpge(DVec3::ZERO), b.min, b.max);
                        (nrm.dot(lowest) - off <= 0.5 * alert).then_some((p.min(i), p.max(i)))
                    })
                }),
        );
        // The broad phase's pairs come sorted: sort the half-space pairs alone, then merge.
        pairs[from_broad..].sort_unstable();
        if from_broad > 0 && from_broad < pairs.len() && pairs[from_broad] < pairs[from_broad - 1] {
            merge_sorted(&pairs[..from_broad], &pairs[from_broad..], &mut self.merged);
            std::mem::swap(&mut pairs, &mut self.merged);
        }
        let exchange = self.exchange.clone().filter(|e| e.size() > 1);
        // A rank that holds its pairs keeps only those.
        if let Some(ex) = exchange.as_deref().filter(|_| self.hold) {
            let owners = self
                .owners
                .as_ref()
                .expect("a rank that holds pairs knows who holds each");
            ranks::keep_own(ex, owners, &mut pairs);
        }
        // Each pair: last step's outcome (parallel, no serial merge), reused if neither body
        // was re-anchored, else computed at the anchors with its hint.
        let mut results = std::mem::take(&mut self.spare_results);
        let this = &*self;
        let (previous_pairs, previous) = (&self.pairs, &self.results);
        let moved = &self.anchors.moved;
        let last_of = |pair: (u32, u32)| previous_pairs.binary_search(&pair).ok();
        let reused = |(i, j): (u32, u32), last: Option<usize>| {
            last.filter(|&l| {
                previous.heads()[l].reusable && !moved[i as usize] && !moved[j as usize]
            })
            .map(|l| PairGeometry {
                reused: true,
                ..previous.get(l)
            })
        };
        let compute = |(i, j): (u32, u32), last: Option<usize>| {
            let (iu, ju) = (i as usize, j as usize);
            let hint = last.map_or(FaceHint::NONE, |l| previous.heads()[l].hint);
            let alert = alert + reach(margins[iu]) + reach(margins[ju]);
            let reusable = reuse > 0.0 && margins[iu] <= reuse && margins[ju] <= reuse;
            let geometry = match (this.world_poly(bodies, iu), this.world_poly(bodies, ju)) {
                (Some(a), Some(b)) => {
                    let (m, hint) = narrow::polyhedron_polyhedron_hinted(&a, &b, alert, hint);
                    PairGeometry::new(i, j, m, hint)
                }
                (None, Some(b)) => {
                    let (nrm, off) = plane_world(&this.anchors, bodies, iu);
                    let m = narrow::plane_polyhedron(nrm, off, &b, alert);
                    PairGeometry::new(i, j, m, FaceHint::NONE)
                }
                (Some(a), None) => {
                    let (nrm, off) = plane_world(&this.anchors, bodies, ju);
                    let m = narrow::plane_polyhedron(nrm, off, &a, alert);
                    PairGeometry::new(j, i, m, FaceHint::NONE)
                }
                (None, None) => PairGeometry::new(i, j, None, FaceHint::NONE),
            };
            PairGeometry {
                reusable,
                ..geometry
            }
        };
        let shared = match exchange.as_deref().filter(|_| !self.hold) {
            None => {
                // Both lists are sorted: each run of pairs bisects for its first pair's
                // outcome, then walks forward with the pairs (a bisection per pair costs more
                // than reusing its manifold).
                results.assemble(pairs.len(), |range, push| {
                    let run = &pairs[range];
                    let Some(first) = run.first() else { return };
                    let mut p = previous_pairs.partition_point(|q| q < first);
                    for &pair in run {
                        while p < previous_pairs.len() && previous_pairs[p] < pair {
                            p += 1;
                        }
                        let last = (previous_pairs.get(p) == Some(&pair)).then_some(p);
                        push(reused(pair, last).unwrap_or_else(|| compute(pair, last)));
                    }
                });
                0.0
            }
            Some(ex) => ranks::narrow_on_ranks(
                ex,
                pairs.len(),
                |k| reused(pairs[k], last_of(pairs[k])),
                |k| compute(pairs[k], last_of(pairs[k])),
                &mut results,
            ),
        };
        self.shared_seconds = shared;
        write_points(&results, &self.anchors, bodies, reuse > 0.0, out);
        self.spare_pairs = std::mem::replace(&mut self.pairs, pairs);
        self.spare_results = std::mem::replace(&mut self.results, results);
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
/// results knows where its points start from the counts of the chunks before it. With
/// `transport`, each point is carried from the anchor poses to the current ones: its foot on
/// each surface (`p ∓ g/2 n`) moves with its body, the normal with body 1, and the gap is the
/// distance between the feet along the normal.
fn write_points(
    results: &Outcomes,
    anchors: &Anchors,
    bodies: &BodySet,
    transport: bool,
    out: &mut Vec<RawContact>,
) {
    let blank = RawContact {
        body1: 0,
        body2: 0,
        point: DVec3::ZERO,
        normal: DVec3::ZERO,
        gap: 0.0,
    };
    // Each run of pairs writes its points, in pair order, where the runs before it end.
    let counts: Vec<usize> = results.runs().map(|(_, run)| run.point_count()).collect();
    let total = counts.iter().sum();
    reserve_total(out, total);
    out.resize(total, blank);
    let (slices, _) = split_lengths(out, counts);
    slices
        .into_par_iter()
        .zip(results.runs())
        .for_each(|(dst, (chunk, run))| {
            let mut d = dst.iter_mut();
            for r in chunk.iter().filter(|r| r.len > 0) {
                let (b1, b2) = (r.body1 as usize, r.body2 as usize);
                let still = !transport || anchors.is_at_anchor(b1) && anchors.is_at_anchor(b2);
                // The pair's normal turns with body 1, the same for all its points.
                let stored = run.normal(r);
                let normal = if still {
                    stored
                } else {
                    anchors.turn(b1, stored)
                };
                for p in run.points(r) {
                    let Some(slot) = d.next() else { return };
                    *slot = if still {
                        RawContact {
                            body1: r.body1,
                            body2: r.body2,
                            point: p.point,
                            normal,
                            gap: p.gap,
                        }
                    } else {
                        let foot1 = anchors.transport(bodies, b1, p.point - 0.5 * p.gap * stored);
                        let foot2 = anchors.transport(bodies, b2, p.point + 0.5 * p.gap * stored);
                        RawContact {
                            body1: r.body1,
                            body2: r.body2,
                            point: 0.5 * (foot1 + foot2),
                            normal,
                            gap: normal.dot(foot2 - foot1),
                        }
                    };
                }
            }
        });
}

/// World normal and offset (`n·x = offset` on the boundary) of half-space body `i` at its
/// anchor pose.
fn plane_world(anchors: &Anchors, bodies: &BodySet, i: usize) -> (DVec3, f64) {
    let Shape::Plane { normal } = &bodies.shape[i] else {
        unreachable!("plane_world called on a polyhedron")
    };
    let n = anchors.orientation[i] * *normal;
    (n, n.dot(anchors.position[i]))
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
