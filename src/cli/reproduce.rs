//! `tandem reproduce`: whole-paper reproductions. `tandem reproduce p0-pendulum` runs p0's three
//! methods (cold start, warm start, difference model) over seeds on the DC-motor pendulum and
//! writes, in the output directory:
//!
//! - `config.json`: the [`P0Config`] used, seeds, status (`running`, `interrupted`, `complete`)
//!   and wall time;
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's learning curve (return of
//!   the deterministic policy on the true system against true training samples);
//! - `table.md`, `table.json`: p0's Table II (return at the fixed budget; true samples to the
//!   fixed target return), a typed [`tandem::report::Table`] rendered by the shared report code
//!   with p0's words ([`markdown`]);
//! - `fig5.svg`: p0's Fig. 5 (mean return on the true system against true samples, ± standard
//!   error across seeds).
//!
//! While it runs, `state/seed<k>/` holds each unfinished run's checkpoint (after every
//! evaluation; the pre-trained agent too), and each run writes its `record.json` as soon as it
//! finishes. SIGINT or SIGTERM stops the jobs at once (each loses at most the steps since its
//! last evaluation), marks `config.json` `interrupted` and exits with 130 or 143;
//! `--resume DIR` continues from the checkpoints (also after a kill), refusing other settings,
//! and ends with the files an uninterrupted run writes (wall times aside); `state/` is removed at
//! the end.
//!
//! Evaluation episodes run on a separate copy of the true system and are not counted as training
//! samples. An `--out` that already holds a reproduction is an error unless `--overwrite` (no seed
//! folders of an earlier run are left beside a new table); a NaN or infinite number in the
//! configuration or about to be written is an error naming it.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use tandem::pipelines::p0::{
    ddpg_agent, pendulum_problem, run_seed, Method, P0Config, RunRecord, Tick,
};
use tandem::pipelines::Checkpoints;
use tandem::report::{
    mean_stderr, Comparison, Figure, MarkdownText, MethodFigures, Reference, SeedRun, Table,
};
use tandem::run::RunDir;

use super::harness::{self, JobError, Study, StudyArgs};
use super::reproduce_p1::P1Study;
use super::reproduce_p3::P3Study;
use super::{CliError, Result};

/// The reproductions.
#[derive(Debug, Subcommand)]
pub enum ReproduceCommand {
    /// p0 (difference models) on the DC-motor pendulum: cold start, warm start and the
    /// difference-model method over seeds; Table II and Fig. 5.
    P0Pendulum(P0Args),
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
    /// Combine p0-pendulum, p1, p3-leg or p3-mujoco reproductions of disjoint seeds (e.g. one
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

/// Arguments of `tandem reproduce p0-pendulum` (per seed, the cold start and the pre-trained
/// pair of warm start and difference model are separate jobs).
#[derive(Debug, Args)]
pub struct P0Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
}

/// Runs a reproduction.
pub fn run(cmd: ReproduceCommand) -> Result<()> {
    match cmd {
        ReproduceCommand::P0Pendulum(args) => harness::run(&P0Pendulum, &args.study),
        ReproduceCommand::P1(args) => harness::run(&P1Study::new(args.env), &args.study),
        ReproduceCommand::P2Cartpole(args) => {
            super::reproduce_p2::p2(super::reproduce_p2::Experiment::CartPole, &args)
        }
        ReproduceCommand::P2Maze(args) => {
            super::reproduce_p2::p2(super::reproduce_p2::Experiment::Maze, &args)
        }
        ReproduceCommand::P3Leg(args) => {
            harness::run(&P3Study::leg(args.ablate_elites, args.oracle), &args.study)
        }
        ReproduceCommand::P3Mujoco(args) => harness::run(
            &P3Study::mujoco(args.env, args.p3.ablate_elites, args.p3.oracle),
            &args.p3.study,
        ),
        ReproduceCommand::Merge(args) => {
            let Some(first) = args.dirs.first() else {
                return Err(CliError::input("merge", "no directories given"));
            };
            match harness::study_of(first)?.as_str() {
                "p0-pendulum" => {
                    harness::merge(&P0Pendulum, &args.dirs, args.out.as_deref(), args.overwrite)
                }
                "p1" => harness::merge(
                    &P1Study::new(None),
                    &args.dirs,
                    args.out.as_deref(),
                    args.overwrite,
                ),
                "p3-leg" => harness::merge(
                    &P3Study::leg(false, false),
                    &args.dirs,
                    args.out.as_deref(),
                    args.overwrite,
                ),
                "p3-mujoco" => harness::merge(
                    &P3Study::mujoco(None, false, false),
                    &args.dirs,
                    args.out.as_deref(),
                    args.overwrite,
                ),
                other => Err(CliError::input(
                    first.display().to_string(),
                    format!("`tandem reproduce merge` does not merge {other} studies"),
                )),
            }
        }
    }
}

/// The `--quick` configuration: the same loop with small networks and budgets, for smoke tests.
pub fn quick_config() -> P0Config {
    let mut c = P0Config::default();
    c.ddpg.actor_hidden = vec![32, 32];
    c.ddpg.critic_hidden = vec![32, 32];
    c.ddpg.buffer_size = 10_000;
    c.residual.hidden = vec![32, 32];
    c.pretrain_steps = 800;
    c.real_batch = 400;
    c.real_budget = 800;
    c.baseline_max_samples = 1200;
    c.eval_interval = 400;
    c.model_steps = 400;
    c.fit.epochs = 3;
    c
}

/// Applies the overrides in `text` (a `--config` file, named `what` in errors) to `base` and
/// validates the result.
pub fn parse_config(base: P0Config, text: &str, what: &str) -> Result<P0Config> {
    let cfg = harness::override_settings(&base, text, what)?;
    checked(cfg, what)
}

/// `cfg` if valid, else an error naming `what`.
fn checked(cfg: P0Config, what: &str) -> Result<P0Config> {
    cfg.validate()
        .map_err(|e| CliError::input(what, e.to_string()))?;
    let h = cfg.fit.holdout_fraction;
    if !(0.0..1.0).contains(&h) {
        return Err(CliError::input(
            what,
            format!("fit.holdout_fraction is {h}, must be in [0, 1)"),
        ));
    }
    Ok(cfg)
}

/// p0's methods as the table names them, in row order.
const LABELS: &[(&str, &str)] = &[
    ("cold", "Cold start"),
    ("warm", "Warm start"),
    ("difference", "Difference model"),
];

/// How the sample ratios are taken.
const RATIO_NOTE: &str =
    "per-seed samples to the target, a seed that never reached it counted at the samples it used";

/// Table II: per method, the return at the budget and the true samples to the target; the
/// reference μ^true (the cold start's converged return); how many times more true samples each
/// baseline needed than the difference method.
pub fn table(records: &[RunRecord], cfg: &P0Config) -> Table {
    let mut t = Table::default();
    // Per method: mean true samples to the target with a seed that never reached it counted at
    // the samples it used, and whether any seed fell short.
    let mut used: Vec<(Method, f64, bool)> = Vec::new();
    for m in Method::ALL {
        let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == m).collect();
        if runs.is_empty() {
            continue;
        }
        let seeds: Vec<SeedRun> = runs
            .iter()
            .map(|r| SeedRun {
                seed: r.seed,
                samples: r.true_samples,
                return_at_budget: r.return_at(cfg.real_budget).unwrap_or(f64::NAN),
                samples_to_target: r.samples_to(cfg.target_return),
            })
            .collect();
        let (figures, mean_samples, short) =
            MethodFigures::from_runs(cfg.real_budget, cfg.target_return, &seeds);
        used.push((m, mean_samples, short));
        t.methods.insert(m.name().into(), figures);
    }
    let cold: Vec<&RunRecord> = records
        .iter()
        .filter(|r| r.method == Method::Cold)
        .collect();
    if !cold.is_empty() {
        let per_seed: Vec<f64> = cold
            .iter()
            .map(|r| r.final_return(cfg.reference_evals))
            .collect();
        let (mean, stderr) = mean_stderr(&per_seed);
        let gap = t
            .methods
            .get(Method::Difference.name())
            .map(|d| (d.return_at_budget.mean - mean).abs() / mean.abs());
        t.reference = Some(Reference {
            what: "cold start after all its true samples: mean of its last evaluations".into(),
            true_samples: cold.iter().map(|r| r.true_samples).max().unwrap_or(0),
            last_evaluations: cfg.reference_evals,
            mean,
            stderr,
            per_seed,
            relative_gaps: [(Method::Difference.name().to_string(), gap)].into(),
        });
    }
    if let Some(&(d, d_mean, d_short)) = used.iter().find(|x| x.0 == Method::Difference) {
        for &(b, b_mean, b_short) in used.iter().filter(|x| x.0 != Method::Difference) {
            t.comparisons.push(Comparison::new(
                (b.name(), b_mean, b_short),
                (d.name(), d_mean, d_short),
                RATIO_NOTE,
            ));
        }
    }
    t
}

/// Table II as Markdown: the shared rendering with p0's words; `wall` is the run's wall time.
pub fn markdown(t: &Table, cfg: &P0Config, wall: f64) -> String {
    let n_seeds = t.methods.values().map(|m| m.seeds.len()).max().unwrap_or(0);
    let mut closing = Vec::new();
    if let Some(r) = &t.reference {
        let gap = r
            .relative_gaps
            .get(Method::Difference.name())
            .copied()
            .flatten();
        closing.push(format!(
            "Reference μ^true (cold start after {} true samples, mean of its last {} \
             evaluations): {:.1} ± {:.1}; the difference method at the budget is {} from it.",
            r.true_samples,
            r.last_evaluations,
            r.mean,
            r.stderr,
            gap.map_or("n/a".to_string(), |g| format!("{:.1} %", 100.0 * g)),
        ));
    }
    closing.push(format!(
        "Cold and warm runs are evaluated every {} true samples; warm runs stop once they have \
         reached the target and used the budget ({}), cold runs use all {} true samples; the \
         difference method is evaluated after each model update ({} true samples each, {} in \
         all). Wall time {wall:.0} s.",
        cfg.eval_interval,
        cfg.baseline_stop_early,
        cfg.baseline_max_samples,
        cfg.real_batch,
        cfg.real_budget,
    ));
    t.markdown(&MarkdownText {
        title: format!("p0 Table II on the DC-motor pendulum ({n_seeds} seeds)"),
        intro: "Return of the deterministic policy on the true system (undiscounted, one \
                400-step episode from (π, 0)). True samples are training samples on the true \
                system, counted exactly; evaluation episodes are not counted. Mean ± standard \
                error over seeds."
            .into(),
        labels: LABELS,
        comparison_intro: "True samples to the target relative to the difference method (means \
                           over seeds; a seed that never reached it counts at the samples it \
                           used)"
            .into(),
        comparison_order: &["warm", "cold"],
        closing,
    })
}

/// Fig. 5: the mean return on the true system against true samples, per method, with ± standard
/// error bands over the seeds that have a point at that sample count.
pub fn fig5(records: &[RunRecord]) -> Figure {
    let names = Method::ALL.map(Method::name);
    let curves = harness::mean_curves(records, &names, |r| (r.method.name(), &r.curve));
    Figure {
        title: "p0 Fig. 5: DC-motor pendulum, policies evaluated on the true system".into(),
        x_label: "true-system training samples".into(),
        y_label: "return on the true system".into(),
        curves,
    }
}

/// The p0-pendulum study: per seed, the cold start, and the warm start with the difference
/// method (one job: they share the pre-trained agent).
pub struct P0Pendulum;

impl Study for P0Pendulum {
    type Settings = P0Config;
    type Record = RunRecord;

    fn name(&self) -> &str {
        "p0-pendulum"
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<P0Config> {
        let base = if quick {
            quick_config()
        } else {
            P0Config::default()
        };
        let Some(path) = config else { return Ok(base) };
        let text = std::fs::read_to_string(path).map_err(|source| CliError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        parse_config(base, &text, &format!("--config {}", path.display()))
    }

    fn jobs(&self, _cfg: &P0Config) -> Vec<Vec<String>> {
        let name = |m: Method| m.name().to_string();
        vec![
            vec![name(Method::Warm), name(Method::Difference)],
            vec![name(Method::Cold)],
        ]
    }

    fn length(&self, cfg: &P0Config, run: &str) -> u64 {
        if run == Method::Difference.name() {
            cfg.real_budget
        } else {
            cfg.baseline_max_samples
        }
    }

    fn run(
        &self,
        cfg: &P0Config,
        run: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<RunRecord, JobError> {
        let m = Method::ALL
            .into_iter()
            .find(|m| m.name() == run)
            .ok_or_else(|| JobError::Failed(format!("unknown run {run}")))?;
        let problem = pendulum_problem();
        let mut records = run_seed(
            &problem,
            cfg,
            &[m],
            seed,
            &|m, s| ddpg_agent(cfg, &problem.task, m, s),
            store,
            &mut |t| {
                if let Tick::True(_, n) = t {
                    if n % 50 == 0 {
                        progress(n);
                    }
                }
            },
        )?;
        records
            .pop()
            .ok_or_else(|| JobError::Failed(format!("seed {seed}: {run} left no record")))
    }

    fn curve(&self, r: &RunRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        harness::curve_rows("true_samples", &r.curve)
    }

    fn report_files(&self) -> &'static [&'static str] {
        &["table.json", "table.md", "fig5.svg"]
    }

    fn report(
        &self,
        dir: &RunDir,
        cfg: &P0Config,
        records: &[RunRecord],
        wall: f64,
    ) -> Result<String> {
        let table = table(records, cfg);
        let md = markdown(&table, cfg, wall);
        harness::write_table(dir, &table, &md)?;
        harness::write(dir, "fig5.svg", &fig5(records).svg())?;
        Ok(md)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem::pipelines::p0::CurvePoint;

    fn record(method: Method, seed: u64, curve: &[(u64, f64)]) -> RunRecord {
        RunRecord {
            method,
            seed,
            curve: curve
                .iter()
                .map(|&(true_samples, eval_return)| CurvePoint {
                    true_samples,
                    eval_return,
                })
                .collect(),
            true_samples: curve.last().map_or(0, |p| p.0),
            simulated_steps: 0,
            updates: 0,
            fit_holdout_loss: vec![],
            wall_seconds: 0.0,
        }
    }

    #[test]
    fn table_has_ratios_lower_bounds_and_the_reference() {
        let cfg = P0Config {
            real_budget: 800,
            reference_evals: 2,
            ..P0Config::default()
        };
        let recs = [
            // Cold: seed 0 reaches −1000 at 1200, seed 1 never within its 1600 samples.
            record(
                Method::Cold,
                0,
                &[(0, -9e3), (800, -2e3), (1200, -900.0), (1600, -700.0)],
            ),
            record(
                Method::Cold,
                1,
                &[(0, -9e3), (800, -5e3), (1200, -3e3), (1600, -1500.0)],
            ),
            // Warm: 400 and 800.
            record(Method::Warm, 0, &[(0, -4e3), (400, -990.0), (800, -800.0)]),
            record(Method::Warm, 1, &[(0, -4e3), (400, -2e3), (800, -950.0)]),
            // Difference: 400 in both seeds, −700 and −660 at the budget.
            record(
                Method::Difference,
                0,
                &[(0, -4e3), (400, -800.0), (800, -700.0)],
            ),
            record(
                Method::Difference,
                1,
                &[(0, -4e3), (400, -900.0), (800, -660.0)],
            ),
        ];
        let t = table(&recs, &cfg);
        let close = |v: f64, x: f64| (v - x).abs() < 1e-12;
        let cmp = |b: &str| t.comparisons.iter().find(|c| c.baseline == b).unwrap();
        // Cold: (1200 + 1600) / 2 over 400, a lower bound (seed 1 never reached it).
        assert!(close(cmp("cold").ratio.unwrap(), 3.5));
        assert!(cmp("cold").lower_bound);
        assert!(close(cmp("warm").ratio.unwrap(), 1.5));
        assert!(!cmp("warm").lower_bound);
        assert_eq!(
            t.methods["cold"].samples_to_target.per_seed,
            [Some(1200), None]
        );
        // Return at the 800 budget: the difference runs' −700 and −660.
        let d_ret = &t.methods["difference"].return_at_budget;
        assert_eq!(d_ret.per_seed, [-700.0, -660.0]);
        assert!(close(d_ret.mean, -680.0) && close(d_ret.stderr, 20.0));
        // Reference: the mean of the cold runs' last two evaluations, per seed.
        let reference = t.reference.as_ref().unwrap();
        assert_eq!(reference.per_seed, [-800.0, -2250.0]);
        let (r, d) = (-1525.0, -680.0);
        assert!(close(reference.mean, r));
        assert!(close(
            reference.relative_gaps["difference"].unwrap(),
            (d - r) / -r
        ));
        let md = markdown(&t, &cfg, 1.0);
        assert!(md.contains("Cold start ≥ 3.5×"), "{md}");
        assert!(md.contains("Warm start 1.5×"), "{md}");
        assert!(
            md.starts_with("# p0 Table II on the DC-motor pendulum (2 seeds)"),
            "{md}"
        );
        // The JSON reads back to the same table.
        assert_eq!(Table::from_json(&t.to_json().unwrap(), "t").unwrap(), t);
    }

    #[test]
    fn a_run_short_of_the_budget_is_an_error_naming_the_seed_not_a_null() {
        let cfg = P0Config {
            real_budget: 800,
            ..P0Config::default()
        };
        // Seed 1's curve has no point at or before the budget... its first point is after it.
        let recs = [
            record(Method::Cold, 0, &[(0, -9e3), (800, -2e3)]),
            record(Method::Cold, 1, &[(1200, -900.0)]),
        ];
        let e = table(&recs, &cfg).to_json().unwrap_err().to_string();
        assert!(
            e.contains("cold.return_at_budget.per_seed[1] is NaN"),
            "{e}"
        );
    }

    /// The committed p0 results (`results/p0-pendulum/`), 5 seeds, 787 s wall time.
    const COMMITTED_JSON: &str = include_str!("../../results/p0-pendulum/table.json");
    const COMMITTED_MD: &str = include_str!("../../results/p0-pendulum/table.md");

    #[test]
    fn the_committed_table_reads_back_and_renders_to_the_committed_files() {
        let t = Table::from_json(COMMITTED_JSON, "table.json").unwrap();
        assert_eq!(t.methods.len(), 3);
        assert_eq!(t.comparisons.len(), 2);
        assert_eq!(t.to_json().unwrap().trim_end(), COMMITTED_JSON.trim_end());
        // The footer's figures are P0Config's defaults, which the committed run used.
        assert_eq!(markdown(&t, &P0Config::default(), 787.0), COMMITTED_MD);
    }
}
