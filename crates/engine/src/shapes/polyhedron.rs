//! Closed convex polyhedra: hull of a point cloud, face/edge topology, body frame.

use super::mass::MassProperties;
use crate::math::{DMat3, DQuat, DVec3};
use std::collections::HashMap as StdHashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Why a shape could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeError {
    /// Fewer than four points, or all points (nearly) coplanar or collinear.
    #[error("degenerate polyhedron: {0}")]
    Degenerate(String),
    /// The hull is smaller than the allowed minimum size.
    #[error("polyhedron too small: {0}")]
    TooSmall(String),
    /// A coordinate is NaN or infinite.
    #[error("non-finite vertex coordinate")]
    NonFinite,
}

/// A closed convex polyhedron in its body frame: origin at the centre of mass, axes along the
/// principal axes of inertia.
///
/// Faces are maximal planar polygons (coplanar hull triangles merged), so that face–face contacts
/// are recognised as such. All arrays are in the body frame.
#[derive(Clone, Debug)]
pub struct ConvexPolyhedron {
    /// Hull vertices.
    pub vertices: Vec<DVec3>,
    /// Outward unit normal of each face.
    pub face_normals: Vec<DVec3>,
    /// Offset of each face plane: `face_normals[f] · x = face_offsets[f]` on face `f`.
    pub face_offsets: Vec<f64>,
    /// Vertex loops of the faces, counter-clockwise seen from outside, flattened:
    /// face `f` is `face_vertices[face_start[f] as usize .. face_start[f + 1] as usize]`.
    pub face_start: Vec<u32>,
    /// See [`ConvexPolyhedron::face_start`].
    pub face_vertices: Vec<u32>,
    /// Edges as vertex pairs `[a, b]` with `a < b`.
    pub edges: Vec<[u32; 2]>,
    /// The two faces adjacent to each edge: `[f0, f1]` where face `f0` runs the edge `a → b` and
    /// face `f1` runs it `b → a`.
    pub edge_faces: Vec<[u32; 2]>,
    /// Radius of the smallest origin-centred sphere holding the polyhedron.
    pub radius: f64,
    /// Volume.
    pub volume: f64,
    /// Principal moments of inertia per unit density (volume-weighted), about the body axes.
    pub unit_inertia: DVec3,
}

/// Result of building a polyhedron from points given in some frame (e.g. the world frame).
#[derive(Clone, Debug)]
pub struct PolyhedronBuild {
    /// The polyhedron in its body frame.
    pub shape: ConvexPolyhedron,
    /// Position of the centre of mass in the input frame.
    pub position: DVec3,
    /// Rotation from the body frame to the input frame: `x_input = position + orientation * x_body`.
    pub orientation: DQuat,
}

/// Smallest accepted size of a polyhedron: the diagonal of its bounding box, in metres.
pub const MIN_EXTENT: f64 = 1e-6;

/// A point set is flat when the volume of its greedy extreme tetrahedron is below this fraction
/// of `extent³` (a slab thinner than about `2e-8` of its width).
const FLATNESS: f64 = 1e-9;
/// Input points closer than this fraction of the extent are merged before the hull is built.
const DUPLICATE_TOL: f64 = 1e-10;
/// Adjacent hull triangles are merged into one face when their normals agree to this cosine…
const MERGE_COS: f64 = 1.0 - 1e-10;
/// …and their vertices lie within this fraction of the extent of the face plane.
const MERGE_DIST: f64 = 1e-9;
/// Largest accepted distance (fraction of the extent) of a face vertex below its face plane.
const PLANAR_TOL: f64 = 1e-8;

impl ConvexPolyhedron {
    /// Builds the convex hull of `points` (given in any frame, e.g. the world frame) in its body
    /// frame.
    ///
    /// The returned [`PolyhedronBuild`] holds the shape with its origin at the centre of mass and
    /// its axes along the principal axes of inertia (moments ascending, so the body `x` axis is
    /// the "long" axis), and the pose that maps it back onto the input points. Coplanar hull
    /// triangles are merged into maximal convex planar polygons, and hull points lying inside a
    /// face or on an edge are dropped, so every vertex is a corner of at least three faces.
    ///
    /// Guarantees, with `extent` the bounding-box diagonal of the input: vertices are input
    /// points (mapped to the body frame), every vertex satisfies `n·x ≤ d` for every face,
    /// face vertices lie within `1e-8·extent` of their plane and every input point within
    /// `1e-8·extent` inside every face plane (both at rounding level unless the input has facets
    /// within about `1e-9·extent` of coplanarity, which are merged), `V − E + F = 2`, and the
    /// volume and inertia are exact (to rounding) for the stored vertices and faces. The result depends only
    /// on the input (no hashing or threading order).
    ///
    /// Building is not meant for hot loops: about 10–50 µs for a 10–30 point grain.
    ///
    /// # Errors
    ///
    /// * [`ShapeError::NonFinite`] if a coordinate is NaN or infinite;
    /// * [`ShapeError::Degenerate`] for fewer than 4 points, coincident, collinear or coplanar
    ///   points (the greedy extreme tetrahedron has a volume below `1e-9·extent³`), or a hull
    ///   whose topology cannot be made consistent;
    /// * [`ShapeError::TooSmall`] if the bounding-box diagonal is below [`MIN_EXTENT`].
    pub fn from_points(points: &[DVec3]) -> Result<PolyhedronBuild, ShapeError> {
        build_indexed(points).map(|(build, _)| build)
    }

    /// A rectangular box with the given half extents, centred at the origin of the input frame.
    ///
    /// The body axes are the box axes reordered by ascending moment (longest box side first), so
    /// `orientation` is a signed permutation; for a cube it is the identity.
    ///
    /// # Errors
    ///
    /// [`ShapeError::NonFinite`] for a non-finite half extent, [`ShapeError::Degenerate`] for a
    /// non-positive one, and the errors of [`ConvexPolyhedron::from_points`].
    pub fn cuboid(half_extents: DVec3) -> Result<PolyhedronBuild, ShapeError> {
        if !half_extents.is_finite() {
            return Err(ShapeError::NonFinite);
        }
        if half_extents.min_element() <= 0.0 {
            return Err(ShapeError::Degenerate(format!(
                "cuboid half extents must be positive, got {half_extents}"
            )));
        }
        let h = half_extents;
        let corners: Vec<DVec3> = (0..8)
            .map(|i| {
                DVec3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                )
            })
            .collect();
        Self::from_points(&corners)
    }

    /// Number of faces.
    #[inline]
    pub fn num_faces(&self) -> usize {
        self.face_normals.len()
    }

    /// Vertex loop of face `f`, counter-clockwise seen from outside.
    #[inline]
    pub fn face(&self, f: usize) -> &[u32] {
        &self.face_vertices[self.face_start[f] as usize..self.face_start[f + 1] as usize]
    }

    /// A vertex maximising `dir · x` (the first one on ties), in the body frame; the origin for
    /// a polyhedron without vertices (never built by this module).
    pub fn support(&self, dir: DVec3) -> DVec3 {
        let Some((&first, rest)) = self.vertices.split_first() else {
            return DVec3::ZERO;
        };
        let mut best = first;
        let mut best_dot = dir.dot(best);
        for &v in rest {
            let d = dir.dot(v);
            if d > best_dot {
                best = v;
                best_dot = d;
            }
        }
        best
    }

    /// Fan triangulation of the faces with outward (counter-clockwise) winding, for output and
    /// mass-property checks: `(V − 2)` triangles per face of `V` vertices.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let mut out = Vec::with_capacity(self.face_vertices.len());
        for f in 0..self.num_faces() {
            let loop_ = self.face(f);
            for k in 1..loop_.len().saturating_sub(1) {
                out.push([loop_[0], loop_[k], loop_[k + 1]]);
            }
        }
        out
    }

    /// The same polyhedron scaled by `factor > 0` about its centre of mass (the body origin):
    /// lengths scale by `factor`, the volume by `factor³`, the unit inertia by `factor⁵`.
    pub fn scaled(&self, factor: f64) -> ConvexPolyhedron {
        let mut s = self.clone();
        for v in &mut s.vertices {
            *v *= factor;
        }
        for d in &mut s.face_offsets {
            *d *= factor;
        }
        // Recomputed rather than scaled, so it stays exactly the largest vertex norm.
        s.radius = s.vertices.iter().map(|v| v.length()).fold(0.0, f64::max);
        s.volume *= factor * factor * factor;
        s.unit_inertia *= factor.powi(5);
        s
    }
}

/// [`ConvexPolyhedron::from_points`], also returning for each vertex of the result the index of
/// the input point it came from.
pub(crate) fn build_indexed(points: &[DVec3]) -> Result<(PolyhedronBuild, Vec<usize>), ShapeError> {
    if points.iter().any(|p| !p.is_finite()) {
        return Err(ShapeError::NonFinite);
    }
    if points.len() < 4 {
        return Err(ShapeError::Degenerate(format!(
            "{} point(s) given, a polyhedron needs at least 4 non-coplanar points",
            points.len()
        )));
    }
    let (lo, hi) = points.iter().fold((points[0], points[0]), |(lo, hi), &p| {
        (lo.min(p), hi.max(p))
    });
    let extent = (hi - lo).length();
    if !extent.is_finite() {
        return Err(ShapeError::Degenerate(format!(
            "coordinates too large: bounding box from {lo} to {hi} overflows"
        )));
    }
    if extent == 0.0 {
        return Err(ShapeError::Degenerate(format!(
            "all {} points coincide at {lo}",
            points.len()
        )));
    }
    if extent < MIN_EXTENT {
        return Err(ShapeError::TooSmall(format!(
            "bounding-box diagonal {extent:e} m is below the minimum {MIN_EXTENT:e} m"
        )));
    }
    let unique = unique_points(points, DUPLICATE_TOL * extent);
    let frame = extreme_frame(points, &unique, extent)?;

    // parry decides the hull's dimension from the covariance of the points scaled by their
    // bounding box, and silently returns a flat (zero-volume) mesh when the smallest spread is
    // below ~3e-4 of the box diagonal, e.g. for a 2 m × 2 m × 1 mm plate. The hull being
    // affine-invariant, it can be computed on the points mapped into the extreme tetrahedron's
    // frame, where the set spans about one unit in every direction, and mapped back by index.
    // That mapping however rounds exactly collinear/coplanar inputs (boxes, prisms, grids) into
    // nearly-degenerate ones, on which parry may return a non-convex mesh, so the raw points are
    // tried first and the mapped ones only if that fails.
    let try_both = |ids: &[usize], used: &mut Vec<usize>| {
        let raw: Vec<DVec3> = ids.iter().map(|&i| points[i]).collect();
        let first = match hull_attempt(points, ids, &raw, extent, used) {
            Ok(done) => return Ok(done),
            Err(why) => why,
        };
        let mapped: Vec<DVec3> = raw.iter().map(|&p| frame.map(p)).collect();
        hull_attempt(points, ids, &mapped, extent, used).map_err(|second| (first, second))
    };
    let mut used = Vec::new();
    let (first, second) = match try_both(&unique, &mut used) {
        Ok(done) => return Ok(done),
        Err(why) => why,
    };
    // Points strictly inside a hull edge can derail parry (they make nearly-zero-area facets
    // whose orientation is decided by rounding). They are never corners, so drop them from the
    // points the failed hulls used, and try once more.
    if used.is_empty() {
        used = unique;
    }
    used.sort_unstable();
    used.dedup();
    let cleaned = drop_points_on_segments(points, &used, MERGE_DIST * extent);
    try_both(&cleaned, &mut Vec::new()).map_err(|(third, fourth)| {
        ShapeError::Degenerate(format!(
            "no consistent convex hull: {first}; {second}; {third}; {fourth}"
        ))
    })
}

/// The points of `ids` that do not lie within `tol` of the inside of a segment joining two other
/// points of `ids` (O(n³), for the rare retry path only).
fn drop_points_on_segments(points: &[DVec3], ids: &[usize], tol: f64) -> Vec<usize> {
    let on_segment = |p: DVec3, a: DVec3, b: DVec3| {
        let ab = b - a;
        let t = (p - a).dot(ab) / ab.length_squared();
        t > 0.0 && t < 1.0 && (a + ab * t).distance(p) <= tol
    };
    ids.iter()
        .copied()
        .filter(|&i| {
            let p = points[i];
            !ids.iter().enumerate().any(|(k, &a)| {
                a != i
                    && ids[k + 1..]
                        .iter()
                        .any(|&b| b != i && on_segment(p, points[a], points[b]))
            })
        })
        .collect()
}

/// One hull computation on `coords` (an affine image of `points[unique[k]]`), mapped back to
/// the input points and assembled; the error says what went wrong. The input points the hull
/// used are appended to `used`.
fn hull_attempt(
    points: &[DVec3],
    unique: &[usize],
    coords: &[DVec3],
    extent: f64,
    used: &mut Vec<usize>,
) -> Result<(PolyhedronBuild, Vec<usize>), String> {
    let (hull_pts, hull_tris) = parry3d_f64::transformation::try_convex_hull(coords)
        .map_err(|e| format!("hull computation failed ({e})"))?;
    let lookup: HashMap<[u64; 3], usize> = coords
        .iter()
        .enumerate()
        .rev() // the first occurrence wins on (unlikely) collisions
        .map(|(k, p)| (p.to_array().map(f64::to_bits), unique[k]))
        .collect();
    let hull_index = hull_pts
        .iter()
        .map(|p| lookup.get(&p.to_array().map(f64::to_bits)).copied())
        .collect::<Option<Vec<usize>>>()
        .ok_or("hull returned a point not in the input")?;
    used.extend_from_slice(&hull_index);
    let mut tris: Vec<[usize; 3]> = Vec::with_capacity(hull_tris.len());
    for t in &hull_tris {
        if t.iter().any(|&k| k as usize >= hull_index.len()) {
            return Err("hull returned an invalid index".into());
        }
        let t = t.map(|k| hull_index[k as usize]);
        // parry pads degenerate (point/segment) results with repeated indices.
        if t[0] != t[1] && t[1] != t[2] && t[2] != t[0] {
            tris.push(t);
        }
    }
    let o = points[unique[0]];
    let signed6: f64 = tris
        .iter()
        .map(|t| {
            let a = points[t[0]] - o;
            a.dot((points[t[1]] - o).cross(points[t[2]] - o))
        })
        .sum();
    if tris.len() < 4 || signed6 == 0.0 || !signed6.is_finite() {
        return Err(format!(
            "hull is flat ({} triangles, volume {:e} m³)",
            tris.len(),
            signed6 / 6.0
        ));
    }
    if signed6 < 0.0 {
        for t in &mut tris {
            t.swap(1, 2);
        }
    }
    let twin = directed_edges(&tris).ok_or("hull is not a closed manifold surface")?;

    // Merged faces first; should the merge give an inconsistent topology (a pathological
    // near-coplanar configuration), keep the hull triangles as faces.
    assemble(points, merge_faces(points, &tris, &twin, extent), extent).or_else(|_| {
        let loops = tris.iter().map(|t| t.to_vec()).collect();
        assemble(points, loops, extent)
    })
}

/// Indices of the points left after merging points closer than `tol` (first occurrence kept),
/// ascending.
fn unique_points(points: &[DVec3], tol: f64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].x.total_cmp(&points[b].x).then(a.cmp(&b)));
    let mut dup = vec![false; points.len()];
    for (k, &i) in order.iter().enumerate() {
        if dup[i] {
            continue;
        }
        for &j in &order[k + 1..] {
            if points[j].x - points[i].x > tol {
                break;
            }
            if !dup[j] && points[i].distance(points[j]) <= tol {
                // Keep the lower input index for determinism independent of the sort.
                dup[i.max(j)] = true;
            }
        }
    }
    (0..points.len()).filter(|&i| !dup[i]).collect()
}

/// Orthonormal frame of a greedy extreme tetrahedron `(a, b, c, d)` of the point set, with the
/// spreads `(L, h, t)` of the set along its axes.
struct ExtremeFrame {
    origin: DVec3,
    axes: [DVec3; 3],
    inv_scale: DVec3,
}

impl ExtremeFrame {
    /// Maps a point into the frame, scaled so the set spans about one unit along each axis.
    fn map(&self, p: DVec3) -> DVec3 {
        let r = p - self.origin;
        DVec3::new(
            r.dot(self.axes[0]),
            r.dot(self.axes[1]),
            r.dot(self.axes[2]),
        ) * self.inv_scale
    }
}

/// Greedy extreme tetrahedron: `a` the first point of least `x`, `b` the farthest from `a`,
/// `c` the farthest from line `ab`, `d` the farthest from plane `abc`. Its volume `L h t / 6`
/// is within a constant factor of the largest tetrahedron of the set, which makes it a sound
/// flatness measure; rejects flat sets with a message saying what was found.
fn extreme_frame(points: &[DVec3], ids: &[usize], extent: f64) -> Result<ExtremeFrame, ShapeError> {
    let arg_max = |f: &dyn Fn(DVec3) -> f64| {
        let mut best = (ids[0], f(points[ids[0]]));
        for &i in &ids[1..] {
            let v = f(points[i]);
            if v > best.1 {
                best = (i, v);
            }
        }
        best
    };
    let (ia, _) = arg_max(&|p: DVec3| -p.x);
    let a = points[ia];
    let (ib, len) = arg_max(&|p: DVec3| p.distance(a));
    let e0 = (points[ib] - a) / len;
    let off_line = |p: DVec3| {
        let r = p - a;
        r - e0 * r.dot(e0)
    };
    let (ic, h) = arg_max(&|p: DVec3| off_line(p).length());
    let flat = |what: String| {
        ShapeError::Degenerate(format!(
            "{} points are (nearly) {what}, for an extent of {extent:e} m",
            points.len()
        ))
    };
    if len * h < FLATNESS * extent * extent || h == 0.0 {
        return Err(flat(format!(
            "collinear: largest distance from the line through two extreme points is {h:e} m"
        )));
    }
    let e1 = off_line(points[ic]) / h;
    let e2 = e0.cross(e1).normalize();
    let (_, t) = arg_max(&|p: DVec3| (p - a).dot(e2).abs());
    let volume = len * h * t / 6.0;
    if volume < FLATNESS * extent.powi(3) || t == 0.0 {
        let what = if t < 1e-3 * h {
            "coplanar"
        } else {
            "collinear (needle-like)"
        };
        return Err(flat(format!(
            "{what}: extreme points span {len:e} m, {h:e} m off their line and {t:e} m off \
             their plane (relative tetrahedron volume {:e} < {FLATNESS:e})",
            volume / extent.powi(3)
        )));
    }
    Ok(ExtremeFrame {
        origin: a,
        axes: [e0, e1, e2],
        inv_scale: DVec3::new(1.0 / len, 1.0 / h, 1.0 / t),
    })
}

/// Map from directed edge `(u, v)` to the triangle holding it, if every directed edge appears
/// once and has its reverse (a closed, consistently oriented 2-manifold).
fn directed_edges(tris: &[[usize; 3]]) -> Option<HashMap<(usize, usize), usize>> {
    let mut map = HashMap::with_capacity_and_hasher(3 * tris.len(), Default::default());
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            if map.insert((tri[k], tri[(k + 1) % 3]), t).is_some() {
                return None;
            }
        }
    }
    map.keys()
        .all(|&(u, v)| map.contains_key(&(v, u)))
        .then_some(map)
}

/// Groups adjacent, coplanar hull triangles into convex polygonal faces and returns each face's
/// boundary loop (outward, counter-clockwise winding).
///
/// 1. Clusters: seeds are taken by decreasing area, so each plane comes from its
///    best-conditioned triangle; a neighbour joins when its vertices lie within
///    `MERGE_DIST·size` of the seed plane and, unless it is a sliver (height below that
///    tolerance, so its normal is noise), its normal agrees to `MERGE_COS`.
/// 2. A cluster whose boundary is one simple, convex loop becomes a face. Otherwise (possible
///    only for nearly, not exactly, coplanar points, whose near-planar triangles can form a
///    non-convex region) it is split by [`grow_convex_faces`].
fn merge_faces(
    p: &[DVec3],
    tris: &[[usize; 3]],
    twin: &HashMap<(usize, usize), usize>,
    size: f64,
) -> Vec<Vec<usize>> {
    let dist_tol = MERGE_DIST * size;
    let mut normal = Vec::with_capacity(tris.len());
    let mut area2 = Vec::with_capacity(tris.len());
    let mut reliable = Vec::with_capacity(tris.len());
    for t in tris {
        let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
        let cross = (b - a).cross(c - a);
        let len = cross.length();
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        normal.push(if len > 0.0 { cross / len } else { DVec3::ZERO });
        area2.push(len);
        reliable.push(len > dist_tol * longest);
    }
    let mut order: Vec<usize> = (0..tris.len()).collect();
    order.sort_by(|&x, &y| area2[y].total_cmp(&area2[x]).then(x.cmp(&y)));

    let mut cluster = vec![usize::MAX; tris.len()];
    let mut planes = Vec::new();
    let mut stack = Vec::new();
    for &seed in &order {
        if cluster[seed] != usize::MAX {
            continue;
        }
        let c = planes.len();
        let (n, d) = (normal[seed], normal[seed].dot(p[tris[seed][0]]));
        planes.push((n, d));
        cluster[seed] = c;
        // A sliver seed has no plane to offer: it stays alone (it is normally absorbed earlier).
        if reliable[seed] {
            stack.push(seed);
        }
        while let Some(t) = stack.pop() {
            for k in 0..3 {
                let nb = twin[&(tris[t][(k + 1) % 3], tris[t][k])];
                if cluster[nb] == usize::MAX
                    && tris[nb]
                        .iter()
                        .all(|&i| (n.dot(p[i]) - d).abs() <= dist_tol)
                    && (!reliable[nb] || normal[nb].dot(n) > MERGE_COS)
                {
                    cluster[nb] = c;
                    stack.push(nb);
                }
            }
        }
    }
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); planes.len()];
    for &t in &order {
        members[cluster[t]].push(t);
    }

    let mut loops = Vec::with_capacity(planes.len());
    let mut next = HashMap::default();
    for (c, group) in members.iter().enumerate() {
        // Boundary: the group's directed edges whose twin lies in another group.
        next.clear();
        let mut simple = true;
        for &t in group {
            for k in 0..3 {
                let (u, v) = (tris[t][k], tris[t][(k + 1) % 3]);
                if cluster[twin[&(v, u)]] != c && next.insert(u, v).is_some() {
                    simple = false; // two boundary edges leave `u`: a pinched group
                }
            }
        }
        if simple {
            if let Some(l) = walk_loop(&next) {
                let n = planes[c].0;
                if l.len() == next.len() && is_convex_loop(p, &l, n, dist_tol) {
                    loops.push(l);
                    continue;
                }
            }
        }
        grow_convex_faces(
            p,
            tris,
            twin,
            group,
            &cluster,
            planes[c].0,
            dist_tol,
            &mut loops,
        );
    }
    loops
}

/// The loop through a successor map, from its smallest vertex (deterministic whatever the hash
/// order); `None` if the map is empty or the walk breaks off. It may cover only part of the map.
fn walk_loop(next: &HashMap<usize, usize>) -> Option<Vec<usize>> {
    let start = next.keys().copied().min()?;
    let mut loop_ = vec![start];
    let mut u = *next.get(&start)?;
    while u != start {
        if loop_.len() > next.len() {
            return None;
        }
        loop_.push(u);
        u = *next.get(&u)?;
    }
    Some(loop_)
}

/// Whether the corner `i → j → k` turns left seen along `n`, or is straight within `tol`
/// (the distance of `j` inside the chord `ik`).
fn convex_corner(p: &[DVec3], i: usize, j: usize, k: usize, n: DVec3, tol: f64) -> bool {
    (p[j] - p[i]).cross(p[k] - p[j]).dot(n) >= -tol * p[k].distance(p[i])
}

fn is_convex_loop(p: &[DVec3], l: &[usize], n: DVec3, tol: f64) -> bool {
    (0..l.len()).all(|k| {
        let m = l.len();
        convex_corner(p, l[(k + m - 1) % m], l[k], l[(k + 1) % m], n, tol)
    })
}

/// Splits a cluster of near-coplanar triangles (`group`, by decreasing area) into convex faces,
/// growing each from its largest free triangle. A face grows across a boundary edge `u → v` by
/// the cluster triangle `(v, u, w)` when it stays a disk (`w` new to the loop: `u → w → v`; or
/// `w` the loop neighbour of `u` or `v`: the triangle fills a notch and `u` or `v` becomes
/// interior) and stays convex at the changed corners. Growth repeats until no edge admits its
/// neighbour; loops are walked from their smallest vertex so hash order never matters.
#[allow(clippy::too_many_arguments)]
fn grow_convex_faces(
    p: &[DVec3],
    tris: &[[usize; 3]],
    twin: &HashMap<(usize, usize), usize>,
    group: &[usize],
    cluster: &[usize],
    n: DVec3,
    tol: f64,
    loops: &mut Vec<Vec<usize>>,
) {
    let c = cluster[group[0]];
    let mut taken: HashMap<usize, bool> = group.iter().map(|&t| (t, false)).collect();
    let convex = |i: usize, j: usize, k: usize| convex_corner(p, i, j, k, n, tol);
    for &seed in group {
        if taken[&seed] {
            continue;
        }
        taken.insert(seed, true);
        let [a, b, c0] = tris[seed];
        let mut next: HashMap<usize, usize> = [(a, b), (b, c0), (c0, a)].into_iter().collect();
        let mut prev: HashMap<usize, usize> = [(b, a), (c0, b), (a, c0)].into_iter().collect();
        let mut grown = true;
        while grown {
            grown = false;
            let Some(loop_) = walk_loop(&next) else { break };
            for k in 0..loop_.len() {
                let (u, v) = (loop_[k], loop_[(k + 1) % loop_.len()]);
                if next.get(&u) != Some(&v) {
                    continue; // the edge went away with an earlier addition
                }
                let t = twin[&(v, u)];
                if cluster[t] != c || taken[&t] {
                    continue;
                }
                let Some(w) = tris[t].iter().copied().find(|&x| x != u && x != v) else {
                    continue;
                };
                let closes_at_v = next.get(&v) == Some(&w);
                let closes_at_u = prev.get(&u) == Some(&w);
                if closes_at_v && closes_at_u {
                    continue; // would close the surface
                } else if closes_at_v {
                    // … u → v → w … becomes … u → w …
                    if !convex(prev[&u], u, w) || !convex(u, w, next[&w]) {
                        continue;
                    }
                    next.remove(&v);
                    prev.remove(&v);
                    next.insert(u, w);
                    prev.insert(w, u);
                } else if closes_at_u {
                    // … w → u → v … becomes … w → v …
                    if !convex(prev[&w], w, v) || !convex(w, v, next[&v]) {
                        continue;
                    }
                    next.remove(&u);
                    prev.remove(&u);
                    next.insert(w, v);
                    prev.insert(v, w);
                } else if next.contains_key(&w) {
                    continue; // would pinch the face
                } else {
                    // … u → v … becomes … u → w → v …
                    if !convex(prev[&u], u, w) || !convex(u, w, v) || !convex(w, v, next[&v]) {
                        continue;
                    }
                    next.insert(u, w);
                    next.insert(w, v);
                    prev.insert(w, u);
                    prev.insert(v, w);
                }
                taken.insert(t, true);
                grown = true;
            }
        }
        if let Some(l) = walk_loop(&next) {
            loops.push(l);
        }
    }
}

/// Drops vertices that are corners of fewer than three faces, computes the mass properties,
/// moves everything to the body frame and checks the topology (closed 2-manifold, Euler) and the
/// geometry (planar, outward faces holding every input point). `loops` index `points`; errors
/// say what failed.
fn assemble(
    points: &[DVec3],
    mut loops: Vec<Vec<usize>>,
    size: f64,
) -> Result<(PolyhedronBuild, Vec<usize>), String> {
    let mut faces_of = HashMap::<usize, u32>::default();
    for l in &loops {
        for &v in l {
            *faces_of.entry(v).or_insert(0) += 1;
        }
    }
    for l in &mut loops {
        l.retain(|v| faces_of[v] >= 3);
        if l.len() < 3 {
            return Err(format!("a face is left with {} vertices", l.len()));
        }
    }
    let mut source: Vec<usize> = faces_of
        .iter()
        .filter(|&(_, &n)| n >= 3)
        .map(|(&v, _)| v)
        .collect();
    source.sort_unstable();
    let mut new_index = HashMap::with_capacity_and_hasher(source.len(), Default::default());
    for (k, &v) in source.iter().enumerate() {
        new_index.insert(v, k as u32);
    }
    let loops: Vec<Vec<u32>> = loops
        .iter()
        .map(|l| l.iter().map(|v| new_index[v]).collect())
        .collect();
    let input: Vec<DVec3> = source.iter().map(|&i| points[i]).collect();

    let mut triangles = Vec::new();
    for l in &loops {
        for k in 1..l.len() - 1 {
            triangles.push([l[0], l[k], l[k + 1]]);
        }
    }
    let mass = MassProperties::of_closed_mesh(&input, &triangles);
    if !(mass.volume > 0.0 && mass.volume.is_finite()) {
        return Err(format!("non-positive volume {:e}", mass.volume));
    }
    let (moments, orientation) = mass.principal();
    let to_body = DMat3::from_quat(orientation).transpose();
    let vertices: Vec<DVec3> = input.iter().map(|&x| to_body * (x - mass.center)).collect();

    // Edges: each undirected edge used once in each direction, by two different faces.
    let mut uses = HashMap::<[u32; 2], [Option<u32>; 2]>::default();
    for (f, l) in loops.iter().enumerate() {
        for k in 0..l.len() {
            let (u, v) = (l[k], l[(k + 1) % l.len()]);
            let slot =
                &mut uses.entry([u.min(v), u.max(v)]).or_insert([None, None])[usize::from(u > v)];
            if slot.replace(f as u32).is_some() {
                return Err(format!("edge {u}-{v} used twice in the same direction"));
            }
        }
    }
    let mut edge_list: Vec<([u32; 2], [Option<u32>; 2])> = uses.into_iter().collect();
    edge_list.sort_unstable_by_key(|e| e.0);
    let mut edges = Vec::with_capacity(edge_list.len());
    let mut edge_faces = Vec::with_capacity(edge_list.len());
    for (e, f) in edge_list {
        match f {
            [Some(f0), Some(f1)] if f0 != f1 => {
                edges.push(e);
                edge_faces.push([f0, f1]);
            }
            _ => return Err(format!("edge {}-{} is not shared by two faces", e[0], e[1])),
        }
    }
    let (nv, ne, nf) = (vertices.len(), edges.len(), loops.len());
    if nv + nf != ne + 2 {
        return Err(format!(
            "Euler characteristic V − E + F = {nv} − {ne} + {nf} ≠ 2"
        ));
    }

    // Newell normals (robust for polygons); offsets from the support function, so every vertex
    // satisfies n·x ≤ d exactly; a face whose own vertices sit below d is not a face.
    let tol = PLANAR_TOL * size;
    let mut face_normals = Vec::with_capacity(nf);
    let mut face_offsets = Vec::with_capacity(nf);
    for l in &loops {
        let c = l.iter().map(|&v| vertices[v as usize]).sum::<DVec3>() / l.len() as f64;
        let mut n = DVec3::ZERO;
        for k in 0..l.len() {
            let a = vertices[l[k] as usize] - c;
            let b = vertices[l[(k + 1) % l.len()] as usize] - c;
            n += a.cross(b);
        }
        let n = n.normalize_or_zero();
        if n == DVec3::ZERO {
            return Err("a face has zero area".into());
        }
        let d = vertices
            .iter()
            .map(|&x| n.dot(x))
            .fold(f64::NEG_INFINITY, f64::max);
        if l.iter().any(|&v| d - n.dot(vertices[v as usize]) > tol) || d <= 0.0 || d.is_nan() {
            return Err("a face is not planar or not a supporting plane".into());
        }
        face_normals.push(n);
        face_offsets.push(d);
    }
    // Every input point inside (to tolerance; the vertices are by construction of `d`): this
    // catches wrong hulls, e.g. parry's flat answer for thin sets, whatever their topology.
    let mut is_vertex = vec![false; points.len()];
    for &i in &source {
        is_vertex[i] = true;
    }
    for (_, &x) in points.iter().enumerate().filter(|&(i, _)| !is_vertex[i]) {
        let y = to_body * (x - mass.center);
        if let Some(f) = (0..nf).find(|&f| face_normals[f].dot(y) > face_offsets[f] + tol) {
            return Err(format!(
                "input point {x} lies {:e} m outside face {f}",
                face_normals[f].dot(y) - face_offsets[f]
            ));
        }
    }
    let mut face_start = Vec::with_capacity(nf + 1);
    let mut face_vertices = Vec::with_capacity(2 * ne);
    face_start.push(0);
    for l in &loops {
        face_vertices.extend_from_slice(l);
        face_start.push(face_vertices.len() as u32);
    }
    let radius = vertices.iter().map(|v| v.length()).fold(0.0f64, f64::max);
    let shape = ConvexPolyhedron {
        vertices,
        face_normals,
        face_offsets,
        face_start,
        face_vertices,
        edges,
        edge_faces,
        radius,
        volume: mass.volume,
        unit_inertia: moments,
    };
    Ok((
        PolyhedronBuild {
            shape,
            position: mass.center,
            orientation,
        },
        source,
    ))
}

/// Hash maps keyed by small integers: the standard SipHash dominated the build time, and the
/// iteration order of these maps never reaches the output.
type HashMap<K, V> = StdHashMap<K, V, BuildHasherDefault<FxHasher>>;

/// The Fx multiplicative hash (as in rustc), for integer keys.
#[derive(Clone, Copy, Default)]
struct FxHasher(u64);

impl FxHasher {
    #[inline]
    fn add(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.add(u64::from_le_bytes(word));
        }
    }
    #[inline]
    fn write_u64(&mut self, x: u64) {
        self.add(x);
    }
    #[inline]
    fn write_usize(&mut self, x: usize) {
        self.add(x as u64);
    }
    #[inline]
    fn write_u32(&mut self, x: u32) {
        self.add(u64::from(x));
    }
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
}
