//! # ballast-railway
//!
//! The track's language on top of the generic engine:
//!
//! * [`grading`]: grading curves (sieve tables, EN 13450 presets) and size sampling that turns a
//!   mass distribution into a number distribution;
//! * [`grains`]: seeded random polyhedral ballast grains following a grading curve;
//! * [`mod@compacity`]: the solid fraction in a control box, from exact clipped volumes;
//! * [`track`]: the bed, its sleeper blocks, cribs and control volumes;
//! * [`tamping`]: the tamping cycle (lift, vibrating tines, squeeze, hold, withdraw, lower);
//! * [`scene`]: the bodies of a track model and the paper's friction groups;
//! * [`preparation`]: the deposited, cached ballast bed;
//! * [`indicators`]: compacity, block heights, tine forces, coordination through a run;
//! * [`sections`]: vertical sections through the bed at chosen moments (speed, load);
//! * [`scenario`]: track scenario files and the `default` and `paper` presets;
//! * `defaults`: the engine settings the scenario and the preparation share;
//! * [`error`]: [`Error`], what the scenario and preparation calls return, and [`FieldError`].
//!
//! Conventions: SI units except sieve sizes, given in millimetres as in the standards; the
//! sieve size of a grain is its volume-equivalent diameter (see [`grading`]).

pub mod compacity;
mod defaults;
pub mod error;
pub mod grading;
pub mod grains;
pub mod indicators;
pub mod preparation;
pub mod scenario;
pub mod scene;
pub mod sections;
pub mod tamping;
pub mod track;

pub use compacity::{clipped_volume, compacity, solid_volume, CompacityError};
pub use error::{Error, FieldError};
pub use grading::{GradingCurve, GradingError, GradingTable, SizeClass};
pub use grains::{generate_grains, Amount, GrainError, GrainSpec};
pub use scenario::{is_track_scenario, TrackModel, TrackScenario};
