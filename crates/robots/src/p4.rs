//! p4's (PILQR, Chebotar et al. 2017) manipulation tasks as MuJoCo scenes written for tandem:
//! the geometry, the conditions (initial states and goals) and the costs, as pure functions of
//! the scene's state `qpos ++ qvel`. The scenes themselves are in this crate's `scenes/` folder
//! ([`scene_path`]); loading them needs the feature `mujoco`.
//!
//! **Gripper pusher** (`scenes/p4_pusher.xml`, p4 Fig. 2 left and Fig. 3): a planar 4-DoF arm
//! (shoulder, elbow, wrist, one sliding finger of a parallel gripper) pushes a block, which
//! slides on the table along x and y, to a goal. State `[q_s, q_e, q_w, q_f, b_x, b_y]` and
//! their velocities (12), action the four motor torques (forces for the finger). The cost
//! (p4: "a weighted combination of the distance from the gripper to the block and from the block
//! to the goal") is, per control step `t` of `T`,
//!
//! ```text
//! c(x, u, t) = w_goal (t+1)²/T² ℓ(‖b − g‖) + w_block ℓ(‖p(q) − b‖) + w_u ‖u‖²,
//! ℓ(d) = ½ l₂ d² + l₁ √(α + d²)
//! ```
//!
//! with `p(q)` the gripper point (forward kinematics, [`pusher_gripper`]), the block–goal term
//! ramped quadratically in time, and `ℓ` the smooth l1-l2 ("Huber-style") penalty usual for
//! LQR-based methods (weights in [`PusherCost::default`]). The four conditions
//! ([`PUSHER_CONDITIONS`]) place the block and the goal; the last one is the hard one of p4's
//! Fig. 3, the block far from both the gripper and the goal.
//!
//! **Door** (`scenes/p4_door.xml`, p4's door opening): a gravity-compensated 6-DoF 3D arm ending
//! in a hook must get the hook behind the handle of a door (a vertical hinge, closed at 0, opening
//! towards the arm up to 1.57 rad; pushing cannot open it) and pull it open. State: the six arm
//! joints, the door angle, and their velocities (14); action: six normalized motor commands in
//! `[−1, 1]` (gears 40, 40, 15, 20, 5, 5 N m). The cost (p4: "a weighted combination of the
//! distance of the end effector to the door handle and the angle of the door") is
//!
//! ```text
//! c(x, u) = w_hand ℓ(‖h(q) − g(q)‖) + w_angle (θ − θ*)² + w_u ‖u‖²
//! ```
//!
//! with `h` the hook's point (site `hand`) and `g` the grasp point behind the handle bar (site
//! `handle`, which moves with the door), both from MuJoCo's kinematics, and `θ* = 1` rad
//! ([`DoorCost::default`]). The four conditions ([`DOOR_CONDITIONS`]) are arm configurations
//! 0.32–0.36 m from the grasp point: above, in front of, left of and right of the handle.
//!
//! **Reacher** (gymnasium's own `reacher.xml`, p4 Fig. 4): a two-link planar arm brings its
//! fingertip to a target. State `[q_0, q_1, g_x, g_y]` and their velocities (8; the target's slide
//! joints never move), action two commands in `[−1, 1]`. p4 replaces gym's distance by a
//! Huber-style penalty: `c(x, u) = w_dist ℓ(‖p(q) − g‖) + w_u ‖u‖²` ([`ReacherCost`]). Starts
//! follow `Reacher-v5`'s reset ([`reacher_starts`]); [`reacher_observation`] is `Reacher-v5`'s
//! observation as a function of the state; [`ReacherTask`] makes it an environment's task.
//!
//! **As environments.** [`PusherTask`] (one condition; the state and the goal observed),
//! `DoorTask` (feature `mujoco`: the door's cost needs MuJoCo's kinematics, `DoorKinematics`;
//! the state and the hook's offset from the grasp point observed) and [`ReacherTask`] are
//! `tandem_envs::Task`s over the scenes' states, each paying `−c(x', u)` a step; with the
//! feature, `pusher_plant` and `door_plant` load the scenes as plants for them.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};

/// The folder of p4's MJCF scenes (`crates/robots/scenes` of the repository this crate was built
/// from).
pub fn scenes_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes"))
}

/// The MJCF file of scene `name` (`"p4_pusher"`, ...).
pub fn scene_path(name: &str) -> PathBuf {
    scenes_dir().join(format!("{name}.xml"))
}

/// The pusher's scene name.
pub const PUSHER_SCENE: &str = "p4_pusher";
/// MuJoCo steps per control step (0.01 s each: control at 20 Hz, as p4's GPS experiments).
pub const PUSHER_FRAME_SKIP: usize = 5;
/// Control steps per episode (5 s).
pub const PUSHER_HORIZON: usize = 100;
/// Length of the state `qpos ++ qvel`.
pub const PUSHER_STATE_DIM: usize = 12;
/// Number of motors.
pub const PUSHER_ACTION_DIM: usize = 4;
/// Link lengths from joint to joint, and from the wrist to the gripper point between the
/// fingers (m), as in the scene.
pub const PUSHER_LINKS: [f64; 3] = [0.5, 0.4, 0.15];

/// One pusher condition: where the block starts and where it must go (m, table frame).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PusherCondition {
    /// The block's start `(x, y)`.
    pub block: [f64; 2],
    /// The goal `(x, y)`.
    pub goal: [f64; 2],
}

/// The four conditions; the arm always starts stretched along +x at rest (gripper point at
/// `(1.05, 0)`). The last is the hard one: the block 1.2 m from the gripper and 0.8 m from the
/// goal, on the far side of the workspace.
pub const PUSHER_CONDITIONS: [PusherCondition; 4] = [
    PusherCondition {
        block: [0.75, 0.35],
        goal: [0.45, 0.7],
    },
    PusherCondition {
        block: [0.8, -0.3],
        goal: [0.85, -0.7],
    },
    PusherCondition {
        block: [0.45, 0.55],
        goal: [0.0, 0.8],
    },
    PusherCondition {
        block: [0.2, -0.85],
        goal: [0.9, -0.45],
    },
];

/// The index of the hard condition in [`PUSHER_CONDITIONS`].
pub const PUSHER_HARD: usize = 3;

impl PusherCondition {
    /// The initial state: arm stretched and open-gripped at zero, the block at its start, all at
    /// rest.
    pub fn initial_state(&self) -> Vec<f64> {
        let mut x = vec![0.0; PUSHER_STATE_DIM];
        x[4] = self.block[0];
        x[5] = self.block[1];
        x
    }

    /// The block–goal distance of a state.
    pub fn block_goal_distance(&self, x: &[f64]) -> f64 {
        (x[4] - self.goal[0]).hypot(x[5] - self.goal[1])
    }
}

/// The gripper point (between the fingers) of arm angles `q = [q_s, q_e, q_w, ..]`: planar
/// forward kinematics of the scene's links.
pub fn pusher_gripper(q: &[f64]) -> [f64; 2] {
    let (mut a, mut p) = (0.0, [0.0, 0.0]);
    for (l, qi) in PUSHER_LINKS.iter().zip(q) {
        a += qi;
        p[0] += l * a.cos();
        p[1] += l * a.sin();
    }
    p
}

/// The gripper point's velocity in the plane for a state `qpos ++ qvel`: the kinematic Jacobian
/// of [`pusher_gripper`] times the arm's joint velocities `x[6..9]`.
pub fn pusher_gripper_velocity(x: &[f64]) -> [f64; 2] {
    let (mut a, mut w) = (0.0, 0.0);
    let mut v = [0.0, 0.0];
    for ((l, qi), wi) in PUSHER_LINKS
        .iter()
        .zip(&x[..3])
        .zip(&x[PUSHER_STATE_DIM / 2..])
    {
        // The angle of link k and its rate: sums of the joints up to k.
        a += qi;
        w += wi;
        v[0] -= l * a.sin() * w;
        v[1] += l * a.cos() * w;
    }
    v
}

/// Number of the pusher's end-effector features ([`pusher_features`]).
pub const PUSHER_FEATURES_DIM: usize = 4;

/// The pusher's end-effector features of a state `qpos ++ qvel` into `out`: the gripper point
/// and its velocity (`[p_x, p_y, ṗ_x, ṗ_y]`, GPS's order: points, then their velocities). The
/// block's position is already in the state.
pub fn pusher_features(x: &[f64], out: &mut [f64]) {
    let (p, v) = (pusher_gripper(x), pusher_gripper_velocity(x));
    out[..PUSHER_FEATURES_DIM].copy_from_slice(&[p[0], p[1], v[0], v[1]]);
}

/// The smooth l1-l2 penalty `½ l₂ d² + l₁ √(α + d²)` of a distance `d`.
pub fn l12(d: f64, l1: f64, l2: f64, alpha: f64) -> f64 {
    0.5 * l2 * d * d + l1 * (alpha + d * d).sqrt()
}

/// `ℓ(‖r‖)` with its gradient and Hessian in `r` (positive definite: `l₂ I + l₁ (s² I − r rᵀ)/s³`
/// with `s² = α + ‖r‖² > ‖r‖²`).
pub fn l12_expansion(r: &[f64], l1: f64, l2: f64, alpha: f64) -> (f64, DVector<f64>, DMatrix<f64>) {
    let r = DVector::from_column_slice(r);
    let s = (alpha + r.norm_squared()).sqrt();
    let v = 0.5 * l2 * r.norm_squared() + l1 * s;
    let k = l2 + l1 / s;
    let hess = DMatrix::identity(r.len(), r.len()) * k - &r * r.transpose() * (l1 / (s * s * s));
    (v, r * k, hess)
}

/// Checks that cost weights are finite and non-negative and the penalty's `α` positive.
fn check_weights(weights: &[(&str, f64)], alpha: f64) -> Result<(), String> {
    for &(name, v) in weights {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("cost weight {name} = {v} must be finite and >= 0"));
        }
    }
    if !(alpha.is_finite() && alpha > 0.0) {
        return Err(format!("cost alpha = {alpha} must be > 0"));
    }
    Ok(())
}

/// The pusher's cost weights (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PusherCost {
    /// Weight of the block–goal term (ramped by `(t+1)²/T²`).
    pub goal: f64,
    /// Weight of the gripper–block term.
    pub block: f64,
    /// Weight of `‖u‖²`.
    pub action: f64,
    /// `l₁` of the penalty.
    pub l1: f64,
    /// `l₂` of the penalty.
    pub l2: f64,
    /// `α` of the penalty.
    pub alpha: f64,
    /// Append the gripper point and its velocity ([`pusher_features`]) to the local
    /// controllers' state, as the authors' `state_include` of `END_EFFECTOR_POINTS` and
    /// `END_EFFECTOR_POINT_VELOCITIES` (`experiments/mjc_gripper_pusher_pilqr/hyperparams.py`):
    /// the TVLG dynamics fit and the controllers' gains then see the kinematics' own coordinates.
    /// Off by default. The cost reads the scene's state part; [`PusherTask`] ignores it.
    #[serde(default, skip_serializing_if = "is_false")]
    pub end_effector_features: bool,
}

/// Whether a flag is off (configurations leave such keys out).
fn is_false(b: &bool) -> bool {
    !*b
}

impl Default for PusherCost {
    /// Block–goal 4, gripper–block 1 (GPS's weighting of the two distance terms),
    /// `ℓ = 5 d² + 0.1 √(10⁻⁵ + d²)`, torques `10⁻³ ‖u‖²`.
    fn default() -> Self {
        Self {
            goal: 4.0,
            block: 1.0,
            action: 1e-3,
            l1: 0.1,
            l2: 10.0,
            alpha: 1e-5,
            end_effector_features: false,
        }
    }
}

impl PusherCost {
    /// `c(x, u, t)` for `cond` over a horizon of `horizon` steps.
    pub fn running(
        &self,
        cond: &PusherCondition,
        horizon: usize,
        x: &[f64],
        u: &[f64],
        t: usize,
    ) -> f64 {
        let ramp = ((t + 1) as f64 / horizon as f64).powi(2);
        let g = pusher_gripper(x);
        let gripper_block = (g[0] - x[4]).hypot(g[1] - x[5]);
        let pen = |d| l12(d, self.l1, self.l2, self.alpha);
        self.goal * ramp * pen(cond.block_goal_distance(x))
            + self.block * pen(gripper_block)
            + self.action * u.iter().map(|v| v * v).sum::<f64>()
    }

    /// The state part of `c(x, u, t)` (everything but `w_u ‖u‖²`) with its gradient and its
    /// Gauss–Newton Hessian in `x`: each term `ℓ(‖r(x)‖)` contributes `Jᵀ ∇ℓ` and `Jᵀ ∇²ℓ J`
    /// (`J = ∂r/∂x`; `∇²ℓ` is positive definite), the curvature of the kinematics left out as in
    /// GPS's forward-kinematics costs, so that LQR-FLM's backward pass sees a convex cost.
    pub fn state_expansion(
        &self,
        cond: &PusherCondition,
        horizon: usize,
        x: &[f64],
        t: usize,
    ) -> (f64, DVector<f64>, DMatrix<f64>) {
        let n = PUSHER_STATE_DIM;
        let ramp = ((t + 1) as f64 / horizon as f64).powi(2);
        let (mut c, mut g, mut h) = (0.0, DVector::zeros(n), DMatrix::zeros(n, n));
        // Block–goal: r = b − goal, J selects the block's coordinates.
        let mut j_goal = DMatrix::zeros(2, n);
        j_goal[(0, 4)] = 1.0;
        j_goal[(1, 5)] = 1.0;
        let r_goal = [x[4] - cond.goal[0], x[5] - cond.goal[1]];
        // Gripper–block: r = p(q) − b, J = [∂p/∂q, 0, −I, 0].
        let p = pusher_gripper(x);
        let r_block = [p[0] - x[4], p[1] - x[5]];
        let mut j_block = DMatrix::zeros(2, n);
        let mut angle = [0.0; 3];
        let mut a = 0.0;
        for (k, qi) in x[..3].iter().enumerate() {
            a += qi;
            angle[k] = a;
        }
        for k in 0..3 {
            // ∂p/∂q_k sums the links from k outwards.
            for (l, ang) in PUSHER_LINKS.iter().zip(&angle).skip(k) {
                j_block[(0, k)] -= l * ang.sin();
                j_block[(1, k)] += l * ang.cos();
            }
        }
        j_block[(0, 4)] = -1.0;
        j_block[(1, 5)] = -1.0;
        for (w, r, j) in [
            (self.goal * ramp, r_goal, j_goal),
            (self.block, r_block, j_block),
        ] {
            let (v, dr, ddr) = l12_expansion(&r, self.l1, self.l2, self.alpha);
            c += w * v;
            g += w * j.transpose() * dr;
            h += w * j.transpose() * ddr * &j;
        }
        (c, g, h)
    }

    /// The terminal cost: the last step's distance terms (the ramp is 1 there), no action.
    pub fn terminal(&self, cond: &PusherCondition, x: &[f64]) -> f64 {
        self.running(cond, 1, x, &[], 0)
    }

    /// Checks that the weights are finite and non-negative and `α > 0`.
    pub fn validate(&self) -> Result<(), String> {
        check_weights(
            &[
                ("goal", self.goal),
                ("block", self.block),
                ("action", self.action),
                ("l1", self.l1),
                ("l2", self.l2),
            ],
            self.alpha,
        )
    }
}

/// The pusher's motor limits (N m; N for the finger): the scene's `ctrlrange`.
pub const PUSHER_CTRL_LIMITS: [f64; PUSHER_ACTION_DIM] = [10.0, 6.0, 3.0, 10.0];
/// Length of [`PusherTask`]'s observation: the state and the goal.
pub const PUSHER_OBS_DIM: usize = PUSHER_STATE_DIM + 2;

/// One pusher condition as an environment's [`tandem_envs::Task`] over the scene's state (with
/// its frame skip, e.g. `PlantEnv::from_parts(pusher_plant()?, PusherTask::new(..)?)`): episodes
/// start from the condition's initial state, the agent observes the state and the goal (so that
/// one policy can serve several conditions, as MDGPS's global policy over the state and the
/// target), commands are clipped to the motors' limits, and the reward of a step is minus the
/// cost of the state it reaches and the command, 100 steps, no termination.
///
/// A step's reward cannot see the step's index, so the block–goal term counts at full weight at
/// every step: `−c(x', u, T−1)`, the cost of the episode's last step, whose ramp `(t+1)²/T²` is 1.
/// The ramp is a shaping of the local controllers' trajectory optimization, which plans whole
/// episodes; for a policy acting step by step, being near the goal early is no worse.
///
/// ```
/// use tandem_envs::Task;
/// use tandem_robots::p4::{PusherCost, PusherTask, PUSHER_CONDITIONS, PUSHER_HARD};
///
/// let task = PusherTask::new(PusherCost::default(), PUSHER_CONDITIONS[PUSHER_HARD]).unwrap();
/// let x0 = task.initial_state(&mut tandem_core::seeding::rng_from_seed(0));
/// assert_eq!(task.observe(&x0)[12..], PUSHER_CONDITIONS[PUSHER_HARD].goal); // after the state
/// // Resting at the start pays for the block 0.81 m from the goal, 1.2 m from the gripper.
/// assert!(task.reward(&x0, &[0.0; 4], &x0) < -10.0);
/// // With the feature `mujoco`, an environment: `TimeLimit::new(PlantEnv::from_parts(
/// // pusher_plant()?, task)?, PUSHER_HORIZON)`.
/// ```
#[derive(Debug, Clone)]
pub struct PusherTask {
    cost: PusherCost,
    condition: PusherCondition,
    observation_space: tandem_core::Space,
    action_space: tandem_core::Space,
}

impl PusherTask {
    /// The task of `condition` with `cost`; an error for invalid weights or a non-finite
    /// condition.
    pub fn new(cost: PusherCost, condition: PusherCondition) -> Result<Self, String> {
        cost.validate()?;
        if !condition
            .block
            .iter()
            .chain(&condition.goal)
            .all(|v| v.is_finite())
        {
            return Err(format!("pusher condition {condition:?} must be finite"));
        }
        let limits = PUSHER_CTRL_LIMITS.to_vec();
        Ok(Self {
            cost,
            condition,
            observation_space: tandem_core::Space::unbounded(PUSHER_OBS_DIM),
            action_space: tandem_core::Space::boxed(limits.iter().map(|l| -l).collect(), limits),
        })
    }

    /// The cost.
    pub fn cost(&self) -> &PusherCost {
        &self.cost
    }

    /// The condition.
    pub fn condition(&self) -> &PusherCondition {
        &self.condition
    }
}

impl tandem_envs::Task for PusherTask {
    fn id(&self) -> &str {
        "p4-Pusher"
    }
    fn observation_space(&self) -> &tandem_core::Space {
        &self.observation_space
    }
    fn action_space(&self) -> &tandem_core::Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        PUSHER_STATE_DIM
    }
    fn control(&self, action: &tandem_core::Action) -> Vec<f64> {
        match action {
            tandem_core::Action::Continuous(a) => tandem_envs::clip_to(&self.action_space, a),
            tandem_core::Action::Discrete(_) => vec![0.0; PUSHER_ACTION_DIM],
        }
    }
    fn initial_state(&self, _rng: &mut tandem_core::Rng) -> Vec<f64> {
        self.condition.initial_state()
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        let mut o = state.to_vec();
        o.extend_from_slice(&self.condition.goal);
        o
    }
    fn reward(&self, _state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        -self
            .cost
            .running(&self.condition, PUSHER_HORIZON, next, u, PUSHER_HORIZON - 1)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(PUSHER_HORIZON)
    }
}

/// The door's scene name.
pub const DOOR_SCENE: &str = "p4_door";
/// MuJoCo steps per control step (0.01 s each).
pub const DOOR_FRAME_SKIP: usize = 5;
/// Control steps per episode (5 s).
pub const DOOR_HORIZON: usize = 100;
/// Length of the state `qpos ++ qvel`.
pub const DOOR_STATE_DIM: usize = 14;
/// Number of motors.
pub const DOOR_ACTION_DIM: usize = 6;
/// The door angle's index in the state.
pub const DOOR_ANGLE: usize = 6;
/// The angle the door should be pulled to (rad).
pub const DOOR_TARGET: f64 = 1.0;

/// The door's four conditions: the six arm joints' start (door closed, all at rest), with the
/// hook level and its finger down, 0.32–0.36 m from the grasp point (offsets from it in m).
pub const DOOR_CONDITIONS: [(&str, [f64; 6]); 4] = [
    (
        "above (-0.1, 0, 0.3)",
        [0.5098, 0.3024, -0.0197, -1.3288, 0.0362, 1.0257],
    ),
    (
        "front (-0.3, 0, 0.2)",
        [0.6823, 0.6805, -0.0255, -1.9626, 0.0686, 1.2809],
    ),
    (
        "left (-0.1, 0.25, 0.2)",
        [0.7640, 0.1799, -0.0519, -0.6595, 0.0575, 0.4785],
    ),
    (
        "right (-0.1, -0.25, 0.2)",
        [0.2036, 0.6102, 0.0403, -1.7234, -0.0742, 1.1114],
    ),
];

/// The initial state of door condition `c`.
pub fn door_initial_state(c: usize) -> Vec<f64> {
    let mut x = vec![0.0; DOOR_STATE_DIM];
    x[..6].copy_from_slice(&DOOR_CONDITIONS[c].1);
    x
}

/// A door start counts as opened when its final door angle is at least this (rad): 80% of
/// [`DOOR_TARGET`].
pub const DOOR_OPENED: f64 = 0.8 * DOOR_TARGET;

/// `n` random door starts for testing a policy that was trained on [`DOOR_CONDITIONS`] (p4
/// Fig. 5's random test conditions): the six arm joints a random convex combination of the four
/// conditions' configurations, the weights uniform on the simplex (normalized exponential draws),
/// the door closed and everything at rest. The combinations stay within the joints' ranges (a
/// box that holds the four) and put the hook between the four starts' positions: across and
/// above the handle within the span of theirs (0.2–0.3 m above the grasp point), in front of it
/// (0.04–0.28 m, where the starts are 0.1–0.3 m: the hull of the configurations reaches closer
/// to the door than the starts do). `tandem-algos`' tests check this with MuJoCo's kinematics,
/// and that the arm rests there without touching the door. The four training starts are the
/// simplex's corners, which a draw reaches with probability zero.
pub fn door_test_starts(n: usize, rng: &mut tandem_core::Rng) -> Vec<Vec<f64>> {
    use rand::Rng as _;
    (0..n)
        .map(|_| {
            // −ln(1 − U) is Exp(1); normalized, four of them are uniform on the simplex.
            let e: [f64; 4] = std::array::from_fn(|_| -(1.0 - rng.random::<f64>()).ln());
            let total: f64 = e.iter().sum();
            let mut x = vec![0.0; DOOR_STATE_DIM];
            for (w, (_, q)) in e.iter().zip(&DOOR_CONDITIONS) {
                for (xj, qj) in x.iter_mut().zip(q) {
                    *xj += w / total * qj;
                }
            }
            x
        })
        .collect()
}

/// The door's cost weights (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DoorCost {
    /// Weight of the hand–handle term.
    pub hand: f64,
    /// Weight of `(θ − θ*)²`.
    pub angle: f64,
    /// The target angle `θ*` (rad).
    pub target: f64,
    /// Weight of `‖u‖²`.
    pub action: f64,
    /// `l₁` of the penalty.
    pub l1: f64,
    /// `l₂` of the penalty.
    pub l2: f64,
    /// `α` of the penalty.
    pub alpha: f64,
    /// Ramp the angle term by `((t+1)/T)²` over the horizon, as GPS's `RAMP_QUADRATIC`
    /// (`python/gps/algorithm/cost/cost_utils.py`, `get_ramp_multiplier`) on the authors' door
    /// angle cost (`experiments/mjc_door_opening_pilqr/hyperparams.py`): the door need not move
    /// early, while the hook is still on its way. Off by default (the weight is constant).
    #[serde(default, skip_serializing_if = "is_false")]
    pub angle_ramp: bool,
    /// The authors' waypoints for the hook ([`DoorWaypoints`]); off by default (weight 0).
    #[serde(default, skip_serializing_if = "DoorWaypoints::is_off")]
    pub waypoints: DoorWaypoints,
    /// Append the hook point, the grasp point and their velocities (`DoorKinematics::features`)
    /// to the local controllers' state, as the authors' `state_include` of
    /// `END_EFFECTOR_POINTS` and `END_EFFECTOR_POINT_VELOCITIES`. Off by default. The cost reads
    /// the scene's state part; `DoorTask` ignores it.
    #[serde(default, skip_serializing_if = "is_false")]
    pub end_effector_features: bool,
}

/// The waypoint terms of the authors' door cost (`CostLinWP` in
/// `python/gps/algorithm/cost/cost_lin_wp.py`, set up in
/// `experiments/mjc_door_opening_pilqr/hyperparams.py`), mapped onto our scene.
///
/// Theirs: the hook is a segment between two sites (`link_top`, and `link_bottom` 0.15 m below
/// it), the door has `handle` and `above_handle` 0.15 m above it. `CostLinWP` applies waypoint
/// `i` on the steps from the previous waypoint's step to `⌈waypoint_time_i · T⌉` (exclusive), each
/// with the penalty `ℓ(‖A_i [x; u]‖)`. With `waypoint_time = [0.25, 1.0]`: on the first quarter
/// of the horizon `A_0` picks `link_bottom − above_handle` (the hook's lower end above the
/// handle), on the rest `A_1` picks `link_top − above_handle` and `link_bottom − handle` (the
/// hook hanging into the handle), with `ℓ(d) = ½ d² + 0.1 √(10⁻⁵ + d²)` and weight 1.
///
/// Ours has one hook point `h` (site `hand`, on the finger) and the grasp point `g` behind the
/// bar (site `handle`), whose offset `h − g` the hand term already pays. So the first waypoint is
/// `h − (g + above · ẑ)` (the hook `above` metres over the grasp point; the hinge is vertical, so
/// "over" stays world `z` as the door turns) on the steps `t < ⌈switch · T⌉`, and the second is
/// `h − g` on the others and at the end: the finger's orientation, which their second point pins,
/// is the scene's own (it hangs from the palm). Both paid as `weight · ℓ(‖·‖)` with this
/// struct's `l1`, `l2`, `alpha`. The authors' door has no separate hand term: set the cost's
/// `hand` to 0 to follow it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DoorWaypoints {
    /// Weight of the waypoint terms; 0 turns them off (the default). The authors': 1.
    pub weight: f64,
    /// The fraction of the horizon the first waypoint holds for (their `waypoint_time[0]`,
    /// 0.25).
    pub switch: f64,
    /// Height of the first waypoint over the grasp point (m; their `above_handle` sits 0.15 m
    /// over `handle`).
    pub above: f64,
    /// `l₁` of the waypoints' penalty (theirs 0.1).
    pub l1: f64,
    /// `l₂` of the waypoints' penalty (theirs 1).
    pub l2: f64,
    /// `α` of the waypoints' penalty (theirs 10⁻⁵).
    pub alpha: f64,
}

impl Default for DoorWaypoints {
    /// Off (weight 0), with the authors' other settings.
    fn default() -> Self {
        Self {
            weight: 0.0,
            switch: 0.25,
            above: 0.15,
            l1: 0.1,
            l2: 1.0,
            alpha: 1e-5,
        }
    }
}

impl DoorWaypoints {
    /// The authors' waypoints: weight 1 and the defaults.
    pub fn authors() -> Self {
        Self {
            weight: 1.0,
            ..Self::default()
        }
    }

    /// Whether the terms are off (weight 0).
    pub fn is_off(&self) -> bool {
        self.weight == 0.0
    }

    /// The waypoint of step `t` of `horizon` as an offset from the grasp point: `above · ẑ`
    /// before `⌈switch · horizon⌉`, the grasp point itself from there on (and at `t ≥ horizon`,
    /// the terminal state).
    pub fn target(&self, t: usize, horizon: usize) -> [f64; 3] {
        if (t as f64) < (self.switch * horizon as f64).ceil() {
            [0.0, 0.0, self.above]
        } else {
            [0.0; 3]
        }
    }

    /// Checks finite, non-negative weights, `α > 0` and `switch` in `[0, 1]`.
    pub fn validate(&self) -> Result<(), String> {
        check_weights(
            &[
                ("waypoints.weight", self.weight),
                ("waypoints.l1", self.l1),
                ("waypoints.l2", self.l2),
            ],
            self.alpha,
        )
        .map_err(|e| format!("{e} (waypoints)"))?;
        if !(0.0..=1.0).contains(&self.switch) {
            return Err(format!(
                "waypoints.switch = {} must be in [0, 1]",
                self.switch
            ));
        }
        if !self.above.is_finite() {
            return Err(format!("waypoints.above = {} must be finite", self.above));
        }
        Ok(())
    }
}

impl Default for DoorCost {
    /// Hand–handle 10, door angle 1 towards 1 rad, `ℓ = ½ d² + 0.1 √(10⁻⁵ + d²)`, `10⁻³ ‖u‖²`
    /// (with these, the scene's scripted hook-and-pull costs 35–44 per episode against 182–201
    /// for staying put).
    fn default() -> Self {
        Self {
            hand: 10.0,
            angle: 1.0,
            target: DOOR_TARGET,
            action: 1e-3,
            l1: 0.1,
            l2: 1.0,
            alpha: 1e-5,
            angle_ramp: false,
            waypoints: DoorWaypoints::default(),
            end_effector_features: false,
        }
    }
}

impl DoorCost {
    /// The angle term's multiplier at step `t` of `horizon`: `((t+1)/T)²` with `angle_ramp`
    /// (GPS's `RAMP_QUADRATIC`; 1 at the last step `T − 1` and at the terminal state), else 1.
    pub fn angle_ramp_at(&self, t: usize, horizon: usize) -> f64 {
        if self.angle_ramp {
            (((t + 1).min(horizon)) as f64 / horizon as f64).powi(2)
        } else {
            1.0
        }
    }

    /// `c` at step `t` of `horizon` (`t = horizon` for the terminal state, with an empty `u`):
    /// [`DoorCost::running`] with the angle term ramped ([`DoorCost::angle_ramp_at`]) and the
    /// waypoint term ([`DoorWaypoints`]) added when they are on; [`DoorCost::running`] itself
    /// when they are off.
    pub fn running_at(&self, r: &[f64; 3], angle: f64, u: &[f64], t: usize, horizon: usize) -> f64 {
        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        let c = self.hand * l12(d, self.l1, self.l2, self.alpha)
            + self.angle * self.angle_ramp_at(t, horizon) * (angle - self.target).powi(2)
            + self.action * u.iter().map(|v| v * v).sum::<f64>();
        if self.waypoints.is_off() {
            return c;
        }
        let w = &self.waypoints;
        let a = w.target(t, horizon);
        let e = [r[0] - a[0], r[1] - a[1], r[2] - a[2]];
        let d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
        c + w.weight * l12(d, w.l1, w.l2, w.alpha)
    }

    /// The offset terms at step `t` of `horizon` (the hand term and, when on, the waypoint
    /// term) with their gradient and (positive definite) Hessian in the offset `r`:
    /// [`DoorCost::hand_expansion`] itself when the waypoints are off.
    pub fn offset_expansion(
        &self,
        r: &[f64; 3],
        t: usize,
        horizon: usize,
    ) -> (f64, [f64; 3], [[f64; 3]; 3]) {
        let (mut v, mut g, mut h) = self.hand_expansion(r);
        if self.waypoints.is_off() {
            return (v, g, h);
        }
        let w = &self.waypoints;
        let a = w.target(t, horizon);
        let e = [r[0] - a[0], r[1] - a[1], r[2] - a[2]];
        let (wv, wg, wh) = l12_expansion(&e, w.l1, w.l2, w.alpha);
        v += w.weight * wv;
        for i in 0..3 {
            g[i] += w.weight * wg[i];
            for j in 0..3 {
                h[i][j] += w.weight * wh[(i, j)];
            }
        }
        (v, g, h)
    }

    /// `c` given the hand–handle offset `r = h − g`, the door angle and the action.
    pub fn running(&self, r: &[f64; 3], angle: f64, u: &[f64]) -> f64 {
        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        self.hand * l12(d, self.l1, self.l2, self.alpha)
            + self.angle * (angle - self.target).powi(2)
            + self.action * u.iter().map(|v| v * v).sum::<f64>()
    }

    /// The hand term `w_hand ℓ(‖r‖)` with its gradient and (positive definite) Hessian in `r`:
    /// [`l12_expansion`] scaled by `w_hand`, written out with the weight inside so that its
    /// rounding, and with it the door runs in `results/p4-door`, stay as they were measured.
    pub fn hand_expansion(&self, r: &[f64; 3]) -> (f64, [f64; 3], [[f64; 3]; 3]) {
        let n2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        let s = (self.alpha + n2).sqrt();
        let v = self.hand * (0.5 * self.l2 * n2 + self.l1 * s);
        let k = self.hand * (self.l2 + self.l1 / s);
        let grad = [k * r[0], k * r[1], k * r[2]];
        let mut hess = [[0.0; 3]; 3];
        for (i, row) in hess.iter_mut().enumerate() {
            for (j, h) in row.iter_mut().enumerate() {
                *h =
                    -self.hand * self.l1 * r[i] * r[j] / (s * s * s) + if i == j { k } else { 0.0 };
            }
        }
        (v, grad, hess)
    }

    /// Checks that the weights are finite and non-negative, `α > 0` and the target finite.
    pub fn validate(&self) -> Result<(), String> {
        check_weights(
            &[
                ("hand", self.hand),
                ("angle", self.angle),
                ("action", self.action),
                ("l1", self.l1),
                ("l2", self.l2),
            ],
            self.alpha,
        )?;
        if !self.target.is_finite() {
            return Err(format!("target angle {} must be finite", self.target));
        }
        self.waypoints.validate()
    }
}

/// Number of the door's end-effector features (`DoorKinematics::features`): the hook and grasp
/// points and their velocities.
pub const DOOR_FEATURES_DIM: usize = 12;

/// Length of `DoorTask`'s observation: the state and the hook's offset from the grasp point.
pub const DOOR_OBS_DIM: usize = DOOR_STATE_DIM + 3;

#[cfg(feature = "mujoco")]
pub use door_scene::{door_plant, pusher_plant, DoorKinematics, DoorTask};

#[cfg(feature = "mujoco")]
mod door_scene {
    use super::*;
    use tandem_mujoco::{MujocoError, MujocoPlant, Scene};

    /// The pusher's scene as a plant (state `qpos ++ qvel`, 0.05 s a control step).
    pub fn pusher_plant() -> Result<MujocoPlant, MujocoError> {
        MujocoPlant::from_xml(scene_path(PUSHER_SCENE), PUSHER_FRAME_SKIP)
    }

    /// The door's scene as a plant (state `qpos ++ qvel`, 0.05 s a control step).
    pub fn door_plant() -> Result<MujocoPlant, MujocoError> {
        MujocoPlant::from_xml(scene_path(DOOR_SCENE), DOOR_FRAME_SKIP)
    }

    /// The door scene's kinematics that its cost reads: the hook's point (site `hand`) minus
    /// the grasp point behind the handle (site `handle`), from MuJoCo's forward kinematics.
    #[derive(Clone)]
    pub struct DoorKinematics {
        scene: Scene,
        ids: [usize; 2],
    }

    impl DoorKinematics {
        /// The kinematics of a loaded door scene; an error if it lacks the two sites.
        pub fn new(scene: Scene) -> Result<Self, MujocoError> {
            let ids = [scene.site_id("hand")?, scene.site_id("handle")?];
            Ok(Self { scene, ids })
        }

        /// The kinematics of the repository's door scene.
        pub fn load() -> Result<Self, MujocoError> {
            Self::new(Scene::from_xml(scene_path(DOOR_SCENE))?)
        }

        /// The scene.
        pub fn scene(&self) -> &Scene {
            &self.scene
        }

        /// Hook point minus grasp point of a state (or of its joint positions: the first 7
        /// entries are read). Errors: fewer than 7 entries, or a non-finite one among them.
        pub fn offset(&self, x: &[f64]) -> Result<[f64; 3], MujocoError> {
            let [h, g] = self.points(x)?;
            Ok([h[0] - g[0], h[1] - g[1], h[2] - g[2]])
        }

        /// The hook point (site `hand`) and the grasp point (site `handle`) of a state (or of its
        /// joint positions: the first 7 entries are read), world frame. Errors as
        /// [`DoorKinematics::offset`].
        pub fn points(&self, x: &[f64]) -> Result<[[f64; 3]; 2], MujocoError> {
            let nq = DOOR_ANGLE + 1;
            if x.len() < nq {
                return Err(MujocoError::Model {
                    path: self.scene.path().to_path_buf(),
                    message: format!(
                        "the door's kinematics need {nq} joint positions, got {}",
                        x.len()
                    ),
                });
            }
            let p = self.scene.site_positions(&x[..nq], &self.ids)?;
            Ok([p[0], p[1]])
        }

        /// The door's end-effector features of a whole state `qpos ++ qvel` into `out`
        /// ([`DOOR_FEATURES_DIM`]): the hook point, the grasp point, then their velocities (GPS's
        /// order: points, then their velocities). A velocity is the points' Jacobian times
        /// `qvel`, taken as one central difference of the kinematics along `qvel` (step
        /// `10⁻⁶ / max(1, |qvel|∞)`). Errors: a state shorter than 14 or not finite.
        pub fn features(&self, x: &[f64], out: &mut [f64]) -> Result<(), MujocoError> {
            let nq = DOOR_ANGLE + 1;
            if x.len() < DOOR_STATE_DIM {
                return Err(MujocoError::Model {
                    path: self.scene.path().to_path_buf(),
                    message: format!(
                        "the door's features need a state of {DOOR_STATE_DIM}, got {}",
                        x.len()
                    ),
                });
            }
            let (q, v) = (&x[..nq], &x[nq..DOOR_STATE_DIM]);
            let at = self.points(q)?;
            let h = 1e-6 / v.iter().fold(1.0f64, |m, vi| m.max(vi.abs()));
            let moved =
                |s: f64| -> Vec<f64> { q.iter().zip(v).map(|(a, b)| a + s * h * b).collect() };
            let (fwd, back) = (self.points(&moved(1.0))?, self.points(&moved(-1.0))?);
            for k in 0..2 {
                for i in 0..3 {
                    out[3 * k + i] = at[k][i];
                    out[6 + 3 * k + i] = (fwd[k][i] - back[k][i]) / (2.0 * h);
                }
            }
            Ok(())
        }

        /// [`DoorKinematics::offset`] for a cost: NaN where the state is not finite, so that the
        /// cost is NaN too and its caller (an environment's state check, an objective's) reports
        /// it with its step. Callers pass whole states.
        pub fn offset_or_nan(&self, x: &[f64]) -> [f64; 3] {
            self.offset(x).unwrap_or([f64::NAN; 3])
        }
    }

    /// The door as an environment's [`tandem_envs::Task`] over the scene's state (with its frame
    /// skip, e.g. `PlantEnv::from_parts(door_plant()?, DoorTask::new(..)?)`): episodes start
    /// from one of [`DOOR_CONDITIONS`] (a given one, or one drawn uniformly), the agent observes
    /// the state and the hook's offset from the grasp point ([`DoorKinematics::offset`], what
    /// the cost reads), commands are clipped to `[−1, 1]`, and the reward of a step is minus the
    /// cost of the state it reaches and the command, `−c(x', u)`, 100 steps, no termination.
    #[derive(Clone)]
    pub struct DoorTask {
        cost: DoorCost,
        kinematics: DoorKinematics,
        start: Option<usize>,
        observation_space: tandem_core::Space,
        action_space: tandem_core::Space,
    }

    impl DoorTask {
        /// The door with `cost`, starting from condition `start` (`None`: one of the four drawn
        /// uniformly at every reset); an error for invalid weights or a condition out of range.
        pub fn new(
            cost: DoorCost,
            kinematics: DoorKinematics,
            start: Option<usize>,
        ) -> Result<Self, String> {
            cost.validate()?;
            if let Some(c) = start.filter(|&c| c >= DOOR_CONDITIONS.len()) {
                return Err(format!(
                    "door condition {c} out of range (there are {})",
                    DOOR_CONDITIONS.len()
                ));
            }
            Ok(Self {
                cost,
                kinematics,
                start,
                observation_space: tandem_core::Space::unbounded(DOOR_OBS_DIM),
                action_space: tandem_core::Space::symmetric(DOOR_ACTION_DIM, 1.0),
            })
        }

        /// The cost.
        pub fn cost(&self) -> &DoorCost {
            &self.cost
        }

        /// The kinematics.
        pub fn kinematics(&self) -> &DoorKinematics {
            &self.kinematics
        }
    }

    impl tandem_envs::Task for DoorTask {
        fn id(&self) -> &str {
            "p4-Door"
        }
        fn observation_space(&self) -> &tandem_core::Space {
            &self.observation_space
        }
        fn action_space(&self) -> &tandem_core::Space {
            &self.action_space
        }
        fn state_dim(&self) -> usize {
            DOOR_STATE_DIM
        }
        fn control(&self, action: &tandem_core::Action) -> Vec<f64> {
            match action {
                tandem_core::Action::Continuous(a) => tandem_envs::clip_to(&self.action_space, a),
                tandem_core::Action::Discrete(_) => vec![0.0; DOOR_ACTION_DIM],
            }
        }
        fn initial_state(&self, rng: &mut tandem_core::Rng) -> Vec<f64> {
            use rand::Rng as _;
            door_initial_state(
                self.start
                    .unwrap_or_else(|| rng.random_range(0..DOOR_CONDITIONS.len())),
            )
        }
        fn observe(&self, state: &[f64]) -> Vec<f64> {
            let mut o = state.to_vec();
            o.extend_from_slice(&self.kinematics.offset_or_nan(state));
            o
        }
        /// A step's reward cannot see the step's index: the cost of the episode's last step
        /// (the angle ramp, if on, is 1 there; the waypoint, if on, is the grasp point).
        fn reward(&self, _state: &[f64], u: &[f64], next: &[f64]) -> f64 {
            -self.cost.running_at(
                &self.kinematics.offset_or_nan(next),
                next[DOOR_ANGLE],
                u,
                DOOR_HORIZON - 1,
                DOOR_HORIZON,
            )
        }
        fn max_episode_steps(&self) -> Option<usize> {
            Some(DOOR_HORIZON)
        }
    }
}

/// Control steps per episode of gymnasium's `Reacher-v5` (1 s at 50 Hz: frame skip 2 of 0.01 s).
pub const REACHER_HORIZON: usize = 50;
/// Length of the reacher's state `qpos ++ qvel`: the two arm joints, the target's x and y (slide
/// joints that never move), and their velocities.
pub const REACHER_STATE_DIM: usize = 8;
/// Number of motors.
pub const REACHER_ACTION_DIM: usize = 2;
/// Link lengths of `reacher.xml`: shoulder to elbow, elbow to fingertip (m).
pub const REACHER_LINKS: [f64; 2] = [0.1, 0.11];
/// `qpos0` of `reacher.xml`: arm straight, target at its slide joints' reference `(0.1, −0.1)`.
pub const REACHER_QPOS0: [f64; 4] = [0.0, 0.0, 0.1, -0.1];

/// The reacher's fingertip in the plane of arm angles `q = [q_0, q_1, ..]`.
pub fn reacher_fingertip(q: &[f64]) -> [f64; 2] {
    let (a0, a1) = (q[0], q[0] + q[1]);
    let [l0, l1] = REACHER_LINKS;
    [l0 * a0.cos() + l1 * a1.cos(), l0 * a0.sin() + l1 * a1.sin()]
}

/// Fingertip–target distance of a reacher state (the target's position is `qpos[2..4]`).
pub fn reacher_distance(x: &[f64]) -> f64 {
    let p = reacher_fingertip(x);
    (p[0] - x[2]).hypot(p[1] - x[3])
}

/// Length of `Reacher-v5`'s observation.
pub const REACHER_OBS_DIM: usize = 10;

/// `Reacher-v5`'s observation of a state: `cos q`, `sin q` (both joints), the target's position,
/// the joint velocities, and the fingertip minus the target (x, y).
pub fn reacher_observation(x: &[f64], out: &mut [f64]) {
    let p = reacher_fingertip(x);
    out[..REACHER_OBS_DIM].copy_from_slice(&[
        x[0].cos(),
        x[1].cos(),
        x[0].sin(),
        x[1].sin(),
        x[2],
        x[3],
        x[4],
        x[5],
        p[0] - x[2],
        p[1] - x[3],
    ]);
}

/// `n` reacher starts from gymnasium's `Reacher-v5` reset distribution: arm angles
/// `U(−0.1, 0.1)`, target uniform in the disc of radius 0.2, arm velocities `U(−0.005, 0.005)`.
pub fn reacher_starts(n: usize, rng: &mut tandem_core::Rng) -> Vec<Vec<f64>> {
    (0..n)
        .map(|_| {
            let (mut q, v) =
                tandem_mujoco::TaskKind::Reacher.reset_state(&REACHER_QPOS0, &[0.0; 4], rng);
            q.extend(v);
            q
        })
        .collect()
}

/// p4's reacher cost: gymnasium's fingertip–target distance through the smooth l1-l2
/// ("Huber-style") penalty, plus the torques:
///
/// ```text
/// c(x, u) = w_dist ℓ(‖p(q) − g‖) + w_u ‖u‖²,   terminal  w_dist ℓ(‖p(q) − g‖)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReacherCost {
    /// Weight of the distance term.
    pub distance: f64,
    /// Weight of `‖u‖²` (`u` the normalized motor commands in `[−1, 1]`).
    pub action: f64,
    /// `l₁` of the penalty.
    pub l1: f64,
    /// `l₂` of the penalty.
    pub l2: f64,
    /// `α` of the penalty.
    pub alpha: f64,
}

impl Default for ReacherCost {
    /// Distance 1 with the pusher's penalty `ℓ = 5 d² + 0.1 √(10⁻⁵ + d²)`, commands
    /// `0.1 ‖u‖²` (the arm turns 0.1 rad in 0.1 s under a command of 0.1, so useful commands are
    /// a few tenths; with `10⁻²` LQR-FLM's first updates asked for saturated ones).
    fn default() -> Self {
        Self {
            distance: 1.0,
            action: 1e-1,
            l1: 0.1,
            l2: 10.0,
            alpha: 1e-5,
        }
    }
}

impl ReacherCost {
    /// `c(x, u)`; with an empty `u`, the terminal cost.
    pub fn running(&self, x: &[f64], u: &[f64]) -> f64 {
        self.distance * l12(reacher_distance(x), self.l1, self.l2, self.alpha)
            + self.action * u.iter().map(|v| v * v).sum::<f64>()
    }

    /// The distance term with its gradient and Gauss–Newton Hessian in `x` (as
    /// [`PusherCost::state_expansion`]: `Jᵀ ∇ℓ`, `Jᵀ ∇²ℓ J`, `J = ∂(p − g)/∂x`).
    pub fn state_expansion(&self, x: &[f64]) -> (f64, DVector<f64>, DMatrix<f64>) {
        let p = reacher_fingertip(x);
        let r = [p[0] - x[2], p[1] - x[3]];
        let (a0, a1) = (x[0], x[0] + x[1]);
        let [l0, l1] = REACHER_LINKS;
        let mut j = DMatrix::zeros(2, REACHER_STATE_DIM);
        j[(0, 0)] = -l0 * a0.sin() - l1 * a1.sin();
        j[(1, 0)] = l0 * a0.cos() + l1 * a1.cos();
        j[(0, 1)] = -l1 * a1.sin();
        j[(1, 1)] = l1 * a1.cos();
        j[(0, 2)] = -1.0;
        j[(1, 3)] = -1.0;
        let (v, g, h) = l12_expansion(&r, self.l1, self.l2, self.alpha);
        let w = self.distance;
        (w * v, j.transpose() * g * w, j.transpose() * h * &j * w)
    }

    /// Checks that the weights are finite and non-negative and `α > 0`.
    pub fn validate(&self) -> Result<(), String> {
        check_weights(
            &[
                ("distance", self.distance),
                ("action", self.action),
                ("l1", self.l1),
                ("l2", self.l2),
            ],
            self.alpha,
        )
    }
}

/// p4's reacher as an environment's [`tandem_envs::Task`] over `reacher.xml`'s state (with
/// frame skip 2, e.g. `PlantEnv::from_parts(MujocoPlant, ReacherTask)`): episodes start from
/// gymnasium's reset distribution ([`reacher_starts`]), the agent observes what `Reacher-v5`'s
/// agents observe ([`reacher_observation`], as MDGPS's global policy does), and the reward of a step is minus the cost
/// of the state it reaches and the command: `−c(x', u)`. 50 steps, no termination.
#[derive(Debug, Clone)]
pub struct ReacherTask {
    cost: ReacherCost,
    observation_space: tandem_core::Space,
    action_space: tandem_core::Space,
}

impl ReacherTask {
    /// The task with `cost`; an error for invalid weights.
    pub fn new(cost: ReacherCost) -> Result<Self, String> {
        cost.validate()?;
        Ok(Self {
            cost,
            observation_space: tandem_core::Space::unbounded(REACHER_OBS_DIM),
            action_space: tandem_core::Space::symmetric(REACHER_ACTION_DIM, 1.0),
        })
    }

    /// The cost.
    pub fn cost(&self) -> &ReacherCost {
        &self.cost
    }
}

impl tandem_envs::Task for ReacherTask {
    fn id(&self) -> &str {
        "p4-Reacher"
    }
    fn observation_space(&self) -> &tandem_core::Space {
        &self.observation_space
    }
    fn action_space(&self) -> &tandem_core::Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        REACHER_STATE_DIM
    }
    fn control(&self, action: &tandem_core::Action) -> Vec<f64> {
        match action {
            tandem_core::Action::Continuous(a) => tandem_envs::clip_to(&self.action_space, a),
            tandem_core::Action::Discrete(_) => vec![0.0; REACHER_ACTION_DIM],
        }
    }
    fn initial_state(&self, rng: &mut tandem_core::Rng) -> Vec<f64> {
        reacher_starts(1, rng).remove(0)
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        let mut o = vec![0.0; REACHER_OBS_DIM];
        reacher_observation(state, &mut o);
        o
    }
    fn reward(&self, _state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        -self.cost.running(next, u)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(REACHER_HORIZON)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn gripper_kinematics_of_simple_poses() {
        let g = pusher_gripper(&[0.0, 0.0, 0.0]);
        assert_relative_eq!(g[0], 1.05, epsilon = 1e-15);
        assert_relative_eq!(g[1], 0.0, epsilon = 1e-15);
        // Shoulder at 90°, elbow back by 90°: (0.4 + 0.15, 0.5).
        let g = pusher_gripper(&[
            std::f64::consts::FRAC_PI_2,
            -std::f64::consts::FRAC_PI_2,
            0.0,
        ]);
        assert_relative_eq!(g[0], 0.55, epsilon = 1e-15);
        assert_relative_eq!(g[1], 0.5, epsilon = 1e-15);
    }

    #[test]
    fn cost_is_the_weighted_sum_of_its_terms() {
        let c = PusherCost::default();
        let cond = PUSHER_CONDITIONS[0];
        // Gripper on the block, block on the goal, no torque: only the l1 floors remain.
        let mut x = cond.initial_state();
        x[4] = 1.05;
        x[5] = 0.0;
        let on_goal = PusherCondition {
            block: [1.05, 0.0],
            goal: [1.05, 0.0],
        };
        let floor = c.l1 * c.alpha.sqrt();
        assert_relative_eq!(
            c.running(&on_goal, 10, &x, &[0.0; 4], 9),
            (c.goal + c.block) * floor,
            epsilon = 1e-15
        );
        // Half-way through, the goal term counts a quarter; the torque term adds w_u |u|^2.
        let d = cond.block_goal_distance(&x);
        let expect =
            c.goal * 0.25 * l12(d, c.l1, c.l2, c.alpha) + c.block * floor + c.action * (1.0 + 4.0);
        assert_relative_eq!(
            c.running(&cond, 10, &x, &[1.0, 2.0, 0.0, 0.0], 4),
            expect,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            c.terminal(&cond, &x),
            c.goal * l12(d, c.l1, c.l2, c.alpha) + c.block * floor,
            epsilon = 1e-12
        );
    }

    /// The expansion's value and gradient are the cost's (central differences); its Hessian is
    /// symmetric positive semi-definite, and equals the finite-difference Hessian where the
    /// kinematics is linear (the block coordinates).
    #[test]
    fn state_expansion_matches_the_cost() {
        let c = PusherCost::default();
        let cond = PUSHER_CONDITIONS[PUSHER_HARD];
        let x = [
            0.4, -0.7, 1.1, 0.01, 0.5, -0.3, 0.2, -0.1, 0.3, 0.0, 0.05, 0.0,
        ];
        let (t, hz) = (37, PUSHER_HORIZON);
        let f = |x: &[f64]| c.running(&cond, hz, x, &[0.0; 4], t);
        let (v, g, h) = c.state_expansion(&cond, hz, &x, t);
        assert_relative_eq!(v, f(&x), epsilon = 1e-12);
        check_expansion(&f, &x, (g, h), 1e-6, &[(4, 4), (4, 5), (5, 5)]);
    }

    /// Checks the derivatives `(g, h)` of a Gauss–Newton expansion of `f` at `x`: `g` the central
    /// difference gradient (relative tolerance `grad_tol`), `h` symmetric positive semi-definite
    /// and equal to the finite-difference Hessian on the `exact` entries (where the residual is
    /// linear in the state).
    fn check_expansion(
        f: &dyn Fn(&[f64]) -> f64,
        x: &[f64],
        (g, h): (DVector<f64>, DMatrix<f64>),
        grad_tol: f64,
        exact: &[(usize, usize)],
    ) {
        let eps = 1e-6;
        for i in 0..x.len() {
            let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
            xp[i] += eps;
            xm[i] -= eps;
            let fd = (f(&xp) - f(&xm)) / (2.0 * eps);
            assert!(
                (fd - g[i]).abs() < grad_tol * (1.0 + fd.abs()),
                "d/dx{i}: {fd} vs {}",
                g[i]
            );
        }
        assert_relative_eq!(h.clone(), h.transpose(), epsilon = 1e-12);
        let eig = h.clone().symmetric_eigen().eigenvalues;
        assert!(eig.min() > -1e-9, "{eig}");
        let eps = 1e-4;
        for &(i, k) in exact {
            let at = |di: f64, dk: f64| {
                let mut y = x.to_vec();
                y[i] += di;
                y[k] += dk;
                f(&y)
            };
            let fd =
                (at(eps, eps) - at(eps, -eps) - at(-eps, eps) + at(-eps, -eps)) / (4.0 * eps * eps);
            assert!(
                (fd - h[(i, k)]).abs() < 1e-4 * (1.0 + fd.abs()),
                "({i},{k}): {fd} vs {}",
                h[(i, k)]
            );
        }
    }

    /// The pusher's task pays minus the cost of the state reached at full goal weight, whatever
    /// the state it came from, and observes the state with the goal after it.
    #[test]
    fn pusher_task_pays_the_unramped_cost() {
        use tandem_envs::Task;
        let c = PusherCost::default();
        let cond = PUSHER_CONDITIONS[PUSHER_HARD];
        let task = PusherTask::new(c, cond).unwrap();
        let next = [
            0.4, -0.7, 1.1, 0.01, 0.5, -0.3, 0.2, -0.1, 0.3, 0.0, 0.05, 0.0,
        ];
        let g = pusher_gripper(&next);
        let pen = |d: f64| l12(d, c.l1, c.l2, c.alpha);
        let u = [1.0, -2.0, 0.5, 0.0];
        let expect = -(c.goal * pen((0.5f64 - 0.9).hypot(-0.3 + 0.45))
            + c.block * pen((g[0] - 0.5).hypot(g[1] + 0.3))
            + c.action * 5.25);
        for from in [[0.0; 12], next] {
            assert_relative_eq!(task.reward(&from, &u, &next), expect, epsilon = 1e-12);
        }
        let o = task.observe(&next);
        assert_eq!(&o[..PUSHER_STATE_DIM], &next);
        assert_eq!(&o[PUSHER_STATE_DIM..], &cond.goal);
        let mut rng = tandem_core::seeding::rng_from_seed(0);
        assert_eq!(task.initial_state(&mut rng), cond.initial_state());
        assert_eq!(
            task.control(&tandem_core::Action::Continuous(vec![
                20.0, -7.0, 1.0, -0.5
            ])),
            vec![10.0, -6.0, 1.0, -0.5]
        );
        assert!(PusherTask::new(PusherCost { l2: -1.0, ..c }, cond).is_err());
    }

    #[test]
    fn the_hard_condition_is_far_from_gripper_and_goal() {
        let start = pusher_gripper(&[0.0; 3]);
        let far = |c: &PusherCondition| {
            (
                (c.block[0] - start[0]).hypot(c.block[1] - start[1]),
                (c.block[0] - c.goal[0]).hypot(c.block[1] - c.goal[1]),
            )
        };
        let (hard_gripper, hard_goal) = far(&PUSHER_CONDITIONS[PUSHER_HARD]);
        for (i, c) in PUSHER_CONDITIONS.iter().enumerate() {
            if i != PUSHER_HARD {
                let (g, b) = far(c);
                assert!(hard_gripper > g && hard_goal > b, "condition {i}");
            }
        }
    }

    #[test]
    fn door_hand_expansion_is_the_hand_terms() {
        let c = DoorCost::default();
        let r = [0.1, -0.2, 0.05];
        let (v, g, h) = c.hand_expansion(&r);
        assert_relative_eq!(v, c.running(&r, c.target, &[0.0; 6]), epsilon = 1e-14);
        let eps = 1e-6;
        for i in 0..3 {
            let (mut rp, mut rm) = (r, r);
            rp[i] += eps;
            rm[i] -= eps;
            let fd = (c.hand_expansion(&rp).0 - c.hand_expansion(&rm).0) / (2.0 * eps);
            assert!((fd - g[i]).abs() < 1e-6, "{i}: {fd} vs {}", g[i]);
            let (gp, gm) = (c.hand_expansion(&rp).1, c.hand_expansion(&rm).1);
            for (j, hij) in h[i].iter().enumerate() {
                let fd = (gp[j] - gm[j]) / (2.0 * eps);
                assert!((fd - hij).abs() < 1e-5, "({i},{j}): {fd} vs {hij}");
            }
        }
        // It is the shared penalty's expansion scaled by the weight.
        let (v1, g1, h1) = l12_expansion(&r, c.l1, c.l2, c.alpha);
        assert_relative_eq!(v, c.hand * v1, epsilon = 1e-14);
        for i in 0..3 {
            assert_relative_eq!(g[i], c.hand * g1[i], epsilon = 1e-12);
            for j in 0..3 {
                assert_relative_eq!(h[i][j], c.hand * h1[(i, j)], epsilon = 1e-10);
            }
        }
        // The angle and action terms.
        assert_relative_eq!(
            c.running(&[0.0; 3], 0.5, &[1.0, 0.0, 0.0, 0.0, 0.0, 2.0])
                - c.running(&[0.0; 3], 1.0, &[0.0; 6]),
            0.25 + 5.0 * c.action,
            epsilon = 1e-14
        );
    }

    #[test]
    fn invalid_cost_weights_are_named() {
        let bad = PusherCost {
            goal: f64::NAN,
            ..PusherCost::default()
        };
        assert!(bad.validate().unwrap_err().contains("goal"));
        let bad = PusherCost {
            alpha: 0.0,
            ..PusherCost::default()
        };
        assert!(bad.validate().unwrap_err().contains("alpha"));
    }
    #[test]
    fn reacher_kinematics_and_distance_of_simple_poses() {
        let p = reacher_fingertip(&[0.0, 0.0]);
        assert_relative_eq!(p[0], 0.21, epsilon = 1e-15);
        assert_relative_eq!(p[1], 0.0, epsilon = 1e-15);
        // Shoulder at 90°, elbow back by 90°: (0.11, 0.1).
        let p = reacher_fingertip(&[std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2]);
        assert_relative_eq!(p[0], 0.11, epsilon = 1e-15);
        assert_relative_eq!(p[1], 0.1, epsilon = 1e-15);
        // Target 3-4-5 away from the straight arm's tip.
        let x = [0.0, 0.0, 0.21 + 0.03, 0.04, 1.0, 2.0, 0.0, 0.0];
        assert_relative_eq!(reacher_distance(&x), 0.05, epsilon = 1e-15);
        let c = ReacherCost::default();
        assert_relative_eq!(
            c.running(&x, &[0.5, -1.0]),
            c.distance * l12(0.05, c.l1, c.l2, c.alpha) + c.action * 1.25,
            epsilon = 1e-15
        );
        assert_relative_eq!(
            c.running(&x, &[]),
            c.distance * l12(0.05, c.l1, c.l2, c.alpha),
            epsilon = 1e-15
        );
        assert!(ReacherCost { alpha: 0.0, ..c }.validate().is_err());
        assert!(ReacherTask::new(ReacherCost {
            action: f64::NAN,
            ..c
        })
        .is_err());
    }

    /// Value and gradient of the reacher's expansion are the cost's (central differences); the
    /// Hessian is symmetric positive semi-definite and exact in the target's coordinates (where
    /// the residual is linear).
    #[test]
    fn reacher_expansion_matches_the_cost() {
        let c = ReacherCost::default();
        let x = [0.7, -1.3, 0.05, 0.12, 0.3, -0.2, 0.0, 0.0];
        let f = |x: &[f64]| c.running(x, &[]);
        let (v, g, h) = c.state_expansion(&x);
        assert_relative_eq!(v, f(&x), epsilon = 1e-15);
        check_expansion(&f, &x, (g, h), 1e-7, &[(2, 2), (2, 3), (3, 3)]);
    }

    /// The starts follow gymnasium's reset: arm within 0.1 rad of straight, target in the disc
    /// of radius 0.2, still target, small arm velocities; the task observes them whole and pays
    /// minus the cost of the state reached.
    #[test]
    fn reacher_starts_follow_gymnasiums_reset() {
        use tandem_envs::Task;
        let mut rng = tandem_core::seeding::rng_from_seed(3);
        let starts = reacher_starts(500, &mut rng);
        let mut far = 0usize;
        for x in &starts {
            assert_eq!(x.len(), REACHER_STATE_DIM);
            assert!(x[0].abs() <= 0.1 && x[1].abs() <= 0.1);
            assert!(x[2].hypot(x[3]) < 0.2);
            assert!(x[4].abs() <= 0.005 && x[5].abs() <= 0.005);
            assert_eq!((x[6], x[7]), (0.0, 0.0));
            far += usize::from(x[2].hypot(x[3]) > 0.1);
        }
        // Uniform in the disc: three quarters of the targets lie beyond half the radius.
        assert!((far as f64 / 500.0 - 0.75).abs() < 0.06, "{far}");
        let task = ReacherTask::new(ReacherCost::default()).unwrap();
        let x = &starts[0];
        let o = task.observe(x);
        let tip = reacher_fingertip(x);
        assert_eq!(o.len(), REACHER_OBS_DIM);
        assert_relative_eq!(o[8], tip[0] - x[2], epsilon = 1e-15);
        assert_relative_eq!(o[9], tip[1] - x[3], epsilon = 1e-15);
        assert_relative_eq!(
            task.reward(&starts[1], &[0.3, 0.1], x),
            -task.cost().running(x, &[0.3, 0.1]),
            epsilon = 1e-15
        );
        assert_eq!(task.max_episode_steps(), Some(REACHER_HORIZON));
    }

    /// The gripper velocity is the derivative of the gripper point along the joint velocities
    /// (central differences of the kinematics), and the features are the point and it.
    #[test]
    fn gripper_velocity_is_the_kinematics_rate() {
        let x = [
            0.4, -0.7, 1.1, 0.01, 0.5, -0.3, 0.8, -1.5, 2.0, 0.3, 0.05, 0.0,
        ];
        let v = pusher_gripper_velocity(&x);
        let h = 1e-6;
        let at = |s: f64| {
            let q: Vec<f64> = (0..3).map(|i| x[i] + s * h * x[6 + i]).collect();
            pusher_gripper(&q)
        };
        let (p, m) = (at(1.0), at(-1.0));
        for k in 0..2 {
            let fd = (p[k] - m[k]) / (2.0 * h);
            assert!((fd - v[k]).abs() < 1e-8, "{k}: {fd} vs {}", v[k]);
        }
        let mut f = [0.0; PUSHER_FEATURES_DIM];
        pusher_features(&x, &mut f);
        let g = pusher_gripper(&x);
        assert_eq!(f, [g[0], g[1], v[0], v[1]]);
        // The block's coordinates and the finger do not move the gripper point.
        let mut y = x;
        (y[4], y[5], y[3], y[9], y[10], y[11]) = (9.0, 9.0, 0.5, 7.0, 7.0, 7.0);
        assert_eq!(pusher_gripper_velocity(&y), v);
    }

    /// GPS's `RAMP_QUADRATIC`: `((t+1)/T)²`, `1/T²` at the first step, 1 at the last and at
    /// the terminal state; 1 throughout when off.
    #[test]
    fn door_angle_ramp_is_gps_quadratic_ramp() {
        let off = DoorCost::default();
        let on = DoorCost {
            angle_ramp: true,
            ..off
        };
        let hz = DOOR_HORIZON;
        assert_relative_eq!(on.angle_ramp_at(0, hz), 1e-4, epsilon = 1e-18);
        assert_eq!(on.angle_ramp_at(49, hz), 0.25);
        assert_eq!(on.angle_ramp_at(hz - 1, hz), 1.0);
        assert_eq!(on.angle_ramp_at(hz, hz), 1.0);
        for t in [0, 49, hz - 1, hz] {
            assert_eq!(off.angle_ramp_at(t, hz), 1.0);
        }
        let r = [0.1, -0.2, 0.05];
        let u = [0.3, 0.0, -0.1, 0.0, 0.2, 0.0];
        let pay = |c: &DoorCost, t| c.running_at(&r, 0.3, &u, t, hz);
        assert_relative_eq!(
            pay(&off, 0) - pay(&on, 0),
            off.angle * (1.0 - 1e-4) * 0.49,
            epsilon = 1e-12
        );
        assert_eq!(pay(&on, hz - 1), pay(&off, hz - 1));
    }

    /// With the new terms off, the time-indexed cost and its expansion are the old ones to the
    /// bit, at every step.
    #[test]
    fn door_cost_without_the_options_is_unchanged() {
        let c = DoorCost::default();
        let u = [0.3, 0.0, -0.1, 0.0, 0.2, 0.7];
        for (r, angle) in [([0.1, -0.2, 0.05], 0.3), ([-0.31, 0.0, 0.2], 0.0)] {
            for t in [0, 24, 25, 99, 100] {
                assert_eq!(
                    c.running_at(&r, angle, &u, t, DOOR_HORIZON).to_bits(),
                    c.running(&r, angle, &u).to_bits()
                );
                assert_eq!(
                    c.offset_expansion(&r, t, DOOR_HORIZON),
                    c.hand_expansion(&r)
                );
            }
        }
    }

    /// The waypoints: the hook 0.15 m over the grasp point on the first quarter of the horizon
    /// (`t < ⌈0.25 T⌉`, as `CostLinWP` discretizes `waypoint_time`), at the grasp point from
    /// there on and at the end; their expansion's value, gradient and Hessian in the offset are
    /// the cost's (central differences), in both phases.
    #[test]
    fn door_waypoints_and_their_expansion() {
        let c = DoorCost {
            waypoints: DoorWaypoints::authors(),
            ..DoorCost::default()
        };
        let w = c.waypoints;
        let hz = DOOR_HORIZON;
        assert_eq!(w.target(0, hz), [0.0, 0.0, 0.15]);
        assert_eq!(w.target(24, hz), [0.0, 0.0, 0.15]);
        assert_eq!(w.target(25, hz), [0.0; 3]);
        assert_eq!(w.target(hz, hz), [0.0; 3]);
        // T = 10: ⌈2.5⌉ = 3 steps of the first waypoint.
        assert_eq!(w.target(2, 10), [0.0, 0.0, 0.15]);
        assert_eq!(w.target(3, 10), [0.0; 3]);
        let base = DoorCost::default();
        for (t, a) in [(3, 0.15), (24, 0.15), (25, 0.0), (hz, 0.0)] {
            let r: [f64; 3] = [0.12, -0.07, 0.21];
            let e = [r[0], r[1], r[2] - a];
            let d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
            let u: &[f64] = if t == hz { &[] } else { &[0.5; 6] };
            assert_relative_eq!(
                c.running_at(&r, 0.4, u, t, hz),
                base.running_at(&r, 0.4, u, t, hz) + l12(d, w.l1, w.l2, w.alpha),
                epsilon = 1e-14
            );
            let (v, g, h) = c.offset_expansion(&r, t, hz);
            let f = |r: &[f64; 3]| c.running_at(r, c.target, &[], t, hz);
            assert_relative_eq!(v, f(&r), epsilon = 1e-14);
            let eps = 1e-6;
            for i in 0..3 {
                let (mut rp, mut rm) = (r, r);
                rp[i] += eps;
                rm[i] -= eps;
                let fd = (f(&rp) - f(&rm)) / (2.0 * eps);
                assert!((fd - g[i]).abs() < 1e-7, "t {t}, d/dr{i}: {fd} vs {}", g[i]);
                let (gp, gm) = (
                    c.offset_expansion(&rp, t, hz).1,
                    c.offset_expansion(&rm, t, hz).1,
                );
                for j in 0..3 {
                    let fd = (gp[j] - gm[j]) / (2.0 * eps);
                    assert!(
                        (fd - h[i][j]).abs() < 1e-6,
                        "t {t}, ({i},{j}): {fd} vs {}",
                        h[i][j]
                    );
                }
            }
        }
    }

    /// Committed settings (no new keys) read as the defaults and are written back without them;
    /// the options read from their keys; bad waypoint settings are named.
    #[test]
    fn door_and_pusher_options_read_and_write() {
        let committed = r#"{"hand": 10.0, "angle": 1.0, "target": 1.0, "action": 0.001,
            "l1": 0.1, "l2": 1.0, "alpha": 0.00001}"#;
        let c: DoorCost = serde_json::from_str(committed).unwrap();
        assert_eq!(c, DoorCost::default());
        let text = serde_json::to_string(&c).unwrap();
        for key in ["angle_ramp", "waypoints", "end_effector_features"] {
            assert!(!text.contains(key), "{text}");
        }
        let on: DoorCost = serde_json::from_str(
            r#"{"hand": 0.0, "angle": 5.0, "target": 1.0, "action": 0.001, "l1": 0.1,
            "l2": 1.0, "alpha": 0.00001, "angle_ramp": true, "waypoints": {"weight": 1.0},
            "end_effector_features": true}"#,
        )
        .unwrap();
        assert!(on.angle_ramp && on.end_effector_features);
        assert_eq!(on.waypoints, DoorWaypoints::authors());
        let back: DoorCost = serde_json::from_str(&serde_json::to_string(&on).unwrap()).unwrap();
        assert_eq!(back, on);
        assert!(serde_json::from_str::<DoorCost>(
            r#"{"hand": 0.0, "angle": 5.0, "target": 1.0, "action": 0.001, "l1": 0.1,
            "l2": 1.0, "alpha": 0.00001, "waypoints": {"weight": 1.0, "height": 2}}"#
        )
        .is_err());
        for (bad, what) in [
            (
                DoorWaypoints {
                    weight: -1.0,
                    ..DoorWaypoints::authors()
                },
                "waypoints.weight",
            ),
            (
                DoorWaypoints {
                    switch: 1.5,
                    ..DoorWaypoints::authors()
                },
                "switch",
            ),
            (
                DoorWaypoints {
                    alpha: 0.0,
                    ..DoorWaypoints::authors()
                },
                "alpha",
            ),
            (
                DoorWaypoints {
                    above: f64::NAN,
                    ..DoorWaypoints::authors()
                },
                "above",
            ),
        ] {
            let e = DoorCost {
                waypoints: bad,
                ..DoorCost::default()
            }
            .validate()
            .unwrap_err();
            assert!(e.contains(what), "{what}: {e}");
        }
        let p: PusherCost = serde_json::from_str(
            r#"{"goal": 4.0, "block": 1.0, "action": 0.001, "l1": 0.1, "l2": 10.0,
            "alpha": 0.00001}"#,
        )
        .unwrap();
        assert_eq!(p, PusherCost::default());
        assert!(!serde_json::to_string(&p).unwrap().contains("end_effector"));
    }
}
