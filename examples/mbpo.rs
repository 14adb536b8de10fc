//! MBPO (Janner et al. 2019, Algorithm 2) on Pendulum-v1 with the `MbpoConfig::pendulum` preset:
//! SAC acts in the real system; every 250 real steps the probabilistic ensemble is refitted on
//! `D_env` and branched rollouts of length `k` from real states fill `D_model`; SAC takes `G`
//! updates per real step on minibatches of 5% `D_env`, 95% `D_model`. The loop body is
//! `Mbpo::step` in `tandem::algos::mbpo`; `drive` runs it to the end (here without checkpoints).
//!
//! `cargo run --release --example mbpo [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::Sac;
use tandem::algos::driver::drive;
use tandem::algos::mbpo::{pendulum_problem, Event, Mbpo, MbpoConfig, Rollouts};
use tandem::algos::Ephemeral;
use tandem::core::SeedStream;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let cfg = MbpoConfig {
        real_steps: arg(2).unwrap_or(5000),
        ..MbpoConfig::pendulum()
    };
    let problem = pendulum_problem();
    let t0 = std::time::Instant::now();

    // The policy π (SAC), the model p (an ensemble), D_env and D_model, as one value.
    let mut rollouts = Rollouts::of(&cfg);
    let mbpo = Mbpo::new(&problem, &cfg, Some(&mut rollouts), seed, |obs, act| {
        let agent_seed = SeedStream::new(seed).derive("agent");
        Ok(Sac::new(cfg.sac.clone(), obs, act, agent_seed)?)
    })?;
    let record = drive(mbpo, &mut Ephemeral, &mut |event| {
        if let Event::Eval(p) = event {
            let secs = t0.elapsed().as_secs_f64();
            let k = cfg.rollout_length.at(cfg.epoch_of(p.true_samples));
            println!(
                "{} real steps (k = {k}): eval return {:.1} ({secs:.0} s)",
                p.true_samples, p.eval_return
            );
        }
    })?;
    println!(
        "{} real steps, {} imagined transitions, {} SAC updates",
        record.real_steps, record.imagined, record.updates
    );
    Ok(())
}
