//! The `tandem` program end to end: `envs`, `rollout`, `env replay` (checked against the
//! gymnasium fixture), and every error path (clear message, non-zero exit, no panic).

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Writes `contents` to a file unique to `name` in Cargo's per-target temp directory.
fn temp_file(name: &str, contents: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}.json"));
    std::fs::write(&path, contents).unwrap();
    path
}

/// Asserts a failed run whose stderr contains every one of `needles`, and no panic.
fn assert_fails_with(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert!(!o.status.success(), "expected failure, stderr: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
}

fn replay(env: &str, state: &str, actions: &str, name: &str) -> Output {
    let path = temp_file(name, actions);
    tandem(&[
        "env",
        "replay",
        "--env",
        env,
        "--state",
        state,
        "--actions",
        path.to_str().unwrap(),
    ])
}

#[test]
fn envs_lists_every_registered_id_with_spaces() {
    let o = tandem(&["envs"]);
    assert!(o.status.success());
    let out = stdout(&o);
    for id in [
        "CartPole-v1",
        "Pendulum-v1",
        "DcMotorPendulum-idealized-v0",
        "DcMotorPendulum-real-v0",
    ] {
        assert!(out.contains(id), "{id} missing from {out}");
    }
    assert!(out.contains("Discrete(2)") && out.contains("low=[-3] high=[3]"));
}

#[test]
fn zero_policy_rollout_on_the_hanging_pendulum_costs_five_pi_squared_per_step() {
    // u = 0 from (π, 0): the pendulum stays hanging, reward −5π² for each of 400 steps.
    let o = tandem(&[
        "rollout",
        "--env",
        "DcMotorPendulum-real-v0",
        "--episodes",
        "2",
        "--seed",
        "3",
        "--policy",
        "zero",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let expected = -400.0 * 5.0 * std::f64::consts::PI.powi(2);
    let returns: Vec<f64> = out
        .lines()
        .filter(|l| l.starts_with("episode "))
        .map(|l| {
            l.split("return ")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap()
                .parse()
                .unwrap()
        })
        .collect();
    assert_eq!(returns.len(), 2);
    for r in returns {
        assert!((r - expected).abs() < 1e-3, "{r} vs {expected}");
    }
    assert!(out.contains("800 real samples"), "{out}");
}

#[test]
fn random_rollouts_are_reproducible_by_seed() {
    let run = |seed: &str| {
        let o = tandem(&[
            "rollout",
            "--env",
            "CartPole-v1",
            "--episodes",
            "3",
            "--seed",
            seed,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let a = run("7");
    assert_eq!(a, run("7"));
    assert_ne!(a, run("8"));
    // CartPole returns are episode lengths.
    for l in a.lines().filter(|l| l.starts_with("episode ")) {
        let ret: f64 = l
            .split("return ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let len: f64 = l.split("length ").nth(1).unwrap().trim().parse().unwrap();
        assert_eq!(ret, len);
    }
}

fn fixture() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/gymnasium/cartpole_v1.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn replay_reproduces_the_gymnasium_fixture_and_stops_at_the_episode_end() {
    let fx = fixture();
    let ep = &fx["episodes"][0];
    let length = ep["length"].as_u64().unwrap() as usize;
    // Extra actions after the terminating step must be ignored.
    let mut actions: Vec<u64> = ep["actions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_u64().unwrap())
        .collect();
    actions.extend([0, 1, 0]);
    let state = ep["initial_state"].to_string();
    let o = replay(
        "CartPole-v1",
        &state,
        &serde_json::to_string(&actions).unwrap(),
        "fixture",
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    for key in [
        "states",
        "observations",
        "rewards",
        "terminated",
        "truncated",
    ] {
        assert_eq!(out[key].as_array().unwrap().len(), length, "{key}");
    }
    for t in 0..length {
        for key in ["states", "observations"] {
            for i in 0..4 {
                let (a, b) = (
                    out[key][t][i].as_f64().unwrap(),
                    ep[key][t][i].as_f64().unwrap(),
                );
                assert!((a - b).abs() <= 1e-9, "{key}[{t}][{i}]: {a} vs {b}");
            }
        }
        assert_eq!(out["rewards"][t], ep["rewards"][t]);
        assert_eq!(out["terminated"][t], ep["terminated"][t]);
        assert_eq!(out["truncated"][t], ep["truncated"][t]);
    }
}

#[test]
fn replay_reads_the_state_from_a_file_and_continuous_actions() {
    let state = temp_file("state", "[0.5, -1.0]");
    let o = replay(
        "Pendulum-v1",
        state.to_str().unwrap(),
        "[[0.5], [-2.0], [1.0]]",
        "pendulum-actions",
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(out["rewards"].as_array().unwrap().len(), 3);
    // First reward is the cost of the start state with u = 0.5.
    let r0 = out["rewards"][0].as_f64().unwrap();
    assert!((r0 + (0.25 + 0.1 + 0.001 * 0.25)).abs() < 1e-12, "{r0}");
}

#[test]
fn replay_reads_actions_from_stdin() {
    use std::io::Write as _;
    let mut child = Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args([
            "env",
            "replay",
            "--env",
            "DcMotorPendulum-idealized-v0",
            "--state",
            "[3.14, 0]",
            "--actions",
            "-",
        ])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"[[3.0], [3.0]]")
        .unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(out["states"].as_array().unwrap().len(), 2);
    // +3 V from hanging accelerates φ upwards.
    assert!(out["states"][1][1].as_f64().unwrap() > 0.0);
}

#[test]
fn unknown_environment_is_an_error() {
    assert_fails_with(
        &replay("CartPole-v0", "[0,0,0,0]", "[0]", "unknown"),
        &["unknown environment", "CartPole-v0"],
    );
    assert_fails_with(
        &tandem(&["rollout", "--env", "Nope-v1", "--episodes", "1"]),
        &["unknown environment", "Nope-v1"],
    );
}

#[test]
fn malformed_json_is_an_error() {
    assert_fails_with(
        &replay("CartPole-v1", "[0, 0, 0", "[0]", "bad-state"),
        &["--state", "malformed JSON"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,0,0,0]", "[0, 1", "bad-actions"),
        &["actions file", "malformed JSON"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,0,0,0]", "{\"a\": 1}", "object-actions"),
        &["expected a JSON array of actions"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,\"x\",0,0]", "[0]", "string-state"),
        &["--state", "element 1"],
    );
}

#[test]
fn missing_files_are_errors() {
    assert_fails_with(
        &tandem(&[
            "env",
            "replay",
            "--env",
            "CartPole-v1",
            "--state",
            "[0,0,0,0]",
            "--actions",
            "/nonexistent/a.json",
        ]),
        &["cannot read", "/nonexistent/a.json"],
    );
    assert_fails_with(
        &replay(
            "CartPole-v1",
            "/nonexistent/state.json",
            "[0]",
            "missing-state",
        ),
        &["cannot read", "/nonexistent/state.json"],
    );
}

#[test]
fn wrong_action_dimensions_and_kinds_are_errors() {
    assert_fails_with(
        &replay("Pendulum-v1", "[0,0]", "[[0.5], [1.0, 2.0]]", "dims"),
        &["action 1", "expected 1 components, got 2"],
    );
    assert_fails_with(
        &replay("Pendulum-v1", "[0,0]", "[0.5]", "kind"),
        &["action 0", "continuous action space"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,0,0,0]", "[0, [1]]", "discrete-kind"),
        &["action 1", "discrete action space"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,0,0,0]", "[0, 2]", "discrete-range"),
        &["action 1", "outside 0..2"],
    );
    assert_fails_with(
        &replay("CartPole-v1", "[0,0,0,0]", "[0.5]", "discrete-fraction"),
        &["action 0", "expected an integer"],
    );
}

#[test]
fn non_finite_actions_and_states_are_errors() {
    assert_fails_with(
        &replay("Pendulum-v1", "[0,0]", "[[0.5], [NaN]]", "nan"),
        &["action 1", "not finite"],
    );
    assert_fails_with(
        &replay("DcMotorPendulum-real-v0", "[0,0]", "[[-Infinity]]", "inf"),
        &["action 0", "not finite"],
    );
    assert_fails_with(
        &replay("Pendulum-v1", "[0, NaN]", "[[0.5]]", "nan-state"),
        &["invalid state", "not finite"],
    );
    assert_fails_with(
        &replay("Pendulum-v1", "[0, 0, 0]", "[[0.5]]", "long-state"),
        &["invalid state", "expected 2 components"],
    );
}

#[test]
fn usage_errors_exit_non_zero_without_panicking() {
    assert_fails_with(
        &tandem(&["rollout", "--env", "CartPole-v1", "--episodes", "0"]),
        &["--episodes"],
    );
    assert_fails_with(
        &tandem(&["rollout", "--env", "CartPole-v1", "--policy", "greedy"]),
        &["greedy"],
    );
    assert_fails_with(&tandem(&["frobnicate"]), &["frobnicate"]);
}

/// `tandem reproduce p0-pendulum --quick --quiet` with `extra` arguments.
fn reproduce(extra: &[&str]) -> Output {
    tandem(
        &[
            &["reproduce", "p0-pendulum", "--quick", "--quiet"][..],
            extra,
        ]
        .concat(),
    )
}

#[test]
fn reproduce_rejects_non_finite_config_values_before_any_work() {
    for (line, key) in [
        ("target_return = nan", "target_return is NaN"),
        (
            "[fit]\nholdout_fraction = nan",
            "fit.holdout_fraction is NaN",
        ),
        (
            "[fit]\nholdout_fraction = 1.5",
            "fit.holdout_fraction is 1.5, must lie in [0, 1)",
        ),
    ] {
        let cfg = temp_file(&format!("p0-{}", key.len()), line);
        let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p0-nan-out");
        let o = reproduce(&[
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_fails_with(&o, &[key]);
        assert!(!out.join("config.json").exists());
    }
}

#[test]
fn reproduce_over_an_earlier_run_is_refused_and_overwrite_names_foreign_files() {
    // An earlier 5-seed reproduction: a seed folder that a 2-seed run would leave stale.
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p0-earlier");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(out.join("runs/cold__seed4")).unwrap();
    std::fs::write(out.join("table.json"), "{}").unwrap();
    let o = reproduce(&["--seeds", "2", "--out", out.to_str().unwrap()]);
    assert_fails_with(&o, &["already holds a run", "--overwrite", "--resume"]);
    assert!(out.join("runs/cold__seed4").exists());
    // --overwrite replaces only a reproduction's own files.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o = reproduce(&[
        "--seeds",
        "2",
        "--out",
        out.to_str().unwrap(),
        "--overwrite",
    ]);
    assert_fails_with(&o, &["notes.txt", "choose another --out"]);
    assert!(out.join("runs/cold__seed4").exists() && out.join("notes.txt").exists());
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn replay_outputs_that_overflow_are_errors_not_null() {
    // A finite start state whose next state is not: theta_dot² overflows.
    let o = replay("CartPole-v1", "[0,0,0,1e200]", "[0, 1]", "overflow");
    assert_fails_with(&o, &["CartPole-v1 replay, step 0", "state is not finite"]);
    assert!(stdout(&o).is_empty(), "no partial JSON: {}", stdout(&o));
    // The same environment from a representable state still replays.
    let o = replay("CartPole-v1", "[0,0,0,1e3]", "[0]", "large-ok");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stdout(&o).contains("null"), "{}", stdout(&o));
}

/// `tandem env replay` of CartPole with `state` and `actions` as given on the command line.
fn replay_args(state: &str, actions: &str) -> Output {
    tandem(&[
        "env",
        "replay",
        "--env",
        "CartPole-v1",
        "--state",
        state,
        "--actions",
        actions,
    ])
}

#[test]
fn an_endless_actions_file_is_refused_at_its_cap() {
    assert_fails_with(
        &replay_args("[0,0,0,0]", "/dev/zero"),
        &["cannot read /dev/zero", "64 MiB"],
    );
}

#[test]
fn an_endless_state_file_is_refused_at_its_cap() {
    let actions = temp_file("capped-state-actions", "[0]");
    assert_fails_with(
        &replay_args("/dev/zero", actions.to_str().unwrap()),
        &["cannot read /dev/zero", "64 MiB"],
    );
}

#[test]
fn endless_actions_on_stdin_are_refused_at_the_cap() {
    let o = Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args([
            "env",
            "replay",
            "--env",
            "CartPole-v1",
            "--state",
            "[0,0,0,0]",
        ])
        .args(["--actions", "-"])
        .stdin(std::fs::File::open("/dev/zero").unwrap())
        .output()
        .unwrap();
    assert_fails_with(&o, &["cannot read stdin", "64 MiB"]);
}

#[test]
fn an_endless_study_config_is_refused_before_the_output_directory_exists() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("capped-config-out");
    let _ = std::fs::remove_dir_all(&out);
    let o = tandem(&[
        "reproduce",
        "p2-cartpole",
        "--quick",
        "--quiet",
        "--config",
        "/dev/zero",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_fails_with(&o, &["/dev/zero", "1 MiB"]);
    assert!(!out.exists());
}

#[test]
fn frame_skip_with_a_registered_environment_is_refused() {
    let actions = temp_file("frame-skip-env", "[[0, 0, 0]]");
    // Refused before the environment is made, so with or without the `mujoco` feature.
    let o = tandem(&[
        "env",
        "replay",
        "--env",
        "Hopper-v5",
        "--frame-skip",
        "50",
        "--state",
        "[0]",
        "--actions",
        actions.to_str().unwrap(),
    ]);
    assert_fails_with(
        &o,
        &[
            "--frame-skip 50",
            "only to --mjcf",
            "Hopper-v5 has its own frame skip (4)",
        ],
    );
}

#[test]
fn frame_skip_beyond_its_cap_is_refused() {
    let actions = temp_file("frame-skip-huge", "[[0]]");
    for n in ["18446744073709551615", "1000001"] {
        let o = tandem(&[
            "env",
            "replay",
            "--mjcf",
            "x.xml",
            "--frame-skip",
            n,
            "--state",
            "[0, 0]",
            "--actions",
            actions.to_str().unwrap(),
        ]);
        assert_fails_with(&o, &["--frame-skip", "1..=1000000"]);
    }
}
