//! Rigid-body dynamics on the 7-DoF fixture arm (`tests/fixtures/pinocchio/arm7.urdf`): ABA, RNEA,
//! CRBA and the forward-dynamics derivatives, each on a preallocated `Data`.
//!
//! Reference (issue 3): Pinocchio 4.1 compiled from its C++ headers on this kind of machine, same
//! URDF: ABA 2.06 µs, RNEA 1.01 µs, CRBA 0.54 µs per call; ABA derivatives about 5 µs for a 6-DoF
//! arm through its Python binding. Run with `cargo bench --bench dynamics`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use tandem_dynamics::rigid::{aba, aba_derivatives, crba, rnea, rnea_derivatives, Data, Model};

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
}

criterion_group!(benches, bench);
criterion_main!(benches);
