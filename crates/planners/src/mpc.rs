//! The [`Planner`] trait, the [`Plan`] it returns, action [`Bounds`], Gaussian [`Noise`], and
//! the batched rollout and warm start every sampling planner shares.
//!
//! Populations are stored horizon-major, `H x N x A`, so that the actions of all `N` samples at
//! one time step are one contiguous `N x A` block: a rollout makes exactly one
//! [`DynamicsModel::predict`] call per time step for the whole population.
//!
//! A model that conditions on more than the state and the action carries it in its state: p1's
//! incremental model plans from `x0 = [s, a_{t−1}]` (`tandem_models::IncrementalModel`), so a
//! planner needs only `(x0, model, objective)`.

use nalgebra::DMatrix;
use ndarray::{s, Array1, Array2, Array3, ArrayView2, ArrayViewMut2, Axis};
use rand::Rng as _;
use rand_distr::StandardNormal;
use tandem_core::Rng;
use tandem_models::{DynamicsModel, ModelInput, Propagation, Transitions};

use crate::error::{check_finite, check_len, PlanError, Result};
use crate::objective::Objective;

/// A planned action sequence and its predicted consequences under the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Planned actions `u_0 .. u_{H-1}`, `H x A` (within the bounds).
    pub actions: Array2<f64>,
    /// Predicted states `x_0 .. x_H` along `actions`, `(H+1) x S`.
    pub states: Array2<f64>,
    /// Undiscounted step costs `c(x_h, u_h) + c(x_h, u_h, x_{h+1})` along the plan, length `H`
    /// (zero after a terminal state).
    pub costs: Array1<f64>,
    /// The step `h` whose next state `x_{h+1}` is terminal under the objective's termination,
    /// if the plan reaches one (the states stay there after it).
    pub terminal_step: Option<usize>,
    /// Terminal cost (including `−V`) at `x_H`.
    pub terminal_cost: f64,
    /// The objective value `Σ γ^h c_h + γ^H c_H` of the plan.
    pub total_cost: f64,
}

impl Plan {
    /// Rolls the action sequence `actions` (`H x A`) out from `x0` through `model` and scores it
    /// under `objective`: what a planner does for each candidate, for one sequence of the
    /// caller's.
    pub fn rollout(
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
        actions: &Array2<f64>,
        rng: &mut Rng,
    ) -> Result<Plan> {
        let (_, a) = check_problem(x0, model, objective)?;
        check_len("actions (columns)", a, actions.ncols())?;
        nonzero("horizon", actions.nrows())?;
        plan_from_actions(x0, model, objective, rng, actions)
    }

    /// The action to apply now, `u_0`.
    pub fn first_action(&self) -> Vec<f64> {
        self.actions.row(0).to_vec()
    }

    /// Horizon `H`.
    pub fn horizon(&self) -> usize {
        self.actions.nrows()
    }

    /// The planned transitions `(x_h, u_h, r_h = −c_h, x_{h+1})` as a dataset a pipeline can add to
    /// a replay buffer (p3 Algorithm 1, lines 14–15), up to and including the
    /// [`Plan::terminal_step`], the one transition marked terminal.
    pub fn transitions(&self) -> Transitions {
        let h = self.terminal_step.map_or(self.horizon(), |t| t + 1);
        let mut terminated = Array1::from_elem(h, false);
        if self.terminal_step.is_some() {
            terminated[h - 1] = true;
        }
        Transitions {
            states: self.states.slice(s![..h, ..]).to_owned(),
            actions: self.actions.slice(s![..h, ..]).to_owned(),
            next_states: self.states.slice(s![1..=h, ..]).to_owned(),
            rewards: self.costs.slice(s![..h]).mapv(|c| -c),
            terminated,
        }
    }
}

/// A receding-horizon planner: plans through any [`DynamicsModel`] (a plant, a learned network,
/// an ensemble, an incremental model) and keeps its warm start between calls.
pub trait Planner {
    /// Plans from state `x0` through `model` under `objective`. The caller applies
    /// [`Plan::first_action`] and calls again at the next state; the warm start is the previous
    /// plan shifted by one step.
    fn plan(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
    ) -> Result<Plan>;

    /// Forgets the warm start and restarts the random stream from the configured seed (call at the
    /// start of an episode).
    fn reset(&mut self);
}

/// Box bounds on actions, `low ≤ u ≤ high` componentwise.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    /// Lower bounds.
    pub low: Vec<f64>,
    /// Upper bounds.
    pub high: Vec<f64>,
}

impl Bounds {
    /// Bounds `low ≤ u ≤ high`; checked by [`Bounds::validate`] when a planner uses them.
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> Self {
        Self { low, high }
    }

    /// The same bound `[-b, b]` on each of `dim` components.
    pub fn symmetric(dim: usize, b: f64) -> Self {
        Self::new(vec![-b; dim], vec![b; dim])
    }

    /// Checks lengths against `dim` and that `low ≤ high` with no NaN.
    pub fn validate(&self, dim: usize) -> Result<()> {
        check_len("bounds low", dim, self.low.len())?;
        check_len("bounds high", dim, self.high.len())?;
        for (i, (l, h)) in self.low.iter().zip(&self.high).enumerate() {
            if l.is_nan() || h.is_nan() || l > h {
                return Err(PlanError::Config(format!(
                    "bounds component {i}: low {l} must not exceed high {h}"
                )));
            }
        }
        Ok(())
    }

    /// Clamps every row of `a` (`B x A`) into the bounds.
    pub fn clamp_rows(&self, mut a: ArrayViewMut2<'_, f64>) {
        for mut r in a.rows_mut() {
            for (j, v) in r.iter_mut().enumerate() {
                *v = v.clamp(self.low[j], self.high[j]);
            }
        }
    }

    /// Clamps one action in place.
    pub fn clamp(&self, u: &mut [f64]) {
        for (j, v) in u.iter_mut().enumerate() {
            *v = v.clamp(self.low[j], self.high[j]);
        }
    }

    /// Midpoint, or 0 where a side is unbounded.
    pub fn center(&self) -> Vec<f64> {
        self.low
            .iter()
            .zip(&self.high)
            .map(|(l, h)| {
                if l.is_finite() && h.is_finite() {
                    0.5 * (l + h)
                } else {
                    0.0f64.clamp(*l, *h)
                }
            })
            .collect()
    }
}

pub(crate) fn clamp_opt(bounds: &Option<Bounds>, a: ArrayViewMut2<'_, f64>) {
    if let Some(b) = bounds {
        b.clamp_rows(a);
    }
}

/// A zero-mean Gaussian over one action, `N(0, Σ)`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Noise {
    /// The same standard deviation on every component.
    Isotropic(f64),
    /// One standard deviation per component.
    Diagonal(Vec<f64>),
    /// A full covariance matrix, row by row.
    Full(Vec<Vec<f64>>),
}

impl Noise {
    /// Lower Cholesky factor `L` (`Σ = L Lᵀ`) for actions of length `dim`.
    pub fn cholesky(&self, dim: usize) -> Result<DMatrix<f64>> {
        match self {
            Noise::Isotropic(s) => {
                positive("noise standard deviation", *s)?;
                Ok(DMatrix::identity(dim, dim) * *s)
            }
            Noise::Diagonal(v) => {
                check_len("noise standard deviations", dim, v.len())?;
                for s in v {
                    positive("noise standard deviation", *s)?;
                }
                Ok(DMatrix::from_diagonal(
                    &nalgebra::DVector::from_column_slice(v),
                ))
            }
            Noise::Full(rows) => {
                check_len("noise covariance rows", dim, rows.len())?;
                for r in rows {
                    check_len("noise covariance columns", dim, r.len())?;
                    check_finite("noise covariance", r)?;
                }
                let m = DMatrix::from_fn(dim, dim, |i, j| rows[i][j]);
                if (&m - m.transpose()).abs().max() > 1e-12 * m.abs().max().max(1.0) {
                    return Err(PlanError::Config(
                        "noise covariance is not symmetric".into(),
                    ));
                }
                m.cholesky().map(|c| c.l()).ok_or_else(|| {
                    PlanError::Config("noise covariance is not positive definite".into())
                })
            }
        }
    }
}

pub(crate) fn positive(what: &str, v: f64) -> Result<()> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(PlanError::Config(format!(
            "{what} must be positive and finite, got {v}"
        )))
    }
}

pub(crate) fn nonzero(what: &str, v: usize) -> Result<()> {
    if v > 0 {
        Ok(())
    } else {
        Err(PlanError::Config(format!("{what} must be at least 1")))
    }
}

pub(crate) fn fraction(what: &str, v: f64) -> Result<()> {
    if v > 0.0 && v <= 1.0 {
        Ok(())
    } else {
        Err(PlanError::Config(format!(
            "{what} must be in (0, 1], got {v}"
        )))
    }
}

/// Checks that the model, the objective and `x0` agree on dimensions and that `x0` is finite;
/// returns `(S, A)`.
pub(crate) fn check_problem(
    x0: &[f64],
    model: &dyn DynamicsModel,
    objective: &Objective,
) -> Result<(usize, usize)> {
    let (s, a) = (model.state_dim(), model.action_dim());
    check_len(
        "objective state dimension vs model",
        s,
        objective.state_dim(),
    )?;
    check_len(
        "objective action dimension vs model",
        a,
        objective.action_dim(),
    )?;
    check_len("initial state", s, x0.len())?;
    check_finite("initial state", x0)?;
    Ok((s, a))
}

/// The warm start of a sampling planner: the previous mean (`H x A`) shifted one step earlier
/// (last action repeated) when it fits the horizon and action width, else the bounds' centre
/// (zero where unbounded) at every step.
pub(crate) fn warm_start(
    previous: Option<Array2<f64>>,
    h: usize,
    a: usize,
    bounds: Option<&Bounds>,
) -> Array2<f64> {
    match previous {
        Some(mut m) if m.dim() == (h, a) => {
            shift_plan(&mut m);
            m
        }
        _ => {
            let c = bounds.map_or(vec![0.0; a], |b| b.center());
            Array2::from_shape_fn((h, a), |(_, j)| c[j])
        }
    }
}

/// `u = centre + L z` row by row (`L` lower triangular): Gaussian perturbations of a batch of
/// actions.
pub(crate) fn add_noise(
    l: &DMatrix<f64>,
    centre: ArrayView2<'_, f64>,
    z: ArrayView2<'_, f64>,
    mut u: ArrayViewMut2<'_, f64>,
) {
    let a = centre.ncols();
    for i in 0..centre.nrows() {
        for j in 0..a {
            let mut e = 0.0;
            for k in 0..=j {
                e += l[(j, k)] * z[(i, k)];
            }
            u[(i, j)] = centre[(i, j)] + e;
        }
    }
}

/// Fills `out` with standard normal draws.
pub(crate) fn fill_normal(rng: &mut Rng, out: &mut [f64]) {
    for v in out.iter_mut() {
        *v = rng.sample(StandardNormal);
    }
}

/// Fills `z` (`H x N x A`) with standard normal sequences that are AR(1)-correlated along the
/// horizon, `z_t = β z_{t−1} + √(1 − β²) w_t` (unit marginal variance; `β = 0`: white noise).
/// Smooth perturbations explore long manoeuvres (a swing-up) far better than white noise, the
/// point of iCEM's coloured noise (Pinneri et al. 2020).
pub(crate) fn fill_correlated_normal(rng: &mut Rng, z: &mut Array3<f64>, beta: f64) {
    fill_normal(rng, z.as_slice_mut().expect("standard layout"));
    if beta != 0.0 {
        let c = (1.0 - beta * beta).sqrt();
        for t in 1..z.shape()[0] {
            let (prev, mut cur) = z.view_mut().split_at(ndarray::Axis(0), t);
            let prev = prev.index_axis(ndarray::Axis(0), t - 1);
            cur.index_axis_mut(ndarray::Axis(0), 0)
                .zip_mut_with(&prev, |v, p| *v = beta * p + c * *v);
        }
    }
}

/// Where the sampling noise is drawn along the horizon: at knots every `spacing` steps, held or
/// linearly interpolated in between (move blocking, Cagienard et al. 2007; the spline policies of
/// MJPC's predictive sampling, Howell et al. 2022). A sampled perturbation then has
/// `⌈H / spacing⌉` (held) or `⌈(H − 1) / spacing⌉ + 1` (linear) degrees of freedom per action
/// component instead of `H`, so the same samples cover a longer horizon. The AR(1) correlation
/// `β` of the planners acts between consecutive knots. `spacing = 1` (the default) is one knot per
/// step, the original algorithms, and draws exactly the same numbers as before knots existed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Knots {
    /// Steps between knots (at least 1).
    pub spacing: usize,
    /// How the noise between two knots is filled in.
    pub interpolation: Interpolation,
}

impl Default for Knots {
    fn default() -> Self {
        Self {
            spacing: 1,
            interpolation: Interpolation::Linear,
        }
    }
}

/// How [`Knots`] fill the steps between two knots.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Interpolation {
    /// Zero-order hold: each knot's value for `spacing` steps.
    Hold,
    /// Linear between knots, rescaled so every step keeps unit marginal variance.
    Linear,
}

impl Knots {
    /// Knots every `spacing` steps with linear interpolation.
    pub fn linear(spacing: usize) -> Self {
        Self {
            spacing,
            interpolation: Interpolation::Linear,
        }
    }

    /// Knots every `spacing` steps, each held until the next.
    pub fn hold(spacing: usize) -> Self {
        Self {
            spacing,
            interpolation: Interpolation::Hold,
        }
    }

    /// Checks `spacing ≥ 1`.
    pub fn validate(&self) -> Result<()> {
        nonzero("knot spacing", self.spacing)
    }

    /// Number of knots that cover a horizon of `h` steps.
    pub fn count(&self, h: usize) -> usize {
        let s = self.spacing.max(1);
        match self.interpolation {
            Interpolation::Hold => h.div_ceil(s),
            Interpolation::Linear => (h.saturating_sub(1)).div_ceil(s) + 1,
        }
    }
}

/// Fills `z` (`H x N x A`) with unit-variance standard normal sequences drawn at `knots`,
/// AR(1)-correlated between knots with `beta` (see [`fill_correlated_normal`] and [`Knots`]).
pub(crate) fn fill_knot_noise(rng: &mut Rng, z: &mut Array3<f64>, beta: f64, knots: &Knots) {
    let s = knots.spacing.max(1);
    if s == 1 {
        fill_correlated_normal(rng, z, beta);
        return;
    }
    let (h, n, a) = z.dim();
    let mut zk = Array3::zeros((knots.count(h), n, a));
    fill_correlated_normal(rng, &mut zk, beta);
    for t in 0..h {
        let (k, r) = (t / s, t % s);
        let mut out = z.index_axis_mut(ndarray::Axis(0), t);
        match knots.interpolation {
            Interpolation::Hold => out.assign(&zk.index_axis(ndarray::Axis(0), k)),
            Interpolation::Linear if r == 0 => out.assign(&zk.index_axis(ndarray::Axis(0), k)),
            Interpolation::Linear => {
                // (1 − w) z_k + w z_{k+1} has variance (1 − w)² + w² + 2 w (1 − w) β.
                let w = r as f64 / s as f64;
                let norm = ((1.0 - w).powi(2) + w * w + 2.0 * w * (1.0 - w) * beta).sqrt();
                let (c0, c1) = ((1.0 - w) / norm, w / norm);
                let (z0, z1) = (
                    zk.index_axis(ndarray::Axis(0), k),
                    zk.index_axis(ndarray::Axis(0), k + 1),
                );
                ndarray::Zip::from(&mut out)
                    .and(&z0)
                    .and(&z1)
                    .for_each(|o, &p, &q| *o = c0 * p + c1 * q);
            }
        }
    }
}

pub(crate) fn correlation(v: f64) -> Result<()> {
    if (0.0..1.0).contains(&v) {
        Ok(())
    } else {
        Err(PlanError::Config(format!(
            "noise correlation must be in [0, 1), got {v}"
        )))
    }
}

/// Shifts a `H x A` plan one step earlier, repeating the last action.
fn shift_plan(mean: &mut Array2<f64>) {
    let h = mean.nrows();
    for t in 0..h.saturating_sub(1) {
        let next = mean.row(t + 1).to_owned();
        mean.row_mut(t).assign(&next);
    }
}

/// `model.predict(input)`, with the next states checked to be `B x S` like the input.
pub(crate) fn predict(
    model: &dyn DynamicsModel,
    input: &ModelInput<'_>,
    rng: &mut Rng,
) -> Result<tandem_models::Prediction> {
    let pred = model.predict(input, rng)?;
    let (b, s) = input.states.dim();
    check_len("predicted next states (rows)", b, pred.next_states.nrows())?;
    check_len(
        "predicted next states (columns)",
        s,
        pred.next_states.ncols(),
    )?;
    Ok(pred)
}

/// Rolls open-loop sequences (`actions`, `H x N x A`) out from `x0` with `particles` rows per
/// sequence and returns each sequence's objective value, the mean over its particles (PETS's
/// trajectory sampling), the batches propagated as `propagation` says (the model's own setting
/// when `None`). A sequence's particles are consecutive rows,
/// so a model that deals its members by row index (the ensemble's `FixedMember`, PETS's TS-∞)
/// spreads them over its members as evenly as the count allows; one that draws a member per row
/// and step (`RandomMember`, TS-1) averages over its draws.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_particles(
    x0: &[f64],
    model: &dyn DynamicsModel,
    objective: &Objective,
    rng: &mut Rng,
    actions: &mut Array3<f64>,
    particles: usize,
    propagation: Option<Propagation>,
) -> Result<Array1<f64>> {
    let open_loop = |_: usize, _: ArrayView2<'_, f64>, _: ArrayViewMut2<'_, f64>| Ok(());
    let start = one_row(x0);
    let rollout = Rollout {
        model,
        objective,
        propagation,
    };
    if particles == 1 {
        let (costs, _) = rollout_starts(start, &rollout, rng, actions, open_loop, None, None)?;
        return Ok(costs);
    }
    let (h, n, a) = actions.dim();
    let mut rows = Array3::from_shape_fn((h, n * particles, a), |(t, r, j)| {
        actions[(t, r / particles, j)]
    });
    let (costs, _) = rollout_starts(start, &rollout, rng, &mut rows, open_loop, None, None)?;
    Ok(mean_per(costs, particles))
}

/// The mean of each run of `particles` consecutive costs (`costs` itself for one particle).
pub(crate) fn mean_per(costs: Array1<f64>, particles: usize) -> Array1<f64> {
    if particles == 1 {
        return costs;
    }
    Array1::from_iter(
        costs
            .as_slice()
            .expect("a fresh array is contiguous")
            .chunks(particles)
            // Shifted by the first particle's cost, so equal costs average to themselves.
            .map(|c| c[0] + c.iter().map(|v| v - c[0]).sum::<f64>() / particles as f64),
    )
}

/// A slice as a `1 x len` matrix.
pub(crate) fn one_row(x: &[f64]) -> ArrayView2<'_, f64> {
    ArrayView2::from_shape((1, x.len()), x).expect("a slice is one row")
}

/// What a population is rolled out through: the model, the objective that scores it, and how
/// the model propagates the batches (its own setting when `None`).
pub(crate) struct Rollout<'a> {
    pub(crate) model: &'a dyn DynamicsModel,
    pub(crate) objective: &'a Objective,
    pub(crate) propagation: Option<Propagation>,
}

/// Rolls a population out, one `predict` per step, from `P` start states at once (`starts`,
/// `P x S`), and returns each sample's objective value `Σ γ^h c(x_h, u_h, x_{h+1}) + γ^H
/// c_H(x_H)`, a sample that reaches a terminal state costing nothing after that step. The
/// `N` samples of `actions` (`H x N x A`, `N` a multiple of `P`) are start-major, rows
/// `p·N/P .. (p+1)·N/P` starting at `starts[p]`.
///
/// Before step `h` the callback `act(h, states, actions_h)` may write the actions of that step
/// from the current states (a policy proposal); pass a no-op for open-loop sequences.
/// `states_out`, when given (`(H+1) x N x S`), records the states.
pub(crate) fn rollout_starts(
    starts: ArrayView2<'_, f64>,
    rollout: &Rollout<'_>,
    rng: &mut Rng,
    actions: &mut Array3<f64>,
    mut act: impl FnMut(usize, ArrayView2<'_, f64>, ArrayViewMut2<'_, f64>) -> Result<()>,
    mut states_out: Option<&mut Array3<f64>>,
    running_out: Option<&mut Array2<f64>>,
) -> Result<(Array1<f64>, Vec<f64>)> {
    let Rollout {
        model,
        objective,
        propagation,
    } = *rollout;
    let (h_len, n, _) = actions.dim();
    let (p, s_dim) = starts.dim();
    if p == 0 || n % p != 0 {
        return Err(PlanError::Config(format!(
            "{n} samples do not split evenly over {p} start states"
        )));
    }
    let per = n / p;
    let mut states = Array2::from_shape_fn((n, s_dim), |(i, j)| starts[(i / per, j)]);
    let mut total = Array1::zeros(n);
    let mut step_cost = vec![0.0; n];
    let gamma = objective.discount();
    let mut disc = 1.0;
    let mut running_out = running_out;
    let mut ended = objective.has_termination().then(|| vec![false; n]);
    if let Some(so) = states_out.as_deref_mut() {
        so.slice_mut(s![0, .., ..]).assign(&states);
    }
    for h in 0..h_len {
        act(h, states.view(), actions.slice_mut(s![h, .., ..]))?;
        let u = actions.slice(s![h, .., ..]);
        objective.running_batch(states.view(), u, h, &mut step_cost)?;
        let input = ModelInput::new(states.view(), u).with_propagation(propagation);
        let pred = predict(model, &input, rng)?;
        if objective.uses_model_reward() {
            let r = pred.rewards.as_ref().ok_or_else(|| {
                PlanError::Config(
                    "objective uses the model's reward but the model predicts none".into(),
                )
            })?;
            check_len("predicted rewards", n, r.len())?;
            for (i, (c, rv)) in step_cost.iter_mut().zip(r.iter()).enumerate() {
                if !rv.is_finite() {
                    return Err(PlanError::NonFiniteCost {
                        what: "model reward",
                        sample: i,
                        step: h,
                        value: *rv,
                    });
                }
                *c -= rv;
            }
        }
        let mut next = pred.next_states;
        objective.add_transition_batch(states.view(), u, next.view(), h, &mut step_cost)?;
        if let Some(ended) = ended.as_mut() {
            for (i, done) in ended.iter_mut().enumerate() {
                if *done {
                    // An ended sample stays where it ended and costs nothing more.
                    step_cost[i] = 0.0;
                    next.row_mut(i).assign(&states.row(i));
                } else {
                    *done = objective.terminated(&next.row(i).to_vec());
                }
            }
        }
        for (t, c) in total.iter_mut().zip(&step_cost) {
            *t += disc * c;
        }
        if let Some(ro) = running_out.as_deref_mut() {
            ro.row_mut(h)
                .assign(&ndarray::ArrayView1::from(&step_cost[..]));
        }
        disc *= gamma;
        states = next;
        if let Some(so) = states_out.as_deref_mut() {
            so.slice_mut(s![h + 1, .., ..]).assign(&states);
        }
    }
    let mut term = vec![0.0; n];
    if objective.has_terminal() {
        objective.terminal_batch(states.view(), h_len, &mut term)?;
        for (i, done) in ended.iter().flatten().enumerate() {
            if *done {
                term[i] = 0.0;
            }
        }
        for (t, c) in total.iter_mut().zip(&term) {
            *t += disc * c;
        }
    }
    Ok((total, term))
}

/// Rolls out one action sequence (`H x A`) and packages it as a [`Plan`].
pub(crate) fn plan_from_actions(
    x0: &[f64],
    model: &dyn DynamicsModel,
    objective: &Objective,
    rng: &mut Rng,
    actions: &Array2<f64>,
) -> Result<Plan> {
    let (h, a) = actions.dim();
    let acts = actions
        .clone()
        .into_shape_with_order((h, 1, a))
        .expect("same size");
    let mut plans = plans_from_actions(one_row(x0), model, objective, rng, acts)?;
    Ok(plans.pop().expect("one start, one plan"))
}

/// Rolls out one action sequence per start state (`actions` `H x P x A`, `starts` `P x S`) in
/// one population and packages each as a [`Plan`].
pub(crate) fn plans_from_actions(
    starts: ArrayView2<'_, f64>,
    model: &dyn DynamicsModel,
    objective: &Objective,
    rng: &mut Rng,
    mut actions: Array3<f64>,
) -> Result<Vec<Plan>> {
    let (h, p, _) = actions.dim();
    let mut states = Array3::zeros((h + 1, p, starts.ncols()));
    let mut running = Array2::zeros((h, p));
    let rollout = Rollout {
        model,
        objective,
        propagation: None,
    };
    let (total, term) = rollout_starts(
        starts,
        &rollout,
        rng,
        &mut actions,
        |_, _, _| Ok(()),
        Some(&mut states),
        Some(&mut running),
    )?;
    Ok((0..p)
        .map(|i| {
            let states = states.index_axis(Axis(1), i).to_owned();
            let terminal_step = (0..h).find(|&t| objective.terminated(&states.row(t + 1).to_vec()));
            Plan {
                actions: actions.index_axis(Axis(1), i).to_owned(),
                states,
                costs: running.column(i).to_owned(),
                terminal_step,
                terminal_cost: term[i],
                total_cost: total[i],
            }
        })
        .collect())
}

/// Indices of the `k` lowest costs, cheapest first (ties broken by index, so results are
/// reproducible).
pub(crate) fn lowest_k(costs: &Array1<f64>, k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..costs.len()).collect();
    idx.sort_by(|&i, &j| costs[i].total_cmp(&costs[j]).then(i.cmp(&j)));
    idx.truncate(k);
    idx
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Axis;
    use tandem_core::seeding::rng_from_seed;

    fn knot_noise(h: usize, n: usize, beta: f64, knots: Knots, seed: u64) -> Array3<f64> {
        let mut z = Array3::zeros((h, n, 1));
        fill_knot_noise(&mut rng_from_seed(seed), &mut z, beta, &knots);
        z
    }

    #[test]
    fn knot_counts_cover_the_horizon() {
        // Hold: knots at 0, s, 2s, … below H. Linear: the last knot at or beyond H − 1.
        assert_eq!(Knots::hold(5).count(30), 6);
        assert_eq!(Knots::hold(4).count(30), 8);
        assert_eq!(Knots::linear(3).count(31), 11);
        assert_eq!(Knots::linear(3).count(30), 11);
        assert_eq!(Knots::linear(1).count(30), 30);
        assert_eq!(Knots::hold(50).count(30), 1);
        assert_eq!(Knots::linear(50).count(30), 2);
        assert!(Knots::hold(0).validate().is_err());
        assert!(Knots::default().validate().is_ok());
    }

    #[test]
    fn one_knot_per_step_draws_the_old_stream() {
        let mut old = Array3::zeros((12, 7, 2));
        fill_correlated_normal(&mut rng_from_seed(4), &mut old, 0.6);
        let mut new = Array3::zeros((12, 7, 2));
        fill_knot_noise(&mut rng_from_seed(4), &mut new, 0.6, &Knots::default());
        assert_eq!(old, new);
    }

    #[test]
    fn held_knots_are_constant_within_blocks_with_unit_variance() {
        let (h, n, s, beta) = (13, 20_000, 4, 0.5);
        let z = knot_noise(h, n, beta, Knots::hold(s), 1);
        for t in 0..h {
            if t % s != 0 {
                assert_eq!(z.index_axis(Axis(0), t), z.index_axis(Axis(0), t - 1));
            }
            let var = z.index_axis(Axis(0), t).mapv(|v| v * v).mean().unwrap();
            assert!((var - 1.0).abs() < 0.05, "step {t}: variance {var}");
        }
        // Consecutive blocks carry the AR(1) correlation β.
        let corr = (&z.index_axis(Axis(0), 3) * &z.index_axis(Axis(0), 4))
            .mean()
            .unwrap();
        assert!((corr - beta).abs() < 0.05, "{corr}");
    }

    #[test]
    fn linear_knots_interpolate_with_unit_variance() {
        let (h, n, s, beta) = (10, 20_000, 3, 0.3);
        let z = knot_noise(h, n, beta, Knots::linear(s), 2);
        for t in 0..h {
            let var = z.index_axis(Axis(0), t).mapv(|v| v * v).mean().unwrap();
            assert!((var - 1.0).abs() < 0.05, "step {t}: variance {var}");
            let (k, r) = (t / s, t % s);
            if r == 0 || (k + 1) * s >= h {
                continue;
            }
            // Between knots at ks and (k+1)s: the normalized convex combination of the two.
            let w = r as f64 / s as f64;
            let norm = ((1.0 - w).powi(2) + w * w + 2.0 * w * (1.0 - w) * beta).sqrt();
            for i in 0..n {
                let want = ((1.0 - w) * z[(k * s, i, 0)] + w * z[((k + 1) * s, i, 0)]) / norm;
                assert!((z[(t, i, 0)] - want).abs() < 1e-12);
            }
        }
    }
}
