//! SAC with a learned model in MBPO-style Dyna on Pendulum-v1 (p1's Algorithm 1 in shape):
//! every real step goes to D_env; every `FIT_EVERY` steps an MLP of the state change is refitted
//! on all real transitions and branched rollouts from real states fill D_model; SAC takes `G`
//! updates per real step on minibatches of 10% D_env, 90% D_model.
//!
//! `cargo run --release --example dyna_sac [seed] [real_steps] [G]` (defaults 0, 5000, 10).
use tandem::agents::{evaluate, EpisodeRunner, OffPolicyLoop, Sac, SacConfig, StepOptions};
use tandem::algos::dyna::{imagine, sample_starts};
use tandem::core::SeedStream;
use tandem::dynamics::classic::GymPendulumParams;
use tandem::envs::{make, PendulumTask, Task};
use tandem::models::{DynamicsModel, FitConfig, Judges, MlpModel, MlpModelConfig};
use tandem::models::{OptimizerConfig, TransitionsBuilder};

const FIT_EVERY: u64 = 250; // real steps between model fits and rollout batches
const ROLLOUTS: usize = 2000; // branched rollouts per batch, from random real states
const HORIZON: usize = 3; // their length (MBPO's k)

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, real_steps) = (arg(1).unwrap_or(0), arg(2).unwrap_or(5000));
    let g = arg(3).unwrap_or(10) as usize;
    let (mut env, mut eval_env) = (make("Pendulum-v1")?, make("Pendulum-v1")?);
    let task = PendulumTask::new(&GymPendulumParams::default()); // Pendulum-v1's own rules
    let seeds = SeedStream::new(seed);
    let (obs, act) = (env.observation_space().clone(), env.action_space().clone());
    let cfg = SacConfig {
        learning_rate: 1e-3,
        learning_starts: 250,
        ..SacConfig::default()
    };
    let sac = Sac::new(cfg.clone(), &obs, &act, seeds.derive("agent"))?;
    let mut lp = OffPolicyLoop::new(sac, cfg.schedule(), &obs, &act, seeds.rng("minibatches"))?
        .with_secondary(4 * ROLLOUTS * HORIZON, 0.1)?;
    let mcfg = MlpModelConfig {
        hidden: vec![200, 200],
        optimizer: OptimizerConfig::adam(1e-3),
        ..MlpModelConfig::state_only()
    };
    let fit = FitConfig {
        epochs: 20,
        ..FitConfig::default()
    };
    let mut model = MlpModel::new(2, 1, mcfg)?; // (θ, θ̇) and the torque
    let mut data = TransitionsBuilder::new(2, 1);
    let mut episodes = EpisodeRunner::new(seeds.derive("episodes"), "ep");
    let (mut rng, judges) = (seeds.rng("rollouts"), Judges::default()); // reward from the task
    for t in 1..=real_steps {
        // One real step (random during SAC's warm-up); its states go to the model's data.
        let opts = StepOptions::real().recording_states().without_updates();
        let rec = lp.step(&mut env, &mut episodes, opts)?;
        let (x, x1) = rec.states.as_ref().expect("recorded");
        let u = task.control(&rec.action);
        data.push_canonical(&task, x, &u, x1, rec.reward, rec.terminated, rec.done())?;
        if t % FIT_EVERY == 0 {
            let all = data.clone().build();
            model.fit(
                &all,
                &FitConfig {
                    seed: t,
                    ..fit.clone()
                },
            )?;
            let starts = sample_starts(&all, ROLLOUTS, &mut rng)?;
            imagine(&mut lp, &model, &task, &judges, &starts, HORIZON, &mut rng)?;
        }
        if lp.primary().len() > cfg.learning_starts {
            lp.update(g)?;
        }
        if t % 1000 == 0 {
            let r = evaluate(&mut lp.agent, eval_env.as_mut(), 10, &seeds, None)?;
            let mean = r.iter().sum::<f64>() / 10.0;
            println!("{t} real steps: eval return {mean:.1}");
        }
    }
    Ok(())
}
