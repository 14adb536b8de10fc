//! An [`Env`] over any [`DynamicsModel`]: a [`Task`] (start state, observation, reward,
//! termination, episode length) plus a model that predicts the next state. With a
//! [`tandem_models::PlantModel`] it is the idealized simulator; with a
//! [`tandem_models::ResidualModel`] it is p0's "idealized plant + difference model" on which the
//! policy is retrained. Rewards always come from the task's reward function, never from the model.

use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::classic::DcMotorPendulumParams;
use tandem_envs::{dc_motor_pendulum_reward, wrap_angle, Env, EnvError, Step};
use tandem_models::{DynamicsModel, ModelInput};

use ndarray::Array2;

/// What an environment adds to dynamics: where episodes start, what the agent observes, the
/// reward, termination and the episode length. Implemented once per task and shared by the true
/// system's environment, the idealized simulator and the model environment, so that all three
/// score and end episodes the same way.
pub trait Task {
    /// Environment id reported by the model environment.
    fn id(&self) -> &str;
    /// Observation space.
    fn observation_space(&self) -> &Space;
    /// Action space, in the units the plant takes.
    fn action_space(&self) -> &Space;
    /// The state an episode starts from.
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64>;
    /// The observation of `state`.
    fn observe(&self, state: &[f64]) -> Vec<f64>;
    /// Maps a state to its canonical representative in place (wrapping angles), so that a
    /// learned model sees states from a bounded range. Default: nothing to do.
    fn canonicalize(&self, _state: &mut [f64]) {}
    /// Reward of the transition `state --action--> next` (`action` already clipped to the
    /// action space).
    fn reward(&self, state: &[f64], action: &[f64], next: &[f64]) -> f64;
    /// Whether `next` is terminal. Default: never.
    fn terminated(&self, _next: &[f64]) -> bool {
        false
    }
    /// Episode length (truncation).
    fn max_episode_steps(&self) -> usize;
}

/// p0's swing-up task on the DC-motor pendulum (Sec. IV-A), the same rules as
/// [`tandem_envs::DcMotorPendulumEnv`]: start at `(π, 0)`, observe `(wrap(φ), φ̇)`, voltage
/// clipped to `±u_max`, reward [`dc_motor_pendulum_reward`] of the new state, 400 steps, never
/// terminates.
#[derive(Debug, Clone)]
pub struct DcMotorPendulumTask {
    observation_space: Space,
    action_space: Space,
}

impl DcMotorPendulumTask {
    /// The task for a pendulum whose voltage bound is `params.u_max`.
    pub fn new(params: &DcMotorPendulumParams) -> Self {
        use std::f64::consts::PI;
        Self {
            observation_space: Space::boxed(vec![-PI, f64::NEG_INFINITY], vec![PI, f64::INFINITY]),
            action_space: Space::symmetric(1, params.u_max),
        }
    }
}

impl Task for DcMotorPendulumTask {
    fn id(&self) -> &str {
        "DcMotorPendulum-model-v0"
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn initial_state(&self, _rng: &mut Rng) -> Vec<f64> {
        vec![std::f64::consts::PI, 0.0]
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        vec![wrap_angle(state[0]), state[1]]
    }
    fn canonicalize(&self, state: &mut [f64]) {
        state[0] = wrap_angle(state[0]);
    }
    fn reward(&self, _state: &[f64], action: &[f64], next: &[f64]) -> f64 {
        dc_motor_pendulum_reward(next, action[0])
    }
    fn max_episode_steps(&self) -> usize {
        tandem_envs::DC_MOTOR_PENDULUM_STEPS
    }
}

/// Clips a continuous action into a box space's bounds (infinite bounds leave it as it is).
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

/// An environment whose transitions come from a [`DynamicsModel`] and whose rewards,
/// observations, starts and episode ends come from a [`Task`]. Episodes truncate after
/// [`Task::max_episode_steps`]. The model's prediction is deterministic here for deterministic
/// models; stochastic models draw from the environment's generator (seeded by `reset`).
#[derive(Debug, Clone)]
pub struct ModelEnv<M, T> {
    model: M,
    task: T,
    state: Vec<f64>,
    rng: Rng,
    elapsed: usize,
    running: bool,
}

impl<M: DynamicsModel, T: Task> ModelEnv<M, T> {
    /// The environment of `task` over `model`; errors when their dimensions disagree.
    pub fn new(model: M, task: T) -> Result<Self, EnvError> {
        let ad = task.action_space().flat_dim();
        let probe = task.initial_state(&mut rng_from_seed(0));
        if model.action_dim() != ad || model.state_dim() != probe.len() {
            return Err(EnvError::Unsupported {
                env: task.id().to_string(),
                reason: format!(
                    "model takes states of {} and actions of {}, the task has {} and {}",
                    model.state_dim(),
                    model.action_dim(),
                    probe.len(),
                    ad
                ),
            });
        }
        Ok(Self {
            model,
            task,
            state: probe,
            rng: rng_from_seed(0),
            elapsed: 0,
            running: false,
        })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The model, mutably (to refit it between training phases).
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    /// The task.
    pub fn task(&self) -> &T {
        &self.task
    }
}

impl<M: DynamicsModel, T: Task> Env for ModelEnv<M, T> {
    fn id(&self) -> &str {
        self.task.id()
    }
    fn observation_space(&self) -> &Space {
        self.task.observation_space()
    }
    fn action_space(&self) -> &Space {
        self.task.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = rng_from_seed(s);
        }
        self.state = self.task.initial_state(&mut self.rng);
        self.task.canonicalize(&mut self.state);
        self.elapsed = 0;
        self.running = true;
        self.task.observe(&self.state)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        let id = self.task.id().to_string();
        if !self.running {
            return Err(EnvError::NeedsReset {
                env: id,
                when: "before reset or after the episode ended",
            });
        }
        self.task
            .action_space()
            .check(action)
            .map_err(|source| EnvError::InvalidAction {
                env: id.clone(),
                source,
            })?;
        let a = clip_to(
            self.task.action_space(),
            action.as_continuous().unwrap_or_default(),
        );
        let s = Array2::from_shape_vec((1, self.state.len()), self.state.clone()).expect("one row");
        let u = Array2::from_shape_vec((1, a.len()), a.clone()).expect("one row");
        let pred = self
            .model
            .predict(&ModelInput::new(s.view(), u.view()), &mut self.rng)
            .map_err(|e| EnvError::Unsupported {
                env: id.clone(),
                reason: format!("model prediction failed: {e}"),
            })?;
        let mut next: Vec<f64> = pred.next_states.row(0).to_vec();
        if let Some(i) = next.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::InvalidState {
                env: id,
                reason: format!("the model predicted a non-finite state component {i}"),
            });
        }
        let reward = self.task.reward(&self.state, &a, &next);
        let terminated = self.task.terminated(&next);
        self.task.canonicalize(&mut next);
        self.state = next;
        self.elapsed += 1;
        let truncated = self.elapsed >= self.task.max_episode_steps();
        self.running = !(terminated || truncated);
        Ok(Step {
            observation: self.task.observe(&self.state),
            reward,
            terminated,
            truncated,
        })
    }
    fn state(&self) -> Vec<f64> {
        self.state.clone()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        tandem_envs::check_state(self.task.id(), state, self.model.state_dim())?;
        self.state = state.to_vec();
        self.task.canonicalize(&mut self.state);
        self.elapsed = 0;
        self.running = true;
        Ok(self.task.observe(&self.state))
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(self.task.max_episode_steps())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_dynamics::classic::DcMotorPendulum;
    use tandem_models::PlantModel;

    /// The model environment over the true plant replays the registered true environment exactly:
    /// same observations, rewards and truncation, including across the ±π wrap.
    #[test]
    fn plant_model_env_matches_the_registered_pendulum() {
        let p = DcMotorPendulumParams::real();
        let mut m = ModelEnv::new(
            PlantModel::new(DcMotorPendulum::new(p)),
            DcMotorPendulumTask::new(&p),
        )
        .unwrap();
        let mut e = tandem_envs::make("DcMotorPendulum-real-v0").unwrap();
        assert_eq!(m.reset(Some(1)), e.reset(Some(1)));
        let mut wrapped = false;
        let mut velocity = 0.0;
        for t in 0..400 {
            // Pumping energy (voltage along the velocity, over-range to test clipping) swings the
            // pendulum to the top and over it, through both wraps.
            let u = if velocity >= 0.0 { 4.5 } else { -4.5 };
            let a = Action::Continuous(vec![u]);
            let (sm, se) = (m.step(&a).unwrap(), e.step(&a).unwrap());
            for k in 0..2 {
                assert!(
                    (sm.observation[k] - se.observation[k]).abs() < 1e-6,
                    "t={t}: {:?} vs {:?}",
                    sm.observation,
                    se.observation
                );
            }
            assert!((sm.reward - se.reward).abs() < 1e-6);
            assert_eq!(sm.truncated, se.truncated, "t={t}");
            wrapped |= sm.observation[0].abs() < 0.5;
            velocity = se.observation[1];
        }
        assert!(wrapped, "the test trajectory should reach the top");
        assert!(matches!(
            m.step(&Action::Continuous(vec![0.0])),
            Err(EnvError::NeedsReset { .. })
        ));
    }
}
