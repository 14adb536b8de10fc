//! p0's first step on Leo: DDPG from scratch on the idealized biped, as `tandem reproduce
//! p0-leo` pre-trains μ^idl (the same agent, loop, settings and random streams), with an
//! evaluation every 10 000 steps. Each line: steps, wall seconds, then the deterministic
//! policy's return, walked distance `L` (m), electrical work (J) and whether it fell, on the
//! idealized and on the true biped. Does it learn to walk?
//!
//! `cargo run --release --example p0_leo_ddpg [standing|stepping|authors] [seed] [steps]`
//! (defaults `standing`, 0, 300000): `stepping` starts every episode mid-step, as p0's authors
//! do ([`LeoStart::Stepping`]); `authors` adds the rest of what their code does that we can
//! set: 14 observed dimensions (torso pitch and the six leg angles, with their velocities: no
//! torso position or velocity), voltages bounded at 8.6 V, only drawn electrical energy
//! counted ([`LeoWork::Positive`]), an L2 penalty of 10⁻³ on the critic, and no update before
//! 20 000 stored transitions. About 30 minutes on one core.

use tandem::agents::{EpisodeRunner, StepOptions};
use tandem::core::SeedStream;
use tandem::envs::{leo_parts, LeoModel, LeoStart, LeoWork};
use tandem::models::{ModelEnv, PlantModel};
use tandem::pipelines::adapter::Feature;
use tandem::pipelines::p0::{
    agent_spaces, ddpg_agent, leo_measures, measured_episode, p0_loop, Method, P0Config,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (start, authors) = match args.get(1).map(String::as_str) {
        None | Some("standing") => (LeoStart::Standing, false),
        Some("stepping") => (LeoStart::Stepping, false),
        Some("authors") => (LeoStart::Stepping, true),
        Some(other) => {
            let e = format!("the mode is standing, stepping or authors, not {other}");
            return Err(e.into());
        }
    };
    let number = |i: usize, d: u64| -> Result<u64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    let (seed, steps) = (number(2, 0)?, number(3, 300_000)?);
    let mut cfg = P0Config::leo();
    if authors {
        // Observation indices: x 0, z 1, pitch 2, leg angles 3-8, ẋ 9, ż 10, pitch rate 11,
        // leg velocities 12-17; angular velocities in units of 10 rad/s, as P0Config::leo.
        cfg.features = (2..=8)
            .map(|index| Feature::Linear { index, scale: 1.0 })
            .chain((11..=17).map(|index| Feature::Linear { index, scale: 0.1 }))
            .collect();
        cfg.ddpg.critic_weight_decay = 1e-3;
        cfg.ddpg.learning_starts = 20_000;
    }

    let biped = |model: LeoModel, id: &str| -> Result<_, Box<dyn std::error::Error>> {
        let (plant, task) = leo_parts(model, id)?;
        let mut task = task.with_start(start)?;
        if authors {
            task = task.with_work(LeoWork::Positive).with_voltage_limit(8.6)?;
        }
        Ok((ModelEnv::new(PlantModel::new(plant), task.clone())?, task))
    };
    let (mut env, task) = biped(LeoModel::Idealized, "Leo-v0")?;
    let (mut idealized, _) = biped(LeoModel::Idealized, "Leo-v0")?;
    let (mut true_biped, true_task) = biped(LeoModel::True, "Leo-true-v0")?;

    let seeds = SeedStream::new(seed);
    let (obs, act) = agent_spaces(&task);
    let agent = ddpg_agent(&cfg, &task, Method::Warm, seeds.derive("agent"))?;
    let mut ddpg = p0_loop(agent, &cfg.ddpg, &obs, &act, seeds.rng("minibatches"))?;
    let mut runner = EpisodeRunner::new(seeds.derive("idealized-episodes"), "ep");
    let measures = leo_measures();
    let t0 = std::time::Instant::now();
    println!(
        "{:>7} {:>6} | idealized: return, L, work, fell | true: the same",
        "steps", "s"
    );
    for k in 1..=steps {
        ddpg.step(&mut env, &mut runner, StepOptions::model())?;
        if k % 10_000 == 0 || k == steps {
            let mut line = format!("{k:>7} {:>6.0}", t0.elapsed().as_secs_f64());
            for (e, t) in [(&mut idealized, &task), (&mut true_biped, &true_task)] {
                let ev = measured_episode(&mut ddpg.agent, e, t, &measures)?;
                let m = |key: &str| ev.measures.get(key).copied().unwrap_or(f64::NAN);
                line += &format!(
                    " | {:>8.1} {:>6.2} {:>7.1} {}",
                    ev.eval_return,
                    m("distance_m"),
                    m("work_j"),
                    m("fell") as u8
                );
            }
            println!("{line}");
        }
    }
    Ok(())
}
