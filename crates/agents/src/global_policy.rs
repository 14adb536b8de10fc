//! GPS's global policy: a neural Gaussian policy `N(μ_θ(o(x)), diag(σ²))` over features `o(x)`
//! of the state, trained by supervised regression onto target actions (in MDGPS, the local
//! controllers' actions at their sampled states), optionally weighted by the local controllers'
//! precisions. MDGPS (`tandem-algos`) linearizes it around its samples
//! ([`GlobalPolicy::linearization`]) to bound the local updates.

use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use tandem_core::Rng;
use tandem_nn::{
    mse, Adam, Checkpoint, Checkpointable, Mlp, MlpConfig, MlpWorkspace, NnError, Optimizer,
};

use crate::error::{AgentError, Result};

/// Writes the features of a state (first argument) into a buffer (second).
pub type FeatureMap = std::sync::Arc<dyn Fn(&[f64], &mut [f64]) + Send + Sync>;

/// What the global policy sees of a state: `dim` features written by `map(state, out)` (e.g. a
/// task's observation: angles as cosines and sines, the end effector's offset to the target).
/// Without one the policy sees the state itself.
#[derive(Clone)]
pub struct PolicyInput {
    /// Number of features.
    pub dim: usize,
    /// Writes the features of a state into `out` (`dim` long).
    pub map: FeatureMap,
}

/// How the global policy is fitted each iteration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyConfig {
    /// Hidden layer widths (ReLU).
    pub hidden: Vec<usize>,
    /// Passes over the iteration's data set.
    pub epochs: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Adam's learning rate.
    pub learning_rate: f32,
    /// How each sampled state's target action is weighted, and how `σ²` follows.
    #[serde(default)]
    pub weighting: Weighting,
}

impl Default for PolicyConfig {
    /// Two hidden layers of 64, 50 epochs of minibatches of 128 at learning rate 10⁻³, targets
    /// weighted uniformly ([`Weighting`] says why).
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            epochs: 50,
            batch_size: 128,
            learning_rate: 1e-3,
            weighting: Weighting::Uniform,
        }
    }
}

/// The global policy's regression loss and variance. The default is `Uniform`: on the reacher (24
/// conditions, fixed `ε`) GPS's precision weighting was mixed with LQR-FLM (final test distance
/// 0.077 against 0.063 m uniformly weighted on seed 0, 0.048 against 0.065 m on seed 1), worse
/// with PILQR (0.111 against 0.074 m, seed 0: the steps where a local controller has narrowed its
/// covariance dominate the fit), and with MDGPS's step rule (`tandem-algos`' `MdgpsStep`) the
/// regression diverged (seed 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// GPS's: the error at a state of step `t` weighted by the local controller's precision
    /// `Σ_t⁻¹`, `(μ_θ(x) − u)ᵀ Σ_t⁻¹ (μ_θ(x) − u)` (scaled so that the mean precision's trace
    /// per action is 1: with equal covariances everywhere it is the mean squared error), and
    /// `σ² = 1 / diag(mean Σ_t⁻¹)` over all sampled states, the variance that maximizes the
    /// targets' likelihood under those weights. Steps where the local controller is sure of its
    /// action count more than those where it still explores.
    Precision,
    /// Plain mean squared error, and `σ²` the mean of the local controllers' variances.
    #[default]
    Uniform,
}

/// The neural global policy `N(μ_θ(o(x)), diag(σ²))` over the features `o(x)` of the state
/// ([`PolicyInput`], or the state itself).
pub struct GlobalPolicy {
    net: Mlp,
    input: Option<PolicyInput>,
    state_dim: usize,
    x_mean: Vec<f64>,
    x_std: Vec<f64>,
    /// The states' standard deviations: the linearization's step scale.
    state_std: Vec<f64>,
    /// Whether the input standardization has been fixed (by the first fit).
    scaled: bool,
    /// Action variances `σ²`.
    pub variance: Vec<f64>,
}

impl GlobalPolicy {
    /// An untrained policy over `state_dim` states (seen through `input`, if given) and
    /// `action_dim` actions (identity input scaling until the first fit), variance `variance` per
    /// action.
    pub fn new(
        state_dim: usize,
        action_dim: usize,
        hidden: &[usize],
        variance: f64,
        input: Option<PolicyInput>,
        rng: &mut Rng,
    ) -> Result<Self> {
        let d = input.as_ref().map_or(state_dim, |i| i.dim);
        let mut sizes = vec![d];
        sizes.extend_from_slice(hidden);
        sizes.push(action_dim);
        Ok(Self {
            net: Mlp::new(MlpConfig::new(&sizes), rng)?,
            input,
            state_dim,
            x_mean: vec![0.0; d],
            x_std: vec![1.0; d],
            state_std: vec![1.0; state_dim],
            scaled: false,
            variance: vec![variance; action_dim],
        })
    }

    /// The mean's network.
    pub fn net(&self) -> &Mlp {
        &self.net
    }

    /// The features of a batch of states (rows of `state_dim`), not yet standardized.
    fn features(&self, states: &[f64]) -> Vec<f64> {
        match &self.input {
            None => states.to_vec(),
            Some(input) => {
                let rows = states.len() / self.state_dim;
                let mut out = vec![0.0; rows * input.dim];
                for (x, o) in states.chunks(self.state_dim).zip(out.chunks_mut(input.dim)) {
                    (input.map)(x, o);
                }
                out
            }
        }
    }

    fn standardized(&self, states: &[f64]) -> Vec<f32> {
        let d = self.x_mean.len();
        self.features(states)
            .iter()
            .enumerate()
            .map(|(i, v)| ((v - self.x_mean[i % d]) / self.x_std[i % d]) as f32)
            .collect()
    }

    /// The mean actions of a batch of states (`B × S` row-major in, `B × A` out).
    pub fn mean(&self, states: &[f64], ws: &mut MlpWorkspace) -> Result<Vec<f64>> {
        let n = self.state_dim;
        if n == 0 || !states.len().is_multiple_of(n) {
            return Err(AgentError::Dim {
                what: "global policy states (whole rows)",
                expected: n,
                got: states.len(),
            });
        }
        let out = self
            .net
            .forward(&self.standardized(states), states.len() / n, ws)?;
        Ok(out.iter().map(|&v| f64::from(v)).collect())
    }

    /// The policy's mean and its Jacobian at the state `x`: `(μ(x), ∂μ/∂x(x))`, the Jacobian
    /// `A × S` row-major by central differences, step `10⁻³` in each state's scale (the
    /// standard deviations of the first fit's states). MDGPS linearizes the policy this way
    /// around its samples' mean states.
    pub fn linearization(&self, x: &[f64], ws: &mut MlpWorkspace) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = self.state_dim;
        if x.len() != n {
            return Err(AgentError::Dim {
                what: "global policy state",
                expected: n,
                got: x.len(),
            });
        }
        let m = self.variance.len();
        // Rows: x, then x ± h e_j for every j.
        let mut batch = x.to_vec();
        let h: Vec<f64> = self.state_std.iter().map(|s| 1e-3 * s).collect();
        for j in 0..n {
            for sign in [1.0, -1.0] {
                let mut xj = x.to_vec();
                xj[j] += sign * h[j];
                batch.extend_from_slice(&xj);
            }
        }
        let out = self.mean(&batch, ws)?;
        let mut jacobian = vec![0.0; m * n];
        for a in 0..m {
            for j in 0..n {
                jacobian[a * n + j] =
                    (out[(1 + 2 * j) * m + a] - out[(2 + 2 * j) * m + a]) / (2.0 * h[j]);
            }
        }
        Ok((out[..m].to_vec(), jacobian))
    }

    /// Regresses the mean onto `targets` at `states` (rows of `S` and `A`), each row's error
    /// weighted by its `A × A` matrix in `weights` (row-major) if given; returns the last epoch's
    /// mean loss. The first call fixes the input standardization.
    pub fn fit(
        &mut self,
        states: &[f64],
        targets: &[f64],
        weights: Option<&[f64]>,
        cfg: &PolicyConfig,
        opt: &mut Adam,
        rng: &mut Rng,
    ) -> Result<f64> {
        let (n, d, m) = (self.state_dim, self.x_mean.len(), self.variance.len());
        let rows = states.len() / n;
        if !self.scaled {
            let stats = |data: &[f64], w: usize, j: usize| {
                let col: Vec<f64> = (0..rows).map(|i| data[i * w + j]).collect();
                let mean = col.iter().sum::<f64>() / rows as f64;
                let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / rows as f64;
                (mean, var.sqrt().max(1e-3))
            };
            let feats = self.features(states);
            for j in 0..d {
                (self.x_mean[j], self.x_std[j]) = stats(&feats, d, j);
            }
            for j in 0..n {
                self.state_std[j] = stats(states, n, j).1;
            }
            self.scaled = true;
        }
        let x = self.standardized(states);
        let y: Vec<f32> = targets.iter().map(|&v| v as f32).collect();
        let w: Option<Vec<f32>> = weights.map(|w| w.iter().map(|&v| v as f32).collect());
        let mut order: Vec<usize> = (0..rows).collect();
        let mut ws = self.net.workspace();
        let mut grads = self.net.zero_grads();
        let (mut bx, mut by) = (Vec::new(), Vec::new());
        let mut last = f64::NAN;
        for _ in 0..cfg.epochs {
            order.shuffle(rng);
            let (mut sum, mut batches) = (0.0, 0);
            for chunk in order.chunks(cfg.batch_size) {
                bx.clear();
                by.clear();
                for &i in chunk {
                    bx.extend_from_slice(&x[i * d..(i + 1) * d]);
                    by.extend_from_slice(&y[i * m..(i + 1) * m]);
                }
                let pred = self
                    .net
                    .forward_train(&bx, chunk.len(), &mut ws, None)?
                    .to_vec();
                let mut d = vec![0.0f32; pred.len()];
                sum += match &w {
                    None => f64::from(mse(&pred, &by, Some(&mut d))?),
                    Some(w) => match weighted_mse(&pred, &by, chunk, w, m, &mut d) {
                        l if l.is_finite() => l,
                        value => {
                            return Err(AgentError::NonFinite {
                                what: "global policy's weighted loss",
                                value,
                            })
                        }
                    },
                };
                batches += 1;
                self.net.backward(&mut ws, &d, Some(&mut grads), None)?;
                opt.step(self.net.params_mut(), &grads)?;
            }
            last = sum / batches as f64;
        }
        Ok(last)
    }
}

/// What a checkpoint keeps of a [`GlobalPolicy`] beside its network.
#[derive(Serialize, Deserialize)]
struct Scaling {
    x_mean: Vec<f64>,
    x_std: Vec<f64>,
    state_std: Vec<f64>,
    scaled: bool,
    variance: Vec<f64>,
}

impl Checkpointable for GlobalPolicy {
    /// Writes the mean's network under `{prefix}.net` and the input standardization and action
    /// variances as `{prefix}.scaling` (JSON). The feature map is not saved: the policy that loads
    /// is built with it.
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        self.net.save_to(&format!("{prefix}.net"), ckpt)?;
        let scaling = Scaling {
            x_mean: self.x_mean.clone(),
            x_std: self.x_std.clone(),
            state_std: self.state_std.clone(),
            scaled: self.scaled,
            variance: self.variance.clone(),
        };
        ckpt.put_json(&format!("{prefix}.scaling"), &scaling)
    }

    /// Reads what [`Checkpointable::save_to`] wrote into a policy of the same shape; on error
    /// `self` is unchanged.
    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let what = format!("{prefix}.scaling");
        let s: Scaling = ckpt.get_json(&what)?;
        let lens = |s: &Scaling| {
            [
                s.x_mean.len(),
                s.x_std.len(),
                s.state_std.len(),
                s.variance.len(),
            ]
        };
        let ours = [
            self.x_mean.len(),
            self.x_std.len(),
            self.state_std.len(),
            self.variance.len(),
        ];
        if lens(&s) != ours {
            return Err(NnError::ShapeMismatch {
                what,
                expected: format!("{ours:?}"),
                got: format!("{:?}", lens(&s)),
            });
        }
        self.net.load_from(&format!("{prefix}.net"), ckpt)?;
        (self.x_mean, self.x_std, self.state_std) = (s.x_mean, s.x_std, s.state_std);
        (self.scaled, self.variance) = (s.scaled, s.variance);
        Ok(())
    }
}

/// `(1 / (B A)) Σ_i r_iᵀ W_i r_i` with `r_i = pred_i − target_i` over the `B` rows of the batch,
/// `W_i` the weight matrix of data row `rows[i]` in `weights` (`A × A` each, row-major), and its
/// gradient in `grad`: with identity weights, [`mse`].
fn weighted_mse(
    pred: &[f32],
    target: &[f32],
    rows: &[usize],
    weights: &[f32],
    m: usize,
    grad: &mut [f32],
) -> f64 {
    let scale = 1.0 / pred.len() as f32;
    let mut sum = 0.0f64;
    for (i, &row) in rows.iter().enumerate() {
        let r = |a: usize| pred[i * m + a] - target[i * m + a];
        let w = &weights[row * m * m..(row + 1) * m * m];
        for a in 0..m {
            let wr: f32 = (0..m).map(|b| w[a * m + b] * r(b)).sum();
            sum += f64::from(r(a) * wr);
            grad[i * m + a] = 2.0 * scale * wr;
        }
    }
    sum * f64::from(scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The weighted loss is the mean squared error under identity weights, `rᵀ W r / (B A)` on a
    /// hand-worked pair, and its gradient matches central differences.
    #[test]
    fn weighted_regression_loss_and_gradient() {
        let (pred, target) = ([0.5f32, -1.0, 2.0, 0.0], [0.0f32, 0.0, 1.0, 1.0]);
        let eye = [1.0f32, 0.0, 0.0, 1.0];
        let ident: Vec<f32> = eye.iter().chain(&eye).copied().collect();
        let (mut g, mut g_mse) = ([0.0f32; 4], [0.0f32; 4]);
        let l = weighted_mse(&pred, &target, &[0, 1], &ident, 2, &mut g);
        let l_mse = mse(&pred, &target, Some(&mut g_mse)).unwrap();
        assert!((l - f64::from(l_mse)).abs() < 1e-6);
        assert_eq!(g, g_mse);
        // Row 1 of the data weighted by [[2, 1], [1, 3]], used by batch row 0 only:
        // r = (0.5, −1): rᵀ W r = 0.5 − 1 + 3 = 2.5, over B A = 2 → 1.25.
        let weights = [1.0f32, 0.0, 0.0, 1.0, 2.0, 1.0, 1.0, 3.0];
        let l = weighted_mse(&pred[..2], &target[..2], &[1], &weights, 2, &mut g[..2]);
        assert!((l - 1.25).abs() < 1e-6, "{l}");
        let rows = [1, 0];
        let mut grad = [0.0f32; 4];
        weighted_mse(&pred, &target, &rows, &weights, 2, &mut grad);
        for j in 0..4 {
            let (mut up, mut down) = (pred, pred);
            up[j] += 1e-2;
            down[j] -= 1e-2;
            let mut scratch = [0.0f32; 4];
            let fd = (weighted_mse(&up, &target, &rows, &weights, 2, &mut scratch)
                - weighted_mse(&down, &target, &rows, &weights, 2, &mut scratch))
                / 2e-2;
            assert!(
                (fd - f64::from(grad[j])).abs() < 1e-4,
                "{j}: {fd} vs {}",
                grad[j]
            );
        }
    }

    /// A fitted policy saved and loaded into a fresh one of the same shape gives the same means
    /// (network and standardization) and variances; a policy of another shape refuses it.
    #[test]
    fn a_saved_policy_loads_into_a_fresh_one() {
        use tandem_core::seeding::rng_from_seed;
        let mut rng = rng_from_seed(4);
        let mut policy = GlobalPolicy::new(2, 1, &[8], 0.5, None, &mut rng).unwrap();
        let states = [0.3, -1.0, 2.0, 0.5, -0.7, 0.1, 1.5, 1.5];
        let targets = [1.0, -0.5, 0.2, 0.8];
        let cfg = PolicyConfig {
            epochs: 3,
            batch_size: 2,
            ..PolicyConfig::default()
        };
        let mut opt = Adam::new(
            tandem_nn::AdamConfig::with_lr(1e-2),
            policy.net().num_params(),
        )
        .unwrap();
        policy
            .fit(&states, &targets, None, &cfg, &mut opt, &mut rng)
            .unwrap();
        policy.variance[0] = 0.25;
        let mut ckpt = Checkpoint::new();
        policy.save_to("pi", &mut ckpt).unwrap();
        let mut fresh = GlobalPolicy::new(2, 1, &[8], 0.5, None, &mut rng).unwrap();
        let mut ws = policy.net().workspace();
        assert_ne!(
            fresh.mean(&states, &mut ws).unwrap(),
            policy.mean(&states, &mut ws).unwrap()
        );
        fresh.load_from("pi", &ckpt).unwrap();
        assert_eq!(
            fresh.mean(&states, &mut ws).unwrap(),
            policy.mean(&states, &mut ws).unwrap()
        );
        assert_eq!(fresh.variance, policy.variance);
        let mut wider = GlobalPolicy::new(3, 1, &[8], 0.5, None, &mut rng).unwrap();
        assert!(wider.load_from("pi", &ckpt).is_err());
    }
}
