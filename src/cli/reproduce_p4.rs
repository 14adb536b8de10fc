//! `tandem reproduce p4-pusher`: p4's Fig. 3 (Chebotar et al., PILQR): LQR-FLM, PI² and PILQR
//! train one time-varying linear-Gaussian controller per condition of the gripper pusher (MuJoCo),
//! on the same seeds and sample budget, through the shared [`super::harness`] (separate processes
//! per seed, merge, resume).
//!
//! Writes, besides the harness' `config.json`, `runs/` and `state/`:
//!
//! - `table.md`, `table.json`: per method (`lqr_flm`, `pi2`, `pilqr`) on the hard condition the
//!   samples to a mean final block–goal distance at or below the target (`samples_to_target`
//!   {target, mean, per_seed}) and the final distance (`final` {mean, stderr, per_seed}); per
//!   condition the final distance and on how many seeds the method solved it (final distance at
//!   or below the target);
//! - `fig3.svg`: the mean final block–goal distance against the samples of the hard condition.
//!
//! A run (one method, one seed, four conditions) takes minutes and keeps no checkpoints: a
//! resumed study keeps the finished runs and reruns the others from their start.

use std::collections::BTreeMap;
use std::path::Path;

use clap::Args;
use serde::{Deserialize, Serialize};
use tandem::mujoco::p4::{PusherCost, PUSHER_CONDITIONS, PUSHER_HARD};
use tandem::pipelines::gps::{train_local, LocalConfig, LocalMethod, LocalPoint};
use tandem::pipelines::p4::pusher_problem;
use tandem::pipelines::Checkpoints;
use tandem::report::{mean_stderr, to_json_pretty, Curve, Figure, SamplesToTarget};
use tandem::run::RunDir;

use super::harness::{self, JobError, Study, StudyArgs};
use super::{CliError, Result};

/// Arguments of `tandem reproduce p4-pusher`.
#[derive(Debug, Clone, Args)]
pub struct P4Args {
    /// Seeds, output, jobs, resume: as every study.
    #[command(flatten)]
    pub study: StudyArgs,
}

/// Everything that decides a p4 pusher study's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct P4PusherSettings {
    /// The local-controller loop (iterations, samples per iteration, optimizers, dynamics fit).
    pub local: LocalConfig,
    /// The cost weights.
    pub cost: PusherCost,
    /// A condition counts as solved when the mean final block–goal distance of the last
    /// iteration's trajectories is at or below this (m).
    pub target_distance: f64,
}

impl Default for P4PusherSettings {
    fn default() -> Self {
        Self {
            local: LocalConfig::default(),
            cost: PusherCost::default(),
            target_distance: 0.1,
        }
    }
}

impl P4PusherSettings {
    /// The `--quick` settings: 3 iterations of 4 trajectories.
    pub fn quick() -> Self {
        let mut s = Self::default();
        s.local.iterations = 3;
        s.local.samples = 4;
        s
    }

    fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| CliError::input(what, m);
        self.local.validate().map_err(|e| bad(e.to_string()))?;
        self.cost.validate().map_err(bad)?;
        // Fails early without the `mujoco` feature (or without the scene), before any directory.
        pusher_problem(self.cost).map_err(|e| bad(e.to_string()))?;
        if !(self.target_distance.is_finite() && self.target_distance > 0.0) {
            return Err(bad(format!(
                "target_distance {} must be finite and > 0",
                self.target_distance
            )));
        }
        Ok(())
    }
}

/// What a finished run leaves.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LocalRecord {
    /// `lqr_flm`, `pi2` or `pilqr`.
    pub method: String,
    /// The seed.
    pub seed: u64,
    /// Per condition, one point per iteration (samples of that condition, mean cost, mean final
    /// block–goal distance of the iteration's trajectories).
    pub curves: Vec<Vec<LocalPoint>>,
    /// Per condition, updates that failed numerically (the controller was kept).
    pub failed_updates: Vec<usize>,
    /// Samples over all conditions.
    pub samples: u64,
    /// Wall time of the run, seconds.
    pub wall_seconds: f64,
}

/// The p4 pusher study.
pub struct P4PusherStudy;

impl Study for P4PusherStudy {
    type Settings = P4PusherSettings;
    type Record = LocalRecord;

    fn name(&self) -> &str {
        "p4-pusher"
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<P4PusherSettings> {
        let base = if quick {
            P4PusherSettings::quick()
        } else {
            P4PusherSettings::default()
        };
        let s = harness::read_overrides(base, config)?;
        let what = config.map_or("settings".to_string(), |p| {
            format!("--config {}", p.display())
        });
        s.validate(&what)?;
        Ok(s)
    }

    fn jobs(&self, _s: &P4PusherSettings) -> Vec<Vec<String>> {
        LocalMethod::ALL
            .iter()
            .map(|m| vec![m.name().to_string()])
            .collect()
    }

    fn length(&self, s: &P4PusherSettings, _run: &str) -> u64 {
        (s.local.iterations * s.local.samples * PUSHER_CONDITIONS.len()) as u64
    }

    fn run(
        &self,
        s: &P4PusherSettings,
        run_name: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<LocalRecord, JobError> {
        let method = LocalMethod::from_name(run_name)
            .ok_or_else(|| JobError::Failed(format!("unknown run {run_name}")))?;
        let problem = pusher_problem(s.cost)?;
        let start = std::time::Instant::now();
        let run = train_local(method, &problem, &s.local, seed, store, progress)?;
        Ok(LocalRecord {
            method: run_name.into(),
            seed,
            curves: run.curves,
            failed_updates: run.failed_updates,
            samples: self.length(s, run_name),
            wall_seconds: start.elapsed().as_secs_f64(),
        })
    }

    fn curve(&self, r: &LocalRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        let header = vec![
            "samples_per_condition",
            "distance_c0",
            "distance_c1",
            "distance_c2",
            "distance_c3",
        ];
        let iterations = r.curves.first().map_or(0, Vec::len);
        let rows = (0..iterations)
            .map(|i| {
                let mut row = vec![r.curves[0][i].samples as f64];
                row.extend(r.curves.iter().map(|c| c[i].measure));
                row
            })
            .collect();
        (header, rows)
    }

    fn report_files(&self) -> &'static [&'static str] {
        &["table.json", "table.md", "fig3.svg"]
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &P4PusherSettings,
        records: &[LocalRecord],
        wall: f64,
    ) -> Result<String> {
        let table = P4Table::new(s, records);
        let json = to_json_pretty(&table).map_err(|e| CliError::Other(e.to_string()))?;
        harness::write(dir, "table.json", &json)?;
        let md = table.markdown(s, records, wall);
        harness::write(dir, "table.md", &md)?;
        let curves = LocalMethod::ALL
            .iter()
            .filter_map(|m| {
                let seeds: Vec<Vec<(u64, f64)>> = records
                    .iter()
                    .filter(|r| r.method == m.name())
                    .map(|r| {
                        r.curves[PUSHER_HARD]
                            .iter()
                            .map(|p| (p.samples, p.measure))
                            .collect()
                    })
                    .collect();
                (!seeds.is_empty()).then(|| Curve::mean_over_seeds(m.name(), &seeds))
            })
            .collect();
        let fig = Figure {
            title: format!(
                "p4 Fig. 3: gripper pusher, hard condition (block at {:?}, goal at {:?})",
                PUSHER_CONDITIONS[PUSHER_HARD].block, PUSHER_CONDITIONS[PUSHER_HARD].goal
            ),
            x_label: "samples (trajectories of this condition)".into(),
            y_label: "final block-goal distance (m)".into(),
            curves,
        };
        harness::write(dir, "fig3.svg", &fig.svg())?;
        Ok(md)
    }
}

/// Mean, standard error and per-seed values of a figure.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SeedFigure {
    /// Mean over seeds.
    pub mean: f64,
    /// Standard error of the mean.
    pub stderr: f64,
    /// One value per seed, in seed order.
    pub per_seed: Vec<f64>,
}

impl SeedFigure {
    fn new(per_seed: Vec<f64>) -> Self {
        let (mean, stderr) = mean_stderr(&per_seed);
        Self {
            mean,
            stderr,
            per_seed,
        }
    }
}

/// One condition's figures for one method.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConditionFigures {
    /// The block's start and the goal.
    pub block: [f64; 2],
    /// The goal.
    pub goal: [f64; 2],
    /// Final block–goal distance (the last iteration's mean).
    #[serde(rename = "final")]
    pub final_distance: SeedFigure,
    /// Seeds whose final distance is at or below the target.
    pub solved: usize,
}

/// One method's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct P4MethodFigures {
    /// Samples of the hard condition until an iteration's mean final distance was at or below the
    /// target (`null` per seed where it never was).
    pub samples_to_target: SamplesToTarget,
    /// The hard condition's final distance.
    #[serde(rename = "final")]
    pub final_distance: SeedFigure,
    /// Per condition.
    pub conditions: Vec<ConditionFigures>,
    /// Conditions solved on every seed.
    pub conditions_solved_on_all_seeds: usize,
    /// Seeds.
    pub seeds: Vec<u64>,
}

/// `table.json` of a p4 pusher study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct P4Table {
    /// The hard condition's index.
    pub hard_condition: usize,
    /// The target distance (m).
    pub target_distance: f64,
    /// Samples per condition (iterations × trajectories per iteration).
    pub samples_per_condition: u64,
    /// Per method key.
    pub methods: BTreeMap<String, P4MethodFigures>,
}

impl P4Table {
    fn new(s: &P4PusherSettings, records: &[LocalRecord]) -> Self {
        let budget = (s.local.iterations * s.local.samples) as u64;
        let target = s.target_distance;
        let mut methods = BTreeMap::new();
        for m in LocalMethod::ALL {
            let runs: Vec<&LocalRecord> = records.iter().filter(|r| r.method == m.name()).collect();
            if runs.is_empty() {
                continue;
            }
            let last =
                |r: &LocalRecord, c: usize| r.curves[c].last().map_or(f64::NAN, |p| p.measure);
            let conditions: Vec<ConditionFigures> = PUSHER_CONDITIONS
                .iter()
                .enumerate()
                .map(|(c, cond)| {
                    let finals: Vec<f64> = runs.iter().map(|r| last(r, c)).collect();
                    ConditionFigures {
                        block: cond.block,
                        goal: cond.goal,
                        solved: finals.iter().filter(|d| **d <= target).count(),
                        final_distance: SeedFigure::new(finals),
                    }
                })
                .collect();
            let reached = runs
                .iter()
                .map(|r| {
                    r.curves[PUSHER_HARD]
                        .iter()
                        .find(|p| p.measure <= target)
                        .map(|p| p.samples)
                })
                .collect();
            methods.insert(
                m.name().to_string(),
                P4MethodFigures {
                    samples_to_target: SamplesToTarget::from_seeds(target, reached, budget),
                    final_distance: SeedFigure::new(
                        runs.iter().map(|r| last(r, PUSHER_HARD)).collect(),
                    ),
                    conditions_solved_on_all_seeds: conditions
                        .iter()
                        .filter(|c| c.solved == runs.len())
                        .count(),
                    conditions,
                    seeds: runs.iter().map(|r| r.seed).collect(),
                },
            );
        }
        Self {
            hard_condition: PUSHER_HARD,
            target_distance: target,
            samples_per_condition: budget,
            methods,
        }
    }

    fn markdown(&self, s: &P4PusherSettings, records: &[LocalRecord], wall: f64) -> String {
        let label = |k: &str| match k {
            "lqr_flm" => "LQR-FLM",
            "pi2" => "PI²",
            _ => "PILQR",
        };
        let seeds = self
            .methods
            .values()
            .map(|m| m.seeds.len())
            .max()
            .unwrap_or(0);
        let mut md = format!(
            "# p4 gripper pusher ({seeds} seeds)\n\nOne time-varying linear-Gaussian controller per \
             condition, {} iterations of {} trajectories each ({} samples per condition; every \
             trajectory counted, no other rollouts). Distances are the mean final block–goal \
             distance of an iteration's trajectories; a condition is solved at or below {} m. \
             Mean ± standard error over seeds.\n\n",
            s.local.iterations, s.local.samples, self.samples_per_condition, self.target_distance
        );
        md.push_str(&format!(
            "## Hard condition (p4 Fig. 3): block at {:?}, goal at {:?}\n\n| method | final distance (m) | samples to {} m | seeds that reached it |\n|---|---|---|---|\n",
            PUSHER_CONDITIONS[PUSHER_HARD].block,
            PUSHER_CONDITIONS[PUSHER_HARD].goal,
            self.target_distance
        ));
        for (k, m) in &self.methods {
            let t = &m.samples_to_target;
            md.push_str(&format!(
                "| {} | {:.3} ± {:.3} | {} | {}/{} |\n",
                label(k),
                m.final_distance.mean,
                m.final_distance.stderr,
                t.mean.map_or("—".into(), |v| format!("{v:.0}")),
                t.reached,
                t.seeds
            ));
        }
        md.push_str("\n## Every condition: final distance (m), seeds solved\n\n| method |");
        for (c, cond) in PUSHER_CONDITIONS.iter().enumerate() {
            md.push_str(&format!(" c{c} {:?}→{:?} |", cond.block, cond.goal));
        }
        md.push_str(" solved on all seeds |\n|---|");
        md.push_str(&"---|".repeat(PUSHER_CONDITIONS.len() + 1));
        md.push('\n');
        for (k, m) in &self.methods {
            md.push_str(&format!("| {} |", label(k)));
            for c in &m.conditions {
                md.push_str(&format!(
                    " {:.3} ± {:.3}, {}/{} |",
                    c.final_distance.mean,
                    c.final_distance.stderr,
                    c.solved,
                    m.seeds.len()
                ));
            }
            md.push_str(&format!(" {}/4 |\n", m.conditions_solved_on_all_seeds));
        }
        let failed: usize = records.iter().flat_map(|r| &r.failed_updates).sum();
        let run_wall: f64 = records.iter().map(|r| r.wall_seconds).sum();
        md.push_str(&format!(
            "\nLQR-FLM: base KL bound {} per step with GPS's step rule for LQR-FLM; PI²: KL {}, \
             covariance damping {}, gains {}; PILQR: the same LQR-FLM and PI² stages, per-step \
             bounds from the residual ratio ({} / {}). Initial controllers `K = 0, k = 0, Σ = {} I`. \
             Updates that failed numerically (controller kept): {failed}. Runs took {run_wall:.0} s \
             in all; the study's wall time {wall:.0} s.\n",
            s.local.trajopt.lqr.kl_step,
            s.local.trajopt.pi2.kl_step,
            s.local.trajopt.pi2.covariance_damping,
            if s.local.trajopt.pi2.update_gains { "refitted" } else { "kept" },
            s.local.trajopt.res_ratio_dec,
            s.local.trajopt.res_ratio_inc,
            s.local.init_variance,
        ));
        md
    }
}
