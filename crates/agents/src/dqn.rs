//! DQN (Mnih et al. 2015) as stable-baselines3's `DQN`: a target network copied every
//! `target_update_interval` environment steps and a linear ε-greedy schedule, both counted in
//! environment steps from the first one (warm-up included) through [`Agent::on_env_step`]; Huber
//! loss, gradient-norm clipping and the double-DQN target (van Hasselt et al. 2016) as an option. The Q-network is an MLP over flat observations; a
//! convolutional Q-network for image observations is not written yet.

use rand::Rng as _;
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{clip_grad_norm, Checkpoint, MlpConfig, MlpWorkspace};

use crate::agent::{check_obs, Agent, Batch, Metrics, Mode, OffPolicyAgent};
use crate::common::{check_header, discrete_n, fit, obs_dim, save_header, Net, Target};
use crate::config::DqnConfig;
use crate::error::{AgentError, Result};

/// A DQN agent.
#[derive(Debug, Clone)]
pub struct Dqn {
    config: DqnConfig,
    od: usize,
    n_actions: usize,
    q: Net,
    q_t: Target,
    env_steps: u64,
    updates: u64,
    rng: Rng,
    next_ws: MlpWorkspace,
    y: Vec<f32>,
    d_q: Vec<f32>,
    best: Vec<usize>,
}

fn argmax(row: &[f32]) -> usize {
    let mut k = 0;
    for (j, v) in row.iter().enumerate() {
        if *v > row[k] {
            k = j;
        }
    }
    k
}

impl Dqn {
    /// A DQN agent for the given spaces (a discrete action space), seeded by `seed`.
    pub fn new(config: DqnConfig, obs_space: &Space, act_space: &Space, seed: u64) -> Result<Self> {
        config.validate()?;
        let od = obs_dim("dqn", obs_space)?;
        let n_actions = discrete_n("dqn", act_space)?;
        let seeds = SeedStream::new(seed);
        let mut sizes = vec![od];
        sizes.extend(&config.hidden);
        sizes.push(n_actions);
        let q = Net::new(
            MlpConfig::new(&sizes),
            config.learning_rate,
            &mut seeds.rng("dqn-init"),
        )?;
        Ok(Self {
            q_t: Target::of(&q),
            rng: seeds.rng("dqn-explore"),
            config,
            od,
            n_actions,
            q,
            env_steps: 0,
            updates: 0,
            next_ws: MlpWorkspace::default(),
            y: Vec::new(),
            d_q: Vec::new(),
            best: Vec::new(),
        })
    }

    /// The current exploration rate.
    pub fn epsilon(&self) -> f64 {
        self.config.epsilon(self.env_steps)
    }

    /// Copies the online network into the target network.
    pub fn sync_target(&mut self) {
        // Same architecture by construction (`Target::of`), so the lengths match.
        self.q_t
            .mlp
            .params_mut()
            .copy_from_slice(self.q.mlp.params());
    }

    /// The target network's flat parameters.
    pub fn target_params(&self) -> &[f32] {
        self.q_t.mlp.params()
    }

    /// The Q-network's flat parameters.
    pub fn q_params(&self) -> &[f32] {
        self.q.mlp.params()
    }

    /// Stores network, target, optimizer, counters and generator.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        save_header(
            ckpt,
            "dqn",
            &self.config,
            (self.od, self.n_actions),
            &self.rng,
        )?;
        self.q.save("q", ckpt)?;
        self.q_t.save("q_target", ckpt)?;
        ckpt.put_u64("counters", &[2], &[self.env_steps, self.updates])?;
        Ok(())
    }

    /// Restores what [`Dqn::save`] stored; errors for another algorithm or architecture.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let rng = check_header(ckpt, "dqn", (self.od, self.n_actions))?;
        self.q.load("q", ckpt)?;
        self.q_t.load("q_target", ckpt)?;
        let c = ckpt.get_u64("counters", Some(&[2]))?;
        self.env_steps = c[0];
        self.updates = c[1];
        self.rng = rng;
        Ok(())
    }
}

impl Agent for Dqn {
    fn name(&self) -> &'static str {
        "dqn"
    }

    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        check_obs(obs, self.od)?;
        if mode == Mode::Explore {
            let eps = self.epsilon();
            if self.rng.random::<f64>() < eps {
                return Ok(Action::Discrete(self.rng.random_range(0..self.n_actions)));
            }
        }
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let q = self.q.mlp.forward(&x, 1, &mut self.q.ws)?;
        Ok(Action::Discrete(argmax(q)))
    }

    /// Advances the ε schedule and copies the online network into the target every
    /// `target_update_interval` environment steps (stable-baselines3 `DQN._on_step`, τ = 1).
    fn on_env_step(&mut self) {
        self.env_steps += 1;
        if self.env_steps % self.config.target_update_interval as u64 == 0 {
            self.sync_target();
        }
    }
}

impl OffPolicyAgent for Dqn {
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        batch.check(self.od, 1)?;
        let (n, na) = (batch.len(), self.n_actions);
        let actions: Vec<usize> = batch.actions.iter().map(|a| *a as usize).collect();
        if let Some(&a) = actions.iter().find(|a| **a >= na) {
            return Err(AgentError::Dim {
                what: "dqn batch action index (must be below the number of actions)",
                expected: na,
                got: a,
            });
        }
        fit(&mut self.y, n);
        fit(&mut self.d_q, n * na);
        self.best.resize(n, 0);
        let obs = batch.obs.as_slice().expect("standard layout");
        let next_obs = batch.next_obs.as_slice().expect("standard layout");

        // Target: r + γ (1 - d) Q_t(s', argmax) with argmax from Q_t (DQN) or Q (double DQN).
        if self.config.double_dqn {
            let qn = self.q.mlp.forward(next_obs, n, &mut self.next_ws)?;
            for (b, row) in self.best.iter_mut().zip(qn.chunks_exact(na)) {
                *b = argmax(row);
            }
        }
        let qt = self.q_t.mlp.forward(next_obs, n, &mut self.q_t.ws)?;
        let gamma = self.config.gamma as f32;
        for i in 0..n {
            let row = &qt[i * na..(i + 1) * na];
            let k = if self.config.double_dqn {
                self.best[i]
            } else {
                argmax(row)
            };
            self.y[i] = batch.rewards[i] + gamma * (1.0 - batch.terminated[i]) * row[k];
        }

        // Huber (smooth L1) on Q(s, a), mean over the batch.
        let q = self.q.mlp.forward_train(obs, n, &mut self.q.ws, None)?;
        let delta = self.config.huber_delta as f32;
        let mut loss = 0.0f64;
        let mut q_mean = 0.0f64;
        self.d_q.iter_mut().for_each(|d| *d = 0.0);
        for i in 0..n {
            let v = q[i * na + actions[i]];
            q_mean += f64::from(v);
            let e = v - self.y[i];
            loss += f64::from(if e.abs() <= delta {
                0.5 * e * e
            } else {
                delta * (e.abs() - 0.5 * delta)
            });
            self.d_q[i * na + actions[i]] = e.clamp(-delta, delta) / n as f32;
        }
        loss /= n as f64;
        if !loss.is_finite() {
            return Err(AgentError::NonFinite {
                what: "dqn loss",
                value: loss,
            });
        }
        self.q
            .mlp
            .backward(&mut self.q.ws, &self.d_q, Some(&mut self.q.grads), None)?;
        clip_grad_norm(&mut self.q.grads, self.config.max_grad_norm as f32)?;
        self.q.step()?;
        self.updates += 1;
        let mut m = Metrics::default();
        m.push("loss", loss);
        m.push("q_mean", q_mean / n as f64);
        m.push("epsilon", self.epsilon());
        Ok(m)
    }
}
