//! How a track run converges from a given state under other settings: reads a run's
//! checkpoint into its scenario, overrides solver, correction or contact settings (which a
//! resume refuses), steps on and prints, per step, the warm start's residual, the sweeps, the
//! final residual, the largest overlap and the grains' kinetic energy. A study tool
//! (BENCHMARKS.md, session 13), not part of the suite:
//!
//! ```text
//! cargo run --release -p ballast-railway --example rest_study -- \
//!     DIR/scenario.toml DIR/checkpoints/checkpoint_N.bin STEPS [EVERY] [KEY=VALUE ...]
//! ```
//!
//! `CHECKPOINT` may be `-` (start at step 0). Keys: `sweeps` (max iterations), `beta`
//! (correction fraction), `slop`, `theta`, `stiffness` (N/m, `inf` = rigid), `symmetric`,
//! `ddm=off`. The bed cache is `$BALLAST_CACHE` (else none).

use ballast_engine::output::checkpoint::read_checkpoint;
use ballast_engine::solver::drive;
use ballast_engine::world::World;
use ballast_railway::TrackScenario;
use std::path::Path;

fn parse<T: std::str::FromStr>(key: &str, v: &str) -> Result<T, String> {
    v.parse()
        .map_err(|_| format!("{key} = {v}: not a valid value"))
}

/// Applies one `KEY=VALUE` override to the world's settings.
fn set(w: &mut World, kv: &str) -> Result<(), String> {
    let (k, v) = kv
        .split_once('=')
        .ok_or_else(|| format!("{kv}: expected KEY=VALUE"))?;
    let s = &mut w.settings;
    match k {
        "sweeps" => s.solver.max_iterations = parse(k, v)?,
        "beta" => s.correction.fraction = parse(k, v)?,
        "slop" => s.correction.slop = parse(k, v)?,
        "theta" => s.theta = parse(k, v)?,
        "symmetric" => s.solver.symmetric = parse(k, v)?,
        "stiffness" => {
            s.contact_stiffness =
                ballast_engine::world::check_contact_stiffness(Some(parse(k, v)?))?
        }
        "ddm" if v == "off" => s.ddm = None,
        _ => return Err(format!("{kv}: unknown key")),
    }
    Ok(())
}

fn main() -> Result<(), String> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 4 {
        return Err("usage: rest_study SCENARIO CHECKPOINT|- STEPS [EVERY] [KEY=VALUE ...]".into());
    }
    let text = std::fs::read_to_string(&a[1]).map_err(|e| format!("{}: {e}", a[1]))?;
    let scenario = TrackScenario::from_toml(&text).map_err(|e| e.to_string())?;
    let cache = std::env::var_os("BALLAST_CACHE");
    let mut model = scenario
        .build(cache.as_deref().map(Path::new), &mut |_| {})
        .map_err(|e| e.to_string())?;
    let w = &mut model.world;
    if a[2] != "-" {
        read_checkpoint(Path::new(&a[2]), w).map_err(|e| e.to_string())?;
    }
    let steps: usize = parse("STEPS", &a[3])?;
    let every: usize = a.get(4).map_or(Ok(1), |s| parse("EVERY", s))?.max(1);
    for kv in a.iter().skip(5) {
        set(w, kv)?;
    }
    let (mut unconverged, mut sweeps) = (0, 0);
    for k in 0..steps {
        // The warm start's residual: the local problems as the step will start them.
        w.detect();
        let nlgs = w.nlgs();
        let locals = w.local_problems().to_vec();
        let mut v = w.solver_bodies().to_vec();
        let drives = w.drives().to_vec();
        let q = (nlgs.free_scale2(&locals, &v[..]) + drive::scale_sum(&drives, &v[..])).sqrt();
        nlgs.warm_start(&locals, &mut v[..]);
        let warm = nlgs.natural_residual(&locals, &drives, &v, q);
        let r = w.step();
        unconverged += usize::from(!r.solve.converged);
        sweeps += r.solve.iterations;
        if k % every == 0 || k + 1 == steps {
            let b = &w.bodies;
            let ke: f64 = (0..b.len())
                .filter(|&i| b.inv_mass[i] > 0.0)
                .map(|i| 0.5 * b.velocity[i].length_squared() / b.inv_mass[i])
                .sum();
            println!(
                "step {} warm {warm:.2e} sweeps {} residual {:.2e} converged {} overlap {:.2e} m ke {ke:.2e} J",
                r.step, r.solve.iterations, r.solve.residual, r.solve.converged, r.max_penetration
            );
        }
    }
    println!(
        "unconverged {unconverged} of {steps}, mean sweeps {:.1}",
        sweeps as f64 / steps.max(1) as f64
    );
    Ok(())
}
