//! p2's loop (Fig. 3): the schedule of real and imagined episodes, exact real-sample counts,
//! determinism, and a stopped run resumed from its checkpoint.

use tandem::algos::imagined_episodes::{
    cartpole, solved_at, AlgoError, Ephemeral, Event, Method, P2Config, RunRecord,
};
use tandem::algos::InMemory;

/// A small, fast configuration that never counts as solved: 12 real episodes, the first 4 real
/// only, then 3 imagined after every 2 real.
fn small() -> P2Config {
    let mut c = P2Config::default();
    c.model.hidden = vec![16, 16];
    c.real_only_episodes = 4;
    c.real_per_cycle = 2;
    c.imagined_per_cycle = 3;
    c.max_real_episodes = 12;
    c.solved_return = 1e9;
    c.fit_rows = 128;
    c.checkpoint_every = 3;
    c
}

/// 'R' for a real episode, 'I' for an imagined one, and the events.
fn run(method: Method, cfg: &P2Config, seed: u64) -> (String, Vec<Event>, RunRecord) {
    let mut events = Vec::new();
    let r = cartpole(method, cfg, seed, &mut Ephemeral, &mut |e| events.push(e)).unwrap();
    let s = events
        .iter()
        .map(|e| match e {
            Event::Real { .. } => 'R',
            Event::Imagined { .. } => 'I',
        })
        .collect();
    (s, events, r)
}

#[test]
fn n_real_episodes_first_then_the_ratio_and_real_samples_counted_exactly() {
    let cfg = small();
    let (schedule, events, r) = run(Method::WithModel, &cfg, 0);
    // Written out by hand: 4 real, then (2 real, 3 imagined) four times.
    assert_eq!(schedule, "RRRR".to_string() + &"RRIII".repeat(4));
    assert_eq!(r.real_returns.len(), 12);
    assert_eq!(r.imagined_episodes, 12);
    let imagined_steps: u64 = events
        .iter()
        .filter_map(|e| match e {
            Event::Imagined { steps, .. } => Some(*steps),
            _ => None,
        })
        .sum();
    assert_eq!(r.imagined_steps, imagined_steps);
    // CartPole pays 1 per real step: the real samples are the sum of the real returns, and
    // imagined steps add none.
    let steps: f64 = r.real_returns.iter().sum();
    assert_eq!(r.real_samples, steps as u64);
    let last_real = events.iter().rev().find_map(|e| match e {
        Event::Real { real_samples, .. } => Some(*real_samples),
        _ => None,
    });
    assert_eq!(last_real, Some(r.real_samples));
    // One refit per real episode (fit_every = 1).
    assert_eq!(r.fit_losses.len(), 12);
    assert!(r.fit_losses.iter().all(|l| l.is_finite()));

    // The baseline: real episodes only, no model. The same seed meets the same first start
    // state and the same initial policy, so its first episode is the with-model run's.
    let (schedule, _, mf) = run(Method::ModelFree, &cfg, 0);
    assert_eq!(schedule, "R".repeat(12));
    assert_eq!((mf.imagined_episodes, mf.fit_losses.len()), (0, 0));
    assert_eq!(mf.real_returns[0], r.real_returns[0]);
    assert_eq!(mf.real_samples, mf.real_returns.iter().sum::<f64>() as u64);
}

#[test]
fn the_same_seed_gives_the_same_run_and_another_seed_another() {
    let cfg = small();
    let strip = |mut r: RunRecord| {
        r.wall_seconds = 0.0;
        r
    };
    let a = strip(run(Method::WithModel, &cfg, 3).2);
    let b = strip(run(Method::WithModel, &cfg, 3).2);
    assert_eq!(a, b);
    let c = strip(run(Method::WithModel, &cfg, 4).2);
    assert_ne!(a.real_returns, c.real_returns);
}

#[test]
fn a_run_stopped_between_episodes_resumes_to_the_same_numbers() {
    let cfg = small();
    for method in Method::ALL {
        let whole = run(method, &cfg, 5).2;
        let mut store = InMemory::default();
        let stop = store.stop_flag();
        // Stops after 8 real episodes; the last checkpoint is from episode 6.
        let mut count = |e: Event| {
            if let Event::Real { episode: 7, .. } = e {
                stop.set(true);
            }
        };
        let e = cartpole(method, &cfg, 5, &mut store, &mut count).unwrap_err();
        assert!(matches!(e, AlgoError::Stopped), "{e}");
        store.stop_flag().set(false);
        let resumed = cartpole(method, &cfg, 5, &mut store, &mut |_| {}).unwrap();
        assert_eq!(resumed.real_returns, whole.real_returns, "{method:?}");
        assert_eq!(resumed.real_samples, whole.real_samples);
        assert_eq!(resumed.imagined_steps, whole.imagined_steps);
        assert_eq!(resumed.fit_losses, whole.fit_losses);
        // Another seed's checkpoint is refused.
        let e = cartpole(method, &cfg, 6, &mut store, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("seed 5"), "{e}");
    }
}

#[test]
fn solved_is_the_first_full_window_whose_mean_reaches_the_target() {
    // Windows of 3: means 2, 3, 4, 5 after episodes 3, 4, 5, 6.
    let r = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    assert_eq!(solved_at(&r, 3, 4.0), Some(5));
    assert_eq!(solved_at(&r, 3, 2.0), Some(3));
    assert_eq!(solved_at(&r, 3, 5.5), None);
    assert_eq!(solved_at(&r[..2], 3, 0.0), None);
    assert_eq!(solved_at(&r, 0, 0.0), None);
}

#[test]
fn out_of_range_settings_are_errors_naming_them() {
    for (c, word) in [
        (
            P2Config {
                real_per_cycle: 0,
                ..small()
            },
            "real_per_cycle",
        ),
        (
            P2Config {
                solved_return: f64::NAN,
                ..small()
            },
            "solved_return",
        ),
    ] {
        let e = cartpole(Method::WithModel, &c, 0, &mut Ephemeral, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains(word), "{e}");
    }
}
