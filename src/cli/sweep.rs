//! `tandem reproduce <study> --slurm` makes a sweep ([`tandem_studies::sweep`]); `tandem sweep`
//! follows it: each cell's state, resubmitting what did not finish, and the two commands the
//! job scripts run (one task, the merge).

use std::path::{Path, PathBuf};

use clap::Subcommand;
use tandem_studies::interrupt::Stop;
use tandem_studies::sweep::{self, CellState, Submission};
use tandem_studies::{StudyArgs, StudyOptions};

use super::reproduce::SlurmArgs;
use super::{emit, CliError, Result};

/// The commands of a SLURM sweep.
#[derive(Debug, Subcommand)]
pub enum SweepCommand {
    /// Each cell's state (pending, running, interrupted, failed with its reason, done), how often
    /// it resumed, and what squeue (or sacct) says of its job.
    Status {
        /// The sweep's directory.
        dir: PathBuf,
    },
    /// Submit the cells that are not done and not queued (failed, stopped by the time limit,
    /// cancelled), and a merge job after them.
    Resubmit {
        /// The sweep's directory.
        dir: PathBuf,
        /// Print the `sbatch` commands, submit nothing.
        #[arg(long)]
        dry_run: bool,
    },
    /// Run one cell (what an array task runs): start it, resume it, or exit if it is done.
    Task {
        /// The sweep's directory.
        dir: PathBuf,
        /// The cell (`$SLURM_ARRAY_TASK_ID`).
        index: usize,
    },
    /// Merge the cells into DIR/merged/ (what the merge job runs).
    Merge {
        /// The sweep's directory.
        dir: PathBuf,
    },
}

/// Runs a `tandem sweep` command.
pub fn run(cmd: SweepCommand) -> Result<()> {
    match cmd {
        SweepCommand::Status { dir } => print_status(&dir),
        SweepCommand::Resubmit { dir, dry_run } => resubmit(&dir, dry_run),
        SweepCommand::Task { dir, index } => {
            let stop =
                Stop::on_signals().map_err(|e| CliError::Other(format!("signal handlers: {e}")))?;
            sweep::run_task(&dir, index, stop)
        }
        SweepCommand::Merge { dir } => sweep::merge_cells(&dir),
    }
}

/// `tandem reproduce <study> ... --slurm`: writes the sweep and submits it, or with `--dry-run`
/// prints what it would submit.
pub fn create(
    name: &str,
    options: &StudyOptions,
    args: &StudyArgs,
    slurm: SlurmArgs,
) -> Result<()> {
    let tandem = match slurm.tandem {
        Some(path) => path,
        None => std::env::current_exe()
            .map_err(|e| CliError::Other(format!("cannot tell this program's path: {e}")))?,
    };
    let tandem = std::path::absolute(&tandem).unwrap_or(tandem);
    let planned = sweep::create(name, options, args, slurm.resources, tandem, slurm.dry_run)?;
    let n = planned.sweep.cells.len();
    let tasks: Vec<usize> = (0..n).collect();
    if slurm.dry_run {
        let (array, merge) = sweep::submit_commands(&planned.dir, &tasks);
        let dir = planned.dir.display();
        emit(&format!(
            "# {n} cells of {name}; the largest needs about {} (the check's estimate)\n\
             # {dir}/slurm/cells.sbatch\n{}\n# {dir}/slurm/merge.sbatch\n{}\n\
             # submitted as\nsbatch --parsable {}\nsbatch --parsable {}",
            tandem_nn::budget::show_bytes(planned.memory),
            planned.cells_script,
            planned.merge_script,
            array.join(" "),
            merge.join(" ").replace("{array}", "<array job id>"),
        ))?;
        return Ok(());
    }
    let submission = sweep::submit(&planned.dir, Some(tasks)).map_err(|e| {
        let d = planned.dir.display();
        CliError::Other(format!(
            "{e}\nthe sweep is written in {d}: once sbatch works, submit it with `tandem sweep \
             resubmit {d}`"
        ))
    })?;
    report_submission(&planned.dir, &submission)
}

fn report_submission(dir: &Path, s: &Submission) -> Result<()> {
    let d = dir.display();
    let cells = if s.tasks.is_empty() {
        "no cells".to_string()
    } else {
        format!("{} cells as array job {}", s.tasks.len(), s.array_job)
    };
    emit(&format!(
        "submitted {cells}, and merge job {} after them\n\
         follow it with `tandem sweep status {d}`; the table will be in {d}/merged/",
        s.merge_job
    ))
}

fn resubmit(dir: &Path, dry_run: bool) -> Result<()> {
    if dry_run {
        let st = sweep::status(dir)?;
        let tasks = st.unfinished();
        let (array, merge) = sweep::submit_commands(dir, &tasks);
        if !tasks.is_empty() {
            emit(&format!("sbatch --parsable {}", array.join(" ")))?;
        }
        let merge = if tasks.is_empty() {
            &merge[2..]
        } else {
            &merge[..]
        };
        return emit(&format!(
            "sbatch --parsable {}",
            merge.join(" ").replace("{array}", "<array job id>")
        ));
    }
    match sweep::resubmit(dir)? {
        Some(s) => report_submission(dir, &s),
        None => emit(&format!(
            "every cell is done and merged: the table is in {}/merged/",
            dir.display()
        )),
    }
}

fn print_status(dir: &Path) -> Result<()> {
    let st = sweep::status(dir)?;
    let mut lines = vec![format!(
        "{:>5}  {:>6}  {:<24}  {:<12}  {:>7}  {}",
        "task", "seed", "methods", "state", "resumed", "slurm"
    )];
    let mut failed = Vec::new();
    for c in &st.cells {
        let state = match &c.state {
            CellState::Failed(why) => {
                failed.push(format!("task {}: {why}", c.task));
                "failed".to_string()
            }
            s => s.to_string(),
        };
        lines.push(format!(
            "{:>5}  {:>6}  {:<24}  {:<12}  {:>7}  {}",
            c.task,
            c.cell.seed,
            c.cell.methods.join(","),
            state,
            c.resumes,
            c.slurm.as_deref().unwrap_or("-"),
        ));
    }
    let done = st
        .cells
        .iter()
        .filter(|c| c.state == CellState::Done)
        .count();
    lines.push(format!(
        "{done} of {} cells done; merged: {}{}",
        st.cells.len(),
        if st.merged { "yes" } else { "no" },
        st.merge_job
            .as_deref()
            .map_or(String::new(), |s| format!(" (merge job: {s})")),
    ));
    lines.extend(failed);
    if !st.unfinished().is_empty() || (!st.merged && done == st.cells.len()) {
        lines.push(format!(
            "to submit what did not finish: `tandem sweep resubmit {}`",
            dir.display()
        ));
    }
    emit(&lines.join("\n"))
}
