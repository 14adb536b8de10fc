//! p0's Leo-like planar biped: the plant ([`plant`]: URDF, DC motors, PD shoulder, ground
//! contact) and its walking task as an idealized/true pair ([`mod@env`]: `Leo-v0`, `Leo-true-v0`).

pub mod env;
pub mod plant;

pub use env::*;
pub use plant::*;
