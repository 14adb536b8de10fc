//! p2's Fig. 3 on CartPole-v1: REINFORCE (one hidden layer of 8 units) learns from real
//! episodes; an MLP of `(s', r, done)` (2×256, SGD 0.01, eq. 1) is refit on the real transitions
//! as they come; after the first N = 100 real episodes, every real episode is followed by an
//! episode imagined by the model, with the model's own reward and termination, started from the
//! start state of a real episode.
//!
//! `cargo run --release --example p2_cartpole [seed] [real_episodes]` (defaults 0, 600).
//! `tandem reproduce p2-cartpole` runs the same loop (`tandem::algos::imagined_episodes`) over seeds.
use rand::Rng as _;
use tandem::agents::{EpisodicAgent, Reinforce, ReinforceConfig};
use tandem::algos::imagined_episodes::play;
use tandem::core::SeedStream;
use tandem::envs::{make, CartPoleTask, Env, Task};
use tandem::models::{DynamicsModel, FitConfig, Judges, MlpModel, MlpModelConfig, ModelEnv};
use tandem::models::{Transitions, TransitionsBuilder};

const N: u64 = 100; // real episodes before the first imagined one
const FIT_ROWS: usize = 2048; // each refit: 5 passes over this many real transitions drawn from all

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, episodes) = (arg(1).unwrap_or(0), arg(2).unwrap_or(600));
    let seeds = SeedStream::new(seed);
    let task = CartPoleTask::default();
    let mut env = make("CartPole-v1")?;
    let (obs_space, act_space) = (task.observation_space(), task.action_space());
    let mut agent = Reinforce::new(ReinforceConfig::default(), obs_space, act_space, seed)?;
    let model = MlpModel::new(4, 1, MlpModelConfig::default())?; // (x, ẋ, θ, θ̇) and the force
    let mut dream = ModelEnv::with_judges(model, task.clone(), Judges::model())?;
    let fit = FitConfig {
        epochs: 5,
        batch_size: 32,
        holdout_fraction: 0.0,
        seed,
    };
    let (mut real, mut starts, mut returns) = (Transitions::default(), Vec::new(), Vec::new());
    let mut rng = seeds.rng("imagined-starts");
    for k in 0..episodes {
        // A real episode: the policy learns from it, its transitions join the model's data.
        let obs = env.reset(Some(seeds.derive(&format!("real-episode-{k}"))));
        starts.push(env.state());
        let mut new = TransitionsBuilder::new(4, 1);
        let ep = play(env.as_mut(), &mut agent, obs, Some((&task, &mut new)))?;
        returns.push(ep.total_reward());
        agent.update(&[ep])?;
        real.extend(&new.build())?;
        // The model on (a draw of) all real transitions so far.
        let rows: Vec<usize> = (0..FIT_ROWS.min(real.len()))
            .map(|_| rng.random_range(0..real.len()))
            .collect();
        dream.model_mut().fit(&real.select(&rows), &fit)?;
        // After N real episodes: an imagined episode from a real start state.
        if k >= N {
            let start = &starts[rng.random_range(0..starts.len())];
            let obs = dream.set_state(start)?;
            let ep = play::<CartPoleTask>(&mut dream, &mut agent, obs, None)?;
            agent.update(&[ep])?;
        }
        if (k + 1) % 50 == 0 {
            let last = &returns[returns.len().saturating_sub(100)..];
            let mean = last.iter().sum::<f64>() / last.len() as f64;
            println!(
                "{} real episodes: mean return of the last 100 {mean:.1}",
                k + 1
            );
        }
    }
    Ok(())
}
