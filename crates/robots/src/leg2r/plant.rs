//! The 2R quadruped leg of paper p3 (§5, "Leg trajectory tracking") on a test rig: the hip is
//! fixed to the rig, thigh and shank (0.15 m each) swing in the sagittal plane under gravity, and
//! both joints are driven by torque-controlled motors.
//!
//! The robot is the URDF [`LEG2R_URDF`] (`assets/leg2r.urdf`), read by the same rigid-body code as
//! every other robot here ([`Model::from_urdf_str`]) and stepped by a [`RigidBodyPlant`]: the
//! task's dynamics, kinematics and the tests' inverse dynamics are one model.
//!
//! | quantity | value | why |
//! |---|---|---|
//! | thigh, shank length | 0.15 m, 0.15 m | p3 §5 |
//! | thigh mass, inertia about its centre (y) | 0.35 kg, 6.8e-4 kg m² | an aluminium-like bar 0.15 × 0.03 × 0.03 m plus the knee drive's belt and pulley; both motors sit at the hip, as on most small quadrupeds |
//! | shank mass, inertia about its centre (y) | 0.20 kg, 3.9e-4 kg m² | a lighter bar and the rubber foot |
//! | centres of mass | mid-length | uniform bars |
//! | motors ([`TorqueMotor`], URDF `effort`, `velocity`) | 3 N m peak, 40 rad/s no-load speed | a small BLDC behind a 6:1 reduction (about 0.5 N m at the rotor; 24 V at about 100 rpm/V), torque-controlled as p3's; a leg that carries a body needs this margin, p3's foot trajectory on the rig needs at most 0.43 N m of feedforward (0.50 N m on the real leg), and a computed-torque controller asks for more only where the target velocity jumps |
//! | position limits (URDF) | hip ±90°, knee 0 (straight) to 2.7 rad | the rig's hard stops, enforced by compliant [`LimitSpring`]s (100 N m/rad) so that an exploring policy cannot fold the leg through itself |
//! | control period | 2 ms (500 Hz) | p3 §5 controls the torque at 500 Hz |
//! | internal RK4 step | 0.5 ms (4 per period) | resolves the limit springs (about 260 rad/s on the shank) and the regularized Coulomb friction of the real variant |
//!
//! Joint angles: both joints turn about +y, so with x forward and z up a positive angle swings
//! the part below backwards; at `q = 0` the leg hangs straight down and the foot is at
//! `(x, z) = (−l₁ sin q₁ − l₂ sin(q₁ + q₂), −l₁ cos q₁ − l₂ cos(q₁ + q₂))`. The knee bends with
//! `q₂ > 0` (knee ahead of the hip–foot line).
//!
//! [`Leg2RParams::idealized`] is the URDF as written; [`Leg2RParams::real`] the "true" system of
//! an idealized/true pair: a 30 % heavier shank and joint friction.
//!
//! ```
//! use tandem_robots::leg2r::{leg2r_plant, FootKinematics, Leg2RParams};
//! use tandem_dynamics::Plant;
//!
//! let plant = leg2r_plant(&Leg2RParams::idealized()).unwrap();
//! assert_eq!((plant.state_dim(), plant.action_dim(), plant.dt()), (4, 2, 0.002));
//! let foot = FootKinematics::new(plant.model()).unwrap();
//! // Hanging straight down, the foot is 0.30 m below the hip.
//! let p = foot.position(&[0.0, 0.0]);
//! assert!(p[0].abs() < 1e-12 && (p[1] + 0.30).abs() < 1e-12);
//! // The knee-forward inverse kinematics recovers a configuration.
//! let q = foot.inverse(foot.position(&[-0.6, 1.2])).unwrap();
//! assert!((q[0] + 0.6).abs() < 1e-12 && (q[1] - 1.2).abs() < 1e-12);
//! ```

use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use tandem_dynamics::actuators::{Actuator, TorqueMotor};
use tandem_dynamics::rigid::{
    forward_kinematics, frame_jacobian, update_frame_placements, Data, Model,
};
use tandem_dynamics::rigid_plant::{
    LimitSpring, Overrides, RigidBodyPlant, RigidPlantConfig, RigidPlantError,
};

/// The leg's URDF (`assets/leg2r.urdf`): links `rig` (fixed), `thigh`, `shank`, `foot` (a
/// massless frame at the end of the shank); joints `hip`, `knee`.
pub const LEG2R_URDF: &str = include_str!("../../assets/leg2r.urdf");

/// Thigh length (m), as in the URDF.
pub const THIGH: f64 = 0.15;
/// Shank length (m), as in the URDF.
pub const SHANK: f64 = 0.15;
/// The actuated joints in action order.
pub const JOINTS: [&str; 2] = ["hip", "knee"];
/// The link whose origin is the foot.
pub const FOOT: &str = "foot";

/// Timing, joint limits and parameter overrides of a [`leg2r_plant`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Leg2RParams {
    /// Control period (s): 0.002 (500 Hz, p3 §5).
    pub control_period: f64,
    /// Internal RK4 step (s): 0.0005.
    pub internal_step: f64,
    /// The rig's hard stops as compliant springs at the URDF's position limits; `None` lets the
    /// joints pass them (the energy-conservation check uses that).
    pub joint_limits: Option<LimitSpring>,
    /// Mass and friction overrides of the URDF (empty for the idealized leg).
    pub overrides: Overrides,
}

impl Default for Leg2RParams {
    fn default() -> Self {
        Self::idealized()
    }
}

impl Leg2RParams {
    /// The leg as in the URDF: 500 Hz control, 0.5 ms RK4 steps, hard stops, no friction.
    pub fn idealized() -> Self {
        Self {
            control_period: 0.002,
            internal_step: 0.0005,
            joint_limits: Some(LimitSpring::default()),
            overrides: Overrides::default(),
        }
    }

    /// The "true" leg of an idealized/true pair: shank 0.26 kg instead of 0.20 (a heavier foot
    /// and its cable), viscous joint friction 0.01 N m s/rad and Coulomb friction 0.05 N m (the
    /// gearbox: under 2 % of the torque limit).
    pub fn real() -> Self {
        Self {
            overrides: Overrides {
                link_mass: [("shank".to_string(), 0.26)].into_iter().collect(),
                viscous_friction: Some(0.01),
                coulomb_friction: Some(0.05),
                ..Overrides::default()
            },
            ..Self::idealized()
        }
    }
}

/// The leg's rigid-body model from [`LEG2R_URDF`].
pub fn leg2r_model() -> Result<Model, RigidPlantError> {
    Model::from_urdf_str(LEG2R_URDF).map_err(|e| RigidPlantError::Config(format!("leg URDF: {e}")))
}

/// The leg as a plant: state `[q_hip, q_knee, q̇_hip, q̇_knee]`, action the two commanded joint
/// torques (N m), each made by a [`TorqueMotor`] whose peak torque and no-load speed are the
/// URDF's `effort` and `velocity` limits ([`joint_motors`]).
pub fn leg2r_plant(params: &Leg2RParams) -> Result<RigidBodyPlant, RigidPlantError> {
    let model = leg2r_model()?;
    let motors = joint_motors(&model)?;
    let config = RigidPlantConfig {
        control_period: params.control_period,
        internal_step: params.internal_step,
    };
    let mut plant = RigidBodyPlant::new(model, config)?;
    for (joint, motor) in JOINTS.into_iter().zip(motors) {
        plant = plant.with_actuator(joint, Actuator::TorqueMotor(motor))?;
    }
    if let Some(spring) = params.joint_limits {
        plant = plant.with_position_limits(spring)?;
    }
    plant.with_overrides(&params.overrides)
}

/// The motors of [`JOINTS`] from the URDF's limits: peak torque = `effort` (3 N m), no-load
/// speed = `velocity` (40 rad/s: a 24 V BLDC of about 100 rpm/V behind a 6:1 reduction); an error
/// when a joint is missing or a limit is not positive and finite.
pub fn joint_motors(model: &Model) -> Result<[TorqueMotor; 2], RigidPlantError> {
    let motor = |name: &str| {
        let i = model
            .joint_index(name)
            .ok_or_else(|| RigidPlantError::UnknownJoint(name.into()))?;
        let j = &model.joints[i];
        if !(j.effort.is_finite() && j.effort > 0.0 && j.velocity.is_finite() && j.velocity > 0.0) {
            return Err(RigidPlantError::Config(format!(
                "joint '{name}' needs positive, finite effort and velocity limits (got {} and {})",
                j.effort, j.velocity
            )));
        }
        Ok(TorqueMotor {
            peak_torque: j.effort,
            no_load_speed: j.velocity,
        })
    };
    Ok([motor(JOINTS[0])?, motor(JOINTS[1])?])
}

/// Position, velocity, Jacobian and inverse kinematics of the foot in the sagittal plane, from
/// the rigid-body model (forward kinematics and the frame Jacobian of [`tandem_dynamics::rigid`]).
/// Coordinates are `(x, z)` in metres: x forward, z up, origin at the hip.
///
/// It keeps a [`Data`] workspace behind a mutex, as [`RigidBodyPlant`] does, so that a task can
/// evaluate it through `&self`.
#[derive(Debug)]
pub struct FootKinematics {
    model: Model,
    frame: usize,
    /// Thigh and shank lengths read from the model (for the closed-form inverse).
    lengths: [f64; 2],
    data: Mutex<Data>,
}

impl Clone for FootKinematics {
    fn clone(&self) -> Self {
        Self {
            model: self.model.clone(),
            frame: self.frame,
            lengths: self.lengths,
            data: Mutex::new(Data::new(&self.model)),
        }
    }
}

impl FootKinematics {
    /// The foot of a leg model (the URDF's `hip`, `knee` and `foot`); an error when the model
    /// lacks them.
    pub fn new(model: &Model) -> Result<Self, RigidPlantError> {
        let frame = model
            .frame_index(FOOT)
            .ok_or_else(|| RigidPlantError::UnknownLink(FOOT.into()))?;
        let knee = model
            .joint_index("knee")
            .ok_or_else(|| RigidPlantError::UnknownJoint("knee".into()))?;
        if model.nv() != 2 || model.joint_index("hip") != Some(0) || knee != 1 {
            return Err(RigidPlantError::Config(format!(
                "a 2R leg has the joints hip then knee, this model has {:?}",
                model.joint_names()
            )));
        }
        let lengths = [
            model.joints[knee].placement.trans.norm(),
            model.frames[frame].placement.trans.norm(),
        ];
        Ok(Self {
            model: model.clone(),
            frame,
            lengths,
            data: Mutex::new(Data::new(model)),
        })
    }

    /// Thigh and shank lengths (m).
    pub fn lengths(&self) -> [f64; 2] {
        self.lengths
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Data> {
        self.data.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Foot position `(x, z)` at joint angles `q`.
    pub fn position(&self, q: &[f64]) -> [f64; 2] {
        let mut d = self.lock();
        forward_kinematics(&self.model, &mut d, q);
        update_frame_placements(&self.model, &mut d);
        let p = d.o_m_f[self.frame].trans;
        [p.x, p.z]
    }

    /// The 2 × 2 foot Jacobian `∂(x, z)/∂q` (rows x, z) at `q`.
    pub fn jacobian(&self, q: &[f64]) -> [[f64; 2]; 2] {
        let mut d = self.lock();
        self.jacobian_locked(&mut d, q)
    }

    fn jacobian_locked(&self, d: &mut Data, q: &[f64]) -> [[f64; 2]; 2] {
        forward_kinematics(&self.model, d, q);
        frame_jacobian(&self.model, d, self.frame);
        let j = &d.jacobian;
        [[j[(0, 0)], j[(0, 1)]], [j[(2, 0)], j[(2, 1)]]]
    }

    /// Foot position and velocity `ṗ = J(q) q̇` at `(q, q̇)`.
    pub fn state(&self, q: &[f64], qdot: &[f64]) -> ([f64; 2], [f64; 2]) {
        let mut d = self.lock();
        let j = self.jacobian_locked(&mut d, q);
        update_frame_placements(&self.model, &mut d);
        let p = d.o_m_f[self.frame].trans;
        let v = j.map(|row| row[0] * qdot[0] + row[1] * qdot[1]);
        ([p.x, p.z], v)
    }

    /// The knee-forward configuration (`q_knee ≥ 0`) that puts the foot at `p`, in closed form;
    /// `None` when `p` is out of reach.
    pub fn inverse(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        let [l1, l2] = self.lengths;
        // With u = −x, w = −z: w + i u = e^{i q₁} (l₁ + l₂ e^{i q₂}).
        let (u, w) = (-p[0], -p[1]);
        let c2 = (u * u + w * w - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        // Rounding may push the straight or folded leg a hair past ±1.
        if !(-1.0 - 1e-12..=1.0 + 1e-12).contains(&c2) {
            return None;
        }
        let c2 = c2.clamp(-1.0, 1.0);
        let q2 = c2.acos();
        let q1 = u.atan2(w) - (l2 * q2.sin()).atan2(l1 + l2 * c2);
        Some([q1, q2])
    }

    /// The joint velocity `J(q)⁻¹ ṗ` that moves the foot with velocity `pdot` at `q`; `None` at a
    /// singular configuration (the knee straight or folded).
    pub fn joint_velocity(&self, q: &[f64], pdot: [f64; 2]) -> Option<[f64; 2]> {
        let [[a, b], [c, d]] = self.jacobian(q);
        let det = a * d - b * c;
        let [l1, l2] = self.lengths;
        if det.abs() < 1e-9 * l1 * l2 {
            return None;
        }
        Some([
            (d * pdot[0] - b * pdot[1]) / det,
            (a * pdot[1] - c * pdot[0]) / det,
        ])
    }
}
