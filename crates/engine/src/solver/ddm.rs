//! Domain-decomposed NLGS: the paper's Algorithm 1 (DDM–OpenMP–NLGS), on rayon.
//!
//! With the primal partition ([`super::Partition`]) the contacts split into subdomain contacts
//! (both bodies in subdomain E, or one of them static) and interface contacts Γ (two dynamic
//! bodies of different subdomains). Subdomains share no body (`W_EE' = 0`, eq. 11), so:
//!
//! 1. free velocities and warm start per subdomain, in parallel;
//! 2. for j = 1 … n_DDM (`solver.max_iterations`):
//!    1. `n` NLGS sweeps on every subdomain, in parallel (each owns a disjoint slice of bodies);
//!    2. `m` NLGS sweeps on Γ;
//!    3. the force-limited drives' rows ([`super::drive`]), on the calling thread: a driven
//!       body belongs to the subdomain of its centre, and its contacts with other
//!       subdomains' grains are in Γ, so its drive comes after both;
//!    4. error of each (the Quad sums of their last sweep, added in a fixed order) and the
//!       convergence test;
//! 3. velocities back to the bodies (the update is done by the caller);
//! 4. optionally ([`solve_and_correct`]), the overlap correction's sweeps on the same split.
//!
//! Beyond the paper, Γ is solved in parallel too: its contacts are grouped by the pair of
//! subdomains they join, the subdomain-adjacency edges are coloured greedily (largest group
//! first, ties by pair) so that the groups of one colour touch disjoint subdomains, and each colour's groups run
//! concurrently. Everything depends on the partition only: the same partition gives
//! bit-identical results for any number of threads. With `n = m = 1` the iterate is exactly
//! monolithic NLGS run in [`DdmProblem::equivalent_order`].

mod census;

use super::correction::{self, CorrectionSettings, Overlap};
use super::delassus::{slot, BodyAccess, LocalBuilder, LocalProblem, SolverBody};
use super::drive::{self, DriveRows};
use super::exchange::{self, Exchange, ShareBuffers, Unit};
use super::nlgs::{Nlgs, SolveReport, SweepSums, TermCache};
use super::partition::{Balance, Partition, LEFT_OUT, STATIC};
use super::StopRule;
use crate::laws::{ContactStatus, Elastic};
use crate::math::DVec3;
use crate::slices::reserve_total;
use crate::ScenarioError;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// Domain-decomposition settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DdmSettings {
    /// Boxes `[nx, ny, nz]`.
    pub subdomains: [usize; 3],
    /// `n`: NLGS sweeps per subdomain per DDM iteration.
    pub inner_sweeps: usize,
    /// `m`: NLGS sweeps on the interface per DDM iteration.
    pub interface_sweeps: usize,
    /// How boxes are placed.
    pub balance: Balance,
    /// Solve the interface in parallel (coloured groups) rather than sequentially.
    pub parallel_interface: bool,
    /// A phase (the subdomain sweeps, or one colour of interface groups) with fewer contacts
    /// than this runs on the calling thread: waking workers would cost more than the sweep.
    /// The value is for two threads; on `T` threads it is scaled by `2 / T`, since a phase
    /// left on one thread idles more cores (measured: 16 threads ran a 20,000-grain packing
    /// fastest near 0, 2 threads near 4096). Scheduling only: the pieces of a phase touch
    /// disjoint bodies, so results are bit-identical for any value (0 = always dispatch, as
    /// tests do to exercise the parallel paths).
    #[serde(skip_serializing_if = "is_default_min_parallel")]
    pub min_parallel_contacts: usize,
}

/// Default of [`DdmSettings::min_parallel_contacts`].
pub const MIN_PARALLEL_CONTACTS: usize = 4096;

/// Left out of the settings' JSON when at its default, so that checkpoints written before the
/// field existed still resume (it never changes results).
fn is_default_min_parallel(n: &usize) -> bool {
    *n == MIN_PARALLEL_CONTACTS
}

impl Default for DdmSettings {
    fn default() -> Self {
        Self {
            subdomains: [1, 1, 1],
            inner_sweeps: 1,
            interface_sweeps: 1,
            balance: Balance::Contacts,
            parallel_interface: true,
            min_parallel_contacts: MIN_PARALLEL_CONTACTS,
        }
    }
}

/// The fewest grains a subdomain must hold on average ([`DdmSettings::check_grains`]).
pub const MIN_GRAINS_PER_SUBDOMAIN: usize = 1;

impl DdmSettings {
    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if self.subdomains.iter().any(|&n| n == 0 || n > 4096) {
            return Err(ScenarioError(format!(
                "ddm.subdomains = {:?}: each must be in 1..=4096",
                self.subdomains
            )));
        }
        if self.inner_sweeps == 0 {
            return Err("ddm.inner_sweeps = 0 must be ≥ 1".into());
        }
        if self.interface_sweeps == 0 {
            return Err("ddm.interface_sweeps = 0 must be ≥ 1".into());
        }
        Ok(())
    }

    /// Refuses more subdomains than `grains` (the dynamic bodies they split): an empty
    /// subdomain only costs its bookkeeping, and 4096 × 4096 of them for 300 grains made a
    /// run 280 times slower. At least [`MIN_GRAINS_PER_SUBDOMAIN`] grains each, on average.
    pub fn check_grains(&self, grains: usize) -> Result<(), ScenarioError> {
        let n: usize = self.subdomains.iter().product();
        if n > 1 && n.saturating_mul(MIN_GRAINS_PER_SUBDOMAIN) > grains {
            return Err(ScenarioError(format!(
                "subdomains = {} ({n} subdomains) for {grains} grains: at most {} \
                 ({MIN_GRAINS_PER_SUBDOMAIN} grain(s) per subdomain on average)",
                self.label(),
                grains / MIN_GRAINS_PER_SUBDOMAIN
            )));
        }
        Ok(())
    }

    /// `"NXxNYxNZ"`.
    pub fn label(&self) -> String {
        let [x, y, z] = self.subdomains;
        format!("{x}x{y}x{z}")
    }
}

/// Seconds spent in the subdomain and interface phases of one solve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DdmTimes {
    pub subdomains: f64,
    pub interface: f64,
    /// Sharing between ranks (a distributed solve only; part of the two above).
    pub communication: f64,
}

/// Contacts solved together (a subdomain's, or an interface group's), bodies in solver
/// numbering.
///
/// In a solve distributed over ranks, a bucket another rank owns is *remote*: its contacts
/// are held by its owner, and only their number is known here (`locals`, `origin` and
/// `status` stay empty).
#[derive(Clone, Debug, Default)]
pub struct Bucket {
    /// The local problems (empty when the bucket is remote).
    pub locals: Vec<LocalProblem>,
    /// Index of each contact in the caller's order.
    pub origin: Vec<u32>,
    pub status: Vec<ContactStatus>,
    /// The overlapping contacts of the position correction (indices into `locals`).
    pub overlaps: Vec<Overlap>,
    /// The residual terms of the current solve (empty until its first check).
    terms: Vec<TermCache>,
    /// The contacts whose residual term was large at the last check (see [`hot_exceeds`]).
    hot: Vec<u32>,
    /// Whether another rank owns this bucket (see above).
    pub remote: bool,
    /// The number of contacts of a remote bucket.
    remote_len: usize,
}

impl Bucket {
    /// Appends the contacts `members`, each as `make` gives it (written in place).
    fn fill(&mut self, members: &[u32], make: impl Fn(u32) -> LocalProblem) {
        let n = self.locals.len() + members.len();
        reserve_total(&mut self.locals, n);
        self.locals.extend(members.iter().map(|&idx| make(idx)));
        self.list(members);
    }

    /// Makes it a remote bucket of `len` contacts.
    fn set_remote(&mut self, len: usize) {
        self.remote = true;
        self.remote_len = len;
    }

    /// Appends the contacts `members` to the bucket's list, their status unknown.
    fn list(&mut self, members: &[u32]) {
        let n = self.origin.len() + members.len();
        reserve_total(&mut self.origin, n);
        reserve_total(&mut self.status, n);
        self.origin.extend_from_slice(members);
        self.status
            .resize(self.origin.len(), ContactStatus::NoContact);
    }

    /// Appends contact `origin`, its local problem `make()` (nothing when remote: its
    /// length is known already).
    fn push(&mut self, make: impl FnOnce() -> LocalProblem, origin: u32) {
        if !self.remote {
            self.locals.push(make());
            self.origin.push(origin);
            self.status.push(ContactStatus::NoContact);
        }
    }

    fn clear(&mut self) {
        self.locals.clear();
        self.origin.clear();
        self.status.clear();
        self.terms.clear();
        self.hot.clear();
        self.remote = false;
        self.remote_len = 0;
    }

    /// Number of contacts (on every rank: a remote bucket's too).
    pub fn len(&self) -> usize {
        match self.remote {
            true => self.remote_len,
            false => self.origin.len(),
        }
    }

    /// Whether it has no contact.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Contact `k`'s impulse after the solve (a bucket of this rank's).
    fn impulse(&self, k: usize) -> DVec3 {
        self.locals[k].r
    }
}

/// Interface contacts joining one pair of subdomains.
#[derive(Clone, Debug)]
pub struct InterfaceGroup {
    /// The two subdomains, `a < b`.
    pub pair: (u32, u32),
    /// Colour: groups of one colour touch disjoint subdomains.
    pub colour: usize,
    /// The rank that sweeps it in a solve distributed over ranks (0 otherwise): each colour's
    /// groups are divided between the ranks by contact count, each kept on the rank of its
    /// lower subdomain while the colour stays balanced (see `group_owners`).
    pub owner: usize,
    pub bucket: Bucket,
    /// The dynamic bodies its contacts join (solver numbering, sorted), listed when the
    /// solve is distributed over ranks: what the group's owner shares after its colour.
    pub bodies: Vec<u32>,
}

/// The contacts bucketed by subdomain and interface group, bodies in solver numbering.
#[derive(Clone, Debug, Default)]
pub struct DdmProblem {
    pub sub: Vec<Bucket>,
    /// Sorted by `(colour, pair)`; a single group with pair `(STATIC, STATIC)` when the
    /// interface is solved sequentially.
    pub groups: Vec<InterfaceGroup>,
    pub colours: usize,
    /// Scratch of [`DdmProblem::rebuild`]: each subdomain's contacts (caller's indices).
    members: Vec<Vec<u32>>,
    /// Per caller contact: its bucket (in the equivalent order) and its place there.
    slot: Vec<(u32, u32)>,
    /// Scratch of [`DdmProblem::plan`]: Γ's contacts (caller's indices) by subdomain pair.
    gamma: Vec<((u32, u32), u32)>,
    /// Each subdomain's number of contacts (over all ranks).
    sub_total: Vec<usize>,
    /// The interface groups' buckets of the step before, emptied: the next groups take
    /// them, so that Γ's local problems are not copied again as their vectors grow.
    spare: Vec<Bucket>,
}

impl DdmProblem {
    /// Buckets `locals` (bodies in the original numbering) by the partition.
    pub fn build(partition: &Partition, locals: &[LocalProblem], parallel_interface: bool) -> Self {
        let mut p = DdmProblem::default();
        p.rebuild(partition, locals, parallel_interface, None);
        p
    }

    /// [`DdmProblem::build`] into the buffers of a previous step (no reallocation once they
    /// have grown); the subdomains' buckets are filled in parallel, each in the caller's order.
    pub(crate) fn rebuild(
        &mut self,
        partition: &Partition,
        locals: &[LocalProblem],
        parallel_interface: bool,
        ranks: Option<(usize, usize)>,
    ) {
        self.rebuild_with(
            partition,
            locals.len(),
            |k| (locals[k].body1, locals[k].body2),
            |k| locals[k],
            parallel_interface,
            ranks,
        );
    }

    /// [`DdmProblem::rebuild`] of `n` contacts that are not built yet: contact `k` joins the
    /// bodies `bodies_of(k)`, and `make(k)` builds its local problem (the caller's numbering)
    /// straight into its bucket, without a copy in the caller's order first.
    ///
    /// `ranks = Some((rank, size))`: a solve distributed over `size` ranks, seen from `rank`,
    /// which builds the local problems of the buckets it owns only ([`exchange::owner`],
    /// [`group_owners`]).
    pub(crate) fn rebuild_with(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32) + Sync,
        make: impl Fn(usize) -> LocalProblem + Sync,
        parallel_interface: bool,
        ranks: Option<(usize, usize)>,
    ) {
        self.plan(partition, n, bodies_of, parallel_interface, ranks);
        self.fill(partition, make, ranks);
    }

    /// The first half of [`DdmProblem::rebuild_with`]: each contact's bucket, the interface
    /// groups, their colours and ranks; no local problem built yet (see
    /// [`DdmProblem::fill`]). Between the two, the owner of each bucket is known.
    pub(crate) fn plan(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32) + Sync,
        parallel_interface: bool,
        ranks: Option<(usize, usize)>,
    ) {
        let k = partition.count();
        let ranks = ranks.filter(|&(_, size)| size > 1);
        self.sort_contacts(partition, n, &bodies_of, parallel_interface);
        // Group Γ by pair (stable: caller's order within a group), colour the pairs greedily,
        // give each group its rank.
        let mut runs: Vec<((u32, u32), usize)> = Vec::new();
        for &(pair, _) in self.gamma.iter() {
            match runs.last_mut() {
                Some((p, count)) if *p == pair => *count += 1,
                _ => runs.push((pair, 1)),
            }
        }
        self.sub_total.clear();
        self.sub_total.extend(self.members.iter().map(Vec::len));
        self.make_groups(&runs, k, ranks);
        self.place_gamma(k);
        if ranks.is_some() {
            // The bodies each group shares.
            for &(_, idx) in &self.gamma {
                let group = &mut self.groups[self.slot[idx as usize].0 as usize - k];
                group
                    .bodies
                    .extend(shared_bodies(partition, bodies_of(idx as usize)));
            }
            for g in &mut self.groups {
                g.bodies.sort_unstable();
                g.bodies.dedup();
            }
        }
    }

    /// Each of the `n` contacts' bucket: a subdomain's (`members`, `slot`), or Γ's (`gamma`,
    /// sorted by group pair, then the caller's order).
    fn sort_contacts(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: &(impl Fn(usize) -> (u32, u32) + Sync),
        parallel_interface: bool,
    ) {
        let k = partition.count();
        let owners: Vec<u32> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|c| home(partition, bodies_of(c)))
            .collect();
        self.members.resize_with(k, Vec::new);
        self.members.iter_mut().for_each(Vec::clear);
        self.slot.clear();
        reserve_total(&mut self.slot, n);
        self.slot.resize(n, (0, 0));
        let gamma = &mut self.gamma;
        gamma.clear();
        for (idx, &owner) in owners.iter().enumerate() {
            if owner != STATIC {
                let members = &mut self.members[owner as usize];
                self.slot[idx] = (owner, members.len() as u32);
                members.push(idx as u32);
            } else {
                let pair = group_pair(partition, bodies_of(idx), parallel_interface);
                gamma.push((pair, idx as u32));
            }
        }
        gamma.sort_unstable();
    }

    /// The interface groups of Γ's `runs` (each group's pair, in pair order, and its
    /// contacts over all ranks) between `k` subdomains: their colours and ranks, their
    /// buckets empty (a remote one knowing its length).
    fn make_groups(
        &mut self,
        runs: &[((u32, u32), usize)],
        k: usize,
        ranks: Option<(usize, usize)>,
    ) {
        let (colour, colours) = colour_groups(runs, k);
        let size = ranks.map_or(1, |(_, size)| size);
        let owner = group_owners(runs, &colour, colours, k, size);
        for g in self.groups.drain(..) {
            let mut bucket = g.bucket;
            bucket.clear();
            self.spare.push(bucket);
        }
        for (r, &(pair, count)) in runs.iter().enumerate() {
            let mut bucket = self.spare.pop().unwrap_or_default();
            if ranks.is_some_and(|(me, _)| owner[r] != me) {
                bucket.set_remote(count);
            }
            self.groups.push(InterfaceGroup {
                pair,
                colour: colour[r],
                owner: owner[r],
                bucket,
                bodies: Vec::new(),
            });
        }
        self.colours = colours;
    }

    /// Each Γ contact's group (the groups in pair order here) in `slot`.
    fn place_gamma(&mut self, k: usize) {
        let mut g = 0;
        for &(pair, idx) in self.gamma.iter() {
            while self.groups[g].pair != pair {
                g += 1;
            }
            self.slot[idx as usize] = ((k + g) as u32, 0);
        }
    }

    /// The second half of [`DdmProblem::rebuild_with`]: the buckets filled, `make(k)`
    /// building the local problems of this rank's.
    pub(crate) fn fill(
        &mut self,
        partition: &Partition,
        make: impl Fn(usize) -> LocalProblem + Sync,
        ranks: Option<(usize, usize)>,
    ) {
        let k = partition.count();
        let ranks = ranks.filter(|&(_, size)| size > 1);
        let remote_sub =
            |s: usize| ranks.is_some_and(|(me, size)| exchange::owner(s, k, size) != me);
        let renumber = |idx: u32| {
            let mut l = make(idx as usize);
            l.body1 = partition.new_index[l.body1 as usize];
            l.body2 = partition.new_index[l.body2 as usize];
            l
        };
        self.sub.resize_with(k, Bucket::default);
        let total = &self.sub_total;
        self.sub
            .par_iter_mut()
            .zip(self.members.par_iter())
            .enumerate()
            .for_each(|(s, (bucket, members))| {
                bucket.clear();
                if remote_sub(s) {
                    bucket.set_remote(total[s]);
                } else {
                    bucket.fill(members, renumber);
                }
            });
        // Γ's contacts into their groups, then the groups in the sweeps' order.
        let m = self.groups.len();
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by_key(|&g| (self.groups[g].colour, self.groups[g].pair));
        let mut sorted = vec![0; m];
        for (new, &old) in order.iter().enumerate() {
            sorted[old] = (k + new) as u32;
        }
        let mut next = vec![0; m];
        for &(_, idx) in &self.gamma {
            let g = self.slot[idx as usize].0 as usize - k;
            self.groups[g].bucket.push(|| renumber(idx), idx);
            self.slot[idx as usize] = (sorted[g], next[g]);
            next[g] += 1;
        }
        self.groups.sort_by_key(|g| (g.colour, g.pair));
    }

    /// The buckets in the equivalent order: subdomains, then Γ by colour and group.
    fn buckets(&self) -> impl Iterator<Item = &Bucket> {
        self.sub.iter().chain(self.groups.iter().map(|g| &g.bucket))
    }

    /// [`Self::buckets`], mutably.
    fn buckets_mut(&mut self) -> impl Iterator<Item = &mut Bucket> {
        self.sub
            .iter_mut()
            .chain(self.groups.iter_mut().map(|g| &mut g.bucket))
    }

    /// Caller's contact indices in the order of the equivalent monolithic NLGS: subdomain 0's
    /// contacts, …, subdomain k−1's, then Γ by colour and group.
    pub fn equivalent_order(&self) -> Vec<u32> {
        self.buckets()
            .flat_map(|b| b.origin.iter().copied())
            .collect()
    }

    /// Number of interface contacts.
    pub fn interface_len(&self) -> usize {
        self.groups.iter().map(|g| g.bucket.len()).sum()
    }
}

/// A subdomain's view: its own bodies (mutable) and the static bodies (read-only).
struct SubView<'a> {
    own: &'a mut [SolverBody],
    start: u32,
    statics: &'a [SolverBody],
    static_start: u32,
}

impl BodyAccess for SubView<'_> {
    #[inline(always)]
    fn body(&self, i: u32) -> &SolverBody {
        if i >= self.static_start {
            &self.statics[(i - self.static_start) as usize]
        } else {
            &self.own[(i - self.start) as usize]
        }
    }
    #[inline(always)]
    fn body_mut(&mut self, i: u32) -> &mut SolverBody {
        &mut self.own[(i - self.start) as usize]
    }
}

/// An interface group's view: the bodies of its two subdomains.
struct PairView<'a> {
    a: &'a mut [SolverBody],
    a_start: u32,
    b: &'a mut [SolverBody],
    b_start: u32,
}

impl BodyAccess for PairView<'_> {
    #[inline(always)]
    fn body(&self, i: u32) -> &SolverBody {
        if i >= self.a_start && ((i - self.a_start) as usize) < self.a.len() {
            &self.a[(i - self.a_start) as usize]
        } else {
            &self.b[(i - self.b_start) as usize]
        }
    }
    #[inline(always)]
    fn body_mut(&mut self, i: u32) -> &mut SolverBody {
        if i >= self.a_start && ((i - self.a_start) as usize) < self.a.len() {
            &mut self.a[(i - self.a_start) as usize]
        } else {
            &mut self.b[(i - self.b_start) as usize]
        }
    }
}

/// Splits the solver bodies into one mutable slice per subdomain and the static bodies.
fn split<'a>(
    pb: &'a mut [SolverBody],
    starts: &[usize],
) -> (Vec<&'a mut [SolverBody]>, &'a [SolverBody]) {
    let (pieces, rest) = crate::slices::split_lengths(pb, starts.windows(2).map(|w| w[1] - w[0]));
    (pieces, rest)
}

/// Runs `f` on every subdomain with its view, in parallel when worth it; results in subdomain
/// order.
fn for_subdomains<T: Send + Default>(
    p: &mut DdmProblem,
    pb: &mut [SolverBody],
    starts: &[usize],
    min_parallel: usize,
    mine: &(dyn Fn(usize) -> bool + Sync),
    f: impl Fn(&mut Bucket, &mut SubView) -> T + Sync,
) -> Vec<T> {
    let k = starts.len() - 1;
    let static_start = starts[k] as u32;
    let (slices, statics) = split(pb, starts);
    if p.sub.iter().map(Bucket::len).sum::<usize>() < min_parallel {
        return p
            .sub
            .iter_mut()
            .zip(slices)
            .enumerate()
            .map(|(e, (bucket, own))| {
                if !mine(e) {
                    return T::default();
                }
                let mut view = SubView {
                    own,
                    start: starts[e] as u32,
                    statics,
                    static_start,
                };
                f(bucket, &mut view)
            })
            .collect();
    }
    p.sub
        .par_iter_mut()
        .zip(slices.into_par_iter())
        .enumerate()
        .map(|(e, (bucket, own))| {
            if !mine(e) {
                return T::default();
            }
            let mut view = SubView {
                own,
                start: starts[e] as u32,
                statics,
                static_start,
            };
            f(bucket, &mut view)
        })
        .collect()
}

/// Called after each colour of interface groups: their range, the bodies, their results.
type AfterColour<'a, T> = dyn FnMut(Range<usize>, &mut [SolverBody], &mut [T]) + 'a;

/// Runs `f` on every interface group that is `mine`, colour after colour, the groups of a
/// colour in parallel (on the calling thread when the colour has one group or fewer than
/// `min_parallel` contacts: they touch disjoint bodies, so the order does not matter), and
/// `after` each colour with its groups' range and results; results in group order (the
/// default for a group that is not `mine`, unless `after` sets it).
fn for_interface<T: Send + Default>(
    p: &mut DdmProblem,
    pb: &mut [SolverBody],
    starts: &[usize],
    min_parallel: usize,
    mine: &(dyn Fn(usize) -> bool + Sync),
    after: &mut AfterColour<T>,
    f: impl Fn(&mut Bucket, &mut dyn BodyAccessDyn) -> T + Sync,
) -> Vec<T> {
    let mut out = Vec::with_capacity(p.groups.len());
    for colour in 0..p.colours {
        let first = out.len();
        // On the calling thread: the sequential interface, a colour of one group (nothing to
        // run beside it), or a colour too small to be worth waking the workers.
        let (mut groups, mut contacts, mut static_pair) = (0, 0, false);
        for g in p.groups.iter().filter(|g| g.colour == colour) {
            groups += 1;
            contacts += g.bucket.len();
            static_pair |= g.pair.0 == STATIC;
        }
        let sequential = static_pair || groups < 2 || contacts < min_parallel;
        if sequential {
            for (i, g) in p
                .groups
                .iter_mut()
                .enumerate()
                .filter(|(_, g)| g.colour == colour)
            {
                out.push(if mine(i) {
                    f(&mut g.bucket, &mut FullView(pb))
                } else {
                    T::default()
                });
            }
            let range = first..out.len();
            after(range.clone(), pb, &mut out[range]);
            continue;
        }
        let (slices, _) = split(pb, starts);
        let mut slots: Vec<Option<&mut [SolverBody]>> = slices.into_iter().map(Some).collect();
        let mut tasks = Vec::new();
        for (i, g) in p
            .groups
            .iter_mut()
            .enumerate()
            .filter(|(_, g)| g.colour == colour)
        {
            let (a, b) = (g.pair.0 as usize, g.pair.1 as usize);
            let (sa, sb) = (slots[a].take(), slots[b].take());
            if let (Some(sa), Some(sb)) = (sa, sb) {
                let view = PairView {
                    a: sa,
                    a_start: starts[a] as u32,
                    b: sb,
                    b_start: starts[b] as u32,
                };
                tasks.push((mine(i), &mut g.bucket, view));
            }
        }
        let results: Vec<T> = tasks
            .into_par_iter()
            .map(|(m, g, mut view)| if m { f(g, &mut view) } else { T::default() })
            .collect();
        out.extend(results);
        let range = first..out.len();
        after(range.clone(), pb, &mut out[range]);
    }
    out
}

/// Object-safe body access for the interface closure.
trait BodyAccessDyn {
    fn body_dyn(&self, i: u32) -> &SolverBody;
    fn body_mut_dyn(&mut self, i: u32) -> &mut SolverBody;
}

impl<T: BodyAccess> BodyAccessDyn for T {
    fn body_dyn(&self, i: u32) -> &SolverBody {
        self.body(i)
    }
    fn body_mut_dyn(&mut self, i: u32) -> &mut SolverBody {
        self.body_mut(i)
    }
}

impl BodyAccess for dyn BodyAccessDyn + '_ {
    #[inline(always)]
    fn body(&self, i: u32) -> &SolverBody {
        self.body_dyn(i)
    }
    #[inline(always)]
    fn body_mut(&mut self, i: u32) -> &mut SolverBody {
        self.body_mut_dyn(i)
    }
}

/// The whole body array (sequential interface).
struct FullView<'a>(&'a mut [SolverBody]);

impl BodyAccess for FullView<'_> {
    #[inline(always)]
    fn body(&self, i: u32) -> &SolverBody {
        &self.0[i as usize]
    }
    #[inline(always)]
    fn body_mut(&mut self, i: u32) -> &mut SolverBody {
        &mut self.0[i as usize]
    }
}

/// A bucket's report as shared between ranks ([`super::exchange`]).
trait Wire: Default + Send {
    const LEN: usize;
    fn put(&self, out: &mut [f64]);
    fn take(x: &[f64]) -> Self;
}

impl Wire for () {
    const LEN: usize = 0;
    fn put(&self, _: &mut [f64]) {}
    fn take(_: &[f64]) -> Self {}
}

impl Wire for SweepSums {
    const LEN: usize = 2;
    fn put(&self, out: &mut [f64]) {
        out[0] = self.dwr2;
        out[1] = self.wr2;
    }
    fn take(x: &[f64]) -> Self {
        SweepSums {
            dwr2: x[0],
            wr2: x[1],
        }
    }
}

/// A bounded residual sum: `None` when it was shown to exceed its bound.
impl Wire for Option<f64> {
    const LEN: usize = 2;
    fn put(&self, out: &mut [f64]) {
        out[0] = f64::from(u8::from(self.is_some()));
        out[1] = self.unwrap_or(0.0);
    }
    fn take(x: &[f64]) -> Self {
        (x[0] == 1.0).then_some(x[1])
    }
}

/// Which of `groups` rank `me` of `size` reads in a solve over `partition` with `drives`:
/// those whose bodies it sweeps or is sent after their colour ([`Ranks::readers`]) — the
/// groups that join a subdomain it sweeps or a subdomain a group of its own joins — and the
/// groups every rank reads: all with the interface solved in one group, a group a drive
/// moves a body of, and the groups joining a subdomain whose shared bodies a drive moves one
/// of (that subdomain's boundary goes to every rank, and is made of its groups' bodies).
fn reads_groups(
    groups: &[InterfaceGroup],
    partition: &Partition,
    drives: &[DriveRows],
    me: usize,
    size: usize,
) -> Vec<bool> {
    let k = partition.count();
    if groups.iter().any(|g| g.pair.0 == STATIC) {
        return vec![true; groups.len()];
    }
    let dynamic = partition.starts[k] as u32;
    let mut driven: Vec<u32> = drives
        .iter()
        .map(|d| partition.new_index[d.body as usize])
        .filter(|&b| b < dynamic)
        .collect();
    driven.sort_unstable();
    // Subdomains whose boundary a drive moves, and those this rank sweeps or borders
    // through a group of its own.
    let mut loud = vec![false; k];
    for d in drives {
        match partition.subdomain[d.body as usize] {
            STATIC => {}
            s => loud[s as usize] = true,
        }
    }
    let mut near: Vec<bool> = (0..k).map(|s| exchange::owner(s, k, size) == me).collect();
    for g in groups.iter().filter(|g| g.owner == me) {
        near[g.pair.0 as usize] = true;
        near[g.pair.1 as usize] = true;
    }
    groups
        .iter()
        .map(|g| {
            let (a, b) = (g.pair.0 as usize, g.pair.1 as usize);
            near[a]
                || near[b]
                || loud[a]
                || loud[b]
                || g.bodies.iter().any(|b| driven.binary_search(b).is_ok())
        })
        .collect()
}

/// The subdomain a contact between bodies `(b1, b2)` is solved in: the subdomain of both,
/// or of the one that is not static; [`STATIC`] for Γ (two static bodies never make a
/// contact, detection skips them: [`STATIC`] keeps such a one in Γ).
fn home(partition: &Partition, (b1, b2): (u32, u32)) -> u32 {
    match (
        partition.subdomain[b1 as usize],
        partition.subdomain[b2 as usize],
    ) {
        (a, b) if a == b => a,
        (STATIC, b) => b,
        (a, STATIC) => a,
        _ => STATIC,
    }
}

/// The bodies a Γ contact between bodies `(b1, b2)` gives its group to share: the dynamic
/// ones, in solver numbering.
fn shared_bodies(partition: &Partition, (b1, b2): (u32, u32)) -> impl Iterator<Item = u32> {
    let dynamic = partition.starts[partition.count()] as u32;
    [b1, b2]
        .map(|b| partition.new_index[b as usize])
        .into_iter()
        .filter(move |&b| b < dynamic)
}

/// The interface group of a Γ contact between bodies `(b1, b2)`: its two subdomains, in
/// order, or `(STATIC, STATIC)` when Γ is solved as one sequential group.
fn group_pair(partition: &Partition, (b1, b2): (u32, u32), parallel_interface: bool) -> (u32, u32) {
    if !parallel_interface {
        return (STATIC, STATIC);
    }
    let (s1, s2) = (
        partition.subdomain[b1 as usize],
        partition.subdomain[b2 as usize],
    );
    (s1.min(s2), s1.max(s2))
}

/// Greedy colouring of Γ's groups (`runs`: each group's pair and contact count, in pair
/// order) over `k` subdomains, largest groups first (ties by pair): a colour lasts as long as
/// its largest group, so the large groups share the first colours instead of each stretching
/// a colour of its own (paper scale, 16x2x1 on 16 threads: the interface took 40 % less time
/// than in pair order). Returns each group's colour and the number of colours.
fn colour_groups(runs: &[((u32, u32), usize)], k: usize) -> (Vec<usize>, usize) {
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_unstable_by_key(|&i| (std::cmp::Reverse(runs[i].1), runs[i].0));
    let mut used: Vec<Vec<usize>> = vec![Vec::new(); k];
    let mut colour = vec![0; runs.len()];
    let mut colours = 0;
    for i in order {
        let (a, b) = runs[i].0;
        if a == STATIC {
            colours = colours.max(1);
            continue;
        }
        let (a, b) = (a as usize, b as usize);
        let c = (0..)
            .find(|c| !used[a].contains(c) && !used[b].contains(c))
            .unwrap_or(0);
        used[a].push(c);
        used[b].push(c);
        colour[i] = c;
        colours = colours.max(c + 1);
    }
    (colour, colours)
}

/// The rank that sweeps each of Γ's groups (`runs`, coloured `colour`, between `count`
/// subdomains) over `size` ranks, a rule of the partition alone. A colour's groups run side
/// by side and every rank waits for the colour's last, so each colour is balanced by itself:
/// first each group, in pair order, goes to its own rank (the owner of its lower subdomain)
/// while that rank's share of the colour stays within the fair share (the colour's contacts
/// over the ranks, rounded up) plus half the colour's largest group; then the others, largest first (ties by pair), each to the
/// rank with the fewest of the colour's contacts so far, then the fewest over the colours
/// before, then the lowest. Should a rank's share then exceed another's by more than the
/// colour's largest group, the colour is divided by the second rule alone, which keeps
/// within that bound. A group kept on its own rank joins bodies that rank holds or borders,
/// and stays there from step to step: a rank then needs the geometry of fewer bodies, the
/// same ones. The sequential interface (pair `(STATIC, STATIC)`) is rank 0's. Any rank may
/// sweep any group: every rank holds the bodies, and the boundary bodies' velocities are
/// shared before each colour.
fn group_owners(
    runs: &[((u32, u32), usize)],
    colour: &[usize],
    colours: usize,
    count: usize,
    size: usize,
) -> Vec<usize> {
    let mut owner = vec![0; runs.len()];
    let mut total = vec![0; size];
    for c in 0..colours {
        let these: Vec<usize> = (0..runs.len()).filter(|&i| colour[i] == c).collect();
        if these.iter().any(|&i| runs[i].0 .0 == STATIC) {
            for &i in &these {
                owner[i] = 0;
                total[0] += runs[i].1;
            }
            continue;
        }
        let largest = these.iter().map(|&i| runs[i].1).max().unwrap_or(0);
        let fair = these
            .iter()
            .map(|&i| runs[i].1)
            .sum::<usize>()
            .div_ceil(size)
            + largest / 2;
        let mut by_size = these.clone();
        by_size.sort_unstable_by_key(|&i| (std::cmp::Reverse(runs[i].1), runs[i].0));
        let least_loaded = |load: &[usize], total: &[usize]| {
            (0..size)
                .min_by_key(|&r| (load[r], total[r], r))
                .expect("at least one rank")
        };
        // Own ranks first, within the fair share and half a group; the rest to the least
        // loaded.
        let mut load = vec![0; size];
        let mut placed = vec![false; runs.len()];
        let mut sorted = these.clone();
        sorted.sort_unstable_by_key(|&i| runs[i].0);
        for &i in &sorted {
            let own = exchange::owner(runs[i].0 .0 as usize, count, size);
            if load[own] + runs[i].1 <= fair {
                owner[i] = own;
                load[own] += runs[i].1;
                placed[i] = true;
            }
        }
        let mut seen = total.clone();
        for &i in by_size.iter().filter(|&&i| !placed[i]) {
            let r = least_loaded(&load, &seen);
            owner[i] = r;
            load[r] += runs[i].1;
            seen[r] += runs[i].1;
        }
        let spread = load.iter().max().unwrap_or(&0) - load.iter().min().unwrap_or(&0);
        if spread > largest {
            load.iter_mut().for_each(|l| *l = 0);
            for &i in &by_size {
                let r = least_loaded(&load, &total);
                owner[i] = r;
                load[r] += runs[i].1;
            }
        }
        for &i in &these {
            total[owner[i]] += runs[i].1;
        }
    }
    owner
}

/// One number per bucket (the correction's overlap counts), as shared between ranks.
impl Wire for f64 {
    const LEN: usize = 1;
    fn put(&self, out: &mut [f64]) {
        out[0] = *self;
    }
    fn take(x: &[f64]) -> Self {
        x[0]
    }
}

/// One step's plan of a solve distributed over ranks: who sweeps what, and which bodies each
/// bucket shares after its phase.
struct Ranks<'a> {
    ex: &'a dyn Exchange,
    sub_owner: Vec<usize>,
    group_owner: Vec<usize>,
    /// Per subdomain: its bodies that an interface contact or a drive reads.
    sub_boundary: Vec<Vec<u32>>,
    /// Per interface group: the bodies its contacts write.
    group_bodies: Vec<Vec<u32>>,
    /// Per subdomain, then per group: which ranks read the bodies it shares (see
    /// [`Ranks::readers`]).
    sub_readers: Vec<Vec<bool>>,
    group_readers: Vec<Vec<bool>>,
    /// The dynamic bodies in solver numbering: subdomain `s`'s are `starts[s]..starts[s + 1]`.
    all_bodies: Vec<u32>,
    /// Whether a solve ends with every body on every rank ([`Ranks::share_solved`]).
    whole_at_end: bool,
    starts: &'a [usize],
    buf: ShareBuffers,
    values: Vec<f64>,
    /// Seconds spent sharing.
    seconds: f64,
}

impl<'a> Ranks<'a> {
    fn new(
        ex: &'a dyn Exchange,
        p: &DdmProblem,
        starts: &'a [usize],
        dr: &[DriveRows],
        whole_at_end: bool,
    ) -> Self {
        let (k, size) = (p.sub.len(), ex.size());
        let sub_owner: Vec<usize> = (0..k).map(|s| exchange::owner(s, k, size)).collect();
        let dynamic = starts[k] as u32;
        let group_owner: Vec<usize> = p.groups.iter().map(|g| g.owner).collect();
        let mut read = vec![false; dynamic as usize];
        // Listed by the rebuild for every group, remote or not (a remote group has no local
        // problems to read them from).
        let group_bodies: Vec<Vec<u32>> = p.groups.iter().map(|g| g.bodies.clone()).collect();
        for &i in group_bodies.iter().flatten() {
            read[i as usize] = true;
        }
        let mut driven = vec![false; dynamic as usize];
        for d in dr {
            if d.body < dynamic {
                read[d.body as usize] = true;
                driven[d.body as usize] = true;
            }
        }
        let sub_boundary: Vec<Vec<u32>> = (0..k)
            .map(|s| {
                (starts[s] as u32..starts[s + 1] as u32)
                    .filter(|&i| read[i as usize])
                    .collect()
            })
            .collect();
        let (sub_readers, group_readers) = Self::readers(
            p,
            &sub_owner,
            &group_owner,
            size,
            |bodies| bodies.iter().any(|&b| driven[b as usize]),
            &sub_boundary,
            &group_bodies,
        );
        Ranks {
            ex,
            sub_owner,
            group_owner,
            sub_boundary,
            group_bodies,
            sub_readers,
            group_readers,
            all_bodies: match whole_at_end {
                true => (0..dynamic).collect(),
                false => Vec::new(),
            },
            whole_at_end,
            starts,
            buf: ShareBuffers::default(),
            values: Vec::new(),
            seconds: 0.0,
        }
    }

    /// Which ranks read the bodies each subdomain and each interface group shares after its
    /// phase (empty: every rank). A subdomain's boundary is read by the ranks of the groups
    /// that join it; a group's bodies by the ranks of its two subdomains and of the groups
    /// that join either (they may share bodies with it). A body that a drive moves is read
    /// by every rank (each sweeps the drives), and so is every body of the interface solved
    /// in one group. Groups of a colour join disjoint subdomains, so no other rank reads
    /// what a phase writes before the next share.
    fn readers(
        p: &DdmProblem,
        sub_owner: &[usize],
        group_owner: &[usize],
        size: usize,
        driven: impl Fn(&[u32]) -> bool,
        sub_boundary: &[Vec<u32>],
        group_bodies: &[Vec<u32>],
    ) -> (Vec<Vec<bool>>, Vec<Vec<bool>>) {
        let k = sub_owner.len();
        let sequential = p.groups.iter().any(|g| g.pair.0 == STATIC);
        // The groups that join each subdomain.
        let mut joins: Vec<Vec<usize>> = vec![Vec::new(); k];
        for (g, grp) in p.groups.iter().enumerate().filter(|_| !sequential) {
            joins[grp.pair.0 as usize].push(g);
            joins[grp.pair.1 as usize].push(g);
        }
        let subs = (0..k)
            .map(|s| {
                if sequential || driven(&sub_boundary[s]) {
                    return Vec::new();
                }
                let mut r = vec![false; size];
                for &g in &joins[s] {
                    r[group_owner[g]] = true;
                }
                r
            })
            .collect();
        let groups = p
            .groups
            .iter()
            .enumerate()
            .map(|(g, grp)| {
                if sequential || driven(&group_bodies[g]) {
                    return Vec::new();
                }
                let mut r = vec![false; size];
                for s in [grp.pair.0 as usize, grp.pair.1 as usize] {
                    r[sub_owner[s]] = true;
                    for &other in &joins[s] {
                        r[group_owner[other]] = true;
                    }
                }
                r
            })
            .collect();
        (subs, groups)
    }

    /// Whether this rank sweeps each subdomain, and each interface group.
    fn mine(&self) -> (Vec<bool>, Vec<bool>) {
        let me = self.ex.rank();
        (
            self.sub_owner.iter().map(|&o| o == me).collect(),
            self.group_owner.iter().map(|&o| o == me).collect(),
        )
    }

    /// Shares units and their reports `results` (the owners' values end in every rank's).
    fn share<T: Wire>(&mut self, units: &[Unit], pb: &mut [SolverBody], results: &mut [T]) {
        let t = Instant::now();
        self.values.clear();
        self.values.resize(results.len() * T::LEN, 0.0);
        for (r, v) in results
            .iter()
            .zip(self.values.chunks_exact_mut(T::LEN.max(1)))
        {
            r.put(v);
        }
        exchange::share(self.ex, units, pb, &mut self.values, &mut self.buf);
        for (u, (r, v)) in units.iter().zip(
            results
                .iter_mut()
                .zip(self.values.chunks_exact(T::LEN.max(1))),
        ) {
            if u.owner != self.ex.rank() {
                *r = T::take(v);
            }
        }
        self.seconds += t.elapsed().as_secs_f64();
    }

    /// After a subdomain phase: the bodies others read (`whole`: every body) and the reports.
    fn share_subdomains<T: Wire>(&mut self, pb: &mut [SolverBody], results: &mut [T], whole: bool) {
        let all = std::mem::take(&mut self.all_bodies);
        let boundary = std::mem::take(&mut self.sub_boundary);
        let readers = std::mem::take(&mut self.sub_readers);
        let units: Vec<Unit> = (0..self.sub_owner.len())
            .map(|s| match whole {
                true => Unit {
                    owner: self.sub_owner[s],
                    bodies: &all[self.starts[s]..self.starts[s + 1]],
                    values: T::LEN,
                    readers: &[],
                },
                false => Unit {
                    owner: self.sub_owner[s],
                    bodies: &boundary[s],
                    values: T::LEN,
                    readers: &readers[s],
                },
            })
            .collect();
        self.share(&units, pb, results);
        drop(units);
        self.all_bodies = all;
        self.sub_boundary = boundary;
        self.sub_readers = readers;
    }

    /// At the end of a solve (or of the correction's sweeps): every subdomain's bodies from its
    /// owner to every rank, when the ranks keep every body. Ranks that hold their own contacts
    /// do not: a dynamic body is then kept up to date by its owner alone, and sent to the
    /// ranks that read it when they do (`detection/ghosts.rs`); the bodies of Γ and of the
    /// drives are shared as the sweeps go, so they are the same on every rank already.
    fn share_solved(&mut self, pb: &mut [SolverBody]) {
        if self.whole_at_end {
            self.share_subdomains(pb, &mut vec![(); self.sub_owner.len()], true);
        }
    }

    /// After one colour of interface groups (`range`): their bodies and reports.
    fn share_groups<T: Wire>(
        &mut self,
        range: Range<usize>,
        pb: &mut [SolverBody],
        results: &mut [T],
    ) {
        let bodies = std::mem::take(&mut self.group_bodies);
        let readers = std::mem::take(&mut self.group_readers);
        let units: Vec<Unit> = range
            .map(|g| Unit {
                owner: self.group_owner[g],
                bodies: &bodies[g],
                values: T::LEN,
                readers: &readers[g],
            })
            .collect();
        self.share(&units, pb, results);
        drop(units);
        self.group_bodies = bodies;
        self.group_readers = readers;
    }

    /// Every bucket's report (subdomains, then groups), no bodies.
    fn share_reports<T: Wire>(&mut self, results: &mut [T]) {
        let units: Vec<Unit> = self
            .sub_owner
            .iter()
            .chain(&self.group_owner)
            .map(|&owner| Unit {
                owner,
                bodies: &[],
                values: T::LEN,
                readers: &[],
            })
            .collect();
        self.share(&units, &mut [], results);
    }
}

/// Solves the step's contact problem by Algorithm 1. `locals` and `bodies` are in the
/// caller's numbering: `bodies` holds `V_free` on entry and the end-of-step velocities on
/// return, impulses are written back to `locals`, statuses to `status`.
pub fn solve(
    nlgs: &Nlgs,
    ddm: &DdmSettings,
    partition: &Partition,
    locals: &mut [LocalProblem],
    bodies: &mut [SolverBody],
    status: &mut [ContactStatus],
) -> (SolveReport, DdmTimes) {
    let mut ws = DdmWorkspace::default();
    let (report, times, _) = solve_and_correct(
        &mut ws,
        nlgs,
        ddm,
        partition,
        locals,
        &mut [],
        bodies,
        status,
        None,
    );
    (report, times)
}

/// The overlap correction run after the velocity solve, on the same split.
pub struct CorrectionPass<'a> {
    pub settings: &'a CorrectionSettings,
    /// Time step (s).
    pub h: f64,
    /// The elastic deflection of compliant contacts, [`Elastic::NONE`] for rigid ones (see
    /// [`correction::overlaps`]).
    pub elastic: Elastic,
    /// The pseudo-velocities, one per body in the caller's numbering (output).
    pub pseudo: &'a mut Vec<SolverBody>,
}

/// Buffers of [`solve_and_correct`] kept from one step to the next, so that a step allocates
/// nothing once they have grown (fresh megabytes every step cost page faults).
#[derive(Clone, Debug, Default)]
pub struct DdmWorkspace {
    problem: DdmProblem,
    /// Bodies in solver numbering.
    pb: Vec<SolverBody>,
    /// Pseudo-velocities of the correction, solver numbering.
    pv: Vec<SolverBody>,
    /// The drives, bodies in solver numbering.
    drives: Vec<DriveRows>,
    /// The ranks of a run distributed over processes (`None`: this process solves alone);
    /// such a solve takes the contacts each rank holds, as [`crate::world::World`] steps.
    pub exchange: Option<Arc<dyn Exchange>>,
}

/// [`solve`], then the overlap correction ([`super::correction`]) on the same subdomains and
/// interface groups: each of its sweeps runs the subdomains in parallel, then Γ colour by
/// colour, so the pseudo-velocities equal those of [`super::correction::pseudo_velocities`]
/// over the contacts in [`DdmProblem::equivalent_order`], bit for bit. Returns whether a
/// correction was computed (otherwise `pseudo` is left zero).
#[allow(clippy::too_many_arguments)]
pub fn solve_and_correct(
    ws: &mut DdmWorkspace,
    nlgs: &Nlgs,
    ddm: &DdmSettings,
    partition: &Partition,
    locals: &mut [LocalProblem],
    drives: &mut [DriveRows],
    bodies: &mut [SolverBody],
    status: &mut [ContactStatus],
    correction: Option<CorrectionPass>,
) -> (SolveReport, DdmTimes, bool) {
    solve_contacts(
        ws,
        nlgs,
        ddm,
        partition,
        Contacts::Built { locals, status },
        drives,
        bodies,
        &[],
        correction,
    )
}

/// The contacts of [`solve_contacts`]: where their local problems come from, where their
/// impulses and statuses go.
pub(crate) enum Contacts<'a> {
    /// Built by the caller (its numbering); impulses and statuses written back to them.
    Built {
        locals: &'a mut [LocalProblem],
        status: &'a mut [ContactStatus],
    },
    /// Built straight into their buckets by [`DdmWorkspace::bucket`]; impulses and statuses
    /// written to `impulse` and `status` (one per contact).
    Bucketed {
        impulse: &'a mut [DVec3],
        status: &'a mut [ContactStatus],
    },
    /// Built into their buckets by [`DdmWorkspace::place_held`] and [`DdmWorkspace::fill`]
    /// from the contacts this rank holds: impulses and statuses written to `impulse` and
    /// `status` (one per contact held).
    Held {
        impulse: &'a mut [DVec3],
        status: &'a mut [ContactStatus],
    },
}

impl DdmWorkspace {
    /// The local problems the last solve built: on K ranks those of this rank's own buckets
    /// only (another rank's are never built here), in one process every contact's.
    pub fn local_problems(&self) -> usize {
        self.problem.buckets().map(|b| b.locals.len()).sum()
    }

    /// The bodies the last solve numbered: every body in one process; on K ranks, those of
    /// this rank's subdomains, those the ranks share and the static ones
    /// (a rank numbers only the bodies its part reads).
    pub fn bodies(&self) -> usize {
        self.pb.len()
    }

    /// Which rank holds each body pair after the last solve (or plan) over `partition`, on
    /// `size` ranks (see [`exchange::PairOwners`]; `attach` as there).
    pub(crate) fn pair_owners(
        &self,
        partition: &Partition,
        size: usize,
        attach: &[u32],
    ) -> exchange::PairOwners {
        let groups = self
            .problem
            .groups
            .iter()
            .map(|g| (g.pair, g.owner))
            .collect();
        exchange::PairOwners::new(partition, groups, size, attach)
    }

    /// The step's buckets over the ranks, from the `n` contacts this rank holds (contact `k`
    /// joins `bodies_of(k)`), without building any local problem (see
    /// [`DdmProblem::census`]): afterwards [`DdmWorkspace::pair_owners`] says which rank
    /// solves each pair, and, once the pairs have moved there, [`DdmWorkspace::place_held`]
    /// and [`DdmWorkspace::fill`] build this rank's buckets. A collective; returns the seconds
    /// spent sharing.
    pub(crate) fn census(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32),
        parallel_interface: bool,
    ) -> f64 {
        let ex = self.exchange.clone().expect("a solve shared between ranks");
        self.problem
            .census(partition, n, bodies_of, parallel_interface, &*ex)
    }

    /// The `n` contacts this rank holds after the census's pairs have moved (contact `k`
    /// joins `bodies_of(k)`) in its buckets (see [`DdmProblem::place_held`]).
    pub(crate) fn place_held(
        &mut self,
        partition: &Partition,
        n: usize,
        bodies_of: impl Fn(usize) -> (u32, u32) + Sync,
        parallel_interface: bool,
    ) {
        self.problem
            .place_held(partition, n, bodies_of, parallel_interface);
    }

    /// The number of contacts of the last solve's buckets, over all ranks (once
    /// [`DdmWorkspace::fill`] has built them).
    pub(crate) fn contact_total(&self) -> usize {
        self.problem.total()
    }

    /// This rank's numbering of the solve of the last [`DdmWorkspace::census`] over `partition`
    /// (on ranks; [`Partition::compact`]): the bodies of the subdomains it sweeps, those of
    /// the interface groups it sweeps or reads (see `reads_groups`), those a drive (of
    /// `drives`, bodies in the caller's numbering) moves, and the static ones. The groups'
    /// bodies are renumbered (emptied for the groups it does not read); [`DdmWorkspace::fill`]
    /// and [`solve_contacts`] take the partition returned. The bodies it leaves out are
    /// those that nothing it sweeps or reads touches: it neither reads nor writes them.
    pub(crate) fn compact(&mut self, partition: &Partition, drives: &[DriveRows]) -> Partition {
        let ex = self
            .exchange
            .as_ref()
            .expect("a solve shared between ranks");
        let (me, size, k) = (ex.rank(), ex.size(), partition.count());
        let starts = &partition.starts;
        let mut keep = vec![false; partition.order.len()];
        for s in (0..k).filter(|&s| exchange::owner(s, k, size) == me) {
            keep[starts[s]..starts[s + 1]].fill(true);
        }
        keep[starts[k]..].fill(true);
        for d in drives {
            keep[partition.new_index[d.body as usize] as usize] = true;
        }
        let read = reads_groups(&self.problem.groups, partition, drives, me, size);
        for (g, _) in self.problem.groups.iter().zip(&read).filter(|x| *x.1) {
            for &b in &g.bodies {
                keep[b as usize] = true;
            }
        }
        let (compact, local) = partition.compact(&keep);
        for (g, &read) in self.problem.groups.iter_mut().zip(&read) {
            match read {
                true => g.bodies.iter_mut().for_each(|b| *b = local[*b as usize]),
                // Nothing here reads or writes them: another rank's group, which no unit this
                // rank sweeps or reads touches.
                false => g.bodies.clear(),
            }
        }
        compact
    }

    /// Builds the local problems of this rank's buckets of the last
    /// [`DdmWorkspace::place_held`], contact `k`'s by `make(k)`, for [`solve_contacts`] with [`Contacts::Held`].
    pub(crate) fn fill(
        &mut self,
        partition: &Partition,
        make: impl Fn(usize) -> LocalProblem + Sync,
    ) {
        let ranks = self.exchange.as_ref().map(|e| (e.rank(), e.size()));
        self.problem.fill(partition, make, ranks);
    }

    /// Builds the local problems of `builder`'s contacts straight into the buckets of
    /// `partition` (no copy of them in the contacts' order first), for [`solve_contacts`]
    /// with [`Contacts::Bucketed`].
    pub(crate) fn bucket(
        &mut self,
        partition: &Partition,
        builder: &LocalBuilder,
        parallel_interface: bool,
    ) {
        let ranks = self.exchange.as_ref().map(|e| (e.rank(), e.size()));
        self.problem.rebuild_with(
            partition,
            builder.contacts.len(),
            |k| builder.bodies_of(k),
            |k| builder.at(k),
            parallel_interface,
            ranks,
        );
    }
}

/// [`solve_and_correct`] of [`Contacts`] built by the caller or here.
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve_contacts(
    ws: &mut DdmWorkspace,
    nlgs: &Nlgs,
    ddm: &DdmSettings,
    partition: &Partition,
    contacts: Contacts,
    drives: &mut [DriveRows],
    bodies: &mut [SolverBody],
    slots: &[u32],
    correction: Option<CorrectionPass>,
) -> (SolveReport, DdmTimes, bool) {
    let mut times = DdmTimes::default();
    let min_parallel = ddm.min_parallel_contacts * 2 / rayon::current_num_threads().max(2);
    let DdmWorkspace {
        problem: p,
        pb,
        pv,
        drives: dr,
        exchange: ex,
    } = ws;
    pb.clear();
    // (A rank's numbering keeps the bodies of groups that other ranks sweep, which need not
    // be up to date here: they are read only once their owners have sent them.)
    let solver_body = |i: u32| match slots.get(i as usize) {
        Some(&LEFT_OUT) => SolverBody::UNREAD,
        _ => bodies[slot(slots, i as usize)],
    };
    pb.par_extend(partition.order.par_iter().map(|&i| solver_body(i)));
    let n = match &contacts {
        Contacts::Built { locals, .. } => {
            let ranks = ex.as_ref().map(|e| (e.rank(), e.size()));
            p.rebuild(partition, locals, ddm.parallel_interface, ranks);
            locals.len()
        }
        Contacts::Bucketed { impulse, status } => {
            assert!(p.slot.len() == impulse.len() && status.len() == impulse.len());
            impulse.len()
        }
        Contacts::Held { .. } => p.total(),
    };
    // Each rank writes back the contacts it holds, all in its own buckets.
    assert!(
        matches!(contacts, Contacts::Held { .. }) || ex.as_ref().is_none_or(|e| e.size() == 1),
        "a solve shared between ranks takes the contacts each rank holds"
    );
    let starts = &partition.starts;
    let mut report = SolveReport::default();

    dr.clear();
    dr.extend(drives.iter().map(|d| DriveRows {
        body: partition.new_index[d.body as usize],
        ..*d
    }));
    // Distributed over ranks: each builds and sweeps its own buckets only, and shares what
    // the others read next.
    let whole_at_end = !matches!(contacts, Contacts::Held { .. });
    let mut ranks = ex
        .as_deref()
        .filter(|e| e.size() > 1)
        .map(|e| Ranks::new(e, p, starts, dr, whole_at_end));

    // 1. Residual scale: each bucket's terms summed in its order (in parallel), the buckets'
    // sums in the equivalent order (on ranks, each bucket's from its owner), then warm start.
    let pbs = pb.as_slice();
    let mut scale: Vec<f64> = p
        .buckets()
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|b| b.locals.iter().fold(0.0, |s, l| s + nlgs.scale2(l, pbs)))
        .collect();
    if let Some(r) = ranks.as_mut() {
        r.share_reports(&mut scale);
    }
    let q2: f64 = scale.iter().fold(0.0, |s, &t| s + t) + drive::scale_sum(dr, pb.as_slice());
    let q = if q2 > 0.0 { q2.sqrt() } else { 1.0 };
    let (sub_mine, group_mine) = match &ranks {
        Some(r) => r.mine(),
        None => (vec![true; p.sub.len()], vec![true; p.groups.len()]),
    };
    let bucket_mine: Vec<bool> = sub_mine.iter().chain(&group_mine).copied().collect();
    let (smine, gmine) = (|s: usize| sub_mine[s], |g: usize| group_mine[g]);
    // The warm start in the sweeps' order, shared as a sweep is.
    let t = Instant::now();
    let mut none = for_subdomains(p, pb, starts, min_parallel, &smine, |b, v| {
        nlgs.warm_start(&b.locals, v)
    });
    if let Some(r) = ranks.as_mut() {
        r.share_subdomains(pb, &mut none, false);
    }
    times.subdomains += t.elapsed().as_secs_f64();
    let t = Instant::now();
    for_interface(
        p,
        pb,
        starts,
        min_parallel,
        &gmine,
        &mut |range, pb, none: &mut [()]| {
            if let Some(r) = ranks.as_mut() {
                r.share_groups(range, pb, none);
            }
        },
        |b, v| nlgs.warm_start(&b.locals, v),
    );
    times.interface += t.elapsed().as_secs_f64();

    // 2. DDM iterations.
    let s = &nlgs.settings;
    let total_rows = n + dr.len();
    let mut stop = StopRule::new();
    if total_rows == 0 {
        report.converged = true;
    }
    let drift = super::nlgs::skip_threshold(s, q, total_rows);
    let mut lazy = nlgs.clone();
    for j in 1..=s.max_iterations {
        if total_rows == 0 {
            break;
        }
        lazy.for_sweep(j, drift);
        let nlgs = &lazy;
        let t = Instant::now();
        let mut sub_sums = for_subdomains(p, pb, starts, min_parallel, &smine, |b, v| {
            let mut sums = SweepSums::default();
            for _ in 0..ddm.inner_sweeps {
                sums = nlgs.sweep_k(j, &mut b.locals, v, &mut b.status);
            }
            sums
        });
        if let Some(r) = ranks.as_mut() {
            r.share_subdomains(pb, &mut sub_sums, false);
        }
        times.subdomains += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut gamma_sums = vec![SweepSums::default(); p.groups.len()];
        for _ in 0..ddm.interface_sweeps {
            gamma_sums = for_interface(
                p,
                pb,
                starts,
                min_parallel,
                &gmine,
                &mut |range, pb, sums| {
                    if let Some(r) = ranks.as_mut() {
                        r.share_groups(range, pb, sums);
                    }
                },
                |b, v| nlgs.sweep_k(j, &mut b.locals, v, &mut b.status),
            );
        }
        let drive_sums = drive::sweep(dr, pb.as_mut_slice());
        times.interface += t.elapsed().as_secs_f64();
        let mut sums = SweepSums::default();
        for x in sub_sums.into_iter().chain(gamma_sums) {
            sums += x;
        }
        sums += drive_sums;
        report.iterations = j;
        report.quad = sums.quad();
        let (checks, proofs) = (&mut report.residual_checks, &mut report.hot_proofs);
        if stop.converged(s, j, report.quad, |bound| {
            *checks += 1;
            residual_within(
                nlgs,
                p,
                dr,
                pb,
                q,
                bound,
                ranks.as_mut(),
                &bucket_mine,
                proofs,
            )
        }) {
            report.converged = true;
            break;
        }
    }
    report.residual = stop.final_residual(report.iterations, || {
        residual_within(
            nlgs,
            p,
            dr,
            pb,
            q,
            f64::INFINITY,
            ranks.as_mut(),
            &bucket_mine,
            &mut 0,
        )
        .unwrap_or(f64::INFINITY)
    });
    for (d, w) in drives.iter_mut().zip(dr.iter()) {
        d.impulse_v = w.impulse_v;
        d.impulse_w = w.impulse_w;
    }
    if let Some(r) = ranks.as_mut() {
        r.share_solved(pb);
    }

    // 3. Back to the caller's numbering, in parallel over the caller's bodies and contacts.
    let (new_index, pb_ref) = (&partition.new_index, pb.as_slice());
    if slots.is_empty() {
        bodies
            .par_iter_mut()
            .with_min_len(1024)
            .zip(new_index.par_iter())
            .for_each(|(b, &k)| *b = pb_ref[k as usize]);
    } else {
        to_slots(partition, slots, pb_ref, bodies);
    }
    let buckets: Vec<&Bucket> = p.buckets().collect();
    let solved = |(st, &(bi, k)): (&mut ContactStatus, &(u32, u32))| {
        let b = buckets[bi as usize];
        *st = b.status[k as usize];
        b.impulse(k as usize)
    };
    let slot = p.slot.par_iter();
    match contacts {
        Contacts::Built { locals, status } => locals
            .par_iter_mut()
            .with_min_len(1024)
            .zip(status.par_iter_mut().zip(slot))
            .for_each(|(c, x)| c.r = solved(x)),
        Contacts::Bucketed { impulse, status } | Contacts::Held { impulse, status } => impulse
            .par_iter_mut()
            .with_min_len(1024)
            .zip(status.par_iter_mut().zip(slot))
            .for_each(|(r, x)| *r = solved(x)),
    }
    drop(buckets);

    // 4. Overlap correction on the same split.
    let corrected = match correction {
        Some(c) => correct(
            p,
            partition,
            pb,
            pv,
            min_parallel,
            c,
            ranks.as_mut(),
            (&sub_mine, &group_mine),
            (slots, bodies.len()),
        ),
        None => false,
    };
    if let Some(r) = &ranks {
        times.communication = r.seconds;
    }
    (report, times, corrected)
}

/// The pseudo-velocity sweeps of the overlap correction, on the subdomains in parallel then
/// on Γ, `settings.sweeps` times (distributed over `ranks` as the velocity solve).
#[allow(clippy::too_many_arguments)]
fn correct(
    p: &mut DdmProblem,
    partition: &Partition,
    pb: &[SolverBody],
    pv: &mut Vec<SolverBody>,
    min_parallel: usize,
    c: CorrectionPass,
    mut ranks: Option<&mut Ranks>,
    (sub_mine, group_mine): (&[bool], &[bool]),
    (slots, n_slots): (&[u32], usize),
) -> bool {
    let (smine, gmine) = (|s: usize| sub_mine[s], |g: usize| group_mine[g]);
    let starts = &partition.starts;
    pv.clear();
    let (settings, h, e) = (c.settings, c.h, c.elastic);
    pv.par_extend(
        pb.par_iter()
            .map(|b| correction::at_rest(b, settings.rotation)),
    );
    // Each rank finds its buckets' overlaps; the counts are shared, so all agree on `found`.
    let overlaps =
        |b: &mut Bucket| correction::overlaps(settings, h, e, &b.locals, &mut b.overlaps) as f64;
    let mut counts: Vec<f64> =
        for_subdomains(p, pv, starts, min_parallel, &smine, |b, _| overlaps(b))
            .into_iter()
            .chain(for_interface(
                p,
                pv,
                starts,
                min_parallel,
                &gmine,
                &mut |_, _, _| {},
                |b, _| overlaps(b),
            ))
            .collect();
    if let Some(r) = ranks.as_deref_mut() {
        r.share_reports(&mut counts);
    }
    let found = counts.iter().any(|&n| n > 0.0);
    if found {
        for _ in 0..settings.sweeps {
            let mut none = vec![(); p.sub.len()];
            none = for_subdomains(p, pv, starts, min_parallel, &smine, |b, v| {
                correction::sweep(&b.locals, &mut b.overlaps, v, settings.rotation)
            });
            if let Some(r) = ranks.as_deref_mut() {
                r.share_subdomains(pv, &mut none, false);
            }
            for_interface(
                p,
                pv,
                starts,
                min_parallel,
                &gmine,
                &mut |range, pv, none: &mut [()]| {
                    if let Some(r) = ranks.as_deref_mut() {
                        r.share_groups(range, pv, none);
                    }
                },
                |b, v| correction::sweep(&b.locals, &mut b.overlaps, v, settings.rotation),
            );
        }
        if let Some(r) = ranks {
            r.share_solved(pv);
        }
    }
    let pv = pv.as_slice();
    c.pseudo.clear();
    if slots.is_empty() {
        c.pseudo.par_extend(
            partition
                .new_index
                .par_iter()
                .with_min_len(1024)
                .map(|&k| pv[k as usize]),
        );
    } else {
        c.pseudo.resize(n_slots, SolverBody::UNREAD);
        to_slots(partition, slots, pv, c.pseudo);
    }
    found
}

/// Writes each body numbered by a rank's `partition` (`numbered`, solver numbering) to its
/// slot in `out`, if it has one here (see [`slot`]).
fn to_slots(partition: &Partition, slots: &[u32], numbered: &[SolverBody], out: &mut [SolverBody]) {
    for (&i, b) in partition.order.iter().zip(numbered) {
        match slots[i as usize] {
            LEFT_OUT => {}
            k => out[k as usize] = *b,
        }
    }
}

/// Whether the terms of the buckets' hot contacts (see [`Bucket::hot`], listed by the last
/// full check) alone exceed `limit`, summed bucket by bucket in the buckets' order and in
/// their order within each bucket. Then the full sum exceeds it too, bit for bit: rounded
/// addition is monotone in each operand and adding a non-negative term never lowers a sum,
/// so leaving out terms of an ordered sum of non-negative terms can only lower it. A check
/// proven failed here is the one the full pass would have failed: same decision, same state.
fn hot_exceeds(nlgs: &Nlgs, p: &mut DdmProblem, pb: &[SolverBody], limit: f64) -> bool {
    if !limit.is_finite() || p.buckets().all(|b| b.hot.is_empty()) {
        return false;
    }
    let reuse = nlgs.settings.reuse_residual_terms;
    let buckets: Vec<&mut Bucket> = p.buckets_mut().collect();
    let sums: Vec<f64> = buckets
        .into_par_iter()
        .map(|b| {
            let cache = TermCache::ready(&mut b.terms, b.locals.len(), reuse);
            nlgs.residual_sum_of(&b.locals, pb, &b.hot, cache)
        })
        .collect();
    sums.into_iter().fold(0.0, |s, t| s + t) > limit
}

/// Relative natural-map residual over all contacts and drives: each bucket's sum in parallel,
/// the sums added in the equivalent order, the drives' last; `None` as soon as one bucket's
/// partial sum shows that it exceeds `bound` (the sums are non-negative), or when the hot
/// contacts alone do (see [`hot_exceeds`], counted in `hot_proofs`).
#[allow(clippy::too_many_arguments)]
fn residual_within(
    nlgs: &Nlgs,
    p: &mut DdmProblem,
    dr: &[DriveRows],
    pb: &[SolverBody],
    q: f64,
    bound: f64,
    ranks: Option<&mut Ranks>,
    mine: &[bool],
    hot_proofs: &mut usize,
) -> Option<f64> {
    let limit = super::exceeding_sum(bound, q);
    let reuse = nlgs.settings.reuse_residual_terms;
    // Shared between ranks, every rank would have to agree on the outcome: the full check.
    let hot_first = nlgs.settings.hot_first && ranks.is_none();
    if hot_first && hot_exceeds(nlgs, p, pb, limit) {
        *hot_proofs += 1;
        return None;
    }
    let rows: usize = p.buckets().map(Bucket::len).sum::<usize>() + dr.len();
    let above = super::nlgs::hot_threshold(limit, rows);
    let buckets: Vec<&mut Bucket> = p.buckets_mut().collect();
    let mut sums: Vec<Option<f64>> = buckets
        .into_par_iter()
        .zip(mine.par_iter())
        .map(|(b, &mine)| {
            if !mine {
                return None;
            }
            let cache = TermCache::ready(&mut b.terms, b.locals.len(), reuse);
            let hot = hot_first.then_some((&mut b.hot, above));
            nlgs.residual_sum_marking(&b.locals, pb, limit, cache, hot)
        })
        .collect();
    if let Some(r) = ranks {
        r.share_reports(&mut sums);
    }
    let mut sum = 0.0;
    for s in sums {
        sum += s?;
    }
    sum += drive::residual_sum(dr, pb);
    Some(sum.sqrt() / q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A local problem between `body1` and `body2`, for tests of the bucketing.
    pub(super) fn local((body1, body2): (u32, u32)) -> LocalProblem {
        LocalProblem {
            body1,
            body2,
            dynamic1: true,
            dynamic2: true,
            frame: [DVec3::X, DVec3::Y],
            r1: DVec3::ZERO,
            r2: DVec3::ZERO,
            w: crate::math::Sym3::from_mat(crate::math::DMat3::IDENTITY),
            gap: 0.0,
            mu: 0.0,
            r: DVec3::ZERO,
            r_prev: 0.0,
            rt_prev: [0.0; 2],
            seen: [0; 2],
        }
    }

    /// The scheduling threshold stays out of the settings' JSON at its default (checkpoints
    /// compare that JSON, so older runs still resume) and round-trips otherwise.
    #[test]
    fn default_threshold_is_not_serialised() {
        let d = DdmSettings::default();
        let json = serde_json::to_string(&d).unwrap();
        assert!(!json.contains("min_parallel_contacts"), "{json}");
        assert_eq!(serde_json::from_str::<DdmSettings>(&json).unwrap(), d);
        let zero = DdmSettings {
            min_parallel_contacts: 0,
            ..d
        };
        let json = serde_json::to_string(&zero).unwrap();
        assert!(json.contains("\"min_parallel_contacts\":0"), "{json}");
        assert_eq!(serde_json::from_str::<DdmSettings>(&json).unwrap(), zero);
    }

    /// 2x2 subdomains, Γ's six pairs: three colours of two disjoint groups. On two ranks each
    /// colour is split one group each (the old rule, a group to its first subdomain's owner,
    /// gave rank 0 both groups of two colours); one rank sweeps everything.
    #[test]
    fn each_colour_of_groups_is_divided_between_the_ranks() {
        let runs = [
            ((0, 1), 40),
            ((0, 2), 35),
            ((0, 3), 5),
            ((1, 2), 6),
            ((1, 3), 30),
            ((2, 3), 38),
        ];
        let (colour, colours) = colour_groups(&runs, 4);
        assert_eq!(colours, 3);
        for c in 0..3 {
            let these: Vec<_> = (0..6).filter(|&i| colour[i] == c).collect();
            assert_eq!(these.len(), 2, "colour {c}: {these:?}");
            let (a, b) = (runs[these[0]].0, runs[these[1]].0);
            assert!(a.0 != b.0 && a.0 != b.1 && a.1 != b.0 && a.1 != b.1);
        }
        let owner = group_owners(&runs, &colour, colours, 4, 2);
        for c in 0..3 {
            let mut ranks: Vec<_> = (0..6)
                .filter(|&i| colour[i] == c)
                .map(|i| owner[i])
                .collect();
            ranks.sort_unstable();
            assert_eq!(ranks, [0, 1], "colour {c}");
        }
        assert_eq!(group_owners(&runs, &colour, colours, 4, 1), [0; 6]);
        // Eight slabs in a row on two ranks (slabs 0–3 rank 0's): a colour's four groups of
        // about the same size stay with the rank of their lower slab, two each (the largest
        // first to the least loaded rank gave ranks 0, 1, 1, 0).
        let row = [((0, 1), 40), ((2, 3), 39), ((4, 5), 38), ((6, 7), 37)];
        assert_eq!(group_owners(&row, &[0; 4], 1, 8, 2), [0, 0, 1, 1]);
        // The sequential interface is rank 0's whatever the ranks.
        assert_eq!(group_owners(&[((STATIC, STATIC), 9)], &[0], 1, 4, 3), [0]);
    }

    /// A rank numbers the bodies of the interface groups it sweeps or reads only: on eight
    /// slabs in a row over two ranks, each leaves out the groups at the other end of the
    /// row, unless a drive moves a body of a slab they join (then every rank reads them).
    #[test]
    fn a_rank_reads_the_groups_near_its_slabs() {
        let n = 80;
        let positions: Vec<DVec3> = (0..n).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        let partition = Partition::build(
            &positions,
            &vec![true; n],
            [8, 1, 1],
            Balance::Volume,
            &[1.0; 80],
        );
        let starts = &partition.starts;
        let runs: Vec<((u32, u32), usize)> = (0..7).map(|s| ((s, s + 1), 10)).collect();
        let (colour, colours) = colour_groups(&runs, 8);
        let owner = group_owners(&runs, &colour, colours, 8, 2);
        let groups: Vec<InterfaceGroup> = runs
            .iter()
            .enumerate()
            .map(|(g, &(pair, _))| InterfaceGroup {
                pair,
                colour: colour[g],
                owner: owner[g],
                bucket: Bucket::default(),
                bodies: vec![starts[g + 1] as u32 - 1, starts[g + 1] as u32],
            })
            .collect();
        let reads = |me: usize, drives: &[DriveRows]| -> Vec<usize> {
            let read = reads_groups(&groups, &partition, drives, me, 2);
            (0..7).filter(|&g| read[g]).collect()
        };
        let (r0, r1) = (reads(0, &[]), reads(1, &[]));
        assert!(
            r0.starts_with(&[0, 1, 2, 3]) && !r0.contains(&6),
            "rank 0 reads {r0:?}"
        );
        assert!(
            r1.ends_with(&[3, 4, 5, 6]) && !r1.contains(&0),
            "rank 1 reads {r1:?}"
        );
        // A drive on the last body (slab 7): the groups joining slab 7 go to every rank.
        let drive = DriveRows {
            body: partition.order[n - 1],
            target_v: DVec3::ZERO,
            target_w: DVec3::ZERO,
            bound_v: DVec3::ZERO,
            bound_w: DVec3::ZERO,
            impulse_v: DVec3::ZERO,
            impulse_w: DVec3::ZERO,
            translate: true,
            rotate: true,
        };
        assert!(reads(0, &[drive]).contains(&6));
        // The interface in one sequential group: every rank reads it.
        let one = InterfaceGroup {
            pair: (STATIC, STATIC),
            ..groups[0].clone()
        };
        assert_eq!(reads_groups(&[one], &partition, &[], 1, 2), [true]);
    }

    proptest::proptest! {
        /// The rank [`exchange::PairOwners`] gives a pair is the owner of the bucket its
        /// contacts were solved in (subdomain or interface group), on any scene and ranks,
        /// with Γ in groups or sequential; a pair without contacts gets a rank too.
        #[test]
        fn a_pair_is_held_by_the_owner_of_its_bucket(
            positions in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0), 12..60),
            picks in proptest::collection::vec((0usize..1000, 0usize..1000), 1..150),
            dims in proptest::sample::select(vec![[2usize, 1, 1], [2, 2, 1], [3, 2, 2], [4, 1, 1]]),
            size in 1usize..5,
            parallel_interface in proptest::bool::ANY,
        ) {
            let n = positions.len();
            let positions: Vec<DVec3> = positions.iter().map(|&(x, y, z)| DVec3::new(x, y, z)).collect();
            // The last three bodies are static (walls, drivers): a pair has a dynamic body.
            let dynamic: Vec<bool> = (0..n).map(|i| i < n - 3).collect();
            let partition =
                Partition::build(&positions, &dynamic, dims, Balance::Volume, &vec![1.0; n]);
            let mut pairs: Vec<(u32, u32)> = picks
                .iter()
                .map(|&(a, b)| ((a % n) as u32, (b % (n - 3)) as u32))
                .filter(|(a, b)| a != b)
                .map(|(a, b)| (a.min(b), a.max(b)))
                .collect();
            pairs.sort_unstable();
            let mut ws = DdmWorkspace::default();
            ws.problem.rebuild_with(
                &partition,
                pairs.len(),
                |k| pairs[k],
                |k| local(pairs[k]),
                parallel_interface,
                Some((0, size)),
            );
            let owners = ws.pair_owners(&partition, size, &[]);
            let k = partition.count();
            for (c, &(a, b)) in pairs.iter().enumerate() {
                let (bucket, _) = ws.problem.slot[c];
                let expected = match bucket as usize {
                    s if s < k => exchange::owner(s, k, size),
                    g => ws.problem.groups[g - k].owner,
                };
                proptest::prop_assert_eq!(owners.of(a, b), expected, "pair {:?}", (a, b));
            }
            for a in 0..n as u32 {
                for b in a + 1..n as u32 {
                    proptest::prop_assert!(owners.of(a, b) < size);
                }
            }
        }
    }

    proptest::proptest! {
        /// Within a colour, the ranks' contact counts differ by at most the colour's largest
        /// group (the greedy rule's bound), whatever the groups and the ranks.
        #[test]
        fn a_colour_is_balanced_within_its_largest_group(
            sizes in proptest::collection::vec(1usize..500, 1..40),
            k in 2usize..12,
            size in 1usize..6,
        ) {
            let mut runs: Vec<((u32, u32), usize)> = Vec::new();
            for (i, &n) in sizes.iter().enumerate() {
                let a = (i * 7) % k;
                let b = (a + 1 + (i * 3) % (k - 1)) % k;
                let pair = (a.min(b) as u32, a.max(b) as u32);
                if !runs.iter().any(|r| r.0 == pair) {
                    runs.push((pair, n));
                }
            }
            runs.sort_unstable();
            let (colour, colours) = colour_groups(&runs, k);
            let owner = group_owners(&runs, &colour, colours, k, size);
            for c in 0..colours {
                let mut load = vec![0; size];
                let mut largest = 0;
                for i in (0..runs.len()).filter(|&i| colour[i] == c) {
                    proptest::prop_assert!(owner[i] < size);
                    load[owner[i]] += runs[i].1;
                    largest = largest.max(runs[i].1);
                }
                let (lo, hi) = (load.iter().min().unwrap(), load.iter().max().unwrap());
                proptest::prop_assert!(hi - lo <= largest, "colour {}: {:?}", c, load);
            }
        }
    }
}
