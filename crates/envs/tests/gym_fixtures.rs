//! Replays every episode of the gymnasium fixtures (`tests/fixtures/gymnasium/*.json`, recorded
//! from gymnasium 1.x) from its initial state with its actions, and checks states, observations,
//! rewards and flags to 1e-9 absolute.

use serde_json::Value;
use tandem_envs::{make, Action, Env, EnvError};

const TOL: f64 = 1e-9;

fn load(name: &str) -> Value {
    let path = format!(
        "{}/../../tests/fixtures/gymnasium/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn assert_close(what: &str, ep: usize, t: usize, got: &[f64], want: &[f64]) {
    assert_eq!(
        got.len(),
        want.len(),
        "{what} length, episode {ep} step {t}"
    );
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= TOL,
            "{what}[{i}] episode {ep} step {t}: got {g:e}, gymnasium {w:e}"
        );
    }
}

/// Replays all episodes of `file`; returns the number of steps compared.
fn replay(file: &str, action: impl Fn(&Value) -> Action) -> usize {
    let fx = load(file);
    let id = fx["env_id"].as_str().unwrap();
    let episodes = fx["episodes"].as_array().unwrap();
    assert_eq!(
        episodes.len() as u64,
        fx["episodes_recorded"].as_u64().unwrap()
    );
    let mut compared = 0;
    for (ep, e) in episodes.iter().enumerate() {
        let mut env = make(id).unwrap();
        assert_eq!(
            env.max_episode_steps(),
            Some(fx["max_episode_steps"].as_u64().unwrap() as usize)
        );
        let obs0 = env.set_state(&floats(&e["initial_state"])).unwrap();
        assert_close(
            "initial observation",
            ep,
            0,
            &obs0,
            &floats(&e["initial_obs"]),
        );
        let actions = e["actions"].as_array().unwrap();
        let length = e["length"].as_u64().unwrap() as usize;
        assert_eq!(actions.len(), length);
        for (t, a) in actions.iter().enumerate() {
            let step = env.step(&action(a)).unwrap();
            assert_close("state", ep, t, &env.state(), &floats(&e["states"][t]));
            assert_close(
                "observation",
                ep,
                t,
                &step.observation,
                &floats(&e["observations"][t]),
            );
            let r = e["rewards"][t].as_f64().unwrap();
            assert!(
                (step.reward - r).abs() <= TOL,
                "reward episode {ep} step {t}: {} vs {r}",
                step.reward
            );
            assert_eq!(
                step.terminated,
                e["terminated"][t].as_bool().unwrap(),
                "terminated, episode {ep} step {t}"
            );
            assert_eq!(
                step.truncated,
                e["truncated"][t].as_bool().unwrap(),
                "truncated, episode {ep} step {t}"
            );
            // Only the last recorded step may end the episode.
            assert_eq!(
                step.done(),
                t + 1 == length && step.done(),
                "episode {ep} ended early at {t}"
            );
            compared += 1;
        }
        // Where the recording ended the episode, so do we.
        let last_done = e["terminated"][length - 1].as_bool().unwrap()
            || e["truncated"][length - 1].as_bool().unwrap();
        if last_done {
            assert!(matches!(
                env.step(&action(&actions[0])),
                Err(EnvError::NeedsReset { .. })
            ));
        }
    }
    compared
}

#[test]
fn cartpole_v1_replays_every_fixture_episode() {
    let n = replay("cartpole_v1.json", |a| {
        Action::Discrete(a.as_u64().unwrap() as usize)
    });
    assert!(n > 0);
}

#[test]
fn pendulum_v1_replays_every_fixture_episode() {
    let n = replay("pendulum_v1.json", |a| {
        Action::Continuous(vec![a.as_f64().unwrap()])
    });
    assert!(n >= 200);
}
