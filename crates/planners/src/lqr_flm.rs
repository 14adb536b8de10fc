//! LQR with fitted linear models (LQR-FLM, p4 §II-A; Levine & Abbeel 2014).
//!
//! Given the previous controller `p̄`, TVLG dynamics fitted to its samples and a quadratic cost,
//! solve `min E_p[Q]` subject to `E[KL(p ‖ p̄)] ≤ ε` **at every time step** (p4 eq. 1: one
//! constraint per step, not one on the whole trajectory). With a dual variable `η_t` per step the
//! Lagrangian is an LQR problem with the cost `c/η_t − log p̄(u|x)`; its maximum-entropy solution
//! is a TVLG controller with `Σ_t = Q_uu⁻¹` ([`LqrFlm::backward`]). Where `Q_uu` is not positive
//! definite the step's `η_t` is raised (×10) and the pass repeated: the known failure of earlier
//! implementations becomes a smaller step instead of an error.
//!
//! The dual search follows GPS's `traj_opt_lqr_python`: bracket each `η_t` in log space on the
//! sign of `KL_t − ε_t` (the KL under the new controller's state distribution, p4 footnote 1),
//! then, if that has not converged, Adam steps on all `η_t` at once. The steps are coupled (the
//! state distribution at `t` depends on every earlier step), so each step's bracket goes stale;
//! returning the last pass, as we did, left steps at 3–50 ε. The search now returns the pass with
//! the lowest predicted cost among those that meet every bound within the tolerance
//! (`KL_t ≤ (1 + tolerance) ε_t`): that is the constrained problem's own objective. If no pass
//! does, it scales the least violating pass's `η_t` up by powers of 10 until every bound holds
//! (the safe, conservative step: at `η = max_eta` the controller is `p̄` itself) and says so in
//! [`LqrFlmStep::fallback`]; GPS instead returns its last pass with a warning.

use nalgebra::{DMatrix, DVector};
use tandem_models::TvlgDynamics;

use crate::error::{check_len, PlanError, Result};
use crate::mpc::positive;
use crate::tvlg::{
    expected_cost, forward_moments, lqr_step, policy_kl, QuadraticCost, TvlgController,
};

/// Settings of [`LqrFlm`]. Defaults follow GPS's `traj_opt_lqr_python` with per-step constraints
/// (η bounds `[1e-8, 1e16]`, 20 bracketing passes then up to 200 Adam steps, constraint met within
/// 10% of ε); the learning rate is ours (GPS's 0.005 is on η itself, ours on `log η`), and so is
/// `kl_step = 1.0` per step.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LqrFlmConfig {
    /// KL bound `ε` per time step.
    pub kl_step: f64,
    /// Smallest dual variable.
    pub min_eta: f64,
    /// Largest dual variable.
    pub max_eta: f64,
    /// Passes (backward + forward) of the first phase, which brackets each `η_t` in log space
    /// (at least 1). Settings recorded before the search had two phases name it
    /// `dual_iterations` (then its only phase, returning the last pass), so that their
    /// directories still read and merge.
    #[serde(alias = "dual_iterations")]
    pub bracket_iterations: usize,
    /// Adam steps on `log η` of the second phase, run when bracketing has not converged (0: none).
    pub adam_iterations: usize,
    /// Adam's learning rate on `log η_t` (the largest change of `log η_t` per step, about).
    pub adam_learning_rate: f64,
    /// Relative tolerance: a pass meets step `t`'s bound when `KL_t ≤ (1 + tolerance) ε_t`, and
    /// the search stops once every `|KL_t − ε_t| ≤ tolerance · ε_t`.
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
            bracket_iterations: 20,
            adam_iterations: 200,
            adam_learning_rate: 0.05,
            tolerance: 0.1,
            eta_init: 1.0,
        }
    }
}

impl LqrFlmConfig {
    /// Checks positive, finite `kl_step`, `min_eta < max_eta`, `eta_init`, `tolerance` and
    /// `adam_learning_rate`, and at least one bracketing pass.
    pub fn validate(&self) -> Result<()> {
        positive("kl_step", self.kl_step)?;
        positive("min_eta", self.min_eta)?;
        positive("max_eta", self.max_eta)?;
        positive("eta_init", self.eta_init)?;
        positive("tolerance", self.tolerance)?;
        positive("adam_learning_rate", self.adam_learning_rate)?;
        crate::mpc::nonzero("bracket_iterations", self.bracket_iterations)?;
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
    /// `max_t KL_t / ε_t`: at most `1 + tolerance`.
    pub max_kl_ratio: f64,
    /// No pass of the search met every bound, and `controller` is the conservative fallback (the
    /// least violating pass's `η_t` scaled up by powers of 10 until every bound holds, the scale
    /// then refined by bisection).
    pub fallback: bool,
    /// Passes (backward pass, forward moments and KL) the search evaluated.
    pub passes: usize,
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
    ///
    /// Returns the feasible pass (every `KL_t ≤ (1 + tolerance) ε_t`) with the lowest predicted
    /// cost over both phases of the dual search; when no pass was feasible, the conservative
    /// fallback of the module docs (`fallback` set). An error when even `η_t = max_eta` at every
    /// step breaks a bound (numerically degenerate: that controller is `p̄` itself).
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
        let mut search = DualSearch::new(kl_steps, cfg.tolerance);
        let mut etas = vec![cfg.eta_init; t_len];
        let mut lo = vec![cfg.min_eta; t_len];
        let mut hi = vec![cfg.max_eta; t_len];
        let at_floor = |eta: f64| eta <= cfg.min_eta * 1.000001;
        let mut converged = false;
        // Phase 1: bracket each η_t in log space on the sign of KL_t − ε_t.
        for _ in 0..cfg.bracket_iterations {
            let pass = self.pass(prev, dynamics, cost, &mut etas, &mut lo)?;
            converged = search.converged(&pass, at_floor);
            for t in 0..t_len {
                let con = pass.kl[t] - kl_steps[t];
                if con.abs() <= cfg.tolerance * kl_steps[t] {
                    continue;
                }
                if con < 0.0 && at_floor(etas[t]) {
                    continue;
                }
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
            search.offer(pass);
            if converged {
                break;
            }
        }
        // Phase 2: the brackets go stale (a step's KL moves with the earlier steps' η), so ascend
        // the dual in all η_t at once with Adam, as GPS does. GPS steps η itself on the dual's
        // gradient KL_t − ε_t; we step log η_t (η spans [min_eta, max_eta] and its scale is the
        // cost's) on ln(KL_t / ε_t), clamped to ±5: the same sign, but violations span orders of
        // magnitude, and with the raw difference Adam's second moment, remembering an early
        // 50 ε, shrinks the steps near the bound to a crawl.
        if !converged && cfg.adam_iterations > 0 {
            let (b1, b2, tiny) = (0.9, 0.999, 1e-8);
            let (lmin, lmax) = (cfg.min_eta.ln(), cfg.max_eta.ln());
            let mut mom1 = vec![0.0; t_len];
            let mut mom2 = vec![0.0; t_len];
            let mut ignored = vec![cfg.min_eta; t_len];
            for i in 0..cfg.adam_iterations {
                let pass = self.pass(prev, dynamics, cost, &mut etas, &mut ignored)?;
                let done = search.converged(&pass, at_floor);
                let k = (i + 1) as i32;
                for t in 0..t_len {
                    let g = (pass.kl[t] / kl_steps[t]).ln().clamp(-5.0, 5.0);
                    mom1[t] = b1 * mom1[t] + (1.0 - b1) * g;
                    mom2[t] = b2 * mom2[t] + (1.0 - b2) * g * g;
                    let step = (mom1[t] / (1.0 - b1.powi(k)))
                        / ((mom2[t] / (1.0 - b2.powi(k))).sqrt() + tiny);
                    etas[t] = (etas[t].ln() + cfg.adam_learning_rate * step)
                        .clamp(lmin, lmax)
                        .exp();
                }
                search.offer(pass);
                if done {
                    break;
                }
            }
        }
        if let Some(best) = search.best.take() {
            return Ok(best.into_step(kl_steps, false, search.passes));
        }
        // Phase 3, no pass met every bound: scale all of the least violating pass's η_t by 10^s,
        // s = 1, 2, …, until one does, then bisect s between the last two. Every step moves
        // toward p̄ and so does the state distribution; at η_t = max_eta everywhere the
        // controller is p̄ itself (KL 0). Only passes that meet every bound are kept.
        let base = search
            .least_violating
            .take()
            .expect("at least one pass")
            .etas;
        let scaled = |s: f64| -> Vec<f64> {
            base.iter()
                .map(|e| (e * 10f64.powf(s)).min(cfg.max_eta))
                .collect()
        };
        let mut s = 0.0;
        loop {
            s += 1.0;
            let mut etas = scaled(s);
            let saturated = etas.iter().all(|&e| e >= cfg.max_eta);
            let pass = self.pass(prev, dynamics, cost, &mut etas, &mut lo)?;
            let ratio = pass.max_ratio(kl_steps);
            search.offer(pass);
            if search.best.is_some() {
                break;
            }
            if saturated {
                return Err(PlanError::Numerical(format!(
                    "LQR-FLM: no controller meets the KL bounds, not even at eta = {:e} \
                     (largest KL_t / eps_t {ratio:.3})",
                    cfg.max_eta
                )));
            }
        }
        let (mut bad, mut good) = (s - 1.0, s);
        for _ in 0..FALLBACK_BISECTIONS {
            let mid = 0.5 * (bad + good);
            let pass = self.pass(prev, dynamics, cost, &mut scaled(mid), &mut lo)?;
            if search.feasible(&pass) {
                good = mid;
            } else {
                bad = mid;
            }
            search.offer(pass);
        }
        let best = search.best.take().expect("a feasible pass");
        Ok(best.into_step(kl_steps, true, search.passes))
    }

    /// One backward pass for `etas` (raised where `Q_uu` is not positive definite) and the KL
    /// and predicted cost of its controller.
    fn pass(
        &self,
        prev: &TvlgController,
        dynamics: &TvlgDynamics,
        cost: &[QuadraticCost],
        etas: &mut [f64],
        lower: &mut [f64],
    ) -> Result<Pass> {
        let controller = self.backward(prev, dynamics, cost, etas, lower)?;
        let mom = forward_moments(&controller, dynamics)?;
        let n = prev.state_dim();
        let kl = (0..prev.horizon())
            .map(|t| {
                let mx = mom.mu[t].rows(0, n).into_owned();
                let sx = mom.sigma[t].view((0, 0), (n, n)).into_owned();
                policy_kl(&controller, prev, t, &mx, &sx)
            })
            .collect();
        let predicted_cost = expected_cost(&mom, cost);
        Ok(Pass {
            controller,
            etas: etas.to_vec(),
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
                let step = lqr_step(&chol, &qtt, &qt, n);
                (vxx, vx) = (step.vxx, step.vx);
                (gains[t], offsets[t], covs[t]) = (step.gain, step.offset, step.cov);
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

/// Bisections of the fallback's scale between the last power of 10 that broke a bound and the
/// first that met them all (to a factor `10^(1/16)` ≈ 1.15 in `η`).
const FALLBACK_BISECTIONS: usize = 4;

/// One pass of the dual search: the controller for `etas`, its KL per step and predicted cost.
struct Pass {
    controller: TvlgController,
    etas: Vec<f64>,
    kl: Vec<f64>,
    predicted_cost: f64,
}

impl Pass {
    /// `max_t KL_t / ε_t` (NaN if a KL is).
    fn max_ratio(&self, eps: &[f64]) -> f64 {
        self.kl
            .iter()
            .zip(eps)
            .map(|(k, e)| k / e)
            .fold(f64::NEG_INFINITY, |a, r| {
                if a.is_nan() || r.is_nan() {
                    f64::NAN
                } else {
                    a.max(r)
                }
            })
    }

    fn into_step(self, eps: &[f64], fallback: bool, passes: usize) -> LqrFlmStep {
        LqrFlmStep {
            passes,
            max_kl_ratio: self.max_ratio(eps),
            controller: self.controller,
            etas: self.etas,
            kl: self.kl,
            predicted_cost: self.predicted_cost,
            fallback,
        }
    }
}

/// The passes seen so far: the feasible one with the lowest predicted cost, and the one whose
/// largest `KL_t / ε_t` is smallest (the fallback's start while none is feasible).
struct DualSearch<'a> {
    eps: &'a [f64],
    tolerance: f64,
    best: Option<Pass>,
    least_violating: Option<Pass>,
    passes: usize,
}

impl<'a> DualSearch<'a> {
    fn new(eps: &'a [f64], tolerance: f64) -> Self {
        Self {
            eps,
            tolerance,
            best: None,
            least_violating: None,
            passes: 0,
        }
    }

    /// Every `KL_t ≤ (1 + tolerance) ε_t`, and a finite predicted cost.
    fn feasible(&self, p: &Pass) -> bool {
        p.predicted_cost.is_finite()
            && p.kl
                .iter()
                .zip(self.eps)
                .all(|(&k, &e)| k <= (1.0 + self.tolerance) * e)
    }

    /// Every `|KL_t − ε_t| ≤ tolerance · ε_t`, or `KL_t < ε_t` with `η_t` at its floor: nothing
    /// left to search for.
    fn converged(&self, p: &Pass, at_floor: impl Fn(f64) -> bool) -> bool {
        self.feasible(p)
            && (0..p.kl.len()).all(|t| {
                let con = p.kl[t] - self.eps[t];
                con.abs() <= self.tolerance * self.eps[t] || (con < 0.0 && at_floor(p.etas[t]))
            })
    }

    /// Keeps `p` if it is the cheapest feasible pass, or (while none is feasible) the least
    /// violating one.
    fn offer(&mut self, p: Pass) {
        self.passes += 1;
        if self.feasible(&p) {
            if self
                .best
                .as_ref()
                .is_none_or(|b| p.predicted_cost < b.predicted_cost)
            {
                self.best = Some(p);
            }
        } else if self.best.is_none() {
            let r = p.max_ratio(self.eps);
            let better = self.least_violating.as_ref().is_none_or(|b| {
                let rb = b.max_ratio(self.eps);
                r < rb || rb.is_nan()
            });
            if better {
                self.least_violating = Some(p);
            }
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
