//! Compliant contacts (`StepSettings::contact_stiffness`): the rate form of an elastic normal
//! law, `uₙ + (rₙ − r̄ₙ)/(k h²) ≥ 0 ⊥ rₙ ≥ 0`. A static load deflects a contact by `F/k`; a
//! rigid setting is the rigid law bit for bit; runs stay deterministic and resume exactly; in
//! a jammed pile the sweeps stop far sooner than with rigid contacts.

mod common;

use ballast_engine::bodies::{BodyKind, BodySet};
use ballast_engine::digest::state_digest;
use ballast_engine::laws::{FrictionTable, NormalLaw};
use ballast_engine::math::DVec3;
use ballast_engine::output::checkpoint::{read_checkpoint, write_checkpoint};
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::scenario::Scenario;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{ConvergenceNorm, CorrectionSettings, DdmSettings, SolverSettings};
use ballast_engine::world::{StepSettings, World};

const G: f64 = 9.81;

/// A 0.1 m cube of 2700 kg/m³ resting on the plane z = 0 (its four bottom corners touching),
/// the overlap correction off so that only the contact law moves it.
fn cube_on_floor(stiffness: Option<f64>, theta: f64) -> (World, f64) {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(0.05)).unwrap();
    cube.position = DVec3::new(0.0, 0.0, 0.05);
    let b = bodies.add_polyhedron(cube, 2700.0, BodyKind::Dynamic, 1);
    let m = bodies.mass(b);
    let settings = StepSettings {
        theta,
        ..tight_settings(stiffness, NormalLaw::Rate, None)
    };
    (World::new(bodies, FrictionTable::new(0.8), settings), m)
}

/// Steps the cube of [`cube_on_floor`] (mass `m`, contacts of `k` N/m) 3,000 times, each
/// converged, and checks that it sank by its deflection `m g / (4 k)`.
fn settles_at_its_deflection(w: &mut World, m: f64, k: f64) {
    for _ in 0..3000 {
        let r = w.step();
        assert!(r.solve.converged, "{:?}", r.solve);
    }
    let sink = 0.05 - w.bodies.position[1].z;
    let expected = m * G / (4.0 * k);
    assert!(
        (sink - expected).abs() <= 1e-3 * expected,
        "sank {sink:e} m, expected {expected:e} m"
    );
}

/// Under its weight the cube sinks until its four corners carry `m g / 4` each: by
/// `m g / (4 k)` (6.6 µm for k = 1e6 N/m). θ = 0.6 damps the contact's oscillation
/// (`ω h = 0.63`: a factor 0.96 a step), so 3,000 steps leave it at rest.
#[test]
fn a_resting_block_sinks_by_its_weight_over_the_stiffness() {
    let k = 1e6;
    let (mut w, m) = cube_on_floor(Some(k), 0.6);
    settles_at_its_deflection(&mut w, m, k);
    // Each corner carries a quarter of the weight, and its overlap is its deflection.
    let c = &w.contacts;
    assert_eq!(c.len(), 4);
    for i in 0..4 {
        let f = c.impulse[i].x / w.settings.dt;
        assert!(
            (f - m * G / 4.0).abs() <= 1e-6 * m * G,
            "corner force {f} N"
        );
    }
    assert!(w.bodies.velocity[1].length() < 1e-9);
}

/// With a maximum closure `V_m` the contact follows the hyperbola `F = k δ/(1 − δ/V_m)`: the
/// cube of [`cube_on_floor`] (corner loads m g/4 = 6.6 N) on contacts of initial stiffness
/// 1e6 N/m and `V_m` = 5 µm (`k V_m` = 5 N) sinks by `F V_m/(k V_m + F)` = 2.85 µm, not the
/// linear law's 6.6 µm, exactly: each step's stiffness is the hyperbola's secant between the
/// force the contact carried and the one it carries (measured 3e-10 from it; a tangent taken
/// at the carried force alone left the cube 5.07 µm deep, loaded within its first steps).
#[test]
fn a_resting_block_sinks_by_the_hyperbolas_deflection() {
    let (k, vm) = (1e6, 5e-6);
    let (mut w, m) = cube_on_floor(Some(k), 0.6);
    w.settings.max_closure = Some(vm);
    for _ in 0..3000 {
        let r = w.step();
        assert!(r.solve.converged, "{:?}", r.solve);
    }
    let f = m * G / 4.0;
    let expected = f * vm / (k * vm + f);
    let sink = 0.05 - w.bodies.position[1].z;
    assert!(
        (sink - expected).abs() <= 1e-6 * expected,
        "sank {sink:e} m, expected {expected:e} m"
    );
    for i in 0..4 {
        let fi = w.contacts.impulse[i].x / w.settings.dt;
        assert!((fi - f).abs() <= 1e-6 * m * G, "corner force {fi} N");
    }
    assert!(w.bodies.velocity[1].length() < 1e-9);
}

/// With the overlap recovery on, the position correction heals overlaps beyond the elastic
/// deflection the contact's force implies, not the deflection itself: with the correction on
/// (β = 0.2, slop 10 µm), a cube on springs of 1e5 N/m still sinks by `m g / (4 k)` = 66 µm
/// (the recovery's slop, 0.25 mm, keeps the recovery itself out of it). Counting the whole
/// overlap, as without the recovery, the correction moved it while the rate form kept its
/// forces, and it came to rest 83 µm deep.
#[test]
fn the_correction_leaves_a_resting_block_its_deflection() {
    let k = 1e5;
    let (mut w, m) = cube_on_floor(Some(k), 0.6);
    w.settings.correction = CorrectionSettings::default();
    w.settings.overlap_recovery = 0.2;
    assert!(w.settings.correction.fraction > 0.0);
    settles_at_its_deflection(&mut w, m, k);
    assert!(w.bodies.velocity[1].length() < 1e-9);
}

/// A tangential stiffness makes a sticking contact a spring. The cube of [`cube_on_floor`]
/// settles on its normal springs, then gravity tilts by 5°: the cube sticks (μ = 0.8, no
/// corner near its cone even in the first swing), and its bottom corners move down the slope
/// by `m g sin α / (4 k_t)` (2.9 µm for k_t = 2e5 N/m: they move together, so each spring
/// carries a quarter of the load), then stay; every step converges. With rigid sticking the
/// corners do not move, and the four tangential forces are not unique: Gauss-Seidel leaves
/// some steps unconverged (23 of 3,000 measured) and an arbitrary split (−2.50, 3.86, −3.08
/// and 4.03 N for a quarter load of 0.58 N).
#[test]
fn a_tangential_stiffness_lets_a_sticking_block_creep_by_its_deflection() {
    let alpha = 5f64.to_radians();
    for kt in [None, Some(2e5)] {
        let (mut w, m) = cube_on_floor(Some(1e6), 0.6);
        w.settings.tangential_stiffness = kt;
        for _ in 0..1500 {
            assert!(w.step().solve.converged);
        }
        w.settings.gravity = DVec3::new(G * alpha.sin(), 0.0, -G * alpha.cos());
        let corner = |w: &World| {
            w.bodies.position[1] + w.bodies.orientation[1] * DVec3::new(-0.05, -0.05, -0.05)
        };
        let x0 = corner(&w).x;
        let mut unconverged = 0;
        for _ in 0..3000 {
            unconverged += usize::from(!w.step().solve.converged);
        }
        let moved = corner(&w).x - x0;
        let load = m * G * alpha.sin() / 4.0;
        let forces: Vec<f64> = (0..w.contacts.len())
            .map(|i| -w.contacts.world_impulse(i).x / w.settings.dt)
            .collect();
        eprintln!("{kt:?}: moved {moved:e} m, forces {forces:?} N, {unconverged} unconverged");
        assert_eq!(forces.len(), 4);
        assert!(
            (forces.iter().sum::<f64>() - 4.0 * load).abs() <= 1e-6 * load,
            "{forces:?}"
        );
        match kt {
            // Unconverged steps let it drift by tens of picometres (measured 3.5e-11 m).
            None => assert!(moved.abs() < 1e-9, "rigid sticking moved {moved:e} m"),
            Some(kt) => {
                assert_eq!(unconverged, 0);
                let expected = load / kt;
                assert!(
                    (moved - expected).abs() <= 1e-3 * expected,
                    "moved {moved:e} m, expected {expected:e} m"
                );
                for f in &forces {
                    assert!((f - load).abs() <= 1e-3 * load, "{forces:?} N");
                }
            }
        }
        assert!(w.bodies.velocity[1].length() < 1e-9);
    }
}

/// The rigid law keeps the same cube where it is (to rounding), and `contact_stiffness =
/// None` is the rigid law: the same bits as a world built before the setting existed.
#[test]
fn rigid_contacts_do_not_sink() {
    let (mut w, _) = cube_on_floor(None, 0.6);
    assert_eq!(w.nlgs().compliance, 0.0);
    for _ in 0..200 {
        w.step();
    }
    let sink = 0.05 - w.bodies.position[1].z;
    assert!(sink.abs() < 1e-12, "rigid cube moved by {sink:e} m");
}

/// 150 grains poured into a 0.2 m box (1.2 s of settling at dt = 4e-4).
fn pile(stiffness: Option<f64>, ddm: Option<DdmSettings>) -> World {
    let mut bodies = common::open_box(0.2);
    let pack = GrainPack {
        count: 150,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.2, 0.2],
        diameter: [0.025, 0.045],
        vertices: [10, 16],
        elongation: 1.3,
        flatness: 1.1,
        seed: 5,
    };
    common::pour(&mut bodies, &pack, 2700.0, 1);
    let settings = StepSettings {
        dt: 4e-4,
        theta: 0.55,
        contact_stiffness: stiffness,
        solver: SolverSettings {
            tolerance: 1e-3,
            max_iterations: 300,
            norm: ConvergenceNorm::NaturalMap,
            ..Default::default()
        },
        ddm,
        ..Default::default()
    };
    World::new(bodies, FrictionTable::new(1.0), settings)
}

/// Sweeps and unconverged steps of `steps` steps.
fn run(w: &mut World, steps: usize) -> (usize, usize) {
    let (mut sweeps, mut unconverged) = (0, 0);
    for _ in 0..steps {
        let r = w.step();
        sweeps += r.solve.iterations;
        unconverged += usize::from(!r.solve.converged);
    }
    (sweeps, unconverged)
}

/// The pile settling at μ = 1, steps 1,000 to 3,000 (0.4 to 1.2 s): rigid contacts need 1.7
/// times the sweeps of contacts of 1e7 N/m and leave 4.5 times as many steps at the cap
/// (measured: 290,183 sweeps and 408 steps against 169,469 and 91). The bounds ask for a
/// third of those gains.
#[test]
fn stiff_contacts_need_fewer_sweeps_in_a_jammed_pile() {
    let mut rigid = pile(None, None);
    let mut stiff = pile(Some(1e7), None);
    run(&mut rigid, 1000);
    run(&mut stiff, 1000);
    let (rs, ru) = run(&mut rigid, 2000);
    let (ss, su) = run(&mut stiff, 2000);
    eprintln!("rigid: {rs} sweeps, {ru} unconverged; k = 1e7: {ss} sweeps, {su} unconverged");
    assert!(ss * 5 < rs * 4, "{ss} vs {rs} sweeps");
    assert!(su * 2 < ru, "{su} vs {ru} steps unconverged");
}

/// With compliant contacts a run depends on the partition alone: the same digest on 1 and 2
/// threads under DDM, and a checkpointed run resumes bit-identical (the law's memory is the
/// impulses the checkpoint keeps), with the overlap recovery off and on (then the correction
/// too reads the impulses: it heals only the excess over `F/k`), with a tangential
/// stiffness (whose memory is the tangential impulses), with sweeps that skip contacts
/// whose bodies did not move (`solver.skip`: the skips depend on the sweep order alone), and
/// with the hyperbolic closure law (whose stiffness is a function of the impulses).
#[test]
fn compliant_runs_are_deterministic_and_resume_exactly() {
    let ddm = DdmSettings {
        subdomains: [2, 2, 1],
        min_parallel_contacts: 1,
        ..Default::default()
    };
    type Law = (f64, Option<f64>, f64, Option<f64>, NormalLaw);
    let pile_with = |(beta, kt, skip, vm, law): Law, ddm: Option<DdmSettings>| {
        let mut w = pile(Some(1e7), ddm);
        w.settings.overlap_recovery = beta;
        w.settings.tangential_stiffness = kt;
        w.settings.solver.skip = skip;
        w.settings.max_closure = vm;
        w.settings.normal_law = law;
        w
    };
    let mut digests = Vec::new();
    for beta in [
        (0.0, None, 0.0, None, NormalLaw::Rate),
        (0.2, None, 0.0, None, NormalLaw::Rate),
        (0.2, Some(5e6), 0.0, None, NormalLaw::Rate),
        (0.2, Some(5e6), 1.0, None, NormalLaw::Rate),
        (0.2, Some(5e6), 0.0, Some(1e-4), NormalLaw::Rate),
        (0.2, Some(5e6), 0.0, Some(1e-4), NormalLaw::Overlap),
    ] {
        let digest = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut w = pile_with(beta, Some(ddm.clone()));
                run(&mut w, 300);
                state_digest(&w.bodies)
            })
        };
        assert_eq!(digest(1), digest(2), "β, k_t, skip, V_m, law {beta:?}");
        digests.push(digest(1));

        let mut whole = pile_with(beta, None);
        run(&mut whole, 400);
        let mut first = pile_with(beta, None);
        run(&mut first, 250);
        let path = std::env::temp_dir().join(format!(
            "ballast-compliance-{}-{}.bin",
            std::process::id(),
            digests.len()
        ));
        write_checkpoint(&first, &path).unwrap();
        let mut resumed = pile_with(beta, None);
        read_checkpoint(&path, &mut resumed).unwrap();
        std::fs::remove_file(&path).ok();
        run(&mut resumed, 150);
        assert_eq!(
            state_digest(&whole.bodies),
            state_digest(&resumed.bodies),
            "β, k_t, skip, V_m, law {beta:?}"
        );
    }
    assert_ne!(digests[0], digests[1], "the recovery should change the run");
    assert_ne!(
        digests[1], digests[2],
        "the tangential spring should change the run"
    );
    assert_ne!(digests[2], digests[3], "skipping should change the iterate");
    assert_ne!(
        digests[2], digests[4],
        "the closure law should change the run"
    );
    assert_ne!(
        digests[4], digests[5],
        "the overlap law should change the run"
    );
}

/// A box dropped 10 mm onto a plane, 50 steps, with `simulation` keys `k` added.
fn cube_scenario(k: &str) -> String {
    format!(
        "[simulation]\ndt = 1e-3\nsteps = 50\n{k}\n[[body]]\nshape = \"plane\"\nkind = \"fixed\"\n\
         point = [0, 0, 0]\nnormal = [0, 0, 1]\n[[body]]\nshape = \"box\"\nhalf_extents = [0.05, 0.05, 0.05]\n\
         center = [0, 0, 0.06]\nmaterial = \"stone\"\n[materials]\nstone = 2700\n\
         [friction]\ndefault = 0.8\n"
    )
}

/// The world of [`cube_scenario`] with the `simulation` keys `k`, after its 50 steps.
fn cube_scenario_run(k: &str) -> World {
    let s = Scenario::from_toml(&cube_scenario(k)).unwrap();
    s.validate().unwrap();
    let mut w = s.build().unwrap();
    for _ in 0..50 {
        w.step();
    }
    w
}

/// The error refusing [`cube_scenario`] with the `simulation` keys `k`.
fn cube_scenario_refused(k: &str) -> String {
    Scenario::from_toml(&cube_scenario(k))
        .and_then(|s| s.validate().map(|_| s))
        .unwrap_err()
        .to_string()
}

/// `[simulation] contact_stiffness`: `inf` is rigid (the same digest as no key), a value that
/// is not > 0 is refused naming the field.
#[test]
fn scenario_contact_stiffness() {
    let digest = |k: &str| {
        let s = Scenario::from_toml(&cube_scenario(k)).unwrap();
        let mut w = s.build().unwrap();
        for _ in 0..50 {
            w.step();
        }
        (state_digest(&w.bodies), w.settings.contact_stiffness)
    };
    let (rigid, none) = digest("");
    assert_eq!(none, None);
    assert_eq!(digest("contact_stiffness = inf"), (rigid.clone(), None));
    let (soft, k) = digest("contact_stiffness = 1e5");
    assert_eq!(k, Some(1e5));
    assert_ne!(soft, rigid);
    for bad in ["0", "-1e7", "nan"] {
        let e = Scenario::from_toml(&cube_scenario(&format!("contact_stiffness = {bad}")))
            .and_then(|s| s.validate().map(|_| s))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("simulation.contact_stiffness") && e.contains("> 0 N/m"),
            "{bad}: {e}"
        );
    }
}

/// `[simulation] max_closure`: `inf` is the linear law (the same digest as no key), a value
/// changes the run, and one that is not > 0, or comes without `contact_stiffness`, is refused
/// naming the field.
#[test]
fn scenario_max_closure() {
    let digest = |k: &str| {
        let w = cube_scenario_run(k);
        (state_digest(&w.bodies), w.settings.max_closure)
    };
    let (linear, none) = digest("contact_stiffness = 1e5");
    assert_eq!(none, None);
    assert_eq!(
        digest("contact_stiffness = 1e5\nmax_closure = inf"),
        (linear.clone(), None)
    );
    let (hyperbolic, vm) = digest("contact_stiffness = 1e5\nmax_closure = 1e-4");
    assert_eq!(vm, Some(1e-4));
    assert_ne!(hyperbolic, linear);
    for bad in [
        "contact_stiffness = 1e5\nmax_closure = 0",
        "contact_stiffness = 1e5\nmax_closure = -1e-3",
        "contact_stiffness = 1e5\nmax_closure = nan",
        "max_closure = 1e-3",
    ] {
        let e = cube_scenario_refused(bad);
        assert!(e.contains("simulation.max_closure"), "{bad}: {e}");
    }
}

/// The cube of [`cube_on_floor`] started 2 mm deep in the floor, with compliant contacts of
/// 1e6 N/m and the overlap recovery `beta` (slop 0.1 mm): its height after each step.
fn sunk_cube_heights(beta: f64, steps: usize) -> (Vec<f64>, Vec<f64>, f64) {
    let (mut w, m) = cube_on_floor(Some(1e6), 0.6);
    w.settings.overlap_recovery = beta;
    w.settings.overlap_slop = 1e-4;
    w.bodies.position[1].z = 0.05 - 2e-3;
    let (mut z, mut vz) = (Vec::new(), Vec::new());
    for _ in 0..steps {
        let r = w.step();
        assert!(r.solve.converged, "{:?}", r.solve);
        z.push(w.bodies.position[1].z);
        vz.push(w.bodies.velocity[1].z);
    }
    (z, vz, m)
}

/// The rate form remembers forces, not overlaps: without the overlap recovery a cube started
/// 2 mm deep stays 2 mm deep. With it, the excess over the deflection `F/k` (beyond the slop)
/// decays within the step's recovery fraction, capped at `ω h / 16` (here `ω h` = 1.2, so
/// 7.6 % a step whatever β above that), and the cube comes to rest at `F/k + slop` without
/// ever leaving that height upward: no jump, no flight (uncapped, β = 0.2 threw it 5.8 mm
/// clear of the floor).
#[test]
fn the_overlap_recovery_lifts_a_sunk_block_without_a_jump() {
    let (z, _, m) = sunk_cube_heights(0.0, 3000);
    let deflection = m * G / (4.0 * 1e6);
    let rest = deflection + 1e-4;
    let overlap = |z: f64| 0.05 - z;
    assert!(overlap(z[2999]) > 2e-3, "{:e}", overlap(z[2999]));
    for beta in [0.2, 1.0] {
        let (z, vz, _) = sunk_cube_heights(beta, 3000);
        let end = overlap(z[2999]);
        assert!(
            (end - rest).abs() <= 1e-6 * rest,
            "β {beta}: {end:e} vs {rest:e}"
        );
        assert!(
            overlap(z[99]) - rest < 1e-5,
            "β {beta}: still {:e} m too deep after 100 steps",
            overlap(z[99]) - rest
        );
        let lowest = z.iter().map(|&z| overlap(z)).fold(f64::MAX, f64::min);
        assert!(
            lowest >= rest - 1e-9,
            "β {beta}: jumped to an overlap of {lowest:e}"
        );
        assert!(
            vz[2999].abs() < 1e-9,
            "β {beta}: still moving at {:e}",
            vz[2999]
        );
    }
}

/// With the overlap law the cube of [`cube_on_floor`] rests at its deflection, linear
/// (`m g / (4 k)`) and hyperbolic (`F V_m/(k V_m + F)`, the default cap 0.8 `V_m` above it):
/// a spring on the overlap has the rate form's equilibrium.
#[test]
fn the_overlap_law_rests_a_block_at_its_deflection() {
    let k = 1e6;
    let (mut w, m) = cube_on_floor(Some(k), 0.6);
    w.settings.normal_law = NormalLaw::Overlap;
    settles_at_its_deflection(&mut w, m, k);
    assert!(w.bodies.velocity[1].length() < 1e-9);

    let vm = 5e-6;
    let (mut w, m) = cube_on_floor(Some(k), 0.6);
    w.settings.normal_law = NormalLaw::Overlap;
    w.settings.max_closure = Some(vm);
    for _ in 0..3000 {
        assert!(w.step().solve.converged);
    }
    let f = m * G / 4.0;
    let expected = f * vm / (k * vm + f);
    let sink = 0.05 - w.bodies.position[1].z;
    assert!(
        (sink - expected).abs() <= 1e-6 * expected,
        "sank {sink:e} m, expected {expected:e} m"
    );
}

/// A 20 mm cube sliding without friction at 2 m/s on a plane of springs (1e4 N/m a corner):
/// its corners move 2 mm a step in the plane's frame, farther than a contact point is
/// recognised from one step to the next, so every step brings new points. The rate form
/// starts each new point from no force, and the cube sinks while it slides (measured: 10.6
/// mm in 2,000 steps, 2,000 times its deflection); the overlap law starts each point from the
/// force its overlap holds, and the cube rides at its deflection `m g / (4 k)` = 5.3 µm (to
/// 1e-9 of it, measured).
#[test]
fn a_sliding_block_rides_at_its_deflection_with_the_overlap_law() {
    let sink_after = |law: NormalLaw| {
        let mut bodies = BodySet::default();
        bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
        let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(0.01)).unwrap();
        cube.position = DVec3::new(0.0, 0.0, 0.01);
        let b = bodies.add_polyhedron(cube, 2700.0, BodyKind::Dynamic, 1);
        bodies.velocity[b] = DVec3::new(2.0, 0.0, 0.0);
        let m = bodies.mass(b);
        let k = 1e4;
        let settings = tight_settings(Some(k), law, None);
        let mut w = World::new(bodies, FrictionTable::new(0.0), settings);
        for _ in 0..2000 {
            assert!(w.step().solve.converged);
        }
        (0.01 - w.bodies.position[1].z, m * G / (4.0 * k))
    };
    let (sink, deflection) = sink_after(NormalLaw::Overlap);
    assert!(
        (sink - deflection).abs() <= 1e-6 * deflection,
        "overlap law: sank {sink:e} m, deflection {deflection:e} m"
    );
    let (sink, deflection) = sink_after(NormalLaw::Rate);
    assert!(
        sink > 100.0 * deflection,
        "rate form: sank {sink:e} m, deflection {deflection:e} m"
    );
}

/// Contacts of stiffness `k` (`None`: rigid) under `law` (and a maximum closure), θ = 0.6,
/// solved to a natural-map residual of 1e-10, the overlap correction off: only the law holds
/// the bodies.
fn tight_settings(k: Option<f64>, law: NormalLaw, max_closure: Option<f64>) -> StepSettings {
    StepSettings {
        dt: 1e-3,
        theta: 0.6,
        contact_stiffness: k,
        max_closure,
        normal_law: law,
        solver: SolverSettings {
            tolerance: 1e-10,
            max_iterations: 10_000,
            norm: ConvergenceNorm::NaturalMap,
            ..Default::default()
        },
        correction: CorrectionSettings {
            fraction: 0.0,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The overlap law's cap against a body that is not dynamic (`driven_overlap_cap`): a cube
/// pressing each of its four corners on a fixed floor with `6 k V_m`, above the grain cap's
/// `4 k V_m` (0.8 `V_m`) and below the driven cap's `9 k V_m` (0.9 `V_m`), rests at the
/// hyperbola's deflection `6/7 V_m` (to 1e-6 of it); the same cube on another cube (two
/// dynamic bodies, the grain cap) restarts each step below its load and sinks past `V_m`
/// (the correction off, so that only the law holds it).
#[test]
fn a_body_pressed_on_a_fixed_floor_rests_at_the_hyperbola_beyond_the_grain_cap() {
    let (k, vm, h) = (1e4, 1e-4, 0.01);
    let load = 6.0 * k * vm;
    let sink = |on_cube: bool| {
        let mut bodies = BodySet::default();
        bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
        let mut z = h;
        if on_cube {
            // A light cube on the floor: its corners carry the load and its own weight.
            let mut low = ConvexPolyhedron::cuboid(DVec3::splat(h)).unwrap();
            low.position = DVec3::new(0.0, 0.0, h);
            bodies.add_polyhedron(low, 100.0, BodyKind::Dynamic, 1);
            z = 3.0 * h;
        }
        let mut top = ConvexPolyhedron::cuboid(DVec3::splat(h)).unwrap();
        top.position = DVec3::new(0.0, 0.0, z);
        let density = 4.0 * load / G / (8.0 * h * h * h);
        let b = bodies.add_polyhedron(top, density, BodyKind::Dynamic, 1);
        let settings = tight_settings(Some(k), NormalLaw::Overlap, Some(vm));
        let mut w = World::new(bodies, FrictionTable::new(0.0), settings);
        for _ in 0..3000 {
            w.step();
        }
        let below = if on_cube {
            w.bodies.position[1].z + h
        } else {
            0.0
        };
        below + h - w.bodies.position[b].z
    };
    let on_floor = sink(false);
    let expected = 6.0 / 7.0 * vm;
    assert!(
        (on_floor - expected).abs() <= 1e-6 * expected,
        "on the floor: {on_floor:e} m, hyperbola {expected:e} m"
    );
    let on_cube = sink(true);
    assert!(on_cube > vm, "on a cube: {on_cube:e} m, V_m {vm:e} m");
}

/// `[simulation] normal_law` and `overlap_cap`: `"rate"` is the default (the same digest as no
/// key), `"overlap"` changes the run, and an overlap law without `contact_stiffness`, a cap
/// that is not > 0 or not below `max_closure`, or a cap without the overlap law, is refused
/// naming the field.
#[test]
fn scenario_normal_law() {
    let digest = |k: &str| {
        let w = cube_scenario_run(k);
        (state_digest(&w.bodies), w.settings.normal_law)
    };
    let (rate, law) = digest("contact_stiffness = 1e5");
    assert_eq!(law, NormalLaw::Rate);
    assert_eq!(
        digest("contact_stiffness = 1e5\nnormal_law = \"rate\""),
        (rate.clone(), NormalLaw::Rate)
    );
    let (overlap, law) = digest("contact_stiffness = 1e5\nnormal_law = \"overlap\"");
    assert_eq!(law, NormalLaw::Overlap);
    assert_ne!(overlap, rate);
    for (bad, field) in [
        ("normal_law = \"overlap\"", "simulation.normal_law"),
        ("contact_stiffness = 1e5\nnormal_law = \"spring\"", "normal_law"),
        (
            "contact_stiffness = 1e5\nnormal_law = \"overlap\"\noverlap_cap = 0",
            "simulation.overlap_cap",
        ),
        (
            "contact_stiffness = 1e5\nmax_closure = 1e-4\nnormal_law = \"overlap\"\noverlap_cap = 1e-4",
            "simulation.overlap_cap",
        ),
        (
            "contact_stiffness = 1e5\noverlap_cap = 1e-4",
            "simulation.overlap_cap",
        ),
    ] {
        let e = cube_scenario_refused(bad);
        assert!(e.contains(field), "{bad}: {e}");
    }
}

/// Residual checks that read back the terms of contacts whose bodies were not written since
/// the previous check (`solver.reuse_residual_terms`, on by default), and checks that first
/// add up the contacts hot at the previous check (`solver.hot_first`, on by default), change
/// no bit: the same sweeps, residuals and stop decisions on every step, the same final state,
/// monolithic and decomposed, with the default job's law (hyperbolic closure on the overlap,
/// recovery, tangential springs, skipping sweeps) and with the plain rigid law.
#[test]
fn shortcut_residual_checks_change_no_bit() {
    let ddm = DdmSettings {
        subdomains: [2, 2, 1],
        min_parallel_contacts: 1,
        ..Default::default()
    };
    let compliant = |w: &mut World| {
        w.settings.overlap_recovery = 0.2;
        w.settings.tangential_stiffness = Some(5e6);
        w.settings.solver.skip = 1.0;
        w.settings.max_closure = Some(1e-4);
        w.settings.normal_law = NormalLaw::Overlap;
    };
    for (label, stiffness, decomposed) in [
        ("compliant, monolithic", Some(1e7), false),
        ("compliant, DDM 2x2x1", Some(1e7), true),
        ("rigid, DDM 2x2x1", None, true),
    ] {
        let trace = |reuse: bool, hot: bool| {
            let mut w = pile(stiffness, decomposed.then(|| ddm.clone()));
            if stiffness.is_some() {
                compliant(&mut w);
            }
            w.settings.solver.reuse_residual_terms = reuse;
            w.settings.solver.hot_first = hot;
            let reports: Vec<_> = (0..1200).map(|_| w.step().solve).collect();
            (reports, state_digest(&w.bodies))
        };
        let (fresh, fresh_digest) = trace(false, false);
        let sweeps: usize = fresh.iter().map(|r| r.iterations).sum();
        assert!(
            sweeps > 3 * fresh.len(),
            "{label}: {sweeps} sweeps in 1,200 steps"
        );
        for (reuse, hot) in [(true, false), (false, true), (true, true)] {
            let (short, short_digest) = trace(reuse, hot);
            let case = format!("{label}, reuse {reuse}, hot first {hot}");
            for (k, (a, b)) in fresh.iter().zip(&short).enumerate() {
                assert_eq!(a.iterations, b.iterations, "{case}, step {k}");
                assert_eq!(
                    a.residual.to_bits(),
                    b.residual.to_bits(),
                    "{case}, step {k}"
                );
                assert_eq!(a.residual_checks, b.residual_checks, "{case}, step {k}");
                assert_eq!(a.quad.to_bits(), b.quad.to_bits(), "{case}, step {k}");
                assert_eq!(a.converged, b.converged, "{case}, step {k}");
            }
            assert_eq!(fresh_digest, short_digest, "{case}");
            // The shortcut was taken: most failing checks were proven on the hot contacts
            // alone (82 % monolithic, 87 % on the decomposed piles when measured).
            let checks: usize = short.iter().map(|r| r.residual_checks).sum();
            let failed = checks - short.iter().filter(|r| r.converged).count();
            let proofs: usize = short.iter().map(|r| r.hot_proofs).sum();
            if hot {
                assert!(
                    proofs * 2 > failed,
                    "{case}: {proofs} of {failed} failing checks proven hot"
                );
            } else {
                assert_eq!(proofs, 0, "{case}");
            }
        }
    }
}
