//! REINFORCE (Williams 1992) with returns-to-go and an optional baseline, as p2 uses it on
//! CartPole: a softmax policy over discrete actions, updated after each episode.
//!
//! Loss over the `N` steps of the episodes in one update:
//! `L = -(1/N) Σ_t log π(a_t|s_t) A_t`, with `A_t` the return-to-go `G_t`, standardized, or
//! `G_t - V(s_t)` for a learned value baseline (fitted by MSE on `G_t` in the same update).
//! Its gradient wrt the logits is `(softmax - onehot(a_t)) A_t / N`.

use rand::Rng as _;
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{Checkpoint, MlpConfig};

use crate::agent::{check_obs, Agent, Episode, EpisodicAgent, Metrics, Mode};
use crate::common::{check_header, discrete_n, obs_dim, save_header, Net};
use crate::config::{Baseline, ReinforceConfig};
use crate::error::{AgentError, Result};

/// A REINFORCE agent.
#[derive(Debug, Clone)]
pub struct Reinforce {
    config: ReinforceConfig,
    od: usize,
    n_actions: usize,
    policy: Net,
    value: Option<Net>,
    rng: Rng,
}

fn softmax_in_place(row: &mut [f32]) {
    let m = row.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let mut z = 0.0;
    for v in row.iter_mut() {
        *v = (*v - m).exp();
        z += *v;
    }
    row.iter_mut().for_each(|v| *v /= z);
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
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let mut p = self
            .policy
            .mlp
            .forward(&x, 1, &mut self.policy.ws)?
            .to_vec();
        softmax_in_place(&mut p);
        Ok(p)
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

    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        let p = self.probabilities(obs)?;
        let k = match mode {
            Mode::Deterministic => {
                let mut k = 0;
                for (j, v) in p.iter().enumerate() {
                    if *v > p[k] {
                        k = j;
                    }
                }
                k
            }
            Mode::Explore => {
                let u: f32 = self.rng.random();
                let mut c = 0.0;
                let mut k = self.n_actions - 1;
                for (j, v) in p.iter().enumerate() {
                    c += v;
                    if u < c {
                        k = j;
                        break;
                    }
                }
                k
            }
        };
        Ok(Action::Discrete(k))
    }
}

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
        let mut d = logits.to_vec();
        let mut loss = 0.0f64;
        let mut entropy = 0.0f64;
        for i in 0..n {
            let row = &mut d[i * na..(i + 1) * na];
            softmax_in_place(row);
            loss -= f64::from(row[acts[i]].max(1e-30).ln() * adv[i]) / n as f64;
            entropy -= row
                .iter()
                .map(|p| f64::from(*p) * f64::from(p.max(1e-30)).ln())
                .sum::<f64>()
                / n as f64;
            row[acts[i]] -= 1.0;
            row.iter_mut().for_each(|v| *v *= adv[i] / n as f32);
        }
        self.policy
            .mlp
            .backward(&mut self.policy.ws, &d, Some(&mut self.policy.grads), None)?;
        self.policy.step()?;
        m.push("policy_loss", loss);
        m.push("entropy", entropy);
        Ok(m)
    }
}
