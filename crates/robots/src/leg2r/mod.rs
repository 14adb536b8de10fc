//! p3's 2R leg on a test rig: the plant ([`plant`], from `assets/leg2r.urdf`) and its tracking
//! task as an idealized/true pair ([`mod@env`]: `Leg2R-v0`, `Leg2R-real-v0`).

pub mod env;
pub mod plant;

pub use env::*;
pub use plant::*;
