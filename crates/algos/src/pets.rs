//! PETS (Chua et al. 2018, "Deep reinforcement learning in a handful of trials using
//! probabilistic dynamics models"): model-predictive control by the cross-entropy method through
//! a probabilistic ensemble, with trajectory sampling, refitted on all data after each episode.
//!
//! The paper's box (Algorithm 1), as [`Pets`] runs it:
//!
//! 1. initialize the data `D` with [`PetsConfig::initial_episodes`] episodes of uniformly random
//!    actions;
//! 2. for each later episode: train the ensemble `f̃` on all of `D` (the observation change
//!    `o' − o` as a Gaussian of each member, [`tandem_models::ProbabilisticEnsemble`]); then at
//!    every step, sample action sequences with CEM ([`tandem_planners::Cem`]), propagate
//!    [`tandem_planners::CemConfig::particles`] particles of each through the ensemble
//!    (TS-∞: each particle keeps its member, [`Propagation::FixedMember`]; TS-1:
//!    [`Propagation::RandomMember`]), score each sequence by the mean over its particles of the
//!    task's cost ([`Objective::from_task_observations`]: the task's reward and termination read
//!    off observations, as mbrl-lib's `reward_fn` and `termination_fn`), execute the first action
//!    of the best sequence, and add the transition to `D`.
//!
//! Here the refit closes each episode (the box trains before each episode; the same thing), so
//! the random episodes' refit is the first episode's last act. mbrl-lib (its `pets.py`) refits
//! every `freq_train_model` real steps instead, which for some tasks is several times an episode;
//! this loop keeps the paper's once per episode.
//!
//! [`Pets`] is an [`Algorithm`]: one [`Algorithm::step`] is one episode and its refit, after which
//! it saves a checkpoint, so [`drive`] resumes a stopped run at the last finished episode and
//! gives exactly the numbers of an uninterrupted one. Every episode's record
//! ([`EpisodeRecord`]: its return, the fit's losses, the seconds spent planning and fitting) is
//! reported as it ends and kept in the [`PetsRecord`].
//!
//! ```no_run
//! use tandem_algos::pets::{run, PetsConfig};
//! use tandem_algos::{mbpo::pendulum_problem, Ephemeral};
//!
//! let cfg = PetsConfig::pendulum();
//! let record = run(&pendulum_problem(), &cfg, 0, &mut Ephemeral, &mut |ep| {
//!     println!("episode {}: return {:.1}", ep.episode + 1, ep.episode_return);
//! })
//! .unwrap();
//! println!("mean over episodes 2-10: {:.1}", record.mean_return(1..10).unwrap());
//! ```
//!
//! `examples/pets.rs` runs it on Pendulum-v1 ([`PetsConfig::pendulum`]).

use std::time::Instant;

use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_core::{Action, SeedStream};
use tandem_envs::{Env, EnvError, ObservedTask};
use tandem_models::{
    DynamicsModel, EarlyStop, EnsembleConfig, FitConfig, MemberData, OptimizerConfig,
    ProbabilisticEnsemble, Propagation, Transitions, TransitionsBuilder,
};
use tandem_nn::{Activation, AdamConfig, Checkpoint, Checkpointable};
use tandem_planners::{Bounds, Cem, CemConfig, Objective, Planner};

use super::driver::{drive, Algorithm};
use super::{box_bounds, AlgoError, Checkpoints, Problem, Result};

/// The gymnasium MuJoCo tasks [`PetsConfig::mujoco`] has settings for.
pub const MUJOCO_TASKS: [&str; 3] = ["HalfCheetah-v5", "Hopper-v5", "InvertedPendulum-v5"];

/// Settings of a PETS run. `Default` is the paper's (Chua et al. 2018, §6 and appendix, and the
/// authors' code `handful-of-trials`, `dmbrl/config`): an ensemble of 5 probabilistic networks,
/// all of them planning (4 hidden layers of 200 swish units, Adam 1e-3, learned log-variance
/// bounds, bootstrapped members), 5 epochs of minibatch 32 per refit with no holdout; CEM with a
/// population of 500, 50 elites, 5 iterations, smoothing 0.1, horizon 30 and the final mean as
/// the plan; 20 particles propagated TS-∞; one random episode. The per-task presets cite where
/// each number comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PetsConfig {
    /// The dynamics model, learning the observation change of each step. Its `learn_reward`
    /// must be off: plans are scored by the task's reward.
    pub ensemble: EnsembleConfig,
    /// Each refit on all data, continuing from the previous weights: epochs (the most, with
    /// `early_stop`), minibatch, the held-out fraction (elites and early stopping read it).
    pub model_fit: FitConfig,
    /// The planner: horizon, population, elites, iterations, smoothing, particles and their
    /// propagation. Its `bounds` default to the task's action bounds, its seed is drawn per
    /// episode from the run's.
    pub cem: CemConfig,
    /// Episodes of uniformly random actions before the first plan (the paper and mbrl-lib: one,
    /// mbrl-lib's `initial_exploration_steps` = `trial_length`).
    pub initial_episodes: usize,
    /// Episodes of the run, the random ones included.
    pub episodes: usize,
    /// Steps per episode (the paper's task horizon, mbrl-lib's `trial_length`); `None`: the real
    /// system's own time limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_episode_steps: Option<usize>,
}

impl Default for PetsConfig {
    fn default() -> Self {
        Self {
            ensemble: EnsembleConfig {
                members: 5,
                elites: 5,
                hidden: vec![200, 200, 200, 200],
                activation: Activation::Silu,
                optimizer: OptimizerConfig::adam(1e-3),
                learn_log_var_bounds: true,
                member_data: MemberData::Bootstrap,
                propagation: Propagation::FixedMember,
                sample: true,
                learn_reward: false,
                ..EnsembleConfig::default()
            },
            model_fit: FitConfig {
                epochs: 5,
                batch_size: 32,
                holdout_fraction: 0.0,
                seed: 0,
                early_stop: None,
            },
            cem: CemConfig {
                horizon: 30,
                population: 500,
                elite_fraction: 0.1,
                iterations: 5,
                alpha: 0.1,
                particles: 20,
                propagation: Some(Propagation::FixedMember),
                return_mean: true,
                ..CemConfig::default()
            },
            initial_episodes: 1,
            episodes: 100,
            max_episode_steps: None,
        }
    }
}

/// mbrl-lib's PETS settings: `conf/algorithm/pets.yaml` (20 particles, the final CEM mean as the
/// plan, `return_mean_elites`; targets as deltas, inputs standardized) over
/// `conf/dynamics_model/gaussian_mlp_ensemble.yaml` (7 members of 4 × 200 SiLU units,
/// `propagation_method: random_model`, i.e. TS-1, log-variance bounds not learned), with one
/// random episode (`initial_exploration_steps: ${overrides.trial_length}`). The arguments are a
/// task's `conf/overrides/pets_*.yaml`.
struct MbrlLib {
    /// `num_elites`.
    elites: usize,
    /// `model_lr`.
    lr: f32,
    /// `model_wd` (Adam's L2 weight decay, `torch.optim.Adam`).
    wd: f32,
    /// `model_batch_size`.
    batch: usize,
    /// `validation_ratio`.
    validation: f64,
    /// `patience` (with mbrl-lib's `improvement_threshold` 0.01).
    patience: usize,
    /// `num_epochs_train_model`.
    epochs: usize,
    /// `planning_horizon`.
    horizon: usize,
    /// `cem_num_iters`.
    iterations: usize,
    /// `cem_elite_ratio`.
    elite_ratio: f64,
    /// `cem_population_size`.
    population: usize,
    /// `cem_alpha`.
    alpha: f64,
    /// `num_steps / trial_length`.
    episodes: usize,
    /// `trial_length`.
    trial_length: usize,
}

impl MbrlLib {
    fn config(self) -> PetsConfig {
        // Early stopping needs held-out rows; without them mbrl-lib stops on the training loss,
        // which with its patience (at least its epoch count in every PETS override) never stops
        // a fit early: all epochs run.
        let early_stop = (self.validation > 0.0).then_some(EarlyStop {
            patience: self.patience,
            improvement_threshold: 0.01,
        });
        PetsConfig {
            ensemble: EnsembleConfig {
                members: 7,
                elites: self.elites,
                hidden: vec![200; 4],
                activation: Activation::Silu,
                optimizer: OptimizerConfig::Adam(AdamConfig {
                    lr: self.lr,
                    weight_decay: self.wd,
                    ..AdamConfig::default()
                }),
                learn_log_var_bounds: false,
                propagation: Propagation::RandomMember,
                ..PetsConfig::default().ensemble
            },
            model_fit: FitConfig {
                epochs: self.epochs,
                batch_size: self.batch,
                holdout_fraction: self.validation,
                seed: 0,
                early_stop,
            },
            cem: CemConfig {
                horizon: self.horizon,
                population: self.population,
                elite_fraction: self.elite_ratio,
                iterations: self.iterations,
                alpha: self.alpha,
                propagation: Some(Propagation::RandomMember),
                ..PetsConfig::default().cem
            },
            initial_episodes: 1,
            episodes: self.episodes,
            max_episode_steps: Some(self.trial_length),
        }
    }
}

impl PetsConfig {
    /// Pendulum-v1 (ours: neither the paper nor mbrl-lib runs it), sized for a 2-core machine:
    /// 10 episodes of 200 steps, the first random; 5 members of 3 × 200 SiLU units, all planning,
    /// refitted for at most 200 epochs of minibatch 32, stopping after 5 without a 1% gain on
    /// the 10% held out (mbrl-lib's `ModelTrainer` rule; 50 epochs left the first fits, on 200
    /// random transitions, too coarse to swing up from on some seeds); CEM over 25 steps
    /// (1.25 s, rl-blox's horizon), population 100, 10 elites, 5 iterations, with 5 particles
    /// TS-∞ (one per member). Smaller networks (3 × 64) or a 15-step horizon failed to swing up
    /// in some episodes on one seed of three. rl-blox's and mbrl-lib's usual sizes (20
    /// particles, 400 samples, 10 iterations) plan about 30 times more rollouts per step.
    pub fn pendulum() -> Self {
        let d = Self::default();
        Self {
            ensemble: EnsembleConfig {
                hidden: vec![200, 200, 200],
                ..d.ensemble
            },
            model_fit: FitConfig {
                epochs: 200,
                batch_size: 32,
                holdout_fraction: 0.1,
                seed: 0,
                early_stop: Some(EarlyStop::default()),
            },
            cem: CemConfig {
                horizon: 25,
                population: 100,
                particles: 5,
                ..d.cem
            },
            episodes: 10,
            max_episode_steps: Some(200),
            ..d
        }
    }

    /// mbrl-lib's `pets_halfcheetah.yaml` over its common PETS settings (`pets.yaml`: 20
    /// particles, the final CEM mean as the plan; `gaussian_mlp_ensemble.yaml`: 7 members of
    /// 4 × 200 SiLU units, TS-1, log-variance bounds not learned; one random episode): 5 elites,
    /// Adam 2e-4 with weight decay 3e-5, minibatch 32, no validation, 25 epochs (patience 25);
    /// horizon 30, CEM population 350, elite ratio 0.1, 5 iterations, α 0.1; 300 episodes of 1000
    /// steps (`num_steps` 300 000). The paper's HalfCheetah (`dmbrl/config/halfcheetah.py`):
    /// 5 networks of 4 × 200, Adam 1e-3, 5 epochs, population 500, horizon 30, 300 episodes.
    pub fn half_cheetah() -> Self {
        Self::half_cheetah_numbers().config()
    }

    /// mbrl-lib's `pets_hopper.yaml`: as [`PetsConfig::half_cheetah`] (Adam 2e-4, weight decay
    /// 3e-5, minibatch 32, 25 epochs, horizon 30, population 350) for 125 episodes of 1000 steps
    /// (`num_steps` 125 000). mbrl-lib refits every 250 steps; this loop once per episode.
    pub fn hopper() -> Self {
        MbrlLib {
            episodes: 125,
            ..Self::half_cheetah_numbers()
        }
        .config()
    }

    /// `pets_halfcheetah.yaml`'s numbers, which the other overrides mostly share.
    fn half_cheetah_numbers() -> MbrlLib {
        MbrlLib {
            elites: 5,
            lr: 2e-4,
            wd: 3e-5,
            batch: 32,
            validation: 0.0,
            patience: 25,
            epochs: 25,
            horizon: 30,
            iterations: 5,
            elite_ratio: 0.1,
            population: 350,
            alpha: 0.1,
            episodes: 300,
            trial_length: 1000,
        }
    }

    /// mbrl-lib's `pets_inv_pendulum.yaml`: Adam 1.43e-3 (the file writes `00143`) with weight
    /// decay 3.3e-5, minibatch 256, 20% validation, at most 31 epochs (patience 50); horizon 45,
    /// CEM population 480, elite ratio 0.078, 5 iterations, α 0.134484; 20 episodes of 1000 steps
    /// (`num_steps` 20 000). mbrl-lib refits every 250 steps; this loop once per episode.
    pub fn inverted_pendulum() -> Self {
        MbrlLib {
            elites: 5,
            lr: 1.43e-3,
            wd: 3.3e-5,
            batch: 256,
            validation: 0.2,
            patience: 50,
            epochs: 31,
            horizon: 45,
            iterations: 5,
            elite_ratio: 0.078,
            population: 480,
            alpha: 0.134484,
            episodes: 20,
            trial_length: 1000,
        }
        .config()
    }

    /// mbrl-lib's `pets_cartpole.yaml`, for a continuous cart-pole (mbrl-lib's
    /// `cartpole_continuous`; tandem's `CartPole-v1` has discrete actions, which CEM cannot
    /// plan): Adam 7.5e-4 with weight decay 3e-5, minibatch 256, no validation, 25 epochs;
    /// horizon 15, population 350, elite ratio 0.1, 5 iterations, α 0.1; 25 episodes of 200 steps
    /// (`num_steps` 5000). mbrl-lib refits every 50 steps; this loop once per episode. The
    /// paper's (`dmbrl/config/cartpole.py`): 3 × 500 units, horizon 25, population 400, 50
    /// episodes.
    pub fn cartpole() -> Self {
        MbrlLib {
            lr: 7.5e-4,
            batch: 256,
            horizon: 15,
            episodes: 25,
            trial_length: 200,
            ..Self::half_cheetah_numbers()
        }
        .config()
    }

    /// mbrl-lib's `pets_reacher.yaml`, for the paper's 7-DoF Reacher3D (not one of tandem's
    /// environments): Adam 4e-4 with weight decay 1.7e-4, minibatch 32, 5% validation, 25 epochs
    /// (patience 25); horizon 15, population 350, elite ratio 0.1, 5 iterations, α 0.1; 15
    /// episodes of 1000 steps (`num_steps` 15 000; the paper's episodes are 150 steps,
    /// `dmbrl/config/reacher.py`). mbrl-lib refits every 250 steps; this loop once per episode.
    pub fn reacher() -> Self {
        MbrlLib {
            lr: 4e-4,
            wd: 1.7e-4,
            validation: 0.05,
            horizon: 15,
            episodes: 15,
            ..Self::half_cheetah_numbers()
        }
        .config()
    }

    /// mbrl-lib's `pets_pusher.yaml`, for the paper's Pusher (not one of tandem's environments):
    /// Adam 1e-5 with weight decay 5e-4, minibatch 32, no validation, 25 epochs; horizon 25,
    /// population 350, elite ratio 0.1, 5 iterations, α 0.1; 100 episodes of 150 steps
    /// (`num_steps` 15 000, refit every 150 steps: once per episode).
    pub fn pusher() -> Self {
        MbrlLib {
            lr: 1e-5,
            wd: 5e-4,
            horizon: 25,
            episodes: 100,
            trial_length: 150,
            ..Self::half_cheetah_numbers()
        }
        .config()
    }

    /// The preset for the gymnasium MuJoCo task `id` ([`MUJOCO_TASKS`]): HalfCheetah-v5,
    /// Hopper-v5 and InvertedPendulum-v5 take mbrl-lib's settings for their gym versions
    /// ([`PetsConfig::half_cheetah`], [`PetsConfig::hopper`],
    /// [`PetsConfig::inverted_pendulum`]); `None` for another task (mbrl-lib has no PETS settings
    /// for Walker2d). At full size one plan is 350 × 20 rollouts of 30 steps through 4 × 200
    /// units, about 9 s a real step on a 2-core machine; [`PetsConfig::small`] cuts it to about
    /// a twelfth.
    pub fn mujoco(id: &str) -> Option<Self> {
        match id {
            "HalfCheetah-v5" => Some(Self::half_cheetah()),
            "Hopper-v5" => Some(Self::hopper()),
            "InvertedPendulum-v5" => Some(Self::inverted_pendulum()),
            _ => None,
        }
    }

    /// This preset with less planning per real step, the model and the loop unchanged: one
    /// particle per elite (TS-∞ then keeps each elite once per sequence; 20 → 5 particles for
    /// the presets here) and a population of at most 100 (the elite fraction kept). What a
    /// 2-core machine affords; the presets keep the paper's and mbrl-lib's numbers.
    pub fn small(mut self) -> Self {
        self.cem.particles = self.cem.particles.min(self.ensemble.elites).max(1);
        self.cem.population = self.cem.population.min(100);
        self
    }

    /// Checks what the loop relies on; an error naming the setting, never a panic.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(AlgoError::Config(format!("pets: {m}")));
        let e = &self.ensemble;
        for (name, v) in [
            ("ensemble.members", e.members),
            ("ensemble.elites", e.elites),
            ("cem.particles", self.cem.particles),
            ("cem.horizon", self.cem.horizon),
            ("cem.population", self.cem.population),
            ("cem.iterations", self.cem.iterations),
            ("model_fit.epochs", self.model_fit.epochs),
            ("model_fit.batch_size", self.model_fit.batch_size),
            ("initial_episodes", self.initial_episodes),
            ("episodes", self.episodes),
        ] {
            if v == 0 {
                return bad(format!("{name} must be at least 1"));
            }
        }
        if e.elites > e.members {
            return bad(format!(
                "ensemble.elites ({}) must not exceed ensemble.members ({})",
                e.elites, e.members
            ));
        }
        if e.hidden.contains(&0) {
            return bad("ensemble.hidden widths must be at least 1".into());
        }
        if e.learn_reward {
            return bad(
                "ensemble.learn_reward must be false: plans are scored by the task's reward".into(),
            );
        }
        if self.max_episode_steps == Some(0) {
            return bad("max_episode_steps must be at least 1".into());
        }
        let holdout = self.model_fit.holdout_fraction;
        if !(0.0..1.0).contains(&holdout) {
            return bad(format!(
                "model_fit.holdout_fraction must lie in [0, 1), got {holdout}"
            ));
        }
        if let Some(stop) = &self.model_fit.early_stop {
            if holdout == 0.0 {
                return bad(
                    "model_fit.early_stop needs held-out rows: raise model_fit.holdout_fraction \
                     above 0"
                        .into(),
                );
            }
            if stop.patience == 0 {
                return bad("model_fit.early_stop.patience must be at least 1".into());
            }
        }
        Cem::new(self.cem.clone()).map_err(|err| AlgoError::Config(format!("pets: cem: {err}")))?;
        Ok(())
    }
}

/// What one episode did, reported as it ends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRecord {
    /// The episode's index, from 0.
    pub episode: usize,
    /// Whether it acted at random (the initial episodes).
    pub random: bool,
    /// Its return (the real system's rewards, summed).
    pub episode_return: f64,
    /// Its real steps.
    pub steps: usize,
    /// Seconds spent choosing its actions (planning; ~0 for a random episode).
    pub act_seconds: f64,
    /// The refit on all data after it.
    pub fit: FitRecord,
}

/// What one refit of the ensemble reported.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitRecord {
    /// Transitions it was fitted on (all data so far).
    pub transitions: usize,
    /// Epochs run (fewer than configured when early stopping cut the fit short).
    pub epochs: usize,
    /// Mean training loss of the last epoch run (Gaussian NLL per element, members averaged).
    /// With early stopping the weights kept are those of the last epoch in which some member
    /// improved, up to `patience` epochs before it.
    pub train_loss: f64,
    /// Held-out loss of the last epoch run; `None` without a holdout.
    pub holdout_loss: Option<f64>,
    /// Seconds the fit took.
    pub seconds: f64,
}

/// What a finished run reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PetsRecord {
    /// The seed.
    pub seed: u64,
    /// Every episode, in order.
    pub episodes: Vec<EpisodeRecord>,
    /// Wall time, seconds (over all the processes that ran it, if resumed).
    pub wall_seconds: f64,
}

impl PetsRecord {
    /// The mean return of the episodes with indices in `range` (from 0); `None` when it holds
    /// none of them.
    pub fn mean_return(&self, range: std::ops::Range<usize>) -> Option<f64> {
        let r: Vec<f64> = self
            .episodes
            .iter()
            .filter(|e| range.contains(&e.episode))
            .map(|e| e.episode_return)
            .collect();
        (!r.is_empty()).then(|| r.iter().sum::<f64>() / r.len() as f64)
    }

    /// Seconds spent choosing an action per real step, over the planned (not random) episodes;
    /// `None` before the first.
    pub fn act_seconds_per_step(&self) -> Option<f64> {
        let planned = self.episodes.iter().filter(|e| !e.random);
        let (secs, steps) = planned.fold((0.0, 0), |(s, n), e| (s + e.act_seconds, n + e.steps));
        (steps > 0).then(|| secs / steps as f64)
    }
}

/// Runs PETS for `seed` on `problem` from the checkpoint `store` holds under `"pets"`, if any,
/// calling `on_episode` as each episode ends.
pub fn run<T, F>(
    problem: &Problem<T, F>,
    cfg: &PetsConfig,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_episode: &mut dyn FnMut(EpisodeRecord),
) -> Result<PetsRecord>
where
    T: ObservedTask + Clone + Send + Sync + 'static,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    drive(Pets::new(problem, cfg, seed)?, store, on_episode)
}

/// One PETS run as one checkpointable value, an episode per [`Algorithm::step`]: the ensemble,
/// all real transitions (observations, actions, next observations) and the episodes so far.
/// Everything else is drawn per episode from the run's seed (the episode's reset, its random
/// actions and member offsets, its planner's sampling), so a resumed run repeats the numbers of
/// an uninterrupted one.
pub struct Pets<'a> {
    cfg: &'a PetsConfig,
    seed: u64,
    seeds: SeedStream,
    objective: Objective,
    bounds: Bounds,
    max_steps: usize,
    model: ProbabilisticEnsemble,
    env: Box<dyn Env>,
    data: Transitions,
    episodes: Vec<EpisodeRecord>,
}

const MODEL: &str = "pets.model";
const DATA: &str = "pets.data";
const EPISODES: &str = "pets.episodes";

impl<'a> Pets<'a> {
    /// A fresh run for `seed` on `problem`: checks `cfg`, builds the real system, the objective
    /// from the task's observation reward and termination, and the ensemble (seeded from
    /// `seed`). An error for a task with discrete actions, unbounded actions (random episodes
    /// draw within the bounds) or episodes with no end.
    pub fn new<T, F>(problem: &Problem<T, F>, cfg: &'a PetsConfig, seed: u64) -> Result<Self>
    where
        T: ObservedTask + Clone + Send + Sync + 'static,
        F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
    {
        cfg.validate()?;
        let task = &problem.task;
        let env = (problem.env)()?;
        let (obs_dim, act_dim) = (
            task.observation_space().flat_dim(),
            task.action_space().flat_dim(),
        );
        for (what, ours, its) in [
            ("observation", obs_dim, env.observation_space().flat_dim()),
            ("action", act_dim, env.action_space().flat_dim()),
        ] {
            if ours != its {
                return Err(AlgoError::Config(format!(
                    "pets: the task's {what} space has {ours} components, the real system's {its}"
                )));
            }
        }
        let bounds = match &cfg.cem.bounds {
            Some(b) => b.clone(),
            None => {
                let (low, high) = box_bounds(task.action_space(), "pets needs")?;
                Bounds::new(low, high)
            }
        };
        bounds.validate(act_dim)?;
        if bounds
            .low
            .iter()
            .chain(&bounds.high)
            .any(|v| !v.is_finite())
        {
            return Err(AlgoError::Config(
                "pets: random episodes need finite action bounds (set cem.bounds)".into(),
            ));
        }
        let max_steps = cfg
            .max_episode_steps
            .or(env.max_episode_steps())
            .ok_or_else(|| {
                AlgoError::Config(format!(
                    "pets: {} has no time limit; set max_episode_steps",
                    env.id()
                ))
            })?;
        let objective = Objective::from_task_observations(task.clone())?;
        let seeds = SeedStream::new(seed);
        let model = ProbabilisticEnsemble::new(
            obs_dim,
            act_dim,
            EnsembleConfig {
                seed: seeds.derive("model"),
                ..cfg.ensemble.clone()
            },
        )?;
        Ok(Self {
            cfg,
            seed,
            seeds,
            objective,
            bounds,
            max_steps,
            model,
            env,
            data: Transitions::default(),
            episodes: Vec::new(),
        })
    }

    /// The ensemble as the last refit left it.
    pub fn model(&self) -> &ProbabilisticEnsemble {
        &self.model
    }

    /// All real transitions so far.
    pub fn data(&self) -> &Transitions {
        &self.data
    }

    /// One episode, random or planned, its transitions added to the data.
    fn episode(&mut self, k: usize) -> Result<(bool, f64, usize, f64)> {
        let random = k < self.cfg.initial_episodes;
        let mut rng = self.seeds.rng(&format!("episode-{k}"));
        let mut planner = Cem::new(CemConfig {
            bounds: Some(self.bounds.clone()),
            seed: self.seeds.derive(&format!("cem-{k}")),
            ..self.cfg.cem.clone()
        })?;
        let (obs_dim, act_dim) = (self.model.state_dim(), self.model.action_dim());
        let mut data = TransitionsBuilder::new(obs_dim, act_dim);
        let mut obs = self
            .env
            .reset(Some(self.seeds.derive(&format!("reset-{k}"))));
        let (mut ret, mut steps, mut act_seconds) = (0.0, 0, 0.0);
        while steps < self.max_steps {
            let t0 = Instant::now();
            let action: Vec<f64> = if random {
                let b = &self.bounds;
                (0..act_dim)
                    .map(|j| rng.random_range(b.low[j]..=b.high[j]))
                    .collect()
            } else {
                // TS-∞ deals a plan's particles to the elites from an offset drawn per plan.
                self.model.resample_member_offset(&mut rng);
                let plan = planner.plan(&obs, &self.model, &self.objective)?;
                plan.actions.row(0).to_vec()
            };
            act_seconds += t0.elapsed().as_secs_f64();
            let step = self.env.step(&Action::Continuous(action.clone()))?;
            data.push(
                &obs,
                &action,
                &step.observation,
                step.reward,
                step.terminated,
            )?;
            ret += step.reward;
            steps += 1;
            if step.done() {
                break;
            }
            obs = step.observation;
        }
        let new = data.build();
        if self.data.is_empty() {
            self.data = new;
        } else {
            self.data.extend(&new)?;
        }
        Ok((random, ret, steps, act_seconds))
    }

    /// Refits the ensemble on all data, continuing from its weights.
    fn refit(&mut self, k: usize) -> Result<FitRecord> {
        let fit = FitConfig {
            seed: self.seeds.derive(&format!("fit-{k}")),
            ..self.cfg.model_fit.clone()
        };
        let t0 = Instant::now();
        let report = self.model.fit(&self.data, &fit)?;
        Ok(FitRecord {
            transitions: self.data.len(),
            epochs: report.train_loss.len(),
            train_loss: report.train_loss.last().copied().unwrap_or(f64::NAN),
            holdout_loss: report.holdout_loss.last().copied(),
            seconds: t0.elapsed().as_secs_f64(),
        })
    }
}

impl Algorithm for Pets<'_> {
    type Event = EpisodeRecord;
    type Record = PetsRecord;
    const SUMS_WALL_TIME: bool = true;

    fn id(&self) -> (&str, u64) {
        ("pets", self.seed)
    }

    fn done(&self) -> bool {
        self.episodes.len() >= self.cfg.episodes
    }

    fn step(
        &mut self,
        on_event: &mut dyn FnMut(EpisodeRecord),
        _stop: &dyn Checkpoints,
    ) -> Result<bool> {
        let k = self.episodes.len();
        let (random, episode_return, steps, act_seconds) = self.episode(k)?;
        let fit = self.refit(k)?;
        let record = EpisodeRecord {
            episode: k,
            random,
            episode_return,
            steps,
            act_seconds,
            fit,
        };
        self.episodes.push(record.clone());
        on_event(record);
        Ok(true)
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        self.model.save_to(MODEL, ckpt)?;
        self.data.save_to(DATA, ckpt)?;
        ckpt.put_json(EPISODES, &self.episodes)?;
        Ok(())
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let episodes = ckpt.get_json(EPISODES)?;
        self.model.load_from(MODEL, ckpt)?;
        self.data.load_from(DATA, ckpt)?;
        self.episodes = episodes;
        Ok(())
    }

    fn finish(self, wall_seconds: f64) -> Result<PetsRecord> {
        Ok(PetsRecord {
            seed: self.seed,
            episodes: self.episodes,
            wall_seconds,
        })
    }
}
