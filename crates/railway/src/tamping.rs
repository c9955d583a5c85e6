//! The tamping cycle: track lift, vibrating tines plunging beside the tamped blocks, squeeze,
//! hold, withdrawal, and the track lowered back onto the ballast.
//!
//! # Timeline
//!
//! With the defaults (the paper's cycle, `T = 1.764 s`, for one block):
//!
//! | phase     | from (s) | to (s) | what moves                                              |
//! |-----------|----------|--------|---------------------------------------------------------|
//! | lift      | 0        | 0.10   | every block rises by `lift` (20 mm) and is held there   |
//! | insertion | 0.10     | 0.40   | the 4 tines go down, tips to `depth_below_soffit` under the lifted soffit |
//! | squeeze   | 0.40     | 1.20   | the tines close toward the block by `squeeze`            |
//! | hold      | 1.20     | 1.30   | the tines stay closed                                   |
//! | withdraw  | 1.30     | 1.55   | the tines go back up to their start height              |
//! | lower     | 1.55     | 1.764  | the blocks are let down onto the new ballast and settle  |
//!
//! Tines vibrate horizontally along the track (displacement `amplitude · sin(2π f t)`, the
//! tines either side of the block in mirror image) from the start of their insertion to the
//! end of their withdrawal, over a whole number of periods. With several tamped blocks the
//! insertion–withdrawal sequence repeats block after block, the track staying lifted; the
//! blocks are released after the last one.
//!
//! Every motion is a trapezoidal velocity profile (ramps of `ramp` seconds), so positions follow
//! exactly from the drivers' trapezoidal integration while the tines are below their limits.
//!
//! # The tamping unit as a machine
//!
//! The tines are hydraulic: each follows its program only while the force it needs stays
//! within its cylinder's limit (see [`ballast_engine::bodies::driver`]): `squeeze_force` along
//! the track, `insertion_force` vertically (insertion and withdrawal), both per tine; beyond
//! it the tine stalls, and its travel falls short of the commanded one. The vibration is
//! superposed on the squeeze whatever the force (the eccentric drives the tine arm). Across
//! the track and in rotation the tines are held by the unit's frame (no limit). A tine moves
//! with the mass `tine_mass` (tine and its share of the arm).
//!
//! # Letting the track down
//!
//! The blocks are held kinematically at their lift until the last withdrawal. Then the
//! lifting unit lets them down as a machine does, not at once: over `lowering_time` (default
//! half the lower phase) each block keeps its held position with a force, along each axis,
//! whose bound falls linearly from `lowering_force` (default twice the block's weight) to
//! zero, its weight included (a gradual release, [`ballast_engine::bodies::driver`]); from
//! then on the block is free and settles. Let go at once, a block held over loaded ballast,
//! or beside a grain wedged between it and a wall, is launched by the energy the contacts
//! stored; the falling bound takes that energy out. The force is reported per block
//! (`block_drive_K_z_N`).
//!
//! # Tines
//!
//! A tine is two kinematic boxes moving together: the blade (`blade` = `[thickness along x,
//! width across y, height]`, 25 × 65 × 80 mm) and the shaft above it (`shaft` = `[x, y]`
//! section, reaching above the bed). Two tines stand in each crib beside the block, at
//! `y = tine_y` (either side of the rail, ±0.15 m), their inner faces `open_gap` from the block
//! face before the squeeze.

use crate::error::{check_range, refuse, FieldError};
use crate::track::{Aabb, TrackSpec};
use ballast_engine::bodies::{Driver, Term, Velocities};
use ballast_engine::math::DVec3;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, TAU};

/// Parameters of the tamping cycle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TampingSpec {
    /// Tamped blocks (1-based), in order.
    pub blocks: Vec<usize>,
    /// Track lift (m).
    pub lift: f64,
    /// Duration of the lift (s).
    pub lift_time: f64,
    /// Tine blade `[thickness along the track, width across it, height]` (m).
    pub blade: [f64; 3],
    /// Tine shaft section `[along the track, across it]` (m).
    pub shaft: [f64; 2],
    /// Tine positions across the track, relative to the block centre (m); two tines per side.
    pub tine_y: Vec<f64>,
    /// Gap between the block face and the tines' inner faces before the squeeze (m).
    pub open_gap: f64,
    /// Squeeze travel of each tine toward the block (m).
    pub squeeze: f64,
    /// Height of the tine tips above the bed surface before insertion (m).
    pub clearance: f64,
    /// Depth of the tine tips under the lifted soffit at the end of insertion (m).
    pub depth_below_soffit: f64,
    /// Vibration frequency (Hz).
    pub frequency: f64,
    /// Vibration amplitude (m, half the peak-to-peak displacement).
    pub amplitude: f64,
    /// Phase durations (s).
    pub insertion_time: f64,
    pub squeeze_time: f64,
    pub hold_time: f64,
    pub withdraw_time: f64,
    /// Time left for the released blocks to settle after the last withdrawal (s).
    pub lower_time: f64,
    /// Acceleration ramps of every trapezoidal motion (s).
    pub ramp: f64,
    /// Largest squeezing force of one tine along the track (N; `inf`: a kinematic tine).
    pub squeeze_force: f64,
    /// Largest vertical force of one tine, inserting or withdrawing (N; `inf`: kinematic).
    pub insertion_force: f64,
    /// Moving mass of one tine (kg): the tine and its share of the arm.
    pub tine_mass: f64,
    /// Largest speed (m/s) at which a tine that fell behind its program makes the distance
    /// up, along the track and vertically (a position-servoed cylinder: a tine stalled short
    /// of its depth returns to its rest height on withdrawal); 0: the tines follow the
    /// program's velocity only and a distance lost stays lost.
    #[serde(skip_serializing_if = "is_zero")]
    pub catch_up_speed: f64,
    /// Duration (s) over which the lifting unit lets the blocks down onto the tamped ballast,
    /// from the start of the lower phase: its holding force falls linearly from
    /// `lowering_force` to zero, then the blocks are free. 0: let go at once. Unset: half the
    /// lower phase.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lowering_time: Option<f64>,
    /// Force (N per block, along each axis) the lifting unit can exert on a block when it
    /// starts letting it down (`inf`: it holds the block to the end of `lowering_time`).
    /// Unset: twice the block's weight.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lowering_force: Option<f64>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for TampingSpec {
    fn default() -> Self {
        TampingSpec {
            blocks: vec![1],
            lift: 0.020,
            lift_time: 0.10,
            blade: [0.025, 0.065, 0.080],
            shaft: [0.030, 0.030],
            tine_y: vec![-0.15, 0.15],
            open_gap: 0.10,
            squeeze: 0.08,
            clearance: 0.02,
            depth_below_soffit: 0.020,
            frequency: 35.0,
            amplitude: 0.003,
            insertion_time: 0.30,
            squeeze_time: 0.80,
            hold_time: 0.10,
            withdraw_time: 0.25,
            lower_time: 0.214,
            ramp: 0.02,
            squeeze_force: DEFAULT_SQUEEZE_FORCE,
            insertion_force: DEFAULT_INSERTION_FORCE,
            tine_mass: 25.0,
            catch_up_speed: 0.0,
            lowering_time: None,
            lowering_force: None,
        }
    }
}

/// Default [`TampingSpec::squeeze_force`] (N per tine): 7.8 kN per pair of picks, the
/// squeezing force found best for bed stiffness and sleeper support in a DEM–MBD study of
/// three-sleeper tamping (Tiedao Xuebao, 2024), shared by the pair's two picks.
pub(crate) const DEFAULT_SQUEEZE_FORCE: f64 = 3900.0;

/// Default [`TampingSpec::insertion_force`] (N per tine): a tamping unit of about 2 t pressed
/// down on its 8 tines, plus its vertical cylinder (an estimate; the literature gives
/// insertion speeds rather than forces).
pub(crate) const DEFAULT_INSERTION_FORCE: f64 = 5000.0;

/// Standard gravity (m/s²) for the blocks' weight.
const STANDARD_GRAVITY: f64 = 9.81;

/// One tine of the built cycle.
#[derive(Clone, Debug, PartialEq)]
pub struct Tine {
    /// Tamped block (1-based).
    pub block: usize,
    /// −1 on the low-x side of the block, +1 on the high-x side.
    pub side: f64,
    /// Blade box at t = 0.
    pub blade: Aabb,
    /// Shaft box at t = 0.
    pub shaft: Aabb,
    /// The driver of the blade (the shaft is attached to the blade).
    pub driver: Driver,
    /// Moving mass (kg).
    pub mass: f64,
}

/// Times of the phases of one tamped block (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockPhases {
    pub insertion: f64,
    pub squeeze: f64,
    pub hold: f64,
    pub withdraw: f64,
    pub end: f64,
}

/// The built cycle: when things happen, the tines, and the blocks' driver.
#[derive(Clone, Debug, PartialEq)]
pub struct Cycle {
    /// Phases per tamped block, in order.
    pub phases: Vec<BlockPhases>,
    /// When the blocks are released (end of the last withdrawal), s.
    pub release: f64,
    /// Total duration (s).
    pub duration: f64,
    /// Driver of every block: the lift, then release.
    pub block_driver: Driver,
    pub tines: Vec<Tine>,
}

/// A trapezoidal velocity profile moving by `distance` between `t0` and `t1`, with ramps of
/// `ramp` (at most a quarter of the motion).
fn motion(t0: f64, t1: f64, distance: f64, ramp: f64) -> Term {
    let r = ramp.min(0.25 * (t1 - t0));
    let v = distance / (t1 - t0 - r);
    Term::Table {
        times: vec![t0, t0 + r, t1 - r, t1],
        values: vec![0.0, v, v, 0.0],
    }
}

impl TampingSpec {
    /// Checks every field against the track.
    ///
    /// # Errors
    ///
    /// The first invalid field, its value and what is allowed.
    pub fn validate(&self, track: &TrackSpec) -> Result<(), FieldError> {
        if self.blocks.is_empty() {
            return Err(refuse(
                "tamping.blocks",
                &self.blocks,
                "at least one block number",
            ));
        }
        for &b in &self.blocks {
            if !(1..=track.blocks).contains(&b) {
                return Err(refuse(
                    "tamping.blocks",
                    &self.blocks,
                    &format!(
                        "block numbers between 1 and track.blocks = {}",
                        track.blocks
                    ),
                ));
            }
        }
        check_range("tamping.lift", self.lift, 0.0, 0.2, "m")?;
        check_range("tamping.lift_time", self.lift_time, 1e-3, 100.0, "s")?;
        for (k, &v) in self.blade.iter().enumerate() {
            check_range(&format!("tamping.blade[{k}]"), v, 1e-3, 1.0, "m")?;
        }
        for (k, &v) in self.shaft.iter().enumerate() {
            check_range(&format!("tamping.shaft[{k}]"), v, 1e-3, 1.0, "m")?;
        }
        if self.tine_y.is_empty() {
            return Err(refuse(
                "tamping.tine_y",
                &self.tine_y,
                "at least one position",
            ));
        }
        let half = 0.5 * track.width - 0.5 * self.blade[1];
        for &y in &self.tine_y {
            if !(y.is_finite() && y.abs() <= half) {
                return Err(refuse(
                    "tamping.tine_y",
                    &self.tine_y,
                    &format!("positions with |y| ≤ {half} m (blades inside the bed)"),
                ));
            }
        }
        check_range("tamping.open_gap", self.open_gap, 0.0, 1.0, "m")?;
        if !(self.squeeze.is_finite() && self.squeeze >= 0.0 && self.squeeze < self.open_gap) {
            return Err(refuse(
                "tamping.squeeze",
                self.squeeze,
                &format!(
                    "≥ 0 and less than tamping.open_gap = {} m (tines stop short of the block)",
                    self.open_gap
                ),
            ));
        }
        check_range("tamping.clearance", self.clearance, 0.0, 1.0, "m")?;
        check_range(
            "tamping.depth_below_soffit",
            self.depth_below_soffit,
            0.0,
            track.depth - 0.01,
            "m (the tips stay above the floor)",
        )?;
        check_range("tamping.frequency", self.frequency, 0.0, 1000.0, "Hz")?;
        check_range("tamping.amplitude", self.amplitude, 0.0, 0.05, "m")?;
        for (name, v) in [
            ("tamping.insertion_time", self.insertion_time),
            ("tamping.squeeze_time", self.squeeze_time),
            ("tamping.hold_time", self.hold_time),
            ("tamping.withdraw_time", self.withdraw_time),
            ("tamping.lower_time", self.lower_time),
        ] {
            check_range(name, v, 0.0, 100.0, "s")?;
        }
        for (name, v) in [
            ("tamping.insertion_time", self.insertion_time),
            ("tamping.withdraw_time", self.withdraw_time),
        ] {
            if v <= 0.0 {
                return Err(refuse(name, v, "> 0 s"));
            }
        }
        check_range("tamping.ramp", self.ramp, 0.0, 1.0, "s")?;
        for (name, f) in [
            ("tamping.squeeze_force", self.squeeze_force),
            ("tamping.insertion_force", self.insertion_force),
        ] {
            if f.is_nan() || f <= 0.0 {
                return Err(refuse(name, f, "> 0 N per tine (inf: a kinematic tine)"));
            }
        }
        check_range("tamping.tine_mass", self.tine_mass, 0.1, 1e4, "kg")?;
        if let Some(t) = self.lowering_time {
            check_range(
                "tamping.lowering_time",
                t,
                0.0,
                self.lower_time,
                "s (within tamping.lower_time)",
            )?;
        }
        if let Some(f) = self.lowering_force {
            if f.is_nan() || f < 0.0 {
                return Err(refuse(
                    "tamping.lowering_force",
                    f,
                    "≥ 0 N per block (inf: held to the end of the lowering)",
                ));
            }
        }
        check_range(
            "tamping.catch_up_speed",
            self.catch_up_speed,
            0.0,
            100.0,
            "m/s",
        )?;
        // Tines must fit in the crib in front of the block (the bed end for end blocks).
        for &b in &self.blocks {
            let bb = track.block_box(b);
            let reach = self.open_gap + self.blade[0].max(self.shaft[0]) + self.amplitude;
            if bb.min.x - reach < 0.0 || bb.max.x + reach > track.length() {
                return Err(refuse(
                    "tamping.open_gap",
                    self.open_gap,
                    &format!(
                        "small enough for the tines of block {b} to stay inside the bed \
                         (they reach {reach:.3} m from the block faces)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Duration of the blocks' lowering (s): `lowering_time`, or half the lower phase.
    pub fn lowering(&self) -> f64 {
        self.lowering_time.unwrap_or(0.5 * self.lower_time)
    }

    /// The lifting unit's force when the lowering starts (N per block): `lowering_force`, or
    /// twice the weight of a block of `track`.
    pub fn lowering_force(&self, track: &TrackSpec) -> f64 {
        self.lowering_force.unwrap_or_else(|| {
            let [a, b, c] = track.block_size;
            2.0 * a * b * c * track.block_density * STANDARD_GRAVITY
        })
    }

    /// Insertion depth: from the tips' start height to their lowest point (m).
    pub fn travel(&self, track: &TrackSpec) -> f64 {
        (track.top() + self.clearance) - (track.soffit() + self.lift - self.depth_below_soffit)
    }

    /// Duration of the whole cycle (s).
    pub fn duration(&self) -> f64 {
        self.lift_time
            + self.blocks.len() as f64
                * (self.insertion_time + self.squeeze_time + self.hold_time + self.withdraw_time)
            + self.lower_time
    }

    /// Builds the cycle for `track` (call [`TampingSpec::validate`] first).
    pub fn build(&self, track: &TrackSpec) -> Cycle {
        let lift = motion(0.0, self.lift_time, self.lift, self.ramp);
        let mut t = self.lift_time;
        let mut phases = Vec::new();
        let mut tines = Vec::new();
        let travel = self.travel(track);
        let [bt, bw, bh] = self.blade;
        for &b in &self.blocks {
            let p = BlockPhases {
                insertion: t,
                squeeze: t + self.insertion_time,
                hold: t + self.insertion_time + self.squeeze_time,
                withdraw: t + self.insertion_time + self.squeeze_time + self.hold_time,
                end: t
                    + self.insertion_time
                    + self.squeeze_time
                    + self.hold_time
                    + self.withdraw_time,
            };
            // Vibration over whole periods from the start of insertion.
            let periods = ((p.end - p.insertion) * self.frequency).floor();
            let vib_end = p.insertion + periods / self.frequency.max(f64::MIN_POSITIVE);
            let bb = track.block_box(b);
            let tip = track.top() + self.clearance;
            let shaft_top = tip + travel + track.block_size[2].max(0.1) + self.lift;
            for side in [-1.0, 1.0] {
                let face = if side < 0.0 { bb.min.x } else { bb.max.x };
                // Blade centre x: outside the face by open_gap + half thickness.
                let x = face + side * (self.open_gap + 0.5 * bt);
                for &y in &self.tine_y {
                    let blade = Aabb {
                        min: DVec3::new(x - 0.5 * bt, y - 0.5 * bw, tip),
                        max: DVec3::new(x + 0.5 * bt, y + 0.5 * bw, tip + bh),
                    };
                    let [sx, sy] = self.shaft;
                    let shaft = Aabb {
                        min: DVec3::new(x - 0.5 * sx, y - 0.5 * sy, tip + bh),
                        max: DVec3::new(x + 0.5 * sx, y + 0.5 * sy, shaft_top),
                    };
                    let vx = vec![motion(p.squeeze, p.hold, -side * self.squeeze, self.ramp)];
                    let mut vibration = Vec::new();
                    if self.amplitude > 0.0 && self.frequency > 0.0 && periods > 0.0 {
                        // Displacement −side·A·sin(ω(t − t₀)): mirror images either side.
                        vibration.push(Term::Sine {
                            amplitude: -side * self.amplitude * TAU * self.frequency,
                            frequency: self.frequency,
                            phase: FRAC_PI_2,
                            start: p.insertion,
                            end: vib_end,
                        });
                    }
                    let vz = vec![
                        motion(p.insertion, p.squeeze, -travel, self.ramp),
                        motion(p.withdraw, p.end, travel, self.ramp),
                    ];
                    tines.push(Tine {
                        block: b,
                        side,
                        blade,
                        shaft,
                        driver: Driver {
                            vx,
                            vz,
                            max_force: [self.squeeze_force, f64::INFINITY, self.insertion_force],
                            catch_up_speed: [self.catch_up_speed, 0.0, self.catch_up_speed],
                            superposed: Velocities {
                                vx: vibration,
                                ..Velocities::default()
                            },
                            ..Driver::default()
                        },
                        mass: self.tine_mass,
                    });
                }
            }
            phases.push(p);
            t = p.end;
        }
        let release = t;
        Cycle {
            phases,
            release,
            duration: release + self.lower_time,
            block_driver: Driver {
                vz: vec![lift],
                release_at: Some(release),
                release_over: self.lowering(),
                release_force: if self.lowering() > 0.0 {
                    [self.lowering_force(track); 3]
                } else {
                    [f64::INFINITY; 3]
                },
                ..Driver::default()
            },
            tines,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Displacement of a driver's dof by the trapezoidal rule on a fine grid.
    fn displacement(p: &[Term], t0: f64, t1: f64) -> f64 {
        let n = 200_000;
        let h = (t1 - t0) / n as f64;
        let v = |t: f64| p.iter().map(|x| x.eval(t)).sum::<f64>();
        (0..n)
            .map(|k| 0.5 * h * (v(t0 + k as f64 * h) + v(t0 + (k + 1) as f64 * h)))
            .sum()
    }

    #[test]
    fn default_cycle_is_the_papers_duration() {
        let s = TampingSpec::default();
        assert!((s.duration() - 1.764).abs() < 1e-12);
    }

    #[test]
    fn tines_reach_depth_squeeze_and_come_back() {
        let track = TrackSpec::default();
        let s = TampingSpec::default();
        s.validate(&track).unwrap();
        let c = s.build(&track);
        assert_eq!(c.tines.len(), 4);
        let p = c.phases[0];
        for tine in &c.tines {
            let dz = displacement(&tine.driver.vz, 0.0, p.squeeze);
            let tip = tine.blade.min.z + dz;
            let lifted_soffit = track.soffit() + s.lift;
            assert!((tip - (lifted_soffit - s.depth_below_soffit)).abs() < 1e-6);
            // Back to the start height at the end.
            assert!(displacement(&tine.driver.vz, 0.0, c.duration).abs() < 1e-6);
            // Squeeze toward the block, vibration averages out over whole periods (exactly; the
            // quadrature errs by up to h·Aω/2 ≈ 3e-6 m at the velocity jumps of the sine's ends).
            let vx: Vec<Term> = tine
                .driver
                .vx
                .iter()
                .chain(&tine.driver.superposed.vx)
                .cloned()
                .collect();
            let dx = displacement(&vx, 0.0, c.duration);
            assert!((dx + tine.side * s.squeeze).abs() < 1e-5, "{dx}");
            // Inner face ends open_gap − squeeze from the block face.
            let face = track.block_box(1);
            let inner = if tine.side < 0.0 {
                tine.blade.max.x + dx - face.min.x
            } else {
                face.max.x - (tine.blade.min.x + dx)
            };
            assert!((inner.abs() - (s.open_gap - s.squeeze)).abs() < 1e-5);
        }
        // Vibration amplitude: peak displacement about A around the mean path.
        let tine = &c.tines[0];
        let vib: Vec<Term> = tine.driver.superposed.vx.clone();
        let mut max: f64 = 0.0;
        for k in 0..400 {
            let t = p.insertion + k as f64 * 1e-4;
            max = max.max(displacement(&vib, p.insertion, t).abs());
        }
        assert!((max - s.amplitude).abs() < 0.02 * s.amplitude, "{max}");
        // Blocks: lifted by `lift`, released at the end of the withdrawal.
        assert!((displacement(&c.block_driver.vz, 0.0, 1.0) - s.lift).abs() < 1e-6);
        assert_eq!(c.block_driver.release_at, Some(p.end));
        // Let down over half the lower phase from twice the block's weight (0.29 × 0.84 ×
        // 0.22 m of concrete: 128.6 kg, 1,262 N), along each axis.
        assert_eq!(c.block_driver.release_over, 0.5 * s.lower_time);
        let weight = 0.29 * 0.84 * 0.22 * 2400.0 * 9.81;
        for f in c.block_driver.release_force {
            assert!((f - 2.0 * weight).abs() < 1e-9 * weight, "{f}");
        }
        assert!(c.block_driver.validate().is_ok());
        // Let go at once: no force of a gradual release.
        let at_once = TampingSpec {
            lowering_time: Some(0.0),
            ..s.clone()
        };
        let d = at_once.build(&track).block_driver;
        assert_eq!(d.release_over, 0.0);
        assert!(d.validate().is_ok());
    }

    #[test]
    fn bad_cycles_name_the_field() {
        let track = TrackSpec::default();
        let bad = |f: &dyn Fn(&mut TampingSpec)| {
            let mut s = TampingSpec::default();
            f(&mut s);
            s.validate(&track).unwrap_err().field
        };
        assert_eq!(bad(&|s| s.blocks = vec![2]), "tamping.blocks");
        assert_eq!(bad(&|s| s.squeeze = 0.2), "tamping.squeeze");
        assert_eq!(bad(&|s| s.frequency = -1.0), "tamping.frequency");
        assert_eq!(bad(&|s| s.open_gap = 0.3), "tamping.open_gap");
        assert_eq!(bad(&|s| s.tine_y = vec![0.6]), "tamping.tine_y");
        assert_eq!(bad(&|s| s.insertion_time = 0.0), "tamping.insertion_time");
        assert_eq!(
            bad(&|s| s.lowering_time = Some(0.3)),
            "tamping.lowering_time"
        );
        assert_eq!(
            bad(&|s| s.lowering_force = Some(-1.0)),
            "tamping.lowering_force"
        );
    }
}
