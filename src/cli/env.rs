//! `tandem env ...`: environment tools.
//!
//! `tandem env replay --env NAME --state STATE --actions FILE` starts `NAME` (with its time
//! limit) from an internal state, applies the actions, and prints one JSON object
//! `{"states", "observations", "rewards", "terminated", "truncated"}` whose entry `t` is the
//! result of action `t` (as in the gymnasium fixtures). It stops where the episode ends, so extra
//! actions are ignored. A tool to diff our environments against any other implementation.
//!
//! - `--state`: a JSON array of numbers, the environment's internal state (e.g. CartPole's
//!   `[x, x_dot, theta, theta_dot]`). If the argument starts with `[` (after whitespace) it is the
//!   JSON itself, otherwise it is the path of a file holding it.
//! - `--actions`: path of a file holding a JSON array of actions (`-` reads stdin): integers for
//!   a discrete action space, arrays of numbers for a box space (`[[0.5], [-1.0]]`).
//!
//! Files (and stdin) are read up to [`tandem_core::MAX_INPUT_BYTES`] (64 MiB); more is an error
//! naming the file and the limit.
//!
//! - MuJoCo (feature `mujoco`): for gymnasium's MuJoCo tasks (`HalfCheetah-v5`, ...) the state is
//!   `qpos` followed by `qvel`, the output `states` are `qpos ++ qvel` after each step, and the
//!   output has one more list, `info`: each step's reward terms as gymnasium's `info` dict.
//!   `--mjcf FILE` (instead of `--env`) replays any MJCF scene: state `qpos ++ qvel`, actions are
//!   `ctrl`, `--frame-skip N` MuJoCo steps per action (default 1, at most [`MAX_FRAME_SKIP`]),
//!   reward 0, no time limit. `--frame-skip` with `--env` is an error: a registered task has its
//!   own frame skip. A step MuJoCo flags as bad (a NaN or a value beyond ±1e10 in `qpos`, `qvel`,
//!   `qacc` or `ctrl`, after which MuJoCo would reset the simulation; full contact or constraint
//!   buffers) is an error naming the quantity and the step, not a reset state in the output.
//!
//! Every action is checked before the first step: wrong kinds, dimensions and non-finite values
//! (`NaN`, `Infinity` as Python's `json` writes them) are errors naming the action's index.
//! Every output is checked too: a finite start state can still overflow (CartPole from
//! `[0, 0, 0, 1e200]` squares the angular velocity), and a state, observation or reward that is
//! no longer finite is an error naming the step and the quantity, not a `null` in the JSON.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use serde_json::{json, Value};
use tandem_core::{read_capped, read_file_capped, MAX_INPUT_BYTES};
use tandem_envs::{Action, Env, Space};

use super::json::{self, kind};
use super::{CliError, IoOp, Result};

/// The most MuJoCo steps per action `--frame-skip` accepts: a million steps of a typical 2 ms
/// timestep are 2000 s of simulated time per action, far past any use, and a larger value would
/// keep the program busy for hours on one action.
pub const MAX_FRAME_SKIP: u64 = 1_000_000;

/// `tandem env` subcommands.
#[derive(Debug, Subcommand)]
pub enum EnvCommand {
    /// Replay actions from a given state; print the trajectory as JSON.
    Replay(ReplayArgs),
}

/// Arguments of `tandem env replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// Registered environment id (see `tandem envs`).
    #[arg(long, required_unless_present = "mjcf", conflicts_with = "mjcf")]
    pub env: Option<String>,
    /// An MJCF file to replay instead of a registered environment (needs the `mujoco` feature):
    /// state `qpos ++ qvel`, actions are the actuators' `ctrl`, reward 0.
    #[arg(long)]
    pub mjcf: Option<PathBuf>,
    /// MuJoCo steps per action of an `--mjcf` scene (default 1, at most 1000000). Refused with
    /// `--env`: a registered task has its own frame skip.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=MAX_FRAME_SKIP))]
    pub frame_skip: Option<u64>,
    /// Start state: a JSON array (e.g. '[0.01, 0, -0.02, 0]') or the path of a file holding one
    /// (at most 64 MiB).
    #[arg(long)]
    pub state: String,
    /// File with a JSON array of actions (numbers for discrete, arrays for continuous); `-` for
    /// stdin. At most 64 MiB.
    #[arg(long)]
    pub actions: PathBuf,
}

/// Runs an `env` subcommand.
pub fn run(cmd: EnvCommand) -> Result<()> {
    match cmd {
        EnvCommand::Replay(args) => {
            let out = replay(&args)?;
            super::emit(&out.to_string())
        }
    }
}

/// The file at `path` (`-`: stdin), at most [`MAX_INPUT_BYTES`].
fn read_file(path: &std::path::Path) -> Result<String> {
    let text = if path.as_os_str() == "-" {
        read_capped(std::io::stdin().lock(), MAX_INPUT_BYTES)
    } else {
        read_file_capped(path, MAX_INPUT_BYTES)
    };
    let shown = if path.as_os_str() == "-" {
        std::path::Path::new("stdin")
    } else {
        path
    };
    text.map_err(|source| CliError::io(IoOp::Read, shown, source))
}

/// The `--state` argument as numbers.
fn parse_state(arg: &str) -> Result<Vec<f64>> {
    let (text, what) = if arg.trim_start().starts_with('[') {
        (arg.to_string(), "--state".to_string())
    } else {
        let path = PathBuf::from(arg);
        (
            read_file(&path)?,
            format!("--state file {}", path.display()),
        )
    };
    json::numbers(&json::parse(&text, &what)?, &what)
}

/// Converts and checks the actions for `space`.
pub fn parse_actions(value: &Value, space: &Space, env: &str, what: &str) -> Result<Vec<Action>> {
    let items = value.as_array().ok_or_else(|| {
        CliError::input(
            what,
            format!("expected a JSON array of actions, got {}", kind(value)),
        )
    })?;
    items
        .iter()
        .enumerate()
        .map(|(t, v)| {
            let bad = |msg: String| CliError::input(what, format!("action {t}: {msg}"));
            let action =
                match space {
                    Space::Discrete { n } => {
                        match v.as_u64() {
                            Some(k) => Action::Discrete(usize::try_from(k).unwrap_or(usize::MAX)),
                            None => {
                                return Err(bad(format!(
                            "{env} has a discrete action space (Discrete({n})): expected an \
                             integer in 0..{n}, got {}",
                            if v.is_number() { v.to_string() } else { kind(v).to_string() }
                        )))
                            }
                        }
                    }
                    Space::Box { low, .. } => {
                        if !v.is_array() {
                            return Err(bad(format!(
                                "{env} has a continuous action space: expected an array of {} \
                             number(s), got {}",
                                low.len(),
                                kind(v)
                            )));
                        }
                        Action::Continuous(json::numbers(v, &format!("{what}: action {t}"))?)
                    }
                };
            space.check(&action).map_err(|e| bad(e.to_string()))?;
            Ok(action)
        })
        .collect()
}

/// Replays `args` and returns the trajectory object.
pub fn replay(args: &ReplayArgs) -> Result<Value> {
    let id = args.env.as_deref().unwrap_or_default();
    if let (Some(n), None) = (args.frame_skip, &args.mjcf) {
        // Applying it would change the task's dt and so its rewards: no longer gymnasium's task.
        return Err(CliError::input(
            format!("--frame-skip {n}"),
            format!(
                "applies only to --mjcf scenes; {id} has its own frame skip{}",
                tandem::mujoco::TaskKind::from_id(id)
                    .map(|k| format!(" ({})", k.spec().frame_skip))
                    .unwrap_or_default()
            ),
        ));
    }
    let state = parse_state(&args.state)?;
    let what = format!("actions file {}", args.actions.display());
    let text = read_file(&args.actions)?;
    if let Some(path) = &args.mjcf {
        return replay_mjcf(path, args.frame_skip.unwrap_or(1), &state, &text, &what);
    }
    if let Some(kind) = tandem::mujoco::TaskKind::from_id(id) {
        return replay_mujoco_task(kind, &state, &text, &what);
    }
    let mut env = tandem::make_env(id)?;
    replay_from(&mut *env, &state, &text, &what)
}

#[cfg(feature = "mujoco")]
fn replay_mujoco_task(
    kind: tandem::mujoco::TaskKind,
    state: &[f64],
    actions: &str,
    what: &str,
) -> Result<Value> {
    use tandem::mujoco::MujocoEnv;
    let env = MujocoEnv::task(kind, &tandem::mujoco::assets_dir()).map_err(CliError::other)?;
    let mut env = tandem_envs::TimeLimit::new(env, kind.spec().max_episode_steps);
    replay_with(&mut env, state, actions, what, |env| {
        env.inner()
            .last_outcome()
            .map(|o| Value::Object(o.terms().map(|(k, v)| (k.to_string(), json!(v))).collect()))
    })
}

#[cfg(feature = "mujoco")]
fn replay_mjcf(
    path: &std::path::Path,
    frame_skip: u64,
    state: &[f64],
    actions: &str,
    what: &str,
) -> Result<Value> {
    use tandem::mujoco::{MujocoEnv, Scene};
    let frame_skip =
        usize::try_from(frame_skip).map_err(|_| CliError::input("--frame-skip", "too large"))?;
    let scene = Scene::from_xml(path).map_err(CliError::other)?;
    let mut env = MujocoEnv::scene(scene, frame_skip).map_err(CliError::other)?;
    replay_from(&mut env, state, actions, what)
}

#[cfg(not(feature = "mujoco"))]
fn replay_mujoco_task(
    kind: tandem::mujoco::TaskKind,
    _state: &[f64],
    _actions: &str,
    _what: &str,
) -> Result<Value> {
    Err(tandem::mujoco::make(kind.spec().id).err().map_or_else(
        || CliError::other("MuJoCo is not available"),
        CliError::from,
    ))
}

#[cfg(not(feature = "mujoco"))]
fn replay_mjcf(
    _path: &std::path::Path,
    _frame_skip: u64,
    _state: &[f64],
    _actions: &str,
    _what: &str,
) -> Result<Value> {
    Err(CliError::input(
        "--mjcf",
        "MJCF scenes need a build with `--features mujoco` after scripts/setup-mujoco.sh \
         (see docs/mujoco.md)",
    ))
}

/// Replays the JSON `actions` (named `what` in errors) on `env` from `state`: the trajectory
/// object, or an error for bad actions, a bad state, or an output that is not finite.
pub fn replay_from(env: &mut dyn Env, state: &[f64], actions: &str, what: &str) -> Result<Value> {
    replay_with(env, state, actions, what, |_| None)
}

/// [`replay_from`] with a per-step `info` object read from the environment after each step; the
/// output gains an `info` list when `info` gives one.
pub fn replay_with<E: Env + ?Sized>(
    env: &mut E,
    state: &[f64],
    actions: &str,
    what: &str,
    mut info: impl FnMut(&E) -> Option<Value>,
) -> Result<Value> {
    let actions = parse_actions(
        &json::parse(actions, what)?,
        env.action_space(),
        env.id(),
        what,
    )?;
    env.set_state(state)?;
    let (mut states, mut observations, mut rewards) = (Vec::new(), Vec::new(), Vec::new());
    let (mut terminated, mut truncated) = (Vec::new(), Vec::new());
    let mut infos = Vec::new();
    for (t, a) in actions.iter().enumerate() {
        let step = env
            .step(a)
            .map_err(|e| CliError::other(format!("step {t}: {e}")))?;
        let at = format!("{} replay, step {t}", env.id());
        let state = env.state();
        json::check_output(&at, "state", &state)?;
        json::check_output(&at, "observation", &step.observation)?;
        json::check_output(&at, "reward", &[step.reward])?;
        states.push(state);
        observations.push(step.observation.clone());
        rewards.push(step.reward);
        terminated.push(step.terminated);
        truncated.push(step.truncated);
        infos.extend(info(env));
        if step.done() {
            break;
        }
    }
    let mut out = json!({
        "states": states,
        "observations": observations,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
    });
    if !infos.is_empty() {
        out["info"] = Value::Array(infos);
    }
    Ok(out)
}
