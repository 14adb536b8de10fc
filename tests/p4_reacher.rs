//! p4's reacher (feature `mujoco`): the DDPG baseline measured on test targets, stopped and
//! resumed to the same numbers, deterministic per seed, and refusing bad settings.
#![cfg(feature = "mujoco")]

use tandem::algos::manipulation::{reacher_test_set, train_ddpg_reacher, ReacherDdpg, TestedPoint};
use tandem::algos::{AlgoError, Checkpoints, Ephemeral, InMemory, Result};
use tandem::robots::p4::ReacherCost;
use tandem_nn::Checkpoint;

/// 300 steps of a small DDPG, measured every 100 on 5 test targets.
fn small() -> ReacherDdpg {
    let mut c = ReacherDdpg {
        steps: 300,
        eval_every: 100,
        ..ReacherDdpg::default()
    };
    c.agent.actor_hidden = vec![16, 16];
    c.agent.critic_hidden = vec![16, 16];
    c.agent.batch_size = 16;
    c.agent.learning_starts = 50;
    c
}

/// Keeps checkpoints in memory and asks to stop once `after` of them were saved.
struct StopAfter {
    inner: InMemory,
    after: usize,
}

impl Checkpoints for StopAfter {
    fn load(&mut self, key: &str) -> Result<Option<Checkpoint>> {
        self.inner.load(key)
    }
    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> Result<()> {
        self.inner.save(key, ckpt)
    }
    fn stop_requested(&self) -> bool {
        self.inner.saves() >= self.after
    }
}

fn run(store: &mut dyn Checkpoints, seed: u64) -> Result<Vec<TestedPoint>> {
    let test = reacher_test_set(5, 1);
    train_ddpg_reacher(
        ReacherCost::default(),
        &small(),
        &test,
        seed,
        store,
        &mut |_| {},
    )
}

#[test]
fn ddpg_on_the_reacher_resumes_to_the_same_numbers() {
    let whole = run(&mut Ephemeral, 3).unwrap();
    let at: Vec<u64> = whole.iter().map(|p| p.samples).collect();
    assert_eq!(at, [0, 100, 200, 300]);
    for p in &whole {
        // A distance within the arm's reach of targets within 0.2 m of the shoulder.
        assert!(p.test_measure > 0.0 && p.test_measure < 0.45, "{p:?}");
    }
    assert_eq!(run(&mut Ephemeral, 3).unwrap(), whole);
    assert_ne!(run(&mut Ephemeral, 4).unwrap(), whole);
    // Stopped after its first checkpoint (step 100), then resumed from the same store.
    let mut store = StopAfter {
        inner: InMemory::default(),
        after: 1,
    };
    assert!(matches!(run(&mut store, 3), Err(AlgoError::Stopped)));
    store.after = usize::MAX;
    assert_eq!(run(&mut store, 3).unwrap(), whole);
    // Another seed refuses that checkpoint.
    assert!(matches!(run(&mut store, 4), Err(AlgoError::Checkpoint(_))));
}

#[test]
fn ddpg_on_the_reacher_refuses_bad_settings() {
    let test = reacher_test_set(5, 1);
    for cfg in [
        ReacherDdpg {
            eval_every: 0,
            ..small()
        },
        ReacherDdpg {
            steps: 0,
            ..small()
        },
    ] {
        let r = train_ddpg_reacher(
            ReacherCost::default(),
            &cfg,
            &test,
            0,
            &mut Ephemeral,
            &mut |_| {},
        );
        assert!(matches!(r, Err(AlgoError::Config(_))), "{cfg:?}");
    }
    let mut bad = small();
    bad.agent.tau = 2.0;
    assert!(train_ddpg_reacher(
        ReacherCost::default(),
        &bad,
        &test,
        0,
        &mut Ephemeral,
        &mut |_| {},
    )
    .is_err());
    let cost = ReacherCost {
        alpha: -1.0,
        ..ReacherCost::default()
    };
    assert!(train_ddpg_reacher(cost, &small(), &test, 0, &mut Ephemeral, &mut |_| {}).is_err());
}
