//! Planners: receding-horizon MPC through any [`tandem_models::DynamicsModel`] (CEM, MPPI,
//! DMD-MPC) and trajectory optimizers over time-varying linear-Gaussian controllers (iLQR,
//! LQR-FLM, PI², PILQR).
//!
//! This crate owns
//! - [`Objective`]: running cost (optionally time-varying, `c(x, u, t)`), transition cost
//!   `c(x, u, x')` and termination (a task's reward and termination, [`Objective::from_task`]),
//!   terminal cost, terminal value (`−V`, p3), derivatives (analytic or finite differences);
//! - [`Planner`] and its implementations [`Cem`], [`Mppi`], [`DmdMpc`], all batched over the
//!   population (one `predict` call per time step), warm-started by shifting, bounded;
//! - [`Ilqr`] (also a [`Planner`]) through any [`tandem_models::DynamicsModel`], linearized by
//!   the model's own `linearize` (a `PlantModel`: the plant's Jacobians, analytic for rigid
//!   bodies; otherwise finite differences of one batched `predict`); the one model trait every
//!   planner here takes, so there is no planner-side dynamics trait or adapter;
//! - planning through models that read the previous action (p1's incremental model) with no
//!   extra input: such a model carries it in its state, `x0 = [s, a_{t−1}]`;
//! - TVLG controllers ([`TvlgController`], sampled with stored noise) and their optimizers
//!   [`LqrFlm`], [`pi2_update`] and [`Pilqr`] (p4), on dynamics fitted by
//!   `tandem_models::TvlgFit`, with a quadratic cost per time step that the caller may supply
//!   ([`Pilqr::update_with_cost`]; by default [`quadratize_cost`] of the [`Objective`]).
//!
//! Dependencies: `tandem-models` (the models planned through), `tandem-dynamics` (plants),
//! `tandem-envs` (tasks, whose reward and termination become objectives),
//! `ndarray` (populations, horizon x samples x dim), `nalgebra` (gains and small matrices),
//! `rand`/`rand_distr` (seeded sampling), `serde`, `thiserror`.

#![warn(missing_docs)]
// Index loops read closest to the papers' equations in this numeric code.
#![allow(clippy::needless_range_loop)]

mod cem;
mod dmd;
mod error;
mod ilqr;
mod lqr_flm;
mod mpc;
mod mppi;
mod objective;
mod pi2;
mod pilqr;
mod tvlg;

pub use cem::{Cem, CemConfig};
pub use dmd::{DmdMpc, DmdMpcConfig, Proposal, ProposalFn, Utility};
pub use error::{PlanError, Result};
pub use ilqr::{backward_pass, BackwardPass, Ilqr, IlqrConfig, IlqrSolution};
pub use lqr_flm::{
    adjust_step_mult, classic_step_mult, laplace_cost, LqrFlm, LqrFlmConfig, LqrFlmStep,
};
pub use mpc::{Bounds, Interpolation, Knots, Noise, Plan, Planner};
pub use mppi::{Mppi, MppiConfig, Temperature};
pub use objective::{
    CostFn, Objective, QuadCost, QuadTerminal, RunningDerivFn, TerminalDerivFn, TerminalFn,
    TerminationFn, TransitionFn, ValueFn,
};
pub use pi2::{pi2_update, pi2_update_with_temperatures, pi2_weights, Pi2Config, Pi2Step};
pub use pilqr::{
    model_cost_to_go, model_costs, reparametrize, PerStep, Pilqr, PilqrConfig, PilqrStep, Residual,
};
pub use tvlg::{
    costs_to_go, expected_cost, forward_moments, policy_kl, quadratize_cost, sample_trajectories,
    InitLqr, QuadraticCost, SampleConfig, TrajectoryMoments, TrajectorySamples, TvlgController,
};
