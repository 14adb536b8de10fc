//! p0 (Rastogi, Koryakovskiy and Kober), Fig. 2 on the DC-motor pendulum: pre-train DDPG on the
//! idealized model, then repeat { collect true samples with the previous policy + noise; fit the
//! difference model on all of them; retrain DDPG on idealized + difference, bootstrapped }. The
//! loop body is `DifferenceModels::step` in `tandem::algos::difference_models`; `run_seed`
//! pre-trains and drives it. Prints the return of the deterministic policy on the true system
//! after each iteration against the true samples used (evaluation episodes are not counted).
//!
//! `cargo run --release --example p0_difference_models [iterations] [seed]` (defaults 4, 0).
//! The comparison with cold and warm start over seeds is `tandem reproduce p0-pendulum`.

use tandem::algos::difference_models::{
    ddpg_agent, pendulum_problem, run_seed, Method, P0Config, Tick,
};
use tandem::algos::Ephemeral;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize, d: u64| {
        std::env::args()
            .nth(i)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (iterations, seed) = (arg(1, 4), arg(2, 0));
    let defaults = P0Config::default(); // p0 Sec. IV-C where the paper gives a value
    let cfg = P0Config {
        real_budget: iterations * defaults.real_batch,
        ..defaults
    };
    let problem = pendulum_problem();
    let t0 = std::time::Instant::now();
    let mut pretrained = false;
    let records = run_seed(
        &problem,
        &cfg,
        &[Method::Difference],
        seed,
        &|m, s| ddpg_agent(&cfg, &problem.real.task, m, s),
        &mut Ephemeral,
        &mut |tick| {
            if matches!(tick, Tick::True(..)) && !pretrained {
                pretrained = true;
                println!("pre-trained ({:.0} s)", t0.elapsed().as_secs_f64());
            }
        },
    )?;
    let r = &records[0];
    println!(
        "μ_idl on the true system: return {:.1}",
        r.curve[0].eval_return
    );
    for (i, (p, loss)) in r.curve[1..].iter().zip(&r.fit_holdout_loss).enumerate() {
        println!(
            "update {}: {} true samples, model held-out loss {loss:.4}, return on the true system {:.1}",
            i + 1,
            p.true_samples,
            p.eval_return
        );
    }
    println!("{:.0} s", t0.elapsed().as_secs_f64());
    Ok(())
}
