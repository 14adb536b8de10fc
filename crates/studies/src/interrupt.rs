//! Interruption of long runs: SIGINT (Ctrl-C) and SIGTERM (a cluster's scheduler, `kill`) ask a
//! run to stop; the run finishes its current step, writes a checkpoint and a summary marked
//! `interrupted`, and the program exits with 130 (SIGINT) or 143 (SIGTERM), the shell's
//! convention of 128 + the signal's number. A second signal ends the program at once, with the
//! same status.
//!
//! Long loops poll a [`Stop`] between steps; library users who handle signals themselves pass
//! [`Stop::never`] or call [`Stop::request`].
//!
//! ```
//! use tandem_studies::interrupt::Stop;
//!
//! let stop = Stop::never();
//! let mut steps = 0;
//! while !stop.requested() && steps < 1000 {
//!     steps += 1;
//!     if steps == 10 {
//!         stop.request(); // what a signal does
//!     }
//! }
//! assert_eq!(steps, 10);
//! assert_eq!(stop.exit_code(), Some(130));
//! ```
//!
//! Signals are caught with `signal-hook` (the maintained crate for signal handling in Rust; its
//! handlers only set atomic flags, which is all a signal handler may safely do). On platforms
//! without POSIX signals, [`Stop::on_signals`] returns a handle that only [`Stop::request`] sets.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A shared stop request: cheap to clone and to poll.
#[derive(Debug, Clone, Default)]
pub struct Stop {
    /// Set by either signal (or [`Stop::request`]).
    any: Arc<AtomicBool>,
    /// Set by SIGTERM only, to tell the exit status.
    term: Arc<AtomicBool>,
}

/// Exit status after SIGINT (128 + 2).
pub const EXIT_SIGINT: u8 = 130;
/// Exit status after SIGTERM (128 + 15).
pub const EXIT_SIGTERM: u8 = 143;

impl Stop {
    /// A handle no signal sets (only [`Stop::request`]).
    pub fn never() -> Self {
        Self::default()
    }

    /// A handle set by SIGINT and SIGTERM; a second signal of either kind exits the process at
    /// once (130 or 143). Call it once per process, before the work starts.
    pub fn on_signals() -> std::io::Result<Self> {
        let stop = Self::default();
        #[cfg(unix)]
        {
            use signal_hook::consts::{SIGINT, SIGTERM};
            use signal_hook::flag;
            for (sig, code) in [(SIGINT, EXIT_SIGINT), (SIGTERM, EXIT_SIGTERM)] {
                // Registered first, so it sees the flag as the previous signal left it.
                flag::register_conditional_shutdown(sig, i32::from(code), stop.any.clone())?;
                flag::register(sig, stop.any.clone())?;
            }
            flag::register(SIGTERM, stop.term.clone())?;
        }
        Ok(stop)
    }

    /// Asks the run to stop, as SIGINT does.
    pub fn request(&self) {
        self.any.store(true, Ordering::SeqCst);
    }

    /// Whether a stop was asked for.
    pub fn requested(&self) -> bool {
        self.any.load(Ordering::Relaxed)
    }

    /// The exit status the program should end with: `None` if no stop was asked for, 143 after
    /// SIGTERM, 130 otherwise.
    pub fn exit_code(&self) -> Option<u8> {
        if !self.requested() {
            None
        } else if self.term.load(Ordering::SeqCst) {
            Some(EXIT_SIGTERM)
        } else {
            Some(EXIT_SIGINT)
        }
    }
}
