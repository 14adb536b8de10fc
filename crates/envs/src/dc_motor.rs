//! The swing-up task of paper p0 on the DC-motor pendulum, as an idealized/true pair.

use std::f64::consts::PI;
use tandem_core::{Action, Space};
use tandem_dynamics::classic::{DcMotorPendulum, DcMotorPendulumParams};

use crate::env::{check_action, check_state, Phase};
use crate::pendulum::angle_normalize;
use crate::{Env, EnvError, Step};

/// Episode length of the p0 swing-up: 20 s at `T_s` = 0.05 s.
pub const DC_MOTOR_PENDULUM_STEPS: usize = 400;

/// Wraps an angle to `[-π, π)`.
pub fn wrap_angle(phi: f64) -> f64 {
    angle_normalize(phi)
}

/// The p0 swing-up reward `r = −5 φ² − 0.1 φ̇² − 0.01 u²` (p0, Sec. IV-A), with φ wrapped to
/// `[-π, π)` and `u` the applied (saturated) voltage.
///
/// `state = (φ, φ̇)` is the state AFTER the step: the reward scores where the action led (the
/// paper gives the formula without saying which state; the resulting state is the usual choice
/// for a swing-up task, and it is what a planner scoring `x_{t+1}` needs). Planners reuse this
/// function directly.
///
/// ```
/// use tandem_envs::dc_motor_pendulum_reward;
/// assert_eq!(dc_motor_pendulum_reward(&[0.0, 0.0], 0.0), 0.0);
/// // Angles are wrapped: 2π is upright.
/// assert!(dc_motor_pendulum_reward(&[2.0 * std::f64::consts::PI, 0.0], 0.0).abs() < 1e-20);
/// ```
pub fn dc_motor_pendulum_reward(state: &[f64], u: f64) -> f64 {
    let phi = wrap_angle(state[0]);
    let phidot = state[1];
    -5.0 * phi * phi - 0.1 * phidot * phidot - 0.01 * u * u
}

/// Which of p0's two pendulum models.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum PendulumModel {
    /// m = 0.055 kg: the model the policy is pre-trained on.
    Idealized,
    /// m = 0.090 kg: the "real" system (Table I).
    Real,
}

/// The p0 swing-up task over [`DcMotorPendulum`], without its time limit ([`crate::make`] adds
/// the 400-step [`crate::TimeLimit`]).
///
/// - state `(φ, φ̇)` (φ not wrapped; φ = 0 upright); start `(π, 0)` on every reset (the paper's
///   `s_0`; the seed is accepted and unused);
/// - observation `(wrap(φ), φ̇)` in `f64`, φ wrapped to `[-π, π)`; the velocity bound of the
///   observation space is infinite (the motor's top speed at 3 V is about 55 rad/s);
/// - action `Box(1)`: voltage in `[-3, 3]` V, clipped when outside;
/// - reward [`dc_motor_pendulum_reward`] of the new state; never terminates.
#[derive(Debug, Clone)]
pub struct DcMotorPendulumEnv {
    id: &'static str,
    plant: DcMotorPendulum,
    state: [f64; 2],
    phase: Phase,
    observation_space: Space,
    action_space: Space,
}

impl DcMotorPendulumEnv {
    /// Id of the idealized task.
    pub const ID_IDEALIZED: &'static str = "DcMotorPendulum-idealized-v0";
    /// Id of the true ("real") task.
    pub const ID_REAL: &'static str = "DcMotorPendulum-real-v0";

    /// The task on one of p0's two models.
    pub fn new(model: PendulumModel) -> Self {
        match model {
            PendulumModel::Idealized => {
                Self::with_params(Self::ID_IDEALIZED, DcMotorPendulumParams::idealized())
            }
            PendulumModel::Real => Self::with_params(Self::ID_REAL, DcMotorPendulumParams::real()),
        }
    }

    /// The task on a pendulum with custom parameters, reported under `id`.
    pub fn with_params(id: &'static str, params: DcMotorPendulumParams) -> Self {
        Self {
            id,
            plant: DcMotorPendulum::new(params),
            state: [PI, 0.0],
            phase: Phase::NotReset,
            observation_space: Space::boxed(vec![-PI, f64::NEG_INFINITY], vec![PI, f64::INFINITY]),
            action_space: Space::symmetric(1, params.u_max),
        }
    }

    /// The plant it steps.
    pub fn plant(&self) -> &DcMotorPendulum {
        &self.plant
    }

    fn observation(&self) -> Vec<f64> {
        vec![wrap_angle(self.state[0]), self.state[1]]
    }
}

impl Env for DcMotorPendulumEnv {
    fn id(&self) -> &str {
        self.id
    }

    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(&mut self, _seed: Option<u64>) -> Vec<f64> {
        self.state = [PI, 0.0];
        self.phase = Phase::Running;
        self.observation()
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        self.phase.check(self.id)?;
        check_action(self.id, &self.action_space, action)?;
        let max = self.plant.params().u_max;
        let u = action
            .as_continuous()
            .map_or(0.0, |a| a[0])
            .clamp(-max, max);
        self.state = self.plant.step_array(&self.state, u);
        Ok(Step {
            observation: self.observation(),
            reward: dc_motor_pendulum_reward(&self.state, u),
            terminated: false,
            truncated: false,
        })
    }

    fn state(&self) -> Vec<f64> {
        self.state.to_vec()
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_state(self.id, state, 2)?;
        self.state.copy_from_slice(state);
        self.phase = Phase::Running;
        Ok(self.observation())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn starts_hanging_and_the_two_models_differ() {
        let mut i = DcMotorPendulumEnv::new(PendulumModel::Idealized);
        let mut r = DcMotorPendulumEnv::new(PendulumModel::Real);
        assert_eq!(i.reset(Some(3)), vec![-PI, 0.0]);
        assert_eq!(r.reset(None), vec![-PI, 0.0]);
        let a = Action::Continuous(vec![3.0]);
        let (si, sr) = (i.step(&a).unwrap(), r.step(&a).unwrap());
        assert_ne!(si.observation, sr.observation);
        // The heavier pendulum (more inertia for the same motor torque) accelerates less.
        assert!(si.observation[1].abs() > sr.observation[1].abs());
    }

    #[test]
    fn reward_is_the_papers_of_the_new_state_with_clipped_voltage() {
        let mut e = DcMotorPendulumEnv::new(PendulumModel::Real);
        e.set_state(&[PI - 0.3, 1.0]).unwrap();
        let st = e.step(&Action::Continuous(vec![7.0])).unwrap();
        let s = e.state();
        let phi = wrap_angle(s[0]);
        let expected = -5.0 * phi * phi - 0.1 * s[1] * s[1] - 0.01 * 9.0;
        assert_eq!(st.reward, expected);
        assert_eq!(e.plant().step_array(&[PI - 0.3, 1.0], 3.0), [s[0], s[1]]);
        // Hanging at rest costs 5π².
        assert!((dc_motor_pendulum_reward(&[PI, 0.0], 0.0) + 5.0 * PI * PI).abs() < 1e-12);
        assert!((dc_motor_pendulum_reward(&[-PI, 0.0], 0.0) + 5.0 * PI * PI).abs() < 1e-12);
    }
}
