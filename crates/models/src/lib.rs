//! Dynamics models: the [`DynamicsModel`] trait, the transition data they are fitted on, and the
//! models the papers use.
//!
//! What this crate owns:
//! * [`DynamicsModel`]: batched one-step prediction ([`ModelInput`] → [`Prediction`]: next state,
//!   and where the model has them its variance, reward and termination probability) and `fit` on
//!   [`Transitions`] (built by [`TransitionsBuilder`]; `with_prev_action` adds each state's
//!   previous action to it, p1's one-step-back data),
//!   returning a [`FitReport`] of training and held-out loss per epoch; and linearization
//!   ([`DynamicsModel::linearize`]: Jacobians at a batch of points, finite differences of one
//!   batched `predict` by default, [`linearize_fd`]). It is the one model trait planners use,
//!   sampling MPC and iLQR alike. Object-safe: planners take `&dyn DynamicsModel`.
//! * [`ModelEnv`] and [`branched_rollouts`]: any model under a `tandem_envs::Task`, one
//!   imagined episode behind the `Env` trait or N branched rollouts from real states at once,
//!   with reward and termination from the task or from the model ([`Judges`]).
//! * [`PlantModel`]: any known [`tandem_dynamics::Plant`] as a deterministic model, so "plan on
//!   the true physics" and "plan on a learned model" are the same call; [`InActions`]: a model
//!   seen through a task's actions, so a planner plans in the units the agent acts in.
//! * The learned models, each with a serde `Config` whose `Default` is its paper's setting:
//!   [`MlpModel`] (p2 eq. 1: state change, reward, termination), [`ResidualModel`] (p0:
//!   `f_idl(s, a) + d_θ(s, a)` over any plant), [`IncrementalModel`] (p1 eqs. 4–6:
//!   `s_t + L_θ Δa_t`), [`ProbabilisticEnsemble`] (p3 / PETS / MBPO: Gaussian members, elites,
//!   three [`Propagation`] modes), `PixelModel` (feature `pixels`; p2 §3.2: an
//!   action-conditioned conv encoder–decoder predicting the next binary frame, reward and
//!   termination from four frames; `PixelEpisodes` its data, `PixelModelEnv` its imagined
//!   episodes, per-channel F1).
//! * [`TvlgFit`]: time-varying linear-Gaussian dynamics from trajectories with a GMM
//!   normal-inverse-Wishart prior (p4 / guided policy search). Time-varying, so not a
//!   `DynamicsModel`: it returns [`TvlgDynamics`] for LQR-type trajectory optimizers.
//!   [`TvlgPolicyFit`] linearizes a policy the same way (GPS's policy prior): the regression of
//!   its actions on the sampled states under a GMM prior, a [`TvlgPolicy`].
//! * Data helpers: [`TransitionsBuilder`], [`Transitions::from_episode`],
//!   [`Transitions::validate`], holdout splits.
//!
//! Conventions shared by the learned models: inputs and targets are standardized inside the model
//! (statistics of the latest fit's training rows), through one fit path that every learned
//! transition model shares (holdout split, targets, standardization, commit on success); networks are `tandem_nn::Mlp` in `f32`, data
//! and predictions `f64`. Weight initialization comes from the config's `seed`, shuffling,
//! dropout, bootstraps and the holdout split from [`FitConfig::seed`]: the same seeds give
//! bit-identical fits. Each fit continues from the current weights and optimizer state. Bad data
//! (wrong widths, empty, non-finite: the array and row are named) and a loss that turns
//! non-finite ([`ModelError::Diverged`], with epoch and step) are errors, and a failed fit leaves
//! the model exactly as it was.
//!
//! # Example: p0's difference model over a known plant
//!
//! ```
//! use nalgebra::{dvector, DVector};
//! use ndarray::array;
//! use tandem_core::seeding::rng_from_seed;
//! use tandem_dynamics::Plant;
//! use tandem_models::{
//!     DynamicsModel, FitConfig, ModelInput, OptimizerConfig, PlantModel, ResidualModel,
//!     ResidualModelConfig, TransitionsBuilder,
//! };
//!
//! /// `x' = x + 0.1 u`, with a gain the real system does not quite have.
//! struct Integrator(f64);
//! impl Plant for Integrator {
//!     fn state_dim(&self) -> usize { 1 }
//!     fn action_dim(&self) -> usize { 1 }
//!     fn dt(&self) -> f64 { 0.1 }
//!     fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
//!         dvector![x[0] + self.0 * u[0]]
//!     }
//! }
//!
//! // Real transitions from the "true" system (gain 0.13).
//! let real = Integrator(0.13);
//! let mut data = TransitionsBuilder::new(1, 1);
//! for i in 0..400 {
//!     let (x, u) = ((i % 20) as f64 / 10.0 - 1.0, (i / 20) as f64 / 10.0 - 1.0);
//!     let next = real.step(&dvector![x], &dvector![u]);
//!     data.push([x], &[u], next.as_slice(), 0.0, false).unwrap();
//! }
//! let data = data.build();
//!
//! let cfg = ResidualModelConfig {
//!     hidden: vec![32, 32],
//!     dropout: 0.0,
//!     optimizer: OptimizerConfig::adam(3e-3),
//!     ..ResidualModelConfig::default()
//! };
//! let mut model = ResidualModel::new(Integrator(0.1), cfg).unwrap();
//! let report = model
//!     .fit(&data, &FitConfig { epochs: 100, batch_size: 32, ..FitConfig::default() })
//!     .unwrap();
//! assert_eq!(report.train_loss.len(), 100);
//!
//! // A planner sees only `&dyn DynamicsModel`: the idealized plant and the corrected model are
//! // interchangeable.
//! let idealized = PlantModel::new(Integrator(0.1));
//! let (x, u) = (array![[0.0]], array![[1.0]]);
//! let input = ModelInput::new(x.view(), u.view());
//! let mut rng = rng_from_seed(0);
//! for (m, expected) in [(&idealized as &dyn DynamicsModel, 0.1), (&model, 0.13)] {
//!     let p = m.predict(&input, &mut rng).unwrap();
//!     assert!((p.next_states[[0, 0]] - expected).abs() < 0.005);
//! }
//! ```
//!
//! Dependencies: `tandem-dynamics` (the plants residual and plant models wrap), `tandem-envs` (the `Task` model environments are judged by), `tandem-nn`
//! (networks and optimizers), `candle-core`/`candle-nn` (optional, feature `pixels`: the pixel
//! model's convolutions, transposed convolutions and autograd, through
//! `tandem_nn::candle_ext::ParamSet`), `ndarray` (batched data), `nalgebra` (plant states and the small
//! matrices of the TVLG fit and its GMM: at most `2 dX + dU` square, where faer has no advantage,
//! so faer is not used), `rand`/`rand_distr` (seeded sampling), `serde`, `thiserror`. An
//! ensemble's members forward and train side by side through `tandem-nn`'s row dealing.

#![warn(missing_docs)]

mod data;
mod ensemble;
mod gmm;
mod in_actions;
mod incremental;
mod mlp_model;
mod model;
mod model_env;
#[cfg(feature = "pixels")]
mod pixel_model;
mod plant_model;
mod policy_fit;
mod residual;
#[cfg(test)]
mod testutil;
mod train;
mod tvlg;

pub use data::{holdout_indices, TransitionsBuilder};
pub use ensemble::{EnsembleConfig, MemberData, ProbabilisticEnsemble, Propagation};
pub use gmm::Gmm;
pub use in_actions::InActions;
pub use incremental::{GainStructure, IncrementalModel, IncrementalModelConfig};
pub use mlp_model::{MlpModel, MlpModelConfig};
pub use model::{
    linearize_fd, DynamicsModel, EarlyStop, FitConfig, FitReport, Linearization, ModelError,
    ModelInput, Prediction, Transitions,
};
pub use model_env::{
    branched_rollouts, canonical_pair, Imagined, Judge, Judges, ModelEnv, RolloutPolicy,
};
#[cfg(feature = "pixels")]
pub use pixel_model::{
    f1_score, PixelBatch, PixelEpisodes, PixelFit, PixelLayers, PixelModel, PixelModelConfig,
    PixelModelEnv, PixelPrediction,
};
pub use plant_model::PlantModel;
pub use policy_fit::{PolicyFitConfig, TvlgPolicy, TvlgPolicyFit};
pub use residual::{ResidualModel, ResidualModelConfig};
pub use train::{OptimizerConfig, Standardizer};
pub use tvlg::{GmmPriorConfig, TvlgConfig, TvlgDynamics, TvlgFit};
