//! Convex polyhedron against convex polyhedron: Separating Axis Test and face clipping.
//!
//! Method (after Gregorius, "The Separating Axis Test between convex polyhedra", GDC 2013):
//!
//! 1. Face normals of A, then of B: the separation along a face normal is the smallest signed
//!    distance of the other body's vertices to the face plane. Any separation above the alert
//!    distance ends the test (no contact).
//! 2. Edge pairs whose Gauss-map arcs cross (the pair spans a face of the Minkowski difference)
//!    give the axis `eA × eB`, oriented out of A. The separation is first bounded from above by
//!    the distance between the edge lines, and only a pair that could win is evaluated exactly
//!    with the support functions of both bodies, so a round-off misjudged Gauss-map test can never
//!    report a separation that does not exist. A first pass skips the edges lying far beyond a
//!    face plane of the other body; the manifold it yields proves whether the bodies are close enough for that
//!    to be exact, and otherwise every edge pair is tested again (see `edge_axis`).
//! 3. The axis of largest separation wins, faces before edges and A's faces before B's within a
//!    small tolerance, which keeps face–face manifolds stable (a face is skipped if its clipped
//!    points do not reach the axis depth, see `choose`); an edge pair must moreover beat the
//!    best face by 10 % of its depth (see `EDGE_BIAS_RELATIVE`). A face axis gives a reference face
//!    and an incident face on the other body; the incident polygon is clipped by the side planes
//!    of the reference face (Sutherland–Hodgman); every clipped point within the alert distance,
//!    and every other vertex of the incident body within it above the reference face, becomes a
//!    contact point. An edge axis gives one point between the closest points of the two edges,
//!    and, when a face next to either edge is nearly orthogonal to the axis or is the face the
//!    preference chose but had to skip, the points of that face clipped along the axis (an edge
//!    lying across a face has two ends, see `edge_manifold`).
//!
//! Touching or overlapping, the largest separation over these axes is minus the penetration
//! depth (the largest over all directions); a face preferred to an edge pair reports a depth
//! at most that preference deeper. Apart, another direction (say, for two vertices
//! facing each other) may separate the bodies a little more, so a pair slightly farther apart
//! than the alert distance can still get a manifold, with gaps positive up to the preference
//! tolerance.
//!
//! Why not parry's manifolds: `parry3d` contact manifolds would need filtering before use in
//! NSCD (points beyond the prediction distance, duplicate points, an extra GJK point), and a
//! failure of its EPA is reported silently as "no contact", which lets grains fall through large
//! fixed boxes; its EPA depths can also be off by percents (see `tests/narrow_phase.rs`). The
//! test here has no iteration that can fail to converge.
//!
//! Deterministic (fixed loop orders, ties to the lowest index) and allocation-light: scratch data
//! lives in fixed-size stack arrays, with a heap fallback only for unusually large polyhedra; the
//! returned manifold is the only allocation.

use super::{reduce_to_four, Manifold, ManifoldPoint, WorldPolyhedron};
use crate::math::DVec3;

/// Preference tolerance between axes, relative to the smaller circumradius: the first axis in
/// the order A's face, B's face, edge pair whose separation is within this of the largest one is
/// chosen. Relative to the *smaller* body so that a grain on a 20 m box keeps a tolerance at the
/// grain's scale (it bounds the error on the deepest gap).
const PREFER_RELATIVE: f64 = 1e-5;
/// An edge pair is chosen over the best face only if it separates the bodies by more than that
/// face does by this fraction of the face's separation (its depth, when they overlap) plus
/// [`EDGE_BIAS_ABSOLUTE`] of the smaller circumradius (after Gregorius's relative and absolute
/// face preference), or if it separates bodies that the face finds overlapping. A grain's face
/// resting across another's ridge of nearly coplanar triangles has an edge pair as its deepest
/// axis, whose manifold keeps the face's points only while the face is within
/// [`EDGE_FACE_COS`] of the axis: as the grain rocks, the contact collapses to one point for a
/// step and the grain tips in by a millimetre. The face axis keeps the face's points whatever
/// the rocking, with a depth at most the bias deeper than the exact one; bodies apart never get
/// an overlap.
const EDGE_BIAS_RELATIVE: f64 = 0.1;
/// See [`EDGE_BIAS_RELATIVE`].
const EDGE_BIAS_ABSOLUTE: f64 = 1e-3;
/// Edge pairs whose directions make an angle with squared sine below this are parallel: their
/// cross product has no reliable direction, and the face axes already cover them.
const PARALLEL_SIN2: f64 = 1e-20;
/// An edge–edge contact also gets the points of a face contact along its axis when a face next
/// to one of the edges makes an angle with the axis whose cosine is at least this (2.6°): see
/// [`edge_manifold`]. Grains' hulls meet at ridges of nearly coplanar triangles, where a face
/// of the other body rests across the ridge and an edge pair is the deepest axis; a wider cone
/// mostly adds points beyond the alert distance's reach and costs sweeps on every contact.
const EDGE_FACE_COS: f64 = 0.999;
/// Edges of B whose Gauss-map arcs live on the stack (a 20-vertex grain has at most 54 edges).
const STACK_EDGES: usize = 64;
/// Vertices whose proximity masks live on the stack.
const STACK_VERTICES: usize = 64;
/// Faces whose bounds live on the stack.
const STACK_FACES: usize = 64;
/// Capacity of the stack buffers of the clipped polygon.
const STACK_POLYGON: usize = 48;

/// Contact manifold between polyhedra `a` (body 1) and `b` (body 2), or `None` when a face
/// normal or an edge–edge axis separates them by more than `alert`.
///
/// The normal points from `a` toward `b`; each point lies midway between the two surfaces and
/// carries its gap (negative when overlapping), at most `alert`. At most four points, reduced by
/// [`reduce_to_four`]. Face contacts give up to four points, edge–edge contacts one, or more
/// when a face next to either edge is within 2.6° of face-on or within the face preference.
///
/// Touching or overlapping, the deepest gap is minus the exact penetration depth (up to the
/// axis preference tolerance, `1e-5` of the smaller circumradius), or deeper by at most the
/// face preference over edge pairs (10 % of the depth plus `1e-3` of the smaller circumradius).
/// Apart within `alert`, gaps are at least the separation along the chosen axis, which is
/// positive up to the preference tolerance.
///
/// # Panics
///
/// Only in debug builds, when the world arrays of `a` or `b` do not match their shape's
/// topology (a caller bug); release builds then return `None`.
pub fn polyhedron_polyhedron(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    alert: f64,
) -> Option<Manifold> {
    polyhedron_polyhedron_hinted(a, b, alert, FaceHint::NONE).0
}

/// A face of one body of a pair, remembered from the pair's previous test: the face that
/// separated the bodies, or the best face of their contact.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FaceHint(u32);

impl FaceHint {
    /// No face.
    pub const NONE: FaceHint = FaceHint(u32::MAX);

    /// Face `face` of body 2 (`of_b`) or body 1.
    pub fn new(of_b: bool, face: usize) -> FaceHint {
        let face = u32::try_from(face)
            .unwrap_or(u32::MAX >> 1)
            .min(u32::MAX >> 1);
        FaceHint(face | (u32::from(of_b) << 31))
    }

    /// The hint as one number (for sharing between ranks), and back.
    pub(crate) fn to_bits(self) -> u32 {
        self.0
    }
    pub(crate) fn from_bits(bits: u32) -> FaceHint {
        FaceHint(bits)
    }

    /// `(of_b, face)`, or `None`.
    pub fn get(self) -> Option<(bool, usize)> {
        (self != FaceHint::NONE).then_some((self.0 >> 31 == 1, (self.0 & (u32::MAX >> 1)) as usize))
    }
}

/// [`polyhedron_polyhedron`] with temporal coherence: the hinted face is tested first, and if
/// it separates the bodies by more than `alert` the answer is `None` at the cost of one face.
/// Also returns the hint for the pair's next test.
///
/// The result never depends on the hint (any hint, valid or not, gives the same answer bit for
/// bit): the full test answers `None` whenever any face separates by more than `alert`. So a run
/// that resumes with no hints, or a hint from another pair, computes exactly the same contacts.
pub fn polyhedron_polyhedron_hinted(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    alert: f64,
    hint: FaceHint,
) -> (Option<Manifold>, FaceHint) {
    if !is_consistent(a) || !is_consistent(b) {
        debug_assert!(
            false,
            "WorldPolyhedron arrays inconsistent with their shape"
        );
        return (None, FaceHint::NONE);
    }
    if let Some((of_b, f)) = hint.get() {
        let (r, o) = if of_b { (b, a) } else { (a, b) };
        if f < r.face_normals.len()
            && min_vertex(o.vertices, r.face_normals[f]).1 - r.face_offsets[f] > alert
        {
            return (None, hint);
        }
    }
    match sat(a, b, alert) {
        Ok((manifold, best)) => (Some(manifold), best),
        Err(separating) => (None, separating),
    }
}

/// The separating axis test proper: the manifold and its best face, or the face that separates
/// the bodies by more than `alert` (`FaceHint::NONE` for bounding spheres or an edge pair).
fn sat(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    alert: f64,
) -> Result<(Manifold, FaceHint), FaceHint> {
    // Bounding spheres apart by more than `alert`: so are the bodies.
    let reach = a.shape.radius + b.shape.radius + alert;
    if (b.center - a.center).length_squared() > reach * reach {
        return Err(FaceHint::NONE);
    }

    let tol = PREFER_RELATIVE * a.shape.radius.min(b.shape.radius);
    let (face_a, scanned_a) = face_axis(a, b, alert).map_err(|f| FaceHint::new(false, f))?;
    let (face_b, scanned_b) = face_axis(b, a, alert).map_err(|f| FaceHint::new(true, f))?;
    // Flag each body's vertices lying far beyond a scanned face of the other, to skip the edges
    // far from the other body (see `edge_axis`). `near` bounds `max(−floor, alert)` from above,
    // since `floor ≥ face_a.sep`.
    let near = (-face_a.sep).max(alert) + tol;
    let (mut stack_far_a, mut heap_far_a) = ([0u64; STACK_VERTICES], Vec::new());
    let far_a = scratch(&mut stack_far_a, &mut heap_far_a, a.vertices.len(), 0);
    far_masks(b, a, near, scanned_b, far_a);
    let (mut stack_far_b, mut heap_far_b) = ([0u64; STACK_VERTICES], Vec::new());
    let far_b = scratch(&mut stack_far_b, &mut heap_far_b, b.vertices.len(), 0);
    far_masks(a, b, near, scanned_a, far_b);
    let floor = face_a.sep.max(face_b.sep);

    // First pass: only the edges near the other body, valid when the manifold proves that the
    // bodies are within `near` of each other. Otherwise, all edge pairs.
    let edge = edge_axis(a, b, alert, floor, Some((&*far_a, &*far_b))).ok_or(FaceHint::NONE)?;
    let bias =
        EDGE_BIAS_RELATIVE * floor.abs() + EDGE_BIAS_ABSOLUTE * a.shape.radius.min(b.shape.radius);
    let (mut manifold, witness) = choose(a, b, &face_a, &face_b, edge, alert, tol, bias);
    if witness > near || witness.is_nan() {
        let edge = edge_axis(a, b, alert, floor, None).ok_or(FaceHint::NONE)?;
        manifold = choose(a, b, &face_a, &face_b, edge, alert, tol, bias).0;
    }
    reduce_to_four(&mut manifold.points, manifold.normal, alert);
    let best = if face_b.sep > face_a.sep {
        FaceHint::new(true, face_b.face)
    } else {
        FaceHint::new(false, face_a.face)
    };
    Ok((manifold, best))
}

/// The manifold of the axis of largest separation, with its witness distance (see
/// [`face_manifold`], [`edge_manifold`]).
///
/// The edge pair counts as the largest separation only when it beats the best face by more
/// than `bias` (see [`EDGE_BIAS_RELATIVE`]). Among the axes within `tol` of the largest
/// separation, A's face comes first, then B's face, then the edge pair. A face is taken only if
/// its clipped points reach the depth of the axis (within `tol`): a face axis merely tied with
/// the true contact feature may clip to nothing representative, e.g. when two edges touch
/// beside a face.
#[allow(clippy::too_many_arguments)]
fn choose(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    face_a: &FaceAxis,
    face_b: &FaceAxis,
    edge: Option<EdgeAxis>,
    alert: f64,
    tol: f64,
    bias: f64,
) -> (Manifold, f64) {
    let faces = face_a.sep.max(face_b.sep);
    let edge_sep = edge.as_ref().map_or(f64::NEG_INFINITY, |e| e.sep);
    // NaN separations fall through to the largest one, as without the bias.
    let edge_wins = edge_sep > faces + bias || (edge_sep > 0.0 && faces <= 0.0);
    let best = if edge_wins || faces.is_nan() {
        faces.max(edge_sep)
    } else {
        faces
    };
    let mut first = None;
    // The faces tried and refused, in that order: an edge manifold takes the first one next to
    // its edges as its face (see `edge_faces`).
    let mut refused = [None; 2];
    for (k, (axis, r, o, flip)) in [(face_a, a, b, false), (face_b, b, a, true)]
        .into_iter()
        .enumerate()
    {
        if axis.sep >= best - tol {
            let (manifold, witness) = face_manifold(r, o, axis, alert, flip);
            let deepest = manifold
                .points
                .iter()
                .fold(f64::INFINITY, |m, p| m.min(p.gap));
            if witness.is_finite() && deepest <= best + tol {
                return (manifold, witness);
            }
            first.get_or_insert((manifold, witness));
            refused[k] = Some((flip, axis.face));
        }
    }
    match (edge, first) {
        (Some(e), _) if e.sep >= best - tol => edge_manifold(a, b, &e, alert, refused),
        (_, Some(first)) => first,
        // Unreachable: the best axis is a face or the edge pair.
        _ => face_manifold(a, b, face_a, alert, false),
    }
}

/// Whether the world arrays match the topology they will be indexed with.
fn is_consistent(p: &WorldPolyhedron) -> bool {
    let s = p.shape;
    let faces = s.face_normals.len();
    !p.vertices.is_empty()
        && faces > 0
        && p.vertices.len() == s.vertices.len()
        && p.face_normals.len() == faces
        && p.face_offsets.len() == faces
        && s.face_start.len() == faces + 1
        && s.edge_faces.len() == s.edges.len()
}

/// Best face axis of a reference body.
struct FaceAxis {
    /// Separation along the face normal.
    sep: f64,
    /// Face of the reference body.
    face: usize,
    /// Deepest vertex of the other body below that face.
    support: usize,
}

/// The face of `r` of largest separation from `o` and the set of faces scanned (bit `f` for the
/// first 64 faces), or `Err(f)` for a face `f` separating the bodies by more than `alert`.
///
/// Only the faces that can win are scanned: `o`'s centre of mass `c` lies in its hull and every
/// vertex within its circumradius `ρ` of `c`, so the separation along face `f` lies in
/// `[U_f − ρ, U_f]` with `U_f = n_f·c − d_f`. The face of largest `U_f` is scanned first; then,
/// in index order, only the faces whose upper bound reaches the best separation so far (they
/// alone can beat it or tie with it). Same result as scanning every face, first face on ties,
/// at a fraction of the cost: most faces of `r` look away from `o`, and a separating face is
/// usually the first one scanned.
fn face_axis(
    r: &WorldPolyhedron,
    o: &WorldPolyhedron,
    alert: f64,
) -> Result<(FaceAxis, u64), usize> {
    let rho = o.shape.radius;
    let faces = r.face_normals.len();
    let (mut stack_upper, mut heap_upper) = ([0.0; STACK_FACES], Vec::new());
    let upper = scratch(&mut stack_upper, &mut heap_upper, faces, 0.0);
    // The face of largest upper bound (first on ties). NaN bounds never compare below the
    // best separation, so their faces are scanned and their separation reports the NaN.
    let (mut first, mut top) = (0, f64::NEG_INFINITY);
    for (f, ((u, &n), &d)) in upper
        .iter_mut()
        .zip(r.face_normals)
        .zip(r.face_offsets)
        .enumerate()
    {
        *u = n.dot(o.center) - d;
        if *u > top {
            (first, top) = (f, *u);
        }
    }
    if upper[first] - rho > alert {
        return Err(first);
    }
    // Round-off of the bounds themselves: a few ulps of the coordinates.
    let slack = 1e-9 * rho;
    let mut scanned = 0u64;
    let mut best: Option<FaceAxis> = None;
    for f in std::iter::once(first).chain((0..faces).filter(|&f| f != first)) {
        if best.as_ref().is_some_and(|b| upper[f] + slack < b.sep) {
            continue;
        }
        let (support, min) = min_vertex(o.vertices, r.face_normals[f]);
        let d = r.face_offsets[f];
        if f < 64 {
            scanned |= 1 << f;
        }
        let sep = min - d;
        // NaN coordinates count as separated.
        if sep > alert || sep.is_nan() {
            return Err(f);
        }
        let better = best
            .as_ref()
            .is_none_or(|b| sep > b.sep || (sep == b.sep && f < b.face));
        if better {
            best = Some(FaceAxis {
                sep,
                face: f,
                support,
            });
        }
    }
    // Some face was scanned: the first one always is.
    best.map(|b| (b, scanned)).ok_or(first)
}

/// Sets bit `f` of `masks[v]` for each face `f` of `r` in `faces` (a set of the first 64) that
/// vertex `v` of `o` lies beyond by more than `thr`.
fn far_masks(r: &WorldPolyhedron, o: &WorldPolyhedron, thr: f64, faces: u64, masks: &mut [u64]) {
    let mut rest = faces;
    while rest != 0 {
        let f = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let (n, d) = (r.face_normals[f], r.face_offsets[f]);
        for (&v, mask) in o.vertices.iter().zip(masks.iter_mut()) {
            *mask |= u64::from(n.dot(v) - d > thr) << f;
        }
    }
}

/// Index and value of the smallest `n·v` (first one on ties).
#[inline]
fn min_vertex(vertices: &[DVec3], n: DVec3) -> (usize, f64) {
    let mut arg = 0;
    let mut min = f64::INFINITY;
    for (i, &v) in vertices.iter().enumerate() {
        let s = n.dot(v);
        if s < min {
            min = s;
            arg = i;
        }
    }
    (arg, min)
}

/// Support separation along unit `n`: `min over B of n·v − max over A of n·v`.
#[inline]
fn support_separation(a: &[DVec3], b: &[DVec3], n: DVec3) -> f64 {
    let max_a = a.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(n.dot(v)));
    let min_b = b.iter().fold(f64::INFINITY, |m, &v| m.min(n.dot(v)));
    min_b - max_a
}

/// Best edge–edge axis.
struct EdgeAxis {
    /// Separation along `normal`.
    sep: f64,
    /// Unit axis, pointing out of A.
    normal: DVec3,
    /// Edge of A.
    edge_a: usize,
    /// Edge of B.
    edge_b: usize,
}

/// The edge–edge axis of largest separation above `floor` (the best face separation) among
/// the edge pairs spanning a face of the Minkowski difference; `None` if one exceeds `alert`,
/// `Some(None)` if none beats `floor`.
///
/// With `far = Some((far_a, far_b))`, an edge of A whose two ends are flagged beyond the same
/// face plane of B (by more than some `thr ≥ max(−floor, alert)`, see [`far_masks`]) is skipped,
/// and so is an edge of B whose ends are beyond the same face plane of A. This loses nothing
/// when the bodies are within `thr` of each other: overlapping, the best edge axis `n`
/// (separation `s ∈ [floor, 0]`) has witness points `qa` on A's edge and `qa + s·n` on B's edge,
/// so each edge has a point within `|s| ≤ thr` of the other body, hence of every one of its
/// face planes; apart by at most `thr`, the Minkowski faces through the closest point have
/// witnesses within `thr` likewise. The caller checks that proximity on the resulting manifold
/// and falls back to all pairs otherwise.
///
/// The Gauss-map test runs branch-free over B's kept edges (structure of arrays, vectorisable);
/// only the few crossing pairs are examined further.
fn edge_axis(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    alert: f64,
    floor: f64,
    far: Option<(&[u64], &[u64])>,
) -> Option<Option<EdgeAxis>> {
    let is_far = |masks: &[u64], e: [u32; 2]| masks[e[0] as usize] & masks[e[1] as usize] != 0;
    // B's kept edges, then the negated Gauss-map arcs (c, d) of each, for the Minkowski
    // difference A − B, and d × c.
    let (mut stack_kept, mut heap_kept) = ([0u32; STACK_EDGES], Vec::new());
    let kept = scratch(&mut stack_kept, &mut heap_kept, b.shape.edges.len(), 0);
    let mut n_b = 0;
    for (j, &e) in b.shape.edges.iter().enumerate() {
        if !far.is_some_and(|(_, far_b)| is_far(far_b, e)) {
            kept[n_b] = j as u32;
            n_b += 1;
        }
    }
    let kept = &kept[..n_b];
    let mut stack = [[0.0; STACK_EDGES]; 9];
    let mut heap: [Vec<f64>; 9] = Default::default();
    let [cx, cy, cz, dx, dy, dz, ux, uy, uz] = if n_b <= STACK_EDGES {
        stack.each_mut().map(|s| &mut s[..n_b])
    } else {
        heap.each_mut().map(|h| {
            h.resize(n_b, 0.0);
            &mut h[..]
        })
    };
    for (k, &j) in kept.iter().enumerate() {
        let faces = b.shape.edge_faces[j as usize];
        let c = -b.face_normals[faces[0] as usize];
        let d = -b.face_normals[faces[1] as usize];
        let u = d.cross(c);
        (cx[k], cy[k], cz[k]) = (c.x, c.y, c.z);
        (dx[k], dy[k], dz[k]) = (d.x, d.y, d.z);
        (ux[k], uy[k], uz[k]) = (u.x, u.y, u.z);
    }
    let mut stack_hits = [false; STACK_EDGES];
    let mut heap_hits = Vec::new();
    let hits = scratch(&mut stack_hits, &mut heap_hits, n_b, false);

    let mut best: Option<EdgeAxis> = None;
    let mut best_sep = floor;
    for (ia, (&edge, faces)) in a.shape.edges.iter().zip(&a.shape.edge_faces).enumerate() {
        if far.is_some_and(|(far_a, _)| is_far(far_a, edge)) {
            continue;
        }
        let na = a.face_normals[faces[0] as usize];
        let nb = a.face_normals[faces[1] as usize];
        let w = nb.cross(na);
        // Do arcs (na, nb) and (c, d) cross on the unit sphere? The last product rejects
        // antipodal arcs (Gregorius' hemisphere test).
        for k in 0..n_b {
            let cba = w.x * cx[k] + w.y * cy[k] + w.z * cz[k];
            let dba = w.x * dx[k] + w.y * dy[k] + w.z * dz[k];
            let adc = na.x * ux[k] + na.y * uy[k] + na.z * uz[k];
            let bdc = nb.x * ux[k] + nb.y * uy[k] + nb.z * uz[k];
            hits[k] = (cba * dba < 0.0) & (adc * bdc < 0.0) & (cba * bdc > 0.0);
        }
        let pa = a.vertices[edge[0] as usize];
        let ea = a.vertices[edge[1] as usize] - pa;
        for (&ib, _) in kept.iter().zip(hits.iter()).filter(|(_, &hit)| hit) {
            let ib = ib as usize;
            let eb_idx = b.shape.edges[ib];
            let pb = b.vertices[eb_idx[0] as usize];
            let eb = b.vertices[eb_idx[1] as usize] - pb;
            let axis = ea.cross(eb);
            let len2 = axis.length_squared();
            if len2 <= PARALLEL_SIN2 * ea.length_squared() * eb.length_squared() || len2.is_nan() {
                continue;
            }
            let mut n = axis / len2.sqrt();
            if n.dot(pa - a.center) < 0.0 {
                n = -n;
            }
            // Distance between the edge lines: an upper bound of the support separation along
            // `n`, equal to it when the pair really spans a Minkowski face.
            if n.dot(pb - pa) <= best_sep {
                continue;
            }
            let sep = support_separation(a.vertices, b.vertices, n);
            if sep > alert || sep.is_nan() {
                return None;
            }
            if sep > best_sep {
                best_sep = sep;
                best = Some(EdgeAxis {
                    sep,
                    normal: n,
                    edge_a: ia,
                    edge_b: ib,
                });
            }
        }
    }
    Some(best)
}

/// A scratch slice of `n` copies of `zero`: the stack array when it is large enough, else the
/// heap vector.
fn scratch<'s, T: Copy, const N: usize>(
    stack: &'s mut [T; N],
    heap: &'s mut Vec<T>,
    n: usize,
    zero: T,
) -> &'s mut [T] {
    if n <= N {
        &mut stack[..n]
    } else {
        heap.clear();
        heap.resize(n, zero);
        heap
    }
}

/// Face contact: reference face `axis.face` of `r`, incident face on `o`; also returns the
/// witness distance, the smallest `|gap|` of the points (each point joins a point of `o`'s
/// incident face to its projection inside the reference face, so the bodies are at most that
/// far apart), or infinity for the fallback point.
///
/// The incident face is the face of `o` most anti-parallel to the reference normal among those
/// holding the deepest vertex: that vertex then always survives clipping when the face is the
/// axis of least penetration, so the deepest gap is the separation.
fn face_manifold(
    r: &WorldPolyhedron,
    o: &WorldPolyhedron,
    axis: &FaceAxis,
    alert: f64,
    flip: bool,
) -> (Manifold, f64) {
    let n = r.face_normals[axis.face];
    let offset = r.face_offsets[axis.face];
    let normal = if flip { -n } else { n };

    let ref_loop = face_loop(r, axis.face);
    let inc_loop = face_loop(o, incident_face(o, n, axis.support as u32));
    let mut points = Vec::with_capacity(inc_loop.len() + 4);
    let mut witness = f64::INFINITY;
    let mut keep = |x: DVec3| {
        let gap = n.dot(x) - offset;
        if gap <= alert {
            points.push(ManifoldPoint {
                point: x - 0.5 * gap * n,
                gap,
            });
            witness = witness.min(gap.abs());
        }
    };
    clip_face(r, ref_loop, o, inc_loop, n, &mut keep);

    // Other vertices of `o` within alert of the reference plane and inside the reference face
    // also bear: the far end of an edge resting on the face may lie on no face holding the
    // deepest vertex, and the body would pivot about a single point.
    let inside = |x: DVec3| {
        ref_loop.iter().enumerate().all(|(i, &v)| {
            let p = r.vertices[v as usize];
            let q = r.vertices[ref_loop[(i + 1) % ref_loop.len()] as usize];
            (q - p).cross(n).dot(x - p) <= 0.0
        })
    };
    let extra = o.vertices.iter().enumerate().filter_map(|(i, &x)| {
        let candidate = n.dot(x) - offset <= alert && !inc_loop.contains(&(i as u32));
        (candidate && inside(x)).then_some(x)
    });
    extra.for_each(&mut keep);
    if points.is_empty() {
        // Apart, with the deepest vertex outside the reference face's prism (e.g. boxes corner
        // to corner): keep one point at the deepest vertex with the axis separation as gap.
        let v = o.vertices[axis.support];
        points.push(ManifoldPoint {
            point: v - 0.5 * axis.sep * n,
            gap: axis.sep,
        });
    }
    (Manifold { normal, points }, witness)
}

/// Clips the incident face loop `inc_loop` of `o` by the side planes of the reference face
/// loop `ref_loop` of `r` and hands each vertex of the clipped polygon to `each`.
///
/// The side planes are parallel to `dir` (a unit vector with a positive component along the
/// reference face's normal, CCW orientation of the loop about it): the clipped polygon is the
/// part of the incident face whose projection along `dir` onto the reference plane lies inside
/// the reference face.
fn clip_face(
    r: &WorldPolyhedron,
    ref_loop: &[u32],
    o: &WorldPolyhedron,
    inc_loop: &[u32],
    dir: DVec3,
    mut each: impl FnMut(DVec3),
) {
    let cap = inc_loop.len() + ref_loop.len();
    let mut stack = [[DVec3::ZERO; STACK_POLYGON]; 2];
    let mut heap = [Vec::new(), Vec::new()];
    let [buf0, buf1] = if cap <= STACK_POLYGON {
        let [s0, s1] = &mut stack;
        [&mut s0[..], &mut s1[..]]
    } else {
        let [h0, h1] = &mut heap;
        h0.resize(cap, DVec3::ZERO);
        h1.resize(cap, DVec3::ZERO);
        [&mut h0[..], &mut h1[..]]
    };
    for (dst, &v) in buf0.iter_mut().zip(inc_loop) {
        *dst = o.vertices[v as usize];
    }
    let mut len = inc_loop.len();
    let (mut src, mut dst) = (buf0, buf1);
    for (i, &v) in ref_loop.iter().enumerate() {
        let p = r.vertices[v as usize];
        let q = r.vertices[ref_loop[(i + 1) % ref_loop.len()] as usize];
        // Outward normal of the side plane through edge (p, q) of the CCW reference loop.
        let side = (q - p).cross(dir);
        len = clip(&src[..len], dst, side, side.dot(p));
        std::mem::swap(&mut src, &mut dst);
        if len == 0 {
            break;
        }
    }
    src[..len].iter().copied().for_each(&mut each);
}

/// Vertex loop of face `f`.
#[inline]
fn face_loop<'s>(p: &WorldPolyhedron<'s>, f: usize) -> &'s [u32] {
    let s = p.shape;
    &s.face_vertices[s.face_start[f] as usize..s.face_start[f + 1] as usize]
}

/// Face of `o` holding vertex `v` with the normal most anti-parallel to `n` (first on ties);
/// over all faces if no face holds `v`.
fn incident_face(o: &WorldPolyhedron, n: DVec3, v: u32) -> usize {
    let mut best = None;
    let mut best_dot = f64::INFINITY;
    for (f, &m) in o.face_normals.iter().enumerate() {
        let dot = m.dot(n);
        if dot < best_dot && face_loop(o, f).contains(&v) {
            best_dot = dot;
            best = Some(f);
        }
    }
    best.unwrap_or_else(|| {
        let mut best = 0;
        let mut best_dot = f64::INFINITY;
        for (f, &m) in o.face_normals.iter().enumerate() {
            let dot = m.dot(n);
            if dot < best_dot {
                best_dot = dot;
                best = f;
            }
        }
        best
    })
}

/// Sutherland–Hodgman: clips convex polygon `input` to `{x : side·x ≤ offset}` into `out`
/// (capacity at least `input.len() + 1`) and returns the output length.
fn clip(input: &[DVec3], out: &mut [DVec3], side: DVec3, offset: f64) -> usize {
    let mut len = 0;
    let count = input.len();
    for i in 0..count {
        let cur = input[i];
        let next = input[(i + 1) % count];
        let dc = side.dot(cur) - offset;
        let dn = side.dot(next) - offset;
        if dc <= 0.0 && len < out.len() {
            out[len] = cur;
            len += 1;
        }
        // Strict crossings only: a vertex on the plane is kept once, not twice. The capacity
        // check only matters for a polygon made non-convex by round-off.
        if ((dc < 0.0 && dn > 0.0) || (dc > 0.0 && dn < 0.0)) && len < out.len() {
            out[len] = cur + (dc / (dc - dn)) * (next - cur);
            len += 1;
        }
    }
    len
}

/// Edge–edge contact: a point midway between the closest points of the two edges, with the
/// axis separation as gap, and their distance as witness distance.
///
/// When a face next to one of the edges is nearly orthogonal to the axis (within
/// [`EDGE_FACE_COS`]), or is a face that [`choose`] preferred but refused (`refused`), the
/// bodies are close to face-on over more than that point: e.g. an edge
/// of B lying across a face of A, sunk a little more at one end. The point alone then jumps
/// between the two ends of the contact as the bodies rock (each end is the deepest in turn, with
/// a different edge of A), and the torque of a single point pumps the rocking. So the manifold
/// also gets the points of the face contact along the same axis: the best aligned of those
/// faces is the reference, the face of the other body's edge most opposed to it the incident
/// face, clipped to the reference face's prism along the axis; each clipped point is joined to
/// the reference plane along the axis, and that length is its gap. Each such point pairs a point
/// of each surface on a line along the axis, so its gap is at least the axis separation: the
/// deepest gap stays the separation.
fn edge_manifold(
    a: &WorldPolyhedron,
    b: &WorldPolyhedron,
    axis: &EdgeAxis,
    alert: f64,
    refused: [Option<(bool, usize)>; 2],
) -> (Manifold, f64) {
    let ea = a.shape.edges[axis.edge_a];
    let eb = b.shape.edges[axis.edge_b];
    let pa = a.vertices[ea[0] as usize];
    let pb = b.vertices[eb[0] as usize];
    let (qa, qb) = closest_on_segments(
        pa,
        a.vertices[ea[1] as usize] - pa,
        pb,
        b.vertices[eb[1] as usize] - pb,
    );
    let n = axis.normal;
    let mut points = vec![ManifoldPoint {
        point: 0.5 * (qa + qb),
        gap: axis.sep,
    }];
    if let Some(EdgeFaces {
        r,
        ref_face,
        o,
        inc_face,
        dir,
    }) = edge_faces(a, b, axis, refused)
    {
        let (m, d) = (r.face_normals[ref_face], r.face_offsets[ref_face]);
        let along = m.dot(dir);
        clip_face(
            r,
            face_loop(r, ref_face),
            o,
            face_loop(o, inc_face),
            dir,
            |x| {
                // `x + s·dir` lies on the reference plane; `dir` points out of `r`, so the
                // surfaces are `−s` apart along the axis (negative when overlapping).
                let s = (d - m.dot(x)) / along;
                if -s <= alert {
                    points.push(ManifoldPoint {
                        point: x + 0.5 * s * dir,
                        gap: -s,
                    });
                }
            },
        );
    }
    (Manifold { normal: n, points }, (qb - qa).length())
}

/// The faces of an edge–edge contact to clip (see [`edge_manifold`]).
struct EdgeFaces<'w, 's> {
    /// Reference body and face.
    r: &'w WorldPolyhedron<'s>,
    ref_face: usize,
    /// Incident body and face.
    o: &'w WorldPolyhedron<'s>,
    inc_face: usize,
    /// The axis oriented out of the reference body.
    dir: DVec3,
}

/// The faces of an edge–edge contact to clip; `None` when no face next to either edge is
/// within [`EDGE_FACE_COS`] of the axis. The reference is the best aligned of the four faces
/// next to the two edges (A's before B's, first on ties); the incident face is the one next to
/// the other body's edge most opposed to the oriented axis.
fn edge_faces<'w, 's>(
    a: &'w WorldPolyhedron<'s>,
    b: &'w WorldPolyhedron<'s>,
    axis: &EdgeAxis,
    refused: [Option<(bool, usize)>; 2],
) -> Option<EdgeFaces<'w, 's>> {
    let n = axis.normal;
    let faces_a = a.shape.edge_faces[axis.edge_a];
    let faces_b = b.shape.edge_faces[axis.edge_b];
    // A face within the face preference of the axis that `choose` refused (its clipped points
    // fall short of its depth, the deepest vertex lying beyond it): it is the face the
    // contact is nearly on, whatever its angle, so it takes the cone's place.
    let adjacent = |&(of_b, f): &(bool, usize)| {
        let faces = if of_b { faces_b } else { faces_a };
        faces.contains(&(f as u32))
    };
    let mut best: Option<(bool, usize)> = None;
    let mut best_cos = EDGE_FACE_COS;
    for (of_b, body, faces, sign) in [(false, a, faces_a, 1.0), (true, b, faces_b, -1.0)] {
        for f in faces {
            let c = sign * body.face_normals[f as usize].dot(n);
            if c >= best_cos && best.is_none_or(|_| c > best_cos) {
                best_cos = c;
                best = Some((of_b, f as usize));
            }
        }
    }
    let (of_b, ref_face) = refused.iter().flatten().copied().find(adjacent).or(best)?;
    let (r, o, dir, inc_faces) = if of_b {
        (b, a, -n, faces_a)
    } else {
        (a, b, n, faces_b)
    };
    let [f0, f1] = inc_faces.map(|f| f as usize);
    let inc_face = if o.face_normals[f1].dot(dir) < o.face_normals[f0].dot(dir) {
        f1
    } else {
        f0
    };
    Some(EdgeFaces {
        r,
        ref_face,
        o,
        inc_face,
        dir,
    })
}

/// Closest points of segments `p1 + s·d1` and `p2 + t·d2`, `s, t ∈ [0, 1]` (Ericson, Real-Time
/// Collision Detection, 5.1.9).
fn closest_on_segments(p1: DVec3, d1: DVec3, p2: DVec3, d2: DVec3) -> (DVec3, DVec3) {
    let r = p1 - p2;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    if a <= f64::MIN_POSITIVE || e <= f64::MIN_POSITIVE {
        // Degenerate edge: never produced by a valid hull; answer something finite.
        return (p1, p2);
    }
    let b = d1.dot(d2);
    let c = d1.dot(r);
    let denom = a * e - b * b;
    let mut s = if denom > 0.0 {
        ((b * f - c * e) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (p1 + d1 * s, p2 + d2 * t)
}
