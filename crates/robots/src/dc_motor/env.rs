//! The swing-up task of paper p0 on the DC-motor pendulum, as an idealized/true pair.

use super::plant::{DcMotorPendulum, DcMotorPendulumParams};
use std::f64::consts::PI;
use tandem_core::{Action, Rng, Space};

use tandem_envs::angle_normalize;
use tandem_envs::clip_to;
use tandem_envs::{PlantEnv, Task};

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
/// use tandem_robots::dc_motor_pendulum_reward;
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

/// p0's swing-up task (Sec. IV-A) over a [`DcMotorPendulum`]:
///
/// - state `(φ, φ̇)` (φ not wrapped; φ = 0 upright); start `(π, 0)` on every reset (the paper's
///   `s_0`; the generator is not used);
/// - observation `(wrap(φ), φ̇)` in `f64`, φ wrapped to `[-π, π)`; the velocity bound of the
///   observation space is infinite (the motor's top speed at 3 V is about 55 rad/s);
/// - action `Box(1)`: voltage in `[-u_max, u_max]` (3 V), clipped when outside;
/// - reward [`dc_motor_pendulum_reward`] of the new state; never terminates; 400 steps.
#[derive(Debug, Clone)]
pub struct DcMotorPendulumTask {
    id: &'static str,
    observation_space: Space,
    action_space: Space,
}

impl DcMotorPendulumTask {
    /// The task, reported as `id`, for a pendulum whose voltage bound is `params.u_max`.
    pub fn new(id: &'static str, params: &DcMotorPendulumParams) -> Self {
        Self {
            id,
            observation_space: Space::boxed(vec![-PI, f64::NEG_INFINITY], vec![PI, f64::INFINITY]),
            action_space: Space::symmetric(1, params.u_max),
        }
    }
}

impl Task for DcMotorPendulumTask {
    fn id(&self) -> &str {
        self.id
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
    fn initial_state(&self, _rng: &mut Rng) -> Vec<f64> {
        vec![PI, 0.0]
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        vec![wrap_angle(state[0]), state[1]]
    }
    fn canonicalize(&self, state: &mut [f64]) {
        state[0] = wrap_angle(state[0]);
    }
    fn reward(&self, _state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        dc_motor_pendulum_reward(next, u[0])
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(DC_MOTOR_PENDULUM_STEPS)
    }
}

/// The p0 swing-up over [`DcMotorPendulum`], truncated at 400 steps by its task: a [`PlantEnv`]
/// of [`DcMotorPendulumTask`].
pub type DcMotorPendulumEnv = PlantEnv<DcMotorPendulum, DcMotorPendulumTask>;

/// The ids and constructors of [`DcMotorPendulumEnv`]. A trait: the environment is `tandem-envs`'
/// [`PlantEnv`], to which only that crate can add inherent items.
pub trait DcMotorPendulumEnvExt: Sized {
    /// Id of the idealized task.
    const ID_IDEALIZED: &'static str = "DcMotorPendulum-idealized-v0";
    /// Id of the true ("real") task.
    const ID_REAL: &'static str = "DcMotorPendulum-real-v0";

    /// The task on one of p0's two models.
    fn new(model: PendulumModel) -> Self;

    /// The task on a pendulum with custom parameters, reported under `id`.
    fn with_params(id: &'static str, params: DcMotorPendulumParams) -> Self;
}

impl DcMotorPendulumEnvExt for DcMotorPendulumEnv {
    fn new(model: PendulumModel) -> Self {
        match model {
            PendulumModel::Idealized => {
                Self::with_params(Self::ID_IDEALIZED, DcMotorPendulumParams::idealized())
            }
            PendulumModel::Real => Self::with_params(Self::ID_REAL, DcMotorPendulumParams::real()),
        }
    }

    fn with_params(id: &'static str, params: DcMotorPendulumParams) -> Self {
        PlantEnv::from_parts(
            DcMotorPendulum::new(params),
            DcMotorPendulumTask::new(id, &params),
        )
        .expect("the pendulum's task and plant agree")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_envs::Env;

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
