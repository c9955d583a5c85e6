//! Contact points (LMGC90's "interactions"): bodies, point, local frame `(n, t, s)`, gap,
//! friction coefficient, impulse and status; built from the detected points, warm-started from
//! the previous step's matching contact.

use crate::bodies::BodySet;
use crate::detection::RawContact;
use crate::laws::{ContactStatus, FrictionTable};
use crate::math::{frame_from_normal, DVec3};
use crate::shapes::Shape;

/// All contacts of a step, as a structure of arrays, sorted by body pair.
#[derive(Clone, Debug, Default)]
pub struct ContactSet {
    pub body1: Vec<u32>,
    pub body2: Vec<u32>,
    /// World position.
    pub point: Vec<DVec3>,
    /// Local frame `[n, t, s]`, `n` from body 1 toward body 2.
    pub frame: Vec<[DVec3; 3]>,
    /// Gap at the beginning of the step (negative = overlap).
    pub gap: Vec<f64>,
    /// Coulomb coefficient.
    pub mu: Vec<f64>,
    /// Impulse over the step in the local frame `(r_n, r_t, r_s)` (N·s).
    pub impulse: Vec<DVec3>,
    /// Status after the last solve.
    pub status: Vec<ContactStatus>,
    /// Position in body 1's frame, to recognise the contact at the next step.
    pub local_point: Vec<DVec3>,
}

impl ContactSet {
    /// Number of contact points.
    pub fn len(&self) -> usize {
        self.body1.len()
    }

    /// True when there is no contact.
    pub fn is_empty(&self) -> bool {
        self.body1.is_empty()
    }

    fn clear(&mut self) {
        self.body1.clear();
        self.body2.clear();
        self.point.clear();
        self.frame.clear();
        self.gap.clear();
        self.mu.clear();
        self.impulse.clear();
        self.status.clear();
        self.local_point.clear();
    }

    /// Impulse of contact `k` in world coordinates (acting on body 2).
    pub fn world_impulse(&self, k: usize) -> DVec3 {
        let [n, t, s] = self.frame[k];
        let r = self.impulse[k];
        n * r.x + t * r.y + s * r.z
    }

    /// Total contact impulse (world frame, N·s) received by each of `bodies` over the last step:
    /// `+r` for body 2 of a contact, `−r` for body 1. Divided by the time step it is the mean
    /// contact force. One pass over the contacts; `bodies` is meant to be short (tines, blocks).
    pub fn impulses_on(&self, bodies: &[u32]) -> Vec<DVec3> {
        let mut out = vec![DVec3::ZERO; bodies.len()];
        for k in 0..self.len() {
            let (a, b) = (self.body1[k], self.body2[k]);
            let ia = bodies.iter().position(|&x| x == a);
            let ib = bodies.iter().position(|&x| x == b);
            if ia.is_none() && ib.is_none() {
                continue;
            }
            let r = self.world_impulse(k);
            if let Some(i) = ia {
                out[i] -= r;
            }
            if let Some(i) = ib {
                out[i] += r;
            }
        }
        out
    }

    /// Unordered pair key of contact `k`.
    fn key(&self, k: usize) -> (u32, u32) {
        let (a, b) = (self.body1[k], self.body2[k]);
        (a.min(b), a.max(b))
    }

    /// Rebuilds `self` from the detected points `raw` (sorted by unordered pair), taking the
    /// impulses of `previous` where a contact persists: same bodies, and a position in body 1's
    /// frame within `match_fraction` × the smaller body radius of the old one. Each old contact
    /// is reused at most once; the old world impulse is re-projected on the new frame.
    pub fn rebuild(
        &mut self,
        raw: &[RawContact],
        bodies: &BodySet,
        friction: &FrictionTable,
        previous: &ContactSet,
        match_fraction: f64,
    ) {
        use rayon::prelude::*;
        let key = |c: &RawContact| (c.body1.min(c.body2), c.body1.max(c.body2));
        // Pairs are independent: match them in parallel, keep the order.
        let groups: Vec<Vec<Built>> = raw
            .par_chunk_by(|a, b| key(a) == key(b))
            .map(|group| {
                let k = key(&group[0]);
                let p0 = partition(previous, |j| previous.key(j) < k);
                let p1 = partition(previous, |j| previous.key(j) <= k);
                let mut used = vec![false; p1 - p0];
                group
                    .iter()
                    .map(|c| {
                        build_one(c, bodies, friction, previous, p0, &mut used, match_fraction)
                    })
                    .collect()
            })
            .collect();
        self.clear();
        for c in groups.into_iter().flatten() {
            self.body1.push(c.raw.body1);
            self.body2.push(c.raw.body2);
            self.point.push(c.raw.point);
            self.frame.push(c.frame);
            self.gap.push(c.raw.gap);
            self.mu.push(c.mu);
            self.impulse.push(c.impulse);
            self.status.push(c.status);
            self.local_point.push(c.local);
        }
    }
}

/// A contact being built by [`ContactSet::rebuild`].
struct Built {
    raw: RawContact,
    frame: [DVec3; 3],
    mu: f64,
    impulse: DVec3,
    status: ContactStatus,
    local: DVec3,
}

/// Frame, friction and warm start of one detected point; `used[j - p0]` marks the previous
/// contacts of this pair already taken.
fn build_one(
    c: &RawContact,
    bodies: &BodySet,
    friction: &FrictionTable,
    previous: &ContactSet,
    p0: usize,
    used: &mut [bool],
    match_fraction: f64,
) -> Built {
    let (b1, b2) = (c.body1 as usize, c.body2 as usize);
    let local = bodies.orientation[b1].inverse() * (c.point - bodies.position[b1]);
    let tol = match_fraction * radius(bodies, b1).min(radius(bodies, b2));
    let mut best: Option<(f64, usize)> = None;
    for (u, &was_used) in used.iter().enumerate() {
        let j = p0 + u;
        if was_used || previous.body1[j] != c.body1 {
            continue;
        }
        let d = previous.local_point[j].distance(local);
        if d <= tol && best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, j));
        }
    }
    let (t, s) = frame_from_normal(c.normal);
    let (impulse, status) = match best {
        Some((_, j)) => {
            used[j - p0] = true;
            let r = previous.world_impulse(j);
            (
                DVec3::new(r.dot(c.normal), r.dot(t), r.dot(s)),
                previous.status[j],
            )
        }
        None => (DVec3::ZERO, ContactStatus::NoContact),
    };
    Built {
        raw: *c,
        frame: [c.normal, t, s],
        mu: friction.get(bodies.group[b1], bodies.group[b2]),
        impulse,
        status,
        local,
    }
}

fn partition(set: &ContactSet, pred: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, set.len());
    while lo < hi {
        let mid = (lo + hi) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

fn radius(bodies: &BodySet, i: usize) -> f64 {
    match &bodies.shape[i] {
        Shape::Polyhedron(p) => p.radius,
        Shape::Plane { .. } => f64::INFINITY,
    }
}
