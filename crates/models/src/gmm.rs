//! A Gaussian mixture fitted by EM, used as the dynamics prior of [`crate::TvlgFit`].
//!
//! Follows the GMM of Levine, Finn et al.'s guided-policy-search code (`gps/utility/gmm.py`):
//! seeded initialization (k-means++ means, see [`Gmm::fit`]), EM with cluster rebooting and a `1e-6 I` covariance
//! floor, and `inference`, which turns the mixture into a normal-inverse-Wishart prior for a
//! batch of points (their average cluster responsibilities weight the cluster moments).

use nalgebra::{DMatrix, DVector};
use rand::Rng as _;
use tandem_core::Rng;

use crate::model::ModelError;

/// A fitted Gaussian mixture over `D`-dimensional points.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Gmm {
    /// Cluster means, `K` vectors of length `D`.
    pub means: Vec<DVector<f64>>,
    /// Cluster covariances, `K` matrices `D x D`.
    pub covs: Vec<DMatrix<f64>>,
    /// Log mixing weights, length `K`.
    pub log_mass: Vec<f64>,
    /// Number of points the mixture was fitted on.
    pub n_points: usize,
}

/// `log(sum(exp(v)))`, stable.
fn logsumexp(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + v.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}

/// Cholesky factor of `s`, adding a growing multiple of the identity when `s` is not numerically
/// positive definite.
pub(crate) fn robust_cholesky(s: &DMatrix<f64>) -> Option<nalgebra::Cholesky<f64, nalgebra::Dyn>> {
    if let Some(c) = s.clone().cholesky() {
        return Some(c);
    }
    let d = s.nrows();
    let scale = (s.trace().abs() / d.max(1) as f64).max(1e-12);
    let mut jitter = 1e-10 * scale;
    for _ in 0..20 {
        let m = s + DMatrix::identity(d, d) * jitter;
        if let Some(c) = m.cholesky() {
            return Some(c);
        }
        jitter *= 10.0;
    }
    None
}

impl Gmm {
    /// Fits `k` clusters to the rows of `data` (`N x D`) with at most `max_iterations` EM steps;
    /// the initial assignment of points to clusters is drawn from `rng`.
    pub fn fit(
        data: &DMatrix<f64>,
        k: usize,
        max_iterations: usize,
        rng: &mut Rng,
    ) -> Result<Self, ModelError> {
        let (n, d) = data.shape();
        if n == 0 {
            return Err(ModelError::Empty);
        }
        let k = k.max(1);
        // Initial means by k-means++ seeding (the GPS code assigns points to clusters uniformly
        // at random, which starts every cluster at the global mean and leaves EM to break the
        // symmetry slowly); every cluster starts with the covariance of all data.
        let all_mean = data.row_mean().transpose();
        let centered = data - DMatrix::from_fn(n, d, |_, j| all_mean[j]);
        let all_cov = centered.transpose() * &centered / n as f64 + DMatrix::identity(d, d) * 2e-6;
        let mut means: Vec<DVector<f64>> = vec![data.row(rng.random_range(0..n)).transpose()];
        let mut dist2: Vec<f64> = (0..n)
            .map(|i| (data.row(i).transpose() - &means[0]).norm_squared())
            .collect();
        while means.len() < k {
            let total: f64 = dist2.iter().sum();
            let pick = if total > 0.0 && total.is_finite() {
                let mut r = rng.random::<f64>() * total;
                dist2
                    .iter()
                    .position(|&w| {
                        r -= w;
                        r <= 0.0
                    })
                    .unwrap_or(n - 1)
            } else {
                rng.random_range(0..n)
            };
            let mu = data.row(pick).transpose();
            for (i, d2) in dist2.iter_mut().enumerate() {
                *d2 = d2.min((data.row(i).transpose() - &mu).norm_squared());
            }
            means.push(mu);
        }
        let covs = vec![all_cov; k];
        let mut gmm = Gmm {
            means,
            covs,
            log_mass: vec![-(k as f64).ln(); k],
            n_points: n,
        };

        let mut prev_ll = f64::NEG_INFINITY;
        for _ in 0..max_iterations {
            // E-step.
            let logobs = gmm.log_obs(data)?;
            let mut ll = 0.0;
            let mut logw = DMatrix::zeros(n, k);
            let mut row = vec![0.0; k];
            for i in 0..n {
                for (c, r) in row.iter_mut().enumerate() {
                    *r = logobs[(i, c)];
                }
                let lse = logsumexp(&row);
                ll += lse;
                for c in 0..k {
                    logw[(i, c)] = logobs[(i, c)] - lse;
                }
            }
            if !ll.is_finite() {
                return Err(ModelError::Other(
                    "GMM log-likelihood became non-finite during EM".into(),
                ));
            }
            if ll < prev_ll || (ll - prev_ll).abs() < 1e-7 * ll.abs() {
                break;
            }
            prev_ll = ll;

            // M-step: masses, then per-cluster normalized weights (rebooting tiny clusters).
            let col_lse: Vec<f64> = (0..k)
                .map(|c| logsumexp(logw.column(c).as_slice()))
                .collect();
            let total = logsumexp(&col_lse);
            gmm.log_mass = col_lse.iter().map(|l| l - total).collect();
            for c in 0..k {
                let reboot = gmm.log_mass[c].exp() < 1e-4 / k as f64;
                let w: Vec<f64> = (0..n)
                    .map(|i| {
                        if reboot {
                            1.0 / n as f64
                        } else {
                            (logw[(i, c)] - col_lse[c]).exp()
                        }
                    })
                    .collect();
                // Weighted moments as matrix products: μ = Xᵀw, S = (√w X)ᵀ(√w X) − μμᵀ.
                let wv = DVector::from_vec(w);
                let mu = data.transpose() * &wv;
                let sw = wv.map(f64::sqrt);
                let mut wx = data.clone();
                for mut col in wx.column_iter_mut() {
                    col.component_mul_assign(&sw);
                }
                let mut s = wx.transpose() * &wx;
                s.ger(-1.0, &mu, &mu, 1.0);
                let s = (&s + s.transpose()) * 0.5 + DMatrix::identity(d, d) * 1e-6;
                gmm.means[c] = mu;
                gmm.covs[c] = s;
            }
        }
        Ok(gmm)
    }

    /// Number of clusters.
    pub fn clusters(&self) -> usize {
        self.means.len()
    }

    /// `N x K` log densities of each point under each cluster, plus the cluster's log mass.
    pub fn log_obs(&self, data: &DMatrix<f64>) -> Result<DMatrix<f64>, ModelError> {
        let (n, d) = data.shape();
        let k = self.clusters();
        let mut out =
            DMatrix::from_element(n, k, -0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln());
        for c in 0..k {
            let chol = robust_cholesky(&self.covs[c]).ok_or_else(|| {
                ModelError::Other(format!(
                    "GMM cluster {c} covariance is not positive definite"
                ))
            })?;
            let l = chol.l();
            let half_logdet: f64 = l.diagonal().iter().map(|v| v.ln()).sum();
            // L⁻¹ once, then one matrix product for all points (faster than a triangular solve
            // with many right-hand sides in nalgebra).
            let linv = l
                .solve_lower_triangular(&DMatrix::identity(d, d))
                .ok_or_else(|| {
                    ModelError::Other(format!("GMM cluster {c}: singular Cholesky factor"))
                })?;
            let mut diff = data.transpose();
            for mut col in diff.column_iter_mut() {
                col -= &self.means[c];
            }
            let sol = &linv * &diff;
            for i in 0..n {
                out[(i, c)] += -half_logdet - 0.5 * sol.column(i).norm_squared() + self.log_mass[c];
            }
        }
        Ok(out)
    }

    /// Normal-inverse-Wishart prior `(mu0, Phi, m, n0)` for the points `pts` (`N x D`), as in the
    /// GPS code's `GMM.inference`: clusters weighted by the points' average responsibility, the
    /// mixture's overall mean and covariance as `mu0` and `Phi`, `m = 1` and
    /// `n0 = (n_points - 2 - D) / n_points` (both before the prior strength is applied).
    pub fn inference(
        &self,
        pts: &DMatrix<f64>,
    ) -> Result<(DVector<f64>, DMatrix<f64>, f64, f64), ModelError> {
        let logobs = self.log_obs(pts)?;
        let (n, k) = logobs.shape();
        let d = pts.ncols();
        let mut row = vec![0.0; k];
        let mut logw_cols: Vec<Vec<f64>> = vec![Vec::with_capacity(n); k];
        for i in 0..n {
            for (c, r) in row.iter_mut().enumerate() {
                *r = logobs[(i, c)];
            }
            let lse = logsumexp(&row);
            for c in 0..k {
                logw_cols[c].push(logobs[(i, c)] - lse);
            }
        }
        let wts: Vec<f64> = logw_cols
            .iter()
            .map(|col| (logsumexp(col) - (n as f64).ln()).exp())
            .collect();
        let mut mu = DVector::zeros(d);
        for (c, w) in wts.iter().enumerate() {
            mu.axpy(*w, &self.means[c], 1.0);
        }
        let mut sigma = DMatrix::zeros(d, d);
        for (c, w) in wts.iter().enumerate() {
            let diff = &self.means[c] - &mu;
            sigma += (&self.covs[c] + &diff * diff.transpose()) * *w;
        }
        let np = self.n_points as f64;
        let n0 = (np - 2.0 - d as f64) / np;
        Ok((mu, sigma, 1.0, n0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::{Distribution, StandardNormal};
    use tandem_core::seeding::rng_from_seed;

    #[test]
    fn em_finds_two_separated_clusters() {
        let mut rng = rng_from_seed(3);
        let n = 400;
        let data = DMatrix::from_fn(n, 2, |i, j| {
            let z: f64 = StandardNormal.sample(&mut rng);
            let centre = if i % 4 == 0 { 10.0 } else { -10.0 };
            centre * (j as f64 + 1.0) + 0.5 * z
        });
        let gmm = Gmm::fit(&data, 2, 100, &mut rng_from_seed(1)).unwrap();
        let mut masses: Vec<(f64, f64)> = gmm
            .means
            .iter()
            .zip(&gmm.log_mass)
            .map(|(m, l)| (m[0], l.exp()))
            .collect();
        masses.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!((masses[0].0 + 10.0).abs() < 0.2, "{masses:?}");
        assert!((masses[1].0 - 10.0).abs() < 0.2, "{masses:?}");
        assert!((masses[0].1 - 0.75).abs() < 0.02 && (masses[1].1 - 0.25).abs() < 0.02);
        for c in &gmm.covs {
            assert!((c[(0, 0)] - 0.25).abs() < 0.1, "{c}");
        }
    }
}
