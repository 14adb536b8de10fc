//! The papers' own robots and scenes: plants, tasks and environments that exist for one paper's
//! experiments, kept out of the general crates so that those hold only reusable machinery.
//!
//! | module | what |
//! |---|---|
//! | [`dc_motor`] | p0's DC-motor pendulum ([`DcMotorPendulum`], voltage input) and its swing-up pair [`DcMotorPendulumEnv`] (`DcMotorPendulum-idealized-v0`, `DcMotorPendulum-real-v0`); reward [`dc_motor_pendulum_reward`] |
//! | [`leo`] | p0's Leo-like planar biped on a boom ([`leo::leo_plant`]) and its walking task [`LeoWalkTask`], [`LeoEnv`] (`Leo-v0`, `Leo-true-v0`): the idealized and true robots, the authors' reward and fall |
//! | [`leg2r`] | p3's 2R leg on a test rig ([`leg2r::leg2r_plant`], from `assets/leg2r.urdf`: 500 Hz, 3 N m joints) tracking a semi-elliptical foot trajectory, [`Leg2REnv`] (`Leg2R-v0`, `Leg2R-real-v0`); reward (15) [`leg2r_reward`] |
//! | [`pixel_maze`] | p2's crowd-navigation maze as 16×16 RGB images, 5 discrete actions, [`PixelMazeEnv`] (`PixelMaze-v0`, `PixelMaze-v1`; v1 is the authors' released layout) |
//! | [`p4`] | p4's manipulation scenes (MJCF in `scenes/`): conditions, forward kinematics, costs, the pusher and the reacher as `Task`s; with the feature `mujoco` also the door, and the scenes as plants |
//! | [`make`], [`make_unwrapped`], [`registered`] | this crate's part of the environment registry (the facade's `make_env` lists `tandem-envs`' first, then these, then `tandem-mujoco`'s) |
//!
//! The generic pieces these robots are built from stay in the general crates: rigid bodies,
//! actuators, contact and `RigidBodyPlant` in `tandem-dynamics`, `Task`/`PlantEnv` and the
//! wrappers in `tandem-envs`, the MuJoCo binding in `tandem-mujoco`. No general crate depends on
//! this one; the pipelines of the papers (`tandem-algos`, `tandem-studies`) and the facade do.
//!
//! Feature `mujoco` (off by default): forwards to `tandem-mujoco/mujoco`, which links MuJoCo, so
//! that p4's scenes load as plants and the door's cost gets MuJoCo's kinematics.
//!
//! Dependencies: `tandem-core` (spaces, actions, seeding), `tandem-dynamics` (the plants' rigid
//! bodies, actuators and the `Plant` trait), `tandem-envs` (`Env`, `Task`, `PlantEnv`, the
//! registry helpers), `tandem-mujoco` (p4's scenes as MuJoCo plants and the reacher's task
//! formulas), `nalgebra` (plant vectors), `rand` (seeded resets), `serde` (parameters and costs
//! in recorded settings).

#![warn(missing_docs)]

pub mod dc_motor;
pub mod leg2r;
pub mod leo;
pub mod p4;
pub mod pixel_maze;
mod registry;

pub use dc_motor::{
    dc_motor_pendulum_reward, wrap_angle, DcMotorPendulum, DcMotorPendulumEnv,
    DcMotorPendulumEnvExt, DcMotorPendulumParams, DcMotorPendulumTask, PendulumModel,
    DC_MOTOR_PENDULUM_STEPS, M_IDEALIZED, M_REAL,
};
pub use leg2r::{
    leg2r_reward, FootTarget, FootTrajectory, Leg2RConfig, Leg2REnv, Leg2REnvExt, Leg2RModel,
    Leg2RTask, LEG2R_STEPS,
};
pub use leo::{
    leo_parts, Gait, LeoEnv, LeoEnvExt, LeoModel, LeoStart, LeoWalkTask, LeoWork, LEO_REWARD_FALL,
    LEO_REWARD_PER_JOULE, LEO_REWARD_PER_METRE, LEO_REWARD_PER_STEP, LEO_STEPS,
};
pub use pixel_maze::{
    ObstaclePlacement, PixelMazeEnv, PixelMazeLayout, PIXEL_MAZE_GRID, PIXEL_MAZE_OBSTACLES,
    PIXEL_MAZE_PIXELS,
};
pub use registry::{make, make_unwrapped, registered};
