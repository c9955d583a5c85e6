//! Exact solution of the local Signorini-Coulomb problem of one contact.
//!
//! # The law
//!
//! In the contact frame `(n, t, s)` (vector component `x` is the normal, `y` and `z` span the
//! tangent plane) the relative velocity at the end of the step is affine in the contact impulse:
//!
//! ```text
//! u = q + W r,        q = u_free,   W = W_αα  (3×3 Delassus block, symmetric positive definite)
//! ```
//!
//! and the Signorini-Coulomb law with restitution 0 reads
//!
//! ```text
//! 0 ≤ uₙ ⊥ rₙ ≥ 0,      ‖r_t‖ ≤ μ rₙ,      ‖u_t‖ > 0  ⇒  r_t = −μ rₙ u_t / ‖u_t‖.
//! ```
//!
//! With the Coulomb cone `K = {‖r_t‖ ≤ μ rₙ}`, its dual `K* = {μ‖u_t‖ ≤ uₙ}` and De Saxcé's
//! modified velocity `û = u + μ‖u_t‖ eₙ`, the law is the second-order cone complementarity
//! `K ∋ r ⊥ û ∈ K*`, equivalently the fixed point `r = P_K(r − û)` of the natural map;
//! [`natural_map_residual`] measures its violation and [`project_on_cone`] is `P_K` in closed form.
//!
//! # The three cases
//!
//! 1. **No contact**, `qₙ ≥ 0`: `r = 0` satisfies the law (`u = q`). With strong normal-tangent
//!    coupling other solutions may exist; the inactive one is the one a time-stepper wants.
//! 2. **Stick**, `u = 0`: `r = −W⁻¹q`, accepted when `rₙ > 0` and `‖r_t‖ ≤ μ rₙ`. This is the hot
//!    path (a matrix-vector product and a comparison), using the inverse the caller precomputed.
//! 3. **Slide**, `uₙ = 0`, `r = rₙ (1, μd)`, `u_t = −λd` with `‖d‖ = 1` and `λ ≥ 0`.
//!
//! For `μ = 0` there is no friction to resolve: `rₙ = −qₙ / Wₙₙ`, `r_t = 0`, and the status is
//! [`ContactStatus::Stick`] when the resulting `u_t` vanishes (to rounding), otherwise
//! [`ContactStatus::Slide`].
//!
//! # The slide system
//!
//! Write `W = [[Wₙₙ, w_rᵀ], [w_c, A]]` (`w_r = w_c` for a symmetric `W`; they are kept apart so
//! the two equations below use exactly the entries `u = q + W r` uses) and `a = −qₙ > 0`. Then
//!
//! ```text
//! uₙ  = 0  ⇔  rₙ = a / D(d),          D(d) = Wₙₙ + μ w_r·d,
//! u_t = q_t + rₙ (w_c + μ A d) = v(d) / D(d),   v(d) = D(d) q_t + a (w_c + μ A d).
//! ```
//!
//! With `d = (cos θ, sin θ)` and `d⊥ = (−sin θ, cos θ)`, sliding reduces to one scalar equation
//! and two sign conditions:
//!
//! ```text
//! g(θ) = d⊥·v(d) = 0        (u_t parallel to d),
//! D(θ) > 0                  (rₙ > 0),
//! h(θ) = d·v(d) ≤ 0         (λ = −h/D ≥ 0: u_t opposes d).
//! ```
//!
//! `g` is a trigonometric polynomial of degree 2, `K₀ + K₁c cos θ + K₁s sin θ + K₂c cos 2θ +
//! K₂s sin 2θ` (a quartic in `tan θ/2`), so it has at most four roots on the circle. Without
//! coupling (`w = 0`), `D = Wₙₙ` is constant and `g = φ'` for `φ(d) = Wₙₙ q_t·d + ½ aμ dᵀAd`:
//! the sliding direction minimises `φ` on the unit circle. That is a 2-D trust-region problem,
//! `(aμ A + λ'I) d = −Wₙₙ q_t` with the unique root `λ' ≥ 0` of the secular equation
//! `‖(aμ A + λ'I)⁻¹ Wₙₙ q_t‖ = 1` (it exists and is positive exactly when stick fails).
//! Coupling (`w ≠ 0`, lever arms) makes `rₙ` depend on `d` and breaks the variational structure.
//!
//! # How it is solved
//!
//! 0. *Warm start* ([`solve_local_from`]). In a Gauss-Seidel sweep a contact's sliding
//!    direction changes little from one sweep to the next: when its previous impulse slid, the
//!    correction (step 2) is tried from that direction first (3 % off the whole step over
//!    the first 500 steps of the default tamping cycle), and steps 1–5 follow if it does not
//!    give an admissible root.
//! 1. *Prediction.* With `rₙ` frozen at `a/Wₙₙ` the tangential problem is the trust-region
//!    problem `(μ rₙ A + λI) d = −b`, `b = q_t + w_c rₙ`, `‖d‖ = 1`, `λ ≥ 0` (the first
//!    fixed-point iterate on `rₙ`). Its secular root is estimated in closed form,
//!    `λ₀ = max(0, ‖b‖ − bᵀ(μ rₙ A)b/‖b‖²)`, exact when `b` is an eigenvector of `A` (isotropic
//!    `A` in particular), and `d₀ ∝ −(μ rₙ A + λ₀I)⁻¹ b`. Iterating the secular equation
//!    further (Moré-Sorensen) costs as much per iteration as the correction and only improves
//!    a starting point, so it is not done.
//! 2. *Correction.* Newton's method on `g(θ)` itself, which carries the coupling exactly,
//!    stepping along the tangent: `d ← (d + τd⊥)/‖d + τd⊥‖` with `τ = −g/g'` clamped to
//!    `|τ| ≤ 1`, so no trigonometric function is evaluated. It converges quadratically and stops
//!    when `|τ| ≤ 10⁻⁸` (the error left is of order `τ²`) or `|g|` is at rounding level: two or
//!    three iterations when the coupling is weak.
//! 3. *Acceptance.* The converged root is kept when `D > 0` and `h ≤ 0` (to rounding). Then
//!    `rₙ = a/D(d)` with `D` recomputed at the final `d`, and `r_t = μ rₙ d`, so `uₙ = 0` holds
//!    to rounding by construction.
//! 4. *Second start.* Otherwise Newton restarts from the stick direction `r_t/‖r_t‖` of
//!    `r = −W⁻¹q`: just outside the cone the admissible root lies next to it, with an
//!    inadmissible root close by that the first start may reach first.
//! 5. *Global fallback.* Otherwise every root of `g` on the circle is enumerated, certified by
//!    Taylor bounds at interval midpoints: with `M₂ = ‖K₁‖ + 4‖K₂‖ ≥ |g''|`, an interval of
//!    half-width `ω` around `m` holds no root when `|g(m)| > |g'(m)| ω + ½ M₂ ω²`, at most one
//!    when `|g'(m)| > M₂ ω` (refined by Newton kept inside the bracket when its ends differ in
//!    sign), and is bisected otherwise, down to `10⁻⁷` rad (a double root, kept as one
//!    candidate). When `g` is rounding noise all around (tiny `μ` and `u_t`), every direction is
//!    a root and a few are taken as candidates. Candidates are polished by Newton, and among the
//!    admissible ones the closest to the prediction is returned, which stays on the weakly
//!    coupled branch. In random tests this happens for well under 1% of the slides.
//!
//! # Degenerate case
//!
//! When `μ‖w‖ ≥ Wₙₙ`, `D` changes sign on the circle and several admissible roots (and a stick
//! solution besides) may coexist: the discrete Coulomb problem is then non-unique, which is
//! known for large `μ` and strong coupling (Painlevé-like jamming). Any of them satisfies the
//! law; the order above prefers no contact, then stick, then the sliding branch of the previous
//! direction (warm start), then the predicted one.
//! Should no admissible root be found (near tangencies of `g`, or an ill-posed input such as a
//! `W` that is not positive definite), the solver returns whichever of `P_K(−W⁻¹q)`, the
//! frictionless impulse `(a/Wₙₙ, 0, 0)` and the impulses of the computed roots projected on
//! `K` has the smallest natural-map residual: always an impulse in `K`, labelled
//! [`ContactStatus::Slide`].
//!
//! # Accuracy
//!
//! Stick inherits the accuracy of the caller's `W⁻¹` (about `κ(W) ε`). A sliding impulse
//! satisfies `uₙ = 0` and `r_t ∥ −u_t` to a few rounding errors of the terms of `u = q + W r`,
//! amplified by `Wₙₙ/D = Wₙₙ rₙ/a`: that factor is about 1 unless the coupling nearly cancels
//! `D`, where the solution itself is that sensitive to the data.

use crate::math::{DMat3, DVec3};

/// Which branch of the Signorini-Coulomb law the local solution lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ContactStatus {
    /// `uₙ ≥ 0` without impulse: the contact opens, `r = 0`.
    NoContact,
    /// `u = 0`, `r` inside (or on) the Coulomb cone.
    Stick,
    /// `uₙ = 0`, `r` on the cone boundary, `r_t` opposing `u_t`.
    Slide,
}

impl ContactStatus {
    /// The status as a number (0, 1, 2), as ranks share it.
    pub(crate) fn code(self) -> f64 {
        match self {
            ContactStatus::NoContact => 0.0,
            ContactStatus::Stick => 1.0,
            ContactStatus::Slide => 2.0,
        }
    }

    /// The status of [`ContactStatus::code`] `x`.
    pub(crate) fn from_code(x: f64) -> Self {
        match x as u8 {
            1 => ContactStatus::Stick,
            2 => ContactStatus::Slide,
            _ => ContactStatus::NoContact,
        }
    }
}

/// Solves the local Signorini-Coulomb problem `u = u_free + W r` of one contact exactly.
///
/// `w` is the Delassus block `W_αα` (symmetric positive definite) in the contact frame
/// `(n, t, s)`, `w_inv` its inverse (precomputed by the caller once per step), `u_free` the
/// free relative velocity and `mu` the friction coefficient (negative or NaN reads as 0).
/// Returns the impulse `r` and the branch of the law it lies on. See the module documentation
/// for the method; the result is always finite for finite SPD input and lies in the cone.
#[inline]
pub fn solve_local(w: &DMat3, w_inv: &DMat3, u_free: DVec3, mu: f64) -> (DVec3, ContactStatus) {
    solve_local_from(w, w_inv, u_free, mu, DVec3::ZERO)
}

/// [`solve_local`] with the contact's previous impulse `previous` as a hint: when it slid
/// (on the cone's boundary), Newton on the slide equation starts from its direction, which in
/// a Gauss-Seidel sweep changes little from one sweep to the next (fewer Newton iterations
/// than from the prediction). The answer is a root of the same law; where the law has several
/// sliding solutions it is the one nearest the previous direction.
#[inline]
pub fn solve_local_from(
    w: &DMat3,
    w_inv: &DMat3,
    u_free: DVec3,
    mu: f64,
    previous: DVec3,
) -> (DVec3, ContactStatus) {
    // NaN goes here too: no impulse out of garbage.
    if u_free.x >= 0.0 || u_free.x.is_nan() {
        return (DVec3::ZERO, ContactStatus::NoContact);
    }
    let mu = if mu > 0.0 { mu } else { 0.0 };
    if mu == 0.0 {
        return solve_frictionless(w, u_free);
    }
    let r = -(*w_inv * u_free);
    let bound = mu * r.x;
    if r.x > 0.0 && r.y * r.y + r.z * r.z <= bound * bound {
        return (r, ContactStatus::Stick);
    }
    solve_slide(w, u_free, mu, r, previous)
}

/// The Euclidean projection of `r` on the Coulomb cone `K = {‖r_t‖ ≤ μ rₙ}` (for `μ = 0`, the
/// half-line `{r_t = 0, rₙ ≥ 0}`; negative or NaN `μ` reads as 0).
///
/// Closed form for a second-order cone: `r` itself inside `K`, `0` inside the polar cone
/// `{μ‖r_t‖ ≤ −rₙ}`, otherwise the orthogonal projection on the generator through `r`:
/// `rₙ' = (rₙ + μ‖r_t‖)/(1 + μ²)`, `r_t' = μ rₙ' r_t/‖r_t‖`.
#[inline]
pub fn project_on_cone(r: DVec3, mu: f64) -> DVec3 {
    let mu = if mu > 0.0 { mu } else { 0.0 };
    let t = (r.y * r.y + r.z * r.z).sqrt();
    // `r.x >= 0` matters only for μ = 0, where `t <= 0 * r.x` holds for any sign of r.x.
    if t <= mu * r.x && r.x >= 0.0 {
        return r;
    }
    if mu * t <= -r.x {
        return DVec3::ZERO;
    }
    // Here t > 0: t = 0 falls in one of the two branches above.
    let rn = (r.x + mu * t) / (1.0 + mu * mu);
    let k = mu * rn / t;
    DVec3::new(rn, k * r.y, k * r.z)
}

/// The natural-map residual `‖r − P_K(r − (u + μ‖u_t‖ eₙ))‖` of the Coulomb law (as in
/// Siconos), zero exactly when `(r, u)` satisfies the Signorini-Coulomb law with friction `mu`.
///
/// It has the units of an impulse only when `u` is scaled accordingly: compare it with a scale
/// such as `‖r‖ + ‖W⁻¹‖‖u‖` or `‖r‖ + ‖u‖/‖W‖`.
#[inline]
pub fn natural_map_residual(r: DVec3, u: DVec3, mu: f64) -> f64 {
    let mu = if mu > 0.0 { mu } else { 0.0 };
    let ut = (u.y * u.y + u.z * u.z).sqrt();
    let y = r - DVec3::new(u.x + mu * ut, u.y, u.z);
    (r - project_on_cone(y, mu)).length()
}

/// `μ = 0`: normal impulse only. Requires `u_free.x < 0`.
fn solve_frictionless(w: &DMat3, q: DVec3) -> (DVec3, ContactStatus) {
    let wnn = w.x_axis.x;
    if wnn.is_nan() || wnn <= 0.0 {
        return (DVec3::ZERO, ContactStatus::NoContact);
    }
    let rn = -q.x / wnn;
    let ut_y = q.y + w.x_axis.y * rn;
    let ut_z = q.z + w.x_axis.z * rn;
    // "u_t = 0" up to the rounding of its two terms.
    let scale = q.y.abs() + q.z.abs() + (w.x_axis.y.abs() + w.x_axis.z.abs()) * rn;
    let status = if ut_y.abs() + ut_z.abs() <= 8.0 * f64::EPSILON * scale {
        ContactStatus::Stick
    } else {
        ContactStatus::Slide
    };
    (DVec3::new(rn, 0.0, 0.0), status)
}

/// Newton iterations on θ before giving up on a start.
const MAX_NEWTON: usize = 12;
/// Newton on θ has converged when the last tangent step is below this: the error left is then
/// of the order of its square, at rounding level.
const NEWTON_TOL: f64 = 1e-8;
/// `|g|` below this (relative to the scale of the terms of `v`) is a root to rounding already.
const NEWTON_NOISE: f64 = 2.0 * f64::EPSILON;
/// Rounding allowance of `g`, `g'` and `h`, relative to the scale of the terms of `v`: the
/// tolerance of the sign condition `h ≤ 0` and of the certificates of the global fallback.
const ROUNDING: f64 = 16.0 * f64::EPSILON;
/// Largest `|g|`, relative to the same scale, of an accepted candidate of the global fallback
/// (polished roots are at rounding level; this leaves room for double roots).
const ROOT_TOL: f64 = 256.0 * f64::EPSILON;
/// `g` is rounding noise all around when its coefficients sum below this many allowances.
const NOISE_FACTOR: f64 = 64.0;
/// Intervals of the initial partition of the circle in the global fallback.
const N_START: usize = 8;
/// Intervals narrower than this are not bisected further (a double root or a near pair).
const MIN_HALF_WIDTH: f64 = 1e-7;
/// Unresolved roots closer than this are one cluster.
const CLUSTER_RADIUS: f64 = 64.0 * MIN_HALF_WIDTH;
/// Bound on the work of the global fallback (evaluations of g).
const MAX_EVALS: usize = 4096;
/// Room for the candidates of the global fallback: at most four roots, or the start points
/// when `g` is noise.
const MAX_ROOTS: usize = 8;

/// The slide system of one contact, entries of `W` and `q` unpacked (see the module docs).
#[derive(Clone, Copy)]
struct SlideProblem {
    mu: f64,
    /// `−qₙ > 0`.
    a: f64,
    wnn: f64,
    /// Row `n` of `W` off the diagonal (`W_nt`, `W_ns`): enters `uₙ`.
    wr0: f64,
    wr1: f64,
    /// Column `n` of `W` off the diagonal (`W_tn`, `W_sn`): enters `u_t`.
    wc0: f64,
    wc1: f64,
    /// Tangential block `A = [[a11, a12], [a21, a22]]`.
    a11: f64,
    a12: f64,
    a21: f64,
    a22: f64,
    /// `q_t`.
    p0: f64,
    p1: f64,
}

/// `D`, `g`, `h` and their derivatives `g' = dg/dθ`, `h' = dh/dθ` at one direction.
#[derive(Clone, Copy)]
struct Eval {
    den: f64,
    g: f64,
    h: f64,
    dg: f64,
    dh: f64,
}

impl SlideProblem {
    fn new(w: &DMat3, q: DVec3, mu: f64) -> Self {
        // glam is column-major: W[row][col] = w.<col>_axis.<row>.
        Self {
            mu,
            a: -q.x,
            wnn: w.x_axis.x,
            wr0: w.y_axis.x,
            wr1: w.z_axis.x,
            wc0: w.x_axis.y,
            wc1: w.x_axis.z,
            a11: w.y_axis.y,
            a12: w.z_axis.y,
            a21: w.y_axis.z,
            a22: w.z_axis.z,
            p0: q.y,
            p1: q.z,
        }
    }

    #[inline]
    fn eval(&self, c: f64, s: f64) -> Eval {
        let am = self.a * self.mu;
        let den = self.wnn + self.mu * (self.wr0 * c + self.wr1 * s);
        let v0 = den * self.p0 + self.a * self.wc0 + am * (self.a11 * c + self.a12 * s);
        let v1 = den * self.p1 + self.a * self.wc1 + am * (self.a21 * c + self.a22 * s);
        let g = c * v1 - s * v0;
        let h = c * v0 + s * v1;
        // dv/dθ, with dd/dθ = d⊥ = (−s, c) and dd⊥/dθ = −d.
        let dden = self.mu * (self.wr1 * c - self.wr0 * s);
        let dv0 = dden * self.p0 + am * (self.a12 * c - self.a11 * s);
        let dv1 = dden * self.p1 + am * (self.a22 * c - self.a21 * s);
        Eval {
            den,
            g,
            h,
            dg: c * dv1 - s * dv0 - h,
            dh: g + c * dv0 + s * dv1,
        }
    }

    #[inline]
    fn eval_angle(&self, theta: f64) -> Eval {
        let (s, c) = theta.sin_cos();
        self.eval(c, s)
    }

    /// Magnitude of the terms of `v`: the scale of the rounding errors of `g` and `h`.
    fn scale(&self) -> f64 {
        let p = self.p0.abs() + self.p1.abs();
        (self.wnn.abs() + self.mu * (self.wr0.abs() + self.wr1.abs())) * p
            + self.a * (self.wc0.abs() + self.wc1.abs())
            + self.a * self.mu * (self.a11.abs() + self.a12.abs() + self.a21.abs() + self.a22.abs())
    }

    /// Smallest `D` accepted: below it `rₙ = a/D` is dominated by rounding.
    fn den_min(&self) -> f64 {
        64.0 * f64::EPSILON * (self.wnn.abs() + self.mu * (self.wr0.abs() + self.wr1.abs()))
    }

    /// `[K₀, K₁c, K₁s, K₂c, K₂s]` of `g(θ) = K₀ + K₁c cos θ + K₁s sin θ + K₂c cos 2θ + K₂s sin 2θ`.
    fn coefficients(&self) -> [f64; 5] {
        let (mu, a) = (self.mu, self.a);
        [
            0.5 * mu * (self.wr0 * self.p1 - self.wr1 * self.p0 + a * (self.a21 - self.a12)),
            self.wnn * self.p1 + a * self.wc1,
            -self.wnn * self.p0 - a * self.wc0,
            0.5 * mu * (self.wr0 * self.p1 + self.wr1 * self.p0 + a * (self.a21 + self.a12)),
            0.5 * mu * (self.wr1 * self.p1 - self.wr0 * self.p0 + a * (self.a22 - self.a11)),
        ]
    }

    #[inline]
    fn impulse(&self, c: f64, s: f64) -> DVec3 {
        // D recomputed at the final d so that uₙ = q_n + D rₙ vanishes to rounding.
        let rn = self.a / (self.wnn + self.mu * (self.wr0 * c + self.wr1 * s));
        let rt = self.mu * rn;
        DVec3::new(rn, rt * c, rt * s)
    }

    /// The sign conditions of a root: `rₙ > 0` and `λ ≥ 0` (to rounding).
    #[inline]
    fn admissible(&self, e: &Eval, tol: f64) -> bool {
        e.den > self.den_min() && e.h <= tol
    }

    /// Step 1: a sliding direction predicted with `rₙ` frozen at `a/Wₙₙ`,
    /// `d ∝ −(μ rₙ A + λ₀I)⁻¹ b` with `b = q_t + w_c rₙ` and the closed-form estimate `λ₀` of
    /// the secular root (exact when `b` is an eigenvector of `A`, in particular for isotropic
    /// `A`). `hint` (the stick impulse's tangential part) only serves when `b = 0`.
    fn predict(&self, hint: (f64, f64)) -> (f64, f64) {
        let rn = self.a / self.wnn;
        let b0 = self.p0 + self.wc0 * rn;
        let b1 = self.p1 + self.wc1 * rn;
        let k = self.mu * rn;
        let s11 = k * self.a11;
        let s22 = k * self.a22;
        let s12 = 0.5 * k * (self.a12 + self.a21);
        let bn2 = b0 * b0 + b1 * b1;
        if bn2 == 0.0 {
            return hint;
        }
        // Rayleigh quotient of the (symmetrised) frozen tangential compliance along b.
        let rayleigh = (b0 * (s11 * b0 + s12 * b1) + b1 * (s12 * b0 + s22 * b1)) / bn2;
        let lam = (bn2.sqrt() - rayleigh).max(0.0);
        let m11 = s11 + lam;
        let m22 = s22 + lam;
        // −M⁻¹b up to the positive factor 1/det M (M is SPD): only the direction matters.
        unit_or(s12 * b1 - m22 * b0, s12 * b0 - m11 * b1, hint)
    }

    /// Step 2: Newton on g(θ) along the tangent. `Some((c, s))` when it converged to an
    /// admissible root. `tol` and `noise` are [`ROUNDING`] and [`NEWTON_NOISE`] times
    /// [`Self::scale`] (computed once per solve: a slide may take several starts).
    fn correct(&self, mut c: f64, mut s: f64, tol: f64, noise: f64) -> Option<(f64, f64)> {
        for _ in 0..MAX_NEWTON {
            let e = self.eval(c, s);
            if e.g.abs() <= noise {
                // Already a root to rounding: a step would only move along the noise.
                return self.admissible(&e, tol).then_some((c, s));
            }
            let tau = -e.g / e.dg;
            if !tau.is_finite() {
                return None;
            }
            let tau = tau.clamp(-1.0, 1.0);
            (c, s) = unit_or(c - tau * s, s + tau * c, (c, s));
            if tau.abs() <= NEWTON_TOL {
                // h carried to the final point to first order: its sign decides near λ = 0,
                // where even a step of NEWTON_TOL can flip it.
                let last = Eval {
                    h: e.h + tau * e.dh,
                    ..e
                };
                return self.admissible(&last, tol).then_some((c, s));
            }
        }
        None
    }

    /// Step 5: every root of g on the circle (angles), by certified subdivision.
    fn enumerate_roots(&self, roots: &mut [f64; MAX_ROOTS]) -> usize {
        let k = self.coefficients();
        // |g''| ≤ ‖K₁‖ + 4‖K₂‖ everywhere (each harmonic bounded by its amplitude).
        let m2 = k[1].hypot(k[2]) + 4.0 * k[3].hypot(k[4]);
        // Allowance for the rounding of g and g' evaluated from v.
        let slack = ROUNDING * self.scale();
        let mut n = 0;
        let mut push_root = |theta: f64, radius: f64, roots: &mut [f64; MAX_ROOTS]| {
            let dup = roots[..n]
                .iter()
                .any(|&r| angle_distance(r, theta) <= radius);
            if !dup && n < MAX_ROOTS {
                roots[n] = theta;
                n += 1;
            }
        };

        let step = std::f64::consts::TAU / N_START as f64;
        // g at rounding level all around (tiny μ and u_t): every direction is a root, and
        // subdividing would only chase noise. The start points are the candidates.
        if k.iter().map(|x| x.abs()).sum::<f64>() <= NOISE_FACTOR * slack {
            for (i, root) in roots.iter_mut().enumerate().take(N_START) {
                *root = i as f64 * step;
            }
            return N_START.min(MAX_ROOTS);
        }

        // (a, b, g(a), g(b)), depth-first; the depth is at most log2(2π/N_START/MIN_HALF_WIDTH),
        // about 23, so the stack never holds more than N_START + 23 intervals.
        let mut stack = [(0.0, 0.0, 0.0, 0.0); 64];
        let mut top = 0;
        let mut evals = N_START;
        // Pushed in reverse so the circle is scanned from θ = 0 on.
        let g_start = self.eval(1.0, 0.0).g;
        let mut gb = g_start;
        for i in (0..N_START).rev() {
            let a = i as f64 * step;
            let ga = if i == 0 {
                g_start
            } else {
                self.eval_angle(a).g
            };
            stack[top] = (a, a + step, ga, gb);
            top += 1;
            gb = ga;
        }
        while top > 0 && evals < MAX_EVALS {
            top -= 1;
            let (a, b, ga, gb) = stack[top];
            let hw = 0.5 * (b - a);
            let m = a + hw;
            let e = self.eval_angle(m);
            evals += 1;
            let sign_change = ga * gb <= 0.0;
            // Taylor at m: |g(x) − g(m) − g'(m)(x − m)| ≤ ½ M₂ hw² and |g'(x) − g'(m)| ≤ M₂ hw.
            if e.dg.abs() > m2 * hw + slack {
                // g' keeps its sign on [a, b]: one root at most, there iff the ends differ.
                if sign_change {
                    push_root(self.refine(a, b, ga, gb), 0.0, roots);
                }
                continue;
            }
            if e.g.abs() > e.dg.abs() * hw + 0.5 * m2 * hw * hw + slack {
                continue;
            }
            if hw < MIN_HALF_WIDTH || top + 2 > stack.len() {
                // Unresolved: a double root or roots closer than the width. One representative
                // (polished and judged by the caller) per cluster.
                let theta = if sign_change {
                    self.refine(a, b, ga, gb)
                } else {
                    m
                };
                push_root(theta, CLUSTER_RADIUS, roots);
                continue;
            }
            stack[top] = (m, b, e.g, gb);
            stack[top + 1] = (a, m, ga, e.g);
            top += 2;
        }
        n
    }

    /// The root of g in `[a, b]`, where `g(a) g(b) ≤ 0`: Newton kept inside a shrinking bracket.
    fn refine(&self, mut a: f64, mut b: f64, ga: f64, gb: f64) -> f64 {
        if ga == 0.0 {
            return a;
        }
        if gb == 0.0 {
            return b;
        }
        let rising = gb > 0.0;
        let mut x = 0.5 * (a + b);
        for _ in 0..100 {
            let e = self.eval_angle(x);
            if e.g == 0.0 {
                return x;
            }
            if (e.g > 0.0) == rising {
                b = x;
            } else {
                a = x;
            }
            let newton = x - e.g / e.dg;
            let next = if newton > a && newton < b {
                newton
            } else {
                0.5 * (a + b)
            };
            let moved = (next - x).abs();
            x = next;
            if moved <= 2.0 * f64::EPSILON * x.abs().max(1.0)
                || b - a <= 4.0 * f64::EPSILON * b.abs()
            {
                break;
            }
        }
        x
    }
}

/// Normalises `(x, y)`, or returns `fallback` when it has no direction.
#[inline]
fn unit_or(x: f64, y: f64, fallback: (f64, f64)) -> (f64, f64) {
    let n2 = x * x + y * y;
    if n2 > 0.0 && n2.is_finite() {
        let inv = 1.0 / n2.sqrt();
        (x * inv, y * inv)
    } else {
        fallback
    }
}

fn angle_distance(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Case 3 (stick failed, `μ > 0`, `u_free.x < 0`). `r_stick = −W⁻¹ u_free`.
#[inline(never)]
fn solve_slide(
    w: &DMat3,
    q: DVec3,
    mu: f64,
    r_stick: DVec3,
    previous: DVec3,
) -> (DVec3, ContactStatus) {
    let pb = SlideProblem::new(w, q, mu);
    if pb.wnn.is_nan() || pb.wnn <= 0.0 {
        return (project_on_cone(r_stick, mu), ContactStatus::Slide);
    }
    let scale = pb.scale();
    let (tol, noise) = (ROUNDING * scale, NEWTON_NOISE * scale);
    // Warm start: the previous sliding direction (its impulse on the cone's boundary).
    let pt2 = previous.y * previous.y + previous.z * previous.z;
    let bound = mu * previous.x;
    if previous.x > 0.0 && pt2 >= bound * bound * (1.0 - 1e-9) {
        let d = unit_or(previous.y, previous.z, (1.0, 0.0));
        if let Some((c, s)) = pb.correct(d.0, d.1, tol, noise) {
            return (pb.impulse(c, s), ContactStatus::Slide);
        }
    }
    let hint = unit_or(r_stick.y, r_stick.z, (1.0, 0.0));
    let (c0, s0) = pb.predict(hint);
    if let Some((c, s)) = pb.correct(c0, s0, tol, noise) {
        return (pb.impulse(c, s), ContactStatus::Slide);
    }
    // Just outside the stick cone the sliding root lies next to the stick direction, with an
    // inadmissible root close by that Newton from the prediction may reach first.
    if hint.0 * c0 + hint.1 * s0 < 1.0 - 1e-12 {
        if let Some((c, s)) = pb.correct(hint.0, hint.1, tol, noise) {
            return (pb.impulse(c, s), ContactStatus::Slide);
        }
    }

    let mut roots = [0.0; MAX_ROOTS];
    let n = pb.enumerate_roots(&mut roots);
    let mut best: Option<(f64, f64, f64)> = None;
    for &theta in &roots[..n] {
        let (s, c) = theta.sin_cos();
        // Polish (matters for roots left unresolved at the subdivision's finest width).
        let (c, s) = pb.correct(c, s, tol, noise).unwrap_or((c, s));
        let e = pb.eval(c, s);
        if pb.admissible(&e, tol) && e.g.abs() <= ROOT_TOL * scale {
            let closeness = c * c0 + s * s0;
            if best.is_none_or(|(_, _, b)| closeness > b) {
                best = Some((c, s, closeness));
            }
        }
    }
    if let Some((c, s, _)) = best {
        return (pb.impulse(c, s), ContactStatus::Slide);
    }
    (
        degenerate(w, q, mu, r_stick, &pb, &roots[..n]),
        ContactStatus::Slide,
    )
}

/// No admissible sliding root: the candidate in K with the smallest natural-map residual.
#[cold]
fn degenerate(
    w: &DMat3,
    q: DVec3,
    mu: f64,
    r_stick: DVec3,
    pb: &SlideProblem,
    roots: &[f64],
) -> DVec3 {
    let residual = |r: DVec3| natural_map_residual(r, q + *w * r, mu);
    let mut best = project_on_cone(r_stick, mu);
    let mut best_res = residual(best);
    let candidates = roots
        .iter()
        .map(|&theta| {
            let (s, c) = theta.sin_cos();
            project_on_cone(pb.impulse(c, s), mu)
        })
        .chain(std::iter::once(DVec3::new(pb.a / pb.wnn, 0.0, 0.0)));
    for r in candidates {
        let res = residual(r);
        if res < best_res || best_res.is_nan() {
            best = r;
            best_res = res;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The trigonometric coefficients (used for the certified bounds) match the direct form.
    #[test]
    fn coefficients_match_direct_evaluation() {
        let w = DMat3::from_cols(
            DVec3::new(2.0, 0.3, -0.4),
            DVec3::new(0.25, 1.5, 0.2),
            DVec3::new(-0.35, 0.1, 0.8),
        );
        let pb = SlideProblem::new(&w, DVec3::new(-1.0, 0.7, -0.2), 0.9);
        let k = pb.coefficients();
        for i in 0..97 {
            let theta = 0.0713 * i as f64;
            let (s, c) = theta.sin_cos();
            let (s2, c2) = (2.0 * theta).sin_cos();
            let direct = pb.eval(c, s);
            let trig = k[0] + k[1] * c + k[2] * s + k[3] * c2 + k[4] * s2;
            assert!((direct.g - trig).abs() < 1e-13, "{} vs {trig}", direct.g);
            // g' by central differences.
            let hstep = 1e-6;
            let fd =
                (pb.eval_angle(theta + hstep).g - pb.eval_angle(theta - hstep).g) / (2.0 * hstep);
            assert!((direct.dg - fd).abs() < 1e-7, "{} vs {fd}", direct.dg);
        }
    }
}
