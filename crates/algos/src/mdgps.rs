//! Mirror-descent guided policy search (MDGPS; Montgomery and Levine 2016) as p4 §IV uses it: a
//! neural *global* policy `π_θ(u | x) = N(μ_θ(x), diag(σ²))` trained by supervised regression onto
//! the per-condition TVLG *local* controllers, each of which is updated under a KL bound against
//! the previous global policy linearized around its samples.
//!
//! One iteration, given the local controllers `p_c` and the global policy `π_θ`:
//!
//! 1. draw `samples` trajectories of every `p_c` on the system (the counted samples);
//! 2. for each condition: fit TVLG dynamics to its samples and linearize `π_θ` around them
//!    ([`Linearization`]). By default as GPS does ([`linearize_by_regression`]): at every step the
//!    regression of `μ_θ(x_t)` on the sampled `x_t` under a GMM prior over the condition's recent
//!    states ([`TvlgPolicyFit`]), its residual covariance plus `diag(σ²)` as `Σ̄_t`. Or the
//!    network's Jacobian at the samples' mean state (`K̄_t = ∂μ_θ/∂x(x̄_t)`,
//!    `k̄_t = μ_θ(x̄_t) − K̄_t x̄_t`, `Σ̄_t = diag(σ²)`: [`linearize`]), which nearly deterministic
//!    samples do not constrain: the local controllers, bounded against it, copy a network's
//!    steepness where no sample is (a policy of slope 1000 at the mean that saturates around it:
//!    gain 1000, against 0.8 by regression). The regression's gain is bounded by the spread of
//!    the policy's actions over the samples and the prior's;
//! 3. update `p_c` with the local method: LQR-FLM minimizes the expected cost subject to
//!    `E[KL(p_c ‖ π̄_c)] ≤ ε m` (p4's constraint against the old global policy; `m = 1`, or from
//!    GPS's MDGPS step rule, [`MdgpsStep`]); PILQR does the same in its LQR-FLM stage (with its own
//!    per-step multipliers) and then PI² on the residual costs-to-go of its samples; PI²
//!    reweights the samples as alone. On the first iteration the global policy is first
//!    regressed onto the initial controllers at their samples (GPS's catch-up,
//!    [`FirstIteration::CatchUp`]), so that the bound has a policy to be taken against; our first
//!    version instead took an unbounded step (the bound against `p_c` itself);
//! 4. regress `μ_θ` onto the new local controllers' mean actions `K_t x + k_t` at every sampled
//!    state of every condition (mean squared error, or GPS's precision-weighted error:
//!    [`Weighting`]; Adam, inputs standardized with the first iteration's statistics), and set
//!    `σ²` to the mean of the local controllers' action variances (or the inverse of their mean
//!    precision).
//!
//! After each iteration the global policy's deterministic mean is rolled out from every test
//! start and the task's measure of the final states averaged: p4 Fig. 4 and 5's "averaged across
//! N random test conditions per iteration". Test rollouts are evaluation, not counted samples.
//!
//! A run is one [`Mdgps`] on the [`drive`]r: it saves itself under `mdgps_<method>` after every
//! iteration (the local controllers and their optimizers' state, the global policy and its Adam
//! state, the step rule's, the policy prior's kept states and mixture, the generator, the curve) and resumes from there with exactly the
//! numbers of an uninterrupted run.

use nalgebra::{DMatrix, DVector};
use ndarray::{s, Array2};
use serde::{Deserialize, Serialize};
use tandem_agents::GlobalPolicy;
pub use tandem_agents::{PolicyConfig, Weighting};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Rng;
pub use tandem_models::PolicyFitConfig;
use tandem_models::{DynamicsModel, ModelInput, TvlgPolicyFit};
use tandem_nn::budget::{widths, MemoryEstimate};
use tandem_nn::{Adam, AdamConfig, Checkpoint, Checkpointable};
use tandem_planners::{adjust_step_mult, laplace_cost, LqrFlm, TrajectorySamples, TvlgController};

use super::gps::{
    load_locals, save_locals, start_locals, Local, LocalConfig, LocalMethod, LocalModel,
    LocalProblem,
};
use super::{AlgoError, Checkpoints, Result};
use crate::driver::{drive, Algorithm};

/// MDGPS's step rule for LQR-FLM local updates (GPS's `AlgorithmMDGPS._stepadjust`, rule
/// `laplace`): one multiplier `m` of the KL bound `ε m` for all conditions. After each update,
/// with `L(p, f, c)` the expected cost of controller `p` under fitted dynamics `f` and cost
/// expansion `c` ([`tandem_planners::laplace_cost`]), averaged over the conditions: the previous
/// linearized global policy `π̄'` under the previous fit, `L(π̄', f', c')`; the local controllers
/// that update produced, `L(p, f', c')`, which it predicted; and the global policy trained on them,
/// linearized around the new samples under the new fit, `L(π̄, f, c)`, which is what happened.
/// The multiplier then moves as [`tandem_planners::adjust_step_mult`]. PILQR keeps its own
/// per-step rule (on the residuals); PI² has no bound.
///
/// Off by default. On the reacher (`ε` 0.1, uniform regression, `tandem reproduce p4-reacher` with
/// `adjust = true`, 3 seeds) MDGPS with LQR-FLM ended at 0.061, 0.131 and 0.036 m against 0.063,
/// 0.065 and 0.040 m at a fixed `ε`: on seed 1 the rule drove `m` to its floor, the local
/// controllers lost ground and the regression diverged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MdgpsStep {
    /// Whether `m` adapts (`false`: `ε` always).
    pub adjust: bool,
    /// Smallest multiplier.
    pub min_mult: f64,
    /// Largest multiplier.
    pub max_mult: f64,
}

impl Default for MdgpsStep {
    /// Not adapting (see above); when on, GPS's default bounds `[0.01, 10]`.
    fn default() -> Self {
        Self {
            adjust: false,
            min_mult: 0.01,
            max_mult: 10.0,
        }
    }
}

/// How the global policy is linearized around a condition's samples for the local update's KL
/// bound (step 2 of the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Linearization {
    /// GPS's (`PolicyPriorGMM`): the regression of the policy's mean actions on the sampled
    /// states at every step under a GMM prior over the condition's last `max_samples`
    /// trajectories, the residual covariance plus `diag(σ²)` ([`linearize_by_regression`]).
    Regression(PolicyFitConfig),
    /// The network's Jacobian at the samples' mean state with `diag(σ²)` ([`linearize`]). Settings
    /// recorded before the regression existed have no `linearization` and read as this, which is
    /// what they ran.
    PointJacobian,
}

impl Default for Linearization {
    /// GPS's regression with its prior's defaults.
    fn default() -> Self {
        Linearization::Regression(PolicyFitConfig::default())
    }
}

impl Linearization {
    /// What settings without a `linearization` ran: the point Jacobian.
    pub fn recorded_default() -> Self {
        Linearization::PointJacobian
    }
}

/// Settings of [`train_mdgps`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MdgpsConfig {
    /// The local controllers' loop: iterations, samples per condition and iteration, initial
    /// variance, the trajectory optimizers, the dynamics fit.
    pub local: LocalConfig,
    /// The global policy's regression.
    pub policy: PolicyConfig,
    /// The step rule of LQR-FLM's KL bound.
    #[serde(default)]
    pub step: MdgpsStep,
    /// How the global policy is linearized for the bound. New settings choose GPS's regression
    /// ([`Linearization::default`]); settings without the key read as the point Jacobian
    /// ([`Linearization::recorded_default`]), which they ran.
    #[serde(default = "Linearization::recorded_default")]
    pub linearization: Linearization,
    /// What the first iteration does before there is a trained global policy. Settings without
    /// the key read as [`FirstIteration::Unbounded`], which they ran.
    #[serde(default = "FirstIteration::recorded_default")]
    pub first_iteration: FirstIteration,
}

/// The first iteration of MDGPS, before the global policy has been trained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FirstIteration {
    /// GPS's (`AlgorithmMDGPS.iteration`: "on the first iteration, need to catch policy up to
    /// init_traj_distr"): regress the global policy onto the initial controllers at their samples
    /// first, then update the local controllers bounded against it, as every later iteration.
    CatchUp,
    /// Our first version: the local controllers take an unbounded step (plain trajectory
    /// optimization, against themselves), then the policy is regressed onto them.
    Unbounded,
}

impl Default for FirstIteration {
    /// GPS's.
    fn default() -> Self {
        FirstIteration::CatchUp
    }
}

impl FirstIteration {
    /// What settings without a `first_iteration` ran.
    pub fn recorded_default() -> Self {
        FirstIteration::Unbounded
    }
}

impl MdgpsConfig {
    /// Checks the settings the loop relies on.
    pub fn validate(&self) -> Result<()> {
        self.local.validate()?;
        let p = &self.policy;
        if p.epochs == 0 || p.batch_size == 0 || p.hidden.contains(&0) {
            return Err(AlgoError::Config(format!(
                "policy epochs {}, batch_size {} and hidden widths {:?} must be positive",
                p.epochs, p.batch_size, p.hidden
            )));
        }
        if !(p.learning_rate.is_finite() && p.learning_rate > 0.0) {
            return Err(AlgoError::Config(format!(
                "policy learning_rate {} must be finite and > 0",
                p.learning_rate
            )));
        }
        let st = &self.step;
        let contains_one = (0.0..=1.0).contains(&st.min_mult) && st.min_mult > 0.0;
        if !(contains_one && st.max_mult.is_finite() && st.max_mult >= 1.0) {
            return Err(AlgoError::Config(format!(
                "step multipliers [{}, {}] must be finite, positive and contain 1",
                st.min_mult, st.max_mult
            )));
        }
        if let Linearization::Regression(fit) = &self.linearization {
            fit.validate()
                .map_err(|e| AlgoError::Config(format!("linearization: {e}")))?;
        }
        Ok(())
    }
}

impl MdgpsConfig {
    /// The memory of a run ([`LocalConfig::memory`]) with the global policy on
    /// `policy_dim`-dimensional inputs: its network trained with Adam and its regression data
    /// (every condition's samples of the iteration, with their precisions), and with the
    /// regression's prior its kept states and the policy's actions there, per condition.
    pub fn memory(
        &self,
        conditions: usize,
        horizon: usize,
        state_dim: usize,
        act_dim: usize,
        policy_dim: usize,
    ) -> MemoryEstimate {
        let p = &self.policy;
        let sizes = widths(policy_dim, &p.hidden, act_dim);
        let row = policy_dim
            .saturating_add(act_dim)
            .saturating_add(act_dim.saturating_mul(act_dim));
        let kept = match &self.linearization {
            Linearization::Regression(fit) => fit.prior.as_ref().map_or(0, |p| p.max_samples),
            Linearization::PointJacobian => 0,
        };
        self.local
            .memory(conditions, horizon, state_dim, act_dim)
            .mlp("policy network", &sizes, 4, p.batch_size)
            .f32s(
                "policy regression data (conditions x samples x horizon)",
                &[conditions, self.local.samples, horizon, row],
            )
            .f32s(
                "policy prior's states and actions (conditions x max_samples)",
                &[
                    2,
                    conditions,
                    kept,
                    horizon,
                    state_dim.saturating_add(act_dim),
                ],
            )
    }
}

/// The task's figure of a final state.
pub type FinalMeasure = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// Whether a final measure counts as solving its start (the door: opened).
pub type Solved = Box<dyn Fn(f64) -> bool + Send + Sync>;

/// Where the global policy is evaluated: starts and the task's measure of a final state.
pub struct TestSet {
    /// Initial states.
    pub starts: Vec<Vec<f64>>,
    /// The measure of a final state (e.g. the end effector's distance to the target).
    pub measure: FinalMeasure,
    /// Whether a start's final measure solves it; `None`: the task counts no solved starts, and
    /// the curve has no [`MdgpsPoint::test_solved`].
    pub solved: Option<Solved>,
}

/// The TVLG controller that linearizes `policy` around the samples' mean state at every step:
/// `K̄_t = ∂μ/∂x(x̄_t)`, `k̄_t = μ(x̄_t) − K̄_t x̄_t`, `Σ̄_t = diag(σ²)`
/// ([`GlobalPolicy::linearization`]).
pub fn linearize(policy: &GlobalPolicy, samples: &TrajectorySamples) -> Result<TvlgController> {
    let shape = samples.actions.shape();
    let (t_len, m) = (shape[1], shape[2]);
    let n = samples.states.shape()[2];
    let mut ws = policy.net().workspace();
    let (mut gains, mut offsets) = (Vec::with_capacity(t_len), Vec::with_capacity(t_len));
    for t in 0..t_len {
        let xbar: Vec<f64> = (0..n)
            .map(|j| samples.states.slice(s![.., t, j]).mean().unwrap_or(0.0))
            .collect();
        let (mu, k) = policy.linearization(&xbar, &mut ws)?;
        let k = DMatrix::from_row_slice(m, n, &k);
        offsets.push(DVector::from_vec(mu) - &k * DVector::from_column_slice(&xbar));
        gains.push(k);
    }
    let cov = DMatrix::from_diagonal(&DVector::from_column_slice(&policy.variance));
    Ok(TvlgController::new(gains, offsets, vec![cov; t_len])?)
}

/// The TVLG controller fitted to `policy` around `samples` by regression (GPS's policy
/// linearization): `fit`'s prior keeps the samples' states and is refitted over `[x, μ(x)]` at
/// all its kept states with the policy as it is now, then at every step the policy's mean actions
/// at the sampled states are regressed on those states under that prior
/// ([`TvlgPolicyFit::fit`]), the residual covariance plus `diag(σ²)` the controller's covariance.
pub fn linearize_by_regression(
    policy: &GlobalPolicy,
    samples: &TrajectorySamples,
    fit: &mut TvlgPolicyFit,
) -> Result<TvlgController> {
    let (rows, t_len, m) = samples.actions.dim();
    let states = samples.states.slice(s![.., ..t_len, ..]).to_owned();
    let mut ws = policy.net().workspace();
    fit.update_prior(states.view(), |x: &DMatrix<f64>| -> Result<DMatrix<f64>> {
        // Row-major rows of the states: the column-major storage of the transpose.
        let u = policy.mean(x.transpose().as_slice(), &mut ws)?;
        Ok(DMatrix::from_row_slice(x.nrows(), m, &u))
    })?;
    let flat = states
        .as_slice()
        .expect("an owned array is in standard layout");
    let mu = policy.mean(flat, &mut ws)?;
    let actions = ndarray::Array3::from_shape_vec((rows, t_len, m), mu)
        .map_err(|e| AlgoError::Config(e.to_string()))?;
    let cov = DMatrix::from_diagonal(&DVector::from_column_slice(&policy.variance));
    let lin = fit.fit(states.view(), actions.view(), &cov)?;
    Ok(TvlgController::new(lin.gains, lin.offsets, lin.cov)?)
}

/// One point of an MDGPS run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MdgpsPoint {
    /// Samples over all training conditions so far.
    pub samples: u64,
    /// The global policy's mean measure over the test starts, after this iteration's fit.
    pub test_measure: f64,
    /// The fraction of the test starts it solved ([`TestSet::solved`]; `None` without).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_solved: Option<f64>,
    /// The local controllers' mean measure over this iteration's samples (all conditions).
    pub local_measure: f64,
    /// The regression's last-epoch mean (weighted) squared error.
    pub policy_loss: f64,
    /// The multiplier of LQR-FLM's KL bound this iteration's update used ([`MdgpsStep`]; 1 for
    /// the other methods and without adjustment).
    #[serde(default = "one")]
    pub step_mult: f64,
}

fn one() -> f64 {
    1.0
}

/// What a run of [`train_mdgps`] leaves.
pub struct MdgpsRun {
    /// One point per iteration.
    pub curve: Vec<MdgpsPoint>,
    /// Local updates that failed numerically (the controller was kept).
    pub failed_updates: usize,
    /// The global policy at the end.
    pub policy: GlobalPolicy,
    /// Wall time of the run, seconds, summed over every process that ran it.
    pub wall_seconds: f64,
}

/// Trains a global policy with MDGPS on `problem`'s conditions, the local controllers updated by
/// `method`, evaluating it on `test` after every iteration, from the checkpoint `store` holds
/// under `mdgps_<method>` if any, saving after every iteration. `progress` receives the samples
/// drawn so far.
pub fn train_mdgps(
    method: LocalMethod,
    problem: &LocalProblem,
    test: &TestSet,
    cfg: &MdgpsConfig,
    seed: u64,
    store: &mut dyn Checkpoints,
    progress: &mut dyn FnMut(u64),
) -> Result<MdgpsRun> {
    drive(
        Mdgps::new(method, problem, test, cfg, seed)?,
        store,
        progress,
    )
}

/// An MDGPS run as one checkpointable value, stepped one iteration at a time by [`drive`]: the
/// local controllers with their optimizers' state, the global policy and its optimizer, the step
/// rule's state, the generator, the curve and the counts. Its events are the samples drawn so far.
pub struct Mdgps<'a> {
    method: LocalMethod,
    /// `mdgps_<method>`: the checkpoint's key.
    name: String,
    problem: &'a LocalProblem,
    test: &'a TestSet,
    cfg: &'a MdgpsConfig,
    seed: u64,
    lqr: LqrFlm,
    locals: Vec<Local>,
    policy: GlobalPolicy,
    opt: Adam,
    s: MdgpsState,
}

/// Where an [`Mdgps`] run stands, besides its controllers, policy and optimizer.
#[derive(Serialize, Deserialize)]
struct MdgpsState {
    /// Iterations done.
    iteration: usize,
    rng: Rng,
    curve: Vec<MdgpsPoint>,
    failed: usize,
    drawn: u64,
    /// MDGPS's step rule: the multiplier, and per condition the last anchor and model.
    mult: f64,
    prev: Vec<Option<(TvlgController, LocalModel)>>,
    /// Per condition, the regression's policy prior ([`Linearization::Regression`]; empty with
    /// the point Jacobian, and in checkpoints written before the regression existed).
    #[serde(default)]
    policy_fits: Vec<TvlgPolicyFit>,
}

const STATE: &str = "mdgps.state";
const LOCALS: &str = "mdgps.locals";
const POLICY: &str = "mdgps.policy";
const OPT: &str = "mdgps.adam";

impl<'a> Mdgps<'a> {
    /// A fresh run of MDGPS with `method` on `problem` for `seed`, tested on `test`.
    pub fn new(
        method: LocalMethod,
        problem: &'a LocalProblem,
        test: &'a TestSet,
        cfg: &'a MdgpsConfig,
        seed: u64,
    ) -> Result<Self> {
        cfg.validate()?;
        super::gps::check_problem(problem)?;
        if test
            .starts
            .iter()
            .any(|x| x.len() != problem.system.state_dim())
            || test.starts.is_empty()
        {
            return Err(AlgoError::Config(
                "the test set needs at least one start of the system's state dimension".into(),
            ));
        }
        let (n, m) = (problem.system.state_dim(), problem.system.action_dim());
        let mut rng = rng_from_seed(seed);
        let policy = GlobalPolicy::new(
            n,
            m,
            &cfg.policy.hidden,
            cfg.local.init_variance,
            problem.policy_input.clone(),
            &mut rng,
        )?;
        let opt = Adam::new(
            AdamConfig::with_lr(cfg.policy.learning_rate),
            policy.net().num_params(),
        )?;
        let k = problem.conditions.len();
        let (lqr, locals) = start_locals(problem, &cfg.local)?;
        Ok(Self {
            method,
            name: format!("mdgps_{}", method.name()),
            problem,
            test,
            cfg,
            seed,
            lqr,
            locals,
            policy,
            opt,
            s: MdgpsState {
                iteration: 0,
                rng,
                curve: Vec::new(),
                failed: 0,
                drawn: 0,
                mult: 1.0,
                prev: (0..k).map(|_| None).collect(),
                policy_fits: policy_fits(&cfg.linearization, k),
            },
        })
    }
}

impl Algorithm for Mdgps<'_> {
    type Event = u64;
    type Record = MdgpsRun;
    const SUMS_WALL_TIME: bool = true;

    fn id(&self) -> (&str, u64) {
        (&self.name, self.seed)
    }

    fn done(&self) -> bool {
        self.s.iteration >= self.cfg.local.iterations
    }

    /// One iteration (steps 1 to 4 of the module docs) and the test of the policy it leaves.
    fn step(&mut self, progress: &mut dyn FnMut(u64), _stop: &dyn Checkpoints) -> Result<bool> {
        let (method, problem, cfg) = (self.method, self.problem, self.cfg);
        let (lqr, locals, policy, st) =
            (&self.lqr, &mut self.locals, &mut self.policy, &mut self.s);
        let local = &cfg.local;
        let (system, horizon) = (&*problem.system, problem.horizon);
        let (n, m) = (system.state_dim(), system.action_dim());
        let k = problem.conditions.len();
        // A checkpoint from before the regression existed has no fits: start them.
        let regression = matches!(cfg.linearization, Linearization::Regression(_));
        if st.policy_fits.len() != if regression { k } else { 0 } {
            st.policy_fits = policy_fits(&cfg.linearization, k);
        }
        let mut batches = Vec::with_capacity(k);
        let mut local_sum = 0.0;
        for (c, cond) in problem.conditions.iter().enumerate() {
            let samples = locals[c].sample(system, cond, local, &mut st.rng)?;
            st.drawn += local.samples as u64;
            progress(st.drawn);
            for i in 0..samples.len() {
                let x = samples.states.slice(s![i, horizon, ..]).to_vec();
                local_sum += (problem.measure)(c, &x);
            }
            batches.push(samples);
        }
        let catch_up = st.iteration == 0 && cfg.first_iteration == FirstIteration::CatchUp;
        if catch_up && method != LocalMethod::Pi2 {
            fit_global(
                policy,
                &mut self.opt,
                locals,
                &batches,
                cfg,
                (n, m, horizon),
                &mut st.rng,
            )?;
        }
        if (st.iteration == 0 && !catch_up) || method == LocalMethod::Pi2 {
            // Before the global policy has been trained, plain trajectory optimization; PI²
            // reweights its own samples.
            for (c, cond) in problem.conditions.iter().enumerate() {
                if !locals[c].improve(method, &batches[c], &cond.objective, lqr, local)? {
                    st.failed += 1;
                }
            }
            // GPS's policy prior keeps every iteration's states, these too (PI² linearizes
            // nothing; with the point Jacobian there are no fits).
            if method != LocalMethod::Pi2 {
                for (fit, samples) in st.policy_fits.iter_mut().zip(&batches) {
                    fit.add_states(samples.states.slice(s![.., ..horizon, ..]))?;
                }
            }
        } else {
            // Bounded against the global policy linearized around each condition's samples.
            let mut cur = Vec::with_capacity(k);
            for (c, cond) in problem.conditions.iter().enumerate() {
                let model = locals[c].model(&batches[c], &cond.objective)?;
                let anchor = match &cfg.linearization {
                    Linearization::Regression(_) => {
                        linearize_by_regression(policy, &batches[c], &mut st.policy_fits[c])?
                    }
                    Linearization::PointJacobian => linearize(policy, &batches[c])?,
                };
                cur.push((anchor, model));
            }
            let kl_step = if method == LocalMethod::LqrFlm {
                if cfg.step.adjust && st.iteration > 0 {
                    st.mult = step_mult(st.mult, &st.prev, &cur, locals, &cfg.step)?;
                }
                Some(local.trajopt.lqr.kl_step * st.mult)
            } else {
                None
            };
            for (c, (anchor, model)) in cur.iter().enumerate() {
                let updated = match model {
                    Some(model) => locals[c].improve_anchored(
                        method,
                        &batches[c],
                        model,
                        lqr,
                        anchor,
                        kl_step,
                    )?,
                    None => false,
                };
                if !updated {
                    st.failed += 1;
                }
            }
            st.prev = cur
                .into_iter()
                .map(|(anchor, model)| model.map(|m| (anchor, m)))
                .collect();
        }
        let policy_loss = fit_global(
            policy,
            &mut self.opt,
            locals,
            &batches,
            cfg,
            (n, m, horizon),
            &mut st.rng,
        )?;
        let finals = final_measures(policy, system, self.test, horizon, &mut st.rng)?;
        let (test_measure, test_solved) = self.test.summary(&finals);
        st.curve.push(MdgpsPoint {
            samples: st.drawn,
            test_measure,
            test_solved,
            local_measure: local_sum / (k * local.samples) as f64,
            policy_loss,
            step_mult: st.mult,
        });
        st.iteration += 1;
        Ok(true)
    }

    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        ckpt.put_json(STATE, &self.s)?;
        save_locals(&self.locals, LOCALS, ckpt)?;
        self.policy.save_to(POLICY, ckpt)?;
        Ok(self.opt.save_to(OPT, ckpt)?)
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        self.s = ckpt.get_json(STATE)?;
        load_locals(&mut self.locals, LOCALS, ckpt)?;
        self.policy.load_from(POLICY, ckpt)?;
        Ok(self.opt.load_from(OPT, ckpt)?)
    }

    fn finish(self, wall_seconds: f64) -> Result<MdgpsRun> {
        Ok(MdgpsRun {
            curve: self.s.curve,
            failed_updates: self.s.failed,
            policy: self.policy,
            wall_seconds,
        })
    }
}

/// Step 4 of the module docs: regresses `policy`'s mean onto the local controllers' mean actions
/// at every sampled state of `batches` (one per condition) and sets its variance; the loss.
fn fit_global(
    policy: &mut GlobalPolicy,
    opt: &mut Adam,
    locals: &[Local],
    batches: &[TrajectorySamples],
    cfg: &MdgpsConfig,
    (n, m, horizon): (usize, usize, usize),
    rng: &mut Rng,
) -> Result<f64> {
    let k = locals.len();
    // The regression's data: every sampled state with the new controller's mean action (and
    // its precision, for the weighted regression).
    let weighted = cfg.policy.weighting == Weighting::Precision;
    let (mut states, mut targets, mut precisions) = (Vec::new(), Vec::new(), Vec::new());
    for (l, samples) in locals.iter().zip(batches) {
        let ctrl = &l.controller;
        for i in 0..samples.len() {
            for t in 0..horizon {
                let x =
                    DVector::from_iterator(n, samples.states.slice(s![i, t, ..]).iter().copied());
                states.extend(x.iter());
                targets.extend(ctrl.mean(t, &x).iter());
                if weighted {
                    // nalgebra is column-major; a precision is symmetric.
                    precisions.extend(ctrl.inv_cov(t).iter());
                }
            }
        }
    }
    let loss = match cfg.policy.weighting {
        Weighting::Uniform => {
            let loss = policy.fit(&states, &targets, None, &cfg.policy, opt, rng)?;
            // σ²: the local controllers' mean action variance.
            for a in 0..m {
                let sum: f64 = locals
                    .iter()
                    .flat_map(|l| l.controller.cov.iter().map(move |s| s[(a, a)]))
                    .sum();
                policy.variance[a] = sum / (k * horizon) as f64;
            }
            loss
        }
        Weighting::Precision => {
            let rows = precisions.len() / (m * m);
            // The mean precision: σ² is its inverse diagonal; the weights are scaled by its
            // trace per action.
            let mut mean = vec![0.0; m * m];
            for w in precisions.chunks(m * m) {
                for (s, v) in mean.iter_mut().zip(w) {
                    *s += v / rows as f64;
                }
            }
            let scale = (0..m).map(|a| mean[a * m + a]).sum::<f64>() / m as f64;
            for a in 0..m {
                policy.variance[a] = 1.0 / mean[a * m + a];
            }
            precisions.iter_mut().for_each(|v| *v /= scale);
            policy.fit(&states, &targets, Some(&precisions), &cfg.policy, opt, rng)?
        }
    };
    Ok(loss)
}

/// One fresh policy fit per condition for the regression, none for the point Jacobian.
fn policy_fits(lin: &Linearization, conditions: usize) -> Vec<TvlgPolicyFit> {
    match lin {
        Linearization::Regression(cfg) => (0..conditions)
            .map(|_| TvlgPolicyFit::new(cfg.clone()))
            .collect(),
        Linearization::PointJacobian => Vec::new(),
    }
}

/// MDGPS's step rule ([`MdgpsStep`]) over the conditions that have both a previous and a current
/// anchor and model; `locals` hold the controllers the previous update produced (those sampled
/// this iteration). Conditions whose expected costs are not finite are left out; with none left
/// the multiplier stays.
fn step_mult(
    mult: f64,
    prev: &[Option<(TvlgController, LocalModel)>],
    cur: &[(TvlgController, Option<LocalModel>)],
    locals: &[Local],
    cfg: &MdgpsStep,
) -> Result<f64> {
    let (mut before, mut predicted, mut after, mut count) = (0.0, 0.0, 0.0, 0usize);
    for ((prev, (anchor, model)), local) in prev.iter().zip(cur).zip(locals) {
        let (Some((prev_anchor, (pf, pc))), Some((f, c))) = (prev, model) else {
            continue;
        };
        let costs = (
            laplace_cost(prev_anchor, pf, pc),
            laplace_cost(&local.controller, pf, pc),
            laplace_cost(anchor, f, c),
        );
        if let (Ok(b), Ok(p), Ok(a)) = costs {
            (before, predicted, after) = (before + b, predicted + p, after + a);
            count += 1;
        }
    }
    if count == 0 {
        return Ok(mult);
    }
    let n = count as f64;
    Ok(adjust_step_mult(
        mult,
        (before - predicted) / n,
        (before - after) / n,
        (cfg.min_mult, cfg.max_mult),
    )?)
}

/// The mean measure of the policy's deterministic rollouts from the test starts.
pub fn evaluate(
    policy: &GlobalPolicy,
    system: &dyn DynamicsModel,
    test: &TestSet,
    horizon: usize,
    rng: &mut Rng,
) -> Result<f64> {
    let finals = final_measures(policy, system, test, horizon, rng)?;
    Ok(test.summary(&finals).0)
}

/// The measures of the policy's deterministic rollouts from each test start.
fn final_measures(
    policy: &GlobalPolicy,
    system: &dyn DynamicsModel,
    test: &TestSet,
    horizon: usize,
    rng: &mut Rng,
) -> Result<Vec<f64>> {
    let mut ws = policy.net().workspace();
    test.final_measures(system, horizon, rng, &mut |x| {
        Ok(policy.mean(x.as_slice().expect("standard layout"), &mut ws)?)
    })
}

impl TestSet {
    /// The mean measure of the final states of `horizon`-step rollouts on `system` from every
    /// start, all starts stepped as one batch: `act` maps the batch's states (`B × S`) to its
    /// actions (`B × A`, row-major). Rollouts are evaluation: they are not counted as samples.
    pub fn measure_policy(
        &self,
        system: &dyn DynamicsModel,
        horizon: usize,
        rng: &mut Rng,
        act: &mut dyn FnMut(&Array2<f64>) -> Result<Vec<f64>>,
    ) -> Result<f64> {
        let finals = self.final_measures(system, horizon, rng, act)?;
        Ok(self.summary(&finals).0)
    }

    /// The mean of `finals` (one measure per start) and, with [`TestSet::solved`], the fraction
    /// of them that solve their start.
    pub fn summary(&self, finals: &[f64]) -> (f64, Option<f64>) {
        let b = finals.len() as f64;
        let solved = self
            .solved
            .as_ref()
            .map(|solves| finals.iter().filter(|&&v| solves(v)).count() as f64 / b);
        (finals.iter().sum::<f64>() / b, solved)
    }

    /// The measure of the final state of a `horizon`-step rollout on `system` from each start,
    /// stepped as [`TestSet::measure_policy`] steps them.
    pub fn final_measures(
        &self,
        system: &dyn DynamicsModel,
        horizon: usize,
        rng: &mut Rng,
        act: &mut dyn FnMut(&Array2<f64>) -> Result<Vec<f64>>,
    ) -> Result<Vec<f64>> {
        let (b, n) = (self.starts.len(), system.state_dim());
        let mut x = Array2::from_shape_vec((b, n), self.starts.concat())
            .map_err(|e| AlgoError::Config(e.to_string()))?;
        for _ in 0..horizon {
            let u = Array2::from_shape_vec((b, system.action_dim()), act(&x)?)
                .map_err(|e| AlgoError::Config(e.to_string()))?;
            x = system
                .predict(&ModelInput::new(x.view(), u.view()), rng)?
                .next_states;
        }
        Ok(x.rows()
            .into_iter()
            .map(|r| (self.measure)(&r.to_vec()))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gps::tests::{a, b, cfg, problem, riccati_cost, T};
    use crate::{Ephemeral, InMemory};
    use tandem_planners::{sample_trajectories, SampleConfig};

    /// The cost of the global policy's mean actions from `x0` on the exact double integrator.
    fn policy_cost(policy: &GlobalPolicy, obj: &tandem_planners::Objective, x0: [f64; 2]) -> f64 {
        let mut ws = policy.net().workspace();
        let mut x = DVector::from_column_slice(&x0);
        let mut cost = 0.0;
        for t in 0..T {
            let u = DVector::from_vec(policy.mean(x.as_slice(), &mut ws).unwrap());
            cost += obj.running_cost(x.as_slice(), u.as_slice(), t).unwrap();
            x = &a() * &x + &b() * &u;
        }
        cost + obj.terminal_cost(x.as_slice()).unwrap()
    }

    /// On a linear system with a quadratic cost, MDGPS with LQR-FLM trains a global policy whose
    /// mean actions, from starts it never trained on, cost close to the Riccati optimum there, with
    /// the plain and with the precision-weighted regression. With GPS's step rule the model is
    /// exact and the linear policy can follow the local controllers, so the rule grows the step to
    /// its cap; the larger steps shrink the local controllers' exploration and the policy
    /// generalizes less well, but still within half again of the optimum.
    #[test]
    fn mdgps_generalizes_the_lqr_solution_to_new_starts() {
        let train = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]];
        let p = problem(&train);
        let held_out = [[0.7, 0.3], [-0.4, -0.8], [0.2, -0.5]];
        let test = TestSet {
            starts: held_out.iter().map(|x| x.to_vec()).collect(),
            measure: Box::new(|x| x[0].abs()),
            solved: None,
        };
        // Measured with the point Jacobian: uniform 1.1, 11.2, 0.3 % above the optimum;
        // precision-weighted 1.9, 5.2, 2.1 %; uniform with the step rule 5.2, 27, 1.8 %. (Before
        // LQR-FLM's search kept every step within its KL bound, the local steps were larger:
        // uniform 0.4, 6.4, 0.9 %.) With the regression, uniform: 1.5, 5.7, 0.5 %; and GPS's
        // first iteration (the default): 0.1, 4.1, 0.3 %, with the step rule 2.5, 10.9, 0.7 %.
        let jacobian = Linearization::PointJacobian;
        let (unbounded, catch_up) = (FirstIteration::Unbounded, FirstIteration::CatchUp);
        for (weighting, adjust, linearization, first_iteration, bound) in [
            (Weighting::Uniform, false, jacobian.clone(), unbounded, 1.15),
            (
                Weighting::Precision,
                false,
                jacobian.clone(),
                unbounded,
                1.1,
            ),
            (Weighting::Uniform, true, jacobian, unbounded, 1.5),
            (
                Weighting::Uniform,
                false,
                Linearization::default(),
                unbounded,
                1.1,
            ),
            (
                Weighting::Uniform,
                false,
                Linearization::default(),
                catch_up,
                1.1,
            ),
            (
                Weighting::Uniform,
                true,
                Linearization::default(),
                catch_up,
                1.5,
            ),
        ] {
            let c = MdgpsConfig {
                local: cfg(8),
                policy: PolicyConfig {
                    hidden: vec![32, 32],
                    epochs: 100,
                    batch_size: 64,
                    learning_rate: 3e-3,
                    weighting,
                },
                step: MdgpsStep {
                    adjust,
                    ..Default::default()
                },
                linearization,
                first_iteration,
            };
            let run = train_mdgps(
                LocalMethod::LqrFlm,
                &p,
                &test,
                &c,
                0,
                &mut Ephemeral,
                &mut |_| {},
            )
            .unwrap();
            let lin = match c.linearization {
                Linearization::Regression(_) => "regression",
                Linearization::PointJacobian => "point Jacobian",
            };
            let case = format!("{weighting:?}, step rule {adjust}, {lin}, {first_iteration:?}");
            assert_eq!(run.failed_updates, 0, "{case}");
            let samples: Vec<u64> = run.curve.iter().map(|p| p.samples).collect();
            assert_eq!(samples, (1..=8).map(|i| 40 * i).collect::<Vec<u64>>());
            let obj = &p.conditions[0].objective;
            for x0 in held_out {
                let (got, opt) = (policy_cost(&run.policy, obj, x0), riccati_cost(x0));
                eprintln!(
                    "{case}: {x0:?}: {:.2} % above the optimum",
                    100.0 * (got / opt - 1.0)
                );
                assert!(
                    got < bound * opt,
                    "{case}: {x0:?}: policy {got}, optimum {opt}"
                );
            }
            assert!(run.curve.last().unwrap().test_measure < 0.5 * run.curve[0].test_measure);
            // The rule needs two anchored updates: it starts at the third iteration after an
            // unbounded first one (measured 1, 1, 5, 10, 2.8, 4.4, 10, 10), at the second after
            // GPS's catch-up.
            let mults: Vec<f64> = run.curve.iter().map(|p| p.step_mult).collect();
            eprintln!("{case}: multipliers {mults:?}");
            if adjust {
                let fixed = if first_iteration == catch_up { 1 } else { 2 };
                assert!(
                    mults[..fixed].iter().all(|&m| m == 1.0),
                    "{case}: {mults:?}"
                );
                assert_ne!(mults[fixed], 1.0, "{case}: {mults:?}");
                assert!(mults.contains(&10.0), "{case}: {mults:?}");
            } else {
                assert!(mults.iter().all(|&m| m == 1.0), "{case}: {mults:?}");
            }
        }
    }

    /// Settings the loop cannot use are errors that name them; the defaults are valid and
    /// round-trip through TOML with the fields added since the first studies left out.
    #[test]
    fn bad_settings_are_named() {
        let ok = MdgpsConfig {
            local: cfg(2),
            policy: PolicyConfig::default(),
            step: MdgpsStep::default(),
            linearization: Linearization::default(),
            first_iteration: FirstIteration::default(),
        };
        ok.validate().unwrap();
        let mut c = ok.clone();
        c.linearization = Linearization::Regression(PolicyFitConfig {
            regularization: f64::NAN,
            ..Default::default()
        });
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("linearization") && e.contains("regularization"),
            "{e}"
        );
        if let Linearization::Regression(fit) = &mut c.linearization {
            fit.regularization = 1e-6;
            fit.prior.as_mut().unwrap().max_clusters = 1;
        }
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("linearization") && e.contains("max_clusters"),
            "{e}"
        );
        for lin in [Linearization::default(), Linearization::PointJacobian] {
            let c = MdgpsConfig {
                linearization: lin,
                ..ok.clone()
            };
            let back: MdgpsConfig = toml::from_str(&toml::to_string(&c).unwrap()).unwrap();
            assert_eq!(back.linearization, c.linearization);
        }
        for (min_mult, max_mult) in [(0.0, 10.0), (2.0, 10.0), (0.1, 0.5), (0.1, f64::NAN)] {
            let mut c = ok.clone();
            c.step = MdgpsStep {
                adjust: true,
                min_mult,
                max_mult,
            };
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("step multipliers"), "{e}");
        }
        let mut c = ok.clone();
        c.policy.epochs = 0;
        assert!(c.validate().unwrap_err().to_string().contains("epochs"));
        let text = toml::to_string(&ok).unwrap();
        let old: String = text
            .split("\n[step]")
            .next()
            .unwrap()
            .replace("weighting = \"uniform\"\n", "");
        assert!(!old.contains("linearization"), "{old}");
        let old = old.replace("first_iteration = \"catch_up\"\n", "");
        assert!(!old.contains("first_iteration"), "{old}");
        let read: MdgpsConfig = toml::from_str(&old).unwrap();
        assert_eq!(read.policy.weighting, Weighting::Uniform);
        assert_eq!(read.step, MdgpsStep::default());
        // Settings recorded before the regression ran the point Jacobian, and read as it.
        assert_eq!(read.linearization, Linearization::PointJacobian);
        assert_eq!(read.first_iteration, FirstIteration::Unbounded);
        // The memory estimate counts the regression prior's kept states and actions: 2 conditions
        // x 20 trajectories x 15 steps x (2 + 1) f64s.
        let total = |c: &MdgpsConfig| c.memory(2, T, 2, 1, 2).total().unwrap();
        let jacobian = MdgpsConfig {
            linearization: Linearization::PointJacobian,
            ..ok.clone()
        };
        assert_eq!(total(&ok) - total(&jacobian), 2 * 20 * T as u64 * 3 * 8);
    }

    /// The linearization of a policy is its Jacobian: for a network that is linear (no hidden
    /// layer) it reproduces the weights exactly.
    /// Trajectories of unit-variance noise on the double integrator from `(1, 0)`: states to
    /// linearize a policy around.
    fn noise_samples(rng: &mut Rng) -> TrajectorySamples {
        noise_samples_of(1.0, rng)
    }

    /// [`noise_samples`] with noise of `variance`.
    fn noise_samples_of(variance: f64, rng: &mut Rng) -> TrajectorySamples {
        let p = problem(&[[1.0, 0.0]]);
        sample_trajectories(
            &TvlgController::constant(T, 2, &[0.0], variance).unwrap(),
            &*p.system,
            &p.conditions[0].objective,
            &p.conditions[0].x0,
            &SampleConfig::default(),
            rng,
        )
        .unwrap()
    }

    #[test]
    fn linearizing_a_linear_policy_gives_its_weights() {
        let mut rng = rng_from_seed(1);
        let policy = GlobalPolicy::new(2, 1, &[], 0.3, None, &mut rng).unwrap();
        let w = policy.net().weight(0).to_vec();
        let bias = policy.net().bias(0)[0];
        let lin = linearize(&policy, &noise_samples(&mut rng)).unwrap();
        for t in [0, 7, T - 1] {
            for (j, wj) in w.iter().enumerate() {
                let err = (lin.gains[t][(0, j)] - f64::from(*wj)).abs();
                assert!(err < 1e-3, "step {t}, state {j}: {err}");
            }
            assert!((lin.offsets[t][0] - f64::from(bias)).abs() < 1e-5);
            assert_eq!(lin.cov[t][(0, 0)], 0.3);
        }
    }

    /// Through features `o(x) = (x₀ + x₁, x₀ − x₁, 2x₀)`, a linear net `w·o + b` is the linear
    /// policy `(w₀ + w₁ + 2w₂) x₀ + (w₀ − w₁) x₁ + b` of the state, and the linearization is
    /// taken in the state.
    #[test]
    fn a_policy_over_features_linearizes_in_the_state() {
        let mut rng = rng_from_seed(2);
        let input = tandem_agents::PolicyInput {
            dim: 3,
            map: std::sync::Arc::new(|x: &[f64], o: &mut [f64]| {
                o.copy_from_slice(&[x[0] + x[1], x[0] - x[1], 2.0 * x[0]]);
            }),
        };
        let policy = GlobalPolicy::new(2, 1, &[], 0.3, Some(input), &mut rng).unwrap();
        let w: Vec<f64> = policy
            .net()
            .weight(0)
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let bias = f64::from(policy.net().bias(0)[0]);
        let gains = [w[0] + w[1] + 2.0 * w[2], w[0] - w[1]];
        let mut ws = policy.net().workspace();
        let x = [0.3, -1.2];
        let mean = policy.mean(&x, &mut ws).unwrap()[0];
        assert!((mean - (gains[0] * x[0] + gains[1] * x[1] + bias)).abs() < 1e-5);
        let lin = linearize(&policy, &noise_samples(&mut rng)).unwrap();
        for t in [0, T - 1] {
            for (j, g) in gains.iter().enumerate() {
                let err = (lin.gains[t][(0, j)] - g).abs();
                assert!(err < 1e-3, "step {t}, state {j}: {err}");
            }
        }
        assert!(policy.mean(&[0.0; 3], &mut ws).is_err());
    }

    /// A policy whose network is a line (no hidden layer) is recovered by the regression too:
    /// gains its weights, offset its bias, and the covariance its own variance (the residual is
    /// the network's `f32` rounding). From step 3: before, the positions have hardly spread from
    /// the common start (at step 0 not at all, and the prior alone sets the gain there), and the
    /// `regularization` of 10⁻⁶ shrinks the gain measurably (4·10⁻³ at step 1, 4·10⁻⁴ at step 3,
    /// 10⁻⁵ at the last).
    #[test]
    fn regression_linearizes_a_linear_policy_to_its_weights() {
        let mut rng = rng_from_seed(1);
        let policy = GlobalPolicy::new(2, 1, &[], 0.3, None, &mut rng).unwrap();
        let w = policy.net().weight(0).to_vec();
        let bias = f64::from(policy.net().bias(0)[0]);
        let samples = noise_samples(&mut rng);
        let mut fit = TvlgPolicyFit::new(PolicyFitConfig::default());
        let lin = linearize_by_regression(&policy, &samples, &mut fit).unwrap();
        assert_eq!(fit.kept_trajectories(), samples.len());
        for t in 3..T {
            for (j, wj) in w.iter().enumerate() {
                let err = (lin.gains[t][(0, j)] - f64::from(*wj)).abs();
                assert!(err < 1e-3, "step {t}, state {j}: {err}");
            }
            assert!((lin.offsets[t][0] - bias).abs() < 1e-3, "step {t}");
            assert!((lin.cov[t][(0, 0)] - 0.3).abs() < 1e-6, "step {t}");
        }
    }

    /// `policy` with its network's parameters replaced by `params` (through a checkpoint: the
    /// policy has no setter, and its standardization stays the identity of an unfitted policy).
    fn with_params(policy: &mut GlobalPolicy, params: &[f32]) {
        let mut ckpt = Checkpoint::new();
        policy.save_to("p", &mut ckpt).unwrap();
        let mut net = policy.net().clone();
        net.set_params(params).unwrap();
        net.save_to("p.net", &mut ckpt).unwrap();
        policy.load_from("p", &ckpt).unwrap();
    }

    /// A policy steep at the samples' mean but saturated around it: `u = clamp(w (x₀ − x̄₀), ±wδ)`
    /// with `w = 1000`, `δ = 0.002` (two ReLUs), at one step's mean position `x̄₀` of noise
    /// samples (variance 100) on the double integrator. The point Jacobian there is the slope
    /// `w`; the regression over the samples, spread far beyond `±δ`, sees an almost constant
    /// policy: its gain is bounded by the spread of the policy's actions over the samples'
    /// positions (Cauchy–Schwarz, with a margin for the second state) and two orders smaller than
    /// the point Jacobian, and the policy's departure from linear widens the covariance beyond
    /// `σ²`.
    #[test]
    fn regression_is_bounded_where_the_point_jacobian_runs_away() {
        let mut rng = rng_from_seed(5);
        let samples = noise_samples_of(100.0, &mut rng);
        let t = 10;
        let xs: Vec<f64> = (0..samples.len())
            .map(|i| samples.states[[i, t, 0]])
            .collect();
        let xbar = xs.iter().sum::<f64>() / xs.len() as f64;
        let (w, delta) = (1000.0f32, 0.002f32);
        let mut policy = GlobalPolicy::new(2, 1, &[2], 0.05, None, &mut rng).unwrap();
        // Hidden: relu(x₀ − x̄₀ + δ), relu(x₀ − x̄₀ − δ); output w (h₁ − h₂) − w δ.
        let c = xbar as f32;
        with_params(
            &mut policy,
            &[
                1.0,
                0.0,
                1.0,
                0.0,
                -c + delta,
                -c - delta,
                w,
                -w,
                -w * delta,
            ],
        );
        let mut ws = policy.net().workspace();
        let u: Vec<f64> = xs
            .iter()
            .enumerate()
            .map(|(i, _)| {
                let x = [samples.states[[i, t, 0]], samples.states[[i, t, 1]]];
                policy.mean(&x, &mut ws).unwrap()[0]
            })
            .collect();
        let std = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|a| (a - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let bound = std(&u) / std(&xs);
        let point = linearize(&policy, &samples).unwrap();
        let mut fit = TvlgPolicyFit::new(PolicyFitConfig::default());
        let lin = linearize_by_regression(&policy, &samples, &mut fit).unwrap();
        let (kp, kr) = (point.gains[t][(0, 0)], lin.gains[t][(0, 0)]);
        let (cov, sigma2) = (lin.cov[t][(0, 0)], policy.variance[0]);
        eprintln!(
            "point Jacobian {kp}, regression gain {kr} (and {}), std(u)/std(x) {bound}, \
             S {cov} against σ² {sigma2}",
            lin.gains[t][(0, 1)]
        );
        assert!((kp - f64::from(w)).abs() < 1.0, "point Jacobian {kp}");
        assert!(kr.abs() <= 2.0 * bound, "regression {kr}, bound {bound}");
        assert!(kr.abs() < kp / 100.0, "regression {kr}, point {kp}");
        assert!(cov > sigma2 + 0.1 * std(&u).powi(2), "S {cov}, σ² {sigma2}");
        for s in 0..T {
            assert!(lin.cov[s][(0, 0)] >= sigma2, "step {s}");
        }
    }

    /// An MDGPS run stopped after any iteration resumes from its checkpoint and ends exactly as
    /// an uninterrupted one (curve, failures, the policy's parameters and variances), for every
    /// local method and both linearizations: the local controllers, the policy's network,
    /// standardization and Adam state, the step rule's multiplier and anchors, the regression's
    /// policy priors, and the generator travel with it. A checkpoint of
    /// another seed is refused.
    #[test]
    fn a_run_stopped_after_any_iteration_resumes_to_the_same_record() {
        let p = problem(&[[1.0, 0.0], [0.0, -1.0]]);
        let test = TestSet {
            starts: vec![vec![0.7, 0.3], vec![-0.4, -0.8]],
            measure: Box::new(|x| x[0].abs()),
            solved: None,
        };
        let mut c = MdgpsConfig {
            local: cfg(4),
            policy: PolicyConfig {
                hidden: vec![8],
                epochs: 5,
                batch_size: 32,
                learning_rate: 3e-3,
                weighting: Weighting::Uniform,
            },
            step: MdgpsStep {
                adjust: true,
                ..Default::default()
            },
            linearization: Linearization::default(),
            first_iteration: FirstIteration::default(),
        };
        c.local.samples = 5;
        let batch = (2 * c.local.samples) as u64;
        let regression = Linearization::default();
        for (method, weighting, linearization) in [
            (LocalMethod::LqrFlm, Weighting::Uniform, regression.clone()),
            (LocalMethod::Pi2, Weighting::Precision, regression.clone()),
            (LocalMethod::Pilqr, Weighting::Uniform, regression),
            (
                LocalMethod::LqrFlm,
                Weighting::Uniform,
                Linearization::PointJacobian,
            ),
        ] {
            c.policy.weighting = weighting;
            c.linearization = linearization;
            let run = |store: &mut dyn Checkpoints, on: &mut dyn FnMut(u64)| {
                train_mdgps(method, &p, &test, &c, 3, store, on)
            };
            let whole = run(&mut Ephemeral, &mut |_| {}).unwrap();
            for stop_after in 1..c.local.iterations as u64 {
                let mut store = InMemory::default();
                let stop = store.stop_flag();
                let e = run(&mut store, &mut |n| stop.set(n == stop_after * batch))
                    .err()
                    .unwrap();
                assert!(matches!(e, AlgoError::Stopped), "{e}");
                stop.set(false);
                let mut first = None;
                let resumed = run(&mut store, &mut |n| {
                    first.get_or_insert(n);
                })
                .unwrap();
                let lin = match c.linearization {
                    Linearization::Regression(_) => "regression",
                    Linearization::PointJacobian => "point Jacobian",
                };
                let case = format!("{} ({lin}) stopped after {stop_after}", method.name());
                assert_eq!(first, Some(stop_after * batch + c.local.samples as u64));
                assert_eq!(resumed.curve, whole.curve, "{case}");
                assert_eq!(resumed.failed_updates, whole.failed_updates, "{case}");
                assert_eq!(resumed.policy.net().params(), whole.policy.net().params());
                assert_eq!(resumed.policy.variance, whole.policy.variance, "{case}");
            }
        }
        let mut store = InMemory::default();
        let pi2 = |seed, store: &mut dyn Checkpoints| {
            train_mdgps(LocalMethod::Pi2, &p, &test, &c, seed, store, &mut |_| {})
        };
        pi2(3, &mut store).unwrap();
        let e = pi2(4, &mut store).err().unwrap();
        assert!(e.to_string().contains("mdgps_pi2 seed 3"), "{e}");
    }
}
