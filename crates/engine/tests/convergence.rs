//! What a converged step means: every step a run calls converged has a relative natural-map
//! residual at most `residual_tolerance`, whatever norm stopped the sweeps; a body resting
//! within the alert distance of the floor settles onto it (Signorini on the predicted gap)
//! and carries its weight.

mod common;

use ballast_engine::bodies::{BodyKind, BodySet};
use ballast_engine::laws::FrictionTable;
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{ConvergenceNorm, CorrectionSettings, SolverSettings};
use ballast_engine::world::{StepSettings, World};

fn pile(norm: ConvergenceNorm) -> World {
    let mut bodies = common::open_box(0.15);
    let pack = GrainPack {
        count: 80,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.15, 0.15],
        diameter: [0.025, 0.04],
        vertices: [10, 14],
        elongation: 1.3,
        flatness: 1.1,
        seed: 11,
    };
    common::pour(&mut bodies, &pack, 2700.0, 1);
    let settings = StepSettings {
        dt: 5e-4,
        solver: SolverSettings {
            tolerance: 1e-3,
            max_iterations: 400,
            norm,
            ..Default::default()
        },
        ..Default::default()
    };
    World::new(bodies, FrictionTable::new(0.8), settings)
}

/// A pile poured and settling: with either stop norm, no step is called converged unless its
/// natural-map residual is within 1e-3, and once at rest the steps converge.
#[test]
fn converged_steps_meet_the_residual_tolerance() {
    for norm in [ConvergenceNorm::Quad, ConvergenceNorm::NaturalMap] {
        let mut w = pile(norm);
        let (mut converged, mut tail_converged) = (0, 0);
        let steps = 4000;
        for k in 0..steps {
            let r = w.step();
            if r.solve.converged {
                converged += 1;
                assert!(
                    r.solve.residual <= 1e-3,
                    "{norm:?}: step {} called converged with residual {:.3e}",
                    r.step,
                    r.solve.residual
                );
                if k >= steps - 200 {
                    tail_converged += 1;
                }
            }
        }
        eprintln!(
            "{norm:?}: {converged} of {steps} steps converged, {tail_converged} of the last 200"
        );
        assert!(
            converged > steps * 9 / 10,
            "{norm:?}: {converged} of {steps}"
        );
        // At rest every step converges (measured: 200 of 200 with either stop norm; 1.2 s
        // into the run, still settling, 192 of 200 with the Quad stop).
        assert_eq!(
            tail_converged, 200,
            "{norm:?}: {tail_converged} of the last 200 steps converged"
        );
        // At rest by then.
        eprintln!("kinetic energy {:.3e} J", w.bodies.kinetic_energy());
        assert!(
            w.bodies.kinetic_energy() < 1e-4,
            "{}",
            w.bodies.kinetic_energy()
        );
    }
}

/// A cube released 0.2 mm above the floor (within the alert distance) falls onto it and
/// rests on it: no hovering at the gap the contact had when it was first predicted to close,
/// and the floor carries the cube's weight.
#[test]
fn a_body_within_the_alert_distance_settles_onto_the_floor() {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    let half = 0.025;
    let mut cube = ConvexPolyhedron::cuboid(DVec3::splat(half)).unwrap();
    cube.position = DVec3::new(0.0, 0.0, half + 2e-4);
    let c = bodies.add_polyhedron(cube, 2700.0, BodyKind::Dynamic, 1);
    let settings = StepSettings {
        dt: 1e-3,
        solver: SolverSettings {
            tolerance: 1e-12,
            max_iterations: 1000,
            ..Default::default()
        },
        // No position correction: the velocity law alone must bring the cube down.
        correction: CorrectionSettings {
            fraction: 0.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut w = World::new(bodies, FrictionTable::new(0.5), settings);
    let mut overlapped = 0;
    for _ in 0..100 {
        let r = w.step();
        if r.max_penetration > 0.0 {
            // The report names the two bodies of the deepest overlap.
            let mut pair = r.deepest;
            pair.sort_unstable();
            assert_eq!(pair, [0, c as u32]);
            overlapped += 1;
        }
    }
    assert!(overlapped > 0);
    let gap = w.bodies.position[c].z - half;
    // The impact leaves an overlap of at most h v (v ≈ √(2 g 0.2 mm) = 0.063 m/s here): the
    // step that closes the predicted gap g + hθ u ends h (1 − θ) v past it, and the next one
    // moves by the remaining closing speed's (1 − θ) share. No correction undoes it here.
    let v_impact = (2.0 * 9.81 * 2e-4f64).sqrt();
    assert!(
        gap <= 0.0 && gap > -1e-3 * v_impact,
        "the cube rests {gap:.3e} m above the floor"
    );
    assert!(w.bodies.velocity[c].length() < 1e-12);
    let m = w.bodies.mass(c);
    let rn: f64 = w.contacts.impulse.iter().map(|r| r.x).sum();
    let weight = m * 9.81 * w.settings.dt;
    assert!((rn - weight).abs() < 1e-9 * weight, "{rn} vs {weight}");
}
