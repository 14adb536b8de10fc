//! p0's DC-motor pendulum: the plant ([`plant`]: voltage input, RK4 with substeps, idealized and
//! true masses) and its swing-up task ([`mod@env`]: `DcMotorPendulum-idealized-v0`,
//! `DcMotorPendulum-real-v0`).

pub mod env;
pub mod plant;

pub use env::*;
pub use plant::*;
