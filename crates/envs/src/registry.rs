//! The environment registry: ids to constructors, as `gymnasium.make`.

use tandem_core::Space;

use crate::{
    CartPoleEnv, DcMotorPendulumEnv, Env, EnvError, Leg2REnv, Leg2RModel, LeoEnv, LeoModel,
    PendulumEnv, PendulumModel, PixelMazeEnv, TimeLimit, LEG2R_STEPS, LEO_STEPS,
};

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

/// (id, description, time limit) of every registered environment.
const REGISTRY: &[(&str, &str, usize)] = &[
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
    (
        DcMotorPendulumEnv::ID_IDEALIZED,
        "p0 DC-motor pendulum swing-up, idealized model (m = 0.055 kg)",
        400,
    ),
    (
        DcMotorPendulumEnv::ID_REAL,
        "p0 DC-motor pendulum swing-up, true model (m = 0.090 kg)",
        400,
    ),
    (
        PixelMazeEnv::ID,
        "p2's maze: reach the goal past patrolling obstacles, observed as 16x16 RGB images",
        50,
    ),
    (
        PixelMazeEnv::ID_V1,
        "p2's maze as the authors released it: 16x16 one-pixel cells, 5 obstacles, fixed start",
        100,
    ),
    (
        Leg2REnv::ID,
        "p3's 2R leg (0.15 m links, 3 N m, 500 Hz) tracking a semi-elliptical foot trajectory",
        LEG2R_STEPS,
    ),
    (
        Leg2REnv::ID_REAL,
        "p3's 2R leg, true model (shank 0.26 kg instead of 0.20, joint friction)",
        LEG2R_STEPS,
    ),
    (
        LeoEnv::ID,
        "p0's Leo-like biped walking on a boom (6 DC motors, 30 ms), idealized model",
        LEO_STEPS,
    ),
    (
        LeoEnv::ID_TRUE,
        "p0's Leo-like biped, true model (torso 1.25 kg instead of 0.942, joint friction)",
        LEO_STEPS,
    ),
];

/// The environment `id` without a time limit, or [`EnvError::Unknown`].
pub fn make_unwrapped(id: &str) -> Result<Box<dyn Env>, EnvError> {
    Ok(match id {
        CartPoleEnv::ID => Box::new(CartPoleEnv::new()),
        PendulumEnv::ID => Box::new(PendulumEnv::new()),
        DcMotorPendulumEnv::ID_IDEALIZED => {
            Box::new(DcMotorPendulumEnv::new(PendulumModel::Idealized))
        }
        DcMotorPendulumEnv::ID_REAL => Box::new(DcMotorPendulumEnv::new(PendulumModel::Real)),
        PixelMazeEnv::ID => Box::new(PixelMazeEnv::new()),
        PixelMazeEnv::ID_V1 => Box::new(PixelMazeEnv::v1()),
        Leg2REnv::ID => Box::new(Leg2REnv::new(Leg2RModel::Idealized)),
        Leg2REnv::ID_REAL => Box::new(Leg2REnv::new(Leg2RModel::Real)),
        LeoEnv::ID => Box::new(LeoEnv::new(LeoModel::Idealized)),
        LeoEnv::ID_TRUE => Box::new(LeoEnv::new(LeoModel::True)),
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
    let env = make_unwrapped(id)?;
    let (_, _, limit) = REGISTRY
        .iter()
        .find(|(rid, _, _)| *rid == id)
        .ok_or_else(|| EnvError::Unknown(id.to_string()))?;
    Ok(Box::new(TimeLimit::new(env, *limit)))
}

/// Every registered environment with its spaces, in registration order.
pub fn registered() -> Vec<EnvSpec> {
    REGISTRY
        .iter()
        .filter_map(|&(id, description, max_episode_steps)| {
            let env = make_unwrapped(id).ok()?;
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
        assert_eq!(
            limits,
            vec![500, 200, 400, 400, 50, 100, 1000, 1000, 667, 667]
        );
    }

    #[test]
    fn unknown_ids_are_errors_naming_the_id() {
        let err = make("Nope-v9").err().unwrap();
        assert_eq!(err, EnvError::Unknown("Nope-v9".into()));
        assert!(err.to_string().contains("Nope-v9"));
    }
}
