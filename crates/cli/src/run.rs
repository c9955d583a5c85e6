//! `ballast run FILE --out DIR`.

use crate::progress::Progress;
use ballast_engine::output::{series_row, RunStats, Summary, SERIES_HEADER};
use ballast_engine::scenario::Scenario;
use ballast_engine::solver::DdmSettings;
use std::io::Write;
use std::path::Path;

/// Runs a scenario file, writing `summary.json` and `series.csv` in `out`.
pub fn run(
    file: &Path,
    out: &Path,
    steps: Option<u64>,
    threads: usize,
    subdomains: Option<[usize; 3]>,
    quiet: bool,
) -> Result<(), String> {
    let text = std::fs::read_to_string(file)
        .map_err(|e| format!("cannot read scenario {}: {e}", file.display()))?;
    let mut scenario =
        Scenario::from_toml(&text).map_err(|e| format!("{}: {e}", file.display()))?;
    if let Some(dims) = subdomains {
        scenario.ddm = match (dims, scenario.ddm.take()) {
            ([1, 1, 1], _) => None,
            (dims, d) => Some(DdmSettings {
                subdomains: dims,
                ..d.unwrap_or_default()
            }),
        };
    }
    let steps = steps.unwrap_or_else(|| scenario.steps());
    let mut world = scenario
        .build()
        .map_err(|e| format!("{}: {e}", file.display()))?;
    std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create output folder {}: {e}", out.display()))?;
    let series_path = out.join("series.csv");
    let mut series = std::io::BufWriter::new(
        std::fs::File::create(&series_path)
            .map_err(|e| format!("cannot write {}: {e}", series_path.display()))?,
    );
    let io = |e: std::io::Error| format!("write error in {}: {e}", out.display());
    writeln!(series, "{SERIES_HEADER}").map_err(io)?;
    let interval = scenario.simulation.output_interval;
    let mut stats = RunStats::default();
    let mut progress = Progress::new(steps, quiet);
    for _ in 0..steps {
        let r = world.step();
        stats.add(&r);
        if r.step % interval == 0 || r.step == steps {
            writeln!(series, "{}", series_row(&r, world.bodies.kinetic_energy())).map_err(io)?;
        }
        progress.update(r.step, r.time, r.contacts, r.solve.iterations);
    }
    progress.finish();
    series.flush().map_err(io)?;
    let summary = Summary::new(&world, &stats, threads);
    summary.write(&out.join("summary.json")).map_err(io)?;
    if stats.not_converged > 0 {
        eprintln!(
            "warning: NLGS did not reach tolerance {} in {} of {} steps (max residual {:.3e})",
            world.settings.solver.tolerance, stats.not_converged, stats.steps, stats.max_residual
        );
    }
    if !quiet {
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
