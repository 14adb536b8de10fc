//! A model seen through a task's actions, so a planner plans in the units the agent acts in.

use ndarray::Array2;
use tandem_core::{Action, Rng};
use tandem_envs::Task;

use crate::{DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions};

/// A model of plant inputs seen through a task's actions: `predict` takes the agent's actions,
/// turns each row into the plant input ([`Task::control`]) and the states into canonical ones
/// ([`Task::canonicalize`]), and asks the model. So a planner plans in the units the agent acts
/// in. Not fittable.
pub struct InActions<'a, M: ?Sized, T: ?Sized> {
    model: &'a M,
    task: &'a T,
    action_dim: usize,
}

impl<'a, M: DynamicsModel + ?Sized, T: Task + ?Sized> InActions<'a, M, T> {
    /// `model` under `task`'s actions.
    pub fn new(model: &'a M, task: &'a T) -> Self {
        Self {
            model,
            task,
            action_dim: task.action_space().flat_dim(),
        }
    }
}

impl<M: DynamicsModel + ?Sized, T: Task + ?Sized> DynamicsModel for InActions<'_, M, T> {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }

    fn action_dim(&self) -> usize {
        self.action_dim
    }

    fn predict(&self, input: &ModelInput<'_>, rng: &mut Rng) -> Result<Prediction, ModelError> {
        let b = input.states.nrows();
        if input.actions.dim() != (b, self.action_dim) {
            return Err(ModelError::Dim {
                what: "actions (rows x columns)".into(),
                expected: b * self.action_dim,
                got: input.actions.len(),
            });
        }
        let mut states = input.states.to_owned();
        for mut r in states.rows_mut() {
            if let Some(s) = r.as_slice_mut() {
                self.task.canonicalize(s);
            }
        }
        let m = tandem_envs::control_dim(self.task);
        let mut controls = Array2::zeros((b, m));
        for (i, a) in input.actions.rows().into_iter().enumerate() {
            let u = self.task.control(&Action::Continuous(a.to_vec()));
            controls
                .row_mut(i)
                .assign(&ndarray::ArrayView1::from(&u[..]));
        }
        self.model
            .predict(&ModelInput::new(states.view(), controls.view()), rng)
    }

    fn fit(&mut self, _data: &Transitions, _cfg: &FitConfig) -> Result<FitReport, ModelError> {
        Err(ModelError::Other(
            "InActions is a view for planning; fit the model it wraps".into(),
        ))
    }
}
