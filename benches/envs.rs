//! Classic plants and environments: one step of each, the hot path of every rollout and of
//! planners that plan through a `Plant`. Run with `cargo bench --bench envs`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use nalgebra::DVector;
use tandem::make_env as make;
use tandem_dynamics::classic::{CartPole, GymPendulum};
use tandem_dynamics::Plant;
use tandem_envs::Action;
use tandem_robots::{DcMotorPendulum, DcMotorPendulumParams};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("plants");
    let cp = CartPole::default();
    g.bench_function("cartpole_step_array", |b| {
        b.iter(|| cp.step_array(black_box(&[0.01, 0.2, -0.03, 0.1]), black_box(10.0)))
    });
    let gp = GymPendulum::default();
    g.bench_function("gym_pendulum_step_array", |b| {
        b.iter(|| gp.step_array(black_box(&[1.0, 0.5]), black_box(1.0)))
    });
    let dc = DcMotorPendulum::new(DcMotorPendulumParams::real());
    g.bench_function("dc_motor_pendulum_step_array_20rk4", |b| {
        b.iter(|| dc.step_array(black_box(&[3.0, 1.0]), black_box(2.0)))
    });
    let (x, u) = (
        DVector::from_row_slice(&[3.0, 1.0]),
        DVector::from_element(1, 2.0),
    );
    g.bench_function("dc_motor_pendulum_plant_step_dvector", |b| {
        b.iter(|| dc.step(black_box(&x), black_box(&u)))
    });
    g.finish();

    let mut g = c.benchmark_group("envs");
    for (id, action) in [
        ("CartPole-v1", Action::Discrete(1)),
        ("Pendulum-v1", Action::Continuous(vec![0.5])),
        ("DcMotorPendulum-real-v0", Action::Continuous(vec![2.0])),
    ] {
        let mut env = make(id).unwrap();
        env.reset(Some(0));
        let start = env.state();
        g.bench_function(format!("{id}_step"), |b| {
            b.iter(|| {
                // Restart from the same state every step, so episodes never end.
                env.set_state(&start).unwrap();
                env.step(black_box(&action)).unwrap()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
