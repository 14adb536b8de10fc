//! REINFORCE (Williams 1992) with returns-to-go and an optional baseline, as p2 uses it on
//! CartPole: a softmax policy over discrete actions, updated after each episode.
//!
//! Loss over the `N` steps of the episodes in one update:
//! `L = -(1/N) Σ_t log π(a_t|s_t) A_t`, with `A_t` the return-to-go `G_t`, standardized, or
//! `G_t - V(s_t)` for a learned value baseline (fitted by MSE on `G_t` in the same update).
//! Its gradient wrt the logits is `(softmax - onehot(a_t)) A_t / N`: `tandem-nn`'s
//! [`Categorical`] head (log-softmax, sampling, argmax and this gradient with weights `-A_t / N`).
//!
//! Batched acting through `&self`: [`Reinforce::act_indices`] and [`crate::BatchPolicy`].

use ndarray::ArrayView2;
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{Categorical, Checkpoint, MlpConfig};

use crate::agent::{
    act_one_row, check_obs, discrete_batch_policy, one_row, Agent, Episode, EpisodicAgent, Metrics,
    Mode,
};
use crate::common::{check_header, discrete_n, obs_dim, save_header, Net};
use crate::config::{Baseline, ReinforceConfig};
use crate::error::{AgentError, Result};

/// A REINFORCE agent.
#[derive(Debug, Clone)]
pub struct Reinforce {
    config: ReinforceConfig,
    od: usize,
    n_actions: usize,
    head: Categorical,
    policy: Net,
    value: Option<Net>,
    rng: Rng,
}

impl Reinforce {
    /// A REINFORCE agent for the given spaces (a discrete action space), seeded by `seed`.
    pub fn new(
        config: ReinforceConfig,
        obs_space: &Space,
        act_space: &Space,
        seed: u64,
    ) -> Result<Self> {
        config.validate()?;
        let od = obs_dim("reinforce", obs_space)?;
        let n_actions = discrete_n("reinforce", act_space)?;
        config
            .memory(od, n_actions)
            .check(&format!("reinforce (obs {od}, {n_actions} actions)"))?;
        let seeds = SeedStream::new(seed);
        let mut init = seeds.rng("reinforce-init");
        let mut sizes = vec![od];
        sizes.extend(&config.hidden);
        sizes.push(n_actions);
        let policy = Net::new(MlpConfig::new(&sizes), config.learning_rate, &mut init)?;
        let value = if config.baseline == Baseline::Value {
            *sizes.last_mut().expect("non-empty") = 1;
            Some(Net::new(
                MlpConfig::new(&sizes),
                config.learning_rate,
                &mut init,
            )?)
        } else {
            None
        };
        Ok(Self {
            rng: seeds.rng("reinforce-sample"),
            head: Categorical::new(n_actions),
            config,
            od,
            n_actions,
            policy,
            value,
        })
    }

    /// Action probabilities for one observation.
    pub fn probabilities(&mut self, obs: &[f64]) -> Result<Vec<f32>> {
        check_obs(obs, self.od)?;
        let mut lp = self.log_probs(one_row(obs))?;
        lp.iter_mut().for_each(|v| *v = v.exp());
        Ok(lp)
    }

    /// Log-probabilities of every action for the rows of `obs` (`B x n_actions`, row-major).
    fn log_probs(&self, obs: ArrayView2<'_, f64>) -> Result<Vec<f32>> {
        let (_, logits) = self.policy.infer_obs(obs, self.od)?;
        let mut lp = vec![0.0; logits.len()];
        self.head.log_softmax(&logits, obs.nrows(), &mut lp)?;
        Ok(lp)
    }

    /// Action indices for the rows of `obs`: sampled from the softmax with one uniform draw per
    /// row from `rng` (Explore), or the most probable (Deterministic, no draw).
    pub fn act_indices(
        &self,
        obs: ArrayView2<'_, f64>,
        mode: Mode,
        rng: &mut Rng,
    ) -> Result<Vec<usize>> {
        let n = obs.nrows();
        let lp = self.log_probs(obs)?;
        let mut k = vec![0; n];
        match mode {
            Mode::Deterministic => self.head.argmax(&lp, n, &mut k)?,
            Mode::Explore => self.head.sample(&lp, n, rng, &mut k)?,
        }
        Ok(k)
    }

    /// The policy's flat parameters.
    pub fn policy_params(&self) -> &[f32] {
        self.policy.mlp.params()
    }

    /// Stores networks, optimizer states and generator.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        save_header(
            ckpt,
            "reinforce",
            &self.config,
            (self.od, self.n_actions),
            &self.rng,
        )?;
        self.policy.save("policy", ckpt)?;
        if let Some(v) = &self.value {
            v.save("value", ckpt)?;
        }
        Ok(())
    }

    /// Restores what [`Reinforce::save`] stored; errors for another algorithm or architecture.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let rng = check_header(ckpt, "reinforce", (self.od, self.n_actions))?;
        self.policy.load("policy", ckpt)?;
        if let Some(v) = &mut self.value {
            v.load("value", ckpt)?;
        }
        self.rng = rng;
        Ok(())
    }
}

impl Agent for Reinforce {
    fn name(&self) -> &'static str {
        "reinforce"
    }

    /// The one-row case of [`Reinforce::act_indices`], drawing from the agent's own generator.
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        act_one_row(self, |s| &mut s.rng, obs, mode)
    }
}

discrete_batch_policy!(Reinforce);

impl EpisodicAgent for Reinforce {
    fn update(&mut self, episodes: &[Episode]) -> Result<Metrics> {
        let (od, na) = (self.od, self.n_actions);
        let n: usize = episodes.iter().map(Episode::len).sum();
        if n == 0 {
            return Err(AgentError::Empty("episode list"));
        }
        let mut x = Vec::with_capacity(n * od);
        let mut acts = Vec::with_capacity(n);
        let mut g = Vec::with_capacity(n);
        for e in episodes {
            if e.observations.len() != e.len() || e.actions.len() != e.len() {
                return Err(AgentError::Dim {
                    what: "episode observations/actions (one per reward)",
                    expected: e.len(),
                    got: e.observations.len().min(e.actions.len()),
                });
            }
            for o in &e.observations {
                check_obs(o, od)?;
                x.extend(o.iter().map(|v| *v as f32));
            }
            for a in &e.actions {
                match a.as_discrete() {
                    Some(k) if k < na => acts.push(k),
                    _ => {
                        return Err(AgentError::WrongActionSpace {
                            agent: "reinforce",
                            expected: "discrete actions below the number of actions",
                            got: format!("{a:?}"),
                        })
                    }
                }
            }
            g.extend(e.returns_to_go(self.config.gamma).iter().map(|v| *v as f32));
        }
        if let Some(v) = g.iter().find(|v| !v.is_finite()) {
            return Err(AgentError::NonFinite {
                what: "return",
                value: f64::from(*v),
            });
        }
        let mut adv = g.clone();
        let mut m = Metrics::default();
        match self.config.baseline {
            Baseline::None => {}
            Baseline::Normalize => {
                let mean = adv.iter().sum::<f32>() / n as f32;
                let var = adv.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / n as f32;
                let sd = var.sqrt() + 1e-8;
                adv.iter_mut().for_each(|v| *v = (*v - mean) / sd);
            }
            Baseline::Value => {
                let vnet = self.value.as_mut().expect("built with a value net");
                let v = vnet.mlp.forward_train(&x, n, &mut vnet.ws, None)?;
                let mut d = vec![0.0; n];
                let mut loss = 0.0;
                for i in 0..n {
                    adv[i] = g[i] - v[i];
                    loss += f64::from(adv[i] * adv[i]) / n as f64;
                    d[i] = -2.0 * adv[i] / n as f32;
                }
                vnet.mlp
                    .backward(&mut vnet.ws, &d, Some(&mut vnet.grads), None)?;
                vnet.step()?;
                m.push("value_loss", loss);
            }
        }
        let logits = self
            .policy
            .mlp
            .forward_train(&x, n, &mut self.policy.ws, None)?;
        let mut lp = vec![0.0; n * na];
        self.head.log_softmax(logits, n, &mut lp)?;
        let mut loss = 0.0f64;
        let mut entropy = 0.0f64;
        for i in 0..n {
            let row = &lp[i * na..(i + 1) * na];
            loss -= f64::from(row[acts[i]] * adv[i]) / n as f64;
            entropy -= row
                .iter()
                .map(|l| f64::from(l.exp()) * f64::from(*l))
                .sum::<f64>()
                / n as f64;
        }
        // L = Σ_i w_i log π(a_i|s_i) with w_i = -A_i / N.
        let w: Vec<f32> = adv.iter().map(|a| -a / n as f32).collect();
        let mut d = vec![0.0; n * na];
        self.head.backward(&lp, &acts, &w, 0.0, &mut d)?;
        self.policy
            .mlp
            .backward(&mut self.policy.ws, &d, Some(&mut self.policy.grads), None)?;
        self.policy.step()?;
        m.push("policy_loss", loss);
        m.push("entropy", entropy);
        Ok(m)
    }
}
