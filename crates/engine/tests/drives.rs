//! Force-limited drives (`Driver::max_force`): a pusher driving a block along a floor follows
//! its program while the force it needs, `μ m g`, is below its limit, and stalls at exactly
//! its limit beyond; a part attached to the pusher passes its contact forces to it; unlimited
//! drives are kinematic bodies bit for bit; the same digest on 1 and 2 threads, monolithic and
//! under domain decomposition.

mod common;

use ballast_engine::bodies::{BodyKind, BodySet, Driver, Term};
use ballast_engine::digest::state_digest;
use ballast_engine::laws::FrictionTable;
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{DdmSettings, SolverSettings};
use ballast_engine::world::{StepSettings, World};

const G: f64 = 9.81;
const RHO: f64 = 2700.0;
const FLOOR: u32 = 0;
const BLOCK: u32 = 1;
const PUSHER: u32 = 2;
const RAMP: f64 = 0.05;

/// The pusher's programmed displacement at `t` (exact for the θ = 0.5 update: the velocity
/// is piecewise linear with its kink on a step).
fn program(speed: f64, t: f64) -> f64 {
    if t <= RAMP {
        0.5 * speed * t * t / RAMP
    } else {
        speed * (t - 0.5 * RAMP)
    }
}

fn settings(dt: f64) -> StepSettings {
    StepSettings {
        dt,
        solver: SolverSettings {
            tolerance: 1e-10,
            max_iterations: 10_000,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn friction(mu: f64) -> FrictionTable {
    let mut f = FrictionTable::new(0.0);
    f.set(FLOOR, BLOCK, mu);
    f
}

/// Floor, a 0.1 m cube resting on it (2.7 kg), and a pusher plate touching its −x face,
/// driven at `speed` along x with the force limit `max_force` (N); returns the world and the
/// block's and pusher's indices. With `attached`, the plate is a part attached to a pusher
/// body 0.3 m above it (the plate has no drive of its own).
fn pusher_world(speed: f64, max_force: f64, attached: bool) -> (World, usize, usize) {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, FLOOR);
    let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(0.05)).unwrap();
    cube.position = DVec3::new(0.0, 0.0, 0.05);
    let block = bodies.add_polyhedron(cube, RHO, BodyKind::Dynamic, BLOCK);
    let mut plate = ConvexPolyhedron::cuboid(DVec3::new(0.01, 0.06, 0.04)).unwrap();
    plate.position = DVec3::new(-0.06, 0.0, 0.05);
    let plate_id = bodies.add_polyhedron(plate, 7850.0, BodyKind::Kinematic, PUSHER);
    // From rest to `speed` in RAMP seconds (50 steps), then constant.
    let driver = Driver {
        vx: vec![Term::Ramp {
            start: 0.0,
            end: RAMP,
            from: 0.0,
            to: speed,
        }],
        max_force: [max_force, f64::INFINITY, f64::INFINITY],
        ..Default::default()
    };
    let pusher = if attached {
        let mut arm = ConvexPolyhedron::cuboid(DVec3::new(0.01, 0.01, 0.1)).unwrap();
        arm.position = DVec3::new(-0.06, 0.0, 0.35);
        let arm_id = bodies.add_polyhedron(arm, 7850.0, BodyKind::Kinematic, PUSHER);
        bodies.driver[arm_id] = Some(Box::new(driver));
        bodies.driver[plate_id] = Some(Box::new(Driver {
            attached_to: Some(arm_id),
            ..Default::default()
        }));
        arm_id
    } else {
        bodies.driver[plate_id] = Some(Box::new(driver));
        plate_id
    };
    (
        World::new(bodies, friction(0.5), settings(1e-3)),
        block,
        pusher,
    )
}

/// Below its limit the pusher follows its program exactly and pushes the block with
/// `μ m g`; with a limit under `μ m g` it stalls (the block stays), pushing with exactly its
/// limit, and lags its program. The same through an attached plate.
#[test]
fn pusher_follows_below_its_limit_and_stalls_at_it() {
    for attached in [false, true] {
        let (speed, mu) = (0.05, 0.5);
        // Limit above the friction force: the pusher follows.
        let (mut w, block, pusher) = pusher_world(speed, 100.0, attached);
        let m = w.bodies.mass(block);
        let x0 = w.bodies.position[pusher].x;
        let (mut f_sum, mut n) = (0.0, 0);
        for k in 0..300 {
            w.step();
            let t = w.time;
            // Exact program, to rounding (the drive meets an unsaturated row exactly).
            let x = w.bodies.position[pusher].x;
            assert!(
                (x - (x0 + program(speed, t))).abs() < 1e-9,
                "attached {attached}: pusher x = {x} at t = {t}, program {}",
                x0 + program(speed, t)
            );
            assert_eq!(w.drives().len(), 1);
            let f = w.drives()[0].impulse_v / w.settings.dt;
            assert!(f.x <= 100.0 * (1.0 + 1e-12), "force {f}");
            // Once the block slides steadily (after the ramp), the drive pushes with the
            // sliding friction force.
            if k >= 60 {
                f_sum += f.x;
                n += 1;
            }
        }
        let f_mean = f_sum / n as f64;
        let friction_force = mu * m * G;
        assert!(
            (f_mean - friction_force).abs() < 5e-3 * friction_force,
            "attached {attached}: drive force {f_mean} N, μ m g = {friction_force} N"
        );
        assert!(w.report_ok());

        // Limit under the friction force (90 %): the block stays, the pusher stalls.
        let limit = 0.9 * mu * m * G;
        let (mut w, block, pusher) = pusher_world(speed, limit, attached);
        let bx0 = w.bodies.position[block].x;
        for _ in 0..300 {
            w.step();
            let f = w.drives()[0].impulse_v.x / w.settings.dt;
            assert!(f <= limit * (1.0 + 1e-12), "{f} > {limit}");
        }
        let f = w.drives()[0].impulse_v.x / w.settings.dt;
        assert!(
            (f - limit).abs() < 5e-3 * limit,
            "attached {attached}: stalled drive force {f} N, limit {limit} N"
        );
        let lag = x0 + program(speed, w.time) - w.bodies.position[pusher].x;
        assert!(
            lag > 0.9 * program(speed, w.time),
            "pusher lags by {lag} m only"
        );
        assert!(
            (w.bodies.position[block].x - bx0).abs() < 1e-6,
            "the block moved by {} m",
            w.bodies.position[block].x - bx0
        );
    }
}

/// The work a drive reports is the energy it put in: pushing the block along the floor, the
/// pusher's work equals the kinetic energy of the block and of the pusher's own mass plus the
/// friction work `μ m g Δx` (to the solver's tolerance: the discrete balance is exact for
/// θ = 0.5); a pusher stalled against a block it cannot move does no work.
#[test]
fn drive_work_is_kinetic_energy_plus_friction_work() {
    for attached in [false, true] {
        let (speed, mu) = (0.05, 0.5);
        let (mut w, block, pusher) = pusher_world(speed, 100.0, attached);
        let m = w.bodies.mass(block);
        let bx0 = w.bodies.position[block].x;
        assert_eq!(w.drive_work(pusher), 0.0);
        for _ in 0..300 {
            w.step();
        }
        let kinetic = |i: usize| 0.5 * w.bodies.velocity[i].length_squared() / w.bodies.inv_mass[i];
        let balance =
            kinetic(block) + kinetic(pusher) + mu * m * G * (w.bodies.position[block].x - bx0);
        let work = w.drive_work(pusher);
        assert!(
            (work - balance).abs() <= 1e-6 * balance,
            "attached {attached}: drive work {work} J, kinetic energy + friction work {balance} J"
        );
        assert_eq!(w.drive_work(block), 0.0, "the block has no drive");

        let (mut w, _, pusher) = pusher_world(speed, 0.9 * mu * m * G, attached);
        for _ in 0..300 {
            w.step();
        }
        // Only the ramp before the block pressed back moved the pusher: work of the order of
        // the limit times a few micrometres.
        let stalled = w.drive_work(pusher);
        assert!(
            stalled.abs() < 1e-3 * balance,
            "attached {attached}: a stalled pusher did {stalled} J"
        );
    }
}

trait ReportOk {
    fn report_ok(&self) -> bool;
}

impl ReportOk for World {
    /// The pusher plate never goes through the block (no overlap beyond 0.1 mm).
    fn report_ok(&self) -> bool {
        self.contacts.gap.iter().all(|&g| g > -1e-4)
    }
}

/// A paddle with a horizontal force limit stirs a small pile: the run exercises drive rows
/// that saturate and rows that do not.
fn stirred_pile(ddm: Option<[usize; 3]>, limit: f64) -> World {
    let mut bodies = common::open_box(0.2);
    let mut paddle = ConvexPolyhedron::cuboid(DVec3::new(0.005, 0.05, 0.03)).unwrap();
    paddle.position = DVec3::new(0.03, 0.1, 0.05);
    let pd = bodies.add_polyhedron(paddle, 7850.0, BodyKind::Kinematic, 2);
    bodies.driver[pd] = Some(Box::new(Driver {
        vx: vec![Term::Constant { value: 0.5 }],
        vz: vec![Term::Sine {
            amplitude: 0.2,
            frequency: 20.0,
            phase: 0.0,
            start: 0.0,
            end: f64::INFINITY,
        }],
        max_force: [limit, f64::INFINITY, 4.0 * limit],
        ..Default::default()
    }));
    let pack = GrainPack {
        count: 60,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.2, 0.2],
        diameter: [0.02, 0.03],
        vertices: [8, 12],
        elongation: 1.0,
        flatness: 1.0,
        seed: 7,
    };
    common::pour(&mut bodies, &pack, RHO, 1);
    let mut s = StepSettings {
        dt: 5e-4,
        solver: SolverSettings {
            tolerance: 1e-4,
            max_iterations: 200,
            ..Default::default()
        },
        ..Default::default()
    };
    s.ddm = ddm.map(|subdomains| DdmSettings {
        subdomains,
        min_parallel_contacts: 0,
        ..Default::default()
    });
    World::new(bodies, FrictionTable::new(0.8), s)
}

fn run_on(threads: usize, ddm: Option<[usize; 3]>, limit: f64, steps: usize) -> (String, f64) {
    run_with(threads, ddm, limit, steps, true)
}

/// [`run_on`], residual terms reused (`solver.reuse_residual_terms`) or not.
fn run_with(
    threads: usize,
    ddm: Option<[usize; 3]>,
    limit: f64,
    steps: usize,
    reuse: bool,
) -> (String, f64) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut w = stirred_pile(ddm, limit);
        w.settings.solver.reuse_residual_terms = reuse;
        let mut peak: f64 = 0.0;
        for _ in 0..steps {
            w.step();
            let f = w.drives()[0].impulse_v / w.settings.dt;
            peak = peak.max(f.x.abs());
            assert!(f.x.abs() <= limit * (1.0 + 1e-12));
        }
        (state_digest(&w.bodies), peak)
    })
}

/// Force-limited drives change nothing with the thread count, monolithic or decomposed, and
/// the paddle's limit is reached (so the clamped rows are exercised).
#[test]
fn force_limited_runs_do_not_depend_on_threads() {
    let (steps, limit) = (400, 2.0);
    let (mono1, peak) = run_on(1, None, limit, steps);
    assert!(
        peak > 0.99 * limit,
        "the limit was never reached ({peak} N)"
    );
    let (mono2, _) = run_on(2, None, limit, steps);
    assert_eq!(mono1, mono2, "monolithic, 1 vs 2 threads");
    let (ddm1, _) = run_on(1, Some([2, 2, 1]), limit, steps);
    let (ddm2, _) = run_on(2, Some([2, 2, 1]), limit, steps);
    assert_eq!(ddm1, ddm2, "DDM 2x2x1, 1 vs 2 threads");
    // The drive rows write their body every pass: residual terms read back across them
    // change nothing.
    assert_eq!(
        mono1,
        run_with(2, None, limit, steps, false).0,
        "monolithic"
    );
    assert_eq!(
        ddm1,
        run_with(2, Some([2, 2, 1]), limit, steps, false).0,
        "DDM"
    );
}

/// A drive whose limits are all infinite is the kinematic body, bit for bit, and a driver
/// written without limits reads as unlimited.
#[test]
fn unlimited_drives_are_kinematic_bodies_bit_for_bit() {
    let run = |explicit: bool| {
        let mut w = stirred_pile(None, 1.0);
        let d = w.bodies.driver[5].as_mut().unwrap();
        d.max_force = if explicit {
            [f64::INFINITY; 3]
        } else {
            Driver::default().max_force
        };
        for _ in 0..200 {
            w.step();
        }
        assert!(w.drives().is_empty());
        state_digest(&w.bodies)
    };
    assert_eq!(run(true), run(false));
    // And the same world with no limit field at all reads as unlimited.
    let d: Driver = toml::from_str("vx = [{ constant = { value = 1.0 } }]").unwrap();
    assert!(!d.is_force_limited());
    let d: Driver = toml::from_str("max_force = [10.0, inf, inf]").unwrap();
    assert!(d.limits_translation() && !d.limits_rotation());
}

/// When the free pusher's program jumps from rest to its speed: over one step.
const JUMP: (f64, f64) = (0.010, 0.011);

/// The free pusher's programmed displacement at `t` (exact for the θ = 0.5 update).
fn jump_program(speed: f64, t: f64) -> f64 {
    let (a, b) = JUMP;
    if t <= a {
        0.0
    } else if t <= b {
        0.5 * speed * (t - a) * (t - a) / (b - a)
    } else {
        speed * (t - 0.5 * (a + b))
    }
}

/// A plate alone, driven along x from rest to `speed` within one step ([`JUMP`]) with the
/// force limit `max_force` (N) and the catch-up speed `catch_up` (m/s); returns the world and
/// the plate's index.
fn free_pusher(speed: f64, max_force: f64, catch_up: f64) -> (World, usize) {
    let mut bodies = BodySet::default();
    let mut plate = ConvexPolyhedron::cuboid(DVec3::new(0.01, 0.06, 0.04)).unwrap();
    plate.position = DVec3::new(0.0, 0.0, 1.0);
    let id = bodies.add_polyhedron(plate, 7850.0, BodyKind::Kinematic, PUSHER);
    bodies.driver[id] = Some(Box::new(Driver {
        vx: vec![Term::Ramp {
            start: JUMP.0,
            end: JUMP.1,
            from: 0.0,
            to: speed,
        }],
        max_force: [max_force, f64::INFINITY, f64::INFINITY],
        catch_up_speed: [catch_up, 0.0, 0.0],
        ..Default::default()
    }));
    (World::new(bodies, friction(0.0), settings(1e-3)), id)
}

/// A drive that cannot follow a jump in its program's velocity lags behind it: with no catch
/// up by `V² m / (2F)` for good (the distance lost while accelerating at `F/m`), and the lag
/// the world reports is the program's displacement less the body's; with a catch-up speed
/// `c` it makes the distance up, never faster than `V + c`, and ends on its program's
/// position without overshooting it.
#[test]
fn a_position_servo_makes_up_the_distance_its_drive_lost() {
    let (speed, force) = (0.2, 0.5);
    let (mut w, p) = free_pusher(speed, force, 0.0);
    let m = w.bodies.mass(p);
    let x0 = w.bodies.position[p].x;
    for _ in 0..1000 {
        w.step();
        let lag = x0 + jump_program(speed, w.time) - w.bodies.position[p].x;
        assert!(
            (w.drive_lag(p).x - lag).abs() < 1e-12,
            "reported lag {} m, geometric {lag} m",
            w.drive_lag(p).x
        );
    }
    // Discrete: the velocity climbs by F h / m a step; the continuous value is V² m / (2F).
    let expected = speed * speed * m / (2.0 * force);
    let lag = w.drive_lag(p).x;
    assert!(
        (lag - expected).abs() < 0.02 * expected,
        "lag {lag} m, V² m / (2F) = {expected} m"
    );
    assert_eq!(w.bodies.velocity[p].x, speed);

    let catch_up = 0.1;
    let (mut w, p) = free_pusher(speed, force, catch_up);
    let (mut caught, mut peak) = (None, 0.0f64);
    for k in 0..3000 {
        w.step();
        let v = w.bodies.velocity[p].x;
        peak = peak.max(v);
        assert!(v <= speed + catch_up + 1e-12, "step {k}: {v} m/s");
        let lag = x0 + jump_program(speed, w.time) - w.bodies.position[p].x;
        assert!(
            (w.drive_lag(p).x - lag).abs() < 1e-12,
            "reported lag {}, geometric {lag}",
            w.drive_lag(p).x
        );
        // No overshoot beyond the braking's discretisation, `a h²` (measured: 1.3e-8 m, one
        // step, then on the program to rounding).
        assert!(
            lag > -force / m * 1e-6,
            "step {k}: {lag} m ahead of the program"
        );
        if caught.is_none() && lag.abs() < 1e-9 {
            caught = Some(k);
        }
    }
    let caught = caught.expect("the servo never caught up");
    assert!(peak > speed + 0.99 * catch_up, "peak speed {peak} m/s");
    let end = x0 + jump_program(speed, w.time);
    assert!(
        (w.bodies.position[p].x - end).abs() < 1e-9,
        "ends {} m from its program",
        w.bodies.position[p].x - end
    );
    assert!((w.bodies.velocity[p].x - speed).abs() < 1e-9);
    assert!(caught < 2500, "caught up at step {caught}");
}

/// A run with a catching-up drive resumes from a checkpoint bit-identical: the lag is state.
#[test]
fn a_catching_up_drive_resumes_bit_identical() {
    use ballast_engine::output::checkpoint::{read_checkpoint, write_checkpoint};
    let (mut straight, _) = free_pusher(0.2, 0.5, 0.1);
    let (mut first, p) = free_pusher(0.2, 0.5, 0.1);
    for _ in 0..400 {
        straight.step();
        first.step();
    }
    assert!(first.drive_lag(p).x > 1e-3, "lag {}", first.drive_lag(p).x);
    let dir = std::env::temp_dir().join(format!("ballast-drives-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("lag.bin");
    write_checkpoint(&first, &path).unwrap();
    let (mut resumed, _) = free_pusher(0.2, 0.5, 0.1);
    read_checkpoint(&path, &mut resumed).unwrap();
    assert_eq!(resumed.drive_lag(p), first.drive_lag(p));
    for _ in 0..400 {
        straight.step();
        resumed.step();
    }
    assert_eq!(
        state_digest(&resumed.bodies),
        state_digest(&straight.bodies)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
