//! `ballast run [FILE | --preset NAME] --out DIR` and `ballast run [FILE] --resume DIR`: engine
//! scenarios and track scenarios (a `[track]` table: bed preparation, tamping, indicators).

use crate::progress::Progress;
use ballast_engine::output::checkpoint::{
    checkpoint_path, newest_valid_checkpoint, prune_checkpoints, write_checkpoint_with_stats,
};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::output::{series_row, write_atomic, RunStats, Summary, SERIES_HEADER};
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

/// What `ballast run` was asked to do.
pub struct RunArgs<'a> {
    /// Scenario file; `None`: `preset`, or `out/scenario.toml` when resuming.
    pub file: Option<&'a Path>,
    /// Built-in track scenario (`default`, `paper`) when there is no file.
    pub preset: Option<&'a str>,
    pub out: &'a Path,
    /// Continue in `out` from its newest valid checkpoint.
    pub resume: bool,
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
        let world = scenario.build().map_err(|e| format!("{source}: {e}"))?;
        let sim = &scenario.simulation;
        Ok(Job {
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
pub fn run(a: &RunArgs) -> Result<(), String> {
    let out = a.out;
    let Job {
        mut world,
        source,
        text,
        steps,
        output_interval,
        vtk_interval,
        checkpoint_interval,
        track,
    } = job(a)?;
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
    let mut row = |r: &StepReport, world: &World| {
        let mut line = series_row(r, world.bodies.kinetic_energy());
        if let Some(t) = &track {
            let values = t.indicators.values(world);
            for v in &values {
                line.push_str(&format!(",{v:.9e}"));
            }
            last_indicators = Some((r.step, values));
        }
        line
    };
    let mut stats = RunStats::default();
    let (mut series, mut vtk) = if a.resume {
        let scan = newest_valid_checkpoint(&ckpt_dir, &mut world).map_err(|e| e.to_string())?;
        for s in &scan.skipped {
            eprintln!("warning: skipped {}: {}", s.path.display(), s.error);
        }
        let Some(r) = scan.resumed else {
            return Err(format!(
                "--resume {}: no valid checkpoint in {}",
                out.display(),
                ckpt_dir.display()
            ));
        };
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
        let mut f = std::io::BufWriter::new(std::fs::File::create(&series_path).map_err(io)?);
        writeln!(f, "{header}").map_err(io)?;
        for l in kept {
            writeln!(f, "{l}").map_err(io)?;
        }
        let vtk = VtkWriter::resume(out, world.time).map_err(io)?;
        (f, vtk)
    } else {
        std::fs::create_dir_all(out)
            .map_err(|e| format!("cannot create output folder {}: {e}", out.display()))?;
        write_atomic(&out.join("scenario.toml"), text.as_bytes()).map_err(io)?;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&series_path).map_err(io)?);
        writeln!(f, "{header}").map_err(io)?;
        let mut vtk = VtkWriter::new(out).map_err(io)?;
        if vtk_interval > 0 {
            vtk.write_frame(&world).map_err(io)?;
        }
        (f, vtk)
    };
    std::fs::create_dir_all(&ckpt_dir).map_err(io)?;
    let start = world.step_index;
    let mut progress = Progress::new(steps.saturating_sub(start), a.quiet);
    let mut deep_steps = 0u64;
    while world.step_index < steps {
        let r = world.step();
        stats.add(&r);
        let k = r.step;
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
            writeln!(series, "{}", row(&r, &world)).map_err(io)?;
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
    let mut value = serde_json::to_value(&summary).map_err(|e| e.to_string())?;
    if let (Some(t), Some(map)) = (&track, value.as_object_mut()) {
        // Track runs add keys (never rename): grains, final indicators, the preparation.
        map.insert("grains".into(), t.grains.into());
        let values = match last_indicators {
            Some((step, v)) if step == world.step_index => v,
            _ => t.indicators.values(&world),
        };
        let finals: serde_json::Map<String, serde_json::Value> = t
            .indicators
            .names()
            .iter()
            .cloned()
            .zip(values.into_iter().map(Into::into))
            .collect();
        map.insert("indicators".into(), finals.into());
        map.insert("preparation".into(), t.preparation.clone());
        map.insert("cycle".into(), t.cycle.clone());
    }
    let json = serde_json::to_string_pretty(&value).map_err(|e| e.to_string())?;
    write_atomic(&out.join("summary.json"), json.as_bytes()).map_err(io)?;
    // The report and its plots: a failure is a warning, the run's data is already safe.
    if let Err(e) = crate::report::write_run_report(out, Path::new(&source), &text, &value) {
        eprintln!("warning: report: {e}");
    }
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
