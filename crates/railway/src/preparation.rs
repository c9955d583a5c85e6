//! Sample preparation: a dense ballast bed around the sleeper blocks, deposited under gravity,
//! and cached on disk keyed by every parameter it depends on.
//!
//! # Algorithm
//!
//! 1. Generate grains (seeded) for a solid volume `compacity × overfill × bed volume`, the bed
//!    being the box up to the block tops, blocks included.
//! 2. Stack them on a height map of the bed (see `place_on_height_map`): each grain, at the
//!    lowest of 32 seeded spots, is lowered until its own lower surface meets the upper
//!    surfaces of the grains already placed, so the stack is about as dense as a loose pour and
//!    barely overlapping. Let them settle in the empty box with cheap solver settings (`dt`,
//!    `tolerance`, `max_iterations` below) until the stack's excess height has had time to fall,
//!    plus `settle_time`, and 99 % of the grains are slower than `rest_speed` (waiting at most
//!    `max_extra_time` more).
//! 3. Put the blocks in place, as an excavation: remove every grain that overlaps a block
//!    (exact clipped volume > 0) or whose centre is above the block tops (the cribs are then
//!    filled to the top of the blocks and the surface is level).
//! 4. Let the bed settle again, blocks fixed, for `block_settle_time` and until at rest.
//! 5. Heal the overlaps left by the deposition: the settling stops at a time limit, and a few
//!    grains may still be wedged a few millimetres into each other (the ordinary overlap
//!    correction heals them only over many steps, and which grains depends on rounding). Until
//!    the largest overlap is below `heal_overlap` (at most `heal_steps` steps), each step starts
//!    from rest (every grain's velocity set to zero: a quasi-static relaxation, which the cached
//!    bed, poses only, starts from anyway) and ends with a strong overlap correction
//!    ([`heal_correction`]).
//!
//! Every contact of the deposition has the friction coefficient `friction` (0.2 by default):
//! grains poured with the track's μ = 1 jam into a loose bed (compacity about 0.5), far from
//! the compacted ballast under a sleeper (about 0.6); gently stacked grains need less friction
//! than dropped ones to reach it (0.3 gives 0.565, 0.2 gives 0.61, 0.1 gives 0.64 on the CI
//! bed).
//!
//! The blocks are thus put in place rather than pressed in: the soffit rests on the cut surface
//! of the bed, which the lift of the tamping cycle leaves anyway.
//!
//! # Tiled preparation
//!
//! With `tiled` (the paper preset), a track of `blocks` equally spaced blocks
//! (`length = blocks × spacing`) is prepared as one segment repeated: stages 1–5 on one block's
//! segment (one `spacing` long, the block in its middle, walls at both ends), the segment's bed
//! copied `blocks` times along the track (copy `c` of grain `i` is grain `c·n + i` of the
//! generated list, the segment's list repeated), then the whole bed settled around its fixed
//! blocks for `tile_settle_time` (the grains at the former segment ends lean on their new
//! neighbours instead of a wall) and healed (stage 5). Its cost is one segment's deposition
//! plus a short settling of the whole bed, instead of depositing all of it: the deposition's
//! 0.9 s of simulated time is what makes a large bed slow. The price: the blocks start on
//! copies of one bed (their compacities differ by the final settling only), and the ballast
//! at the segment ends, deposited against a wall, is a little looser there.
//!
//! # Cache
//!
//! The result is a list of (grain index in the generated list, pose), stored with the key (the
//! JSON of every input plus the crate version) in `sample_<hash>.bin`, checksummed and written
//! atomically. A later run with the same inputs regenerates the grains from their seed (cheap)
//! and takes the poses from the file: the prepared bed is bit-identical to a fresh preparation.

use crate::compacity::clipped_volume;
use crate::defaults::{default_ddm, DEFAULT_ALERT};
use crate::error::{check_range, Error, FieldError};
use crate::grains::{generate_grains, Amount, GrainSpec};
use crate::scene::{build_bodies, Blocks, PlacedGrain, TrackFriction};
use crate::track::TrackSpec;
use ballast_engine::fnv1a64;
use ballast_engine::math::{DQuat, DVec3};
use ballast_engine::output::write_atomic;
use ballast_engine::shapes::Shape;
use ballast_engine::solver::{ConvergenceNorm, CorrectionSettings, Exchange, SolverSettings};
use ballast_engine::world::{StepSettings, World};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The ballast: grain shapes, grading, density, and the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BallastSpec {
    #[serde(flatten)]
    pub grains: GrainSpec,
    /// Seed of the grain shapes, sizes and orientations.
    pub seed: u64,
}

impl Default for BallastSpec {
    fn default() -> Self {
        BallastSpec {
            grains: GrainSpec::default(),
            seed: 1,
        }
    }
}

/// How the bed is prepared.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PreparationSpec {
    /// Target solid fraction used to size the grain volume.
    pub compacity: f64,
    /// Extra volume of grains, the excess being trimmed above the block tops.
    pub overfill: f64,
    /// Time step of the deposition (s).
    pub dt: f64,
    /// NLGS tolerance (Quad norm) and sweep cap of the deposition. A falling, settling heap
    /// needs no converged forces, only contacts that stop the grains: 12 sweeps a step prepare
    /// the default bed in half the time of 40, to the same compacity within 2 %, healed all
    /// the same.
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Alert distance of the contact detection (m), as `[simulation] alert` for the run.
    pub alert: f64,
    /// Settling time after the fall (s).
    pub settle_time: f64,
    /// Settling time after the blocks are put in place (s): the bed is already settled, only
    /// the grains cut by the excavation move.
    pub block_settle_time: f64,
    /// The bed is at rest when 99 % of its grains are slower than this (m/s): a few rattlers
    /// at the surface, which may spin for long, do not hold the preparation up.
    pub rest_speed: f64,
    /// Longest wait for rest beyond the minimum time of a stage (s of simulated time).
    pub max_extra_time: f64,
    /// Friction coefficient of every contact during the deposition: low friction gives the
    /// dense beds of a compacted track (the run itself uses `[friction]`).
    pub friction: f64,
    /// The preparation ends with its largest overlap below this (m), see stage 5.
    pub heal_overlap: f64,
    /// Most steps of the healing stage.
    pub heal_steps: usize,
    /// Reuse a prepared bed with the same parameters from the cache folder.
    pub cache: bool,
    /// Prepare one block's segment of the track (one `spacing` long, its block in the middle,
    /// walls at its ends) and repeat it along the track, then let the whole bed settle for
    /// `tile_settle_time` and heal it (see the [module documentation](self)). Needs
    /// `track.length = blocks × spacing`. Absent from the cache key when false, so that the
    /// beds prepared before it existed are still read.
    #[serde(skip_serializing_if = "is_false")]
    pub tiled: bool,
    /// Settling time of the whole tiled bed (s), see `tiled`.
    #[serde(skip_serializing_if = "is_default_tile_settle_time")]
    pub tile_settle_time: f64,
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// Default of [`PreparationSpec::tile_settle_time`] (s).
const TILE_SETTLE_TIME: f64 = 0.05;

fn is_default_tile_settle_time(t: &f64) -> bool {
    *t == TILE_SETTLE_TIME
}

impl Default for PreparationSpec {
    fn default() -> Self {
        PreparationSpec {
            compacity: 0.60,
            overfill: 1.08,
            dt: 5e-4,
            tolerance: 1e-2,
            max_iterations: 12,
            alert: DEFAULT_ALERT,
            settle_time: 0.25,
            block_settle_time: 0.2,
            rest_speed: 0.05,
            max_extra_time: 0.1,
            friction: 0.2,
            heal_overlap: 1e-3,
            heal_steps: 50,
            cache: true,
            tiled: false,
            tile_settle_time: TILE_SETTLE_TIME,
        }
    }
}

impl PreparationSpec {
    /// Checks every field.
    ///
    /// # Errors
    ///
    /// The first invalid field, its value and what is allowed.
    pub fn validate(&self) -> Result<(), FieldError> {
        check_range("preparation.compacity", self.compacity, 0.3, 0.74, "")?;
        check_range("preparation.overfill", self.overfill, 1.0, 2.0, "")?;
        check_range("preparation.dt", self.dt, 1e-6, 1e-2, "s")?;
        check_range("preparation.tolerance", self.tolerance, 1e-12, 1.0, "")?;
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(crate::error::refuse(
                "preparation.max_iterations",
                self.max_iterations,
                "1 to 100000 sweeps",
            ));
        }
        check_range("preparation.settle_time", self.settle_time, 0.0, 100.0, "s")?;
        check_range(
            "preparation.block_settle_time",
            self.block_settle_time,
            0.0,
            100.0,
            "s",
        )?;
        check_range("preparation.alert", self.alert, 0.0, 0.1, "m")?;
        check_range("preparation.rest_speed", self.rest_speed, 1e-6, 10.0, "m/s")?;
        check_range(
            "preparation.max_extra_time",
            self.max_extra_time,
            0.0,
            1000.0,
            "s",
        )?;
        check_range(
            "preparation.heal_overlap",
            self.heal_overlap,
            1e-6,
            0.1,
            "m",
        )?;
        check_range(
            "preparation.tile_settle_time",
            self.tile_settle_time,
            0.0,
            100.0,
            "s",
        )?;
        if self.heal_steps > 100_000 {
            return Err(crate::error::refuse(
                "preparation.heal_steps",
                self.heal_steps,
                "0 to 100000 steps",
            ));
        }
        Ok(())
    }
}

/// What a preparation did (stored with the cached sample).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PreparationReport {
    /// Grains generated, and kept in the bed.
    pub generated: usize,
    pub grains: usize,
    /// Grains removed where the blocks go, and above the block tops.
    pub removed_in_blocks: usize,
    pub removed_above: usize,
    /// Grains removed because they were still wedged into a neighbour deeper than
    /// `heal_overlap` after the healing stage.
    #[serde(default)]
    pub removed_wedged: usize,
    /// Deposition steps and simulated time (fall + settling).
    pub steps: u64,
    pub simulated_s: f64,
    /// Wall-clock time of the preparation (s).
    pub wall_s: f64,
    /// Largest overlap among the final contacts (m).
    pub max_penetration: f64,
    /// Largest and mean grain speed at the end (m/s, rotation included at the circumscribed
    /// radius).
    pub max_speed: f64,
    #[serde(default)]
    pub mean_speed: f64,
    /// Top of the stacked grains before they settle (m above the floor).
    #[serde(default)]
    pub stack_height: f64,
    /// Largest overlap when the settling stopped, before the healing stage (m).
    #[serde(default)]
    pub settled_penetration: f64,
    /// Steps of the healing stage (included in `steps`).
    #[serde(default)]
    pub heal_steps: u64,
}

/// A prepared bed: the grains' poses (blocks in their design position).
#[derive(Clone, Debug)]
pub struct PreparedSample {
    pub grains: Vec<PlacedGrain>,
    pub report: PreparationReport,
    /// True when it was read from the cache.
    pub from_cache: bool,
}

/// Progress of a preparation, for terminals.
#[derive(Clone, Copy, Debug)]
pub struct PrepProgress {
    /// 1 = deposition, 2 = settling around the blocks, 3 = healing the overlaps.
    pub stage: u8,
    pub time: f64,
    /// Time the stage will at least last.
    pub target: f64,
    pub grains: usize,
    pub contacts: usize,
}

/// Everything the prepared bed depends on.
#[derive(Serialize)]
struct Key<'a> {
    version: &'static str,
    format: u32,
    track: &'a TrackSpec,
    ballast: &'a BallastSpec,
    preparation: &'a PreparationSpec,
    friction: &'a TrackFriction,
}

const MAGIC: &[u8] = b"BALLASTSAMPLE";
/// Bumped when the preparation's algorithm changes, so older cached beds are not reused.
const FORMAT: u32 = 7;

/// The overlap correction of the healing stage: half of each overlap removed per step, but
/// at most half the alert distance (a deep overlap heals over several steps, each moving the
/// grains by less than the alert distance, so that every neighbour they approach is a
/// contact), with the open contacts held (`guard`: pushing one overlap apart must not make
/// another), the grains translated only (turned by impulses at their corners, they drove
/// other corners into their neighbours: on the default bed the overlaps beyond 0.5 mm went
/// from 38 to 81 over the first 10 steps with rotation, down to 7 without) and enough sweeps
/// for the wedged grains' neighbours to make room. The run's default (20 %, 10 sweeps,
/// overlaps only) is gentle enough not to be seen in the indicators, and heals a grain
/// wedged a few millimetres deep only over a hundred steps.
pub fn heal_correction(alert: f64) -> CorrectionSettings {
    CorrectionSettings {
        fraction: 0.5,
        slop: 1e-5,
        sweeps: 50,
        max_push: 0.5 * alert,
        guard: true,
        rotation: false,
    }
}

fn key_json(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    friction: &TrackFriction,
) -> String {
    // `cache` itself does not change the bed.
    let prep = PreparationSpec {
        cache: true,
        ..prep.clone()
    };
    serde_json::to_string(&Key {
        version: env!("CARGO_PKG_VERSION"),
        format: FORMAT,
        track,
        ballast,
        preparation: &prep,
        friction,
    })
    .expect("specs serialise")
}

/// The cache file of these parameters in `dir`.
pub fn cache_path(
    dir: &Path,
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    friction: &TrackFriction,
) -> PathBuf {
    let h = fnv1a64(key_json(track, ballast, prep, friction).as_bytes());
    dir.join(format!("sample_{h:016x}.bin"))
}

/// Prepares the bed, or reads it from `cache_dir` when `prep.cache` and a valid file with the
/// same key is there; a fresh preparation is stored there (a failed write is only a warning,
/// returned as the second value).
///
/// # Errors
///
/// Invalid parameters ([`FieldError`]), or grains that cannot be generated.
pub fn load_or_prepare(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    friction: &TrackFriction,
    cache_dir: Option<&Path>,
    progress: &mut dyn FnMut(PrepProgress),
) -> Result<(PreparedSample, Option<String>), Error> {
    load_or_prepare_shared(track, ballast, prep, friction, cache_dir, None, progress)
}

/// [`load_or_prepare`] by the ranks of a distributed run together (`exchange`; see
/// `ballast_engine::solver::exchange`): each rank prepares the same bed in lockstep with the
/// others, sharing the solves and the narrow phase, and rank 0 alone writes the cache. The
/// bed is bit-identical to one process's.
///
/// # Errors
///
/// As [`load_or_prepare`].
#[allow(clippy::too_many_arguments)]
pub fn load_or_prepare_shared(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    friction: &TrackFriction,
    cache_dir: Option<&Path>,
    exchange: Option<&Arc<dyn Exchange>>,
    progress: &mut dyn FnMut(PrepProgress),
) -> Result<(PreparedSample, Option<String>), Error> {
    track.validate()?;
    ballast.grains.validate()?;
    prep.validate()?;
    if prep.tiled {
        check_tiling(track)?;
    }
    friction.validate()?;
    let key = key_json(track, ballast, prep, friction);
    let path = cache_dir
        .filter(|_| prep.cache)
        .map(|d| cache_path(d, track, ballast, prep, friction));
    let generated = generate(track, ballast, prep)?;
    if let Some(p) = &path {
        if let Ok(bytes) = std::fs::read(p) {
            if let Some(s) = decode(&bytes, &key, &generated) {
                return Ok((s, None));
            }
        }
    }
    let sample = prepare_from(track, ballast, prep, generated, exchange, progress);
    let mut warning = None;
    let writer = exchange.is_none_or(|e| e.rank() == 0);
    if let Some(p) = path.as_ref().filter(|_| writer) {
        let written = std::fs::create_dir_all(p.parent().unwrap_or(Path::new(".")))
            .and_then(|_| write_atomic(p, &encode(&sample, &key)));
        if let Err(e) = written {
            warning = Some(format!(
                "could not cache the prepared bed in {}: {e}",
                p.display()
            ));
        }
    }
    Ok((sample, warning))
}

/// The generated grains, in body frame (pose = orientation only).
fn generate(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
) -> Result<Vec<PlacedGrain>, Error> {
    if prep.tiled {
        // The segment's grains once per block; the copies share their shapes.
        let (piece_track, piece) = segment(track, prep);
        let one = generate(&piece_track, ballast, &piece)?;
        let n = one.len();
        return Ok((0..track.blocks.max(1))
            .flat_map(|c| {
                one.iter().map(move |g| PlacedGrain {
                    index: c * n + g.index,
                    ..g.clone()
                })
            })
            .collect());
    }
    let volume = prep.compacity * prep.overfill * track.bed_box().volume();
    let builds = generate_grains(&ballast.grains, Amount::SolidVolume(volume), ballast.seed)?;
    Ok(builds
        .into_iter()
        .enumerate()
        .map(|(index, b)| PlacedGrain {
            index,
            shape: Arc::new(b.shape),
            position: b.position,
            orientation: b.orientation,
        })
        .collect())
}

/// Prepares a bed from scratch (see the [module documentation](self)).
///
/// # Errors
///
/// Invalid parameters, or grains that cannot be generated.
pub fn prepare(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    friction: &TrackFriction,
    progress: &mut dyn FnMut(PrepProgress),
) -> Result<PreparedSample, Error> {
    load_or_prepare(
        track,
        ballast,
        &PreparationSpec {
            cache: false,
            ..prep.clone()
        },
        friction,
        None,
        progress,
    )
    .map(|(s, _)| s)
}

fn prepare_from(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    grains: Vec<PlacedGrain>,
    exchange: Option<&Arc<dyn Exchange>>,
    progress: &mut dyn FnMut(PrepProgress),
) -> PreparedSample {
    if prep.tiled {
        prepare_tiled(track, ballast, prep, grains, exchange, progress)
    } else {
        deposit(track, ballast, prep, grains, exchange, progress)
    }
}

/// The solver settings of every stage of the preparation.
fn deposition_settings(prep: &PreparationSpec) -> StepSettings {
    StepSettings {
        dt: prep.dt,
        alert: prep.alert,
        solver: SolverSettings {
            tolerance: prep.tolerance,
            max_iterations: prep.max_iterations,
            norm: ConvergenceNorm::Quad,
            ..SolverSettings::default()
        },
        // Parallel NLGS on the same split as the default job (deterministic, any thread count).
        ddm: Some(default_ddm()),
        ..StepSettings::default()
    }
}

/// The preparation's friction: `prep.friction` on every contact.
fn deposition_friction(prep: &PreparationSpec) -> TrackFriction {
    TrackFriction {
        grain_grain: prep.friction,
        grain_block: prep.friction,
        grain_tine: prep.friction,
        grain_wall: prep.friction,
    }
}

/// Steps `world` until `min_time`, then on while 99 % of its grains are not slower than
/// `prep.rest_speed`, for at most `max_extra` more seconds; returns the steps done.
fn settle(
    world: &mut World,
    prep: &PreparationSpec,
    stage: u8,
    min_time: f64,
    max_extra: f64,
    progress: &mut dyn FnMut(PrepProgress),
) -> u64 {
    let n = world.bodies.len();
    let mut speed = f64::INFINITY;
    let mut steps = 0;
    while world.time < min_time || (speed > prep.rest_speed && world.time < min_time + max_extra) {
        let r = world.step();
        steps += 1;
        if world.step_index.is_multiple_of(20) {
            speed = rest_quantile(world);
            progress(PrepProgress {
                stage,
                time: world.time,
                target: min_time,
                grains: n,
                contacts: r.contacts,
            });
        }
    }
    steps
}

/// The classic preparation (stages 1–5 of the [module documentation](self)).
fn deposit(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    mut grains: Vec<PlacedGrain>,
    exchange: Option<&Arc<dyn Exchange>>,
    progress: &mut dyn FnMut(PrepProgress),
) -> PreparedSample {
    let clock = std::time::Instant::now();
    let generated = grains.len();
    // Stack the grains on a height map of their own surfaces (the stack is about 1.8 times
    // the settled bed's height on the default bed: a short fall).
    let bed = track.bed_box();
    let height = place_on_height_map(&mut grains, &bed, ballast.seed, SPOTS);
    // The stack's top falls by what exceeds the settled bed (about `overfill` times the bed's
    // height, at the target compacity).
    let excess = height - bed.min.z - prep.overfill * (bed.max.z - bed.min.z);
    let fall = (2.0 * excess.max(0.0) / 9.81).sqrt();

    let settings = deposition_settings(prep);
    let density = ballast.grains.density;
    let friction = deposition_friction(prep);

    // Deposition into the empty box.
    let (bodies, layout) = build_bodies(track, &Blocks::Absent, None, &grains, density);
    let mut world = World::new(bodies, friction.table(), settings.clone());
    world.set_exchange(exchange.cloned());
    let mut steps = settle(
        &mut world,
        prep,
        1,
        fall + prep.settle_time,
        prep.max_extra_time,
        progress,
    );
    let mut simulated = world.time;
    for (g, (p, q)) in grains.iter_mut().zip(poses(&world, layout.grains.clone())) {
        (g.position, g.orientation) = (p, q);
    }

    // Excavate the blocks and trim above the block tops.
    let top = track.top();
    let blocks: Vec<_> = (1..=track.blocks).map(|k| track.block_box(k)).collect();
    let (mut in_blocks, mut above) = (0, 0);
    grains.retain(|g| {
        if blocks
            .iter()
            .any(|b| clipped_volume(&g.shape, g.position, g.orientation, b.min, b.max) > 0.0)
        {
            in_blocks += 1;
            false
        } else if g.position.z > top {
            above += 1;
            false
        } else {
            true
        }
    });

    // Settle around the fixed blocks.
    let (bodies, layout) = build_bodies(track, &Blocks::Fixed, None, &grains, density);
    let mut world = World::new(bodies, friction.table(), settings);
    world.set_exchange(exchange.cloned());
    steps += settle(
        &mut world,
        prep,
        2,
        prep.block_settle_time,
        prep.max_extra_time,
        progress,
    );
    simulated += world.time;
    let mut sample = heal_and_keep(&mut world, prep, layout.grains, grains, progress);
    let r = &mut sample.report;
    r.generated = generated;
    r.removed_in_blocks = in_blocks;
    r.removed_above = above;
    r.steps += steps;
    r.simulated_s += simulated;
    r.stack_height = height - bed.min.z;
    r.wall_s = clock.elapsed().as_secs_f64();
    sample
}

/// Heals `world` (stage 5), whose grains are the bodies `bodies` made of `grains` in order,
/// and returns the bed: the grains at their poses, those still wedged taken out. The report
/// holds what the healing did and the bed's final state; the caller fills in the rest.
fn heal_and_keep(
    world: &mut World,
    prep: &PreparationSpec,
    bodies: std::ops::Range<usize>,
    mut grains: Vec<PlacedGrain>,
    progress: &mut dyn FnMut(PrepProgress),
) -> PreparedSample {
    let healed = heal(world, prep, bodies.clone(), progress);
    for (g, (p, q)) in grains.iter_mut().zip(poses(world, bodies.clone())) {
        (g.position, g.orientation) = (p, q);
    }
    let first = bodies.start;
    let mut j = 0;
    grains.retain(|_| {
        j += 1;
        healed.wedged.binary_search(&(first + j - 1)).is_err()
    });
    let (speed, mean_speed) = speeds(world);
    PreparedSample {
        report: PreparationReport {
            grains: grains.len(),
            removed_wedged: healed.wedged.len(),
            steps: healed.steps,
            simulated_s: healed.steps as f64 * prep.dt,
            max_penetration: healed.max_penetration,
            max_speed: speed,
            mean_speed,
            settled_penetration: healed.settled_penetration,
            heal_steps: healed.steps,
            ..PreparationReport::default()
        },
        grains,
        from_cache: false,
    }
}

/// The track segment a tiled preparation prepares (one block, one spacing long) and how:
/// deposited in one piece.
fn segment(track: &TrackSpec, prep: &PreparationSpec) -> (TrackSpec, PreparationSpec) {
    let piece_track = TrackSpec {
        blocks: 1,
        length: Some(track.spacing),
        ..track.clone()
    };
    let piece = PreparationSpec {
        tiled: false,
        ..prep.clone()
    };
    (piece_track, piece)
}

/// Checks that `track` can be tiled by its segment (`preparation.tiled`).
fn check_tiling(track: &TrackSpec) -> Result<(), FieldError> {
    let whole = track.blocks as f64 * track.spacing;
    if (track.length() - whole).abs() > 1e-9 * whole {
        return Err(crate::error::refuse(
            "preparation.tiled",
            true,
            &format!(
                "true only when track.length ({} m) is blocks × spacing ({} m)",
                track.length(),
                whole
            ),
        ));
    }
    Ok(())
}

/// The tiled preparation (`preparation.tiled`): the segment's bed by [`deposit`], repeated
/// `blocks` times along the track, settled as a whole for `tile_settle_time` (the grains at
/// the former segment ends lean on their new neighbours instead of a wall), then healed.
/// `generated` is the segment's generated list repeated `blocks` times (see [`generate`]).
fn prepare_tiled(
    track: &TrackSpec,
    ballast: &BallastSpec,
    prep: &PreparationSpec,
    generated: Vec<PlacedGrain>,
    exchange: Option<&Arc<dyn Exchange>>,
    progress: &mut dyn FnMut(PrepProgress),
) -> PreparedSample {
    let clock = std::time::Instant::now();
    let copies = track.blocks.max(1);
    let n = generated.len() / copies;
    let (piece_track, piece) = segment(track, prep);
    let seg = deposit(
        &piece_track,
        ballast,
        &piece,
        generated[..n].to_vec(),
        exchange,
        progress,
    );
    let mut grains = Vec::with_capacity(seg.grains.len() * copies);
    for c in 0..copies {
        let shift = DVec3::new(c as f64 * track.spacing, 0.0, 0.0);
        grains.extend(seg.grains.iter().map(|g| PlacedGrain {
            index: c * n + g.index,
            shape: g.shape.clone(),
            position: g.position + shift,
            orientation: g.orientation,
        }));
    }
    let (bodies, layout) =
        build_bodies(track, &Blocks::Fixed, None, &grains, ballast.grains.density);
    let mut world = World::new(
        bodies,
        deposition_friction(prep).table(),
        deposition_settings(prep),
    );
    world.set_exchange(exchange.cloned());
    let steps = settle(&mut world, prep, 2, prep.tile_settle_time, 0.0, progress);
    let simulated = world.time;
    let mut sample = heal_and_keep(&mut world, prep, layout.grains, grains, progress);
    let s = &seg.report;
    let r = &mut sample.report;
    r.generated = generated.len();
    r.removed_in_blocks = s.removed_in_blocks * copies;
    r.removed_above = s.removed_above * copies;
    r.removed_wedged += s.removed_wedged * copies;
    r.steps += s.steps + steps;
    r.simulated_s += s.simulated_s + simulated;
    r.stack_height = s.stack_height;
    r.settled_penetration = r.settled_penetration.max(s.settled_penetration);
    r.heal_steps += s.heal_steps;
    r.wall_s = clock.elapsed().as_secs_f64();
    sample
}

/// What the healing stage did.
struct Healed {
    steps: u64,
    /// Largest overlap before, and after (the wedged grains left out) (m).
    settled_penetration: f64,
    max_penetration: f64,
    /// Bodies of the grains to take out (sorted).
    wedged: Vec<usize>,
}

/// Stage 5 on the settled `world` (see the [module documentation](self)), whose grains are
/// the bodies `grains`: steps from rest with [`heal_correction`] until the largest overlap is
/// below `prep.heal_overlap` or `prep.heal_steps` are done; the grains still wedged deeper
/// (jammed among neighbours that make room only slowly: 18 of 87,159 grains on the paper
/// preset's bed of session 7, none on the default and the test beds) are to be taken out, as the excavation takes out the grains in the
/// blocks: of each such contact, the lighter grain.
fn heal(
    world: &mut World,
    prep: &PreparationSpec,
    grains: std::ops::Range<usize>,
    progress: &mut dyn FnMut(PrepProgress),
) -> Healed {
    let settled_penetration = max_overlap(world);
    world.settings.correction = heal_correction(prep.alert);
    let mut max_penetration = settled_penetration;
    let mut steps = 0;
    while max_penetration >= prep.heal_overlap && steps < prep.heal_steps as u64 {
        world.bodies.velocity.fill(DVec3::ZERO);
        world.bodies.angular_velocity.fill(DVec3::ZERO);
        world.bodies.angular_momentum.fill(DVec3::ZERO);
        let r = world.step();
        steps += 1;
        // Measured at the start of the step: the bed this step started from.
        max_penetration = r.max_penetration;
        if steps.is_multiple_of(10) {
            progress(PrepProgress {
                stage: 3,
                time: world.time,
                target: world.time,
                grains: grains.len(),
                contacts: r.contacts,
            });
        }
    }
    if steps > 0 {
        // The last step's correction moved the grains on from the bed it measured.
        world.prepare();
    }
    let wedged = wedged_grains(world, prep.heal_overlap, grains);
    let max_penetration = world.max_over_contacts(0.0, |c, k| {
        let kept = wedged.binary_search(&(c.body1[k] as usize)).is_err()
            && wedged.binary_search(&(c.body2[k] as usize)).is_err();
        if kept {
            -c.gap[k]
        } else {
            0.0
        }
    });
    Healed {
        steps,
        settled_penetration,
        max_penetration,
        wedged,
    }
}

/// Cell of the height map (m).
const MAP_CELL: f64 = 5e-3;
/// Random spots tried per grain; the lowest wins. More spots fill the holes of the stack
/// better, so the fall to simulate is shorter: on the default bed 4 spots stack 1.35 m, 32
/// spots 0.96 m (the settled bed is 0.52 m), for 3 s of placement.
const SPOTS: usize = 32;

/// Clearance added under each dropped grain (m): covers the sampling of the envelopes at cell
/// centres (see [`place_on_height_map`]).
const DROP_CLEARANCE: f64 = 1e-3;

/// Places `grains` (orientations kept) by dropping them onto a height map of the bed, each at
/// the lowest of [`SPOTS`] seeded random spots; returns the top height.
///
/// A grain's lower and upper envelopes over a vertical column are its face planes: the column
/// `(u, v)` (relative to the centre) crosses the grain between `l = max (d − n_x u − n_y v)/n_z`
/// over the downward faces and `h = min` of the same over the upward faces, where `l ≤ h`. The
/// grain is dropped until its lower envelope meets the map at some cell centre (plus
/// [`DROP_CLEARANCE`]), and the map then takes its upper envelope. Sampled at cell centres, the
/// envelopes may miss a sliver of a grain's silhouette, so neighbours can overlap by a fraction
/// of a millimetre, which the first steps' overlap correction removes; the stack is about as
/// dense as a loose pour, so the deposition is a short settlement rather than a long fall.
fn place_on_height_map(
    grains: &mut [PlacedGrain],
    bed: &crate::track::Aabb,
    seed: u64,
    spots: usize,
) -> f64 {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x6265_645f_6d61_7000);
    let nx = ((bed.max.x - bed.min.x) / MAP_CELL).ceil() as usize;
    let ny = ((bed.max.y - bed.min.y) / MAP_CELL).ceil() as usize;
    let mut map = vec![bed.min.z; nx * ny];
    let mut top = bed.min.z;
    // Envelopes `(low, high)` of the footprint's cells at the spot being tried and at the best
    // spot so far, row by row (NaN outside the silhouette).
    let mut envelope: Vec<(f64, f64)> = Vec::new();
    let mut chosen: Vec<(f64, f64)> = Vec::new();
    for g in grains.iter_mut() {
        let q = g.orientation;
        let (lo, hi) = g.shape.vertices.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &v| {
                let w = q * v;
                (lo.min(w), hi.max(w))
            },
        );
        let planes: Vec<(DVec3, f64)> = g
            .shape
            .face_normals
            .iter()
            .zip(&g.shape.face_offsets)
            .map(|(&n, &d)| (q * n, d))
            .collect();
        // Envelopes of the column at (u, v) from the centre, `None` outside the silhouette.
        let column = |u: f64, v: f64| -> Option<(f64, f64)> {
            let (mut low, mut high) = (f64::NEG_INFINITY, f64::INFINITY);
            for &(n, d) in &planes {
                let rest = d - n.x * u - n.y * v;
                if n.z < -1e-12 {
                    low = low.max(rest / n.z);
                } else if n.z > 1e-12 {
                    high = high.min(rest / n.z);
                } else if rest < 0.0 {
                    return None;
                }
            }
            (low <= high).then_some((low, high))
        };
        let size = hi - lo;
        // Cells covered by the footprint whose low corner is in cell (i, j).
        let (cx, cy) = (
            ((size.x / MAP_CELL).ceil() as usize + 1).min(nx),
            ((size.y / MAP_CELL).ceil() as usize + 1).min(ny),
        );
        let mut best: Option<(f64, DVec3, usize, usize)> = None;
        chosen.clear();
        for _ in 0..spots {
            let i = rng.gen_range(0..=nx - cx);
            let j = rng.gen_range(0..=ny - cy);
            // Footprint low corner at the cell corner, kept inside the walls.
            let x0 = (bed.min.x + i as f64 * MAP_CELL).min(bed.max.x - size.x - 1e-4);
            let y0 = (bed.min.y + j as f64 * MAP_CELL).min(bed.max.y - size.y - 1e-4);
            let (x, y) = (x0 - lo.x, y0 - lo.y);
            envelope.clear();
            // The lowest centre height that keeps the lower envelope above the map.
            let mut z = bed.min.z - lo.z;
            for b in j..j + cy {
                for a in i..i + cx {
                    let u = bed.min.x + (a as f64 + 0.5) * MAP_CELL - x;
                    let v = bed.min.y + (b as f64 + 0.5) * MAP_CELL - y;
                    let e = column(u, v).unwrap_or((f64::NAN, f64::NAN));
                    if !e.0.is_nan() {
                        z = z.max(map[b * nx + a] - e.0);
                    }
                    envelope.push(e);
                }
            }
            if best.is_none_or(|(bz, ..)| z < bz) {
                best = Some((z, DVec3::new(x, y, z + DROP_CLEARANCE), i, j));
                std::mem::swap(&mut envelope, &mut chosen);
            }
        }
        let Some((_, position, i, j)) = best else {
            continue;
        };
        g.position = position;
        top = top.max(position.z + hi.z);
        for (k, &(_, high)) in chosen.iter().enumerate() {
            let cell = &mut map[(j + k / cx) * nx + i + k % cx];
            if !high.is_nan() {
                *cell = cell.max(position.z + high);
            }
        }
    }
    top
}

/// The bodies (sorted) to take out so that no contact among the others overlaps by
/// `bound` or more: of each such contact, its lighter grain,
/// or its grain when the other body is not one; the lower index when both are as heavy.
fn wedged_grains(world: &World, bound: f64, grains: std::ops::Range<usize>) -> Vec<usize> {
    // The contacts that deep, from every rank, in pair order.
    let c = &world.gather_contacts(|c, k| c.gap[k] <= -bound || c.gap[k].is_nan());
    let mass = |i: usize| 1.0 / world.bodies.inv_mass[i];
    let mut out: Vec<usize> = Vec::new();
    for k in 0..c.len() {
        let (a, b) = (c.body1[k] as usize, c.body2[k] as usize);
        if out.contains(&a) || out.contains(&b) {
            continue;
        }
        let take = match (grains.contains(&a), grains.contains(&b)) {
            (true, true) => {
                if (mass(a), a) < (mass(b), b) {
                    a
                } else {
                    b
                }
            }
            (true, false) => a,
            (false, true) => b,
            (false, false) => continue,
        };
        out.push(take);
    }
    out.sort_unstable();
    out
}

/// Largest overlap among the world's current contacts (m).
fn max_overlap(world: &World) -> f64 {
    world.max_over_contacts(0.0, |c, k| -c.gap[k])
}

/// Largest and mean speed of the dynamic bodies (m/s), rotation included through the
/// circumscribed radius.
fn speeds(world: &World) -> (f64, f64) {
    let all = grain_speeds(world);
    let max = all.iter().copied().fold(0.0, f64::max);
    (max, all.iter().sum::<f64>() / all.len().max(1) as f64)
}

/// The speed that 99 % of the dynamic bodies stay below (m/s), see [`speeds`].
fn rest_quantile(world: &World) -> f64 {
    let mut all = grain_speeds(world);
    if all.is_empty() {
        return 0.0;
    }
    let k = (0.99 * (all.len() - 1) as f64).round() as usize;
    *all.select_nth_unstable_by(k, f64::total_cmp).1
}

/// Speed of each dynamic body, rotation included at its circumscribed radius (m/s), in body
/// order, each from the rank that answers for it (on ranks, a collective).
fn grain_speeds(world: &World) -> Vec<f64> {
    let b = &world.bodies;
    let speeds = world.gather_body_values(|i, out| {
        if b.kind[i] != ballast_engine::bodies::BodyKind::Dynamic {
            return;
        }
        let r = match &b.shape[i] {
            Shape::Polyhedron(p) => p.radius,
            Shape::Plane { .. } => 0.0,
        };
        out.push(b.velocity[i].length() + b.angular_velocity[i].length() * r);
    });
    speeds.iter().map(|(_, v)| v[0]).collect()
}

/// The poses of the bodies `bodies`, each from the rank that answers for it (on ranks, a
/// collective).
fn poses(world: &World, bodies: std::ops::Range<usize>) -> Vec<(DVec3, DQuat)> {
    let b = &world.bodies;
    let got = world.gather_body_values(|i, out| {
        if bodies.contains(&i) {
            let (p, q) = (b.position[i], b.orientation[i]);
            out.extend([p.x, p.y, p.z, q.x, q.y, q.z, q.w]);
        }
    });
    debug_assert_eq!(got.len(), bodies.len());
    got.iter()
        .map(|(_, v)| {
            (
                DVec3::new(v[0], v[1], v[2]),
                DQuat::from_xyzw(v[3], v[4], v[5], v[6]),
            )
        })
        .collect()
}

/// The cache file: magic, format, key, report (JSON), then per kept grain its index in the
/// generated list and its pose (exact bits), and an FNV-1a checksum of all that.
fn encode(sample: &PreparedSample, key: &str) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT.to_le_bytes());
    out.extend_from_slice(&(key.len() as u64).to_le_bytes());
    out.extend_from_slice(key.as_bytes());
    let report = serde_json::to_string(&sample.report).expect("report serialises");
    out.extend_from_slice(&(report.len() as u64).to_le_bytes());
    out.extend_from_slice(report.as_bytes());
    out.extend_from_slice(&(sample.grains.len() as u64).to_le_bytes());
    for g in &sample.grains {
        out.extend_from_slice(&(g.index as u32).to_le_bytes());
        for v in g.position.to_array() {
            out.extend_from_slice(&v.to_bits().to_le_bytes());
        }
        for v in g.orientation.to_array() {
            out.extend_from_slice(&v.to_bits().to_le_bytes());
        }
    }
    let sum = fnv1a64(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// Reads a cached sample; `None` if anything is off (the bed is then prepared again).
fn decode(bytes: &[u8], key: &str, generated: &[PlacedGrain]) -> Option<PreparedSample> {
    let n = bytes.len();
    if n < MAGIC.len() + 8 {
        return None;
    }
    let (body, sum) = bytes.split_at(n - 8);
    if fnv1a64(body) != u64::from_le_bytes(sum.try_into().ok()?) {
        return None;
    }
    let mut d = body.strip_prefix(MAGIC)?;
    let mut take = |k: usize| -> Option<&[u8]> {
        if d.len() < k {
            return None;
        }
        let (a, b) = d.split_at(k);
        d = b;
        Some(a)
    };
    let format = u32::from_le_bytes(take(4)?.try_into().ok()?);
    if format != FORMAT {
        return None;
    }
    let klen = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    if take(klen)? != key.as_bytes() {
        return None;
    }
    let rlen = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let report: PreparationReport = serde_json::from_slice(take(rlen)?).ok()?;
    let count = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    if count > generated.len() {
        return None;
    }
    let mut grains = Vec::with_capacity(count);
    let f = |b: &[u8]| f64::from_bits(u64::from_le_bytes(b.try_into().unwrap()));
    for _ in 0..count {
        let index = u32::from_le_bytes(take(4)?.try_into().ok()?) as usize;
        let g = generated.get(index)?;
        let p = take(24)?;
        let q = take(32)?;
        grains.push(PlacedGrain {
            index,
            shape: g.shape.clone(),
            position: DVec3::new(f(&p[0..8]), f(&p[8..16]), f(&p[16..24])),
            orientation: DQuat::from_xyzw(f(&q[0..8]), f(&q[8..16]), f(&q[16..24]), f(&q[24..32])),
        });
    }
    Some(PreparedSample {
        grains,
        report,
        from_cache: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// More spots stack lower (a shorter fall to simulate), every grain inside the walls.
    #[test]
    fn more_spots_stack_lower_inside_the_walls() {
        let track = TrackSpec {
            depth: 0.12,
            width: 0.4,
            ..TrackSpec::default()
        };
        let (ballast, prep) = (BallastSpec::default(), PreparationSpec::default());
        let bed = track.bed_box();
        let stack = |spots: usize| {
            let mut g = generate(&track, &ballast, &prep).unwrap();
            let h = place_on_height_map(&mut g, &bed, ballast.seed, spots);
            for p in &g {
                for v in &p.shape.vertices {
                    let w = p.position + p.orientation * *v;
                    assert!(w.x >= bed.min.x && w.x <= bed.max.x, "x {w}");
                    assert!(w.y >= bed.min.y && w.y <= bed.max.y, "y {w}");
                    assert!(w.z >= bed.min.z && w.z <= h + 1e-12, "z {w} (top {h})");
                }
            }
            h - bed.min.z
        };
        let (few, many) = (stack(4), stack(SPOTS));
        assert!(
            many < 0.85 * few,
            "{SPOTS} spots: {many} m, 4 spots: {few} m"
        );
    }
}
