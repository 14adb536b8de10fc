//! Gymnasium's `Pendulum-v1` dynamics.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use crate::Plant;

/// Constants of gymnasium 1.x `PendulumEnv`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GymPendulumParams {
    /// Gravitational acceleration (10.0, gymnasium's default `g`).
    pub g: f64,
    /// Mass (1.0).
    pub m: f64,
    /// Length (1.0).
    pub l: f64,
    /// Control period, s (0.05).
    pub dt: f64,
    /// Torque bound: the input is clipped to `±max_torque` (2.0).
    pub max_torque: f64,
    /// Speed bound: the new angular velocity is clipped to `±max_speed` (8.0).
    pub max_speed: f64,
}

impl Default for GymPendulumParams {
    fn default() -> Self {
        Self {
            g: 10.0,
            m: 1.0,
            l: 1.0,
            dt: 0.05,
            max_torque: 2.0,
            max_speed: 8.0,
        }
    }
}

/// The pendulum of gymnasium's `Pendulum-v1`: state `(θ, θ̇)` with θ = 0 upright (θ is not
/// wrapped), action `(u)`, a torque clipped to `±max_torque`.
///
/// One step is gymnasium's semi-implicit Euler update, in gymnasium's operation order:
///
/// ```text
/// θ̇' = clip(θ̇ + (3g/(2l) sin θ + 3/(m l²) u) dt, ±max_speed)
/// θ'  = θ + θ̇' dt
/// ```
///
/// ```
/// use tandem_dynamics::classic::GymPendulum;
/// let p = GymPendulum::default();
/// // Torque beyond the bound is clipped: 5 acts like 2.
/// assert_eq!(p.step_array(&[0.3, 0.0], 5.0), p.step_array(&[0.3, 0.0], 2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GymPendulum {
    params: GymPendulumParams,
}

impl GymPendulum {
    /// A pendulum with the given constants.
    pub fn new(params: GymPendulumParams) -> Self {
        Self { params }
    }

    /// Its constants.
    pub fn params(&self) -> &GymPendulumParams {
        &self.params
    }

    /// One step from `s = (θ, θ̇)` under torque `u` (clipped to `±max_torque`).
    #[inline]
    pub fn step_array(&self, s: &[f64; 2], u: f64) -> [f64; 2] {
        let p = &self.params;
        let u = u.clamp(-p.max_torque, p.max_torque);
        let [th, thdot] = *s;
        let newthdot =
            thdot + (3.0 * p.g / (2.0 * p.l) * th.sin() + 3.0 / (p.m * p.l.powi(2)) * u) * p.dt;
        let newthdot = newthdot.clamp(-p.max_speed, p.max_speed);
        [th + newthdot * p.dt, newthdot]
    }
}

impl Plant for GymPendulum {
    fn state_dim(&self) -> usize {
        2
    }

    fn action_dim(&self) -> usize {
        1
    }

    fn dt(&self) -> f64 {
        self.params.dt
    }

    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let s = self.step_array(&[x[0], x[1]], u[0]);
        DVector::from_row_slice(&s)
    }

    fn step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_array(&[x[0], x[1]], u[0]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_is_clipped_and_angle_uses_the_new_speed() {
        let p = GymPendulum::default();
        let s = p.step_array(&[0.0, 7.99], 2.0);
        assert_eq!(s[1], 8.0);
        assert_eq!(s[0], 8.0 * 0.05);
        let s = p.step_array(&[0.0, -7.99], -2.0);
        assert_eq!(s, [-0.4, -8.0]);
    }

    #[test]
    fn hanging_pendulum_oscillates_with_the_small_angle_period() {
        // θ = π + ε: ε̈ = -(3g/2l) ε, period 2π / sqrt(15). Semi-implicit Euler keeps the
        // oscillation bounded; its frequency error is O(dt²).
        let p = GymPendulum::default();
        let mut s = [std::f64::consts::PI + 0.01, 0.0];
        let mut crossings = Vec::new();
        let mut prev = s[0] - std::f64::consts::PI;
        for k in 1..=2000 {
            s = p.step_array(&s, 0.0);
            let e = s[0] - std::f64::consts::PI;
            if prev > 0.0 && e <= 0.0 {
                // Linear interpolation of the crossing time.
                crossings.push((k as f64 - 1.0 + prev / (prev - e)) * 0.05);
            }
            prev = e;
        }
        let period = (crossings.last().unwrap() - crossings[0]) / (crossings.len() - 1) as f64;
        let exact = 2.0 * std::f64::consts::PI / 15f64.sqrt();
        assert!((period - exact).abs() / exact < 0.01, "{period} vs {exact}");
    }
}
