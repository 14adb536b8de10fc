//! Learning curves.

use serde::{Deserialize, Serialize};

/// One point of a learning curve: the deterministic policy's return on the true (real) system
/// after `true_samples` training samples from it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// True-system training samples used so far (evaluation episodes excluded).
    pub true_samples: u64,
    /// Mean undiscounted return of the deterministic policy on the true system.
    pub eval_return: f64,
}
