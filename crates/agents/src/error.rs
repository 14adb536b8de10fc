//! The error type of the agents crate.

use tandem_core::SpaceError;

/// Everything that can go wrong when building, running, updating or restoring an agent.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// The agent cannot act in this kind of action space (e.g. DQN on a box, SAC on a discrete).
    #[error("{agent} needs a {expected} action space, got {got}")]
    WrongActionSpace {
        /// The agent's name.
        agent: &'static str,
        /// What it needs, e.g. `"continuous (Box)"`.
        expected: &'static str,
        /// The space that was given, as [`tandem_core::Space::describe`] writes it.
        got: String,
    },
    /// The observation space is not a flat box of finite dimension.
    #[error("{agent}: unsupported observation space {got}: {reason}")]
    WrongObservationSpace {
        /// The agent's name.
        agent: &'static str,
        /// The space that was given.
        got: String,
        /// Why it is not supported.
        reason: &'static str,
    },
    /// A configuration value outside its valid range.
    #[error("config: `{field}` = {value} is out of range: {reason}")]
    Config {
        /// The offending field.
        field: &'static str,
        /// Its value, formatted.
        value: String,
        /// The valid range.
        reason: &'static str,
    },
    /// A configuration file that does not parse (unknown key, wrong type).
    #[error("{0}")]
    ConfigParse(String),
    /// An input of the wrong length (observation, action, batch column).
    #[error("{what}: expected length {expected}, got {got}")]
    Dim {
        /// What was checked.
        what: &'static str,
        /// The expected length.
        expected: usize,
        /// The length that was given.
        got: usize,
    },
    /// A NaN or infinite number where a finite one is required (an observation, a loss).
    #[error("{what} is not finite ({value})")]
    NonFinite {
        /// What was checked.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// An empty buffer, batch or episode list.
    #[error("{0} is empty")]
    Empty(&'static str),
    /// A checkpoint that cannot be read, or that belongs to another algorithm or architecture.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// An environment error during training or evaluation.
    #[error("environment: {0}")]
    Env(String),
    /// An action that does not belong to the action space.
    #[error(transparent)]
    Space(#[from] SpaceError),
    /// An error from the neural-network layer.
    #[error(transparent)]
    Nn(#[from] tandem_nn::NnError),
    /// The configuration's estimated memory is above the limit (see `tandem_nn::budget`).
    #[error(transparent)]
    Memory(#[from] tandem_nn::budget::MemoryError),
    /// Reading or writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = AgentError> = std::result::Result<T, E>;

/// Returns a [`AgentError::Config`] unless `ok`.
pub(crate) fn ensure(
    ok: bool,
    field: &'static str,
    value: impl std::fmt::Display,
    reason: &'static str,
) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(AgentError::Config {
            field,
            value: value.to_string(),
            reason,
        })
    }
}
