//! PETS: settings are checked with errors that name them, the presets survive TOML, and a tiny
//! run on Pendulum-v1 plans better than it acted at random and resumes to the same numbers.

use tandem_algos::mbpo::pendulum_problem;
use tandem_algos::pets::{run, PetsConfig, MUJOCO_TASKS};
use tandem_algos::{AlgoError, Ephemeral, InMemory};
use tandem_models::EarlyStop;

fn presets() -> Vec<(&'static str, PetsConfig)> {
    vec![
        ("default", PetsConfig::default()),
        ("pendulum", PetsConfig::pendulum()),
        ("half_cheetah", PetsConfig::half_cheetah()),
        ("hopper", PetsConfig::hopper()),
        ("inverted_pendulum", PetsConfig::inverted_pendulum()),
        ("cartpole", PetsConfig::cartpole()),
        ("reacher", PetsConfig::reacher()),
        ("pusher", PetsConfig::pusher()),
        ("small half_cheetah", PetsConfig::half_cheetah().small()),
    ]
}

#[test]
fn presets_are_valid_and_survive_toml() {
    for (name, cfg) in presets() {
        cfg.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        let toml = toml::to_string(&cfg).unwrap();
        assert_eq!(toml::from_str::<PetsConfig>(&toml).unwrap(), cfg, "{name}");
    }
    for id in MUJOCO_TASKS {
        assert!(PetsConfig::mujoco(id).is_some(), "{id}");
    }
    assert!(PetsConfig::mujoco("Walker2d-v5").is_none());
    let small = PetsConfig::half_cheetah().small();
    assert_eq!((small.cem.particles, small.cem.population), (5, 100));
    // A typo is refused rather than ignored.
    let e = toml::from_str::<PetsConfig>("episodes = 3\nepisdoes = 4").unwrap_err();
    assert!(e.to_string().contains("episdoes"), "{e}");
}

/// A change that makes a valid configuration invalid.
type Spoil = Box<dyn Fn(&mut PetsConfig)>;

#[test]
fn bad_settings_are_errors_that_name_them() {
    let cases: Vec<(&str, Spoil)> = vec![
        ("ensemble.members", Box::new(|c| c.ensemble.members = 0)),
        ("ensemble.elites", Box::new(|c| c.ensemble.elites = 0)),
        ("must not exceed", Box::new(|c| c.ensemble.elites = 9)),
        ("cem.particles", Box::new(|c| c.cem.particles = 0)),
        ("cem.horizon", Box::new(|c| c.cem.horizon = 0)),
        ("cem.population", Box::new(|c| c.cem.population = 0)),
        ("cem.iterations", Box::new(|c| c.cem.iterations = 0)),
        ("initial_episodes", Box::new(|c| c.initial_episodes = 0)),
        ("episodes", Box::new(|c| c.episodes = 0)),
        ("model_fit.epochs", Box::new(|c| c.model_fit.epochs = 0)),
        (
            "model_fit.batch_size",
            Box::new(|c| c.model_fit.batch_size = 0),
        ),
        (
            "max_episode_steps",
            Box::new(|c| c.max_episode_steps = Some(0)),
        ),
        ("learn_reward", Box::new(|c| c.ensemble.learn_reward = true)),
        (
            "holdout_fraction",
            Box::new(|c| c.model_fit.holdout_fraction = 1.0),
        ),
        (
            "early_stop needs held-out rows",
            Box::new(|c| {
                c.model_fit.holdout_fraction = 0.0;
                c.model_fit.early_stop = Some(EarlyStop::default());
            }),
        ),
        ("alpha", Box::new(|c| c.cem.alpha = 1.5)),
    ];
    for (what, spoil) in cases {
        let mut cfg = PetsConfig::pendulum();
        spoil(&mut cfg);
        let e = cfg.validate().unwrap_err();
        assert!(matches!(e, AlgoError::Config(_)), "{what}: {e}");
        assert!(e.to_string().contains(what), "{what}: {e}");
        // The run refuses it too, before building anything.
        let e = run(&pendulum_problem(), &cfg, 0, &mut Ephemeral, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains(what), "{what}: {e}");
    }
}

/// Tiny PETS on the pendulum: 3 episodes of 60 steps from the hanging start, two random; a
/// small ensemble and a short CEM. The planned episode earns more than the random ones; a run
/// stopped after its second episode resumes to the same record.
#[test]
fn a_tiny_run_plans_better_than_random_and_resumes_to_the_same_numbers() {
    let mut cfg = PetsConfig::pendulum();
    cfg.ensemble.members = 3;
    cfg.ensemble.elites = 3;
    cfg.ensemble.hidden = vec![32, 32];
    cfg.model_fit.epochs = 30;
    cfg.cem.horizon = 10;
    cfg.cem.population = 40;
    cfg.cem.particles = 3;
    cfg.cem.iterations = 3;
    cfg.initial_episodes = 2;
    cfg.episodes = 3;
    cfg.max_episode_steps = Some(60);
    let problem = pendulum_problem();
    let whole = run(&problem, &cfg, 1, &mut Ephemeral, &mut |_| {}).unwrap();
    let returns: Vec<f64> = whole.episodes.iter().map(|e| e.episode_return).collect();
    eprintln!("returns {returns:?}");
    assert_eq!(whole.episodes.len(), 3);
    assert!(whole.episodes[..2].iter().all(|e| e.random));
    assert!(!whole.episodes[2].random);
    let fit = &whole.episodes[2].fit;
    assert_eq!(fit.transitions, 180);
    assert!(fit.train_loss.is_finite() && fit.holdout_loss.is_some_and(f64::is_finite));
    assert!(
        returns[2] > returns[0].max(returns[1]),
        "planned {} vs random {:?}",
        returns[2],
        &returns[..2]
    );

    let mut store = InMemory::default();
    let stop = store.stop_flag();
    let e = run(&problem, &cfg, 1, &mut store, &mut |ep| {
        stop.set(ep.episode == 1)
    })
    .unwrap_err();
    assert!(matches!(e, AlgoError::Stopped), "{e}");
    stop.set(false);
    let mut seen = vec![];
    let resumed = run(&problem, &cfg, 1, &mut store, &mut |ep| {
        seen.push(ep.episode)
    })
    .unwrap();
    assert_eq!(seen, [2]);
    let strip = |r: &tandem_algos::pets::PetsRecord| -> Vec<(f64, usize, f64)> {
        r.episodes
            .iter()
            .map(|e| (e.episode_return, e.fit.epochs, e.fit.train_loss))
            .collect()
    };
    assert_eq!(strip(&resumed), strip(&whole));
}
