//! Rigid-body dynamics on the 7-DoF fixture arm (`tests/fixtures/pinocchio/arm7.urdf`): ABA, RNEA,
//! CRBA and the forward-dynamics derivatives, each on a preallocated `Data`.
//!
//! Reference: Pinocchio 4.1 compiled from its C++ headers on this kind of machine, same
//! URDF: ABA 2.06 µs, RNEA 1.01 µs, CRBA 0.54 µs per call; ABA derivatives about 5 µs for a 6-DoF
//! arm through its Python binding.
//!
//! Side by side on one 2-core machine at one time (2026-11-21; the host's speed drifts by ±30%
//! over hours, so only same-run comparisons are meaningful): Pinocchio 4.1 from the `pin` wheel,
//! its algorithms compiled from the headers with `g++ -O3` (baseline x86-64, as tandem is built;
//! a `-march=native` build crashed against the wheel's libraries), against
//! `rigid_timing` (example of `tandem-robots`), same URDF and state, per call:
//!
//! | | Pinocchio min-of-N CPU | tandem min-of-N CPU | Pinocchio 5×100k wall median | tandem 5×100k wall median |
//! |---|---|---|---|---|
//! | ABA | 2.35 µs | 1.19 µs | 2.60–2.98 µs | 1.23–1.52 µs |
//! | RNEA | 1.08–1.23 µs | 0.54 µs | 1.33–1.44 µs | 0.55–0.60 µs |
//! | CRBA | 0.60–0.61 µs | 0.445 µs | 0.64–0.66 µs | 0.47–0.78 µs |
//!
//! The `biped` group times `RigidBodyPlant::linearize` of one 30 ms control period (30 RK4 steps
//! with contact) of the Leo-like biped (10 DoF, 6 actions): analytical (ABA derivatives chained
//! with the actuator and contact partials through the RK4 stages) against central differences
//! (`2 (20 + 6)` rollouts of the period), and `step`, one control period of the true biped
//! (what p0's Leo study spends per sample on the true system). Run with
//! `cargo bench --bench dynamics`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use nalgebra::DVector;
use tandem_dynamics::rigid::{aba, aba_derivatives, crba, rnea, rnea_derivatives, Data, Model};
use tandem_dynamics::rigid_plant::RigidPlantConfig;
use tandem_robots::leo::{leo_plant, leo_true_overrides, standing_state};

fn arm7() -> Model {
    Model::from_urdf_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/pinocchio/arm7.urdf"
    ))
    .expect("arm7.urdf parses")
}

fn bench(c: &mut Criterion) {
    let model = arm7();
    let mut data = Data::new(&model);
    let q = [0.3, -0.5, 1.1, -1.2, 0.4, 0.9, -2.0];
    let v = [0.5, -1.0, 2.0, 0.3, -0.7, 1.5, -2.5];
    let a = [1.0, -2.0, 3.0, -4.0, 5.0, -6.0, 7.0];
    let tau = [10.0, -20.0, 5.0, 3.0, -1.0, 2.0, 0.5];
    let mut g = c.benchmark_group("arm7");
    g.bench_function("aba", |b| {
        b.iter(|| {
            aba(
                &model,
                &mut data,
                black_box(&q),
                black_box(&v),
                black_box(&tau),
            );
        })
    });
    g.bench_function("rnea", |b| {
        b.iter(|| {
            rnea(
                &model,
                &mut data,
                black_box(&q),
                black_box(&v),
                black_box(&a),
            );
        })
    });
    g.bench_function("crba", |b| {
        b.iter(|| {
            crba(&model, &mut data, black_box(&q));
        })
    });
    g.bench_function("rnea_derivatives", |b| {
        b.iter(|| {
            rnea_derivatives(
                &model,
                &mut data,
                black_box(&q),
                black_box(&v),
                black_box(&a),
            )
        })
    });
    g.bench_function("aba_derivatives", |b| {
        b.iter(|| {
            aba_derivatives(
                &model,
                &mut data,
                black_box(&q),
                black_box(&v),
                black_box(&tau),
            )
        })
    });
    g.finish();

    let plant = leo_plant(RigidPlantConfig::default(), &leo_true_overrides()).expect("biped");
    let mut x = standing_state(plant.model());
    let n = plant.model().nv();
    x[1] -= 0.001;
    x[n] = 0.03;
    x[n + 3] = 0.2;
    let u = DVector::from_vec(vec![1.5, -2.0, 0.7, -1.0, 2.5, -0.4]);
    let mut g = c.benchmark_group("biped");
    g.sample_size(20);
    g.bench_function("linearize_analytic", |b| {
        b.iter(|| plant.linearize_analytic(black_box(x.as_slice()), black_box(u.as_slice())))
    });
    g.bench_function("linearize_fd", |b| {
        b.iter(|| plant.linearize_fd(black_box(&x), black_box(&u)))
    });
    g.bench_function("step", |b| {
        b.iter(|| {
            let mut y = x.as_slice().to_vec();
            plant.step_in_place(black_box(&mut y), black_box(u.as_slice()));
            y
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
