//! Post-stabilisation of overlaps (split impulse): a position-only correction.
//!
//! Velocity-level Signorini (`uₙ ≥ 0` on closed contacts) stops bodies from approaching but
//! never undoes an overlap made at an impact (the θ-scheme lets a point arriving at `v` overlap
//! by up to `h (1 − θ) v`), so overlaps accumulate over repeated impacts. After the velocity
//! solve, this step finds *pseudo-velocities* `Ṽ = M⁻¹ Hₙ p` with frictionless normal impulses
//! `p ≥ 0` such that `0 ≤ p_α ⊥ ũₙ,α − b_α ≥ 0`, with the target separation speed
//! `b_α = β max(0, −g_α − slop) / h`, by projected Gauss-Seidel sweeps in contact order. The
//! positions move by `h Ṽ`; the velocities are untouched, so no kinetic energy is injected.
//! β = 0 switches it off (plain Moreau-Jean, as LMGC90).

use super::delassus::{LocalProblem, SolverBody};
use crate::math::DVec3;
use serde::{Deserialize, Serialize};

/// Settings of the overlap correction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CorrectionSettings {
    /// Fraction β ∈ [0, 1] of the overlap (beyond `slop`) removed per step; 0 = off.
    pub fraction: f64,
    /// Overlap tolerated without correction (m).
    pub slop: f64,
    /// Gauss-Seidel sweeps of the pseudo-velocity problem.
    pub sweeps: usize,
}

impl Default for CorrectionSettings {
    fn default() -> Self {
        Self {
            fraction: 0.2,
            slop: 1e-5,
            sweeps: 10,
        }
    }
}

impl CorrectionSettings {
    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<(), String> {
        if !(0.0..=1.0).contains(&self.fraction) {
            return Err(format!(
                "correction.fraction = {} must be in [0, 1]",
                self.fraction
            ));
        }
        if !(self.slop.is_finite() && self.slop >= 0.0) {
            return Err(format!("correction.slop = {} must be ≥ 0 m", self.slop));
        }
        Ok(())
    }
}

/// Computes the pseudo-velocities in `pseudo` (one per body, zero-initialised here; inverse
/// masses copied from `bodies`) for the overlapping contacts among `locals`.
pub fn pseudo_velocities(
    settings: &CorrectionSettings,
    h: f64,
    locals: &[LocalProblem],
    bodies: &[SolverBody],
    pseudo: &mut Vec<SolverBody>,
) -> bool {
    pseudo.clear();
    pseudo.extend(bodies.iter().map(|b| SolverBody {
        v: DVec3::ZERO,
        w: DVec3::ZERO,
        ..*b
    }));
    if settings.fraction == 0.0 {
        return false;
    }
    let active: Vec<(usize, f64)> = locals
        .iter()
        .enumerate()
        .filter(|(_, c)| c.gap < -settings.slop)
        .map(|(k, c)| (k, settings.fraction * (-c.gap - settings.slop) / h))
        .collect();
    if active.is_empty() {
        return false;
    }
    let mut p = vec![0.0; active.len()];
    for _ in 0..settings.sweeps {
        for (&(k, target), pk) in active.iter().zip(p.iter_mut()) {
            let c = &locals[k];
            let un = c.velocity(pseudo.as_slice()).x;
            let new = (*pk + (target - un) / c.w.x_axis.x).max(0.0);
            let dp = new - *pk;
            if dp != 0.0 {
                c.apply(pseudo.as_mut_slice(), DVec3::new(dp, 0.0, 0.0));
                *pk = new;
            }
        }
    }
    true
}
