//! The papers' loops, generic over the traits: each composes a plant or environment, a model, a
//! planner and an agent.
//!
//! | module | paper | loop |
//! |---|---|---|
//! | [`p0`] | Rastogi et al., difference models | pre-train on the idealized plant; collect true samples, fit a residual model, retrain on plant + residual |
//! | [`adapter`] | (shared) | observation features, reward scale and settable exploration noise in front of any off-policy agent |

pub mod adapter;
pub mod p0;
