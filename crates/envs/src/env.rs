//! The [`Env`] trait.

use tandem_core::{Action, Space, SpaceError};

/// Errors an environment reports instead of panicking.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvError {
    /// The action does not belong to the action space.
    #[error("invalid action for {env}: {source}")]
    InvalidAction {
        /// The environment's id.
        env: String,
        /// What is wrong with the action.
        #[source]
        source: SpaceError,
    },
    /// `step` was called before `reset`, or after the episode ended.
    #[error("{env}: step called {when}; call reset first")]
    NeedsReset {
        /// The environment's id.
        env: String,
        /// `"before reset"` or `"after the episode ended"`.
        when: &'static str,
    },
    /// A state given to [`Env::set_state`] has the wrong length or is not finite.
    #[error("{env}: invalid state: {reason}")]
    InvalidState {
        /// The environment's id.
        env: String,
        /// What is wrong with it.
        reason: String,
    },
    /// No environment of that name.
    #[error("unknown environment `{0}`")]
    Unknown(String),
}

/// What [`Env::step`] returns: gymnasium's `(observation, reward, terminated, truncated)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Observation after the action.
    pub observation: Vec<f64>,
    /// Reward for the transition.
    pub reward: f64,
    /// The task reached a terminal state (a failure or a goal): do not bootstrap past it.
    pub terminated: bool,
    /// The episode was cut short (time limit): bootstrap past it.
    pub truncated: bool,
}

impl Step {
    /// `terminated || truncated`: the episode is over and the environment needs a reset.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// An environment with gymnasium semantics.
///
/// `reset(Some(seed))` reseeds the environment's generator and starts an episode; `reset(None)`
/// continues the current generator. The internal state is exposed ([`Env::state`],
/// [`Env::set_state`]) so that trajectories can be replayed from a given state and compared with
/// other implementations.
pub trait Env {
    /// The registered id, e.g. `"CartPole-v1"`.
    fn id(&self) -> &str;

    /// Space of observations.
    fn observation_space(&self) -> &Space;

    /// Space of actions.
    fn action_space(&self) -> &Space;

    /// Starts an episode and returns the first observation.
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64>;

    /// Applies `action` and advances one step.
    fn step(&mut self, action: &Action) -> Result<Step, EnvError>;

    /// The full internal state (may hold more than the observation).
    fn state(&self) -> Vec<f64>;

    /// Starts an episode from the internal state `state` (as returned by [`Env::state`]) and
    /// returns its observation.
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError>;
}
