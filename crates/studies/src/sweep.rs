//! A study on a SLURM cluster: one array task per cell, a merge job after them, and the sweep's
//! state read back from the cells' directories.
//!
//! A *cell* is one seed and the methods of one of its jobs ([`Study::jobs`](crate::Study::jobs):
//! usually one method; p0's pre-trained methods share one job). [`create`] checks the study's
//! settings as a run would, then writes the sweep's directory:
//!
//! - `sweep.json`: the study, its options and settings file, the cells, the resources asked for
//!   and each submission's job ids;
//! - `settings.toml`: a copy of the `--config` file, so that every task reads the same settings;
//! - `slurm/cells.sbatch` (the array, task `k` runs cell `k`) and `slurm/merge.sbatch`;
//! - `cells/<cell>/`: each cell's study directory; `tasks/<k>.json`: each start of task `k`;
//! - `logs/`: SLURM's output files; `merged/`: the merged table and figures.
//!
//! A task ([`run_task`]) is idempotent: a finished cell exits at once, a started one resumes
//! from its checkpoints, a new one starts. The array asks for `--requeue` and for SIGTERM
//! `grace` seconds before its time limit, so a preempted or requeued task checkpoints, and its
//! next start resumes where it stopped. The merge job ([`merge_cells`]) runs after every task
//! succeeded (`--dependency=afterok`); [`status`] tells each cell's state, and [`resubmit`]
//! submits the cells that are not done (failed, stopped by the time limit, cancelled) with a new
//! merge job.

use std::path::{Path, PathBuf};
use std::process::Command;

use clap::Args;
use serde::{Deserialize, Serialize};

use crate::harness::{failed, read_study_file};
use crate::interrupt::Stop;
use crate::run::{Existing, Layout, RunDir, LOCK_FILE};
use crate::{Error, IoOp, Result, StudyArgs, StudyOptions};

/// What each array task asks SLURM for. Values are passed to `sbatch` as they are given.
#[derive(Debug, Clone, Default, PartialEq, Args, Serialize, Deserialize)]
pub struct Resources {
    /// SLURM: the partition (`--partition`) [default: the cluster's].
    #[arg(long)]
    pub partition: Option<String>,
    /// SLURM: each task's time limit (`--time`, e.g. `8:00:00` or `1-12:00:00`) [default: the
    /// partition's].
    #[arg(long)]
    pub time: Option<String>,
    /// SLURM: each task's memory (`--mem`, e.g. `4G`) [default: twice the check's estimate for
    /// the largest cell, plus 512 MiB].
    #[arg(long)]
    pub mem: Option<String>,
    /// SLURM: CPUs per task (`--cpus-per-task`; also `RAYON_NUM_THREADS`) [default: 1, as a cell
    /// runs one job on one thread].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub cpus_per_task: Option<u32>,
    /// SLURM: the account to charge (`--account`) [default: yours].
    #[arg(long)]
    pub account: Option<String>,
    /// SLURM: seconds before the time limit at which a task gets SIGTERM, checkpoints and stops
    /// (`--signal=B:TERM@<grace>`) [default: 300].
    #[arg(long, value_parser = clap::value_parser!(u32).range(60..=65_535))]
    pub grace: Option<u32>,
}

/// The grace when `--grace` is not given: SLURM sends the signal up to a minute early, and the
/// slowest step between two stop checks (an M-DeMoRL plan, a model refit) takes seconds.
const DEFAULT_GRACE: u32 = 300;

impl Resources {
    /// Refuses values that are empty or would break the script (whitespace, quotes, `$`).
    fn validate(&self) -> Result<()> {
        let fields = [
            ("--partition", &self.partition),
            ("--time", &self.time),
            ("--mem", &self.mem),
            ("--account", &self.account),
        ];
        for (flag, value) in fields {
            if let Some(v) = value {
                script_word(flag, v)?;
            }
        }
        Ok(())
    }
}

/// `value` as one word of an `#SBATCH` line: refused when empty or holding anything a shell or
/// SLURM would split or expand.
fn script_word(what: &str, value: &str) -> Result<()> {
    let bad = value.chars().find(|c| {
        c.is_whitespace() || c.is_control() || matches!(c, '\'' | '"' | '`' | '$' | '\\' | '#')
    });
    if value.is_empty() || bad.is_some() {
        return Err(Error::input(
            what,
            format!(
                "{value:?} is not a value `sbatch` takes (empty, or with whitespace, quotes or $)"
            ),
        ));
    }
    Ok(())
}

/// One cell: a seed and the methods of one of its jobs, with its study directory (relative to
/// the sweep's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// The seed.
    pub seed: u64,
    /// The methods (`--methods`).
    pub methods: Vec<String>,
    /// `cells/seed<k>-<first method>`.
    pub dir: String,
}

/// One `sbatch` of the array and its merge job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Submission {
    /// The array's job id.
    pub array_job: String,
    /// The merge job's id.
    pub merge_job: String,
    /// The array's task ids (the cells' indices).
    pub tasks: Vec<usize>,
}

/// `sweep.json`: everything a task, the merge and the status read.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sweep {
    /// The study's name.
    pub study: String,
    /// The study's options (task, p3's extra runs).
    pub options: StudyOptions,
    /// Whether the cells run `--quick`.
    pub quick: bool,
    /// Whether `settings.toml` (a copy of `--config`) overrides the settings.
    pub config: bool,
    /// The cells; task `k` runs `cells[k]`.
    pub cells: Vec<Cell>,
    /// What each task asks for.
    pub resources: Resources,
    /// The `tandem` program the tasks run.
    pub tandem: PathBuf,
    /// The submissions, oldest first.
    pub submissions: Vec<Submission>,
}

const SWEEP_FILE: &str = "sweep.json";
const SETTINGS_FILE: &str = "settings.toml";
const MERGED: &str = "merged";

fn layout() -> Layout {
    Layout {
        owned: &[
            SWEEP_FILE,
            SETTINGS_FILE,
            "slurm",
            "cells",
            "tasks",
            "logs",
            MERGED,
        ],
        resumable: false,
    }
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(failed(IoOp::Create, parent))?;
    }
    tandem_nn::write_atomic(path, text.as_bytes()).map_err(failed(IoOp::Write, path))
}

/// A path as one single-quoted shell word; refused if it holds a quote or a line break.
fn quoted(path: &Path) -> Result<String> {
    let text = path.display().to_string();
    if text.contains(['\'', '\n', '\r']) {
        return Err(Error::input(
            text,
            "a sweep's paths may not hold quotes or line breaks (they go into the job scripts)",
        ));
    }
    Ok(format!("'{text}'"))
}

impl Sweep {
    /// Reads `dir/sweep.json`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(SWEEP_FILE);
        let text = read_study_file(&path).map_err(|e| {
            Error::input(
                dir.display().to_string(),
                format!(
                    "{} cannot be read ({e}): not a sweep's directory",
                    path.display()
                ),
            )
        })?;
        serde_json::from_str(&text)
            .map_err(|e| Error::input(path.display().to_string(), e.to_string()))
    }

    fn write(&self, dir: &Path) -> Result<()> {
        let text = crate::report::to_json_pretty(self).map_err(Error::other)?;
        write_file(&dir.join(SWEEP_FILE), &text)
    }

    /// The array's script: task `k` runs cell `k` (`dir` absolute).
    pub fn cells_script(&self, dir: &Path, memory: &str) -> Result<String> {
        let r = &self.resources;
        let cpus = r.cpus_per_task.unwrap_or(1);
        let mut s = format!(
            "#!/bin/bash\n\
             # tandem: {} as {} cells; task k runs cell k of sweep.json, resuming it if it started.\n\
             #SBATCH --job-name=tandem-{}\n\
             #SBATCH --requeue\n\
             #SBATCH --signal=B:TERM@{}\n\
             #SBATCH --ntasks=1\n\
             #SBATCH --cpus-per-task={cpus}\n\
             #SBATCH --mem={memory}\n",
            self.study,
            self.cells.len(),
            self.study,
            r.grace.unwrap_or(DEFAULT_GRACE),
        );
        sbatch_common(&mut s, r, r.time.as_deref());
        let logs = dir.join("logs");
        s.push_str(&format!(
            "#SBATCH --output={}/%A_%a.out\n#SBATCH --open-mode=append\n\
             export RAYON_NUM_THREADS={cpus}\n\
             exec {} sweep task {} \"$SLURM_ARRAY_TASK_ID\"\n",
            logs.display(),
            quoted(&self.tandem)?,
            quoted(dir)?,
        ));
        Ok(s)
    }

    /// The merge job's script.
    pub fn merge_script(&self, dir: &Path) -> Result<String> {
        let mut s = format!(
            "#!/bin/bash\n\
             # tandem: merges the cells of {} into merged/ once every task succeeded.\n\
             #SBATCH --job-name=tandem-{}-merge\n\
             #SBATCH --ntasks=1\n\
             #SBATCH --cpus-per-task=1\n\
             #SBATCH --mem=2G\n",
            self.study, self.study,
        );
        sbatch_common(&mut s, &self.resources, Some("1:00:00"));
        s.push_str(&format!(
            "#SBATCH --output={}/merge-%j.out\n\
             exec {} sweep merge {}\n",
            dir.join("logs").display(),
            quoted(&self.tandem)?,
            quoted(dir)?,
        ));
        Ok(s)
    }
}

/// The `#SBATCH` lines both scripts share.
fn sbatch_common(s: &mut String, r: &Resources, time: Option<&str>) {
    for (flag, value) in [
        ("partition", r.partition.as_deref()),
        ("account", r.account.as_deref()),
        ("time", time),
    ] {
        if let Some(v) = value {
            s.push_str(&format!("#SBATCH --{flag}={v}\n"));
        }
    }
}

/// `--mem` when not given: twice the largest cell's estimate plus 512 MiB (the estimate counts
/// networks, optimizer state, buffers and planner populations, not the program, MuJoCo or the
/// allocator's slack), in whole MiB.
fn default_memory(estimate: u64) -> String {
    let mib = estimate
        .saturating_mul(2)
        .div_ceil(1 << 20)
        .saturating_add(512);
    format!("{mib}M")
}

/// What [`create`] made: the sweep, its directory, and the two scripts.
#[derive(Debug, Clone)]
pub struct Planned {
    /// The sweep (`sweep.json`).
    pub sweep: Sweep,
    /// The sweep's directory (absolute).
    pub dir: PathBuf,
    /// `slurm/cells.sbatch`.
    pub cells_script: String,
    /// `slurm/merge.sbatch`.
    pub merge_script: String,
    /// The largest cell's estimated peak memory, bytes.
    pub memory: u64,
}

/// Plans the study `name` (`args` as the command line gives them; `args.out` is the sweep's
/// directory) as a sweep: checks the settings as a run would, lists the cells, and writes the
/// sweep's directory unless `dry_run`. `tandem` is the program the tasks run.
pub fn create(
    name: &str,
    options: &StudyOptions,
    args: &StudyArgs,
    resources: Resources,
    tandem: PathBuf,
    dry_run: bool,
) -> Result<Planned> {
    if args.resume.is_some() {
        return Err(Error::input(
            "--slurm",
            "a sweep is not resumed with --resume: `tandem sweep resubmit DIR` submits its \
             unfinished cells",
        ));
    }
    resources.validate()?;
    // Each task runs one job: check the settings, the seeds and one job's memory.
    let one = StudyArgs {
        jobs: 1,
        stop: Stop::never(),
        ..args.clone()
    };
    let checked = crate::check_study(name, options, &one)?;
    let cells: Vec<Cell> = checked
        .cells
        .iter()
        .map(|(seed, methods)| Cell {
            seed: *seed,
            dir: format!("cells/seed{seed}-{}", methods[0]),
            methods: methods.clone(),
        })
        .collect();
    let (dir, run_dir) = if dry_run {
        let dir = args
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("runs/{name}-sweep__<time>")));
        (
            std::path::absolute(&dir).map_err(failed(IoOp::Read, &dir))?,
            None,
        )
    } else {
        let existing = if args.overwrite {
            Existing::Overwrite
        } else {
            Existing::Refuse
        };
        let rd = RunDir::create(
            args.out.as_deref(),
            &format!("{name}-sweep"),
            layout(),
            existing,
        )
        .map_err(Error::other)?;
        let dir = std::path::absolute(rd.path()).map_err(failed(IoOp::Read, rd.path()))?;
        (dir, Some(rd))
    };
    let sweep = Sweep {
        study: name.to_string(),
        options: options.clone(),
        quick: args.quick,
        config: args.config.is_some(),
        cells,
        resources,
        tandem,
        submissions: Vec::new(),
    };
    let memory = sweep
        .resources
        .mem
        .clone()
        .unwrap_or_else(|| default_memory(checked.memory));
    let cells_script = sweep.cells_script(&dir, &memory)?;
    let merge_script = sweep.merge_script(&dir)?;
    if run_dir.is_some() {
        if let Some(config) = &args.config {
            let text = tandem_core::read_file_capped(config, tandem_core::MAX_CONFIG_BYTES)
                .map_err(failed(IoOp::Read, config))?;
            write_file(&dir.join(SETTINGS_FILE), &text)?;
        }
        write_file(&dir.join("slurm/cells.sbatch"), &cells_script)?;
        write_file(&dir.join("slurm/merge.sbatch"), &merge_script)?;
        for sub in ["cells", "tasks", "logs"] {
            let path = dir.join(sub);
            std::fs::create_dir_all(&path).map_err(failed(IoOp::Create, &path))?;
        }
        sweep.write(&dir)?;
    }
    Ok(Planned {
        sweep,
        dir,
        cells_script,
        merge_script,
        memory: checked.memory,
    })
}

/// `sbatch --parsable ARGS`: the job id it prints.
fn sbatch(args: &[String]) -> Result<String> {
    let out = Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .output()
        .map_err(|e| {
            Error::Other(format!(
                "cannot run sbatch ({e}): submit from a SLURM login node, or see the scripts \
                 with --dry-run"
            ))
        })?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(Error::Other(format!(
            "sbatch {} failed ({}): {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    // `--parsable` prints `id` or `id;cluster`.
    let id = stdout
        .trim()
        .split(';')
        .next()
        .unwrap_or_default()
        .to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(Error::Other(format!(
            "sbatch printed no job id: {stdout:?}"
        )));
    }
    Ok(id)
}

/// `--array`'s value for `tasks`: ranges of consecutive ids (`0-8`, `1,4-6`).
fn array_spec(tasks: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut k = 0;
    while k < tasks.len() {
        let start = tasks[k];
        while k + 1 < tasks.len() && tasks[k + 1] == tasks[k] + 1 {
            k += 1;
        }
        parts.push(if tasks[k] == start {
            start.to_string()
        } else {
            format!("{start}-{}", tasks[k])
        });
        k += 1;
    }
    parts.join(",")
}

/// The `sbatch` arguments that submit `tasks` of the sweep in `dir`, and those of its merge job
/// (`{array}` standing for the array's job id).
pub fn submit_commands(dir: &Path, tasks: &[usize]) -> (Vec<String>, Vec<String>) {
    let slurm = dir.join("slurm");
    let array = vec![
        format!("--array={}", array_spec(tasks)),
        slurm.join("cells.sbatch").display().to_string(),
    ];
    let merge = vec![
        "--dependency=afterok:{array}".to_string(),
        "--kill-on-invalid-dep=yes".to_string(),
        slurm.join("merge.sbatch").display().to_string(),
    ];
    (array, merge)
}

/// Submits `tasks` of the sweep in `dir` (all its cells for `None`) and a merge job after them;
/// records the submission in `sweep.json`.
pub fn submit(dir: &Path, tasks: Option<Vec<usize>>) -> Result<Submission> {
    let mut sweep = Sweep::read(dir)?;
    let tasks = tasks.unwrap_or_else(|| (0..sweep.cells.len()).collect());
    let (array, merge) = submit_commands(dir, &tasks);
    let array_job = if tasks.is_empty() {
        String::new()
    } else {
        sbatch(&array)?
    };
    let merge: Vec<String> = if tasks.is_empty() {
        merge[2..].to_vec()
    } else {
        merge
            .iter()
            .map(|a| a.replace("{array}", &array_job))
            .collect()
    };
    let merge_job = sbatch(&merge)?;
    let submission = Submission {
        array_job,
        merge_job,
        tasks,
    };
    sweep.submissions.push(submission.clone());
    sweep.write(dir)?;
    Ok(submission)
}

/// One start of an array task, as `tasks/<k>.json` lists them.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Start {
    /// SLURM's job id of the task (`<array>_<k>`), if it ran under SLURM.
    pub job: Option<String>,
    /// The host it ran on.
    pub host: String,
    /// Seconds since the Unix epoch.
    pub at: u64,
    /// `started`, `resumed` or `finished already`.
    pub mode: String,
}

fn starts_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("tasks").join(format!("{index}.json"))
}

fn read_starts(dir: &Path, index: usize) -> Result<Vec<Start>> {
    let path = starts_path(dir, index);
    match read_study_file(&path) {
        Ok(text) => serde_json::from_str(&text)
            .map_err(|e| Error::input(path.display().to_string(), e.to_string())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(e) => Err(Error::io(IoOp::Read, path, e)),
    }
}

/// A cell's `config.json` status (`running`, `interrupted`, `failed`, `complete`) and error,
/// or `None` before it started.
fn cell_status(cell_dir: &Path) -> Result<Option<(String, Option<String>)>> {
    #[derive(Deserialize)]
    struct Status {
        status: String,
        #[serde(default)]
        error: Option<String>,
    }
    let path = cell_dir.join("config.json");
    match read_study_file(&path) {
        Ok(text) => {
            let s: Status = serde_json::from_str(&text)
                .map_err(|e| Error::input(path.display().to_string(), e.to_string()))?;
            Ok(Some((s.status, s.error)))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(IoOp::Read, path, e)),
    }
}

/// Runs task `index` of the sweep in `dir`: cell `index` from its start, from its checkpoints if
/// it started before, or not at all if it is done. Each start is recorded in `tasks/<k>.json`.
pub fn run_task(dir: &Path, index: usize, stop: Stop) -> Result<()> {
    let sweep = Sweep::read(dir)?;
    let Some(cell) = sweep.cells.get(index) else {
        return Err(Error::input(
            "task",
            format!(
                "{index}: the sweep has {} cells (0 to {})",
                sweep.cells.len(),
                sweep.cells.len().saturating_sub(1)
            ),
        ));
    };
    let cell_dir = dir.join(&cell.dir);
    let status = cell_status(&cell_dir)?;
    let mode = match &status {
        Some((s, _)) if s == "complete" => "finished already",
        Some(_) => "resumed",
        None => "started",
    };
    let mut starts = read_starts(dir, index)?;
    starts.push(Start {
        job: std::env::var("SLURM_ARRAY_JOB_ID")
            .ok()
            .zip(std::env::var("SLURM_ARRAY_TASK_ID").ok())
            .map(|(a, k)| format!("{a}_{k}"))
            .or_else(|| std::env::var("SLURM_JOB_ID").ok()),
        host: hostname(),
        at: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        mode: mode.to_string(),
    });
    let text = crate::report::to_json_pretty(&starts).map_err(Error::other)?;
    write_file(&starts_path(dir, index), &text)?;
    eprintln!(
        "tandem sweep: task {index}, seed {} {}: {mode}",
        cell.seed,
        cell.methods.join(",")
    );
    if mode == "finished already" {
        return Ok(());
    }
    if status.is_some() && std::env::var_os("SLURM_JOB_ID").is_some() {
        // SLURM runs one instance of an array task at a time, so a lock left in the cell is
        // a killed start's, perhaps on another node where its process id means nothing.
        let lock = cell_dir.join(LOCK_FILE);
        match std::fs::remove_file(&lock) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(Error::io(IoOp::Remove, lock, e))
            }
            _ => {}
        }
    }
    let args = StudyArgs {
        seeds: Some(1),
        first_seed: Some(cell.seed),
        methods: Some(cell.methods.clone()),
        quick: sweep.quick,
        config: sweep.config.then(|| dir.join(SETTINGS_FILE)),
        jobs: 1,
        quiet: true,
        // A start that died before its first record holds nothing worth keeping.
        overwrite: status.is_none(),
        out: status.is_none().then(|| cell_dir.clone()),
        resume: status.is_some().then(|| cell_dir.clone()),
        check: false,
        stop,
    };
    crate::run_study(&sweep.study, &sweep.options, &args)
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .or_else(|_| std::env::var("HOSTNAME"))
        .unwrap_or_else(|_| "unknown".into())
}

/// Merges the cells of the sweep in `dir` into `dir/merged/` (replacing an earlier merge).
pub fn merge_cells(dir: &Path) -> Result<()> {
    let sweep = Sweep::read(dir)?;
    let dirs: Vec<PathBuf> = sweep.cells.iter().map(|c| dir.join(&c.dir)).collect();
    crate::merge(&dirs, Some(&dir.join(MERGED)), true)
}

/// A cell's state as [`status`] reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CellState {
    /// Not started.
    Pending,
    /// Started and not finished: running, or killed while running.
    Running,
    /// Stopped by SIGINT or SIGTERM (preemption, the time limit, a requeue) with a checkpoint.
    Interrupted,
    /// A run or a write failed: the reason.
    Failed(String),
    /// Every run of the cell has its record.
    Done,
}

impl std::fmt::Display for CellState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CellState::Pending => f.write_str("pending"),
            CellState::Running => f.write_str("running"),
            CellState::Interrupted => f.write_str("interrupted"),
            CellState::Failed(why) => write!(f, "failed: {why}"),
            CellState::Done => f.write_str("done"),
        }
    }
}

/// One cell's line of [`status`].
#[derive(Debug, Clone)]
pub struct CellReport {
    /// The array task id.
    pub task: usize,
    /// The cell.
    pub cell: Cell,
    /// Its state, from its directory.
    pub state: CellState,
    /// How often a start found it begun and resumed it.
    pub resumes: usize,
    /// What SLURM says of its latest job (`squeue`'s state and reason, else `sacct`'s state),
    /// where SLURM answers.
    pub slurm: Option<String>,
}

/// The sweep in `dir`: every cell's state, and whether the merge is done.
#[derive(Debug, Clone)]
pub struct SweepStatus {
    /// The cells, by task id.
    pub cells: Vec<CellReport>,
    /// Whether `merged/` holds the merged table.
    pub merged: bool,
    /// What SLURM says of the latest merge job, where it answers.
    pub merge_job: Option<String>,
}

impl SweepStatus {
    /// The cells that are not done and have no job queued or running: what [`resubmit`]
    /// submits.
    pub fn unfinished(&self) -> Vec<usize> {
        self.cells
            .iter()
            .filter(|c| c.state != CellState::Done && !c.slurm.as_deref().is_some_and(queued))
            .map(|c| c.task)
            .collect()
    }
}

/// Whether a SLURM state means the job will still run.
fn queued(state: &str) -> bool {
    [
        "PENDING",
        "RUNNING",
        "REQUEUED",
        "CONFIGURING",
        "COMPLETING",
        "RESIZING",
        "SUSPENDED",
    ]
    .iter()
    .any(|s| state.starts_with(s))
}

/// Runs a SLURM query; `None` where the command is missing or refuses (no accounting, say).
fn query(program: &str, args: &[&str]) -> Option<String> {
    let out = Command::new(program).args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Job id → state (with squeue's reason), from `squeue` for jobs in the queue and `sacct` for
/// finished ones where accounting is on.
fn slurm_states(jobs: &[String]) -> std::collections::HashMap<String, String> {
    let mut states = std::collections::HashMap::new();
    if jobs.is_empty() {
        return states;
    }
    let list = jobs.join(",");
    if let Some(text) = query(
        "sacct",
        &["-n", "-P", "-X", "-j", &list, "-o", "JobID,State"],
    ) {
        for line in text.lines() {
            if let Some((id, state)) = line.split_once('|') {
                states.insert(id.trim().to_string(), state.trim().to_string());
            }
        }
    }
    if let Some(text) = query("squeue", &["-h", "-r", "-j", &list, "-o", "%i|%T|%r"]) {
        for line in text.lines() {
            let mut f = line.split('|');
            if let (Some(id), Some(state), Some(reason)) = (f.next(), f.next(), f.next()) {
                let reason = reason.trim();
                let state = if reason.is_empty() || reason == "None" {
                    state.trim().to_string()
                } else {
                    format!("{} ({reason})", state.trim())
                };
                states.insert(id.trim().to_string(), state);
            }
        }
    }
    states
}

/// Reads the sweep in `dir`: each cell's state from its directory, its resumes from
/// `tasks/<k>.json`, and SLURM's view of its latest job from `squeue` (and `sacct` where
/// accounting is on).
pub fn status(dir: &Path) -> Result<SweepStatus> {
    let sweep = Sweep::read(dir)?;
    let mut jobs: Vec<String> = Vec::new();
    for s in &sweep.submissions {
        if !s.array_job.is_empty() {
            jobs.push(s.array_job.clone());
        }
        jobs.push(s.merge_job.clone());
    }
    let states = slurm_states(&jobs);
    let mut cells = Vec::new();
    for (task, cell) in sweep.cells.iter().enumerate() {
        let state = match cell_status(&dir.join(&cell.dir))? {
            None => CellState::Pending,
            Some((s, error)) => match s.as_str() {
                "complete" => CellState::Done,
                "interrupted" => CellState::Interrupted,
                "failed" => CellState::Failed(error.unwrap_or_else(|| "no reason recorded".into())),
                _ => CellState::Running,
            },
        };
        let resumes = read_starts(dir, task)?
            .iter()
            .filter(|s| s.mode == "resumed")
            .count();
        let latest = sweep
            .submissions
            .iter()
            .rev()
            .find(|s| s.tasks.contains(&task));
        let slurm = latest.and_then(|s| states.get(&format!("{}_{task}", s.array_job)).cloned());
        cells.push(CellReport {
            task,
            cell: cell.clone(),
            state,
            resumes,
            slurm,
        });
    }
    let merged = matches!(cell_status(&dir.join(MERGED))?, Some((s, _)) if s == "complete");
    let merge_job = sweep
        .submissions
        .last()
        .and_then(|s| states.get(&s.merge_job).cloned());
    Ok(SweepStatus {
        cells,
        merged,
        merge_job,
    })
}

/// Submits the cells of the sweep in `dir` that are not done and not queued (failed, stopped
/// by the time limit, cancelled, never submitted), and a merge job after them; the merge job
/// alone when every cell is done. Returns the submission, or `None` when there is nothing to do.
pub fn resubmit(dir: &Path) -> Result<Option<Submission>> {
    let st = status(dir)?;
    let waiting = st
        .cells
        .iter()
        .any(|c| c.state != CellState::Done && c.slurm.as_deref().is_some_and(queued));
    if waiting {
        return Err(Error::input(
            dir.display().to_string(),
            "some cells are still queued or running; resubmit once they have ended (`tandem \
             sweep status` shows them)",
        ));
    }
    let tasks = st.unfinished();
    if tasks.is_empty() && st.merged {
        return Ok(None);
    }
    submit(dir, Some(tasks)).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("tandem-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn array_specs_join_consecutive_tasks() {
        assert_eq!(array_spec(&[0, 1, 2, 3]), "0-3");
        assert_eq!(array_spec(&[0, 1, 2, 5, 7, 8]), "0-2,5,7-8");
        assert_eq!(array_spec(&[4]), "4");
    }

    #[test]
    fn values_that_would_break_a_script_are_refused() {
        for bad in ["", "a b", "x\ny", "$HOME", "it's", "a#b"] {
            let r = Resources {
                partition: Some(bad.into()),
                ..Resources::default()
            };
            assert!(r.validate().is_err(), "{bad:?}");
        }
        let r = Resources {
            partition: Some("gpu-a100".into()),
            time: Some("1-12:00:00".into()),
            mem: Some("4G".into()),
            account: Some("proj_42".into()),
            ..Resources::default()
        };
        r.validate().unwrap();
        // Twice 100 MiB, plus 512 MiB.
        assert_eq!(default_memory(100 << 20), "712M");
    }

    /// Without SLURM: the tasks run by hand, each idempotent, merge to one local run's table.
    #[test]
    fn tasks_run_by_hand_merge_to_the_table_of_one_run() {
        let (root, local) = (temp("tasks"), temp("local"));
        let args = StudyArgs {
            seeds: Some(2),
            quick: true,
            quiet: true,
            out: Some(root.clone()),
            ..StudyArgs::default()
        };
        let options = StudyOptions::default();
        let tandem = PathBuf::from("/opt/tandem");
        let planned = create(
            "p2-cartpole",
            &options,
            &args,
            Resources::default(),
            tandem,
            false,
        )
        .unwrap();
        let cells: Vec<(u64, &str, &str)> = planned
            .sweep
            .cells
            .iter()
            .map(|c| (c.seed, c.methods[0].as_str(), c.dir.as_str()))
            .collect();
        assert_eq!(
            cells,
            [
                (0, "model_free", "cells/seed0-model_free"),
                (0, "with_model", "cells/seed0-with_model"),
                (1, "model_free", "cells/seed1-model_free"),
                (1, "with_model", "cells/seed1-with_model"),
            ]
        );
        let script = std::fs::read_to_string(root.join("slurm/cells.sbatch")).unwrap();
        assert!(script.contains("#SBATCH --requeue\n#SBATCH --signal=B:TERM@300\n"));
        assert!(script.contains("exec '/opt/tandem' sweep task '"));

        let st = status(&root).unwrap();
        assert!(st.cells.iter().all(|c| c.state == CellState::Pending));
        assert_eq!(st.unfinished(), [0, 1, 2, 3]);
        let e = run_task(&root, 4, Stop::never()).unwrap_err().to_string();
        assert!(e.contains("the sweep has 4 cells"), "{e}");
        for k in [3, 0, 2, 1, 0] {
            run_task(&root, k, Stop::never()).unwrap();
        }
        let modes: Vec<String> = read_starts(&root, 0)
            .unwrap()
            .into_iter()
            .map(|s| s.mode)
            .collect();
        assert_eq!(modes, ["started", "finished already"]);
        let st = status(&root).unwrap();
        assert!(st.cells.iter().all(|c| c.state == CellState::Done));
        assert!(st.unfinished().is_empty() && !st.merged);
        merge_cells(&root).unwrap();
        assert!(status(&root).unwrap().merged);

        let one = StudyArgs {
            out: Some(local.clone()),
            ..args
        };
        crate::run_study("p2-cartpole", &options, &one).unwrap();
        let table = |d: &Path| std::fs::read(d.join("table.json")).unwrap();
        assert!(table(&local) == table(&root.join(MERGED)));
        let _ = std::fs::remove_dir_all(&root);
        let _ = std::fs::remove_dir_all(&local);
    }
}
