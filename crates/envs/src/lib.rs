//! Environments with gymnasium semantics: the [`Env`] trait, tasks (reward, termination and reset
//! over a [`tandem_dynamics::Plant`]), idealized/true pairs for sim-to-real gaps, and the wrappers
//! every training loop needs.
//!
//! | item | what |
//! |---|---|
//! | [`Env`], [`Step`], [`EnvError`] | the trait, with gymnasium's `terminated`/`truncated` |
//! | [`Task`], [`PlantEnv`] | start, observation, control, reward, termination and episode length over a plant's state; an environment over any [`tandem_dynamics::Plant`] plus a task (the classic environments below are instances) |
//! | [`CartPoleEnv`] (`CartPole-v1`), [`PendulumEnv`] (`Pendulum-v1`) | exact to gymnasium 1.x |
//! | [`PixelMazeEnv`] (`PixelMaze-v0`, `PixelMaze-v1`) | p2's crowd-navigation maze as 16×16 RGB images, 5 discrete actions; v1 is the authors' released layout |
//! | [`DcMotorPendulumEnv`] (`DcMotorPendulum-idealized-v0`, `DcMotorPendulum-real-v0`) | p0's swing-up pair; reward [`dc_motor_pendulum_reward`] |
//! | [`Leg2REnv`] (`Leg2R-v0`, `Leg2R-real-v0`) | p3's 2R leg on a test rig (URDF, 500 Hz, 3 N m joints) tracking a semi-elliptical foot trajectory; reward (15) [`leg2r_reward`]; idealized/true pair |
//! | [`LeoEnv`] (`Leo-v0`, `Leo-true-v0`), [`LeoWalkTask`] | p0's Leo-like biped walking: the idealized and true robots, the authors' reward and fall |
//! | [`WithPrevAction`] | a task whose state carries the previous control, for models that condition on it |
//! | [`make`], [`make_unwrapped`], [`registered`] | the registry |
//! | [`TimeLimit`], [`SampleCounter`], [`ClipAction`], [`RescaleAction`], [`TransformObservation`] | wrappers |
//!
//! Dependencies: `tandem-core` (spaces, actions, seeding), `tandem-dynamics` (the plants tasks
//! run on), `rand` (seeded resets), `serde` (configs), `thiserror` (errors).

mod cartpole;
mod dc_motor;
mod env;
mod leg2r;
mod leo;
mod pendulum;
mod pixel_maze;
mod prev_action;
mod registry;
mod task;
pub mod wrappers;

pub use cartpole::{CartPoleEnv, CartPoleTask};
pub use dc_motor::{
    dc_motor_pendulum_reward, wrap_angle, DcMotorPendulumEnv, DcMotorPendulumTask, PendulumModel,
    DC_MOTOR_PENDULUM_STEPS,
};
pub use env::{check_state, round_to_f32, Env, EnvError, Step};
pub use leg2r::{
    leg2r_reward, FootTarget, FootTrajectory, Leg2RConfig, Leg2REnv, Leg2RModel, Leg2RTask,
    LEG2R_STEPS,
};
pub use leo::{
    leo_parts, Gait, LeoEnv, LeoModel, LeoStart, LeoWalkTask, LeoWork, LEO_REWARD_FALL,
    LEO_REWARD_PER_JOULE, LEO_REWARD_PER_METRE, LEO_REWARD_PER_STEP, LEO_STEPS,
};
pub use pendulum::{angle_normalize, pendulum_reward, PendulumEnv, PendulumTask};
pub use pixel_maze::{
    ObstaclePlacement, PixelMazeEnv, PixelMazeLayout, PIXEL_MAZE_GRID, PIXEL_MAZE_OBSTACLES,
    PIXEL_MAZE_PIXELS,
};
pub use prev_action::WithPrevAction;
pub use registry::{make, make_unwrapped, registered, EnvSpec};
pub use tandem_core::{Action, Space};
pub use task::{clip_to, control_dim, PlantEnv, Task, TaskEpisodes};
pub use wrappers::{
    ClipAction, NormalizeObservation, ObservationHook, RescaleAction, RunningNormalizer,
    SampleCount, SampleCounter, TimeLimit, TransformObservation,
};
