//! Dyna-style SAC with a learned model on Pendulum-v1 (MBPO's loop in miniature, p1 Algorithm 1's
//! shape): every real step goes to D_env; every `FIT_EVERY` steps an MLP model of the state
//! change is refitted on all real transitions and branched rollouts from real states fill
//! D_model; SAC takes `G` updates per real step on minibatches mixing both.
//!
//! `cargo run --release --example dyna_sac [seed] [real_steps] [G]` (defaults 0, 5000, 10).
use tandem::agents::{
    evaluate, Agent, EpisodeRunner, Mode, OffPolicyLoop, Sac, SacConfig, StepOptions, Store,
};
use tandem::core::SeedStream;
use tandem::dynamics::classic::GymPendulumParams;
use tandem::envs::{make, PendulumTask, Task};
use tandem::models::{
    branched_rollouts, DynamicsModel, FitConfig, Judges, MlpModel, MlpModelConfig, OptimizerConfig,
    TransitionsBuilder,
};

const FIT_EVERY: u64 = 250; // real steps between model fits (and rollout batches)
const ROLLOUTS: usize = 2000; // branched rollouts per batch, from random real states
const HORIZON: usize = 3; // their length (MBPO's k)

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize, d: u64| {
        std::env::args()
            .nth(i)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (seed, real_steps, g) = (arg(1, 0), arg(2, 5000), arg(3, 10) as usize);
    let (mut env, mut eval_env) = (make("Pendulum-v1")?, make("Pendulum-v1")?);
    let task = PendulumTask::new(&GymPendulumParams::default()); // Pendulum-v1's own rules
    let seeds = SeedStream::new(seed);
    let cfg = SacConfig {
        learning_rate: 1e-3,
        learning_starts: 250,
        ..SacConfig::default()
    };
    let (obs, act) = (env.observation_space().clone(), env.action_space().clone());
    let sac = Sac::new(cfg.clone(), &obs, &act, seeds.derive("agent"))?;
    // Minibatches: 10% real transitions (D_env), 90% imagined (D_model) once there are any.
    let mut lp = OffPolicyLoop::new(sac, cfg.schedule(), &obs, &act, seeds.rng("minibatches"))?
        .with_secondary(ROLLOUTS * HORIZON * 4, 0.1)?;
    let mcfg = MlpModelConfig {
        hidden: vec![200, 200],
        optimizer: OptimizerConfig::adam(1e-3),
        learn_reward: false,
        learn_termination: false,
        ..MlpModelConfig::default()
    };
    let mut model = MlpModel::new(2, 1, mcfg)?;
    let mut data = TransitionsBuilder::new(2, 1);
    let mut episodes = EpisodeRunner::new(seeds.derive("episodes"), "ep");
    let mut rng = seeds.rng("rollouts");
    for t in 1..=real_steps {
        // One real step (random during SAC's warm-up), kept in canonical states for the model.
        let opts = StepOptions {
            learn: false,
            record_states: true,
            ..StepOptions::real()
        };
        let rec = lp.step(&mut env, &mut episodes, opts)?;
        let (x, x1) = rec.states.as_ref().expect("recorded");
        let u = task.control(&rec.action);
        data.push_canonical(&task, x, &u, x1, rec.reward, rec.terminated, rec.done())?;
        if t % FIT_EVERY == 0 {
            // Refit the model on all real data, then imagine from random real states.
            let all = data.clone().build();
            model.fit(
                &all,
                &FitConfig {
                    epochs: 20,
                    seed: t,
                    ..FitConfig::default()
                },
            )?;
            let idx: Vec<usize> = (0..ROLLOUTS)
                .map(|_| rand::Rng::random_range(&mut rng, 0..all.len()))
                .collect();
            let starts = all.states.select(ndarray::Axis(0), &idx);
            let agent = &mut lp.agent;
            let mut policy = |o: ndarray::ArrayView2<'_, f64>, _: &mut tandem::core::Rng| {
                let rows: Result<Vec<f64>, _> = o
                    .rows()
                    .into_iter()
                    .map(|r| {
                        agent
                            .act(r.as_slice().unwrap(), Mode::Explore)
                            .map(|a| a.as_continuous().unwrap()[0])
                    })
                    .collect();
                Ok(ndarray::Array2::from_shape_vec(
                    (o.nrows(), 1),
                    rows.map_err(|e| tandem::models::ModelError::Other(e.to_string()))?,
                )
                .unwrap())
            };
            let im = branched_rollouts(
                &model,
                &task,
                &Judges::default(),
                starts.view(),
                None,
                HORIZON,
                &mut policy,
                &mut rng,
            )?;
            let ob = (
                im.observations.view(),
                im.actions.view(),
                im.rewards.view(),
                im.next_observations.view(),
            );
            lp.push_rows(Store::Secondary, ob.0, ob.1, ob.2, ob.3, &im.terminated)?;
        }
        if lp.primary().len() > cfg.learning_starts {
            lp.update(g)?;
        }
        if t % 1000 == 0 {
            let r = evaluate(&mut lp.agent, eval_env.as_mut(), 10, &seeds, None)?;
            println!(
                "{t} real steps: eval return {:.1}",
                r.iter().sum::<f64>() / 10.0
            );
        }
    }
    Ok(())
}
