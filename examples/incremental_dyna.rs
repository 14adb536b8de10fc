//! p1's Algorithm 1 (deep incremental model-based RL) on Pendulum-v1: SAC acts in the real
//! system; the incremental model `ŝ' = s + L_θ(s, a_prev) (a − a_prev)` is trained on `D_env`
//! (one-step-back data); `M` one-step model rollouts per real step from real states (each with
//! the real control before it) fill `D_model`, scored with the task's reward; SAC takes `G`
//! updates on minibatches of 5% `D_env`, 95% `D_model`. It runs on MBPO's loop (`Mbpo::step`),
//! whose rollouts come in one batch after each refit (`M × model_train_freq` of them: the paper's
//! count); `IncrementalRollouts` in `tandem::algos::incremental_dyna` is the model and its
//! rollouts.
//!
//! `cargo run --release --example incremental_dyna [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::Sac;
use tandem::algos::driver::drive;
use tandem::algos::incremental_dyna::{IncrementalRollouts, P1Config};
use tandem::algos::mbpo::{pendulum_problem, Event, Mbpo, MbpoConfig};
use tandem::algos::Ephemeral;
use tandem::core::SeedStream;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let cfg = P1Config {
        base: MbpoConfig {
            real_steps: arg(2).unwrap_or(5000),
            ..MbpoConfig::pendulum()
        },
        ..P1Config::default()
    };
    let problem = pendulum_problem();
    let t0 = std::time::Instant::now();

    // 1: the policy π (SAC), the incremental model f(θ), D_env and D_model.
    let mut rollouts = IncrementalRollouts::of(&cfg);
    let dyna = Mbpo::new(
        &problem,
        &cfg.base,
        Some(&mut rollouts),
        seed,
        |obs, act| {
            let agent_seed = SeedStream::new(seed).derive("agent");
            Ok(Sac::new(cfg.base.sac.clone(), obs, act, agent_seed)?)
        },
    )?;
    // 2–12, one real step at a time.
    drive(dyna, &mut Ephemeral, &mut |event| {
        if let Event::Eval(p) = event {
            let secs = t0.elapsed().as_secs_f64();
            println!(
                "{} real steps: eval return {:.1} ({secs:.0} s)",
                p.true_samples, p.eval_return
            );
        }
    })?;
    Ok(())
}
