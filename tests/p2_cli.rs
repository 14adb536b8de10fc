//! `tandem reproduce p2-cartpole --quick` end to end: the files it writes, their shape, and an
//! existing reproduction refused without `--overwrite`.

use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

#[test]
fn quick_reproduction_writes_the_table_the_figure_and_the_runs() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-cartpole-quick");
    let _ = std::fs::remove_dir_all(&out);
    let o = out.to_str().unwrap();
    let run = |extra: &[&str]| {
        let base = [
            "reproduce",
            "p2-cartpole",
            "--quick",
            "--quiet",
            "--seeds",
            "2",
        ];
        Command::new(env!("CARGO_BIN_EXE_tandem"))
            .args(base.iter().chain(["--out", o].iter()).chain(extra))
            .output()
            .expect("the tandem binary runs")
    };
    let first = run(&[]);
    let err = String::from_utf8_lossy(&first.stderr);
    assert!(first.status.success(), "{err}");
    let table: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    for m in ["model_free", "with_model"] {
        let e = &table[m]["episodes_to_solve"];
        assert_eq!(e["per_seed"].as_array().unwrap().len(), 2, "{m}: {e}");
        assert!(e.get("mean").is_some() && e.get("stderr").is_some(), "{e}");
        for seed in 0..2 {
            let dir = out.join("runs").join(format!("{m}__seed{seed}"));
            let rec: Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join("record.json")).unwrap())
                    .unwrap();
            // --quick: 20 real episodes unless solved earlier (window 10, return 475).
            let n = rec["real_returns"].as_array().unwrap().len();
            assert!((10..=20).contains(&n), "{m} seed {seed}: {n} episodes");
            let csv = std::fs::read_to_string(dir.join("curve.csv")).unwrap();
            assert_eq!(csv.lines().count(), n + 1, "{csv}");
        }
    }
    assert!(
        table["with_model"]["mean_imagined_episodes"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert_eq!(table["model_free"]["mean_imagined_episodes"], 0.0);
    assert!(
        table["with_model_over_model_free"]["ratio"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(md.contains("REINFORCE with the model"), "{md}");
    let svg = std::fs::read_to_string(out.join("fig6.svg")).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("with_model"),
        "{svg}"
    );
    let config: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["status"], "complete");

    // Again into the same directory: refused, then replaced with --overwrite.
    let again = run(&[]);
    assert!(!again.status.success());
    assert!(!String::from_utf8_lossy(&again.stderr).contains("panicked"));
    let over = run(&["--overwrite"]);
    assert!(
        over.status.success(),
        "{}",
        String::from_utf8_lossy(&over.stderr)
    );
}

/// `tandem reproduce p2-maze --quick`: DQN alone and with the pixel model on seed 3
/// (`--first-seed`), and the pixel model's F1 experiment (on seed 3 by a `[quality]` table in
/// `--config`) with its picture.
#[test]
fn quick_maze_reproduction_writes_the_f1_table_and_the_frames() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-maze-quick");
    let _ = std::fs::remove_dir_all(&out);
    let o = out.to_str().unwrap();
    let cfg = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-maze-quick.toml");
    std::fs::write(&cfg, "[quality]\nseeds = [3]\n").unwrap();
    let args = [
        "reproduce",
        "p2-maze",
        "--quick",
        "--quiet",
        "--seeds",
        "1",
        "--first-seed",
        "3",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        o,
    ];
    let r = Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap();
    let table: Value = serde_json::from_str(&read("table.json")).unwrap();
    for m in ["model_free", "with_model"] {
        assert_eq!(table[m]["seeds"], serde_json::json!([3]), "{m}");
        let rec: Value =
            serde_json::from_str(&read(&format!("runs/{m}__seed3/record.json"))).unwrap();
        let n = rec["real_returns"].as_array().unwrap().len();
        assert!((10..=20).contains(&n), "{m}: {n} episodes");
    }
    // --quick: the model method imagines after its first 5 real episodes.
    assert!(
        table["with_model"]["mean_imagined_episodes"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    // The F1 table: after 2 and 5 training episodes (--quick), each channel a score in [0, 1].
    let f1 = table["f1"].as_object().unwrap();
    assert_eq!(
        f1.keys().collect::<Vec<_>>(),
        ["after_2", "after_5"],
        "{f1:?}"
    );
    for row in f1.values() {
        for ch in ["agent", "obstacles", "goal"] {
            let v = row[ch].as_f64().unwrap();
            assert!((0.0..=1.0).contains(&v), "{ch}: {v}");
        }
    }
    let quality: Value = serde_json::from_str(&read("quality.json")).unwrap();
    assert_eq!(quality.as_array().unwrap().len(), 1); // the F1 experiment on seed 3
    assert_eq!(quality[0]["seed"], 3);
    let f1_curve = read("runs/model_f1__seed3/curve.csv");
    assert_eq!(f1_curve.lines().count(), 3, "{f1_curve}"); // header, after 2, after 5
    let md = read("table.md");
    assert!(
        md.contains("DQN with the model") && md.contains("| 5 |"),
        "{md}"
    );
    let fig7 = read("fig7.svg");
    assert!(
        fig7.starts_with("<svg") && fig7.contains("after 5"),
        "{fig7}"
    );
    assert!(read("fig8.svg").contains("with_model"));
}

#[test]
fn env_is_a_maze_option_and_unknown_mazes_are_errors() {
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_tandem"))
            .args(args)
            .output()
            .expect("the tandem binary runs")
    };
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-env-errors");
    let o = out.to_str().unwrap();
    let v0 = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-env-v0.toml");
    std::fs::write(&v0, "env = \"PixelMaze-v0\"\n").unwrap();
    let v0 = v0.to_str().unwrap();
    for (args, says) in [
        (
            vec![
                "reproduce",
                "p2-maze",
                "--env",
                "PixelMaze-v1",
                "--config",
                v0,
            ],
            "says env = \"PixelMaze-v0\"",
        ),
        (
            vec!["reproduce", "p2-cartpole", "--env", "PixelMaze-v1"],
            "p2-maze only",
        ),
        (
            vec!["reproduce", "p2-maze", "--env", "PixelMaze-v7"],
            "not a pixel maze",
        ),
    ] {
        let r = run(&[&args[..], &["--quick", "--quiet", "--out", o]].concat());
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(says) && !err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{args:?} wrote {o}");
    }
}

/// `tandem reproduce p2-maze` killed (SIGKILL) once a run has a checkpoint and resumed ends with
/// the table, figure, curves and records of an uninterrupted run (wall times aside) and no state
/// left; a second seed run as its own process and `tandem reproduce merge` give the table of
/// one process running both seeds.
#[cfg(unix)]
#[test]
fn a_killed_maze_reproduction_resumes_and_separate_seeds_merge_to_the_same_table() {
    use std::path::Path;
    use std::process::Stdio;
    use std::time::{Duration, Instant};

    let root = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("p2-maze-resume");
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let cfg = root.join("often.toml");
    std::fs::write(&cfg, "checkpoint_every = 4\n").unwrap();
    let cfg = cfg.to_str().unwrap();
    let tandem = |args: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_tandem"));
        c.args(args).stdout(Stdio::null()).stderr(Stdio::piped());
        c
    };
    let fresh = |out: &Path, seeds: &str, first: &str| {
        let o = out.to_str().unwrap().to_string();
        let args = [
            "reproduce",
            "p2-maze",
            "--quick",
            "--quiet",
            "--config",
            cfg,
            "--seeds",
            seeds,
            "--first-seed",
            first,
            "--out",
            &o,
        ];
        tandem(&args)
    };
    let ok = |mut c: Command| {
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };

    let whole = root.join("whole");
    ok(fresh(&whole, "2", "0"));

    let cut = root.join("cut");
    let mut child = fresh(&cut, "1", "0").spawn().unwrap();
    let ckpt = cut.join("state/seed0/model_free/model_free.safetensors");
    let start = Instant::now();
    while !ckpt.exists() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "finished before a checkpoint"
        );
        assert!(start.elapsed() < Duration::from_secs(120));
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    ok(tandem(&[
        "reproduce",
        "p2-maze",
        "--quiet",
        "--resume",
        cut.to_str().unwrap(),
    ]));
    assert!(!cut.join("state").exists() && !cut.join(".tandem.lock").exists());
    let record = |d: &Path, run: &str| {
        let text = std::fs::read_to_string(d.join("runs").join(run).join("record.json")).unwrap();
        let mut r: Value = serde_json::from_str(&text).unwrap();
        r["wall_seconds"] = Value::Null;
        r
    };
    for run in ["model_f1__seed0", "model_free__seed0", "with_model__seed0"] {
        assert_eq!(record(&whole, run), record(&cut, run), "{run}");
        let curve = |d: &Path| std::fs::read_to_string(d.join("runs").join(run).join("curve.csv"));
        assert_eq!(curve(&whole).unwrap(), curve(&cut).unwrap(), "{run}");
    }

    let other = root.join("seed1");
    ok(fresh(&other, "1", "1"));
    assert!(
        !other.join("runs/model_f1__seed1").exists(),
        "F1 runs on seed 0 only"
    );
    let merged = root.join("merged");
    ok(tandem(&[
        "reproduce",
        "merge",
        cut.to_str().unwrap(),
        other.to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
    ]));
    for f in ["table.json", "fig8.svg", "fig7.svg"] {
        let same = std::fs::read(whole.join(f)).unwrap() == std::fs::read(merged.join(f)).unwrap();
        assert!(same, "{f} differs");
    }
    std::fs::remove_dir_all(&root).ok();
}
