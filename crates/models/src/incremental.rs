//! [`IncrementalModel`]: p1's deep incremental model `s_{t+1} = s_t + L_θ(·) Δa_t`
//! (eqs. 4–6).

use nalgebra::DMatrix;
use ndarray::{s, Array2, ArrayView2};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
use tandem_nn::budget::{widths, MemoryEstimate};
use tandem_nn::{Activation, Checkpoint, Checkpointable, Mlp, MlpConfig, NnError};

use crate::data::{check_array, check_input};
use crate::model::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use crate::train::{
    nn_other, standardized_inputs, FitRows, FitSpec, Network, Objective, OptimizerConfig,
    RowFilter, Standardized, Standardizer, Targets,
};

/// Shape of the learned matrix `L_t` (`S x A`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GainStructure {
    /// A full `S x A` matrix.
    Full,
    /// A diagonal matrix (p1 Remark 3; needs `S == A`).
    Diagonal,
}

/// Settings of an [`IncrementalModel`]. `Default`: p1 trains `L_θ` with Adam (Sec. 4.2) and
/// gives no architecture; two hidden layers of 200 ReLU units (MBPO's width), Adam 1e-3, a full
/// `L`, no prior.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IncrementalModelConfig {
    /// Hidden layer widths of the network giving `L_θ`.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Full or diagonal `L`.
    pub structure: GainStructure,
    /// Prior `L0` (p1 Remark 4), row-major `S x A` for `Full`, the `S` diagonal entries for
    /// `Diagonal`: the model starts at `L = L0` and learns the correction.
    pub prior_gain: Option<Vec<f64>>,
    /// Transitions whose largest `|Δa_j|` is at most this carry no information about `L_t`
    /// (p1: `L_t = L_{t-1}` when `Δa_t = 0`) and are left out of the fit.
    pub min_action_change: f64,
    /// Optimizer.
    pub optimizer: OptimizerConfig,
    /// Seed of the weight initialization.
    pub seed: u64,
}

impl IncrementalModelConfig {
    /// Checks positive hidden widths, a finite non-negative `min_action_change` and the
    /// optimizer's ranges (the dimensions are checked by [`IncrementalModel::new`]).
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.hidden.contains(&0) {
            return Err(ModelError::Other(format!(
                "incremental model hidden widths {:?} must be positive",
                self.hidden
            )));
        }
        if !(self.min_action_change >= 0.0 && self.min_action_change.is_finite()) {
            return Err(ModelError::Other(format!(
                "min_action_change {} must be finite and >= 0",
                self.min_action_change
            )));
        }
        self.optimizer.validate()
    }

    /// The memory of the network giving `L_θ` (with its optimizer state) for
    /// `state_dim`-dimensional states and `action_dim`-dimensional actions, trained on
    /// minibatches of `batch` rows.
    pub fn memory(&self, state_dim: usize, action_dim: usize, batch: usize) -> MemoryEstimate {
        let out = match self.structure {
            GainStructure::Full => state_dim.saturating_mul(action_dim),
            GainStructure::Diagonal => state_dim,
        };
        let sizes = widths(state_dim.saturating_add(action_dim), &self.hidden, out);
        self.optimizer.network_memory(
            format!("incremental model {:?}", self.hidden),
            &sizes,
            batch,
        )
    }
}

impl Default for IncrementalModelConfig {
    fn default() -> Self {
        Self {
            hidden: vec![200, 200],
            activation: Activation::Relu,
            structure: GainStructure::Full,
            prior_gain: None,
            min_action_change: 1e-9,
            optimizer: OptimizerConfig::adam(1e-3),
            seed: 0,
        }
    }
}

/// p1's deep incremental model: `ŝ_{t+1} = s_t + L_θ(s_t, a_{t−1}) Δa_t` with
/// `Δa_t = a_t − a_{t−1}` (eqs. 4 and 6), fitted by least squares on one-step-back data (eq. 5,
/// squared norm).
///
/// **What `L_θ` sees.** p1 estimates the unknown part from one step back,
/// `ĥ_t = s_t − L a_{t−1}` (eq. 3), so `(s_t, a_{t−1})` is what is known before `a_t` is chosen;
/// the network maps it to `L_t`. The prediction is linear in `a_t`, which makes the model an
/// error-evolution model for linear MPC/LQR (p1 eq. 9; [`IncrementalModel::gain`] gives `L_t`).
///
/// **The previous action is part of its state.** The model's state is `z_t = [s_t, a_{t−1}]`
/// (`S + A` wide, [`DynamicsModel::state_dim`]) and it predicts `z_{t+1} = [ŝ_{t+1}, a_t]`, so
/// planners, rollouts and linearizations need nothing beyond `(z, a)`.
/// [`crate::TransitionsBuilder::with_prev_action`] records such rows (the previous action zero
/// at an episode's start), and [`tandem_envs::WithPrevAction`] is the task over them. The fit
/// learns from the first `S` columns of the next state only: the rest is `a_t` by definition.
///
/// **Δa = 0.** The prediction is then `s_t` whatever `L_t` is (p1 keeps `L_t = L_{t−1}` there to
/// avoid the singularity of its definition); such transitions give no information about `L`
/// and are excluded from the fit (`min_action_change`). A dataset with no action change at all is
/// an error.
///
/// **Scaling.** The network sees standardized `(s_t, a_{t−1})` and outputs `M`;
/// `L = L0 + diag(σ_Δs) M diag(σ_Δa)⁻¹` with `σ` the root-mean-square state and action changes
/// of the training rows, so the loss is in standard units. The output layer starts at zero, so
/// before any fit `L = L0` exactly (Remark 4's starting point; `L0 = 0` without a prior).
///
/// ```
/// use ndarray::array;
/// use tandem_core::seeding::rng_from_seed;
/// use tandem_models::{DynamicsModel, IncrementalModel, IncrementalModelConfig, ModelInput};
///
/// let cfg = IncrementalModelConfig { prior_gain: Some(vec![0.5, 2.0]), ..Default::default() };
/// let m = IncrementalModel::new(2, 1, cfg).unwrap();
/// assert_eq!(m.state_dim(), 3);
/// // z = [s, a_prev] = [1, 1, 0.1], a = 0.3.
/// let (z, a) = (array![[1.0, 1.0, 0.1]], array![[0.3]]);
/// let p = m.predict(&ModelInput::new(z.view(), a.view()), &mut rng_from_seed(0)).unwrap();
/// // Unfitted: [s + L0 (a - a_prev), a] = [1 + 0.5 * 0.2, 1 + 2 * 0.2, 0.3].
/// assert!((p.next_states[[0, 0]] - 1.1).abs() < 1e-12);
/// assert!((p.next_states[[0, 1]] - 1.4).abs() < 1e-12);
/// assert_eq!(p.next_states[[0, 2]], 0.3);
/// ```
#[derive(Debug, Clone)]
pub struct IncrementalModel {
    cfg: IncrementalModelConfig,
    /// `S`, the state without the previous action.
    state_dim: usize,
    action_dim: usize,
    /// The network giving `M`, its inputs `(s_t, a_{t−1})`; its targets' scales are the RMS of
    /// the state changes (`σ_Δs`, length S).
    learned: Standardized<Network>,
    /// RMS of the action changes (`σ_Δa`, length A).
    da_scale: Vec<f64>,
    /// `L0`, row-major `S x A` (zeros without a prior).
    l0: Vec<f64>,
}

impl IncrementalModel {
    /// A model of `S = state_dim` states and `A = action_dim` actions, whose own state is the
    /// `S + A` wide `[s, a_{t−1}]`; errors if `Diagonal` is asked with `S != A` or the prior has
    /// the wrong length or non-finite entries.
    pub fn new(
        state_dim: usize,
        action_dim: usize,
        cfg: IncrementalModelConfig,
    ) -> Result<Self, ModelError> {
        cfg.validate()?;
        let (s, a) = (state_dim, action_dim);
        if s == 0 || a == 0 {
            return Err(ModelError::Dim {
                what: "state_dim and action_dim (must be positive)".into(),
                expected: 1,
                got: 0,
            });
        }
        if cfg.structure == GainStructure::Diagonal && s != a {
            return Err(ModelError::Dim {
                what: "action_dim (a diagonal L needs as many actions as states)".into(),
                expected: s,
                got: a,
            });
        }
        let n_out = match cfg.structure {
            GainStructure::Full => s * a,
            GainStructure::Diagonal => s,
        };
        let mut l0 = vec![0.0; s * a];
        if let Some(p) = &cfg.prior_gain {
            if p.len() != n_out {
                return Err(ModelError::Dim {
                    what: "prior_gain entries".into(),
                    expected: n_out,
                    got: p.len(),
                });
            }
            if let Some(row) = p.iter().position(|v| !v.is_finite()) {
                return Err(ModelError::NonFinite {
                    what: "prior_gain (row = entry)".into(),
                    row,
                });
            }
            match cfg.structure {
                GainStructure::Full => l0.copy_from_slice(p),
                GainStructure::Diagonal => {
                    for (i, v) in p.iter().enumerate() {
                        l0[i * a + i] = *v;
                    }
                }
            }
        }
        let mut sizes = vec![s + a];
        sizes.extend(&cfg.hidden);
        sizes.push(n_out);
        let mut net = Mlp::new(
            MlpConfig::new(&sizes).hidden(cfg.activation),
            &mut rng_from_seed(cfg.seed),
        )
        .map_err(nn_other)?;
        // Zero output layer: L = L0 before any fit (Remark 4).
        let last = *net.layers().last().expect("at least one layer");
        net.params_mut()[last.weight_offset..last.bias_offset + last.fan_out].fill(0.0);
        Ok(Self {
            state_dim: s,
            action_dim: a,
            learned: Standardized::new(Network::new(net, &cfg.optimizer)?, [s, a], s),
            da_scale: vec![1.0; a],
            l0,
            cfg,
        })
    }

    /// Its settings.
    pub fn config(&self) -> &IncrementalModelConfig {
        &self.cfg
    }

    /// The network giving `L_θ` (for checkpoints and inspection).
    pub fn network(&self) -> &Mlp {
        &self.learned.trained.net
    }

    /// `L_t = L_θ(s_t, a_{t−1})` for each row `[s_t, a_{t−1}]` of `states` (`B x (S + A)`),
    /// `S x A` each.
    pub fn gain(&self, states: ArrayView2<'_, f64>) -> Result<Vec<DMatrix<f64>>, ModelError> {
        let b = states.nrows();
        check_array("states", states, b, self.state_dim + self.action_dim)?;
        let out = self.raw_outputs(states, b)?;
        Ok((0..b).map(|r| self.gain_of(&out, r)).collect())
    }

    /// The network's outputs at the rows `[s, a_{t−1}]` of `states`.
    fn raw_outputs(&self, states: ArrayView2<'_, f64>, b: usize) -> Result<Vec<f32>, ModelError> {
        let (s, prev) = states.split_at(ndarray::Axis(1), self.state_dim);
        let mut x = Vec::new();
        self.learned.inputs_into(s, prev, b, &mut x);
        let net = &self.learned.trained.net;
        let mut ws = net.workspace();
        Ok(net.forward(&x, b, &mut ws).map_err(nn_other)?.to_vec())
    }

    fn gain_of(&self, out: &[f32], r: usize) -> DMatrix<f64> {
        let (s, a) = (self.state_dim, self.action_dim);
        let n_out = self.learned.trained.net.output_dim();
        let ds_scale = &self.learned.targets.std;
        let o = &out[r * n_out..(r + 1) * n_out];
        DMatrix::from_fn(s, a, |i, j| {
            let m = match self.cfg.structure {
                GainStructure::Full => f64::from(o[i * a + j]),
                GainStructure::Diagonal if i == j => f64::from(o[i]),
                GainStructure::Diagonal => 0.0,
            };
            self.l0[i * a + j] + ds_scale[i] * m / self.da_scale[j]
        })
    }
}

/// The squared error of `M u` against the residual targets `r = Δs / σ_Δs − σ_Δs⁻¹ L0 Δa`, with
/// the scaled action changes `u = Δa / σ_Δa`.
struct IncrementalObjective {
    s: usize,
    a: usize,
    diagonal: bool,
    u: Vec<f32>,
}

impl Objective for IncrementalObjective {
    fn loss(&self, fit: &FitRows, idx: &[usize], out: &[f32], mut grad: Option<&mut [f32]>) -> f64 {
        let (s, a) = (self.s, self.a);
        let n_out = if self.diagonal { s } else { s * a };
        let n = idx.len() as f32;
        let mut total = 0.0f64;
        for (k, &row) in idx.iter().enumerate() {
            let o = &out[k * n_out..(k + 1) * n_out];
            let u = &self.u[row * a..(row + 1) * a];
            for i in 0..s {
                let pred = if self.diagonal {
                    o[i] * u[i]
                } else {
                    (0..a).map(|j| o[i * a + j] * u[j]).sum()
                };
                let e = pred - fit.y[row * s + i];
                total += f64::from(e * e);
                if let Some(g) = grad.as_deref_mut() {
                    let g = &mut g[k * n_out..(k + 1) * n_out];
                    if self.diagonal {
                        g[i] = 2.0 * e * u[i] / n;
                    } else {
                        for j in 0..a {
                            g[i * a + j] = 2.0 * e * u[j] / n;
                        }
                    }
                }
            }
        }
        total / idx.len().max(1) as f64
    }
}

impl DynamicsModel for IncrementalModel {
    /// `S + A`: the state and the previous action.
    fn state_dim(&self) -> usize {
        self.state_dim + self.action_dim
    }

    fn action_dim(&self) -> usize {
        self.action_dim
    }

    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let (s, a) = (self.state_dim, self.action_dim);
        let b = check_input(input, s + a, a)?;
        let out = self.raw_outputs(input.states, b)?;
        let mut next = input.states.to_owned();
        for r in 0..b {
            let l = self.gain_of(&out, r);
            let (u, prev) = (input.actions.row(r), input.states.slice(s![r, s..]));
            for i in 0..s {
                next[[r, i]] += (0..a).map(|j| l[(i, j)] * (u[j] - prev[j])).sum::<f64>();
            }
            next.slice_mut(s![r, s..]).assign(&u);
        }
        Ok(Prediction::deterministic(next))
    }

    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError> {
        let (s, a) = (self.state_dim, self.action_dim);
        data.validate(s + a, a)?;
        let n = data.len();
        let (states, prev) = data.states.view().split_at(ndarray::Axis(1), s);
        let da: Array2<f64> = &data.actions - &prev;
        let ds: Array2<f64> = &data.next_states.slice(s![.., ..s]) - &states;
        let informative: Vec<bool> = da
            .outer_iter()
            .map(|r| r.iter().any(|v| v.abs() > self.cfg.min_action_change))
            .collect();
        // Δs − L0 Δa: what the network's `M` has to explain.
        let mut residual = Array2::zeros((n, s));
        for row in 0..n {
            for i in 0..s {
                let prior: f64 = (0..a).map(|j| self.l0[i * a + j] * da[[row, j]]).sum();
                residual[[row, i]] = ds[[row, i]] - prior;
            }
        }
        let spec = FitSpec {
            inputs: [states, prev],
            targets: Targets::ScaledByRms {
                values: residual,
                rms_of: ds.view(),
            },
            filter: Some(RowFilter {
                keep: &informative,
                none_kept: "incremental model: no training transition with a nonzero action \
                            change (Δa = 0 carries no information about L)",
            }),
        };
        let diagonal = self.cfg.structure == GainStructure::Diagonal;
        let mut rng = rng_from_seed(cfg.seed);
        let (report, da_scale) =
            self.learned
                .fit(data, cfg, spec, &mut rng, |network, rows, rng| {
                    let da_norm = Standardizer::root_mean_square(da.view(), &rows.train);
                    let obj = IncrementalObjective {
                        s,
                        a,
                        diagonal,
                        u: standardized_inputs(&[(da.view(), &da_norm)], n),
                    };
                    Ok((network.train(&obj, rows, cfg, rng)?, da_norm.std))
                })?;
        self.da_scale = da_scale;
        Ok(report)
    }
}

/// What a fit learned besides the network and its optimizer: the input standardizations and
/// the change scales.
#[derive(serde::Serialize, serde::Deserialize)]
struct Learned {
    in_state: Standardizer,
    in_prev: Standardizer,
    ds_scale: Vec<f64>,
    da_scale: Vec<f64>,
}

/// The learned part (network, optimizer state, standardizations, change scales); the widths,
/// structure and prior are the constructor's. Loading into a model of other widths is an error
/// naming the entry, and leaves the model unchanged. A run that saves and loads its model
/// predicts and fits on exactly as one that did not.
impl Checkpointable for IncrementalModel {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        let l = &self.learned;
        l.trained.save_to(prefix, ckpt)?;
        let learned = Learned {
            in_state: l.inputs[0].clone(),
            in_prev: l.inputs[1].clone(),
            ds_scale: l.targets.std.clone(),
            da_scale: self.da_scale.clone(),
        };
        ckpt.put_json(&format!("{prefix}.learned"), &learned)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let name = format!("{prefix}.learned");
        let l: Learned = ckpt.get_json(&name)?;
        let widths = (
            l.in_state.dim(),
            l.in_prev.dim(),
            l.ds_scale.len(),
            l.da_scale.len(),
        );
        let (s, a) = (self.state_dim, self.action_dim);
        if widths != (s, a, s, a) {
            return Err(NnError::Checkpoint(format!(
                "`{name}`: widths {widths:?} (state, previous action, state change, action \
                 change), this model's are {:?}",
                (s, a, s, a)
            )));
        }
        self.learned.trained.load_from(prefix, ckpt)?;
        self.learned.inputs = [l.in_state, l.in_prev];
        self.learned.targets = Standardizer {
            mean: vec![0.0; s],
            std: l.ds_scale,
        };
        self.da_scale = l.da_scale;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array1;
    use rand::Rng as _;

    /// Trajectories of `x_{t+1} = B u_t + c` (a linear system with `A = 0`, for which the
    /// incremental form is exact with `L = B`): `episodes` of `len` steps, actions uniform in
    /// [-1, 1], with a fraction of steps repeating the previous action (Δa = 0); rows
    /// `[x, u_prev] --u--> [x', u]`.
    fn static_linear_data(
        b: &DMatrix<f64>,
        c: &[f64],
        episodes: usize,
        len: usize,
        seed: u64,
    ) -> Transitions {
        let (s, a) = b.shape();
        let mut rng = rng_from_seed(seed);
        let n = episodes * len;
        let mut t = Transitions {
            states: Array2::zeros((n, s + a)),
            actions: Array2::zeros((n, a)),
            next_states: Array2::zeros((n, s + a)),
            rewards: Array1::zeros(n),
            terminated: Array1::from_elem(n, false),
        };
        let step = |u: &[f64]| -> Vec<f64> {
            (0..s)
                .map(|i| c[i] + (0..a).map(|j| b[(i, j)] * u[j]).sum::<f64>())
                .collect()
        };
        let mut row = 0;
        for _ in 0..episodes {
            let mut prev: Vec<f64> = (0..a).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut x = step(&prev);
            for _ in 0..len {
                let u: Vec<f64> = if rng.random::<f64>() < 0.2 {
                    prev.clone()
                } else {
                    (0..a).map(|_| rng.random_range(-1.0..1.0)).collect()
                };
                let next = step(&u);
                for i in 0..s {
                    t.states[[row, i]] = x[i];
                    t.next_states[[row, i]] = next[i];
                }
                for j in 0..a {
                    t.actions[[row, j]] = u[j];
                    t.states[[row, s + j]] = prev[j];
                    t.next_states[[row, s + j]] = u[j];
                }
                row += 1;
                x = next;
                prev = u;
            }
        }
        t
    }

    fn fast(structure: GainStructure, prior: Option<Vec<f64>>) -> IncrementalModelConfig {
        IncrementalModelConfig {
            hidden: vec![32, 32],
            structure,
            prior_gain: prior,
            optimizer: OptimizerConfig::adam(3e-3),
            ..IncrementalModelConfig::default()
        }
    }

    #[test]
    fn recovers_the_input_matrix_of_a_linear_system() {
        let b = DMatrix::from_row_slice(3, 2, &[0.5, -0.2, 0.0, 1.5, -0.8, 0.3]);
        let data = static_linear_data(&b, &[0.1, -0.2, 0.3], 40, 25, 1);
        let mut m = IncrementalModel::new(3, 2, fast(GainStructure::Full, None)).unwrap();
        let fit = FitConfig {
            epochs: 60,
            batch_size: 32,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        m.fit(&data, &fit).unwrap();
        let test = static_linear_data(&b, &[0.1, -0.2, 0.3], 10, 10, 2);
        let gains = m.gain(test.states.view()).unwrap();
        let worst = gains
            .iter()
            .map(|l| (l - &b).abs().max())
            .fold(0.0, f64::max);
        eprintln!("incremental model: largest |L - B| entry over 100 held-out states {worst:.4}");
        assert!(worst < 0.03, "largest gain error {worst}");
        let e = crate::testutil::rmse(&m, &test);
        assert!(e < 0.02, "one-step rmse {e}");
    }

    #[test]
    fn a_checkpoint_restores_the_predictions_and_other_widths_are_refused() {
        let b = DMatrix::from_row_slice(3, 2, &[0.5, -0.2, 0.0, 1.5, -0.8, 0.3]);
        let data = static_linear_data(&b, &[0.1, -0.2, 0.3], 10, 20, 4);
        let fit = FitConfig {
            epochs: 2,
            batch_size: 32,
            holdout_fraction: 0.2,
            seed: 0,
            early_stop: None,
        };
        let mut m = IncrementalModel::new(3, 2, fast(GainStructure::Full, None)).unwrap();
        m.fit(&data, &fit).unwrap();
        let mut ckpt = Checkpoint::new();
        m.save_to("m", &mut ckpt).unwrap();
        let input = ModelInput::new(data.states.view(), data.actions.view());
        let predict = |m: &IncrementalModel| m.predict(&input, &mut rng_from_seed(0)).unwrap();
        // A fresh model (L = 0 before a fit) predicts otherwise until it loads the checkpoint.
        let mut back = IncrementalModel::new(3, 2, fast(GainStructure::Full, None)).unwrap();
        assert_ne!(predict(&back), predict(&m));
        back.load_from("m", &ckpt).unwrap();
        assert_eq!(predict(&back), predict(&m));
        // Both continue training alike (optimizer state restored too).
        m.fit(&data, &fit).unwrap();
        back.fit(&data, &fit).unwrap();
        assert_eq!(back.network().params(), m.network().params());
        assert_eq!(predict(&back), predict(&m));
        let mut other = IncrementalModel::new(2, 2, fast(GainStructure::Full, None)).unwrap();
        let before = other.network().params().to_vec();
        let e = other.load_from("m", &ckpt).unwrap_err().to_string();
        assert!(e.contains("m.learned"), "{e}");
        assert_eq!(other.network().params(), &before[..]);
    }

    /// A rigid-body plant whose exact input Jacobian comes from the analytic ABA derivatives:
    /// the 2R leg of the Pinocchio fixtures with torque-driven joints, torques well inside their
    /// limits. On one-step-back
    /// data whose two steps leave the same predecessor `x` (`s_t = f(x, u_prev)`,
    /// `s_{t+1} = f(x, u)`) the incremental form is exact to first order in `Δu`, so the fitted
    /// `L_θ(s_t, u_prev)` must be `∂f/∂u (x, u_prev)`: checked at held-out states.
    #[test]
    fn learns_the_input_jacobian_of_a_rigid_body_plant() {
        use nalgebra::DVector;
        use tandem_dynamics::actuators::Actuator;
        use tandem_dynamics::rigid::Model;
        use tandem_dynamics::rigid_plant::{RigidBodyPlant, RigidPlantConfig};
        use tandem_dynamics::Plant;

        let model = Model::from_urdf_file(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../tests/fixtures/pinocchio/leg2r.urdf"
        ))
        .unwrap();
        let config = RigidPlantConfig {
            control_period: 0.002,
            internal_step: 0.0005,
        };
        let mut plant = RigidBodyPlant::new(model, config).unwrap();
        for joint in ["hip", "knee"] {
            plant = plant
                .with_actuator(joint, Actuator::Torque { limit: 3.0 })
                .unwrap();
        }
        let mut rng = rng_from_seed(5);
        // (x, u_prev, u): joint angles over a band of the workspace, slow joints, torques of
        // at most 1 N m (the joints allow 3) changed by at most 0.3 N m.
        let mut sample = |n: usize| -> Vec<(DVector<f64>, DVector<f64>, DVector<f64>)> {
            (0..n)
                .map(|_| {
                    let x = DVector::from_vec(vec![
                        rng.random_range(-0.6..0.6),
                        rng.random_range(-1.6..-0.4),
                        rng.random_range(-0.5..0.5),
                        rng.random_range(-0.5..0.5),
                    ]);
                    let up = DVector::from_vec(vec![
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    ]);
                    let du = DVector::from_vec(vec![
                        rng.random_range(-0.3..0.3),
                        rng.random_range(-0.3..0.3),
                    ]);
                    let u = &up + du;
                    (x, up, u)
                })
                .collect()
        };
        let to_data = |rows: &[(DVector<f64>, DVector<f64>, DVector<f64>)]| {
            let n = rows.len();
            let mut t = Transitions {
                states: Array2::zeros((n, 6)),
                actions: Array2::zeros((n, 2)),
                next_states: Array2::zeros((n, 6)),
                rewards: Array1::zeros(n),
                terminated: Array1::from_elem(n, false),
            };
            for (r, (x, up, u)) in rows.iter().enumerate() {
                let (s, s1) = (plant.step(x, up), plant.step(x, u));
                for i in 0..4 {
                    t.states[[r, i]] = s[i];
                    t.next_states[[r, i]] = s1[i];
                }
                for j in 0..2 {
                    t.states[[r, 4 + j]] = up[j];
                    t.actions[[r, j]] = u[j];
                    t.next_states[[r, 4 + j]] = u[j];
                }
            }
            t
        };
        let train = to_data(&sample(1500));
        let test_rows = sample(50);
        let test = to_data(&test_rows);
        let cfg = IncrementalModelConfig {
            hidden: vec![64, 64],
            activation: Activation::Tanh,
            optimizer: OptimizerConfig::adam(3e-3),
            ..IncrementalModelConfig::default()
        };
        let mut m = IncrementalModel::new(4, 2, cfg).unwrap();
        let fit = FitConfig {
            epochs: 150,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        m.fit(&train, &fit).unwrap();
        let gains = m.gain(test.states.view()).unwrap();
        let mut worst = 0.0f64;
        for ((x, up, _), l) in test_rows.iter().zip(&gains) {
            let (_, b) = plant.linearize(x, up);
            // Rows of joint angles and of joint velocities differ by the control period: each
            // row block relative to its own size.
            for rows in [0..2, 2..4] {
                let bb = b.rows(rows.start, 2);
                let ll = l.rows(rows.start, 2);
                worst = worst.max((ll - bb).norm() / bb.norm());
            }
        }
        eprintln!(
            "incremental model on the leg: largest relative error of L's row blocks {worst:.4}"
        );
        assert!(
            worst < 0.1,
            "relative error of the learned input matrix {worst}"
        );
    }

    #[test]
    fn diagonal_gain_and_prior_starting_point() {
        let b = DMatrix::from_diagonal(&nalgebra::dvector![0.7, -1.2]);
        let data = static_linear_data(&b, &[0.0, 0.5], 40, 25, 3);
        let prior = vec![0.6, -1.0];
        let mut m =
            IncrementalModel::new(2, 2, fast(GainStructure::Diagonal, Some(prior))).unwrap();
        // Remark 4: before any fit, L = L0 exactly.
        let l = m.gain(data.states.view()).unwrap();
        assert_eq!(l[0], DMatrix::from_diagonal(&nalgebra::dvector![0.6, -1.0]));
        let fit = FitConfig {
            epochs: 40,
            batch_size: 32,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        let rep = m.fit(&data, &fit).unwrap();
        assert!(rep.holdout_loss.last().unwrap() < &1e-3, "{rep:?}");
        let l = m.gain(data.states.view()).unwrap();
        assert!((&l[5] - &b).abs().max() < 0.02, "{}", l[5]);
        assert_eq!((l[5][(0, 1)], l[5][(1, 0)]), (0.0, 0.0));
    }

    /// With a known `L` (the prior of an unfitted model) the model is
    /// `[x, u_prev] → [x + L (u − u_prev), u]`: the default finite-difference linearization gives
    /// `A = [[I, −L], [0, 0]]` and `B = [[L], [I]]`.
    #[test]
    fn linearization_of_a_known_gain() {
        let l0 = [0.5, -2.0, 0.25, 1.5];
        let m = IncrementalModel::new(2, 2, fast(GainStructure::Full, Some(l0.to_vec()))).unwrap();
        let z = ndarray::array![[1.0, -3.0, 0.0, 0.3], [0.2, 40.0, 7.0, -2.0]];
        let a = ndarray::array![[0.5, 0.1], [-1.0, 2.0]];
        let lin = m
            .linearize(&ModelInput::new(z.view(), a.view()), &mut rng_from_seed(0))
            .unwrap();
        let l = DMatrix::from_row_slice(2, 2, &l0);
        let mut want_a = DMatrix::zeros(4, 4);
        want_a.view_mut((0, 0), (2, 2)).fill_with_identity();
        want_a.view_mut((0, 2), (2, 2)).copy_from(&(-&l));
        let mut want_b = DMatrix::zeros(4, 2);
        want_b.view_mut((0, 0), (2, 2)).copy_from(&l);
        want_b.view_mut((2, 0), (2, 2)).fill_with_identity();
        for li in lin {
            assert!((li.a - &want_a).abs().max() < 1e-8);
            assert!((li.b - &want_b).abs().max() < 1e-8);
        }
    }

    #[test]
    fn zero_action_change_and_bad_widths() {
        let m =
            IncrementalModel::new(2, 1, fast(GainStructure::Full, Some(vec![1.0, 2.0]))).unwrap();
        let a = ndarray::array![[0.7]];
        let mut rng = rng_from_seed(0);
        // A state without its previous action is refused, naming the width.
        let s = ndarray::array![[0.3, -0.4]];
        assert!(matches!(
            m.predict(&ModelInput::new(s.view(), a.view()), &mut rng),
            Err(ModelError::Dim {
                expected: 3,
                got: 2,
                ..
            })
        ));
        // Repeating the previous action leaves the state where it is.
        let z = ndarray::array![[0.3, -0.4, 0.7]];
        let p = m
            .predict(&ModelInput::new(z.view(), a.view()), &mut rng)
            .unwrap();
        assert_eq!(p.next_states, z);
        // Data where the action never changes cannot inform L.
        let mut m = m;
        let data = Transitions {
            states: ndarray::array![[0.0, 0.0, 0.5], [0.1, 0.1, 0.5]],
            actions: ndarray::array![[0.5], [0.5]],
            next_states: ndarray::array![[0.1, 0.1, 0.5], [0.2, 0.2, 0.5]],
            rewards: ndarray::array![0.0, 0.0],
            terminated: ndarray::array![false, false],
        };
        assert!(matches!(
            m.fit(&data, &FitConfig::default()),
            Err(ModelError::Other(_))
        ));
        assert!(matches!(
            IncrementalModel::new(2, 1, fast(GainStructure::Diagonal, None)),
            Err(ModelError::Dim { .. })
        ));
        assert!(matches!(
            IncrementalModel::new(2, 1, fast(GainStructure::Full, Some(vec![1.0]))),
            Err(ModelError::Dim {
                expected: 2,
                got: 1,
                ..
            })
        ));
    }
}
