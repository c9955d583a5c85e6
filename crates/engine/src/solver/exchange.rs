//! The domain decomposition across processes (MPI ranks): what a DDM solve shares, and with
//! whom.
//!
//! Every process has every body's slot, but a dynamic body is kept up to date only by the
//! rank that owns it (the owner of its subdomain at the last solve): each step the owners
//! send the other ranks the bodies those read — ghosts within reach of their regions, and
//! the bodies a solve moves to them (`detection/ghosts.rs`) — and what is computed
//! over all bodies is gathered from their owners. Bodies that are not dynamic (walls,
//! drives) are stepped alike everywhere. Rank `r` owns the subdomains [`owner`] gives it
//! (contiguous blocks of subdomains, a rule of the partition alone) and its share of the
//! interface groups (balanced colour by colour), and *holds* their pairs (`PairOwners`):
//! it alone tests them, keeps their manifolds and contacts, warm-starts, builds and sweeps
//! them. Once a step the ranks share their contacts' count per bucket and the bodies of
//! their interface contacts (the census every rank colours and assigns the groups by, see
//! `ddm/census.rs`), and the pairs whose bucket changes rank move to the new owner with
//! their manifold and contacts. After each phase of the solve the ranks share what the
//! phase wrote that another rank reads next: the velocities of the bodies the interface
//! contacts and the drives touch, each bucket's sums for the stop test, and once a step each
//! bucket's share of the residual's scale. At the end of the solve a grain's velocity stays
//! on its owner, which alone integrates it. Sharing copies
//! values: each bucket is swept with the same arithmetic in the same order as in one
//! process, so a run over K ranks is bit-identical to a shared-memory run with the same
//! partition.
//!
//! The engine needs no MPI library: [`Exchange`] has the collectives it calls (an
//! all-gather of `f64`s, and an all-to-all for what goes to some ranks only); the command line implements it over MPI (the `mpi` feature), and
//! [`ThreadRanks`] in-process, for tests.

use super::delassus::SolverBody;
use super::partition::{Partition, STATIC};
use crate::math::DVec3;
use std::sync::{Arc, Barrier, Mutex};

/// The collective a distributed DDM solve calls: every rank calls it at the same points of
/// the solve, in the same order.
pub trait Exchange: Send + Sync + std::fmt::Debug {
    /// This process's rank, in `0..size()`.
    fn rank(&self) -> usize;
    /// The number of ranks.
    fn size(&self) -> usize;
    /// All-gather: each rank gives `mine` (`counts[rank]` values); `all` (`Σ counts` values)
    /// receives every rank's values, rank after rank.
    fn all_gather(&self, mine: &[f64], counts: &[usize], all: &mut [f64]);

    /// Personalised all-to-all: `send` holds `send_counts[r]` values for each rank `r`, rank
    /// after rank (this rank's own part included); `recv` (`Σ recv_counts` values) receives
    /// what each rank sent this one, rank after rank, `recv_counts[r]` from rank `r` (each
    /// rank's count for this one, which the ranks exchange first).
    fn all_to_all(
        &self,
        send: &[f64],
        send_counts: &[usize],
        recv_counts: &[usize],
        recv: &mut [f64],
    );

    /// All-reduce by sum: `values` (the same length on every rank) becomes, element by
    /// element, the sum over the ranks. Only for counts (whole numbers below 2⁵³), whose sums
    /// are exact in any order, so an implementation may add in any order (as `MPI_Allreduce`
    /// does). By default an all-gather, summed in rank order.
    fn sum_counts(&self, values: &mut [f64]) {
        let (size, n) = (self.size(), values.len());
        let mut all = vec![0.0; size * n];
        self.all_gather(values, &vec![n; size], &mut all);
        for (k, v) in values.iter_mut().enumerate() {
            *v = (0..size).map(|r| all[r * n + k]).sum();
        }
    }
}

/// All-gather of the same number of values on every rank: every rank's `mine`, rank after
/// rank.
pub(crate) fn gather_equal(ex: &dyn Exchange, mine: &[f64]) -> Vec<f64> {
    let size = ex.size();
    let mut all = vec![0.0; size * mine.len()];
    ex.all_gather(mine, &vec![mine.len(); size], &mut all);
    all
}

/// All-gather of a different number of values per rank: every rank's `mine`, rank after
/// rank, and how many each gave (two collectives: the counts, then the values).
pub(crate) fn gather_varying(ex: &dyn Exchange, mine: &[f64]) -> (Vec<f64>, Vec<usize>) {
    let size = ex.size();
    let mut counts = vec![0.0; size];
    ex.all_gather(&[mine.len() as f64], &vec![1; size], &mut counts);
    let counts: Vec<usize> = counts.iter().map(|&c| c as usize).collect();
    let mut all = vec![0.0; counts.iter().sum()];
    ex.all_gather(mine, &counts, &mut all);
    (all, counts)
}

/// Sends `parts[r]` to rank `r` (this rank's own part included), point to point: what every
/// rank sent this one, rank after rank, and how many values came from each (two collectives:
/// the counts, then the values). Each rank receives only what is meant for it, where
/// [`gather_varying`] would give every rank every rank's messages.
pub(crate) fn exchange_parts(ex: &dyn Exchange, parts: &[Vec<f64>]) -> (Vec<f64>, Vec<usize>) {
    let size = ex.size();
    debug_assert_eq!(parts.len(), size);
    let send_counts: Vec<usize> = parts.iter().map(Vec::len).collect();
    let counts: Vec<f64> = send_counts.iter().map(|&c| c as f64).collect();
    let mut recv_counts = vec![0.0; size];
    ex.all_to_all(&counts, &vec![1; size], &vec![1; size], &mut recv_counts);
    let recv_counts: Vec<usize> = recv_counts.iter().map(|&c| c as usize).collect();
    let mut recv = vec![0.0; recv_counts.iter().sum()];
    ex.all_to_all(&parts.concat(), &send_counts, &recv_counts, &mut recv);
    (recv, recv_counts)
}

/// The rank that owns subdomain `s` of `n` over `size` ranks: contiguous blocks of
/// subdomains (boxes numbered along x first, so a rank's boxes are neighbours).
pub fn owner(s: usize, n: usize, size: usize) -> usize {
    s * size / n.max(1)
}

/// Which rank holds each body pair of a distributed run: the owner of the bucket its contacts
/// were solved in at the last step ([`owner`] for a subdomain's pairs, the group's rank for
/// an interface group's). Detection hands each pair to this rank, so the pair's last
/// outcome and contacts, which it reuses and warm-starts from, are where it is tested. Any
/// rule would give the same results (an outcome is the same whichever rank computes it);
/// this one puts the work where the data is.
#[derive(Clone, Debug, Default)]
pub(crate) struct PairOwners {
    /// Each body's subdomain ([`STATIC`] for the others).
    subdomain: Vec<u32>,
    /// Each body's subdomain in the partition, where a body is attached to another (empty:
    /// `subdomain`).
    placed: Vec<u32>,
    /// Number of subdomains, and of ranks.
    count: usize,
    size: usize,
    /// The interface groups' subdomain pairs, sorted, and their ranks.
    groups: Vec<((u32, u32), usize)>,
    /// Γ solved as one sequential group (pair `(STATIC, STATIC)`).
    sequential: bool,
}

impl PairOwners {
    /// The owners of the solve over `partition` whose interface groups had `groups` (subdomain
    /// pair, rank), over `size` ranks; a body attached to another (`attach[i]`, empty when
    /// none is) is solved as that one, in its subdomain.
    pub(crate) fn new(
        partition: &Partition,
        mut groups: Vec<((u32, u32), usize)>,
        size: usize,
        attach: &[u32],
    ) -> Self {
        groups.sort_unstable();
        let sequential = groups.first().is_some_and(|g| g.0 .0 == STATIC);
        let (subdomain, placed) = match attach.is_empty() {
            true => (partition.subdomain.clone(), Vec::new()),
            false => (
                attach
                    .iter()
                    .map(|&p| partition.subdomain[p as usize])
                    .collect(),
                partition.subdomain.clone(),
            ),
        };
        PairOwners {
            subdomain,
            placed,
            count: partition.count(),
            size,
            groups,
            sequential,
        }
    }

    /// Body `i`'s subdomain as the rule counts it (an attached body's parent's; [`STATIC`]
    /// for the bodies of no subdomain).
    pub(crate) fn subdomain(&self, i: usize) -> u32 {
        self.subdomain.get(i).copied().unwrap_or(STATIC)
    }

    /// Body `i`'s subdomain in the partition of the solve (an attached body's own:
    /// [`STATIC`]).
    pub(crate) fn placed(&self, i: usize) -> u32 {
        match self.placed.is_empty() {
            true => self.subdomain(i),
            false => self.placed.get(i).copied().unwrap_or(STATIC),
        }
    }

    /// The number of subdomains.
    pub(crate) fn count(&self) -> usize {
        self.count
    }

    /// The rank that holds subdomain `s`'s own pairs.
    pub(crate) fn of_subdomain(&self, s: usize) -> usize {
        owner(s, self.count, self.size)
    }

    /// The interface groups: subdomain pair (`(STATIC, STATIC)` alone when Γ is solved as one
    /// sequential group) and the rank that holds its pairs.
    pub(crate) fn groups(&self) -> &[((u32, u32), usize)] {
        &self.groups
    }

    /// The rank that holds the pair of bodies `i`, `j`.
    pub(crate) fn of(&self, i: u32, j: u32) -> usize {
        let sub = |b: u32| self.subdomain.get(b as usize).copied().unwrap_or(STATIC);
        let by_sub = |s: u32| owner(s as usize, self.count, self.size);
        match (sub(i), sub(j)) {
            (STATIC, STATIC) => 0,
            (a, b) if a == b => by_sub(a),
            (STATIC, s) | (s, STATIC) => by_sub(s),
            (a, b) => {
                let key = if self.sequential {
                    (STATIC, STATIC)
                } else {
                    (a.min(b), a.max(b))
                };
                match self.groups.binary_search_by_key(&key, |g| g.0) {
                    Ok(g) => self.groups[g].1,
                    // No contact joined the two subdomains at the last step.
                    Err(_) => by_sub(a.min(b)),
                }
            }
        }
    }
}

/// Values of a body a solve changes, as shared: velocities and the skip and term-cache
/// counters (the counters are integers below 2^32, exact in an `f64`).
pub(crate) const BODY_VALUES: usize = 9;

/// Appends body `b`'s shared values to `out`.
pub(crate) fn put_body(b: &SolverBody, out: &mut Vec<f64>) {
    out.extend_from_slice(&[
        b.v.x,
        b.v.y,
        b.v.z,
        b.w.x,
        b.w.y,
        b.w.z,
        f64::from(b.epoch),
        f64::from(b.drift),
        f64::from(b.version),
    ]);
}

/// Sets body `b`'s shared values from `x` (written by [`put_body`]).
pub(crate) fn take_body(b: &mut SolverBody, x: &[f64]) {
    b.v = DVec3::new(x[0], x[1], x[2]);
    b.w = DVec3::new(x[3], x[4], x[5]);
    b.epoch = x[6] as u32;
    b.drift = x[7] as f32;
    b.version = x[8] as u32;
}

/// What one phase of a distributed solve shares from one bucket: the rank that swept it, the
/// bodies it wrote that others read (solver numbering), how many values it reports, and which
/// ranks read those bodies.
pub(crate) struct Unit<'a> {
    pub owner: usize,
    pub bodies: &'a [u32],
    pub values: usize,
    /// `readers[r]`: whether rank `r` reads the bodies (empty: every rank does). Every rank
    /// receives the values.
    pub readers: &'a [bool],
}

impl Unit<'_> {
    /// Whether rank `r` receives the unit's bodies.
    fn read_by(&self, r: usize) -> bool {
        self.readers.is_empty() || self.readers[r]
    }

    /// The number of values rank `r` receives of the unit (`r` is not its owner).
    fn sent_to(&self, r: usize) -> usize {
        self.values + usize::from(self.read_by(r)) * self.bodies.len() * BODY_VALUES
    }
}

/// Buffers of [`share`], kept from one call to the next.
#[derive(Clone, Debug, Default)]
pub(crate) struct ShareBuffers {
    send: Vec<f64>,
    all: Vec<f64>,
    send_counts: Vec<usize>,
    counts: Vec<usize>,
    cursor: Vec<usize>,
}

/// Shares `units`: each rank sends the values of the units it owns (`values` holds every
/// unit's values, unit after unit) to every other rank, and their bodies to the ranks that
/// read them, point to point; afterwards `values` holds, on every rank, what each unit's
/// owner computed, and `bodies` the bodies each rank reads. Every rank knows every unit, so
/// each knows what it receives from whom without asking: one all-to-all.
pub(crate) fn share(
    ex: &dyn Exchange,
    units: &[Unit],
    bodies: &mut [SolverBody],
    values: &mut [f64],
    buf: &mut ShareBuffers,
) {
    let (me, size) = (ex.rank(), ex.size());
    buf.send_counts.clear();
    buf.send_counts.resize(size, 0);
    buf.counts.clear();
    buf.counts.resize(size, 0);
    for u in units {
        if u.owner == me {
            for r in (0..size).filter(|&r| r != me) {
                buf.send_counts[r] += u.sent_to(r);
            }
        } else {
            buf.counts[u.owner] += u.sent_to(me);
        }
    }
    // Rank after rank, each rank's part in unit order.
    buf.send.clear();
    for r in (0..size).filter(|&r| r != me) {
        let mut off = 0;
        for u in units {
            if u.owner == me {
                if u.read_by(r) {
                    for &b in u.bodies {
                        put_body(&bodies[b as usize], &mut buf.send);
                    }
                }
                buf.send.extend_from_slice(&values[off..off + u.values]);
            }
            off += u.values;
        }
    }
    buf.all.clear();
    buf.all.resize(buf.counts.iter().sum(), 0.0);
    ex.all_to_all(&buf.send, &buf.send_counts, &buf.counts, &mut buf.all);
    // Where each rank's part starts, then read in unit order.
    buf.cursor.clear();
    let mut at = 0;
    for &c in &buf.counts {
        buf.cursor.push(at);
        at += c;
    }
    let mut off = 0;
    for u in units {
        if u.owner != me {
            let c = &mut buf.cursor[u.owner];
            if u.read_by(me) {
                for &b in u.bodies {
                    take_body(&mut bodies[b as usize], &buf.all[*c..*c + BODY_VALUES]);
                    *c += BODY_VALUES;
                }
            }
            values[off..off + u.values].copy_from_slice(&buf.all[*c..*c + u.values]);
            *c += u.values;
        }
        off += u.values;
    }
}

/// In-process ranks: `K` threads, each stepping its own copy of a scene, sharing through
/// memory what MPI ranks would send. Used by tests to check that a distributed solve is
/// bit-identical to a single process without launching MPI.
#[derive(Debug)]
pub struct ThreadRanks {
    rank: usize,
    size: usize,
    shared: Arc<ThreadShared>,
}

#[derive(Debug)]
struct ThreadShared {
    barrier: Barrier,
    parts: Mutex<Vec<Vec<f64>>>,
    /// The all-to-all's messages: from rank `a` to rank `b` at `a · size + b`.
    mail: Mutex<Vec<Vec<f64>>>,
}

impl ThreadRanks {
    /// The `k` ranks of one group, to hand one to each thread.
    pub fn group(k: usize) -> Vec<ThreadRanks> {
        let shared = Arc::new(ThreadShared {
            barrier: Barrier::new(k),
            parts: Mutex::new(vec![Vec::new(); k]),
            mail: Mutex::new(vec![Vec::new(); k * k]),
        });
        (0..k)
            .map(|rank| ThreadRanks {
                rank,
                size: k,
                shared: shared.clone(),
            })
            .collect()
    }
}

impl Exchange for ThreadRanks {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn all_gather(&self, mine: &[f64], counts: &[usize], all: &mut [f64]) {
        debug_assert_eq!(mine.len(), counts[self.rank]);
        {
            let mut parts = self.shared.parts.lock().expect("a rank thread panicked");
            parts[self.rank].clear();
            parts[self.rank].extend_from_slice(mine);
        }
        self.shared.barrier.wait();
        {
            let parts = self.shared.parts.lock().expect("a rank thread panicked");
            let mut at = 0;
            for p in parts.iter() {
                all[at..at + p.len()].copy_from_slice(p);
                at += p.len();
            }
        }
        // Nobody writes its next part before everyone has read this one.
        self.shared.barrier.wait();
    }

    fn all_to_all(
        &self,
        send: &[f64],
        send_counts: &[usize],
        recv_counts: &[usize],
        recv: &mut [f64],
    ) {
        let (me, size) = (self.rank, self.size);
        {
            let mut mail = self.shared.mail.lock().expect("a rank thread panicked");
            let mut at = 0;
            for (r, &c) in send_counts.iter().enumerate() {
                mail[me * size + r].clear();
                mail[me * size + r].extend_from_slice(&send[at..at + c]);
                at += c;
            }
        }
        self.shared.barrier.wait();
        {
            let mail = self.shared.mail.lock().expect("a rank thread panicked");
            let mut at = 0;
            for (r, &c) in recv_counts.iter().enumerate() {
                let part = &mail[r * size + me];
                debug_assert_eq!(part.len(), c);
                recv[at..at + c].copy_from_slice(part);
                at += c;
            }
        }
        self.shared.barrier.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each subdomain has one owner, owners never decrease along the subdomains, and every
    /// rank owns some subdomain when there are at least as many subdomains as ranks.
    #[test]
    fn owners_are_contiguous_blocks() {
        for n in 1..20 {
            for size in 1..=n {
                let o: Vec<usize> = (0..n).map(|s| owner(s, n, size)).collect();
                assert!(o.windows(2).all(|w| w[0] <= w[1]), "{o:?}");
                for r in 0..size {
                    assert!(o.contains(&r), "n {n} size {size}: {o:?}");
                }
            }
        }
    }

    /// A body's shared values round-trip exactly.
    #[test]
    fn body_values_round_trip() {
        let b = SolverBody {
            v: DVec3::new(0.1, -2.5e-7, 3.0),
            w: DVec3::new(1e300, -0.0, 7.25),
            epoch: u32::MAX,
            drift: 1.5e-3,
            version: 123_456_789,
            inv_mass: 0.5,
            inv_inertia: crate::math::DMat3::IDENTITY,
        };
        let mut x = Vec::new();
        put_body(&b, &mut x);
        assert_eq!(x.len(), BODY_VALUES);
        let mut c = SolverBody {
            v: DVec3::ZERO,
            w: DVec3::ZERO,
            epoch: 0,
            drift: 0.0,
            version: 0,
            ..b
        };
        take_body(&mut c, &x);
        assert_eq!(c.v, b.v);
        assert_eq!(c.w, b.w);
        assert_eq!(
            (c.epoch, c.drift.to_bits(), c.version),
            (b.epoch, b.drift.to_bits(), b.version)
        );
    }

    /// Three in-process ranks send each other parts of different lengths (some empty, one to
    /// itself): each receives exactly the parts meant for it, in rank order — what it would
    /// keep of an all-gather of every rank's messages.
    #[test]
    fn thread_ranks_exchange_parts_point_to_point() {
        let part = |from: usize, to: usize| -> Vec<f64> {
            (0..(from + 2 * to) % 4)
                .map(|i| (100 * from + 10 * to + i) as f64)
                .collect()
        };
        let handles: Vec<_> = ThreadRanks::group(3)
            .into_iter()
            .map(|r| {
                std::thread::spawn(move || {
                    let parts: Vec<Vec<f64>> = (0..3).map(|to| part(r.rank(), to)).collect();
                    let mut got = Vec::new();
                    for _ in 0..3 {
                        got.push(exchange_parts(&r, &parts));
                    }
                    (r.rank(), got)
                })
            })
            .collect();
        for h in handles {
            let (me, got) = h.join().unwrap();
            let expect: Vec<f64> = (0..3).flat_map(|from| part(from, me)).collect();
            let counts: Vec<usize> = (0..3).map(|from| part(from, me).len()).collect();
            for g in got {
                assert_eq!(g, (expect.clone(), counts.clone()), "rank {me}");
            }
        }
    }

    /// Three in-process ranks gather parts of different lengths in rank order.
    #[test]
    fn thread_ranks_gather_in_rank_order() {
        let counts = [2, 0, 3];
        let handles: Vec<_> = ThreadRanks::group(3)
            .into_iter()
            .map(|r| {
                std::thread::spawn(move || {
                    let mine: Vec<f64> = (0..counts[r.rank()])
                        .map(|i| (10 * r.rank() + i) as f64)
                        .collect();
                    let mut all = vec![0.0; 5];
                    for _ in 0..3 {
                        r.all_gather(&mine, &counts, &mut all);
                    }
                    all
                })
            })
            .collect();
        for h in handles {
            assert_eq!(h.join().unwrap(), vec![0.0, 1.0, 20.0, 21.0, 22.0]);
        }
    }
}
