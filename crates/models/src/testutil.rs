//! Data generators and error measures shared by the models' tests.

use nalgebra::DVector;
use rand::Rng as _;
use tandem_core::seeding::rng_from_seed;
use tandem_dynamics::classic::{CartPole, GymPendulum, GymPendulumParams};
use tandem_dynamics::Plant;

use crate::{DynamicsModel, EarlyStop, FitConfig, ModelInput, Transitions, TransitionsBuilder};

/// Gymnasium's pendulum (1 kg), the idealized plant of the tests' idealized/true pair.
pub(crate) fn idealized_pendulum() -> GymPendulum {
    GymPendulum::default()
}

/// The true plant of that pair: a 60 % heavier bob.
pub(crate) fn true_pendulum() -> GymPendulum {
    GymPendulum::new(GymPendulumParams {
        m: 1.6,
        ..GymPendulumParams::default()
    })
}

/// `n` transitions of a pendulum from uniform states (φ in [-π, π], φ̇ in [-6, 6] rad/s: one step
/// stays inside the gymnasium pendulum's ±8 rad/s clip) and inputs in [-2, 2] (its torque bound);
/// reward `-(φ² + 0.1 φ̇²)`.
pub(crate) fn pendulum_data<P: Plant>(plant: &P, n: usize, seed: u64) -> Transitions {
    let mut rng = rng_from_seed(seed);
    let mut b = TransitionsBuilder::new(2, 1);
    for _ in 0..n {
        let s = [
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
            rng.random_range(-6.0..6.0),
        ];
        let a = [rng.random_range(-2.0..2.0)];
        let next = plant.step(&DVector::from_row_slice(&s), &DVector::from_row_slice(&a));
        b.push(
            s,
            &a,
            next.as_slice(),
            -(s[0] * s[0] + 0.1 * s[1] * s[1]),
            false,
        )
        .unwrap();
        b.end_episode();
    }
    b.build()
}

/// `n` CartPole-v1 transitions from uniform states within the episode bounds and forces ±10 N;
/// reward 1, terminated when the next state leaves `|x| <= 2.4`, `|θ| <= 12°` (gymnasium).
pub(crate) fn cartpole_data(n: usize, seed: u64) -> Transitions {
    let plant = CartPole::default();
    let mut rng = rng_from_seed(seed);
    let mut b = TransitionsBuilder::new(4, 1);
    let limit = 12.0 * 2.0 * std::f64::consts::PI / 360.0;
    for _ in 0..n {
        let s = [
            rng.random_range(-2.4..2.4),
            rng.random_range(-2.0..2.0),
            rng.random_range(-limit..limit),
            rng.random_range(-2.0..2.0),
        ];
        let a = [if rng.random::<bool>() { 10.0 } else { -10.0 }];
        let next = plant.step_array(&s, a[0]);
        let done = next[0].abs() > 2.4 || next[2].abs() > limit;
        b.push(s, &a, &next, 1.0, done).unwrap();
        b.end_episode();
    }
    b.build()
}

/// Root mean squared one-step error of `model` on `data`.
pub(crate) fn rmse(model: &dyn DynamicsModel, data: &Transitions) -> f64 {
    let input = ModelInput::new(data.states.view(), data.actions.view());
    let p = model.predict(&input, &mut rng_from_seed(0)).unwrap();
    let e = &p.next_states - &data.next_states;
    (e.mapv(|v| v * v).sum() / e.len() as f64).sqrt()
}

/// Root mean squared error of predicting `s' = s`.
pub(crate) fn zero_change_rmse(data: &Transitions) -> f64 {
    let e = &data.states - &data.next_states;
    (e.mapv(|v| v * v).sum() / e.len() as f64).sqrt()
}

/// `f` on a rayon pool of `threads` threads.
pub(crate) fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A fit of up to `epochs` epochs on minibatches of 32 with 30 % held out, stopping early after
/// `patience` epochs without a 5 % improvement; and the plain fit of its first `kept` epochs.
pub(crate) fn early_stopping(
    patience: usize,
    epochs: usize,
) -> (FitConfig, impl Fn(usize) -> FitConfig) {
    let stopping = FitConfig {
        epochs,
        batch_size: 32,
        holdout_fraction: 0.3,
        early_stop: Some(EarlyStop {
            patience,
            improvement_threshold: 0.05,
        }),
        ..FitConfig::default()
    };
    let plain = {
        let stopping = stopping.clone();
        move |kept| FitConfig {
            epochs: kept,
            early_stop: None,
            ..stopping.clone()
        }
    };
    (stopping, plain)
}
