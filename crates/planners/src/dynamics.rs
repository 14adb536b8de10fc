//! [`Dynamics`]: what the trajectory optimizers (iLQR) need from a system: batched steps and
//! Jacobians. Two adapters: [`PlantDynamics`] (a known [`Plant`], with its own
//! [`Plant::linearize`], analytic where the plant provides it) and [`ModelDynamics`] (any
//! [`DynamicsModel`], Jacobians by central differences, all evaluation points of a trajectory in
//! one `predict` call).

use std::cell::RefCell;

use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, ArrayView2};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_dynamics::Plant;
use tandem_models::{DynamicsModel, ModelInput};

use crate::error::{check_len, PlanError, Result};

/// A discrete-time system a trajectory optimizer can roll out and linearize.
pub trait Dynamics {
    /// Length of the state.
    fn state_dim(&self) -> usize;
    /// Length of the action.
    fn action_dim(&self) -> usize;
    /// One step for a batch: `B x S` states and `B x A` actions to `B x S` next states.
    fn step_batch(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array2<f64>>;
    /// Jacobians `(A_t, B_t) = (∂f/∂x, ∂f/∂u)` at each row `(x_t, u_t)` of `T x S` states and
    /// `T x A` actions. The default uses central differences (step `1e-6·max(1, |z_i|)`) with all
    /// `T·2(S+A)` points in one [`Dynamics::step_batch`] call.
    fn jacobians(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Vec<(DMatrix<f64>, DMatrix<f64>)>> {
        let (t_len, n) = states.dim();
        let m = actions.ncols();
        let d = n + m;
        let rows = t_len * 2 * d;
        let mut xs = Array2::zeros((rows, n));
        let mut us = Array2::zeros((rows, m));
        let mut hs = vec![0.0; t_len * d];
        for t in 0..t_len {
            for k in 0..d {
                let z = if k < n {
                    states[(t, k)]
                } else {
                    actions[(t, k - n)]
                };
                let h = 1e-6 * z.abs().max(1.0);
                hs[t * d + k] = h;
                for (s, sign) in [(0, 1.0), (1, -1.0)] {
                    let r = (t * d + k) * 2 + s;
                    xs.row_mut(r).assign(&states.row(t));
                    us.row_mut(r).assign(&actions.row(t));
                    if k < n {
                        xs[(r, k)] += sign * h;
                    } else {
                        us[(r, k - n)] += sign * h;
                    }
                }
            }
        }
        let f = self.step_batch(xs.view(), us.view())?;
        let mut out = Vec::with_capacity(t_len);
        for t in 0..t_len {
            let mut a = DMatrix::zeros(n, n);
            let mut b = DMatrix::zeros(n, m);
            for k in 0..d {
                let r = (t * d + k) * 2;
                let h = hs[t * d + k];
                for i in 0..n {
                    let v = (f[(r, i)] - f[(r + 1, i)]) / (2.0 * h);
                    if k < n {
                        a[(i, k)] = v;
                    } else {
                        b[(i, k - n)] = v;
                    }
                }
            }
            out.push((a, b));
        }
        Ok(out)
    }
}

/// A known plant as [`Dynamics`]; Jacobians from [`Plant::linearize`].
#[derive(Debug, Clone, Copy)]
pub struct PlantDynamics<'a, P: Plant>(pub &'a P);

impl<P: Plant> Dynamics for PlantDynamics<'_, P> {
    fn state_dim(&self) -> usize {
        self.0.state_dim()
    }
    fn action_dim(&self) -> usize {
        self.0.action_dim()
    }
    fn step_batch(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array2<f64>> {
        check_batch(self, states, actions)?;
        let mut out = Array2::zeros(states.dim());
        for i in 0..states.nrows() {
            let x = DVector::from_iterator(states.ncols(), states.row(i).iter().copied());
            let u = DVector::from_iterator(actions.ncols(), actions.row(i).iter().copied());
            let y = self.0.step(&x, &u);
            check_len("plant next state", states.ncols(), y.len())?;
            out.row_mut(i)
                .iter_mut()
                .zip(y.iter())
                .for_each(|(o, v)| *o = *v);
        }
        Ok(out)
    }
    fn jacobians(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Vec<(DMatrix<f64>, DMatrix<f64>)>> {
        check_batch(self, states, actions)?;
        Ok((0..states.nrows())
            .map(|t| {
                let x = DVector::from_iterator(states.ncols(), states.row(t).iter().copied());
                let u = DVector::from_iterator(actions.ncols(), actions.row(t).iter().copied());
                self.0.linearize(&x, &u)
            })
            .collect())
    }
}

/// Any [`DynamicsModel`] as [`Dynamics`]: steps are `predict` means (a stochastic model is sampled
/// with a generator restarted from `seed` for every call, so repeated evaluations agree), Jacobians
/// by central differences.
pub struct ModelDynamics<'a> {
    model: &'a dyn DynamicsModel,
    seed: u64,
    rng: RefCell<Rng>,
}

impl<'a> ModelDynamics<'a> {
    /// Wraps `model`; `seed` drives any stochastic propagation.
    pub fn new(model: &'a dyn DynamicsModel, seed: u64) -> Self {
        Self {
            model,
            seed,
            rng: RefCell::new(rng_from_seed(seed)),
        }
    }
}

impl Dynamics for ModelDynamics<'_> {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn action_dim(&self) -> usize {
        self.model.action_dim()
    }
    fn step_batch(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array2<f64>> {
        check_batch(self, states, actions)?;
        let mut rng = self.rng.borrow_mut();
        *rng = rng_from_seed(self.seed);
        let p = self
            .model
            .predict(&ModelInput::new(states.view(), actions.view()), &mut rng)?;
        check_len(
            "predicted next states (rows)",
            states.nrows(),
            p.next_states.nrows(),
        )?;
        check_len(
            "predicted next states (columns)",
            states.ncols(),
            p.next_states.ncols(),
        )?;
        Ok(p.next_states)
    }
}

fn check_batch<D: Dynamics + ?Sized>(
    d: &D,
    states: ArrayView2<'_, f64>,
    actions: ArrayView2<'_, f64>,
) -> Result<()> {
    check_len("states (columns)", d.state_dim(), states.ncols())?;
    check_len("actions (columns)", d.action_dim(), actions.ncols())?;
    check_len("actions (rows)", states.nrows(), actions.nrows())?;
    if states.iter().chain(actions.iter()).any(|v| !v.is_finite()) {
        return Err(PlanError::NonFinite(
            "states or actions given to the dynamics".into(),
        ));
    }
    Ok(())
}
