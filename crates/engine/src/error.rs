//! [`Error`]: every error of the engine's library calls in one type, for a front end that
//! builds a scenario, reads checkpoints and writes outputs with one `?`. Each variant keeps
//! the message of the error it holds.

use crate::output::checkpoint::CheckpointError;
use crate::shapes::ShapeError;

/// A refused scenario or setting: one message naming the field, the value and what is
/// allowed (callers prefix the path of the table they checked it in).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ScenarioError(pub String);

impl From<String> for ScenarioError {
    fn from(message: String) -> Self {
        ScenarioError(message)
    }
}

impl From<&str> for ScenarioError {
    fn from(message: &str) -> Self {
        ScenarioError(message.to_string())
    }
}

/// An error of the engine: a refused scenario or setting, a shape that cannot be built, a
/// checkpoint that cannot be used, or an I/O error.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A refused scenario or setting: the field, the value and what is allowed.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A convex polyhedron that cannot be built.
    #[error(transparent)]
    Shape(#[from] ShapeError),
    /// A checkpoint that cannot be read or does not fit the world.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// Reading or writing a file.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// A result with the engine's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
