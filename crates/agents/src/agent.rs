//! What every agent shares: the [`Agent`] trait (acting), the two ways of learning
//! ([`OffPolicyAgent`] from minibatches, [`EpisodicAgent`] from whole episodes), and the data they
//! learn from ([`Batch`], [`Episode`]).
//!
//! Planners and model rollouts use agents read-only through two object-safe traits:
//! [`BatchPolicy`] (acting on `B x obs_dim` observations with an explicit generator) and
//! [`Critic`] (`Q(s, a)` and `V(s)`). They take `&self`, so DMD-MPC can hold a `&dyn BatchPolicy`
//! and a `&dyn Critic` of the SAC agent it trains, and they draw every random number from the
//! caller's generator, never from the agent's own stream.
//!
//! ```
//! use ndarray::array;
//! use tandem_agents::{BatchPolicy, Critic, Mode, Sac, SacConfig};
//! use tandem_core::{seeding::rng_from_seed, Space};
//!
//! let obs_space = Space::boxed(vec![-1.0; 3], vec![1.0; 3]);
//! let act_space = Space::boxed(vec![-2.0], vec![2.0]);
//! let sac = Sac::new(SacConfig::default(), &obs_space, &act_space, 0).unwrap();
//! let policy: &dyn BatchPolicy = &sac;
//! let obs = array![[0.1, 0.2, 0.3], [-0.5, 0.0, 0.9]];
//! let mut rng = rng_from_seed(7);
//! let a = policy.act_batch(obs.view(), Mode::Explore, &mut rng).unwrap(); // 2 x 1, in [-2, 2]
//! let v = sac.v_batch(obs.view(), Mode::Explore, &mut rng).unwrap(); // soft values, length 2
//! assert_eq!((a.dim(), v.len()), ((2, 1), 2));
//! ```

use ndarray::{Array1, Array2, ArrayView2};
use tandem_core::{Action, Rng};

use crate::error::{AgentError, Result};

/// How an agent acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// With exploration: noise (DDPG), sampling (SAC, REINFORCE), ε-greedy (DQN).
    Explore,
    /// Deterministically: the mean action (DDPG, SAC), the most likely action (REINFORCE), the
    /// greedy action (DQN). Used for evaluation.
    Deterministic,
}

/// Named scalar figures an update reports (losses, entropy coefficient, ...), in a fixed order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Metrics(pub Vec<(&'static str, f64)>);

impl Metrics {
    /// The value called `name`, if reported.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }

    /// Adds a figure.
    pub fn push(&mut self, name: &'static str, value: f64) {
        self.0.push((name, value));
    }
}

/// An agent that acts in an environment.
pub trait Agent {
    /// Short name of the algorithm, e.g. `"sac"`.
    fn name(&self) -> &'static str;

    /// The action for observation `obs`. Errors on a wrong length or a non-finite observation.
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action>;

    /// Called at the start of every episode (resets temporally correlated noise).
    fn reset_episode(&mut self) {}

    /// Called once after every real environment step, warm-up steps with actions not drawn from
    /// the agent included (stable-baselines3's `_on_step`). DQN counts its ε schedule and its
    /// target-network updates here; the default does nothing.
    fn on_env_step(&mut self) {}
}

/// Batched acting through `&self`: `B x obs_dim` observations (environment units, `f64`) in,
/// `B` actions out, every random number drawn from the caller's `rng`.
///
/// With [`Mode::Explore`] the agent explores as it does in [`Agent::act`]: SAC samples its
/// squashed Gaussian, DQN is ε-greedy with its current ε, REINFORCE samples its softmax, DDPG adds
/// its configured noise, drawn independently per row (for Ornstein–Uhlenbeck noise, from the
/// process's stationary distribution: the batch API keeps no per-episode state; see
/// [`crate::Ddpg`]). With [`Mode::Deterministic`] no random number is drawn.
///
/// Rows are independent: row `i` of a batch equals [`BatchPolicy::act_batch`] of row `i` alone in
/// deterministic mode; in explore mode the draws are made row by row, in order.
pub trait BatchPolicy {
    /// Observation dimension.
    fn obs_dim(&self) -> usize;

    /// Width of an action row: the action dimension, or 1 (the index) for a discrete action.
    fn action_width(&self) -> usize;

    /// `Some(n)` for a policy over `n` discrete actions, `None` for a continuous one.
    fn discrete_actions(&self) -> Option<usize> {
        None
    }

    /// The actions for the rows of `obs`, `B x action_width`: environment units for a continuous
    /// action, the index (as `f64`) for a discrete one, the layout of [`Batch::actions`]. Errors
    /// on a wrong width, an empty batch or a non-finite observation.
    fn act_batch(&self, obs: ArrayView2<'_, f64>, mode: Mode, rng: &mut Rng)
        -> Result<Array2<f64>>;

    /// [`BatchPolicy::act_batch`] as one [`Action`] per row.
    fn act_rows(&self, obs: ArrayView2<'_, f64>, mode: Mode, rng: &mut Rng) -> Result<Vec<Action>> {
        let a = self.act_batch(obs, mode, rng)?;
        Ok(match self.discrete_actions() {
            Some(_) => a
                .column(0)
                .iter()
                .map(|k| Action::Discrete(*k as usize))
                .collect(),
            None => a
                .rows()
                .into_iter()
                .map(|r| Action::Continuous(r.to_vec()))
                .collect(),
        })
    }
}

/// Critic values through `&self`, on `B` rows: `Q(s, a)` and `V(s)` (a planner's terminal value,
/// p3's `-V` terminal cost).
pub trait Critic {
    /// `Q(s_i, a_i)` for the rows of `obs` (`B x obs_dim`) and `actions` (`B x action_width`, in
    /// the layout of [`BatchPolicy::act_batch`]). Errors on wrong widths, differing row counts,
    /// out-of-range or non-finite input.
    fn q_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array1<f64>>;

    /// `V(s_i)` for the rows of `obs`. What `mode` and `rng` mean is the agent's: SAC's soft value
    /// is estimated from one sampled action per row (`Explore`) or at the mean action
    /// (`Deterministic`); DDPG's `Q(s, μ(s))` and DQN's `max_a Q(s, a)` ignore both.
    fn v_batch(&self, obs: ArrayView2<'_, f64>, mode: Mode, rng: &mut Rng) -> Result<Array1<f64>>;
}

/// An agent that learns from minibatches of transitions, whatever produced them (real data, model
/// data, or a mix).
pub trait OffPolicyAgent: Agent {
    /// One gradient step on `batch`.
    fn update(&mut self, batch: &Batch) -> Result<Metrics>;
}

/// An agent whose whole state (networks, optimizer moments, noise, generator) goes into a
/// [`Checkpoint`](tandem_nn::Checkpoint) and comes back into an agent built with the same
/// configuration, so that a run saved at any step resumes with exactly its numbers. Loading
/// another algorithm's or architecture's state is an error.
pub trait Resumable {
    /// Stores the state in `ckpt`.
    fn save(&self, ckpt: &mut tandem_nn::Checkpoint) -> Result<()>;
    /// Restores what [`Resumable::save`] stored.
    fn load(&mut self, ckpt: &tandem_nn::Checkpoint) -> Result<()>;
}

/// The agents' inherent `save`/`load` as [`Resumable`].
macro_rules! resumable {
    ($($t:ty),*) => {$(
        impl Resumable for $t {
            fn save(&self, ckpt: &mut tandem_nn::Checkpoint) -> Result<()> {
                <$t>::save(self, ckpt)
            }
            fn load(&mut self, ckpt: &tandem_nn::Checkpoint) -> Result<()> {
                <$t>::load(self, ckpt)
            }
        }
    )*};
}
resumable!(
    crate::Ddpg,
    crate::Sac,
    crate::Dqn,
    crate::Reinforce,
    crate::Learner
);

/// An agent that learns from complete episodes.
pub trait EpisodicAgent: Agent {
    /// One policy-gradient step on `episodes`.
    fn update(&mut self, episodes: &[Episode]) -> Result<Metrics>;
}

/// A minibatch of transitions, one row per transition, in `f32` (the networks' precision).
///
/// A discrete action is stored as its index in a single column.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch {
    /// Observations `s`, `n x obs_dim`.
    pub obs: Array2<f32>,
    /// Actions `a`, `n x act_dim`.
    pub actions: Array2<f32>,
    /// Rewards `r`, length `n`.
    pub rewards: Array1<f32>,
    /// Next observations `s'`, `n x obs_dim`.
    pub next_obs: Array2<f32>,
    /// `1.0` where `s'` is terminal (do not bootstrap), else `0.0`. Truncation is not terminal.
    pub terminated: Array1<f32>,
}

impl Batch {
    /// An all-zero batch of `n` rows.
    pub fn zeros(n: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            obs: Array2::zeros((n, obs_dim)),
            actions: Array2::zeros((n, act_dim)),
            rewards: Array1::zeros(n),
            next_obs: Array2::zeros((n, obs_dim)),
            terminated: Array1::zeros(n),
        }
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// `true` if the batch holds no transition.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Observation dimension.
    pub fn obs_dim(&self) -> usize {
        self.obs.ncols()
    }

    /// Action dimension (1 for a discrete action).
    pub fn act_dim(&self) -> usize {
        self.actions.ncols()
    }

    /// Checks that the columns agree in length, the widths match `obs_dim` and `act_dim`, and
    /// every number is finite.
    pub fn check(&self, obs_dim: usize, act_dim: usize) -> Result<()> {
        let n = self.len();
        if n == 0 {
            return Err(AgentError::Empty("batch"));
        }
        let shapes = [
            ("batch observations", self.obs.dim(), (n, obs_dim)),
            ("batch next observations", self.next_obs.dim(), (n, obs_dim)),
            ("batch actions", self.actions.dim(), (n, act_dim)),
        ];
        for (what, got, want) in shapes {
            if got.1 != want.1 {
                return Err(AgentError::Dim {
                    what,
                    expected: want.1,
                    got: got.1,
                });
            }
            if got.0 != want.0 {
                return Err(AgentError::Dim {
                    what,
                    expected: want.0,
                    got: got.0,
                });
            }
        }
        if self.terminated.len() != n {
            return Err(AgentError::Dim {
                what: "batch terminal flags",
                expected: n,
                got: self.terminated.len(),
            });
        }
        let bad = |what: &'static str, mut it: ndarray::iter::Iter<'_, f32, _>| -> Result<()> {
            match it.find(|v| !v.is_finite()) {
                Some(v) => Err(AgentError::NonFinite {
                    what,
                    value: f64::from(*v),
                }),
                None => Ok(()),
            }
        };
        bad("batch observation", self.obs.iter())?;
        bad("batch next observation", self.next_obs.iter())?;
        bad("batch action", self.actions.iter())?;
        if let Some(v) = self.rewards.iter().find(|v| !v.is_finite()) {
            return Err(AgentError::NonFinite {
                what: "batch reward",
                value: f64::from(*v),
            });
        }
        Ok(())
    }
}

/// One complete episode (or the part of it an episodic learner sees), in `f64` as the environment
/// produced it.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Episode {
    /// Observations `s_0 .. s_{T-1}`.
    pub observations: Vec<Vec<f64>>,
    /// Actions `a_0 .. a_{T-1}`.
    pub actions: Vec<Action>,
    /// Rewards `r_0 .. r_{T-1}`.
    pub rewards: Vec<f64>,
    /// The episode ended in a terminal state (rather than being cut short).
    pub terminated: bool,
}

impl Episode {
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// `true` for an episode without steps.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Sum of rewards.
    pub fn total_reward(&self) -> f64 {
        self.rewards.iter().sum()
    }

    /// Appends one step.
    pub fn push(&mut self, obs: Vec<f64>, action: Action, reward: f64) {
        self.observations.push(obs);
        self.actions.push(action);
        self.rewards.push(reward);
    }

    /// Discounted returns-to-go `G_t = sum_{k >= t} gamma^(k-t) r_k` (Williams 1992; p2).
    pub fn returns_to_go(&self, gamma: f64) -> Vec<f64> {
        let mut g = 0.0;
        let mut out = vec![0.0; self.rewards.len()];
        for t in (0..self.rewards.len()).rev() {
            g = self.rewards[t] + gamma * g;
            out[t] = g;
        }
        out
    }
}

/// Converts an [`Action`] into the row stored in a [`Batch`] (`f32` values; the index for a
/// discrete action).
pub fn action_row(action: &Action, out: &mut [f32]) {
    match action {
        Action::Continuous(v) => {
            for (o, x) in out.iter_mut().zip(v) {
                *o = *x as f32;
            }
        }
        Action::Discrete(k) => out[0] = *k as f32,
    }
}

/// Checks a batch of observations (`B x dim`, `B >= 1`) and converts it to row-major `f32`.
pub(crate) fn obs_rows(obs: ArrayView2<'_, f64>, dim: usize) -> Result<Vec<f32>> {
    if obs.ncols() != dim {
        return Err(AgentError::Dim {
            what: "observation batch width",
            expected: dim,
            got: obs.ncols(),
        });
    }
    if obs.nrows() == 0 {
        return Err(AgentError::Empty("observation batch"));
    }
    if let Some(v) = obs.iter().find(|v| !v.is_finite()) {
        return Err(AgentError::NonFinite {
            what: "observation",
            value: *v,
        });
    }
    Ok(obs.iter().map(|v| *v as f32).collect())
}

/// [`obs_rows`] of `obs`, then `infer(rows, B)`: the prologue of every batched acting and critic
/// path. Returns the `f32` rows and the network's outputs.
pub(crate) fn infer_rows(
    obs: ArrayView2<'_, f64>,
    dim: usize,
    infer: impl FnOnce(&[f32], usize) -> Result<Vec<f32>>,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let x = obs_rows(obs, dim)?;
    let out = infer(&x, obs.nrows())?;
    Ok((x, out))
}

/// [`Agent::act`] as the one-row case of [`BatchPolicy::act_rows`]: checks `obs`, draws from the
/// agent's own generator (`rng_of`) and keeps the generator's advance.
pub(crate) fn act_one_row<A: BatchPolicy>(
    agent: &mut A,
    rng_of: fn(&mut A) -> &mut Rng,
    obs: &[f64],
    mode: Mode,
) -> Result<Action> {
    check_obs(obs, agent.obs_dim())?;
    let mut rng = rng_of(agent).clone();
    let mut a = agent.act_rows(one_row(obs), mode, &mut rng)?;
    *rng_of(agent) = rng;
    Ok(a.swap_remove(0))
}

/// [`BatchPolicy`] for an agent over discrete actions, with fields `od` and `n_actions` and a
/// method `act_indices(obs, mode, rng) -> Result<Vec<usize>>`: the indices as one column.
macro_rules! discrete_batch_policy {
    ($agent:ty) => {
        impl $crate::agent::BatchPolicy for $agent {
            fn obs_dim(&self) -> usize {
                self.od
            }

            fn action_width(&self) -> usize {
                1
            }

            fn discrete_actions(&self) -> Option<usize> {
                Some(self.n_actions)
            }

            #[doc = concat!("[`", stringify!($agent), "::act_indices`] as a column of indices.")]
            fn act_batch(
                &self,
                obs: ndarray::ArrayView2<'_, f64>,
                mode: $crate::agent::Mode,
                rng: &mut tandem_core::Rng,
            ) -> $crate::error::Result<ndarray::Array2<f64>> {
                let k = self.act_indices(obs, mode, rng)?;
                Ok(ndarray::Array2::from_shape_fn((k.len(), 1), |(i, _)| {
                    k[i] as f64
                }))
            }
        }
    };
}
pub(crate) use discrete_batch_policy;

/// Checks that a batch of actions has `rows x width` entries, all finite.
pub(crate) fn check_action_rows(
    actions: ArrayView2<'_, f64>,
    rows: usize,
    width: usize,
) -> Result<()> {
    if actions.ncols() != width {
        return Err(AgentError::Dim {
            what: "action batch width",
            expected: width,
            got: actions.ncols(),
        });
    }
    if actions.nrows() != rows {
        return Err(AgentError::Dim {
            what: "action batch rows (one per observation)",
            expected: rows,
            got: actions.nrows(),
        });
    }
    if let Some(v) = actions.iter().find(|v| !v.is_finite()) {
        return Err(AgentError::NonFinite {
            what: "action",
            value: *v,
        });
    }
    Ok(())
}

/// One observation as a `1 x dim` view, for the single-row [`Agent::act`] over the batch path.
pub(crate) fn one_row(obs: &[f64]) -> ArrayView2<'_, f64> {
    ArrayView2::from_shape((1, obs.len()), obs).expect("a slice is one contiguous row")
}

/// Checks an observation's length and finiteness.
pub(crate) fn check_obs(obs: &[f64], dim: usize) -> Result<()> {
    if obs.len() != dim {
        return Err(AgentError::Dim {
            what: "observation",
            expected: dim,
            got: obs.len(),
        });
    }
    if let Some(v) = obs.iter().find(|v| !v.is_finite()) {
        return Err(AgentError::NonFinite {
            what: "observation",
            value: *v,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn returns_to_go_match_hand_computation() {
        let mut e = Episode::default();
        for r in [1.0, 2.0, 3.0] {
            e.push(vec![0.0], Action::Discrete(0), r);
        }
        let g = e.returns_to_go(0.5);
        // G2 = 3, G1 = 2 + 0.5*3 = 3.5, G0 = 1 + 0.5*3.5 = 2.75
        assert_eq!(g, vec![2.75, 3.5, 3.0]);
        assert_eq!(e.total_reward(), 6.0);
    }

    #[test]
    fn batch_check_finds_bad_widths_and_nan() {
        let mut b = Batch::zeros(4, 3, 1);
        assert!(b.check(3, 1).is_ok());
        assert!(matches!(
            b.check(2, 1),
            Err(AgentError::Dim {
                expected: 2,
                got: 3,
                ..
            })
        ));
        b.rewards[2] = f32::NAN;
        assert!(matches!(b.check(3, 1), Err(AgentError::NonFinite { .. })));
        assert!(matches!(
            Batch::zeros(0, 3, 1).check(3, 1),
            Err(AgentError::Empty(_))
        ));
    }
}
