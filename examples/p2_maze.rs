//! p2's Fig. 3 on its maze, from pixels, with the `MazeConfig` defaults: DQN (a convolutional
//! Q-network on the 16×16 RGB frame) learns from real episodes; the pixel model (four frames and
//! the action in; next frame, reward and termination out) is refit on all real transitions; after
//! the first N real episodes, every real episode is followed by an episode imagined by the model,
//! started from the first frame of a real episode, whose transitions the agent learns from as if
//! they were real (same replay buffer, same update schedule). The loop body is `PixelDqn::step`
//! in `tandem::algos::imagined_pixels`; `tandem reproduce p2-maze` runs it over seeds against DQN
//! alone.
//!
//! `cargo run --release --example p2_maze [seed] [real_episodes]` (defaults 0, 300).
use tandem::algos::imagined_episodes::{Event, Method};
use tandem::algos::imagined_pixels::{run, MazeConfig};
use tandem::algos::Ephemeral;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, episodes) = (arg(1).unwrap_or(0), arg(2).unwrap_or(300));
    let cfg = MazeConfig {
        max_real_episodes: episodes,
        ..MazeConfig::default()
    };
    let mut returns = Vec::new();
    let record = run(
        Method::WithModel,
        &cfg,
        seed,
        &mut Ephemeral,
        &mut |event| {
            if let Event::Real { episode, ret, .. } = event {
                returns.push(ret);
                if (episode + 1) % 25 == 0 {
                    let last = &returns[returns.len().saturating_sub(25)..];
                    let mean = last.iter().sum::<f64>() / last.len() as f64;
                    println!(
                        "{} real episodes: mean return of the last 25 {mean:.1}",
                        episode + 1
                    );
                }
            }
        },
    )?;
    match record.solved_at {
        Some(k) => println!(
            "solved after {k} real episodes ({} imagined)",
            record.imagined_episodes
        ),
        None => println!("not solved in {} real episodes", record.real_returns.len()),
    }
    Ok(())
}
