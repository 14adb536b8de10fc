//! What every resumable `tandem reproduce` study shares: the command line (`--seeds`,
//! `--first-seed`, `--quick`, `--out`, `--jobs`, `--config`, `--quiet`, `--overwrite`,
//! `--resume`), the run directory, parallel jobs, checkpoints on disk, each run's record, the
//! report, and merging the directories of separate processes.
//!
//! A [`Study`] says what its settings are, which runs make one seed (grouped into jobs), how one
//! run goes and what report its records make. [`run`] then writes, in the output directory:
//!
//! - `config.json`: the study's name, its settings, the seeds, how the run stands (`running`,
//!   `interrupted`, `failed` with its `error`, `complete`) with its wall time, and the build
//!   that ran it ([`Build`]: commit, dirty flag, features; a resume by another build is
//!   appended to its `resumed_by`);
//! - `runs/<run>__seed<k>/record.json`, its SHA-256 (`record.json.sha256`, in `sha256sum`'s
//!   format) and the study's `curve.csv` as soon as a run finishes;
//! - `state/seed<k>/<job>/`: each unfinished job's checkpoints, removed when the job is done;
//! - the study's report files (tables, figures).
//!
//! A stop request ([`StudyArgs::stop`]; the `tandem` program sets it on SIGINT or SIGTERM)
//! stops every job at once (each loses the steps since its last checkpoint), marks
//! `config.json` `interrupted` and returns [`Error::Interrupted`] with the exit status 130 or
//! 143. A failed run or write (a full disk, a removed file) lets the other jobs finish, then
//! marks `config.json` `failed` with the reason. `--resume DIR` continues from the checkpoints,
//! after a kill or a failure too, refusing settings other than the recorded ones. Seeds can run
//! as separate processes (`--seeds 1 --first-seed k`), on one machine or many; [`merge`] joins
//! their complete directories into one report, checking each record against its folder and its
//! checksum, and merges merged directories again (per node, then across nodes).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use crate::interrupt::{Stop, EXIT_SIGINT};
use crate::provenance::{self, Build, PartBuild};
use crate::report::{ensure_finite, to_json_pretty, Curve, Table};
use crate::run::{Existing, Layout, RunDir};
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use tandem_algos::{AlgoError, Checkpoints, Result as AlgoResult};
use tandem_core::CurvePoint;
use tandem_nn::budget::{memory_limit, MemoryEstimate};
use tandem_nn::Checkpoint;

use crate::{Error, IoOp, Result};

/// The command line every study shares (`#[command(flatten)]` it into the study's arguments).
#[derive(Debug, Clone, Args)]
pub struct StudyArgs {
    /// Number of seeds (S, S+1, ..., S+N-1 for `--first-seed S`) [default: the study's].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: Option<u64>,
    /// The first seed [default: 0]: `--seeds 1 --first-seed 3` runs seed 3 alone, so that seeds
    /// can run as separate processes (or cluster jobs) whose directories
    /// `tandem reproduce merge` combines into one report.
    #[arg(long)]
    pub first_seed: Option<u64>,
    /// Run only these methods (the runs' names, comma-separated, e.g. `sac,mbpo`) [default:
    /// all]: one (seed, method) cell per process on a cluster; `tandem reproduce merge`
    /// combines disjoint cells of equal settings.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    pub methods: Option<Vec<String>>,
    /// Small smoke configuration (small networks, short budgets; numbers are meaningless).
    #[arg(long)]
    pub quick: bool,
    /// Output directory (default `runs/<study>__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Parallel jobs, one thread each.
    #[arg(long, default_value_t = DEFAULT_JOBS, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// TOML file overriding fields of the study's settings (unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Check the settings whole (every range, the seeds, the memory of `--jobs` parallel jobs),
    /// print the estimate and exit, without running or writing anything.
    #[arg(long)]
    pub check: bool,
    /// Replace the study in an existing `--out` directory; without it, an existing study there
    /// is an error.
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Continue the study in DIR (interrupted or killed) from its checkpoints, with the
    /// settings its `config.json` records; finished runs are kept, unfinished ones resume from
    /// their last checkpoint. `--seeds`, `--first-seed`, `--quick` and `--config` may be given
    /// and must then agree with the recorded ones.
    #[arg(long, value_name = "DIR", conflicts_with = "out")]
    pub resume: Option<PathBuf>,
    /// What stops the study: [`Stop::never`] by default, so that a library caller keeps its own
    /// signal handling; the `tandem` program passes [`Stop::on_signals`].
    #[arg(skip)]
    pub stop: Stop,
}

/// Parallel jobs when `--jobs` is not given.
const DEFAULT_JOBS: u64 = 2;

impl Default for StudyArgs {
    /// The command line's defaults: the study's seeds from 0, full settings, two jobs.
    fn default() -> Self {
        Self {
            seeds: None,
            first_seed: None,
            methods: None,
            quick: false,
            out: None,
            jobs: DEFAULT_JOBS,
            config: None,
            quiet: false,
            check: false,
            overwrite: false,
            resume: None,
            stop: Stop::never(),
        }
    }
}

/// Why a job ended early.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// SIGINT or SIGTERM: the checkpoint is on disk.
    #[error("stopped")]
    Stopped,
    /// Anything else, phrased for the user.
    #[error("{0}")]
    Failed(String),
}

impl From<AlgoError> for JobError {
    fn from(e: AlgoError) -> Self {
        match e {
            AlgoError::Stopped => JobError::Stopped,
            e => JobError::Failed(e.to_string()),
        }
    }
}

impl From<Error> for JobError {
    fn from(e: Error) -> Self {
        JobError::Failed(e.to_string())
    }
}

/// A reproduction: its settings, the runs of one seed, one run, and the report.
pub trait Study: Sync {
    /// Everything that decides the numbers (recorded in `config.json`; a resumed or merged run
    /// must have equal settings).
    type Settings: Clone + PartialEq + Serialize + DeserializeOwned + Send + Sync;
    /// What a finished run leaves (`record.json`).
    type Record: Serialize + DeserializeOwned + Send;

    /// The command's name, e.g. `"p3-leg"`: `config.json`'s `study` and the default directory.
    fn name(&self) -> &str;

    /// Seeds when `--seeds` is not given.
    fn default_seeds(&self) -> u64 {
        5
    }

    /// The settings for `--quick` and a `--config` file, validated.
    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<Self::Settings>;

    /// Whether the command line asks for settings of its own beyond `--quick`/`--config` (then
    /// a resumed run checks them against the recorded ones).
    fn overrides_settings(&self) -> bool {
        false
    }

    /// The runs of `seed` (their names, the keys of records and checkpoints), grouped into
    /// jobs: the runs of a job go one after another in one thread, jobs in parallel. Most
    /// studies run the same on every seed; one may add runs on chosen seeds (p2-maze's F1
    /// experiment).
    fn jobs(&self, settings: &Self::Settings, seed: u64) -> Vec<Vec<String>>;

    /// What one run of `run` allocates at most (networks with their optimizer state, buffers,
    /// planner populations, condition sets), for the check before any work: a job's runs go one
    /// after another, so a job needs its largest run's, and `--jobs` jobs run at once.
    fn memory(&self, settings: &Self::Settings, run: &str) -> Result<MemoryEstimate>;

    /// The length of `run`'s progress bar (e.g. its real steps).
    fn length(&self, settings: &Self::Settings, run: &str) -> u64;

    /// Runs `run` for `seed`, resuming from and saving to `store`, reporting progress (in the
    /// units of [`Study::length`]).
    fn run(
        &self,
        settings: &Self::Settings,
        run: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<Self::Record, JobError>;

    /// `curve.csv` beside a record: header and rows.
    fn curve(&self, record: &Self::Record) -> (Vec<&'static str>, Vec<Vec<f64>>);

    /// The report files this study writes besides `config.json`, `runs/` and `state/`.
    fn report_files(&self) -> &'static [&'static str];

    /// Writes the report of `records` (ordered by seed, then by run as [`Study::jobs`] lists
    /// them) into `dir`; returns the markdown table to print.
    fn report(
        &self,
        dir: &RunDir,
        settings: &Self::Settings,
        records: &[Self::Record],
        wall: f64,
    ) -> Result<String>;
}

/// What `config.json` records.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(bound(deserialize = "S: DeserializeOwned"))]
pub struct RunConfig<S> {
    /// The study's name (directories written before studies recorded it are p0-pendulum's).
    #[serde(default = "first_study")]
    pub study: String,
    /// The settings.
    pub config: S,
    /// Number of seeds.
    pub seeds: u64,
    /// The first seed.
    pub first_seed: u64,
    /// The methods run (`--methods`) when not all are; absent for all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub methods: Option<Vec<String>>,
    /// Whether `--quick` chose the base settings.
    pub quick: bool,
    /// Parallel jobs of the last process.
    pub jobs: u64,
    /// `running`, `interrupted`, `failed` (then `config.json` also holds the `error`) or
    /// `complete`.
    pub status: String,
    /// Wall time of the last (or only) process, seconds; absent while running.
    pub wall_seconds: Option<f64>,
    /// The build that started the study, with those that resumed it; absent in directories
    /// written before builds were recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build: Option<Build>,
}

fn first_study() -> String {
    "p0-pendulum".into()
}

/// The study a `config.json` names.
#[derive(Deserialize)]
struct StudyName {
    #[serde(default = "first_study")]
    study: String,
}

/// A file of a study's directory (`config.json`, a record, its checksum), read up to
/// [`tandem_core::MAX_INPUT_BYTES`].
pub(crate) fn read_study_file(path: &Path) -> std::io::Result<String> {
    tandem_core::read_file_capped(path, tandem_core::MAX_INPUT_BYTES)
}

/// The name of the study that wrote `dir` (its `config.json`'s `study`).
pub fn study_of(dir: &Path) -> Result<String> {
    let path = dir.join("config.json");
    let text = read_study_file(&path).map_err(failed(IoOp::Read, &path))?;
    let n: StudyName = serde_json::from_str(&text)
        .map_err(|e| Error::input(path.display().to_string(), e.to_string()))?;
    Ok(n.study)
}

/// The error of `op` on `path` failing.
pub(crate) fn failed(op: IoOp, path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::io(op, path, source)
}

fn write_json(dir: &RunDir, name: &str, value: &impl Serialize) -> Result<()> {
    let text = to_json_pretty(value).map_err(|e| Error::Other(format!("{name}: {e}")))?;
    write(dir, name, &text)
}

/// Writes the file `name` of `dir` (atomically).
pub fn write(dir: &RunDir, name: &str, text: &str) -> Result<()> {
    dir.write(name, text)
        .map(drop)
        .map_err(failed(IoOp::Write, &dir.path().join(name)))
}

/// Writes a study's `table.json` and its Markdown rendering `table.md`.
pub fn write_table(dir: &RunDir, table: &Table, markdown: &str) -> Result<()> {
    let json = table
        .to_json()
        .map_err(|e| Error::Other(format!("table.json: {e}")))?;
    write(dir, "table.json", &json)?;
    write(dir, "table.md", markdown)
}

/// `curve.csv`'s header and rows of a learning curve: `x` (the samples' name) and the return.
pub fn curve_rows(x: &'static str, curve: &[CurvePoint]) -> (Vec<&'static str>, Vec<Vec<f64>>) {
    let rows = curve
        .iter()
        .map(|p| vec![p.true_samples as f64, p.eval_return])
        .collect();
    (vec![x, "eval_return"], rows)
}

/// Per name in `names` with any run: the mean learning curve (± standard error) over the runs
/// `run` gives that name, each run's curve as (samples, return) points.
pub fn mean_curves<R>(
    records: &[R],
    names: &[&str],
    run: impl Fn(&R) -> (&str, &[CurvePoint]),
) -> Vec<Curve> {
    names
        .iter()
        .filter_map(|&name| {
            let seeds: Vec<Vec<(u64, f64)>> = records
                .iter()
                .map(&run)
                .filter(|(n, _)| *n == name)
                .map(|(_, c)| c.iter().map(|p| (p.true_samples, p.eval_return)).collect())
                .collect();
            (!seeds.is_empty()).then(|| Curve::mean_over_seeds(name, &seeds))
        })
        .collect()
}

/// `dir/config.json`, which must be `study`'s (`what` names the directory in errors).
fn read_config<S: Study>(study: &S, dir: &Path, what: &str) -> Result<RunConfig<S::Settings>> {
    let (path, text) = config_text(study, dir, what)?;
    serde_json::from_str(&text).map_err(|e| {
        let listed = serde_json::from_str::<serde_json::Value>(&text)
            .is_ok_and(|v| v.get("seeds").is_some_and(|s| s.is_array()));
        if listed {
            Error::input(
                what,
                "a merge's directory: its seeds are finished and cannot be resumed; merge it \
                 with others instead",
            )
        } else {
            Error::input(path.display().to_string(), e.to_string())
        }
    })
}

/// `config.json` as merge reads it: a study's own (`seeds` counted from `first_seed`) or a
/// merge's (`seeds` listed, `parts` the directories whose processes ran them).
#[derive(Deserialize)]
#[serde(bound(deserialize = "S: DeserializeOwned"))]
struct DirConfig<S> {
    config: S,
    quick: bool,
    seeds: SeedSet,
    #[serde(default)]
    first_seed: u64,
    #[serde(default)]
    methods: Option<Vec<String>>,
    status: String,
    /// Why a `failed` study failed.
    #[serde(default)]
    error: Option<String>,
    wall_seconds: Option<f64>,
    #[serde(default)]
    parts: Vec<Part>,
    /// A study's build (absent before builds were recorded).
    #[serde(default)]
    build: Option<Build>,
    /// A merge's builds of its parts.
    #[serde(default)]
    builds: Vec<PartBuild>,
}

/// A directory whose process ran seeds: its path (as the merge that read it was given it), first
/// seed, seed count and wall time.
type Part = (String, u64, u64, Option<f64>);

/// `config.json`'s `seeds`: a count from `first_seed` (a study's) or a list (a merge's).
#[derive(Deserialize)]
#[serde(untagged)]
enum SeedSet {
    Count(u64),
    List(Vec<u64>),
}

impl<S> DirConfig<S> {
    fn seeds(&self) -> Result<Vec<u64>> {
        Ok(match &self.seeds {
            SeedSet::Count(n) => seed_range(self.first_seed, *n)?.collect(),
            SeedSet::List(l) => l.clone(),
        })
    }

    /// The processes that ran this directory's seeds: a merge's parts, or the study itself
    /// (`dir`), so that merging merges again sums the same wall times.
    fn leaves(&self, dir: &Path) -> Result<Vec<Part>> {
        let seeds = self.seeds()?;
        Ok(match &self.seeds {
            SeedSet::List(_) if !self.parts.is_empty() => self.parts.clone(),
            _ => vec![(
                dir.display().to_string(),
                seeds.iter().copied().min().unwrap_or(self.first_seed),
                seeds.len() as u64,
                self.wall_seconds,
            )],
        })
    }

    /// The builds of [`DirConfig::leaves`] that recorded one.
    fn leaf_builds(&self, dir: &Path) -> Vec<PartBuild> {
        match &self.seeds {
            SeedSet::List(_) if !self.parts.is_empty() => self.builds.clone(),
            _ => self
                .build
                .iter()
                .map(|b| PartBuild {
                    part: dir.display().to_string(),
                    build: b.clone(),
                })
                .collect(),
        }
    }
}

/// `dir/config.json` of a study or a merge for [`merge`].
fn read_dir_config<S: Study>(study: &S, dir: &Path, what: &str) -> Result<DirConfig<S::Settings>> {
    let (path, text) = config_text(study, dir, what)?;
    serde_json::from_str(&text).map_err(|e| Error::input(path.display().to_string(), e.to_string()))
}

/// `dir/config.json`'s path and text, which must name `study`.
fn config_text<S: Study>(study: &S, dir: &Path, what: &str) -> Result<(PathBuf, String)> {
    let path = dir.join("config.json");
    let text = read_study_file(&path).map_err(|e| {
        Error::input(
            what,
            format!(
                "{} cannot be read ({e}): not a study's directory",
                path.display()
            ),
        )
    })?;
    let bad = |e: serde_json::Error| Error::input(path.display().to_string(), e.to_string());
    let name: StudyName = serde_json::from_str(&text).map_err(bad)?;
    if name.study != study.name() {
        return Err(Error::input(
            what,
            format!(
                "the directory holds a {} study, not {}",
                name.study,
                study.name()
            ),
        ));
    }
    Ok((path, text))
}

/// The settings of a new study from the command line.
fn fresh<S: Study>(study: &S, args: &StudyArgs) -> Result<RunConfig<S::Settings>> {
    let settings = study.settings(args.quick, args.config.as_deref())?;
    ensure_finite(&settings).map_err(|e| Error::input("settings", e.to_string()))?;
    Ok(RunConfig {
        study: study.name().to_string(),
        config: settings,
        seeds: args.seeds.unwrap_or(study.default_seeds()),
        first_seed: args.first_seed.unwrap_or(0),
        methods: args.methods.clone(),
        quick: args.quick,
        jobs: args.jobs,
        status: "running".into(),
        wall_seconds: None,
        build: Some(Build::current()),
    })
}

/// The most seeds one process runs: its jobs are listed before the first starts.
pub const MAX_SEEDS: u64 = 100_000;

/// The seeds `first, first + 1, ..., first + seeds - 1`, refused when empty, above [`MAX_SEEDS`]
/// or past `u64::MAX`.
pub fn seed_range(first: u64, seeds: u64) -> Result<std::ops::Range<u64>> {
    let what = "--seeds/--first-seed";
    if seeds == 0 || seeds > MAX_SEEDS {
        return Err(Error::input(
            what,
            format!("{seeds} seeds: a process runs 1 to {MAX_SEEDS} (run more as separate processes and merge them)"),
        ));
    }
    match first.checked_add(seeds) {
        Some(end) => Ok(first..end),
        None => Err(Error::input(
            what,
            format!(
                "{seeds} seeds from {first} run past the last seed a process can run, {}",
                u64::MAX - 1
            ),
        )),
    }
}

/// The runs of `seed` that `methods` selects (all for `None`), grouped into jobs as
/// [`Study::jobs`] groups them; a job left without runs is dropped.
pub fn selected_jobs<S: Study>(
    study: &S,
    settings: &S::Settings,
    seed: u64,
    methods: Option<&[String]>,
) -> Vec<Vec<String>> {
    let mut jobs = study.jobs(settings, seed);
    if let Some(methods) = methods {
        for job in &mut jobs {
            job.retain(|run| methods.contains(run));
        }
        jobs.retain(|job| !job.is_empty());
    }
    jobs
}

/// The jobs of the run `rc` records, each with its seed, in the order a run starts them: the
/// cells of a sweep.
pub fn cells<S: Study>(study: &S, rc: &RunConfig<S::Settings>) -> Result<Vec<(u64, Vec<String>)>> {
    let methods = rc.methods.as_deref();
    Ok(seed_range(rc.first_seed, rc.seeds)?
        .flat_map(|seed| {
            selected_jobs(study, &rc.config, seed, methods)
                .into_iter()
                .map(move |job| (seed, job))
        })
        .collect())
}

/// Every run of `seeds` that `methods` selects, once each, in the order the study lists them.
fn runs_of<S: Study>(
    study: &S,
    settings: &S::Settings,
    seeds: impl IntoIterator<Item = u64>,
    methods: Option<&[String]>,
) -> Vec<String> {
    let mut runs: Vec<String> = Vec::new();
    for seed in seeds {
        for run in selected_jobs(study, settings, seed, methods)
            .into_iter()
            .flatten()
        {
            if !runs.contains(&run) {
                runs.push(run);
            }
        }
    }
    runs
}

/// `--methods` checked against the runs of `seeds`: each one of the study's, none twice, at
/// least one run selected. Returns them in the study's order, or `None` when they are all.
pub fn select_methods<S: Study>(
    study: &S,
    settings: &S::Settings,
    seeds: impl IntoIterator<Item = u64> + Clone,
    methods: Option<&[String]>,
) -> Result<Option<Vec<String>>> {
    let Some(methods) = methods else {
        return Ok(None);
    };
    let all = runs_of(study, settings, seeds, None);
    for (k, m) in methods.iter().enumerate() {
        if !all.contains(m) {
            return Err(Error::input(
                "--methods",
                format!(
                    "{} has no run {m:?} on these seeds; its runs are {}",
                    study.name(),
                    all.join(", ")
                ),
            ));
        }
        if methods[..k].contains(m) {
            return Err(Error::input("--methods", format!("{m} is named twice")));
        }
    }
    let chosen: Vec<String> = all
        .iter()
        .filter(|r| methods.contains(r))
        .cloned()
        .collect();
    Ok((chosen.len() < all.len()).then_some(chosen))
}

/// Checks that `jobs` parallel jobs of `settings` fit in memory before any work: each job needs
/// its largest run's estimate ([`Study::memory`]), and the `jobs` largest jobs run at once.
/// The error names the run, its largest part (the setting to change) and the limit.
fn check_memory<S: Study>(
    study: &S,
    settings: &S::Settings,
    cells: &[(u64, Vec<String>)],
    jobs: u64,
    what: &str,
) -> Result<u64> {
    let limit = memory_limit().map_err(|e| Error::input("memory limit", e.to_string()))?;
    // Runs are the same on most seeds: estimate each distinct job once.
    let mut distinct: Vec<Vec<String>> = Vec::new();
    let mut count: Vec<u64> = Vec::new();
    for (_, job) in cells {
        match distinct.iter().position(|j| j == job) {
            Some(k) => count[k] += 1,
            None => {
                distinct.push(job.clone());
                count.push(1);
            }
        }
    }
    let mut per_job: Vec<(u64, String, MemoryEstimate)> = Vec::new();
    for (job, n) in distinct.iter().zip(&count) {
        let estimates = job
            .iter()
            .map(|run| Ok((run.clone(), study.memory(settings, run)?)))
            .collect::<Result<Vec<_>>>()?;
        let largest = estimates
            .into_iter()
            .max_by_key(|(_, e)| e.total().map_or(u128::MAX, u128::from));
        let Some((run, est)) = largest else { continue };
        // An estimate that alone is over the limit names its run.
        est.check_against(&format!("{what}: the {run} run"), limit)
            .map_err(|e| Error::input("memory", e.to_string()))?;
        let bytes = est.total().unwrap_or(u64::MAX);
        per_job.extend(std::iter::repeat_n(
            (bytes, run, est),
            (*n).min(jobs) as usize,
        ));
    }
    per_job.sort_by_key(|j| std::cmp::Reverse(j.0));
    let at_once = per_job
        .into_iter()
        .take(jobs as usize)
        .fold(MemoryEstimate::new(), |acc, (_, run, est)| {
            acc.with(&format!("{run}: "), est)
        });
    at_once
        .check_against(&format!("{what}: {jobs} parallel jobs (--jobs)"), limit)
        .map_err(|e| Error::input("memory", e.to_string()))
}

/// The settings recorded in `dir/config.json`, checked against the command line.
fn recorded<S: Study>(study: &S, args: &StudyArgs, dir: &Path) -> Result<RunConfig<S::Settings>> {
    let what = format!("--resume {}", dir.display());
    let mut rc = read_config(study, dir, &what)?;
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
    if args.config.is_some() || args.quick || study.overrides_settings() {
        let given = study.settings(rc.quick, args.config.as_deref())?;
        if given != rc.config {
            conflicts.push("the settings (they differ from the run's config.json)".into());
        }
    }
    if !conflicts.is_empty() {
        return Err(Error::input(
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

/// One seed's checkpoints as files `<dir>/<key>.safetensors`, stopping on SIGINT/SIGTERM.
pub struct SeedState {
    dir: PathBuf,
    stop: Stop,
}

impl SeedState {
    /// The checkpoints in `dir` (created on the first save).
    pub fn new(dir: PathBuf, stop: Stop) -> Self {
        Self { dir, stop }
    }

    fn path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.safetensors"))
    }
}

impl Checkpoints for SeedState {
    fn load(&mut self, key: &str) -> AlgoResult<Option<Checkpoint>> {
        let path = self.path(key);
        if !path.exists() {
            return Ok(None);
        }
        Checkpoint::load(&path)
            .map(Some)
            .map_err(|e| AlgoError::Checkpoint(format!("{}: {e}", path.display())))
    }

    fn save(&mut self, key: &str, ckpt: &Checkpoint) -> AlgoResult<()> {
        std::fs::create_dir_all(&self.dir)
            .map_err(|e| AlgoError::Checkpoint(format!("{}: {e}", self.dir.display())))?;
        Ok(ckpt.save(self.path(key))?)
    }

    fn stop_requested(&self) -> bool {
        self.stop.requested()
    }
}

/// `runs/<run>__seed<k>/` of the study directory `dir`.
fn record_dir(dir: &Path, run: &str, seed: u64) -> PathBuf {
    dir.join("runs").join(format!("{run}__seed{seed}"))
}

/// The file beside each `record.json` holding its SHA-256 as `sha256sum` writes it, so that
/// `sha256sum -c record.json.sha256` checks a record without tandem.
const CHECKSUM: &str = "record.json.sha256";

/// `bytes`' SHA-256 in lowercase hexadecimal.
fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    use std::fmt::Write as _;
    Sha256::digest(bytes)
        .iter()
        .fold(String::with_capacity(64), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

/// Writes a finished run's `curve.csv` and `record.json` (the record last: its presence says
/// the run is done).
fn write_record<S: Study>(
    study: &S,
    dir: &Path,
    run: &str,
    seed: u64,
    r: &S::Record,
) -> Result<()> {
    let path = record_dir(dir, run, seed).join("record.json");
    let text = to_json_pretty(r).map_err(|e| Error::Other(format!("{}: {e}", path.display())))?;
    write_record_text(study, dir, run, seed, r, &text)
}

/// [`write_record`] with the record's text given (a merge copies each record's bytes).
fn write_record_text<S: Study>(
    study: &S,
    dir: &Path,
    run: &str,
    seed: u64,
    r: &S::Record,
    text: &str,
) -> Result<()> {
    let sub = record_dir(dir, run, seed);
    std::fs::create_dir_all(&sub).map_err(failed(IoOp::Create, &sub))?;
    let (header, rows) = study.curve(r);
    let curve = crate::run::csv(&header, &rows);
    let path = sub.join("curve.csv");
    tandem_nn::write_atomic(&path, curve.as_bytes()).map_err(failed(IoOp::Write, &path))?;
    // The checksum before the record, whose presence alone says the run is done.
    let path = sub.join(CHECKSUM);
    let line = format!("{}  record.json\n", sha256_hex(text.as_bytes()));
    tandem_nn::write_atomic(&path, line.as_bytes()).map_err(failed(IoOp::Write, &path))?;
    let path = sub.join("record.json");
    tandem_nn::write_atomic(&path, text.as_bytes()).map_err(failed(IoOp::Write, &path))
}

/// A finished run's record as its folder holds it.
struct Stored<R> {
    run: String,
    seed: u64,
    record: R,
    /// The file's text, which a merge copies unchanged.
    text: String,
    /// Whether a checksum covered it (records written before records had one have none).
    checksummed: bool,
}

/// A finished run's record, if it is there, checked against the run and seed of its folder and
/// against its checksum where it has one.
fn read_record<R: DeserializeOwned>(dir: &Path, run: &str, seed: u64) -> Result<Option<Stored<R>>> {
    let sub = record_dir(dir, run, seed);
    let path = sub.join("record.json");
    let text = match read_study_file(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(Error::io(IoOp::Read, path, source)),
    };
    let bad = |message: String| Error::input(path.display().to_string(), message);
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    // Every study's records name their seed, and all but p2-maze's F1 experiment their method
    // (the run's name): a record moved or edited into another run's folder disagrees.
    let folder = format!("runs/{run}__seed{seed}/");
    if let Some(s) = value.get("seed").filter(|s| s.as_u64() != Some(seed)) {
        return Err(bad(format!(
            "records seed {s}, but its folder {folder} is seed {seed}'s"
        )));
    }
    if let Some(m) = value.get("method").filter(|m| m.as_str() != Some(run)) {
        return Err(bad(format!(
            "records method {m}, but its folder {folder} is the {run} run's"
        )));
    }
    let sum_path = sub.join(CHECKSUM);
    let checksummed = match read_study_file(&sum_path) {
        Ok(line) => {
            let recorded = line.split_whitespace().next().unwrap_or_default();
            let actual = sha256_hex(text.as_bytes());
            if recorded != actual {
                return Err(bad(format!(
                    "its SHA-256 is {actual}, but {CHECKSUM} beside it says {recorded}: the \
                     record changed after it was written"
                )));
            }
            true
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(source) => return Err(Error::io(IoOp::Read, sum_path, source)),
    };
    let record = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    Ok(Some(Stored {
        run: run.to_string(),
        seed,
        record,
        text,
        checksummed,
    }))
}

/// The record of every run of `seeds` that `methods` selects in the study directory `dir`, by
/// seed, then run.
fn read_records<S: Study>(
    study: &S,
    settings: &S::Settings,
    dir: &Path,
    seeds: impl IntoIterator<Item = u64>,
    methods: Option<&[String]>,
) -> Result<Vec<Stored<S::Record>>> {
    let mut records = Vec::new();
    for seed in seeds {
        for run in selected_jobs(study, settings, seed, methods)
            .iter()
            .flatten()
        {
            let r = read_record(dir, run, seed)?.ok_or_else(|| {
                Error::Other(format!(
                    "{}: seed {seed}: the {run} run left no record",
                    dir.display()
                ))
            })?;
            records.push(r);
        }
    }
    Ok(records)
}

/// Refuses a record in `dir/runs/` that is no run of `records` (the directory's seeds and
/// settings): a merge would leave it out without a word.
fn refuse_strays<R>(dir: &Path, records: &[Stored<R>]) -> Result<()> {
    let runs = dir.join("runs");
    let entries = match std::fs::read_dir(&runs) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(source) => return Err(Error::io(IoOp::Read, runs, source)),
    };
    for entry in entries {
        let entry = entry.map_err(failed(IoOp::Read, &runs))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let record = entry.path().join("record.json");
        let known = records
            .iter()
            .any(|r| name == format!("{}__seed{}", r.run, r.seed));
        if !known && record.exists() {
            return Err(Error::input(
                record.display().to_string(),
                "is no run of its directory's seeds and settings (config.json): move it out, \
                 or merge the directory it belongs to",
            ));
        }
    }
    Ok(())
}

fn layout<S: Study>(study: &S, merged: bool) -> Layout {
    // `Layout` wants static names: a study's few files, leaked once per process.
    let mut owned: Vec<&'static str> = vec!["config.json", "runs"];
    if !merged {
        owned.push("state");
    }
    owned.extend_from_slice(study.report_files());
    Layout {
        owned: Box::leak(owned.into_boxed_slice()),
        resumable: !merged,
    }
}

/// The settings the command line asks for (or `--resume` records), checked whole before any
/// work: each setting's range, the seed range, the methods, and the memory of `--jobs` parallel
/// jobs. Returns them with the estimated peak memory in bytes and the jobs ([`cells`]).
#[allow(clippy::type_complexity)]
pub fn check<S: Study>(
    study: &S,
    args: &StudyArgs,
) -> Result<(RunConfig<S::Settings>, u64, Vec<(u64, Vec<String>)>)> {
    let mut rc = match &args.resume {
        Some(dir) => recorded(study, args, dir)?,
        None => fresh(study, args)?,
    };
    let seeds = seed_range(rc.first_seed, rc.seeds)?;
    let asked = args.methods.as_deref().or(rc.methods.as_deref());
    let methods = select_methods(study, &rc.config, seeds.clone(), asked)?;
    if let (Some(dir), Some(given)) = (&args.resume, &args.methods) {
        if methods != rc.methods {
            return Err(Error::input(
                format!("--resume {}", dir.display()),
                format!(
                    "conflicts with the run being resumed: --methods {} (the run has {}); a \
                     resumed run keeps its settings",
                    given.join(","),
                    rc.methods
                        .as_ref()
                        .map_or("all".to_string(), |m| m.join(","))
                ),
            ));
        }
    }
    rc.methods = methods;
    let jobs = cells(study, &rc)?;
    let bytes = check_memory(study, &rc.config, &jobs, args.jobs, &harness_what(args))?;
    Ok((rc, bytes, jobs))
}

/// Runs (or resumes) `study` as the command line says, after [`check`].
pub fn run<S: Study>(study: &S, args: &StudyArgs) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let stop = args.stop.clone();
    let (mut rc, bytes, jobs) = check(study, args)?;
    if args.check {
        println!(
            "{}: settings valid; {} seeds from {}; estimated peak memory {} with {} parallel jobs \
             (limit {})",
            study.name(),
            rc.seeds,
            rc.first_seed,
            tandem_nn::budget::show_bytes(bytes),
            args.jobs,
            tandem_nn::budget::show_bytes(memory_limit().unwrap_or(0)),
        );
        return Ok(());
    }
    let (out, existing) = match (&args.resume, args.overwrite) {
        (Some(d), _) => (Some(d.as_path()), Existing::Resume),
        (None, true) => (args.out.as_deref(), Existing::Overwrite),
        (None, false) => (args.out.as_deref(), Existing::Refuse),
    };
    let dir =
        RunDir::create(out, study.name(), layout(study, false), existing).map_err(Error::other)?;
    if let Some(pid) = dir.stale_lock_taken_over() {
        eprintln!(
            "note: took over {} from process {pid}, which is no longer running",
            dir.path().display()
        );
    }
    if args.resume.is_some() {
        if let Some(note) = provenance::on_resume(&mut rc.build, Build::current()) {
            eprintln!("{}: {note}", dir.path().display());
        }
    }
    rc.status = "running".into();
    rc.wall_seconds = None;
    write_json(&dir, "config.json", &rc)?;
    let start = Instant::now();
    let multi = MultiProgress::new();
    if args.quiet {
        multi.set_draw_target(ProgressDrawTarget::hidden());
    }
    let style =
        ProgressStyle::with_template("{prefix:>24} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
    let settings = &rc.config;
    let next = AtomicUsize::new(0);
    let errors: Mutex<Vec<(u64, String)>> = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..(args.jobs as usize).min(jobs.len()) {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                if k >= jobs.len() || stop.requested() {
                    break;
                }
                let (seed, runs) = &jobs[k];
                let state = job_state(dir.path(), *seed, runs);
                let mut store = SeedState::new(state.clone(), stop.clone());
                let done = runs.iter().try_for_each(|run| {
                    run_one(
                        study, &dir, settings, run, *seed, &mut store, &multi, &style,
                    )
                    .map_err(|e| (run, e))
                });
                let failed = match done {
                    // A stopped job keeps its checkpoints for `--resume`.
                    Err((_, JobError::Stopped)) => None,
                    Err((run, JobError::Failed(e))) => Some(format!("{run}: {e}")),
                    Ok(()) => remove_dir(&state).err().map(|e| e.to_string()),
                };
                if let Some(e) = failed {
                    let mut errors = errors.lock().expect("no panics while holding the lock");
                    errors.push((*seed, e));
                }
            });
        }
    });
    let wall = start.elapsed().as_secs_f64();
    let mut errors = errors.into_inner().expect("threads joined");
    errors.sort();
    if let Some((seed, e)) = errors.first() {
        let e = Error::Other(format!("seed {seed}: {e}"));
        return Err(mark_failed(study, &dir, &mut rc, wall, e));
    }
    if stop.requested() {
        rc.status = "interrupted".into();
        rc.wall_seconds = Some(wall);
        write_json(&dir, "config.json", &rc)?;
        return Err(Error::Interrupted {
            what: format!(
                "finished runs and the others' last checkpoints are in {}; continue with \
                 `tandem reproduce {} --resume {}`",
                dir.path().display(),
                study.name(),
                dir.path().display()
            ),
            code: stop.exit_code().unwrap_or(EXIT_SIGINT),
        });
    }
    let seeds = seed_range(rc.first_seed, rc.seeds)?;
    let report = || -> Result<String> {
        let records = read_records(study, settings, dir.path(), seeds, rc.methods.as_deref())?;
        remove_dir(&dir.path().join("state"))?;
        let records: Vec<S::Record> = records.into_iter().map(|r| r.record).collect();
        study.report(&dir, settings, &records, wall)
    };
    let md = match report() {
        Ok(md) => md,
        Err(e) => return Err(mark_failed(study, &dir, &mut rc, wall, e)),
    };
    rc.status = "complete".into();
    rc.wall_seconds = Some(wall);
    if let Err(e) = write_json(&dir, "config.json", &rc) {
        return Err(mark_failed(study, &dir, &mut rc, wall, e));
    }
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

/// How errors name the settings of a run: its `--config` file, the resumed directory, or the
/// study's own.
fn harness_what(args: &StudyArgs) -> String {
    match &args.resume {
        Some(d) => format!("--resume {}", d.display()),
        None => settings_name(args.config.as_deref()),
    }
}

/// `config.json` of a failed study: the run's, with why it failed.
#[derive(Serialize)]
struct FailedConfig<'a, S> {
    #[serde(flatten)]
    run: &'a RunConfig<S>,
    error: &'a str,
}

/// Marks `dir`'s `config.json` `failed` with `e` as the reason, and returns the error to report:
/// `e` and how to go on. Finished records and the checkpoints of unfinished jobs stay, so that
/// `--resume` continues once the cause (a full disk, a removed file) is fixed.
fn mark_failed<S: Study>(
    study: &S,
    dir: &RunDir,
    rc: &mut RunConfig<S::Settings>,
    wall: f64,
    e: Error,
) -> Error {
    let reason = e.to_string();
    rc.status = "failed".into();
    rc.wall_seconds = Some(wall);
    let failed = FailedConfig {
        run: rc,
        error: &reason,
    };
    let d = dir.path().display();
    let marked = match write_json(dir, "config.json", &failed) {
        Ok(()) => format!("{d}/config.json records the failure"),
        // A full disk may refuse this too; then config.json still says `running`.
        Err(w) => format!("{w}, so config.json does not record the failure"),
    };
    Error::Other(format!(
        "{reason}\n{marked}; finished runs and the others' last checkpoints stay: once the cause \
         is fixed, continue with `tandem reproduce {} --resume {d}`",
        study.name()
    ))
}

/// `state/seed<k>/<first run>/`: the checkpoints of one job (its runs may share some, e.g. a
/// pre-trained agent), removed when the job is done.
fn job_state(dir: &Path, seed: u64, runs: &[String]) -> PathBuf {
    let first = runs.first().map_or("job", String::as_str);
    dir.join("state").join(format!("seed{seed}")).join(first)
}

fn remove_dir(path: &Path) -> Result<()> {
    match std::fs::remove_dir_all(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(IoOp::Remove, path, e)),
        _ => Ok(()),
    }
}

/// One run of one seed, skipped if recorded.
#[allow(clippy::too_many_arguments)]
fn run_one<S: Study>(
    study: &S,
    dir: &RunDir,
    settings: &S::Settings,
    run: &str,
    seed: u64,
    store: &mut dyn Checkpoints,
    multi: &MultiProgress,
    style: &ProgressStyle,
) -> std::result::Result<(), JobError> {
    if read_record::<S::Record>(dir.path(), run, seed)?.is_none() {
        let bar = multi.add(ProgressBar::new(study.length(settings, run)));
        bar.set_style(style.clone());
        bar.set_prefix(format!("seed {seed} {run}"));
        let r = study.run(settings, run, seed, store, &mut |n| bar.set_position(n));
        bar.finish();
        write_record(study, dir.path(), run, seed, &r?)?;
    }
    Ok(())
}

/// What a merge's `config.json` records; [`merge`] reads it back ([`DirConfig`]), so that a
/// merged directory merges again.
#[derive(Debug, Serialize)]
struct MergeConfig<'a, S> {
    study: &'a str,
    config: &'a S,
    quick: bool,
    /// The seeds, ascending (any set: merges of merges need not be contiguous).
    seeds: Vec<u64>,
    /// The methods, when not all of the study's.
    #[serde(skip_serializing_if = "Option::is_none")]
    methods: Option<Vec<String>>,
    /// The directories whose processes ran the seeds (through merged directories too), by
    /// first seed, with their first seed, seed count and wall time.
    parts: Vec<Part>,
    /// The builds of the parts that recorded one, in the order of `parts`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    builds: Vec<PartBuild>,
    /// The commits of `builds` when there are several: the merged numbers are each
    /// bit-reproducible only at their own.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    mixed_commits: Vec<String>,
    /// The directories this merge read.
    merged: Vec<String>,
    /// The build that merged them and wrote the report.
    merged_by: Build,
    /// Sum of the parts' wall times, seconds.
    wall_seconds: f64,
    status: &'static str,
}

/// Joins complete directories of `study` (studies' or merges') with disjoint (seed, method)
/// cells and equal settings into one report in `out` (default `runs/<study>-merged__<time>/`).
/// The cells must make a table: every merged method on every merged seed.
///
/// Each record must agree with its folder (its `seed` and `method`) and with its checksum
/// (`record.json.sha256`); a record without one (written before records had checksums) is
/// taken as it is, with a note. Records are copied byte for byte, so that merging in two
/// levels (per node, then across nodes) writes the report of one merge of all parts.
pub fn merge<S: Study>(
    study: &S,
    dirs: &[PathBuf],
    out: Option<&Path>,
    overwrite: bool,
) -> Result<()> {
    let mut parts: Vec<(PathBuf, DirConfig<S::Settings>)> = Vec::new();
    for d in dirs {
        let what = d.display().to_string();
        let dc = read_dir_config(study, d, &what)?;
        let resume = format!(
            "`tandem reproduce {} --resume {}`",
            study.name(),
            d.display()
        );
        match dc.status.as_str() {
            "complete" => {}
            "failed" => {
                return Err(Error::input(
                    what,
                    format!(
                        "the study failed ({}); fix the cause, continue it with {resume}, then \
                         merge it",
                        dc.error.as_deref().unwrap_or("no reason recorded")
                    ),
                ))
            }
            status => {
                return Err(Error::input(
                    what,
                    format!("the study is {status}; finish it first ({resume})"),
                ))
            }
        }
        if let Some((first, f)) = parts.first() {
            if (&f.config, f.quick) != (&dc.config, dc.quick) {
                return Err(Error::input(
                    what,
                    format!(
                        "its settings differ from {}'s: only runs of one configuration merge",
                        first.display()
                    ),
                ));
            }
        }
        parts.push((d.clone(), dc));
    }
    let Some((_, first)) = parts.first() else {
        return Err(Error::input("merge", "no directories given"));
    };
    let settings = &first.config;
    let mut seeds: Vec<u64> = Vec::new();
    let mut leaves: Vec<Part> = Vec::new();
    let mut builds: Vec<PartBuild> = Vec::new();
    let mut stored: Vec<Stored<S::Record>> = Vec::new();
    let mut cells: HashSet<(u64, String)> = HashSet::new();
    for (d, dc) in &parts {
        let own = dc.seeds()?;
        let mut unique = own.clone();
        unique.sort_unstable();
        unique.dedup();
        if unique.len() != own.len() {
            return Err(Error::input(
                format!("{}/config.json", d.display()),
                "lists a seed twice",
            ));
        }
        let methods = dc.methods.as_deref();
        let records = read_records(study, settings, d, own.iter().copied(), methods)?;
        refuse_strays(d, &records)?;
        if let Some(r) = records
            .iter()
            .find(|r| !cells.insert((r.seed, r.run.clone())))
        {
            return Err(Error::input(
                d.display().to_string(),
                format!(
                    "seed {}'s {} run is in two of the merged directories",
                    r.seed, r.run
                ),
            ));
        }
        let unchecked = records.iter().filter(|r| !r.checksummed).count();
        if unchecked > 0 {
            eprintln!(
                "note: {}: {unchecked} of {} records have no checksum (written before records \
                 had one); merged as they are",
                d.display(),
                records.len()
            );
        }
        seeds.extend(own);
        leaves.extend(dc.leaves(d)?);
        builds.extend(dc.leaf_builds(d));
        stored.extend(records);
    }
    seeds.sort_unstable();
    seeds.dedup();
    // The cells must make a table: every selected method on every seed.
    let mut ran: Vec<String> = Vec::new();
    for r in &stored {
        if !ran.contains(&r.run) {
            ran.push(r.run.clone());
        }
    }
    let methods = select_methods(study, settings, seeds.iter().copied(), Some(&ran))?;
    let order: Vec<(u64, String)> = seeds
        .iter()
        .flat_map(|&seed| {
            selected_jobs(study, settings, seed, methods.as_deref())
                .into_iter()
                .flatten()
                .map(move |run| (seed, run))
        })
        .collect();
    if let Some((seed, run)) = order.iter().find(|cell| !cells.contains(*cell)) {
        return Err(Error::input(
            "merge",
            format!(
                "seed {seed}'s {run} run is in none of the directories: a table needs every \
                 merged method on every merged seed; run it (`tandem reproduce {} --seeds 1 \
                 --first-seed {seed} --methods {run}`) and merge its directory too",
                study.name()
            ),
        ));
    }
    // By seed, then run as the study lists them.
    let rank: HashMap<(u64, String), usize> =
        order.into_iter().enumerate().map(|(k, c)| (c, k)).collect();
    stored.sort_by_key(|r| rank.get(&(r.seed, r.run.clone())).copied());
    leaves.sort_by(|a, b| (a.1, &a.0).cmp(&(b.1, &b.0)));
    let mixed_commits = merged_builds(&mut builds, &leaves);
    // Summed in the parts' seed order, so that a merge of merges gives the same number.
    let wall: f64 = leaves.iter().filter_map(|p| p.3).sum();
    let existing = if overwrite {
        Existing::Overwrite
    } else {
        Existing::Refuse
    };
    let name = format!("{}-merged", study.name());
    let dir = RunDir::create(out, &name, layout(study, true), existing).map_err(Error::other)?;
    for r in &stored {
        write_record_text(study, dir.path(), &r.run, r.seed, &r.record, &r.text)?;
    }
    let records: Vec<S::Record> = stored.into_iter().map(|r| r.record).collect();
    let md = study.report(&dir, settings, &records, wall)?;
    let merged = MergeConfig {
        study: study.name(),
        config: settings,
        quick: first.quick,
        seeds,
        methods,
        parts: leaves,
        builds,
        mixed_commits,
        merged: dirs.iter().map(|d| d.display().to_string()).collect(),
        merged_by: Build::current(),
        wall_seconds: wall,
        status: "complete",
    };
    write_json(&dir, "config.json", &merged)?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

/// Puts a merge's `builds` in the order of its `leaves` and warns when they are not all of one
/// commit, or when some parts recorded no build; returns the commits when there are several.
/// Builds never stop a merge: settings alone decide what merges.
fn merged_builds(builds: &mut [PartBuild], leaves: &[Part]) -> Vec<String> {
    let rank = |b: &PartBuild| leaves.iter().position(|l| l.0 == b.part);
    builds.sort_by_key(rank);
    let mut commits = provenance::distinct_commits(builds);
    let mixed = commits.len() > 1;
    if mixed {
        eprintln!(
            "warning: the merged runs come from {} commits ({}): each part's numbers are \
             bit-reproducible only at its own commit; config.json lists them under builds",
            commits.len(),
            commits
                .iter()
                .map(|c| provenance::short_commit(c))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let dirty = builds
        .iter()
        .filter(|b| {
            std::iter::once(&b.build)
                .chain(&b.build.resumed_by)
                .any(|b| b.dirty)
        })
        .count();
    if dirty > 0 {
        eprintln!(
            "note: {dirty} merged parts ran on a build with uncommitted changes (dirty), which \
             no commit reproduces"
        );
    }
    let unrecorded = leaves.len().saturating_sub(builds.len());
    if !builds.is_empty() && unrecorded > 0 {
        eprintln!(
            "note: {unrecorded} of {} merged parts record no build (run before builds were \
             recorded)",
            leaves.len()
        );
    }
    if !mixed {
        commits.clear();
    }
    commits
}

/// Applies the overrides in `text` (a `--config` file, named `what` in errors) to `base`: the
/// file's tables merge into the serialized base, key by key; unknown keys are errors where the
/// settings deny them.
pub fn override_settings<C: Serialize + DeserializeOwned>(
    base: &C,
    text: &str,
    what: &str,
) -> Result<C> {
    let over: toml::Table = toml::from_str(text).map_err(|e| Error::input(what, e.to_string()))?;
    override_with_table(base, over, what)
}

/// [`override_settings`] with the overrides already parsed.
pub fn override_with_table<C: Serialize + DeserializeOwned>(
    base: &C,
    over: toml::Table,
    what: &str,
) -> Result<C> {
    let mut v = toml::Value::try_from(base).map_err(Error::other)?;
    merge_toml(&mut v, toml::Value::Table(over));
    let c: C = v
        .try_into()
        .map_err(|e: toml::de::Error| Error::input(what, e.to_string()))?;
    ensure_finite(&c).map_err(|e| Error::input(what, e.to_string()))?;
    Ok(c)
}

/// `base` with `over`'s keys, tables merged recursively.
fn merge_toml(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(b), toml::Value::Table(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(bv) if bv.is_table() && v.is_table() => merge_toml(bv, v),
                    _ => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, o) => *b = o,
    }
}

/// The `--config` file at `path` as a TOML table, for a study that takes some keys out before
/// applying the rest ([`override_with_table`]). At most [`tandem_core::MAX_CONFIG_BYTES`]
/// (1 MiB) are read: more (or an endless stream) is an error naming the file and the limit.
pub fn read_table(path: &Path) -> Result<toml::Table> {
    let text = tandem_core::read_file_capped(path, tandem_core::MAX_CONFIG_BYTES)
        .map_err(failed(IoOp::Read, path))?;
    toml::from_str(&text).map_err(|e| Error::input(settings_name(Some(path)), e.to_string()))
}

/// How errors name a study's settings: `--config PATH` for a file's, `settings` for the
/// defaults.
pub fn settings_name(config: Option<&Path>) -> String {
    config.map_or("settings".to_string(), |p| {
        format!("--config {}", p.display())
    })
}

/// Reads a `--config` file and applies it to `base` ([`override_settings`]).
pub fn read_overrides<C: Serialize + DeserializeOwned>(base: C, path: Option<&Path>) -> Result<C> {
    let Some(p) = path else { return Ok(base) };
    override_with_table(&base, read_table(p)?, &settings_name(path))
}
