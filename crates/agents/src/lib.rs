//! Model-free agents: DDPG, SAC, REINFORCE and DQN, replay buffers (including the mixed
//! real/model sampler of p1 and p3), and checkpoints. Off-policy agents update from any batch, so
//! a pipeline decides whether it holds real data, model data, or a mix.
//!
//! Dependencies: `tandem-nn` (networks and optimizers), `ndarray` (replay storage and
//! minibatches), `rand`/`rand_distr` (seeded exploration and sampling), `serde`, `thiserror`.

// Index loops over several parallel columns read closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod agent;
mod common;
pub mod config;
pub mod ddpg;
pub mod dqn;
pub mod error;
pub mod learner;
pub mod noise;
pub mod reinforce;
pub mod replay;
pub mod sac;
pub mod trainer;

pub use agent::{Agent, Batch, Episode, EpisodicAgent, Metrics, Mode, OffPolicyAgent};
pub use config::{Baseline, DdpgConfig, DqnConfig, OffPolicySchedule, ReinforceConfig, SacConfig};
pub use ddpg::{random_action, Ddpg};
pub use dqn::Dqn;
pub use error::{AgentError, Result};
pub use learner::{Algo, AlgoConfig, Learner};
pub use noise::{Noise, NoiseConfig};
pub use reinforce::Reinforce;
pub use replay::{MixedSampler, ReplayBuffer, TransitionRef};
pub use sac::Sac;
pub use trainer::{EpisodeRecord, EvalRecord, RunLog, TrainSettings, Trainer};

#[cfg(test)]
mod tests;
#[cfg(test)]
mod trainer_tests;
