//! LQR with fitted linear models (LQR-FLM, p4 §II-A; Levine & Abbeel 2014).
//!
//! Given the previous controller `p̄`, TVLG dynamics fitted to its samples and a quadratic cost,
//! solve `min E_p[Q]` subject to `E[KL(p ‖ p̄)] ≤ ε` **at every time step** (p4 eq. 1: one
//! constraint per step, not one on the whole trajectory). With a dual variable `η_t` per step the
//! Lagrangian is an LQR problem with the cost `c/η_t − log p̄(u|x)`; its maximum-entropy solution
//! is a TVLG controller with `Σ_t = Q_uu⁻¹` ([`LqrFlm::backward`]). Each `η_t` is found by
//! bracketing in log space on the constraint `KL_t − ε` (the KL evaluated under the new
//! controller's state distribution, p4 footnote 1). Where `Q_uu` is not positive definite the
//! step's `η_t` is raised (×10) and the pass repeated: the known failure of earlier
//! implementations becomes a smaller step instead of an error.

use nalgebra::{DMatrix, DVector};
use tandem_models::TvlgDynamics;

use crate::error::{check_len, PlanError, Result};
use crate::mpc::positive;
use crate::tvlg::{expected_cost, forward_moments, policy_kl, QuadraticCost, TvlgController};

/// Settings of [`LqrFlm`]. Defaults follow GPS's `traj_opt_lqr_python` (η bounds `[1e-8, 1e16]`,
/// 50 dual iterations, constraint met within 10% of ε); `kl_step = 1.0` per step is ours.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LqrFlmConfig {
    /// KL bound `ε` per time step.
    pub kl_step: f64,
    /// Smallest dual variable.
    pub min_eta: f64,
    /// Largest dual variable.
    pub max_eta: f64,
    /// Dual iterations (backward + forward passes).
    pub dual_iterations: usize,
    /// Relative tolerance on `|KL_t − ε| / ε`.
    pub tolerance: f64,
    /// Initial dual variable.
    pub eta_init: f64,
}

impl Default for LqrFlmConfig {
    fn default() -> Self {
        Self {
            kl_step: 1.0,
            min_eta: 1e-8,
            max_eta: 1e16,
            dual_iterations: 50,
            tolerance: 0.1,
            eta_init: 1.0,
        }
    }
}

impl LqrFlmConfig {
    /// Checks positive, finite `kl_step`, `min_eta < max_eta`, `eta_init`, `tolerance`, and at
    /// least one dual iteration.
    pub fn validate(&self) -> Result<()> {
        positive("kl_step", self.kl_step)?;
        positive("min_eta", self.min_eta)?;
        positive("max_eta", self.max_eta)?;
        positive("eta_init", self.eta_init)?;
        positive("tolerance", self.tolerance)?;
        crate::mpc::nonzero("dual_iterations", self.dual_iterations)?;
        if self.min_eta >= self.max_eta {
            return Err(PlanError::Config(format!(
                "min_eta {} must be below max_eta {}",
                self.min_eta, self.max_eta
            )));
        }
        Ok(())
    }
}

/// The result of one LQR-FLM update.
#[derive(Debug, Clone)]
pub struct LqrFlmStep {
    /// The new controller.
    pub controller: TvlgController,
    /// Dual variables `η_t`.
    pub etas: Vec<f64>,
    /// `E[KL(p ‖ p̄)]` at each step.
    pub kl: Vec<f64>,
    /// Expected quadratic cost of the new controller under the fitted dynamics.
    pub predicted_cost: f64,
}

/// The LQR-FLM update; see the module docs.
#[derive(Debug, Clone)]
pub struct LqrFlm {
    cfg: LqrFlmConfig,
}

impl LqrFlm {
    /// An optimizer with these settings (checked here).
    pub fn new(cfg: LqrFlmConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(Self { cfg })
    }

    /// The settings.
    pub fn config(&self) -> &LqrFlmConfig {
        &self.cfg
    }

    /// One KL-constrained update of `prev` with step `kl_step` (the configured one if `None`).
    ///
    /// `cost` is a quadratic cost per time step, `T` running terms then the terminal one: the
    /// objective's expansion around the samples ([`crate::quadratize_cost`]), or one the caller
    /// builds per step (a time-varying target, MDGPS's surrogate with its KL term to the global
    /// policy).
    pub fn update(
        &self,
        prev: &TvlgController,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
        kl_step: Option<f64>,
    ) -> Result<LqrFlmStep> {
        let eps = kl_step.unwrap_or(self.cfg.kl_step);
        self.update_per_step(prev, dynamics, cost, &vec![eps; prev.horizon()])
    }

    /// One update with its own KL bound `ε_t` at every step (PILQR's per-step step adjustment).
    pub fn update_per_step(
        &self,
        prev: &TvlgController,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
        kl_steps: &[f64],
    ) -> Result<LqrFlmStep> {
        let t_len = prev.horizon();
        check_len("fitted dynamics horizon", t_len, dynamics.horizon())?;
        check_len("cost terms (T running + terminal)", t_len + 1, cost.len())?;
        check_len("per-step KL bounds", t_len, kl_steps.len())?;
        for &e in kl_steps {
            positive("kl_step", e)?;
        }
        let cfg = &self.cfg;
        let mut etas = vec![cfg.eta_init; t_len];
        let mut lo = vec![cfg.min_eta; t_len];
        let mut hi = vec![cfg.max_eta; t_len];
        let mut best: Option<(TvlgController, Vec<f64>, Vec<f64>)> = None;
        for _ in 0..cfg.dual_iterations {
            let ctrl = self.backward(prev, dynamics, cost, &mut etas, &mut lo)?;
            let mom = forward_moments(&ctrl, dynamics)?;
            let n = prev.state_dim();
            let kl: Vec<f64> = (0..t_len)
                .map(|t| {
                    let mx = mom.mu[t].rows(0, n).into_owned();
                    let sx = mom.sigma[t].view((0, 0), (n, n)).into_owned();
                    policy_kl(&ctrl, prev, t, &mx, &sx)
                })
                .collect();
            let mut done = true;
            for t in 0..t_len {
                let eps = kl_steps[t];
                let con = kl[t] - eps;
                let at_floor = etas[t] <= cfg.min_eta * 1.000001;
                if con.abs() <= cfg.tolerance * eps || (con < 0.0 && at_floor) {
                    continue;
                }
                done = false;
                if con > 0.0 {
                    // Step too large: η too small.
                    lo[t] = etas[t];
                    etas[t] = if hi[t] < cfg.max_eta {
                        (lo[t] * hi[t]).sqrt()
                    } else {
                        etas[t] * 10.0
                    };
                } else {
                    hi[t] = etas[t];
                    etas[t] = if lo[t] > cfg.min_eta {
                        (lo[t] * hi[t]).sqrt()
                    } else {
                        etas[t] / 10.0
                    };
                }
                etas[t] = etas[t].clamp(cfg.min_eta, cfg.max_eta);
            }
            best = Some((ctrl, etas.clone(), kl));
            if done {
                break;
            }
        }
        let (controller, etas, kl) = best.expect("at least one dual iteration");
        let predicted_cost = expected_cost(&forward_moments(&controller, dynamics)?, cost);
        Ok(LqrFlmStep {
            controller,
            etas,
            kl,
            predicted_cost,
        })
    }

    /// The backward pass for given dual variables: LQR on `c/η_t − log p̄(u|x)` under the fitted
    /// dynamics. Raises `η_t` (and its lower bracket) wherever `Q_uu` is not positive definite.
    pub fn backward(
        &self,
        prev: &TvlgController,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
        etas: &mut [f64],
        lower: &mut [f64],
    ) -> Result<TvlgController> {
        let t_len = prev.horizon();
        let (n, m) = (prev.state_dim(), prev.action_dim());
        'retry: loop {
            let mut gains = vec![DMatrix::zeros(m, n); t_len];
            let mut offsets = vec![DVector::zeros(m); t_len];
            let mut covs = vec![DMatrix::zeros(m, m); t_len];
            // Terminal cost enters V scaled like the last step.
            let eta_last = etas[t_len - 1];
            let mut vxx = &cost[t_len].hess / eta_last;
            let mut vx = &cost[t_len].grad / eta_last;
            for t in (0..t_len).rev() {
                let eta = etas[t];
                // Previous policy's −log p̄ in z = [x; u].
                let pinv = prev.inv_cov(t);
                let kb = &prev.gains[t];
                let kkb = &prev.offsets[t];
                let mut fcm = &cost[t].hess / eta;
                let mut fcv = &cost[t].grad / eta;
                let ktp = kb.transpose() * pinv;
                let mut v = fcm.view_mut((0, 0), (n, n));
                v += &ktp * kb;
                let mut v = fcm.view_mut((0, n), (n, m));
                v -= &ktp;
                let mut v = fcm.view_mut((n, 0), (m, n));
                v -= pinv * kb;
                let mut v = fcm.view_mut((n, n), (m, m));
                v += pinv;
                let mut v = fcv.rows_mut(0, n);
                v += &ktp * kkb;
                let mut v = fcv.rows_mut(n, m);
                v -= pinv * kkb;
                // Q-function.
                let mut f = DMatrix::zeros(n, n + m);
                f.view_mut((0, 0), (n, n)).copy_from(&dynamics.fx[t]);
                f.view_mut((0, n), (n, m)).copy_from(&dynamics.fu[t]);
                let qtt = &fcm + f.transpose() * &vxx * &f;
                let qt = &fcv + f.transpose() * (&vx + &vxx * &dynamics.fc[t]);
                let quu = qtt.view((n, n), (m, m)).into_owned();
                let quu = (&quu + quu.transpose()) * 0.5;
                let Some(chol) = quu.cholesky() else {
                    if etas[t] >= self.cfg.max_eta {
                        return Err(PlanError::Numerical(format!(
                            "LQR-FLM: Q_uu not positive definite at step {t} even at eta = {:e}",
                            self.cfg.max_eta
                        )));
                    }
                    lower[t] = etas[t];
                    etas[t] = (etas[t] * 10.0).min(self.cfg.max_eta);
                    continue 'retry;
                };
                let qux = qtt.view((n, 0), (m, n)).into_owned();
                let qu = qt.rows(n, m).into_owned();
                let k = -chol.solve(&qu);
                let kk = -chol.solve(&qux);
                let qxu = qtt.view((0, n), (n, m));
                vxx = qtt.view((0, 0), (n, n)) + qxu * &kk;
                vxx = (&vxx + vxx.transpose()) * 0.5;
                vx = qt.rows(0, n) + qxu * &k;
                covs[t] = chol.inverse();
                gains[t] = kk;
                offsets[t] = k;
                // Values are in units of the cost divided by η_t; the next step (t−1) divides by
                // η_{t−1}: rescale so that each step's Q is consistently scaled by its own η.
                if t > 0 {
                    let r = etas[t] / etas[t - 1];
                    vxx *= r;
                    vx *= r;
                }
            }
            return TvlgController::new(gains, offsets, covs);
        }
    }
}

/// GPS's step-size rule for LQR-FLM on its own ("classic", Levine & Abbeel 2014 §3.1; GPS
/// `AlgorithmTrajOpt._stepadjust` and `_set_new_mult`), for a baseline whose KL bound adapts as
/// PILQR's does. With `L(p, f, c)` the expected quadratic cost of controller `p` under fitted
/// dynamics `f` and cost expansion `c`, the improvement the last model predicted,
/// `L(p̄, f̄, c̄) − L(p, f̄, c̄)`, and the one the new model sees, `L(p̄, f̄, c̄) − L(p, f, c)`, scale
/// the multiplier of `ε` by `predicted / (2 max(predicted − actual, 1e-4))`, clamped to
/// `[0.1, 5]`; the multiplier stays in `[0.01, 10]`. `p̄, f̄, c̄` are the previous iteration's
/// controller, fit and cost; `p, f, c` the current controller (the one just sampled) and the fit
/// and cost from its samples. Returns the new multiplier.
#[allow(clippy::too_many_arguments)]
pub fn classic_step_mult(
    mult: f64,
    prev_controller: &TvlgController,
    prev_dynamics: &TvlgDynamics,
    prev_cost: &[QuadraticCost],
    controller: &TvlgController,
    dynamics: &TvlgDynamics,
    cost: &[QuadraticCost],
) -> Result<f64> {
    positive("step multiplier", mult)?;
    let before = laplace_cost(prev_controller, prev_dynamics, prev_cost)?;
    let predicted = before - laplace_cost(controller, prev_dynamics, prev_cost)?;
    let actual = before - laplace_cost(controller, dynamics, cost)?;
    adjust_step_mult(mult, predicted, actual, (0.01, 10.0))
}

/// The expected cost `L(p, f, c)` of controller `p` under fitted dynamics `f` and the quadratic
/// cost `c` (`T` running terms then the terminal one): the "Laplace" estimate GPS's step rules
/// compare.
pub fn laplace_cost(p: &TvlgController, f: &TvlgDynamics, c: &[QuadraticCost]) -> Result<f64> {
    check_len(
        "cost terms (T running + terminal)",
        p.horizon() + 1,
        c.len(),
    )?;
    let l = expected_cost(&forward_moments(p, f)?, c);
    if l.is_finite() {
        Ok(l)
    } else {
        Err(PlanError::NonFinite(
            "expected cost of a TVLG controller".into(),
        ))
    }
}

/// GPS's step rule (`_set_new_mult`): modelling the improvement as quadratic in the KL step, the
/// step that maximizes it scales the multiplier by `predicted / (2 max(predicted − actual,
/// 10⁻⁴))`, clamped to `[0.1, 5]`; the new multiplier is clamped to `bounds` (min, max).
/// [`classic_step_mult`] uses it with `(0.01, 10)`; MDGPS with its own improvements and bounds.
pub fn adjust_step_mult(
    mult: f64,
    predicted: f64,
    actual: f64,
    (min, max): (f64, f64),
) -> Result<f64> {
    positive("step multiplier", mult)?;
    positive("smallest step multiplier", min)?;
    if max.is_nan() || max < min {
        return Err(PlanError::Config(format!(
            "step multiplier bounds [{min}, {max}] are empty"
        )));
    }
    if !(predicted.is_finite() && actual.is_finite()) {
        return Err(PlanError::NonFinite("step adjustment improvements".into()));
    }
    let factor = (predicted / (2.0 * (predicted - actual).max(1e-4))).clamp(0.1, 5.0);
    Ok((mult * factor).clamp(min, max))
}
