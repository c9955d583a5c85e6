//! # ballast-engine
//!
//! A Non-Smooth Contact Dynamics (NSCD) engine for rigid convex polyhedra, after Moreau and Jean.
//! Data flows one way through a time step, and the modules follow that flow:
//!
//! 1. [`bodies`]: rigid bodies (structure of arrays), mass properties, kinematic drivers;
//! 2. [`shapes`]: convex polyhedra and half-spaces, their hull and mass properties;
//! 3. `detection`: broad phase (uniform grid) and narrow phase (contact manifolds ≤ 4 points);
//! 4. [`contacts`]: contact points with local frames `(n, t, s)`, persistence for warm start;
//! 5. [`laws`]: the Signorini-Coulomb law, friction table and the exact local 3×3 solver;
//! 6. [`solver`]: Delassus blocks and Non-Linear Gauss-Seidel (NLGS);
//! 7. [`world`]: the θ-method time step tying it all together, with per-phase timers;
//! 8. [`scenario`]: TOML scenario files, validated field by field;
//! 9. [`health`]: the check after every step that stops a diverging run, naming the bodies.
//!
//! Conventions: SI units; a contact joins body 1 and body 2, its normal `n` points from body 1
//! toward body 2; the gap `g` is positive when the surfaces are apart; the relative velocity is
//! `u = v₂(x) − v₁(x)` so `uₙ > 0` separates; the contact impulse `r` acts `+r` on body 2 and `−r`
//! on body 1.

pub mod bodies;
pub mod contacts;
// Internals exposed for the crate's tests and benches; not part of the supported API.
#[doc(hidden)]
pub mod detection;
pub mod digest;
pub mod error;
pub mod health;
pub mod laws;
pub mod math;
pub mod output;
pub mod scenario;
pub mod shapes;
mod slices;
pub mod solver;
pub mod timing;
pub mod world;

pub use error::{Error, Result, ScenarioError};
/// The 64-bit FNV-1a hash of checkpoints, also the cache key of scenes built on the engine.
pub use output::checkpoint::fnv1a64;
/// A uniformly distributed random rotation, as random grains are placed.
pub use scenario::generate::random_rotation;
/// The default of `[ddm] min_parallel_contacts` (on 2 threads).
pub use solver::ddm::MIN_PARALLEL_CONTACTS;

/// The types most programs on the engine use: `use ballast_engine::prelude::*;`.
pub mod prelude {
    pub use crate::bodies::{BodyKind, BodySet, Driver, Term};
    pub use crate::math::{DMat3, DQuat, DVec3};
    pub use crate::scenario::Scenario;
    pub use crate::shapes::{ConvexPolyhedron, PolyhedronBuild, Shape, ShapeError};
    pub use crate::solver::{
        ContactProblem, ConvergenceNorm, CorrectionSettings, DdmSettings, SolverSettings,
    };
    pub use crate::world::{StepReport, StepSettings, World};
    pub use crate::{Error, ScenarioError};
}
