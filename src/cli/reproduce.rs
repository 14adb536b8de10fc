//! `tandem reproduce`: the papers' studies ([`tandem_studies`]) by name, each with its own
//! arguments, and `tandem reproduce merge`, which combines studies of disjoint (seed, method)
//! cells.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use tandem_studies::interrupt::Stop;
use tandem_studies::p4::Preset;
use tandem_studies::sweep::Resources;
use tandem_studies::{StudyArgs, StudyOptions};

use super::{CliError, Result};

/// The reproductions.
#[derive(Debug, Subcommand)]
pub enum ReproduceCommand {
    /// p0 (difference models) on the DC-motor pendulum: cold start, warm start and the
    /// difference-model method over seeds; Table II and Fig. 5.
    P0Pendulum(P0Args),
    /// p0 (difference models) on the Leo-like biped: cold start, warm start and the
    /// difference-model method over seeds; Tables III and IV, Fig. 8 and the gaits.
    P0Leo(P0Args),
    /// p1 (the deep incremental model) on a gymnasium MuJoCo task (`--env`, needs `--features
    /// mujoco`): SAC, MBPO and Dyna-SAC with the incremental model at the same real steps and
    /// updates per step; p1 Fig. 1.
    P1(P1Args),
    /// p2 (model-augmented REINFORCE) on CartPole-v1: REINFORCE alone and with the learned model.
    P2Cartpole(P2Args),
    /// p2 (model-augmented DQN) on its pixel maze: DQN alone and with the pixel model, and the
    /// pixel model's F1 after 10, 100 and 300 training episodes.
    P2Maze(P2Args),
    /// p3 (M-DeMoRL) on the 2R leg: SAC, MBPO and M-DeMoRL on the same seeds and real-step
    /// budget; p3 Fig. 4, and Fig. 3's elite-fraction ablation with `--ablate-elites`.
    P3Leg(P3Args),
    /// p3 (M-DeMoRL) on a gymnasium MuJoCo task (`--env`, needs `--features mujoco`): SAC, MBPO
    /// and M-DeMoRL with MBPO's settings for the task; p3 Fig. 2, and Fig. 3 with
    /// `--ablate-elites`.
    P3Mujoco(P3MujocoArgs),
    /// p4 (PILQR) on the gripper pusher (MuJoCo, needs `--features mujoco`): LQR-FLM, PI² and
    /// PILQR local controllers on four conditions, the same seeds and samples; p4 Fig. 3.
    P4Pusher(P4Args),
    /// p4 (PILQR) on the door (MuJoCo, needs `--features mujoco`): LQR-FLM, PI² and PILQR local
    /// controllers from four arm starts, the same seeds and samples.
    P4Door(P4Args),
    /// p4 (PILQR) Fig. 4 on gymnasium's reacher (MuJoCo, needs `--features mujoco`): neural
    /// policies by MDGPS with LQR-FLM, PI² or PILQR and by DDPG, final distance on 300 test targets.
    P4Reacher(P4Args),
    /// Combine p0-pendulum, p0-leo, p1, p2-cartpole, p2-maze, p3-leg, p3-mujoco, p4-pusher,
    /// p4-door or p4-reacher reproductions of disjoint (seed, method) cells (e.g. one process
    /// per seed and method, `--first-seed`, `--methods`) into one table and figure; their
    /// settings must be equal, and every merged method must be there on every merged seed.
    Merge(MergeArgs),
}

/// Arguments of `tandem reproduce p0-pendulum` and `p0-leo` (per seed, the cold start and the
/// pre-trained warm start and difference methods are separate jobs).
#[derive(Debug, Args)]
pub struct P0Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
    /// `--slurm`: submit the study to a SLURM cluster instead.
    #[command(flatten)]
    pub slurm: SlurmArgs,
}

/// Arguments of `tandem reproduce p1`.
#[derive(Debug, Clone, Args)]
pub struct P1Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
    /// `--slurm`: submit the study to a SLURM cluster instead.
    #[command(flatten)]
    pub slurm: SlurmArgs,
    /// The task: HalfCheetah-v5, Hopper-v5, Walker2d-v5 or InvertedPendulum-v5 [default:
    /// HalfCheetah-v5; on `--resume`, the recorded one].
    #[arg(long)]
    pub env: Option<String>,
}

/// Arguments of `tandem reproduce p2-cartpole` and `p2-maze`.
#[derive(Debug, Clone, Args)]
pub struct P2Args {
    /// Seeds (default 10, as p2 averages over 10 runs), output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
    /// `--slurm`: submit the study to a SLURM cluster instead.
    #[command(flatten)]
    pub slurm: SlurmArgs,
    /// p2-maze only: the maze, `PixelMaze-v0` (ours, from the paper alone) or `PixelMaze-v1`
    /// (the authors' released layout), with its default settings [default: a `--config`
    /// file's `env`, else PixelMaze-v0; on `--resume`, the recorded one].
    #[arg(long)]
    pub env: Option<String>,
}

/// Arguments of `tandem reproduce p3-leg`.
#[derive(Debug, Clone, Args)]
pub struct P3Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
    /// `--slurm`: submit the study to a SLURM cluster instead.
    #[command(flatten)]
    pub slurm: SlurmArgs,
    /// Also run M-DeMoRL with elite fractions 1, 5, 10, 20, 50 and 100 % (p3 Fig. 3).
    #[arg(long)]
    pub ablate_elites: bool,
    /// Also run MBPO with the true system as its model (`mbpo_oracle`; the leg only): what MBPO
    /// would do with a perfect model, to tell model error from the loop's own limits.
    #[arg(long)]
    pub oracle: bool,
}

/// Arguments of `tandem reproduce p3-mujoco`.
#[derive(Debug, Clone, Args)]
pub struct P3MujocoArgs {
    /// The p3-leg arguments.
    #[command(flatten)]
    pub p3: P3Args,
    /// The task: HalfCheetah-v5, Hopper-v5, Walker2d-v5 or InvertedPendulum-v5 [default:
    /// HalfCheetah-v5; on `--resume`, the recorded one].
    #[arg(long)]
    pub env: Option<String>,
}

/// Arguments of `tandem reproduce p4-pusher`, `p4-door` and `p4-reacher`.
#[derive(Debug, Clone, Args)]
pub struct P4Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
    /// `--slurm`: submit the study to a SLURM cluster instead.
    #[command(flatten)]
    pub slurm: SlurmArgs,
    /// The settings to start from, before `--quick` and `--config`: `authors` (the authors' GPS
    /// experiment files where the paper is silent) or `ours` (our first settings) [default:
    /// authors; on `--resume`, the recorded settings].
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
}

/// `tandem reproduce <study> --slurm`: the study as a SLURM job array of (seed, method) cells
/// and a merge job after them ([`tandem_studies::sweep`]); `--out` is the sweep's directory.
#[derive(Debug, Clone, Args)]
pub struct SlurmArgs {
    /// Submit the study to SLURM instead of running it here: one array task per cell (a seed
    /// and a method), resumed after preemption, and a job that merges them into `--out`/merged/.
    #[arg(long)]
    pub slurm: bool,
    /// What each task asks for.
    #[command(flatten)]
    pub resources: Resources,
    /// With `--slurm`: print the job scripts and the `sbatch` commands, write and submit
    /// nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// With `--slurm`: the `tandem` program the tasks run [default: this one].
    #[arg(long, value_name = "PATH")]
    pub tandem: Option<PathBuf>,
}

impl SlurmArgs {
    /// Refuses SLURM's options without `--slurm`.
    fn refuse_without_slurm(&self) -> Result<()> {
        let given = self.dry_run || self.tandem.is_some() || self.resources != Resources::default();
        if !self.slurm && given {
            return Err(CliError::input(
                "--slurm",
                "--partition, --time, --mem, --cpus-per-task, --account, --grace, --dry-run and \
                 --tandem are options of a SLURM sweep: add --slurm",
            ));
        }
        Ok(())
    }
}

/// Arguments of `tandem reproduce merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The reproductions' directories (each complete).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Output directory (default `runs/<study>-merged__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace a merge already in `--out`.
    #[arg(long)]
    pub overwrite: bool,
}

impl P3Args {
    /// The study's options on the task `env`.
    fn options(&self, env: Option<String>) -> StudyOptions {
        StudyOptions {
            env,
            ablate_elites: self.ablate_elites,
            oracle: self.oracle,
            ..StudyOptions::default()
        }
    }
}

/// Runs a reproduction, or merges some.
pub fn run(cmd: ReproduceCommand) -> Result<()> {
    let on = |env| StudyOptions {
        env,
        ..StudyOptions::default()
    };
    let p4 = |preset| StudyOptions {
        preset,
        ..StudyOptions::default()
    };
    let (name, args, slurm, options) = match cmd {
        ReproduceCommand::P0Pendulum(a) => ("p0-pendulum", a.study, a.slurm, on(None)),
        ReproduceCommand::P0Leo(a) => ("p0-leo", a.study, a.slurm, on(None)),
        ReproduceCommand::P1(a) => ("p1", a.study, a.slurm, on(a.env)),
        ReproduceCommand::P2Cartpole(a) => ("p2-cartpole", a.study, a.slurm, on(a.env)),
        ReproduceCommand::P2Maze(a) => ("p2-maze", a.study, a.slurm, on(a.env)),
        ReproduceCommand::P3Leg(a) => {
            let options = a.options(None);
            ("p3-leg", a.study, a.slurm, options)
        }
        ReproduceCommand::P3Mujoco(a) => {
            let options = a.p3.options(a.env);
            ("p3-mujoco", a.p3.study, a.p3.slurm, options)
        }
        ReproduceCommand::P4Pusher(a) => ("p4-pusher", a.study, a.slurm, p4(a.preset)),
        ReproduceCommand::P4Door(a) => ("p4-door", a.study, a.slurm, p4(a.preset)),
        ReproduceCommand::P4Reacher(a) => ("p4-reacher", a.study, a.slurm, p4(a.preset)),
        ReproduceCommand::Merge(a) => {
            return tandem_studies::merge(&a.dirs, a.out.as_deref(), a.overwrite)
        }
    };
    slurm.refuse_without_slurm()?;
    if slurm.slurm {
        return super::sweep::create(name, &options, &args, slurm);
    }
    let stop = Stop::on_signals().map_err(|e| CliError::Other(format!("signal handlers: {e}")))?;
    tandem_studies::run_study(name, &options, &StudyArgs { stop, ..args })
}
