//! `tandem reproduce p3-leg`: the quick study's files, seeds run apart and merged, the elite
//! ablation, and a resume that asks for other settings; the committed leg and p1 (p3-mujoco's
//! loop) studies merged again from their records.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `tandem reproduce p3-leg --quick --quiet --seeds 1 FLAG --out OUT`.
fn quick_leg_seed(flag: &str, out: &str) -> Output {
    tandem(&[
        "reproduce",
        "p3-leg",
        "--quick",
        "--quiet",
        "--seeds",
        "1",
        flag,
        "--out",
        out,
    ])
}

/// Merges the committed study directories `dirs` into a temporary folder, asserts that the
/// `table.json` written there equals `committed`'s byte for byte, and returns that table.
fn merges_again_to(name: &str, dirs: &[PathBuf], committed: &Path) -> Value {
    let root = root(name);
    let out = root.join("merged");
    let mut args = vec!["reproduce".to_owned(), "merge".to_owned()];
    args.extend(dirs.iter().map(|d| d.display().to_string()));
    args.extend(["--out".to_owned(), out.display().to_string()]);
    ok(&tandem(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
    ));
    let again = std::fs::read_to_string(out.join("table.json")).unwrap();
    let before = std::fs::read_to_string(committed.join("table.json")).unwrap();
    assert_eq!(again, before, "{} merged again", committed.display());
    let _ = std::fs::remove_dir_all(&root);
    serde_json::from_str(&before).unwrap()
}

fn root(name: &str) -> PathBuf {
    let r = std::env::temp_dir().join(format!("tandem-p3-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&r);
    r
}

/// Two seeds in one process equal the same seeds run apart and merged: table, figure, curves;
/// the table has p3's three methods with one figure per seed and the ratios over M-DeMoRL.
#[test]
fn seeds_run_apart_and_merged_equal_one_study_of_all_seeds() {
    let root = root("merge");
    let p = |name: &str| root.join(name).to_str().unwrap().to_string();
    let quick = ["reproduce", "p3-leg", "--quick", "--quiet"];
    for (out, extra) in [
        ("all", &["--seeds", "2"][..]),
        ("s0", &["--seeds", "1", "--jobs", "1"][..]),
        ("s1", &["--seeds", "1", "--first-seed", "1"][..]),
    ] {
        ok(&tandem(&[&quick[..], extra, &["--out", &p(out)]].concat()));
    }
    ok(&tandem(&[
        "reproduce",
        "merge",
        &p("s1"),
        &p("s0"),
        "--out",
        &p("merged"),
    ]));
    for f in ["table.json", "fig4.svg", "runs/m_demorl__seed1/curve.csv"] {
        let a = std::fs::read(root.join("all").join(f)).unwrap();
        assert!(
            a == std::fs::read(root.join("merged").join(f)).unwrap(),
            "{f}"
        );
    }
    let table = json(&root.join("all/table.json"));
    for m in ["sac", "mbpo", "m_demorl"] {
        let r = &table[m]["return_at_budget"];
        assert_eq!(r["budget"], 900, "{m}");
        assert_eq!(r["per_seed"].as_array().unwrap().len(), 2, "{m}");
        assert_eq!(table[m]["seeds"], serde_json::json!([0, 1]));
        let curve = std::fs::read_to_string(root.join(format!("all/runs/{m}__seed0/curve.csv")));
        // The initial evaluation and one per 300-step epoch.
        assert_eq!(curve.unwrap().lines().count(), 1 + 4, "{m}");
    }
    for base in ["sac", "mbpo"] {
        assert!(table[format!("{base}_over_m_demorl")]["ratio"].is_number());
    }
    let config = json(&root.join("merged/config.json"));
    assert_eq!(config["study"], "p3-leg");
    assert_eq!(config["seeds"], serde_json::json!([0, 1]));
    // A p0 directory does not merge with a p3 one.
    ok(&tandem(&[
        "reproduce",
        "p0-pendulum",
        "--quick",
        "--quiet",
        "--seeds",
        "1",
        "--first-seed",
        "2",
        "--out",
        &p("p0"),
    ]));
    let o = tandem(&["reproduce", "merge", &p("s0"), &p("p0"), "--out", &p("m2")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("p0-pendulum study, not p3-leg"), "{err}");
    let _ = std::fs::remove_dir_all(&root);
}

/// `--ablate-elites` adds M-DeMoRL with p3's other elite fractions (10 % is the main run) and
/// Fig. 3; resuming it without the flag's settings, or a finished study of another kind, is
/// refused.
#[test]
fn the_elite_ablation_adds_runs_and_a_figure() {
    let root = root("ablate");
    let out = root.join("a");
    let o = out.to_str().unwrap();
    ok(&quick_leg_seed("--ablate-elites", o));
    let table = json(&out.join("table.json"));
    for m in [
        "m_demorl",
        "m_demorl_elites_1",
        "m_demorl_elites_5",
        "m_demorl_elites_20",
    ] {
        assert!(table[m]["return_at_budget"]["mean"].is_number(), "{m}");
    }
    assert!(table.get("m_demorl_elites_10").is_none());
    let svg = std::fs::read_to_string(out.join("fig3.svg")).unwrap();
    assert!(svg.contains("m_demorl_elites_100"));
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(md.contains("M-DeMoRL (50 % elites)"), "{md}");
    // Another elite count is another study: the recorded settings win, the conflict is named.
    let cfg = root.join("other.toml");
    std::fs::write(&cfg, "ablate_elites = [0.3]\n").unwrap();
    let o = tandem(&[
        "reproduce",
        "p3-leg",
        "--resume",
        o,
        "--config",
        cfg.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("conflicts with the run being resumed"),
        "{err}"
    );
    let o = tandem(&[
        "reproduce",
        "p0-pendulum",
        "--resume",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("holds a p3-leg study"), "{err}");
    let _ = std::fs::remove_dir_all(&root);
}

/// `--oracle` adds MBPO with the true leg as its model to the table and Fig. 4; p3-mujoco
/// refuses it (no true model there) before writing anything.
#[test]
fn the_oracle_adds_mbpo_with_the_true_leg() {
    let root = root("oracle");
    let out = root.join("a");
    let o = out.to_str().unwrap();
    ok(&quick_leg_seed("--oracle", o));
    let table = json(&out.join("table.json"));
    for m in ["sac", "mbpo", "m_demorl", "mbpo_oracle"] {
        assert!(table[m]["return_at_budget"]["mean"].is_number(), "{m}");
    }
    // The leg's table has the return at each epoch (quick: 3 epochs of 300 steps).
    let epochs = table["mbpo_oracle"]["return_at_epoch"].as_object().unwrap();
    let keys: Vec<&str> = epochs.keys().map(String::as_str).collect();
    assert_eq!(keys, ["0", "1", "2", "3"]);
    assert_eq!(
        epochs["3"], table["mbpo_oracle"]["return_at_budget"]["mean"],
        "one seed: the last epoch's return is the return at the budget"
    );
    let record = json(&out.join("runs/mbpo_oracle__seed0/record.json"));
    assert_eq!(record["fit_holdout_loss"], serde_json::json!([]));
    assert!(record["imagined"].as_u64().unwrap() > 0);
    let svg = std::fs::read_to_string(out.join("fig4.svg")).unwrap();
    assert!(svg.contains("mbpo_oracle"));
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(md.contains("MBPO, true leg as model"), "{md}");

    let m = root.join("m");
    let o = tandem(&[
        "reproduce",
        "p3-mujoco",
        "--env",
        "InvertedPendulum-v5",
        "--quick",
        "--oracle",
        "--out",
        m.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("oracle"), "{err}");
    assert!(!m.join("config.json").exists());
    let _ = std::fs::remove_dir_all(&root);
}

/// The committed leg results (`results/p3-leg/`) are one study's output: merging their recorded
/// runs again writes the same table, with every method's return at each of the 81 epochs.
#[test]
fn the_committed_leg_results_render_again_from_their_records() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("results/p3-leg");
    let table = merges_again_to(
        "leg-committed",
        std::slice::from_ref(&committed),
        &committed,
    );
    for m in ["sac", "mbpo", "m_demorl", "mbpo_oracle"] {
        assert_eq!(
            table[m]["return_at_epoch"].as_object().unwrap().len(),
            81,
            "{m}"
        );
        assert_eq!(table[m]["seeds"], serde_json::json!([0, 1, 2, 3, 4]), "{m}");
    }
}

/// p1 runs on p3-mujoco's loop and harness: its committed tables (`results/p1/halfcheetah/`,
/// `results/p1/hopper/`) are the merges of the three one-seed studies committed beside each, each
/// run as its own process (several resumed in later sessions); the one Walker2d-v5 study
/// (`results/p1/walker2d-seed0/`) merges alone to its own table.
#[test]
fn the_committed_p1_tables_are_the_merges_of_their_one_seed_studies() {
    let p1 = Path::new(env!("CARGO_MANIFEST_DIR")).join("results/p1");
    for task in ["halfcheetah", "hopper"] {
        let seeds: Vec<PathBuf> = (0..3).map(|k| p1.join(format!("{task}-seed{k}"))).collect();
        let table = merges_again_to(&format!("p1-committed-{task}"), &seeds, &p1.join(task));
        for m in ["sac", "mbpo", "incremental_dyna"] {
            assert_eq!(
                table[m]["seeds"],
                serde_json::json!([0, 1, 2]),
                "{task} {m}"
            );
        }
    }
    // Walker2d-v5 has one seed: merging its study alone gives its own table again.
    let walker = p1.join("walker2d-seed0");
    let table = merges_again_to(
        "p1-committed-walker2d",
        std::slice::from_ref(&walker),
        &walker,
    );
    for m in ["sac", "mbpo", "incremental_dyna"] {
        assert_eq!(table[m]["seeds"], serde_json::json!([0]), "walker2d {m}");
    }
}
