//! `tandem urdf inspect|eval` end to end: eval reproduces the Pinocchio fixtures, errors are clear.

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

const FIX: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/pinocchio/");

fn tandem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args(args)
        .output()
        .expect("the tandem binary runs")
}

fn temp_file(name: &str, contents: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("urdf-cli-{name}"));
    std::fs::write(&path, contents).unwrap();
    path
}

fn assert_fails_with(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "expected failure, stderr: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
}

#[test]
fn inspect_lists_joints_in_pinocchio_order() {
    let o = tandem(&["urdf", "inspect", &format!("{FIX}arm7.urdf")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("7 DoF"), "{out}");
    assert!(out.contains("18.05"), "total mass: {out}");
    let pos: Vec<usize> = ["a1 ", "a2 ", "a7 "]
        .iter()
        .map(|n| out.find(n).unwrap())
        .collect();
    assert!(pos[0] < pos[1] && pos[1] < pos[2]);
}

#[test]
fn eval_reproduces_the_fixture() {
    let fx: Value =
        serde_json::from_str(&std::fs::read_to_string(format!("{FIX}leg2r.json")).unwrap())
            .unwrap();
    let samples = fx["samples"].as_array().unwrap();
    let states: Vec<Value> = samples
        .iter()
        .map(|s| serde_json::json!({"q": s["q"], "v": s["v"], "tau": s["tau"], "a": s["a"]}))
        .collect();
    let path = temp_file(
        "leg2r-states.json",
        &serde_json::to_string(&states).unwrap(),
    );
    let o = tandem(&[
        "urdf",
        "eval",
        &format!("{FIX}leg2r.urdf"),
        "--states",
        path.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(out["joint_names"], fx["joint_names"]);
    let results = out["results"].as_array().unwrap();
    assert_eq!(results.len(), samples.len());
    let close = |a: &Value, b: &Value| {
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        assert!((a - b).abs() <= 1e-10f64.max(1e-9 * b.abs()), "{a} vs {b}");
    };
    for (r, s) in results.iter().zip(samples) {
        for key in [
            "rnea",
            "aba",
            "nle",
            "gravity_torque",
            "com",
            "com_velocity",
        ] {
            for (x, y) in r[key]
                .as_array()
                .unwrap()
                .iter()
                .zip(s[key].as_array().unwrap())
            {
                close(x, y);
            }
        }
        for (ra, rb) in r["mass_matrix"]
            .as_array()
            .unwrap()
            .iter()
            .zip(s["mass_matrix"].as_array().unwrap())
        {
            for (x, y) in ra.as_array().unwrap().iter().zip(rb.as_array().unwrap()) {
                close(x, y);
            }
        }
        close(&r["kinetic_energy"], &s["kinetic_energy"]);
        close(&r["potential_energy"], &s["potential_energy"]);
        let foot = &r["link_placements"]["foot"];
        let want = &s["link_placements"]["foot"];
        for (x, y) in foot["translation"]
            .as_array()
            .unwrap()
            .iter()
            .zip(want["translation"].as_array().unwrap())
        {
            close(x, y);
        }
    }
}

#[test]
fn eval_and_inspect_errors_are_clear() {
    let urdf = format!("{FIX}leg2r.urdf");
    let o = tandem(&["urdf", "inspect", "/nonexistent/robot.urdf"]);
    assert_fails_with(&o, &["cannot read URDF file", "/nonexistent/robot.urdf"]);
    let bad = temp_file(
        "bad.urdf",
        r#"<robot name="r"><link name="a"/><joint name="j" type="ball"><parent link="a"/><child link="b"/></joint><link name="b"/></robot>"#,
    );
    let o = tandem(&["urdf", "inspect", bad.to_str().unwrap()]);
    assert_fails_with(&o, &["joint 'j'", "unknown type 'ball'"]);
    for (name, contents, needles) in [
        ("not-json", "[{\"q\": [0, ", vec!["malformed JSON"]),
        (
            "not-list",
            "{\"q\": [0, 0]}",
            vec!["expected a list of states"],
        ),
        (
            "no-q",
            "[{\"v\": [0, 0]}]",
            vec!["state 0", "missing \"q\""],
        ),
        (
            "short-q",
            "[{\"q\": [0]}]",
            vec!["\"q\"", "1 entries", "2 DoF"],
        ),
        (
            "nan",
            "[{\"q\": [0, 0], \"v\": [NaN, 0]}]",
            vec!["\"v\"", "not finite"],
        ),
        (
            "extra",
            "[{\"q\": [0, 0], \"qdd\": [0, 0]}]",
            vec!["unknown field \"qdd\""],
        ),
        (
            "string",
            "[{\"q\": [0, \"x\"]}]",
            vec!["element 1 is a string"],
        ),
    ] {
        let path = temp_file(&format!("{name}.json"), contents);
        let o = tandem(&["urdf", "eval", &urdf, "--states", path.to_str().unwrap()]);
        assert_fails_with(&o, &needles);
    }
    let o = tandem(&[
        "urdf",
        "eval",
        &urdf,
        "--states",
        "/nonexistent/states.json",
    ]);
    assert_fails_with(&o, &["/nonexistent/states.json"]);
}

/// `urdf eval` of `states` on `urdf`: must fail naming each of `needles`, and print no JSON.
fn assert_eval_fails(name: &str, urdf: &str, states: &str, needles: &[&str]) {
    let states = temp_file(&format!("{name}-states.json"), states);
    let o = tandem(&["urdf", "eval", urdf, "--states", states.to_str().unwrap()]);
    assert_fails_with(&o, needles);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

#[test]
fn eval_results_that_overflow_are_errors_naming_the_quantity() {
    let leg = format!("{FIX}leg2r.urdf");
    // Finite inputs, but v² overflows: the Coriolis terms of RNEA are infinite.
    assert_eval_fails(
        "huge-v",
        &leg,
        r#"[{"q": [0, 0]}, {"q": [0.1, 0.2], "v": [1e200, -1e200]}]"#,
        &["state 1", "rnea is not finite"],
    );
    // A 1.7e308 kg link one metre off its joint: its gravity torque is out of range.
    let heavy = temp_file(
        "heavy.urdf",
        r#"<robot name="heavy"><link name="base"/>
        <link name="a"><inertial><origin xyz="1 0 0"/><mass value="1.7e308"/>
        <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
        <joint name="j" type="continuous"><parent link="base"/><child link="a"/>
        <axis xyz="0 1 0"/></joint></robot>"#,
    );
    assert_eval_fails(
        "heavy",
        heavy.to_str().unwrap(),
        r#"[{"q": [0]}]"#,
        &["state 0", "rnea is not finite"],
    );
    // A link spinning about an axis through its centre of mass: every torque is zero, but at
    // 1e155 rad/s the kinetic energy 0.5 * 1 * 1e310 is beyond f64.
    let light = temp_file(
        "light.urdf",
        r#"<robot name="light"><link name="base"/>
        <link name="a"><inertial><mass value="2"/>
        <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
        <joint name="j" type="continuous"><parent link="base"/><child link="a"/>
        <axis xyz="0 1 0"/></joint></robot>"#,
    );
    assert_eval_fails(
        "light",
        light.to_str().unwrap(),
        r#"[{"q": [0], "v": [1e155]}]"#,
        &["state 0", "kinetic_energy is not finite"],
    );
}
