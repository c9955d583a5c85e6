//! The normal law of compliant contacts: a spring and a dashpot in parallel (Kelvin-Voigt),
//! on the overlap the Moreau-Jean step predicts.
//!
//! With the stiffness `k` (N/m per contact point), the damping ratio `ζ` and the contact's
//! effective mass `m = 1/W_nn`, the force over the step is that of the predicted overlap
//! `δ⁺ = −(g + hθ uₙ)` and the approach speed, `λ = k δ⁺ − d uₙ` with `d = 2ζ √(k m)`, and
//! the contact only pushes. With the impulse `rₙ = h λ`:
//!
//! ```text
//! 0 ≤ rₙ  ⊥  uₙ + s g + c rₙ ≥ 0,    c = 1 / (h (h k θ + d)),    s = k h c   (g ≤ 0)
//! ```
//!
//! the rigid law's local problem with `W_nn + c` and the gap shift `s g` on an overlap (a
//! positive gap keeps the rigid law's shift `g/(hθ)`: the spring engages at contact). A static
//! load `F` deflects a contact by `F/k`. The force follows the overlap itself: a law on the
//! change of force from the previous step's impulse restarts at zero on every contact point
//! that is not found again (a manifold's points move over a face) and lets the bodies approach
//! by `F/k` per step, an overlap that ratchets without bound. The dashpot takes out the energy
//! the spring would return: with `θ = 1/2` the scheme conserves a spring's energy, so an
//! undamped stiff contact rattles; `ζ = 1` (critical) leaves an impact without rebound, like
//! the rigid law's restitution 0.

use serde::{Deserialize, Serialize};

/// Parameters of the compliant normal law for one time step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ElasticNormal {
    /// Stiffness `k` (N/m per contact point).
    pub stiffness: f64,
    /// Damping ratio `ζ` (1: critical).
    pub damping: f64,
    /// Time step `h` (s).
    pub h: f64,
    /// Moreau-Jean's `θ`.
    pub theta: f64,
}

impl ElasticNormal {
    /// The compliance `c` of a contact whose Delassus normal entry is `w_nn` (its effective
    /// mass is `1/w_nn`).
    #[inline]
    pub fn compliance(&self, w_nn: f64) -> f64 {
        let d = 2.0 * self.damping * (self.stiffness / w_nn).sqrt();
        1.0 / (self.h * (self.h * self.stiffness * self.theta + d))
    }

    /// `k h`: the shift of an overlap `g < 0` is `k h c g`.
    #[inline]
    pub fn overlap_factor(&self) -> f64 {
        self.stiffness * self.h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without damping the law is the spring's, `c = 1/(k h² θ)`; a dashpot makes the contact
    /// stiffer over the step (a smaller `c`), the more so for a heavier contact.
    #[test]
    fn compliance_of_spring_and_dashpot() {
        let law = |damping| ElasticNormal {
            stiffness: 1e7,
            damping,
            h: 1e-4,
            theta: 0.55,
        };
        let c = law(0.0).compliance(12.0);
        assert!((c - 1.0 / (1e7 * 1e-8 * 0.55)).abs() < 1e-12 * c);
        assert!(law(1.0).compliance(12.0) < c);
        assert!(law(1.0).compliance(1.0) < law(1.0).compliance(12.0));
    }

    /// A contact of effective mass `m` hit at speed `v` (free velocity `uₙ = −v` at zero
    /// overlap) takes the impulse of a spring and a dashpot: `rₙ = h (k hθ + d) v / (1 + …)`,
    /// checked against the law's complementarity `uₙ + c rₙ = 0` with `uₙ = −v + rₙ/m`.
    #[test]
    fn impact_impulse_solves_the_law() {
        let law = ElasticNormal {
            stiffness: 1e7,
            damping: 1.0,
            h: 1e-4,
            theta: 0.5,
        };
        let (m, v) = (0.05, 1.0);
        let c = law.compliance(1.0 / m);
        let r = v / (1.0 / m + c);
        let u = -v + r / m;
        let d = 2.0 * (1e7 * m).sqrt();
        // The force is the spring on the predicted overlap and the dashpot on the approach.
        let lambda = 1e7 * (-(law.h * law.theta * u)) - d * u;
        assert!(
            (r / law.h - lambda).abs() < 1e-9 * lambda,
            "{} vs {lambda}",
            r / law.h
        );
    }
}
