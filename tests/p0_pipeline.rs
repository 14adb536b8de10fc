//! Smoke tests of p0's pipeline (seconds): exact true-sample accounting, the data the difference
//! model is fitted on, determinism, and the `tandem reproduce p0-pendulum --quick` outputs.

use std::cell::Cell;
use std::collections::BTreeMap;
use tandem::agents::NoiseConfig;
use tandem::core::{Action, Space};
use tandem::envs::{SampleCounter, Task};
use tandem::make_env as make;
use tandem::robots::{DcMotorPendulum, DcMotorPendulumParams};

use tandem::algos::difference_models::{
    agent_spaces, collect, ddpg_agent, leo_problem, p0_loop, pendulum_problem, run_seed, Method,
    P0Config, RunRecord, LEO_VOLTAGE_LIMIT,
};
use tandem::algos::{AlgoError, Checkpoints, Ephemeral, Result};
use tandem::nn::Checkpoint;

/// A configuration small enough for a test: tiny networks and budgets.
fn tiny() -> P0Config {
    let mut c = P0Config::default().with_networks(&[16], 5000);
    c.pretrain_steps = 300;
    c.real_batch = 250;
    c.real_budget = 500;
    c.baseline_max_samples = 700;
    c.baseline_stop_early = false;
    c.eval_interval = 300;
    c.model_steps = 200;
    c.fit.epochs = 2;
    c
}

fn run(cfg: &P0Config, seed: u64) -> Vec<RunRecord> {
    run_with(cfg, seed, &mut Ephemeral).unwrap()
}

fn run_with(cfg: &P0Config, seed: u64, store: &mut dyn Checkpoints) -> Result<Vec<RunRecord>> {
    let problem = pendulum_problem();
    run_seed(
        &problem,
        cfg,
        &Method::ALL,
        seed,
        &|m, s| ddpg_agent(cfg, &problem.real.task, m, s),
        store,
        &mut |_| {},
    )
}

/// Checkpoints kept in memory (as bytes, so they go through the file format), asking to stop
/// at the `stop_at`-th poll (one poll per step).
#[derive(Default)]
struct Memory {
    files: BTreeMap<String, Vec<u8>>,
    polls: Cell<u64>,
    stop_at: Option<u64>,
    saves: usize,
}

impl Checkpoints for Memory {
    fn load(&mut self, key: &str) -> Result<Option<Checkpoint>> {
        let bytes = self.files.get(key);
        Ok(bytes.map(|b| Checkpoint::from_bytes(b)).transpose()?)
    }
    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> Result<()> {
        self.saves += 1;
        self.files.insert(key.to_string(), ckpt.to_bytes()?);
        Ok(())
    }
    fn stop_requested(&self) -> bool {
        self.polls.set(self.polls.get() + 1);
        self.stop_at.is_some_and(|n| self.polls.get() >= n)
    }
}

fn without_timing(mut r: Vec<RunRecord>) -> Vec<RunRecord> {
    r.iter_mut().for_each(|r| r.wall_seconds = 0.0);
    r
}

/// Stopped in pre-training, in each method's first iteration and in the difference model's
/// second round, then resumed (as many times as it takes) from the checkpoints: every record
/// equals the uninterrupted run's, and equal runs save equal bytes.
#[test]
fn a_seed_stopped_anywhere_resumes_from_its_checkpoints_to_the_same_records() {
    let cfg = tiny();
    let mut whole = Memory::default();
    let reference = without_timing(run_with(&cfg, 4, &mut whole).unwrap());
    assert_eq!(without_timing(run(&cfg, 4)), reference);
    // Pre-training 300 steps; cold 700 and warm 700 true samples; difference 2 x (250 + 200).
    for stop_at in [150, 650, 1500, 2300] {
        let mut store = Memory {
            stop_at: Some(stop_at),
            ..Memory::default()
        };
        let e = run_with(&cfg, 4, &mut store).unwrap_err();
        assert!(matches!(e, AlgoError::Stopped), "{e}");
        store.stop_at = None;
        let resumed = without_timing(run_with(&cfg, 4, &mut store).unwrap());
        assert_eq!(resumed, reference, "stopped at poll {stop_at}");
        for (key, bytes) in &whole.files {
            assert!(store.files.get(key) == Some(bytes), "{key} differs");
        }
    }
}

#[test]
fn true_samples_are_counted_exactly_and_runs_are_deterministic() {
    let cfg = tiny();
    let a = run(&cfg, 3);
    let by = |m: Method| a.iter().find(|r| r.method == m).unwrap();
    // The difference method: 0 before any true sample, then one point per batch of 250.
    let d = by(Method::Difference);
    let xs: Vec<u64> = d.curve.iter().map(|p| p.true_samples).collect();
    assert_eq!(xs, vec![0, 250, 500]);
    assert_eq!(d.true_samples, 500);
    assert_eq!(d.simulated_steps, 400);
    assert_eq!(d.fit_holdout_loss.len(), 2);
    // Cold and warm: evaluated every 300 true samples, capped at 700.
    for m in [Method::Cold, Method::Warm] {
        let xs: Vec<u64> = by(m).curve.iter().map(|p| p.true_samples).collect();
        assert_eq!(xs, vec![0, 300, 600, 700], "{m:?}");
        assert_eq!(by(m).true_samples, 700);
    }
    // Warm start and the difference method start from the same pre-trained policy.
    assert_eq!(by(Method::Warm).curve[0], d.curve[0]);
    assert!(a.iter().all(|r| r
        .curve
        .iter()
        .all(|p| p.eval_return.is_finite() && p.eval_return < 0.0)));
    // Same seed, same numbers.
    let b = run(&cfg, 3);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(
            (x.method, &x.curve, x.updates),
            (y.method, &y.curve, y.updates)
        );
        assert_eq!(x.fit_holdout_loss, y.fit_holdout_loss);
    }
}

/// The transitions the difference model learns from are true-plant transitions from canonical
/// (wrapped) states, without 2π jumps when the pendulum passes the bottom.
#[test]
fn collected_transitions_are_true_plant_steps_from_wrapped_states() {
    let mut cfg = tiny();
    cfg.cold_noise = NoiseConfig::OrnsteinUhlenbeck {
        theta: 0.15,
        sigma: 1.0,
        dt: 1.0,
    };
    let problem = pendulum_problem();
    let agent = ddpg_agent(&cfg, &problem.real.task, Method::Cold, 0).unwrap();
    let (obs, act) = agent_spaces(&problem.real.task);
    let rng = tandem::core::seeding::rng_from_seed(0);
    let mut lp = p0_loop(agent, &cfg.ddpg, &obs, &act, rng).unwrap();
    let (mut env, count) = SampleCounter::new(make("DcMotorPendulum-real-v0").unwrap());
    let data = collect(&mut lp, &mut env, &problem.real.task, 900, 5, &mut || {}).unwrap();
    // Collecting neither stores nor learns.
    assert_eq!((lp.primary().len(), lp.counts().updates), (0, 0));
    assert_eq!(lp.counts().real_steps, 900);
    assert_eq!((data.len(), count.get()), (900, 900));
    let real = DcMotorPendulum::new(DcMotorPendulumParams::real());
    let mut crossed = 0;
    for i in 0..data.len() {
        let s = [data.states[[i, 0]], data.states[[i, 1]]];
        assert!((-std::f64::consts::PI..std::f64::consts::PI).contains(&s[0]));
        let want = real.step_array(&s, data.actions[[i, 0]]);
        for (k, w) in want.iter().enumerate() {
            assert!((data.next_states[[i, k]] - w).abs() < 1e-9, "row {i}");
        }
        crossed += usize::from(want[0].abs() > std::f64::consts::PI);
    }
    assert!(
        crossed > 0,
        "the noisy policy should swing past the bottom (±π) at least once"
    );
}

#[test]
fn reproduce_quick_writes_table_ii_and_fig_5() {
    let out = std::env::temp_dir().join(format!("tandem-p0-quick-{}", std::process::id()));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args([
            "reproduce",
            "p0-pendulum",
            "--quick",
            "--seeds",
            "2",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    for m in ["cold", "warm", "difference"] {
        let r = &table[m]["return_at_budget"];
        assert!(r["mean"].as_f64().unwrap() < 0.0, "{m}");
        assert!(r["stderr"].as_f64().unwrap() >= 0.0);
        assert_eq!(r["per_seed"].as_array().unwrap().len(), 2);
        let t = &table[m]["samples_to_target"];
        assert_eq!(t["per_seed"].as_array().unwrap().len(), 2);
        assert!(t.get("mean").is_some());
        assert!(out.join(format!("runs/{m}__seed1/curve.csv")).exists());
    }
    // The small-batch row (400 true samples per update, the quick budget 800): two updates.
    let small = &table["difference_small_batch"]["return_at_budget"];
    assert_eq!(small["per_seed"].as_array().unwrap().len(), 2);
    assert!(table.get("cold_over_difference_small_batch").is_some());
    let rec: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("runs/difference_small_batch__seed0/record.json"))
            .unwrap(),
    )
    .unwrap();
    let samples: Vec<u64> = rec["curve"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["true_samples"].as_u64().unwrap())
        .collect();
    assert_eq!(samples, [0, 400, 800]);
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(md.contains("Difference model") && md.contains("not counted"));
    assert!(md.contains("Difference model, small batch") && md.contains("batch of 400"));
    let svg = std::fs::read_to_string(out.join("fig5.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("difference"));
    std::fs::remove_dir_all(&out).ok();
}

/// `tandem reproduce p0-pendulum` killed (SIGKILL) once it has checkpoints, resumed, stopped by
/// SIGINT, resumed again: the tables, figure and every run's curve and record equal an
/// uninterrupted run's (wall times aside), and no checkpoint is left behind.
#[cfg(unix)]
#[test]
fn reproduce_killed_and_interrupted_resumes_to_the_uninterrupted_outputs() {
    use std::path::Path;
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    let root = std::env::temp_dir().join(format!("tandem-p0-resume-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let cfg = root.join("longer.toml");
    std::fs::write(
        &cfg,
        "baseline_max_samples = 4000\nreal_budget = 2000\nmodel_steps = 1500\n",
    )
    .unwrap();
    let reproduce = |extra: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_tandem"));
        c.args(["reproduce", "p0-pendulum", "--quiet", "--jobs", "2"])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        c
    };
    let fresh = |out: &Path| {
        let mut c = reproduce(&["--quick", "--seeds", "1", "--config"]);
        c.arg(&cfg).arg("--out").arg(out);
        c
    };
    let resume = |out: &Path| {
        let o = reproduce(&["--resume", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    // Waits until the run has saved `n` checkpoint files or finished records.
    let wait_for_files = |out: &Path, child: &mut std::process::Child, n: usize| {
        let start = Instant::now();
        let count = || {
            let state = std::fs::read_dir(out.join("state/seed0")).map_or(0, |d| d.count());
            let done = std::fs::read_dir(out.join("runs")).map_or(0, |d| d.count());
            state + done
        };
        while count() < n {
            assert!(child.try_wait().unwrap().is_none(), "finished too early");
            assert!(start.elapsed() < Duration::from_secs(120));
            std::thread::sleep(Duration::from_millis(5));
        }
    };

    let whole = root.join("whole");
    let o = fresh(&whole).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let cut = root.join("cut");
    let mut child = fresh(&cut).spawn().unwrap();
    wait_for_files(&cut, &mut child, 1);
    child.kill().unwrap();
    child.wait().unwrap();
    let mut child = reproduce(&["--resume", cut.to_str().unwrap()])
        .spawn()
        .unwrap();
    wait_for_files(&cut, &mut child, 3);
    let ok = Command::new("kill")
        .args(["-s", "INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("--resume"), "{err}");
    let config = std::fs::read_to_string(cut.join("config.json")).unwrap();
    assert!(config.contains("\"status\": \"interrupted\""), "{config}");
    resume(&cut);

    for f in ["table.json", "fig5.svg"] {
        let same = std::fs::read(whole.join(f)).unwrap() == std::fs::read(cut.join(f)).unwrap();
        assert!(same, "{f} differs");
    }
    for m in ["cold", "warm", "difference"] {
        let sub = format!("runs/{m}__seed0");
        let curve = |d: &Path| std::fs::read_to_string(d.join(&sub).join("curve.csv")).unwrap();
        assert_eq!(curve(&whole), curve(&cut), "{m}");
        let record = |d: &Path| {
            let text = std::fs::read_to_string(d.join(&sub).join("record.json")).unwrap();
            let mut r: RunRecord = serde_json::from_str(&text).unwrap();
            r.wall_seconds = 0.0;
            r
        };
        assert_eq!(record(&whole), record(&cut), "{m}");
    }
    assert!(!cut.join("state").exists() && !cut.join(".tandem.lock").exists());
    let _ = std::fs::remove_dir_all(&root);
}

/// Seeds run as separate processes (`--first-seed`) and merged give the table and figure of one
/// process running them all; overlapping seeds, other settings and unfinished parts are refused.
#[test]
fn seeds_run_apart_and_merged_equal_one_run_of_all_seeds() {
    use std::process::Command;
    let root = std::env::temp_dir().join(format!("tandem-p0-merge-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let tandem = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_tandem"))
            .args(args)
            .output()
            .unwrap()
    };
    let p = |name: &str| root.join(name).to_str().unwrap().to_string();
    let quick = ["reproduce", "p0-pendulum", "--quick", "--quiet"];
    for (out, extra) in [
        ("all", &["--seeds", "2"][..]),
        ("s0", &["--seeds", "1"][..]),
        ("s1", &["--seeds", "1", "--first-seed", "1"][..]),
        (
            "s1-other",
            &["--seeds", "1", "--first-seed", "1", "--jobs", "1"][..],
        ),
    ] {
        let o = tandem(&[&quick[..], extra, &["--out", &p(out)]].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let o = tandem(&[
        "reproduce",
        "merge",
        &p("s1"),
        &p("s0"),
        "--out",
        &p("merged"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["table.json", "fig5.svg", "runs/difference__seed1/curve.csv"] {
        let a = std::fs::read(root.join("all").join(f)).unwrap();
        assert!(
            a == std::fs::read(root.join("merged").join(f)).unwrap(),
            "{f}"
        );
    }
    let fails = |args: &[&str], needle: &str| {
        let o = tandem(args);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(needle), "{err}");
    };
    fails(
        &[
            "reproduce",
            "merge",
            &p("s1"),
            &p("s1-other"),
            "--out",
            &p("m2"),
        ],
        "seed 1's warm run is in two",
    );
    // Another configuration does not merge.
    let cfg = root.join("other.toml");
    std::fs::write(&cfg, "model_steps = 300\n").unwrap();
    let o = tandem(
        &[
            &quick[..],
            &["--seeds", "1", "--first-seed", "2", "--config"],
            &[cfg.to_str().unwrap(), "--out", &p("s2")],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    fails(
        &["reproduce", "merge", &p("s0"), &p("s2"), "--out", &p("m3")],
        "settings differ",
    );
    // An unfinished part is refused.
    let c = root.join("s0/config.json");
    let text = std::fs::read_to_string(&c).unwrap();
    std::fs::write(&c, text.replace("\"complete\"", "\"interrupted\"")).unwrap();
    fails(
        &["reproduce", "merge", &p("s0"), &p("s1"), "--out", &p("m4")],
        "is interrupted",
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// A tiny Leo configuration: p0's Leo settings with small networks and budgets.
fn tiny_leo() -> P0Config {
    let mut c = P0Config::leo().with_networks(&[16], 5000);
    c.pretrain_steps = 300;
    c.real_batch = 300;
    c.real_budget = 600;
    c.baseline_max_samples = 600;
    c.eval_interval = 300;
    c.model_steps = 200;
    c.fit.epochs = 1;
    // A warm-up shorter than pre-training (Leo's 20 000 would leave these runs without updates).
    c.ddpg.learning_starts = 150;
    c
}

#[test]
fn p0_leo_runs_the_authors_task_on_both_bipeds() {
    let problem = leo_problem().unwrap();
    let mut true_env = (problem.real.env)().unwrap();
    let bounded = Space::symmetric(6, LEO_VOLTAGE_LIMIT);
    assert_eq!(problem.real.task.action_space(), &bounded);
    assert_eq!(true_env.action_space(), &bounded);
    // Both start mid-step, the right foot in the air: with the motors off the true biped
    // topples (a fall ends the episode) well before the 667-step limit.
    let start = problem
        .real
        .task
        .initial_state(&mut tandem::core::seeding::rng_from_seed(0));
    assert_eq!(true_env.reset(Some(1)), problem.real.task.observe(&start));
    let mut steps = 0;
    loop {
        let s = true_env.step(&Action::Continuous(vec![0.0; 6])).unwrap();
        steps += 1;
        assert!(s.reward.is_finite());
        if s.terminated || s.truncated {
            assert!(s.terminated && steps < 100, "fell after {steps} steps");
            break;
        }
    }
}

#[test]
fn leo_runs_measure_their_first_and_last_policy_on_the_same_episode_as_the_curve() {
    let cfg = tiny_leo();
    assert_eq!(
        cfg.methods(),
        [Method::Cold, Method::Warm, Method::Difference]
    );
    let problem = leo_problem().unwrap();
    let records = run_seed(
        &problem,
        &cfg,
        &cfg.methods(),
        3,
        &|m, s| ddpg_agent(&cfg, &problem.real.task, m, s),
        &mut Ephemeral,
        &mut |_| {},
    )
    .unwrap();
    for r in &records {
        let (start, last) = (r.start.as_ref().unwrap(), r.last.as_ref().unwrap());
        // The measured episodes are the curve's evaluation episodes: same start, same policy.
        assert_eq!(start.eval_return, r.curve[0].eval_return, "{:?}", r.method);
        assert_eq!(last.eval_return, r.curve.last().unwrap().eval_return);
        // Frames every 5 steps (first and last kept) of the 10 joint positions; the distance
        // is the torso's x at the last frame minus its start.
        assert_eq!(start.frame_every, 5);
        assert!(start.frames.iter().all(|f| f.len() == 10));
        let (first, end) = (&last.frames[0], last.frames.last().unwrap());
        let d = last.measures["distance_m"];
        assert!((d - (end[0] - first[0])).abs() < 1e-12);
        assert!(last.measures.contains_key("work_j") && last.measures.contains_key("fell"));
        // The true system counted: cold and warm use their 600 samples, the difference method
        // two batches of 300.
        assert_eq!(r.true_samples, 600);
    }
    // A fresh agent waits for its warm-up (updates from the 151st transition on), the
    // pre-trained one fine-tunes from its first minibatch of 64 (Leo's fine-tuning warm-up).
    assert_eq!(cfg.fine_tune_learning_starts, Some(0));
    let updates = |m: Method| records.iter().find(|r| r.method == m).unwrap().updates;
    assert_eq!(updates(Method::Cold), 600 - 150 + 1);
    assert_eq!(updates(Method::Warm), 600 - 64 + 1);
    // Warm start and the difference method start from the same pre-trained policy.
    let start = |m: Method| {
        records
            .iter()
            .find(|r| r.method == m)
            .unwrap()
            .start
            .clone()
    };
    assert_eq!(start(Method::Warm), start(Method::Difference));
    assert_ne!(start(Method::Warm), start(Method::Cold));
}

#[test]
fn reproduce_p0_leo_quick_writes_tables_iii_and_iv_fig_8_and_the_gaits() {
    let out = std::env::temp_dir().join(format!("tandem-p0-leo-quick-{}", std::process::id()));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args([
            "reproduce",
            "p0-leo",
            "--quick",
            "--seeds",
            "1",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap();
    let table: serde_json::Value = serde_json::from_str(&read("table.json")).unwrap();
    for m in ["cold", "warm", "difference"] {
        assert_eq!(table[m]["return_at_budget"]["budget"], 1400, "{m}");
        assert_eq!(table[m]["samples_to_target"]["target"], 560.0);
    }
    assert!(table.get("difference_small_batch").is_none());
    let t3: serde_json::Value = serde_json::from_str(&read("table3.json")).unwrap();
    for p in ["mu_idl", "mu_d", "mu_true"] {
        assert_eq!(t3[p]["seeds"], serde_json::json!([0]), "{p}");
        assert!(t3[p]["return"]["mean"].as_f64().is_some());
        assert!(t3[p]["distance_m"]["per_seed"][0].as_f64().is_some());
    }
    // μ^idl is the warm start's first policy: its return is the warm curve's first point.
    let warm: serde_json::Value =
        serde_json::from_str(&read("runs/warm__seed0/record.json")).unwrap();
    assert_eq!(
        t3["mu_idl"]["return"]["mean"],
        warm["curve"][0]["eval_return"]
    );
    let md = read("table.md");
    assert!(
        md.starts_with("# p0 Table IV on the Leo-like biped (1 seeds)"),
        "{md}"
    );
    assert!(md.contains("## p0 Table III") && md.contains("| μ^d (difference) |"));
    assert!(read("fig8.svg").contains("Fig. 8"));
    let gait = read("gait.svg");
    assert_eq!(
        gait.matches("<line").count(),
        3,
        "one ground line per policy"
    );
    assert!(gait.contains("μ^idl: return") && gait.contains("μ^true: return"));
    std::fs::remove_dir_all(&out).ok();
}
