//! Local problems: for each contact, its frame and lever arms (which define the rows `H_αᵀ`)
//! and the diagonal Delassus block `W_αα = H_αᵀ M⁻¹ H_α`.
//!
//! Only what cannot be recomputed cheaply is stored (208 bytes per contact: `W` as a symmetric
//! matrix, its inverse computed when needed; the frame as `[n, t]`): the sweep is memory-bound at large scale, so `r × e_k` and `I⁻¹ (r × P)` are recomputed from the lever arms and the
//! body's inverse inertia, which stays in cache across that body's contacts.

use crate::bodies::{BodyKind, BodySet};
use crate::contacts::ContactSet;
use crate::laws::Elastic;
use crate::math::{skew, DMat3, DVec3, Sym3};

/// What the solver knows of a body: current velocities and inverse mass properties (zero for
/// kinematic and fixed bodies, whose velocities therefore never change).
#[derive(Clone, Copy, Debug)]
pub struct SolverBody {
    pub v: DVec3,
    /// World angular velocity.
    pub w: DVec3,
    pub inv_mass: f64,
    /// World inverse inertia.
    pub inv_inertia: DMat3,
    /// Counts this body's velocity changes past the skip threshold (see
    /// [`super::SolverSettings::skip`]; a drive row's change always counts).
    pub epoch: u32,
    /// Velocity change (m/s, at the contact points) accumulated since `epoch` last moved.
    pub drift: f32,
    /// Counts every write of this body's velocities within a solve (exact, unlike `epoch`):
    /// a residual term computed at the same versions of its two bodies is still exact (see
    /// the solver's `TermCache`).
    pub version: u32,
}

impl SolverBody {
    /// A placeholder at rest with no mass: the solver body of a body that a rank sharing a
    /// solve neither owns nor reads this step, which nothing reads.
    pub const UNREAD: SolverBody = SolverBody {
        v: DVec3::ZERO,
        w: DVec3::ZERO,
        inv_mass: 0.0,
        inv_inertia: DMat3::ZERO,
        epoch: 0,
        drift: 0.0,
        version: 0,
    };
}

/// Where body `i`'s solver body lies among a rank's (`slots[i]`; see [`SolverBody::UNREAD`]),
/// or at `i` when `slots` is empty: every body has one, in body order.
#[inline]
pub(crate) fn slot(slots: &[u32], i: usize) -> usize {
    match slots.is_empty() {
        true => i,
        false => slots[i] as usize,
    }
}

/// One contact's local problem.
#[derive(Clone, Copy, Debug)]
pub struct LocalProblem {
    pub body1: u32,
    pub body2: u32,
    /// Whether each body is dynamic (non-dynamic bodies are never written).
    pub dynamic1: bool,
    pub dynamic2: bool,
    /// Local frame `e = [n, t, s]`, stored as `[n, t]`: `s = n × t` (see [`Self::frame3`]).
    pub frame: [DVec3; 2],
    /// Lever arms from each body's centre of mass to the contact point.
    pub r1: DVec3,
    pub r2: DVec3,
    /// Diagonal Delassus block (local frame), symmetric; its inverse is computed where needed
    /// (a contact that does not stay open), which costs less than streaming it from memory.
    pub w: Sym3,
    /// Gap at the beginning of the step.
    pub gap: f64,
    pub mu: f64,
    /// Current impulse `(r_n, r_t, r_s)`.
    pub r: DVec3,
    /// Normal impulse the compliant normal law starts the step from (see [`super::Nlgs`]): the
    /// one the contact carried at the end of the previous step (0 for a new contact), or with
    /// [`crate::laws::NormalLaw::Overlap`] the one its overlap holds.
    pub r_prev: f64,
    /// Tangential impulse `(r_t, r_s)` at the end of the previous step, re-projected on this
    /// step's frame: the memory of the tangential spring (single precision: it only shifts
    /// a sticking contact's rest point, and keeps the local problem at 216 bytes).
    pub rt_prev: [f32; 2],
    /// The bodies' epochs (their low 16 bits) when this contact was last solved (see
    /// [`super::SolverSettings::skip`]; 16 bits fill the struct's padding: an epoch wraps
    /// only after 65,536 changes of one body within one sweep).
    pub seen: [u16; 2],
}

/// Access to the solver bodies a sweep works on: the whole array (monolithic NLGS), or the
/// disjoint slices a subdomain or an interface group owns (domain decomposition).
///
/// Kinematic and fixed bodies are never written: their velocities are imposed.
pub trait BodyAccess {
    /// Body `i` (global solver numbering).
    fn body(&self, i: u32) -> &SolverBody;
    /// Body `i`, mutably; only called for dynamic bodies.
    fn body_mut(&mut self, i: u32) -> &mut SolverBody;
    /// Asks the cache for body `i` ahead of its use (a hint: no effect on results).
    #[inline(always)]
    fn prefetch(&self, i: u32) {
        prefetch_body(self.body(i));
    }
}

/// Asks the cache for every 64-byte line `b` touches (at any 8-byte offset, its 144 bytes
/// span up to four).
#[inline(always)]
pub(crate) fn prefetch_body(b: &SolverBody) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching is a hint that never faults, and `b` is a valid reference.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = (b as *const SolverBody).cast::<i8>();
        let size = std::mem::size_of::<SolverBody>();
        let mut offset = 0;
        while offset < size {
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(offset));
            offset += 64;
        }
        _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(size - 1));
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = b;
}

impl BodyAccess for [SolverBody] {
    #[inline(always)]
    fn body(&self, i: u32) -> &SolverBody {
        &self[i as usize]
    }
    #[inline(always)]
    fn body_mut(&mut self, i: u32) -> &mut SolverBody {
        &mut self[i as usize]
    }
}

impl SolverBody {
    /// Whether impulses change this body's velocities (a dynamic body, or a force-limited
    /// driven one).
    #[inline]
    pub(crate) fn writable(&self) -> bool {
        self.inv_mass > 0.0 || self.inv_inertia != DMat3::ZERO
    }
}

impl LocalProblem {
    /// The local frame `[n, t, s = n × t]`.
    #[inline(always)]
    pub fn frame3(&self) -> [DVec3; 3] {
        let [n, t] = self.frame;
        [n, t, n.cross(t)]
    }

    /// Local relative velocity `u = H_αᵀ V = Eᵀ[(v₂ + ω₂ × r₂) − (v₁ + ω₁ × r₁)]`.
    #[inline(always)]
    pub fn velocity<B: BodyAccess + ?Sized>(&self, b: &B) -> DVec3 {
        let (b1, b2) = (b.body(self.body1), b.body(self.body2));
        let d = (b2.v + b2.w.cross(self.r2)) - (b1.v + b1.w.cross(self.r1));
        let [n, t, s] = self.frame3();
        DVec3::new(n.dot(d), t.dot(d), s.dot(d))
    }

    /// Applies the impulse increment `dr` (local frame): `V += M⁻¹ H_α dr`, i.e. `+P` on body 2
    /// and `−P` on body 1 with `P = E dr`. Non-dynamic bodies are left alone.
    #[inline(always)]
    pub fn apply<B: BodyAccess + ?Sized>(&self, b: &mut B, dr: DVec3) {
        let [n, t, s] = self.frame3();
        let p = n * dr.x + t * dr.y + s * dr.z;
        if self.dynamic1 {
            let b1 = b.body_mut(self.body1);
            b1.v -= p * b1.inv_mass;
            b1.w -= b1.inv_inertia * self.r1.cross(p);
            b1.version = b1.version.wrapping_add(1);
        }
        if self.dynamic2 {
            let b2 = b.body_mut(self.body2);
            b2.v += p * b2.inv_mass;
            b2.w += b2.inv_inertia * self.r2.cross(p);
            b2.version = b2.version.wrapping_add(1);
        }
    }

    /// [`Self::apply`], adding each body's velocity change at the contact point (an upper
    /// bound, in the max norm) to its drift and moving its epoch past `eps`.
    #[inline(always)]
    pub fn apply_tracked<B: BodyAccess + ?Sized>(&self, b: &mut B, dr: DVec3, eps: f32) {
        let [n, t, s] = self.frame3();
        let p = n * dr.x + t * dr.y + s * dr.z;
        let track = |bd: &mut SolverBody, dv: DVec3, dw: DVec3, arm: DVec3| {
            bd.version = bd.version.wrapping_add(1);
            bd.drift +=
                (dv.abs().max_element() + dw.abs().max_element() * arm.abs().max_element()) as f32;
            if bd.drift > eps {
                bd.epoch = bd.epoch.wrapping_add(1);
                bd.drift = 0.0;
            }
        };
        if self.dynamic1 {
            let b1 = b.body_mut(self.body1);
            let (dv, dw) = (p * b1.inv_mass, b1.inv_inertia * self.r1.cross(p));
            b1.v -= dv;
            b1.w -= dw;
            track(b1, dv, dw, self.r1);
        }
        if self.dynamic2 {
            let b2 = b.body_mut(self.body2);
            let (dv, dw) = (p * b2.inv_mass, b2.inv_inertia * self.r2.cross(p));
            b2.v += dv;
            b2.w += dw;
            track(b2, dv, dw, self.r2);
        }
    }

    /// The bodies' epochs now (low 16 bits).
    #[inline(always)]
    pub fn epochs<B: BodyAccess + ?Sized>(&self, b: &B) -> [u16; 2] {
        [
            b.body(self.body1).epoch as u16,
            b.body(self.body2).epoch as u16,
        ]
    }
}

/// `W = Eᵀ [ (m₁⁻¹ + m₂⁻¹) 1 − [r₁×] I₁⁻¹ [r₁×] − [r₂×] I₂⁻¹ [r₂×] ] E`.
pub(crate) fn delassus_block(
    e: &[DVec3; 3],
    r1: DVec3,
    r2: DVec3,
    b1: &SolverBody,
    b2: &SolverBody,
) -> DMat3 {
    let (s1, s2) = (skew(r1), skew(r2));
    let world = DMat3::from_diagonal(DVec3::splat(b1.inv_mass + b2.inv_mass))
        - s1 * b1.inv_inertia * s1
        - s2 * b2.inv_inertia * s2;
    let basis = DMat3::from_cols(e[0], e[1], e[2]);
    basis.transpose() * world * basis
}

/// What a contact's local problem is built from: the contacts, the bodies and their solver
/// view. `attach[i]` is the body whose velocities body `i` takes (itself, or the body it is a
/// rigid part of; empty: every body is itself): a contact on an attached part acts on that
/// body, with the lever arm from its centre of mass. With `warm_start` a problem starts from
/// its contact's impulse, else from zero. `overlap_law`: the elastic law and the overlap caps
/// of [`crate::laws::NormalLaw::Overlap`] (the compliant law starts from the force the capped
/// overlap holds), between two dynamic bodies and with a body that is not dynamic (see
/// [`crate::laws::driven_overlap_cap`]); `None` for the rate form (from the force the contact
/// carried).
#[derive(Clone, Copy)]
pub(crate) struct LocalBuilder<'a> {
    pub contacts: &'a ContactSet,
    pub warm_start: bool,
    pub bodies: &'a BodySet,
    pub solver_bodies: &'a [SolverBody],
    /// Where each body's solver body lies in `solver_bodies` (see [`slot`]).
    pub slots: &'a [u32],
    pub attach: &'a [u32],
    pub overlap_law: Option<(Elastic, [f64; 2])>,
}

impl LocalBuilder<'_> {
    /// The two bodies contact `k`'s problem acts on.
    #[inline]
    pub fn bodies_of(&self, k: usize) -> (u32, u32) {
        let (b1, b2) = (self.contacts.body1[k], self.contacts.body2[k]);
        if self.attach.is_empty() {
            (b1, b2)
        } else {
            (self.attach[b1 as usize], self.attach[b2 as usize])
        }
    }

    /// Contact `k`'s local problem, bodies in the caller's numbering.
    #[inline]
    pub fn at(&self, k: usize) -> LocalProblem {
        let (contacts, bodies) = (self.contacts, self.bodies);
        let (b1, b2) = self.bodies_of(k);
        let (b1, b2) = (b1 as usize, b2 as usize);
        let (s1, s2) = (
            &self.solver_bodies[slot(self.slots, b1)],
            &self.solver_bodies[slot(self.slots, b2)],
        );
        // The frame as the sweep rebuilds it from `[n, t]`.
        let [n, t, _] = contacts.frame[k];
        let e = [n, t, n.cross(t)];
        let x = contacts.point[k];
        let (r1, r2) = (x - bodies.position[b1], x - bodies.position[b2]);
        let w = Sym3::from_mat(delassus_block(&e, r1, r2, s1, s2));
        LocalProblem {
            body1: b1 as u32,
            body2: b2 as u32,
            dynamic1: s1.writable(),
            dynamic2: s2.writable(),
            frame: [n, t],
            r1,
            r2,
            w,
            gap: contacts.gap[k],
            mu: contacts.mu[k],
            r: if self.warm_start {
                contacts.impulse[k]
            } else {
                DVec3::ZERO
            },
            // The compliant law's starting force: remembered, or held by the overlap.
            r_prev: match self.overlap_law {
                Some((e, [cap, driven])) => {
                    let dynamic = |b: u32| bodies.kind[b as usize] == BodyKind::Dynamic;
                    let both = dynamic(contacts.body1[k]) && dynamic(contacts.body2[k]);
                    e.impulse_at((-contacts.gap[k]).min(if both { cap } else { driven }))
                }
                None => contacts.impulse[k].x,
            },
            rt_prev: [contacts.impulse[k].y as f32, contacts.impulse[k].z as f32],
            seen: [u16::MAX; 2],
        }
    }

    /// Builds the local problem of every contact into `out` (in parallel; the order is the
    /// contacts' order).
    pub fn build_all(&self, out: &mut Vec<LocalProblem>) {
        use rayon::prelude::*;
        out.clear();
        (0..self.contacts.len())
            .into_par_iter()
            .with_min_len(256)
            .map(|k| self.at(k))
            .collect_into_vec(out);
    }
}

/// For unit tests: a contact between bodies `a` and `b` on the line of their centres along
/// x (lever arms ±x/2, frame x, y, z); body 0 is the static one.
#[cfg(test)]
pub(crate) fn contact_along_x(
    bodies: &[SolverBody],
    a: u32,
    b: u32,
    gap: f64,
    mu: f64,
) -> LocalProblem {
    let frame = [DVec3::X, DVec3::Y, DVec3::Z];
    let (r1, r2) = (DVec3::X * 0.5, -DVec3::X * 0.5);
    let w = delassus_block(&frame, r1, r2, &bodies[a as usize], &bodies[b as usize]);
    LocalProblem {
        body1: a,
        body2: b,
        dynamic1: a != 0,
        dynamic2: true,
        frame: [frame[0], frame[1]],
        r1,
        r2,
        w: Sym3::from_mat(w),
        gap,
        mu,
        r: DVec3::ZERO,
        r_prev: 0.0,
        rt_prev: [0.0; 2],
        seen: [u16::MAX; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sweep streams the local problems from memory at large scale: their size is a
    /// budget (320 bytes with `W` and `W⁻¹` as full matrices and the frame's three vectors;
    /// 16 of the 216 are the compliant law's memory).
    #[test]
    fn local_problem_size() {
        assert_eq!(std::mem::size_of::<LocalProblem>(), 216);
    }
}
