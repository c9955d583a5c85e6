//! Contact points (LMGC90's "interactions"): bodies, point, local frame `(n, t, s)`, gap,
//! friction coefficient, impulse and status; built from the detected points, warm-started from
//! the previous step's matching contact.

use crate::bodies::BodySet;
use crate::detection::RawContact;
use crate::laws::{ContactStatus, FrictionTable};
use crate::math::{frame_from_normal, DVec3};
use crate::slices::reserve_total;

mod ranks;

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

    /// Room for `n` contacts in every field, grown tightly (see [`reserve_total`]).
    fn reserve_total(&mut self, n: usize) {
        reserve_total(&mut self.body1, n);
        reserve_total(&mut self.body2, n);
        reserve_total(&mut self.point, n);
        reserve_total(&mut self.frame, n);
        reserve_total(&mut self.gap, n);
        reserve_total(&mut self.mu, n);
        reserve_total(&mut self.impulse, n);
        reserve_total(&mut self.status, n);
        reserve_total(&mut self.local_point, n);
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
    /// frame within `match_fraction` × the smaller body radius (`radii`, one per body, ∞ for a
    /// half-space) of the old one. Each old contact
    /// is reused at most once, taken by the pair's points in order; the old world impulse is
    /// re-projected on the new frame.
    ///
    /// Every point is built in parallel straight into the arrays (kept across steps: no
    /// allocation, no serial copy). A point replays the matching of its pair's earlier points
    /// to know which old contacts they took: a pair has at most a few points, so this costs
    /// less than grouping the pairs would.
    pub(crate) fn rebuild(
        &mut self,
        raw: &[RawContact],
        bodies: &BodySet,
        friction: &FrictionTable,
        previous: &ContactSet,
        match_fraction: f64,
        radii: &[f64],
    ) {
        use rayon::prelude::*;
        let n = raw.len();
        self.reserve_total(n);
        self.body1.resize(n, 0);
        self.body2.resize(n, 0);
        self.point.resize(n, DVec3::ZERO);
        self.frame.resize(n, [DVec3::ZERO; 3]);
        self.gap.resize(n, 0.0);
        self.mu.resize(n, 0.0);
        self.impulse.resize(n, DVec3::ZERO);
        self.status.resize(n, ContactStatus::NoContact);
        // Body-1 frame points first: the matching compares each contact of a pair with the
        // pair's earlier ones, which would otherwise transform them again and again.
        raw.par_iter()
            .with_min_len(1024)
            .map(|c| local_point(bodies, c))
            .collect_into_vec(&mut self.local_point);
        let locals = &self.local_point;
        // The old contact each new one takes over, found pair by pair (a pair's points are
        // consecutive: `raw` is sorted by pair).
        let starts: Vec<usize> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .filter(|&k| k == 0 || raw_key(&raw[k - 1]) != raw_key(&raw[k]))
            .collect();
        let mut matched: Vec<Option<usize>> = vec![None; n];
        let lengths =
            (0..starts.len()).map(|g| starts.get(g + 1).copied().unwrap_or(n) - starts[g]);
        let (mut pieces, _) = crate::slices::split_lengths(&mut matched, lengths);
        // Both lists are sorted by pair: each run of pairs finds its first pair's old
        // contacts by bisection, then walks forward with the pairs.
        const PAIRS_PER_TASK: usize = 256;
        pieces
            .par_chunks_mut(PAIRS_PER_TASK)
            .zip(starts.par_chunks(PAIRS_PER_TASK))
            .for_each(|(outs, firsts)| {
                let key0 = raw_key(&raw[firsts[0]]);
                let mut p = partition(previous, |j| previous.key(j) < key0);
                for (out, &first) in outs.iter_mut().zip(firsts) {
                    let key = raw_key(&raw[first]);
                    while p < previous.len() && previous.key(p) < key {
                        p += 1;
                    }
                    let p0 = p;
                    while p < previous.len() && previous.key(p) == key {
                        p += 1;
                    }
                    let new = first..first + out.len();
                    let (points, locals) = (&raw[new.clone()], &locals[new]);
                    match_pair(points, locals, out, p0..p, radii, previous, match_fraction);
                }
            });
        (
            &mut self.body1,
            &mut self.body2,
            &mut self.point,
            &mut self.frame,
            &mut self.gap,
            &mut self.mu,
            &mut self.impulse,
            &mut self.status,
        )
            .into_par_iter()
            .enumerate()
            .with_min_len(256)
            .for_each(|(k, (b1, b2, point, frame, gap, mu, impulse, status))| {
                let c = &raw[k];
                let (t, s) = frame_from_normal(c.normal);
                (*impulse, *status) = match matched[k] {
                    Some(j) => {
                        let r = previous.world_impulse(j);
                        (
                            DVec3::new(r.dot(c.normal), r.dot(t), r.dot(s)),
                            previous.status[j],
                        )
                    }
                    None => (DVec3::ZERO, ContactStatus::NoContact),
                };
                (*b1, *b2, *point, *gap) = (c.body1, c.body2, c.point, c.gap);
                *frame = [c.normal, t, s];
                *mu = friction.get(
                    bodies.group[c.body1 as usize],
                    bodies.group[c.body2 as usize],
                );
            });
    }
}

/// Unordered pair key of a detected point.
fn raw_key(c: &RawContact) -> (u32, u32) {
    (c.body1.min(c.body2), c.body1.max(c.body2))
}

/// Position of a detected point in body 1's frame.
fn local_point(bodies: &BodySet, c: &RawContact) -> DVec3 {
    let b1 = c.body1 as usize;
    bodies.orientation[b1].inverse() * (c.point - bodies.position[b1])
}

/// The old contacts that the detected `points` of one pair (`locals`: in body 1's frame) take
/// over, into `out`: in order, each point takes the nearest old contact of the same pair (the
/// range `old` of `previous`; same body 1) within the match distance that an earlier point has
/// not taken.
fn match_pair(
    points: &[RawContact],
    locals: &[DVec3],
    out: &mut [Option<usize>],
    old: std::ops::Range<usize>,
    radii: &[f64],
    previous: &ContactSet,
    match_fraction: f64,
) {
    let (p0, p1) = (old.start, old.end);
    if p0 == p1 {
        out.fill(None);
        return;
    }
    let (mut small, mut large) = ([false; 16], Vec::new());
    let used: &mut [bool] = if p1 - p0 <= small.len() {
        &mut small[..p1 - p0]
    } else {
        large.resize(p1 - p0, false);
        &mut large
    };
    let (b1, b2) = (points[0].body1 as usize, points[0].body2 as usize);
    let tol = match_fraction * radii[b1].min(radii[b2]);
    for ((c, &local), taken) in points.iter().zip(locals).zip(out) {
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
        *taken = best.map(|(_, j)| j);
        if let Some(j) = *taken {
            used[j - p0] = true;
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
