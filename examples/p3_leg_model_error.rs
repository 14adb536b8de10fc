//! How well p3's ensemble predicts the 2R leg one step ahead, by where the data come from.
//!
//! MBPO and M-DeMoRL train SAC on the ensemble's predictions, so its one-step error bounds what
//! they can gain. This fits the leg preset's ensemble (3 members of 3 × 64 units, here all
//! three averaged) on 17 000 transitions of the true leg and reports its error on the next
//! 3 000, per state component, relative to the spread of that component's one-step change
//! (0: exact; 1: no better than predicting the mean change). Three data sources:
//!
//! - `iid`: uniformly random torques every step (SAC's first 1000 steps);
//! - `walk`: torques that drift as a random walk (a slow, strong excitation);
//! - `track`: a PD controller on the foot trajectory with ±30 % torque noise (what a policy that
//!   tracks the trajectory visits).
//!
//! and separately for the held-out rows away from the joint stops (hip within ±1.5 rad, knee bent
//! by more than 0.05 rad), where the leg's dynamics are smooth.
//!
//! ```sh
//! cargo run --release --example p3_leg_model_error -- iid      # or walk, track
//! ```

use std::error::Error;

use ndarray::Array2;
use rand::Rng as _;
use tandem::core::{Rng, SeedStream};
use tandem::dynamics::{Clocked, Plant};
use tandem::envs::Task;
use tandem::models::{
    DynamicsModel, EnsembleConfig, FitConfig, ModelInput, ProbabilisticEnsemble, Propagation,
    Transitions, TransitionsBuilder,
};
use tandem::robots::leg2r::{leg2r_plant, Leg2RParams};
use tandem::robots::{Leg2REnv, Leg2REnvExt, Leg2RModel};

const STEPS: usize = 20_000;
const HELD_OUT: usize = 3_000;
const EPISODE: usize = 1_000;

fn main() -> Result<(), Box<dyn Error>> {
    let source = std::env::args().nth(1).unwrap_or_else(|| "iid".into());
    if !["iid", "walk", "track"].contains(&source.as_str()) {
        return Err(format!("data source {source}: expected iid, walk or track").into());
    }
    let data = collect(&source)?;
    let train = data.select(&(0..STEPS - HELD_OUT).collect::<Vec<_>>());
    let held = data.select(&(STEPS - HELD_OUT..STEPS).collect::<Vec<_>>());
    let change = &held.next_states - &held.states;
    let away: Vec<usize> = (0..HELD_OUT)
        .filter(|&i| held.states[[i, 1]] > 0.05 && held.states[[i, 0]].abs() < 1.5)
        .collect();
    println!(
        "{source}: {} held-out rows, {} away from the stops",
        HELD_OUT,
        away.len()
    );
    let mut model = ProbabilisticEnsemble::new(
        6,
        2,
        EnsembleConfig {
            hidden: vec![64; 3],
            members: 3,
            elites: 3,
            propagation: Propagation::Expectation,
            ..EnsembleConfig::default()
        },
    )?;
    let mut rng: Rng = SeedStream::new(0).rng("predictions");
    println!("refit  relative error: q_hip q_knee dq_hip dq_knee cos sin | away from the stops");
    for refit in 0..20u64 {
        let fit = FitConfig {
            epochs: 5,
            batch_size: 256,
            holdout_fraction: 0.1,
            seed: refit,
            early_stop: None,
        };
        model.fit(&train, &fit)?;
        if refit % 5 == 4 {
            let input = ModelInput::new(held.states.view(), held.actions.view());
            let error = &model.predict(&input, &mut rng)?.next_states - &held.next_states;
            let all: Vec<usize> = (0..HELD_OUT).collect();
            println!(
                "{:>5}  {} | {}",
                refit + 1,
                relative(&error, &change, &all),
                relative(&error, &change, &away)
            );
        }
    }
    Ok(())
}

/// `STEPS` transitions of the true leg (state `[q, q̇, cos φ, sin φ]`, torques in N m) in
/// 1000-step episodes from the task's start distribution.
fn collect(source: &str) -> Result<Transitions, Box<dyn Error>> {
    let task = Leg2REnv::new(Leg2RModel::Real).task().clone();
    let plant = Clocked::new(leg2r_plant(&Leg2RParams::real())?, 0.5)?;
    let limit = task.torque_limit();
    let mut rng: Rng = SeedStream::new(0).rng("data");
    let mut out = TransitionsBuilder::new(6, 2);
    let mut x = task.initial_state(&mut rng);
    let mut next = vec![0.0; 6];
    let mut a = [0.0f64; 2];
    for t in 1..=STEPS {
        match source {
            "iid" => a = [0, 1].map(|_| rng.random_range(-1.0..1.0)),
            "walk" => {
                for ai in &mut a {
                    *ai = (*ai + rng.random_range(-0.1..0.1)).clamp(-1.0, 1.0);
                }
            }
            _ => {
                let target = task.state_on_trajectory(Clocked::<Leg2RPlant>::phase(&x));
                for i in 0..2 {
                    let pd = 30.0 * (target[i] - x[i]) + (target[i + 2] - x[i + 2]);
                    a[i] = (pd / limit[i] + rng.random_range(-0.3..0.3)).clamp(-1.0, 1.0);
                }
            }
        }
        let u = [a[0] * limit[0], a[1] * limit[1]];
        plant.step_into(&x, &u, &mut next);
        out.push(&x, &u, &next, task.reward(&x, &u, &next), false)?;
        x.copy_from_slice(&next);
        if t % EPISODE == 0 {
            out.end_episode();
            x = task.initial_state(&mut rng);
        }
    }
    Ok(out.build())
}

type Leg2RPlant = tandem::dynamics::rigid_plant::RigidBodyPlant;

/// Per component, the root-mean-square error over `rows` divided by the standard deviation of
/// the true one-step change over the same rows.
fn relative(error: &Array2<f64>, change: &Array2<f64>, rows: &[usize]) -> String {
    let n = rows.len().max(1) as f64;
    (0..error.ncols())
        .map(|j| {
            let mse = rows.iter().map(|&i| error[[i, j]].powi(2)).sum::<f64>() / n;
            let mean = rows.iter().map(|&i| change[[i, j]]).sum::<f64>() / n;
            let var = rows
                .iter()
                .map(|&i| (change[[i, j]] - mean).powi(2))
                .sum::<f64>()
                / n;
            format!("{:.3}", (mse / var).sqrt())
        })
        .collect::<Vec<_>>()
        .join(" ")
}
