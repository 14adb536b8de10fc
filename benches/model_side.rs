//! The model side of model-based RL at the sizes of its reference implementations, so that each
//! case pairs with a PyTorch or mbrl-lib run of the same work (`docs/performance.md` gives the
//! Python side and the measured ratios):
//!
//! - `cem_*`/`mppi_*`: one plan (population 500, horizon 30, 5 iterations: 150 batched `predict`
//!   calls of 500 rows) on Pendulum-v1's dimensions (3 observations, 1 action in `[-2, 2]`),
//!   through a 2×200 MLP and through a 5-member probabilistic ensemble of 3×200 whose rows keep
//!   their member for the whole rollout and sample its Gaussian (PETS's TS∞, mbrl-lib's
//!   `fixed_model` propagation);
//! - `pets_cem_*`: the same CEM plan through the same ensemble as mbrl-lib 0.2.0's PETS runs it:
//!   20 particles per sequence, each sequence scored by the mean cost of its particles, and
//!   TS-1 propagation (a random member per row at every step, mbrl-lib's `random_model`): 150
//!   `predict` calls of 10 000 rows;
//! - `ensemble_fit_*`: MBPO's ensemble (7 members of 4×200 SiLU, HalfCheetah's 17 + 6 inputs to
//!   17 + 1 Gaussian outputs, learned log-variance bounds, Adam) fitted for one epoch of 20
//!   minibatches of 256 per member, plus the held-out evaluation that picks the 5 elites;
//! - `mbpo_rollouts_*`: MBPO's imagined data of one refit: 100 000 one-step branched rollouts
//!   from real states, SAC's actor (2×256) choosing the actions, the ensemble's elites
//!   predicting next state and reward (a random elite per row, sampled); `100k_rows_only` is
//!   what the rollouts and MBPO's loop do besides the two networks, on HalfCheetah-v5's task:
//!   observations, controls, judging, and storing the rows in SAC's model buffer, through a
//!   model that copies its input;
//! - `dmd_*`: p3's DMD-MPC inner loop: 100 sampled rollouts of horizon 15 through the ensemble,
//!   SAC's actor as the proposal and its soft value as the terminal value, for a batch of start
//!   states.
//!
//! Run: `cargo bench --bench model_side` (`-- cem` for one group). Threads: one gemm thread per
//! product and rayon's pool for independent work, and the allocator (mimalloc, keeping the memory
//! it frees), as the `tandem` program runs.

use criterion::{criterion_group, criterion_main, Criterion};
use mimalloc::MiMalloc;
use ndarray::{Array1, Array2, ArrayView2};
use rand::Rng as _;
use std::sync::Arc;
use tandem_agents::{BatchPolicy, Critic, Mode, OffPolicyLoop, Sac, SacConfig, Store};
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::{Action, Space};
use tandem_envs::Task;
use tandem_models::{
    branched_rollouts, DynamicsModel, EnsembleConfig, FitConfig, FitReport, Judge, Judges,
    MlpModel, MlpModelConfig, ModelError, ModelInput, Prediction, ProbabilisticEnsemble,
    Propagation, Transitions, TransitionsBuilder,
};
use tandem_mujoco::{GymTask, TaskKind};
use tandem_planners::{
    Bounds, Cem, CemConfig, DmdMpc, DmdMpcConfig, Mppi, MppiConfig, Noise, Objective, Planner,
    Temperature,
};

/// The allocator the `tandem` program runs with: the system allocator hands large buffers back to
/// the kernel after each call, and their pages fault in again on the next (about a sixth of the
/// rollouts' profile).
#[global_allocator]
static GLOBAL: MiMalloc = MiMalloc;

fn uniform(rows: usize, cols: usize, rng: &mut Rng) -> Array2<f64> {
    Array2::from_shape_fn((rows, cols), |_| rng.random_range(-1.0..1.0))
}

/// Random transitions of a `s`-state, `a`-action system (the timing does not depend on them).
fn transitions(n: usize, s: usize, a: usize, rng: &mut Rng) -> tandem_models::Transitions {
    let mut b = TransitionsBuilder::new(s, a);
    for _ in 0..n {
        let x: Vec<f64> = (0..s).map(|_| rng.random_range(-1.0..1.0)).collect();
        let u: Vec<f64> = (0..a).map(|_| rng.random_range(-1.0..1.0)).collect();
        let y: Vec<f64> = x
            .iter()
            .map(|v| v + 0.1 * rng.random_range(-1.0..1.0))
            .collect();
        b.push(&x, &u, &y, rng.random_range(-1.0..1.0), false)
            .expect("transition");
    }
    b.build()
}

/// One epoch of minibatches of 256, `holdout_fraction` of the rows held out.
fn one_epoch(holdout_fraction: f64) -> FitConfig {
    FitConfig {
        epochs: 1,
        batch_size: 256,
        holdout_fraction,
        seed: 0,
        early_stop: None,
    }
}

/// Pendulum-v1's cost of `(cos θ, sin θ, θ̇)` and torque.
fn pendulum_objective() -> Objective {
    Objective::new(3, 1, |x, u| {
        let th = x[1].atan2(x[0]);
        th * th + 0.1 * x[2] * x[2] + 0.001 * u[0] * u[0]
    })
}

/// 1000 random pendulum transitions and one epoch over them: a short fit gives the models real
/// input and output standardizations.
fn pendulum_data() -> (tandem_models::Transitions, FitConfig) {
    let mut rng = rng_from_seed(0);
    (transitions(1000, 3, 1, &mut rng), one_epoch(0.0))
}

/// The 5-member probabilistic ensemble of 3×200 on Pendulum-v1's dimensions, sampling its
/// Gaussian, its rows keeping their member (TS∞) unless a planner names another propagation.
fn pendulum_ensemble() -> ProbabilisticEnsemble {
    let (data, fit) = pendulum_data();
    let mut ens = ProbabilisticEnsemble::new(
        3,
        1,
        EnsembleConfig {
            members: 5,
            elites: 5,
            hidden: vec![200, 200, 200],
            learn_reward: false,
            propagation: Propagation::FixedMember,
            sample: true,
            ..EnsembleConfig::default()
        },
    )
    .expect("ensemble");
    ens.fit(&data, &fit).expect("fit");
    ens
}

fn pendulum_models() -> Vec<(&'static str, Box<dyn DynamicsModel>)> {
    let (data, fit) = pendulum_data();
    let mut mlp = MlpModel::new(
        3,
        1,
        MlpModelConfig {
            hidden: vec![200, 200],
            learn_reward: false,
            learn_termination: false,
            ..MlpModelConfig::default()
        },
    )
    .expect("mlp");
    mlp.fit(&data, &fit).expect("fit");
    vec![
        ("mlp1_2x200_det", Box::new(mlp)),
        ("ens5_3x200_prob", Box::new(pendulum_ensemble())),
    ]
}

fn planners(c: &mut Criterion) {
    let objective = pendulum_objective();
    let x0 = [-1.0, 0.0, 0.0];
    let bounds = Some(Bounds::symmetric(1, 2.0));
    let mut g = c.benchmark_group("plan");
    g.sample_size(10);
    for (name, model) in pendulum_models() {
        let mut cem = Cem::new(CemConfig {
            horizon: 30,
            population: 500,
            iterations: 5,
            elite_fraction: 0.1,
            alpha: 0.1,
            bounds: bounds.clone(),
            ..CemConfig::default()
        })
        .expect("cem");
        g.bench_function(format!("cem_{name}"), |b| {
            b.iter(|| cem.plan(&x0, model.as_ref(), &objective).expect("plan"))
        });
        // mbrl-lib's MPPI settings: temperature γ = 10, σ = 1, correlation β = 0.6.
        let mut mppi = Mppi::new(MppiConfig {
            horizon: 30,
            samples: 500,
            iterations: 5,
            lambda: 0.1,
            temperature: Temperature::Fixed,
            noise: Noise::Diagonal(vec![1.0]),
            correlation: 0.6,
            bounds: bounds.clone(),
            ..MppiConfig::default()
        })
        .expect("mppi");
        g.bench_function(format!("mppi_{name}"), |b| {
            b.iter(|| mppi.plan(&x0, model.as_ref(), &objective).expect("plan"))
        });
    }
    // PETS at mbrl-lib 0.2.0's settings: 20 particles per sequence (`algorithm/pets.yaml`) and
    // its ensemble's `random_model` propagation (`dynamics_model/gaussian_mlp_ensemble.yaml`,
    // PETS's TS-1: every row draws a member at every step): 10 000 rows per prediction.
    let ens = pendulum_ensemble();
    let mut pets = Cem::new(CemConfig {
        horizon: 30,
        population: 500,
        particles: 20,
        propagation: Some(Propagation::RandomMember),
        iterations: 5,
        elite_fraction: 0.1,
        alpha: 0.1,
        bounds,
        ..CemConfig::default()
    })
    .expect("cem");
    g.bench_function("pets_cem_ens5_3x200_p20_ts1", |b| {
        b.iter(|| pets.plan(&x0, &ens, &objective).expect("plan"))
    });
    g.finish();
}

/// MBPO's ensemble on HalfCheetah's dimensions.
fn cheetah_ensemble() -> ProbabilisticEnsemble {
    ProbabilisticEnsemble::new(17, 6, EnsembleConfig::default()).expect("ensemble")
}

fn ensemble_fit(c: &mut Criterion) {
    let mut rng = rng_from_seed(1);
    // 20 minibatches of 256 per member after a 10% holdout.
    let data = transitions(5689, 17, 6, &mut rng);
    let fit = one_epoch(0.1);
    let mut ens = cheetah_ensemble();
    let mut g = c.benchmark_group("ensemble_fit");
    g.sample_size(10);
    g.bench_function("7x4x200_b256_20steps", |b| {
        b.iter(|| ens.fit(&data, &fit).expect("fit"))
    });
    g.finish();
}

/// A task of HalfCheetah's shape (17 states observed as they are, 6 actions in `[-1, 1]`),
/// rewarded by the model, never terminating, as MBPO's HalfCheetah.
#[derive(Clone)]
struct CheetahShaped {
    obs: Space,
    act: Space,
}

impl CheetahShaped {
    fn new() -> Self {
        Self {
            obs: Space::boxed(vec![-f64::INFINITY; 17], vec![f64::INFINITY; 17]),
            act: Space::symmetric(6, 1.0),
        }
    }
}

impl Task for CheetahShaped {
    fn id(&self) -> &str {
        "cheetah-shaped"
    }
    fn observation_space(&self) -> &Space {
        &self.obs
    }
    fn action_space(&self) -> &Space {
        &self.act
    }
    fn state_dim(&self) -> usize {
        17
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        match action {
            Action::Continuous(v) => v.clone(),
            Action::Discrete(i) => vec![*i as f64; 6],
        }
    }
    fn initial_state(&self, _rng: &mut Rng) -> Vec<f64> {
        vec![0.0; 17]
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        state.to_vec()
    }
    fn reward(&self, _: &[f64], _: &[f64], _: &[f64]) -> f64 {
        0.0
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(1000)
    }
}

/// A fitted cheetah-shaped ensemble, SAC with its default 2×256 networks, and the task.
fn cheetah_parts() -> (ProbabilisticEnsemble, Sac, CheetahShaped) {
    let mut rng = rng_from_seed(2);
    let data = transitions(2000, 17, 6, &mut rng);
    let mut ens = cheetah_ensemble();
    ens.fit(&data, &one_epoch(0.1)).expect("fit");
    let task = CheetahShaped::new();
    let sac = Sac::new(
        SacConfig::default(),
        task.observation_space(),
        task.action_space(),
        0,
    )
    .expect("sac");
    (ens, sac, task)
}

fn mbpo_rollouts(c: &mut Criterion) {
    let (ens, sac, task) = cheetah_parts();
    let mut rng = rng_from_seed(3);
    let starts = uniform(100_000, 17, &mut rng);
    let judges = Judges {
        reward: Judge::Model,
        termination: Judge::Task,
        ..Judges::default()
    };
    let mut g = c.benchmark_group("mbpo_rollouts");
    g.sample_size(10);
    g.bench_function("100k_1step_ens7x4x200_sac2x256", |b| {
        b.iter(|| {
            let mut policy = |obs: ArrayView2<'_, f64>, rng: &mut Rng| {
                sac.act_batch(obs, Mode::Explore, rng)
                    .map_err(|e| ModelError::Other(e.to_string()))
            };
            branched_rollouts(
                &ens,
                &task,
                &judges,
                starts.view(),
                1,
                &mut policy,
                &mut rng,
            )
            .expect("rollouts")
        })
    });
    // The two halves of it.
    g.bench_function("100k_policy_only", |b| {
        b.iter(|| {
            sac.act_batch(starts.view(), Mode::Explore, &mut rng)
                .expect("act")
        })
    });
    let actions = uniform(100_000, 6, &mut rng);
    g.bench_function("100k_ensemble_predict_only", |b| {
        b.iter(|| {
            ens.predict(
                &tandem_models::ModelInput::new(starts.view(), actions.view()),
                &mut rng,
            )
            .expect("predict")
        })
    });
    rows_only(&mut g, &judges);
    g.finish();
}

/// A model whose prediction is its input state, with reward 0: one copy, no network.
#[derive(Debug, Clone)]
struct Standstill;

impl DynamicsModel for Standstill {
    fn state_dim(&self) -> usize {
        18
    }
    fn action_dim(&self) -> usize {
        6
    }
    fn predict(&self, input: &ModelInput<'_>, _: &mut Rng) -> Result<Prediction, ModelError> {
        let mut p = Prediction::deterministic(input.states.to_owned());
        p.rewards = Some(Array1::zeros(input.states.nrows()));
        Ok(p)
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

/// 100 000 one-step rollouts on HalfCheetah-v5's task through [`Standstill`] with a fixed
/// action, stored in a loop's model buffer as MBPO stores them.
fn rows_only(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    judges: &Judges,
) {
    let task = GymTask::new(TaskKind::HalfCheetah, vec![0.0; 9]).expect("task");
    let mut rng = rng_from_seed(5);
    let starts = uniform(100_000, 18, &mut rng);
    let cfg = SacConfig::default();
    let (o, a) = (task.observation_space(), task.action_space());
    let sac = Sac::new(cfg.clone(), o, a, 0).expect("sac");
    let mut lp = OffPolicyLoop::new(sac, cfg.schedule(), o, a, rng_from_seed(6))
        .expect("loop")
        .with_secondary(400_000, 1.0)
        .expect("model buffer");
    g.bench_function("100k_rows_only", |b| {
        b.iter(|| {
            let mut policy = |obs: ArrayView2<'_, f64>, _: &mut Rng| {
                Ok(Array2::from_elem((obs.nrows(), 6), 0.1))
            };
            let im = branched_rollouts(
                &Standstill,
                &task,
                judges,
                starts.view(),
                1,
                &mut policy,
                &mut rng,
            )
            .expect("rollouts");
            lp.push_rows(
                Store::Secondary,
                im.observations.view(),
                im.actions.view(),
                im.rewards.view(),
                im.next_observations.view(),
                &im.terminated,
            )
            .expect("stored")
        })
    });
}

fn dmd_inner_loop(c: &mut Criterion) {
    let (mut ens, sac, _task) = cheetah_parts();
    ens.set_propagation(Propagation::FixedMember);
    let mut rng = rng_from_seed(4);
    let starts = uniform(10, 17, &mut rng);
    let critic = Arc::new(sac.clone());
    let objective = Objective::new(17, 6, |_, _| 0.0)
        .with_model_reward()
        .with_discount(0.99)
        .expect("discount")
        .with_terminal_value(move |x: ArrayView2<'_, f64>| {
            critic
                .v_batch(x, Mode::Deterministic, &mut rng_from_seed(0))
                .unwrap_or_else(|_| Array1::from_elem(x.nrows(), f64::NAN))
        });
    let mut planner = DmdMpc::new(DmdMpcConfig {
        horizon: 15,
        samples: 100,
        bounds: Some(Bounds::symmetric(6, 1.0)),
        noise: Noise::Diagonal(vec![0.5; 6]),
        ..DmdMpcConfig::default()
    })
    .expect("dmd");
    let proposal_rng = std::cell::RefCell::new(rng_from_seed(5));
    let proposal = |x: ArrayView2<'_, f64>| {
        sac.act_batch(x, Mode::Explore, &mut proposal_rng.borrow_mut())
            .expect("act")
    };
    let mut g = c.benchmark_group("dmd");
    g.sample_size(10);
    g.bench_function("10_plans_m100_h15_ens7x4x200_sac_proposal", |b| {
        b.iter(|| {
            planner
                .plan_batch_with_proposal(starts.view(), &ens, &objective, &proposal)
                .expect("plan")
        })
    });
    g.finish();
}

criterion_group!(
    name = benches;
    config = {
        tandem::keep_freed_memory();
        Criterion::default()
    };
    targets = planners, ensemble_fit, mbpo_rollouts, dmd_inner_loop
);
criterion_main!(benches);
