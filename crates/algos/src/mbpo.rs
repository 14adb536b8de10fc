//! MBPO (Janner et al. 2019, "When to trust your model", Algorithm 2) as a reusable pipeline
//! over any real system (an [`Env`]) and the [`Task`] that describes it to a model, with SAC.
//!
//! Every real step, one line each:
//!
//! 1. act in the real system with SAC's exploring policy (uniformly random actions for the first
//!    [`SacConfig::learning_starts`] steps), transition into `D_env` (the [`OffPolicyLoop`]'s
//!    primary buffer) and, in the task's canonical state coordinates, into the model's data;
//! 2. every [`MbpoConfig::model_train_freq`] real steps: fit the [`ProbabilisticEnsemble`] (7
//!    Gaussian members, the 5 with the lowest held-out error predict) on all real data, then
//!    start `rollouts_per_step × model_train_freq` branched rollouts of length `k` (the
//!    [`MbpoConfig::rollout_length`] schedule of the epoch) at real states drawn uniformly,
//!    acted by SAC, each step through a random elite; their transitions go into `D_model` (the
//!    loop's secondary buffer, sized `rollouts_per_step × epoch_length × k × retain_epochs` and
//!    reallocated, newest kept, when `k` changes);
//! 3. `G` ([`MbpoConfig::updates_per_step`]) SAC updates on minibatches of
//!    [`MbpoConfig::real_ratio`] real and the rest model transitions.
//!
//! The rollouts in step 2 are MBPO's own implementation's batching: the paper's box draws `M`
//! rollouts every step, the authors' code draws `M × 250` every 250 steps, right after the model
//! is trained; the count is the same.
//!
//! The same loop without a model ([`run_sac`]) is the model-free baseline at equal real steps and
//! equal updates per step, and M-DeMoRL ([`super::m_demorl`]) fills the secondary buffer with
//! DMD-MPC plans instead of rollouts: both share [`run_with`], which counts real samples exactly (a
//! [`SampleCounter`] around the real system), evaluates the deterministic policy with
//! [`evaluate`] on a separate, uncounted copy every [`MbpoConfig::eval_every`] real steps, and
//! saves itself in a [`Checkpoints`] store every [`MbpoConfig::checkpoint_every`] real steps so a
//! stopped run resumes to exactly the numbers of an uninterrupted one.
//!
//! `examples/mbpo.rs` runs it on Pendulum-v1 ([`MbpoConfig::pendulum`]).

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use tandem_agents::{
    evaluate, BatchPolicy, EpisodeRunner, OffPolicyAgent, OffPolicyLoop, Resumable, Sac, SacConfig,
    StepOptions,
};
use tandem_core::{CurvePoint, LinearSchedule, Rng, SeedStream, Space};
use tandem_dynamics::classic::GymPendulumParams;
use tandem_envs::{Env, EnvError, PendulumTask, SampleCount, SampleCounter, Task};
use tandem_models::{
    DynamicsModel, EnsembleConfig, FitConfig, Judge, Judges, ProbabilisticEnsemble, Propagation,
    Transitions, TransitionsBuilder,
};
use tandem_nn::budget::MemoryEstimate;
use tandem_nn::{Checkpoint, Checkpointable};
use tandem_robots::{Leg2REnv, Leg2REnvExt, Leg2RModel, Leg2RTask};

use super::driver::{drive, timed, Algorithm};
use super::dyna::{imagine, sample_starts};
use super::{AlgoError, Checkpoints, MakeEnv, Problem, Result};

/// The gymnasium MuJoCo tasks [`MbpoConfig::mujoco`] has settings for.
pub const MUJOCO_TASKS: [&str; 4] = [
    "HalfCheetah-v5",
    "Hopper-v5",
    "Walker2d-v5",
    "InvertedPendulum-v5",
];

/// SAC updates per real step `G` in [`MbpoConfig::mujoco`] (MBPO: 20, 40 on HalfCheetah). Ours:
/// SAC's 256×256 update (about 0.67 GFLOP) takes about 12.5 ms on one core of a 2-core machine
/// and about 6.7 ms with its passes split over both, so at 4 one seed of SAC over 100 epochs
/// (95 000 × 4 updates) takes about 45 minutes, MBPO and M-DeMoRL about an hour.
pub const MUJOCO_UPDATES_PER_STEP: usize = 4;

/// Settings of an MBPO run (and of the loop M-DeMoRL and the SAC baseline share). `Default` is
/// MBPO's (Janner et al. 2019, Appendix C, and the authors' configuration files), cited per
/// field; where a figure is ours it says so.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MbpoConfig {
    /// The agent: SAC with two hidden layers of 256, Adam 3e-4, batch 256, τ = 0.005, γ = 0.99,
    /// automatic entropy tuning, replay 10⁶ (MBPO's SAC, the softlearning defaults), and 5000
    /// uniformly random steps before learning (MBPO's `n_initial_exploration_steps`). Its
    /// `train_freq`/`gradient_steps` are unused: the pipeline takes `updates_per_step`.
    pub sac: SacConfig,
    /// The model: 7 members, 5 elites, 4 hidden layers of 200 swish units, Adam 1e-3, learned
    /// log-variance bounds, reward learned (MBPO Appendix C; [`EnsembleConfig`]'s default).
    pub ensemble: EnsembleConfig,
    /// Each refit of the model on all real data: minibatch 256, 20% held out (the elites are
    /// chosen on it; MBPO's `holdout_ratio` 0.2), `epochs` passes continuing from the previous
    /// weights. MBPO trains each refit until the held-out loss stops improving (5 epochs
    /// without a 1% gain); ours: a fixed count, 5, and see `model_min_updates`.
    pub model_fit: FitConfig,
    /// At least this many minibatches per member per refit (ours: 200): on little data an
    /// epoch is a few steps, where MBPO's early stopping would train on.
    pub model_min_updates: usize,
    /// At most this many minibatches per member per refit, in whole epochs and at least one
    /// (`None`: no cap, as MBPO). Ours, for runs where refitting on all data every time would
    /// dominate the cost: the weights carry over from refit to refit.
    #[serde(default)]
    pub model_max_updates: Option<usize>,
    /// Real steps per epoch (MBPO: 1000); schedules count epochs.
    pub epoch_length: u64,
    /// Real steps of the run (the budget; MBPO's HalfCheetah: 400 epochs).
    pub real_steps: u64,
    /// Refit the model and refill `D_model` every this many real steps (MBPO: 250).
    pub model_train_freq: u64,
    /// Model rollouts per real step `M` (MBPO: 400, its `rollout_batch_size` 10⁵ every 250
    /// steps).
    pub rollouts_per_step: usize,
    /// Rollout length `k` by epoch (MBPO's Hopper: 1 → 15 over epochs 20–100; HalfCheetah and
    /// Walker2d keep 1).
    pub rollout_length: LinearSchedule,
    /// Epochs of model rollouts `D_model` holds (MBPO's configurations: 1).
    pub retain_epochs: usize,
    /// Fraction of every SAC minibatch from real data (MBPO: 0.05).
    pub real_ratio: f64,
    /// SAC updates per real step `G` (MBPO: 20; 40 on HalfCheetah).
    pub updates_per_step: usize,
    /// Who scores imagined transitions: MBPO's model learns the reward ([`Judge::Model`]);
    /// termination always comes from the task (MBPO's hand-written termination functions).
    pub reward: Judge,
    /// Evaluate every this many real steps (MBPO: every epoch).
    pub eval_every: u64,
    /// Deterministic evaluation episodes, their mean reported (MBPO's configurations: 1 to 10;
    /// ours: 5).
    pub eval_episodes: usize,
    /// Save a checkpoint every this many real steps (ours: every epoch).
    pub checkpoint_every: u64,
}

impl Default for MbpoConfig {
    fn default() -> Self {
        Self {
            sac: SacConfig {
                learning_starts: 5000,
                ..SacConfig::default()
            },
            ensemble: EnsembleConfig::default(),
            model_fit: FitConfig {
                epochs: 5,
                batch_size: 256,
                holdout_fraction: 0.2,
                seed: 0,
                early_stop: None,
            },
            model_min_updates: 200,
            model_max_updates: None,
            epoch_length: 1000,
            real_steps: 400_000,
            model_train_freq: 250,
            rollouts_per_step: 400,
            rollout_length: LinearSchedule {
                from_epoch: 20,
                to_epoch: 100,
                start: 1,
                end: 15,
            },
            retain_epochs: 1,
            real_ratio: 0.05,
            updates_per_step: 20,
            reward: Judge::Model,
            eval_every: 1000,
            eval_episodes: 5,
            checkpoint_every: 1000,
        }
    }
}

impl MbpoConfig {
    /// A small preset for Pendulum-v1 (ours; MBPO did not run it): 5 epochs of 1000 steps,
    /// SAC 64×64 with Adam 1e-3 and 250 random steps, an ensemble of 3-layer 64-unit members,
    /// 100 rollouts per step of length 1 → 3 over epochs 1–3, `G` = 10, 5 evaluation episodes.
    pub fn pendulum() -> Self {
        Self {
            sac: SacConfig {
                hidden: vec![64, 64],
                learning_rate: 1e-3,
                learning_starts: 250,
                ..SacConfig::default()
            },
            ensemble: EnsembleConfig {
                hidden: vec![64, 64, 64],
                ..EnsembleConfig::default()
            },
            real_steps: 5000,
            rollouts_per_step: 100,
            rollout_length: LinearSchedule {
                from_epoch: 1,
                to_epoch: 3,
                start: 1,
                end: 3,
            },
            updates_per_step: 10,
            ..Self::default()
        }
    }

    /// MBPO's settings for the gymnasium MuJoCo task `id` ([`MUJOCO_TASKS`]) sized to a 2-core
    /// machine; `None` for another task. MBPO's (Appendix C): SAC 256×256 after 5000 random
    /// steps, ensembles of 7 members of 4 × 200 SiLU units, 5 elites, real ratio 0.05, rollouts of
    /// the task's length schedule from real states (Hopper: 1 → 15 over epochs 20–100, the others
    /// 1). Ours: 100 epochs of 1000 real steps (InvertedPendulum: 15), 400 rollouts per real step
    /// (Hopper: 100, where long rollouts would cost hours), [`MUJOCO_UPDATES_PER_STEP`] updates
    /// per real step, and the model refit once an epoch (MBPO: every 250 steps) with at most 200
    /// minibatches per member, whole epochs and at least one, the weights carried over (MBPO:
    /// until the held-out loss stops improving).
    pub fn mujoco(id: &str) -> Option<Self> {
        let (epochs, rollout_length, rollouts_per_step) = match id {
            "HalfCheetah-v5" | "Walker2d-v5" => (100, LinearSchedule::constant(1), 400),
            "Hopper-v5" => (
                100,
                LinearSchedule {
                    from_epoch: 20,
                    to_epoch: 100,
                    start: 1,
                    end: 15,
                },
                100,
            ),
            "InvertedPendulum-v5" => (15, LinearSchedule::constant(1), 400),
            _ => return None,
        };
        let mut c = Self::default();
        c.real_steps = epochs * c.epoch_length;
        c.updates_per_step = MUJOCO_UPDATES_PER_STEP;
        c.rollout_length = rollout_length;
        c.rollouts_per_step = rollouts_per_step;
        c.model_train_freq = c.epoch_length;
        c.model_max_updates = Some(200);
        Some(c)
    }

    /// This loop at toy sizes, for smoke runs and tests: 3 epochs of `epoch_length` real steps
    /// (the first 100 random), SAC 16×16 with minibatches of 32, an ensemble of 3 (2 elites)
    /// 16×16 members fitted for 2 epochs and at least 4 minibatches, a refit and a checkpoint
    /// every half epoch, 2 rollouts and one update per real step, one evaluation episode an
    /// epoch.
    pub fn toy(mut self, epoch_length: u64) -> Self {
        self.sac.hidden = vec![16, 16];
        self.sac.batch_size = 32;
        self.sac.learning_starts = 100;
        self.ensemble.members = 3;
        self.ensemble.elites = 2;
        self.ensemble.hidden = vec![16, 16];
        self.model_fit.epochs = 2;
        self.model_min_updates = 4;
        self.epoch_length = epoch_length;
        self.real_steps = 3 * epoch_length;
        self.model_train_freq = epoch_length / 2;
        self.rollouts_per_step = 2;
        self.updates_per_step = 1;
        self.eval_every = epoch_length;
        self.eval_episodes = 1;
        self.checkpoint_every = epoch_length / 2;
        self
    }

    /// Checks the ranges the loop relies on.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(AlgoError::Config(m.to_string()));
        let counts = [
            self.epoch_length,
            self.real_steps,
            self.model_train_freq,
            self.eval_every,
            self.checkpoint_every,
        ];
        if counts.contains(&0) {
            return bad("epoch_length, real_steps, model_train_freq, eval_every and checkpoint_every must be >= 1");
        }
        if self.rollouts_per_step == 0 || self.retain_epochs == 0 || self.updates_per_step == 0 {
            return bad("rollouts_per_step, retain_epochs and updates_per_step must be >= 1");
        }
        if self.model_max_updates == Some(0) {
            return bad("model_max_updates must be >= 1");
        }
        if !(0.0..=1.0).contains(&self.real_ratio) {
            return bad("real_ratio must lie in [0, 1]");
        }
        if self.eval_episodes == 0 || self.model_fit.epochs == 0 || self.model_fit.batch_size == 0 {
            return bad("eval_episodes, model_fit.epochs and model_fit.batch_size must be >= 1");
        }
        if !(0.0..1.0).contains(&self.model_fit.holdout_fraction) {
            return bad("model_fit.holdout_fraction must lie in [0, 1)");
        }
        if self.reward == Judge::Model && !self.ensemble.learn_reward {
            return bad("reward = model needs ensemble.learn_reward");
        }
        self.rollout_length
            .validate("rollout_length")
            .map_err(AlgoError::Config)?;
        self.ensemble.validate()?;
        self.model_fit.validate()?;
        if self.max_rollout_capacity().is_none() {
            return bad(
                "the rollout buffer rollouts_per_step x epoch_length x rollout_length x \
                 retain_epochs overflows",
            );
        }
        self.sac.validate()?;
        Ok(())
    }

    /// The largest the rollout buffer gets: [`Self::rollout_capacity`] at the longest `k`.
    pub fn max_rollout_capacity(&self) -> Option<usize> {
        self.rollout_capacity(self.rollout_length.max())
    }

    /// The rollout buffer for rollouts of length `k`: `rollouts_per_step × epoch_length × k ×
    /// retain_epochs`; `None` on overflow.
    pub fn rollout_capacity(&self, k: usize) -> Option<usize> {
        self.rollouts_per_step
            .checked_mul(usize::try_from(self.epoch_length).ok()?)?
            .checked_mul(k)?
            .checked_mul(self.retain_epochs)
    }

    /// The memory of one run on `obs_dim`-dimensional states and `act_dim`-dimensional actions:
    /// the ensemble with its optimizer state, SAC with its replay buffer, and the largest
    /// secondary buffer (`secondary` transitions: [`Self::max_rollout_capacity`] for MBPO).
    pub fn memory(
        &self,
        obs_dim: usize,
        act_dim: usize,
        secondary: Option<usize>,
    ) -> MemoryEstimate {
        MemoryEstimate::new()
            .with(
                "",
                self.ensemble
                    .memory(obs_dim, act_dim, self.model_fit.batch_size),
            )
            .with("sac.", self.sac.memory(obs_dim, act_dim))
            .part(
                "secondary buffer (model transitions)",
                secondary
                    .and_then(|n| tandem_agents::replay::ReplayBuffer::bytes(n, obs_dim, act_dim)),
            )
    }

    /// The epoch (from 0) that real step `t` (from 1) belongs to.
    pub fn epoch_of(&self, t: u64) -> u64 {
        (t.max(1) - 1) / self.epoch_length
    }

    /// The model fit at a refit on `n` transitions: `model_fit` with enough epochs for
    /// `model_min_updates` minibatches per member, no more than `model_max_updates` allows,
    /// and the seed `seed`.
    pub fn fit_for(&self, n: usize, seed: u64) -> FitConfig {
        let train = ((n as f64) * (1.0 - self.model_fit.holdout_fraction)).ceil() as usize;
        let per_epoch = train.div_ceil(self.model_fit.batch_size).max(1);
        let epochs = self
            .model_fit
            .epochs
            .max(self.model_min_updates.div_ceil(per_epoch));
        let cap = self
            .model_max_updates
            .map_or(usize::MAX, |m| (m / per_epoch).max(1));
        FitConfig {
            epochs: epochs.min(cap),
            seed,
            ..self.model_fit.clone()
        }
    }
}

/// Pendulum-v1 with its own rules as the task.
pub fn pendulum_problem() -> Problem<PendulumTask, MakeEnv> {
    Problem {
        task: PendulumTask::new(&GymPendulumParams::default()),
        env: Box::new(|| tandem_envs::make("Pendulum-v1")),
    }
}

/// p3's 2R leg (`Leg2R-v0`, the idealized leg) with its task (reward (15); 1000-step episodes).
/// Its actions are torques as fractions of the motors' limits, so a planner plans in fractions
/// and the model sees newton metres.
pub fn leg2r_problem() -> Problem<Leg2RTask, MakeEnv> {
    Problem {
        task: Leg2REnv::new(Leg2RModel::Idealized).task().clone(),
        env: Box::new(|| tandem_robots::make(Leg2REnv::ID)),
    }
}

/// The 2R leg built from `config` (e.g. the true leg, or the reward in other units), reported as
/// `id`, with its [`tandem_envs::TimeLimit`] of `config.max_episode_steps`; an error when the
/// configuration is invalid.
pub fn leg2r_problem_with(
    id: &str,
    config: &tandem_robots::Leg2RConfig,
) -> Result<Problem<Leg2RTask, MakeEnv>> {
    let env = Leg2REnv::with_config(id, config.clone())?;
    let task = env.task().clone();
    let (id, config) = (id.to_string(), config.clone());
    Ok(Problem {
        task,
        env: Box::new(move || {
            let env = Leg2REnv::with_config(&id, config.clone())?;
            let limited = tandem_envs::TimeLimit::new(env, config.max_episode_steps);
            Ok(Box::new(limited) as Box<dyn Env>)
        }),
    })
}

/// A gymnasium MuJoCo task (`HalfCheetah-v5`, `Hopper-v5`, `Walker2d-v5`,
/// `InvertedPendulum-v5`) with [`tandem_mujoco::GymTask`] as its task, its model's `qpos0` read
/// from the MJCF. Needs the feature `mujoco`; without it, an error saying so.
pub fn mujoco_problem(id: &str) -> Result<Problem<tandem_mujoco::GymTask, MakeEnv>> {
    #[cfg(feature = "mujoco")]
    {
        let task = tandem_mujoco::gym_task(id)?;
        let id = id.to_string();
        Ok(Problem {
            task,
            env: Box::new(move || tandem_mujoco::make(&id)),
        })
    }
    #[cfg(not(feature = "mujoco"))]
    {
        Err(AlgoError::Config(format!(
            "{id} needs a build with `--features mujoco` after scripts/setup-mujoco.sh"
        )))
    }
}

/// What a run reports as it goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A real step was taken; `real_steps` so far.
    Step {
        /// Real steps so far.
        real_steps: u64,
    },
    /// The model was refit and the secondary buffer refilled.
    Fit {
        /// Real steps so far.
        real_steps: u64,
        /// The fit's last held-out loss (mean Gaussian NLL per element; NaN where the loop fits
        /// no model, [`OracleRollouts`]).
        holdout_loss: f64,
        /// Imagined transitions stored.
        imagined: u64,
    },
    /// The deterministic policy was evaluated.
    Eval(CurvePoint),
}

/// What one run reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The method's name: `"sac"`, or its [`Imagination::name`] (`"mbpo"`, `"mbpo_oracle"`,
    /// `"m_demorl"`, `"incremental_dyna"`).
    pub method: String,
    /// The seed.
    pub seed: u64,
    /// Mean evaluation return after `true_samples` real steps, at 0 and every `eval_every`.
    pub curve: Vec<CurvePoint>,
    /// Real steps taken, counted by the [`SampleCounter`] around the real system.
    pub real_steps: u64,
    /// Imagined transitions stored in the secondary buffer (model rollouts or MPC plans).
    pub imagined: u64,
    /// The schedule's value at each refit (MBPO's `k`, M-DeMoRL's `H`), one per refit.
    pub horizons: Vec<usize>,
    /// Last held-out loss of each refit (none where the loop fits no model).
    pub fit_holdout_loss: Vec<f64>,
    /// SAC updates.
    pub updates: u64,
    /// Seconds spent in SAC updates (their rate: `updates / update_seconds`).
    pub update_seconds: f64,
    /// Seconds spent fitting the model (0 for SAC alone).
    #[serde(default)]
    pub fit_seconds: f64,
    /// Seconds spent filling the secondary buffer: model rollouts or MPC plans.
    #[serde(default)]
    pub imagine_seconds: f64,
    /// Wall time, seconds (over all the processes that ran it, if resumed).
    pub wall_seconds: f64,
}

impl RunRecord {
    /// The return at the last evaluation with at most `budget` real steps.
    pub fn return_at(&self, budget: u64) -> Option<f64> {
        let last = self.curve.iter().take_while(|p| p.true_samples <= budget);
        last.last().map(|p| p.eval_return)
    }

    /// Real steps at the first evaluation whose return reached `target`.
    pub fn steps_to(&self, target: f64) -> Option<u64> {
        let mut hit = self.curve.iter().filter(|p| p.eval_return >= target);
        hit.next().map(|p| p.true_samples)
    }
}

/// What fills the loop's secondary buffer after each refit (MBPO's rollouts, M-DeMoRL's plans,
/// p1's one-step incremental predictions): its name, sizes and the model the loop fits for it.
/// [`Imagine`] does the filling.
pub trait Imagination {
    /// The model the loop fits on all real data before each filling and saves with every
    /// checkpoint: MBPO's and M-DeMoRL's [`ProbabilisticEnsemble`], p1's
    /// [`tandem_models::IncrementalModel`]; [`NoModel`] where the imagination steps a model it
    /// was given ([`OracleRollouts`]).
    type Model: DynamicsModel + Checkpointable;
    /// The method's name in records and checkpoints.
    fn name(&self) -> &'static str;
    /// The secondary buffer's capacity during `epoch`.
    fn capacity(&self, cfg: &MbpoConfig, epoch: u64) -> usize;
    /// The schedule's value (`k` or `H`) at `epoch`.
    fn horizon(&self, epoch: u64) -> usize;
    /// A fresh model for `state_dim` canonical states and `control_dim` controls under `cfg`,
    /// initialized from `seed`; `None` when nothing is fitted (a given model).
    fn new_model(
        &self,
        cfg: &MbpoConfig,
        state_dim: usize,
        control_dim: usize,
        seed: u64,
    ) -> Result<Option<Self::Model>>;
    /// An empty record of real transitions as the model learns from them: the task's canonical
    /// states (the default), or those and the previous control (p1's incremental model).
    fn new_data(&self, state_dim: usize, control_dim: usize) -> TransitionsBuilder {
        TransitionsBuilder::new(state_dim, control_dim)
    }
}

/// The model of an imagination that fits none ([`OracleRollouts`]): a type without values, so
/// the loop's model is always `None` for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoModel {}

impl DynamicsModel for NoModel {
    fn state_dim(&self) -> usize {
        match *self {}
    }

    fn action_dim(&self) -> usize {
        match *self {}
    }

    fn predict(
        &self,
        _input: &tandem_models::ModelInput<'_>,
        _rng: &mut Rng,
    ) -> std::result::Result<tandem_models::Prediction, tandem_models::ModelError> {
        match *self {}
    }

    fn fit(
        &mut self,
        _data: &Transitions,
        _cfg: &FitConfig,
    ) -> std::result::Result<tandem_models::FitReport, tandem_models::ModelError> {
        match *self {}
    }
}

impl Checkpointable for NoModel {
    fn save_to(&self, _prefix: &str, _ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        match *self {}
    }

    fn load_from(&mut self, _prefix: &str, _ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        match *self {}
    }
}

/// MBPO's probabilistic ensemble ([`MbpoConfig::ensemble`]) seeded with `seed`.
pub(crate) fn ensemble_of(
    cfg: &MbpoConfig,
    state_dim: usize,
    control_dim: usize,
    seed: u64,
) -> Result<Option<ProbabilisticEnsemble>> {
    let ens = EnsembleConfig {
        seed,
        ..cfg.ensemble.clone()
    };
    Ok(Some(ProbabilisticEnsemble::new(
        state_dim,
        control_dim,
        ens,
    )?))
}

/// The model an imagination was handed, or an error naming the method.
pub(crate) fn fitted<'a, M>(model: Option<&'a mut M>, method: &str) -> Result<&'a mut M> {
    model.ok_or_else(|| AlgoError::Config(format!("{method}: the loop passed no fitted model")))
}

/// Fills the loop's secondary buffer for a task `T` and an agent `A`.
pub trait Imagine<T: Task, A>: Imagination {
    /// Fills the secondary buffer after a refit during `epoch`; returns how many transitions
    /// it stored. `model` is the one [`Imagination::new_model`] made, just refitted; `data` are
    /// all real transitions (canonical states); `seed` is this refit's.
    #[allow(clippy::too_many_arguments)]
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<A>,
        model: Option<&mut Self::Model>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        seed: u64,
        rng: &mut Rng,
    ) -> Result<usize>;
}

/// MBPO's branched rollouts ([`super::dyna::imagine`]).
#[derive(Debug, Clone)]
pub struct Rollouts {
    /// `M`, per real step.
    pub rollouts_per_step: usize,
    /// Real steps between refits.
    pub per_refit: u64,
    /// `k` by epoch.
    pub length: LinearSchedule,
    /// Epochs kept.
    pub retain_epochs: usize,
    /// Reward and termination of imagined steps.
    pub judges: Judges,
}

impl Rollouts {
    /// MBPO's rollouts as `cfg` sets them.
    pub fn of(cfg: &MbpoConfig) -> Self {
        Self {
            rollouts_per_step: cfg.rollouts_per_step,
            per_refit: cfg.model_train_freq,
            length: cfg.rollout_length,
            retain_epochs: cfg.retain_epochs,
            judges: Judges {
                reward: cfg.reward,
                ..Judges::default()
            },
        }
    }
}

impl Imagination for Rollouts {
    type Model = ProbabilisticEnsemble;

    fn name(&self) -> &'static str {
        "mbpo"
    }

    fn new_model(
        &self,
        cfg: &MbpoConfig,
        state_dim: usize,
        control_dim: usize,
        seed: u64,
    ) -> Result<Option<ProbabilisticEnsemble>> {
        ensemble_of(cfg, state_dim, control_dim, seed)
    }

    fn capacity(&self, cfg: &MbpoConfig, epoch: u64) -> usize {
        // Checked by `MbpoConfig::validate` at the longest length.
        self.rollouts_per_step
            * cfg.epoch_length as usize
            * self.length.at(epoch)
            * self.retain_epochs
    }

    fn horizon(&self, epoch: u64) -> usize {
        self.length.at(epoch)
    }
}

impl<T: Task, A: OffPolicyAgent + BatchPolicy> Imagine<T, A> for Rollouts {
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<A>,
        model: Option<&mut ProbabilisticEnsemble>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        _seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let model = fitted(model, "mbpo")?;
        model.set_propagation(Propagation::RandomMember);
        self.through(&*model, &self.judges, lp, task, data, epoch, rng)
    }
}

impl Rollouts {
    /// `M × per_refit` rollouts of the epoch's length `k` through `model` from real states drawn
    /// uniformly from `data`, acted by SAC, stored in the loop's secondary buffer.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn through<T: Task, M: DynamicsModel + ?Sized, A: OffPolicyAgent + BatchPolicy>(
        &self,
        model: &M,
        judges: &Judges,
        lp: &mut OffPolicyLoop<A>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let n = self.rollouts_per_step * self.per_refit as usize;
        let starts = sample_starts(data, n, rng)?;
        imagine(
            lp,
            model,
            task,
            judges,
            starts.view(),
            self.length.at(epoch),
            rng,
        )
    }
}

/// MBPO's branched rollouts through a model the loop does not fit, with the task's reward and
/// termination: given the true system as a [`tandem_models::PlantModel`], MBPO with oracle
/// dynamics. Every imagined transition is then one the real system would produce, so what such
/// a run still lacks against SAC alone is due to the loop (its data mix, its rollout starts),
/// not to model error. Recorded and checkpointed as `"mbpo_oracle"`.
#[derive(Debug, Clone)]
pub struct OracleRollouts<M> {
    /// The rollouts' sizes and schedule (their `judges` are replaced by the task's).
    pub rollouts: Rollouts,
    /// The model the rollouts step.
    pub model: M,
}

impl<M> OracleRollouts<M> {
    /// MBPO's rollouts as `cfg` sets them, through `model`.
    pub fn of(cfg: &MbpoConfig, model: M) -> Self {
        Self {
            rollouts: Rollouts::of(cfg),
            model,
        }
    }
}

impl<M> Imagination for OracleRollouts<M> {
    type Model = NoModel;

    fn name(&self) -> &'static str {
        "mbpo_oracle"
    }

    fn new_model(&self, _: &MbpoConfig, _: usize, _: usize, _: u64) -> Result<Option<NoModel>> {
        Ok(None)
    }

    fn capacity(&self, cfg: &MbpoConfig, epoch: u64) -> usize {
        self.rollouts.capacity(cfg, epoch)
    }

    fn horizon(&self, epoch: u64) -> usize {
        self.rollouts.horizon(epoch)
    }
}

impl<T: Task, A: OffPolicyAgent + BatchPolicy, M: DynamicsModel> Imagine<T, A>
    for OracleRollouts<M>
{
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<A>,
        _model: Option<&mut NoModel>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        _seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let task_judges = Judges::default();
        self.rollouts
            .through(&self.model, &task_judges, lp, task, data, epoch, rng)
    }
}

/// MBPO with `model` in place of the fitted ensemble ([`OracleRollouts`]), checkpointed under
/// `"mbpo_oracle"`.
pub fn run_oracle<T: Task, F, M: DynamicsModel>(
    problem: &Problem<T, F>,
    cfg: &MbpoConfig,
    model: M,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    let mut rollouts = OracleRollouts::of(cfg, model);
    run_with(problem, cfg, seed, Some(&mut rollouts), store, on_event)
}

/// Runs MBPO for `seed` on `problem` (from the checkpoint `store` holds under `"mbpo"`, if any).
pub fn run<T: Task, F>(
    problem: &Problem<T, F>,
    cfg: &MbpoConfig,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    let mut rollouts = Rollouts::of(cfg);
    run_with(problem, cfg, seed, Some(&mut rollouts), store, on_event)
}

/// The model-free baseline: the same loop, SAC alone on real data (`G` updates per real step,
/// the same evaluations), checkpointed under `"sac"`.
pub fn run_sac<T: Task, F>(
    problem: &Problem<T, F>,
    cfg: &MbpoConfig,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    run_with::<T, F, Rollouts>(problem, cfg, seed, None, store, on_event)
}

/// [`Mbpo`] with SAC as `cfg.sac` sets it, driven to its end by [`drive`]: the loop every method
/// of this module, [`super::m_demorl`] and [`super::incremental_dyna`] runs.
pub fn run_with<T: Task, F, I: Imagine<T, Sac>>(
    problem: &Problem<T, F>,
    cfg: &MbpoConfig,
    seed: u64,
    imagination: Option<&mut I>,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    let algo = Mbpo::new(problem, cfg, imagination, seed, |obs, act| {
        let seeds = SeedStream::new(seed);
        Ok(Sac::new(cfg.sac.clone(), obs, act, seeds.derive("agent"))?)
    })?;
    drive(algo, store, on_event)
}

/// One run of MBPO's loop (Janner et al., Algorithm 2) as one checkpointable value, stepped one
/// real step at a time by [`drive`]: the agent and its two replay buffers (`D_env`, and `D_model`
/// where an imagination fills it), the model, the real transitions in the task's canonical
/// states, the generators, the counters and the episode in progress. With no imagination it is
/// the model-free baseline on the same loop.
pub struct Mbpo<'a, T, F, A, I: Imagination> {
    problem: &'a Problem<T, F>,
    cfg: &'a MbpoConfig,
    imagination: Option<&'a mut I>,
    seeds: SeedStream,
    seed: u64,
    lp: OffPolicyLoop<A>,
    model: Option<I::Model>,
    env: SampleCounter<Box<dyn Env>>,
    count: SampleCount,
    eval_env: Box<dyn Env>,
    /// `D_env` in the task's canonical states, for the model: `stored` up to the last refit or
    /// checkpoint, `pending` since.
    stored: Transitions,
    pending: TransitionsBuilder,
    s: State,
}

/// Where a run stands, besides the agent, its loop, the model and the real transitions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct State {
    real_steps: u64,
    curve: Vec<CurvePoint>,
    horizons: Vec<usize>,
    fit_losses: Vec<f64>,
    imagined: u64,
    refits: u64,
    capacity: usize,
    runner: EpisodeRunner,
    env_state: Option<Vec<f64>>,
    rng: Rng,
    seconds: Seconds,
}

/// Seconds a run spent in its parts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
struct Seconds {
    updates: f64,
    fit: f64,
    imagine: f64,
}

const STATE: &str = "mbpo.state";
const LOOP: &str = "mbpo.loop";
const MODEL: &str = "mbpo.model";
const DATA: &str = "mbpo.data";

impl<'a, T, F, A, I> Mbpo<'a, T, F, A, I>
where
    T: Task,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
    A: OffPolicyAgent + BatchPolicy + Resumable,
    I: Imagine<T, A>,
{
    /// A fresh run for `seed` on `problem` with the agent `agent(observation space, action
    /// space)` and `imagination` filling `D_model` (none: the agent alone on real data).
    pub fn new(
        problem: &'a Problem<T, F>,
        cfg: &'a MbpoConfig,
        imagination: Option<&'a mut I>,
        seed: u64,
        agent: impl FnOnce(&Space, &Space) -> Result<A>,
    ) -> Result<Self> {
        cfg.validate()?;
        let task = &problem.task;
        let seeds = SeedStream::new(seed);
        let eval_env = (problem.env)()?;
        let (obs_space, act_space) = (task.observation_space(), task.action_space());
        for (what, task_space, env_space) in [
            ("observation", obs_space, eval_env.observation_space()),
            ("action", act_space, eval_env.action_space()),
        ] {
            if task_space.flat_dim() != env_space.flat_dim() {
                return Err(AlgoError::Config(format!(
                    "the task's {what} space has {} components, the real system's {}",
                    task_space.flat_dim(),
                    env_space.flat_dim()
                )));
            }
        }
        let agent = agent(obs_space, act_space)?;
        let mut lp = OffPolicyLoop::new(
            agent,
            cfg.sac.schedule(),
            obs_space,
            act_space,
            seeds.rng("minibatches"),
        )?;
        let capacity = imagination.as_ref().map_or(0, |i| i.capacity(cfg, 0));
        if imagination.is_some() {
            lp = lp.with_secondary(capacity, cfg.real_ratio)?;
        }
        let (s_dim, u_dim) = (task.state_dim(), tandem_envs::control_dim(task));
        let model = match imagination.as_deref() {
            Some(i) => i.new_model(cfg, s_dim, u_dim, seeds.derive("model"))?,
            None => None,
        };
        let pending = imagination.as_deref().map_or_else(
            || TransitionsBuilder::new(s_dim, u_dim),
            |i| i.new_data(s_dim, u_dim),
        );
        let (env, count) = SampleCounter::new((problem.env)()?);
        Ok(Self {
            problem,
            cfg,
            imagination,
            seeds,
            seed,
            lp,
            model,
            env,
            count,
            eval_env,
            stored: Transitions::default(),
            pending,
            s: State {
                real_steps: 0,
                curve: Vec::new(),
                horizons: Vec::new(),
                fit_losses: Vec::new(),
                imagined: 0,
                refits: 0,
                capacity,
                runner: EpisodeRunner::new(seeds.derive("episodes"), "episode-"),
                env_state: None,
                rng: seeds.rng("imagination"),
                seconds: Seconds::default(),
            },
        })
    }

    /// The deterministic policy's mean return over `eval_episodes` on the evaluation copy.
    fn evaluate(&mut self) -> Result<f64> {
        let r = evaluate(
            &mut self.lp.agent,
            self.eval_env.as_mut(),
            self.cfg.eval_episodes,
            &self.seeds,
            None,
        )?;
        Ok(r.iter().sum::<f64>() / r.len() as f64)
    }

    /// Moves the real transitions gathered since the last call into `stored`.
    fn flush(&mut self) -> Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let fresh = self.pending.empty_like();
        let new = std::mem::replace(&mut self.pending, fresh).build();
        if self.stored.is_empty() {
            self.stored = new;
        } else {
            self.stored.extend(&new)?;
        }
        Ok(())
    }

    /// Trains the model on `D_env`, then lets the imagination fill `D_model` (MBPO: `M`
    /// branched rollouts per real step, `k` steps each, from real states).
    fn refit_and_imagine(&mut self, t: u64, on_event: &mut dyn FnMut(Event)) -> Result<()> {
        self.flush()?;
        let Some(imagination) = self.imagination.as_deref_mut() else {
            return Ok(());
        };
        let (cfg, s) = (self.cfg, &mut self.s);
        let epoch = cfg.epoch_of(t);
        let mut loss = None;
        if let Some(model) = self.model.as_mut() {
            let fit = cfg.fit_for(
                self.stored.len(),
                self.seeds.derive(&format!("fit-{}", s.refits)),
            );
            let report = timed(&mut s.seconds.fit, || model.fit(&self.stored, &fit))?;
            loss = Some(report.holdout_loss.last().copied().unwrap_or(f64::NAN));
        }
        let capacity = imagination.capacity(cfg, epoch);
        if capacity != s.capacity {
            self.lp.resize_secondary(capacity)?;
            s.capacity = capacity;
        }
        let seed = self.seeds.derive(&format!("imagine-{}", s.refits));
        let n = timed(&mut s.seconds.imagine, || {
            imagination.imagine(
                &mut self.lp,
                self.model.as_mut(),
                &self.problem.task,
                &self.stored,
                epoch,
                seed,
                &mut s.rng,
            )
        })?;
        s.refits += 1;
        s.imagined += n as u64;
        s.fit_losses.extend(loss);
        s.horizons.push(imagination.horizon(epoch));
        on_event(Event::Fit {
            real_steps: t,
            holdout_loss: loss.unwrap_or(f64::NAN),
            imagined: n as u64,
        });
        Ok(())
    }
}

impl<T, F, A, I> Algorithm for Mbpo<'_, T, F, A, I>
where
    T: Task,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
    A: OffPolicyAgent + BatchPolicy + Resumable,
    I: Imagine<T, A>,
{
    type Event = Event;
    type Record = RunRecord;
    const SUMS_WALL_TIME: bool = true;

    fn id(&self) -> (&str, u64) {
        let name = self.imagination.as_ref().map_or("sac", |i| i.name());
        (name, self.seed)
    }

    fn start(&mut self, _on_event: &mut dyn FnMut(Event)) -> Result<()> {
        let eval_return = self.evaluate()?;
        self.s.curve.push(CurvePoint {
            true_samples: 0,
            eval_return,
        });
        Ok(())
    }

    fn done(&self) -> bool {
        self.count.get() >= self.cfg.real_steps
    }

    fn step(&mut self, on_event: &mut dyn FnMut(Event), _stop: &dyn Checkpoints) -> Result<bool> {
        let (cfg, task) = (self.cfg, &self.problem.task);
        // Act in the real system with the exploring policy; the transition goes into D_env.
        let opts = StepOptions::real().recording_states().without_updates();
        let rec = self.lp.step(&mut self.env, &mut self.s.runner, opts)?;
        let t = self.count.get();
        on_event(Event::Step { real_steps: t });
        if self.imagination.is_some() {
            let (x, x1) = rec.states.as_ref().expect("recorded");
            let u = task.control(&rec.action);
            let done = rec.done();
            self.pending
                .push_canonical(task, x, &u, x1, rec.reward, rec.terminated, done)?;
            if t.is_multiple_of(cfg.model_train_freq) && t >= cfg.sac.learning_starts as u64 {
                self.refit_and_imagine(t, on_event)?;
            }
        }
        // G updates on minibatches mixing D_env and D_model.
        if self.lp.primary().len() > cfg.sac.learning_starts {
            let lp = &mut self.lp;
            timed(&mut self.s.seconds.updates, || {
                lp.update(cfg.updates_per_step)
            })?;
        }
        if t.is_multiple_of(cfg.eval_every) {
            let point = CurvePoint {
                true_samples: t,
                eval_return: self.evaluate()?,
            };
            self.s.curve.push(point);
            on_event(Event::Eval(point));
        }
        let checkpoint = t.is_multiple_of(cfg.checkpoint_every);
        if checkpoint {
            self.flush()?;
            self.s.real_steps = t;
            self.s.env_state = self.s.runner.in_episode().then(|| self.env.state());
        }
        Ok(checkpoint)
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        self.lp.agent.save(ckpt)?;
        self.lp.save(LOOP, ckpt)?;
        if let Some(m) = self.model.as_ref() {
            m.save_to(MODEL, ckpt)?;
        }
        self.stored.save_to(DATA, ckpt)?;
        ckpt.put_json(STATE, &self.s)?;
        Ok(())
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        self.s = ckpt.get_json(STATE)?;
        self.lp.agent.load(ckpt)?;
        if self.imagination.is_some() {
            self.lp.resize_secondary(self.s.capacity)?;
        }
        self.lp.load(LOOP, ckpt)?;
        if let Some(m) = self.model.as_mut() {
            m.load_from(MODEL, ckpt)?;
        }
        self.stored.load_from(DATA, ckpt)?;
        (self.env, self.count) =
            SampleCounter::starting_at((self.problem.env)()?, self.s.real_steps);
        if let Some(state) = &self.s.env_state {
            self.env.set_state(state)?;
        }
        Ok(())
    }

    fn finish(self, wall_seconds: f64) -> Result<RunRecord> {
        let (method, seed) = self.id();
        let method = method.to_string();
        Ok(RunRecord {
            method,
            seed,
            real_steps: self.count.get(),
            updates: self.lp.counts().updates,
            curve: self.s.curve,
            imagined: self.s.imagined,
            horizons: self.s.horizons,
            fit_holdout_loss: self.s.fit_losses,
            update_seconds: self.s.seconds.updates,
            fit_seconds: self.s.seconds.fit,
            imagine_seconds: self.s.seconds.imagine,
            wall_seconds,
        })
    }
}

/// Observations of the rows of `states` under `task` (`B x O`).
pub fn observations<T: Task + ?Sized>(
    task: &T,
    states: ndarray::ArrayView2<'_, f64>,
) -> Array2<f64> {
    let o = task.observation_space().flat_dim();
    let mut out = Array2::zeros((states.nrows(), o));
    for (i, s) in states.rows().into_iter().enumerate() {
        let obs = task.observe(&s.to_vec());
        out.row_mut(i).assign(&ndarray::ArrayView1::from(&obs[..]));
    }
    out
}
