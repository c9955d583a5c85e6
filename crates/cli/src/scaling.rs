//! `ballast bench --scaling`: thread scaling of monolithic NLGS and DDM on a settled packing
//! (the paper's Table 1 and Fig. 4).
//!
//! The packing is poured and settled once (cheap solver settings), then every configuration
//! (solver × partition × threads) restarts from the same settled state, runs a few warm-up
//! steps (so warm start is in place) and is timed over `steps` steps. Speedup and efficiency
//! compare a configuration with itself on one thread: results are bit-identical across thread
//! counts, so the same work is timed.

use crate::bench::{measure, Measured};
use ballast_engine::bodies::BodyKind;
use ballast_engine::output::checkpoint::{read_checkpoint, write_checkpoint};
use ballast_engine::scenario::presets::pile;
use ballast_engine::solver::ddm::DdmProblem;
use ballast_engine::solver::{DdmSettings, SolverSettings};
use ballast_engine::timing::PhaseTimes;
use ballast_engine::world::World;
use serde::Serialize;
use std::path::Path;

/// One scaling case (keys as the engine benchmark's, plus DDM fields).
#[derive(Serialize, Debug, Clone)]
pub struct ScalingCase {
    pub name: String,
    pub grains: usize,
    pub threads: usize,
    pub subdomains: String,
    pub contact_points: f64,
    pub ms_per_step: f64,
    pub sweeps_per_step: f64,
    pub contact_updates_per_s: f64,
    pub speedup: f64,
    pub efficiency: f64,
    pub timings_s: PhaseTimes,
    pub interface_contacts_fraction: f64,
}

fn time_case(
    settled: &World,
    ddm: Option<DdmSettings>,
    threads: usize,
    warmup: u64,
    steps: u64,
) -> Result<(Measured, f64), String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| e.to_string())?;
    Ok(pool.install(|| {
        let mut settings = settled.settings.clone();
        settings.ddm = ddm.clone();
        let mut w = World::new(settled.bodies.clone(), settled.friction.clone(), settings);
        for _ in 0..warmup {
            w.step();
        }
        let m = measure(&mut w, steps);
        // Interface share of the next step's contacts (detected, and their local problems
        // built, for this: a step with `[ddm]` builds them in its subdomains' buckets).
        let interface_fraction = match &ddm {
            Some(d) => {
                w.detect();
                let p = w.partition(d);
                let n = w.local_problems().len().max(1) as f64;
                DdmProblem::build(&p, w.local_problems(), d.parallel_interface).interface_len()
                    as f64
                    / n
            }
            None => 0.0,
        };
        (m, interface_fraction)
    }))
}

/// What the scaling study was asked to do.
pub struct ScalingArgs<'a> {
    pub json: Option<&'a Path>,
    pub grains: usize,
    pub settle_steps: u64,
    pub steps: u64,
    pub partitions: &'a [[usize; 3]],
    /// Fixed NLGS sweeps (or DDM iterations) per step instead of the tolerance-based stop.
    pub sweeps: Option<usize>,
    /// Settled packing to load, or to write after settling if it does not exist yet.
    pub packing: Option<&'a Path>,
    /// Thread counts to time (1 is always added: speedups are against it); empty: 1, 2 and
    /// all available threads.
    pub thread_counts: &'a [usize],
    /// [`DdmSettings::min_parallel_contacts`] of the DDM cases.
    pub min_parallel_contacts: usize,
    /// Detection reuse distance of the measured steps (m; 0 = the exact method).
    pub reuse_distance: f64,
}

/// Runs the scaling study and prints the Table-1 and speedup rows. With `steps = 0` it only
/// prepares the packing.
pub fn scaling(a: &ScalingArgs) -> Result<(), String> {
    let (json, grains, settle_steps, steps, partitions) =
        (a.json, a.grains, a.settle_steps, a.steps, a.partitions);
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = if a.thread_counts.is_empty() {
        vec![1, 2, all]
    } else {
        // Speedups are against one thread, so one thread is always timed.
        [&[1], a.thread_counts].concat()
    };
    threads.sort_unstable();
    threads.dedup();
    // 1. Pour and settle once, cheaply (or load the packing settled before).
    let mut scenario = pile(grains, [0.025, 0.05], 1, settle_steps);
    scenario.solver = SolverSettings {
        tolerance: 1e-3,
        max_iterations: 60,
        ..Default::default()
    };
    let mut settled = scenario.build().map_err(|e| e.to_string())?;
    match a.packing {
        Some(path) if path.exists() => {
            read_checkpoint(path, &mut settled).map_err(|e| e.to_string())?;
            eprintln!(
                "loaded the settled packing {} (step {})",
                path.display(),
                settled.step_index
            );
        }
        _ => {
            eprintln!("settling {grains} grains for {settle_steps} steps …");
            for _ in 0..settle_steps {
                settled.step();
            }
            if let Some(path) = a.packing {
                write_checkpoint(&settled, path)
                    .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
            }
        }
    }
    if steps == 0 {
        return Ok(());
    }
    // How settled the packing is: a packing still flowing costs far more detection (its pairs
    // cannot be reused) than the settled bed the study stands for.
    let mut speeds: Vec<f64> = (0..settled.bodies.len())
        .filter(|&i| settled.bodies.kind[i] == BodyKind::Dynamic)
        .map(|i| settled.bodies.velocity[i].length())
        .collect();
    speeds.sort_by(f64::total_cmp);
    if let (Some(&fastest), false) = (speeds.last(), speeds.is_empty()) {
        eprintln!(
            "grain speeds: median {:.2e} m/s, 90 % below {:.2e} m/s, fastest {fastest:.2e} m/s",
            speeds[speeds.len() / 2],
            speeds[speeds.len() * 9 / 10]
        );
    }
    settled.settings.reuse_distance = a.reuse_distance;
    // 2. Measured settings: the engine's defaults, or a fixed number of sweeps.
    settled.settings.solver = match a.sweeps {
        Some(n) => SolverSettings {
            tolerance: 1e-300,
            max_iterations: n,
            ..Default::default()
        },
        None => SolverSettings::default(),
    };
    let mut configs: Vec<Option<DdmSettings>> = vec![None];
    configs.extend(partitions.iter().map(|&d| {
        Some(DdmSettings {
            subdomains: d,
            min_parallel_contacts: a.min_parallel_contacts,
            ..Default::default()
        })
    }));
    println!(
        "{:<26} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7} {:>7} {:>6}",
        "case",
        "threads",
        "ms/step",
        "detect%",
        "nlgs%",
        "subdom%",
        "iface%",
        "other%",
        "sweeps",
        "speedup",
        "eff"
    );
    let mut cases = Vec::new();
    for ddm in configs {
        let label = ddm.as_ref().map_or("1x1x1".to_string(), |d| d.label());
        let mut t1 = None;
        for &p in &threads {
            let (m, interface_fraction) = time_case(&settled, ddm.clone(), p, 5, steps)?;
            let t = m.times;
            let base = *t1.get_or_insert(t.total);
            let speedup = base / t.total;
            let pct = |x: f64| 100.0 * x / t.total;
            let name = format!(
                "{}_{grains}_{label}",
                if ddm.is_some() { "ddm" } else { "nlgs" }
            );
            println!(
                "{:<26} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>7.1} {:>7.2} {:>5.0}%",
                name,
                p,
                1e3 * t.total / steps as f64,
                pct(t.detection),
                pct(t.nlgs),
                pct(t.subdomains),
                pct(t.interface),
                pct(t.other),
                m.sweeps,
                speedup,
                100.0 * speedup / p as f64
            );
            cases.push(ScalingCase {
                name,
                grains,
                threads: p,
                subdomains: label.clone(),
                contact_points: m.contacts,
                ms_per_step: 1e3 * t.total / steps as f64,
                sweeps_per_step: m.sweeps,
                contact_updates_per_s: m.updates_per_s,
                speedup,
                efficiency: speedup / p as f64,
                timings_s: t,
                interface_contacts_fraction: interface_fraction,
            });
        }
    }
    if let Some(path) = json {
        // Plots next to the JSON: FILE_plots/{speedup,efficiency,timings}.{svg,png}.
        let stem = path
            .file_stem()
            .map_or("scaling".into(), |s| s.to_string_lossy().to_string());
        let dir = path.with_file_name(format!("{stem}_plots"));
        let points: Vec<ballast_run::report::ScalingPoint> = cases
            .iter()
            .map(|c| {
                let t = &c.timings_s;
                let label = match c.subdomains.as_str() {
                    "1x1x1" => "NLGS".to_string(),
                    d => format!("DDM {d}"),
                };
                let nlgs = (t.nlgs - t.interface).max(0.0);
                (
                    label,
                    c.threads,
                    c.speedup,
                    c.efficiency,
                    [t.detection, nlgs, t.interface, t.other],
                )
            })
            .collect();
        if let Err(e) = ballast_run::report::write_scaling_plots(&dir, &points) {
            eprintln!("warning: plots: {e}");
        }
        let text = serde_json::to_string_pretty(&cases).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    }
    Ok(())
}
