//! iLQR: exact on linear-quadratic problems (Riccati truth), bounds, finite-difference Jacobians,
//! pendulum swing-up as MPC.
#![allow(clippy::needless_range_loop)]

mod common;

use common::{quadratic_objective, riccati, LinearModel, PendulumModel};
use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_planners::{
    Bounds, Dynamics, Ilqr, IlqrConfig, ModelDynamics, Objective, PlanError, Planner,
};

const T: usize = 20;

fn problem() -> (LinearModel, Objective, DMatrix<f64>, Vec<DMatrix<f64>>) {
    let m = LinearModel::double_integrator();
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
    let r = DMatrix::from_element(1, 1, 0.01);
    let qf = &q * 10.0;
    let obj = quadratic_objective(&q, &r, &qf);
    let (p, k) = riccati(&m.a, &m.b, &q, &r, &qf, T);
    (m, obj, p[0].clone(), k)
}

#[test]
fn linear_quadratic_is_solved_exactly_with_riccati_gains() {
    let (m, obj, p0, k) = problem();
    let x0 = DVector::from_vec(vec![1.0, -0.5]);
    let jstar = (x0.transpose() * &p0 * &x0)[0];
    let ilqr = Ilqr::new(IlqrConfig::default()).unwrap();
    let dynamics = ModelDynamics::new(&m, 0);
    let sol = ilqr
        .solve(&dynamics, &obj, x0.as_slice(), &Array2::zeros((T, 1)))
        .unwrap();
    assert!(
        (sol.cost - jstar).abs() < 1e-6 * jstar,
        "{} vs {jstar}",
        sol.cost
    );
    assert!(
        sol.converged && sol.iterations <= 3,
        "{} iterations",
        sol.iterations
    );
    for t in 0..T {
        // u = ū + K (x − x̄) with K = −K_riccati.
        for j in 0..2 {
            assert!(
                (sol.gains[t][(0, j)] + k[t][(0, j)]).abs() < 1e-4 * (1.0 + k[t][(0, j)].abs())
            );
        }
    }
    // Costs fall monotonically.
    assert!(sol.cost_history.windows(2).all(|w| w[1] <= w[0]));
}

#[test]
fn finite_difference_jacobians_of_a_model() {
    let m = LinearModel {
        a: DMatrix::from_row_slice(2, 2, &[0.9, 0.2, -0.1, 1.1]),
        b: DMatrix::from_row_slice(2, 2, &[0.5, 0.0, 0.3, -2.0]),
    };
    let d = ModelDynamics::new(&m, 0);
    let xs = Array2::from_shape_vec((2, 2), vec![1.0, 2.0, -30.0, 0.1]).unwrap();
    let us = Array2::from_shape_vec((2, 2), vec![0.0, 5.0, 1.0, 1.0]).unwrap();
    for (a, b) in d.jacobians(xs.view(), us.view()).unwrap() {
        assert!((a - &m.a).abs().max() < 1e-7);
        assert!((b - &m.b).abs().max() < 1e-7);
    }
}

#[test]
fn bounds_hold_and_beat_clamping_the_unbounded_solution() {
    let (m, obj, _, _) = problem();
    let x0 = [3.0, 0.0];
    let d = ModelDynamics::new(&m, 0);
    let free = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&d, &obj, &x0, &Array2::zeros((T, 1)))
        .unwrap();
    let b = Bounds::symmetric(1, 2.0);
    let bounded = Ilqr::new(IlqrConfig {
        bounds: Some(b.clone()),
        ..Default::default()
    })
    .unwrap()
    .solve(&d, &obj, &x0, &Array2::zeros((T, 1)))
    .unwrap();
    assert!(
        free.actions.iter().any(|u| u.abs() > 2.5),
        "bounds must matter in this test"
    );
    assert!(bounded.actions.iter().all(|u| u.abs() <= 2.0 + 1e-12));
    // Clamping the unbounded optimum open loop is feasible but worse.
    let mut clamped = free.actions.clone();
    b.clamp_rows(clamped.view_mut());
    let mut x = DVector::from_row_slice(&x0);
    let mut c = 0.0;
    for t in 0..T {
        let u = clamped[(t, 0)];
        c += obj.running_cost(x.as_slice(), &[u]).unwrap();
        x = m.step(&x, &DVector::from_vec(vec![u]));
    }
    c += obj.terminal_cost(x.as_slice()).unwrap();
    assert!(
        bounded.cost <= c + 1e-9,
        "bounded {} vs clamped {c}",
        bounded.cost
    );
    assert!(bounded.cost >= free.cost);
}

fn smooth_pendulum_objective() -> Objective {
    // 10 (1 − cos φ) ≈ 5 φ² near upright, smooth everywhere (the wrapped φ² jumps at ±π).
    Objective::new(2, 1, |x, u| {
        10.0 * (1.0 - x[0].cos()) + 0.1 * x[1] * x[1] + 0.01 * u[0] * u[0]
    })
}

/// The test pendulum with a stronger motor (|u| <= 5, half the gravity torque) swings up within
/// the 3 s horizon.
#[test]
fn ilqr_mpc_swings_up_and_holds_a_pendulum() {
    let mut p = Ilqr::new(IlqrConfig {
        horizon: 60,
        max_iterations: 30,
        init_std: 0.1,
        bounds: Some(Bounds::symmetric(1, 5.0)),
        ..Default::default()
    })
    .unwrap();
    let obj = smooth_pendulum_objective();
    let mut x = [std::f64::consts::PI, 0.0];
    let mut worst: f64 = 0.0;
    for t in 0..150 {
        let u = p.plan(&x, &PendulumModel, &obj).unwrap().first_action()[0];
        assert!(u.abs() <= 5.0);
        x = PendulumModel::step(&x, u);
        if t >= 100 {
            let phi = (x[0] + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            worst = worst.max(phi.abs());
        }
    }
    assert!(worst < 0.05, "max |phi| over the last 50 steps {worst}");
}

#[test]
fn seeds_and_errors() {
    let (m, obj, _, _) = problem();
    let cfg = IlqrConfig {
        horizon: 10,
        init_std: 0.5,
        max_iterations: 1,
        ..Default::default()
    };
    let a = Ilqr::new(cfg.clone())
        .unwrap()
        .plan(&[1.0, 0.0], &m, &obj)
        .unwrap()
        .actions;
    let b = Ilqr::new(cfg.clone())
        .unwrap()
        .plan(&[1.0, 0.0], &m, &obj)
        .unwrap()
        .actions;
    let c = Ilqr::new(IlqrConfig { seed: 1, ..cfg })
        .unwrap()
        .plan(&[1.0, 0.0], &m, &obj)
        .unwrap()
        .actions;
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert!(matches!(
        Ilqr::new(IlqrConfig {
            horizon: 0,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    assert!(matches!(
        Ilqr::new(IlqrConfig {
            mu_factor: 0.5,
            ..Default::default()
        }),
        Err(PlanError::Config(_))
    ));
    let ilqr = Ilqr::new(IlqrConfig::default()).unwrap();
    let d = ModelDynamics::new(&m, 0);
    assert!(matches!(
        ilqr.solve(&d, &obj, &[1.0], &Array2::zeros((5, 1))),
        Err(PlanError::Dim { .. })
    ));
    assert!(matches!(
        ilqr.solve(&d, &obj, &[1.0, 0.0], &Array2::zeros((5, 2))),
        Err(PlanError::Dim { .. })
    ));
    assert!(matches!(
        ilqr.solve(&d, &obj, &[1.0, 0.0], &Array2::zeros((0, 1))),
        Err(PlanError::Config(_))
    ));
    let nan = Objective::new(2, 1, |x, _| if x[0] < 0.99 { f64::NAN } else { 0.0 });
    assert!(matches!(
        ilqr.solve(&d, &nan, &[1.0, 0.0], &Array2::from_elem((5, 1), -1.0)),
        Err(PlanError::NonFiniteCost { .. })
    ));
}
