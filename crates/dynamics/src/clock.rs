//! [`Clocked`]: any [`Plant`] with a phase clock appended to its state, for tasks that track a
//! periodic reference.
//!
//! A task whose reward depends on time (p3's leg tracks a foot trajectory of fixed period) must
//! read the time from the state, since a task is a function of states (it is shared by the real
//! environment and by a learned model's imagined one). The clock is stored as `(cos φ, sin φ)`
//! rather than as the angle `φ`: the pair is bounded and advances by a fixed rotation, a linear
//! map, so a learned dynamics model predicts it without the jump an angle makes when it wraps
//! from 2π to 0.
//!
//! ```
//! use nalgebra::dvector;
//! use tandem_dynamics::classic::GymPendulum;
//! use tandem_dynamics::{Clocked, Plant};
//!
//! // Gymnasium's pendulum (dt = 0.05 s) with a 1 s clock: 20 steps are one period.
//! let plant = Clocked::new(GymPendulum::default(), 1.0).unwrap();
//! assert_eq!(plant.state_dim(), 4);
//! let mut x = dvector![0.5, 0.0, 1.0, 0.0];
//! for _ in 0..5 {
//!     x = plant.step(&x, &dvector![0.0]);
//! }
//! // A quarter period later the clock reads φ = π/2.
//! assert!((Clocked::<GymPendulum>::phase(x.as_slice()) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
//! ```

use std::f64::consts::TAU;

use nalgebra::{DMatrix, DVector};

use crate::{Plant, PlantError};

/// A plant `P` whose state is extended by a clock `(cos φ, sin φ)` that turns by
/// `2π dt / period` every step: state `[x_P; cos φ; sin φ]`, the same action as `P`.
#[derive(Debug, Clone)]
pub struct Clocked<P> {
    plant: P,
    period: f64,
    /// `(cos, sin)` of the angle the clock turns in one step.
    turn: (f64, f64),
}

impl<P: Plant> Clocked<P> {
    /// `plant` with a clock of period `period` seconds; an error unless the period is positive
    /// and finite.
    pub fn new(plant: P, period: f64) -> Result<Self, PlantError> {
        if !(period.is_finite() && period > 0.0) {
            return Err(PlantError::InvalidParameter(format!(
                "the clock period must be positive and finite, got {period}"
            )));
        }
        let (s, c) = (TAU * plant.dt() / period).sin_cos();
        Ok(Self {
            plant,
            period,
            turn: (c, s),
        })
    }

    /// The plant under the clock.
    pub fn plant(&self) -> &P {
        &self.plant
    }

    /// The clock's period (s).
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The clock reading `(cos φ, sin φ)` at phase `φ` (rad): the last two state components.
    pub fn clock(phase: f64) -> [f64; 2] {
        let (s, c) = phase.sin_cos();
        [c, s]
    }

    /// The phase `φ ∈ [0, 2π)` of a state (its last two components, `(cos φ, sin φ)`; they need
    /// not be normalized).
    pub fn phase(x: &[f64]) -> f64 {
        let n = x.len();
        let phi = x[n - 1].atan2(x[n - 2]);
        match phi + TAU {
            // A tiny negative angle rounds to 2π: that is phase 0.
            wrapped if phi < 0.0 && wrapped < TAU => wrapped,
            _ if phi < 0.0 => 0.0,
            _ => phi,
        }
    }

    /// The state `[x_plant; clock(phase)]`.
    pub fn state(x_plant: &[f64], phase: f64) -> Vec<f64> {
        let mut x = x_plant.to_vec();
        x.extend_from_slice(&Self::clock(phase));
        x
    }
}

impl<P: Plant> Plant for Clocked<P> {
    fn state_dim(&self) -> usize {
        self.plant.state_dim() + 2
    }

    fn action_dim(&self) -> usize {
        self.plant.action_dim()
    }

    fn dt(&self) -> f64 {
        self.plant.dt()
    }

    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let mut y = DVector::zeros(x.len());
        self.step_into(x.as_slice(), u.as_slice(), y.as_mut_slice());
        y
    }

    fn step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        let n = self.plant.state_dim();
        self.plant.step_into(&x[..n], u, &mut next[..n]);
        let (c, s) = self.turn;
        let (cp, sp) = (x[n], x[n + 1]);
        next[n] = c * cp - s * sp;
        next[n + 1] = s * cp + c * sp;
    }

    /// The plant's Jacobians (analytical where the plant's are) with the clock's rotation block:
    /// `A = diag(A_P, R)`, `B = [B_P; 0]`.
    fn linearize(&self, x: &DVector<f64>, u: &DVector<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.plant.state_dim();
        let (ap, bp) = self.plant.linearize(&x.rows(0, n).into_owned(), u);
        let mut a = DMatrix::zeros(n + 2, n + 2);
        a.view_mut((0, 0), (n, n)).copy_from(&ap);
        let (c, s) = self.turn;
        a[(n, n)] = c;
        a[(n, n + 1)] = -s;
        a[(n + 1, n)] = s;
        a[(n + 1, n + 1)] = c;
        let mut b = DMatrix::zeros(n + 2, bp.ncols());
        b.view_mut((0, 0), (n, bp.ncols())).copy_from(&bp);
        (a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classic::GymPendulum;
    use crate::linearize_fd;
    use nalgebra::dvector;

    #[test]
    fn the_clock_completes_a_period_and_leaves_the_plant_alone() {
        let p = GymPendulum::default();
        let c = Clocked::new(p, 0.5).unwrap();
        // dt = 0.05 s: 10 steps are one period.
        let mut x = dvector![0.3, -0.2, 1.0, 0.0];
        let mut y = dvector![0.3, -0.2];
        for k in 1..=10 {
            x = c.step(&x, &dvector![1.0]);
            y = p.step(&y, &dvector![1.0]);
            let phase = Clocked::<GymPendulum>::phase(x.as_slice());
            let expected = (TAU * k as f64 / 10.0) % TAU;
            let d = (phase - expected).abs();
            assert!(d.min(TAU - d) < 1e-12, "step {k}: {phase} vs {expected}");
            assert_eq!(x.rows(0, 2), y);
        }
        assert!((x[2] - 1.0).abs() < 1e-13 && x[3].abs() < 1e-13);
    }

    #[test]
    fn phase_lies_in_zero_two_pi_and_inverts_clock() {
        for phi in [0.0, 0.1, 3.0, 3.5, 6.2] {
            let x = Clocked::<GymPendulum>::state(&[7.0], phi);
            assert_eq!(x.len(), 3);
            assert!((Clocked::<GymPendulum>::phase(&x) - phi).abs() < 1e-12);
        }
        // Unnormalized clocks read the same phase.
        assert!(
            (Clocked::<GymPendulum>::phase(&[0.0, -2.0]) - 1.5 * std::f64::consts::PI).abs()
                < 1e-12
        );
    }

    #[test]
    fn linearize_matches_finite_differences() {
        let c = Clocked::new(GymPendulum::default(), 0.7).unwrap();
        let x = dvector![0.4, 1.1, 0.6, 0.8];
        let u = dvector![0.5];
        let (a, b) = c.linearize(&x, &u);
        let (fa, fb) = linearize_fd(&c, &x, &u);
        assert!((a - fa).abs().max() < 1e-7);
        assert!((b - fb).abs().max() < 1e-7);
    }

    #[test]
    fn a_bad_period_is_an_error() {
        for p in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = Clocked::new(GymPendulum::default(), p).err().unwrap();
            assert!(e.to_string().contains("period"), "{e}");
        }
    }
}
