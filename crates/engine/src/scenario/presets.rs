//! Ready-made scenarios shared by tests, benchmarks and examples.

use super::{
    BodySpec, Friction, FrictionPair, GrainPack, GrainsSpec, Scenario, ShapeKind, Simulation,
};
use crate::bodies::BodyKind;
use crate::solver::SolverSettings;
use std::collections::BTreeMap;

/// Random ballast grains (12–20 vertices, equivalent diameters `[d_min, d_max]`) poured from a
/// loose lattice into a square box of half-spaces (floor and four walls), about five layers
/// high. Friction μ = 1 grain–grain, 0.8 grain–wall; density 2700 kg/m³; dt = 2e-4 s.
pub fn pile(grains: usize, diameter: [f64; 2], seed: u64, steps: u64) -> Scenario {
    // Lattice pitch ≈ 2 × 1.02 × circumradius, and random grains of volume-equivalent diameter d
    // have circumradii up to ≈ 0.75 d.
    let pitch = 1.53 * diameter[1];
    let side = ((grains as f64 / 5.0).sqrt().ceil().max(2.0)) * pitch + 1e-3;
    let wall = |point: [f64; 3], normal: [f64; 3]| BodySpec {
        shape: ShapeKind::Plane,
        kind: BodyKind::Fixed,
        group: "wall".into(),
        material: None,
        vertices: None,
        half_extents: None,
        center: None,
        rotation: None,
        point: Some(point),
        normal: Some(normal),
        velocity: None,
        angular_velocity: None,
        driver: None,
    };
    Scenario {
        simulation: Simulation {
            dt: 2e-4,
            steps: Some(steps),
            duration: None,
            theta: 0.5,
            gravity: [0.0, 0.0, -9.81],
            alert: 1e-3,
            reuse_distance: crate::world::default_reuse_distance(),
            contact_stiffness: None,
            tangential_stiffness: None,
            max_closure: None,
            normal_law: Default::default(),
            overlap_cap: None,
            overlap_recovery: crate::world::default_overlap_recovery(),
            overlap_slop: crate::world::default_overlap_slop(),
            output_interval: 50,
            checkpoint_interval: 1000,
            vtk_interval: 500,
            max_speed: None,
            max_overlap: None,
        },
        solver: SolverSettings {
            tolerance: 1e-4,
            max_iterations: 200,
            ..Default::default()
        },
        correction: Default::default(),
        ddm: None,
        materials: BTreeMap::from([("stone".to_string(), 2700.0)]),
        friction: Friction {
            default: 1.0,
            pairs: vec![FrictionPair {
                groups: ["grain".into(), "wall".into()],
                mu: 0.8,
            }],
        },
        bodies: vec![
            wall([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
            wall([side, 0.0, 0.0], [-1.0, 0.0, 0.0]),
            wall([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            wall([0.0, side, 0.0], [0.0, -1.0, 0.0]),
        ],
        grains: vec![GrainsSpec {
            pack: GrainPack {
                count: grains,
                min: [0.0, 0.0, 0.002],
                max_xy: [side, side],
                diameter,
                vertices: [12, 20],
                elongation: 1.0,
                flatness: 1.0,
                seed,
            },
            material: "stone".into(),
            group: "grain".into(),
        }],
    }
}
