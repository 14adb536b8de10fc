//! `Pendulum-v1`, exact to gymnasium 1.x.

use rand::Rng as _;
use std::f64::consts::PI;
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::{Action, Space};
use tandem_dynamics::classic::GymPendulum;

use crate::env::{check_action, check_state, Phase};
use crate::{Env, EnvError, Step};

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

/// Gymnasium's `Pendulum-v1` without its time limit ([`crate::make`] adds the 200-step
/// [`crate::TimeLimit`]).
///
/// - state `(θ, θ̇)` in `f64` (θ not wrapped), stepped by [`GymPendulum`];
/// - observation `f32`-rounded `(cos θ, sin θ, θ̇)` of the new state;
/// - action `Box(1)` in `[-2, 2]`, clipped (not rejected) when outside;
/// - reward [`pendulum_reward`] of the state before the step; never terminates;
/// - reset: `(θ, θ̇)` uniform in `[-π, π) × [-1, 1)` from the environment's own generator.
#[derive(Debug, Clone)]
pub struct PendulumEnv {
    plant: GymPendulum,
    state: [f64; 2],
    phase: Phase,
    rng: Rng,
    observation_space: Space,
    action_space: Space,
}

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
        let p = *plant.params();
        Self {
            plant,
            state: [0.0; 2],
            phase: Phase::NotReset,
            rng: rng_from_seed(0),
            observation_space: Space::boxed(
                vec![-1.0, -1.0, -p.max_speed],
                vec![1.0, 1.0, p.max_speed],
            ),
            action_space: Space::symmetric(1, p.max_torque),
        }
    }

    /// The plant it steps.
    pub fn plant(&self) -> &GymPendulum {
        &self.plant
    }

    fn observation(&self) -> Vec<f64> {
        let [th, thdot] = self.state;
        [th.cos(), th.sin(), thdot]
            .iter()
            .map(|&v| v as f32 as f64)
            .collect()
    }
}

impl Env for PendulumEnv {
    fn id(&self) -> &str {
        Self::ID
    }

    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = rng_from_seed(s);
        }
        self.state = [
            self.rng.random_range(-PI..PI),
            self.rng.random_range(-1.0..1.0),
        ];
        self.phase = Phase::Running;
        self.observation()
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        self.phase.check(Self::ID)?;
        check_action(Self::ID, &self.action_space, action)?;
        let max = self.plant.params().max_torque;
        let u = action
            .as_continuous()
            .map_or(0.0, |a| a[0])
            .clamp(-max, max);
        let reward = pendulum_reward(&self.state, u);
        self.state = self.plant.step_array(&self.state, u);
        Ok(Step {
            observation: self.observation(),
            reward,
            terminated: false,
            truncated: false,
        })
    }

    fn state(&self) -> Vec<f64> {
        self.state.to_vec()
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_state(Self::ID, state, 2)?;
        self.state.copy_from_slice(state);
        self.phase = Phase::Running;
        Ok(self.observation())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
