//! Known physics: the [`Plant`] trait and everything that implements it.
//!
//! A plant is a deterministic discrete-time system `x_{t+1} = f(x_t, u_t)` with a control period
//! [`Plant::dt`]. Idealized and true systems of the papers are two parameter sets of one plant, so
//! a learned model can be trained on the difference between them.
//!
//! This crate owns
//! - the [`Plant`] trait and its finite-difference [`Plant::linearize`] default ([`linearize_fd`]),
//! - [`integrate`]: fixed-step integrators (explicit Euler, RK4) for continuous-time dynamics,
//! - classic plants (cart-pole, gymnasium pendulum),
//! - [`rigid`]: rigid bodies from URDF (kinematics, Jacobians, RNEA, CRBA, ABA, analytical
//!   derivatives, COM, energies) in Pinocchio's Model/Data style; [`actuators`] (DC motor, joint
//!   friction, PD), [`contact`] (compliant ground contact), [`rigid_plant::RigidBodyPlant`] (a URDF
//!   robot as a [`Plant`], with idealized/true overrides); the papers' robots built from them
//!   (p0's DC-motor pendulum and Leo-like biped, p3's 2R leg) are `tandem-robots`',
//! - [`Clocked`]: any plant with a phase clock in its state, for tasks that track a periodic
//!   reference.
//!
//! Dependencies: `nalgebra` (states, small matrices and spatial algebra), `serde` (plant
//! parameters are readable from configs), `thiserror` (error types), `urdf-rs` (the only reader of
//! robot files), `quick-xml` (already under urdf-rs: a light pre-pass over the XML so that an
//! unknown joint type or an `<inertial>` without `<mass>`/`<inertia>` is reported with the
//! element's name, which urdf-rs's serde errors do not give), `libm` (pure-Rust `sincos` of the
//! joint angles: inlinable and free of glibc's rounding-mode save and restore, it made the CRBA on
//! the 7-DoF arm ~7% faster; musl's kernels, under 1 ulp).

#![warn(missing_docs)]

pub mod actuators;
pub mod classic;
mod clock;
pub mod contact;
pub mod integrate;
mod plant;
pub mod rigid;
pub mod rigid_plant;

pub use clock::Clocked;
pub use plant::{check_dims, linearize_fd, Plant, PlantError};
