//! `CartPole-v1`, exact to gymnasium 1.x: [`CartPoleTask`] over the [`CartPole`] plant.

use rand::Rng as _;
use tandem_core::seeding::Rng;
use tandem_core::{Action, Space};
use tandem_dynamics::classic::CartPole;

use crate::env::round_to_f32;
use crate::{ObservedTask, PlantEnv, Task};

/// Gymnasium's `CartPole-v1` task over the [`CartPole`] plant:
///
/// - state `(x, ẋ, θ, θ̇)` in `f64`; observation = the state rounded to `f32` (gymnasium returns
///   a `float32` array);
/// - action `Discrete(2)`: 1 pushes with `+force_mag` = +10 N, 0 with −10 N;
/// - reward 1.0 on every step, the terminating one included;
/// - terminated when `|x| > 2.4` or `|θ| > 12°` (strict inequalities);
/// - start: every component uniform in `[-0.05, 0.05)` from the environment's seeded generator
///   (not numpy's stream: replay from a state with [`crate::Env::set_state`] instead);
/// - 500 steps.
#[derive(Debug, Clone)]
pub struct CartPoleTask {
    force_mag: f64,
    x_threshold: f64,
    theta_threshold_radians: f64,
    observation_space: Space,
    action_space: Space,
}

impl Default for CartPoleTask {
    fn default() -> Self {
        // Computed as gymnasium does: 12 * 2 * math.pi / 360.
        let theta_threshold_radians = 12.0 * 2.0 * std::f64::consts::PI / 360.0;
        let x_threshold = 2.4;
        let big = f32::MAX as f64;
        let high = vec![x_threshold * 2.0, big, theta_threshold_radians * 2.0, big];
        Self {
            force_mag: 10.0,
            x_threshold,
            theta_threshold_radians,
            observation_space: Space::boxed(high.iter().map(|h| -h).collect(), high),
            action_space: Space::discrete(2),
        }
    }
}

impl Task for CartPoleTask {
    fn id(&self) -> &str {
        CartPoleEnv::ID
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        4
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        let push = if action.as_discrete() == Some(1) {
            1.0
        } else {
            -1.0
        };
        vec![push * self.force_mag]
    }
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        (0..4).map(|_| rng.random_range(-0.05..0.05)).collect()
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        round_to_f32(state)
    }
    fn reward(&self, _state: &[f64], _u: &[f64], _next: &[f64]) -> f64 {
        1.0
    }
    fn terminated(&self, next: &[f64]) -> bool {
        let (x, theta) = (next[0], next[2]);
        x < -self.x_threshold
            || x > self.x_threshold
            || theta < -self.theta_threshold_radians
            || theta > self.theta_threshold_radians
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(500)
    }
}

/// The observation is the state (rounded to `f32`), so the reward and termination read it alike.
impl ObservedTask for CartPoleTask {
    fn observation_reward(&self, obs: &[f64], u: &[f64], next_obs: &[f64]) -> f64 {
        self.reward(obs, u, next_obs)
    }
    fn observation_terminated(&self, next_obs: &[f64]) -> bool {
        self.terminated(next_obs)
    }
}

/// Gymnasium's `CartPole-v1`, truncated at 500 steps by its task: a [`PlantEnv`] of
/// [`CartPoleTask`] over [`CartPole`].
pub type CartPoleEnv = PlantEnv<CartPole, CartPoleTask>;

impl Default for CartPoleEnv {
    fn default() -> Self {
        Self::new()
    }
}

impl CartPoleEnv {
    /// The registered id.
    pub const ID: &'static str = "CartPole-v1";

    /// The environment with gymnasium's constants; its generator starts from seed 0 until a
    /// seeded `reset`.
    pub fn new() -> Self {
        PlantEnv::from_parts(CartPole::default(), CartPoleTask::default())
            .expect("CartPole's task and plant agree")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Env, EnvError};

    #[test]
    fn seeded_resets_are_reproducible_and_in_range() {
        let mut a = CartPoleEnv::new();
        let mut b = CartPoleEnv::new();
        assert_eq!(a.reset(Some(5)), b.reset(Some(5)));
        let s = a.state();
        assert!(s.iter().all(|v| (-0.05..0.05).contains(v)));
        assert_ne!(a.reset(None), b.reset(Some(6)));
    }

    #[test]
    fn step_before_reset_and_after_termination_are_errors() {
        let mut e = CartPoleEnv::new();
        assert!(matches!(
            e.step(&Action::Discrete(0)),
            Err(EnvError::NeedsReset {
                when: "before reset",
                ..
            })
        ));
        e.set_state(&[2.39, 5.0, 0.0, 0.0]).unwrap();
        let st = e.step(&Action::Discrete(1)).unwrap();
        assert!(st.terminated && st.reward == 1.0);
        assert!(matches!(
            e.step(&Action::Discrete(1)),
            Err(EnvError::NeedsReset { .. })
        ));
    }

    #[test]
    fn bad_actions_and_states_are_errors() {
        let mut e = CartPoleEnv::new();
        e.reset(Some(0));
        assert!(matches!(
            e.step(&Action::Discrete(2)),
            Err(EnvError::InvalidAction { .. })
        ));
        assert!(matches!(
            e.step(&Action::Continuous(vec![1.0])),
            Err(EnvError::InvalidAction { .. })
        ));
        assert!(e.set_state(&[0.0; 3]).is_err());
        assert!(e.set_state(&[0.0, f64::NAN, 0.0, 0.0]).is_err());
    }
}
