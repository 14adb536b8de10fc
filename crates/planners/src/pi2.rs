//! Policy improvement with path integrals for TVLG controllers (PI², p4 §II-B; Theodorou et al.
//! 2010 with the per-time-step KL constraint of Chebotar et al. 2017).
//!
//! At each step `t`, sample `i` gets the probability `P_{i,t} ∝ exp(−S_{i,t}/η_t)` of its
//! cost-to-go (p4 eq. 2); the temperature `η_t` is the dual variable of
//! `KL(P_t ‖ uniform) ≤ ε` (Theorem 1), found by bisection in log space (the dual is convex and its
//! derivative is `ε − KL`). The new `K_t, k_t, Σ_t` are the weighted maximum-likelihood fit of
//! the sampled `u_{i,t}` on `x_{i,t}` (ridge-regularized towards the previous gains so that few
//! effective samples still give a well-posed fit; `Σ_t` floored at `min_variance`, optionally
//! damped towards the previous `Σ_t` as in the authors' GPS code, `covariance_damping`).

use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, Array3};

use crate::error::{check_len, Result};
use crate::mpc::positive;
use crate::tvlg::TvlgController;

/// Settings of [`pi2_update`]. `kl_step` is ours (p4 gives none); the rest are numerical guards.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Pi2Config {
    /// KL bound `ε` between the sample weights and uniform weights, per step.
    pub kl_step: f64,
    /// Ridge weight pulling `[K_t k_t]` towards the previous controller's.
    pub ridge: f64,
    /// Floor added to the diagonal of every updated `Σ_t`.
    pub min_variance: f64,
    /// Whether to refit the gains `K_t` (otherwise only `k_t` and `Σ_t` move).
    pub update_gains: bool,
    /// Covariance damping `d` (the authors' GPS `TrajOptPI2`, `covariance_damping`): with `d > 0`
    /// the new `Σ_t` is the old one scaled by `s^{1/d}`, `s = tr(Σ_old⁻¹ Σ_ML)/A`, instead of the
    /// weighted maximum-likelihood `Σ_ML` itself (`0`: plain ML). Keeps exploration from
    /// collapsing on a few effective samples.
    pub covariance_damping: f64,
}

impl Default for Pi2Config {
    fn default() -> Self {
        Self {
            kl_step: 0.5,
            ridge: 1e-3,
            min_variance: 1e-6,
            update_gains: true,
            covariance_damping: 0.0,
        }
    }
}

impl Pi2Config {
    /// Checks a positive `kl_step`, and finite, non-negative `ridge`, `min_variance` and
    /// `covariance_damping`.
    pub fn validate(&self) -> Result<()> {
        positive("kl_step", self.kl_step)?;
        for (what, v) in [
            ("ridge", self.ridge),
            ("min_variance", self.min_variance),
            ("covariance_damping", self.covariance_damping),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(crate::PlanError::Config(format!(
                    "{what} must be finite and non-negative, got {v}"
                )));
            }
        }
        Ok(())
    }
}

/// The result of one PI² update.
#[derive(Debug, Clone)]
pub struct Pi2Step {
    /// The new controller.
    pub controller: TvlgController,
    /// Temperatures `η_t`.
    pub etas: Vec<f64>,
    /// Sample weights `P_{i,t}`, `N x T`.
    pub weights: Array2<f64>,
}

/// Weights `softmax(−(S − min S)/η)` with `KL(w ‖ uniform) ≈ ε`, and the `η` found.
pub fn pi2_weights(s: &[f64], eps: f64) -> (Vec<f64>, f64) {
    let n = s.len();
    let smin = s.iter().copied().fold(f64::INFINITY, f64::min);
    let smax = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let spread = (smax - smin).max(1e-300);
    let weights = |eta: f64| -> Vec<f64> {
        let w: Vec<f64> = s.iter().map(|v| (-(v - smin) / eta).exp()).collect();
        let z: f64 = w.iter().sum();
        w.into_iter().map(|v| v / z).collect()
    };
    let kl = |w: &[f64]| -> f64 {
        w.iter()
            .filter(|&&v| v > 0.0)
            .map(|v| v * (v * n as f64).ln())
            .sum()
    };
    if spread <= 1e-300 {
        return (vec![1.0 / n as f64; n], f64::INFINITY);
    }
    // KL decreases in η: bisection in log space between "one sample" and "uniform".
    let (mut lo, mut hi) = ((spread * 1e-8).ln(), (spread * 1e8).ln());
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if kl(&weights(mid.exp())) > eps {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let eta = hi.exp();
    (weights(eta), eta)
}

/// Weights `softmax(−(S − min S)/η)` at a given temperature `η` (`+∞`: uniform).
fn weights_at(s: &[f64], eta: f64) -> Vec<f64> {
    let smin = s.iter().copied().fold(f64::INFINITY, f64::min);
    let w: Vec<f64> = s
        .iter()
        .map(|v| {
            if eta.is_finite() {
                (-(v - smin) / eta).exp()
            } else {
                1.0
            }
        })
        .collect();
    let z: f64 = w.iter().sum();
    w.into_iter().map(|v| v / z).collect()
}

/// One PI² update of `prev` from samples: `states` `N x (T+1) x S` (or `N x T x S`), `actions`
/// `N x T x A` (the controls to reweigh: the sampled ones, or in PILQR their reparametrized
/// versions), `cost_to_go` `N x T`.
pub fn pi2_update(
    prev: &TvlgController,
    states: &Array3<f64>,
    actions: &Array3<f64>,
    cost_to_go: &Array2<f64>,
    cfg: &Pi2Config,
) -> Result<Pi2Step> {
    pi2_update_with_temperatures(prev, states, actions, cost_to_go, cfg, None)
}

/// [`pi2_update`] with the temperatures `η_t` given instead of found from the KL bound (`None`:
/// from the bound). PILQR finds `η_t` on the full cost-to-go and then reweighs by the residual
/// cost-to-go at those temperatures (the authors' GPS code, `traj_opt_pilqr.py`: `fixed_eta`),
/// so that residuals that are small next to the full cost spread move the controller little.
pub fn pi2_update_with_temperatures(
    prev: &TvlgController,
    states: &Array3<f64>,
    actions: &Array3<f64>,
    cost_to_go: &Array2<f64>,
    cfg: &Pi2Config,
    temperatures: Option<&[f64]>,
) -> Result<Pi2Step> {
    cfg.validate()?;
    let (n_s, t_len, m) = actions.dim();
    let n = prev.state_dim();
    check_len("controller horizon", prev.horizon(), t_len)?;
    check_len("controller action dimension", prev.action_dim(), m)?;
    check_len("state samples", n_s, states.shape()[0])?;
    check_len("state dimension", n, states.shape()[2])?;
    check_len("cost-to-go rows", n_s, cost_to_go.nrows())?;
    check_len("cost-to-go columns", t_len, cost_to_go.ncols())?;
    if cost_to_go.iter().any(|v| !v.is_finite()) {
        return Err(crate::PlanError::NonFinite("PI2 cost-to-go".into()));
    }
    if let Some(etas) = temperatures {
        check_len("PI2 temperatures", t_len, etas.len())?;
        if let Some(e) = etas.iter().find(|e| e.is_nan() || **e <= 0.0) {
            return Err(crate::PlanError::Config(format!(
                "PI2 temperatures must be positive (+inf: uniform weights), got {e}"
            )));
        }
    }
    let mut gains = Vec::with_capacity(t_len);
    let mut offsets = Vec::with_capacity(t_len);
    let mut covs = Vec::with_capacity(t_len);
    let mut etas = Vec::with_capacity(t_len);
    let mut wmat = Array2::zeros((n_s, t_len));
    let d = n + 1;
    for t in 0..t_len {
        let column = cost_to_go.column(t).to_vec();
        let (w, eta) = match temperatures {
            Some(etas) => (weights_at(&column, etas[t]), etas[t]),
            None => pi2_weights(&column, cfg.kl_step),
        };
        etas.push(eta);
        // Weighted least squares of u on [x; 1] (or on 1 with K fixed), ridge towards prev.
        let mut theta_prev = DMatrix::zeros(d, m);
        theta_prev
            .view_mut((0, 0), (n, m))
            .copy_from(&prev.gains[t].transpose());
        theta_prev
            .row_mut(n)
            .copy_from(&prev.offsets[t].transpose());
        let mut a = DMatrix::zeros(d, d);
        let mut b = DMatrix::zeros(d, m);
        for i in 0..n_s {
            let mut z = DVector::zeros(d);
            for j in 0..n {
                z[j] = states[(i, t, j)];
            }
            z[n] = 1.0;
            let mut u = DVector::zeros(m);
            for j in 0..m {
                u[j] = actions[(i, t, j)];
                if !cfg.update_gains {
                    // Remove the fixed feedback part; only the offset is fitted.
                    u[j] -= (prev.gains[t].row(j) * z.rows(0, n))[0];
                }
            }
            a += &z * z.transpose() * w[i];
            b += &z * u.transpose() * w[i];
            wmat[(i, t)] = w[i];
        }
        let theta = if cfg.update_gains {
            let reg = DMatrix::identity(d, d) * cfg.ridge;
            (a + &reg)
                .cholesky()
                .ok_or_else(|| crate::PlanError::Numerical(format!("PI2 regression at step {t}")))?
                .solve(&(b + reg * &theta_prev))
        } else {
            let mut th = theta_prev.clone();
            th.row_mut(n).copy_from(&(b.row(n) / a[(n, n)]));
            th
        };
        let kt = theta.view((0, 0), (n, m)).transpose();
        let kk = theta.row(n).transpose();
        let mut cov = DMatrix::identity(m, m) * cfg.min_variance;
        for i in 0..n_s {
            let x = DVector::from_iterator(n, (0..n).map(|j| states[(i, t, j)]));
            let u = DVector::from_iterator(m, (0..m).map(|j| actions[(i, t, j)]));
            let r = u - &kt * x - &kk;
            cov += &r * r.transpose() * w[i];
        }
        if cfg.covariance_damping > 0.0 {
            let ratio = (prev.inv_cov(t) * &cov).trace() / m as f64;
            cov = &prev.cov[t] * ratio.powf(1.0 / cfg.covariance_damping);
        }
        gains.push(kt);
        offsets.push(kk);
        covs.push(cov);
    }
    Ok(Pi2Step {
        controller: TvlgController::new(gains, offsets, covs)?,
        etas,
        weights: wmat,
    })
}
