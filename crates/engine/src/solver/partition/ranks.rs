//! The partition's cuts found by ranks that each count a part of the bodies: no rank reads
//! the positions of bodies it does not count.
//!
//! One process cuts each axis at weighted quantiles of the dynamic bodies' centres
//! (`Balance::Contacts`: each body weighs `1 + its contacts`) or uniformly over their extent
//! (`Balance::Volume`). Shared between ranks, each rank counts each dynamic body it owns once
//! and each body of each contact it holds once more; the ranks together count every body and
//! every contact once. A quantile is then found by a distributed radix select: every body has
//! a 96-bit key, its coordinate's bits in total order then its index, which orders the bodies
//! as one process sorts them; the key of the body where the cumulated weight crosses the
//! quantile is narrowed 8 bits a round, each round one sum over the ranks of a 256-bin
//! histogram of the weights in the range left. Weights are counts, whole numbers, so every sum
//! is exact in whatever order the ranks add: the cuts are one process's, bit for bit. 13
//! collectives a step, of 256 values per quantile still open.

use super::{box_of, Balance, STATIC};
use crate::math::DVec3;
use crate::solver::exchange::{gather_equal, gather_varying, Exchange};

/// Bits of a key: the coordinate's 64, then the body's index's 32.
const KEY_BITS: u32 = 96;
/// Bits narrowed per round.
const DIGIT: u32 = 8;
const BINS: usize = 1 << DIGIT;

/// A body's key along an axis: `x`'s bits in the order of [`f64::total_cmp`], then `i`.
fn key(x: f64, i: u32) -> u128 {
    let bits = x.to_bits();
    let ordered = if bits >> 63 == 1 {
        !bits
    } else {
        bits | 1 << 63
    };
    (u128::from(ordered) << 32) | u128::from(i)
}

/// The coordinate a key was made from.
fn coordinate(k: u128) -> f64 {
    let ordered = (k >> 32) as u64;
    f64::from_bits(if ordered >> 63 == 1 {
        ordered & !(1 << 63)
    } else {
        !ordered
    })
}

/// One quantile being narrowed: the keys left are `lo..lo + 2^shift`, of which those below
/// the quantile's body weigh `below` together with every key under `lo`.
#[derive(Clone, Copy, Debug)]
struct Open {
    axis: usize,
    threshold: f64,
    lo: u128,
    shift: u32,
    below: f64,
}

impl Open {
    /// Narrows to the bin where the cumulated weight reaches the threshold.
    fn narrow(&mut self, hist: &[f64]) {
        let mut acc = self.below;
        let mut digit = BINS - 1;
        for (d, &w) in hist.iter().enumerate() {
            if acc + w >= self.threshold {
                digit = d;
                break;
            }
            acc += w;
        }
        self.below = acc;
        self.shift -= DIGIT;
        self.lo += (digit as u128) << self.shift;
    }
}

/// This rank's keyed bodies along an axis, sorted: (key, weight).
fn keyed(positions: &[DVec3], dynamic: &[bool], counts: &[u32], axis: usize) -> Vec<(u128, f64)> {
    let mut items: Vec<(u128, f64)> = (0..positions.len())
        .filter(|&i| dynamic[i] && counts[i] > 0)
        .map(|i| (key(positions[i][axis], i as u32), f64::from(counts[i])))
        .collect();
    items.sort_unstable_by_key(|&(k, _)| k);
    items
}

/// The histogram of `items`' weights in the key range `lo..=hi` over the digit below bit
/// `shift`, added to `hist`.
fn histogram(items: &[(u128, f64)], (lo, hi): (u128, u128), shift: u32, hist: &mut [f64]) {
    let from = items.partition_point(|&(k, _)| k < lo);
    let to = items.partition_point(|&(k, _)| k <= hi);
    for &(k, w) in &items[from..to] {
        hist[((k - lo) >> (shift - DIGIT)) as usize & (BINS - 1)] += w;
    }
}

/// The cuts of [`super::Partition::build`] along each axis (none where `dims[axis]` is 1 or
/// no rank counts a dynamic body), found together by the ranks of `ex` (a collective: every
/// rank calls it at the same point). `counts[i]` is how many times this rank counts body `i`
/// (its own dynamic bodies once, each body of each contact it holds once more); over the
/// ranks, a dynamic body's counts add up to `1 + its contacts`, and every dynamic body has
/// one. Only dynamic bodies are read.
pub(crate) fn shared_cuts(
    ex: &dyn Exchange,
    positions: &[DVec3],
    dynamic: &[bool],
    counts: &[u32],
    dims: [usize; 3],
    balance: Balance,
) -> [Vec<f64>; 3] {
    let mut cuts: [Vec<f64>; 3] = Default::default();
    let axes: Vec<usize> = (0..3).filter(|&a| dims[a] > 1).collect();
    if axes.is_empty() {
        return cuts;
    }
    let counted = |i: usize| dynamic[i] && counts[i] > 0;
    if balance == Balance::Volume {
        // Each rank's extent and count, then the smallest, largest and sum over the ranks
        // (cut wherever a dynamic body is, as one process does, even from non-finite extents).
        let mut mine = Vec::with_capacity(3 * axes.len());
        let count = (0..positions.len()).filter(|&i| counted(i)).count() as f64;
        for &a in &axes {
            let (lo, hi) = (0..positions.len())
                .filter(|&i| counted(i))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), i| {
                    (lo.min(positions[i][a]), hi.max(positions[i][a]))
                });
            mine.extend([lo, hi, count]);
        }
        let (size, all) = (ex.size(), gather_equal(ex, &mine));
        for (j, &a) in axes.iter().enumerate() {
            let (mut lo, mut hi, mut count) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
            for r in 0..size {
                let x = &all[r * mine.len() + 3 * j..r * mine.len() + 3 * j + 3];
                (lo, hi, count) = (lo.min(x[0]), hi.max(x[1]), count + x[2]);
            }
            if count > 0.0 {
                cuts[a] = super::uniform_cuts(lo, hi, dims[a]);
            }
        }
        return cuts;
    }

    let items: Vec<Vec<(u128, f64)>> = (0..3)
        .map(|a| match dims[a] > 1 {
            true => keyed(positions, dynamic, counts, a),
            false => Vec::new(),
        })
        .collect();
    // Round 0: each axis's whole key range; its sum is the axis's total weight.
    let whole = (0, u128::MAX >> (128 - KEY_BITS));
    let mut hist = vec![0.0; axes.len() * BINS];
    for (j, &a) in axes.iter().enumerate() {
        histogram(
            &items[a],
            whole,
            KEY_BITS,
            &mut hist[j * BINS..(j + 1) * BINS],
        );
    }
    ex.sum_counts(&mut hist);
    let mut open = Vec::new();
    for (j, &a) in axes.iter().enumerate() {
        let h = &hist[j * BINS..(j + 1) * BINS];
        // Summed in bin order: the total one process sums in body order (whole numbers).
        let total: f64 = h.iter().sum();
        if total == 0.0 {
            continue;
        }
        let parts = dims[a];
        for p in 1..parts {
            let mut q = Open {
                axis: a,
                threshold: total * p as f64 / parts as f64,
                lo: 0,
                shift: KEY_BITS,
                below: 0.0,
            };
            q.narrow(h);
            open.push(q);
        }
    }
    // Rounds 1–11: quantiles in the same range share one histogram.
    while open.first().is_some_and(|q| q.shift > 0) {
        let mut ranges: Vec<(usize, u128)> = open.iter().map(|q| (q.axis, q.lo)).collect();
        ranges.dedup();
        let shift = open[0].shift;
        let mut hist = vec![0.0; ranges.len() * BINS];
        for (j, &(a, lo)) in ranges.iter().enumerate() {
            let range = (lo, lo + ((1u128 << shift) - 1));
            histogram(&items[a], range, shift, &mut hist[j * BINS..(j + 1) * BINS]);
        }
        ex.sum_counts(&mut hist);
        for q in &mut open {
            let j = ranges
                .iter()
                .position(|&r| r == (q.axis, q.lo))
                .expect("every open quantile's range has a histogram");
            q.narrow(&hist[j * BINS..(j + 1) * BINS]);
        }
    }
    // The body after each quantile's (the least key above it over the ranks): the cut is
    // midway between their centres, or infinite after the last body.
    const NONE: [f64; 4] = [0.0; 4];
    let mut mine = Vec::with_capacity(4 * open.len());
    for q in &open {
        let items = &items[q.axis];
        let next = items.partition_point(|&(key, _)| key <= q.lo);
        mine.extend(match items.get(next) {
            Some(&(n, _)) => [
                1.0,
                (n >> 64) as u32 as f64,
                (n >> 32) as u32 as f64,
                n as u32 as f64,
            ],
            None => NONE,
        });
    }
    let (size, all) = (ex.size(), gather_equal(ex, &mine));
    for (j, q) in open.iter().enumerate() {
        let next = (0..size)
            .map(|r| &all[r * mine.len() + 4 * j..r * mine.len() + 4 * j + 4])
            .filter(|v| v[0] == 1.0)
            .map(|v| (v[1] as u128) << 64 | (v[2] as u128) << 32 | v[3] as u128)
            .min();
        cuts[q.axis].push(match next {
            Some(n) => 0.5 * (coordinate(q.lo) + coordinate(n)),
            None => f64::INFINITY,
        });
    }
    cuts
}

/// Every body's subdomain under `cuts`, as [`super::Partition::from_cuts`] places them,
/// found together by the ranks of `ex` (a collective): each rank places the bodies it owns
/// (`owned`; every body is owned by one rank), reading no other position, and the ranks
/// share those whose subdomain differs from `previous` (the last partition's, the same on
/// every rank; [`STATIC`] where there was none).
pub(crate) fn shared_subdomains(
    ex: &dyn Exchange,
    positions: &[DVec3],
    dynamic: &[bool],
    dims: [usize; 3],
    cuts: &[Vec<f64>; 3],
    owned: impl Fn(usize) -> bool,
    previous: impl Fn(usize) -> u32,
) -> Vec<u32> {
    let n = positions.len();
    let mut moved = Vec::new();
    for i in (0..n).filter(|&i| owned(i)) {
        let s = match dynamic[i] {
            true => box_of(positions[i], dims, cuts),
            false => STATIC,
        };
        if s != previous(i) {
            moved.extend([i as f64, f64::from(s)]);
        }
    }
    let mut subdomain: Vec<u32> = (0..n).map(previous).collect();
    for m in gather_varying(ex, &moved).0.chunks_exact(2) {
        subdomain[m[0] as usize] = m[1] as u32;
    }
    subdomain
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::exchange::ThreadRanks;
    use crate::solver::partition::Partition;

    #[test]
    fn keys_order_as_total_cmp_then_index() {
        let xs = [
            f64::NEG_INFINITY,
            -3.5,
            -1e-300,
            -0.0,
            0.0,
            1e-300,
            2.0,
            2.0,
            f64::INFINITY,
        ];
        for (a, &x) in xs.iter().enumerate() {
            assert_eq!(coordinate(key(x, 7)).to_bits(), x.to_bits());
            for (b, &y) in xs.iter().enumerate() {
                let (i, j) = (a as u32, b as u32);
                let want = x.total_cmp(&y).then(i.cmp(&j));
                assert_eq!(key(x, i).cmp(&key(y, j)), want, "{x} #{i} against {y} #{j}");
            }
        }
    }

    proptest::proptest! {
        /// The ranks' cuts and subdomains are one process's, bit for bit: random centres
        /// (some sharing a coordinate, some on the same spot, some not finite), random
        /// contacts, random dynamic bodies, the bodies and contacts dealt at random among 1–4
        /// ranks, each rank knowing only the centres of the bodies it owns or holds a contact
        /// of, all starting from a random last partition.
        #[test]
        fn ranks_cut_where_one_process_does(
            seed in 0u64..1_000_000,
            n in 0usize..200,
            contacts in 0usize..400,
            size in 1usize..5,
            volume in proptest::bool::ANY,
        ) {
            let mut state = seed;
            let mut next = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            // A diverged scene too (every seventh seed): non-finite centres, one axis all NaN.
            let diverged = seed % 7 == 0;
            let positions: Vec<DVec3> = (0..n)
                .map(|i| match i % 9 {
                    4 => DVec3::new(0.25, -0.5, 0.0),
                    5 => DVec3::new(next() - 0.5, 0.25, 1.5),
                    8 if diverged => DVec3::new(f64::NAN, f64::INFINITY, f64::NAN),
                    _ => DVec3::new(next() - 0.5, 3.0 * next() - 2.0, next() * 1e-3),
                })
                .map(|p| if diverged { DVec3::new(p.x, p.y, f64::NAN) } else { p })
                .collect();
            let dynamic: Vec<bool> = (0..n).map(|_| next() < 0.9).collect();
            let pairs: Vec<(usize, usize)> = (0..contacts.min(n * n))
                .filter_map(|_| {
                    let (a, b) = ((next() * n as f64) as usize, (next() * n as f64) as usize);
                    (a != b).then_some((a, b))
                })
                .collect();
            let mut weights = vec![1.0; n];
            for &(a, b) in &pairs {
                weights[a] += 1.0;
                weights[b] += 1.0;
            }
            let owner: Vec<usize> = (0..n).map(|_| (next() * size as f64) as usize).collect();
            let holder: Vec<usize> = pairs.iter().map(|_| (next() * size as f64) as usize).collect();
            // The last partition's subdomains (any, the same on every rank).
            let previous: Vec<u32> = (0..n)
                .map(|_| match next() {
                    x if x < 0.3 => STATIC,
                    x => (x * 7.0) as u32,
                })
                .collect();
            let balance = if volume { Balance::Volume } else { Balance::Contacts };
            for dims in [[3, 1, 1], [1, 4, 2], [2, 2, 2], [1, 1, 1], [7, 1, 1]] {
                let one = Partition::build(&positions, &dynamic, dims, balance, &weights);
                let results: Vec<Partition> = std::thread::scope(|s| {
                    let handles: Vec<_> = ThreadRanks::group(size)
                        .into_iter()
                        .map(|ex| {
                            let (positions, dynamic) = (&positions, &dynamic);
                            let (owner, holder, pairs) = (&owner, &holder, &pairs);
                            let previous = &previous;
                            s.spawn(move || {
                                let r = ex.rank();
                                let mut counts = vec![0u32; n];
                                for i in (0..n).filter(|&i| owner[i] == r) {
                                    counts[i] += 1;
                                }
                                for (&(a, b), _) in pairs.iter().zip(holder).filter(|(_, &h)| h == r) {
                                    counts[a] += 1;
                                    counts[b] += 1;
                                }
                                // What this rank neither owns nor holds a contact of, it does
                                // not know.
                                let mine: Vec<DVec3> = (0..n)
                                    .map(|i| match owner[i] == r || counts[i] > 0 {
                                        true => positions[i],
                                        false => DVec3::new(-7.0, f64::NAN, 1e300),
                                    })
                                    .collect();
                                let cuts = shared_cuts(&ex, &mine, dynamic, &counts, dims, balance);
                                let subdomain = shared_subdomains(
                                    &ex,
                                    &mine,
                                    dynamic,
                                    dims,
                                    &cuts,
                                    |i| owner[i] == r,
                                    |i| previous[i],
                                );
                                Partition::from_subdomains(dims, subdomain)
                            })
                        })
                        .collect();
                    handles.into_iter().map(|h| h.join().expect("a rank panicked")).collect()
                });
                for p in &results {
                    proptest::prop_assert_eq!(p, &one);
                }
            }
        }
    }
}
