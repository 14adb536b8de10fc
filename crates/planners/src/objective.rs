//! [`Objective`]: what every planner and trajectory optimizer minimizes.
//!
//! `C(x_{0:H}, u_{0:H-1}) = Σ_h γ^h c(x_h, u_h) + γ^H (c_H(x_H) − V(x_H))` (p3 eq. 3), with a
//! running cost `c`, an optional terminal cost `c_H`, an optional terminal value `V` (p3 uses the
//! SAC critic, so the terminal cost is `−V`), and a discount `γ` (1 unless set). Costs are
//! evaluated in batches (one row per sample of a population); a NaN or infinite cost is an error
//! naming the sample and the time step.
//!
//! The running cost may vary with time, `c(x_h, u_h, h)` ([`Objective::time_varying`]): a
//! tracking target that moves, a surrogate that differs at every step. The index `h` counts
//! steps from the start of the plan or trajectory (`h = 0` at `x_0`); a receding-horizon caller
//! whose cost depends on absolute time builds the objective for the current time at each call.
//!
//! A cost may also depend on where a step lands, `c(x_h, u_h, x_{h+1})`
//! ([`Objective::with_transition_cost`]), and a rollout may end early
//! ([`Objective::with_termination`]): a sample whose state is terminal accrues no cost after the
//! step that reached it, as an episode that ends earns no more reward. Both are how a task's
//! reward and termination become a planning objective ([`Objective::from_task`],
//! [`Objective::from_task_observations`]). MPC rollouts honour them; the trajectory optimizers,
//! which expand costs of `(x, u)`, refuse them.
//!
//! Derivatives for iLQR and LQR-FLM: analytic when given
//! ([`Objective::with_running_derivatives`], [`Objective::with_terminal_derivatives`]), central
//! finite differences otherwise (the numerical twin is also the test oracle of the analytic
//! ones, as in Crocoddyl).

use nalgebra::{DMatrix, DVector};
use ndarray::{Array1, Array2, ArrayView2};

use tandem_core::{Action, Space};
use tandem_envs::{ObservedTask, Task};

use crate::error::{check_finite, check_len, PlanError, Result};

/// Running cost `c(x, u, t)` at time step `t`.
pub type CostFn = Box<dyn Fn(&[f64], &[f64], usize) -> f64 + Send + Sync>;
/// Cost of a transition `c(x, u, x')`, added to the running cost of the step.
pub type TransitionFn = Box<dyn Fn(&[f64], &[f64], &[f64]) -> f64 + Send + Sync>;
/// Whether a state ends a rollout (a task's termination).
pub type TerminationFn = Box<dyn Fn(&[f64]) -> bool + Send + Sync>;
/// Terminal cost `c_H(x)`.
pub type TerminalFn = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;
/// Terminal value over a batch of states (`B x S` in, `B` values out), e.g. a critic `V(x)`.
pub type ValueFn = Box<dyn Fn(ArrayView2<'_, f64>) -> Array1<f64> + Send + Sync>;
/// Analytic second-order expansion of the running cost at `(x, u)` and time step `t`.
pub type RunningDerivFn = Box<dyn Fn(&[f64], &[f64], usize) -> QuadCost + Send + Sync>;
/// Analytic second-order expansion of the terminal cost at `x`.
pub type TerminalDerivFn = Box<dyn Fn(&[f64]) -> QuadTerminal + Send + Sync>;

/// Second-order expansion of a running cost around `(x, u)`:
/// `c(x+δx, u+δu) ≈ c + cxᵀδx + cuᵀδu + ½δxᵀcxx δx + ½δuᵀcuu δu + δuᵀcux δx`.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadCost {
    /// Cost value.
    pub c: f64,
    /// Gradient in `x` (`n`).
    pub cx: DVector<f64>,
    /// Gradient in `u` (`m`).
    pub cu: DVector<f64>,
    /// Hessian in `x` (`n x n`).
    pub cxx: DMatrix<f64>,
    /// Hessian in `u` (`m x m`).
    pub cuu: DMatrix<f64>,
    /// Mixed second derivative `∂²c/∂u∂x` (`m x n`).
    pub cux: DMatrix<f64>,
}

/// Second-order expansion of a terminal cost around `x`.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadTerminal {
    /// Cost value.
    pub c: f64,
    /// Gradient (`n`).
    pub cx: DVector<f64>,
    /// Hessian (`n x n`).
    pub cxx: DMatrix<f64>,
}

/// A cost to minimize over a horizon; see the module docs.
///
/// ```
/// use tandem_planners::Objective;
/// // Reward of the p0 pendulum, turned into a cost.
/// let obj = Objective::from_reward(2, 1, |x, u| -5.0 * x[0] * x[0] - 0.1 * x[1] * x[1] - 0.01 * u[0] * u[0]);
/// assert_eq!(obj.running_cost(&[1.0, 0.0], &[0.0], 0).unwrap(), 5.0);
/// // A target that moves with the time step t.
/// let track = Objective::time_varying(1, 1, |x, _u, t| (x[0] - 0.1 * t as f64).powi(2));
/// assert_eq!(track.running_cost(&[1.0], &[0.0], 10).unwrap(), 0.0);
/// ```
pub struct Objective {
    state_dim: usize,
    action_dim: usize,
    running: CostFn,
    transition: Option<TransitionFn>,
    termination: Option<TerminationFn>,
    terminal: Option<TerminalFn>,
    value: Option<ValueFn>,
    running_derivs: Option<RunningDerivFn>,
    terminal_derivs: Option<TerminalDerivFn>,
    discount: f64,
    model_reward: bool,
}

impl std::fmt::Debug for Objective {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Objective")
            .field("state_dim", &self.state_dim)
            .field("action_dim", &self.action_dim)
            .field("transition_cost", &self.transition.is_some())
            .field("termination", &self.termination.is_some())
            .field("terminal", &self.terminal.is_some())
            .field("terminal_value", &self.value.is_some())
            .field(
                "analytic_running_derivatives",
                &self.running_derivs.is_some(),
            )
            .field(
                "analytic_terminal_derivatives",
                &self.terminal_derivs.is_some(),
            )
            .field("discount", &self.discount)
            .field("model_reward", &self.model_reward)
            .finish()
    }
}

impl Objective {
    /// An objective with running cost `c(x, u)` (the same at every step) for states of length
    /// `state_dim` and actions of length `action_dim`.
    pub fn new(
        state_dim: usize,
        action_dim: usize,
        running: impl Fn(&[f64], &[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        Self::time_varying(state_dim, action_dim, move |x, u, _| running(x, u))
    }

    /// An objective whose running cost `c(x, u, t)` depends on the time step `t` (counted from
    /// the start of the plan; see the module docs).
    pub fn time_varying(
        state_dim: usize,
        action_dim: usize,
        running: impl Fn(&[f64], &[f64], usize) -> f64 + Send + Sync + 'static,
    ) -> Self {
        Self {
            state_dim,
            action_dim,
            running: Box::new(running),
            transition: None,
            termination: None,
            terminal: None,
            value: None,
            running_derivs: None,
            terminal_derivs: None,
            discount: 1.0,
            model_reward: false,
        }
    }

    /// An objective whose running cost is the negated reward, `c(x, u) = −r(x, u)` (p3 eq. 3).
    pub fn from_reward(
        state_dim: usize,
        action_dim: usize,
        reward: impl Fn(&[f64], &[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        Self::new(state_dim, action_dim, move |x, u| -reward(x, u))
    }

    /// An objective whose cost is the negated reward of each transition, `c(x, u, x') =
    /// −r(x, u, x')`, for rewards that depend on where a step lands (a forward velocity).
    pub fn from_transition_reward(
        state_dim: usize,
        action_dim: usize,
        reward: impl Fn(&[f64], &[f64], &[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        Self::new(state_dim, action_dim, |_, _| 0.0)
            .with_transition_cost(move |x, u, next| -reward(x, u, next))
    }

    /// `task`'s reward (negated) and termination as an objective over the task's states, for a
    /// model that predicts them (the plant itself, or a model learned on states). Actions are
    /// the agent's, turned into the plant's input by [`Task::control`] as the environment does.
    /// An error for a task with discrete actions.
    pub fn from_task<T: Task + Send + Sync + 'static>(task: T) -> Result<Self> {
        let state_dim = task.state_dim();
        Self::task_objective(task, state_dim, T::reward, T::terminated)
    }

    /// `task`'s reward (negated) and termination read off observations
    /// ([`ObservedTask`]), as an objective for a model learned on observations (PETS's). An
    /// error for a task with discrete actions.
    pub fn from_task_observations<T: ObservedTask + Send + Sync + 'static>(
        task: T,
    ) -> Result<Self> {
        let obs_dim = task.observation_space().flat_dim();
        Self::task_objective(
            task,
            obs_dim,
            T::observation_reward,
            T::observation_terminated,
        )
    }

    /// The negated `reward(task, x, u, x')` and `terminated(task, x')` of a task over states of
    /// length `state_dim`, the agent's actions turned into plant inputs by [`Task::control`].
    fn task_objective<T: Task + Send + Sync + 'static>(
        task: T,
        state_dim: usize,
        reward: fn(&T, &[f64], &[f64], &[f64]) -> f64,
        terminated: fn(&T, &[f64]) -> bool,
    ) -> Result<Self> {
        let action_dim = continuous_dim(task.id(), task.action_space())?;
        let task = std::sync::Arc::new(task);
        let ends = task.clone();
        Ok(
            Self::from_transition_reward(state_dim, action_dim, move |x, a, next| {
                let u = task.control(&Action::Continuous(a.to_vec()));
                reward(&task, x, &u, next)
            })
            .with_termination(move |next| terminated(&ends, next)),
        )
    }

    /// Adds a transition cost `c(x_h, u_h, x_{h+1})` to every step's cost (see the module docs).
    pub fn with_transition_cost(
        mut self,
        cost: impl Fn(&[f64], &[f64], &[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        self.transition = Some(Box::new(cost));
        self
    }

    /// Ends a rollout's sample at the first state where `terminated` holds: its later steps and
    /// its terminal cost count zero (see the module docs).
    pub fn with_termination(
        mut self,
        terminated: impl Fn(&[f64]) -> bool + Send + Sync + 'static,
    ) -> Self {
        self.termination = Some(Box::new(terminated));
        self
    }

    /// Adds a terminal cost `c_H(x_H)`.
    pub fn with_terminal(
        mut self,
        terminal: impl Fn(&[f64]) -> f64 + Send + Sync + 'static,
    ) -> Self {
        self.terminal = Some(Box::new(terminal));
        self
    }

    /// Adds a terminal value `V` evaluated on a batch of states; the terminal cost gains `−V(x_H)`
    /// (p3 §3: the outer loop's critic as the MPC's terminal cost).
    pub fn with_terminal_value(
        mut self,
        value: impl Fn(ArrayView2<'_, f64>) -> Array1<f64> + Send + Sync + 'static,
    ) -> Self {
        self.value = Some(Box::new(value));
        self
    }

    /// Gives the analytic expansion of the running cost at `(x, u, t)` (otherwise finite
    /// differences).
    pub fn with_running_derivatives(
        mut self,
        d: impl Fn(&[f64], &[f64], usize) -> QuadCost + Send + Sync + 'static,
    ) -> Self {
        self.running_derivs = Some(Box::new(d));
        self
    }

    /// Gives the analytic expansion of the terminal cost (otherwise finite differences). It must
    /// include the terminal value's contribution if one is set.
    pub fn with_terminal_derivatives(
        mut self,
        d: impl Fn(&[f64]) -> QuadTerminal + Send + Sync + 'static,
    ) -> Self {
        self.terminal_derivs = Some(Box::new(d));
        self
    }

    /// Sets the discount `γ ∈ (0, 1]` of p3 eq. 3.
    pub fn with_discount(mut self, gamma: f64) -> Result<Self> {
        if !(gamma > 0.0 && gamma <= 1.0) {
            return Err(PlanError::Config(format!(
                "discount must be in (0, 1], got {gamma}"
            )));
        }
        self.discount = gamma;
        Ok(self)
    }

    /// Adds the model's predicted reward (negated) to the running cost in MPC rollouts, for models
    /// that learn the reward (p3's ensemble predicts `(Δx, r)`). A model that predicts no reward is
    /// then an error.
    pub fn with_model_reward(mut self) -> Self {
        self.model_reward = true;
        self
    }

    /// Length of the state vector.
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// Length of the action vector.
    pub fn action_dim(&self) -> usize {
        self.action_dim
    }

    /// Discount `γ`.
    pub fn discount(&self) -> f64 {
        self.discount
    }

    /// Whether rollouts add the model's predicted reward; see [`Objective::with_model_reward`].
    pub fn uses_model_reward(&self) -> bool {
        self.model_reward
    }

    /// Whether the cost depends only on `(x, u)` at each step and rollouts never end early: what
    /// the trajectory optimizers, which expand costs of `(x, u)`, require. An error naming what
    /// they cannot use otherwise.
    pub fn check_stagewise(&self) -> Result<()> {
        let what = match (&self.transition, &self.termination) {
            (Some(_), _) => "a transition cost c(x, u, x')",
            (None, Some(_)) => "a termination",
            (None, None) => return Ok(()),
        };
        Err(PlanError::Config(format!(
            "this objective has {what}; trajectory optimizers expand costs of (x, u) only, so \
             plan it with a sampling planner (CEM, MPPI, DMD-MPC)"
        )))
    }

    /// Whether rollouts end a sample at a terminal state; see [`Objective::with_termination`].
    pub fn has_termination(&self) -> bool {
        self.termination.is_some()
    }

    /// Adds the transition costs of a batch (`B x S` states, `B x A` actions, `B x S` next
    /// states) at time step `step` to `out` (length `B`); nothing without a transition cost.
    pub fn add_transition_batch(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
        next: ArrayView2<'_, f64>,
        step: usize,
        out: &mut [f64],
    ) -> Result<()> {
        let Some(cost) = &self.transition else {
            return Ok(());
        };
        check_len(
            "objective next states (columns)",
            self.state_dim,
            next.ncols(),
        )?;
        check_len("objective next states (rows)", states.nrows(), next.nrows())?;
        check_len("objective output", states.nrows(), out.len())?;
        let mut xb = vec![0.0; self.state_dim];
        let mut ub = vec![0.0; self.action_dim];
        let mut nb = vec![0.0; self.state_dim];
        for (i, o) in out.iter_mut().enumerate() {
            let x = row_slice(states, i, &mut xb);
            let u = row_slice(actions, i, &mut ub);
            let n = row_slice(next, i, &mut nb);
            *o += finite_cost("transition cost", i, step, cost(x, u, n))?;
        }
        Ok(())
    }

    /// Whether `state` ends a rollout (false without a termination).
    pub fn terminated(&self, state: &[f64]) -> bool {
        self.termination.as_ref().is_some_and(|t| t(state))
    }

    /// Whether a terminal cost or value is set.
    pub fn has_terminal(&self) -> bool {
        self.terminal.is_some() || self.value.is_some()
    }

    /// Running cost at one `(x, u)` at time step `t`; non-finite is an error.
    pub fn running_cost(&self, x: &[f64], u: &[f64], t: usize) -> Result<f64> {
        check_len("objective state", self.state_dim, x.len())?;
        check_len("objective action", self.action_dim, u.len())?;
        let c = (self.running)(x, u, t);
        finite_cost("running cost", 0, t, c)
    }

    /// Running costs of a batch (`B x S` states, `B x A` actions) at time step `step` into `out`
    /// (length `B`).
    pub fn running_batch(
        &self,
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
        step: usize,
        out: &mut [f64],
    ) -> Result<()> {
        check_len("objective states (columns)", self.state_dim, states.ncols())?;
        check_len(
            "objective actions (columns)",
            self.action_dim,
            actions.ncols(),
        )?;
        check_len("objective actions (rows)", states.nrows(), actions.nrows())?;
        check_len("objective output", states.nrows(), out.len())?;
        let mut xb = vec![0.0; self.state_dim];
        let mut ub = vec![0.0; self.action_dim];
        for (i, o) in out.iter_mut().enumerate() {
            let x = row_slice(states, i, &mut xb);
            let u = row_slice(actions, i, &mut ub);
            *o = finite_cost("running cost", i, step, (self.running)(x, u, step))?;
        }
        Ok(())
    }

    /// Terminal costs `c_H(x) − V(x)` of a batch of states into `out`; zero without either.
    pub fn terminal_batch(
        &self,
        states: ArrayView2<'_, f64>,
        step: usize,
        out: &mut [f64],
    ) -> Result<()> {
        check_len("objective states (columns)", self.state_dim, states.ncols())?;
        check_len("objective output", states.nrows(), out.len())?;
        out.iter_mut().for_each(|o| *o = 0.0);
        if let Some(t) = &self.terminal {
            let mut xb = vec![0.0; self.state_dim];
            for (i, o) in out.iter_mut().enumerate() {
                *o = finite_cost("terminal cost", i, step, t(row_slice(states, i, &mut xb)))?;
            }
        }
        if let Some(v) = &self.value {
            let vals = v(states);
            check_len("terminal value output", states.nrows(), vals.len())?;
            for (i, (o, val)) in out.iter_mut().zip(vals.iter()).enumerate() {
                *o -= finite_cost("terminal value", i, step, *val)?;
            }
        }
        Ok(())
    }

    /// Terminal cost of one state.
    pub fn terminal_cost(&self, x: &[f64]) -> Result<f64> {
        check_len("objective state", self.state_dim, x.len())?;
        let mut out = [0.0];
        let view = ArrayView2::from_shape((1, x.len()), x).expect("one row");
        self.terminal_batch(view, 0, &mut out)?;
        Ok(out[0])
    }

    /// Second-order expansion of the running cost at `(x, u)` and time step `t`: analytic when
    /// given, otherwise central finite differences (step `1e-4·max(1, |z_i|)`, about 1e-7
    /// accurate for smooth costs).
    pub fn running_quadratic(&self, x: &[f64], u: &[f64], t: usize) -> Result<QuadCost> {
        self.check_stagewise()?;
        check_len("objective state", self.state_dim, x.len())?;
        check_len("objective action", self.action_dim, u.len())?;
        let (n, m) = (self.state_dim, self.action_dim);
        if let Some(d) = &self.running_derivs {
            let q = d(x, u, t);
            check_len("analytic cx", n, q.cx.len())?;
            check_len("analytic cu", m, q.cu.len())?;
            check_len("analytic cxx", n * n, q.cxx.len())?;
            check_len("analytic cuu", m * m, q.cuu.len())?;
            check_len("analytic cux", m * n, q.cux.len())?;
            finite_cost("running cost", 0, t, q.c)?;
            for (what, s) in [
                ("cost gradient cx", q.cx.as_slice()),
                ("cost gradient cu", q.cu.as_slice()),
                ("cost Hessian cxx", q.cxx.as_slice()),
                ("cost Hessian cuu", q.cuu.as_slice()),
                ("cost Hessian cux", q.cux.as_slice()),
            ] {
                check_finite(what, s)?;
            }
            return Ok(q);
        }
        let z: Vec<f64> = x.iter().chain(u.iter()).copied().collect();
        let (c, g, h) = fd_quadratic(&z, |pts| {
            let mut out = vec![0.0; pts.nrows()];
            let xs = pts.slice(ndarray::s![.., ..n]);
            let us = pts.slice(ndarray::s![.., n..]);
            self.running_batch(xs, us, t, &mut out)?;
            Ok(out)
        })?;
        Ok(QuadCost {
            c,
            cx: g.rows(0, n).into_owned(),
            cu: g.rows(n, m).into_owned(),
            cxx: h.view((0, 0), (n, n)).into_owned(),
            cuu: h.view((n, n), (m, m)).into_owned(),
            cux: h.view((n, 0), (m, n)).into_owned(),
        })
    }

    /// Second-order expansion of the terminal cost (including `−V`) at `x`.
    pub fn terminal_quadratic(&self, x: &[f64]) -> Result<QuadTerminal> {
        self.check_stagewise()?;
        check_len("objective state", self.state_dim, x.len())?;
        let n = self.state_dim;
        if let Some(d) = &self.terminal_derivs {
            let q = d(x);
            check_len("analytic terminal cx", n, q.cx.len())?;
            check_len("analytic terminal cxx", n * n, q.cxx.len())?;
            finite_cost("terminal cost", 0, 0, q.c)?;
            check_finite("terminal gradient", q.cx.as_slice())?;
            check_finite("terminal Hessian", q.cxx.as_slice())?;
            return Ok(q);
        }
        if !self.has_terminal() {
            return Ok(QuadTerminal {
                c: 0.0,
                cx: DVector::zeros(n),
                cxx: DMatrix::zeros(n, n),
            });
        }
        let (c, cx, cxx) = fd_quadratic(x, |pts| {
            let mut out = vec![0.0; pts.nrows()];
            self.terminal_batch(pts, 0, &mut out)?;
            Ok(out)
        })?;
        Ok(QuadTerminal { c, cx, cxx })
    }
}

/// The length of a continuous action space; an error for a discrete one, which planners over
/// action sequences cannot search.
fn continuous_dim(env: &str, space: &Space) -> Result<usize> {
    if space.is_discrete() {
        return Err(PlanError::Config(format!(
            "{env} has discrete actions; the planners search continuous action sequences"
        )));
    }
    Ok(space.flat_dim())
}

fn finite_cost(what: &'static str, sample: usize, step: usize, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(PlanError::NonFiniteCost {
            what,
            sample,
            step,
            value,
        })
    }
}

/// Row `i` of `a` copied into `buf` (rows of strided views are not contiguous).
fn row_slice<'b>(a: ArrayView2<'_, f64>, i: usize, buf: &'b mut [f64]) -> &'b [f64] {
    for (b, v) in buf.iter_mut().zip(a.row(i).iter()) {
        *b = *v;
    }
    buf
}

/// Value, gradient and Hessian of a scalar function at `z` by central differences, evaluating all
/// points in one batch (so a batched terminal value, e.g. a critic network, is called once).
pub(crate) fn fd_quadratic(
    z: &[f64],
    eval: impl Fn(ArrayView2<'_, f64>) -> Result<Vec<f64>>,
) -> Result<(f64, DVector<f64>, DMatrix<f64>)> {
    let d = z.len();
    let h: Vec<f64> = z.iter().map(|v| 1e-4 * v.abs().max(1.0)).collect();
    let npts = 1 + 2 * d + 2 * d * d.saturating_sub(1);
    let mut pts = Array2::zeros((npts, d));
    for mut r in pts.rows_mut() {
        r.iter_mut().zip(z).for_each(|(p, v)| *p = *v);
    }
    let mut k = 1;
    for i in 0..d {
        pts[(k, i)] += h[i];
        pts[(k + 1, i)] -= h[i];
        k += 2;
    }
    for i in 0..d {
        for j in (i + 1)..d {
            for (si, sj) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                pts[(k, i)] += si * h[i];
                pts[(k, j)] += sj * h[j];
                k += 1;
            }
        }
    }
    let f = eval(pts.view())?;
    check_len("finite-difference evaluations", npts, f.len())?;
    let f0 = f[0];
    let mut g = DVector::zeros(d);
    let mut hess = DMatrix::zeros(d, d);
    for i in 0..d {
        let (fp, fm) = (f[1 + 2 * i], f[2 + 2 * i]);
        g[i] = (fp - fm) / (2.0 * h[i]);
        hess[(i, i)] = (fp - 2.0 * f0 + fm) / (h[i] * h[i]);
    }
    let mut k = 1 + 2 * d;
    for i in 0..d {
        for j in (i + 1)..d {
            let v = (f[k] - f[k + 1] - f[k + 2] + f[k + 3]) / (4.0 * h[i] * h[j]);
            hess[(i, j)] = v;
            hess[(j, i)] = v;
            k += 4;
        }
    }
    Ok((f0, g, hess))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use ndarray::array;

    fn nonquadratic() -> Objective {
        Objective::new(2, 1, |x, u| {
            x[0].sin() * x[1] + 0.5 * x[1] * x[1] * u[0] + u[0].powi(4) + (x[0] * u[0]).cos()
        })
        .with_terminal(|x| x[0].powi(2) * x[1].exp())
    }

    #[test]
    fn finite_difference_expansion_matches_hand_derivatives() {
        let obj = nonquadratic();
        let (x, u) = ([0.3, -0.7], [0.4]);
        let q = obj.running_quadratic(&x, &u, 0).unwrap();
        let (x0, x1, u0) = (x[0], x[1], u[0]);
        // Hand-derived derivatives of the running cost.
        let cx = [x0.cos() * x1 - u0 * (x0 * u0).sin(), x0.sin() + x1 * u0];
        let cu = 0.5 * x1 * x1 + 4.0 * u0.powi(3) - x0 * (x0 * u0).sin();
        let cxx = [
            [-x0.sin() * x1 - u0 * u0 * (x0 * u0).cos(), x0.cos()],
            [x0.cos(), u0],
        ];
        let cuu = 12.0 * u0 * u0 - x0 * x0 * (x0 * u0).cos();
        let cux = [-(x0 * u0).sin() - x0 * u0 * (x0 * u0).cos(), x1];
        for i in 0..2 {
            assert_relative_eq!(q.cx[i], cx[i], epsilon = 1e-7);
            assert_relative_eq!(q.cux[(0, i)], cux[i], epsilon = 1e-6);
            for j in 0..2 {
                assert_relative_eq!(q.cxx[(i, j)], cxx[i][j], epsilon = 1e-6);
            }
        }
        assert_relative_eq!(q.cu[0], cu, epsilon = 1e-7);
        assert_relative_eq!(q.cuu[(0, 0)], cuu, epsilon = 1e-6);

        let t = obj.terminal_quadratic(&x).unwrap();
        let e = x1.exp();
        assert_relative_eq!(t.cx[0], 2.0 * x0 * e, epsilon = 1e-7);
        assert_relative_eq!(t.cx[1], x0 * x0 * e, epsilon = 1e-7);
        assert_relative_eq!(t.cxx[(0, 0)], 2.0 * e, epsilon = 1e-6);
        assert_relative_eq!(t.cxx[(0, 1)], 2.0 * x0 * e, epsilon = 1e-6);
        assert_relative_eq!(t.cxx[(1, 1)], x0 * x0 * e, epsilon = 1e-6);
    }

    #[test]
    fn time_varying_cost_sees_the_step_in_batches_and_expansions() {
        // c = (x − t)² u: cx = 2 (x − t) u, cu = (x − t)², cxx = 2u, cuu = 0, cux = 2 (x − t).
        let obj = Objective::time_varying(1, 1, |x, u, t| (x[0] - t as f64).powi(2) * u[0]);
        let s = array![[1.0], [4.0]];
        let a = array![[2.0], [0.5]];
        let mut out = [0.0; 2];
        obj.running_batch(s.view(), a.view(), 3, &mut out).unwrap();
        assert_eq!(out, [8.0, 0.5]);
        assert_eq!(obj.running_cost(&[1.0], &[2.0], 0).unwrap(), 2.0);
        let q = obj.running_quadratic(&[1.0], &[2.0], 3).unwrap();
        assert_relative_eq!(q.c, 8.0, epsilon = 1e-12);
        assert_relative_eq!(q.cx[0], -8.0, epsilon = 1e-7);
        assert_relative_eq!(q.cu[0], 4.0, epsilon = 1e-7);
        assert_relative_eq!(q.cxx[(0, 0)], 4.0, epsilon = 1e-5);
        assert_relative_eq!(q.cuu[(0, 0)], 0.0, epsilon = 1e-5);
        assert_relative_eq!(q.cux[(0, 0)], -4.0, epsilon = 1e-5);
        // Analytic derivatives get the step too.
        let analytic = Objective::time_varying(1, 1, |x, _, t| x[0] * t as f64)
            .with_running_derivatives(|_, _, t| QuadCost {
                c: 0.0,
                cx: DVector::from_element(1, t as f64),
                cu: DVector::zeros(1),
                cxx: DMatrix::zeros(1, 1),
                cuu: DMatrix::zeros(1, 1),
                cux: DMatrix::zeros(1, 1),
            });
        assert_eq!(
            analytic.running_quadratic(&[0.0], &[0.0], 5).unwrap().cx[0],
            5.0
        );
        // A non-finite cost names its step.
        let nan = Objective::time_varying(1, 1, |_, _, t| if t == 4 { f64::NAN } else { 0.0 });
        assert!(matches!(
            nan.running_cost(&[0.0], &[0.0], 4),
            Err(PlanError::NonFiniteCost { step: 4, .. })
        ));
    }

    #[test]
    fn terminal_value_enters_negated_and_batched() {
        let obj = Objective::new(1, 1, |_, _| 0.0)
            .with_terminal(|x| x[0])
            .with_terminal_value(|s| s.column(0).mapv(|v| 3.0 * v * v));
        let s = array![[1.0], [2.0]];
        let mut out = [0.0; 2];
        obj.terminal_batch(s.view(), 0, &mut out).unwrap();
        assert_eq!(out, [1.0 - 3.0, 2.0 - 12.0]);
        let t = obj.terminal_quadratic(&[2.0]).unwrap();
        assert_relative_eq!(t.cx[0], 1.0 - 12.0, epsilon = 1e-7);
        assert_relative_eq!(t.cxx[(0, 0)], -6.0, epsilon = 1e-5);
    }

    #[test]
    fn non_finite_costs_and_bad_dims_are_errors() {
        let obj = Objective::new(1, 1, |x, _| if x[0] > 0.0 { f64::NAN } else { 0.0 });
        let s = array![[-1.0], [1.0]];
        let a = array![[0.0], [0.0]];
        let mut out = [0.0; 2];
        let err = obj
            .running_batch(s.view(), a.view(), 7, &mut out)
            .unwrap_err();
        assert!(matches!(
            err,
            PlanError::NonFiniteCost {
                sample: 1,
                step: 7,
                ..
            }
        ));
        assert!(matches!(
            obj.running_cost(&[0.0, 1.0], &[0.0], 0),
            Err(PlanError::Dim { .. })
        ));
        assert!(Objective::new(1, 1, |_, _| 0.0).with_discount(1.5).is_err());
    }
}
