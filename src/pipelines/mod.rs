//! The papers' loops, generic over the traits: each composes a plant or environment, a model, a
//! planner and an agent.
//!
//! | module | paper | loop |
//! |---|---|---|
//! | [`p0`] | Rastogi et al., difference models | pre-train on the idealized plant; collect true samples, fit a residual model, retrain on plant + residual |
//! | [`dyna`] | (shared) | MBPO-style Dyna: branched rollouts of a learned model from real states, acted by the agent's own batched policy, into the loop's second buffer |
//! | [`adapter`] | (shared) | observation features, reward scale and settable exploration noise in front of any off-policy agent |

pub mod adapter;
pub mod dyna;
pub mod p0;

use tandem_agents::AgentError;
use tandem_envs::EnvError;
use tandem_models::ModelError;

/// Why a pipeline stopped.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The agent failed (bad configuration, non-finite loss, ...).
    #[error("agent: {0}")]
    Agent(#[from] AgentError),
    /// An environment failed.
    #[error("environment: {0}")]
    Env(#[from] EnvError),
    /// A model failed (to fit, or to predict).
    #[error("model: {0}")]
    Model(#[from] ModelError),
    /// A configuration value out of range.
    #[error("configuration: {0}")]
    Config(String),
}

/// Result of the pipelines.
pub type Result<T> = std::result::Result<T, PipelineError>;
