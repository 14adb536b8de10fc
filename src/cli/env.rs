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
//! Every action is checked before the first step: wrong kinds, dimensions and non-finite values
//! (`NaN`, `Infinity` as Python's `json` writes them) are errors naming the action's index.
//! Every output is checked too: a finite start state can still overflow (CartPole from
//! `[0, 0, 0, 1e200]` squares the angular velocity), and a state, observation or reward that is
//! no longer finite is an error naming the step and the quantity, not a `null` in the JSON.

use std::io::Read as _;
use std::path::PathBuf;

use clap::{Args, Subcommand};
use serde_json::{json, Value};
use tandem_envs::{make, Action, Env, Space};

use super::json::{self, kind};
use super::{CliError, Result};

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
    #[arg(long)]
    pub env: String,
    /// Start state: a JSON array (e.g. '[0.01, 0, -0.02, 0]') or the path of a file holding one.
    #[arg(long)]
    pub state: String,
    /// File with a JSON array of actions (numbers for discrete, arrays for continuous); `-` for
    /// stdin.
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

fn read_file(path: &std::path::Path) -> Result<String> {
    if path.as_os_str() == "-" {
        let mut s = String::new();
        std::io::stdin()
            .read_to_string(&mut s)
            .map_err(|source| CliError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        return Ok(s);
    }
    std::fs::read_to_string(path).map_err(|source| CliError::Io {
        path: path.to_path_buf(),
        source,
    })
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
    let mut env = make(&args.env)?;
    let state = parse_state(&args.state)?;
    let what = format!("actions file {}", args.actions.display());
    let text = read_file(&args.actions)?;
    replay_from(&mut *env, &state, &text, &what)
}

/// Replays the JSON `actions` (named `what` in errors) on `env` from `state`: the trajectory
/// object, or an error for bad actions, a bad state, or an output that is not finite.
pub fn replay_from(env: &mut dyn Env, state: &[f64], actions: &str, what: &str) -> Result<Value> {
    let actions = parse_actions(
        &json::parse(actions, what)?,
        env.action_space(),
        env.id(),
        what,
    )?;
    env.set_state(state)?;
    let (mut states, mut observations, mut rewards) = (Vec::new(), Vec::new(), Vec::new());
    let (mut terminated, mut truncated) = (Vec::new(), Vec::new());
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
        if step.done() {
            break;
        }
    }
    Ok(json!({
        "states": states,
        "observations": observations,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
    }))
}
