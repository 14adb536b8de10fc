//! The [`Plant`] trait.

use nalgebra::{DMatrix, DVector};

/// Errors of plants: bad inputs at a checked boundary, or bad parameters at construction.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlantError {
    /// A state or action vector of the wrong length.
    #[error("{what} has {got} components, the plant expects {expected}")]
    WrongDim {
        /// `"state"` or `"action"`.
        what: &'static str,
        /// The plant's dimension.
        expected: usize,
        /// The length that was given.
        got: usize,
    },
    /// A NaN or infinite component.
    #[error("{what} component {index} is not finite ({value})")]
    NonFinite {
        /// `"state"` or `"action"`.
        what: &'static str,
        /// Index of the offending component.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A plant parameter out of its range (e.g. a clock period that is not positive).
    #[error("invalid plant parameter: {0}")]
    InvalidParameter(String),
}

/// A known physical model in discrete time: `x_{t+1} = step(x_t, u_t)` every [`Plant::dt`]
/// seconds.
///
/// `step` is the hot path and takes its inputs as given: callers at a user-facing boundary
/// validate once with [`check_dims`]. Implementations are pure (no hidden state), so one plant can
/// be shared by many rollouts.
///
/// ```
/// use nalgebra::{dvector, DVector};
/// use tandem_dynamics::Plant;
///
/// /// A double integrator: position and velocity, force input.
/// struct DoubleIntegrator;
///
/// impl Plant for DoubleIntegrator {
///     fn state_dim(&self) -> usize { 2 }
///     fn action_dim(&self) -> usize { 1 }
///     fn dt(&self) -> f64 { 0.1 }
///     fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
///         let dt = self.dt();
///         dvector![x[0] + dt * x[1] + 0.5 * dt * dt * u[0], x[1] + dt * u[0]]
///     }
/// }
///
/// let (a, b) = DoubleIntegrator.linearize(&dvector![0.0, 0.0], &dvector![0.0]);
/// assert!((a[(0, 1)] - 0.1).abs() < 1e-9);
/// assert!((b[(0, 0)] - 0.005).abs() < 1e-9);
/// ```
pub trait Plant {
    /// Length of the state vector.
    fn state_dim(&self) -> usize;

    /// Length of the action vector.
    fn action_dim(&self) -> usize;

    /// Control period in seconds: the time one [`Plant::step`] advances.
    fn dt(&self) -> f64;

    /// The state after applying action `u` for one control period from state `x`.
    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64>;

    /// [`Plant::step`] on slices, writing the next state into `next` (length
    /// [`Plant::state_dim`]). The default copies through [`Plant::step`]; small plants override
    /// it with an allocation-free path, which environments use on every step.
    fn step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        let y = self.step(
            &DVector::from_column_slice(x),
            &DVector::from_column_slice(u),
        );
        next.copy_from_slice(y.as_slice());
    }

    /// Jacobians `(A, B) = (∂step/∂x, ∂step/∂u)` at `(x, u)`.
    ///
    /// The default uses central differences with a step scaled to each component's magnitude
    /// (`h = 1e-6 · max(1, |z_i|)`), accurate to about 1e-8 for smooth dynamics. Plants with
    /// analytical derivatives override it.
    fn linearize(&self, x: &DVector<f64>, u: &DVector<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        linearize_fd(self, x, u)
    }
}

/// Central-difference Jacobians `(∂step/∂x, ∂step/∂u)` of any plant, with a step scaled to each
/// component's magnitude (`h = 1e-6 · max(1, |z_i|)`): the default [`Plant::linearize`], and the
/// test oracle of plants that override it with analytical derivatives.
pub fn linearize_fd<P: Plant + ?Sized>(
    plant: &P,
    x: &DVector<f64>,
    u: &DVector<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (plant.state_dim(), plant.action_dim());
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, m);
    let mut xp = x.clone();
    for i in 0..n {
        let h = 1e-6 * x[i].abs().max(1.0);
        xp[i] = x[i] + h;
        let fp = plant.step(&xp, u);
        xp[i] = x[i] - h;
        let fm = plant.step(&xp, u);
        xp[i] = x[i];
        a.set_column(i, &((fp - fm) / (2.0 * h)));
    }
    let mut up = u.clone();
    for j in 0..m {
        let h = 1e-6 * u[j].abs().max(1.0);
        up[j] = u[j] + h;
        let fp = plant.step(x, &up);
        up[j] = u[j] - h;
        let fm = plant.step(x, &up);
        up[j] = u[j];
        b.set_column(j, &((fp - fm) / (2.0 * h)));
    }
    (a, b)
}

/// Checks that `x` and `u` have the plant's dimensions and are finite.
pub fn check_dims<P: Plant + ?Sized>(plant: &P, x: &[f64], u: &[f64]) -> Result<(), PlantError> {
    for (what, v, expected) in [
        ("state", x, plant.state_dim()),
        ("action", u, plant.action_dim()),
    ] {
        if v.len() != expected {
            return Err(PlantError::WrongDim {
                what,
                expected,
                got: v.len(),
            });
        }
        if let Some((index, &value)) = v.iter().enumerate().find(|(_, z)| !z.is_finite()) {
            return Err(PlantError::NonFinite { what, index, value });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dvector;

    /// Discretized linear system with known matrices.
    struct Linear(DMatrix<f64>, DMatrix<f64>);
    impl Plant for Linear {
        fn state_dim(&self) -> usize {
            self.0.nrows()
        }
        fn action_dim(&self) -> usize {
            self.1.ncols()
        }
        fn dt(&self) -> f64 {
            0.1
        }
        fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
            &self.0 * x + &self.1 * u
        }
    }

    #[test]
    fn finite_difference_linearization_recovers_linear_system() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.1, -0.3, 0.9]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 0.7]);
        let p = Linear(a.clone(), b.clone());
        let (fa, fb) = p.linearize(&dvector![3.0, -20.0], &dvector![100.0]);
        assert!((fa - a).abs().max() < 1e-7);
        assert!((fb - b).abs().max() < 1e-7);
    }

    #[test]
    fn check_dims_names_the_problem() {
        let p = Linear(DMatrix::identity(2, 2), DMatrix::zeros(2, 1));
        assert!(check_dims(&p, &[0.0, 0.0], &[1.0]).is_ok());
        assert_eq!(
            check_dims(&p, &[0.0], &[1.0]),
            Err(PlantError::WrongDim {
                what: "state",
                expected: 2,
                got: 1
            })
        );
        assert!(matches!(
            check_dims(&p, &[0.0, 0.0], &[f64::INFINITY]),
            Err(PlantError::NonFinite { what: "action", .. })
        ));
    }
}
