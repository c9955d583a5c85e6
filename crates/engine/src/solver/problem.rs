//! The contact problem of one step as a value: `(W, q, μ)`, as Siconos' `FrictionContactProblem`
//! and the FCLIB collection (`fclib_local`) hold it.
//!
//! Mathematics. With the local impulses `r = (r_α)` and local velocities `u = (u_α)` (each in
//! its contact frame `[n, t, s]`), the step's dynamics gives
//!
//! ```text
//! u = W r + q,    W = Hᵀ M⁻¹ H,    q = Hᵀ V_free + (max(g_α, 0) / hθ) eₙ per contact,
//! ```
//!
//! and each `(u_α, r_α)` obeys the Signorini-Coulomb law with `μ_α`. The shift of `q` is the
//! engine's Signorini on the predicted gap (see [`super::nlgs::Nlgs`]): with it, the plain
//! Signorini-Coulomb law on `(W, q, μ)` is the engine's law, so any solver of that standard
//! problem (Siconos' and LMGC90's included) solves the step's contacts.
//!
//! With a contact stiffness `k` (the compliant normal law of [`super::Nlgs`]), the law
//! `uₙ + c (rₙ − r̄ₙ) ≥ 0` with `c = 1/(k h²)` and `r̄ₙ` the previous step's normal impulse is
//! folded in the same way: `c` is added to every diagonal block's normal entry and `−c r̄ₙ` to
//! `qₙ`, so the standard problem on `(W, q, μ)` is again the engine's. The law's overlap
//! recovery (a separation speed on overlaps deeper than the elastic deflection) is one more
//! shift of `qₙ`.
//!
//! `W` is assembled as a sparse symmetric matrix of 3×3 blocks: block `(α, β)` is
//!
//! ```text
//! W_αβ = Σ_b s_αb s_βb E_αᵀ (m_b⁻¹ 1 − [r_αb×] I_b⁻¹ [r_βb×]) E_β
//! ```
//!
//! over the bodies `b` that contacts α and β share and whose velocities impulses change
//! (`s = −1` for a contact's first body, `+1` for its second; `r_αb` the lever arm). Force-limited
//! drive rows are not part of this problem (FCLIB has no such rows): with drives, `q` is the
//! free velocity of the contacts with the drive impulses left at zero.

use super::delassus::{LocalProblem, SolverBody};
use super::nlgs::{Nlgs, SolveReport};
use super::{SolverSettings, StopRule};
use crate::laws::coulomb::{natural_map_residual, solve_local_from};
use crate::math::{skew, DMat3, DVec3};

/// A sparse matrix of 3×3 blocks in compressed rows: row α holds the blocks
/// `blocks[row_start[α]..row_start[α + 1]]` at block columns `cols[..]`, in increasing order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BlockMatrix {
    /// Start of each block row in `cols` and `blocks` (length: rows + 1).
    pub row_start: Vec<usize>,
    /// Block column of each stored block.
    pub cols: Vec<u32>,
    /// The stored blocks.
    pub blocks: Vec<DMat3>,
}

impl BlockMatrix {
    /// Number of block rows.
    pub fn rows(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }

    /// Block `(i, j)`, if stored.
    pub fn get(&self, i: usize, j: usize) -> Option<&DMat3> {
        let range = self.row_start[i]..self.row_start[i + 1];
        let k = self.cols[range.clone()].binary_search(&(j as u32)).ok()?;
        Some(&self.blocks[range.start + k])
    }

    /// Block row `i`: `(column, block)` pairs.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, &DMat3)> {
        let range = self.row_start[i]..self.row_start[i + 1];
        self.cols[range.clone()]
            .iter()
            .map(|&c| c as usize)
            .zip(&self.blocks[range])
    }

    /// `Σ_j A_ij x_j` for row `i`.
    #[inline]
    pub fn row_dot(&self, i: usize, x: &[DVec3]) -> DVec3 {
        self.row(i).map(|(j, b)| *b * x[j]).sum()
    }

    /// `A x`.
    pub fn mul(&self, x: &[DVec3]) -> Vec<DVec3> {
        (0..self.rows()).map(|i| self.row_dot(i, x)).collect()
    }
}

/// The contact problem of one step (see the module documentation).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactProblem {
    /// The Delassus operator `W` (symmetric, positive semi-definite).
    pub w: BlockMatrix,
    /// `q`: the free local velocities, shifted by the positive gaps (m/s).
    pub q: Vec<DVec3>,
    /// Friction coefficient per contact.
    pub mu: Vec<f64>,
    /// `‖Hᵀ V_free‖` (without the gap shift): the scale of the engine's relative
    /// natural-map residual.
    pub scale: f64,
    /// The normal compliance `c = 1/(k h²)` included in `W` and `q` (0: rigid contacts); with
    /// the hyperbolic closure law, contact α's is `c` divided by the square of its stiffening
    /// at the force it carried (the law linearised there, see [`crate::laws::closure`]), as is
    /// its tangential one.
    pub compliance: f64,
    /// The tangential compliance `c_t = 1/(k_t h²)` included in `W` and `q` (0: rigid
    /// sticking).
    pub tangential_compliance: f64,
    /// Each contact's normal and tangential compliance as included in `W`'s diagonal block
    /// and in `q`: [`Self::compliance`] and [`Self::tangential_compliance`] for the linear law,
    /// less for a loaded contact under the closure law.
    pub compliances: Vec<[f64; 2]>,
}

/// Lever arm, sign and body of one side of a contact, for the assembly.
#[derive(Clone, Copy)]
struct Side {
    contact: u32,
    sign: f64,
    arm: DVec3,
}

impl ContactProblem {
    /// Assembles the problem of `locals` (the step's local problems) on the free velocities
    /// `v_free` (the solver bodies before any impulse), with `nlgs`'s law: its gap-prediction
    /// factor `h θ`, its normal compliance (0: rigid) and its overlap recovery. Deterministic:
    /// blocks are summed in body order.
    pub(crate) fn assemble(locals: &[LocalProblem], v_free: &[SolverBody], nlgs: &Nlgs) -> Self {
        let (compliance, ct) = (nlgs.compliance, nlgs.tangential_compliance);
        let n = locals.len();
        // The contacts each writable body carries, in contact order.
        let mut sides: Vec<Vec<Side>> = vec![Vec::new(); v_free.len()];
        for (a, c) in locals.iter().enumerate() {
            for (body, sign, arm, dynamic) in [
                (c.body1, -1.0, c.r1, c.dynamic1),
                (c.body2, 1.0, c.r2, c.dynamic2),
            ] {
                if dynamic {
                    sides[body as usize].push(Side {
                        contact: a as u32,
                        sign,
                        arm,
                    });
                }
            }
        }
        let frames: Vec<DMat3> = locals
            .iter()
            .map(|c| {
                let [n, t, s] = c.frame3();
                DMat3::from_cols(n, t, s)
            })
            .collect();
        let mut rows: Vec<Vec<(u32, DMat3)>> = vec![Vec::new(); n];
        for (b, list) in sides.iter().enumerate() {
            let body = &v_free[b];
            let m_inv = DMat3::from_diagonal(DVec3::splat(body.inv_mass));
            for x in list {
                let ex = frames[x.contact as usize];
                let left = ex.transpose();
                for y in list {
                    let ey = frames[y.contact as usize];
                    let world = m_inv - skew(x.arm) * body.inv_inertia * skew(y.arm);
                    let block = left * world * ey * (x.sign * y.sign);
                    rows[x.contact as usize].push((y.contact, block));
                }
            }
        }
        let mut w = BlockMatrix {
            row_start: Vec::with_capacity(n + 1),
            ..BlockMatrix::default()
        };
        w.row_start.push(0);
        for mut row in rows {
            // Stable: two contributions to one block (contacts sharing both bodies) add in
            // body order.
            row.sort_by_key(|&(c, _)| c);
            let mut last: Option<u32> = None;
            for (c, block) in row {
                if last == Some(c) {
                    *w.blocks.last_mut().expect("a block was pushed") += block;
                } else {
                    w.cols.push(c);
                    w.blocks.push(block);
                    last = Some(c);
                }
            }
            w.row_start.push(w.cols.len());
        }
        let free: Vec<DVec3> = locals.iter().map(|c| c.velocity(v_free)).collect();
        // `Nlgs::scale2` on the velocities just computed.
        let scale = locals
            .iter()
            .zip(&free)
            .map(|(c, u)| u.length_squared() + nlgs.recovery_speed(c).powi(2))
            .sum::<f64>()
            .sqrt();
        let compliances: Vec<[f64; 2]> = locals
            .iter()
            .map(|c| {
                let (cn, ct) = nlgs.compliances_at(c, c.r_prev);
                [cn, ct]
            })
            .collect();
        let q = locals
            .iter()
            .zip(free)
            .zip(&compliances)
            .map(|((c, u), &[cn, ct])| {
                let [t, s] = c.rt_prev.map(f64::from);
                let u = DVec3::new(u.x - cn * c.r_prev, u.y - ct * t, u.z - ct * s);
                nlgs.shifted(c, u)
            })
            .collect();
        if compliance > 0.0 {
            for (a, &[compliance, ct]) in compliances.iter().enumerate() {
                let range = w.row_start[a]..w.row_start[a + 1];
                if let Ok(k) = w.cols[range.clone()].binary_search(&(a as u32)) {
                    let b = &mut w.blocks[range.start + k];
                    b.x_axis.x += compliance;
                    b.y_axis.y += ct;
                    b.z_axis.z += ct;
                }
            }
        }
        ContactProblem {
            w,
            q,
            mu: locals.iter().map(|c| c.mu).collect(),
            scale,
            compliance,
            tangential_compliance: ct,
            compliances,
        }
    }

    /// Number of contacts.
    pub fn len(&self) -> usize {
        self.q.len()
    }

    /// Whether the problem has no contact.
    pub fn is_empty(&self) -> bool {
        self.q.is_empty()
    }

    /// `u = W r + q`.
    pub fn velocity(&self, r: &[DVec3]) -> Vec<DVec3> {
        self.w
            .mul(r)
            .into_iter()
            .zip(&self.q)
            .map(|(wr, q)| wr + *q)
            .collect()
    }

    /// The engine's relative natural-map residual of `r` (per contact scaled by
    /// `ρ_α = 1/W_nn,α`, over [`ContactProblem::scale`]).
    pub fn residual(&self, r: &[DVec3]) -> f64 {
        let sum: f64 = self.residual_terms(r).iter().sum();
        let scale = if self.scale > 0.0 { self.scale } else { 1.0 };
        sum.sqrt() / scale
    }

    /// Each contact's squared term of [`ContactProblem::residual`] (m²/s², not scaled):
    /// where the residual is.
    pub fn residual_terms(&self, r: &[DVec3]) -> Vec<f64> {
        let u = self.velocity(r);
        (0..self.len())
            .map(|a| {
                let wnn = self.w.get(a, a).map_or(0.0, |b| b.x_axis.x);
                if wnn <= 0.0 {
                    return 0.0;
                }
                let rho = 1.0 / wnn;
                (natural_map_residual(r[a], u[a] * rho, self.mu[a]) / rho).powi(2)
            })
            .collect()
    }

    /// Non-Linear Gauss-Seidel on the assembled problem, contacts in order, from the impulses
    /// in `r` (left there): the reference solver for a problem handed in from elsewhere, and a
    /// cross-check of the engine's matrix-free sweep. Stops as the engine does (the stop norm
    /// of `settings`, then the natural-map residual).
    pub fn solve_nlgs(&self, r: &mut [DVec3], settings: &SolverSettings) -> SolveReport {
        let n = self.len();
        let mut report = SolveReport::default();
        if n == 0 {
            report.converged = true;
            return report;
        }
        let diag: Vec<DMat3> = (0..n)
            .map(|a| self.w.get(a, a).copied().unwrap_or(DMat3::ZERO))
            .collect();
        let mut stop = StopRule::new();
        for k in 1..=settings.max_iterations {
            let (mut dwr2, mut wr2) = (0.0, 0.0);
            for a in 0..n {
                let w = diag[a];
                if w.x_axis.x <= 0.0 {
                    // Two bodies that no impulse moves: nothing to solve.
                    continue;
                }
                let u = self.w.row_dot(a, r) + self.q[a];
                let uf = u - w * r[a];
                let (rhat, _) = solve_local_from(&w, &w.inverse(), uf, self.mu[a], r[a]);
                dwr2 += (w * (rhat - r[a])).length_squared();
                wr2 += (w * rhat).length_squared();
                r[a] = rhat;
            }
            report.iterations = k;
            report.quad = if wr2 > 0.0 {
                (dwr2 / wr2).sqrt()
            } else {
                dwr2.sqrt()
            };
            if stop.converged(settings, k, report.quad, |_| Some(self.residual(r))) {
                report.converged = true;
                break;
            }
        }
        report.residual = stop.final_residual(report.iterations, || self.residual(r));
        report
    }
}

/// One 6×3 block of `H`: the impulse (`force`) and angular impulse about the centre of mass
/// (`torque`) that a local impulse `r` of `contact` applies to body slot `body`:
/// `P = force · r`, `L = torque · r`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HBlock {
    /// Slot of the body in [`GlobalProblem::bodies`].
    pub body: u32,
    /// The contact.
    pub contact: u32,
    /// `s E` (`s = −1` for the contact's first body, `+1` for its second; `E = [n t s]`).
    pub force: DMat3,
    /// `s [a×] E` with `a` the lever arm from the body's centre of mass to the point.
    pub torque: DMat3,
}

/// The global form of a step's contact problem, as FCLIB's `fclib_global` and Siconos'
/// `GlobalFrictionContactProblem` hold it: with `v` the velocities `(v, ω)` of the bodies the
/// contacts move,
///
/// ```text
/// v = v_free + M⁻¹ H r,   u = Hᵀ v + b,   so   W = Hᵀ M⁻¹ H,   q = Hᵀ v_free + b,
/// ```
///
/// where `b` gathers what does not depend on those bodies: the motion of driven and fixed
/// bodies and the gap shift of [`ContactProblem`]. `M⁻¹` is the solver's: zero on a degree of
/// freedom a drive imposes. With a contact stiffness, `W = Hᵀ M⁻¹ H + c Iₙ` (`c` on the normal
/// rows, [`GlobalProblem::compliance`]; `c_t` on the tangential ones with a tangential
/// stiffness) and `b` holds `−c r̄ₙ` (and `−c_t r̄_t`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GlobalProblem {
    /// The bodies the contacts move (world indices, increasing).
    pub bodies: Vec<u32>,
    /// Their inverse masses.
    pub inv_mass: Vec<f64>,
    /// Their inverse inertia tensors (world frame).
    pub inv_inertia: Vec<DMat3>,
    /// Their free velocities: linear, angular.
    pub v_free: Vec<[DVec3; 2]>,
    /// `H` as 6×3 blocks, by contact, then body slot.
    pub h: Vec<HBlock>,
    /// `b = q − Hᵀ v_free`, per contact.
    pub b: Vec<DVec3>,
    /// The normal compliance `c` of [`ContactProblem::compliance`].
    pub compliance: f64,
    /// The tangential compliance of [`ContactProblem::tangential_compliance`].
    pub tangential_compliance: f64,
}

impl GlobalProblem {
    /// The global form of `problem`, the contact problem of `locals` on `v_free` (see
    /// [`ContactProblem::assemble`]).
    pub(crate) fn assemble(
        locals: &[LocalProblem],
        v_free: &[SolverBody],
        problem: &ContactProblem,
    ) -> Self {
        let mut slot = vec![u32::MAX; v_free.len()];
        let mut bodies = Vec::new();
        for c in locals {
            for (body, dynamic) in [(c.body1, c.dynamic1), (c.body2, c.dynamic2)] {
                if dynamic {
                    bodies.push(body);
                }
            }
        }
        bodies.sort_unstable();
        bodies.dedup();
        for (k, &b) in bodies.iter().enumerate() {
            slot[b as usize] = k as u32;
        }
        let mut h = Vec::with_capacity(2 * locals.len());
        let mut b = Vec::with_capacity(locals.len());
        for (a, c) in locals.iter().enumerate() {
            let [n, t, s] = c.frame3();
            let e = DMat3::from_cols(n, t, s);
            let mut htv = DVec3::ZERO;
            for (body, sign, arm, dynamic) in [
                (c.body1, -1.0, c.r1, c.dynamic1),
                (c.body2, 1.0, c.r2, c.dynamic2),
            ] {
                if !dynamic {
                    continue;
                }
                let force = e * sign;
                let torque = skew(arm) * force;
                let vb = &v_free[body as usize];
                htv += force.transpose() * vb.v + torque.transpose() * vb.w;
                h.push(HBlock {
                    body: slot[body as usize],
                    contact: a as u32,
                    force,
                    torque,
                });
            }
            b.push(problem.q[a] - htv);
        }
        GlobalProblem {
            inv_mass: bodies
                .iter()
                .map(|&i| v_free[i as usize].inv_mass)
                .collect(),
            inv_inertia: bodies
                .iter()
                .map(|&i| v_free[i as usize].inv_inertia)
                .collect(),
            v_free: bodies
                .iter()
                .map(|&i| [v_free[i as usize].v, v_free[i as usize].w])
                .collect(),
            bodies,
            h,
            b,
            compliance: problem.compliance,
            tangential_compliance: problem.tangential_compliance,
        }
    }

    /// `Hᵀ M⁻¹ H r` for local impulses `r`: `W r` computed through the bodies (a check of
    /// [`ContactProblem::w`]).
    pub fn w_times(&self, r: &[DVec3]) -> Vec<DVec3> {
        let mut p = vec![[DVec3::ZERO; 2]; self.bodies.len()];
        for blk in &self.h {
            let x = r[blk.contact as usize];
            let pb = &mut p[blk.body as usize];
            pb[0] += blk.force * x;
            pb[1] += blk.torque * x;
        }
        let dv: Vec<[DVec3; 2]> = p
            .iter()
            .enumerate()
            .map(|(k, [f, l])| [*f * self.inv_mass[k], self.inv_inertia[k] * *l])
            .collect();
        let mut u = vec![DVec3::ZERO; r.len()];
        for blk in &self.h {
            let [dv, dw] = dv[blk.body as usize];
            u[blk.contact as usize] += blk.force.transpose() * dv + blk.torque.transpose() * dw;
        }
        u
    }
}
