//! Cart-pole with gymnasium's `CartPole-v1` physics.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use crate::Plant;

/// Physical constants of the cart-pole (gymnasium 1.x `CartPoleEnv.__init__`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CartPoleParams {
    /// Gravitational acceleration, m/s² (9.8).
    pub gravity: f64,
    /// Cart mass, kg (1.0).
    pub masscart: f64,
    /// Pole mass, kg (0.1).
    pub masspole: f64,
    /// HALF the pole length, m (0.5).
    pub length: f64,
    /// Control period, s (0.02).
    pub tau: f64,
}

impl Default for CartPoleParams {
    fn default() -> Self {
        Self {
            gravity: 9.8,
            masscart: 1.0,
            masspole: 0.1,
            length: 0.5,
            tau: 0.02,
        }
    }
}

/// The cart-pole of gymnasium's `CartPole-v1`: state `(x, ẋ, θ, θ̇)`, action `(F)`, the horizontal
/// force on the cart in newtons (the environment maps its discrete action to `±force_mag`).
///
/// One step is gymnasium's explicit Euler update with the `"euler"` kinematics integrator, with the
/// operations in gymnasium's order so that results agree bit for bit:
///
/// ```text
/// temp   = (F + m_p l θ̇² sin θ) / (m_c + m_p)
/// θ̈      = (g sin θ − cos θ · temp) / (l (4/3 − m_p cos²θ / (m_c + m_p)))
/// ẍ      = temp − m_p l θ̈ cos θ / (m_c + m_p)
/// x += τ ẋ;  ẋ += τ ẍ;  θ += τ θ̇;  θ̇ += τ θ̈
/// ```
///
/// ```
/// use tandem_dynamics::classic::CartPole;
/// let cp = CartPole::default();
/// let next = cp.step_array(&[0.0, 0.0, 0.0, 0.0], 10.0);
/// assert_eq!(next[0], 0.0); // position integrates the old velocity
/// assert!(next[1] > 0.0 && next[3] < 0.0); // pushed right, the pole tips left
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CartPole {
    params: CartPoleParams,
}

impl CartPole {
    /// A cart-pole with the given constants.
    pub fn new(params: CartPoleParams) -> Self {
        Self { params }
    }

    /// Its constants.
    pub fn params(&self) -> &CartPoleParams {
        &self.params
    }

    /// One Euler step from `s = (x, ẋ, θ, θ̇)` under force `force` (N).
    #[inline]
    pub fn step_array(&self, s: &[f64; 4], force: f64) -> [f64; 4] {
        let p = &self.params;
        let total_mass = p.masspole + p.masscart;
        let polemass_length = p.masspole * p.length;
        let [x, x_dot, theta, theta_dot] = *s;
        let costheta = theta.cos();
        let sintheta = theta.sin();
        let temp = (force + polemass_length * theta_dot.powi(2) * sintheta) / total_mass;
        let thetaacc = (p.gravity * sintheta - costheta * temp)
            / (p.length * (4.0 / 3.0 - p.masspole * costheta.powi(2) / total_mass));
        let xacc = temp - polemass_length * thetaacc * costheta / total_mass;
        [
            x + p.tau * x_dot,
            x_dot + p.tau * xacc,
            theta + p.tau * theta_dot,
            theta_dot + p.tau * thetaacc,
        ]
    }
}

impl Plant for CartPole {
    fn state_dim(&self) -> usize {
        4
    }

    fn action_dim(&self) -> usize {
        1
    }

    fn dt(&self) -> f64 {
        self.params.tau
    }

    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let s = self.step_array(&[x[0], x[1], x[2], x[3]], u[0]);
        DVector::from_row_slice(&s)
    }

    fn step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next.copy_from_slice(&self.step_array(&[x[0], x[1], x[2], x[3]], u[0]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upright_pole_at_rest_stays_and_cart_accelerates_as_a_rigid_body_when_theta_is_zero() {
        // With θ = θ̇ = 0: θ̈ = -temp / (l (4/3 - m_p/M)), ẍ = temp - m_p l θ̈ / M, temp = F/M.
        let cp = CartPole::default();
        let f = 10.0;
        let m = 1.1;
        let temp = f / m;
        let thetaacc = -temp / (0.5 * (4.0 / 3.0 - 0.1 / m));
        let xacc = temp - 0.05 * thetaacc / m;
        let s = cp.step_array(&[0.0; 4], f);
        assert!((s[1] - 0.02 * xacc).abs() < 1e-15);
        assert!((s[3] - 0.02 * thetaacc).abs() < 1e-15);
        assert_eq!(cp.step_array(&[0.0; 4], 0.0), [0.0; 4]);
    }

    #[test]
    fn small_angles_fall_with_the_linearized_rate() {
        // Linearized, force-free: θ̈ = g θ / (l (4/3 - m_p/M)).
        let cp = CartPole::default();
        let th = 1e-6;
        let s = cp.step_array(&[0.0, 0.0, th, 0.0], 0.0);
        let rate = 9.8 / (0.5 * (4.0 / 3.0 - 0.1 / 1.1));
        assert!((s[3] / 0.02 - rate * th).abs() < 1e-15);
    }
}
