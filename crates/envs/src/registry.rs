//! The environment registry: ids to constructors, as `gymnasium.make`.

use tandem_core::Space;

use crate::{CartPoleEnv, Env, EnvError, PendulumEnv, TimeLimit};

/// One registered environment: its id, what it is, its episode limit and its spaces.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvSpec {
    /// The id [`make`] accepts.
    pub id: &'static str,
    /// One line on what the environment is.
    pub description: &'static str,
    /// The [`TimeLimit`] [`make`] adds.
    pub max_episode_steps: usize,
    /// Observation space.
    pub observation_space: Space,
    /// Action space.
    pub action_space: Space,
}

/// A registry's table: (id, description, time limit) of each environment, in registration order.
/// Crates with environments of their own (`tandem-robots`) keep one and build their `make` and
/// `registered` with [`make_from`] and [`specs_of`].
pub type Registry = [(&'static str, &'static str, usize)];

/// (id, description, time limit) of every registered environment.
const REGISTRY: &Registry = &[
    (
        CartPoleEnv::ID,
        "gymnasium CartPole-v1: balance a pole on a cart, push left or right",
        500,
    ),
    (
        PendulumEnv::ID,
        "gymnasium Pendulum-v1: swing up and hold a torque-limited pendulum",
        200,
    ),
];

/// The environment `id` without a time limit, or [`EnvError::Unknown`].
pub fn make_unwrapped(id: &str) -> Result<Box<dyn Env>, EnvError> {
    Ok(match id {
        CartPoleEnv::ID => Box::new(CartPoleEnv::new()),
        PendulumEnv::ID => Box::new(PendulumEnv::new()),
        _ => return Err(EnvError::Unknown(id.to_string())),
    })
}

/// The environment `id` with its registered [`TimeLimit`] (as `gymnasium.make`), or
/// [`EnvError::Unknown`].
///
/// ```
/// let mut env = tandem_envs::make("CartPole-v1").unwrap();
/// env.reset(Some(0));
/// assert_eq!(env.max_episode_steps(), Some(500));
/// assert!(tandem_envs::make("CartPole-v0").is_err());
/// ```
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    make_from(REGISTRY, make_unwrapped, id)
}

/// Every registered environment with its spaces, in registration order.
pub fn registered() -> Vec<EnvSpec> {
    specs_of(REGISTRY, make_unwrapped)
}

/// `make` of a registry: the environment `id` of `table`, made by `unwrapped`, in its
/// [`TimeLimit`]; [`EnvError::Unknown`] for an id the table does not hold.
pub fn make_from(
    table: &Registry,
    unwrapped: fn(&str) -> Result<Box<dyn Env>, EnvError>,
    id: &str,
) -> Result<Box<dyn Env>, EnvError> {
    let env = unwrapped(id)?;
    let (_, _, limit) = table
        .iter()
        .find(|(rid, _, _)| *rid == id)
        .ok_or_else(|| EnvError::Unknown(id.to_string()))?;
    Ok(Box::new(TimeLimit::new(env, *limit)))
}

/// `registered` of a registry: every environment of `table` with its spaces (read from the
/// environment `unwrapped` makes), in the table's order.
pub fn specs_of(
    table: &Registry,
    unwrapped: fn(&str) -> Result<Box<dyn Env>, EnvError>,
) -> Vec<EnvSpec> {
    table
        .iter()
        .filter_map(|&(id, description, max_episode_steps)| {
            let env = unwrapped(id).ok()?;
            Some(EnvSpec {
                id,
                description,
                max_episode_steps,
                observation_space: env.observation_space().clone(),
                action_space: env.action_space().clone(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_registered_id_makes_an_env_with_its_limit() {
        let specs = registered();
        assert_eq!(specs.len(), REGISTRY.len());
        for spec in specs {
            let env = make(spec.id).unwrap();
            assert_eq!(env.id(), spec.id);
            assert_eq!(env.max_episode_steps(), Some(spec.max_episode_steps));
            assert_eq!(env.action_space(), &spec.action_space);
        }
        let limits: Vec<usize> = registered().iter().map(|s| s.max_episode_steps).collect();
        assert_eq!(limits, vec![500, 200]);
    }

    #[test]
    fn unknown_ids_are_errors_naming_the_id() {
        let err = make("Nope-v9").err().unwrap();
        assert_eq!(err, EnvError::Unknown("Nope-v9".into()));
        assert!(err.to_string().contains("Nope-v9"));
    }
}
