//! # tandem-studies
//!
//! The papers' reproductions as studies: each runs the methods a paper compares over seeds, on
//! the algorithms of `tandem-algos`, and writes a table and figures beside every run's record.
//! A study is resumable after a kill, runs its seeds in parallel or as separate processes, and
//! merges the directories of separate processes into one report ([`harness`]).
//!
//! | module | owns |
//! |---|---|
//! | [`harness`] | the [`Study`] trait, the shared command line, run, resume and merge |
//! | [`p0`] … [`p4_reacher`] | one study per paper: its settings, its runs and its report |
//! | [`report`] | tables, comparisons and figures of the reports |
//! | [`run`] | run directories (no run overwritten by accident), CSV and SVG |
//! | [`interrupt`] | SIGINT/SIGTERM as a stop request that long runs poll |
//! | [`provenance`] | the build (git commit, features) a study's `config.json` records |
//! | [`sweep`] | a study as a SLURM job array of (seed, method) cells and a merge job |
//!
//! [`run_study`] and [`merge`] reach every study by its name through one registry, as the
//! `tandem reproduce` program does:
//!
//! ```
//! assert!(tandem_studies::study_names().contains(&"p3-leg".to_string()));
//! let refused = tandem_studies::run_study(
//!     "p9",
//!     &tandem_studies::StudyOptions::default(),
//!     &Default::default(),
//! );
//! assert!(refused.unwrap_err().to_string().contains("no study p9"));
//! ```
//!
//! Dependencies: the workspace crates the studies run (`tandem-robots` for the papers' robots and
//! scenes); `serde`/`serde_json` and `toml` for the recorded settings and `--config` files,
//! `clap` so that every study's command line flattens the one [`StudyArgs`], `indicatif` for the
//! progress bars, `signal-hook` for [`interrupt`], `thiserror` for [`Error`], and `sha2`
//! (RustCrypto's, small and widely used) for the records' checksums: SHA-256 rather than the
//! CRC-32 of the checkpoints, so that `sha256sum -c` checks a committed record without tandem.
//! The build script (`build.rs`) asks `git` for the commit [`provenance`] records, if git is
//! there; no crate is needed for it.

#![warn(missing_docs)]

pub mod harness;
pub mod interrupt;
pub mod p0;
pub mod p1;
pub mod p2;
pub mod p3;
pub mod p4;
pub mod p4_reacher;
pub mod provenance;
pub mod report;
pub mod run;
pub mod sweep;

use std::path::{Path, PathBuf};

pub use harness::{Study, StudyArgs};
use tandem_envs::EnvError;

/// Why a study or a command failed. The message names the problem and where it is.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An environment refused something (unknown id, invalid action or state).
    #[error(transparent)]
    Env(#[from] EnvError),
    /// A file could not be read, written, created or removed.
    #[error("cannot {op} {}: {source}", path.display())]
    Io {
        /// What was being done.
        op: IoOp,
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// Malformed or unsuitable input (JSON, actions, arguments, settings).
    #[error("{what}: {message}")]
    Input {
        /// Which input, e.g. `--state` or `actions file a.json`.
        what: String,
        /// What is wrong with it.
        message: String,
    },
    /// Anything else, already phrased for the user.
    #[error("{0}")]
    Other(String),
    /// SIGINT or SIGTERM stopped the run after it wrote a checkpoint; a program exits with
    /// `code` (130 or 143).
    #[error("interrupted: {what}")]
    Interrupted {
        /// What was saved and how to go on.
        what: String,
        /// The exit status.
        code: u8,
    },
}

impl Error {
    /// An [`Error::Input`] error.
    pub fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input {
            what: what.into(),
            message: message.into(),
        }
    }

    /// An [`Error::Io`] error: `op` on `path` failed with `source`.
    pub fn io(op: IoOp, path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            op,
            path: path.into(),
            source,
        }
    }

    /// An [`Error::Other`] error from anything printable (e.g. another crate's error).
    pub fn other(e: impl std::fmt::Display) -> Self {
        Error::Other(e.to_string())
    }
}

/// What [`Error::Io`] was doing with its file, so that the message says so ("cannot write ...:
/// No space left on device", not "cannot read").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IoOp {
    /// Reading a file.
    Read,
    /// Writing a file.
    Write,
    /// Creating a directory.
    Create,
    /// Removing a file or directory.
    Remove,
}

impl std::fmt::Display for IoOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            IoOp::Read => "read",
            IoOp::Write => "write",
            IoOp::Create => "create",
            IoOp::Remove => "remove",
        })
    }
}

/// The result of a study or a command.
pub type Result<T> = std::result::Result<T, Error>;

/// What a study's command line may choose besides [`StudyArgs`]: the task of the studies that
/// run on several, and p3's extra runs. A study reads what applies to it; [`merge`] passes none,
/// as each directory's settings record them.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StudyOptions {
    /// The task (`p1`, `p2-maze`, `p3-mujoco`) [default: a `--config` file's or the study's].
    pub env: Option<String>,
    /// p3: also run M-DeMoRL's elite-fraction ablation (p3 Fig. 3).
    pub ablate_elites: bool,
    /// p3 on the leg: also run MBPO with the true system as its model.
    pub oracle: bool,
    /// p4: the settings to start from [default: the authors'].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<p4::Preset>,
}

/// A study as the registry holds it: run and merge with its settings type erased.
trait Registered {
    fn name(&self) -> &str;
    fn run(&self, args: &StudyArgs) -> Result<()>;
    fn check(&self, args: &StudyArgs) -> Result<Checked>;
    fn merge(&self, dirs: &[PathBuf], out: Option<&Path>, overwrite: bool) -> Result<()>;
}

impl<S: Study> Registered for S {
    fn name(&self) -> &str {
        Study::name(self)
    }
    fn run(&self, args: &StudyArgs) -> Result<()> {
        harness::run(self, args)
    }
    fn check(&self, args: &StudyArgs) -> Result<Checked> {
        let (rc, memory, cells) = harness::check(self, args)?;
        let settings = serde_json::to_value(&rc.config).map_err(Error::other)?;
        Ok(Checked {
            settings,
            memory,
            cells,
        })
    }
    fn merge(&self, dirs: &[PathBuf], out: Option<&Path>, overwrite: bool) -> Result<()> {
        harness::merge(self, dirs, out, overwrite)
    }
}

/// The registry: every study, made with `options`.
fn registry(options: &StudyOptions) -> Vec<Box<dyn Registered>> {
    use p0::{P0Study, P0Task};
    use p2::{Experiment, P2Study};
    use p4::{Door, P4Study, Pusher};
    let env = || options.env.clone();
    vec![
        Box::new(P0Study(P0Task::Pendulum)),
        Box::new(P0Study(P0Task::Leo)),
        Box::new(p1::P1Study::new(env())),
        Box::new(P2Study::new(Experiment::CartPole, env())),
        Box::new(P2Study::new(Experiment::Maze, env())),
        Box::new(p3::P3Study::leg(options.ablate_elites, options.oracle)),
        Box::new(p3::P3Study::mujoco(
            env(),
            options.ablate_elites,
            options.oracle,
        )),
        Box::new(P4Study::<Pusher>::new(options.preset)),
        Box::new(P4Study::<Door>::new(options.preset)),
        Box::new(p4_reacher::ReacherStudy {
            preset: options.preset,
        }),
    ]
}

/// Every study's name, in the registry's order.
pub fn study_names() -> Vec<String> {
    registry(&StudyOptions::default())
        .iter()
        .map(|s| s.name().to_string())
        .collect()
}

fn find(name: &str, options: &StudyOptions) -> Result<Box<dyn Registered>> {
    registry(options)
        .into_iter()
        .find(|s| s.name() == name)
        .ok_or_else(|| {
            Error::input(
                "study",
                format!(
                    "no study {name}; the studies are {}",
                    study_names().join(", ")
                ),
            )
        })
}

/// What [`check_study`] found: the settings a run would use and its estimated peak memory.
#[derive(Debug, Clone)]
pub struct Checked {
    /// The settings, as `config.json` records them.
    pub settings: serde_json::Value,
    /// The estimated peak memory of `--jobs` parallel jobs, bytes.
    pub memory: u64,
    /// The jobs, each a seed and its runs (those `--methods` selects), in the order a run
    /// starts them: the cells of a sweep ([`sweep`]).
    pub cells: Vec<(u64, Vec<String>)>,
}

/// Checks the study `name`'s settings whole as a run would before any work ([`harness::check`]:
/// ranges, products, seeds, memory), writing nothing; `tandem reproduce <study> --check`.
pub fn check_study(name: &str, options: &StudyOptions, args: &StudyArgs) -> Result<Checked> {
    find(name, options)?.check(args)
}

/// Runs (or with `--resume`, continues) the study `name` ([`harness::run`]).
pub fn run_study(name: &str, options: &StudyOptions, args: &StudyArgs) -> Result<()> {
    find(name, options)?.run(args)
}

/// Combines complete directories of one study with disjoint (seed, method) cells into one report in `out`
/// (default `runs/<study>-merged__<time>/`); the study is the one their `config.json` names
/// ([`harness::merge`]).
pub fn merge(dirs: &[PathBuf], out: Option<&Path>, overwrite: bool) -> Result<()> {
    let Some(first) = dirs.first() else {
        return Err(Error::input("merge", "no directories given"));
    };
    let name = harness::study_of(first)?;
    let study = find(&name, &StudyOptions::default()).map_err(|_| {
        Error::input(
            first.display().to_string(),
            format!("`tandem reproduce merge` does not merge {name} studies"),
        )
    })?;
    study.merge(dirs, out, overwrite)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_study_is_registered_once() {
        let names = study_names();
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(
            unique.len(),
            names.len(),
            "a name is registered twice: {names:?}"
        );
        assert!(names.contains(&"p0-pendulum".to_string()));
    }
}
