//! Cross-entropy method MPC (the planner of PETS, Chua et al. 2018).
//!
//! Each call: warm start from the previous mean shifted by one step, then `iterations` rounds of
//! sample `N` sequences from `N(μ, σ²)`, clamp them into the bounds, roll them out through the
//! model, refit `μ, σ` to the elites with smoothing `α` (`μ ← αμ + (1−α)μ_elite`), and keep
//! `σ ≥ min_std`. Sample 0 of every round is the current mean itself, so the mean is always
//! evaluated. The plan is the cheapest sequence sampled over all rounds (mbrl-lib's default,
//! `return_mean_elites = false`), or the final mean with `return_mean`; the warm start of the next
//! call is the final mean either way. The sampling noise may be time-correlated (`correlation`)
//! and drawn at [`Knots`] (held or interpolated between them); mean and σ stay per step.
//!
//! With `particles = P > 1`, each sequence is rolled out `P` times and scored by the mean of its
//! costs (PETS's trajectory sampling). The particles of a sequence are consecutive rows of one
//! batch: through a [`tandem_models::ProbabilisticEnsemble`] propagating with `FixedMember`
//! (TS-∞) they are dealt over the elites as evenly as `P` allows (each elite `P/E` times when
//! `P` is a multiple of the elite count `E`), with `RandomMember` (TS-1) each particle draws a
//! member at every step, and with `Expectation` they differ only by the model's sampling. The
//! propagation is the model's own setting unless `propagation` names one. Defaults: one particle
//! (PETS uses 20), the model's propagation.

use ndarray::{s, Array2, Array3, Axis};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_models::{DynamicsModel, Propagation};

use crate::error::Result;
use crate::mpc::{
    check_problem, clamp_opt, fraction, lowest_k, nonzero, plan_from_actions, positive,
    rollout_particles, warm_start, Bounds, Knots, Plan, Planner,
};
use crate::objective::Objective;

/// Settings of [`Cem`]. Defaults are PETS's (Chua et al. 2018, §5/appendix): population 500, 50
/// elites, 5 iterations, smoothing 0.1, horizon 30.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CemConfig {
    /// Planning horizon `H`.
    pub horizon: usize,
    /// Sequences sampled per iteration `N`.
    pub population: usize,
    /// Rollouts per sequence `P`, its cost their mean (PETS's particles; see
    /// [`Cem`]'s docs for how they meet an ensemble's members).
    pub particles: usize,
    /// How an ensemble propagates the rollouts (`fixed_member`: TS-∞, `random_member`: TS-1,
    /// `expectation`); `None` keeps the model's own setting.
    pub propagation: Option<Propagation>,
    /// Fraction of the population kept as elites.
    pub elite_fraction: f64,
    /// Refits per plan.
    pub iterations: usize,
    /// Smoothing `α ∈ [0, 1)`: weight of the old mean and variance in each refit.
    pub alpha: f64,
    /// Initial standard deviation per action component; `None`: a quarter of the bound range
    /// (PETS: variance `(high − low)² / 16`), or 1 where unbounded.
    pub init_std: Option<Vec<f64>>,
    /// Correlation `β ∈ [0, 1)` of the sampling noise between consecutive steps (AR(1); 0 is
    /// white noise, the original algorithm).
    pub correlation: f64,
    /// Where the sampling noise is drawn along the horizon (default: every step).
    pub knots: Knots,
    /// Floor on the standard deviation.
    pub min_std: f64,
    /// Action bounds; samples are clamped into them.
    pub bounds: Option<Bounds>,
    /// Return the final mean instead of the cheapest sampled sequence.
    pub return_mean: bool,
    /// Seed of the sampling stream.
    pub seed: u64,
}

impl Default for CemConfig {
    fn default() -> Self {
        Self {
            horizon: 30,
            population: 500,
            particles: 1,
            propagation: None,
            elite_fraction: 0.1,
            iterations: 5,
            alpha: 0.1,
            init_std: None,
            min_std: 1e-3,
            correlation: 0.0,
            knots: Knots::default(),
            bounds: None,
            return_mean: false,
            seed: 0,
        }
    }
}

/// Cross-entropy method planner; see the module docs.
#[derive(Debug, Clone)]
pub struct Cem {
    cfg: CemConfig,
    rng: Rng,
    mean: Option<Array2<f64>>,
}

impl Cem {
    /// A planner with these settings (checked here).
    pub fn new(cfg: CemConfig) -> Result<Self> {
        nonzero("horizon", cfg.horizon)?;
        nonzero("population", cfg.population)?;
        nonzero("particles", cfg.particles)?;
        nonzero("iterations", cfg.iterations)?;
        crate::mpc::correlation(cfg.correlation)?;
        cfg.knots.validate()?;
        fraction("elite fraction", cfg.elite_fraction)?;
        if !(0.0..1.0).contains(&cfg.alpha) {
            return Err(crate::PlanError::Config(format!(
                "smoothing alpha must be in [0, 1), got {}",
                cfg.alpha
            )));
        }
        if cfg.min_std != 0.0 {
            positive("min_std", cfg.min_std)?;
        }
        if let Some(s) = &cfg.init_std {
            for v in s {
                positive("init_std", *v)?;
            }
        }
        let rng = rng_from_seed(cfg.seed);
        Ok(Self {
            cfg,
            rng,
            mean: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &CemConfig {
        &self.cfg
    }

    fn init_std(&self, a: usize) -> Result<Vec<f64>> {
        if let Some(s) = &self.cfg.init_std {
            crate::error::check_len("init_std", a, s.len())?;
            return Ok(s.clone());
        }
        Ok(match &self.cfg.bounds {
            Some(b) => b
                .low
                .iter()
                .zip(&b.high)
                .map(|(l, h)| {
                    if (h - l).is_finite() {
                        0.25 * (h - l)
                    } else {
                        1.0
                    }
                })
                .collect(),
            None => vec![1.0; a],
        })
    }
}

impl Planner for Cem {
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
        let (h, n) = (self.cfg.horizon, self.cfg.population);
        let n_elite = ((self.cfg.elite_fraction * n as f64).round() as usize).clamp(1, n);
        let std0 = self.init_std(a)?;
        let mut mean = warm_start(self.mean.take(), h, a, self.cfg.bounds.as_ref());
        let mut std = Array2::from_shape_fn((h, a), |(_, j)| std0[j]);
        let mut acts = Array3::zeros((h, n, a));
        let mut best: Option<(f64, Array2<f64>)> = None;
        for _ in 0..self.cfg.iterations {
            crate::mpc::fill_knot_noise(
                &mut self.rng,
                &mut acts,
                self.cfg.correlation,
                &self.cfg.knots,
            );
            for t in 0..h {
                for i in 0..n {
                    for j in 0..a {
                        let z = if i == 0 { 0.0 } else { acts[(t, i, j)] };
                        acts[(t, i, j)] = mean[(t, j)] + std[(t, j)] * z;
                    }
                }
                clamp_opt(&self.cfg.bounds, acts.slice_mut(s![t, .., ..]));
            }
            let costs = rollout_particles(
                x0,
                model,
                objective,
                &mut self.rng,
                &mut acts,
                self.cfg.particles,
                self.cfg.propagation,
            )?;
            let elites = lowest_k(&costs, n_elite);
            if best.as_ref().is_none_or(|(c, _)| costs[elites[0]] < *c) {
                best = Some((
                    costs[elites[0]],
                    acts.index_axis(Axis(1), elites[0]).to_owned(),
                ));
            }
            let el = acts.select(Axis(1), &elites);
            let em = el.mean_axis(Axis(1)).expect("at least one elite");
            let ev = el.var_axis(Axis(1), 0.0);
            let al = self.cfg.alpha;
            mean = &mean * al + &em * (1.0 - al);
            std.zip_mut_with(&ev, |sd, v| {
                *sd = (al * *sd * *sd + (1.0 - al) * v)
                    .sqrt()
                    .max(self.cfg.min_std)
            });
        }
        clamp_opt(&self.cfg.bounds, mean.view_mut());
        let chosen = match best {
            Some((_, seq)) if !self.cfg.return_mean => seq,
            _ => mean.clone(),
        };
        let plan = plan_from_actions(x0, model, objective, &mut self.rng, &chosen)?;
        self.mean = Some(mean);
        Ok(plan)
    }

    fn reset(&mut self) {
        self.mean = None;
        self.rng = rng_from_seed(self.cfg.seed);
    }
}
