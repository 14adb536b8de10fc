//! p2's loop on the pixel maze (DQN through the shared off-policy loop, the pixel model): the
//! schedule of real and imagined episodes, exact real-sample counts, a stopped run resumed from
//! its checkpoint, and the F1 experiment's held-out scoring.

use tandem::algos::imagined_episodes::{AlgoError, Ephemeral, Event, Method, RunRecord};
use tandem::algos::imagined_pixels::{model_quality, run, MazeConfig, QualityConfig};
use tandem::algos::InMemory;

/// A small configuration that never counts as solved: 8 real episodes, the first 3 real only,
/// then 2 imagined after each real one; a tiny model; learning from the 100th transition.
fn small() -> MazeConfig {
    let mut c = MazeConfig::default();
    c.model.channels = [4, 4, 4];
    c.model.features = 16;
    c.model.factors = 16;
    c.fit.steps = 2;
    c.fit.batch_size = 8;
    c.dqn.learning_starts = 100;
    c.dqn.buffer_size = 2000;
    c.dqn.conv.channels = vec![4, 4, 4];
    c.dqn.hidden = vec![16];
    c.real_only_episodes = 3;
    c.imagined_per_cycle = 2;
    c.max_real_episodes = 8;
    c.solved_return = 1e9;
    c.checkpoint_every = 2;
    c
}

fn schedule(events: &[Event]) -> String {
    events
        .iter()
        .map(|e| match e {
            Event::Real { .. } => 'R',
            Event::Imagined { .. } => 'I',
        })
        .collect()
}

fn whole(method: Method, cfg: &MazeConfig, seed: u64) -> (Vec<Event>, RunRecord) {
    let mut events = Vec::new();
    let r = run(method, cfg, seed, &mut Ephemeral, &mut |e| events.push(e)).unwrap();
    (events, r)
}

#[test]
fn real_episodes_first_then_imagined_ones_and_real_samples_counted_exactly() {
    let cfg = small();
    let (events, r) = whole(Method::WithModel, &cfg, 0);
    assert_eq!(schedule(&events), "RRR".to_string() + &"RII".repeat(5));
    assert_eq!((r.real_returns.len(), r.imagined_episodes), (8, 10));
    // The real samples are the real episodes' steps (events report the count after each), and
    // imagined steps add none.
    let mut last = 0;
    for e in &events {
        if let Event::Real { real_samples, .. } = e {
            assert!(*real_samples > last);
            last = *real_samples;
        }
    }
    assert_eq!(r.real_samples, last);
    let imagined: u64 = events
        .iter()
        .filter_map(|e| match e {
            Event::Imagined { steps, .. } => Some(*steps),
            _ => None,
        })
        .sum();
    assert_eq!(r.imagined_steps, imagined);
    assert!((10..=10 * 50).contains(&imagined));
    assert_eq!(r.fit_losses.len(), 8);
    assert!(r.fit_losses.iter().all(|l| l.is_finite() && *l > 0.0));
    // The baseline meets the same first start and acts the same until learning starts.
    let (events, mf) = whole(Method::ModelFree, &cfg, 0);
    assert_eq!(schedule(&events), "R".repeat(8));
    assert_eq!((mf.imagined_episodes, mf.fit_losses.len()), (0, 0));
    assert_eq!(mf.real_returns[0], r.real_returns[0]);
}

#[test]
fn a_stopped_run_resumes_to_the_same_numbers() {
    let cfg = small();
    for method in Method::ALL {
        let (_, all) = whole(method, &cfg, 2);
        let mut store = InMemory::default();
        let stop = store.stop_flag();
        // Stops after 5 real episodes; the last checkpoint is from episode 4.
        let mut count = |e: Event| {
            if let Event::Real { episode: 4, .. } = e {
                stop.set(true);
            }
        };
        let e = run(method, &cfg, 2, &mut store, &mut count).unwrap_err();
        assert!(matches!(e, AlgoError::Stopped), "{e}");
        assert_eq!(store.saves(), 2);
        store.stop_flag().set(false);
        let resumed = run(method, &cfg, 2, &mut store, &mut |_| {}).unwrap();
        assert_eq!(resumed.real_returns, all.real_returns, "{method:?}");
        assert_eq!(resumed.real_samples, all.real_samples);
        assert_eq!(resumed.imagined_steps, all.imagined_steps);
        assert_eq!(resumed.fit_losses, all.fit_losses);
        let e = run(method, &cfg, 3, &mut store, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("seed 2"), "{e}");
    }
}

#[test]
fn the_f1_experiment_scores_copies_on_later_episodes_past_solved() {
    let mut cfg = small();
    cfg.solved_return = -100.0; // solved at once: the experiment goes on regardless
    cfg.max_real_episodes = 1;
    let q = QualityConfig {
        checkpoints: vec![2, 4],
        heldout_episodes: 2,
        seeds: vec![1],
    };
    let out = model_quality(&cfg, &q, 1, &Ephemeral, &mut |_| {}).unwrap();
    assert_eq!(out.real_returns.len(), 6); // the last checkpoint and its 2 held-out episodes
    let eps: Vec<u64> = out.points.iter().map(|p| p.episodes).collect();
    assert_eq!(eps, [2, 4]);
    for p in &out.points {
        assert!(p.heldout_transitions >= 2 && p.transitions >= 2);
        for f in [p.agent, p.obstacles, p.goal] {
            assert!((0.0..=1.0).contains(&f), "{f}");
        }
        assert_eq!(p.shown_truth.len(), 768);
        assert_eq!(p.predicted.len(), 768);
        // The true frame is binary; the prediction a probability.
        assert!(p.shown_truth.iter().all(|v| *v == 0.0 || *v == 1.0));
        assert!(p.predicted.iter().all(|v| (0.0..=1.0).contains(v)));
    }
    // The model after 4 episodes trained on more transitions than after 2.
    assert!(out.points[1].transitions > out.points[0].transitions);
    for (checkpoints, heldout_episodes) in [(vec![0], 2), (vec![], 2), (vec![3], 0)] {
        let bad = QualityConfig {
            checkpoints,
            heldout_episodes,
            seeds: vec![1],
        };
        assert!(model_quality(&cfg, &bad, 1, &Ephemeral, &mut |_| {}).is_err());
    }
}

#[test]
fn out_of_range_settings_are_errors() {
    let mut c = small();
    c.fit.steps = 0;
    assert!(run(Method::WithModel, &c, 0, &mut Ephemeral, &mut |_| {}).is_err());
    let mut c = small();
    c.model.image = [8, 8, 3];
    let e = run(Method::ModelFree, &c, 0, &mut Ephemeral, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("16, 16, 3"), "{e}");
    let mut c = small();
    c.solved_return = f64::NAN;
    assert!(run(Method::ModelFree, &c, 0, &mut Ephemeral, &mut |_| {}).is_err());
    let mut c = small();
    c.env = "CartPole-v1".into();
    let e = run(Method::ModelFree, &c, 0, &mut Ephemeral, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("not a pixel maze"), "{e}");
}

#[test]
fn the_authors_layout_runs_its_100_step_episodes_without_ending_at_collisions() {
    let cfg = MazeConfig {
        env: "PixelMaze-v1".into(),
        ..small()
    };
    let v1 = MazeConfig::for_env("PixelMaze-v1").unwrap();
    assert_eq!((v1.env.as_str(), v1.solved_return), ("PixelMaze-v1", 35.0));
    assert_eq!(
        (v1.dqn.learning_rate, v1.dqn.learning_rate_final),
        (1e-4, Some(1e-4))
    );
    assert_eq!(v1.model, MazeConfig::default().model);
    let e = MazeConfig::for_env("PixelMaze-v2").unwrap_err();
    assert!(e.to_string().contains("not a pixel maze"), "{e}");
    let (events, r) = whole(Method::WithModel, &cfg, 1);
    assert_eq!(schedule(&events), "RRR".to_string() + &"RII".repeat(5));
    // Collisions do not end an episode and reaching the goal does not either: every real
    // episode runs to the 100-step limit, and every return is a sum of -5, 0 and +1 steps.
    assert_eq!(r.real_samples, 8 * 100);
    assert!(r
        .real_returns
        .iter()
        .all(|g| g.fract() == 0.0 && *g <= 70.0));
    // The default maze's episodes are at most 50 steps.
    let (_, v0) = whole(Method::ModelFree, &small(), 1);
    assert!(v0.real_samples <= 8 * 50);
}

/// The conv Q-network on p2's pixel maze: a run saved mid-episode and resumed equals an
/// uninterrupted one (networks, Adam state, generators and replay of images all restored).
#[test]
fn conv_dqn_on_the_pixel_maze_resumes_bit_for_bit() {
    use tandem::agents::{AlgoConfig, ConvQNetConfig, DqnConfig, Learner, QNetwork};
    use tandem::algos::model_free::{train, Event, TrainSettings, Trained};
    use tandem::algos::{AlgoError, Checkpoints, Ephemeral, InMemory};
    use tandem::robots::PixelMazeEnv;
    fn params(t: &mut Trained) -> Vec<f32> {
        match &mut t.learner {
            Learner::Dqn(a) => a.q_params().to_vec(),
            _ => unreachable!("a DQN run"),
        }
    }
    let cfg = AlgoConfig::Dqn(DqnConfig {
        network: QNetwork::Conv,
        conv: ConvQNetConfig {
            channels: vec![4],
            kernels: vec![3],
            strides: vec![4],
            ..ConvQNetConfig::default()
        },
        hidden: vec![8],
        batch_size: 8,
        learning_starts: 40,
        train_freq: 8,
        gradient_steps: 2,
        target_update_interval: 6,
        exploration_steps: 100,
        ..DqnConfig::default()
    });
    let settings = TrainSettings {
        eval_interval: 70,
        eval_episodes: 1,
        max_episode_steps: Some(30),
        ..TrainSettings::default()
    };
    let run = |store: &mut dyn Checkpoints, on_event: &mut dyn FnMut(Event)| {
        let (env, eval) = (Box::new(PixelMazeEnv::new()), Box::new(PixelMazeEnv::new()));
        let (cfg, settings) = (cfg.clone(), settings.clone());
        train(cfg, settings, env, eval, 150, 4, store, on_event)
    };
    let mut whole = run(&mut Ephemeral, &mut |_| {}).unwrap();
    assert!(whole.updates > 0);

    // Stopped after 97 steps, mid-episode: the stop saves that step.
    let mut store = InMemory::default();
    let stop = store.stop_flag();
    let e = run(&mut store, &mut |e| stop.set(e == Event::Step(97))).unwrap_err();
    assert!(matches!(e, AlgoError::Stopped), "{e}");
    stop.set(false);
    let mut resumed = run(&mut store, &mut |e| assert_ne!(e, Event::Step(97))).unwrap();
    assert_eq!(whole.log, resumed.log);
    assert_eq!(params(&mut whole), params(&mut resumed));
    assert_eq!(whole.updates, resumed.updates);
}
