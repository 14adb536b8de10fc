//! [`TvlgPolicyFit`]: a global policy's time-varying linear-Gaussian linearization, fitted by
//! regression over sampled states with a GMM prior (GPS's `PolicyPriorGMM`, which MDGPS bounds
//! its local updates against).
//!
//! At every step `t` the joint Gaussian of `[x_t; μ(x_t)]` over the `N` sampled states is the MAP
//! of the same normal-inverse-Wishart posterior as the dynamics fit ([`crate::TvlgFit`]), with the
//! prior from a GMM over `[x, μ(x)]` at the states of the last `max_samples` trajectories (the
//! policy evaluated anew at every prior update); then `u` is conditioned on `x`:
//! `K_t = Σ_ux Σ_xx⁻¹`, `k_t = μ_u − K_t μ_x`, and the covariance is the residual
//! `Σ_uu − K_t Σ_xx K_tᵀ` plus the policy's own action covariance.
//!
//! Unlike the policy's Jacobian at one point, the regression gain is what the policy does over
//! the region its samples cover: by Cauchy–Schwarz `|K| ≤ std(u) / std(x)` for one state and one
//! action (prior-free), however steep the policy is somewhere in between, and where the policy is
//! not linear the residual widens the covariance instead of being extrapolated. With nearly
//! identical samples the prior, fitted over earlier trajectories, supplies the spread.

use nalgebra::{DMatrix, DVector};
use ndarray::ArrayView3;
use tandem_core::seeding::rng_from_seed;

use crate::gmm::Gmm;
use crate::model::ModelError;
use crate::tvlg::{fit_conditional, Conditional, GmmPriorConfig};

/// Settings of a [`TvlgPolicyFit`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyFitConfig {
    /// Added to the diagonal of the state block of the joint covariance before conditioning
    /// (1e-6, as the dynamics fit; GPS adds 1e-8 at the first step only): keeps the solve well
    /// posed with fewer samples than state dimensions and no prior.
    pub regularization: f64,
    /// The GMM prior (GPS's `POLICY_PRIOR_GMM`: the defaults of [`GmmPriorConfig`]); `None`
    /// fits each step by regularized least squares alone.
    pub prior: Option<GmmPriorConfig>,
}

impl Default for PolicyFitConfig {
    fn default() -> Self {
        Self {
            regularization: 1e-6,
            prior: Some(GmmPriorConfig::default()),
        }
    }
}

impl PolicyFitConfig {
    /// Checks a finite, non-negative `regularization` and the prior's ranges.
    pub fn validate(&self) -> Result<(), ModelError> {
        if !(self.regularization.is_finite() && self.regularization >= 0.0) {
            return Err(ModelError::Other(format!(
                "policy fit regularization {} must be finite and >= 0",
                self.regularization
            )));
        }
        self.prior.as_ref().map_or(Ok(()), GmmPriorConfig::validate)
    }
}

/// A time-varying linear-Gaussian policy `u_t ~ N(gains_t x_t + offsets_t, cov_t)`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TvlgPolicy {
    /// Gains `dU x dX`.
    pub gains: Vec<DMatrix<f64>>,
    /// Offsets, length `dU`.
    pub offsets: Vec<DVector<f64>>,
    /// Action covariances `dU x dU`.
    pub cov: Vec<DMatrix<f64>>,
}

impl TvlgPolicy {
    /// Number of fitted steps.
    pub fn horizon(&self) -> usize {
        self.gains.len()
    }

    /// Mean action at step `t`.
    pub fn mean(&self, t: usize, x: &DVector<f64>) -> DVector<f64> {
        &self.gains[t] * x + &self.offsets[t]
    }
}

/// Linearizes a policy by regression over its sampled states, keeping the states of the last
/// `max_samples` trajectories for a GMM prior.
///
/// ```
/// use nalgebra::DMatrix;
/// use ndarray::Array3;
/// use tandem_models::{PolicyFitConfig, TvlgPolicyFit};
///
/// // u = 2 x − 1 at 10 spread states per step, 4 steps; the policy's own variance 0.1.
/// let (n, t) = (10, 4);
/// let xs = Array3::from_shape_fn((n, t, 1), |(i, k, _)| i as f64 * 0.1 + k as f64);
/// let us = xs.mapv(|x| 2.0 * x - 1.0);
/// let mut fit = TvlgPolicyFit::new(PolicyFitConfig::default());
/// fit.update_prior(xs.view(), |x: &DMatrix<f64>| {
///     Ok::<_, tandem_models::ModelError>(x.map(|v| 2.0 * v - 1.0))
/// })
/// .unwrap();
/// let lin = fit.fit(xs.view(), us.view(), &DMatrix::from_element(1, 1, 0.1)).unwrap();
/// assert!((lin.gains[2][(0, 0)] - 2.0).abs() < 1e-3);
/// assert!((lin.offsets[2][0] + 1.0).abs() < 1e-2);
/// assert!((lin.cov[2][(0, 0)] - 0.1).abs() < 1e-3);
/// ```
///
/// Serializable with its prior's data, so a resumed run continues exactly.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TvlgPolicyFit {
    cfg: PolicyFitConfig,
    /// States of the kept trajectories, `steps x dX` each, oldest first.
    kept: Vec<DMatrix<f64>>,
    gmm: Option<Gmm>,
    prior_updates: u64,
}

/// Checks a batch of states (`N x T x dX`, finite, `N, T >= 1`); returns `(N, T, dX)`.
fn check_states(states: &ArrayView3<'_, f64>) -> Result<(usize, usize, usize), ModelError> {
    let (n, t, dx) = states.dim();
    if n == 0 || t == 0 || dx == 0 {
        return Err(ModelError::Empty);
    }
    for (i, traj) in states.outer_iter().enumerate() {
        if traj.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "policy fit states (row = trajectory)".into(),
                row: i,
            });
        }
    }
    Ok((n, t, dx))
}

impl TvlgPolicyFit {
    /// A fitter with no prior data yet.
    pub fn new(cfg: PolicyFitConfig) -> Self {
        Self {
            cfg,
            kept: Vec::new(),
            gmm: None,
            prior_updates: 0,
        }
    }

    /// Its settings.
    pub fn config(&self) -> &PolicyFitConfig {
        &self.cfg
    }

    /// The current GMM prior, once [`TvlgPolicyFit::update_prior`] has run.
    pub fn gmm(&self) -> Option<&Gmm> {
        self.gmm.as_ref()
    }

    /// Trajectories whose states the prior keeps.
    pub fn kept_trajectories(&self) -> usize {
        self.kept.len()
    }

    /// The kept trajectories with `states` (`N x T x dX`) added, the oldest beyond `max_samples`
    /// dropped.
    fn with_states(
        &self,
        states: &ArrayView3<'_, f64>,
        max_samples: usize,
    ) -> Result<Vec<DMatrix<f64>>, ModelError> {
        let (n, t, dx) = check_states(states)?;
        if let Some(first) = self.kept.first() {
            if first.ncols() != dx {
                return Err(ModelError::Dim {
                    what: "policy fit states (dX) against earlier prior data".into(),
                    expected: first.ncols(),
                    got: dx,
                });
            }
        }
        let mut kept = self.kept.clone();
        for i in 0..n {
            kept.push(DMatrix::from_fn(t, dx, |k, j| states[[i, k, j]]));
        }
        let keep = max_samples.max(1);
        if kept.len() > keep {
            kept.drain(..kept.len() - keep);
        }
        Ok(kept)
    }

    /// Keeps the states of these trajectories (`N x T x dX`) for the prior without refitting
    /// it (GPS adds every iteration's samples, also those the policy is not linearized around).
    /// Does nothing without a prior configured. On error nothing changes.
    pub fn add_states(&mut self, states: ArrayView3<'_, f64>) -> Result<(), ModelError> {
        let Some(max_samples) = self.cfg.prior.as_ref().map(|p| p.max_samples) else {
            return Ok(());
        };
        self.kept = self.with_states(&states, max_samples)?;
        Ok(())
    }

    /// Keeps the states of these trajectories (as [`TvlgPolicyFit::add_states`]) and refits the
    /// GMM over `[x, μ(x)]` at all kept states, `policy` giving the current policy's mean actions
    /// of a batch of states (rows in, rows out): the policy is evaluated anew each time, since it
    /// changes between updates. Does nothing without a prior configured. On error nothing
    /// changes.
    pub fn update_prior<E: From<ModelError>>(
        &mut self,
        states: ArrayView3<'_, f64>,
        policy: impl FnOnce(&DMatrix<f64>) -> Result<DMatrix<f64>, E>,
    ) -> Result<(), E> {
        let Some(pcfg) = self.cfg.prior.clone() else {
            return Ok(());
        };
        let kept = self.with_states(&states, pcfg.max_samples)?;
        let dx = states.dim().2;
        let rows: usize = kept.iter().map(|d| d.nrows()).sum();
        let mut xs = DMatrix::zeros(rows, dx);
        let mut r = 0;
        for d in &kept {
            xs.rows_mut(r, d.nrows()).copy_from(d);
            r += d.nrows();
        }
        let us = policy(&xs)?;
        if us.nrows() != rows || us.ncols() == 0 {
            return Err(ModelError::Dim {
                what: "policy actions at the prior's states (rows)".into(),
                expected: rows,
                got: us.nrows(),
            }
            .into());
        }
        if let Some(i) = us.row_iter().position(|r| r.iter().any(|v| !v.is_finite())) {
            return Err(ModelError::NonFinite {
                what: "policy actions at the prior's states".into(),
                row: i,
            }
            .into());
        }
        let du = us.ncols();
        let mut all = DMatrix::zeros(rows, dx + du);
        all.columns_mut(0, dx).copy_from(&xs);
        all.columns_mut(dx, du).copy_from(&us);
        let k = (rows / pcfg.min_samples_per_cluster.max(1)).clamp(2, pcfg.max_clusters.max(2));
        let mut rng = rng_from_seed(pcfg.seed.wrapping_add(self.prior_updates));
        let gmm = Gmm::fit(&all, k, pcfg.max_iterations, &mut rng)?;
        self.kept = kept;
        self.gmm = Some(gmm);
        self.prior_updates += 1;
        Ok(())
    }

    /// Fits the linearization at every step from the sampled `states` (`N x T x dX`) and the
    /// policy's mean `actions` there (`N x T x dU`), with the prior as it is (without a fitted
    /// GMM, or without a prior configured, the prior-free fit), and adds `policy_cov` (`dU x dU`,
    /// the policy's own action covariance) to every step's residual covariance.
    pub fn fit(
        &self,
        states: ArrayView3<'_, f64>,
        actions: ArrayView3<'_, f64>,
        policy_cov: &DMatrix<f64>,
    ) -> Result<TvlgPolicy, ModelError> {
        let (n, steps, dx) = check_states(&states)?;
        let (na, ta, du) = actions.dim();
        for (what, expected, got) in [
            ("policy actions (trajectories)", n, na),
            ("policy actions (time steps)", steps, ta),
            ("policy covariance (rows)", du, policy_cov.nrows()),
            ("policy covariance (columns)", du, policy_cov.ncols()),
        ] {
            if expected != got {
                return Err(ModelError::Dim {
                    what: what.into(),
                    expected,
                    got,
                });
            }
        }
        if du == 0 {
            return Err(ModelError::Empty);
        }
        if let Some(i) = actions
            .outer_iter()
            .position(|a| a.iter().any(|v| !v.is_finite()))
        {
            return Err(ModelError::NonFinite {
                what: "policy actions (row = trajectory)".into(),
                row: i,
            });
        }
        if let Some(g) = &self.gmm {
            if g.means[0].len() != dx + du {
                return Err(ModelError::Dim {
                    what: "policy fit width (dX + dU) against the prior".into(),
                    expected: g.means[0].len(),
                    got: dx + du,
                });
            }
        }
        let strength = self.cfg.prior.as_ref().map_or(0.0, |p| p.strength);
        let prior = self
            .gmm
            .as_ref()
            .filter(|_| strength > 0.0)
            .map(|g| (g, strength));
        let mut out = TvlgPolicy {
            gains: Vec::with_capacity(steps),
            offsets: Vec::with_capacity(steps),
            cov: Vec::with_capacity(steps),
        };
        for t in 0..steps {
            let ys = DMatrix::from_fn(n, dx + du, |i, j| {
                if j < dx {
                    states[[i, t, j]]
                } else {
                    actions[[i, t, j - dx]]
                }
            });
            let Conditional { gain, offset, cov } =
                fit_conditional(&ys, prior, self.cfg.regularization, dx)?.ok_or_else(|| {
                    ModelError::Other(format!(
                        "policy fit, step {t}: the state covariance is not positive definite \
                         (raise `regularization`)"
                    ))
                })?;
            let cov = cov + policy_cov;
            if gain
                .iter()
                .chain(offset.iter())
                .chain(cov.iter())
                .any(|v| !v.is_finite())
            {
                return Err(ModelError::NonFinite {
                    what: "fitted policy linearization (row = time step)".into(),
                    row: t,
                });
            }
            out.gains.push(gain);
            out.offsets.push(offset);
            out.cov.push(cov);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;
    use rand_distr::{Distribution, StandardNormal};

    /// `N x T x dX` states `centre + spread · z`, `z` standard normal, with the second half of
    /// the trajectories the mirror images of the first (`centre − spread · z`): the samples'
    /// mean at every step is `centre` (to rounding).
    fn mirrored_states(n: usize, t: usize, centre: &[f64], spread: f64, seed: u64) -> Array3<f64> {
        let mut rng = rng_from_seed(seed);
        let dx = centre.len();
        let mut xs = Array3::zeros((n, t, dx));
        for i in 0..n / 2 {
            for k in 0..t {
                for j in 0..dx {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    xs[[i, k, j]] = centre[j] + spread * z;
                    xs[[n / 2 + i, k, j]] = centre[j] - spread * z;
                }
            }
        }
        xs
    }

    /// `policy` applied to every state of `xs` (rows of `dX` in, rows of `dU` out).
    fn actions(xs: &Array3<f64>, du: usize, policy: &dyn Fn(&[f64]) -> Vec<f64>) -> Array3<f64> {
        let (n, t, _) = xs.dim();
        let mut us = Array3::zeros((n, t, du));
        for i in 0..n {
            for k in 0..t {
                let x: Vec<f64> = xs.slice(ndarray::s![i, k, ..]).to_vec();
                for (j, u) in policy(&x).into_iter().enumerate() {
                    us[[i, k, j]] = u;
                }
            }
        }
        us
    }

    fn rows_policy(
        policy: &dyn Fn(&[f64]) -> Vec<f64>,
        du: usize,
    ) -> impl FnOnce(&DMatrix<f64>) -> Result<DMatrix<f64>, ModelError> + '_ {
        move |x: &DMatrix<f64>| {
            let mut u = DMatrix::zeros(x.nrows(), du);
            for (r, row) in x.row_iter().enumerate() {
                let xr: Vec<f64> = row.iter().copied().collect();
                for (j, v) in policy(&xr).into_iter().enumerate() {
                    u[(r, j)] = v;
                }
            }
            Ok(u)
        }
    }

    /// A policy that is linear, `u = A x + b`, sampled at well-spread states, is recovered:
    /// gains `A`, offsets `b`, and the covariance the policy's own `diag(σ²)` (no residual),
    /// with and without the prior (every cluster of the prior lies on the same hyperplane).
    #[test]
    fn regression_recovers_a_linear_policy_and_its_variance() {
        let a = DMatrix::from_row_slice(2, 3, &[0.8, -1.5, 0.3, 2.0, 0.1, -0.7]);
        let b = DVector::from_column_slice(&[0.25, -1.0]);
        let policy = |x: &[f64]| {
            (&a * DVector::from_column_slice(x) + &b)
                .as_slice()
                .to_vec()
        };
        let xs = mirrored_states(30, 5, &[0.5, -0.2, 1.0], 1.0, 1);
        let us = actions(&xs, 2, &policy);
        let sigma2 = DMatrix::from_diagonal(&DVector::from_column_slice(&[0.3, 0.05]));
        for prior in [None, Some(GmmPriorConfig::default())] {
            let with_prior = prior.is_some();
            let mut fit = TvlgPolicyFit::new(PolicyFitConfig {
                prior,
                ..PolicyFitConfig::default()
            });
            fit.update_prior(xs.view(), rows_policy(&policy, 2))
                .unwrap();
            assert_eq!(fit.gmm().is_some(), with_prior);
            let lin = fit.fit(xs.view(), us.view(), &sigma2).unwrap();
            assert_eq!(lin.horizon(), 5);
            for t in 0..5 {
                let case = format!("prior {with_prior}, step {t}");
                assert!(
                    (&lin.gains[t] - &a).abs().max() < 1e-4,
                    "{case}: {}",
                    lin.gains[t]
                );
                assert!((&lin.offsets[t] - &b).abs().max() < 1e-4, "{case}");
                assert!(
                    (&lin.cov[t] - &sigma2).abs().max() < 1e-4,
                    "{case}: {}",
                    lin.cov[t]
                );
            }
        }
    }

    /// `u = c tanh(s (x − x₀))` with `s = 1000`: the samples' mean state is `x₀`, where the
    /// policy's Jacobian (the point linearization) is `c s = 500`, but the samples spread over
    /// ±1 where the policy is saturated nearly everywhere. The regression gain obeys
    /// Cauchy–Schwarz, `|K| ≤ std(u) / std(x)` over the samples (prior-free; loosely with the
    /// prior too), and is two orders smaller than the point Jacobian; the policy's departure from
    /// linear is the residual variance of an ordinary least-squares fit (computed here from the
    /// samples directly), and it is added to the policy's own `σ²`.
    #[test]
    fn regression_gain_is_bounded_where_the_point_jacobian_runs_away() {
        let (c, s, x0) = (0.5, 1000.0, 0.3);
        let policy = move |x: &[f64]| vec![c * (s * (x[0] - x0)).tanh()];
        let point_jacobian = c * s;
        let (n, steps) = (20, 4);
        let xs = mirrored_states(n, steps, &[x0], 0.5, 2);
        let us = actions(&xs, 1, &policy);
        let sigma2 = DMatrix::from_element(1, 1, 0.02);
        for (prior, reg) in [
            (None, 0.0),
            (None, 1e-6),
            (Some(GmmPriorConfig::default()), 1e-6),
        ] {
            let with_prior = prior.is_some();
            let mut fit = TvlgPolicyFit::new(PolicyFitConfig {
                regularization: reg,
                prior,
            });
            fit.update_prior(xs.view(), rows_policy(&policy, 1))
                .unwrap();
            let lin = fit.fit(xs.view(), us.view(), &sigma2).unwrap();
            for t in 0..steps {
                let x: Vec<f64> = (0..n).map(|i| xs[[i, t, 0]]).collect();
                let u: Vec<f64> = (0..n).map(|i| us[[i, t, 0]]).collect();
                let mean = |v: &[f64]| v.iter().sum::<f64>() / n as f64;
                let (mx, mu) = (mean(&x), mean(&u));
                assert!((mx - x0).abs() < 1e-12);
                let vx = x.iter().map(|v| (v - mx).powi(2)).sum::<f64>() / n as f64;
                let vu = u.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / n as f64;
                let cxu = x
                    .iter()
                    .zip(&u)
                    .map(|(a, b)| (a - mx) * (b - mu))
                    .sum::<f64>();
                let ols = cxu / n as f64 / vx;
                let resid = x
                    .iter()
                    .zip(&u)
                    .map(|(a, b)| (b - mu - ols * (a - mx)).powi(2))
                    .sum::<f64>()
                    / n as f64;
                let (k, cov) = (lin.gains[t][(0, 0)], lin.cov[t][(0, 0)]);
                let bound = (vu / vx).sqrt();
                let case = format!("prior {with_prior}, reg {reg}, step {t}: K {k}, bound {bound}");
                eprintln!("{case}, point Jacobian {point_jacobian}, S {cov}");
                assert!(k > 0.0 && k < point_jacobian / 100.0, "{case}");
                // The residual is material: the policy is far from linear over the samples.
                assert!(resid > 0.1 * vu, "{case}: residual {resid}, var(u) {vu}");
                assert!(cov >= sigma2[(0, 0)], "{case}: S {cov}");
                if with_prior {
                    assert!(k <= 2.0 * bound, "{case}");
                } else {
                    assert!(k <= bound * (1.0 + 1e-12), "{case}");
                    if reg == 0.0 {
                        assert!((k - ols).abs() < 1e-9 * ols, "{case}: OLS {ols}");
                        let got = cov - sigma2[(0, 0)];
                        assert!((got - resid).abs() < 1e-9, "{case}: residual {resid}");
                    }
                }
            }
        }
    }

    /// Three trajectories whose states lie within 10⁻⁶ of the point where the saturating policy
    /// of the test above is steepest: without a prior (and without regularization) the regression
    /// follows the policy's local slope (the point Jacobian, 500); with the prior over the
    /// earlier, spread trajectories the gain stays at the slope over the region those cover, and
    /// everything stays finite.
    #[test]
    fn nearly_identical_samples_are_bounded_by_the_prior() {
        let (c, s, x0) = (0.5, 1000.0, 0.3);
        let policy = move |x: &[f64]| vec![c * (s * (x[0] - x0)).tanh()];
        let (steps, sigma2) = (4, DMatrix::from_element(1, 1, 0.02));
        let earlier = mirrored_states(20, steps, &[x0], 0.5, 3);
        let mut close = mirrored_states(2, steps, &[x0], 1e-6, 4);
        // A third trajectory at the centre.
        close = ndarray::concatenate(
            ndarray::Axis(0),
            &[close.view(), Array3::from_elem((1, steps, 1), x0).view()],
        )
        .unwrap();
        let us = actions(&close, 1, &policy);
        let mut gains = Vec::new();
        for prior in [None, Some(GmmPriorConfig::default())] {
            let with_prior = prior.is_some();
            let mut fit = TvlgPolicyFit::new(PolicyFitConfig {
                regularization: 0.0,
                prior,
            });
            fit.add_states(earlier.view()).unwrap();
            assert_eq!(fit.kept_trajectories(), if with_prior { 20 } else { 0 });
            fit.update_prior(close.view(), rows_policy(&policy, 1))
                .unwrap();
            if with_prior {
                // GPS's max_samples: the last 20 trajectories.
                assert_eq!(fit.kept_trajectories(), 20);
            }
            let lin = fit.fit(close.view(), us.view(), &sigma2).unwrap();
            for t in 0..steps {
                let (k, k0, cov) = (lin.gains[t][(0, 0)], lin.offsets[t][0], lin.cov[t][(0, 0)]);
                eprintln!("prior {with_prior}, step {t}: K {k}, k {k0}, S {cov}");
                assert!(k.is_finite() && k0.is_finite() && cov.is_finite());
                assert!(cov >= sigma2[(0, 0)]);
                if with_prior {
                    // The slope over the earlier samples: |K| <= std(u) / std(x) there, about 1.
                    assert!(k.abs() < 3.0, "step {t}: K {k}");
                } else {
                    assert!((k - c * s).abs() < 1e-3 * c * s, "step {t}: K {k}");
                }
            }
            gains.push(lin.gains[0][(0, 0)]);
        }
        assert!(gains[0] > 100.0 * gains[1].abs(), "{gains:?}");
    }

    /// A fitter read back from JSON (kept states, mixture, update count) continues exactly;
    /// bad input is an error that changes nothing; a policy of another width is refused.
    #[test]
    fn a_fit_read_back_continues_exactly_and_bad_input_changes_nothing() {
        let policy = |x: &[f64]| vec![(2.0 * x[0]).sin() + x[1], x[0] * x[1]];
        let mut fit = TvlgPolicyFit::new(PolicyFitConfig::default());
        let xs = mirrored_states(6, 5, &[0.1, 0.2], 0.3, 5);
        fit.update_prior(xs.view(), rows_policy(&policy, 2))
            .unwrap();
        let mut back: TvlgPolicyFit =
            serde_json::from_str(&serde_json::to_string(&fit).unwrap()).unwrap();
        assert_eq!(back, fit);
        let xs = mirrored_states(6, 5, &[0.0, 0.3], 0.3, 6);
        let us = actions(&xs, 2, &policy);
        let cov = DMatrix::identity(2, 2) * 0.1;
        for f in [&mut fit, &mut back] {
            f.update_prior(xs.view(), rows_policy(&policy, 2)).unwrap();
        }
        assert_eq!(back, fit);
        let lin = fit.fit(xs.view(), us.view(), &cov).unwrap();
        assert_eq!(back.fit(xs.view(), us.view(), &cov).unwrap(), lin);

        let before = fit.clone();
        let mut bad = xs.clone();
        bad[[3, 1, 0]] = f64::NAN;
        assert!(matches!(
            fit.update_prior(bad.view(), rows_policy(&policy, 2)),
            Err(ModelError::NonFinite { row: 3, .. })
        ));
        let nan_policy = |_: &[f64]| vec![f64::NAN, 0.0];
        assert!(matches!(
            fit.update_prior(xs.view(), rows_policy(&nan_policy, 2)),
            Err(ModelError::NonFinite { .. })
        ));
        let wide = Array3::<f64>::zeros((2, 5, 3));
        assert!(matches!(
            fit.add_states(wide.view()),
            Err(ModelError::Dim { .. })
        ));
        assert_eq!(fit, before);
        let one_action = actions(&xs, 1, &|x| vec![x[0]]);
        assert!(matches!(
            fit.fit(xs.view(), one_action.view(), &DMatrix::identity(1, 1)),
            Err(ModelError::Dim { .. })
        ));
        assert!(matches!(
            fit.fit(xs.view(), us.view(), &DMatrix::identity(1, 1)),
            Err(ModelError::Dim { .. })
        ));
        let bad_cfg = PolicyFitConfig {
            regularization: -1.0,
            ..PolicyFitConfig::default()
        };
        assert!(bad_cfg
            .validate()
            .unwrap_err()
            .to_string()
            .contains("regularization"));
    }
}
