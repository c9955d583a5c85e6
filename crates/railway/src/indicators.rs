//! Track indicators, one value per column of `series.csv`:
//!
//! * `compacity_under_block_K`: solid fraction of the ballast in the control volume under
//!   block K (its footprint, from `depth` below the design soffit up to it), exact by clipping;
//! * `compacity_crib_K`: the same in crib K (0 = before block 1, between blocks K and K+1,
//!   over the block width, from soffit to top level);
//! * `block_z_K_m`: height of block K's centre (m);
//! * `tine_force_J_x_N`, `tine_force_J_z_N`: force of the ballast on tine J (blade + shaft),
//!   along the track and vertical, the mean over the last step (contact impulses / h). It
//!   includes the tine's inertia: a vibrating tine striking a stone feels more than its
//!   cylinder gives (over a vibration period the two agree);
//! * `tine_drive_J_x_N`, `tine_drive_J_z_N`: force the tamping unit exerts on tine J over the
//!   last step (the drive's impulse / h), within `±squeeze_force` and `±insertion_force`;
//! * `tine_travel_J_x_m`, `tine_travel_J_z_m`: displacement of tine J since the start, and
//!   `tine_travel_J_x_command_m`, `tine_travel_J_z_command_m` the displacement its program
//!   commanded (vibration included): a tine that met more resistance than its limit lags;
//! * `coordination`: mean number of grain–grain contacts per grain (pairs carrying a
//!   compressive normal impulse, counted once however many contact points they have);
//! * `tine_work_J_J`: work (J) the tamping unit's cylinders have done on tine J since the
//!   start, its drive force times the distance the tine moved, step by step
//!   ([`World::drive_work`]; the vibration, imposed on top, is not counted). Negative while
//!   the ballast pushes the tine back against its cylinder.
//! * `block_drive_K_z_N`: vertical force the lifting unit exerts on block K over the last
//!   step while it lets the block down (within `±lowering_force`, falling to zero; see
//!   [`crate::tamping`]), 0 while the block is held kinematically or free.

use crate::compacity::clipped_volume;
use crate::scene::Layout;
use crate::track::{Aabb, TrackSpec};
use ballast_engine::bodies::{BodySet, BodyValues};
use ballast_engine::math::DVec3;
use ballast_engine::shapes::Shape;
use ballast_engine::world::World;
use std::ops::Range;

/// The indicators of one track model.
#[derive(Clone, Debug)]
pub struct Indicators {
    names: Vec<String>,
    volumes: Vec<Aabb>,
    blocks: Vec<usize>,
    tines: Vec<[usize; 2]>,
    /// Blade positions at t = 0.
    tine_starts: Vec<DVec3>,
    grains: Range<usize>,
}

/// Displacement the driver commands over the first `steps` steps of length `h`, by the
/// θ-rule of the position update, on the world's clock (`t += h`, so that a velocity jump
/// falls on the same step as in the run).
fn commanded_displacement(
    d: &ballast_engine::bodies::Driver,
    h: f64,
    theta: f64,
    steps: u64,
) -> DVec3 {
    let (mut x, mut t) = (DVec3::ZERO, 0.0);
    let mut v0 = d.velocity(0.0).0;
    for _ in 0..steps {
        t += h;
        let v1 = d.velocity(t).0;
        x += h * (theta * v1 + (1.0 - theta) * v0);
        v0 = v1;
    }
    x
}

impl Indicators {
    /// The indicators of `track` built with `layout`; `depth` is the height of the control
    /// volumes under the blocks (m); `bodies` are the bodies at t = 0.
    pub fn new(track: &TrackSpec, layout: &Layout, depth: f64, bodies: &BodySet) -> Self {
        let mut names = Vec::new();
        let mut volumes = Vec::new();
        for k in 1..=track.blocks {
            names.push(format!("compacity_under_block_{k}"));
            volumes.push(track.under_block(k, depth));
        }
        for k in 0..=track.blocks {
            if let Some(c) = track.crib(k) {
                names.push(format!("compacity_crib_{k}"));
                volumes.push(c);
            }
        }
        let blocks: Vec<usize> = layout.blocks.clone().collect();
        for k in 1..=blocks.len() {
            names.push(format!("block_z_{k}_m"));
        }
        for j in 1..=layout.tines.len() {
            names.push(format!("tine_force_{j}_x_N"));
            names.push(format!("tine_force_{j}_z_N"));
        }
        for j in 1..=layout.tines.len() {
            names.push(format!("tine_drive_{j}_x_N"));
            names.push(format!("tine_drive_{j}_z_N"));
        }
        for j in 1..=layout.tines.len() {
            for a in ["x", "z"] {
                names.push(format!("tine_travel_{j}_{a}_m"));
                names.push(format!("tine_travel_{j}_{a}_command_m"));
            }
        }
        names.push("coordination".into());
        for j in 1..=layout.tines.len() {
            names.push(format!("tine_work_{j}_J"));
        }
        for k in 1..=blocks.len() {
            names.push(format!("block_drive_{k}_z_N"));
        }
        Indicators {
            names,
            volumes,
            blocks,
            tines: layout.tines.clone(),
            tine_starts: layout.tines.iter().map(|t| bodies.position[t[0]]).collect(),
            grains: layout.grains.clone(),
        }
    }

    /// Column names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The control volumes, in column order (under blocks, then cribs).
    pub fn volumes(&self) -> &[Aabb] {
        &self.volumes
    }

    /// Values for the current state of `world`, in column order. On ranks that share the
    /// bodies, a collective: what it reads of the grains, the blocks and the tines comes from
    /// the rank that answers for each ([`World::gather_body_values`]).
    pub fn values(&self, world: &World) -> Vec<f64> {
        let b = &world.bodies;
        let read = self.read_bodies(world);
        // Each control volume's solid volume: its grains' clipped volumes summed in body
        // order, as [`crate::compacity::solid_volume`] sums them (the grains outside add 0).
        let mut solid = vec![0.0; self.volumes.len()];
        // The blocks' and blades' positions, in body order.
        let mut placed: Vec<(usize, DVec3)> = Vec::new();
        for (i, v) in read.iter() {
            if self.grains.contains(&i) {
                for kv in v.chunks_exact(2) {
                    solid[kv[0] as usize] += kv[1];
                }
            } else {
                placed.push((i, DVec3::new(v[0], v[1], v[2])));
            }
        }
        let at = |i: usize| {
            placed
                .binary_search_by_key(&i, |&(j, _)| j)
                .map_or(DVec3::NAN, |k| placed[k].1)
        };
        let mut out: Vec<f64> = solid
            .iter()
            .zip(&self.volumes)
            .map(|(s, v)| s / v.volume())
            .collect();
        out.extend(self.blocks.iter().map(|&i| at(i).z));
        let ids: Vec<u32> = self.tines.iter().flatten().map(|&i| i as u32).collect();
        // The tines' contacts, from every rank, in pair order (the sums a single process
        // makes).
        let touching =
            world.gather_contacts(|c, k| ids.contains(&c.body1[k]) || ids.contains(&c.body2[k]));
        let impulses = touching.impulses_on(&ids);
        let h = world.settings.dt;
        for pair in impulses.chunks(2) {
            let f = (pair[0] + pair[1]) / h;
            out.push(f.x);
            out.push(f.z);
        }
        for [blade, _] in &self.tines {
            let d = world.drives().iter().find(|d| d.body as usize == *blade);
            let f = d.map_or(DVec3::ZERO, |d| d.impulse_v / h);
            out.push(f.x);
            out.push(f.z);
        }
        for (j, [blade, _]) in self.tines.iter().enumerate() {
            let moved = at(*blade) - self.tine_starts[j];
            let commanded = b.driver[*blade].as_ref().map_or(DVec3::ZERO, |d| {
                commanded_displacement(d, h, world.settings.theta, world.step_index)
            });
            out.extend([moved.x, commanded.x, moved.z, commanded.z]);
        }
        out.push(self.coordination(world));
        out.extend(self.tines.iter().map(|[blade, _]| world.drive_work(*blade)));
        for &i in &self.blocks {
            let d = world.drives().iter().find(|d| d.body as usize == i);
            out.push(d.map_or(0.0, |d| d.impulse_v.z / h));
        }
        out
    }

    /// What [`Indicators::values`] reads of the bodies, each from the rank that answers for
    /// it: of each grain, the control volumes it reaches, as (volume, clipped volume) pairs;
    /// of each block and tine blade, its position.
    fn read_bodies(&self, world: &World) -> BodyValues {
        let b = &world.bodies;
        let blades: Vec<usize> = self.tines.iter().map(|[blade, _]| *blade).collect();
        world.gather_body_values(|i, out| {
            if self.grains.contains(&i) {
                let Shape::Polyhedron(p) = &b.shape[i] else {
                    return;
                };
                let (x, q) = (b.position[i], b.orientation[i]);
                for (k, v) in self.volumes.iter().enumerate() {
                    let solid = clipped_volume(p, x, q, v.min, v.max);
                    if solid != 0.0 {
                        out.extend([k as f64, solid]);
                    }
                }
            } else if self.blocks.contains(&i) || blades.contains(&i) {
                out.extend(b.position[i].to_array());
            }
        })
    }

    /// Mean number of grain–grain contacts per grain.
    pub fn coordination(&self, world: &World) -> f64 {
        let c = &world.contacts;
        let n = self.grains.len();
        if n == 0 {
            return 0.0;
        }
        // Contacts are grouped by pair (sorted by unordered pair): count distinct loaded pairs,
        // each on the rank that holds it.
        let mut pairs = 0usize;
        let mut last = (u32::MAX, u32::MAX);
        for k in (0..c.len()).filter(|&k| world.holds_contact(k)) {
            let (a, b) = (c.body1[k], c.body2[k]);
            if !(self.grains.contains(&(a as usize)) && self.grains.contains(&(b as usize))) {
                continue;
            }
            if c.impulse[k].x <= 0.0 {
                continue;
            }
            let key = (a.min(b), a.max(b));
            if key != last {
                pairs += 1;
                last = key;
            }
        }
        let pairs = world.sum_over_ranks(pairs as u64);
        2.0 * pairs as f64 / n as f64
    }
}
