//! What the learned models share: optimizer choice, standardization, the minibatch loop, and the
//! one fit path ([`Standardized::fit`]).

use ndarray::{Array2, ArrayView2};
use rand::seq::SliceRandom;
use tandem_core::Rng;
use tandem_nn::budget::MemoryEstimate;
use tandem_nn::{
    AdaGrad, AdaGradConfig, Adam, AdamConfig, Mlp, MlpWorkspace, NnError, Optimizer, Sgd, SgdConfig,
};

use crate::data::holdout_indices;
use crate::model::{EarlyStop, FitConfig, FitReport, ModelError, Transitions};

/// Which optimizer trains a network, with its settings (serde: `{ adam = { lr = 1e-3, ... } }`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum OptimizerConfig {
    /// Adam.
    Adam(AdamConfig),
    /// AdaGrad (p0's difference model).
    AdaGrad(AdaGradConfig),
    /// Plain or momentum SGD (p2's dynamics model).
    Sgd(SgdConfig),
}

impl OptimizerConfig {
    /// Adam with learning rate `lr` and otherwise PyTorch's defaults.
    pub fn adam(lr: f32) -> Self {
        OptimizerConfig::Adam(AdamConfig {
            lr,
            ..AdamConfig::default()
        })
    }

    /// AdaGrad with learning rate `lr` and otherwise PyTorch's defaults.
    pub fn adagrad(lr: f32) -> Self {
        OptimizerConfig::AdaGrad(AdaGradConfig {
            lr,
            ..AdaGradConfig::default()
        })
    }

    /// Plain SGD with learning rate `lr`.
    pub fn sgd(lr: f32) -> Self {
        OptimizerConfig::Sgd(SgdConfig {
            lr,
            ..SgdConfig::default()
        })
    }

    /// Checks the optimizer's ranges (a positive learning rate, moments in `[0, 1)`, ...).
    pub fn validate(&self) -> Result<(), ModelError> {
        match self {
            OptimizerConfig::Adam(c) => c.validate(),
            OptimizerConfig::AdaGrad(c) => c.validate(),
            OptimizerConfig::Sgd(c) => c.validate(),
        }
        .map_err(nn_other)
    }

    /// Parameter-sized buffers a network trained with this optimizer keeps: the parameters, their
    /// gradient and the optimizer's state (Adam's two moments, AdaGrad's sum, SGD's momentum).
    pub fn copies(&self) -> u64 {
        match self {
            OptimizerConfig::Adam(_) => 4,
            OptimizerConfig::AdaGrad(_) => 3,
            OptimizerConfig::Sgd(c) if c.momentum == 0.0 => 2,
            OptimizerConfig::Sgd(_) => 3,
        }
    }

    /// The memory of an MLP with layer widths `sizes` trained with this optimizer on minibatches
    /// of `batch` rows: parameters, gradients, the optimizer's state and one pass's activations.
    pub fn network_memory(
        &self,
        what: impl Into<String>,
        sizes: &[usize],
        batch: usize,
    ) -> MemoryEstimate {
        MemoryEstimate::new().mlp(what, sizes, self.copies(), batch)
    }

    pub(crate) fn build(&self, n_params: usize) -> Result<Opt, ModelError> {
        Ok(match *self {
            OptimizerConfig::Adam(c) => Opt::Adam(Adam::new(c, n_params).map_err(nn_other)?),
            OptimizerConfig::AdaGrad(c) => {
                Opt::AdaGrad(AdaGrad::new(c, n_params).map_err(nn_other)?)
            }
            OptimizerConfig::Sgd(c) => Opt::Sgd(Sgd::new(c, n_params).map_err(nn_other)?),
        })
    }
}

/// An optimizer with its state (kept between fits, cloneable so a failed fit can be undone).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Opt {
    Adam(Adam),
    AdaGrad(AdaGrad),
    Sgd(Sgd),
}

impl tandem_nn::Checkpointable for Opt {
    fn save_to(&self, prefix: &str, ckpt: &mut tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        match self {
            Opt::Adam(o) => o.save_to(prefix, ckpt),
            Opt::AdaGrad(o) => o.save_to(prefix, ckpt),
            Opt::Sgd(o) => o.save_to(prefix, ckpt),
        }
    }

    fn load_from(&mut self, prefix: &str, ckpt: &tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        match self {
            Opt::Adam(o) => o.load_from(prefix, ckpt),
            Opt::AdaGrad(o) => o.load_from(prefix, ckpt),
            Opt::Sgd(o) => o.load_from(prefix, ckpt),
        }
    }
}

impl Opt {
    pub(crate) fn step(&mut self, params: &mut [f32], grads: &[f32]) -> tandem_nn::Result<()> {
        match self {
            Opt::Adam(o) => o.step(params, grads),
            Opt::AdaGrad(o) => o.step(params, grads),
            Opt::Sgd(o) => o.step(params, grads),
        }
    }
}

/// An `NnError` outside training, as a model error.
pub(crate) fn nn_other(e: NnError) -> ModelError {
    ModelError::Other(format!("network: {e}"))
}

/// An `NnError` during training: non-finite numbers mean the fit diverged.
pub(crate) fn nn_train(e: NnError, epoch: usize, step: usize) -> ModelError {
    match e {
        NnError::NonFinite { .. } => ModelError::Diverged { epoch, step },
        other => nn_other(other),
    }
}

/// Per-column affine standardization `(x - mean) / std`, fitted on training data.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Standardizer {
    /// Column means.
    pub mean: Vec<f64>,
    /// Column standard deviations (floored, so constant columns pass through shifted).
    pub std: Vec<f64>,
}

impl Standardizer {
    /// The identity map for `dim` columns.
    pub fn identity(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            std: vec![1.0; dim],
        }
    }

    /// Fitted on the rows `idx` of `x` (all rows if `idx` is empty); standard deviations below
    /// `1e-6` (constant columns) become 1.
    pub fn fit(x: ArrayView2<'_, f64>, idx: &[usize]) -> Self {
        let d = x.ncols();
        let rows: Vec<usize> = if idx.is_empty() {
            (0..x.nrows()).collect()
        } else {
            idx.to_vec()
        };
        let n = rows.len().max(1) as f64;
        let mut mean = vec![0.0; d];
        for &r in &rows {
            for (m, v) in mean.iter_mut().zip(x.row(r)) {
                *m += v;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n);
        let mut var = vec![0.0; d];
        for &r in &rows {
            for ((s, v), m) in var.iter_mut().zip(x.row(r)).zip(&mean) {
                *s += (v - m) * (v - m);
            }
        }
        let std = var
            .iter()
            .map(|v| {
                let s = (v / n).sqrt();
                if s < 1e-6 {
                    1.0
                } else {
                    s
                }
            })
            .collect();
        Self { mean, std }
    }

    /// Unshifted (mean 0), scaled by each column's root mean square over the rows `idx`; a
    /// root mean square below `1e-9` becomes 1.
    pub(crate) fn root_mean_square(x: ArrayView2<'_, f64>, idx: &[usize]) -> Self {
        let std = (0..x.ncols())
            .map(|j| {
                let v = idx.iter().map(|&i| x[[i, j]] * x[[i, j]]).sum::<f64>() / idx.len() as f64;
                let r = v.sqrt();
                if r < 1e-9 {
                    1.0
                } else {
                    r
                }
            })
            .collect();
        Self {
            mean: vec![0.0; x.ncols()],
            std,
        }
    }

    /// Number of columns.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Writes the standardized `row` into `out` as `f32`.
    #[inline]
    pub(crate) fn apply(&self, row: impl IntoIterator<Item = f64>, out: &mut [f32]) {
        for (((o, v), m), s) in out.iter_mut().zip(row).zip(&self.mean).zip(&self.std) {
            *o = ((v - m) / s) as f32;
        }
    }

    /// The value in original units of standardized component `j`.
    #[inline]
    pub(crate) fn invert(&self, j: usize, z: f32) -> f64 {
        f64::from(z) * self.std[j] + self.mean[j]
    }
}

/// [`EarlyStop`] as a fit goes: each member's best held-out loss and the epochs since one
/// improved.
pub(crate) struct Stopper {
    cfg: EarlyStop,
    best: Vec<f64>,
    since: usize,
}

impl Stopper {
    /// The fit's early stopping over `members` held-out losses, if it has one.
    pub(crate) fn of(cfg: &FitConfig, members: usize) -> Option<Self> {
        cfg.early_stop.clone().map(|cfg| Self {
            cfg,
            best: vec![f64::INFINITY; members],
            since: 0,
        })
    }

    /// Notes an epoch's held-out losses (one per member); whether it improved, so that the
    /// caller keeps its weights.
    pub(crate) fn improved(&mut self, losses: &[f64]) -> bool {
        let mut any = false;
        for (best, &loss) in self.best.iter_mut().zip(losses) {
            let better = match best.is_finite() {
                true => (*best - loss) / best.abs() > self.cfg.improvement_threshold,
                false => loss.is_finite(),
            };
            if better {
                *best = loss;
                any = true;
            }
        }
        self.since = if any { 0 } else { self.since + 1 };
        any
    }

    /// Whether `patience` epochs went by without an improvement.
    pub(crate) fn done(&self) -> bool {
        self.since >= self.cfg.patience
    }
}

/// A network with its optimizer state: what a one-network model trains. Checkpointed as
/// `{prefix}.net` and `{prefix}.opt`.
#[derive(Debug, Clone)]
pub(crate) struct Network {
    pub net: Mlp,
    pub opt: Opt,
}

impl Network {
    /// `net` with a fresh optimizer of `cfg`.
    pub(crate) fn new(net: Mlp, cfg: &OptimizerConfig) -> Result<Self, ModelError> {
        let opt = cfg.build(net.num_params())?;
        Ok(Self { net, opt })
    }

    /// Trains for `cfg.epochs` passes over `rows.train` (reshuffled each epoch from `rng`),
    /// recording the training loss and the loss on `rows.holdout` after each epoch. A non-finite
    /// loss (or non-finite numbers in the network) is `Diverged`.
    pub(crate) fn train(
        &mut self,
        obj: &dyn Objective,
        rows: &FitRows,
        cfg: &FitConfig,
        rng: &mut Rng,
    ) -> Result<FitReport, ModelError> {
        let mut s = Scratch::default();
        let mut order = rows.train.clone();
        let mut report = FitReport::default();
        let mut stop = Stopper::of(cfg, 1);
        let mut kept = None;
        for epoch in 0..cfg.epochs {
            order.shuffle(rng);
            let l = self.run_epoch(obj, rows, &order, cfg.batch_size, rng, epoch, &mut s)?;
            report.train_loss.push(l);
            if !rows.holdout.is_empty() {
                let h = self
                    .evaluate(obj, rows, &rows.holdout, &mut s)
                    .map_err(|e| nn_train(e, epoch, 0))?;
                if !h.is_finite() {
                    return Err(ModelError::Diverged { epoch, step: 0 });
                }
                report.holdout_loss.push(h);
                if let Some(stop) = stop.as_mut() {
                    if stop.improved(&[h]) {
                        kept = Some(self.clone());
                    }
                    if stop.done() {
                        break;
                    }
                }
            }
        }
        if let Some(best) = kept {
            *self = best;
        }
        Ok(report)
    }

    /// One pass over `order` in minibatches of `batch`: forward (with dropout from `rng` when the
    /// network has it), loss, backward, optimizer step. Returns the mean training loss.
    #[allow(clippy::too_many_arguments)]
    fn run_epoch(
        &mut self,
        obj: &dyn Objective,
        rows: &FitRows,
        order: &[usize],
        batch: usize,
        rng: &mut Rng,
        epoch: usize,
        s: &mut Scratch,
    ) -> Result<f64, ModelError> {
        let Self { net, opt } = self;
        let batch = batch.max(1);
        let dout = net.output_dim();
        s.grads.resize(net.num_params(), 0.0);
        let mut total = 0.0;
        for (step, idx) in order.chunks(batch).enumerate() {
            let b = idx.len();
            rows.gather_inputs(idx, &mut s.x);
            s.d_out.resize(b * dout, 0.0);
            let out = net
                .forward_train(&s.x, b, &mut s.ws, Some(rng))
                .map_err(|e| nn_train(e, epoch, step))?;
            let loss = obj.loss(rows, idx, out, Some(&mut s.d_out[..b * dout]));
            if !loss.is_finite() {
                return Err(ModelError::Diverged { epoch, step });
            }
            total += loss * b as f64;
            net.backward(&mut s.ws, &s.d_out[..b * dout], Some(&mut s.grads), None)
                .map_err(|e| nn_train(e, epoch, step))?;
            opt.step(net.params_mut(), &s.grads)
                .map_err(|e| nn_train(e, epoch, step))?;
        }
        Ok(total / order.len().max(1) as f64)
    }

    /// Mean loss over rows `idx` without dropout (NaN for no rows).
    fn evaluate(
        &self,
        obj: &dyn Objective,
        rows: &FitRows,
        idx: &[usize],
        s: &mut Scratch,
    ) -> Result<f64, NnError> {
        if idx.is_empty() {
            return Ok(f64::NAN);
        }
        let mut total = 0.0;
        for chunk in idx.chunks(1024) {
            let b = chunk.len();
            rows.gather_inputs(chunk, &mut s.x);
            let out = self.net.forward(&s.x, b, &mut s.ws)?;
            total += obj.loss(rows, chunk, out, None) * b as f64;
        }
        Ok(total / idx.len() as f64)
    }
}

impl tandem_nn::Checkpointable for Network {
    fn save_to(&self, prefix: &str, ckpt: &mut tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        self.net.save_to(&format!("{prefix}.net"), ckpt)?;
        self.opt.save_to(&format!("{prefix}.opt"), ckpt)
    }

    /// Both or neither: a failed load leaves the network as it was.
    fn load_from(&mut self, prefix: &str, ckpt: &tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        let mut n = self.clone();
        n.net.load_from(&format!("{prefix}.net"), ckpt)?;
        n.opt.load_from(&format!("{prefix}.opt"), ckpt)?;
        *self = n;
        Ok(())
    }
}

/// A network's loss over rows of a fit.
pub(crate) trait Objective {
    /// Mean loss over rows `idx` of `fit` for network outputs `out`; writes `dL/dout` into `grad`
    /// when given.
    fn loss(&self, fit: &FitRows, idx: &[usize], out: &[f32], grad: Option<&mut [f32]>) -> f64;
}

/// Scratch buffers of a training loop.
#[derive(Default)]
struct Scratch {
    ws: MlpWorkspace,
    x: Vec<f32>,
    d_out: Vec<f32>,
    grads: Vec<f32>,
}

/// One fit's rows: the training and holdout row indices, and every row's standardized inputs
/// (`din` wide) and targets (`dout` wide), row-major.
pub(crate) struct FitRows {
    pub train: Vec<usize>,
    pub holdout: Vec<usize>,
    pub din: usize,
    pub x: Vec<f32>,
    pub dout: usize,
    pub y: Vec<f32>,
}

impl FitRows {
    /// The inputs of rows `idx`, one after the other, into `xb`.
    pub(crate) fn gather_inputs(&self, idx: &[usize], xb: &mut Vec<f32>) {
        xb.clear();
        for &i in idx {
            xb.extend_from_slice(&self.x[i * self.din..(i + 1) * self.din]);
        }
    }

    /// The targets of rows `idx`, one after the other, into `yb`.
    pub(crate) fn gather_targets(&self, idx: &[usize], yb: &mut Vec<f32>) {
        yb.clear();
        for &i in idx {
            yb.extend_from_slice(self.targets(i));
        }
    }

    /// The standardized targets of row `i`.
    pub(crate) fn targets(&self, i: usize) -> &[f32] {
        &self.y[i * self.dout..(i + 1) * self.dout]
    }
}

/// What a model's network regresses on, per row, and how the targets are standardized.
pub(crate) enum Targets<'a> {
    /// The state change `s' − s`, then the reward when `reward`; standardized by the training
    /// rows' means and standard deviations.
    StateChange { reward: bool },
    /// The residual `s' − f(s, a)` over a known model's predictions `f(s, a)`; standardized like
    /// the state change.
    ResidualOver(Array2<f64>),
    /// Targets the model builds itself, divided by the root mean square of `rms_of`'s columns
    /// over the training rows (not shifted).
    ScaledByRms {
        values: Array2<f64>,
        rms_of: ArrayView2<'a, f64>,
    },
}

impl Targets<'_> {
    /// The targets of every row of `data` (validated), and their standardization fitted on the
    /// rows `train`.
    fn build(self, data: &Transitions, train: &[usize]) -> (Array2<f64>, Standardizer) {
        let values = match self {
            Targets::StateChange { reward } => {
                let (n, s) = (data.len(), data.state_dim());
                let mut t = Array2::zeros((n, s + usize::from(reward)));
                for r in 0..n {
                    for j in 0..s {
                        t[[r, j]] = data.next_states[[r, j]] - data.states[[r, j]];
                    }
                    if reward {
                        t[[r, s]] = data.rewards[r];
                    }
                }
                t
            }
            Targets::ResidualOver(base) => &data.next_states - &base,
            Targets::ScaledByRms { values, rms_of } => {
                let norm = Standardizer::root_mean_square(rms_of, train);
                return (values, norm);
            }
        };
        let norm = Standardizer::fit(values.view(), train);
        (values, norm)
    }
}

/// Rows a fit keeps of its split: those `keep` marks; `none_kept` is the error when it keeps no
/// training row.
pub(crate) struct RowFilter<'a> {
    pub keep: &'a [bool],
    pub none_kept: &'a str,
}

/// What one fit of a transition model learns from: two input blocks (the state and the action;
/// the incremental model's are the state and the previous action), `targets`, and the rows
/// `filter` keeps (all without one).
pub(crate) struct FitSpec<'a> {
    pub inputs: [ArrayView2<'a, f64>; 2],
    pub targets: Targets<'a>,
    pub filter: Option<RowFilter<'a>>,
}

/// What a transition model learns, `trained` (a network and its optimizer, or an ensemble's
/// members), with the standardizations of its two input blocks (see [`FitSpec`]) and of its
/// targets: the shape of mbrl-lib's `OneDTransitionRewardModel`.
/// [`Standardized::fit`] is the one fit path of the learned transition models.
#[derive(Debug, Clone)]
pub(crate) struct Standardized<T> {
    pub trained: T,
    pub inputs: [Standardizer; 2],
    pub targets: Standardizer,
}

impl<T: Clone> Standardized<T> {
    /// `trained` with identity standardizations of the given widths.
    pub(crate) fn new(trained: T, input_dims: [usize; 2], target_dim: usize) -> Self {
        Self {
            trained,
            inputs: input_dims.map(Standardizer::identity),
            targets: Standardizer::identity(target_dim),
        }
    }

    /// Fits on `data` (validated): splits its rows into training and holdout rows
    /// ([`holdout_indices`] from `rng`, then `spec.filter`), builds the targets, fits the input
    /// and target standardizations on the training rows, standardizes every row, and has `train`
    /// train a clone of `trained` on them (with `rng` to draw on). The clone and the
    /// standardizations are kept only when training succeeds, so a failed fit changes nothing.
    pub(crate) fn fit<'a, R>(
        &mut self,
        data: &'a Transitions,
        cfg: &FitConfig,
        spec: FitSpec<'a>,
        rng: &mut Rng,
        train: impl FnOnce(&mut T, &FitRows, &mut Rng) -> Result<R, ModelError>,
    ) -> Result<R, ModelError> {
        let n = data.len();
        let (mut train_rows, mut holdout) = holdout_indices(n, cfg.holdout_fraction, rng);
        if let Some(f) = &spec.filter {
            train_rows.retain(|&i| f.keep[i]);
            holdout.retain(|&i| f.keep[i]);
            if train_rows.is_empty() {
                return Err(ModelError::Other(f.none_kept.into()));
            }
        }
        if let Some(stop) = &cfg.early_stop {
            stop.validate()?;
            if holdout.is_empty() {
                return Err(ModelError::Other(
                    "early stopping needs held-out rows: raise holdout_fraction above 0".into(),
                ));
            }
        }
        let [first, second] = spec.inputs;
        let inputs = [
            Standardizer::fit(first, &train_rows),
            Standardizer::fit(second, &train_rows),
        ];
        let (targets, target_norm) = spec.targets.build(data, &train_rows);
        let rows = FitRows {
            din: inputs.iter().map(Standardizer::dim).sum(),
            x: standardized_inputs(&[(first, &inputs[0]), (second, &inputs[1])], n),
            dout: target_norm.dim(),
            y: standardized_inputs(&[(targets.view(), &target_norm)], n),
            train: train_rows,
            holdout,
        };
        let mut trained = self.trained.clone();
        let result = train(&mut trained, &rows, rng)?;
        *self = Self {
            trained,
            inputs,
            targets: target_norm,
        };
        Ok(result)
    }

    /// The standardized `[first | second]` input rows into `x` (reused).
    pub(crate) fn inputs_into<'a>(
        &self,
        first: ArrayView2<'a, f64>,
        second: ArrayView2<'a, f64>,
        rows: usize,
        x: &mut Vec<f32>,
    ) {
        let [a, b] = &self.inputs;
        standardized_inputs_into(&[(first, a), (second, b)], rows, x);
    }
}

/// Rows of `[states | actions]` standardized into one `f32` buffer.
pub(crate) fn standardized_inputs(
    parts: &[(ArrayView2<'_, f64>, &Standardizer)],
    rows: usize,
) -> Vec<f32> {
    let mut x = Vec::new();
    standardized_inputs_into(parts, rows, &mut x);
    x
}

/// [`standardized_inputs`] into a reused buffer (no allocation once it has held this many rows).
pub(crate) fn standardized_inputs_into(
    parts: &[(ArrayView2<'_, f64>, &Standardizer)],
    rows: usize,
    x: &mut Vec<f32>,
) {
    let din: usize = parts.iter().map(|(_, s)| s.dim()).sum();
    x.clear();
    x.resize(rows * din, 0.0);
    for (r, out) in x.chunks_exact_mut(din.max(1)).enumerate().take(rows) {
        let mut off = 0;
        for (a, s) in parts {
            let d = s.dim();
            s.apply(a.row(r).iter().copied(), &mut out[off..off + d]);
            off += d;
        }
    }
}

/// Reusable buffers of a model's `predict` (standardized inputs and the network workspace).
pub(crate) type PredictScratch = tandem_nn::SharedWorkspace;
