//! `CartPole-v1`, exact to gymnasium 1.x.

use rand::Rng as _;
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::{Action, Space};
use tandem_dynamics::classic::CartPole;

use crate::env::{check_action, check_state, round_to_f32, Phase};
use crate::{Env, EnvError, Step};

/// Gymnasium's `CartPole-v1` without its time limit ([`crate::make`] adds the 500-step
/// [`crate::TimeLimit`]).
///
/// - state `(x, ẋ, θ, θ̇)` in `f64`, stepped by [`CartPole`]; observation = the state rounded to
///   `f32` (gymnasium returns a `float32` array);
/// - action `Discrete(2)`: 1 pushes with `+force_mag` = +10 N, 0 with −10 N;
/// - reward 1.0 on every step, the terminating one included;
/// - terminated when `|x| > 2.4` or `|θ| > 12°` (strict inequalities);
/// - reset: every component uniform in `[-0.05, 0.05)` from the environment's own seeded
///   generator (not numpy's stream: replay from a state with [`Env::set_state`] instead).
#[derive(Debug, Clone)]
pub struct CartPoleEnv {
    plant: CartPole,
    force_mag: f64,
    x_threshold: f64,
    theta_threshold_radians: f64,
    state: [f64; 4],
    phase: Phase,
    rng: Rng,
    observation_space: Space,
    action_space: Space,
}

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
        // Computed as gymnasium does: 12 * 2 * math.pi / 360.
        let theta_threshold_radians = 12.0 * 2.0 * std::f64::consts::PI / 360.0;
        let x_threshold = 2.4;
        let big = f32::MAX as f64;
        let high = vec![x_threshold * 2.0, big, theta_threshold_radians * 2.0, big];
        Self {
            plant: CartPole::default(),
            force_mag: 10.0,
            x_threshold,
            theta_threshold_radians,
            state: [0.0; 4],
            phase: Phase::NotReset,
            rng: rng_from_seed(0),
            observation_space: Space::boxed(high.iter().map(|h| -h).collect(), high),
            action_space: Space::discrete(2),
        }
    }

    /// The plant it steps.
    pub fn plant(&self) -> &CartPole {
        &self.plant
    }

    fn terminated(&self) -> bool {
        let [x, _, theta, _] = self.state;
        x < -self.x_threshold
            || x > self.x_threshold
            || theta < -self.theta_threshold_radians
            || theta > self.theta_threshold_radians
    }
}

impl Env for CartPoleEnv {
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
        for v in &mut self.state {
            *v = self.rng.random_range(-0.05..0.05);
        }
        self.phase = Phase::Running;
        round_to_f32(&self.state)
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        self.phase.check(Self::ID)?;
        check_action(Self::ID, &self.action_space, action)?;
        let force = if action.as_discrete() == Some(1) {
            self.force_mag
        } else {
            -self.force_mag
        };
        self.state = self.plant.step_array(&self.state, force);
        let terminated = self.terminated();
        if terminated {
            self.phase = Phase::Ended;
        }
        Ok(Step {
            observation: round_to_f32(&self.state),
            reward: 1.0,
            terminated,
            truncated: false,
        })
    }

    fn state(&self) -> Vec<f64> {
        self.state.to_vec()
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_state(Self::ID, state, 4)?;
        self.state.copy_from_slice(state);
        self.phase = Phase::Running;
        Ok(round_to_f32(&self.state))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
