//! The bodies of a run shared between ranks, as what is computed over them sees them.
//!
//! Each body is *owned* by one rank: in a domain-decomposed run whose ranks hold their own
//! pairs, the owner of the body's subdomain at the last solve (rank 0 for the bodies of no
//! subdomain, and before the first solve). What is computed over all bodies — the health
//! check's non-finite and speed passes, the partition's weights — is computed by each rank
//! over its own bodies and combined over the ranks, so that it needs the state of no other
//! rank's bodies and gives a single process's answer. Otherwise (one process, or ranks that
//! each solve the whole scene) every rank answers for every body.
//!
//! What an output reads of every body (the kinetic energy, the state digest, a railway
//! indicator's grains) is gathered from the bodies' owners in body order
//! ([`World::gather_body_values`]), so that its sums and hashes run in one process's order.
//! Between steps a rank need keep only its own dynamic bodies up to date: the others it
//! reads during a step are sent to it (`detection/ghosts.rs`).

use super::BodyKind;
use crate::detection::ghosts::owner_of;
use crate::digest::{body_state, digest_of};
use crate::solver::exchange::gather_varying;
use crate::world::World;

impl World {
    /// The rank that owns body `i` when the ranks hold their own pairs (see the module).
    pub(crate) fn body_owner(&self, i: usize) -> usize {
        self.detector
            .owners
            .as_ref()
            .map_or(0, |owners| owner_of(owners, i))
    }

    /// Whether what is computed over all bodies is each rank's over its own, combined over
    /// the ranks (a domain-decomposed run whose ranks hold their own pairs).
    pub(crate) fn shares_bodies(&self) -> bool {
        self.detector.hold
    }

    /// Whether this rank answers for body `i` in what is computed over all bodies: its owner
    /// when the ranks share the bodies, every rank otherwise. Only the bodies a rank answers
    /// for need be up to date on it for [`World::gather_body_values`] and what uses it.
    pub fn answers_for(&self, i: usize) -> bool {
        !self.shares_bodies() || self.body_owner(i) == self.rank()
    }

    /// The values `f` gives each body (any number, pushed onto its second argument) on the
    /// rank that answers for the body, in body order, on every rank; bodies given none are
    /// left out. `f` is asked only about the bodies this rank answers for. A collective when
    /// the ranks share the bodies: every rank calls it at the same point.
    pub fn gather_body_values(&self, f: impl Fn(usize, &mut Vec<f64>)) -> BodyValues {
        let mut mine = BodyValues::default();
        let mut row = Vec::new();
        for i in (0..self.bodies.len()).filter(|&i| self.answers_for(i)) {
            row.clear();
            f(i, &mut row);
            if !row.is_empty() {
                let at = mine.values.len();
                mine.values.extend_from_slice(&row);
                mine.rows.push((i, at..mine.values.len()));
            }
        }
        let Some(ex) = self.exchange().filter(|_| self.shares_bodies()) else {
            return mine;
        };
        // Sent as: index, number of values, the values; body after body.
        let mut send = Vec::with_capacity(mine.values.len() + 2 * mine.rows.len());
        for (i, r) in &mine.rows {
            send.extend([*i as f64, r.len() as f64]);
            send.extend_from_slice(&mine.values[r.clone()]);
        }
        let (all, _) = gather_varying(ex, &send);
        let mut rows = Vec::new();
        let mut at = 0;
        while at < all.len() {
            let (i, len) = (all[at] as usize, all[at + 1] as usize);
            rows.push((i, at + 2..at + 2 + len));
            at += 2 + len;
        }
        // Each rank's run is in body order and a body has one owner: a merge of the runs.
        rows.sort_unstable_by_key(|(i, _)| *i);
        BodyValues { rows, values: all }
    }

    /// Kinetic energy of the dynamic bodies ([`super::BodySet::kinetic_energy`]), each from
    /// its owner, summed in body order: one process's value on every rank. A collective when
    /// the ranks share the bodies.
    pub fn kinetic_energy(&self) -> f64 {
        let b = &self.bodies;
        self.gather_body_values(|i, out| {
            if b.kind[i] == BodyKind::Dynamic {
                out.push(b.kinetic_energy_of(i));
            }
        })
        .iter()
        .map(|(_, e)| e[0])
        .sum()
    }

    /// The digest of every body's state ([`crate::digest::state_digest`]), each body's state
    /// from its owner: one process's digest on every rank. A collective when the ranks share
    /// the bodies.
    pub fn state_digest(&self) -> String {
        let states = self.gather_body_values(|i, out| out.extend(body_state(&self.bodies, i)));
        digest_of(states.iter().map(|(_, s)| s))
    }
}

/// Values of bodies gathered from the ranks that answer for them
/// ([`World::gather_body_values`]), in body order.
#[derive(Clone, Debug, Default)]
pub struct BodyValues {
    /// Each body given values: its index and where its values lie in `values`.
    rows: Vec<(usize, std::ops::Range<usize>)>,
    values: Vec<f64>,
}

impl BodyValues {
    /// Each body given values, with its values, in body order.
    pub fn iter(&self) -> impl Iterator<Item = (usize, &[f64])> + '_ {
        self.rows.iter().map(|(i, r)| (*i, &self.values[r.clone()]))
    }

    /// The number of bodies given values.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether no body was given values.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}
