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
    let window = cfg.solved_window;
    let mut show = |event| match event {
        Event::Real {
            episode,
            window_mean,
            ..
        } if (episode + 1) % 25 == 0 => {
            let n = episode + 1;
            println!("{n} real episodes: mean return of the last {window} {window_mean:.1}");
        }
        _ => {}
    };
    let record = run(Method::WithModel, &cfg, seed, &mut Ephemeral, &mut show)?;
    println!("{record}");
    Ok(())
}
