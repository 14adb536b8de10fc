//! p4 (Chebotar et al., PILQR) on its MuJoCo manipulation tasks: the problems the GPS loop
//! ([`super::gps`]) trains local controllers on.
//!
//! The gripper pusher ([`pusher_problem`]): the scene `p4_pusher.xml` as a `MujocoPlant`
//! (state `qpos ++ qvel`, 0.05 s control), [`tandem_robots::p4::PUSHER_CONDITIONS`] as the
//! conditions, [`PusherCost`] as every condition's cost (its terminal cost the last step's
//! distance terms), and the final block–goal distance as the measure.
//!
//! The door ([`door_problem`]): the scene `p4_door.xml`, [`tandem_robots::p4::DOOR_CONDITIONS`],
//! [`DoorCost`] on the hook and grasp points from MuJoCo's kinematics (its expansion Gauss–Newton
//! through finite-difference site Jacobians), and the final door angle as the measure. MDGPS's
//! global policy on it (p4 Fig. 5) sees `DoorTask`'s observation, and [`door_test_set`] is where
//! it is measured: random arm starts between the four conditions.

use nalgebra::{DMatrix, DVector};
use tandem_planners::{Objective, QuadCost, QuadTerminal};
use tandem_robots::p4::{
    reacher_distance, reacher_starts, DoorCost, PusherCondition, PusherCost, ReacherCost,
    PUSHER_ACTION_DIM, PUSHER_CONDITIONS, PUSHER_HORIZON, PUSHER_STATE_DIM, REACHER_ACTION_DIM,
    REACHER_HORIZON, REACHER_STATE_DIM,
};

use super::gps::{Condition, LocalProblem};
use super::mdgps::TestSet;
use super::{AlgoError, Result};

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
///
/// With `cost.end_effector_features` the state is `qpos ++ qvel ++ [p, ṗ]` (16): the gripper
/// point and its velocity ([`tandem_robots::p4::pusher_features`]) appended by
/// [`super::state_features::with_features`].
pub fn pusher_problem(cost: PusherCost) -> Result<LocalProblem> {
    cost.validate().map_err(AlgoError::Config)?;
    let conditions = PUSHER_CONDITIONS
        .iter()
        .map(|c| Condition {
            x0: c.initial_state(),
            objective: pusher_objective(*c, cost, PUSHER_HORIZON),
        })
        .collect();
    let problem = LocalProblem {
        system: pusher_system()?,
        conditions,
        horizon: PUSHER_HORIZON,
        measure: Box::new(|c, x| PUSHER_CONDITIONS[c].block_goal_distance(x)),
        policy_input: None,
    };
    if !cost.end_effector_features {
        return Ok(problem);
    }
    let features: super::state_features::FeatureFn =
        std::sync::Arc::new(|x: &[f64], out: &mut [f64]| {
            if let Some(v) = x.iter().find(|v| !v.is_finite()) {
                return Err(format!("the pusher's features of a state with {v}"));
            }
            tandem_robots::p4::pusher_features(x, out);
            Ok(())
        });
    super::state_features::with_features(problem, tandem_robots::p4::PUSHER_FEATURES_DIM, features)
}

#[cfg(feature = "mujoco")]
fn pusher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    let plant = tandem_robots::p4::pusher_plant().map_err(|e| AlgoError::Config(e.to_string()))?;
    Ok(Box::new(tandem_models::PlantModel::new(plant)))
}

#[cfg(not(feature = "mujoco"))]
fn pusher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    Err(AlgoError::Config(
        "p4's pusher needs a build with `--features mujoco` after scripts/setup-mujoco.sh".into(),
    ))
}

/// The reacher's objective: [`ReacherCost`] at every step, its distance term at the end, with the
/// Gauss–Newton expansion ([`ReacherCost::state_expansion`]).
pub fn reacher_objective(cost: ReacherCost) -> Objective {
    Objective::new(REACHER_STATE_DIM, REACHER_ACTION_DIM, move |x, u| {
        cost.running(x, u)
    })
    .with_terminal(move |x| cost.running(x, &[]))
    .with_running_derivatives(move |x, u, _| {
        let (c, cx, cxx) = cost.state_expansion(x);
        with_action_cost(c, cx, cxx, u, cost.action)
    })
    .with_terminal_derivatives(move |x| {
        let (c, cx, cxx) = cost.state_expansion(x);
        QuadTerminal { c, cx, cxx }
    })
}

/// The reacher with `conditions` training starts drawn from `Reacher-v5`'s reset distribution by
/// `seed`'s generator, and `cost`. Needs the feature `mujoco`; without it, an error saying so.
pub fn reacher_problem(cost: ReacherCost, conditions: usize, seed: u64) -> Result<LocalProblem> {
    cost.validate().map_err(AlgoError::Config)?;
    if conditions == 0 {
        return Err(AlgoError::Config(
            "the reacher needs at least one condition".into(),
        ));
    }
    let mut rng = tandem_core::seeding::rng_from_seed(seed);
    let conditions = reacher_starts(conditions, &mut rng)
        .into_iter()
        .map(|x0| Condition {
            x0,
            objective: reacher_objective(cost),
        })
        .collect();
    Ok(LocalProblem {
        system: reacher_system()?,
        conditions,
        horizon: REACHER_HORIZON,
        measure: Box::new(|_, x| reacher_distance(x)),
        policy_input: Some(reacher_policy_input()),
    })
}

/// The reacher's global policy sees `Reacher-v5`'s observation
/// ([`tandem_robots::p4::reacher_observation`]), as DDPG does.
pub fn reacher_policy_input() -> tandem_agents::PolicyInput {
    tandem_agents::PolicyInput {
        dim: tandem_robots::p4::REACHER_OBS_DIM,
        map: std::sync::Arc::new(tandem_robots::p4::reacher_observation),
    }
}

/// MDGPS's settings for the reacher: 15 iterations of 3 trajectories per condition, initial
/// action variance 0.02 (standard deviation 0.14: the commands that matter are a few tenths),
/// KL bound `ε = 0.1` per step (at 0.5 or 1 the local controllers, bounded against a global
/// policy that still fits them loosely, lost more than they gained; GPS's step rule,
/// [`super::mdgps::MdgpsStep`], helped a little on two seeds and hurt badly on the third), a
/// policy of two hidden layers of 64 fitted uniformly, linearized for the bound by GPS's
/// regression with its GMM prior ([`super::mdgps::Linearization`]; `results/p4-reacher/` ran the
/// point Jacobian).
pub fn reacher_config() -> super::mdgps::MdgpsConfig {
    let mut local = super::gps::LocalConfig {
        iterations: 15,
        samples: 3,
        init_variance: 0.02,
        ..Default::default()
    };
    local.trajopt.lqr.kl_step = 0.1;
    super::mdgps::MdgpsConfig {
        local,
        policy: Default::default(),
        step: Default::default(),
        linearization: Default::default(),
        first_iteration: super::mdgps::FirstIteration::Unbounded,
    }
}

/// p4's number of reacher test starts.
pub const REACHER_TEST_CONDITIONS: usize = 300;
/// The generator of the reacher's test starts in `tandem reproduce p4-reacher` and the example.
pub const REACHER_TEST_SEED: u64 = 2017;

/// `n` test starts of the reacher drawn by `seed`'s generator, measured by the final
/// fingertip–target distance.
pub fn reacher_test_set(n: usize, seed: u64) -> TestSet {
    let mut rng = tandem_core::seeding::rng_from_seed(seed);
    TestSet {
        starts: reacher_starts(n, &mut rng),
        measure: Box::new(reacher_distance),
        solved: None,
    }
}

/// gymnasium's `reacher.xml` as a plant (`$TANDEM_MUJOCO_ASSETS` or the setup script's assets).
#[cfg(feature = "mujoco")]
pub fn reacher_plant() -> Result<tandem_mujoco::MujocoPlant> {
    let kind = tandem_mujoco::TaskKind::Reacher;
    let path = tandem_mujoco::assets_dir().join(kind.spec().xml);
    tandem_mujoco::MujocoPlant::from_xml(&path, kind.spec().frame_skip).map_err(|e| {
        AlgoError::Config(format!(
            "{e} (gymnasium's assets: run scripts/setup-mujoco.sh)"
        ))
    })
}

#[cfg(feature = "mujoco")]
fn reacher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    Ok(Box::new(tandem_models::PlantModel::new(reacher_plant()?)))
}

#[cfg(not(feature = "mujoco"))]
fn reacher_system() -> Result<Box<dyn tandem_models::DynamicsModel + Send + Sync>> {
    Err(AlgoError::Config(
        "p4's reacher needs a build with `--features mujoco` after scripts/setup-mujoco.sh".into(),
    ))
}

/// The door's four conditions on MuJoCo, with `cost`. Needs the feature `mujoco`; without it, an
/// error saying so.
///
/// A global policy on it (MDGPS) sees `DoorTask`'s observation of the scene's part of the state:
/// the state `qpos ++ qvel` (14) and the hook's offset from the grasp point (3), what the cost
/// reads, as the reacher's policy sees its fingertip's offset to the target. With
/// `cost.end_effector_features` the features appended to the state are the local controllers'
/// alone.
pub fn door_problem(cost: DoorCost) -> Result<LocalProblem> {
    cost.validate().map_err(AlgoError::Config)?;
    door::problem(cost)
}

/// p4's number of door test starts (Fig. 5: "100 random test conditions per iteration").
pub const DOOR_TEST_CONDITIONS: usize = 100;
/// The generator of the door's test starts in the example.
pub const DOOR_TEST_SEED: u64 = 2017;

/// `n` test starts of the door drawn by `seed`'s generator
/// ([`tandem_robots::p4::door_test_starts`]: the arm's joints a random convex combination of the
/// four conditions'), in the state of [`door_problem`] with `cost` (its end-effector features
/// appended when `cost.end_effector_features`), measured by the final door angle; a start is
/// solved when the door ends opened ([`tandem_robots::p4::DOOR_OPENED`], 0.8 rad). Needs the
/// feature `mujoco` for the features; without it, an error saying so when they are on.
pub fn door_test_set(n: usize, seed: u64, cost: &DoorCost) -> Result<TestSet> {
    cost.validate().map_err(AlgoError::Config)?;
    if n == 0 {
        return Err(AlgoError::Config(
            "the door's test set needs at least one start".into(),
        ));
    }
    let mut rng = tandem_core::seeding::rng_from_seed(seed);
    let starts = tandem_robots::p4::door_test_starts(n, &mut rng);
    let starts = if cost.end_effector_features {
        door::extend_starts(starts)?
    } else {
        starts
    };
    let angle = tandem_robots::p4::DOOR_ANGLE;
    Ok(TestSet {
        starts,
        measure: Box::new(move |x| x[angle]),
        solved: Some(Box::new(|a| a >= tandem_robots::p4::DOOR_OPENED)),
    })
}

#[cfg(feature = "mujoco")]
mod door {
    use nalgebra::{DMatrix, DVector};
    use tandem_planners::{Objective, QuadTerminal};
    use tandem_robots::p4::{
        door_initial_state, door_plant, DoorCost, DoorKinematics, DOOR_ACTION_DIM, DOOR_ANGLE,
        DOOR_CONDITIONS, DOOR_FEATURES_DIM, DOOR_HORIZON, DOOR_OBS_DIM, DOOR_STATE_DIM,
    };

    use super::super::gps::{Condition, LocalProblem};
    use super::super::state_features::{with_features, FeatureFn};
    use super::super::{AlgoError, Result};

    /// Value, gradient and Gauss–Newton Hessian in the state of the state terms of the cost at
    /// step `t` (`DOOR_HORIZON` for the terminal state).
    pub(super) fn expansion(
        kin: &DoorKinematics,
        cost: &DoorCost,
        x: &[f64],
        t: usize,
    ) -> (f64, DVector<f64>, DMatrix<f64>) {
        let r = kin.offset_or_nan(x);
        let (v, g, h) = cost.offset_expansion(&r, t, DOOR_HORIZON);
        let (g, h) = (
            DVector::from_column_slice(&g),
            DMatrix::from_fn(3, 3, |i, j| h[i][j]),
        );
        // ∂r/∂q by central differences of the kinematics.
        let eps = 1e-6;
        let mut jac = DMatrix::zeros(3, DOOR_STATE_DIM);
        let mut q = x[..=DOOR_ANGLE].to_vec();
        for j in 0..q.len() {
            let q0 = q[j];
            q[j] = q0 + eps;
            let rp = kin.offset_or_nan(&q);
            q[j] = q0 - eps;
            let rm = kin.offset_or_nan(&q);
            q[j] = q0;
            for i in 0..3 {
                jac[(i, j)] = (rp[i] - rm[i]) / (2.0 * eps);
            }
        }
        let mut cx = jac.transpose() * g;
        let mut cxx = jac.transpose() * h * &jac;
        let e = x[DOOR_ANGLE] - cost.target;
        // Exactly `cost.angle` without the ramp.
        let w = cost.angle * cost.angle_ramp_at(t, DOOR_HORIZON);
        cx[DOOR_ANGLE] += 2.0 * w * e;
        cxx[(DOOR_ANGLE, DOOR_ANGLE)] += 2.0 * w;
        (v + w * e * e, cx, cxx)
    }

    /// The door's objective for one condition: [`DoorCost::running_at`] at every step, the
    /// last step's state terms at the end, with the Gauss–Newton expansion through
    /// finite-difference site Jacobians.
    pub(super) fn objective(kin: &DoorKinematics, cost: DoorCost) -> Objective {
        let (k1, k2, k3, k4) = (kin.clone(), kin.clone(), kin.clone(), kin.clone());
        let hz = DOOR_HORIZON;
        Objective::time_varying(DOOR_STATE_DIM, DOOR_ACTION_DIM, move |x, u, t| {
            cost.running_at(&k1.offset_or_nan(x), x[DOOR_ANGLE], u, t, hz)
        })
        .with_terminal(move |x| cost.running_at(&k2.offset_or_nan(x), x[DOOR_ANGLE], &[], hz, hz))
        .with_running_derivatives(move |x, u, t| {
            let (c, cx, cxx) = expansion(&k3, &cost, x, t);
            super::with_action_cost(c, cx, cxx, u, cost.action)
        })
        .with_terminal_derivatives(move |x| {
            let (c, cx, cxx) = expansion(&k4, &cost, x, hz);
            QuadTerminal { c, cx, cxx }
        })
    }

    pub(super) fn problem(cost: DoorCost) -> Result<LocalProblem> {
        let bad = |e: tandem_mujoco::MujocoError| AlgoError::Config(e.to_string());
        let plant = door_plant().map_err(bad)?;
        let kin = DoorKinematics::new(plant.scene().clone()).map_err(bad)?;
        let conditions = (0..DOOR_CONDITIONS.len())
            .map(|c| Condition {
                x0: door_initial_state(c),
                objective: objective(&kin, cost),
            })
            .collect();
        let problem = LocalProblem {
            system: Box::new(tandem_models::PlantModel::new(plant)),
            conditions,
            horizon: DOOR_HORIZON,
            measure: Box::new(|_, x| x[DOOR_ANGLE]),
            policy_input: Some(policy_input(kin.clone())),
        };
        if !cost.end_effector_features {
            return Ok(problem);
        }
        let features: FeatureFn = std::sync::Arc::new(move |x: &[f64], out: &mut [f64]| {
            kin.features(x, out).map_err(|e| e.to_string())
        });
        with_features(problem, DOOR_FEATURES_DIM, features)
    }

    /// `DoorTask`'s observation of a state's first [`DOOR_STATE_DIM`] entries: those entries and
    /// the hook's offset from the grasp point (NaN for a state that is not finite).
    fn policy_input(kin: DoorKinematics) -> tandem_agents::PolicyInput {
        tandem_agents::PolicyInput {
            dim: DOOR_OBS_DIM,
            map: std::sync::Arc::new(move |x: &[f64], out: &mut [f64]| {
                out[..DOOR_STATE_DIM].copy_from_slice(&x[..DOOR_STATE_DIM]);
                out[DOOR_STATE_DIM..DOOR_OBS_DIM].copy_from_slice(&kin.offset_or_nan(x));
            }),
        }
    }

    /// Scene states with the door's end-effector features appended.
    pub(super) fn extend_starts(starts: Vec<Vec<f64>>) -> Result<Vec<Vec<f64>>> {
        let kin = DoorKinematics::load().map_err(|e| AlgoError::Config(e.to_string()))?;
        starts
            .into_iter()
            .map(|mut x| {
                let mut f = [0.0; DOOR_FEATURES_DIM];
                kin.features(&x, &mut f)
                    .map_err(|e| AlgoError::Config(e.to_string()))?;
                x.extend_from_slice(&f);
                Ok(x)
            })
            .collect()
    }
}

#[cfg(not(feature = "mujoco"))]
mod door {
    use super::super::gps::LocalProblem;
    use super::super::{AlgoError, Result};

    pub(super) fn problem(_cost: tandem_robots::p4::DoorCost) -> Result<LocalProblem> {
        Err(unavailable())
    }

    pub(super) fn extend_starts(_starts: Vec<Vec<f64>>) -> Result<Vec<Vec<f64>>> {
        Err(unavailable())
    }

    fn unavailable() -> AlgoError {
        AlgoError::Config(
            "p4's door needs a build with `--features mujoco` after scripts/setup-mujoco.sh".into(),
        )
    }
}

/// A point of a neural policy's curve on a test set: after `samples` real steps, the mean
/// measure of its deterministic rollouts from the test starts.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TestedPoint {
    /// Real environment steps so far.
    pub samples: u64,
    /// The mean final measure over the test starts.
    pub test_measure: f64,
}

/// DDPG's settings on the reacher: the agent, the step budget and how often it is measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReacherDdpg {
    /// The agent (with its off-policy schedule).
    pub agent: tandem_agents::DdpgConfig,
    /// Real steps to train for.
    pub steps: u64,
    /// Measure on the test set (and checkpoint) every this many steps.
    pub eval_every: u64,
}

impl Default for ReacherDdpg {
    /// stable-baselines3's DDPG defaults (two hidden layers of 400 and 300, Adam 10⁻³ for both
    /// networks, τ = 0.005, γ = 0.99, minibatch 256, one update per step after 100 random steps)
    /// with Gaussian exploration noise σ = 0.1 (rl-baselines3-zoo's usual choice for MuJoCo);
    /// 50,000 steps, measured every 2,500.
    fn default() -> Self {
        Self {
            agent: tandem_agents::DdpgConfig {
                actor_hidden: vec![400, 300],
                critic_hidden: vec![400, 300],
                actor_lr: 1e-3,
                critic_lr: 1e-3,
                critic_weight_decay: 0.0,
                tau: 0.005,
                gamma: 0.99,
                noise: tandem_agents::NoiseConfig::Gaussian { sigma: 0.1 },
                buffer_size: 1_000_000,
                learning_starts: 100,
                batch_size: 256,
                train_freq: 1,
                gradient_steps: 1,
            },
            steps: 50_000,
            eval_every: 2_500,
        }
    }
}

impl ReacherDdpg {
    /// Checks the agent's settings and that the budget and the measurement interval are
    /// positive.
    pub fn validate(&self) -> Result<()> {
        if self.eval_every == 0 || self.steps == 0 {
            return Err(AlgoError::Config(format!(
                "ddpg steps {} and eval_every {} must be positive",
                self.steps, self.eval_every
            )));
        }
        Ok(self.agent.validate()?)
    }
}

/// Trains DDPG on the reacher (episodes from `Reacher-v5`'s reset distribution, reward `−c`,
/// observing the whole state) with the loop `tandem train` runs, measuring its deterministic
/// policy on `test` at the start and every `eval_every` steps. Checkpoints (under `"ddpg"`) at
/// every measurement, so an interrupted run resumes with exactly its numbers. `progress`
/// receives the steps taken so far. Needs the feature `mujoco`.
pub fn train_ddpg_reacher(
    cost: ReacherCost,
    cfg: &ReacherDdpg,
    test: &TestSet,
    seed: u64,
    store: &mut dyn super::Checkpoints,
    progress: &mut dyn FnMut(u64),
) -> Result<Vec<TestedPoint>> {
    cfg.validate()?;
    ddpg::train(cost, cfg, test, seed, store, progress)
}

#[cfg(feature = "mujoco")]
mod ddpg {
    use ndarray::Array2;
    use tandem_agents::{AlgoConfig, BatchPolicy, Learner, Mode};
    use tandem_envs::{Env, PlantEnv, TimeLimit};
    use tandem_models::PlantModel;
    use tandem_mujoco::MujocoPlant;
    use tandem_nn::Checkpoint;
    use tandem_robots::p4::{
        reacher_observation, ReacherCost, ReacherTask, REACHER_HORIZON, REACHER_OBS_DIM,
    };

    use super::super::driver::{drive, Algorithm};
    use super::super::mdgps::TestSet;
    use super::super::model_free::{ModelFree, TrainSettings};
    use super::super::{AlgoError, Checkpoints, Result};
    use super::{reacher_plant, ReacherDdpg, TestedPoint};

    const CURVE: &str = "reacher_ddpg.curve";

    /// DDPG on the reacher as one checkpointable value: the model-free run and the test curve.
    struct ReacherRun<'a> {
        run: ModelFree,
        system: PlantModel<MujocoPlant>,
        test: &'a TestSet,
        seed: u64,
        curve: Vec<TestedPoint>,
    }

    impl ReacherRun<'_> {
        /// The deterministic policy's point on the test set now.
        fn measure(&mut self) -> Result<TestedPoint> {
            let samples = self.run.steps();
            let Learner::Ddpg(agent) = self.run.learner() else {
                unreachable!("the run was built for DDPG");
            };
            // Deterministic acting draws nothing; the generator only satisfies the signature.
            let (mut rng, mut unused) = (
                tandem_core::seeding::rng_from_seed(self.seed),
                tandem_core::seeding::rng_from_seed(self.seed),
            );
            let test_measure = self.test.measure_policy(
                &self.system,
                REACHER_HORIZON,
                &mut rng,
                &mut |x: &Array2<f64>| {
                    let mut obs = Array2::zeros((x.nrows(), REACHER_OBS_DIM));
                    for (s, mut o) in x.rows().into_iter().zip(obs.rows_mut()) {
                        reacher_observation(
                            s.as_slice().expect("standard layout"),
                            o.as_slice_mut().expect("standard layout"),
                        );
                    }
                    let a = agent.act_batch(obs.view(), Mode::Deterministic, &mut unused)?;
                    Ok(a.iter().copied().collect())
                },
            )?;
            Ok(TestedPoint {
                samples,
                test_measure,
            })
        }
    }

    impl Algorithm for ReacherRun<'_> {
        type Event = u64;
        type Record = Vec<TestedPoint>;

        fn id(&self) -> (&str, u64) {
            ("ddpg", self.seed)
        }

        fn start(&mut self, _: &mut dyn FnMut(u64)) -> Result<()> {
            self.curve = vec![self.measure()?];
            Ok(())
        }

        fn done(&self) -> bool {
            self.run.done()
        }

        /// An environment step; measured (and checkpointed) every `eval_every` steps and at
        /// the end.
        fn step(&mut self, on_event: &mut dyn FnMut(u64), _: &dyn Checkpoints) -> Result<bool> {
            let due = self.run.advance(&mut |_| {})?;
            let steps = self.run.steps();
            if steps.is_multiple_of(1000) {
                on_event(steps);
            }
            if due || self.run.done() {
                let point = self.measure()?;
                self.curve.push(point);
            }
            Ok(due)
        }

        fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
            self.run.save(ckpt)?;
            Ok(ckpt.put_json(CURVE, &self.curve)?)
        }

        fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
            self.run.load(ckpt)?;
            self.curve = ckpt.get_json(CURVE)?;
            Ok(())
        }

        fn finish(self, _wall_seconds: f64) -> Result<Vec<TestedPoint>> {
            Ok(self.curve)
        }
    }

    pub(super) fn train(
        cost: ReacherCost,
        cfg: &ReacherDdpg,
        test: &TestSet,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Vec<TestedPoint>> {
        let task = ReacherTask::new(cost).map_err(AlgoError::Config)?;
        // The scene is read once: the training environment, the loop's (unused) evaluation
        // environment and the test rollouts step copies of one plant.
        let plant = reacher_plant()?;
        let make = || -> Result<Box<dyn Env>> {
            let env = PlantEnv::from_parts(plant.clone(), task.clone())?;
            Ok(Box::new(TimeLimit::new(env, REACHER_HORIZON)))
        };
        let settings = TrainSettings {
            eval_interval: 0,
            checkpoint_interval: cfg.eval_every,
            max_episode_steps: Some(REACHER_HORIZON),
            ..TrainSettings::default()
        };
        let agent = AlgoConfig::Ddpg(cfg.agent.clone());
        let run = ModelFree::new(agent, settings, make()?, make()?, cfg.steps, seed)?;
        let run = ReacherRun {
            run,
            system: PlantModel::new(plant),
            test,
            seed,
            curve: Vec::new(),
        };
        drive(run, store, progress)
    }
}

#[cfg(not(feature = "mujoco"))]
mod ddpg {
    use tandem_robots::p4::ReacherCost;

    use super::super::mdgps::TestSet;
    use super::super::{AlgoError, Checkpoints, Result};
    use super::{ReacherDdpg, TestedPoint};

    pub(super) fn train(
        _cost: ReacherCost,
        _cfg: &ReacherDdpg,
        _test: &TestSet,
        _seed: u64,
        _store: &mut dyn Checkpoints,
        _progress: &mut dyn FnMut(u64),
    ) -> Result<Vec<TestedPoint>> {
        Err(AlgoError::Config(
            "p4's reacher needs a build with `--features mujoco` after scripts/setup-mujoco.sh"
                .into(),
        ))
    }
}

#[cfg(all(test, feature = "mujoco"))]
mod tests {
    use super::*;
    use ndarray::{s, Array2};
    use tandem_core::seeding::rng_from_seed;
    use tandem_models::ModelInput;
    use tandem_robots::p4::{
        pusher_features, DoorKinematics, DoorWaypoints, DOOR_ACTION_DIM, DOOR_ANGLE,
        DOOR_FEATURES_DIM, DOOR_HORIZON, DOOR_STATE_DIM, PUSHER_FEATURES_DIM,
    };

    /// The states of `steps` of fixed pseudo-random actions (the same for every problem) from
    /// every condition's start: `steps + 1` arrays of one row per condition.
    fn roll(p: &LocalProblem, steps: usize, scale: f64) -> Vec<Array2<f64>> {
        let (n, m) = (p.system.state_dim(), p.system.action_dim());
        let k = p.conditions.len();
        let mut x = Array2::zeros((k, n));
        for (i, c) in p.conditions.iter().enumerate() {
            x.row_mut(i)
                .iter_mut()
                .zip(&c.x0)
                .for_each(|(d, v)| *d = *v);
        }
        let mut out = vec![x.clone()];
        let mut rng = rng_from_seed(0);
        for t in 0..steps {
            let u = Array2::from_shape_fn((k, m), |(i, j)| {
                scale * ((1 + i + 2 * j + 3 * t) as f64 * 0.7).sin()
            });
            x = p
                .system
                .predict(&ModelInput::new(x.view(), u.view()), &mut rng)
                .unwrap()
                .next_states;
            out.push(x.clone());
        }
        out
    }

    /// The pusher with features: its base part is the plain pusher's under the same actions,
    /// bit for bit, the features are the gripper point and velocity of it, and the costs are
    /// the plain objective's.
    #[test]
    fn pusher_features_extend_the_state_only() {
        let plain = pusher_problem(PusherCost::default()).unwrap();
        let with = pusher_problem(PusherCost {
            end_effector_features: true,
            ..PusherCost::default()
        })
        .unwrap();
        let n = PUSHER_STATE_DIM;
        assert_eq!(with.system.state_dim(), n + PUSHER_FEATURES_DIM);
        let (a, b) = (roll(&plain, 12, 3.0), roll(&with, 12, 3.0));
        let mut f = [0.0; PUSHER_FEATURES_DIM];
        for (t, (xa, xb)) in a.iter().zip(&b).enumerate() {
            assert_eq!(xa, &xb.slice(s![.., ..n]), "step {t}");
            for (c, row) in xb.rows().into_iter().enumerate() {
                let x = row.to_vec();
                pusher_features(&x[..n], &mut f);
                assert_eq!(&x[n..], &f, "step {t}, condition {c}");
                let (oa, ob) = (
                    &plain.conditions[c].objective,
                    &with.conditions[c].objective,
                );
                assert_eq!(
                    oa.running_cost(&x[..n], &[0.1; 4], t).unwrap(),
                    ob.running_cost(&x, &[0.1; 4], t).unwrap()
                );
                assert_eq!(
                    oa.terminal_cost(&x[..n]).unwrap(),
                    ob.terminal_cost(&x).unwrap()
                );
            }
        }
        // At the start the arm rests stretched: the gripper at (1.05, 0), still.
        let x0 = &with.conditions[0].x0;
        assert!((x0[n] - 1.05).abs() < 1e-15 && x0[n + 1].abs() < 1e-15);
        assert_eq!(&x0[n + 2..], &[0.0, 0.0]);
    }

    /// The door with features: the base part is the plain door's under the same actions; the
    /// features are the hook and grasp points (their difference the cost's offset) and their
    /// velocities, which equal the points' Jacobian (by per-coordinate central differences)
    /// times the joint velocities.
    #[test]
    fn door_features_are_the_kinematics() {
        let plain = door_problem(DoorCost::default()).unwrap();
        let with = door_problem(DoorCost {
            end_effector_features: true,
            ..DoorCost::default()
        })
        .unwrap();
        let n = DOOR_STATE_DIM;
        assert_eq!(with.system.state_dim(), n + DOOR_FEATURES_DIM);
        let kin = DoorKinematics::load().unwrap();
        let (a, b) = (roll(&plain, 8, 0.8), roll(&with, 8, 0.8));
        for (t, (xa, xb)) in a.iter().zip(&b).enumerate() {
            assert_eq!(xa, &xb.slice(s![.., ..n]), "step {t}");
            for row in xb.rows() {
                let x = row.to_vec();
                let f = &x[n..];
                let r = kin.offset(&x).unwrap();
                for i in 0..3 {
                    assert!((f[i] - f[3 + i] - r[i]).abs() < 1e-12);
                }
                let eps = 1e-6;
                let mut vel = [0.0; 6];
                for j in 0..=DOOR_ANGLE {
                    let (mut qp, mut qm) = (x[..=DOOR_ANGLE].to_vec(), x[..=DOOR_ANGLE].to_vec());
                    qp[j] += eps;
                    qm[j] -= eps;
                    let (pp, pm) = (kin.points(&qp).unwrap(), kin.points(&qm).unwrap());
                    for k in 0..2 {
                        for i in 0..3 {
                            vel[3 * k + i] +=
                                (pp[k][i] - pm[k][i]) / (2.0 * eps) * x[DOOR_ANGLE + 1 + j];
                        }
                    }
                }
                for i in 0..6 {
                    assert!(
                        (f[6 + i] - vel[i]).abs() < 1e-6 * (1.0 + vel[i].abs()),
                        "step {t}, velocity {i}: {} vs {}",
                        f[6 + i],
                        vel[i]
                    );
                }
            }
        }
        // Some steps moved: the test saw velocities.
        assert!(b[8].slice(s![.., n + 6..]).iter().any(|v| v.abs() > 1e-3));
    }

    /// The door's test starts: the same for a seed and others for another; each a state of the
    /// problem (with its end-effector features), the door closed and the arm at rest, none a
    /// training start; the hook between the training starts: its offset from the grasp point
    /// within the box their offsets span across and above the handle (2 cm of slack for the
    /// kinematics' curvature), and in front of the grasp point (over 1000 starts: 0.04–0.28 m in
    /// front, where the training starts are 0.1–0.3 m; 0.20–0.29 m above it, the starts
    /// 0.2–0.3 m); and the arm rests there touching nothing: a step of zero commands (the arm is
    /// gravity-compensated) moves no joint by 10⁻³ rad and leaves the door shut.
    #[test]
    fn door_test_starts_lie_between_the_training_starts() {
        let cost = DoorCost {
            end_effector_features: true,
            ..DoorCost::default()
        };
        let test = door_test_set(24, 7, &cost).unwrap();
        assert_eq!(test.starts, door_test_set(24, 7, &cost).unwrap().starts);
        assert_ne!(test.starts, door_test_set(24, 8, &cost).unwrap().starts);
        let problem = door_problem(cost).unwrap();
        let kin = DoorKinematics::load().unwrap();
        let trained: Vec<[f64; 3]> = problem
            .conditions
            .iter()
            .map(|c| kin.offset(&c.x0).unwrap())
            .collect();
        let n = problem.system.state_dim();
        let mut f = [0.0; DOOR_FEATURES_DIM];
        for x in &test.starts {
            assert_eq!(x.len(), n);
            assert!(problem.conditions.iter().all(|c| {
                c.x0[..6]
                    .iter()
                    .zip(&x[..6])
                    .any(|(a, b)| (a - b).abs() > 1e-3)
            }));
            assert!(x[DOOR_ANGLE..DOOR_STATE_DIM].iter().all(|v| *v == 0.0));
            kin.features(x, &mut f).unwrap();
            assert_eq!(&x[DOOR_STATE_DIM..], &f);
            let r = kin.offset(x).unwrap();
            for i in 0..3 {
                let lo = trained.iter().map(|o| o[i]).fold(f64::INFINITY, f64::min);
                let hi = trained
                    .iter()
                    .map(|o| o[i])
                    .fold(f64::NEG_INFINITY, f64::max);
                // Towards the door (x) the hull reaches closer than the starts: in front of the
                // grasp point, not behind the bar.
                let hi = if i == 0 { 0.0 } else { hi + 0.02 };
                assert!(
                    r[i] > lo - 0.02 && r[i] < hi,
                    "offset {r:?} outside the training starts' {lo}..{hi} in {i}"
                );
            }
        }
        let x = Array2::from_shape_vec((test.starts.len(), n), test.starts.concat()).unwrap();
        let u = Array2::zeros((test.starts.len(), DOOR_ACTION_DIM));
        let next = problem
            .system
            .predict(&ModelInput::new(x.view(), u.view()), &mut rng_from_seed(0))
            .unwrap()
            .next_states;
        for (a, b) in x.rows().into_iter().zip(next.rows()) {
            for j in 0..6 {
                assert!(
                    (a[j] - b[j]).abs() < 1e-3,
                    "joint {j}: {} to {}",
                    a[j],
                    b[j]
                );
            }
            assert!(
                b[DOOR_ANGLE].abs() < 1e-6,
                "the door moved to {}",
                b[DOOR_ANGLE]
            );
        }
        // The test's measure is the final angle, and a start is opened from 0.8 rad.
        let mut end = test.starts[0].clone();
        end[DOOR_ANGLE] = 0.9;
        assert_eq!((test.measure)(&end), 0.9);
        let (mean, opened) = test.summary(&[0.79, 0.8, 1.1, 0.0]);
        assert!((mean - 2.69 / 4.0).abs() < 1e-12, "{mean}");
        assert_eq!(opened, Some(0.5));
    }

    /// MDGPS with PILQR runs on the door with its features and the policy's observation (two
    /// iterations of two trajectories per start, a small policy, three test starts): a point per
    /// iteration, the test angle finite and within the hinge's range, the fraction opened a
    /// fraction of three.
    #[test]
    fn mdgps_runs_on_the_door() {
        use crate::gps::{LocalConfig, LocalMethod};
        use crate::mdgps::{
            train_mdgps, FirstIteration, Linearization, MdgpsConfig, PolicyConfig, PolicyFitConfig,
        };
        let cost = DoorCost {
            end_effector_features: true,
            ..DoorCost::default()
        };
        let problem = door_problem(cost).unwrap();
        let test = door_test_set(3, 1, &cost).unwrap();
        // Small mixtures for the dynamics' and the policy's priors: a smoke test, not a fit.
        let prior = Some(tandem_models::GmmPriorConfig {
            max_clusters: 2,
            ..Default::default()
        });
        let mut local = LocalConfig {
            iterations: 2,
            samples: 2,
            init_variance: 0.05,
            ..LocalConfig::default()
        };
        local.dynamics.prior = prior.clone();
        let cfg = MdgpsConfig {
            local,
            policy: PolicyConfig {
                hidden: vec![8],
                epochs: 2,
                ..PolicyConfig::default()
            },
            step: Default::default(),
            linearization: Linearization::Regression(PolicyFitConfig {
                prior,
                ..Default::default()
            }),
            first_iteration: FirstIteration::CatchUp,
        };
        let run = train_mdgps(
            LocalMethod::Pilqr,
            &problem,
            &test,
            &cfg,
            0,
            &mut crate::Ephemeral,
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(run.curve.len(), 2);
        for (i, p) in run.curve.iter().enumerate() {
            assert_eq!(p.samples, 8 * (i as u64 + 1));
            assert!((-1e-3..1.58).contains(&p.test_measure), "{p:?}");
            let opened = p.test_solved.unwrap() * 3.0;
            assert!((opened - opened.round()).abs() < 1e-12, "{p:?}");
            assert!(
                p.local_measure.is_finite() && p.policy_loss.is_finite(),
                "{p:?}"
            );
        }
    }

    /// With the ramp and the waypoints, the door's expansion is the cost's: its value, its
    /// gradient against central differences of the cost in the state (both waypoint phases),
    /// and the angle term's curvature `2 w_angle ((t+1)/T)²`.
    #[test]
    fn door_expansion_with_ramp_and_waypoints() {
        let cost = DoorCost {
            angle_ramp: true,
            waypoints: DoorWaypoints::authors(),
            angle: 5.0,
            ..DoorCost::default()
        };
        let kin = DoorKinematics::load().unwrap();
        let obj = door::objective(&kin, cost);
        let no_angle = door::objective(&kin, DoorCost { angle: 0.0, ..cost });
        let mut x = tandem_robots::p4::door_initial_state(2);
        x[DOOR_ANGLE] = 0.3;
        x[8] = 0.2;
        let u = [0.1, -0.2, 0.0, 0.3, 0.0, 0.1];
        for t in [3, 24, 25, 70, DOOR_HORIZON - 1] {
            let q = obj.running_quadratic(&x, &u, t).unwrap();
            let c = obj.running_cost(&x, &u, t).unwrap();
            assert!((q.c - c).abs() < 1e-12 * c, "t {t}: {} vs {c}", q.c);
            let eps = 1e-6;
            for i in 0..DOOR_STATE_DIM {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[i] += eps;
                xm[i] -= eps;
                let fd = (obj.running_cost(&xp, &u, t).unwrap()
                    - obj.running_cost(&xm, &u, t).unwrap())
                    / (2.0 * eps);
                assert!(
                    (fd - q.cx[i]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "t {t}, d/dx{i}: {fd} vs {}",
                    q.cx[i]
                );
            }
            let q0 = no_angle.running_quadratic(&x, &u, t).unwrap();
            let ramp = ((t + 1) as f64 / DOOR_HORIZON as f64).powi(2);
            let curv = q.cxx[(DOOR_ANGLE, DOOR_ANGLE)] - q0.cxx[(DOOR_ANGLE, DOOR_ANGLE)];
            assert!((curv - 2.0 * 5.0 * ramp).abs() < 1e-12, "t {t}: {curv}");
        }
        let (qt, c) = (
            obj.terminal_quadratic(&x).unwrap(),
            obj.terminal_cost(&x).unwrap(),
        );
        assert!((qt.c - c).abs() < 1e-12 * c, "{} vs {c}", qt.c);
    }
}
