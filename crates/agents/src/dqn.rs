//! DQN (Mnih et al. 2015) as stable-baselines3's `DQN`: a target network copied every
//! `target_update_interval` environment steps and a linear ε-greedy schedule, both counted in
//! environment steps from the first one (warm-up included) through [`Agent::on_env_step`]; Huber
//! loss, gradient-norm clipping, the double-DQN target (van Hasselt et al. 2016) and a linearly
//! decaying learning rate (SB3's `linear_schedule`) as options.
//!
//! The Q-network is an MLP over flat observations (`network = "mlp"`) or, with the feature
//! `pixels`, for image observations such as p2's 16×16 RGB maze, a `ConvQNet` (`network =
//! "conv"`, layers in `DqnConfig::conv`).
//! Both are trained by the same loss code: the agent computes `∂L/∂Q` of the Huber loss on
//! `Q(s, a)` (`tandem-nn`'s [`huber`]) and the network back-propagates it.
//!
//! Batched acting through `&self` ([`crate::BatchPolicy`], indices in [`Dqn::act_indices`]) is
//! ε-greedy with the agent's current ε and the caller's generator; [`Dqn::q_table`] gives
//! `Q(s, ·)` and [`Critic`] `Q(s, a)` and `V(s) = max_a Q(s, a)`.

use ndarray::{Array1, Array2, ArrayView2};
use rand::Rng as _;
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{clip_grad_norm, huber, Checkpoint, MlpConfig, MlpWorkspace, Optimizer};
#[cfg(feature = "pixels")]
use tandem_nn::{Adam, AdamConfig, Checkpointable};

use crate::agent::{
    act_one_row, check_action_rows, check_obs, discrete_batch_policy, infer_rows, obs_rows, Agent,
    Batch, Critic, Metrics, Mode, OffPolicyAgent,
};
use crate::common::{check_header, discrete_n, fit, obs_dim, save_header, Net, Target};
use crate::config::{DqnConfig, QNetwork};
#[cfg(feature = "pixels")]
use crate::conv_qnet::ConvQNet;
use crate::error::{AgentError, Result};

/// The online and target Q-networks with what training them needs.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
enum QNets {
    Mlp {
        q: Net,
        q_t: Target,
        next_ws: MlpWorkspace,
    },
    #[cfg(feature = "pixels")]
    Conv {
        q: ConvQNet,
        q_t: ConvQNet,
        opt: Adam,
        grads: Vec<f32>,
    },
}

impl QNets {
    /// Online-network Q-values of `n` observations through `&self`.
    fn infer(&self, x: &[f32], n: usize) -> Result<Vec<f32>> {
        match self {
            QNets::Mlp { q, .. } => q.infer(x, n),
            #[cfg(feature = "pixels")]
            QNets::Conv { q, .. } => q.infer(x, n),
        }
    }

    /// Online-network Q-values of the next observations, into a buffer that leaves the online
    /// network's training workspace alone.
    fn online_next(&mut self, x: &[f32], n: usize) -> Result<&[f32]> {
        match self {
            QNets::Mlp { q, next_ws, .. } => Ok(q.mlp.forward(x, n, next_ws)?),
            #[cfg(feature = "pixels")]
            QNets::Conv { q, .. } => q.forward(x, n),
        }
    }

    fn target(&mut self, x: &[f32], n: usize) -> Result<&[f32]> {
        match self {
            QNets::Mlp { q_t, .. } => Ok(q_t.mlp.forward(x, n, &mut q_t.ws)?),
            #[cfg(feature = "pixels")]
            QNets::Conv { q_t, .. } => q_t.forward(x, n),
        }
    }

    fn forward_train(&mut self, x: &[f32], n: usize) -> Result<&[f32]> {
        match self {
            QNets::Mlp { q, .. } => Ok(q.mlp.forward_train(x, n, &mut q.ws, None)?),
            #[cfg(feature = "pixels")]
            QNets::Conv { q, .. } => q.forward_train(x, n),
        }
    }

    /// Back-propagates `d_q = ∂L/∂Q` of the last `forward_train`, clips the gradient's norm and
    /// takes one Adam step with learning rate `lr`.
    fn backward_step(&mut self, d_q: &[f32], max_norm: f32, lr: f32) -> Result<()> {
        match self {
            QNets::Mlp { q, .. } => {
                q.mlp.backward(&mut q.ws, d_q, Some(&mut q.grads), None)?;
                clip_grad_norm(&mut q.grads, max_norm)?;
                q.opt.set_lr(lr);
                q.step()
            }
            #[cfg(feature = "pixels")]
            QNets::Conv { q, opt, grads, .. } => {
                q.backward(d_q, grads)?;
                clip_grad_norm(grads, max_norm)?;
                opt.set_lr(lr);
                let mut p = q.params().to_vec();
                opt.step(&mut p, grads)?;
                q.set_params(&p)
            }
        }
    }

    fn q_params(&self) -> &[f32] {
        match self {
            QNets::Mlp { q, .. } => q.mlp.params(),
            #[cfg(feature = "pixels")]
            QNets::Conv { q, .. } => q.params(),
        }
    }

    fn target_params(&self) -> &[f32] {
        match self {
            QNets::Mlp { q_t, .. } => q_t.mlp.params(),
            #[cfg(feature = "pixels")]
            QNets::Conv { q_t, .. } => q_t.params(),
        }
    }

    fn sync_target(&mut self) {
        // Same architecture by construction, so the lengths match and the values are finite.
        match self {
            QNets::Mlp { q, q_t, .. } => q_t.mlp.params_mut().copy_from_slice(q.mlp.params()),
            #[cfg(feature = "pixels")]
            QNets::Conv { q, q_t, .. } => q_t
                .set_params(q.params())
                .expect("online and target conv Q-networks share one architecture"),
        }
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        match self {
            QNets::Mlp { q, q_t, .. } => {
                q.save("q", ckpt)?;
                q_t.save("q_target", ckpt)
            }
            #[cfg(feature = "pixels")]
            QNets::Conv { q, q_t, opt, .. } => {
                q.save("qconv", ckpt)?;
                opt.save_to("qconv_opt", ckpt)?;
                q_t.save("qconv_target", ckpt)
            }
        }
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        match self {
            QNets::Mlp { q, q_t, .. } => {
                q.load("q", ckpt)?;
                q_t.load("q_target", ckpt)
            }
            #[cfg(feature = "pixels")]
            QNets::Conv { q, q_t, opt, .. } => {
                let missing = |_| {
                    AgentError::Checkpoint(
                        "has no conv Q-network (`qconv.*`): written by an MLP DQN?".into(),
                    )
                };
                ckpt.shape("qconv_opt.m").map_err(missing)?;
                // Load into copies first so a failure leaves the agent unchanged.
                let (mut q2, mut t2, mut o2) = (q.clone(), q_t.clone(), opt.clone());
                q2.load("qconv", ckpt)?;
                t2.load("qconv_target", ckpt)?;
                o2.load_from("qconv_opt", ckpt).map_err(|e| {
                    AgentError::Checkpoint(format!(
                        "does not match this agent's conv Q-network optimizer: {e}"
                    ))
                })?;
                (*q, *q_t, *opt) = (q2, t2, o2);
                Ok(())
            }
        }
    }
}

/// A DQN agent.
#[derive(Debug, Clone)]
pub struct Dqn {
    config: DqnConfig,
    od: usize,
    n_actions: usize,
    nets: QNets,
    env_steps: u64,
    updates: u64,
    rng: Rng,
    y: Vec<f32>,
    q_sa: Vec<f32>,
    d_sa: Vec<f32>,
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
    /// A DQN agent for the given spaces (a discrete action space), seeded by `seed`. With
    /// `network = "conv"` the observation space must be a `Box` image of shape `conv.image`.
    pub fn new(config: DqnConfig, obs_space: &Space, act_space: &Space, seed: u64) -> Result<Self> {
        config.validate()?;
        let od = obs_dim("dqn", obs_space)?;
        let n_actions = discrete_n("dqn", act_space)?;
        config
            .memory(od, n_actions)
            .check(&format!("dqn (obs {od}, {n_actions} actions)"))?;
        let seeds = SeedStream::new(seed);
        let mut init = seeds.rng("dqn-init");
        let nets = match config.network {
            QNetwork::Mlp => {
                let mut sizes = vec![od];
                sizes.extend(&config.hidden);
                sizes.push(n_actions);
                let q = Net::new(MlpConfig::new(&sizes), config.learning_rate, &mut init)?;
                QNets::Mlp {
                    q_t: Target::of(&q),
                    q,
                    next_ws: MlpWorkspace::default(),
                }
            }
            #[cfg(feature = "pixels")]
            QNetwork::Conv => {
                config.conv.check_space(obs_space)?;
                let q = ConvQNet::new(config.conv.clone(), &config.hidden, n_actions, &mut init)?;
                let opt = Adam::new(
                    AdamConfig::with_lr(config.learning_rate as f32),
                    q.num_params(),
                )?;
                #[cfg(feature = "pixels")]
                QNets::Conv {
                    q_t: q.clone(),
                    grads: vec![0.0; q.num_params()],
                    q,
                    opt,
                }
            }
        };
        Ok(Self {
            nets,
            rng: seeds.rng("dqn-explore"),
            config,
            od,
            n_actions,
            env_steps: 0,
            updates: 0,
            y: Vec::new(),
            q_sa: Vec::new(),
            d_sa: Vec::new(),
            d_q: Vec::new(),
            best: Vec::new(),
        })
    }

    /// The current exploration rate.
    pub fn epsilon(&self) -> f64 {
        self.config.epsilon(self.env_steps)
    }

    /// The learning rate the next update uses.
    pub fn learning_rate(&self) -> f64 {
        self.config.learning_rate_at(self.env_steps)
    }

    /// Copies the online network into the target network.
    pub fn sync_target(&mut self) {
        self.nets.sync_target();
    }

    /// The target network's flat parameters.
    pub fn target_params(&self) -> &[f32] {
        self.nets.target_params()
    }

    /// The Q-network's flat parameters.
    pub fn q_params(&self) -> &[f32] {
        self.nets.q_params()
    }

    /// The greedy Q-values of one observation.
    pub fn q_values(&mut self, obs: &[f64]) -> Result<Vec<f32>> {
        check_obs(obs, self.od)?;
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        self.nets.infer(&x, 1)
    }

    /// `Q(s, ·)` of the online network for the rows of `obs`: `B x n_actions`.
    pub fn q_table(&self, obs: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
        let (_, q) = infer_rows(obs, self.od, |x, n| self.nets.infer(x, n))?;
        Ok(Array2::from_shape_fn(
            (obs.nrows(), self.n_actions),
            |(i, j)| f64::from(q[i * self.n_actions + j]),
        ))
    }

    /// ε-greedy action indices for the rows of `obs` with the current ε, drawing from `rng` row
    /// by row (a uniform number, then the random index when it falls below ε) as [`Agent::act`]
    /// does; Deterministic is greedy and draws nothing. Only the greedy rows go through the
    /// network.
    pub fn act_indices(
        &self,
        obs: ArrayView2<'_, f64>,
        mode: Mode,
        rng: &mut Rng,
    ) -> Result<Vec<usize>> {
        let x = obs_rows(obs, self.od)?;
        let (od, na) = (self.od, self.n_actions);
        let mut out: Vec<Option<usize>> = vec![None; obs.nrows()];
        if mode == Mode::Explore {
            let eps = self.epsilon();
            for o in out.iter_mut() {
                if rng.random::<f64>() < eps {
                    *o = Some(rng.random_range(0..na));
                }
            }
        }
        let greedy: Vec<usize> = (0..out.len()).filter(|i| out[*i].is_none()).collect();
        if !greedy.is_empty() {
            let xg: Vec<f32> = greedy
                .iter()
                .flat_map(|i| x[i * od..(i + 1) * od].iter().copied())
                .collect();
            let q = self.nets.infer(&xg, greedy.len())?;
            for (row, i) in q.chunks_exact(na).zip(&greedy) {
                out[*i] = Some(argmax(row));
            }
        }
        Ok(out
            .into_iter()
            .map(|k| k.expect("every row chosen"))
            .collect())
    }

    /// Stores networks, optimizer, counters and generator.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        save_header(
            ckpt,
            "dqn",
            &self.config,
            (self.od, self.n_actions),
            &self.rng,
        )?;
        self.nets.save(ckpt)?;
        ckpt.put_u64("counters", &[2], &[self.env_steps, self.updates])?;
        Ok(())
    }

    /// Restores what [`Dqn::save`] stored; errors for another algorithm or architecture.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let rng = check_header(ckpt, "dqn", (self.od, self.n_actions))?;
        self.nets.load(ckpt)?;
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

    /// The one-row case of [`Dqn::act_indices`], drawing from the agent's own generator.
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        act_one_row(self, |s| &mut s.rng, obs, mode)
    }

    /// Advances the ε schedule and copies the online network into the target every
    /// `target_update_interval` environment steps (stable-baselines3 `DQN._on_step`, τ = 1).
    fn on_env_step(&mut self) {
        self.env_steps += 1;
        if self
            .env_steps
            .is_multiple_of(self.config.target_update_interval as u64)
        {
            self.sync_target();
        }
    }
}

discrete_batch_policy!(Dqn);

impl Critic for Dqn {
    /// `Q(s, a)` for actions given as indices (one column).
    fn q_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array1<f64>> {
        check_action_rows(actions, obs.nrows(), 1)?;
        let na = self.n_actions;
        let idx = actions
            .column(0)
            .iter()
            .map(|a| {
                if *a >= 0.0 && *a < na as f64 && a.fract() == 0.0 {
                    Ok(*a as usize)
                } else {
                    Err(AgentError::WrongActionSpace {
                        agent: "dqn",
                        expected: "action indices 0 <= k < n_actions",
                        got: a.to_string(),
                    })
                }
            })
            .collect::<Result<Vec<_>>>()?;
        let q = self.q_table(obs)?;
        Ok(idx.iter().enumerate().map(|(i, k)| q[[i, *k]]).collect())
    }

    /// `V(s) = max_a Q(s, a)`, the greedy policy's value (`mode` and `rng` unused).
    fn v_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        _mode: Mode,
        _rng: &mut Rng,
    ) -> Result<Array1<f64>> {
        let q = self.q_table(obs)?;
        Ok(q.rows()
            .into_iter()
            .map(|r| r.iter().copied().fold(f64::NEG_INFINITY, f64::max))
            .collect())
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
        fit(&mut self.q_sa, n);
        fit(&mut self.d_sa, n);
        fit(&mut self.d_q, n * na);
        self.best.resize(n, 0);
        let obs = batch.obs.as_slice().expect("standard layout");
        let next_obs = batch.next_obs.as_slice().expect("standard layout");

        // Target: r + γ (1 - d) Q_t(s', argmax) with argmax from Q_t (DQN) or Q (double DQN).
        if self.config.double_dqn {
            let qn = self.nets.online_next(next_obs, n)?;
            for (b, row) in self.best.iter_mut().zip(qn.chunks_exact(na)) {
                *b = argmax(row);
            }
        }
        let qt = self.nets.target(next_obs, n)?;
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

        // Huber (smooth L1) on Q(s, a), mean over the batch; its gradient scattered into the
        // taken actions' outputs. A non-finite loss is nn's error.
        let q = self.nets.forward_train(obs, n)?;
        for i in 0..n {
            self.q_sa[i] = q[i * na + actions[i]];
        }
        let q_mean = self.q_sa.iter().map(|v| f64::from(*v)).sum::<f64>();
        let delta = self.config.huber_delta as f32;
        let loss = f64::from(huber(&self.q_sa, &self.y, delta, Some(&mut self.d_sa))?);
        self.d_q.iter_mut().for_each(|d| *d = 0.0);
        for i in 0..n {
            self.d_q[i * na + actions[i]] = self.d_sa[i];
        }
        let lr = self.learning_rate();
        self.nets
            .backward_step(&self.d_q, self.config.max_grad_norm as f32, lr as f32)?;
        self.updates += 1;
        let mut m = Metrics::default();
        m.push("loss", loss);
        m.push("q_mean", q_mean / n as f64);
        m.push("epsilon", self.epsilon());
        m.push("learning_rate", lr);
        Ok(m)
    }
}
