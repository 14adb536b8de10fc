//! PILQR's residuals and step bounds as the authors' GPS code computes them: model costs from a
//! replay of each sample's noise from the mean start (`approximated_cost`), the per-step residual
//! ratio over the remaining steps, and bounds linear over the steps.

mod common;

use common::{lq_weights, quadratic_objective, LinearModel};
use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, Array3};
use tandem_core::seeding::rng_from_seed;
use tandem_models::{TvlgConfig, TvlgDynamics, TvlgFit};
use tandem_planners::{
    model_costs, sample_trajectories, LqrFlmConfig, Objective, PerStep, Pilqr, PilqrConfig,
    QuadraticCost, Residual, SampleConfig, TrajectorySamples, TvlgController,
};

const T: usize = 20;

fn double_integrator_objective() -> Objective {
    let (q, r, qf) = lq_weights();
    quadratic_objective(&q, &r, &qf)
}

/// On a scalar system the model costs are the recursion written out by hand: `x̂_0 = x̄_0`,
/// `û_t = K x̂_t + k + σ ξ_{i,t}`, `ĉ_t = x̂_t² + û_t²`, `x̂_{t+1} = a x̂_t + b û_t + c`, terminal
/// `2 x̂_T²`, whatever the samples' own states were.
#[test]
fn model_costs_replay_each_samples_noise_from_the_mean_start() {
    let (a, b, c, gain, offset, var) = (0.9, 0.5, 0.1, -0.2, 0.3, 0.04);
    let (t_len, x0) = (3, 0.7);
    let dynamics = TvlgDynamics {
        fx: vec![DMatrix::from_element(1, 1, a); t_len],
        fu: vec![DMatrix::from_element(1, 1, b); t_len],
        fc: vec![DVector::from_element(1, c); t_len],
        cov: vec![DMatrix::from_element(1, 1, 1e-6); t_len],
        x0_mean: DVector::from_element(1, x0),
        x0_cov: DMatrix::from_element(1, 1, 1e-6),
    };
    let ctrl = TvlgController::new(
        vec![DMatrix::from_element(1, 1, gain); t_len],
        vec![DVector::from_element(1, offset); t_len],
        vec![DMatrix::from_element(1, 1, var); t_len],
    )
    .unwrap();
    let running = QuadraticCost {
        hess: DMatrix::identity(2, 2) * 2.0,
        grad: DVector::zeros(2),
        constant: 0.0,
    };
    let terminal = QuadraticCost {
        hess: DMatrix::from_element(1, 1, 4.0),
        grad: DVector::zeros(1),
        constant: 0.0,
    };
    let cost = vec![running.clone(), running.clone(), running, terminal];
    let noise = [[0.5, -1.0, 2.0], [-0.3, 0.0, 1.5]];
    let samples = TrajectorySamples {
        // The samples' own states must not matter.
        states: Array3::from_elem((2, t_len + 1, 1), 123.0),
        actions: Array3::from_elem((2, t_len, 1), -7.0),
        noise: Array3::from_shape_fn((2, t_len, 1), |(i, t, _)| noise[i][t]),
        costs: Array2::zeros((2, t_len + 1)),
    };
    let got = model_costs(&ctrl, &samples, &dynamics, &cost).unwrap();
    for (i, xi) in noise.iter().enumerate() {
        let mut x: f64 = x0;
        for t in 0..t_len {
            let u = gain * x + offset + var.sqrt() * xi[t];
            assert!((got[(i, t)] - (x * x + u * u)).abs() < 1e-12, "{got}");
            x = a * x + b * u + c;
        }
        assert!((got[(i, t_len)] - 2.0 * x * x).abs() < 1e-12, "{got}");
    }
    // A fit of another horizon is refused, not indexed out of range.
    let short = TvlgDynamics {
        fx: dynamics.fx[..2].to_vec(),
        fu: dynamics.fu[..2].to_vec(),
        fc: dynamics.fc[..2].to_vec(),
        cov: dynamics.cov[..2].to_vec(),
        ..dynamics
    };
    assert!(model_costs(&ctrl, &samples, &short, &cost).is_err());
}

/// Samples of a deterministic linear system, its own matrices as the fit, a quadratic cost: the model
/// predicts every cost, the residual ratio is near 0 at every step, and the multipliers double at every
/// update up to the largest multiplier of each step (linear from 10 to 5, GPS's `ALG_PILQR`). Each
/// update's LQR stage meets its bound `kl_t m_t` at every step, `kl_t` linear from 0.6 to 0.2 (the
/// authors' gripper pusher).
#[test]
fn an_exact_model_leaves_no_residual_and_the_bounds_follow_the_schedules() {
    let sys = LinearModel::double_integrator();
    let obj = double_integrator_objective();
    let x0 = [1.0, 0.0];
    let (kl, max_mult) = (
        PerStep::Linear {
            first: 0.6,
            last: 0.2,
        },
        PerStep::Linear {
            first: 10.0,
            last: 5.0,
        },
    );
    let mut pilqr = Pilqr::new(PilqrConfig {
        kl_step: Some(kl),
        max_step_mult: max_mult,
        ..PilqrConfig::default()
    })
    .unwrap();
    let scfg = SampleConfig {
        samples: 20,
        x0_std: 0.0,
        process_std: 0.0,
    };
    // The system's own matrices as the fit.
    let dynamics = TvlgDynamics {
        fx: vec![sys.a.clone(); T],
        fu: vec![sys.b.clone(); T],
        fc: vec![DVector::zeros(2); T],
        cov: vec![DMatrix::identity(2, 2) * 1e-12; T],
        x0_mean: DVector::from_column_slice(&x0),
        x0_cov: DMatrix::identity(2, 2) * 1e-12,
    };
    let mut ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
    let mut rng = rng_from_seed(3);
    for update in 0..5 {
        let samples = sample_trajectories(&ctrl, &sys, &obj, &x0, &scfg, &mut rng).unwrap();
        let step = pilqr.update(&ctrl, &samples, &dynamics, &obj).unwrap();
        assert!(
            // (Rounding, and the cost expansion by finite differences.)
            step.residual_ratio.iter().all(|&r| r < 1e-6),
            "update {update}: {:?}",
            step.residual_ratio
        );
        for t in 0..T {
            let expect = 2f64.powi(update).min(max_mult.at(t, T));
            assert!(
                (step.step_mult[t] - expect).abs() < 1e-12,
                "update {update}, step {t}: {:?}",
                step.step_mult
            );
            let bound = kl.at(t, T) * step.step_mult[t];
            assert!(
                step.lqr.kl[t] <= 1.1 * bound,
                "update {update}, step {t}: KL {} over {bound}",
                step.lqr.kl[t]
            );
        }
        assert!(!step.lqr.fallback);
        ctrl = step.controller;
    }
    // After five updates every multiplier sits at its step's ceiling.
    for t in 0..T {
        assert_eq!(pilqr.step_mult()[t], max_mult.at(t, T));
    }
}

/// With process noise, replaying each sample's noise from the start accumulates the deviations the
/// model cannot predict, while restarting at the sample's own state at every step forgets them:
/// late in the trajectory the authors' residual ratio is the larger, so their LQR steps the smaller.
#[test]
fn replaying_from_the_start_sees_the_drift_that_restarting_hides() {
    let sys = LinearModel::double_integrator();
    let obj = double_integrator_objective();
    let scfg = SampleConfig {
        samples: 20,
        x0_std: 0.0,
        process_std: 0.1,
    };
    let ctrl = TvlgController::constant(T, 2, &[0.0], 1.0).unwrap();
    let samples =
        sample_trajectories(&ctrl, &sys, &obj, &[1.0, 0.0], &scfg, &mut rng_from_seed(5)).unwrap();
    let dynamics = TvlgFit::new(TvlgConfig {
        prior: None,
        ..Default::default()
    })
    .fit(samples.states.view(), samples.actions.view())
    .unwrap();
    let ratio = |residual| {
        Pilqr::new(PilqrConfig {
            residual,
            lqr: LqrFlmConfig {
                kl_step: 0.5,
                ..Default::default()
            },
            ..PilqrConfig::default()
        })
        .unwrap()
        .update(&ctrl, &samples, &dynamics, &obj)
        .unwrap()
        .residual_ratio
    };
    let (start, each) = (ratio(Residual::FromStart), ratio(Residual::FromEachStep));
    println!("from the start {start:?}\nfrom each step {each:?}");
    let late = |r: &[f64]| r[3 * T / 4..].iter().sum::<f64>();
    assert!(late(&start) > 2.0 * late(&each), "{start:?} {each:?}");
    assert!(start.iter().all(|r| r.is_finite() && *r >= 0.0));
}

/// `PerStep` is GPS's `np.linspace(first, last, T)` (value `i` is `first + i (last − first) /
/// (T − 1)`), reads from a number or a `{ first, last }` table, refuses anything else with a
/// message that says what it wants, and bounds are checked at every step.
#[test]
fn per_step_settings_read_and_check() {
    let lin = PerStep::Linear {
        first: 0.6,
        last: 0.2,
    };
    assert_eq!(lin.at(0, 100), 0.6);
    assert!((lin.at(50, 100) - (0.6 - 0.4 * 50.0 / 99.0)).abs() < 1e-15);
    assert!((lin.at(99, 100) - 0.2).abs() < 1e-15);
    assert_eq!(lin.at(0, 1), 0.6);
    assert_eq!(PerStep::Constant(0.3).at(7, 100), 0.3);

    #[derive(serde::Deserialize, serde::Serialize)]
    struct S {
        a: PerStep,
        b: PerStep,
    }
    let s: S = toml::from_str("a = 2\nb = { first = 10.0, last = 5.0 }").unwrap();
    assert_eq!(s.a, PerStep::Constant(2.0));
    assert_eq!(
        s.b,
        PerStep::Linear {
            first: 10.0,
            last: 5.0
        }
    );
    // A constant writes as a plain number, so settings that had numbers keep their bytes.
    assert_eq!(
        serde_json::to_string(&PerStep::Constant(0.5)).unwrap(),
        "0.5"
    );
    let err = toml::from_str::<S>("a = \"big\"\nb = 1").err().unwrap();
    assert!(err.to_string().contains("a number, or a table"), "{err}");

    let cfg = |min: PerStep, max: PerStep, kl: Option<PerStep>| {
        PilqrConfig {
            min_step_mult: min,
            max_step_mult: max,
            kl_step: kl,
            ..PilqrConfig::default()
        }
        .validate()
    };
    let c = PerStep::Constant;
    assert!(cfg(c(0.01), lin_of(10.0, 5.0), Some(lin)).is_ok());
    // A ceiling that falls below 1 on some step, a floor above 1, a bound that reaches 0.
    assert!(cfg(c(0.01), lin_of(10.0, 0.5), None).is_err());
    assert!(cfg(lin_of(0.01, 2.0), c(10.0), None).is_err());
    assert!(cfg(c(0.01), c(10.0), Some(lin_of(0.5, 0.0))).is_err());
    assert!(cfg(c(0.01), c(10.0), Some(c(f64::NAN))).is_err());
}

fn lin_of(first: f64, last: f64) -> PerStep {
    PerStep::Linear { first, last }
}

/// Settings written before the residual was the authors' read as what they ran.
#[test]
fn settings_without_the_residual_key_read_as_the_first_version() {
    let mut v = serde_json::to_value(PilqrConfig::default()).unwrap();
    assert_eq!(v["residual"], "from_start");
    v.as_object_mut().unwrap().remove("residual");
    let old: PilqrConfig = serde_json::from_value(v).unwrap();
    assert_eq!(old.residual, Residual::FromEachStep);
}
