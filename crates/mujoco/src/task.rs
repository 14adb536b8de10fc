//! gymnasium's MuJoCo v5 tasks as pure functions of what the simulator reports: observation
//! layouts, rewards and their terms (gymnasium's `info`), health and termination, and reset noise.
//!
//! Nothing here calls MuJoCo, so the formulas are tested without the library: the environments of
//! [`crate::MujocoEnv`] (feature `mujoco`) read a [`Readout`] from MuJoCo's data after each step and
//! call [`TaskKind::outcome`] and [`TaskKind::observe`].
//!
//! Exactness: gymnasium computes control costs in `float32` (the action is a `float32` array and
//! NumPy 2 keeps Python-float weights weak), sums with NumPy's pairwise order
//! ([`crate::numpy`]), and reads body positions (`xpos`) as MuJoCo leaves them after the last
//! substep. Doing the same gives gymnasium's rewards bit for bit, except where gymnasium takes a
//! Euclidean norm through BLAS (Reacher, Pusher, Ant's `distance_from_origin`: within 2.3e-16 on
//! the recorded episodes).

use rand::Rng as _;
use rand_distr::{Distribution, StandardNormal};
use tandem_core::Rng;

use crate::numpy::{norm3, np_sum_f64, np_sum_squares_f32};

/// The seven gymnasium MuJoCo v5 tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TaskKind {
    /// `HalfCheetah-v5`: run forward; never terminates.
    HalfCheetah,
    /// `Hopper-v5`: hop forward; terminates when unhealthy.
    Hopper,
    /// `Walker2d-v5`: walk forward; terminates when unhealthy.
    Walker2d,
    /// `Ant-v5`: walk forward on four legs; terminates when the torso leaves `[0.2, 1.0]`.
    Ant,
    /// `InvertedPendulum-v5`: keep the pole within 0.2 rad.
    InvertedPendulum,
    /// `Reacher-v5`: move a two-link arm's fingertip to a random target.
    Reacher,
    /// `Pusher-v5`: push a cylinder to a goal with a 7-DoF arm.
    Pusher,
}

/// Constants of a task: gymnasium's registration and constructor defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskSpec {
    /// The registered id, e.g. `"HalfCheetah-v5"`.
    pub id: &'static str,
    /// The MJCF file in gymnasium's asset folder.
    pub xml: &'static str,
    /// MuJoCo substeps per environment step.
    pub frame_skip: usize,
    /// The MJCF's `timestep` (checked against the loaded model).
    pub timestep: f64,
    /// `TimeLimit` of the registration.
    pub max_episode_steps: usize,
    /// Position coordinates.
    pub nq: usize,
    /// Velocity coordinates.
    pub nv: usize,
    /// Actuators (the action's length).
    pub nu: usize,
    /// Bodies in the model (world included).
    pub nbody: usize,
    /// Observation length.
    pub obs_dim: usize,
    /// The action box is `[-action_bound, action_bound]` per component (the actuators' ctrlrange).
    pub action_bound: f64,
    /// Bodies whose position (`xpos`) the task reads, in the order of [`Readout::bodies`].
    pub bodies: &'static [&'static str],
    /// Names of the per-step terms ([`Outcome::terms`]), as gymnasium's `info` keys.
    pub terms: &'static [&'static str],
    /// One line on the task.
    pub description: &'static str,
}

const LOCOMOTION_TERMS: &[&str] = &[
    "x_position",
    "z_distance_from_origin",
    "x_velocity",
    "reward_forward",
    "reward_ctrl",
    "reward_survive",
];

impl TaskKind {
    /// All tasks, in registration order.
    pub const ALL: [TaskKind; 7] = [
        TaskKind::HalfCheetah,
        TaskKind::Hopper,
        TaskKind::Walker2d,
        TaskKind::Ant,
        TaskKind::InvertedPendulum,
        TaskKind::Reacher,
        TaskKind::Pusher,
    ];

    /// The task registered as `id`.
    pub fn from_id(id: &str) -> Option<TaskKind> {
        Self::ALL.into_iter().find(|k| k.spec().id == id)
    }

    /// The task's constants.
    pub const fn spec(self) -> TaskSpec {
        match self {
            TaskKind::HalfCheetah => TaskSpec {
                id: "HalfCheetah-v5",
                xml: "half_cheetah.xml",
                frame_skip: 5,
                timestep: 0.01,
                max_episode_steps: 1000,
                nq: 9,
                nv: 9,
                nu: 6,
                nbody: 8,
                obs_dim: 17,
                action_bound: 1.0,
                bodies: &[],
                terms: &["x_position", "x_velocity", "reward_forward", "reward_ctrl"],
                description: "gymnasium HalfCheetah-v5 on MuJoCo: a planar cheetah runs forward",
            },
            TaskKind::Hopper => TaskSpec {
                id: "Hopper-v5",
                xml: "hopper.xml",
                frame_skip: 4,
                timestep: 0.002,
                max_episode_steps: 1000,
                nq: 6,
                nv: 6,
                nu: 3,
                nbody: 5,
                obs_dim: 11,
                action_bound: 1.0,
                bodies: &[],
                terms: LOCOMOTION_TERMS,
                description: "gymnasium Hopper-v5 on MuJoCo: a one-legged hopper hops forward",
            },
            TaskKind::Walker2d => TaskSpec {
                id: "Walker2d-v5",
                xml: "walker2d_v5.xml",
                frame_skip: 4,
                timestep: 0.002,
                max_episode_steps: 1000,
                nq: 9,
                nv: 9,
                nu: 6,
                nbody: 8,
                obs_dim: 17,
                action_bound: 1.0,
                bodies: &[],
                terms: LOCOMOTION_TERMS,
                description: "gymnasium Walker2d-v5 on MuJoCo: a planar biped walks forward",
            },
            TaskKind::Ant => TaskSpec {
                id: "Ant-v5",
                xml: "ant.xml",
                frame_skip: 5,
                timestep: 0.01,
                max_episode_steps: 1000,
                nq: 15,
                nv: 14,
                nu: 8,
                nbody: 14,
                obs_dim: 105,
                action_bound: 1.0,
                bodies: &["torso"],
                terms: &[
                    "x_position",
                    "y_position",
                    "distance_from_origin",
                    "x_velocity",
                    "y_velocity",
                    "reward_forward",
                    "reward_ctrl",
                    "reward_contact",
                    "reward_survive",
                ],
                description: "gymnasium Ant-v5 on MuJoCo: a quadruped walks forward",
            },
            TaskKind::InvertedPendulum => TaskSpec {
                id: "InvertedPendulum-v5",
                xml: "inverted_pendulum.xml",
                frame_skip: 2,
                timestep: 0.02,
                max_episode_steps: 1000,
                nq: 2,
                nv: 2,
                nu: 1,
                nbody: 3,
                obs_dim: 4,
                action_bound: 3.0,
                bodies: &[],
                terms: &["reward_survive"],
                description: "gymnasium InvertedPendulum-v5 on MuJoCo: balance a pole on a cart",
            },
            TaskKind::Reacher => TaskSpec {
                id: "Reacher-v5",
                xml: "reacher.xml",
                frame_skip: 2,
                timestep: 0.01,
                max_episode_steps: 50,
                nq: 4,
                nv: 4,
                nu: 2,
                nbody: 5,
                obs_dim: 10,
                action_bound: 1.0,
                bodies: &["fingertip", "target"],
                terms: &["reward_dist", "reward_ctrl"],
                description: "gymnasium Reacher-v5 on MuJoCo: bring a 2-link arm's tip to a target",
            },
            TaskKind::Pusher => TaskSpec {
                id: "Pusher-v5",
                xml: "pusher_v5.xml",
                frame_skip: 5,
                timestep: 0.01,
                max_episode_steps: 100,
                nq: 11,
                nv: 11,
                nu: 7,
                nbody: 13,
                obs_dim: 23,
                action_bound: 2.0,
                bodies: &["tips_arm", "object", "goal"],
                terms: &["reward_dist", "reward_ctrl", "reward_near"],
                description:
                    "gymnasium Pusher-v5 on MuJoCo: push a cylinder to a goal with a 7-DoF arm",
            },
        }
    }

    /// Seconds per environment step: `timestep · frame_skip`, as gymnasium's `dt`.
    pub fn dt(self) -> f64 {
        let s = self.spec();
        s.timestep * s.frame_skip as f64
    }

    /// The observation of `r`, written into `out` (cleared first).
    pub fn observe(self, r: &Readout<'_>, out: &mut Vec<f64>) {
        out.clear();
        match self {
            TaskKind::HalfCheetah => {
                out.extend_from_slice(&r.qpos[1..]);
                out.extend_from_slice(r.qvel);
            }
            TaskKind::Hopper | TaskKind::Walker2d => {
                out.extend_from_slice(&r.qpos[1..]);
                out.extend(r.qvel.iter().map(|v| v.clamp(-10.0, 10.0)));
            }
            TaskKind::Ant => {
                out.extend_from_slice(&r.qpos[2..]);
                out.extend_from_slice(r.qvel);
                for f in &r.cfrc_ext[1..] {
                    out.extend(f.iter().map(|v| v.clamp(-1.0, 1.0)));
                }
            }
            TaskKind::InvertedPendulum => {
                out.extend_from_slice(r.qpos);
                out.extend_from_slice(r.qvel);
            }
            TaskKind::Reacher => {
                out.extend(r.qpos[..2].iter().map(|q| q.cos()));
                out.extend(r.qpos[..2].iter().map(|q| q.sin()));
                out.extend_from_slice(&r.qpos[2..]);
                out.extend_from_slice(&r.qvel[..2]);
                let d = sub(r.bodies[0], r.bodies[1]);
                out.extend_from_slice(&d[..2]);
            }
            TaskKind::Pusher => {
                out.extend_from_slice(&r.qpos[..7]);
                out.extend_from_slice(&r.qvel[..7]);
                for b in r.bodies {
                    out.extend_from_slice(b);
                }
            }
        }
    }

    /// Reward, termination and reward terms of the step from `before` to `after` under `action`
    /// (the `float32` action as given to gymnasium, before MuJoCo clamps it into ctrlrange).
    ///
    /// `init_qpos` is the model's `qpos0` (Hopper and Walker2d report the height relative to it).
    pub fn outcome(
        self,
        before: &Readout<'_>,
        after: &Readout<'_>,
        action: &[f32],
        init_qpos: &[f64],
    ) -> Outcome {
        let spec = self.spec();
        let dt = self.dt();
        let sq = np_sum_squares_f32(action);
        let mut terms = [0.0; MAX_TERMS];
        let (reward, terminated) = match self {
            TaskKind::HalfCheetah => {
                let x_vel = (after.qpos[0] - before.qpos[0]) / dt;
                let forward = 1.0 * x_vel;
                let ctrl = (0.1f32 * sq) as f64;
                terms[..4].copy_from_slice(&[after.qpos[0], x_vel, forward, -ctrl]);
                (forward - ctrl, false)
            }
            TaskKind::Hopper | TaskKind::Walker2d => {
                let x_vel = (after.qpos[0] - before.qpos[0]) / dt;
                let forward = 1.0 * x_vel;
                let healthy = self.is_healthy(after);
                let survive = if healthy { 1.0 } else { 0.0 };
                let ctrl = (0.001f32 * sq) as f64;
                terms[..6].copy_from_slice(&[
                    after.qpos[0],
                    after.qpos[1] - init_qpos[1],
                    x_vel,
                    forward,
                    -ctrl,
                    survive,
                ]);
                ((forward + survive) - ctrl, !healthy)
            }
            TaskKind::Ant => {
                let (b, a) = (before.bodies[0], after.bodies[0]);
                let x_vel = (a[0] - b[0]) / dt;
                let y_vel = (a[1] - b[1]) / dt;
                let forward = x_vel * 1.0;
                let healthy = self.is_healthy(after);
                let survive = if healthy { 1.0 } else { 0.0 };
                let ctrl = (0.5f32 * sq) as f64;
                let contact = 5e-4 * ant_contact_sum(after.cfrc_ext);
                let (x, y) = (after.qpos[0], after.qpos[1]);
                terms[..9].copy_from_slice(&[
                    x,
                    y,
                    (x * x + y * y).sqrt(),
                    x_vel,
                    y_vel,
                    forward,
                    -ctrl,
                    -contact,
                    survive,
                ]);
                ((forward + survive) - (ctrl + contact), !healthy)
            }
            TaskKind::InvertedPendulum => {
                let finite = after.qpos.iter().chain(after.qvel).all(|v| v.is_finite());
                let terminated = !finite || after.qpos[1].abs() > 0.2;
                let r = if terminated { 0.0 } else { 1.0 };
                terms[0] = r;
                (r, terminated)
            }
            TaskKind::Reacher => {
                let dist = -norm3(sub(after.bodies[0], after.bodies[1]));
                let ctrl = (-sq) as f64;
                terms[..2].copy_from_slice(&[dist, ctrl]);
                (dist + ctrl, false)
            }
            TaskKind::Pusher => {
                let (tips, object, goal) = (after.bodies[0], after.bodies[1], after.bodies[2]);
                let near = -norm3(sub(object, tips)) * 0.5;
                let dist = -norm3(sub(object, goal));
                let ctrl = (-sq * 0.1f32) as f64;
                terms[..3].copy_from_slice(&[dist, ctrl, near]);
                ((dist + ctrl) + near, false)
            }
        };
        Outcome {
            reward,
            terminated,
            names: spec.terms,
            values: terms,
        }
    }

    /// gymnasium's `is_healthy` of the locomotion tasks (`true` for the others).
    pub fn is_healthy(self, r: &Readout<'_>) -> bool {
        match self {
            TaskKind::Hopper => {
                let (z, angle) = (r.qpos[1], r.qpos[2]);
                let state_ok = r.qpos[2..]
                    .iter()
                    .chain(r.qvel)
                    .all(|&s| -100.0 < s && s < 100.0);
                state_ok && 0.7 < z && -0.2 < angle && angle < 0.2
            }
            TaskKind::Walker2d => {
                let (z, angle) = (r.qpos[1], r.qpos[2]);
                0.8 < z && z < 2.0 && -1.0 < angle && angle < 1.0
            }
            TaskKind::Ant => {
                let finite = r.qpos.iter().chain(r.qvel).all(|v| v.is_finite());
                finite && (0.2..=1.0).contains(&r.qpos[2])
            }
            _ => true,
        }
    }

    /// The start of an episode: gymnasium's `reset_model` noise around `init_qpos`/`init_qvel`
    /// (the model's `qpos0` and zero), drawn from `rng`. Returns `(qpos, qvel)`.
    ///
    /// The distributions are gymnasium's; the numbers are not (they come from our generator, not
    /// NumPy's), so compare starts by distribution, and replay gymnasium episodes from their
    /// recorded start.
    pub fn reset_state(
        self,
        init_qpos: &[f64],
        init_qvel: &[f64],
        rng: &mut Rng,
    ) -> (Vec<f64>, Vec<f64>) {
        let uniform = |v: &[f64], s: f64, rng: &mut Rng| -> Vec<f64> {
            v.iter().map(|x| x + rng.random_range(-s..s)).collect()
        };
        match self {
            TaskKind::HalfCheetah | TaskKind::Ant => {
                let qpos = uniform(init_qpos, 0.1, rng);
                let qvel = init_qvel
                    .iter()
                    .map(|v| {
                        let n: f64 = StandardNormal.sample(rng);
                        v + 0.1 * n
                    })
                    .collect();
                (qpos, qvel)
            }
            TaskKind::Hopper | TaskKind::Walker2d => {
                let qpos = uniform(init_qpos, 0.005, rng);
                (qpos, uniform(init_qvel, 0.005, rng))
            }
            TaskKind::InvertedPendulum => {
                let qpos = uniform(init_qpos, 0.01, rng);
                (qpos, uniform(init_qvel, 0.01, rng))
            }
            TaskKind::Reacher => {
                let mut qpos = uniform(init_qpos, 0.1, rng);
                let goal = loop {
                    let g: [f64; 2] = [rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2)];
                    if (g[0] * g[0] + g[1] * g[1]).sqrt() < 0.2 {
                        break g;
                    }
                };
                let n = qpos.len();
                qpos[n - 2..].copy_from_slice(&goal);
                let mut qvel = uniform(init_qvel, 0.005, rng);
                let m = qvel.len();
                qvel[m - 2..].fill(0.0);
                (qpos, qvel)
            }
            TaskKind::Pusher => {
                let mut qpos = init_qpos.to_vec();
                let cylinder = loop {
                    let c: [f64; 2] = [rng.random_range(-0.3..0.0), rng.random_range(-0.2..0.2)];
                    if (c[0] * c[0] + c[1] * c[1]).sqrt() > 0.17 {
                        break c;
                    }
                };
                let n = qpos.len();
                qpos[n - 4..n - 2].copy_from_slice(&cylinder);
                qpos[n - 2..].fill(0.0);
                let mut qvel = uniform(init_qvel, 0.005, rng);
                let m = qvel.len();
                qvel[m - 4..].fill(0.0);
                (qpos, qvel)
            }
        }
    }
}

/// `Σ clip(cfrc_ext, -1, 1)²` over all bodies (world included) in NumPy's order, as Ant's
/// contact cost.
fn ant_contact_sum(cfrc_ext: &[[f64; 6]]) -> f64 {
    let mut sq = [0.0; 6 * 14];
    let n = 6 * cfrc_ext.len();
    if n > sq.len() {
        let v: Vec<f64> = cfrc_ext
            .iter()
            .flatten()
            .map(|f| f.clamp(-1.0, 1.0).powi(2))
            .collect();
        return np_sum_f64(&v);
    }
    for (s, f) in sq.iter_mut().zip(cfrc_ext.iter().flatten()) {
        let c = f.clamp(-1.0, 1.0);
        *s = c * c;
    }
    np_sum_f64(&sq[..n])
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// What a task reads from the simulator after (or before) a step.
#[derive(Debug, Clone, Copy)]
pub struct Readout<'a> {
    /// Joint positions (`data.qpos`).
    pub qpos: &'a [f64],
    /// Joint velocities (`data.qvel`).
    pub qvel: &'a [f64],
    /// Positions (`data.xpos`) of the bodies [`TaskSpec::bodies`] names, in that order.
    pub bodies: &'a [[f64; 3]],
    /// External contact forces of every body (`data.cfrc_ext`, world first); read by Ant only
    /// (may be empty for the others).
    pub cfrc_ext: &'a [[f64; 6]],
}

/// The most terms a task reports (Ant's nine).
pub const MAX_TERMS: usize = 9;

/// Reward, termination and the reward terms of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// The step's reward.
    pub reward: f64,
    /// The task reached a terminal state.
    pub terminated: bool,
    names: &'static [&'static str],
    values: [f64; MAX_TERMS],
}

impl Outcome {
    /// `(name, value)` of each term, named as gymnasium's `info` keys (e.g. `reward_forward`,
    /// `reward_ctrl`, `reward_contact`, `reward_survive`, `x_velocity`).
    pub fn terms(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.names.iter().copied().zip(self.values)
    }

    /// The value of term `name`, if the task reports it.
    pub fn term(&self, name: &str) -> Option<f64> {
        self.terms().find(|(n, _)| *n == name).map(|(_, v)| v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_core::seeding::rng_from_seed;

    fn readout<'a>(qpos: &'a [f64], qvel: &'a [f64]) -> Readout<'a> {
        Readout {
            qpos,
            qvel,
            bodies: &[],
            cfrc_ext: &[],
        }
    }

    #[test]
    fn ids_round_trip_and_specs_are_consistent() {
        for k in TaskKind::ALL {
            let s = k.spec();
            assert_eq!(TaskKind::from_id(s.id), Some(k));
            assert!(s.terms.len() <= MAX_TERMS);
        }
        assert_eq!(TaskKind::from_id("HalfCheetah-v4"), None);
        assert_eq!(TaskKind::HalfCheetah.dt(), 0.01 * 5.0);
    }

    #[test]
    fn hopper_health_uses_strict_bounds() {
        let qvel = [0.0; 6];
        let ok = [0.0, 1.25, 0.0, 0.0, 0.0, 0.0];
        assert!(TaskKind::Hopper.is_healthy(&readout(&ok, &qvel)));
        for (i, v) in [(1, 0.7), (2, 0.2), (2, -0.2), (3, 100.0)] {
            let mut q = ok;
            q[i] = v;
            assert!(!TaskKind::Hopper.is_healthy(&readout(&q, &qvel)), "{i} {v}");
        }
        // The state range skips x and z (index 0 and 1): a huge x is healthy.
        let mut q = ok;
        q[0] = 1e6;
        assert!(TaskKind::Hopper.is_healthy(&readout(&q, &qvel)));
    }

    #[test]
    fn ant_health_range_is_inclusive() {
        let qvel = [0.0; 14];
        let mut q = [0.0; 15];
        for (z, healthy) in [(0.2, true), (1.0, true), (0.19999, false), (1.00001, false)] {
            q[2] = z;
            assert_eq!(
                TaskKind::Ant.is_healthy(&readout(&q, &qvel)),
                healthy,
                "{z}"
            );
        }
        q[2] = 0.5;
        q[7] = f64::NAN;
        assert!(!TaskKind::Ant.is_healthy(&readout(&q, &qvel)));
    }

    #[test]
    fn half_cheetah_reward_by_hand() {
        let (q0, q1, v) = ([0.0; 9], [0.1; 9], [0.0; 9]);
        let o = TaskKind::HalfCheetah.outcome(
            &readout(&q0, &v),
            &readout(&q1, &v),
            &[0.5, -0.5, 0.0, 0.0, 0.0, 1.0],
            &[0.0; 9],
        );
        // x velocity 0.1 / 0.05 = 2; control cost 0.1 * 1.5 = 0.15 in float32.
        assert!((o.reward - (2.0 - 0.15)).abs() < 1e-7);
        assert_eq!(o.term("reward_ctrl"), Some(-((0.1f32 * 1.5f32) as f64)));
        assert!(!o.terminated);
    }

    #[test]
    fn inverted_pendulum_ends_past_0_2_rad() {
        let v = [0.0; 2];
        let o = |a: f64| {
            TaskKind::InvertedPendulum.outcome(
                &readout(&[0.0, 0.0], &v),
                &readout(&[0.0, a], &v),
                &[0.0],
                &[0.0; 2],
            )
        };
        assert_eq!((o(0.2).reward, o(0.2).terminated), (1.0, false));
        assert_eq!((o(-0.21).reward, o(-0.21).terminated), (0.0, true));
    }

    #[test]
    fn reset_noise_has_gymnasium_distributions() {
        let mut rng = rng_from_seed(3);
        let n = 4000;
        let (mut max_q, mut sum_v2) = (0.0f64, 0.0);
        for _ in 0..n {
            let (q, v) = TaskKind::HalfCheetah.reset_state(&[0.0; 9], &[0.0; 9], &mut rng);
            max_q = q.iter().fold(max_q, |m, x| m.max(x.abs()));
            sum_v2 += v.iter().map(|x| x * x).sum::<f64>();
        }
        assert!(max_q < 0.1 && max_q > 0.099);
        // qvel = 0.1 N(0, 1): variance 0.01 per component.
        let var = sum_v2 / (9 * n) as f64;
        assert!((var - 0.01).abs() < 0.0005, "{var}");

        for _ in 0..200 {
            let (q, v) = TaskKind::Reacher.reset_state(&[0.0, 0.0, 0.1, -0.1], &[0.0; 4], &mut rng);
            assert!(q[2].hypot(q[3]) < 0.2 && q[..2].iter().all(|x| x.abs() < 0.1));
            assert_eq!(&v[2..], &[0.0, 0.0]);
            assert!(v[..2].iter().all(|x| x.abs() < 0.005));
            let (q, v) = TaskKind::Pusher.reset_state(&[0.0; 11], &[0.0; 11], &mut rng);
            assert!(q[7].hypot(q[8]) > 0.17 && (-0.3..0.0).contains(&q[7]));
            assert_eq!(&q[9..], &[0.0, 0.0]);
            assert_eq!(&v[7..], &[0.0; 4]);
        }
    }
}
