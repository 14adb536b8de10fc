//! MuJoCo itself (feature `mujoco`): [`Scene`] (a loaded MJCF model), [`MujocoEnv`] (gymnasium's
//! v5 tasks, or any scene, as an [`Env`]) and [`MujocoPlant`] (any scene as a [`Plant`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mujoco_rs::mujoco_c::{mjVERSION_HEADER, mj_version};
use mujoco_rs::prelude::{MjData, MjModel, MjtObjBase, MjtWarning};
use nalgebra::DVector;
use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::Plant;
use tandem_envs::{check_state, Env, EnvError, Step};

use crate::task::{Outcome, Readout, TaskKind};
use crate::MujocoError;

type Data = MjData<Arc<MjModel>>;

/// A loaded MJCF model: immutable, shared by the environments and plants made from it.
#[derive(Clone)]
pub struct Scene {
    model: Arc<MjModel>,
    path: PathBuf,
}

impl fmt::Debug for Scene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Scene")
            .field("path", &self.path)
            .field("nq", &self.nq())
            .field("nv", &self.nv())
            .field("nu", &self.nu())
            .finish()
    }
}

impl Scene {
    /// Loads the MJCF file at `path` (relative includes and meshes resolve from its folder).
    ///
    /// Errors: the linked library is not MuJoCo 3.17.0, the file is missing, larger than
    /// [`tandem_core::MAX_INPUT_BYTES`] (64 MiB, as URDF files; checked by reading at most one
    /// byte more, so `/dev/zero` is refused quickly) or malformed, or the model has actuator
    /// activations (`na > 0`; tandem's state is `qpos ++ qvel`).
    pub fn from_xml(path: impl AsRef<Path>) -> Result<Self, MujocoError> {
        let path = path.as_ref();
        check_library()?;
        let shown = path.display().to_string();
        if shown.contains('\0') {
            return Err(MujocoError::Load {
                path: path.to_path_buf(),
                message: "the path contains a NUL character".into(),
            });
        }
        // MuJoCo reads the file itself (includes resolve from its folder); this bounded read
        // only refuses what is too large, before MuJoCo would read all of it.
        tandem_core::read_file_capped(path, tandem_core::MAX_INPUT_BYTES).map_err(|e| {
            MujocoError::Load {
                path: path.to_path_buf(),
                message: e.to_string(),
            }
        })?;
        if !path.is_file() {
            return Err(MujocoError::Load {
                path: path.to_path_buf(),
                message: "not a regular file".into(),
            });
        }
        let model = MjModel::from_xml(path).map_err(|e| MujocoError::Load {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        if model.ffi().na > 0 {
            return Err(MujocoError::Load {
                path: path.to_path_buf(),
                message: format!(
                    "{} actuator activation states (na > 0) are not supported: tandem's state is \
                     qpos ++ qvel",
                    model.ffi().na
                ),
            });
        }
        Ok(Self {
            model: Arc::new(model),
            path: path.to_path_buf(),
        })
    }

    /// The file it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Position coordinates.
    pub fn nq(&self) -> usize {
        self.model.ffi().nq as usize
    }

    /// Velocity coordinates.
    pub fn nv(&self) -> usize {
        self.model.ffi().nv as usize
    }

    /// Actuators.
    pub fn nu(&self) -> usize {
        self.model.ffi().nu as usize
    }

    /// Bodies, the world included.
    pub fn nbody(&self) -> usize {
        self.model.ffi().nbody as usize
    }

    /// The simulation timestep in seconds (one `mj_step`).
    pub fn timestep(&self) -> f64 {
        self.model.opt().timestep
    }

    /// The model's default pose `qpos0`.
    pub fn qpos0(&self) -> &[f64] {
        self.model.qpos0()
    }

    /// The id of body `name`.
    pub fn body_id(&self, name: &str) -> Result<usize, MujocoError> {
        self.model
            .name_to_id(MjtObjBase::mjOBJ_BODY, name)
            .ok_or_else(|| MujocoError::Model {
                path: self.path.clone(),
                message: format!("no body named `{name}`"),
            })
    }

    /// The action box: each actuator's ctrlrange, or unbounded where the control is not limited.
    pub fn action_space(&self) -> Space {
        let (mut low, mut high) = (Vec::new(), Vec::new());
        let limited = self.model.actuator_ctrllimited();
        for (i, r) in self.model.actuator_ctrlrange().iter().enumerate() {
            // MuJoCo's ctrllimited is "auto" by default: limited when a range is given.
            if limited[i] && r[0] < r[1] {
                low.push(r[0]);
                high.push(r[1]);
            } else {
                low.push(f64::NEG_INFINITY);
                high.push(f64::INFINITY);
            }
        }
        Space::boxed(low, high)
    }

    /// The id of site `name`.
    pub fn site_id(&self, name: &str) -> Result<usize, MujocoError> {
        self.model
            .name_to_id(MjtObjBase::mjOBJ_SITE, name)
            .ok_or_else(|| MujocoError::Model {
                path: self.path.clone(),
                message: format!("no site named `{name}`"),
            })
    }

    /// The world positions of the sites `ids` (from [`Scene::site_id`]) at joint positions
    /// `qpos`: MuJoCo's forward kinematics (`mj_kinematics`), for costs on end-effector points.
    ///
    /// Errors: `qpos` is not `nq` long or not finite, or an id is out of range.
    pub fn site_positions(
        &self,
        qpos: &[f64],
        ids: &[usize],
    ) -> Result<Vec<[f64; 3]>, MujocoError> {
        let bad = |message: String| MujocoError::Model {
            path: self.path.clone(),
            message,
        };
        if qpos.len() != self.nq() {
            return Err(bad(format!(
                "qpos has {} entries, the model {}",
                qpos.len(),
                self.nq()
            )));
        }
        if let Some(i) = qpos.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!("qpos[{i}] = {} is not finite", qpos[i])));
        }
        let nsite = self.model.ffi().nsite as usize;
        if let Some(id) = ids.iter().find(|&&id| id >= nsite) {
            return Err(bad(format!(
                "site id {id} out of range (the model has {nsite})"
            )));
        }
        let mut data = self.new_data();
        data.qpos_mut().copy_from_slice(qpos);
        data.kinematics();
        let xpos = data.site_xpos();
        Ok(ids.iter().map(|&id| xpos[id]).collect())
    }

    fn new_data(&self) -> Data {
        MjData::new(self.model.clone())
    }
}

/// Checks that the linked library is the MuJoCo version mujoco-rs was written for (mujoco-rs
/// itself panics on a mismatch).
fn check_library() -> Result<(), MujocoError> {
    // SAFETY: `mj_version` only returns a constant of the loaded library.
    let linked = unsafe { mj_version() } as u32;
    if linked != mjVERSION_HEADER {
        return Err(MujocoError::Version {
            linked,
            expected: mjVERSION_HEADER,
        });
    }
    Ok(())
}

/// Sets `data` to `(qpos, qvel)` as gymnasium's `set_state` after `mj_resetData`: everything else
/// back to the model's defaults, then `mj_forward` (which fills `xpos` for the first step).
fn load_state(data: &mut Data, qpos: &[f64], qvel: &[f64]) {
    data.reset();
    data.qpos_mut().copy_from_slice(qpos);
    data.qvel_mut().copy_from_slice(qvel);
    data.forward();
}

/// The warnings after which a step's result is not the model's physics, with the quantity
/// each concerns. MuJoCo counts them in `mjData.warning`, prints a line and carries on:
/// - `BADQPOS`, `BADQVEL`, `BADQACC`: a NaN or a value beyond ±1e10 (`mjMAXVAL`); MuJoCo then
///   resets the simulation (`mj_resetData`), so the step returns the model's default state.
/// - `BADCTRL`: a NaN or a value beyond ±1e10 in the `ctrl` of an actuator without ctrlrange
///   (an `f32` action of 1e300 is infinite; a limited actuator's is clamped first, correctly);
///   MuJoCo zeroes `ctrl`, so the step would run with no control at all.
/// - `CONTACTFULL`, `CNSTRFULL`: the arena is full, so contacts or constraints were dropped and
///   bodies may pass through each other.
///
/// `INERTIA` (a (near) singular mass matrix) is not among them: MuJoCo regularizes the pivot and
/// the step goes on finite; it marks a degenerate model (a massless chain), not a bad state.
const FATAL_WARNINGS: [(MjtWarning, &str); 6] = [
    (MjtWarning::mjWARN_BADQPOS, "qpos"),
    (MjtWarning::mjWARN_BADQVEL, "qvel"),
    (MjtWarning::mjWARN_BADQACC, "qacc"),
    (MjtWarning::mjWARN_BADCTRL, "ctrl"),
    (MjtWarning::mjWARN_CONTACTFULL, "contacts"),
    (MjtWarning::mjWARN_CNSTRFULL, "constraints"),
];

/// Runs `mj_step` `substeps` times, failing at the first substep after which MuJoCo raised one
/// of the [`FATAL_WARNINGS`].
///
/// The counters are zeroed before each substep rather than compared: the reset that follows a
/// bad state zeroes them itself before counting the warning, so a count could stay the same.
fn step_checked(data: &mut Data, substeps: usize) -> Result<(), MujocoError> {
    for substep in 0..substeps {
        let time = data.time();
        {
            let warnings = data.warning_mut();
            for (w, _) in FATAL_WARNINGS {
                warnings[w as usize].number = 0;
            }
        }
        data.step();
        let warnings = data.warning();
        if let Some((w, quantity)) = FATAL_WARNINGS
            .into_iter()
            .find(|(w, _)| warnings[*w as usize].number > 0)
        {
            let index = warnings[w as usize].lastinfo;
            let problem = match w {
                MjtWarning::mjWARN_CONTACTFULL | MjtWarning::mjWARN_CNSTRFULL => format!(
                    "too many {quantity} for MuJoCo's arena (some were dropped; raise the MJCF's \
                     <size memory>)"
                ),
                _ => format!(
                    "a bad {quantity}: {quantity}[{index}] is NaN or beyond ±1e10 (MuJoCo {})",
                    if w == MjtWarning::mjWARN_BADCTRL {
                        "zeroes ctrl"
                    } else {
                        "resets the simulation"
                    }
                ),
            };
            return Err(MujocoError::Step {
                quantity,
                problem,
                substep: substep + 1,
                substeps,
                time,
            });
        }
    }
    Ok(())
}

/// Where an environment is in its episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    NotReset,
    Running,
    Ended,
    /// A step failed (MuJoCo flagged its result, see [`step_checked`]).
    Failed,
}

/// A MuJoCo scene as an environment with gymnasium's semantics: one of gymnasium's v5 tasks
/// ([`MujocoEnv::task`]), exact to gymnasium 1.4.0 on MuJoCo 3.17.0, or any MJCF scene without a
/// task ([`MujocoEnv::scene`]).
///
/// The state ([`Env::state`], [`Env::set_state`]) is `qpos ++ qvel`. Each step sets
/// `ctrl` to the action rounded to `float32` (gymnasium's action dtype), runs `mj_step`
/// `frame_skip` times, then `mj_rnePostConstraint` (contact forces), as gymnasium's `MujocoEnv`.
/// Actions are not clipped: MuJoCo clamps `ctrl` into ctrlrange, and the control cost uses the
/// action as given. A step after which MuJoCo raised a warning that makes its result wrong (a
/// bad `qpos`, `qvel`, `qacc` or `ctrl`, which MuJoCo answers by resetting the simulation or
/// zeroing `ctrl`; full contact or constraint buffers) is an [`EnvError::Simulation`] naming the
/// quantity and the substep, and the environment then needs a reset.
/// A base environment does not truncate; [`crate::make`] adds the task's
/// [`tandem_envs::TimeLimit`]. The reward terms of the last step (gymnasium's `info`) are in
/// [`MujocoEnv::last_outcome`].
pub struct MujocoEnv {
    id: String,
    task: Option<TaskKind>,
    scene: Scene,
    data: Data,
    frame_skip: usize,
    body_ids: Vec<usize>,
    init_qpos: Vec<f64>,
    init_qvel: Vec<f64>,
    observation_space: Space,
    action_space: Space,
    phase: Phase,
    rng: Rng,
    action: Vec<f32>,
    ctrl: Vec<f64>,
    before_qpos: Vec<f64>,
    before_bodies: Vec<[f64; 3]>,
    after_bodies: Vec<[f64; 3]>,
    observation: Vec<f64>,
    last: Option<Outcome>,
}

impl fmt::Debug for MujocoEnv {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MujocoEnv")
            .field("id", &self.id)
            .field("scene", &self.scene)
            .field("frame_skip", &self.frame_skip)
            .finish_non_exhaustive()
    }
}

impl MujocoEnv {
    /// gymnasium's `kind` task over its MJCF file from `assets` (gymnasium's asset folder, e.g.
    /// [`crate::assets_dir`]). Checks that the model has the task's dimensions and timestep.
    pub fn task(kind: TaskKind, assets: &Path) -> Result<Self, MujocoError> {
        let spec = kind.spec();
        let scene = Scene::from_xml(assets.join(spec.xml))?;
        let found = (
            scene.nq(),
            scene.nv(),
            scene.nu(),
            scene.nbody(),
            scene.timestep(),
        );
        let expected = (spec.nq, spec.nv, spec.nu, spec.nbody, spec.timestep);
        if found != expected {
            return Err(MujocoError::Model {
                path: scene.path.clone(),
                message: format!(
                    "{} expects (nq, nv, nu, nbody, timestep) = {expected:?}, the file has \
                     {found:?}",
                    spec.id
                ),
            });
        }
        let body_ids = spec
            .bodies
            .iter()
            .map(|b| scene.body_id(b))
            .collect::<Result<Vec<_>, _>>()?;
        let action_space = Space::symmetric(spec.nu, spec.action_bound);
        if scene.action_space() != action_space {
            return Err(MujocoError::Model {
                path: scene.path.clone(),
                message: format!("{} expects actuator ranges ±{}", spec.id, spec.action_bound),
            });
        }
        let mut env = Self::build(scene, spec.id.to_string(), spec.frame_skip, body_ids);
        env.task = Some(kind);
        env.observation_space = Space::unbounded(spec.obs_dim);
        env.action_space = action_space;
        Ok(env)
    }

    /// Any scene without a task: observation `qpos ++ qvel`, reward 0, never terminated, resets to
    /// `qpos0` and zero velocity, `frame_skip` MuJoCo steps per environment step. Its id is
    /// `mjcf:<file name>`.
    pub fn scene(scene: Scene, frame_skip: usize) -> Result<Self, MujocoError> {
        if frame_skip == 0 {
            return Err(MujocoError::Model {
                path: scene.path.clone(),
                message: "frame_skip must be at least 1".into(),
            });
        }
        let name = scene
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(Self::build(
            scene,
            format!("mjcf:{name}"),
            frame_skip,
            Vec::new(),
        ))
    }

    fn build(scene: Scene, id: String, frame_skip: usize, body_ids: Vec<usize>) -> Self {
        let (nq, nv, nu) = (scene.nq(), scene.nv(), scene.nu());
        let nb = body_ids.len();
        Self {
            id,
            task: None,
            data: scene.new_data(),
            frame_skip,
            body_ids,
            init_qpos: scene.qpos0().to_vec(),
            init_qvel: vec![0.0; nv],
            observation_space: Space::unbounded(nq + nv),
            action_space: scene.action_space(),
            phase: Phase::NotReset,
            rng: rng_from_seed(0),
            action: vec![0.0; nu],
            ctrl: vec![0.0; nu],
            before_qpos: vec![0.0; nq],
            before_bodies: vec![[0.0; 3]; nb],
            after_bodies: vec![[0.0; 3]; nb],
            observation: Vec::new(),
            last: None,
            scene,
        }
    }

    /// The task, if this environment is one of gymnasium's.
    pub fn task_kind(&self) -> Option<TaskKind> {
        self.task
    }

    /// The scene it simulates.
    pub fn scene_ref(&self) -> &Scene {
        &self.scene
    }

    /// Seconds per environment step: `timestep · frame_skip`.
    pub fn dt(&self) -> f64 {
        self.scene.timestep() * self.frame_skip as f64
    }

    /// Reward, termination and reward terms (gymnasium's `info`) of the last step; `None` before
    /// the first step of an episode.
    pub fn last_outcome(&self) -> Option<&Outcome> {
        self.last.as_ref()
    }

    /// A plant over the same scene and frame skip (for planners and models).
    pub fn plant(&self) -> MujocoPlant {
        MujocoPlant::new(self.scene.clone(), self.frame_skip).expect("frame_skip is at least 1")
    }

    fn read_bodies(data: &Data, ids: &[usize], out: &mut [[f64; 3]]) {
        let xpos = data.xpos();
        for (o, &id) in out.iter_mut().zip(ids) {
            *o = xpos[id];
        }
    }

    fn observe(&mut self) -> Vec<f64> {
        Self::read_bodies(&self.data, &self.body_ids, &mut self.after_bodies);
        match self.task {
            Some(kind) => {
                let r = Readout {
                    qpos: self.data.qpos(),
                    qvel: self.data.qvel(),
                    bodies: &self.after_bodies,
                    cfrc_ext: self.data.cfrc_ext(),
                };
                kind.observe(&r, &mut self.observation);
            }
            None => {
                self.observation.clear();
                self.observation.extend_from_slice(self.data.qpos());
                self.observation.extend_from_slice(self.data.qvel());
            }
        }
        self.observation.clone()
    }

    fn start(&mut self, qpos: &[f64], qvel: &[f64]) -> Vec<f64> {
        load_state(&mut self.data, qpos, qvel);
        self.phase = Phase::Running;
        self.last = None;
        self.observe()
    }
}

impl Env for MujocoEnv {
    fn id(&self) -> &str {
        &self.id
    }

    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = rng_from_seed(s);
        }
        let (qpos, qvel) = match self.task {
            Some(kind) => kind.reset_state(&self.init_qpos, &self.init_qvel, &mut self.rng),
            None => (self.init_qpos.clone(), self.init_qvel.clone()),
        };
        self.start(&qpos, &qvel)
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        match self.phase {
            Phase::Running => {}
            Phase::NotReset | Phase::Ended | Phase::Failed => {
                return Err(EnvError::NeedsReset {
                    env: self.id.clone(),
                    when: match self.phase {
                        Phase::NotReset => "before reset",
                        Phase::Ended => "after the episode ended",
                        _ => "after a failed step",
                    },
                })
            }
        }
        self.action_space
            .check(action)
            .map_err(|source| EnvError::InvalidAction {
                env: self.id.clone(),
                source,
            })?;
        let Action::Continuous(a) = action else {
            unreachable!("a box space accepts only continuous actions")
        };
        for ((a32, c), &v) in self.action.iter_mut().zip(&mut self.ctrl).zip(a) {
            *a32 = v as f32;
            *c = *a32 as f64;
        }
        self.before_qpos.copy_from_slice(self.data.qpos());
        Self::read_bodies(&self.data, &self.body_ids, &mut self.before_bodies);
        self.data.ctrl_mut().copy_from_slice(&self.ctrl);
        if let Err(e) = step_checked(&mut self.data, self.frame_skip) {
            self.phase = Phase::Failed;
            return Err(EnvError::Simulation {
                env: self.id.clone(),
                reason: e.to_string(),
            });
        }
        self.data.rne_post_constraint();
        let observation = self.observe();
        let (reward, terminated) = match self.task {
            Some(kind) => {
                let before = Readout {
                    qpos: &self.before_qpos,
                    qvel: &[],
                    bodies: &self.before_bodies,
                    cfrc_ext: &[],
                };
                let after = Readout {
                    qpos: self.data.qpos(),
                    qvel: self.data.qvel(),
                    bodies: &self.after_bodies,
                    cfrc_ext: self.data.cfrc_ext(),
                };
                let o = kind.outcome(&before, &after, &self.action, &self.init_qpos);
                self.last = Some(o);
                (o.reward, o.terminated)
            }
            None => (0.0, false),
        };
        if terminated {
            self.phase = Phase::Ended;
        }
        Ok(Step {
            observation,
            reward,
            terminated,
            truncated: false,
        })
    }

    fn state(&self) -> Vec<f64> {
        let mut s = self.data.qpos().to_vec();
        s.extend_from_slice(self.data.qvel());
        s
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        let nq = self.scene.nq();
        check_state(&self.id, state, nq + self.scene.nv())?;
        Ok(self.start(&state[..nq], &state[nq..]))
    }
}

/// A MuJoCo scene as a [`Plant`]: state `qpos ++ qvel`, action `ctrl`, one step = `frame_skip`
/// calls of `mj_step`, so planners (CEM, DMD-MPC, iLQR and the TVLG methods through
/// `tandem_models::PlantModel`) run on MuJoCo scenes.
///
/// [`Plant::step`] is a pure function of `(x, u)`: each call starts from `mj_resetData` (no
/// solver warm start, time 0), sets the state and steps. A step MuJoCo flags (see
/// [`MujocoEnv`]: a bad `qpos`, `qvel`, `qacc` or `ctrl`, full buffers) gives an all-NaN next
/// state through the [`Plant`] trait, which has no error channel (`tandem_models::PlantModel`
/// refuses it as non-finite); [`MujocoPlant::try_step_into`] and [`MujocoPlant::step_batch`]
/// return the error itself. An environment keeps its warm start from
/// step to step, so where contacts are active a plant step can differ from an environment step
/// in the solver's last digits. Scratch `mjData` are pooled, so one plant serves many threads.
/// [`Plant::linearize`] is the trait's central differences.
///
/// ```no_run
/// use nalgebra::DVector;
/// use tandem_dynamics::Plant;
/// use tandem_mujoco::{MujocoPlant, Scene};
///
/// let scene = Scene::from_xml("crates/mujoco/tests/scenes/slider.xml").unwrap();
/// let plant = MujocoPlant::new(scene, 1).unwrap();
/// let x = DVector::zeros(plant.state_dim());
/// let (a, b) = plant.linearize(&x, &DVector::zeros(plant.action_dim()));
/// assert_eq!(a.ncols(), plant.state_dim());
/// assert_eq!(b.ncols(), plant.action_dim());
/// ```
pub struct MujocoPlant {
    scene: Scene,
    frame_skip: usize,
    pool: Mutex<Vec<Data>>,
}

impl fmt::Debug for MujocoPlant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MujocoPlant")
            .field("scene", &self.scene)
            .field("frame_skip", &self.frame_skip)
            .finish_non_exhaustive()
    }
}

impl Clone for MujocoPlant {
    fn clone(&self) -> Self {
        Self {
            scene: self.scene.clone(),
            frame_skip: self.frame_skip,
            pool: Mutex::new(Vec::new()),
        }
    }
}

impl MujocoPlant {
    /// The plant of `scene` with `frame_skip` MuJoCo steps per plant step (at least 1).
    pub fn new(scene: Scene, frame_skip: usize) -> Result<Self, MujocoError> {
        if frame_skip == 0 {
            return Err(MujocoError::Model {
                path: scene.path.clone(),
                message: "frame_skip must be at least 1".into(),
            });
        }
        Ok(Self {
            scene,
            frame_skip,
            pool: Mutex::new(Vec::new()),
        })
    }

    /// Loads `path` (see [`Scene::from_xml`]) as a plant.
    pub fn from_xml(path: impl AsRef<Path>, frame_skip: usize) -> Result<Self, MujocoError> {
        Self::new(Scene::from_xml(path)?, frame_skip)
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Steps a batch: row `i` of `states` (`b × state_dim`, row-major) under row `i` of `actions`
    /// (`b × action_dim`) into row `i` of `next`, reusing one scratch `mjData`.
    ///
    /// Errors: the first row whose step MuJoCo flags ([`MujocoError::Step`], see
    /// [`MujocoPlant::try_step_into`]); the rows after it are not stepped.
    ///
    /// # Panics
    /// If the slice lengths are not multiples of the dimensions with equal row counts (callers
    /// check at their boundary, see [`tandem_dynamics::check_dims`]).
    pub fn step_batch(
        &self,
        states: &[f64],
        actions: &[f64],
        next: &mut [f64],
    ) -> Result<(), MujocoError> {
        let (n, m) = (self.state_dim(), self.action_dim());
        let rows = states.len() / n.max(1);
        assert!(
            states.len() == rows * n && actions.len() == rows * m && next.len() == rows * n,
            "step_batch: {} states, {} actions, {} outputs for dims ({n}, {m})",
            states.len(),
            actions.len(),
            next.len()
        );
        let mut data = self.take();
        let result = (0..rows).try_for_each(|i| {
            self.step_with(
                &mut data,
                &states[i * n..(i + 1) * n],
                &actions[i * m..(i + 1) * m],
                &mut next[i * n..(i + 1) * n],
            )
        });
        self.give(data);
        result
    }

    /// [`Plant::step_into`] with MuJoCo's verdict: an error ([`MujocoError::Step`]) where MuJoCo
    /// flagged a substep (a bad `qpos`, `qvel`, `qacc` or `ctrl`, full contact or constraint
    /// buffers), instead of the state MuJoCo reset to. `next` is then unspecified.
    ///
    /// # Panics
    /// If `x`, `u` or `next` do not have the plant's dimensions.
    pub fn try_step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) -> Result<(), MujocoError> {
        let mut data = self.take();
        let result = self.step_with(&mut data, x, u, next);
        self.give(data);
        result
    }

    fn take(&self) -> Data {
        let popped = self.pool.lock().map(|mut p| p.pop()).unwrap_or(None);
        popped.unwrap_or_else(|| self.scene.new_data())
    }

    fn give(&self, data: Data) {
        if let Ok(mut p) = self.pool.lock() {
            p.push(data);
        }
    }

    fn step_with(
        &self,
        data: &mut Data,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), MujocoError> {
        let nq = self.scene.nq();
        data.reset();
        data.qpos_mut().copy_from_slice(&x[..nq]);
        data.qvel_mut().copy_from_slice(&x[nq..]);
        data.ctrl_mut().copy_from_slice(u);
        step_checked(data, self.frame_skip)?;
        next[..nq].copy_from_slice(data.qpos());
        next[nq..].copy_from_slice(data.qvel());
        Ok(())
    }
}

impl Plant for MujocoPlant {
    fn state_dim(&self) -> usize {
        self.scene.nq() + self.scene.nv()
    }

    fn action_dim(&self) -> usize {
        self.scene.nu()
    }

    fn dt(&self) -> f64 {
        self.scene.timestep() * self.frame_skip as f64
    }

    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let mut next = DVector::zeros(self.state_dim());
        self.step_into(x.as_slice(), u.as_slice(), next.as_mut_slice());
        next
    }

    fn step_into(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        if self.try_step_into(x, u, next).is_err() {
            // The trait has no error channel; NaN is refused by every finiteness check
            // downstream, where MuJoCo's reset state would pass as a real one.
            next.fill(f64::NAN);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(name: &str) -> Scene {
        let path = format!("{}/tests/scenes/{name}", env!("CARGO_MANIFEST_DIR"));
        Scene::from_xml(path).unwrap()
    }

    /// The quantity of a failed plant step from `x` under `u`, or `None` when it succeeds.
    fn failure(plant: &MujocoPlant, x: &[f64], u: &[f64]) -> Option<&'static str> {
        let mut next = vec![0.0; plant.state_dim()];
        match plant.try_step_into(x, u, &mut next) {
            Ok(()) => None,
            Err(MujocoError::Step { quantity, .. }) => Some(quantity),
            Err(e) => panic!("unexpected error {e}"),
        }
    }

    #[test]
    fn a_normal_step_succeeds_and_a_blown_up_one_is_an_error_naming_the_quantity() {
        let plant = MujocoPlant::new(scene("pendulum.xml"), 2).unwrap();
        assert_eq!(failure(&plant, &[0.1, 0.0], &[1.0]), None);
        // A torque of 1e10 accelerates the bob beyond 1e10 rad/s²: MuJoCo would reset.
        assert_eq!(failure(&plant, &[0.1, 0.0], &[1e10]), Some("qacc"));
        assert_eq!(failure(&plant, &[0.1, 1e12], &[0.0]), Some("qvel"));
        assert_eq!(failure(&plant, &[1e12, 0.0], &[0.0]), Some("qpos"));
        // 1e300 is infinite in f32: MuJoCo would zero the unlimited motor's ctrl...
        assert_eq!(failure(&plant, &[0.1, 0.0], &[1e300]), Some("ctrl"));
        // ...and clamps a limited one into ctrlrange first (the slider's ±4 N on 2 kg), which is
        // the right answer, not an error.
        let slider = MujocoPlant::new(scene("slider.xml"), 1).unwrap();
        let mut next = [0.0; 2];
        slider
            .try_step_into(&[0.0, 0.0], &[1e300], &mut next)
            .unwrap();
        assert!((next[0] - 0.01 * 0.02).abs() < 1e-15 && (next[1] - 0.02).abs() < 1e-15);
        // Through the trait, which has no error channel: NaN, never MuJoCo's reset state.
        let next = plant.step(
            &DVector::from_vec(vec![0.1, 0.0]),
            &DVector::from_vec(vec![1e10]),
        );
        assert!(next.iter().all(|v| v.is_nan()), "{next}");
        let mut batch = vec![0.0; 4];
        let err = plant
            .step_batch(&[0.1, 0.0, 0.1, 0.0], &[1.0, 1e10], &mut batch)
            .unwrap_err();
        assert!(err.to_string().contains("qacc[0]"), "{err}");
    }

    #[test]
    fn an_environment_step_that_blows_up_is_an_error_and_needs_a_reset() {
        let mut env = MujocoEnv::scene(scene("pendulum.xml"), 3).unwrap();
        env.set_state(&[0.1, 0.0]).unwrap();
        env.step(&Action::Continuous(vec![1.0])).unwrap();
        let err = env.step(&Action::Continuous(vec![1e10])).unwrap_err();
        assert!(matches!(err, EnvError::Simulation { .. }), "{err:?}");
        let text = err.to_string();
        assert!(
            text.contains("qacc[0]")
                && text.contains("substep 1 of 3")
                && text.contains("t = 0.03"),
            "{text}"
        );
        let again = env.step(&Action::Continuous(vec![0.0])).unwrap_err();
        assert!(again.to_string().contains("after a failed step"), "{again}");
        env.reset(None);
        env.step(&Action::Continuous(vec![0.0])).unwrap();
    }
}
