//! `tandem reproduce merge` checks what it reads (each record against its folder and its
//! checksum), merges merged directories again (per node, then across nodes) to the table of
//! one merge, merges disjoint (seed, method) cells of `--methods` runs to the table of one run,
//! and refuses a failed study, which `--resume` continues once the cause is gone. Each
//! directory records the build that ran it, and a merge the builds of its parts.
//! On `p2-cartpole --quick`, the cheapest study.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// Asserts that `o` failed with exit status 1 and a message holding every one of `needles`.
fn fails(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "no {n:?} in: {err}");
    }
}

fn root(name: &str) -> PathBuf {
    let r = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("study-merge-{name}"));
    let _ = std::fs::remove_dir_all(&r);
    std::fs::create_dir_all(&r).unwrap();
    r
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `tandem reproduce p2-cartpole --quick` of `seeds` seeds from `first` into `out`.
fn cartpole(out: &Path, seeds: u64, first: u64) {
    let (n, k) = (seeds.to_string(), first.to_string());
    ok(&tandem(&[
        "reproduce",
        "p2-cartpole",
        "--quick",
        "--quiet",
        "--seeds",
        &n,
        "--first-seed",
        &k,
        "--out",
        s(out),
    ]));
}

fn merge(dirs: &[&Path], out: &Path) -> Output {
    let mut args = vec!["reproduce", "merge"];
    args.extend(dirs.iter().map(|d| s(d)));
    args.extend(["--out", s(out)]);
    tandem(&args)
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn merge_refuses_a_record_that_disagrees_with_its_folder_or_its_checksum() {
    let root = root("checks");
    let (s0, s1) = (root.join("s0"), root.join("s1"));
    cartpole(&s0, 1, 0);
    cartpole(&s1, 1, 1);
    let folder = s1.join("runs/model_free__seed1");
    let record = folder.join("record.json");
    let sum = folder.join("record.json.sha256");
    let original = std::fs::read_to_string(&record).unwrap();
    let line = std::fs::read_to_string(&sum).unwrap();
    assert!(
        line.ends_with("  record.json\n") && line.len() == 64 + 14,
        "{line:?}"
    );
    let out = root.join("merged");
    let named = "model_free__seed1/record.json";

    // A number changed after the record was written: its checksum no longer matches.
    let r: Value = serde_json::from_str(&original).unwrap();
    let n = r["real_samples"].as_u64().unwrap();
    let changed = original.replacen(
        &format!("\"real_samples\": {n}"),
        &format!("\"real_samples\": {}", n + 1),
        1,
    );
    assert_ne!(changed, original);
    std::fs::write(&record, &changed).unwrap();
    fails(
        &merge(&[&s0, &s1], &out),
        &[named, "SHA-256", "changed after it was written"],
    );
    assert!(!out.exists(), "nothing written");

    // A record of another seed (or method) in this folder, without a checksum to catch it.
    std::fs::remove_file(&sum).unwrap();
    std::fs::write(&record, original.replacen("\"seed\": 1", "\"seed\": 4", 1)).unwrap();
    fails(&merge(&[&s0, &s1], &out), &[named, "records seed 4"]);
    let other = original.replacen(
        "\"method\": \"model_free\"",
        "\"method\": \"with_model\"",
        1,
    );
    std::fs::write(&record, other).unwrap();
    fails(
        &merge(&[&s0, &s1], &out),
        &[named, "records method \"with_model\""],
    );

    // The record as written but its checksum gone (a directory from before checksums): merged,
    // with a note, and the merge writes the checksum.
    std::fs::write(&record, &original).unwrap();
    let o = merge(&[&s0, &s1], &out);
    ok(&o);
    assert!(
        stderr(&o).contains("1 of 2 records have no checksum"),
        "{}",
        stderr(&o)
    );
    let copied = out.join("runs/model_free__seed1");
    assert_eq!(
        std::fs::read_to_string(copied.join("record.json")).unwrap(),
        original
    );
    assert_eq!(
        std::fs::read_to_string(copied.join("record.json.sha256")).unwrap(),
        line
    );

    // A record of a seed the directory does not have is refused, not left out.
    let stray = s0.join("runs/model_free__seed7");
    std::fs::create_dir_all(&stray).unwrap();
    std::fs::write(stray.join("record.json"), "{}").unwrap();
    let again = root.join("again");
    fails(
        &merge(&[&s0, &s1], &again),
        &["model_free__seed7/record.json", "no run of its directory"],
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn merges_of_merges_equal_one_merge_of_all_seeds() {
    let root = root("levels");
    let seed: Vec<PathBuf> = (0..4).map(|k| root.join(format!("s{k}"))).collect();
    for (k, d) in seed.iter().enumerate() {
        cartpole(d, 1, k as u64);
    }
    let [a, b, c, d] = [&seed[0], &seed[1], &seed[2], &seed[3]].map(PathBuf::as_path);
    let p = |n: &str| root.join(n);
    ok(&merge(&[a, b, c, d], &p("all")));
    // Per node, then across nodes.
    ok(&merge(&[a, b], &p("m1")));
    ok(&merge(&[d, c], &p("m2")));
    ok(&merge(&[&p("m2"), &p("m1")], &p("m")));
    // Seeds {0, 2} (not contiguous), then with {1} and {3}.
    ok(&merge(&[c, a], &p("n1")));
    ok(&merge(&[b, &p("n1"), d], &p("n")));
    let config = json(&p("n1/config.json"));
    assert_eq!(config["seeds"], serde_json::json!([0, 2]));
    for m in ["m", "n"] {
        for f in [
            "table.json",
            "table.md",
            "fig6.svg",
            "runs/with_model__seed2/record.json",
        ] {
            let one = std::fs::read(p("all").join(f)).unwrap();
            assert!(one == std::fs::read(p(m).join(f)).unwrap(), "{m}/{f}");
        }
        let config = json(&p(m).join("config.json"));
        assert_eq!(config["seeds"], serde_json::json!([0, 1, 2, 3]));
        assert_eq!(config["status"], "complete");
        // The four processes that ran the seeds, by first seed.
        let parts = config["parts"].as_array().unwrap();
        let firsts: Vec<u64> = parts.iter().map(|p| p[1].as_u64().unwrap()).collect();
        assert_eq!(firsts, [0, 1, 2, 3], "{m}: {parts:?}");
        assert_eq!(
            config["wall_seconds"],
            json(&p("all/config.json"))["wall_seconds"]
        );
    }
    // A merged directory again with one of its seeds; resuming one is refused clearly.
    fails(
        &merge(&[&p("m1"), b], &p("x")),
        &["seed 1's model_free run is in two"],
    );
    let o = tandem(&["reproduce", "p2-cartpole", "--resume", s(&p("m1"))]);
    fails(&o, &["a merge's directory", "cannot be resumed"]);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn a_failed_study_is_marked_refused_by_merge_and_resumes_once_fixed() {
    let root = root("failed");
    let whole = root.join("whole");
    cartpole(&whole, 2, 0);
    let cut = root.join("cut");
    cartpole(&cut, 2, 0);
    // One run left to do, whose curve.csv cannot be written: a directory holds its name.
    let folder = cut.join("runs/with_model__seed1");
    std::fs::remove_file(folder.join("record.json")).unwrap();
    std::fs::remove_file(folder.join("curve.csv")).unwrap();
    std::fs::create_dir_all(folder.join("curve.csv/in-the-way")).unwrap();
    let resume = || tandem(&["reproduce", "p2-cartpole", "--quiet", "--resume", s(&cut)]);
    let o = resume();
    fails(
        &o,
        &["cannot write", "with_model__seed1/curve.csv", "--resume"],
    );
    let config = json(&cut.join("config.json"));
    assert_eq!(config["status"], "failed");
    let error = config["error"].as_str().unwrap();
    assert!(
        error.contains("seed 1: with_model: cannot write") && error.contains("curve.csv"),
        "{error}"
    );
    // The other runs' records stay; no lock is left behind.
    assert!(cut.join("runs/model_free__seed1/record.json").exists());
    assert!(!cut.join(".tandem.lock").exists());
    fails(
        &merge(&[&cut], &root.join("merged")),
        &[
            "the study failed (seed 1: with_model: cannot write",
            "--resume",
        ],
    );

    // The cause fixed, the report cannot be written: failed again, after every run finished.
    std::fs::remove_dir_all(folder.join("curve.csv")).unwrap();
    std::fs::remove_file(cut.join("table.json")).unwrap();
    std::fs::create_dir_all(cut.join("table.json/in-the-way")).unwrap();
    fails(&resume(), &["cannot write", "table.json"]);
    assert_eq!(json(&cut.join("config.json"))["status"], "failed");
    assert!(folder.join("record.json").exists() && !cut.join("state").exists());

    std::fs::remove_dir_all(cut.join("table.json")).unwrap();
    ok(&resume());
    let config = json(&cut.join("config.json"));
    assert_eq!(config["status"], "complete");
    assert!(config.get("error").is_none(), "{config}");
    for f in ["table.json", "fig6.svg"] {
        let a = std::fs::read(whole.join(f)).unwrap();
        assert!(a == std::fs::read(cut.join(f)).unwrap(), "{f}");
    }
    ok(&merge(&[&cut], &root.join("merged")));
    let _ = std::fs::remove_dir_all(&root);
}

/// `p2-cartpole --quick` of one seed and the methods `methods` into `out`.
fn cell(out: &Path, seed: u64, methods: &str) -> Output {
    let k = seed.to_string();
    tandem(&[
        "reproduce",
        "p2-cartpole",
        "--quick",
        "--quiet",
        "--seeds",
        "1",
        "--first-seed",
        &k,
        "--methods",
        methods,
        "--out",
        s(out),
    ])
}

#[test]
fn disjoint_method_cells_merge_to_the_table_of_one_run() {
    let root = root("cells");
    let whole = root.join("whole");
    cartpole(&whole, 2, 0);
    let p = |n: &str| root.join(n);
    let mut cells = Vec::new();
    // Given in reverse order: a cell's methods are recorded in the study's order.
    for seed in [1, 0] {
        for method in ["with_model", "model_free"] {
            let d = p(&format!("s{seed}-{method}"));
            ok(&cell(&d, seed, method));
            cells.push(d);
        }
    }
    let config = json(&cells[0].join("config.json"));
    assert_eq!(config["methods"], serde_json::json!(["with_model"]));
    // Every run of its own and no other.
    assert!(cells[0].join("runs/with_model__seed1/record.json").exists());
    assert!(!cells[0].join("runs/model_free__seed1").exists());

    let dirs: Vec<&Path> = cells.iter().map(PathBuf::as_path).collect();
    ok(&merge(&dirs, &p("merged")));
    // Per method, then across methods.
    ok(&merge(&[dirs[1], dirs[3]], &p("free")));
    ok(&merge(&[dirs[0], dirs[2]], &p("model")));
    assert_eq!(
        json(&p("free/config.json"))["methods"],
        serde_json::json!(["model_free"])
    );
    ok(&merge(&[&p("model"), &p("free")], &p("two-level")));
    for m in ["merged", "two-level"] {
        let merged = json(&p(m).join("config.json"));
        assert!(merged.get("methods").is_none(), "{m}: all methods");
        assert_eq!(merged["seeds"], serde_json::json!([0, 1]));
        let one = std::fs::read(whole.join("table.json")).unwrap();
        assert!(
            one == std::fs::read(p(m).join("table.json")).unwrap(),
            "{m}"
        );
    }
    // A table needs every merged method on every merged seed.
    fails(
        &merge(&[dirs[0], dirs[1], dirs[2]], &p("x")),
        &["seed 0's model_free run is in none", "--methods model_free"],
    );
    // The same cell twice, directly or inside a merge.
    fails(
        &merge(&[dirs[1], &p("free")], &p("x")),
        &["seed 1's model_free run is in two"],
    );
    assert!(!p("x").exists());

    // Unknown or repeated methods, and a resume that names other ones, are refused.
    fails(
        &cell(&p("y"), 0, "sac"),
        &["no run \"sac\"", "its runs are model_free, with_model"],
    );
    fails(
        &cell(&p("y"), 0, "model_free,model_free"),
        &["model_free is named twice"],
    );
    let o = tandem(&[
        "reproduce",
        "p2-cartpole",
        "--resume",
        s(dirs[0]),
        "--methods",
        "model_free",
    ]);
    fails(&o, &["--methods model_free (the run has with_model)"]);
    assert!(!p("y").exists());
    let _ = std::fs::remove_dir_all(&root);
}

/// Rewrites `dir/config.json` through `edit`.
fn edit_config(dir: &Path, edit: impl FnOnce(&mut Value)) {
    let path = dir.join("config.json");
    let mut config = json(&path);
    edit(&mut config);
    std::fs::write(&path, serde_json::to_string_pretty(&config).unwrap()).unwrap();
}

fn is_commit(c: &Value) -> bool {
    let c = c.as_str().unwrap();
    let hex = matches!(c.len(), 40 | 64) && c.bytes().all(|b| b.is_ascii_hexdigit());
    hex || c == "unknown"
}

#[test]
fn a_run_records_its_build_and_directories_without_one_still_merge_and_resume() {
    let root = root("build");
    let (s0, s1, s2) = (root.join("s0"), root.join("s1"), root.join("s2"));
    cartpole(&s0, 1, 0);
    let build = json(&s0.join("config.json"))["build"].clone();
    assert!(is_commit(&build["commit"]), "{build}");
    assert!(build["dirty"].is_boolean(), "{build}");
    let mujoco = serde_json::json!(["mujoco"]);
    let features = if cfg!(feature = "mujoco") {
        mujoco
    } else {
        serde_json::json!([])
    };
    assert_eq!(build["features"], features);
    assert!(build.get("resumed_by").is_none(), "{build}");

    // A directory from before builds were recorded merges, with a note.
    cartpole(&s1, 1, 1);
    edit_config(&s1, |c| {
        c.as_object_mut().unwrap().remove("build");
    });
    let o = merge(&[&s0, &s1], &root.join("m"));
    ok(&o);
    assert!(
        stderr(&o).contains("1 of 2 merged parts record no build"),
        "{}",
        stderr(&o)
    );
    let merged = json(&root.join("m/config.json"));
    let builds = merged["builds"].as_array().unwrap();
    assert_eq!(builds.len(), 1, "{merged}");
    assert_eq!(builds[0]["part"], s(&s0));
    assert_eq!(builds[0]["commit"], build["commit"]);
    assert!(merged.get("mixed_commits").is_none(), "{merged}");
    assert_eq!(merged["merged_by"]["commit"], build["commit"]);

    // ... and resumes: what ran it is unrecorded, this build is the resuming one.
    let resume = |d: &Path| tandem(&["reproduce", "p2-cartpole", "--quiet", "--resume", s(d)]);
    edit_config(&s1, |c| c["status"] = "interrupted".into());
    let o = resume(&s1);
    ok(&o);
    assert!(stderr(&o).contains("is continued by"), "{}", stderr(&o));
    let b = json(&s1.join("config.json"))["build"].clone();
    assert_eq!(b["commit"], "unknown");
    assert_eq!(b["commit_source"], "unrecorded");
    assert_eq!(b["resumed_by"][0]["commit"], build["commit"], "{b}");

    // A study of another commit resumed: its build stays first, this one is appended once.
    cartpole(&s2, 1, 2);
    let other = "0".repeat(40);
    edit_config(&s2, |c| {
        c["status"] = "interrupted".into();
        c["build"]["commit"] = other.clone().into();
    });
    let o = resume(&s2);
    ok(&o);
    assert!(
        stderr(&o).contains("carry the new build's numbers"),
        "{}",
        stderr(&o)
    );
    let b = json(&s2.join("config.json"))["build"].clone();
    assert_eq!(b["commit"], other.as_str());
    assert_eq!(b["resumed_by"].as_array().unwrap().len(), 1, "{b}");
    assert_eq!(b["resumed_by"][0]["commit"], build["commit"], "{b}");
    edit_config(&s2, |c| c["status"] = "interrupted".into());
    let o = resume(&s2);
    ok(&o);
    assert!(!stderr(&o).contains("continued by"), "{}", stderr(&o));
    assert_eq!(json(&s2.join("config.json"))["build"], b);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn parts_of_different_commits_merge_with_a_warning_and_keep_both_builds() {
    let root = root("commits");
    let (s0, s1) = (root.join("s0"), root.join("s1"));
    cartpole(&s0, 1, 0);
    cartpole(&s1, 1, 1);
    let p = |n: &str| root.join(n);
    ok(&merge(&[&s0, &s1], &p("same")));
    assert!(json(&p("same/config.json")).get("mixed_commits").is_none());
    let other = "f".repeat(40);
    edit_config(&s1, |c| c["build"]["commit"] = other.clone().into());
    let o = merge(&[&s0, &s1], &p("mixed"));
    ok(&o);
    assert!(
        stderr(&o).contains("warning: the merged runs come from 2 commits"),
        "{}",
        stderr(&o)
    );
    // The builds never make equal settings unequal: the same table as one commit's.
    for f in ["table.json", "table.md"] {
        let a = std::fs::read(p("same").join(f)).unwrap();
        assert!(a == std::fs::read(p("mixed").join(f)).unwrap(), "{f}");
    }
    let config = json(&p("mixed/config.json"));
    let ours = json(&s0.join("config.json"))["build"]["commit"].clone();
    let commits: Vec<&Value> = config["builds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| &b["commit"])
        .collect();
    assert_eq!(commits, [&ours, &Value::from(other.as_str())]);
    assert_eq!(config["mixed_commits"], serde_json::json!([ours, other]));
    // A merge of the merge keeps both, with the parts' directories.
    ok(&merge(&[&p("mixed")], &p("again")));
    let again = json(&p("again/config.json"));
    assert_eq!(again["builds"], config["builds"]);
    assert_eq!(again["builds"][1]["part"], s(&s1));
    let _ = std::fs::remove_dir_all(&root);
}
