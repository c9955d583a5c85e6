//! Force-limited drives as rows of the Gauss-Seidel sweep.
//!
//! Mathematics. A force-limited driven body B (see [`crate::bodies::driver`]) has, per free
//! degree of freedom d (a world axis of its translation, or of its rotation), one scalar
//! unknown: the drive's impulse λ_d over the step. With `e_d` the unit vector of d, the
//! velocity it acts on is `u_d = e_d · V_B` (or `e_d · ω_B`), the target `c_d` is the
//! program's velocity plus the superposed one at the end of the step, and the bound is
//! `b_d = F_d h` (a force limit times the step). The row is a box-constrained bilateral
//! constraint,
//!
//! ```text
//! λ_d = proj_[−b_d, b_d] (λ_d − ρ_d (u_d − c_d)),   ρ_d = 1 / (e_d · M_B⁻¹ e_d),
//! ```
//!
//! which the sweep solves exactly for one row with the others fixed:
//! `λ_d ← clamp(λ_d + ρ_d (c_d − u_d), −b_d, b_d)`, then `V_B += M_B⁻¹ e_d Δλ_d`. Translation
//! rows are independent of each other (`M⁻¹ = m⁻¹ 1`), so an unlimited translation row meets
//! its target exactly after each pass; rotation rows are coupled through `I_w⁻¹` and converge
//! over the sweeps like the contacts. The rows are swept after the contacts of each
//! iteration, and enter the Quad norm (`‖W Δλ‖`, `‖W λ‖` with `W = ρ⁻¹`) and the natural-map
//! residual (`(λ − proj(λ − ρ (u − c))) / ρ`, in m/s or rad/s) like the contacts. Drives are
//! not warm-started: λ starts at 0 each step, and the contacts' warm start already carries the
//! load the drive took last step.

use super::delassus::BodyAccess;
use super::nlgs::SweepSums;
use crate::math::DVec3;

/// The rows of one force-limited driven body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveRows {
    /// The body (solver numbering of the caller).
    pub body: u32,
    /// Target linear velocity at the end of the step (program + superposed).
    pub target_v: DVec3,
    /// Target angular velocity.
    pub target_w: DVec3,
    /// Impulse bounds `F h` per translation axis (`inf`: unlimited).
    pub bound_v: DVec3,
    /// Impulse bounds `T h` per rotation axis.
    pub bound_w: DVec3,
    /// Drive impulse on the translation (N·s).
    pub impulse_v: DVec3,
    /// Drive angular impulse (N·m·s).
    pub impulse_w: DVec3,
    /// Whether the translation (rotation) is solved here; otherwise it is imposed and the
    /// body's solver inverse mass (inertia) is zero.
    pub translate: bool,
    pub rotate: bool,
}

impl DriveRows {
    /// One Gauss-Seidel pass over the rows of this body.
    #[inline]
    pub fn update<B: BodyAccess + ?Sized>(&mut self, v: &mut B, sums: &mut SweepSums) {
        let b = v.body_mut(self.body);
        // Every pass writes the velocities (if only by adding zero).
        b.version = b.version.wrapping_add(1);
        if self.translate {
            let m_inv = b.inv_mass;
            for d in 0..3 {
                let lam = self.impulse_v[d];
                let new = (lam + (self.target_v[d] - b.v[d]) / m_inv)
                    .clamp(-self.bound_v[d], self.bound_v[d]);
                let dl = new - lam;
                b.v[d] += dl * m_inv;
                if dl != 0.0 {
                    b.epoch = b.epoch.wrapping_add(1);
                }
                self.impulse_v[d] = new;
                sums.dwr2 += (dl * m_inv).powi(2);
                sums.wr2 += (new * m_inv).powi(2);
            }
        }
        if self.rotate {
            let ii = b.inv_inertia;
            for d in 0..3 {
                let col = ii.col(d);
                let lam = self.impulse_w[d];
                let new = (lam + (self.target_w[d] - b.w[d]) / col[d])
                    .clamp(-self.bound_w[d], self.bound_w[d]);
                let dl = new - lam;
                b.w += col * dl;
                if dl != 0.0 {
                    b.epoch = b.epoch.wrapping_add(1);
                }
                self.impulse_w[d] = new;
                sums.dwr2 += (col * dl).length_squared();
                sums.wr2 += (col * new).length_squared();
            }
        }
    }

    /// `Σ_d residual_d²` of this body's rows at the current state (m²/s², rad²/s²).
    pub(crate) fn residual2<B: BodyAccess + ?Sized>(&self, v: &B) -> f64 {
        let b = v.body(self.body);
        let row = |lam: f64, w: f64, u: f64, bound: f64| {
            // ρ = 1/w: (λ − proj(λ − ρ u)) / ρ = w λ − w proj(λ − u / w).
            (w * lam - w * (lam - u / w).clamp(-bound, bound)).powi(2)
        };
        let mut s = 0.0;
        if self.translate {
            for d in 0..3 {
                let u = b.v[d] - self.target_v[d];
                s += row(self.impulse_v[d], b.inv_mass, u, self.bound_v[d]);
            }
        }
        if self.rotate {
            for d in 0..3 {
                let u = b.w[d] - self.target_w[d];
                s += row(
                    self.impulse_w[d],
                    b.inv_inertia.col(d)[d],
                    u,
                    self.bound_w[d],
                );
            }
        }
        s
    }

    /// `Σ_d (u_d − c_d)²` on the free velocities: this body's share of the residual's scale.
    pub(crate) fn scale2<B: BodyAccess + ?Sized>(&self, v: &B) -> f64 {
        let b = v.body(self.body);
        let mut s = 0.0;
        if self.translate {
            s += (b.v - self.target_v).length_squared();
        }
        if self.rotate {
            s += (b.w - self.target_w).length_squared();
        }
        s
    }

    /// Drive force (N) and torque (N·m): the impulses over the step `h`.
    pub fn force(&self, h: f64) -> (DVec3, DVec3) {
        (self.impulse_v / h, self.impulse_w / h)
    }
}

/// One pass over every drive, in order.
pub fn sweep<B: BodyAccess + ?Sized>(drives: &mut [DriveRows], v: &mut B) -> SweepSums {
    let mut sums = SweepSums::default();
    for d in drives {
        d.update(v, &mut sums);
    }
    sums
}

/// `Σ residual²` over the drives.
pub(crate) fn residual_sum<B: BodyAccess + ?Sized>(drives: &[DriveRows], v: &B) -> f64 {
    drives.iter().map(|d| d.residual2(v)).sum()
}

/// `Σ scale²` over the drives.
pub fn scale_sum<B: BodyAccess + ?Sized>(drives: &[DriveRows], v: &B) -> f64 {
    drives.iter().map(|d| d.scale2(v)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::DMat3;
    use crate::solver::SolverBody;

    /// A pass writes its body's velocities and moves its version, so that a contact's
    /// residual term computed before the pass is not read back after it
    /// (see [`crate::solver::SolverSettings::reuse_residual_terms`]).
    #[test]
    fn a_pass_moves_the_bodys_version() {
        let mut bodies = [SolverBody {
            v: DVec3::new(0.2, 0.0, 0.0),
            w: DVec3::ZERO,
            inv_mass: 0.5,
            inv_inertia: DMat3::IDENTITY,
            epoch: 0,
            drift: 0.0,
            version: 7,
        }];
        let mut d = DriveRows {
            body: 0,
            target_v: DVec3::new(0.5, 0.0, 0.0),
            target_w: DVec3::ZERO,
            bound_v: DVec3::splat(f64::INFINITY),
            bound_w: DVec3::ZERO,
            impulse_v: DVec3::ZERO,
            impulse_w: DVec3::ZERO,
            translate: true,
            rotate: false,
        };
        sweep(std::slice::from_mut(&mut d), &mut bodies[..]);
        assert_eq!(bodies[0].v.x, 0.5);
        assert_ne!(bodies[0].version, 7);
    }
}
