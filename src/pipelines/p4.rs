//! p4 (Chebotar et al., PILQR) on its MuJoCo manipulation tasks: the problems the GPS loop
//! ([`super::gps`]) trains local controllers on.
//!
//! The gripper pusher ([`pusher_problem`]): the scene `p4_pusher.xml` as a [`MujocoPlant`]
//! (state `qpos ++ qvel`, 0.05 s control), [`tandem_mujoco::p4::PUSHER_CONDITIONS`] as the
//! conditions, [`PusherCost`] as every condition's cost (its terminal cost the last step's
//! distance terms), and the final block–goal distance as the measure.

use nalgebra::{DMatrix, DVector};
use tandem_mujoco::p4::{
    PusherCondition, PusherCost, PUSHER_ACTION_DIM, PUSHER_CONDITIONS, PUSHER_HORIZON,
    PUSHER_STATE_DIM,
};
use tandem_planners::{Objective, QuadCost, QuadTerminal};

use super::gps::{Condition, LocalProblem};
use super::{PipelineError, Result};

/// The pusher's objective for one condition, with the cost's Gauss–Newton expansion
/// ([`PusherCost::state_expansion`]) as its derivatives.
pub fn pusher_objective(cond: PusherCondition, cost: PusherCost, horizon: usize) -> Objective {
    let m = PUSHER_ACTION_DIM;
    Objective::time_varying(PUSHER_STATE_DIM, m, move |x, u, t| {
        cost.running(&cond, horizon, x, u, t)
    })
    .with_terminal(move |x| cost.terminal(&cond, x))
    .with_running_derivatives(move |x, u, t| {
        let (c, cx, cxx) = cost.state_expansion(&cond, horizon, x, t);
        let u = DVector::from_column_slice(u);
        QuadCost {
            c: c + cost.action * u.norm_squared(),
            cx,
            cu: &u * (2.0 * cost.action),
            cxx,
            cuu: DMatrix::identity(m, m) * (2.0 * cost.action),
            cux: DMatrix::zeros(m, PUSHER_STATE_DIM),
        }
    })
    .with_terminal_derivatives(move |x| {
        let (c, cx, cxx) = cost.state_expansion(&cond, 1, x, 0);
        QuadTerminal { c, cx, cxx }
    })
}

/// The gripper pusher's four conditions on MuJoCo, with `cost`. Needs the feature `mujoco`;
/// without it, an error saying so.
pub fn pusher_problem(cost: PusherCost) -> Result<LocalProblem> {
    cost.validate().map_err(PipelineError::Config)?;
    let conditions = PUSHER_CONDITIONS
        .iter()
        .map(|c| Condition {
            x0: c.initial_state(),
            objective: pusher_objective(*c, cost, PUSHER_HORIZON),
        })
        .collect();
    Ok(LocalProblem {
        system: pusher_system()?,
        conditions,
        horizon: PUSHER_HORIZON,
        measure: Box::new(|c, x| PUSHER_CONDITIONS[c].block_goal_distance(x)),
    })
}

#[cfg(feature = "mujoco")]
fn pusher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    use tandem_mujoco::p4::{scene_path, PUSHER_FRAME_SKIP, PUSHER_SCENE};
    let plant = tandem_mujoco::MujocoPlant::from_xml(scene_path(PUSHER_SCENE), PUSHER_FRAME_SKIP)
        .map_err(|e| PipelineError::Config(e.to_string()))?;
    Ok(Box::new(tandem_models::PlantModel::new(plant)))
}

#[cfg(not(feature = "mujoco"))]
fn pusher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    Err(PipelineError::Config(
        "p4's pusher needs a build with `--features mujoco` after scripts/setup-mujoco.sh".into(),
    ))
}
