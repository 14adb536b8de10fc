//! PETS (Chua et al. 2018) on Pendulum-v1 with the `PetsConfig::pendulum` preset: one random
//! episode, then every episode CEM-MPC through a 5-member probabilistic ensemble of the
//! observation change, 5 particles per sequence (TS-∞), scored by the pendulum's own reward; the
//! ensemble is refitted on all data after each episode. The loop is `Pets::step` in
//! `tandem::algos::pets`; `drive` runs it to the end (here without checkpoints).
//!
//! `cargo run --release --example pets -- [seed] [episodes]` (defaults 0, 10).
use tandem::algos::driver::drive;
use tandem::algos::mbpo::pendulum_problem;
use tandem::algos::pets::{Pets, PetsConfig};
use tandem::algos::Ephemeral;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let cfg = PetsConfig {
        episodes: arg(2).map_or(10, |n| n as usize),
        ..PetsConfig::pendulum()
    };
    let pets = Pets::new(&pendulum_problem(), &cfg, seed)?;
    let record = drive(pets, &mut Ephemeral, &mut |ep| {
        let loss = ep.fit.holdout_loss.unwrap_or(ep.fit.train_loss);
        println!(
            "episode {:2}{}: return {:8.1}   model: {} epochs, held-out NLL {loss:.3}",
            ep.episode + 1,
            if ep.random { " (random)" } else { "" },
            ep.episode_return,
            ep.fit.epochs,
        );
    })?;
    if let Some(mean) = record.mean_return(1..record.episodes.len()) {
        println!(
            "mean return over episodes 2-{}: {mean:.1}",
            record.episodes.len()
        );
    }
    if let Some(s) = record.act_seconds_per_step() {
        println!("planning: {:.1} ms per step", 1e3 * s);
    }
    println!("wall time: {:.0} s", record.wall_seconds);
    Ok(())
}
