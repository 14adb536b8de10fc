//! p4's MJCF scenes (feature `mujoco`): they load with the dimensions the task code assumes, the
//! task's forward kinematics is MuJoCo's, and the physics does what the tasks need.
#![cfg(feature = "mujoco")]

use nalgebra::DVector;
use tandem_dynamics::Plant;
use tandem_mujoco::{MujocoPlant, Scene};
use tandem_robots::p4::{
    pusher_gripper, scene_path, PUSHER_ACTION_DIM, PUSHER_CONDITIONS, PUSHER_FRAME_SKIP,
    PUSHER_SCENE, PUSHER_STATE_DIM,
};

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

/// The door scene: the task's dimensions, a gravity-compensated arm that zero torque holds still
/// from every start with the door closed, and the grasp point where the scene's geometry puts
/// it (0.0565 m in front of the door face, 0.35 m from the hinge), moving with the door.
#[test]
fn door_scene_holds_still_and_its_grasp_point_turns_with_the_door() {
    use tandem_robots::p4::{
        door_initial_state, DOOR_ACTION_DIM, DOOR_ANGLE, DOOR_CONDITIONS, DOOR_FRAME_SKIP,
        DOOR_SCENE, DOOR_STATE_DIM,
    };
    let p = MujocoPlant::from_xml(scene_path(DOOR_SCENE), DOOR_FRAME_SKIP).unwrap();
    assert_eq!(
        (p.state_dim(), p.action_dim()),
        (DOOR_STATE_DIM, DOOR_ACTION_DIM)
    );
    for c in 0..DOOR_CONDITIONS.len() {
        let x0 = DVector::from_vec(door_initial_state(c));
        let mut x = x0.clone();
        for _ in 0..100 {
            x = p.step(&x, &DVector::zeros(DOOR_ACTION_DIM));
        }
        assert!(
            (&x - &x0).amax() < 1e-9,
            "condition {c}: drifted by {}",
            (&x - &x0).amax()
        );
    }
    let scene = Scene::from_xml(scene_path(DOOR_SCENE)).unwrap();
    let id = scene.site_id("handle").unwrap();
    let mut q = door_initial_state(0)[..7].to_vec();
    let closed = scene.site_positions(&q, &[id]).unwrap()[0];
    let expect = [0.76 - 0.0565, 0.35, 0.9];
    for k in 0..3 {
        assert!((closed[k] - expect[k]).abs() < 1e-12, "{closed:?}");
    }
    // Opened by θ about the vertical hinge at (0.76, 0): the point turns on its 0.3545 m circle.
    let theta: f64 = 0.7;
    q[DOOR_ANGLE] = theta;
    let open = scene.site_positions(&q, &[id]).unwrap()[0];
    let (dx, dy) = (-0.0565, 0.35);
    let turned = [
        0.76 + dx * theta.cos() - dy * theta.sin(),
        dx * theta.sin() + dy * theta.cos(),
    ];
    assert!(
        (open[0] - turned[0]).abs() < 1e-12 && (open[1] - turned[1]).abs() < 1e-12,
        "{open:?} vs {turned:?}"
    );
}

/// p4's reacher is gymnasium's `reacher.xml`: its `qpos0`, dimensions and control period, and a
/// fingertip–target offset equal to the one gymnasium observes (MuJoCo's body positions), and
/// gymnasium's whole observation.
#[test]
fn reacher_kinematics_is_gymnasiums() {
    use tandem_envs::Env;
    use tandem_mujoco::{assets_dir, MujocoEnv, TaskKind};
    use tandem_robots::p4::{
        reacher_fingertip, reacher_observation, REACHER_ACTION_DIM, REACHER_OBS_DIM, REACHER_QPOS0,
        REACHER_STATE_DIM,
    };
    let mut env = MujocoEnv::task(TaskKind::Reacher, &assets_dir()).unwrap();
    assert_eq!(env.scene_ref().qpos0(), &REACHER_QPOS0);
    let plant = env.plant();
    assert_eq!(plant.state_dim(), REACHER_STATE_DIM);
    assert_eq!(plant.action_dim(), REACHER_ACTION_DIM);
    assert!((plant.dt() - 0.02).abs() < 1e-15);
    for x in [
        [0.0, 0.0, 0.1, -0.1, 0.0, 0.0, 0.0, 0.0],
        [0.7, -1.9, -0.05, 0.15, 0.1, 0.2, 0.0, 0.0],
        [-2.8, 2.5, 0.12, 0.02, 0.0, 0.0, 0.0, 0.0],
    ] {
        let obs = env.set_state(&x).unwrap();
        let p = reacher_fingertip(&x);
        let (dx, dy) = (p[0] - x[2], p[1] - x[3]);
        assert!(
            (obs[8] - dx).abs() < 1e-12 && (obs[9] - dy).abs() < 1e-12,
            "{x:?}: gymnasium ({}, {}), ours ({dx}, {dy})",
            obs[8],
            obs[9]
        );
        let mut ours = [0.0; REACHER_OBS_DIM];
        reacher_observation(&x, &mut ours);
        for (a, b) in obs.iter().zip(ours) {
            assert!(
                (a - b).abs() < 1e-12,
                "{x:?}: gymnasium {obs:?}, ours {ours:?}"
            );
        }
    }
}

/// The pusher as an environment: its command box is the scene's `ctrlrange`, it observes the
/// state and the goal, and a step at rest from a condition's start pays the cost of the start,
/// whose distances follow from the condition's coordinates (the gripper at `(1.05, 0)`).
#[test]
fn pusher_task_is_an_environment_over_the_scene() {
    use tandem_envs::{Action, Env, PlantEnv, Task, TimeLimit};
    use tandem_robots::p4::{
        l12, pusher_plant, PusherCost, PusherTask, PUSHER_HORIZON, PUSHER_OBS_DIM,
    };
    let scene = Scene::from_xml(scene_path(PUSHER_SCENE)).unwrap();
    let cost = PusherCost::default();
    let cond = PUSHER_CONDITIONS[1];
    let task = PusherTask::new(cost, cond).unwrap();
    assert_eq!(task.action_space(), &scene.action_space());
    // A `PlantEnv` does not truncate by itself; the task's episode length goes to a `TimeLimit`.
    let horizon = task.max_episode_steps().unwrap();
    let mut env = TimeLimit::new(
        PlantEnv::from_parts(pusher_plant().unwrap(), task).unwrap(),
        horizon,
    );
    let obs = env.reset(Some(0));
    assert_eq!(obs.len(), PUSHER_OBS_DIM);
    assert_eq!(&obs[..PUSHER_STATE_DIM], cond.initial_state().as_slice());
    assert_eq!(&obs[PUSHER_STATE_DIM..], &cond.goal);
    let step = env
        .step(&Action::Continuous(vec![0.0; PUSHER_ACTION_DIM]))
        .unwrap();
    let pen = |d: f64| l12(d, cost.l1, cost.l2, cost.alpha);
    let block_goal = (cond.block[0] - cond.goal[0]).hypot(cond.block[1] - cond.goal[1]);
    let gripper_block = (cond.block[0] - 1.05).hypot(cond.block[1]);
    let expect = -(cost.goal * pen(block_goal) + cost.block * pen(gripper_block));
    assert!(
        (step.reward - expect).abs() < 1e-9,
        "{} vs {expect}",
        step.reward
    );
    // Commands beyond the motors' limits are clipped to them, and the episode lasts 100 steps.
    let mut steps = 1;
    for _ in 0..PUSHER_HORIZON {
        let s = env
            .step(&Action::Continuous(vec![100.0, -100.0, 0.0, 0.0]))
            .unwrap();
        steps += 1;
        assert!(s.observation.iter().all(|v| v.is_finite()));
        if s.truncated || s.terminated {
            assert!(s.truncated && !s.terminated);
            break;
        }
    }
    assert_eq!(steps, PUSHER_HORIZON);
    assert!(PusherTask::new(
        cost,
        tandem_robots::p4::PusherCondition {
            block: [f64::NAN, 0.0],
            goal: [0.0, 0.0]
        }
    )
    .is_err());
}

/// The door as an environment: the hook's offset from the grasp point at each start is the one
/// the conditions were placed at (their names), the task observes it after the state, a step at
/// rest pays the door's cost of it, and resets draw every start.
#[test]
fn door_task_is_an_environment_over_the_scene() {
    use tandem_envs::{Action, Env, PlantEnv, Task};
    use tandem_robots::p4::{
        door_initial_state, door_plant, l12, DoorCost, DoorKinematics, DoorTask, DOOR_ACTION_DIM,
        DOOR_CONDITIONS, DOOR_OBS_DIM, DOOR_STATE_DIM,
    };
    let kin = DoorKinematics::load().unwrap();
    let placed = [
        [-0.1, 0.0, 0.3],
        [-0.3, 0.0, 0.2],
        [-0.1, 0.25, 0.2],
        [-0.1, -0.25, 0.2],
    ];
    for (c, want) in placed.iter().enumerate() {
        let r = kin.offset(&door_initial_state(c)).unwrap();
        for k in 0..3 {
            assert!((r[k] - want[k]).abs() < 1e-3, "condition {c}: {r:?}");
        }
    }
    assert!(kin.offset(&[f64::NAN; DOOR_STATE_DIM]).is_err());
    assert!(kin.offset_or_nan(&[f64::NAN; DOOR_STATE_DIM])[0].is_nan());
    let short = kin.offset(&[0.0; 3]).unwrap_err().to_string();
    assert!(short.contains("7 joint positions, got 3"), "{short}");
    let cost = DoorCost::default();
    let task = DoorTask::new(cost, kin.clone(), Some(2)).unwrap();
    let mut env = PlantEnv::from_parts(door_plant().unwrap(), task).unwrap();
    let obs = env.reset(Some(5));
    assert_eq!(obs.len(), DOOR_OBS_DIM);
    assert_eq!(&obs[..DOOR_STATE_DIM], door_initial_state(2).as_slice());
    let r = kin.offset(&door_initial_state(2)).unwrap();
    assert_eq!(&obs[DOOR_STATE_DIM..], &r);
    let step = env
        .step(&Action::Continuous(vec![0.0; DOOR_ACTION_DIM]))
        .unwrap();
    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let expect =
        -(cost.hand * l12(d, cost.l1, cost.l2, cost.alpha) + cost.angle * cost.target.powi(2));
    assert!(
        (step.reward - expect).abs() < 1e-6,
        "{} vs {expect}",
        step.reward
    );
    // Without a fixed start, resets draw all four.
    let task = DoorTask::new(cost, kin.clone(), None).unwrap();
    let mut seen = [false; 4];
    let mut rng = tandem_core::seeding::rng_from_seed(1);
    for _ in 0..40 {
        let x = task.initial_state(&mut rng);
        let c = (0..DOOR_CONDITIONS.len())
            .find(|&c| door_initial_state(c) == x)
            .unwrap();
        seen[c] = true;
    }
    assert_eq!(seen, [true; 4]);
    assert!(DoorTask::new(cost, kin.clone(), Some(4)).is_err());
    assert!(DoorTask::new(
        DoorCost {
            alpha: -1.0,
            ..cost
        },
        kin,
        None
    )
    .is_err());
}
