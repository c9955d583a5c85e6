//! Released kinematic bodies (`Driver::release_at`): driven exactly until the release time,
//! ballistic (θ = 0.5 is exact for constant gravity) and with their angular momentum after it,
//! landing and resting on a floor with the weight they were given, bit-identical resume across
//! the release, and no release without `release_at`.

use ballast_engine::bodies::{BodyKind, BodySet, Driver, Term};
use ballast_engine::digest::state_digest;
use ballast_engine::laws::FrictionTable;
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::output::checkpoint::{read_checkpoint, write_checkpoint};
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::SolverSettings;
use ballast_engine::world::{StepSettings, World};
use std::path::PathBuf;

const G: f64 = 9.81;
const RHO: f64 = 2700.0;

fn tight_settings(dt: f64) -> StepSettings {
    StepSettings {
        dt,
        solver: SolverSettings {
            tolerance: 1e-12,
            max_iterations: 10_000,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// A fresh, empty folder under the system temporary folder, unique to this process and test.
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "ballast_release_tests_{}_{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Number of steps after which `World::time` (accumulated as `time += h`) first reaches `t`:
/// the release happens at the start of the next step.
fn steps_to_reach(t: f64, h: f64) -> u64 {
    let (mut time, mut k) = (0.0f64, 0u64);
    while time < t {
        time += h;
        k += 1;
    }
    k
}

fn bits3(v: DVec3) -> [u64; 3] {
    v.to_array().map(f64::to_bits)
}

fn bitsq(q: DQuat) -> [u64; 4] {
    q.to_array().map(f64::to_bits)
}

/// (1) A cube driven upward at 0.5 m/s until 0.1 s, then free: z follows the driver exactly
/// before, the exact parabola after (trapezoidal rule = exact for a constant acceleration, so
/// only rounding remains), with the velocity continuous at the release.
#[test]
fn released_cube_flies_ballistically() {
    let (h, vz, t_r, z0) = (1e-3, 0.5, 0.1, 1.0);
    let mut bodies = BodySet::default();
    let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(0.05)).unwrap();
    cube.position = DVec3::new(0.3, -0.2, z0);
    let c = bodies.add_polyhedron(cube, RHO, BodyKind::Kinematic, 0);
    bodies.driver[c] = Some(Box::new(Driver {
        vz: vec![Term::Constant { value: vz }],
        release_at: Some(t_r),
        ..Default::default()
    }));
    // Kinematic bodies carry their real mass (2700 kg/m³ · 0.001 m³ = 2.7 kg).
    assert!((bodies.mass(c) - RHO * 1e-3).abs() < 1e-12);
    let mut w = World::new(bodies, FrictionTable::new(0.5), tight_settings(h));
    assert_eq!(w.bodies.kind[c], BodyKind::Kinematic);
    assert_eq!(w.bodies.velocity[c], DVec3::new(0.0, 0.0, vz));

    let release_step = steps_to_reach(t_r, h);
    // Rounding of N additions of numbers of order 1: a few ulp (2.2e-16) each, N ≤ 400.
    let tol = 1e-12;
    let mut released: Option<(u64, f64, f64)> = None; // (step index, t_r, z_r) at the release
    let (mut max_err_z, mut max_err_v) = (0.0f64, 0.0f64);
    for _ in 0..400 {
        let (t0, z_start, v_start) = (w.time, w.bodies.position[c].z, w.bodies.velocity[c]);
        let kind_before = w.bodies.kind[c];
        w.step();
        let p = w.bodies.position[c];
        // x and y never move.
        assert_eq!((p.x, p.y), (0.3, -0.2));
        if w.bodies.kind[c] == BodyKind::Kinematic {
            assert!(released.is_none(), "a released body became kinematic again");
            assert!(
                t0 < t_r,
                "still kinematic in a step starting at t = {t0} ≥ {t_r}"
            );
            let exact = z0 + vz * w.time;
            assert!(
                (p.z - exact).abs() < tol,
                "driven: z = {p:?} at t = {}, driver says {exact}",
                w.time
            );
            assert_eq!(w.bodies.velocity[c], DVec3::new(0.0, 0.0, vz));
            continue;
        }
        if released.is_none() {
            // This step started with the release.
            assert_eq!(kind_before, BodyKind::Kinematic);
            assert!(t0 >= t_r && t0 < t_r + h, "released at t = {t0}");
            assert_eq!(w.step_index - 1, release_step, "release step");
            // The velocity at the release instant is the driver's.
            assert_eq!(v_start, DVec3::new(0.0, 0.0, vz));
            assert!((z_start - (z0 + vz * t0)).abs() < tol);
            released = Some((w.step_index - 1, t0, z_start));
        }
        let (k_r, _, z_r) = released.unwrap();
        // Time since the release as n h (the scheme's own clock, free of the sum's rounding).
        let tau = (w.step_index - k_r) as f64 * h;
        let z_exact = z_r + vz * tau - 0.5 * G * tau * tau;
        let v_exact = vz - G * tau;
        let v = w.bodies.velocity[c];
        max_err_z = max_err_z.max((p.z - z_exact).abs());
        max_err_v = max_err_v.max((v.z - v_exact).abs());
        assert!(
            (p.z - z_exact).abs() < tol,
            "free: z = {} after τ = {tau}, exact {z_exact}",
            p.z
        );
        assert!(
            (v.z - v_exact).abs() < tol,
            "free: vz = {} after τ = {tau}, exact {v_exact}",
            v.z
        );
        assert_eq!((v.x, v.y), (0.0, 0.0));
    }
    let (_, t_rel, _) = released.expect("the cube was never released");
    assert_eq!(w.bodies.kind[c], BodyKind::Dynamic);
    // The free flight is long enough to matter: the apex is passed and the cube falls.
    assert!(w.bodies.velocity[c].z < -2.0);
    assert!(w.time - t_rel > 0.29);
    eprintln!("ballistic flight: max |Δz| = {max_err_z:e} m, max |Δvz| = {max_err_v:e} m/s");
}

/// (1b) A spinning driven cuboid keeps its angular momentum `L = I_w ω` at the release and,
/// without torque, exactly afterwards.
#[test]
fn released_spin_keeps_angular_momentum() {
    let (h, t_r) = (1e-3, 0.05);
    let mut bodies = BodySet::default();
    let mut b = ConvexPolyhedron::cuboid(DVec3::new(0.1, 0.05, 0.02)).unwrap();
    b.position = DVec3::new(0.0, 0.0, 1.0);
    let i = bodies.add_polyhedron(b, RHO, BodyKind::Kinematic, 0);
    let omega = DVec3::new(1.0, -2.0, 3.0);
    bodies.driver[i] = Some(Box::new(Driver {
        vx: vec![Term::Constant { value: 0.2 }],
        wx: vec![Term::Constant { value: omega.x }],
        wy: vec![Term::Constant { value: omega.y }],
        wz: vec![Term::Constant { value: omega.z }],
        release_at: Some(t_r),
        ..Default::default()
    }));
    let mut w = World::new(bodies, FrictionTable::new(0.5), tight_settings(h));
    let release_step = steps_to_reach(t_r, h);
    for _ in 0..release_step {
        w.step();
    }
    assert_eq!(w.bodies.kind[i], BodyKind::Kinematic);
    assert_eq!(w.bodies.angular_velocity[i], omega);
    let l_r = w.bodies.angular_momentum[i];
    let expected = w.bodies.inertia_world(i) * omega;
    assert!(
        (l_r - expected).length() <= 1e-12 * expected.length(),
        "driven L = {l_r}, I_w ω = {expected}"
    );
    let v_r = w.bodies.velocity[i];
    w.step();
    assert_eq!(w.bodies.kind[i], BodyKind::Dynamic);
    // First free step: v = v_r + g h, and no torque: L unchanged, bit for bit.
    let v1 = w.bodies.velocity[i];
    assert!((v1 - (v_r + DVec3::new(0.0, 0.0, -G * h))).length() < 1e-15);
    assert_eq!(bits3(w.bodies.angular_momentum[i]), bits3(l_r));
    // ω is still I_w⁻¹ L (it tumbles, so ω itself changes slowly with the orientation).
    let w1 = w.bodies.angular_velocity[i];
    assert!(
        (w1 - omega).length() < 0.05 * omega.length(),
        "ω jumped to {w1}"
    );
    for _ in 0..200 {
        w.step();
        assert_eq!(bits3(w.bodies.angular_momentum[i]), bits3(l_r));
    }
}

/// A floor plane and a 0.2 × 0.16 × 0.1 m box held still (zero driver) with its bottom 2 cm
/// above the floor, released at `release_at`. Returns the bodies and the box index.
fn held_box_bodies(release_at: f64) -> (BodySet, usize) {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    let mut b = ConvexPolyhedron::cuboid(DVec3::new(0.1, 0.08, 0.05)).unwrap();
    b.position = DVec3::new(0.0, 0.0, 0.07);
    let i = bodies.add_polyhedron(b, RHO, BodyKind::Kinematic, 1);
    bodies.driver[i] = Some(Box::new(Driver {
        release_at: Some(release_at),
        ..Default::default()
    }));
    (bodies, i)
}

fn held_box(release_at: f64, dt: f64) -> (World, usize) {
    let (bodies, i) = held_box_bodies(release_at);
    (
        World::new(bodies, FrictionTable::new(0.6), tight_settings(dt)),
        i,
    )
}

/// (2) The held box does not move until released, then falls 2 cm, lands and rests on the
/// floor: centre at the half height (1 mm), contact force m g (3 %).
#[test]
fn released_box_lands_and_rests() {
    let (h, t_r) = (2e-4, 0.05);
    let (mut w, i) = held_box(t_r, h);
    let (x0, q0) = (w.bodies.position[i], w.bodies.orientation[i]);
    let release_step = steps_to_reach(t_r, h);
    for _ in 0..release_step {
        w.step();
        assert_eq!(w.bodies.kind[i], BodyKind::Kinematic);
        assert_eq!(bits3(w.bodies.position[i]), bits3(x0));
        assert_eq!(bitsq(w.bodies.orientation[i]), bitsq(q0));
        assert_eq!(w.bodies.velocity[i], DVec3::ZERO);
    }
    let steps = 3000; // 0.6 s; the fall takes √(2 · 0.02 / g) ≈ 0.064 s.
    for _ in 0..steps {
        w.step();
    }
    assert_eq!(w.bodies.kind[i], BodyKind::Dynamic);
    let m = w.bodies.mass(i);
    let x = w.bodies.position[i];
    assert!(
        (x.z - 0.05).abs() < 1e-3,
        "box centre at z = {}, expected 0.05",
        x.z
    );
    assert!(x.x.abs() < 1e-6 && x.y.abs() < 1e-6, "box drifted: {x}");
    let v = w.bodies.velocity[i];
    assert!(v.length() < 1e-6, "box not at rest: v = {v}");
    let tilt = (w.bodies.orientation[i] * DVec3::Z).dot(DVec3::Z);
    assert!(tilt > 1.0 - 1e-9, "box tilted: cos = {tilt}");
    let force = w.contacts.impulses_on(&[i as u32])[0] / h;
    let weight = m * G;
    assert!(
        (force.z - weight).abs() < 0.03 * weight,
        "floor force {} N, weight {weight} N",
        force.z
    );
    assert!(force.truncate().length() < 1e-3 * weight);
    eprintln!(
        "box at rest: z − 0.05 = {:e} m, force / mg − 1 = {:e}",
        x.z - 0.05,
        force.z / weight - 1.0
    );
}

const SCENE_DT: f64 = 2e-4;
const SCENE_RELEASE: f64 = 0.05;
const SCENE_STEPS: u64 = 1200;

/// The held box of (2) with a dynamic cube resting on its top (carried by it while held, so
/// there are loaded contacts with a driven body across the release) and two dynamic cubes on
/// the floor, one of which the falling box does not touch and one it lands next to.
fn scene() -> (World, usize, usize) {
    let (mut bodies, b) = held_box_bodies(SCENE_RELEASE);
    let mut top = ConvexPolyhedron::cuboid(DVec3::splat(0.03)).unwrap();
    top.position = DVec3::new(0.02, -0.01, 0.12 + 0.03);
    let t = bodies.add_polyhedron(top, RHO, BodyKind::Dynamic, 2);
    for (k, x) in [0.2, -0.125].into_iter().enumerate() {
        let mut c = ConvexPolyhedron::cuboid(DVec3::splat(0.02)).unwrap();
        c.position = DVec3::new(x, 0.01 * k as f64, 0.02 + 1e-3);
        bodies.add_polyhedron(c, RHO, BodyKind::Dynamic, 2);
    }
    let w = World::new(bodies, FrictionTable::new(0.6), tight_settings(SCENE_DT));
    (w, b, t)
}

fn run_to(w: &mut World, step: u64) {
    while w.step_index < step {
        w.step();
    }
}

/// Bodies, clock and contacts of two worlds, bit for bit.
fn assert_identical(a: &World, b: &World, what: &str) {
    assert_eq!(a.step_index, b.step_index, "{what}: step");
    assert_eq!(a.time.to_bits(), b.time.to_bits(), "{what}: time");
    assert_eq!(a.bodies.kind, b.bodies.kind, "{what}: kinds");
    assert_eq!(
        state_digest(&a.bodies),
        state_digest(&b.bodies),
        "{what}: state digest"
    );
    for i in 0..a.bodies.len() {
        assert_eq!(
            bits3(a.bodies.position[i]),
            bits3(b.bodies.position[i]),
            "{what}: position {i}"
        );
        assert_eq!(
            bitsq(a.bodies.orientation[i]),
            bitsq(b.bodies.orientation[i]),
            "{what}: orientation {i}"
        );
    }
    assert_eq!(a.contacts.len(), b.contacts.len(), "{what}: contacts");
    for k in 0..a.contacts.len() {
        assert_eq!(
            bits3(a.contacts.impulse[k]),
            bits3(b.contacts.impulse[k]),
            "{what}: impulse {k}"
        );
    }
}

/// (3) Checkpoints before the release, at the step whose end reaches the release time (the
/// writer is still kinematic, the reader releases at once) and after it: each resumed run ends
/// bit-identical to the straight one.
#[test]
fn resume_across_release_is_bit_identical() {
    let (mut straight, b, t) = scene();
    let z_top0 = straight.bodies.position[t].z;
    run_to(&mut straight, SCENE_STEPS);
    // The scene does what it is meant to: the box was released and fell with the cube on it.
    assert_eq!(straight.bodies.kind[b], BodyKind::Dynamic);
    assert!((straight.bodies.position[b].z - 0.05).abs() < 2e-3);
    assert!(
        z_top0 - straight.bodies.position[t].z > 0.015,
        "top cube did not follow the box down"
    );

    let boundary = steps_to_reach(SCENE_RELEASE, SCENE_DT);
    let dir = tmp("resume");
    for split in [boundary / 2, boundary - 1, boundary, boundary + 1, 800] {
        let path = dir.join(format!("checkpoint_{split}.bin"));
        let mut first = scene().0;
        run_to(&mut first, split);
        if split == boundary / 2 {
            // Loaded contacts between the carried cube and the driven box.
            let loaded = (0..first.contacts.len())
                .filter(|&k| {
                    let pair = (first.contacts.body1[k], first.contacts.body2[k]);
                    (pair == (b as u32, t as u32) || pair == (t as u32, b as u32))
                        && first.contacts.impulse[k].x > 0.0
                })
                .count();
            assert!(loaded >= 3, "only {loaded} loaded box–cube contacts");
        }
        let writer_kind = first.bodies.kind[b];
        write_checkpoint(&first, &path).unwrap();

        let mut resumed = scene().0;
        read_checkpoint(&path, &mut resumed)
            .unwrap_or_else(|e| panic!("checkpoint at step {split} refused: {e}"));
        assert_eq!(resumed.step_index, split);
        let expect_kind = if resumed.time >= SCENE_RELEASE {
            BodyKind::Dynamic
        } else {
            BodyKind::Kinematic
        };
        assert_eq!(
            resumed.bodies.kind[b], expect_kind,
            "kind after reading {split}"
        );
        if split == boundary {
            assert_eq!(writer_kind, BodyKind::Kinematic);
        }
        // The writer continues too: reading must not differ from never having stopped.
        run_to(&mut first, SCENE_STEPS);
        run_to(&mut resumed, SCENE_STEPS);
        assert_identical(&resumed, &straight, &format!("resumed from {split}"));
        assert_identical(&first, &straight, &format!("writer of {split}"));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// (3b) Rewinding: a checkpoint taken before the release read into a world that has already
/// released the box (not a fresh one) must bring the box back under its driver.
#[test]
fn rewind_to_before_release_restores_the_driver() {
    let (mut straight, b, _) = scene();
    let split = steps_to_reach(SCENE_RELEASE, SCENE_DT) / 2;
    let dir = tmp("rewind");
    let path = dir.join("checkpoint.bin");
    run_to(&mut straight, split);
    write_checkpoint(&straight, &path).unwrap();
    run_to(&mut straight, SCENE_STEPS);
    let reference = state_digest(&straight.bodies);
    assert_eq!(straight.bodies.kind[b], BodyKind::Dynamic);

    // The same world, read back to before the release.
    read_checkpoint(&path, &mut straight).unwrap();
    assert_eq!(
        straight.bodies.kind[b],
        BodyKind::Kinematic,
        "after reading a checkpoint of t = {} < release_at = {SCENE_RELEASE}, the box is still \
         dynamic",
        straight.time
    );
    run_to(&mut straight, SCENE_STEPS);
    assert_eq!(state_digest(&straight.bodies), reference);
    let _ = std::fs::remove_dir_all(&dir);
}

/// (4) Without `release_at` a driven body (and an undriven kinematic one) stays kinematic at
/// any time, follows its driver exactly and is not pushed by what lands on it.
#[test]
fn kinematic_without_release_at_is_never_released() {
    let h = 2e-4;
    let mut bodies = BodySet::default();
    let mut slab = ConvexPolyhedron::cuboid(DVec3::new(0.2, 0.2, 0.02)).unwrap();
    slab.position = DVec3::new(0.0, 0.0, 0.5);
    let s = bodies.add_polyhedron(slab, RHO, BodyKind::Kinematic, 0);
    bodies.driver[s] = Some(Box::new(Driver {
        vx: vec![Term::Constant { value: 0.01 }],
        ..Default::default()
    }));
    let mut still = ConvexPolyhedron::cuboid(DVec3::splat(0.05)).unwrap();
    still.position = DVec3::new(1.0, 0.0, 0.5);
    let k = bodies.add_polyhedron(still, RHO, BodyKind::Kinematic, 0);
    let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(0.03)).unwrap();
    cube.position = DVec3::new(0.0, 0.0, 0.5 + 0.02 + 0.03 + 0.01);
    let c = bodies.add_polyhedron(cube, RHO, BodyKind::Dynamic, 1);
    let mut w = World::new(bodies, FrictionTable::new(0.5), tight_settings(h));
    assert!(w.bodies.driver[s].as_ref().unwrap().release_at.is_none());

    // `n` steps after the slab was at `x0`.
    let check = |w: &World, x0: f64, n: u64| {
        assert_eq!(
            w.bodies.kind[s],
            BodyKind::Kinematic,
            "driven slab released"
        );
        assert_eq!(
            w.bodies.kind[k],
            BodyKind::Kinematic,
            "undriven body released"
        );
        let p = w.bodies.position[s];
        let exact = x0 + 0.01 * n as f64 * h;
        assert!(
            (p.x - exact).abs() < 1e-10,
            "slab x = {}, driver {exact}",
            p.x
        );
        assert_eq!((p.y, p.z), (0.0, 0.5), "slab pushed");
        assert_eq!(w.bodies.velocity[s], DVec3::new(0.01, 0.0, 0.0));
        assert_eq!(w.bodies.position[k], DVec3::new(1.0, 0.0, 0.5));
    };
    // The cube lands on the slab (0.045 s) and rests there.
    for n in 1..=2000 {
        w.step();
        check(&w, 0.0, n);
    }
    let zc = w.bodies.position[c].z;
    assert!(
        (zc - 0.55).abs() < 1e-3,
        "cube not resting on the slab: z = {zc}"
    );
    // Much later in time.
    let x0 = w.bodies.position[s].x;
    w.time = 1e9;
    for n in 1..=200 {
        w.step();
        check(&w, x0, n);
    }
    assert!(!w.bodies.driver[s].as_ref().unwrap().released(f64::MAX));
}
