//! Subcommands of the `tandem` program, one module each, and the error type they share.

pub mod env;
pub mod envs;
pub mod json;
pub mod presets;
pub mod reproduce;
pub mod rollout;
pub mod sweep;
pub mod train;
pub mod urdf;

/// Why a command failed: the studies' error type serves every command. `main` prints it and
/// exits with status 1 (or the status of an interruption).
pub use tandem_studies::{Error as CliError, IoOp, Result};

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
