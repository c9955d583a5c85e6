//! The global contact problem of one step and its Non-Linear Gauss-Seidel solution.
//!
//! Mathematics. With `V` the body velocities at the end of the step, `V_free = Vᵢ + h M⁻¹ F_ext`
//! and `H` the map from contact impulses (in local frames) to body impulses, the discrete dynamics
//! is `M (V − V_free) = H r`, and at each contact α the relative velocity is
//! `u_α = H_αᵀ V = u_free,α + Σ_β W_αβ r_β` with the Delassus operator `W = Hᵀ M⁻¹ H`.
//! Each pair `(u_α, r_α)` obeys the Signorini-Coulomb law (see [`crate::laws`]) with gap
//! prediction: if `g_α + h θ u_n` is positive, where `u_n` is the normal velocity the contact
//! would have without its own impulse, the contact carries no impulse.
//!
//! `W` is never assembled off its diagonal blocks: the solver keeps `V = V_free + M⁻¹ H r`
//! current, so `u_α` is read from the two bodies' velocities at any time.

// Internals exposed for the crate's tests, benches and the railway studies (local problems,
// subdomain solves, correction passes, drive rows); not part of the supported API, which is
// re-exported below.
#[doc(hidden)]
pub mod correction;
#[doc(hidden)]
pub mod ddm;
#[doc(hidden)]
pub mod delassus;
#[doc(hidden)]
pub mod drive;
pub mod exchange;
mod nlgs;
#[doc(hidden)]
pub mod partition;
mod problem;

pub use correction::CorrectionSettings;
pub use ddm::DdmSettings;
pub use delassus::{LocalProblem, SolverBody};
pub use drive::DriveRows;
pub use exchange::{Exchange, ThreadRanks};
pub use nlgs::{Nlgs, SolveReport};
pub use partition::{Balance, Partition};
pub use problem::{BlockMatrix, ContactProblem, GlobalProblem, HBlock};

use crate::ScenarioError;
use serde::{Deserialize, Serialize};

/// The convergence measure used to stop NLGS.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConvergenceNorm {
    /// LMGC90's "Quad"-type norm: over one sweep,
    /// `sqrt(Σ_α ‖W_αα Δr_α‖²) / sqrt(Σ_α ‖W_αα r_α‖²)`, the relative change of the contact
    /// velocities produced by the impulses. Cheap: computed inside the sweep.
    Quad,
    /// Siconos' natural-map residual, per contact scaled by `ρ_α = 1/W_nn,α` so that impulses
    /// and velocities are consistent in units (evaluated, since it costs a pass over the
    /// contacts, once the Quad norm of a sweep is below the tolerance, and otherwise after a
    /// quarter more sweeps than at the previous evaluation):
    /// `sqrt(Σ_α ‖r_α − P_K(r_α − ρ_α(u_α + μ‖u_t,α‖ n))‖² / ρ_α²) / ‖q‖` with `q` the free
    /// local velocities (a contact opened by gap prediction contributes `‖r_α‖/ρ_α`).
    /// Costs one extra pass over the contacts per check.
    NaturalMap,
}

/// NLGS settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSettings {
    /// Stop when the chosen norm is below this value.
    pub tolerance: f64,
    /// Iteration (sweep) cap; reaching it without convergence is reported.
    pub max_iterations: usize,
    /// Convergence measure.
    pub norm: ConvergenceNorm,
    /// Relaxation ω ∈ (0, 1]: `r ← (1 − ω) r_old + ω r_local`.
    pub relaxation: f64,
    /// Test convergence every this many sweeps.
    pub check_every: usize,
    /// Start from the previous step's impulses of persisting contacts.
    pub warm_start: bool,
    /// A step is converged only when its relative natural-map residual is at most this,
    /// whatever norm stops the sweeps (`inf`: the stop norm alone decides). A cheap norm such
    /// as Quad measures the change of one sweep, which Gauss-Seidel makes small long before
    /// the forces are right (a resting pile: Quad 9e-4 after 4 sweeps with a residual of
    /// 1.2e-2); once the stop norm is met the residual is checked, and the sweeps go on until
    /// it is met too, checking again after a quarter more sweeps each time.
    #[serde(deserialize_with = "correction::infinite_if_null")]
    pub residual_tolerance: f64,
    /// Symmetric Gauss-Seidel: every second sweep runs the contacts backward (under domain
    /// decomposition, within each subdomain and interface group). A forward-only sweep can
    /// lock into a cycle (a grain on the floor pressed by a neighbour: the two contacts undo
    /// each other's update every sweep, the residual frozen at 1.6e-2 for 1,000 sweeps) that
    /// the backward sweep breaks (1e-3 in 37 sweeps).
    pub symmetric: bool,
    /// Skip threshold `η` (≥ 0; 0: off). A sweep skips a contact whose two bodies' velocities
    /// (at its point) changed by less than `η τ q / √N` since it was last solved, `τ` being
    /// the natural-map tolerance, `q` the residual's scale and `N` the number of rows: its
    /// local problem is still solved within that change, so the sweep costs only where the
    /// solution moves. Every eighth sweep updates every contact, so Gauss-Seidel slows by at
    /// most that factor and never stalls; the residual checks see every contact (the Quad norm
    /// of a sweep, only those it updated). Off when no
    /// natural-map tolerance stops the solve (`residual_tolerance = inf` with the Quad norm).
    #[serde(skip_serializing_if = "is_zero")]
    pub skip: f64,
    /// Whether a residual check reads back the terms of the contacts whose bodies were not
    /// written since the previous check instead of recomputing them (on by default). The
    /// results are the same bit for bit either way; off, every check computes every term
    /// (the reference the equivalence tests compare with).
    #[serde(skip_serializing_if = "is_true")]
    pub reuse_residual_terms: bool,
    /// Whether a residual check first adds up the terms of the contacts that carried the
    /// residual at the previous check, and stops there when they alone exceed the tolerance
    /// (on by default). Near convergence most checks fail, and they fail on a few contacts:
    /// proving it on those costs a fraction of a pass. The results are the same bit for bit
    /// either way (see `solver::ddm::hot_exceeds`); off, every check is a full pass (not in a
    /// run distributed over processes, whose checks always are).
    #[serde(skip_serializing_if = "is_true")]
    pub hot_first: bool,
}

/// Left out of the settings' JSON at its default (see [`is_zero`]).
fn is_true(x: &bool) -> bool {
    *x
}

/// Left out of the settings' JSON when off, so that scenarios, checkpoints and cache keys
/// written before the setting existed read the same.
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-4,
            max_iterations: 1000,
            norm: ConvergenceNorm::Quad,
            relaxation: 1.0,
            check_every: 1,
            warm_start: true,
            residual_tolerance: DEFAULT_RESIDUAL_TOLERANCE,
            symmetric: false,
            skip: 0.0,
            reuse_residual_terms: true,
            hot_first: true,
        }
    }
}

/// The squared bound past which a partial sum of squared residual terms proves that the
/// relative residual `√sum / q` exceeds `bound` (with room for the rounding of the square
/// root and the division, so that the proof never contradicts the full evaluation).
#[inline]
pub(crate) fn exceeding_sum(bound: f64, q: f64) -> f64 {
    let b = bound * q;
    b * b * (1.0 + 1e-9)
}

/// Default [`SolverSettings::residual_tolerance`]: a relative natural-map residual of 1e-3.
pub(crate) const DEFAULT_RESIDUAL_TOLERANCE: f64 = 1e-3;

/// The stopping rule of NLGS and of the DDM iterations (see [`SolverSettings`]): the stop
/// norm, then the natural-map residual, checked with a growing interval while it fails.
#[derive(Clone, Copy, Debug)]
pub(crate) struct StopRule {
    /// First iteration at which the residual may be checked again.
    next_residual_check: usize,
    /// The last residual evaluated, and at which iteration.
    last: Option<(usize, f64)>,
}

impl StopRule {
    pub(crate) fn new() -> Self {
        StopRule {
            next_residual_check: 0,
            last: None,
        }
    }

    /// The residual at iteration `k`: the one evaluated there, if any, else `residual()`.
    pub(crate) fn final_residual(&self, k: usize, residual: impl FnOnce() -> f64) -> f64 {
        match self.last {
            Some((at, r)) if at == k => r,
            _ => residual(),
        }
    }

    /// Whether iteration `k` (1-based) ends the solve as converged. `quad` is the Quad norm
    /// of its sweep; `residual(bound)` evaluates the relative natural-map residual (called at
    /// most once), or returns `None` as soon as it is known to exceed `bound`: the step is then
    /// not converged whatever its value, and a stalled step's checks stop after the first
    /// contacts that carry more residual than the tolerance allows, instead of costing a sweep.
    pub(crate) fn converged(
        &mut self,
        s: &SolverSettings,
        k: usize,
        quad: f64,
        residual: impl FnOnce(f64) -> Option<f64>,
    ) -> bool {
        if !k.is_multiple_of(s.check_every) && k != s.max_iterations {
            return false;
        }
        let last = k == s.max_iterations;
        // Whether the residual is within `bound`.
        let within = |bound: f64| {
            let r = residual(bound);
            self.last = r.map(|r| (k, r));
            r.is_some_and(|r| r <= bound)
        };
        match s.norm {
            ConvergenceNorm::Quad => {
                if quad > s.tolerance {
                    return false;
                }
                if s.residual_tolerance == f64::INFINITY {
                    return true;
                }
                if k < self.next_residual_check && !last {
                    return false;
                }
                let ok = within(s.residual_tolerance);
                if !ok {
                    self.next_residual_check = k + (k / 4).max(1);
                }
                ok
            }
            ConvergenceNorm::NaturalMap => {
                // The residual costs a pass over the contacts: evaluate it once the sweeps'
                // change is as small as the tolerance, else every quarter more sweeps.
                if quad > s.tolerance && k < self.next_residual_check && !last {
                    return false;
                }
                let ok = within(s.tolerance.min(s.residual_tolerance));
                if !ok {
                    self.next_residual_check = k + (k / 4).max(1);
                }
                ok
            }
        }
    }
}

impl SolverSettings {
    /// Checks every field; the error names it, with the value and what is allowed.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(ScenarioError(format!(
                "solver.tolerance = {} must be > 0",
                self.tolerance
            )));
        }
        if self.max_iterations == 0 {
            return Err("solver.max_iterations = 0 must be ≥ 1".into());
        }
        if !(self.relaxation > 0.0 && self.relaxation <= 1.0) {
            return Err(ScenarioError(format!(
                "solver.relaxation = {} must be in (0, 1]",
                self.relaxation
            )));
        }
        if self.check_every == 0 {
            return Err("solver.check_every = 0 must be ≥ 1".into());
        }
        if !(self.skip.is_finite() && self.skip >= 0.0) {
            return Err(ScenarioError(format!(
                "solver.skip = {} must be a finite number ≥ 0 (0: every contact every sweep)",
                self.skip
            )));
        }
        if self.residual_tolerance.is_nan() || self.residual_tolerance <= 0.0 {
            return Err(ScenarioError(format!(
                "solver.residual_tolerance = {} must be > 0 (inf: the stop norm alone decides)",
                self.residual_tolerance
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual that may stop early (`None` past the bound) gives the stop rule the same
    /// decisions, at the same iterations, and the same final residual as the full one.
    #[test]
    fn bounded_residual_checks_decide_as_full_ones() {
        // A residual that falls, stalls above the tolerance, then passes it.
        let residual_at = |k: usize| 0.5 / k as f64 + if k < 60 { 2e-3 } else { 0.0 };
        for norm in [ConvergenceNorm::Quad, ConvergenceNorm::NaturalMap] {
            let s = SolverSettings {
                tolerance: 1e-3,
                max_iterations: 1000,
                norm,
                ..Default::default()
            };
            let (mut full, mut bounded) = (StopRule::new(), StopRule::new());
            let (mut calls, mut stops) = (0, None);
            for k in 1..=s.max_iterations {
                // A Quad norm below the tolerance from iteration 20 on.
                let quad = if k < 20 { 1.0 } else { 1e-4 };
                let a = full.converged(&s, k, quad, |_| Some(residual_at(k)));
                let b = bounded.converged(&s, k, quad, |bound| {
                    calls += 1;
                    let r = residual_at(k);
                    (r <= bound).then_some(r)
                });
                assert_eq!(a, b, "{norm:?}, iteration {k}");
                if a {
                    stops = Some(k);
                    break;
                }
            }
            let k = stops.expect("the residual passes the tolerance");
            assert!((500..=600).contains(&k), "{norm:?}: stopped at {k}");
            assert!(calls > 1);
            assert_eq!(
                full.final_residual(k, || unreachable!()),
                bounded.final_residual(k, || unreachable!())
            );
            // A check that stopped early is evaluated again in full at the end.
            let mut early = StopRule::new();
            assert!(!early.converged(&s, 1, 1e-4, |_| None));
            assert_eq!(early.final_residual(1, || 0.25), 0.25);
        }
    }

    /// The bound on the partial sums proves `√sum / q > bound` with room for rounding.
    #[test]
    fn exceeding_sum_is_past_the_bound() {
        for (bound, q) in [(1e-3, 2.5), (1e-3, 1e-7), (0.7, 3e4)] {
            let limit = exceeding_sum(bound, q);
            assert!(limit.sqrt() / q > bound);
            assert!(limit <= (bound * q).powi(2) * (1.0 + 1e-8));
        }
        assert_eq!(exceeding_sum(f64::INFINITY, 1.0), f64::INFINITY);
    }
}
