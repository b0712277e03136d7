//! The errors a checked value gives, naming its key.

use crate::MatchError;

pub(super) fn bad(key: impl Into<String>, message: impl Into<String>) -> MatchError {
    MatchError::Config { key: key.into(), message: message.into() }
}

pub(super) fn positive(key: &str, v: f64) -> Result<f64, MatchError> {
    if v > 0.0 && v.is_finite() { Ok(v) } else { Err(bad(key, format!("must be positive and finite, got {v}"))) }
}
