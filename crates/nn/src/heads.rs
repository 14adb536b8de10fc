//! Distribution heads on top of an [`Mlp`](crate::Mlp)'s raw output, with their gradients:
//!
//! * [`GaussianHead`]: mean and softly bounded log-variance (PETS, Chua et al. 2018, appendix;
//!   mbrl-lib's `GaussianMLP`), for probabilistic dynamics models.
//! * [`TanhGaussian`]: SAC's squashed Gaussian policy (Haarnoja et al. 2018, appendix C):
//!   reparametrized samples, the exact log-probability with the change-of-variables term in its
//!   stable form `log(1 - tanh²u) = 2(log 2 - u - softplus(-2u))` (sampling computes it together
//!   with `tanh u` from one `expm1`: [`tanh_and_log1m_tanh_sq`]), and the backward pass for the
//!   actor loss.
//! * [`Categorical`]: softmax policies over discrete actions (REINFORCE on CartPole, p2).
//!
//! Layouts are row-major: a head reading `k` values per sample takes `batch × k` slices.

use rand::Rng as _;
use rand_distr::{Distribution as _, StandardNormal};
use tandem_core::seeding::Rng;

use crate::error::{check_finite, check_len, NnError, Result};
use crate::fastmath;
use crate::simd::multiversion;

/// `ln(1 + e^x)`, stable for any `x`, through libm (SAC's log-probabilities; batched kernels use
/// [`fastmath::softplus`]).
#[inline]
pub fn softplus(x: f32) -> f32 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// `log(1 - tanh²(u))` in the stable form `2(log 2 - u - softplus(-2u))`.
#[inline]
pub fn log1m_tanh_sq(u: f32) -> f32 {
    2.0 * (std::f32::consts::LN_2 - u - softplus(-2.0 * u))
}

/// `(tanh u, log(1 - tanh²u))` from one `expm1` and one `ln` (what sampling a [`TanhGaussian`]
/// needs per component): with `m = e^{-2|u|} - 1`, `tanh|u| = -m / (2 + m)` and
/// `log(1 - tanh²u) = -2|u| - 2 log(1 + m/2)`. `tanh` is accurate to a few ulps, the log-term to
/// a few ulps of `max(|log(1 - tanh²u)|, 1)`, as [`log1m_tanh_sq`] (an absolute error of about
/// `1e-7` near 0, where the term is `≈ -u²`: negligible in a log-density), for any `u` (no
/// underflow for large `|u|`, where the naive `log(1 - tanh²u)` is `-inf` from `|u| ≈ 9` in
/// `f32`). It costs less than `tanh` alone (which calls `expm1` too) plus a `ln`.
#[inline]
pub fn tanh_and_log1m_tanh_sq(u: f32) -> (f32, f32) {
    let (a, t, m) = tanh_parts(u);
    let l = -2.0 * (t + (1.0 + 0.5 * m).ln());
    // Rounding can leave it just above 0 for tiny |u|; it never is (NaN stays NaN).
    (a, if l > 0.0 { 0.0 } else { l })
}

/// `(tanh u, |u|, e^{-2|u|} - 1)`: the squashed value and what its log-derivative reuses.
#[inline]
fn tanh_parts(u: f32) -> (f32, f32, f32) {
    let t = u.abs();
    let m = (-2.0 * t).exp_m1();
    ((-m / (2.0 + m)).copysign(u), t, m)
}

const HALF_LN_2PI: f32 = 0.918_938_5;

/// Fills `out` with standard-normal draws from `rng`, in order (the noise [`TanhGaussian::sample`]
/// uses; draw it yourself and call [`TanhGaussian::sample_with_noise`] to fix the order of draws
/// independently of how the work is scheduled).
pub fn fill_standard_normal(rng: &mut Rng, out: &mut [f32]) {
    for e in out.iter_mut() {
        *e = StandardNormal.sample(rng);
    }
}

/// Mean and log-variance from a network output of `2·dim` values per sample: the first `dim` are
/// the mean, the next `dim` a raw log-variance that is softly bounded to `[min, max]` as in PETS:
/// `lv = max - softplus(max - raw)`, then `lv = min + softplus(lv - min)` (soft: `lv` can exceed
/// `max` by at most `softplus(min - max)`).
///
/// The bounds are one buffer `[min (dim) | max (dim)]` so that a model can learn them (PETS adds
/// `0.01·(Σmax - Σmin)` to its loss) with any optimizer; [`GaussianHead::backward`] gives their
/// gradient.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianHead {
    dim: usize,
    bounds: Vec<f32>,
}

/// What [`GaussianHead::forward`] computes, kept for the backward pass.
#[derive(Debug, Clone, Default)]
pub struct GaussianOutput {
    batch: usize,
    dim: usize,
    /// Means, `batch × dim`.
    pub mean: Vec<f32>,
    /// Bounded log-variances, `batch × dim`.
    pub log_var: Vec<f32>,
    dlv_draw: Vec<f32>,
    dlv_dmin: Vec<f32>,
    /// Whether `dlv_*` belong to this output ([`GaussianHead::forward`], not
    /// [`GaussianHead::predict`]).
    differentiable: bool,
}

impl GaussianHead {
    /// A head for `dim` outputs with PETS's initial bounds (min −10, max 0.5 on the log-variance).
    pub fn new(dim: usize) -> Self {
        Self::with_bounds(dim, -10.0, 0.5).expect("valid default bounds")
    }

    /// A head with the same bounds on every dimension; `min < max` required.
    pub fn with_bounds(dim: usize, min_log_var: f32, max_log_var: f32) -> Result<Self> {
        if !(min_log_var.is_finite() && max_log_var.is_finite() && min_log_var < max_log_var) {
            return Err(NnError::InvalidConfig(format!(
                "log-variance bounds need min < max, got [{min_log_var}, {max_log_var}]"
            )));
        }
        let mut bounds = vec![min_log_var; dim];
        bounds.extend(std::iter::repeat_n(max_log_var, dim));
        Ok(Self { dim, bounds })
    }

    /// Output dimension (the network needs `2·dim` outputs).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The bounds `[min (dim) | max (dim)]`.
    pub fn bounds(&self) -> &[f32] {
        &self.bounds
    }

    /// The bounds, mutable (to learn them).
    pub fn bounds_mut(&mut self) -> &mut [f32] {
        &mut self.bounds
    }

    /// Splits and bounds `net_out` (`batch × 2·dim`) into `out.mean` and `out.log_var`.
    pub fn forward(&self, net_out: &[f32], batch: usize, out: &mut GaussianOutput) -> Result<()> {
        let d = self.dim;
        check_len("gaussian head input", batch * 2 * d, net_out.len())?;
        let n = batch * d;
        for v in [
            &mut out.mean,
            &mut out.log_var,
            &mut out.dlv_draw,
            &mut out.dlv_dmin,
        ] {
            v.resize(n, 0.0);
        }
        out.batch = batch;
        out.dim = d;
        out.differentiable = true;
        let (lo, hi) = self.bounds.split_at(d);
        bound_log_var_with_derivatives(
            net_out,
            lo,
            hi,
            &mut out.mean,
            &mut out.log_var,
            &mut out.dlv_draw,
            &mut out.dlv_dmin,
        );
        check_finite("gaussian head log-variance", &out.log_var)
    }

    /// [`GaussianHead::forward`] without what the backward pass needs (inference: the same means
    /// and log-variances, bit for bit, at about half the cost); [`GaussianHead::backward`] refuses
    /// its output.
    pub fn predict(&self, net_out: &[f32], batch: usize, out: &mut GaussianOutput) -> Result<()> {
        let d = self.dim;
        check_len("gaussian head input", batch * 2 * d, net_out.len())?;
        let n = batch * d;
        out.mean.resize(n, 0.0);
        out.log_var.resize(n, 0.0);
        out.batch = batch;
        out.dim = d;
        out.differentiable = false;
        let (lo, hi) = self.bounds.split_at(d);
        bound_log_var(net_out, lo, hi, &mut out.mean, &mut out.log_var);
        check_finite("gaussian head log-variance", &out.log_var)
    }

    /// Gradients through the head: given `dL/dmean` and `dL/dlog_var` (`batch × dim` each),
    /// overwrites `d_net_out` (`batch × 2·dim`) and, if given, `d_bounds` (`2·dim`, summed over
    /// the batch).
    pub fn backward(
        &self,
        out: &GaussianOutput,
        d_mean: &[f32],
        d_log_var: &[f32],
        d_net_out: &mut [f32],
        d_bounds: Option<&mut [f32]>,
    ) -> Result<()> {
        let (b, d) = (out.batch, self.dim);
        if !out.differentiable {
            return Err(NnError::InvalidConfig(
                "gaussian head backward needs the output of `forward`, not of `predict`".into(),
            ));
        }
        check_len("gaussian head d_mean", b * d, d_mean.len())?;
        check_len("gaussian head d_log_var", b * d, d_log_var.len())?;
        check_len("gaussian head d_net_out", b * 2 * d, d_net_out.len())?;
        for r in 0..b {
            for j in 0..d {
                let k = r * d + j;
                d_net_out[r * 2 * d + j] = d_mean[k];
                d_net_out[r * 2 * d + d + j] = d_log_var[k] * out.dlv_draw[k];
            }
        }
        if let Some(db) = d_bounds {
            check_len("gaussian head d_bounds", 2 * d, db.len())?;
            db.fill(0.0);
            for r in 0..b {
                for j in 0..d {
                    let k = r * d + j;
                    let g = d_log_var[k];
                    let dmin = out.dlv_dmin[k];
                    // lv = min + sp(l1 - min): ∂lv/∂min = 1 - σ(s2); ∂lv/∂max = σ(s2)(1 - σ(t)),
                    // and σ(s2)·σ(t) = dlv_draw.
                    db[j] += g * dmin;
                    db[d + j] += g * ((1.0 - dmin) - out.dlv_draw[k]);
                }
            }
        }
        Ok(())
    }
}

/// `f(x, lo[j], hi[j])` for every element of `x` (rows of `lo.len()` values): the per-column
/// steps between the vectorized passes over whole buffers in the Gaussian head (a loop over one
/// row's few values would leave much of it to the scalar tail).
#[inline(always)]
fn by_column(x: &mut [f32], lo: &[f32], hi: &[f32], f: impl Fn(f32, f32, f32) -> f32) {
    for row in x.chunks_exact_mut(lo.len()) {
        for ((v, lo), hi) in row.iter_mut().zip(lo).zip(hi) {
            *v = f(*v, *lo, *hi);
        }
    }
}

/// Splits `net_out` (rows of `[mean | raw]`) into `mean` and `t = max - raw` in `log_var`.
#[inline(always)]
fn split_head(net_out: &[f32], hi: &[f32], mean: &mut [f32], log_var: &mut [f32]) {
    let d = hi.len();
    for ((row, m), t) in net_out
        .chunks_exact(2 * d)
        .zip(mean.chunks_exact_mut(d))
        .zip(log_var.chunks_exact_mut(d))
    {
        m.copy_from_slice(&row[..d]);
        for ((t, raw), hi) in t.iter_mut().zip(&row[d..]).zip(hi) {
            *t = hi - raw;
        }
    }
}

multiversion! {
    /// The means and bounded log-variances of [`GaussianHead::predict`]: `lv = min + softplus(max -
    /// softplus(max - raw) - min)`, each softplus one pass over the whole batch.
    fn bound_log_var(
        net_out: &[f32],
        lo: &[f32],
        hi: &[f32],
        mean: &mut [f32],
        log_var: &mut [f32],
    ) {
        split_head(net_out, hi, mean, log_var);
        for v in log_var.iter_mut() {
            *v = fastmath::softplus(*v);
        }
        by_column(log_var, lo, hi, |sp, lo, hi| (hi - sp) - lo);
        for v in log_var.iter_mut() {
            *v = fastmath::softplus(*v);
        }
        by_column(log_var, lo, hi, |sp, lo, _| lo + sp);
    }
}

multiversion! {
    /// [`bound_log_var`] (the same bits) with the derivatives [`GaussianHead::backward`] needs:
    /// `∂lv/∂raw = σ(s2)σ(t)` and `∂lv/∂min = 1 - σ(s2)`, `t = max - raw`, `s2 = max -
    /// softplus(t) - min`.
    fn bound_log_var_with_derivatives(
        net_out: &[f32],
        lo: &[f32],
        hi: &[f32],
        mean: &mut [f32],
        log_var: &mut [f32],
        dlv_draw: &mut [f32],
        dlv_dmin: &mut [f32],
    ) {
        split_head(net_out, hi, mean, log_var);
        for (v, st) in log_var.iter_mut().zip(dlv_draw.iter_mut()) {
            (*v, *st) = fastmath::softplus_and_sigmoid(*v);
        }
        by_column(log_var, lo, hi, |sp, lo, hi| (hi - sp) - lo);
        for ((v, dr), dm) in log_var.iter_mut().zip(dlv_draw.iter_mut()).zip(dlv_dmin.iter_mut()) {
            let (sp, ss) = fastmath::softplus_and_sigmoid(*v);
            *v = sp;
            *dr *= ss;
            *dm = 1.0 - ss;
        }
        by_column(log_var, lo, hi, |sp, lo, _| lo + sp);
    }
}

/// SAC's tanh-squashed Gaussian policy head. The network outputs `2·dim` values per sample: the
/// mean `μ` and the log-std, clamped to `[log_std_min, log_std_max]` (stable-baselines3: −20, 2;
/// zero gradient where clamped). Actions are `a = tanh(μ + σ·ε)` in `(-1, 1)`; scale them to the
/// action space outside (a constant shift of the log-probability by `-Σ log scale`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TanhGaussian {
    /// Action dimension.
    pub dim: usize,
    /// Lower clamp of the log-std.
    pub log_std_min: f32,
    /// Upper clamp of the log-std.
    pub log_std_max: f32,
}

/// A batch of reparametrized samples of a [`TanhGaussian`], with what the backward pass needs.
#[derive(Debug, Clone, Default)]
pub struct TanhGaussianSample {
    batch: usize,
    dim: usize,
    /// Standard-normal noise ε, `batch × dim`.
    pub eps: Vec<f32>,
    /// Squashed actions `tanh(u)`, `batch × dim`.
    pub action: Vec<f32>,
    /// `log π(a|s)` per sample (summed over dimensions), `batch`.
    pub log_prob: Vec<f32>,
    /// Log-std after clamping, `batch × dim`.
    pub log_std: Vec<f32>,
    /// Pre-squash values `u = μ + σ ε`, `batch × dim`.
    pub pre_tanh: Vec<f32>,
    /// `σ ε` (`∂u/∂log σ`), kept for the backward pass.
    std_eps: Vec<f32>,
    clamped: Vec<bool>,
}

impl TanhGaussianSample {
    /// Batch size of the sample.
    pub fn batch(&self) -> usize {
        self.batch
    }
}

impl TanhGaussian {
    /// A head for `dim` actions with stable-baselines3's log-std clamp [−20, 2].
    pub fn new(dim: usize) -> Self {
        Self {
            dim,
            log_std_min: -20.0,
            log_std_max: 2.0,
        }
    }

    /// Draws ε from `rng` (standard normal, row-major) and samples; see
    /// [`TanhGaussian::sample_with_noise`].
    pub fn sample(
        &self,
        net_out: &[f32],
        batch: usize,
        rng: &mut Rng,
        s: &mut TanhGaussianSample,
    ) -> Result<()> {
        s.eps.resize(batch * self.dim, 0.0);
        fill_standard_normal(rng, &mut s.eps);
        self.fill(net_out, batch, s)
    }

    /// Samples with the given noise `eps` (`batch × dim`): `u = μ + σε`, `a = tanh u`,
    /// `log π = Σ_j [-ε_j²/2 - log σ_j - ½log 2π - log(1 - tanh² u_j)]`.
    pub fn sample_with_noise(
        &self,
        net_out: &[f32],
        batch: usize,
        eps: &[f32],
        s: &mut TanhGaussianSample,
    ) -> Result<()> {
        check_len("tanh-gaussian noise", batch * self.dim, eps.len())?;
        s.eps.clear();
        s.eps.extend_from_slice(eps);
        self.fill(net_out, batch, s)
    }

    /// Samples with the noise already in `s.eps` (`batch × dim`), without copying it: draw it
    /// up front with [`fill_standard_normal`] so that the order of draws does not depend on how
    /// the forward passes are scheduled (SAC draws the noise of `s` and `s'` before running both
    /// actor passes side by side).
    pub fn resample(
        &self,
        net_out: &[f32],
        batch: usize,
        s: &mut TanhGaussianSample,
    ) -> Result<()> {
        check_len("tanh-gaussian noise", batch * self.dim, s.eps.len())?;
        self.fill(net_out, batch, s)
    }

    /// Draws ε from `rng` as [`TanhGaussian::sample`] does and writes only the actions
    /// (`batch × dim`), the bits `sample` gives them, without the log-density and what its
    /// gradient keeps: an acting policy's share of the work.
    pub fn sample_actions(
        &self,
        net_out: &[f32],
        batch: usize,
        rng: &mut Rng,
        action: &mut [f32],
    ) -> Result<()> {
        let d = self.dim;
        check_len("tanh-gaussian input", batch * 2 * d, net_out.len())?;
        check_finite("tanh-gaussian input", net_out)?;
        check_len("tanh-gaussian action", batch * d, action.len())?;
        fill_standard_normal(rng, action);
        for (r, row) in action.chunks_exact_mut(d).enumerate() {
            let out = &net_out[r * 2 * d..(r + 1) * 2 * d];
            for (j, a) in row.iter_mut().enumerate() {
                let (_, std_eps) = self.std_eps(out[d + j], *a);
                *a = tanh_parts(out[j] + std_eps).0;
            }
        }
        Ok(())
    }

    /// `(log σ, σε)` of a raw log-std output and noise `e`, the log-std clamped to its range.
    #[inline]
    fn std_eps(&self, raw: f32, e: f32) -> (f32, f32) {
        let ls = raw.clamp(self.log_std_min, self.log_std_max);
        (ls, ls.exp() * e)
    }

    fn fill(&self, net_out: &[f32], batch: usize, s: &mut TanhGaussianSample) -> Result<()> {
        let d = self.dim;
        check_len("tanh-gaussian input", batch * 2 * d, net_out.len())?;
        check_finite("tanh-gaussian input", net_out)?;
        let n = batch * d;
        s.batch = batch;
        s.dim = d;
        for v in [
            &mut s.action,
            &mut s.log_std,
            &mut s.pre_tanh,
            &mut s.std_eps,
        ] {
            v.resize(n, 0.0);
        }
        s.clamped.resize(n, false);
        s.log_prob.clear();
        s.log_prob.resize(batch, 0.0);
        let outs = (s.action.iter_mut().zip(&mut s.log_std))
            .zip(s.std_eps.iter_mut().zip(&mut s.pre_tanh))
            .zip(s.clamped.iter_mut().zip(&s.eps));
        // Row r, component j of the flat index k = r·d + j.
        let (mut r, mut j) = (0, 0);
        for (((a, ls), (std_eps, u)), (clamped, &e)) in outs {
            let raw = net_out[r * 2 * d + d + j];
            (*ls, *std_eps) = self.std_eps(raw, e);
            *clamped = raw != *ls;
            *u = net_out[r * 2 * d + j] + *std_eps;
            let log_det;
            (*a, log_det) = tanh_and_log1m_tanh_sq(*u);
            s.log_prob[r] += -0.5 * e * e - *ls - HALF_LN_2PI - log_det;
            j += 1;
            if j == d {
                (r, j) = (r + 1, 0);
            }
        }
        check_finite("tanh-gaussian log-prob", &s.log_prob)
    }

    /// The deterministic action `tanh(μ)` (`batch × dim`).
    pub fn mode(&self, net_out: &[f32], batch: usize, action: &mut [f32]) -> Result<()> {
        let d = self.dim;
        check_len("tanh-gaussian input", batch * 2 * d, net_out.len())?;
        check_len("tanh-gaussian action", batch * d, action.len())?;
        for r in 0..batch {
            for j in 0..d {
                action[r * d + j] = net_out[r * 2 * d + j].tanh();
            }
        }
        check_finite("tanh-gaussian action", action)
    }

    /// `log π(a|s)` of given actions in `(-1, 1)` (clipped to `±(1 - 1e-6)` before `atanh`).
    pub fn log_prob(
        &self,
        net_out: &[f32],
        batch: usize,
        action: &[f32],
        log_prob: &mut [f32],
    ) -> Result<()> {
        let d = self.dim;
        check_len("tanh-gaussian input", batch * 2 * d, net_out.len())?;
        check_len("tanh-gaussian action", batch * d, action.len())?;
        check_len("tanh-gaussian log_prob", batch, log_prob.len())?;
        for r in 0..batch {
            let mut lp = 0.0f32;
            for j in 0..d {
                let a = action[r * d + j].clamp(-1.0 + 1e-6, 1.0 - 1e-6);
                let u = a.atanh();
                let mu = net_out[r * 2 * d + j];
                let ls = net_out[r * 2 * d + d + j].clamp(self.log_std_min, self.log_std_max);
                let z = (u - mu) * (-ls).exp();
                lp += -0.5 * z * z - ls - HALF_LN_2PI - log1m_tanh_sq(u);
            }
            log_prob[r] = lp;
        }
        check_finite("tanh-gaussian log-prob", log_prob)
    }

    /// Backward of a loss `L(a, log π)` through a reparametrized sample: given `dL/da`
    /// (`batch × dim`, e.g. `-∂Q/∂a / B` in SAC's actor loss) and `dL/dlog π` (`batch`, e.g.
    /// `α / B`), overwrites `d_net_out` (`batch × 2·dim`) with the gradient wrt `[μ | raw log-std]`:
    ///
    /// `∂a/∂μ = 1 - a²`, `∂log π/∂μ = 2a` (from `d/du log(1 - tanh²u) = -2 tanh u`),
    /// `∂u/∂log σ = σε`, `∂log π/∂log σ = 2a·σε - 1`; zero through a clamped log-std.
    pub fn backward(
        &self,
        s: &TanhGaussianSample,
        d_action: Option<&[f32]>,
        d_log_prob: Option<&[f32]>,
        d_net_out: &mut [f32],
    ) -> Result<()> {
        let (b, d) = (s.batch, self.dim);
        if s.dim != d {
            return Err(NnError::ShapeMismatch {
                what: "tanh-gaussian sample".into(),
                expected: format!("dim {d}"),
                got: format!("dim {}", s.dim),
            });
        }
        if let Some(g) = d_action {
            check_len("tanh-gaussian d_action", b * d, g.len())?;
            check_finite("tanh-gaussian d_action", g)?;
        }
        if let Some(g) = d_log_prob {
            check_len("tanh-gaussian d_log_prob", b, g.len())?;
            check_finite("tanh-gaussian d_log_prob", g)?;
        }
        check_len("tanh-gaussian d_net_out", b * 2 * d, d_net_out.len())?;
        for r in 0..b {
            let glp = d_log_prob.map_or(0.0, |g| g[r]);
            for j in 0..d {
                let k = r * d + j;
                let a = s.action[k];
                let ga = d_action.map_or(0.0, |g| g[k]);
                // dL/du through both paths (action and the log-det term).
                let du = ga * (1.0 - a * a) + glp * 2.0 * a;
                d_net_out[r * 2 * d + j] = du;
                d_net_out[r * 2 * d + d + j] = if s.clamped[k] {
                    0.0
                } else {
                    du * s.std_eps[k] - glp
                };
            }
        }
        Ok(())
    }
}

/// Softmax distribution over `n` discrete actions from logits (`batch × n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Categorical {
    /// Number of actions.
    pub n: usize,
}

impl Categorical {
    /// A head over `n` actions.
    pub fn new(n: usize) -> Self {
        Self { n }
    }

    /// Log-softmax of every row into `log_probs` (`batch × n`), max-shifted for stability.
    pub fn log_softmax(&self, logits: &[f32], batch: usize, log_probs: &mut [f32]) -> Result<()> {
        let n = self.n;
        check_len("categorical logits", batch * n, logits.len())?;
        check_len("categorical log_probs", batch * n, log_probs.len())?;
        check_finite("categorical logits", logits)?;
        for (row, out) in logits.chunks_exact(n).zip(log_probs.chunks_exact_mut(n)) {
            let m = row.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            let lse = m + row.iter().map(|v| (v - m).exp()).sum::<f32>().ln();
            for (o, v) in out.iter_mut().zip(row) {
                *o = v - lse;
            }
        }
        Ok(())
    }

    /// Samples one action per row from log-probabilities (inverse CDF with a uniform draw).
    pub fn sample(
        &self,
        log_probs: &[f32],
        batch: usize,
        rng: &mut Rng,
        actions: &mut [usize],
    ) -> Result<()> {
        let n = self.n;
        check_len("categorical log_probs", batch * n, log_probs.len())?;
        check_len("categorical actions", batch, actions.len())?;
        for (row, a) in log_probs.chunks_exact(n).zip(actions.iter_mut()) {
            let u: f32 = rng.random();
            let mut c = 0.0f32;
            *a = n - 1;
            for (i, lp) in row.iter().enumerate() {
                c += lp.exp();
                if u < c {
                    *a = i;
                    break;
                }
            }
        }
        Ok(())
    }

    /// The most probable action of every row.
    pub fn argmax(&self, logits: &[f32], batch: usize, actions: &mut [usize]) -> Result<()> {
        let n = self.n;
        check_len("categorical logits", batch * n, logits.len())?;
        check_len("categorical actions", batch, actions.len())?;
        for (row, a) in logits.chunks_exact(n).zip(actions.iter_mut()) {
            let mut best = 0;
            for (i, v) in row.iter().enumerate() {
                if *v > row[best] {
                    best = i;
                }
            }
            *a = best;
        }
        Ok(())
    }

    /// Gradient wrt the logits of `L = Σ_b w_b log π(a_b | s_b) + c Σ_b H(π(·|s_b))`, given the
    /// rows' log-probabilities: `∂/∂z_j = w (1[j=a] - p_j) - c p_j (log p_j + H)`. Overwrites
    /// `d_logits` (`batch × n`). For REINFORCE, `w_b = -G_b / B`.
    pub fn backward(
        &self,
        log_probs: &[f32],
        actions: &[usize],
        weights: &[f32],
        entropy_coef: f32,
        d_logits: &mut [f32],
    ) -> Result<()> {
        let n = self.n;
        let batch = actions.len();
        check_len("categorical log_probs", batch * n, log_probs.len())?;
        check_len("categorical weights", batch, weights.len())?;
        check_len("categorical d_logits", batch * n, d_logits.len())?;
        for (b, (row, out)) in log_probs
            .chunks_exact(n)
            .zip(d_logits.chunks_exact_mut(n))
            .enumerate()
        {
            let a = actions[b];
            if a >= n {
                return Err(NnError::ShapeMismatch {
                    what: "categorical action".into(),
                    expected: format!("index < {n}"),
                    got: a.to_string(),
                });
            }
            let h: f32 = -row.iter().map(|lp| lp.exp() * lp).sum::<f32>();
            for (j, (o, lp)) in out.iter_mut().zip(row).enumerate() {
                let p = lp.exp();
                let onehot = if j == a { 1.0 } else { 0.0 };
                *o = weights[b] * (onehot - p) - entropy_coef * p * (lp + h);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use tandem_core::seeding::rng_from_seed;

    fn log1m_tanh_sq_f64(u: f64) -> f64 {
        // log sech²u = -2 log cosh u, written to avoid overflow.
        let a = u.abs();
        -2.0 * (a + (-2.0 * a).exp().ln_1p() - std::f64::consts::LN_2)
    }

    #[test]
    fn stable_log_det_matches_closed_form_even_where_naive_fails() {
        for u in [-30.0f32, -9.0, -1.0, -1e-3, 0.0, 0.5, 3.0, 12.0, 40.0] {
            let got = f64::from(log1m_tanh_sq(u));
            let want = log1m_tanh_sq_f64(f64::from(u));
            assert!(
                (got - want).abs() < 1e-5 * (1.0 + want.abs()),
                "u={u}: {got} vs {want}"
            );
        }
        // The naive form underflows to -inf in f32 at u = 12.
        assert!((1.0 - 12.0f32.tanh().powi(2)).ln().is_infinite());
    }

    #[test]
    fn fused_tanh_and_log_det_match_f64_to_a_few_ulps() {
        let ulp = |x: f64| f64::from(f32::EPSILON) * x.abs().max(f64::from(f32::MIN_POSITIVE));
        for u in [
            -40.0f32, -12.0, -9.0, -1.0, -1e-3, -1e-30, 0.0, 1e-7, 2e-4, 0.5, 0.9, 3.0, 12.0, 88.0,
        ] {
            let (a, l) = tanh_and_log1m_tanh_sq(u);
            let want_a = f64::from(u).tanh();
            let want_l = log1m_tanh_sq_f64(f64::from(u));
            assert!(
                (f64::from(a) - want_a).abs() <= 4.0 * ulp(want_a),
                "u={u}: tanh {a} vs {want_a}"
            );
            // Near 0 the log-det (≈ -u²) is accurate to a few ulps of 1, as the separate form.
            assert!(
                (f64::from(l) - want_l).abs() <= 4.0 * ulp(want_l.abs().max(1.0)),
                "u={u}: log det {l} vs {want_l}"
            );
            assert!(a.abs() <= 1.0 && l <= 0.0);
            // The same value as the separate stable form, to rounding.
            let sep = f64::from(log1m_tanh_sq(u));
            assert!(
                (f64::from(l) - sep).abs() <= 1e-5 * (1.0 + sep.abs()),
                "u={u}"
            );
        }
        assert_eq!(
            tanh_and_log1m_tanh_sq(-0.0).0.to_bits(),
            (-0.0f32).to_bits()
        );
        assert_eq!(
            tanh_and_log1m_tanh_sq(f32::INFINITY),
            (1.0, f32::NEG_INFINITY)
        );
        assert!(tanh_and_log1m_tanh_sq(f32::NAN).1.is_nan());
    }

    #[test]
    fn tanh_gaussian_log_prob_matches_change_of_variables_and_integrates_to_one() {
        let head = TanhGaussian::new(2);
        let out = [0.3f32, -1.1, -0.5, 0.2]; // μ = (0.3, -1.1), log σ = (-0.5, 0.2)
        let eps = [0.7f32, -1.9];
        let mut s = TanhGaussianSample::default();
        head.sample_with_noise(&out, 1, &eps, &mut s).unwrap();
        let mut want = 0.0f64;
        for j in 0..2 {
            let (mu, ls, e) = (f64::from(out[j]), f64::from(out[2 + j]), f64::from(eps[j]));
            let u = mu + ls.exp() * e;
            let log_n =
                -0.5 * ((u - mu) / ls.exp()).powi(2) - ls - 0.5 * (2.0 * std::f64::consts::PI).ln();
            want += log_n - (1.0 - u.tanh().powi(2)).ln();
            assert!((f64::from(s.action[j]) - u.tanh()).abs() < 1e-6);
        }
        assert!(
            (f64::from(s.log_prob[0]) - want).abs() < 1e-4,
            "{} vs {want}",
            s.log_prob[0]
        );
        // log_prob of the sampled action agrees with the sample's own log-prob.
        let mut lp = [0.0f32];
        head.log_prob(&out, 1, &s.action, &mut lp).unwrap();
        assert!((lp[0] - s.log_prob[0]).abs() < 1e-3);

        // 1-D density over a ∈ (-1, 1) integrates to 1 (midpoint rule).
        let h1 = TanhGaussian::new(1);
        let o1 = [0.4f32, -0.3];
        let n = 200_000;
        let mut total = 0.0f64;
        let mut p = [0.0f32];
        for i in 0..n {
            let a = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
            h1.log_prob(&o1, 1, &[a as f32], &mut p).unwrap();
            total += f64::from(p[0]).exp() * 2.0 / n as f64;
        }
        assert!((total - 1.0).abs() < 2e-3, "integral {total}");
    }

    #[test]
    fn tanh_gaussian_backward_matches_finite_differences() {
        let head = TanhGaussian::new(3);
        let batch = 2;
        let mut rng = rng_from_seed(4);
        let out: Vec<f32> = (0..batch * 6)
            .map(|i| ((i as f32) * 0.77).sin() * if i % 6 >= 3 { 0.8 } else { 1.5 })
            .collect();
        let mut s = TanhGaussianSample::default();
        head.sample(&out, batch, &mut rng, &mut s).unwrap();
        let eps = s.eps.clone();
        let wa: Vec<f32> = (0..batch * 3).map(|i| 0.3 - 0.2 * i as f32).collect();
        let wl = [0.7f32, -0.4];
        let loss = |o: &[f32]| -> f64 {
            let mut t = TanhGaussianSample::default();
            head.sample_with_noise(o, batch, &eps, &mut t).unwrap();
            let la: f64 = t
                .action
                .iter()
                .zip(&wa)
                .map(|(a, w)| f64::from(a * w))
                .sum();
            let ll: f64 = t
                .log_prob
                .iter()
                .zip(&wl)
                .map(|(a, w)| f64::from(a * w))
                .sum();
            la + ll
        };
        let mut g = vec![0.0f32; batch * 6];
        head.backward(&s, Some(&wa), Some(&wl), &mut g).unwrap();
        for i in 0..g.len() {
            let h = 1e-3f32;
            let (mut p, mut m) = (out.clone(), out.clone());
            p[i] += h;
            m[i] -= h;
            let fd = (loss(&p) - loss(&m)) / (2.0 * f64::from(h));
            assert!(
                (fd - f64::from(g[i])).abs() < 2e-3 * (1.0 + fd.abs()),
                "[{i}] fd {fd} vs {}",
                g[i]
            );
        }
        // Clamped log-std passes no gradient.
        let clamped = [0.0f32, 5.0];
        let h1 = TanhGaussian::new(1);
        h1.sample_with_noise(&clamped, 1, &[0.5], &mut s).unwrap();
        let mut g1 = [0.0f32; 2];
        h1.backward(&s, Some(&[1.0]), Some(&[1.0]), &mut g1)
            .unwrap();
        assert_eq!(g1[1], 0.0);
        assert!((s.log_std[0] - 2.0).abs() < 1e-7);
    }

    /// The actions alone are `sample`'s, bit for bit (log-stds clamped at both ends too), with
    /// the same draws: the generator is left where `sample` leaves it.
    #[test]
    fn sample_actions_are_the_actions_of_sample() {
        let head = TanhGaussian::new(3);
        let mut rng = rng_from_seed(4);
        let batch = 50;
        let mut out: Vec<f32> = (0..batch * 6)
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        (out[3], out[4]) = (5.0, -30.0);
        let (mut r1, mut r2) = (rng_from_seed(9), rng_from_seed(9));
        let mut full = TanhGaussianSample::default();
        head.sample(&out, batch, &mut r1, &mut full).unwrap();
        let mut actions = vec![0.0; batch * 3];
        head.sample_actions(&out, batch, &mut r2, &mut actions)
            .unwrap();
        for (i, (a, b)) in actions.iter().zip(&full.action).enumerate() {
            assert_eq!(a.to_bits(), b.to_bits(), "element {i}");
            let (r, j) = (i / 3, i % 3);
            let ls = f64::from(out[r * 6 + 3 + j]).clamp(-20.0, 2.0);
            let want = (f64::from(out[r * 6 + j]) + ls.exp() * f64::from(full.eps[i])).tanh();
            assert!((f64::from(*a) - want).abs() < 1e-6, "element {i}");
        }
        assert_eq!(r1.random::<u64>(), r2.random::<u64>());
        assert!(head
            .sample_actions(&out, batch, &mut r2, &mut actions[1..])
            .is_err());
    }

    #[test]
    fn sampling_is_seeded_and_mode_is_tanh_of_mean() {
        let head = TanhGaussian::new(2);
        let out = [0.1f32, 0.2, -1.0, -1.0, 2.0, -3.0, 0.0, 0.0];
        let (mut a, mut b) = (TanhGaussianSample::default(), TanhGaussianSample::default());
        head.sample(&out, 2, &mut rng_from_seed(1), &mut a).unwrap();
        head.sample(&out, 2, &mut rng_from_seed(1), &mut b).unwrap();
        assert_eq!(a.action, b.action);
        let mut m = [0.0f32; 4];
        head.mode(&out, 2, &mut m).unwrap();
        assert_eq!(
            m,
            [
                0.1f32.tanh(),
                0.2f32.tanh(),
                2.0f32.tanh(),
                (-3.0f32).tanh()
            ]
        );
        assert!(head
            .sample(&out[..7], 2, &mut rng_from_seed(1), &mut a)
            .is_err());
        assert!(head
            .sample(&[f32::NAN; 8], 2, &mut rng_from_seed(1), &mut a)
            .is_err());
    }

    #[test]
    fn gaussian_head_bounds_and_gradients() {
        let mut head = GaussianHead::with_bounds(2, -4.0, 1.0).unwrap();
        let raws = [-100.0f32, -4.0, 0.0, 1.0, 100.0];
        let mut o = GaussianOutput::default();
        for r in raws {
            head.forward(&[0.5, -0.5, r, r], 1, &mut o).unwrap();
            // Soft bounds: above min, and above max by at most softplus(min - max).
            let hi = 1.0 + softplus(-5.0) + 1e-6;
            assert!(
                o.log_var.iter().all(|lv| (-4.0..=hi).contains(lv)),
                "raw {r}: {:?}",
                o.log_var
            );
            assert_eq!(o.mean, vec![0.5, -0.5]);
        }
        // Far inside the bounds the head is nearly the identity.
        head.forward(&[0.0, 0.0, -1.5, -1.5], 1, &mut o).unwrap();
        assert!((o.log_var[0] + 1.5).abs() < 0.1);

        head.bounds_mut()[1] = -3.0; // per-dim bounds
        let net: Vec<f32> = vec![0.3, -0.2, 0.8, -2.9, -0.1, 0.4, -6.0, 0.3];
        let dm = [0.5f32, -1.0, 0.25, 2.0];
        let dl = [1.0f32, 0.3, -0.7, 0.9];
        let f = |h: &GaussianHead, x: &[f32]| -> f64 {
            let mut o = GaussianOutput::default();
            h.forward(x, 2, &mut o).unwrap();
            o.mean
                .iter()
                .zip(&dm)
                .chain(o.log_var.iter().zip(&dl))
                .map(|(a, b)| f64::from(a * b))
                .sum()
        };
        head.forward(&net, 2, &mut o).unwrap();
        let mut g = vec![0.0f32; 8];
        let mut gb = vec![0.0f32; 4];
        head.backward(&o, &dm, &dl, &mut g, Some(&mut gb)).unwrap();
        let hstep = 1e-3f32;
        for i in 0..8 {
            let (mut p, mut m) = (net.clone(), net.clone());
            p[i] += hstep;
            m[i] -= hstep;
            let fd = (f(&head, &p) - f(&head, &m)) / (2.0 * f64::from(hstep));
            assert!(
                (fd - f64::from(g[i])).abs() < 2e-3,
                "net[{i}]: {fd} vs {}",
                g[i]
            );
        }
        for i in 0..4 {
            let (mut p, mut m) = (head.clone(), head.clone());
            p.bounds_mut()[i] += hstep;
            m.bounds_mut()[i] -= hstep;
            let fd = (f(&p, &net) - f(&m, &net)) / (2.0 * f64::from(hstep));
            assert!(
                (fd - f64::from(gb[i])).abs() < 2e-3,
                "bound[{i}]: {fd} vs {}",
                gb[i]
            );
        }
        assert!(GaussianHead::with_bounds(1, 1.0, 0.0).is_err());
    }

    #[test]
    fn gaussian_head_predict_is_forward_without_the_backward() {
        let mut head = GaussianHead::with_bounds(3, -10.0, 0.5).unwrap();
        head.bounds_mut()[4] = 2.0; // per-dim bounds
        let net: Vec<f32> = (0..6 * 40)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.3)
            .collect();
        let (mut f, mut p) = (GaussianOutput::default(), GaussianOutput::default());
        head.forward(&net, 40, &mut f).unwrap();
        head.predict(&net, 40, &mut p).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&p.mean), bits(&f.mean));
        assert_eq!(bits(&p.log_var), bits(&f.log_var));
        let d = vec![1.0; 120];
        let mut g = vec![0.0; 240];
        assert!(head.backward(&p, &d, &d, &mut g, None).is_err());
        assert!(head.backward(&f, &d, &d, &mut g, None).is_ok());
        assert!(head.predict(&net[1..], 40, &mut p).is_err());
    }

    #[test]
    fn categorical_probabilities_sampling_and_gradient() {
        let c = Categorical::new(3);
        let logits = [1.0f32, 2.0, 0.5, -50.0, 60.0, 0.0];
        let mut lp = [0.0f32; 6];
        c.log_softmax(&logits, 2, &mut lp).unwrap();
        for row in lp.chunks(3) {
            let s: f32 = row.iter().map(|v| v.exp()).sum();
            assert!((s - 1.0).abs() < 1e-6);
        }
        let z: f64 = [1.0f64, 2.0, 0.5].iter().map(|v| v.exp()).sum();
        assert!((f64::from(lp[1]) - (2.0 - z.ln())).abs() < 1e-6);
        // Sampling frequencies follow the probabilities.
        let mut rng = rng_from_seed(3);
        let mut counts = [0usize; 3];
        let mut a = [0usize; 1];
        for _ in 0..30_000 {
            c.sample(&lp[..3], 1, &mut rng, &mut a).unwrap();
            counts[a[0]] += 1;
        }
        for j in 0..3 {
            let f = counts[j] as f32 / 30_000.0;
            assert!((f - lp[j].exp()).abs() < 0.01, "action {j}: {f}");
        }
        let mut am = [0usize; 2];
        c.argmax(&logits, 2, &mut am).unwrap();
        assert_eq!(am, [1, 1]);
        // Gradient of w·log π(a) + c·H vs finite differences.
        let x = [0.3f32, -0.8, 1.1];
        let (act, w, coef) = (2usize, 1.7f32, 0.4f32);
        let f = |z: &[f32]| -> f64 {
            let mut l = [0.0f32; 3];
            c.log_softmax(z, 1, &mut l).unwrap();
            let h: f32 = -l.iter().map(|v| v.exp() * v).sum::<f32>();
            f64::from(w * l[act] + coef * h)
        };
        c.log_softmax(&x, 1, &mut lp[..3]).unwrap();
        let mut g = [0.0f32; 3];
        c.backward(&lp[..3], &[act], &[w], coef, &mut g).unwrap();
        for i in 0..3 {
            let (mut p, mut m) = (x, x);
            p[i] += 1e-3;
            m[i] -= 1e-3;
            let fd = (f(&p) - f(&m)) / 2e-3;
            assert!(
                (fd - f64::from(g[i])).abs() < 2e-3,
                "[{i}] {fd} vs {}",
                g[i]
            );
        }
        assert!(c.backward(&lp[..3], &[3], &[1.0], 0.0, &mut g).is_err());
    }
}
