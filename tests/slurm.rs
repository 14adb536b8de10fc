//! Sweeps on a live SLURM: `tandem reproduce <study> --slurm` submits a job array of cells and a
//! merge job, and the merged table equals one local run of the same study byte for byte, also
//! when a task is requeued (`scontrol requeue`: SIGTERM, then a new start) mid-run.
//!
//! They need a running SLURM (`scripts/setup-slurm.sh` starts one on this machine) and
//! `SLURM_CONF` pointing at it, so they are ignored by default; `.ci/run` runs them after the
//! setup: `cargo test --test slurm -- --ignored --test-threads=1`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs")
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn slurm(program: &str, args: &[&str]) -> String {
    let o = Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{program} does not run ({e}): start scripts/setup-slurm.sh"));
    assert!(
        o.status.success(),
        "{program} {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn root(name: &str) -> PathBuf {
    let r = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("slurm-{name}"));
    let _ = std::fs::remove_dir_all(&r);
    std::fs::create_dir_all(&r).unwrap();
    r
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json(path: &Path) -> Option<Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Polls `done` every half second for at most `limit`; on timeout shows the queue and the logs.
fn wait_for(what: &str, sweep: &Path, limit: Duration, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        if start.elapsed() > limit {
            let queue = slurm("squeue", &["-r"]);
            let status = tandem(&["sweep", "status", s(sweep)]);
            panic!(
                "{what}: not after {limit:?}\nsqueue:\n{queue}\nstatus:\n{}{}",
                String::from_utf8_lossy(&status.stdout),
                String::from_utf8_lossy(&status.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(500));
    }
}

fn merged(sweep: &Path) -> bool {
    json(&sweep.join("merged/config.json")).is_some_and(|c| c["status"] == "complete")
}

/// `p3-leg --quick` of `seeds` seeds and `methods`, with `extra` arguments, run here into `out`
/// or (`sweep`) submitted as a sweep with its directory `out`.
fn p3_leg(out: &Path, methods: &str, extra: &[&str], sweep: bool) -> String {
    let mut args = vec![
        "reproduce",
        "p3-leg",
        "--quick",
        "--quiet",
        "--seeds",
        "2",
        "--methods",
        methods,
        "--out",
        s(out),
    ];
    args.extend(extra);
    if sweep {
        args.extend(["--slurm", "--time", "0:30:00", "--grace", "60"]);
    }
    ok(&tandem(&args))
}

fn same_table(local: &Path, sweep: &Path) {
    let one = std::fs::read(local.join("table.json")).unwrap();
    let merged = std::fs::read(sweep.join("merged/table.json")).unwrap();
    assert!(
        one == merged,
        "the merged table differs from the local run's:\n{}\n{}",
        String::from_utf8_lossy(&one),
        String::from_utf8_lossy(&merged)
    );
}

#[test]
#[ignore = "needs a live SLURM (scripts/setup-slurm.sh)"]
fn a_sweep_of_cells_merges_to_the_table_of_one_local_run() {
    let root = root("sweep");
    let sweep = root.join("sweep");
    let submitted = p3_leg(&sweep, "sac,mbpo", &[], true);
    assert!(
        submitted.contains("submitted 4 cells as array job"),
        "{submitted}"
    );
    let local = root.join("local");
    p3_leg(&local, "sac,mbpo", &[], false);
    wait_for(
        "the merge job's table",
        &sweep,
        Duration::from_secs(300),
        || merged(&sweep),
    );
    same_table(&local, &sweep);
    let status = ok(&tandem(&["sweep", "status", s(&sweep)]));
    assert!(
        status.contains("4 of 4 cells done; merged: yes"),
        "{status}"
    );
    for (task, seed, method) in [(0, 0, "sac"), (1, 0, "mbpo"), (2, 1, "sac"), (3, 1, "mbpo")] {
        let line = status
            .lines()
            .find(|l| l.split_whitespace().next() == Some(&task.to_string()))
            .unwrap_or_else(|| panic!("no task {task} in:\n{status}"));
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(words[1..4], [&seed.to_string(), method, "done"], "{line}");
    }
    // Each task ran once; one started again exits at once, leaving the cell as it was.
    let record = sweep.join("cells/seed1-mbpo/runs/mbpo__seed1/record.json");
    let before = std::fs::read(&record).unwrap();
    let o = tandem(&["sweep", "task", s(&sweep), "3"]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("finished already"));
    assert_eq!(std::fs::read(&record).unwrap(), before);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
#[ignore = "needs a live SLURM (scripts/setup-slurm.sh)"]
fn a_task_requeued_mid_run_resumes_and_the_table_is_unchanged() {
    let root = root("requeue");
    // Long enough (seconds) to be caught running, with a checkpoint every 150 steps.
    let config = root.join("long.toml");
    std::fs::write(&config, "[p3.base]\nreal_steps = 60000\n").unwrap();
    let sweep = root.join("sweep");
    let extra = ["--config", s(&config)];
    let submitted = p3_leg(&sweep, "sac", &extra, true);
    let array = submitted
        .split("array job ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("no array job id in {submitted}"))
        .trim_end_matches(',')
        .to_string();
    let task = format!("{array}_0");
    // Running, with a checkpoint on disk.
    let state = sweep.join("cells/seed0-sac/state");
    wait_for(
        "task 0 checkpointing",
        &sweep,
        Duration::from_secs(120),
        || state.exists(),
    );
    slurm("scontrol", &["requeue", &task]);
    // SLURM holds a requeued job for two minutes; let it start again now.
    let requeued = Instant::now();
    wait_for("task 0 requeued", &sweep, Duration::from_secs(60), || {
        let q = slurm("squeue", &["-h", "-r", "-j", &task, "-o", "%T"]);
        q.trim() == "PENDING" || q.trim() == "REQUEUED"
    });
    while requeued.elapsed() < Duration::from_secs(60) {
        let o = Command::new("scontrol")
            .args(["update", &format!("JobId={task}"), "StartTime=now"])
            .output()
            .unwrap();
        if o.status.success() {
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let local = root.join("local");
    p3_leg(&local, "sac", &extra, false);
    wait_for(
        "the merge job's table",
        &sweep,
        Duration::from_secs(300),
        || merged(&sweep),
    );
    same_table(&local, &sweep);
    let starts = json(&sweep.join("tasks/0.json")).unwrap();
    let modes: Vec<&str> = starts
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["mode"].as_str().unwrap())
        .collect();
    assert_eq!(modes, ["started", "resumed"], "{starts}");
    let status = ok(&tandem(&["sweep", "status", s(&sweep)]));
    let line = status
        .lines()
        .find(|l| l.split_whitespace().next() == Some("0"))
        .unwrap();
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(words[3..5], ["done", "1"], "resumed once: {status}");
    let log = std::fs::read_to_string(sweep.join(format!("logs/{array}_0.out"))).unwrap();
    assert!(
        log.contains("interrupted"),
        "the first start stopped on SIGTERM: {log}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
