//! Environments with gymnasium semantics: the [`Env`] trait, tasks (reward, termination and reset
//! over a [`tandem_dynamics::Plant`]), idealized/true pairs for sim-to-real gaps, and the wrappers
//! every training loop needs.
//!
//! Dependencies: `tandem-core` (spaces, actions, seeding), `tandem-dynamics` (the plants tasks
//! run on), `nalgebra` (plant states), `rand`/`rand_distr` (seeded resets), `serde`, `thiserror`.

mod env;

pub use env::{Env, EnvError, Step};
pub use tandem_core::{Action, Space};
