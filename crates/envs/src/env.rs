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
    /// The simulation behind the environment failed during a step (e.g. MuJoCo found a NaN or a
    /// huge acceleration and would reset itself); the environment needs a reset.
    #[error("{env}: {reason}")]
    Simulation {
        /// The environment's id.
        env: String,
        /// What failed, naming the quantity and when.
        reason: String,
    },
    /// No environment of that name.
    #[error("unknown environment `{0}`")]
    Unknown(String),
    /// A wrapper cannot wrap this environment (e.g. rescaling a discrete or unbounded action
    /// space).
    #[error("{env}: {reason}")]
    Unsupported {
        /// The environment's id.
        env: String,
        /// Why the wrapper does not apply.
        reason: String,
    },
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
///
/// ```
/// use tandem_envs::{make, Action, Env};
///
/// let mut env = make("CartPole-v1").unwrap();
/// let first = env.reset(Some(42));
/// assert_eq!(first.len(), 4);
/// let mut ret = 0.0;
/// loop {
///     let step = env.step(&Action::Discrete(1)).unwrap(); // always push right
///     ret += step.reward;
///     if step.done() {
///         assert!(step.terminated); // the pole falls long before the 500-step limit
///         break;
///     }
/// }
/// assert!(ret >= 1.0 && ret < 500.0);
/// // Replaying from a state: the same action from the same state gives the same step.
/// env.set_state(&[0.0, 0.1, 0.02, -0.1]).unwrap();
/// let a = env.step(&Action::Discrete(0)).unwrap();
/// env.set_state(&[0.0, 0.1, 0.02, -0.1]).unwrap();
/// assert_eq!(a, env.step(&Action::Discrete(0)).unwrap());
/// ```
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

    /// The episode length after which the environment truncates, if it has one (a
    /// [`crate::PlantEnv`]'s task's, or a [`crate::TimeLimit`]'s). Default: `None`, never.
    fn max_episode_steps(&self) -> Option<usize> {
        None
    }
}

/// A boxed environment is an environment, so wrappers compose over `Box<dyn Env>`.
impl<E: Env + ?Sized> Env for Box<E> {
    fn id(&self) -> &str {
        (**self).id()
    }
    fn observation_space(&self) -> &Space {
        (**self).observation_space()
    }
    fn action_space(&self) -> &Space {
        (**self).action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        (**self).reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        (**self).step(action)
    }
    fn state(&self) -> Vec<f64> {
        (**self).state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        (**self).set_state(state)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        (**self).max_episode_steps()
    }
}

/// Checks a state given to [`Env::set_state`]: length `dim`, all components finite.
pub fn check_state(env: &str, state: &[f64], dim: usize) -> Result<(), EnvError> {
    if state.len() != dim {
        return Err(EnvError::InvalidState {
            env: env.to_string(),
            reason: format!("expected {dim} components, got {}", state.len()),
        });
    }
    if let Some((i, v)) = state.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(EnvError::InvalidState {
            env: env.to_string(),
            reason: format!("component {i} is not finite ({v})"),
        });
    }
    Ok(())
}

/// Rounds every component to `f32` and back: gymnasium's observations are `float32` arrays.
pub fn round_to_f32(v: &[f64]) -> Vec<f64> {
    v.iter().map(|&x| x as f32 as f64).collect()
}

/// Where a base environment is in its episode; shared bookkeeping of the environments here and
/// of those written over this crate (`tandem-robots`' pixel maze).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// `reset` has not been called yet.
    NotReset,
    /// An episode is running.
    Running,
    /// The episode terminated.
    Ended,
}

impl Phase {
    /// `Ok` if `step` may be called.
    pub fn check(self, env: &str) -> Result<(), EnvError> {
        match self {
            Phase::Running => Ok(()),
            Phase::NotReset => Err(EnvError::NeedsReset {
                env: env.to_string(),
                when: "before reset",
            }),
            Phase::Ended => Err(EnvError::NeedsReset {
                env: env.to_string(),
                when: "after the episode ended",
            }),
        }
    }
}

/// Checks `action` against `space`, naming the environment in the error.
pub fn check_action(env: &str, space: &Space, action: &Action) -> Result<(), EnvError> {
    space
        .check(action)
        .map_err(|source| EnvError::InvalidAction {
            env: env.to_string(),
            source,
        })
}
