//! `Pendulum-v1`, exact to gymnasium 1.x: [`PendulumTask`] over the [`GymPendulum`] plant.

use rand::Rng as _;
use std::f64::consts::PI;
use tandem_core::seeding::Rng;
use tandem_core::{Action, Space};
use tandem_dynamics::classic::{GymPendulum, GymPendulumParams};

use crate::task::clip_to;
use crate::{ObservedTask, PlantEnv, Task};

/// Gymnasium's `angle_normalize`: `((x + π) mod 2π) − π` with numpy's floor modulo, in
/// `[-π, π)`.
pub fn angle_normalize(x: f64) -> f64 {
    let r = (x + PI).rem_euclid(2.0 * PI) - PI;
    // rem_euclid can round up to exactly 2π for tiny negative arguments.
    if r >= PI {
        r - 2.0 * PI
    } else {
        r
    }
}

/// Gymnasium's `Pendulum-v1` reward: `−(angle_normalize(θ)² + 0.1 θ̇² + 0.001 u²)` of the state
/// BEFORE the step, with `u` the clipped torque.
pub fn pendulum_reward(state: &[f64; 2], u: f64) -> f64 {
    let [th, thdot] = *state;
    -(angle_normalize(th).powi(2) + 0.1 * thdot.powi(2) + 0.001 * u.powi(2))
}

/// Gymnasium's `Pendulum-v1` task over the [`GymPendulum`] plant (g = 10):
///
/// - state `(θ, θ̇)` in `f64` (θ not wrapped);
/// - observation `f32`-rounded `(cos θ, sin θ, θ̇)`;
/// - action `Box(1)` in `[-2, 2]`, clipped (not rejected) when outside;
/// - reward [`pendulum_reward`] of the state before the step; never terminates;
/// - start: `(θ, θ̇)` uniform in `[-π, π) × [-1, 1)` from the environment's generator;
/// - 200 steps.
#[derive(Debug, Clone)]
pub struct PendulumTask {
    observation_space: Space,
    action_space: Space,
}

impl PendulumTask {
    /// The task for a pendulum with `params`' speed and torque bounds.
    pub fn new(params: &GymPendulumParams) -> Self {
        Self {
            observation_space: Space::boxed(
                vec![-1.0, -1.0, -params.max_speed],
                vec![1.0, 1.0, params.max_speed],
            ),
            action_space: Space::symmetric(1, params.max_torque),
        }
    }
}

impl Task for PendulumTask {
    fn id(&self) -> &str {
        PendulumEnv::ID
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        2
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        clip_to(&self.action_space, action.as_continuous().unwrap_or(&[0.0]))
    }
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        vec![rng.random_range(-PI..PI), rng.random_range(-1.0..1.0)]
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        let (th, thdot) = (state[0], state[1]);
        [th.cos(), th.sin(), thdot]
            .iter()
            .map(|&v| v as f32 as f64)
            .collect()
    }
    fn canonicalize(&self, state: &mut [f64]) {
        state[0] = angle_normalize(state[0]);
    }
    fn reward(&self, state: &[f64], u: &[f64], _next: &[f64]) -> f64 {
        pendulum_reward(&[state[0], state[1]], u[0])
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(200)
    }
}

/// The reward read off `(cos θ, sin θ, θ̇)`: `θ = atan2(sin θ, cos θ)`, which is already
/// normalized; it equals [`Task::reward`] up to the observation's `f32` rounding.
impl ObservedTask for PendulumTask {
    fn observation_reward(&self, obs: &[f64], u: &[f64], _next_obs: &[f64]) -> f64 {
        pendulum_reward(&[obs[1].atan2(obs[0]), obs[2]], u[0])
    }
}

/// Gymnasium's `Pendulum-v1`, truncated at 200 steps by its task: a [`PlantEnv`] of
/// [`PendulumTask`] over [`GymPendulum`].
pub type PendulumEnv = PlantEnv<GymPendulum, PendulumTask>;

impl Default for PendulumEnv {
    fn default() -> Self {
        Self::new()
    }
}

impl PendulumEnv {
    /// The registered id.
    pub const ID: &'static str = "Pendulum-v1";

    /// The environment with gymnasium's constants (g = 10); its generator starts from seed 0.
    pub fn new() -> Self {
        let plant = GymPendulum::default();
        let task = PendulumTask::new(plant.params());
        PlantEnv::from_parts(plant, task).expect("the pendulum's task and plant agree")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Env;

    #[test]
    fn angle_normalize_is_numpy_floor_mod() {
        assert_eq!(angle_normalize(PI), -PI);
        assert_eq!(angle_normalize(-PI), -PI);
        assert!((angle_normalize(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((angle_normalize(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-15);
        let r = angle_normalize(-1e-300);
        assert!((-PI..PI).contains(&r));
    }

    #[test]
    fn the_reward_read_off_observations_is_the_steps_reward() {
        let task = PendulumTask::new(&GymPendulumParams::default());
        let mut env = PendulumEnv::new();
        let mut obs = env.reset(Some(3));
        for t in 0..200 {
            // Far outside the bounds at times, and unwrapped angles after many turns.
            let a = 5.0 * (t as f64 * 0.37).sin();
            let step = env.step(&Action::Continuous(vec![a])).unwrap();
            let u = task.control(&Action::Continuous(vec![a]));
            let r = task.observation_reward(&obs, &u, &step.observation);
            // Equal up to the observation's f32 rounding.
            assert!((r - step.reward).abs() < 1e-5, "{r} vs {}", step.reward);
            assert!(!task.observation_terminated(&step.observation));
            obs = step.observation;
        }
    }

    #[test]
    fn reward_uses_the_pre_step_state_and_clipped_torque() {
        let mut e = PendulumEnv::new();
        e.set_state(&[1.0, 2.0]).unwrap();
        let st = e.step(&Action::Continuous(vec![5.0])).unwrap();
        assert_eq!(st.reward, -(1.0 + 0.1 * 4.0 + 0.001 * 4.0));
        assert!(!st.terminated && !st.truncated);
    }

    #[test]
    fn wrong_dimension_and_non_finite_actions_are_errors() {
        let mut e = PendulumEnv::new();
        e.reset(Some(1));
        assert!(e.step(&Action::Continuous(vec![0.0, 0.0])).is_err());
        assert!(e.step(&Action::Continuous(vec![f64::NAN])).is_err());
        assert!(e.step(&Action::Discrete(0)).is_err());
    }
}
