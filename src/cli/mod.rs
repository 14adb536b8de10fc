//! Subcommands of the `tandem` program, one module each, and the error type they share.

pub mod env;
pub mod envs;
pub mod harness;
pub mod json;
pub mod presets;
pub mod reproduce;
pub mod reproduce_p0;
pub mod reproduce_p1;
pub mod reproduce_p2;
pub mod reproduce_p3;
pub mod reproduce_p4;
pub mod reproduce_p4_reacher;
pub mod rollout;
pub mod train;
pub mod urdf;

use std::path::PathBuf;

use tandem_envs::EnvError;

/// Why a command failed. The message names the problem and where it is; `main` prints it and
/// exits with status 1.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// An environment refused something (unknown id, invalid action or state).
    #[error(transparent)]
    Env(#[from] EnvError),
    /// A file could not be read or written.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// Malformed or unsuitable input (JSON, actions, arguments).
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
    /// SIGINT or SIGTERM stopped the run after it wrote a checkpoint; `main` exits with `code`
    /// (130 or 143).
    #[error("interrupted: {what}")]
    Interrupted {
        /// What was saved and how to go on.
        what: String,
        /// The exit status.
        code: u8,
    },
}

impl CliError {
    /// An [`CliError::Input`] error.
    pub fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        CliError::Input {
            what: what.into(),
            message: message.into(),
        }
    }

    /// A [`CliError::Other`] error from anything printable (e.g. another crate's error).
    pub fn other(e: impl std::fmt::Display) -> Self {
        CliError::Other(e.to_string())
    }
}

/// The result of a command.
pub type Result<T> = std::result::Result<T, CliError>;

/// Writes `text` and a newline to stdout. A closed pipe (`tandem ... | head`) ends the program
/// quietly with status 0, as a Unix tool stopped by SIGPIPE would, instead of panicking.
pub fn emit(text: &str) -> Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => Err(CliError::Other(format!("cannot write to stdout: {e}"))),
    }
}
