//! `tandem train` end to end: a short run writes every file with the promised fields; without
//! `--config` the (algo, env) preset is used and named; an existing run is never overwritten or
//! shared by accident (`--overwrite`, the lock file, unique default names); and bad input (wrong
//! action space, unknown config key, out-of-range or non-finite value, unknown algorithm) is a
//! clear error with exit status 1.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tandem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tandem-train-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `tandem train` with SAC on Pendulum-v1 for 300 steps, seed 3, with `cfg` and `out`.
fn train_sac(cfg: &std::path::Path, out: &std::path::Path) -> std::process::Output {
    tandem()
        .args([
            "train",
            "--algo",
            "sac",
            "--env",
            "Pendulum-v1",
            "--steps",
            "300",
            "--seed",
            "3",
            "--quiet",
        ])
        .arg("--config")
        .arg(cfg)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn a_short_run_writes_config_metrics_summary_curve_and_checkpoint() {
    let dir = tmp("run");
    let cfg = dir.join("small.toml");
    std::fs::write(
        &cfg,
        "[agent]\nhidden = [16, 16]\nbatch_size = 32\n[train]\neval_interval = 100\neval_episodes = 2\n",
    )
    .unwrap();
    let out = dir.join("out");
    let o = train_sac(&cfg, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "config.toml",
        "metrics.csv",
        "episodes.csv",
        "summary.json",
        "curve.svg",
        "checkpoint.safetensors",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["real_samples"], 300);
    assert_eq!(s["eval_returns"].as_array().unwrap().len(), 2);
    for k in [
        "eval_return_mean",
        "eval_return_std",
        "wall_seconds",
        "env_steps_per_second",
    ] {
        assert!(s[k].as_f64().unwrap().is_finite(), "{k}");
    }
    // Pendulum rewards are in [-16.27, 0] per step, 200 steps per episode.
    let m = s["eval_return_mean"].as_f64().unwrap();
    assert!((-3300.0..=0.0).contains(&m), "{m}");
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(metrics.lines().count(), 1 + 3, "{metrics}");
    assert!(metrics.starts_with("step,episodes,updates,eval_return_mean,eval_return_std"));
    let cfg_written = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(cfg_written.contains("hidden = [16, 16]"), "{cfg_written}");

    // The same seed again: identical metrics.
    let out2 = dir.join("out2");
    let o = train_sac(&cfg, &out2);
    assert!(o.status.success());
    assert_eq!(
        metrics,
        std::fs::read_to_string(out2.join("metrics.csv")).unwrap()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn fails_with(args: &[&str], config: Option<&str>, needle: &str) {
    let dir = tmp(&needle.replace(|c: char| !c.is_alphanumeric(), "_"));
    let mut c = tandem();
    c.arg("train")
        .args(args)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--quiet");
    if let Some(text) = config {
        let p = dir.join("c.toml");
        std::fs::write(&p, text).unwrap();
        c.arg("--config").arg(p);
    }
    let o = c.output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(needle), "expected `{needle}` in: {err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_a_clear_error() {
    let base = ["--env", "Pendulum-v1", "--steps", "10"];
    fails_with(
        &[&["--algo", "dqn"][..], &base].concat(),
        None,
        "dqn needs a discrete action space",
    );
    fails_with(
        &["--algo", "sac", "--env", "CartPole-v1", "--steps", "10"],
        None,
        "sac needs a continuous",
    );
    fails_with(
        &[&["--algo", "sac"][..], &base].concat(),
        Some("[agent]\nlearnin_rate = 1e-3\n"),
        "learnin_rate",
    );
    fails_with(
        &[&["--algo", "sac"][..], &base].concat(),
        Some("[agent]\ntau = 2.0\n"),
        "tau",
    );
    fails_with(
        &[&["--algo", "sac"][..], &base].concat(),
        Some("[trian]\n"),
        "trian",
    );
    fails_with(&[&["--algo", "ppo"][..], &base].concat(), None, "ppo");
    // Non-finite settings are rejected before any work, naming the key.
    fails_with(
        &[&["--algo", "sac"][..], &base].concat(),
        Some("[train]\nsolved_threshold = nan\n"),
        "train.solved_threshold is NaN",
    );
    fails_with(
        &[&["--algo", "sac"][..], &base].concat(),
        Some("[agent]\ntarget_entropy = -inf\n"),
        "target_entropy",
    );
}

/// `tandem train --algo dqn --env CartPole-v1 --steps 200 --seed 0 --quiet --out OUT` plus
/// `extra`, run in `cwd`: DQN's 1000 warm-up steps make it a run without updates (fast).
fn train_dqn(cwd: &Path, out: Option<&Path>, extra: &[&str]) -> Output {
    let mut c = tandem();
    c.current_dir(cwd).args([
        "train",
        "--algo",
        "dqn",
        "--env",
        "CartPole-v1",
        "--steps",
        "200",
        "--seed",
        "0",
        "--quiet",
    ]);
    if let Some(out) = out {
        c.arg("--out").arg(out);
    }
    c.args(extra).output().unwrap()
}

fn text(o: &[u8]) -> String {
    String::from_utf8_lossy(o).into_owned()
}

#[test]
fn without_config_the_preset_for_the_pair_is_used_and_named() {
    let dir = tmp("preset");
    let out = dir.join("out");
    let o = train_dqn(&dir, Some(&out), &[]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("using preset dqn_cartpole.toml"), "{err}");
    assert!(err.contains("differs from the 50000 steps"), "{err}");
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    // The preset's values, not DqnConfig::default()'s (batch 64, no double DQN).
    for line in [
        "config_source = \"preset:dqn_cartpole.toml\"",
        "double_dqn = true",
        "batch_size = 128",
        "eval_interval = 5000",
    ] {
        assert!(cfg.contains(line), "{line} missing from {cfg}");
    }
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["config_source"], "preset:dqn_cartpole.toml");

    // --no-preset: the defaults.
    let out2 = dir.join("out2");
    let o = train_dqn(&dir, Some(&out2), &["--no-preset"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(!text(&o.stderr).contains("preset dqn_cartpole"));
    let cfg = std::fs::read_to_string(out2.join("config.toml")).unwrap();
    assert!(cfg.contains("config_source = \"defaults\""), "{cfg}");
    assert!(
        cfg.contains("double_dqn = false") && cfg.contains("batch_size = 64"),
        "{cfg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_existing_run_is_refused_unless_overwrite() {
    let dir = tmp("overwrite");
    let out = dir.join("out");
    assert!(train_dqn(&dir, Some(&out), &[]).status.success());
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    std::fs::write(out.join("metrics.csv"), "marker").unwrap();

    let o = train_dqn(&dir, Some(&out), &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("already holds a run")
            && err.contains("--overwrite")
            && err.contains("--resume"),
        "{err}"
    );
    // Nothing was touched.
    assert_eq!(
        std::fs::read_to_string(out.join("metrics.csv")).unwrap(),
        "marker"
    );
    assert_eq!(
        std::fs::read_to_string(out.join("summary.json")).unwrap(),
        summary
    );

    let o = train_dqn(&dir, Some(&out), &["--overwrite"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(std::fs::read_to_string(out.join("metrics.csv"))
        .unwrap()
        .starts_with("step,"));
    assert!(
        !out.join(".tandem.lock").exists(),
        "the lock is removed at the end"
    );

    // --overwrite removes only a run's own files: a directory holding others is refused.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o = train_dqn(&dir, Some(&out), &["--overwrite"]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("notes.txt"), "{err}");
    assert!(out.join("notes.txt").exists() && out.join("summary.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_locked_directory_is_refused_and_a_stale_lock_reported() {
    let dir = tmp("lock");
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    // A live writer: this test process.
    std::fs::write(
        out.join(".tandem.lock"),
        format!("{}\n", std::process::id()),
    )
    .unwrap();
    let o = train_dqn(&dir, Some(&out), &["--overwrite"]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("in use by process {}", std::process::id())),
        "{err}"
    );
    assert!(!out.join("summary.json").exists());

    // A dead writer: a process that has exited.
    let mut child = Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    std::fs::write(out.join(".tandem.lock"), format!("{dead}\n")).unwrap();
    let o = train_dqn(&dir, Some(&out), &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("stale lock: process {dead}")) && err.contains("no longer running"),
        "{err}"
    );
    // --overwrite takes it over, says so, and leaves no lock behind.
    let o = train_dqn(&dir, Some(&out), &["--overwrite"]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains(&format!("from process {dead}")), "{err}");
    assert!(out.join("summary.json").exists() && !out.join(".tandem.lock").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn two_runs_started_together_get_their_own_default_directories() {
    let dir = tmp("names");
    let spawn = || {
        let mut c = tandem();
        c.current_dir(&dir)
            .args([
                "train",
                "--algo",
                "dqn",
                "--env",
                "CartPole-v1",
                "--steps",
                "50",
                "--quiet",
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    for c in [a, b] {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let mut names: Vec<String> = std::fs::read_dir(dir.join("runs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 2, "{names:?}");
    for n in &names {
        assert!(n.starts_with("CartPole-v1__dqn__0__"), "{n}");
        assert!(
            dir.join("runs").join(n).join("summary.json").exists(),
            "{n}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
