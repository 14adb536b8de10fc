//! The algorithms of tandem, each generic over the parts it composes (a plant or environment, a
//! learned model, a planner, an agent), with its settings type and the papers' settings as named
//! presets: the model-based ones, and model-free training (the baseline they are measured
//! against, and `tandem train`'s loop).
//!
//! | module | algorithm | loop |
//! |---|---|---|
//! | [`mbpo`] | Janner et al., MBPO | SAC on the real system; every 250 steps an ensemble refit and branched rollouts of length `k` into `D_model`; `G` updates per step at real ratio 0.05; the SAC baseline on the same loop |
//! | [`dyna`] | MBPO-style Dyna (shared) | branched rollouts of a learned model from real states, acted by the agent's own batched policy, into the loop's second buffer |
//! | [`m_demorl`] | Mishra et al., M-DeMoRL (p3) | the MBPO loop with `D_MPC` filled by DMD-MPC plans (CEM elites, SAC's policy as shift, `−V` terminal cost) through the ensemble's elites |
//! | [`incremental_dyna`] | Cong Li, deep incremental model (p1) | the MBPO loop with one-step rollouts through the incremental model `s + L_θ(s, a_prev) Δa`, the task's reward |
//! | [`difference_models`] | Rastogi et al., difference models (p0) | pre-train on the idealized plant; collect true samples, fit a residual model, retrain on plant + residual |
//! | [`imagined_episodes`] | Manglik and Tripathi, model-augmented REINFORCE (p2) | N real episodes, then real episodes alternated with episodes imagined by a learned `(s', r, done)` model |
//! | [`imagined_pixels`] | the same, DQN from pixels (p2) | the same loop for an off-policy agent on p2's maze, with the pixel model; the pixel model's F1 experiment |
//! | [`gps`] | Chebotar et al., PILQR (and GPS; p4) | one TVLG controller per condition, improved from its own samples by LQR-FLM, PI² or PILQR |
//! | [`mdgps`] | Montgomery and Levine, MDGPS (p4 §IV) | a neural global policy regressed onto the local controllers, each updated under a KL bound to the linearized global policy |
//! | [`pets`] | Chua et al., PETS | one random episode, then CEM-MPC through a probabilistic ensemble of the observation change with particles (TS-∞ or TS-1), scored by the task's reward over observations; the ensemble refitted on all data after each episode |
//! | [`model_free`] | any of the four agents alone (`tandem train`) | DDPG, SAC or DQN on the shared off-policy loop, or REINFORCE on whole episodes; periodic deterministic evaluation |
//! | [`manipulation`] | p4's tasks | the gripper pusher's, the door's and the reacher's conditions and costs on MuJoCo for [`gps`] and [`mdgps`]; DDPG on the reacher, measured on the same test targets |
//!
//! The loops that act in a real system take a [`Problem`]: the task the real system and its
//! models share, and a [`MakeEnv`] that builds a fresh real system (p0's [`difference_models`]
//! adds the idealized plant, `SimToReal`).
//!
//! A long run saves itself in a [`Checkpoints`] store and polls it for stop requests: the
//! `tandem` program keeps checkpoints as files, [`InMemory`] keeps them in memory, [`Ephemeral`]
//! keeps none. A resumed run gives exactly the numbers of an uninterrupted one.
//!
//! Dependencies: the workspace crates it composes, among them `tandem-robots` (the papers'
//! problems: p0's pendulum and Leo, p3's leg, p2's maze, p4's scenes) and, with their feature
//! `pixels`, `tandem-models` and `tandem-agents` (p2's pixel model and conv Q-network for
//! `imagined_pixels`); `nalgebra` and `ndarray` (the controllers'
//! matrices and batched states), `rand` (seeded sampling), `serde` (settings, records and
//! checkpoint payloads), `thiserror` (the error type), `toml` (p2's maze reads the DQN preset it
//! shares with `tandem train`).

#![warn(missing_docs)]

pub mod difference_models;
pub mod driver;
pub mod dyna;
pub mod gps;
pub mod imagined_episodes;
pub mod imagined_pixels;
pub mod incremental_dyna;
pub mod m_demorl;
pub mod manipulation;
pub mod mbpo;
pub mod mdgps;
pub mod model_free;
pub mod pets;
pub mod state_features;

use tandem_agents::AgentError;
use tandem_envs::EnvError;
use tandem_models::ModelError;
use tandem_nn::{Checkpoint, NnError};
use tandem_planners::PlanError;

/// Why an algorithm stopped.
#[derive(Debug, thiserror::Error)]
pub enum AlgoError {
    /// The agent failed (bad configuration, non-finite loss, ...).
    #[error("agent: {0}")]
    Agent(#[from] AgentError),
    /// An environment failed.
    #[error("environment: {0}")]
    Env(#[from] EnvError),
    /// A model failed (to fit, or to predict).
    #[error("model: {0}")]
    Model(#[from] ModelError),
    /// A planner failed (bad settings, a non-finite cost).
    #[error("planner: {0}")]
    Planner(#[from] PlanError),
    /// A configuration value out of range.
    #[error("configuration: {0}")]
    Config(String),
    /// A network failed while computing (a non-finite loss or gradient, a bad setting).
    #[error("network: {0}")]
    Network(NnError),
    /// A checkpoint could not be written or read, or belongs to another run.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// [`Checkpoints::stop_requested`] said to stop; the last checkpoint saved resumes the run.
    #[error("stopped on request")]
    Stopped,
}

/// The bounds `(low, high)` of a continuous (box) action space; for a discrete one, the error
/// "`needs` a continuous (box) action space".
pub fn box_bounds(space: &tandem_core::Space, needs: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    match space {
        tandem_core::Space::Box { low, high, .. } => Ok((low.clone(), high.clone())),
        tandem_core::Space::Discrete { .. } => Err(AlgoError::Config(format!(
            "{needs} a continuous (box) action space"
        ))),
    }
}

/// What a checkpoint read can fail with (unreadable, a tensor missing, a tensor of the wrong
/// shape or type) is a checkpoint error; what only computing can fail with (non-finite numbers, a
/// bad setting, candle) is [`AlgoError::Network`].
impl From<NnError> for AlgoError {
    fn from(e: NnError) -> Self {
        match e {
            NnError::Checkpoint(what) => AlgoError::Checkpoint(what),
            NnError::MissingTensor(_) | NnError::ShapeMismatch { .. } => {
                AlgoError::Checkpoint(e.to_string())
            }
            NnError::NonFinite { .. }
            | NnError::InvalidConfig(_)
            | NnError::NoTape(_)
            | NnError::Candle(_) => AlgoError::Network(e),
        }
    }
}

/// A constructor of a real (or true) system with its episode limit, carrying its settings.
pub type MakeEnv =
    Box<dyn Fn() -> std::result::Result<Box<dyn tandem_envs::Env>, EnvError> + Send + Sync>;

/// What an algorithm learns to act in: the task (start, observation, control, reward,
/// termination and episode length, shared by the real system and any model of it) and a way
/// to build a fresh real system.
pub struct Problem<T, F = MakeEnv> {
    /// The task.
    pub task: T,
    /// Builds a fresh real system with its episode limit.
    pub env: F,
}

/// Result of the algorithms.
pub type Result<T> = std::result::Result<T, AlgoError>;

/// Where a long pipeline keeps its checkpoints, and how it learns that it should stop: the
/// `tandem` program keeps them as files in the run directory and stops on SIGINT/SIGTERM;
/// [`Ephemeral`] keeps nothing and never stops. A pipeline saves at each of its checkpoint
/// points (e.g. every evaluation), resumes from what [`Checkpoints::load`] returns, and polls
/// [`Checkpoints::stop_requested`] between steps; equal runs save equal bytes, and a resumed run
/// gives exactly the numbers of an uninterrupted one.
pub trait Checkpoints {
    /// The latest checkpoint saved under `key`, if any.
    fn load(&mut self, key: &str) -> Result<Option<Checkpoint>>;
    /// Saves `ckpt` under `key`, replacing the previous one only once it is complete.
    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> Result<()>;
    /// Whether to stop now; the pipeline then returns [`AlgoError::Stopped`].
    fn stop_requested(&self) -> bool {
        false
    }
}

/// Refuses a checkpoint saved by another run: `saved` and `this` are (method name, seed).
pub fn ensure_same_run(saved: (&str, u64), this: (&str, u64)) -> Result<()> {
    if saved == this {
        return Ok(());
    }
    Err(AlgoError::Checkpoint(format!(
        "the checkpoint is {} seed {}'s, not {} seed {}'s",
        saved.0, saved.1, this.0, this.1
    )))
}

/// Keeps checkpoints in memory, as the bytes of their file format (so they go through the same
/// serialization and checks as files on disk), and stops when its [`InMemory::stop_flag`] is
/// raised: a run embedded in another program, or a test that stops a run where it likes (raise
/// the flag from the run's event callback) and resumes it from the same store.
///
/// ```
/// use tandem_algos::{Checkpoints, InMemory};
/// use tandem_nn::Checkpoint;
///
/// let mut store = InMemory::default();
/// let mut ckpt = Checkpoint::new();
/// ckpt.put_json("progress", &3u32).unwrap();
/// store.save("sac", &ckpt).unwrap();
/// assert_eq!(store.load("sac").unwrap().unwrap().get_json::<u32>("progress").unwrap(), 3);
/// assert!(store.load("mbpo").unwrap().is_none());
/// let stop = store.stop_flag();
/// stop.set(true);
/// assert!(store.stop_requested());
/// ```
#[derive(Debug, Default)]
pub struct InMemory {
    files: std::collections::BTreeMap<String, Vec<u8>>,
    stop: std::rc::Rc<std::cell::Cell<bool>>,
    saves: usize,
}

impl InMemory {
    /// The flag [`Checkpoints::stop_requested`] reads; set it to `true` to stop the run at its
    /// next poll, back to `false` before resuming.
    pub fn stop_flag(&self) -> std::rc::Rc<std::cell::Cell<bool>> {
        self.stop.clone()
    }

    /// How many checkpoints were saved.
    pub fn saves(&self) -> usize {
        self.saves
    }
}

impl Checkpoints for InMemory {
    fn load(&mut self, key: &str) -> Result<Option<Checkpoint>> {
        Ok(self
            .files
            .get(key)
            .map(|b| Checkpoint::from_bytes(b))
            .transpose()?)
    }
    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> Result<()> {
        self.files.insert(key.to_string(), ckpt.to_bytes()?);
        self.saves += 1;
        Ok(())
    }
    fn stop_requested(&self) -> bool {
        self.stop.get()
    }
}

/// Keeps no checkpoints and never stops: a run from start to end in one go.
#[derive(Debug, Clone, Copy, Default)]
pub struct Ephemeral;

impl Checkpoints for Ephemeral {
    fn load(&mut self, _key: &str) -> Result<Option<Checkpoint>> {
        Ok(None)
    }
    fn save(&mut self, _key: &str, _ckpt: &Checkpoint) -> Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn network_failures_are_not_reported_as_checkpoint_failures() {
        let mut store = InMemory::default();
        store
            .files
            .insert("run".into(), b"not safetensors".to_vec());
        let e = store.load("run").unwrap_err();
        assert!(matches!(e, AlgoError::Checkpoint(_)), "{e}");
        let missing = AlgoError::from(NnError::MissingTensor("actor.w0".into()));
        assert!(matches!(missing, AlgoError::Checkpoint(_)), "{missing}");
        let shape = AlgoError::from(NnError::ShapeMismatch {
            what: "actor.w0".into(),
            expected: "[256, 17]".into(),
            got: "[256, 11]".into(),
        });
        assert!(matches!(shape, AlgoError::Checkpoint(_)), "{shape}");

        let e = AlgoError::from(NnError::NonFinite {
            what: "critic loss".into(),
            index: 0,
        });
        assert!(matches!(e, AlgoError::Network(_)), "{e}");
        assert_eq!(
            e.to_string(),
            "network: non-finite value in critic loss (first at flat index 0)"
        );
    }
}
