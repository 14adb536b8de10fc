//! The MuJoCo environments' registry entries: ids to environments, with time limits.

use std::path::PathBuf;

use tandem_core::Space;
use tandem_envs::{Env, EnvError, EnvSpec};

use crate::task::TaskKind;

/// Whether this build links MuJoCo (the cargo feature `mujoco`).
pub const AVAILABLE: bool = cfg!(feature = "mujoco");

/// gymnasium's MJCF assets: `$TANDEM_MUJOCO_ASSETS` if set, otherwise the `.mujoco/assets` link
/// that `scripts/setup-mujoco.sh` makes in the repository this crate was built from.
pub fn assets_dir() -> PathBuf {
    match std::env::var_os("TANDEM_MUJOCO_ASSETS") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../.mujoco/assets")),
    }
}

/// gymnasium's MuJoCo task `id` with its time limit, as `gymnasium.make`.
///
/// Errors: [`EnvError::Unknown`] for an id that is not one of the seven tasks;
/// [`EnvError::Unsupported`] when the build lacks the `mujoco` feature or the model cannot be
/// loaded (the message says what to do).
///
/// ```
/// let made = tandem_mujoco::make("HalfCheetah-v5");
/// if tandem_mujoco::AVAILABLE {
///     assert_eq!(made.unwrap().max_episode_steps(), Some(1000));
/// } else {
///     assert!(made.err().unwrap().to_string().contains("--features mujoco"));
/// }
/// assert!(matches!(tandem_mujoco::make("CartPole-v1"), Err(tandem_envs::EnvError::Unknown(_))));
/// ```
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    let kind = TaskKind::from_id(id).ok_or_else(|| EnvError::Unknown(id.to_string()))?;
    make_task(kind)
}

#[cfg(feature = "mujoco")]
fn make_task(kind: TaskKind) -> Result<Box<dyn Env>, EnvError> {
    let spec = kind.spec();
    let env = crate::MujocoEnv::task(kind, &assets_dir()).map_err(|e| EnvError::Unsupported {
        env: spec.id.to_string(),
        reason: format!("{e} (gymnasium's assets: run scripts/setup-mujoco.sh)"),
    })?;
    Ok(Box::new(tandem_envs::TimeLimit::new(
        env,
        spec.max_episode_steps,
    )))
}

/// The task registered as `id` as a [`crate::GymTask`], its `qpos0` read from its MJCF; an error
/// for an unknown id, missing assets or a task that is not a function of `qpos`/`qvel`.
#[cfg(feature = "mujoco")]
pub fn gym_task(id: &str) -> Result<crate::GymTask, EnvError> {
    let kind = TaskKind::from_id(id).ok_or_else(|| EnvError::Unknown(id.to_string()))?;
    let env = crate::MujocoEnv::task(kind, &assets_dir()).map_err(|e| EnvError::Unsupported {
        env: id.to_string(),
        reason: format!("{e} (gymnasium's assets: run scripts/setup-mujoco.sh)"),
    })?;
    crate::GymTask::new(kind, env.scene_ref().qpos0().to_vec())
}

#[cfg(not(feature = "mujoco"))]
fn make_task(kind: TaskKind) -> Result<Box<dyn Env>, EnvError> {
    Err(EnvError::Unsupported {
        env: kind.spec().id.to_string(),
        reason: "MuJoCo environments need a build with `--features mujoco` after \
                 scripts/setup-mujoco.sh (see docs/mujoco.md)"
            .into(),
    })
}

/// The seven tasks' registry entries (spaces from their specs), in registration order; empty
/// without the `mujoco` feature, where they cannot be made.
pub fn registered() -> Vec<EnvSpec> {
    if !AVAILABLE {
        return Vec::new();
    }
    TaskKind::ALL
        .into_iter()
        .map(|k| {
            let s = k.spec();
            EnvSpec {
                id: s.id,
                description: s.description,
                max_episode_steps: s.max_episode_steps,
                observation_space: Space::unbounded(s.obs_dim),
                action_space: Space::symmetric(s.nu, s.action_bound),
            }
        })
        .collect()
}
