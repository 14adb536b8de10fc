//! Environments with gymnasium semantics: the [`Env`] trait, tasks (reward, termination and reset
//! over a [`tandem_dynamics::Plant`]), the classic gymnasium environments, and the wrappers every
//! training loop needs. The papers' own environments (idealized/true pairs for sim-to-real gaps,
//! the pixel maze) are `tandem-robots`', built on the same [`Task`] and [`PlantEnv`].
//!
//! | item | what |
//! |---|---|
//! | [`Env`], [`Step`], [`EnvError`] | the trait, with gymnasium's `terminated`/`truncated` |
//! | [`Task`], [`PlantEnv`] | start, observation, control, reward, termination and episode length over a plant's state; an environment over any [`tandem_dynamics::Plant`] plus a task (the classic environments below are instances) |
//! | [`CartPoleEnv`] (`CartPole-v1`), [`PendulumEnv`] (`Pendulum-v1`) | exact to gymnasium 1.x |
//! | [`FnTask`] | a task made of closures: the short path to a task of your own |
//! | [`ObservedTask`] | a task whose reward and termination read observations, for planning through a model learned on them |
//! | [`WithPrevAction`] | a task whose state carries the previous control, for models that condition on it |
//! | [`make`], [`make_unwrapped`], [`registered`] | the registry of the classic environments; [`make_from`], [`specs_of`] build the registries of other crates' environments from their tables ([`Registry`]) |
//! | [`Phase`], [`check_action`], [`check_state`] | the episode bookkeeping and checks of an environment, for environments written over this crate |
//! | [`TimeLimit`], [`SampleCounter`], [`ClipAction`], [`RescaleAction`], [`TransformObservation`] | wrappers |
//!
//! Dependencies: `tandem-core` (spaces, actions, seeding), `tandem-dynamics` (the plants tasks
//! run on), `rand` (seeded resets), `thiserror` (errors).

#![warn(missing_docs)]

mod cartpole;
mod env;
mod fn_task;
mod pendulum;
mod prev_action;
mod registry;
mod task;
pub mod wrappers;

pub use cartpole::{CartPoleEnv, CartPoleTask};
pub use env::{check_action, check_state, round_to_f32, Env, EnvError, Phase, Step};
pub use fn_task::FnTask;
pub use pendulum::{angle_normalize, pendulum_reward, PendulumEnv, PendulumTask};
pub use prev_action::WithPrevAction;
pub use registry::{make, make_from, make_unwrapped, registered, specs_of, EnvSpec, Registry};
pub use tandem_core::{Action, Space};
pub use task::{clip_to, control_dim, ObservedTask, PlantEnv, Task, TaskEpisodes};
pub use wrappers::{
    ClipAction, NormalizeObservation, ObservationHook, RescaleAction, RunningNormalizer,
    SampleCount, SampleCounter, TimeLimit, TransformObservation,
};
