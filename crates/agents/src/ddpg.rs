//! DDPG (Lillicrap et al. 2016) as p0 uses it: a deterministic tanh actor, a Q critic on the
//! concatenated observation and action, target networks following by polyak averaging, and
//! Ornstein–Uhlenbeck (or Gaussian) exploration noise.
//!
//! One update (stable-baselines3's order): critic regression on
//! `y = r + γ (1 - done) Q'(s', μ'(s'))` (MSE), then the actor ascends `Q(s, μ(s))` through the
//! freshly updated critic (`dQ/da` from the critic's input gradient), then both targets move by τ.
//! Actions are `[-1, 1]` inside the networks and environment units outside.

use rand::Rng as _;
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{Activation, Checkpoint, Init, MlpConfig};

use crate::agent::{check_obs, Agent, Batch, Metrics, Mode, OffPolicyAgent};
use crate::common::{
    check_header, concat_rows, fit, obs_dim, save_header, ActionScale, Net, Target,
};
use crate::config::DdpgConfig;
use crate::error::{AgentError, Result};
use crate::noise::Noise;

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
        let critic = Net::new(critic_cfg, config.critic_lr, &mut init)?;
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

    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        check_obs(obs, self.od)?;
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let mut a = self.actor.mlp.forward(&x, 1, &mut self.actor.ws)?.to_vec();
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
