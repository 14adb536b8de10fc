//! p1's claim about its model: the deep incremental model `ŝ_{t+1} = s_t + L_θ Δa_t` learns from
//! fewer real transitions than a plain network, because it only has to learn a matrix (p1 §4).
//! This fits both on the same transitions of a gymnasium MuJoCo task and compares their one-step
//! errors on held-out transitions:
//!
//! - the incremental model ([`IncrementalModel`], a 2 × 200 network giving the full `S × A`
//!   matrix `L`, trained with p1's loss (5) on one-step-back data);
//! - an MLP of the same size ([`MlpModel`], 2 × 200, predicting the state change), on the same
//!   rows;
//!
//! for 1 000, 5 000 and 20 000 training transitions, both for the same number of gradient steps
//! (Adam 1e-3, minibatches of 256). The error is per state component the root-mean-square error
//! divided by the standard deviation of that component's true one-step change (0: exact; 1: no
//! better than predicting the mean change), averaged over the components. Data: episodes of up to
//! 1000 steps from the task's start distribution with actions from one of two sources:
//!
//! - `iid`: uniform random actions every step (SAC's first steps);
//! - `smooth`: actions that drift by at most ±0.1 of the range a step (a correlated exploration
//!   signal, as a policy with smooth exploration noise gives).
//!
//! States are `qpos ++ qvel` with the x position moved to 0 (what tandem's models see).
//!
//! ```sh
//! scripts/setup-mujoco.sh
//! cargo run --release --features mujoco --example p1_model_error -- HalfCheetah-v5 iid
//! ```

use std::error::Error;

use ndarray::Array2;
use rand::Rng as _;
use tandem::core::{Action, Rng, SeedStream, Space};
use tandem::dynamics::Plant;
use tandem::envs::Task;
use tandem::models::{
    DynamicsModel, FitConfig, IncrementalModel, IncrementalModelConfig, MlpModel, MlpModelConfig,
    ModelInput, Transitions, TransitionsBuilder,
};

const HELD_OUT: usize = 5_000;
const SIZES: [usize; 3] = [1_000, 5_000, 20_000];
const GRADIENT_STEPS: usize = 10_000;
const BATCH: usize = 256;

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let id = args.next().unwrap_or_else(|| "HalfCheetah-v5".into());
    let source = args.next().unwrap_or_else(|| "iid".into());
    if !["iid", "smooth"].contains(&source.as_str()) {
        return Err(format!("action source {source}: expected iid or smooth").into());
    }
    let largest = SIZES[SIZES.len() - 1];
    // Rows [s, a_prev] for the incremental model; the MLP sees their first `s` columns.
    let data = collect(&id, &source, largest + HELD_OUT)?;
    let a = data.actions.ncols();
    let s = data.states.ncols() - a;
    let held = data.select(&(largest..largest + HELD_OUT).collect::<Vec<_>>());
    println!(
        "{id}, {source} actions: one-step error on {HELD_OUT} held-out transitions \
         (RMSE / std of the true change, mean over {s} components)"
    );
    println!("| training transitions | MLP 2×200 | incremental 2×200 |");
    println!("|---|---|---|");
    for n in SIZES {
        let train = data.select(&(0..n).collect::<Vec<_>>());
        let plain = own_states(&train, s);
        let fit = FitConfig {
            epochs: (GRADIENT_STEPS * BATCH).div_ceil(n),
            batch_size: BATCH,
            holdout_fraction: 0.0,
            seed: 0,
            early_stop: None,
        };
        let mut mlp = MlpModel::new(
            s,
            a,
            MlpModelConfig {
                hidden: vec![200, 200],
                learn_reward: false,
                learn_termination: false,
                ..MlpModelConfig::default()
            },
        )?;
        mlp.fit(&plain, &fit)?;
        let mut inc = IncrementalModel::new(s, a, IncrementalModelConfig::default())?;
        inc.fit(&train, &fit)?;
        println!(
            "| {n} | {:.3} | {:.3} |",
            relative_error(&mlp, &own_states(&held, s), s)?,
            relative_error(&inc, &held, s)?
        );
    }
    Ok(())
}

/// `n` transitions of `id` in canonical coordinates, each state followed by the action before it
/// (zero at an episode's start), episodes ending at termination or after 1000 steps.
fn collect(id: &str, source: &str, n: usize) -> Result<Transitions, Box<dyn Error>> {
    let task = tandem::mujoco::gym_task(id)?;
    let kind = tandem::mujoco::TaskKind::from_id(id).ok_or("not a MuJoCo task")?;
    let env = tandem::mujoco::MujocoEnv::task(kind, &tandem::mujoco::assets_dir())?;
    let plant = env.plant();
    let dim = match task.action_space() {
        Space::Box { low, .. } => low.len(),
        Space::Discrete { .. } => return Err("a box action space is expected".into()),
    };
    let mut rng: Rng = SeedStream::new(0).rng("data");
    let mut out = TransitionsBuilder::with_prev_action(task.state_dim(), dim);
    let mut x = task.initial_state(&mut rng);
    let mut next = vec![0.0; x.len()];
    let mut a = vec![0.0f64; dim];
    let mut t = 0;
    for _ in 0..n {
        for ai in &mut a {
            *ai = match source {
                "iid" => rng.random_range(-1.0..1.0),
                _ => (*ai + rng.random_range(-0.1..0.1f64)).clamp(-1.0, 1.0),
            };
        }
        let u = task.control(&Action::Continuous(a.clone()));
        plant.step_into(&x, &u, &mut next);
        let terminated = task.terminated(&next);
        t += 1;
        let done = terminated || t == 1000;
        out.push_canonical(
            &task,
            &x,
            &u,
            &next,
            task.reward(&x, &u, &next),
            terminated,
            done,
        )?;
        if done {
            x = task.initial_state(&mut rng);
            a.fill(0.0);
            t = 0;
        } else {
            x.copy_from_slice(&next);
            task.canonicalize(&mut x);
        }
    }
    Ok(out.build())
}

/// `data` without the previous action: the first `s` state columns.
fn own_states(data: &Transitions, s: usize) -> Transitions {
    Transitions {
        states: data.states.slice(ndarray::s![.., ..s]).to_owned(),
        next_states: data.next_states.slice(ndarray::s![.., ..s]).to_owned(),
        ..data.clone()
    }
}

/// Mean over the first `s` state components of the held-out RMSE divided by the standard
/// deviation of the true one-step change.
fn relative_error(
    model: &dyn DynamicsModel,
    held: &Transitions,
    s: usize,
) -> Result<f64, Box<dyn Error>> {
    let input = ModelInput::new(held.states.view(), held.actions.view());
    let mut rng: Rng = SeedStream::new(0).rng("predict");
    let error: Array2<f64> = &model.predict(&input, &mut rng)?.next_states - &held.next_states;
    let change = &held.next_states - &held.states;
    let n = held.len() as f64;
    let mut total = 0.0;
    let mut counted = 0;
    for j in 0..s {
        let mse = error.column(j).iter().map(|e| e * e).sum::<f64>() / n;
        let mean = change.column(j).sum() / n;
        let var = change
            .column(j)
            .iter()
            .map(|c| (c - mean).powi(2))
            .sum::<f64>()
            / n;
        if var > 1e-18 {
            total += (mse / var).sqrt();
            counted += 1;
        }
    }
    Ok(total / counted.max(1) as f64)
}
