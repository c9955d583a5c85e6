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
//!   `uₙ + rₙ / (k h² θ) ≥ 0`, residual of that law), `μ ≤ 0.3`, and `nlgs + cluster LM`
//!   (every 25 sweeps, Levenberg–Marquardt on the Alart–Curnier equations of the ≤ 250
//!   contacts around the 30 largest residual terms, the rest held: a dense, local semismooth
//!   Newton; `LMTRACE=1` prints its merit).
//!
//! Each line prints `sweeps:residual(Σ rₙ)`.

use ballast_engine::laws::coulomb::solve_local_from;
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
    let mut terms: Vec<(f64, usize)> = p
        .residual_terms(r)
        .into_iter()
        .enumerate()
        .map(|(a, t)| (t, a))
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
    // NLGS sweeps interleaved with Levenberg–Marquardt on the cluster carrying the residual.
    let mut r = r0.clone();
    let mut line = String::new();
    let zero = vec![0.0; p.len()];
    for round in 1..=8 {
        for _ in 0..25 {
            let anchor = r.clone();
            sweep(&p, Local::Coulomb, &mut r, &anchor, &zero);
        }
        let cluster = hot_cluster(world, &p, &r, 30, 250);
        let before = p.residual(&r);
        cluster_newton(&p, &mut r, &cluster, 15);
        line += &format!(
            " {}:{before:.1e}->{:.1e}[{}]",
            round * 25,
            p.residual(&r),
            cluster.len()
        );
    }
    println!("nlgs + cluster LM{line}");
    let mut r = r0.clone();
    for _ in 0..300 {
        sweep(&p, Local::Coulomb, &mut r, &r0, &vec![0.0; p.len()]);
    }
    println!("where the residual is after 300 sweeps of nlgs:");
    hot_contacts(world, &p, &r, 12);
    Ok(())
}

/// Solves `a x = b` in place for a symmetric positive definite `a` (dense, row-major `n × n`),
/// `x` left in `b`; false if `a` is not positive definite.
fn cholesky_solve(a: &mut [f64], n: usize, b: &mut [f64]) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    true
}

/// Alart–Curnier function of one contact and its derivatives `(Φ, ∂Φ/∂r, ∂Φ/∂u)`.
fn alart_curnier(r: DVec3, u: DVec3, mu: f64, rho: f64) -> (DVec3, DMat3, DMat3) {
    let mut phi = DVec3::ZERO;
    let mut a = DMat3::ZERO;
    let mut b = DMat3::ZERO;
    let xn = r.x - rho * u.x;
    // Rows: set a.row(i) via columns (glam stores columns): a.col(j)[i].
    let set = |m: &mut DMat3, i: usize, j: usize, v: f64| {
        m.col_mut(j)[i] = v;
    };
    if xn > 0.0 {
        phi.x = rho * u.x;
        set(&mut b, 0, 0, rho);
    } else {
        phi.x = r.x;
        set(&mut a, 0, 0, 1.0);
    }
    let radius = mu * xn.max(0.0);
    let (zy, zz) = (r.y - rho * u.y, r.z - rho * u.z);
    let nz = zy.hypot(zz);
    let (py, pz, dpdz, dpdr) = if nz <= radius {
        (zy, zz, [[1.0, 0.0], [0.0, 1.0]], [0.0, 0.0])
    } else {
        let (ey, ez) = (zy / nz, zz / nz);
        let f = radius / nz;
        (
            radius * ey,
            radius * ez,
            [
                [f * (1.0 - ey * ey), -f * ey * ez],
                [-f * ey * ez, f * (1.0 - ez * ez)],
            ],
            [ey, ez],
        )
    };
    phi.y = r.y - py;
    phi.z = r.z - pz;
    let (drdrn, drdun) = if xn > 0.0 {
        (mu, -mu * rho)
    } else {
        (0.0, 0.0)
    };
    for (i, (row, dr)) in dpdz.iter().zip(dpdr).enumerate() {
        for (j, d) in row.iter().enumerate() {
            let id = if i == j { 1.0 } else { 0.0 };
            set(&mut a, 1 + i, 1 + j, id - d);
            set(&mut b, 1 + i, 1 + j, rho * d);
        }
        set(&mut a, 1 + i, 0, -dr * drdrn);
        set(&mut b, 1 + i, 0, -dr * drdun);
    }
    (phi, a, b)
}

/// Levenberg–Marquardt on the Alart–Curnier equations of the contacts `cluster`, the other
/// impulses fixed, at most `iterations` accepted steps.
fn cluster_newton(p: &ContactProblem, r: &mut [DVec3], cluster: &[usize], iterations: usize) {
    let m = cluster.len();
    let n = 3 * m;
    let slot: std::collections::HashMap<usize, usize> =
        cluster.iter().enumerate().map(|(k, &a)| (a, k)).collect();
    let rho: Vec<f64> = cluster
        .iter()
        .map(|&a| 1.0 / p.w.get(a, a).map_or(1.0, |b| b.x_axis.x))
        .collect();
    let eval = |r: &[DVec3]| -> (Vec<DVec3>, Vec<DMat3>, Vec<DMat3>, f64) {
        let mut phis = Vec::with_capacity(m);
        let mut aa = Vec::with_capacity(m);
        let mut bb = Vec::with_capacity(m);
        let mut merit = 0.0;
        for (k, &a) in cluster.iter().enumerate() {
            let u = p.w.row_dot(a, r) + p.q[a];
            let (phi, am, bm) = alart_curnier(r[a], u, p.mu[a], rho[k]);
            merit += phi.length_squared() / (rho[k] * rho[k]);
            phis.push(phi);
            aa.push(am);
            bb.push(bm);
        }
        (phis, aa, bb, merit)
    };
    let mut lambda = 1e-3;
    let (mut phis, mut aa, mut bb, mut merit) = eval(r);
    let merit0 = merit;
    for _ in 0..iterations {
        // J = A + B W_CC (dense), scaled rows by 1/ρ.
        let mut j = vec![0.0; n * n];
        for (k, &a) in cluster.iter().enumerate() {
            let s = 1.0 / rho[k];
            for (col, blk) in p.w.row(a) {
                let Some(&l) = slot.get(&col) else { continue };
                let bw = bb[k] * *blk;
                for i in 0..3 {
                    for jj in 0..3 {
                        j[(3 * k + i) * n + 3 * l + jj] += s * bw.col(jj)[i];
                    }
                }
            }
            for i in 0..3 {
                for jj in 0..3 {
                    j[(3 * k + i) * n + 3 * k + jj] += s * aa[k].col(jj)[i];
                }
            }
        }
        let f: Vec<f64> = phis
            .iter()
            .zip(&rho)
            .flat_map(|(p, r)| (*p / *r).to_array())
            .collect();
        // JᵀJ and Jᵀf.
        let mut jtj = vec![0.0; n * n];
        let mut g = vec![0.0; n];
        for row in 0..n {
            let jr = &j[row * n..(row + 1) * n];
            let nz: Vec<usize> = (0..n).filter(|&c| jr[c] != 0.0).collect();
            for &a in &nz {
                g[a] += jr[a] * f[row];
                for &b in &nz {
                    jtj[a * n + b] += jr[a] * jr[b];
                }
            }
        }
        let scale = (0..n).map(|i| jtj[i * n + i]).fold(0.0f64, f64::max);
        let mut accepted = false;
        for _ in 0..8 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[i * n + i] += lambda * scale;
            }
            let mut d: Vec<f64> = g.iter().map(|x| -x).collect();
            if !cholesky_solve(&mut a, n, &mut d) {
                lambda *= 10.0;
                continue;
            }
            let mut trial = r.to_vec();
            for (k, &ac) in cluster.iter().enumerate() {
                trial[ac] += DVec3::new(d[3 * k], d[3 * k + 1], d[3 * k + 2]);
            }
            let e = eval(&trial);
            if e.3 < merit {
                r.copy_from_slice(&trial);
                (phis, aa, bb, merit) = e;
                lambda = (lambda * 0.3).max(1e-12);
                accepted = true;
                break;
            }
            lambda *= 10.0;
        }
        if !accepted {
            break;
        }
    }
    if std::env::var("LMTRACE").is_ok() {
        eprintln!(
            "    cluster of {m}: AC merit {:.2e} -> {:.2e}",
            merit0.sqrt(),
            merit.sqrt()
        );
    }
}

/// Contacts of `p` whose residual terms are largest, grown by one ring of contacts sharing a
/// body, at most `cap`.
fn hot_cluster(
    world: &World,
    p: &ContactProblem,
    r: &[DVec3],
    seeds: usize,
    cap: usize,
) -> Vec<usize> {
    let mut terms: Vec<(f64, usize)> = p
        .residual_terms(r)
        .into_iter()
        .enumerate()
        .map(|(a, t)| (t, a))
        .collect();
    terms.sort_by(|x, y| y.0.total_cmp(&x.0));
    let mut set: std::collections::BTreeSet<usize> =
        terms.iter().take(seeds).map(|t| t.1).collect();
    let locals = world.local_problems();
    let bodies: std::collections::HashSet<u32> = set
        .iter()
        .flat_map(|&a| {
            let c = &locals[a];
            [(c.body1, c.dynamic1), (c.body2, c.dynamic2)]
        })
        .filter(|x| x.1)
        .map(|x| x.0)
        .collect();
    for &(_, a) in &terms {
        if set.len() >= cap {
            break;
        }
        let c = &locals[a];
        if (c.dynamic1 && bodies.contains(&c.body1)) || (c.dynamic2 && bodies.contains(&c.body2)) {
            set.insert(a);
        }
    }
    set.into_iter().collect()
}
