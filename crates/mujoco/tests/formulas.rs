//! The task formulas recomputed from gymnasium's recorded states, without MuJoCo: for the tasks
//! whose observation, reward and termination depend only on `qpos`/`qvel`, every recorded step's
//! observation, reward, flags and `info` terms must come out bit for bit.

mod common;

use tandem_envs::{Action, ObservedTask, Task};
use tandem_mujoco::{GymTask, Readout, TaskKind};

fn check(kind: TaskKind) {
    let fx = common::load(kind.spec().id);
    let mut obs = Vec::new();
    let mut steps = 0;
    for ep in &fx.episodes {
        let (mut qpos, mut qvel) = (ep.init_qpos.clone(), ep.init_qvel.clone());
        let first = Readout {
            qpos: &qpos,
            qvel: &qvel,
            bodies: &[],
            cfrc_ext: &[],
        };
        kind.observe(&first, &mut obs);
        assert_eq!(obs, ep.reset_obs, "seed {} reset observation", ep.seed);
        for (t, s) in ep.steps.iter().enumerate() {
            let at = format!("{} seed {} step {t}", kind.spec().id, ep.seed);
            let action: Vec<f32> = s.action.iter().map(|&a| a as f32).collect();
            let before = Readout {
                qpos: &qpos,
                qvel: &qvel,
                bodies: &[],
                cfrc_ext: &[],
            };
            let after = Readout {
                qpos: &s.qpos,
                qvel: &s.qvel,
                bodies: &[],
                cfrc_ext: &[],
            };
            let o = kind.outcome(&before, &after, &action, &fx.init_qpos);
            assert_eq!(o.reward, s.reward, "{at}: reward");
            assert_eq!(o.terminated, s.terminated, "{at}: terminated");
            kind.observe(&after, &mut obs);
            assert_eq!(obs, s.obs, "{at}: observation");
            assert_eq!(o.terms().count(), s.info.len(), "{at}: info keys");
            for (name, value) in &s.info {
                assert_eq!(o.term(name), Some(*value), "{at}: info {name}");
            }
            qpos.clone_from(&s.qpos);
            qvel.clone_from(&s.qvel);
            steps += 1;
        }
    }
    assert!(steps >= 15, "{steps} steps checked");
}

#[test]
fn half_cheetah_formulas_match_gymnasium() {
    check(TaskKind::HalfCheetah);
}

#[test]
fn hopper_formulas_match_gymnasium() {
    check(TaskKind::Hopper);
}

#[test]
fn walker2d_formulas_match_gymnasium() {
    check(TaskKind::Walker2d);
}

#[test]
fn inverted_pendulum_formulas_match_gymnasium() {
    check(TaskKind::InvertedPendulum);
}

/// `GymTask` over the recorded states gives gymnasium's observations, rewards and terminations
/// for every task that is a function of `qpos`/`qvel`, and refuses the others.
#[test]
fn the_gym_task_over_recorded_states_matches_gymnasium() {
    for kind in [
        TaskKind::HalfCheetah,
        TaskKind::Hopper,
        TaskKind::Walker2d,
        TaskKind::InvertedPendulum,
    ] {
        let fx = common::load(kind.spec().id);
        let task = GymTask::new(kind, fx.init_qpos.clone()).unwrap();
        assert_eq!(task.observation_space().flat_dim(), kind.spec().obs_dim);
        for ep in &fx.episodes {
            let mut x: Vec<f64> = ep.init_qpos.iter().chain(&ep.init_qvel).copied().collect();
            assert_eq!(task.observe(&x), ep.reset_obs);
            for (t, s) in ep.steps.iter().enumerate() {
                let at = format!("{} seed {} step {t}", kind.spec().id, ep.seed);
                let next: Vec<f64> = s.qpos.iter().chain(&s.qvel).copied().collect();
                let u = task.control(&Action::Continuous(s.action.clone()));
                if s.action.iter().all(|a| a.abs() <= kind.spec().action_bound) {
                    assert_eq!(task.reward(&x, &u, &next), s.reward, "{at}: reward");
                }
                assert_eq!(task.terminated(&next), s.terminated, "{at}: terminated");
                assert_eq!(task.observe(&next), s.obs, "{at}: observation");
                // The canonical pair keeps the reward: x moves to 0, its change stays.
                let (c, c1) = tandem_models::canonical_pair(&task, &x, &next);
                let r = task.reward(&c, &u, &c1);
                assert!((r - task.reward(&x, &u, &next)).abs() < 1e-9, "{at}");
                x = next;
            }
        }
    }
    for kind in [TaskKind::Ant, TaskKind::Reacher, TaskKind::Pusher] {
        let err = GymTask::new(kind, vec![0.0; kind.spec().nq]).unwrap_err();
        assert!(err.to_string().contains("more than qpos and qvel"), "{err}");
    }
    let err = GymTask::new(TaskKind::Hopper, vec![0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("init_qpos must be 6"), "{err}");
}

/// Episodes start around `qpos0` with gymnasium's noise (Hopper: ±0.005) and the step length.
#[test]
fn the_gym_task_starts_near_qpos0() {
    let q0 = vec![0.0, 1.25, 0.0, 0.0, 0.0, 0.0];
    let task = GymTask::new(TaskKind::Hopper, q0.clone()).unwrap();
    let mut rng = tandem_core::seeding::rng_from_seed(3);
    let x = task.initial_state(&mut rng);
    assert_eq!(x.len(), task.state_dim());
    assert!(x
        .iter()
        .zip(q0.iter().chain(&[0.0; 6]))
        .all(|(a, b)| (a - b).abs() <= 0.005));
    assert!(!task.terminated(&x));
    assert_eq!(task.max_episode_steps(), Some(1000));
}

/// The reward and termination read off gymnasium's recorded observations: termination and
/// InvertedPendulum's reward exactly; the locomotion tasks' forward reward, whose x position the
/// observation leaves out, within the error of the velocity approximation.
#[test]
fn the_gym_task_over_recorded_observations_scores_as_gymnasium() {
    for (kind, tolerance) in [
        (TaskKind::HalfCheetah, 0.6),
        (TaskKind::Hopper, 0.02),
        (TaskKind::Walker2d, 0.04),
        (TaskKind::InvertedPendulum, 0.0),
    ] {
        let fx = common::load(kind.spec().id);
        let task = GymTask::new(kind, fx.init_qpos.clone()).unwrap();
        let mut worst: f64 = 0.0;
        for ep in &fx.episodes {
            let mut obs = ep.reset_obs.clone();
            for (t, s) in ep.steps.iter().enumerate() {
                let at = format!("{} seed {} step {t}", kind.spec().id, ep.seed);
                let u = task.control(&Action::Continuous(s.action.clone()));
                assert_eq!(
                    task.observation_terminated(&s.obs),
                    s.terminated,
                    "{at}: terminated"
                );
                if s.action.iter().all(|a| a.abs() <= kind.spec().action_bound) {
                    let r = task.observation_reward(&obs, &u, &s.obs);
                    worst = worst.max((r - s.reward).abs());
                }
                obs.clone_from(&s.obs);
            }
        }
        assert!(worst <= tolerance, "{}: {worst}", kind.spec().id);
    }
}
