//! Environments imagined by a model: any [`DynamicsModel`] under a [`Task`].
//!
//! The task gives starts, observations, the plant input of an action, and (by default) reward
//! and termination, exactly as it does for the real system's `tandem_envs::PlantEnv`, so that
//! real and imagined episodes are scored alike. Where the model learns them (p2's
//! `(s', r, done)` model), reward and termination can come from the model's prediction instead
//! ([`Judge::Model`]).
//!
//! Two shapes:
//! - [`ModelEnv`]: one imagined episode at a time behind the `Env` trait, so every loop that
//!   trains on an environment trains on a model (p0's `f_idl + d`, p2's imagined episodes);
//! - [`branched_rollouts`]: N imagined rollouts at once, started from a batch of real states, one
//!   `predict` call per step (MBPO's branched rollouts, p1's one-step Dyna).
//!
//! The model works in the task's state space. States are canonicalized by the task after every
//! prediction ([`Task::canonicalize`]: wrapped angles), and the model also receives the control
//! applied one step before (zeros at a start), which the incremental model (p1) needs and the
//! others ignore.

use ndarray::{Array1, Array2, ArrayView2};
use serde::{Deserialize, Serialize};
use tandem_core::{Action, Rng, Space};
use tandem_envs::{Env, EnvError, Step, Task, TaskEpisodes};

use crate::model::{DynamicsModel, ModelError, ModelInput, Prediction};

/// Who decides a quantity of an imagined transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Judge {
    /// The task's function of `(s, u, s')` (exact where the task is known: p0, p3).
    Task,
    /// The model's prediction (p2: a learned reward, and termination when the predicted
    /// probability reaches [`Judges::terminal_threshold`]).
    Model,
}

/// Where reward and termination of imagined transitions come from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Judges {
    /// The reward.
    pub reward: Judge,
    /// Termination.
    pub termination: Judge,
    /// A predicted terminal probability at or above this ends the episode (p2: 0.5).
    pub terminal_threshold: f64,
}

impl Default for Judges {
    /// Both from the task.
    fn default() -> Self {
        Self {
            reward: Judge::Task,
            termination: Judge::Task,
            terminal_threshold: 0.5,
        }
    }
}

impl Judges {
    /// Both from the model, terminal at a predicted probability of 0.5 (p2).
    pub fn model() -> Self {
        Self {
            reward: Judge::Model,
            termination: Judge::Model,
            terminal_threshold: 0.5,
        }
    }

    fn validate(&self) -> Result<(), ModelError> {
        if !(self.terminal_threshold > 0.0 && self.terminal_threshold <= 1.0) {
            return Err(ModelError::Other(format!(
                "terminal_threshold must lie in (0, 1], got {}",
                self.terminal_threshold
            )));
        }
        Ok(())
    }

    /// Reward and termination of row `i` of `pred`, for the transition `s --u--> next`.
    fn judge<T: Task + ?Sized>(
        &self,
        task: &T,
        pred: &Prediction,
        i: usize,
        (s, u, next): (&[f64], &[f64], &[f64]),
    ) -> Result<(f64, bool), ModelError> {
        let reward = match self.reward {
            Judge::Task => task.reward(s, u, next),
            Judge::Model => pred
                .rewards
                .as_ref()
                .ok_or_else(|| ModelError::MissingInput("the model predicts no reward".into()))?[i],
        };
        let terminated = match self.termination {
            Judge::Task => task.terminated(next),
            Judge::Model => {
                pred.terminal_prob.as_ref().ok_or_else(|| {
                    ModelError::MissingInput("the model predicts no termination".into())
                })?[i]
                    >= self.terminal_threshold
            }
        };
        if !reward.is_finite() {
            return Err(ModelError::NonFinite {
                what: "imagined reward".into(),
                row: i,
            });
        }
        Ok((reward, terminated))
    }
}

/// A real transition `x → x1` in `task`'s canonical coordinates: `s = canon(x)` and
/// `s' = s + (x1 − x)`, so that a wrapped angle never makes the change jump by 2π. This is the
/// data a model of state changes is fitted on (p0's difference model, Dyna's learned model);
/// the model's predictions are canonicalized again by [`ModelEnv`] and [`branched_rollouts`].
///
/// ```
/// use tandem_envs::PendulumTask;
/// use tandem_dynamics::classic::GymPendulumParams;
/// use tandem_models::canonical_pair;
///
/// let task = PendulumTask::new(&GymPendulumParams::default());
/// // Passing the bottom: 3.1 → 3.2 rad is a change of 0.1, not of 0.1 − 2π.
/// let (s, s1) = canonical_pair(&task, &[3.1 + 2.0 * std::f64::consts::PI, 0.0], &[3.2 + 2.0 * std::f64::consts::PI, 2.0]);
/// assert!((s[0] - 3.1).abs() < 1e-12 && (s1[0] - s[0] - 0.1).abs() < 1e-12);
/// ```
pub fn canonical_pair<T: Task + ?Sized>(task: &T, x: &[f64], x1: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut s = x.to_vec();
    task.canonicalize(&mut s);
    let s1 = s
        .iter()
        .zip(x1.iter().zip(x))
        .map(|(s, (b, a))| s + (b - a))
        .collect();
    (s, s1)
}

impl crate::TransitionsBuilder {
    /// Appends the real transition `x --u--> x1` in `task`'s canonical coordinates
    /// ([`canonical_pair`]), and ends the episode when `done`.
    #[allow(clippy::too_many_arguments)]
    pub fn push_canonical<T: Task + ?Sized>(
        &mut self,
        task: &T,
        x: &[f64],
        u: &[f64],
        x1: &[f64],
        reward: f64,
        terminated: bool,
        done: bool,
    ) -> Result<(), ModelError> {
        let (s, s1) = canonical_pair(task, x, x1);
        self.push(&s, u, &s1, reward, terminated)?;
        if done {
            self.end_episode();
        }
        Ok(())
    }
}

/// Checks that `model` and `task` agree on the state and control sizes.
fn check_pair<M: DynamicsModel + ?Sized, T: Task + ?Sized>(
    model: &M,
    task: &T,
) -> Result<usize, ModelError> {
    let m = tandem_envs::control_dim(task);
    for (what, want, got) in [
        ("task state", model.state_dim(), task.state_dim()),
        ("task control", model.action_dim(), m),
    ] {
        if want != got {
            return Err(ModelError::Dim {
                what: what.into(),
                expected: want,
                got,
            });
        }
    }
    Ok(m)
}

/// An environment whose transitions come from a [`DynamicsModel`] and whose starts,
/// observations and plant inputs come from a [`Task`]; reward and termination as [`Judges`]
/// say. Episodes truncate after [`Task::max_episode_steps`] (when the task has a limit).
/// Stochastic models draw from the environment's generator (seeded by `reset`).
///
/// ```
/// use tandem_dynamics::classic::{GymPendulum, GymPendulumParams};
/// use tandem_envs::{Action, Env, PendulumTask};
/// use tandem_models::{ModelEnv, PlantModel};
///
/// // A known plant as a simulator: the pre-training environment of a difference model.
/// let p = GymPendulumParams::default();
/// let task = PendulumTask::new(&p);
/// let mut env = ModelEnv::new(PlantModel::new(GymPendulum::new(p)), task).unwrap();
/// env.reset(Some(0));
/// let step = env.step(&Action::Continuous(vec![3.0])).unwrap();
/// assert!(step.reward < 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct ModelEnv<M, T> {
    model: M,
    episodes: TaskEpisodes<T>,
    judges: Judges,
    state: Vec<f64>,
    elapsed: usize,
    running: bool,
}

impl<M: DynamicsModel, T: Task> ModelEnv<M, T> {
    /// The environment of `task` over `model`, judged by the task; an error when their
    /// dimensions disagree.
    pub fn new(model: M, task: T) -> Result<Self, EnvError> {
        Self::with_judges(model, task, Judges::default())
    }

    /// The environment of `task` over `model`, with reward and termination from `judges`.
    pub fn with_judges(model: M, task: T, judges: Judges) -> Result<Self, EnvError> {
        let unsupported = |e: ModelError| EnvError::Unsupported {
            env: task.id().to_string(),
            reason: e.to_string(),
        };
        check_pair(&model, &task).map_err(unsupported)?;
        judges.validate().map_err(unsupported)?;
        let n = task.state_dim();
        Ok(Self {
            model,
            episodes: TaskEpisodes::new(task),
            judges,
            state: vec![0.0; n],
            elapsed: 0,
            running: false,
        })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The model, mutably (to refit it between training phases).
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    /// The task.
    pub fn task(&self) -> &T {
        self.episodes.task()
    }

    fn start(&mut self) -> Vec<f64> {
        let task = self.episodes.task();
        task.canonicalize(&mut self.state);
        self.elapsed = 0;
        self.running = true;
        task.observe(&self.state)
    }
}

fn model_failure(env: &str) -> impl Fn(ModelError) -> EnvError + '_ {
    move |e| EnvError::Unsupported {
        env: env.to_string(),
        reason: format!("model prediction failed: {e}"),
    }
}

impl<M: DynamicsModel, T: Task> Env for ModelEnv<M, T> {
    fn id(&self) -> &str {
        self.task().id()
    }

    fn observation_space(&self) -> &Space {
        self.task().observation_space()
    }

    fn action_space(&self) -> &Space {
        self.task().action_space()
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        self.state = self.episodes.initial_state(seed);
        self.start()
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        if !self.running {
            return Err(EnvError::NeedsReset {
                env: self.task().id().to_string(),
                when: "before reset or after the episode ended",
            });
        }
        let u = self.episodes.control(action)?;
        let row = |v: &[f64]| Array2::from_shape_vec((1, v.len()), v.to_vec());
        let (s, a) = (row(&self.state), row(&u));
        let (s, a) = (s.expect("one row"), a.expect("one row"));
        let input = ModelInput::new(s.view(), a.view());
        let pred = self.model.predict(&input, self.episodes.rng_mut());
        let task = self.episodes.task();
        let id = task.id();
        let pred = pred.map_err(model_failure(id))?;
        let mut next: Vec<f64> = pred.next_states.row(0).to_vec();
        if let Some(i) = next.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::InvalidState {
                env: id.to_string(),
                reason: format!("the model predicted a non-finite state component {i}"),
            });
        }
        let (reward, terminated) = self
            .judges
            .judge(task, &pred, 0, (&self.state, &u, &next))
            .map_err(model_failure(id))?;
        task.canonicalize(&mut next);
        self.state = next;
        self.elapsed += 1;
        let truncated = task.max_episode_steps().is_some_and(|m| self.elapsed >= m);
        self.running = !(terminated || truncated);
        Ok(Step {
            observation: task.observe(&self.state),
            reward,
            terminated,
            truncated,
        })
    }

    fn state(&self) -> Vec<f64> {
        self.state.clone()
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        self.episodes.check_state(state)?;
        self.state = state.to_vec();
        Ok(self.start())
    }

    fn max_episode_steps(&self) -> Option<usize> {
        self.task().max_episode_steps()
    }
}

/// Imagined transitions from [`branched_rollouts`], one row each, step-major: all rollouts'
/// first steps, then the second steps of those that did not terminate, and so on.
#[derive(Debug, Clone, PartialEq)]
pub struct Imagined {
    /// States `s`, `N x S` (canonical).
    pub states: Array2<f64>,
    /// Observations of `s`, `N x O`: what the agent saw.
    pub observations: Array2<f64>,
    /// The agent's actions, `N x A` (for a discrete action space one column with the index).
    pub actions: Array2<f64>,
    /// The plant inputs they became, `N x U`.
    pub controls: Array2<f64>,
    /// Rewards, length `N`.
    pub rewards: Array1<f64>,
    /// Next states, `N x S` (canonical).
    pub next_states: Array2<f64>,
    /// Observations of the next states, `N x O`.
    pub next_observations: Array2<f64>,
    /// Whether the next state is terminal, length `N`.
    pub terminated: Vec<bool>,
    /// Index of the start (row of `starts`) each transition descends from.
    pub origin: Vec<usize>,
}

impl Imagined {
    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// `true` without transitions.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// The steps' rows one after the other (a single step as it is), with widths
    /// `(state, observation, action, control)`.
    fn stacked(steps: Vec<Imagined>, (n, o, a, m): (usize, usize, usize, usize)) -> Imagined {
        if steps.len() == 1 {
            return steps.into_iter().next().expect("one step");
        }
        let stack = |part: fn(&Imagined) -> ArrayView2<'_, f64>, cols: usize| {
            let parts: Vec<_> = steps.iter().map(part).collect();
            if parts.is_empty() {
                Array2::zeros((0, cols))
            } else {
                ndarray::concatenate(ndarray::Axis(0), &parts).expect("equal widths")
            }
        };
        Imagined {
            states: stack(|s| s.states.view(), n),
            observations: stack(|s| s.observations.view(), o),
            actions: stack(|s| s.actions.view(), a),
            controls: stack(|s| s.controls.view(), m),
            rewards: steps
                .iter()
                .flat_map(|s| s.rewards.iter().copied())
                .collect(),
            next_states: stack(|s| s.next_states.view(), n),
            next_observations: stack(|s| s.next_observations.view(), o),
            terminated: steps
                .iter()
                .flat_map(|s| s.terminated.iter().copied())
                .collect(),
            origin: steps
                .iter()
                .flat_map(|s| s.origin.iter().copied())
                .collect(),
        }
    }
}

/// A batched policy for imagined rollouts: observations `B x O` to actions `B x A` (for a
/// discrete action space one column holding the index), drawing any randomness from the
/// generator it is given.
pub type RolloutPolicy<'a> =
    dyn FnMut(ArrayView2<'_, f64>, &mut Rng) -> Result<Array2<f64>, ModelError> + 'a;

/// Rolls `horizon` steps of `model` under `task` from every row of `starts` at once (MBPO's
/// branched rollouts; `horizon = 1` is p1's one-step Dyna). Each step asks `policy` for the
/// actions of the rollouts still running, makes one `predict` call for all of them, and judges reward
/// and termination as `judges` say; a rollout that terminates stops. The model draws from
/// `rng`, and so does the policy.
///
/// Errors for mismatched sizes, a policy returning the wrong shape or an action outside the
/// task's action space, a model without the reward or termination `judges` ask of it, and
/// non-finite predictions (naming the row).
#[allow(clippy::too_many_arguments)]
pub fn branched_rollouts<M, T>(
    model: &M,
    task: &T,
    judges: &Judges,
    starts: ArrayView2<'_, f64>,
    horizon: usize,
    policy: &mut RolloutPolicy<'_>,
    rng: &mut Rng,
) -> Result<Imagined, ModelError>
where
    M: DynamicsModel + ?Sized,
    T: Task + ?Sized,
{
    let m = check_pair(model, task)?;
    judges.validate()?;
    let (b, n) = (starts.nrows(), task.state_dim());
    crate::data::check_array("start states", starts, b, n)?;
    let mut state = starts.as_standard_layout().into_owned();
    for mut r in state.rows_mut() {
        task.canonicalize(r.as_slice_mut().expect("row-major"));
    }
    let a_dim = match task.action_space() {
        Space::Discrete { .. } => 1,
        Space::Box { low, .. } => low.len(),
    };
    let o_dim = task.observation_space().flat_dim();
    let mut obs = observations(task, state.view(), o_dim)?;
    let mut alive: Vec<usize> = (0..b).collect();
    let mut steps = Vec::with_capacity(horizon);
    for t in 0..horizon {
        let k = alive.len();
        if k == 0 {
            break;
        }
        let actions = row_major(policy(obs.view(), rng)?);
        if actions.dim() != (k, a_dim) {
            return Err(ModelError::Dim {
                what: "policy actions (rows x columns)".into(),
                expected: k * a_dim,
                got: actions.len(),
            });
        }
        let controls = controls_of(task, actions.view(), m)?;
        let input = ModelInput::new(state.view(), controls.view());
        let mut pred = model.predict(&input, rng)?;
        crate::data::check_array("predicted next states", pred.next_states.view(), k, n)?;
        // The judges read the predicted reward and termination, not the next states.
        let mut next = row_major(std::mem::take(&mut pred.next_states));
        let mut rewards = Vec::with_capacity(k);
        let mut terminated = Vec::with_capacity(k);
        for i in 0..k {
            let (s, u) = (state.row(i), controls.row(i));
            let (s, u) = (s.as_slice().expect("row"), u.as_slice().expect("row"));
            let mut s1 = next.row_mut(i);
            let s1 = s1.as_slice_mut().expect("row");
            let (reward, done) = judges.judge(task, &pred, i, (s, u, s1))?;
            task.canonicalize(s1);
            rewards.push(reward);
            terminated.push(done);
        }
        let next_obs = observations(task, next.view(), o_dim)?;
        let step = Imagined {
            states: state,
            observations: obs,
            actions,
            controls,
            rewards: Array1::from(rewards),
            next_states: next,
            next_observations: next_obs,
            terminated,
            origin: alive,
        };
        let keep: Vec<usize> = (0..k).filter(|&i| !step.terminated[i]).collect();
        alive = keep.iter().map(|&i| step.origin[i]).collect();
        // The survivors' observations are those of their next states.
        (state, obs) = if t + 1 == horizon {
            (Array2::zeros((0, n)), Array2::zeros((0, o_dim)))
        } else {
            let select = |a: &Array2<f64>| a.select(ndarray::Axis(0), &keep);
            (select(&step.next_states), select(&step.next_observations))
        };
        steps.push(step);
    }
    Ok(Imagined::stacked(steps, (n, o_dim, a_dim, m)))
}

/// `a` in row-major order, copied only where it is not (a policy or a model may return any
/// layout; the rows are read as slices).
fn row_major(a: Array2<f64>) -> Array2<f64> {
    if a.is_standard_layout() {
        a
    } else {
        a.as_standard_layout().into_owned()
    }
}

/// The observation of every row of `states`; an error where one is not `o` wide.
fn observations<T: Task + ?Sized>(
    task: &T,
    states: ArrayView2<'_, f64>,
    o: usize,
) -> Result<Array2<f64>, ModelError> {
    let mut out = Vec::with_capacity(states.nrows() * o);
    for s in states.rows() {
        let y = task.observe(s.as_slice().expect("row-major"));
        check_width("task observation", &y, o)?;
        out.extend_from_slice(&y);
    }
    Ok(Array2::from_shape_vec((states.nrows(), o), out).expect("checked widths"))
}

fn check_width(what: &str, v: &[f64], expected: usize) -> Result<(), ModelError> {
    if v.len() == expected {
        Ok(())
    } else {
        Err(ModelError::Dim {
            what: what.into(),
            expected,
            got: v.len(),
        })
    }
}

/// The plant inputs `k x m` of the policy's `actions`, each checked against the action space.
fn controls_of<T: Task + ?Sized>(
    task: &T,
    actions: ArrayView2<'_, f64>,
    m: usize,
) -> Result<Array2<f64>, ModelError> {
    let space = task.action_space();
    let mut out = Vec::with_capacity(actions.nrows() * m);
    let mut action = Action::Continuous(Vec::with_capacity(actions.ncols()));
    for (i, row) in actions.rows().into_iter().enumerate() {
        set_action(space, row.as_slice().expect("row-major"), &mut action);
        space
            .check(&action)
            .map_err(|e| ModelError::Other(format!("policy action of row {i} is invalid: {e}")))?;
        let u = task.control(&action);
        check_width("task control", &u, m)?;
        out.extend_from_slice(&u);
    }
    Ok(Array2::from_shape_vec((actions.nrows(), m), out).expect("checked widths"))
}

/// Makes `action` the action a stored row stands for in `space`, reusing its vector.
fn set_action(space: &Space, row: &[f64], action: &mut Action) {
    if let Space::Discrete { .. } = space {
        let k = row[0];
        if k >= 0.0 && k.fract() == 0.0 && k < usize::MAX as f64 {
            *action = Action::Discrete(k as usize);
            return;
        }
        // Not an index: let the space's check report it.
    }
    match action {
        Action::Continuous(v) => {
            v.clear();
            v.extend_from_slice(row);
        }
        Action::Discrete(_) => *action = Action::Continuous(row.to_vec()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FitConfig, FitReport, PlantModel, Transitions};
    use ndarray::array;
    use tandem_core::seeding::rng_from_seed;
    use tandem_dynamics::classic::{CartPole, GymPendulum, GymPendulumParams};
    use tandem_envs::{CartPoleEnv, CartPoleTask, PendulumTask};

    /// The model environment over the plant replays the registered environment exactly: same
    /// observations, rewards and truncation, also over the top.
    #[test]
    fn plant_model_env_matches_the_registered_pendulum() {
        let p = GymPendulumParams::default();
        let task = PendulumTask::new(&p);
        let mut m = ModelEnv::new(PlantModel::new(GymPendulum::new(p)), task).unwrap();
        let mut e = tandem_envs::make("Pendulum-v1").unwrap();
        assert_eq!(m.reset(Some(1)), e.reset(Some(1)));
        let mut wrapped = false;
        let mut velocity = 0.0;
        for t in 0..200 {
            // Pumping energy (torque along the velocity, over-range to test clipping) swings the
            // pendulum to the top and over it.
            let u = if velocity >= 0.0 { 3.0 } else { -3.0 };
            let a = Action::Continuous(vec![u]);
            let (sm, se) = (m.step(&a).unwrap(), e.step(&a).unwrap());
            for k in 0..3 {
                assert!(
                    (sm.observation[k] - se.observation[k]).abs() < 1e-6,
                    "t={t}: {:?} vs {:?}",
                    sm.observation,
                    se.observation
                );
            }
            assert!((sm.reward - se.reward).abs() < 1e-6);
            assert_eq!(sm.truncated, se.truncated, "t={t}");
            wrapped |= sm.observation[0] > 0.9;
            velocity = se.observation[2];
        }
        assert!(wrapped, "the test trajectory should reach the top");
        assert!(matches!(
            m.step(&Action::Continuous(vec![0.0])),
            Err(EnvError::NeedsReset { .. })
        ));
    }

    /// Branched rollouts through the true plant are the real environment stepped row by row:
    /// the same transitions, rewards and terminations, and a terminated rollout stops.
    #[test]
    fn branched_rollouts_through_the_plant_replay_the_environment() {
        let model = PlantModel::new(CartPole::default());
        let task = CartPoleTask::default();
        // The second start is about to fall: it terminates at the first step.
        let starts = array![
            [0.0, 0.1, 0.02, -0.1],
            [2.39, 5.0, 0.0, 0.0],
            [0.0, 0.0, 0.1, 0.5]
        ];
        // Push right on even columns of the observation's sign, left otherwise.
        let mut policy = |obs: ArrayView2<'_, f64>, _: &mut Rng| {
            Ok(obs
                .map_axis(ndarray::Axis(1), |r| f64::from(u8::from(r[2] > 0.0)))
                .insert_axis(ndarray::Axis(1)))
        };
        let h = 4;
        let out = branched_rollouts(
            &model,
            &task,
            &Judges::default(),
            starts.view(),
            h,
            &mut policy,
            &mut rng_from_seed(0),
        )
        .unwrap();
        assert_eq!(out.len(), 3 + 2 * (h - 1));
        assert_eq!(out.origin[..5], [0, 1, 2, 0, 2]);
        let mut row = 0;
        let mut envs: Vec<CartPoleEnv> = (0..3).map(|_| CartPoleEnv::new()).collect();
        for (i, env) in envs.iter_mut().enumerate() {
            env.set_state(starts.row(i).as_slice().unwrap()).unwrap();
        }
        for t in 0..h {
            for (i, env) in envs.iter_mut().enumerate() {
                if i == 1 && t > 0 {
                    continue;
                }
                let s = env.state();
                let a = Action::Discrete(usize::from(s[2] > 0.0));
                let st = env.step(&a).unwrap();
                assert_eq!(out.origin[row], i);
                assert_eq!(out.states.row(row).to_vec(), s);
                assert_eq!(out.observations.row(row).to_vec(), task.observe(&s));
                assert_eq!(out.next_states.row(row).to_vec(), env.state());
                assert_eq!(out.next_observations.row(row).to_vec(), st.observation);
                assert_eq!(out.rewards[row], st.reward);
                assert_eq!(out.terminated[row], st.terminated);
                assert_eq!(
                    out.controls[(row, 0)],
                    if s[2] > 0.0 { 10.0 } else { -10.0 }
                );
                row += 1;
            }
        }
        assert!(out.terminated[1]);
    }

    /// `s' = s + u`, reward 7, terminal with probability 0.9 where `s[0] > 0`, else 0.1.
    #[derive(Debug, Clone)]
    struct Scripted;
    impl DynamicsModel for Scripted {
        fn state_dim(&self) -> usize {
            4
        }
        fn action_dim(&self) -> usize {
            1
        }
        fn predict(&self, input: &ModelInput<'_>, _: &mut Rng) -> Result<Prediction, ModelError> {
            let mut next = input.states.to_owned();
            next.column_mut(0).scaled_add(1.0, &input.actions.column(0));
            let b = next.nrows();
            Ok(Prediction {
                terminal_prob: Some(
                    input
                        .states
                        .column(0)
                        .mapv(|x| if x > 0.0 { 0.9 } else { 0.1 }),
                ),
                next_states: next,
                variance: None,
                rewards: Some(Array1::from_elem(b, 7.0)),
            })
        }
        fn fit(&mut self, _: &Transitions, _: &FitConfig) -> Result<FitReport, ModelError> {
            Ok(FitReport::default())
        }
    }

    #[test]
    fn model_judges_take_reward_and_termination_from_the_prediction() {
        let mut env =
            ModelEnv::with_judges(Scripted, CartPoleTask::default(), Judges::model()).unwrap();
        env.set_state(&[-1.0, 0.0, 0.0, 0.0]).unwrap();
        // -1 + 10: the state the model saw was negative, so p = 0.1 < 0.5.
        let st = env.step(&Action::Discrete(1)).unwrap();
        assert_eq!((st.reward, st.terminated), (7.0, false));
        assert_eq!(env.state()[0], 9.0);
        let st = env.step(&Action::Discrete(0)).unwrap();
        assert_eq!((st.reward, st.terminated), (7.0, true));
        // The task would have ended the episode at |x| > 2.4 after the first step.
        let mut by_task = ModelEnv::new(Scripted, CartPoleTask::default()).unwrap();
        by_task.set_state(&[-1.0, 0.0, 0.0, 0.0]).unwrap();
        let st = by_task.step(&Action::Discrete(1)).unwrap();
        assert_eq!((st.reward, st.terminated), (1.0, true));
    }

    /// A model's next states and the starts in column-major order give the rollouts of
    /// row-major ones (the rows are read as slices).
    #[test]
    fn branched_rollouts_take_any_layout() {
        #[derive(Debug, Clone)]
        struct ColumnMajor<M>(M);
        impl<M: DynamicsModel> DynamicsModel for ColumnMajor<M> {
            fn state_dim(&self) -> usize {
                self.0.state_dim()
            }
            fn action_dim(&self) -> usize {
                self.0.action_dim()
            }
            fn predict(
                &self,
                input: &ModelInput<'_>,
                rng: &mut Rng,
            ) -> Result<Prediction, ModelError> {
                let mut p = self.0.predict(input, rng)?;
                p.next_states = column_major(&p.next_states);
                Ok(p)
            }
            fn fit(
                &mut self,
                data: &Transitions,
                cfg: &FitConfig,
            ) -> Result<FitReport, ModelError> {
                self.0.fit(data, cfg)
            }
        }
        fn column_major(a: &Array2<f64>) -> Array2<f64> {
            use ndarray::ShapeBuilder;
            let mut f = Array2::zeros(a.raw_dim().f());
            f.assign(a);
            f
        }
        let p = GymPendulumParams::default();
        let (task, model) = (PendulumTask::new(&p), PlantModel::new(GymPendulum::new(p)));
        let starts = array![[0.5, 0.0], [-2.0, 1.0], [3.0, -0.5]];
        let starts_f = column_major(&starts);
        assert!(!starts_f.is_standard_layout());
        let run = |model: &dyn DynamicsModel, starts: ArrayView2<'_, f64>| {
            branched_rollouts(
                model,
                &task,
                &Judges::default(),
                starts,
                3,
                &mut |obs: ArrayView2<'_, f64>, _: &mut Rng| {
                    Ok(obs.slice(ndarray::s![.., 2..3]).to_owned())
                },
                &mut rng_from_seed(0),
            )
            .unwrap()
        };
        let rows = run(&model, starts.view());
        assert_eq!(rows.len(), 9);
        assert_eq!(run(&ColumnMajor(model), starts_f.view()), rows);
    }

    #[test]
    fn bad_pairs_policies_and_missing_predictions_are_errors() {
        let p = GymPendulumParams::default();
        let task = PendulumTask::new(&p);
        assert!(ModelEnv::new(PlantModel::new(CartPole::default()), task.clone()).is_err());
        let bad = Judges {
            terminal_threshold: f64::NAN,
            ..Judges::default()
        };
        let model = PlantModel::new(GymPendulum::new(p));
        assert!(ModelEnv::with_judges(model.clone(), task.clone(), bad).is_err());
        let mut env = ModelEnv::with_judges(model.clone(), task.clone(), Judges::model()).unwrap();
        env.reset(Some(0));
        let err = env.step(&Action::Continuous(vec![1.0])).unwrap_err();
        assert!(err.to_string().contains("no reward"), "{err}");

        let starts = array![[0.0, 0.0]];
        let run = |policy: &mut RolloutPolicy<'_>, starts: ArrayView2<'_, f64>| {
            branched_rollouts(
                &model,
                &task,
                &Judges::default(),
                starts,
                2,
                policy,
                &mut rng_from_seed(0),
            )
        };
        let wide = run(&mut |_, _| Ok(array![[0.0, 0.0]]), starts.view());
        assert!(matches!(wide, Err(ModelError::Dim { .. })));
        let nan = run(&mut |_, _| Ok(array![[f64::NAN]]), starts.view());
        assert!(nan.unwrap_err().to_string().contains("row 0"));
        let bad_start = run(
            &mut |_, _| Ok(array![[0.0]]),
            array![[f64::INFINITY, 0.0]].view(),
        );
        assert!(matches!(bad_start, Err(ModelError::NonFinite { .. })));
        let ok = run(&mut |_, _| Ok(array![[3.0]]), starts.view()).unwrap();
        assert_eq!(ok.len(), 2);

        // A task whose observations are wider than its observation space says.
        struct Wide(PendulumTask);
        impl Task for Wide {
            fn id(&self) -> &str {
                self.0.id()
            }
            fn observation_space(&self) -> &Space {
                self.0.observation_space()
            }
            fn action_space(&self) -> &Space {
                self.0.action_space()
            }
            fn state_dim(&self) -> usize {
                self.0.state_dim()
            }
            fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
                self.0.initial_state(rng)
            }
            fn observe(&self, state: &[f64]) -> Vec<f64> {
                let mut o = self.0.observe(state);
                o.push(0.0);
                o
            }
            fn reward(&self, s: &[f64], u: &[f64], next: &[f64]) -> f64 {
                self.0.reward(s, u, next)
            }
        }
        let wide_obs = branched_rollouts(
            &model,
            &Wide(task),
            &Judges::default(),
            starts.view(),
            1,
            &mut |_, _| Ok(array![[0.0]]),
            &mut rng_from_seed(0),
        );
        assert!(
            matches!(&wide_obs, Err(ModelError::Dim { what, expected: 3, got: 4 }) if what == "task observation"),
            "{wide_obs:?}"
        );
    }
}
