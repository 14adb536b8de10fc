//! Dyna with a learned model, MBPO-style (Janner et al.; p1's Algorithm 1 with `horizon = 1`):
//! imagined transitions from branched model rollouts, started at real states and acted by the
//! agent's own exploring policy, go into the [`OffPolicyLoop`]'s second buffer, which the loop
//! mixes into every minibatch at its set fraction.
//!
//! The model works in the task's (canonical) state space and the agent in its observation
//! space; [`tandem_models::branched_rollouts`] maps between them with the [`Task`]. Real
//! transitions for the model are recorded with `StepOptions { record_states: true, .. }` and
//! [`tandem_models::TransitionsBuilder::push_canonical`]. `examples/dyna_sac.rs` is the whole
//! loop on Pendulum-v1.

use ndarray::{Array2, ArrayView2, Axis};
use rand::Rng as _;
use tandem_agents::{BatchPolicy, Mode, OffPolicyAgent, OffPolicyLoop, Store};
use tandem_core::Rng;
use tandem_envs::Task;
use tandem_models::{branched_rollouts, DynamicsModel, Judges, ModelError, Transitions};

use super::Result;

/// `n` states drawn uniformly (with replacement) from `data`: where branched rollouts start.
/// An error for empty data.
pub fn sample_starts(data: &Transitions, n: usize, rng: &mut Rng) -> Result<Array2<f64>> {
    if data.is_empty() {
        return Err(ModelError::Empty.into());
    }
    let idx: Vec<usize> = (0..n).map(|_| rng.random_range(0..data.len())).collect();
    Ok(data.states.select(Axis(0), &idx))
}

/// Rolls `model` under `task` for `horizon` steps from every row of `starts`, acting with the
/// loop's agent ([`BatchPolicy::act_batch`] in [`Mode::Explore`]), judged as `judges` say, and
/// stores every imagined transition in the loop's secondary buffer. Returns how many were
/// stored. The loop must have a secondary buffer ([`OffPolicyLoop::with_secondary`]).
pub fn imagine<A, M, T>(
    lp: &mut OffPolicyLoop<A>,
    model: &M,
    task: &T,
    judges: &Judges,
    starts: ArrayView2<'_, f64>,
    horizon: usize,
    rng: &mut Rng,
) -> Result<usize>
where
    A: OffPolicyAgent + BatchPolicy,
    M: DynamicsModel + ?Sized,
    T: Task + ?Sized,
{
    let agent = &lp.agent;
    let mut policy = |obs: ndarray::ArrayView2<'_, f64>, rng: &mut Rng| {
        agent
            .act_batch(obs, Mode::Explore, rng)
            .map_err(|e| ModelError::Other(format!("policy: {e}")))
    };
    let im = branched_rollouts(model, task, judges, starts, horizon, &mut policy, rng)?;
    lp.push_rows(
        Store::Secondary,
        im.observations.view(),
        im.actions.view(),
        im.rewards.view(),
        im.next_observations.view(),
        &im.terminated,
    )?;
    Ok(im.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_agents::{Sac, SacConfig};
    use tandem_core::seeding::rng_from_seed;
    use tandem_dynamics::classic::GymPendulum;
    use tandem_envs::PendulumTask;
    use tandem_models::{PlantModel, TransitionsBuilder};

    /// Imagined rollouts through the true plant store exactly what the real environment would
    /// give for the stored actions.
    #[test]
    fn imagined_transitions_through_the_plant_are_real_ones() {
        let plant = GymPendulum::default();
        let task = PendulumTask::new(plant.params());
        let cfg = SacConfig {
            hidden: vec![8],
            batch_size: 4,
            ..SacConfig::default()
        };
        let (o, a) = (
            task.observation_space().clone(),
            task.action_space().clone(),
        );
        let sac = Sac::new(cfg.clone(), &o, &a, 0).unwrap();
        let mut lp = OffPolicyLoop::new(sac, cfg.schedule(), &o, &a, rng_from_seed(1))
            .unwrap()
            .with_secondary(100, 0.5)
            .unwrap();
        let mut b = TransitionsBuilder::new(2, 1);
        b.push([0.5, 0.0], &[0.0], &[0.5, 0.1], -0.25, false)
            .unwrap();
        b.push([-2.0, 1.0], &[1.0], &[-2.0, 1.1], -4.0, false)
            .unwrap();
        let data = b.build();
        let mut rng = rng_from_seed(2);
        let starts = sample_starts(&data, 5, &mut rng).unwrap();
        assert!(starts
            .rows()
            .into_iter()
            .all(|r| r[0] == 0.5 || r[0] == -2.0));
        let n = imagine(
            &mut lp,
            &PlantModel::new(plant),
            &task,
            &Judges::default(),
            starts.view(),
            3,
            &mut rng,
        )
        .unwrap();
        assert_eq!(n, 15);
        let buf = lp.secondary().unwrap();
        assert_eq!(buf.len(), 15);
        for k in 0..15 {
            let t = buf.get(k).unwrap();
            let (c, s, w) = (
                t.obs[[0, 0]] as f64,
                t.obs[[0, 1]] as f64,
                t.obs[[0, 2]] as f64,
            );
            let u = t.actions[[0, 0]] as f64;
            assert!(u.abs() <= 2.0);
            let next = plant.step_array(&[s.atan2(c), w], u);
            // f32 storage: the observations agree to f32 precision.
            assert!(
                (t.next_obs[[0, 2]] as f64 - next[1]).abs() < 1e-4,
                "row {k}"
            );
            let r = tandem_envs::pendulum_reward(&[s.atan2(c), w], u);
            assert!((f64::from(t.rewards[0]) - r).abs() < 1e-3 * r.abs().max(1.0));
        }
        assert!(sample_starts(&Transitions::default(), 1, &mut rng).is_err());
    }
}
