//! What the learned models share: optimizer choice, standardization, and the minibatch loop.

use ndarray::ArrayView2;
use rand::seq::SliceRandom;
use tandem_core::Rng;
use tandem_nn::{
    AdaGrad, AdaGradConfig, Adam, AdamConfig, Mlp, MlpWorkspace, NnError, Optimizer, Sgd, SgdConfig,
};

use crate::model::ModelError;

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

/// A network's training data: standardized inputs, one row per sample, and a loss over rows.
pub(crate) trait Objective {
    /// Input width.
    fn in_dim(&self) -> usize;
    /// Writes the inputs of rows `idx` (`idx.len() x in_dim`) into `buf`.
    fn inputs(&self, idx: &[usize], buf: &mut [f32]);
    /// Mean loss over rows `idx` for network outputs `out`; writes `dL/dout` when asked.
    fn loss(&self, idx: &[usize], out: &[f32], d_out: Option<&mut [f32]>) -> f64;
}

/// Scratch buffers of a training loop.
#[derive(Default)]
pub(crate) struct Scratch {
    pub ws: MlpWorkspace,
    pub x: Vec<f32>,
    pub d_out: Vec<f32>,
    pub grads: Vec<f32>,
}

/// One pass over `order` in minibatches of `batch`: forward (with dropout from `rng` when the
/// network has it), loss, backward, optimizer step. Returns the mean training loss.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_epoch(
    net: &mut Mlp,
    opt: &mut Opt,
    obj: &dyn Objective,
    order: &[usize],
    batch: usize,
    rng: &mut Rng,
    epoch: usize,
    s: &mut Scratch,
) -> Result<f64, ModelError> {
    let batch = batch.max(1);
    let (din, dout) = (obj.in_dim(), net.output_dim());
    s.grads.resize(net.num_params(), 0.0);
    let mut total = 0.0;
    for (step, idx) in order.chunks(batch).enumerate() {
        let b = idx.len();
        s.x.resize(b * din, 0.0);
        obj.inputs(idx, &mut s.x[..b * din]);
        s.d_out.resize(b * dout, 0.0);
        let out = net
            .forward_train(&s.x[..b * din], b, &mut s.ws, Some(rng))
            .map_err(|e| nn_train(e, epoch, step))?;
        let loss = obj.loss(idx, out, Some(&mut s.d_out[..b * dout]));
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
pub(crate) fn evaluate(
    net: &Mlp,
    obj: &dyn Objective,
    idx: &[usize],
    s: &mut Scratch,
) -> Result<f64, NnError> {
    if idx.is_empty() {
        return Ok(f64::NAN);
    }
    let din = obj.in_dim();
    let mut total = 0.0;
    for chunk in idx.chunks(1024) {
        let b = chunk.len();
        s.x.resize(b * din, 0.0);
        obj.inputs(chunk, &mut s.x[..b * din]);
        let out = net.forward(&s.x[..b * din], b, &mut s.ws)?;
        total += obj.loss(chunk, out, None) * b as f64;
    }
    Ok(total / idx.len() as f64)
}

/// Trains one network for `epochs` passes over `train` (reshuffled each epoch from `rng`),
/// recording the training loss and the loss on `holdout` after each epoch. A non-finite loss (or
/// non-finite numbers in the network) is `Diverged`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn train_network(
    net: &mut Mlp,
    opt: &mut Opt,
    obj: &dyn Objective,
    train: &[usize],
    holdout: &[usize],
    epochs: usize,
    batch: usize,
    rng: &mut Rng,
) -> Result<crate::FitReport, ModelError> {
    let mut s = Scratch::default();
    let mut order = train.to_vec();
    let mut report = crate::FitReport::default();
    for epoch in 0..epochs {
        order.shuffle(rng);
        let l = run_epoch(net, opt, obj, &order, batch, rng, epoch, &mut s)?;
        report.train_loss.push(l);
        if !holdout.is_empty() {
            let h = evaluate(net, obj, holdout, &mut s).map_err(|e| nn_train(e, epoch, 0))?;
            if !h.is_finite() {
                return Err(ModelError::Diverged { epoch, step: 0 });
            }
            report.holdout_loss.push(h);
        }
    }
    Ok(report)
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
