//! Paper p1 (Cong Li): Dyna-SAC with the deep incremental model, Algorithm 1, against SAC and
//! MBPO on the same loop.
//!
//! p1's Algorithm 1 is MBPO's loop ([`super::mbpo`]) with its model replaced and its rollouts one
//! step long:
//!
//! - line 3: **train `f(θ)` on `D_env`**: here the [`IncrementalModel`] `ŝ_{t+1} = s_t +
//!   L_θ(s_t, a_{t−1}) (a_t − a_{t−1})` (eqs. 4–6), refit on all real transitions every
//!   [`MbpoConfig::model_train_freq`] real steps by loss (5) on the one-step-back data (the
//!   loop's data carry each transition's previous control, zero at an episode's start);
//! - line 5: act in the real system with SAC's exploring policy, the transition into `D_env`;
//! - lines 6–9: **`M` one-step model rollouts** from real states drawn uniformly from `D_env`,
//!   acted by SAC, each predicted from its real state and the real control before it; the
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
use tandem_agents::{OffPolicyLoop, Sac};
use tandem_core::Rng;
use tandem_envs::{Env, EnvError, Task};
use tandem_models::{IncrementalModel, IncrementalModelConfig, Judges, Transitions};

use super::mbpo::{
    fitted, run_with, Event, Imagination, Imagine, LinearSchedule, MbpoConfig, Problem, Rollouts,
    RunRecord,
};
use super::{Checkpoints, Result};

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
        self.base.validate()
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
}

impl<T: Task> Imagine<T> for IncrementalRollouts {
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<Sac>,
        model: Option<&mut IncrementalModel>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        _seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let model = fitted(model, Method::IncrementalDyna.name())?;
        let r = &self.rollouts;
        r.through(&*model, &r.judges, lp, task, data, epoch, rng)
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
