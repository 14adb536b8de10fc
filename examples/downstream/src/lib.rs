//! A pipeline of our own over `tandem` alone: a plant and a task that tandem does not ship, and
//! PETS (probabilistic ensemble, trajectory sampling, CEM) composed from tandem's parts.
//!
//! The plant is a cart on a rail pushed by a bounded force; the task brings it to rest at the
//! origin. PETS learns the cart from its own episodes and plans through what it learned, scored
//! by the task's own reward ([`Objective::from_task_observations`]); the same planner through
//! the true cart ([`PlantModel`]) is the yardstick.

use std::error::Error;

use tandem::prelude::*;

/// A cart on a frictionless rail: state `(p, v)`, force `u`, 0.05 s semi-implicit Euler steps.
pub struct Cart;

impl Plant for Cart {
    fn state_dim(&self) -> usize {
        2
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn dt(&self) -> f64 {
        0.05
    }
    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let v = x[1] + 0.05 * u[0];
        DVector::from_vec(vec![x[0] + 0.05 * v, v])
    }
}

/// Bring the cart to rest at the origin from up to a metre away, with a force of at most 1, in
/// 100 steps; leaving the 5 m rail ends the episode.
pub fn to_origin() -> FnTask {
    FnTask::new(
        "CartToOrigin-v0",
        Space::symmetric(2, 5.0),
        Space::symmetric(1, 1.0),
        |rng| vec![rng.random_range(-1.0..1.0), 0.0],
        |_x, u, next| -(next[0] * next[0] + 0.1 * next[1] * next[1] + 0.01 * u[0] * u[0]),
    )
    .with_termination(|next| next[0].abs() > 5.0)
    .with_max_episode_steps(100)
}

/// The planner every episode uses: CEM over 12 steps, each sequence scored by the mean over 5
/// particles (one per ensemble member, PETS's TS-∞).
pub fn planner() -> Result<Cem, Box<dyn Error>> {
    Ok(Cem::new(CemConfig {
        horizon: 12,
        population: 50,
        particles: 5,
        propagation: Some(Propagation::FixedMember),
        iterations: 3,
        bounds: Some(Bounds::symmetric(1, 1.0)),
        ..CemConfig::default()
    })?)
}

/// One episode from `seed`'s start, acting by `act(observation)`; returns its return and adds
/// its transitions to `data`.
pub fn episode(
    seed: u64,
    data: &mut TransitionsBuilder,
    mut act: impl FnMut(&[f64]) -> Result<Vec<f64>, Box<dyn Error>>,
) -> Result<f64, Box<dyn Error>> {
    let mut env = PlantEnv::from_parts(Cart, to_origin())?;
    let mut obs = env.reset(Some(seed));
    let mut total = 0.0;
    loop {
        let a = act(&obs)?;
        let step = env.step(&Action::Continuous(a.clone()))?;
        data.push(&obs, &a, &step.observation, step.reward, step.terminated)?;
        total += step.reward;
        if step.terminated || step.truncated {
            data.end_episode();
            return Ok(total);
        }
        obs = step.observation;
    }
}

/// PETS: one episode of random actions, then `episodes` episodes planned through an ensemble
/// refitted on everything seen before each. Returns every episode's return, the random one
/// first.
pub fn pets(seed: u64, episodes: usize) -> Result<Vec<f64>, Box<dyn Error>> {
    let objective = Objective::from_task_observations(to_origin())?;
    let mut data = TransitionsBuilder::new(2, 1);
    let mut rng = rng_from_seed(seed);
    let random = episode(seed, &mut data, |_| Ok(vec![rng.random_range(-1.0..1.0)]))?;
    let mut returns = vec![random];
    let mut model = ProbabilisticEnsemble::new(
        2,
        1,
        EnsembleConfig {
            members: 5,
            elites: 5,
            hidden: vec![32, 32],
            learn_reward: false,
            propagation: Propagation::FixedMember,
            seed,
            ..EnsembleConfig::default()
        },
    )?;
    let fit = FitConfig {
        epochs: 60,
        seed,
        ..FitConfig::default()
    };
    for e in 1..=episodes as u64 {
        model.fit(&data.clone().build(), &fit)?;
        let mut cem = planner()?;
        let ret = episode(seed + e, &mut data, |obs| {
            Ok(cem.plan(obs, &model, &objective)?.first_action())
        })?;
        returns.push(ret);
    }
    Ok(returns)
}

/// The return of the same planner through the true cart from `seed`'s start: what PETS would
/// reach with a perfect model.
pub fn planned_through_the_cart(seed: u64) -> Result<f64, Box<dyn Error>> {
    let objective = Objective::from_task(to_origin())?;
    let model = PlantModel::new(Cart);
    let mut cem = planner()?;
    let mut data = TransitionsBuilder::new(2, 1);
    episode(seed, &mut data, |obs| {
        Ok(cem.plan(obs, &model, &objective)?.first_action())
    })
}
