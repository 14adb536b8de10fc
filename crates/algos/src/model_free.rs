//! Model-free training, the loop of `tandem train`: one of the four agents ([`Learner`]) alone
//! on one environment, with periodic deterministic evaluation and a run log, as one
//! checkpointable value ([`ModelFree`]) stepped one environment step at a time by [`drive`].
//! The off-policy agents run the shared [`OffPolicyLoop`] (the same loop every model-based
//! algorithm runs); REINFORCE collects episodes with the same [`EpisodeRunner`].
//!
//! Reproducible by construction: every episode is reset with a seed derived from the run seed and
//! the episode's index, warm-up actions and minibatches come from the loop's own generator, and
//! the agent draws from its own. A checkpoint stores all generators, the replay buffer, the
//! episode in progress and the environment's internal state, so a run saved at any step and
//! resumed continues with exactly the numbers of an uninterrupted one; a stop request therefore
//! saves before it returns, and loses nothing.
//!
//! The loop follows stable-baselines3's off-policy schedule: uniformly random actions for the
//! first `learning_starts` steps, then `gradient_steps` updates every `train_freq` steps once more
//! than `learning_starts` steps were taken; after every environment step (warm-up included) the
//! agent's `on_env_step` runs, as `_on_step` does there. A time-limit truncation is stored as not
//! terminated, so targets bootstrap through it (stable-baselines3's
//! `handle_timeout_termination`). The episode length limit is enforced here as well as
//! by any `TimeLimit` wrapper (so it survives a resume that restores the environment's state).

use serde::{Deserialize, Serialize};
use tandem_agents::{
    evaluate, AlgoConfig, Episode, EpisodeRunner, Learner, Mode, OffPolicyLoop, StepOptions,
    StepRecord,
};
use tandem_core::SeedStream;
use tandem_envs::Env;
use tandem_nn::Checkpoint;

use crate::driver::{drive, Algorithm};
use crate::{AlgoError, Checkpoints, Result};

/// Settings of the loop itself (not of the agent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainSettings {
    /// Evaluate every this many environment steps (0: only at the end).
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
    /// Also checkpoint every this many environment steps (0: only at evaluations). A run killed
    /// at any moment loses at most this many steps (or the evaluation interval, if smaller).
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
        let at_least_one = |name: &str, v: usize| {
            if v >= 1 {
                Ok(())
            } else {
                Err(AlgoError::Config(format!("{name} = {v}: must be >= 1")))
            }
        };
        at_least_one("eval_episodes", self.eval_episodes)?;
        at_least_one("solved_window", self.solved_window)?;
        if let Some(m) = self.max_episode_steps {
            at_least_one("max_episode_steps", m)?;
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

const LOG: &str = "model_free.log";
const STATE: &str = "model_free.state";
const CONFIG: &str = "model_free.config";
const LOOP: &str = "model_free";

impl RunLog {
    /// The log a [`ModelFree`] checkpoint holds (e.g. to write a run's files as it goes).
    pub fn from_checkpoint(ckpt: &Checkpoint) -> Result<Self> {
        Ok(ckpt.get_json(LOG)?)
    }
}

/// What a run reports as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// An environment step was taken: the steps so far.
    Step(u64),
    /// A training episode ended.
    Episode(EpisodeRecord),
    /// An evaluation ran.
    Evaluation(EvalRecord),
}

/// A finished (or restored) run: the agent and what it reported.
#[derive(Debug, Clone)]
pub struct Trained {
    /// The agent.
    pub learner: Learner,
    /// Every episode and evaluation.
    pub log: RunLog,
    /// Environment steps taken (the exact count of real samples used for training).
    pub steps: u64,
    /// Training episodes finished.
    pub episodes: u64,
    /// Gradient updates made.
    pub updates: u64,
}

/// Where a run stands between steps, besides the agent, its loop and the log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct State {
    /// Environment steps (REINFORCE; the off-policy loop counts its own).
    step: u64,
    /// Gradient updates (REINFORCE).
    updates: u64,
    last_update: Vec<(String, f64)>,
    runner: EpisodeRunner,
    /// The environment's internal state, mid-episode.
    env_state: Option<Vec<f64>>,
    /// REINFORCE's episode in progress, and those waiting for an update.
    current: Episode,
    pending: Vec<Episode>,
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

/// A model-free training run as one checkpointable value: the agent (with its replay buffer and
/// generators), the training and evaluation environments, the episode in progress and the log.
pub struct ModelFree {
    core: Core,
    config: AlgoConfig,
    settings: TrainSettings,
    /// The step budget.
    budget: u64,
    seeds: SeedStream,
    env: Box<dyn Env>,
    eval_env: Box<dyn Env>,
    s: State,
    log: RunLog,
}

/// Trains the agent `config` describes on `env` for `steps` environment steps (or
/// `settings.max_episodes`), evaluating it on `eval_env` every `eval_interval` steps and at the
/// end; resumes from the checkpoint `store` holds under the agent's name, if any.
#[allow(clippy::too_many_arguments)]
pub fn train(
    config: AlgoConfig,
    settings: TrainSettings,
    env: Box<dyn Env>,
    eval_env: Box<dyn Env>,
    steps: u64,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained> {
    let run = ModelFree::new(config, settings, env, eval_env, steps, seed)?;
    drive(run, store, on_event)
}

impl ModelFree {
    /// A fresh run of the agent `config` describes, for `steps` environment steps on `env`,
    /// evaluated on `eval_env`.
    pub fn new(
        config: AlgoConfig,
        settings: TrainSettings,
        env: Box<dyn Env>,
        eval_env: Box<dyn Env>,
        steps: u64,
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
            s: State {
                step: 0,
                updates: 0,
                last_update: Vec::new(),
                runner: EpisodeRunner::new(seed, "train-episode-")
                    .with_limit(settings.max_episode_steps),
                env_state: None,
                current: Episode::default(),
                pending: Vec::new(),
            },
            settings,
            budget: steps,
            seeds,
            env,
            eval_env,
            log: RunLog::default(),
        })
    }

    /// Environment steps taken (the exact count of real samples used for training).
    pub fn steps(&self) -> u64 {
        match &self.core {
            Core::OffPolicy(l) => l.counts().real_steps,
            Core::Episodic(_) => self.s.step,
        }
    }

    /// Training episodes finished.
    pub fn episodes(&self) -> u64 {
        self.s.runner.episode()
    }

    /// Gradient updates made.
    pub fn updates(&self) -> u64 {
        match &self.core {
            Core::OffPolicy(l) => l.counts().updates,
            Core::Episodic(_) => self.s.updates,
        }
    }

    /// The run log so far.
    pub fn log(&self) -> &RunLog {
        &self.log
    }

    /// The agent.
    pub fn learner(&mut self) -> &mut Learner {
        match &mut self.core {
            Core::OffPolicy(l) => &mut l.agent,
            Core::Episodic(a) => a,
        }
    }

    fn last_update(&self) -> Vec<(String, f64)> {
        match &self.core {
            Core::OffPolicy(l) => l.last_update().to_vec(),
            Core::Episodic(_) => self.s.last_update.clone(),
        }
    }

    /// One environment step with its episode's and the periodic evaluation's bookkeeping;
    /// whether a checkpoint is due after it (an evaluation ran, or `checkpoint_interval` steps
    /// passed).
    pub(crate) fn advance(&mut self, on_event: &mut dyn FnMut(Event)) -> Result<bool> {
        let rec = match &mut self.core {
            Core::OffPolicy(l) => {
                l.step(&mut *self.env, &mut self.s.runner, StepOptions::real())?
            }
            Core::Episodic(agent) => {
                let obs = self.s.runner.observation(&mut *self.env, agent.agent());
                let action = agent.act(&obs, Mode::Explore)?;
                let rec = self.s.runner.step(&mut *self.env, obs, action, false)?;
                self.s.step += 1;
                agent.agent().on_env_step();
                self.s
                    .current
                    .push(rec.obs.clone(), rec.action.clone(), rec.reward);
                rec
            }
        };
        if rec.done() {
            self.finish_episode(&rec, on_event)?;
        }
        let steps = self.steps();
        on_event(Event::Step(steps));
        let every = |n: u64| n > 0 && steps.is_multiple_of(n);
        let evaluated = every(self.settings.eval_interval);
        if evaluated {
            self.evaluate(on_event)?;
        }
        Ok(evaluated || every(self.settings.checkpoint_interval))
    }

    fn finish_episode(&mut self, rec: &StepRecord, on_event: &mut dyn FnMut(Event)) -> Result<()> {
        let w = self.settings.solved_window;
        let k = self.log.episodes.len();
        let lo = (k + 1).saturating_sub(w);
        let sum = self.log.episodes[lo..].iter().map(|e| e.ret).sum::<f64>() + rec.episode_return;
        let mean = sum / (k + 1 - lo) as f64;
        // The runner has counted this episode already.
        let episode = self.s.runner.episode() - 1;
        let record = EpisodeRecord {
            episode,
            step: self.steps(),
            ret: rec.episode_return,
            length: rec.episode_len,
            ret_window_mean: mean,
        };
        self.log.episodes.push(record.clone());
        on_event(Event::Episode(record));
        if let Some(t) = self.settings.solved_threshold {
            if self.log.solved_at_episode.is_none() && k + 1 >= w && mean >= t {
                self.log.solved_at_episode = Some(episode);
            }
        }
        if let (Core::Episodic(agent), AlgoConfig::Reinforce(c)) = (&mut self.core, &self.config) {
            let mut e = std::mem::take(&mut self.s.current);
            e.terminated = rec.terminated;
            self.s.pending.push(e);
            if self.s.pending.len() >= c.episodes_per_update {
                let m = agent.update_episodes(&self.s.pending)?;
                self.s.updates += 1;
                self.s.last_update = m.0.iter().map(|(k, v)| (k.to_string(), *v)).collect();
                self.s.pending.clear();
            }
        }
        Ok(())
    }

    /// Runs `eval_episodes` deterministic episodes on the evaluation environment (fixed seeds,
    /// the same at every evaluation) and logs them. Draws nothing from the training generators.
    fn evaluate(&mut self, on_event: &mut dyn FnMut(Event)) -> Result<()> {
        let (episodes, limit) = (self.settings.eval_episodes, self.settings.max_episode_steps);
        let seeds = self.seeds;
        let agent = match &mut self.core {
            Core::OffPolicy(l) => l.agent.agent(),
            Core::Episodic(a) => a.agent(),
        };
        let returns = evaluate(agent, &mut *self.eval_env, episodes, &seeds, limit)?;
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
        self.log.evals.push(rec.clone());
        on_event(Event::Evaluation(rec));
        Ok(())
    }
}

impl Algorithm for ModelFree {
    type Event = Event;
    type Record = Trained;
    const SAVES_ON_STOP: bool = true;

    fn id(&self) -> (&str, u64) {
        (self.config.algo().name(), self.seeds.seed())
    }

    fn done(&self) -> bool {
        self.steps() >= self.budget
            || self
                .settings
                .max_episodes
                .is_some_and(|m| self.episodes() >= m)
    }

    /// An environment step; after the last, the final evaluation (unless one just ran).
    fn step(&mut self, on_event: &mut dyn FnMut(Event), _: &dyn Checkpoints) -> Result<bool> {
        let due = self.advance(on_event)?;
        if !self.done() {
            return Ok(due);
        }
        if self.log.evals.last().map(|e| e.step) != Some(self.steps()) {
            self.evaluate(on_event)?;
        }
        Ok(true)
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        match &self.core {
            Core::OffPolicy(l) => {
                l.agent.save(ckpt)?;
                l.save(LOOP, ckpt)?;
            }
            Core::Episodic(a) => a.save(ckpt)?,
        }
        let mut s = self.s.clone();
        s.env_state = s.runner.in_episode().then(|| self.env.state());
        ckpt.put_json(STATE, &s)?;
        ckpt.put_json(LOG, &self.log)?;
        ckpt.put_json(CONFIG, &(&self.config, &self.settings))?;
        Ok(())
    }

    /// Restores a run saved with the same configuration, putting the environment back into the
    /// saved episode. Errors for another algorithm, architecture or configuration.
    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let (config, settings): (AlgoConfig, TrainSettings) = ckpt.get_json(CONFIG)?;
        self.learner().load(ckpt)?;
        if config != self.config || settings != self.settings {
            return Err(AlgoError::Checkpoint(
                "the run's configuration differs from this one's".into(),
            ));
        }
        if let Core::OffPolicy(l) = &mut self.core {
            l.load(LOOP, ckpt)?;
        }
        let s: State = ckpt.get_json(STATE)?;
        if let Some(state) = &s.env_state {
            self.env.set_state(state)?;
        }
        self.s = s;
        self.log = ckpt.get_json(LOG)?;
        Ok(())
    }

    fn finish(self, _wall_seconds: f64) -> Result<Trained> {
        let (steps, episodes, updates) = (self.steps(), self.episodes(), self.updates());
        let learner = match self.core {
            Core::OffPolicy(l) => l.agent,
            Core::Episodic(a) => a,
        };
        Ok(Trained {
            learner,
            log: self.log,
            steps,
            episodes,
            updates,
        })
    }
}

#[cfg(test)]
#[path = "model_free_tests.rs"]
mod tests;
