//! p2's Fig. 3 on CartPole-v1 with the `P2Config` defaults: REINFORCE (one hidden layer of 8
//! units) learns from real episodes; an MLP of `(s', r, done)` (2×256, SGD 0.01, eq. 1) is refit
//! on (a draw of) the real transitions as they come; after the first N = 100 real episodes,
//! every real episode is followed by an episode imagined by the model, with the model's own
//! reward and termination, started from the start state of a real episode. The loop body is
//! `ImaginedEpisodes::step` in `tandem::algos::imagined_episodes`; `tandem reproduce p2-cartpole`
//! runs it over seeds against REINFORCE alone.
//!
//! `cargo run --release --example p2_cartpole [seed] [real_episodes]` (defaults 0, 600).
use tandem::algos::imagined_episodes::{cartpole, Event, Method, P2Config};
use tandem::algos::Ephemeral;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, episodes) = (arg(1).unwrap_or(0), arg(2).unwrap_or(600));
    let cfg = P2Config {
        max_real_episodes: episodes,
        ..P2Config::default()
    };
    let window = cfg.solved_window;
    let mut show = |event| match event {
        Event::Real {
            episode,
            window_mean,
            ..
        } if (episode + 1) % 50 == 0 => {
            let n = episode + 1;
            println!("{n} real episodes: mean return of the last {window} {window_mean:.1}");
        }
        _ => {}
    };
    let record = cartpole(Method::WithModel, &cfg, seed, &mut Ephemeral, &mut show)?;
    println!("{record}");
    Ok(())
}
