//! States extended by features of themselves, for the local controllers: the authors' GPS
//! experiments put end-effector points and their velocities into the state the TVLG dynamics are
//! fitted on and the controllers act on (`state_include: [JOINT_ANGLES, JOINT_VELOCITIES,
//! END_EFFECTOR_POINTS, END_EFFECTOR_POINT_VELOCITIES]`), where a linear model of them is a
//! better one than a linear model of the joint angles (the kinematics are not linear).
//!
//! [`WithFeatures`] is a system whose state is `base ++ φ(base)`: it steps the base system on the
//! base part and recomputes the features of the next base state, so that the features are always
//! the kinematics' own and the base part of a trajectory is that of the base system under the
//! same actions. [`on_base_state`] makes an objective over the base state one over the extended
//! state (the features cost nothing: zero rows and columns in its expansion).

use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use ndarray::{s, Array2};
use tandem_core::Rng;
use tandem_models::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use tandem_planners::{Objective, QuadCost, QuadTerminal};

use super::{AlgoError, Result};

/// The features of a base state into a slice of their length; an error message when they cannot
/// be computed (a non-finite state, say).
pub type FeatureFn =
    Arc<dyn Fn(&[f64], &mut [f64]) -> std::result::Result<(), String> + Send + Sync>;

/// A system whose state is the base system's followed by features of it (see the module docs).
pub struct WithFeatures {
    base: Box<dyn DynamicsModel + Send + Sync>,
    features: FeatureFn,
    extra: usize,
}

impl WithFeatures {
    /// `base` with `extra` features computed by `features`; an error for no features.
    pub fn new(
        base: Box<dyn DynamicsModel + Send + Sync>,
        extra: usize,
        features: FeatureFn,
    ) -> Result<Self> {
        if extra == 0 {
            return Err(AlgoError::Config(
                "a state with features needs at least one feature".into(),
            ));
        }
        Ok(Self {
            base,
            features,
            extra,
        })
    }

    /// Length of the base state.
    pub fn base_dim(&self) -> usize {
        self.base.state_dim()
    }

    /// `x ++ φ(x)` for a base state `x`.
    pub fn extend(&self, x: &[f64]) -> Result<Vec<f64>> {
        let n = self.base_dim();
        if x.len() != n {
            return Err(AlgoError::Config(format!(
                "a base state of {} entries for a system of {n}",
                x.len()
            )));
        }
        let mut out = vec![0.0; n + self.extra];
        out[..n].copy_from_slice(x);
        (self.features)(x, &mut out[n..]).map_err(AlgoError::Config)?;
        Ok(out)
    }
}

impl DynamicsModel for WithFeatures {
    fn state_dim(&self) -> usize {
        self.base_dim() + self.extra
    }

    fn action_dim(&self) -> usize {
        self.base.action_dim()
    }

    /// The base system's prediction from the base part, its features appended; a predicted
    /// variance gets zeros for the features (they are functions of the base state).
    fn predict(
        &self,
        input: &ModelInput<'_>,
        rng: &mut Rng,
    ) -> std::result::Result<Prediction, ModelError> {
        let (n, k) = (self.base_dim(), self.extra);
        if input.states.ncols() != n + k {
            return Err(ModelError::Dim {
                what: "input states (columns, with features)".into(),
                expected: n + k,
                got: input.states.ncols(),
            });
        }
        let base_in = ModelInput::new(input.states.slice(s![.., ..n]), input.actions.view())
            .with_propagation(input.propagation);
        let p = self.base.predict(&base_in, rng)?;
        let rows = p.next_states.nrows();
        let mut next = Array2::zeros((rows, n + k));
        next.slice_mut(s![.., ..n]).assign(&p.next_states);
        let mut x = vec![0.0; n];
        let mut f = vec![0.0; k];
        for (i, mut row) in next.rows_mut().into_iter().enumerate() {
            x.iter_mut()
                .zip(p.next_states.row(i))
                .for_each(|(d, v)| *d = *v);
            (self.features)(&x, &mut f).map_err(|e| {
                ModelError::Other(format!("features of the predicted state {i}: {e}"))
            })?;
            row.slice_mut(s![n..])
                .iter_mut()
                .zip(&f)
                .for_each(|(d, v)| *d = *v);
        }
        let variance = p.variance.map(|v| {
            let mut out = Array2::zeros((v.nrows(), n + k));
            out.slice_mut(s![.., ..n]).assign(&v);
            out
        });
        Ok(Prediction {
            next_states: next,
            variance,
            rewards: p.rewards,
            terminal_prob: p.terminal_prob,
        })
    }

    /// Fits the base system on the base parts of `data`.
    fn fit(
        &mut self,
        data: &Transitions,
        cfg: &FitConfig,
    ) -> std::result::Result<FitReport, ModelError> {
        let n = self.base_dim();
        data.validate(self.state_dim(), self.action_dim())?;
        let base = Transitions {
            states: data.states.slice(s![.., ..n]).to_owned(),
            actions: data.actions.clone(),
            next_states: data.next_states.slice(s![.., ..n]).to_owned(),
            rewards: data.rewards.clone(),
            terminated: data.terminated.clone(),
        };
        self.base.fit(&base, cfg)
    }
}

/// An objective over `base ++ features` (`extra` of them) that pays `base`'s costs on the base
/// part: the features cost nothing, and the expansions get zero rows and columns for them. For
/// stage-wise objectives without termination, discount or a terminal value (the local
/// controllers' tasks); others are refused. A cost the base objective refuses reads as NaN, which
/// the objective then reports with its step.
pub fn on_base_state(base: Objective, extra: usize) -> Result<Objective> {
    base.check_stagewise()?;
    if base.has_termination() || base.discount() != 1.0 || base.uses_model_reward() {
        return Err(AlgoError::Config(
            "features of the state: the objective must have no termination, discount or model \
             reward"
                .into(),
        ));
    }
    let (n, m) = (base.state_dim(), base.action_dim());
    let has_terminal = base.has_terminal();
    let base = Arc::new(base);
    let (b1, b2, b3, b4) = (base.clone(), base.clone(), base.clone(), base);
    let mut obj = Objective::time_varying(n + extra, m, move |x, u, t| {
        b1.running_cost(&x[..n], u, t).unwrap_or(f64::NAN)
    })
    .with_running_derivatives(move |x, u, t| match b2.running_quadratic(&x[..n], u, t) {
        Ok(q) => QuadCost {
            c: q.c,
            cx: pad_vector(&q.cx, extra),
            cu: q.cu,
            cxx: pad_matrix(&q.cxx, extra),
            cuu: q.cuu,
            cux: q.cux.resize_horizontally(n + extra, 0.0),
        },
        Err(_) => QuadCost {
            c: f64::NAN,
            cx: DVector::zeros(n + extra),
            cu: DVector::zeros(m),
            cxx: DMatrix::zeros(n + extra, n + extra),
            cuu: DMatrix::zeros(m, m),
            cux: DMatrix::zeros(m, n + extra),
        },
    });
    if has_terminal {
        obj = obj
            .with_terminal(move |x| b3.terminal_cost(&x[..n]).unwrap_or(f64::NAN))
            .with_terminal_derivatives(move |x| match b4.terminal_quadratic(&x[..n]) {
                Ok(q) => QuadTerminal {
                    c: q.c,
                    cx: pad_vector(&q.cx, extra),
                    cxx: pad_matrix(&q.cxx, extra),
                },
                Err(_) => QuadTerminal {
                    c: f64::NAN,
                    cx: DVector::zeros(n + extra),
                    cxx: DMatrix::zeros(n + extra, n + extra),
                },
            });
    }
    Ok(obj)
}

/// `problem` with `extra` features of its state appended ([`WithFeatures`]): its system
/// wrapped, its starts extended, its objectives paying on the base part ([`on_base_state`]). The
/// measure and the policy input read the extended state, whose base part comes first.
pub fn with_features(
    problem: crate::gps::LocalProblem,
    extra: usize,
    features: FeatureFn,
) -> Result<crate::gps::LocalProblem> {
    let system = WithFeatures::new(problem.system, extra, features)?;
    let conditions = problem
        .conditions
        .into_iter()
        .map(|c| {
            Ok(crate::gps::Condition {
                x0: system.extend(&c.x0)?,
                objective: on_base_state(c.objective, extra)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(crate::gps::LocalProblem {
        system: Box::new(system),
        conditions,
        horizon: problem.horizon,
        measure: problem.measure,
        policy_input: problem.policy_input,
    })
}

fn pad_vector(v: &DVector<f64>, extra: usize) -> DVector<f64> {
    v.clone().resize_vertically(v.len() + extra, 0.0)
}

fn pad_matrix(a: &DMatrix<f64>, extra: usize) -> DMatrix<f64> {
    a.clone().resize(a.nrows() + extra, a.ncols() + extra, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gps::tests::{DoubleIntegrator, DT};
    use nalgebra::dvector;
    use tandem_core::seeding::rng_from_seed;
    use tandem_models::PlantModel;
    use tandem_planners::{sample_trajectories, SampleConfig, TvlgController};

    /// Features of the double integrator: `x²` and its rate `2 x v`.
    fn features() -> FeatureFn {
        Arc::new(|x: &[f64], out: &mut [f64]| {
            out[0] = x[0] * x[0];
            out[1] = 2.0 * x[0] * x[1];
            Ok(())
        })
    }

    fn objective() -> Objective {
        Objective::time_varying(2, 1, |x, u, t| {
            (1.0 + t as f64) * x[0] * x[0] + 0.1 * x[1] * x[1] + 0.01 * u[0] * u[0]
        })
        .with_terminal(|x| 10.0 * x[0] * x[0])
    }

    /// The base part of trajectories with features is that of the base system under the same
    /// actions, bit for bit; the features are those of the base state (the rate to finite
    /// differences of the trajectory); the costs are the base objective's.
    #[test]
    fn the_base_part_is_the_base_systems_and_the_features_the_kinematics() {
        let sys =
            WithFeatures::new(Box::new(PlantModel::new(DoubleIntegrator)), 2, features()).unwrap();
        assert_eq!((sys.state_dim(), sys.action_dim()), (4, 1));
        let x0 = [1.0, -0.5];
        let ext = sys.extend(&x0).unwrap();
        assert_eq!(ext, vec![1.0, -0.5, 1.0, -1.0]);
        let obj = on_base_state(objective(), 2).unwrap();
        let base_obj = objective();
        // The same actions on both: a controller on the base state, and the same gains with
        // zeros on the features.
        let base_ctrl = TvlgController::constant(15, 2, &[0.3], 0.5).unwrap();
        let ext_ctrl = TvlgController::constant(15, 4, &[0.3], 0.5).unwrap();
        let cfg = SampleConfig {
            samples: 3,
            ..SampleConfig::default()
        };
        let plain = PlantModel::new(DoubleIntegrator);
        let a = sample_trajectories(
            &base_ctrl,
            &plain,
            &base_obj,
            &x0,
            &cfg,
            &mut rng_from_seed(4),
        )
        .unwrap();
        let b =
            sample_trajectories(&ext_ctrl, &sys, &obj, &ext, &cfg, &mut rng_from_seed(4)).unwrap();
        assert_eq!(a.actions, b.actions);
        assert_eq!(a.states, b.states.slice(s![.., .., ..2]));
        assert_eq!(a.costs, b.costs);
        for i in 0..3 {
            for t in 0..=15 {
                let (x, v) = (b.states[(i, t, 0)], b.states[(i, t, 1)]);
                assert_eq!(b.states[(i, t, 2)], x * x);
                assert_eq!(b.states[(i, t, 3)], 2.0 * x * v);
            }
            // d(x²)/dt by central differences along the trajectory, to O(dt) (the semi-implicit
            // steps move x by dt·v and the velocity in between).
            for t in 1..15 {
                let fd = (b.states[(i, t + 1, 2)] - b.states[(i, t - 1, 2)]) / (2.0 * DT);
                let rate = b.states[(i, t, 3)];
                assert!(
                    (fd - rate).abs() < 0.1 * (1.0 + rate.abs()),
                    "{t}: {fd} vs {rate}"
                );
            }
        }
    }

    /// The expansions over the extended state are the base's, with zero rows and columns for
    /// the features; a cost the base refuses is reported, not hidden.
    #[test]
    fn the_features_cost_nothing() {
        let obj = on_base_state(objective(), 2).unwrap();
        let base = objective();
        let (x, u) = ([0.4, -0.3, 9.0, 9.0], [0.2]);
        let q = obj.running_quadratic(&x, &u, 3).unwrap();
        let qb = base.running_quadratic(&x[..2], &u, 3).unwrap();
        assert_eq!(q.c, qb.c);
        assert_eq!(q.cx.rows(0, 2), qb.cx);
        assert_eq!(q.cxx.view((0, 0), (2, 2)), qb.cxx);
        assert_eq!(q.cx.rows(2, 2), dvector![0.0, 0.0]);
        assert_eq!(q.cxx.rows(2, 2).amax() + q.cxx.columns(2, 2).amax(), 0.0);
        assert_eq!(q.cux.columns(2, 2).amax(), 0.0);
        let qt = obj.terminal_quadratic(&x).unwrap();
        assert_eq!(qt.c, base.terminal_quadratic(&x[..2]).unwrap().c);
        assert_eq!(qt.cxx.shape(), (4, 4));
        assert!(obj.running_cost(&[f64::NAN, 0.0, 0.0, 0.0], &u, 0).is_err());
        assert!(on_base_state(objective().with_discount(0.9).unwrap(), 2).is_err());
        assert!(
            WithFeatures::new(Box::new(PlantModel::new(DoubleIntegrator)), 0, features()).is_err()
        );
    }
}
