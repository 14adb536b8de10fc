//! M-DeMoRL (p3, Algorithm 1) on Pendulum-v1 with the `P3Config::pendulum` preset. The real
//! system is stepped with SAC's action (line 4); every 250 real steps the ensemble is refitted
//! on D_ENV (lines 5–7), D_MPC is emptied (line 8), and DMD-MPC plans from real states — 100
//! sequences sampled around SAC's own actions through the elites, the best 10% averaged into a
//! mirror-descent step, cost −r̂ with SAC's −V at the horizon — put their model rollouts in D_MPC
//! (lines 9–15); SAC then takes G updates on D_ENV ∪ D_MPC (lines 16–18). The outer loop is
//! MBPO's (`Mbpo::step`); the inner loop is `MpcPlans` in `tandem::algos::m_demorl`.
//!
//! `cargo run --release --example m_demorl [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::Sac;
use tandem::algos::driver::drive;
use tandem::algos::m_demorl::{MpcPlans, P3Config};
use tandem::algos::mbpo::{pendulum_problem, Event, Mbpo};
use tandem::algos::Ephemeral;
use tandem::core::SeedStream;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let mut cfg = P3Config::pendulum();
    cfg.base.real_steps = arg(2).unwrap_or(5000);
    let outer = cfg.m_demorl_loop();
    let problem = pendulum_problem();
    let t0 = std::time::Instant::now();

    // 1–2: SAC, the model f_φ, D_ENV, and the DMD-MPC inner loop that fills D_MPC.
    let mut inner = MpcPlans { cfg: cfg.clone() };
    let m_demorl = Mbpo::new(&problem, &outer, Some(&mut inner), seed, |obs, act| {
        let agent_seed = SeedStream::new(seed).derive("agent");
        Ok(Sac::new(outer.sac.clone(), obs, act, agent_seed)?)
    })?;
    // 3–18, one real step at a time.
    drive(m_demorl, &mut Ephemeral, &mut |event| {
        if let Event::Eval(p) = event {
            let secs = t0.elapsed().as_secs_f64();
            let h = cfg.horizon.at(outer.epoch_of(p.true_samples));
            println!(
                "{} real steps (H = {h}): eval return {:.1} ({secs:.0} s)",
                p.true_samples, p.eval_return
            );
        }
    })?;
    Ok(())
}
