//! SAC, MBPO and M-DeMoRL on Pendulum-v1 (`P3Config::pendulum`) for a few seeds at one budget of
//! real steps, through `tandem::algos::m_demorl::run`: the return of each evaluation, the wall time
//! and SAC's update rate per run.
//!
//! `cargo run --release --example p3_compare [seeds] [real_steps] [first_seed]` (defaults 2,
//! 5000, 0).
use tandem::algos::m_demorl::{run, Method, P3Config};
use tandem::algos::mbpo::pendulum_problem;
use tandem::algos::Ephemeral;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let mut cfg = P3Config::pendulum();
    cfg.base.real_steps = arg(2).unwrap_or(5000);
    let problem = pendulum_problem();
    let first = arg(3).unwrap_or(0);
    for seed in first..first + arg(1).unwrap_or(2) {
        for method in Method::ALL {
            let r = run(method, &problem, &cfg, seed, &mut Ephemeral, &mut |_| {})?;
            let curve: Vec<String> = r
                .curve
                .iter()
                .map(|p| format!("{:.0}", p.eval_return))
                .collect();
            println!(
                "{:>8} seed {seed}: returns [{}] | {:.0} s, {} updates at {:.0}/s, {} imagined",
                method.name(),
                curve.join(", "),
                r.wall_seconds,
                r.updates,
                r.updates as f64 / r.update_seconds.max(1e-9),
                r.imagined
            );
        }
    }
    Ok(())
}
