//! The task formulas recomputed from gymnasium's recorded states, without MuJoCo: for the tasks
//! whose observation, reward and termination depend only on `qpos`/`qvel`, every recorded step's
//! observation, reward, flags and `info` terms must come out bit for bit.

mod common;

use tandem_mujoco::{Readout, TaskKind};

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
