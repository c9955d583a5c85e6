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

use crate::math::DVec3;
use serde::{Deserialize, Serialize};

/// Marks a body that belongs to no subdomain (kinematic or fixed).
pub const STATIC: u32 = u32::MAX;

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
        let n = positions.len();
        let dyn_ids: Vec<usize> = (0..n).filter(|&i| dynamic[i]).collect();
        let mut cuts: [Vec<f64>; 3] = Default::default();
        for axis in 0..3 {
            cuts[axis] = axis_cuts(positions, &dyn_ids, axis, dims[axis], balance, weights);
        }
        let mut subdomain = vec![STATIC; n];
        for &i in &dyn_ids {
            let mut idx = [0usize; 3];
            for axis in 0..3 {
                let x = positions[i][axis];
                idx[axis] = cuts[axis].partition_point(|&c| c <= x).min(dims[axis] - 1);
            }
            subdomain[i] = (idx[0] + dims[0] * (idx[1] + dims[1] * idx[2])) as u32;
        }
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

/// Interior cut positions along `axis` (`parts − 1` values, increasing).
fn axis_cuts(
    positions: &[DVec3],
    ids: &[usize],
    axis: usize,
    parts: usize,
    balance: Balance,
    weights: &[f64],
) -> Vec<f64> {
    if parts <= 1 || ids.is_empty() {
        return Vec::new();
    }
    match balance {
        Balance::Volume => {
            let (lo, hi) = ids
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
                    (lo.min(positions[i][axis]), hi.max(positions[i][axis]))
                });
            (1..parts)
                .map(|p| lo + (hi - lo) * p as f64 / parts as f64)
                .collect()
        }
        Balance::Contacts => {
            let mut sorted: Vec<usize> = ids.to_vec();
            sorted.sort_by(|&a, &b| {
                positions[a][axis]
                    .total_cmp(&positions[b][axis])
                    .then(a.cmp(&b))
            });
            let total: f64 = sorted.iter().map(|&i| weights[i]).sum();
            let mut cuts = Vec::with_capacity(parts - 1);
            let mut acc = 0.0;
            let mut p = 1;
            for w in sorted.windows(2) {
                acc += weights[w[0]];
                while p < parts && acc >= total * p as f64 / parts as f64 {
                    // Cut midway between two consecutive centres.
                    cuts.push(0.5 * (positions[w[0]][axis] + positions[w[1]][axis]));
                    p += 1;
                }
            }
            while cuts.len() < parts - 1 {
                cuts.push(f64::INFINITY);
            }
            cuts
        }
    }
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
}
