//! The run loop of `ballast run` as a library call: a scenario (an engine scenario, or a track
//! scenario with a `[track]` table: bed preparation, tamping, indicators) stepped to its end
//! while its run folder is written: `scenario.toml`, `series.csv`, ParaView frames,
//! checkpoints, `summary.json`, `report.md` with its figures, and for track runs the sections.
//! A run resumes from its folder's newest valid checkpoint, is stopped by the health check
//! when its state stops being physical, and stops between two steps when its front end asks
//! ([`Observer::stop_requested`]).

use crate::report::write_run_report;
use ballast_engine::health::{initial_warnings, Divergence, HealthCheck};
use ballast_engine::output::checkpoint::{
    checkpoint_path, list_checkpoints, newest_valid_checkpoint, prune_checkpoints,
    remove_partial_checkpoints, write_checkpoint_on_ranks, Snapshot,
};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::output::{
    json_number, naming, quality_row, series_row, write_atomic, RunStats, Summary, QUALITY_HEADER,
    SERIES_HEADER,
};
use ballast_engine::scenario::Scenario;
use ballast_engine::solver::DdmSettings;
use ballast_engine::world::{StepReport, World};
use ballast_railway::indicators::Indicators;
use ballast_railway::preparation::PrepProgress;
use ballast_railway::scene::Layout;
use ballast_railway::sections::{section_csv, Sections};
use ballast_railway::tamping::Cycle;
use ballast_railway::{is_track_scenario, TrackScenario};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Checkpoints kept in `DIR/checkpoints` (the newest ones).
const KEEP_CHECKPOINTS: usize = 3;

/// Overlaps deeper than this (m) are reported with the two bodies (4 % of the smallest
/// ballast grain).
const OVERLAP_REPORT: f64 = 1e-3;

/// Steps with such an overlap named one by one; beyond, only their number.
const OVERLAP_LINES: u64 = 20;

/// Why a run did not finish.
#[derive(Debug)]
pub enum Failure {
    /// Bad input: a scenario, setting or flag refused, or a folder that is not this run's
    /// (the command's exit code 1).
    Error(String),
    /// A file that cannot be written or read (a full disk, a file size limit, a folder
    /// without permission): the message names the file; rows and checkpoints written before
    /// are whole, so the run continues from its last checkpoint once the cause is removed
    /// (exit code 1).
    Io(String),
    /// The health check stopped a diverging run (exit code 3); its outputs are written.
    Diverged(String),
    /// A stop was requested ([`Observer::stop_requested`]: Ctrl-C or SIGTERM on the command
    /// line) and the run stopped after a step, its state checkpointed (exit code 130).
    Interrupted(String),
}

impl Failure {
    /// The message, whatever the kind of failure.
    pub fn message(&self) -> &str {
        match self {
            Failure::Error(m) | Failure::Io(m) | Failure::Diverged(m) | Failure::Interrupted(m) => {
                m
            }
        }
    }
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.message())
    }
}

impl std::error::Error for Failure {}

impl From<String> for Failure {
    fn from(e: String) -> Self {
        Failure::Error(e)
    }
}

/// What a front end sees of a run, and how it stops one. Every method has a default: no
/// progress display, messages on stderr, no stop.
pub trait Observer {
    /// The steps start: `total` of them in this session (a resumed run counts from its
    /// checkpoint). Called once the scene is built and its folder ready.
    fn start(&mut self, _total: u64) {}

    /// After each step: `done` steps of this session so far, and the step's report (its
    /// index, time, contacts, NLGS iterations, …).
    fn step(&mut self, _done: u64, _report: &StepReport) {}

    /// The steps are over or stopped; called before the closing messages.
    fn finish(&mut self) {}

    /// Asked after every step: `true` stops the run after it, with a checkpoint, `"status":
    /// "interrupted"` in `summary.json` and [`Failure::Interrupted`].
    fn stop_requested(&mut self) -> bool {
        false
    }

    /// A line for the user: warnings (`warning: …`), the bed's preparation, the closing line.
    fn message(&mut self, line: &str) {
        eprintln!("{line}");
    }
}

/// The default [`Observer`]: no progress, messages on stderr, never stops.
#[derive(Clone, Copy, Debug, Default)]
pub struct Plain;

impl Observer for Plain {}

/// How a front end names a run's arguments in its messages (`--out DIR` on the command line,
/// `out='DIR'` in Python), so that a refusal names what its user wrote.
#[derive(Clone, Copy, Debug)]
pub struct ArgNames {
    /// The output folder: `--out DIR`.
    pub out: fn(&Path) -> String,
    /// Resuming the run in a folder: `--resume DIR`.
    pub resume: fn(&Path) -> String,
    /// What continues the run in a folder: `` `ballast run --resume DIR` ``.
    pub resume_command: fn(&Path) -> String,
    /// Deleting a previous run's files first: `--overwrite`.
    pub overwrite: &'static str,
    /// A step count given by the front end rather than the scenario: `--steps`.
    pub steps: &'static str,
    /// Subdomains given by the front end rather than the scenario: `--subdomains`.
    pub subdomains: &'static str,
}

impl ArgNames {
    /// The names of `ballast run`'s options.
    pub const CLI: ArgNames = ArgNames {
        out: |d| format!("--out {}", d.display()),
        resume: |d| format!("--resume {}", d.display()),
        resume_command: |d| format!("`ballast run --resume {}`", d.display()),
        overwrite: "--overwrite",
        steps: "--steps",
        subdomains: "--subdomains",
    };
}

/// What `ballast run` was asked to do.
pub struct RunArgs<'a> {
    /// Scenario file; `None`: `preset`, or `out/scenario.toml` when resuming.
    pub file: Option<&'a Path>,
    /// Built-in track scenario (`default`, `paper`) when there is no file.
    pub preset: Option<&'a str>,
    /// The run folder.
    pub out: &'a Path,
    /// Continue in `out` from its newest valid checkpoint.
    pub resume: bool,
    /// Delete the run files a previous run left in `out` before starting (else such a folder
    /// is refused).
    pub overwrite: bool,
    /// Stop after this many steps (the scenario's count when `None`).
    pub steps: Option<u64>,
    /// Worker threads, as written in `summary.json`.
    pub threads: usize,
    /// Domain decomposition over the scenario's (`[1, 1, 1]`: monolithic NLGS).
    pub subdomains: Option<[usize; 3]>,
    /// Only warnings and errors as messages.
    pub quiet: bool,
    /// Folder of prepared ballast beds; `None`: no cache.
    pub cache: Option<PathBuf>,
    /// The processes of a run distributed over ranks (MPI); `None`: one process.
    pub ranks: Option<&'a dyn Ranks>,
}

/// The processes of a run distributed over ranks, as a front end provides them (the command
/// line's over MPI). Every rank builds the same scene (a track's bed prepared together) and
/// steps it in lockstep, sharing its domain-decomposed solves and its narrow phase
/// ([`ballast_engine::solver::exchange`]); rank 0 writes the run folder and the bed cache, the
/// others follow ([`Job::follow`]). The observer of each rank must agree with the
/// others on [`Observer::stop_requested`].
pub trait Ranks {
    /// The solves' collective.
    fn exchange(&self) -> std::sync::Arc<dyn ballast_engine::solver::Exchange>;
}

/// How [`Job::build`] builds a scene.
#[derive(Clone, Copy, Debug)]
pub struct BuildOptions<'a> {
    /// Folder of prepared ballast beds; `None`: no cache.
    pub cache: Option<&'a Path>,
    /// Domain decomposition over the scenario's (`[1, 1, 1]`: monolithic NLGS).
    pub subdomains: Option<[usize; 3]>,
    /// Only warnings as messages (no report of the bed's preparation).
    pub quiet: bool,
    /// How the front end names its arguments.
    pub names: &'a ArgNames,
    /// The ranks of a distributed run, which prepare a track's bed together (rank 0 writes
    /// the cache); `None`: one process.
    pub exchange: Option<&'a std::sync::Arc<dyn ballast_engine::solver::Exchange>>,
}

/// How [`Job::run`] runs.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions<'a> {
    /// The run folder.
    pub out: &'a Path,
    /// Continue the run in `out` from its newest valid checkpoint (read into the job's
    /// world), rather than start one there.
    pub resume: bool,
    /// Delete the run files a previous run left in `out` before starting (else such a folder
    /// is refused).
    pub overwrite: bool,
    /// Stop at this step (the scenario's count when `None`).
    pub steps: Option<u64>,
    /// Worker threads, as written in `summary.json`.
    pub threads: usize,
    /// Only warnings as messages.
    pub quiet: bool,
    /// How the front end names its arguments.
    pub names: &'a ArgNames,
}

/// What a finished run gives back.
#[derive(Clone, Debug)]
pub struct RunOutcome {
    /// `summary.json`, as written.
    pub summary: serde_json::Value,
    /// The step the run ended at.
    pub steps: u64,
}

/// A scene ready to run: its world, the statistics of its steps, and what its run folder
/// needs (scenario text, intervals, track indicators and sections, health bounds).
pub struct Job {
    world: World,
    stats: RunStats,
    /// Where the scenario came from, for messages and the report.
    source: String,
    /// The resolved scenario (`scenario.toml`).
    text: String,
    /// The scenario's step count.
    steps: u64,
    output_interval: u64,
    vtk_interval: u64,
    checkpoint_interval: u64,
    track: Option<TrackParts>,
    /// Bounds of the scene as built, before any checkpoint is read (the same on resume).
    health: HealthCheck,
    /// The state before the step [`Job::checked_step`] is taking, put back if it diverges.
    before: Snapshot,
}

/// The track-specific parts of a run.
struct TrackParts {
    indicators: Indicators,
    grains: usize,
    preparation: serde_json::Value,
    /// When each tamped block's cycle happens (`summary.json`'s `cycle`).
    cycle_json: serde_json::Value,
    /// What the sections are cut from (their moments depend on the run's step count).
    scenario: TrackScenario,
    layout: Layout,
    cycle: Cycle,
}

impl TrackParts {
    /// The sections of a run of `steps` steps.
    fn sections(&self, steps: u64) -> Sections {
        let s = &self.scenario;
        Sections::new(
            &s.track,
            s.tamping.tine_y.first().copied().unwrap_or(0.0),
            &self.layout,
            &self.cycle,
            &s.tamping.blocks,
            s.simulation.dt,
            steps,
        )
    }
}

fn apply_subdomains(ddm: &mut Option<DdmSettings>, dims: Option<[usize; 3]>) {
    if let Some(dims) = dims {
        *ddm = match (dims, ddm.take()) {
            ([1, 1, 1], _) => None,
            (dims, d) => Some(DdmSettings {
                subdomains: dims,
                ..d.unwrap_or_default()
            }),
        };
    }
}

/// The files and folders a run writes in its folder (all that `--overwrite` deletes).
const RUN_FILES: [&str; 12] = [
    "scenario.toml",
    "summary.json",
    "series.csv",
    "quality.csv",
    "report.md",
    "grains.pvd",
    "bodies.pvd",
    "contacts.pvd",
    "vtk",
    "checkpoints",
    "plots",
    "sections",
];

/// What a previous run left in `out` that a new run would mix with: the run files present,
/// with the number of checkpoints.
fn previous_run(out: &Path) -> Vec<String> {
    let mut found = Vec::new();
    for name in ["scenario.toml", "summary.json", "series.csv", "quality.csv"] {
        if out.join(name).exists() {
            found.push(name.to_string());
        }
    }
    match list_checkpoints(&out.join("checkpoints")) {
        Ok(l) if !l.is_empty() => found.push(format!("{} checkpoint(s)", l.len())),
        _ => {}
    }
    found
}

/// Makes `out` a folder that belongs to the run about to start: refused when it holds another
/// run's files (its checkpoints would be resumed, its rows mixed with the new ones), unless
/// `overwrite`, which deletes exactly the files a run writes ([`RUN_FILES`]) and nothing else.
fn claim_folder(out: &Path, overwrite: bool, names: &ArgNames) -> Result<(), Failure> {
    let found = previous_run(out);
    if !found.is_empty() {
        if !overwrite {
            return Err(Failure::Error(format!(
                "{}: the folder holds another run ({}); continue it with {}, write to another \
                 folder, or add {} to delete that run's files first",
                (names.out)(out),
                found.join(", "),
                (names.resume_command)(out),
                names.overwrite
            )));
        }
        for name in RUN_FILES {
            let p = out.join(name);
            let removed = if p.is_dir() {
                std::fs::remove_dir_all(&p)
            } else if p.exists() {
                std::fs::remove_file(&p)
            } else {
                Ok(())
            };
            removed.map_err(|e| {
                Failure::Io(format!(
                    "{}: cannot delete {}: {e}",
                    names.overwrite,
                    p.display()
                ))
            })?;
        }
    }
    std::fs::create_dir_all(out).map_err(|e| {
        Failure::Io(format!(
            "cannot create output folder {}: {e}",
            out.display()
        ))
    })
}

/// The scenario of a `ballast run` (file, preset, or the run folder's copy when resuming):
/// where it came from, and its text.
fn scenario_text(a: &RunArgs) -> Result<(String, String), String> {
    Ok(match (a.file, a.preset) {
        (Some(f), _) => (
            f.display().to_string(),
            std::fs::read_to_string(f)
                .map_err(|e| format!("cannot read scenario {}: {e}", f.display()))?,
        ),
        (None, None) if a.resume => {
            let f = a.out.join("scenario.toml");
            (
                f.display().to_string(),
                std::fs::read_to_string(&f).map_err(|e| {
                    format!(
                        "{}: cannot read {}: {e}",
                        (ArgNames::CLI.resume)(a.out),
                        f.display()
                    )
                })?,
            )
        }
        (None, p) => {
            let name = p.unwrap_or("default");
            let s = TrackScenario::preset(name).map_err(|e| e.to_string())?;
            (format!("preset {name}"), s.to_toml())
        }
    })
}

/// Runs a scenario (file or preset) up to its step count (or `steps`), writing
/// `scenario.toml`, `summary.json`, `series.csv`, ParaView frames, checkpoints and the report
/// in `out`, or continues the run there (`resume`): `ballast run` as a call, its messages
/// naming the command's options.
pub fn run(a: &RunArgs, observer: &mut dyn Observer) -> Result<RunOutcome, Failure> {
    let names = &ArgNames::CLI;
    let exchange = a.ranks.map(|r| r.exchange()).filter(|e| e.size() > 1);
    let writer = exchange.as_ref().is_none_or(|e| e.rank() == 0);
    if !a.resume && writer {
        // Before the bed is prepared (minutes): a refusal should come at once.
        if !a.overwrite && !previous_run(a.out).is_empty() {
            claim_folder(a.out, false, names)?;
        }
    }
    let (source, text) = scenario_text(a)?;
    // The ranks prepare a track's bed together (rank 0 writes the cache).
    let mut job = Job::build(
        &source,
        &text,
        &BuildOptions {
            cache: a.cache.as_deref(),
            subdomains: a.subdomains,
            quiet: a.quiet || !writer,
            names,
            exchange: exchange.as_ref(),
        },
        observer,
    )?;
    job.world_mut().set_exchange(exchange);
    let options = RunOptions {
        out: a.out,
        resume: a.resume,
        overwrite: a.overwrite,
        steps: a.steps,
        threads: a.threads,
        quiet: a.quiet || !writer,
        names,
    };
    if writer {
        job.run(&options, observer)
    } else {
        job.follow(&options, observer)
    }
}

impl Job {
    /// Builds the scene of scenario `text` (an engine scenario, or a track scenario: its bed
    /// prepared, or read from `o.cache`); `source` names where the text came from (a file,
    /// `preset NAME`) in messages and in the report. A refused scenario is
    /// [`Failure::Error`], its message naming the field, the value and what is allowed.
    pub fn build(
        source: &str,
        text: &str,
        o: &BuildOptions,
        observer: &mut dyn Observer,
    ) -> Result<Job, Failure> {
        let job = if is_track_scenario(text) {
            Self::build_track(source, text, o, observer)?
        } else {
            let mut scenario = Scenario::from_toml(text).map_err(|e| format!("{source}: {e}"))?;
            apply_subdomains(&mut scenario.ddm, o.subdomains);
            // The run folder's copy says how the run was made, subdomains included, so that
            // a plain resume rebuilds the same scene.
            let text = match o.subdomains {
                Some(_) => scenario.to_toml().map_err(|e| e.to_string())?,
                None => text.to_string(),
            };
            let world = scenario.build().map_err(|e| format!("{source}: {e}"))?;
            let sim = &scenario.simulation;
            Job {
                health: scenario.health_check(&world),
                stats: RunStats::default(),
                steps: scenario.steps(),
                output_interval: sim.output_interval,
                vtk_interval: sim.vtk_interval,
                checkpoint_interval: sim.checkpoint_interval,
                track: None,
                world,
                source: source.to_string(),
                text,
                before: Snapshot::default(),
            }
        };
        if let Some(d) = &job.world.settings.ddm {
            let grains = (0..job.world.bodies.len())
                .filter(|&i| job.world.bodies.kind[i] == ballast_engine::bodies::BodyKind::Dynamic)
                .count();
            d.check_grains(grains).map_err(|e| {
                // `e` starts "subdomains = …": name the key, or the option that set it.
                let field = if o.subdomains.is_some() {
                    format!("{}: ", o.names.subdomains)
                } else {
                    "ddm.".to_string()
                };
                format!("{source}: {field}{e}")
            })?;
            if let Some(w) =
                subdomain_warning(&d.subdomains, grains, o.subdomains.is_some(), o.names)
            {
                observer.message(&w);
            }
        }
        Ok(job)
    }

    /// [`Job::build`] for a track scenario.
    fn build_track(
        source: &str,
        text: &str,
        o: &BuildOptions,
        observer: &mut dyn Observer,
    ) -> Result<Job, String> {
        let mut s = TrackScenario::from_toml(text).map_err(|e| format!("{source}: {e}"))?;
        apply_subdomains(&mut s.ddm, o.subdomains);
        let mut last = std::time::Instant::now();
        let quiet = o.quiet;
        if !quiet {
            observer.message(&format!(
                "preparing the ballast bed ({} block(s), {} m × {} m), or reading it from the cache",
                s.track.blocks,
                short(s.track.length()),
                short(s.track.width)
            ));
        }
        let model = s
            .build_shared(o.cache, o.exchange, &mut |p: PrepProgress| {
                if !quiet && last.elapsed().as_secs_f64() > 5.0 {
                    last = std::time::Instant::now();
                    observer.message(&format!(
                        "  {}: t = {:.3} s (at least {:.3} s), {} grains, {} contacts",
                        match p.stage {
                            1 => "deposition",
                            2 => "settling around the blocks",
                            _ => "healing the overlaps",
                        },
                        p.time,
                        p.target,
                        p.grains,
                        p.contacts
                    ));
                }
            })
            .map_err(|e| format!("{source}: {e}"))?;
        if let Some(w) = &model.cache_warning {
            observer.message(&format!("warning: {w}"));
        }
        if !quiet {
            let r = &model.preparation;
            observer.message(&format!(
                "bed {}: {} grains ({} steps of deposition, {:.1} s)",
                if model.from_cache {
                    "read from the cache"
                } else {
                    "prepared"
                },
                r.grains,
                r.steps,
                r.wall_s
            ));
        }
        let sim = &s.simulation;
        Ok(Job {
            health: ballast_engine::scenario::health_check(
                &model.world,
                sim.max_speed,
                sim.max_overlap,
            ),
            stats: RunStats::default(),
            steps: s.steps(),
            output_interval: sim.output_interval,
            vtk_interval: sim.vtk_interval,
            checkpoint_interval: sim.checkpoint_interval,
            text: s.to_toml(),
            track: Some(TrackParts {
                grains: model.layout.grains.len(),
                preparation: serde_json::to_value(&model.preparation).unwrap_or_default(),
                indicators: model.indicators,
                cycle_json: cycle_json(&model.cycle, &s.tamping.blocks),
                layout: model.layout,
                cycle: model.cycle,
                scenario: s,
            }),
            world: model.world,
            source: source.to_string(),
            before: Snapshot::default(),
        })
    }

    /// The world: bodies, contacts, clock.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, to change or step outside a run (a run folder starts at step 0).
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// Statistics of the steps done ([`Job::step`], [`Job::run`]).
    pub fn stats(&self) -> &RunStats {
        &self.stats
    }

    /// The statistics, to replace (with a checkpoint's, say).
    pub fn stats_mut(&mut self) -> &mut RunStats {
        &mut self.stats
    }

    /// One step, counted in the statistics.
    pub fn step(&mut self) -> StepReport {
        let r = self.world.step();
        self.stats.add(&r);
        r
    }

    /// One step as [`Job::step`], under the health check a run is under: the first step of a
    /// simulation checks its initial state first (as [`Job::run`] does), and a step after
    /// which the state is no longer a physical one gives the [`Divergence`] instead of its
    /// report, the world and the statistics put back to the state before it (bit for bit:
    /// stepping on repeats the same step). Not put back when the step was detected before
    /// ([`World::is_detected`]): its state before detection is not kept, and the world is
    /// left in the diverged state. An initial state out of bounds is left as it is, detected.
    /// The check only reads the world: checked steps give the same states as unchecked ones.
    pub fn checked_step(&mut self) -> Result<StepReport, Divergence> {
        let restorable = !self.world.is_detected();
        if restorable {
            self.before.retake(&self.world, Some(&self.stats));
        }
        if self.world.step_index == 0 {
            // Detected now, so that bodies placed inside each other are seen; the step then
            // solves that detection (the same result).
            self.world.detect();
            self.health.initial().check(&self.world)?;
        }
        let r = self.step();
        if let Err(d) = self.health.check(&self.world) {
            if restorable {
                // The snapshot is of this world: restoring it cannot fail.
                if let Ok(stats) = self.before.restore(&mut self.world) {
                    self.stats = stats.unwrap_or_default();
                }
            }
            return Err(d);
        }
        Ok(r)
    }

    /// The resolved scenario: what a run writes to `scenario.toml`.
    pub fn scenario(&self) -> &str {
        &self.text
    }

    /// Where the scenario came from (a file, `preset NAME`).
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The scenario's step count (a track scenario: its whole cycle).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Track runs: the indicators that `series.csv` adds.
    pub fn indicators(&self) -> Option<&Indicators> {
        self.track.as_ref().map(|t| &t.indicators)
    }

    /// The keys of `summary.json` for the steps done so far, `"status": "completed"`, run on
    /// `threads` worker threads.
    pub fn summary(&self, threads: usize) -> Result<serde_json::Value, String> {
        summary_json(&self.world, &self.stats, threads, &self.track, None, None)
    }

    /// Runs the job's world up to `o.steps` (the scenario's step count when `None`) writing its
    /// run folder `o.out`, or continues the run there from its newest valid checkpoint
    /// (`o.resume`). A new run starts at step 0: a world already stepped is refused.
    pub fn run(
        &mut self,
        o: &RunOptions,
        observer: &mut dyn Observer,
    ) -> Result<RunOutcome, Failure> {
        let out = o.out;
        let names = o.names;
        let Job {
            world,
            stats,
            source,
            text,
            output_interval,
            vtk_interval,
            checkpoint_interval,
            track,
            health,
            ..
        } = self;
        let (source, text, track, health) = (&*source, &*text, &*track, &*health);
        let (output_interval, vtk_interval, checkpoint_interval) =
            (*output_interval, *vtk_interval, *checkpoint_interval);
        if !o.resume && world.step_index != 0 {
            return Err(Failure::Error(format!(
                "{}: the simulation is already at step {} and a new run starts at step 0; run \
                 a fresh simulation of the scenario, or continue a run folder with {}",
                (names.out)(out),
                world.step_index,
                (names.resume)(out)
            )));
        }
        let steps = o.steps.unwrap_or(self.steps);
        let sections = track.as_ref().map(|t| t.sections(steps));
        let io = |e: std::io::Error| Failure::Io(format!("write error in {}: {e}", out.display()));
        let series_path = out.join("series.csv");
        let series_error = |e: std::io::Error| write_error(&series_path, e);
        let quality_path = out.join("quality.csv");
        let quality_error = |e: std::io::Error| write_error(&quality_path, e);
        let ckpt_dir = out.join("checkpoints");
        let mut header = SERIES_HEADER.to_string();
        if let Some(t) = track {
            for n in t.indicators.names() {
                header.push(',');
                header.push_str(n);
            }
        }
        // The indicators of the last row, reused by the summary (they clip every grain near a
        // control volume: not worth computing twice).
        let mut last_indicators: Option<(u64, Vec<f64>)> = None;
        let mut row = |r: &StepReport, world: &World, healthy: bool| {
            // Gathered from the bodies' owners: the other ranks take part ([`Job::follow`]).
            let mut line = series_row(r, world.kinetic_energy());
            if let Some(t) = track {
                // A diverged state's indicators mean nothing (and its grains may be NaN).
                let values = if healthy {
                    t.indicators.values(world)
                } else {
                    vec![f64::NAN; t.indicators.names().len()]
                };
                for v in &values {
                    line.push_str(&format!(",{v:.9e}"));
                }
                last_indicators = Some((r.step, values));
            }
            line
        };
        let (mut series, mut quality, mut vtk) = if o.resume {
            let no_checkpoint = || {
                format!(
                    "{}: no valid checkpoint in {}",
                    (names.resume)(out),
                    ckpt_dir.display()
                )
            };
            // A folder without a checkpoints/ folder has none (not "cannot read checkpoint").
            if !ckpt_dir.is_dir() {
                return Err(no_checkpoint().into());
            }
            // What the interrupted run was writing when it stopped is never read: its space
            // is given back (best effort; the resume does not depend on it).
            let _ = remove_partial_checkpoints(&ckpt_dir);
            let scan = newest_valid_checkpoint(&ckpt_dir, world)
                .map_err(|e| format!("{}: {e}", (names.resume)(out)))?;
            for s in &scan.skipped {
                observer.message(&format!(
                    "warning: skipped {}: {}",
                    s.path.display(),
                    s.error
                ));
            }
            let Some(r) = scan.resumed else {
                return Err(no_checkpoint().into());
            };
            if steps < r.step {
                return Err(format!(
                    "{}: {} asks for {steps} steps, but the run is already at step {} (its \
                     newest checkpoint, {}); ask for more than {} to continue it",
                    (names.resume)(out),
                    if o.steps.is_some() {
                        names.steps
                    } else {
                        "the scenario"
                    },
                    r.step,
                    r.path.display(),
                    r.step
                )
                .into());
            }
            *stats = r.stats.unwrap_or_default();
            if !o.quiet {
                observer.message(&format!(
                    "resuming from {} (step {})",
                    r.path.display(),
                    r.step
                ));
            }
            // Keep the rows up to the checkpoint: later ones were written by the interrupted
            // run. Written whole and renamed into place before anything is appended: a resume
            // killed (or out of disk) before its next checkpoint still leaves every row up to
            // this one.
            let old = std::fs::read_to_string(&series_path).unwrap_or_default();
            write_atomic(&series_path, rows_up_to(&old, &header, r.step).as_bytes())
                .map_err(series_error)?;
            let f = SeriesFile::open(&series_path).map_err(series_error)?;
            // A folder written before quality.csv existed has none: it starts empty.
            let old = std::fs::read_to_string(&quality_path).unwrap_or_default();
            write_atomic(
                &quality_path,
                rows_up_to(&old, QUALITY_HEADER, r.step).as_bytes(),
            )
            .map_err(quality_error)?;
            let q = SeriesFile::open(&quality_path).map_err(quality_error)?;
            let vtk = VtkWriter::resume_on(out, world.time, world.rank(), world.ranks())
                .map_err(named_write_error)?;
            (f, q, vtk)
        } else {
            claim_folder(out, o.overwrite, names)?;
            *stats = RunStats::default();
            let scenario_path = out.join("scenario.toml");
            write_atomic(&scenario_path, text.as_bytes())
                .map_err(|e| write_error(&scenario_path, e))?;
            write_atomic(&series_path, format!("{header}\n").as_bytes()).map_err(series_error)?;
            let f = SeriesFile::open(&series_path).map_err(series_error)?;
            write_atomic(&quality_path, format!("{QUALITY_HEADER}\n").as_bytes())
                .map_err(quality_error)?;
            let q = SeriesFile::open(&quality_path).map_err(quality_error)?;
            let mut vtk =
                VtkWriter::new_on(out, world.rank(), world.ranks()).map_err(named_write_error)?;
            if vtk_interval > 0 {
                vtk.write_frame(world).map_err(named_write_error)?;
            }
            (f, q, vtk)
        };
        std::fs::create_dir_all(&ckpt_dir).map_err(io)?;
        let start = world.step_index;
        // A run that starts out of bounds (a body thrown at 1e12 m/s) is stopped before its
        // first step, naming that body rather than the grains it would hit.
        if start == 0 {
            for (i, d) in world.bodies.driver.iter().enumerate() {
                for w in d
                    .iter()
                    .flat_map(|d| d.sampling_warnings(world.settings.dt))
                {
                    observer.message(&format!(
                        "warning: body {i} (group \"{}\") driver {w}",
                        world.group_name(world.bodies.group[i])
                    ));
                }
            }
            // The first step's detection, done now (the step then solves it: same result) so
            // that the initial contacts are checked too: bodies placed inside each other.
            world.detect();
            for w in initial_warnings(world, OVERLAP_REPORT, OVERLAP_LINES as usize / 4) {
                observer.message(&format!("warning: {w}"));
            }
            if let Err(d) = health.initial().check(world) {
                let value = summary_json(world, stats, o.threads, track, None, Some(&d))?;
                write_summary_and_report(out, source, text, &value, observer)?;
                return Err(diverged(&d, out, names));
            }
        }
        observer.start(steps.saturating_sub(start));
        let mut interrupted = false;
        let mut deep_steps = 0u64;
        while world.step_index < steps {
            let r = world.step();
            stats.add(&r);
            let k = r.step;
            if let Err(d) = health.check(world) {
                // Stop here: the diverged step's row is written (it shows the fault), no
                // checkpoint or frame is, so the last checkpoint is the last healthy state.
                observer.finish();
                series
                    .append(&row(&r, world, false))
                    .map_err(series_error)?;
                quality.append(&quality_row(&r)).map_err(quality_error)?;
                let value = summary_json(world, stats, o.threads, track, None, Some(&d))?;
                write_summary_and_report(out, source, text, &value, observer)?;
                return Err(diverged(&d, out, names));
            }
            if r.max_penetration > OVERLAP_REPORT {
                deep_steps += 1;
                if !o.quiet && deep_steps <= OVERLAP_LINES {
                    let [b1, b2] = r.deepest;
                    observer.message(&format!(
                        "warning: step {k}: overlap {:.2} mm between bodies {b1} and {b2} (more than {} mm)",
                        r.max_penetration * 1e3,
                        OVERLAP_REPORT * 1e3
                    ));
                }
            }
            // What the step writes. A write that fails (a full disk) stops the run here: the
            // rows and checkpoints written so far are whole, so a resume continues it.
            let written = (|| -> Result<(), Failure> {
                if !r.solve.converged || r.max_penetration > OVERLAP_REPORT {
                    quality.append(&quality_row(&r)).map_err(quality_error)?;
                }
                if k % output_interval == 0 || k == steps {
                    // Written row by row: a killed run keeps every row it computed.
                    series.append(&row(&r, world, true)).map_err(series_error)?;
                }
                if let Some(s) = &sections {
                    write_sections(s, k, world, out).map_err(named_write_error)?;
                }
                if vtk_interval > 0 && (k % vtk_interval == 0 || k == steps) {
                    vtk.write_frame(world).map_err(named_write_error)?;
                }
                if checkpoint_interval > 0 && k % checkpoint_interval == 0 && k != steps {
                    let path = checkpoint_path(&ckpt_dir, k);
                    write_checkpoint_on_ranks(world, Some(stats), &path)
                        .map_err(|e| write_error(&path, e))?;
                    prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
                }
                Ok(())
            })();
            if let Err(e) = written {
                observer.finish();
                return Err(stopped(e.message(), k, out, names));
            }
            observer.step(k - start, &r);
            if observer.stop_requested() && world.step_index < steps {
                // Stop after a whole, healthy step, checkpointed below; no off-interval row,
                // so that a resumed run's series.csv is that of an uninterrupted one.
                interrupted = true;
                break;
            }
        }
        observer.finish();
        if !o.quiet && deep_steps > OVERLAP_LINES {
            observer.message(&format!(
                "warning: {deep_steps} steps of this session had an overlap of more than {} mm \
                 (the first {OVERLAP_LINES} named above)",
                OVERLAP_REPORT * 1e3
            ));
        }
        let last = checkpoint_path(&ckpt_dir, world.step_index);
        write_checkpoint_on_ranks(world, Some(stats), &last).map_err(|e| {
            stopped(
                write_error(&last, e).message(),
                world.step_index,
                out,
                names,
            )
        })?;
        prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
        let summary = Summary::new(world, stats, o.threads);
        let finals = match last_indicators {
            Some((step, v)) if step == world.step_index => Some(v),
            _ => None,
        };
        let mut value = summary_value(&summary, world, track, finals, None)?;
        if interrupted {
            value["status"] = "interrupted".into();
        }
        write_summary_and_report(out, source, text, &value, observer)?;
        if stats.not_converged > 0 {
            observer.message(&format!(
                "warning: NLGS did not reach tolerance {:e} in {} of {} steps (max residual {:.3e})",
                world.settings.solver.tolerance,
                stats.not_converged,
                stats.steps,
                stats.max_residual
            ));
        }
        if !o.quiet {
            observer.message(&format!(
                "{} steps, {} bodies, {:.1} contacts/step, {:.1} iterations/step, {:.3} s; outputs in {}",
                stats.steps,
                world.bodies.len(),
                summary.contacts.mean,
                summary.solver.mean_iterations,
                world.timers.total,
                out.display()
            ));
        }
        if interrupted {
            return Err(Failure::Interrupted(format!(
                "interrupted at step {} of {steps}: its state is checkpointed; {} continues it",
                world.step_index,
                (names.resume_command)(out)
            )));
        }
        Ok(RunOutcome {
            summary: value,
            steps: world.step_index,
        })
    }
}

impl Job {
    /// What a rank other than 0 of a distributed run does instead of [`Job::run`]: the same
    /// steps from the same state (`o.resume`: the newest valid checkpoint in `o.out`, which
    /// rank 0 reads too), writing only its pieces of the ParaView frames and its parts of the
    /// checkpoints, at the steps rank 0 writes them. Its world shares each solve with rank 0's, so the
    /// two must stop together: on the same divergence (the same state gives the same check),
    /// or when `observer` says so (the ranks' observers agree).
    pub fn follow(
        &mut self,
        o: &RunOptions,
        observer: &mut dyn Observer,
    ) -> Result<RunOutcome, Failure> {
        let (out, names) = (o.out, o.names);
        let (vtk_interval, checkpoint_interval) = (self.vtk_interval, self.checkpoint_interval);
        let ckpt_dir = out.join("checkpoints");
        let world = &mut self.world;
        let (rank, ranks) = (world.rank(), world.ranks());
        let frame_error = |e: std::io::Error| Failure::Io(format!("cannot write a VTK frame: {e}"));
        let part_error = |e: std::io::Error| Failure::Io(format!("cannot write a checkpoint: {e}"));
        let mut vtk = if o.resume {
            let scan = newest_valid_checkpoint(&out.join("checkpoints"), world)
                .map_err(|e| format!("{}: {e}", (names.resume)(out)))?;
            let Some(r) = scan.resumed else {
                return Err(format!("{}: no valid checkpoint", (names.resume)(out)).into());
            };
            self.stats = r.stats.unwrap_or_default();
            VtkWriter::resume_on(out, world.time, rank, ranks).map_err(frame_error)?
        } else {
            self.stats = RunStats::default();
            VtkWriter::new_on(out, rank, ranks).map_err(frame_error)?
        };
        let steps = o.steps.unwrap_or(self.steps);
        // Frames at the steps rank 0 writes them (each rank writes its pieces).
        let frame_at = |k: u64| vtk_interval > 0 && (k.is_multiple_of(vtk_interval) || k == steps);
        observer.start(steps.saturating_sub(world.step_index));
        if world.step_index == 0 {
            if !o.resume && vtk_interval > 0 {
                vtk.write_frame(world).map_err(frame_error)?;
            }
            world.detect();
            // What rank 0 computes over the contacts of every rank, it computes with the
            // others: each rank makes the same collective calls, in the same order.
            initial_warnings(world, OVERLAP_REPORT, OVERLAP_LINES as usize / 4);
            if let Err(d) = self.health.initial().check(world) {
                // Rank 0's summary of the diverged state.
                summary_json(world, &self.stats, o.threads, &self.track, None, Some(&d))?;
                return Err(diverged(&d, out, names));
            }
        }
        let sections = self.track.as_ref().map(|t| t.sections(steps));
        let mut last_indicators = None;
        while world.step_index < steps {
            let r = world.step();
            self.stats.add(&r);
            if let Err(d) = self.health.check(world) {
                // Rank 0's row (its indicators left out) and summary of the diverged state.
                world.kinetic_energy();
                summary_json(world, &self.stats, o.threads, &self.track, None, Some(&d))?;
                return Err(diverged(&d, out, names));
            }
            let k = r.step;
            // Rank 0's series row and sections (see above).
            if k.is_multiple_of(self.output_interval) || k == steps {
                world.kinetic_energy();
                if let Some(t) = &self.track {
                    last_indicators = Some((k, t.indicators.values(world)));
                }
            }
            if let Some(s) = &sections {
                for _ in s.due(k) {
                    s.planes.iter().for_each(|p| drop(s.points(world, p)));
                }
            }
            if frame_at(r.step) {
                vtk.write_frame(world).map_err(frame_error)?;
            }
            if checkpoint_interval > 0 && k.is_multiple_of(checkpoint_interval) && k != steps {
                write_checkpoint_on_ranks(world, Some(&self.stats), &checkpoint_path(&ckpt_dir, k))
                    .map_err(part_error)?;
            }
            if observer.stop_requested() && world.step_index < steps {
                break;
            }
        }
        observer.finish();
        let last = checkpoint_path(&ckpt_dir, world.step_index);
        write_checkpoint_on_ranks(world, Some(&self.stats), &last).map_err(part_error)?;
        // Rank 0's summary reuses its last row's indicators when that row is of this step.
        let finals = match last_indicators {
            Some((step, v)) if step == world.step_index => Some(v),
            _ => None,
        };
        let summary = summary_json(world, &self.stats, o.threads, &self.track, finals, None)?;
        Ok(RunOutcome {
            summary,
            steps: world.step_index,
        })
    }
}

/// Subdomains holding fewer grains than this on average cost more than they save. Measured
/// on a settled pile of 1,000 grains at 100 sweeps a step (`ballast bench --scaling --sweeps
/// 100`, one thread, `BENCHMARKS.md`): 2 subdomains make a step 16 % cheaper than monolithic
/// NLGS, and the gain shrinks with the subdomains: 7 % at 8 grains each (11x11x1, 22 % of the
/// contacts on the interface, the phase that scales worst with threads), 3 % at 3.9
/// (16x16x1, 32 %); at 2 and 1 grain a step costs 5 % and 15 % more than monolithic (41 %,
/// 50 % on the interface). More subdomains than grains are refused
/// ([`DdmSettings::check_grains`]).
pub const WARN_GRAINS_PER_SUBDOMAIN: usize = 10;

/// A warning when the partition `dims` leaves fewer than [`WARN_GRAINS_PER_SUBDOMAIN`] of the
/// `grains` per subdomain on average (none for a monolithic run): naming the option that set
/// it (`by_option`) or `ddm.subdomains`, the value, the grains per subdomain and the largest
/// partition advised. The run is unchanged: a decomposition changes speed, not validity.
pub fn subdomain_warning(
    dims: &[usize; 3],
    grains: usize,
    by_option: bool,
    names: &ArgNames,
) -> Option<String> {
    let n: usize = dims.iter().product();
    if n <= 1 || grains >= n.saturating_mul(WARN_GRAINS_PER_SUBDOMAIN) {
        return None;
    }
    let [x, y, z] = *dims;
    let name = if by_option {
        format!("{} {x}x{y}x{z}", names.subdomains)
    } else {
        format!("ddm.subdomains = [{x}, {y}, {z}]")
    };
    Some(format!(
        "warning: {name}: {n} subdomains for {grains} grains, {:.1} grains per subdomain on \
         average; below {WARN_GRAINS_PER_SUBDOMAIN} a decomposition costs more than it saves \
         (the run is slower than with fewer subdomains, same results): use at most {} \
         subdomains here, or none (1x1x1)",
        grains as f64 / n as f64,
        (grains / WARN_GRAINS_PER_SUBDOMAIN).max(1)
    ))
}

/// What a stopped run leaves in `out` to continue from: its last checkpoint, or none.
fn kept_checkpoint(out: &Path, names: &ArgNames) -> String {
    match list_checkpoints(&out.join("checkpoints"))
        .ok()
        .and_then(|l| l.last().cloned())
    {
        Some((step, _)) => format!(
            "its last checkpoint (step {step}) is kept: {} continues from it",
            (names.resume)(out)
        ),
        None => "no checkpoint was written".into(),
    }
}

/// The message of a run stopped by a write error (`error`, naming the file) after step
/// `step`: a full disk or file size limit leaves whole rows and checkpoints, and the run
/// continues from its last checkpoint once there is room again.
fn stopped(error: &str, step: u64, out: &Path, names: &ArgNames) -> Failure {
    Failure::Io(format!(
        "{error}; the run is stopped after step {step} and {}",
        kept_checkpoint(out, names)
    ))
}

/// A write error, naming the file.
fn write_error(path: &Path, e: std::io::Error) -> Failure {
    Failure::Io(format!("write error in {}: {e}", path.display()))
}

/// A write error whose error names its file already ([`VtkWriter`], sections).
fn named_write_error(e: std::io::Error) -> Failure {
    Failure::Io(format!("write error in {e}"))
}

/// `series.csv` open for appending rows. Each row is written whole by one call (no buffer
/// left to flush later), and a row that cannot be written whole (a full disk) is cut off
/// again, so that the file ends with a whole row.
struct SeriesFile {
    file: std::fs::File,
    /// Bytes of whole rows (and the header).
    len: u64,
}

impl SeriesFile {
    fn open(path: &Path) -> std::io::Result<Self> {
        let file = std::fs::OpenOptions::new().append(true).open(path)?;
        let len = file.metadata()?.len();
        Ok(SeriesFile { file, len })
    }

    /// Appends `row` and a newline.
    fn append(&mut self, row: &str) -> std::io::Result<()> {
        let line = format!("{row}\n");
        match self.file.write_all(line.as_bytes()) {
            Ok(()) => {
                self.len += line.len() as u64;
                Ok(())
            }
            Err(e) => {
                // Best effort: truncating needs no space.
                let _ = self.file.set_len(self.len);
                Err(e)
            }
        }
    }
}

/// `series.csv` (or `quality.csv`) for a run resumed at step `step`: `header`, then the rows
/// of `old` (the file the interrupted run left) up to that step. Whole rows only: a run killed
/// in the middle of a row leaves it cut, perhaps in its step number.
fn rows_up_to(old: &str, header: &str, step: u64) -> String {
    let columns = header.split(',').count();
    let mut text = format!("{header}\n");
    for line in old.split_inclusive('\n').skip(1) {
        let Some(row) = line.strip_suffix('\n') else {
            break;
        };
        let at = row.split(',').next().and_then(|s| s.parse::<u64>().ok());
        if row.split(',').count() == columns && at.is_some_and(|s| s <= step) {
            text.push_str(line);
        }
    }
    text
}

/// The message of a run stopped by the health check: what diverged, and what is left.
fn diverged(d: &Divergence, out: &Path, names: &ArgNames) -> Failure {
    let kept = kept_checkpoint(out, names);
    let advice = if d.step == 0 {
        "check the scenario's initial positions and velocities"
    } else {
        "a smaller simulation.dt or tighter solver settings usually help"
    };
    Failure::Diverged(format!("{d}; the run is stopped and {kept} ({advice})"))
}

/// `summary.json`: the engine's [`Summary`], `status` (`"completed"`, or `"diverged"` with the
/// `divergence`), and for track runs `grains`, the final `indicators` (`finals`, when already
/// computed for this step), `preparation` and `cycle`.
///
/// The summary and the indicators are gathered from the bodies' and contacts' owners: every
/// rank of a distributed run calls this at the same point ([`Job::follow`]).
fn summary_json(
    world: &World,
    stats: &RunStats,
    threads: usize,
    track: &Option<TrackParts>,
    finals: Option<Vec<f64>>,
    diverged: Option<&Divergence>,
) -> Result<serde_json::Value, String> {
    let summary = Summary::new(world, stats, threads);
    summary_value(&summary, world, track, finals, diverged)
}

/// [`summary_json`] of a summary already made.
fn summary_value(
    summary: &Summary,
    world: &World,
    track: &Option<TrackParts>,
    finals: Option<Vec<f64>>,
    diverged: Option<&Divergence>,
) -> Result<serde_json::Value, String> {
    let mut value = serde_json::to_value(summary).map_err(|e| e.to_string())?;
    let Some(map) = value.as_object_mut() else {
        return Ok(value);
    };
    // Keys are only added, never renamed.
    map.insert(
        "status".into(),
        if diverged.is_some() {
            "diverged"
        } else {
            "completed"
        }
        .into(),
    );
    if let Some(d) = diverged {
        map.insert(
            "divergence".into(),
            serde_json::json!({
                "step": d.step,
                "time": json_number(d.time),
                "quantity": d.quantity.name(),
                "value": json_number(d.value),
                "bound": json_number(d.bound),
                "bodies": d.bodies,
                "groups": d.groups,
                "count": d.count,
                "message": d.to_string(),
            }),
        );
    }
    if let Some(t) = track {
        map.insert("grains".into(), t.grains.into());
        let values = match (finals, diverged) {
            (Some(v), _) => v,
            (None, None) => t.indicators.values(world),
            (None, Some(_)) => vec![f64::NAN; t.indicators.names().len()],
        };
        let finals: serde_json::Map<String, serde_json::Value> = t
            .indicators
            .names()
            .iter()
            .cloned()
            .zip(values.into_iter().map(json_number))
            .collect();
        map.insert("indicators".into(), finals.into());
        map.insert("preparation".into(), t.preparation.clone());
        map.insert("cycle".into(), t.cycle_json.clone());
    }
    Ok(value)
}

/// Writes `summary.json` (atomically), then the report and its plots, whose failure is only a
/// warning: the run's data is already safe.
fn write_summary_and_report(
    out: &Path,
    source: &str,
    text: &str,
    value: &serde_json::Value,
    observer: &mut dyn Observer,
) -> Result<(), Failure> {
    let json = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    let path = out.join("summary.json");
    write_atomic(&path, json.as_bytes()).map_err(|e| write_error(&path, e))?;
    if let Err(e) = write_run_report(out, Path::new(source), text, value) {
        observer.message(&format!("warning: report: {e}"));
    }
    Ok(())
}

/// The moments of the tamping cycle, for the summary and the report: per tamped block (its
/// 1-based number),
/// the start of its insertion, squeeze, hold, withdrawal and the end of its cycle; the
/// release and the duration (s).
fn cycle_json(c: &ballast_railway::tamping::Cycle, blocks: &[usize]) -> serde_json::Value {
    let per_block: Vec<serde_json::Value> = c
        .phases
        .iter()
        .enumerate()
        .map(|(k, p)| {
            serde_json::json!({
                "block": blocks.get(k).copied().unwrap_or(k + 1),
                "insertion_s": p.insertion,
                "squeeze_s": p.squeeze,
                "hold_s": p.hold,
                "withdraw_s": p.withdraw,
                "end_s": p.end,
            })
        })
        .collect();
    serde_json::json!({
        "blocks": per_block,
        "release_s": c.release,
        "duration_s": c.duration,
    })
}

/// Writes the sections due after step `k` into `out/sections/`.
fn write_sections(s: &Sections, k: u64, world: &World, out: &Path) -> std::io::Result<()> {
    for m in s.due(k) {
        let dir = out.join("sections");
        std::fs::create_dir_all(&dir).map_err(|e| naming(&dir, e))?;
        for p in &s.planes {
            let csv = section_csv(&s.points(world, p));
            let path = dir.join(Sections::file_name(m, p));
            write_atomic(&path, csv.as_bytes()).map_err(|e| naming(&path, e))?;
        }
    }
    Ok(())
}

/// A length for a message: millimetre precision, no trailing zeros (3.6, not
/// 3.6000000000000005).
fn short(x: f64) -> String {
    let s = format!("{x:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    /// A resume keeps the whole rows up to its checkpoint: not a row cut by a kill or a full
    /// disk (here in its step number: "1" of "13"), nor rows after the checkpoint.
    #[test]
    fn a_resume_keeps_whole_rows_up_to_its_checkpoint() {
        let old = "step,a,b\n10,1,2\n11,1\n12,1,2\n13,1,2\n1";
        assert_eq!(
            super::rows_up_to(old, "step,a,b", 12),
            "step,a,b\n10,1,2\n12,1,2\n"
        );
        assert_eq!(super::rows_up_to("", "step,a,b", 12), "step,a,b\n");
    }

    #[test]
    fn lengths_in_messages_are_short() {
        assert_eq!(super::short(3.6000000000000005), "3.6");
        assert_eq!(super::short(2.0), "2");
        assert_eq!(super::short(0.6), "0.6");
        assert_eq!(super::short(0.0125), "0.013");
    }
}
