//! Losses with their gradients, all reduced by the mean over every element (PyTorch's default
//! `reduction="mean"`), accumulated in f64. Each returns the loss and, if asked, **overwrites**
//! `grad` with `dloss/dprediction`. A non-finite loss is an error.

use crate::error::{check_finite_scalar, check_len, NnError, Result};
use crate::fastmath;
use crate::heads::softplus;
use crate::mlp::sigmoid;
use crate::simd::multiversion;

fn check_pair(what: &str, pred: &[f32], target: &[f32], grad: Option<&[f32]>) -> Result<()> {
    check_len(&format!("{what} target"), pred.len(), target.len())?;
    if let Some(g) = grad {
        check_len(&format!("{what} gradient"), pred.len(), g.len())?;
    }
    if pred.is_empty() {
        return Err(NnError::InvalidConfig(format!("{what}: empty prediction")));
    }
    Ok(())
}

/// Mean squared error `mean((pred - target)²)`.
pub fn mse(pred: &[f32], target: &[f32], grad: Option<&mut [f32]>) -> Result<f32> {
    check_pair("mse", pred, target, grad.as_deref())?;
    let n = pred.len() as f32;
    let mut s = 0.0f64;
    for (p, t) in pred.iter().zip(target) {
        let d = f64::from(p - t);
        s += d * d;
    }
    let loss = check_finite_scalar("mse loss", (s / pred.len() as f64) as f32)?;
    if let Some(g) = grad {
        for ((g, p), t) in g.iter_mut().zip(pred).zip(target) {
            *g = 2.0 * (p - t) / n;
        }
    }
    Ok(loss)
}

/// Huber loss with threshold `delta` (`torch.nn.HuberLoss`; with δ = 1 it equals
/// `smooth_l1_loss`, DQN's loss): `½d²` for `|d| ≤ δ`, `δ(|d| - ½δ)` beyond.
pub fn huber(pred: &[f32], target: &[f32], delta: f32, grad: Option<&mut [f32]>) -> Result<f32> {
    check_pair("huber", pred, target, grad.as_deref())?;
    if !(delta.is_finite() && delta > 0.0) {
        return Err(NnError::InvalidConfig(format!(
            "huber delta must be > 0, got {delta}"
        )));
    }
    let n = pred.len() as f32;
    let mut s = 0.0f64;
    for (p, t) in pred.iter().zip(target) {
        let d = f64::from(p - t);
        let a = d.abs();
        let dl = f64::from(delta);
        s += if a <= dl {
            0.5 * d * d
        } else {
            dl * (a - 0.5 * dl)
        };
    }
    let loss = check_finite_scalar("huber loss", (s / pred.len() as f64) as f32)?;
    if let Some(g) = grad {
        for ((g, p), t) in g.iter_mut().zip(pred).zip(target) {
            *g = (p - t).clamp(-delta, delta) / n;
        }
    }
    Ok(loss)
}

/// Binary cross-entropy on logits, `mean(softplus(x) - x·t)`, stable for any logit (candle's
/// version returns inf near ±30). Targets in `[0, 1]`.
pub fn bce_with_logits(logits: &[f32], target: &[f32], grad: Option<&mut [f32]>) -> Result<f32> {
    check_pair("bce", logits, target, grad.as_deref())?;
    let n = logits.len() as f32;
    let mut s = 0.0f64;
    for (x, t) in logits.iter().zip(target) {
        s += f64::from(softplus(*x)) - f64::from(*x) * f64::from(*t);
    }
    let loss = check_finite_scalar("bce loss", (s / logits.len() as f64) as f32)?;
    if let Some(g) = grad {
        for ((g, x), t) in g.iter_mut().zip(logits).zip(target) {
            *g = (sigmoid(*x) - t) / n;
        }
    }
    Ok(loss)
}

/// Gaussian negative log-likelihood with a predicted log-variance:
/// `mean(½[(y - μ)² e^{-lv} + lv + ln 2π])` (the full NLL per element, so values are comparable
/// across models; the constant does not change gradients). Writes `dloss/dμ` and `dloss/dlv`
/// when asked.
pub fn gaussian_nll(
    mean: &[f32],
    log_var: &[f32],
    target: &[f32],
    d_mean: Option<&mut [f32]>,
    d_log_var: Option<&mut [f32]>,
) -> Result<f32> {
    check_pair("gaussian nll", mean, target, d_mean.as_deref())?;
    check_len("gaussian nll log_var", mean.len(), log_var.len())?;
    if let Some(d) = d_log_var.as_deref() {
        check_len("gaussian nll log_var gradient", mean.len(), d.len())?;
    }
    let ln2pi = (2.0 * std::f64::consts::PI).ln();
    let sum = gaussian_nll_pass(
        mean,
        log_var,
        target,
        d_mean.unwrap_or(&mut []),
        d_log_var.unwrap_or(&mut []),
    );
    let loss = check_finite_scalar(
        "gaussian nll loss",
        (0.5 * (sum / mean.len() as f64 + ln2pi)) as f32,
    )?;
    Ok(loss)
}

/// Elements per block of [`gaussian_nll_pass`]: its per-element terms wait on the stack for the
/// f64 sum, which runs in order (a vectorized sum would reassociate it).
const NLL_BLOCK: usize = 256;

multiversion! {
    /// `Σ (y - m)² e^{-lv} + lv` over the elements, in f64, and into each non-empty gradient
    /// buffer the mean's `(m - y) e^{-lv} / n` or the log-variance's `(1 - (y - m)² e^{-lv}) / 2n`
    /// (`n` elements): one `exp` per element serves all three.
    fn gaussian_nll_pass(
        mean: &[f32],
        log_var: &[f32],
        target: &[f32],
        d_mean: &mut [f32],
        d_log_var: &mut [f32],
    ) -> f64 {
        let n = mean.len() as f32;
        let mut total = 0.0f64;
        let (mut terms, mut inv_var) = ([0.0f32; NLL_BLOCK], [0.0f32; NLL_BLOCK]);
        for (start, (m, lv)) in mean.chunks(NLL_BLOCK).zip(log_var.chunks(NLL_BLOCK)).enumerate() {
            let start = start * NLL_BLOCK;
            let y = &target[start..start + m.len()];
            let terms = &mut terms[..m.len()];
            let inv_var = &mut inv_var[..m.len()];
            let pairs = terms.iter_mut().zip(inv_var.iter_mut());
            for ((((q, iv), m), lv), y) in pairs.zip(m).zip(lv).zip(y) {
                let d = y - m;
                *iv = fastmath::exp(-lv);
                *q = d * d * *iv + lv;
            }
            if let Some(g) = d_mean.get_mut(start..start + m.len()) {
                for (((g, m), iv), y) in g.iter_mut().zip(m).zip(inv_var.iter()).zip(y) {
                    *g = (m - y) * iv / n;
                }
            }
            if let Some(g) = d_log_var.get_mut(start..start + m.len()) {
                for (((g, m), iv), y) in g.iter_mut().zip(m).zip(inv_var.iter()).zip(y) {
                    let d = y - m;
                    *g = 0.5 * (1.0 - d * d * iv) / n;
                }
            }
            for q in terms.iter() {
                total += f64::from(*q);
            }
        }
        total
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    /// Central finite difference of `f` at `x` in coordinate `i`, in f64 on f32 inputs.
    fn fd(f: &dyn Fn(&[f32]) -> f32, x: &[f32], i: usize, h: f32) -> f32 {
        let (mut a, mut b) = (x.to_vec(), x.to_vec());
        a[i] += h;
        b[i] -= h;
        (f(&a) - f(&b)) / (2.0 * h)
    }

    #[test]
    fn values_match_closed_forms() {
        let p = [1.0f32, 2.0, -1.0];
        let t = [0.0f32, 2.0, 1.0];
        assert!((mse(&p, &t, None).unwrap() - 5.0 / 3.0).abs() < 1e-6);
        // huber δ=1: d = (1, 0, -2) -> 0.5, 0, 1.5
        assert!((huber(&p, &t, 1.0, None).unwrap() - 2.0 / 3.0).abs() < 1e-6);
        // bce: -[t ln σ(x) + (1-t) ln(1-σ(x))] on moderate logits
        let x = [0.3f32, -2.0, 4.0, -1.0];
        let y = [1.0f32, 0.0, 0.25, 0.0];
        let want: f64 = x
            .iter()
            .zip(&y)
            .map(|(x, y)| {
                let s = 1.0 / (1.0 + (-f64::from(*x)).exp());
                let y = f64::from(*y);
                -(y * s.ln() + (1.0 - y) * (1.0 - s).ln())
            })
            .sum::<f64>()
            / 4.0;
        let got = bce_with_logits(&x, &y, None).unwrap();
        assert!(
            ((f64::from(got) - want) / want).abs() < 1e-5,
            "{got} vs {want}"
        );
        // Extreme logits: loss ≈ |x| when wrong, ≈ 0 when right (candle gives inf here).
        assert!((bce_with_logits(&[35.0], &[0.0], None).unwrap() - 35.0).abs() < 1e-5);
        assert!((bce_with_logits(&[-40.0], &[1.0], None).unwrap() - 40.0).abs() < 1e-5);
        assert!(bce_with_logits(&[-40.0], &[0.0], None).unwrap().abs() < 1e-6);
        // gaussian nll vs the log-density of N(μ, σ²)
        let (m, lv, yv) = (0.5f32, 0.7f32, -0.3f32);
        let var = f64::from(lv).exp();
        let logpdf = -0.5 * (2.0 * std::f64::consts::PI * var).ln()
            - (f64::from(yv) - f64::from(m)).powi(2) / (2.0 * var);
        let nll = gaussian_nll(&[m], &[lv], &[yv], None, None).unwrap();
        assert!((f64::from(nll) + logpdf).abs() < 1e-6);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let p = [0.4f32, -1.3, 2.5, 0.05];
        let t = [0.0f32, 0.2, 1.0, 0.05];
        let mut g = [0.0f32; 4];
        mse(&p, &t, Some(&mut g)).unwrap();
        for i in 0..4 {
            let n = fd(&|x| mse(x, &t, None).unwrap(), &p, i, 1e-3);
            assert!((n - g[i]).abs() < 1e-3, "mse {i}");
        }
        huber(&p, &t, 1.0, Some(&mut g)).unwrap();
        for i in 0..3 {
            let n = fd(&|x| huber(x, &t, 1.0, None).unwrap(), &p, i, 1e-3);
            assert!((n - g[i]).abs() < 1e-3, "huber {i}");
        }
        let tb = [1.0f32, 0.0, 0.3, 1.0];
        bce_with_logits(&p, &tb, Some(&mut g)).unwrap();
        for i in 0..4 {
            let n = fd(&|x| bce_with_logits(x, &tb, None).unwrap(), &p, i, 1e-3);
            assert!((n - g[i]).abs() < 1e-3, "bce {i}");
        }
        let lv = [0.1f32, -1.0, 0.5, 2.0];
        let (mut gm, mut gl) = ([0.0f32; 4], [0.0f32; 4]);
        gaussian_nll(&p, &lv, &t, Some(&mut gm), Some(&mut gl)).unwrap();
        for i in 0..4 {
            let n = fd(
                &|x| gaussian_nll(x, &lv, &t, None, None).unwrap(),
                &p,
                i,
                1e-3,
            );
            assert!((n - gm[i]).abs() < 2e-3, "nll mean {i}: {n} vs {}", gm[i]);
            let n = fd(
                &|x| gaussian_nll(&p, x, &t, None, None).unwrap(),
                &lv,
                i,
                1e-3,
            );
            assert!((n - gl[i]).abs() < 2e-3, "nll logvar {i}: {n} vs {}", gl[i]);
        }
    }

    #[test]
    fn errors() {
        assert!(mse(&[1.0], &[1.0, 2.0], None).is_err());
        assert!(mse(&[], &[], None).is_err());
        assert!(matches!(
            mse(&[f32::NAN], &[1.0], None),
            Err(NnError::NonFinite { .. })
        ));
        assert!(huber(&[1.0], &[1.0], 0.0, None).is_err());
        let mut g = [0.0f32; 2];
        assert!(bce_with_logits(&[1.0], &[1.0], Some(&mut g)).is_err());
        assert!(gaussian_nll(&[0.0], &[-200.0], &[1.0], None, None).is_err());
    }
}
