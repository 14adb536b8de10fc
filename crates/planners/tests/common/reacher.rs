//! A planar 2-link reacher for the TVLG optimizers, shared by `tests/tvlg.rs` and
//! `examples/wall_reacher.rs`: joint angles and velocities, torque-like inputs on two damped
//! joints (dt = 0.05); cost on the squared end-effector distance to a target. An optional wall
//! stops joint 1 at `q₁ = wall`: with `bounce = e > 0` the joint rebounds with velocity `−e q̇₁`
//! (an elastic impact), with `e = 0` it sticks (velocity zeroed): an abrupt change in the
//! dynamics.
#![allow(dead_code)]

use ndarray::{Array2, ArrayView2};
use tandem_core::seeding::rng_from_seed;
use tandem_planners::{
    sample_trajectories, Dynamics, Objective, Result, SampleConfig, TvlgController,
};

/// The reacher; see the module docs.
#[derive(Clone)]
pub struct Reacher {
    /// Joint-1 angle of the wall, if any.
    pub wall: Option<f64>,
    /// Restitution at the wall (0: stick).
    pub bounce: f64,
}

/// End-effector position (links of length 1 and 0.8).
pub fn ee(x: &[f64]) -> [f64; 2] {
    [
        x[0].cos() + (x[0] + x[1]).cos() * 0.8,
        x[0].sin() + (x[0] + x[1]).sin() * 0.8,
    ]
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

impl Dynamics for Reacher {
    fn state_dim(&self) -> usize {
        4
    }
    fn action_dim(&self) -> usize {
        2
    }
    fn step_batch(&self, s: ArrayView2<'_, f64>, a: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
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
            out.row_mut(i)
                .assign(&ndarray::arr1(&[q[0], q[1], v[0], v[1]]));
        }
        Ok(out)
    }
}

/// Expected cost of a controller, estimated with a fixed set of 200 rollouts (common random
/// numbers, so successive controllers are compared on the same noise).
pub fn evaluate(ctrl: &TvlgController, sys: &dyn Dynamics, obj: &Objective, x0: &[f64]) -> f64 {
    let cfg = SampleConfig {
        samples: 200,
        ..Default::default()
    };
    sample_trajectories(ctrl, sys, obj, x0, &cfg, &mut rng_from_seed(999))
        .expect("evaluation rollouts")
        .mean_cost()
}
