//! MPC planners on a linear system with quadratic cost (truth: the Riccati solution), a pendulum,
//! and bad inputs.

#![allow(clippy::needless_range_loop)]

mod common;

use common::{quadratic_objective, riccati, LinearModel, PendulumModel};
use nalgebra::{DMatrix, DVector};
use ndarray::{Array1, Array2};
use tandem_models::DynamicsModel;
use tandem_planners::{
    Bounds, Cem, CemConfig, DmdMpc, DmdMpcConfig, Mppi, MppiConfig, Noise, Objective, PlanError,
    Planner, Utility,
};

const H: usize = 15;

fn lqr_problem() -> (LinearModel, Objective, f64, Vec<f64>) {
    let m = LinearModel::double_integrator();
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
    let r = DMatrix::from_element(1, 1, 0.01);
    let qf = &q * 10.0;
    let obj = quadratic_objective(&q, &r, &qf);
    let (p, k) = riccati(&m.a, &m.b, &q, &r, &qf, H);
    let x0 = DVector::from_vec(vec![1.0, 0.0]);
    let jstar = (x0.transpose() * &p[0] * &x0)[0];
    let u0 = -(&k[0] * &x0)[0];
    (m, obj, jstar, vec![u0])
}

fn cem(iterations: usize, seed: u64) -> Cem {
    Cem::new(CemConfig {
        horizon: H,
        population: 200,
        iterations,
        init_std: Some(vec![2.0]),
        seed,
        ..CemConfig::default()
    })
    .unwrap()
}

fn mppi(iterations: usize, seed: u64) -> Mppi {
    Mppi::new(MppiConfig {
        horizon: H,
        samples: 200,
        lambda: 0.05,
        noise: Noise::Isotropic(1.0),
        iterations,
        seed,
        ..MppiConfig::default()
    })
    .unwrap()
}

fn dmd(iterations: usize, seed: u64) -> DmdMpc {
    DmdMpc::new(DmdMpcConfig {
        horizon: H,
        samples: 200,
        step_size: 0.8,
        noise: Noise::Isotropic(1.0),
        iterations,
        seed,
        ..DmdMpcConfig::default()
    })
    .unwrap()
}

/// Every planner's cost falls towards the LQR optimum with more iterations, never beats it, and
/// ends within a few percent of it; the first action approaches the LQR action.
#[test]
fn planners_approach_the_lqr_optimum() {
    let (m, obj, jstar, u0) = lqr_problem();
    let x0 = [1.0, 0.0];
    type Make = fn(usize, u64) -> Box<dyn Planner>;
    let makers: [(&str, Make, usize); 3] = [
        ("cem", |i, s| Box::new(cem(i, s)), 12),
        ("mppi", |i, s| Box::new(mppi(i, s)), 30),
        ("dmd", |i, s| Box::new(dmd(i, s)), 20),
    ];
    for (name, make, many) in makers {
        let few = make(1, 3).plan(&x0, &m, &obj).unwrap().total_cost;
        let plan = make(many, 3).plan(&x0, &m, &obj).unwrap();
        let best = plan.total_cost;
        println!("{name}: J* = {jstar:.5}, 1 iteration {few:.5}, {many} iterations {best:.5}, u0 {:.4} vs {:.4}", plan.actions[(0, 0)], u0[0]);
        assert!(
            best >= jstar - 1e-9,
            "{name} beat the optimum: {best} < {jstar}"
        );
        assert!(best < few, "{name}: cost did not fall ({few} -> {best})");
        assert!(
            best < 1.03 * jstar,
            "{name}: {best} not within 3% of {jstar}"
        );
        assert!(
            (plan.actions[(0, 0)] - u0[0]).abs() < 0.3 * u0[0].abs(),
            "{name} first action"
        );
    }
}

/// Warm starting: replanning from the states the plan predicts keeps improving (closed loop on the
/// linear system reaches near the origin).
#[test]
fn closed_loop_regulates_linear_system() {
    let (m, obj, _, _) = lqr_problem();
    for mut p in [
        Box::new(cem(3, 1)) as Box<dyn Planner>,
        Box::new(mppi(3, 1)),
        Box::new(dmd(3, 1)),
    ] {
        let mut x = DVector::from_vec(vec![1.0, 0.0]);
        for _ in 0..40 {
            let plan = p.plan(x.as_slice(), &m, &obj).unwrap();
            x = m.step(&x, &DVector::from_vec(plan.first_action()));
        }
        assert!(x.norm() < 0.05, "state after 40 steps {x}");
    }
}

#[test]
fn equal_seeds_equal_actions_different_seeds_differ() {
    let (m, obj, _, _) = lqr_problem();
    let x0 = [1.0, 0.0];
    let run = |mut p: Box<dyn Planner>| -> Vec<Array2<f64>> {
        (0..3)
            .map(|_| p.plan(&x0, &m, &obj).unwrap().actions)
            .collect()
    };
    for (a, b, c) in [
        (
            Box::new(cem(2, 5)) as Box<dyn Planner>,
            Box::new(cem(2, 5)) as Box<dyn Planner>,
            Box::new(cem(2, 6)) as Box<dyn Planner>,
        ),
        (
            Box::new(mppi(2, 5)),
            Box::new(mppi(2, 5)),
            Box::new(mppi(2, 6)),
        ),
        (
            Box::new(dmd(2, 5)),
            Box::new(dmd(2, 5)),
            Box::new(dmd(2, 6)),
        ),
    ] {
        let (ra, rb, rc) = (run(a), run(b), run(c));
        assert_eq!(ra, rb);
        assert_ne!(ra, rc);
    }
    // reset restarts the stream: the same first plan again.
    let mut p = cem(2, 9);
    let first = p.plan(&x0, &m, &obj).unwrap().actions;
    p.plan(&x0, &m, &obj).unwrap();
    p.reset();
    assert_eq!(p.plan(&x0, &m, &obj).unwrap().actions, first);
}

#[test]
fn bounds_hold() {
    let (m, obj, _, _) = lqr_problem();
    let b = Bounds::new(vec![-0.3], vec![0.2]);
    let mut planners: Vec<Box<dyn Planner>> = vec![
        Box::new(
            Cem::new(CemConfig {
                horizon: H,
                population: 100,
                bounds: Some(b.clone()),
                ..Default::default()
            })
            .unwrap(),
        ),
        Box::new(
            Mppi::new(MppiConfig {
                horizon: H,
                samples: 100,
                noise: Noise::Isotropic(3.0),
                bounds: Some(b.clone()),
                ..Default::default()
            })
            .unwrap(),
        ),
        Box::new(
            DmdMpc::new(DmdMpcConfig {
                horizon: H,
                samples: 100,
                noise: Noise::Isotropic(3.0),
                bounds: Some(b.clone()),
                ..Default::default()
            })
            .unwrap(),
        ),
    ];
    for p in planners.iter_mut() {
        // Far from the origin the optimum pushes as hard as allowed: the active bound is reached.
        for (x0, active) in [([5.0, 0.0], -0.3), ([-5.0, 0.0], 0.2)] {
            p.reset();
            for _ in 0..3 {
                let plan = p.plan(&x0, &m, &obj).unwrap();
                assert!(plan.actions.iter().all(|&u| (-0.3..=0.2).contains(&u)));
                let u0 = plan.actions[(0, 0)];
                assert!(
                    (u0 - active).abs() < 0.1,
                    "first action {u0}, bound {active}"
                );
            }
        }
    }
}

/// With the critic's value of the remaining LQR problem as terminal value, a 3-step plan picks
/// the first action of the 15-step optimum (p3's terminal cost −V).
#[test]
fn terminal_value_extends_the_horizon() {
    let m = LinearModel::double_integrator();
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
    let r = DMatrix::from_element(1, 1, 0.01);
    let qf = &q * 10.0;
    let (p, k) = riccati(&m.a, &m.b, &q, &r, &qf, H);
    let p3 = p[3].clone();
    let (q2, r2) = (q.clone(), r.clone());
    let obj = Objective::new(2, 1, move |x, u| {
        let x = DVector::from_column_slice(x);
        (x.transpose() * &q2 * &x)[0] + r2[(0, 0)] * u[0] * u[0]
    })
    .with_terminal_value(move |s| {
        Array1::from_iter(s.rows().into_iter().map(|row| {
            let x = DVector::from_iterator(2, row.iter().copied());
            -(x.transpose() * &p3 * &x)[0]
        }))
    });
    let x0 = DVector::from_vec(vec![1.0, 0.0]);
    let u_star = -(&k[0] * &x0)[0];
    let mut c = Cem::new(CemConfig {
        horizon: 3,
        population: 200,
        iterations: 10,
        init_std: Some(vec![2.0]),
        ..Default::default()
    })
    .unwrap();
    let plan = c.plan(x0.as_slice(), &m, &obj).unwrap();
    assert!(
        (plan.actions[(0, 0)] - u_star).abs() < 0.1 * u_star.abs(),
        "{} vs {u_star}",
        plan.actions[(0, 0)]
    );
    let jstar = (x0.transpose() * &p[0] * &x0)[0];
    assert!((plan.total_cost - jstar).abs() < 0.01 * jstar);
}

/// DMD-MPC's two-loop shift: with a tiny step the plan is the policy's own rollout; the planned
/// transitions are consistent with the model and the costs.
#[test]
fn dmd_policy_proposal_and_transitions() {
    let (m, obj, jstar, _) = lqr_problem();
    let kinf = {
        let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
        let r = DMatrix::from_element(1, 1, 0.01);
        riccati(&m.a, &m.b, &q, &r, &q, 300).1[0].clone()
    };
    let k2 = kinf.clone();
    let policy = move |s: ndarray::ArrayView2<'_, f64>| {
        Array2::from_shape_fn((s.nrows(), 1), |(i, _)| {
            -(k2[(0, 0)] * s[(i, 0)] + k2[(0, 1)] * s[(i, 1)])
        })
    };
    let mut p = DmdMpc::new(DmdMpcConfig {
        horizon: H,
        samples: 50,
        step_size: 1e-9,
        ..Default::default()
    })
    .unwrap()
    .with_proposal(policy);
    let plan = p.plan(&[1.0, 0.0], &m, &obj).unwrap();
    let mut x = DVector::from_vec(vec![1.0, 0.0]);
    for h in 0..H {
        let u = -(&kinf * &x)[0];
        assert!((plan.actions[(h, 0)] - u).abs() < 1e-6);
        x = m.step(&x, &DVector::from_vec(vec![u]));
    }
    // The stationary LQR policy is near-optimal on this horizon.
    assert!(plan.total_cost < 1.05 * jstar);
    let tr = plan.transitions();
    assert_eq!(tr.states.nrows(), H);
    for h in 0..H {
        let xs = DVector::from_iterator(2, tr.states.row(h).iter().copied());
        let next = m.step(&xs, &DVector::from_vec(vec![tr.actions[(h, 0)]]));
        for j in 0..2 {
            assert!((next[j] - tr.next_states[(h, j)]).abs() < 1e-12);
        }
        let c = obj
            .running_cost(xs.as_slice(), &[tr.actions[(h, 0)]])
            .unwrap();
        assert!((tr.rewards[h] + c).abs() < 1e-12);
        // One-step-back data: the previous row's state and action (the start state and a zero
        // action at h = 0).
        let (ps, pa) = if h == 0 {
            (tr.states.row(0).to_owned(), 0.0)
        } else {
            (tr.states.row(h - 1).to_owned(), tr.actions[(h - 1, 0)])
        };
        assert_eq!(tr.prev_states.row(h), ps);
        assert_eq!(tr.prev_actions[(h, 0)], pa);
    }

    // A full step with the exponential utility improves on the policy.
    let mut p = DmdMpc::new(DmdMpcConfig {
        horizon: H,
        samples: 300,
        step_size: 0.5,
        noise: Noise::Isotropic(0.5),
        utility: Utility::Exponential { lambda: 0.01 },
        iterations: 10,
        ..Default::default()
    })
    .unwrap();
    let pol_cost = plan.total_cost;
    let k3 = kinf.clone();
    let better = p
        .plan_with_proposal(&[1.0, 0.0], &m, &obj, &move |s: ndarray::ArrayView2<
            '_,
            f64,
        >| {
            Array2::from_shape_fn((s.nrows(), 1), |(i, _)| {
                -(k3[(0, 0)] * s[(i, 0)] + k3[(0, 1)] * s[(i, 1)])
            })
        })
        .unwrap();
    assert!(better.total_cost <= pol_cost + 1e-12 && better.total_cost >= jstar - 1e-9);
}

/// Swing-up of a torque-limited pendulum (|u| <= 2, gravity torque up to 9.81): every planner
/// brings it from hanging to upright and holds it, with small populations.
#[test]
fn pendulum_swing_up_with_small_populations() {
    let m = PendulumModel;
    let obj = Objective::from_reward(2, 1, |x, u| {
        let phi = (x[0] + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        -5.0 * phi * phi - 0.1 * x[1] * x[1] - 0.01 * u[0] * u[0]
    });
    let b = Some(Bounds::symmetric(1, 2.0));
    let mut planners: Vec<(&str, Box<dyn Planner>)> = vec![
        (
            "cem",
            Box::new(
                Cem::new(CemConfig {
                    horizon: 40,
                    population: 60,
                    iterations: 3,
                    bounds: b.clone(),
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
        (
            "mppi",
            Box::new(
                Mppi::new(MppiConfig {
                    horizon: 40,
                    samples: 60,
                    lambda: 1.0,
                    noise: Noise::Isotropic(2.0),
                    bounds: b.clone(),
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
        (
            "dmd",
            Box::new(
                DmdMpc::new(DmdMpcConfig {
                    horizon: 40,
                    samples: 60,
                    iterations: 3,
                    noise: Noise::Isotropic(1.0),
                    adapt_covariance: true,
                    utility: Utility::CemElite {
                        elite_fraction: 0.1,
                        reward_weighted: true,
                    },
                    bounds: b.clone(),
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
    ];
    for (name, p) in planners.iter_mut() {
        let mut x = [std::f64::consts::PI, 0.0];
        let mut last = Vec::new();
        for t in 0..200 {
            let u = p.plan(&x, &m, &obj).unwrap().first_action()[0];
            assert!(u.abs() <= 2.0);
            x = PendulumModel::step(&x, u);
            if t >= 150 {
                let phi = (x[0] + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                    - std::f64::consts::PI;
                last.push(phi.abs());
            }
        }
        let worst = last.iter().copied().fold(0.0, f64::max);
        println!("{name}: max |phi| over the last 50 steps {worst:.4}");
        assert!(worst < 0.1, "{name} did not hold upright: {worst}");
    }
}

#[test]
fn bad_inputs_are_clear_errors() {
    let (m, obj, _, _) = lqr_problem();
    assert!(matches!(
        Cem::new(CemConfig {
            horizon: 0,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    assert!(matches!(
        Cem::new(CemConfig {
            population: 0,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    assert!(matches!(
        Cem::new(CemConfig {
            elite_fraction: 0.0,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    assert!(matches!(
        Mppi::new(MppiConfig {
            lambda: -1.0,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    assert!(matches!(
        DmdMpc::new(DmdMpcConfig {
            step_size: 1.5,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    let mut p = cem(1, 0);
    assert!(matches!(
        p.plan(&[1.0], &m, &obj),
        Err(PlanError::Dim { .. })
    ));
    assert!(matches!(
        p.plan(&[f64::NAN, 0.0], &m, &obj),
        Err(PlanError::NonFinite(_))
    ));
    let wrong = Objective::new(3, 1, |_, _| 0.0);
    assert!(matches!(
        p.plan(&[1.0, 0.0], &m, &wrong),
        Err(PlanError::Dim { .. })
    ));
    let nan = Objective::new(2, 1, |x, _| if x[0] < 0.5 { f64::NAN } else { 0.0 });
    assert!(matches!(
        p.plan(&[1.0, 0.0], &m, &nan),
        Err(PlanError::NonFiniteCost { .. })
    ));
    let mut bad_bounds = Cem::new(CemConfig {
        bounds: Some(Bounds::new(vec![1.0], vec![-1.0])),
        ..Default::default()
    })
    .unwrap();
    assert!(matches!(
        bad_bounds.plan(&[1.0, 0.0], &m, &obj),
        Err(PlanError::Config(_))
    ));
    let mut full = Mppi::new(MppiConfig {
        noise: Noise::Full(vec![vec![1.0, 2.0], vec![2.0, 1.0]]),
        ..Default::default()
    })
    .unwrap();
    let m2 = LinearModel {
        a: DMatrix::identity(2, 2),
        b: DMatrix::identity(2, 2),
    };
    let obj2 = Objective::new(2, 2, |_, _| 0.0);
    assert!(matches!(
        full.plan(&[1.0, 0.0], &m2, &obj2),
        Err(PlanError::Config(_))
    ));
    let _ = m.state_dim();
    let mut dm = DmdMpc::new(DmdMpcConfig::default())
        .unwrap()
        .with_proposal(|s| Array2::zeros((s.nrows(), 3)));
    assert!(matches!(
        dm.plan(&[1.0, 0.0], &m, &obj),
        Err(PlanError::Dim { .. })
    ));
}
