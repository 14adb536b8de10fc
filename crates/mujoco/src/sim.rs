//! MuJoCo itself (feature `mujoco`): [`Scene`] (a loaded MJCF model), [`MujocoEnv`] (gymnasium's
//! v5 tasks, or any scene, as an [`Env`]) and [`MujocoPlant`] (any scene as a [`Plant`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mujoco_rs::mujoco_c::{mjVERSION_HEADER, mj_version};
use mujoco_rs::prelude::{MjData, MjModel, MjtObjBase};
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
    /// Errors: the linked library is not MuJoCo 3.17.0, the file is missing or malformed, or the
    /// model has actuator activations (`na > 0`; tandem's state is `qpos ++ qvel`).
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
        if !path.is_file() {
            return Err(MujocoError::Load {
                path: path.to_path_buf(),
                message: "no such file".into(),
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

/// Where an environment is in its episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    NotReset,
    Running,
    Ended,
}

/// A MuJoCo scene as an environment with gymnasium's semantics: one of gymnasium's v5 tasks
/// ([`MujocoEnv::task`]), exact to gymnasium 1.4.0 on MuJoCo 3.17.0, or any MJCF scene without a
/// task ([`MujocoEnv::scene`]).
///
/// The state ([`Env::state`], [`Env::set_state`]) is `qpos ++ qvel`. Each step sets
/// `ctrl` to the action rounded to `float32` (gymnasium's action dtype), runs `mj_step`
/// `frame_skip` times, then `mj_rnePostConstraint` (contact forces), as gymnasium's `MujocoEnv`.
/// Actions are not clipped: MuJoCo clamps `ctrl` into ctrlrange, and the control cost uses the
/// action as given. A base environment does not truncate; [`crate::make`] adds the task's
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
            Phase::NotReset | Phase::Ended => {
                return Err(EnvError::NeedsReset {
                    env: self.id.clone(),
                    when: if self.phase == Phase::NotReset {
                        "before reset"
                    } else {
                        "after the episode ended"
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
        for _ in 0..self.frame_skip {
            self.data.step();
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
/// solver warm start, time 0), sets the state and steps. An environment keeps its warm start from
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
    /// # Panics
    /// If the slice lengths are not multiples of the dimensions with equal row counts (callers
    /// check at their boundary, see [`tandem_dynamics::check_dims`]).
    pub fn step_batch(&self, states: &[f64], actions: &[f64], next: &mut [f64]) {
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
        for i in 0..rows {
            self.step_with(
                &mut data,
                &states[i * n..(i + 1) * n],
                &actions[i * m..(i + 1) * m],
                &mut next[i * n..(i + 1) * n],
            );
        }
        self.give(data);
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

    fn step_with(&self, data: &mut Data, x: &[f64], u: &[f64], next: &mut [f64]) {
        let nq = self.scene.nq();
        data.reset();
        data.qpos_mut().copy_from_slice(&x[..nq]);
        data.qvel_mut().copy_from_slice(&x[nq..]);
        data.ctrl_mut().copy_from_slice(u);
        for _ in 0..self.frame_skip {
            data.step();
        }
        next[..nq].copy_from_slice(data.qpos());
        next[nq..].copy_from_slice(data.qvel());
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
        let mut data = self.take();
        self.step_with(&mut data, x, u, next);
        self.give(data);
    }
}
