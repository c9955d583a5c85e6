//! Why a step does not converge: the relative natural-map residual of one step's contact
//! problem after 10 … 2,000 sweeps of several solvers, all started from the step's warm start,
//! and the contacts that carry the residual. A study tool (BENCHMARKS.md, issue 15), not part
//! of the suite:
//!
//! ```text
//! cargo run --release -p ballast-railway --example solver_study -- SCENARIO.toml STEP [CACHE]
//! ```
//!
//! runs the track scenario to `STEP` and studies step `STEP + 1`:
//! - `engine`: the engine's sweep (contacts, then the force-limited drive rows);
//! - on the assembled `(W, q, μ)` (drive rows left out: their bodies move freely):
//!   `nlgs`, `prox σ` (a proximal point: every sweep solves `W + σ W_nn` around the last
//!   iterate), `tresca` (Panagiotopoulos' fixed point: Gauss-Seidel on the convex Tresca
//!   problem with thresholds `μ rₙ` updated every sweep), `compliant k` (the normal law
//!   `uₙ + rₙ / (k h² θ) ≥ 0`, residual of that law), and `μ ≤ 0.3`.
//!
//! Each line prints `sweeps:residual(Σ rₙ)`.

use ballast_engine::laws::coulomb::{natural_map_residual, solve_local_from};
use ballast_engine::laws::ContactStatus;
use ballast_engine::math::{DMat3, DVec3};
use ballast_engine::solver::{drive, ContactProblem};
use ballast_engine::world::World;
use ballast_railway::TrackScenario;
use std::path::Path;

const AT: [usize; 8] = [10, 50, 100, 150, 300, 600, 1000, 2000];

/// How a sweep updates contact `a` of the assembled problem.
#[derive(Clone, Copy)]
enum Local {
    /// Exact Signorini-Coulomb solve, `W_αα` plus `σ_α` around the anchor impulse.
    Coulomb,
    /// One projected step per normal and tangential block on the Tresca problem.
    Tresca,
}

/// One Gauss-Seidel sweep over the assembled problem `p`.
fn sweep(p: &ContactProblem, local: Local, r: &mut [DVec3], anchor: &[DVec3], sigma: &[f64]) {
    for a in 0..p.len() {
        let w = p.w.get(a, a).copied().unwrap_or(DMat3::ZERO);
        if w.x_axis.x <= 0.0 {
            continue;
        }
        let mut u = p.w.row_dot(a, r) + p.q[a];
        match local {
            Local::Coulomb => {
                let s = sigma[a];
                let ws = w + DMat3::from_diagonal(DVec3::splat(s));
                let uf = u + (r[a] - anchor[a]) * s - ws * r[a];
                r[a] = solve_local_from(&ws, &ws.inverse(), uf, p.mu[a], r[a]).0;
            }
            Local::Tresca => {
                let threshold = p.mu[a] * anchor[a].x.max(0.0);
                let rn = (r[a].x - u.x / w.x_axis.x).max(0.0);
                u += w.x_axis * (rn - r[a].x);
                r[a].x = rn;
                let lam = w.y_axis.y + w.z_axis.z;
                let mut t = DVec3::new(0.0, r[a].y, r[a].z);
                for _ in 0..3 {
                    let mut next = t - DVec3::new(0.0, u.y, u.z) / lam;
                    let len = next.y.hypot(next.z);
                    if len > threshold {
                        next *= threshold / len;
                    }
                    u += w * (next - t);
                    t = next;
                }
                r[a] = DVec3::new(rn, t.y, t.z);
            }
        }
    }
}

/// Residual history of `local` sweeps on `p` from `r0`; `sigma_factor` scales `W_nn` into the
/// proximal weight.
fn history(p: &ContactProblem, local: Local, r0: &[DVec3], sigma_factor: f64) -> String {
    let sigma: Vec<f64> = (0..p.len())
        .map(|a| sigma_factor * p.w.get(a, a).map_or(0.0, |b| b.x_axis.x))
        .collect();
    let mut r = r0.to_vec();
    let mut anchor = r.clone();
    let mut line = String::new();
    let mut k = 0;
    for at in AT {
        while k < at {
            sweep(p, local, &mut r, &anchor, &sigma);
            anchor.copy_from_slice(&r);
            k += 1;
        }
        let sum: f64 = r.iter().map(|x| x.x).sum();
        line += &format!(" {at}:{:.2e}({sum:.0})", p.residual(&r));
    }
    line
}

/// The engine's own sweeps from the prepared step.
fn engine(world: &World) -> String {
    let nlgs = world.nlgs();
    let mut locals = world.local_problems().to_vec();
    let mut v = world.solver_bodies().to_vec();
    let mut drives = world.drives().to_vec();
    let mut status = vec![ContactStatus::NoContact; locals.len()];
    let q = (nlgs.free_scale2(&locals, &v[..]) + drive::scale_sum(&drives, &v[..])).sqrt();
    nlgs.warm_start(&locals, &mut v[..]);
    let mut line = String::new();
    let mut k = 0;
    for at in AT {
        while k < at {
            nlgs.sweep(&mut locals, &mut v[..], &mut status);
            drive::sweep(&mut drives, &mut v[..]);
            k += 1;
        }
        let sum: f64 = locals.iter().map(|c| c.r.x).sum();
        let res = nlgs.natural_residual(&locals, &drives, &v, q);
        line += &format!(" {at}:{res:.2e}({sum:.0})");
    }
    line
}

/// The contacts carrying most of the residual of `r` on `p`.
fn hot_contacts(world: &World, p: &ContactProblem, r: &[DVec3], count: usize) {
    let u = p.velocity(r);
    let mut terms: Vec<(f64, usize)> = (0..p.len())
        .map(|a| {
            let wnn = p.w.get(a, a).map_or(0.0, |b| b.x_axis.x);
            if wnn <= 0.0 {
                return (0.0, a);
            }
            let rho = 1.0 / wnn;
            (
                (natural_map_residual(r[a], u[a] * rho, p.mu[a]) / rho).powi(2),
                a,
            )
        })
        .collect();
    let total: f64 = terms.iter().map(|t| t.0).sum();
    terms.sort_by(|x, y| y.0.total_cmp(&x.0));
    let groups = &world.bodies.group;
    let mut cumulated = 0.0;
    for &(t, a) in terms.iter().take(count) {
        cumulated += t;
        let c = &world.local_problems()[a];
        let (b1, b2) = (c.body1 as usize, c.body2 as usize);
        println!(
            "  {:5.1} % (cum. {:5.1} %) bodies {b1} (group {}) – {b2} (group {}): gap {:.1e} m, \
             r {:.3} {:.3} {:.3} N·s, u {:.1e} {:.1e} {:.1e} m/s",
            100.0 * t / total,
            100.0 * cumulated / total,
            groups[b1],
            groups[b2],
            c.gap,
            r[a].x,
            r[a].y,
            r[a].z,
            u[a].x,
            u[a].y,
            u[a].z
        );
    }
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: solver_study SCENARIO.toml STEP [CACHE]".into());
    }
    let text = std::fs::read_to_string(&args[1]).map_err(|e| format!("{}: {e}", args[1]))?;
    let step: usize = args[2]
        .parse()
        .map_err(|e| format!("STEP = {}: {e}", args[2]))?;
    let scenario = TrackScenario::from_toml(&text).map_err(|e| e.to_string())?;
    let mut model = scenario
        .build(args.get(3).map(Path::new), &mut |_| {})
        .map_err(|e| e.to_string())?;
    for _ in 0..step {
        model.world.step();
    }
    model.world.detect();
    let world = &model.world;
    let p = world.contact_problem();
    let r0: Vec<DVec3> = world.local_problems().iter().map(|c| c.r).collect();
    println!(
        "step {}: {} contact points, {} drives",
        step + 1,
        p.len(),
        world.drives().len()
    );
    println!("engine          {}", engine(world));
    println!("nlgs            {}", history(&p, Local::Coulomb, &r0, 0.0));
    for s in [0.3, 1.0, 3.0] {
        println!("prox σ = {s} W_nn{}", history(&p, Local::Coulomb, &r0, s));
    }
    println!("tresca          {}", history(&p, Local::Tresca, &r0, 0.0));
    let s = &world.settings;
    for k in [1e9, 1e8, 1e7] {
        let mut compliant = p.clone();
        let c = 1.0 / (k * s.dt * s.dt * s.theta);
        for a in 0..p.len() {
            let row = compliant.w.row_start[a]..compliant.w.row_start[a + 1];
            if let Ok(j) = compliant.w.cols[row.clone()].binary_search(&(a as u32)) {
                compliant.w.blocks[row.start + j].x_axis.x += c;
            }
        }
        let line = history(&compliant, Local::Coulomb, &r0, 0.0);
        println!("compliant k = {k:.0e}{line}");
    }
    let mut low = p.clone();
    low.mu.iter_mut().for_each(|m| *m = m.min(0.3));
    println!(
        "μ ≤ 0.3         {}",
        history(&low, Local::Coulomb, &r0, 0.0)
    );
    let mut r = r0.clone();
    for _ in 0..300 {
        sweep(&p, Local::Coulomb, &mut r, &r0, &vec![0.0; p.len()]);
    }
    println!("where the residual is after 300 sweeps of nlgs:");
    hot_contacts(world, &p, &r, 12);
    Ok(())
}
