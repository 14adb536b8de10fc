//! Model-free agents: DDPG, SAC, REINFORCE and DQN, replay buffers (including the mixed
//! real/model sampler of p1 and p3), and checkpoints. Off-policy agents update from any batch, so
//! a pipeline decides whether it holds real data, model data, or a mix.
//!
//! Dependencies: `tandem-nn` (networks and optimizers), `ndarray` (replay storage and
//! minibatches), `rand`/`rand_distr` (seeded exploration and sampling), `serde`, `thiserror`.

pub mod agent;
pub mod config;
pub mod error;
pub mod noise;
pub mod replay;

pub use agent::{Agent, Batch, Episode, EpisodicAgent, Metrics, Mode, OffPolicyAgent};
pub use config::{Baseline, DdpgConfig, DqnConfig, OffPolicySchedule, ReinforceConfig, SacConfig};
pub use error::{AgentError, Result};
pub use noise::{Noise, NoiseConfig};
pub use replay::{MixedSampler, ReplayBuffer, TransitionRef};
