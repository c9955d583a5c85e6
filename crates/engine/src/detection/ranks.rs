//! The narrow phase divided between the ranks of a distributed run (see
//! [`crate::solver::exchange`]): every rank holds the same bodies, finds the same candidate
//! pairs and reuses the same manifolds; each pair left to test goes to the rank that holds it
//! (see [`crate::solver::exchange::PairOwners`]), each rank tests its pairs, and an all-gather
//! gives every rank every outcome. An outcome is the same whichever rank computes it, so detection is bit-identical
//! to one process.

use super::{FaceHint, ManifoldPoint, Outcomes, PairGeometry};
use crate::math::DVec3;
use crate::solver::Exchange;
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

/// The outcomes of `pairs` into `results`: `reused(k)` for each pair whose manifold is reused
/// (every rank), `compute(k)` for the pairs to test that this rank holds (`holder(k)`, the
/// pair's rank; without one, contiguous shares of the pairs to test), the rest from the ranks
/// that computed them. Returns the seconds spent sharing.
pub(super) fn narrow_on_ranks(
    ex: &dyn Exchange,
    pairs: usize,
    holder: Option<&(dyn Fn(usize) -> usize + Sync)>,
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
    // Each pair to test goes to its rank.
    let (me, size) = (ex.rank(), ex.size());
    let rank_of: Vec<u32> = match holder {
        Some(h) => todo.par_iter().map(|&k| h(k as usize) as u32).collect(),
        None => (0..todo.len())
            .map(|i| (i * size / todo.len().max(1)) as u32)
            .collect(),
    };
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
    // Each rank's number of values first: outcomes have different lengths.
    let mut counts = vec![0.0; size];
    ex.all_gather(&[send.len() as f64], &vec![1; size], &mut counts);
    let counts: Vec<usize> = counts.iter().map(|&c| c as usize).collect();
    let mut all = vec![0.0; counts.iter().sum()];
    ex.all_gather(&send, &counts, &mut all);
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
