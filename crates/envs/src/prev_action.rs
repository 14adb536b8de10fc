//! [`WithPrevAction`]: a task whose state carries the control applied before it, for models
//! that condition on the previous action (p1's incremental model).

use tandem_core::{Action, Rng, Space};

use crate::task::{control_dim, Task};

/// `task` over the state `z = [s, u_{t−1}]`: the task's own state followed by the control
/// applied before it (zero at an episode's start). Observations, rewards, termination and
/// canonical form are the task's, read from the leading `s`; a model of `z` predicts
/// `[s', u_t]`. A learned model's environment or rollouts over it thus give the model the
/// previous action through the state, as any other state component.
///
/// ```
/// use tandem_core::{seeding::rng_from_seed, Action};
/// use tandem_envs::{PendulumTask, Task, WithPrevAction};
///
/// let task = WithPrevAction::new(PendulumTask::new(&Default::default()));
/// assert_eq!(task.state_dim(), 3);
/// let z = task.initial_state(&mut rng_from_seed(0));
/// assert_eq!(z[2], 0.0);
/// let u = task.control(&Action::Continuous(vec![1.5]));
/// let next = [z[0], z[1], u[0]];
/// assert_eq!(task.reward(&z, &u, &next), task.inner().reward(&z[..2], &u, &z[..2]));
/// ```
#[derive(Debug, Clone)]
pub struct WithPrevAction<T> {
    task: T,
    state_dim: usize,
}

impl<T: Task> WithPrevAction<T> {
    /// `task`, its state extended by its control.
    pub fn new(task: T) -> Self {
        let state_dim = task.state_dim() + control_dim(&task);
        Self { task, state_dim }
    }

    /// The task itself.
    pub fn inner(&self) -> &T {
        &self.task
    }

    /// The leading part of `z`: the task's own state.
    fn own<'a>(&self, z: &'a [f64]) -> &'a [f64] {
        &z[..self.task.state_dim()]
    }
}

impl<T: Task> Task for WithPrevAction<T> {
    fn id(&self) -> &str {
        self.task.id()
    }

    fn observation_space(&self) -> &Space {
        self.task.observation_space()
    }

    fn action_space(&self) -> &Space {
        self.task.action_space()
    }

    /// The task's state length plus its control length.
    fn state_dim(&self) -> usize {
        self.state_dim
    }

    fn control(&self, action: &Action) -> Vec<f64> {
        self.task.control(action)
    }

    /// The task's start, and a zero previous control.
    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        let mut z = self.task.initial_state(rng);
        z.resize(self.state_dim, 0.0);
        z
    }

    fn observe(&self, state: &[f64]) -> Vec<f64> {
        self.task.observe(self.own(state))
    }

    fn canonicalize(&self, state: &mut [f64]) {
        let n = self.task.state_dim();
        self.task.canonicalize(&mut state[..n]);
    }

    fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        self.task.reward(self.own(state), u, self.own(next))
    }

    fn terminated(&self, next: &[f64]) -> bool {
        self.task.terminated(self.own(next))
    }

    fn max_episode_steps(&self) -> Option<usize> {
        self.task.max_episode_steps()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CartPoleTask, PendulumTask};
    use tandem_core::seeding::rng_from_seed;

    #[test]
    fn the_extended_task_reads_its_own_state_and_appends_the_control() {
        let inner = PendulumTask::new(&Default::default());
        let task = WithPrevAction::new(inner.clone());
        let (s, s1) = ([0.5, -0.25], [7.0, 1.0]);
        let (z, mut z1) = ([0.5, -0.25, 1.0], [7.0, 1.0, -2.0]);
        assert_eq!(task.observe(&z), inner.observe(&s));
        assert_eq!(
            task.reward(&z, &[-2.0], &z1),
            inner.reward(&s, &[-2.0], &s1)
        );
        assert_eq!(task.terminated(&z1), inner.terminated(&s1));
        // Angles wrap; the previous control is not an angle and stays.
        task.canonicalize(&mut z1);
        assert!((z1[0] - (7.0 - 2.0 * std::f64::consts::PI)).abs() < 1e-15);
        assert_eq!(z1[2], -2.0);
        let (mut a, mut b) = (rng_from_seed(3), rng_from_seed(3));
        let start = task.initial_state(&mut a);
        assert_eq!(start[..2], inner.initial_state(&mut b)[..]);
        assert_eq!(start[2], 0.0);
        assert_eq!(task.max_episode_steps(), inner.max_episode_steps());
    }

    #[test]
    fn a_discrete_task_extends_by_its_force() {
        // CartPole's control is one force, whichever of its two actions.
        let task = WithPrevAction::new(CartPoleTask::default());
        assert_eq!(task.state_dim(), 5);
        assert_eq!(task.control(&Action::Discrete(1)).len(), 1);
    }
}
