//! Time-varying linear-Gaussian (TVLG) controllers `u = K_t x + k_t + chol(Σ_t) ξ` (p4 §II,
//! eq. 6), sampling with stored noise (the reparametrization of p4 §III-C), and the pieces the
//! TVLG optimizers share: trajectory samples with costs-to-go, quadratic cost approximations, and
//! moments of a controller under fitted TVLG dynamics.

use nalgebra::{DMatrix, DVector};
use ndarray::{s, Array2, Array3};
use tandem_core::Rng;
use tandem_models::{DynamicsModel, ModelInput, TvlgDynamics};

use crate::error::{check_len, PlanError, Result};
use crate::mpc::fill_normal;
use crate::objective::{Objective, QuadCost};

/// A TVLG controller `p(u_t | x_t) = N(K_t x_t + k_t, Σ_t)`, `t = 0..T`.
///
/// Serialized as its gains, offsets and covariances; reading it back goes through
/// [`TvlgController::new`], which checks them and recomputes the factors bit for bit (the
/// covariances it keeps are already symmetric).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(into = "TvlgParts", try_from = "TvlgParts")]
pub struct TvlgController {
    /// Gains `K_t` (`A x S`).
    pub gains: Vec<DMatrix<f64>>,
    /// Offsets `k_t` (`A`).
    pub offsets: Vec<DVector<f64>>,
    /// Covariances `Σ_t` (`A x A`).
    pub cov: Vec<DMatrix<f64>>,
    chol: Vec<DMatrix<f64>>,
    inv_cov: Vec<DMatrix<f64>>,
}

/// What a [`TvlgController`] is serialized as.
#[derive(serde::Serialize, serde::Deserialize)]
struct TvlgParts {
    gains: Vec<DMatrix<f64>>,
    offsets: Vec<DVector<f64>>,
    cov: Vec<DMatrix<f64>>,
}

impl From<TvlgController> for TvlgParts {
    fn from(c: TvlgController) -> Self {
        Self {
            gains: c.gains,
            offsets: c.offsets,
            cov: c.cov,
        }
    }
}

impl TryFrom<TvlgParts> for TvlgController {
    type Error = PlanError;
    fn try_from(p: TvlgParts) -> Result<Self> {
        Self::new(p.gains, p.offsets, p.cov)
    }
}

impl TvlgController {
    /// A controller from its parts; every `Σ_t` must be symmetric positive definite.
    pub fn new(
        gains: Vec<DMatrix<f64>>,
        offsets: Vec<DVector<f64>>,
        cov: Vec<DMatrix<f64>>,
    ) -> Result<Self> {
        let t_len = gains.len();
        if t_len == 0 {
            return Err(PlanError::Config(
                "a TVLG controller needs at least one step".into(),
            ));
        }
        check_len("controller offsets", t_len, offsets.len())?;
        check_len("controller covariances", t_len, cov.len())?;
        let (m, n) = gains[0].shape();
        let mut chol = Vec::with_capacity(t_len);
        let mut inv_cov = Vec::with_capacity(t_len);
        for t in 0..t_len {
            check_len("gain rows", m, gains[t].nrows())?;
            check_len("gain columns", n, gains[t].ncols())?;
            check_len("offset length", m, offsets[t].len())?;
            check_len("covariance size", m * m, cov[t].len())?;
            if gains[t]
                .iter()
                .chain(offsets[t].iter())
                .chain(cov[t].iter())
                .any(|v| !v.is_finite())
            {
                return Err(PlanError::NonFinite(format!(
                    "controller parameters at step {t}"
                )));
            }
            let sym = (&cov[t] + cov[t].transpose()) * 0.5;
            let c = sym.clone().cholesky().ok_or_else(|| {
                PlanError::Numerical(format!(
                    "controller covariance at step {t} is not positive definite"
                ))
            })?;
            inv_cov.push(c.inverse());
            chol.push(c.l());
        }
        let cov = cov.iter().map(|c| (c + c.transpose()) * 0.5).collect();
        Ok(Self {
            gains,
            offsets,
            cov,
            chol,
            inv_cov,
        })
    }

    /// `K = 0`, `k = k0`, `Σ = variance · I` for `horizon` steps: the usual initial controller.
    pub fn constant(horizon: usize, state_dim: usize, k0: &[f64], variance: f64) -> Result<Self> {
        crate::mpc::positive("initial variance", variance)?;
        let m = k0.len();
        Self::new(
            vec![DMatrix::zeros(m, state_dim); horizon],
            vec![DVector::from_column_slice(k0); horizon],
            vec![DMatrix::identity(m, m) * variance; horizon],
        )
    }

    /// GPS's initial controller (`init_lqr` in cbfinn/gps,
    /// `python/gps/algorithm/policy/lin_gauss_init.py`): the LQR controller that holds `x0` on
    /// guessed double-integrator dynamics under a stiffness cost, with `Σ_t = Q_uu,t⁻¹`, so that
    /// the initial exploration is wide where an action moves the joints little and scales with
    /// `cfg.variance`.
    ///
    /// Each action `j` drives one joint whose angle is `x[cfg.positions[j]]` and velocity
    /// `x[cfg.velocities[j]]`: `a_j = gain_j u_j + acc_j`, `q' = q + dt v + dt² a`, `v' = v + dt a`
    /// (GPS's `guess_dynamics`); every other state entry has zero cost and a zero row in the
    /// guessed dynamics (as GPS's), so the controller's gains on it are zero. The cost per step is
    /// `½ (z − z₀)ᵀ L (z − z₀)` with `z = [x; u]`, `z₀ = [x0; 0]` and
    /// `L = diag(stiffness on the angles, stiffness · stiffness_vel on the velocities, 1 on the
    /// actions) / variance`, times `final_weight` at the last step `T − 1`.
    ///
    /// GPS assumes that the first `dU` state entries are the joint angles and the next `dU` their
    /// velocities ("TODO: Use packing instead of assuming which indices are the joint angles").
    /// Our states are MuJoCo's `qpos ++ qvel`, where unactuated coordinates sit among them (the
    /// pusher's block `x, y` after the four arm joints, the door's hinge after the six), so the
    /// indices are explicit here.
    ///
    /// Errors: settings out of range or of the wrong length for `x0` and the `action_dim`
    /// ([`InitLqr::check`]), a zero horizon, or a non-finite `x0`.
    pub fn init_lqr(cfg: &InitLqr, x0: &[f64], action_dim: usize, horizon: usize) -> Result<Self> {
        let (n, m) = (x0.len(), action_dim);
        cfg.check(n, m)?;
        crate::mpc::nonzero("init_lqr horizon", horizon)?;
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(PlanError::NonFinite("init_lqr's x0".into()));
        }
        let gain = |j: usize| cfg.gains.get(j).copied().unwrap_or(1.0);
        let acc = |j: usize| cfg.acc.get(j).copied().unwrap_or(0.0);
        let dt = cfg.dt;
        // Guessed dynamics x' = F [x; u] + f.
        let mut f = DMatrix::zeros(n, n + m);
        let mut fc = DVector::zeros(n);
        for (j, (&p, &v)) in cfg.positions.iter().zip(&cfg.velocities).enumerate() {
            f[(p, p)] = 1.0;
            f[(p, v)] = dt;
            f[(p, n + j)] = dt * dt * gain(j);
            fc[p] = dt * dt * acc(j);
            f[(v, v)] = 1.0;
            f[(v, n + j)] = dt * gain(j);
            fc[v] = dt * acc(j);
        }
        // The stiffness cost around [x0; 0].
        let mut l = DVector::zeros(n + m);
        for (&p, &v) in cfg.positions.iter().zip(&cfg.velocities) {
            l[p] = cfg.stiffness;
            l[v] = cfg.stiffness * cfg.stiffness_vel;
        }
        l.rows_mut(n, m).fill(1.0);
        let ltt = DMatrix::from_diagonal(&(l / cfg.variance));
        let mut z0 = DVector::zeros(n + m);
        z0.rows_mut(0, n).copy_from_slice(x0);
        let lt = -(&ltt * z0);
        let (mut vxx, mut vx) = (DMatrix::<f64>::zeros(n, n), DVector::<f64>::zeros(n));
        let mut gains = vec![DMatrix::zeros(m, n); horizon];
        let mut offsets = vec![DVector::zeros(m); horizon];
        let mut cov = vec![DMatrix::zeros(m, m); horizon];
        for t in (0..horizon).rev() {
            let w = if t + 1 == horizon {
                cfg.final_weight
            } else {
                1.0
            };
            let qtt = &ltt * w + f.transpose() * &vxx * &f;
            let qt = &lt * w + f.transpose() * (&vx + &vxx * &fc);
            let quu = qtt.view((n, n), (m, m)).into_owned();
            let chol = quu.cholesky().ok_or_else(|| {
                PlanError::Numerical(format!(
                    "init_lqr: Q_uu at step {t} is not positive definite"
                ))
            })?;
            let step = lqr_step(&chol, &qtt, &qt, n);
            (vxx, vx) = (step.vxx, step.vx);
            (gains[t], offsets[t], cov[t]) = (step.gain, step.offset, step.cov);
        }
        Self::new(gains, offsets, cov)
    }

    /// Horizon `T`.
    pub fn horizon(&self) -> usize {
        self.gains.len()
    }
    /// Length of the state.
    pub fn state_dim(&self) -> usize {
        self.gains[0].ncols()
    }
    /// Length of the action.
    pub fn action_dim(&self) -> usize {
        self.gains[0].nrows()
    }
    /// Lower Cholesky factor of `Σ_t`.
    pub fn chol(&self, t: usize) -> &DMatrix<f64> {
        &self.chol[t]
    }
    /// `Σ_t⁻¹`.
    pub fn inv_cov(&self, t: usize) -> &DMatrix<f64> {
        &self.inv_cov[t]
    }
    /// Mean action `K_t x + k_t`.
    pub fn mean(&self, t: usize, x: &DVector<f64>) -> DVector<f64> {
        &self.gains[t] * x + &self.offsets[t]
    }
    /// The action for noise `ξ ~ N(0, I)`: `K_t x + k_t + chol(Σ_t) ξ` (p4 eq. 6).
    pub fn act(&self, t: usize, x: &DVector<f64>, xi: &DVector<f64>) -> DVector<f64> {
        self.mean(t, x) + &self.chol[t] * xi
    }
}

/// The settings of GPS's LQR initial controller ([`TvlgController::init_lqr`]). The defaults of
/// the optional fields are GPS's `INIT_LG_LQR` (`python/gps/algorithm/policy/config.py`):
/// variance 1, stiffness 1, velocity stiffness 0.5, final weight 1, gains 1, accelerations 0.
/// The authors' p4 experiments (`experiments/mjc_gripper_pusher_pilqr/hyperparams.py`,
/// `mjc_door_opening_pilqr/hyperparams.py`) used variance 10 and gains `1 / their motor gains`
/// at `dt = 0.05`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitLqr {
    /// Per action, the acceleration a unit action gives its joint (`init_gains`); empty: all 1.
    #[serde(default)]
    pub gains: Vec<f64>,
    /// Per action, a constant acceleration of its joint (`init_acc`); empty: all 0.
    #[serde(default)]
    pub acc: Vec<f64>,
    /// `init_var`: divides the whole cost, so `Σ` scales with it (and the gains do not).
    #[serde(default = "InitLqr::default_variance")]
    pub variance: f64,
    /// Weight of the joint angles' distance from `x0`.
    #[serde(default = "InitLqr::default_stiffness")]
    pub stiffness: f64,
    /// Weight of the joint velocities, relative to `stiffness`.
    #[serde(default = "InitLqr::default_stiffness_vel")]
    pub stiffness_vel: f64,
    /// Multiplier of the last step's cost.
    #[serde(default = "InitLqr::default_final_weight")]
    pub final_weight: f64,
    /// The control period of the guessed dynamics (s).
    pub dt: f64,
    /// Per action, the state index of its joint's angle.
    pub positions: Vec<usize>,
    /// Per action, the state index of its joint's velocity.
    pub velocities: Vec<usize>,
}

impl InitLqr {
    fn default_variance() -> f64 {
        1.0
    }
    fn default_stiffness() -> f64 {
        1.0
    }
    fn default_stiffness_vel() -> f64 {
        0.5
    }
    fn default_final_weight() -> f64 {
        1.0
    }

    /// GPS's defaults for a system of control period `dt` whose action `j` drives the joint at
    /// state indices `positions[j]` (angle) and `velocities[j]` (velocity).
    pub fn new(dt: f64, positions: Vec<usize>, velocities: Vec<usize>) -> Self {
        Self {
            gains: Vec::new(),
            acc: Vec::new(),
            variance: Self::default_variance(),
            stiffness: Self::default_stiffness(),
            stiffness_vel: Self::default_stiffness_vel(),
            final_weight: Self::default_final_weight(),
            dt,
            positions,
            velocities,
        }
    }

    /// Checks the settings that do not depend on the system: finite values, a positive
    /// variance, `dt` and final weight (the last step's `Q_uu` is `final_weight / variance · I`),
    /// non-negative stiffnesses.
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [
            ("init_lqr variance", self.variance),
            ("init_lqr dt", self.dt),
            ("init_lqr final_weight", self.final_weight),
        ] {
            crate::mpc::positive(what, v)?;
        }
        for (what, v) in [
            ("init_lqr stiffness", self.stiffness),
            ("init_lqr stiffness_vel", self.stiffness_vel),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(PlanError::Config(format!(
                    "{what} must be finite and >= 0, got {v}"
                )));
            }
        }
        if let Some(v) = self.gains.iter().chain(&self.acc).find(|v| !v.is_finite()) {
            return Err(PlanError::Config(format!(
                "init_lqr gains and acc must be finite, got {v}"
            )));
        }
        Ok(())
    }

    /// [`InitLqr::validate`], and that the settings fit a state of `state_dim` entries and
    /// `action_dim` actions: one gain and acceleration per action (or none), one angle and one
    /// velocity index per action, all inside the state and no index used twice.
    pub fn check(&self, state_dim: usize, action_dim: usize) -> Result<()> {
        self.validate()?;
        for (what, len) in [
            ("init_lqr gains", self.gains.len()),
            ("init_lqr acc", self.acc.len()),
        ] {
            if len != 0 && len != action_dim {
                return Err(PlanError::Config(format!(
                    "{what} has {len} entries: give one per action ({action_dim}) or none"
                )));
            }
        }
        check_len(
            "init_lqr positions (one per action)",
            action_dim,
            self.positions.len(),
        )?;
        check_len(
            "init_lqr velocities (one per action)",
            action_dim,
            self.velocities.len(),
        )?;
        let mut seen = vec![false; state_dim];
        for &i in self.positions.iter().chain(&self.velocities) {
            if i >= state_dim {
                return Err(PlanError::Config(format!(
                    "init_lqr state index {i} is outside the state of {state_dim} entries"
                )));
            }
            if std::mem::replace(&mut seen[i], true) {
                return Err(PlanError::Config(format!(
                    "init_lqr state index {i} is used twice among positions and velocities"
                )));
            }
        }
        Ok(())
    }
}

/// `N` sampled trajectories of a TVLG controller with the noise that produced them.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectorySamples {
    /// States, `N x (T+1) x S`.
    pub states: Array3<f64>,
    /// Actions, `N x T x A`.
    pub actions: Array3<f64>,
    /// Standard normal noise `ξ` behind each action, `N x T x A`.
    pub noise: Array3<f64>,
    /// Costs `c(x_t, u_t)` and, in the last column, the terminal cost: `N x (T+1)`.
    pub costs: Array2<f64>,
}

/// One step of a maximum-entropy LQR backward pass, from the step's Q-function `qtt`, `qt` over
/// `z = [x; u]` (`n` states) and the Cholesky factor of its `Q_uu`: the controller `u = K x + k`
/// with `Σ = Q_uu⁻¹`, and the value function `V_xx`, `v_x` it leaves for the step before.
pub(crate) struct LqrStep {
    pub(crate) gain: DMatrix<f64>,
    pub(crate) offset: DVector<f64>,
    pub(crate) cov: DMatrix<f64>,
    pub(crate) vxx: DMatrix<f64>,
    pub(crate) vx: DVector<f64>,
}

/// [`LqrStep`] of `qtt`, `qt` with `chol` the factor of their `Q_uu`.
pub(crate) fn lqr_step(
    chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
    qtt: &DMatrix<f64>,
    qt: &DVector<f64>,
    n: usize,
) -> LqrStep {
    let m = qtt.nrows() - n;
    let gain = -chol.solve(&qtt.view((n, 0), (m, n)).into_owned());
    let offset = -chol.solve(&qt.rows(n, m).into_owned());
    let qxu = qtt.view((0, n), (n, m));
    let vxx = qtt.view((0, 0), (n, n)) + qxu * &gain;
    let vxx = (&vxx + vxx.transpose()) * 0.5;
    let vx = qt.rows(0, n) + qxu * &offset;
    LqrStep {
        gain,
        offset,
        cov: chol.inverse(),
        vxx,
        vx,
    }
}

/// Costs-to-go `S_{i,t} = Σ_{j ≥ t} c_{i,j}` of per-step costs `N x (T+1)` whose last column is
/// the terminal cost, `N x T`.
pub fn costs_to_go(costs: &Array2<f64>) -> Array2<f64> {
    let (n, t1) = costs.dim();
    let mut s = Array2::zeros((n, t1 - 1));
    for i in 0..n {
        let mut acc = costs[(i, t1 - 1)];
        for t in (0..t1 - 1).rev() {
            acc += costs[(i, t)];
            s[(i, t)] = acc;
        }
    }
    s
}

impl TrajectorySamples {
    /// Number of trajectories.
    pub fn len(&self) -> usize {
        self.states.shape()[0]
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Costs-to-go `S_{i,t} = Σ_{j ≥ t} c_{i,j}` including the terminal cost, `N x T` (p4 §II-B).
    pub fn cost_to_go(&self) -> Array2<f64> {
        costs_to_go(&self.costs)
    }
    /// Adds per-step quadratic terms to the stored costs: `costs[i, t] += extra[t](x_{i,t}, u_{i,t})`
    /// for `t < T` and `extra[T](x_{i,T})` to the terminal column (`T + 1` terms), e.g. the KL
    /// surrogate MDGPS adds to the task cost before a [`crate::Pilqr::update_with_cost`] on the
    /// same sum.
    pub fn add_quadratic_costs(&mut self, extra: &[QuadraticCost]) -> Result<()> {
        let (ns, t1) = self.costs.dim();
        check_len("cost terms (T running + terminal)", t1, extra.len())?;
        let (n, m) = (self.states.shape()[2], self.actions.shape()[2]);
        for (t, q) in extra.iter().enumerate() {
            let width = if t + 1 < t1 { n + m } else { n };
            check_len("quadratic cost size", width * width, q.hess.len())?;
            check_len("quadratic cost gradient", width, q.grad.len())?;
            for i in 0..ns {
                let mut z = DVector::zeros(width);
                z.rows_mut(0, n)
                    .iter_mut()
                    .zip(self.states.slice(s![i, t, ..]))
                    .for_each(|(d, v)| *d = *v);
                if width > n {
                    z.rows_mut(n, m)
                        .iter_mut()
                        .zip(self.actions.slice(s![i, t, ..]))
                        .for_each(|(d, v)| *d = *v);
                }
                let c = q.eval(&z);
                if !c.is_finite() {
                    return Err(PlanError::NonFiniteCost {
                        what: "added quadratic cost",
                        sample: i,
                        step: t,
                        value: c,
                    });
                }
                self.costs[(i, t)] += c;
            }
        }
        Ok(())
    }

    /// Mean total cost over the trajectories.
    pub fn mean_cost(&self) -> f64 {
        self.costs.sum() / self.len() as f64
    }
}

/// How [`sample_trajectories`] draws initial states and process noise.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SampleConfig {
    /// Trajectories per batch.
    pub samples: usize,
    /// Standard deviation of Gaussian noise on the initial state.
    pub x0_std: f64,
    /// Standard deviation of Gaussian noise added to each next state (a linear-Gaussian system).
    pub process_std: f64,
}

impl Default for SampleConfig {
    fn default() -> Self {
        Self {
            samples: 20,
            x0_std: 0.0,
            process_std: 0.0,
        }
    }
}

/// Runs `controller` on `system` from `x0` (`N` trajectories batched, one `predict` call per time
/// step), storing the noise of every action. `rng` draws the noise and drives a stochastic
/// system.
pub fn sample_trajectories(
    controller: &TvlgController,
    system: &dyn DynamicsModel,
    objective: &Objective,
    x0: &[f64],
    cfg: &SampleConfig,
    rng: &mut Rng,
) -> Result<TrajectorySamples> {
    let (n, m, t_len) = (
        controller.state_dim(),
        controller.action_dim(),
        controller.horizon(),
    );
    check_len(
        "system state dimension vs controller",
        n,
        system.state_dim(),
    )?;
    check_len(
        "system action dimension vs controller",
        m,
        system.action_dim(),
    )?;
    check_len("initial state", n, x0.len())?;
    objective.check_stagewise()?;
    crate::mpc::nonzero("samples", cfg.samples)?;
    let ns = cfg.samples;
    let mut noise = Array3::zeros((ns, t_len, m));
    fill_normal(rng, noise.as_slice_mut().expect("standard layout"));
    let mut states = Array3::zeros((ns, t_len + 1, n));
    let mut actions = Array3::zeros((ns, t_len, m));
    let mut costs = Array2::zeros((ns, t_len + 1));
    let mut cur = Array2::zeros((ns, n));
    let mut z = vec![0.0; ns * n];
    fill_normal(rng, &mut z);
    for i in 0..ns {
        for j in 0..n {
            cur[(i, j)] = x0[j] + cfg.x0_std * z[i * n + j];
        }
    }
    let mut act = Array2::zeros((ns, m));
    let mut c = vec![0.0; ns];
    for t in 0..t_len {
        states.slice_mut(s![.., t, ..]).assign(&cur);
        for i in 0..ns {
            let x = DVector::from_iterator(n, cur.row(i).iter().copied());
            let xi = DVector::from_iterator(m, noise.slice(s![i, t, ..]).iter().copied());
            let u = controller.act(t, &x, &xi);
            act.row_mut(i)
                .iter_mut()
                .zip(u.iter())
                .for_each(|(a, v)| *a = *v);
        }
        actions.slice_mut(s![.., t, ..]).assign(&act);
        objective.running_batch(cur.view(), act.view(), t, &mut c)?;
        costs
            .column_mut(t)
            .iter_mut()
            .zip(&c)
            .for_each(|(o, v)| *o = *v);
        if cur.iter().chain(act.iter()).any(|v| !v.is_finite()) {
            return Err(PlanError::NonFinite(format!(
                "states or actions of the samples at step {t}"
            )));
        }
        cur =
            crate::mpc::predict(system, &ModelInput::new(cur.view(), act.view()), rng)?.next_states;
        if cfg.process_std > 0.0 {
            fill_normal(rng, &mut z);
            cur.iter_mut()
                .zip(&z)
                .for_each(|(v, e)| *v += cfg.process_std * e);
        }
    }
    states.slice_mut(s![.., t_len, ..]).assign(&cur);
    objective.terminal_batch(cur.view(), t_len, &mut c)?;
    costs
        .column_mut(t_len)
        .iter_mut()
        .zip(&c)
        .for_each(|(o, v)| *o = *v);
    Ok(TrajectorySamples {
        states,
        actions,
        noise,
        costs,
    })
}

/// A quadratic cost in absolute coordinates, `c(z) ≈ ½ zᵀ C z + cᵀ z + c₀` with `z = [x; u]`
/// (for the terminal step `z = x`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QuadraticCost {
    /// `C_t`, `(S+A) x (S+A)` (terminal: `S x S`).
    pub hess: DMatrix<f64>,
    /// `c_t`.
    pub grad: DVector<f64>,
    /// `c₀`.
    pub constant: f64,
}

impl QuadraticCost {
    /// Value at `z`.
    pub fn eval(&self, z: &DVector<f64>) -> f64 {
        0.5 * (z.transpose() * &self.hess * z)[0] + self.grad.dot(z) + self.constant
    }
}

/// Expands the objective to second order around the mean trajectory of `samples` (`T` running
/// costs, then the terminal cost), as LQR-FLM needs it (p4 §II-A: "a twice-differentiable cost").
pub fn quadratize_cost(
    objective: &Objective,
    samples: &TrajectorySamples,
) -> Result<Vec<QuadraticCost>> {
    let xbar = samples.states.mean_axis(ndarray::Axis(0)).expect("samples");
    let ubar = samples
        .actions
        .mean_axis(ndarray::Axis(0))
        .expect("samples");
    let t_len = ubar.nrows();
    let mut out = Vec::with_capacity(t_len + 1);
    for t in 0..=t_len {
        let x = DVector::from_iterator(xbar.ncols(), xbar.row(t).iter().copied());
        if t < t_len {
            let u = DVector::from_iterator(ubar.ncols(), ubar.row(t).iter().copied());
            let q = objective.running_quadratic(x.as_slice(), u.as_slice(), t)?;
            out.push(absolute(&q, &x, &u));
        } else {
            let q = objective.terminal_quadratic(x.as_slice())?;
            let g = &q.cx - &q.cxx * &x;
            let constant = q.c - q.cx.dot(&x) + 0.5 * (x.transpose() * &q.cxx * &x)[0];
            out.push(QuadraticCost {
                hess: q.cxx,
                grad: g,
                constant,
            });
        }
    }
    Ok(out)
}

/// Turns an expansion around `(x̄, ū)` into absolute coordinates.
pub(crate) fn absolute(q: &QuadCost, x: &DVector<f64>, u: &DVector<f64>) -> QuadraticCost {
    let (n, m) = (x.len(), u.len());
    let mut h = DMatrix::zeros(n + m, n + m);
    h.view_mut((0, 0), (n, n)).copy_from(&q.cxx);
    h.view_mut((n, n), (m, m)).copy_from(&q.cuu);
    h.view_mut((n, 0), (m, n)).copy_from(&q.cux);
    h.view_mut((0, n), (n, m)).copy_from(&q.cux.transpose());
    let mut g0 = DVector::zeros(n + m);
    g0.rows_mut(0, n).copy_from(&q.cx);
    g0.rows_mut(n, m).copy_from(&q.cu);
    let mut z = DVector::zeros(n + m);
    z.rows_mut(0, n).copy_from(x);
    z.rows_mut(n, m).copy_from(u);
    let hz = &h * &z;
    QuadraticCost {
        grad: &g0 - &hz,
        constant: q.c - g0.dot(&z) + 0.5 * z.dot(&hz),
        hess: h,
    }
}

/// Means and covariances of `(x_t, u_t)` (and the final state) when `controller` runs on the
/// fitted `dynamics` from its initial-state distribution.
#[derive(Debug, Clone)]
pub struct TrajectoryMoments {
    /// Means of `[x_t; u_t]`, `t < T`, then of `x_T`.
    pub mu: Vec<DVector<f64>>,
    /// Covariances of `[x_t; u_t]`, then of `x_T`.
    pub sigma: Vec<DMatrix<f64>>,
}

/// Propagates the moments of a controller through TVLG dynamics (the LQR-FLM forward pass).
pub fn forward_moments(
    controller: &TvlgController,
    dynamics: &TvlgDynamics,
) -> Result<TrajectoryMoments> {
    let t_len = controller.horizon();
    check_len("fitted dynamics horizon", t_len, dynamics.horizon())?;
    let (n, m) = (controller.state_dim(), controller.action_dim());
    let mut mx = dynamics.x0_mean.clone();
    let mut sx = dynamics.x0_cov.clone();
    check_len("fitted dynamics state", n, mx.len())?;
    let mut mu = Vec::with_capacity(t_len + 1);
    let mut sigma = Vec::with_capacity(t_len + 1);
    for t in 0..t_len {
        let k = &controller.gains[t];
        let mu_u = k * &mx + &controller.offsets[t];
        let sxu = &sx * k.transpose();
        let suu = k * &sxu + &controller.cov[t];
        let mut s_joint = DMatrix::zeros(n + m, n + m);
        s_joint.view_mut((0, 0), (n, n)).copy_from(&sx);
        s_joint.view_mut((0, n), (n, m)).copy_from(&sxu);
        s_joint.view_mut((n, 0), (m, n)).copy_from(&sxu.transpose());
        s_joint.view_mut((n, n), (m, m)).copy_from(&suu);
        let mut m_joint = DVector::zeros(n + m);
        m_joint.rows_mut(0, n).copy_from(&mx);
        m_joint.rows_mut(n, m).copy_from(&mu_u);
        let mut f = DMatrix::zeros(n, n + m);
        f.view_mut((0, 0), (n, n)).copy_from(&dynamics.fx[t]);
        f.view_mut((0, n), (n, m)).copy_from(&dynamics.fu[t]);
        mx = &f * &m_joint + &dynamics.fc[t];
        sx = &f * &s_joint * f.transpose() + &dynamics.cov[t];
        sx = (&sx + sx.transpose()) * 0.5;
        mu.push(m_joint);
        sigma.push(s_joint);
    }
    mu.push(mx);
    sigma.push(sx);
    Ok(TrajectoryMoments { mu, sigma })
}

/// Expected quadratic cost `Σ_t E[c_t]` of trajectory moments.
pub fn expected_cost(moments: &TrajectoryMoments, cost: &[QuadraticCost]) -> f64 {
    moments
        .mu
        .iter()
        .zip(&moments.sigma)
        .zip(cost)
        .map(|((m, s), c)| c.eval(m) + 0.5 * (&c.hess * s).trace())
        .sum()
}

/// `E_x[KL(p(·|x) ‖ q(·|x))]` at step `t` for two linear-Gaussian policies, with `x ~ N(μ_x, Σ_x)`.
pub fn policy_kl(
    p: &TvlgController,
    q: &TvlgController,
    t: usize,
    mu_x: &DVector<f64>,
    sigma_x: &DMatrix<f64>,
) -> f64 {
    let m = p.action_dim() as f64;
    let qinv = q.inv_cov(t);
    let dk = &p.gains[t] - &q.gains[t];
    let dmean = &dk * mu_x + (&p.offsets[t] - &q.offsets[t]);
    let logdet = |c: &DMatrix<f64>| 2.0 * c.diagonal().iter().map(|v| v.ln()).sum::<f64>();
    let quad =
        (dmean.transpose() * qinv * &dmean)[0] + (dk.transpose() * qinv * &dk * sigma_x).trace();
    0.5 * ((qinv * &p.cov[t]).trace() - m + logdet(q.chol(t)) - logdet(p.chol(t)) + quad)
}
