//! `ballast bench --paper`: the paper's tamping computation step by step (issue 18's contract).
//!
//! The paper preset's bed is prepared once (or read from the cache), then every case starts
//! from the same world at t = 0 and times `steps` steps of the tamping cycle (after one
//! untimed step, so that warm start and the detection anchors are in place as in a run):
//! the paper's stop (exactly 740 sweeps per step) and the preset's tolerance stop, each on 1
//! thread and on all threads. Results do not depend on the thread count, so the two thread
//! counts time the same work (the bench checks it: same contact points and sweeps).

use crate::bench::{measure, Measured};
use ballast_engine::solver::ConvergenceNorm;
use ballast_engine::timing::PhaseTimes;
use ballast_engine::world::World;
use ballast_railway::preparation::PrepProgress;
use ballast_railway::scenario::{TrackModel, TrackScenario};
use serde::Serialize;
use std::path::Path;

/// The paper's fixed number of DDM iterations per step (its Table 1).
pub const PAPER_SWEEPS: usize = 740;

/// One case (JSON keys are a contract: the engine benchmark's, plus `stop`,
/// `preparation_s`, `peak_rss_bytes`).
#[derive(Serialize, Debug, Clone)]
pub struct PaperCase {
    pub name: String,
    pub grains: usize,
    pub threads: usize,
    pub contact_points: f64,
    pub ms_per_step: f64,
    pub sweeps_per_step: f64,
    pub contact_updates_per_s: f64,
    /// `"740"` (the paper's fixed sweeps) or `"tolerance"` (the preset's stop).
    pub stop: String,
    /// Seconds spent preparing the bed in this run, or recorded when the cached bed was made.
    pub preparation_s: f64,
    /// The process's peak resident memory after the case (bytes; 0 where unknown).
    pub peak_rss_bytes: u64,
    /// Table 1's phases over the timed steps.
    pub timings_s: PhaseTimes,
    /// Steps timed.
    pub steps: u64,
    /// Subdomains of the case (`"NXxNYxNZ"`, `"1x1x1"` when monolithic).
    pub subdomains: String,
    /// Steps of the timed ones that missed the solver's tolerance.
    pub steps_not_converged: u64,
}

/// What `ballast bench --paper` is given.
pub struct PaperArgs<'a> {
    /// The track scenario: `"paper"` (the contract), another preset name or a scenario file.
    pub bed: &'a str,
    pub cache: Option<&'a Path>,
    pub json: Option<&'a Path>,
    pub steps: u64,
    /// Thread counts to time (1 and all cores by default).
    pub thread_counts: &'a [usize],
    pub quiet: bool,
}

/// The process's peak resident set size (Linux `VmHWM`), 0 elsewhere.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// The track scenario named by `bed`: a preset name, or a file.
fn scenario(bed: &str) -> Result<TrackScenario, String> {
    let path = Path::new(bed);
    if path.extension().is_some_and(|e| e == "toml") || path.exists() {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("--bed {bed}: cannot read it: {e}"))?;
        TrackScenario::from_toml(&text).map_err(|e| format!("--bed {bed}: {e}"))
    } else {
        TrackScenario::preset(bed).map_err(|_| {
            format!("--bed {bed}: neither a preset (default, paper) nor a track scenario file")
        })
    }
}

/// Times one case: a world at t = 0 built from `model`'s bodies, with the paper's stop or the
/// scenario's.
fn time_case(
    model: &TrackModel,
    tolerance_stop: bool,
    threads: usize,
    steps: u64,
) -> Result<Measured, String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start {threads} threads: {e}"))?;
    Ok(pool.install(|| {
        let mut settings = model.world.settings.clone();
        if !tolerance_stop {
            // The paper's stop: a tolerance never met, so every step runs exactly 740 sweeps.
            settings.solver.norm = ConvergenceNorm::Quad;
            settings.solver.tolerance = 1e-300;
            settings.solver.residual_tolerance = f64::INFINITY;
            settings.solver.max_iterations = PAPER_SWEEPS;
        }
        let mut w = World::new(
            model.world.bodies.clone(),
            model.world.friction.clone(),
            settings,
        );
        w.step();
        measure(&mut w, steps)
    }))
}

/// Runs the bench, prints its table and writes its JSON (`{"cases": [...]}`).
pub fn paper(a: &PaperArgs) -> Result<Vec<PaperCase>, String> {
    if a.steps == 0 {
        return Err("--steps = 0: must be ≥ 1".into());
    }
    let s = scenario(a.bed)?;
    let quiet = a.quiet;
    let mut last = std::time::Instant::now();
    if !quiet {
        eprintln!(
            "bench --paper: preparing the bed of {} ({} block(s)), or reading it from the cache",
            a.bed, s.track.blocks
        );
    }
    let model = s
        .build(a.cache, &mut |p: PrepProgress| {
            if !quiet && last.elapsed().as_secs_f64() > 10.0 {
                last = std::time::Instant::now();
                eprintln!(
                    "  stage {}: t = {:.3} s (at least {:.3} s), {} grains, {} contacts",
                    p.stage, p.time, p.target, p.grains, p.contacts
                );
            }
        })
        .map_err(|e| format!("--bed {}: {e}", a.bed))?;
    let grains = model.preparation.grains;
    let subdomains = model
        .world
        .settings
        .ddm
        .as_ref()
        .map_or("1x1x1".to_string(), |d| d.label());
    println!(
        "{:<10} {:>7} {:>7} {:>10} {:>10} {:>8} {:>12} {:>10} {:>6}",
        "stop",
        "grains",
        "threads",
        "contacts",
        "ms/step",
        "sweeps",
        "ns/update",
        "peak MiB",
        "unconv"
    );
    let mut cases = Vec::new();
    for tolerance_stop in [false, true] {
        let mut first: Option<(f64, f64)> = None;
        for &threads in a.thread_counts {
            let m = time_case(&model, tolerance_stop, threads, a.steps)?;
            // The same work on every thread count: a difference is a determinism bug.
            match first {
                None => first = Some((m.contacts, m.sweeps)),
                Some(f) if f != (m.contacts, m.sweeps) => {
                    return Err(format!(
                        "bench --paper: {threads} threads gave {} contact points and {} sweeps \
                         per step, 1 thread {} and {}: results must not depend on the thread \
                         count",
                        m.contacts, m.sweeps, f.0, f.1
                    ));
                }
                Some(_) => {}
            }
            let case = PaperCase {
                name: format!("paper_{}", if tolerance_stop { "tolerance" } else { "740" }),
                grains,
                threads,
                contact_points: m.contacts,
                ms_per_step: 1e3 * m.times.total / a.steps as f64,
                sweeps_per_step: m.sweeps,
                contact_updates_per_s: m.updates_per_s,
                stop: if tolerance_stop { "tolerance" } else { "740" }.into(),
                preparation_s: model.preparation.wall_s,
                peak_rss_bytes: peak_rss_bytes(),
                timings_s: m.times,
                steps: a.steps,
                subdomains: subdomains.clone(),
                steps_not_converged: m.not_converged,
            };
            println!(
                "{:<10} {:>7} {:>7} {:>10.0} {:>10.1} {:>8.1} {:>12.1} {:>10.0} {:>6}",
                case.stop,
                case.grains,
                case.threads,
                case.contact_points,
                case.ms_per_step,
                case.sweeps_per_step,
                1e9 * case.threads as f64 / case.contact_updates_per_s.max(1e-300),
                case.peak_rss_bytes as f64 / (1024.0 * 1024.0),
                case.steps_not_converged
            );
            cases.push(case);
        }
    }
    if let Some(path) = a.json {
        let text = serde_json::to_string_pretty(&serde_json::json!({ "cases": cases }))
            .map_err(|e| e.to_string())?;
        std::fs::write(path, text)
            .map_err(|e| format!("--json {}: cannot write it: {e}", path.display()))?;
    }
    Ok(cases)
}
