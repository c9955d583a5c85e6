//! The elastic deflection of a compliant contact point, linear or hyperbolic in its force.
//!
//! The compliant law (see [`crate::solver::Nlgs`]) is written in rate form with a tangent
//! stiffness `k_α`: over a step the normal force changes by `k_α h uₙ`. With a constant
//! `k_α = k` the elastic deflection under a force `F` is `F/k`. With a maximum closure `V_m`
//! the point follows the hyperbolic closure law of rock joints (Bandis, Lumsden & Barton,
//! Int. J. Rock Mech. Min. Sci. 20, 1983; Goodman's hyperbola),
//!
//! ```text
//! F(δ) = k δ / (1 − δ/V_m),   δ(F) = F V_m / (k V_m + F),   k_α(F) = k (1 + F/(k V_m))²,
//! ```
//!
//! soft (`k`) under light loads, stiffening without bound as the closure nears `V_m`: a
//! packing's light contacts keep the compliance that makes Gauss-Seidel converge, and a
//! contact carrying kilonewtons (a grain under a tine) overlaps by less than `V_m`.
//! Over a step the force goes from `F₀ = r̄ₙ/h` to `F₁ = rₙ/h`, and the hyperbola's exact
//! secant stiffness between them is `k f(F₀) f(F₁)` with `f(F) = 1 + F/(k V_m)`:
//! `δ(F₁) − δ(F₀) = (F₁ − F₀)/(k f(F₀) f(F₁))`. The local problem keeps its form
//! (`W_nn + 1/(k_α h²)`) with `k_α` that secant at the current iterate `rₙ`, so Gauss-Seidel's
//! fixed point integrates the law exactly whatever the step (a tangent taken at `F₀` alone
//! deflects a contact loaded within one step by the linear law's `F/k`). The tangential
//! stiffness is scaled by the same factor (a stiffer contact is stiffer in both directions,
//! as Mindlin's is with Hertz's).

/// A contact point's elastic deflection as a function of the normal impulse `r̄ₙ` it carried
/// over the previous step (the force times `h`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Elastic {
    /// `1/(k h)`: the deflection per unit of normal impulse at the initial stiffness (0: rigid
    /// contacts, or the law does not own the deflection).
    pub per_impulse: f64,
    /// `k h V_m`: the normal impulse at which the tangent stiffness has grown fourfold
    /// (0: linear law).
    pub closure_impulse: f64,
}

impl Elastic {
    /// No elastic deflection (rigid contacts).
    pub const NONE: Self = Self {
        per_impulse: 0.0,
        closure_impulse: 0.0,
    };

    /// `f = 1 + r̄ₙ/(k h V_m)` (1 for the linear law): the tangent stiffness is `k f²`, and
    /// the deflection `r̄ₙ/(k h f)`.
    #[inline(always)]
    pub fn stiffening(&self, r_prev: f64) -> f64 {
        if self.closure_impulse > 0.0 {
            1.0 + r_prev.max(0.0) / self.closure_impulse
        } else {
            1.0
        }
    }

    /// The secant stiffness between the impulses `r0` and `r1`, as a multiple of `k`:
    /// `f(r0) f(r1)` (1 for the linear law).
    #[inline(always)]
    pub fn secant(&self, r0: f64, r1: f64) -> f64 {
        self.stiffening(r0) * self.stiffening(r1)
    }

    /// The elastic deflection (m) under the normal impulse `r̄ₙ` (negative impulses: 0).
    #[inline(always)]
    pub fn deflection(&self, r_prev: f64) -> f64 {
        let r = r_prev.max(0.0);
        if self.closure_impulse > 0.0 {
            self.per_impulse * r / (1.0 + r / self.closure_impulse)
        } else {
            self.per_impulse * r
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The deflection never reaches `V_m`, grows with the force, and matches the
        /// hyperbola's tangent stiffness: `dF/dδ = k (1 + F/(k V_m))²`.
        #[test]
        fn the_hyperbola_stays_below_the_maximum_closure(
            k in 1e4f64..1e9,
            h in 1e-5f64..1e-3,
            vm in 1e-5f64..1e-2,
            f in 0.0f64..1e5,
        ) {
            let e = Elastic { per_impulse: 1.0 / (k * h), closure_impulse: k * h * vm };
            let d = e.deflection(f * h);
            prop_assert!(d >= 0.0 && d < vm);
            prop_assert!(d <= f / k * (1.0 + 1e-12));
            let df = 1e-6 * (f + 1.0);
            let slope = df / (e.deflection((f + df) * h) - d);
            let s = e.stiffening(f * h);
            prop_assert!((slope / (k * s * s) - 1.0).abs() < 1e-4, "{slope} vs {}", k * s * s);
        }

        /// The secant stiffness is exact: `δ(F₁) − δ(F₀) = (F₁ − F₀)/(k f(F₀) f(F₁))`.
        #[test]
        fn the_secant_integrates_the_hyperbola(
            k in 1e4f64..1e9,
            h in 1e-5f64..1e-3,
            vm in 1e-5f64..1e-2,
            f0 in 0.0f64..1e5,
            f1 in 0.0f64..1e5,
        ) {
            let e = Elastic { per_impulse: 1.0 / (k * h), closure_impulse: k * h * vm };
            let exact = e.deflection(f1 * h) - e.deflection(f0 * h);
            let secant = (f1 - f0) / (k * e.secant(f0 * h, f1 * h));
            prop_assert!((exact - secant).abs() <= 1e-9 * vm, "{exact} vs {secant}");
        }
    }

    /// The linear law: `F/k`, stiffening 1; rigid contacts: no deflection.
    #[test]
    fn the_linear_law_deflects_by_f_over_k() {
        let (k, h) = (1e7, 2e-4);
        let e = Elastic {
            per_impulse: 1.0 / (k * h),
            closure_impulse: 0.0,
        };
        assert_eq!(e.stiffening(5.0), 1.0);
        assert!((e.deflection(1000.0 * h) - 1e-4).abs() < 1e-16);
        assert_eq!(e.deflection(-1.0), 0.0);
        assert_eq!(Elastic::NONE.deflection(3.0), 0.0);
    }
}
