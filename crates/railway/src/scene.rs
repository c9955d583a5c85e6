//! Assembling the bodies of a track model: the bed's walls, the blocks, the tines and the
//! grains, in that order, with the friction groups of the paper.

use crate::tamping::Cycle;
use crate::track::{Aabb, TrackSpec};
use ballast_engine::bodies::{BodyKind, BodySet, Driver};
use ballast_engine::laws::FrictionTable;
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::shapes::{ConvexPolyhedron, PolyhedronBuild};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::Arc;

/// Friction group of the grains.
pub const GRAIN: u32 = 0;
/// Friction group of the bed's walls and floor.
pub const WALL: u32 = 1;
/// Friction group of the sleeper blocks.
pub const BLOCK: u32 = 2;
/// Friction group of the tines.
pub const TINE: u32 = 3;
/// The names of the groups above, by number (messages name a body's group with them).
pub const GROUP_NAMES: [&str; 4] = ["grain", "wall", "block", "tine"];

/// Friction coefficients of the track model (the paper's: μ = 1 except against the walls).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackFriction {
    pub grain_grain: f64,
    pub grain_block: f64,
    pub grain_tine: f64,
    pub grain_wall: f64,
}

impl Default for TrackFriction {
    fn default() -> Self {
        TrackFriction {
            grain_grain: 1.0,
            grain_block: 1.0,
            grain_tine: 1.0,
            grain_wall: 0.8,
        }
    }
}

impl TrackFriction {
    /// Checks every coefficient.
    ///
    /// # Errors
    ///
    /// The first coefficient that is not finite and ≥ 0.
    pub fn validate(&self) -> Result<(), crate::error::FieldError> {
        for (name, mu) in [
            ("friction.grain_grain", self.grain_grain),
            ("friction.grain_block", self.grain_block),
            ("friction.grain_tine", self.grain_tine),
            ("friction.grain_wall", self.grain_wall),
        ] {
            crate::error::check_range(name, mu, 0.0, 10.0, "(friction coefficient)")?;
        }
        Ok(())
    }

    /// The engine's friction table over the groups above (pairs that never touch: 0).
    pub fn table(&self) -> FrictionTable {
        let mut t = FrictionTable::new(0.0);
        t.set(GRAIN, GRAIN, self.grain_grain);
        t.set(GRAIN, BLOCK, self.grain_block);
        t.set(GRAIN, TINE, self.grain_tine);
        t.set(GRAIN, WALL, self.grain_wall);
        t
    }
}

/// Where each kind of body sits in the body set.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Layout {
    pub walls: Range<usize>,
    pub blocks: Range<usize>,
    /// Per tine, its blade and shaft bodies.
    pub tines: Vec<[usize; 2]>,
    pub grains: Range<usize>,
}

/// A placed grain: its shape and pose.
#[derive(Clone, Debug)]
pub struct PlacedGrain {
    /// Index of the grain in the generated list (its seed stream).
    pub index: usize,
    pub shape: Arc<ConvexPolyhedron>,
    pub position: DVec3,
    pub orientation: DQuat,
}

/// How the blocks are present in a scene.
#[derive(Clone, Debug)]
pub enum Blocks {
    /// No blocks (a bed being deposited).
    Absent,
    /// Fixed in their design position.
    Fixed,
    /// Driven by the given driver (lift, then release).
    Driven(Box<Driver>),
}

fn cuboid(b: &Aabb) -> PolyhedronBuild {
    // Sizes come from validated specs, so a degenerate box is a bug, not a user error.
    ConvexPolyhedron::cuboid(b.half_extents()).expect("validated box sizes")
}

/// Builds the bodies: 5 walls (floor and 4 sides; the bed is open at the top), the blocks,
/// the tines of `cycle` (if any), then `grains` (dynamic, density `grain_density`).
pub fn build_bodies(
    track: &TrackSpec,
    blocks: &Blocks,
    cycle: Option<&Cycle>,
    grains: &[PlacedGrain],
    grain_density: f64,
) -> (BodySet, Layout) {
    let mut b = BodySet::default();
    let bed = track.bed_box();
    let w0 = b.len();
    b.add_plane(DVec3::ZERO, DVec3::Z, WALL);
    b.add_plane(DVec3::new(bed.min.x, 0.0, 0.0), DVec3::X, WALL);
    b.add_plane(DVec3::new(bed.max.x, 0.0, 0.0), -DVec3::X, WALL);
    b.add_plane(DVec3::new(0.0, bed.min.y, 0.0), DVec3::Y, WALL);
    b.add_plane(DVec3::new(0.0, bed.max.y, 0.0), -DVec3::Y, WALL);
    let walls = w0..b.len();
    let b0 = b.len();
    let (kind, driver) = match blocks {
        Blocks::Absent => (None, None),
        Blocks::Fixed => (Some(BodyKind::Fixed), None),
        Blocks::Driven(d) => (Some(BodyKind::Kinematic), Some(Box::new(Driver::clone(d)))),
    };
    if let Some(kind) = kind {
        for k in 1..=track.blocks {
            let bb = track.block_box(k);
            let mut build = cuboid(&bb);
            build.position = bb.centre();
            let i = b.add_polyhedron(build, track.block_density, kind, BLOCK);
            b.driver[i] = driver.clone();
        }
    }
    let block_range = b0..b.len();
    let mut tines = Vec::new();
    if let Some(c) = cycle {
        for t in &c.tines {
            let mut ids = [0; 2];
            for (slot, bx) in [&t.blade, &t.shaft].into_iter().enumerate() {
                let mut build = cuboid(bx);
                build.position = bx.centre();
                let i = b.add_polyhedron(build, 7850.0, BodyKind::Kinematic, TINE);
                ids[slot] = i;
            }
            // The blade carries the drive and the tine's moving mass; the shaft is a rigid
            // part of it, so the ballast's forces on the shaft load the same drive.
            let [blade, shaft] = ids;
            b.driver[blade] = Some(Box::new(t.driver.clone()));
            b.inv_mass[blade] = 1.0 / t.mass;
            b.driver[shaft] = Some(Box::new(Driver {
                attached_to: Some(blade),
                ..Driver::default()
            }));
            tines.push(ids);
        }
    }
    let g0 = b.len();
    for g in grains {
        b.add_shared_polyhedron(
            g.shape.clone(),
            g.position,
            g.orientation,
            grain_density,
            BodyKind::Dynamic,
            GRAIN,
        );
    }
    let layout = Layout {
        walls,
        blocks: block_range,
        tines,
        grains: g0..b.len(),
    };
    (b, layout)
}
