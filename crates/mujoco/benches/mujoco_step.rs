//! One `HalfCheetah-v5` environment step (`ctrl`, 5 × `mj_step`, `mj_rnePostConstraint`, reward
//! and observation), the figure to put beside gymnasium's `env.step`
//! (`scripts/bench-gymnasium-step.py`), and one plant step (reset, state, 5 × `mj_step`).
//!
//! `cargo bench -p tandem-mujoco --features mujoco --bench mujoco_step`

use criterion::{criterion_group, criterion_main, Criterion};
use rand::Rng as _;
use tandem_core::seeding::rng_from_seed;
use tandem_dynamics::Plant;
use tandem_envs::{Action, Env};
use tandem_mujoco::{assets_dir, MujocoEnv, TaskKind};

fn half_cheetah_step(c: &mut Criterion) {
    let mut env = MujocoEnv::task(TaskKind::HalfCheetah, &assets_dir()).unwrap();
    let mut rng = rng_from_seed(0);
    let actions: Vec<Action> = (0..1000)
        .map(|_| Action::Continuous((0..6).map(|_| rng.random_range(-1.0..1.0)).collect()))
        .collect();
    env.reset(Some(0));
    let mut t = 0;
    c.bench_function("HalfCheetah-v5 env step", |b| {
        b.iter(|| {
            if t == actions.len() {
                env.reset(None);
                t = 0;
            }
            let s = env.step(&actions[t]).unwrap();
            t += 1;
            s.reward
        })
    });
    let plant = env.plant();
    let x: Vec<f64> = env.state();
    let mut next = vec![0.0; x.len()];
    let u = [0.5, -0.5, 0.2, 0.1, -0.3, 0.9];
    c.bench_function("HalfCheetah-v5 plant step", |b| {
        b.iter(|| {
            plant.step_into(&x, &u, &mut next);
            next[0]
        })
    });
}

criterion_group!(benches, half_cheetah_step);
criterion_main!(benches);
