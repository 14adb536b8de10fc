//! Paper p2 (Manglik and Tripathi): a model-free agent trained on real episodes alternated with
//! episodes imagined by a learned model of `(s', r, done)` (Sec. 3.1.2, Fig. 3).
//!
//! The loop of Fig. 3, generic over the episodic agent (any [`EpisodicAgent`]; REINFORCE in the
//! paper), the [`Task`] and the real system (any [`Env`], counted by a [`SampleCounter`]):
//!
//! 1. the first [`P2Config::real_only_episodes`] episodes (p2: N = 100) are real only: the agent
//!    updates after each, and the model ([`MlpModel`], p2 eq. 1) is refit on the real
//!    transitions as they come ([`P2Config::fit_every`]);
//! 2. after that, every [`P2Config::real_per_cycle`] real episodes are followed by
//!    [`P2Config::imagined_per_cycle`] imagined ones: a [`ModelEnv`] whose reward and termination
//!    are the model's own ([`Judges::model`]), each started from a start state of a real episode
//!    (drawn uniformly from those seen so far).
//!
//! [`Method::ModelFree`] runs step 1 forever (no model at all): the baseline. Real episodes are
//! counted exactly; imagined ones cost no real sample. A run stops when the mean return of the
//! last [`P2Config::solved_window`] real episodes reaches [`P2Config::solved_return`] (p2 states
//! no definition; for CartPole-v1 we take gymnasium's reward threshold, 475 over 100 episodes),
//! or after [`P2Config::max_real_episodes`].
//!
//! Everything random derives from the run's seed: real episode `k` resets with the seed derived
//! from `"real-episode-{k}"` in both methods (the two methods meet the same start states), the
//! agent from `"agent"`, fit `j` from `"fit-{j}"`, the start of imagined episode `i` from
//! `"imagined-{i}"`. A run saves itself under its method's name every
//! [`P2Config::checkpoint_every`] real episodes (between episodes) and resumes from there with
//! exactly the numbers of an uninterrupted run.

use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_agents::{Agent, Episode, EpisodicAgent, Mode, Reinforce, ReinforceConfig, Resumable};
use tandem_core::SeedStream;
use tandem_envs::{Env, EnvError, SampleCount, SampleCounter, Task};
use tandem_models::{
    DynamicsModel, FitConfig, Judges, MlpModel, MlpModelConfig, ModelEnv, Transitions,
    TransitionsBuilder,
};
use tandem_nn::{Checkpoint, Checkpointable};

pub use super::{AlgoError, Checkpoints, Ephemeral, Result};
use crate::driver::{drive, Algorithm};
use tandem_nn::budget::MemoryEstimate;

/// The two methods of p2's comparison (Fig. 6, the table of Sec. 4.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Real episodes only.
    ModelFree,
    /// Real episodes alternated with episodes imagined by the learned model.
    WithModel,
}

impl Method {
    /// Both, model-free first.
    pub const ALL: [Method; 2] = [Method::ModelFree, Method::WithModel];

    /// `"model_free"` or `"with_model"`.
    pub fn name(self) -> &'static str {
        match self {
            Method::ModelFree => "model_free",
            Method::WithModel => "with_model",
        }
    }
}

/// Settings of a p2 run. `Default` follows p2 where it gives a figure (cited per field) and says
/// where a figure is ours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct P2Config {
    /// The agent (p2 §3.1.2: one hidden layer of 8 units, softmax over the actions, an update
    /// after each episode).
    pub reinforce: ReinforceConfig,
    /// The dynamics model (p2 §3.1: 2×256, SGD 0.01, eq. 1).
    pub model: MlpModelConfig,
    /// Real episodes before the first imagined one (p2: N = 100).
    pub real_only_episodes: u64,
    /// Real episodes per cycle after the first N (p2 alternates: 1).
    pub real_per_cycle: u64,
    /// Imagined episodes per cycle after the first N (p2 alternates: 1).
    pub imagined_per_cycle: u64,
    /// Refit the model after every this many real episodes (p2 trains it on each episode's
    /// transitions: 1).
    pub fit_every: u64,
    /// Each refit: `fit.epochs` passes over at most `fit_rows` real transitions drawn uniformly
    /// from all so far (0: all of them). Ours: bounds the cost of a refit as the data grow.
    pub fit_rows: usize,
    /// Passes, minibatch size and held-out fraction of each refit (ours: 5 passes of
    /// minibatches of 32, no holdout; measured over CartPole seeds 0-9, 1, 3 and 5 passes gave
    /// the model method 400, 375 and 360 mean real episodes to solve: the better the model, the
    /// fewer real episodes).
    pub fit: FitConfig,
    /// Reward and termination of imagined transitions (p2: the model's own, terminal at a
    /// predicted probability of 0.5).
    pub judges: Judges,
    /// The run ends after this many real episodes if not solved before.
    pub max_real_episodes: u64,
    /// "Solved": the mean return of the last `solved_window` real episodes reaches this (p2
    /// gives no definition; gymnasium's CartPole-v1 threshold 475).
    pub solved_return: f64,
    /// The window of that mean (gymnasium's 100 consecutive episodes).
    pub solved_window: usize,
    /// Save a checkpoint every this many real episodes.
    pub checkpoint_every: u64,
}

impl Default for P2Config {
    fn default() -> Self {
        Self {
            reinforce: ReinforceConfig::default(),
            model: MlpModelConfig::default(),
            real_only_episodes: 100,
            real_per_cycle: 1,
            imagined_per_cycle: 1,
            fit_every: 1,
            fit_rows: 2048,
            fit: FitConfig {
                epochs: 5,
                batch_size: 32,
                holdout_fraction: 0.0,
                seed: 0,
                early_stop: None,
            },
            judges: Judges::model(),
            max_real_episodes: 2000,
            solved_return: 475.0,
            solved_window: 100,
            checkpoint_every: 50,
        }
    }
}

impl P2Config {
    /// Checks the ranges the loop relies on.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(AlgoError::Config(m.to_string()));
        check_schedule(
            [self.real_per_cycle, self.fit_every, self.checkpoint_every],
            self.max_real_episodes,
            self.solved_window,
            self.solved_return,
        )?;
        if self.fit.epochs == 0 || self.fit.batch_size == 0 {
            return bad("fit.epochs and fit.batch_size must be >= 1");
        }
        if !(0.0..1.0).contains(&self.fit.holdout_fraction) {
            return bad("fit.holdout_fraction must lie in [0, 1)");
        }
        if !(self.judges.terminal_threshold > 0.0 && self.judges.terminal_threshold <= 1.0) {
            return bad("judges.terminal_threshold must lie in (0, 1]");
        }
        self.fit.validate()?;
        self.model.validate()?;
        self.reinforce.validate()?;
        Ok(())
    }

    /// The memory of a run on `obs_dim`-dimensional states with `n_actions` actions: the agent,
    /// the model with its optimizer state, and the real transitions of `max_real_episodes`
    /// episodes of up to `episode_steps` steps (`f64`).
    pub fn memory(&self, obs_dim: usize, n_actions: usize, episode_steps: usize) -> MemoryEstimate {
        let steps = usize::try_from(self.max_real_episodes)
            .unwrap_or(usize::MAX)
            .saturating_mul(episode_steps);
        MemoryEstimate::new()
            .with("reinforce.", self.reinforce.memory(obs_dim, n_actions))
            .with("", self.model.memory(obs_dim, 1, self.fit.batch_size))
            .f32s(
                "real transitions (max_real_episodes x episode steps)",
                &[2, steps, obs_dim.saturating_mul(2).saturating_add(3)],
            )
    }
}

/// The checks both p2 loops' schedules need: `[real_per_cycle, fit_every, checkpoint_every]`
/// and the stop (`max_real_episodes`, `solved_window`, `solved_return`).
pub(super) fn check_schedule(
    periods: [u64; 3],
    max_real_episodes: u64,
    solved_window: usize,
    solved_return: f64,
) -> Result<()> {
    let bad = |m: &str| Err(AlgoError::Config(m.to_string()));
    if periods.contains(&0) {
        return bad("real_per_cycle, fit_every and checkpoint_every must be >= 1");
    }
    if max_real_episodes == 0 || solved_window == 0 {
        return bad("max_real_episodes and solved_window must be >= 1");
    }
    if !solved_return.is_finite() {
        return bad("solved_return must be finite");
    }
    Ok(())
}

/// What a run reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The method.
    pub method: Method,
    /// The seed.
    pub seed: u64,
    /// The return of every real training episode, in order: the learning curve against real
    /// episodes.
    pub real_returns: Vec<f64>,
    /// Real samples (steps of the real system), counted by the [`SampleCounter`].
    pub real_samples: u64,
    /// Imagined episodes the agent learned from.
    pub imagined_episodes: u64,
    /// Steps of those imagined episodes.
    pub imagined_steps: u64,
    /// Real episodes when the run was solved (the windowed mean reached the target), if it was.
    pub solved_at: Option<u64>,
    /// Last training loss of each model refit.
    pub fit_losses: Vec<f64>,
    /// Wall time of the run, seconds (of the last process, for a resumed run).
    pub wall_seconds: f64,
}

impl std::fmt::Display for RunRecord {
    /// When the run was solved, and with how many imagined episodes.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let imagined = self.imagined_episodes;
        match self.solved_at {
            Some(k) => write!(f, "solved after {k} real episodes ({imagined} imagined)"),
            None => write!(f, "not solved in {} real episodes", self.real_returns.len()),
        }
    }
}

/// The first episode count `k` (≥ `window`) at which the mean of `returns[k - window..k]`
/// reaches `target`.
pub fn solved_at(returns: &[f64], window: usize, target: f64) -> Option<u64> {
    if window == 0 || returns.len() < window {
        return None;
    }
    let mut sum: f64 = returns[..window].iter().sum();
    for k in window..=returns.len() {
        if k > window {
            sum += returns[k - 1] - returns[k - 1 - window];
        }
        if sum / window as f64 >= target {
            return Some(k as u64);
        }
    }
    None
}

/// What both p2 loops count between episodes and report in their [`RunRecord`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct Tally {
    pub(super) method: Method,
    pub(super) seed: u64,
    pub(super) real_returns: Vec<f64>,
    pub(super) real_samples: u64,
    pub(super) imagined_episodes: u64,
    pub(super) imagined_steps: u64,
    pub(super) fit_losses: Vec<f64>,
}

impl Tally {
    /// Nothing done yet.
    pub(super) fn new(method: Method, seed: u64) -> Self {
        Self {
            method,
            seed,
            real_returns: Vec::new(),
            real_samples: 0,
            imagined_episodes: 0,
            imagined_steps: 0,
            fit_losses: Vec::new(),
        }
    }

    /// The method's name and the seed: the run's identity for [`drive`].
    pub(super) fn id(&self) -> (&str, u64) {
        (self.method.name(), self.seed)
    }

    /// Counts a real episode of return `ret` that ended with `real_samples` samples so far.
    pub(super) fn real(&mut self, ret: f64, real_samples: u64, window: usize) -> Event {
        self.real_returns.push(ret);
        self.real_samples = real_samples;
        let last = &self.real_returns[self.real_returns.len().saturating_sub(window)..];
        Event::Real {
            episode: self.real_returns.len() as u64 - 1,
            ret,
            real_samples,
            window_mean: last.iter().sum::<f64>() / last.len() as f64,
        }
    }

    /// The real episode at which the run was solved ([`solved_at`]), if it was.
    pub(super) fn solved_at(&self, window: usize, target: f64) -> Option<u64> {
        solved_at(&self.real_returns, window, target)
    }

    /// Whether the run is over: solved, or `max_episodes` real episodes played.
    pub(super) fn over(&self, max_episodes: u64, window: usize, target: f64) -> bool {
        self.real_returns.len() as u64 >= max_episodes || self.solved_at(window, target).is_some()
    }

    /// The record of a run that ended here, solved as `solved_at` says, after `wall_seconds`.
    pub(super) fn record(self, solved_at: Option<u64>, wall_seconds: f64) -> RunRecord {
        RunRecord {
            method: self.method,
            seed: self.seed,
            solved_at,
            real_returns: self.real_returns,
            real_samples: self.real_samples,
            imagined_episodes: self.imagined_episodes,
            imagined_steps: self.imagined_steps,
            fit_losses: self.fit_losses,
            wall_seconds,
        }
    }
}

/// What the loop reports as it goes (progress bars; tests follow the schedule with it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// Real episode `episode` (0-based) ended with return `ret`; `real_samples` so far.
    Real {
        /// Its index among the real episodes.
        episode: u64,
        /// Its undiscounted return.
        ret: f64,
        /// Real samples after it.
        real_samples: u64,
        /// The mean return of the last `solved_window` real episodes (all of them, while there
        /// are fewer), this one included: what "solved" is judged by.
        window_mean: f64,
    },
    /// An imagined episode ended after `steps` steps with return `ret`.
    Imagined {
        /// Its index among the imagined episodes.
        episode: u64,
        /// Its steps.
        steps: u64,
        /// Its return (the model's rewards).
        ret: f64,
    },
}

/// Plays one episode of `agent` (exploring) on `env` from observation `obs` (just after a reset
/// or [`Env::set_state`]), until termination, truncation or the environment's step limit. With
/// `record`, the transitions go there in the task's canonical coordinates (states read from
/// `env.state()`), the model's training data.
pub fn play<T: Task + ?Sized>(
    env: &mut dyn Env,
    agent: &mut dyn Agent,
    mut obs: Vec<f64>,
    mut record: Option<(&T, &mut TransitionsBuilder)>,
) -> Result<Episode> {
    let limit = env.max_episode_steps();
    agent.reset_episode();
    let mut ep = Episode::default();
    loop {
        let action = agent.act(&obs, Mode::Explore)?;
        let before = record.as_ref().map(|_| env.state());
        let st = env.step(&action)?;
        let cut = limit.is_some_and(|m| ep.len() + 1 >= m);
        let done = st.terminated || st.truncated || cut;
        if let (Some((task, b)), Some(x)) = (record.as_mut(), before) {
            let u = task.control(&action);
            b.push_canonical(*task, &x, &u, &env.state(), st.reward, st.terminated, done)?;
        }
        ep.push(obs, action, st.reward);
        if done {
            ep.terminated = st.terminated;
            return Ok(ep);
        }
        obs = st.observation;
    }
}

/// Where a run stands between episodes, besides the agent, the model and the real transitions
/// (stored beside it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Progress {
    t: Tally,
    /// Start states of the real episodes so far (where imagined episodes start).
    starts: Vec<Vec<f64>>,
    /// Episodes waiting for the next update (`reinforce.episodes_per_update > 1`).
    pending: Vec<Episode>,
}

const PROGRESS: &str = "p2.progress";
const MODEL: &str = "p2.model";
const REAL: &str = "p2.real_transitions";

/// Runs `method` for `seed` from a fresh `agent` (or from the checkpoint `store` holds under the
/// method's name) and returns its record. `real_env` builds the real system (with its episode
/// limit); `on_event` hears of every finished episode.
#[allow(clippy::too_many_arguments)]
pub fn run<A, T, F>(
    method: Method,
    cfg: &P2Config,
    task: &T,
    real_env: F,
    agent: A,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    A: EpisodicAgent + Resumable,
    T: Task + Clone,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    let run = ImaginedEpisodes::new(method, cfg, task, real_env, agent, seed)?;
    drive(run, store, on_event)
}

/// One run of p2's loop (Fig. 3) as one checkpointable value, stepped one real episode at a time
/// by [`drive`]: the agent, the model environment and the real transitions it is fitted on, the
/// start states, the episodes waiting for an update and the counts.
pub struct ImaginedEpisodes<'a, A, T, F> {
    cfg: &'a P2Config,
    task: &'a T,
    real_env: F,
    agent: A,
    seeds: SeedStream,
    /// Width of the plant input of the task's actions.
    control_dim: usize,
    model_env: Option<ModelEnv<MlpModel, T>>,
    real: Option<Transitions>,
    p: Progress,
    env: SampleCounter<Box<dyn Env>>,
    count: SampleCount,
}

impl<'a, A, T, F> ImaginedEpisodes<'a, A, T, F>
where
    A: EpisodicAgent + Resumable,
    T: Task + Clone,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    /// A fresh run of `method` for `seed` from `agent`; `real_env` builds the real system (with
    /// its episode limit).
    pub fn new(
        method: Method,
        cfg: &'a P2Config,
        task: &'a T,
        real_env: F,
        agent: A,
        seed: u64,
    ) -> Result<Self> {
        cfg.validate()?;
        let control_dim = task.control(&probe_action(task)).len();
        let model_env = match method {
            Method::WithModel => {
                let model = MlpModel::new(task.state_dim(), control_dim, cfg.model.clone())?;
                Some(ModelEnv::with_judges(model, task.clone(), cfg.judges)?)
            }
            Method::ModelFree => None,
        };
        let (env, count) = SampleCounter::new(real_env()?);
        Ok(Self {
            cfg,
            task,
            real_env,
            agent,
            seeds: SeedStream::new(seed),
            control_dim,
            model_env,
            real: None,
            p: Progress {
                t: Tally::new(method, seed),
                starts: Vec::new(),
                pending: Vec::new(),
            },
            env,
            count,
        })
    }

    /// Adds `ep` to the episodes waiting for an update, and updates once there are enough.
    fn learn(&mut self, ep: Episode) -> Result<()> {
        self.p.pending.push(ep);
        if self.p.pending.len() >= self.cfg.reinforce.episodes_per_update {
            self.agent.update(&self.p.pending)?;
            self.p.pending.clear();
        }
        Ok(())
    }

    /// Fit `j` of the model, on (a draw of) all real transitions so far.
    fn fit(&mut self, j: u64) -> Result<()> {
        let (Some(menv), Some(all)) = (self.model_env.as_mut(), self.real.as_ref()) else {
            return Ok(());
        };
        let cfg = self.cfg;
        let mut rng = self.seeds.rng(&format!("fit-{j}"));
        let data = if cfg.fit_rows > 0 && all.len() > cfg.fit_rows {
            let idx: Vec<usize> = (0..cfg.fit_rows)
                .map(|_| rng.random_range(0..all.len()))
                .collect();
            all.select(&idx)
        } else {
            all.clone()
        };
        let fit = FitConfig {
            seed: self.seeds.derive(&format!("fit-{j}")),
            ..cfg.fit.clone()
        };
        let report = menv.model_mut().fit(&data, &fit)?;
        let loss = report.train_loss.last().copied().unwrap_or(f64::NAN);
        self.p.t.fit_losses.push(loss);
        Ok(())
    }

    /// One imagined episode from a real start state, learned from like a real one.
    fn imagined_episode(&mut self, on_event: &mut dyn FnMut(Event)) -> Result<()> {
        let Some(menv) = self.model_env.as_mut() else {
            return Ok(());
        };
        let i = self.p.t.imagined_episodes;
        let mut rng = self.seeds.rng(&format!("imagined-{i}"));
        let start = &self.p.starts[rng.random_range(0..self.p.starts.len())];
        let obs = menv.set_state(start)?;
        let ep = play::<T>(menv, &mut self.agent, obs, None)?;
        self.p.t.imagined_episodes += 1;
        self.p.t.imagined_steps += ep.len() as u64;
        on_event(Event::Imagined {
            episode: i,
            steps: ep.len() as u64,
            ret: ep.total_reward(),
        });
        self.learn(ep)
    }
}

impl<A, T, F> Algorithm for ImaginedEpisodes<'_, A, T, F>
where
    A: EpisodicAgent + Resumable,
    T: Task + Clone,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    type Event = Event;
    type Record = RunRecord;

    fn id(&self) -> (&str, u64) {
        self.p.t.id()
    }

    fn done(&self) -> bool {
        let cfg = self.cfg;
        let (max, window) = (cfg.max_real_episodes, cfg.solved_window);
        self.p.t.over(max, window, cfg.solved_return)
    }

    fn step(&mut self, on_event: &mut dyn FnMut(Event), stop: &dyn Checkpoints) -> Result<bool> {
        let (cfg, task) = (self.cfg, self.task);
        // One real episode; with a model, its transitions join the model's data.
        let k = self.p.t.real_returns.len() as u64;
        let seed = self.seeds.derive(&format!("real-episode-{k}"));
        let obs = self.env.reset(Some(seed));
        self.p.starts.push(self.env.state());
        let mut b = TransitionsBuilder::new(task.state_dim(), self.control_dim);
        let rec = self.model_env.is_some().then_some((task, &mut b));
        let ep = play(&mut self.env, &mut self.agent, obs, rec)?;
        let real = self
            .p
            .t
            .real(ep.total_reward(), self.count.get(), cfg.solved_window);
        on_event(real);
        self.learn(ep)?;
        let done_real = k + 1;
        if self.model_env.is_some() {
            let new = b.build();
            match self.real.as_mut() {
                Some(all) => all.extend(&new)?,
                None => self.real = Some(new),
            }
            if done_real.is_multiple_of(cfg.fit_every) {
                self.fit(done_real / cfg.fit_every)?;
            }
            // Imagined episodes, once the first N real ones are done, after each cycle.
            let after_n = done_real.checked_sub(cfg.real_only_episodes);
            if after_n.is_some_and(|n| n > 0 && n % cfg.real_per_cycle == 0) {
                for _ in 0..cfg.imagined_per_cycle {
                    // A cycle may hold many imagined episodes: stop between them (the run
                    // resumes from its last checkpoint).
                    if stop.stop_requested() {
                        return Err(AlgoError::Stopped);
                    }
                    self.imagined_episode(on_event)?;
                }
            }
        }
        Ok(done_real.is_multiple_of(cfg.checkpoint_every))
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        self.agent.save(ckpt)?;
        ckpt.put_json(PROGRESS, &self.p)?;
        if let Some(m) = self.model_env.as_ref() {
            m.model().save_to(MODEL, ckpt)?;
        }
        if let Some(t) = self.real.as_ref() {
            t.save_to(REAL, ckpt)?;
        }
        Ok(())
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        self.p = ckpt.get_json(PROGRESS)?;
        self.agent.load(ckpt)?;
        if let Some(m) = self.model_env.as_mut() {
            m.model_mut().load_from(MODEL, ckpt)?;
            if ckpt.contains(&format!("{REAL}.rewards")) {
                let mut t = Transitions::default();
                t.load_from(REAL, ckpt)?;
                self.real = Some(t);
            }
        }
        (self.env, self.count) =
            SampleCounter::starting_at((self.real_env)()?, self.p.t.real_samples);
        Ok(())
    }

    fn finish(self, wall_seconds: f64) -> Result<RunRecord> {
        let solved_at = self
            .p
            .t
            .solved_at(self.cfg.solved_window, self.cfg.solved_return);
        Ok(self.p.t.record(solved_at, wall_seconds))
    }
}

/// An action of `task`'s action space (to learn the width of its plant input).
fn probe_action<T: Task + ?Sized>(task: &T) -> tandem_core::Action {
    match task.action_space() {
        tandem_core::Space::Discrete { .. } => tandem_core::Action::Discrete(0),
        tandem_core::Space::Box { low, .. } => {
            tandem_core::Action::Continuous(vec![0.0; low.len()])
        }
    }
}

/// p2's REINFORCE agent for `task` (`cfg.reinforce`), seeded from the run's seed: the same
/// initial policy for both methods.
pub fn reinforce_agent<T: Task>(
    cfg: &P2Config,
    task: &T,
    seed: u64,
) -> std::result::Result<Reinforce, tandem_agents::AgentError> {
    Reinforce::new(
        cfg.reinforce.clone(),
        task.observation_space(),
        task.action_space(),
        SeedStream::new(seed).derive("agent"),
    )
}

/// p2's CartPole experiment for one method and seed: REINFORCE on gymnasium's `CartPole-v1`
/// (500-step limit), with [`run`]'s checkpoints and events.
pub fn cartpole(
    method: Method,
    cfg: &P2Config,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord> {
    let task = tandem_envs::CartPoleTask::default();
    let agent = reinforce_agent(cfg, &task, seed)?;
    let make = || tandem_envs::make(tandem_envs::CartPoleEnv::ID);
    run(method, cfg, &task, make, agent, seed, store, on_event)
}
