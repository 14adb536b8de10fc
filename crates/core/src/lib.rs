//! Types that several tandem crates share, and nothing else: observation/action [`Space`]s,
//! the [`Action`] an agent hands to an environment, and [`seeding`] (one seeded generator type,
//! so every crate draws reproducible numbers the same way), the one running mean/variance
//! [`RunningNormalizer`] (network inputs in `tandem-nn`, observations in `tandem-envs`), and what
//! training loops and reports share: [`CurvePoint`]s of learning curves and [`LinearSchedule`]s
//! of settings that change by epoch. [`read_capped`] reads every input file a user names, up to
//! a stated cap ([`input`]). [`first_non_finite`] scans a buffer for NaN and infinities at
//! vector speed.
//!
//! Dependencies: `rand` and `rand_chacha` (a portable, serializable, seedable generator: a
//! checkpoint can store its exact state), `serde` (spaces and actions appear in configs and run
//! files), `thiserror` (the error type),
//! `num-traits` (one finiteness scan for `f32` and `f64`).

#![warn(missing_docs)]

pub mod curve;
pub mod finite;
pub mod input;
pub mod normalizer;
pub mod schedule;
pub mod seeding;
mod space;

pub use curve::CurvePoint;
pub use finite::first_non_finite;
pub use input::{read_capped, read_file_capped, MAX_CONFIG_BYTES, MAX_INPUT_BYTES};
pub use normalizer::{NormalizerError, NormalizerState, RunningNormalizer};
pub use schedule::LinearSchedule;
pub use seeding::{Rng, SeedStream};
pub use space::{Action, Space, SpaceError};
