//! The plan of a solve distributed over ranks, from the contacts each rank holds.
//!
//! Before the pairs move to the ranks that solve them, no rank has the step's contacts: each
//! holds those of the pairs it tested. Each rank counts its own per bucket — per subdomain,
//! and per interface group with the bodies its contacts join — and the ranks share these
//! counts (one all-gather, of the size of the interface, not of the step's contacts). From
//! the sums every rank colours the same groups and gives them the same ranks a single
//! process's plan gives them ([`DdmProblem::plan`]): the groups depend on which subdomain
//! pairs have contacts and how many, not on which rank holds them. Once the pairs have moved,
//! each rank buckets the contacts it then holds — exactly those of its buckets, in pair
//! order, the order a single process keeps within a bucket ([`DdmProblem::place_held`]).

use super::{group_pair, home, shared_bodies, DdmProblem};
use crate::solver::exchange::{self, Exchange};
use crate::solver::partition::{Partition, STATIC};
use std::collections::BTreeMap;
use std::time::Instant;

/// Per interface group (subdomain pair): its contacts and the dynamic bodies they join
/// (solver numbering).
type Groups = BTreeMap<(u32, u32), (usize, Vec<u32>)>;

impl DdmProblem {
    /// The step's buckets over the ranks of `ex`, from the `n` contacts this rank holds
    /// (contact `k` joins the bodies `bodies_of(k)`): every subdomain's and interface
    /// group's number of contacts over all ranks, the groups' colours, ranks and bodies. A
    /// collective. Returns the seconds spent sharing.
    pub(crate) fn census(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32),
        parallel_interface: bool,
        ex: &dyn Exchange,
    ) -> f64 {
        let k = partition.count();
        let mut sub = vec![0usize; k];
        let mut groups = Groups::new();
        for idx in 0..n {
            let b = bodies_of(idx);
            match home(partition, b) {
                STATIC => {
                    let g = groups
                        .entry(group_pair(partition, b, parallel_interface))
                        .or_default();
                    g.0 += 1;
                    g.1.extend(shared_bodies(partition, b));
                }
                s => sub[s as usize] += 1,
            }
        }
        // Counts and body indices are below 2^32: exact in an `f64`.
        let mut mine: Vec<f64> = sub.iter().map(|&c| c as f64).collect();
        for (pair, (count, mut bodies)) in groups {
            bodies.sort_unstable();
            bodies.dedup();
            mine.extend([pair.0, pair.1].map(f64::from));
            mine.extend([count, bodies.len()].map(|x| x as f64));
            mine.extend(bodies.iter().map(|&b| f64::from(b)));
        }
        let t = Instant::now();
        let (all, counts) = exchange::gather_varying(ex, &mine);
        let seconds = t.elapsed().as_secs_f64();
        let mut total = vec![0; k];
        let mut merged = Groups::new();
        let mut at = 0;
        for &c in &counts {
            let part = &all[at..at + c];
            at += c;
            for (t, &x) in total.iter_mut().zip(part) {
                *t += x as usize;
            }
            let mut rest = &part[k..];
            while let [a, b, count, len, tail @ ..] = rest {
                let len = *len as usize;
                let g = merged.entry((*a as u32, *b as u32)).or_default();
                g.0 += *count as usize;
                g.1.extend(tail[..len].iter().map(|&i| i as u32));
                rest = &tail[len..];
            }
        }
        let runs: Vec<((u32, u32), usize)> = merged.iter().map(|(&p, g)| (p, g.0)).collect();
        self.sub_total = total;
        self.make_groups(&runs, k, Some((ex.rank(), ex.size())));
        for (group, (_, (_, mut bodies))) in self.groups.iter_mut().zip(merged) {
            bodies.sort_unstable();
            bodies.dedup();
            group.bodies = bodies;
        }
        seconds
    }

    /// After [`DdmProblem::census`] and the pairs' move to the ranks that solve them: each of
    /// the `n` contacts this rank now holds (all of its buckets', in pair order) in its
    /// bucket; [`DdmProblem::fill`] builds them.
    pub(crate) fn place_held(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32) + Sync,
        parallel_interface: bool,
    ) {
        self.sort_contacts(partition, n, &bodies_of, parallel_interface);
        self.place_gamma(partition.count());
    }

    /// The step's number of contacts over all ranks, once [`DdmProblem::fill`] has built
    /// the buckets.
    pub(crate) fn total(&self) -> usize {
        self.buckets().map(|b| b.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::local;
    use super::super::DdmProblem;
    use crate::math::DVec3;
    use crate::solver::exchange::{self, Exchange, ThreadRanks};
    use crate::solver::partition::{Balance, Partition};

    /// A bucket's contacts as the step's indices (`held[k]` for this rank's contact `k`).
    fn contents(p: &DdmProblem, held: &[usize]) -> Vec<(bool, usize, Vec<usize>)> {
        p.buckets()
            .map(|b| {
                let o = b.origin.iter().map(|&k| held[k as usize]).collect();
                (b.remote, b.len(), o)
            })
            .collect()
    }

    proptest::proptest! {
        /// The census over the contacts each rank holds, then the bucketing of those it holds
        /// once the pairs have moved, give every rank the plan a single process makes of all
        /// the step's contacts: the same groups (pair, colour, rank, bodies), every bucket's
        /// length, and this rank's buckets with the same contacts in the same order —
        /// whichever rank held each pair before.
        #[test]
        fn the_census_plans_as_one_process_does(
            positions in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0), 12..60),
            picks in proptest::collection::vec((0usize..1000, 0usize..1000, 1usize..4, 0usize..8), 1..150),
            dims in proptest::sample::select(vec![[2usize, 1, 1], [2, 2, 1], [3, 2, 2], [4, 1, 1]]),
            size in 2usize..5,
            parallel_interface in proptest::bool::ANY,
        ) {
            let n = positions.len();
            let positions: Vec<DVec3> =
                positions.iter().map(|&(x, y, z)| DVec3::new(x, y, z)).collect();
            // The last three bodies are static: a pair has a dynamic body.
            let dynamic: Vec<bool> = (0..n).map(|i| i < n - 3).collect();
            let partition =
                Partition::build(&positions, &dynamic, dims, Balance::Volume, &vec![1.0; n]);
            // Pairs in order, each with 1 to 3 contacts and a rank that holds it before the
            // solve.
            let mut pairs: Vec<((u32, u32), usize, usize)> = picks
                .iter()
                .map(|&(a, b, m, r)| ((a % n) as u32, (b % (n - 3)) as u32, m, r % size))
                .filter(|(a, b, _, _)| a != b)
                .map(|(a, b, m, r)| ((a.min(b), a.max(b)), m, r))
                .collect();
            pairs.sort_unstable();
            pairs.dedup_by_key(|p| p.0);
            let contacts: Vec<((u32, u32), usize)> = pairs
                .iter()
                .flat_map(|&(pair, m, r)| std::iter::repeat_n((pair, r), m))
                .collect();
            let all = contacts.len();
            let results = std::thread::scope(|scope| {
                let handles: Vec<_> = ThreadRanks::group(size)
                    .into_iter()
                    .map(|ex| {
                        let (partition, contacts) = (&partition, &contacts);
                        scope.spawn(move || {
                            let me = ex.rank();
                            // One process's plan, seen from this rank.
                            let mut one = DdmProblem::default();
                            one.rebuild_with(
                                partition,
                                all,
                                |k| contacts[k].0,
                                |k| local(contacts[k].0),
                                parallel_interface,
                                Some((me, size)),
                            );
                            // The census of what this rank held, then the contacts of the
                            // buckets it solves.
                            let mut p = DdmProblem::default();
                            let before: Vec<usize> =
                                (0..all).filter(|&k| contacts[k].1 == me).collect();
                            p.census(
                                partition,
                                before.len(),
                                |k| contacts[before[k]].0,
                                parallel_interface,
                                &ex,
                            );
                            let k = partition.count();
                            let owner = |c: usize| match one.slot[c].0 as usize {
                                s if s < k => exchange::owner(s, k, size),
                                g => one.groups[g - k].owner,
                            };
                            let held: Vec<usize> = (0..all).filter(|&c| owner(c) == me).collect();
                            p.place_held(
                                partition,
                                held.len(),
                                |k| contacts[held[k]].0,
                                parallel_interface,
                            );
                            p.fill(partition, |k| local(contacts[held[k]].0), Some((me, size)));
                            let groups = |p: &DdmProblem| -> Vec<_> {
                                p.groups
                                    .iter()
                                    .map(|g| (g.pair, g.colour, g.owner, g.bodies.clone()))
                                    .collect()
                            };
                            let identity: Vec<usize> = (0..all).collect();
                            (
                                (groups(&one), contents(&one, &identity), one.total()),
                                (groups(&p), contents(&p, &held), p.total()),
                            )
                        })
                    })
                    .collect();
                handles.into_iter().map(|h| h.join().unwrap()).collect::<Vec<_>>()
            });
            for (rank, (one, census)) in results.into_iter().enumerate() {
                proptest::prop_assert_eq!(one.2, all);
                proptest::prop_assert_eq!(one, census, "rank {}", rank);
            }
        }
    }
}
