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

/// Where a compliant contact's normal force starts each step from.
///
/// Over a step the law adds `k_α` times the approach `−h uₙ` to a starting force `F₀`:
///
/// - [`NormalLaw::Rate`]: `F₀` is the force the same contact point carried at the end of the
///   previous step (the rate form; a new point starts from 0). Nothing ties the overlap to
///   that force, and where manifold points churn or a polyhedral depth jumps the overlap
///   drifts away from the deflection the force implies.
/// - [`NormalLaw::Overlap`]: `F₀ = F(min(δ, δ_cap))`, the force the overlap `δ` measured at
///   the start of the step holds elastically (`F(δ) = k δ/(1 − δ/V_m)`, or `k δ`), whatever
///   the point carried before: the force follows the geometry (a spring on the overlap,
///   integrated by backward Euler: `F₁ = F(δ − h uₙ)`). `δ_cap` bounds the force a step
///   starts from: a polyhedral depth that jumps deep (the closest features change) is not
///   turned into a force near the hyperbola's asymptote; the overlap beyond it is left to the
///   overlap recovery and the position correction, as the rate form's drift is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalLaw {
    /// The rate form: the force the contact point carried.
    #[default]
    Rate,
    /// The force the measured overlap holds (up to the cap).
    Overlap,
}

impl NormalLaw {
    /// Whether this is the rate form (the default, left out of serialised settings).
    pub fn is_rate(&self) -> bool {
        *self == Self::Rate
    }
}

/// The default overlap cap `δ_cap` of [`NormalLaw::Overlap`] (m): 0.8 `V_m` with the closure
/// law (a starting force of `4 k V_m`, where the tangent stiffness is 25 `k`), 1 mm (the
/// overlap a trusted run stays under) with the linear law. On the soft tamping cycle a cap
/// of 0.6 `V_m` let a tine's contact ratchet deep (each step restarting below the load it
/// carries), one of 0.95 `V_m` stalled Gauss-Seidel on stiff springs (BENCHMARKS.md).
pub fn default_overlap_cap(max_closure: Option<f64>) -> f64 {
    max_closure.map_or(1e-3, |vm| 0.8 * vm)
}

/// The overlap cap of a contact with a body that is not dynamic (a wall, a driven block or
/// tine), as a fraction of `V_m`: [`driven_overlap_cap`].
pub const DRIVEN_CAP_FRACTION: f64 = 0.9;

/// The overlap cap of a contact between a grain and a body that is not dynamic, given the cap
/// `cap` of contacts between grains: `max(cap, 0.9 V_m)` with the closure law (a starting force
/// of `9 k V_m`, 6.75 kN with the track defaults), `cap` with the linear law. A tine or a block
/// can press one grain corner harder than the cap's `4 k V_m` (a vibrating tine stopped by a
/// grain put 9 kN on one point), and from a start below its load the point approaches each
/// step until the correction balances it, past 1 mm. Stiffer starts stall Gauss-Seidel on
/// chains of grains (0.95 `V_m`); a grain against a body the solver does not move is no chain,
/// and the tamping cycle's sweeps rose by 3 % where it mattered (BENCHMARKS.md).
pub fn driven_overlap_cap(cap: f64, max_closure: Option<f64>) -> f64 {
    max_closure.map_or(cap, |vm| cap.max(DRIVEN_CAP_FRACTION * vm))
}

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
        // Unloaded: 1 without a division (exactly what `1 + 0 / (k h V_m)` rounds to).
        if self.closure_impulse > 0.0 && r_prev > 0.0 {
            1.0 + r_prev / self.closure_impulse
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

    /// The normal impulse whose elastic deflection is `delta` (m): the inverse of
    /// [`Self::deflection`] (`∞` at and beyond the hyperbola's `V_m`; 0 for `delta ≤ 0`).
    #[inline(always)]
    pub fn impulse_at(&self, delta: f64) -> f64 {
        let d = delta.max(0.0);
        if self.closure_impulse > 0.0 {
            let left = self.per_impulse - d / self.closure_impulse;
            if left > 0.0 {
                d / left
            } else {
                f64::INFINITY
            }
        } else {
            d / self.per_impulse
        }
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

    proptest! {
        /// `impulse_at` inverts `deflection`, linear and hyperbolic: the force the overlap
        /// law starts from deflects the contact by its overlap.
        #[test]
        fn impulse_at_inverts_the_deflection(
            k in 1e4f64..1e9,
            h in 1e-5f64..1e-3,
            vm in 1e-5f64..1e-2,
            f in 0.0f64..1e5,
            linear in proptest::bool::ANY,
        ) {
            let e = Elastic {
                per_impulse: 1.0 / (k * h),
                closure_impulse: if linear { 0.0 } else { k * h * vm },
            };
            let r = f * h;
            let back = e.impulse_at(e.deflection(r));
            prop_assert!((back - r).abs() <= 1e-9 * (r + k * h * vm), "{back} vs {r}");
        }
    }

    /// Beyond the hyperbola's asymptote no force holds the overlap; none holds a gap.
    #[test]
    fn impulse_at_the_asymptote_is_infinite() {
        let (k, h, vm) = (1e6, 1e-4, 1e-3);
        let e = Elastic {
            per_impulse: 1.0 / (k * h),
            closure_impulse: k * h * vm,
        };
        assert_eq!(e.impulse_at(vm), f64::INFINITY);
        assert_eq!(e.impulse_at(2.0 * vm), f64::INFINITY);
        assert_eq!(e.impulse_at(-1e-3), 0.0);
        // The default cap, 0.8 V_m, holds 4 k V_m.
        let f = e.impulse_at(default_overlap_cap(Some(vm))) / h;
        assert!((f - 4.0 * k * vm).abs() <= 1e-9 * f, "{f}");
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
