//! The domain decomposition shared between ranks ([`ballast_engine::solver::exchange`]): K
//! in-process ranks ([`ThreadRanks`]), each stepping its own copy of a scene, give on every
//! rank the bodies, impulses, sweep counts and residuals of one process with the same
//! partition, bit for bit — with compliant contacts and the overlap correction, with a
//! force-limited drive, with the interface solved in one group, for K = 2, 3, 4.

mod common;

use ballast_engine::bodies::{BodyKind, Driver, Term};
use ballast_engine::digest::state_digest;
use ballast_engine::laws::{FrictionTable, NormalLaw};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{
    ConvergenceNorm, DdmSettings, Exchange, SolveReport, SolverSettings, ThreadRanks,
};
use ballast_engine::world::{StepSettings, World};
use std::sync::Arc;

/// A pile of 150 grains settling at μ = 1 with the default job's contact law (compliant,
/// overlap law, hyperbolic closure, recovery), decomposed into `subdomains`; with `paddle`, a
/// force-limited paddle stirs it (its drive row is solved after the interface).
fn pile(subdomains: [usize; 3], parallel_interface: bool, paddle: bool) -> World {
    let mut bodies = common::open_box(0.2);
    if paddle {
        let mut p = ConvexPolyhedron::cuboid(DVec3::new(0.005, 0.05, 0.03)).unwrap();
        p.position = DVec3::new(0.03, 0.1, 0.05);
        let i = bodies.add_polyhedron(p, 7850.0, BodyKind::Kinematic, 2);
        bodies.driver[i] = Some(Driver {
            vx: vec![Term::Constant { value: 0.5 }],
            vz: vec![Term::Sine {
                amplitude: 0.2,
                frequency: 20.0,
                phase: 0.0,
                start: 0.0,
                end: f64::INFINITY,
            }],
            max_force: [2.0, f64::INFINITY, 8.0],
            ..Default::default()
        });
    }
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
        contact_stiffness: Some(1e7),
        tangential_stiffness: Some(5e6),
        overlap_recovery: 0.2,
        max_closure: Some(1e-4),
        normal_law: NormalLaw::Overlap,
        solver: SolverSettings {
            tolerance: 1e-3,
            max_iterations: 300,
            norm: ConvergenceNorm::NaturalMap,
            ..Default::default()
        },
        ddm: Some(DdmSettings {
            subdomains,
            parallel_interface,
            // Every phase dispatched to the workers, as on many cores.
            min_parallel_contacts: 0,
            ..Default::default()
        }),
        ..Default::default()
    };
    World::new(bodies, FrictionTable::new(1.0), settings)
}

/// What a run leaves: each step's solve, the bodies' digest, the impulses' bits, and the
/// seconds its ranks spent sharing.
#[derive(Debug, PartialEq)]
struct Trace {
    solves: Vec<SolveReport>,
    digest: String,
    impulses: Vec<[u64; 3]>,
}

fn trace(w: &mut World, steps: usize) -> (Trace, f64) {
    let solves = (0..steps).map(|_| w.step().solve).collect();
    let impulses = w
        .contacts
        .impulse
        .iter()
        .map(|r| [r.x.to_bits(), r.y.to_bits(), r.z.to_bits()])
        .collect();
    let t = Trace {
        solves,
        digest: state_digest(&w.bodies),
        impulses,
    };
    (t, w.timers.communication)
}

/// Runs `make()`'s scene on `k` in-process ranks; every rank's trace.
fn on_ranks(k: usize, steps: usize, make: fn() -> World) -> Vec<(Trace, f64)> {
    let handles: Vec<_> = ThreadRanks::group(k)
        .into_iter()
        .map(|r| {
            std::thread::spawn(move || {
                let mut w = make();
                let ex: Arc<dyn Exchange> = Arc::new(r);
                w.set_exchange(Some(ex));
                trace(&mut w, steps)
            })
        })
        .collect();
    handles.into_iter().map(|h| h.join().unwrap()).collect()
}

fn assert_same(label: &str, make: fn() -> World, steps: usize, ranks: &[usize]) {
    let (alone, comm) = trace(&mut make(), steps);
    assert_eq!(comm, 0.0, "{label}: one process shares nothing");
    let sweeps: usize = alone.solves.iter().map(|r| r.iterations).sum();
    assert!(
        sweeps > 3 * steps,
        "{label}: {sweeps} sweeps in {steps} steps: too few to test the sharing"
    );
    for &k in ranks {
        for (rank, (t, comm)) in on_ranks(k, steps, make).into_iter().enumerate() {
            assert!(comm > 0.0, "{label}, {k} ranks: rank {rank} shared nothing");
            for (s, (a, b)) in alone.solves.iter().zip(&t.solves).enumerate() {
                assert_eq!(
                    (a.iterations, a.residual.to_bits(), a.quad.to_bits()),
                    (b.iterations, b.residual.to_bits(), b.quad.to_bits()),
                    "{label}, {k} ranks, rank {rank}, step {s}"
                );
            }
            assert_eq!(alone, t, "{label}, {k} ranks, rank {rank}");
        }
    }
}

#[test]
fn compliant_pile_on_ranks_is_bit_identical() {
    assert_same(
        "compliant pile, 2x2x1",
        || pile([2, 2, 1], true, false),
        700,
        &[2, 3, 4],
    );
}

#[test]
fn more_ranks_than_a_row_of_subdomains() {
    assert_same(
        "compliant pile, 3x2x1",
        || pile([3, 2, 1], true, false),
        600,
        &[4],
    );
}

#[test]
fn force_limited_drive_on_ranks_is_bit_identical() {
    assert_same(
        "stirred pile, 2x2x1",
        || pile([2, 2, 1], true, true),
        600,
        &[2, 3],
    );
}

#[test]
fn one_interface_group_on_ranks_is_bit_identical() {
    assert_same(
        "compliant pile, 2x2x1, sequential interface",
        || pile([2, 2, 1], false, false),
        600,
        &[2],
    );
}
