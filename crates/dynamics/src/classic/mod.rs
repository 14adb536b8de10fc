//! Classic low-dimensional plants.
//!
//! - [`CartPole`]: gymnasium's `CartPole-v1` physics (explicit Euler, force input).
//! - [`GymPendulum`]: gymnasium's `Pendulum-v1` dynamics (semi-implicit Euler, torque input).
//!
//! Each plant has an allocation-free array step (`step_array`) for hot loops; the [`Plant`]
//! implementation wraps it for callers that work with `nalgebra` vectors.
//!
//! [`Plant`]: crate::Plant

mod cartpole;
mod gym_pendulum;

pub use cartpole::{CartPole, CartPoleParams};
pub use gym_pendulum::{GymPendulum, GymPendulumParams};
