//! [`ResidualModel`]: a known plant plus a learned difference, `s' = f_idl(s, a) + d_θ(s, a)`
//! (p0's difference model).

use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
use tandem_dynamics::Plant;
use tandem_nn::budget::{widths, MemoryEstimate};
use tandem_nn::{Activation, Checkpoint, Checkpointable, Mlp, MlpConfig, NnError};

use crate::data::check_input;
use crate::model::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use crate::plant_model::step_rows;
use crate::train::{
    nn_other, FitRows, FitSpec, Network, Objective, OptimizerConfig, Standardized, Standardizer,
    Targets,
};

/// Settings of a [`ResidualModel`]. `Default` = p0 (Sec. IV): 3 hidden layers of 400 ReLU
/// units, linear output, dropout 0.3 on every hidden layer, AdaGrad (p0 gives no learning rate
/// and notes it matters little with AdaGrad; PyTorch's default 0.01).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ResidualModelConfig {
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Dropout probability on hidden layers during training.
    pub dropout: f32,
    /// Optimizer.
    pub optimizer: OptimizerConfig,
    /// Seed of the weight initialization.
    pub seed: u64,
}

impl ResidualModelConfig {
    /// Checks positive hidden widths, dropout in `[0, 1)` and the optimizer's ranges.
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.hidden.contains(&0) || !(0.0..1.0).contains(&self.dropout) {
            return Err(ModelError::Other(format!(
                "residual model: hidden widths {:?} must be positive and dropout {} in [0, 1)",
                self.hidden, self.dropout
            )));
        }
        self.optimizer.validate()
    }

    /// The memory of the difference network (with its optimizer state) for
    /// `state_dim`-dimensional states and `action_dim`-dimensional inputs, trained on
    /// minibatches of `batch` rows.
    pub fn memory(&self, state_dim: usize, action_dim: usize, batch: usize) -> MemoryEstimate {
        let sizes = widths(
            state_dim.saturating_add(action_dim),
            &self.hidden,
            state_dim,
        );
        self.optimizer.network_memory(
            format!("difference network {:?}", self.hidden),
            &sizes,
            batch,
        )
    }
}

impl Default for ResidualModelConfig {
    fn default() -> Self {
        Self {
            hidden: vec![400, 400, 400],
            activation: Activation::Relu,
            dropout: 0.3,
            optimizer: OptimizerConfig::adagrad(0.01),
            seed: 0,
        }
    }
}

/// p0's difference model over any [`Plant`]: the plant (the idealized model) predicts
/// `f_idl(s, a)`, a network learns the difference `d(s, a) = s'_true − f_idl(s, a)` from real
/// transitions, and the model predicts their sum.
///
/// Inputs `[s, a]` and the differences are standardized with the statistics of the latest fit's
/// training rows; the loss is the squared error of the standardized difference, summed over state
/// components and averaged over the batch. Dropout is active only in training. Each fit
/// continues from the current weights and optimizer state (p0 refits on the growing buffer);
/// a failed fit changes nothing. Before any fit the network's output is not trained: fit first.
///
/// ```
/// use nalgebra::{dvector, DVector};
/// use tandem_dynamics::Plant;
/// use tandem_models::{ResidualModel, ResidualModelConfig, DynamicsModel};
///
/// struct Integrator;
/// impl Plant for Integrator {
///     fn state_dim(&self) -> usize { 1 }
///     fn action_dim(&self) -> usize { 1 }
///     fn dt(&self) -> f64 { 0.1 }
///     fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
///         dvector![x[0] + 0.1 * u[0]]
///     }
/// }
/// let m = ResidualModel::new(Integrator, ResidualModelConfig::default()).unwrap();
/// assert_eq!((m.state_dim(), m.action_dim()), (1, 1));
/// ```
#[derive(Debug, Clone)]
pub struct ResidualModel<P: Plant> {
    plant: P,
    cfg: ResidualModelConfig,
    /// The difference network; its targets the differences.
    learned: Standardized<Network>,
    fitted: bool,
}

/// The learned part (network, optimizer state, standardizations); the plant and the settings are
/// the constructor's. Loading into a model of another architecture is an error naming the tensor.
impl<P: Plant> Checkpointable for ResidualModel<P> {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        let l = &self.learned;
        l.trained.save_to(prefix, ckpt)?;
        let norms = (&l.inputs[0], &l.inputs[1], &l.targets, self.fitted);
        ckpt.put_json(&format!("{prefix}.norms"), &norms)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let name = format!("{prefix}.norms");
        let (in_state, in_action, out_norm, fitted): (
            Standardizer,
            Standardizer,
            Standardizer,
            bool,
        ) = ckpt.get_json(&name)?;
        let widths = (in_state.dim(), in_action.dim(), out_norm.dim());
        let (s, a) = (self.plant.state_dim(), self.plant.action_dim());
        if widths != (s, a, s) {
            return Err(NnError::Checkpoint(format!(
                "`{name}`: standardizations of widths {widths:?}, this model's are {:?}",
                (s, a, s)
            )));
        }
        self.learned.trained.load_from(prefix, ckpt)?;
        (self.learned.inputs, self.learned.targets) = ([in_state, in_action], out_norm);
        self.fitted = fitted;
        Ok(())
    }
}

impl<P: Plant> ResidualModel<P> {
    /// A difference model over `plant`, initialized from `cfg.seed`.
    pub fn new(plant: P, cfg: ResidualModelConfig) -> Result<Self, ModelError> {
        let (s, a) = (plant.state_dim(), plant.action_dim());
        let mut sizes = vec![s + a];
        sizes.extend(&cfg.hidden);
        sizes.push(s);
        let net = Mlp::new(
            MlpConfig::new(&sizes)
                .hidden(cfg.activation)
                .dropout(cfg.dropout),
            &mut rng_from_seed(cfg.seed),
        )
        .map_err(nn_other)?;
        Ok(Self {
            learned: Standardized::new(Network::new(net, &cfg.optimizer)?, [s, a], s),
            plant,
            cfg,
            fitted: false,
        })
    }

    /// The known plant.
    pub fn plant(&self) -> &P {
        &self.plant
    }

    /// Its settings.
    pub fn config(&self) -> &ResidualModelConfig {
        &self.cfg
    }

    /// The difference network (for checkpoints and inspection).
    pub fn network(&self) -> &Mlp {
        &self.learned.trained.net
    }

    /// Whether a fit has succeeded; before that, `predict` returns the plant's prediction alone
    /// (an untrained difference network would only add noise).
    pub fn is_fitted(&self) -> bool {
        self.fitted
    }
}

/// Squared error of the standardized targets, summed over components and averaged over rows.
struct SquaredError;

impl Objective for SquaredError {
    fn loss(&self, fit: &FitRows, idx: &[usize], out: &[f32], mut grad: Option<&mut [f32]>) -> f64 {
        let d = fit.dout;
        let n = idx.len() as f32;
        let mut total = 0.0f64;
        for (k, &i) in idx.iter().enumerate() {
            for j in 0..d {
                let e = out[k * d + j] - fit.y[i * d + j];
                total += f64::from(e * e);
                if let Some(g) = grad.as_deref_mut() {
                    g[k * d + j] = 2.0 * e / n;
                }
            }
        }
        total / idx.len().max(1) as f64
    }
}

impl<P: Plant> DynamicsModel for ResidualModel<P> {
    fn state_dim(&self) -> usize {
        self.plant.state_dim()
    }

    fn action_dim(&self) -> usize {
        self.plant.action_dim()
    }

    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let b = check_input(input, self.state_dim(), self.action_dim())?;
        let mut next = step_rows(&self.plant, input)?;
        if self.fitted {
            let l = &self.learned;
            let mut x = Vec::new();
            l.inputs_into(input.states, input.actions, b, &mut x);
            let net = &l.trained.net;
            let mut ws = net.workspace();
            let out = net.forward(&x, b, &mut ws).map_err(nn_other)?;
            let s = self.state_dim();
            for (r, mut row) in next.outer_iter_mut().enumerate() {
                for j in 0..s {
                    row[j] += l.targets.invert(j, out[r * s + j]);
                }
            }
        }
        Ok(Prediction {
            next_states: next,
            variance: None,
            rewards: None,
            terminal_prob: None,
        })
    }

    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError> {
        data.validate(self.state_dim(), self.action_dim())?;
        let idealized = step_rows(
            &self.plant,
            &ModelInput::new(data.states.view(), data.actions.view()),
        )?;
        let spec = FitSpec {
            inputs: [data.states.view(), data.actions.view()],
            targets: Targets::ResidualOver(idealized),
            filter: None,
        };
        let mut rng = rng_from_seed(cfg.seed);
        let report = self
            .learned
            .fit(data, cfg, spec, &mut rng, |network, rows, rng| {
                network.train(&SquaredError, rows, cfg, rng)
            })?;
        self.fitted = true;
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{idealized_pendulum as idealized, pendulum_data, rmse, true_pendulum};
    use crate::PlantModel;

    /// Fits on 3750 transitions of the true pendulum of the tests' pair and compares held-out
    /// one-step errors.
    pub(super) fn residual_gain(cfg: ResidualModelConfig, fit: &FitConfig) -> (f64, f64) {
        let real = true_pendulum();
        let train = pendulum_data(&real, 3750, 11);
        let test = pendulum_data(&real, 1000, 12);
        let mut m = ResidualModel::new(idealized(), cfg).unwrap();
        m.fit(&train, fit).unwrap();
        (rmse(&PlantModel::new(idealized()), &test), rmse(&m, &test))
    }

    #[test]
    fn cuts_the_idealized_one_step_error_tenfold_on_a_pendulum_pair() {
        // A narrower network than p0's 3x400 without dropout keeps this test fast (dropout 0.3
        // on 64-unit layers costs most of the accuracy); p0's own network and dropout run in the
        // ignored test below. AdaGrad and ReLU as in p0.
        let cfg = ResidualModelConfig {
            hidden: vec![64, 64, 64],
            dropout: 0.0,
            optimizer: OptimizerConfig::adagrad(0.03),
            ..ResidualModelConfig::default()
        };
        let fit = FitConfig {
            epochs: 60,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        let (e_idl, e_res) = residual_gain(cfg, &fit);
        eprintln!(
            "pendulum pair one-step RMSE: idealized {e_idl:.4}, residual {e_res:.5}, ratio {:.1}",
            e_idl / e_res
        );
        assert!(e_res * 30.0 < e_idl, "idealized {e_idl}, residual {e_res}");
    }

    #[test]
    #[ignore = "p0's 3x400 network: about 40 s in the test profile"]
    fn p0_network_cuts_the_idealized_one_step_error_tenfold() {
        let fit = FitConfig {
            epochs: 100,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        let (e_idl, e_res) = residual_gain(ResidualModelConfig::default(), &fit);
        eprintln!(
            "p0 network: idealized {e_idl:.4}, residual {e_res:.5}, ratio {:.1}",
            e_idl / e_res
        );
        assert!(e_res * 10.0 < e_idl, "idealized {e_idl}, residual {e_res}");
    }

    /// A model saved after one fit and loaded into a fresh one predicts the same and continues
    /// (optimizer state included) to the same second fit; another architecture is refused.
    #[test]
    fn a_saved_model_resumes_fitting_exactly() {
        let real = true_pendulum();
        let (d1, d2) = (pendulum_data(&real, 300, 21), pendulum_data(&real, 300, 22));
        let cfg = ResidualModelConfig {
            hidden: vec![16, 16],
            ..Default::default()
        };
        let fit = FitConfig {
            epochs: 3,
            batch_size: 32,
            ..FitConfig::default()
        };
        let mut a = ResidualModel::new(idealized(), cfg.clone()).unwrap();
        a.fit(&d1, &fit).unwrap();
        let mut ckpt = Checkpoint::new();
        a.save_to("model", &mut ckpt).unwrap();
        let ckpt = Checkpoint::from_bytes(&ckpt.to_bytes().unwrap()).unwrap();
        let mut b = ResidualModel::new(
            idealized(),
            ResidualModelConfig {
                seed: 99,
                ..cfg.clone()
            },
        )
        .unwrap();
        b.load_from("model", &ckpt).unwrap();
        assert!(b.is_fitted());
        assert_eq!(rmse(&a, &d2), rmse(&b, &d2));
        a.fit(&d2, &fit).unwrap();
        b.fit(&d2, &fit).unwrap();
        assert_eq!(a.network().params(), b.network().params());
        let mut wider = ResidualModel::new(
            idealized(),
            ResidualModelConfig {
                hidden: vec![32, 16],
                ..cfg
            },
        )
        .unwrap();
        let e = wider.load_from("model", &ckpt).unwrap_err();
        assert!(e.to_string().contains("model.net"), "{e}");
    }

    #[test]
    fn unfitted_model_is_the_plant_and_failures_change_nothing() {
        let real = true_pendulum();
        let data = pendulum_data(&real, 200, 13);
        let mut m = ResidualModel::new(
            idealized(),
            ResidualModelConfig {
                hidden: vec![16],
                optimizer: OptimizerConfig::sgd(1e12),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(rmse(&m, &data), rmse(&PlantModel::new(idealized()), &data));
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
        assert!(!m.is_fitted());
        let mut bad = data.clone();
        bad.next_states[[3, 1]] = f64::INFINITY;
        assert_eq!(
            m.fit(&bad, &fit),
            Err(ModelError::NonFinite {
                what: "next_states".into(),
                row: 3
            })
        );
    }
}
