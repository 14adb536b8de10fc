//! PILQR (p4 §III): an LQR-FLM step on the quadratic approximation of the cost, then PI² on the
//! residual cost, with the LQR step shrunk where the fitted model explains the samples poorly.
//!
//! The composition (p4 eq. 4–6), as the authors' GPS code runs it (`traj_opt_pilqr.py`,
//! `algorithm_traj_opt_pilqr.py`, `traj_opt_utils.py`):
//! 1. quadratic cost `ĉ` around the samples' mean; each sample's model costs `ĉ_{i,t}`: replay its
//!    stored noise `ξ_{i,t}` through the old controller and the mean of the fitted TVLG dynamics
//!    from the mean initial state (GPS's `approximated_cost`, [`model_costs`]); the residual costs
//!    `c̃_{i,t} = c_{i,t} − ĉ_{i,t}` and their costs-to-go `S̃`;
//! 2. step adjustment (p4 §V: "shift towards model-free updates from the PI² method as the TVLG
//!    approximation of the dynamics became less accurate"; the rule is GPS's
//!    `step_rule = 'res_percent'` with one bound per step): at each step the residual ratio
//!    `r_t = mean_i Σ_{j≥t} |c̃_{i,j}| / mean_i Σ_{j≥t} |c_{i,j}|`; a per-step multiplier `m_t` is
//!    halved where `r_t > 0.2`, doubled where `r_t < 0.05`, kept in `[min_t, max_t]`, and carried
//!    from update to update (not adjusted on the first); the LQR-FLM bound at step `t` is
//!    `ε_t = kl_t m_t`, with the base bound `kl_t`, `min_t` and `max_t` constant or linear over the
//!    steps ([`PerStep`]);
//! 3. `p̂ = LQR-FLM(p̄, ε_t)`; reparametrized controls `û_{i,t} = K̂_t x_{i,t} + k̂_t + chol(Σ̂_t) ξ_{i,t}`;
//! 4. `p = PI²(p̂)` on `(x, û)` weighted by the residual costs-to-go `S̃`, at the temperatures
//!    `η_t` that the PI² KL bound gives on the full cost-to-go `S` (the authors' code:
//!    `fixed_eta`). Residuals that are small next to the spread of `S` then move the controller
//!    little, while a poor model (large residuals) hands the step over to PI². As in the authors'
//!    `TrajOptPI2` ([`Pilqr::default_pi2`]), this stage keeps `K̂_t` and refits only `k_t` and
//!    `Σ_t`, the latter damped towards `Σ̂_t`.
//!
//! p4's text states the step adjustment only in words (§V); the per-step residual-ratio rule
//! above is the authors' PILQR code. GPS's other rule, from the predicted and the actual
//! improvement of the expected cost, is the authors' rule for LQR-FLM alone
//! ([`crate::classic_step_mult`]), not PILQR's.
//!
//! Our first version predicted each sample's cost-to-go from its own `(x_{i,t}, u_{i,t})` at every
//! step ([`Residual::FromEachStep`], [`model_cost_to_go`]) and took the ratio of the absolute
//! costs-to-go. Restarting on the samples hides the model's drift, so its residuals and ratios are
//! smaller and its LQR steps larger; it is kept to rerun the results it produced.

use ndarray::{Array2, Array3};
use tandem_models::TvlgDynamics;

use crate::error::{PlanError, Result};
use crate::lqr_flm::{LqrFlm, LqrFlmConfig, LqrFlmStep};
use crate::objective::Objective;
use crate::pi2::{pi2_update_with_temperatures, pi2_weights, Pi2Config, Pi2Step};
use crate::tvlg::{costs_to_go, quadratize_cost, QuadraticCost, TrajectorySamples, TvlgController};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// A setting with one value per time step: the same at every step, or linear from the first step
/// to the last (as GPS's `np.linspace(first, last, T)`). In TOML `x = 0.5` or
/// `x = { first = 0.6, last = 0.2 }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "a number, or a table { first = .., last = .. } for a value linear over the steps"
)]
pub enum PerStep {
    /// The same value at every step.
    Constant(f64),
    /// `first` at step 0, `last` at step `T − 1`, linear in between.
    Linear {
        /// The value at the first step.
        first: f64,
        /// The value at the last step.
        last: f64,
    },
}

impl PerStep {
    /// The value at step `t` of `horizon`.
    pub fn at(&self, t: usize, horizon: usize) -> f64 {
        match *self {
            PerStep::Constant(v) => v,
            PerStep::Linear { first, last } if horizon > 1 => {
                first + (last - first) * t as f64 / (horizon - 1) as f64
            }
            PerStep::Linear { first, .. } => first,
        }
    }

    /// The smallest and the largest value over the steps.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            PerStep::Constant(v) => (v, v),
            PerStep::Linear { first, last } => (first.min(last), first.max(last)),
        }
    }

    /// An error naming `name` unless every value is finite and positive.
    fn check_positive(&self, name: &str) -> Result<()> {
        let (lo, hi) = self.range();
        crate::mpc::positive(name, lo)?;
        crate::mpc::positive(name, hi)
    }
}

/// How PILQR's model predicts the samples' costs, against which their residuals are taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Residual {
    /// The authors': each sample's noise replayed from the mean initial state under the fitted
    /// dynamics ([`model_costs`]); the ratio sums absolute per-step residuals from `t` on.
    FromStart,
    /// Our first version: a model cost-to-go restarted at every sample's own `(x_t, u_t)`
    /// ([`model_cost_to_go`]); the ratio of absolute costs-to-go. Settings without the key read
    /// as this, which is what they ran.
    FromEachStep,
}

impl Residual {
    fn from_each_step() -> Self {
        Residual::FromEachStep
    }
}

/// Settings of [`Pilqr`]. The step-adjustment defaults are the authors' (GPS `ALG_PILQR`:
/// `step_rule_res_ratio_dec = 0.2`, `step_rule_res_ratio_inc = 0.05`, step multipliers in
/// `[0.01, 10]`; their experiments also make the bounds linear over the steps, e.g. the gripper
/// pusher's `kl_step` from 0.6 to 0.2 and `ALG_PILQR`'s `max_step_mult` from 10 to 5). The PI²
/// stage defaults to the authors' `TrajOptPI2` as PILQR calls it ([`Pilqr::default_pi2`]): it
/// keeps the LQR-FLM gains `K̂_t` and moves only `k_t` and `Σ_t`, with covariance damping 2.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PilqrConfig {
    /// The LQR-FLM stage (its `kl_step` is the base bound `ε` that the multipliers scale, unless
    /// [`PilqrConfig::kl_step`] is given).
    pub lqr: LqrFlmConfig,
    /// The base bound per step `kl_t`; `None`: `lqr.kl_step` at every step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kl_step: Option<PerStep>,
    /// How the residuals are taken; settings without the key read as
    /// [`Residual::FromEachStep`], which is what they ran.
    #[serde(default = "Residual::from_each_step")]
    pub residual: Residual,
    /// The PI² stage on the residuals (its `kl_step` sets the temperatures on the full cost).
    pub pi2: Pi2Config,
    /// Whether to adjust the per-step multipliers (`false`: `ε_t = ε` always, GPS's `'const'`).
    pub adjust_step: bool,
    /// Residual ratio above which a step's multiplier is halved.
    pub res_ratio_dec: f64,
    /// Residual ratio below which a step's multiplier is doubled.
    pub res_ratio_inc: f64,
    /// Smallest multiplier, per step.
    pub min_step_mult: PerStep,
    /// Largest multiplier, per step.
    pub max_step_mult: PerStep,
}

impl Default for PilqrConfig {
    fn default() -> Self {
        Self {
            lqr: LqrFlmConfig::default(),
            kl_step: None,
            residual: Residual::FromStart,
            pi2: Pilqr::default_pi2(),
            adjust_step: true,
            res_ratio_dec: 0.2,
            res_ratio_inc: 0.05,
            min_step_mult: PerStep::Constant(0.01),
            max_step_mult: PerStep::Constant(10.0),
        }
    }
}

impl PilqrConfig {
    /// Checks both stages' settings, positive bounds and residual thresholds with
    /// `res_ratio_inc <= res_ratio_dec`, and step multipliers around 1 at every step.
    pub fn validate(&self) -> Result<()> {
        self.lqr.validate()?;
        self.pi2.validate()?;
        if let Some(k) = &self.kl_step {
            k.check_positive("kl_step")?;
        }
        self.min_step_mult.check_positive("min_step_mult")?;
        self.max_step_mult.check_positive("max_step_mult")?;
        crate::mpc::positive("res_ratio_dec", self.res_ratio_dec)?;
        crate::mpc::positive("res_ratio_inc", self.res_ratio_inc)?;
        if self.min_step_mult.range().1 > 1.0 || self.max_step_mult.range().0 < 1.0 {
            return Err(PlanError::Config(format!(
                "step multipliers [{:?}, {:?}] must contain 1 at every step",
                self.min_step_mult, self.max_step_mult
            )));
        }
        if self.res_ratio_inc > self.res_ratio_dec {
            return Err(PlanError::Config(format!(
                "res_ratio_inc {} must not exceed res_ratio_dec {}",
                self.res_ratio_inc, self.res_ratio_dec
            )));
        }
        Ok(())
    }
}

/// One PILQR update and its parts.
#[derive(Debug, Clone)]
pub struct PilqrStep {
    /// The new controller.
    pub controller: TvlgController,
    /// Residual ratios `r_t` (see the module docs).
    pub residual_ratio: Vec<f64>,
    /// The multipliers `m_t` this update used (`ε_t = kl_t m_t`).
    pub step_mult: Vec<f64>,
    /// The LQR-FLM stage.
    pub lqr: LqrFlmStep,
    /// The PI² stage.
    pub pi2: Pi2Step,
}

/// PILQR; see the module docs. Keeps the per-step multipliers between updates (one optimizer per
/// trajectory; [`Pilqr::reset`] forgets them).
#[derive(Debug, Clone)]
pub struct Pilqr {
    cfg: PilqrConfig,
    lqr: LqrFlm,
    step_mult: Vec<f64>,
}

impl Pilqr {
    /// The PI² stage's defaults: the authors' GPS `TrajOptPI2` with `use_lqr_actions` ("we only
    /// optimize feedforward controls with PI2": the feedback gains stay the LQR-FLM stage's
    /// `K̂_t`) and `covariance_damping = 2`; `kl_step` as [`Pi2Config::default`]. Refitting
    /// `K_t` by weighted regression on a few effective samples adds noise to gains the model-based
    /// stage already fits well.
    pub fn default_pi2() -> Pi2Config {
        Pi2Config {
            update_gains: false,
            covariance_damping: 2.0,
            ..Pi2Config::default()
        }
    }

    /// An optimizer with these settings (checked here).
    pub fn new(cfg: PilqrConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(Self {
            lqr: LqrFlm::new(cfg.lqr.clone())?,
            cfg,
            step_mult: Vec::new(),
        })
    }

    /// The per-step multipliers after the last update (empty before the first).
    pub fn step_mult(&self) -> &[f64] {
        &self.step_mult
    }

    /// Forgets the multipliers (start of a new trajectory optimization).
    pub fn reset(&mut self) {
        self.step_mult.clear();
    }

    /// Restores multipliers that [`Pilqr::step_mult`] returned (a resumed run).
    pub fn set_step_mult(&mut self, step_mult: Vec<f64>) {
        self.step_mult = step_mult;
    }

    /// One update of `prev` from its `samples` and the dynamics fitted to them, on the quadratic
    /// expansion of `objective` around the samples' mean ([`quadratize_cost`]): the default cost
    /// of [`Pilqr::update_with_cost`].
    pub fn update(
        &mut self,
        prev: &TvlgController,
        samples: &TrajectorySamples,
        dynamics: &TvlgDynamics,
        objective: &Objective,
    ) -> Result<PilqrStep> {
        let cost = quadratize_cost(objective, samples)?;
        self.update_with_cost(prev, samples, dynamics, &cost)
    }

    /// One update on a quadratic cost per time step supplied by the caller: `T` running costs
    /// then the terminal one (`T + 1` entries), e.g. MDGPS's surrogate, the task cost plus a KL
    /// term to the linearized global policy, different at every step. The samples' own costs
    /// (`samples.costs`, whose costs-to-go PI² weighs and the residuals compare against) must be
    /// of the same cost: a caller that adds a term to the quadratic cost adds it to the samples
    /// too ([`TrajectorySamples::add_quadratic_costs`]).
    pub fn update_with_cost(
        &mut self,
        prev: &TvlgController,
        samples: &TrajectorySamples,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
    ) -> Result<PilqrStep> {
        self.update_anchored(prev, prev, samples, dynamics, cost)
    }

    /// [`Pilqr::update_with_cost`] with the LQR-FLM stage's KL bound taken against `anchor`
    /// instead of the controller `prev` that drew the samples: MDGPS (p4 §IV) constrains each local
    /// controller against the old global policy linearized around its samples. The residuals and
    /// the reparametrized controls still come from `prev`, which produced the samples.
    pub fn update_anchored(
        &mut self,
        prev: &TvlgController,
        anchor: &TvlgController,
        samples: &TrajectorySamples,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
    ) -> Result<PilqrStep> {
        crate::error::check_len("anchor horizon", prev.horizon(), anchor.horizon())?;
        crate::error::check_len(
            "anchor state dimension",
            prev.state_dim(),
            anchor.state_dim(),
        )?;
        crate::error::check_len(
            "anchor action dimension",
            prev.action_dim(),
            anchor.action_dim(),
        )?;
        crate::error::check_len(
            "cost terms (T running + terminal)",
            prev.horizon() + 1,
            cost.len(),
        )?;
        let s = samples.cost_to_go();
        let t_len = s.ncols();
        let (resid, ratio) = match self.cfg.residual {
            Residual::FromStart => {
                let c = &samples.costs;
                let r = c - &model_costs(prev, samples, dynamics, cost)?;
                let ratio = suffix_ratio(&r, c);
                (costs_to_go(&r), ratio)
            }
            Residual::FromEachStep => {
                let r = &s - &model_cost_to_go(prev, samples, dynamics, cost);
                let ratio = (0..t_len)
                    .map(|t| {
                        let num = r.column(t).mapv(f64::abs).mean().unwrap_or(0.0);
                        let den = s.column(t).mapv(f64::abs).mean().unwrap_or(0.0);
                        num / den.max(1e-300)
                    })
                    .collect();
                (r, ratio)
            }
        };
        if self.step_mult.len() != t_len {
            // First update: multipliers start at 1 and are not adjusted (the authors' code
            // adjusts from the second iteration on).
            self.step_mult = vec![1.0; t_len];
        } else if self.cfg.adjust_step {
            for (t, (m, r)) in self.step_mult.iter_mut().zip(&ratio).enumerate() {
                let f = if *r > self.cfg.res_ratio_dec {
                    0.5
                } else if *r < self.cfg.res_ratio_inc {
                    2.0
                } else {
                    1.0
                };
                let (lo, hi) = (
                    self.cfg.min_step_mult.at(t, t_len),
                    self.cfg.max_step_mult.at(t, t_len),
                );
                *m = (*m * f).clamp(lo, hi);
            }
        }
        let eps: Vec<f64> = self
            .step_mult
            .iter()
            .enumerate()
            .map(|(t, m)| {
                let base = self
                    .cfg
                    .kl_step
                    .map_or(self.cfg.lqr.kl_step, |k| k.at(t, t_len));
                base * m
            })
            .collect();
        let lqr = self.lqr.update_per_step(anchor, dynamics, cost, &eps)?;
        let u_hat = reparametrize(&lqr.controller, samples);
        let etas: Vec<f64> = (0..t_len)
            .map(|t| pi2_weights(&s.column(t).to_vec(), self.cfg.pi2.kl_step).1)
            .collect();
        let pi2 = pi2_update_with_temperatures(
            &lqr.controller,
            &samples.states,
            &u_hat,
            &resid,
            &self.cfg.pi2,
            Some(&etas),
        )?;
        Ok(PilqrStep {
            controller: pi2.controller.clone(),
            residual_ratio: ratio,
            step_mult: self.step_mult.clone(),
            lqr,
            pi2,
        })
    }
}

/// The controls the samples would have had under `controller` with their stored noise (p4 §III-C).
pub fn reparametrize(controller: &TvlgController, samples: &TrajectorySamples) -> Array3<f64> {
    let (ns, t_len, m) = samples.actions.dim();
    let n = controller.state_dim();
    let mut out = Array3::zeros((ns, t_len, m));
    for i in 0..ns {
        for t in 0..t_len {
            let x = DVector::from_iterator(n, (0..n).map(|j| samples.states[(i, t, j)]));
            let xi = DVector::from_iterator(m, (0..m).map(|j| samples.noise[(i, t, j)]));
            let u = controller.act(t, &x, &xi);
            for j in 0..m {
                out[(i, t, j)] = u[j];
            }
        }
    }
    out
}

/// Each sample's costs as the model predicts them, `N x (T+1)` like `samples.costs`: sample `i`'s
/// noise `ξ_{i,t}` replayed through `controller` from the fitted mean initial state under the mean
/// of the fitted dynamics, `ĉ_t` at every step and the terminal cost at the end (GPS's
/// `approximated_cost`). An error if the dynamics do not span the controller's horizon.
pub fn model_costs(
    controller: &TvlgController,
    samples: &TrajectorySamples,
    dynamics: &TvlgDynamics,
    cost: &[QuadraticCost],
) -> Result<Array2<f64>> {
    let (ns, t_len, m) = samples.actions.dim();
    let n = controller.state_dim();
    crate::error::check_len("fitted dynamics horizon", t_len, dynamics.horizon())?;
    crate::error::check_len("fitted initial state", n, dynamics.x0_mean.len())?;
    crate::error::check_len("cost terms (T running + terminal)", t_len + 1, cost.len())?;
    let mut out = Array2::zeros((ns, t_len + 1));
    for i in 0..ns {
        let mut x = dynamics.x0_mean.clone();
        for t in 0..t_len {
            let xi = DVector::from_iterator(m, (0..m).map(|k| samples.noise[(i, t, k)]));
            let u = controller.act(t, &x, &xi);
            let z = DVector::from_iterator(n + m, x.iter().chain(u.iter()).copied());
            out[(i, t)] = cost[t].eval(&z);
            x = dynamics.mean_next(t, &x, &u);
        }
        out[(i, t_len)] = cost[t_len].eval(&x);
    }
    Ok(out)
}

/// GPS's per-step residual ratio: `mean_i Σ_{j≥t} |r_{i,j}| / mean_i Σ_{j≥t} |c_{i,j}|` for
/// `t < T`, the terminal column included in every sum.
fn suffix_ratio(resid: &Array2<f64>, costs: &Array2<f64>) -> Vec<f64> {
    let abs_to_go = |a: &Array2<f64>| costs_to_go(&a.mapv(f64::abs));
    let (r, c) = (abs_to_go(resid), abs_to_go(costs));
    (0..r.ncols())
        .map(|t| {
            let num = r.column(t).mean().unwrap_or(0.0);
            let den = c.column(t).mean().unwrap_or(0.0);
            num / den.max(1e-300)
        })
        .collect()
}

/// `Ŝ_{i,t}`: the quadratic cost-to-go of running `controller` with sample `i`'s noise from
/// `(x_{i,t}, u_{i,t})` under the mean of the fitted dynamics, `N x T` ([`Residual::FromEachStep`]).
pub fn model_cost_to_go(
    controller: &TvlgController,
    samples: &TrajectorySamples,
    dynamics: &TvlgDynamics,
    cost: &[QuadraticCost],
) -> Array2<f64> {
    let (ns, t_len, m) = samples.actions.dim();
    let n = controller.state_dim();
    let mut out = Array2::zeros((ns, t_len));
    let join = |x: &DVector<f64>, u: &DVector<f64>| {
        DVector::from_iterator(n + m, x.iter().chain(u.iter()).copied())
    };
    for i in 0..ns {
        for t in 0..t_len {
            let mut x = DVector::from_iterator(n, (0..n).map(|j| samples.states[(i, t, j)]));
            let mut u = DVector::from_iterator(m, (0..m).map(|j| samples.actions[(i, t, j)]));
            let mut acc = 0.0;
            for j in t..t_len {
                if j > t {
                    let xi = DVector::from_iterator(m, (0..m).map(|k| samples.noise[(i, j, k)]));
                    u = controller.act(j, &x, &xi);
                }
                acc += cost[j].eval(&join(&x, &u));
                x = dynamics.mean_next(j, &x, &u);
            }
            out[(i, t)] = acc + cost[t_len].eval(&x);
        }
    }
    out
}
