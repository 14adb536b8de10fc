//! Hot paths of `tandem-models`: batched prediction for a planner's population (500 states), one
//! TVLG fit with its GMM prior, and one training minibatch (32) of p2's pixel model.
//!
//! Run: `cargo bench --bench models` (medians are what reports quote).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use ndarray::{Array2, Array3};
use rand::Rng as _;
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::Action;
use tandem_envs::Env;
use tandem_models::{
    DynamicsModel, EnsembleConfig, ModelInput, PixelEpisodes, PixelFit, PixelModel,
    PixelModelConfig, ProbabilisticEnsemble, Propagation, ResidualModel, ResidualModelConfig,
    TvlgConfig, TvlgFit,
};
use tandem_robots::{DcMotorPendulum, DcMotorPendulumParams, PixelMazeEnv};

fn uniform(rows: usize, cols: usize, rng: &mut Rng) -> Array2<f64> {
    Array2::from_shape_fn((rows, cols), |_| rng.random::<f64>() * 2.0 - 1.0)
}

fn predictions(c: &mut Criterion) {
    let mut rng = rng_from_seed(0);
    // MBPO-sized ensemble on a HalfCheetah-sized problem: 17 states, 6 actions.
    let mut ens = ProbabilisticEnsemble::new(17, 6, EnsembleConfig::default()).unwrap();
    let (s, a) = (uniform(500, 17, &mut rng), uniform(500, 6, &mut rng));
    for (name, mode) in [
        (
            "ensemble 7x(23-200x4-36) predict 500, random member",
            Propagation::RandomMember,
        ),
        (
            "ensemble 7x(23-200x4-36) predict 500, expectation",
            Propagation::Expectation,
        ),
    ] {
        ens.set_propagation(mode);
        c.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    ens.predict(&ModelInput::new(s.view(), a.view()), &mut rng)
                        .unwrap(),
                )
            })
        });
    }

    // p0's difference model over the DC-motor pendulum (plant step + 3x400 network).
    let res = ResidualModel::new(
        DcMotorPendulum::new(DcMotorPendulumParams::idealized()),
        ResidualModelConfig::default(),
    )
    .unwrap();
    let (s, a) = (uniform(500, 2, &mut rng), uniform(500, 1, &mut rng));
    c.bench_function("residual p0 (plant + 3-400-400-400-2) predict 500", |b| {
        b.iter(|| {
            black_box(
                res.predict(&ModelInput::new(s.view(), a.view()), &mut rng)
                    .unwrap(),
            )
        })
    });
}

fn tvlg(c: &mut Criterion) {
    // 20 samples of 100 steps of a 7-state, 2-action system.
    let mut rng = rng_from_seed(1);
    let (n, t, dx, du) = (20, 100, 7, 2);
    let mut xs = Array3::zeros((n, t + 1, dx));
    let us = Array3::from_shape_fn((n, t, du), |_| rng.random::<f64>() - 0.5);
    for i in 0..n {
        for k in 0..t {
            for j in 0..dx {
                xs[[i, k + 1, j]] = 0.95 * xs[[i, k, j]]
                    + 0.1 * us[[i, k, j % du]]
                    + 0.01 * (rng.random::<f64>() - 0.5);
            }
        }
    }
    let mut group = c.benchmark_group("tvlg");
    group.sample_size(10);
    group.bench_function("fit N=20 T=100 dX=7 dU=2 with GMM prior", |b| {
        b.iter(|| {
            let mut fit = TvlgFit::new(TvlgConfig::default());
            black_box(fit.fit(xs.view(), us.view()).unwrap())
        })
    });
    group.finish();
}

/// One optimizer step of p2's pixel model (default settings: 4 stacked 16×16 RGB frames, batch
/// normalization) on a minibatch of 32 maze transitions (random-policy episodes): forward,
/// backward, Adam. One thread, as the reproductions run one job per core.
fn pixel_model(c: &mut Criterion) {
    tandem_nn::set_gemm_threads(1);
    let mut data = PixelEpisodes::new(16 * 16 * 3);
    let mut env = PixelMazeEnv::new();
    let mut rng = rng_from_seed(2);
    for k in 0..10 {
        let mut frames = vec![env.reset(Some(k))];
        let (mut actions, mut rewards) = (vec![], vec![]);
        let terminated = loop {
            let a = rng.random_range(0..5);
            let st = env.step(&Action::Discrete(a)).unwrap();
            frames.push(st.observation);
            actions.push(a);
            rewards.push(st.reward);
            if st.terminated || actions.len() == 50 {
                break st.terminated;
            }
        };
        data.push_episode(&frames, &actions, &rewards, terminated)
            .unwrap();
    }
    let mut model = PixelModel::new(PixelModelConfig::default()).unwrap();
    let mut seed = 0;
    c.bench_function("pixel model (p2 maze) fit step, batch 32", |b| {
        b.iter(|| {
            seed += 1;
            let fit = PixelFit {
                steps: 1,
                batch_size: 32,
                seed,
            };
            black_box(model.fit(&data, &fit).unwrap())
        })
    });
}

criterion_group!(benches, predictions, tvlg, pixel_model);
criterion_main!(benches);
