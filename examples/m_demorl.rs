//! M-DeMoRL (p3, Algorithm 1) on Pendulum-v1 with the `P3Config::pendulum` preset. The real
//! system is stepped with SAC's action (line 4); every 250 real steps the ensemble is refitted
//! on D_ENV (lines 5–7), D_MPC is emptied (line 8), and DMD-MPC plans from real states — 100
//! sequences sampled around SAC's own actions through the elites, the best 10% averaged into a
//! mirror-descent step, cost −r̂ with SAC's −V at the horizon — put their model rollouts in D_MPC
//! (lines 9–15); SAC then takes G updates on D_ENV ∪ D_MPC (lines 16–18).
//! `tandem::algos::m_demorl` is the same loop with checkpoints and exact sample counts.
//!
//! `cargo run --release --example m_demorl [seed] [real_steps]` (defaults 0, 5000).
use tandem::agents::{evaluate, EpisodeRunner, OffPolicyLoop, Sac, StepOptions};
use tandem::algos::m_demorl::{MpcPlans, P3Config};
use tandem::algos::mbpo::{pendulum_problem, Imagination, Imagine};
use tandem::core::SeedStream;
use tandem::envs::{control_dim, Task};
use tandem::models::{DynamicsModel, EnsembleConfig, ProbabilisticEnsemble, TransitionsBuilder};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let seed = arg(1).unwrap_or(0);
    let mut cfg = P3Config::pendulum();
    cfg.base.real_steps = arg(2).unwrap_or(5000);
    let b = cfg.m_demorl_loop();
    let problem = pendulum_problem();
    let (task, seeds) = (&problem.task, SeedStream::new(seed));
    let (mut env, mut eval_env) = ((problem.env)()?, (problem.env)()?);
    let (obs, act) = (task.observation_space(), task.action_space());
    let (s_dim, u_dim) = (task.state_dim(), control_dim(task));
    let t0 = std::time::Instant::now();

    // 1–2: initialize SAC, the model f_φ and D_ENV (and the DMD-MPC inner loop with D_MPC).
    let sac = Sac::new(b.sac.clone(), obs, act, seeds.derive("agent"))?;
    let mut inner = MpcPlans { cfg: cfg.clone() };
    let d_mpc = inner.capacity(&b, 0);
    let mut lp = OffPolicyLoop::new(sac, b.sac.schedule(), obs, act, seeds.rng("minibatches"))?
        .with_secondary(d_mpc, b.real_ratio)?;
    let ens = EnsembleConfig {
        seed: seeds.derive("model"),
        ..b.ensemble.clone()
    };
    let mut f_phi = ProbabilisticEnsemble::new(s_dim, u_dim, ens)?;
    let mut d_env = TransitionsBuilder::new(s_dim, u_dim);
    let mut episodes = EpisodeRunner::new(seeds.derive("episodes"), "episode-");
    let mut rng = seeds.rng("imagination");

    // 3: for max iterations (one real step each).
    for t in 1..=b.real_steps {
        // 4: D_ENV ← D_ENV ∪ {x, u, r, x'}, u ~ π_θ(x).
        let opts = StepOptions::real().recording_states().without_updates();
        let rec = lp.step(env.as_mut(), &mut episodes, opts)?;
        let (x, x1) = rec.states.as_ref().expect("recorded");
        let u = task.control(&rec.action);
        d_env.push_canonical(task, x, &u, x1, rec.reward, rec.terminated, rec.done())?;
        let epoch = b.epoch_of(t);
        if t % b.model_train_freq == 0 && t >= b.sac.learning_starts as u64 {
            // 5–7: train f_φ on D_ENV with the loss ‖{x' − x, r} − f_φ(x, u)‖.
            let all = d_env.clone().build();
            f_phi.fit(
                &all,
                &b.fit_for(all.len(), seeds.derive(&format!("fit-{t}"))),
            )?;
            // 8–15: initialize D_MPC; M and H from the schedules; DMD-MPC from x_{t,0} ~ D_ENV.
            lp.resize_secondary(inner.capacity(&b, epoch))?;
            inner.imagine(&mut lp, Some(&mut f_phi), task, &all, epoch, t, &mut rng)?;
        }
        // 16–18: update SAC on D_ENV ∪ D_MPC.
        if lp.primary().len() > b.sac.learning_starts {
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
            println!(
                "{t} real steps (H = {}): eval return {mean:.1} ({secs:.0} s)",
                cfg.horizon.at(epoch)
            );
        }
    }
    Ok(())
}
