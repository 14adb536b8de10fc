//! The papers' loops, generic over the traits: each composes a plant or environment, a model, a
//! planner and an agent.
//!
//! | module | paper | loop |
//! |---|---|---|
//! | [`p0`] | Rastogi et al., difference models | pre-train on the idealized plant; collect true samples, fit a residual model, retrain on plant + residual |
//! | [`p1`] | Cong Li, deep incremental model | the MBPO loop with one-step rollouts through the incremental model `s + L_θ(s, a_prev) Δa`, the task's reward |
//! | [`p2`] | Manglik and Tripathi, model-augmented REINFORCE | N real episodes, then real episodes alternated with episodes imagined by a learned `(s', r, done)` model |
//! | [`p2_maze`] | the same, DQN from pixels | the same loop for an off-policy agent on p2's maze, with the pixel model; the pixel model's F1 experiment |
//! | [`dyna`] | (shared) | MBPO-style Dyna: branched rollouts of a learned model from real states, acted by the agent's own batched policy, into the loop's second buffer |
//! | [`gps`] | Chebotar et al., PILQR (and GPS) | one TVLG controller per condition, improved from its own samples by LQR-FLM, PI² or PILQR |
//! | [`mdgps`] | Montgomery and Levine, MDGPS (p4 §IV) | a neural global policy regressed onto the local controllers, each updated under a KL bound to the linearized global policy |
//! | [`mbpo`] | Janner et al., MBPO (shared) | SAC on the real system; every 250 steps an ensemble refit and branched rollouts of length `k` into `D_model`; `G` updates per step at real ratio 0.05; the SAC baseline on the same loop |
//! | [`p3`] | Mishra et al., M-DeMoRL | the MBPO loop with `D_MPC` filled by DMD-MPC plans (CEM elites, SAC's policy as shift, `−V` terminal cost) through the ensemble's elites |
//! | [`p4`] | Chebotar et al., PILQR | the gripper pusher's, the door's and the reacher's conditions and costs on MuJoCo for [`gps`] and [`mdgps`]; DDPG on the reacher, measured on the same test targets |
//! | [`adapter`] | (shared) | observation features, reward scale and settable exploration noise in front of any off-policy agent |

pub mod adapter;
pub mod dyna;
pub mod gps;
pub mod mbpo;
pub mod mdgps;
pub mod p0;
pub mod p1;
pub mod p2;
pub mod p2_maze;
pub mod p3;
pub mod p4;

use tandem_agents::AgentError;
use tandem_envs::EnvError;
use tandem_models::ModelError;
use tandem_nn::{Checkpoint, NnError};
use tandem_planners::PlanError;

/// Why a pipeline stopped.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
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
        tandem_core::Space::Discrete { .. } => Err(PipelineError::Config(format!(
            "{needs} a continuous (box) action space"
        ))),
    }
}

/// What a checkpoint read can fail with (unreadable, a tensor missing, a tensor of the wrong
/// shape or type) is a checkpoint error; what only computing can fail with (non-finite numbers, a
/// bad setting, candle) is [`PipelineError::Network`].
impl From<NnError> for PipelineError {
    fn from(e: NnError) -> Self {
        match e {
            NnError::Checkpoint(what) => PipelineError::Checkpoint(what),
            NnError::MissingTensor(_) | NnError::ShapeMismatch { .. } => {
                PipelineError::Checkpoint(e.to_string())
            }
            NnError::NonFinite { .. }
            | NnError::InvalidConfig(_)
            | NnError::NoTape(_)
            | NnError::Candle(_) => PipelineError::Network(e),
        }
    }
}

/// Result of the pipelines.
pub type Result<T> = std::result::Result<T, PipelineError>;

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
    /// Whether to stop now; the pipeline then returns [`PipelineError::Stopped`].
    fn stop_requested(&self) -> bool {
        false
    }
}

/// Refuses a checkpoint saved by another run: `saved` and `this` are (method name, seed).
pub fn ensure_same_run(saved: (&str, u64), this: (&str, u64)) -> Result<()> {
    if saved == this {
        return Ok(());
    }
    Err(PipelineError::Checkpoint(format!(
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
/// use tandem::pipelines::{Checkpoints, InMemory};
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
        assert!(matches!(e, PipelineError::Checkpoint(_)), "{e}");
        let missing = PipelineError::from(NnError::MissingTensor("actor.w0".into()));
        assert!(matches!(missing, PipelineError::Checkpoint(_)), "{missing}");
        let shape = PipelineError::from(NnError::ShapeMismatch {
            what: "actor.w0".into(),
            expected: "[256, 17]".into(),
            got: "[256, 11]".into(),
        });
        assert!(matches!(shape, PipelineError::Checkpoint(_)), "{shape}");

        let e = PipelineError::from(NnError::NonFinite {
            what: "critic loss".into(),
            index: 0,
        });
        assert!(matches!(e, PipelineError::Network(_)), "{e}");
        assert_eq!(
            e.to_string(),
            "network: non-finite value in critic loss (first at flat index 0)"
        );
    }
}
