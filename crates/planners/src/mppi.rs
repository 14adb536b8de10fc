//! Model predictive path integral control (Williams et al. 2017, information-theoretic MPC,
//! Algorithm 2).
//!
//! Each call: warm start from the previous mean shifted by one step; sample perturbations
//! `ε ~ N(0, Σ)` per step, clamp `μ + ε` into the bounds (the perturbation used in the update is
//! the clamped one), roll out, weight each sample by `exp(−(S_i − min S)/λ_eff)`, and move the
//! mean by the weighted perturbation. `λ_eff` is `λ` itself (Williams et al.) or, with
//! [`Temperature::Spread`] / [`Temperature::EffectiveSamples`], scaled to the sampled costs.
//! Sample 0 is the unperturbed mean. With `control_cost` the sample cost gains Williams et al.'s
//! importance-sampling term `λ Σ_h μ_hᵀ Σ⁻¹ ε_h`. The perturbations may be time-correlated
//! (`correlation`) and drawn at [`Knots`] (held or interpolated between them); the mean itself
//! stays one action per step.

use ndarray::{s, Array1, Array2, Array3};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_models::{DynamicsModel, Propagation};

use crate::error::Result;
use crate::mpc::{
    add_noise, check_problem, clamp_opt, nonzero, plan_from_actions, positive, rollout_particles,
    warm_start, Bounds, Knots, Noise, Plan, Planner,
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
    /// Rollouts per sequence, its cost their mean (PETS's particles, dealt over an ensemble's
    /// members as [`crate::Cem`]'s docs say).
    pub particles: usize,
    /// How an ensemble propagates the rollouts; `None` keeps the model's own setting.
    pub propagation: Option<Propagation>,
    /// Temperature `λ > 0`; how it scales with the costs is set by `temperature`.
    pub lambda: f64,
    /// How `λ` enters the weights `exp(−(S_i − min S)/λ_eff)`.
    pub temperature: Temperature,
    /// Perturbation covariance `Σ`.
    pub noise: Noise,
    /// Correlation `β ∈ [0, 1)` of the sampling noise between consecutive steps (AR(1); 0 is
    /// white noise, the original algorithm).
    pub correlation: f64,
    /// Where the sampling noise is drawn along the horizon (default: every step). Like
    /// `correlation`, knots make the noise dependent across steps, which `control_cost` (derived
    /// for independent per-step noise) does not account for.
    pub knots: Knots,
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
            particles: 1,
            propagation: None,
            lambda: 1.0,
            temperature: Temperature::Fixed,
            noise: Noise::Isotropic(1.0),
            iterations: 1,
            control_cost: false,
            correlation: 0.0,
            knots: Knots::default(),
            bounds: None,
            seed: 0,
        }
    }
}

/// How MPPI's temperature relates to the sampled costs.
///
/// With `Fixed`, `λ` is in units of the cost, so one value cannot serve a task whose cost spread
/// across samples changes by orders of magnitude between phases (a swing-up: spreads of hundreds
/// while swinging, below one while balancing): too hot and the mean does not move (or averages
/// mirror-image solutions to nothing), too cold and one noisy sample is followed. The other rules
/// make the weights invariant to the cost scale.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Temperature {
    /// `λ_eff = λ` (Williams et al. 2017).
    Fixed,
    /// `λ_eff = λ (max S − min S)`: the cost normalization of PI² (Theodorou et al. 2010, weights
    /// `exp(−h (S − min S)/(max S − min S))` with `h = 1/λ`; they use `h = 10`).
    Spread,
    /// `λ_eff` chosen at every update (bisection in log space) so that the effective sample size
    /// `(Σ w)² / Σ w²` is `λ N` (`λ ∈ (0, 1]`): a constant share of the samples carries the update,
    /// the adaptive-temperature rule of sequential Monte Carlo / PI²-type KL bounds.
    EffectiveSamples,
}

impl Temperature {
    fn validate(&self, lambda: f64) -> Result<()> {
        match self {
            Temperature::EffectiveSamples if lambda > 1.0 => Err(crate::PlanError::Config(
                format!("lambda is an effective-sample fraction in (0, 1], got {lambda}"),
            )),
            _ => Ok(()),
        }
    }

    /// `λ_eff` for these costs.
    pub fn resolve(&self, lambda: f64, costs: &Array1<f64>) -> f64 {
        let lo = costs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = costs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let spread = hi - lo;
        match self {
            Temperature::Fixed => lambda,
            _ if spread <= 0.0 => lambda,
            Temperature::Spread => lambda * spread,
            Temperature::EffectiveSamples => {
                let target = lambda * costs.len() as f64;
                let ess = |l: f64| {
                    let (mut s1, mut s2) = (0.0, 0.0);
                    for c in costs {
                        let w = (-(c - lo) / l).exp();
                        s1 += w;
                        s2 += w * w;
                    }
                    s1 * s1 / s2
                };
                // ESS grows with λ_eff from 1 (one sample) towards N (uniform).
                let (mut a, mut b) = ((spread * 1e-6).ln(), (spread * 1e6).ln());
                for _ in 0..60 {
                    let mid = 0.5 * (a + b);
                    if ess(mid.exp()) < target {
                        a = mid;
                    } else {
                        b = mid;
                    }
                }
                b.exp()
            }
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
        nonzero("particles", cfg.particles)?;
        nonzero("iterations", cfg.iterations)?;
        crate::mpc::correlation(cfg.correlation)?;
        cfg.knots.validate()?;
        positive("lambda", cfg.lambda)?;
        cfg.temperature.validate(cfg.lambda)?;
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
        let mut mean = warm_start(self.mean.take(), h, a, self.cfg.bounds.as_ref());
        let mut z = Array3::zeros((h, n, a));
        let mut acts = Array3::zeros((h, n, a));
        for _ in 0..self.cfg.iterations {
            crate::mpc::fill_knot_noise(
                &mut self.rng,
                &mut z,
                self.cfg.correlation,
                &self.cfg.knots,
            );
            // Sample 0 carries no noise: it is the mean itself.
            z.slice_mut(s![.., 0, ..]).fill(0.0);
            for t in 0..h {
                let centre = mean.slice(s![t..t + 1, ..]);
                add_noise(
                    &l,
                    centre.broadcast((n, a)).expect("one row broadcasts"),
                    z.slice(s![t, .., ..]),
                    acts.slice_mut(s![t, .., ..]),
                );
                clamp_opt(&self.cfg.bounds, acts.slice_mut(s![t, .., ..]));
            }
            let mut costs = rollout_particles(
                x0,
                model,
                objective,
                &mut self.rng,
                &mut acts,
                self.cfg.particles,
                self.cfg.propagation,
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
            let lam_eff = self.cfg.temperature.resolve(lam, &costs);
            let beta = costs.iter().copied().fold(f64::INFINITY, f64::min);
            let w = costs.mapv(|c| (-(c - beta) / lam_eff).exp());
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ess(costs: &Array1<f64>, l: f64) -> f64 {
        let lo = costs.iter().copied().fold(f64::INFINITY, f64::min);
        let w = costs.mapv(|c| (-(c - lo) / l).exp());
        w.sum().powi(2) / w.mapv(|v| v * v).sum()
    }

    #[test]
    fn temperature_rules() {
        let costs = Array1::from_iter((0..100).map(|i| ((i * 37) % 101) as f64 * 0.5));
        assert_eq!(Temperature::Fixed.resolve(2.0, &costs), 2.0);
        // Spread: the weights do not change when the costs are scaled and shifted.
        let scaled = costs.mapv(|c| 1000.0 * c + 7.0);
        let (a, b) = (
            Temperature::Spread.resolve(0.05, &costs),
            Temperature::Spread.resolve(0.05, &scaled),
        );
        assert!((b / a - 1000.0).abs() < 1e-9);
        assert!((a - 0.05 * 50.0).abs() < 1e-12);
        // Effective samples: the bisection meets the target share, at any cost scale.
        for c in [&costs, &scaled] {
            let l = Temperature::EffectiveSamples.resolve(0.1, c);
            assert!((ess(c, l) - 10.0).abs() < 1e-6, "{}", ess(c, l));
        }
        // Equal costs: nothing to scale, λ is returned as is.
        let flat = Array1::from_elem(5, 3.0);
        assert_eq!(Temperature::EffectiveSamples.resolve(0.1, &flat), 0.1);
        assert!(Temperature::EffectiveSamples.validate(1.5).is_err());
    }
}
