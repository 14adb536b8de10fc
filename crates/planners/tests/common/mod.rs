//! Shared test fixtures: a linear model, a pendulum model, and the Riccati truth.
#![allow(dead_code)]

pub mod reacher;

use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_core::Rng;
use tandem_models::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use tandem_planners::Objective;

/// `x' = A x + B u`, batched.
#[derive(Clone)]
pub struct LinearModel {
    pub a: DMatrix<f64>,
    pub b: DMatrix<f64>,
}

impl LinearModel {
    /// A discretized double integrator (dt = 0.1).
    pub fn double_integrator() -> Self {
        let dt = 0.1;
        Self {
            a: DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0]),
            b: DMatrix::from_row_slice(2, 1, &[0.5 * dt * dt, dt]),
        }
    }
    pub fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        &self.a * x + &self.b * u
    }
}

impl DynamicsModel for LinearModel {
    fn state_dim(&self) -> usize {
        self.a.nrows()
    }
    fn action_dim(&self) -> usize {
        self.b.ncols()
    }
    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let n = input.states.nrows();
        let mut out = Array2::zeros((n, self.state_dim()));
        for i in 0..n {
            let x = DVector::from_iterator(self.state_dim(), input.states.row(i).iter().copied());
            let u = DVector::from_iterator(self.action_dim(), input.actions.row(i).iter().copied());
            let y = self.step(&x, &u);
            for j in 0..y.len() {
                out[(i, j)] = y[j];
            }
        }
        Ok(Prediction::deterministic(out))
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

/// A torque-limited pendulum, phi = 0 upright: phi'' = (g/l) sin(phi) - b phi' + u / (m l^2),
/// semi-implicit Euler with dt = 0.05.
#[derive(Clone)]
pub struct PendulumModel;

impl PendulumModel {
    pub fn step(x: &[f64], u: f64) -> [f64; 2] {
        let (dt, g, l, m, b) = (0.05, 9.81, 1.0, 1.0, 0.1);
        let acc = g / l * x[0].sin() - b * x[1] + u / (m * l * l);
        let v = x[1] + dt * acc;
        [x[0] + dt * v, v]
    }
}

impl DynamicsModel for PendulumModel {
    fn state_dim(&self) -> usize {
        2
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let n = input.states.nrows();
        let mut out = Array2::zeros((n, 2));
        for i in 0..n {
            let y = Self::step(
                &[input.states[(i, 0)], input.states[(i, 1)]],
                input.actions[(i, 0)],
            );
            out[(i, 0)] = y[0];
            out[(i, 1)] = y[1];
        }
        Ok(Prediction::deterministic(out))
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

/// The weights the double-integrator tests share: `Q = diag(1, 0.1)`, `R = 0.01`, `Q_f = 10 Q`.
pub fn lq_weights() -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
    let r = DMatrix::from_element(1, 1, 0.01);
    let qf = &q * 10.0;
    (q, r, qf)
}

/// Quadratic objective `xᵀQx + uᵀRu` with terminal `xᵀQf x`.
pub fn quadratic_objective(q: &DMatrix<f64>, r: &DMatrix<f64>, qf: &DMatrix<f64>) -> Objective {
    let (q2, r2, qf2) = (q.clone(), r.clone(), qf.clone());
    Objective::new(q.nrows(), r.nrows(), move |x, u| {
        let x = DVector::from_column_slice(x);
        let u = DVector::from_column_slice(u);
        (x.transpose() * &q2 * &x)[0] + (u.transpose() * &r2 * &u)[0]
    })
    .with_terminal(move |x| {
        let x = DVector::from_column_slice(x);
        (x.transpose() * &qf2 * &x)[0]
    })
}

/// Finite-horizon LQR by the Riccati recursion: returns (P_0 .. P_H, K_0 .. K_{H-1}) with
/// `u_t = -K_t x_t` optimal and optimal cost `x0ᵀ P_0 x0`.
pub fn riccati(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    qf: &DMatrix<f64>,
    h: usize,
) -> (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>) {
    let mut p = vec![qf.clone(); h + 1];
    let mut k = vec![DMatrix::zeros(b.ncols(), a.nrows()); h];
    for t in (0..h).rev() {
        let pn = &p[t + 1];
        let s = r + b.transpose() * pn * b;
        let kt = s.try_inverse().unwrap() * b.transpose() * pn * a;
        p[t] = q + a.transpose() * pn * a - a.transpose() * pn * b * &kt;
        k[t] = kt;
    }
    (p, k)
}
