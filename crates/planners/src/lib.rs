//! Planners: receding-horizon MPC through any [`tandem_models::DynamicsModel`] (CEM, MPPI,
//! DMD-MPC) and trajectory optimizers over time-varying linear-Gaussian controllers (iLQR,
//! LQR-FLM, PI², PILQR).
//!
//! Dependencies: `tandem-models` (the models planned through), `tandem-dynamics` (plants),
//! `ndarray` (populations, samples x horizon x dim), `nalgebra` (gains and small matrices),
//! `rand`/`rand_distr` (seeded sampling), `serde`, `thiserror`.
