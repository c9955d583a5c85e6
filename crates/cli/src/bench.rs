//! `ballast bench`: piles of random ballast grains settling in a box.
//!
//! For each pile size: pour the grains, let them settle for `settle_steps` steps (not timed),
//! then time `steps` steps. Reported per case: mean contact points, ms per step, NLGS sweeps
//! per step, and NLGS contact-point updates per second (Σ contacts × sweeps / NLGS time).

use ballast_engine::scenario::presets::pile;
use serde::Serialize;
use std::path::Path;

/// One benchmark case (JSON keys are a contract).
#[derive(Serialize, Debug)]
struct Case {
    name: String,
    grains: usize,
    threads: usize,
    contact_points: f64,
    ms_per_step: f64,
    sweeps_per_step: f64,
    contact_updates_per_s: f64,
    timings_s: ballast_engine::timing::PhaseTimes,
    steps: u64,
    settle_steps: u64,
    tolerance: f64,
}

/// What `steps` timed steps of a world measured.
pub struct Measured {
    /// Phase times over the timed steps.
    pub times: ballast_engine::timing::PhaseTimes,
    /// Mean contact points per step.
    pub contacts: f64,
    /// Mean NLGS sweeps (or DDM iterations) per step.
    pub sweeps: f64,
    /// Σ contacts × sweeps over the NLGS time.
    pub updates_per_s: f64,
    /// Steps that missed the solver's tolerance.
    pub not_converged: u64,
}

/// Times `steps` steps of `world` (≥ 1).
pub fn measure(world: &mut ballast_engine::world::World, steps: u64) -> Measured {
    let before = world.timers;
    let (mut contacts, mut sweeps, mut updates, mut not_converged) = (0u64, 0u64, 0u64, 0u64);
    for _ in 0..steps {
        let r = world.step();
        not_converged += u64::from(!r.solve.converged);
        contacts += r.contacts as u64;
        sweeps += r.solve.iterations as u64;
        updates += (r.contacts * r.solve.iterations) as u64;
    }
    let times = world.timers - before;
    let n = steps as f64;
    Measured {
        times,
        contacts: contacts as f64 / n,
        sweeps: sweeps as f64 / n,
        updates_per_s: updates as f64 / times.nlgs.max(1e-12),
        not_converged,
    }
}

pub fn bench(
    json: Option<&Path>,
    sizes: &[usize],
    settle_steps: u64,
    steps: u64,
    threads: usize,
) -> Result<(), String> {
    if steps == 0 {
        return Err("--steps = 0: must be ≥ 1".into());
    }
    let mut cases = Vec::new();
    println!(
        "{:<12} {:>7} {:>7} {:>10} {:>10} {:>8} {:>14}",
        "case", "grains", "threads", "contacts", "ms/step", "sweeps", "updates/s"
    );
    for &n in sizes {
        if n == 0 {
            return Err("--grains: sizes must be ≥ 1".into());
        }
        let scenario = pile(n, [0.025, 0.05], 1, settle_steps + steps);
        let mut world = scenario.build().map_err(|e| e.to_string())?;
        for _ in 0..settle_steps {
            world.step();
        }
        let m = measure(&mut world, steps);
        let case = Case {
            name: format!("pile_{n}"),
            grains: n,
            threads,
            contact_points: m.contacts,
            ms_per_step: 1e3 * m.times.total / steps as f64,
            sweeps_per_step: m.sweeps,
            contact_updates_per_s: m.updates_per_s,
            timings_s: m.times,
            steps,
            settle_steps,
            tolerance: world.settings.solver.tolerance,
        };
        println!(
            "{:<12} {:>7} {:>7} {:>10.0} {:>10.3} {:>8.1} {:>14.3e}",
            case.name,
            case.grains,
            case.threads,
            case.contact_points,
            case.ms_per_step,
            case.sweeps_per_step,
            case.contact_updates_per_s
        );
        cases.push(case);
    }
    if let Some(path) = json {
        let text = serde_json::to_string_pretty(&cases).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    }
    Ok(())
}
