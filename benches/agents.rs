//! One update of the off-policy agents at the sizes we compare against stable-baselines3
//! 2.9 + PyTorch on a 2-core machine (SAC 11.9–12.3 ms, DDPG 11.5 ms per update):
//! Pendulum-v1's dimensions (3 observations, 1 action), minibatch 256, SAC with two hidden layers
//! of 256 (SB3 defaults), DDPG with 400 and 300 (SB3 zoo / p0). Each iteration samples the
//! minibatch from a filled replay buffer and makes one gradient step, as SB3's `train` does.
//!
//! Run: `cargo bench --bench agents`.

use criterion::{criterion_group, criterion_main, Criterion};
use rand::Rng as _;
use tandem_agents::{
    Agent, Batch, BatchPolicy, Ddpg, DdpgConfig, Dqn, DqnConfig, Mode, OffPolicyAgent,
    ReplayBuffer, Sac, SacConfig, TransitionRef,
};
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::Space;

fn filled_buffer(n: usize, od: usize, discrete: Option<usize>, rng: &mut Rng) -> ReplayBuffer {
    let mut b = ReplayBuffer::new(n, od, 1).unwrap();
    for _ in 0..n {
        let obs: Vec<f64> = (0..od).map(|_| rng.random_range(-1.0..1.0)).collect();
        let next: Vec<f64> = (0..od).map(|_| rng.random_range(-1.0..1.0)).collect();
        let a = match discrete {
            Some(k) => rng.random_range(0..k) as f64,
            None => rng.random_range(-2.0..2.0),
        };
        b.push(TransitionRef {
            obs: &obs,
            action: &[a],
            reward: rng.random_range(-16.0..0.0),
            next_obs: &next,
            terminated: false,
        })
        .unwrap();
    }
    b
}

fn bench(c: &mut Criterion) {
    tandem_nn::set_gemm_threads(1);
    let mut rng = rng_from_seed(0);
    let obs = Space::boxed(vec![-1.0, -1.0, -8.0], vec![1.0, 1.0, 8.0]);
    let act = Space::symmetric(1, 2.0);
    let buf = filled_buffer(20_000, 3, None, &mut rng);
    let mut batch = Batch::zeros(256, 3, 1);

    let mut sac = Sac::new(SacConfig::default(), &obs, &act, 0).unwrap();
    c.bench_function("sac_update_pendulum_b256_h256x256", |b| {
        b.iter(|| {
            buf.sample_into(&mut rng, &mut batch, 0..256).unwrap();
            sac.update(&batch).unwrap()
        })
    });
    // One row through `Agent::act` (the environment loop's call).
    c.bench_function("sac_act_explore_1row_h256x256", |b| {
        b.iter(|| sac.act(&[0.1, -0.2, 0.5], Mode::Explore).unwrap())
    });
    // A planner's population through the `&self` batch path: 256 rows at once.
    let rows = buf.sample(256, &mut rng).unwrap().obs.mapv(f64::from);
    let mut act_rng = rng_from_seed(1);
    c.bench_function("sac_act_batch_explore_b256_h256x256", |b| {
        b.iter(|| {
            sac.act_batch(rows.view(), Mode::Explore, &mut act_rng)
                .unwrap()
        })
    });

    let cfg = DdpgConfig {
        batch_size: 256,
        ..DdpgConfig::default()
    };
    let mut ddpg = Ddpg::new(cfg, &obs, &act, 0).unwrap();
    c.bench_function("ddpg_update_pendulum_b256_h400x300", |b| {
        b.iter(|| {
            buf.sample_into(&mut rng, &mut batch, 0..256).unwrap();
            ddpg.update(&batch).unwrap()
        })
    });

    let cart = Space::symmetric(4, f64::INFINITY);
    let dbuf = filled_buffer(20_000, 4, Some(2), &mut rng);
    let mut dqn = Dqn::new(DqnConfig::default(), &cart, &Space::discrete(2), 0).unwrap();
    let mut dbatch = Batch::zeros(64, 4, 1);
    c.bench_function("dqn_update_cartpole_b64_h256x256", |b| {
        b.iter(|| {
            dbuf.sample_into(&mut rng, &mut dbatch, 0..64).unwrap();
            dqn.update(&dbatch).unwrap()
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
