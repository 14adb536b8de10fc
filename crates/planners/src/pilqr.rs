//! PILQR (p4 §III): an LQR-FLM step on the quadratic approximation of the cost, then PI² on the
//! residual cost-to-go, with the LQR step shrunk where the fitted model explains the samples
//! poorly.
//!
//! The composition (p4 eq. 4–6):
//! 1. quadratic cost `ĉ` around the samples' mean; the model cost-to-go `Ŝ_{i,t}`: run the old
//!    controller with each sample's stored noise `ξ_{i,j}` from `(x_{i,t}, u_{i,t})` under the
//!    fitted TVLG dynamics and sum `ĉ` (§III-C); the residual `S̃ = S − Ŝ`;
//! 2. step adjustment: `ρ = mean_t std_i(S̃_{i,t}) / std_i(S_{i,t})` is the share of the
//!    cost-to-go differences the model does not explain; the LQR-FLM step is
//!    `ε_LQR = ε · max(min_lqr_fraction, 1 − ρ)`, so PILQR shifts towards PI² as the model
//!    degrades. (p4 describes the behaviour, not the formula; this rule is ours.)
//! 3. `p̂ = LQR-FLM(p̄, ε_LQR)`; reparametrized controls `û_{i,t} = K̂_t x_{i,t} + k̂_t + chol(Σ̂_t) ξ_{i,t}`;
//! 4. `p = PI²(p̂)` on `(x, û)` weighted by the residuals `S̃`.

use ndarray::{Array2, Array3};
use tandem_models::TvlgDynamics;

use crate::error::Result;
use crate::lqr_flm::{LqrFlm, LqrFlmConfig, LqrFlmStep};
use crate::objective::Objective;
use crate::pi2::{pi2_update, Pi2Config, Pi2Step};
use crate::tvlg::{quadratize_cost, QuadraticCost, TrajectorySamples, TvlgController};
use nalgebra::DVector;

/// Settings of [`Pilqr`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PilqrConfig {
    /// The LQR-FLM stage (its `kl_step` is the full step `ε`).
    pub lqr: LqrFlmConfig,
    /// The PI² stage on the residuals.
    pub pi2: Pi2Config,
    /// Smallest share of `ε` the LQR-FLM stage keeps.
    pub min_lqr_fraction: f64,
}

impl Default for PilqrConfig {
    fn default() -> Self {
        Self {
            lqr: LqrFlmConfig::default(),
            pi2: Pi2Config::default(),
            min_lqr_fraction: 0.1,
        }
    }
}

/// One PILQR update and its parts.
#[derive(Debug, Clone)]
pub struct PilqrStep {
    /// The new controller.
    pub controller: TvlgController,
    /// `ρ`, the unexplained share of the cost-to-go differences.
    pub residual_share: f64,
    /// The LQR-FLM stage.
    pub lqr: LqrFlmStep,
    /// The PI² stage.
    pub pi2: Pi2Step,
}

/// PILQR; see the module docs.
#[derive(Debug, Clone)]
pub struct Pilqr {
    cfg: PilqrConfig,
    lqr: LqrFlm,
}

impl Pilqr {
    /// An optimizer with these settings (checked here).
    pub fn new(cfg: PilqrConfig) -> Result<Self> {
        crate::mpc::fraction("min_lqr_fraction", cfg.min_lqr_fraction)?;
        Ok(Self {
            lqr: LqrFlm::new(cfg.lqr.clone())?,
            cfg,
        })
    }

    /// One update of `prev` from its `samples` and the dynamics fitted to them.
    pub fn update(
        &self,
        prev: &TvlgController,
        samples: &TrajectorySamples,
        dynamics: &TvlgDynamics,
        objective: &Objective,
    ) -> Result<PilqrStep> {
        let cost = quadratize_cost(objective, samples)?;
        let s = samples.cost_to_go();
        let resid = &s - &model_cost_to_go(prev, samples, dynamics, &cost);
        let t_len = s.ncols();
        let rho = (0..t_len)
            .map(|t| {
                (std(&resid.column(t).to_vec()) / std(&s.column(t).to_vec()).max(1e-12)).min(1.0)
            })
            .sum::<f64>()
            / t_len as f64;
        let eps = self.cfg.lqr.kl_step * (1.0 - rho).max(self.cfg.min_lqr_fraction);
        let lqr = self.lqr.update(prev, dynamics, &cost, Some(eps))?;
        let u_hat = reparametrize(&lqr.controller, samples);
        let pi2 = pi2_update(
            &lqr.controller,
            &samples.states,
            &u_hat,
            &resid,
            &self.cfg.pi2,
        )?;
        Ok(PilqrStep {
            controller: pi2.controller.clone(),
            residual_share: rho,
            lqr,
            pi2,
        })
    }
}

fn std(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
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

/// `Ŝ_{i,t}`: the quadratic cost-to-go of running `controller` with sample `i`'s noise from
/// `(x_{i,t}, u_{i,t})` under the mean of the fitted dynamics (p4 §III-C), `N x T`.
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
