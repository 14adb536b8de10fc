//! What every resumable `tandem reproduce` study shares: the command line (`--seeds`,
//! `--first-seed`, `--quick`, `--out`, `--jobs`, `--config`, `--quiet`, `--overwrite`,
//! `--resume`), the run directory, parallel jobs, checkpoints on disk, each run's record, the
//! report, and merging the directories of separate processes.
//!
//! A [`Study`] says what its settings are, which runs make one seed (grouped into jobs), how one
//! run goes and what report its records make. [`run`] then writes, in the output directory:
//!
//! - `config.json`: the study's name, its settings, the seeds, and how the run stands (`running`,
//!   `interrupted`, `complete`) with its wall time;
//! - `runs/<run>__seed<k>/record.json` (and the study's `curve.csv`) as soon as a run finishes;
//! - `state/seed<k>/<job>/`: each unfinished job's checkpoints, removed when the job is done;
//! - the study's report files (tables, figures).
//!
//! A stop request ([`StudyArgs::stop`]; the `tandem` program sets it on SIGINT or SIGTERM)
//! stops every job at once (each loses the steps since its last checkpoint), marks
//! `config.json` `interrupted` and returns [`Error::Interrupted`] with the exit status 130 or
//! 143. `--resume DIR` continues from the checkpoints, also after a kill, refusing settings
//! other than the recorded ones. Seeds can run as separate processes (`--seeds 1 --first-seed
//! k`), on one machine or many; [`merge`] joins their complete directories into one report.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use crate::interrupt::{Stop, EXIT_SIGINT};
use crate::report::{ensure_finite, to_json_pretty, Curve, Table};
use crate::run::{Existing, Layout, RunDir};
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use tandem_algos::{AlgoError, Checkpoints, Result as AlgoResult};
use tandem_core::CurvePoint;
use tandem_nn::Checkpoint;

use crate::{Error, Result};

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
            quick: false,
            out: None,
            jobs: DEFAULT_JOBS,
            config: None,
            quiet: false,
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
    /// Whether `--quick` chose the base settings.
    pub quick: bool,
    /// Parallel jobs of the last process.
    pub jobs: u64,
    /// `running`, `interrupted` or `complete`.
    pub status: String,
    /// Wall time of the last (or only) process, seconds; absent while running.
    pub wall_seconds: Option<f64>,
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

/// The name of the study that wrote `dir` (its `config.json`'s `study`).
pub fn study_of(dir: &Path) -> Result<String> {
    let path = dir.join("config.json");
    let text = std::fs::read_to_string(&path).map_err(|source| Error::Io {
        path: path.clone(),
        source,
    })?;
    let n: StudyName = serde_json::from_str(&text)
        .map_err(|e| Error::input(path.display().to_string(), e.to_string()))?;
    Ok(n.study)
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write_json(dir: &RunDir, name: &str, value: &impl Serialize) -> Result<()> {
    let text = to_json_pretty(value).map_err(|e| Error::Other(format!("{name}: {e}")))?;
    write(dir, name, &text)
}

/// Writes the file `name` of `dir` (atomically).
pub fn write(dir: &RunDir, name: &str, text: &str) -> Result<()> {
    dir.write(name, text)
        .map(drop)
        .map_err(io(&dir.path().join(name)))
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
    let path = dir.join("config.json");
    let text = std::fs::read_to_string(&path).map_err(|e| {
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
    serde_json::from_str(&text).map_err(bad)
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
        quick: args.quick,
        jobs: args.jobs,
        status: "running".into(),
        wall_seconds: None,
    })
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

/// Writes a finished run's `curve.csv` and `record.json` (the record last: its presence says
/// the run is done).
fn write_record<S: Study>(
    study: &S,
    dir: &Path,
    run: &str,
    seed: u64,
    r: &S::Record,
) -> Result<()> {
    let sub = record_dir(dir, run, seed);
    std::fs::create_dir_all(&sub).map_err(io(&sub))?;
    let (header, rows) = study.curve(r);
    let curve = crate::run::csv(&header, &rows);
    let path = sub.join("curve.csv");
    tandem_nn::write_atomic(&path, curve.as_bytes()).map_err(io(&path))?;
    let path = sub.join("record.json");
    let text = to_json_pretty(r).map_err(|e| Error::Other(format!("{}: {e}", path.display())))?;
    tandem_nn::write_atomic(&path, text.as_bytes()).map_err(io(&path))
}

/// A finished run's record, if it is there.
fn read_record<R: DeserializeOwned>(dir: &Path, run: &str, seed: u64) -> Result<Option<R>> {
    let path = record_dir(dir, run, seed).join("record.json");
    match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| Error::input(path.display().to_string(), e.to_string())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(Error::Io { path, source }),
    }
}

/// Every run's record for `seeds` in the study directory `dir`, by seed, then run.
fn read_records<S: Study>(
    study: &S,
    settings: &S::Settings,
    dir: &Path,
    seeds: std::ops::Range<u64>,
) -> Result<Vec<S::Record>> {
    let mut records = Vec::new();
    for seed in seeds {
        for run in study.jobs(settings, seed).iter().flatten() {
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

/// Runs (or resumes) `study` as the command line says.
pub fn run<S: Study>(study: &S, args: &StudyArgs) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let stop = args.stop.clone();
    let mut rc = match &args.resume {
        Some(dir) => recorded(study, args, dir)?,
        None => fresh(study, args)?,
    };
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
    let jobs: Vec<(u64, Vec<String>)> = (rc.first_seed..rc.first_seed + rc.seeds)
        .flat_map(|seed| {
            study
                .jobs(settings, seed)
                .into_iter()
                .map(move |j| (seed, j))
        })
        .collect();
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
        return Err(Error::Other(format!("seed {seed}: {e}")));
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
    let seeds = rc.first_seed..rc.first_seed + rc.seeds;
    let records = read_records(study, settings, dir.path(), seeds)?;
    remove_dir(&dir.path().join("state"))?;
    let md = study.report(&dir, settings, &records, wall)?;
    rc.status = "complete".into();
    rc.wall_seconds = Some(wall);
    write_json(&dir, "config.json", &rc)?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

/// `state/seed<k>/<first run>/`: the checkpoints of one job (its runs may share some, e.g. a
/// pre-trained agent), removed when the job is done.
fn job_state(dir: &Path, seed: u64, runs: &[String]) -> PathBuf {
    let first = runs.first().map_or("job", String::as_str);
    dir.join("state").join(format!("seed{seed}")).join(first)
}

fn remove_dir(path: &Path) -> Result<()> {
    match std::fs::remove_dir_all(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::Io {
            path: path.to_path_buf(),
            source: e,
        }),
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

/// What a merge's `config.json` records.
#[derive(Debug, Serialize)]
struct MergeConfig<'a, S> {
    study: &'a str,
    config: &'a S,
    quick: bool,
    seeds: Vec<u64>,
    /// The merged directories, with their first seed, seed count and wall time.
    parts: Vec<(String, u64, u64, Option<f64>)>,
    /// Sum of the parts' wall times, seconds.
    wall_seconds: f64,
    status: &'static str,
}

/// Joins complete directories of `study` with disjoint seeds and equal settings into one report
/// in `out` (default `runs/<study>-merged__<time>/`).
pub fn merge<S: Study>(
    study: &S,
    dirs: &[PathBuf],
    out: Option<&Path>,
    overwrite: bool,
) -> Result<()> {
    let mut parts: Vec<(PathBuf, RunConfig<S::Settings>)> = Vec::new();
    for d in dirs {
        let what = d.display().to_string();
        let rc = read_config(study, d, &what)?;
        if rc.status != "complete" {
            return Err(Error::input(
                what,
                format!(
                    "the study is {}; finish it first (`tandem reproduce {} --resume {}`)",
                    rc.status,
                    study.name(),
                    d.display()
                ),
            ));
        }
        if let Some((first, f)) = parts.first() {
            if (&f.config, f.quick) != (&rc.config, rc.quick) {
                return Err(Error::input(
                    what,
                    format!(
                        "its settings differ from {}'s: only runs of one configuration merge",
                        first.display()
                    ),
                ));
            }
        }
        parts.push((d.clone(), rc));
    }
    let Some((_, first)) = parts.first() else {
        return Err(Error::input("merge", "no directories given"));
    };
    let settings = &first.config;
    let mut seeds: Vec<u64> = Vec::new();
    let mut by_seed = Vec::new();
    for (d, rc) in &parts {
        let range = rc.first_seed..rc.first_seed + rc.seeds;
        if let Some(s) = range.clone().find(|s| seeds.contains(s)) {
            return Err(Error::input(
                d.display().to_string(),
                format!("seed {s} is in two of the merged directories"),
            ));
        }
        seeds.extend(range.clone());
        for seed in range {
            by_seed.push((seed, read_records(study, settings, d, seed..seed + 1)?));
        }
    }
    by_seed.sort_by_key(|(s, _)| *s);
    seeds.sort_unstable();
    let existing = if overwrite {
        Existing::Overwrite
    } else {
        Existing::Refuse
    };
    let name = format!("{}-merged", study.name());
    let dir = RunDir::create(out, &name, layout(study, true), existing).map_err(Error::other)?;
    let mut records = Vec::new();
    for (seed, rs) in by_seed {
        for (run, r) in study.jobs(settings, seed).iter().flatten().zip(rs) {
            write_record(study, dir.path(), run, seed, &r)?;
            records.push(r);
        }
    }
    let wall: f64 = parts.iter().filter_map(|(_, rc)| rc.wall_seconds).sum();
    let md = study.report(&dir, settings, &records, wall)?;
    let merged = MergeConfig {
        study: study.name(),
        config: settings,
        quick: first.quick,
        seeds,
        parts: parts
            .iter()
            .map(|(d, rc)| {
                (
                    d.display().to_string(),
                    rc.first_seed,
                    rc.seeds,
                    rc.wall_seconds,
                )
            })
            .collect(),
        wall_seconds: wall,
        status: "complete",
    };
    write_json(&dir, "config.json", &merged)?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
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
    let text =
        tandem_core::read_file_capped(path, tandem_core::MAX_CONFIG_BYTES).map_err(io(path))?;
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
