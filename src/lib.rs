//! # tandem
//!
//! Sample-efficient robot learning, with model-based and model-free methods run in tandem.
//! This facade re-exports the workspace crates, among them [`algos`], the model-based algorithms
//! composed from the others, and [`studies`], the papers' reproductions over them, and holds the
//! registry of every environment.
//!
//! | module | crate | owns |
//! |---|---|---|
//! | [`core`] | `tandem-core` | spaces, actions, seeding |
//! | [`dynamics`] | `tandem-dynamics` | `Plant`, integrators, rigid bodies, actuators, contact |
//! | [`envs`] | `tandem-envs` | `Env`, tasks, the classic gymnasium environments, wrappers |
//! | [`nn`] | `tandem-nn` | MLPs, optimizers, heads, normalizers, checkpoints |
//! | [`models`] | `tandem-models` | `DynamicsModel` and the learned models |
//! | [`planners`] | `tandem-planners` | MPC planners and TVLG trajectory optimizers |
//! | [`agents`] | `tandem-agents` | DDPG, SAC, REINFORCE, DQN, replay, agent adapters |
//! | [`algos`] | `tandem-algos` | MBPO, Dyna, M-DeMoRL, difference models, imagined episodes, GPS, MDGPS |
//! | [`mujoco`] | `tandem-mujoco` | gymnasium's MuJoCo v5 tasks and MJCF scenes (real MuJoCo with the feature `mujoco`) |
//! | [`robots`] | `tandem-robots` | the papers' robots and scenes: the DC-motor pendulum, Leo, the 2R leg, the pixel maze, p4's scenes |
//! | [`studies`] | `tandem-studies` | the papers' studies, run directories, reports, stop requests |
//!
//! [`make_env`] and [`registered_envs`] are the registry of every environment: `tandem-envs`'s,
//! then `tandem-robots`' and gymnasium's MuJoCo tasks (made with the feature `mujoco`).
//!
//! [`prelude`] brings the traits and the common types into scope, and the facade re-exports the
//! versions of [`nalgebra`], [`ndarray`] and [`rand`] that the public API speaks, so a crate that
//! composes its own pipeline can depend on `tandem` alone.

#![warn(missing_docs)]

pub use tandem_agents as agents;
pub use tandem_algos as algos;
pub use tandem_core as core;
pub use tandem_dynamics as dynamics;
pub use tandem_envs as envs;
pub use tandem_models as models;
pub use tandem_mujoco as mujoco;
pub use tandem_nn as nn;
pub use tandem_planners as planners;
pub use tandem_robots as robots;
pub use tandem_studies as studies;

pub use nalgebra;
pub use ndarray;
pub use rand;

/// The traits and the types most pipelines use, in one import.
///
/// ```
/// use tandem::prelude::*;
///
/// // CEM with 4 particles per sequence plans a pendulum swing through its exact model.
/// let model = PlantModel::new(GymPendulum::new(GymPendulumParams::default()));
/// let objective = Objective::new(2, 1, |x, u| 1.0 - x[0].cos() + 1e-3 * u[0] * u[0]);
/// let mut cem = Cem::new(CemConfig {
///     horizon: 10,
///     population: 50,
///     particles: 4,
///     bounds: Some(Bounds::symmetric(1, 2.0)),
///     ..CemConfig::default()
/// })
/// .unwrap();
/// let plan = cem.plan(&[3.0, 0.0], &model, &objective).unwrap();
/// assert_eq!(plan.actions.dim(), (10, 1));
/// assert!(plan.total_cost.is_finite());
/// ```
pub mod prelude {
    pub use crate::{make_env, registered_envs};
    pub use nalgebra::{DMatrix, DVector};
    pub use ndarray::{Array1, Array2, ArrayView2};
    pub use rand::{Rng as _, SeedableRng as _};
    pub use tandem_agents::{
        Agent, BatchPolicy, Critic, Ddpg, DdpgConfig, Dqn, DqnConfig, EpisodicAgent, Mode,
        OffPolicyAgent, OffPolicyLoop, Reinforce, ReinforceConfig, ReplayBuffer, Sac, SacConfig,
    };
    pub use tandem_algos::driver::{drive, Algorithm};
    pub use tandem_algos::{AlgoError, Checkpoints, Ephemeral, InMemory, MakeEnv, Problem};
    pub use tandem_core::seeding::rng_from_seed;
    pub use tandem_core::{Action, Rng, SeedStream, Space};
    pub use tandem_dynamics::classic::{CartPole, CartPoleParams, GymPendulum, GymPendulumParams};
    pub use tandem_dynamics::Plant;
    pub use tandem_envs::{Env, FnTask, ObservedTask, PlantEnv, Step, Task, TimeLimit};
    pub use tandem_models::{
        DynamicsModel, EarlyStop, EnsembleConfig, FitConfig, MlpModel, MlpModelConfig, ModelInput,
        PlantModel, Prediction, ProbabilisticEnsemble, Propagation, Transitions,
        TransitionsBuilder,
    };
    pub use tandem_planners::{
        Bounds, Cem, CemConfig, Ilqr, IlqrConfig, Mppi, MppiConfig, Objective, Plan, Planner,
    };
}

/// The registered environment `id` with its time limit: `tandem-envs`'s own ([`envs::make`]),
/// then the papers' ([`robots::make`]), then gymnasium's MuJoCo tasks ([`mujoco::make`]; without
/// the feature `mujoco` their ids give an error saying how to enable it).
///
/// ```
/// assert_eq!(tandem::make_env("CartPole-v1").unwrap().max_episode_steps(), Some(500));
/// assert!(tandem::make_env("Nope-v0").is_err());
/// ```
pub fn make_env(id: &str) -> Result<Box<dyn envs::Env>, envs::EnvError> {
    match envs::make(id) {
        Err(envs::EnvError::Unknown(_)) => match robots::make(id) {
            Err(envs::EnvError::Unknown(_)) => mujoco::make(id),
            made => made,
        },
        made => made,
    }
}

/// Every environment [`make_env`] can make, in its order: `tandem-envs`'s, `tandem-robots`',
/// gymnasium's MuJoCo tasks.
pub fn registered_envs() -> Vec<envs::EnvSpec> {
    let mut specs = envs::registered();
    specs.extend(robots::registered());
    specs.extend(mujoco::registered());
    specs
}

/// Has mimalloc (the global allocator of the `tandem` program and its benches) keep the memory
/// it frees for reuse, instead of returning it to the OS a second later. Model-based loops allocate
/// the same large buffers seconds apart: MBPO's 100 000 imagined rollouts and their network
/// activations once per refit. Memory returned in between is faulted in and zeroed again on the
/// next use, which was half of MBPO's rollout time. The resident size then stays at the run's
/// peak. A pipeline with its own binary and mimalloc as its allocator can call it first thing.
pub fn keep_freed_memory() {
    // SAFETY: sets an integer option; mimalloc reads it when it next considers purging.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) }
}

/// mimalloc 3's `mi_option_purge_delay` (milliseconds; -1: never purge), which `libmimalloc-sys`
/// names no constant for.
const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// The README's Rust blocks, compiled and run as doc-tests (`cargo test --doc -p tandem`), so
/// that its quickstart keeps working.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// The code of `docs/compose.md`, built and run as doc-tests so the page cannot drift from the
/// API.
#[cfg(doctest)]
#[doc = include_str!("../docs/compose.md")]
pub struct ComposeDocs;

#[cfg(test)]
mod tests {
    /// The option index is mimalloc's purge delay: its default of 1000 ms, then never.
    #[test]
    fn keep_freed_memory_turns_purging_off() {
        // SAFETY: reads an integer option.
        let get = || unsafe { libmimalloc_sys::mi_option_get(super::PURGE_DELAY) };
        if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
            assert_eq!(get(), 1000);
        }
        super::keep_freed_memory();
        assert_eq!(get(), -1);
    }
}
