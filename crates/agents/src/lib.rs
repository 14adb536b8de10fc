//! Model-free agents: DDPG, SAC, REINFORCE and DQN, replay buffers (including the mixed
//! real/model sampler of p1 and p3), and checkpoints. Off-policy agents update from any batch, so
//! a pipeline decides whether it holds real data, model data, or a mix.
//!
//! Dependencies: `tandem-nn` (networks and optimizers), `ndarray` (replay storage and
//! minibatches), `rand`/`rand_distr` (seeded exploration and sampling), `serde`, `thiserror`.
