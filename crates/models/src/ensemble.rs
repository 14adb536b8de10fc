//! [`ProbabilisticEnsemble`]: `K` Gaussian MLPs predicting the state change and the reward, with
//! held-out elite selection and PETS's propagation modes (p3's dynamics model; Chua et al. 2018,
//! Janner et al. 2019).

use ndarray::{Array1, Array2};
use rand::seq::SliceRandom;
use rand::Rng as _;
use rand_distr::{Distribution, StandardNormal};
use std::sync::Mutex;
use tandem_core::seeding::SeedStream;
use tandem_core::Rng;
use tandem_nn::budget::{widths, MemoryEstimate};
use tandem_nn::{
    fastmath, gaussian_nll, map_side_by_side, Activation, Checkpoint, Checkpointable, GaussianHead,
    GaussianOutput, Mlp, MlpConfig, MlpWorkspace, NnError, RowBlock, RowDealer,
};

use crate::data::check_input;
use crate::model::{
    DynamicsModel, FitConfig, FitReport, ModelError, ModelInput, Prediction, Transitions,
};
use crate::train::{
    nn_other, nn_train, FitRows, FitSpec, Opt, OptimizerConfig, Standardized, Standardizer,
    Stopper, Targets,
};

/// How a batch is propagated through the ensemble (PETS, Sec. 4.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Propagation {
    /// Every row picks a random elite at every call (PETS "TS1"; MBPO's model rollouts).
    RandomMember,
    /// Row `i` always uses elite `(i + offset) mod E` (PETS "TS∞"): a planner that keeps a
    /// trajectory in the same row keeps its member for the whole rollout. `offset` is set with
    /// [`ProbabilisticEnsemble::set_member_offset`] (e.g. drawn anew for each plan).
    FixedMember,
    /// The elites' mixture moments: mean of the means, and variance = mean of the variances +
    /// variance of the means (aleatoric + epistemic). Deterministic.
    Expectation,
}

/// Which data each member trains on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MemberData {
    /// A bootstrap resample (with replacement) of the training rows, drawn per fit (PETS).
    Bootstrap,
    /// All training rows, each member in its own shuffled order (MBPO's practice).
    Shuffle,
}

/// Settings of a [`ProbabilisticEnsemble`]. `Default` = MBPO's model (the PETS/MBPO line p3
/// builds on; p3 gives no sizes): 7 members, 5 elites, 4 hidden layers of 200 SiLU units, Adam
/// 1e-3, log-variance bounded softly to `[-10, 0.5]` with learned bounds (PETS penalty
/// `0.01 (Σ max − Σ min)`), bootstrapped members, random-member propagation with sampling.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnsembleConfig {
    /// Number of members `K`.
    pub members: usize,
    /// Number of elites used for prediction (`<= members`).
    pub elites: usize,
    /// Hidden widths of each member.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Optimizer of each member.
    pub optimizer: OptimizerConfig,
    /// Initial lower bound of the log-variance (standardized units).
    pub min_log_var: f32,
    /// Initial upper bound of the log-variance (standardized units).
    pub max_log_var: f32,
    /// Learn the bounds with the PETS penalty (else they stay fixed).
    pub learn_log_var_bounds: bool,
    /// Bootstrap or shuffled members.
    pub member_data: MemberData,
    /// Propagation mode of `predict` (changeable with
    /// [`ProbabilisticEnsemble::set_propagation`]).
    pub propagation: Propagation,
    /// In the member modes, return a sample of the member's Gaussian (PETS particles) rather
    /// than its mean. Rewards are always the mean (p3 uses a deterministic reward estimate).
    pub sample: bool,
    /// Learn the reward as an extra Gaussian output.
    pub learn_reward: bool,
    /// Seed of the weight initialization.
    pub seed: u64,
}

impl Default for EnsembleConfig {
    fn default() -> Self {
        Self {
            members: 7,
            elites: 5,
            hidden: vec![200, 200, 200, 200],
            activation: Activation::Silu,
            optimizer: OptimizerConfig::adam(1e-3),
            min_log_var: -10.0,
            max_log_var: 0.5,
            learn_log_var_bounds: true,
            member_data: MemberData::Bootstrap,
            propagation: Propagation::RandomMember,
            sample: true,
            learn_reward: true,
            seed: 0,
        }
    }
}

impl EnsembleConfig {
    /// Checks the ranges an ensemble relies on: `1 <= elites <= members`, positive hidden
    /// widths, finite log-variance bounds with `min_log_var < max_log_var`, the optimizer's.
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Other(m));
        if self.members == 0 || self.elites == 0 || self.elites > self.members {
            return bad(format!(
                "ensemble needs 1 <= elites <= members, got {} elites of {} members",
                self.elites, self.members
            ));
        }
        if self.hidden.contains(&0) {
            return bad(format!(
                "ensemble hidden widths {:?} must be positive",
                self.hidden
            ));
        }
        let (lo, hi) = (self.min_log_var, self.max_log_var);
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return bad(format!(
                "ensemble log-variance bounds need finite min_log_var < max_log_var, got {lo} and {hi}"
            ));
        }
        self.optimizer.validate()
    }

    /// The layer widths of each member for `state_dim`-dimensional states and
    /// `action_dim`-dimensional actions: `[s, a]` in, mean and log-variance of `[Δs, r]` out.
    pub fn sizes(&self, state_dim: usize, action_dim: usize) -> Vec<usize> {
        let dim = state_dim.saturating_add(usize::from(self.learn_reward));
        widths(
            state_dim.saturating_add(action_dim),
            &self.hidden,
            dim.saturating_mul(2),
        )
    }

    /// The memory of the ensemble trained on minibatches of `batch` rows: every member's
    /// parameters with their gradients and optimizer state, and one training pass's activations.
    pub fn memory(&self, state_dim: usize, action_dim: usize, batch: usize) -> MemoryEstimate {
        let one =
            self.optimizer
                .network_memory("member", &self.sizes(state_dim, action_dim), batch);
        MemoryEstimate::new().part(
            format!("ensemble ({} members of {:?})", self.members, self.hidden),
            one.total().and_then(|b| b.checked_mul(self.members as u64)),
        )
    }
}

/// One Gaussian MLP with its optimizers.
#[derive(Debug, Clone)]
struct Member {
    net: Mlp,
    opt: Opt,
    head: GaussianHead,
    bounds_opt: Opt,
}

/// A probabilistic ensemble: each member maps standardized `[s, a]` to a Gaussian over the
/// standardized `[Δs, r]` (mean and bounded log-variance) and is trained by Gaussian negative
/// log-likelihood (summed over outputs, averaged over the batch). After each fit the `elites`
/// members with the lowest held-out mean squared error are the ones that predict.
///
/// `predict` follows [`EnsembleConfig::propagation`]; [`Prediction::variance`] is the chosen
/// member's variance (member modes) or the mixture variance (expectation), in state units;
/// [`Prediction::rewards`] is the mean reward. Fit reports give the mean over members of the
/// per-element NLL (including `½ ln 2π`) on training and held-out rows, per epoch. Each fit
/// continues from the current weights; a failed fit changes nothing.
///
/// ```
/// use ndarray::array;
/// use tandem_core::seeding::rng_from_seed;
/// use tandem_models::{DynamicsModel, EnsembleConfig, FitConfig, ModelInput,
///     ProbabilisticEnsemble, Propagation, TransitionsBuilder};
///
/// let mut b = TransitionsBuilder::new(1, 1);
/// for i in 0..100 {
///     let (s, a) = (i as f64 / 50.0 - 1.0, ((i * 7) % 10) as f64 / 5.0 - 1.0);
///     b.push([s], &[a], &[s + 0.1 * a], -s * s, false).unwrap();
/// }
/// let cfg = EnsembleConfig { members: 3, elites: 2, hidden: vec![16], ..Default::default() };
/// let mut ens = ProbabilisticEnsemble::new(1, 1, cfg).unwrap();
/// ens.fit(&b.build(), &FitConfig { epochs: 5, batch_size: 32, ..Default::default() }).unwrap();
/// ens.set_propagation(Propagation::Expectation);
/// let (s, a) = (array![[0.0]], array![[0.5]]);
/// let p = ens.predict(&ModelInput::new(s.view(), a.view()), &mut rng_from_seed(0)).unwrap();
/// assert!(p.variance.is_some() && p.rewards.is_some());
/// assert_eq!(ens.elites().len(), 2);
/// ```
#[derive(Debug, Clone)]
pub struct ProbabilisticEnsemble {
    cfg: EnsembleConfig,
    state_dim: usize,
    action_dim: usize,
    /// The members; their targets `[Δs, r]`.
    learned: Standardized<Vec<Member>>,
    elites: Vec<usize>,
    holdout_mse: Vec<f64>,
    propagation: Propagation,
    member_offset: usize,
    scratch: Scratch,
}

impl ProbabilisticEnsemble {
    /// An ensemble for the given widths, members initialized from independent streams of
    /// `cfg.seed`.
    pub fn new(
        state_dim: usize,
        action_dim: usize,
        cfg: EnsembleConfig,
    ) -> Result<Self, ModelError> {
        if state_dim == 0 {
            return Err(ModelError::Dim {
                what: "state_dim (must be positive)".into(),
                expected: 1,
                got: 0,
            });
        }
        cfg.validate()?;
        let dim = state_dim + usize::from(cfg.learn_reward);
        let sizes = cfg.sizes(state_dim, action_dim);
        let seeds = SeedStream::new(cfg.seed);
        let mut members = Vec::with_capacity(cfg.members);
        for k in 0..cfg.members {
            let net = Mlp::new(
                MlpConfig::new(&sizes).hidden(cfg.activation),
                &mut seeds.rng(&format!("member-{k}")),
            )
            .map_err(nn_other)?;
            let head = GaussianHead::with_bounds(dim, cfg.min_log_var, cfg.max_log_var)
                .map_err(nn_other)?;
            members.push(Member {
                opt: cfg.optimizer.build(net.num_params())?,
                bounds_opt: cfg.optimizer.build(2 * dim)?,
                net,
                head,
            });
        }
        Ok(Self {
            elites: (0..cfg.elites).collect(),
            holdout_mse: vec![f64::NAN; cfg.members],
            propagation: cfg.propagation,
            member_offset: 0,
            scratch: Scratch::default(),
            state_dim,
            action_dim,
            learned: Standardized::new(members, [state_dim, action_dim], dim),
            cfg,
        })
    }

    /// Its settings.
    pub fn config(&self) -> &EnsembleConfig {
        &self.cfg
    }

    /// Indices of the elite members, best first.
    pub fn elites(&self) -> &[usize] {
        &self.elites
    }

    /// Each member's held-out mean squared error (standardized units) after the last fit.
    pub fn member_holdout_mse(&self) -> &[f64] {
        &self.holdout_mse
    }

    /// The propagation mode of `predict`.
    pub fn propagation(&self) -> Propagation {
        self.propagation
    }

    /// Sets the propagation mode of `predict`.
    pub fn set_propagation(&mut self, p: Propagation) {
        self.propagation = p;
    }

    /// Sets the row-to-member offset of [`Propagation::FixedMember`].
    pub fn set_member_offset(&mut self, offset: usize) {
        self.member_offset = offset;
    }

    /// Draws a new row-to-member offset for [`Propagation::FixedMember`].
    pub fn resample_member_offset(&mut self, rng: &mut Rng) {
        self.member_offset = rng.random_range(0..self.elites.len());
    }

    /// The network of member `k` (for checkpoints and inspection).
    pub fn member_network(&self, k: usize) -> Option<&Mlp> {
        self.learned.trained.get(k).map(|m| &m.net)
    }

    /// Width of the Gaussian output (`S`, plus one with the reward).
    fn out_dim(&self) -> usize {
        self.state_dim + usize::from(self.cfg.learn_reward)
    }

    /// Runs every elite on its rows of the standardized inputs `x` (`b` rows of `din`): elite
    /// slot `i` (member `self.elites[i]`) takes the rows `assign` gives it (all rows when `assign`
    /// is `None`), its standardized means and variances left in `bufs.slots[i]` with its row
    /// indices. When the work is large enough to pay for it, the slots' rows are dealt in equal
    /// blocks to as many groups as rayon's pool has threads ([`RowDealer`]), run side by side
    /// (one elite per thread left one of two threads idle a third of the pass with five elites).
    /// A slot's rows are cut only where each block gets exactly the numbers of the whole slot's
    /// pass ([`Mlp::rows_run_apart`]), and every block has its own buffers, so the numbers do not
    /// depend on the threads.
    fn elite_forwards(
        &self,
        x: &[f32],
        b: usize,
        assign: Option<&[usize]>,
        bufs: &mut EliteScratch,
    ) -> Result<(), ModelError> {
        let din = self.state_dim + self.action_dim;
        let dim = self.out_dim();
        let e = self.elites.len();
        let EliteScratch { slots, dealer } = bufs;
        slots.resize_with(e, SlotScratch::default);
        for (i, sc) in slots.iter_mut().enumerate() {
            sc.rows.clear();
            match assign {
                None => sc.rows.extend(0..b),
                Some(assign) => {
                    sc.rows.extend((0..b).filter(|&r| assign[r] == i));
                    sc.x.clear();
                    for &r in &sc.rows {
                        sc.x.extend_from_slice(&x[r * din..(r + 1) * din]);
                    }
                }
            }
        }
        let threads =
            RowDealer::<BlockScratch>::threads_for(b * self.learned.trained[0].net.num_params());
        let net = |i: usize| &self.learned.trained[self.elites[i]].net;
        dealer.deal(
            e,
            |i| slots[i].rows.len(),
            threads,
            |i, whole, part| net(i).rows_run_apart(whole, part),
        );
        let run = |bl: &mut RowBlock<BlockScratch>| -> tandem_nn::Result<()> {
            let m = &self.learned.trained[self.elites[bl.slot]];
            let input = match assign {
                None => x,
                Some(_) => &slots[bl.slot].x[..],
            };
            let rows = bl.end - bl.start;
            let bufs = &mut bl.bufs;
            let out = m
                .net
                .forward(&input[bl.start * din..bl.end * din], rows, &mut bufs.ws)?;
            m.head.predict(out, rows, &mut bufs.g)?;
            // Variances from log-variances, in place, while the block is hot.
            fastmath::apply(fastmath::Function::Exp, &mut bufs.g.log_var);
            Ok(())
        };
        dealer.run(&run).map_err(nn_other)?;
        let blocks = dealer.blocks_mut();
        // Each slot's outputs in row order (the blocks are in slot and row order); a slot in one
        // block takes that block's buffers as they are.
        let mut k = 0;
        for (i, sc) in slots.iter_mut().enumerate() {
            let first = k;
            while k < blocks.len() && blocks[k].slot == i {
                k += 1;
            }
            match &mut blocks[first..k] {
                [one] => {
                    std::mem::swap(&mut sc.mean, &mut one.bufs.g.mean);
                    std::mem::swap(&mut sc.var, &mut one.bufs.g.log_var);
                }
                several => {
                    sc.mean.clear();
                    sc.var.clear();
                    for bl in several {
                        sc.mean.extend_from_slice(&bl.bufs.g.mean);
                        sc.var.extend_from_slice(&bl.bufs.g.log_var);
                    }
                }
            }
            debug_assert_eq!(sc.mean.len(), sc.rows.len() * dim);
        }
        Ok(())
    }
}

/// Reusable buffers of one elite slot's batched inference: its row indices, its gathered inputs
/// (when the rows are assigned to elites) and its standardized means and variances.
#[derive(Debug, Default)]
struct SlotScratch {
    rows: Vec<usize>,
    x: Vec<f32>,
    mean: Vec<f32>,
    var: Vec<f32>,
}

/// Reusable buffers of one block of a slot's rows: the network's workspace and the Gaussian
/// outputs.
#[derive(Debug, Default)]
struct BlockScratch {
    ws: MlpWorkspace,
    g: GaussianOutput,
}

/// All buffers of the elites' inference.
#[derive(Debug, Default)]
struct EliteScratch {
    slots: Vec<SlotScratch>,
    dealer: RowDealer<BlockScratch>,
}

/// The elites' inference buffers behind a mutex, so that `predict` through `&self` allocates only
/// its result when called again at the same batch size (a planner's rollouts, MBPO's 100 000
/// imagined rows). A contended lock falls back to fresh buffers, so concurrent callers never wait
/// and get the same numbers. Cloning gives empty buffers.
#[derive(Debug, Default)]
struct Scratch(Mutex<EliteScratch>);

impl Clone for Scratch {
    fn clone(&self) -> Self {
        Self::default()
    }
}

/// What a fit learned, besides the members: elites, their scores, the standardizations and the
/// propagation state.
#[derive(serde::Serialize, serde::Deserialize)]
struct Learned {
    elites: Vec<usize>,
    holdout_mse: Vec<f64>,
    norms: (Standardizer, Standardizer, Standardizer),
    propagation: Propagation,
    member_offset: usize,
}

/// The learned part (every member's network, optimizer states and log-variance bounds, the
/// elites and their held-out scores, the standardizations, the propagation mode and offset);
/// widths and settings are the constructor's. Loading into an ensemble of other widths or
/// another member count is an error naming the entry, and leaves the ensemble unchanged. A
/// run that saves and loads its ensemble predicts and fits on exactly as one that did not.
impl Checkpointable for ProbabilisticEnsemble {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        for (k, m) in self.learned.trained.iter().enumerate() {
            let p = format!("{prefix}.member{k}");
            m.net.save_to(&format!("{p}.net"), ckpt)?;
            m.opt.save_to(&format!("{p}.opt"), ckpt)?;
            m.bounds_opt.save_to(&format!("{p}.bounds_opt"), ckpt)?;
            let b = m.head.bounds();
            ckpt.put_f32(&format!("{p}.bounds"), &[b.len()], b)?;
        }
        let learned = Learned {
            elites: self.elites.clone(),
            holdout_mse: self.holdout_mse.clone(),
            norms: (
                self.learned.inputs[0].clone(),
                self.learned.inputs[1].clone(),
                self.learned.targets.clone(),
            ),
            propagation: self.propagation,
            member_offset: self.member_offset,
        };
        ckpt.put_json(&format!("{prefix}.learned"), &learned)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let name = format!("{prefix}.learned");
        let l: Learned = ckpt.get_json(&name)?;
        let (s, a, d) = (self.state_dim, self.action_dim, self.out_dim());
        let widths = (l.norms.0.dim(), l.norms.1.dim(), l.norms.2.dim());
        let k = self.learned.trained.len();
        if widths != (s, a, d)
            || l.holdout_mse.len() != k
            || l.elites.len() != self.cfg.elites
            || l.elites.iter().any(|&e| e >= k)
        {
            return Err(NnError::Checkpoint(format!(
                "`{name}`: an ensemble of widths {widths:?} with {} scores and elites {:?}; this one \
                 has widths {:?}, {k} members and {} elites",
                l.holdout_mse.len(),
                l.elites,
                (s, a, d),
                self.cfg.elites
            )));
        }
        let mut members = self.learned.trained.clone();
        for (k, m) in members.iter_mut().enumerate() {
            let p = format!("{prefix}.member{k}");
            m.net.load_from(&format!("{p}.net"), ckpt)?;
            m.opt.load_from(&format!("{p}.opt"), ckpt)?;
            m.bounds_opt.load_from(&format!("{p}.bounds_opt"), ckpt)?;
            let n = m.head.bounds().len();
            ckpt.read_f32_into(&format!("{p}.bounds"), &[n], m.head.bounds_mut())?;
        }
        let (in_state, in_action, out_norm) = l.norms;
        self.learned = Standardized {
            trained: members,
            inputs: [in_state, in_action],
            targets: out_norm,
        };
        self.elites = l.elites;
        self.holdout_mse = l.holdout_mse;
        self.propagation = l.propagation;
        self.member_offset = l.member_offset;
        Ok(())
    }
}

/// One member's epoch: its mean training NLL and, with a holdout, its held-out (NLL, MSE).
type EpochLosses = (f64, Option<(f64, f64)>);

/// One member in a fit: its training rows (a bootstrap or all of them), its random stream and
/// its buffers.
struct MemberFit<'a> {
    member: &'a mut Member,
    rng: Rng,
    rows: Vec<usize>,
    scratch: FitScratch,
}

/// Reusable buffers of one member's training steps.
#[derive(Default)]
struct FitScratch {
    ws: MlpWorkspace,
    xb: Vec<f32>,
    yb: Vec<f32>,
    g: GaussianOutput,
    d_mean: Vec<f32>,
    d_lv: Vec<f32>,
    d_out: Vec<f32>,
    d_bounds: Vec<f32>,
    grads: Vec<f32>,
}

/// Held-out `(nll per element, mse per element)` of one member, in the buffers of its training
/// steps (a fresh workspace for each epoch's evaluation cost page faults).
fn member_eval(
    m: &Member,
    data: &FitRows,
    idx: &[usize],
    sc: &mut FitScratch,
) -> Result<(f64, f64), tandem_nn::NnError> {
    if idx.is_empty() {
        return Ok((f64::NAN, f64::NAN));
    }
    let FitScratch { ws, xb, yb, g, .. } = sc;
    let (mut nll, mut mse) = (0.0, 0.0);
    for chunk in idx.chunks(1024) {
        data.gather_inputs(chunk, xb);
        data.gather_targets(chunk, yb);
        let out = m.net.forward(xb, chunk.len(), ws)?;
        m.head.predict(out, chunk.len(), g)?;
        let l = gaussian_nll(&g.mean, &g.log_var, yb, None, None)?;
        nll += f64::from(l) * chunk.len() as f64;
        mse += g
            .mean
            .iter()
            .zip(yb.iter())
            .map(|(p, t)| f64::from((p - t) * (p - t)))
            .sum::<f64>()
            / data.dout as f64;
    }
    Ok((nll / idx.len() as f64, mse / idx.len() as f64))
}

impl DynamicsModel for ProbabilisticEnsemble {
    fn state_dim(&self) -> usize {
        self.state_dim
    }

    fn action_dim(&self) -> usize {
        self.action_dim
    }

    fn predict(&self, input: &ModelInput<'_>, rng: &mut Rng) -> Result<Prediction, ModelError> {
        let b = check_input(input, self.state_dim, self.action_dim)?;
        let (s, dim) = (self.state_dim, self.out_dim());
        let mut x = Vec::new();
        self.learned
            .inputs_into(input.states, input.actions, b, &mut x);
        let mut next = input.states.to_owned();
        let mut var = Array2::zeros((b, s));
        let mut rewards = self.cfg.learn_reward.then(|| Array1::zeros(b));
        let e = self.elites.len();
        let mut guard = self.scratch.0.try_lock();
        let mut fresh = EliteScratch::default();
        let bufs = match guard.as_deref_mut() {
            Ok(bufs) => bufs,
            Err(_) => &mut fresh,
        };
        match input.propagation.unwrap_or(self.propagation) {
            Propagation::Expectation => {
                self.elite_forwards(&x, b, None, bufs)?;
                // Mixture moments in original units.
                let mut mean_acc = Array2::<f64>::zeros((b, dim));
                let mut sq_acc = Array2::<f64>::zeros((b, dim));
                let mut var_acc = Array2::<f64>::zeros((b, dim));
                for sc in &bufs.slots[..e] {
                    for r in 0..b {
                        for j in 0..dim {
                            let mu = self.learned.targets.invert(j, sc.mean[r * dim + j]);
                            let sd = self.learned.targets.std[j];
                            let v = f64::from(sc.var[r * dim + j]) * sd * sd;
                            mean_acc[[r, j]] += mu;
                            sq_acc[[r, j]] += mu * mu;
                            var_acc[[r, j]] += v;
                        }
                    }
                }
                let ef = e as f64;
                for r in 0..b {
                    for j in 0..dim {
                        let m = mean_acc[[r, j]] / ef;
                        let v = var_acc[[r, j]] / ef + (sq_acc[[r, j]] / ef - m * m).max(0.0);
                        if j < s {
                            next[[r, j]] += m;
                            var[[r, j]] = v;
                        } else if let Some(rw) = rewards.as_mut() {
                            rw[r] = m;
                        }
                    }
                }
            }
            mode => {
                // The elite slot of each row.
                let assign: Vec<usize> = match mode {
                    Propagation::RandomMember => (0..b).map(|_| rng.random_range(0..e)).collect(),
                    _ => (0..b).map(|r| (r + self.member_offset) % e).collect(),
                };
                self.elite_forwards(&x, b, Some(&assign), bufs)?;
                // Noise is drawn elite by elite, rows in order: the same stream whatever ran in
                // parallel.
                for sc in &bufs.slots[..e] {
                    for (q, &r) in sc.rows.iter().enumerate() {
                        for j in 0..dim {
                            let mu = self.learned.targets.invert(j, sc.mean[q * dim + j]);
                            let sd = self.learned.targets.std[j];
                            let v = f64::from(sc.var[q * dim + j]) * sd * sd;
                            if j < s {
                                let noise: f64 = if self.cfg.sample {
                                    StandardNormal.sample(rng)
                                } else {
                                    0.0
                                };
                                next[[r, j]] += mu + v.sqrt() * noise;
                                var[[r, j]] = v;
                            } else if let Some(rw) = rewards.as_mut() {
                                rw[r] = mu;
                            }
                        }
                    }
                }
            }
        }
        Ok(Prediction {
            next_states: next,
            variance: Some(var),
            rewards,
            terminal_prob: None,
        })
    }

    fn fit(&mut self, data: &Transitions, cfg: &FitConfig) -> Result<FitReport, ModelError> {
        data.validate(self.state_dim, self.action_dim)?;
        let spec = FitSpec {
            inputs: [data.states.view(), data.actions.view()],
            targets: Targets::StateChange {
                reward: self.cfg.learn_reward,
            },
            filter: None,
        };
        let seeds = SeedStream::new(cfg.seed);
        let ens = &self.cfg;
        let (report, elites, holdout_mse) = self.learned.fit(
            data,
            cfg,
            spec,
            &mut seeds.rng("holdout"),
            |members, rows, _| train_members(members, rows, cfg, ens, &seeds),
        )?;
        self.elites = elites;
        self.holdout_mse = holdout_mse;
        Ok(report)
    }
}

/// Trains every member on `data` (its bootstrap or shuffle of the training rows drawn from its
/// stream of `seeds`) for `cfg.epochs` epochs; returns the report (mean over members per epoch),
/// the elites (lowest held-out MSE first; training MSE without a holdout) and each member's MSE.
fn train_members(
    members: &mut [Member],
    data: &FitRows,
    cfg: &FitConfig,
    ens: &EnsembleConfig,
    seeds: &SeedStream,
) -> Result<(FitReport, Vec<usize>, Vec<f64>), ModelError> {
    let dim = data.dout;
    let mut fits: Vec<MemberFit<'_>> = members
        .iter_mut()
        .enumerate()
        .map(|(k, member)| {
            let mut rng = seeds.rng(&format!("member-{k}"));
            let rows = match ens.member_data {
                MemberData::Bootstrap => (0..data.train.len())
                    .map(|_| data.train[rng.random_range(0..data.train.len())])
                    .collect(),
                MemberData::Shuffle => data.train.clone(),
            };
            MemberFit {
                member,
                rng,
                rows,
                scratch: FitScratch::default(),
            }
        })
        .collect();

    let bs = cfg.batch_size.max(1);
    let mut report = FitReport::default();
    let mut hold_mse = vec![f64::NAN; fits.len()];
    let learn_bounds = ens.learn_log_var_bounds;
    // One epoch of member `k`: (mean training NLL, held-out (NLL, MSE) when there is a
    // holdout). Members share nothing, so they train side by side on rayon's threads with
    // the numbers they would have one after the other.
    let member_epoch = |epoch: usize, fit: &mut MemberFit| -> Result<EpochLosses, ModelError> {
        let MemberFit {
            member: m,
            rng,
            rows,
            scratch: sc,
        } = fit;
        let mut order = rows.clone();
        order.shuffle(rng);
        let FitScratch {
            ws,
            xb,
            yb,
            g,
            d_mean,
            d_lv,
            d_out,
            d_bounds,
            grads,
        } = sc;
        grads.resize(m.net.num_params(), 0.0);
        d_bounds.resize(2 * dim, 0.0);
        let mut total = 0.0;
        for (step, idx) in order.chunks(bs).enumerate() {
            let nb = idx.len();
            data.gather_inputs(idx, xb);
            data.gather_targets(idx, yb);
            let out = m
                .net
                .forward_train(xb, nb, ws, None)
                .map_err(|e| nn_train(e, epoch, step))?;
            m.head
                .forward(out, nb, g)
                .map_err(|e| nn_train(e, epoch, step))?;
            d_mean.resize(nb * dim, 0.0);
            d_lv.resize(nb * dim, 0.0);
            let nll = gaussian_nll(&g.mean, &g.log_var, yb, Some(d_mean), Some(d_lv))
                .map_err(|e| nn_train(e, epoch, step))?;
            if !nll.is_finite() {
                return Err(ModelError::Diverged { epoch, step });
            }
            total += f64::from(nll) * nb as f64;
            // Sum over outputs, mean over the batch (gaussian_nll averages both).
            let scale = dim as f32;
            d_mean.iter_mut().for_each(|v| *v *= scale);
            d_lv.iter_mut().for_each(|v| *v *= scale);
            d_out.resize(nb * 2 * dim, 0.0);
            m.head
                .backward(g, d_mean, d_lv, d_out, Some(d_bounds))
                .map_err(|e| nn_train(e, epoch, step))?;
            m.net
                .backward(ws, d_out, Some(grads), None)
                .map_err(|e| nn_train(e, epoch, step))?;
            m.opt
                .step(m.net.params_mut(), grads)
                .map_err(|e| nn_train(e, epoch, step))?;
            if learn_bounds {
                // PETS penalty 0.01 (Σ max − Σ min).
                for (j, db) in d_bounds.iter_mut().enumerate() {
                    *db += if j < dim { -0.01 } else { 0.01 };
                }
                m.bounds_opt
                    .step(m.head.bounds_mut(), d_bounds)
                    .map_err(|e| nn_train(e, epoch, step))?;
            }
        }
        let train_nll = total / order.len().max(1) as f64;
        if data.holdout.is_empty() {
            return Ok((train_nll, None));
        }
        let (nll, mse) =
            member_eval(m, data, &data.holdout, sc).map_err(|e| nn_train(e, epoch, 0))?;
        if !nll.is_finite() {
            return Err(ModelError::Diverged { epoch, step: 0 });
        }
        Ok((train_nll, Some((nll, mse))))
    };
    let mut stop = Stopper::of(cfg, fits.len());
    let mut kept: Option<(Vec<Member>, Vec<f64>)> = None;
    let mut hold_nll = vec![f64::NAN; fits.len()];
    for epoch in 0..cfg.epochs {
        let results = map_side_by_side(&mut fits, |fit| member_epoch(epoch, fit));
        // Summed in member order, as one member after the other would.
        let mut epoch_train = 0.0;
        let mut epoch_hold = 0.0;
        for (k, r) in results.into_iter().enumerate() {
            let (train_nll, hold) = r?;
            epoch_train += train_nll;
            if let Some((nll, mse)) = hold {
                epoch_hold += nll;
                (hold_nll[k], hold_mse[k]) = (nll, mse);
            }
        }
        let kf = fits.len() as f64;
        report.train_loss.push(epoch_train / kf);
        if !data.holdout.is_empty() {
            report.holdout_loss.push(epoch_hold / kf);
        }
        if let Some(stop) = stop.as_mut() {
            if stop.improved(&hold_nll) {
                let members = fits.iter().map(|f| (*f.member).clone()).collect();
                kept = Some((members, hold_mse.clone()));
            }
            if stop.done() {
                break;
            }
        }
    }
    drop(fits);
    if let Some((best, mse)) = kept {
        members.clone_from_slice(&best);
        hold_mse = mse;
    }
    // Elites: lowest held-out MSE (training MSE without a holdout).
    if data.holdout.is_empty() {
        let mut sc = FitScratch::default();
        for (k, m) in members.iter().enumerate() {
            hold_mse[k] = member_eval(m, data, &data.train, &mut sc)
                .map_err(nn_other)?
                .1;
        }
    }
    let mut order: Vec<usize> = (0..members.len()).collect();
    order.sort_by(|&i, &j| hold_mse[i].total_cmp(&hold_mse[j]));
    order.truncate(ens.elites);

    Ok((report, order, hold_mse))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::on_threads;
    use crate::{MlpModel, MlpModelConfig, TransitionsBuilder};
    use tandem_core::seeding::rng_from_seed;

    /// `s' = s + 0.1 a + 0.1 sin(2 s) + σ(s) ε`, `σ(s) = 0.01 + 0.05 (s + 1)`, s, a in [-1, 1].
    fn noisy(n: usize, seed: u64) -> Transitions {
        let mut rng = rng_from_seed(seed);
        let mut b = TransitionsBuilder::new(1, 1);
        for _ in 0..n {
            let s: f64 = rng.random_range(-1.0..1.0);
            let a: f64 = rng.random_range(-1.0..1.0);
            let e: f64 = StandardNormal.sample(&mut rng);
            let next = s + 0.1 * a + 0.1 * (2.0 * s).sin() + (0.01 + 0.05 * (s + 1.0)) * e;
            b.push([s], &[a], &[next], s, false).unwrap();
            b.end_episode();
        }
        b.build()
    }

    fn small(seed: u64) -> EnsembleConfig {
        EnsembleConfig {
            members: 5,
            elites: 4,
            hidden: vec![32, 32],
            optimizer: OptimizerConfig::adam(3e-3),
            seed,
            ..EnsembleConfig::default()
        }
    }

    fn gauss_nll(mean: f64, var: f64, y: f64) -> f64 {
        0.5 * ((y - mean).powi(2) / var + var.ln() + (2.0 * std::f64::consts::PI).ln())
    }

    #[test]
    fn heldout_nll_beats_a_fixed_variance_model_and_variance_grows_off_data() {
        let train = noisy(2000, 1);
        let test = noisy(1000, 2);
        let fit = FitConfig {
            epochs: 40,
            batch_size: 64,
            holdout_fraction: 0.1,
            seed: 0,
            early_stop: None,
        };
        let mut ens = ProbabilisticEnsemble::new(1, 1, small(0)).unwrap();
        let rep = ens.fit(&train, &fit).unwrap();
        assert!(rep.holdout_loss.last() < rep.holdout_loss.first());
        ens.set_propagation(Propagation::Expectation);
        let mut rng = rng_from_seed(0);
        let p = ens
            .predict(
                &ModelInput::new(test.states.view(), test.actions.view()),
                &mut rng,
            )
            .unwrap();
        let var = p.variance.unwrap();
        let nll_ens: f64 = (0..test.len())
            .map(|i| gauss_nll(p.next_states[[i, 0]], var[[i, 0]], test.next_states[[i, 0]]))
            .sum::<f64>()
            / test.len() as f64;

        // Fixed-variance baseline: a deterministic MLP and the variance of its training residuals.
        let mut det = MlpModel::new(
            1,
            1,
            MlpModelConfig {
                hidden: vec![32, 32],
                optimizer: OptimizerConfig::adam(3e-3),
                learn_reward: false,
                learn_termination: false,
                ..MlpModelConfig::default()
            },
        )
        .unwrap();
        det.fit(&train, &fit).unwrap();
        let mut resid = |d: &Transitions| {
            let q = det
                .predict(
                    &ModelInput::new(d.states.view(), d.actions.view()),
                    &mut rng,
                )
                .unwrap();
            q.next_states.column(0).to_owned() - d.next_states.column(0)
        };
        let v0 = resid(&train).mapv(|e| e * e).mean().unwrap();
        let r = resid(&test);
        let pt = det
            .predict(
                &ModelInput::new(test.states.view(), test.actions.view()),
                &mut rng,
            )
            .unwrap();
        let nll_fixed: f64 = (0..test.len())
            .map(|i| gauss_nll(pt.next_states[[i, 0]], v0, test.next_states[[i, 0]]))
            .sum::<f64>()
            / test.len() as f64;
        eprintln!(
            "held-out NLL: ensemble {nll_ens:.4}, fixed variance {nll_fixed:.4} (residual rms {:.4})",
            r.mapv(|e| e * e).mean().unwrap().sqrt()
        );
        assert!(
            nll_ens < nll_fixed - 0.1,
            "ensemble {nll_ens}, fixed {nll_fixed}"
        );

        // Predicted standard deviation follows σ(s) on the data ...
        let q = |s: f64| {
            let (st, ac) = (ndarray::array![[s]], ndarray::array![[0.0]]);
            ens.predict(
                &ModelInput::new(st.view(), ac.view()),
                &mut rng_from_seed(0),
            )
            .unwrap()
            .variance
            .unwrap()[[0, 0]]
        };
        let (lo, hi) = (q(-0.9).sqrt(), q(0.9).sqrt());
        eprintln!("predicted std at s=-0.9: {lo:.4} (true 0.015), at s=0.9: {hi:.4} (true 0.105)");
        assert!(hi > 3.0 * lo, "std at -0.9 {lo}, at 0.9 {hi}");
        // ... and grows off the data (epistemic disagreement and extrapolated noise).
        let (far_lo, far_hi) = (q(-4.0).sqrt(), q(4.0).sqrt());
        eprintln!("predicted std off the data: {far_lo:.4} at s=-4, {far_hi:.4} at s=4");
        assert!(far_lo > 3.0 * lo, "std at -4 {far_lo}, at -0.9 {lo}");
        assert!(far_hi > 1.2 * hi, "std at 4 {far_hi}, at 0.9 {hi}");
    }

    /// Early stopping over members: the ensemble stops `patience` epochs after the last epoch
    /// in which some member improved, and keeps all members (and the elites they give) as they
    /// were then, as a plain fit of that many epochs leaves them.
    #[test]
    fn early_stopping_keeps_every_member_at_the_last_improving_epoch() {
        let data = noisy(300, 4);
        let patience = 2;
        let (stopping, plain) = crate::testutil::early_stopping(patience, 300);
        let mut ens = ProbabilisticEnsemble::new(1, 1, small(2)).unwrap();
        let rep = ens.fit(&data, &stopping).unwrap();
        let n = rep.holdout_loss.len();
        assert!(n < 300, "never stopped");
        let mut p = ProbabilisticEnsemble::new(1, 1, small(2)).unwrap();
        let plain_rep = p.fit(&data, &plain(n - patience)).unwrap();
        assert_eq!(plain_rep.holdout_loss[..], rep.holdout_loss[..n - patience]);
        assert_eq!(ens.elites(), p.elites());
        assert_eq!(ens.member_holdout_mse(), p.member_holdout_mse());
        let s = ndarray::Array2::from_elem((8, 1), 0.3);
        let a = ndarray::Array2::from_elem((8, 1), -0.2);
        let input = ModelInput::new(s.view(), a.view());
        let predict = |m: &ProbabilisticEnsemble| m.predict(&input, &mut rng_from_seed(9)).unwrap();
        assert_eq!(predict(&ens), predict(&p));
    }

    #[test]
    fn propagation_modes_and_elites() {
        let data = noisy(400, 3);
        let mut ens = ProbabilisticEnsemble::new(1, 1, small(1)).unwrap();
        let fit = FitConfig {
            epochs: 5,
            batch_size: 64,
            holdout_fraction: 0.2,
            seed: 0,
            early_stop: None,
        };
        ens.fit(&data, &fit).unwrap();
        // Elites are the members with the lowest held-out MSE, best first.
        let mse = ens.member_holdout_mse().to_vec();
        let e = ens.elites().to_vec();
        assert_eq!(e.len(), 4);
        assert!(e.windows(2).all(|w| mse[w[0]] <= mse[w[1]]));
        let worst = (0..5).find(|k| !e.contains(k)).unwrap();
        assert!(e.iter().all(|&k| mse[k] <= mse[worst]));

        let s = ndarray::Array2::from_elem((8, 1), 0.2);
        let a = ndarray::Array2::from_elem((8, 1), 0.1);
        let input = ModelInput::new(s.view(), a.view());
        // Fixed member without sampling: row i and row i + E use the same member; a repeat call
        // gives the same numbers.
        ens.cfg.sample = false;
        ens.set_propagation(Propagation::FixedMember);
        let p1 = ens.predict(&input, &mut rng_from_seed(1)).unwrap();
        let p2 = ens.predict(&input, &mut rng_from_seed(2)).unwrap();
        assert_eq!(p1, p2);
        for r in 0..4 {
            assert_eq!(p1.next_states[[r, 0]], p1.next_states[[r + 4, 0]]);
        }
        let distinct: std::collections::BTreeSet<u64> =
            (0..4).map(|r| p1.next_states[[r, 0]].to_bits()).collect();
        assert_eq!(distinct.len(), 4, "four elites, four different predictions");
        // Random member: rows draw members from the rng.
        ens.set_propagation(Propagation::RandomMember);
        let p3 = ens.predict(&input, &mut rng_from_seed(3)).unwrap();
        assert!(p3
            .next_states
            .iter()
            .all(|v| distinct.contains(&v.to_bits())));
        // Expectation: mean of the member means, deterministic.
        ens.set_propagation(Propagation::Expectation);
        let pe = ens.predict(&input, &mut rng_from_seed(4)).unwrap();
        let mean: f64 = (0..4).map(|r| p1.next_states[[r, 0]]).sum::<f64>() / 4.0;
        assert!((pe.next_states[[0, 0]] - mean).abs() < 1e-9);
        // A batch's own propagation overrides the model's setting, for that call only.
        let fixed = input
            .clone()
            .with_propagation(Some(Propagation::FixedMember));
        assert_eq!(ens.predict(&fixed, &mut rng_from_seed(6)).unwrap(), p1);
        assert_eq!(ens.predict(&input, &mut rng_from_seed(6)).unwrap(), pe);
        // Sampling adds noise of the member's variance.
        ens.cfg.sample = true;
        ens.set_propagation(Propagation::FixedMember);
        let ps = ens.predict(&input, &mut rng_from_seed(5)).unwrap();
        assert!((0..8).any(|r| ps.next_states[[r, 0]] != p1.next_states[[r, 0]]));
    }

    #[test]
    fn a_saved_ensemble_loads_into_one_that_predicts_and_fits_on_alike() {
        let data = noisy(200, 6);
        let fit = FitConfig {
            epochs: 2,
            batch_size: 32,
            holdout_fraction: 0.2,
            seed: 1,
            early_stop: None,
        };
        let mut a = ProbabilisticEnsemble::new(1, 1, small(7)).unwrap();
        a.fit(&data, &fit).unwrap();
        a.set_propagation(Propagation::FixedMember);
        a.set_member_offset(3);
        let mut ckpt = Checkpoint::new();
        a.save_to("ens", &mut ckpt).unwrap();
        // Another initialization, then the checkpoint: the same predictions and the same next fit.
        let mut b = ProbabilisticEnsemble::new(1, 1, small(8)).unwrap();
        b.load_from("ens", &ckpt).unwrap();
        assert_eq!(b.elites(), a.elites());
        assert_eq!(b.propagation(), Propagation::FixedMember);
        let input = ModelInput::new(data.states.view(), data.actions.view());
        let pa = a.predict(&input, &mut rng_from_seed(2)).unwrap();
        assert_eq!(pa, b.predict(&input, &mut rng_from_seed(2)).unwrap());
        let (ra, rb) = (a.fit(&data, &fit).unwrap(), b.fit(&data, &fit).unwrap());
        assert_eq!(ra, rb);
        assert_eq!(
            a.member_network(4).unwrap().params(),
            b.member_network(4).unwrap().params()
        );
        // Another shape is refused and leaves the ensemble as it was.
        let mut c = ProbabilisticEnsemble::new(2, 1, small(9)).unwrap();
        let before = c.member_network(0).unwrap().params().to_vec();
        assert!(c.load_from("ens", &ckpt).is_err());
        assert_eq!(c.member_network(0).unwrap().params(), &before[..]);
    }

    /// Members fit and predict side by side on two threads with exactly the numbers they give
    /// one after the other on one: losses, elites, weights and sampled predictions, in every
    /// propagation mode.
    #[test]
    fn two_threads_give_the_numbers_of_one() {
        let data = noisy(1500, 5);
        let fit = FitConfig {
            epochs: 3,
            batch_size: 64,
            holdout_fraction: 0.2,
            seed: 3,
            early_stop: None,
        };
        let (s, a) = (
            Array2::from_shape_fn((1200, 1), |(i, _)| (i as f64 / 600.0) - 1.0),
            Array2::from_shape_fn((1200, 1), |(i, _)| ((i * 7) % 13) as f64 / 6.5 - 1.0),
        );
        let run = |threads: usize| {
            on_threads(threads, || {
                let mut ens = ProbabilisticEnsemble::new(1, 1, small(9)).unwrap();
                let report = ens.fit(&data, &fit).unwrap();
                let mut out = vec![];
                for mode in [
                    Propagation::RandomMember,
                    Propagation::FixedMember,
                    Propagation::Expectation,
                ] {
                    ens.set_propagation(mode);
                    let p = ens
                        .predict(&ModelInput::new(s.view(), a.view()), &mut rng_from_seed(4))
                        .unwrap();
                    out.push((p.next_states, p.variance.unwrap(), p.rewards.unwrap()));
                }
                (
                    report,
                    ens.elites().to_vec(),
                    ens.member_holdout_mse().to_vec(),
                    out,
                )
            })
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one.0.train_loss, two.0.train_loss);
        assert_eq!(one.0.holdout_loss, two.0.holdout_loss);
        assert_eq!(one.1, two.1);
        assert_eq!(one.2, two.2);
        assert_eq!(one.3, two.3);
    }

    /// Inference large enough to deal its rows to threads (five elites of 3×200, 500 rows: one
    /// elite's rows cut between two threads) gives the numbers of one thread, bit for bit, in
    /// every propagation mode, on two and three threads.
    #[test]
    fn rows_dealt_to_threads_give_the_numbers_of_one() {
        let cfg = EnsembleConfig {
            members: 5,
            elites: 5,
            hidden: vec![200, 200, 200],
            seed: 4,
            ..EnsembleConfig::default()
        };
        let ens = ProbabilisticEnsemble::new(3, 1, cfg).unwrap();
        let net = ens.member_network(0).unwrap();
        assert!(500 * net.num_params() >= tandem_nn::row_deal::PARALLEL_MIN_MACS);
        assert!(net.rows_run_apart(100, 48) && net.rows_run_apart(100, 52));
        let mut rng = rng_from_seed(9);
        let s = Array2::from_shape_fn((500, 3), |_| rng.random_range(-1.0..1.0));
        let a = Array2::from_shape_fn((500, 1), |_| rng.random_range(-2.0..2.0));
        let run = |threads: usize| {
            on_threads(threads, || {
                let mut ens = ens.clone();
                let mut out = vec![];
                for mode in [
                    Propagation::FixedMember,
                    Propagation::RandomMember,
                    Propagation::Expectation,
                ] {
                    ens.set_propagation(mode);
                    // Twice: the second call reuses the buffers the first left.
                    for seed in [4, 5] {
                        let p = ens
                            .predict(
                                &ModelInput::new(s.view(), a.view()),
                                &mut rng_from_seed(seed),
                            )
                            .unwrap();
                        out.push((p.next_states, p.variance.unwrap(), p.rewards.unwrap()));
                    }
                }
                out
            })
        };
        let one = run(1);
        for threads in [2, 3] {
            let many = run(threads);
            for (k, (a, b)) in one.iter().zip(&many).enumerate() {
                let bits = |m: &Array2<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.0), bits(&b.0), "{threads} threads, call {k}");
                assert_eq!(bits(&a.1), bits(&b.1), "{threads} threads, call {k}");
                assert_eq!(a.2, b.2, "{threads} threads, call {k}");
            }
        }
    }

    #[test]
    fn same_seed_same_fit_and_failures_change_nothing() {
        let data = noisy(300, 4);
        let fit = FitConfig {
            epochs: 3,
            batch_size: 32,
            holdout_fraction: 0.2,
            seed: 5,
            early_stop: None,
        };
        let run = |seed: u64| {
            let mut e = ProbabilisticEnsemble::new(1, 1, small(seed)).unwrap();
            let r = e.fit(&data, &fit).unwrap();
            let p = e
                .predict(
                    &ModelInput::new(data.states.view(), data.actions.view()),
                    &mut rng_from_seed(0),
                )
                .unwrap();
            (e.member_network(2).unwrap().params().to_vec(), r, p)
        };
        let (a, ra, pa) = run(3);
        let (b, rb, pb) = run(3);
        assert_eq!((a.clone(), ra), (b, rb));
        assert_eq!(pa, pb);
        assert_ne!(a, run(4).0);

        let cfg = EnsembleConfig {
            optimizer: OptimizerConfig::sgd(1e12),
            ..small(0)
        };
        let mut e = ProbabilisticEnsemble::new(1, 1, cfg).unwrap();
        let before = e.member_network(0).unwrap().params().to_vec();
        assert!(matches!(
            e.fit(
                &data,
                &FitConfig {
                    epochs: 20,
                    ..fit.clone()
                }
            ),
            Err(ModelError::Diverged { .. })
        ));
        assert_eq!(e.member_network(0).unwrap().params(), &before[..]);
        let mut bad = data.clone();
        bad.rewards[9] = f64::NAN;
        assert_eq!(
            e.fit(&bad, &fit),
            Err(ModelError::NonFinite {
                what: "rewards".into(),
                row: 9
            })
        );
    }
}
