//! p0's first step on Leo: DDPG from scratch on the idealized biped, as `tandem reproduce
//! p0-leo` pre-trains μ^idl (the same agent, loop, settings and random streams), with an
//! evaluation every 10 000 steps. Each line: steps, wall seconds, then the deterministic
//! policy's return, walked distance `L` (m), electrical work (J) and whether it fell, on the
//! idealized and on the true biped. Does it learn to walk?
//!
//! `cargo run --release --example p0_leo_ddpg [standing|stepping] [seed] [steps]` (defaults
//! `standing`, 0, 300000): `stepping` starts every episode mid-step, as p0's authors do
//! ([`LeoStart::Stepping`]). About 30 minutes on one core.

use tandem::agents::{EpisodeRunner, StepOptions};
use tandem::core::SeedStream;
use tandem::envs::{leo_parts, LeoModel, LeoStart};
use tandem::models::{ModelEnv, PlantModel};
use tandem::pipelines::p0::{
    agent_spaces, ddpg_agent, leo_measures, measured_episode, p0_loop, Method, P0Config,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let start = match args.get(1).map(String::as_str) {
        None | Some("standing") => LeoStart::Standing,
        Some("stepping") => LeoStart::Stepping,
        Some(other) => {
            return Err(format!("start must be standing or stepping, got {other}").into())
        }
    };
    let number = |i: usize, d: u64| -> Result<u64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    let (seed, steps) = (number(2, 0)?, number(3, 300_000)?);
    let cfg = P0Config::leo();

    let biped = |model: LeoModel, id: &str| -> Result<_, Box<dyn std::error::Error>> {
        let (plant, task) = leo_parts(model, id)?;
        let task = task.with_start(start)?;
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
