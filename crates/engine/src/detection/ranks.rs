//! The narrow phase of a distributed run (see [`crate::solver::exchange`]). Every rank holds
//! the same bodies and finds the same candidate pairs. In a domain-decomposed run each rank
//! keeps the pairs it holds ([`keep_own`]) and tests, reuses and keeps their outcomes only;
//! the outcomes of pairs that change rank move with them ([`Detector::migrate`]). Without
//! domain decomposition every rank solves the whole step: the pairs left to test are cut
//! into one contiguous share per rank, each rank tests its share, and an all-gather gives
//! every rank every outcome ([`narrow_on_ranks`]). An outcome is the same whichever rank
//! computes it, so detection is bit-identical to one process.

use super::{Detector, FaceHint, ManifoldPoint, Outcomes, PairGeometry};
use crate::math::DVec3;
use crate::solver::exchange::PairOwners;
use crate::solver::{exchange, Exchange};
use rayon::prelude::*;
use std::time::Instant;

/// Values of a shared outcome before its manifold: bodies, point count, hint, reusable.
const HEAD: usize = 5;

/// Appends outcome `g` to `out`: its head, then, when it has points, the normal and each
/// point's position and gap (a pair that is apart, about half of those tested, sends five
/// values instead of twenty-five).
fn put(g: &PairGeometry, out: &mut Vec<f64>) {
    out.extend_from_slice(&[
        f64::from(g.body1),
        f64::from(g.body2),
        f64::from(g.len),
        f64::from(g.hint.to_bits()),
        f64::from(u8::from(g.reusable)),
    ]);
    if g.len > 0 {
        out.extend_from_slice(&[g.normal.x, g.normal.y, g.normal.z]);
        for p in g.points() {
            out.extend_from_slice(&[p.point.x, p.point.y, p.point.z, p.gap]);
        }
    }
}

/// The outcome at the start of `x` (written by [`put`]) and the number of values it took.
fn take(x: &[f64]) -> (PairGeometry, usize) {
    let mut g = PairGeometry::new(
        x[0] as u32,
        x[1] as u32,
        None,
        FaceHint::from_bits(x[3] as u32),
    );
    g.len = x[2] as u8;
    g.reusable = x[4] == 1.0;
    let mut at = HEAD;
    if g.len > 0 {
        g.normal = DVec3::new(x[at], x[at + 1], x[at + 2]);
        at += 3;
        for p in &mut g.points[..g.len as usize] {
            *p = ManifoldPoint {
                point: DVec3::new(x[at], x[at + 1], x[at + 2]),
                gap: x[at + 3],
            };
            at += 4;
        }
    }
    (g, at)
}

/// Number of values of the outcome at the start of `x` (written by [`put`]).
fn length(x: &[f64]) -> usize {
    match x[2] as usize {
        0 => HEAD,
        n => HEAD + 3 + 4 * n,
    }
}

/// Keeps, of the candidate `pairs` (sorted), those this rank holds: `owners`' rule, or
/// before the first solve contiguous shares of the list.
pub(super) fn keep_own(
    ex: &dyn Exchange,
    owners: Option<&PairOwners>,
    pairs: &mut Vec<(u32, u32)>,
) {
    let (me, size, n) = (ex.rank(), ex.size(), pairs.len());
    match owners {
        Some(o) => {
            let own: Vec<bool> = pairs.par_iter().map(|&(i, j)| o.of(i, j) == me).collect();
            let mut k = 0;
            pairs.retain(|_| {
                k += 1;
                own[k - 1]
            });
        }
        None => {
            pairs.truncate((me + 1) * n / size);
            pairs.drain(..me * n / size);
        }
    }
}

impl Detector {
    /// Hands the outcomes of this rank's pairs that `owners` gives to other ranks to them,
    /// and takes in those they hand it: afterwards each rank keeps, in pair order, the
    /// outcomes of the pairs it holds — what its next detection reuses (a collective). Returns
    /// the seconds spent sharing.
    pub(crate) fn migrate(&mut self, ex: &dyn Exchange, owners: &PairOwners) -> f64 {
        let me = ex.rank();
        let holder: Vec<usize> = self
            .pairs
            .par_iter()
            .map(|&(i, j)| owners.of(i, j))
            .collect();
        let mut send = Vec::new();
        for (l, &h) in holder.iter().enumerate() {
            if h != me {
                send.push(h as f64);
                put(&self.results.get(l), &mut send);
            }
        }
        let t = Instant::now();
        let (all, _) = exchange::gather_varying(ex, &send);
        let seconds = t.elapsed().as_secs_f64();
        let mut arrived: Vec<PairGeometry> = Vec::new();
        let mut at = 0;
        while at < all.len() {
            let to = all[at] as usize;
            let (g, used) = take(&all[at + 1..]);
            if to == me {
                arrived.push(g);
            }
            at += 1 + used;
        }
        if send.is_empty() && arrived.is_empty() {
            return seconds;
        }
        let key = |g: &PairGeometry| (g.body1.min(g.body2), g.body1.max(g.body2));
        // From several ranks, each in pair order; no pair twice (each had one holder).
        arrived.sort_by_key(key);
        // The kept and the arrived outcomes, merged in pair order.
        enum From {
            Kept(usize),
            Arrived(usize),
        }
        let mut order = Vec::with_capacity(self.pairs.len() + arrived.len());
        let mut pairs = std::mem::take(&mut self.spare_pairs);
        pairs.clear();
        let mut a = arrived.iter().enumerate().peekable();
        for (l, &pair) in self.pairs.iter().enumerate() {
            if holder[l] != me {
                continue;
            }
            while let Some((i, g)) = a.next_if(|(_, g)| key(g) < pair) {
                order.push(From::Arrived(i));
                pairs.push(key(g));
            }
            order.push(From::Kept(l));
            pairs.push(pair);
        }
        for (i, g) in a {
            order.push(From::Arrived(i));
            pairs.push(key(g));
        }
        let mut results = std::mem::take(&mut self.spare_results);
        let old = &self.results;
        results.assemble(order.len(), |range, push| {
            for o in &order[range] {
                push(match *o {
                    From::Kept(l) => old.get(l),
                    From::Arrived(i) => arrived[i],
                });
            }
        });
        self.spare_pairs = std::mem::replace(&mut self.pairs, pairs);
        self.spare_results = std::mem::replace(&mut self.results, results);
        seconds
    }
}

/// The outcomes of `pairs` into `results`: `reused(k)` for each pair whose manifold is reused
/// (every rank), `compute(k)` for this rank's contiguous share of the others, the rest from
/// the ranks that computed them. Returns the seconds spent sharing.
pub(super) fn narrow_on_ranks(
    ex: &dyn Exchange,
    pairs: usize,
    reused: impl Fn(usize) -> Option<PairGeometry> + Sync,
    compute: impl Fn(usize) -> PairGeometry + Sync,
    results: &mut Outcomes,
) -> f64 {
    // The reused outcomes first (a pair to test is marked by its `reused` flag, false).
    let blank = PairGeometry::new(0, 0, None, FaceHint::NONE);
    let mut first = Outcomes::default();
    first.assemble(pairs, |range, push| {
        range.for_each(|k| push(reused(k).unwrap_or(blank)));
    });
    let todo: Vec<u32> = first
        .heads()
        .par_iter()
        .enumerate()
        .filter(|(_, h)| !h.reused)
        .map(|(k, _)| k as u32)
        .collect();
    // Contiguous shares of the pairs to test, one per rank.
    let (me, size) = (ex.rank(), ex.size());
    let rank_of: Vec<u32> = (0..todo.len())
        .map(|i| (i * size / todo.len().max(1)) as u32)
        .collect();
    let mine: Vec<u32> = todo
        .iter()
        .zip(&rank_of)
        .filter(|(_, &r)| r as usize == me)
        .map(|(&k, _)| k)
        .collect();
    let computed: Vec<PairGeometry> = mine.par_iter().map(|&k| compute(k as usize)).collect();
    drop(mine);
    let t = Instant::now();
    let mut send = Vec::with_capacity(computed.len() * HEAD);
    for g in &computed {
        put(g, &mut send);
    }
    drop(computed);
    // Outcomes have different lengths.
    let (all, counts) = exchange::gather_varying(ex, &send);
    drop(send);
    // The ranks' outcomes follow one another, each rank's in `todo`'s order: where each
    // outcome starts.
    let mut cursor: Vec<usize> = counts
        .iter()
        .scan(0, |at, &c| {
            let start = *at;
            *at += c;
            Some(start)
        })
        .collect();
    let mut at = Vec::with_capacity(todo.len());
    for &r in &rank_of {
        let c = &mut cursor[r as usize];
        at.push(*c);
        *c += length(&all[*c..]);
    }
    debug_assert!(cursor
        .iter()
        .zip(counts.iter().scan(0, |e, &c| {
            *e += c;
            Some(*e)
        }))
        .all(|(&c, e)| c == e));
    let shared = t.elapsed().as_secs_f64();
    results.assemble(pairs, |range, push| {
        let mut i = todo.partition_point(|&k| (k as usize) < range.start);
        for k in range {
            if todo.get(i) == Some(&(k as u32)) {
                push(take(&all[at[i]..]).0);
                i += 1;
            } else {
                push(first.get(k));
            }
        }
    });
    shared
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An outcome round-trips exactly through its shared values.
    #[test]
    fn outcomes_round_trip() {
        let mut g = PairGeometry::new(7, 4_000_000_000, None, FaceHint::new(true, 17));
        g.normal = DVec3::new(0.6, -0.8, 1e-300);
        g.len = 3;
        g.points[2] = ManifoldPoint {
            point: DVec3::new(1.0 / 3.0, -2.5, 7e8),
            gap: -1.25e-4,
        };
        g.reusable = true;
        let mut x = Vec::new();
        put(&g, &mut x);
        assert_eq!(x.len(), HEAD + 3 + 4 * 3);
        // Followed by another outcome, apart: each is read back whole, and only itself.
        let apart = PairGeometry::new(3, 9, None, FaceHint::new(false, 4));
        put(&apart, &mut x);
        assert_eq!(x.len(), 2 * HEAD + 3 + 4 * 3);
        let (h, used) = take(&x);
        assert_eq!(used, HEAD + 3 + 4 * 3);
        assert_eq!((length(&x), length(&x[used..])), (used, HEAD));
        let (a, rest) = take(&x[used..]);
        assert_eq!(
            (a.body1, a.body2, a.len, a.hint, rest),
            (3, 9, 0, apart.hint, HEAD)
        );
        let mut y = Vec::new();
        put(&h, &mut y);
        put(&a, &mut y);
        assert_eq!(
            x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            y.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(
            (h.hint, h.reused, h.reusable, h.len),
            (g.hint, false, true, 3)
        );
    }
}
