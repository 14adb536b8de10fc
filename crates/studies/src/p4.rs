//! `tandem reproduce p4-pusher` and `p4-door`: p4's local-controller experiments (Chebotar et al.,
//! PILQR; Fig. 3 and the door): LQR-FLM, PI² and PILQR train one time-varying linear-Gaussian
//! controller per condition (MuJoCo), on the same seeds and sample budget, through the shared
//! [`crate::harness`] (separate processes per seed, merge, resume).
//!
//! Each task has a measure of a trajectory's final state (the pusher: the block–goal distance,
//! lower is better; the door: its angle, higher is better), a target that counts a condition as
//! solved, and a headline: the pusher's hard condition (p4 Fig. 3), the door's worst condition
//! (it is opened "from all four starts" when the worst one is). Writes, besides the harness'
//! `config.json`, `runs/` and `state/`:
//!
//! - `table.md`, `table.json`: per method (`lqr_flm`, `pi2`, `pilqr`) the samples per condition
//!   until the headline (an iteration's mean measure) reached the target (`samples_to_target`
//!   {target, mean, per_seed}) and its final value (`final` {mean, stderr, per_seed}); per
//!   condition the final measure and on how many seeds the method solved it;
//! - `fig3.svg` (pusher) or `door.svg`: the headline against the samples per condition.
//!
//! A run (one method, one seed, four conditions) takes minutes and checkpoints after every
//! iteration ([`tandem_algos::gps::LocalGps`]): a resumed study keeps the finished runs and
//! continues the others from their last iteration, with the numbers of an uninterrupted run.

use std::collections::BTreeMap;
use std::path::Path;

use crate::report::words::reals;
use crate::report::{mean_stderr, to_json_pretty, Curve, Figure, SamplesToTarget};
use crate::run::RunDir;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use tandem_algos::gps::{
    train_local, InitController, LocalConfig, LocalMethod, LocalPoint, LocalProblem,
};
use tandem_algos::manipulation::{door_problem, pusher_problem};
use tandem_algos::mdgps::{FirstIteration, Linearization, MdgpsConfig};
use tandem_algos::{Checkpoints, Result as AlgoResult};
use tandem_robots::p4::{
    DoorCost, PusherCost, DOOR_CONDITIONS, DOOR_OPENED, PUSHER_CONDITIONS, PUSHER_HARD,
};

use crate::harness::{self, JobError, Study};
use crate::{Error, Result};
use tandem_nn::budget::MemoryEstimate;

/// The settings a p4 study starts from, before `--quick` and `--config`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// The authors' own settings where the paper is silent (their GPS experiment files, each
    /// setting citing its source in `crates/studies/presets/`), applied over ours.
    #[default]
    Authors,
    /// Our first settings, chosen before we followed the authors' files (the committed
    /// `results/p4-*` directories without `-authors`).
    Ours,
}

impl Preset {
    /// `ours` with this preset's file applied (`what` names the study in errors).
    pub(crate) fn apply<C: Serialize + DeserializeOwned>(
        self,
        ours: C,
        authors: &str,
        what: &str,
    ) -> Result<C> {
        match self {
            Preset::Ours => Ok(ours),
            Preset::Authors => {
                harness::override_settings(&ours, authors, &format!("{what}'s authors' preset"))
            }
        }
    }
}

/// What differs between p4's local-controller tasks.
pub trait P4Task: Sync {
    /// The cost's weights (recorded in the settings).
    type Cost: Clone
        + Copy
        + PartialEq
        + std::fmt::Debug
        + Serialize
        + DeserializeOwned
        + Send
        + Sync;
    /// The study's name.
    const NAME: &'static str;
    /// The figure's file.
    const FIGURE: &'static str;
    /// The report's files: the tables and [`P4Task::FIGURE`].
    const REPORT_FILES: &'static [&'static str];
    /// Whether a lower measure is better.
    const LOWER_IS_BETTER: bool;
    /// The measure's words, with its unit.
    const MEASURE: &'static str;
    /// Our first settings ([`Preset::Ours`]).
    fn defaults() -> P4Settings<Self::Cost>;
    /// The authors' preset, TOML applied over [`P4Task::defaults`] ([`Preset::Authors`]).
    const AUTHORS: &'static str;
    /// The problem with `cost`.
    fn problem(cost: Self::Cost) -> AlgoResult<LocalProblem>;
    /// The cost's own checks.
    fn validate_cost(cost: &Self::Cost) -> std::result::Result<(), String>;
    /// One label per condition.
    fn conditions() -> Vec<String>;
    /// The headline's words.
    fn headline() -> String;
    /// The headline of one iteration's per-condition measures.
    fn headline_of(measures: &[f64]) -> f64;
}

/// The gripper pusher (p4 Fig. 3).
pub struct Pusher;

impl P4Task for Pusher {
    type Cost = PusherCost;
    const NAME: &'static str = "p4-pusher";
    const FIGURE: &'static str = "fig3.svg";
    const REPORT_FILES: &'static [&'static str] = &["table.json", "table.md", "fig3.svg"];
    const LOWER_IS_BETTER: bool = true;
    const MEASURE: &'static str = "final block–goal distance (m)";
    const AUTHORS: &'static str = include_str!("../presets/p4-pusher-authors.toml");
    fn defaults() -> P4Settings<PusherCost> {
        P4Settings {
            local: LocalConfig::default(),
            cost: PusherCost::default(),
            target: 0.1,
        }
    }
    fn problem(cost: PusherCost) -> AlgoResult<LocalProblem> {
        pusher_problem(cost)
    }
    fn validate_cost(cost: &PusherCost) -> std::result::Result<(), String> {
        cost.validate()
    }
    fn conditions() -> Vec<String> {
        PUSHER_CONDITIONS
            .iter()
            .map(|c| format!("block {} → goal {}", reals(&c.block), reals(&c.goal)))
            .collect()
    }
    fn headline() -> String {
        format!(
            "the hard condition (p4 Fig. 3): block at {}, goal at {}",
            reals(&PUSHER_CONDITIONS[PUSHER_HARD].block),
            reals(&PUSHER_CONDITIONS[PUSHER_HARD].goal)
        )
    }
    fn headline_of(measures: &[f64]) -> f64 {
        measures[PUSHER_HARD]
    }
}

/// The door.
pub struct Door;

impl P4Task for Door {
    type Cost = DoorCost;
    const NAME: &'static str = "p4-door";
    const FIGURE: &'static str = "door.svg";
    const REPORT_FILES: &'static [&'static str] = &["table.json", "table.md", "door.svg"];
    const LOWER_IS_BETTER: bool = false;
    const MEASURE: &'static str = "final door angle (rad)";
    const AUTHORS: &'static str = include_str!("../presets/p4-door-authors.toml");
    fn defaults() -> P4Settings<DoorCost> {
        P4Settings {
            local: LocalConfig {
                // Normalized motor commands in [-1, 1]: exploration of ±0.22 (up to 9 N m).
                init_variance: 0.05,
                ..LocalConfig::default()
            },
            cost: DoorCost::default(),
            target: DOOR_OPENED,
        }
    }
    fn problem(cost: DoorCost) -> AlgoResult<LocalProblem> {
        door_problem(cost)
    }
    fn validate_cost(cost: &DoorCost) -> std::result::Result<(), String> {
        cost.validate()
    }
    fn conditions() -> Vec<String> {
        DOOR_CONDITIONS
            .iter()
            .map(|c| format!("start {}", c.0))
            .collect()
    }
    fn headline() -> String {
        "the worst of the four starts (the door opened from all four)".into()
    }
    fn headline_of(measures: &[f64]) -> f64 {
        measures.iter().copied().fold(f64::INFINITY, f64::min)
    }
}

/// MDGPS's settings on the door (p4 Fig. 5) and its cost: p4-door's local settings and cost
/// from `preset` ([`Preset::Authors`]: the authors' door file over ours, as `tandem reproduce
/// p4-door` runs them) with the zero initial controller (`K = 0`, `k = 0`,
/// `Σ = local.init_variance · I`, 0.05) instead of the preset's `init_lqr`; a global policy of
/// two hidden layers of 64 ([`tandem_algos::mdgps::PolicyConfig::default`]), GPS's first
/// iteration (catch-up) and GPS's regression linearization, the step multiplier fixed (the
/// authors' door file: `'step_rule': 'const'`).
pub fn door_mdgps_settings(preset: Preset) -> Result<(MdgpsConfig, DoorCost)> {
    let s = preset.apply(Door::defaults(), Door::AUTHORS, Door::NAME)?;
    let local = LocalConfig {
        init: InitController::Zero,
        ..s.local
    };
    let cfg = MdgpsConfig {
        local,
        policy: Default::default(),
        step: Default::default(),
        linearization: Linearization::default(),
        first_iteration: FirstIteration::CatchUp,
    };
    cfg.validate().map_err(Error::other)?;
    Ok((cfg, s.cost))
}

/// Everything that decides a p4 study's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct P4Settings<C> {
    /// The local-controller loop (iterations, samples per iteration, optimizers, dynamics fit).
    pub local: LocalConfig,
    /// The cost weights.
    pub cost: C,
    /// A condition counts as solved when the mean measure of the last iteration's trajectories
    /// reaches this (at or below for the pusher's distance, at or above for the door's angle).
    pub target: f64,
}

impl<C> P4Settings<C> {
    fn validate<T: P4Task<Cost = C>>(&self, what: &str) -> Result<()>
    where
        C: Copy,
    {
        let bad = |m: String| Error::input(what, m);
        self.local.validate().map_err(|e| bad(e.to_string()))?;
        T::validate_cost(&self.cost).map_err(bad)?;
        if !self.target.is_finite() {
            return Err(bad(format!("target {} must be finite", self.target)));
        }
        if total_samples(&self.local, T::conditions().len()).is_none() {
            return Err(bad(format!(
                "local.iterations {} x local.samples {} x {} conditions overflows",
                self.local.iterations,
                self.local.samples,
                T::conditions().len()
            )));
        }
        // Fails early without the `mujoco` feature (or without the scene), before any directory.
        T::problem(self.cost).map_err(|e| bad(e.to_string()))?;
        Ok(())
    }
}

/// Samples of one run over all `conditions`, `None` on overflow.
fn total_samples(local: &LocalConfig, conditions: usize) -> Option<u64> {
    let n = local
        .iterations
        .checked_mul(local.samples)?
        .checked_mul(conditions)?;
    u64::try_from(n).ok()
}

/// What a finished run leaves.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LocalRecord {
    /// `lqr_flm`, `pi2` or `pilqr`.
    pub method: String,
    /// The seed.
    pub seed: u64,
    /// Per condition, one point per iteration (samples of that condition, mean cost, mean final
    /// measure of the iteration's trajectories).
    pub curves: Vec<Vec<LocalPoint>>,
    /// Per condition, updates that failed numerically (the controller was kept).
    pub failed_updates: Vec<usize>,
    /// Samples over all conditions.
    pub samples: u64,
    /// Wall time of the run, seconds, summed over every process that ran it.
    pub wall_seconds: f64,
}

impl LocalRecord {
    /// The headline of each iteration.
    fn headlines<T: P4Task>(&self) -> Vec<(u64, f64)> {
        let iterations = self.curves.first().map_or(0, Vec::len);
        (0..iterations)
            .map(|i| {
                let m: Vec<f64> = self.curves.iter().map(|c| c[i].measure).collect();
                (self.curves[0][i].samples, T::headline_of(&m))
            })
            .collect()
    }
}

/// A p4 local-controller study on task `T`, from a preset (`None`: the default, and a resumed
/// run keeps what its `config.json` records).
pub struct P4Study<T> {
    preset: Option<Preset>,
    task: std::marker::PhantomData<T>,
}

impl<T> P4Study<T> {
    /// The study from `preset`.
    pub fn new(preset: Option<Preset>) -> Self {
        Self {
            preset,
            task: std::marker::PhantomData,
        }
    }
}

impl<T> Default for P4Study<T> {
    fn default() -> Self {
        Self::new(None)
    }
}

impl<T: P4Task> Study for P4Study<T> {
    type Settings = P4Settings<T::Cost>;
    type Record = LocalRecord;

    fn name(&self) -> &str {
        T::NAME
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<Self::Settings> {
        let preset = self.preset.unwrap_or_default();
        let mut base = preset.apply(T::defaults(), T::AUTHORS, T::NAME)?;
        if quick {
            base.local.iterations = 3;
            base.local.samples = 4;
        }
        let s = harness::read_overrides(base, config)?;
        let what = harness::settings_name(config);
        s.validate::<T>(&what)?;
        Ok(s)
    }

    fn overrides_settings(&self) -> bool {
        self.preset.is_some()
    }

    fn jobs(&self, _s: &Self::Settings, _seed: u64) -> Vec<Vec<String>> {
        LocalMethod::ALL
            .iter()
            .map(|m| vec![m.name().to_string()])
            .collect()
    }

    fn memory(&self, s: &Self::Settings, _run: &str) -> Result<MemoryEstimate> {
        let problem = T::problem(s.cost).map_err(Error::other)?;
        let (sd, ad) = (problem.system.state_dim(), problem.system.action_dim());
        let k = problem.conditions.len();
        Ok(MemoryEstimate::new().with("local: ", s.local.memory(k, problem.horizon, sd, ad)))
    }

    fn length(&self, s: &Self::Settings, _run: &str) -> u64 {
        // Checked by the settings' validation.
        total_samples(&s.local, T::conditions().len()).unwrap_or(u64::MAX)
    }

    fn run(
        &self,
        s: &Self::Settings,
        run_name: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<LocalRecord, JobError> {
        let method = LocalMethod::from_name(run_name)
            .ok_or_else(|| JobError::Failed(format!("unknown run {run_name}")))?;
        let problem = T::problem(s.cost)?;
        let run = train_local(method, &problem, &s.local, seed, store, progress)?;
        Ok(LocalRecord {
            method: run_name.into(),
            seed,
            curves: run.curves,
            failed_updates: run.failed_updates,
            samples: self.length(s, run_name),
            wall_seconds: run.wall_seconds,
        })
    }

    fn curve(&self, r: &LocalRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        let header = vec![
            "samples_per_condition",
            "measure_c0",
            "measure_c1",
            "measure_c2",
            "measure_c3",
        ];
        let iterations = r.curves.first().map_or(0, Vec::len);
        let rows = (0..iterations)
            .map(|i| {
                let mut row = vec![r.curves[0][i].samples as f64];
                row.extend(r.curves.iter().map(|c| c[i].measure));
                row
            })
            .collect();
        (header, rows)
    }

    fn report_files(&self) -> &'static [&'static str] {
        T::REPORT_FILES
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &Self::Settings,
        records: &[LocalRecord],
        wall: f64,
    ) -> Result<String> {
        let table = P4Table::new::<T>(s.target, &s.local, records);
        let json = to_json_pretty(&table).map_err(|e| Error::Other(e.to_string()))?;
        harness::write(dir, "table.json", &json)?;
        let md = table.markdown::<T>(&s.local, records, wall);
        harness::write(dir, "table.md", &md)?;
        let curves = LocalMethod::ALL
            .iter()
            .filter_map(|m| {
                let seeds: Vec<Vec<(u64, f64)>> = records
                    .iter()
                    .filter(|r| r.method == m.name())
                    .map(|r| r.headlines::<T>())
                    .collect();
                (!seeds.is_empty()).then(|| Curve::mean_over_seeds(m.name(), &seeds))
            })
            .collect();
        let fig = Figure {
            title: format!("{}: {}", T::NAME, T::headline()),
            x_label: "samples (trajectories per condition)".into(),
            y_label: T::MEASURE.into(),
            curves,
        };
        harness::write(dir, T::FIGURE, &fig.svg())?;
        Ok(md)
    }
}
/// Mean, standard error and per-seed values of a figure.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SeedFigure {
    /// Mean over seeds.
    pub mean: f64,
    /// Standard error of the mean.
    pub stderr: f64,
    /// One value per seed, in seed order.
    pub per_seed: Vec<f64>,
}

impl SeedFigure {
    pub(crate) fn new(per_seed: Vec<f64>) -> Self {
        let (mean, stderr) = mean_stderr(&per_seed);
        Self {
            mean,
            stderr,
            per_seed,
        }
    }
}

/// A method's table row `| label | final ± s.e. | samples to target | seeds that reached it |`,
/// the final figure with `decimals` decimals.
pub(crate) fn figure_row(
    label: &str,
    fin: &SeedFigure,
    t: &SamplesToTarget,
    decimals: usize,
) -> String {
    format!(
        "| {label} | {:.*} ± {:.*} | {} | {}/{} |\n",
        decimals,
        fin.mean,
        decimals,
        fin.stderr,
        t.mean.map_or("—".into(), |v| format!("{v:.0}")),
        t.reached,
        t.seeds
    )
}

/// One condition's figures for one method.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConditionFigures {
    /// The condition.
    pub condition: String,
    /// Final measure (the last iteration's mean).
    #[serde(rename = "final")]
    pub final_measure: SeedFigure,
    /// Seeds whose final measure reached the target.
    pub solved: usize,
}

/// One method's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct P4MethodFigures {
    /// Samples per condition until an iteration's headline reached the target (`null` per seed
    /// where it never did).
    pub samples_to_target: SamplesToTarget,
    /// The headline's final value.
    #[serde(rename = "final")]
    pub final_measure: SeedFigure,
    /// Per condition.
    pub conditions: Vec<ConditionFigures>,
    /// Conditions solved on every seed.
    pub conditions_solved_on_all_seeds: usize,
    /// Seeds on which every condition was solved.
    pub seeds_solving_all: usize,
    /// Seeds.
    pub seeds: Vec<u64>,
}

/// `table.json` of a p4 local-controller study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct P4Table {
    /// The measure.
    pub measure: String,
    /// Whether lower is better.
    pub lower_is_better: bool,
    /// What the headline is.
    pub headline: String,
    /// The target.
    pub target: f64,
    /// Samples per condition (iterations × trajectories per iteration).
    pub samples_per_condition: u64,
    /// Per method key.
    pub methods: BTreeMap<String, P4MethodFigures>,
}

impl P4Table {
    fn new<T: P4Task>(target: f64, local: &LocalConfig, records: &[LocalRecord]) -> Self {
        let budget = (local.iterations * local.samples) as u64;
        let reached = |v: f64| {
            if T::LOWER_IS_BETTER {
                v <= target
            } else {
                v >= target
            }
        };
        let labels = T::conditions();
        let mut methods = BTreeMap::new();
        for m in LocalMethod::ALL {
            let runs: Vec<&LocalRecord> = records.iter().filter(|r| r.method == m.name()).collect();
            if runs.is_empty() {
                continue;
            }
            let last =
                |r: &LocalRecord, c: usize| r.curves[c].last().map_or(f64::NAN, |p| p.measure);
            let conditions: Vec<ConditionFigures> = labels
                .iter()
                .enumerate()
                .map(|(c, label)| {
                    let finals: Vec<f64> = runs.iter().map(|r| last(r, c)).collect();
                    ConditionFigures {
                        condition: label.clone(),
                        solved: finals.iter().filter(|v| reached(**v)).count(),
                        final_measure: SeedFigure::new(finals),
                    }
                })
                .collect();
            let to_target = runs
                .iter()
                .map(|r| {
                    r.headlines::<T>()
                        .into_iter()
                        .find(|p| reached(p.1))
                        .map(|p| p.0)
                })
                .collect();
            let finals: Vec<f64> = runs
                .iter()
                .map(|r| r.headlines::<T>().last().map_or(f64::NAN, |p| p.1))
                .collect();
            let seeds_solving_all = runs
                .iter()
                .filter(|r| (0..labels.len()).all(|c| reached(last(r, c))))
                .count();
            methods.insert(
                m.name().to_string(),
                P4MethodFigures {
                    samples_to_target: SamplesToTarget::from_seeds(target, to_target, budget),
                    final_measure: SeedFigure::new(finals),
                    conditions_solved_on_all_seeds: conditions
                        .iter()
                        .filter(|c| c.solved == runs.len())
                        .count(),
                    seeds_solving_all,
                    conditions,
                    seeds: runs.iter().map(|r| r.seed).collect(),
                },
            );
        }
        Self {
            measure: T::MEASURE.into(),
            lower_is_better: T::LOWER_IS_BETTER,
            headline: T::headline(),
            target,
            samples_per_condition: budget,
            methods,
        }
    }

    fn markdown<T: P4Task>(
        &self,
        local: &LocalConfig,
        records: &[LocalRecord],
        wall: f64,
    ) -> String {
        let label = |k: &str| match k {
            "lqr_flm" => "LQR-FLM",
            "pi2" => "PI²",
            _ => "PILQR",
        };
        let relation = if self.lower_is_better {
            "at or below"
        } else {
            "at or above"
        };
        let seeds = self
            .methods
            .values()
            .map(|m| m.seeds.len())
            .max()
            .unwrap_or(0);
        let mut md = format!(
            "# {} ({seeds} seeds)\n\nOne time-varying linear-Gaussian controller per condition, {} \
             iterations of {} trajectories each ({} samples per condition; every trajectory \
             counted, no other rollouts). The measure is the mean {} of an iteration's \
             trajectories; a condition is solved when the last iteration's is {relation} {}. Mean \
             ± standard error over seeds.\n\n",
            T::NAME,
            local.iterations,
            local.samples,
            self.samples_per_condition,
            self.measure,
            self.target
        );
        md.push_str(&format!(
            "## Headline: {}\n\n| method | final | samples to {} | seeds that reached it |\n|---|---|---|---|\n",
            self.headline, self.target
        ));
        for (k, m) in &self.methods {
            md.push_str(&figure_row(
                label(k),
                &m.final_measure,
                &m.samples_to_target,
                3,
            ));
        }
        md.push_str("\n## Every condition: final measure, seeds that solved it\n\n| method |");
        for (c, cond) in T::conditions().iter().enumerate() {
            md.push_str(&format!(" c{c}: {cond} |"));
        }
        md.push_str(" conditions solved on all seeds | seeds solving all |\n|---|");
        md.push_str(&"---|".repeat(T::conditions().len() + 2));
        md.push('\n');
        for (k, m) in &self.methods {
            md.push_str(&format!("| {} |", label(k)));
            for c in &m.conditions {
                md.push_str(&format!(
                    " {:.3} ± {:.3}, {}/{} |",
                    c.final_measure.mean,
                    c.final_measure.stderr,
                    c.solved,
                    m.seeds.len()
                ));
            }
            md.push_str(&format!(
                " {}/{} | {}/{} |\n",
                m.conditions_solved_on_all_seeds,
                m.conditions.len(),
                m.seeds_solving_all,
                m.seeds.len()
            ));
        }
        let failed: usize = records.iter().flat_map(|r| &r.failed_updates).sum();
        let run_wall: f64 = records.iter().map(|r| r.wall_seconds).sum();
        let t = &local.trajopt;
        md.push_str(&format!(
            "\nLQR-FLM: base KL bound {} per step with GPS's step rule for LQR-FLM; PI²: KL {}, \
             covariance damping {}, gains {}; PILQR: the same LQR-FLM and PI² stages, {}. \
             Initial controllers {}. Updates that failed numerically (controller kept): {failed}. \
             Runs took {run_wall:.0} s in all; the study's wall time {wall:.0} s.\n",
            t.lqr.kl_step,
            t.pi2.kl_step,
            t.pi2.covariance_damping,
            if t.pi2.update_gains {
                "refitted"
            } else {
                "kept"
            },
            pilqr_bounds(t),
            init_words(local),
        ));
        md
    }
}

/// The initial controllers, in the report's words.
fn init_words(local: &LocalConfig) -> String {
    match &local.init {
        tandem_algos::gps::InitController::Zero => {
            format!("`K = 0, k = 0, Σ = {} I`", local.init_variance)
        }
        tandem_algos::gps::InitController::Lqr(l) => format!(
            "GPS's LQR start holding each condition's initial state (variance {}, stiffness {}, \
             velocity stiffness {})",
            l.variance, l.stiffness, l.stiffness_vel
        ),
    }
}

/// How PILQR's per-step bounds were set. The first version's settings read as its reports did;
/// later settings add what differs from them.
fn pilqr_bounds(t: &tandem_planners::PilqrConfig) -> String {
    use tandem_planners::{PerStep, Residual};
    let words = |p: &PerStep| match p {
        PerStep::Constant(v) => format!("{v}"),
        PerStep::Linear { first, last } => format!("{first} → {last} over the steps"),
    };
    let mut s = if t.adjust_step {
        format!(
            "per-step bounds from the residual ratio ({} / {}",
            t.res_ratio_dec, t.res_ratio_inc
        )
    } else {
        "per-step bounds at the base bound, no step rule (multipliers 1".to_string()
    };
    if t.residual == Residual::FromStart {
        s.push_str("; residuals of the model's replay of each sample from the mean start");
    }
    if let Some(k) = &t.kl_step {
        s.push_str(&format!("; base bound {}", words(k)));
    }
    if t.adjust_step
        && (t.min_step_mult != PerStep::Constant(0.01)
            || t.max_step_mult != PerStep::Constant(10.0))
    {
        s.push_str(&format!(
            "; multipliers from {} to {}",
            words(&t.min_step_mult),
            words(&t.max_step_mult)
        ));
    }
    s.push(')');
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_planners::{PerStep, Residual};

    /// The door's MDGPS settings are p4-door's under the same preset but for the initial
    /// controller, which is the zero one at the preset's variance; the cost is p4-door's.
    #[test]
    fn door_mdgps_settings_are_the_door_study_s_with_the_zero_start() {
        for preset in [Preset::Authors, Preset::Ours] {
            let study = preset
                .apply(Door::defaults(), Door::AUTHORS, "test")
                .unwrap();
            let (cfg, cost) = door_mdgps_settings(preset).unwrap();
            assert_eq!(cost, study.cost);
            assert_eq!(
                cfg.local,
                LocalConfig {
                    init: InitController::Zero,
                    ..study.local.clone()
                }
            );
            // The authors' preset starts p4-door from GPS's init_lqr.
            if preset == Preset::Authors {
                assert_ne!(study.local.init, InitController::Zero);
                assert!(cost.end_effector_features);
            }
            assert_eq!(cfg.first_iteration, FirstIteration::CatchUp);
            assert!(matches!(cfg.linearization, Linearization::Regression(_)));
        }
    }

    /// The authors' presets name only settings that exist (the settings refuse unknown keys), and
    /// what they give is valid; `ours` is the settings as first chosen.
    #[test]
    fn the_presets_read_and_are_valid() {
        let pusher = Preset::Authors
            .apply(Pusher::defaults(), Pusher::AUTHORS, "test")
            .unwrap();
        pusher.local.validate().unwrap();
        let t = &pusher.local.trajopt;
        assert_eq!(
            t.kl_step,
            Some(PerStep::Linear {
                first: 0.6,
                last: 0.2
            })
        );
        assert_eq!((t.pi2.kl_step, t.pi2.covariance_damping), (1.0, 10.0));
        assert_eq!(t.residual, Residual::FromStart);
        let door = Preset::Authors
            .apply(Door::defaults(), Door::AUTHORS, "test")
            .unwrap();
        door.local.validate().unwrap();
        assert!(!door.local.trajopt.adjust_step);
        assert_eq!(door.local.trajopt.pi2.kl_step, 0.5);
        let reacher = Preset::Authors
            .apply(
                crate::p4_reacher::ReacherSettings::default(),
                crate::p4_reacher::AUTHORS,
                "test",
            )
            .unwrap();
        reacher.mdgps.validate().unwrap();
        assert_eq!(reacher.mdgps.local.samples, 5);
        assert_eq!(
            reacher.mdgps.first_iteration,
            tandem_algos::mdgps::FirstIteration::CatchUp
        );
        let ours = Preset::Ours.apply(Pusher::defaults(), Pusher::AUTHORS, "test");
        assert_eq!(ours.unwrap(), Pusher::defaults());
        // A preset with a misspelt key is an error that names it, not a silent default.
        let e = Preset::Authors
            .apply(Pusher::defaults(), "[local]\nsampels = 3\n", "p4-pusher")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sampels") && e.contains("authors' preset"),
            "{e}"
        );
    }
}
