//! [`MlpModel`]: one MLP predicting the next-state change, the reward and the termination
//! probability jointly (p2, eq. 1).

use ndarray::{Array1, Array2};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
use tandem_nn::budget::{widths, MemoryEstimate};
use tandem_nn::{
    bce_with_logits, sigmoid, Activation, Checkpoint, Checkpointable, Mlp, MlpConfig, NnError,
};

use crate::data::check_input;
use crate::model::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use crate::train::{
    nn_other, FitRows, FitSpec, Network, Objective, OptimizerConfig, PredictScratch, Standardized,
    Standardizer, Targets,
};

/// Settings of an [`MlpModel`]. `Default` = p2 (Sec. 3.1): two hidden layers of 256 units, SGD
/// with learning rate 0.01, next state, reward and termination learned jointly. The activation is
/// not stated in p2; ReLU.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MlpModelConfig {
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Optimizer.
    pub optimizer: OptimizerConfig,
    /// Learn the reward (an output and a squared-error term).
    pub learn_reward: bool,
    /// Learn the termination probability (an output and a cross-entropy term).
    pub learn_termination: bool,
    /// Seed of the weight initialization.
    pub seed: u64,
}

impl Default for MlpModelConfig {
    fn default() -> Self {
        Self {
            hidden: vec![256, 256],
            activation: Activation::Relu,
            optimizer: OptimizerConfig::sgd(0.01),
            learn_reward: true,
            learn_termination: true,
            seed: 0,
        }
    }
}

impl MlpModelConfig {
    /// The default network predicting the next state only (no reward or termination outputs):
    /// for a task whose reward and termination are known.
    pub fn state_only() -> Self {
        Self {
            learn_reward: false,
            learn_termination: false,
            ..Self::default()
        }
    }

    /// Checks positive hidden widths and the optimizer's ranges.
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.hidden.contains(&0) {
            return Err(ModelError::Other(format!(
                "model hidden widths {:?} must be positive",
                self.hidden
            )));
        }
        self.optimizer.validate()
    }

    /// The memory of the network (with its optimizer state) for `state_dim`-dimensional states
    /// and `action_dim`-dimensional actions, trained on minibatches of `batch` rows.
    pub fn memory(&self, state_dim: usize, action_dim: usize, batch: usize) -> MemoryEstimate {
        let out = state_dim + usize::from(self.learn_reward) + usize::from(self.learn_termination);
        let sizes = widths(state_dim.saturating_add(action_dim), &self.hidden, out);
        self.optimizer
            .network_memory(format!("model {:?}", self.hidden), &sizes, batch)
    }
}

/// p2's dynamics model: an MLP from `[s, a]` to `[Δs, r, logit p(done)]`, trained with p2 eq. (1)
/// `Σ ‖s' − ŝ'‖² + (r − r̂)² − (d log p + (1 − d) log(1 − p))`.
///
/// It predicts the change `Δs = s' − s` rather than `s'` (the usual and better-conditioned target;
/// `ŝ' = s + Δŝ`). Inputs, state changes and rewards are standardized with statistics of the
/// training rows of the latest fit, so the squared errors of eq. (1) are in standard units. Each
/// fit continues from the current weights and optimizer state; a failed fit changes nothing.
///
/// ```
/// use ndarray::array;
/// use tandem_core::seeding::rng_from_seed;
/// use tandem_models::{DynamicsModel, FitConfig, MlpModel, MlpModelConfig, ModelInput,
///     OptimizerConfig, TransitionsBuilder};
///
/// // s' = s + 0.1 a, reward -s².
/// let mut b = TransitionsBuilder::new(1, 1);
/// for i in 0..200 {
///     let (s, a) = ((i % 20) as f64 / 10.0 - 1.0, (i / 20) as f64 / 5.0 - 1.0);
///     b.push([s], &[a], &[s + 0.1 * a], -s * s, false).unwrap();
/// }
/// let cfg = MlpModelConfig { hidden: vec![32, 32], optimizer: OptimizerConfig::adam(3e-3),
///     ..MlpModelConfig::default() };
/// let mut m = MlpModel::new(1, 1, cfg).unwrap();
/// let fit = FitConfig { epochs: 150, batch_size: 32, ..FitConfig::default() };
/// m.fit(&b.build(), &fit).unwrap();
/// let (s, a) = (array![[0.5]], array![[1.0]]);
/// let p = m.predict(&ModelInput::new(s.view(), a.view()), &mut rng_from_seed(0)).unwrap();
/// assert!((p.next_states[[0, 0]] - 0.6).abs() < 0.02);
/// assert!((p.rewards.unwrap()[0] + 0.25).abs() < 0.05);
/// assert!(p.terminal_prob.unwrap()[0] < 0.1);
/// ```
#[derive(Debug, Clone)]
pub struct MlpModel {
    cfg: MlpModelConfig,
    state_dim: usize,
    action_dim: usize,
    /// The network; its targets `[Δs, r]`.
    learned: Standardized<Network>,
    /// `predict`'s reused input and workspace buffers.
    scratch: PredictScratch,
}

impl MlpModel {
    /// A model for the given widths, initialized from `cfg.seed`.
    pub fn new(
        state_dim: usize,
        action_dim: usize,
        cfg: MlpModelConfig,
    ) -> Result<Self, ModelError> {
        cfg.validate()?;
        if state_dim == 0 {
            return Err(ModelError::Dim {
                what: "state_dim (must be positive)".into(),
                expected: 1,
                got: 0,
            });
        }
        let out = state_dim + usize::from(cfg.learn_reward) + usize::from(cfg.learn_termination);
        let mut sizes = vec![state_dim + action_dim];
        sizes.extend(&cfg.hidden);
        sizes.push(out);
        let net = Mlp::new(
            MlpConfig::new(&sizes).hidden(cfg.activation),
            &mut rng_from_seed(cfg.seed),
        )
        .map_err(nn_other)?;
        Ok(Self {
            state_dim,
            action_dim,
            learned: Standardized::new(
                Network::new(net, &cfg.optimizer)?,
                [state_dim, action_dim],
                state_dim + 1,
            ),
            scratch: PredictScratch::default(),
            cfg,
        })
    }

    /// Its settings.
    pub fn config(&self) -> &MlpModelConfig {
        &self.cfg
    }

    /// The network (for checkpoints and inspection).
    pub fn network(&self) -> &Mlp {
        &self.learned.trained.net
    }
}

/// The learned part (network, optimizer state, standardizations); the widths and settings are
/// the constructor's. Loading into a model of other widths is an error naming the entry, and
/// leaves the model unchanged.
impl Checkpointable for MlpModel {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        let l = &self.learned;
        l.trained.save_to(prefix, ckpt)?;
        let norms = (&l.inputs[0], &l.inputs[1], &l.targets);
        ckpt.put_json(&format!("{prefix}.norms"), &norms)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let name = format!("{prefix}.norms");
        let (in_state, in_action, out_norm): (Standardizer, Standardizer, Standardizer) =
            ckpt.get_json(&name)?;
        let widths = (in_state.dim(), in_action.dim(), out_norm.dim());
        let (s, a) = (self.state_dim, self.action_dim);
        if widths != (s, a, s + 1) {
            return Err(NnError::Checkpoint(format!(
                "`{name}`: standardizations of widths {widths:?}, this model's are {:?}",
                (s, a, s + 1)
            )));
        }
        self.learned.trained.load_from(prefix, ckpt)?;
        (self.learned.inputs, self.learned.targets) = ([in_state, in_action], out_norm);
        Ok(())
    }
}

/// p2 eq. (1) over the standardized `[Δs, r]` targets (the reward's term when learned) and the
/// termination flags.
struct MlpObjective {
    done: Vec<f32>,
    s: usize,
    reward: bool,
    term: bool,
}

impl Objective for MlpObjective {
    fn loss(&self, fit: &FitRows, idx: &[usize], out: &[f32], mut grad: Option<&mut [f32]>) -> f64 {
        let s = self.s;
        let dout = s + usize::from(self.reward) + usize::from(self.term);
        let n = idx.len() as f32;
        let mut total = 0.0f64;
        for (k, &i) in idx.iter().enumerate() {
            let o = &out[k * dout..(k + 1) * dout];
            let y = fit.targets(i);
            let regress = s + usize::from(self.reward);
            for j in 0..regress {
                let e = o[j] - y[j];
                total += f64::from(e * e);
                if let Some(d) = grad.as_deref_mut() {
                    d[k * dout + j] = 2.0 * e / n;
                }
            }
        }
        if self.term && !idx.is_empty() {
            // Termination logit: tandem-nn's stable binary cross-entropy, summed over the rows
            // like the squared errors (its mean times the row count; its gradient is already
            // divided by the row count).
            let z: Vec<f32> = (0..idx.len()).map(|k| out[k * dout + dout - 1]).collect();
            let t: Vec<f32> = idx.iter().map(|&i| self.done[i]).collect();
            let mut g = vec![0.0; idx.len()];
            let bce_grad = grad.is_some().then_some(g.as_mut_slice());
            match bce_with_logits(&z, &t, bce_grad) {
                Ok(l) => total += f64::from(l) * idx.len() as f64,
                // A non-finite logit: report a non-finite loss, as the sum above would.
                Err(_) => total = f64::NAN,
            }
            if let Some(d) = grad {
                for (k, gk) in g.iter().enumerate() {
                    d[k * dout + dout - 1] = *gk;
                }
            }
        }
        total / idx.len().max(1) as f64
    }
}

impl MlpModel {
    /// `predict` on given buffers: standardized inputs into `x`, the forward pass in `ws`.
    fn predict_with(
        &self,
        input: &ModelInput<'_>,
        b: usize,
        x: &mut Vec<f32>,
        ws: &mut tandem_nn::MlpWorkspace,
    ) -> Result<Prediction, ModelError> {
        let l = &self.learned;
        l.inputs_into(input.states, input.actions, b, x);
        let out = l.trained.net.forward(x, b, ws).map_err(nn_other)?;
        let s = self.state_dim;
        let dout = l.trained.net.output_dim();
        let mut next = Array2::zeros((b, s));
        let mut rewards = self.cfg.learn_reward.then(|| Array1::zeros(b));
        let mut probs = self.cfg.learn_termination.then(|| Array1::zeros(b));
        for r in 0..b {
            let o = &out[r * dout..(r + 1) * dout];
            for j in 0..s {
                next[[r, j]] = input.states[[r, j]] + l.targets.invert(j, o[j]);
            }
            if let Some(rw) = rewards.as_mut() {
                rw[r] = l.targets.invert(s, o[s]);
            }
            if let Some(p) = probs.as_mut() {
                p[r] = f64::from(sigmoid(o[dout - 1]));
            }
        }
        Ok(Prediction {
            next_states: next,
            variance: None,
            rewards,
            terminal_prob: probs,
        })
    }
}

impl DynamicsModel for MlpModel {
    fn state_dim(&self) -> usize {
        self.state_dim
    }

    fn action_dim(&self) -> usize {
        self.action_dim
    }

    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let b = check_input(input, self.state_dim, self.action_dim)?;
        self.scratch
            .with(|x, ws| self.predict_with(input, b, x, ws))
    }

    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError> {
        data.validate(self.state_dim, self.action_dim)?;
        // The reward column is standardized and kept even when its loss term is off.
        let spec = FitSpec {
            inputs: [data.states.view(), data.actions.view()],
            targets: Targets::StateChange { reward: true },
            filter: None,
        };
        let obj = MlpObjective {
            done: data
                .terminated
                .iter()
                .map(|&d| f32::from(u8::from(d)))
                .collect(),
            s: self.state_dim,
            reward: self.cfg.learn_reward,
            term: self.cfg.learn_termination,
        };
        let mut rng = rng_from_seed(cfg.seed);
        self.learned
            .fit(data, cfg, spec, &mut rng, |network, rows, rng| {
                network.train(&obj, rows, cfg, rng)
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{
        cartpole_data, idealized_pendulum, pendulum_data, rmse, true_pendulum, zero_change_rmse,
    };

    fn small(seed: u64) -> MlpModelConfig {
        MlpModelConfig {
            hidden: vec![64, 64],
            optimizer: OptimizerConfig::adam(3e-3),
            seed,
            ..MlpModelConfig::default()
        }
    }

    /// With early stopping, the fit ends `patience` epochs after its last improvement and keeps
    /// that epoch's weights: it predicts exactly as a plain fit of that many epochs, whose
    /// losses it repeats. Bad settings and a missing holdout are errors.
    #[test]
    fn early_stopping_keeps_the_last_improving_epoch() {
        let plant = true_pendulum();
        let (train, test) = (pendulum_data(&plant, 300, 1), pendulum_data(&plant, 100, 2));
        let patience = 3;
        let (stopping, plain) = crate::testutil::early_stopping(patience, 400);
        let mut m = MlpModel::new(2, 1, small(0)).unwrap();
        let rep = m.fit(&train, &stopping).unwrap();
        let n = rep.holdout_loss.len();
        assert!(n < 400, "never stopped");
        let kept = n - patience;
        let mut p = MlpModel::new(2, 1, small(0)).unwrap();
        let plain_rep = p.fit(&train, &plain(kept)).unwrap();
        assert_eq!(plain_rep.holdout_loss[..], rep.holdout_loss[..kept]);
        assert_eq!(rmse(&m, &test), rmse(&p, &test));
        // The epochs after the kept one did not improve it by 5 %.
        let best = rep.holdout_loss[kept - 1];
        assert!(rep.holdout_loss[kept..]
            .iter()
            .all(|h| (best - h) / best.abs() <= 0.05));

        for (stop, holdout) in [(0, 0.3), (3, 0.0)] {
            let bad = FitConfig {
                holdout_fraction: holdout,
                early_stop: Some(crate::EarlyStop {
                    patience: stop,
                    ..Default::default()
                }),
                ..stopping.clone()
            };
            let e = m.fit(&train, &bad).unwrap_err().to_string();
            assert!(e.contains("early stopping"), "{e}");
        }
    }

    #[test]
    fn one_step_error_on_the_pendulum() {
        let plant = true_pendulum();
        let train = pendulum_data(&plant, 3000, 1);
        let test = pendulum_data(&plant, 500, 2);
        let mut m = MlpModel::new(2, 1, small(0)).unwrap();
        let fit = FitConfig {
            epochs: 60,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        let rep = m.fit(&train, &fit).unwrap();
        assert_eq!(rep.train_loss.len(), 60);
        assert_eq!(rep.holdout_loss.len(), 60);
        let (e, e0) = (rmse(&m, &test), zero_change_rmse(&test));
        eprintln!("pendulum MlpModel one-step RMSE {e:.5} (no-change predictor {e0:.4})");
        assert!(e < 0.03 * e0, "rmse {e}, no-change {e0}");
    }

    #[test]
    fn one_step_error_reward_and_termination_on_cartpole() {
        let train = cartpole_data(3000, 3);
        let test = cartpole_data(500, 4);
        let mut m = MlpModel::new(4, 1, small(1)).unwrap();
        let fit = FitConfig {
            epochs: 60,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 1,
            early_stop: None,
        };
        m.fit(&train, &fit).unwrap();
        let (e, e0) = (rmse(&m, &test), zero_change_rmse(&test));
        let p = m
            .predict(
                &ModelInput::new(test.states.view(), test.actions.view()),
                &mut rng_from_seed(0),
            )
            .unwrap();
        let probs = p.terminal_prob.unwrap();
        let correct = probs
            .iter()
            .zip(&test.terminated)
            .filter(|(p, d)| (**p > 0.5) == **d)
            .count();
        let acc = correct as f64 / test.len() as f64;
        let base = test.terminated.iter().filter(|d| !**d).count() as f64 / test.len() as f64;
        let rerr = p
            .rewards
            .unwrap()
            .iter()
            .zip(&test.rewards)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!("CartPole MlpModel one-step RMSE {e:.5} (no-change {e0:.4}), termination accuracy {acc:.3} (majority {base:.3}), max reward error {rerr:.4}");
        assert!(e < 0.03 * e0, "rmse {e}, no-change {e0}");
        assert!(
            acc > 0.95 && acc > base,
            "termination accuracy {acc}, majority {base}"
        );
        assert!(rerr < 0.05, "reward error {rerr}");
    }

    #[test]
    fn a_checkpoint_restores_the_predictions_and_other_widths_are_refused() {
        let data = cartpole_data(300, 8);
        let fit = FitConfig {
            epochs: 2,
            batch_size: 32,
            ..FitConfig::default()
        };
        let mut m = MlpModel::new(4, 1, small(2)).unwrap();
        m.fit(&data, &fit).unwrap();
        let mut ckpt = Checkpoint::new();
        m.save_to("m", &mut ckpt).unwrap();
        let input = ModelInput::new(data.states.view(), data.actions.view());
        let predict = |m: &MlpModel| m.predict(&input, &mut rng_from_seed(0)).unwrap();
        // A fresh model of another seed predicts otherwise until it loads the checkpoint.
        let mut back = MlpModel::new(4, 1, small(3)).unwrap();
        assert_ne!(predict(&back), predict(&m));
        back.load_from("m", &ckpt).unwrap();
        assert_eq!(predict(&back), predict(&m));
        // Both continue training alike (optimizer state restored too).
        m.fit(&data, &fit).unwrap();
        back.fit(&data, &fit).unwrap();
        assert_eq!(back.network().params(), m.network().params());
        let mut other = MlpModel::new(3, 1, small(2)).unwrap();
        let before = other.network().params().to_vec();
        let e = other.load_from("m", &ckpt).unwrap_err().to_string();
        assert!(e.contains("m.norms"), "{e}");
        assert_eq!(other.network().params(), &before[..]);
    }

    #[test]
    fn same_seed_same_fit_bit_for_bit() {
        let plant = idealized_pendulum();
        let data = pendulum_data(&plant, 300, 5);
        let fit = FitConfig {
            epochs: 3,
            batch_size: 32,
            holdout_fraction: 0.2,
            seed: 9,
            early_stop: None,
        };
        let run = |seed: u64, fit_seed: u64| {
            let mut m = MlpModel::new(2, 1, small(seed)).unwrap();
            let r = m
                .fit(
                    &data,
                    &FitConfig {
                        seed: fit_seed,
                        ..fit.clone()
                    },
                )
                .unwrap();
            (m.network().params().to_vec(), r)
        };
        let (a, ra) = run(7, 9);
        let (b, rb) = run(7, 9);
        assert_eq!(a, b);
        assert_eq!(ra, rb);
        assert_ne!(a, run(8, 9).0);
        assert_ne!(a, run(7, 10).0);
    }

    #[test]
    fn divergence_and_bad_data_leave_the_model_unchanged() {
        let plant = idealized_pendulum();
        let data = pendulum_data(&plant, 200, 6);
        let cfg = MlpModelConfig {
            optimizer: OptimizerConfig::sgd(1e12),
            ..small(0)
        };
        let mut m = MlpModel::new(2, 1, cfg).unwrap();
        let before = m.network().params().to_vec();
        let fit = FitConfig {
            epochs: 20,
            batch_size: 32,
            ..FitConfig::default()
        };
        assert!(matches!(
            m.fit(&data, &fit),
            Err(ModelError::Diverged { .. })
        ));
        assert_eq!(m.network().params(), &before[..]);

        let mut bad = data.clone();
        bad.actions[[17, 0]] = f64::NAN;
        assert_eq!(
            m.fit(&bad, &fit),
            Err(ModelError::NonFinite {
                what: "actions".into(),
                row: 17
            })
        );
        assert_eq!(m.fit(&Transitions::default(), &fit), Err(ModelError::Empty));
        let wrong = pendulum_data(&plant, 10, 7);
        let mut m3 = MlpModel::new(3, 1, small(0)).unwrap();
        assert!(matches!(m3.fit(&wrong, &fit), Err(ModelError::Dim { .. })));
        assert_eq!(m.network().params(), &before[..]);
    }
}
