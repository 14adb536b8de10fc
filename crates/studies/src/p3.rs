//! `tandem reproduce p3-leg` and `p3-mujoco`: p3's comparison of SAC, MBPO and M-DeMoRL on the 2R
//! leg or a gymnasium MuJoCo task, on the same seeds and real-step budget, through the shared
//! [`crate::harness`] (resume, separate processes per seed, merge).
//!
//! Writes, besides the harness' `config.json`, `runs/` and `state/`:
//!
//! - `table.md`, `table.json`: per method the return at the budget and the real steps to the
//!   stated return (p0's table layout, methods keyed `sac`, `mbpo`, `m_demorl`), and how many
//!   times more real steps SAC and MBPO needed than M-DeMoRL;
//! - `fig4.svg` (the leg) or `fig2.svg` (MuJoCo): the mean return against real steps with ±
//!   standard error bands (p3 Fig. 4 and Fig. 2);
//! - with `--ablate-elites`, `fig3.svg`: M-DeMoRL's curves for elite fractions 1, 5, 10, 20, 50
//!   and 100 % (p3 Fig. 3), whose runs are in the table as `m_demorl_elites_<percent>`.

use std::collections::BTreeMap;
use std::path::Path;

use crate::report::{words, Comparison, Figure, MarkdownText, MethodFigures, SeedRun, Table};
use crate::run::RunDir;
use serde::{Deserialize, Serialize};
use tandem_algos::m_demorl::{run, Method, P3Config};
use tandem_algos::mbpo::{
    leg2r_problem_with, mujoco_problem, run_oracle, Event, MbpoConfig, RunRecord, MUJOCO_TASKS,
};
use tandem_algos::{Checkpoints, Problem};
use tandem_core::LinearSchedule;
use tandem_envs::{Env, EnvError, Task};
use tandem_models::PlantModel;
use tandem_mujoco::TaskKind;
use tandem_planners::Utility;
use tandem_robots::{Leg2RConfig, Leg2REnv, Leg2REnvExt, Leg2RModel};

use crate::harness::{self, JobError, Study};
use crate::{Error, Result};
use tandem_nn::budget::MemoryEstimate;

/// p3's elite fractions (Fig. 3).
pub const ELITE_FRACTIONS: [f64; 6] = [0.01, 0.05, 0.10, 0.20, 0.50, 1.0];

/// Everything that decides a p3-leg study's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct P3Settings {
    /// The environment: `Leg2R-real-v0` (the leg, built from `leg`) or a gymnasium MuJoCo task.
    pub env: String,
    /// The loop all methods share and M-DeMoRL's inner loop ([`P3Config::leg2r`] on the leg).
    pub p3: P3Config,
    /// The leg the methods train on (the leg only): the true leg (30 % heavier shank, joint
    /// friction), its reward (15) with errors in units of 2 cm and 0.2 m/s (ours: in metres the
    /// reward is flat, random torques score 0.80 of a perfect step, so no method could double
    /// another's).
    /// (Missing from a file, it is `None`, not the leg of `Default`: a MuJoCo study's settings,
    /// which leave it out, stay a MuJoCo study's through `--config` and `--resume`.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub leg: Option<Leg2RConfig>,
    /// The return (per episode) whose first evaluation at or above it counts as
    /// reached, unless `target_method` names a run.
    pub target_return: f64,
    /// The run whose mean return at the budget is the target instead (the MuJoCo tasks: `mbpo`,
    /// for "reaches MBPO's final return in fewer real steps"); `None`: `target_return`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_method: Option<String>,
    /// M-DeMoRL's elite fractions to ablate (p3 Fig. 3); empty: no ablation.
    pub ablate_elites: Vec<f64>,
    /// Also run MBPO with the true system as its model (the run `mbpo_oracle`, the leg only):
    /// its rollouts are exact, so its gap to SAC is the loop's, not the model's.
    pub oracle: bool,
}

impl Default for P3Settings {
    fn default() -> Self {
        Self {
            env: LEG.into(),
            p3: P3Config::leg2r(),
            leg: Some(Leg2RConfig {
                position_scale: 0.02,
                velocity_scale: 0.2,
                ..Leg2RConfig::for_model(Leg2RModel::Real)
            }),
            target_return: 500.0,
            target_method: None,
            ablate_elites: Vec::new(),
            oracle: false,
        }
    }
}

/// The shared loop at `--quick`'s toy sizes ([`MbpoConfig::toy`]): 3 epochs of 300 steps.
pub(crate) fn quick_loop(b: &mut MbpoConfig) {
    *b = std::mem::take(b).toy(300);
}

/// The leg's id.
const LEG: &str = "Leg2R-real-v0";

/// The ids a leg study runs on: the true leg and the idealized one.
const LEG_IDS: [&str; 2] = [LEG, "Leg2R-v0"];

/// The return each MuJoCo task's study counts real steps to, where no run's return is the
/// target: HalfCheetah p3 Fig. 3's 10 000, the others ours.
const MUJOCO_TARGETS: [(&str, f64); 4] = [
    ("HalfCheetah-v5", 10_000.0),
    ("Hopper-v5", 3000.0),
    ("Walker2d-v5", 3500.0),
    ("InvertedPendulum-v5", 1000.0),
];

/// The shared loop on the MuJoCo task `env` ([`MbpoConfig::mujoco`]) and its fixed target
/// return; `None` for a task the studies do not run.
pub(crate) fn mujoco_loop(env: &str) -> Option<(MbpoConfig, f64)> {
    let (_, target) = MUJOCO_TARGETS.iter().find(|(id, _)| *id == env)?;
    Some((MbpoConfig::mujoco(env)?, *target))
}

/// The observation and action dimensions of the MuJoCo task `env`, from its spec (no model is
/// loaded).
pub(crate) fn mujoco_dims(env: &str) -> Result<(usize, usize)> {
    let spec = TaskKind::from_id(env)
        .ok_or_else(|| Error::input("env", format!("{env}: not a gymnasium MuJoCo task")))?
        .spec();
    Ok((spec.obs_dim, spec.nu))
}

/// The ids `p3-mujoco` runs, for messages.
pub(crate) fn mujoco_ids() -> String {
    MUJOCO_TASKS.join(", ")
}

impl P3Settings {
    /// p3's settings on the MuJoCo task `env` (MBPO's loop for it, p3's inner loop); `None` for
    /// a task `p3-mujoco` does not run.
    pub fn mujoco(env: &str) -> Option<Self> {
        let (base, target_return) = mujoco_loop(env)?;
        let p3 = P3Config {
            base,
            ..P3Config::default()
        };
        Some(Self {
            env: env.into(),
            p3,
            leg: None,
            target_return,
            target_method: Some(Method::Mbpo.name().into()),
            ablate_elites: Vec::new(),
            oracle: false,
        })
    }

    /// The `--quick` settings: p3's loop at toy sizes (3 epochs of 300 steps, tiny networks).
    pub fn quick(self) -> Self {
        let mut s = self;
        quick_loop(&mut s.p3.base);
        s.p3.mpc.samples = 8;
        s.p3.horizon = LinearSchedule {
            from_epoch: 0,
            to_epoch: 2,
            start: 2,
            end: 4,
        };
        s.p3.transitions_per_epoch = LinearSchedule::constant(60);
        if let Some(leg) = &mut s.leg {
            leg.max_episode_steps = 300;
            s.target_return = 30.0;
        }
        s
    }

    /// The episode length of the environment.
    fn episode_steps(&self) -> usize {
        match (&self.leg, TaskKind::from_id(&self.env)) {
            (Some(leg), _) => leg.max_episode_steps,
            (None, Some(kind)) => kind.spec().max_episode_steps,
            (None, None) => 0,
        }
    }

    /// Checks what the runs rely on.
    fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::input(what, m));
        self.p3
            .validate()
            .map_err(|e| Error::input(what, e.to_string()))?;
        match &self.leg {
            Some(leg) => {
                if !LEG_IDS.contains(&self.env.as_str()) {
                    return bad(format!(
                        "env {}: a leg study runs {} (p3-mujoco runs {})",
                        self.env,
                        LEG_IDS.join(" or "),
                        mujoco_ids()
                    ));
                }
                if let Err(e) = leg2r_problem_with(&self.env, leg) {
                    return bad(format!("leg: {e}"));
                }
            }
            None => {
                if self.oracle {
                    return bad("oracle: the true model is available for the leg only".into());
                }
                if !MUJOCO_TASKS.contains(&self.env.as_str()) {
                    return bad(format!(
                        "env {}: p3-mujoco runs {} (a leg needs its `leg` settings)",
                        self.env,
                        mujoco_ids()
                    ));
                }
                if let Err(e) = mujoco_problem(&self.env) {
                    return bad(e.to_string());
                }
            }
        }
        let known: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        check_target_method(self.target_method.as_deref(), &known).or_else(bad)?;
        if !self.target_return.is_finite() {
            return bad(format!(
                "target_return {} must be finite",
                self.target_return
            ));
        }
        if let Some(f) = self
            .ablate_elites
            .iter()
            .find(|f| !(**f > 0.0 && **f <= 1.0))
        {
            return bad(format!("ablate_elites: {f} must lie in (0, 1]"));
        }
        let runs = self.ablation();
        for (k, (name, f)) in runs.iter().enumerate() {
            if let Some((_, g)) = runs[..k].iter().find(|(n, _)| n == name) {
                return bad(format!(
                    "ablate_elites: {g} and {f} both name the run {name}; give fractions that \
                     differ in their percent to two decimals"
                ));
            }
        }
        if !matches!(self.p3.mpc.utility, Utility::CemElite { .. })
            && !self.ablate_elites.is_empty()
        {
            return bad("ablate_elites needs the CEM elite utility (p3.mpc.utility)".into());
        }
        Ok(())
    }

    /// M-DeMoRL's own elite fraction, if it uses CEM elites.
    fn elite_fraction(&self) -> Option<f64> {
        match self.p3.mpc.utility {
            Utility::CemElite { elite_fraction, .. } => Some(elite_fraction),
            Utility::Exponential { .. } => None,
        }
    }

    /// The ablation's runs, as `(name, fraction)`; the fraction M-DeMoRL already uses is its
    /// `m_demorl` run.
    fn ablation(&self) -> Vec<(String, f64)> {
        self.ablate_elites
            .iter()
            .map(|&f| {
                let name = if Some(f) == self.elite_fraction() {
                    Method::MDemorl.name().to_string()
                } else {
                    format!("m_demorl_elites_{}", percent(f))
                };
                (name, f)
            })
            .collect()
    }
}

/// `0.05` as `"5"`, `0.125` as `"12.5"`.
fn percent(f: f64) -> String {
    let p = (f * 1e4).round() / 100.0;
    format!("{p}")
}

/// The name of the MBPO run with the true system as its model.
const ORACLE: &str = "mbpo_oracle";

/// The p3 studies: on the leg, or on a MuJoCo task.
pub struct P3Study {
    target: Target,
    ablate: bool,
    oracle: bool,
}

/// Where a p3 study runs.
enum Target {
    /// `p3-leg`.
    Leg,
    /// `p3-mujoco` on `--env` (`None`: HalfCheetah-v5, or the recorded task on `--resume`).
    Mujoco(Option<String>),
}

impl P3Study {
    /// `p3-leg`; `ablate` adds p3's elite fractions to the settings, `oracle` the MBPO run
    /// with the true leg as its model.
    pub fn leg(ablate: bool, oracle: bool) -> Self {
        Self {
            target: Target::Leg,
            ablate,
            oracle,
        }
    }

    /// `p3-mujoco` on `env` (default HalfCheetah-v5).
    pub fn mujoco(env: Option<String>, ablate: bool, oracle: bool) -> Self {
        Self {
            target: Target::Mujoco(env),
            ablate,
            oracle,
        }
    }
}

impl Study for P3Study {
    type Settings = P3Settings;
    type Record = RunRecord;

    fn name(&self) -> &str {
        match self.target {
            Target::Leg => "p3-leg",
            Target::Mujoco(_) => "p3-mujoco",
        }
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<P3Settings> {
        let base = match &self.target {
            Target::Leg => P3Settings::default(),
            Target::Mujoco(env) => {
                let env = env.as_deref().unwrap_or(MUJOCO_TASKS[0]);
                P3Settings::mujoco(env).ok_or_else(|| {
                    Error::input("--env", format!("{env}: p3-mujoco runs {}", mujoco_ids()))
                })?
            }
        };
        let base = if quick { base.quick() } else { base };
        let mut s = harness::read_overrides(base, config)?;
        if self.ablate && s.ablate_elites.is_empty() {
            s.ablate_elites = ELITE_FRACTIONS.to_vec();
        }
        s.oracle |= self.oracle;
        let what = harness::settings_name(config);
        s.validate(&what)?;
        Ok(s)
    }

    fn overrides_settings(&self) -> bool {
        self.ablate || self.oracle || matches!(self.target, Target::Mujoco(Some(_)))
    }

    fn jobs(&self, s: &P3Settings, _seed: u64) -> Vec<Vec<String>> {
        let mut runs: Vec<String> = Method::ALL.iter().map(|m| m.name().to_string()).collect();
        if s.oracle {
            runs.push(ORACLE.to_string());
        }
        for (name, _) in s.ablation() {
            if !runs.contains(&name) {
                runs.push(name);
            }
        }
        runs.into_iter().map(|r| vec![r]).collect()
    }

    fn memory(&self, s: &P3Settings, run: &str) -> Result<MemoryEstimate> {
        let (od, ad) = match &s.leg {
            Some(leg) => {
                let env = (leg2r_problem_with(&s.env, leg).map_err(Error::other)?.env)()?;
                (
                    env.observation_space().flat_dim(),
                    env.action_space().flat_dim(),
                )
            }
            None => mujoco_dims(&s.env)?,
        };
        let p3 = &s.p3;
        let est = if run == Method::Sac.name() {
            MemoryEstimate::new().with("base.sac.", p3.base.sac.memory(od, ad))
        } else if run == Method::Mbpo.name() || run == ORACLE {
            let rollouts = p3.base.max_rollout_capacity();
            MemoryEstimate::new().with("base.", p3.base.memory(od, ad, rollouts))
        } else {
            p3.memory(od, ad)
        };
        Ok(MemoryEstimate::new().with("p3.", est))
    }

    fn length(&self, s: &P3Settings, _run: &str) -> u64 {
        s.p3.base.real_steps
    }

    fn run(
        &self,
        s: &P3Settings,
        run_name: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<RunRecord, JobError> {
        let mut r = match &s.leg {
            Some(leg) if run_name == ORACLE => {
                let problem = leg2r_problem_with(&s.env, leg)?;
                // The model steps a copy of the real system's own plant (the clocked leg).
                let real = Leg2REnv::with_config(&s.env, leg.clone())
                    .map_err(|e| JobError::Failed(e.to_string()))?;
                run_oracle(
                    &problem,
                    &s.p3.base,
                    PlantModel::new(real.plant().clone()),
                    seed,
                    store,
                    &mut step_progress(progress),
                )
                .map_err(JobError::from)
            }
            Some(leg) => run_on(
                &leg2r_problem_with(&s.env, leg)?,
                s,
                run_name,
                seed,
                store,
                progress,
            ),
            None => run_on(&mujoco_problem(&s.env)?, s, run_name, seed, store, progress),
        }?;
        r.method = run_name.to_string();
        Ok(r)
    }

    fn curve(&self, r: &RunRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        harness::curve_rows("real_steps", &r.curve)
    }

    fn report_files(&self) -> &'static [&'static str] {
        &["table.json", "table.md", "fig2.svg", "fig4.svg", "fig3.svg"]
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &P3Settings,
        records: &[RunRecord],
        wall: f64,
    ) -> Result<String> {
        let t = table(records, s);
        let md = markdown(&t, s, records, wall);
        harness::write_table(dir, &t, &md)?;
        let mut main: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        if s.oracle {
            main.push(ORACLE);
        }
        let (file, title) = match s.leg {
            Some(_) => (
                "fig4.svg",
                "p3 Fig. 4: the 2R leg, SAC, MBPO and M-DeMoRL".to_string(),
            ),
            None => (
                "fig2.svg",
                format!("p3 Fig. 2: {}, SAC, MBPO and M-DeMoRL", s.env),
            ),
        };
        harness::write(dir, file, &figure(records, &main, &title).svg())?;
        let ablation: Vec<String> = s.ablation().into_iter().map(|(n, _)| n).collect();
        if !ablation.is_empty() {
            let names: Vec<&str> = ablation.iter().map(String::as_str).collect();
            harness::write(
                dir,
                "fig3.svg",
                &figure(
                    records,
                    &names,
                    &format!("p3 Fig. 3: M-DeMoRL's elite fraction on {}", s.env),
                )
                .svg(),
            )?;
        }
        Ok(md)
    }
}

/// Runs `run_name` (a method, or an ablation's M-DeMoRL) for `seed` on `problem`.
fn run_on<T, F>(
    problem: &Problem<T, F>,
    s: &P3Settings,
    run_name: &str,
    seed: u64,
    store: &mut dyn Checkpoints,
    progress: &mut dyn FnMut(u64),
) -> std::result::Result<RunRecord, JobError>
where
    T: Task + Clone + Send + Sync + 'static,
    F: Fn() -> std::result::Result<Box<dyn Env>, EnvError>,
{
    let mut cfg = s.p3.clone();
    let method = match Method::ALL.iter().find(|m| m.name() == run_name) {
        Some(&m) => m,
        None => {
            let (_, f) = s
                .ablation()
                .into_iter()
                .find(|(n, _)| n == run_name)
                .ok_or_else(|| JobError::Failed(format!("unknown run {run_name}")))?;
            if let Utility::CemElite { elite_fraction, .. } = &mut cfg.mpc.utility {
                *elite_fraction = f;
            }
            Method::MDemorl
        }
    };
    let r = run(
        method,
        problem,
        &cfg,
        seed,
        store,
        &mut step_progress(progress),
    )?;
    Ok(r)
}

/// The run's events as the harness' progress: the real steps, every 100.
pub(crate) fn step_progress(progress: &mut dyn FnMut(u64)) -> impl FnMut(Event) + '_ {
    move |e| {
        if let Event::Step { real_steps } = e {
            if real_steps % 100 == 0 {
                progress(real_steps);
            }
        }
    }
}

/// How the sample ratios are taken.
pub(crate) const RATIO_NOTE: &str =
    "per-seed real steps to the target, a seed that never reached it counted at the steps it used";

/// The runs' names in table order: the three methods, then the ablation.
fn names(records: &[RunRecord]) -> Vec<String> {
    let mut names: Vec<String> = Method::ALL.iter().map(|m| m.name().to_string()).collect();
    for r in records {
        if !names.contains(&r.method) {
            names.push(r.method.clone());
        }
    }
    names
}

/// Per run name: the return at the budget and the real steps to the target; SAC and MBPO over
/// M-DeMoRL.
pub fn table(records: &[RunRecord], s: &P3Settings) -> Table {
    let b = &s.p3.base;
    let target = target_of(
        records,
        b.real_steps,
        s.target_return,
        s.target_method.as_deref(),
    );
    runs_table(
        records,
        &names(records),
        b.real_steps,
        target,
        s.leg.is_some().then_some(b.epoch_length),
        Method::MDemorl.name(),
        &[Method::Sac.name(), Method::Mbpo.name()],
    )
}

/// "All methods take … updates per real step": the budget, evaluations and SAC of the loop
/// every method of a study shares.
pub(crate) fn loop_sentence(b: &MbpoConfig) -> String {
    format!(
        "All methods take {} real steps ({} epochs of {}), evaluated every {} with {} \
         deterministic episodes (not counted); SAC {} hidden units, {} random steps, {} \
         updates per real step",
        b.real_steps,
        b.real_steps / b.epoch_length,
        b.epoch_length,
        b.eval_every,
        b.eval_episodes,
        words::list(&b.sac.hidden),
        b.sac.learning_starts,
        b.updates_per_step,
    )
}

/// An error message unless `method` is `None` or one of the runs `known`.
pub(crate) fn check_target_method(
    method: Option<&str>,
    known: &[&str],
) -> std::result::Result<(), String> {
    match method {
        Some(m) if !known.contains(&m) => {
            Err(format!("target_method {m}: one of {}", known.join(", ")))
        }
        _ => Ok(()),
    }
}

/// The return whose reaching is counted: the mean return at `budget` of the runs `method`
/// where it names one that has runs, else `fixed`.
pub(crate) fn target_of(
    records: &[RunRecord],
    budget: u64,
    fixed: f64,
    method: Option<&str>,
) -> f64 {
    let Some(m) = method else { return fixed };
    let at: Vec<f64> = records
        .iter()
        .filter(|r| r.method == m)
        .filter_map(|r| r.return_at(budget))
        .collect();
    if at.is_empty() {
        fixed
    } else {
        at.iter().sum::<f64>() / at.len() as f64
    }
}

/// Per run of `names` (those with records): the return at the budget and the real steps to
/// `target` (with the mean return per epoch where `epoch_length` is given); the `baselines`'
/// real steps over `ours`'s.
pub(crate) fn runs_table(
    records: &[RunRecord],
    names: &[String],
    budget: u64,
    target: f64,
    epoch_length: Option<u64>,
    ours: &str,
    baselines: &[&str],
) -> Table {
    let mut t = Table::default();
    let mut used = Vec::new();
    for name in names {
        let seeds: Vec<SeedRun> = records
            .iter()
            .filter(|r| &r.method == name)
            .map(|r| SeedRun {
                seed: r.seed,
                samples: r.real_steps,
                return_at_budget: r.return_at(budget).unwrap_or(f64::NAN),
                samples_to_target: r.steps_to(target),
            })
            .collect();
        if seeds.is_empty() {
            continue;
        }
        let (mut figures, mean, short) = MethodFigures::from_runs(budget, target, &seeds);
        if let Some(len) = epoch_length {
            figures.return_at_epoch = return_at_epoch(records, name, len);
        }
        used.push((name.clone(), mean, short));
        t.methods.insert(name.clone(), figures);
    }
    if let Some((_, m_mean, m_short)) = used.iter().find(|u| u.0 == ours) {
        for base in baselines {
            if let Some((_, b_mean, b_short)) = used.iter().find(|u| u.0 == *base) {
                t.comparisons.push(Comparison::new(
                    (base, *b_mean, *b_short),
                    (ours, *m_mean, *m_short),
                    RATIO_NOTE,
                ));
            }
        }
    }
    t
}

/// The mean return of the runs `name` at each epoch (evaluations at whole multiples of
/// `epoch_length` real steps) where every one of them was evaluated.
fn return_at_epoch(records: &[RunRecord], name: &str, epoch_length: u64) -> BTreeMap<u64, f64> {
    let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == name).collect();
    let mut sums: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
    for r in &runs {
        for p in r
            .curve
            .iter()
            .filter(|p| p.true_samples % epoch_length == 0)
        {
            let e = sums.entry(p.true_samples / epoch_length).or_default();
            e.0 += p.eval_return;
            e.1 += 1;
        }
    }
    sums.into_iter()
        .filter(|(_, (_, n))| *n == runs.len())
        .map(|(epoch, (sum, n))| (epoch, sum / n as f64))
        .collect()
}

/// The table as Markdown with p3's words, the settings that matter and the wall time.
pub fn markdown(t: &Table, s: &P3Settings, records: &[RunRecord], wall: f64) -> String {
    let labels: Vec<(String, String)> = names(records)
        .into_iter()
        .map(|n| {
            let label = match n.as_str() {
                "sac" => "SAC".to_string(),
                "mbpo" => "MBPO".to_string(),
                ORACLE => "MBPO, true leg as model".to_string(),
                "m_demorl" => match s.elite_fraction() {
                    Some(f) => format!("M-DeMoRL ({} % elites)", percent(f)),
                    None => "M-DeMoRL".to_string(),
                },
                other => match s.ablation().into_iter().find(|(a, _)| a == other) {
                    Some((_, f)) => format!("M-DeMoRL ({} % elites)", percent(f)),
                    None => other.to_string(),
                },
            };
            (n, label)
        })
        .collect();
    let labels: Vec<(&str, &str)> = labels
        .iter()
        .map(|(n, l)| (n.as_str(), l.as_str()))
        .collect();
    let n_seeds = t.methods.values().map(|m| m.seeds.len()).max().unwrap_or(0);
    let b = &s.p3.base;
    let closing = vec![
        format!(
            "{}; the model an ensemble of {} ({} elites) of {}, refit every {} real steps; \
             MBPO {} rollouts per real step, {} % real data in SAC's minibatches; M-DeMoRL {} \
             sampled sequences, H {} → {} over epochs {}–{}, up to {} MPC transitions an \
             epoch, {} % real data in SAC's minibatches.{}",
            loop_sentence(b),
            b.ensemble.members,
            b.ensemble.elites,
            words::list(&b.ensemble.hidden),
            b.model_train_freq,
            b.rollouts_per_step,
            b.real_ratio * 100.0,
            s.p3.mpc.samples,
            s.p3.horizon.start,
            s.p3.horizon.end,
            s.p3.horizon.from_epoch,
            s.p3.horizon.to_epoch,
            s.p3.transitions_per_epoch.max(),
            s.p3.m_demorl_loop().real_ratio * 100.0,
            s.leg.as_ref().map_or(String::new(), |l| format!(
                " Reward (15) with errors in units of {} m and {} m/s on the true leg.",
                l.position_scale, l.velocity_scale
            )),
        ),
        target_sentence(t, s.target_method.as_deref(), &labels),
        format!(
            "{} {}",
            if s.leg.is_some() {
                "p3 reports M-DeMoRL at about twice SAC's reward on the hardware leg by 80 epochs."
            } else {
                "p3 reports M-DeMoRL about 30 % faster than MBPO to the same final return."
            },
            rates_and_wall(records, &labels, wall)
        ),
        seconds_per_seed(records, &labels),
    ];
    t.markdown(&MarkdownText {
        title: format!("p3 on {} ({n_seeds} seeds)", s.env),
        intro: format!(
            "Mean return of the deterministic policy over {}-step episodes of {}. Real steps \
             are counted exactly; model and MPC transitions cost none. Mean ± standard error \
             over seeds.",
            s.episode_steps(),
            if s.leg.is_some() {
                "the true leg (reward (15), at most 1 a step)"
            } else {
                "the task"
            }
        ),
        labels: &labels,
        comparison_intro: "Real steps to the target relative to M-DeMoRL (means over seeds; a \
                           seed that never reached it counts at the steps it used)"
            .into(),
        comparison_order: &["sac", "mbpo"],
        closing,
    })
}

/// "SAC update rate … Wall time … s.": each labelled run's updates per second of update time.
pub(crate) fn rates_and_wall(records: &[RunRecord], labels: &[(&str, &str)], wall: f64) -> String {
    let rates: Vec<String> = labels
        .iter()
        .filter_map(|(n, l)| update_rate(records, n).map(|r| format!("{r:.0} updates/s ({l})")))
        .collect();
    format!(
        "SAC update rate {}. Wall time {wall:.0} s.",
        rates.join(", ")
    )
}

/// "Seconds per seed of one thread (mean): …" for each labelled run ([`time_split`]).
pub(crate) fn seconds_per_seed(records: &[RunRecord], labels: &[(&str, &str)]) -> String {
    let parts: Vec<String> = labels
        .iter()
        .filter_map(|(n, l)| time_split(records, n).map(|t| format!("{l} {t}")))
        .collect();
    format!(
        "Seconds per seed of one thread (mean): {}.",
        parts.join("; ")
    )
}

/// SAC updates per second of update time over the runs `name` (`None` without update time).
fn update_rate(records: &[RunRecord], name: &str) -> Option<f64> {
    let (u, sec) = records
        .iter()
        .filter(|r| r.method == name)
        .fold((0u64, 0.0), |(u, s), r| {
            (u + r.updates, s + r.update_seconds)
        });
    (sec > 0.0).then(|| u as f64 / sec)
}

/// What the target return is: a fixed figure, or a run's mean return at the budget.
pub(crate) fn target_sentence(t: &Table, method: Option<&str>, labels: &[(&str, &str)]) -> String {
    let target = t
        .methods
        .values()
        .next()
        .map_or(f64::NAN, |m| m.samples_to_target.target);
    match method.and_then(|m| labels.iter().find(|(n, _)| *n == m)) {
        Some((_, label)) => format!(
            "The target return {target:.1} is {label}'s mean return at the budget: the real \
             steps to it say how much sooner a method reaches {label}'s final return."
        ),
        None => format!("The target return is {target:.1}."),
    }
}

/// The mean seconds per seed of the runs `name`: the total, and its SAC updates, model fits and
/// imagination (rollouts or plans) where they took any; `None` without runs.
fn time_split(records: &[RunRecord], name: &str) -> Option<String> {
    let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == name).collect();
    if runs.is_empty() {
        return None;
    }
    let mean =
        |f: fn(&RunRecord) -> f64| runs.iter().map(|r| f(r)).sum::<f64>() / runs.len() as f64;
    let parts: Vec<String> = [
        ("SAC updates", mean(|r| r.update_seconds)),
        ("model fits", mean(|r| r.fit_seconds)),
        ("imagination", mean(|r| r.imagine_seconds)),
    ]
    .into_iter()
    .filter(|(_, t)| *t > 0.0)
    .map(|(what, t)| format!("{what} {t:.0}"))
    .collect();
    Some(format!(
        "{:.0} ({})",
        mean(|r| r.wall_seconds),
        parts.join(", ")
    ))
}

/// The mean return against real steps of the runs `names`, ± standard error.
pub fn figure(records: &[RunRecord], names: &[&str], title: &str) -> Figure {
    let curves = harness::mean_curves(records, names, |r| (r.method.as_str(), &r.curve));
    Figure {
        title: title.into(),
        x_label: "real steps".into(),
        y_label: "return per episode".into(),
        curves,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `--config` file over a MuJoCo study's settings leaves it a MuJoCo study: the leg's
    /// settings, which it leaves out, do not come back from `Default`.
    #[test]
    fn a_config_file_keeps_a_mujoco_study_off_the_leg() {
        let base = P3Settings::mujoco("HalfCheetah-v5").unwrap();
        let s = harness::override_settings(&base, "[p3.base]\nreal_steps = 10000\n", "t").unwrap();
        assert!(s.leg.is_none());
        assert_eq!(s.p3.base.real_steps, 10_000);
        assert_eq!(s.target_method.as_deref(), Some("mbpo"));
        assert_eq!(
            P3Settings {
                p3: s.p3.clone(),
                ..base.clone()
            },
            s
        );
        // The leg's own settings keep the leg.
        let leg =
            harness::override_settings(&P3Settings::default(), "oracle = true\n", "t").unwrap();
        assert!(leg.leg.is_some() && leg.oracle);
    }
}
