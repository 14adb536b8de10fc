//! Iterative LQR (Li & Todorov 2004; regularization and line search after Tassa, Erez & Todorov
//! 2012, "Synthesis and stabilization of complex behaviors"; p4 ref. [18]).
//!
//! One iteration, in the order [`Ilqr::solve`] runs it (Crocoddyl's `computeDirection`,
//! `tryStep`, `stoppingCriteria`):
//! 1. **linearize** the model along the nominal trajectory ([`DynamicsModel::linearize`]: the
//!    plant's own Jacobians for a `PlantModel`, finite differences of one batched `predict`
//!    otherwise) and expand the cost to second order ([`Objective::running_quadratic`], at each
//!    step's time index);
//! 2. **backward pass** ([`backward_pass`]): the Riccati-like recursion for the feedforward
//!    `k_t` and gains `K_t`, with `μ I` added to `Q_uu` (if it is not positive definite the pass
//!    fails and `μ` grows by Tassa's schedule); control bounds by one active-set pass of the
//!    box-QP of Tassa et al. 2014 (bounded components keep their clamped step and get no
//!    feedback; the free ones are re-solved);
//! 3. **forward pass**: all line-search step sizes `α` in one batched rollout,
//!    `u = clamp(ū + α k + K (x − x̄))`, accepting the largest `α` whose actual decrease is at
//!    least `c₁` times the predicted one;
//! 4. **stop** when the relative decrease falls below `tolerance`.
//!
//! A model that reads the previous action (p1's incremental model) has it in its state,
//! `z_t = [x_t; u_{t−1}]`: its Jacobians are `A = [[f_x, f_{u_prev}], [0, 0]]`,
//! `B = [[f_u], [I]]`, and the feedback acts on both parts, with nothing special here.

use nalgebra::{DMatrix, DVector};
use ndarray::{s, Array1, Array2, ArrayView2};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_models::DynamicsModel;

use tandem_models::ModelInput;

use crate::error::{check_len, PlanError, Result};
use crate::mpc::{
    check_problem, fill_normal, nonzero, positive, warm_start, Bounds, Plan, Planner,
};
use crate::objective::Objective;

/// Settings of [`Ilqr`]. Defaults follow Tassa et al. 2012 (regularization `μ_min = 1e-6`,
/// factor `Δ₀ = 2`, step sizes `α = 10^{0, −0.3, …, −3}`, acceptance `c₁ = 0.1`... in their
/// paper `0 < c₁`; we take 0.1 as Crocoddyl does with its `th_acceptStep`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IlqrConfig {
    /// Horizon `T` (used when planning as MPC; [`Ilqr::solve`] takes it from the initial guess).
    pub horizon: usize,
    /// Iterations per solve.
    pub max_iterations: usize,
    /// Stop when the relative cost decrease of an accepted step is below this.
    pub tolerance: f64,
    /// Initial regularization `μ`.
    pub mu_init: f64,
    /// Smallest non-zero `μ` (below it `μ` becomes 0).
    pub mu_min: f64,
    /// Largest `μ` before giving up.
    pub mu_max: f64,
    /// Growth factor `Δ₀` of the regularization schedule.
    pub mu_factor: f64,
    /// Number of line-search step sizes, `α_i = 10^{−3 i / (n − 1)}`.
    pub line_search_steps: usize,
    /// Accept a step when actual decrease ≥ `c₁` · predicted decrease.
    pub accept_ratio: f64,
    /// Standard deviation of the seeded noise added to a cold-start guess of zeros (breaks the
    /// symmetry of, e.g., a pendulum hanging exactly still).
    pub init_std: f64,
    /// Control bounds.
    pub bounds: Option<Bounds>,
    /// Seed of the cold-start noise and of stochastic models.
    pub seed: u64,
}

impl Default for IlqrConfig {
    fn default() -> Self {
        Self {
            horizon: 50,
            max_iterations: 100,
            tolerance: 1e-7,
            mu_init: 1e-6,
            mu_min: 1e-6,
            mu_max: 1e10,
            mu_factor: 2.0,
            line_search_steps: 11,
            accept_ratio: 0.1,
            init_std: 0.0,
            bounds: None,
            seed: 0,
        }
    }
}

/// A solved trajectory with its time-varying feedback law `u = ū_t + K_t (x − x̄_t)`.
#[derive(Debug, Clone, PartialEq)]
pub struct IlqrSolution {
    /// Nominal states `x̄_0 .. x̄_T`, `(T+1) x S`.
    pub states: Array2<f64>,
    /// Nominal actions `ū_0 .. ū_{T−1}`, `T x A`.
    pub actions: Array2<f64>,
    /// Feedback gains `K_t` (`A x S`) of the last backward pass.
    pub gains: Vec<DMatrix<f64>>,
    /// Objective value of the nominal trajectory.
    pub cost: f64,
    /// Cost after each accepted iteration (first entry: the initial guess).
    pub cost_history: Vec<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the relative decrease fell below the tolerance.
    pub converged: bool,
}

impl IlqrSolution {
    /// The feedback law at step `t`: `ū_t + K_t (x − x̄_t)`, clamped into `bounds`.
    pub fn control(&self, t: usize, x: &[f64], bounds: Option<&Bounds>) -> Vec<f64> {
        let n = self.states.ncols();
        let dx = DVector::from_iterator(
            n,
            x.iter().zip(self.states.row(t).iter()).map(|(a, b)| a - b),
        );
        let du = &self.gains[t] * dx;
        let mut u: Vec<f64> = self
            .actions
            .row(t)
            .iter()
            .zip(du.iter())
            .map(|(a, b)| a + b)
            .collect();
        if let Some(b) = bounds {
            b.clamp(&mut u);
        }
        u
    }
}

/// Output of one backward pass.
#[derive(Debug, Clone)]
pub struct BackwardPass {
    /// Feedforward steps `k_t`.
    pub k: Vec<DVector<f64>>,
    /// Gains `K_t`.
    pub gains: Vec<DMatrix<f64>>,
    /// Predicted decrease terms: `ΔJ(α) = −(α d1 + α² d2)`.
    pub d1: f64,
    /// See `d1`.
    pub d2: f64,
}

/// Iterative LQR; see the module docs. Also a receding-horizon [`Planner`] (warm-started by
/// shifting the previous solution).
#[derive(Debug, Clone)]
pub struct Ilqr {
    cfg: IlqrConfig,
    rng: Rng,
    warm: Option<Array2<f64>>,
}

impl Ilqr {
    /// An optimizer with these settings (checked here).
    pub fn new(cfg: IlqrConfig) -> Result<Self> {
        nonzero("horizon", cfg.horizon)?;
        nonzero("max_iterations", cfg.max_iterations)?;
        nonzero("line_search_steps", cfg.line_search_steps)?;
        positive("mu_max", cfg.mu_max)?;
        positive("mu_min", cfg.mu_min)?;
        if cfg.mu_factor <= 1.0 {
            return Err(PlanError::Config(format!(
                "mu_factor must exceed 1, got {}",
                cfg.mu_factor
            )));
        }
        if !(cfg.mu_init >= 0.0 && cfg.tolerance >= 0.0 && cfg.init_std >= 0.0) {
            return Err(PlanError::Config(
                "mu_init, tolerance and init_std must be non-negative".into(),
            ));
        }
        let rng = rng_from_seed(cfg.seed);
        Ok(Self {
            cfg,
            rng,
            warm: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &IlqrConfig {
        &self.cfg
    }

    /// Optimizes the action sequence `init` (`T x A`) from `x0` through `model`. A stochastic
    /// model is evaluated with a generator restarted from the configured seed at every
    /// step, so repeated evaluations agree.
    pub fn solve(
        &self,
        model: &dyn DynamicsModel,
        objective: &Objective,
        x0: &[f64],
        init: &Array2<f64>,
    ) -> Result<IlqrSolution> {
        let (_, m) = check_problem(x0, model, objective)?;
        check_len("initial actions (columns)", m, init.ncols())?;
        nonzero("horizon of the initial guess", init.nrows())?;
        let dynamics = System {
            model,
            seed: self.cfg.seed,
        };
        if init.iter().any(|v| !v.is_finite()) {
            return Err(PlanError::NonFinite("initial actions".into()));
        }
        if let Some(b) = &self.cfg.bounds {
            b.validate(m)?;
        }
        let cfg = &self.cfg;
        let mut us = init.clone();
        if let Some(b) = &cfg.bounds {
            b.clamp_rows(us.view_mut());
        }
        let (mut xs, mut cost) = rollout(&dynamics, objective, x0, &us)?;
        let mut history = vec![cost];
        let mut mu = cfg.mu_init;
        let mut delta = 1.0;
        let mut gains = Vec::new();
        let mut converged = false;
        let mut iterations = 0;
        let alphas: Vec<f64> = (0..cfg.line_search_steps)
            .map(|i| {
                if cfg.line_search_steps == 1 {
                    1.0
                } else {
                    10f64.powf(-3.0 * i as f64 / (cfg.line_search_steps - 1) as f64)
                }
            })
            .collect();
        while iterations < cfg.max_iterations {
            iterations += 1;
            // 1. Linearize.
            let jac = dynamics.jacobians(xs.slice(s![..-1, ..]), &us)?;
            let quad = expand_cost(objective, &xs, &us)?;
            // 2. Backward pass, raising μ until Q_uu is positive definite.
            let bp = loop {
                match backward_pass(&jac, &quad, &us, mu, cfg.bounds.as_ref()) {
                    Some(bp) => break Some(bp),
                    None => {
                        delta = (delta * cfg.mu_factor).max(cfg.mu_factor);
                        mu = (mu * delta).max(cfg.mu_min);
                        if mu > cfg.mu_max {
                            break None;
                        }
                    }
                }
            };
            let Some(bp) = bp else {
                return Err(PlanError::Numerical(format!(
                    "iLQR: Q_uu not positive definite even with regularization {:e}",
                    cfg.mu_max
                )));
            };
            // 3. Forward pass over all step sizes at once.
            let (cand_xs, cand_us, cand_cost) = forward_batch(
                &dynamics,
                objective,
                x0,
                &xs,
                &us,
                &bp,
                &alphas,
                cfg.bounds.as_ref(),
            )?;
            let mut accepted = None;
            for (i, &al) in alphas.iter().enumerate() {
                let expected = al * bp.d1 + al * al * bp.d2;
                let actual = cost - cand_cost[i];
                let ok = if expected < 0.0 {
                    actual > cfg.accept_ratio * -expected
                } else {
                    actual > 0.0
                };
                if ok && cand_cost[i].is_finite() {
                    accepted = Some(i);
                    break;
                }
            }
            gains = bp.gains;
            match accepted {
                Some(i) => {
                    let rel = (cost - cand_cost[i]) / cost.abs().max(1e-12);
                    xs = cand_xs[i].clone();
                    us = cand_us[i].clone();
                    cost = cand_cost[i];
                    history.push(cost);
                    // Decrease μ (Tassa et al. 2012, §II-F).
                    delta = (delta / cfg.mu_factor).min(1.0 / cfg.mu_factor);
                    mu *= delta;
                    if mu < cfg.mu_min {
                        mu = 0.0;
                    }
                    // 4. Stopping criterion.
                    if rel < cfg.tolerance {
                        converged = true;
                        break;
                    }
                }
                None => {
                    // No decrease: either converged (tiny predicted decrease) or regularize more.
                    if -(bp.d1 + bp.d2) < cfg.tolerance * cost.abs().max(1e-12) {
                        converged = true;
                        break;
                    }
                    delta = (delta * cfg.mu_factor).max(cfg.mu_factor);
                    mu = (mu * delta).max(cfg.mu_min);
                    if mu > cfg.mu_max {
                        break;
                    }
                }
            }
        }
        Ok(IlqrSolution {
            states: xs,
            actions: us,
            gains,
            cost,
            cost_history: history,
            iterations,
            converged,
        })
    }
}

/// The model as iLQR sees it: batched steps with the generator restarted from `seed` at every
/// call, and Jacobians.
struct System<'a> {
    model: &'a dyn DynamicsModel,
    seed: u64,
}

impl System<'_> {
    /// One step of a batch.
    fn step_batch<'v>(
        &self,
        states: ArrayView2<'v, f64>,
        actions: ArrayView2<'v, f64>,
    ) -> Result<Array2<f64>> {
        if states.iter().chain(actions.iter()).any(|v| !v.is_finite()) {
            return Err(PlanError::NonFinite(
                "states or actions given to the model".into(),
            ));
        }
        let input = ModelInput::new(states, actions);
        Ok(crate::mpc::predict(self.model, &input, &mut rng_from_seed(self.seed))?.next_states)
    }

    /// `(A_t, B_t)` of the backward pass along `(xs, us)`: the model's Jacobians.
    fn jacobians(
        &self,
        xs: ArrayView2<'_, f64>,
        us: &Array2<f64>,
    ) -> Result<Vec<(DMatrix<f64>, DMatrix<f64>)>> {
        let input = ModelInput::new(xs.view(), us.view());
        let lin = self
            .model
            .linearize(&input, &mut rng_from_seed(self.seed))?;
        check_len("model linearizations", xs.nrows(), lin.len())?;
        let (n, m) = (xs.ncols(), us.ncols());
        lin.into_iter()
            .map(|l| {
                check_len("Jacobian A entries", n * n, l.a.len())?;
                check_len("Jacobian B entries", n * m, l.b.len())?;
                Ok((l.a, l.b))
            })
            .collect()
    }
}

/// Rolls `us` out from `x0` (one step per call) and returns the states and the objective value.
fn rollout(
    dynamics: &System<'_>,
    objective: &Objective,
    x0: &[f64],
    us: &Array2<f64>,
) -> Result<(Array2<f64>, f64)> {
    let alphas = [0.0];
    let (t_len, m) = us.dim();
    let n = x0.len();
    let xs = Array2::zeros((t_len + 1, n));
    let bp = BackwardPass {
        k: vec![DVector::zeros(m); t_len],
        gains: vec![DMatrix::zeros(m, n); t_len],
        d1: 0.0,
        d2: 0.0,
    };
    let (mut cx, _, cc) = forward_batch(dynamics, objective, x0, &xs, us, &bp, &alphas, None)?;
    Ok((cx.pop().expect("one candidate"), cc[0]))
}

/// Second-order cost expansions along a trajectory, discounted by `γ^t`; the last entry holds the
/// terminal expansion in `cx`/`cxx` (its `u` parts are empty).
pub(crate) fn expand_cost(
    objective: &Objective,
    xs: &Array2<f64>,
    us: &Array2<f64>,
) -> Result<Vec<crate::objective::QuadCost>> {
    let t_len = us.nrows();
    let g = objective.discount();
    let mut out = Vec::with_capacity(t_len + 1);
    let mut w = 1.0;
    for t in 0..t_len {
        let x = xs.row(t).to_vec();
        let u = us.row(t).to_vec();
        let mut q = objective.running_quadratic(&x, &u, t)?;
        if w != 1.0 {
            q.c *= w;
            q.cx *= w;
            q.cu *= w;
            q.cxx *= w;
            q.cuu *= w;
            q.cux *= w;
        }
        out.push(q);
        w *= g;
    }
    let term = objective.terminal_quadratic(&xs.row(t_len).to_vec())?;
    out.push(crate::objective::QuadCost {
        c: w * term.c,
        cx: term.cx * w,
        cu: DVector::zeros(0),
        cxx: term.cxx * w,
        cuu: DMatrix::zeros(0, 0),
        cux: DMatrix::zeros(0, xs.ncols()),
    });
    Ok(out)
}

/// The iLQR backward pass with `μ I` on `Q_uu` and an active-set pass for bounds; `None` when
/// `Q_uu + μ I` is not positive definite at some step.
pub fn backward_pass(
    jac: &[(DMatrix<f64>, DMatrix<f64>)],
    quad: &[crate::objective::QuadCost],
    us: &Array2<f64>,
    mu: f64,
    bounds: Option<&Bounds>,
) -> Option<BackwardPass> {
    let t_len = jac.len();
    let m = us.ncols();
    let mut vx = quad[t_len].cx.clone();
    let mut vxx = quad[t_len].cxx.clone();
    let mut ks = vec![DVector::zeros(m); t_len];
    let mut gs = vec![DMatrix::zeros(m, vx.len()); t_len];
    let (mut d1, mut d2) = (0.0, 0.0);
    for t in (0..t_len).rev() {
        let (a, b) = &jac[t];
        let q = &quad[t];
        let qx = &q.cx + a.transpose() * &vx;
        let qu = &q.cu + b.transpose() * &vx;
        let vxx_a = &vxx * a;
        let qxx = &q.cxx + a.transpose() * &vxx_a;
        let quu = &q.cuu + b.transpose() * &vxx * b;
        let qux = &q.cux + b.transpose() * &vxx_a;
        let quu_reg = &quu + DMatrix::identity(m, m) * mu;
        let chol = quu_reg.clone().cholesky()?;
        let mut k = -chol.solve(&qu);
        let mut g = -chol.solve(&qux);
        if let Some(bd) = bounds {
            let u = us.row(t);
            let clamped: Vec<bool> = (0..m)
                .map(|j| {
                    let target = u[j] + k[j];
                    target < bd.low[j] || target > bd.high[j]
                })
                .collect();
            if clamped.iter().any(|&c| c) {
                let free: Vec<usize> = (0..m).filter(|&j| !clamped[j]).collect();
                let cl: Vec<usize> = (0..m).filter(|&j| clamped[j]).collect();
                let mut kc = DVector::zeros(cl.len());
                for (i, &j) in cl.iter().enumerate() {
                    kc[i] = (u[j] + k[j]).clamp(bd.low[j], bd.high[j]) - u[j];
                }
                k = DVector::zeros(m);
                g = DMatrix::zeros(m, g.ncols());
                for (i, &j) in cl.iter().enumerate() {
                    k[j] = kc[i];
                }
                if !free.is_empty() {
                    let qff = quu_reg.select_rows(&free).select_columns(&free);
                    let qfc = quu_reg.select_rows(&free).select_columns(&cl);
                    let cf = qff.cholesky()?;
                    let rhs = qu.select_rows(&free) + qfc * &kc;
                    let kf = -cf.solve(&rhs);
                    let gf = -cf.solve(&qux.select_rows(&free));
                    for (i, &j) in free.iter().enumerate() {
                        k[j] = kf[i];
                        g.set_row(j, &gf.row(i));
                    }
                }
            }
        }
        d1 += (k.transpose() * &qu)[0];
        d2 += 0.5 * (k.transpose() * &quu * &k)[0];
        vx = &qx + g.transpose() * &quu * &k + g.transpose() * &qu + qux.transpose() * &k;
        vxx = &qxx + g.transpose() * &quu * &g + g.transpose() * &qux + qux.transpose() * &g;
        vxx = (&vxx + vxx.transpose()) * 0.5;
        ks[t] = k;
        gs[t] = g;
    }
    Some(BackwardPass {
        k: ks,
        gains: gs,
        d1,
        d2,
    })
}

/// Candidate trajectories of a forward pass: states, actions, objective values.
type Candidates = (Vec<Array2<f64>>, Vec<Array2<f64>>, Vec<f64>);

/// Rolls out `u = clamp(ū + α k + K (x − x̄))` for every `α` at once (one batched step per time
/// step); returns the candidates' states, actions and objective values.
#[allow(clippy::too_many_arguments)]
fn forward_batch(
    dynamics: &System<'_>,
    objective: &Objective,
    x0: &[f64],
    xs: &Array2<f64>,
    us: &Array2<f64>,
    bp: &BackwardPass,
    alphas: &[f64],
    bounds: Option<&Bounds>,
) -> Result<Candidates> {
    let (t_len, m) = us.dim();
    let n = x0.len();
    let nb = alphas.len();
    let mut cand_x = vec![Array2::zeros((t_len + 1, n)); nb];
    let mut cand_u = vec![Array2::zeros((t_len, m)); nb];
    let mut cost = Array1::zeros(nb);
    let mut cur = Array2::zeros((nb, n));
    for mut r in cur.rows_mut() {
        r.assign(&ndarray::ArrayView1::from(x0));
    }
    let mut act = Array2::zeros((nb, m));
    let mut step_cost = vec![0.0; nb];
    let g = objective.discount();
    let mut w = 1.0;
    for t in 0..t_len {
        for b in 0..nb {
            cand_x[b].row_mut(t).assign(&cur.row(b));
            for j in 0..m {
                let mut v = us[(t, j)] + alphas[b] * bp.k[t][j];
                for i in 0..n {
                    v += bp.gains[t][(j, i)] * (cur[(b, i)] - xs[(t, i)]);
                }
                act[(b, j)] = v;
            }
            if let Some(bd) = bounds {
                bd.clamp(act.row_mut(b).as_slice_mut().expect("contiguous row"));
            }
            cand_u[b].row_mut(t).assign(&act.row(b));
        }
        objective.running_batch(cur.view(), act.view(), t, &mut step_cost)?;
        cost.zip_mut_with(&Array1::from(step_cost.clone()), |c, s| *c += w * s);
        cur = dynamics.step_batch(cur.view(), act.view())?;
        w *= g;
    }
    for b in 0..nb {
        cand_x[b].row_mut(t_len).assign(&cur.row(b));
    }
    if objective.has_terminal() {
        let mut term = vec![0.0; nb];
        objective.terminal_batch(cur.view(), t_len, &mut term)?;
        for b in 0..nb {
            cost[b] += w * term[b];
        }
    }
    Ok((cand_x, cand_u, cost.to_vec()))
}

impl Planner for Ilqr {
    fn plan(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
    ) -> Result<Plan> {
        let (_, a) = check_problem(x0, model, objective)?;
        let h = self.cfg.horizon;
        let cold = !matches!(&self.warm, Some(w) if w.dim() == (h, a));
        let mut init = warm_start(self.warm.take(), h, a, self.cfg.bounds.as_ref());
        if cold && self.cfg.init_std > 0.0 {
            // Seeded noise around the cold start (see `IlqrConfig::init_std`).
            let mut z = Array2::zeros((h, a));
            fill_normal(&mut self.rng, z.as_slice_mut().expect("standard layout"));
            z *= self.cfg.init_std;
            init += &z;
        }
        let sol = self.solve(model, objective, x0, &init)?;
        let mut rng = rng_from_seed(self.cfg.seed);
        let plan = crate::mpc::plan_from_actions(x0, model, objective, &mut rng, &sol.actions)?;
        self.warm = Some(sol.actions);
        Ok(plan)
    }

    fn reset(&mut self) {
        self.warm = None;
        self.rng = rng_from_seed(self.cfg.seed);
    }
}
