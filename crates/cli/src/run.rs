//! `ballast run [FILE | --preset NAME] --out DIR` and `ballast run [FILE] --resume DIR`: engine
//! scenarios and track scenarios (a `[track]` table: bed preparation, tamping, indicators).

use crate::progress::Progress;
use ballast_engine::health::{initial_warnings, Divergence, HealthCheck};
use ballast_engine::output::checkpoint::{
    checkpoint_path, list_checkpoints, newest_valid_checkpoint, prune_checkpoints,
    write_checkpoint_with_stats,
};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::output::{
    json_number, series_row, write_atomic, RunStats, Summary, SERIES_HEADER,
};
use ballast_engine::scenario::Scenario;
use ballast_engine::solver::DdmSettings;
use ballast_engine::world::{StepReport, World};
use ballast_railway::indicators::Indicators;
use ballast_railway::preparation::PrepProgress;
use ballast_railway::sections::{section_csv, Sections};
use ballast_railway::{is_track_scenario, TrackScenario};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Checkpoints kept in `DIR/checkpoints` (the newest ones).
const KEEP_CHECKPOINTS: usize = 3;

/// Overlaps deeper than this (m) are reported on stderr with the two bodies (4 % of the
/// smallest ballast grain).
const OVERLAP_REPORT: f64 = 1e-3;

/// Steps with such an overlap named one by one; beyond, only their number.
const OVERLAP_LINES: u64 = 20;

/// Why `ballast run` did not finish.
#[derive(Debug)]
pub enum Failure {
    /// Bad input or an I/O error (exit code 1).
    Error(String),
    /// The health check stopped a diverging run (exit code 3); its outputs are written.
    Diverged(String),
    /// Ctrl-C or SIGTERM stopped the run after a step, its state checkpointed (exit code 130).
    Interrupted(String),
}

impl From<String> for Failure {
    fn from(e: String) -> Self {
        Failure::Error(e)
    }
}

/// What `ballast run` was asked to do.
pub struct RunArgs<'a> {
    /// Scenario file; `None`: `preset`, or `out/scenario.toml` when resuming.
    pub file: Option<&'a Path>,
    /// Built-in track scenario (`default`, `paper`) when there is no file.
    pub preset: Option<&'a str>,
    pub out: &'a Path,
    /// Continue in `out` from its newest valid checkpoint.
    pub resume: bool,
    /// Delete the run files a previous run left in `out` before starting (else such a folder
    /// is refused).
    pub overwrite: bool,
    pub steps: Option<u64>,
    pub threads: usize,
    pub subdomains: Option<[usize; 3]>,
    pub quiet: bool,
    /// Folder of prepared ballast beds; `None`: no cache.
    pub cache: Option<PathBuf>,
}

/// A run ready to step: the world and what to write.
struct Job {
    world: World,
    /// Where the scenario came from, for messages and the report.
    source: String,
    text: String,
    steps: u64,
    output_interval: u64,
    vtk_interval: u64,
    checkpoint_interval: u64,
    track: Option<TrackParts>,
    /// Bounds of the scene as built, before any checkpoint is read (the same on resume).
    health: HealthCheck,
}

/// The track-specific parts of a run.
struct TrackParts {
    indicators: Indicators,
    grains: usize,
    preparation: serde_json::Value,
    /// When each tamped block's cycle happens (`summary.json`'s `cycle`).
    cycle: serde_json::Value,
    sections: Sections,
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
const RUN_FILES: [&str; 11] = [
    "scenario.toml",
    "summary.json",
    "series.csv",
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
    for name in ["scenario.toml", "summary.json", "series.csv"] {
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
fn claim_folder(out: &Path, overwrite: bool) -> Result<(), String> {
    let found = previous_run(out);
    if !found.is_empty() {
        if !overwrite {
            return Err(format!(
                "--out {}: the folder holds another run ({}); continue it with \
                 `ballast run --resume {}`, write to another folder, or add --overwrite to \
                 delete that run's files first",
                out.display(),
                found.join(", "),
                out.display()
            ));
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
            removed.map_err(|e| format!("--overwrite: cannot delete {}: {e}", p.display()))?;
        }
    }
    std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create output folder {}: {e}", out.display()))
}

/// Reads the scenario (file, preset, or the run folder's copy when resuming) and builds it.
fn job(a: &RunArgs) -> Result<Job, String> {
    let (source, text) = match (a.file, a.preset) {
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
                        "--resume {}: cannot read {}: {e}",
                        a.out.display(),
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
    };
    if is_track_scenario(&text) {
        let mut s = TrackScenario::from_toml(&text).map_err(|e| format!("{source}: {e}"))?;
        apply_subdomains(&mut s.ddm, a.subdomains);
        let mut last = std::time::Instant::now();
        let quiet = a.quiet;
        if !quiet {
            eprintln!(
                "preparing the ballast bed ({} block(s), {} m × {} m), or reading it from the cache",
                s.track.blocks,
                short(s.track.length()),
                short(s.track.width)
            );
        }
        let model = s
            .build(a.cache.as_deref(), &mut |p: PrepProgress| {
                if !quiet && last.elapsed().as_secs_f64() > 5.0 {
                    last = std::time::Instant::now();
                    eprintln!(
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
                    );
                }
            })
            .map_err(|e| format!("{source}: {e}"))?;
        if let Some(w) = &model.cache_warning {
            eprintln!("warning: {w}");
        }
        if !quiet {
            let r = &model.preparation;
            eprintln!(
                "bed {}: {} grains ({} steps of deposition, {:.1} s)",
                if model.from_cache {
                    "read from the cache"
                } else {
                    "prepared"
                },
                r.grains,
                r.steps,
                r.wall_s
            );
        }
        let sim = &s.simulation;
        let steps = a.steps.unwrap_or_else(|| s.steps());
        let sections = Sections::new(
            &s.track,
            s.tamping.tine_y.first().copied().unwrap_or(0.0),
            &model.layout,
            &model.cycle,
            &s.tamping.blocks,
            sim.dt,
            steps,
        );
        Ok(Job {
            health: ballast_engine::scenario::health_check(
                &model.world,
                sim.max_speed,
                sim.max_overlap,
            ),
            steps,
            output_interval: sim.output_interval,
            vtk_interval: sim.vtk_interval,
            checkpoint_interval: sim.checkpoint_interval,
            track: Some(TrackParts {
                grains: model.layout.grains.len(),
                preparation: serde_json::to_value(&model.preparation).unwrap_or_default(),
                indicators: model.indicators,
                cycle: cycle_json(&model.cycle, &s.tamping.blocks),
                sections,
            }),
            world: model.world,
            source,
            text: s.to_toml(),
        })
    } else {
        let mut scenario = Scenario::from_toml(&text).map_err(|e| format!("{source}: {e}"))?;
        apply_subdomains(&mut scenario.ddm, a.subdomains);
        // The run folder's copy says how the run was made, --subdomains included, so that a
        // plain --resume rebuilds the same scene.
        let text = match a.subdomains {
            Some(_) => scenario.to_toml().map_err(|e| e.to_string())?,
            None => text,
        };
        let world = scenario.build().map_err(|e| format!("{source}: {e}"))?;
        let sim = &scenario.simulation;
        Ok(Job {
            health: scenario.health_check(&world),
            steps: a.steps.unwrap_or_else(|| scenario.steps()),
            output_interval: sim.output_interval,
            vtk_interval: sim.vtk_interval,
            checkpoint_interval: sim.checkpoint_interval,
            track: None,
            world,
            source,
            text: text.to_string(),
        })
    }
}

/// Runs a scenario (file or preset) up to its step count (or `--steps`), writing
/// `scenario.toml`, `summary.json`, `series.csv`, ParaView frames and checkpoints in `out`.
pub fn run(a: &RunArgs) -> Result<(), Failure> {
    let out = a.out;
    if !a.resume {
        // Before the bed is prepared (minutes): a refusal should come at once.
        if !a.overwrite && !previous_run(a.out).is_empty() {
            claim_folder(a.out, false)?;
        }
    }
    let Job {
        mut world,
        source,
        text,
        steps,
        output_interval,
        vtk_interval,
        checkpoint_interval,
        track,
        health,
    } = job(a)?;
    if let Some(d) = &world.settings.ddm {
        let grains = (0..world.bodies.len())
            .filter(|&i| world.bodies.kind[i] == ballast_engine::bodies::BodyKind::Dynamic)
            .count();
        d.check_grains(grains).map_err(|e| {
            // `e` starts "subdomains = …": name the key, or the flag that set it.
            let field = if a.subdomains.is_some() {
                "--subdomains: "
            } else {
                "ddm."
            };
            format!("{source}: {field}{e}")
        })?;
    }
    let io = |e: std::io::Error| format!("write error in {}: {e}", out.display());
    let ckpt_dir = out.join("checkpoints");
    let series_path = out.join("series.csv");
    let mut header = SERIES_HEADER.to_string();
    if let Some(t) = &track {
        for n in t.indicators.names() {
            header.push(',');
            header.push_str(n);
        }
    }
    // The indicators of the last row, reused by the summary (they clip every grain near a
    // control volume: not worth computing twice).
    let mut last_indicators: Option<(u64, Vec<f64>)> = None;
    let mut row = |r: &StepReport, world: &World, healthy: bool| {
        let mut line = series_row(r, world.bodies.kinetic_energy());
        if let Some(t) = &track {
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
    let mut stats = RunStats::default();
    let (mut series, mut vtk) = if a.resume {
        let no_checkpoint = || {
            format!(
                "--resume {}: no valid checkpoint in {}",
                out.display(),
                ckpt_dir.display()
            )
        };
        // A folder without a checkpoints/ folder has none (not "cannot read checkpoint").
        if !ckpt_dir.is_dir() {
            return Err(no_checkpoint().into());
        }
        let scan = newest_valid_checkpoint(&ckpt_dir, &mut world)
            .map_err(|e| format!("--resume {}: {e}", out.display()))?;
        for s in &scan.skipped {
            eprintln!("warning: skipped {}: {}", s.path.display(), s.error);
        }
        let Some(r) = scan.resumed else {
            return Err(no_checkpoint().into());
        };
        if steps < r.step {
            return Err(format!(
                "--resume {}: {} asks for {steps} steps, but the run is already at step {} \
                 (its newest checkpoint, {}); ask for more than {} to continue it",
                out.display(),
                if a.steps.is_some() {
                    "--steps"
                } else {
                    "the scenario"
                },
                r.step,
                r.path.display(),
                r.step
            )
            .into());
        }
        stats = r.stats.unwrap_or_default();
        if !a.quiet {
            eprintln!("resuming from {} (step {})", r.path.display(), r.step);
        }
        // Keep the rows up to the checkpoint: later ones were written by the interrupted run.
        let old = std::fs::read_to_string(&series_path).unwrap_or_default();
        let kept: Vec<&str> = old
            .lines()
            .skip(1)
            .filter(|l| {
                l.split(',')
                    .next()
                    .and_then(|s| s.parse::<u64>().ok())
                    .is_some_and(|s| s <= r.step)
            })
            .collect();
        // Written whole and renamed into place before anything is appended: a resume killed
        // (or out of disk) before its next checkpoint still leaves every row up to this one.
        let mut kept_text = format!("{header}\n");
        for l in kept {
            kept_text.push_str(l);
            kept_text.push('\n');
        }
        write_atomic(&series_path, kept_text.as_bytes()).map_err(io)?;
        let f = std::io::BufWriter::new(
            std::fs::OpenOptions::new()
                .append(true)
                .open(&series_path)
                .map_err(io)?,
        );
        let vtk = VtkWriter::resume(out, world.time).map_err(io)?;
        (f, vtk)
    } else {
        claim_folder(out, a.overwrite)?;
        write_atomic(&out.join("scenario.toml"), text.as_bytes()).map_err(io)?;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&series_path).map_err(io)?);
        writeln!(f, "{header}").map_err(io)?;
        f.flush().map_err(io)?;
        let mut vtk = VtkWriter::new(out).map_err(io)?;
        if vtk_interval > 0 {
            vtk.write_frame(&world).map_err(io)?;
        }
        (f, vtk)
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
                eprintln!(
                    "warning: body {i} (group \"{}\") driver {w}",
                    world.group_name(world.bodies.group[i])
                );
            }
        }
        // The first step's detection, done now (the step then solves it: same result) so
        // that the initial contacts are checked too: bodies placed inside each other.
        world.detect();
        for w in initial_warnings(&world, OVERLAP_REPORT, OVERLAP_LINES as usize / 4) {
            eprintln!("warning: {w}");
        }
        if let Err(d) = health.initial().check(&world) {
            let value = summary_json(&world, &stats, a.threads, &track, None, Some(&d))?;
            write_summary_and_report(out, &source, &text, &value)?;
            return Err(diverged(&d, out));
        }
    }
    let mut progress = Progress::new(steps.saturating_sub(start), a.quiet);
    crate::interrupt::install();
    let mut interrupted = false;
    let mut deep_steps = 0u64;
    while world.step_index < steps {
        let r = world.step();
        stats.add(&r);
        let k = r.step;
        if let Err(d) = health.check(&world) {
            // Stop here: the diverged step's row is written (it shows the fault), no
            // checkpoint or frame is, so the last checkpoint is the last healthy state.
            progress.finish();
            writeln!(series, "{}", row(&r, &world, false)).map_err(io)?;
            series.flush().map_err(io)?;
            let value = summary_json(&world, &stats, a.threads, &track, None, Some(&d))?;
            write_summary_and_report(out, &source, &text, &value)?;
            return Err(diverged(&d, out));
        }
        if r.max_penetration > OVERLAP_REPORT {
            deep_steps += 1;
            if !a.quiet && deep_steps <= OVERLAP_LINES {
                let [b1, b2] = r.deepest;
                eprintln!(
                    "warning: step {k}: overlap {:.2} mm between bodies {b1} and {b2} (more than {} mm)",
                    r.max_penetration * 1e3,
                    OVERLAP_REPORT * 1e3
                );
            }
        }
        if k % output_interval == 0 || k == steps {
            // Flushed row by row: a killed run keeps every row it computed.
            writeln!(series, "{}", row(&r, &world, true)).map_err(io)?;
            series.flush().map_err(io)?;
        }
        if let Some(t) = &track {
            write_sections(&t.sections, k, &world, out).map_err(io)?;
        }
        if vtk_interval > 0 && (k % vtk_interval == 0 || k == steps) {
            vtk.write_frame(&world).map_err(io)?;
        }
        if checkpoint_interval > 0 && k % checkpoint_interval == 0 && k != steps {
            series.flush().map_err(io)?;
            write_checkpoint_with_stats(&world, Some(&stats), &checkpoint_path(&ckpt_dir, k))
                .map_err(io)?;
            prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
        }
        progress.update(k - start, r.time, r.contacts, r.solve.iterations);
        if crate::interrupt::requested() && world.step_index < steps {
            // Stop after a whole, healthy step, checkpointed below; no off-interval row, so
            // that a resumed run's series.csv is that of an uninterrupted one.
            interrupted = true;
            break;
        }
    }
    progress.finish();
    if !a.quiet && deep_steps > OVERLAP_LINES {
        eprintln!(
            "warning: {deep_steps} steps of this session had an overlap of more than {} mm \
             (the first {OVERLAP_LINES} named above)",
            OVERLAP_REPORT * 1e3
        );
    }
    series.flush().map_err(io)?;
    write_checkpoint_with_stats(
        &world,
        Some(&stats),
        &checkpoint_path(&ckpt_dir, world.step_index),
    )
    .map_err(io)?;
    prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
    let summary = Summary::new(&world, &stats, a.threads);
    let finals = match last_indicators {
        Some((step, v)) if step == world.step_index => Some(v),
        _ => None,
    };
    let mut value = summary_json(&world, &stats, a.threads, &track, finals, None)?;
    if interrupted {
        value["status"] = "interrupted".into();
    }
    write_summary_and_report(out, &source, &text, &value)?;
    if stats.not_converged > 0 {
        eprintln!(
            "warning: NLGS did not reach tolerance {:e} in {} of {} steps (max residual {:.3e})",
            world.settings.solver.tolerance, stats.not_converged, stats.steps, stats.max_residual
        );
    }
    if !a.quiet {
        eprintln!(
            "{} steps, {} bodies, {:.1} contacts/step, {:.1} iterations/step, {:.3} s; outputs in {}",
            stats.steps,
            world.bodies.len(),
            summary.contacts.mean,
            summary.solver.mean_iterations,
            world.timers.total,
            out.display()
        );
    }
    if interrupted {
        return Err(Failure::Interrupted(format!(
            "interrupted at step {} of {steps}: its state is checkpointed; `ballast run \
             --resume {}` continues it",
            world.step_index,
            out.display()
        )));
    }
    Ok(())
}

/// The message of a run stopped by the health check: what diverged, and what is left.
fn diverged(d: &Divergence, out: &Path) -> Failure {
    let kept = match list_checkpoints(&out.join("checkpoints"))
        .ok()
        .and_then(|l| l.last().cloned())
    {
        Some((step, _)) => format!(
            "its last checkpoint (step {step}) is kept: --resume {} continues from it",
            out.display()
        ),
        None => "no checkpoint was written".into(),
    };
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
fn summary_json(
    world: &World,
    stats: &RunStats,
    threads: usize,
    track: &Option<TrackParts>,
    finals: Option<Vec<f64>>,
    diverged: Option<&Divergence>,
) -> Result<serde_json::Value, String> {
    let summary = Summary::new(world, stats, threads);
    let mut value = serde_json::to_value(&summary).map_err(|e| e.to_string())?;
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
        map.insert("cycle".into(), t.cycle.clone());
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
) -> Result<(), String> {
    let json = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    write_atomic(&out.join("summary.json"), json.as_bytes())
        .map_err(|e| format!("write error in {}: {e}", out.display()))?;
    if let Err(e) = crate::report::write_run_report(out, Path::new(source), text, value) {
        eprintln!("warning: report: {e}");
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
        std::fs::create_dir_all(&dir)?;
        for p in &s.planes {
            let csv = section_csv(&s.points(world, p));
            write_atomic(&dir.join(Sections::file_name(m, p)), csv.as_bytes())?;
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
    #[test]
    fn lengths_in_messages_are_short() {
        assert_eq!(super::short(3.6000000000000005), "3.6");
        assert_eq!(super::short(2.0), "2");
        assert_eq!(super::short(0.6), "0.6");
        assert_eq!(super::short(0.0125), "0.013");
    }
}
