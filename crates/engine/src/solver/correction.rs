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

use super::delassus::{BodyAccess, LocalProblem, SolverBody};
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

/// An overlapping contact of the pseudo-velocity problem.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Overlap {
    /// Index of the contact among the local problems it was found in.
    pub k: u32,
    /// Target separation speed `b_α` (m/s).
    pub target: f64,
    /// Pseudo normal impulse `p_α ≥ 0`.
    pub p: f64,
}

/// A body's solver copy with zero velocities (its inverse masses kept).
pub fn at_rest(b: &SolverBody) -> SolverBody {
    SolverBody {
        v: DVec3::ZERO,
        w: DVec3::ZERO,
        ..*b
    }
}

/// Lists in `out` the contacts of `locals` overlapping beyond the slop, in order, with
/// `p = 0`; returns how many. None when the correction is off.
pub fn overlaps(
    settings: &CorrectionSettings,
    h: f64,
    locals: &[LocalProblem],
    out: &mut Vec<Overlap>,
) -> usize {
    out.clear();
    if settings.fraction == 0.0 {
        return 0;
    }
    out.extend(
        locals
            .iter()
            .enumerate()
            .filter(|(_, c)| c.gap < -settings.slop)
            .map(|(k, c)| Overlap {
                k: k as u32,
                target: settings.fraction * (-c.gap - settings.slop) / h,
                p: 0.0,
            }),
    );
    out.len()
}

/// One projected Gauss-Seidel sweep over `rows` (in order):
/// `p_α ← max(0, p_α + (b_α − ũₙ,α) / W_α,nn)`, the pseudo-velocities updated at once.
pub fn sweep<B: BodyAccess + ?Sized>(
    locals: &[LocalProblem],
    rows: &mut [Overlap],
    pseudo: &mut B,
) {
    for row in rows {
        let c = &locals[row.k as usize];
        let un = c.velocity(pseudo).x;
        let new = (row.p + (row.target - un) / c.w.x_axis.x).max(0.0);
        let dp = new - row.p;
        if dp != 0.0 {
            c.apply(pseudo, DVec3::new(dp, 0.0, 0.0));
            row.p = new;
        }
    }
}

/// Computes the pseudo-velocities in `pseudo` (one per body, zero-initialised here; inverse
/// masses copied from `bodies`) for the overlapping contacts among `locals`, by
/// `settings.sweeps` sweeps in contact order. Returns whether any contact overlapped.
pub fn pseudo_velocities(
    settings: &CorrectionSettings,
    h: f64,
    locals: &[LocalProblem],
    bodies: &[SolverBody],
    pseudo: &mut Vec<SolverBody>,
) -> bool {
    pseudo.clear();
    pseudo.extend(bodies.iter().map(at_rest));
    let mut rows = Vec::new();
    if overlaps(settings, h, locals, &mut rows) == 0 {
        return false;
    }
    for _ in 0..settings.sweeps {
        sweep(locals, &mut rows, pseudo.as_mut_slice());
    }
    true
}
