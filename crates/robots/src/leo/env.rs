//! p0's walking task for the Leo-like biped (§IV-B): walk forwards on the boom, fast and
//! cheaply, without falling.
//!
//! The plant is [`crate::leo`]'s planar biped: torso on a boom (`boom_x`, `boom_z`,
//! `torso_pitch`), six DC-motor leg joints driven by voltages, a PD-held shoulder, ground contact
//! at heels, toes, knees, hip, head and hand; 30 ms control period (1 ms RK4 inside).
//!
//! | | |
//! |---|---|
//! | state | the plant's `[q (10), q̇ (10)]`, joints in [`crate::leo`]'s order: `boom_x`, `boom_z`, `torso_pitch`, hips, knees, ankles (left then right), `shoulder` |
//! | observation | p0's 18 dimensions: the state without the shoulder's angle and velocity, i.e. `[x, z, θ_torso, 6 leg angles, ẋ, ż, θ̇_torso, 6 leg velocities]` (m, rad, m/s, rad/s) |
//! | action | `Box(6)`: the six leg motors' voltages in [`crate::leo::MOTOR_JOINTS`] order, clipped to ±10.7 V |
//! | reward | [`LeoWalkTask::reward`]: `300 Δx − 1.5 − 2 W` per step, `W` the step's electrical work (J), and `−75` on a fall |
//! | start | standing straight with flat feet, at rest (deterministic); [`LeoWalkTask::with_start`] with [`LeoStart::Stepping`] starts mid-step instead |
//! | episode | 667 steps (20 s at 30 ms); terminates on a fall: a knee, the hip, the head or the hand touches the ground |
//!
//! The electrical work of a step is p0's measure `W = T_s Σ_j U_j (U_j − K G φ̇_j) / R` over the
//! six motors (the voltage is held over the step; `φ̇_j` is the mean of the joint's velocity at
//! the start and the end of the step). It is signed: a back-driven motor returns energy.
//! [`LeoWalkTask::gait`] turns a trajectory into p0's walked distance `L` and work per metre `E`.
//!
//! ```
//! use tandem_envs::{Action, Env};
//! use tandem_robots::{LeoEnv, LeoEnvExt, LeoModel};
//!
//! let mut env = LeoEnv::new(LeoModel::Idealized);
//! let obs = env.reset(Some(0));
//! assert_eq!(obs.len(), 18);
//! // Motors off: the biped stands for a moment; each step costs 1.5.
//! let step = env.step(&Action::Continuous(vec![0.0; 6])).unwrap();
//! assert!(!step.terminated && (step.reward + 1.5).abs() < 0.1);
//! assert!(env.step(&Action::Continuous(vec![0.0; 5])).is_err());
//! ```

use super::plant::{leo_plant, leo_true_overrides, standing_state};
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::actuators::{Actuator, DcMotor};
use tandem_dynamics::rigid_plant::{Overrides, RigidBodyPlant, RigidPlantConfig};
use tandem_dynamics::Plant;

use tandem_envs::clip_to;
use tandem_envs::{EnvError, PlantEnv, Task};

/// Episode length: 20 s at p0's sampling period of 30 ms.
pub const LEO_STEPS: usize = 667;

/// Reward per metre of forward motion of the torso (p0: 300 m⁻¹).
pub const LEO_REWARD_PER_METRE: f64 = 300.0;
/// Reward per step (p0: −1.5).
pub const LEO_REWARD_PER_STEP: f64 = -1.5;
/// Reward per joule of electrical work (p0: −2 J⁻¹).
pub const LEO_REWARD_PER_JOULE: f64 = -2.0;
/// Reward of a fall, which ends the episode (p0: −75).
pub const LEO_REWARD_FALL: f64 = -75.0;

/// Which Leo: p0's idealized model or its true system (Table I).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeoModel {
    /// Torso 0.942 kg, no joint friction.
    Idealized,
    /// Torso 1.25 kg, viscous friction 0.03 N m s/rad on every actuated joint.
    True,
}

impl LeoModel {
    /// The plant overrides of this model.
    pub fn overrides(self) -> Overrides {
        match self {
            LeoModel::Idealized => Overrides::default(),
            LeoModel::True => leo_true_overrides(),
        }
    }
}

/// Where a Leo episode starts. Both at rest, the stance foot flat on the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LeoStart {
    /// Standing straight on both feet.
    #[default]
    Standing,
    /// Mid-step, as p0's authors start their walking task: the left leg straight, the right
    /// hip swung 0.82 rad forward and the right knee bent 1.27 rad, the right foot in the air.
    /// With the motors off it topples forwards.
    Stepping,
}

impl LeoStart {
    /// The plant state of this start for the biped `plant` (a [`leo_plant`]); an error if
    /// `plant` lacks a joint the start sets.
    pub fn state(self, plant: &RigidBodyPlant) -> Result<Vec<f64>, EnvError> {
        let model = plant.model();
        let mut x = standing_state(model).as_slice().to_vec();
        if self == LeoStart::Stepping {
            // A positive angle swings the part below the joint backwards.
            for (joint, angle) in [("right_hip", -0.82), ("right_knee", 1.27)] {
                let i = model
                    .joint_index(joint)
                    .ok_or_else(|| EnvError::Unsupported {
                        env: format!("{self:?} start"),
                        reason: format!("the plant has no joint {joint}"),
                    })?;
                x[i] = angle;
            }
        }
        Ok(x)
    }
}

/// How a step's electrical work counts each motor's energy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LeoWork {
    /// p0's measure: `U (U − K G φ̇) / R` per motor, negative when a back-driven motor returns
    /// energy.
    #[default]
    Signed,
    /// Only the energy each motor draws, `max(0, U (U − K G φ̇) / R)`, as p0's authors' code
    /// counts it: braking earns nothing back.
    Positive,
}

/// p0's walked distance and motor work of one episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gait {
    /// Forward displacement of the torso over the episode, `L` (m).
    pub distance: f64,
    /// Electrical work of the six motors over the episode (J).
    pub work: f64,
    /// `E = work / L` (J/m); `None` unless the biped walked forwards.
    pub work_per_metre: Option<f64>,
    /// Whether the episode ended in a fall.
    pub fell: bool,
}

/// The walking task over [`leo_plant`] (see the module docs).
#[derive(Debug, Clone)]
pub struct LeoWalkTask {
    id: String,
    /// Forward kinematics for the fall check.
    plant: RigidBodyPlant,
    dt: f64,
    /// The six motors in action order, with their plant joint index.
    motors: Vec<(usize, DcMotor)>,
    /// Contact points that end the episode when they touch the ground.
    fall_contacts: Vec<usize>,
    start: Vec<f64>,
    work: LeoWork,
    observation_space: Space,
    action_space: Space,
}

/// Plant state indices left out of the observation: the shoulder's angle and velocity.
const SHOULDER: usize = 9;
const NV: usize = 10;

impl LeoWalkTask {
    /// The task over `plant` (a [`leo_plant`]), reported as `id`.
    pub fn new(id: &str, plant: &RigidBodyPlant) -> Result<Self, EnvError> {
        let model = plant.model();
        let bad = |reason: String| EnvError::Unsupported {
            env: id.to_string(),
            reason,
        };
        if model.nv() != NV || plant.action_dim() != 6 {
            return Err(bad(format!(
                "expected the Leo biped (10 joints, 6 motors), got {} joints and {} inputs",
                model.nv(),
                plant.action_dim()
            )));
        }
        // The learned actuators in action order, which must all be DC motors of one voltage
        // limit (the action space's bound).
        let motors: Vec<(usize, DcMotor)> = plant
            .actuators()
            .iter()
            .filter(|(_, a)| a.is_learned())
            .map(|&(j, a)| match a {
                Actuator::Motor(m) => Ok((j, m)),
                other => Err(bad(format!(
                    "joint {j} is driven by {other:?}, not a DC motor"
                ))),
            })
            .collect::<Result<_, _>>()?;
        let voltage_max = motors[0].1.voltage_max;
        if motors.iter().any(|(_, m)| m.voltage_max != voltage_max) {
            return Err(bad("the motors' voltage limits differ".into()));
        }
        let fall_contacts = plant
            .contacts()
            .iter()
            .enumerate()
            .filter(|(_, c)| !(c.name.ends_with("_heel") || c.name.ends_with("_toe")))
            .map(|(i, _)| i)
            .collect();
        let inf = f64::INFINITY;
        Ok(Self {
            id: id.to_string(),
            dt: plant.dt(),
            motors,
            fall_contacts,
            start: standing_state(model).as_slice().to_vec(),
            work: LeoWork::Signed,
            observation_space: Space::boxed(vec![-inf; 18], vec![inf; 18]),
            action_space: Space::symmetric(6, voltage_max),
            plant: plant.clone(),
        })
    }

    /// The same task starting from `start`.
    pub fn with_start(mut self, start: LeoStart) -> Result<Self, EnvError> {
        self.start = start.state(&self.plant)?;
        Ok(self)
    }

    /// The same task counting electrical work as `work` (the default is p0's signed measure).
    pub fn with_work(mut self, work: LeoWork) -> Self {
        self.work = work;
        self
    }

    /// The same task with the voltages clipped to `±volts` instead of the motors' limit (p0's
    /// authors' code bounds them at 8.6 V); an error unless `0 < volts <=` the motors' limit.
    pub fn with_voltage_limit(mut self, volts: f64) -> Result<Self, EnvError> {
        let max = self.motors[0].1.voltage_max;
        if !(volts > 0.0 && volts <= max) {
            return Err(EnvError::Unsupported {
                env: self.id,
                reason: format!("voltage limit {volts} V outside (0, {max}] V"),
            });
        }
        self.action_space = Space::symmetric(6, volts);
        Ok(self)
    }

    /// The motors' electrical work (J) over the step `state --u--> next`:
    /// `T_s Σ_j U_j (U_j − K G φ̇_j) / R`, `φ̇_j` the mean of the start and end velocities
    /// (each term floored at zero under [`LeoWork::Positive`]).
    pub fn electrical_work(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        self.motors
            .iter()
            .zip(u)
            .map(|(&(j, m), &uj)| {
                let kg = m.torque_constant * m.gear;
                let uj = uj.clamp(-m.voltage_max, m.voltage_max);
                let w = 0.5 * (state[NV + j] + next[NV + j]);
                let e = uj * (uj - kg * w) / m.resistance;
                match self.work {
                    LeoWork::Signed => e,
                    LeoWork::Positive => e.max(0.0),
                }
            })
            .sum::<f64>()
            * self.dt
    }

    /// Whether the biped has fallen in `state`: a knee, the hip, the head or the hand is at or
    /// below the ground.
    pub fn fallen(&self, state: &[f64]) -> bool {
        let h = self.plant.contact_heights(state);
        self.fall_contacts.iter().any(|&i| h[i] <= 0.0)
    }

    /// p0's walked distance `L` and work per metre `E` of one episode: `states` from the start
    /// to the last state, `controls` the plant inputs between them.
    pub fn gait(&self, states: &[Vec<f64>], controls: &[Vec<f64>]) -> Gait {
        let distance = match (states.first(), states.last()) {
            (Some(a), Some(b)) => b[0] - a[0],
            _ => 0.0,
        };
        let work = states
            .windows(2)
            .zip(controls)
            .map(|(w, u)| self.electrical_work(&w[0], u, &w[1]))
            .sum::<f64>();
        Gait {
            distance,
            work,
            work_per_metre: (distance > 0.0).then(|| work / distance),
            fell: states.last().is_some_and(|s| self.fallen(s)),
        }
    }
}

impl Task for LeoWalkTask {
    fn id(&self) -> &str {
        &self.id
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        2 * NV
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        clip_to(
            &self.action_space,
            action.as_continuous().unwrap_or(&[0.0; 6]),
        )
    }
    fn initial_state(&self, _rng: &mut Rng) -> Vec<f64> {
        self.start.clone()
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        state
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != SHOULDER && i != NV + SHOULDER)
            .map(|(_, &v)| v)
            .collect()
    }
    /// `300 Δx − 1.5 − 2 W`, and `−75` more when `next` is a fall (p0 §IV-B).
    fn reward(&self, state: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let r = LEO_REWARD_PER_METRE * (next[0] - state[0])
            + LEO_REWARD_PER_STEP
            + LEO_REWARD_PER_JOULE * self.electrical_work(state, u, next);
        if self.fallen(next) {
            r + LEO_REWARD_FALL
        } else {
            r
        }
    }
    fn terminated(&self, next: &[f64]) -> bool {
        self.fallen(next)
    }
    fn max_episode_steps(&self) -> Option<usize> {
        Some(LEO_STEPS)
    }
}

/// The registered Leo environments: p0's walking task over the idealized or the true biped.
pub type LeoEnv = PlantEnv<RigidBodyPlant, LeoWalkTask>;

/// The ids and constructor of [`LeoEnv`]. A trait: the environment is `tandem-envs`'
/// [`PlantEnv`], to which only that crate can add inherent items.
pub trait LeoEnvExt: Sized {
    /// Id of the idealized biped's environment.
    const ID: &'static str = "Leo-v0";
    /// Id of the true biped's environment.
    const ID_TRUE: &'static str = "Leo-true-v0";

    /// The registered id of `model`'s biped ([`Self::ID`] or [`Self::ID_TRUE`]).
    fn id_of(model: LeoModel) -> &'static str {
        match model {
            LeoModel::Idealized => Self::ID,
            LeoModel::True => Self::ID_TRUE,
        }
    }

    /// The walking task over `model`'s biped.
    fn new(model: LeoModel) -> Self;
}

impl LeoEnvExt for LeoEnv {
    fn new(model: LeoModel) -> Self {
        let (plant, task) = leo_parts(model).expect("the registered Leo builds");
        PlantEnv::from_parts(plant, task).expect("the Leo task fits its plant")
    }
}

/// The biped of `model` and the walking task over it, reported under its registered id
/// ([`LeoEnv::id_of`]).
pub fn leo_parts(model: LeoModel) -> Result<(RigidBodyPlant, LeoWalkTask), EnvError> {
    let id = LeoEnv::id_of(model);
    let plant = leo_plant(RigidPlantConfig::default(), &model.overrides()).map_err(|e| {
        EnvError::Unsupported {
            env: id.to_string(),
            reason: e.to_string(),
        }
    })?;
    let task = LeoWalkTask::new(id, &plant)?;
    Ok((plant, task))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::leo::BipedTestPolicy;
    use tandem_dynamics::Plant;
    use tandem_envs::Env;

    /// Runs `policy` for `steps` steps on `model`'s biped; returns states and controls.
    fn rollout(
        model: LeoModel,
        policy: Option<BipedTestPolicy>,
        steps: usize,
    ) -> (LeoWalkTask, RigidBodyPlant, Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let (plant, task) = leo_parts(model).unwrap();
        let mut x = task.initial_state(&mut tandem_core::seeding::rng_from_seed(0));
        let mut states = vec![x.clone()];
        let mut controls = Vec::new();
        for t in 0..steps {
            let xv = nalgebra::DVector::from_column_slice(&x);
            let u: Vec<f64> = match &policy {
                Some(p) => p
                    .act(&plant, t as f64 * plant.dt(), &xv)
                    .as_slice()
                    .to_vec(),
                None => vec![0.0; 6],
            };
            plant.step_in_place(&mut x, &u);
            states.push(x.clone());
            controls.push(u);
            if task.fallen(&x) {
                break;
            }
        }
        (task, plant, states, controls)
    }

    #[test]
    fn observation_drops_the_shoulder_and_keeps_p0s_18_dimensions() {
        let (_, task) = leo_parts(LeoModel::Idealized).unwrap();
        let s: Vec<f64> = (0..20).map(|i| i as f64).collect();
        let o = task.observe(&s);
        assert_eq!(o.len(), 18);
        assert!(!o.contains(&9.0) && !o.contains(&19.0));
        assert_eq!(&o[..9], &s[..9]);
        assert_eq!(&o[9..], &s[10..19]);
    }

    #[test]
    fn electrical_work_is_joule_heat_at_stall_and_signed_when_back_driven() {
        let (_, task) = leo_parts(LeoModel::Idealized).unwrap();
        let m = DcMotor::default();
        let s = vec![0.0; 20];
        // At rest: U² / R per motor for 30 ms.
        let u = [5.0, 0.0, 0.0, 0.0, 0.0, -5.0];
        let w = task.electrical_work(&s, &u, &s);
        approx::assert_relative_eq!(w, 2.0 * 25.0 / m.resistance * 0.03, max_relative = 1e-12);
        // A joint turning faster than the voltage drives it returns energy (negative work).
        let mut fast = s.clone();
        fast[NV + 3] = 10.0; // left hip, the first motor
        let u = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert!(task.electrical_work(&fast, &u, &fast) < 0.0);
        // p0's authors count only the energy drawn: the back-driven motor adds nothing, the
        // stalled one its joule heat.
        let positive = task.clone().with_work(LeoWork::Positive);
        assert_eq!(positive.electrical_work(&fast, &u, &fast), 0.0);
        let u2 = [1.0, 0.0, 0.0, 0.0, 0.0, 5.0];
        approx::assert_relative_eq!(
            positive.electrical_work(&fast, &u2, &fast),
            25.0 / m.resistance * 0.03,
            max_relative = 1e-12
        );
        // The episode sum equals the joule heat plus the mechanical power into the motors.
        let kg = m.torque_constant * m.gear;
        let (uu, wv) = (3.0, 2.0);
        let mut a = s.clone();
        a[NV + 3] = wv;
        let w = task.electrical_work(&a, &[uu, 0.0, 0.0, 0.0, 0.0, 0.0], &a);
        let heat = m.joule_power(uu, wv);
        let mech = m.torque(uu, wv) * wv;
        approx::assert_relative_eq!(w, (heat + mech) * 0.03, max_relative = 1e-12);
        assert!((uu * (uu - kg * wv) / m.resistance * 0.03 - w).abs() < 1e-15);
    }

    #[test]
    fn a_voltage_limit_bounds_the_action_space_and_clips_the_controls() {
        let (_, task) = leo_parts(LeoModel::Idealized).unwrap();
        let limited = task.clone().with_voltage_limit(8.6).unwrap();
        assert_eq!(limited.action_space(), &Space::symmetric(6, 8.6));
        let u = limited.control(&Action::Continuous(vec![10.0, -10.0, 1.0, 0.0, 0.0, 0.0]));
        assert_eq!(u, vec![8.6, -8.6, 1.0, 0.0, 0.0, 0.0]);
        for bad in [0.0, -1.0, 11.0, f64::NAN] {
            let e = task.clone().with_voltage_limit(bad).unwrap_err();
            assert!(e.to_string().contains("voltage limit"), "{e}");
        }
    }

    #[test]
    fn the_hand_written_gait_walks_without_falling_and_its_reward_adds_up() {
        for model in [LeoModel::Idealized, LeoModel::True] {
            let steps = 200;
            let policy = Some(BipedTestPolicy::walk());
            let (task, _, states, controls) = rollout(model, policy, steps);
            assert_eq!(states.len(), steps + 1, "{model:?} fell");
            let g = task.gait(&states, &controls);
            assert!(!g.fell && g.distance > 0.05, "{model:?}: {g:?}");
            // The return is 300 L − 1.5 T − 2 W: the reward's three terms telescope.
            let ret: f64 = states
                .windows(2)
                .zip(&controls)
                .map(|(w, u)| task.reward(&w[0], u, &w[1]))
                .sum();
            let expect = 300.0 * g.distance - 1.5 * steps as f64 - 2.0 * g.work;
            approx::assert_relative_eq!(ret, expect, max_relative = 1e-12);
            assert!(g.work > 0.0 && g.work_per_metre.unwrap() > 0.0);
        }
    }

    #[test]
    fn a_limp_biped_falls_and_the_fall_ends_the_episode_with_its_penalty() {
        let mut env = LeoEnv::new(LeoModel::True);
        env.reset(Some(0));
        let mut last = None;
        for _ in 0..LEO_STEPS {
            let s = env.step(&Action::Continuous(vec![0.0; 6])).unwrap();
            if s.terminated {
                last = Some(s);
                break;
            }
        }
        let s = last.expect("a limp biped falls within 20 s");
        assert!(
            s.reward < LEO_REWARD_FALL + 10.0,
            "fall reward {}",
            s.reward
        );
        let x = env.state();
        assert!(x[1] < crate::leo::HIP_HEIGHT - 0.05);
    }

    #[test]
    fn the_stepping_start_stands_on_the_left_foot_and_left_alone_falls_forwards() {
        let (plant, task) = leo_parts(LeoModel::Idealized).unwrap();
        let standing = task.initial_state(&mut tandem_core::seeding::rng_from_seed(0));
        assert_eq!(standing, LeoStart::Standing.state(&plant).unwrap());
        let task = task.with_start(LeoStart::Stepping).unwrap();
        let x = task.initial_state(&mut tandem_core::seeding::rng_from_seed(0));
        let height = |x: &[f64], name: &str| {
            let i = plant
                .contacts()
                .iter()
                .position(|c| c.name == name)
                .unwrap();
            plant.contact_heights(x)[i]
        };
        // The left foot is where standing puts it, flat; the right one is in the air; nothing
        // else differs from standing.
        for c in ["left_heel", "left_toe"] {
            approx::assert_abs_diff_eq!(height(&x, c), height(&standing, c), epsilon = 1e-12);
        }
        for c in ["right_heel", "right_toe"] {
            assert!(height(&x, c) > 0.02, "{c} at {}", height(&x, c));
        }
        let differ: Vec<usize> = (0..x.len()).filter(|&i| x[i] != standing[i]).collect();
        assert_eq!(differ.len(), 2);
        assert!(!task.fallen(&x));
        // Motors off, the biped topples forwards and the fall ends the episode.
        let mut env = PlantEnv::from_parts(plant.clone(), task.clone()).unwrap();
        env.reset(Some(0));
        let mut fell = false;
        for _ in 0..100 {
            if env
                .step(&Action::Continuous(vec![0.0; 6]))
                .unwrap()
                .terminated
            {
                fell = true;
                break;
            }
        }
        assert!(fell && env.state()[0] > 0.1, "x = {}", env.state()[0]);
    }

    #[test]
    fn the_true_biped_differs_from_the_idealized_one_as_table_i() {
        let (pi, _) = leo_parts(LeoModel::Idealized).unwrap();
        let (pt, _) = leo_parts(LeoModel::True).unwrap();
        let x = standing_state(pi.model());
        // Same posture, different weight: the heavier torso adds (1.25 − 0.942) g to the
        // potential energy's slope in z.
        let mut up = x.clone();
        up[1] += 0.01;
        let de = |p: &RigidBodyPlant| p.energy(up.as_slice()) - p.energy(x.as_slice());
        approx::assert_relative_eq!(
            de(&pt) - de(&pi),
            (1.25 - 0.942) * 9.81 * 0.01,
            max_relative = 1e-3
        );
    }
}
