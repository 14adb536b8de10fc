//! `tandem train` end to end: a short run writes every file with the promised fields, and bad
//! input (wrong action space, unknown config key, out-of-range value, unknown algorithm) is a
//! clear error with exit status 1.

use std::path::PathBuf;
use std::process::Command;

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
}
