//! One type over the four agents, chosen by name, so that a training loop, a checkpoint or the
//! command line can hold "some agent".

use std::str::FromStr;

use serde::{Deserialize, Serialize};
use tandem_core::{Action, Space};
use tandem_nn::Checkpoint;

use crate::agent::{Agent, Batch, Episode, EpisodicAgent, Metrics, Mode, OffPolicyAgent};
use crate::config::{DdpgConfig, DqnConfig, OffPolicySchedule, ReinforceConfig, SacConfig};
use crate::error::{AgentError, Result};
use crate::{Ddpg, Dqn, Reinforce, Sac};

/// The algorithms this crate provides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Algo {
    /// [`Ddpg`].
    Ddpg,
    /// [`Sac`].
    Sac,
    /// [`Dqn`].
    Dqn,
    /// [`Reinforce`].
    Reinforce,
}

impl Algo {
    /// The lowercase name (`"sac"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Algo::Ddpg => "ddpg",
            Algo::Sac => "sac",
            Algo::Dqn => "dqn",
            Algo::Reinforce => "reinforce",
        }
    }
}

impl FromStr for Algo {
    type Err = AgentError;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "ddpg" => Ok(Algo::Ddpg),
            "sac" => Ok(Algo::Sac),
            "dqn" => Ok(Algo::Dqn),
            "reinforce" => Ok(Algo::Reinforce),
            _ => Err(AgentError::Config {
                field: "algo",
                value: s.to_string(),
                reason: "must be one of ddpg, sac, dqn, reinforce",
            }),
        }
    }
}

/// The configuration of one of the agents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlgoConfig {
    /// DDPG.
    Ddpg(DdpgConfig),
    /// SAC.
    Sac(SacConfig),
    /// DQN.
    Dqn(DqnConfig),
    /// REINFORCE.
    Reinforce(ReinforceConfig),
}

impl AlgoConfig {
    /// The default configuration of `algo`.
    pub fn default_for(algo: Algo) -> Self {
        match algo {
            Algo::Ddpg => AlgoConfig::Ddpg(DdpgConfig::default()),
            Algo::Sac => AlgoConfig::Sac(SacConfig::default()),
            Algo::Dqn => AlgoConfig::Dqn(DqnConfig::default()),
            Algo::Reinforce => AlgoConfig::Reinforce(ReinforceConfig::default()),
        }
    }

    /// `algo`'s configuration read from a TOML table (missing keys take the defaults, unknown
    /// keys are an error naming the key).
    pub fn from_toml(algo: Algo, table: toml::Table) -> Result<Self> {
        let v = toml::Value::Table(table);
        let bad = |e: toml::de::Error| {
            AgentError::ConfigParse(format!("{} config: {}", algo.name(), e.to_string().trim()))
        };
        Ok(match algo {
            Algo::Ddpg => AlgoConfig::Ddpg(v.try_into().map_err(bad)?),
            Algo::Sac => AlgoConfig::Sac(v.try_into().map_err(bad)?),
            Algo::Dqn => AlgoConfig::Dqn(v.try_into().map_err(bad)?),
            Algo::Reinforce => AlgoConfig::Reinforce(v.try_into().map_err(bad)?),
        })
    }

    /// Which algorithm.
    pub fn algo(&self) -> Algo {
        match self {
            AlgoConfig::Ddpg(_) => Algo::Ddpg,
            AlgoConfig::Sac(_) => Algo::Sac,
            AlgoConfig::Dqn(_) => Algo::Dqn,
            AlgoConfig::Reinforce(_) => Algo::Reinforce,
        }
    }

    /// The off-policy schedule (`None` for REINFORCE).
    pub fn schedule(&self) -> Option<OffPolicySchedule> {
        match self {
            AlgoConfig::Ddpg(c) => Some(c.schedule()),
            AlgoConfig::Sac(c) => Some(c.schedule()),
            AlgoConfig::Dqn(c) => Some(c.schedule()),
            AlgoConfig::Reinforce(_) => None,
        }
    }
}

/// One of the four agents. (Held once per run, so the size difference between variants does
/// not matter.)
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
pub enum Learner {
    /// DDPG.
    Ddpg(Ddpg),
    /// SAC.
    Sac(Sac),
    /// DQN.
    Dqn(Dqn),
    /// REINFORCE.
    Reinforce(Reinforce),
}

impl Learner {
    /// Builds the agent `config` describes for the given spaces.
    pub fn new(config: &AlgoConfig, obs: &Space, act: &Space, seed: u64) -> Result<Self> {
        Ok(match config {
            AlgoConfig::Ddpg(c) => Learner::Ddpg(Ddpg::new(c.clone(), obs, act, seed)?),
            AlgoConfig::Sac(c) => Learner::Sac(Sac::new(c.clone(), obs, act, seed)?),
            AlgoConfig::Dqn(c) => Learner::Dqn(Dqn::new(c.clone(), obs, act, seed)?),
            AlgoConfig::Reinforce(c) => {
                Learner::Reinforce(Reinforce::new(c.clone(), obs, act, seed)?)
            }
        })
    }

    /// The agent as an [`Agent`].
    pub fn agent(&mut self) -> &mut dyn Agent {
        match self {
            Learner::Ddpg(a) => a,
            Learner::Sac(a) => a,
            Learner::Dqn(a) => a,
            Learner::Reinforce(a) => a,
        }
    }

    /// The action for `obs`.
    pub fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        self.agent().act(obs, mode)
    }

    /// One off-policy update; an error for REINFORCE.
    pub fn update_batch(&mut self, batch: &Batch) -> Result<Metrics> {
        match self {
            Learner::Ddpg(a) => a.update(batch),
            Learner::Sac(a) => a.update(batch),
            Learner::Dqn(a) => a.update(batch),
            Learner::Reinforce(_) => Err(AgentError::Config {
                field: "algo",
                value: "reinforce".into(),
                reason: "REINFORCE learns from episodes, not minibatches",
            }),
        }
    }

    /// One episodic update; an error for the off-policy agents.
    pub fn update_episodes(&mut self, episodes: &[Episode]) -> Result<Metrics> {
        match self {
            Learner::Reinforce(a) => a.update(episodes),
            _ => Err(AgentError::Config {
                field: "algo",
                value: self.agent_name().into(),
                reason: "off-policy agents learn from minibatches",
            }),
        }
    }

    fn agent_name(&self) -> &'static str {
        match self {
            Learner::Ddpg(_) => "ddpg",
            Learner::Sac(_) => "sac",
            Learner::Dqn(_) => "dqn",
            Learner::Reinforce(_) => "reinforce",
        }
    }

    /// Stores the agent's full state.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        match self {
            Learner::Ddpg(a) => a.save(ckpt),
            Learner::Sac(a) => a.save(ckpt),
            Learner::Dqn(a) => a.save(ckpt),
            Learner::Reinforce(a) => a.save(ckpt),
        }
    }

    /// Restores the agent's full state; errors for another algorithm or architecture.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        match self {
            Learner::Ddpg(a) => a.load(ckpt),
            Learner::Sac(a) => a.load(ckpt),
            Learner::Dqn(a) => a.load(ckpt),
            Learner::Reinforce(a) => a.load(ckpt),
        }
    }
}

/// The chosen agent acts as itself.
impl Agent for Learner {
    fn name(&self) -> &'static str {
        self.agent_name()
    }
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        self.agent().act(obs, mode)
    }
    fn reset_episode(&mut self) {
        self.agent().reset_episode()
    }
    fn on_env_step(&mut self) {
        self.agent().on_env_step()
    }
}

/// The off-policy agents learn from minibatches; REINFORCE's `update` is an error.
impl OffPolicyAgent for Learner {
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        self.update_batch(batch)
    }
}
