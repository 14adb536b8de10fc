//! The error type of every planner and trajectory optimizer.

use tandem_models::ModelError;

/// What can go wrong when planning: bad settings, inputs of the wrong size, a cost or model that
/// produced NaN or infinity, a numerical failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A configuration value out of its valid range (zero horizon, empty population, ...).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// Arrays or vectors whose lengths do not fit each other or the model.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    Dim {
        /// Which input.
        what: String,
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// A cost (or value) that evaluated to NaN or infinity.
    #[error("non-finite cost {value} in {what} (sample {sample}, time step {step})")]
    NonFiniteCost {
        /// `"running cost"`, `"terminal cost"`, `"terminal value"`, `"model reward"`.
        what: &'static str,
        /// Row of the batch (sample of the population).
        sample: usize,
        /// Time step within the horizon.
        step: usize,
        /// The value.
        value: f64,
    },
    /// A NaN or infinite value somewhere other than a cost (a state, an action, a gain).
    #[error("non-finite value in {0}")]
    NonFinite(String),
    /// The model failed.
    #[error("model error: {0}")]
    Model(#[from] ModelError),
    /// A linear-algebra failure that the algorithm could not recover from (for example no
    /// positive-definite solution even at the largest dual variable).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, PlanError>;

pub(crate) fn check_len(what: &str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(PlanError::Dim {
            what: what.to_string(),
            expected,
            got,
        })
    }
}

pub(crate) fn check_finite(what: &str, v: &[f64]) -> Result<()> {
    if v.iter().all(|z| z.is_finite()) {
        Ok(())
    } else {
        Err(PlanError::NonFinite(what.to_string()))
    }
}
