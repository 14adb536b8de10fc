//! p2's Fig. 3 on its maze, from pixels: DQN (a convolutional Q-network on the 16×16 RGB frame)
//! learns from real episodes; the pixel model (four frames and the action in; next frame, reward
//! and termination out) is refit on all real transitions after each real episode; after the first
//! N = 100 real episodes, every real episode is followed by an episode imagined by the model,
//! started from the first frame of a real episode, whose transitions the agent learns from as if
//! they were real (same replay buffer, same update schedule).
//!
//! `cargo run --release --example p2_maze [seed] [real_episodes]` (defaults 0, 300).
//! `tandem reproduce p2-maze` runs the same loop (`tandem::algos::imagined_pixels`) over seeds.
use tandem::agents::{Dqn, EpisodeRunner, OffPolicyLoop, StepOptions};
use tandem::algos::imagined_pixels::maze_dqn;
use tandem::core::SeedStream;
use tandem::envs::{make, Env};
use tandem::models::{PixelEpisodes, PixelFit, PixelModel, PixelModelConfig, PixelModelEnv};

const N: u64 = 100; // real episodes before the first imagined one

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, episodes) = (arg(1).unwrap_or(0), arg(2).unwrap_or(300));
    let seeds = SeedStream::new(seed);
    let mut env = make("PixelMaze-v0")?; // 50-step episodes
    let (obs, act) = (env.observation_space().clone(), env.action_space().clone());
    let dqn = maze_dqn(); // the dqn_pixelmaze preset, constant learning rate
    let agent = Dqn::new(dqn.clone(), &obs, &act, seed)?;
    let mut lp = OffPolicyLoop::new(agent, dqn.schedule(), &obs, &act, seeds.rng("minibatches"))?;
    let model = PixelModel::new(PixelModelConfig::default())?;
    let mut dream = PixelModelEnv::new(model, vec![], Some(50))?;
    let mut data = PixelEpisodes::new(16 * 16 * 3);
    let (mut real, mut imagined) = (
        EpisodeRunner::new(seed, "real-episode-"),
        EpisodeRunner::new(seed, "imagined-episode-"),
    );
    let mut returns = Vec::new();
    for k in 0..episodes {
        // A real episode: the agent learns as it plays; its frames join the model's data.
        let (mut frames, mut actions, mut rewards) = (vec![], vec![], vec![]);
        let last = loop {
            let rec = lp.step(env.as_mut(), &mut real, StepOptions::real())?;
            if frames.is_empty() {
                frames.push(rec.obs.clone());
            }
            frames.push(rec.next_obs.clone());
            actions.push(rec.action.as_discrete().unwrap_or(0));
            rewards.push(rec.reward);
            if rec.done() {
                break rec;
            }
        };
        returns.push(last.episode_return);
        data.push_episode(&frames, &actions, &rewards, last.terminated)?;
        dream.add_start(frames[0].clone())?;
        // The model on minibatches drawn from all real transitions so far.
        let fit = PixelFit {
            seed: seeds.derive(&format!("fit-{k}")),
            ..PixelFit::default()
        };
        dream.model_mut().fit(&data, &fit)?;
        // After N real episodes: an imagined episode from a real first frame.
        if k >= N {
            while !lp
                .step(&mut dream, &mut imagined, StepOptions::model())?
                .done()
            {}
        }
        if (k + 1) % 50 == 0 {
            let tail = &returns[returns.len().saturating_sub(100)..];
            let mean = tail.iter().sum::<f64>() / tail.len() as f64;
            println!(
                "{} real episodes: mean return of the last 100 {mean:.1}",
                k + 1
            );
        }
    }
    let f1 = dream.model().f1(&data)?; // on its own training data: [obstacles, goal, agent]
    println!(
        "model F1 on the real transitions: obstacles {:.2}, goal {:.2}, agent {:.2}",
        f1[0], f1[1], f1[2]
    );
    Ok(())
}
