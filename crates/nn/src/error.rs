//! The one error type of this crate.

/// Everything that can go wrong in `tandem-nn`: bad shapes, bad configuration, non-finite numbers
/// and checkpoint problems. Each variant names *what* was wrong so that the caller can report it.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum NnError {
    /// A buffer or tensor had the wrong length or shape.
    #[error("shape mismatch in {what}: expected {expected}, got {got}")]
    ShapeMismatch {
        /// Which buffer or tensor (for checkpoints: the tensor name).
        what: String,
        /// The expected shape or length, written out.
        expected: String,
        /// The shape or length that was given.
        got: String,
    },
    /// A loss, gradient, parameter or input contained NaN or infinity.
    #[error("non-finite value in {what} (first at flat index {index})")]
    NonFinite {
        /// Which quantity (e.g. "gradient", "mse loss", "input").
        what: String,
        /// Flat index of the first non-finite element (0 for scalars).
        index: usize,
    },
    /// A configuration value was out of range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// A backward pass was requested without a matching training forward pass.
    #[error("backward called without a matching forward_train on this workspace: {0}")]
    NoTape(String),
    /// A checkpoint could not be written, read or decoded.
    #[error("checkpoint error: {0}")]
    Checkpoint(String),
    /// A tensor expected in a checkpoint is absent.
    #[error("checkpoint has no tensor named `{0}`")]
    MissingTensor(String),
    /// An error from candle (used by the candle helpers).
    #[error("candle: {0}")]
    Candle(String),
}

impl From<candle_core::Error> for NnError {
    fn from(e: candle_core::Error) -> Self {
        NnError::Candle(e.to_string())
    }
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, NnError>;

/// `Err(ShapeMismatch)` unless `got == expected`.
pub(crate) fn check_len(what: &str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(NnError::ShapeMismatch {
            what: what.to_string(),
            expected: format!("length {expected}"),
            got: format!("length {got}"),
        })
    }
}

pub use tandem_core::first_non_finite;

/// `Err(NonFinite)` if `x` has a NaN or infinity.
pub fn check_finite(what: &str, x: &[f32]) -> Result<()> {
    match first_non_finite(x) {
        None => Ok(()),
        Some(index) => Err(NnError::NonFinite {
            what: what.to_string(),
            index,
        }),
    }
}

/// `Err(NonFinite)` if the scalar `x` is NaN or infinite.
pub fn check_finite_scalar(what: &str, x: f32) -> Result<f32> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(NnError::NonFinite {
            what: what.to_string(),
            index: 0,
        })
    }
}
