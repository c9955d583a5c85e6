//! Fixtures shared by the engine's test files.
#![allow(dead_code)]

use ballast_engine::bodies::{BodyKind, BodySet};
use ballast_engine::math::DVec3;
use ballast_engine::scenario::generate::GrainPack;

/// A floor and four walls (group 0): a box `side` × `side` wide, open at the top, its corner at
/// the origin.
pub fn open_box(side: f64) -> BodySet {
    let mut bodies = BodySet::default();
    bodies.add_plane(DVec3::ZERO, DVec3::Z, 0);
    for (p, n) in [
        (DVec3::ZERO, DVec3::X),
        (DVec3::new(side, 0.0, 0.0), -DVec3::X),
        (DVec3::ZERO, DVec3::Y),
        (DVec3::new(0.0, side, 0.0), -DVec3::Y),
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
