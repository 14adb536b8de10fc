//! Optimizers over flat `f32` parameter buffers, updated in place, plus gradient-norm clipping
//! and polyak (soft target) updates.
//!
//! Each optimizer follows PyTorch's update formulas exactly (the reference implementations every
//! paper here used), keeps its state in buffers the length of the parameters, allocates nothing
//! per step, and refuses a step with a non-finite gradient (parameters left untouched).
//!
//! Adam, AdaGrad and SGD are element-wise, so one optimizer per network is the same as one over
//! several networks' concatenated parameters (e.g. SAC's twin critics).

use serde::{Deserialize, Serialize};

use crate::checkpoint::{Checkpoint, Checkpointable};
use crate::error::{check_finite, check_len, NnError, Result};
use crate::simd::multiversion;

/// A first-order optimizer stepping a flat parameter buffer with a gradient of the same layout.
pub trait Optimizer {
    /// One update: `params -= f(grads, state)`. Errors on length mismatch or a non-finite
    /// gradient, leaving `params` and the state unchanged.
    fn step(&mut self, params: &mut [f32], grads: &[f32]) -> Result<()>;
    /// The current learning rate.
    fn lr(&self) -> f32;
    /// Sets the learning rate (schedules).
    fn set_lr(&mut self, lr: f32);
    /// Number of steps taken.
    fn steps(&self) -> u64;
}

fn check_step(n: usize, params: &[f32], grads: &[f32]) -> Result<()> {
    check_len("optimizer parameters", n, params.len())?;
    check_len("optimizer gradients", n, grads.len())?;
    check_finite("gradient", grads)
}

fn positive(name: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(NnError::InvalidConfig(format!(
            "{name} must be finite and > 0, got {v}"
        )))
    }
}

fn unit(name: &str, v: f32) -> Result<()> {
    if (0.0..1.0).contains(&v) {
        Ok(())
    } else {
        Err(NnError::InvalidConfig(format!(
            "{name} must be in [0, 1), got {v}"
        )))
    }
}

fn non_negative(name: &str, v: f32) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(NnError::InvalidConfig(format!(
            "{name} must be finite and >= 0, got {v}"
        )))
    }
}

/// Adam's hyperparameters. `Default` = `torch.optim.Adam` defaults with stable-baselines3's SAC
/// learning rate 3e-4.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdamConfig {
    /// Learning rate.
    pub lr: f32,
    /// First-moment decay β1.
    pub beta1: f32,
    /// Second-moment decay β2.
    pub beta2: f32,
    /// Denominator epsilon.
    pub eps: f32,
    /// Weight decay. Added to the gradient (L2, `torch.optim.Adam`) unless `decoupled`.
    pub weight_decay: f32,
    /// Decoupled weight decay (`torch.optim.AdamW`: `p *= 1 - lr·wd` before the step).
    pub decoupled: bool,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 3e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
            decoupled: false,
        }
    }
}

impl AdamConfig {
    /// Defaults with learning rate `lr`.
    pub fn with_lr(lr: f32) -> Self {
        Self {
            lr,
            ..Self::default()
        }
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<()> {
        positive("adam lr", self.lr)?;
        unit("adam beta1", self.beta1)?;
        unit("adam beta2", self.beta2)?;
        positive("adam eps", self.eps)?;
        non_negative("adam weight_decay", self.weight_decay)
    }
}

/// Adam (Kingma & Ba 2015) in PyTorch's form:
/// `m ← β1 m + (1-β1) g`, `v ← β2 v + (1-β2) g²`,
/// `p ← p - (lr / (1-β1^t)) · m / (√v / √(1-β2^t) + ε)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    cfg: AdamConfig,
    m: Vec<f32>,
    v: Vec<f32>,
    t: u64,
}

impl Adam {
    /// Adam for `n_params` parameters, zero moments.
    pub fn new(cfg: AdamConfig, n_params: usize) -> Result<Self> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            m: vec![0.0; n_params],
            v: vec![0.0; n_params],
            t: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &AdamConfig {
        &self.cfg
    }

    /// First and second moment buffers.
    pub fn moments(&self) -> (&[f32], &[f32]) {
        (&self.m, &self.v)
    }
}

/// The per-step constants of [`adam_update`].
#[derive(Clone, Copy)]
struct AdamCoefficients {
    b1: f32,
    b2: f32,
    ob1: f32,
    ob2: f32,
    eps: f32,
    l2: f32,
    step_size: f32,
    inv_bc2_sqrt: f32,
}

multiversion! {
    /// One Adam step over flat slices (one pass over parameters, gradients and both moments).
    fn adam_update(
        params: &mut [f32],
        grads: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        c: AdamCoefficients,
    ) {
        let n = params.len();
        let (grads, m, v) = (&grads[..n], &mut m[..n], &mut v[..n]);
        for i in 0..n {
            let p = &mut params[i];
            let g = grads[i] + c.l2 * *p;
            let mi = c.b1 * m[i] + c.ob1 * g;
            let vi = c.b2 * v[i] + c.ob2 * g * g;
            m[i] = mi;
            v[i] = vi;
            *p -= c.step_size * mi / (vi.sqrt() * c.inv_bc2_sqrt + c.eps);
        }
    }
}

impl Optimizer for Adam {
    fn step(&mut self, params: &mut [f32], grads: &[f32]) -> Result<()> {
        check_step(self.m.len(), params, grads)?;
        self.t += 1;
        let c = &self.cfg;
        let t = self.t as i32;
        let bc1 = 1.0 - f64::from(c.beta1).powi(t);
        let bc2 = 1.0 - f64::from(c.beta2).powi(t);
        let step_size = (f64::from(c.lr) / bc1) as f32;
        let inv_bc2_sqrt = (1.0 / bc2.sqrt()) as f32;
        let (b1, b2, eps) = (c.beta1, c.beta2, c.eps);
        let (ob1, ob2) = (1.0 - b1, 1.0 - b2);
        let wd = c.weight_decay;
        if wd > 0.0 && c.decoupled {
            let f = 1.0 - c.lr * wd;
            params.iter_mut().for_each(|p| *p *= f);
        }
        let l2 = if c.decoupled { 0.0 } else { wd };
        let coef = AdamCoefficients {
            b1,
            b2,
            ob1,
            ob2,
            eps,
            l2,
            step_size,
            inv_bc2_sqrt,
        };
        adam_update(params, grads, &mut self.m, &mut self.v, coef);
        Ok(())
    }

    fn lr(&self) -> f32 {
        self.cfg.lr
    }

    fn set_lr(&mut self, lr: f32) {
        self.cfg.lr = lr;
    }

    fn steps(&self) -> u64 {
        self.t
    }
}

impl Checkpointable for Adam {
    /// Writes `{prefix}.m`, `{prefix}.v` (f32) and `{prefix}.step` (u64).
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        ckpt.put_f32(&format!("{prefix}.m"), &[self.m.len()], &self.m)?;
        ckpt.put_f32(&format!("{prefix}.v"), &[self.v.len()], &self.v)?;
        ckpt.put_u64(&format!("{prefix}.step"), &[1], &[self.t])
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let n = self.m.len();
        let m = ckpt.get_f32(&format!("{prefix}.m"), Some(&[n]))?;
        let v = ckpt.get_f32(&format!("{prefix}.v"), Some(&[n]))?;
        let t = ckpt.get_u64(&format!("{prefix}.step"), Some(&[1]))?[0];
        self.m = m;
        self.v = v;
        self.t = t;
        Ok(())
    }
}

/// AdaGrad's hyperparameters. `Default` = `torch.optim.Adagrad` defaults.
///
/// ε is added to `√G` as in PyTorch. TensorFlow 1's `AdagradOptimizer` (accumulator starting at
/// 0.1, no ε) is `initial_accumulator = 0.1, eps = 0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdaGradConfig {
    /// Learning rate.
    pub lr: f32,
    /// Learning-rate decay: `lr_t = lr / (1 + (t-1)·lr_decay)`.
    pub lr_decay: f32,
    /// Weight decay (L2 added to the gradient).
    pub weight_decay: f32,
    /// Starting value of the squared-gradient accumulator.
    pub initial_accumulator: f32,
    /// Denominator epsilon.
    pub eps: f32,
}

impl Default for AdaGradConfig {
    fn default() -> Self {
        Self {
            lr: 0.01,
            lr_decay: 0.0,
            weight_decay: 0.0,
            initial_accumulator: 0.0,
            eps: 1e-10,
        }
    }
}

impl AdaGradConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<()> {
        positive("adagrad lr", self.lr)?;
        non_negative("adagrad lr_decay", self.lr_decay)?;
        non_negative("adagrad weight_decay", self.weight_decay)?;
        non_negative("adagrad initial_accumulator", self.initial_accumulator)?;
        non_negative("adagrad eps", self.eps)?;
        if self.initial_accumulator == 0.0 && self.eps == 0.0 {
            return Err(NnError::InvalidConfig(
                "adagrad needs eps > 0 or initial_accumulator > 0 (else 0/0 on a zero gradient)"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// AdaGrad (Duchi et al. 2011) in PyTorch's form: `G ← G + g²`,
/// `p ← p - lr_t · g / (√G + ε)`.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaGrad {
    cfg: AdaGradConfig,
    sum: Vec<f32>,
    t: u64,
}

impl AdaGrad {
    /// AdaGrad for `n_params` parameters.
    pub fn new(cfg: AdaGradConfig, n_params: usize) -> Result<Self> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            sum: vec![cfg.initial_accumulator; n_params],
            t: 0,
        })
    }

    /// The accumulated squared gradients.
    pub fn accumulator(&self) -> &[f32] {
        &self.sum
    }
}

impl Optimizer for AdaGrad {
    fn step(&mut self, params: &mut [f32], grads: &[f32]) -> Result<()> {
        check_step(self.sum.len(), params, grads)?;
        self.t += 1;
        let c = &self.cfg;
        let clr = c.lr / (1.0 + (self.t - 1) as f32 * c.lr_decay);
        let (wd, eps) = (c.weight_decay, c.eps);
        for ((p, &g), s) in params.iter_mut().zip(grads).zip(self.sum.iter_mut()) {
            let g = g + wd * *p;
            *s += g * g;
            *p -= clr * g / (s.sqrt() + eps);
        }
        Ok(())
    }

    fn lr(&self) -> f32 {
        self.cfg.lr
    }

    fn set_lr(&mut self, lr: f32) {
        self.cfg.lr = lr;
    }

    fn steps(&self) -> u64 {
        self.t
    }
}

impl Checkpointable for AdaGrad {
    /// Writes `{prefix}.sum` (f32) and `{prefix}.step` (u64).
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        ckpt.put_f32(&format!("{prefix}.sum"), &[self.sum.len()], &self.sum)?;
        ckpt.put_u64(&format!("{prefix}.step"), &[1], &[self.t])
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let sum = ckpt.get_f32(&format!("{prefix}.sum"), Some(&[self.sum.len()]))?;
        let t = ckpt.get_u64(&format!("{prefix}.step"), Some(&[1]))?[0];
        self.sum = sum;
        self.t = t;
        Ok(())
    }
}

/// SGD's hyperparameters. `Default`: plain SGD, lr 0.01, no momentum.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SgdConfig {
    /// Learning rate.
    pub lr: f32,
    /// Momentum μ (0 = none).
    pub momentum: f32,
    /// Nesterov momentum (needs μ > 0).
    pub nesterov: bool,
    /// Weight decay (L2 added to the gradient).
    pub weight_decay: f32,
}

impl Default for SgdConfig {
    fn default() -> Self {
        Self {
            lr: 0.01,
            momentum: 0.0,
            nesterov: false,
            weight_decay: 0.0,
        }
    }
}

impl SgdConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<()> {
        positive("sgd lr", self.lr)?;
        unit("sgd momentum", self.momentum)?;
        non_negative("sgd weight_decay", self.weight_decay)?;
        if self.nesterov && self.momentum == 0.0 {
            return Err(NnError::InvalidConfig("nesterov needs momentum > 0".into()));
        }
        Ok(())
    }
}

/// SGD with optional (Nesterov) momentum in PyTorch's form (dampening 0):
/// `b ← μ b + g` (`b = g` on the first step), `p ← p - lr·(nesterov ? g + μ b : b)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Sgd {
    cfg: SgdConfig,
    buf: Vec<f32>,
    t: u64,
}

impl Sgd {
    /// SGD for `n_params` parameters.
    pub fn new(cfg: SgdConfig, n_params: usize) -> Result<Self> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            buf: vec![0.0; n_params],
            t: 0,
        })
    }
}

impl Optimizer for Sgd {
    fn step(&mut self, params: &mut [f32], grads: &[f32]) -> Result<()> {
        check_step(self.buf.len(), params, grads)?;
        let c = self.cfg;
        let first = self.t == 0;
        self.t += 1;
        if c.momentum == 0.0 {
            for (p, &g) in params.iter_mut().zip(grads) {
                let g = g + c.weight_decay * *p;
                *p -= c.lr * g;
            }
            return Ok(());
        }
        for ((p, &g), b) in params.iter_mut().zip(grads).zip(self.buf.iter_mut()) {
            let g = g + c.weight_decay * *p;
            *b = if first { g } else { c.momentum * *b + g };
            let d = if c.nesterov { g + c.momentum * *b } else { *b };
            *p -= c.lr * d;
        }
        Ok(())
    }

    fn lr(&self) -> f32 {
        self.cfg.lr
    }

    fn set_lr(&mut self, lr: f32) {
        self.cfg.lr = lr;
    }

    fn steps(&self) -> u64 {
        self.t
    }
}

impl Checkpointable for Sgd {
    /// Writes `{prefix}.momentum_buffer` (f32) and `{prefix}.step` (u64).
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        ckpt.put_f32(
            &format!("{prefix}.momentum_buffer"),
            &[self.buf.len()],
            &self.buf,
        )?;
        ckpt.put_u64(&format!("{prefix}.step"), &[1], &[self.t])
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let buf = ckpt.get_f32(
            &format!("{prefix}.momentum_buffer"),
            Some(&[self.buf.len()]),
        )?;
        let t = ckpt.get_u64(&format!("{prefix}.step"), Some(&[1]))?[0];
        self.buf = buf;
        self.t = t;
        Ok(())
    }
}

/// Euclidean norm of a gradient buffer (accumulated in f64).
pub fn grad_norm(grads: &[f32]) -> f32 {
    let mut acc = [0.0f64; 4];
    let chunks = grads.chunks_exact(4);
    let rem = chunks.remainder();
    for c in chunks {
        for k in 0..4 {
            acc[k] += f64::from(c[k]) * f64::from(c[k]);
        }
    }
    let mut s: f64 = acc.iter().sum();
    for &g in rem {
        s += f64::from(g) * f64::from(g);
    }
    s.sqrt() as f32
}

/// Scales `grads` so that its norm is at most `max_norm` (`torch.nn.utils.clip_grad_norm_`, with
/// its 1e-6 guard) and returns the norm before clipping. Errors on a non-finite norm (gradients
/// untouched) or a non-positive `max_norm`.
pub fn clip_grad_norm(grads: &mut [f32], max_norm: f32) -> Result<f32> {
    positive("max_norm", max_norm)?;
    let norm = grad_norm(grads);
    if !norm.is_finite() {
        check_finite("gradient", grads)?;
        return Err(NnError::NonFinite {
            what: "gradient norm (overflow)".into(),
            index: 0,
        });
    }
    let coef = max_norm / (norm + 1e-6);
    if coef < 1.0 {
        grads.iter_mut().for_each(|g| *g *= coef);
    }
    Ok(norm)
}

/// Clips several gradient buffers by their joint norm; returns the joint norm before clipping.
pub fn clip_grad_norm_many(grads: &mut [&mut [f32]], max_norm: f32) -> Result<f32> {
    positive("max_norm", max_norm)?;
    let sq: f64 = grads.iter().map(|g| f64::from(grad_norm(g)).powi(2)).sum();
    let norm = sq.sqrt() as f32;
    if !norm.is_finite() {
        return Err(NnError::NonFinite {
            what: "gradient norm".into(),
            index: 0,
        });
    }
    let coef = max_norm / (norm + 1e-6);
    if coef < 1.0 {
        for g in grads.iter_mut() {
            g.iter_mut().for_each(|v| *v *= coef);
        }
    }
    Ok(norm)
}

/// Polyak (soft) target update: `target ← (1 - τ)·target + τ·source`, τ ∈ [0, 1]
/// (τ = 1 copies). Errors on length mismatch or τ out of range.
pub fn polyak_update(target: &mut [f32], source: &[f32], tau: f32) -> Result<()> {
    check_len("polyak source", target.len(), source.len())?;
    if !(0.0..=1.0).contains(&tau) {
        return Err(NnError::InvalidConfig(format!(
            "polyak tau must be in [0, 1], got {tau}"
        )));
    }
    polyak_loop(target, source, tau);
    Ok(())
}

multiversion! {
    /// `target = (1 - tau) target + tau source`, element-wise.
    fn polyak_loop(target: &mut [f32], source: &[f32], tau: f32) {
        let keep = 1.0 - tau;
        for (t, &s) in target.iter_mut().zip(source) {
            *t = keep * *t + tau * s;
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    /// Adam written out in f64 from the paper's Algorithm 1 with PyTorch's ε placement.
    fn adam_reference(p0: &[f64], grads: &[Vec<f64>], lr: f64) -> Vec<f64> {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let mut p = p0.to_vec();
        let mut m = vec![0.0; p.len()];
        let mut v = vec![0.0; p.len()];
        for (t, g) in grads.iter().enumerate() {
            let t = (t + 1) as i32;
            for i in 0..p.len() {
                m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                let mh = m[i] / (1.0 - b1.powi(t));
                let vh = v[i] / (1.0 - b2.powi(t));
                p[i] -= lr * mh / (vh.sqrt() + eps);
            }
        }
        p
    }

    #[test]
    fn adam_matches_the_paper_algorithm() {
        let p0 = [1.0f32, -2.0, 0.5];
        let grads: Vec<Vec<f32>> = (0..6)
            .map(|k| vec![0.5 - k as f32 * 0.2, 3.0 * (k as f32).cos(), 1e-3])
            .collect();
        let mut p = p0.to_vec();
        let mut opt = Adam::new(AdamConfig::with_lr(0.01), 3).unwrap();
        for g in &grads {
            opt.step(&mut p, g).unwrap();
        }
        let g64: Vec<Vec<f64>> = grads
            .iter()
            .map(|g| g.iter().map(|v| f64::from(*v)).collect())
            .collect();
        let want = adam_reference(&[1.0, -2.0, 0.5], &g64, 0.01);
        for (a, b) in p.iter().zip(&want) {
            assert!((f64::from(*a) - b).abs() < 1e-6, "{a} vs {b}");
        }
        // First step moves every parameter by ≈ lr against the gradient's sign.
        let mut q = p0.to_vec();
        let mut o = Adam::new(AdamConfig::with_lr(0.01), 3).unwrap();
        o.step(&mut q, &grads[0]).unwrap();
        for (a, b) in q.iter().zip(&p0) {
            assert!(((b - a).abs() - 0.01).abs() < 1e-5);
        }
        assert_eq!(opt.steps(), 6);
    }

    #[test]
    fn adam_matches_candle_adamw_without_decay() {
        use candle_core::{Device, Tensor, Var};
        use candle_nn::optim::{AdamW, Optimizer as _, ParamsAdamW};
        let dev = Device::Cpu;
        let target = [0.3f32, -1.2, 2.0, 0.0];
        let var = Var::from_tensor(&Tensor::new(&[1.0f32, 1.0, -1.0, 0.5], &dev).unwrap()).unwrap();
        let tt = Tensor::new(&target, &dev).unwrap();
        let mut copt = AdamW::new(
            vec![var.clone()],
            ParamsAdamW {
                lr: 0.05,
                weight_decay: 0.0,
                ..Default::default()
            },
        )
        .unwrap();
        let mut p = vec![1.0f32, 1.0, -1.0, 0.5];
        let mut opt = Adam::new(AdamConfig::with_lr(0.05), 4).unwrap();
        for _ in 0..20 {
            let loss = (var.as_tensor() - &tt)
                .unwrap()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap();
            copt.backward_step(&loss).unwrap();
            let g: Vec<f32> = p.iter().zip(&target).map(|(a, t)| 2.0 * (a - t)).collect();
            opt.step(&mut p, &g).unwrap();
        }
        let want = var.as_tensor().to_vec1::<f32>().unwrap();
        for (a, b) in p.iter().zip(&want) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn adagrad_and_sgd_hand_computed_steps() {
        let mut p = vec![1.0f32];
        let mut ada = AdaGrad::new(
            AdaGradConfig {
                lr: 0.1,
                ..Default::default()
            },
            1,
        )
        .unwrap();
        ada.step(&mut p, &[2.0]).unwrap(); // G = 4: p = 1 - 0.1·2/2
        assert!((p[0] - 0.9).abs() < 1e-7);
        ada.step(&mut p, &[1.0]).unwrap(); // G = 5: p -= 0.1/√5
        assert!((p[0] - (0.9 - 0.1 / 5f32.sqrt())).abs() < 1e-6);
        // TensorFlow form: accumulator starts at 0.1, no ε.
        let mut p = vec![0.0f32];
        let mut tf = AdaGrad::new(
            AdaGradConfig {
                lr: 1.0,
                initial_accumulator: 0.1,
                eps: 0.0,
                ..Default::default()
            },
            1,
        )
        .unwrap();
        tf.step(&mut p, &[0.3]).unwrap();
        assert!((p[0] + 0.3 / (0.1f32 + 0.09).sqrt()).abs() < 1e-6);

        let mut p = vec![1.0f32];
        let mut sgd = Sgd::new(
            SgdConfig {
                lr: 0.1,
                momentum: 0.9,
                ..Default::default()
            },
            1,
        )
        .unwrap();
        sgd.step(&mut p, &[1.0]).unwrap(); // b = 1, p = 0.9
        sgd.step(&mut p, &[1.0]).unwrap(); // b = 1.9, p = 0.71
        assert!((p[0] - 0.71).abs() < 1e-6);
        let mut p = vec![1.0f32];
        let mut nes = Sgd::new(
            SgdConfig {
                lr: 0.1,
                momentum: 0.9,
                nesterov: true,
                ..Default::default()
            },
            1,
        )
        .unwrap();
        nes.step(&mut p, &[1.0]).unwrap(); // b = 1, d = 1 + 0.9 = 1.9
        assert!((p[0] - 0.81).abs() < 1e-6);
        let mut p = vec![1.0f32];
        let mut plain = Sgd::new(SgdConfig::default(), 1).unwrap();
        plain.step(&mut p, &[2.0]).unwrap();
        assert!((p[0] - 0.98).abs() < 1e-7);
    }

    #[test]
    fn non_finite_or_misshapen_gradients_leave_everything_unchanged() {
        let mut p = vec![1.0f32, 2.0];
        let mut opt = Adam::new(AdamConfig::default(), 2).unwrap();
        let before = opt.clone();
        let e = opt.step(&mut p, &[0.1, f32::NAN]).unwrap_err();
        assert_eq!(
            e,
            NnError::NonFinite {
                what: "gradient".into(),
                index: 1
            }
        );
        assert_eq!(p, vec![1.0, 2.0]);
        assert_eq!(opt, before);
        assert!(opt.step(&mut p, &[0.1]).is_err());
        let mut ada = AdaGrad::new(AdaGradConfig::default(), 2).unwrap();
        assert!(ada.step(&mut p, &[f32::INFINITY, 0.0]).is_err());
        assert_eq!(ada.steps(), 0);
        assert!(Adam::new(AdamConfig::with_lr(-1.0), 2).is_err());
        assert!(AdaGrad::new(
            AdaGradConfig {
                eps: 0.0,
                ..Default::default()
            },
            1
        )
        .is_err());
        assert!(Sgd::new(
            SgdConfig {
                nesterov: true,
                ..Default::default()
            },
            1
        )
        .is_err());
    }

    #[test]
    fn clipping_and_polyak() {
        let mut g = vec![3.0f32, 4.0];
        let n = clip_grad_norm(&mut g, 1.0).unwrap();
        assert_eq!(n, 5.0);
        assert!((g[0] - 0.6).abs() < 1e-6 && (g[1] - 0.8).abs() < 1e-6);
        let mut small = vec![0.3f32, 0.4];
        clip_grad_norm(&mut small, 1.0).unwrap();
        assert_eq!(small, vec![0.3, 0.4]);
        assert!(clip_grad_norm(&mut [f32::NAN], 1.0).is_err());
        let (mut a, mut b) = (vec![3.0f32], vec![4.0f32]);
        let joint = clip_grad_norm_many(&mut [&mut a, &mut b], 1.0).unwrap();
        assert_eq!(joint, 5.0);
        assert!((a[0] - 0.6).abs() < 1e-6 && (b[0] - 0.8).abs() < 1e-6);

        let mut t = vec![1.0f32, 0.0];
        polyak_update(&mut t, &[3.0, 10.0], 0.25).unwrap();
        assert_eq!(t, vec![1.5, 2.5]);
        polyak_update(&mut t, &[3.0, 10.0], 1.0).unwrap();
        assert_eq!(t, vec![3.0, 10.0]);
        assert!(polyak_update(&mut t, &[1.0], 0.5).is_err());
        assert!(polyak_update(&mut t, &[1.0, 1.0], 1.5).is_err());
    }

    #[test]
    fn resumed_optimizer_continues_bit_identically() {
        let grads: Vec<Vec<f32>> = (0..8)
            .map(|k| (0..5).map(|i| ((k * 5 + i) as f32 * 0.7).sin()).collect())
            .collect();
        let p = vec![0.1f32; 5];
        let mut a = Adam::new(AdamConfig::default(), 5).unwrap();
        let mut s = Sgd::new(
            SgdConfig {
                momentum: 0.5,
                ..Default::default()
            },
            5,
        )
        .unwrap();
        let mut g2 = AdaGrad::new(AdaGradConfig::default(), 5).unwrap();
        let (mut pa, mut ps, mut pg) = (p.clone(), p.clone(), p.clone());
        for g in &grads[..4] {
            a.step(&mut pa, g).unwrap();
            s.step(&mut ps, g).unwrap();
            g2.step(&mut pg, g).unwrap();
        }
        let mut ck = Checkpoint::new();
        a.save_to("a", &mut ck).unwrap();
        s.save_to("s", &mut ck).unwrap();
        g2.save_to("g", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        let mut a2 = Adam::new(AdamConfig::default(), 5).unwrap();
        let mut s2 = Sgd::new(
            SgdConfig {
                momentum: 0.5,
                ..Default::default()
            },
            5,
        )
        .unwrap();
        let mut g3 = AdaGrad::new(AdaGradConfig::default(), 5).unwrap();
        a2.load_from("a", &ck).unwrap();
        s2.load_from("s", &ck).unwrap();
        g3.load_from("g", &ck).unwrap();
        let (mut qa, mut qs, mut qg) = (pa.clone(), ps.clone(), pg.clone());
        for g in &grads[4..] {
            a.step(&mut pa, g).unwrap();
            a2.step(&mut qa, g).unwrap();
            s.step(&mut ps, g).unwrap();
            s2.step(&mut qs, g).unwrap();
            g2.step(&mut pg, g).unwrap();
            g3.step(&mut qg, g).unwrap();
        }
        assert_eq!(pa, qa);
        assert_eq!(ps, qs);
        assert_eq!(pg, qg);
        let mut wrong = Adam::new(AdamConfig::default(), 6).unwrap();
        assert!(wrong.load_from("a", &ck).is_err());
    }
}
