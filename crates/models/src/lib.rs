//! Learned dynamics models: the [`DynamicsModel`] trait, transition datasets and fit reports, and
//! the models the papers use (MLP, residual over a known plant, incremental, probabilistic
//! ensemble, time-varying linear-Gaussian fit).
//!
//! Dependencies: `tandem-dynamics` (the plants residual models wrap), `tandem-nn` (networks),
//! `ndarray` (batched data), `nalgebra` (plant states), `rand`, `serde`, `thiserror`.

mod data;
mod ensemble;
mod gmm;
mod incremental;
mod mlp_model;
mod model;
mod plant_model;
mod residual;
#[cfg(test)]
mod testutil;
mod train;
mod tvlg;

pub use data::{holdout_indices, TransitionsBuilder};
pub use ensemble::{EnsembleConfig, MemberData, ProbabilisticEnsemble, Propagation};
pub use gmm::Gmm;
pub use incremental::{GainStructure, IncrementalModel, IncrementalModelConfig};
pub use mlp_model::{MlpModel, MlpModelConfig};
pub use model::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
pub use plant_model::PlantModel;
pub use residual::{ResidualModel, ResidualModelConfig};
pub use train::{OptimizerConfig, Standardizer};
pub use tvlg::{GmmPriorConfig, TvlgConfig, TvlgDynamics, TvlgFit};
