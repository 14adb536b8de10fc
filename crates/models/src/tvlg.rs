//! [`TvlgFit`]: time-varying linear-Gaussian dynamics fitted from trajectories, with a
//! normal-inverse-Wishart prior from a Gaussian mixture over all transitions (the dynamics fit of
//! guided policy search that p4's LQR-FLM step uses).
//!
//! At every step `t` the joint Gaussian of `[x_t; u_t; x_{t+1}]` over the `N` samples is
//! estimated as the MAP of a normal-inverse-Wishart posterior (GPS `gauss_fit_joint_prior`):
//!
//! ```text
//! Σ = (N Σ_emp + Φ + N m / (N + m) (μ_emp − μ0)(μ_emp − μ0)ᵀ) / (N + n0) + reg·I_{xu}
//! ```
//!
//! and conditioned on `[x_t; u_t]`: `F_t = Σ_{y,xu} Σ_{xu,xu}⁻¹`, `f_t = μ_y − F_t μ_xu`,
//! `Σ_t = Σ_{yy} − F_t Σ_{xu,xu} F_tᵀ`. The prior `(μ0, Φ, m, n0)` comes from a GMM fitted over
//! the transitions of all steps and samples (Levine, Finn, Darrell, Abbeel 2016, appendix A.3):
//! the samples at step `t` select the clusters that explain them, so a step with fewer samples
//! than dimensions borrows the local linear structure of neighbouring steps and earlier samples.
//! Without a prior (`TvlgConfig::prior = None`) `Φ = 0`, `n0 = m = 0`: plain least squares
//! with the same `reg` regularization.
//!
//! All matrices are at most `(2 dX + dU)` square, so nalgebra does the linear algebra (faer's
//! advantage starts at sizes these fits never reach).

use nalgebra::{DMatrix, DVector};
use ndarray::{ArrayView3, Axis};
use tandem_core::seeding::rng_from_seed;

use crate::gmm::{robust_cholesky, Gmm};
use crate::model::ModelError;

/// Settings of a GMM prior: the dynamics' ([`TvlgConfig`]) and the policy linearization's
/// ([`crate::PolicyFitConfig`]). Defaults are the GPS code's `DYN_PRIOR_GMM` (its
/// `POLICY_PRIOR_GMM` has the same values).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GmmPriorConfig {
    /// Clusters are `clamp(points / min_samples_per_cluster, 2, max_clusters)` (GPS: 20).
    pub min_samples_per_cluster: usize,
    /// Most clusters (GPS: 50).
    pub max_clusters: usize,
    /// Most trajectories kept for the prior; older ones are dropped first (GPS: 20).
    pub max_samples: usize,
    /// EM iterations (GPS: 100).
    pub max_iterations: usize,
    /// Prior strength: multiplies `m`, `n0` and `Φ` (GPS: 1).
    pub strength: f64,
    /// Seed of the random initial cluster assignment.
    pub seed: u64,
}

impl Default for GmmPriorConfig {
    fn default() -> Self {
        Self {
            min_samples_per_cluster: 20,
            max_clusters: 50,
            max_samples: 20,
            max_iterations: 100,
            strength: 1.0,
            seed: 0,
        }
    }
}

impl GmmPriorConfig {
    /// Checks the ranges the prior relies on: at least 2 clusters (the fit clamps the count to
    /// `[2, max_clusters]`), at least one sample per cluster, kept trajectory and EM iteration, and
    /// a finite positive strength.
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.max_clusters < 2
            || self.min_samples_per_cluster == 0
            || self.max_samples == 0
            || self.max_iterations == 0
        {
            return Err(ModelError::Other(format!(
                "GMM prior: max_clusters {} must be >= 2, and min_samples_per_cluster {}, \
                 max_samples {} and max_iterations {} >= 1",
                self.max_clusters,
                self.min_samples_per_cluster,
                self.max_samples,
                self.max_iterations
            )));
        }
        if !(self.strength.is_finite() && self.strength > 0.0) {
            return Err(ModelError::Other(format!(
                "GMM prior: strength {} must be finite and > 0",
                self.strength
            )));
        }
        Ok(())
    }
}

/// Settings of a [`TvlgFit`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TvlgConfig {
    /// Added to the `[x; u]` block of the joint covariance before conditioning (GPS
    /// `regularization`, 1e-6): keeps the solve well posed with few samples or collinear data.
    pub regularization: f64,
    /// The GMM prior; `None` fits each step by regularized least squares alone.
    pub prior: Option<GmmPriorConfig>,
}

impl Default for TvlgConfig {
    fn default() -> Self {
        Self {
            regularization: 1e-6,
            prior: Some(GmmPriorConfig::default()),
        }
    }
}

impl TvlgConfig {
    /// Checks a finite, non-negative `regularization` and the prior's ranges.
    pub fn validate(&self) -> Result<(), ModelError> {
        if !(self.regularization.is_finite() && self.regularization >= 0.0) {
            return Err(ModelError::Other(format!(
                "dynamics regularization {} must be finite and >= 0",
                self.regularization
            )));
        }
        self.prior.as_ref().map_or(Ok(()), GmmPriorConfig::validate)
    }
}

/// Fitted time-varying linear-Gaussian dynamics
/// `x_{t+1} ~ N(fx_t x_t + fu_t u_t + fc_t, cov_t)`, `t = 0..horizon()`, and the initial-state
/// distribution `N(x0_mean, x0_cov)` of the samples.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TvlgDynamics {
    /// State Jacobians `dX x dX`.
    pub fx: Vec<DMatrix<f64>>,
    /// Action Jacobians `dX x dU`.
    pub fu: Vec<DMatrix<f64>>,
    /// Offsets, length `dX`.
    pub fc: Vec<DVector<f64>>,
    /// Noise covariances `dX x dX`.
    pub cov: Vec<DMatrix<f64>>,
    /// Mean of the initial states.
    pub x0_mean: DVector<f64>,
    /// Covariance of the initial states (diagonal of their variances, floored at 1e-6).
    pub x0_cov: DMatrix<f64>,
}

impl TvlgDynamics {
    /// Number of fitted steps.
    pub fn horizon(&self) -> usize {
        self.fx.len()
    }

    /// Mean next state at step `t`.
    pub fn mean_next(&self, t: usize, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        &self.fx[t] * x + &self.fu[t] * u + &self.fc[t]
    }
}

/// Fits TVLG dynamics from `N` trajectories, keeping a GMM prior over the transitions it has
/// seen (the last `max_samples` trajectories).
///
/// ```
/// use ndarray::Array3;
/// use tandem_models::{TvlgConfig, TvlgFit};
///
/// // x_{t+1} = 0.9 x_t + 0.5 u_t, 20 noiseless trajectories of 5 steps.
/// let (n, t) = (20, 5);
/// let mut xs = Array3::zeros((n, t + 1, 1));
/// let mut us = Array3::zeros((n, t, 1));
/// for i in 0..n {
///     xs[[i, 0, 0]] = i as f64 * 0.1 - 1.0;
///     for k in 0..t {
///         us[[i, k, 0]] = ((i * 7 + k * 3) % 5) as f64 - 2.0;
///         xs[[i, k + 1, 0]] = 0.9 * xs[[i, k, 0]] + 0.5 * us[[i, k, 0]];
///     }
/// }
/// let mut fit = TvlgFit::new(TvlgConfig::default());
/// let dyn_ = fit.fit(xs.view(), us.view()).unwrap();
/// assert_eq!(dyn_.horizon(), 5);
/// assert!((dyn_.fx[2][(0, 0)] - 0.9).abs() < 1e-3);
/// assert!((dyn_.fu[2][(0, 0)] - 0.5).abs() < 1e-3);
/// ```
///
/// Serializable with its prior's data, so a resumed fit continues exactly.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TvlgFit {
    cfg: TvlgConfig,
    /// Transitions `[x_t, u_t, x_{t+1}]` of the kept trajectories, one block per trajectory.
    prior_data: Vec<DMatrix<f64>>,
    gmm: Option<Gmm>,
    prior_updates: u64,
}

/// Checks the shapes and values of a trajectory batch; returns `(N, steps, dX, dU)`.
fn check_trajectories(
    states: &ArrayView3<'_, f64>,
    actions: &ArrayView3<'_, f64>,
) -> Result<(usize, usize, usize, usize), ModelError> {
    let (n, ts, dx) = states.dim();
    let (na, ta, du) = actions.dim();
    if n == 0 || ts < 2 {
        return Err(ModelError::Empty);
    }
    if na != n {
        return Err(ModelError::Dim {
            what: "actions (trajectories)".into(),
            expected: n,
            got: na,
        });
    }
    if ta + 1 < ts {
        return Err(ModelError::Dim {
            what: "actions (time steps, at least states' steps - 1)".into(),
            expected: ts - 1,
            got: ta,
        });
    }
    for (what, a) in [("states", states.view()), ("actions", actions.view())] {
        for (i, traj) in a.outer_iter().enumerate() {
            if traj.iter().any(|v| !v.is_finite()) {
                return Err(ModelError::NonFinite {
                    what: format!("{what} (row = trajectory)"),
                    row: i,
                });
            }
        }
    }
    Ok((n, ts - 1, dx, du))
}

/// The `N x (2 dX + dU)` matrix of `[x_t, u_t, x_{t+1}]` at step `t`.
fn joint_at(states: &ArrayView3<'_, f64>, actions: &ArrayView3<'_, f64>, t: usize) -> DMatrix<f64> {
    let (n, _, dx) = states.dim();
    let du = actions.dim().2;
    DMatrix::from_fn(n, 2 * dx + du, |i, j| {
        if j < dx {
            states[[i, t, j]]
        } else if j < dx + du {
            actions[[i, t, j - dx]]
        } else {
            states[[i, t + 1, j - dx - du]]
        }
    })
}

/// A Gaussian `y | a ~ N(gain a + offset, cov)`: the last block of a joint Gaussian conditioned
/// on its first.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Conditional {
    /// `Σ_{y,a} Σ_{a,a}⁻¹`, `dY x dA`.
    pub(crate) gain: DMatrix<f64>,
    /// `μ_y − gain μ_a`.
    pub(crate) offset: DVector<f64>,
    /// `Σ_{yy} − gain Σ_{a,a} gainᵀ`, symmetrized.
    pub(crate) cov: DMatrix<f64>,
}

/// Fits the joint Gaussian of the rows `[a, y]` of `ys` (`N x (dA + dY)`, `dA = d_in`) and
/// conditions `y` on `a` (GPS `gauss_fit_joint_prior`): the empirical covariance, or with
/// `prior = Some((gmm, strength))` the MAP of the normal-inverse-Wishart posterior whose prior is
/// the mixture's inference for these rows (`m`, `n0`, `Φ` scaled by `strength`), with
/// `regularization` added to the diagonal of the `a` block. `None` when that block is not
/// positive definite even with jitter. The dynamics fit ([`TvlgFit`]) and the policy fit
/// ([`crate::TvlgPolicyFit`]) share it.
pub(crate) fn fit_conditional(
    ys: &DMatrix<f64>,
    prior: Option<(&Gmm, f64)>,
    regularization: f64,
    d_in: usize,
) -> Result<Option<Conditional>, ModelError> {
    let nf = ys.nrows() as f64;
    let d_out = ys.ncols() - d_in;
    let mun = ys.row_mean().transpose();
    let mut diff = ys.clone();
    for mut row in diff.row_iter_mut() {
        row -= mun.transpose();
    }
    let empsig = diff.transpose() * &diff / nf;
    let empsig = (&empsig + empsig.transpose()) * 0.5;
    let mut sigma = match prior {
        Some((gmm, strength)) => {
            let (mu0, phi, m, n0) = gmm.inference(ys)?;
            let (m, n0) = (m * strength, n0 * strength);
            let phi = phi * m;
            let dm = &mun - mu0;
            let denom = (nf + n0).max(1e-12);
            (&empsig * nf + phi + &dm * dm.transpose() * (nf * m / (nf + m))) / denom
        }
        None => empsig,
    };
    sigma = (&sigma + sigma.transpose()) * 0.5;
    for i in 0..d_in {
        sigma[(i, i)] += regularization;
    }
    let sxx = sigma.view((0, 0), (d_in, d_in)).into_owned();
    let sxy = sigma.view((0, d_in), (d_in, d_out)).into_owned();
    let Some(chol) = robust_cholesky(&sxx) else {
        return Ok(None);
    };
    let gain = chol.solve(&sxy).transpose(); // dY x dA
    let offset = mun.rows(d_in, d_out) - &gain * mun.rows(0, d_in);
    let syy = sigma.view((d_in, d_in), (d_out, d_out)).into_owned();
    let cov = syy - &gain * &sxx * gain.transpose();
    let cov = (&cov + cov.transpose()) * 0.5;
    Ok(Some(Conditional { gain, offset, cov }))
}

impl TvlgFit {
    /// A fitter with no prior data yet.
    pub fn new(cfg: TvlgConfig) -> Self {
        Self {
            cfg,
            prior_data: Vec::new(),
            gmm: None,
            prior_updates: 0,
        }
    }

    /// Its settings.
    pub fn config(&self) -> &TvlgConfig {
        &self.cfg
    }

    /// The current GMM prior, once [`TvlgFit::update_prior`] has run.
    pub fn gmm(&self) -> Option<&Gmm> {
        self.gmm.as_ref()
    }

    /// Adds trajectories (`states`: `N x T1 x dX`, `actions`: `N x T x dU` with `T >= T1 - 1`)
    /// to the prior's data, drops the oldest beyond `max_samples`, and refits the GMM. Does
    /// nothing without a prior configured. On error the prior is unchanged.
    pub fn update_prior(
        &mut self,
        states: ArrayView3<'_, f64>,
        actions: ArrayView3<'_, f64>,
    ) -> Result<(), ModelError> {
        let Some(pcfg) = self.cfg.prior.clone() else {
            return Ok(());
        };
        let (n, steps, dx, du) = check_trajectories(&states, &actions)?;
        if let Some(first) = self.prior_data.first() {
            if first.ncols() != 2 * dx + du {
                return Err(ModelError::Dim {
                    what: "trajectory width (2 dX + dU) against earlier prior data".into(),
                    expected: first.ncols(),
                    got: 2 * dx + du,
                });
            }
        }
        let mut data = self.prior_data.clone();
        for i in 0..n {
            let traj = DMatrix::from_fn(steps, 2 * dx + du, |t, j| {
                if j < dx {
                    states[[i, t, j]]
                } else if j < dx + du {
                    actions[[i, t, j - dx]]
                } else {
                    states[[i, t + 1, j - dx - du]]
                }
            });
            data.push(traj);
        }
        let keep = pcfg.max_samples.max(1);
        if data.len() > keep {
            data.drain(..data.len() - keep);
        }
        let rows: usize = data.iter().map(|d| d.nrows()).sum();
        let width = 2 * dx + du;
        let mut all = DMatrix::zeros(rows, width);
        let mut r = 0;
        for d in &data {
            all.rows_mut(r, d.nrows()).copy_from(d);
            r += d.nrows();
        }
        let k = (rows / pcfg.min_samples_per_cluster.max(1)).clamp(2, pcfg.max_clusters.max(2));
        let mut rng = rng_from_seed(pcfg.seed.wrapping_add(self.prior_updates));
        let gmm = Gmm::fit(&all, k, pcfg.max_iterations, &mut rng)?;
        self.prior_data = data;
        self.gmm = Some(gmm);
        self.prior_updates += 1;
        Ok(())
    }

    /// Updates the prior with these trajectories (as GPS does before each fit) and fits the
    /// dynamics of every step. Shapes as in [`TvlgFit::update_prior`].
    pub fn fit(
        &mut self,
        states: ArrayView3<'_, f64>,
        actions: ArrayView3<'_, f64>,
    ) -> Result<TvlgDynamics, ModelError> {
        check_trajectories(&states, &actions)?;
        let saved = (
            self.prior_data.clone(),
            self.gmm.clone(),
            self.prior_updates,
        );
        self.update_prior(states, actions)?;
        let out = self.fit_with_current_prior(states, actions);
        if out.is_err() {
            (self.prior_data, self.gmm, self.prior_updates) = saved;
        }
        out
    }

    /// Fits the dynamics of every step with the prior as it is (no prior update); without a
    /// fitted GMM (or without a prior configured) this is the prior-free fit.
    pub fn fit_with_current_prior(
        &self,
        states: ArrayView3<'_, f64>,
        actions: ArrayView3<'_, f64>,
    ) -> Result<TvlgDynamics, ModelError> {
        let (n, steps, dx, du) = check_trajectories(&states, &actions)?;
        let dxu = dx + du;
        let d = dxu + dx;
        if let Some(g) = &self.gmm {
            if g.means[0].len() != d {
                return Err(ModelError::Dim {
                    what: "trajectory width (2 dX + dU) against the prior".into(),
                    expected: g.means[0].len(),
                    got: d,
                });
            }
        }
        let strength = self.cfg.prior.as_ref().map_or(0.0, |p| p.strength);
        let mut out = TvlgDynamics {
            fx: Vec::with_capacity(steps),
            fu: Vec::with_capacity(steps),
            fc: Vec::with_capacity(steps),
            cov: Vec::with_capacity(steps),
            x0_mean: DVector::zeros(dx),
            x0_cov: DMatrix::zeros(dx, dx),
        };
        let x0 = states.index_axis(Axis(1), 0);
        for j in 0..dx {
            let col = x0.column(j);
            let mean = col.mean().unwrap_or(0.0);
            let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
            out.x0_mean[j] = mean;
            out.x0_cov[(j, j)] = var.max(1e-6);
        }
        let prior = self
            .gmm
            .as_ref()
            .filter(|_| strength > 0.0)
            .map(|g| (g, strength));
        for t in 0..steps {
            let ys = joint_at(&states, &actions, t);
            let Conditional {
                gain: fd,
                offset: fc,
                cov: dynsig,
            } = fit_conditional(&ys, prior, self.cfg.regularization, dxu)?.ok_or_else(|| {
                ModelError::Other(format!(
                    "TVLG fit, step {t}: the [x; u] covariance is not positive definite \
                     (raise `regularization`)"
                ))
            })?;
            if fd
                .iter()
                .chain(fc.iter())
                .chain(dynsig.iter())
                .any(|v| !v.is_finite())
            {
                return Err(ModelError::NonFinite {
                    what: "fitted TVLG dynamics (row = time step)".into(),
                    row: t,
                });
            }
            out.fx.push(fd.columns(0, dx).into_owned());
            out.fu.push(fd.columns(dx, du).into_owned());
            out.fc.push(fc);
            out.cov.push(dynsig);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;
    use rand_distr::{Distribution, StandardNormal};
    use tandem_core::Rng;

    /// A known time-varying linear system with noise `L_noise L_noiseᵀ`.
    struct System {
        a: Vec<DMatrix<f64>>,
        b: Vec<DMatrix<f64>>,
        c: Vec<DVector<f64>>,
        noise_chol: DMatrix<f64>,
    }

    impl System {
        fn new(dx: usize, du: usize, steps: usize, noise: f64) -> Self {
            Self::with_variation(dx, du, steps, noise, 1.0)
        }

        /// `variation = 0` gives a time-invariant system.
        fn with_variation(dx: usize, du: usize, steps: usize, noise: f64, variation: f64) -> Self {
            let mut a = Vec::new();
            let mut b = Vec::new();
            let mut c = Vec::new();
            for t in 0..steps {
                let s = variation * t as f64 / steps as f64;
                a.push(DMatrix::from_fn(dx, dx, |i, j| {
                    if i == j {
                        0.95 - 0.1 * s
                    } else if j == i + 1 {
                        0.1 + 0.05 * s
                    } else if i == j + 1 {
                        -0.05 * (1.0 + s)
                    } else {
                        0.0
                    }
                }));
                b.push(DMatrix::from_fn(dx, du, |i, j| {
                    0.3 * ((i + 2 * j) as f64 * 0.7 + s).sin()
                }));
                c.push(DVector::from_fn(dx, |i, _| 0.05 * (i as f64 - s)));
            }
            let noise_chol = DMatrix::from_fn(dx, dx, |i, j| {
                if i == j {
                    noise
                } else if i > j {
                    0.3 * noise
                } else {
                    0.0
                }
            });
            Self {
                a,
                b,
                c,
                noise_chol,
            }
        }

        fn rollouts(&self, n: usize, rng: &mut Rng) -> (Array3<f64>, Array3<f64>) {
            let steps = self.a.len();
            let (dx, du) = (self.a[0].nrows(), self.b[0].ncols());
            let mut xs = Array3::zeros((n, steps + 1, dx));
            let mut us = Array3::zeros((n, steps, du));
            let mut g = || -> f64 { StandardNormal.sample(rng) };
            for i in 0..n {
                let mut x = DVector::from_fn(dx, |_, _| g());
                for t in 0..steps {
                    let u = DVector::from_fn(du, |_, _| g());
                    for j in 0..dx {
                        xs[[i, t, j]] = x[j];
                    }
                    for j in 0..du {
                        us[[i, t, j]] = u[j];
                    }
                    let w = DVector::from_fn(dx, |_, _| g());
                    x = &self.a[t] * &x + &self.b[t] * &u + &self.c[t] + &self.noise_chol * w;
                }
                for j in 0..dx {
                    xs[[i, steps, j]] = x[j];
                }
            }
            (xs, us)
        }
    }

    #[test]
    fn recovers_a_noiseless_linear_system_exactly() {
        // Time-varying: the prior-free fit is exact. Time-invariant: every GMM cluster lies on
        // the system's hyperplane, so the prior is exact too.
        for (variation, prior) in [(1.0, None), (0.0, Some(GmmPriorConfig::default()))] {
            let sys = System::with_variation(3, 2, 6, 0.0, variation);
            let (xs, us) = sys.rollouts(30, &mut rng_from_seed(1));
            let cfg = TvlgConfig {
                prior,
                ..TvlgConfig::default()
            };
            let d = TvlgFit::new(cfg).fit(xs.view(), us.view()).unwrap();
            for t in 0..6 {
                assert!((&d.fx[t] - &sys.a[t]).abs().max() < 1e-4, "t={t}");
                assert!((&d.fu[t] - &sys.b[t]).abs().max() < 1e-4, "t={t}");
                assert!((&d.fc[t] - &sys.c[t]).abs().max() < 1e-4, "t={t}");
                assert!(d.cov[t].abs().max() < 1e-4, "t={t}");
            }
        }
    }

    #[test]
    fn recovers_dynamics_and_noise_covariance_with_many_samples() {
        let sys = System::new(3, 2, 4, 0.1);
        let (xs, us) = sys.rollouts(20_000, &mut rng_from_seed(2));
        let d = TvlgFit::new(TvlgConfig::default())
            .fit(xs.view(), us.view())
            .unwrap();
        let true_cov = &sys.noise_chol * sys.noise_chol.transpose();
        for t in 0..4 {
            // Standard error of each coefficient ~ 0.1 / sqrt(20000) = 7e-4.
            assert!((&d.fx[t] - &sys.a[t]).abs().max() < 5e-3, "t={t}");
            assert!((&d.fu[t] - &sys.b[t]).abs().max() < 5e-3, "t={t}");
            assert!((&d.fc[t] - &sys.c[t]).abs().max() < 5e-3, "t={t}");
            assert!(
                (&d.cov[t] - &true_cov).abs().max() < 0.05 * true_cov.max(),
                "t={t}"
            );
        }
    }

    #[test]
    fn prior_beats_prior_free_fit_with_fewer_samples_than_dimensions() {
        // dX + dU = 6 > N = 3 samples per step: the per-step least squares is underdetermined.
        let steps = 40;
        let sys = System::new(4, 2, steps, 0.02);
        let (xs, us) = sys.rollouts(3, &mut rng_from_seed(3));
        let (hx, hu) = sys.rollouts(200, &mut rng_from_seed(4));
        let error = |d: &TvlgDynamics| {
            let mut se = 0.0;
            for i in 0..200 {
                for t in 0..steps {
                    let x = DVector::from_fn(4, |j, _| hx[[i, t, j]]);
                    let u = DVector::from_fn(2, |j, _| hu[[i, t, j]]);
                    let y = DVector::from_fn(4, |j, _| hx[[i, t + 1, j]]);
                    se += (d.mean_next(t, &x, &u) - y).norm_squared();
                }
            }
            se / (200 * steps) as f64
        };
        let with_prior = TvlgFit::new(TvlgConfig::default())
            .fit(xs.view(), us.view())
            .unwrap();
        let without = TvlgFit::new(TvlgConfig {
            prior: None,
            ..TvlgConfig::default()
        })
        .fit(xs.view(), us.view())
        .unwrap();
        let (ep, ef) = (error(&with_prior), error(&without));
        eprintln!("TVLG held-out one-step MSE: with prior {ep}, prior-free {ef}");
        // Noise floor: trace of the noise covariance = 4 * 0.02^2 * (1 + 3 * 0.09) ~ 0.002.
        assert!(ep < 0.05 * ef, "with prior {ep}, prior-free {ef}");
        assert!(ep < 0.05, "with prior {ep}");
    }

    #[test]
    fn ill_conditioned_data_gives_finite_dynamics_and_seeded_fits_repeat() {
        // No excitation (u = 0) and two identical state components: the [x; u] covariance is
        // singular; regularization keeps the fit finite and the mean prediction exact on data.
        let (n, steps) = (8, 10);
        let mut xs = Array3::zeros((n, steps + 1, 3));
        let us = Array3::zeros((n, steps, 2));
        for i in 0..n {
            let x0 = i as f64 * 0.3 - 1.0;
            for t in 0..=steps {
                let v = x0 * 0.9f64.powi(t as i32);
                xs[[i, t, 0]] = v;
                xs[[i, t, 1]] = v;
                xs[[i, t, 2]] = 1.0;
            }
        }
        for prior in [None, Some(GmmPriorConfig::default())] {
            let cfg = TvlgConfig {
                prior,
                ..TvlgConfig::default()
            };
            let d = TvlgFit::new(cfg.clone()).fit(xs.view(), us.view()).unwrap();
            let again = TvlgFit::new(cfg).fit(xs.view(), us.view()).unwrap();
            assert_eq!(d, again, "same seed, same fit");
            for t in 0..steps {
                assert!(d.fx[t].iter().chain(d.cov[t].iter()).all(|v| v.is_finite()));
                let x = DVector::from_fn(3, |j, _| xs[[2, t, j]]);
                let u = DVector::zeros(2);
                let y = DVector::from_fn(3, |j, _| xs[[2, t + 1, j]]);
                assert!((d.mean_next(t, &x, &u) - y).abs().max() < 1e-3, "t={t}");
            }
        }
    }

    #[test]
    fn bad_data_is_an_error_and_leaves_the_prior_unchanged() {
        let sys = System::new(2, 1, 5, 0.01);
        let (xs, us) = sys.rollouts(10, &mut rng_from_seed(5));
        let mut fit = TvlgFit::new(TvlgConfig::default());
        fit.fit(xs.view(), us.view()).unwrap();
        let before = fit.gmm().cloned();
        let mut bad = xs.clone();
        bad[[7, 2, 1]] = f64::NAN;
        assert_eq!(
            fit.fit(bad.view(), us.view()).unwrap_err(),
            ModelError::NonFinite {
                what: "states (row = trajectory)".into(),
                row: 7
            }
        );
        let short = us.slice(ndarray::s![.., ..3, ..]).to_owned();
        assert!(matches!(
            fit.fit(xs.view(), short.view()),
            Err(ModelError::Dim { .. })
        ));
        let wide = Array3::<f64>::zeros((10, 6, 3));
        let wide_u = Array3::<f64>::zeros((10, 5, 1));
        assert!(matches!(
            fit.fit(wide.view(), wide_u.view()),
            Err(ModelError::Dim { .. })
        ));
        assert_eq!(fit.gmm().cloned(), before);
        assert_eq!(
            fit.fit(Array3::zeros((0, 6, 2)).view(), us.view()),
            Err(ModelError::Empty)
        );
    }

    /// A fit read back from JSON (prior data, mixture, update count) continues exactly as the
    /// one written: the next fit gives the same dynamics and the same prior, bit for bit.
    #[test]
    fn a_fit_read_back_from_json_continues_exactly() {
        let sys = System::new(2, 1, 6, 0.05);
        let mut rng = rng_from_seed(9);
        let mut fit = TvlgFit::new(TvlgConfig::default());
        let (xs, us) = sys.rollouts(5, &mut rng);
        fit.fit(xs.view(), us.view()).unwrap();
        let mut back: TvlgFit =
            serde_json::from_str(&serde_json::to_string(&fit).unwrap()).unwrap();
        assert_eq!(back, fit);
        let (xs, us) = sys.rollouts(5, &mut rng);
        let expected = fit.fit(xs.view(), us.view()).unwrap();
        assert_eq!(back.fit(xs.view(), us.view()).unwrap(), expected);
        assert_eq!(back, fit);
        assert!(fit.gmm().is_some());
    }
}
