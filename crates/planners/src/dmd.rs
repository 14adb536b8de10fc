//! Dynamic mirror descent MPC (DMD-MPC: Wagener et al. 2019; p3 §2–3).
//!
//! The control distribution is a Gaussian over the `H x A` sequence with fixed covariance `Σ`
//! per step. One round (p3 eq. 5–6 with the KL divergence as Bregman divergence):
//!
//! 1. **Shift** `μ̃ = Φ(μ_prev)`: either the previous plan moved one step earlier (Wagener et al.)
//!    or, in p3's two-loop scheme, a policy proposal: `μ̃_h = π_θ(x_h)` along the model rollout of
//!    the policy itself (eq. 10). Samples then draw `u_h ~ N(π_θ(x_h), Σ)` at their own states
//!    (eq. 11) and step the model (eq. 12).
//! 2. **Mirror-descent step** on the expectation parameter (eq. 9):
//!    `μ = (1 − α) μ̃ + α g`, where `g` is the utility-weighted mean of the sampled sequences:
//!    the elite mean (CEM utility, eq. 13; optionally reward-weighted among the elites, eq. 14) or
//!    the exponentially weighted mean `Σ e^{−C_i/λ} u_i / Σ e^{−C_i/λ}` (MPPI's utility).
//!
//! The sampling noise may be time-correlated (`correlation`) and drawn at [`Knots`] (held or
//! interpolated between them); `μ` and `Σ` stay per step.
//!
//! The returned [`Plan`] is the model rollout of `μ` (p3 Algorithm 1, line 14); its
//! [`Plan::transitions`] are what p3 adds to the MPC replay buffer (line 15). A terminal value
//! `−V` enters through the [`Objective`].

use ndarray::{s, Array1, Array2, Array3, ArrayView1, ArrayView2, ArrayView3, ArrayViewMut2, Axis};
use tandem_core::{seeding::rng_from_seed, Rng};
use tandem_models::{DynamicsModel, Propagation};

use crate::error::{check_len, PlanError, Result};
use crate::mpc::{
    add_noise, check_problem, clamp_opt, fraction, lowest_k, mean_per, nonzero, one_row,
    plans_from_actions, positive, rollout_starts, warm_start, Bounds, Knots, Noise, Plan, Planner,
    Rollout,
};
use crate::objective::Objective;

/// A policy proposal for the shift operator: a batch of states (`B x S`) to action means
/// (`B x A`), e.g. the mean action of p3's SAC actor.
pub type Proposal = Box<dyn Fn(ArrayView2<'_, f64>) -> Array2<f64> + Send + Sync>;

/// A borrowed policy proposal (states to action means).
pub type ProposalFn<'a> = &'a dyn Fn(ArrayView2<'_, f64>) -> Array2<f64>;

/// How sampled sequences are weighted into the gradient estimate `g` of eq. 9.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Utility {
    /// CEM utility `−log E[1{C ≤ C_max}]` (p3 eq. 13): `g` is the mean of the elite fraction.
    /// With `reward_weighted`, elites are weighted by how much better than the worst elite they
    /// are (`w_i = C_max − C_i`), our reading of p3 eq. 14's "reward weighted mean".
    CemElite {
        /// Fraction of samples kept (p3: 10%).
        elite_fraction: f64,
        /// Weight elites by their cost margin instead of equally.
        reward_weighted: bool,
    },
    /// Exponential utility: `g = Σ e^{−(C_i − min C)/λ} u_i / Σ e^{−(C_i − min C)/λ}`.
    Exponential {
        /// Temperature `λ > 0`.
        lambda: f64,
    },
}

/// Settings of [`DmdMpc`]. Defaults follow p3 §4.1: 100 rollouts, 10% elites, horizon 15 (the top
/// of their 5–15 schedule). p3 gives no step size or covariance; `α = 0.8` and unit noise are ours.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DmdMpcConfig {
    /// Planning horizon `H`.
    pub horizon: usize,
    /// Sampled sequences `M` per round.
    pub samples: usize,
    /// Rollouts per sequence, its cost their mean (PETS's particles, dealt over an ensemble's
    /// members as [`crate::Cem`]'s docs say). With a policy proposal each particle acts on its
    /// own state, and the sequence's actions are its first particle's.
    #[serde(skip_serializing_if = "is_one")]
    pub particles: usize,
    /// How an ensemble propagates the rollouts; `None` keeps the model's own setting.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub propagation: Option<Propagation>,
    /// Mirror-descent step size `α ∈ (0, 1]` (eq. 9).
    pub step_size: f64,
    /// Utility that weights the samples.
    pub utility: Utility,
    /// Covariance `Σ` of the control distribution at each step.
    pub noise: Noise,
    /// Correlation `β ∈ [0, 1)` of the sampling noise between consecutive steps (AR(1); 0 is
    /// white noise, the original algorithm).
    pub correlation: f64,
    /// Where the sampling noise is drawn along the horizon (default: every step).
    pub knots: Knots,
    /// Rounds per call (the first uses the shift operator; later ones re-sample around `μ`).
    pub iterations: usize,
    /// Also take the mirror-descent step on the second moment (the Gaussian's other expectation
    /// parameter): `E[u²] ← (1 − α) E_μ̃[u²] + α E_w[u²]`, per component (a diagonal covariance
    /// restarted from the diagonal of `noise` at every call, as PETS restarts CEM's variance: a
    /// collapsed covariance carried over by the shift stops exploring; floored at `min_std`).
    /// p3 keeps `Σ` fixed (`false`).
    pub adapt_covariance: bool,
    /// Floor on the adapted standard deviation.
    pub min_std: f64,
    /// Action bounds.
    pub bounds: Option<Bounds>,
    /// Seed of the sampling stream.
    pub seed: u64,
}

impl Default for DmdMpcConfig {
    fn default() -> Self {
        Self {
            horizon: 15,
            samples: 100,
            particles: 1,
            propagation: None,
            step_size: 0.8,
            utility: Utility::CemElite {
                elite_fraction: 0.1,
                reward_weighted: false,
            },
            noise: Noise::Isotropic(1.0),
            iterations: 1,
            adapt_covariance: false,
            min_std: 0.05,
            correlation: 0.0,
            knots: Knots::default(),
            bounds: None,
            seed: 0,
        }
    }
}

/// DMD-MPC planner; see the module docs.
pub struct DmdMpc {
    cfg: DmdMpcConfig,
    rng: Rng,
    mean: Option<Array2<f64>>,
    proposal: Option<Proposal>,
}

impl std::fmt::Debug for DmdMpc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DmdMpc")
            .field("cfg", &self.cfg)
            .field("has_proposal", &self.proposal.is_some())
            .finish()
    }
}

impl DmdMpc {
    /// A planner with these settings (checked here), shifting the previous plan.
    pub fn new(cfg: DmdMpcConfig) -> Result<Self> {
        nonzero("horizon", cfg.horizon)?;
        nonzero("samples", cfg.samples)?;
        nonzero("particles", cfg.particles)?;
        nonzero("iterations", cfg.iterations)?;
        crate::mpc::correlation(cfg.correlation)?;
        cfg.knots.validate()?;
        fraction("step size alpha", cfg.step_size)?;
        if cfg.adapt_covariance {
            positive("min_std", cfg.min_std)?;
        }
        match cfg.utility {
            Utility::CemElite { elite_fraction, .. } => fraction("elite fraction", elite_fraction)?,
            Utility::Exponential { lambda } => positive("lambda", lambda)?,
        }
        let rng = rng_from_seed(cfg.seed);
        Ok(Self {
            cfg,
            rng,
            mean: None,
            proposal: None,
        })
    }

    /// Uses a policy proposal as the shift operator (p3's two-loop shift, eq. 10–12).
    pub fn with_proposal(
        mut self,
        proposal: impl Fn(ArrayView2<'_, f64>) -> Array2<f64> + Send + Sync + 'static,
    ) -> Self {
        self.proposal = Some(Box::new(proposal));
        self
    }

    /// Replaces (or removes) the policy proposal, e.g. after the outer loop updated its policy.
    pub fn set_proposal(&mut self, proposal: Option<Proposal>) {
        self.proposal = proposal;
    }

    /// The settings.
    pub fn config(&self) -> &DmdMpcConfig {
        &self.cfg
    }

    /// One call with an explicit proposal (borrowed for this call only), ignoring any stored one.
    pub fn plan_with_proposal(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
        proposal: ProposalFn<'_>,
    ) -> Result<Plan> {
        self.plan_one(x0, model, objective, Some(proposal))
    }

    /// Plans from every row of `starts` (`P x S`) at once, as `P` independent calls of
    /// [`DmdMpc::plan_with_proposal`] would, each with its own samples, but in one population of
    /// `P × samples` rows: each model, proposal and terminal-value call is one batch for all
    /// starts instead of one per start (the plans differ from sequential calls only in the
    /// random numbers drawn). The plans neither use nor replace the stored warm start, which belongs to one state: without a proposal each
    /// start's first centre is the middle of the bounds (zero without bounds).
    pub fn plan_batch_with_proposal(
        &mut self,
        starts: ArrayView2<'_, f64>,
        model: &dyn DynamicsModel,
        objective: &Objective,
        proposal: ProposalFn<'_>,
    ) -> Result<Vec<Plan>> {
        let (h, a) = (self.cfg.horizon, model.action_dim());
        for x0 in starts.rows() {
            check_problem(&x0.to_vec(), model, objective)?;
        }
        let means = vec![warm_start(None, h, a, self.cfg.bounds.as_ref()); starts.nrows()];
        let (plans, _) = self.plan_impl(starts, model, objective, Some(proposal), means)?;
        Ok(plans)
    }

    /// One start: the stored warm start in, the new mean stored.
    fn plan_one(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
        proposal: Option<ProposalFn<'_>>,
    ) -> Result<Plan> {
        let (_, a) = check_problem(x0, model, objective)?;
        let mean = warm_start(
            self.mean.take(),
            self.cfg.horizon,
            a,
            self.cfg.bounds.as_ref(),
        );
        let (mut plans, mut means) =
            self.plan_impl(one_row(x0), model, objective, proposal, vec![mean])?;
        self.mean = means.pop();
        Ok(plans.pop().expect("one start, one plan"))
    }

    /// The rounds for `P` starts (`starts` checked by the caller) from their first means
    /// (`H x A` each); returns the plans and the final means.
    fn plan_impl(
        &mut self,
        starts: ArrayView2<'_, f64>,
        model: &dyn DynamicsModel,
        objective: &Objective,
        proposal: Option<ProposalFn<'_>>,
        mut means: Vec<Array2<f64>>,
    ) -> Result<(Vec<Plan>, Vec<Array2<f64>>)> {
        let a = model.action_dim();
        if let Some(b) = &self.cfg.bounds {
            b.validate(a)?;
        }
        let l = self.cfg.noise.cholesky(a)?;
        let (h, n, p) = (self.cfg.horizon, self.cfg.samples, starts.nrows());
        let std0: Vec<f64> = (0..a).map(|j| l.row(j).norm()).collect();
        let mut stds = vec![Array2::from_shape_fn((h, a), |(_, j)| std0[j]); p];
        let adapt = self.cfg.adapt_covariance;
        // Rows are start-major, then sample, then particle.
        let q = self.cfg.particles;
        let mut z = Array3::zeros((h, n * p, a));
        let mut acts = Array3::zeros((h, n * p * q, a));
        for it in 0..self.cfg.iterations {
            crate::mpc::fill_knot_noise(
                &mut self.rng,
                &mut z,
                self.cfg.correlation,
                &self.cfg.knots,
            );
            // Sample 0 of each start carries no noise: it is the shifted mean μ̃ itself.
            for k in 0..p {
                z.slice_mut(s![.., k * n, ..]).fill(0.0);
            }
            // A sample's particles share its noise.
            let particle_noise;
            let z = match q {
                1 => &z,
                _ => {
                    particle_noise =
                        Array3::from_shape_fn((h, n * p * q, a), |(t, r, j)| z[(t, r / q, j)]);
                    &particle_noise
                }
            };
            let bounds = self.cfg.bounds.clone();
            let policy = if it == 0 { proposal } else { None };
            let (means_ref, stds_ref) = (&means, &stds);
            let act = |t: usize, states: ArrayView2<'_, f64>, mut u: ArrayViewMut2<'_, f64>| {
                let centre: Array2<f64> = match policy {
                    Some(pf) => {
                        let c = pf(states);
                        check_len("proposal rows", states.nrows(), c.nrows())?;
                        check_len("proposal columns", a, c.ncols())?;
                        if c.iter().any(|v| !v.is_finite()) {
                            return Err(PlanError::NonFinite("policy proposal".into()));
                        }
                        c
                    }
                    None => Array2::from_shape_fn((states.nrows(), a), |(i, j)| {
                        means_ref[i / (n * q)][(t, j)]
                    }),
                };
                if adapt {
                    let zt = z.slice(s![t, .., ..]);
                    u.zip_mut_with(&centre, |o, c| *o = *c);
                    for i in 0..u.nrows() {
                        let sd = &stds_ref[i / (n * q)];
                        for j in 0..a {
                            u[(i, j)] += sd[(t, j)] * zt[(i, j)];
                        }
                    }
                } else {
                    add_noise(&l, centre.view(), z.slice(s![t, .., ..]), u.view_mut());
                }
                clamp_opt(&bounds, u);
                Ok(())
            };
            let rollout = Rollout {
                model,
                objective,
                propagation: self.cfg.propagation,
            };
            let (costs, _) =
                rollout_starts(starts, &rollout, &mut self.rng, &mut acts, act, None, None)?;
            let costs = mean_per(costs, q);
            // Each sample's actions: its first particle's.
            let sampled = acts.slice(s![.., ..;q, ..]);
            let al = self.cfg.step_size;
            for k in 0..p {
                let rows = s![.., k * n..(k + 1) * n, ..];
                let acts_k = sampled.slice(rows);
                let costs_k = costs.slice(s![k * n..(k + 1) * n]);
                // μ̃: the noise-free sample (the shifted plan, or the policy's own rollout).
                let shifted = acts_k.index_axis(Axis(1), 0).to_owned();
                let (g, g2) = self.weighted_moments(acts_k, costs_k)?;
                let mean = &shifted * (1.0 - al) + &g * al;
                if adapt {
                    let std = &mut stds[k];
                    for t in 0..h {
                        for j in 0..a {
                            let (mt, st) = (shifted[(t, j)], std[(t, j)]);
                            let m2 = (1.0 - al) * (st * st + mt * mt) + al * g2[(t, j)];
                            let var = m2 - mean[(t, j)] * mean[(t, j)];
                            std[(t, j)] = var.max(0.0).sqrt().max(self.cfg.min_std);
                        }
                    }
                }
                means[k] = mean;
            }
        }
        let mut chosen = Array3::zeros((h, p, a));
        for (k, mean) in means.iter_mut().enumerate() {
            clamp_opt(&self.cfg.bounds, mean.view_mut());
            chosen.index_axis_mut(Axis(1), k).assign(mean);
        }
        let plans = plans_from_actions(starts, model, objective, &mut self.rng, chosen)?;
        Ok((plans, means))
    }

    /// `g` of eq. 9, the utility-weighted mean sequence (`H x A`), and the weighted second moment.
    fn weighted_moments(
        &self,
        acts: ArrayView3<'_, f64>,
        costs: ArrayView1<'_, f64>,
    ) -> Result<(Array2<f64>, Array2<f64>)> {
        let (h, n, a) = acts.dim();
        let mut w = Array1::zeros(n);
        match self.cfg.utility {
            Utility::CemElite {
                elite_fraction,
                reward_weighted,
            } => {
                let k = ((elite_fraction * n as f64).round() as usize).clamp(1, n);
                let el = lowest_k(&costs.to_owned(), k);
                let cmax = costs[el[k - 1]];
                let scale = 1e-9 * (1.0 + cmax.abs());
                for &i in &el {
                    w[i] = if reward_weighted {
                        cmax - costs[i] + scale
                    } else {
                        1.0
                    };
                }
            }
            Utility::Exponential { lambda } => {
                let beta = costs.iter().copied().fold(f64::INFINITY, f64::min);
                w = costs.mapv(|c| (-(c - beta) / lambda).exp());
            }
        }
        let wsum = w.sum();
        if !(wsum > 0.0 && wsum.is_finite()) {
            return Err(PlanError::Numerical("utility weights sum to zero".into()));
        }
        let mut g = Array2::zeros((h, a));
        let mut g2 = Array2::zeros((h, a));
        for t in 0..h {
            for i in 0..n {
                if w[i] != 0.0 {
                    for j in 0..a {
                        let v = acts[(t, i, j)];
                        g[(t, j)] += w[i] * v;
                        g2[(t, j)] += w[i] * v * v;
                    }
                }
            }
        }
        Ok((g / wsum, g2 / wsum))
    }
}

impl Planner for DmdMpc {
    fn plan(
        &mut self,
        x0: &[f64],
        model: &dyn DynamicsModel,
        objective: &Objective,
    ) -> Result<Plan> {
        let proposal = self.proposal.take();
        let r = self.plan_one(
            x0,
            model,
            objective,
            proposal
                .as_ref()
                .map(|p| p.as_ref() as &dyn Fn(ArrayView2<'_, f64>) -> Array2<f64>),
        );
        self.proposal = proposal;
        r
    }

    fn reset(&mut self) {
        self.mean = None;
        self.rng = rng_from_seed(self.cfg.seed);
    }
}

/// Serde's test for the default particle count, so settings written before particles existed
/// stay byte for byte.
fn is_one(v: &usize) -> bool {
    *v == 1
}
