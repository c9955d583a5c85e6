//! One error type for refused parameters of the track model: the field, its value and what is
//! allowed, printed as `field = value: allowed`.

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
pub fn refuse(field: &str, value: impl std::fmt::Debug, allowed: &str) -> FieldError {
    FieldError {
        field: field.into(),
        value: format!("{value:?}"),
        allowed: allowed.into(),
    }
}

/// Checks that `v` is finite and in `[lo, hi]`.
pub fn check_range(field: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Result<(), FieldError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(refuse(field, v, &format!("between {lo} and {hi} {unit}")))
    }
}
