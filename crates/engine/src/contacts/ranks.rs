//! The contacts of a run shared between ranks, as their consumers see them.
//!
//! Each contact is *held* by one rank, the one that solved it (the owner of its bucket, see
//! [`crate::solver::exchange::PairOwners`]): only that rank counts it, writes it in its
//! output pieces and checkpoint part, and contributes it to whatever is computed over all
//! contacts. A consumer asks for what it needs — a count, a largest value, or the few
//! contacts that match a test, gathered in pair order — and every rank gets the same answer,
//! the one a single process computes from its whole contact set. These are collectives: every
//! rank makes the same calls in the same order. In a world that solves alone each is a plain
//! pass over its contacts.

use super::ContactSet;
use crate::laws::ContactStatus;
use crate::math::DVec3;
use crate::output::shared::gather;
use crate::solver::exchange::{self, PairOwners};
use crate::solver::Exchange;
use crate::world::World;

/// Values of one contact as gathered: bodies, point, frame, gap, μ, impulse, status, point
/// in body 1's frame.
const VALUES: usize = 23;

impl World {
    /// Whether this rank holds contact `k` (always, in a world that solves alone). In a
    /// domain-decomposed run each rank keeps only the contacts it holds (the world's
    /// `contacts`); a world whose every rank has every contact (without `[ddm]`, or resumed
    /// and not stepped yet) has rank 0 hold them.
    pub fn holds_contact(&self, k: usize) -> bool {
        let Some(ex) = self.exchange().filter(|e| e.size() > 1) else {
            return true;
        };
        // Each rank of a domain-decomposed run keeps only the contacts it holds.
        if self.detector.hold {
            return true;
        }
        let c = &self.contacts;
        match &self.detector.owners {
            Some(o) => o.of(c.body1[k], c.body2[k]) == ex.rank(),
            None => ex.rank() == 0,
        }
    }

    /// The step's number of contacts over all ranks (no collective: the solve counted them).
    pub fn contact_total(&self) -> usize {
        match self.detector.hold {
            true => self.contact_total,
            false => self.contacts.len(),
        }
    }

    /// The place of each contact this rank holds among the step's contacts of all ranks (in
    /// pair order, a single process's contact order). A collective when each rank holds its
    /// own contacts.
    pub(crate) fn contact_places(&self) -> Vec<u32> {
        let c = &self.contacts;
        match (self.exchange(), self.detector.hold) {
            (Some(ex), true) => places(ex, c),
            _ => (0..c.len() as u32).collect(),
        }
    }

    /// The contacts `keep` takes among those of every rank, in pair order (the order of a
    /// single process's contact set), on every rank. A collective.
    pub fn gather_contacts(&self, keep: impl Fn(&ContactSet, usize) -> bool) -> ContactSet {
        let c = &self.contacts;
        let kept = (0..c.len()).filter(|&k| self.holds_contact(k) && keep(c, k));
        let Some(ex) = self.exchange().filter(|e| e.size() > 1) else {
            let mut out = ContactSet::default();
            kept.for_each(|k| out.push_from(c, k));
            return out;
        };
        let mut mine = Vec::new();
        for k in kept {
            put(c, k, &mut mine);
        }
        let (all, counts) = exchange::gather_varying(ex, &mine);
        let mut out = ContactSet::default();
        in_pair_order(&all, &counts, VALUES, |x| take(x, &mut out));
        out
    }

    /// The largest `value(k)` over the contacts of all ranks (`f64::max` from `start`: the
    /// same whatever the order). A collective.
    pub fn max_over_contacts(&self, start: f64, value: impl Fn(&ContactSet, usize) -> f64) -> f64 {
        let c = &self.contacts;
        let m = (0..c.len())
            .filter(|&k| self.holds_contact(k))
            .fold(start, |m, k| m.max(value(c, k)));
        self.max_over_ranks(m)
    }

    /// Σ of each rank's `n` (exact: integers). A collective.
    pub fn sum_over_ranks(&self, n: u64) -> u64 {
        gather(self, &[n as f64]).iter().map(|&x| x as u64).sum()
    }

    /// The largest of each rank's `x`. A collective.
    pub fn max_over_ranks(&self, x: f64) -> f64 {
        gather(self, &[x]).iter().fold(x, |m, &y| m.max(y))
    }
}

impl ContactSet {
    /// An empty set with room for `n` contacts in every field.
    fn with_capacity(n: usize) -> Self {
        ContactSet {
            body1: Vec::with_capacity(n),
            body2: Vec::with_capacity(n),
            point: Vec::with_capacity(n),
            frame: Vec::with_capacity(n),
            gap: Vec::with_capacity(n),
            mu: Vec::with_capacity(n),
            impulse: Vec::with_capacity(n),
            status: Vec::with_capacity(n),
            local_point: Vec::with_capacity(n),
        }
    }

    /// Appends contact `k` of `from`.
    pub(crate) fn push_from(&mut self, from: &ContactSet, k: usize) {
        self.body1.push(from.body1[k]);
        self.body2.push(from.body2[k]);
        self.point.push(from.point[k]);
        self.frame.push(from.frame[k]);
        self.gap.push(from.gap[k]);
        self.mu.push(from.mu[k]);
        self.impulse.push(from.impulse[k]);
        self.status.push(from.status[k]);
        self.local_point.push(from.local_point[k]);
    }
}

/// Unordered pair key of contact `k`.
fn key_of(c: &ContactSet, k: usize) -> (u32, u32) {
    let (a, b) = (c.body1[k], c.body2[k]);
    (a.min(b), a.max(b))
}

/// The runs of contacts of one pair in `c`: each run's first contact, and the end.
fn pair_starts(c: &ContactSet) -> Vec<usize> {
    let mut starts: Vec<usize> = (0..c.len())
        .filter(|&k| k == 0 || key_of(c, k - 1) != key_of(c, k))
        .collect();
    starts.push(c.len());
    starts
}

/// [`World::contact_places`] of the contacts `c` this rank holds, each rank holding its own:
/// every pair's contact count from the ranks (a collective), in pair order, and the place
/// of each of this rank's pairs there.
fn places(ex: &dyn Exchange, c: &ContactSet) -> Vec<u32> {
    let starts = pair_starts(c);
    let mut mine = Vec::with_capacity(3 * starts.len());
    for w in starts.windows(2) {
        let (a, b) = key_of(c, w[0]);
        mine.extend_from_slice(&[f64::from(a), f64::from(b), (w[1] - w[0]) as f64]);
    }
    let (all, counts) = exchange::gather_varying(ex, &mine);
    // Each pair's key and its first contact's place, in pair order.
    let mut runs: Vec<((u32, u32), u32)> = Vec::with_capacity(all.len() / 3);
    let mut total = 0;
    in_pair_order(&all, &counts, 3, |x| {
        runs.push(((x[0] as u32, x[1] as u32), total));
        total += x[2] as u32;
    });
    let mut places = Vec::with_capacity(c.len());
    for w in starts.windows(2) {
        let r = runs
            .binary_search_by_key(&key_of(c, w[0]), |r| r.0)
            .expect("a held pair is among the ranks' pairs");
        let first = runs[r].1;
        places.extend(first..first + (w[1] - w[0]) as u32);
    }
    places
}

impl ContactSet {
    /// Hands the contacts whose pair `owners` gives to another rank to it, and takes in
    /// those handed to this rank (a collective): afterwards each rank holds, in pair order,
    /// the contacts of its pairs. Returns the seconds spent sharing.
    pub(crate) fn migrate(&mut self, ex: &dyn Exchange, owners: &PairOwners) -> f64 {
        let me = ex.rank();
        let holder: Vec<usize> = (0..self.len())
            .map(|k| owners.of(self.body1[k], self.body2[k]))
            .collect();
        let mut send_count = vec![0; ex.size()];
        for &h in holder.iter().filter(|&&h| h != me) {
            send_count[h] += 1;
        }
        let mut send: Vec<Vec<f64>> = send_count
            .iter()
            .map(|&c| Vec::with_capacity(c * VALUES))
            .collect();
        for (k, &h) in holder.iter().enumerate() {
            if h != me {
                put(self, k, &mut send[h]);
            }
        }
        let send_count: usize = send_count.iter().sum();
        let t = std::time::Instant::now();
        let (all, _) = exchange::exchange_parts(ex, &send);
        drop(send);
        let seconds = t.elapsed().as_secs_f64();
        let mut arrived = ContactSet::with_capacity(all.len() / VALUES);
        for x in all.chunks_exact(VALUES) {
            take(x, &mut arrived);
        }
        if send_count == 0 && arrived.is_empty() {
            return seconds;
        }
        // From several ranks, each in pair order; no pair on two ranks: sorted by pair, each
        // pair's points in their order.
        let mut order: Vec<usize> = (0..arrived.len()).collect();
        order.sort_by_key(|&k| key_of(&arrived, k));
        // Where each contact of the merged set comes from: (arrived, index).
        let mut plan: Vec<(bool, u32)> =
            Vec::with_capacity(self.len() - send_count + arrived.len());
        let mut a = order.iter().peekable();
        for k in (0..self.len()).filter(|&k| holder[k] == me) {
            while let Some(&&j) = a.peek() {
                if key_of(&arrived, j) >= key_of(self, k) {
                    break;
                }
                plan.push((true, j as u32));
                a.next();
            }
            plan.push((false, k as u32));
        }
        plan.extend(a.map(|&j| (true, j as u32)));
        // Field after field, so that one field's new copy at most sits beside the set.
        fn pick<T: Copy>(field: &mut Vec<T>, arrived: &[T], plan: &[(bool, u32)]) {
            let merged: Vec<T> = plan
                .iter()
                .map(|&(new, k)| match new {
                    true => arrived[k as usize],
                    false => field[k as usize],
                })
                .collect();
            *field = merged;
        }
        pick(&mut self.body1, &arrived.body1, &plan);
        pick(&mut self.body2, &arrived.body2, &plan);
        pick(&mut self.point, &arrived.point, &plan);
        pick(&mut self.frame, &arrived.frame, &plan);
        pick(&mut self.gap, &arrived.gap, &plan);
        pick(&mut self.mu, &arrived.mu, &plan);
        pick(&mut self.impulse, &arrived.impulse, &plan);
        pick(&mut self.status, &arrived.status, &plan);
        pick(&mut self.local_point, &arrived.local_point, &plan);
        seconds
    }
}

/// Calls `each` with every rank's records of `len` values, bodies first, from `all` as
/// gathered (`counts` values per rank), in pair order. Each rank's come in pair order and a
/// pair is one rank's: merged by pair, they come in a single process's order.
fn in_pair_order(all: &[f64], counts: &[usize], len: usize, mut each: impl FnMut(&[f64])) {
    let mut lists: Vec<&[f64]> = Vec::with_capacity(counts.len());
    let mut at = 0;
    for &n in counts {
        lists.push(&all[at..at + n]);
        at += n;
    }
    let key = |x: &[f64]| {
        let (a, b) = (x[0] as u32, x[1] as u32);
        (a.min(b), a.max(b))
    };
    while let Some(r) = (0..lists.len())
        .filter(|&r| !lists[r].is_empty())
        .min_by_key(|&r| key(lists[r]))
    {
        // The whole pair: its records stay together and in order.
        let pair = key(lists[r]);
        while !lists[r].is_empty() && key(lists[r]) == pair {
            each(&lists[r][..len]);
            lists[r] = &lists[r][len..];
        }
    }
}

/// Appends contact `k`'s [`VALUES`] values to `out`.
fn put(c: &ContactSet, k: usize, out: &mut Vec<f64>) {
    let v = |d: DVec3| [d.x, d.y, d.z];
    out.extend_from_slice(&[f64::from(c.body1[k]), f64::from(c.body2[k])]);
    out.extend_from_slice(&v(c.point[k]));
    for d in c.frame[k] {
        out.extend_from_slice(&v(d));
    }
    out.extend_from_slice(&[c.gap[k], c.mu[k]]);
    out.extend_from_slice(&v(c.impulse[k]));
    out.push(c.status[k].code());
    out.extend_from_slice(&v(c.local_point[k]));
}

/// Appends the contact of values `x` (written by [`put`]) to `out`.
fn take(x: &[f64], out: &mut ContactSet) {
    let v = |i: usize| DVec3::new(x[i], x[i + 1], x[i + 2]);
    out.body1.push(x[0] as u32);
    out.body2.push(x[1] as u32);
    out.point.push(v(2));
    out.frame.push([v(5), v(8), v(11)]);
    out.gap.push(x[14]);
    out.mu.push(x[15]);
    out.impulse.push(v(16));
    out.status.push(ContactStatus::from_code(x[19]));
    out.local_point.push(v(20));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A contact round-trips exactly through its gathered values.
    #[test]
    fn contacts_round_trip() {
        let mut c = ContactSet::default();
        c.body1.push(4_000_000_000);
        c.body2.push(7);
        c.point.push(DVec3::new(1.0 / 3.0, -2.0, 7e8));
        c.frame.push([
            DVec3::X,
            DVec3::new(0.0, 0.6, 0.8),
            DVec3::new(1e-300, -0.8, 0.6),
        ]);
        c.gap.push(-1.25e-4);
        c.mu.push(0.8);
        c.impulse.push(DVec3::new(3.5, -0.0, 1e-9));
        c.status.push(ContactStatus::Slide);
        c.local_point.push(DVec3::new(0.01, 0.02, -0.03));
        let mut x = Vec::new();
        put(&c, 0, &mut x);
        assert_eq!(x.len(), VALUES);
        let mut back = ContactSet::default();
        take(&x, &mut back);
        let mut y = Vec::new();
        put(&back, 0, &mut y);
        assert_eq!(
            x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            y.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(back.status[0], ContactStatus::Slide);
    }
}
