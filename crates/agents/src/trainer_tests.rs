//! Determinism and save/resume of whole runs, on a small environment defined here (so the test
//! does not depend on any particular task implementation).

use rand::{Rng as _, SeedableRng};
use tandem_core::{Action, Rng, Space};
use tandem_envs::{Env, EnvError, Step};

use crate::config::{DdpgConfig, DqnConfig, ReinforceConfig, SacConfig};
use crate::learner::{AlgoConfig, Learner};
use crate::trainer::{Pause, TrainSettings, Trainer};
use crate::AgentError;
use std::ops::ControlFlow;

/// A damped point mass: obs `[x, v]`, push `u` in `[-1, 1]` (or 3 discrete pushes), reward
/// `-x²`, terminated when `|x| > 2`, episodes of at most 30 steps.
struct PointMass {
    obs_space: Space,
    act_space: Space,
    rng: Rng,
    x: f64,
    v: f64,
}

impl PointMass {
    fn new(discrete: bool) -> Self {
        Self {
            obs_space: Space::symmetric(2, f64::INFINITY),
            act_space: if discrete {
                Space::discrete(3)
            } else {
                Space::symmetric(1, 1.0)
            },
            rng: Rng::seed_from_u64(0),
            x: 0.0,
            v: 0.0,
        }
    }
}

impl Env for PointMass {
    fn id(&self) -> &str {
        "PointMass"
    }
    fn observation_space(&self) -> &Space {
        &self.obs_space
    }
    fn action_space(&self) -> &Space {
        &self.act_space
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = Rng::seed_from_u64(s);
        }
        self.x = self.rng.random_range(-1.0..1.0);
        self.v = 0.0;
        vec![self.x, self.v]
    }
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        let u = match action {
            Action::Continuous(a) => a[0].clamp(-1.0, 1.0),
            Action::Discrete(k) => *k as f64 - 1.0,
        };
        self.v = 0.95 * self.v + 0.1 * u;
        self.x += 0.1 * self.v;
        Ok(Step {
            observation: vec![self.x, self.v],
            reward: -self.x * self.x,
            terminated: self.x.abs() > 2.0,
            truncated: false,
        })
    }
    fn state(&self) -> Vec<f64> {
        vec![self.x, self.v]
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.x = state[0];
        self.v = state[1];
        Ok(vec![self.x, self.v])
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(30)
    }
}

fn configs() -> Vec<(AlgoConfig, bool)> {
    vec![
        (
            AlgoConfig::Sac(SacConfig {
                hidden: vec![16, 16],
                batch_size: 16,
                learning_starts: 40,
                ..SacConfig::default()
            }),
            false,
        ),
        (
            AlgoConfig::Ddpg(DdpgConfig {
                actor_hidden: vec![16],
                critic_hidden: vec![16],
                batch_size: 16,
                learning_starts: 40,
                train_freq: 2,
                gradient_steps: 3,
                ..DdpgConfig::default()
            }),
            false,
        ),
        (
            AlgoConfig::Dqn(DqnConfig {
                hidden: vec![16],
                batch_size: 16,
                learning_starts: 40,
                train_freq: 8,
                gradient_steps: 4,
                target_update_interval: 6,
                exploration_steps: 100,
                ..DqnConfig::default()
            }),
            true,
        ),
        (
            AlgoConfig::Reinforce(ReinforceConfig {
                episodes_per_update: 2,
                ..ReinforceConfig::default()
            }),
            true,
        ),
    ]
}

fn settings() -> TrainSettings {
    TrainSettings {
        eval_interval: 70,
        eval_episodes: 2,
        ..TrainSettings::default()
    }
}

fn params(t: &mut Trainer) -> Vec<f32> {
    match t.learner() {
        Learner::Sac(a) => a.actor_params().to_vec(),
        Learner::Ddpg(a) => a.actor_params().to_vec(),
        Learner::Dqn(a) => a.q_params().to_vec(),
        Learner::Reinforce(a) => a.policy_params().to_vec(),
    }
}

fn run(cfg: &AlgoConfig, discrete: bool, seed: u64, steps: u64) -> Trainer {
    let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
    let mut t = Trainer::new(cfg.clone(), settings(), &env, seed).unwrap();
    t.run(&mut env, &mut eval, steps, &mut |_| {}).unwrap();
    t
}

/// The trainer reports every environment step, warm-up included, to DQN (SB3's `_on_step`).
#[test]
fn dqn_epsilon_follows_the_trainers_env_steps_from_step_zero() {
    for (cfg, discrete) in configs() {
        if let AlgoConfig::Dqn(c) = &cfg {
            let mut t = run(&cfg, discrete, 5, 70);
            let steps = t.steps();
            match t.learner() {
                Learner::Dqn(a) => assert_eq!(a.epsilon(), c.epsilon(steps)),
                _ => unreachable!(),
            }
            assert!(c.epsilon(steps) < c.epsilon(steps - c.learning_starts as u64));
        }
    }
}

#[test]
fn same_seed_gives_bit_identical_runs_and_another_seed_does_not() {
    for (cfg, discrete) in configs() {
        let mut a = run(&cfg, discrete, 7, 210);
        let mut b = run(&cfg, discrete, 7, 210);
        let name = cfg.algo().name();
        assert!(a.updates() > 0, "{name}: no update happened");
        assert_eq!(a.log().evals.len(), 3, "{name}");
        assert_eq!(a.log(), b.log(), "{name}: logs differ");
        assert_eq!(params(&mut a), params(&mut b), "{name}: parameters differ");
        let mut c = run(&cfg, discrete, 8, 210);
        assert_ne!(params(&mut a), params(&mut c), "{name}: seed has no effect");
    }
}

#[test]
fn a_run_saved_mid_episode_and_resumed_equals_an_uninterrupted_one() {
    for (cfg, discrete) in configs() {
        let name = cfg.algo().name();
        let mut whole = run(&cfg, discrete, 3, 230);

        // 97 steps: in the middle of an episode (at most 30 steps each), between trainings.
        let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
        let mut first = Trainer::new(cfg.clone(), settings(), &env, 3).unwrap();
        first.run(&mut env, &mut eval, 97, &mut |_| {}).unwrap();
        let bytes = first.save(&env).unwrap().to_bytes().unwrap();
        drop(first);

        let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
        let mut resumed = Trainer::new(cfg.clone(), settings(), &env, 3).unwrap();
        let ckpt = tandem_nn::Checkpoint::from_bytes(&bytes).unwrap();
        resumed.load(&ckpt, &mut env).unwrap();
        assert_eq!(resumed.steps(), 97);
        resumed.run(&mut env, &mut eval, 230, &mut |_| {}).unwrap();

        assert_eq!(
            whole.log(),
            resumed.log(),
            "{name}: logs differ after resume"
        );
        assert_eq!(
            params(&mut whole),
            params(&mut resumed),
            "{name}: parameters differ"
        );
        assert_eq!(whole.updates(), resumed.updates());
    }
}

/// Pausing at every checkpoint point, stopping at an arbitrary step and resuming from the bytes
/// saved there changes nothing: the final checkpoints are the same bytes.
#[test]
fn pauses_and_a_stop_resumed_from_bytes_give_the_same_final_checkpoint() {
    for (cfg, discrete) in configs() {
        let name = cfg.algo().name();
        let settings = TrainSettings {
            checkpoint_interval: 40,
            ..settings()
        };
        let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
        let mut whole = Trainer::new(cfg.clone(), settings.clone(), &env, 3).unwrap();
        let mut pauses = Vec::new();
        loop {
            let go_on = &mut |_: &Trainer| ControlFlow::Continue(());
            match whole
                .run_until_pause(&mut env, &mut eval, 230, go_on)
                .unwrap()
            {
                Pause::Checkpoint => pauses.push(whole.steps()),
                Pause::Finished => break,
                Pause::Stopped => unreachable!("never asked to stop"),
            }
        }
        // Evaluations every 70 steps, checkpoints every 40.
        assert_eq!(pauses, [40, 70, 80, 120, 140, 160, 200, 210], "{name}");
        let whole_bytes = whole.save(&env).unwrap().to_bytes().unwrap();

        let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
        let mut first = Trainer::new(cfg.clone(), settings.clone(), &env, 3).unwrap();
        let stop_at_101 = &mut |t: &Trainer| {
            if t.steps() == 101 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        };
        while first
            .run_until_pause(&mut env, &mut eval, 230, stop_at_101)
            .unwrap()
            == Pause::Checkpoint
        {}
        assert_eq!(first.steps(), 101, "{name}");
        let bytes = first.save(&env).unwrap().to_bytes().unwrap();

        let (mut env, mut eval) = (PointMass::new(discrete), PointMass::new(discrete));
        let mut resumed = Trainer::new(cfg.clone(), settings.clone(), &env, 3).unwrap();
        let ckpt = tandem_nn::Checkpoint::from_bytes(&bytes).unwrap();
        resumed.load(&ckpt, &mut env).unwrap();
        resumed.run(&mut env, &mut eval, 230, &mut |_| {}).unwrap();
        assert!(
            resumed.save(&env).unwrap().to_bytes().unwrap() == whole_bytes,
            "{name}: final checkpoints differ"
        );
    }
}

#[test]
fn resuming_into_another_algorithm_or_architecture_is_an_error() {
    let cfgs = configs();
    let (sac, _) = &cfgs[0];
    let (ddpg, _) = &cfgs[1];
    let mut env = PointMass::new(false);
    let t = run(sac, false, 1, 50);
    let ckpt = t.save(&env).unwrap();
    let mut other = Trainer::new(ddpg.clone(), settings(), &env, 1).unwrap();
    let e = other.load(&ckpt, &mut env).unwrap_err();
    assert!(matches!(e, AgentError::Checkpoint(_)), "{e}");
    assert!(e.to_string().contains("sac"), "{e}");
    let wider = AlgoConfig::Sac(SacConfig {
        hidden: vec![32, 16],
        batch_size: 16,
        learning_starts: 40,
        ..SacConfig::default()
    });
    let mut other = Trainer::new(wider, settings(), &env, 1).unwrap();
    let e = other.load(&ckpt, &mut env).unwrap_err();
    assert!(e.to_string().contains("architecture"), "{e}");
}

#[test]
fn episodes_respect_the_length_limit_and_real_samples_are_counted() {
    let (cfg, d) = &configs()[0];
    let t = run(cfg, *d, 2, 200);
    assert_eq!(t.steps(), 200);
    let log = t.log();
    assert!(log.episodes.iter().all(|e| e.length <= 30));
    let last = log.episodes.last().unwrap();
    let total: usize = log.episodes.iter().map(|e| e.length).sum();
    assert_eq!(last.step as usize, total);
}
