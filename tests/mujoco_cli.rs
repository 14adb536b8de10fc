//! The `tandem` program on MuJoCo: `envs` lists gymnasium's MuJoCo tasks exactly when the build has
//! the `mujoco` feature; `env replay` reproduces a recorded gymnasium episode (with `info`) and
//! replays any MJCF file (`--mjcf`); without the feature both say how to enable it.

use std::path::PathBuf;
use std::process::{Command, Output};

#[cfg(feature = "mujoco")]
use serde_json::Value;

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs")
}

fn err_text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[cfg(feature = "mujoco")]
fn mujoco_dir(rel: &str) -> String {
    format!("{}/crates/mujoco/tests/{rel}", env!("CARGO_MANIFEST_DIR"))
}

/// `tandem reproduce STUDY --quick --quiet --seeds SEEDS --out OUT`, with `OUT` removed first.
fn quick_study(study: &str, seeds: &str, out: &std::path::Path) -> Output {
    let _ = std::fs::remove_dir_all(out);
    tandem(&[
        "reproduce",
        study,
        "--quick",
        "--quiet",
        "--seeds",
        seeds,
        "--out",
        out.to_str().unwrap(),
    ])
}

/// A study refused by a build without MuJoCo: exit code 1, a message saying how to enable it,
/// and no output directory.
fn refused_without_the_feature(o: &Output, out: &std::path::Path) {
    assert_eq!(o.status.code(), Some(1));
    assert!(err_text(o).contains("--features mujoco"), "{}", err_text(o));
    assert!(!out.exists());
}

fn write_temp(name: &str, contents: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("mujoco-cli-{name}.json"));
    std::fs::write(&path, contents).unwrap();
    path
}

#[test]
fn envs_lists_mujoco_tasks_with_the_feature_only() {
    let o = tandem(&["envs"]);
    assert!(o.status.success());
    let listed = String::from_utf8_lossy(&o.stdout).contains("HalfCheetah-v5");
    assert_eq!(listed, cfg!(feature = "mujoco"));
}

#[cfg(not(feature = "mujoco"))]
#[test]
fn without_the_feature_mujoco_ids_and_files_say_how_to_enable_it() {
    let actions = write_temp("nofeature", "[[0, 0, 0, 0, 0, 0]]");
    let actions = actions.to_str().unwrap();
    for args in [
        vec![
            "env",
            "replay",
            "--env",
            "HalfCheetah-v5",
            "--state",
            "[0]",
            "--actions",
            actions,
        ],
        vec![
            "env",
            "replay",
            "--mjcf",
            "x.xml",
            "--state",
            "[0]",
            "--actions",
            actions,
        ],
        vec!["rollout", "--env", "Hopper-v5", "--episodes", "1"],
    ] {
        let o = tandem(&args);
        assert!(!o.status.success());
        let err = err_text(&o);
        assert!(
            err.contains("--features mujoco") && !err.contains("panicked"),
            "{err}"
        );
    }
}

#[cfg(feature = "mujoco")]
#[test]
fn replay_reproduces_a_gymnasium_episode_with_its_info() {
    let text =
        std::fs::read_to_string(mujoco_dir("fixtures/gymnasium-mujoco/Reacher-v5.json")).unwrap();
    let fx: Value = serde_json::from_str(&text).unwrap();
    let ep = &fx["episodes"][2];
    let mut state = ep["init_qpos"].as_array().unwrap().clone();
    state.extend(ep["init_qvel"].as_array().unwrap().iter().cloned());
    let steps = ep["steps"].as_array().unwrap();
    let actions: Vec<Value> = steps.iter().map(|s| s["action"].clone()).collect();
    let path = write_temp("reacher", &Value::Array(actions).to_string());
    let o = tandem(&[
        "env",
        "replay",
        "--env",
        "Reacher-v5",
        "--state",
        &Value::Array(state).to_string(),
        "--actions",
        path.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err_text(&o));
    let out: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(out["states"].as_array().unwrap().len(), 50);
    for (t, s) in steps.iter().enumerate() {
        let mut qq = s["qpos"].as_array().unwrap().clone();
        qq.extend(s["qvel"].as_array().unwrap().iter().cloned());
        assert_eq!(out["states"][t], Value::Array(qq), "step {t}");
        assert_eq!(out["observations"][t], s["obs"], "step {t}");
        let r = out["rewards"][t].as_f64().unwrap();
        assert!(
            (r - s["reward"].as_f64().unwrap()).abs() < 1e-12,
            "step {t}"
        );
        let ctrl = out["info"][t]["reward_ctrl"].as_f64().unwrap();
        assert_eq!(ctrl, s["info"]["reward_ctrl"].as_f64().unwrap(), "step {t}");
    }
    // Reacher's 50-step time limit truncates the last step, as gymnasium's did.
    assert_eq!(out["truncated"][49], Value::Bool(true));
}

#[cfg(feature = "mujoco")]
#[test]
fn replay_runs_any_mjcf_file() {
    let actions = write_temp("slider", "[[2.0], [2.0]]");
    let scene = mujoco_dir("scenes/slider.xml");
    let o = tandem(&[
        "env",
        "replay",
        "--mjcf",
        &scene,
        "--frame-skip",
        "2",
        "--state",
        "[0.0, 0.0]",
        "--actions",
        actions.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err_text(&o));
    let out: Value = serde_json::from_slice(&o.stdout).unwrap();
    // Semi-implicit Euler by hand: h = 0.01, u / m = 1, four substeps.
    let (mut x, mut v) = (0.0, 0.0);
    for _ in 0..4 {
        v += 0.01 * 1.0;
        x += 0.01 * v;
    }
    let last = &out["states"][1];
    assert!((last[0].as_f64().unwrap() - x).abs() < 1e-12);
    assert!((last[1].as_f64().unwrap() - v).abs() < 1e-12);
    assert_eq!(out["rewards"], serde_json::json!([0.0, 0.0]));

    let missing = tandem(&[
        "env",
        "replay",
        "--mjcf",
        "/nonexistent.xml",
        "--state",
        "[0, 0]",
        "--actions",
        actions.to_str().unwrap(),
    ]);
    assert!(!missing.status.success());
    assert!(err_text(&missing).contains("/nonexistent.xml"));
    let both = tandem(&[
        "env",
        "replay",
        "--env",
        "Hopper-v5",
        "--mjcf",
        &scene,
        "--state",
        "[0, 0]",
        "--actions",
        actions.to_str().unwrap(),
    ]);
    assert!(!both.status.success());
}

/// `tandem reproduce p3-mujoco`: with the feature, a quick HalfCheetah study writes p3's table
/// (three methods) and Fig. 2; without it, the study refuses before writing anything. An
/// unsupported task is refused either way.
#[test]
fn p3_mujoco_runs_with_the_feature_only() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("mujoco-cli-p3");
    let o = quick_study("p3-mujoco", "1", &out);
    if cfg!(feature = "mujoco") {
        assert!(o.status.success(), "{}", err_text(&o));
        let table = std::fs::read_to_string(out.join("table.json")).unwrap();
        let table: serde_json::Value = serde_json::from_str(&table).unwrap();
        for m in ["sac", "mbpo", "m_demorl"] {
            assert!(table[m]["return_at_budget"]["mean"].is_number(), "{m}");
        }
        // The target is MBPO's mean return at the budget.
        assert_eq!(
            table["mbpo"]["samples_to_target"]["target"],
            table["mbpo"]["return_at_budget"]["mean"]
        );
        let svg = std::fs::read_to_string(out.join("fig2.svg")).unwrap();
        assert!(svg.contains("HalfCheetah-v5"));
        // p1 on the same task: its SAC and MBPO are p3's runs, number for number; its target
        // is SAC's mean return at the budget.
        let p1 = out.with_file_name("mujoco-cli-p1");
        let o = quick_study("p1", "1", &p1);
        assert!(o.status.success(), "{}", err_text(&o));
        let t1 = std::fs::read_to_string(p1.join("table.json")).unwrap();
        let t1: serde_json::Value = serde_json::from_str(&t1).unwrap();
        for m in ["sac", "mbpo", "incremental_dyna"] {
            assert!(t1[m]["return_at_budget"]["mean"].is_number(), "{m}");
        }
        assert_eq!(
            t1["sac"]["samples_to_target"]["target"],
            t1["sac"]["return_at_budget"]["mean"]
        );
        for m in ["sac", "mbpo"] {
            let curve = |d: &PathBuf| {
                std::fs::read_to_string(d.join(format!("runs/{m}__seed0/curve.csv"))).unwrap()
            };
            assert_eq!(curve(&p1), curve(&out), "{m}");
        }
        assert!(std::fs::read_to_string(p1.join("fig1.svg"))
            .unwrap()
            .contains("incremental"));
        let _ = std::fs::remove_dir_all(&p1);
    } else {
        refused_without_the_feature(&o, &out);
    }
    let o = tandem(&["reproduce", "p3-mujoco", "--env", "Ant-v5", "--quick"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err_text(&o).contains("p3-mujoco runs HalfCheetah-v5"),
        "{}",
        err_text(&o)
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn p4_pusher_runs_with_the_feature_only() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("mujoco-cli-p4");
    let o = quick_study("p4-pusher", "2", &out);
    if cfg!(feature = "mujoco") {
        assert!(o.status.success(), "{}", err_text(&o));
        let table = std::fs::read_to_string(out.join("table.json")).unwrap();
        let table: serde_json::Value = serde_json::from_str(&table).unwrap();
        assert_eq!(table["lower_is_better"], true);
        // --quick: 3 iterations of 4 trajectories per condition.
        assert_eq!(table["samples_per_condition"], 12);
        for m in ["lqr_flm", "pi2", "pilqr"] {
            let f = &table["methods"][m];
            assert_eq!(f["samples_to_target"]["target"], 0.1, "{m}");
            assert_eq!(f["final"]["per_seed"].as_array().unwrap().len(), 2, "{m}");
            assert_eq!(f["conditions"].as_array().unwrap().len(), 4, "{m}");
            // The hard condition's final distance is the one in the per-condition list.
            assert_eq!(f["final"], f["conditions"][3]["final"], "{m}");
            let curve =
                std::fs::read_to_string(out.join(format!("runs/{m}__seed1/curve.csv"))).unwrap();
            let rows: Vec<&str> = curve.lines().collect();
            assert_eq!(
                rows[0],
                "samples_per_condition,measure_c0,measure_c1,measure_c2,measure_c3"
            );
            assert_eq!(rows.len(), 4, "{curve}");
            assert!(rows[3].starts_with("12,"), "{curve}");
        }
        assert!(std::fs::read_to_string(out.join("fig3.svg"))
            .unwrap()
            .contains("pilqr"));
        assert!(std::fs::read_to_string(out.join("table.md"))
            .unwrap()
            .contains("hard condition"));
        // The door: its headline is the worst start, a higher angle is better.
        let door = out.with_file_name("mujoco-cli-p4-door");
        let o = quick_study("p4-door", "1", &door);
        assert!(o.status.success(), "{}", err_text(&o));
        let table = std::fs::read_to_string(door.join("table.json")).unwrap();
        let table: serde_json::Value = serde_json::from_str(&table).unwrap();
        assert_eq!(table["lower_is_better"], false);
        for m in ["lqr_flm", "pi2", "pilqr"] {
            let f = &table["methods"][m];
            let worst = f["conditions"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c["final"]["mean"].as_f64().unwrap())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(f["final"]["mean"].as_f64().unwrap(), worst, "{m}");
        }
        assert!(door.join("door.svg").exists());
        let _ = std::fs::remove_dir_all(&door);
    } else {
        refused_without_the_feature(&o, &out);
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn p4_reacher_runs_with_the_feature_only() {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("mujoco-cli-p4-reacher");
    let o = quick_study("p4-reacher", "2", &out);
    if cfg!(feature = "mujoco") {
        assert!(o.status.success(), "{}", err_text(&o));
        let table = std::fs::read_to_string(out.join("table.json")).unwrap();
        let table: serde_json::Value = serde_json::from_str(&table).unwrap();
        assert_eq!(table["test_conditions"], 20);
        for m in ["mdgps_lqr_flm", "mdgps_pi2", "mdgps_pilqr", "ddpg"] {
            let f = &table["methods"][m];
            assert_eq!(f["samples_to_target"]["target"], 0.08, "{m}");
            let finals = f["final"]["per_seed"].as_array().unwrap();
            assert_eq!(finals.len(), 2, "{m}");
            // The final figure is the curve's last point, a distance within the arm's reach.
            let curve =
                std::fs::read_to_string(out.join(format!("runs/{m}__seed1/curve.csv"))).unwrap();
            let rows: Vec<&str> = curve.lines().collect();
            assert_eq!(rows[0], "samples,test_distance");
            let last: Vec<f64> = rows
                .last()
                .unwrap()
                .split(',')
                .map(|v| v.parse().unwrap())
                .collect();
            assert_eq!(last[1], finals[1].as_f64().unwrap(), "{m}");
            assert!(last[1] > 0.0 && last[1] < 0.45, "{m}: {last:?}");
            // --quick: MDGPS 2 conditions x 2 iterations x 2 trajectories x 50 steps; DDPG 400
            // steps, measured at 0, 200 and 400.
            let (budget, points) = if m == "ddpg" { (400.0, 3) } else { (400.0, 2) };
            assert_eq!(last[0], budget, "{m}");
            assert_eq!(rows.len(), 1 + points, "{m}: {curve}");
        }
        let ratio = &table["ddpg_over_mdgps_pilqr"];
        assert_eq!(
            ratio["level"],
            table["methods"]["mdgps_pilqr"]["final"]["mean"]
        );
        assert!(std::fs::read_to_string(out.join("fig4.svg"))
            .unwrap()
            .contains("mdgps_pilqr"));
        assert!(std::fs::read_to_string(out.join("table.md"))
            .unwrap()
            .contains("p4's comparison"));
    } else {
        refused_without_the_feature(&o, &out);
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// `tandem env replay` of `target` (`["--env", ID]` or `["--mjcf", FILE]`) from `state` under
/// the JSON `actions`, run in a temp folder (MuJoCo appends its warnings to `MUJOCO_LOG.TXT` in
/// the working directory).
#[cfg(feature = "mujoco")]
fn replay_in_tmp(target: [&str; 2], state: &str, actions: &str, name: &str) -> Output {
    let path = write_temp(name, actions);
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(["env", "replay", target[0], target[1], "--state", state])
        .args(["--actions", path.to_str().unwrap()])
        .current_dir(env!("CARGO_TARGET_TMPDIR"))
        .output()
        .expect("the tandem binary runs")
}

/// A failed run (exit code 1, no panic, nothing on stdout) whose stderr has every needle.
#[cfg(feature = "mujoco")]
fn fails_naming(o: &Output, needles: &[&str]) {
    let err = err_text(o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(o.stdout.is_empty() && !err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
}

#[cfg(feature = "mujoco")]
#[test]
fn replay_of_a_torque_that_blows_up_the_pendulum_is_an_error_naming_qacc() {
    let scene = mujoco_dir("scenes/pendulum.xml");
    // A moderate torque first: the failure is reported at step 1, not 0.
    let o = replay_in_tmp(
        ["--mjcf", &scene],
        "[0.1, 0]",
        "[[1.0], [1e10], [1e10]]",
        "pendulum-1e10",
    );
    fails_naming(&o, &["step 1", "qacc[0]", "NaN or beyond ±1e10"]);
}

#[cfg(feature = "mujoco")]
#[test]
fn replay_of_hopper_with_a_huge_velocity_is_an_error_naming_qvel() {
    let mut state = vec![
        "0", "1.25", "0", "0", "0", "0", "0", "0", "0", "0", "0", "0",
    ];
    state[9] = "1e12";
    let o = replay_in_tmp(
        ["--env", "Hopper-v5"],
        &format!("[{}]", state.join(",")),
        "[[0, 0, 0]]",
        "hopper-1e12",
    );
    fails_naming(&o, &["Hopper-v5", "step 0", "qvel[3]", "substep 1 of 4"]);
}

#[cfg(feature = "mujoco")]
#[test]
fn replay_of_a_1e300_action_is_an_error_not_a_zero_action() {
    // The pendulum's motor has no ctrlrange: 1e300 (infinite in float32) is a bad ctrl, which
    // MuJoCo would replace by 0.
    let scene = mujoco_dir("scenes/pendulum.xml");
    let o = replay_in_tmp(
        ["--mjcf", &scene],
        "[0.1, 0]",
        "[[0.5], [1e300]]",
        "pendulum-1e300",
    );
    fails_naming(&o, &["step 1", "ctrl[0]", "zeroes ctrl"]);
    // Hopper's motors are limited: MuJoCo clamps the control into [-1, 1], and gymnasium's
    // float32 control cost of an infinite action is infinite, so the reward is the error.
    let o = replay_in_tmp(
        ["--env", "Hopper-v5"],
        "[0, 1.25, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]",
        "[[0, 0, 0], [0, 1e300, 0]]",
        "hopper-1e300",
    );
    fails_naming(&o, &["step 1", "reward is not finite"]);
}
