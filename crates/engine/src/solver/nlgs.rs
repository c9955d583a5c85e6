//! Non-Linear Gauss-Seidel (NLGS) over the local problems.
//!
//! Algorithm (one step; `V` are body velocities, initialised to `V_free + M⁻¹ H r⁰` with `r⁰`
//! the warm-start impulses):
//!
//! 1. `q_α = H_αᵀ V_free` for every α (scale of the natural-map residual).
//! 2. For k = 1, 2, … up to `max_iterations`, sweep α in the given order:
//!    1. `u = H_αᵀ V`, then `u_f = u − W_αα r_α` (velocity without α's own impulse);
//!    2. if `g_α + h θ u_f,n > 0` (gap prediction): `r̂ = 0`; else `r̂` = exact local
//!       Signorini-Coulomb solution for `(W_αα, u_f + (max(g_α, 0)/hθ) n, μ_α)` (Signorini on
//!       the predicted gap: the contact closes its gap within the step and no further), a
//!       slide's Newton iteration starting from the direction of `r_α`
//!       ([`crate::laws::coulomb::solve_local_from`]);
//!    3. relax `r_new = (1 − ω) r_α + ω r̂`, apply `V += M⁻¹ H_α (r_new − r_α)`, `r_α = r_new`;
//!    4. accumulate `‖W_αα Δr_α‖²` and `‖W_αα r_α‖²` for the Quad norm.
//! 3. Every `check_every` sweeps, evaluate the chosen norm; stop when it is below `tolerance`
//!    and the natural-map residual is below `residual_tolerance` (see [`SolverSettings`]).
//! 4. Report iterations, the final Quad norm and natural-map residual, and convergence.
//!
//! # Compliant contacts
//!
//! With a contact stiffness `k` ([`crate::world::StepSettings::contact_stiffness`]) the normal
//! law is the rate form of an elastic contact: over the step the normal force `λ = rₙ/h`
//! changes by `k` times the approach `−h uₙ`, from the force `r̄ₙ/h` the contact carried at the
//! end of the previous step, and the contact opens when that would make it negative:
//!
//! ```text
//! 0 ≤ rₙ  ⊥  uₙ + c (rₙ − r̄ₙ) ≥ 0,      c = 1 / (k h²)
//! ```
//!
//! (with the gap shift of the rigid law on top). It is the rigid law's local problem with
//! `W_nn + c` and `u_f,n − c r̄ₙ`, so the exact local solver, the sweep and the residual are
//! unchanged; `c = 0` is the rigid law, bit for bit. A static load `F` deflects a contact by
//! `F/k`. Why: in a jammed packing with `μ = 1` the rigid law's forces are not unique (wedged
//! grains carry self-stresses of any size) and Gauss-Seidel drifts along them without
//! converging; a stiffness picks the elastic solution, and a stiff one (granite corners under
//! kN loads: about 1e7–1e8 N/m) changes the motion by micrometres.
//!
//! The rate form remembers the force, not the overlap: nothing ties the overlap `δ = −g` to the
//! deflection `r̄ₙ/(k h)` its force implies, and it drifts where contact points churn (a new
//! point starts with `r̄ₙ = 0` and may approach by `c rₙ`) or where a polyhedral overlap's depth
//! jumps as the closest features change. The overlap recovery
//! ([`crate::world::StepSettings::overlap_recovery`] β) asks an overlapping compliant contact
//! to separate at `(β/h) max(0, δ − r̄ₙ/(k h) − slop)` on top of the law, a Baumgarte-type
//! stabilisation of the drift alone: a contact whose overlap is its elastic deflection is not
//! touched, and the speed is part of `q` (and of the residual's scale).
//!
//! With [`crate::laws::NormalLaw::Overlap`] `r̄ₙ` is not remembered but read from the
//! geometry: the impulse the overlap at the start of the step holds elastically (capped),
//! so the same local problem is a spring on the measured overlap.

//!
//! # Skipping still contacts
//!
//! Step 2 solves contact α exactly with the others fixed, so while neither of its bodies'
//! velocities changes, α stays solved. With [`SolverSettings::skip`] `η > 0` each body counts
//! the changes of its velocity (at the contact points, accumulated until they pass
//! `ε = η τ q / √N`), α remembers the counts when it was last solved, and a sweep skips α
//! while they are unchanged; every eighth sweep updates every contact. The residual checks
//! read every contact.

use super::delassus::{BodyAccess, LocalProblem, SolverBody};
use super::drive::{self, DriveRows};
use super::{SolverSettings, StopRule};
use crate::laws::coulomb::{natural_map_residual, project_on_cone, solve_local_from};
use crate::laws::{ContactStatus, Elastic};
use crate::math::DVec3;
use serde::{Deserialize, Serialize};

/// What one solve did: a per-step record users can trust.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Sweeps performed.
    pub iterations: usize,
    /// Quad norm of the last sweep.
    pub quad: f64,
    /// Natural-map residual at the end.
    pub residual: f64,
    /// Whether the tolerance was met before the iteration cap.
    pub converged: bool,
    /// Natural-map residual checks made by the stopping rule (the final evaluation of a
    /// solve that stopped otherwise not counted).
    #[serde(default)]
    pub residual_checks: usize,
    /// Of these, the checks that the contacts hot at the previous check proved failed
    /// without a pass over all contacts (see
    /// [`SolverSettings::hot_first`](super::SolverSettings::hot_first)).
    #[serde(default)]
    pub hot_proofs: usize,
}

/// The NLGS solver (stateless apart from its settings).
#[derive(Clone, Debug)]
pub struct Nlgs {
    pub settings: SolverSettings,
    /// `h θ`, the gap-prediction factor.
    pub h_theta: f64,
    /// Normal compliance `c = 1/(k h²)` of the compliant law (0: rigid contacts).
    pub compliance: f64,
    /// Tangential compliance `c_t = 1/(k_t h²)` (0: sticking contacts are rigid).
    pub tangential_compliance: f64,
    /// β of the compliant law's overlap recovery (0: off; always 0 for rigid contacts).
    pub recovery: f64,
    /// `1/h`.
    pub inv_h: f64,
    /// `1/(k h)`: the elastic deflection per unit of normal impulse.
    pub overlap_per_impulse: f64,
    /// Excess overlap the recovery tolerates (m).
    pub recovery_slop: f64,
    /// `k h V_m` of the hyperbolic closure law (see [`crate::laws::closure`]); 0: the linear
    /// law, every contact's compliance is [`Self::compliance`].
    pub closure_impulse: f64,
    /// The skip threshold (m/s, see [`SolverSettings::skip`]); 0: no skipping and no
    /// tracking of the bodies' changes.
    pub(crate) skip_drift: f64,
    /// Whether this sweep may skip (tracking goes on in the sweeps that update every contact).
    pub(crate) skip_now: bool,
}

/// The skip threshold of a solve (m/s): `η τ q / √N` with `η` = [`SolverSettings::skip`],
/// `τ` the natural-map tolerance, `q` the residual's scale and `N` the rows: `N` contacts each
/// off by the threshold would add up to `η` times the tolerance. 0 (no skipping) when skipping
/// is off or no natural-map tolerance stops the solve (nothing then bounds what is skipped).
pub(crate) fn skip_threshold(s: &SolverSettings, q: f64, rows: usize) -> f64 {
    let tol = match s.norm {
        super::ConvergenceNorm::NaturalMap => s.tolerance.min(s.residual_tolerance),
        super::ConvergenceNorm::Quad => s.residual_tolerance,
    };
    if s.skip > 0.0 && tol.is_finite() {
        s.skip * tol * q / (rows.max(1) as f64).sqrt()
    } else {
        0.0
    }
}

/// A contact's natural-map residual term as last computed, with its bodies'
/// [`SolverBody::version`]s then.
///
/// Between two residual checks most contacts of a large bed are untouched by the sweep in
/// between (skipped, or solved with no change), and the check is mostly arithmetic (square
/// roots, divisions): reading the term back costs what a skipped contact costs. A term depends
/// on the contact's impulse and its bodies' velocities (the rest of its local problem is fixed
/// within a solve); its impulse changes only with an increment applied to its bodies, which
/// writes a dynamic body and so moves its version. A contact with no dynamic body is
/// recomputed every time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TermCache {
    value: f64,
    versions: [u32; 2],
}

impl TermCache {
    /// No term yet (a solve starts with every contact's cache empty).
    pub(crate) const EMPTY: TermCache = TermCache {
        value: f64::NAN,
        versions: [0; 2],
    };

    /// `cache` sized for `n` contacts (emptied when it was not), or `None` when `reuse` is off.
    pub(crate) fn ready(
        cache: &mut Vec<TermCache>,
        n: usize,
        reuse: bool,
    ) -> Option<&mut [TermCache]> {
        if !reuse {
            return None;
        }
        if cache.len() != n {
            cache.clear();
            cache.resize(n, TermCache::EMPTY);
        }
        Some(cache.as_mut_slice())
    }

    /// The term of contact `c`: read back when its bodies' versions are those it was computed
    /// at, else `compute(c)` (and remembered).
    #[inline(always)]
    fn term<B: BodyAccess + ?Sized>(
        &mut self,
        c: &LocalProblem,
        v: &B,
        compute: impl FnOnce(&LocalProblem) -> f64,
    ) -> f64 {
        let versions = [v.body(c.body1).version, v.body(c.body2).version];
        if versions == self.versions && !self.value.is_nan() {
            return self.value;
        }
        let value = compute(c);
        if c.dynamic1 || c.dynamic2 {
            *self = TermCache { value, versions };
        }
        value
    }
}

/// The sum of `terms` in order, or `None` once a partial sum exceeds `limit`.
#[inline(always)]
fn bounded_sum(terms: impl Iterator<Item = f64>, limit: f64) -> Option<f64> {
    let mut sum = 0.0;
    for t in terms {
        sum += t;
        if sum > limit {
            return None;
        }
    }
    Some(sum)
}

/// A contact is hot when its residual term exceeds this many times its share of a sum that
/// fails a check (the limit over the number of rows): few enough to be summed at a fraction of
/// a pass, enough to carry most of the residual of a check that fails (see
/// [`SolverSettings::hot_first`](super::SolverSettings::hot_first)).
const HOT_TERM: f64 = 3.0;

/// The term above which a contact is hot, for a check with sum limit `limit` over `rows`.
pub(crate) fn hot_threshold(limit: f64, rows: usize) -> f64 {
    HOT_TERM * limit / rows.max(1) as f64
}

/// Every this many sweeps, a solve that skips updates every contact: skipping can then slow
/// Gauss-Seidel by at most this factor, never stall it short of the tolerance.
const FULL_SWEEP_EVERY: usize = 8;
/// Contacts ahead of the one being solved whose bodies a sweep asks the cache for: far enough
/// that the lines arrive in time, near enough that they are still there when used.
const PREFETCH: usize = 8;

/// Asks the cache for the bodies of contact `k` of `locals`, if there is one: the sweep's
/// contacts are streamed in order, but their bodies are scattered (a hint: no effect on
/// results).
#[inline(always)]
fn ahead<B: BodyAccess + ?Sized>(locals: &[LocalProblem], v: &B, k: usize) {
    if let Some(c) = locals.get(k) {
        v.prefetch(c.body1);
        v.prefetch(c.body2);
    }
}

/// Sums carried through a sweep.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
pub struct SweepSums {
    /// `Σ ‖W Δr‖²`.
    pub dwr2: f64,
    /// `Σ ‖W r‖²`.
    pub wr2: f64,
}

impl std::ops::AddAssign for SweepSums {
    fn add_assign(&mut self, o: Self) {
        self.dwr2 += o.dwr2;
        self.wr2 += o.wr2;
    }
}

impl SweepSums {
    /// Quad norm from the sums (0 when nothing is loaded).
    pub(crate) fn quad(&self) -> f64 {
        if self.wr2 > 0.0 {
            (self.dwr2 / self.wr2).sqrt()
        } else {
            self.dwr2.sqrt()
        }
    }
}

impl Nlgs {
    /// Updates contact α (step 2 of the algorithm) and returns its status.
    #[inline(always)]
    pub(crate) fn update_contact<B: BodyAccess + ?Sized>(
        &self,
        c: &mut LocalProblem,
        v: &mut B,
        sums: &mut SweepSums,
    ) -> ContactStatus {
        let u = c.velocity(v);
        let unloaded = c.r == DVec3::ZERO;
        // Unloaded now and at the end of the last step, the compliant law's shift `c r̄ₙ` is
        // zero: the open test below needs no compliance (whose divisions would sit on this
        // path, the one about 40 % of the updates in a dense bed take), and decides the same.
        if unloaded && c.r_prev == 0.0 && c.gap + self.h_theta * u.x > 0.0 {
            return ContactStatus::NoContact;
        }
        let uf = if unloaded { u } else { u - c.w * c.r };
        // The compliant law's free velocity (exactly `uf` for rigid contacts).
        let (cn, ct) = self.compliances(c);
        let uf = DVec3::new(
            uf.x - cn * c.r_prev,
            uf.y - ct * f64::from(c.rt_prev[0]),
            uf.z - ct * f64::from(c.rt_prev[1]),
        );
        let (rhat, status) = if c.gap + self.h_theta * uf.x > 0.0 {
            // An open contact that stays open (about 40 % of the updates in a dense bed):
            // nothing to apply, nothing to add to the sums.
            if unloaded {
                return ContactStatus::NoContact;
            }
            (DVec3::ZERO, ContactStatus::NoContact)
        } else {
            // W⁻¹ is not stored: at large scale the sweep is bound by memory traffic, and the
            // inverse costs less than streaming 72 more bytes per contact.
            let mut w = c.w.to_mat();
            w.x_axis.x += cn;
            w.y_axis.y += ct;
            w.z_axis.z += ct;
            solve_local_from(&w, &w.inverse(), self.shifted(c, uf), c.mu, c.r)
        };
        let om = self.settings.relaxation;
        let rnew = if om == 1.0 {
            rhat
        } else if om < 1.0 {
            c.r + (rhat - c.r) * om
        } else {
            // Over-relaxation can leave the cone: project back onto it.
            project_on_cone(c.r + (rhat - c.r) * om, c.mu)
        };
        let dr = rnew - c.r;
        if dr != DVec3::ZERO {
            if self.skip_drift > 0.0 {
                c.apply_tracked(v, dr, self.skip_drift as f32);
            } else {
                c.apply(v, dr);
            }
        }
        c.r = rnew;
        sums.dwr2 += (c.w * dr).length_squared();
        sums.wr2 += (c.w * rnew).length_squared();
        status
    }

    /// Contact `c`'s normal and tangential compliances at its current impulse: with the
    /// closure law, [`Self::compliance`] and [`Self::tangential_compliance`] divided by the
    /// secant stiffening between the force it carried and the one it carries now (see
    /// [`crate::laws::closure`]).
    #[inline(always)]
    pub(crate) fn compliances(&self, c: &LocalProblem) -> (f64, f64) {
        self.compliances_at(c, c.r.x)
    }

    /// [`Self::compliances`] with the current normal impulse `r`.
    #[inline(always)]
    pub(crate) fn compliances_at(&self, c: &LocalProblem, r: f64) -> (f64, f64) {
        if self.closure_impulse > 0.0 && (c.r_prev > 0.0 || r > 0.0) {
            let soft = 1.0 / self.elastic().secant(c.r_prev, r);
            (self.compliance * soft, self.tangential_compliance * soft)
        } else {
            (self.compliance, self.tangential_compliance)
        }
    }

    /// The elastic deflection law of the compliant contacts (see [`Elastic`]).
    #[inline(always)]
    pub fn elastic(&self) -> Elastic {
        Elastic {
            per_impulse: self.overlap_per_impulse,
            closure_impulse: self.closure_impulse,
        }
    }

    /// The velocity the Signorini condition acts on: `u + (max(g, 0) / hθ) n`, so that a
    /// contact with a positive gap may close it within the step (`g + hθ uₙ ≥ 0`) and no
    /// further. Signorini on `uₙ` itself would stop the bodies at the gap they had while the
    /// gap prediction calls that same state open: a contact then flips between the two from
    /// sweep to sweep, a limit cycle Gauss-Seidel never leaves.
    ///
    /// On an overlapping compliant contact, the recovery's separation speed is subtracted.
    #[inline(always)]
    pub(crate) fn shifted(&self, c: &LocalProblem, u: DVec3) -> DVec3 {
        if c.gap > 0.0 {
            DVec3::new(u.x + c.gap / self.h_theta, u.y, u.z)
        } else if self.recovery > 0.0 {
            DVec3::new(u.x - self.recovery_speed(c), u.y, u.z)
        } else {
            u
        }
    }

    /// The separation speed the compliant law's overlap recovery asks of contact `c`:
    /// `(β_α/h) max(0, δ − r̄ₙ/(k h) − slop)` with `δ = −g` the overlap at the start of the step
    /// and `r̄ₙ/(k h)` the elastic deflection under the force it carried (0 when off, for an
    /// open contact and for rigid contacts).
    ///
    /// `β_α = min(β, ω_α h / 16)`, `ω_α = √(k W_nn)` the contact's own angular frequency: the
    /// speed moves the spring's rest point, and a rest point that moves within a fraction of
    /// the contact's period kicks the bodies into an oscillation as large as the excess (a
    /// cube 2 mm deep in the floor at `ω h` = 1.2 jumps 0.6 mm clear of it with β = 0.1, 5.8 mm
    /// with β = 0.2; test `the_overlap_recovery_lifts_a_sunk_block_without_a_jump`). Spread
    /// over 16 radians, 2.5 periods, the bodies follow it.
    #[inline(always)]
    pub(crate) fn recovery_speed(&self, c: &LocalProblem) -> f64 {
        if self.recovery > 0.0 && c.gap <= 0.0 {
            let excess = -c.gap - self.elastic().deflection(c.r_prev) - self.recovery_slop;
            if excess > 0.0 {
                let omega_h = (c.w.xx() / self.compliances_at(c, c.r_prev).0).sqrt();
                return self.recovery.min(omega_h * (1.0 / 16.0)) * self.inv_h * excess;
            }
        }
        0.0
    }

    /// `‖H_αᵀ V‖²` plus the square of the recovery's speed: a contact's share of the
    /// residual's squared scale on `V_free` (without the recovery's speed a step whose only
    /// motion is that recovery would read as a relative residual of order 1).
    #[inline]
    pub(crate) fn scale2<B: BodyAccess + ?Sized>(&self, c: &LocalProblem, v: &B) -> f64 {
        c.velocity(v).length_squared() + self.recovery_speed(c).powi(2)
    }

    /// Natural-map residual contribution `‖·‖²` of contact α at the current state, on the
    /// shifted velocity (see [`Nlgs::update_contact`]) and, for compliant contacts, on
    /// `uₙ + c (rₙ − r̄ₙ)`; an open contact with no impulse contributes nothing, one with an
    /// impulse `‖W_nn r‖`.
    #[inline]
    pub(crate) fn residual2<B: BodyAccess + ?Sized>(&self, c: &LocalProblem, v: &B) -> f64 {
        let mut u = c.velocity(v);
        let (cn, ct) = self.compliances(c);
        u.x += cn * (c.r.x - c.r_prev);
        u.y += ct * (c.r.y - f64::from(c.rt_prev[0]));
        u.z += ct * (c.r.z - f64::from(c.rt_prev[1]));
        // ρ = 1/W_nn makes `r − ρ u` consistent in units (N·s); dividing by ρ gives m/s.
        let rho = 1.0 / (c.w.xx() + cn);
        (natural_map_residual(c.r, self.shifted(c, u) * rho, c.mu) / rho).powi(2)
    }

    /// `Σ ‖H_αᵀ V‖²` over `locals`: on `V_free`, the squared scale of the residual.
    pub fn free_scale2<B: BodyAccess + ?Sized>(&self, locals: &[LocalProblem], v: &B) -> f64 {
        locals.iter().map(|c| self.scale2(c, v)).sum()
    }

    /// Applies the warm-start impulses, in order: `V += M⁻¹ H r⁰`.
    pub fn warm_start<B: BodyAccess + ?Sized>(&self, locals: &[LocalProblem], v: &mut B) {
        for c in locals {
            if c.r != DVec3::ZERO {
                c.apply(v, c.r);
            }
        }
    }

    /// One Gauss-Seidel sweep over `locals` in order (step 2 of the algorithm).
    pub fn sweep<B: BodyAccess + ?Sized>(
        &self,
        locals: &mut [LocalProblem],
        v: &mut B,
        status: &mut [ContactStatus],
    ) -> SweepSums {
        let mut sums = SweepSums::default();
        let n = locals.len().min(status.len());
        if self.skip_drift > 0.0 {
            for k in 0..n {
                ahead(locals, v, k + PREFETCH);
                self.update_or_skip(&mut locals[k], v, &mut status[k], &mut sums);
            }
            return sums;
        }
        for k in 0..n {
            ahead(locals, v, k + PREFETCH);
            status[k] = self.update_contact(&mut locals[k], v, &mut sums);
        }
        sums
    }

    /// With skipping on: [`Self::update_contact`], unless this sweep may skip and neither body
    /// moved past the threshold since the contact was last solved (its local problem is then
    /// still solved within that change, and its status stands).
    #[inline(always)]
    fn update_or_skip<B: BodyAccess + ?Sized>(
        &self,
        c: &mut LocalProblem,
        v: &mut B,
        st: &mut ContactStatus,
        sums: &mut SweepSums,
    ) {
        if self.skip_now && c.seen == c.epochs(v) {
            return;
        }
        *st = self.update_contact(c, v, sums);
        c.seen = c.epochs(v);
    }

    /// The threshold and skip flag of sweep `k` of a solve whose threshold is `drift`.
    pub(crate) fn for_sweep(&mut self, k: usize, drift: f64) {
        self.skip_drift = drift;
        self.skip_now = k > 1 && !k.is_multiple_of(FULL_SWEEP_EVERY);
    }

    /// Sweep `k` (1-based) of a solve: forward, or with [`SolverSettings::symmetric`] every
    /// even sweep backward.
    pub(crate) fn sweep_k<B: BodyAccess + ?Sized>(
        &self,
        k: usize,
        locals: &mut [LocalProblem],
        v: &mut B,
        status: &mut [ContactStatus],
    ) -> SweepSums {
        if !(self.settings.symmetric && k.is_multiple_of(2)) {
            return self.sweep(locals, v, status);
        }
        let mut sums = SweepSums::default();
        for k in (0..locals.len().min(status.len())).rev() {
            if let Some(a) = k.checked_sub(PREFETCH) {
                ahead(locals, v, a);
            }
            let (c, st) = (&mut locals[k], &mut status[k]);
            if self.skip_drift > 0.0 {
                self.update_or_skip(c, v, st, &mut sums);
            } else {
                *st = self.update_contact(c, v, &mut sums);
            }
        }
        sums
    }

    /// `Σ_α ‖residual_α‖²` over `locals` (see [`ConvergenceNorm::NaturalMap`]), or `None` once
    /// the partial sum exceeds `limit` (the terms are non-negative: the whole sum would too).
    /// With a `cache` (one entry per contact, see [`TermCache`]) a term whose bodies have not
    /// been written since it was computed is read back instead: the same value, so the same
    /// sum bit for bit.
    pub(crate) fn residual_sum_within<B: BodyAccess + ?Sized>(
        &self,
        locals: &[LocalProblem],
        v: &B,
        limit: f64,
        cache: Option<&mut [TermCache]>,
    ) -> Option<f64> {
        self.residual_sum_marking(locals, v, limit, cache, None)
    }

    /// [`Self::residual_sum_within`] that also lists in `hot.0` (cleared first), in order,
    /// the contacts it visited whose term exceeds `hot.1`.
    pub(crate) fn residual_sum_marking<B: BodyAccess + ?Sized>(
        &self,
        locals: &[LocalProblem],
        v: &B,
        limit: f64,
        cache: Option<&mut [TermCache]>,
        mut hot: Option<(&mut Vec<u32>, f64)>,
    ) -> Option<f64> {
        if let Some((list, _)) = hot.as_mut() {
            list.clear();
        }
        let mut mark = |k: usize, term: f64| {
            if let Some((list, above)) = hot.as_mut() {
                if term > *above {
                    list.push(k as u32);
                }
            }
            term
        };
        match cache {
            Some(cache) if cache.len() == locals.len() => bounded_sum(
                locals.iter().zip(cache).enumerate().map(|(k, (c, t))| {
                    ahead(locals, v, k + PREFETCH);
                    mark(k, t.term(c, v, |c| self.residual2(c, v)))
                }),
                limit,
            ),
            _ => bounded_sum(
                locals.iter().enumerate().map(|(k, c)| {
                    ahead(locals, v, k + PREFETCH);
                    mark(k, self.residual2(c, v))
                }),
                limit,
            ),
        }
    }

    /// The sum, in order, of the residual terms of the contacts `some` (ascending indices
    /// into `locals`), read back from `cache` where it holds them.
    pub(crate) fn residual_sum_of<B: BodyAccess + ?Sized>(
        &self,
        locals: &[LocalProblem],
        v: &B,
        some: &[u32],
        cache: Option<&mut [TermCache]>,
    ) -> f64 {
        let mut sum = 0.0;
        match cache {
            Some(cache) if cache.len() == locals.len() => {
                for &k in some {
                    let k = k as usize;
                    sum += cache[k].term(&locals[k], v, |c| self.residual2(c, v));
                }
            }
            _ => {
                for &k in some {
                    sum += self.residual2(&locals[k as usize], v);
                }
            }
        }
        sum
    }

    /// Solves the problem with all contacts in their stored order. `v` holds `V_free` on entry
    /// and the end-of-step velocities on return; the impulses are left in the local problems,
    /// the statuses in `status`.
    pub fn solve(
        &self,
        locals: &mut [LocalProblem],
        v: &mut [SolverBody],
        status: &mut [ContactStatus],
    ) -> SolveReport {
        self.solve_with_drives(locals, &mut [], v, status)
    }

    /// [`Nlgs::solve`] with force-limited drives: each sweep runs the contacts in order, then
    /// the drives' rows ([`super::drive`]). The drive impulses are left in `drives`.
    pub(crate) fn solve_with_drives(
        &self,
        locals: &mut [LocalProblem],
        drives: &mut [DriveRows],
        v: &mut [SolverBody],
        status: &mut [ContactStatus],
    ) -> SolveReport {
        // 1. Scale of the residual: free local velocities.
        let q2 = self.free_scale2(locals, v) + drive::scale_sum(drives, v);
        let q = if q2 > 0.0 { q2.sqrt() } else { 1.0 };
        let drift = skip_threshold(&self.settings, q, locals.len() + drives.len());
        let mut this = self.clone();
        self.warm_start(locals, v);
        let mut report = SolveReport::default();
        if locals.is_empty() && drives.is_empty() {
            report.converged = true;
            return report;
        }
        let s = &self.settings;
        let mut stop = StopRule::new();
        let mut cache = Vec::new();
        let mut hot = Vec::new();
        for k in 1..=s.max_iterations {
            this.for_sweep(k, drift);
            let mut sums = this.sweep_k(k, locals, v, status);
            sums += drive::sweep(drives, v);
            report.iterations = k;
            report.quad = sums.quad();
            let (checks, proofs) = (&mut report.residual_checks, &mut report.hot_proofs);
            if stop.converged(s, k, report.quad, |bound| {
                *checks += 1;
                let terms = TermCache::ready(&mut cache, locals.len(), s.reuse_residual_terms);
                let hot = s.hot_first.then_some((&mut hot, proofs));
                self.natural_residual_within(locals, drives, v, q, bound, terms, hot)
            }) {
                report.converged = true;
                break;
            }
        }
        report.residual = stop.final_residual(report.iterations, || {
            let terms = TermCache::ready(&mut cache, locals.len(), s.reuse_residual_terms);
            self.natural_residual_within(locals, drives, v, q, f64::INFINITY, terms, None)
                .unwrap_or(f64::INFINITY)
        });
        report
    }

    /// [`Nlgs::natural_residual`], or `None` as soon as a partial sum shows it exceeds `bound`
    /// (the terms are added in the same order, so a full evaluation gives the same value).
    /// With `hot` (the contacts hot at the last check, and a count of the checks they
    /// decided), the hot contacts are summed first (see [`SolverSettings::hot_first`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn natural_residual_within(
        &self,
        locals: &[LocalProblem],
        drives: &[DriveRows],
        v: &[SolverBody],
        q: f64,
        bound: f64,
        mut cache: Option<&mut [TermCache]>,
        hot: Option<(&mut Vec<u32>, &mut usize)>,
    ) -> Option<f64> {
        let limit = super::exceeding_sum(bound, q);
        let sum = match hot {
            Some((hot, proofs)) => {
                // As `ddm::hot_exceeds`: a subsequence of the ordered sum of non-negative
                // terms exceeding the limit proves that the whole sum does, bit for bit.
                if limit.is_finite()
                    && !hot.is_empty()
                    && self.residual_sum_of(locals, v, hot, cache.as_deref_mut()) > limit
                {
                    *proofs += 1;
                    return None;
                }
                let above = hot_threshold(limit, locals.len() + drives.len());
                self.residual_sum_marking(locals, v, limit, cache, Some((hot, above)))?
            }
            None => self.residual_sum_within(locals, v, limit, cache)?,
        };
        Some((sum + drive::residual_sum(drives, v)).sqrt() / q)
    }

    /// Relative natural-map residual of the whole problem (contacts and drives).
    pub fn natural_residual(
        &self,
        locals: &[LocalProblem],
        drives: &[DriveRows],
        v: &[SolverBody],
        q: f64,
    ) -> f64 {
        // Never `None` without a bound.
        self.natural_residual_within(locals, drives, v, q, f64::INFINITY, None, None)
            .unwrap_or(f64::INFINITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::DMat3;
    use crate::solver::delassus::contact_along_x;

    /// Three unit cubes in a row along x, approaching each other, and a fixed body 0 below:
    /// every contact violates the law, so every residual term is positive.
    fn row() -> (Vec<LocalProblem>, Vec<SolverBody>) {
        let body = |inv_mass: f64, vx: f64| SolverBody {
            v: DVec3::new(vx, 0.0, 0.0),
            w: DVec3::ZERO,
            inv_mass,
            inv_inertia: DMat3::IDENTITY * 6.0 * inv_mass,
            epoch: 0,
            drift: 0.0,
            version: 0,
        };
        let bodies = vec![
            body(0.0, 0.0),
            body(1.0, -0.1),
            body(1.0, -0.3),
            body(1.0, -0.6),
        ];
        let contact = |a, b| contact_along_x(&bodies, a, b, 0.0, 0.5);
        (vec![contact(0, 1), contact(1, 2), contact(2, 3)], bodies)
    }

    fn rigid_nlgs() -> Nlgs {
        Nlgs {
            settings: SolverSettings::default(),
            h_theta: 5e-4,
            compliance: 0.0,
            tangential_compliance: 0.0,
            recovery: 0.0,
            inv_h: 1.0 / 5e-4,
            overlap_per_impulse: 0.0,
            recovery_slop: 0.0,
            closure_impulse: 0.0,
            skip_drift: 0.0,
            skip_now: false,
        }
    }

    /// The bounded sum is the full sum, term for term, unless a partial sum passes the limit.
    #[test]
    fn bounded_residual_sum_is_the_full_sum_or_proves_it_larger() {
        let (locals, bodies) = row();
        let nlgs = rigid_nlgs();
        let terms: Vec<f64> = locals
            .iter()
            .map(|c| nlgs.residual2(c, &bodies[..]))
            .collect();
        assert!(terms.iter().all(|&t| t > 0.0), "{terms:?}");
        let full = terms.iter().fold(0.0, |s, &t| s + t);
        assert_eq!(
            nlgs.residual_sum_within(&locals, &bodies[..], f64::INFINITY, None),
            Some(full)
        );
        assert_eq!(
            nlgs.residual_sum_within(&locals, &bodies[..], full, None),
            Some(full)
        );
        // Past the first term's share: it stops there.
        assert_eq!(
            nlgs.residual_sum_within(&locals, &bodies[..], 0.5 * terms[0], None),
            None
        );
        assert_eq!(
            nlgs.residual_sum_within(&locals, &bodies[..], full * (1.0 - 1e-12), None),
            None
        );
        // The relative residual: the same value as the full evaluation, or None past the bound.
        let q = 0.7;
        let r = nlgs.natural_residual(&locals, &[], &bodies, q);
        assert_eq!(
            nlgs.natural_residual_within(&locals, &[], &bodies, q, r, None, None),
            Some(r)
        );
        assert_eq!(
            nlgs.natural_residual_within(&locals, &[], &bodies, q, 0.5 * r, None, None),
            None
        );
    }

    /// A residual check reads back the terms whose bodies' versions did not move, and only
    /// those: after each sweep the sum with the cache equals the full sum bit for bit; a body
    /// written behind the versions' back shows that the read-back happens, and moving its
    /// version brings the term up to date.
    #[test]
    fn cached_residual_terms_follow_the_bodies_versions() {
        let (mut locals, mut bodies) = row();
        let nlgs = rigid_nlgs();
        let mut cache = vec![TermCache::EMPTY; locals.len()];
        let mut status = vec![ContactStatus::NoContact; locals.len()];
        for sweep in 0..6 {
            let full = nlgs.residual_sum_within(&locals, &bodies[..], f64::INFINITY, None);
            let cached =
                nlgs.residual_sum_within(&locals, &bodies[..], f64::INFINITY, Some(&mut cache));
            assert_eq!(
                full.map(f64::to_bits),
                cached.map(f64::to_bits),
                "sweep {sweep}"
            );
            nlgs.sweep(&mut locals, &mut bodies[..], &mut status);
        }
        let sum = |cache: &mut [TermCache], bodies: &[SolverBody]| {
            nlgs.residual_sum_within(&locals, bodies, f64::INFINITY, Some(cache))
                .unwrap()
        };
        let before = sum(&mut cache, &bodies);
        // Body 3 (only in the last contact) pushed away without its version moving: the
        // stale term is read back.
        bodies[3].v.x -= 1.0;
        assert_eq!(sum(&mut cache, &bodies), before);
        let full = nlgs
            .residual_sum_within(&locals, &bodies[..], f64::INFINITY, None)
            .unwrap();
        assert_ne!(full, before);
        bodies[3].version += 1;
        assert_eq!(sum(&mut cache, &bodies), full);
        // Too short a cache is ignored rather than misread.
        assert_eq!(
            nlgs.residual_sum_within(&locals, &bodies[..], f64::INFINITY, Some(&mut cache[..1])),
            Some(full)
        );
    }
}
