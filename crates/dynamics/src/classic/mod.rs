//! Classic low-dimensional plants.
//!
//! - [`CartPole`]: gymnasium's `CartPole-v1` physics (explicit Euler, force input).
//! - [`GymPendulum`]: gymnasium's `Pendulum-v1` dynamics (semi-implicit Euler, torque input).
//! - [`DcMotorPendulum`]: the DC-motor-driven inverted pendulum of paper p0 (voltage input, RK4
//!   with substeps), with its idealized and true parameter sets
//!   ([`DcMotorPendulumParams::idealized`], [`DcMotorPendulumParams::real`]).
//!
//! Each plant has an allocation-free array step (`step_array`) for hot loops; the [`Plant`]
//! implementation wraps it for callers that work with `nalgebra` vectors.
//!
//! [`Plant`]: crate::Plant

mod cartpole;
mod dc_motor_pendulum;
mod gym_pendulum;

pub use cartpole::{CartPole, CartPoleParams};
pub use dc_motor_pendulum::{DcMotorPendulum, DcMotorPendulumParams, M_IDEALIZED, M_REAL};
pub use gym_pendulum::{GymPendulum, GymPendulumParams};
