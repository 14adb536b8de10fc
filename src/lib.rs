//! # tandem
//!
//! Sample-efficient robot learning, with model-based and model-free methods run in tandem.
//! This facade re-exports the workspace crates and holds the [`pipelines`]: the papers' loops,
//! written generically over the traits.
//!
//! | module | crate | owns |
//! |---|---|---|
//! | [`core`] | `tandem-core` | spaces, actions, seeding |
//! | [`dynamics`] | `tandem-dynamics` | `Plant`, integrators, rigid bodies, actuators, contact |
//! | [`envs`] | `tandem-envs` | `Env`, tasks, sim-to-real pairs, wrappers |
//! | [`nn`] | `tandem-nn` | MLPs, optimizers, heads, normalizers, checkpoints |
//! | [`models`] | `tandem-models` | `DynamicsModel` and the learned models |
//! | [`planners`] | `tandem-planners` | MPC planners and TVLG trajectory optimizers |
//! | [`agents`] | `tandem-agents` | DDPG, SAC, REINFORCE, DQN, replay |
//!
//! [`run`] writes run directories; [`report`] renders reproduction tables and figures;
//! [`interrupt`] turns SIGINT/SIGTERM into a stop request that long runs poll.

pub use tandem_agents as agents;
pub use tandem_core as core;
pub use tandem_dynamics as dynamics;
pub use tandem_envs as envs;
pub use tandem_models as models;
pub use tandem_nn as nn;
pub use tandem_planners as planners;

pub mod interrupt;
pub mod pipelines;
pub mod report;
pub mod run;
