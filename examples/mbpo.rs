//! MBPO (Janner et al. 2019, Algorithm 2) on Pendulum-v1 with the `MbpoConfig::pendulum` preset:
//! SAC acts in the real system; every 250 real steps the probabilistic ensemble is refitted on
//! `D_env` and branched rollouts of length `k` from real states fill `D_model`; SAC takes `G`
//! updates per real step on minibatches of 5% `D_env`, 95% `D_model`. `tandem::algos::mbpo`
//! is the same loop with checkpoints and exact sample counts.
//!
//! `cargo run --release --example mbpo [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::{evaluate, EpisodeRunner, OffPolicyLoop, Sac, StepOptions};
use tandem::algos::mbpo::{pendulum_problem, Imagination, Imagine, MbpoConfig, Rollouts};
use tandem::core::SeedStream;
use tandem::envs::{control_dim, Task};
use tandem::models::{DynamicsModel, EnsembleConfig, ProbabilisticEnsemble, TransitionsBuilder};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let cfg = MbpoConfig {
        real_steps: arg(2).unwrap_or(5000),
        ..MbpoConfig::pendulum()
    };
    let problem = pendulum_problem();
    let (task, seeds) = (&problem.task, SeedStream::new(seed));
    let (mut env, mut eval_env) = ((problem.env)()?, (problem.env)()?);
    let (obs, act) = (task.observation_space(), task.action_space());
    let t0 = std::time::Instant::now();

    // Initialize policy π, predictive model p, environment dataset D_env, model dataset D_model.
    let sac = Sac::new(cfg.sac.clone(), obs, act, seeds.derive("agent"))?;
    let mut rollouts = Rollouts::of(&cfg);
    let d_model = rollouts.capacity(&cfg, 0);
    let mut lp = OffPolicyLoop::new(sac, cfg.sac.schedule(), obs, act, seeds.rng("minibatches"))?
        .with_secondary(d_model, cfg.real_ratio)?;
    let ens = EnsembleConfig {
        seed: seeds.derive("model"),
        ..cfg.ensemble.clone()
    };
    let mut model = ProbabilisticEnsemble::new(task.state_dim(), control_dim(task), ens)?;
    let mut d_env = TransitionsBuilder::new(task.state_dim(), control_dim(task));
    let mut episodes = EpisodeRunner::new(seeds.derive("episodes"), "episode-");
    let mut rng = seeds.rng("imagination");
    let warmup = cfg.sac.learning_starts as u64;

    for t in 1..=cfg.real_steps {
        // Take an action in the environment according to π; add it to D_env.
        let opts = StepOptions::real().recording_states().without_updates();
        let rec = lp.step(env.as_mut(), &mut episodes, opts)?;
        let (x, x1) = rec.states.as_ref().expect("recorded");
        let u = task.control(&rec.action);
        d_env.push_canonical(task, x, &u, x1, rec.reward, rec.terminated, rec.done())?;
        let epoch = cfg.epoch_of(t);
        if t % cfg.model_train_freq == 0 && t >= warmup {
            // Train the model p on D_env by maximum likelihood (elites by held-out error).
            let all = d_env.clone().build();
            model.fit(
                &all,
                &cfg.fit_for(all.len(), seeds.derive(&format!("fit-{t}"))),
            )?;
            // M rollouts per step: s uniformly from D_env, k steps with π, into D_model.
            lp.resize_secondary(rollouts.capacity(&cfg, epoch))?;
            rollouts.imagine(&mut lp, Some(&mut model), task, &all, epoch, t, &mut rng)?;
        }
        // G gradient updates of π on D_env ∪ D_model.
        if lp.primary().len() > cfg.sac.learning_starts {
            lp.update(cfg.updates_per_step)?;
        }
        if t % cfg.eval_every == 0 {
            let r = evaluate(
                &mut lp.agent,
                eval_env.as_mut(),
                cfg.eval_episodes,
                &seeds,
                None,
            )?;
            let mean = r.iter().sum::<f64>() / r.len() as f64;
            let secs = t0.elapsed().as_secs_f64();
            println!(
                "{t} real steps (k = {}): eval return {mean:.1} ({secs:.0} s)",
                rollouts.length.at(epoch)
            );
        }
    }
    Ok(())
}
