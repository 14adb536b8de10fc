//! p3's leg trajectory tracking (§5): a torque-controlled 2R leg on a test rig moves its foot
//! along a semi-elliptical trajectory, scored by reward (15).
//!
//! The plant is [`crate::leg2r`]'s URDF leg (thigh and shank 0.15 m, 0.35 and 0.20 kg,
//! 3 N m per joint, 500 Hz) with a [`Clocked`] phase: the task's target depends on time, and a
//! task reads time from the state, so the state carries the gait phase as `(cos φ, sin φ)`.
//!
//! | | |
//! |---|---|
//! | state | `[q_hip, q_knee, q̇_hip, q̇_knee, cos φ, sin φ]` (rad, rad/s) |
//! | observation | `[q_hip, q_knee, q̇_hip, q̇_knee, cos φ, sin φ, p_x − p_dx, p_z − p_dz, ṗ_x − ṗ_dx, ṗ_z − ṗ_dz]`: the joints, the phase and the foot's tracking error (m, m/s) |
//! | action | `Box(2)` in `[-1, 1]` (clipped): hip and knee torque commands as fractions of the motors' 3 N m peak; a motor delivers less in the direction of motion at speed (back-EMF, no torque left at 40 rad/s) |
//! | reward | [`leg2r_reward`] of the foot's errors after the step, in metres as p3: at most 1 per step |
//! | start | a random phase, the joints on the target (inverse kinematics, `J⁻¹ ṗ_d`) perturbed by up to ±0.05 rad and ±0.2 rad/s, from the seeded generator |
//! | episode | 1000 steps (2 s, four gait periods); never terminates |
//!
//! The trajectory ([`FootTrajectory`], origin at the hip, x forward, z up): stance is a straight
//! line at `z = −0.24 m` from `x = +0.06` to `−0.06 m` during the first half of the 0.5 s period
//! (0.48 m/s backwards, as the foot of a leg walking forwards), swing the upper half-ellipse back
//! to the front (semi-axes 0.06 m along x, 0.05 m high) at a uniform angular rate. The target
//! velocity jumps where the segments meet (by about 0.8 m/s), so a real foot cannot follow it
//! exactly there.
//!
//! Reward (15) in metres is flat: a 5 cm position error still scores 0.998 of the position term.
//! Mean reward per step over 5 seeded episodes (measured): uniformly random torques 0.80, a limp
//! leg (zero torque) 0.89, holding the start pose 0.94, a computed-torque tracking controller
//! 0.997. The errors can be measured in other units with [`Leg2RConfig::position_scale`] and
//! [`Leg2RConfig::velocity_scale`] (`|e|²` becomes `|e / scale|²`); the defaults (1 m, 1 m/s) are
//! the paper's. In units of 2 cm and 0.2 m/s the same four policies score 0.02, 0.03, 0.09 and
//! 0.97.
//!
//! ```
//! use tandem_envs::{Action, Env};
//! use tandem_robots::{Leg2REnv, Leg2REnvExt, Leg2RModel};
//!
//! let mut env = Leg2REnv::new(Leg2RModel::Idealized);
//! let obs = env.reset(Some(0));
//! assert_eq!(obs.len(), 10);
//! let step = env.step(&Action::Continuous(vec![0.0, 0.0])).unwrap();
//! assert!(step.reward > 0.0 && step.reward <= 1.0);
//! // Wrong lengths and NaN are errors, not panics.
//! assert!(env.step(&Action::Continuous(vec![0.0])).is_err());
//! assert!(env.step(&Action::Continuous(vec![0.0, f64::NAN])).is_err());
//! ```

use std::f64::consts::{PI, TAU};

use super::plant::{joint_motors, leg2r_plant, FootKinematics, Leg2RParams};
use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::rigid_plant::RigidBodyPlant;
use tandem_dynamics::Clocked;

use tandem_envs::clip_to;
use tandem_envs::{EnvError, PlantEnv, Task};

/// Episode length of p3's leg task: 1000 steps (p3: "1000 interactions per episode"), 2 s at
/// 500 Hz.
pub const LEG2R_STEPS: usize = 1000;

/// Reward (15) of p3: `0.8 exp(−|e_p|²) + 0.2 exp(−|e_v|²)`, with `e_p = p − p_d` the foot's
/// position error and `e_v = ṗ − ṗ_d` its velocity error (the paper's units: metres and m/s).
///
/// ```
/// use tandem_robots::leg2r_reward;
/// assert_eq!(leg2r_reward([0.0, 0.0], [0.0, 0.0]), 1.0);
/// // A 10 cm position error costs half a percent of the position term.
/// assert!((leg2r_reward([0.1, 0.0], [0.0, 0.0]) - (0.8 * (-0.01f64).exp() + 0.2)).abs() < 1e-15);
/// ```
pub fn leg2r_reward(position_error: [f64; 2], velocity_error: [f64; 2]) -> f64 {
    let sq = |e: [f64; 2]| e[0] * e[0] + e[1] * e[1];
    0.8 * (-sq(position_error)).exp() + 0.2 * (-sq(velocity_error)).exp()
}

/// Where the foot should be at one phase: position (m), velocity (m/s), acceleration (m/s²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FootTarget {
    /// `p_d = (x, z)`.
    pub position: [f64; 2],
    /// `ṗ_d`.
    pub velocity: [f64; 2],
    /// `p̈_d` (within a segment; the jumps between segments are not in it).
    pub acceleration: [f64; 2],
}

/// A semi-elliptical foot trajectory in the sagittal plane (x forward, z up, origin at the hip),
/// periodic in the phase `φ ∈ [0, 2π)`: stance (`φ < π`) a straight line from the front end
/// `(center_x + half_stride, stance_z)` to the back end at constant speed, swing (`φ ≥ π`) the
/// upper half of the ellipse of semi-axes `(half_stride, height)` back to the front, at a uniform
/// angular rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FootTrajectory {
    /// x of the ellipse's centre (m): 0, under the hip.
    pub center_x: f64,
    /// Height of the stance line (m): −0.24, 80 % of the leg's 0.30 m reach.
    pub stance_z: f64,
    /// Half the stride (m): 0.06 (a 12 cm step).
    pub half_stride: f64,
    /// Swing height (m): 0.05.
    pub height: f64,
    /// Period (s): 0.5 (a 2 Hz trot); the phase turns by `2π dt / period` a step.
    pub period: f64,
}

impl Default for FootTrajectory {
    fn default() -> Self {
        Self {
            center_x: 0.0,
            stance_z: -0.24,
            half_stride: 0.06,
            height: 0.05,
            period: 0.5,
        }
    }
}

impl FootTrajectory {
    /// The target at phase `phase` (rad; any real, taken modulo 2π).
    pub fn at(&self, phase: f64) -> FootTarget {
        let phi = phase.rem_euclid(TAU);
        let w = TAU / self.period;
        let (a, b) = (self.half_stride, self.height);
        if phi < PI {
            // Stance: x goes from +a to −a while φ goes from 0 to π.
            let s = phi / PI;
            FootTarget {
                position: [self.center_x + a * (1.0 - 2.0 * s), self.stance_z],
                velocity: [-2.0 * a * w / PI, 0.0],
                acceleration: [0.0, 0.0],
            }
        } else {
            let (sin, cos) = (phi - PI).sin_cos();
            FootTarget {
                position: [self.center_x - a * cos, self.stance_z + b * sin],
                velocity: [a * w * sin, b * w * cos],
                acceleration: [a * w * w * cos, -b * w * w * sin],
            }
        }
    }

    /// Checks the numbers are finite and positive where they must be, and that `foot` can
    /// follow the whole trajectory inside `joint_range` with the knee bent (away from the
    /// straight-leg singularity), checked every degree of phase.
    fn check(&self, foot: &FootKinematics, joint_range: [[f64; 2]; 2]) -> Result<(), String> {
        let all = [
            self.center_x,
            self.stance_z,
            self.half_stride,
            self.height,
            self.period,
        ];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(format!("trajectory numbers must be finite: {self:?}"));
        }
        if !(self.half_stride > 0.0 && self.height > 0.0 && self.period > 0.0) {
            return Err(format!(
                "half_stride, height and period must be positive: {self:?}"
            ));
        }
        for k in 0..360 {
            let phase = TAU * k as f64 / 360.0;
            let p = self.at(phase).position;
            let q = foot
                .inverse(p)
                .ok_or_else(|| format!("the foot cannot reach {p:?} (phase {phase:.3})"))?;
            let inside = q
                .iter()
                .zip(joint_range)
                .all(|(q, [lo, hi])| (lo..=hi).contains(q));
            if !inside || q[1] < 0.1 {
                return Err(format!(
                    "reaching {p:?} (phase {phase:.3}) needs joint angles {q:?}: outside the \
                     joint range {joint_range:?} or with the knee nearly straight"
                ));
            }
        }
        Ok(())
    }
}

/// The error of an invalid leg configuration.
fn invalid_config(id: &str, reason: String) -> EnvError {
    EnvError::Unsupported {
        env: id.to_string(),
        reason: format!("invalid configuration: {reason}"),
    }
}

/// Which leg of the idealized/true pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Leg2RModel {
    /// The URDF as written ([`Leg2RParams::idealized`]).
    Idealized,
    /// A 30 % heavier shank and joint friction ([`Leg2RParams::real`]).
    Real,
}

/// Everything [`Leg2RTask`] and [`Leg2REnv`] are built from; `Default` is the registered
/// `Leg2R-v0`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Leg2RConfig {
    /// The plant's timing, hard stops and overrides.
    pub plant: Leg2RParams,
    /// The foot's target.
    pub trajectory: FootTrajectory,
    /// Unit of the position error in the reward (m): 1, p3's metres.
    pub position_scale: f64,
    /// Unit of the velocity error in the reward (m/s): 1.
    pub velocity_scale: f64,
    /// Half-width of the uniform noise on the starting joint angles (rad): 0.05.
    pub start_angle_noise: f64,
    /// Half-width of the uniform noise on the starting joint velocities (rad/s): 0.2.
    pub start_velocity_noise: f64,
    /// Episode length: [`LEG2R_STEPS`].
    pub max_episode_steps: usize,
}

impl Default for Leg2RConfig {
    fn default() -> Self {
        Self {
            plant: Leg2RParams::idealized(),
            trajectory: FootTrajectory::default(),
            position_scale: 1.0,
            velocity_scale: 1.0,
            start_angle_noise: 0.05,
            start_velocity_noise: 0.2,
            max_episode_steps: LEG2R_STEPS,
        }
    }
}

impl Leg2RConfig {
    /// The registered task on one leg of the pair.
    pub fn for_model(model: Leg2RModel) -> Self {
        let plant = match model {
            Leg2RModel::Idealized => Leg2RParams::idealized(),
            Leg2RModel::Real => Leg2RParams::real(),
        };
        Self {
            plant,
            ..Self::default()
        }
    }

    fn check(&self) -> Result<(), String> {
        let positive = [
            ("position_scale", self.position_scale),
            ("velocity_scale", self.velocity_scale),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be positive and finite, got {v}"));
            }
        }
        let noise = [
            ("start_angle_noise", self.start_angle_noise),
            ("start_velocity_noise", self.start_velocity_noise),
        ];
        for (name, v) in noise {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be finite and non-negative, got {v}"));
            }
        }
        if self.max_episode_steps == 0 {
            return Err("max_episode_steps must be positive".into());
        }
        Ok(())
    }
}

/// p3's leg tracking task over a [`Clocked`] leg plant (see the module documentation).
#[derive(Debug, Clone)]
pub struct Leg2RTask {
    id: String,
    config: Leg2RConfig,
    foot: FootKinematics,
    torque_limit: [f64; 2],
    observation_space: Space,
    action_space: Space,
}

impl Leg2RTask {
    /// The task on `plant` (a leg from [`leg2r_plant`]), reported as `id`; an error when the
    /// configuration or the plant does not fit (a trajectory out of reach, a bad scale).
    pub fn new(id: &str, config: Leg2RConfig, plant: &RigidBodyPlant) -> Result<Self, EnvError> {
        let invalid = |reason: String| invalid_config(id, reason);
        config.check().map_err(invalid)?;
        let model = plant.model();
        let foot = FootKinematics::new(model).map_err(|e| invalid(e.to_string()))?;
        let motors = joint_motors(model).map_err(|e| invalid(e.to_string()))?;
        let range = [0, 1].map(|i| [model.joints[i].lower, model.joints[i].upper]);
        config.trajectory.check(&foot, range).map_err(invalid)?;
        let inf = f64::INFINITY;
        let mut high = vec![inf; 10];
        high[4] = 1.0;
        high[5] = 1.0;
        Ok(Self {
            id: id.to_string(),
            torque_limit: motors.map(|m| m.peak_torque),
            observation_space: Space::boxed(high.iter().map(|h| -h).collect(), high),
            action_space: Space::symmetric(2, 1.0),
            foot,
            config,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Leg2RConfig {
        &self.config
    }

    /// The foot's kinematics (of the plant the task was built on).
    pub fn foot(&self) -> &FootKinematics {
        &self.foot
    }

    /// Joint torque limits (N m) an action of ±1 stands for.
    pub fn torque_limit(&self) -> [f64; 2] {
        self.torque_limit
    }

    /// The target at a state's phase.
    pub fn target(&self, state: &[f64]) -> FootTarget {
        self.config
            .trajectory
            .at(Clocked::<RigidBodyPlant>::phase(state))
    }

    /// The foot's position and velocity errors `(p − p_d, ṗ − ṗ_d)` at a state (m, m/s).
    pub fn tracking_error(&self, state: &[f64]) -> ([f64; 2], [f64; 2]) {
        let (p, v) = self.foot.state(&state[..2], &state[2..4]);
        let t = self.target(state);
        (
            [p[0] - t.position[0], p[1] - t.position[1]],
            [v[0] - t.velocity[0], v[1] - t.velocity[1]],
        )
    }

    /// A state on the trajectory at `phase`: the joints where the inverse kinematics puts the
    /// foot on its target, moving with it (`q̇ = J⁻¹ ṗ_d`).
    pub fn state_on_trajectory(&self, phase: f64) -> Vec<f64> {
        let t = self.config.trajectory.at(phase);
        // The trajectory was checked reachable with a bent knee at construction.
        let q = self.foot.inverse(t.position).unwrap_or([0.0, 0.0]);
        let qdot = self
            .foot
            .joint_velocity(&q, t.velocity)
            .unwrap_or([0.0, 0.0]);
        Clocked::<RigidBodyPlant>::state(&[q[0], q[1], qdot[0], qdot[1]], phase)
    }
}

impl Task for Leg2RTask {
    fn id(&self) -> &str {
        &self.id
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        6
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        let a = clip_to(
            &self.action_space,
            action.as_continuous().unwrap_or(&[0.0, 0.0]),
        );
        vec![a[0] * self.torque_limit[0], a[1] * self.torque_limit[1]]
    }
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        let mut x = self.state_on_trajectory(rng.random_range(0.0..TAU));
        let (dq, dv) = (
            self.config.start_angle_noise,
            self.config.start_velocity_noise,
        );
        for (i, d) in [dq, dq, dv, dv].into_iter().enumerate() {
            if d > 0.0 {
                x[i] += rng.random_range(-d..d);
            }
        }
        x
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        let (e, ev) = self.tracking_error(state);
        let mut obs = state.to_vec();
        obs.extend_from_slice(&[e[0], e[1], ev[0], ev[1]]);
        obs
    }
    /// Puts the clock back on the unit circle (a learned model's prediction drifts off it).
    fn canonicalize(&self, state: &mut [f64]) {
        let n = (state[4] * state[4] + state[5] * state[5]).sqrt();
        if n > 0.0 && n.is_finite() {
            state[4] /= n;
            state[5] /= n;
        } else {
            state[4] = 1.0;
            state[5] = 0.0;
        }
    }
    fn reward(&self, _state: &[f64], _u: &[f64], next: &[f64]) -> f64 {
        let (e, ev) = self.tracking_error(next);
        let (sp, sv) = (self.config.position_scale, self.config.velocity_scale);
        leg2r_reward([e[0] / sp, e[1] / sp], [ev[0] / sv, ev[1] / sv])
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(self.config.max_episode_steps)
    }
}

/// p3's leg task, truncated at its configured episode length (1000 steps by default) by its
/// task: a [`PlantEnv`] of [`Leg2RTask`] over the [`Clocked`] leg.
pub type Leg2REnv = PlantEnv<Clocked<RigidBodyPlant>, Leg2RTask>;

/// The ids and constructors of [`Leg2REnv`]. A trait: the environment is `tandem-envs`'
/// [`PlantEnv`], to which only that crate can add inherent items.
pub trait Leg2REnvExt: Sized {
    /// Id of the idealized leg.
    const ID: &'static str = "Leg2R-v0";
    /// Id of the true ("real") leg: heavier shank, joint friction.
    const ID_REAL: &'static str = "Leg2R-real-v0";

    /// The registered task on one leg of the pair.
    fn new(model: Leg2RModel) -> Self;

    /// The task with a custom configuration, reported as `id`; an error when the configuration
    /// is invalid (a trajectory out of reach, a non-positive scale or period).
    fn with_config(id: &str, config: Leg2RConfig) -> Result<Self, EnvError>;
}

impl Leg2REnvExt for Leg2REnv {
    fn new(model: Leg2RModel) -> Self {
        let id = match model {
            Leg2RModel::Idealized => Self::ID,
            Leg2RModel::Real => Self::ID_REAL,
        };
        Self::with_config(id, Leg2RConfig::for_model(model))
            .expect("the registered leg configurations are valid")
    }

    fn with_config(id: &str, config: Leg2RConfig) -> Result<Self, EnvError> {
        let invalid = |e: &dyn std::fmt::Display| invalid_config(id, e.to_string());
        let leg = leg2r_plant(&config.plant).map_err(|e| invalid(&e))?;
        let task = Leg2RTask::new(id, config.clone(), &leg)?;
        let plant = Clocked::new(leg, config.trajectory.period).map_err(|e| invalid(&e))?;
        PlantEnv::from_parts(plant, task)
    }
}
