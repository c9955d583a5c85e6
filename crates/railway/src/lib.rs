//! # ballast-railway
//!
//! The track's language on top of the generic engine:
//!
//! * [`grading`]: grading curves (sieve tables, EN 13450 presets) and size sampling that turns a
//!   mass distribution into a number distribution;
//! * [`grains`]: seeded random polyhedral ballast grains following a grading curve;
//! * [`mod@compacity`]: the solid fraction in a control box, from exact clipped volumes.
//!
//! Conventions: SI units except sieve sizes, given in millimetres as in the standards; the
//! sieve size of a grain is its volume-equivalent diameter (see [`grading`]).

pub mod compacity;
pub mod grading;
pub mod grains;

pub use compacity::{clipped_volume, compacity, solid_volume, CompacityError};
pub use grading::{GradingCurve, GradingError, GradingTable, SizeClass};
pub use grains::{generate_grains, Amount, GrainError, GrainSpec};
