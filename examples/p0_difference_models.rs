//! p0 (Rastogi, Koryakovskiy and Kober), Fig. 2 on the DC-motor pendulum, top to bottom:
//! pre-train DDPG on the idealized model, then repeat { collect true samples with the previous
//! policy + noise; fit the difference model on all of them; retrain DDPG on idealized + difference,
//! bootstrapped }. Prints the return of the deterministic policy on the true system after each
//! iteration against the true samples used (evaluation episodes are not counted).
//!
//! `cargo run --release --example p0_difference_models [iterations] [seed]` (defaults 4, 0).
//! The comparison with cold and warm start over seeds is `tandem reproduce p0-pendulum`.

use tandem::agents::{EpisodeRunner, StepOptions};
use tandem::algos::difference_models::{
    agent_spaces, collect, ddpg_agent, mean_return, p0_loop, pendulum_problem, pretrain, Method,
    P0Config,
};
use tandem::envs::{make, SampleCounter};
use tandem::models::{DynamicsModel, FitConfig, ModelEnv, ResidualModel, Transitions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize, d: u64| {
        std::env::args()
            .nth(i)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (iterations, seed) = (arg(1, 4), arg(2, 0));
    let cfg = P0Config::default(); // p0 Sec. IV-C where the paper gives a value
    let problem = pendulum_problem();
    let task = problem.task.clone();
    let agent = ddpg_agent(&cfg, &task, Method::Difference, seed)?;
    let (obs, act) = agent_spaces(&task);
    let rng = tandem::core::seeding::rng_from_seed(seed);
    let mut ddpg = p0_loop(agent, &cfg.ddpg, &obs, &act, rng)?;
    let (mut true_system, count) = SampleCounter::new(make("DcMotorPendulum-real-v0")?);
    let mut eval_system = make("DcMotorPendulum-real-v0")?; // evaluation only, not counted
    let t0 = std::time::Instant::now();

    // Pre-train μ_idl on the idealized model f_idl, then explore with p0's σ = 0.12.
    pretrain(
        &mut ddpg,
        problem.idealized,
        task.clone(),
        cfg.pretrain_steps,
        seed,
        &mut || {},
    )?;
    ddpg.agent.set_noise(cfg.ddpg.noise)?;
    let r = mean_return(&mut ddpg.agent, eval_system.as_mut(), 1)?;
    println!(
        "μ_idl on the true system: return {r:.1} ({:.0} s)",
        t0.elapsed().as_secs_f64()
    );

    // The difference model d(s, a) = s'_true − f_idl(s, a), added to the idealized plant.
    let model = ResidualModel::new(problem.idealized, cfg.residual.clone())?;
    let mut idealized_plus_d = ModelEnv::new(model, task.clone())?;
    let mut buffer_d: Option<Transitions> = None; // D: all true samples, no size limit
    let mut episodes = EpisodeRunner::new(seed + 1, "ep");
    for i in 0..iterations {
        // 1. Collect 3750 true samples with μ(s; θ_{i-1}) + N.
        let new = collect(
            &mut ddpg,
            &mut true_system,
            &task,
            cfg.real_batch,
            seed + 2 + i,
            &mut || {},
        )?;
        match &mut buffer_d {
            Some(d) => d.extend(&new)?,
            None => buffer_d = Some(new),
        }
        // 2. Learn the difference model on the whole buffer D.
        let fit = FitConfig {
            seed: seed + 100 + i,
            ..cfg.fit.clone()
        };
        let report = idealized_plus_d
            .model_mut()
            .fit(buffer_d.as_ref().unwrap(), &fit)?;
        // 3. DDPG on f_idl + d, bootstrapped from the previous actor, critic and replay buffer.
        let sim = StepOptions::model();
        ddpg.train(
            &mut idealized_plus_d,
            &mut episodes,
            cfg.model_steps,
            sim,
            &mut |_| {},
        )?;
        let r = mean_return(&mut ddpg.agent, eval_system.as_mut(), 1)?;
        println!(
            "update {}: {} true samples, model held-out loss {:.4}, return on the true system {r:.1} ({:.0} s)",
            i + 1,
            count.get(),
            report.holdout_loss.last().unwrap_or(&f64::NAN),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
