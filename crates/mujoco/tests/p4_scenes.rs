//! p4's MJCF scenes (feature `mujoco`): they load with the dimensions the task code assumes, the
//! task's forward kinematics is MuJoCo's, and the physics does what the tasks need.
#![cfg(feature = "mujoco")]

use nalgebra::DVector;
use tandem_dynamics::Plant;
use tandem_mujoco::p4::{
    pusher_gripper, scene_path, PUSHER_ACTION_DIM, PUSHER_CONDITIONS, PUSHER_FRAME_SKIP,
    PUSHER_SCENE, PUSHER_STATE_DIM,
};
use tandem_mujoco::{MujocoPlant, Scene};

fn pusher() -> MujocoPlant {
    MujocoPlant::from_xml(scene_path(PUSHER_SCENE), PUSHER_FRAME_SKIP).unwrap()
}

#[test]
fn pusher_scene_has_the_task_dimensions_and_control_period() {
    let p = pusher();
    assert_eq!(p.state_dim(), PUSHER_STATE_DIM);
    assert_eq!(p.action_dim(), PUSHER_ACTION_DIM);
    assert!((p.dt() - 0.05).abs() < 1e-15);
}

#[test]
fn pusher_gripper_kinematics_is_mujocos() {
    let scene = Scene::from_xml(scene_path(PUSHER_SCENE)).unwrap();
    let id = scene.site_id("gripper").unwrap();
    for q in [
        [0.0, 0.0, 0.0],
        [0.7, -1.2, 0.4],
        [-2.5, 2.0, -1.9],
        [1.3, 0.3, 1.1],
    ] {
        let qpos = [q[0], q[1], q[2], 0.03, 0.4, -0.2];
        let site = scene.site_positions(&qpos, &[id]).unwrap()[0];
        let ours = pusher_gripper(&q);
        assert!(
            (site[0] - ours[0]).abs() < 1e-12 && (site[1] - ours[1]).abs() < 1e-12,
            "{q:?}: MuJoCo {site:?}, ours {ours:?}"
        );
    }
    assert!(scene.site_id("nowhere").is_err());
    assert!(scene.site_positions(&[0.0; 3], &[id]).is_err());
    assert!(scene
        .site_positions(&[f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0], &[id])
        .is_err());
}

/// The block only moves when the arm touches it: from each condition's start, zero torque leaves
/// it where it is, and sweeping the arm through it moves it.
#[test]
fn pusher_block_moves_only_on_contact() {
    let p = pusher();
    for (i, c) in PUSHER_CONDITIONS.iter().enumerate() {
        let mut x = DVector::from_vec(c.initial_state());
        for _ in 0..40 {
            x = p.step(&x, &DVector::zeros(4));
        }
        assert!(
            (x[4] - c.block[0]).abs() < 1e-9 && (x[5] - c.block[1]).abs() < 1e-9,
            "condition {i}: block drifted to ({}, {})",
            x[4],
            x[5]
        );
    }
    // Block in the arm's sweep: (0.7, 0.3) lies at radius 0.76 and angle 0.40 rad.
    let mut x = DVector::from_vec(vec![
        0.0, 0.0, 0.0, 0.0, 0.7, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    ]);
    for _ in 0..30 {
        x = p.step(&x, &DVector::from_vec(vec![4.0, 0.0, 0.0, 0.0]));
        assert!(x.iter().all(|v| v.is_finite()));
    }
    let moved = (x[4] - 0.7).hypot(x[5] - 0.3);
    assert!(moved > 0.1, "block moved only {moved} m");
}
