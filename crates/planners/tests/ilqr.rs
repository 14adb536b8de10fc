//! iLQR: exact on linear-quadratic problems (Riccati truth), bounds, finite-difference Jacobians,
//! pendulum swing-up as MPC.
#![allow(clippy::needless_range_loop)]

mod common;

use common::{lq_weights, quadratic_objective, riccati, LinearModel, PendulumModel};
use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_core::seeding::rng_from_seed;
use tandem_models::{DynamicsModel, ModelInput};
use tandem_planners::{Bounds, Ilqr, IlqrConfig, Objective, PlanError, Planner};

const T: usize = 20;

fn problem() -> (LinearModel, Objective, DMatrix<f64>, Vec<DMatrix<f64>>) {
    let m = LinearModel::double_integrator();
    let (q, r, qf) = lq_weights();
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
    let sol = ilqr
        .solve(&m, &obj, x0.as_slice(), &Array2::zeros((T, 1)))
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
    let xs = Array2::from_shape_vec((2, 2), vec![1.0, 2.0, -30.0, 0.1]).unwrap();
    let us = Array2::from_shape_vec((2, 2), vec![0.0, 5.0, 1.0, 1.0]).unwrap();
    let lin = m
        .linearize(
            &ModelInput::new(xs.view(), us.view()),
            &mut rng_from_seed(0),
        )
        .unwrap();
    assert_eq!(lin.len(), 2);
    for l in lin {
        assert!((l.a - &m.a).abs().max() < 1e-7);
        assert!((l.b - &m.b).abs().max() < 1e-7);
    }
}

#[test]
fn bounds_hold_and_beat_clamping_the_unbounded_solution() {
    let (m, obj, _, _) = problem();
    let x0 = [3.0, 0.0];
    let free = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&m, &obj, &x0, &Array2::zeros((T, 1)))
        .unwrap();
    let b = Bounds::symmetric(1, 2.0);
    let bounded = Ilqr::new(IlqrConfig {
        bounds: Some(b.clone()),
        ..Default::default()
    })
    .unwrap()
    .solve(&m, &obj, &x0, &Array2::zeros((T, 1)))
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
        c += obj.running_cost(x.as_slice(), &[u], t).unwrap();
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
    assert!(matches!(
        ilqr.solve(&m, &obj, &[1.0], &Array2::zeros((5, 1))),
        Err(PlanError::Dim { .. })
    ));
    assert!(matches!(
        ilqr.solve(&m, &obj, &[1.0, 0.0], &Array2::zeros((5, 2))),
        Err(PlanError::Dim { .. })
    ));
    assert!(matches!(
        ilqr.solve(&m, &obj, &[1.0, 0.0], &Array2::zeros((0, 1))),
        Err(PlanError::Config(_))
    ));
    let nan = Objective::new(2, 1, |x, _| if x[0] < 0.99 { f64::NAN } else { 0.0 });
    assert!(matches!(
        ilqr.solve(&m, &nan, &[1.0, 0.0], &Array2::from_elem((5, 1), -1.0)),
        Err(PlanError::NonFiniteCost { .. })
    ));
}

/// A time-varying cost: track `r_t = (sin 0.3t, 0)` with `(x − r_t)ᵀ Q (x − r_t) + uᵀ R u` on the
/// double integrator, terminal `(x − r_T)ᵀ Q_f (x − r_T)`. iLQR (exact on linear-quadratic
/// problems) must give the actions of the hand-rolled affine Riccati recursion:
/// `V_t(x) = xᵀ P_t x − 2 s_tᵀ x + const`, `u_t = −K_t x + k_t`,
/// `K_t = (R + BᵀP B)⁻¹ BᵀP A`, `k_t = (R + BᵀP B)⁻¹ Bᵀ s`,
/// `P_t = Q + AᵀP A − AᵀP B K_t`, `s_t = Q r_t + (A − B K_t)ᵀ s` (with `P, s` of step `t + 1`).
#[test]
fn time_varying_tracking_cost_matches_the_affine_riccati_recursion() {
    let m = LinearModel::double_integrator();
    let (q, r, qf) = lq_weights();
    let target = |t: usize| DVector::from_vec(vec![(0.3 * t as f64).sin(), 0.0]);
    let (q2, r2, qf2) = (q.clone(), r.clone(), qf.clone());
    let obj = Objective::time_varying(2, 1, move |x, u, t| {
        let e = DVector::from_column_slice(x) - target(t);
        (e.transpose() * &q2 * &e)[0] + r2[(0, 0)] * u[0] * u[0]
    })
    .with_terminal(move |x| {
        let e = DVector::from_column_slice(x) - target(T);
        (e.transpose() * &qf2 * &e)[0]
    });
    // Hand-rolled backward recursion.
    let (a, b) = (&m.a, &m.b);
    let mut p = qf.clone();
    let mut s = &qf * target(T);
    let mut gains = vec![(DMatrix::zeros(1, 2), DVector::zeros(1)); T];
    for t in (0..T).rev() {
        let h = (&r + b.transpose() * &p * b).try_inverse().unwrap();
        let k = &h * b.transpose() * &p * a;
        let kff = &h * b.transpose() * &s;
        let p_next = &q + a.transpose() * &p * a - a.transpose() * &p * b * &k;
        s = &q * target(t) + (a - b * &k).transpose() * &s;
        p = p_next;
        gains[t] = (k, kff);
    }
    let x0 = [0.5, 0.0];
    let sol = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&m, &obj, &x0, &Array2::zeros((T, 1)))
        .unwrap();
    let mut x = DVector::from_row_slice(&x0);
    let mut moved = 0.0f64;
    for t in 0..T {
        let u = -(&gains[t].0 * &x)[0] + gains[t].1[0];
        assert!(
            (sol.actions[(t, 0)] - u).abs() < 1e-5 * (1.0 + u.abs()),
            "step {t}: {} vs {u}",
            sol.actions[(t, 0)]
        );
        moved = moved.max(gains[t].1[0].abs());
        x = m.step(&x, &DVector::from_vec(vec![u]));
    }
    // The feedforward terms matter: the target moves.
    assert!(moved > 1.0, "{moved}");
    // The same cost with the target frozen at r_0 gives another plan.
    let frozen = Objective::time_varying(2, 1, move |x, u, _| {
        let e = DVector::from_column_slice(x) - target(0);
        (e.transpose() * &q * &e)[0] + r[(0, 0)] * u[0] * u[0]
    });
    let other = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&m, &frozen, &x0, &Array2::zeros((T, 1)))
        .unwrap();
    assert!((other.actions[(3, 0)] - sol.actions[(3, 0)]).abs() > 1e-2);
}
