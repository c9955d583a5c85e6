//! Compacity (solid volume fraction) of the grains in an axis-aligned control box, from exact
//! clipped volumes.
//!
//! # Mathematics
//!
//! The compacity of a box `B` is `C = Σᵢ |Pᵢ ∩ B| / |B|` over the selected grains `Pᵢ`. Each
//! `|P ∩ B|` is computed exactly (to rounding) for a convex polyhedron `P`:
//!
//! 1. `P ∩ B` is `P` clipped in turn by the six half-spaces of the box. Clipping a closed convex
//!    polyhedron, given as its face polygons, by a plane `δ(x) ≤ 0` keeps the part of each face
//!    with `δ ≤ 0` (Sutherland–Hodgman) and closes the solid with a *cap*: the convex polygon
//!    `P ∩ {δ = 0}`, whose vertices are the crossing points of the edges and the vertices lying
//!    on the plane (their convex hull, in the plane's coordinates).
//! 2. The volume of the closed polyhedral surface follows from the divergence theorem, as a sum
//!    of signed tetrahedra from a reference point `o`:
//!    `V = (1/6) Σ_faces Σ_fan (a − o)·((b − o) × (c − o))`.
//!
//! Exactness and robustness come from the box planes being axis-aligned: `δ` is a single
//! subtraction whose sign is exact, a crossing point is computed from the inside end of the edge
//! whichever face visits it (so the two faces sharing an edge get the same point, bit for bit)
//! and is snapped onto the plane. A plane that leaves no vertex strictly outside is skipped
//! (faces lying on a box face are kept, once); one that leaves no vertex strictly inside makes
//! the intersection empty (a grain touching the box from outside counts 0).
//!
//! Grains far from the box boundary are settled by their bounding sphere (`radius` about the
//! centre of mass) and then their bounding box: fully outside gives 0, fully inside gives the
//! grain's own `volume`.
//!
//! The volume shared by two overlapping grains (the small interpenetrations of contact
//! dynamics) is counted in both, so a packing with overlaps reads slightly high.

use ballast_engine::bodies::BodySet;
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::shapes::{ConvexPolyhedron, Shape};

/// Why a control box was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value}: {allowed}")]
pub struct CompacityError {
    /// The offending bound, e.g. `box_max.y`.
    pub field: String,
    /// Its value.
    pub value: String,
    /// What is allowed.
    pub allowed: String,
}

/// Volume of `shape ∩ box`, `shape` being placed at `position` (its centre of mass) with
/// `orientation` (body → world), the box `[box_min, box_max]` axis-aligned in the world frame.
///
/// Exact to rounding (see the [module documentation](self)). A box that is empty (some
/// `box_max ≤ box_min`) gives 0; infinite bounds are allowed (a slab, a half-space). A NaN bound
/// or a pose that is not finite gives NaN, so that a corrupted state is not read as an empty box.
pub fn clipped_volume(
    shape: &ConvexPolyhedron,
    position: DVec3,
    orientation: DQuat,
    box_min: DVec3,
    box_max: DVec3,
) -> f64 {
    if box_min.is_nan() || box_max.is_nan() || !position.is_finite() || !orientation.is_finite() {
        return f64::NAN;
    }
    if !box_min.cmplt(box_max).all() {
        return 0.0;
    }
    let r = shape.radius;
    if (position + r).cmple(box_min).any() || (position - r).cmpge(box_max).any() {
        return 0.0;
    }
    if (position - r).cmpge(box_min).all() && (position + r).cmple(box_max).all() {
        return shape.volume;
    }
    let world: Vec<DVec3> = shape
        .vertices
        .iter()
        .map(|&v| position + orientation * v)
        .collect();
    let (lo, hi) = world.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    if hi.cmple(box_min).any() || lo.cmpge(box_max).any() {
        return 0.0;
    }
    if lo.cmpge(box_min).all() && hi.cmple(box_max).all() {
        return shape.volume;
    }
    let faces: Vec<Vec<DVec3>> = (0..shape.num_faces())
        .map(|f| shape.face(f).iter().map(|&i| world[i as usize]).collect())
        .collect();
    match clip_to_box(faces, box_min, box_max) {
        Clipped::Empty => 0.0,
        Clipped::Unchanged => shape.volume,
        Clipped::Cut(faces) => surface_volume(&faces, position),
    }
}

/// Total volume of the selected polyhedral bodies inside the box `[box_min, box_max]`: the sum
/// of their [`clipped_volume`]s. Bodies `i` with `which(i)` false and half-space bodies are
/// ignored. The box is not validated (an empty box gives 0).
pub fn solid_volume(
    bodies: &BodySet,
    which: impl Fn(usize) -> bool,
    box_min: DVec3,
    box_max: DVec3,
) -> f64 {
    (0..bodies.len())
        .filter(|&i| which(i))
        .map(|i| match &bodies.shape[i] {
            Shape::Polyhedron(p) => clipped_volume(
                p,
                bodies.position[i],
                bodies.orientation[i],
                box_min,
                box_max,
            ),
            Shape::Plane { .. } => 0.0,
        })
        .sum()
}

/// Compacity (solid fraction) of the selected bodies in the box `[box_min, box_max]`:
/// [`solid_volume`] divided by the box volume.
///
/// # Errors
///
/// [`CompacityError`] naming the first bound that is not finite, or the upper bound of an axis
/// that is not greater than the lower one.
pub fn compacity(
    bodies: &BodySet,
    which: impl Fn(usize) -> bool,
    box_min: DVec3,
    box_max: DVec3,
) -> Result<f64, CompacityError> {
    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
        for (name, v) in [("box_min", box_min[k]), ("box_max", box_max[k])] {
            if !v.is_finite() {
                return Err(CompacityError {
                    field: format!("{name}.{axis}"),
                    value: v.to_string(),
                    allowed: "a finite coordinate (m)".into(),
                });
            }
        }
        if box_max[k] <= box_min[k] {
            return Err(CompacityError {
                field: format!("box_max.{axis}"),
                value: box_max[k].to_string(),
                allowed: format!("greater than box_min.{axis} = {}", box_min[k]),
            });
        }
    }
    let size = box_max - box_min;
    Ok(solid_volume(bodies, which, box_min, box_max) / (size.x * size.y * size.z))
}

/// One of the six box planes: outward normal `±e_axis`, signed distance
/// `δ(x) = x[axis] − bound` (upper) or `bound − x[axis]` (lower), positive outside.
#[derive(Clone, Copy, Debug)]
struct BoxPlane {
    axis: usize,
    upper: bool,
    bound: f64,
}

impl BoxPlane {
    /// Signed distance along the outward normal; its sign is exact (one rounded subtraction).
    #[inline]
    fn dist(&self, p: DVec3) -> f64 {
        if self.upper {
            p[self.axis] - self.bound
        } else {
            self.bound - p[self.axis]
        }
    }
}

/// Outcome of clipping a closed polyhedral surface by the box.
#[derive(Debug)]
enum Clipped {
    /// No box plane cuts the solid: it is inside the box (boundaries may touch).
    Unchanged,
    /// The faces of the clipped solid, caps included.
    Cut(Vec<Vec<DVec3>>),
    /// The intersection has no volume.
    Empty,
}

/// Clips the closed convex surface `faces` (polygons counter-clockwise seen from outside) by the
/// six half-spaces of the box.
fn clip_to_box(mut faces: Vec<Vec<DVec3>>, box_min: DVec3, box_max: DVec3) -> Clipped {
    let mut cut = false;
    for axis in 0..3 {
        for (upper, bound) in [(false, box_min[axis]), (true, box_max[axis])] {
            let plane = BoxPlane { axis, upper, bound };
            let vertices = || faces.iter().flatten();
            if !vertices().any(|&p| plane.dist(p) > 0.0) {
                continue;
            }
            if !vertices().any(|&p| plane.dist(p) < 0.0) {
                return Clipped::Empty;
            }
            faces = clip_by_plane(&faces, plane);
            cut = true;
        }
    }
    if cut {
        Clipped::Cut(faces)
    } else {
        Clipped::Unchanged
    }
}

/// Clips a closed convex surface that the plane strictly cuts (vertices strictly on both sides)
/// and closes it with the cap polygon.
fn clip_by_plane(faces: &[Vec<DVec3>], plane: BoxPlane) -> Vec<Vec<DVec3>> {
    let mut out = Vec::with_capacity(faces.len() + 1);
    let mut cap_points = Vec::new();
    for face in faces {
        let clipped = clip_polygon(face, plane, &mut cap_points);
        // Faces touching the plane along an edge or at a vertex leave 0–2 points: no area.
        if clipped.len() >= 3 {
            out.push(clipped);
        }
    }
    if let Some(cap) = cap_polygon(cap_points, plane) {
        out.push(cap);
    }
    out
}

/// Sutherland–Hodgman: the part of `poly` with `δ ≤ 0`, same winding. Vertices on the plane and
/// crossing points are also appended to `cap`.
fn clip_polygon(poly: &[DVec3], plane: BoxPlane, cap: &mut Vec<DVec3>) -> Vec<DVec3> {
    let n = poly.len();
    let mut out = Vec::with_capacity(n + 1);
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let (da, db) = (plane.dist(a), plane.dist(b));
        if da <= 0.0 {
            out.push(a);
            if da == 0.0 {
                cap.push(a);
            }
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            let p = crossing(a, da, b, db, plane);
            out.push(p);
            cap.push(p);
        }
    }
    out
}

/// The point where the edge `ab` (`δ` of strictly opposite signs) crosses the plane. Computed
/// from the inside end whichever way the edge is run, so the two faces sharing the edge get the
/// same point bit for bit, and snapped exactly onto the plane.
fn crossing(a: DVec3, da: f64, b: DVec3, db: f64, plane: BoxPlane) -> DVec3 {
    let (inside, di, outside, dout) = if da < 0.0 {
        (a, da, b, db)
    } else {
        (b, db, a, da)
    };
    let t = di / (di - dout);
    let mut p = inside + (outside - inside) * t;
    p[plane.axis] = plane.bound;
    p
}

/// The cap `P ∩ {δ = 0}` from its boundary points: their convex hull in the plane (Andrew's
/// monotone chain, collinear points dropped), counter-clockwise seen along the outward normal.
/// `None` when the points span no area.
fn cap_polygon(mut points: Vec<DVec3>, plane: BoxPlane) -> Option<Vec<DVec3>> {
    // (u, v, normal) is right-handed, so counter-clockwise in (u, v) is counter-clockwise seen
    // from +e_axis.
    let (u, v) = ((plane.axis + 1) % 3, (plane.axis + 2) % 3);
    points.sort_by(|p, q| p[u].total_cmp(&q[u]).then(p[v].total_cmp(&q[v])));
    points.dedup_by(|p, q| p[u] == q[u] && p[v] == q[v]);
    if points.len() < 3 {
        return None;
    }
    let turn = |o: DVec3, a: DVec3, b: DVec3| {
        (a[u] - o[u]) * (b[v] - o[v]) - (a[v] - o[v]) * (b[u] - o[u])
    };
    let mut hull: Vec<DVec3> = Vec::with_capacity(points.len() + 1);
    // Lower chain left to right, then upper chain right to left, each keeping left turns only.
    for &p in &points {
        while hull.len() >= 2 && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in points.iter().rev().skip(1) {
        while hull.len() >= lower && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop(); // the first point, reached again by the upper chain
    if hull.len() < 3 {
        return None;
    }
    if !plane.upper {
        hull.reverse();
    }
    Some(hull)
}

/// Volume enclosed by a closed surface of polygons wound counter-clockwise seen from outside:
/// signed tetrahedra from `o` (a point near the solid, for conditioning).
fn surface_volume(faces: &[Vec<DVec3>], o: DVec3) -> f64 {
    let mut six_v = 0.0;
    for face in faces {
        let a = face[0] - o;
        for k in 1..face.len() - 1 {
            six_v += a.dot((face[k] - o).cross(face[k + 1] - o));
        }
    }
    six_v / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballast_engine::bodies::BodyKind;
    use ballast_engine::random_rotation;
    use ballast_engine::shapes::random::{random_grain, GrainParams};
    use ballast_engine::shapes::PolyhedronBuild;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn unit_cube() -> ConvexPolyhedron {
        ConvexPolyhedron::cuboid(DVec3::splat(0.5)).unwrap().shape
    }

    /// A random grain of equivalent diameter 40 mm with a random orientation.
    fn grain(seed: u64) -> (ConvexPolyhedron, DQuat) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let PolyhedronBuild { shape, .. } =
            random_grain(&mut rng, &GrainParams::default(), 0.04).unwrap();
        (shape, random_rotation(&mut rng))
    }

    fn world_aabb(shape: &ConvexPolyhedron, pos: DVec3, q: DQuat) -> (DVec3, DVec3) {
        shape.vertices.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &v| (lo.min(pos + q * v), hi.max(pos + q * v)),
        )
    }

    #[test]
    fn cube_half_inside_gives_exactly_half() {
        let cube = unit_cube();
        let v = clipped_volume(
            &cube,
            DVec3::new(1.0, 0.5, 0.5),
            DQuat::IDENTITY,
            DVec3::ZERO,
            DVec3::ONE,
        );
        assert_eq!(v, 0.5);
        // Cut on three axes at once: a 0.25 × 0.5 × 0.75 corner.
        let v = clipped_volume(
            &cube,
            DVec3::new(0.75, 0.5, 0.25),
            DQuat::IDENTITY,
            DVec3::new(-5.0, -5.0, -5.0),
            DVec3::new(0.5, 0.5, 0.5),
        );
        assert_eq!(v, 0.25 * 0.5 * 0.75);
    }

    #[test]
    fn cube_inside_or_touching() {
        let cube = unit_cube();
        let at = |p: DVec3, lo: DVec3, hi: DVec3| clipped_volume(&cube, p, DQuat::IDENTITY, lo, hi);
        let half = DVec3::splat(0.5);
        // Fully inside; equal to the box; touching the box from outside by a face, an edge, a
        // vertex; empty boxes.
        assert_eq!(at(half, DVec3::splat(-1.0), DVec3::splat(2.0)), cube.volume);
        assert_eq!(at(half, DVec3::ZERO, DVec3::ONE), cube.volume);
        assert_eq!(at(DVec3::new(1.5, 0.5, 0.5), DVec3::ZERO, DVec3::ONE), 0.0);
        assert_eq!(at(DVec3::new(1.5, 1.5, 0.5), DVec3::ZERO, DVec3::ONE), 0.0);
        assert_eq!(at(DVec3::splat(1.5), DVec3::ZERO, DVec3::ONE), 0.0);
        assert_eq!(at(half, DVec3::ONE, DVec3::ZERO), 0.0);
        // Infinite bounds: the slab 0 ≤ z ≤ 0.25 holds a quarter.
        let inf = f64::INFINITY;
        let v = at(
            half,
            DVec3::new(-inf, -inf, 0.0),
            DVec3::new(inf, inf, 0.25),
        );
        assert_eq!(v, 0.25);
        // Non-finite input reads NaN.
        assert!(at(half, DVec3::ZERO, DVec3::new(1.0, f64::NAN, 1.0)).is_nan());
        assert!(at(DVec3::new(0.5, 0.5, f64::NAN), DVec3::ZERO, DVec3::ONE).is_nan());
        let nan_q = DQuat::from_xyzw(f64::NAN, 0.0, 0.0, 1.0);
        assert!(clipped_volume(&cube, half, nan_q, DVec3::ZERO, DVec3::ONE).is_nan());
        // A thin box slicing the cube: a 1 × 1 × 0.1 slab.
        let v = at(half, DVec3::new(-1.0, -1.0, 0.3), DVec3::new(2.0, 2.0, 0.4));
        assert!((v - 0.1).abs() < 1e-15, "{v}");
    }

    #[test]
    fn cube_rotated_45_degrees_straddling_a_face() {
        // Cross-section |x'| + |y'| ≤ √2/2 over the unit height. The plane x' = a cuts off the
        // triangle x' > a, of area h² with h = √2/2 − a, when a ≥ 0, and keeps the triangle
        // x' < a, of area (√2/2 + a)², when a ≤ 0.
        let cube = unit_cube();
        let q = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        for a in [-0.6, -0.3, 0.0, 0.2, 0.5, 0.7] {
            let r = std::f64::consts::FRAC_1_SQRT_2;
            let want = if a >= 0.0 {
                1.0 - (r - a) * (r - a)
            } else {
                (r + a) * (r + a)
            };
            let v = clipped_volume(
                &cube,
                DVec3::ZERO,
                q,
                DVec3::new(-5.0, -5.0, -0.5),
                DVec3::new(a, 5.0, 0.5),
            );
            assert!((v - want).abs() < 1e-14, "a = {a}: {v} vs {want}");
        }
    }

    #[test]
    fn uncut_surfaces_recover_the_polyhedron_volume() {
        for seed in 0..20 {
            let (shape, q) = grain(seed);
            let pos = DVec3::new(0.3, -1.2, 2.0);
            let faces: Vec<Vec<DVec3>> = (0..shape.num_faces())
                .map(|f| {
                    shape
                        .face(f)
                        .iter()
                        .map(|&i| pos + q * shape.vertices[i as usize])
                        .collect()
                })
                .collect();
            let v = surface_volume(&faces, pos);
            assert!((v - shape.volume).abs() <= 1e-12 * shape.volume, "{v}");
            // A containing box touching the grain's extreme vertices cuts nothing.
            let (lo, hi) = world_aabb(&shape, pos, q);
            assert!(matches!(clip_to_box(faces, lo, hi), Clipped::Unchanged));
            assert_eq!(clipped_volume(&shape, pos, q, lo, hi), shape.volume);
        }
    }

    #[test]
    fn clipped_volume_agrees_with_monte_carlo() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for seed in 0..4 {
            let (shape, q) = grain(100 + seed);
            let pos = DVec3::new(1.0, 2.0, 3.0);
            let (lo, hi) = world_aabb(&shape, pos, q);
            // A box covering a random part of the grain's bounding box.
            let cut = DVec3::new(rng.gen(), rng.gen(), rng.gen());
            let box_min = lo + (hi - lo) * cut * 0.5;
            let box_max = hi - (hi - lo) * DVec3::new(rng.gen(), rng.gen(), rng.gen()) * 0.3;
            let exact = clipped_volume(&shape, pos, q, box_min, box_max);
            let n = 200_000;
            let inv = q.inverse();
            let hits = (0..n)
                .filter(|_| {
                    let p =
                        box_min + (box_max - box_min) * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                    let y = inv * (p - pos);
                    (0..shape.num_faces())
                        .all(|f| shape.face_normals[f].dot(y) <= shape.face_offsets[f])
                })
                .count();
            let size = box_max - box_min;
            let frac = hits as f64 / n as f64;
            let estimate = frac * size.x * size.y * size.z;
            let sigma = (frac * (1.0 - frac) / n as f64).sqrt() * size.x * size.y * size.z;
            assert!(exact > 0.0 && exact < shape.volume);
            assert!(
                (estimate - exact).abs() < 4.0 * sigma + 1e-12,
                "seed {seed}: exact {exact:e}, Monte Carlo {estimate:e} ± {sigma:e}"
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 64,
            rng_seed: proptest::test_runner::RngSeed::Fixed(0x0c7a_17e5),
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        /// The eight octants of a box around the grain, split at any point inside it, share
        /// the grain's volume to 1e-12.
        #[test]
        fn octants_sum_to_the_whole(
            seed in 0u64..1_000_000,
            t in prop::array::uniform3(0.02f64..0.98),
        ) {
            let (shape, q) = grain(seed);
            let pos = DVec3::new(-0.7, 0.1, 0.25);
            let (lo, hi) = world_aabb(&shape, pos, q);
            let split = lo + (hi - lo) * DVec3::from_array(t);
            let total = octant_sum(&shape, pos, q, split);
            prop_assert!(
                (total - shape.volume).abs() <= 1e-12 * shape.volume,
                "octants {total:e} vs volume {:e}",
                shape.volume
            );
        }
    }

    /// Sum of the clipped volumes in the eight octants around `split` of a box holding the grain.
    fn octant_sum(shape: &ConvexPolyhedron, pos: DVec3, q: DQuat, split: DVec3) -> f64 {
        let (lo, hi) = world_aabb(shape, pos, q);
        let (lo, hi) = (lo - 0.01, hi + 0.01);
        let mut total = 0.0;
        for k in 0..8 {
            let side = |bit: usize| k >> bit & 1 == 1;
            let corner = |upper: bool| {
                DVec3::from_array(std::array::from_fn(|a| match (side(a), upper) {
                    (false, false) => lo[a],
                    (false, true) | (true, false) => split[a],
                    (true, true) => hi[a],
                }))
            };
            let v = clipped_volume(shape, pos, q, corner(false), corner(true));
            assert!(v >= 0.0, "octant {k}: {v}");
            total += v;
        }
        total
    }

    /// Degenerate cuts: the three splitting planes through a vertex of the grain.
    #[test]
    fn octants_split_at_a_vertex_sum_to_the_whole() {
        for seed in 0..10 {
            let (shape, q) = grain(500 + seed);
            let pos = DVec3::new(0.2, 0.3, -0.4);
            for v in shape.vertices.iter().step_by(3) {
                let total = octant_sum(&shape, pos, q, pos + q * *v);
                assert!(
                    (total - shape.volume).abs() <= 1e-12 * shape.volume,
                    "seed {seed}: {total:e} vs {:e}",
                    shape.volume
                );
            }
        }
    }

    #[test]
    fn compacity_of_a_lattice_of_cubes() {
        let mut bodies = BodySet::default();
        for i in 0..8 {
            let c = DVec3::new(
                (i & 1) as f64 + 0.5,
                (i >> 1 & 1) as f64 + 0.5,
                (i >> 2 & 1) as f64 + 0.5,
            );
            let mut b = ConvexPolyhedron::cuboid(DVec3::splat(0.5)).unwrap();
            b.position = c;
            bodies.add_polyhedron(b, 2700.0, BodyKind::Dynamic, 0);
        }
        bodies.add_plane(DVec3::ZERO, DVec3::Z, 1);
        let all = |_: usize| true;
        let c = compacity(&bodies, all, DVec3::splat(0.5), DVec3::splat(1.5)).unwrap();
        assert!((c - 1.0).abs() < 1e-15, "{c}");
        let c = compacity(&bodies, all, DVec3::ZERO, DVec3::splat(4.0)).unwrap();
        assert_eq!(c, 8.0 / 64.0);
        // Only the bottom layer (bodies 0–3), all inside a box of volume 6.
        let c = compacity(&bodies, |i| i < 4, DVec3::ZERO, DVec3::new(2.0, 2.0, 1.5)).unwrap();
        assert!((c - 4.0 / 6.0).abs() < 1e-15, "{c}");
        let solid = solid_volume(
            &bodies,
            all,
            DVec3::new(0.25, 0.0, 0.0),
            DVec3::new(1.0, 2.0, 2.0),
        );
        assert!((solid - 3.0).abs() < 1e-14, "{solid}");
    }

    #[test]
    fn invalid_control_boxes_are_refused() {
        let bodies = BodySet::default();
        let e = compacity(&bodies, |_| true, DVec3::ZERO, DVec3::new(1.0, 0.0, 1.0)).unwrap_err();
        assert_eq!(e.to_string(), "box_max.y = 0: greater than box_min.y = 0");
        let e = compacity(
            &bodies,
            |_| true,
            DVec3::new(0.0, 0.0, f64::NAN),
            DVec3::ONE,
        )
        .unwrap_err();
        assert_eq!(e.field, "box_min.z");
        assert_eq!(
            compacity(&bodies, |_| true, DVec3::ZERO, DVec3::ONE),
            Ok(0.0)
        );
    }
}
