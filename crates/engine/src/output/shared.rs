//! Outputs of a world whose solves are shared between ranks: which rank owns each body, for
//! the parts each rank writes (VTK pieces, checkpoint parts) — the same on every rank, found
//! without a collective — and the agreement that every part is written. A
//! contact goes in the part of the rank that holds it ([`World::holds_contact`]).

use crate::bodies::BodyKind;
use crate::world::World;

/// The rank that owns each body of a world shared between ranks, for the parts each rank
/// writes: when the ranks share the bodies (a domain-decomposed run), the rank that answers
/// for it ([`World::answers_for`]: the owner of its subdomain at the last solve, which has
/// it up to date); otherwise, dynamic bodies in contiguous blocks of body indices. Other
/// bodies: rank 0. Every rank finds the same owners, with no collective.
pub(crate) struct Owners {
    /// Owner of each body.
    pub body: Vec<usize>,
}

impl Owners {
    /// The owners in `world` as it is, over `ranks` ranks.
    pub fn of(world: &World, ranks: usize) -> Self {
        let n = world.bodies.len();
        let body = if world.shares_bodies() {
            (0..n).map(|i| world.body_owner(i)).collect()
        } else {
            (0..n)
                .map(|i| {
                    if world.bodies.kind[i] == BodyKind::Dynamic {
                        i * ranks / n.max(1)
                    } else {
                        0
                    }
                })
                .collect()
        };
        Owners { body }
    }
}

/// Every rank's `mine` (the same number of values on every rank), gathered in rank order: a
/// collective, every rank calls it at the same point. Alone: `mine`.
pub(crate) fn gather(world: &World, mine: &[f64]) -> Vec<f64> {
    match world.exchange() {
        Some(ex) => crate::solver::exchange::gather_equal(ex, mine),
        None => mine.to_vec(),
    }
}
