//! [`GymTask`]: a gymnasium locomotion task as a [`tandem_envs::Task`] over the MuJoCo state
//! `qpos ++ qvel`, so that a learned model (MBPO's ensemble, M-DeMoRL's planner) can observe,
//! score and end its imagined steps exactly as the real environment does.
//!
//! Only the tasks whose observation, reward and termination are functions of `qpos`/`qvel` alone
//! qualify: HalfCheetah-v5, Hopper-v5, Walker2d-v5 and InvertedPendulum-v5 (Ant reads contact
//! forces, Reacher and Pusher body positions).
//!
//! ```
//! use tandem_envs::Task;
//! use tandem_mujoco::{GymTask, TaskKind};
//!
//! // HalfCheetah's qpos0 is zero.
//! let task = GymTask::new(TaskKind::HalfCheetah, vec![0.0; 9]).unwrap();
//! let mut x = vec![0.0; 18];
//! let mut next = x.clone();
//! next[0] = 0.05; // 5 cm forward in one 0.05 s step
//! let r = task.reward(&x, &[0.0; 6], &next);
//! assert!((r - 1.0).abs() < 1e-12);
//! // The x position is translation-invariant: a model sees it at 0.
//! x[0] = 3.0;
//! task.canonicalize(&mut x);
//! assert_eq!(x[0], 0.0);
//! ```

use tandem_core::{Action, Rng, Space};
use tandem_envs::{EnvError, ObservedTask, Task};

use crate::task::{Readout, TaskKind};

/// A gymnasium locomotion task over the state `qpos ++ qvel` (see the module docs).
#[derive(Debug, Clone)]
pub struct GymTask {
    kind: TaskKind,
    init_qpos: Vec<f64>,
    observation_space: Space,
    action_space: Space,
}

impl GymTask {
    /// The task `kind` of a model whose `qpos0` is `init_qpos` (Hopper and Walker2d measure the
    /// height from it, and episodes start around it); an error for a task that needs more than
    /// `qpos`/`qvel`, or an `init_qpos` of the wrong length or not finite.
    pub fn new(kind: TaskKind, init_qpos: Vec<f64>) -> Result<Self, EnvError> {
        let spec = kind.spec();
        let unsupported = |reason: String| EnvError::Unsupported {
            env: spec.id.to_string(),
            reason,
        };
        if matches!(kind, TaskKind::Ant | TaskKind::Reacher | TaskKind::Pusher) {
            return Err(unsupported(
                "its observation or reward reads more than qpos and qvel (contact forces or body \
                 positions), so it is not a task over the state"
                    .into(),
            ));
        }
        if init_qpos.len() != spec.nq || init_qpos.iter().any(|v| !v.is_finite()) {
            return Err(unsupported(format!(
                "init_qpos must be {} finite numbers, got {:?}",
                spec.nq, init_qpos
            )));
        }
        let b = spec.action_bound;
        Ok(Self {
            kind,
            init_qpos,
            observation_space: Space::unbounded(spec.obs_dim),
            action_space: Space::Box {
                low: vec![-b; spec.nu],
                high: vec![b; spec.nu],
                shape: vec![spec.nu],
            },
        })
    }

    /// The task.
    pub fn kind(&self) -> TaskKind {
        self.kind
    }

    fn readout<'a>(&self, state: &'a [f64]) -> Readout<'a> {
        let nq = self.kind.spec().nq;
        Readout {
            qpos: &state[..nq],
            qvel: &state[nq..],
            bodies: &[],
            cfrc_ext: &[],
        }
    }
}

impl GymTask {
    /// `(qpos, qvel)` of an observation, the x position (left out of the locomotion tasks'
    /// observations) at 0; the velocities as observed (Hopper and Walker2d clip them to ±10).
    fn state_of_observation(&self, obs: &[f64]) -> Vec<f64> {
        match self.kind {
            TaskKind::InvertedPendulum => obs.to_vec(),
            _ => std::iter::once(0.0).chain(obs.iter().copied()).collect(),
        }
    }
}

/// Reward and termination over observations. Termination is gymnasium's, read off the
/// observation (Hopper's `|s| < 100` test sees velocities clipped to ±10, so a velocity beyond
/// 100 is missed). The locomotion tasks' forward reward is the change of the x position, which
/// the observation leaves out: it is approximated by the mean of the x velocities observed
/// before and after the step. On gymnasium's recorded random-action steps the reward is off by at
/// most 0.54 on HalfCheetah (0.05 s steps; 0.18 root mean square) and 0.04 on Hopper and
/// Walker2d (0.008 s steps).
impl ObservedTask for GymTask {
    fn observation_reward(&self, obs: &[f64], u: &[f64], next_obs: &[f64]) -> f64 {
        let mut state = self.state_of_observation(obs);
        let mut next = self.state_of_observation(next_obs);
        if self.kind != TaskKind::InvertedPendulum {
            let nq = self.kind.spec().nq;
            next[0] = 0.5 * (state[nq] + next[nq]) * self.kind.dt();
            state[0] = 0.0;
        }
        self.reward(&state, u, &next)
    }

    fn observation_terminated(&self, next_obs: &[f64]) -> bool {
        self.terminated(&self.state_of_observation(next_obs))
    }
}

impl Task for GymTask {
    fn id(&self) -> &str {
        self.kind.spec().id
    }

    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn state_dim(&self) -> usize {
        let spec = self.kind.spec();
        spec.nq + spec.nv
    }

    /// The action clipped into the actuators' range, as MuJoCo applies it.
    fn control(&self, action: &Action) -> Vec<f64> {
        match action {
            Action::Continuous(a) => tandem_envs::clip_to(&self.action_space, a),
            Action::Discrete(_) => vec![0.0; self.kind.spec().nu],
        }
    }

    fn initial_state(&self, rng: &mut Rng) -> Vec<f64> {
        let nv = self.kind.spec().nv;
        let (mut qpos, qvel) = self.kind.reset_state(&self.init_qpos, &vec![0.0; nv], rng);
        qpos.extend(qvel);
        qpos
    }

    fn observe(&self, state: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.kind.spec().obs_dim);
        self.kind.observe(&self.readout(state), &mut out);
        out
    }

    /// The x position at 0: the locomotion tasks are invariant to it (their observations leave
    /// it out and their rewards use its change). InvertedPendulum's cart position is observed,
    /// so it stays.
    fn canonicalize(&self, state: &mut [f64]) {
        if self.kind != TaskKind::InvertedPendulum {
            state[0] = 0.0;
        }
    }

    /// gymnasium's reward of the step, its control cost on `u` (the clipped action: equal to
    /// gymnasium's for actions within the range, which is where agents with squashed actions
    /// act).
    fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let action: Vec<f32> = u.iter().map(|&v| v as f32).collect();
        let (before, after) = (self.readout(state), self.readout(next));
        self.kind
            .outcome(&before, &after, &action, &self.init_qpos)
            .reward
    }

    fn terminated(&self, next: &[f64]) -> bool {
        let r = self.readout(next);
        match self.kind {
            TaskKind::InvertedPendulum => {
                let finite = next.iter().all(|v| v.is_finite());
                !finite || r.qpos[1].abs() > 0.2
            }
            kind => !kind.is_healthy(&r),
        }
    }

    fn max_episode_steps(&self) -> Option<usize> {
        Some(self.kind.spec().max_episode_steps)
    }
}
