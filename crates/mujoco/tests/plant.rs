//! MuJoCo scenes as plants and environments (feature `mujoco`), against analytic solutions of a
//! slider (`scenes/slider.xml`) and against gymnasium's recorded first steps.
#![cfg(feature = "mujoco")]

mod common;

use nalgebra::{dvector, DMatrix, DVector};
use tandem_dynamics::Plant;
use tandem_envs::{Action, Env};
use tandem_mujoco::{assets_dir, MujocoEnv, MujocoError, MujocoPlant, Scene, TaskKind};

const MASS: f64 = 2.0;
const H: f64 = 0.01;

fn slider_path() -> String {
    format!("{}/tests/scenes/slider.xml", env!("CARGO_MANIFEST_DIR"))
}

/// `k` semi-implicit Euler steps of the slider, written out by hand.
fn slider_exact(x: f64, v: f64, u: f64, k: usize) -> (f64, f64) {
    let (mut x, mut v) = (x, v);
    for _ in 0..k {
        v += H * u / MASS;
        x += H * v;
    }
    (x, v)
}

#[test]
fn slider_plant_steps_as_semi_implicit_euler() {
    let plant = MujocoPlant::from_xml(slider_path(), 3).unwrap();
    assert_eq!((plant.state_dim(), plant.action_dim()), (2, 1));
    assert!((plant.dt() - 0.03).abs() < 1e-15);
    let next = plant.step(&dvector![0.5, -1.0], &dvector![3.0]);
    let (x, v) = slider_exact(0.5, -1.0, 3.0, 3);
    assert!(
        (next[0] - x).abs() < 1e-12 && (next[1] - v).abs() < 1e-12,
        "{next}"
    );
    // MuJoCo clamps ctrl into ctrlrange [-4, 4].
    let clamped = plant.step(&dvector![0.0, 0.0], &dvector![10.0]);
    let (x, v) = slider_exact(0.0, 0.0, 4.0, 3);
    assert!((clamped[0] - x).abs() < 1e-12 && (clamped[1] - v).abs() < 1e-12);
}

#[test]
fn slider_linearization_is_the_analytic_jacobian() {
    let k = 4;
    let plant = MujocoPlant::from_xml(slider_path(), k).unwrap();
    let (a, b) = plant.linearize(&dvector![0.2, 0.7], &dvector![-1.0]);
    let kh = k as f64 * H;
    let a_true = DMatrix::from_row_slice(2, 2, &[1.0, kh, 0.0, 1.0]);
    let b_true = DMatrix::from_row_slice(
        2,
        1,
        &[H * H * (k * (k + 1)) as f64 / (2.0 * MASS), kh / MASS],
    );
    assert!((a - a_true).abs().max() < 1e-8);
    assert!((b - b_true).abs().max() < 1e-8);
}

#[test]
fn plant_steps_are_pure_and_batch_steps_agree() {
    let env = MujocoEnv::task(TaskKind::HalfCheetah, &assets_dir()).unwrap();
    let plant = env.plant();
    let fx = common::load("HalfCheetah-v5");
    let (mut states, mut actions) = (Vec::new(), Vec::new());
    for ep in &fx.episodes {
        states.extend(ep.init_qpos.iter().chain(&ep.init_qvel));
        actions.extend(&ep.steps[0].action);
    }
    let mut next = vec![0.0; states.len()];
    plant.step_batch(&states, &actions, &mut next).unwrap();
    for (i, ep) in fx.episodes.iter().enumerate() {
        let x = DVector::from_column_slice(&states[i * 18..(i + 1) * 18]);
        let u = DVector::from_column_slice(&actions[i * 6..(i + 1) * 6]);
        let one = plant.step(&x, &u);
        // Twice the same step (the pool's scratch data keeps no warm start).
        assert_eq!(one, plant.step(&x, &u));
        assert_eq!(one.as_slice(), &next[i * 18..(i + 1) * 18]);
        // The first step after a reset has no warm start in gymnasium either: bit-identical.
        let s = &ep.steps[0];
        let expected: Vec<f64> = s.qpos.iter().chain(&s.qvel).copied().collect();
        assert_eq!(one.as_slice(), &expected[..]);
    }
}

#[test]
fn first_plant_step_of_every_task_is_gymnasium_s() {
    for kind in TaskKind::ALL {
        let spec = kind.spec();
        let plant = MujocoEnv::task(kind, &assets_dir()).unwrap().plant();
        assert!((plant.dt() - kind.dt()).abs() < 1e-15);
        let ep = &common::load(spec.id).episodes[0];
        let x: Vec<f64> = ep.init_qpos.iter().chain(&ep.init_qvel).copied().collect();
        let mut next = vec![0.0; x.len()];
        plant.step_into(&x, &ep.steps[0].action, &mut next);
        let s = &ep.steps[0];
        let expected: Vec<f64> = s.qpos.iter().chain(&s.qvel).copied().collect();
        assert_eq!(next, expected, "{}", spec.id);
    }
}

#[test]
fn any_mjcf_scene_is_an_environment() {
    let scene = Scene::from_xml(slider_path()).unwrap();
    let mut env = MujocoEnv::scene(scene, 2).unwrap();
    assert_eq!(env.id(), "mjcf:slider.xml");
    assert_eq!(env.reset(Some(0)), vec![0.0, 0.0]);
    let step = env.step(&Action::Continuous(vec![2.0])).unwrap();
    let (x, v) = slider_exact(0.0, 0.0, 2.0, 2);
    assert!((step.observation[0] - x).abs() < 1e-12 && (step.observation[1] - v).abs() < 1e-12);
    assert_eq!(
        (step.reward, step.terminated, step.truncated),
        (0.0, false, false)
    );
    assert_eq!(env.state(), step.observation);
    // Bad input is an error naming the problem.
    assert!(env.step(&Action::Continuous(vec![f64::NAN])).is_err());
    assert!(env.step(&Action::Continuous(vec![1.0, 2.0])).is_err());
    assert!(env.set_state(&[0.0]).is_err());
    assert!(env.set_state(&[0.0, f64::INFINITY]).is_err());
}

#[test]
fn bad_files_are_errors_not_panics() {
    let missing = Scene::from_xml("/nonexistent/scene.xml").unwrap_err();
    assert!(matches!(missing, MujocoError::Load { .. }), "{missing}");
    let dir = std::env::temp_dir().join(format!("tandem-mujoco-bad-{}.xml", std::process::id()));
    std::fs::write(
        &dir,
        "<mujoco><worldbody><body><joint type='nonsense'/></body></worldbody></mujoco>",
    )
    .unwrap();
    let err = Scene::from_xml(&dir).unwrap_err();
    std::fs::remove_file(&dir).ok();
    assert!(matches!(err, MujocoError::Load { .. }), "{err}");
    assert!(MujocoPlant::from_xml(slider_path(), 0).is_err());
    // A task over the wrong file is refused with the dimensions it expected.
    let err = MujocoEnv::task(
        TaskKind::Ant,
        std::path::Path::new(&format!("{}/tests/scenes", env!("CARGO_MANIFEST_DIR"))),
    )
    .unwrap_err();
    assert!(err.to_string().contains("ant.xml"), "{err}");
}

#[test]
fn env_steps_need_a_reset_and_stop_after_termination() {
    let mut env = MujocoEnv::task(TaskKind::InvertedPendulum, &assets_dir()).unwrap();
    assert!(env.step(&Action::Continuous(vec![0.0])).is_err());
    env.reset(Some(1));
    let mut t = 0;
    loop {
        let s = env.step(&Action::Continuous(vec![3.0])).unwrap();
        t += 1;
        if s.terminated {
            assert_eq!(s.reward, 0.0);
            break;
        }
        assert!(t < 1000);
    }
    assert!(env.step(&Action::Continuous(vec![0.0])).is_err());
    // Seeded resets are reproducible and within gymnasium's noise.
    let a = env.reset(Some(7));
    assert_eq!(a, env.reset(Some(7)));
    assert!(a.iter().all(|v| v.abs() <= 0.01));
}
