//! The one off-policy loop every pipeline runs: [`OffPolicyLoop`] over any [`OffPolicyAgent`],
//! with episodes kept by [`EpisodeRunner`].
//!
//! A loop holds the agent, its replay (a primary buffer and optionally a second one mixed into
//! every minibatch at a set fraction: MBPO's `D_env`/`D_model` with its real ratio, p3's
//! `D_ENV ∪ D_MPC`), the minibatch generator and the counters. Callers compose it:
//!
//! - [`OffPolicyLoop::step`]/[`OffPolicyLoop::train`]: exploring steps on any environment (real
//!   or imagined, [`StepOptions`] says which and where the transition goes), with the
//!   [`OffPolicySchedule`]'s updates after each;
//! - [`OffPolicyLoop::push`]: transitions produced elsewhere (branched model rollouts);
//! - [`OffPolicyLoop::update`]: gradient steps on mixed minibatches, when the caller's schedule
//!   (G updates per real step) is not the environment-step schedule;
//! - [`evaluate`]: deterministic episodes that touch no training generator.
//!
//! Counting is exact: real and model steps are counted separately ([`LoopCounts`]); only
//! [`Source::Real`] steps are real samples. The schedule is stable-baselines3's: with
//! `random_warmup`, uniformly random actions until the primary buffer holds `learning_starts`
//! transitions; `gradient_steps` updates every `train_freq` learning steps once it holds more
//! than `learning_starts`; a time-limit truncation is stored as not terminated.
//!
//! ```
//! use tandem_agents::{evaluate, EpisodeRunner, OffPolicyLoop, Sac, SacConfig, StepOptions};
//! use tandem_core::SeedStream;
//!
//! let mut env = tandem_envs::make("Pendulum-v1").unwrap();
//! let cfg = SacConfig { hidden: vec![16, 16], learning_starts: 50, batch_size: 32, ..SacConfig::default() };
//! let seeds = SeedStream::new(0);
//! let agent = Sac::new(cfg.clone(), env.observation_space(), env.action_space(), 1).unwrap();
//! let mut lp = OffPolicyLoop::new(agent, cfg.schedule(), env.observation_space(),
//!     env.action_space(), seeds.rng("minibatches")).unwrap();
//! let mut runner = EpisodeRunner::new(seeds.derive("episodes"), "train-episode-");
//! lp.train(&mut env, &mut runner, 100, StepOptions::real(), &mut |_| {}).unwrap();
//! assert_eq!(lp.counts().real_steps, 100);
//! assert_eq!(lp.counts().updates, 50); // after the 50 warm-up steps, one per step
//! let returns = evaluate(&mut lp.agent, &mut env, 1, &seeds, None).unwrap();
//! assert!(returns[0] < 0.0);
//! ```

use std::borrow::Cow;

use ndarray::{ArrayView1, ArrayView2};
use serde::{Deserialize, Serialize};
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_envs::Env;
use tandem_nn::Checkpoint;

use crate::agent::{action_row, Agent, Batch, Mode, OffPolicyAgent};
use crate::config::OffPolicySchedule;
use crate::ddpg::random_action;
use crate::error::{AgentError, Result};
use crate::replay::{MixedSampler, ReplayBuffer, TransitionRef};

pub(crate) fn env_err(e: tandem_envs::EnvError) -> AgentError {
    AgentError::Env(e.to_string())
}

/// Whether a step's transition is a real sample or an imagined one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Source {
    /// A sample of the real (true) system: counted in [`LoopCounts::real_steps`].
    Real,
    /// A step of a simulator or learned model: counted in [`LoopCounts::model_steps`].
    Model,
}

/// Which replay buffer a transition goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Store {
    /// The primary buffer (learning starts once it holds `learning_starts` transitions).
    Primary,
    /// The secondary buffer ([`OffPolicyLoop::with_secondary`]).
    Secondary,
    /// Nowhere (collecting data for a model, not for the agent).
    Nowhere,
}

/// What one step does besides acting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepOptions {
    /// How the step is counted.
    pub source: Source,
    /// Where its transition goes.
    pub store: Store,
    /// Run the schedule's updates after it.
    pub learn: bool,
    /// Record the environment's internal state before and after ([`StepRecord::states`]).
    pub record_states: bool,
}

impl StepOptions {
    /// A real step, stored in the primary buffer, with updates.
    pub fn real() -> Self {
        Self {
            source: Source::Real,
            store: Store::Primary,
            learn: true,
            record_states: false,
        }
    }

    /// A simulated step, stored in the primary buffer, with updates (p0's retraining on the
    /// model environment).
    pub fn model() -> Self {
        Self {
            source: Source::Model,
            ..Self::real()
        }
    }

    /// A real step that only collects: nothing stored or learned, internal states recorded
    /// (data for a dynamics model).
    pub fn collect() -> Self {
        Self {
            source: Source::Real,
            store: Store::Nowhere,
            learn: false,
            record_states: true,
        }
    }
}

impl StepOptions {
    /// The same step, recording the environment's internal state before and after.
    pub fn recording_states(mut self) -> Self {
        self.record_states = true;
        self
    }

    /// The same step without the schedule's updates (the caller updates: G per real step).
    pub fn without_updates(mut self) -> Self {
        self.learn = false;
        self
    }
}

/// One step taken.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRecord {
    /// The observation acted on.
    pub obs: Vec<f64>,
    /// The action taken.
    pub action: Action,
    /// The action as stored (`f32` precision; the index for a discrete action).
    pub action_row: Vec<f64>,
    /// The reward.
    pub reward: f64,
    /// The next observation.
    pub next_obs: Vec<f64>,
    /// The next state is terminal.
    pub terminated: bool,
    /// The episode was cut short (by the environment or the runner's limit).
    pub truncated: bool,
    /// The environment's internal state before and after, when asked for.
    pub states: Option<(Vec<f64>, Vec<f64>)>,
    /// Return of the episode so far, this step included.
    pub episode_return: f64,
    /// Steps of the episode so far, this step included.
    pub episode_len: usize,
}

impl StepRecord {
    /// The episode ended with this step.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// One episode in progress on one environment: seeded resets, the running return and length,
/// and the episode limit. Serializable, so a run saved mid-episode
/// resumes with the same numbers (the environment's own state is saved by the caller).
///
/// Episode `k` starts with `env.reset(Some(seed))` for the seed `SeedStream::new(seed)` derives
/// from `"{prefix}{k}"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRunner {
    seed: u64,
    prefix: String,
    limit: Option<usize>,
    obs: Option<Vec<f64>>,
    episode: u64,
    ep_return: f64,
    ep_len: usize,
}

impl EpisodeRunner {
    /// No episode started yet.
    pub fn new(seed: u64, prefix: &str) -> Self {
        Self {
            seed,
            prefix: prefix.to_string(),
            limit: None,
            obs: None,
            episode: 0,
            ep_return: 0.0,
            ep_len: 0,
        }
    }

    /// Episodes end after `limit` steps; `None` (the default) takes the environment's
    /// [`Env::max_episode_steps`].
    pub fn with_limit(mut self, limit: Option<usize>) -> Self {
        self.limit = limit;
        self
    }

    /// Index of the episode running (or the next to start): episodes finished so far.
    pub fn episode(&self) -> u64 {
        self.episode
    }

    /// Whether an episode is in progress.
    pub fn in_episode(&self) -> bool {
        self.obs.is_some()
    }

    /// Ends the episode in progress without a step (the next step starts a new one).
    pub fn abandon(&mut self) {
        self.obs = None;
    }

    /// The observation to act on, starting episode [`EpisodeRunner::episode`] (seeded reset,
    /// `agent.reset_episode()`) if none is in progress.
    pub fn observation(&mut self, env: &mut dyn Env, agent: &mut dyn Agent) -> Vec<f64> {
        if let Some(o) = self.obs.take() {
            return o;
        }
        let seed = SeedStream::new(self.seed).derive(&format!("{}{}", self.prefix, self.episode));
        let o = env.reset(Some(seed));
        agent.reset_episode();
        self.ep_return = 0.0;
        self.ep_len = 0;
        o
    }

    /// Applies `action` (chosen for `obs`, from [`EpisodeRunner::observation`]) to `env` and
    /// advances the episode.
    pub fn step(
        &mut self,
        env: &mut dyn Env,
        obs: Vec<f64>,
        action: Action,
        record_states: bool,
    ) -> Result<StepRecord> {
        let before = record_states.then(|| env.state());
        let st = env.step(&action).map_err(env_err)?;
        let states = before.map(|b| (b, env.state()));
        self.ep_len += 1;
        self.ep_return += st.reward;
        let limit = self.limit.or(env.max_episode_steps());
        let truncated = st.truncated || limit.is_some_and(|m| self.ep_len >= m);
        let mut row = vec![0.0f32; env.action_space().flat_dim()];
        action_row(&action, &mut row);
        let action_row: Vec<f64> = row.iter().map(|v| f64::from(*v)).collect();
        let done = st.terminated || truncated;
        if done {
            self.episode += 1;
        } else {
            self.obs = Some(st.observation.clone());
        }
        Ok(StepRecord {
            obs,
            action,
            action_row,
            reward: st.reward,
            next_obs: st.observation,
            terminated: st.terminated,
            truncated,
            states,
            episode_return: self.ep_return,
            episode_len: self.ep_len,
        })
    }
}

/// Steps and updates of a loop so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoopCounts {
    /// Steps of the real system (exact: the figure papers report).
    pub real_steps: u64,
    /// Steps of simulators and models.
    pub model_steps: u64,
    /// Steps after which the schedule may update (the `train_freq` clock).
    pub learn_steps: u64,
    /// Transitions pushed into the primary buffer since it was last cleared.
    pub primary_pushed: u64,
    /// Gradient updates.
    pub updates: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct LoopState {
    counts: LoopCounts,
    rng: Rng,
    last_update: Vec<(String, f64)>,
    random_warmup: bool,
    schedule: OffPolicySchedule,
    secondary: Option<MixedSampler>,
}

/// An off-policy agent in training: replay, minibatches, schedule and counters.
#[derive(Debug, Clone)]
pub struct OffPolicyLoop<A> {
    /// The agent.
    pub agent: A,
    act_space: Space,
    primary: ReplayBuffer,
    secondary: Option<(ReplayBuffer, MixedSampler)>,
    batch: Batch,
    s: LoopState,
}

impl<A: OffPolicyAgent> OffPolicyLoop<A> {
    /// `agent` with an empty primary buffer of `schedule.buffer_size` transitions, uniformly
    /// random warm-up actions (stable-baselines3), and minibatches drawn from `rng`.
    pub fn new(
        agent: A,
        schedule: OffPolicySchedule,
        obs_space: &Space,
        act_space: &Space,
        rng: Rng,
    ) -> Result<Self> {
        schedule.validate()?;
        let (od, ad) = (obs_space.flat_dim(), act_space.flat_dim());
        Ok(Self {
            agent,
            act_space: act_space.clone(),
            primary: ReplayBuffer::new(schedule.buffer_size, od, ad)?,
            secondary: None,
            batch: Batch::zeros(schedule.batch_size, od, ad),
            s: LoopState {
                counts: LoopCounts::default(),
                rng,
                last_update: Vec::new(),
                random_warmup: true,
                schedule,
                secondary: None,
            },
        })
    }

    /// Acts with the agent from the first step (no random warm-up actions).
    pub fn without_random_warmup(mut self) -> Self {
        self.s.random_warmup = false;
        self
    }

    /// Adds a secondary buffer of `capacity` transitions; minibatches then draw
    /// `primary_fraction` of their rows from the primary buffer and the rest from the secondary
    /// (all from one when the other is empty), as [`MixedSampler`] does.
    pub fn with_secondary(mut self, capacity: usize, primary_fraction: f64) -> Result<Self> {
        let mix = MixedSampler::new(primary_fraction)?;
        let buf = ReplayBuffer::new(capacity, self.primary.obs_dim(), self.primary.act_dim())?;
        self.secondary = Some((buf, mix));
        self.s.secondary = Some(mix);
        Ok(self)
    }

    /// Changes the secondary buffer's capacity, keeping its newest transitions
    /// ([`ReplayBuffer::resized`]); an error without a secondary buffer.
    pub fn resize_secondary(&mut self, capacity: usize) -> Result<()> {
        match &mut self.secondary {
            Some((b, _)) => {
                if b.capacity() != capacity {
                    *b = b.resized(capacity)?;
                }
                Ok(())
            }
            None => Err(AgentError::Config {
                field: "store",
                value: "secondary".into(),
                reason: "this loop has no secondary buffer (with_secondary)",
            }),
        }
    }

    /// Steps and updates so far.
    pub fn counts(&self) -> LoopCounts {
        self.s.counts
    }

    /// The schedule.
    pub fn schedule(&self) -> &OffPolicySchedule {
        &self.s.schedule
    }

    /// Updates start once the primary buffer holds more than `n` transitions from now on (the
    /// schedule's warm-up suits a fresh agent; a trained one moved to a new system may need
    /// none). A saved loop restores only into a loop with the same setting.
    pub fn set_learning_starts(&mut self, n: usize) {
        self.s.schedule.learning_starts = n;
    }

    /// The primary buffer.
    pub fn primary(&self) -> &ReplayBuffer {
        &self.primary
    }

    /// The secondary buffer, if any.
    pub fn secondary(&self) -> Option<&ReplayBuffer> {
        self.secondary.as_ref().map(|(b, _)| b)
    }

    /// The last update's figures (every update when `gradient_steps` is 1, else every 64th).
    pub fn last_update(&self) -> &[(String, f64)] {
        &self.s.last_update
    }

    /// Empties a buffer (its transitions came from a system the agent should forget).
    pub fn clear(&mut self, store: Store) -> Result<()> {
        let fresh = |b: &ReplayBuffer| ReplayBuffer::new(b.capacity(), b.obs_dim(), b.act_dim());
        match store {
            Store::Primary => {
                self.primary = fresh(&self.primary)?;
                self.s.counts.primary_pushed = 0;
            }
            Store::Secondary => {
                if let Some((b, _)) = &mut self.secondary {
                    *b = fresh(b)?;
                }
            }
            Store::Nowhere => {}
        }
        Ok(())
    }

    /// Stores one transition.
    pub fn push(&mut self, store: Store, t: TransitionRef<'_>) -> Result<()> {
        match store {
            Store::Primary => {
                self.primary.push(t)?;
                self.s.counts.primary_pushed += 1;
            }
            Store::Secondary => match &mut self.secondary {
                Some((b, _)) => b.push(t)?,
                None => {
                    return Err(AgentError::Config {
                        field: "store",
                        value: "secondary".into(),
                        reason: "this loop has no secondary buffer (with_secondary)",
                    })
                }
            },
            Store::Nowhere => {}
        }
        Ok(())
    }

    /// Stores transitions produced elsewhere (a model's imagined rollouts), one per row: `obs`,
    /// `actions` (the index for a discrete action), `rewards`, `next_obs` and `terminated`.
    pub fn push_rows(
        &mut self,
        store: Store,
        obs: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
        rewards: ArrayView1<'_, f64>,
        next_obs: ArrayView2<'_, f64>,
        terminated: &[bool],
    ) -> Result<()> {
        let n = obs.nrows();
        for (what, got) in [
            ("actions (rows)", actions.nrows()),
            ("rewards", rewards.len()),
            ("next observations (rows)", next_obs.nrows()),
            ("terminal flags", terminated.len()),
        ] {
            if got != n {
                return Err(AgentError::Dim {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        for i in 0..n {
            let (o, a, o1) = (obs.row(i), actions.row(i), next_obs.row(i));
            self.push(
                store,
                TransitionRef {
                    obs: &contiguous(o),
                    action: &contiguous(a),
                    reward: rewards[i],
                    next_obs: &contiguous(o1),
                    terminated: terminated[i],
                },
            )?;
        }
        Ok(())
    }

    /// One exploring step of `runner`'s episode on `env`: act (random during the warm-up),
    /// step, count, store as `opts` says, then the schedule's updates if `opts.learn`.
    pub fn step(
        &mut self,
        env: &mut dyn Env,
        runner: &mut EpisodeRunner,
        opts: StepOptions,
    ) -> Result<StepRecord> {
        let obs = runner.observation(env, &mut self.agent);
        let sch = self.s.schedule;
        let warmup =
            self.s.random_warmup && self.s.counts.primary_pushed < sch.learning_starts as u64;
        let action = if warmup {
            random_action(&self.act_space, &mut self.s.rng)
        } else {
            self.agent.act(&obs, Mode::Explore)?
        };
        let rec = runner.step(env, obs, action, opts.record_states)?;
        match opts.source {
            Source::Real => self.s.counts.real_steps += 1,
            Source::Model => self.s.counts.model_steps += 1,
        }
        self.agent.on_env_step();
        self.push(
            opts.store,
            TransitionRef {
                obs: &rec.obs,
                action: &rec.action_row,
                reward: rec.reward,
                next_obs: &rec.next_obs,
                terminated: rec.terminated,
            },
        )?;
        if opts.learn {
            self.s.counts.learn_steps += 1;
            if self.s.counts.primary_pushed > sch.learning_starts as u64
                && self
                    .s
                    .counts
                    .learn_steps
                    .is_multiple_of(sch.train_freq as u64)
            {
                self.update(sch.gradient_steps)?;
            }
        }
        Ok(rec)
    }

    /// `steps` steps of [`OffPolicyLoop::step`], calling `on_step` after each.
    pub fn train(
        &mut self,
        env: &mut dyn Env,
        runner: &mut EpisodeRunner,
        steps: u64,
        opts: StepOptions,
        on_step: &mut dyn FnMut(&StepRecord),
    ) -> Result<()> {
        for _ in 0..steps {
            let rec = self.step(env, runner, opts)?;
            on_step(&rec);
        }
        Ok(())
    }

    /// `n` gradient steps, each on a minibatch drawn (with replacement) from the buffers.
    pub fn update(&mut self, n: usize) -> Result<()> {
        for _ in 0..n {
            match &self.secondary {
                Some((second, mix)) => {
                    mix.sample_into(&self.primary, second, &mut self.s.rng, &mut self.batch)?
                }
                None => {
                    let n = self.batch.len();
                    self.primary
                        .sample_into(&mut self.s.rng, &mut self.batch, 0..n)?
                }
            }
            let m = self.agent.update(&self.batch)?;
            self.s.counts.updates += 1;
            if self.s.counts.updates.is_multiple_of(64) || self.s.schedule.gradient_steps == 1 {
                self.s.last_update = m.0.iter().map(|(k, v)| (k.to_string(), *v)).collect();
            }
        }
        Ok(())
    }

    /// Stores the loop's state (buffers, generator, counters; not the agent) under `prefix`.
    pub fn save(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        self.primary.save_to(&format!("{prefix}.primary"), ckpt)?;
        if let Some((b, _)) = &self.secondary {
            b.save_to(&format!("{prefix}.secondary"), ckpt)?;
        }
        ckpt.put_json(&format!("{prefix}.loop"), &self.s)?;
        Ok(())
    }

    /// Restores what [`OffPolicyLoop::save`] stored into a loop built with the same schedule
    /// and buffers; an error for another configuration.
    pub fn load(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let s: LoopState = ckpt.get_json(&format!("{prefix}.loop"))?;
        if s.schedule != self.s.schedule
            || s.random_warmup != self.s.random_warmup
            || s.secondary != self.s.secondary
        {
            return Err(AgentError::Checkpoint(
                "the saved loop's schedule or buffers differ from this loop's".into(),
            ));
        }
        self.primary.load_from(&format!("{prefix}.primary"), ckpt)?;
        if let Some((b, _)) = &mut self.secondary {
            b.load_from(&format!("{prefix}.secondary"), ckpt)?;
        }
        self.s = s;
        Ok(())
    }
}

/// Returns of `episodes` deterministic episodes of `agent` on `env`, episode `i` reset with the
/// seed `seeds` derives from `"eval-episode-{i}"` (the same at every evaluation), each ending at
/// termination, truncation or `limit` (default: the environment's). Touches no training
/// generator and no episode state of the agent.
pub fn evaluate(
    agent: &mut dyn Agent,
    env: &mut dyn Env,
    episodes: usize,
    seeds: &SeedStream,
    limit: Option<usize>,
) -> Result<Vec<f64>> {
    (0..episodes)
        .map(|i| {
            let seed = seeds.derive(&format!("eval-episode-{i}"));
            evaluate_episode(agent, env, seed, limit, &mut |_, _| {})
        })
        .collect()
}

/// The return of one deterministic episode of `agent` on `env` reset with `seed`, ending at
/// termination, truncation or `limit` (default: the environment's), as [`evaluate`] runs each
/// of its episodes. `observe(env, action)` sees the environment after the reset (`None`) and
/// after every step (`Some` of the action taken), e.g. to record its states.
pub fn evaluate_episode(
    agent: &mut dyn Agent,
    env: &mut dyn Env,
    seed: u64,
    limit: Option<usize>,
    observe: &mut dyn FnMut(&dyn Env, Option<&Action>),
) -> Result<f64> {
    let limit = limit.or(env.max_episode_steps());
    let mut obs = env.reset(Some(seed));
    observe(env, None);
    let (mut ret, mut len) = (0.0, 0usize);
    loop {
        let a = agent.act(&obs, Mode::Deterministic)?;
        let st = env.step(&a).map_err(env_err)?;
        observe(env, Some(&a));
        ret += st.reward;
        len += 1;
        if st.terminated || st.truncated || limit.is_some_and(|m| len >= m) {
            return Ok(ret);
        }
        obs = st.observation;
    }
}

/// `row` as a slice, copied only where its elements are not adjacent.
fn contiguous(row: ArrayView1<'_, f64>) -> Cow<'_, [f64]> {
    match row.to_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(row.to_vec()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Sac, SacConfig};
    use ndarray::{Array1, Array2};

    fn small_loop(
        learning_starts: usize,
        train_freq: usize,
        gradient_steps: usize,
    ) -> OffPolicyLoop<Sac> {
        let env = tandem_envs::make("Pendulum-v1").unwrap();
        let cfg = SacConfig {
            hidden: vec![8],
            batch_size: 8,
            buffer_size: 1000,
            learning_starts,
            train_freq,
            gradient_steps,
            ..SacConfig::default()
        };
        let (o, a) = (env.observation_space(), env.action_space());
        let sac = Sac::new(cfg.clone(), o, a, 1).unwrap();
        OffPolicyLoop::new(
            sac,
            cfg.schedule(),
            o,
            a,
            tandem_core::seeding::rng_from_seed(2),
        )
        .unwrap()
    }

    #[test]
    fn the_schedule_updates_after_learning_starts_every_train_freq_steps() {
        let mut env = tandem_envs::make("Pendulum-v1").unwrap();
        let mut lp = small_loop(10, 2, 3);
        let mut runner = EpisodeRunner::new(0, "ep");
        lp.train(&mut env, &mut runner, 30, StepOptions::real(), &mut |_| {})
            .unwrap();
        // Learning steps 12, 14, ..., 30 (more than 10 stored, even clock): 10 times 3 updates.
        let c = lp.counts();
        assert_eq!((c.real_steps, c.model_steps, c.updates), (30, 0, 30));
        // Model steps count apart; collecting stores and learns nothing.
        lp.train(&mut env, &mut runner, 4, StepOptions::model(), &mut |_| {})
            .unwrap();
        lp.train(&mut env, &mut runner, 5, StepOptions::collect(), &mut |r| {
            assert!(r.states.is_some())
        })
        .unwrap();
        let c = lp.counts();
        assert_eq!((c.real_steps, c.model_steps, c.updates), (35, 4, 36));
        assert_eq!(lp.primary().len(), 34);
        // Clearing the buffer restarts the warm-up count.
        lp.clear(Store::Primary).unwrap();
        assert_eq!((lp.primary().len(), lp.counts().primary_pushed), (0, 0));
        assert!(lp.update(1).is_err(), "no data to sample from");
        // A shorter warm-up from now on: learning steps 35..=46 store transitions 1..=12, and
        // the even ones holding more than 8 (44 and 46) update; with the old 10, only 46.
        lp.set_learning_starts(8);
        assert_eq!(lp.schedule().learning_starts, 8);
        lp.train(&mut env, &mut runner, 12, StepOptions::real(), &mut |_| {})
            .unwrap();
        assert_eq!(lp.counts().updates, 36 + 2 * 3);
    }

    #[test]
    fn a_secondary_buffer_feeds_minibatches_and_must_exist_to_be_used() {
        let mut lp = small_loop(10, 1, 1);
        let rows = |n: usize| {
            (
                Array2::<f64>::zeros((n, 3)),
                Array2::<f64>::zeros((n, 1)),
                Array1::<f64>::from_elem(n, -1.0),
            )
        };
        let (o, a, r) = rows(5);
        let flags = vec![false; 5];
        let push = |lp: &mut OffPolicyLoop<Sac>, store| {
            lp.push_rows(store, o.view(), a.view(), r.view(), o.view(), &flags)
        };
        assert!(push(&mut lp, Store::Secondary).is_err());
        let mut lp = lp.with_secondary(50, 0.25).unwrap();
        push(&mut lp, Store::Secondary).unwrap();
        assert_eq!((lp.secondary().unwrap().len(), lp.primary().len()), (5, 0));
        // All rows from the secondary buffer while the primary is empty.
        lp.update(2).unwrap();
        assert_eq!(lp.counts().updates, 2);
        let short = lp.push_rows(
            Store::Primary,
            o.view(),
            a.view(),
            r.view(),
            o.view(),
            &flags[..4],
        );
        assert!(matches!(
            short,
            Err(AgentError::Dim {
                expected: 5,
                got: 4,
                ..
            })
        ));
    }

    #[test]
    fn the_runner_limits_episodes_and_seeds_them_by_index() {
        let mut env = tandem_envs::make("Pendulum-v1").unwrap();
        let mut lp = small_loop(1000, 1, 1);
        let mut runner = EpisodeRunner::new(7, "x").with_limit(Some(3));
        let mut recs = Vec::new();
        lp.train(&mut env, &mut runner, 7, StepOptions::collect(), &mut |r| {
            recs.push(r.clone())
        })
        .unwrap();
        let done: Vec<bool> = recs.iter().map(StepRecord::done).collect();
        assert_eq!(done, [false, false, true, false, false, true, false]);
        assert_eq!(runner.episode(), 2);
        assert!(runner.in_episode());
        // Episode 1 started from the reset seeded by "x1".
        let mut fresh = tandem_envs::make("Pendulum-v1").unwrap();
        fresh.reset(Some(SeedStream::new(7).derive("x1")));
        assert_eq!(recs[3].states.as_ref().unwrap().0, fresh.state());
        assert_eq!(recs[5].episode_len, 3);
        let sum: f64 = recs[3..6].iter().map(|r| r.reward).sum();
        assert!((recs[5].episode_return - sum).abs() < 1e-12);
    }

    #[test]
    fn a_saved_loop_loads_into_the_same_schedule_only() {
        let mut env = tandem_envs::make("Pendulum-v1").unwrap();
        let mut lp = small_loop(5, 1, 1);
        let mut runner = EpisodeRunner::new(0, "ep");
        lp.train(&mut env, &mut runner, 12, StepOptions::real(), &mut |_| {})
            .unwrap();
        let mut ckpt = Checkpoint::new();
        lp.save("l", &mut ckpt).unwrap();
        let mut back = small_loop(5, 1, 1);
        back.load("l", &ckpt).unwrap();
        assert_eq!(back.counts(), lp.counts());
        assert_eq!(back.primary().get(3), lp.primary().get(3));
        assert!(small_loop(6, 1, 1).load("l", &ckpt).is_err());
    }
}
