//! The training loop of `tandem train`: one of the four agents ([`Learner`]) on one environment,
//! periodic deterministic evaluation, a run log, and checkpoints of all of it. The off-policy
//! agents run the shared [`OffPolicyLoop`] (the same loop every paper's pipeline runs);
//! REINFORCE collects episodes with the same [`EpisodeRunner`].
//!
//! Reproducible by construction: every episode is reset with a seed derived from the run seed and
//! the episode's index, warm-up actions and minibatches come from the trainer's own generator, and
//! the agent draws from its own. A checkpoint stores all generators, the replay buffer, the
//! in-progress episode and the environment's internal state, so a run saved at any step and
//! resumed continues with exactly the numbers of an uninterrupted one.
//!
//! The loop follows stable-baselines3's off-policy schedule: uniformly random actions for the
//! first `learning_starts` steps, then `gradient_steps` updates every `train_freq` steps once more
//! than `learning_starts` steps were taken; after every environment step (warm-up included) the
//! agent's `on_env_step` runs, as `_on_step` does there. A time-limit truncation is stored as not
//! terminated, so targets bootstrap through it (stable-baselines3's
//! `handle_timeout_termination`). The episode length limit is enforced here as well as
//! by any `TimeLimit` wrapper (so it survives a resume that restores the environment's state).

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};
use tandem_core::SeedStream;
use tandem_envs::Env;
use tandem_nn::Checkpoint;

use crate::agent::{Episode, Mode};
use crate::error::{ensure, AgentError, Result};
use crate::learner::{AlgoConfig, Learner};
use crate::off_policy::{env_err, evaluate, EpisodeRunner, OffPolicyLoop, StepOptions, StepRecord};

/// Settings of the loop itself (not of the agent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainSettings {
    /// Evaluate every this many environment steps (0: only when asked, e.g. at the end).
    pub eval_interval: u64,
    /// Deterministic episodes per evaluation.
    pub eval_episodes: usize,
    /// Stop after this many training episodes, even before the step budget is spent.
    pub max_episodes: Option<u64>,
    /// Episode length limit; `None` takes the environment's (`Env::max_episode_steps`).
    pub max_episode_steps: Option<usize>,
    /// A training-return level: the log reports the first episode at which the average return
    /// of the last `solved_window` episodes reaches it (195 for CartPole in p2).
    pub solved_threshold: Option<f64>,
    /// Window of that average.
    pub solved_window: usize,
    /// [`Trainer::run_until_pause`] also pauses for a checkpoint every this many environment
    /// steps (0: only at evaluations). A run killed at any moment loses at most this many steps
    /// (or the evaluation interval, if smaller).
    pub checkpoint_interval: u64,
}

impl Default for TrainSettings {
    /// Evaluate every 1000 steps on 10 deterministic episodes (the final evaluation
    /// uses 10 as well); CartPole's solved criterion window of 100 episodes.
    fn default() -> Self {
        Self {
            eval_interval: 1000,
            eval_episodes: 10,
            max_episodes: None,
            max_episode_steps: None,
            solved_threshold: None,
            solved_window: 100,
            checkpoint_interval: 10_000,
        }
    }
}

impl TrainSettings {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<()> {
        ensure(
            self.eval_episodes >= 1,
            "eval_episodes",
            self.eval_episodes,
            "must be >= 1",
        )?;
        ensure(
            self.solved_window >= 1,
            "solved_window",
            self.solved_window,
            "must be >= 1",
        )?;
        if let Some(m) = self.max_episode_steps {
            ensure(m >= 1, "max_episode_steps", m, "must be >= 1")?;
        }
        Ok(())
    }
}

/// One finished training episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRecord {
    /// Index (from 0).
    pub episode: u64,
    /// Environment steps taken when it ended.
    pub step: u64,
    /// Sum of rewards.
    pub ret: f64,
    /// Number of steps.
    pub length: usize,
    /// Average return of the last `solved_window` episodes, this one included.
    pub ret_window_mean: f64,
}

/// One evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalRecord {
    /// Environment (training) steps taken.
    pub step: u64,
    /// Training episodes finished.
    pub episodes: u64,
    /// Mean return of the deterministic episodes.
    pub mean: f64,
    /// Their standard deviation (population).
    pub std: f64,
    /// The returns.
    pub returns: Vec<f64>,
    /// Gradient updates so far.
    pub updates: u64,
    /// The last update's figures.
    pub last_update: Vec<(String, f64)>,
}

/// Everything a run reports.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunLog {
    /// Every training episode.
    pub episodes: Vec<EpisodeRecord>,
    /// Every evaluation.
    pub evals: Vec<EvalRecord>,
    /// First episode at which the windowed training return reached `solved_threshold`.
    pub solved_at_episode: Option<u64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Progress {
    /// Environment steps (REINFORCE; the off-policy loop counts its own).
    step: u64,
    /// Gradient updates (REINFORCE).
    updates: u64,
    last_update: Vec<(String, f64)>,
    runner: EpisodeRunner,
    env_state: Option<Vec<f64>>,
    current: Episode,
    pending: Vec<Episode>,
    log: RunLog,
}

/// Why [`Trainer::run_until_pause`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pause {
    /// The step budget (or `max_episodes`) is spent.
    Finished,
    /// A checkpoint point: an evaluation just ran, or `checkpoint_interval` steps passed. Save
    /// with [`Trainer::save`] and call again to go on.
    Checkpoint,
    /// The progress callback asked to stop; the step it saw is complete, so a checkpoint saved
    /// now resumes exactly.
    Stopped,
}

/// The agent and how it learns.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
enum Core {
    /// DDPG, SAC, DQN: the shared off-policy loop.
    OffPolicy(OffPolicyLoop<Learner>),
    /// REINFORCE: whole episodes.
    Episodic(Learner),
}

/// A training run in progress.
#[derive(Debug, Clone)]
pub struct Trainer {
    core: Core,
    config: AlgoConfig,
    settings: TrainSettings,
    seeds: SeedStream,
    p: Progress,
}

impl Trainer {
    /// A fresh run of the agent `config` describes on environments with `env`'s spaces.
    pub fn new(
        config: AlgoConfig,
        settings: TrainSettings,
        env: &dyn Env,
        seed: u64,
    ) -> Result<Self> {
        settings.validate()?;
        let (obs_space, act_space) = (env.observation_space(), env.action_space());
        let seeds = SeedStream::new(seed);
        let learner = Learner::new(&config, obs_space, act_space, seeds.derive("agent"))?;
        let core = match config.schedule() {
            Some(s) => Core::OffPolicy(OffPolicyLoop::new(
                learner,
                s,
                obs_space,
                act_space,
                seeds.rng("trainer"),
            )?),
            None => Core::Episodic(learner),
        };
        Ok(Self {
            core,
            config,
            p: Progress {
                step: 0,
                updates: 0,
                last_update: Vec::new(),
                runner: EpisodeRunner::new(seed, "train-episode-")
                    .with_limit(settings.max_episode_steps),
                env_state: None,
                current: Episode::default(),
                pending: Vec::new(),
                log: RunLog::default(),
            },
            settings,
            seeds,
        })
    }

    /// Environment steps taken (the exact count of real samples used for training).
    pub fn steps(&self) -> u64 {
        match &self.core {
            Core::OffPolicy(l) => l.counts().real_steps,
            Core::Episodic(_) => self.p.step,
        }
    }

    /// Training episodes finished.
    pub fn episodes(&self) -> u64 {
        self.p.runner.episode()
    }

    /// Gradient updates made.
    pub fn updates(&self) -> u64 {
        match &self.core {
            Core::OffPolicy(l) => l.counts().updates,
            Core::Episodic(_) => self.p.updates,
        }
    }

    /// The run log so far.
    pub fn log(&self) -> &RunLog {
        &self.p.log
    }

    /// The agent.
    pub fn learner(&mut self) -> &mut Learner {
        match &mut self.core {
            Core::OffPolicy(l) => &mut l.agent,
            Core::Episodic(a) => a,
        }
    }

    /// The agent's configuration.
    pub fn config(&self) -> &AlgoConfig {
        &self.config
    }

    /// The loop's settings.
    pub fn settings(&self) -> &TrainSettings {
        &self.settings
    }

    /// `true` once `max_episodes` training episodes are finished.
    pub fn episodes_done(&self) -> bool {
        self.settings
            .max_episodes
            .is_some_and(|m| self.episodes() >= m)
    }

    fn last_update(&self) -> Vec<(String, f64)> {
        match &self.core {
            Core::OffPolicy(l) => l.last_update().to_vec(),
            Core::Episodic(_) => self.p.last_update.clone(),
        }
    }

    /// Trains until `until_step` environment steps (or `max_episodes`), evaluating on `eval_env`
    /// every `eval_interval` steps and calling `progress` after every step.
    pub fn run(
        &mut self,
        env: &mut dyn Env,
        eval_env: &mut dyn Env,
        until_step: u64,
        progress: &mut dyn FnMut(&Trainer),
    ) -> Result<()> {
        let mut go_on = |t: &Trainer| {
            progress(t);
            ControlFlow::Continue(())
        };
        while self.run_until_pause(env, eval_env, until_step, &mut go_on)? != Pause::Finished {}
        Ok(())
    }

    /// Like [`Trainer::run`], but returns at every checkpoint point (after an evaluation, and
    /// every `checkpoint_interval` steps) and as soon as `progress` returns
    /// [`ControlFlow::Break`] (after the step it was called for), saying which with [`Pause`].
    /// Calling it again goes on where it stopped; where it pauses never changes the numbers.
    pub fn run_until_pause(
        &mut self,
        env: &mut dyn Env,
        eval_env: &mut dyn Env,
        until_step: u64,
        progress: &mut dyn FnMut(&Trainer) -> ControlFlow<()>,
    ) -> Result<Pause> {
        while self.steps() < until_step && !self.episodes_done() {
            let rec = match &mut self.core {
                Core::OffPolicy(l) => l.step(env, &mut self.p.runner, StepOptions::real())?,
                Core::Episodic(agent) => {
                    let obs = self.p.runner.observation(env, agent.agent());
                    let action = agent.act(&obs, Mode::Explore)?;
                    let rec = self.p.runner.step(env, obs, action, false)?;
                    self.p.step += 1;
                    agent.agent().on_env_step();
                    self.p
                        .current
                        .push(rec.obs.clone(), rec.action.clone(), rec.reward);
                    rec
                }
            };
            if rec.done() {
                self.finish_episode(&rec)?;
            }
            let steps = self.steps();
            let every = |n: u64| n > 0 && steps.is_multiple_of(n);
            let evaluated = every(self.settings.eval_interval);
            if evaluated {
                self.evaluate(eval_env)?;
            }
            if progress(self).is_break() {
                return Ok(Pause::Stopped);
            }
            if evaluated || every(self.settings.checkpoint_interval) {
                return Ok(Pause::Checkpoint);
            }
        }
        Ok(Pause::Finished)
    }

    fn finish_episode(&mut self, rec: &StepRecord) -> Result<()> {
        let w = self.settings.solved_window;
        let log = &mut self.p.log;
        let k = log.episodes.len();
        let lo = (k + 1).saturating_sub(w);
        let sum: f64 = log.episodes[lo..].iter().map(|e| e.ret).sum::<f64>() + rec.episode_return;
        let mean = sum / (k + 1 - lo) as f64;
        // The runner has counted this episode already.
        let episode = self.p.runner.episode() - 1;
        log.episodes.push(EpisodeRecord {
            episode,
            step: match &self.core {
                Core::OffPolicy(l) => l.counts().real_steps,
                Core::Episodic(_) => self.p.step,
            },
            ret: rec.episode_return,
            length: rec.episode_len,
            ret_window_mean: mean,
        });
        if let Some(t) = self.settings.solved_threshold {
            if log.solved_at_episode.is_none() && k + 1 >= w && mean >= t {
                log.solved_at_episode = Some(episode);
            }
        }
        if let (Core::Episodic(agent), AlgoConfig::Reinforce(c)) = (&mut self.core, &self.config) {
            let mut e = std::mem::take(&mut self.p.current);
            e.terminated = rec.terminated;
            self.p.pending.push(e);
            if self.p.pending.len() >= c.episodes_per_update {
                let m = agent.update_episodes(&self.p.pending)?;
                self.p.updates += 1;
                self.p.last_update = m.0.iter().map(|(k, v)| (k.to_string(), *v)).collect();
                self.p.pending.clear();
            }
        }
        Ok(())
    }

    /// Runs `eval_episodes` deterministic episodes on `env` (fixed seeds, the same at every
    /// evaluation), logs and returns the record. Does not touch the training generators.
    pub fn evaluate(&mut self, env: &mut dyn Env) -> Result<EvalRecord> {
        let (episodes, limit) = (self.settings.eval_episodes, self.settings.max_episode_steps);
        let seeds = self.seeds;
        let returns = evaluate(self.learner().agent(), env, episodes, &seeds, limit)?;
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let rec = EvalRecord {
            step: self.steps(),
            episodes: self.episodes(),
            mean,
            std,
            returns,
            updates: self.updates(),
            last_update: self.last_update(),
        };
        self.p.log.evals.push(rec.clone());
        Ok(rec)
    }

    /// The whole run's state: agent, replay buffer, generators, in-progress episode (with
    /// `env`'s internal state), and log.
    pub fn save(&self, env: &dyn Env) -> Result<Checkpoint> {
        let mut ckpt = Checkpoint::new();
        match &self.core {
            Core::OffPolicy(l) => {
                l.agent.save(&mut ckpt)?;
                l.save("trainer", &mut ckpt)?;
            }
            Core::Episodic(a) => a.save(&mut ckpt)?,
        }
        let mut p = self.p.clone();
        p.env_state = p.runner.in_episode().then(|| env.state());
        ckpt.put_json("trainer", &p)?;
        ckpt.put_json("trainer_config", &(&self.config, &self.settings))?;
        Ok(ckpt)
    }

    /// Restores a run saved by [`Trainer::save`] into a trainer built with the same
    /// configuration, putting `env` back into the saved episode. Errors for another algorithm,
    /// architecture or configuration.
    pub fn load(&mut self, ckpt: &Checkpoint, env: &mut dyn Env) -> Result<()> {
        let (config, settings): (AlgoConfig, TrainSettings) = ckpt.get_json("trainer_config")?;
        if config.algo() != self.config.algo() {
            return Err(AgentError::Checkpoint(format!(
                "written by a `{}` run, cannot resume a `{}` run",
                config.algo().name(),
                self.config.algo().name()
            )));
        }
        self.learner().load(ckpt)?;
        if config != self.config || settings != self.settings {
            return Err(AgentError::Checkpoint(
                "the run's configuration differs from this trainer's".into(),
            ));
        }
        if let Core::OffPolicy(l) = &mut self.core {
            l.load("trainer", ckpt)?;
        }
        let p: Progress = ckpt.get_json("trainer")?;
        if let Some(state) = &p.env_state {
            env.set_state(state).map_err(env_err)?;
        }
        self.p = p;
        Ok(())
    }
}
