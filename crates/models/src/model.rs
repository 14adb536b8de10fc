//! The [`DynamicsModel`] trait and the data it is fitted on.

use nalgebra::DMatrix;
use ndarray::{Array1, Array2, ArrayView2};
use tandem_core::Rng;

use crate::data::check_input;
use crate::ensemble::Propagation;

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
    /// Something the caller needs was not given or not predicted (a reward from a model that
    /// learns none).
    #[error("missing input: {0}")]
    MissingInput(String),
    /// Anything else, with a message.
    #[error("{0}")]
    Other(String),
}

/// Transitions `(s, a, s', r, terminated)`, one row per transition. A model that conditions on
/// more than the state (p1's incremental model reads the previous action) finds it in the state:
/// [`crate::TransitionsBuilder::with_prev_action`] records `[s, a_{t−1}]` rows.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Transitions {
    /// States `s_t`, `N x S`.
    pub states: Array2<f64>,
    /// Actions `a_t`, `N x A`.
    pub actions: Array2<f64>,
    /// Next states `s_{t+1}`, `N x S`.
    pub next_states: Array2<f64>,
    /// Rewards `r_t`, length `N`.
    pub rewards: Array1<f64>,
    /// Whether `s_{t+1}` is terminal, length `N`.
    pub terminated: Array1<bool>,
}

/// A batch to predict from: `B` states and actions.
#[derive(Debug, Clone)]
pub struct ModelInput<'a> {
    /// States, `B x S`.
    pub states: ArrayView2<'a, f64>,
    /// Actions, `B x A`.
    pub actions: ArrayView2<'a, f64>,
    /// How a model of several members propagates this batch, in place of its own setting (a
    /// planner's choice of PETS's TS-1, TS-∞ or expectation); a model of one member ignores it.
    pub propagation: Option<Propagation>,
}

impl<'a> ModelInput<'a> {
    /// A batch of states and actions, propagated as the model is set to.
    pub fn new(states: ArrayView2<'a, f64>, actions: ArrayView2<'a, f64>) -> Self {
        Self {
            states,
            actions,
            propagation: None,
        }
    }

    /// The same batch, propagated with `propagation` whatever the model's own setting.
    pub fn with_propagation(self, propagation: Option<Propagation>) -> Self {
        Self {
            propagation,
            ..self
        }
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

impl Prediction {
    /// A prediction of next states only (no variance, reward or termination), as deterministic
    /// models give.
    pub fn deterministic(next_states: Array2<f64>) -> Self {
        Self {
            next_states,
            variance: None,
            rewards: None,
            terminal_prob: None,
        }
    }
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
    /// Stop when the held-out loss stops improving, keeping the weights of the last epoch that
    /// improved it (needs a holdout); `None` trains every epoch and keeps the last.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub early_stop: Option<EarlyStop>,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            epochs: 50,
            batch_size: 256,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        }
    }
}

impl FitConfig {
    /// Checks the ranges a fit relies on.
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.epochs == 0 || self.batch_size == 0 {
            return Err(ModelError::Other(format!(
                "fit.epochs {} and fit.batch_size {} must be >= 1",
                self.epochs, self.batch_size
            )));
        }
        if !(0.0..1.0).contains(&self.holdout_fraction) {
            return Err(ModelError::Other(format!(
                "fit.holdout_fraction is {}, must lie in [0, 1)",
                self.holdout_fraction
            )));
        }
        self.early_stop.as_ref().map_or(Ok(()), EarlyStop::validate)
    }
}

/// Early stopping of a fit, as mbrl-lib's `ModelTrainer` does it: an epoch improves when the
/// held-out loss of some member (the only one, for a single network) falls below that member's
/// best by more than `improvement_threshold` of its size; after `patience` epochs without one
/// the fit stops, and the model goes back to the weights of the last epoch that improved.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EarlyStop {
    /// Epochs without an improvement before the fit stops (at least 1).
    pub patience: usize,
    /// The relative drop `(best − loss) / |best|` that counts as an improvement.
    pub improvement_threshold: f64,
}

impl Default for EarlyStop {
    /// mbrl-lib's threshold (0.01) with a patience of 5 epochs.
    fn default() -> Self {
        Self {
            patience: 5,
            improvement_threshold: 0.01,
        }
    }
}

impl EarlyStop {
    /// Checks that the patience is at least 1 and the threshold finite and at least 0.
    pub fn validate(&self) -> Result<(), ModelError> {
        let threshold = self.improvement_threshold;
        if self.patience == 0 || !(threshold >= 0.0 && threshold.is_finite()) {
            return Err(ModelError::Other(format!(
                "early stopping with patience {} and improvement threshold {threshold}: the \
                 patience must be at least 1 and the threshold finite and at least 0",
                self.patience
            )));
        }
        Ok(())
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

/// The Jacobians of a model's next state (its mean) at one point `(x, u)`:
/// `x' ≈ x̄' + A δx + B δu`.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearization {
    /// `A = ∂x'/∂x`, `S x S`.
    pub a: DMatrix<f64>,
    /// `B = ∂x'/∂u`, `S x A`.
    pub b: DMatrix<f64>,
}

/// A dynamics model: batched prediction of the next state (and, where learned, its variance,
/// the reward and termination), fitted on transitions.
///
/// * Rows of a [`ModelInput`] are independent samples (a planner's population). What a model
///   conditions on besides the action is in its state: p1's incremental model, which reads the
///   previous action, is a model of `[s, a_{t−1}]` (see [`crate::IncrementalModel`]).
/// * Stochastic behaviour (the ensemble's member choice and sampling) draws from the `rng`
///   argument only; its mode is a setting of the model
///   (`ProbabilisticEnsemble::set_propagation`), which a batch may override
///   ([`ModelInput::with_propagation`]: a planner's particles), so planners stay model-agnostic.
/// * Linearization ([`DynamicsModel::linearize`]) is what trajectory optimizers (iLQR) need on
///   top of stepping: central finite differences of `predict` by default, analytic where a model
///   knows better (a [`crate::PlantModel`] uses [`tandem_dynamics::Plant::linearize`]).
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

    /// Jacobians of the predicted next state at each row of `input` (`B` points, one
    /// [`Linearization`] each).
    ///
    /// The default takes central differences of [`DynamicsModel::predict`] with step
    /// `1e-6·max(1, |z_i|)` per coordinate, all `2B(S + 2A)` perturbed points in one batched
    /// `predict` call (one network pass for a learned model). `rng` is passed to that call: a
    /// stochastic model should propagate its mean (or be given a generator that makes every row
    /// draw alike), or the differences mix different samples.
    fn linearize(
        &self,
        input: &ModelInput<'_>,
        rng: &mut Rng,
    ) -> Result<Vec<Linearization>, ModelError> {
        linearize_fd(self, input, rng)
    }
}

/// Central-difference Jacobians of `model`'s `predict` at each row of `input`: the default of
/// [`DynamicsModel::linearize`], and the test oracle of analytic overrides.
pub fn linearize_fd<M: DynamicsModel + ?Sized>(
    model: &M,
    input: &ModelInput<'_>,
    rng: &mut Rng,
) -> Result<Vec<Linearization>, ModelError> {
    let (n, m) = (model.state_dim(), model.action_dim());
    let t_len = check_input(input, n, m)?;
    // Coordinates perturbed per point: x, then u.
    let d = n + m;
    let rows = t_len * 2 * d;
    let mut xs = Array2::zeros((rows, n));
    let mut us = Array2::zeros((rows, m));
    let mut hs = vec![0.0; t_len * d];
    for t in 0..t_len {
        for k in 0..d {
            let z = if k < n {
                input.states[(t, k)]
            } else {
                input.actions[(t, k - n)]
            };
            let h = 1e-6 * z.abs().max(1.0);
            hs[t * d + k] = h;
            for (s, sign) in [(0, 1.0), (1, -1.0)] {
                let r = (t * d + k) * 2 + s;
                xs.row_mut(r).assign(&input.states.row(t));
                us.row_mut(r).assign(&input.actions.row(t));
                if k < n {
                    xs[(r, k)] += sign * h;
                } else {
                    us[(r, k - n)] += sign * h;
                }
            }
        }
    }
    let f = model
        .predict(&ModelInput::new(xs.view(), us.view()), rng)?
        .next_states;
    if f.dim() != (rows, n) {
        return Err(ModelError::Dim {
            what: "predicted next states for finite differences (rows x columns)".into(),
            expected: rows * n,
            got: f.len(),
        });
    }
    let mut out = Vec::with_capacity(t_len);
    for t in 0..t_len {
        let mut jac = DMatrix::zeros(n, d);
        for k in 0..d {
            let r = (t * d + k) * 2;
            let h = hs[t * d + k];
            for i in 0..n {
                jac[(i, k)] = (f[(r, i)] - f[(r + 1, i)]) / (2.0 * h);
            }
        }
        out.push(Linearization {
            a: jac.columns(0, n).into_owned(),
            b: jac.columns(n, m).into_owned(),
        });
    }
    if let Some(row) = out
        .iter()
        .position(|l| l.a.iter().chain(l.b.iter()).any(|v| !v.is_finite()))
    {
        return Err(ModelError::NonFinite {
            what: "model Jacobians".into(),
            row,
        });
    }
    Ok(out)
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

    fn linearize(
        &self,
        input: &ModelInput<'_>,
        rng: &mut Rng,
    ) -> Result<Vec<Linearization>, ModelError> {
        (**self).linearize(input, rng)
    }
}

/// Compile-time check that the trait stays object-safe.
const _: Option<&dyn DynamicsModel> = None;
