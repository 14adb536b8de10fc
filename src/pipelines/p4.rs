//! p4 (Chebotar et al., PILQR) on its MuJoCo manipulation tasks: the problems the GPS loop
//! ([`super::gps`]) trains local controllers on.
//!
//! The gripper pusher ([`pusher_problem`]): the scene `p4_pusher.xml` as a `MujocoPlant`
//! (state `qpos ++ qvel`, 0.05 s control), [`tandem_mujoco::p4::PUSHER_CONDITIONS`] as the
//! conditions, [`PusherCost`] as every condition's cost (its terminal cost the last step's
//! distance terms), and the final block–goal distance as the measure.
//!
//! The door ([`door_problem`]): the scene `p4_door.xml`, [`tandem_mujoco::p4::DOOR_CONDITIONS`],
//! [`DoorCost`] on the hook and grasp points from MuJoCo's kinematics (its expansion Gauss–Newton
//! through finite-difference site Jacobians), and the final door angle as the measure.

use nalgebra::{DMatrix, DVector};
use tandem_mujoco::p4::{
    DoorCost, PusherCondition, PusherCost, PUSHER_ACTION_DIM, PUSHER_CONDITIONS, PUSHER_HORIZON,
    PUSHER_STATE_DIM,
};
use tandem_planners::{Objective, QuadCost, QuadTerminal};

use super::gps::{Condition, LocalProblem};
use super::{PipelineError, Result};

/// The expansion of a cost whose state part is `(c, cx, cxx)` plus `w_u ‖u‖²` (no cross term).
fn with_action_cost(c: f64, cx: DVector<f64>, cxx: DMatrix<f64>, u: &[f64], w_u: f64) -> QuadCost {
    let (n, m) = (cx.len(), u.len());
    let u = DVector::from_column_slice(u);
    QuadCost {
        c: c + w_u * u.norm_squared(),
        cx,
        cu: &u * (2.0 * w_u),
        cxx,
        cuu: DMatrix::identity(m, m) * (2.0 * w_u),
        cux: DMatrix::zeros(m, n),
    }
}

/// The pusher's objective for one condition, with the cost's Gauss–Newton expansion
/// ([`PusherCost::state_expansion`]) as its derivatives.
pub fn pusher_objective(cond: PusherCondition, cost: PusherCost, horizon: usize) -> Objective {
    Objective::time_varying(PUSHER_STATE_DIM, PUSHER_ACTION_DIM, move |x, u, t| {
        cost.running(&cond, horizon, x, u, t)
    })
    .with_terminal(move |x| cost.terminal(&cond, x))
    .with_running_derivatives(move |x, u, t| {
        let (c, cx, cxx) = cost.state_expansion(&cond, horizon, x, t);
        with_action_cost(c, cx, cxx, u, cost.action)
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

/// The door's four conditions on MuJoCo, with `cost`. Needs the feature `mujoco`; without it, an
/// error saying so.
pub fn door_problem(cost: DoorCost) -> Result<LocalProblem> {
    cost.validate().map_err(PipelineError::Config)?;
    door::problem(cost)
}

#[cfg(feature = "mujoco")]
mod door {
    use nalgebra::{DMatrix, DVector};
    use tandem_mujoco::p4::{
        door_initial_state, scene_path, DoorCost, DOOR_ACTION_DIM, DOOR_ANGLE, DOOR_CONDITIONS,
        DOOR_FRAME_SKIP, DOOR_HORIZON, DOOR_SCENE, DOOR_STATE_DIM,
    };
    use tandem_mujoco::{MujocoPlant, Scene};
    use tandem_planners::{Objective, QuadTerminal};

    use super::super::gps::{Condition, LocalProblem};
    use super::super::{PipelineError, Result};

    /// Joint positions of the door scene (arm and door).
    const NQ: usize = 7;

    /// Hook point minus grasp point at joint positions `q`.
    fn offset(scene: &Scene, ids: &[usize; 2], q: &[f64]) -> [f64; 3] {
        match scene.site_positions(&q[..NQ], ids) {
            Ok(p) => [p[0][0] - p[1][0], p[0][1] - p[1][1], p[0][2] - p[1][2]],
            // Only a non-finite state gets here; the cost is then non-finite too, and the
            // objective reports it with its step.
            Err(_) => [f64::NAN; 3],
        }
    }

    /// Value, gradient and Gauss–Newton Hessian in the state of the state terms of the cost.
    fn expansion(
        scene: &Scene,
        ids: &[usize; 2],
        cost: &DoorCost,
        x: &[f64],
    ) -> (f64, DVector<f64>, DMatrix<f64>) {
        let r = offset(scene, ids, x);
        let (v, g, h) = cost.hand_expansion(&r);
        let (g, h) = (
            DVector::from_column_slice(&g),
            DMatrix::from_fn(3, 3, |i, j| h[i][j]),
        );
        // ∂r/∂q by central differences of the kinematics.
        let eps = 1e-6;
        let mut jac = DMatrix::zeros(3, DOOR_STATE_DIM);
        let mut q = x[..NQ].to_vec();
        for j in 0..NQ {
            let q0 = q[j];
            q[j] = q0 + eps;
            let rp = offset(scene, ids, &q);
            q[j] = q0 - eps;
            let rm = offset(scene, ids, &q);
            q[j] = q0;
            for i in 0..3 {
                jac[(i, j)] = (rp[i] - rm[i]) / (2.0 * eps);
            }
        }
        let mut cx = jac.transpose() * g;
        let mut cxx = jac.transpose() * h * &jac;
        let e = x[DOOR_ANGLE] - cost.target;
        cx[DOOR_ANGLE] += 2.0 * cost.angle * e;
        cxx[(DOOR_ANGLE, DOOR_ANGLE)] += 2.0 * cost.angle;
        (v + cost.angle * e * e, cx, cxx)
    }

    pub(super) fn problem(cost: DoorCost) -> Result<LocalProblem> {
        let bad = |e: tandem_mujoco::MujocoError| PipelineError::Config(e.to_string());
        let scene = Scene::from_xml(scene_path(DOOR_SCENE)).map_err(bad)?;
        let ids = [
            scene.site_id("hand").map_err(bad)?,
            scene.site_id("handle").map_err(bad)?,
        ];
        let conditions = (0..DOOR_CONDITIONS.len())
            .map(|c| {
                let (s1, s2, s3, s4) = (scene.clone(), scene.clone(), scene.clone(), scene.clone());
                Condition {
                    x0: door_initial_state(c),
                    objective: Objective::new(DOOR_STATE_DIM, DOOR_ACTION_DIM, move |x, u| {
                        cost.running(&offset(&s1, &ids, x), x[DOOR_ANGLE], u)
                    })
                    .with_terminal(move |x| cost.running(&offset(&s2, &ids, x), x[DOOR_ANGLE], &[]))
                    .with_running_derivatives(move |x, u, _| {
                        let (c, cx, cxx) = expansion(&s3, &ids, &cost, x);
                        super::with_action_cost(c, cx, cxx, u, cost.action)
                    })
                    .with_terminal_derivatives(move |x| {
                        let (c, cx, cxx) = expansion(&s4, &ids, &cost, x);
                        QuadTerminal { c, cx, cxx }
                    }),
                }
            })
            .collect();
        let plant = MujocoPlant::new(scene, DOOR_FRAME_SKIP).map_err(bad)?;
        Ok(LocalProblem {
            system: Box::new(tandem_models::PlantModel::new(plant)),
            conditions,
            horizon: DOOR_HORIZON,
            measure: Box::new(|_, x| x[DOOR_ANGLE]),
        })
    }
}

#[cfg(not(feature = "mujoco"))]
mod door {
    use super::super::gps::LocalProblem;
    use super::super::{PipelineError, Result};

    pub(super) fn problem(_cost: tandem_mujoco::p4::DoorCost) -> Result<LocalProblem> {
        Err(PipelineError::Config(
            "p4's door needs a build with `--features mujoco` after scripts/setup-mujoco.sh".into(),
        ))
    }
}
