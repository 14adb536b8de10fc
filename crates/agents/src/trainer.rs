//! The training loop: an agent, an environment, replay (off-policy) or episode collection
//! (REINFORCE), periodic deterministic evaluation, a run log, and checkpoints of all of it.
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

use serde::{Deserialize, Serialize};
use tandem_core::{Rng, SeedStream, Space};
use tandem_envs::Env;
use tandem_nn::Checkpoint;

use crate::agent::{action_row, Batch, Episode, Mode};
use crate::ddpg::random_action;
use crate::error::{ensure, AgentError, Result};
use crate::learner::{AlgoConfig, Learner};
use crate::replay::{ReplayBuffer, TransitionRef};

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
    step: u64,
    episode: u64,
    updates: u64,
    obs: Option<Vec<f64>>,
    env_state: Option<Vec<f64>>,
    prev_action: Vec<f64>,
    ep_return: f64,
    ep_len: usize,
    current: Episode,
    pending: Vec<Episode>,
    last_update: Vec<(String, f64)>,
    rng: Rng,
    log: RunLog,
}

/// A training run in progress.
#[derive(Debug, Clone)]
pub struct Trainer {
    learner: Learner,
    config: AlgoConfig,
    settings: TrainSettings,
    seeds: SeedStream,
    act_space: Space,
    act_dim: usize,
    replay: Option<ReplayBuffer>,
    batch: Batch,
    p: Progress,
}

fn env_err(e: tandem_envs::EnvError) -> AgentError {
    AgentError::Env(e.to_string())
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
        let obs_space = env.observation_space().clone();
        let act_space = env.action_space().clone();
        let seeds = SeedStream::new(seed);
        let learner = Learner::new(&config, &obs_space, &act_space, seeds.derive("agent"))?;
        let act_dim = act_space.flat_dim();
        let od = obs_space.flat_dim();
        let (replay, batch) = match config.schedule() {
            Some(s) => (
                Some(ReplayBuffer::new(s.buffer_size, od, act_dim)?),
                Batch::zeros(s.batch_size, od, act_dim),
            ),
            None => (None, Batch::zeros(0, od, act_dim)),
        };
        Ok(Self {
            learner,
            config,
            settings,
            act_space,
            act_dim,
            replay,
            batch,
            p: Progress {
                step: 0,
                episode: 0,
                updates: 0,
                obs: None,
                env_state: None,
                prev_action: vec![0.0; act_dim],
                ep_return: 0.0,
                ep_len: 0,
                current: Episode::default(),
                pending: Vec::new(),
                last_update: Vec::new(),
                rng: seeds.rng("trainer"),
                log: RunLog::default(),
            },
            seeds,
        })
    }

    /// Environment steps taken (the exact count of real samples used for training).
    pub fn steps(&self) -> u64 {
        self.p.step
    }

    /// Training episodes finished.
    pub fn episodes(&self) -> u64 {
        self.p.episode
    }

    /// Gradient updates made.
    pub fn updates(&self) -> u64 {
        self.p.updates
    }

    /// The run log so far.
    pub fn log(&self) -> &RunLog {
        &self.p.log
    }

    /// The agent.
    pub fn learner(&mut self) -> &mut Learner {
        &mut self.learner
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
            .is_some_and(|m| self.p.episode >= m)
    }

    fn limit(&self, env: &dyn Env) -> Option<usize> {
        self.settings.max_episode_steps.or(env.max_episode_steps())
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
        let limit = self.limit(env);
        let schedule = self.config.schedule();
        while self.p.step < until_step && !self.episodes_done() {
            let obs = match self.p.obs.take() {
                Some(o) => o,
                None => {
                    let seed = self
                        .seeds
                        .derive(&format!("train-episode-{}", self.p.episode));
                    let o = env.reset(Some(seed));
                    self.learner.agent().reset_episode();
                    self.p.prev_action.iter_mut().for_each(|a| *a = 0.0);
                    self.p.ep_return = 0.0;
                    self.p.ep_len = 0;
                    self.p.current = Episode::default();
                    o
                }
            };
            let warmup = schedule.is_some_and(|s| self.p.step < s.learning_starts as u64);
            let action = if warmup {
                random_action(&self.act_space, &mut self.p.rng)
            } else {
                self.learner.act(&obs, Mode::Explore)?
            };
            let st = env.step(&action).map_err(env_err)?;
            self.p.step += 1;
            self.learner.agent().on_env_step();
            self.p.ep_len += 1;
            self.p.ep_return += st.reward;
            let truncated = st.truncated || limit.is_some_and(|m| self.p.ep_len >= m);
            let mut a_row = vec![0.0f32; self.act_dim];
            action_row(&action, &mut a_row);
            let a64: Vec<f64> = a_row.iter().map(|v| f64::from(*v)).collect();
            if let Some(r) = &mut self.replay {
                r.push(TransitionRef {
                    obs: &obs,
                    action: &a64,
                    prev_action: &self.p.prev_action,
                    reward: st.reward,
                    next_obs: &st.observation,
                    terminated: st.terminated,
                })?;
            } else {
                self.p.current.push(obs, action, st.reward);
            }
            self.p.prev_action = a64;
            self.p.obs = Some(st.observation);

            if let (Some(s), Some(r)) = (schedule, &self.replay) {
                if self.p.step > s.learning_starts as u64 && self.p.step % s.train_freq as u64 == 0
                {
                    for _ in 0..s.gradient_steps {
                        let n = self.batch.len();
                        r.sample_into(&mut self.p.rng, &mut self.batch, 0..n)?;
                        let m = self.learner.update_batch(&self.batch)?;
                        self.p.updates += 1;
                        if self.p.updates % 64 == 0 || s.gradient_steps == 1 {
                            self.p.last_update =
                                m.0.iter().map(|(k, v)| (k.to_string(), *v)).collect();
                        }
                    }
                }
            }

            if st.terminated || truncated {
                self.finish_episode(st.terminated)?;
            }
            let ei = self.settings.eval_interval;
            if ei > 0 && self.p.step % ei == 0 {
                self.evaluate(eval_env)?;
            }
            progress(self);
        }
        Ok(())
    }

    fn finish_episode(&mut self, terminated: bool) -> Result<()> {
        let w = self.settings.solved_window;
        let log = &mut self.p.log;
        let k = log.episodes.len();
        let lo = (k + 1).saturating_sub(w);
        let sum: f64 = log.episodes[lo..].iter().map(|e| e.ret).sum::<f64>() + self.p.ep_return;
        let mean = sum / (k + 1 - lo) as f64;
        log.episodes.push(EpisodeRecord {
            episode: self.p.episode,
            step: self.p.step,
            ret: self.p.ep_return,
            length: self.p.ep_len,
            ret_window_mean: mean,
        });
        if let Some(t) = self.settings.solved_threshold {
            if log.solved_at_episode.is_none() && k + 1 >= w && mean >= t {
                log.solved_at_episode = Some(self.p.episode);
            }
        }
        self.p.episode += 1;
        self.p.obs = None;
        if let AlgoConfig::Reinforce(c) = &self.config {
            let mut e = std::mem::take(&mut self.p.current);
            e.terminated = terminated;
            self.p.pending.push(e);
            if self.p.pending.len() >= c.episodes_per_update {
                let m = self.learner.update_episodes(&self.p.pending)?;
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
        let limit = self.limit(env);
        let mut returns = Vec::with_capacity(self.settings.eval_episodes);
        for i in 0..self.settings.eval_episodes {
            let mut obs = env.reset(Some(self.seeds.derive(&format!("eval-episode-{i}"))));
            let (mut ret, mut len) = (0.0, 0usize);
            loop {
                let a = self.learner.act(&obs, Mode::Deterministic)?;
                let st = env.step(&a).map_err(env_err)?;
                ret += st.reward;
                len += 1;
                if st.terminated || st.truncated || limit.is_some_and(|m| len >= m) {
                    break;
                }
                obs = st.observation;
            }
            returns.push(ret);
        }
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let rec = EvalRecord {
            step: self.p.step,
            episodes: self.p.episode,
            mean,
            std,
            returns,
            updates: self.p.updates,
            last_update: self.p.last_update.clone(),
        };
        self.p.log.evals.push(rec.clone());
        Ok(rec)
    }

    /// The whole run's state: agent, replay buffer, generators, in-progress episode (with
    /// `env`'s internal state), and log.
    pub fn save(&self, env: &dyn Env) -> Result<Checkpoint> {
        let mut ckpt = Checkpoint::new();
        self.learner.save(&mut ckpt)?;
        if let Some(r) = &self.replay {
            r.save_to("replay", &mut ckpt)?;
        }
        let mut p = self.p.clone();
        p.env_state = p.obs.as_ref().map(|_| env.state());
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
        self.learner.load(ckpt)?;
        if config != self.config || settings != self.settings {
            return Err(AgentError::Checkpoint(
                "the run's configuration differs from this trainer's".into(),
            ));
        }
        if let Some(r) = &mut self.replay {
            r.load_from("replay", ckpt)?;
        }
        let p: Progress = ckpt.get_json("trainer")?;
        if let Some(state) = &p.env_state {
            env.set_state(state).map_err(env_err)?;
        }
        self.p = p;
        Ok(())
    }
}
