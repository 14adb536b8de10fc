//! [`RunningNormalizer`]: running per-feature mean and variance, the one normalizer of the
//! workspace: network inputs and targets (`tandem-nn`, which adds checkpointing) and observations
//! (`tandem-envs`'s `NormalizeObservation`, gymnasium's wrapper). It lives here because both sit
//! above this crate and neither may depend on the other.
//!
//! Statistics are kept in f64 and merged batch by batch with Chan et al.'s parallel formula
//! (each batch's own mean and squared deviations are computed two-pass, then combined), so long
//! streams do not lose precision. Normalization itself runs in f32 with cached `mean` and
//! `1/std`, allocation-free.

use serde::{Deserialize, Serialize};

/// What a [`RunningNormalizer`] rejects.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NormalizerError {
    /// A buffer whose length does not fit the normalizer's dimension.
    #[error("{what}: expected {expected}, got {got}")]
    ShapeMismatch {
        /// Which buffer.
        what: String,
        /// The expected length, written out.
        expected: String,
        /// The length given, written out.
        got: String,
    },
    /// A NaN or infinity in data or state.
    #[error("non-finite value in {what} at index {index}")]
    NonFinite {
        /// Which buffer.
        what: String,
        /// Index of the first non-finite element.
        index: usize,
    },
    /// An out-of-range setting (eps, clip).
    #[error("invalid normalizer setting: {0}")]
    InvalidConfig(String),
}

type Result<T> = std::result::Result<T, NormalizerError>;
type NnError = NormalizerError;

fn check_len(what: &str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        return Ok(());
    }
    Err(NormalizerError::ShapeMismatch {
        what: what.to_string(),
        expected: format!("length {expected}"),
        got: format!("length {got}"),
    })
}

fn check_finite(what: &str, x: &[f32]) -> Result<()> {
    match x.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(NormalizerError::NonFinite {
            what: what.to_string(),
            index,
        }),
    }
}

/// Per-feature running mean and (population) variance; normalizes as
/// `(x - mean) / sqrt(var + eps)`, optionally clipped to `±clip` (stable-baselines3's
/// `VecNormalize` conventions). Before any data it is the identity (mean 0, var 1).
///
/// A *frozen* normalizer ([`RunningNormalizer::set_frozen`]) tells an owner that updates it from
/// a stream (the observation wrapper) to stop updating; `update_*` and `merge` themselves always
/// update.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "NormalizerState", into = "NormalizerState")]
pub struct RunningNormalizer {
    dim: usize,
    count: f64,
    mean: Vec<f64>,
    m2: Vec<f64>,
    eps: f64,
    clip: Option<f64>,
    frozen: bool,
    cache: Cache,
}

/// The serialized form of a [`RunningNormalizer`] (its statistics; the f32 cache is rebuilt).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NormalizerState {
    /// Number of features.
    pub dim: usize,
    /// Samples seen.
    pub count: f64,
    /// Per-feature means.
    pub mean: Vec<f64>,
    /// Per-feature sums of squared deviations.
    pub m2: Vec<f64>,
    /// Variance epsilon.
    pub eps: f64,
    /// Clip of normalized values.
    pub clip: Option<f64>,
    /// Statistics no longer updated from a stream.
    #[serde(default)]
    pub frozen: bool,
}

impl From<RunningNormalizer> for NormalizerState {
    fn from(n: RunningNormalizer) -> Self {
        Self {
            dim: n.dim,
            count: n.count,
            mean: n.mean,
            m2: n.m2,
            eps: n.eps,
            clip: n.clip,
            frozen: n.frozen,
        }
    }
}

impl TryFrom<NormalizerState> for RunningNormalizer {
    type Error = NnError;
    fn try_from(s: NormalizerState) -> Result<Self> {
        if s.mean.len() != s.dim || s.m2.len() != s.dim {
            return Err(NnError::ShapeMismatch {
                what: "normalizer state".into(),
                expected: format!("mean and m2 of length {}", s.dim),
                got: format!("{} and {}", s.mean.len(), s.m2.len()),
            });
        }
        let ok = s.count.is_finite()
            && s.count >= 0.0
            && s.eps.is_finite()
            && s.eps >= 0.0
            && s.mean.iter().chain(&s.m2).all(|v| v.is_finite());
        if !ok {
            return Err(NnError::NonFinite {
                what: "normalizer state".into(),
                index: 0,
            });
        }
        let mut n = Self {
            dim: s.dim,
            count: s.count,
            mean: s.mean,
            m2: s.m2,
            eps: s.eps,
            clip: s.clip,
            frozen: s.frozen,
            cache: Cache::default(),
        };
        n.refresh();
        Ok(n)
    }
}

#[derive(Debug, Clone, PartialEq, Default)]
struct Cache {
    mean: Vec<f32>,
    inv_std: Vec<f32>,
    std: Vec<f32>,
}

impl RunningNormalizer {
    /// A normalizer for `dim` features with `eps = 1e-8` and no clipping.
    pub fn new(dim: usize) -> Self {
        let mut n = Self {
            dim,
            count: 0.0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
            eps: 1e-8,
            clip: None,
            frozen: false,
            cache: Cache::default(),
        };
        n.refresh();
        n
    }

    /// Sets the variance epsilon (must be ≥ 0).
    pub fn with_eps(mut self, eps: f64) -> Result<Self> {
        if !(eps.is_finite() && eps >= 0.0) {
            return Err(NnError::InvalidConfig(format!(
                "normalizer eps must be >= 0, got {eps}"
            )));
        }
        self.eps = eps;
        self.refresh();
        Ok(self)
    }

    /// Clips normalized values to `±clip` (must be > 0).
    pub fn with_clip(mut self, clip: f64) -> Result<Self> {
        if !(clip.is_finite() && clip > 0.0) {
            return Err(NnError::InvalidConfig(format!(
                "normalizer clip must be > 0, got {clip}"
            )));
        }
        self.clip = Some(clip);
        Ok(self)
    }

    /// Freezes (or thaws) the statistics for owners that update from a stream.
    pub fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
    }

    /// Whether the statistics are frozen.
    pub fn is_frozen(&self) -> bool {
        self.frozen
    }

    /// The statistics and settings (what serialization writes).
    pub fn state(&self) -> NormalizerState {
        self.clone().into()
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of samples seen.
    pub fn count(&self) -> f64 {
        self.count
    }

    /// Per-feature means.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Per-feature population variances (1 before any data).
    pub fn var(&self) -> Vec<f64> {
        if self.count > 0.0 {
            self.m2.iter().map(|m| m / self.count).collect()
        } else {
            vec![1.0; self.dim]
        }
    }

    /// Per-feature `sqrt(var + eps)` in f32 (the divisor used by `normalize`).
    pub fn std_f32(&self) -> &[f32] {
        &self.cache.std
    }

    /// Per-feature means in f32.
    pub fn mean_f32(&self) -> &[f32] {
        &self.cache.mean
    }

    /// Rebuilds the f32 cache; called after every change of the statistics.
    fn refresh(&mut self) {
        let var = self.var();
        self.cache.mean = self.mean.iter().map(|m| *m as f32).collect();
        self.cache.std = var.iter().map(|v| (v + self.eps).sqrt() as f32).collect();
        self.cache.inv_std = var
            .iter()
            .map(|v| (1.0 / (v + self.eps).sqrt()) as f32)
            .collect();
    }

    /// Adds a batch of f64 rows (`rows × dim`, row-major). Non-finite data is an error (nothing
    /// added).
    pub fn update_f64(&mut self, batch: &[f64]) -> Result<()> {
        if !batch.len().is_multiple_of(self.dim.max(1)) {
            return Err(NnError::ShapeMismatch {
                what: "normalizer batch".into(),
                expected: format!("a multiple of {}", self.dim),
                got: format!("length {}", batch.len()),
            });
        }
        if let Some(i) = batch.iter().position(|v| !v.is_finite()) {
            return Err(NnError::NonFinite {
                what: "normalizer batch".into(),
                index: i,
            });
        }
        let rows = batch.len() / self.dim.max(1);
        if rows == 0 {
            return Ok(());
        }
        let d = self.dim;
        let nb = rows as f64;
        let mut bmean = vec![0.0f64; d];
        for row in batch.chunks_exact(d) {
            for (m, v) in bmean.iter_mut().zip(row) {
                *m += v;
            }
        }
        bmean.iter_mut().for_each(|m| *m /= nb);
        let mut bm2 = vec![0.0f64; d];
        for row in batch.chunks_exact(d) {
            for ((s, v), m) in bm2.iter_mut().zip(row).zip(&bmean) {
                *s += (v - m) * (v - m);
            }
        }
        self.merge_stats(nb, &bmean, &bm2);
        Ok(())
    }

    /// Adds a batch of f32 rows (`rows × dim`).
    pub fn update_f32(&mut self, batch: &[f32]) -> Result<()> {
        let b: Vec<f64> = batch.iter().map(|v| f64::from(*v)).collect();
        self.update_f64(&b)
    }

    fn merge_stats(&mut self, nb: f64, bmean: &[f64], bm2: &[f64]) {
        let na = self.count;
        let n = na + nb;
        for j in 0..self.dim {
            let delta = bmean[j] - self.mean[j];
            self.mean[j] += delta * nb / n;
            self.m2[j] += bm2[j] + delta * delta * na * nb / n;
        }
        self.count = n;
        self.refresh();
    }

    /// Merges another normalizer's statistics (Chan et al.), as if its data had been added here.
    pub fn merge(&mut self, other: &RunningNormalizer) -> Result<()> {
        check_len("normalizer merge dim", self.dim, other.dim)?;
        if other.count > 0.0 {
            self.merge_stats(other.count, &other.mean.clone(), &other.m2.clone());
        }
        Ok(())
    }

    /// Normalizes f32 rows in place.
    pub fn normalize_f32(&self, x: &mut [f32]) -> Result<()> {
        self.check_rows(x.len())?;
        let clip = self.clip.map(|c| c as f32);
        for row in x.chunks_exact_mut(self.dim) {
            for ((v, m), s) in row
                .iter_mut()
                .zip(&self.cache.mean)
                .zip(&self.cache.inv_std)
            {
                *v = (*v - m) * s;
            }
            if let Some(c) = clip {
                row.iter_mut().for_each(|v| *v = v.clamp(-c, c));
            }
        }
        check_finite("normalized values", x)
    }

    /// Maps normalized f32 rows back in place: `x · std + mean` (clipping is not undone).
    pub fn denormalize_f32(&self, x: &mut [f32]) -> Result<()> {
        self.check_rows(x.len())?;
        for row in x.chunks_exact_mut(self.dim) {
            for ((v, m), s) in row.iter_mut().zip(&self.cache.mean).zip(&self.cache.std) {
                *v = *v * s + m;
            }
        }
        Ok(())
    }

    /// Normalizes f64 rows in place (full f64 precision).
    pub fn normalize_f64(&self, x: &mut [f64]) -> Result<()> {
        self.check_rows(x.len())?;
        let var = self.var();
        for row in x.chunks_exact_mut(self.dim) {
            for ((v, m), s2) in row.iter_mut().zip(&self.mean).zip(&var) {
                *v = (*v - m) / (s2 + self.eps).sqrt();
                if let Some(c) = self.clip {
                    *v = v.clamp(-c, c);
                }
            }
        }
        Ok(())
    }

    /// Maps normalized f64 rows back in place.
    pub fn denormalize_f64(&self, x: &mut [f64]) -> Result<()> {
        self.check_rows(x.len())?;
        let var = self.var();
        for row in x.chunks_exact_mut(self.dim) {
            for ((v, m), s2) in row.iter_mut().zip(&self.mean).zip(&var) {
                *v = *v * (s2 + self.eps).sqrt() + m;
            }
        }
        Ok(())
    }

    fn check_rows(&self, len: usize) -> Result<()> {
        if self.dim == 0 || !len.is_multiple_of(self.dim) {
            return Err(NnError::ShapeMismatch {
                what: "normalizer input".into(),
                expected: format!("a multiple of {}", self.dim),
                got: format!("length {len}"),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_pass(data: &[f64], dim: usize) -> (Vec<f64>, Vec<f64>) {
        let n = (data.len() / dim) as f64;
        let mut mean = vec![0.0; dim];
        for r in data.chunks(dim) {
            for j in 0..dim {
                mean[j] += r[j] / n;
            }
        }
        let mut var = vec![0.0; dim];
        for r in data.chunks(dim) {
            for j in 0..dim {
                var[j] += (r[j] - mean[j]).powi(2) / n;
            }
        }
        (mean, var)
    }

    #[test]
    fn streaming_matches_two_pass_statistics() {
        let dim = 3;
        // Large offset, small spread: the case where naive sum-of-squares loses precision.
        let data: Vec<f64> = (0..3000)
            .map(|i| 1e6 + ((i as f64) * 0.37).sin() * (1.0 + (i % 3) as f64))
            .collect();
        let mut n = RunningNormalizer::new(dim);
        for chunk in data.chunks(3 * 17) {
            n.update_f64(chunk).unwrap();
        }
        let (mean, var) = two_pass(&data, dim);
        for j in 0..dim {
            assert!((n.mean()[j] - mean[j]).abs() < 1e-8, "mean {j}");
            assert!(
                (n.var()[j] - var[j]).abs() < 1e-8 * var[j].max(1.0),
                "var {j}"
            );
        }
        assert_eq!(n.count(), 1000.0);
        // Merging two halves equals one stream.
        let mut a = RunningNormalizer::new(dim);
        let mut b = RunningNormalizer::new(dim);
        a.update_f64(&data[..1500]).unwrap();
        b.update_f64(&data[1500..]).unwrap();
        a.merge(&b).unwrap();
        for j in 0..dim {
            assert!((a.mean()[j] - mean[j]).abs() < 1e-8);
            assert!((a.var()[j] - var[j]).abs() < 1e-8);
        }
    }

    #[test]
    fn normalize_denormalize_and_identity_before_data() {
        let mut n = RunningNormalizer::new(2);
        let mut x = vec![3.0f32, -4.0];
        n.normalize_f32(&mut x).unwrap();
        assert!((x[0] - 3.0).abs() < 1e-6 && (x[1] + 4.0).abs() < 1e-6);
        n.update_f32(&[1.0, 10.0, 3.0, 10.0, 5.0, 10.0]).unwrap();
        let mut y = vec![3.0f32, 10.0, 5.0, 10.0];
        n.normalize_f32(&mut y).unwrap();
        // feature 0: mean 3, var 8/3; feature 1: constant (var 0 -> divided by sqrt(eps))
        assert!((y[0]).abs() < 1e-6);
        assert!((y[2] - 2.0 / (8.0f32 / 3.0).sqrt()).abs() < 1e-5);
        assert_eq!(y[1], 0.0);
        n.denormalize_f32(&mut y).unwrap();
        assert!((y[2] - 5.0).abs() < 1e-5);
        let mut z = vec![5.0f64, 10.0];
        n.normalize_f64(&mut z).unwrap();
        n.denormalize_f64(&mut z).unwrap();
        assert!((z[0] - 5.0).abs() < 1e-12);
        let mut c = RunningNormalizer::new(1).with_clip(1.0).unwrap();
        c.update_f64(&[0.0, 1.0]).unwrap();
        let mut v = vec![100.0f32];
        c.normalize_f32(&mut v).unwrap();
        assert_eq!(v, vec![1.0]);
    }

    #[test]
    fn errors_and_serialization() {
        let mut n = RunningNormalizer::new(2);
        assert!(n.update_f64(&[1.0, 2.0, 3.0]).is_err());
        assert!(n.update_f64(&[1.0, f64::NAN]).is_err());
        assert_eq!(n.count(), 0.0);
        assert!(n.normalize_f32(&mut [1.0]).is_err());
        n.update_f64(&[1.0, 2.0, 4.0, -1.0]).unwrap();
        let json = serde_json::to_string(&n).unwrap();
        let back: RunningNormalizer = serde_json::from_str(&json).unwrap();
        assert_eq!(back, n);
        assert!(
            serde_json::from_str::<RunningNormalizer>(&json.replace("\"eps\"", "\"epz\"")).is_err()
        );
        let (mut a, mut b) = (vec![0.5f32, 0.5], vec![0.5f32, 0.5]);
        n.normalize_f32(&mut a).unwrap();
        back.normalize_f32(&mut b).unwrap();
        assert_eq!(a, b);
    }
}
