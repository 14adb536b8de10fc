//! MPC planners on a linear system with quadratic cost (truth: the Riccati solution), a pendulum,
//! and bad inputs.

#![allow(clippy::needless_range_loop)]

mod common;

use common::{lq_weights, quadratic_objective, riccati, LinearModel, PendulumModel};
use nalgebra::{DMatrix, DVector};
use ndarray::{Array1, Array2};
use tandem_models::DynamicsModel;
use tandem_planners::{
    Bounds, Cem, CemConfig, DmdMpc, DmdMpcConfig, Knots, Mppi, MppiConfig, Noise, Objective,
    PlanError, Planner, Utility,
};

const H: usize = 15;

fn lqr_problem() -> (LinearModel, Objective, f64, Vec<f64>) {
    let m = LinearModel::double_integrator();
    let (q, r, qf) = lq_weights();
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

/// The three planners with noise drawn at knots (held or interpolated) built for the bounded LQR
/// problem.
fn knotted(knots: Knots, seed: u64, b: &Bounds) -> Vec<Box<dyn Planner>> {
    vec![
        Box::new(
            Cem::new(CemConfig {
                horizon: H,
                population: 100,
                iterations: 4,
                init_std: Some(vec![2.0]),
                knots,
                bounds: Some(b.clone()),
                seed,
                ..Default::default()
            })
            .unwrap(),
        ),
        Box::new(
            Mppi::new(MppiConfig {
                horizon: H,
                samples: 100,
                iterations: 4,
                lambda: 0.05,
                noise: Noise::Isotropic(2.0),
                knots,
                bounds: Some(b.clone()),
                seed,
                ..Default::default()
            })
            .unwrap(),
        ),
        Box::new(
            DmdMpc::new(DmdMpcConfig {
                horizon: H,
                samples: 100,
                iterations: 4,
                noise: Noise::Isotropic(2.0),
                adapt_covariance: true,
                knots,
                bounds: Some(b.clone()),
                seed,
                ..Default::default()
            })
            .unwrap(),
        ),
    ]
}

/// Noise at knots (every 4 steps held, every 3 steps interpolated): every plan stays within the
/// bounds and never beats the LQR optimum, equal seeds give equal actions, different seeds differ.
#[test]
fn knotted_noise_keeps_bounds_and_determinism() {
    let (m, obj, jstar, _) = lqr_problem();
    let b = Bounds::new(vec![-0.8], vec![0.5]);
    let x0 = [1.0, 0.0];
    for knots in [Knots::hold(4), Knots::linear(3)] {
        let run = |seed: u64| -> Vec<(Array2<f64>, f64)> {
            knotted(knots, seed, &b)
                .into_iter()
                .flat_map(|mut p| {
                    (0..3)
                        .map(|_| {
                            let plan = p.plan(&x0, &m, &obj).unwrap();
                            (plan.actions, plan.total_cost)
                        })
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let (a, a2, c) = (run(5), run(5), run(6));
        assert_eq!(a, a2);
        assert_ne!(a, c);
        for (acts, cost) in &a {
            assert!(acts.iter().all(|u| (-0.8..=0.5).contains(u)), "{knots:?}");
            assert!(*cost >= jstar - 1e-9);
        }
    }
}

/// With held knots every 3 steps and a cold start, every sample is constant over blocks of 3
/// steps, and so is every update: one plan's cost falls to the optimum over block-constant
/// sequences (move blocking), found here in closed form by least squares on the stacked linear
/// dynamics `X = Φ x0 + Γ E v`, and stays above it (and above the unblocked LQR optimum).
#[test]
fn held_knots_reach_the_move_blocked_optimum() {
    let (m, obj, jstar, _) = lqr_problem();
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1]));
    let (r, qf) = (0.01, &q * 10.0);
    let (s_dim, spacing) = (2, 3);
    let k_blocks = H.div_ceil(spacing);
    // Stacked states x_0 .. x_H = Φ x0 + Γ u and the block-to-step map E (u = E v).
    let x0 = DVector::from_vec(vec![1.0, 0.0]);
    let mut phi = DMatrix::zeros((H + 1) * s_dim, s_dim);
    let mut gamma = DMatrix::zeros((H + 1) * s_dim, H);
    let mut at = DMatrix::identity(s_dim, s_dim);
    for t in 0..=H {
        phi.view_mut((t * s_dim, 0), (s_dim, s_dim)).copy_from(&at);
        for j in 0..t {
            let mut blk = m.b.clone();
            for _ in 0..(t - 1 - j) {
                blk = &m.a * blk;
            }
            gamma.view_mut((t * s_dim, j), (s_dim, 1)).copy_from(&blk);
        }
        at = &m.a * at;
    }
    let mut qbar = DMatrix::zeros((H + 1) * s_dim, (H + 1) * s_dim);
    for t in 0..=H {
        let w = if t == H { &qf } else { &q };
        qbar.view_mut((t * s_dim, t * s_dim), (s_dim, s_dim))
            .copy_from(w);
    }
    let e = DMatrix::from_fn(H, k_blocks, |t, k| if t / spacing == k { 1.0 } else { 0.0 });
    let ge = &gamma * &e;
    let hess = ge.transpose() * &qbar * &ge + e.transpose() * &e * r;
    let grad = ge.transpose() * &qbar * &phi * &x0;
    let v = -hess.cholesky().unwrap().solve(&grad);
    let xs = &phi * &x0 + &ge * &v;
    let u = &e * &v;
    let jblock = (xs.transpose() * &qbar * &xs)[0] + r * u.norm_squared();
    assert!(jblock > jstar * 1.001, "blocking should cost something");
    let knots = Knots::hold(spacing);
    type Make = fn(usize, Knots) -> Box<dyn Planner>;
    let makers: [(&str, Make, usize); 3] = [
        (
            "cem",
            |i, k| {
                Box::new(
                    Cem::new(CemConfig {
                        knots: k,
                        ..cem(i, 3).config().clone()
                    })
                    .unwrap(),
                )
            },
            12,
        ),
        (
            "mppi",
            |i, k| {
                Box::new(
                    Mppi::new(MppiConfig {
                        knots: k,
                        ..mppi(i, 3).config().clone()
                    })
                    .unwrap(),
                )
            },
            30,
        ),
        (
            "dmd",
            |i, k| {
                Box::new(
                    DmdMpc::new(DmdMpcConfig {
                        knots: k,
                        ..dmd(i, 3).config().clone()
                    })
                    .unwrap(),
                )
            },
            20,
        ),
    ];
    for (name, make, many) in makers {
        let plan = make(many, knots).plan(x0.as_slice(), &m, &obj).unwrap();
        let cost = plan.total_cost;
        println!("{name}: block optimum {jblock:.5} (LQR {jstar:.5}), plan {cost:.5}");
        for t in 0..H {
            if t % spacing != 0 {
                assert!((plan.actions[(t, 0)] - plan.actions[(t - 1, 0)]).abs() < 1e-12);
            }
        }
        assert!(cost >= jblock - 1e-9, "{name} beat the blocked optimum");
        assert!(
            cost < 1.03 * jblock,
            "{name}: {cost} not within 3% of {jblock}"
        );
    }
}

/// With the critic's value of the remaining LQR problem as terminal value, a 3-step plan picks
/// the first action of the 15-step optimum (p3's terminal cost −V).
#[test]
fn terminal_value_extends_the_horizon() {
    let m = LinearModel::double_integrator();
    let (q, r, qf) = lq_weights();
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
            .running_cost(xs.as_slice(), &[tr.actions[(h, 0)]], h)
            .unwrap();
        assert!((tr.rewards[h] + c).abs() < 1e-12);
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

/// Planning from several starts at once: one start is bit for bit the single call of a fresh
/// planner; with a vanishing step each plan is the policy's rollout from its own start; with
/// a full step every start's plan improves on its policy rollout, as its single call does.
#[test]
fn dmd_batch_plans_are_independent_plans() {
    let (m, obj, _, _) = lqr_problem();
    // A deliberately poor linear policy, so the planner has something to improve.
    let policy = |s: ndarray::ArrayView2<'_, f64>| {
        Array2::from_shape_fn((s.nrows(), 1), |(i, _)| {
            -(0.3 * s[(i, 0)] + 0.2 * s[(i, 1)])
        })
    };
    let planner = |step_size: f64, seed: u64| {
        DmdMpc::new(DmdMpcConfig {
            horizon: H,
            samples: 64,
            step_size,
            noise: Noise::Isotropic(0.5),
            seed,
            ..Default::default()
        })
        .unwrap()
    };
    let starts = ndarray::arr2(&[[1.0, 0.0], [-0.5, 0.3], [0.2, -1.0]]);

    let one = planner(0.8, 4)
        .plan_with_proposal(&[-0.5, 0.3], &m, &obj, &policy)
        .unwrap();
    let batch = planner(0.8, 4)
        .plan_batch_with_proposal(starts.slice(ndarray::s![1..2, ..]), &m, &obj, &policy)
        .unwrap();
    assert_eq!(batch.len(), 1);
    assert_eq!(batch[0].actions, one.actions);
    assert_eq!(batch[0].states, one.states);
    assert_eq!(batch[0].total_cost, one.total_cost);

    let tiny = planner(1e-9, 5)
        .plan_batch_with_proposal(starts.view(), &m, &obj, &policy)
        .unwrap();
    let full = planner(1.0, 6)
        .plan_batch_with_proposal(starts.view(), &m, &obj, &policy)
        .unwrap();
    assert_eq!((tiny.len(), full.len()), (3, 3));
    for (k, x0) in starts.rows().into_iter().enumerate() {
        let mut x = DVector::from_vec(x0.to_vec());
        assert_eq!(tiny[k].states.row(0), x0);
        for h in 0..H {
            let u = -(0.3 * x[0] + 0.2 * x[1]);
            assert!(
                (tiny[k].actions[(h, 0)] - u).abs() < 1e-6,
                "start {k} step {h}"
            );
            x = m.step(&x, &DVector::from_vec(vec![u]));
        }
        // The elite mean of 64 samples beats the policy's own rollout from every start.
        assert!(
            full[k].total_cost < tiny[k].total_cost,
            "start {k}: {} vs the policy's {}",
            full[k].total_cost,
            tiny[k].total_cost
        );
        let single = planner(1.0, 6)
            .plan_with_proposal(&x0.to_vec(), &m, &obj, &policy)
            .unwrap();
        assert!(single.total_cost < tiny[k].total_cost);
    }

    // Bad shapes are errors, not panics.
    let bad = ndarray::arr2(&[[1.0, 0.0, 0.0]]);
    assert!(planner(0.8, 4)
        .plan_batch_with_proposal(bad.view(), &m, &obj, &policy)
        .is_err());
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
    assert!(matches!(
        Mppi::new(MppiConfig {
            knots: Knots::hold(0),
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
