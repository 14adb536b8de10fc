//! Rigid-body dynamics from URDF, in the line of RBDL and Pinocchio.
//!
//! An immutable [`Model`] (the robot, built from URDF by [`Model::from_urdf_str`]) and a reusable
//! [`Data`] workspace that the algorithms fill, one algorithm per file, read next to Featherstone's
//! *Rigid Body Dynamics Algorithms*:
//!
//! | algorithm | file | result |
//! |---|---|---|
//! | [`forward_kinematics`], [`frame_jacobian`] | `kinematics.rs` | `data.o_m_i`, `data.o_m_f`, `data.jacobian` |
//! | [`rnea`], [`nonlinear_effects`], [`gravity_torque`] | `rnea.rs` | `data.tau` |
//! | [`crba`] | `crba.rs` | `data.mass_matrix` |
//! | [`aba`] | `aba.rs` | `data.ddq` |
//! | [`rnea_derivatives`], [`aba_derivatives`] | `derivatives.rs` | `data.dtau_dq`, `data.ddq_dq`, ... |
//! | [`center_of_mass`], [`kinetic_energy`], [`potential_energy`] | `energy.rs` | `data.com`, ... |
//!
//! Conventions are Pinocchio's (and those of `tests/fixtures/pinocchio/*.json`): joint order
//! depth-first with siblings in alphabetical order of joint names, spatial vectors linear part
//! first, gravity `(0, 0, -9.81)`. All joints are 1-DoF, so `nq == nv`. The algorithms take
//! slices of length `nv` and panic on a wrong length (a programming error); validate user input
//! once with [`Model::check_state`].

mod aba;
mod crba;
mod data;
mod derivatives;
mod energy;
mod kinematics;
mod model;
mod rnea;
pub mod spatial;

pub use aba::aba;
pub use crba::crba;
pub use data::Data;
pub use derivatives::{
    aba_derivatives, aba_derivatives_fd, compute_minverse, rnea_derivatives,
    rnea_derivatives_tangent,
};
pub use energy::{center_of_mass, kinetic_energy, potential_energy};
pub use kinematics::{
    forward_kinematics, forward_kinematics_velocity, frame_jacobian, update_frame_placements,
};
pub use model::{
    Frame, JointKind, JointModel, Model, UrdfError, MAX_URDF_BYTES, MAX_XML_DEPTH, STANDARD_GRAVITY,
};
pub use rnea::{gravity_torque, nonlinear_effects, rnea};
pub use spatial::{Force, Inertia, Motion, Se3};
