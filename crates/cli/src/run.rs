//! `ballast run FILE --out DIR` and `ballast run FILE --resume DIR`.

use crate::progress::Progress;
use ballast_engine::output::checkpoint::{
    checkpoint_path, newest_valid_checkpoint, prune_checkpoints, write_checkpoint_with_stats,
};
use ballast_engine::output::vtk::VtkWriter;
use ballast_engine::output::{series_row, RunStats, Summary, SERIES_HEADER};
use ballast_engine::scenario::Scenario;
use ballast_engine::solver::DdmSettings;
use std::io::Write;
use std::path::Path;

/// Checkpoints kept in `DIR/checkpoints` (the newest ones).
const KEEP_CHECKPOINTS: usize = 3;

/// What `ballast run` was asked to do.
pub struct RunArgs<'a> {
    pub file: &'a Path,
    pub out: &'a Path,
    /// Continue in `out` from its newest valid checkpoint.
    pub resume: bool,
    pub steps: Option<u64>,
    pub threads: usize,
    pub subdomains: Option<[usize; 3]>,
    pub quiet: bool,
}

/// Runs a scenario file up to its step count (or `--steps`), writing `summary.json`,
/// `series.csv`, ParaView frames and checkpoints in `out`.
pub fn run(a: &RunArgs) -> Result<(), String> {
    let (file, out) = (a.file, a.out);
    let text = std::fs::read_to_string(file)
        .map_err(|e| format!("cannot read scenario {}: {e}", file.display()))?;
    let mut scenario =
        Scenario::from_toml(&text).map_err(|e| format!("{}: {e}", file.display()))?;
    if let Some(dims) = a.subdomains {
        scenario.ddm = match (dims, scenario.ddm.take()) {
            ([1, 1, 1], _) => None,
            (dims, d) => Some(DdmSettings {
                subdomains: dims,
                ..d.unwrap_or_default()
            }),
        };
    }
    let steps = a.steps.unwrap_or_else(|| scenario.steps());
    let mut world = scenario
        .build()
        .map_err(|e| format!("{}: {e}", file.display()))?;
    let io = |e: std::io::Error| format!("write error in {}: {e}", out.display());
    let ckpt_dir = out.join("checkpoints");
    let series_path = out.join("series.csv");
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
        writeln!(f, "{SERIES_HEADER}").map_err(io)?;
        for l in kept {
            writeln!(f, "{l}").map_err(io)?;
        }
        let vtk = VtkWriter::resume(out, world.time).map_err(io)?;
        (f, vtk)
    } else {
        std::fs::create_dir_all(out)
            .map_err(|e| format!("cannot create output folder {}: {e}", out.display()))?;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&series_path).map_err(io)?);
        writeln!(f, "{SERIES_HEADER}").map_err(io)?;
        let mut vtk = VtkWriter::new(out).map_err(io)?;
        if scenario.simulation.vtk_interval > 0 {
            vtk.write_frame(&world).map_err(io)?;
        }
        (f, vtk)
    };
    std::fs::create_dir_all(&ckpt_dir).map_err(io)?;
    let sim = &scenario.simulation;
    let start = world.step_index;
    let mut progress = Progress::new(steps.saturating_sub(start), a.quiet);
    while world.step_index < steps {
        let r = world.step();
        stats.add(&r);
        let k = r.step;
        if k % sim.output_interval == 0 || k == steps {
            writeln!(series, "{}", series_row(&r, world.bodies.kinetic_energy())).map_err(io)?;
        }
        if sim.vtk_interval > 0 && (k % sim.vtk_interval == 0 || k == steps) {
            vtk.write_frame(&world).map_err(io)?;
        }
        if sim.checkpoint_interval > 0 && k % sim.checkpoint_interval == 0 && k != steps {
            series.flush().map_err(io)?;
            write_checkpoint_with_stats(&world, Some(&stats), &checkpoint_path(&ckpt_dir, k))
                .map_err(io)?;
            prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
        }
        progress.update(k - start, r.time, r.contacts, r.solve.iterations);
    }
    progress.finish();
    series.flush().map_err(io)?;
    write_checkpoint_with_stats(
        &world,
        Some(&stats),
        &checkpoint_path(&ckpt_dir, world.step_index),
    )
    .map_err(io)?;
    prune_checkpoints(&ckpt_dir, KEEP_CHECKPOINTS).map_err(io)?;
    let summary = Summary::new(&world, &stats, a.threads);
    summary.write(&out.join("summary.json")).map_err(io)?;
    // The report and its plots: a failure is a warning, the run's data is already safe.
    match serde_json::to_value(&summary) {
        Ok(v) => {
            if let Err(e) = crate::report::write_run_report(out, file, &text, &v) {
                eprintln!("warning: report: {e}");
            }
        }
        Err(e) => eprintln!("warning: report: {e}"),
    }
    if stats.not_converged > 0 {
        eprintln!(
            "warning: NLGS did not reach tolerance {} in {} of {} steps (max residual {:.3e})",
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
