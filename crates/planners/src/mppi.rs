//! Model predictive path integral control (Williams et al. 2017, information-theoretic MPC,
//! Algorithm 2).
//!
//! Each call: warm start from the previous mean shifted by one step; sample perturbations
//! `ε ~ N(0, Σ)` per step, clamp `μ + ε` into the bounds (the perturbation used in the update is
//! the clamped one), roll out, weight each sample by `exp(−(S_i − min S)/λ)`, and move the mean
//! by the weighted perturbation. Sample 0 is the unperturbed mean. With `control_cost` the
//! sample cost gains Williams et al.'s importance-sampling term `λ Σ_h μ_hᵀ Σ⁻¹ ε_h`.

use ndarray::{s, Array2, Array3};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_models::DynamicsModel;

use crate::error::Result;
use crate::mpc::{
    check_problem, clamp_opt, nonzero, plan_from_actions, positive, rollout_population, shift_plan,
    Bounds, Noise, Plan, Planner,
};
use crate::objective::Objective;

/// Settings of [`Mppi`]. Defaults: temperature `λ = 1`, unit isotropic noise, 500 samples,
/// horizon 30, one update per call (Williams et al. 2017 use one update per control step).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MppiConfig {
    /// Planning horizon `H`.
    pub horizon: usize,
    /// Sampled sequences `N` per update.
    pub samples: usize,
    /// Temperature `λ > 0`.
    pub lambda: f64,
    /// Perturbation covariance `Σ`.
    pub noise: Noise,
    /// Correlation `β ∈ [0, 1)` of the sampling noise between consecutive steps (AR(1); 0 is
    /// white noise, the original algorithm).
    pub correlation: f64,
    /// Updates per call.
    pub iterations: usize,
    /// Whether to add the control-cost term `λ μᵀ Σ⁻¹ ε` to each sample's cost.
    pub control_cost: bool,
    /// Action bounds.
    pub bounds: Option<Bounds>,
    /// Seed of the sampling stream.
    pub seed: u64,
}

impl Default for MppiConfig {
    fn default() -> Self {
        Self {
            horizon: 30,
            samples: 500,
            lambda: 1.0,
            noise: Noise::Isotropic(1.0),
            iterations: 1,
            control_cost: false,
            correlation: 0.0,
            bounds: None,
            seed: 0,
        }
    }
}

/// MPPI planner; see the module docs.
#[derive(Debug, Clone)]
pub struct Mppi {
    cfg: MppiConfig,
    rng: Rng,
    mean: Option<Array2<f64>>,
}

impl Mppi {
    /// A planner with these settings (checked here).
    pub fn new(cfg: MppiConfig) -> Result<Self> {
        nonzero("horizon", cfg.horizon)?;
        nonzero("samples", cfg.samples)?;
        nonzero("iterations", cfg.iterations)?;
        crate::mpc::correlation(cfg.correlation)?;
        positive("lambda", cfg.lambda)?;
        let rng = rng_from_seed(cfg.seed);
        Ok(Self {
            cfg,
            rng,
            mean: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &MppiConfig {
        &self.cfg
    }
}

impl Planner for Mppi {
    fn plan(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
    ) -> Result<Plan> {
        let (_, a) = check_problem(x0, model, objective)?;
        if let Some(b) = &self.cfg.bounds {
            b.validate(a)?;
        }
        let l = self.cfg.noise.cholesky(a)?;
        let sigma_inv = (&l * l.transpose())
            .try_inverse()
            .ok_or_else(|| crate::PlanError::Config("noise covariance is singular".into()))?;
        let (h, n, lam) = (self.cfg.horizon, self.cfg.samples, self.cfg.lambda);
        let mut mean = match self.mean.take() {
            Some(mut m) if m.dim() == (h, a) => {
                shift_plan(&mut m);
                m
            }
            _ => {
                let c = self
                    .cfg
                    .bounds
                    .as_ref()
                    .map_or(vec![0.0; a], |b| b.center());
                Array2::from_shape_fn((h, a), |(_, j)| c[j])
            }
        };
        let mut z = Array3::zeros((h, n, a));
        let mut acts = Array3::zeros((h, n, a));
        for _ in 0..self.cfg.iterations {
            crate::mpc::fill_correlated_normal(&mut self.rng, &mut z, self.cfg.correlation);
            for t in 0..h {
                for i in 0..n {
                    for j in 0..a {
                        let mut e = 0.0;
                        if i > 0 {
                            for k in 0..=j {
                                e += l[(j, k)] * z[(t, i, k)];
                            }
                        }
                        acts[(t, i, j)] = mean[(t, j)] + e;
                    }
                }
                clamp_opt(&self.cfg.bounds, acts.slice_mut(s![t, .., ..]));
            }
            let (mut costs, _) = rollout_population(
                x0,
                model,
                objective,
                &mut self.rng,
                &mut acts,
                |_, _, _| Ok(()),
                None,
                None,
            )?;
            if self.cfg.control_cost {
                for i in 0..n {
                    let mut cc = 0.0;
                    for t in 0..h {
                        for j in 0..a {
                            for k in 0..a {
                                cc += mean[(t, j)]
                                    * sigma_inv[(j, k)]
                                    * (acts[(t, i, k)] - mean[(t, k)]);
                            }
                        }
                    }
                    costs[i] += lam * cc;
                }
            }
            let beta = costs.iter().copied().fold(f64::INFINITY, f64::min);
            let w = costs.mapv(|c| (-(c - beta) / lam).exp());
            let wsum = w.sum();
            let mut new_mean = mean.clone();
            for t in 0..h {
                for j in 0..a {
                    let mut d = 0.0;
                    for i in 0..n {
                        d += w[i] * (acts[(t, i, j)] - mean[(t, j)]);
                    }
                    new_mean[(t, j)] += d / wsum;
                }
            }
            mean = new_mean;
        }
        clamp_opt(&self.cfg.bounds, mean.view_mut());
        let plan = plan_from_actions(x0, model, objective, &mut self.rng, &mean)?;
        self.mean = Some(mean);
        Ok(plan)
    }

    fn reset(&mut self) {
        self.mean = None;
        self.rng = rng_from_seed(self.cfg.seed);
    }
}
