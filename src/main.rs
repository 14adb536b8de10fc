//! The `tandem` program.
//!
//! Each subcommand lives in its own module under `src/cli/`. Adding one takes three lines here
//! and in `cli/mod.rs`: a `pub mod NAME;` in `cli/mod.rs`, one variant in [`Command`] (its
//! arguments or nested subcommands defined in the module), and one arm in [`run`] calling the
//! module's `run`, which returns [`cli::Result`]. Errors are printed as `error: ...` on stderr
//! with exit status 1; clap's usage errors exit with status 2.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use mimalloc::MiMalloc;

mod cli;

#[global_allocator]
static GLOBAL: MiMalloc = MiMalloc;

/// tandem: sample-efficient robot learning, model-based and model-free methods in tandem.
#[derive(Debug, Parser)]
#[command(name = "tandem", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
enum Command {
    /// List the registered environments with their spaces and episode limits.
    Envs,
    /// Run a random or zero policy for some episodes and print the returns.
    Rollout(cli::rollout::RolloutArgs),
    /// Environment tools (replay a trajectory from a state).
    #[command(subcommand)]
    Env(cli::env::EnvCommand),
    /// Train a model-free agent (ddpg, sac, dqn, reinforce) and write a run directory.
    Train(cli::train::TrainArgs),
    /// Reproduce a paper end to end: its study over seeds, with tables and figures (p0-pendulum,
    /// p0-leo, p1, p2-cartpole, p2-maze, p3-leg, p3-mujoco, p4-pusher, p4-door, p4-reacher), or
    /// merge studies of disjoint (seed, method) cells.
    #[command(subcommand)]
    Reproduce(cli::reproduce::ReproduceCommand),
    /// A study submitted with `tandem reproduce <study> --slurm`: its cells' state, resubmitting
    /// what did not finish, and the commands its job scripts run.
    #[command(subcommand)]
    Sweep(cli::sweep::SweepCommand),
    /// Rigid-body dynamics of a URDF robot (inspect its joints; evaluate RNEA/CRBA/ABA/...).
    #[command(subcommand)]
    Urdf(cli::urdf::UrdfCommand),
}

/// Runs one parsed command.
fn run(command: Command) -> cli::Result<()> {
    match command {
        Command::Envs => cli::envs::run(),
        Command::Rollout(args) => cli::rollout::run(&args),
        Command::Env(cmd) => cli::env::run(cmd),
        Command::Train(args) => cli::train::run(&args),
        Command::Reproduce(cmd) => cli::reproduce::run(cmd),
        Command::Sweep(cmd) => cli::sweep::run(cmd),
        Command::Urdf(cmd) => cli::urdf::run(cmd),
    }
}

fn main() -> ExitCode {
    tandem::keep_freed_memory();
    // candle (conv Q-networks) needs its thread settings before any thread exists.
    tandem_nn::candle_ext::configure_cpu_threads();
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e @ cli::CliError::Interrupted { code, .. }) => {
            eprintln!("{e}");
            ExitCode::from(code)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
