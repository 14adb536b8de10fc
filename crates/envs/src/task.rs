//! [`Task`]: what an environment adds to dynamics, and [`PlantEnv`]: an environment over any
//! [`Plant`] plus a task.
//!
//! A task says where episodes start, what the agent observes, how an action becomes the plant's
//! input, the reward, termination and the episode length. It is written once and shared by the
//! true system's environment ([`PlantEnv`]), an idealized simulator (the same `PlantEnv` over
//! other parameters) and a learned model's environment (`tandem_models::ModelEnv`), so that all
//! of them score and end episodes alike. The classic environments are `PlantEnv`s:
//! [`crate::CartPoleEnv`], [`crate::PendulumEnv`]; so are the papers' (`tandem-robots`).
//!
//! ```
//! use tandem_envs::{Action, Env, PendulumTask, PlantEnv, Task};
//! use tandem_dynamics::classic::{GymPendulum, GymPendulumParams};
//!
//! // Gymnasium's swing-up task over a heavier pendulum than the registered one.
//! let params = GymPendulumParams { m: 2.0, ..GymPendulumParams::default() };
//! let task = PendulumTask::new(&params);
//! let mut env = PlantEnv::from_parts(GymPendulum::new(params), task).unwrap();
//! let obs = env.reset(Some(0));
//! assert_eq!(obs.len(), 3);
//! let step = env.step(&Action::Continuous(vec![2.0])).unwrap();
//! assert!(step.reward < 0.0 && !step.terminated);
//! ```

use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::Plant;

use crate::env::{check_action, check_state, Phase};
use crate::{Env, EnvError, Step};

/// Start, observation, plant input, reward, termination and episode length of an environment,
/// over the plant's state.
///
/// States are the plant's (`tandem_dynamics::Plant::step`'s `x`); observations are what the agent
/// sees; controls are the plant's inputs (`u`). Methods receive inputs of the right lengths
/// (callers check at their boundary).
pub trait Task {
    /// The environment id this task is registered under (or reported as).
    fn id(&self) -> &str;

    /// Space of observations.
    fn observation_space(&self) -> &Space;

    /// Space of actions the agent picks from.
    fn action_space(&self) -> &Space;

    /// Length of the state. Default: the observation's, for a task that observes its state as it
    /// is (the default [`Task::observe`]).
    fn state_dim(&self) -> usize {
        self.observation_space().flat_dim()
    }

    /// The plant input for `action` (an element of [`Task::action_space`]): clipped into the
    /// plant's limits, or a discrete choice turned into a force. Default: a continuous action
    /// clipped into the action space's box ([`clip_to`]), a discrete one as its index.
    fn control(&self, action: &Action) -> Vec<f64> {
        match action {
            Action::Continuous(a) => clip_to(self.action_space(), a),
            Action::Discrete(i) => vec![*i as f64],
        }
    }

    /// The state an episode starts from, drawn from `rng` where the start is random.
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64>;

    /// The observation of `state`. Default: the state as it is.
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        state.to_vec()
    }

    /// Maps a state to its canonical representative in place (wrapping angles), so that a
    /// learned model sees states from a bounded range. Default: nothing to do.
    fn canonicalize(&self, _state: &mut [f64]) {}

    /// Reward of the transition `state --u--> next`, `u` being [`Task::control`]'s output.
    fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64;

    /// Whether `next` is terminal (a failure or a goal). Default: never.
    fn terminated(&self, _next: &[f64]) -> bool {
        false
    }

    /// The episode length after which the environment truncates. Default: `None`, never.
    fn max_episode_steps(&self) -> Option<usize> {
        None
    }
}

/// A [`Task`] whose reward and termination can also be read off observations, so that a model
/// learned on observations (PETS's) can be planned through with the task's own score
/// (`tandem_planners::Objective::from_task_observations`); mbrl-lib's `reward_fns` and
/// `termination_fns` play this part.
///
/// Where an observation leaves out what the reward reads (a locomotion task's x position), the
/// implementation says how it approximates it.
pub trait ObservedTask: Task {
    /// Reward of the transition `obs --u--> next_obs`, `u` being [`Task::control`]'s output.
    fn observation_reward(&self, obs: &[f64], u: &[f64], next_obs: &[f64]) -> f64;

    /// Whether `next_obs` is terminal. Default: never.
    fn observation_terminated(&self, _next_obs: &[f64]) -> bool {
        false
    }
}

/// `Task` through a pointer: a boxed task and a borrowed one are tasks.
macro_rules! forward_task {
    ($($ptr:ty),*) => {$(
        impl<T: Task + ?Sized> Task for $ptr {
            fn id(&self) -> &str {
                (**self).id()
            }
            fn observation_space(&self) -> &Space {
                (**self).observation_space()
            }
            fn action_space(&self) -> &Space {
                (**self).action_space()
            }
            fn state_dim(&self) -> usize {
                (**self).state_dim()
            }
            fn control(&self, action: &Action) -> Vec<f64> {
                (**self).control(action)
            }
            fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
                (**self).initial_state(rng)
            }
            fn observe(&self, state: &[f64]) -> Vec<f64> {
                (**self).observe(state)
            }
            fn canonicalize(&self, state: &mut [f64]) {
                (**self).canonicalize(state)
            }
            fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
                (**self).reward(state, u, next)
            }
            fn terminated(&self, next: &[f64]) -> bool {
                (**self).terminated(next)
            }
            fn max_episode_steps(&self) -> Option<usize> {
                (**self).max_episode_steps()
            }
        }
    )*};
}

forward_task!(Box<T>, &T);

macro_rules! forward_observed_task {
    ($($ptr:ty),*) => {$(
        impl<T: ObservedTask + ?Sized> ObservedTask for $ptr {
            fn observation_reward(&self, obs: &[f64], u: &[f64], next_obs: &[f64]) -> f64 {
                (**self).observation_reward(obs, u, next_obs)
            }
            fn observation_terminated(&self, next_obs: &[f64]) -> bool {
                (**self).observation_terminated(next_obs)
            }
        }
    )*};
}

forward_observed_task!(Box<T>, &T);

/// Clips a continuous action into a box space's bounds (infinite bounds leave it as it is); the
/// usual [`Task::control`] of a continuous task.
pub fn clip_to(space: &Space, a: &[f64]) -> Vec<f64> {
    match space {
        Space::Box { low, high, .. } => a
            .iter()
            .zip(low.iter().zip(high))
            .map(|(v, (l, h))| v.clamp(*l, *h))
            .collect(),
        Space::Discrete { .. } => a.to_vec(),
    }
}

/// What an environment over a [`Task`] keeps whatever advances its state (a [`Plant`] in
/// [`PlantEnv`], a learned model in `tandem_models::ModelEnv`): the task, the generator its starts
/// are drawn from with gymnasium's seeded reset, and the action check.
#[derive(Debug, Clone)]
pub struct TaskEpisodes<T> {
    task: T,
    rng: Rng,
}

impl<T: Task> TaskEpisodes<T> {
    /// Episodes of `task`, drawn from a generator seeded with 0 until the first seeded reset.
    pub fn new(task: T) -> Self {
        Self {
            task,
            rng: rng_from_seed(0),
        }
    }

    /// The task.
    pub fn task(&self) -> &T {
        &self.task
    }

    /// The generator starts are drawn from (a stochastic model draws from it too).
    pub fn rng_mut(&mut self) -> &mut Rng {
        &mut self.rng
    }

    /// The state a new episode starts from: `Some(seed)` reseeds the generator first, `None`
    /// continues it ([`crate::Env::reset`]).
    pub fn initial_state(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = rng_from_seed(s);
        }
        self.task.initial_state(&mut self.rng)
    }

    /// The plant input of `action` ([`Task::control`]), or an error naming the environment when
    /// the action is not in the task's action space.
    pub fn control(&self, action: &Action) -> Result<Vec<f64>, EnvError> {
        check_action(self.task.id(), self.task.action_space(), action)?;
        Ok(self.task.control(action))
    }

    /// Checks a state's size and finiteness ([`crate::check_state`]).
    pub fn check_state(&self, state: &[f64]) -> Result<(), EnvError> {
        check_state(self.task.id(), state, self.task.state_dim())
    }
}

/// The length of the plant input [`Task::control`] gives.
pub fn control_dim<T: Task + ?Sized>(task: &T) -> usize {
    let probe = match task.action_space() {
        Space::Discrete { .. } => Action::Discrete(0),
        Space::Box { low, .. } => Action::Continuous(vec![0.0; low.len()]),
    };
    task.control(&probe).len()
}

/// An environment stepping a [`Plant`] under a [`Task`], with gymnasium's semantics. It
/// truncates episodes at [`Task::max_episode_steps`] as gymnasium's `TimeLimit` does: the step
/// that reaches the limit has `truncated = true`, and stepping again needs a reset.
///
/// `reset(Some(seed))` reseeds the environment's generator, which draws the initial state;
/// `reset(None)` continues it.
#[derive(Debug, Clone)]
pub struct PlantEnv<P, T> {
    plant: P,
    episodes: TaskEpisodes<T>,
    state: Vec<f64>,
    next: Vec<f64>,
    phase: Phase,
    elapsed: usize,
}

impl<P: Plant, T: Task> PlantEnv<P, T> {
    /// The environment of `task` over `plant`; an error when their state or action dimensions
    /// disagree.
    pub fn from_parts(plant: P, task: T) -> Result<Self, EnvError> {
        let m = control_dim(&task);
        if plant.state_dim() != task.state_dim() || plant.action_dim() != m {
            return Err(EnvError::Unsupported {
                env: task.id().to_string(),
                reason: format!(
                    "the plant takes states of {} and inputs of {}, the task gives {} and {}",
                    plant.state_dim(),
                    plant.action_dim(),
                    task.state_dim(),
                    m
                ),
            });
        }
        let n = task.state_dim();
        Ok(Self {
            plant,
            episodes: TaskEpisodes::new(task),
            state: vec![0.0; n],
            next: vec![0.0; n],
            phase: Phase::NotReset,
            elapsed: 0,
        })
    }

    /// The plant it steps.
    pub fn plant(&self) -> &P {
        &self.plant
    }

    /// The task.
    pub fn task(&self) -> &T {
        self.episodes.task()
    }
}

impl<P: Plant, T: Task> Env for PlantEnv<P, T> {
    fn id(&self) -> &str {
        self.task().id()
    }

    fn observation_space(&self) -> &Space {
        self.task().observation_space()
    }

    fn action_space(&self) -> &Space {
        self.task().action_space()
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.state = self.episodes.initial_state(seed);
        self.phase = Phase::Running;
        self.elapsed = 0;
        self.task().observe(&self.state)
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        self.phase.check(self.task().id())?;
        let u = self.episodes.control(action)?;
        if self.state.len() != self.next.len() {
            // Only a task's initial state can be of the wrong length: set_state checks its own.
            return Err(EnvError::InvalidState {
                env: self.task().id().to_string(),
                reason: format!(
                    "the task's initial state has {} components, its state_dim is {}",
                    self.state.len(),
                    self.next.len()
                ),
            });
        }
        let task = self.episodes.task();
        self.plant.step_into(&self.state, &u, &mut self.next);
        let reward = task.reward(&self.state, &u, &self.next);
        let terminated = task.terminated(&self.next);
        std::mem::swap(&mut self.state, &mut self.next);
        self.elapsed += 1;
        let truncated = task.max_episode_steps().is_some_and(|m| self.elapsed >= m);
        if terminated || truncated {
            self.phase = Phase::Ended;
        }
        Ok(Step {
            observation: task.observe(&self.state),
            reward,
            terminated,
            truncated,
        })
    }

    fn state(&self) -> Vec<f64> {
        self.state.clone()
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.episodes.check_state(state)?;
        self.state.copy_from_slice(state);
        self.phase = Phase::Running;
        self.elapsed = 0;
        Ok(self.task().observe(&self.state))
    }

    fn max_episode_steps(&self) -> Option<usize> {
        self.task().max_episode_steps()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CartPoleTask, PendulumTask};
    use tandem_dynamics::classic::{CartPole, GymPendulum, GymPendulumParams};

    #[test]
    fn a_plant_and_task_of_different_sizes_are_refused() {
        let err = PlantEnv::from_parts(GymPendulum::default(), CartPoleTask::default())
            .err()
            .unwrap();
        assert!(err.to_string().contains("states of 2"), "{err}");
        let task = PendulumTask::new(&GymPendulumParams::default());
        assert!(PlantEnv::from_parts(CartPole::default(), task).is_err());
    }

    #[test]
    fn a_task_env_truncates_at_its_tasks_limit_and_then_needs_a_reset() {
        let mut env = crate::PendulumEnv::new();
        assert_eq!(env.max_episode_steps(), Some(200));
        for round in 0..2 {
            env.reset(Some(round));
            for t in 1..=200 {
                let st = env.step(&Action::Continuous(vec![0.0])).unwrap();
                assert_eq!(st.truncated, t == 200, "step {t}");
            }
            let err = env.step(&Action::Continuous(vec![0.0])).unwrap_err();
            assert!(matches!(err, EnvError::NeedsReset { .. }), "{err}");
        }
        // Setting the state starts a new episode, with a new count.
        env.set_state(&[0.1, 0.0]).unwrap();
        for _ in 0..199 {
            assert!(!env.step(&Action::Continuous(vec![0.0])).unwrap().truncated);
        }
    }

    #[test]
    fn a_task_env_steps_the_plant_and_scores_with_the_task() {
        let plant = GymPendulum::default();
        let task = PendulumTask::new(plant.params());
        let mut env = PlantEnv::from_parts(plant, task.clone()).unwrap();
        env.set_state(&[0.5, -0.25]).unwrap();
        // 7 N m is clipped to the 2 N m bound before it reaches the plant and the reward.
        let st = env.step(&Action::Continuous(vec![7.0])).unwrap();
        assert_eq!(env.state(), plant.step_array(&[0.5, -0.25], 2.0).to_vec());
        assert_eq!(st.reward, -(0.25 + 0.1 * 0.0625 + 0.001 * 4.0));
        assert_eq!(st.observation, task.observe(&env.state()));
        let mut s = vec![7.0, 0.0];
        task.canonicalize(&mut s);
        assert!((s[0] - (7.0 - 2.0 * std::f64::consts::PI)).abs() < 1e-15);
    }
}
