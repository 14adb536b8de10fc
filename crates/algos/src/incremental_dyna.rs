//! Paper p1 (Cong Li): Dyna-SAC with the deep incremental model, Algorithm 1, against SAC and
//! MBPO on the same loop.
//!
//! p1's Algorithm 1 is MBPO's loop ([`super::mbpo`]) with its model replaced and its rollouts one
//! step long:
//!
//! - line 3: **train `f(θ)` on `D_env`**: here the [`IncrementalModel`] `ŝ_{t+1} = s_t +
//!   L_θ(s_t, a_{t−1}) (a_t − a_{t−1})` (eqs. 4–6), refit on all real transitions every
//!   [`MbpoConfig::model_train_freq`] real steps by loss (5) on the one-step-back data (the
//!   model's state is `[s_t, a_{t−1}]`: the loop records each state with the control before it,
//!   zero at an episode's start, [`Imagination::new_data`]);
//! - line 5: act in the real system with SAC's exploring policy, the transition into `D_env`;
//! - lines 6–9: **`M` one-step model rollouts** from real states drawn uniformly from `D_env`,
//!   acted by SAC, each predicted from its real state and the real control before it (the
//!   rollouts run under [`WithPrevAction`] of the task, whose state carries that control); the
//!   reward and termination of the predicted step are the task's ("reward from the task": the
//!   incremental model predicts states only); the transitions fill `D_model`;
//! - lines 10–12: `G` SAC updates on minibatches of `D_model` and `D_env` at
//!   [`MbpoConfig::real_ratio`] real data.
//!
//! Like MBPO's implementation, the `M` rollouts of every real step are made in one batch right
//! after each refit (`M × model_train_freq` of them); the count is the same.
//!
//! [`run`] runs one [`Method`] for one seed; `examples/incremental_dyna.rs` reads next to
//! Algorithm 1.

use serde::{Deserialize, Serialize};
use tandem_agents::{BatchPolicy, OffPolicyAgent, OffPolicyLoop};
use tandem_core::{LinearSchedule, Rng};
use tandem_envs::{Env, EnvError, Task, WithPrevAction};
use tandem_models::{
    DynamicsModel, FitConfig, IncrementalModel, IncrementalModelConfig, Judges, Transitions,
    TransitionsBuilder,
};
use tandem_nn::budget::MemoryEstimate;

use super::mbpo::{fitted, run_with, Event, Imagination, Imagine, MbpoConfig, Rollouts, RunRecord};
use super::{Checkpoints, Problem, Result};

/// One of the three methods p1's Fig. 1 compares here (MnM is not built).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// SAC alone on the real system.
    Sac,
    /// MBPO: branched rollouts through a probabilistic ensemble.
    Mbpo,
    /// p1: one-step rollouts through the incremental model.
    IncrementalDyna,
}

impl Method {
    /// All three.
    pub const ALL: [Method; 3] = [Method::Sac, Method::Mbpo, Method::IncrementalDyna];

    /// `"sac"`, `"mbpo"` or `"incremental_dyna"` (the keys of records and checkpoints).
    pub fn name(self) -> &'static str {
        match self {
            Method::Sac => "sac",
            Method::Mbpo => "mbpo",
            Method::IncrementalDyna => "incremental_dyna",
        }
    }
}

/// Settings of a p1 comparison: the loop all three methods share (MBPO's, as p1 compares at
/// MBPO's settings) and the incremental model.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct P1Config {
    /// The shared loop. Its `ensemble` and `reward` concern MBPO only; Dyna-SAC's rollouts take
    /// `rollouts_per_step`, `model_train_freq`, the fit budget and `real_ratio` from it, and are
    /// always one step long with the task's reward and termination.
    pub base: MbpoConfig,
    /// The incremental model (its `seed` is set per run): two hidden layers of 200 ReLU units,
    /// Adam 1e-3, a full `L` (p1 gives no architecture; [`IncrementalModelConfig`]'s default).
    pub model: IncrementalModelConfig,
}

impl P1Config {
    /// Checks the ranges the loops rely on.
    pub fn validate(&self) -> Result<()> {
        self.base.validate()?;
        Ok(self.model.validate()?)
    }

    /// The memory of `method`'s run on `obs_dim`-dimensional states and `act_dim`-dimensional
    /// actions ([`MbpoConfig::memory`]; Dyna-SAC's model is the incremental one and its
    /// rollouts are one step long).
    pub fn memory(&self, method: Method, obs_dim: usize, act_dim: usize) -> MemoryEstimate {
        let b = &self.base;
        match method {
            Method::Sac => MemoryEstimate::new().with("base.sac.", b.sac.memory(obs_dim, act_dim)),
            Method::Mbpo => MemoryEstimate::new().with(
                "base.",
                b.memory(obs_dim, act_dim, b.max_rollout_capacity()),
            ),
            Method::IncrementalDyna => {
                let rollouts = b.rollout_capacity(1);
                MemoryEstimate::new()
                    .with("base.sac.", b.sac.memory(obs_dim, act_dim))
                    .with(
                        "model: ",
                        self.model.memory(obs_dim, act_dim, b.model_fit.batch_size),
                    )
                    .part(
                        "base: secondary buffer (one-step rollouts)",
                        rollouts.and_then(|n| {
                            tandem_agents::replay::ReplayBuffer::bytes(n, obs_dim, act_dim)
                        }),
                    )
            }
        }
    }
}

/// p1's one-step rollouts through the incremental model, as the shared loop's [`Imagination`]:
/// MBPO's rollout sizes with the length fixed at 1 and the task's reward and termination.
#[derive(Debug, Clone)]
pub struct IncrementalRollouts {
    /// `M` per real step, real steps between refits, retained epochs (length 1 throughout).
    pub rollouts: Rollouts,
    /// The model's settings; [`Imagination::new_model`] sets the seed.
    pub model: IncrementalModelConfig,
}

impl IncrementalRollouts {
    /// The rollouts as `cfg` sizes them, through an incremental model of `model`'s settings.
    pub fn of(cfg: &P1Config) -> Self {
        let mut rollouts = Rollouts::of(&cfg.base);
        rollouts.length = LinearSchedule::constant(1);
        rollouts.judges = Judges::default();
        Self {
            rollouts,
            model: cfg.model.clone(),
        }
    }
}

impl Imagination for IncrementalRollouts {
    type Model = IncrementalModel;

    fn name(&self) -> &'static str {
        Method::IncrementalDyna.name()
    }

    fn capacity(&self, cfg: &MbpoConfig, epoch: u64) -> usize {
        self.rollouts.capacity(cfg, epoch)
    }

    fn horizon(&self, _epoch: u64) -> usize {
        1
    }

    fn new_model(
        &self,
        _cfg: &MbpoConfig,
        state_dim: usize,
        control_dim: usize,
        seed: u64,
    ) -> Result<Option<IncrementalModel>> {
        let cfg = IncrementalModelConfig {
            seed,
            ..self.model.clone()
        };
        Ok(Some(IncrementalModel::new(state_dim, control_dim, cfg)?))
    }

    /// The incremental model's rows: canonical states and the control applied before them.
    fn new_data(&self, state_dim: usize, control_dim: usize) -> TransitionsBuilder {
        TransitionsBuilder::with_prev_action(state_dim, control_dim)
    }
}

impl<T: Task, A: OffPolicyAgent + BatchPolicy> Imagine<T, A> for IncrementalRollouts {
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<A>,
        model: Option<&mut IncrementalModel>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        _seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let model = fitted(model, Method::IncrementalDyna.name())?;
        let r = &self.rollouts;
        let task = WithPrevAction::new(task);
        r.through(&*model, &r.judges, lp, &task, data, epoch, rng)
    }
}

/// Runs `method` for `seed` on `problem` (resuming from the checkpoint `store` holds under the
/// method's name, if any). SAC and MBPO run [`super::mbpo`]'s loop with `cfg.base`, so their
/// numbers are those of [`super::mbpo::run_sac`] and [`super::mbpo::run`] with it.
pub fn run<T, F>(
    method: Method,
    problem: &Problem<T, F>,
    cfg: &P1Config,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    T: Task,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    cfg.validate()?;
    match method {
        Method::Sac => super::mbpo::run_sac(problem, &cfg.base, seed, store, on_event),
        Method::Mbpo => super::mbpo::run(problem, &cfg.base, seed, store, on_event),
        Method::IncrementalDyna => {
            let mut r = IncrementalRollouts::of(cfg);
            run_with(problem, &cfg.base, seed, Some(&mut r), store, on_event)
        }
    }
}

/// Settings of p1's §6 online fine-tuning: a residual incremental policy from the
/// error-evolution model `e_{k+1} = e_k + L_k Δa_{e,k}` (eq. 9) added to a pre-trained policy
/// after the system changed. `Default`: 10 episodes (our budget), MPC over one step
/// (`horizon` 1; p1 allows "MPC or LQR"), the model refit after every episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FineTuneConfig {
    /// Episodes on the changed system.
    pub episodes: usize,
    /// `Q`'s diagonal: the weight of each state component's squared tracking error (0 for a
    /// component without a target, e.g. a clock). Empty: all ones.
    pub error_weights: Vec<f64>,
    /// `R = r I`: the weight of the squared residual increment (in the agent's action units).
    pub increment_weight: f64,
    /// Steps of the finite-horizon LQR on eq. (9) with `L_k` held over them (1: one-step MPC).
    pub horizon: usize,
    /// Refit `L_θ` after every episode on all of the changed system's transitions so far (p1:
    /// the error-evolution model is fitted online); `false` keeps the model it is given.
    pub refit: bool,
    /// Each refit (continuing from the current weights).
    pub fit: FitConfig,
}

impl Default for FineTuneConfig {
    fn default() -> Self {
        Self {
            episodes: 10,
            error_weights: Vec::new(),
            increment_weight: 1e-3,
            horizon: 1,
            refit: true,
            fit: FitConfig {
                epochs: 5,
                batch_size: 256,
                holdout_fraction: 0.1,
                seed: 0,
                early_stop: None,
            },
        }
    }
}

/// The first step's gain of the LQR on `e_{t+1} = e_t + L u_t` (A = I, B = L) with stage cost
/// `eᵀQe + uᵀRu` over `horizon` steps and terminal weight `Q`: `Δa = −K e`. `None` where a
/// solve fails (a singular `R + LᵀPL`, which `R > 0` rules out).
pub fn residual_gain(
    l: &nalgebra::DMatrix<f64>,
    q: &[f64],
    r: f64,
    horizon: usize,
) -> Option<nalgebra::DMatrix<f64>> {
    use nalgebra::DMatrix;
    let (s, a) = l.shape();
    let qm = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(q));
    let mut p = qm.clone();
    let mut k = DMatrix::zeros(a, s);
    for _ in 0..horizon.max(1) {
        let m = DMatrix::<f64>::identity(a, a) * r + l.transpose() * &p * l;
        k = m.cholesky()?.solve(&(l.transpose() * &p));
        p = &qm + &p - &p * l * &k;
    }
    Some(k)
}

/// One episode of fine-tuning (or of the pre-trained policy alone).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FineTuneEpisode {
    /// The episode's return.
    pub episode_return: f64,
    /// Mean over the steps of the residual's largest component (action units).
    pub mean_residual: f64,
}

/// p1 §6 on a changed system: `cfg.episodes` episodes of `agent`'s deterministic policy `a_d`
/// plus, where `residual` is set, the residual incremental policy: at every step the tracking
/// error `e = s − desired(s)` (canonical states), `L_k = L_θ(s_k, a_{k−1})` from `model`, the
/// increment `Δa_e = −K e` of the LQR on eq. (9), accumulated (`c_k = c_{k−1} + Δa_e`, an
/// incremental policy integrates its increments) and applied as `a = clip(a_d + c)`. The
/// model works in the agent's action units (fitted on them, e.g. on the original system, or
/// started from a prior `L0`); with `cfg.refit` it is refit after every episode on all
/// transitions of the changed system so far. Episode `i` resets `env` with seed `seed + i`.
/// Returns each episode's figures.
#[allow(clippy::too_many_arguments)]
pub fn fine_tune<T: Task + ?Sized>(
    agent: &mut dyn tandem_agents::Agent,
    env: &mut dyn Env,
    task: &T,
    desired: &dyn Fn(&[f64]) -> Vec<f64>,
    model: &mut IncrementalModel,
    cfg: &FineTuneConfig,
    residual: bool,
    seed: u64,
) -> Result<Vec<FineTuneEpisode>> {
    use tandem_core::Action;
    let (low, high) = super::box_bounds(task.action_space(), "fine-tuning adds residual actions:")?;
    let (s_dim, a_dim) = (task.state_dim(), low.len());
    let q: Vec<f64> = if cfg.error_weights.is_empty() {
        vec![1.0; s_dim]
    } else {
        cfg.error_weights.clone()
    };
    if q.len() != s_dim || q.iter().any(|w| !(w.is_finite() && *w >= 0.0)) {
        return Err(super::AlgoError::Config(format!(
            "error_weights: {s_dim} finite weights >= 0, got {:?}",
            cfg.error_weights
        )));
    }
    if !(cfg.increment_weight.is_finite() && cfg.increment_weight > 0.0) {
        return Err(super::AlgoError::Config(format!(
            "increment_weight {} must be > 0",
            cfg.increment_weight
        )));
    }
    let mut data = TransitionsBuilder::with_prev_action(s_dim, a_dim);
    let mut out = Vec::with_capacity(cfg.episodes);
    for ep in 0..cfg.episodes {
        let mut obs = env.reset(Some(seed + ep as u64));
        let mut prev = vec![0.0; a_dim];
        let mut c = vec![0.0; a_dim];
        let (mut ret, mut res_sum, mut steps) = (0.0, 0.0, 0usize);
        loop {
            let mut s = env.state();
            task.canonicalize(&mut s);
            let a_d = agent.act(&obs, tandem_agents::Mode::Deterministic)?;
            let a_d = a_d.as_continuous().unwrap_or(&[]).to_vec();
            if residual {
                let sd = desired(&s);
                let e: Vec<f64> = s.iter().zip(&sd).map(|(x, d)| x - d).collect();
                let z = ndarray::Array2::from_shape_fn((1, s_dim + a_dim), |(_, j)| {
                    if j < s_dim {
                        s[j]
                    } else {
                        prev[j - s_dim]
                    }
                });
                let l = model.gain(z.view())?.remove(0);
                if let Some(k) = residual_gain(&l, &q, cfg.increment_weight, cfg.horizon) {
                    let de = k * nalgebra::DVector::from_column_slice(&e);
                    for j in 0..a_dim {
                        // The residual never needs more than the action range.
                        let span = high[j] - low[j];
                        c[j] = (c[j] - de[j]).clamp(-span, span);
                    }
                }
            }
            let a: Vec<f64> = (0..a_dim)
                .map(|j| (a_d[j] + c[j]).clamp(low[j], high[j]))
                .collect();
            res_sum += c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let step = env.step(&Action::Continuous(a.clone()))?;
            let mut s1 = env.state();
            task.canonicalize(&mut s1);
            data.push(&s, &a, &s1, step.reward, step.terminated)?;
            ret += step.reward;
            steps += 1;
            prev = a;
            obs = step.observation;
            if step.terminated || step.truncated {
                data.end_episode();
                break;
            }
        }
        out.push(FineTuneEpisode {
            episode_return: ret,
            mean_residual: res_sum / steps.max(1) as f64,
        });
        if residual && cfg.refit {
            let all = data.clone().build();
            model.fit(
                &all,
                &FitConfig {
                    seed: cfg.fit.seed + ep as u64,
                    ..cfg.fit.clone()
                },
            )?;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// On the scalar integrator `e' = e + u` with `q = r = 1`, one step gives `K = 1/2`; the
    /// infinite horizon solves `p²/(1 + p) = 1`, `p` the golden ratio, and `K = p/(1 + p)`.
    #[test]
    fn residual_gain_matches_the_scalar_riccati_solution() {
        let l = DMatrix::from_element(1, 1, 1.0);
        let one = residual_gain(&l, &[1.0], 1.0, 1).unwrap();
        assert!((one[(0, 0)] - 0.5).abs() < 1e-12);
        let p = (1.0 + 5f64.sqrt()) / 2.0;
        let many = residual_gain(&l, &[1.0], 1.0, 200).unwrap();
        assert!(
            (many[(0, 0)] - p / (1.0 + p)).abs() < 1e-12,
            "{}",
            many[(0, 0)]
        );
        // A state component without weight gets no feedback; a 2 x 1 `L` with weights (4, 0)
        // in one step: K = (r + 4 l1²)⁻¹ [4 l1, 0].
        let l = DMatrix::from_column_slice(2, 1, &[0.5, 3.0]);
        let k = residual_gain(&l, &[4.0, 0.0], 0.1, 1).unwrap();
        assert!((k[(0, 0)] - 2.0 / 1.1).abs() < 1e-12 && k[(0, 1)] == 0.0);
    }
}
