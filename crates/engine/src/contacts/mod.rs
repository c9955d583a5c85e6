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
        self.clear();
        let mut used = vec![false; previous.len()];
        let mut k = 0;
        while k < raw.len() {
            let key = (
                raw[k].body1.min(raw[k].body2),
                raw[k].body1.max(raw[k].body2),
            );
            let mut end = k + 1;
            while end < raw.len()
                && (
                    raw[end].body1.min(raw[end].body2),
                    raw[end].body1.max(raw[end].body2),
                ) == key
            {
                end += 1;
            }
            let p0 = partition(previous, |j| previous.key(j) < key);
            let p1 = partition(previous, |j| previous.key(j) <= key);
            for c in &raw[k..end] {
                let (b1, b2) = (c.body1 as usize, c.body2 as usize);
                let q1 = bodies.orientation[b1];
                let local = q1.inverse() * (c.point - bodies.position[b1]);
                let tol = match_fraction * radius(bodies, b1).min(radius(bodies, b2));
                let mut best: Option<(f64, usize)> = None;
                for (j, &was_used) in used.iter().enumerate().take(p1).skip(p0) {
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
                        used[j] = true;
                        let r = previous.world_impulse(j);
                        (
                            DVec3::new(r.dot(c.normal), r.dot(t), r.dot(s)),
                            previous.status[j],
                        )
                    }
                    None => (DVec3::ZERO, ContactStatus::NoContact),
                };
                self.body1.push(c.body1);
                self.body2.push(c.body2);
                self.point.push(c.point);
                self.frame.push([c.normal, t, s]);
                self.gap.push(c.gap);
                self.mu
                    .push(friction.get(bodies.group[b1], bodies.group[b2]));
                self.impulse.push(impulse);
                self.status.push(status);
                self.local_point.push(local);
            }
            k = end;
        }
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
