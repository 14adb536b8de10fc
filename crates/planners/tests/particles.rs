//! Particles in the sampling planners, CEM, MPPI and DMD-MPC (PETS's trajectory sampling): a sequence's cost is the mean
//! over its rollouts. Truth: a model of two worlds dealt by row index, where only the average
//! over both has a unique optimum, and a deterministic model, where particles change nothing.

mod common;

use common::LinearModel;
use ndarray::Array2;
use std::sync::Mutex;
use tandem_core::Rng;

use tandem_models::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Propagation,
    Transitions,
};
use tandem_planners::{
    Bounds, Cem, CemConfig, DmdMpc, DmdMpcConfig, Mppi, MppiConfig, Noise, Objective, Planner,
};

/// `x' = x + u` in even rows and `x' = x − u` in odd ones: two members dealt by row index, as
/// an ensemble propagating with `FixedMember` deals its elites.
struct TwoWorlds;

impl DynamicsModel for TwoWorlds {
    fn state_dim(&self) -> usize {
        1
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let (s, a) = (input.states, input.actions);
        let next = Array2::from_shape_fn((s.nrows(), 1), |(r, _)| {
            let sign = if r % 2 == 0 { 1.0 } else { -1.0 };
            s[(r, 0)] + sign * a[(r, 0)]
        });
        Ok(Prediction::deterministic(next))
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

const H: usize = 3;

/// Reach `x_H = 1` from 0: `x_H = ±Σu`, so each world alone is solved by `Σu = ±1` at cost 0,
/// and their mean `((Σu − 1)² + (Σu + 1)²) / 2 = (Σu)² + 1` only by `Σu = 0`.
fn objective() -> Objective {
    Objective::new(1, 1, |_, _| 0.0).with_terminal(|x| (x[0] - 1.0).powi(2))
}

fn planners(particles: usize) -> Vec<(&'static str, Box<dyn Planner>)> {
    let bounds = Some(Bounds::symmetric(1, 1.0));
    let cem = Cem::new(CemConfig {
        horizon: H,
        population: 300,
        particles,
        iterations: 6,
        init_std: Some(vec![0.5]),
        bounds: bounds.clone(),
        seed: 3,
        ..CemConfig::default()
    })
    .unwrap();
    let mppi = Mppi::new(MppiConfig {
        horizon: H,
        samples: 300,
        particles,
        lambda: 0.01,
        noise: Noise::Isotropic(0.25),
        iterations: 6,
        bounds,
        seed: 3,
        ..MppiConfig::default()
    })
    .unwrap();
    let dmd = DmdMpc::new(DmdMpcConfig {
        horizon: H,
        samples: 300,
        particles,
        noise: Noise::Isotropic(0.25),
        iterations: 6,
        adapt_covariance: true,
        bounds: Some(Bounds::symmetric(1, 1.0)),
        seed: 3,
        ..DmdMpcConfig::default()
    })
    .unwrap();
    vec![
        ("cem", Box::new(cem)),
        ("mppi", Box::new(mppi)),
        ("dmd", Box::new(dmd)),
    ]
}

#[test]
fn particles_average_a_sequences_cost_over_the_members_they_are_dealt() {
    let obj = objective();
    for particles in [2, 4] {
        for (name, mut p) in planners(particles) {
            let plan = p.plan(&[0.0], &TwoWorlds, &obj).unwrap();
            let sum = plan.actions.sum();
            assert!(sum.abs() < 0.1, "{name} P={particles}: Σu = {sum}");
        }
    }
    // One rollout per sequence: each sample sees one world, and CEM keeps the cheapest sample,
    // which solves its own world (Σu near ±1) at a cost near 0.
    let (_, mut cem) = planners(1).remove(0);
    let sum = cem.plan(&[0.0], &TwoWorlds, &obj).unwrap().actions.sum();
    assert!((sum.abs() - 1.0).abs() < 0.2, "cem P=1: Σu = {sum}");
}

#[test]
fn particles_of_a_deterministic_model_change_nothing() {
    let m = LinearModel::double_integrator();
    let obj = Objective::new(2, 1, |x, u| {
        x[0] * x[0] + 0.1 * x[1] * x[1] + 0.01 * u[0] * u[0]
    });
    let x0 = [1.0, 0.0];
    for ((name, mut one), (_, mut three)) in planners(1).into_iter().zip(planners(3)) {
        for _ in 0..3 {
            let (a, b) = (
                one.plan(&x0, &m, &obj).unwrap(),
                three.plan(&x0, &m, &obj).unwrap(),
            );
            assert_eq!(a.actions, b.actions, "{name}");
            assert_eq!(a.total_cost, b.total_cost, "{name}");
        }
    }
}

#[test]
fn zero_particles_are_refused() {
    let cem = Cem::new(CemConfig {
        particles: 0,
        ..CemConfig::default()
    });
    assert!(cem.unwrap_err().to_string().contains("particles"));
    let mppi = Mppi::new(MppiConfig {
        particles: 0,
        ..MppiConfig::default()
    });
    assert!(mppi.unwrap_err().to_string().contains("particles"));
    let dmd = DmdMpc::new(DmdMpcConfig {
        particles: 0,
        ..DmdMpcConfig::default()
    });
    assert!(dmd.unwrap_err().to_string().contains("particles"));
}

/// [`TwoWorlds`] that notes how each batch asked to be propagated.
#[derive(Default)]
struct Noting(Mutex<Vec<Option<Propagation>>>);

impl DynamicsModel for Noting {
    fn state_dim(&self) -> usize {
        1
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn predict(&self, input: &ModelInput<'_>, rng: &mut Rng) -> Result<Prediction, ModelError> {
        self.0.lock().unwrap().push(input.propagation);
        TwoWorlds.predict(input, rng)
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

#[test]
fn the_configured_propagation_reaches_every_sampled_batch() {
    let obj = objective();
    for propagation in [None, Some(Propagation::Expectation)] {
        let cem = CemConfig {
            horizon: H,
            population: 10,
            particles: 2,
            propagation,
            iterations: 2,
            ..CemConfig::default()
        };
        let mppi = MppiConfig {
            horizon: H,
            samples: 10,
            particles: 2,
            propagation,
            ..MppiConfig::default()
        };
        let dmd = DmdMpcConfig {
            horizon: H,
            samples: 10,
            particles: 2,
            propagation,
            ..DmdMpcConfig::default()
        };
        let planners: [Box<dyn Planner>; 3] = [
            Box::new(Cem::new(cem).unwrap()),
            Box::new(Mppi::new(mppi).unwrap()),
            Box::new(DmdMpc::new(dmd).unwrap()),
        ];
        for (iterations, mut p) in [2, 1, 1].into_iter().zip(planners) {
            let model = Noting::default();
            p.plan(&[0.0], &model, &obj).unwrap();
            let seen = model.0.into_inner().unwrap();
            // H batches per iteration, then the chosen plan's own rollout (as the model is set).
            assert_eq!(seen.len(), H * iterations + H);
            assert!(seen[..H * iterations].iter().all(|p| *p == propagation));
            assert!(seen[H * iterations..].iter().all(Option::is_none));
        }
    }
}
