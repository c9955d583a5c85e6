//! Shapes: exact mass properties, hull building, face merging, errors and random grains.

use ballast_engine::math::{DMat3, DQuat, DVec3};
use ballast_engine::shapes::mass::symmetric_eigen;
use ballast_engine::shapes::random::{equivalent_diameter, random_grain, GrainParams};
use ballast_engine::shapes::{ConvexPolyhedron, MassProperties, PolyhedronBuild, ShapeError};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// ---------------------------------------------------------------------------------------------
// Helpers

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
}

fn assert_close(a: f64, b: f64, rel: f64, what: &str) {
    assert!(close(a, b, rel), "{what}: {a} vs {b} (rel {rel:e})");
}

fn assert_vec_close(a: DVec3, b: DVec3, tol: f64, what: &str) {
    assert!((a - b).length() <= tol, "{what}: {a} vs {b} (tol {tol:e})");
}

fn assert_mat_close(a: DMat3, b: DMat3, tol: f64, what: &str) {
    let d = (a - b)
        .to_cols_array()
        .iter()
        .map(|x| x.abs())
        .fold(0.0, f64::max);
    assert!(d <= tol, "{what}: max diff {d:e} > {tol:e}\n{a}\n{b}");
}

/// Ascending, where rounding-level (1e-12 relative) ties may keep their input order.
fn assert_ascending(v: DVec3) {
    let tie = 1e-12 * v.abs().max_element();
    assert!(v.x <= v.y + tie && v.y <= v.z + tie, "not ascending: {v}");
}

/// Corners of the box `[lo, hi]` (bit `k` of the index picks `hi` along axis `k`).
fn box_corners(lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect()
}

/// Outward triangles of [`box_corners`].
fn box_triangles() -> Vec<[u32; 3]> {
    vec![
        [0, 2, 1],
        [1, 2, 3], // z = lo
        [4, 5, 6],
        [5, 7, 6], // z = hi
        [0, 1, 4],
        [1, 5, 4], // y = lo
        [2, 6, 3],
        [3, 6, 7], // y = hi
        [0, 4, 2],
        [2, 4, 6], // x = lo
        [1, 3, 5],
        [3, 7, 5], // x = hi
    ]
}

fn random_rotation(rng: &mut impl Rng) -> DQuat {
    let q = DQuat::from_xyzw(
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
    );
    if q.length() < 1e-3 {
        DQuat::IDENTITY
    } else {
        q.normalize()
    }
}

/// Full inertia tensor of a built shape, in the input frame.
fn input_frame_inertia(b: &PolyhedronBuild) -> DMat3 {
    let r = DMat3::from_quat(b.orientation);
    r * DMat3::from_diagonal(b.shape.unit_inertia) * r.transpose()
}

/// Every structural and geometric invariant of a built polyhedron.
fn check_polyhedron(s: &ConvexPolyhedron) {
    let size = 2.0 * s.radius;
    let nv = s.vertices.len();
    let nf = s.num_faces();
    let ne = s.edges.len();
    assert!(nv >= 4 && nf >= 4 && ne >= 6, "V={nv} E={ne} F={nf}");
    assert_eq!(
        nv as i64 - ne as i64 + nf as i64,
        2,
        "Euler: V={nv} E={ne} F={nf}"
    );
    assert_eq!(s.face_start.len(), nf + 1);
    assert_eq!(s.face_offsets.len(), nf);
    assert_eq!(s.edge_faces.len(), ne);
    assert_eq!(
        *s.face_start.last().unwrap() as usize,
        s.face_vertices.len()
    );
    assert_eq!(
        s.face_vertices.len(),
        2 * ne,
        "each edge bounds two face loops"
    );

    // Faces: unit outward normals, planar loops of ≥ 3 distinct vertices, CCW seen from outside.
    let mut faces_of_vertex = vec![0; nv];
    for f in 0..nf {
        let n = s.face_normals[f];
        let d = s.face_offsets[f];
        assert!((n.length() - 1.0).abs() < 1e-12, "face {f} normal not unit");
        assert!(d > 0.0, "centre of mass not strictly inside face {f}");
        let l = s.face(f);
        assert!(l.len() >= 3, "face {f} has {} vertices", l.len());
        let mut sorted = l.to_vec();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), l.len(), "face {f} repeats a vertex");
        for &v in l {
            faces_of_vertex[v as usize] += 1;
            // Merging accepts facets within 1e-9 of the extent of a plane; the polyhedron
            // promises 1e-8 (rounding level for exactly coplanar input).
            let dist = d - n.dot(s.vertices[v as usize]);
            assert!(
                dist.abs() <= 1e-8 * size,
                "face {f} vertex {v} off plane by {dist:e}"
            );
        }
        for (v, x) in s.vertices.iter().enumerate() {
            assert!(n.dot(*x) <= d + 1e-12 * size, "vertex {v} outside face {f}");
        }
        let c = l.iter().map(|&v| s.vertices[v as usize]).sum::<DVec3>() / l.len() as f64;
        let mut newell = DVec3::ZERO;
        for k in 0..l.len() {
            let a = s.vertices[l[k] as usize] - c;
            let b = s.vertices[l[(k + 1) % l.len()] as usize] - c;
            newell += a.cross(b);
        }
        assert!(
            newell.normalize().dot(n) > 1.0 - 1e-9,
            "face {f} loop not CCW"
        );
        // Convex loop: every turn is to the left around the outward normal, or straight to
        // rounding (a corner of three faces may sit on a straight side of a fourth).
        for k in 0..l.len() {
            let a = s.vertices[l[k] as usize];
            let b = s.vertices[l[(k + 1) % l.len()] as usize];
            let e = s.vertices[l[(k + 2) % l.len()] as usize];
            let turn = (b - a).cross(e - b).dot(n);
            assert!(
                turn >= -1e-9 * size * a.distance(e),
                "face {f} not convex at {k}: {turn:e}"
            );
        }
    }
    assert!(
        faces_of_vertex.iter().all(|&k| k >= 3),
        "a vertex is a corner of fewer than 3 faces"
    );

    // Edges: sorted unique pairs a < b, two distinct faces running them in opposite directions.
    for w in s.edges.windows(2) {
        assert!(w[0] < w[1], "edges not sorted/unique");
    }
    let runs = |f: u32, a: u32, b: u32| {
        let l = s.face(f as usize);
        (0..l.len()).any(|k| l[k] == a && l[(k + 1) % l.len()] == b)
    };
    for (e, (&[a, b], &[f0, f1])) in s.edges.iter().zip(&s.edge_faces).enumerate() {
        assert!(a < b, "edge {e} not ordered");
        assert_ne!(f0, f1, "edge {e} has one face twice");
        assert!(
            runs(f0, a, b) && runs(f1, b, a),
            "edge {e} face orientation"
        );
    }

    // Body frame: the stored quantities match the geometry.
    let radius = s.vertices.iter().map(|v| v.length()).fold(0.0, f64::max);
    assert_eq!(radius, s.radius);
    let m = MassProperties::of_closed_mesh(&s.vertices, &s.triangles());
    // Moving the vertices to the body frame rounds them by ~1e-16·size, which moves the volume
    // by ~1e-16·size³: relatively large for slivers.
    let dv = (m.volume - s.volume).abs();
    assert!(
        dv <= 1e-12 * s.volume + 1e-14 * size.powi(3),
        "volume {} vs {}",
        m.volume,
        s.volume
    );
    assert!(
        m.center.length() <= 1e-12 * size,
        "centre of mass {} not at origin",
        m.center
    );
    let scale = s.unit_inertia.max_element();
    assert_mat_close(
        m.inertia,
        DMat3::from_diagonal(s.unit_inertia),
        1e-10 * scale,
        "inertia not diagonal in the body frame",
    );
    assert_ascending(s.unit_inertia);
}

// ---------------------------------------------------------------------------------------------
// Mass properties

#[test]
fn unit_cube_mass_properties() {
    let v = box_corners(DVec3::ZERO, DVec3::ONE);
    let m = MassProperties::of_closed_mesh(&v, &box_triangles());
    assert_close(m.volume, 1.0, 1e-15, "volume");
    assert_vec_close(m.center, DVec3::splat(0.5), 1e-15, "centre");
    assert_mat_close(
        m.inertia,
        DMat3::from_diagonal(DVec3::splat(1.0 / 6.0)),
        1e-15,
        "J",
    );
}

#[test]
fn box_inertia_is_analytic() {
    let (a, b, c) = (0.3, 1.7, 2.9);
    let lo = DVec3::new(-4.0, 2.0, 10.0);
    let v = box_corners(lo, lo + DVec3::new(a, b, c));
    let m = MassProperties::of_closed_mesh(&v, &box_triangles());
    let vol = a * b * c;
    assert_close(m.volume, vol, 1e-13, "volume");
    assert_vec_close(m.center, lo + DVec3::new(a, b, c) / 2.0, 1e-13, "centre");
    let expect = DVec3::new(b * b + c * c, a * a + c * c, a * a + b * b) * vol / 12.0;
    assert_mat_close(m.inertia, DMat3::from_diagonal(expect), 1e-12, "J");

    // The same box through the hull: moments ascending, volume exact.
    let built = ConvexPolyhedron::cuboid(DVec3::new(a, b, c) / 2.0).unwrap();
    let mut sorted = expect.to_array();
    sorted.sort_by(f64::total_cmp);
    assert_vec_close(
        built.shape.unit_inertia,
        DVec3::from(sorted),
        1e-12,
        "moments",
    );
    assert_close(built.shape.volume, vol, 1e-13, "volume");
    check_polyhedron(&built.shape);
}

#[test]
fn inward_winding_gives_negative_volume() {
    let v = box_corners(DVec3::ZERO, DVec3::ONE);
    let tris: Vec<[u32; 3]> = box_triangles().iter().map(|t| [t[0], t[2], t[1]]).collect();
    let m = MassProperties::of_closed_mesh(&v, &tris);
    assert_close(m.volume, -1.0, 1e-15, "volume");
    assert_vec_close(m.center, DVec3::splat(0.5), 1e-15, "centre");
}

#[test]
fn regular_tetrahedron() {
    // Edge 2√2: volume a³/(6√2) = 8/3, isotropic inertia V a²/20 = 16/15 per unit density.
    let pts = [
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(1.0, -1.0, -1.0),
        DVec3::new(-1.0, 1.0, -1.0),
        DVec3::new(-1.0, -1.0, 1.0),
    ];
    let m = MassProperties::of_closed_mesh(&pts, &[[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]);
    assert_close(m.volume, 8.0 / 3.0, 1e-15, "volume");
    assert_vec_close(m.center, DVec3::ZERO, 1e-15, "centre");
    assert_mat_close(
        m.inertia,
        DMat3::from_diagonal(DVec3::splat(16.0 / 15.0)),
        1e-14,
        "J",
    );

    let b = ConvexPolyhedron::from_points(&pts).unwrap();
    check_polyhedron(&b.shape);
    assert_eq!(
        (
            b.shape.vertices.len(),
            b.shape.num_faces(),
            b.shape.edges.len()
        ),
        (4, 4, 6)
    );
    assert_close(b.shape.volume, 8.0 / 3.0, 1e-14, "volume");
    assert_vec_close(
        b.shape.unit_inertia,
        DVec3::splat(16.0 / 15.0),
        1e-13,
        "moments",
    );
    assert_close(b.shape.radius, 3f64.sqrt(), 1e-14, "radius");
}

#[test]
fn symmetric_eigen_reconstructs() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for case in 0..200 {
        let q = random_rotation(&mut rng);
        let mut d = DVec3::new(rng.gen(), rng.gen(), rng.gen());
        match case % 4 {
            1 => d.y = d.x, // a repeated eigenvalue
            2 => d = DVec3::splat(d.x),
            _ => {}
        }
        let r0 = DMat3::from_quat(q);
        let a = r0 * DMat3::from_diagonal(d) * r0.transpose();
        let (values, r) = symmetric_eigen(&a);
        assert_ascending(values);
        assert_close(r.determinant(), 1.0, 1e-14, "det");
        assert_mat_close(r.transpose() * r, DMat3::IDENTITY, 1e-14, "orthonormal");
        assert_mat_close(r * DMat3::from_diagonal(values), a * r, 1e-14, "A R = R Λ");
        let mut sorted = d.to_array();
        sorted.sort_by(f64::total_cmp);
        assert_vec_close(values, DVec3::from(sorted), 1e-14, "eigenvalues");
        // Deterministic: same input, same bits.
        assert_eq!(symmetric_eigen(&a), (values, r));
    }
}

#[test]
fn mass_properties_principal_frame() {
    let v = box_corners(DVec3::ZERO, DVec3::new(1.0, 2.0, 3.0));
    let m = MassProperties::of_closed_mesh(&v, &box_triangles());
    let (moments, q) = m.principal();
    let r = DMat3::from_quat(q);
    assert_mat_close(
        r * DMat3::from_diagonal(moments) * r.transpose(),
        m.inertia,
        1e-13,
        "J",
    );
    // Smallest moment about the longest side (z).
    assert_close(r.x_axis.z.abs(), 1.0, 1e-14, "long axis");
}

// ---------------------------------------------------------------------------------------------
// Hull building

#[test]
fn translated_rotated_box_recovers_pose() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // Grain-sized, where inertia tensors are ~1e-9 per unit density.
    let h = DVec3::new(0.01, 0.02, 0.03);
    let vol = 8.0 * h.x * h.y * h.z;
    let s = 2.0 * h;
    // Ascending moments: about z (longest side) first.
    let expect = DVec3::new(
        s.x * s.x + s.y * s.y,
        s.x * s.x + s.z * s.z,
        s.y * s.y + s.z * s.z,
    ) * vol
        / 12.0;
    for _ in 0..50 {
        let q0 = random_rotation(&mut rng);
        let p0 = DVec3::new(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0), 3.0);
        let pts: Vec<DVec3> = box_corners(-h, h).iter().map(|&c| p0 + q0 * c).collect();
        let b = ConvexPolyhedron::from_points(&pts).unwrap();
        check_polyhedron(&b.shape);
        assert_eq!(b.shape.num_faces(), 6);
        assert_vec_close(b.position, p0, 1e-13, "position");
        assert_close(b.shape.volume, vol, 1e-12, "volume");
        assert_vec_close(b.shape.unit_inertia, expect, 1e-12 * expect.z, "moments");
        // Body x, y, z ↔ box z, y, x, up to sign.
        let (rb, r0) = (DMat3::from_quat(b.orientation), DMat3::from_quat(q0));
        assert_close(rb.x_axis.dot(r0.z_axis).abs(), 1.0, 1e-12, "x ↔ z");
        assert_close(rb.y_axis.dot(r0.y_axis).abs(), 1.0, 1e-12, "y ↔ y");
        assert_close(rb.z_axis.dot(r0.x_axis).abs(), 1.0, 1e-12, "z ↔ x");
        // Every body vertex maps back onto an input corner.
        for v in &b.shape.vertices {
            let x = b.position + b.orientation * *v;
            assert!(
                pts.iter().any(|p| p.distance(x) < 1e-13),
                "vertex {x} not a corner"
            );
        }
    }
}

#[test]
fn agrees_with_parry_mass_properties() {
    use parry3d_f64::mass_properties::details::tetrahedron_unit_inertia_tensor_wrt_point;
    use parry3d_f64::mass_properties::MassProperties as ParryMass;
    use parry3d_f64::shape::{ConvexPolyhedron as ParryPoly, Shape};
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for case in 0..100 {
        let n = rng.gen_range(4..60);
        let scale = 10f64.powf(rng.gen_range(-2.0..1.0));
        let offset = DVec3::new(rng.gen(), rng.gen(), rng.gen()) * 3.0 * scale;
        let pts: Vec<DVec3> = (0..n)
            .map(|_| offset + DVec3::new(rng.gen(), rng.gen(), rng.gen()) * scale)
            .collect();
        let Ok(b) = ConvexPolyhedron::from_points(&pts) else {
            continue; // a rare flat sample of 4 points
        };
        check_polyhedron(&b.shape);
        let poly = ParryPoly::from_convex_hull(&pts).expect("parry hull");
        let parry = poly.mass_properties(1.0);
        assert_close(b.shape.volume, parry.mass(), 1e-9, "volume");
        assert_vec_close(b.position, parry.local_com, 1e-9 * scale, "centre");
        let mut moments = parry.principal_inertia().to_array();
        moments.sort_by(f64::total_cmp);
        let tol = 1e-9 * b.shape.unit_inertia.z;
        assert_vec_close(b.shape.unit_inertia, DVec3::from(moments), tol, "moments");
        // parry's principal *frame* is unreliable for small bodies (glamx's 3×3 eigen solver
        // has an absolute 1e-20 threshold), so compare full tensors assembled from parry's
        // per-tetrahedron formula, exactly as its `from_trimesh` does before diagonalising.
        let parry_tensor = |v: &[DVec3], t: &[[u32; 3]], com: DVec3| {
            t.iter().fold(DMat3::ZERO, |acc, t| {
                let [a, b, c] = t.map(|i| v[i as usize]);
                let vol = (a - com).dot((b - com).cross(c - com)) / 6.0;
                acc + tetrahedron_unit_inertia_tensor_wrt_point(com, com, a, b, c) * vol
            })
        };
        let jp = parry_tensor(poly.points(), &poly.to_trimesh().1, parry.local_com);
        let j = input_frame_inertia(&b);
        assert_mat_close(j, jp, tol, &format!("inertia, case {case}"));

        // Raw mesh formula against parry's on the same triangles.
        let (hv, ht) = parry3d_f64::transformation::try_convex_hull(&pts).unwrap();
        let ours = MassProperties::of_closed_mesh(&hv, &ht);
        let theirs = ParryMass::from_convex_polyhedron(1.0, &hv, &ht);
        assert_close(ours.volume, theirs.mass(), 1e-9, "mesh volume");
        assert_vec_close(ours.center, theirs.local_com, 1e-9 * scale, "mesh centre");
        assert_mat_close(
            ours.inertia,
            parry_tensor(&hv, &ht, theirs.local_com),
            tol,
            "mesh J",
        );
    }
}

#[test]
fn cube_merges_to_six_quads() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for k in 0..50 {
        let q = if k == 0 {
            DQuat::IDENTITY
        } else {
            random_rotation(&mut rng)
        };
        let p = DVec3::new(rng.gen(), rng.gen(), rng.gen());
        let mut pts: Vec<DVec3> = box_corners(-DVec3::ONE, DVec3::ONE);
        // Extra points inside faces, on edges and inside: none may survive.
        pts.extend([
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.3, -1.0, 0.2),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(-1.0, 0.25, -1.0),
            DVec3::new(0.1, 0.2, 0.3),
        ]);
        let pts: Vec<DVec3> = pts.iter().map(|&x| p + q * (0.1 * x)).collect();
        let b = ConvexPolyhedron::from_points(&pts).unwrap();
        let s = &b.shape;
        check_polyhedron(s);
        assert_eq!(s.vertices.len(), 8);
        assert_eq!(s.edges.len(), 12);
        assert_eq!(s.num_faces(), 6);
        assert!((0..6).all(|f| s.face(f).len() == 4));
        assert_eq!(s.triangles().len(), 12);
        assert_close(s.volume, 8e-3, 1e-12, "volume");
        assert_close(s.radius, 0.1 * 3f64.sqrt(), 1e-12, "radius");
        if k == 0 {
            // A cube keeps the input axes: identity orientation, axis-aligned normals.
            assert_eq!(b.orientation, DQuat::IDENTITY);
            assert!(s.face_normals.iter().all(|n| n.abs().max_element() == 1.0));
        }
    }
}

#[test]
fn hexagonal_prism_has_eight_faces() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for k in 0..20 {
        let q = if k == 0 {
            DQuat::IDENTITY
        } else {
            random_rotation(&mut rng)
        };
        let mut pts = Vec::new();
        for i in 0..6 {
            let a = i as f64 * std::f64::consts::FRAC_PI_3;
            for z in [-0.02, 0.03] {
                pts.push(q * DVec3::new(0.04 * a.cos(), 0.04 * a.sin(), z));
            }
        }
        let b = ConvexPolyhedron::from_points(&pts).unwrap();
        let s = &b.shape;
        check_polyhedron(s);
        assert_eq!(
            (s.vertices.len(), s.edges.len(), s.num_faces()),
            (12, 18, 8)
        );
        let mut sizes: Vec<usize> = (0..8).map(|f| s.face(f).len()).collect();
        sizes.sort_unstable();
        assert_eq!(sizes, [4, 4, 4, 4, 4, 4, 6, 6]);
        let area = 1.5 * 3f64.sqrt() * 0.04f64.powi(2);
        assert_close(s.volume, area * 0.05, 1e-12, "volume");
    }
}

#[test]
fn thin_plates_are_not_flattened() {
    // parry's hull flattens sets thinner than ~3e-4 of their diagonal; ours must not.
    for t in [1e-2, 5e-4, 1e-5, 1e-7] {
        let b = ConvexPolyhedron::cuboid(DVec3::new(1.0, 1.0, t)).unwrap();
        check_polyhedron(&b.shape);
        assert_eq!(b.shape.num_faces(), 6, "t = {t}");
        assert_close(b.shape.volume, 8.0 * t, 1e-10, "plate volume");
    }
    // A thin rotated wall plate from points.
    let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
    let pts: Vec<DVec3> = box_corners(DVec3::new(-5.0, -5.0, -5e-4), DVec3::new(5.0, 5.0, 5e-4))
        .iter()
        .map(|&c| q * c)
        .collect();
    let b = ConvexPolyhedron::from_points(&pts).unwrap();
    check_polyhedron(&b.shape);
    assert_close(b.shape.volume, 0.1, 1e-10, "wall volume");
}

#[test]
fn error_cases() {
    let degenerate = |r: Result<PolyhedronBuild, ShapeError>, what: &str| match r {
        Err(ShapeError::Degenerate(msg)) => assert!(msg.contains(what), "{msg:?} lacks {what:?}"),
        other => panic!("expected Degenerate({what}), got {other:?}"),
    };
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    degenerate(
        ConvexPolyhedron::from_points(&[p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.)]),
        "at least 4",
    );
    degenerate(ConvexPolyhedron::from_points(&[]), "at least 4");
    let coplanar: Vec<DVec3> = (0..10)
        .map(|i| p((i as f64 * 0.7).cos(), (i as f64 * 1.3).sin(), 0.0))
        .collect();
    degenerate(ConvexPolyhedron::from_points(&coplanar), "coplanar");
    // Tilted and nearly coplanar (1e-10 relative) is still coplanar.
    let q = DQuat::from_rotation_x(0.4);
    let tilted: Vec<DVec3> = coplanar
        .iter()
        .enumerate()
        .map(|(i, &x)| q * (x + DVec3::Z * 1e-10 * (i % 2) as f64))
        .collect();
    degenerate(ConvexPolyhedron::from_points(&tilted), "coplanar");
    let collinear: Vec<DVec3> = (0..6).map(|i| p(1.0, 2.0, 3.0) * i as f64).collect();
    degenerate(ConvexPolyhedron::from_points(&collinear), "collinear");
    degenerate(
        ConvexPolyhedron::from_points(&[p(1., 1., 1.); 5]),
        "coincide",
    );
    let needle = box_corners(DVec3::ZERO, p(1.0, 1e-5, 1e-5));
    degenerate(ConvexPolyhedron::from_points(&needle), "needle");
    let mut nan = box_corners(DVec3::ZERO, DVec3::ONE);
    nan[3].y = f64::NAN;
    assert_eq!(
        ConvexPolyhedron::from_points(&nan).unwrap_err(),
        ShapeError::NonFinite
    );
    nan[3].y = f64::INFINITY;
    assert_eq!(
        ConvexPolyhedron::from_points(&nan).unwrap_err(),
        ShapeError::NonFinite
    );
    let tiny = box_corners(DVec3::ZERO, DVec3::splat(1e-8));
    match ConvexPolyhedron::from_points(&tiny) {
        Err(ShapeError::TooSmall(msg)) => assert!(msg.contains("1e-6"), "{msg}"),
        other => panic!("expected TooSmall, got {other:?}"),
    }
    assert!(matches!(
        ConvexPolyhedron::cuboid(DVec3::new(1.0, 0.0, 1.0)),
        Err(ShapeError::Degenerate(_))
    ));
    assert_eq!(
        ConvexPolyhedron::cuboid(DVec3::new(1.0, f64::NAN, 1.0)).unwrap_err(),
        ShapeError::NonFinite
    );
    // Coordinates whose differences overflow.
    degenerate(
        ConvexPolyhedron::from_points(&box_corners(DVec3::splat(-1e308), DVec3::splat(1e308))),
        "too large",
    );
}

#[test]
fn duplicate_and_near_duplicate_points() {
    let mut pts = box_corners(DVec3::ZERO, DVec3::splat(0.1));
    pts.extend(box_corners(DVec3::ZERO, DVec3::splat(0.1)));
    pts.push(DVec3::splat(0.1) + DVec3::new(1e-13, -1e-13, 0.0));
    let b = ConvexPolyhedron::from_points(&pts).unwrap();
    check_polyhedron(&b.shape);
    assert_eq!((b.shape.vertices.len(), b.shape.num_faces()), (8, 6));
}

#[test]
fn many_points_on_box_edges() {
    // Collinear points inside hull edges, rotated and far from the origin: parry's hull can come
    // out non-convex on such input (here for both the raw and the mapped points in one of the
    // 50 cases, which then needs the retry without the points inside edges); the builder must
    // still find the box.
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for _ in 0..50 {
        let q = random_rotation(&mut rng);
        let p0 = DVec3::new(100.0, -40.0, 7.0);
        let mut pts = Vec::new();
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            pts.push(DVec3::new(x, y, -1.0));
            pts.push(DVec3::new(x, y, 1.0));
            for _ in 0..40 {
                pts.push(DVec3::new(x, y, rng.gen_range(-1.0..1.0)));
            }
        }
        let pts: Vec<DVec3> = pts.iter().map(|&x| p0 + q * (0.02 * x)).collect();
        let b = ConvexPolyhedron::from_points(&pts).unwrap();
        check_polyhedron(&b.shape);
        assert_eq!((b.shape.vertices.len(), b.shape.num_faces()), (8, 6));
        assert_close(b.shape.volume, 6.4e-5, 1e-9, "volume");
    }
}

#[test]
fn support_triangles_and_scaling() {
    let b = ConvexPolyhedron::cuboid(DVec3::new(0.1, 0.2, 0.3)).unwrap();
    let s = &b.shape;
    // Body x is the long box axis (z in the input frame).
    assert_vec_close(
        s.support(DVec3::new(1.0, 1e-3, 1e-3)),
        DVec3::new(0.3, 0.2, 0.1),
        1e-15,
        "",
    );
    let tris = s.triangles();
    assert_eq!(tris.len(), 12);
    let m = MassProperties::of_closed_mesh(&s.vertices, &tris);
    assert_close(m.volume, s.volume, 1e-14, "fan volume");

    let t = s.scaled(2.0);
    check_polyhedron(&t);
    assert_close(t.volume, 8.0 * s.volume, 1e-15, "scaled volume");
    assert_vec_close(
        t.unit_inertia,
        32.0 * s.unit_inertia,
        1e-15,
        "scaled inertia",
    );
    assert_close(t.radius, 2.0 * s.radius, 1e-15, "scaled radius");
    assert_eq!(t.face_normals, s.face_normals);
}

// ---------------------------------------------------------------------------------------------
// Property tests on random point clouds

/// A seeded point cloud of one of several kinds, some deliberately degenerate.
fn cloud(seed: u64, n: usize, scale: f64, kind: u8) -> Vec<DVec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let offset = DVec3::new(rng.gen(), rng.gen(), rng.gen()) * 10.0;
    let q = random_rotation(&mut rng);
    (0..n)
        .map(|_| {
            let u = DVec3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
            );
            let local = match kind {
                0 => u,                                           // uniform in a cube
                1 => u.normalize_or(DVec3::X),                    // on a sphere
                2 => (u * 2.0).round() / 2.0, // a coarse grid: coplanar faces, duplicates
                3 => DVec3::new(u.x, u.y, 0.0), // exactly flat
                4 => DVec3::new(u.x, u.y, 1e-3 * u.z), // thin slab
                5 => DVec3::new(u.x, 0.5 * u.x, 0.25 * u.x), // collinear
                6 => DVec3::new(u.x.signum(), u.y, u.z), // two parallel planes
                7 => DVec3::new(u.x.signum(), u.y.signum(), u.z), // on the 4 edges of a prism
                _ => {
                    // On the faces of a cube, 1e-8 off: nearly (not exactly) coplanar facets.
                    let mut v = u;
                    let k = rng.gen_range(0..3);
                    v[k] = v[k].signum();
                    v + 1e-8 * DVec3::new(rng.gen(), rng.gen(), rng.gen())
                }
            };
            offset + q * (scale * local)
        })
        .collect()
}

proptest! {
    // A fixed seed: the same 512 clouds on every run, and no regression files written.
    #![proptest_config(ProptestConfig {
        cases: 512,
        rng_seed: proptest::test_runner::RngSeed::Fixed(20_240_611),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn hulls_build_or_report_degenerate(
        seed in any::<u64>(),
        n in 4usize..=40,
        scale in 1e-2f64..1.0,
        kind in 0u8..9,
    ) {
        let pts = cloud(seed, n, scale, kind);
        match ConvexPolyhedron::from_points(&pts) {
            Ok(b) => {
                check_polyhedron(&b.shape);
                let s = &b.shape;
                let size = 2.0 * s.radius;
                let inv = b.orientation.inverse();
                for x in &pts {
                    let y = inv * (*x - b.position);
                    for f in 0..s.num_faces() {
                        prop_assert!(
                            s.face_normals[f].dot(y) <= s.face_offsets[f] + 1e-8 * size,
                            "input point outside face {}", f
                        );
                    }
                }
                prop_assert!(s.face_offsets.iter().all(|&d| d > 0.0));
                // Every vertex is an input point.
                for v in &s.vertices {
                    let x = b.position + b.orientation * *v;
                    prop_assert!(pts.iter().any(|p| p.distance(x) <= 1e-12 * (10.0 + size)));
                }
            }
            Err(ShapeError::Degenerate(_)) => prop_assert!(kind >= 2 || n < 8),
            Err(e) => prop_assert!(false, "unexpected error {e:?}"),
        }
        if kind == 3 || kind == 5 {
            prop_assert!(ConvexPolyhedron::from_points(&pts).is_err());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Random grains

#[test]
fn random_grains_are_valid() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let param_sets = [
        GrainParams::default(),
        GrainParams {
            vertices_min: 4,
            vertices_max: 8,
            elongation: 1.0,
            flatness: 1.0,
        },
        GrainParams {
            vertices_min: 30,
            vertices_max: 40,
            elongation: 2.5,
            flatness: 1.5,
        },
        GrainParams {
            vertices_min: 40,
            vertices_max: 40,
            elongation: 1.0,
            flatness: 1.0,
        },
    ];
    for params in &param_sets {
        for _ in 0..100 {
            let d = rng.gen_range(0.02..0.06);
            let g = random_grain(&mut rng, params, d).unwrap();
            check_polyhedron(&g.shape);
            let n = g.shape.vertices.len();
            assert!(
                (params.vertices_min..=params.vertices_max).contains(&n),
                "{n} vertices"
            );
            assert_close(
                equivalent_diameter(g.shape.volume),
                d,
                1e-12,
                "equivalent diameter",
            );
            // The circumscribed ball holds at least the volume of the equivalent sphere.
            assert!(g.shape.radius >= 0.5 * d);
        }
    }
}

#[test]
fn random_grains_are_deterministic() {
    let params = GrainParams::default();
    let make = |seed| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..20)
            .map(|_| random_grain(&mut rng, &params, 0.04).unwrap())
            .collect::<Vec<_>>()
    };
    let (a, b, c) = (make(1), make(1), make(2));
    for (x, y) in a.iter().zip(&b) {
        let bits = |g: &PolyhedronBuild| {
            g.shape
                .vertices
                .iter()
                .flat_map(|v| v.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(x), bits(y));
        assert_eq!(x.shape.face_vertices, y.shape.face_vertices);
        assert_eq!(x.shape.volume.to_bits(), y.shape.volume.to_bits());
    }
    assert_ne!(a[0].shape.vertices, c[0].shape.vertices);
}

#[test]
fn elongation_shows_in_principal_extents() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let params = GrainParams {
        vertices_min: 20,
        vertices_max: 30,
        elongation: 2.0,
        flatness: 1.0,
    };
    let mut sum = 0.0;
    for _ in 0..50 {
        let g = random_grain(&mut rng, &params, 0.05).unwrap();
        let extent = |axis: DVec3| {
            let dots = g.shape.vertices.iter().map(|v| v.dot(axis));
            dots.clone().fold(f64::MIN, f64::max) - dots.fold(f64::MAX, f64::min)
        };
        // Body x is the axis of least inertia, i.e. the long one.
        sum += extent(DVec3::X) / extent(DVec3::Y);
    }
    let mean = sum / 50.0;
    assert!((1.5..2.5).contains(&mean), "mean extent ratio {mean}");
}

#[test]
fn random_grain_rejects_bad_parameters() {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let ok = GrainParams::default();
    let bad = |p: GrainParams, d: f64| random_grain(&mut ChaCha8Rng::seed_from_u64(0), &p, d);
    assert!(matches!(
        bad(
            GrainParams {
                vertices_min: 3,
                ..ok
            },
            0.04
        ),
        Err(ShapeError::Degenerate(_))
    ));
    assert!(matches!(
        bad(
            GrainParams {
                vertices_min: 20,
                vertices_max: 10,
                ..ok
            },
            0.04
        ),
        Err(ShapeError::Degenerate(_))
    ));
    assert!(matches!(
        bad(
            GrainParams {
                elongation: 0.5,
                ..ok
            },
            0.04
        ),
        Err(ShapeError::Degenerate(_))
    ));
    assert_eq!(
        bad(
            GrainParams {
                flatness: f64::NAN,
                ..ok
            },
            0.04
        )
        .unwrap_err(),
        ShapeError::NonFinite
    );
    assert!(matches!(bad(ok, 0.0), Err(ShapeError::TooSmall(_))));
    assert!(matches!(bad(ok, -1.0), Err(ShapeError::TooSmall(_))));
    assert!(random_grain(&mut rng, &ok, 0.04).is_ok());
}

#[test]
fn equivalent_diameter_of_a_sphere_volume() {
    let d = 0.0375;
    let v = std::f64::consts::PI * d * d * d / 6.0;
    assert_close(equivalent_diameter(v), d, 1e-15, "d_eq");
    assert_eq!(equivalent_diameter(0.0), 0.0);
}
