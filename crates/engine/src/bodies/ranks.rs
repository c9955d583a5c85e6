//! The bodies of a run shared between ranks, as what is computed over them sees them.
//!
//! Each body is *owned* by one rank: in a domain-decomposed run whose ranks hold their own
//! pairs, the owner of the body's subdomain at the last solve (rank 0 for the bodies of no
//! subdomain, and before the first solve). What is computed over all bodies — the health
//! check's non-finite and speed passes, the partition's weights — is computed by each rank
//! over its own bodies and combined over the ranks, so that it needs the state of no other
//! rank's bodies and gives a single process's answer. Otherwise (one process, or ranks that
//! each solve the whole scene) every rank answers for every body.

use crate::solver::partition::STATIC;
use crate::world::World;

impl World {
    /// The rank that owns body `i` when the ranks hold their own pairs (see the module).
    pub(crate) fn body_owner(&self, i: usize) -> usize {
        let Some(owners) = self.detector.owners.as_ref() else {
            return 0;
        };
        match owners.subdomain(i) {
            STATIC => 0,
            s => owners.of_subdomain(s as usize),
        }
    }

    /// Whether what is computed over all bodies is each rank's over its own, combined over
    /// the ranks (a domain-decomposed run whose ranks hold their own pairs).
    pub(crate) fn shares_bodies(&self) -> bool {
        self.detector.hold
    }

    /// Whether this rank answers for body `i` in what is computed over all bodies: its owner
    /// when the ranks share the bodies, every rank otherwise.
    pub(crate) fn answers_for(&self, i: usize) -> bool {
        !self.shares_bodies() || self.body_owner(i) == self.rank()
    }
}
