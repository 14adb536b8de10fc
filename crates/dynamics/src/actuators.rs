//! Actuators and joint friction for rigid-body plants.
//!
//! - [`DcMotor`]: voltage in, torque out through a gearbox,
//!   `τ = G K (U − K G q̇) / R` (paper p0, Leo's motors; the back-EMF term is a velocity damping
//!   `G² K² / R`).
//! - [`JointFriction`]: viscous `b q̇` and Coulomb `c · tanh(q̇ / v_s)` (regularized so the
//!   dynamics stay smooth for fixed-step integration).
//! - [`PdController`]: `τ = kp (q* − q) − kd q̇` for joints that are not learned (Leo's shoulder).
//!
//! Each actuator clips its torque to its limit.

use serde::{Deserialize, Serialize};

/// A geared DC motor driven by a voltage.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DcMotor {
    /// Gear ratio `G` (joint turns per motor turn, inverted).
    pub gear: f64,
    /// Torque constant `K` (N m / A = V s / rad).
    pub torque_constant: f64,
    /// Winding resistance `R` (Ω).
    pub resistance: f64,
    /// Voltage limit `|U| ≤ voltage_max` (V).
    pub voltage_max: f64,
    /// Joint torque limit (N m); `inf` for none.
    pub torque_max: f64,
    /// Rotor inertia reflected through the gearbox, `G² J_rotor` (kg m²): the joint's armature.
    pub armature: f64,
}

impl Default for DcMotor {
    /// A Dynamixel RX-28-like servo as on Leo (p0 names the motor law, not the constants; these
    /// are approximate datasheet-level values): `G = 193`, `K = 0.0093 N m/A`, `R = 8.6 Ω`,
    /// `|U| ≤ 10.7 V`, rotor inertia `1.06e-6 kg m²`.
    fn default() -> Self {
        Self {
            gear: 193.0,
            torque_constant: 0.0093,
            resistance: 8.6,
            voltage_max: 10.7,
            torque_max: f64::INFINITY,
            armature: 193.0 * 193.0 * 1.06e-6,
        }
    }
}

impl DcMotor {
    /// Joint torque for voltage `u` (clipped to `±voltage_max`) at joint velocity `qdot`.
    #[inline]
    pub fn torque(&self, u: f64, qdot: f64) -> f64 {
        let u = u.clamp(-self.voltage_max, self.voltage_max);
        let k = self.torque_constant;
        let g = self.gear;
        let tau = g * k * (u - k * g * qdot) / self.resistance;
        tau.clamp(-self.torque_max, self.torque_max)
    }

    /// Voltage that produces torque `tau` at velocity `qdot` (inverse of [`DcMotor::torque`]
    /// before clipping): what a torque-level controller sends.
    #[inline]
    pub fn voltage_for(&self, tau: f64, qdot: f64) -> f64 {
        let k = self.torque_constant;
        let g = self.gear;
        tau * self.resistance / (g * k) + k * g * qdot
    }

    /// Joule heating `I² R` of the winding, with `I = (U − K G q̇) / R`.
    #[inline]
    pub fn joule_power(&self, u: f64, qdot: f64) -> f64 {
        let u = u.clamp(-self.voltage_max, self.voltage_max);
        let i = (u - self.torque_constant * self.gear * qdot) / self.resistance;
        i * i * self.resistance
    }
}

/// Viscous and (regularized) Coulomb friction of a joint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointFriction {
    /// Viscous coefficient `b` (N m s/rad).
    pub viscous: f64,
    /// Coulomb friction torque `c` (N m).
    pub coulomb: f64,
    /// Regularization velocity `v_s` of `tanh(q̇ / v_s)` (rad/s).
    pub stiction_velocity: f64,
}

impl Default for JointFriction {
    /// No friction (the idealized Leo of p0, Table I); `v_s = 0.01` rad/s.
    fn default() -> Self {
        Self {
            viscous: 0.0,
            coulomb: 0.0,
            stiction_velocity: 0.01,
        }
    }
}

impl JointFriction {
    /// Friction torque (opposing the motion) at velocity `qdot`.
    #[inline]
    pub fn torque(&self, qdot: f64) -> f64 {
        let coulomb = if self.coulomb != 0.0 {
            self.coulomb * (qdot / self.stiction_velocity.max(1e-12)).tanh()
        } else {
            0.0
        };
        -self.viscous * qdot - coulomb
    }
}

/// A proportional-derivative joint controller.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PdController {
    /// Position gain (N m/rad).
    pub kp: f64,
    /// Velocity gain (N m s/rad).
    pub kd: f64,
    /// Target position (rad).
    pub target: f64,
    /// Torque limit (N m).
    pub torque_max: f64,
}

impl PdController {
    /// `kp (target − q) − kd q̇`, clipped.
    #[inline]
    pub fn torque(&self, q: f64, qdot: f64) -> f64 {
        (self.kp * (self.target - q) - self.kd * qdot).clamp(-self.torque_max, self.torque_max)
    }
}

/// What drives a joint of a [`crate::rigid_plant::RigidBodyPlant`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Actuator {
    /// A DC motor; its action component is a voltage.
    Motor(DcMotor),
    /// An ideal torque source; its action component is a torque, clipped to `±limit`.
    Torque {
        /// Torque limit (N m or N).
        limit: f64,
    },
    /// A PD controller that is not part of the action.
    Pd(PdController),
}

impl Actuator {
    /// Whether this actuator takes a component of the action vector.
    pub fn is_learned(&self) -> bool {
        !matches!(self, Actuator::Pd(_))
    }

    /// Joint torque for action component `u` (ignored by PD) at joint state `(q, q̇)`.
    #[inline]
    pub fn torque(&self, u: f64, q: f64, qdot: f64) -> f64 {
        match self {
            Actuator::Motor(m) => m.torque(u, qdot),
            Actuator::Torque { limit } => u.clamp(-limit, *limit),
            Actuator::Pd(pd) => pd.torque(q, qdot),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dc_motor_matches_its_equation_and_limits() {
        let m = DcMotor::default();
        let (g, k, r) = (193.0, 0.0093, 8.6);
        let t = m.torque(5.0, 0.7);
        assert!((t - g * k * (5.0 - k * g * 0.7) / r).abs() < 1e-12);
        // Stall torque at the voltage limit; voltage beyond it is clipped.
        assert_eq!(m.torque(100.0, 0.0), m.torque(10.7, 0.0));
        // Back-EMF: zero torque at the no-load speed U / (K G).
        assert!(m.torque(6.0, 6.0 / (k * g)).abs() < 1e-12);
        assert!((m.torque(m.voltage_for(0.4, 1.3), 1.3) - 0.4).abs() < 1e-12);
        let lim = DcMotor {
            torque_max: 0.5,
            ..m
        };
        assert_eq!(lim.torque(10.0, 0.0), 0.5);
    }

    #[test]
    fn friction_opposes_motion_and_saturates() {
        let f = JointFriction {
            viscous: 0.03,
            coulomb: 0.1,
            stiction_velocity: 0.01,
        };
        assert!(f.torque(1.0) < 0.0 && f.torque(-1.0) > 0.0);
        assert_eq!(f.torque(0.0), 0.0);
        assert!((f.torque(2.0) - (-0.06 - 0.1)).abs() < 1e-9);
    }

    #[test]
    fn pd_drives_towards_target_within_limit() {
        let pd = PdController {
            kp: 10.0,
            kd: 1.0,
            target: 0.5,
            torque_max: 2.0,
        };
        assert!((pd.torque(0.4, 0.0) - 1.0).abs() < 1e-12);
        assert_eq!(pd.torque(-3.0, 0.0), 2.0);
        assert!(pd.torque(0.5, 1.0) < 0.0);
    }
}
