//! TVLG optimizers: LQR-FLM against the Riccati optimum with dynamics fitted from samples, PI²
//! on a 2-link reacher, PILQR composition.
#![allow(clippy::needless_range_loop)]

mod common;

use common::reacher::{evaluate, objective, push_objective, Reacher};
use common::{lq_weights, quadratic_objective, riccati, LinearModel};
use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_core::seeding::rng_from_seed;
use tandem_models::{DynamicsModel, ModelInput, TvlgConfig, TvlgFit};
use tandem_planners::{
    adjust_step_mult, classic_step_mult, laplace_cost, pi2_update, pi2_update_with_temperatures,
    pi2_weights, quadratize_cost, sample_trajectories, LqrFlm, LqrFlmConfig, Objective, Pi2Config,
    Pilqr, PilqrConfig, QuadraticCost, Residual, SampleConfig, TvlgController,
};

const T: usize = 20;

/// The quadratic cost the double-integrator tests share: `Q = diag(1, 0.1)`, `R = 0.01`,
/// terminal `10 Q` (as in `lqr_flm_with_fitted_dynamics_reaches_the_lqr_cost`, which needs the
/// matrices themselves for the Riccati optimum).
fn double_integrator_objective() -> Objective {
    let (q, r, qf) = lq_weights();
    quadratic_objective(&q, &r, &qf)
}

/// Cost of the controller's mean (no action noise) on a deterministic system from `x0`.
fn mean_cost(ctrl: &TvlgController, sys: &dyn DynamicsModel, obj: &Objective, x0: &[f64]) -> f64 {
    let mut x = DVector::from_column_slice(x0);
    let mut c = 0.0;
    for t in 0..ctrl.horizon() {
        let u = ctrl.mean(t, &x);
        c += obj.running_cost(x.as_slice(), u.as_slice(), t).unwrap();
        let xs = Array2::from_shape_vec((1, x.len()), x.as_slice().to_vec()).unwrap();
        let us = Array2::from_shape_vec((1, u.len()), u.as_slice().to_vec()).unwrap();
        let y = sys
            .predict(
                &ModelInput::new(xs.view(), us.view()),
                &mut rng_from_seed(0),
            )
            .unwrap()
            .next_states;
        x = DVector::from_iterator(x.len(), y.row(0).iter().copied());
    }
    c + obj.terminal_cost(x.as_slice()).unwrap()
}

#[test]
fn lqr_flm_with_fitted_dynamics_reaches_the_lqr_cost() {
    let m = LinearModel::double_integrator();
    let (q, r, qf) = lq_weights();
    let obj = quadratic_objective(&q, &r, &qf);
    let (p, _) = riccati(&m.a, &m.b, &q, &r, &qf, T);
    let x0 = [1.0, 0.0];
    let jstar =
        (DVector::from_row_slice(&x0).transpose() * &p[0] * DVector::from_row_slice(&x0))[0];
    let sys = m.clone();
    let lqr = LqrFlm::new(LqrFlmConfig {
        kl_step: 2.0,
        ..Default::default()
    })
    .unwrap();
    let mut ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
    let mut fit = TvlgFit::new(TvlgConfig::default());
    let mut rng = rng_from_seed(1);
    let scfg = SampleConfig {
        samples: 20,
        x0_std: 0.0,
        process_std: 0.001,
    };
    let mut costs = vec![mean_cost(&ctrl, &sys, &obj, &x0)];
    for _ in 0..12 {
        let samples = sample_trajectories(&ctrl, &sys, &obj, &x0, &scfg, &mut rng).unwrap();
        let dynamics = fit
            .fit(samples.states.view(), samples.actions.view())
            .unwrap();
        let cost = quadratize_cost(&obj, &samples).unwrap();
        let step = lqr.update(&ctrl, &dynamics, &cost, None).unwrap();
        // Every step meets its bound within the tolerance.
        assert!(step.kl.iter().all(|&kl| kl <= 2.0 * 1.1), "{:?}", step.kl);
        ctrl = step.controller;
        costs.push(mean_cost(&ctrl, &sys, &obj, &x0));
    }
    println!("J* = {jstar:.5}; LQR-FLM mean costs {costs:?}");
    let last = *costs.last().unwrap();
    assert!(last >= jstar - 1e-9);
    assert!(
        last < 1.01 * jstar,
        "LQR-FLM cost {last} not within 1% of {jstar}"
    );
}

#[test]
fn pi2_improves_a_reacher_monotonically() {
    let sys = Reacher::free();
    let obj = objective([0.2, 1.2]);
    let x0 = [0.0, 0.0, 0.0, 0.0];
    let mut ctrl = TvlgController::constant(30, 4, &[0.0, 0.0], 4.0).unwrap();
    let cfg = Pi2Config::default();
    let mut rng = rng_from_seed(3);
    let mut evals = vec![evaluate(&ctrl, &sys, &obj, &x0)];
    for _ in 0..8 {
        let samples = sample_trajectories(
            &ctrl,
            &sys,
            &obj,
            &x0,
            &SampleConfig {
                samples: 30,
                ..Default::default()
            },
            &mut rng,
        )
        .unwrap();
        let step = pi2_update(
            &ctrl,
            &samples.states,
            &samples.actions,
            &samples.cost_to_go(),
            &cfg,
        )
        .unwrap();
        ctrl = step.controller;
        evals.push(evaluate(&ctrl, &sys, &obj, &x0));
    }
    println!("PI2 reacher costs {evals:?}");
    assert!(
        evals.windows(2).all(|w| w[1] < w[0]),
        "not monotone: {evals:?}"
    );
    assert!(evals.last().unwrap() < &(0.5 * evals[0]));
}

#[test]
fn pi2_temperature_meets_the_kl_bound() {
    let s: Vec<f64> = (0..50).map(|i| ((i * 37) % 11) as f64).collect();
    let (w, eta) = pi2_weights(&s, 0.5);
    let kl: f64 = w.iter().map(|v| v * (v * 50.0).ln()).sum();
    assert!((kl - 0.5).abs() < 1e-6, "KL {kl}");
    assert!(eta > 0.0 && (w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    // Lower cost, higher weight.
    assert!(w[0] > w[1]);
}

/// PILQR's step adjustment (the authors' `res_percent` rule), with the residuals restarted at every
/// sample's state ([`Residual::FromEachStep`]; `tests/pilqr.rs` covers the authors' replay from the
/// start, over which the fit's small bias accumulates): on a linear system with a quadratic
/// cost the fitted model and the quadratic cost are exact, the residual cost-to-go vanishes, and
/// every step's multiplier doubles per update (after the first, which keeps 1); with strong
/// process noise the model's mean prediction explains little of each sample's cost-to-go, the
/// residuals stay large and the multipliers halve. The comparison with LQR-FLM and PI² on the
/// pusher and the walled reacher is the `wall_reacher` example (seconds to a minute in release).
#[test]
fn pilqr_step_multipliers_follow_the_residual_ratio() {
    let m = LinearModel::double_integrator();
    let sys = m.clone();
    let x0 = [1.0, 0.0];
    let quadratic = double_integrator_objective();
    let obj = &quadratic;
    for (process_std, expect_up) in [(1e-4, true), (0.3, false)] {
        let scfg = SampleConfig {
            samples: 20,
            x0_std: 0.0,
            process_std,
        };
        let mut pilqr = Pilqr::new(PilqrConfig {
            lqr: LqrFlmConfig {
                kl_step: 0.5,
                ..Default::default()
            },
            residual: Residual::FromEachStep,
            ..Default::default()
        })
        .unwrap();
        let mut ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
        let mut fit = TvlgFit::new(TvlgConfig {
            prior: None,
            ..Default::default()
        });
        let mut rng = rng_from_seed(7);
        let mut mults = Vec::new();
        let mut ratios = Vec::new();
        for _ in 0..3 {
            let samples = sample_trajectories(&ctrl, &sys, obj, &x0, &scfg, &mut rng).unwrap();
            let dynamics = fit
                .fit(samples.states.view(), samples.actions.view())
                .unwrap();
            let step = pilqr.update(&ctrl, &samples, &dynamics, obj).unwrap();
            mults.push(step.step_mult.clone());
            ratios.push(step.residual_ratio.clone());
            ctrl = step.controller;
        }
        println!("expect_up {expect_up}: ratios {ratios:?}\nmultipliers {mults:?}");
        assert!(mults[0].iter().all(|&v| v == 1.0));
        if expect_up {
            // (The first batch, from a fixed start under an open-loop controller, excites the
            // fit less; its ratio is not used for adjustment.)
            assert!(
                ratios[1..].iter().flatten().all(|&v| v < 0.05),
                "{ratios:?}"
            );
            assert!(mults[2].iter().all(|&v| v == 4.0), "{mults:?}");
        } else {
            let mean_ratio = ratios[2].iter().sum::<f64>() / T as f64;
            assert!(mean_ratio > 0.2, "{ratios:?}");
            assert!(mults[2].iter().any(|&v| v < 1.0), "{mults:?}");
        }
        // The multipliers are the update's per-step KL bounds: the LQR stage meets them on average.
        assert_eq!(pilqr.step_mult(), &mults[2][..]);
    }
}

/// PI² at given temperatures: the temperatures the KL bound finds reproduce `pi2_update` exactly;
/// a hotter temperature moves the controller's offsets less; an infinite one weighs all samples
/// equally, so `k_t` (gains fixed) becomes the plain mean of the sampled open-loop actions.
#[test]
fn pi2_at_given_temperatures() {
    let m = LinearModel::double_integrator();
    let sys = m.clone();
    let obj = double_integrator_objective();
    let ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
    let samples = sample_trajectories(
        &ctrl,
        &sys,
        &obj,
        &[1.0, 0.0],
        &SampleConfig::default(),
        &mut rng_from_seed(2),
    )
    .unwrap();
    let s = samples.cost_to_go();
    let cfg = Pi2Config {
        update_gains: false,
        ..Default::default()
    };
    let free = pi2_update(&ctrl, &samples.states, &samples.actions, &s, &cfg).unwrap();
    let fixed = pi2_update_with_temperatures(
        &ctrl,
        &samples.states,
        &samples.actions,
        &s,
        &cfg,
        Some(&free.etas),
    )
    .unwrap();
    assert_eq!(free.controller.offsets, fixed.controller.offsets);
    let hot: Vec<f64> = free.etas.iter().map(|e| e * 100.0).collect();
    let hot = pi2_update_with_temperatures(
        &ctrl,
        &samples.states,
        &samples.actions,
        &s,
        &cfg,
        Some(&hot),
    )
    .unwrap();
    let moved = |c: &TvlgController| c.offsets.iter().map(|k| k.norm()).sum::<f64>();
    assert!(moved(&hot.controller) < moved(&free.controller));
    let inf = vec![f64::INFINITY; T];
    let uniform = pi2_update_with_temperatures(
        &ctrl,
        &samples.states,
        &samples.actions,
        &s,
        &cfg,
        Some(&inf),
    )
    .unwrap();
    let n = samples.len() as f64;
    for t in 0..T {
        let mean = samples.actions.slice(ndarray::s![.., t, 0]).sum() / n;
        assert!((uniform.controller.offsets[t][0] - mean).abs() < 1e-12);
    }
    assert!(pi2_update_with_temperatures(
        &ctrl,
        &samples.states,
        &samples.actions,
        &s,
        &cfg,
        Some(&[1.0]),
    )
    .is_err());
}

/// Covariance damping (the authors' `TrajOptPI2`): `Σ_new = Σ_old s^{1/d}` with
/// `s = tr(Σ_old⁻¹ Σ_ML)/A`. With one action and uniform weights `Σ_ML` is the plain variance of
/// the sampled actions around their mean (plus the floor), so `d = 1` gives `Σ_ML` itself and
/// `d = 2` the geometric mean `√(Σ_old Σ_ML)`.
#[test]
fn pi2_covariance_damping_scales_the_old_covariance() {
    let m = LinearModel::double_integrator();
    let sys = m.clone();
    let obj = double_integrator_objective();
    let ctrl = TvlgController::constant(T, 2, &[0.3], 1.7).unwrap();
    let samples = sample_trajectories(
        &ctrl,
        &sys,
        &obj,
        &[1.0, 0.0],
        &SampleConfig::default(),
        &mut rng_from_seed(5),
    )
    .unwrap();
    let s = samples.cost_to_go();
    let uniform = vec![f64::INFINITY; T];
    let update = |d: f64| {
        let cfg = Pi2Config {
            update_gains: false,
            covariance_damping: d,
            ..Default::default()
        };
        pi2_update_with_temperatures(
            &ctrl,
            &samples.states,
            &samples.actions,
            &s,
            &cfg,
            Some(&uniform),
        )
        .unwrap()
        .controller
    };
    let (plain, d1, d2) = (update(0.0), update(1.0), update(2.0));
    let n = samples.len() as f64;
    for t in 0..T {
        let u = samples.actions.slice(ndarray::s![.., t, 0]);
        let mean = u.sum() / n;
        let var = u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n + 1e-6;
        assert!((plain.cov[t][(0, 0)] - var).abs() < 1e-12);
        assert!((d1.cov[t][(0, 0)] - var).abs() < 1e-12);
        assert!((d2.cov[t][(0, 0)] - (1.7 * var).sqrt()).abs() < 1e-12);
    }
    let bad = Pi2Config {
        covariance_damping: -1.0,
        ..Default::default()
    };
    assert!(pi2_update(&ctrl, &samples.states, &samples.actions, &s, &bad).is_err());
}

/// PILQR's PI² stage (the authors' `use_lqr_actions` update) keeps the LQR-FLM stage's gains
/// `K̂_t` and moves only the offsets and covariances.
#[test]
fn pilqr_pi2_stage_keeps_the_lqr_gains() {
    let sys = Reacher::pusher(0.5);
    let obj = push_objective(0.8);
    let x0 = sys.x0(0.3);
    let ctrl = TvlgController::constant(30, 5, &[0.0, 0.0], 2.0).unwrap();
    let samples = sample_trajectories(
        &ctrl,
        &sys,
        &obj,
        &x0,
        &SampleConfig::default(),
        &mut rng_from_seed(0),
    )
    .unwrap();
    let dynamics = TvlgFit::new(TvlgConfig::default())
        .fit(samples.states.view(), samples.actions.view())
        .unwrap();
    let step = Pilqr::new(PilqrConfig::default())
        .unwrap()
        .update(&ctrl, &samples, &dynamics, &obj)
        .unwrap();
    assert_eq!(step.controller.gains, step.lqr.controller.gains);
    assert!(step
        .controller
        .offsets
        .iter()
        .zip(&step.lqr.controller.offsets)
        .any(|(a, b)| (a - b).norm() > 1e-6));
}

/// The pusher and hockey variants against hand-computed steps: the block stays put until link 1
/// passes it, is then carried to `q₁` while the arm loses `push_loss` of its velocity; in the
/// hockey variant it also slides on with `kick · q̇₁`, decelerated by friction.
#[test]
fn pusher_block_moves_only_in_contact() {
    let step = |sys: &Reacher, x: &[f64]| {
        let s = Array2::from_shape_vec((1, x.len()), x.to_vec()).unwrap();
        let a = Array2::zeros((1, 2));
        sys.predict(&ModelInput::new(s.view(), a.view()), &mut rng_from_seed(0))
            .unwrap()
            .next_states
            .row(0)
            .to_vec()
    };
    let push = Reacher::pusher(0.5);
    // Free: v₁' = 2 − 0.05·0.5·2 = 1.95, q₁' = 0.1 + 0.05·1.95 = 0.1975 < 0.3.
    let y = step(&push, &[0.1, 0.0, 2.0, 0.0, 0.3]);
    assert!((y[0] - 0.1975).abs() < 1e-12 && (y[2] - 1.95).abs() < 1e-12);
    assert_eq!(y[4], 0.3);
    // Contact: q₁' = 0.25 + 0.0975 = 0.3475 > 0.3 carries the block; v₁' = 1.95 · 0.5.
    let y = step(&push, &[0.25, 0.0, 2.0, 0.0, 0.3]);
    assert!((y[4] - 0.3475).abs() < 1e-12 && (y[2] - 0.975).abs() < 1e-12);
    let hockey = Reacher::hockey(0.5, 1.5);
    // Hit: the block takes 1.5 · 1.95 = 2.925 rad/s.
    let y = step(&hockey, &[0.25, 0.0, 2.0, 0.0, 0.3, 0.0]);
    assert!((y[4] - 0.3475).abs() < 1e-12 && (y[5] - 2.925).abs() < 1e-12);
    // Sliding ahead of the arm: v_b' = 2.925 − 0.05·2 = 2.825, b' = 0.5 + 0.05·2.825.
    let y = step(&hockey, &[0.0, 0.0, 0.0, 0.0, 0.5, 2.925]);
    assert!((y[5] - 2.825).abs() < 1e-12 && (y[4] - 0.64125).abs() < 1e-12);
}

/// The pusher's point (p4 Fig. 3): a controller that drives link 1 towards the block, with the
/// examples' exploration noise, reaches it at many different time steps across samples, so each
/// step's linear fit mixes contact and free motion.
#[test]
fn pusher_contact_happens_at_different_steps() {
    let sys = Reacher::pusher(0.5);
    let obj = push_objective(0.8);
    let ctrl = TvlgController::constant(30, 5, &[1.5, 0.0], 2.0).unwrap();
    let samples = sample_trajectories(
        &ctrl,
        &sys,
        &obj,
        &sys.x0(0.3),
        &SampleConfig::default(),
        &mut rng_from_seed(0),
    )
    .unwrap();
    let first_contact: Vec<Option<usize>> = (0..samples.len())
        .map(|i| (1..=30).find(|&t| samples.states[(i, t, 4)] > 0.3))
        .collect();
    let mut steps: Vec<usize> = first_contact.iter().flatten().copied().collect();
    steps.sort_unstable();
    steps.dedup();
    println!("first contact steps {first_contact:?}");
    assert!(steps.len() >= 5, "{first_contact:?}");
    assert!(steps[steps.len() - 1] - steps[0] >= 5, "{first_contact:?}");
}

/// The first iteration on the double integrator from `(1, 0)`: the quadratic objective, the
/// initial controller (`K = 0`, `k = 0`, `Σ = I`), 20 samples of it with process noise
/// `process_std` (seeded) and the TVLG dynamics fitted to them.
fn first_batch(
    process_std: f64,
    seed: u64,
) -> (
    Objective,
    TvlgController,
    tandem_planners::TrajectorySamples,
    tandem_models::TvlgDynamics,
) {
    let m = LinearModel::double_integrator();
    let obj = double_integrator_objective();
    let ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
    let scfg = SampleConfig {
        process_std,
        ..Default::default()
    };
    let samples = sample_trajectories(
        &ctrl,
        &m,
        &obj,
        &[1.0, 0.0],
        &scfg,
        &mut rng_from_seed(seed),
    )
    .unwrap();
    let dynamics = TvlgFit::new(TvlgConfig::default())
        .fit(samples.states.view(), samples.actions.view())
        .unwrap();
    (obj, ctrl, samples, dynamics)
}

/// GPS's classic step rule for LQR-FLM: when the new model agrees with the old one (same fit and
/// cost), the actual improvement equals the predicted one and the multiplier grows by the
/// maximum factor 5 (capped at 10); when the "new" controller is the old one, nothing was
/// predicted and it shrinks by the minimum factor 0.1. The expected cost the rule compares
/// (`laplace_cost`) falls with the update.
#[test]
fn classic_step_rule_on_agreeing_and_null_predictions() {
    let (obj, ctrl, samples, dynamics) = first_batch(0.01, 4);
    let cost = quadratize_cost(&obj, &samples).unwrap();
    let next = LqrFlm::new(LqrFlmConfig::default())
        .unwrap()
        .update(&ctrl, &dynamics, &cost, None)
        .unwrap()
        .controller;
    let grow = classic_step_mult(1.0, &ctrl, &dynamics, &cost, &next, &dynamics, &cost).unwrap();
    assert_eq!(grow, 5.0);
    let capped = classic_step_mult(3.0, &ctrl, &dynamics, &cost, &next, &dynamics, &cost).unwrap();
    assert_eq!(capped, 10.0);
    let shrink = classic_step_mult(1.0, &ctrl, &dynamics, &cost, &ctrl, &dynamics, &cost).unwrap();
    assert!((shrink - 0.1).abs() < 1e-12);
    assert!(classic_step_mult(0.0, &ctrl, &dynamics, &cost, &next, &dynamics, &cost).is_err());
    let (before, after) = (
        laplace_cost(&ctrl, &dynamics, &cost).unwrap(),
        laplace_cost(&next, &dynamics, &cost).unwrap(),
    );
    assert!(
        after < before,
        "LQR-FLM lowers the expected cost: {before} -> {after}"
    );
    assert!(laplace_cost(&ctrl, &dynamics, &cost[1..]).is_err());
}

/// GPS's step rule on hand-worked improvements: a model whose prediction came true (actual =
/// predicted) asks for the largest growth, 5; half the predicted improvement is the optimum of the
/// quadratic model, so the step stays; none of it halves it; a loss shrinks it by at most 0.1; the
/// multiplier stays in the caller's bounds; bad bounds, multipliers or non-finite improvements are
/// errors.
#[test]
fn step_rule_on_hand_worked_improvements() {
    let b = (0.01, 10.0);
    assert_eq!(adjust_step_mult(1.0, 2.0, 2.0, b).unwrap(), 5.0);
    assert!((adjust_step_mult(1.0, 2.0, 1.0, b).unwrap() - 1.0).abs() < 1e-12);
    assert!((adjust_step_mult(1.0, 2.0, 0.0, b).unwrap() - 0.5).abs() < 1e-12);
    // predicted 1, actual −1: 1 / (2 · 2) = 0.25.
    assert!((adjust_step_mult(2.0, 1.0, -1.0, b).unwrap() - 0.5).abs() < 1e-12);
    assert!((adjust_step_mult(1.0, 1.0, -100.0, b).unwrap() - 0.1).abs() < 1e-12);
    assert_eq!(adjust_step_mult(2.0, 2.0, 2.0, (0.5, 3.0)).unwrap(), 3.0);
    assert_eq!(adjust_step_mult(0.6, 1.0, -100.0, (0.5, 3.0)).unwrap(), 0.5);
    assert!(adjust_step_mult(1.0, 1.0, 1.0, (2.0, 1.0)).is_err());
    assert!(adjust_step_mult(1.0, 1.0, 1.0, (0.0, 1.0)).is_err());
    assert!(adjust_step_mult(-1.0, 1.0, 1.0, b).is_err());
    assert!(adjust_step_mult(1.0, f64::NAN, 1.0, b).is_err());
}

/// PILQR on a cost supplied per time step: the quadratized objective given from outside is the
/// default path, step for step; a per-step constant added to both the quadratic cost and the
/// samples' costs (`add_quadratic_costs`) changes neither the LQR step (constants do not enter
/// it) nor the PI² step (residuals and weights are shift-invariant per step); a cost of the wrong
/// length is an error.
#[test]
fn pilqr_with_an_externally_supplied_per_step_cost() {
    let (obj, ctrl, samples, dynamics) = first_batch(0.05, 2);
    let cfg = PilqrConfig {
        lqr: LqrFlmConfig {
            kl_step: 0.5,
            ..Default::default()
        },
        ..Default::default()
    };
    let default = Pilqr::new(cfg.clone())
        .unwrap()
        .update(&ctrl, &samples, &dynamics, &obj)
        .unwrap();
    let cost = quadratize_cost(&obj, &samples).unwrap();
    let supplied = Pilqr::new(cfg.clone())
        .unwrap()
        .update_with_cost(&ctrl, &samples, &dynamics, &cost)
        .unwrap();
    assert_eq!(default.controller, supplied.controller);
    assert_eq!(default.residual_ratio, supplied.residual_ratio);
    assert_eq!(default.lqr.controller, supplied.lqr.controller);

    // Shift step t by c_t = t + 1 (terminal included) in both the model cost and the samples.
    let shift: Vec<QuadraticCost> = (0..=T)
        .map(|t| {
            let d = if t < T { 3 } else { 2 };
            QuadraticCost {
                hess: DMatrix::zeros(d, d),
                grad: DVector::zeros(d),
                constant: (t + 1) as f64,
            }
        })
        .collect();
    let mut shifted_samples = samples.clone();
    shifted_samples.add_quadratic_costs(&shift).unwrap();
    assert_eq!(
        shifted_samples.costs[(3, 7)],
        samples.costs[(3, 7)] + 8.0,
        "the sample's cost at step 7 gains c_7"
    );
    let shifted_cost: Vec<QuadraticCost> = cost
        .iter()
        .zip(&shift)
        .map(|(c, s)| QuadraticCost {
            constant: c.constant + s.constant,
            ..c.clone()
        })
        .collect();
    let shifted = Pilqr::new(cfg.clone())
        .unwrap()
        .update_with_cost(&ctrl, &shifted_samples, &dynamics, &shifted_cost)
        .unwrap();
    assert_eq!(shifted.lqr.controller, default.lqr.controller);
    for t in 0..T {
        let d = (&shifted.controller.offsets[t] - &default.controller.offsets[t]).amax();
        assert!(d < 1e-9, "step {t}: {d}");
        let d = (&shifted.controller.cov[t] - &default.controller.cov[t]).amax();
        assert!(d < 1e-9, "step {t}: {d}");
    }
    // A non-constant term does change the step: a pull of the actions towards u = 2.
    let pull: Vec<QuadraticCost> = (0..=T)
        .map(|t| {
            if t < T {
                // 5 (u − 2)² in z = [x; u].
                let mut hess = DMatrix::zeros(3, 3);
                hess[(2, 2)] = 10.0;
                QuadraticCost {
                    hess,
                    grad: DVector::from_vec(vec![0.0, 0.0, -20.0]),
                    constant: 20.0,
                }
            } else {
                QuadraticCost {
                    hess: DMatrix::zeros(2, 2),
                    grad: DVector::zeros(2),
                    constant: 0.0,
                }
            }
        })
        .collect();
    let mut pulled_samples = samples.clone();
    pulled_samples.add_quadratic_costs(&pull).unwrap();
    let u = samples.actions[(0, 0, 0)];
    assert!(
        (pulled_samples.costs[(0, 0)] - samples.costs[(0, 0)] - 5.0 * (u - 2.0).powi(2)).abs()
            < 1e-12
    );
    let pulled_cost: Vec<QuadraticCost> = cost
        .iter()
        .zip(&pull)
        .map(|(c, p)| QuadraticCost {
            hess: &c.hess + &p.hess,
            grad: &c.grad + &p.grad,
            constant: c.constant + p.constant,
        })
        .collect();
    let pulled = Pilqr::new(cfg.clone())
        .unwrap()
        .update_with_cost(&ctrl, &pulled_samples, &dynamics, &pulled_cost)
        .unwrap();
    let mean_offset = |c: &TvlgController| c.offsets.iter().map(|k| k[0]).sum::<f64>() / T as f64;
    assert!(
        mean_offset(&pulled.lqr.controller) > mean_offset(&default.lqr.controller) + 0.1,
        "{} vs {}",
        mean_offset(&pulled.lqr.controller),
        mean_offset(&default.lqr.controller)
    );
    assert!(Pilqr::new(cfg)
        .unwrap()
        .update_with_cost(&ctrl, &samples, &dynamics, &cost[..T])
        .is_err());
    assert!(shifted_samples.add_quadratic_costs(&shift[..T]).is_err());
}

/// A controller read back from JSON equals the one written, factors included (a resumed run
/// samples with them); covariances that are not positive definite are refused on reading.
#[test]
fn a_controller_round_trips_through_json_and_bad_covariances_are_refused() {
    let t = 4;
    let gains = (0..t)
        .map(|i| DMatrix::from_fn(2, 3, |r, c| 0.1 * (i + r) as f64 - 0.3 * c as f64))
        .collect();
    let offsets = (0..t)
        .map(|i| DVector::from_vec(vec![0.7 / (i + 1) as f64, -0.2]))
        .collect();
    // Not exactly symmetric on input: the controller keeps the symmetric part.
    let cov = (0..t)
        .map(|i| DMatrix::from_row_slice(2, 2, &[1.3 + i as f64, 0.1, 0.1 + 1e-13, 0.7]))
        .collect();
    let c = TvlgController::new(gains, offsets, cov).unwrap();
    let text = serde_json::to_string(&c).unwrap();
    let back: TvlgController = serde_json::from_str(&text).unwrap();
    assert_eq!(back, c);
    assert_eq!(back.chol(2), c.chol(2));
    assert_eq!(back.inv_cov(3), c.inv_cov(3));
    let mut bad: serde_json::Value = serde_json::from_str(&text).unwrap();
    let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
    bad["cov"][1] = serde_json::to_value(indefinite).unwrap();
    let e = serde_json::from_value::<TvlgController>(bad).unwrap_err();
    assert!(e.to_string().contains("positive definite"), "{e}");
}
