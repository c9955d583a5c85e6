//! The narrow phase of a distributed run (see [`crate::solver::exchange`]). Every rank holds
//! the same bodies. In a domain-decomposed run each rank places the world geometry of, and
//! runs the broad phase over, only the bodies its pairs may join ([`bodies_needed`]: its
//! subdomains' and those within reach of them), keeps the pairs it holds ([`keep_own`]) and
//! tests, reuses and keeps their outcomes only; the outcomes of pairs that change rank move
//! with them ([`Detector::migrate`]). Without domain decomposition every rank solves the
//! whole step: the pairs left to test are cut into one contiguous share per rank, each rank
//! tests its share, and an all-gather gives every rank every outcome ([`narrow_on_ranks`]).
//! An outcome is the same whichever rank computes it, so detection is bit-identical to one
//! process.

use super::{Aabb, Detector, FaceHint, ManifoldPoint, Outcomes, PairGeometry};
use crate::math::DVec3;
use crate::solver::exchange::PairOwners;
use crate::solver::partition::STATIC;
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

/// Keeps, of the candidate `pairs` (sorted), those this rank holds by `owners`' rule.
pub(super) fn keep_own(ex: &dyn Exchange, owners: &PairOwners, pairs: &mut Vec<(u32, u32)>) {
    let me = ex.rank();
    let own: Vec<bool> = pairs
        .par_iter()
        .map(|&(i, j)| owners.of(i, j) == me)
        .collect();
    let mut k = 0;
    pairs.retain(|_| {
        k += 1;
        own[k - 1]
    });
}

/// The bodies whose pairs this rank (`me`) may hold under `owners`' rule, given each body's
/// `bound`: a box that holds its detection box (bounds of no body need not be finite). The
/// rank's regions are the bounds of each subdomain whose own pairs it holds (the union of its
/// bodies' bounds), and the overlap of the two subdomains' bounds of each interface group it
/// holds; a body is needed when its bound meets a region, and the bodies of no subdomain
/// always are. Every pair the rank holds whose detection boxes overlap joins two needed
/// bodies: within one subdomain both bounds lie in its region; across an interface each
/// bound lies in its own subdomain's bounds and meets the other's, so it meets their
/// overlap; a pair across subdomains with no group is held with the lower one, whose region
/// holds one bound and so meets the other. Empty when every body is (a sequential interface
/// this rank holds).
/// `extents`: each subdomain's bound as its owner found it ([`subdomain_extents`] over its
/// bodies), or empty to find them from `bound`.
pub(super) fn bodies_needed(
    owners: &PairOwners,
    me: usize,
    bound: &[Aabb],
    extents: &[Aabb],
) -> Vec<bool> {
    let found;
    let extent = match extents.is_empty() {
        true => {
            found = subdomain_extents(owners, bound, |_| true);
            &found
        }
        false => extents,
    };
    let Some(regions) = regions(owners, me, extent) else {
        return Vec::new();
    };
    bound
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, b)| needs(owners, &regions, i, b))
        .collect()
}

/// Whether a rank of `regions` ([`regions`]) needs body `i` of bound `b`.
pub(super) fn needs(owners: &PairOwners, regions: &[Aabb], i: usize, b: &Aabb) -> bool {
    owners.subdomain(i) == STATIC || regions.iter().any(|r| r.overlaps(b))
}

/// The bound of each subdomain whose bodies `counted` takes: the union of their bounds (a
/// body of NaN bounds adds nothing: its boxes overlap none).
pub(super) fn subdomain_extents(
    owners: &PairOwners,
    bound: &[Aabb],
    counted: impl Fn(usize) -> bool,
) -> Vec<Aabb> {
    let mut extent = vec![Aabb::EMPTY; owners.count()];
    for (i, b) in bound.iter().enumerate().filter(|(_, b)| !b.is_empty()) {
        if let Some(e) = extent.get_mut(owners.subdomain(i) as usize) {
            if counted(i) {
                *e = e.union(b);
            }
        }
    }
    extent
}

/// Rank `me`'s regions ([`bodies_needed`]) from the subdomains' `extent`s; `None` when it
/// needs every body (it holds the sequential interface).
pub(super) fn regions(owners: &PairOwners, me: usize, extent: &[Aabb]) -> Option<Vec<Aabb>> {
    let mut regions: Vec<Aabb> = (0..owners.count())
        .filter(|&s| owners.of_subdomain(s) == me)
        .map(|s| extent[s])
        .collect();
    for &((a, b), rank) in owners.groups() {
        if rank != me {
            continue;
        }
        if a == STATIC {
            return None;
        }
        regions.push(extent[a as usize].intersection(&extent[b as usize]));
    }
    regions.retain(|r| !r.is_empty());
    Some(regions)
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
        let mut send = vec![Vec::new(); ex.size()];
        for (l, &h) in holder.iter().enumerate() {
            if h != me {
                put(&self.results.get(l), &mut send[h]);
            }
        }
        let t = Instant::now();
        let (all, _) = exchange::exchange_parts(ex, &send);
        let seconds = t.elapsed().as_secs_f64();
        let mut arrived: Vec<PairGeometry> = Vec::new();
        let mut at = 0;
        while at < all.len() {
            let (g, used) = take(&all[at..]);
            arrived.push(g);
            at += used;
        }
        if send.iter().all(Vec::is_empty) && arrived.is_empty() {
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
    use crate::solver::partition::{Balance, Partition};

    /// A body's detection box `x ± half` and its bound, a cube about `x` that holds it.
    fn boxes(x: DVec3, half: DVec3) -> (Aabb, Aabb) {
        let r = half.length();
        (
            Aabb {
                min: x - half,
                max: x + half,
            },
            Aabb {
                min: x - DVec3::splat(r),
                max: x + DVec3::splat(r),
            },
        )
    }

    proptest::proptest! {
        /// Every pair a rank holds whose detection boxes overlap joins two bodies it needs,
        /// whatever the partition, the interface groups (held by any rank, or Γ as one
        /// sequential group) and the number of ranks.
        #[test]
        fn a_rank_needs_both_bodies_of_every_pair_it_holds(
            bodies in proptest::collection::vec(
                ((0.0f64..4.0, 0.0f64..2.0, 0.0f64..1.0), (0.01f64..0.3, 0.01f64..0.3, 0.01f64..0.3), 0u8..10),
                8..70,
            ),
            dims in proptest::sample::select(vec![[2usize, 1, 1], [4, 1, 1], [3, 2, 1], [2, 2, 2]]),
            size in 1usize..5,
            groups in proptest::collection::vec((0u32..16, 0u32..16, 0usize..5), 0..12),
            sequential in proptest::option::of(0usize..5),
        ) {
            let x: Vec<DVec3> = bodies.iter().map(|b| DVec3::new(b.0 .0, b.0 .1, b.0 .2)).collect();
            // About one body in ten is not dynamic (in no subdomain).
            let dynamic: Vec<bool> = bodies.iter().map(|b| b.2 > 0).collect();
            let partition = Partition::build(&x, &dynamic, dims, Balance::Volume, &vec![1.0; x.len()]);
            let k = partition.count() as u32;
            let groups: Vec<((u32, u32), usize)> = match sequential {
                Some(rank) => vec![((STATIC, STATIC), rank % size)],
                None => {
                    let mut g: Vec<_> = groups
                        .iter()
                        .map(|&(a, b, r)| ((a % k).min(b % k), (a % k).max(b % k), r % size))
                        .filter(|&(a, b, _)| a != b)
                        .map(|(a, b, r)| ((a, b), r))
                        .collect();
                    g.sort_unstable();
                    g.dedup_by_key(|g| g.0);
                    g
                }
            };
            let owners = PairOwners::new(&partition, groups, size, &[]);
            let (detect, bound): (Vec<Aabb>, Vec<Aabb>) = bodies
                .iter()
                .zip(&x)
                .map(|(b, &x)| boxes(x, DVec3::new(b.1 .0, b.1 .1, b.1 .2)))
                .unzip();
            for me in 0..size {
                let needed = bodies_needed(&owners, me, &bound, &[]);
                let need = |i: usize| needed.is_empty() || needed[i];
                for i in 0..x.len() {
                    for j in i + 1..x.len() {
                        let held = owners.of(i as u32, j as u32) == me;
                        if held && (dynamic[i] || dynamic[j]) && detect[i].overlaps(&detect[j]) {
                            proptest::prop_assert!(need(i) && need(j), "rank {} pair {:?}", me, (i, j));
                        }
                    }
                }
            }
        }
    }

    /// A rank needs its subdomains' bodies and the bodies within reach of them, not the far
    /// side of the bed: four slabs over two ranks, grains 0.1 m wide every 0.25 m along x.
    #[test]
    fn a_rank_needs_its_slabs_and_their_rim() {
        let x: Vec<DVec3> = (0..16)
            .map(|i| DVec3::new(0.125 + 0.25 * i as f64, 0.5, 0.5))
            .collect();
        let partition = Partition::build(&x, &[true; 16], [4, 1, 1], Balance::Volume, &[1.0; 16]);
        let owners = PairOwners::new(&partition, vec![((1, 2), 1)], 2, &[]);
        let bound: Vec<Aabb> = x.iter().map(|&x| boxes(x, DVec3::splat(0.05)).1).collect();
        let needed = |me| bodies_needed(&owners, me, &bound, &[]);
        // Rank 0 holds slabs 0 and 1 (grains 0–7); rank 1 slabs 2, 3 and the group between
        // slabs 1 and 2. Grains are 0.25 m apart, their bounds 0.17 m wide: a slab's bodies'
        // extent reaches no other slab's grain.
        let expect0: Vec<bool> = (0..16).map(|i| i < 8).collect();
        assert_eq!(needed(0), expect0);
        assert_eq!(needed(1), (0..16).map(|i| i >= 8).collect::<Vec<_>>());
        // Wider grains (bounds 0.35 m wide) reach their neighbours: each rank needs one more.
        let bound: Vec<Aabb> = x.iter().map(|&x| boxes(x, DVec3::splat(0.1)).1).collect();
        let wide = bodies_needed(&owners, 0, &bound, &[]);
        assert_eq!(wide, (0..16).map(|i| i < 9).collect::<Vec<_>>());
        let wide = bodies_needed(&owners, 1, &bound, &[]);
        assert_eq!(wide, (0..16).map(|i| i >= 7).collect::<Vec<_>>());
    }

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
