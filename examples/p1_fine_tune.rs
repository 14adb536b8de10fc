//! p1 §6, online fine-tuning, on the 2R leg tracking its foot trajectory (p3's task, reward (15)
//! with errors in units of 2 cm and 0.2 m/s):
//!
//! 1. SAC (p3's leg settings) is trained on the idealized leg (`Leg2R-v0`);
//! 2. `L_θ` is fitted on transitions of the idealized leg under that policy with exploration
//!    (the incremental model "learned offline"), and a second model starts from Remark 4's
//!    prior `L0`: the idealized leg's exact input Jacobian (analytic rigid-body derivatives) at
//!    the trajectory's start, in the agent's action units;
//! 3. the environment changes: the motors apply `k a + bias` for the command `a` (a torque
//!    offset, a miscalibration; and half-strength motors with an offset);
//! 4. the pre-trained policy runs on the changed leg alone, and with the residual incremental
//!    policy from the error-evolution model (9) (`tandem::algos::incremental_dyna::fine_tune`: LQR on
//!    `e_{k+1} = e_k + L_k Δa_e` with `e = s − s_d`, `s_d` the joint state on the foot's
//!    trajectory at the current phase), 10 episodes each, with `L0` held, `L0` refit online
//!    after every episode, and the offline `L_θ` refit online.
//!
//! `cargo run --release --example p1_fine_tune [seed] [epochs]` (defaults 0, 60).
use nalgebra::DVector;
use tandem::agents::{Agent, Mode, Sac};
use tandem::algos::incremental_dyna::{fine_tune, FineTuneConfig, FineTuneEpisode, P1Config};
use tandem::algos::m_demorl::P3Config;
use tandem::algos::mbpo::{leg2r_problem_with, run_sac};
use tandem::algos::{Checkpoints, InMemory};
use tandem::core::{Action, SeedStream};
use tandem::dynamics::rigid_plant::RigidBodyPlant;
use tandem::dynamics::Clocked;
use tandem::dynamics::Plant;
use tandem::envs::{Env, Task, TimeLimit};
use tandem::models::{
    DynamicsModel, FitConfig, IncrementalModel, IncrementalModelConfig, TransitionsBuilder,
};
use tandem::robots::{Leg2RConfig, Leg2REnv, Leg2REnvExt, Leg2RModel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let seeds = SeedStream::new(seed);
    let ideal = Leg2RConfig {
        position_scale: 0.02,
        velocity_scale: 0.2,
        ..Leg2RConfig::for_model(Leg2RModel::Idealized)
    };
    // 1. SAC on the idealized leg.
    let mut loop_cfg = P3Config::leg2r().base;
    loop_cfg.real_steps = arg(2).unwrap_or(60) * loop_cfg.epoch_length;
    let problem = leg2r_problem_with(Leg2REnv::ID, &ideal)?;
    let task = &problem.task;
    let mut store = InMemory::default();
    let t0 = std::time::Instant::now();
    let rec = run_sac(&problem, &loop_cfg, seed, &mut store, &mut |_| {})?;
    let last = rec.curve.last().map_or(f64::NAN, |p| p.eval_return);
    println!(
        "SAC on the idealized leg: return {last:.1} after {} real steps ({:.0} s)",
        rec.real_steps,
        t0.elapsed().as_secs_f64()
    );
    let mut agent = Sac::new(
        loop_cfg.sac.clone(),
        task.observation_space(),
        task.action_space(),
        seeds.derive("agent"),
    )?;
    agent.load(&store.load("sac")?.expect("the run's last checkpoint"))?;

    // 2. L_θ fitted on the idealized leg under the exploring policy (20 episodes).
    let (s_dim, a_dim) = (task.state_dim(), 2);
    let mut data = TransitionsBuilder::new(s_dim, a_dim);
    let mut env = (problem.env)()?;
    for ep in 0..20 {
        let mut obs = env.reset(Some(seeds.derive(&format!("model-{ep}"))));
        loop {
            let s = env.state();
            let a = agent.act(&obs, Mode::Explore)?;
            let step = env.step(&a)?;
            let u = a.as_continuous().unwrap_or(&[]).to_vec();
            data.push(&s, &u, &env.state(), step.reward, step.terminated)?;
            obs = step.observation;
            if step.terminated || step.truncated {
                data.end_episode();
                break;
            }
        }
    }
    let data = data.build();
    let cfg = P1Config::default();
    let mut model = IncrementalModel::new(s_dim, a_dim, cfg.model.clone())?;
    let fit = FitConfig {
        epochs: 30,
        batch_size: 256,
        holdout_fraction: 0.1,
        seed: seeds.derive("fit"),
        early_stop: None,
    };
    let report = model.fit(&data, &fit)?;
    println!(
        "L_θ on {} idealized transitions: held-out loss {:.4}",
        data.len(),
        report.holdout_loss.last().copied().unwrap_or(f64::NAN)
    );

    // 3–4. Before and after the change, without and with the residual.
    let leg_env = |c: &Leg2RConfig, id: &str| -> Result<Box<dyn Env>, Box<dyn std::error::Error>> {
        let env = Leg2REnv::with_config(id, c.clone())?;
        Ok(Box::new(TimeLimit::new(env, c.max_episode_steps)))
    };
    let desired = |s: &[f64]| task.state_on_trajectory(Clocked::<RigidBodyPlant>::phase(s));
    // Joint angles weighted by the foot's lever (0.15 m) in the reward's 2 cm units, joint
    // velocities in its 0.2 m/s units; the clock carries no error.
    let (wq, wv) = ((0.15f64 / 0.02).powi(2), (0.15f64 / 0.2).powi(2));
    let eval_seed = seeds.derive("evaluation");
    let mean =
        |r: &[FineTuneEpisode]| r.iter().map(|e| e.episode_return).sum::<f64>() / r.len() as f64;
    let mut run_on =
        |mut env: Box<dyn Env>, ft: Option<&FineTuneConfig>, model: &IncrementalModel| {
            let mut m = model.clone();
            let plain = FineTuneConfig::default();
            let r = fine_tune(
                &mut agent,
                env.as_mut(),
                task,
                &desired,
                &mut m,
                ft.unwrap_or(&plain),
                ft.is_some(),
                eval_seed,
            )?;
            Ok::<Vec<FineTuneEpisode>, Box<dyn std::error::Error>>(r)
        };
    let before = mean(&run_on(leg_env(&ideal, Leg2REnv::ID)?, None, &model)?);
    println!("return before the change (idealized leg): {before:.1}");

    // L0: the idealized leg's exact input Jacobian (analytic rigid-body derivatives) at the
    // trajectory's start, in the agent's action units (Remark 4's prior).
    let plant = Leg2REnv::with_config(Leg2REnv::ID, ideal.clone())?
        .plant()
        .clone();
    let x0 = task.state_on_trajectory(0.0);
    let (_, bu) = plant.linearize(&DVector::from_column_slice(&x0), &DVector::zeros(2));
    let limit = task.torque_limit();
    let l0: Vec<f64> = (0..s_dim)
        .flat_map(|i| (0..a_dim).map(move |j| (i, j)))
        .map(|(i, j)| bu[(i, j)] * limit[j])
        .collect();
    let prior = IncrementalModel::new(
        s_dim,
        a_dim,
        IncrementalModelConfig {
            prior_gain: Some(l0),
            ..cfg.model.clone()
        },
    )?;
    println!(
        "| motors apply | return after the change | L | fine-tuning episodes 1..10 | mean | \
         of the lost return |"
    );
    println!("|---|---|---|---|---|---|");
    // The changes: a torque offset on both motors (a miscalibration) of 0.2 and 0.4 of the
    // action range, and that with motors at half strength; none for reference.
    for (k, bias) in [(1.0, 0.0), (1.0, 0.2), (1.0, 0.4), (0.5, 0.2)] {
        let changed = |c: &Leg2RConfig| -> Result<Box<dyn Env>, Box<dyn std::error::Error>> {
            let env = leg_env(c, Leg2REnv::ID)?;
            Ok(Box::new(ChangedMotors { env, k, bias }))
        };
        let after = mean(&run_on(changed(&ideal)?, None, &model)?);
        // The error-evolution model: L0 alone, L0 refit online after every episode (p1), and
        // L_θ fitted offline on the idealized leg, refit online.
        for (which, m, refit) in [
            ("L0", &prior, false),
            ("L0, refit online", &prior, true),
            ("fitted offline, refit online", &model, true),
        ] {
            let ft = FineTuneConfig {
                error_weights: vec![wq, wq, wv, wv, 0.0, 0.0],
                increment_weight: 10.0,
                refit,
                ..FineTuneConfig::default()
            };
            let tuned = run_on(changed(&ideal)?, Some(&ft), m)?;
            let list: Vec<String> = tuned
                .iter()
                .map(|e| format!("{:.0}", e.episode_return))
                .collect();
            let recovered = if before - after > 1.0 {
                format!("{:.0} %", 100.0 * (mean(&tuned) - after) / (before - after))
            } else {
                "(none lost)".into()
            };
            println!(
                "| {k} a + {bias} | {after:.1} | {which} | {} | {:.1} | {recovered} |",
                list.join(", "),
                mean(&tuned)
            );
        }
    }
    Ok(())
}

/// The leg with motors that apply `k a + bias` for the command `a` (clipped to the range): the
/// changed system.
struct ChangedMotors {
    env: Box<dyn Env>,
    k: f64,
    bias: f64,
}

impl Env for ChangedMotors {
    fn id(&self) -> &str {
        self.env.id()
    }
    fn observation_space(&self) -> &tandem::core::Space {
        self.env.observation_space()
    }
    fn action_space(&self) -> &tandem::core::Space {
        self.env.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: &Action) -> Result<tandem::envs::Step, tandem::envs::EnvError> {
        let a: Vec<f64> = action
            .as_continuous()
            .unwrap_or(&[])
            .iter()
            .map(|v| (v * self.k + self.bias).clamp(-1.0, 1.0))
            .collect();
        self.env.step(&Action::Continuous(a))
    }
    fn state(&self) -> Vec<f64> {
        self.env.state()
    }
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, tandem::envs::EnvError> {
        self.env.set_state(state)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        self.env.max_episode_steps()
    }
}
