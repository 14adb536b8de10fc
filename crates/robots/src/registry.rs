//! The papers' environments in the registry: ids to constructors, with time limits, after
//! `tandem-envs`' own (the facade's `make_env` asks `tandem-envs` first, then this crate).

use tandem_envs::{make_from, specs_of, Env, EnvError, EnvSpec, Registry};

use crate::{
    DcMotorPendulumEnv, DcMotorPendulumEnvExt, Leg2REnv, Leg2REnvExt, Leg2RModel, LeoEnv,
    LeoEnvExt, LeoModel, PendulumModel, PixelMazeEnv, LEG2R_STEPS, LEO_STEPS,
};

/// (id, description, time limit) of every environment of this crate, in registration order.
const REGISTRY: &Registry = &[
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

/// The environment `id` of this crate without a time limit, or [`EnvError::Unknown`].
pub fn make_unwrapped(id: &str) -> Result<Box<dyn Env>, EnvError> {
    Ok(match id {
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

/// The environment `id` of this crate with its registered time limit (as `gymnasium.make`), or
/// [`EnvError::Unknown`] (also for `tandem-envs`' own ids).
///
/// ```
/// let env = tandem_robots::make("Leg2R-v0").unwrap();
/// assert_eq!(env.max_episode_steps(), Some(1000));
/// assert!(tandem_robots::make("CartPole-v1").is_err());
/// ```
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    make_from(REGISTRY, make_unwrapped, id)
}

/// Every environment of this crate with its spaces, in registration order.
pub fn registered() -> Vec<EnvSpec> {
    specs_of(REGISTRY, make_unwrapped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_papers_environments_make_with_their_ids_and_limits() {
        let made: Vec<(String, Option<usize>)> = registered()
            .iter()
            .map(|s| {
                let env = make(s.id).unwrap();
                (env.id().to_string(), env.max_episode_steps())
            })
            .collect();
        let expected = [
            ("DcMotorPendulum-idealized-v0", 400),
            ("DcMotorPendulum-real-v0", 400),
            ("PixelMaze-v0", 50),
            ("PixelMaze-v1", 100),
            ("Leg2R-v0", 1000),
            ("Leg2R-real-v0", 1000),
            ("Leo-v0", 667),
            ("Leo-true-v0", 667),
        ]
        .map(|(id, limit)| (id.to_string(), Some(limit)));
        assert_eq!(made, expected);
        assert_eq!(
            make("CartPole-v1").err(),
            Some(EnvError::Unknown("CartPole-v1".into()))
        );
    }
}
