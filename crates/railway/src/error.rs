//! The railway crate's errors: [`FieldError`], a refused parameter of the track model (the
//! field, its value and what is allowed, printed as `field = value: allowed`), and [`Error`],
//! what its scenario and preparation calls return.

use crate::grains::GrainError;
use ballast_engine::ScenarioError;

/// An error of a track scenario or of a bed's preparation; `Display` gives the message the
/// command prints.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// A refused parameter of the track model (the grading and grain parameters named by
    /// their `ballast.` keys).
    #[error(transparent)]
    Field(#[from] FieldError),
    /// Grains that cannot be generated.
    #[error(transparent)]
    Grains(#[from] GrainError),
    /// A setting the engine refused (`[solver]`, `[correction]`, `[ddm]`).
    #[error(transparent)]
    Engine(#[from] ScenarioError),
    /// A scenario file that is not TOML, or a key unknown or of the wrong type (the message
    /// quotes the line).
    #[error("{0}")]
    Toml(String),
}

/// The message, for callers that still carry errors as text.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.to_string()
    }
}

/// A refused parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value}: {allowed}")]
pub struct FieldError {
    /// Path of the field, e.g. `tamping.frequency`.
    pub field: String,
    /// The offending value.
    pub value: String,
    /// What is allowed.
    pub allowed: String,
}

/// A [`FieldError`] for `field` holding `value`.
pub(crate) fn refuse(field: &str, value: impl std::fmt::Debug, allowed: &str) -> FieldError {
    FieldError {
        field: field.into(),
        value: format!("{value:?}"),
        allowed: allowed.into(),
    }
}

/// Checks that `v` is finite and in `[lo, hi]`.
pub(crate) fn check_range(
    field: &str,
    v: f64,
    lo: f64,
    hi: f64,
    unit: &str,
) -> Result<(), FieldError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(refuse(field, v, &format!("between {lo} and {hi} {unit}")))
    }
}
