//! Planner hot path: one CEM plan (population 500, horizon 30, 5 iterations: 75 000 model
//! evaluations in 150 batched `predict` calls of 500 rows) through a 2-hidden-layer, 200-unit
//! `MlpModel` (state 4, action 2; untrained weights, the cost of a forward pass does not depend on
//! them).
//!
//! `cargo bench --bench planners`
//!
//! Measured on 2 shared cores under load 7–17 (criterion, 10 samples of 2 plans; min and median
//! of the per-plan sample means): before `MlpModel::predict` reused its buffers, min 244/251 ms,
//! median 322/315 ms; after, min 206/206 ms, median 229/248 ms (two alternating runs each).

use criterion::{criterion_group, criterion_main, Criterion};
use tandem_models::{MlpModel, MlpModelConfig};
use tandem_planners::{Bounds, Cem, CemConfig, Objective, Planner};

fn cem_plan(c: &mut Criterion) {
    let cfg = MlpModelConfig {
        hidden: vec![200, 200],
        learn_reward: false,
        learn_termination: false,
        ..MlpModelConfig::default()
    };
    let model = MlpModel::new(4, 2, cfg).expect("model");
    let objective = Objective::new(4, 2, |x, u| {
        x.iter().map(|v| v * v).sum::<f64>() + 0.01 * u.iter().map(|v| v * v).sum::<f64>()
    });
    let mut cem = Cem::new(CemConfig {
        horizon: 30,
        population: 500,
        iterations: 5,
        bounds: Some(Bounds::symmetric(2, 1.0)),
        ..CemConfig::default()
    })
    .expect("cem");
    let x0 = [0.1, -0.2, 0.3, 0.0];
    c.bench_function("cem_plan_pop500_h30_it5_mlp200x2", |b| {
        b.iter(|| {
            cem.reset();
            cem.plan(&x0, &model, &objective).expect("plan")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = cem_plan
}
criterion_main!(benches);
