//! Outputs of a world whose solves are shared between ranks: which rank owns each body, for
//! the parts each rank writes (VTK pieces, checkpoint parts) — a rule of the scene alone, so
//! every rank finds the same owners — and the agreement that every part is written. A
//! contact goes in the part of the rank that holds it ([`World::holds_contact`]).

use crate::bodies::BodyKind;
use crate::solver::partition::STATIC;
use crate::world::World;

/// The rank that owns each body of a world shared between ranks: a dynamic body (or a
/// force-limited driven one) belongs to the owner of its subdomain in the partition of the scene as it is
/// ([`World::partition`]); without domain decomposition, to contiguous blocks of body
/// indices. Other bodies: rank 0.
pub(crate) struct Owners {
    /// Owner of each body.
    pub body: Vec<usize>,
}

impl Owners {
    /// The owners in `world` as it is, over `ranks` ranks.
    pub fn of(world: &World, ranks: usize) -> Self {
        let n = world.bodies.len();
        let body = match &world.settings.ddm {
            Some(d) => {
                let p = world.partition(d);
                let count: usize = p.dims.iter().product();
                p.subdomain
                    .iter()
                    .map(|&s| {
                        if s == STATIC {
                            0
                        } else {
                            crate::solver::exchange::owner(s as usize, count, ranks)
                        }
                    })
                    .collect()
            }
            None => (0..n)
                .map(|i| {
                    if world.bodies.kind[i] == BodyKind::Dynamic {
                        i * ranks / n.max(1)
                    } else {
                        0
                    }
                })
                .collect(),
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
