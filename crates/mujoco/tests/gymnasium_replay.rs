//! Real MuJoCo against gymnasium 1.4.0 (feature `mujoco`): every recorded episode replayed from its
//! recorded start gives bit-identical `qpos`, `qvel` and observations, rewards and `info` terms
//! within 1e-12 (bit-exact except where gymnasium takes a norm through BLAS), and identical
//! `terminated`/`truncated` under the registered time limit.
#![cfg(feature = "mujoco")]

mod common;

use tandem_envs::{Action, Env, TimeLimit};
use tandem_mujoco::{assets_dir, MujocoEnv, TaskKind};

fn replay(kind: TaskKind) {
    let spec = kind.spec();
    let fx = common::load(spec.id);
    let env = MujocoEnv::task(kind, &assets_dir()).unwrap();
    let mut env = TimeLimit::new(env, spec.max_episode_steps);
    let mut steps = 0;
    for ep in &fx.episodes {
        env.reset(Some(ep.seed));
        let mut state = ep.init_qpos.clone();
        state.extend_from_slice(&ep.init_qvel);
        let obs = env.set_state(&state).unwrap();
        assert_eq!(
            obs, ep.reset_obs,
            "{} seed {} reset observation",
            spec.id, ep.seed
        );
        for (t, s) in ep.steps.iter().enumerate() {
            let at = format!("{} seed {} step {t}", spec.id, ep.seed);
            let step = env.step(&Action::Continuous(s.action.clone())).unwrap();
            let mut expected = s.qpos.clone();
            expected.extend_from_slice(&s.qvel);
            assert_eq!(env.state(), expected, "{at}: qpos ++ qvel");
            assert_eq!(step.observation, s.obs, "{at}: observation");
            assert!(
                (step.reward - s.reward).abs() <= 1e-12,
                "{at}: reward {} vs {}",
                step.reward,
                s.reward
            );
            assert_eq!(
                (step.terminated, step.truncated),
                (s.terminated, s.truncated),
                "{at}: flags"
            );
            let outcome = env.inner().last_outcome().unwrap();
            assert_eq!(outcome.terms().count(), s.info.len(), "{at}: info keys");
            for (name, value) in &s.info {
                let got = outcome.term(name).unwrap();
                assert!(
                    (got - value).abs() <= 1e-12,
                    "{at}: info {name} {got} vs {value}"
                );
            }
            steps += 1;
        }
        // The episode ended exactly where gymnasium's did (or the recording stopped at 100).
        let last = ep.steps.last().unwrap();
        assert!(last.terminated || last.truncated || ep.steps.len() == 100);
    }
    assert!(steps >= 15, "{steps} steps replayed");
}

#[test]
fn half_cheetah_replays_gymnasium_exactly() {
    replay(TaskKind::HalfCheetah);
}

#[test]
fn hopper_replays_gymnasium_exactly() {
    replay(TaskKind::Hopper);
}

#[test]
fn walker2d_replays_gymnasium_exactly() {
    replay(TaskKind::Walker2d);
}

#[test]
fn ant_replays_gymnasium_exactly() {
    replay(TaskKind::Ant);
}

#[test]
fn inverted_pendulum_replays_gymnasium_exactly() {
    replay(TaskKind::InvertedPendulum);
}

#[test]
fn reacher_replays_gymnasium_exactly() {
    replay(TaskKind::Reacher);
}

#[test]
fn pusher_replays_gymnasium_exactly() {
    replay(TaskKind::Pusher);
}
