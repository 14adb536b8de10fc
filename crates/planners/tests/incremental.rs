//! Planning through p1's incremental model, a model of `y = [x; u_prev]`:
//! `y' = [x + L (u − u_prev); u]`. With a known `L` (the prior of an unfitted model, exactly `L0`)
//! it is a linear system, so every planner must give the same plan through it as through that
//! system written by hand, and iLQR must reach the system's Riccati optimum.
#![allow(clippy::needless_range_loop)]

mod common;

use common::{lq_weights, quadratic_objective, riccati};
use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_core::Rng;
use tandem_models::{
    DynamicsModel, FitConfig, FitReport, IncrementalModel, IncrementalModelConfig, ModelError,
    ModelInput, Prediction, Transitions,
};
use tandem_planners::{
    Cem, CemConfig, DmdMpc, DmdMpcConfig, Ilqr, IlqrConfig, Mppi, MppiConfig, Noise, Objective,
    PlanError, Planner,
};

const DT: f64 = 0.1;
const H: usize = 12;

/// `L`: a double integrator's input matrix.
fn gain() -> [f64; 2] {
    [0.5 * DT * DT, DT]
}

fn incremental() -> IncrementalModel {
    IncrementalModel::new(
        2,
        1,
        IncrementalModelConfig {
            hidden: vec![8],
            prior_gain: Some(gain().to_vec()),
            ..Default::default()
        },
    )
    .unwrap()
}

/// The same system written by hand: `y' = [x + L (u − y₂); u]`, computed in the incremental
/// model's order of operations so that rollouts agree bit for bit.
struct Augmented;

impl DynamicsModel for Augmented {
    fn state_dim(&self) -> usize {
        3
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let (s, a) = (input.states, input.actions);
        let l = gain();
        let next = Array2::from_shape_fn((s.nrows(), 3), |(r, i)| {
            let du = a[(r, 0)] - s[(r, 2)];
            if i < 2 {
                s[(r, i)] + [l[i] * du].into_iter().sum::<f64>()
            } else {
                a[(r, 0)]
            }
        });
        Ok(Prediction::deterministic(next))
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

/// The quadratic cost on `x`, as a cost on `y = [x; u_prev]` (blind to `u_prev`).
fn objective() -> Objective {
    let (q, r, qf) = lq_weights();
    let full = quadratic_objective(&q, &r, &qf);
    let full_t = quadratic_objective(&q, &r, &qf);
    Objective::new(3, 1, move |y, u| full.running_cost(&y[..2], u, 0).unwrap())
        .with_terminal(move |y| full_t.terminal_cost(&y[..2]).unwrap())
}

fn planners() -> Vec<(&'static str, Box<dyn Planner>)> {
    vec![
        (
            "cem",
            Box::new(
                Cem::new(CemConfig {
                    horizon: H,
                    population: 60,
                    iterations: 3,
                    seed: 3,
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
        (
            "mppi",
            Box::new(
                Mppi::new(MppiConfig {
                    horizon: H,
                    samples: 60,
                    lambda: 0.1,
                    iterations: 2,
                    noise: Noise::Isotropic(0.5),
                    seed: 4,
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
        (
            "dmd",
            Box::new(
                DmdMpc::new(DmdMpcConfig {
                    horizon: H,
                    samples: 60,
                    iterations: 2,
                    seed: 5,
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
        (
            "ilqr",
            Box::new(
                Ilqr::new(IlqrConfig {
                    horizon: H,
                    ..Default::default()
                })
                .unwrap(),
            ),
        ),
    ]
}

#[test]
fn every_planner_plans_through_the_incremental_model_as_through_the_system_by_hand() {
    let inc = incremental();
    assert_eq!(inc.state_dim(), 3);
    let obj = objective();
    let y0 = [1.0, -0.5, 0.7];
    for ((name, mut p), (_, mut q)) in planners().into_iter().zip(planners()) {
        // Three receding-horizon calls: the warm start and the previous action move on.
        let mut y = y0.to_vec();
        for call in 0..3 {
            let ip = p.plan(&y, &inc, &obj).unwrap();
            let plan = q.plan(&y, &Augmented, &obj).unwrap();
            // iLQR's finite-difference Jacobians differ in rounding between the two models (and
            // its stopping test acts on that difference); the sampling planners see identical
            // rollouts.
            let tol = if name == "ilqr" { 1e-5 } else { 0.0 };
            for h in 0..H {
                let d = (plan.actions[(h, 0)] - ip.actions[(h, 0)]).abs();
                assert!(d <= tol, "{name}, call {call}, step {h}: {d}");
                for i in 0..2 {
                    let d = (plan.states[(h + 1, i)] - ip.states[(h + 1, i)]).abs();
                    assert!(d <= tol.max(1e-12), "{name}, call {call}, state {h}: {d}");
                }
                // The state carries the action just applied.
                assert_eq!(ip.states[(h + 1, 2)], ip.actions[(h, 0)]);
            }
            assert!((plan.total_cost - ip.total_cost).abs() <= tol.max(1e-12) * ip.total_cost);
            assert_eq!(ip.transitions().states[(0, 2)], y[2]);
            // The next call starts where the incremental planner's loop went.
            y = ip.states.row(1).to_vec();
        }
    }
}

#[test]
fn ilqr_through_the_incremental_model_reaches_the_riccati_optimum() {
    let inc = incremental();
    let obj = objective();
    let (q, r, qf) = lq_weights();
    let l = gain();
    // y' = A y + B u with y = [x; u_prev].
    let a = DMatrix::from_row_slice(3, 3, &[1.0, 0.0, -l[0], 0.0, 1.0, -l[1], 0.0, 0.0, 0.0]);
    let b = DMatrix::from_row_slice(3, 1, &[l[0], l[1], 1.0]);
    let pad = |m: &DMatrix<f64>| {
        let mut p = DMatrix::zeros(3, 3);
        p.view_mut((0, 0), (2, 2)).copy_from(m);
        p
    };
    let (p, k) = riccati(&a, &b, &pad(&q), &r, &pad(&qf), H);
    let y0 = DVector::from_vec(vec![1.0, -0.5, 0.7]);
    let jstar = (y0.transpose() * &p[0] * &y0)[0];
    let sol = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&inc, &obj, y0.as_slice(), &Array2::zeros((H, 1)))
        .unwrap();
    assert!(
        (sol.cost - jstar).abs() < 1e-7 * jstar,
        "{} vs {jstar}",
        sol.cost
    );
    // The optimal actions u_t = −K_t y_t, and the feedback on both parts of the state.
    let mut y = y0.clone();
    for t in 0..H {
        let u = -(&k[t] * &y)[0];
        assert!((sol.actions[(t, 0)] - u).abs() < 1e-5, "step {t}");
        for j in 0..3 {
            assert!(
                (sol.gains[t][(0, j)] + k[t][(0, j)]).abs() < 1e-4 * (1.0 + k[t][(0, j)].abs())
            );
        }
        y = &a * &y + &b * u;
    }
    // Ignoring the previous action (planning as if it were zero) gives another, worse plan.
    let zero = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(&inc, &obj, &[1.0, -0.5, 0.0], &Array2::zeros((H, 1)))
        .unwrap();
    assert!((zero.actions[(0, 0)] - sol.actions[(0, 0)]).abs() > 1e-3);
}

#[test]
fn a_start_without_its_previous_action_is_an_error() {
    let inc = incremental();
    let obj = objective();
    for (name, mut p) in planners() {
        let err = p.plan(&[1.0, 0.0], &inc, &obj).unwrap_err();
        assert!(matches!(err, PlanError::Dim { .. }), "{name}: {err:?}");
        assert!(matches!(
            p.plan(&[1.0, 0.0, f64::NAN], &inc, &obj),
            Err(PlanError::NonFinite(_))
        ));
    }
}
