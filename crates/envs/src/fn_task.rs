//! [`FnTask`]: a task made of closures, the short path to a task of your own.
//!
//! A task over a plant of your own in a few lines: the states are observed as they are, the
//! action is clipped into its box, and what remains to say is where episodes start, the reward,
//! and optionally the termination and the episode length.
//!
//! ```
//! use nalgebra::DVector;
//! use tandem_core::{Action, Space};
//! use tandem_dynamics::Plant;
//! use tandem_envs::{Env, FnTask, PlantEnv};
//!
//! /// A cart on a frictionless rail pushed by a force: `x = (p, v)`, 0.05 s Euler steps.
//! struct Cart;
//! impl Plant for Cart {
//!     fn state_dim(&self) -> usize { 2 }
//!     fn action_dim(&self) -> usize { 1 }
//!     fn dt(&self) -> f64 { 0.05 }
//!     fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
//!         DVector::from_vec(vec![x[0] + 0.05 * x[1], x[1] + 0.05 * u[0]])
//!     }
//! }
//!
//! // Bring the cart to rest at the origin; the episode ends if it leaves the rail.
//! let task = FnTask::new(
//!     "CartToOrigin-v0",
//!     Space::symmetric(2, 5.0),
//!     Space::symmetric(1, 1.0),
//!     |rng| vec![rand::Rng::random_range(rng, -1.0..1.0), 0.0],
//!     |_x, u, next| -(next[0] * next[0] + 0.1 * next[1] * next[1] + 0.01 * u[0] * u[0]),
//! )
//! .with_termination(|next| next[0].abs() > 5.0)
//! .with_max_episode_steps(100);
//!
//! let mut env = PlantEnv::from_parts(Cart, task).unwrap();
//! env.reset(Some(0));
//! let step = env.step(&Action::Continuous(vec![3.0])).unwrap(); // clipped to 1
//! assert!(step.reward < 0.0 && !step.terminated);
//! assert_eq!(env.max_episode_steps(), Some(100));
//! ```

use std::sync::Arc;

use tandem_core::{Rng, Space};

use crate::{ObservedTask, Task};

type StartFn = Arc<dyn Fn(&mut Rng) -> Vec<f64> + Send + Sync>;
type RewardFn = Arc<dyn Fn(&[f64], &[f64], &[f64]) -> f64 + Send + Sync>;
type EndFn = Arc<dyn Fn(&[f64]) -> bool + Send + Sync>;

/// A [`Task`] from closures over states observed as they are (see the module docs). Cloning it
/// shares the closures.
#[derive(Clone)]
pub struct FnTask {
    id: String,
    state_space: Space,
    action_space: Space,
    initial_state: StartFn,
    reward: RewardFn,
    terminated: Option<EndFn>,
    max_episode_steps: Option<usize>,
}

impl std::fmt::Debug for FnTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FnTask")
            .field("id", &self.id)
            .field("state_space", &self.state_space)
            .field("action_space", &self.action_space)
            .field("terminates", &self.terminated.is_some())
            .field("max_episode_steps", &self.max_episode_steps)
            .finish()
    }
}

impl FnTask {
    /// The task `id` over states in `state_space` (also its observation space), with actions
    /// from `action_space` (a box's actions are clipped into it), episodes starting at
    /// `initial_state(rng)` and the reward `reward(x, u, x')` of each step. It never terminates
    /// and never truncates unless told ([`FnTask::with_termination`],
    /// [`FnTask::with_max_episode_steps`]).
    pub fn new(
        id: impl Into<String>,
        state_space: Space,
        action_space: Space,
        initial_state: impl Fn(&mut Rng) -> Vec<f64> + Send + Sync + 'static,
        reward: impl Fn(&[f64], &[f64], &[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        Self {
            id: id.into(),
            state_space,
            action_space,
            initial_state: Arc::new(initial_state),
            reward: Arc::new(reward),
            terminated: None,
            max_episode_steps: None,
        }
    }

    /// Ends an episode at the first state where `terminated` holds.
    pub fn with_termination(
        mut self,
        terminated: impl Fn(&[f64]) -> bool + Send + Sync + 'static,
    ) -> Self {
        self.terminated = Some(Arc::new(terminated));
        self
    }

    /// Truncates episodes after `steps` steps.
    pub fn with_max_episode_steps(mut self, steps: usize) -> Self {
        self.max_episode_steps = Some(steps);
        self
    }
}

impl Task for FnTask {
    fn id(&self) -> &str {
        &self.id
    }
    fn observation_space(&self) -> &Space {
        &self.state_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        (self.initial_state)(rng)
    }
    fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        (self.reward)(state, u, next)
    }
    fn terminated(&self, next: &[f64]) -> bool {
        self.terminated.as_ref().is_some_and(|t| t(next))
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.max_episode_steps
    }
}

/// The observations are the states, so the reward and termination read them alike.
impl ObservedTask for FnTask {
    fn observation_reward(&self, obs: &[f64], u: &[f64], next_obs: &[f64]) -> f64 {
        self.reward(obs, u, next_obs)
    }
    fn observation_terminated(&self, next_obs: &[f64]) -> bool {
        self.terminated(next_obs)
    }
}
