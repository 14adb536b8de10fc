//! Every malformed or unsupported URDF is a clear error naming the element, never a panic.

use tandem_dynamics::rigid::{Model, UrdfError};

const INERTIAL: &str = r#"<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>"#;

fn link(name: &str) -> String {
    format!(r#"<link name="{name}">{INERTIAL}</link>"#)
}

fn joint(name: &str, ty: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        r#"<joint name="{name}" type="{ty}"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>{extra}</joint>"#
    )
}

fn robot(body: &str) -> String {
    format!(r#"<?xml version="1.0"?><robot name="r"><link name="base"/>{body}</robot>"#)
}

fn err(xml: &str) -> UrdfError {
    Model::from_urdf_str(xml).expect_err("must be rejected")
}

#[test]
fn valid_minimal_model_parses() {
    let xml = robot(&(link("a") + &joint("j", "revolute", "base", "a", "")));
    let m = Model::from_urdf_str(&xml).unwrap();
    assert_eq!(m.nv(), 1);
}

#[test]
fn malformed_xml() {
    let e = err(r#"<robot name="r"><link name="base"></robot>"#);
    assert!(matches!(e, UrdfError::Malformed(_)), "{e}");
    let e = err("not xml at all <<");
    assert!(matches!(e, UrdfError::Malformed(_)), "{e}");
    let e = err(r#"<robot name="empty"></robot>"#);
    assert!(matches!(e, UrdfError::Malformed(_)), "{e}");
    let e = err(r#"<model name="r"><link name="a"/></model>"#);
    assert!(e.to_string().contains("<model>"), "{e}");
}

#[test]
fn unknown_joint_type_names_joint() {
    let e = err(&robot(
        &(link("a") + &joint("elbow", "ball", "base", "a", "")),
    ));
    assert_eq!(
        e,
        UrdfError::UnknownJointType {
            joint: "elbow".into(),
            joint_type: "ball".into()
        }
    );
    assert!(e.to_string().contains("elbow"));
}

#[test]
fn floating_and_mimic_are_unsupported() {
    let e = err(&robot(
        &(link("a") + &joint("free", "floating", "base", "a", "")),
    ));
    assert!(
        matches!(e, UrdfError::Unsupported { ref joint, .. } if joint == "free"),
        "{e}"
    );
    let body = link("a")
        + &link("b")
        + &joint("j1", "revolute", "base", "a", "")
        + &joint(
            "j2",
            "revolute",
            "a",
            "b",
            r#"<mimic joint="j1" multiplier="2"/>"#,
        );
    let e = err(&robot(&body));
    assert!(
        matches!(e, UrdfError::Unsupported { ref joint, .. } if joint == "j2"),
        "{e}"
    );
    assert!(e.to_string().contains("mimic"));
}

#[test]
fn two_parents_names_link_and_joints() {
    let body = link("a")
        + &link("b")
        + &joint("j1", "revolute", "base", "a", "")
        + &joint("j2", "revolute", "base", "b", "")
        + &joint("j3", "revolute", "a", "b", "");
    let e = err(&robot(&body));
    assert!(
        matches!(e, UrdfError::TwoParents { ref link, .. } if link == "b"),
        "{e}"
    );
}

#[test]
fn cycle_is_detected() {
    // base is the root; a -> b -> a is a loop unreachable from it.
    let body = link("a")
        + &link("b")
        + &link("c")
        + &joint("j0", "revolute", "base", "c", "")
        + &joint("j1", "revolute", "a", "b", "")
        + &joint("j2", "revolute", "b", "a", "");
    let e = err(&robot(&body));
    assert!(matches!(e, UrdfError::Cycle { .. }), "{e}");
}

#[test]
fn missing_inertia_names_link() {
    let body = r#"<link name="a"><inertial><mass value="1"/></inertial></link>"#.to_string()
        + &joint("j", "revolute", "base", "a", "");
    let e = err(&robot(&body));
    assert_eq!(
        e,
        UrdfError::MissingInertia {
            link: "a".into(),
            missing: "inertia"
        }
    );
}

#[test]
fn non_positive_definite_inertia_names_link() {
    let body = r#"<link name="a"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0.5" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#.to_string()
        + &joint("j", "revolute", "base", "a", "");
    let e = err(&robot(&body));
    assert!(
        matches!(e, UrdfError::BadInertia { ref link, .. } if link == "a"),
        "{e}"
    );
    let body = r#"<link name="a"><inertial><mass value="-1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#.to_string()
        + &joint("j", "revolute", "base", "a", "");
    assert!(matches!(err(&robot(&body)), UrdfError::BadInertia { .. }));
}

#[test]
fn massless_moving_link_is_rejected() {
    let body = r#"<link name="a"/>"#.to_string() + &joint("j", "revolute", "base", "a", "");
    let e = err(&robot(&body));
    assert_eq!(e, UrdfError::MasslessJoint { joint: "j".into() });
}

#[test]
fn unknown_link_and_duplicates() {
    let e = err(&robot(
        &(link("a") + &joint("j", "revolute", "base", "zz", "")),
    ));
    assert!(
        matches!(e, UrdfError::UnknownLink { ref link, .. } if link == "zz"),
        "{e}"
    );
    let e = err(&robot(&(link("a") + &link("a"))));
    assert!(
        matches!(
            e,
            UrdfError::Duplicate {
                element: "link",
                ..
            }
        ),
        "{e}"
    );
    let e = err(&robot(&(link("a") + &link("b"))));
    assert!(matches!(e, UrdfError::SeveralRoots { .. }), "{e}");
}

#[test]
fn zero_axis_is_rejected() {
    let body = link("a")
        + r#"<joint name="j" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"#;
    let e = err(&robot(&body));
    assert!(
        matches!(e, UrdfError::BadAxis { ref joint, .. } if joint == "j"),
        "{e}"
    );
}

#[test]
fn revolute_or_prismatic_joint_without_limit_is_rejected_as_urdfdom_does() {
    for ty in ["revolute", "prismatic"] {
        let no_limit = format!(
            r#"<joint name="elbow" type="{ty}"><parent link="base"/><child link="a"/><axis xyz="0 1 0"/></joint>"#
        );
        let e = err(&robot(&(link("a") + &no_limit)));
        assert!(
            matches!(e, UrdfError::MissingLimit { ref joint, ref joint_type } if joint == "elbow" && joint_type == ty),
            "{e}"
        );
        assert!(e.to_string().contains("'elbow'"), "{e}");
        // Self-closing joint element: no children at all.
        let empty = format!(r#"<joint name="bare" type="{ty}"/>"#);
        let e = err(&robot(&(link("a") + &empty)));
        assert!(
            matches!(e, UrdfError::MissingLimit { ref joint, .. } if joint == "bare"),
            "{e}"
        );
    }
    // Continuous joints need none and are unbounded; a <limit> elsewhere in the file does not
    // count for a joint without one.
    let cont = r#"<joint name="wheel" type="continuous"><parent link="base"/><child link="a"/><axis xyz="0 1 0"/></joint>"#;
    let m = Model::from_urdf_str(&robot(&(link("a") + cont))).unwrap();
    assert_eq!(
        (m.joints[0].lower, m.joints[0].upper),
        (f64::NEG_INFINITY, f64::INFINITY)
    );
    let no_limit = r#"<joint name="knee" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 1 0"/></joint>"#;
    let body = link("a") + &link("b") + &joint("hip", "revolute", "base", "a", "") + no_limit;
    let e = err(&robot(&body));
    assert!(
        matches!(e, UrdfError::MissingLimit { ref joint, .. } if joint == "knee"),
        "{e}"
    );
    // With its <limit>, the range is the one written.
    let m = Model::from_urdf_str(&robot(
        &(link("a") + &joint("j", "prismatic", "base", "a", "")),
    ))
    .unwrap();
    assert_eq!((m.joints[0].lower, m.joints[0].upper), (-1.0, 1.0));
}

#[test]
fn missing_file_is_an_io_error() {
    let e = Model::from_urdf_file("/nonexistent/robot.urdf").unwrap_err();
    assert!(matches!(e, UrdfError::Io { .. }));
}

#[test]
fn sibling_order_is_alphabetical_by_joint_name_depth_first() {
    // Children of base: "zeta" (with a grandchild) and "alpha"; Pinocchio order is
    // alpha, zeta, zeta_child, regardless of the order in the file.
    let body = link("a")
        + &link("b")
        + &link("c")
        + &joint("zeta", "revolute", "base", "a", "")
        + &joint("zeta_child", "prismatic", "a", "b", "")
        + &joint(
            "alpha",
            "continuous",
            "base",
            "c",
            r#"<dynamics damping="0.5" friction="0.1"/>"#,
        );
    let m = Model::from_urdf_str(&robot(&body)).unwrap();
    assert_eq!(m.joint_names(), ["alpha", "zeta", "zeta_child"]);
    assert_eq!(m.joints[2].parent, Some(1));
    assert!(m.joints[0].upper.is_infinite());
    assert_eq!((m.joints[0].damping, m.joints[0].friction), (0.5, 0.1));
}

/// Truncated or corrupted versions of a real URDF are rejected or accepted, never a panic.
#[test]
fn corrupted_urdfs_never_panic() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/fixtures/pinocchio/arm7.urdf"
    ))
    .unwrap();
    let bytes = text.as_bytes();
    let mut state = 0x2545F4914F6CDD1Du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let replacements = [b'<', b'>', b'"', b'/', b'0', b'-', b' ', b'x', b'e'];
    for _ in 0..300 {
        let cut = (next() % bytes.len() as u64) as usize;
        let mut corrupted = bytes.to_vec();
        let pos = (next() % bytes.len() as u64) as usize;
        corrupted[pos] = replacements[(next() % replacements.len() as u64) as usize];
        for candidate in [&bytes[..cut], &corrupted[..]] {
            let s = String::from_utf8_lossy(candidate).into_owned();
            let r = std::panic::catch_unwind(|| Model::from_urdf_str(&s).map(|m| m.nv()));
            assert!(r.is_ok(), "panicked on input cut at {cut} / byte {pos}");
        }
    }
}

/// Runs `f` on a thread with a 256 KiB stack (the main thread has 8 MiB): anything recursing
/// once per link or per XML level would overflow it on the inputs below.
fn on_small_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new()
        .stack_size(256 << 10)
        .spawn(f)
        .unwrap()
        .join()
        .expect("no stack overflow or panic")
}

#[test]
fn a_ten_thousand_link_chain_loads_without_recursion() {
    const N: usize = 10_000;
    let mut body = String::new();
    let mut parent = "base".to_string();
    for i in 0..N {
        let name = format!("l{i:05}");
        body += &link(&name);
        body += &joint(&format!("j{i:05}"), "revolute", &parent, &name, "");
        parent = name;
    }
    let xml = robot(&body);
    let m = on_small_stack(move || Model::from_urdf_str(&xml)).unwrap();
    assert_eq!(m.nv(), N);
    assert_eq!(m.frames.len(), N + 1);
    // A chain: joint i hangs from joint i - 1, in order, and each moves its 1 kg link.
    for (i, j) in m.joints.iter().enumerate() {
        assert_eq!(j.parent, i.checked_sub(1), "joint {i}");
        assert_eq!(j.name, format!("j{i:05}"));
    }
    assert_eq!(m.total_mass(), N as f64);
}

#[test]
fn deep_xml_nesting_is_rejected_before_parsing() {
    use tandem_dynamics::rigid::MAX_XML_DEPTH;
    // `<robot>` is level 1, so `levels` nested `<x>` reach depth `levels + 1`.
    let nested = |levels: usize| robot(&("<x>".repeat(levels) + &"</x>".repeat(levels)));
    let xml = nested(20_000);
    let e = on_small_stack(move || err(&xml));
    assert!(
        matches!(
            e,
            UrdfError::TooLarge {
                limit: MAX_XML_DEPTH,
                ..
            }
        ),
        "{e}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("XML nesting depth") && msg.contains("256"),
        "{msg}"
    );
    // The limit itself is accepted (urdf-rs ignores unknown elements); one more level is not.
    let xml = nested(MAX_XML_DEPTH - 1);
    let m = on_small_stack(move || Model::from_urdf_str(&xml));
    assert_eq!(m.map(|m| m.nv()), Ok(0));
    let xml = nested(MAX_XML_DEPTH);
    assert!(matches!(err(&xml), UrdfError::TooLarge { .. }));
}

#[test]
fn oversized_input_is_rejected_by_size() {
    use tandem_dynamics::rigid::MAX_URDF_BYTES;
    let pad = MAX_URDF_BYTES + 1 - robot("").len();
    let xml = robot(&" ".repeat(pad));
    assert_eq!(xml.len(), MAX_URDF_BYTES + 1);
    let e = err(&xml);
    assert!(
        matches!(
            e,
            UrdfError::TooLarge {
                limit: MAX_URDF_BYTES,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("size"), "{e}");
    // From a file, without reading past the limit.
    let path = std::env::temp_dir().join(format!("tandem-oversized-{}.urdf", std::process::id()));
    std::fs::write(&path, &xml).unwrap();
    let e = Model::from_urdf_file(&path).expect_err("too large");
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(e, UrdfError::TooLarge { .. }), "{e}");
}
