//! Determinism and save/resume of whole runs, on a small environment defined here (so the test
//! does not depend on any particular task implementation).

use rand::{Rng as _, SeedableRng};
use tandem_core::{Action, Rng, Space};
use tandem_envs::{Env, EnvError, Step};

use std::cell::Cell;

use tandem_agents::{AlgoConfig, DdpgConfig, DqnConfig, Learner, ReinforceConfig, SacConfig};
use tandem_nn::Checkpoint;

use super::{train, Event, TrainSettings, Trained};
use crate::{AlgoError, Checkpoints, Ephemeral, InMemory};

type Result<T, E = AlgoError> = std::result::Result<T, E>;

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

fn params(t: &mut Trained) -> Vec<f32> {
    match &mut t.learner {
        Learner::Sac(a) => a.actor_params().to_vec(),
        Learner::Ddpg(a) => a.actor_params().to_vec(),
        Learner::Dqn(a) => a.q_params().to_vec(),
        Learner::Reinforce(a) => a.policy_params().to_vec(),
    }
}

fn train_on(
    cfg: &AlgoConfig,
    settings: &TrainSettings,
    discrete: bool,
    (seed, steps): (u64, u64),
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained> {
    let env = |_| -> Box<dyn Env> { Box::new(PointMass::new(discrete)) };
    let (env, eval) = (env(()), env(()));
    train(
        cfg.clone(),
        settings.clone(),
        env,
        eval,
        steps,
        seed,
        store,
        on_event,
    )
}

fn run(cfg: &AlgoConfig, discrete: bool, seed: u64, steps: u64) -> Trained {
    let (seed_steps, s) = ((seed, steps), settings());
    train_on(cfg, &s, discrete, seed_steps, &mut Ephemeral, &mut |_| {}).unwrap()
}

/// The loop reports every environment step, warm-up included, to DQN (SB3's `_on_step`).
#[test]
fn dqn_epsilon_follows_the_loops_env_steps_from_step_zero() {
    for (cfg, discrete) in configs() {
        if let AlgoConfig::Dqn(c) = &cfg {
            let t = run(&cfg, discrete, 5, 70);
            let steps = t.steps;
            match &t.learner {
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
        assert!(a.updates > 0, "{name}: no update happened");
        // Every 70 steps; the last one is also the final evaluation.
        assert_eq!(a.log.evals.len(), 3, "{name}");
        assert_eq!(a.log, b.log, "{name}: logs differ");
        assert_eq!(params(&mut a), params(&mut b), "{name}: parameters differ");
        let mut c = run(&cfg, discrete, 8, 210);
        assert_ne!(params(&mut a), params(&mut c), "{name}: seed has no effect");
    }
}

/// A store that notes the step at which each checkpoint was saved.
struct Noting<'a> {
    store: InMemory,
    step: &'a Cell<u64>,
    saved_at: Vec<u64>,
}

impl Checkpoints for Noting<'_> {
    fn load(&mut self, key: &str) -> Result<Option<Checkpoint>> {
        self.store.load(key)
    }
    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> Result<()> {
        self.saved_at.push(self.step.get());
        self.store.save(key, ckpt)
    }
    fn stop_requested(&self) -> bool {
        self.store.stop_requested()
    }
}

/// Checkpoints at every evaluation, every `checkpoint_interval` steps and at the end; a stop
/// requested at any step (here mid-episode, between trainings) saves that step, and the run
/// resumed from it ends with the same log, parameters and final checkpoint bytes.
#[test]
fn a_run_stopped_at_any_step_saves_it_and_resumes_to_the_uninterrupted_run() {
    for (cfg, discrete) in configs() {
        let name = cfg.algo().name();
        let settings = TrainSettings {
            checkpoint_interval: 40,
            ..settings()
        };
        let step = Cell::new(0);
        let on_step = &mut |e: Event| {
            if let Event::Step(n) = e {
                step.set(n);
            }
        };
        let mut whole = Noting {
            store: InMemory::default(),
            step: &step,
            saved_at: Vec::new(),
        };
        let mut w = train_on(&cfg, &settings, discrete, (3, 230), &mut whole, on_step).unwrap();
        // Evaluations every 70 steps, checkpoints every 40, and the end.
        assert_eq!(
            whole.saved_at,
            [40, 70, 80, 120, 140, 160, 200, 210, 230],
            "{name}"
        );
        assert_eq!(w.log.evals.last().map(|e| e.step), Some(230), "{name}");

        // 101 steps: in the middle of an episode (at most 30 steps each).
        let mut cut = Noting {
            store: InMemory::default(),
            step: &step,
            saved_at: Vec::new(),
        };
        let stop = cut.store.stop_flag();
        let stop_at_101 = &mut |e: Event| {
            on_step(e.clone());
            stop.set(e == Event::Step(101));
        };
        let e = train_on(&cfg, &settings, discrete, (3, 230), &mut cut, stop_at_101);
        assert!(matches!(e, Err(AlgoError::Stopped)), "{name}");
        assert_eq!(cut.saved_at, [40, 70, 80, 101], "{name}");
        stop.set(false);
        let mut store = cut.store;
        // A stop requested before the first step saves step 0, which resumes like any other.
        let mut early = InMemory::default();
        early.stop_flag().set(true);
        let e = train_on(&cfg, &settings, discrete, (3, 230), &mut early, &mut |_| {});
        assert!(matches!(e, Err(AlgoError::Stopped)), "{name}");
        early.stop_flag().set(false);
        let mut r0 = train_on(&cfg, &settings, discrete, (3, 230), &mut early, &mut |_| {});
        assert_eq!(
            r0.as_mut().unwrap().log,
            w.log,
            "{name}: resumed from step 0"
        );
        assert!(early.files[name] == whole.store.files[name], "{name}");
        let mut r = train_on(&cfg, &settings, discrete, (3, 230), &mut store, &mut |_| {});
        let r = r.as_mut().unwrap();
        assert_eq!(w.log, r.log, "{name}: logs differ after resume");
        assert_eq!(params(&mut w), params(r), "{name}: parameters differ");
        assert_eq!((w.steps, w.updates), (r.steps, r.updates), "{name}");
        assert!(
            whole.store.files[name] == store.files[name],
            "{name}: final checkpoints differ"
        );
    }
}

#[test]
fn resuming_into_another_algorithm_or_architecture_is_an_error() {
    let cfgs = configs();
    let (sac, _) = &cfgs[0];
    let (ddpg, _) = &cfgs[1];
    let mut store = InMemory::default();
    let s = settings();
    train_on(sac, &s, false, (1, 50), &mut store, &mut |_| {}).unwrap();
    let bytes = store.files["sac"].clone();
    store.files.insert("ddpg".into(), bytes);
    let e = train_on(ddpg, &s, false, (1, 50), &mut store, &mut |_| {}).unwrap_err();
    assert!(matches!(e, AlgoError::Checkpoint(_)), "{e}");
    assert!(e.to_string().contains("sac"), "{e}");
    let wider = AlgoConfig::Sac(SacConfig {
        hidden: vec![32, 16],
        batch_size: 16,
        learning_starts: 40,
        ..SacConfig::default()
    });
    let e = train_on(&wider, &s, false, (1, 50), &mut store, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("architecture"), "{e}");
}

#[test]
fn episodes_respect_the_length_limit_and_real_samples_are_counted() {
    let (cfg, d) = &configs()[0];
    let t = run(cfg, *d, 2, 200);
    assert_eq!(t.steps, 200);
    assert!(t.log.episodes.iter().all(|e| e.length <= 30));
    let last = t.log.episodes.last().unwrap();
    let total: usize = t.log.episodes.iter().map(|e| e.length).sum();
    assert_eq!(last.step as usize, total);
}
