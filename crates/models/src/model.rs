//! The [`DynamicsModel`] trait and the data it is fitted on.

use ndarray::{Array1, Array2, ArrayView2};
use tandem_core::Rng;

/// Errors of models: bad data, bad dimensions, a fit that diverged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// Arrays whose shapes do not fit the model or each other.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    Dim {
        /// Which array.
        what: String,
        /// Expected size.
        expected: usize,
        /// Size given.
        got: usize,
    },
    /// No data to fit on.
    #[error("empty dataset")]
    Empty,
    /// A NaN or infinite value in the data.
    #[error("non-finite value in {what} at row {row}")]
    NonFinite {
        /// Which array.
        what: String,
        /// Its row.
        row: usize,
    },
    /// The loss became non-finite during a fit; the model was left as it was before the fit.
    #[error("loss became non-finite at epoch {epoch}, step {step}; model left unchanged")]
    Diverged {
        /// Epoch of the failure.
        epoch: usize,
        /// Optimizer step within the epoch.
        step: usize,
    },
    /// An input the model needs was not given (the incremental model needs previous actions).
    #[error("missing input: {0}")]
    MissingInput(String),
    /// Anything else, with a message.
    #[error("{0}")]
    Other(String),
}

/// Transitions `(s, a, s', r, terminated)` with the previous state and action of each (p1 learns
/// from the one-step-back data `{s_{t-1}, a_{t-1}, s_t, a_t}`), one row per transition.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Transitions {
    /// States `s_t`, `N x S`.
    pub states: Array2<f64>,
    /// Actions `a_t`, `N x A`.
    pub actions: Array2<f64>,
    /// Previous states `s_{t-1}` (at the start of an episode, where there is none, `s_t`
    /// itself), `N x S`.
    pub prev_states: Array2<f64>,
    /// Previous actions `a_{t-1}` (zeros at the start of an episode), `N x A`.
    pub prev_actions: Array2<f64>,
    /// Next states `s_{t+1}`, `N x S`.
    pub next_states: Array2<f64>,
    /// Rewards `r_t`, length `N`.
    pub rewards: Array1<f64>,
    /// Whether `s_{t+1}` is terminal, length `N`.
    pub terminated: Array1<bool>,
}

/// A batch to predict from: `B` states and actions (and previous actions for models that use
/// them).
#[derive(Debug, Clone)]
pub struct ModelInput<'a> {
    /// States, `B x S`.
    pub states: ArrayView2<'a, f64>,
    /// Actions, `B x A`.
    pub actions: ArrayView2<'a, f64>,
    /// Previous actions, `B x A`, for models that condition on them.
    pub prev_actions: Option<ArrayView2<'a, f64>>,
}

impl<'a> ModelInput<'a> {
    /// A batch of states and actions.
    pub fn new(states: ArrayView2<'a, f64>, actions: ArrayView2<'a, f64>) -> Self {
        Self {
            states,
            actions,
            prev_actions: None,
        }
    }

    /// Adds previous actions.
    pub fn with_prev_actions(mut self, prev_actions: ArrayView2<'a, f64>) -> Self {
        self.prev_actions = Some(prev_actions);
        self
    }
}

/// A batched prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Next states (mean, or a sample for stochastic propagation), `B x S`.
    pub next_states: Array2<f64>,
    /// Per-component variance of the next state, for probabilistic models.
    pub variance: Option<Array2<f64>>,
    /// Predicted rewards, for models that learn them.
    pub rewards: Option<Array1<f64>>,
    /// Predicted probability that the next state is terminal, for models that learn it.
    pub terminal_prob: Option<Array1<f64>>,
}

/// Settings of one fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitConfig {
    /// Passes over the training data.
    pub epochs: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Fraction of the data held out to report (and select on) held-out loss.
    pub holdout_fraction: f64,
    /// Seed for shuffling, dropout and holdout selection.
    pub seed: u64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            epochs: 50,
            batch_size: 256,
            holdout_fraction: 0.1,
            seed: 0,
        }
    }
}

/// What a fit reports.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct FitReport {
    /// Training loss after each epoch.
    pub train_loss: Vec<f64>,
    /// Held-out loss after each epoch (empty without a holdout).
    pub holdout_loss: Vec<f64>,
}

/// A dynamics model: batched prediction of the next state (and, where learned, its variance,
/// the reward and termination), fitted on transitions.
///
/// * Rows of a [`ModelInput`] are independent samples (a planner's population); a model that
///   needs the previous action (the incremental model) reads [`ModelInput::prev_actions`] and
///   returns [`ModelError::MissingInput`] without it; others ignore it.
/// * Stochastic behaviour (the ensemble's member choice and sampling) draws from the `rng`
///   argument only; its mode is a setting of the model
///   (`ProbabilisticEnsemble::set_propagation`), so planners stay model-agnostic.
/// * Object-safe: planners and pipelines hold `&dyn DynamicsModel` or `Box<dyn DynamicsModel>`
///   (which implements the trait too).
pub trait DynamicsModel {
    /// Length of the state vector.
    fn state_dim(&self) -> usize;

    /// Length of the action vector.
    fn action_dim(&self) -> usize;

    /// Predicts a batch. `rng` drives stochastic propagation (sampling an ensemble member or a
    /// Gaussian); deterministic models ignore it.
    fn predict(&self, input: &ModelInput<'_>, rng: &mut Rng) -> Result<Prediction, ModelError>;

    /// Fits the model on `data`. On error the model is left as it was.
    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError>;
}

impl<M: DynamicsModel + ?Sized> DynamicsModel for Box<M> {
    fn state_dim(&self) -> usize {
        (**self).state_dim()
    }

    fn action_dim(&self) -> usize {
        (**self).action_dim()
    }

    fn predict(&self, input: &ModelInput<'_>, rng: &mut Rng) -> Result<Prediction, ModelError> {
        (**self).predict(input, rng)
    }

    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError> {
        (**self).fit(data, cfg)
    }
}

/// Compile-time check that the trait stays object-safe.
const _: Option<&dyn DynamicsModel> = None;
