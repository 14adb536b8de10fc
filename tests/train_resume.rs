//! `tandem train` survives interruption: a run killed with SIGKILL after a checkpoint, or
//! stopped by SIGINT/SIGTERM at any moment, resumes from its directory (`--resume DIR`) and ends
//! with exactly the files of an uninterrupted run (timings aside); a resume that conflicts with
//! the recorded run, or a corrupted checkpoint, is refused.
#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn tandem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tandem-resume-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Small SAC networks on Pendulum, checkpoints every 150 steps, evaluations every 500.
const CONFIG: &str = "[agent]\nhidden = [24, 24]\nbatch_size = 32\nlearning_starts = 100\n\
                      [train]\neval_interval = 500\neval_episodes = 2\ncheckpoint_interval = 150\n";
const STEPS: &str = "6000";

fn setup(name: &str) -> (PathBuf, PathBuf) {
    let dir = tmp(name);
    let cfg = dir.join("small.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    (dir, cfg)
}

fn train(cfg: &Path, out: &Path) -> Command {
    let mut c = tandem();
    c.args([
        "train",
        "--algo",
        "sac",
        "--env",
        "Pendulum-v1",
        "--seed",
        "2",
        "--quiet",
    ])
    .args(["--steps", STEPS])
    .arg("--config")
    .arg(cfg)
    .arg("--out")
    .arg(out)
    .stdout(Stdio::null())
    .stderr(Stdio::piped());
    c
}

fn resume(dir: &Path, extra: &[&str]) -> Output {
    tandem()
        .args(["train", "--quiet", "--resume"])
        .arg(dir)
        .args(extra)
        .output()
        .unwrap()
}

fn text(o: &[u8]) -> String {
    String::from_utf8_lossy(o).into_owned()
}

/// Waits until `path` exists (the child has written its first checkpoint).
fn wait_for(path: &Path, child: &mut Child) {
    let start = Instant::now();
    while !path.exists() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before writing {}",
            path.display()
        );
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no {}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args(["-s", sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -s {sig}");
}

/// Every file the run writes equals `reference`'s, and the summary does apart from its timings
/// and the directory's name.
fn assert_same_run(reference: &Path, run: &Path) {
    for f in [
        "config.toml",
        "metrics.csv",
        "episodes.csv",
        "curve.svg",
        "checkpoint.safetensors",
    ] {
        let (a, b) = (
            std::fs::read(reference.join(f)).unwrap(),
            std::fs::read(run.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs from the uninterrupted run's");
    }
    let summary = |d: &Path| {
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap())
                .unwrap();
        let m = v.as_object_mut().unwrap();
        for timing in [
            "wall_seconds",
            "train_seconds",
            "env_steps_per_second",
            "checkpoint",
        ] {
            assert!(m.remove(timing).is_some(), "{timing}");
        }
        v
    };
    assert_eq!(summary(reference), summary(run));
    assert!(!run.join(".tandem.lock").exists());
    let names: Vec<String> = std::fs::read_dir(run)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(
        !names.iter().any(|n| n.ends_with(".tmp")),
        "temporary files left: {names:?}"
    );
}

fn uninterrupted(dir: &Path, cfg: &Path) -> PathBuf {
    let whole = dir.join("whole");
    let o = train(cfg, &whole).output().unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    whole
}

#[test]
fn a_run_killed_after_a_checkpoint_resumes_to_the_uninterrupted_files() {
    let (dir, cfg) = setup("kill");
    let whole = uninterrupted(&dir, &cfg);
    let cut = dir.join("cut");
    let mut child = train(&cfg, &cut).spawn().unwrap();
    wait_for(&cut.join("checkpoint.safetensors"), &mut child);
    child.kill().unwrap(); // SIGKILL: no handler runs.
    child.wait().unwrap();
    assert!(
        cut.join(".tandem.lock").exists(),
        "a killed run leaves its lock"
    );
    assert!(!cut.join("summary.json").exists());

    let o = resume(&cut, &[]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("took over") && err.contains("resuming"),
        "{err}"
    );
    assert_same_run(&whole, &cut);
    // Resuming a finished run changes nothing.
    let o = resume(&cut, &[]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_same_run(&whole, &cut);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigint_and_sigterm_save_an_interrupted_run_that_resumes_exactly() {
    let (dir, cfg) = setup("signals");
    let whole = uninterrupted(&dir, &cfg);
    // Stopped as soon as the run directory exists (before or at its first steps), and later,
    // mid-run: both leave a checkpoint, a summary marked interrupted, and exit 130 / 143.
    for (name, sig, code, wait_file) in [
        ("int-early", "INT", 130, "config.toml"),
        ("term-mid", "TERM", 143, "metrics.csv"),
    ] {
        let cut = dir.join(name);
        let mut child = train(&cfg, &cut).spawn().unwrap();
        wait_for(&cut.join(wait_file), &mut child);
        signal(&child, sig);
        let o = child.wait_with_output().unwrap();
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{name}: {err}");
        assert!(
            err.contains("interrupted") && err.contains("--resume"),
            "{err}"
        );
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(cut.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(summary["status"], "interrupted", "{name}");
        let steps = summary["steps"].as_u64().unwrap();
        // A signal before the first step stops the run at step 0, saved like any other.
        assert!(steps < 6000, "{name}: stopped at {steps}");
        assert!(cut.join("checkpoint.safetensors").exists());

        let o = resume(&cut, &[]);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        assert_same_run(&whole, &cut);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_resume_that_conflicts_with_the_run_or_a_corrupt_checkpoint_is_refused() {
    let (dir, cfg) = setup("conflicts");
    let run = dir.join("run");
    let mut child = train(&cfg, &run).spawn().unwrap();
    wait_for(&run.join("checkpoint.safetensors"), &mut child);
    signal(&child, "INT");
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let before = std::fs::read(run.join("checkpoint.safetensors")).unwrap();

    let other_cfg = dir.join("other.toml");
    std::fs::write(&other_cfg, CONFIG.replace("[24, 24]", "[32, 32]")).unwrap();
    let other = other_cfg.to_str().unwrap();
    for (extra, needle) in [
        (&["--seed", "3"][..], "--seed 3 (the run has 2)"),
        (&["--steps", "7000"][..], "--steps 7000 (the run has 6000)"),
        (&["--algo", "ddpg"][..], "--algo ddpg (the run has sac)"),
        (&["--env", "CartPole-v1"][..], "--env CartPole-v1"),
        (&["--config", other][..], "its settings differ"),
    ] {
        let o = resume(&run, extra);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {err}");
        assert!(err.contains(needle) && err.contains("conflicts"), "{err}");
    }
    let o = resume(&dir.join("nothing-here"), &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("not a `tandem train` run directory"), "{err}");

    // One flipped byte in the weights: the checksum refuses the checkpoint.
    let mut bad = before.clone();
    let k = bad.len() - 7;
    bad[k] ^= 0x10;
    std::fs::write(run.join("checkpoint.safetensors"), &bad).unwrap();
    let o = resume(&run, &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("checksum mismatch"), "{err}");

    // The same settings spelled out are accepted.
    std::fs::write(run.join("checkpoint.safetensors"), &before).unwrap();
    let o = resume(&run, &["--seed", "2", "--steps", STEPS, "--algo", "sac"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}
