//! Paper p3 (Mishra et al.): M-DeMoRL, Algorithm 1, against SAC and MBPO on the same loop.
//!
//! M-DeMoRL is [`super::mbpo`]'s loop with its secondary buffer `D_MPC` filled by a DMD-MPC
//! inner loop instead of branched rollouts. Each iteration (Algorithm 1, lines 3–19):
//!
//! - line 4: **the real system is stepped with SAC's action** `u ~ π_θ(x)` (exploring), and the
//!   transition joins `D_ENV`; the MPC's actions never reach the real system (they only make
//!   data);
//! - lines 5–7: the ensemble `f_φ` is fitted on `D_ENV` (every [`MbpoConfig::model_train_freq`]
//!   real steps, as MBPO, whose hyper-parameters p3 takes);
//! - line 8: `D_MPC` is initialized (emptied; [`P3Config::keep_iterations`] `> 1` keeps older
//!   plans, ours);
//! - line 9: `H` and the number of plans from their schedules ([`P3Config::horizon`]: 5 → 15,
//!   §4.1; [`P3Config::transitions_per_epoch`]: up to 10 000 MPC transitions an epoch);
//! - lines 10–15, per plan: `x_{t,0}` drawn uniformly from `D_ENV`; [`DmdMpc`] samples `M = 100`
//!   sequences around SAC's own actions along each sample's model rollout (the shift, eq.
//!   10–12: `u_{t,h} ~ N(π_θ(x_{t,h}), Σ)`, `π_θ` sampled as footnote 2 says), through the
//!   ensemble's elites (each plan keeps one random elite per sample row: PETS's TS∞), costs
//!   `Σ γ^h (−r̂) − γ^H V(x_{t,H})` with the model's mean reward `r̂` and SAC's soft value `V`
//!   (eq. 3, §3 item 2); the mean of the best 10% (eq. 13–14) is the mirror-descent step (eq.
//!   9, step size α); the model rollout of that mean is the plan, and its `H` transitions (up
//!   to the first terminal one, the task says which) join `D_MPC`;
//! - lines 16–18: `G` SAC updates on minibatches of `D_ENV ∪ D_MPC` (MBPO's real ratio).
//!
//! The planner plans in the agent's action space ([`tandem_models::InActions`] turns actions into
//! plant inputs with the task), so SAC's proposals, the MPC's bounds and the `D_MPC` actions are
//! all in the units SAC acts in.
//!
//! [`run`] runs one [`Method`] for one seed; `examples/m_demorl.rs` runs M-DeMoRL on Pendulum-v1.

use std::cell::RefCell;
use std::sync::Arc;

use ndarray::{Array1, Array2, ArrayView2};
use serde::{Deserialize, Serialize};
use tandem_agents::{BatchPolicy, Critic, Mode, OffPolicyLoop, Sac, Store};
use tandem_core::{seeding::rng_from_seed, LinearSchedule, Rng};
use tandem_envs::{Env, EnvError, Task};
use tandem_models::{DynamicsModel, InActions, ProbabilisticEnsemble, Propagation, Transitions};
use tandem_nn::budget::MemoryEstimate;
use tandem_planners::{Bounds, DmdMpc, DmdMpcConfig, Noise, Objective};

use super::dyna::sample_starts;
use super::mbpo::{
    ensemble_of, fitted, observations, run_with, Event, Imagination, Imagine, MbpoConfig, Rollouts,
    RunRecord,
};
use super::{AlgoError, Checkpoints, Problem, Result};

/// One of the three methods p3 compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// SAC alone on the real system.
    Sac,
    /// MBPO: branched model rollouts.
    Mbpo,
    /// M-DeMoRL: DMD-MPC plans.
    MDemorl,
}

impl Method {
    /// All three, in p3's order.
    pub const ALL: [Method; 3] = [Method::Sac, Method::Mbpo, Method::MDemorl];

    /// `"sac"`, `"mbpo"` or `"m_demorl"` (the keys of records and checkpoints).
    pub fn name(self) -> &'static str {
        match self {
            Method::Sac => "sac",
            Method::Mbpo => "mbpo",
            Method::MDemorl => "m_demorl",
        }
    }
}

/// Settings of a p3 comparison: the shared loop (MBPO's settings, which p3 says it takes) and
/// M-DeMoRL's inner loop. `Default` follows p3 §4.1 where it gives a figure and says where a
/// figure is ours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct P3Config {
    /// The loop all three methods run (p3 §4.2: MBPO's hyper-parameters for all). Its `reward`
    /// judges MBPO's rollouts only: the MPC always scores with the model's mean reward (§4.1).
    pub base: MbpoConfig,
    /// DMD-MPC: 100 sampled sequences (§4.1), CEM utility with 10% elites (§4.1, eq. 13),
    /// equally weighted among the elites (eq. 14's "reward weighted mean" read literally weighs
    /// by the cost, which is sign-ambiguous; [`tandem_planners::Utility`] offers the margin
    /// weighting), step size α = 0.8 (ours: p3 gives none), one round per plan. Its `horizon`,
    /// `bounds`, `noise` and `seed` are set by the pipeline.
    pub mpc: DmdMpcConfig,
    /// Standard deviation of the control distribution `Σ^{1/2}` per action component, as a
    /// fraction of the component's half range (ours: 0.3; p3 gives none).
    pub noise_fraction: f64,
    /// Planning horizon `H` by epoch (§4.1: 5 → 15; the ramp over epochs 0–80 is MoPAC's, whose
    /// configuration p3's figures match).
    pub horizon: LinearSchedule,
    /// MPC transitions per epoch (§4.1: "a varying batch-size with maximum of 10,000"; ours:
    /// 10 000 throughout), spread over the epoch's refits: `ceil(n · model_train_freq /
    /// epoch_length / H)` plans per refit.
    pub transitions_per_epoch: LinearSchedule,
    /// Refits' worth of plans `D_MPC` keeps (Algorithm 1, line 8: 1, a fresh buffer each time).
    pub keep_iterations: usize,
    /// Plans made at once, as one population of `plans_per_batch × mpc.samples` rows through
    /// the model, the policy and the critic (ours: 64; only the random numbers depend on it).
    pub plans_per_batch: usize,
    /// The share of real transitions in M-DeMoRL's SAC minibatches, the rest drawn from `D_MPC`
    /// (Algorithm 1 says only that SAC learns from `D_ENV ∪ D_MPC`). `None`: `base.real_ratio`,
    /// MBPO's share (5 % real).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mpc_real_ratio: Option<f64>,
}

impl Default for P3Config {
    fn default() -> Self {
        Self {
            base: MbpoConfig::default(),
            mpc: DmdMpcConfig::default(),
            noise_fraction: 0.3,
            horizon: LinearSchedule {
                from_epoch: 0,
                to_epoch: 80,
                start: 5,
                end: 15,
            },
            transitions_per_epoch: LinearSchedule::constant(10_000),
            keep_iterations: 1,
            plans_per_batch: 64,
            mpc_real_ratio: None,
        }
    }
}

impl P3Config {
    /// [`MbpoConfig::pendulum`] as the loop, `H` 5 → 10 over epochs 0–4 (ours, a short run's
    /// share of p3's ramp) and p3's 10 000 MPC transitions an epoch.
    pub fn pendulum() -> Self {
        Self {
            base: MbpoConfig::pendulum(),
            horizon: LinearSchedule {
                from_epoch: 0,
                to_epoch: 4,
                start: 5,
                end: 10,
            },
            ..Self::default()
        }
    }

    /// A preset for p3's 2R leg (§5): 80 epochs of 1000 real steps, `H` 5 → 15 over them.
    /// Ours, where p3 gives no figure for the leg, sized so that five seeds of all three methods
    /// run in under 30 minutes on two cores: SAC 64×64 with 1000 random steps and `G` = 1
    /// update per real step (the same for all three methods); an ensemble of 3-layer 64-unit
    /// members refit once an epoch with at most 200 minibatches per member (whole epochs, at
    /// least one); MBPO's rollouts 100 per step of length 1; 5000 MPC transitions an epoch (p3:
    /// "a varying batch-size with maximum of 10,000"); 3 evaluation episodes.
    pub fn leg2r() -> Self {
        let defaults = MbpoConfig::default();
        Self {
            base: MbpoConfig {
                sac: tandem_agents::SacConfig {
                    hidden: vec![64, 64],
                    learning_starts: 1000,
                    ..defaults.sac.clone()
                },
                ensemble: tandem_models::EnsembleConfig {
                    hidden: vec![64, 64, 64],
                    ..defaults.ensemble.clone()
                },
                real_steps: 80_000,
                model_train_freq: 1000,
                model_max_updates: Some(200),
                rollouts_per_step: 100,
                rollout_length: LinearSchedule::constant(1),
                updates_per_step: 1,
                eval_episodes: 3,
                ..defaults
            },
            transitions_per_epoch: LinearSchedule::constant(5000),
            ..Self::default()
        }
    }

    /// Checks the ranges the loops rely on.
    pub fn validate(&self) -> Result<()> {
        self.base.validate()?;
        self.horizon
            .validate("horizon")
            .map_err(AlgoError::Config)?;
        self.transitions_per_epoch
            .validate("transitions_per_epoch")
            .map_err(AlgoError::Config)?;
        if let Some(r) = self.mpc_real_ratio {
            if !(0.0..=1.0).contains(&r) {
                return Err(AlgoError::Config(format!(
                    "mpc_real_ratio must lie in [0, 1], got {r}"
                )));
            }
        }
        if self.keep_iterations == 0 || self.plans_per_batch == 0 {
            return Err(AlgoError::Config(
                "keep_iterations and plans_per_batch must be >= 1".into(),
            ));
        }
        if !(self.noise_fraction > 0.0 && self.noise_fraction.is_finite()) {
            return Err(AlgoError::Config(format!(
                "noise_fraction must be positive and finite, got {}",
                self.noise_fraction
            )));
        }
        if self.max_plan_capacity().is_none() {
            return Err(AlgoError::Config(
                "the MPC buffer transitions_per_epoch x base.model_train_freq x keep_iterations \
                 overflows"
                    .into(),
            ));
        }
        // The planner checks the rest of its settings.
        DmdMpc::new(DmdMpcConfig {
            horizon: self.horizon.max(),
            ..self.mpc.clone()
        })?;
        Ok(())
    }

    /// The loop M-DeMoRL runs: `base` with [`Self::mpc_real_ratio`] as its real share.
    pub fn m_demorl_loop(&self) -> MbpoConfig {
        MbpoConfig {
            real_ratio: self.mpc_real_ratio.unwrap_or(self.base.real_ratio),
            ..self.base.clone()
        }
    }

    /// An upper bound on `D_MPC`'s capacity over all epochs (a refit's transitions rounded up to
    /// whole plans, times `keep_iterations`); `None` on overflow.
    pub fn max_plan_capacity(&self) -> Option<usize> {
        let b = &self.base;
        let n = (self.transitions_per_epoch.max() as u64).checked_mul(b.model_train_freq)?;
        let per_refit = usize::try_from(n.div_ceil(b.epoch_length.max(1))).ok()?;
        per_refit
            .checked_add(self.horizon.max())?
            .checked_mul(self.keep_iterations)
    }

    /// The memory of an M-DeMoRL run ([`MbpoConfig::memory`] with `D_MPC` as the secondary
    /// buffer) and of its planner's population: `plans_per_batch × samples` action sequences of
    /// `H × act_dim` and `× particles` model states, in `f64`.
    pub fn memory(&self, obs_dim: usize, act_dim: usize) -> MemoryEstimate {
        let m = &self.mpc;
        let rows = [self.plans_per_batch, m.samples];
        let h = self.horizon.max();
        // f64 buffers as pairs of f32s: sequences, their noise and the means.
        let sequences = [&[6][..], &rows, &[h, act_dim]].concat();
        // States, next states, model inputs and outputs.
        let states = [
            &[8][..],
            &rows,
            &[m.particles, obs_dim.saturating_add(act_dim)],
        ]
        .concat();
        let costs = [&[2][..], &rows, &[m.particles, h]].concat();
        MemoryEstimate::new()
            .with(
                "base.",
                self.base.memory(obs_dim, act_dim, self.max_plan_capacity()),
            )
            .f32s(
                "mpc action sequences (plans_per_batch x mpc.samples)",
                &sequences,
            )
            .f32s("mpc model states (x mpc.particles)", &states)
            .f32s("mpc costs", &costs)
    }

    /// Plans per refit at `epoch`.
    pub fn plans_per_refit(&self, epoch: u64) -> usize {
        let b = &self.base;
        let n = self.transitions_per_epoch.at(epoch) as u64 * b.model_train_freq;
        let per_refit = n.div_ceil(b.epoch_length) as usize;
        per_refit.div_ceil(self.horizon.at(epoch)).max(1)
    }
}

/// Runs `method` for `seed` on `problem` (resuming from the checkpoint `store` holds under the
/// method's name, if any). SAC and MBPO run [`super::mbpo`]'s loop with `cfg.base`, M-DeMoRL
/// with [`P3Config::m_demorl_loop`].
pub fn run<T, F>(
    method: Method,
    problem: &Problem<T, F>,
    cfg: &P3Config,
    seed: u64,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunRecord>
where
    T: Task + Clone + Send + Sync + 'static,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    cfg.validate()?;
    match method {
        Method::Sac => run_with::<T, F, Rollouts>(problem, &cfg.base, seed, None, store, on_event),
        Method::Mbpo => {
            let mut r = Rollouts::of(&cfg.base);
            run_with(problem, &cfg.base, seed, Some(&mut r), store, on_event)
        }
        Method::MDemorl => {
            let mut plans = MpcPlans { cfg: cfg.clone() };
            let base = cfg.m_demorl_loop();
            run_with(problem, &base, seed, Some(&mut plans), store, on_event)
        }
    }
}

/// M-DeMoRL's inner loop as the shared loop's [`Imagination`].
#[derive(Debug, Clone)]
pub struct MpcPlans {
    /// The settings.
    pub cfg: P3Config,
}

impl Imagination for MpcPlans {
    type Model = ProbabilisticEnsemble;

    fn name(&self) -> &'static str {
        Method::MDemorl.name()
    }

    fn new_model(
        &self,
        cfg: &MbpoConfig,
        state_dim: usize,
        control_dim: usize,
        seed: u64,
    ) -> Result<Option<ProbabilisticEnsemble>> {
        ensemble_of(cfg, state_dim, control_dim, seed)
    }

    fn capacity(&self, _base: &MbpoConfig, epoch: u64) -> usize {
        self.cfg.plans_per_refit(epoch) * self.cfg.horizon.at(epoch) * self.cfg.keep_iterations
    }

    fn horizon(&self, epoch: u64) -> usize {
        self.cfg.horizon.at(epoch)
    }
}

impl<T: Task + Clone + Send + Sync + 'static> Imagine<T, Sac> for MpcPlans {
    fn imagine(
        &mut self,
        lp: &mut OffPolicyLoop<Sac>,
        model: Option<&mut ProbabilisticEnsemble>,
        task: &T,
        data: &Transitions,
        epoch: u64,
        seed: u64,
        rng: &mut Rng,
    ) -> Result<usize> {
        let model = fitted(model, Method::MDemorl.name())?;
        if self.cfg.keep_iterations == 1 {
            lp.clear(Store::Secondary)?;
        }
        model.set_propagation(Propagation::FixedMember);
        let h = self.cfg.horizon.at(epoch);
        let starts = sample_starts(data, self.cfg.plans_per_refit(epoch), rng)?;
        let (low, high) = super::box_bounds(task.action_space(), "M-DeMoRL plans over")?;
        let half: Vec<f64> = low.iter().zip(&high).map(|(l, u)| 0.5 * (u - l)).collect();
        let mut planner = DmdMpc::new(DmdMpcConfig {
            horizon: h,
            bounds: Some(Bounds::new(low, high)),
            noise: Noise::Diagonal(half.iter().map(|r| r * self.cfg.noise_fraction).collect()),
            seed,
            ..self.cfg.mpc.clone()
        })?;
        let objective = value_objective(&lp.agent, task, model.state_dim(), half.len())?;
        let rows = {
            let agent = &lp.agent;
            let rng = RefCell::new(&mut *rng);
            let proposal = |states: ArrayView2<'_, f64>| {
                let obs = observations(task, states);
                let mut r = rng.borrow_mut();
                agent
                    .act_batch(obs.view(), Mode::Explore, &mut r)
                    .unwrap_or_else(|_| Array2::from_elem((states.nrows(), half.len()), f64::NAN))
            };
            let mut rows = PlanRows::default();
            let chunk = self.cfg.plans_per_batch.max(1);
            for i in (0..starts.nrows()).step_by(chunk) {
                let batch = starts.slice(ndarray::s![i..(i + chunk).min(starts.nrows()), ..]);
                model.resample_member_offset(&mut rng.borrow_mut());
                let m = InActions::new(&*model, task);
                let plans = planner.plan_batch_with_proposal(batch, &m, &objective, &proposal)?;
                for plan in &plans {
                    rows.push(task, &plan.transitions());
                }
            }
            rows
        };
        rows.store(lp)
    }
}

/// The MPC objective: the model's mean reward as the running reward, SAC's discount, and SAC's
/// soft value of the final state's observation as the terminal value (p3 eq. 3, §3 item 2). The
/// value is a copy of the critic at the time of the call.
fn value_objective<T: Task + Clone + Send + Sync + 'static>(
    agent: &Sac,
    task: &T,
    state_dim: usize,
    action_dim: usize,
) -> Result<Objective> {
    let critic = Arc::new(agent.clone());
    let task = task.clone();
    let value = move |states: ArrayView2<'_, f64>| {
        let obs = observations(&task, states);
        // Deterministic: V at the mean action, no random number drawn.
        critic
            .v_batch(obs.view(), Mode::Deterministic, &mut rng_from_seed(0))
            .unwrap_or_else(|_| Array1::from_elem(states.nrows(), f64::NAN))
    };
    let obj = Objective::new(state_dim, action_dim, |_, _| 0.0)
        .with_model_reward()
        .with_terminal_value(value)
        .with_discount(agent.config().gamma)
        .map_err(|e| AlgoError::Config(e.to_string()))?;
    Ok(obj)
}

/// The MPC's transitions in the agent's terms, gathered plan by plan.
#[derive(Default)]
struct PlanRows {
    obs: Vec<f64>,
    actions: Vec<f64>,
    rewards: Vec<f64>,
    next_obs: Vec<f64>,
    terminated: Vec<bool>,
    widths: (usize, usize),
}

impl PlanRows {
    /// Adds a plan's transitions up to (and with) the first terminal one.
    fn push<T: Task + ?Sized>(&mut self, task: &T, t: &Transitions) {
        let obs = observations(task, t.states.view());
        let next = observations(task, t.next_states.view());
        self.widths = (obs.ncols(), t.actions.ncols());
        for h in 0..t.len() {
            let mut s1 = t.next_states.row(h).to_vec();
            task.canonicalize(&mut s1);
            let done = task.terminated(&s1);
            self.obs.extend(obs.row(h));
            self.actions.extend(t.actions.row(h));
            self.rewards.push(t.rewards[h]);
            self.next_obs.extend(next.row(h));
            self.terminated.push(done);
            if done {
                break;
            }
        }
    }

    /// Stores them in the loop's secondary buffer; returns how many.
    fn store(self, lp: &mut OffPolicyLoop<Sac>) -> Result<usize> {
        let n = self.rewards.len();
        let (o, a) = self.widths;
        let shape = |v: Vec<f64>, w: usize| {
            Array2::from_shape_vec((n, w), v).map_err(|e| AlgoError::Config(e.to_string()))
        };
        lp.push_rows(
            Store::Secondary,
            shape(self.obs, o)?.view(),
            shape(self.actions, a)?.view(),
            Array1::from(self.rewards).view(),
            shape(self.next_obs, o)?.view(),
            &self.terminated,
        )?;
        Ok(n)
    }
}
