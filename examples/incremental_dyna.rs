//! p1's Algorithm 1 (deep incremental model-based RL) on Pendulum-v1, line for line: SAC acts in
//! the real system; at the start of every epoch the incremental model
//! `ŝ' = s + L_θ(s, a_prev) (a − a_prev)` is trained on `D_env`; after every real step `M`
//! one-step model rollouts from real states (each with the real control before it) fill
//! `D_model`, scored with the task's reward; SAC takes `G` updates on minibatches of 5% `D_env`,
//! 95% `D_model`. `tandem::algos::incremental_dyna` is the same loop with checkpoints, exact sample counts
//! and the rollouts batched after each refit (`tandem reproduce p1` runs it on MuJoCo).
//!
//! `cargo run --release --example incremental_dyna [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::{evaluate, EpisodeRunner, OffPolicyLoop, Sac, StepOptions};
use tandem::algos::incremental_dyna::{IncrementalRollouts, P1Config};
use tandem::algos::mbpo::{pendulum_problem, Imagination, Imagine, MbpoConfig};
use tandem::core::SeedStream;
use tandem::envs::{control_dim, Task};
use tandem::models::{DynamicsModel, TransitionsBuilder};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let cfg = P1Config {
        base: MbpoConfig {
            real_steps: arg(2).unwrap_or(5000),
            ..MbpoConfig::pendulum()
        },
        ..P1Config::default()
    };
    let b = &cfg.base;
    let problem = pendulum_problem();
    let (task, seeds) = (&problem.task, SeedStream::new(seed));
    let (mut env, mut eval_env) = ((problem.env)()?, (problem.env)()?);
    let (obs, act) = (task.observation_space(), task.action_space());
    let (s_dim, u_dim) = (task.state_dim(), control_dim(task));
    let t0 = std::time::Instant::now();

    // 1: initialize policy π, predictive model f(θ), D_env and D_model (M rollouts a step).
    let sac = Sac::new(b.sac.clone(), obs, act, seeds.derive("agent"))?;
    let mut rollouts = IncrementalRollouts::of(&cfg);
    rollouts.rollouts.per_refit = 1;
    let mut f = rollouts
        .new_model(b, s_dim, u_dim, seeds.derive("model"))?
        .expect("the incremental model");
    let mut lp = OffPolicyLoop::new(sac, b.sac.schedule(), obs, act, seeds.rng("minibatches"))?
        .with_secondary(rollouts.capacity(b, 0), b.real_ratio)?;
    let mut d_env = TransitionsBuilder::new(s_dim, u_dim);
    let mut episodes = EpisodeRunner::new(seeds.derive("episodes"), "episode-");
    let mut rng = seeds.rng("imagination");
    let warmup = b.sac.learning_starts as u64;

    // 2: for N epochs (of E = epoch_length real steps).
    for t in 1..=b.real_steps {
        // 3: train f(θ) on D_env (loss (5) on the one-step-back data), once an epoch and as
        // soon as the random warm-up steps are in.
        if t > warmup && ((t - 1) % b.epoch_length == 0 || t == warmup + 1) {
            let all = d_env.clone().build();
            f.fit(
                &all,
                &b.fit_for(all.len(), seeds.derive(&format!("fit-{t}"))),
            )?;
        }
        // 5: take an action in the environment according to π; add it to D_env (with the
        // control before it, which the model conditions on).
        let opts = StepOptions::real().recording_states().without_updates();
        let rec = lp.step(env.as_mut(), &mut episodes, opts)?;
        let (x, x1) = rec.states.as_ref().expect("recorded");
        let u = task.control(&rec.action);
        d_env.push_canonical(task, x, &u, x1, rec.reward, rec.terminated, rec.done())?;
        if t > warmup {
            // 6–9: M one-step rollouts from states sampled uniformly from D_env, into D_model.
            let all = d_env.clone().build();
            let epoch = b.epoch_of(t);
            rollouts.imagine(&mut lp, Some(&mut f), task, &all, epoch, t, &mut rng)?;
            // 10–12: G gradient updates of π on D_env ∪ D_model.
            lp.update(b.updates_per_step)?;
        }
        if t % b.eval_every == 0 {
            let r = evaluate(
                &mut lp.agent,
                eval_env.as_mut(),
                b.eval_episodes,
                &seeds,
                None,
            )?;
            let mean = r.iter().sum::<f64>() / r.len() as f64;
            let secs = t0.elapsed().as_secs_f64();
            println!("{t} real steps: eval return {mean:.1} ({secs:.0} s)");
        }
    }
    Ok(())
}
