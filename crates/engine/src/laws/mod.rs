//! Contact laws: Signorini-Coulomb with restitution 0, friction coefficients per pair of groups,
//! and the exact solver of the local 3×3 problem.

pub mod closure;
pub mod coulomb;
pub mod friction;

pub use closure::{default_overlap_cap, driven_overlap_cap, Elastic, NormalLaw};
pub use coulomb::{solve_local, ContactStatus};
pub use friction::FrictionTable;
