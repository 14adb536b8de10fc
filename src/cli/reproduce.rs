//! `tandem reproduce`: whole-paper reproductions. `tandem reproduce p0-pendulum` runs p0's three
//! methods (cold start, warm start, difference model) over seeds on the DC-motor pendulum and
//! writes, in the output directory:
//!
//! - `config.json`: the [`P0Config`] used, seeds, status (`running`, `interrupted`, `complete`)
//!   and wall time;
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's learning curve (return of
//!   the deterministic policy on the true system against true training samples);
//! - `table.md`, `table.json`: p0's Table II (return at the fixed budget; true samples to the
//!   fixed target return), a typed [`tandem::report::Table`] rendered by the shared report code
//!   with p0's words ([`markdown`]);
//! - `fig5.svg`: p0's Fig. 5 (mean return on the true system against true samples, ± standard
//!   error across seeds).
//!
//! While it runs, `state/seed<k>/` holds each unfinished run's checkpoint (after every
//! evaluation; the pre-trained agent too), and each run writes its `record.json` as soon as it
//! finishes. SIGINT or SIGTERM stops the jobs at once (each loses at most the steps since its
//! last evaluation), marks `config.json` `interrupted` and exits with 130 or 143;
//! `--resume DIR` continues from the checkpoints (also after a kill), refusing other settings,
//! and ends with the files an uninterrupted run writes (wall times aside); `state/` is removed at
//! the end.
//!
//! Evaluation episodes run on a separate copy of the true system and are not counted as training
//! samples. An `--out` that already holds a reproduction is an error unless `--overwrite` (no seed
//! folders of an earlier run are left beside a new table); a NaN or infinite number in the
//! configuration or about to be written is an error naming it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use clap::{Args, Subcommand};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use tandem::interrupt::{Stop, EXIT_SIGINT};
use tandem::pipelines::p0::{
    ddpg_agent, pendulum_problem, run_seed, Method, P0Config, RunRecord, Tick,
};
use tandem::pipelines::{Checkpoints, PipelineError, Result as PipelineResult};
use tandem::report::{
    ensure_finite, mean_stderr, to_json_pretty, Comparison, Curve, Figure, MarkdownText,
    MethodFigures, Reference, ReturnAtBudget, SamplesToTarget, Table,
};
use tandem::run::{csv, Existing, Layout, RunDir};
use tandem_nn::Checkpoint;

use super::{CliError, Result};

/// The reproductions.
#[derive(Debug, Subcommand)]
pub enum ReproduceCommand {
    /// p0 (difference models) on the DC-motor pendulum: cold start, warm start and the
    /// difference-model method over seeds; Table II and Fig. 5.
    P0Pendulum(P0Args),
    /// p2 (model-augmented REINFORCE) on CartPole-v1: REINFORCE alone and with the learned model.
    P2Cartpole(super::reproduce_p2::P2Args),
    /// p2 (model-augmented DQN) on its pixel maze: DQN alone and with the pixel model, and the
    /// pixel model's F1 after 10, 100 and 300 training episodes.
    P2Maze(super::reproduce_p2::P2Args),
    /// Combine p0-pendulum reproductions of disjoint seeds (e.g. one process per seed,
    /// `--first-seed`) into one table and figure; their settings must be equal.
    Merge(MergeArgs),
}

/// Arguments of `tandem reproduce merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The reproductions' directories (each complete).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Output directory (default `runs/p0-pendulum-merged__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace a merge already in `--out`.
    #[arg(long)]
    pub overwrite: bool,
}

/// Arguments of `tandem reproduce p0-pendulum`.
#[derive(Debug, Args)]
pub struct P0Args {
    /// Number of seeds (S, S+1, ..., S+N-1 for `--first-seed S`) [default: 5].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: Option<u64>,
    /// The first seed [default: 0]: `--seeds 1 --first-seed 3` runs seed 3 alone, so that seeds
    /// can run as separate processes (or cluster jobs) whose directories
    /// `tandem reproduce merge` combines into one table.
    #[arg(long)]
    pub first_seed: Option<u64>,
    /// Small smoke configuration (small networks, short budgets; numbers are meaningless).
    #[arg(long)]
    pub quick: bool,
    /// Output directory (default `runs/p0-pendulum__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Parallel jobs, one thread each (per seed, the cold start and the pre-trained pair of warm
    /// start and difference model are separate jobs).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// TOML file overriding fields of the configuration (`P0Config`; unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Replace the reproduction in an existing `--out` directory (its seed runs, tables and
    /// figure); without it, an existing reproduction there is an error.
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Continue the reproduction in DIR (interrupted or killed) from its checkpoints, with the
    /// settings its `config.json` records; finished runs are kept, unfinished ones resume from
    /// their last evaluation. `--seeds`, `--quick` and `--config` may be given and must then
    /// agree with the recorded ones.
    #[arg(long, value_name = "DIR", conflicts_with = "out")]
    pub resume: Option<PathBuf>,
}

/// Runs a reproduction.
pub fn run(cmd: ReproduceCommand) -> Result<()> {
    match cmd {
        ReproduceCommand::P0Pendulum(args) => p0_pendulum(&args),
        ReproduceCommand::P2Cartpole(args) => {
            super::reproduce_p2::p2(super::reproduce_p2::Experiment::CartPole, &args)
        }
        ReproduceCommand::P2Maze(args) => {
            super::reproduce_p2::p2(super::reproduce_p2::Experiment::Maze, &args)
        }
        ReproduceCommand::Merge(args) => merge_runs(&args),
    }
}

/// The `--quick` configuration: the same loop with small networks and budgets, for smoke tests.
pub fn quick_config() -> P0Config {
    let mut c = P0Config::default();
    c.ddpg.actor_hidden = vec![32, 32];
    c.ddpg.critic_hidden = vec![32, 32];
    c.ddpg.buffer_size = 10_000;
    c.residual.hidden = vec![32, 32];
    c.pretrain_steps = 800;
    c.real_batch = 400;
    c.real_budget = 800;
    c.baseline_max_samples = 1200;
    c.eval_interval = 400;
    c.model_steps = 400;
    c.fit.epochs = 3;
    c
}

fn other(e: impl std::fmt::Display) -> CliError {
    CliError::other(e)
}

fn read_config(quick: bool, path: Option<&Path>) -> Result<P0Config> {
    let base = if quick {
        quick_config()
    } else {
        P0Config::default()
    };
    let Some(p) = path else { return Ok(base) };
    let text = std::fs::read_to_string(p).map_err(|source| CliError::Io {
        path: p.to_path_buf(),
        source,
    })?;
    parse_config(base, &text, &format!("--config {}", p.display()))
}

/// Applies the overrides in `text` (a `--config` file, named `what` in errors) to `base` and
/// validates the result.
pub fn parse_config(base: P0Config, text: &str, what: &str) -> Result<P0Config> {
    // Overrides on top of `base`: merge the file's table into the serialized base.
    let mut v = toml::Value::try_from(&base).map_err(other)?;
    let over: toml::Table =
        toml::from_str(text).map_err(|e| CliError::input(what, e.to_string()))?;
    merge(&mut v, toml::Value::Table(over));
    let cfg: P0Config = v
        .try_into()
        .map_err(|e: toml::de::Error| CliError::input(what, e.to_string()))?;
    cfg.validate()
        .map_err(|e| CliError::input(what, e.to_string()))?;
    ensure_finite(&cfg).map_err(|e| CliError::input(what, e.to_string()))?;
    let h = cfg.fit.holdout_fraction;
    if !(0.0..1.0).contains(&h) {
        return Err(CliError::input(
            what,
            format!("fit.holdout_fraction is {h}, must be in [0, 1)"),
        ));
    }
    Ok(cfg)
}

fn merge(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(b), toml::Value::Table(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(bv) if bv.is_table() && v.is_table() => merge(bv, v),
                    _ => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, o) => *b = o,
    }
}

/// The files and folders `tandem reproduce` writes (what `--overwrite` removes).
pub const LAYOUT: Layout = Layout {
    owned: &[
        "config.json",
        "runs",
        "state",
        "table.json",
        "table.md",
        "fig5.svg",
    ],
    resumable: true,
};

/// p0's methods as the table names them, in row order.
const LABELS: &[(&str, &str)] = &[
    ("cold", "Cold start"),
    ("warm", "Warm start"),
    ("difference", "Difference model"),
];

/// How the sample ratios are taken.
const RATIO_NOTE: &str =
    "per-seed samples to the target, a seed that never reached it counted at the samples it used";

/// Table II: per method, the return at the budget and the true samples to the target; the
/// reference μ^true (the cold start's converged return); how many times more true samples each
/// baseline needed than the difference method.
pub fn table(records: &[RunRecord], cfg: &P0Config) -> Table {
    let mut t = Table::default();
    // Per method: mean true samples to the target with a seed that never reached it counted at
    // the samples it used, and whether any seed fell short.
    let mut used: Vec<(Method, f64, bool)> = Vec::new();
    for m in Method::ALL {
        let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == m).collect();
        if runs.is_empty() {
            continue;
        }
        let ret: Vec<f64> = runs
            .iter()
            .map(|r| r.return_at(cfg.real_budget).unwrap_or(f64::NAN))
            .collect();
        let to: Vec<Option<u64>> = runs
            .iter()
            .map(|r| r.samples_to(cfg.target_return))
            .collect();
        let searched = runs.iter().map(|r| r.true_samples).max().unwrap_or(0);
        let samples: Vec<f64> = runs
            .iter()
            .zip(&to)
            .map(|(r, t)| t.unwrap_or(r.true_samples) as f64)
            .collect();
        let mean_samples = samples.iter().sum::<f64>() / samples.len() as f64;
        used.push((m, mean_samples, to.iter().any(Option::is_none)));
        t.methods.insert(
            m.name().into(),
            MethodFigures {
                return_at_budget: ReturnAtBudget::from_seeds(cfg.real_budget, ret),
                samples_to_target: SamplesToTarget::from_seeds(cfg.target_return, to, searched),
                seeds: runs.iter().map(|r| r.seed).collect(),
            },
        );
    }
    let cold: Vec<&RunRecord> = records
        .iter()
        .filter(|r| r.method == Method::Cold)
        .collect();
    if !cold.is_empty() {
        let per_seed: Vec<f64> = cold
            .iter()
            .map(|r| r.final_return(cfg.reference_evals))
            .collect();
        let (mean, stderr) = mean_stderr(&per_seed);
        let gap = t
            .methods
            .get(Method::Difference.name())
            .map(|d| (d.return_at_budget.mean - mean).abs() / mean.abs());
        t.reference = Some(Reference {
            what: "cold start after all its true samples: mean of its last evaluations".into(),
            true_samples: cold.iter().map(|r| r.true_samples).max().unwrap_or(0),
            last_evaluations: cfg.reference_evals,
            mean,
            stderr,
            per_seed,
            relative_gaps: [(Method::Difference.name().to_string(), gap)].into(),
        });
    }
    if let Some(&(d, d_mean, d_short)) = used.iter().find(|x| x.0 == Method::Difference) {
        for &(b, b_mean, b_short) in used.iter().filter(|x| x.0 != Method::Difference) {
            t.comparisons.push(Comparison::new(
                (b.name(), b_mean, b_short),
                (d.name(), d_mean, d_short),
                RATIO_NOTE,
            ));
        }
    }
    t
}

/// Table II as Markdown: the shared rendering with p0's words; `wall` is the run's wall time.
pub fn markdown(t: &Table, cfg: &P0Config, wall: f64) -> String {
    let n_seeds = t.methods.values().map(|m| m.seeds.len()).max().unwrap_or(0);
    let mut closing = Vec::new();
    if let Some(r) = &t.reference {
        let gap = r
            .relative_gaps
            .get(Method::Difference.name())
            .copied()
            .flatten();
        closing.push(format!(
            "Reference μ^true (cold start after {} true samples, mean of its last {} \
             evaluations): {:.1} ± {:.1}; the difference method at the budget is {} from it.",
            r.true_samples,
            r.last_evaluations,
            r.mean,
            r.stderr,
            gap.map_or("n/a".to_string(), |g| format!("{:.1} %", 100.0 * g)),
        ));
    }
    closing.push(format!(
        "Cold and warm runs are evaluated every {} true samples; warm runs stop once they have \
         reached the target and used the budget ({}), cold runs use all {} true samples; the \
         difference method is evaluated after each model update ({} true samples each, {} in \
         all). Wall time {wall:.0} s.",
        cfg.eval_interval,
        cfg.baseline_stop_early,
        cfg.baseline_max_samples,
        cfg.real_batch,
        cfg.real_budget,
    ));
    t.markdown(&MarkdownText {
        title: format!("p0 Table II on the DC-motor pendulum ({n_seeds} seeds)"),
        intro: "Return of the deterministic policy on the true system (undiscounted, one \
                400-step episode from (π, 0)). True samples are training samples on the true \
                system, counted exactly; evaluation episodes are not counted. Mean ± standard \
                error over seeds."
            .into(),
        labels: LABELS,
        comparison_intro: "True samples to the target relative to the difference method (means \
                           over seeds; a seed that never reached it counts at the samples it \
                           used)"
            .into(),
        comparison_order: &["warm", "cold"],
        closing,
    })
}

/// Fig. 5: the mean return on the true system against true samples, per method, with ± standard
/// error bands over the seeds that have a point at that sample count.
pub fn fig5(records: &[RunRecord]) -> Figure {
    let curves = Method::ALL
        .iter()
        .filter_map(|&m| {
            let seeds: Vec<Vec<(u64, f64)>> = records
                .iter()
                .filter(|r| r.method == m)
                .map(|r| {
                    r.curve
                        .iter()
                        .map(|p| (p.true_samples, p.eval_return))
                        .collect()
                })
                .collect();
            (!seeds.is_empty()).then(|| Curve::mean_over_seeds(m.name(), &seeds))
        })
        .collect();
    Figure {
        title: "p0 Fig. 5: DC-motor pendulum, policies evaluated on the true system".into(),
        x_label: "true-system training samples".into(),
        y_label: "return on the true system".into(),
        curves,
    }
}

/// What `config.json` records: the settings (what `--resume` continues with) and how the run
/// stands.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct RunConfig {
    config: P0Config,
    seeds: u64,
    #[serde(default)]
    first_seed: u64,
    quick: bool,
    jobs: u64,
    /// `running`, `interrupted` or `complete`.
    status: String,
    /// Wall time of the last (or only) process, seconds; absent while running.
    wall_seconds: Option<f64>,
    note: String,
}

impl RunConfig {
    fn write(&self, dir: &RunDir) -> Result<()> {
        let text =
            to_json_pretty(self).map_err(|e| CliError::Other(format!("config.json: {e}")))?;
        dir.write("config.json", &text)
            .map(drop)
            .map_err(|source| CliError::Io {
                path: dir.path().join("config.json"),
                source,
            })
    }
}

/// The settings of a new reproduction from the command line.
fn fresh(args: &P0Args) -> Result<RunConfig> {
    let cfg = read_config(args.quick, args.config.as_deref())?;
    cfg.validate().map_err(other)?;
    Ok(RunConfig {
        config: cfg,
        seeds: args.seeds.unwrap_or(5),
        first_seed: args.first_seed.unwrap_or(0),
        quick: args.quick,
        jobs: args.jobs,
        status: "running".into(),
        wall_seconds: None,
        note: "evaluation episodes on the true system are not counted as training samples".into(),
    })
}

/// The settings recorded in `dir/config.json`, checked against the command line.
fn recorded(args: &P0Args, dir: &Path) -> Result<RunConfig> {
    let what = format!("--resume {}", dir.display());
    let path = dir.join("config.json");
    let text = std::fs::read_to_string(&path).map_err(|e| {
        CliError::input(
            &what,
            format!(
                "{} cannot be read ({e}): not a `tandem reproduce p0-pendulum` directory",
                path.display()
            ),
        )
    })?;
    let mut rc: RunConfig = serde_json::from_str(&text)
        .map_err(|e| CliError::input(path.display().to_string(), e.to_string()))?;
    let mut conflicts = Vec::new();
    if let Some(n) = args.seeds.filter(|n| *n != rc.seeds) {
        conflicts.push(format!("--seeds {n} (the run has {})", rc.seeds));
    }
    if let Some(s) = args.first_seed.filter(|s| *s != rc.first_seed) {
        conflicts.push(format!("--first-seed {s} (the run has {})", rc.first_seed));
    }
    if args.quick && !rc.quick {
        conflicts.push("--quick (the run is not quick)".into());
    }
    if args.config.is_some() || args.quick {
        let given = read_config(rc.quick, args.config.as_deref())?;
        if given != rc.config {
            conflicts.push("--config (its settings differ from the run's config.json)".into());
        }
    }
    if !conflicts.is_empty() {
        return Err(CliError::input(
            what,
            format!(
                "conflicts with the run being resumed: {}; a resumed run keeps its settings",
                conflicts.join(", ")
            ),
        ));
    }
    rc.jobs = args.jobs;
    Ok(rc)
}

/// One seed's checkpoints as files `state/seed<k>/<key>.safetensors` of the run directory,
/// stopping on SIGINT/SIGTERM.
struct SeedState {
    dir: PathBuf,
    stop: Stop,
}

impl SeedState {
    fn path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.safetensors"))
    }

    /// Removes `key`'s checkpoint (its run is finished and recorded).
    fn discard(&self, key: &str) -> Result<()> {
        match std::fs::remove_file(self.path(key)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(CliError::Io {
                path: self.path(key),
                source: e,
            }),
            _ => Ok(()),
        }
    }
}

impl Checkpoints for SeedState {
    fn load(&mut self, key: &str) -> PipelineResult<Option<Checkpoint>> {
        let path = self.path(key);
        if !path.exists() {
            return Ok(None);
        }
        Checkpoint::load(&path)
            .map(Some)
            .map_err(|e| PipelineError::Checkpoint(format!("{}: {e}", path.display())))
    }

    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> PipelineResult<()> {
        std::fs::create_dir_all(&self.dir)
            .map_err(|e| PipelineError::Checkpoint(format!("{}: {e}", self.dir.display())))?;
        Ok(ckpt.save(self.path(key))?)
    }

    fn stop_requested(&self) -> bool {
        self.stop.requested()
    }
}

/// `runs/<method>__seed<k>/`: where a finished run's record and curve go.
fn run_dir(dir: &RunDir, method: Method, seed: u64) -> PathBuf {
    dir.path()
        .join("runs")
        .join(format!("{}__seed{seed}", method.name()))
}

/// Writes a finished run's `record.json` and `curve.csv` (the record last: its presence says
/// the run is done).
fn write_record(dir: &RunDir, r: &RunRecord) -> Result<()> {
    let sub = run_dir(dir, r.method, r.seed);
    let io = |source| CliError::Io {
        path: sub.clone(),
        source,
    };
    std::fs::create_dir_all(&sub).map_err(io)?;
    let rows: Vec<Vec<f64>> = r
        .curve
        .iter()
        .map(|p| vec![p.true_samples as f64, p.eval_return])
        .collect();
    let curve = csv(&["true_samples", "eval_return"], &rows);
    tandem_nn::write_atomic(&sub.join("curve.csv"), curve.as_bytes()).map_err(io)?;
    let text = to_json_pretty(r)
        .map_err(|e| CliError::Other(format!("{}: {e}", sub.join("record.json").display())))?;
    tandem_nn::write_atomic(&sub.join("record.json"), text.as_bytes()).map_err(io)
}

/// Every method's record for `seeds` in the reproduction directory `dir`.
fn read_records(dir: &Path, seeds: std::ops::Range<u64>) -> Result<Vec<RunRecord>> {
    let mut records = Vec::new();
    for seed in seeds {
        for &m in &Method::ALL {
            let r = read_record_at(dir, m, seed)?.ok_or_else(|| {
                CliError::Other(format!(
                    "{}: seed {seed}: the {} run left no record",
                    dir.display(),
                    m.name()
                ))
            })?;
            records.push(r);
        }
    }
    Ok(records)
}

/// `table.json`, `table.md` and `fig5.svg` of `records`; returns the markdown.
fn write_report(dir: &RunDir, records: &[RunRecord], cfg: &P0Config, wall: f64) -> Result<String> {
    let table = table(records, cfg);
    let md = markdown(&table, cfg, wall);
    let w = |name: &str, text: &str| {
        dir.write(name, text)
            .map(drop)
            .map_err(|source| CliError::Io {
                path: dir.path().join(name),
                source,
            })
    };
    w(
        "table.json",
        &table
            .to_json()
            .map_err(|e| CliError::Other(format!("table.json: {e}")))?,
    )?;
    w("table.md", &md)?;
    w("fig5.svg", &fig5(records).svg())?;
    Ok(md)
}

/// The files `tandem reproduce merge` writes.
const MERGE_LAYOUT: Layout = Layout {
    owned: &["config.json", "runs", "table.json", "table.md", "fig5.svg"],
    resumable: false,
};

/// What a merge's `config.json` records.
#[derive(Debug, Serialize)]
struct MergeConfig<'a> {
    config: &'a P0Config,
    quick: bool,
    seeds: Vec<u64>,
    /// The merged directories, with their first seed, seed count and wall time.
    parts: Vec<(String, u64, u64, Option<f64>)>,
    /// Sum of the parts' wall times, seconds.
    wall_seconds: f64,
    status: &'static str,
}

fn merge_runs(args: &MergeArgs) -> Result<()> {
    let mut parts: Vec<(PathBuf, RunConfig)> = Vec::new();
    for d in &args.dirs {
        let path = d.join("config.json");
        let text = std::fs::read_to_string(&path).map_err(|source| CliError::Io {
            path: path.clone(),
            source,
        })?;
        let rc: RunConfig = serde_json::from_str(&text)
            .map_err(|e| CliError::input(path.display().to_string(), e.to_string()))?;
        if rc.status != "complete" {
            return Err(CliError::input(
                d.display().to_string(),
                format!(
                    "the reproduction is {}; finish it first (`tandem reproduce p0-pendulum \
                     --resume {}`)",
                    rc.status,
                    d.display()
                ),
            ));
        }
        if let Some((first, f)) = parts.first() {
            if (&f.config, f.quick) != (&rc.config, rc.quick) {
                return Err(CliError::input(
                    d.display().to_string(),
                    format!(
                        "its settings differ from {}'s: only runs of one configuration merge",
                        first.display()
                    ),
                ));
            }
        }
        parts.push((d.clone(), rc));
    }
    let mut records = Vec::new();
    let mut seeds: Vec<u64> = Vec::new();
    for (d, rc) in &parts {
        let range = rc.first_seed..rc.first_seed + rc.seeds;
        if let Some(s) = range.clone().find(|s| seeds.contains(s)) {
            return Err(CliError::input(
                d.display().to_string(),
                format!("seed {s} is in two of the merged directories"),
            ));
        }
        seeds.extend(range.clone());
        records.extend(read_records(d, range)?);
    }
    seeds.sort_unstable();
    records.sort_by_key(|r| (r.seed, Method::ALL.iter().position(|m| *m == r.method)));
    let existing = if args.overwrite {
        Existing::Overwrite
    } else {
        Existing::Refuse
    };
    let dir = RunDir::create(
        args.out.as_deref(),
        "p0-pendulum-merged",
        MERGE_LAYOUT,
        existing,
    )
    .map_err(other)?;
    for r in &records {
        write_record(&dir, r)?;
    }
    let cfg = &parts[0].1.config;
    let wall: f64 = parts.iter().filter_map(|(_, rc)| rc.wall_seconds).sum();
    let md = write_report(&dir, &records, cfg, wall)?;
    let merged = MergeConfig {
        config: cfg,
        quick: parts[0].1.quick,
        seeds,
        parts: parts
            .iter()
            .map(|(d, rc)| {
                let d = d.display().to_string();
                (d, rc.first_seed, rc.seeds, rc.wall_seconds)
            })
            .collect(),
        wall_seconds: wall,
        status: "complete",
    };
    let text = to_json_pretty(&merged).map_err(|e| CliError::Other(format!("config.json: {e}")))?;
    dir.write("config.json", &text)
        .map_err(|source| CliError::Io {
            path: dir.path().join("config.json"),
            source,
        })?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

/// A finished run's record, if it is there.
fn read_record(dir: &RunDir, method: Method, seed: u64) -> Result<Option<RunRecord>> {
    read_record_at(dir.path(), method, seed)
}

fn read_record_at(dir: &Path, method: Method, seed: u64) -> Result<Option<RunRecord>> {
    let path = dir
        .join("runs")
        .join(format!("{}__seed{seed}", method.name()))
        .join("record.json");
    match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| CliError::input(path.display().to_string(), e.to_string())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(CliError::Io { path, source }),
    }
}

fn p0_pendulum(args: &P0Args) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let stop = Stop::on_signals().map_err(|e| CliError::Other(format!("signal handlers: {e}")))?;
    let mut rc = match &args.resume {
        Some(dir) => recorded(args, dir)?,
        None => fresh(args)?,
    };
    let cfg = rc.config.clone();
    let (out, existing) = match (&args.resume, args.overwrite) {
        (Some(d), _) => (Some(d.as_path()), Existing::Resume),
        (None, true) => (args.out.as_deref(), Existing::Overwrite),
        (None, false) => (args.out.as_deref(), Existing::Refuse),
    };
    let dir = RunDir::create(out, "p0-pendulum", LAYOUT, existing).map_err(other)?;
    if let Some(pid) = dir.stale_lock_taken_over() {
        eprintln!(
            "note: took over {} from process {pid}, which is no longer running",
            dir.path().display()
        );
    }
    rc.status = "running".into();
    rc.wall_seconds = None;
    rc.write(&dir)?;
    let start = Instant::now();
    let multi = MultiProgress::new();
    if args.quiet {
        multi.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let style =
        ProgressStyle::with_template("{prefix:>22} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");

    let (first, seeds) = (rc.first_seed, rc.seeds);
    let next = AtomicUsize::new(0);
    let errors: Mutex<Vec<(u64, String)>> = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.min(2 * seeds) {
            scope.spawn(|| loop {
                // Jobs: per seed, the cold start alone, and warm start with the difference method
                // (they share one pre-training).
                let k = next.fetch_add(1, Ordering::Relaxed) as u64;
                if k >= 2 * seeds || stop.requested() {
                    break;
                }
                let (seed, methods): (u64, &[Method]) = if k % 2 == 0 {
                    (first + k / 2, &[Method::Warm, Method::Difference])
                } else {
                    (first + k / 2, &[Method::Cold])
                };
                let mut store = SeedState {
                    dir: dir.path().join("state").join(format!("seed{seed}")),
                    stop: stop.clone(),
                };
                let r = run_job(&dir, &cfg, seed, methods, &mut store, &multi, &style);
                if let Err(e) = r {
                    if !matches!(e, JobError::Stopped) {
                        errors
                            .lock()
                            .expect("no panics while holding the lock")
                            .push((seed, e.to_string()));
                    }
                }
            });
        }
    });
    let wall = start.elapsed().as_secs_f64();
    let mut errors = errors.into_inner().expect("threads joined");
    errors.sort();
    if let Some((seed, e)) = errors.first() {
        return Err(CliError::Other(format!("seed {seed}: {e}")));
    }
    if stop.requested() {
        rc.status = "interrupted".into();
        rc.wall_seconds = Some(wall);
        rc.write(&dir)?;
        return Err(CliError::Interrupted {
            what: format!(
                "finished runs and the others' last checkpoints are in {}; continue with \
                 `tandem reproduce p0-pendulum --resume {}`",
                dir.path().display(),
                dir.path().display()
            ),
            code: stop.exit_code().unwrap_or(EXIT_SIGINT),
        });
    }
    let records = read_records(dir.path(), first..first + seeds)?;
    let state = dir.path().join("state");
    if state.exists() {
        std::fs::remove_dir_all(&state).map_err(|source| CliError::Io {
            path: state.clone(),
            source,
        })?;
    }
    let md = write_report(&dir, &records, &cfg, wall)?;
    rc.status = "complete".into();
    rc.wall_seconds = Some(wall);
    rc.write(&dir)?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

/// Why a job ended early.
#[derive(Debug, thiserror::Error)]
enum JobError {
    #[error("stopped")]
    Stopped,
    #[error("{0}")]
    Failed(String),
}

impl From<PipelineError> for JobError {
    fn from(e: PipelineError) -> Self {
        match e {
            PipelineError::Stopped => JobError::Stopped,
            e => JobError::Failed(e.to_string()),
        }
    }
}

impl From<CliError> for JobError {
    fn from(e: CliError) -> Self {
        JobError::Failed(e.to_string())
    }
}

/// One job: `methods` for `seed`, skipping those already recorded, each recorded as soon as it
/// finishes; checkpoints in `store`.
fn run_job(
    dir: &RunDir,
    cfg: &P0Config,
    seed: u64,
    methods: &[Method],
    store: &mut SeedState,
    multi: &MultiProgress,
    style: &ProgressStyle,
) -> std::result::Result<(), JobError> {
    let problem = pendulum_problem();
    let bar = |name: String, len: u64| {
        let b = multi.add(ProgressBar::new(len));
        b.set_style(style.clone());
        b.set_prefix(name);
        b
    };
    let mut pre: Option<ProgressBar> = None;
    for &m in methods {
        if read_record(dir, m, seed)?.is_some() {
            store.discard(m.name())?;
            continue;
        }
        let len = if m == Method::Difference {
            cfg.real_budget
        } else {
            cfg.baseline_max_samples
        };
        let mut b: Option<ProgressBar> = None;
        let r = run_seed(
            &problem,
            cfg,
            &[m],
            seed,
            &|m, s| ddpg_agent(cfg, &problem.task, m, s),
            store,
            &mut |t| match t {
                Tick::Pretrain(k) => {
                    let p = pre.get_or_insert_with(|| {
                        bar(format!("seed {seed} pretrain"), cfg.pretrain_steps)
                    });
                    if k % 100 == 0 || k == cfg.pretrain_steps {
                        p.set_position(k);
                    }
                }
                Tick::True(m, n) => {
                    let b = b.get_or_insert_with(|| bar(format!("seed {seed} {}", m.name()), len));
                    if n % 50 == 0 {
                        b.set_position(n);
                    }
                }
            },
        );
        if let Some(b) = &b {
            b.finish();
        }
        let r = r?;
        write_record(dir, &r[0])?;
        store.discard(m.name())?;
    }
    if let Some(p) = &pre {
        p.finish();
    }
    if methods.iter().all(|m| *m != Method::Cold) {
        store.discard("pretrained")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem::pipelines::p0::CurvePoint;

    fn record(method: Method, seed: u64, curve: &[(u64, f64)]) -> RunRecord {
        RunRecord {
            method,
            seed,
            curve: curve
                .iter()
                .map(|&(true_samples, eval_return)| CurvePoint {
                    true_samples,
                    eval_return,
                })
                .collect(),
            true_samples: curve.last().map_or(0, |p| p.0),
            simulated_steps: 0,
            updates: 0,
            fit_holdout_loss: vec![],
            wall_seconds: 0.0,
        }
    }

    #[test]
    fn table_has_ratios_lower_bounds_and_the_reference() {
        let cfg = P0Config {
            real_budget: 800,
            reference_evals: 2,
            ..P0Config::default()
        };
        let recs = [
            // Cold: seed 0 reaches −1000 at 1200, seed 1 never within its 1600 samples.
            record(
                Method::Cold,
                0,
                &[(0, -9e3), (800, -2e3), (1200, -900.0), (1600, -700.0)],
            ),
            record(
                Method::Cold,
                1,
                &[(0, -9e3), (800, -5e3), (1200, -3e3), (1600, -1500.0)],
            ),
            // Warm: 400 and 800.
            record(Method::Warm, 0, &[(0, -4e3), (400, -990.0), (800, -800.0)]),
            record(Method::Warm, 1, &[(0, -4e3), (400, -2e3), (800, -950.0)]),
            // Difference: 400 in both seeds, −700 and −660 at the budget.
            record(
                Method::Difference,
                0,
                &[(0, -4e3), (400, -800.0), (800, -700.0)],
            ),
            record(
                Method::Difference,
                1,
                &[(0, -4e3), (400, -900.0), (800, -660.0)],
            ),
        ];
        let t = table(&recs, &cfg);
        let close = |v: f64, x: f64| (v - x).abs() < 1e-12;
        let cmp = |b: &str| t.comparisons.iter().find(|c| c.baseline == b).unwrap();
        // Cold: (1200 + 1600) / 2 over 400, a lower bound (seed 1 never reached it).
        assert!(close(cmp("cold").ratio.unwrap(), 3.5));
        assert!(cmp("cold").lower_bound);
        assert!(close(cmp("warm").ratio.unwrap(), 1.5));
        assert!(!cmp("warm").lower_bound);
        assert_eq!(
            t.methods["cold"].samples_to_target.per_seed,
            [Some(1200), None]
        );
        // Return at the 800 budget: the difference runs' −700 and −660.
        let d_ret = &t.methods["difference"].return_at_budget;
        assert_eq!(d_ret.per_seed, [-700.0, -660.0]);
        assert!(close(d_ret.mean, -680.0) && close(d_ret.stderr, 20.0));
        // Reference: the mean of the cold runs' last two evaluations, per seed.
        let reference = t.reference.as_ref().unwrap();
        assert_eq!(reference.per_seed, [-800.0, -2250.0]);
        let (r, d) = (-1525.0, -680.0);
        assert!(close(reference.mean, r));
        assert!(close(
            reference.relative_gaps["difference"].unwrap(),
            (d - r) / -r
        ));
        let md = markdown(&t, &cfg, 1.0);
        assert!(md.contains("Cold start ≥ 3.5×"), "{md}");
        assert!(md.contains("Warm start 1.5×"), "{md}");
        assert!(
            md.starts_with("# p0 Table II on the DC-motor pendulum (2 seeds)"),
            "{md}"
        );
        // The JSON reads back to the same table.
        assert_eq!(Table::from_json(&t.to_json().unwrap(), "t").unwrap(), t);
    }

    #[test]
    fn a_run_short_of_the_budget_is_an_error_naming_the_seed_not_a_null() {
        let cfg = P0Config {
            real_budget: 800,
            ..P0Config::default()
        };
        // Seed 1's curve has no point at or before the budget... its first point is after it.
        let recs = [
            record(Method::Cold, 0, &[(0, -9e3), (800, -2e3)]),
            record(Method::Cold, 1, &[(1200, -900.0)]),
        ];
        let e = table(&recs, &cfg).to_json().unwrap_err().to_string();
        assert!(
            e.contains("cold.return_at_budget.per_seed[1] is NaN"),
            "{e}"
        );
    }

    /// The committed p0 results (`results/p0-pendulum/`), 5 seeds, 787 s wall time.
    const COMMITTED_JSON: &str = include_str!("../../results/p0-pendulum/table.json");
    const COMMITTED_MD: &str = include_str!("../../results/p0-pendulum/table.md");

    #[test]
    fn the_committed_table_reads_back_and_renders_to_the_committed_files() {
        let t = Table::from_json(COMMITTED_JSON, "table.json").unwrap();
        assert_eq!(t.methods.len(), 3);
        assert_eq!(t.comparisons.len(), 2);
        assert_eq!(t.to_json().unwrap().trim_end(), COMMITTED_JSON.trim_end());
        // The footer's figures are P0Config's defaults, which the committed run used.
        assert_eq!(markdown(&t, &P0Config::default(), 787.0), COMMITTED_MD);
    }
}
