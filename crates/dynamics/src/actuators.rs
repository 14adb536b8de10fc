//! Actuators and joint friction for rigid-body plants.
//!
//! - [`DcMotor`]: voltage in, torque out through a gearbox,
//!   `τ = G K (U − K G q̇) / R` (paper p0, Leo's motors; the back-EMF term is a velocity damping
//!   `G² K² / R`).
//! - [`JointFriction`]: viscous `b q̇` and Coulomb `c · tanh(q̇ / v_s)` (regularized so the
//!   dynamics stay smooth for fixed-step integration).
//! - [`PdController`]: `τ = kp (q* − q) − kd q̇` for joints that are not learned (Leo's shoulder).
//! - [`TorqueMotor`]: a torque-controlled motor (a BLDC behind a current loop, p3's leg): the
//!   commanded torque, within the peak torque and the back-EMF envelope of its supply voltage.
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

    /// [`DcMotor::torque`] and its partial derivatives `(τ, ∂τ/∂U, ∂τ/∂q̇)`: `G K / R` and
    /// `−G² K² / R` inside the limits, zero where the voltage or the torque is clipped (the
    /// one-sided derivative of the clipped branch).
    #[inline]
    pub fn torque_partials(&self, u: f64, qdot: f64) -> (f64, f64, f64) {
        let uc = u.clamp(-self.voltage_max, self.voltage_max);
        let k = self.torque_constant;
        let g = self.gear;
        let tau = g * k * (uc - k * g * qdot) / self.resistance;
        if tau.abs() > self.torque_max {
            return (tau.clamp(-self.torque_max, self.torque_max), 0.0, 0.0);
        }
        let du = if u.abs() < self.voltage_max {
            g * k / self.resistance
        } else {
            0.0
        };
        (tau, du, -g * k * k * g / self.resistance)
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

    /// `∂τ/∂q̇` of [`JointFriction::torque`]: `−b − (c / v_s) (1 − tanh²(q̇ / v_s))`.
    #[inline]
    pub fn torque_derivative(&self, qdot: f64) -> f64 {
        let coulomb = if self.coulomb != 0.0 {
            let vs = self.stiction_velocity.max(1e-12);
            let t = (qdot / vs).tanh();
            self.coulomb / vs * (1.0 - t * t)
        } else {
            0.0
        };
        -self.viscous - coulomb
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

    /// [`PdController::torque`] and `(∂τ/∂q, ∂τ/∂q̇)`: `(−kp, −kd)`, zero where clipped.
    #[inline]
    pub fn torque_partials(&self, q: f64, qdot: f64) -> (f64, f64, f64) {
        let tau = self.kp * (self.target - q) - self.kd * qdot;
        if tau.abs() > self.torque_max {
            (tau.clamp(-self.torque_max, self.torque_max), 0.0, 0.0)
        } else {
            (tau, -self.kp, -self.kd)
        }
    }
}

/// A torque-controlled motor: a current loop (p3's leg: 40 kHz) makes the commanded torque,
/// clipped to `±peak_torque` and to what the supply voltage can drive against the back-EMF,
/// `−τ_p (1 + q̇/ω₀) ≤ τ ≤ τ_p (1 − q̇/ω₀)` with `ω₀` the no-load speed: full torque at rest, none
/// left in the direction of motion at `ω₀`, so the joint cannot run away past it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TorqueMotor {
    /// Peak joint torque `τ_p` (N m).
    pub peak_torque: f64,
    /// No-load joint speed `ω₀` (rad/s).
    pub no_load_speed: f64,
}

impl TorqueMotor {
    /// The torque range `(low, high)` available at joint velocity `qdot`.
    #[inline]
    pub fn bounds(&self, qdot: f64) -> (f64, f64) {
        let (tp, w) = (self.peak_torque, self.no_load_speed);
        (
            (-tp * (1.0 + qdot / w)).max(-tp),
            (tp * (1.0 - qdot / w)).min(tp),
        )
    }

    /// The torque for command `u` at `qdot`: `u` clipped into [`TorqueMotor::bounds`].
    #[inline]
    pub fn torque(&self, u: f64, qdot: f64) -> f64 {
        let (lo, hi) = self.bounds(qdot);
        u.max(lo).min(hi)
    }

    /// [`TorqueMotor::torque`] and its partials `(τ, ∂τ/∂u, ∂τ/∂q̇)`: `(u, 1, 0)` inside the
    /// range, `(bound, 0, ∓τ_p/ω₀)` on a back-EMF bound, `(±τ_p, 0, 0)` on the peak.
    #[inline]
    pub fn torque_partials(&self, u: f64, qdot: f64) -> (f64, f64, f64) {
        let (tp, w) = (self.peak_torque, self.no_load_speed);
        let (lo, hi) = self.bounds(qdot);
        if u > hi {
            let slope = if tp * (1.0 - qdot / w) < tp {
                -tp / w
            } else {
                0.0
            };
            (hi, 0.0, slope)
        } else if u < lo {
            let slope = if -tp * (1.0 + qdot / w) > -tp {
                -tp / w
            } else {
                0.0
            };
            (lo, 0.0, slope)
        } else {
            (u, 1.0, 0.0)
        }
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
    /// A torque-controlled motor; its action component is the commanded torque.
    TorqueMotor(TorqueMotor),
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
            Actuator::TorqueMotor(m) => m.torque(u, qdot),
        }
    }

    /// [`Actuator::torque`] and its partial derivatives `(τ, ∂τ/∂u, ∂τ/∂q, ∂τ/∂q̇)`; a clipped
    /// input or output has zero derivative (the clipped branch's).
    #[inline]
    pub fn torque_partials(&self, u: f64, q: f64, qdot: f64) -> (f64, f64, f64, f64) {
        match self {
            Actuator::Motor(m) => {
                let (t, du, dv) = m.torque_partials(u, qdot);
                (t, du, 0.0, dv)
            }
            Actuator::Torque { limit } => {
                let du = if u.abs() < *limit { 1.0 } else { 0.0 };
                (u.clamp(-limit, *limit), du, 0.0, 0.0)
            }
            Actuator::Pd(pd) => {
                let (t, dq, dv) = pd.torque_partials(q, qdot);
                (t, 0.0, dq, dv)
            }
            Actuator::TorqueMotor(m) => {
                let (t, du, dv) = m.torque_partials(u, qdot);
                (t, du, 0.0, dv)
            }
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

    /// Central difference of `f` at `z`.
    fn fd(f: impl Fn(f64) -> f64, z: f64) -> f64 {
        let h = 1e-6 * z.abs().max(1.0);
        (f(z + h) - f(z - h)) / (2.0 * h)
    }

    #[test]
    fn partials_match_finite_differences_and_vanish_when_clipped() {
        let motor = Actuator::Motor(DcMotor {
            torque_max: 1.0,
            ..DcMotor::default()
        });
        let pd = Actuator::Pd(PdController {
            kp: 10.0,
            kd: 0.5,
            target: 0.2,
            torque_max: 3.0,
        });
        let src = Actuator::Torque { limit: 2.0 };
        let bldc = Actuator::TorqueMotor(TorqueMotor {
            peak_torque: 3.0,
            no_load_speed: 40.0,
        });
        // (actuator, u, q, q̇): inside the limits, then voltage-, torque- and output-clipped.
        let cases = [
            (motor, 3.0, 0.1, 0.4, true),
            (motor, 12.0, 0.1, 0.4, false),
            (motor, 9.0, 0.1, -3.0, false),
            (pd, 0.0, 0.1, 0.7, true),
            (pd, 0.0, -1.0, 0.0, false),
            (src, 1.5, 0.0, 0.0, true),
            (src, -2.5, 0.0, 0.0, false),
            (bldc, 1.0, 0.0, 10.0, true),
            // On the back-EMF bound, in and against the direction of motion, beyond ω₀ (the
            // motor brakes), then on the peak.
            (bldc, 2.9, 0.0, 10.0, false),
            (bldc, -2.9, 0.0, -10.0, false),
            (bldc, 0.5, 0.0, 50.0, false),
            (bldc, -3.5, 0.0, 10.0, false),
        ];
        for (a, u, q, v, inside) in cases {
            let (t, du, dq, dv) = a.torque_partials(u, q, v);
            assert_eq!(t, a.torque(u, q, v));
            let fu = fd(|z| a.torque(z, q, v), u);
            let fq = fd(|z| a.torque(u, z, v), q);
            let fv = fd(|z| a.torque(u, q, z), v);
            for (an, num) in [(du, fu), (dq, fq), (dv, fv)] {
                assert!(
                    (an - num).abs() < 1e-6 * an.abs().max(1.0),
                    "{a:?}: {an} vs {num}"
                );
            }
            assert_eq!(inside, du != 0.0 || dq != 0.0, "{a:?} at u = {u}");
        }
        let f = JointFriction {
            viscous: 0.03,
            coulomb: 0.1,
            stiction_velocity: 0.01,
        };
        for v in [-0.5, -0.004, 0.0, 0.003, 0.02, 1.0] {
            let num = fd(|z| f.torque(z), v);
            let an = f.torque_derivative(v);
            assert!(
                (an - num).abs() < 1e-6 * an.abs().max(1.0),
                "{v}: {an} vs {num}"
            );
        }
    }

    #[test]
    fn torque_motor_follows_the_command_inside_its_envelope() {
        let m = TorqueMotor {
            peak_torque: 3.0,
            no_load_speed: 40.0,
        };
        assert_eq!(m.torque(1.2, 0.0), 1.2);
        assert_eq!(m.torque(5.0, 0.0), 3.0);
        // At 10 rad/s a quarter of the peak is lost in the direction of motion, none against it.
        assert_eq!(m.bounds(10.0), (-3.0, 2.25));
        assert_eq!(m.bounds(-10.0), (-2.25, 3.0));
        assert_eq!(m.torque(3.0, 10.0), 2.25);
        // At the no-load speed no driving torque is left; beyond it the motor brakes.
        assert_eq!(m.torque(3.0, 40.0), 0.0);
        assert_eq!(m.torque(3.0, 60.0), -1.5);
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
