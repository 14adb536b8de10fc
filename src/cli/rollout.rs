//! `tandem rollout`: run a random or zero policy and print the returns (a non-finite return is
//! an error naming the episode, never a printed `NaN`).

use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rand::Rng as _;
use tandem::make_env as make;
use tandem_core::seeding::{Rng, SeedStream};
use tandem_envs::{Action, Env, SampleCounter, Space};

use super::{CliError, Result};

/// Which policy acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Policy {
    /// Uniform over a bounded action space (standard normal on unbounded components; uniform
    /// index for a discrete space), as gymnasium's `action_space.sample()`.
    Random,
    /// The zero vector (action 0 for a discrete space).
    Zero,
}

/// Arguments of `tandem rollout`.
#[derive(Debug, Args)]
pub struct RolloutArgs {
    /// Registered environment id (see `tandem envs`).
    #[arg(long)]
    pub env: String,
    /// Number of episodes.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub episodes: u64,
    /// Seed: the first reset uses it, the policy draws from a stream derived from it.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Policy.
    #[arg(long, value_enum, default_value_t = Policy::Random)]
    pub policy: Policy,
}

/// One action of `policy` in `space`.
pub fn sample_action(policy: Policy, space: &Space, rng: &mut Rng) -> Action {
    match (policy, space) {
        (Policy::Zero, Space::Discrete { .. }) => Action::Discrete(0),
        (Policy::Zero, Space::Box { low, .. }) => Action::Continuous(vec![0.0; low.len()]),
        (Policy::Random, Space::Discrete { n }) => Action::Discrete(rng.random_range(0..*n)),
        (Policy::Random, Space::Box { low, high, .. }) => Action::Continuous(
            low.iter()
                .zip(high)
                .map(|(&l, &h)| {
                    if l.is_finite() && h.is_finite() {
                        rng.random_range(l..=h)
                    } else {
                        // Box–Muller standard normal.
                        let (u1, u2): (f64, f64) = (1.0 - rng.random::<f64>(), rng.random());
                        let z = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
                        z.clamp(l, h)
                    }
                })
                .collect(),
        ),
    }
}

/// Runs the episodes, printing one line per episode and a summary.
pub fn run(args: &RolloutArgs) -> Result<()> {
    let (env, count) = SampleCounter::new(make(&args.env)?);
    let mut env = env;
    let mut rng = SeedStream::new(args.seed).rng("rollout-policy");
    let limit = env.max_episode_steps().unwrap_or(0) as u64;
    let bar = ProgressBar::new(args.episodes * limit.max(1));
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} steps ({per_sec}, eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let mut returns = Vec::with_capacity(args.episodes as usize);
    for episode in 0..args.episodes {
        bar.set_message(format!("episode {}/{}", episode + 1, args.episodes));
        env.reset(if episode == 0 { Some(args.seed) } else { None });
        let (mut ret, mut len) = (0.0, 0u64);
        loop {
            let a = sample_action(args.policy, env.action_space(), &mut rng);
            let step = env.step(&a)?;
            ret += step.reward;
            len += 1;
            bar.inc(1);
            if step.done() {
                break;
            }
        }
        if !ret.is_finite() {
            return Err(CliError::Other(format!(
                "{}: the return of episode {episode} is {ret}, not a finite number (step {len})",
                env.id()
            )));
        }
        bar.suspend(|| super::emit(&format!("episode {episode}: return {ret:.6} length {len}")))?;
        returns.push(ret);
    }
    bar.finish_and_clear();
    let n = returns.len() as f64;
    let mean = returns.iter().sum::<f64>() / n;
    let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    super::emit(&format!(
        "{}: mean return {mean:.6} (std {std:.6}) over {} episodes, {} real samples",
        env.id(),
        returns.len(),
        count.get()
    ))
}
