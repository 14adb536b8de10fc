//! Neural-network building blocks shared by models and agents, on candle: MLPs with seeded
//! initialization, optimizers (Adam, AdaGrad, SGD), Gaussian and tanh-Gaussian heads, polyak
//! target updates, running normalizers, and safetensors checkpoints.
//!
//! Networks compute in `f32`; physics and planning stay in `f64` and convert at the boundary.
//! candle's CPU generator cannot be seeded, so every random number here comes from
//! [`tandem_core::Rng`].
//!
//! Dependencies: `candle-core`/`candle-nn` (tensors, autograd, safetensors), `rand`/`rand_distr`
//! (seeded initialization and noise), `serde`, `thiserror`.
