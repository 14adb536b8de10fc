//! Real MuJoCo for tandem: gymnasium's MuJoCo v5 tasks (`HalfCheetah-v5`, `Hopper-v5`,
//! `Walker2d-v5`, `Ant-v5`, `InvertedPendulum-v5`, `Reacher-v5`, `Pusher-v5`) as environments,
//! and any MJCF scene as an environment or a [`tandem_dynamics::Plant`].
//!
//! Physics is MuJoCo's: this crate binds it, it does not re-implement it. The binding is
//! `mujoco-rs` (an optional dependency, enabled by the cargo feature `mujoco`), linked against
//! the `libmujoco.so.3.17.0` of the PyPI wheel `mujoco==3.17.0` that `scripts/setup-mujoco.sh`
//! installs under the repository's `.mujoco/` (see `docs/mujoco.md`). mujoco-rs is there because
//! it is the maintained safe wrapper of MuJoCo's C API on crates.io; it is pinned to `=7.0.0`,
//! which checks that the library is exactly 3.17.0.
//!
//! | item | feature | what |
//! |---|---|---|
//! | [`TaskKind`], [`TaskSpec`], [`Readout`], [`Outcome`] | always | the tasks' observation layouts, rewards (with gymnasium's float32 control costs and NumPy's summation order, [`numpy`]), reward terms, health, reset noise: pure functions, tested without the library |
//! | [`GymTask`] | always | a locomotion task as a `tandem_envs::Task` over `qpos ++ qvel`, for learned models (with the feature, `gym_task(id)` reads the model's `qpos0` from its MJCF) |
//! | [`make`], [`registered`], [`AVAILABLE`] | always | the registry: with the feature, `make("HalfCheetah-v5")` is the task with its time limit; without it, an error saying how to enable it |
//! | `Scene`, `MujocoEnv`, `MujocoPlant` | `mujoco` | a loaded MJCF model; an environment (gymnasium's task, or any scene); a plant (state `qpos ++ qvel`, batch step, finite-difference linearization) |
//!
//! A step after which MuJoCo flags a bad state (NaN or beyond ±1e10 in `qpos`, `qvel`, `qacc` or
//! `ctrl`, which MuJoCo answers by resetting the simulation or zeroing `ctrl`; full contact or
//! constraint buffers) is an error naming the quantity ([`MujocoError::Step`], in environments
//! `tandem_envs::EnvError::Simulation`), never the reset state. MJCF files are read up to
//! `tandem_core::MAX_INPUT_BYTES` (64 MiB).
//!
//! With the feature, replaying gymnasium 1.4.0's recorded episodes gives bit-identical `qpos`,
//! `qvel` and observations, bit-identical rewards for five tasks and rewards within 2.3e-16 for
//! Reacher and Pusher, whose norms gymnasium takes through BLAS (this crate's
//! `tests/gymnasium_replay.rs`, which allows 1e-12).
//!
//! Dependencies: `tandem-core` (spaces, seeding), `tandem-dynamics` (the `Plant` trait),
//! `tandem-envs` (the `Env` trait, `TimeLimit`), `nalgebra` (plant vectors), `rand` and
//! `rand_distr` (reset noise), `thiserror` (errors), optional `mujoco-rs` (MuJoCo).
//!
//! p4's own MJCF scenes (pusher, door) and their tasks are `tandem-robots`' (`p4`), built on the
//! `Scene`/`MujocoPlant` here.

#![warn(missing_docs)]

mod gym_task;
pub mod numpy;
mod registry;
#[cfg(feature = "mujoco")]
mod sim;
mod task;

use std::path::PathBuf;

pub use gym_task::GymTask;
#[cfg(feature = "mujoco")]
pub use registry::gym_task;
pub use registry::{assets_dir, make, registered, AVAILABLE};
#[cfg(feature = "mujoco")]
pub use sim::{MujocoEnv, MujocoPlant, Scene};
pub use task::{Outcome, Readout, TaskKind, TaskSpec, MAX_TERMS};

/// Errors of loading MuJoCo models and of stepping them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MujocoError {
    /// The linked MuJoCo library is not the version the bindings expect.
    #[error(
        "the linked MuJoCo library is version {linked}, tandem needs {expected} \
         (run scripts/setup-mujoco.sh)"
    )]
    Version {
        /// `mj_version()` of the loaded library.
        linked: u32,
        /// The version the bindings were written for.
        expected: u32,
    },
    /// An MJCF file could not be loaded.
    #[error("cannot load MJCF {}: {message}", path.display())]
    Load {
        /// The file.
        path: PathBuf,
        /// MuJoCo's (or our) explanation.
        message: String,
    },
    /// The model does not fit its use (dimensions of a task, missing bodies).
    #[error("MJCF {}: {message}", path.display())]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// MuJoCo raised a warning during a step after which the result is not the model's physics
    /// (it reset the simulation, zeroed `ctrl`, or dropped contacts or constraints).
    #[error("MuJoCo step failed at substep {substep} of {substeps} (t = {time} s): {problem}")]
    Step {
        /// What went bad: `qpos`, `qvel`, `qacc`, `ctrl`, `contacts` or `constraints`.
        quantity: &'static str,
        /// The explanation, naming the quantity's index where MuJoCo gives one.
        problem: String,
        /// The failed `mj_step` call, counted from 1, of the step's frame skip.
        substep: usize,
        /// The frame skip.
        substeps: usize,
        /// Simulation time before the failed substep, in seconds.
        time: f64,
    },
}
