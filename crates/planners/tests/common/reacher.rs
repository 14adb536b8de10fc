//! A planar 2-link reacher for the TVLG optimizers, shared by `tests/tvlg.rs` and
//! `examples/wall_reacher.rs`: joint angles and velocities, torque-like inputs on two damped
//! joints (dt = 0.05); cost on the squared end-effector distance to a target. An optional wall
//! stops joint 1 at `q₁ = wall`: with `bounce = e > 0` the joint rebounds with velocity `−e q̇₁`
//! (an elastic impact), with `e = 0` it sticks (velocity zeroed): an abrupt change in the
//! dynamics.
//!
//! The pusher variant ([`Reacher::pusher`], p4 Fig. 3's gripper pusher in miniature): a block
//! lies on link 1's arc at joint angle `b` (a fifth state). Link 1 pushes it when `q₁` passes it:
//! the block is carried to `q₁` and stops there (friction), and the arm loses the fraction
//! `push_loss` of its joint-1 velocity to it at every step of contact. Before contact the block
//! does not depend on the arm at all, in contact it moves one for one with `q₁`, so a
//! time-indexed linear fit of samples that touch the block at different steps mixes two modes.
//! [`push_objective`] scores the arm-to-block and block-to-goal distances, as p4's pusher does.
//! The hockey variant ([`Reacher::hockey`]) lets the hit block slide on (a sixth state, its
//! velocity), decelerated by friction.
#![allow(dead_code)]

use ndarray::Array2;
use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
use tandem_models::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use tandem_planners::{sample_trajectories, Objective, SampleConfig, TvlgController};

/// The reacher; see the module docs.
#[derive(Clone)]
pub struct Reacher {
    /// Joint-1 angle of the wall, if any.
    pub wall: Option<f64>,
    /// Restitution at the wall (0: stick).
    pub bounce: f64,
    /// Fraction of joint-1 velocity lost to the block per step of contact (pusher variant; the
    /// block exists iff the state has a fifth component).
    pub push_loss: Option<f64>,
    /// Hockey variant (with a block): the block slides after a hit, with `kick` times link 1's
    /// velocity, decelerated by friction `FRICTION`; its velocity is a sixth state. `0`: no slide.
    pub kick: f64,
}

/// Sliding friction of the block in the hockey variant (rad/s²).
pub const FRICTION: f64 = 2.0;

impl Reacher {
    /// The free reacher (no wall, no block).
    pub fn free() -> Self {
        Self {
            wall: None,
            bounce: 0.0,
            push_loss: None,
            kick: 0.0,
        }
    }

    /// The reacher with a wall at `q₁ = wall` and restitution `bounce`.
    pub fn walled(wall: f64, bounce: f64) -> Self {
        Self {
            wall: Some(wall),
            bounce,
            push_loss: None,
            kick: 0.0,
        }
    }

    /// The pusher variant: a block on link 1's arc, losing `push_loss` of `q̇₁` per contact step.
    pub fn pusher(push_loss: f64) -> Self {
        Self {
            wall: None,
            bounce: 0.0,
            push_loss: Some(push_loss),
            kick: 0.0,
        }
    }

    /// The hockey variant: a pushed block that also slides on with `kick` times the arm's velocity.
    pub fn hockey(push_loss: f64, kick: f64) -> Self {
        Self {
            kick,
            ..Self::pusher(push_loss)
        }
    }

    /// Initial state: arm at rest at zero, and the block at `block` in the pusher variant.
    pub fn x0(&self, block: f64) -> Vec<f64> {
        let mut x = vec![0.0; self.state_dim()];
        if self.push_loss.is_some() {
            x[4] = block;
        }
        x
    }
}

/// End-effector position (links of length 1 and 0.8).
pub fn ee(x: &[f64]) -> [f64; 2] {
    [
        x[0].cos() + (x[0] + x[1]).cos() * 0.8,
        x[0].sin() + (x[0] + x[1]).sin() * 0.8,
    ]
}

/// Pusher cost (p4's gripper pusher: "a weighted combination of the distance from the gripper to
/// the block and from the block to the goal"): `(q₁ − b)² + 4 (b − goal)²` per step plus a small
/// control cost, ×20 at the end plus a velocity term. The arm cannot pull the block back, so an
/// overshoot is final.
pub fn push_objective(goal: f64) -> Objective {
    push_objective_dim(goal, 5)
}

/// [`push_objective`] for a state of length `n` (6 in the hockey variant, whose terminal cost also
/// asks the block to have stopped: `+ x₅²`).
pub fn push_objective_dim(goal: f64, n: usize) -> Objective {
    Objective::new(n, 2, move |x, u| {
        (x[0] - x[4]).powi(2) + 4.0 * (x[4] - goal).powi(2) + 1e-3 * (u[0] * u[0] + u[1] * u[1])
    })
    .with_terminal(move |x| {
        20.0 * ((x[0] - x[4]).powi(2) + 4.0 * (x[4] - goal).powi(2))
            + 0.1 * (x[2] * x[2] + x[3] * x[3])
            + x.get(5).map_or(0.0, |v| v * v)
    })
}

/// Squared distance to `target` plus a small control cost; ×20 at the end, plus a velocity term.
pub fn objective(target: [f64; 2]) -> Objective {
    Objective::new(4, 2, move |x, u| {
        let e = ee(x);
        let d2 = (e[0] - target[0]).powi(2) + (e[1] - target[1]).powi(2);
        d2 + 1e-3 * (u[0] * u[0] + u[1] * u[1])
    })
    .with_terminal(move |x| {
        let e = ee(x);
        20.0 * ((e[0] - target[0]).powi(2) + (e[1] - target[1]).powi(2))
            + 0.1 * (x[2] * x[2] + x[3] * x[3])
    })
}

impl DynamicsModel for Reacher {
    fn state_dim(&self) -> usize {
        match (self.push_loss, self.kick > 0.0) {
            (None, _) => 4,
            (Some(_), false) => 5,
            (Some(_), true) => 6,
        }
    }
    fn action_dim(&self) -> usize {
        2
    }
    fn predict(&self, input: &ModelInput<'_>, _rng: &mut Rng) -> Result<Prediction, ModelError> {
        let (s, a) = (input.states, input.actions);
        let dt = 0.05;
        let mut out = Array2::zeros(s.dim());
        for i in 0..s.nrows() {
            let mut v = [
                s[(i, 2)] + dt * (a[(i, 0)] - 0.5 * s[(i, 2)]),
                s[(i, 3)] + dt * (a[(i, 1)] - 0.5 * s[(i, 3)]),
            ];
            let mut q = [s[(i, 0)] + dt * v[0], s[(i, 1)] + dt * v[1]];
            if let Some(w) = self.wall {
                if q[0] > w {
                    // Reflect the overshoot and the velocity.
                    q[0] = w - self.bounce * (q[0] - w);
                    v[0] *= -self.bounce;
                }
            }
            out[(i, 0)] = q[0];
            out[(i, 1)] = q[1];
            out[(i, 3)] = v[1];
            if let Some(loss) = self.push_loss {
                let (mut b, mut vb) = (s[(i, 4)], 0.0);
                if self.kick > 0.0 {
                    // The block slides on, decelerated by friction.
                    vb = (s[(i, 5)] - dt * FRICTION).max(0.0);
                    b += dt * vb;
                }
                if q[0] > b {
                    // Link 1 carries the block along (and kicks it) and loses momentum to it.
                    b = q[0];
                    vb = vb.max(self.kick * v[0]);
                    v[0] *= 1.0 - loss;
                }
                out[(i, 4)] = b;
                if self.kick > 0.0 {
                    out[(i, 5)] = vb;
                }
            }
            out[(i, 2)] = v[0];
        }
        Ok(Prediction::deterministic(out))
    }
    fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
        Ok(FitReport::default())
    }
}

/// Expected cost of a controller, estimated with a fixed set of 200 rollouts (common random
/// numbers, so successive controllers are compared on the same noise).
pub fn evaluate(
    ctrl: &TvlgController,
    sys: &dyn DynamicsModel,
    obj: &Objective,
    x0: &[f64],
) -> f64 {
    let cfg = SampleConfig {
        samples: 200,
        ..Default::default()
    };
    sample_trajectories(ctrl, sys, obj, x0, &cfg, &mut rng_from_seed(999))
        .expect("evaluation rollouts")
        .mean_cost()
}
