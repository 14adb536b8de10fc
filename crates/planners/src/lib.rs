//! Planners: receding-horizon MPC through any [`tandem_models::DynamicsModel`] (CEM, MPPI,
//! DMD-MPC) and trajectory optimizers over time-varying linear-Gaussian controllers (iLQR,
//! LQR-FLM, PI², PILQR).
//!
//! This crate owns
//! - [`Objective`]: running cost, terminal cost, terminal value (`−V`, p3), derivatives
//!   (analytic or finite differences);
//! - [`Planner`] and its implementations [`Cem`], [`Mppi`], [`DmdMpc`], all batched over the
//!   population (one `predict` call per time step), warm-started by shifting, bounded;
//!
//! Dependencies: `tandem-models` (the models planned through), `tandem-dynamics` (plants),
//! `ndarray` (populations, horizon x samples x dim), `nalgebra` (gains and small matrices),
//! `rand`/`rand_distr` (seeded sampling), `serde`, `thiserror`.

// Index loops read closest to the papers' equations in this numeric code.
#![allow(clippy::needless_range_loop)]

mod cem;
mod dmd;
mod error;
mod mpc;
mod mppi;
mod objective;

pub use cem::{Cem, CemConfig};
pub use dmd::{DmdMpc, DmdMpcConfig, Proposal, ProposalFn, Utility};
pub use error::{PlanError, Result};
pub use mpc::{Bounds, Noise, Plan, Planner};
pub use mppi::{Mppi, MppiConfig};
pub use objective::{
    CostFn, Objective, QuadCost, QuadTerminal, RunningDerivFn, TerminalDerivFn, TerminalFn, ValueFn,
};
