//! Model-free agents: DDPG, SAC, REINFORCE and DQN, replay buffers (including the mixed
//! real/model sampler of p1 and p3), the one off-policy loop with its checkpoints, and the
//! configurations. Off-policy agents update from any [`Batch`], so a pipeline decides whether it
//! holds real data, model data, or a mix; REINFORCE updates from any list of [`Episode`]s.
//!
//! | item | what |
//! |---|---|
//! | [`Agent`], [`OffPolicyAgent`], [`EpisodicAgent`], [`Mode`] | acting and the two ways of learning |
//! | [`BatchPolicy`], [`Critic`] | batched `&self` acting (explicit generator) and `Q(s, a)`, `V(s)`, for planners and model rollouts |
//! | [`ReplayBuffer`], [`MixedSampler`], [`Batch`], [`Episode`] | data (ring buffer in `ndarray`) |
//! | [`Ddpg`], [`Sac`], [`Dqn`], [`Reinforce`] and their `*Config` | the agents; each `Default` cites its source |
//! | [`Noise`], [`NoiseConfig`] | Ornstein–Uhlenbeck and Gaussian exploration |
//! | [`Learner`], [`Algo`], [`AlgoConfig`] | "one of the four", chosen by name |
//! | [`OffPolicyLoop`], [`EpisodeRunner`], [`evaluate`] | the one off-policy loop every pipeline runs: real and model steps, two replay buffers mixed at a set ratio, exact sample counts, stable-baselines3's schedule, evaluation, save/resume |
//! | [`Adapted`], [`Feature`] | an adapter in front of any off-policy agent: observation features, reward scale, settable exploration noise |
//! | [`GlobalPolicy`], [`PolicyConfig`], [`PolicyInput`] | GPS's neural Gaussian policy, regressed onto target actions (MDGPS's global policy) |
//!
//! Networks are `tandem-nn`'s hand-derived [`tandem_nn::Mlp`]s with in-place Adam; the actor
//! gradients (DDPG through the critic's input gradient, SAC's reparametrized tanh-Gaussian) are
//! derived in the agents' module docs and tested against finite differences. Actions are `[-1, 1]`
//! inside the networks and environment units in batches and replay, so model-based pipelines see
//! real actions.
//!
//! Every random number comes from seeded [`tandem_core::Rng`] streams derived from one run seed;
//! checkpoints ([`tandem_nn::Checkpoint`], safetensors) hold networks, optimizer states, noise
//! state, generators, replay and the in-progress episode, so a resumed run continues bit-for-bit.
//!
//! DQN's Q-network is an MLP or, with the feature `pixels`, for image observations (p2's 16x16
//! RGB maze, `PixelMaze-v0`), a `ConvQNet` built from candle convolutions with
//! `tandem_nn::candle_ext`'s seeded parameters, stepped by the same Adam. Not written yet: a Gaussian-policy REINFORCE for
//! continuous actions.
//!
//! Feature `pixels` (off by default; on where p2's pixel pipeline is built: `tandem-algos`,
//! `tandem-studies`, the facade): the conv Q-network. A feature rather than a crate above this
//! one because DQN holds its Q-network in a private enum (MLP or conv) behind one config, its
//! checkpoints and its memory estimate; a crate would need a new Q-network trait through DQN.
//! Without it, `network = "conv"` is not a known value.
//!
//! Dependencies: `tandem-nn` (networks, optimizers, checkpoints), `candle-core`/`candle-nn`
//! (optional, feature `pixels`: the conv Q-network's layers and autograd), `tandem-envs` (the `Env` trait
//! the off-policy loop drives), `ndarray` (replay storage and minibatches), `rand`/`rand_distr`
//! (seeded exploration and sampling), `serde`/`serde_json`/`toml` (configs, checkpoint payloads),
//! `thiserror`.

#![warn(missing_docs)]
// Index loops over several parallel columns read closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod adapter;
pub mod agent;
mod common;
pub mod config;
#[cfg(feature = "pixels")]
pub mod conv_qnet;
pub mod ddpg;
pub mod dqn;
pub mod error;
pub mod global_policy;
pub mod learner;
pub mod noise;
pub mod off_policy;
pub mod reinforce;
pub mod replay;
pub mod sac;

pub use adapter::{feature_dim, features_of, Adapted, Feature};
pub use agent::{
    Agent, Batch, BatchPolicy, Critic, Episode, EpisodicAgent, Metrics, Mode, OffPolicyAgent,
    Resumable,
};
pub use config::{
    Baseline, DdpgConfig, DqnConfig, OffPolicySchedule, QNetwork, ReinforceConfig, SacConfig,
};
#[cfg(feature = "pixels")]
pub use conv_qnet::{ConvQNet, ConvQNetConfig};
pub use ddpg::{random_action, Ddpg};
pub use dqn::Dqn;
pub use error::{AgentError, Result};
pub use global_policy::{FeatureMap, GlobalPolicy, PolicyConfig, PolicyInput, Weighting};
pub use learner::{Algo, AlgoConfig, Learner};
pub use noise::{Noise, NoiseConfig};
pub use off_policy::{
    evaluate, evaluate_episode, EpisodeRunner, LoopCounts, OffPolicyLoop, Source, StepOptions,
    StepRecord, Store,
};
pub use reinforce::Reinforce;
pub use replay::{MixedSampler, ReplayBuffer, TransitionRef};
pub use sac::Sac;

#[cfg(test)]
mod tests;
