//! Wrappers every training loop needs: [`TimeLimit`], [`SampleCounter`], [`ClipAction`],
//! [`RescaleAction`] and observation hooks ([`TransformObservation`], [`RunningNormalizer`]).
//!
//! Every wrapper is generic over `E: Env` and `Box<dyn Env>` is an `Env`, so they stack over
//! boxed environments from [`crate::make`]:
//!
//! ```
//! use tandem_envs::{make, Action, Env, RescaleAction, SampleCounter};
//!
//! let (env, count) = SampleCounter::new(make("Pendulum-v1").unwrap());
//! let mut env = RescaleAction::new(env).unwrap(); // the agent acts in [-1, 1]
//! env.reset(Some(0));
//! let step = env.step(&Action::Continuous(vec![1.0])).unwrap(); // 2 N m
//! assert_eq!(count.get(), 1);
//! # let _ = step;
//! ```

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use tandem_core::{Action, Space};

use crate::env::check_action;
use crate::{Env, EnvError, Step};

/// Truncates episodes after `max_episode_steps` steps (gymnasium's `TimeLimit`): the step that
/// reaches the limit has `truncated = true` (also when it terminates), and stepping again needs a
/// reset.
#[derive(Debug, Clone)]
pub struct TimeLimit<E> {
    env: E,
    max_episode_steps: usize,
    elapsed: usize,
    done: bool,
}

impl<E: Env> TimeLimit<E> {
    /// Wraps `env` with a limit of `max_episode_steps` steps per episode.
    pub fn new(env: E, max_episode_steps: usize) -> Self {
        Self {
            env,
            max_episode_steps,
            elapsed: 0,
            done: false,
        }
    }

    /// Steps taken in the current episode.
    pub fn elapsed_steps(&self) -> usize {
        self.elapsed
    }

    /// The wrapped environment.
    pub fn inner(&self) -> &E {
        &self.env
    }

    /// The wrapped environment, mutably.
    pub fn inner_mut(&mut self) -> &mut E {
        &mut self.env
    }
}

impl<E: Env> Env for TimeLimit<E> {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &Space {
        self.env.observation_space()
    }
    fn action_space(&self) -> &Space {
        self.env.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.elapsed = 0;
        self.done = false;
        self.env.reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        if self.done {
            return Err(EnvError::NeedsReset {
                env: self.env.id().to_string(),
                when: "after the episode ended",
            });
        }
        let mut step = self.env.step(action)?;
        self.elapsed += 1;
        if self.elapsed >= self.max_episode_steps {
            step.truncated = true;
        }
        self.done = step.done();
        Ok(step)
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        let obs = self.env.set_state(state)?;
        self.elapsed = 0;
        self.done = false;
        Ok(obs)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(self.max_episode_steps)
    }
}

/// A shared, read-only view of a [`SampleCounter`]'s count. Cloning it shares the count; it stays
/// readable while the counted environment is boxed or moved into a training loop.
#[derive(Debug, Clone, Default)]
pub struct SampleCount(Arc<AtomicU64>);

impl SampleCount {
    /// Environment transitions taken so far.
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Counts real environment samples exactly: every `step` that returns `Ok` is one sample
/// (resets and rejected actions are not). The count is the figure every paper reports.
#[derive(Debug)]
pub struct SampleCounter<E> {
    env: E,
    count: SampleCount,
}

impl<E: Env> SampleCounter<E> {
    /// Wraps `env`; returns the wrapper and a handle to its count.
    pub fn new(env: E) -> (Self, SampleCount) {
        let count = SampleCount::default();
        (
            Self {
                env,
                count: count.clone(),
            },
            count,
        )
    }

    /// Wraps `env` with the count starting at `samples`: a run resumed from a checkpoint
    /// continues the count it had.
    pub fn starting_at(env: E, samples: u64) -> (Self, SampleCount) {
        let (wrapper, count) = Self::new(env);
        count.0.store(samples, Ordering::Relaxed);
        (wrapper, count)
    }

    /// Another handle to the count.
    pub fn count(&self) -> SampleCount {
        self.count.clone()
    }
}

impl<E: Env> Env for SampleCounter<E> {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &Space {
        self.env.observation_space()
    }
    fn action_space(&self) -> &Space {
        self.env.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        let step = self.env.step(action)?;
        self.count.0.fetch_add(1, Ordering::Relaxed);
        Ok(step)
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.env.set_state(state)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.env.max_episode_steps()
    }
}

/// The finite bounds of a box action space, or an error naming why a wrapper cannot use them.
fn finite_box(env: &dyn Env) -> Result<(Vec<f64>, Vec<f64>), EnvError> {
    let unsupported = |reason: &str| EnvError::Unsupported {
        env: env.id().to_string(),
        reason: reason.to_string(),
    };
    match env.action_space() {
        Space::Box { low, high, .. } => {
            if low.iter().chain(high).any(|v| !v.is_finite()) {
                Err(unsupported("action bounds must be finite"))
            } else if low.iter().zip(high).any(|(l, h)| l >= h) {
                Err(unsupported("action bounds must satisfy low < high"))
            } else {
                Ok((low.clone(), high.clone()))
            }
        }
        Space::Discrete { .. } => Err(unsupported("a discrete action space has no bounds")),
    }
}

/// Clips continuous actions into the action space's bounds before the environment sees them.
/// Non-finite or wrongly sized actions are still rejected.
#[derive(Debug, Clone)]
pub struct ClipAction<E> {
    env: E,
    low: Vec<f64>,
    high: Vec<f64>,
}

impl<E: Env> ClipAction<E> {
    /// Wraps `env`; fails for a discrete or unbounded action space.
    pub fn new(env: E) -> Result<Self, EnvError> {
        let (low, high) = finite_box(&env)?;
        Ok(Self { env, low, high })
    }
}

impl<E: Env> Env for ClipAction<E> {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &Space {
        self.env.observation_space()
    }
    fn action_space(&self) -> &Space {
        self.env.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        check_action(self.env.id(), self.env.action_space(), action)?;
        let a = action.as_continuous().unwrap_or_default();
        let clipped = a
            .iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(v, (l, h))| v.clamp(*l, *h))
            .collect();
        self.env.step(&Action::Continuous(clipped))
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.env.set_state(state)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.env.max_episode_steps()
    }
}

/// The agent acts in `[-1, 1]^n`; actions are clipped to that box and mapped affinely onto the
/// environment's bounds: `a_env = low + (a + 1)/2 · (high − low)`.
#[derive(Debug, Clone)]
pub struct RescaleAction<E> {
    env: E,
    low: Vec<f64>,
    high: Vec<f64>,
    space: Space,
}

impl<E: Env> RescaleAction<E> {
    /// Wraps `env`; fails for a discrete or unbounded action space.
    pub fn new(env: E) -> Result<Self, EnvError> {
        let (low, high) = finite_box(&env)?;
        let space = Space::symmetric(low.len(), 1.0);
        Ok(Self {
            env,
            low,
            high,
            space,
        })
    }

    /// Maps an agent action in `[-1, 1]^n` (clipped first) to the environment's bounds.
    pub fn to_env(&self, a: &[f64]) -> Vec<f64> {
        a.iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(v, (l, h))| l + (v.clamp(-1.0, 1.0) + 1.0) * 0.5 * (h - l))
            .collect()
    }

    /// Maps an environment action back to `[-1, 1]^n` (the inverse of [`Self::to_env`] inside
    /// the bounds).
    pub fn to_agent(&self, a: &[f64]) -> Vec<f64> {
        a.iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(v, (l, h))| 2.0 * (v - l) / (h - l) - 1.0)
            .collect()
    }
}

impl<E: Env> Env for RescaleAction<E> {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &Space {
        self.env.observation_space()
    }
    fn action_space(&self) -> &Space {
        &self.space
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        check_action(self.env.id(), &self.space, action)?;
        let a = self.to_env(action.as_continuous().unwrap_or_default());
        self.env.step(&Action::Continuous(a))
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.env.set_state(state)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.env.max_episode_steps()
    }
}

/// A hook that rewrites observations in place (normalization, feature maps of the same size).
pub trait ObservationHook {
    /// Transforms `obs` in place. Called on every observation `reset`, `set_state` and `step`
    /// return, in that order of calls.
    fn apply(&mut self, obs: &mut [f64]);

    /// The observation space after the hook, given the wrapped environment's. The default is an
    /// unbounded box of the same shape.
    fn space(&self, inner: &Space) -> Space {
        match inner {
            Space::Box { low, shape, .. } => Space::Box {
                low: vec![f64::NEG_INFINITY; low.len()],
                high: vec![f64::INFINITY; low.len()],
                shape: shape.clone(),
            },
            other => other.clone(),
        }
    }
}

/// Applies an [`ObservationHook`] to every observation of `env`.
#[derive(Debug, Clone)]
pub struct TransformObservation<E, H> {
    env: E,
    hook: H,
    space: Space,
}

impl<E: Env, H: ObservationHook> TransformObservation<E, H> {
    /// Wraps `env` with `hook`.
    pub fn new(env: E, hook: H) -> Self {
        let space = hook.space(env.observation_space());
        Self { env, hook, space }
    }

    /// The hook (e.g. to read normalization statistics).
    pub fn hook(&self) -> &H {
        &self.hook
    }

    /// The hook, mutably (e.g. to freeze its statistics for evaluation).
    pub fn hook_mut(&mut self) -> &mut H {
        &mut self.hook
    }
}

impl<E: Env, H: ObservationHook> Env for TransformObservation<E, H> {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &Space {
        &self.space
    }
    fn action_space(&self) -> &Space {
        self.env.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        let mut obs = self.env.reset(seed);
        self.hook.apply(&mut obs);
        obs
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        let mut step = self.env.step(action)?;
        self.hook.apply(&mut step.observation);
        Ok(step)
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        let mut obs = self.env.set_state(state)?;
        self.hook.apply(&mut obs);
        Ok(obs)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.env.max_episode_steps()
    }
}

pub use tandem_core::RunningNormalizer;

/// Running mean/variance normalization, as gymnasium's `NormalizeObservation`:
/// `(obs − mean) / sqrt(var + ε)` (ε = 1e-8) with the statistics updated from every observation
/// first, unless frozen ([`RunningNormalizer::set_frozen`]). A non-finite observation is not added
/// to the statistics (it would spoil them for the rest of the run); it is normalized like any
/// other, so the non-finite value reaches whoever checks the observation.
impl ObservationHook for RunningNormalizer {
    fn apply(&mut self, obs: &mut [f64]) {
        if !self.is_frozen() && obs.iter().all(|v| v.is_finite()) {
            // Length and finiteness are what update_f64 checks: the length is the env's.
            let _ = self.update_f64(obs);
        }
        if self.normalize_f64(obs).is_err() {
            obs.iter_mut().for_each(|v| *v = f64::NAN);
        }
    }
}

/// An environment whose observations are normalized by running statistics.
pub type NormalizeObservation<E> = TransformObservation<E, RunningNormalizer>;

impl<E: Env> TransformObservation<E, RunningNormalizer> {
    /// Normalizes `env`'s observations with a fresh [`RunningNormalizer`].
    pub fn normalized(env: E) -> Self {
        let dim = env.observation_space().flat_dim();
        Self::new(env, RunningNormalizer::new(dim))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CartPoleEnv, PendulumEnv};

    #[test]
    fn time_limit_truncates_at_the_limit_and_blocks_until_reset() {
        let mut env = TimeLimit::new(PendulumEnv::new(), 3);
        env.reset(Some(0));
        let a = Action::Continuous(vec![0.0]);
        assert!(!env.step(&a).unwrap().truncated);
        assert!(!env.step(&a).unwrap().truncated);
        let last = env.step(&a).unwrap();
        assert!(last.truncated && !last.terminated);
        assert!(matches!(env.step(&a), Err(EnvError::NeedsReset { .. })));
        env.reset(None);
        assert_eq!(env.elapsed_steps(), 0);
        assert!(env.step(&a).is_ok());
        // set_state starts a new episode too.
        env.set_state(&[0.0, 0.0]).unwrap();
        assert_eq!(env.elapsed_steps(), 0);
        assert_eq!(env.max_episode_steps(), Some(3));
    }

    #[test]
    fn time_limit_sets_truncated_even_on_a_terminating_step() {
        let mut env = TimeLimit::new(CartPoleEnv::new(), 1);
        env.set_state(&[2.399, 1.0, 0.0, 0.0]).unwrap();
        let st = env.step(&Action::Discrete(1)).unwrap();
        assert!(st.terminated && st.truncated);
    }

    #[test]
    fn sample_counter_counts_successful_steps_through_a_box() {
        let (env, count) = SampleCounter::new(PendulumEnv::new());
        let mut boxed: Box<dyn Env> = Box::new(TimeLimit::new(env, 5));
        let before_reset = boxed.step(&Action::Continuous(vec![0.0]));
        assert!(before_reset.is_err());
        boxed.reset(Some(1));
        for _ in 0..5 {
            boxed.step(&Action::Continuous(vec![1.0])).unwrap();
        }
        assert!(boxed.step(&Action::Continuous(vec![f64::NAN])).is_err());
        assert!(boxed.step(&Action::Continuous(vec![1.0])).is_err()); // truncated
        assert_eq!(count.get(), 5);
        let other = count.clone();
        boxed.reset(None);
        boxed.step(&Action::Continuous(vec![1.0])).unwrap();
        assert_eq!(other.get(), 6);

        let (mut resumed, count) = SampleCounter::starting_at(PendulumEnv::new(), 6);
        resumed.reset(Some(1));
        resumed.step(&Action::Continuous(vec![1.0])).unwrap();
        assert_eq!(count.get(), 7);
    }

    #[test]
    fn clip_action_clips_into_bounds() {
        let mut plain = PendulumEnv::new();
        let mut clipped = ClipAction::new(PendulumEnv::new()).unwrap();
        plain.reset(Some(0));
        clipped.reset(Some(0));
        let a = plain.step(&Action::Continuous(vec![-2.0])).unwrap();
        let b = clipped.step(&Action::Continuous(vec![-100.0])).unwrap();
        assert_eq!(a, b);
        assert!(clipped.step(&Action::Continuous(vec![f64::NAN])).is_err());
        assert!(matches!(
            ClipAction::new(CartPoleEnv::new()),
            Err(EnvError::Unsupported { .. })
        ));
        assert!(RescaleAction::new(CartPoleEnv::new()).is_err());
    }

    #[test]
    fn rescale_action_maps_the_unit_box_onto_the_bounds() {
        let env = RescaleAction::new(PendulumEnv::new()).unwrap();
        assert_eq!(env.action_space(), &Space::symmetric(1, 1.0));
        assert_eq!(env.to_env(&[-1.0]), vec![-2.0]);
        assert_eq!(env.to_env(&[1.0]), vec![2.0]);
        assert_eq!(env.to_env(&[0.25]), vec![0.5]);
        assert_eq!(env.to_env(&[7.0]), vec![2.0]);
        assert!((env.to_agent(&env.to_env(&[-0.3]))[0] + 0.3).abs() < 1e-15);
        // Stepping with 0.5 equals stepping the plain env with 1.0 N m.
        let mut plain = PendulumEnv::new();
        let mut scaled = env;
        plain.set_state(&[1.0, 0.0]).unwrap();
        scaled.set_state(&[1.0, 0.0]).unwrap();
        assert_eq!(
            plain.step(&Action::Continuous(vec![1.0])).unwrap(),
            scaled.step(&Action::Continuous(vec![0.5])).unwrap()
        );
    }

    #[test]
    fn running_normalizer_matches_batch_statistics() {
        let data = [[1.0, 10.0], [2.0, 20.0], [4.0, -5.0], [7.0, 0.0]];
        let mut n = RunningNormalizer::new(2);
        let mut out = Vec::new();
        for d in &data {
            let mut o = d.to_vec();
            n.apply(&mut o);
            out.push(o);
        }
        let mean0 = 14.0 / 4.0;
        let var0 = data.iter().map(|d| (d[0] - mean0).powi(2)).sum::<f64>() / 4.0;
        assert!((n.mean()[0] - mean0).abs() < 1e-12);
        assert!((n.var()[0] - var0).abs() < 1e-12);
        // The last observation is normalized by statistics that include it.
        assert!((out[3][0] - (7.0 - mean0) / (var0 + 1e-8).sqrt()).abs() < 1e-12);
        n.set_frozen(true);
        let mut o = vec![3.5, 6.25];
        n.apply(&mut o);
        assert_eq!(n.count(), 4.0);
        assert!(o[0].abs() < 1e-12);
    }

    #[test]
    fn normalize_observation_wraps_an_env() {
        let mut env = NormalizeObservation::normalized(PendulumEnv::new());
        let first = env.reset(Some(2));
        // One observation: mean = obs, variance 0, so the normalized value is 0.
        assert!(first.iter().all(|v| v.abs() < 1e-12));
        for _ in 0..50 {
            env.step(&Action::Continuous(vec![2.0])).unwrap();
        }
        assert_eq!(env.hook().count(), 51.0);
        assert!(
            matches!(env.observation_space(), Space::Box { high, .. } if high[0].is_infinite())
        );
    }
}
