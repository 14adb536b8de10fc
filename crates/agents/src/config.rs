//! Configurations of the four agents. Each `Default` holds the values of the source it cites;
//! every struct reads from TOML/JSON and rejects unknown keys.

use serde::{Deserialize, Serialize};
use tandem_nn::budget::{widths, MemoryEstimate};

#[cfg(feature = "pixels")]
use crate::conv_qnet::ConvQNetConfig;
use crate::error::{ensure, Result};
use crate::noise::NoiseConfig;

fn check_hidden(field: &'static str, h: &[usize]) -> Result<()> {
    ensure(
        !h.is_empty() && h.iter().all(|&w| (1..=16_384).contains(&w)),
        field,
        format!("{h:?}"),
        "needs at least one hidden layer, each of 1..=16384 units",
    )
}

/// Parameter-sized buffers of a network trained with Adam and tracked by a target network:
/// parameters, gradients, two moments, target.
const WITH_TARGET: u64 = 5;
/// The same without a target network.
const NO_TARGET: u64 = 4;

/// Adds the replay buffer of `schedule` for `obs_dim`/`act_dim` (as `ReplayBuffer::new`
/// allocates it) and the minibatch.
fn with_replay(est: MemoryEstimate, s: &OffPolicySchedule, od: usize, ad: usize) -> MemoryEstimate {
    est.part(
        "replay buffer",
        crate::replay::ReplayBuffer::bytes(s.buffer_size, od, ad),
    )
    .part(
        "minibatch",
        crate::replay::ReplayBuffer::bytes(s.batch_size, od, ad),
    )
}

fn check_lr(field: &'static str, lr: f64) -> Result<()> {
    ensure(lr > 0.0 && lr < 1.0, field, lr, "must lie in (0, 1)")
}

fn check_gamma(gamma: f64) -> Result<()> {
    ensure(
        (0.0..=1.0).contains(&gamma),
        "gamma",
        gamma,
        "must lie in [0, 1]",
    )
}

fn check_tau(tau: f64) -> Result<()> {
    ensure(tau > 0.0 && tau <= 1.0, "tau", tau, "must lie in (0, 1]")
}

/// The off-policy training schedule stable-baselines3 shares between its off-policy agents:
/// replay size, warm-up, minibatch size, and how often and how much to train.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OffPolicySchedule {
    /// Replay capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps with uniformly random actions before learning starts.
    pub learning_starts: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Train every `train_freq` environment steps ...
    pub train_freq: usize,
    /// ... with this many gradient steps.
    pub gradient_steps: usize,
}

impl OffPolicySchedule {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<()> {
        ensure(
            self.buffer_size >= 1,
            "buffer_size",
            self.buffer_size,
            "must be >= 1",
        )?;
        ensure(
            (1..=1_000_000).contains(&self.batch_size),
            "batch_size",
            self.batch_size,
            "must lie in 1..=1000000",
        )?;
        ensure(
            self.train_freq >= 1,
            "train_freq",
            self.train_freq,
            "must be >= 1",
        )?;
        ensure(
            self.gradient_steps >= 1,
            "gradient_steps",
            self.gradient_steps,
            "must be >= 1",
        )
    }
}

/// DDPG (Lillicrap et al. 2016) as configured in p0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DdpgConfig {
    /// Actor hidden layers.
    pub actor_hidden: Vec<usize>,
    /// Critic hidden layers.
    pub critic_hidden: Vec<usize>,
    /// Actor learning rate (Adam).
    pub actor_lr: f64,
    /// Critic learning rate (Adam).
    pub critic_lr: f64,
    /// L2 penalty on the critic's parameters, added to its gradient (Adam's coupled weight
    /// decay; Lillicrap et al. §7 use 10⁻², p0's authors' code 10⁻³). 0 turns it off.
    pub critic_weight_decay: f64,
    /// Target-network update rate τ (polyak).
    pub tau: f64,
    /// Discount γ.
    pub gamma: f64,
    /// Exploration noise.
    pub noise: NoiseConfig,
    /// Replay capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps with uniformly random actions before learning starts.
    pub learning_starts: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Train every `train_freq` environment steps ...
    pub train_freq: usize,
    /// ... with this many gradient steps.
    pub gradient_steps: usize,
}

impl Default for DdpgConfig {
    /// p0 §IV: actor and critic with two hidden layers of 400 and 300 units, learning rates
    /// 1e-4 (actor) and 1e-3 (critic), τ = 0.001, γ = 0.99, Ornstein–Uhlenbeck noise with
    /// σ = 0.12, θ = 0.15. p0 gives no replay or batch figures: replay 10^6 and minibatch 64 are
    /// Lillicrap et al.'s (2016, §7), warm-up 100 and one update per step stable-baselines3's.
    fn default() -> Self {
        Self {
            actor_hidden: vec![400, 300],
            critic_hidden: vec![400, 300],
            actor_lr: 1e-4,
            critic_lr: 1e-3,
            critic_weight_decay: 0.0,
            tau: 0.001,
            gamma: 0.99,
            noise: NoiseConfig::default(),
            buffer_size: 1_000_000,
            learning_starts: 100,
            batch_size: 64,
            train_freq: 1,
            gradient_steps: 1,
        }
    }
}

impl DdpgConfig {
    /// Checks every range.
    pub fn validate(&self) -> Result<()> {
        check_hidden("actor_hidden", &self.actor_hidden)?;
        check_hidden("critic_hidden", &self.critic_hidden)?;
        check_lr("actor_lr", self.actor_lr)?;
        check_lr("critic_lr", self.critic_lr)?;
        ensure(
            self.critic_weight_decay >= 0.0 && self.critic_weight_decay.is_finite(),
            "critic_weight_decay",
            self.critic_weight_decay,
            "must be finite and >= 0",
        )?;
        check_tau(self.tau)?;
        check_gamma(self.gamma)?;
        self.noise.validate()?;
        self.schedule().validate()
    }

    /// The memory a DDPG agent with this config needs for `obs_dim`-dimensional observations
    /// and `act_dim`-dimensional actions: actor and critic (each with gradients, Adam moments
    /// and a target copy, activations of a minibatch) and the replay buffer. Checked by
    /// [`Ddpg::new`](crate::Ddpg::new) before anything is allocated.
    pub fn memory(&self, obs_dim: usize, act_dim: usize) -> MemoryEstimate {
        let b = self.batch_size;
        let est = MemoryEstimate::new()
            .mlp(
                "actor",
                &widths(obs_dim, &self.actor_hidden, act_dim),
                WITH_TARGET,
                b,
            )
            .mlp(
                "critic",
                &widths(obs_dim.saturating_add(act_dim), &self.critic_hidden, 1),
                WITH_TARGET,
                b,
            );
        with_replay(est, &self.schedule(), obs_dim, act_dim)
    }
}

/// SAC (Haarnoja et al. 2018, with automatic entropy tuning).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    /// Hidden layers of the actor and of each critic.
    pub hidden: Vec<usize>,
    /// Learning rate of actor, critics and entropy coefficient (Adam).
    pub learning_rate: f64,
    /// Target-critic update rate τ (polyak).
    pub tau: f64,
    /// Discount γ.
    pub gamma: f64,
    /// Tune the entropy coefficient α to reach `target_entropy`; otherwise keep `init_alpha`.
    pub auto_entropy: bool,
    /// Initial (or fixed) entropy coefficient α.
    pub init_alpha: f64,
    /// Target entropy; `None` means `-action_dim` (Haarnoja et al. 2018b).
    pub target_entropy: Option<f64>,
    /// Lower clamp of the actor's log standard deviation.
    pub log_std_min: f64,
    /// Upper clamp of the actor's log standard deviation.
    pub log_std_max: f64,
    /// Replay capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps with uniformly random actions before learning starts.
    pub learning_starts: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Train every `train_freq` environment steps ...
    pub train_freq: usize,
    /// ... with this many gradient steps.
    pub gradient_steps: usize,
}

impl Default for SacConfig {
    /// stable-baselines3 2.x `SAC` defaults: two hidden layers of 256 (ReLU), learning rate 3e-4,
    /// τ = 0.005, γ = 0.99, automatic entropy tuning from α = 1 towards `-dim(A)`, log-std in
    /// [-20, 2], replay 10^6, 100 warm-up steps, minibatch 256, one update per step.
    fn default() -> Self {
        Self {
            hidden: vec![256, 256],
            learning_rate: 3e-4,
            tau: 0.005,
            gamma: 0.99,
            auto_entropy: true,
            init_alpha: 1.0,
            target_entropy: None,
            log_std_min: -20.0,
            log_std_max: 2.0,
            buffer_size: 1_000_000,
            learning_starts: 100,
            batch_size: 256,
            train_freq: 1,
            gradient_steps: 1,
        }
    }
}

impl SacConfig {
    /// Checks every range.
    pub fn validate(&self) -> Result<()> {
        check_hidden("hidden", &self.hidden)?;
        check_lr("learning_rate", self.learning_rate)?;
        check_tau(self.tau)?;
        check_gamma(self.gamma)?;
        ensure(
            self.init_alpha > 0.0 && self.init_alpha.is_finite(),
            "init_alpha",
            self.init_alpha,
            "must be > 0",
        )?;
        if let Some(t) = self.target_entropy {
            ensure(t.is_finite(), "target_entropy", t, "must be finite")?;
        }
        ensure(
            self.log_std_min < self.log_std_max,
            "log_std_min",
            self.log_std_min,
            "must be below log_std_max",
        )?;
        self.schedule().validate()
    }

    /// The memory a SAC agent with this config needs (see [`DdpgConfig::memory`]): the actor
    /// (no target), two critics with targets, the replay buffer. Checked by
    /// [`Sac::new`](crate::Sac::new) before anything is allocated.
    pub fn memory(&self, obs_dim: usize, act_dim: usize) -> MemoryEstimate {
        let b = self.batch_size;
        let critic = widths(obs_dim.saturating_add(act_dim), &self.hidden, 1);
        let est = MemoryEstimate::new()
            .mlp(
                "actor",
                &widths(obs_dim, &self.hidden, act_dim.saturating_mul(2)),
                NO_TARGET,
                b,
            )
            .mlp("critic 1", &critic, WITH_TARGET, b)
            .mlp("critic 2", &critic, WITH_TARGET, b);
        with_replay(est, &self.schedule(), obs_dim, act_dim)
    }
}

/// Which Q-network DQN uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QNetwork {
    /// An MLP over flat observations.
    Mlp,
    /// A `ConvQNet` over image observations (`DqnConfig::conv`; feature `pixels`).
    #[cfg(feature = "pixels")]
    Conv,
}

/// DQN (Mnih et al. 2015) with the double-DQN option (van Hasselt et al. 2016).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DqnConfig {
    /// The Q-network: `"mlp"` or `"conv"`.
    pub network: QNetwork,
    /// The convolutional layers when `network = "conv"` (a `[agent.conv]` table in TOML).
    #[cfg(feature = "pixels")]
    pub conv: ConvQNetConfig,
    /// Hidden layers of the Q-network: the whole MLP, or the fully connected layers after the
    /// convolutions of a conv Q-network.
    pub hidden: Vec<usize>,
    /// Learning rate (Adam) at the first environment step.
    pub learning_rate: f64,
    /// If set, the learning rate decays linearly from `learning_rate` to this value over
    /// `learning_rate_decay_steps` environment steps and stays there (stable-baselines3's
    /// `linear_schedule` / rl-baselines3-zoo's `lin_` prefix, with the run length as the
    /// horizon). `None`: constant.
    pub learning_rate_final: Option<f64>,
    /// Horizon of that decay, in environment steps (counted from step 0, warm-up included).
    pub learning_rate_decay_steps: usize,
    /// Discount γ.
    pub gamma: f64,
    /// Copy the online network into the target network every this many environment steps
    /// (stable-baselines3 counts it in `_on_step`, warm-up steps included).
    pub target_update_interval: usize,
    /// ε at the start of training.
    pub exploration_initial_eps: f64,
    /// ε after `exploration_steps` exploring steps (and from then on).
    pub exploration_final_eps: f64,
    /// Length of the linear ε schedule, in environment steps counted from the first step (warm-up
    /// included, as stable-baselines3's `exploration_fraction × total_timesteps`).
    pub exploration_steps: usize,
    /// Use the online network to choose the next action and the target to evaluate it.
    pub double_dqn: bool,
    /// Huber loss threshold (smooth L1 with δ = 1 in stable-baselines3).
    pub huber_delta: f64,
    /// Clip the gradient's global L2 norm to this value.
    pub max_grad_norm: f64,
    /// Replay capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps with uniformly random actions before learning starts.
    pub learning_starts: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Train every `train_freq` environment steps ...
    pub train_freq: usize,
    /// ... with this many gradient steps.
    pub gradient_steps: usize,
}

impl Default for DqnConfig {
    /// rl-baselines3-zoo `dqn.yml`, CartPole-v1 (50k steps): learning rate 2.3e-3, minibatch 64,
    /// replay 10^5, 1000 warm-up steps, γ = 0.99, train every 256 steps with 128 gradient steps,
    /// hidden [256, 256], ε from 1 to 0.04 over 16% of the 50k steps (8000), gradient-norm clip 10
    /// counted from step 0, a hard target copy every 10 environment steps, Adam (ε = 1e-8),
    /// gradient-norm clip 10 and Huber loss (stable-baselines3 `DQN` defaults); a constant
    /// learning rate and an MLP Q-network (`conv` holds p2's maze encoder for `network = "conv"`).
    fn default() -> Self {
        Self {
            network: QNetwork::Mlp,
            #[cfg(feature = "pixels")]
            conv: ConvQNetConfig::default(),
            hidden: vec![256, 256],
            learning_rate: 2.3e-3,
            learning_rate_final: None,
            learning_rate_decay_steps: 50_000,
            gamma: 0.99,
            target_update_interval: 10,
            exploration_initial_eps: 1.0,
            exploration_final_eps: 0.04,
            exploration_steps: 8000,
            double_dqn: false,
            huber_delta: 1.0,
            max_grad_norm: 10.0,
            buffer_size: 100_000,
            learning_starts: 1000,
            batch_size: 64,
            train_freq: 256,
            gradient_steps: 128,
        }
    }
}

impl DqnConfig {
    /// Checks every range.
    pub fn validate(&self) -> Result<()> {
        check_hidden("hidden", &self.hidden)?;
        #[cfg(feature = "pixels")]
        if self.network == QNetwork::Conv {
            self.conv.validate()?;
        }
        check_lr("learning_rate", self.learning_rate)?;
        if let Some(lr) = self.learning_rate_final {
            ensure(
                lr.is_finite() && lr >= 0.0 && lr <= self.learning_rate,
                "learning_rate_final",
                lr,
                "must lie in [0, learning_rate]",
            )?;
            ensure(
                self.learning_rate_decay_steps >= 1,
                "learning_rate_decay_steps",
                self.learning_rate_decay_steps,
                "must be >= 1",
            )?;
        }
        check_gamma(self.gamma)?;
        ensure(
            self.target_update_interval >= 1,
            "target_update_interval",
            self.target_update_interval,
            "must be >= 1",
        )?;
        for (f, v) in [
            ("exploration_initial_eps", self.exploration_initial_eps),
            ("exploration_final_eps", self.exploration_final_eps),
        ] {
            ensure((0.0..=1.0).contains(&v), f, v, "must lie in [0, 1]")?;
        }
        ensure(
            self.huber_delta > 0.0,
            "huber_delta",
            self.huber_delta,
            "must be > 0",
        )?;
        ensure(
            self.max_grad_norm > 0.0,
            "max_grad_norm",
            self.max_grad_norm,
            "must be > 0",
        )?;
        self.schedule().validate()
    }

    /// The memory a DQN agent with this config needs for `obs_dim`-dimensional observations
    /// and `n_actions` actions: the Q-network (MLP, or convolutions and fully connected layers)
    /// with gradients, Adam moments and the target copy, a minibatch's activations, and the
    /// replay buffer (one number per discrete action). Checked by [`Dqn::new`](crate::Dqn::new)
    /// before anything is allocated.
    pub fn memory(&self, obs_dim: usize, n_actions: usize) -> MemoryEstimate {
        let b = self.batch_size;
        let est = match self.network {
            QNetwork::Mlp => MemoryEstimate::new().mlp(
                "Q-network",
                &widths(obs_dim, &self.hidden, n_actions),
                WITH_TARGET,
                b,
            ),
            #[cfg(feature = "pixels")]
            QNetwork::Conv => self.conv.memory(
                MemoryEstimate::new(),
                &self.hidden,
                n_actions,
                WITH_TARGET,
                b,
            ),
        };
        with_replay(est, &self.schedule(), obs_dim, 1)
    }

    /// The learning rate after `steps` environment steps (see `learning_rate_final`).
    pub fn learning_rate_at(&self, steps: u64) -> f64 {
        match self.learning_rate_final {
            None => self.learning_rate,
            Some(end) => {
                let f = (steps as f64 / self.learning_rate_decay_steps as f64).min(1.0);
                self.learning_rate + f * (end - self.learning_rate)
            }
        }
    }

    /// ε after `steps` environment steps: linear from initial to final over `exploration_steps`.
    pub fn epsilon(&self, steps: u64) -> f64 {
        if self.exploration_steps == 0 {
            return self.exploration_final_eps;
        }
        if steps >= self.exploration_steps as u64 {
            return self.exploration_final_eps;
        }
        let f = steps as f64 / self.exploration_steps as f64;
        self.exploration_initial_eps
            + f * (self.exploration_final_eps - self.exploration_initial_eps)
    }
}

macro_rules! schedule_of {
    ($($t:ty),*) => {$(
        impl $t {
            /// The off-policy schedule part of this config.
            pub fn schedule(&self) -> OffPolicySchedule {
                OffPolicySchedule {
                    buffer_size: self.buffer_size,
                    learning_starts: self.learning_starts,
                    batch_size: self.batch_size,
                    train_freq: self.train_freq,
                    gradient_steps: self.gradient_steps,
                }
            }
        }
    )*};
}
schedule_of!(DdpgConfig, SacConfig, DqnConfig);

/// How REINFORCE reduces the variance of its gradient.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Baseline {
    /// Plain returns-to-go (Williams 1992).
    None,
    /// Returns-to-go standardized over the update's steps (mean 0, std 1).
    Normalize,
    /// A learned state value `V(s)` subtracted from the returns (same hidden layers as the
    /// policy, same learning rate).
    Value,
}

/// REINFORCE with returns-to-go (Williams 1992), as used in p2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReinforceConfig {
    /// Hidden layers of the policy (ReLU).
    pub hidden: Vec<usize>,
    /// Learning rate (Adam).
    pub learning_rate: f64,
    /// Discount γ.
    pub gamma: f64,
    /// Variance reduction.
    pub baseline: Baseline,
    /// Episodes per policy update (p2 updates after each episode).
    pub episodes_per_update: usize,
}

impl Default for ReinforceConfig {
    /// p2 §3.1.2: one hidden layer of 8 units, softmax over the two actions, one update per
    /// episode. p2 gives no learning rate or discount: Adam 1e-2, γ = 0.99 and standardized
    /// returns are PyTorch's `examples/reinforcement_learning/reinforce.py` values.
    fn default() -> Self {
        Self {
            hidden: vec![8],
            learning_rate: 1e-2,
            gamma: 0.99,
            baseline: Baseline::Normalize,
            episodes_per_update: 1,
        }
    }
}

impl ReinforceConfig {
    /// Checks every range.
    pub fn validate(&self) -> Result<()> {
        check_hidden("hidden", &self.hidden)?;
        check_lr("learning_rate", self.learning_rate)?;
        check_gamma(self.gamma)?;
        ensure(
            self.episodes_per_update >= 1,
            "episodes_per_update",
            self.episodes_per_update,
            "must be >= 1",
        )
    }

    /// The memory of a REINFORCE agent's networks (policy, and the value network with
    /// `baseline = "value"`, each with gradients and Adam moments); its episodes grow with the
    /// run and are not counted. Checked by [`Reinforce::new`](crate::Reinforce::new).
    pub fn memory(&self, obs_dim: usize, n_actions: usize) -> MemoryEstimate {
        let est = MemoryEstimate::new().mlp(
            "policy",
            &widths(obs_dim, &self.hidden, n_actions),
            NO_TARGET,
            0,
        );
        if self.baseline == Baseline::Value {
            est.mlp(
                "value network",
                &widths(obs_dim, &self.hidden, 1),
                NO_TARGET,
                0,
            )
        } else {
            est
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_out_of_range_is_named() {
        DdpgConfig::default().validate().unwrap();
        SacConfig::default().validate().unwrap();
        DqnConfig::default().validate().unwrap();
        ReinforceConfig::default().validate().unwrap();
        let c = SacConfig {
            tau: 1.5,
            ..SacConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tau") && e.contains("1.5"), "{e}");
        let c = DqnConfig {
            exploration_final_eps: -0.1,
            ..DqnConfig::default()
        };
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("exploration_final_eps"));
        let c = ReinforceConfig {
            hidden: vec![],
            ..ReinforceConfig::default()
        };
        assert!(c.validate().is_err());
    }

    #[test]
    fn epsilon_schedule_is_linear_then_flat() {
        let c = DqnConfig::default();
        assert_eq!(c.epsilon(0), 1.0);
        assert!((c.epsilon(4000) - 0.52).abs() < 1e-12);
        assert_eq!(c.epsilon(8000), 0.04);
        assert_eq!(c.epsilon(100_000), 0.04);
    }

    #[test]
    fn toml_overrides_and_unknown_keys() {
        let c: SacConfig = toml::from_str("learning_rate = 1e-3\nbuffer_size = 10\n").unwrap();
        assert_eq!(c.learning_rate, 1e-3);
        assert_eq!(c.hidden, vec![256, 256]);
        assert_eq!(c.buffer_size, 10);
        let e = toml::from_str::<SacConfig>("learnin_rate = 1e-3").unwrap_err();
        assert!(e.to_string().contains("learnin_rate"), "{e}");
        let d: DdpgConfig = toml::from_str("[noise]\nkind = \"gaussian\"\nsigma = 0.1\n").unwrap();
        assert_eq!(d.noise, NoiseConfig::Gaussian { sigma: 0.1 });
    }
}
