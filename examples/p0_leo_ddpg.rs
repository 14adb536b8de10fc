//! p0's first step on Leo: DDPG from scratch on the idealized biped, as `tandem reproduce
//! p0-leo` pre-trains μ^idl (the same agent, loop, settings and random streams), with an
//! evaluation every 10 000 steps. Each line: steps, wall seconds, then the deterministic
//! policy's return, walked distance `L` (m), electrical work (J) and whether it fell, on the
//! idealized and on the true biped. Does it learn to walk?
//!
//! `cargo run --release --example p0_leo_ddpg [authors|stepping|standing] [seed] [steps]`
//! (defaults `authors`, 0, 300000). `authors` is p0-leo's set-up ([`leo_task`],
//! [`P0Config::leo`]): what p0's authors' code does where the paper is silent (mid-step start,
//! 14 observed dimensions, 8.6 V, only drawn energy counted, an L2 penalty of 10⁻³ on the critic,
//! no update before 20 000 stored transitions). `stepping` and `standing` are the earlier
//! settings, which did not learn to walk (docs/p0.md): 17 observed dimensions (all but `x`), the
//! motors' full voltage, signed work, no critic penalty, updates after 100 transitions; starting
//! mid-step or standing. About 30 minutes on one core.

use tandem::agents::adapter::Feature;
use tandem::agents::{EpisodeRunner, StepOptions};
use tandem::algos::difference_models::{
    agent_spaces, ddpg_agent, leo_measures, leo_task, measured_episode, p0_loop, Method, P0Config,
};
use tandem::core::SeedStream;
use tandem::models::{ModelEnv, PlantModel};
use tandem::robots::{leo_parts, LeoModel, LeoStart};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let earlier = match args.get(1).map(String::as_str) {
        None | Some("authors") => None,
        Some("stepping") => Some(LeoStart::Stepping),
        Some("standing") => Some(LeoStart::Standing),
        Some(other) => {
            let e = format!("the mode is authors, stepping or standing, not {other}");
            return Err(e.into());
        }
    };
    let number = |i: usize, d: u64| -> Result<u64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    let (seed, steps) = (number(2, 0)?, number(3, 300_000)?);
    let mut cfg = P0Config::leo();
    if earlier.is_some() {
        // Observation indices: x 0, z 1, pitch 2, leg angles 3-8, ẋ 9, ż 10, pitch rate 11,
        // leg velocities 12-17. All but x: z in decimetres, angular velocities in 10 rad/s.
        cfg.features = std::iter::once(Feature::Linear {
            index: 1,
            scale: 10.0,
        })
        .chain((2..=10).map(|index| Feature::Linear { index, scale: 1.0 }))
        .chain((11..=17).map(|index| Feature::Linear { index, scale: 0.1 }))
        .collect();
        cfg.ddpg.critic_weight_decay = 0.0;
        cfg.ddpg.learning_starts = 100;
    }

    let biped = |model: LeoModel| -> Result<_, Box<dyn std::error::Error>> {
        let (plant, task) = match earlier {
            None => leo_task(model)?,
            Some(start) => {
                let (plant, task) = leo_parts(model)?;
                (plant, task.with_start(start)?)
            }
        };
        Ok((ModelEnv::new(PlantModel::new(plant), task.clone())?, task))
    };
    let (mut env, task) = biped(LeoModel::Idealized)?;
    let (mut idealized, _) = biped(LeoModel::Idealized)?;
    let (mut true_biped, true_task) = biped(LeoModel::True)?;

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
