//! The papers' loops, generic over the traits: each composes a plant or environment, a model, a
//! planner and an agent.
//!
//! | module | paper | loop |
//! |---|---|---|
//! | [`p0`] | Rastogi et al., difference models | pre-train on the idealized plant; collect true samples, fit a residual model, retrain on plant + residual |
//! | [`adapter`] | (shared) | observation features, reward scale and settable exploration noise in front of any off-policy agent |
//! | [`model_env`] | (shared) | an [`tandem_envs::Env`] over any [`tandem_models::DynamicsModel`] and a [`model_env::Task`] |

pub mod adapter;
pub mod model_env;
pub mod p0;
