//! Fixtures shared by the engine's test files.
#![allow(dead_code)]

use ballast_engine::bodies::{BodyKind, BodySet, Driver, Term};
use ballast_engine::laws::{FrictionTable, NormalLaw};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;
use ballast_engine::shapes::ConvexPolyhedron;
use ballast_engine::solver::{ConvergenceNorm, DdmSettings, SolverSettings};
use ballast_engine::world::{StepSettings, World};

/// A floor and four walls (group 0): a box `side` × `side` wide, open at the top, its corner at
/// the origin.
pub fn open_box(side: f64) -> BodySet {
    open_trench(side, side)
}

/// A floor and four walls (group 0): a box `length` × `width` (along x, y), open at the top,
/// its corner at the origin.
pub fn open_trench(length: f64, width: f64) -> BodySet {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    for (p, n) in [
        (DVec3::ZERO, DVec3::X),
        (DVec3::new(length, 0.0, 0.0), -DVec3::X),
        (DVec3::ZERO, DVec3::Y),
        (DVec3::new(0.0, width, 0.0), -DVec3::Y),
    ] {
        bodies.add_plane(p, n, 0);
    }
    bodies
}

/// Adds the grains of `pack` as dynamic bodies of density `rho` (kg/m³) in `group`.
pub fn pour(bodies: &mut BodySet, pack: &GrainPack, rho: f64, group: u32) {
    for g in pack.build().unwrap() {
        bodies.add_polyhedron(g, rho, BodyKind::Dynamic, group);
    }
}

/// A pile of 150 grains settling at μ = 1 with the default job's contact law (compliant,
/// overlap law, hyperbolic closure, recovery), decomposed into `subdomains`; with `paddle`, a
/// force-limited paddle stirs it (its drive row is solved after the interface).
pub fn compliant_pile(subdomains: [usize; 3], parallel_interface: bool, paddle: bool) -> World {
    let mut bodies = open_box(0.2);
    if paddle {
        let mut p = ConvexPolyhedron::cuboid(DVec3::new(0.005, 0.05, 0.03)).unwrap();
        p.position = DVec3::new(0.03, 0.1, 0.05);
        let i = bodies.add_polyhedron(p, 7850.0, BodyKind::Kinematic, 2);
        bodies.driver[i] = Some(Box::new(Driver {
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
        }));
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
    pour(&mut bodies, &pack, 2700.0, 1);
    compliant(bodies, subdomains, parallel_interface)
}

/// 250 grains settling at μ = 1 in a trench 0.8 m long and 0.1 m wide, with the law and
/// solver of [`compliant_pile`], decomposed into `subdomains`.
pub fn compliant_trench(subdomains: [usize; 3]) -> World {
    let mut bodies = open_trench(0.8, 0.1);
    let pack = GrainPack {
        count: 250,
        min: [0.0, 0.0, 0.002],
        max_xy: [0.8, 0.1],
        diameter: [0.025, 0.045],
        vertices: [10, 16],
        elongation: 1.3,
        flatness: 1.1,
        seed: 9,
    };
    pour(&mut bodies, &pack, 2700.0, 1);
    compliant(bodies, subdomains, true)
}

/// `bodies` settling at μ = 1 with the default job's contact law (compliant, overlap law,
/// hyperbolic closure, recovery), decomposed into `subdomains`.
fn compliant(bodies: BodySet, subdomains: [usize; 3], parallel_interface: bool) -> World {
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
