//! DDPG (Lillicrap et al. 2016) as p0 uses it: a deterministic tanh actor, a Q critic on the
//! concatenated observation and action, target networks following by polyak averaging, and
//! Ornstein–Uhlenbeck (or Gaussian) exploration noise.
//!
//! One update (stable-baselines3's order): critic regression on
//! `y = r + γ (1 - done) Q'(s', μ'(s'))` (MSE), then the actor ascends `Q(s, μ(s))` through the
//! freshly updated critic (`dQ/da` from the critic's input gradient), then both targets move by τ.
//! Actions are `[-1, 1]` inside the networks and environment units outside.
//!
//! Exploration noise is the agent's: [`NoiseConfig`] in [`DdpgConfig`], changed between phases
//! with [`Ddpg::set_noise`] (p0 lowers σ after pre-training). [`Agent::act`] adds the stateful
//! noise (an Ornstein–Uhlenbeck process restarted by [`Agent::reset_episode`]). The batched
//! `&self` path ([`BatchPolicy::act_batch`] with [`Mode::Explore`]) keeps no per-episode state: it
//! adds independent Gaussian noise per row and component with the process's stationary standard
//! deviation ([`NoiseConfig::stationary_std`]), drawn from the caller's generator, then clips to
//! the action box as `act` does.

use ndarray::{Array1, Array2, ArrayView2};
use rand::Rng as _;
use rand_distr::{Distribution, StandardNormal};
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{Activation, AdamConfig, Checkpoint, Init, MlpConfig};

use crate::agent::{
    check_action_rows, check_obs, obs_rows, Agent, Batch, BatchPolicy, Critic, Metrics, Mode,
    OffPolicyAgent,
};
use crate::common::{
    check_header, concat_rows, fit, obs_dim, save_header, ActionScale, Net, Target,
};
use crate::config::DdpgConfig;
use crate::error::{AgentError, Result};
use crate::noise::{Noise, NoiseConfig};

/// A DDPG agent.
#[derive(Debug, Clone)]
pub struct Ddpg {
    config: DdpgConfig,
    od: usize,
    scale: ActionScale,
    actor: Net,
    critic: Net,
    actor_t: Target,
    critic_t: Target,
    noise: Noise,
    rng: Rng,
    s: Scratch,
}

#[derive(Debug, Clone, Default)]
struct Scratch {
    a_norm: Vec<f32>,
    x: Vec<f32>,
    next_x: Vec<f32>,
    y: Vec<f32>,
    d_q: Vec<f32>,
    d_x: Vec<f32>,
    d_a: Vec<f32>,
    mu: Vec<f32>,
}

impl Ddpg {
    /// A DDPG agent for the given spaces (a bounded box action space), seeded by `seed`.
    pub fn new(
        config: DdpgConfig,
        obs_space: &Space,
        act_space: &Space,
        seed: u64,
    ) -> Result<Self> {
        config.validate()?;
        let od = obs_dim("ddpg", obs_space)?;
        let scale = ActionScale::new("ddpg", act_space)?;
        let ad = scale.dim();
        config
            .memory(od, ad)
            .check(&format!("ddpg (obs {od}, act {ad})"))?;
        let seeds = SeedStream::new(seed);
        let mut init = seeds.rng("ddpg-init");
        let mut sizes = vec![od];
        sizes.extend(&config.actor_hidden);
        sizes.push(ad);
        // Lillicrap et al. §7: final layers drawn from U(-3e-3, 3e-3).
        let actor_cfg = MlpConfig::new(&sizes)
            .output(Activation::Tanh)
            .output_init(Init::Uniform { bound: 3e-3 });
        let mut sizes = vec![od + ad];
        sizes.extend(&config.critic_hidden);
        sizes.push(1);
        let critic_cfg = MlpConfig::new(&sizes).output_init(Init::Uniform { bound: 3e-3 });
        let actor = Net::new(actor_cfg, config.actor_lr, &mut init)?;
        let critic_adam = AdamConfig {
            weight_decay: config.critic_weight_decay as f32,
            ..AdamConfig::with_lr(config.critic_lr as f32)
        };
        let critic = Net::with_adam(critic_cfg, critic_adam, &mut init)?;
        Ok(Self {
            actor_t: Target::of(&actor),
            critic_t: Target::of(&critic),
            noise: Noise::new(config.noise, ad)?,
            rng: seeds.rng("ddpg-act"),
            config,
            od,
            scale,
            actor,
            critic,
            s: Scratch::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DdpgConfig {
        &self.config
    }

    /// The actor's flat parameters.
    pub fn actor_params(&self) -> &[f32] {
        self.actor.mlp.params()
    }

    /// The critic's flat parameters.
    pub fn critic_params(&self) -> &[f32] {
        self.critic.mlp.params()
    }

    /// Replaces the exploration noise (p0 changes σ between its phases); the process restarts
    /// at zero. Errors on an out-of-range configuration, leaving the noise unchanged.
    pub fn set_noise(&mut self, noise: NoiseConfig) -> Result<()> {
        self.noise = Noise::new(noise, self.scale.dim())?;
        self.config.noise = noise;
        Ok(())
    }

    /// The exploration noise in use.
    pub fn noise(&self) -> NoiseConfig {
        self.noise.config()
    }

    /// `Q(s, a)` for row-major `f32` observations and actions in `[-1, 1]`.
    fn q_rows(&self, x: &[f32], a: &[f32], n: usize) -> Result<Array1<f64>> {
        let (od, ad) = (self.od, self.scale.dim());
        let mut xa = vec![0.0; n * (od + ad)];
        concat_rows(x, od, a, ad, &mut xa);
        let q = self.critic.infer(&xa, n)?;
        Ok(q.iter().map(|v| f64::from(*v)).collect())
    }

    /// Stores networks, optimizer states, noise state and generator.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        save_header(
            ckpt,
            "ddpg",
            &self.config,
            (self.od, self.scale.dim()),
            &self.rng,
        )?;
        self.actor.save("actor", ckpt)?;
        self.critic.save("critic", ckpt)?;
        self.actor_t.save("actor_target", ckpt)?;
        self.critic_t.save("critic_target", ckpt)?;
        ckpt.put_json("noise", &self.noise)?;
        Ok(())
    }

    /// Restores what [`Ddpg::save`] stored; errors for another algorithm or architecture, leaving
    /// `self` usable but possibly partly restored.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let rng = check_header(ckpt, "ddpg", (self.od, self.scale.dim()))?;
        self.actor.load("actor", ckpt)?;
        self.critic.load("critic", ckpt)?;
        self.actor_t.load("actor_target", ckpt)?;
        self.critic_t.load("critic_target", ckpt)?;
        self.noise = ckpt.get_json("noise")?;
        self.rng = rng;
        Ok(())
    }
}

impl Agent for Ddpg {
    fn name(&self) -> &'static str {
        "ddpg"
    }

    /// The batch path's deterministic action of one row plus the stateful noise (`Explore`).
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        check_obs(obs, self.od)?;
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let mut a = self.actor.infer(&x, 1)?;
        if mode == Mode::Explore {
            let n = self.noise.sample(&mut self.rng);
            for (ai, ni) in a.iter_mut().zip(n) {
                *ai = (*ai + *ni as f32).clamp(-1.0, 1.0);
            }
        }
        Ok(Action::Continuous(self.scale.to_env(&a)))
    }

    fn reset_episode(&mut self) {
        self.noise.reset();
    }
}

impl BatchPolicy for Ddpg {
    fn obs_dim(&self) -> usize {
        self.od
    }

    fn action_width(&self) -> usize {
        self.scale.dim()
    }

    /// `μ(s)`; Explore adds independent `N(0, stationary_std²)` noise per row and component
    /// (drawn from `rng` row by row) and clips to the box.
    fn act_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        mode: Mode,
        rng: &mut Rng,
    ) -> Result<Array2<f64>> {
        let (_, mut a) = self.actor.infer_obs(obs, self.od)?;
        if mode == Mode::Explore {
            let sd = self.noise.config().stationary_std();
            for ai in a.iter_mut() {
                let e: f64 = StandardNormal.sample(rng);
                *ai = (*ai + (sd * e) as f32).clamp(-1.0, 1.0);
            }
        }
        Ok(self.scale.to_env_rows(&a))
    }
}

impl Critic for Ddpg {
    fn q_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array1<f64>> {
        let x = obs_rows(obs, self.od)?;
        check_action_rows(actions, obs.nrows(), self.scale.dim())?;
        self.q_rows(&x, &self.scale.normalize_view(actions), obs.nrows())
    }

    /// `V(s) = Q(s, μ(s))`, the deterministic policy's value (`mode` and `rng` unused).
    fn v_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        _mode: Mode,
        _rng: &mut Rng,
    ) -> Result<Array1<f64>> {
        let (x, mu) = self.actor.infer_obs(obs, self.od)?;
        self.q_rows(&x, &mu, obs.nrows())
    }
}

impl OffPolicyAgent for Ddpg {
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        let (od, ad) = (self.od, self.scale.dim());
        batch.check(od, ad)?;
        let n = batch.len();
        let s = &mut self.s;
        let obs = batch.obs.as_slice().expect("standard layout");
        let next_obs = batch.next_obs.as_slice().expect("standard layout");
        fit(&mut s.a_norm, n * ad);
        fit(&mut s.x, n * (od + ad));
        fit(&mut s.next_x, n * (od + ad));
        fit(&mut s.y, n);
        fit(&mut s.d_q, n);
        fit(&mut s.d_x, n * (od + ad));
        fit(&mut s.d_a, n * ad);
        fit(&mut s.mu, n * ad);
        self.scale.normalize_rows(
            batch.actions.as_slice().expect("standard layout"),
            &mut s.a_norm,
        );

        // Critic target y = r + γ (1 - d) Q'(s', μ'(s')).
        let next_a = self
            .actor_t
            .mlp
            .forward(next_obs, n, &mut self.actor_t.ws)?;
        concat_rows(next_obs, od, next_a, ad, &mut s.next_x);
        let q_next = self
            .critic_t
            .mlp
            .forward(&s.next_x, n, &mut self.critic_t.ws)?;
        let gamma = self.config.gamma as f32;
        for i in 0..n {
            s.y[i] = batch.rewards[i] + gamma * (1.0 - batch.terminated[i]) * q_next[i];
        }

        // Critic: MSE.
        concat_rows(obs, od, &s.a_norm, ad, &mut s.x);
        let q = self
            .critic
            .mlp
            .forward_train(&s.x, n, &mut self.critic.ws, None)?;
        let mut critic_loss = 0.0f64;
        for i in 0..n {
            let e = q[i] - s.y[i];
            critic_loss += f64::from(e * e);
            s.d_q[i] = 2.0 * e / n as f32;
        }
        critic_loss /= n as f64;
        if !critic_loss.is_finite() {
            return Err(AgentError::NonFinite {
                what: "ddpg critic loss",
                value: critic_loss,
            });
        }
        self.critic.mlp.backward(
            &mut self.critic.ws,
            &s.d_q,
            Some(&mut self.critic.grads),
            None,
        )?;
        self.critic.step()?;

        // Actor: maximize Q(s, μ(s)) through the updated critic.
        let mu = self
            .actor
            .mlp
            .forward_train(obs, n, &mut self.actor.ws, None)?;
        s.mu.copy_from_slice(mu);
        concat_rows(obs, od, &s.mu, ad, &mut s.x);
        let q_pi = self
            .critic
            .mlp
            .forward_train(&s.x, n, &mut self.critic.ws, None)?;
        let actor_loss = -q_pi.iter().map(|v| f64::from(*v)).sum::<f64>() / n as f64;
        s.d_q.iter_mut().for_each(|d| *d = -1.0 / n as f32);
        self.critic
            .mlp
            .backward(&mut self.critic.ws, &s.d_q, None, Some(&mut s.d_x))?;
        for (da, dx) in s.d_a.chunks_exact_mut(ad).zip(s.d_x.chunks_exact(od + ad)) {
            da.copy_from_slice(&dx[od..]);
        }
        self.actor.mlp.backward(
            &mut self.actor.ws,
            &s.d_a,
            Some(&mut self.actor.grads),
            None,
        )?;
        self.actor.step()?;

        self.critic_t.polyak(&self.critic, self.config.tau)?;
        self.actor_t.polyak(&self.actor, self.config.tau)?;
        let mut m = Metrics::default();
        m.push("critic_loss", critic_loss);
        m.push("actor_loss", actor_loss);
        Ok(m)
    }
}

/// A uniformly random action in a box or discrete space (warm-up steps).
pub fn random_action(space: &Space, rng: &mut Rng) -> Action {
    match space {
        Space::Box { low, high, .. } => Action::Continuous(
            low.iter()
                .zip(high)
                .map(|(l, h)| {
                    if l.is_finite() && h.is_finite() {
                        rng.random_range(*l..=*h)
                    } else {
                        0.0
                    }
                })
                .collect(),
        ),
        Space::Discrete { n } => Action::Discrete(rng.random_range(0..*n)),
    }
}
