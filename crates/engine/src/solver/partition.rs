//! Primal geometric partition of the bodies into `nx × ny × nz` subdomains (the paper's §2.2).
//!
//! A dynamic body belongs to the box that holds its centre of mass. Box boundaries are either
//! uniform over the bounding box of the dynamic bodies' centres (`Volume`, the paper's choice),
//! or, per axis, weighted quantiles of the centres with weight `1 + contacts of the body`
//! (`Contacts`): each slab then carries the same number of contacts, so the subdomains' work is
//! balanced; recomputed every step, it follows the grains as they move. Kinematic and fixed
//! bodies belong to no subdomain: their velocities are imposed, every subdomain reads them and
//! none writes them, so a contact with a wall stays inside its grain's subdomain.
//!
//! Bodies are renumbered so that each subdomain's bodies are contiguous (then the static
//! bodies): subdomains own disjoint slices of the solver's body array. The partition depends on
//! the scene only, never on the number of threads.
//!
//! Ranks sharing a run find the same cuts together, each from the bodies it owns and the
//! contacts it holds (a radix select over sums of per-rank histograms), bit for bit those of
//! one process; each rank then places the bodies it owns, and the ranks share the bodies
//! that changed subdomain.

use crate::math::DVec3;
use serde::{Deserialize, Serialize};

mod ranks;
pub(crate) use ranks::{shared_cuts, shared_subdomains};

/// Marks a body that belongs to no subdomain (kinematic or fixed).
pub const STATIC: u32 = u32::MAX;

/// The solver index of a body that a rank's own numbering of a solve leaves out.
pub const LEFT_OUT: u32 = u32::MAX;

/// How box boundaries are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Balance {
    /// Uniform boxes over the bounding box of the grains (the paper).
    Volume,
    /// Per-axis quantiles weighted by contact count (balanced work).
    Contacts,
}

/// A partition of the bodies into subdomains, with the solver numbering.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Partition {
    /// `[nx, ny, nz]`.
    pub dims: [usize; 3],
    /// Subdomain of each body ([`STATIC`] for non-dynamic bodies).
    pub subdomain: Vec<u32>,
    /// Solver index of each body.
    pub new_index: Vec<u32>,
    /// Bodies in solver order (inverse of `new_index`).
    pub order: Vec<u32>,
    /// `starts[e]..starts[e + 1]` are subdomain `e`'s bodies in solver order;
    /// `starts[count]..` are the static bodies.
    pub starts: Vec<usize>,
}

impl Partition {
    /// Number of subdomains.
    pub fn count(&self) -> usize {
        self.dims.iter().product()
    }

    /// Builds the partition. `weights[i]` (used by `Balance::Contacts`) is body `i`'s work.
    pub fn build(
        positions: &[DVec3],
        dynamic: &[bool],
        dims: [usize; 3],
        balance: Balance,
        weights: &[f64],
    ) -> Self {
        Self::build_from(
            positions,
            dynamic,
            dims,
            balance,
            weights,
            &mut SortedAxes::default(),
        )
    }

    /// [`Partition::build`] starting from the orders of the bodies along the axes that the
    /// last call left in `sorted`: the bodies move little between steps, so the orders are
    /// repaired instead of sorted afresh. The same partition whatever `sorted` holds.
    pub(crate) fn build_from(
        positions: &[DVec3],
        dynamic: &[bool],
        dims: [usize; 3],
        balance: Balance,
        weights: &[f64],
        sorted: &mut SortedAxes,
    ) -> Self {
        let n = positions.len();
        let dyn_ids: Vec<usize> = (0..n).filter(|&i| dynamic[i]).collect();
        let cut = |axis: usize, order: &mut Vec<u32>| {
            if dims[axis] <= 1 || dyn_ids.is_empty() {
                return Vec::new();
            }
            match balance {
                Balance::Volume => volume_cuts(positions, &dyn_ids, axis, dims[axis]),
                Balance::Contacts => {
                    sort_along(positions, dynamic, &dyn_ids, axis, order);
                    contact_cuts(positions, order, axis, dims[axis], weights)
                }
            }
        };
        // The axes are independent: each sorts its own order, on its own thread.
        let [ox, oy, oz] = &mut sorted.0;
        let ((cx, cy), cz) =
            rayon::join(|| rayon::join(|| cut(0, ox), || cut(1, oy)), || cut(2, oz));
        Self::from_cuts(positions, dynamic, dims, &[cx, cy, cz])
    }

    /// The partition whose boxes are cut along each axis at `cuts[axis]` (`dims[axis] − 1`
    /// increasing values, or none: one box along that axis): each dynamic body in the box of
    /// its centre, a cut's own coordinate in the box above it.
    pub(crate) fn from_cuts(
        positions: &[DVec3],
        dynamic: &[bool],
        dims: [usize; 3],
        cuts: &[Vec<f64>; 3],
    ) -> Self {
        let n = positions.len();
        let mut subdomain = vec![STATIC; n];
        for i in (0..n).filter(|&i| dynamic[i]) {
            subdomain[i] = box_of(positions[i], dims, cuts);
        }
        Self::from_subdomains(dims, subdomain)
    }

    /// The partition of `dims` whose bodies lie in `subdomain` (each body's box, [`STATIC`]
    /// for the bodies of none), numbered for the solver.
    pub(crate) fn from_subdomains(dims: [usize; 3], subdomain: Vec<u32>) -> Self {
        let n = subdomain.len();
        // Counting sort by subdomain (stable: body order within a subdomain).
        let k = dims.iter().product::<usize>();
        let mut starts = vec![0usize; k + 2];
        for &s in &subdomain {
            let slot = if s == STATIC { k } else { s as usize };
            starts[slot + 1] += 1;
        }
        for e in 0..=k {
            starts[e + 1] += starts[e];
        }
        let mut fill = starts.clone();
        let mut order = vec![0u32; n];
        let mut new_index = vec![0u32; n];
        for (i, &s) in subdomain.iter().enumerate() {
            let slot = if s == STATIC { k } else { s as usize };
            order[fill[slot]] = i as u32;
            new_index[i] = fill[slot] as u32;
            fill[slot] += 1;
        }
        starts.pop();
        Partition {
            dims,
            subdomain,
            new_index,
            order,
            starts,
        }
    }
}

impl Partition {
    /// This partition's solver numbering restricted to the solver indices `keep` marks, in the
    /// same order: each subdomain's kept bodies still contiguous, the static ones last. A rank
    /// that solves part of a step numbers by it only the bodies its part reads, so that its
    /// copies of the solver's per-body arrays shrink with the number of ranks. Returns it and
    /// the new index of each old one ([`LEFT_OUT`] for those left out, whose `new_index` is
    /// [`LEFT_OUT`] too).
    pub(crate) fn compact(&self, keep: &[bool]) -> (Partition, Vec<u32>) {
        let mut local = vec![LEFT_OUT; keep.len()];
        let mut order = Vec::new();
        let mut starts = Vec::with_capacity(self.starts.len());
        let mut s = 0;
        for (j, &b) in self.order.iter().enumerate() {
            while s < self.starts.len() && self.starts[s] == j {
                starts.push(order.len());
                s += 1;
            }
            if keep[j] {
                local[j] = order.len() as u32;
                order.push(b);
            }
        }
        starts.resize(self.starts.len(), order.len());
        let new_index = self.new_index.iter().map(|&j| local[j as usize]).collect();
        let compact = Partition {
            dims: self.dims,
            subdomain: self.subdomain.clone(),
            new_index,
            order,
            starts,
        };
        (compact, local)
    }
}

/// The box of `dims` cut at `cuts` that holds `x` (a cut's own coordinate in the box above it;
/// a non-finite coordinate where the comparisons put it).
pub(crate) fn box_of(x: DVec3, dims: [usize; 3], cuts: &[Vec<f64>; 3]) -> u32 {
    let mut idx = [0usize; 3];
    for axis in 0..3 {
        let c = x[axis];
        idx[axis] = cuts[axis]
            .partition_point(|&cut| cut <= c)
            .min(dims[axis] - 1);
    }
    (idx[0] + dims[0] * (idx[1] + dims[1] * idx[2])) as u32
}

/// The orders of the dynamic bodies along each axis (by centre, ties by index) of the last
/// [`Partition::build_from`], kept by the caller between steps.
#[derive(Clone, Debug, Default)]
pub(crate) struct SortedAxes([Vec<u32>; 3]);

/// Insertions beyond this many per body: the order is sorted afresh instead of repaired.
const REPAIR_SHIFTS_PER_BODY: usize = 16;

/// Leaves in `order` the bodies `ids` (ascending, those marked in `dynamic`) sorted by their
/// centre's coordinate `axis`, ties by index. When `order` already holds the same bodies (the
/// last step's order) it is repaired by insertion, which costs one pass when few bodies
/// changed places; else it is sorted afresh. The ordering is total, so the result is the same.
fn sort_along(
    positions: &[DVec3],
    dynamic: &[bool],
    ids: &[usize],
    axis: usize,
    order: &mut Vec<u32>,
) {
    let before = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    let same = order.len() == ids.len() && {
        let mut seen = vec![false; positions.len()];
        order.iter().all(|&i| {
            let i = i as usize;
            let fresh = i < seen.len() && dynamic[i] && !seen[i];
            if fresh {
                seen[i] = true;
            }
            fresh
        })
    };
    let mut keyed: Vec<(f64, u32)> = if same {
        order
            .iter()
            .map(|&i| (positions[i as usize][axis], i))
            .collect()
    } else {
        ids.iter()
            .map(|&i| (positions[i][axis], i as u32))
            .collect()
    };
    let repaired = same && {
        let mut budget = REPAIR_SHIFTS_PER_BODY * keyed.len();
        let mut done = true;
        'outer: for k in 1..keyed.len() {
            let mut j = k;
            while j > 0 && before(&keyed[j], &keyed[j - 1]).is_lt() {
                if budget == 0 {
                    done = false;
                    break 'outer;
                }
                keyed.swap(j, j - 1);
                budget -= 1;
                j -= 1;
            }
        }
        done
    };
    if !repaired {
        keyed.sort_unstable_by(before);
    }
    order.clear();
    order.extend(keyed.iter().map(|&(_, i)| i));
}

/// Uniform interior cuts (`parts − 1` values, increasing) over the bounding interval of the
/// centres of `ids` along `axis`.
fn volume_cuts(positions: &[DVec3], ids: &[usize], axis: usize, parts: usize) -> Vec<f64> {
    let (lo, hi) = ids
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
            (lo.min(positions[i][axis]), hi.max(positions[i][axis]))
        });
    uniform_cuts(lo, hi, parts)
}

/// `parts − 1` cuts evenly spaced in `lo..hi`.
fn uniform_cuts(lo: f64, hi: f64, parts: usize) -> Vec<f64> {
    (1..parts)
        .map(|p| lo + (hi - lo) * p as f64 / parts as f64)
        .collect()
}

/// Interior cuts (`parts − 1` values, increasing) at the weighted quantiles of the bodies
/// `sorted` (by their coordinate `axis`): midway between the two bodies where the cumulated
/// weight crosses each `p / parts` of the total (infinite where the bodies run out).
fn contact_cuts(
    positions: &[DVec3],
    sorted: &[u32],
    axis: usize,
    parts: usize,
    weights: &[f64],
) -> Vec<f64> {
    let weight = |i: u32| weights[i as usize];
    let at = |i: u32| positions[i as usize];
    let total: f64 = sorted.iter().map(|&i| weight(i)).sum();
    let mut cuts = Vec::with_capacity(parts - 1);
    let mut acc = 0.0;
    let mut p = 1;
    for w in sorted.windows(2) {
        acc += weight(w[0]);
        while p < parts && acc >= total * p as f64 / parts as f64 {
            // Cut midway between two consecutive centres.
            cuts.push(0.5 * (at(w[0])[axis] + at(w[1])[axis]));
            p += 1;
        }
    }
    while cuts.len() < parts - 1 {
        cuts.push(f64::INFINITY);
    }
    cuts
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bodies_are_contiguous_and_statics_last() {
        let pos: Vec<DVec3> = (0..40)
            .map(|i| DVec3::new((i * 7 % 40) as f64, 0.0, 0.0))
            .collect();
        let mut dynamic = vec![true; 40];
        dynamic[3] = false;
        dynamic[17] = false;
        let w = vec![1.0; 40];
        for balance in [Balance::Volume, Balance::Contacts] {
            let p = Partition::build(&pos, &dynamic, [4, 1, 1], balance, &w);
            assert_eq!(p.starts.len(), 5);
            assert_eq!(p.starts[4], 38, "two static bodies at the end");
            for e in 0..4 {
                let range = p.starts[e]..p.starts[e + 1];
                assert!(
                    range.len() >= 9,
                    "{balance:?}: subdomain {e} has {} bodies",
                    range.len()
                );
                for k in range {
                    assert_eq!(p.subdomain[p.order[k] as usize], e as u32);
                }
            }
            for i in 0..40 {
                assert_eq!(p.order[p.new_index[i] as usize] as usize, i);
            }
        }
    }

    #[test]
    fn contact_balance_follows_weights() {
        // 100 bodies on a line; the last 20 carry almost all contacts.
        let pos: Vec<DVec3> = (0..100).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        let w: Vec<f64> = (0..100).map(|i| if i >= 80 { 20.0 } else { 1.0 }).collect();
        let p = Partition::build(&pos, &[true; 100], [2, 1, 1], Balance::Contacts, &w);
        let load = |e: usize| {
            (p.starts[e]..p.starts[e + 1])
                .map(|k| w[p.order[k] as usize])
                .sum::<f64>()
        };
        assert!(
            (load(0) - load(1)).abs() <= 20.0,
            "{} vs {}",
            load(0),
            load(1)
        );
        let q = Partition::build(&pos, &[true; 100], [2, 1, 1], Balance::Volume, &w);
        assert_eq!(q.starts[1], 50);
    }

    proptest::proptest! {
        /// A rank's numbering keeps the kept bodies in the partition's order, each subdomain's
        /// (and the static ones) together in its own range, and maps each body to its place
        /// there or leaves it out.
        #[test]
        fn a_compact_numbering_is_the_partitions_restricted(
            subdomain in proptest::collection::vec(proptest::prop_oneof![0u32..6, proptest::strategy::Just(STATIC)], 0..200),
            keep_seed in proptest::collection::vec(proptest::bool::ANY, 200),
        ) {
            let whole = Partition::from_subdomains([3, 2, 1], subdomain.clone());
            let keep: Vec<bool> = (0..subdomain.len()).map(|j| keep_seed[j]).collect();
            let (part, local) = whole.compact(&keep);
            let kept: Vec<u32> = (0..whole.order.len())
                .filter(|&j| keep[j])
                .map(|j| whole.order[j])
                .collect();
            proptest::prop_assert_eq!(&part.order, &kept);
            proptest::prop_assert_eq!(part.starts.len(), whole.starts.len());
            for (s, w) in part.starts.windows(2).enumerate() {
                for &i in &part.order[w[0]..w[1]] {
                    proptest::prop_assert_eq!(subdomain[i as usize], s as u32);
                }
            }
            for &i in &part.order[part.starts[6]..] {
                proptest::prop_assert_eq!(subdomain[i as usize], STATIC);
            }
            for (i, &j) in whole.new_index.iter().enumerate() {
                let l = part.new_index[i];
                proptest::prop_assert_eq!(l, local[j as usize]);
                if keep[j as usize] {
                    proptest::prop_assert_eq!(part.order[l as usize], i as u32);
                } else {
                    proptest::prop_assert_eq!(l, LEFT_OUT);
                }
            }
        }

        /// A partition built from the orders left by another scene (moved bodies, another
        /// dynamic set, or none at all) is the partition built afresh, whatever the number of
        /// bodies that changed places (few: repaired; many: sorted again).
        #[test]
        fn orders_kept_between_steps_change_nothing(
            seed in 0u64..1_000_000,
            n in 1usize..300,
            jitter in proptest::prop_oneof![proptest::strategy::Just(1e-4), proptest::strategy::Just(0.5)],
            drop_one in proptest::bool::ANY,
        ) {
            let mut state = seed;
            let mut next = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let before: Vec<DVec3> = (0..n).map(|_| DVec3::new(next(), next(), next())).collect();
            // Ties along an axis are broken by index: give some bodies equal coordinates.
            let after: Vec<DVec3> = before
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let d = DVec3::new(next(), next(), next()) - 0.5;
                    if i % 7 == 3 { DVec3::new(0.5, p.y, 0.5) } else { *p + d * jitter }
                })
                .collect();
            let weights: Vec<f64> = (0..n).map(|_| 1.0 + (10.0 * next()).floor()).collect();
            let mut dynamic = vec![true; n];
            let mut dynamic_after = dynamic.clone();
            if drop_one {
                dynamic_after[n / 2] = false;
            }
            dynamic[0] = n == 1 || next() < 0.9;
            for dims in [[3, 2, 1], [1, 1, 4], [2, 2, 2]] {
                let mut sorted = SortedAxes::default();
                let b = Partition::build_from(&before, &dynamic, dims, Balance::Contacts, &weights, &mut sorted);
                proptest::prop_assert_eq!(&b, &Partition::build(&before, &dynamic, dims, Balance::Contacts, &weights));
                let a = Partition::build_from(&after, &dynamic_after, dims, Balance::Contacts, &weights, &mut sorted);
                proptest::prop_assert_eq!(&a, &Partition::build(&after, &dynamic_after, dims, Balance::Contacts, &weights));
                // The orders left are the sorted orders of the dynamic bodies.
                let count = dynamic_after.iter().filter(|&&d| d).count();
                for axis in (0..3).filter(|&axis| dims[axis] > 1 && count > 0) {
                    let order = &sorted.0[axis];
                    proptest::prop_assert_eq!(order.len(), count);
                    for w in order.windows(2) {
                        let (p, q) = (after[w[0] as usize][axis], after[w[1] as usize][axis]);
                        proptest::prop_assert!(p < q || (p == q && w[0] < w[1]));
                    }
                }
            }
        }
    }
}
