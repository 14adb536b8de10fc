//! `tandem reproduce`: whole-paper reproductions, one module each (`reproduce_p0`,
//! `reproduce_p1`, ...), and `tandem reproduce merge`, which combines studies of disjoint seeds.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};

use super::harness;
use super::reproduce_p0::{P0Args, P0Study, P0Task};
use super::reproduce_p1::P1Study;
use super::reproduce_p2::{Experiment, P2Study};
use super::reproduce_p3::P3Study;
use super::reproduce_p4::{Door, P4Study, Pusher};
use super::reproduce_p4_reacher::ReacherStudy;
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
    P1(super::reproduce_p1::P1Args),
    /// p2 (model-augmented REINFORCE) on CartPole-v1: REINFORCE alone and with the learned model.
    P2Cartpole(super::reproduce_p2::P2Args),
    /// p2 (model-augmented DQN) on its pixel maze: DQN alone and with the pixel model, and the
    /// pixel model's F1 after 10, 100 and 300 training episodes.
    P2Maze(super::reproduce_p2::P2Args),
    /// p3 (M-DeMoRL) on the 2R leg: SAC, MBPO and M-DeMoRL on the same seeds and real-step
    /// budget; p3 Fig. 4, and Fig. 3's elite-fraction ablation with `--ablate-elites`.
    P3Leg(super::reproduce_p3::P3Args),
    /// p3 (M-DeMoRL) on a gymnasium MuJoCo task (`--env`, needs `--features mujoco`): SAC, MBPO
    /// and M-DeMoRL with MBPO's settings for the task; p3 Fig. 2, and Fig. 3 with
    /// `--ablate-elites`.
    P3Mujoco(super::reproduce_p3::P3MujocoArgs),
    /// p4 (PILQR) on the gripper pusher (MuJoCo, needs `--features mujoco`): LQR-FLM, PI² and
    /// PILQR local controllers on four conditions, the same seeds and samples; p4 Fig. 3.
    P4Pusher(super::reproduce_p4::P4Args),
    /// p4 (PILQR) on the door (MuJoCo, needs `--features mujoco`): LQR-FLM, PI² and PILQR local
    /// controllers from four arm starts, the same seeds and samples.
    P4Door(super::reproduce_p4::P4Args),
    /// p4 (PILQR) Fig. 4 on gymnasium's reacher (MuJoCo, needs `--features mujoco`): neural
    /// policies by MDGPS with LQR-FLM, PI² or PILQR and by DDPG, final distance on 300 test targets.
    P4Reacher(super::reproduce_p4_reacher::ReacherArgs),
    /// Combine p0-pendulum, p0-leo, p1, p2-cartpole, p2-maze, p3-leg, p3-mujoco, p4-pusher, p4-door or p4-reacher reproductions of disjoint seeds (e.g. one
    /// process per seed, `--first-seed`) into one table and figure; their settings must be equal.
    Merge(MergeArgs),
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

/// Runs a reproduction.
pub fn run(cmd: ReproduceCommand) -> Result<()> {
    match cmd {
        ReproduceCommand::P0Pendulum(args) => harness::run(&P0Study(P0Task::Pendulum), &args.study),
        ReproduceCommand::P0Leo(args) => harness::run(&P0Study(P0Task::Leo), &args.study),
        ReproduceCommand::P1(args) => harness::run(&P1Study::new(args.env), &args.study),
        ReproduceCommand::P2Cartpole(args) => {
            harness::run(&P2Study::new(Experiment::CartPole, args.env), &args.study)
        }
        ReproduceCommand::P2Maze(args) => {
            harness::run(&P2Study::new(Experiment::Maze, args.env), &args.study)
        }
        ReproduceCommand::P3Leg(args) => {
            harness::run(&P3Study::leg(args.ablate_elites, args.oracle), &args.study)
        }
        ReproduceCommand::P3Mujoco(args) => harness::run(
            &P3Study::mujoco(args.env, args.p3.ablate_elites, args.p3.oracle),
            &args.p3.study,
        ),
        ReproduceCommand::P4Pusher(args) => harness::run(&P4Study::<Pusher>::new(), &args.study),
        ReproduceCommand::P4Door(args) => harness::run(&P4Study::<Door>::new(), &args.study),
        ReproduceCommand::P4Reacher(args) => harness::run(&ReacherStudy, &args.study),
        ReproduceCommand::Merge(args) => {
            let Some(first) = args.dirs.first() else {
                return Err(CliError::input("merge", "no directories given"));
            };
            let name = harness::study_of(first)?;
            let Some(study) = registry().into_iter().find(|s| s.name() == name) else {
                return Err(CliError::input(
                    first.display().to_string(),
                    format!("`tandem reproduce merge` does not merge {name} studies"),
                ));
            };
            study.merge(&args.dirs, args.out.as_deref(), args.overwrite)
        }
    }
}

/// A study as `merge` finds it by its name; the settings come from the directories.
trait Registered {
    fn name(&self) -> &str;
    fn merge(&self, dirs: &[PathBuf], out: Option<&Path>, overwrite: bool) -> Result<()>;
}

impl<S: harness::Study> Registered for S {
    fn name(&self) -> &str {
        harness::Study::name(self)
    }
    fn merge(&self, dirs: &[PathBuf], out: Option<&Path>, overwrite: bool) -> Result<()> {
        harness::merge(self, dirs, out, overwrite)
    }
}

/// Every study of `tandem reproduce`.
fn registry() -> Vec<Box<dyn Registered>> {
    vec![
        Box::new(P0Study(P0Task::Pendulum)),
        Box::new(P0Study(P0Task::Leo)),
        Box::new(P1Study::new(None)),
        Box::new(P2Study::new(Experiment::CartPole, None)),
        Box::new(P2Study::new(Experiment::Maze, None)),
        Box::new(P3Study::leg(false, false)),
        Box::new(P3Study::mujoco(None, false, false)),
        Box::new(P4Study::<Pusher>::new()),
        Box::new(P4Study::<Door>::new()),
        Box::new(ReacherStudy),
    ]
}
