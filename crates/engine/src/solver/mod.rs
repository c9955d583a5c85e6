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

pub mod correction;
pub mod ddm;
pub mod delassus;
pub mod drive;
pub mod nlgs;
pub mod partition;

pub use correction::CorrectionSettings;
pub use ddm::DdmSettings;
pub use delassus::{LocalProblem, SolverBody};
pub use drive::DriveRows;
pub use nlgs::{Nlgs, SolveReport};
pub use partition::{Balance, Partition};

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
    /// and velocities are consistent in units:
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
        }
    }
}

impl SolverSettings {
    /// Checks every field; the error names it, with the value and what is allowed.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(format!("solver.tolerance = {} must be > 0", self.tolerance));
        }
        if self.max_iterations == 0 {
            return Err("solver.max_iterations = 0 must be ≥ 1".into());
        }
        if !(self.relaxation > 0.0 && self.relaxation <= 1.0) {
            return Err(format!(
                "solver.relaxation = {} must be in (0, 1]",
                self.relaxation
            ));
        }
        if self.check_every == 0 {
            return Err("solver.check_every = 0 must be ≥ 1".into());
        }
        Ok(())
    }
}
