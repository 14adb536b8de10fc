//! SAC with a learned model in MBPO-style Dyna on Pendulum-v1 (p1's Algorithm 1 in shape), as a
//! composition: MBPO's loop (`Mbpo`) with an imagination of our own, `MlpRollouts`, which fits an
//! MLP of the state change (not MBPO's ensemble) and fills `D_model` with branched rollouts from
//! real states. Every real step goes to `D_env`; every `FIT_EVERY` steps the MLP is refitted on all
//! real transitions and `ROLLOUTS` rollouts of `HORIZON` steps follow; SAC takes `G` updates per
//! real step on minibatches of 10% `D_env`, 90% `D_model`.
//!
//! `cargo run --release --example dyna_sac [seed] [real_steps] [G]` (defaults 0, 5000, 10).
use tandem::agents::{BatchPolicy, OffPolicyAgent, OffPolicyLoop, Sac, SacConfig};
use tandem::algos::driver::drive;
use tandem::algos::dyna::{imagine, sample_starts};
use tandem::algos::mbpo::{pendulum_problem, Event, Imagination, Imagine, Mbpo, MbpoConfig};
use tandem::algos::{AlgoError, Ephemeral, Result};
use tandem::core::{Rng, SeedStream};
use tandem::envs::Task;
use tandem::models::{FitConfig, Judges, MlpModel, MlpModelConfig, OptimizerConfig, Transitions};

const FIT_EVERY: u64 = 250; // real steps between model fits and rollout batches
const ROLLOUTS: usize = 2000; // branched rollouts per batch, from random real states
const HORIZON: usize = 3; // their length (MBPO's k)

/// Branched rollouts through an MLP of the state change; reward and termination from the task.
struct MlpRollouts;

impl Imagination for MlpRollouts {
    type Model = MlpModel;

    fn name(&self) -> &'static str {
        "dyna_sac"
    }

    /// Four batches of rollouts.
    fn capacity(&self, _cfg: &MbpoConfig, _epoch: u64) -> usize {
        4 * ROLLOUTS * HORIZON
    }

    fn horizon(&self, _epoch: u64) -> usize {
        HORIZON
    }

    fn new_model(&self, _: &MbpoConfig, s: usize, u: usize, seed: u64) -> Result<Option<MlpModel>> {
        let cfg = MlpModelConfig {
            hidden: vec![200, 200],
            optimizer: OptimizerConfig::adam(1e-3),
            seed,
            ..MlpModelConfig::state_only()
        };
        Ok(Some(MlpModel::new(s, u, cfg)?))
    }
}

impl<T: Task, A: OffPolicyAgent + BatchPolicy> Imagine<T, A> for MlpRollouts {
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<A>,
        model: Option<&mut MlpModel>,
        task: &T,
        data: &Transitions,
        _epoch: u64,
        _seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let model = model.ok_or_else(|| AlgoError::Config("no model to roll out".into()))?;
        let starts = sample_starts(data, ROLLOUTS, rng)?;
        imagine(
            lp,
            &*model,
            task,
            &Judges::default(),
            starts.view(),
            HORIZON,
            rng,
        )
    }
}

fn main() -> std::result::Result<(), Box<dyn std::error::Error>> {
    let arg = |i: usize| std::env::args().nth(i).and_then(|s| s.parse::<u64>().ok());
    let (seed, real_steps) = (arg(1).unwrap_or(0), arg(2).unwrap_or(5000));
    let cfg = MbpoConfig {
        sac: SacConfig {
            learning_rate: 1e-3,
            learning_starts: 250,
            ..SacConfig::default()
        },
        model_fit: FitConfig {
            epochs: 20,
            ..FitConfig::default()
        },
        model_min_updates: 0,
        real_steps,
        model_train_freq: FIT_EVERY,
        real_ratio: 0.1,
        updates_per_step: arg(3).unwrap_or(10) as usize,
        eval_episodes: 10,
        ..MbpoConfig::default()
    };
    let problem = pendulum_problem(); // Pendulum-v1 with its own rules as the model's task
    let mut rollouts = MlpRollouts;
    let dyna = Mbpo::new(&problem, &cfg, Some(&mut rollouts), seed, |obs, act| {
        let agent_seed = SeedStream::new(seed).derive("agent");
        Ok(Sac::new(cfg.sac.clone(), obs, act, agent_seed)?)
    })?;
    drive(dyna, &mut Ephemeral, &mut |event| {
        if let Event::Eval(p) = event {
            println!(
                "{} real steps: eval return {:.1}",
                p.true_samples, p.eval_return
            );
        }
    })?;
    Ok(())
}
