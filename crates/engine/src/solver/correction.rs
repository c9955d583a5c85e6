//! Post-stabilisation of overlaps (split impulse): a position-only correction.
//!
//! Velocity-level Signorini (`uₙ ≥ 0` on closed contacts) stops bodies from approaching but
//! never undoes an overlap made at an impact (the θ-scheme lets a point arriving at `v` overlap
//! by up to `h (1 − θ) v`), so overlaps accumulate over repeated impacts. After the velocity
//! solve, this step finds *pseudo-velocities* `Ṽ = M⁻¹ Hₙ p` with frictionless normal impulses
//! `p ≥ 0` such that `0 ≤ p_α ⊥ ũₙ,α − b_α ≥ 0`, with the target separation speed
//! `b_α = min(β max(0, −g_α − slop), push) / h`, by projected Gauss-Seidel sweeps in contact
//! order. The positions move by `h Ṽ`; the velocities are untouched, so no kinetic energy is
//! injected. With `guard`, the open contacts (`g_α ≥ −slop`) join the problem with
//! `b_α = −max(g_α, 0) / h`: pushing one overlap apart may close their gap, not overlap them.
//! Without `rotation`, the pseudo-impulses move the bodies' centres only (`Ṽ = M⁻¹ Hₙ p` with
//! the inertia terms left out, and `W_α,nn = m₁⁻¹ + m₂⁻¹`).
//! With the compliant law's overlap recovery on, a compliant contact (stiffness `k`) is meant
//! to overlap by its elastic deflection `r̄ₙ/(k h)`, with `r̄ₙ` the normal impulse of the step
//! before (the force that goes with the step's initial gap; the rate form keeps
//! `δ − r̄ₙ/(k h)` constant): only the excess over it counts as an overlap, `g_α` above is
//! then `g_α + r̄ₙ/(k h)` (with a maximum closure, the hyperbola's deflection of
//! [`crate::laws::closure`]), and the correction leaves a loaded spring its deflection.
//! β = 0 switches it off (plain Moreau-Jean, as LMGC90).

use super::delassus::{BodyAccess, LocalProblem, SolverBody};
use crate::laws::Elastic;
use crate::math::{DMat3, DVec3};
use crate::ScenarioError;
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
    /// Largest correction of one contact in one step (m): a deeper overlap is healed over
    /// several steps, each moving the grains by less than the alert distance, so that the
    /// neighbours they approach are detected (and, with `guard`, held).
    #[serde(deserialize_with = "infinite_if_null")]
    pub max_push: f64,
    /// Hold the detected open contacts too (see the module documentation). Off by default:
    /// the default correction moves grains by far less than the alert distance, and sweeping
    /// every contact would cost as much again as sweeping the overlaps.
    pub guard: bool,
    /// Let the correction rotate the bodies (the default), or only translate them: a normal
    /// impulse at a corner of an elongated grain also turns it, and where that corner is
    /// deep in a neighbour the turn can drive another corner into the next one.
    pub rotation: bool,
}

impl Default for CorrectionSettings {
    fn default() -> Self {
        Self {
            fraction: 0.2,
            slop: 1e-5,
            sweeps: 10,
            max_push: f64::INFINITY,
            guard: false,
            rotation: true,
        }
    }
}

/// JSON writes an infinite `max_push` (no limit) as `null`: read it back as infinite.
pub(crate) fn infinite_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

impl CorrectionSettings {
    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if !(0.0..=1.0).contains(&self.fraction) {
            return Err(ScenarioError(format!(
                "correction.fraction = {} must be in [0, 1]",
                self.fraction
            )));
        }
        if !(self.slop.is_finite() && self.slop >= 0.0) {
            return Err(ScenarioError(format!(
                "correction.slop = {} must be ≥ 0 m",
                self.slop
            )));
        }
        if self.max_push.is_nan() || self.max_push <= 0.0 {
            return Err(ScenarioError(format!(
                "correction.max_push = {} must be > 0 m (inf: no limit)",
                self.max_push
            )));
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

/// A body's solver copy with zero velocities (its inverse masses kept; its inverse inertia
/// too when the correction may rotate it, otherwise zero).
pub(crate) fn at_rest(b: &SolverBody, rotation: bool) -> SolverBody {
    SolverBody {
        v: DVec3::ZERO,
        w: DVec3::ZERO,
        inv_inertia: if rotation { b.inv_inertia } else { DMat3::ZERO },
        ..*b
    }
}

/// Lists in `out` the contacts of `locals` overlapping beyond the slop (with `guard`, every
/// contact), in order, with `p = 0`; returns how many overlap. None when the correction is
/// off. `elastic` is the compliant contacts' deflection law (the deflection the normal impulse
/// of the step before implies is not an overlap), [`Elastic::NONE`] for rigid ones.
pub fn overlaps(
    settings: &CorrectionSettings,
    h: f64,
    elastic: Elastic,
    locals: &[LocalProblem],
    out: &mut Vec<Overlap>,
) -> usize {
    out.clear();
    if settings.fraction == 0.0 {
        return 0;
    }
    let mut overlapping = 0;
    out.extend(locals.iter().enumerate().filter_map(|(k, c)| {
        // Exact for rigid contacts: adding 0 leaves the gap's bits.
        let gap = c.gap + elastic.deflection(c.r_prev);
        let target = if gap < -settings.slop {
            overlapping += 1;
            (settings.fraction * (-gap - settings.slop)).min(settings.max_push) / h
        } else if settings.guard {
            -c.gap.max(0.0) / h
        } else {
            return None;
        };
        Some(Overlap {
            k: k as u32,
            target,
            p: 0.0,
        })
    }));
    overlapping
}

/// One projected Gauss-Seidel sweep over `rows` (in order):
/// `p_α ← max(0, p_α + (b_α − ũₙ,α) / W_α,nn)`, the pseudo-velocities updated at once
/// (`W_α,nn` without its inertia terms when the pseudo bodies have none, see [`at_rest`]).
pub(crate) fn sweep<B: BodyAccess + ?Sized>(
    locals: &[LocalProblem],
    rows: &mut [Overlap],
    pseudo: &mut B,
    rotation: bool,
) {
    for row in rows {
        let c = &locals[row.k as usize];
        let un = c.velocity(pseudo).x;
        let wnn = if rotation {
            c.w.xx()
        } else {
            pseudo.body(c.body1).inv_mass + pseudo.body(c.body2).inv_mass
        };
        let new = (row.p + (row.target - un) / wnn).max(0.0);
        let dp = new - row.p;
        if dp != 0.0 {
            c.apply(pseudo, DVec3::new(dp, 0.0, 0.0));
            row.p = new;
        }
    }
}

/// Computes the pseudo-velocities in `pseudo` (one per body, zero-initialised here; inverse
/// masses copied from `bodies`) for the overlapping contacts among `locals`, by
/// `settings.sweeps` sweeps in contact order (`elastic` as in [`overlaps`]).
/// Returns whether any contact overlapped.
pub fn pseudo_velocities(
    settings: &CorrectionSettings,
    h: f64,
    elastic: Elastic,
    locals: &[LocalProblem],
    bodies: &[SolverBody],
    pseudo: &mut Vec<SolverBody>,
) -> bool {
    pseudo.clear();
    pseudo.extend(bodies.iter().map(|b| at_rest(b, settings.rotation)));
    let mut rows = Vec::new();
    if overlaps(settings, h, elastic, locals, &mut rows) == 0 {
        return false;
    }
    for _ in 0..settings.sweeps {
        sweep(locals, &mut rows, pseudo.as_mut_slice(), settings.rotation);
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{DMat3, Sym3};
    use crate::solver::delassus::{contact_along_x, delassus_block};

    /// A fixed body 0 and two unit-mass cubes 1, 2 in a row along x; contact (0, 1) overlaps
    /// by 5 mm, (1, 2) is open by 0.1 mm. Points on the line of the centres: no rotation.
    fn row() -> (Vec<LocalProblem>, Vec<SolverBody>) {
        let body = |inv_mass: f64| SolverBody {
            v: DVec3::ZERO,
            w: DVec3::ZERO,
            inv_mass,
            inv_inertia: DMat3::IDENTITY * 6.0 * inv_mass,
            epoch: 0,
            drift: 0.0,
            version: 0,
        };
        let bodies = vec![body(0.0), body(1.0), body(1.0)];
        let contact = |a, b, gap| contact_along_x(&bodies, a, b, gap, 0.0);
        let locals = vec![contact(0, 1, -5e-3), contact(1, 2, 1e-4)];
        (locals, bodies)
    }

    /// Gaps after the positions move by `h Ṽ`.
    fn gaps_after(settings: &CorrectionSettings) -> [f64; 2] {
        let (locals, bodies) = row();
        let h = 1e-3;
        let mut pseudo = Vec::new();
        assert!(pseudo_velocities(
            settings,
            h,
            Elastic::NONE,
            &locals,
            &bodies,
            &mut pseudo
        ));
        [0, 1].map(|k| locals[k].gap + h * locals[k].velocity(pseudo.as_slice()).x)
    }

    #[test]
    fn guard_keeps_open_contacts_open() {
        let plain = CorrectionSettings {
            fraction: 1.0,
            slop: 0.0,
            sweeps: 50,
            ..Default::default()
        };
        // Alone, the overlap is pushed straight into the open neighbour.
        let [g01, g12] = gaps_after(&plain);
        assert!(g01.abs() < 1e-12, "{g01}");
        assert!((g12 + 4.9e-3).abs() < 1e-12, "{g12}");
        // Guarded, the neighbour is pushed along and only touches.
        let [g01, g12] = gaps_after(&CorrectionSettings {
            guard: true,
            ..plain.clone()
        });
        assert!(g01.abs() < 1e-9, "{g01}");
        assert!(g12.abs() < 1e-9, "{g12}");
        // At most `max_push` per step.
        let [g01, g12] = gaps_after(&CorrectionSettings {
            guard: true,
            max_push: 1e-3,
            ..plain
        });
        assert!((g01 + 4e-3).abs() < 1e-9, "{g01}");
        assert!(g12.abs() < 1e-9, "{g12}");
    }

    #[test]
    fn without_rotation_the_correction_translates() {
        let (mut locals, bodies) = row();
        // Move the overlapping contact's point off the line of the centres: its impulse has
        // a lever arm.
        let c = &mut locals[0];
        c.r1 += DVec3::Y * 0.4;
        c.r2 += DVec3::Y * 0.4;
        c.w = Sym3::from_mat(delassus_block(
            &c.frame3(),
            c.r1,
            c.r2,
            &bodies[0],
            &bodies[1],
        ));
        let h = 1e-3;
        for rotation in [true, false] {
            let s = CorrectionSettings {
                fraction: 1.0,
                slop: 0.0,
                sweeps: 50,
                rotation,
                ..Default::default()
            };
            let mut pseudo = Vec::new();
            assert!(pseudo_velocities(
                &s,
                h,
                Elastic::NONE,
                &locals[..1],
                &bodies,
                &mut pseudo
            ));
            let healed = locals[0].gap + h * locals[0].velocity(pseudo.as_slice()).x;
            assert!(healed.abs() < 1e-12, "{rotation}: {healed}");
            let spin = pseudo[1].w.length();
            if rotation {
                assert!(spin > 1.0, "{spin}");
            } else {
                assert_eq!(spin, 0.0);
                // All of the 5 mm by translation, along the normal.
                assert!((pseudo[1].v - DVec3::X * 5.0).length() < 1e-9);
            }
        }
    }

    #[test]
    fn a_compliant_contact_keeps_the_deflection_its_impulse_implies() {
        // k = 1e7 N/m, h = 1e-3 s: an impulse of 2 N s (a 2 kN force) deflects the spring by
        // 0.2 mm. A contact 0.2 mm deep carrying it is not an overlap; 1.2 mm deep, its
        // excess of 1 mm is.
        let (k, h) = (1e7, 1e-3);
        let (mut locals, bodies) = row();
        locals[0].r_prev = 2.0;
        let s = CorrectionSettings {
            fraction: 1.0,
            slop: 0.0,
            sweeps: 50,
            ..Default::default()
        };
        let mut rows = Vec::new();
        let e = Elastic {
            per_impulse: 1.0 / (k * h),
            closure_impulse: 0.0,
        };
        locals[0].gap = -2e-4;
        assert_eq!(overlaps(&s, h, e, &locals, &mut rows), 0);
        // The same depth in a rigid contact is an overlap.
        assert_eq!(overlaps(&s, h, Elastic::NONE, &locals, &mut rows), 1);
        // With a maximum closure of 0.2 mm (k V_m = 2 kN) the hyperbola deflects by
        // F V_m/(k V_m + F) = 0.1 mm under 2 kN: 0.1 mm deep is not an overlap, 0.2 mm is.
        let hyperbolic = Elastic {
            closure_impulse: k * h * 2e-4,
            ..e
        };
        locals[0].gap = -1e-4 + 1e-12;
        assert_eq!(overlaps(&s, h, hyperbolic, &locals, &mut rows), 0);
        locals[0].gap = -2e-4;
        assert_eq!(overlaps(&s, h, hyperbolic, &locals, &mut rows), 1);
        assert!(
            (rows[0].target * h - 1e-4).abs() < 1e-15,
            "{}",
            rows[0].target
        );
        locals[0].gap = -1.2e-3;
        let mut pseudo = Vec::new();
        assert!(pseudo_velocities(
            &s,
            h,
            e,
            &locals[..1],
            &bodies,
            &mut pseudo
        ));
        let after = locals[0].gap + h * locals[0].velocity(pseudo.as_slice()).x;
        assert!((after + 2e-4).abs() < 1e-12, "{after}");
    }

    #[test]
    fn max_push_must_be_positive() {
        for bad in [0.0, -1e-3, f64::NAN] {
            let s = CorrectionSettings {
                max_push: bad,
                ..Default::default()
            };
            let e = s.validate().unwrap_err();
            assert!(e.0.contains("correction.max_push"), "{e}");
        }
        let s = CorrectionSettings::default();
        assert!(s.validate().is_ok());
    }
}
