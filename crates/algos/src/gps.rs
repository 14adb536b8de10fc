//! Guided policy search's outer loop for local controllers (p4 §II–III): one time-varying
//! linear-Gaussian controller per condition (an initial state with its own cost), improved from
//! its own samples by LQR-FLM, PI² or PILQR, with exact sample counting across conditions.
//!
//! Each iteration, for every condition in turn: draw `samples` trajectories of the condition's
//! controller on the system (real samples: they are counted and they are the only rollouts the
//! loop makes), record their mean cost and the task's measure of their final states (e.g. the
//! block–goal distance), then update the controller from them:
//!
//! | method | update |
//! |---|---|
//! | `lqr_flm` | fit TVLG dynamics to the samples (GMM prior over this condition's recent samples), quadratize the cost around them, LQR-FLM under the KL bound `ε·m` with GPS's step rule for LQR-FLM (`m` from predicted vs actual improvement, [`classic_step_mult`]) |
//! | `pi2` | PI² on the samples' costs-to-go (the authors' `TrajOptPI2` settings, [`Pilqr::default_pi2`]) |
//! | `pilqr` | the same fit and quadratization, then PILQR: LQR-FLM with per-step bounds from the residual ratio, PI² on the residual costs-to-go ([`Pilqr`]) |
//!
//! The curve's point `i` is the controller after `i` updates, measured on its own `samples`
//! trajectories, at `(i + 1)·samples` samples of that condition; the last point is the
//! controller the run ends with. No evaluation episodes are drawn besides.
//!
//! A run is one [`LocalGps`] on the [`drive`]r: it saves itself under its method's name after
//! every iteration (the controllers, their dynamics fits with the GMM prior's data, the step
//! rules' state, the generator, the curves) and resumes from there with exactly the numbers of an
//! uninterrupted run.

use ndarray::s;
use serde::{Deserialize, Serialize};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
use tandem_models::{DynamicsModel, TvlgConfig, TvlgDynamics, TvlgFit};
use tandem_nn::budget::MemoryEstimate;
use tandem_nn::Checkpoint;
use tandem_planners::{
    classic_step_mult, pi2_update, quadratize_cost, sample_trajectories, InitLqr, LqrFlm,
    Objective, Pilqr, PilqrConfig, QuadraticCost, SampleConfig, TrajectorySamples, TvlgController,
};

use super::{AlgoError, Checkpoints, Result};
use crate::driver::{drive, Algorithm};

/// How a local controller is updated from its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LocalMethod {
    /// LQR-FLM (p4 §II-A) with GPS's step rule for it.
    LqrFlm,
    /// PI² (p4 §II-B).
    Pi2,
    /// PILQR (p4 §III).
    Pilqr,
}

impl LocalMethod {
    /// All three, in p4's order.
    pub const ALL: [LocalMethod; 3] = [LocalMethod::LqrFlm, LocalMethod::Pi2, LocalMethod::Pilqr];

    /// The key in records and tables: `lqr_flm`, `pi2`, `pilqr`.
    pub fn name(self) -> &'static str {
        match self {
            LocalMethod::LqrFlm => "lqr_flm",
            LocalMethod::Pi2 => "pi2",
            LocalMethod::Pilqr => "pilqr",
        }
    }

    /// The method named `name` ([`LocalMethod::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// Settings of the local-controller loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalConfig {
    /// Iterations (sample batches) per condition; the samples per condition are
    /// `iterations · samples`.
    pub iterations: usize,
    /// Trajectories per iteration and condition.
    pub samples: usize,
    /// Variance of the initial controller's actions (`K = 0`, `k = 0`, `Σ = variance · I`) with
    /// [`InitController::Zero`]; unused by [`InitController::Lqr`], which has its own. MDGPS
    /// also starts its global policy's variance from it.
    pub init_variance: f64,
    /// The initial controller of every condition: [`InitController::Zero`] (the default, and
    /// what a configuration without the key reads) or GPS's LQR one.
    #[serde(default, skip_serializing_if = "InitController::is_zero")]
    pub init: InitController,
    /// The trajectory optimizers' settings, shared by the three methods where they have the part:
    /// LQR-FLM (`trajopt.lqr`, whose `kl_step` is the base bound `ε` per time step, alone and in
    /// PILQR), PI² (`trajopt.pi2`, alone and in PILQR) and PILQR's step rule.
    pub trajopt: PilqrConfig,
    /// The TVLG dynamics fit of LQR-FLM and PILQR.
    pub dynamics: TvlgConfig,
}

impl Default for LocalConfig {
    /// p4's sample budget (20 iterations of 20 trajectories: 400 per condition), variance 1,
    /// `ε = 1` ([`PilqrConfig::default`]: the authors' PI² and PILQR settings), GPS's dynamics fit
    /// with its GMM prior.
    fn default() -> Self {
        Self {
            iterations: 20,
            samples: 20,
            init_variance: 1.0,
            init: InitController::Zero,
            trajopt: PilqrConfig::default(),
            dynamics: TvlgConfig::default(),
        }
    }
}

impl LocalConfig {
    /// Checks the settings the loop relies on.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(AlgoError::Config(m));
        if self.iterations == 0 || self.samples < 2 {
            return bad(format!(
                "iterations {} must be >= 1 and samples {} >= 2",
                self.iterations, self.samples
            ));
        }
        for (name, v) in [
            ("init_variance", self.init_variance),
            ("trajopt.lqr.kl_step", self.trajopt.lqr.kl_step),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{name} = {v} must be finite and > 0"));
            }
        }
        if let InitController::Lqr(lqr) = &self.init {
            lqr.validate()
                .map_err(|e| AlgoError::Config(format!("init.lqr: {e}")))?;
        }
        self.trajopt
            .validate()
            .map_err(|e| AlgoError::Config(format!("trajopt: {e}")))?;
        self.dynamics
            .validate()
            .map_err(|e| AlgoError::Config(format!("dynamics: {e}")))
    }

    /// The memory of the loop on `conditions` conditions of `horizon` steps with
    /// `state_dim`-dimensional states and `act_dim`-dimensional actions, in `f64`: each
    /// iteration's samples, and per condition the controller, the previous one and the fitted
    /// dynamics with their covariances, the prior's kept trajectories, and the learning curve.
    pub fn memory(
        &self,
        conditions: usize,
        horizon: usize,
        state_dim: usize,
        act_dim: usize,
    ) -> MemoryEstimate {
        let xu = state_dim.saturating_add(act_dim);
        let per_step = xu.saturating_mul(xu).saturating_mul(4);
        let kept = self.dynamics.prior.as_ref().map_or(0, |p| p.max_samples);
        MemoryEstimate::new()
            .f32s(
                "samples (conditions x samples x horizon)",
                &[2, conditions, self.samples, horizon, xu],
            )
            .f32s(
                "controllers and fitted dynamics (conditions x horizon)",
                &[2, conditions, horizon, per_step],
            )
            .f32s(
                "dynamics prior's trajectories (conditions x max_samples)",
                &[2, conditions, kept, horizon, xu],
            )
            .f32s(
                "learning curve (conditions x iterations)",
                &[4, conditions, self.iterations],
            )
    }
}

/// How the local controllers start.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitController {
    /// `K = 0`, `k = 0`, `Σ = init_variance · I`: zero mean actions and exploration alike in
    /// every action.
    #[default]
    Zero,
    /// GPS's `init_lqr` (the authors' p4 experiments start from it): the LQR controller that
    /// holds the condition's initial state on guessed double-integrator dynamics, `Σ` its
    /// `Q_uu⁻¹` ([`TvlgController::init_lqr`]).
    Lqr(InitLqr),
}

impl InitController {
    /// Whether it is [`InitController::Zero`] (which configurations leave out).
    pub fn is_zero(&self) -> bool {
        *self == InitController::Zero
    }
}

/// One condition: where trajectories start and what they pay.
pub struct Condition {
    /// The initial state.
    pub x0: Vec<f64>,
    /// The cost (running, with the time index, and terminal).
    pub objective: Objective,
}

/// The task's figure of a trajectory's end: `measure(condition, final_state)`, e.g. the
/// block–goal distance.
pub type Measure = Box<dyn Fn(usize, &[f64]) -> f64 + Send + Sync>;

/// What the local controllers are trained on.
pub struct LocalProblem {
    /// The system the samples come from (a plant, or any model).
    pub system: Box<dyn DynamicsModel + Send + Sync>,
    /// The conditions.
    pub conditions: Vec<Condition>,
    /// Control steps per trajectory.
    pub horizon: usize,
    /// The task's measure of a final state.
    pub measure: Measure,
    /// What a neural policy for the task sees of a state (MDGPS's global policy); `None`: the
    /// state itself. The local controllers always act on the state.
    pub policy_input: Option<tandem_agents::PolicyInput>,
}

/// One point of a condition's curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalPoint {
    /// Samples of this condition so far (including this batch).
    pub samples: u64,
    /// Mean total cost of the batch.
    pub mean_cost: f64,
    /// Mean of the task's measure of the batch's final states.
    pub measure: f64,
}

/// What a run of [`train_local`] leaves.
#[derive(Debug, Clone)]
pub struct LocalRun {
    /// Per condition, one point per iteration.
    pub curves: Vec<Vec<LocalPoint>>,
    /// Per condition, updates that failed numerically (the controller was kept).
    pub failed_updates: Vec<usize>,
    /// The controllers after the last update.
    pub controllers: Vec<TvlgController>,
    /// Wall time of the run, seconds, summed over every process that ran it.
    pub wall_seconds: f64,
}

/// The previous LQR-FLM iteration, for GPS's step rule.
#[derive(Clone, Serialize, Deserialize)]
struct LqrState {
    mult: f64,
    prev: Option<(TvlgController, TvlgDynamics, Vec<QuadraticCost>)>,
}

/// One condition's controller and the state of its optimizers (shared with MDGPS).
pub(crate) struct Local {
    /// The current controller.
    pub(crate) controller: TvlgController,
    fit: TvlgFit,
    lqr: LqrState,
    pilqr: Pilqr,
}

impl Local {
    /// The initial controller of a condition starting at `x0` (`cfg.init`: `K = 0`, `k = 0`,
    /// `Σ = init_variance · I`, or GPS's LQR controller holding `x0`) and fresh optimizers.
    pub(crate) fn new(horizon: usize, x0: &[f64], m: usize, cfg: &LocalConfig) -> Result<Self> {
        let controller = match &cfg.init {
            InitController::Zero => {
                TvlgController::constant(horizon, x0.len(), &vec![0.0; m], cfg.init_variance)?
            }
            InitController::Lqr(lqr) => TvlgController::init_lqr(lqr, x0, m, horizon)
                .map_err(|e| AlgoError::Config(format!("init.lqr: {e}")))?,
        };
        Ok(Self {
            controller,
            fit: TvlgFit::new(cfg.dynamics.clone()),
            lqr: LqrState {
                mult: 1.0,
                prev: None,
            },
            pilqr: Pilqr::new(cfg.trajopt.clone())?,
        })
    }

    /// `cfg.samples` trajectories of the controller on `system` from `cond`'s start, with its
    /// costs.
    pub(crate) fn sample(
        &self,
        system: &dyn DynamicsModel,
        cond: &Condition,
        cfg: &LocalConfig,
        rng: &mut tandem_core::Rng,
    ) -> Result<TrajectorySamples> {
        let scfg = SampleConfig {
            samples: cfg.samples,
            ..SampleConfig::default()
        };
        Ok(sample_trajectories(
            &self.controller,
            system,
            &cond.objective,
            &cond.x0,
            &scfg,
            rng,
        )?)
    }

    /// Updates the controller from its `samples` with `method` (LQR-FLM with GPS's step rule). A
    /// numerical failure of the fit or of the optimizer keeps the controller and returns `false`.
    pub(crate) fn improve(
        &mut self,
        method: LocalMethod,
        samples: &TrajectorySamples,
        objective: &Objective,
        lqr: &LqrFlm,
        cfg: &LocalConfig,
    ) -> Result<bool> {
        let next = numerical(self.next(method, samples, objective, lqr, cfg))?;
        Ok(self.replace(next))
    }

    /// The dynamics fitted to `samples` (GMM prior over this condition's recent samples) and the
    /// objective's quadratic expansion around them. A numerical failure is `None`.
    pub(crate) fn model(
        &mut self,
        samples: &TrajectorySamples,
        objective: &Objective,
    ) -> Result<Option<LocalModel>> {
        numerical(self.fit_model(samples, objective))
    }

    /// [`Local::model`] with failures as errors.
    fn fit_model(
        &mut self,
        samples: &TrajectorySamples,
        objective: &Objective,
    ) -> Result<LocalModel> {
        let dynamics = self
            .fit
            .fit(samples.states.view(), samples.actions.view())?;
        Ok((dynamics, quadratize_cost(objective, samples)?))
    }

    /// MDGPS's update of the controller from its `samples` and their `model`: LQR-FLM under
    /// `E[KL(p ‖ anchor)] ≤ kl_step` (or the configured `ε` when `None`), or PILQR whose LQR-FLM
    /// stage takes its bounds against `anchor`. Not for PI², which has no anchor. A numerical
    /// failure keeps the controller and returns `false`.
    pub(crate) fn improve_anchored(
        &mut self,
        method: LocalMethod,
        samples: &TrajectorySamples,
        (dynamics, cost): &LocalModel,
        lqr: &LqrFlm,
        anchor: &TvlgController,
        kl_step: Option<f64>,
    ) -> Result<bool> {
        let next = numerical(match method {
            LocalMethod::Pilqr => self
                .pilqr
                .update_anchored(&self.controller, anchor, samples, dynamics, cost)
                .map(|s| s.controller)
                .map_err(AlgoError::from),
            LocalMethod::LqrFlm => lqr
                .update(anchor, dynamics, cost, kl_step)
                .map(|s| s.controller)
                .map_err(AlgoError::from),
            LocalMethod::Pi2 => Err(AlgoError::Config(
                "PI² takes no anchor: its update reweights its own samples".into(),
            )),
        })?;
        Ok(self.replace(next))
    }

    /// What a checkpoint keeps of it: all but the optimizers' settings, which the run is given.
    fn saved(&self) -> SavedLocal {
        SavedLocal {
            controller: self.controller.clone(),
            fit: self.fit.clone(),
            lqr: self.lqr.clone(),
            pilqr_mult: self.pilqr.step_mult().to_vec(),
        }
    }

    /// Restores what [`Local::saved`] returned.
    fn restore(&mut self, s: SavedLocal) {
        (self.controller, self.fit, self.lqr) = (s.controller, s.fit, s.lqr);
        self.pilqr.set_step_mult(s.pilqr_mult);
    }

    /// Takes `next` if there is one; whether it was taken.
    fn replace(&mut self, next: Option<TvlgController>) -> bool {
        match next {
            Some(c) => {
                self.controller = c;
                true
            }
            None => false,
        }
    }

    fn next(
        &mut self,
        method: LocalMethod,
        samples: &TrajectorySamples,
        objective: &Objective,
        lqr: &LqrFlm,
        cfg: &LocalConfig,
    ) -> Result<TvlgController> {
        if method == LocalMethod::Pi2 {
            let s = pi2_update(
                &self.controller,
                &samples.states,
                &samples.actions,
                &samples.cost_to_go(),
                &cfg.trajopt.pi2,
            )?;
            return Ok(s.controller);
        }
        let (dynamics, cost) = self.fit_model(samples, objective)?;
        if method == LocalMethod::Pilqr {
            return Ok(self
                .pilqr
                .update_with_cost(&self.controller, samples, &dynamics, &cost)?
                .controller);
        }
        if let Some((pc, pd, pq)) = &self.lqr.prev {
            self.lqr.mult = classic_step_mult(
                self.lqr.mult,
                pc,
                pd,
                pq,
                &self.controller,
                &dynamics,
                &cost,
            )?;
        }
        let next = lqr.update(
            &self.controller,
            &dynamics,
            &cost,
            Some(cfg.trajopt.lqr.kl_step * self.lqr.mult),
        )?;
        self.lqr.prev = Some((self.controller.clone(), dynamics, cost));
        Ok(next.controller)
    }
}

/// A [`Local`] in a checkpoint.
#[derive(Serialize, Deserialize)]
struct SavedLocal {
    controller: TvlgController,
    fit: TvlgFit,
    lqr: LqrState,
    /// PILQR's per-step multipliers.
    pilqr_mult: Vec<f64>,
}

/// Saves the local controllers and their optimizers' state under `key` (shared with MDGPS).
pub(crate) fn save_locals(locals: &[Local], key: &str, ckpt: &mut Checkpoint) -> Result<()> {
    let saved: Vec<SavedLocal> = locals.iter().map(Local::saved).collect();
    Ok(ckpt.put_json(key, &saved)?)
}

/// Restores what [`save_locals`] wrote into `locals` (one per condition).
pub(crate) fn load_locals(locals: &mut [Local], key: &str, ckpt: &Checkpoint) -> Result<()> {
    let saved: Vec<SavedLocal> = ckpt.get_json(key)?;
    if saved.len() != locals.len() {
        return Err(AlgoError::Checkpoint(format!(
            "{} local controllers saved, {} conditions",
            saved.len(),
            locals.len()
        )));
    }
    for (l, s) in locals.iter_mut().zip(saved) {
        l.restore(s);
    }
    Ok(())
}

/// The dynamics fitted to a batch of samples and the cost's quadratic expansion around them.
pub(crate) type LocalModel = (TvlgDynamics, Vec<QuadraticCost>);

/// A numerical failure of a fit or an optimizer (`Planner` and `Model` errors) as `None`; other
/// errors pass.
fn numerical<T>(r: Result<T>) -> Result<Option<T>> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(AlgoError::Planner(_) | AlgoError::Model(_)) => Ok(None),
        Err(e) => Err(e),
    }
}

/// Trains one local controller per condition of `problem` with `method`, `seed` drawing all
/// noise, from the checkpoint `store` holds under the method's name if any, saving after every
/// iteration. `progress` is called with the samples drawn so far over all conditions.
pub fn train_local(
    method: LocalMethod,
    problem: &LocalProblem,
    cfg: &LocalConfig,
    seed: u64,
    store: &mut dyn Checkpoints,
    progress: &mut dyn FnMut(u64),
) -> Result<LocalRun> {
    drive(LocalGps::new(method, problem, cfg, seed)?, store, progress)
}

/// A run of the local-controller loop as one checkpointable value, stepped one iteration (all
/// conditions) at a time by [`drive`]: the controllers with their optimizers' state, the
/// generator, the curves and the counts. Its events are the samples drawn so far.
pub struct LocalGps<'a> {
    method: LocalMethod,
    problem: &'a LocalProblem,
    cfg: &'a LocalConfig,
    seed: u64,
    lqr: LqrFlm,
    locals: Vec<Local>,
    s: LocalState,
}

/// Where a [`LocalGps`] run stands, besides its controllers.
#[derive(Serialize, Deserialize)]
struct LocalState {
    /// Iterations done.
    iteration: usize,
    rng: Rng,
    curves: Vec<Vec<LocalPoint>>,
    failed: Vec<usize>,
    drawn: u64,
}

const STATE: &str = "gps.state";
const LOCALS: &str = "gps.locals";

impl<'a> LocalGps<'a> {
    /// A fresh run of `method` on `problem` for `seed`.
    pub fn new(
        method: LocalMethod,
        problem: &'a LocalProblem,
        cfg: &'a LocalConfig,
        seed: u64,
    ) -> Result<Self> {
        cfg.validate()?;
        check_problem(problem)?;
        let (lqr, locals) = start_locals(problem, cfg)?;
        let k = problem.conditions.len();
        Ok(Self {
            method,
            problem,
            cfg,
            seed,
            lqr,
            locals,
            s: LocalState {
                iteration: 0,
                rng: rng_from_seed(seed),
                curves: vec![Vec::new(); k],
                failed: vec![0; k],
                drawn: 0,
            },
        })
    }
}

impl Algorithm for LocalGps<'_> {
    type Event = u64;
    type Record = LocalRun;
    const SUMS_WALL_TIME: bool = true;

    fn id(&self) -> (&str, u64) {
        (self.method.name(), self.seed)
    }

    fn done(&self) -> bool {
        self.s.iteration >= self.cfg.iterations
    }

    /// One iteration: every condition's batch, its point on the curve, and (but after the last
    /// batch) the controller's update.
    fn step(&mut self, progress: &mut dyn FnMut(u64), _stop: &dyn Checkpoints) -> Result<bool> {
        let (problem, cfg, s) = (self.problem, self.cfg, &mut self.s);
        let last = s.iteration + 1 == cfg.iterations;
        for (c, (cond, local)) in problem.conditions.iter().zip(&mut self.locals).enumerate() {
            let samples = local.sample(&*problem.system, cond, cfg, &mut s.rng)?;
            s.drawn += cfg.samples as u64;
            progress(s.drawn);
            s.curves[c].push(point(&samples, (s.iteration + 1) * cfg.samples, |x| {
                (problem.measure)(c, x)
            }));
            if !last && !local.improve(self.method, &samples, &cond.objective, &self.lqr, cfg)? {
                s.failed[c] += 1;
            }
        }
        s.iteration += 1;
        Ok(true)
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        ckpt.put_json(STATE, &self.s)?;
        save_locals(&self.locals, LOCALS, ckpt)
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        self.s = ckpt.get_json(STATE)?;
        load_locals(&mut self.locals, LOCALS, ckpt)
    }

    fn finish(self, wall_seconds: f64) -> Result<LocalRun> {
        Ok(LocalRun {
            curves: self.s.curves,
            failed_updates: self.s.failed,
            controllers: self.locals.into_iter().map(|l| l.controller).collect(),
            wall_seconds,
        })
    }
}

/// What both loops (the local controllers alone, MDGPS) start from: LQR-FLM with the configured
/// settings and one fresh controller per condition of `problem`.
pub(crate) fn start_locals(
    problem: &LocalProblem,
    cfg: &LocalConfig,
) -> Result<(LqrFlm, Vec<Local>)> {
    let m = problem.system.action_dim();
    let locals = problem
        .conditions
        .iter()
        .map(|c| Local::new(problem.horizon, &c.x0, m, cfg))
        .collect::<Result<Vec<_>>>()?;
    Ok((LqrFlm::new(cfg.trajopt.lqr.clone())?, locals))
}

/// Checks that there are conditions, a horizon, and dimensions that fit the system.
pub(crate) fn check_problem(problem: &LocalProblem) -> Result<()> {
    let system = &problem.system;
    if problem.conditions.is_empty() || problem.horizon == 0 {
        return Err(AlgoError::Config(format!(
            "{} conditions and a horizon of {}: both must be at least 1",
            problem.conditions.len(),
            problem.horizon
        )));
    }
    for (i, c) in problem.conditions.iter().enumerate() {
        if c.x0.len() != system.state_dim()
            || c.objective.state_dim() != system.state_dim()
            || c.objective.action_dim() != system.action_dim()
        {
            return Err(AlgoError::Config(format!(
                "condition {i}: initial state of {} and objective of ({}, {}) do not fit a \
                 system of state {} and action {}",
                c.x0.len(),
                c.objective.state_dim(),
                c.objective.action_dim(),
                system.state_dim(),
                system.action_dim()
            )));
        }
    }
    Ok(())
}

/// The batch's mean cost and mean final-state measure.
fn point(samples: &TrajectorySamples, total: usize, measure: impl Fn(&[f64]) -> f64) -> LocalPoint {
    let n = samples.len();
    let t = samples.states.shape()[1] - 1;
    let finals: f64 = (0..n)
        .map(|i| {
            let x = samples.states.slice(s![i, t, ..]).to_vec();
            measure(&x)
        })
        .sum();
    LocalPoint {
        samples: total as u64,
        mean_cost: samples.mean_cost(),
        measure: finals / n as f64,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{Ephemeral, InMemory};
    use nalgebra::{dmatrix, DMatrix, DVector};
    use tandem_dynamics::Plant;
    use tandem_models::PlantModel;

    pub(crate) const DT: f64 = 0.1;
    pub(crate) const T: usize = 15;

    /// A double integrator `x' = A x + B u`.
    pub(crate) struct DoubleIntegrator;
    impl Plant for DoubleIntegrator {
        fn state_dim(&self) -> usize {
            2
        }
        fn action_dim(&self) -> usize {
            1
        }
        fn dt(&self) -> f64 {
            DT
        }
        fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
            &a() * x + &b() * u
        }
    }
    pub(crate) fn a() -> DMatrix<f64> {
        dmatrix![1.0, DT; 0.0, 1.0]
    }
    pub(crate) fn b() -> DMatrix<f64> {
        dmatrix![0.5 * DT * DT; DT]
    }
    const Q: [f64; 2] = [1.0, 0.1];
    const R: f64 = 0.01;
    const QF: [f64; 2] = [10.0, 1.0];

    pub(crate) fn problem(starts: &[[f64; 2]]) -> LocalProblem {
        let conditions = starts
            .iter()
            .map(|x0| Condition {
                x0: x0.to_vec(),
                objective: Objective::new(2, 1, |x, u| {
                    0.5 * (Q[0] * x[0] * x[0] + Q[1] * x[1] * x[1] + R * u[0] * u[0])
                })
                .with_terminal(|x| 0.5 * (QF[0] * x[0] * x[0] + QF[1] * x[1] * x[1])),
            })
            .collect();
        LocalProblem {
            system: Box::new(PlantModel::new(DoubleIntegrator)),
            conditions,
            horizon: T,
            measure: Box::new(|_, x| x[0].abs()),
            policy_input: None,
        }
    }

    /// The optimal cost `½ x0ᵀ P_0 x0` by the finite-horizon Riccati recursion.
    pub(crate) fn riccati_cost(x0: [f64; 2]) -> f64 {
        let (a, b) = (a(), b());
        let q = DMatrix::from_diagonal(&DVector::from_column_slice(&Q));
        let mut p = DMatrix::from_diagonal(&DVector::from_column_slice(&QF));
        for _ in 0..T {
            let k = (dmatrix![R] + b.transpose() * &p * &b)
                .try_inverse()
                .unwrap()
                * b.transpose()
                * &p
                * &a;
            p = &q + a.transpose() * &p * (&a - &b * k);
        }
        let x = DVector::from_column_slice(&x0);
        0.5 * (x.transpose() * p * x)[(0, 0)]
    }

    /// The cost of a controller's mean actions, rolled out on the exact system.
    pub(crate) fn mean_cost(c: &TvlgController, obj: &Objective, x0: [f64; 2]) -> f64 {
        let mut x = DVector::from_column_slice(&x0);
        let mut cost = 0.0;
        for t in 0..T {
            let u = c.mean(t, &x);
            cost += obj.running_cost(x.as_slice(), u.as_slice(), t).unwrap();
            x = &a() * &x + &b() * &u;
        }
        cost + obj.terminal_cost(x.as_slice()).unwrap()
    }

    pub(crate) fn cfg(iterations: usize) -> LocalConfig {
        let mut c = LocalConfig {
            iterations,
            samples: 10,
            init_variance: 1.0,
            ..LocalConfig::default()
        };
        c.dynamics.prior = None;
        c
    }

    /// On a linear system with a quadratic cost, LQR-FLM's fit is exact, and its controller's
    /// mean actions reach the Riccati optimum for every condition.
    #[test]
    fn lqr_flm_reaches_the_riccati_optimum_on_a_linear_system() {
        let starts = [[1.0, 0.0], [-0.5, 1.0]];
        let p = problem(&starts);
        let run = train_local(
            LocalMethod::LqrFlm,
            &p,
            &cfg(8),
            3,
            &mut Ephemeral,
            &mut |_| {},
        )
        .unwrap();
        for (c, x0) in starts.iter().enumerate() {
            let opt = riccati_cost(*x0);
            let got = mean_cost(&run.controllers[c], &p.conditions[c].objective, *x0);
            assert!(
                got <= opt * 1.02 && got >= opt * (1.0 - 1e-9),
                "condition {c}: {got} vs the optimum {opt}"
            );
            assert_eq!(run.failed_updates[c], 0);
        }
    }

    /// Every method lowers the cost; the curve counts samples exactly, per condition, and the
    /// progress reports them over all conditions.
    #[test]
    fn every_method_improves_and_samples_are_counted_exactly() {
        let p = problem(&[[1.0, 0.0], [0.0, -1.0]]);
        let c = cfg(10);
        for method in LocalMethod::ALL {
            let mut seen = Vec::new();
            let run =
                train_local(method, &p, &c, 0, &mut Ephemeral, &mut |n| seen.push(n)).unwrap();
            assert_eq!(seen.len(), 20);
            assert_eq!(*seen.last().unwrap(), 10 * 10 * 2);
            for curve in &run.curves {
                let samples: Vec<u64> = curve.iter().map(|p| p.samples).collect();
                assert_eq!(samples, (1..=10).map(|i| 10 * i).collect::<Vec<u64>>());
                let (first, last) = (curve[0].mean_cost, curve[9].mean_cost);
                assert!(
                    last < 0.7 * first,
                    "{}: mean cost {first} -> {last}",
                    method.name()
                );
            }
            // Equal seeds, equal runs.
            let again = train_local(method, &p, &c, 0, &mut Ephemeral, &mut |_| {}).unwrap();
            assert_eq!(again.curves, run.curves);
        }
    }

    #[test]
    fn a_stop_request_ends_the_run_and_bad_settings_are_named() {
        let p = problem(&[[1.0, 0.0]]);
        let mut store = InMemory::default();
        store.stop_flag().set(true);
        let r = train_local(LocalMethod::Pi2, &p, &cfg(3), 0, &mut store, &mut |_| {});
        assert!(matches!(r, Err(AlgoError::Stopped)));
        let mut bad = cfg(3);
        bad.samples = 1;
        let e = train_local(LocalMethod::Pi2, &p, &bad, 0, &mut Ephemeral, &mut |_| {});
        assert!(e.unwrap_err().to_string().contains("samples"));
        let mut bad = cfg(3);
        bad.init_variance = f64::NAN;
        let e = train_local(LocalMethod::Pi2, &p, &bad, 0, &mut Ephemeral, &mut |_| {});
        assert!(e.unwrap_err().to_string().contains("init_variance"));
        let mut wrong = problem(&[[1.0, 0.0]]);
        wrong.conditions[0].x0 = vec![1.0];
        let e = train_local(
            LocalMethod::Pi2,
            &wrong,
            &cfg(3),
            0,
            &mut Ephemeral,
            &mut |_| {},
        );
        assert!(e.unwrap_err().to_string().contains("condition 0"));
    }

    /// A run stopped after any iteration resumes from its checkpoint, not from its start, and
    /// ends exactly as an uninterrupted one, for every method: the GMM prior's data, LQR-FLM's
    /// step rule, PILQR's multipliers and the generator travel with it. Checkpoints are keyed by
    /// method; one of another seed is refused.
    #[test]
    fn a_run_stopped_after_any_iteration_resumes_to_the_same_record() {
        let p = problem(&[[1.0, 0.0], [-0.5, 1.0]]);
        let mut c = cfg(4);
        c.samples = 6;
        c.dynamics = TvlgConfig::default();
        let batch = (2 * c.samples) as u64;
        for method in LocalMethod::ALL {
            let whole = train_local(method, &p, &c, 7, &mut Ephemeral, &mut |_| {}).unwrap();
            for stop_after in 1..c.iterations as u64 {
                let mut store = InMemory::default();
                let stop = store.stop_flag();
                let e = train_local(method, &p, &c, 7, &mut store, &mut |n| {
                    stop.set(n == stop_after * batch)
                })
                .unwrap_err();
                assert!(matches!(e, AlgoError::Stopped), "{e}");
                assert_eq!(store.saves() as u64, stop_after);
                stop.set(false);
                let mut first = None;
                let resumed = train_local(method, &p, &c, 7, &mut store, &mut |n| {
                    first.get_or_insert(n);
                })
                .unwrap();
                let case = format!("{} stopped after {stop_after}", method.name());
                assert_eq!(first, Some(stop_after * batch + c.samples as u64), "{case}");
                assert_eq!(resumed.curves, whole.curves, "{case}");
                assert_eq!(resumed.failed_updates, whole.failed_updates, "{case}");
                assert_eq!(resumed.controllers, whole.controllers, "{case}");
            }
        }
        let mut store = InMemory::default();
        train_local(LocalMethod::Pi2, &p, &c, 7, &mut store, &mut |_| {}).unwrap();
        let e = train_local(LocalMethod::Pi2, &p, &c, 8, &mut store, &mut |_| {}).unwrap_err();
        assert!(matches!(e, AlgoError::Checkpoint(_)), "{e}");
        assert!(e.to_string().contains("pi2 seed 7"), "{e}");
        let other = train_local(LocalMethod::Pilqr, &p, &c, 8, &mut store, &mut |_| {}).unwrap();
        let fresh = train_local(LocalMethod::Pilqr, &p, &c, 8, &mut Ephemeral, &mut |_| {});
        assert_eq!(other.curves, fresh.unwrap().curves);
    }

    /// A configuration without `init` reads as today's zero controller and is written without
    /// the key; GPS's LQR start reads from TOML, starts every condition at its own `x0`, and
    /// settings that do not fit the system are refused by name before any sample.
    #[test]
    fn the_initial_controller_is_configurable() {
        let plain = toml::to_string(&LocalConfig::default()).unwrap();
        assert!(!plain.contains("init."), "{plain}");
        let back: LocalConfig = toml::from_str(&plain).unwrap();
        assert_eq!(back, LocalConfig::default());
        assert_eq!(back.init, InitController::Zero);
        let with = format!(
            "{plain}\n[init.lqr]\ndt = 0.1\npositions = [0]\nvelocities = [1]\nvariance = 0.5\n"
        );
        let lqr: LocalConfig = toml::from_str(&with).unwrap();
        let InitController::Lqr(init) = &lqr.init else {
            panic!("{:?}", lqr.init)
        };
        assert_eq!(init.variance, 0.5);
        assert_eq!(init.stiffness_vel, 0.5);
        // Written back with the key, read back the same.
        let again: LocalConfig = toml::from_str(&toml::to_string(&lqr).unwrap()).unwrap();
        assert_eq!(again, lqr);

        let starts = [[1.0, 0.0], [-0.5, 0.0]];
        let p = problem(&starts);
        let c = LocalConfig {
            init: lqr.init.clone(),
            ..cfg(2)
        };
        let (_, locals) = start_locals(&p, &c).unwrap();
        for (l, x0) in locals.iter().zip(&starts) {
            let want = TvlgController::init_lqr(init, x0, 1, T).unwrap();
            assert_eq!(l.controller, want);
            // It holds its start.
            assert!(l.controller.mean(0, &DVector::from_column_slice(x0))[0].abs() < 1e-12);
        }
        let run = train_local(LocalMethod::LqrFlm, &p, &c, 0, &mut Ephemeral, &mut |_| {});
        assert_eq!(run.unwrap().failed_updates, vec![0, 0]);

        let bad = |init: InitLqr| {
            let c = LocalConfig {
                init: InitController::Lqr(init),
                ..cfg(2)
            };
            train_local(LocalMethod::Pi2, &p, &c, 0, &mut Ephemeral, &mut |_| {})
                .unwrap_err()
                .to_string()
        };
        let e = bad(InitLqr::new(0.1, vec![0], vec![2]));
        assert!(e.contains("init.lqr") && e.contains("index 2"), "{e}");
        let e = bad(InitLqr {
            variance: -1.0,
            ..init.clone()
        });
        assert!(e.contains("init.lqr") && e.contains("variance"), "{e}");
        let e = bad(InitLqr {
            gains: vec![1.0, 1.0],
            ..init.clone()
        });
        assert!(e.contains("gains"), "{e}");
    }
}
