//! `tandem reproduce p4-reacher`: p4 Fig. 4 (Chebotar et al., PILQR): neural-network policies for
//! gymnasium's reacher (MuJoCo), trained by MDGPS with LQR-FLM, PI² or PILQR as the local
//! optimizer and by DDPG, on the same seeds, measured by the mean final fingertip–target distance
//! of the deterministic policy on the same 300 random test targets, against real samples (time
//! steps) on a log axis. Through the shared [`crate::harness`] (separate processes per seed,
//! merge, resume).
//!
//! Writes, besides the harness' `config.json`, `runs/` and `state/`:
//!
//! - `table.md`, `table.json`: per method (`mdgps_lqr_flm`, `mdgps_pi2`, `mdgps_pilqr`, `ddpg`)
//!   the samples until the test distance reached the stated target (`samples_to_target`
//!   {target, mean, per_seed}) and the final test distance (`final` {mean, stderr, per_seed});
//!   and p4's comparison: the samples DDPG needs to reach MDGPS-PILQR's final mean distance, over
//!   the samples MDGPS-PILQR needs (`ddpg_over_mdgps_pilqr`);
//! - `fig4.svg`: the test distance against log₁₀ of the samples.
//!
//! MDGPS runs take minutes and checkpoint after every iteration ([`tandem_algos::mdgps::Mdgps`]);
//! DDPG checkpoints at every measurement. A resumed study continues an unfinished run from its
//! last checkpoint, with the numbers of an uninterrupted run.

use std::collections::BTreeMap;
use std::path::Path;

use crate::p4::Preset;
use crate::report::{to_json_pretty, Curve, Figure, SamplesToTarget};
use crate::run::RunDir;
use serde::{Deserialize, Serialize};
use tandem_algos::gps::LocalMethod;
use tandem_algos::manipulation::{
    reacher_config, reacher_problem, reacher_test_set, train_ddpg_reacher, ReacherDdpg,
    TestedPoint, REACHER_TEST_CONDITIONS, REACHER_TEST_SEED,
};
use tandem_algos::mdgps::{train_mdgps, MdgpsConfig};
use tandem_algos::Checkpoints;
use tandem_robots::p4::{ReacherCost, REACHER_HORIZON};

use crate::harness::{self, JobError, Study};
use crate::p4::{figure_row, SeedFigure};
use crate::{Error, Result};
use tandem_nn::budget::MemoryEstimate;

/// The methods, in the table's order.
pub const METHODS: [&str; 4] = ["mdgps_lqr_flm", "mdgps_pi2", "mdgps_pilqr", "ddpg"];

/// Everything that decides the study's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReacherSettings {
    /// MDGPS: the local controllers' loop and the global policy's regression.
    pub mdgps: MdgpsConfig,
    /// Training conditions (targets and arm starts from `Reacher-v5`'s reset distribution,
    /// drawn per seed).
    pub conditions: usize,
    /// DDPG: the agent, its step budget and measurement interval.
    pub ddpg: ReacherDdpg,
    /// Test starts (the same for every method and seed).
    pub test_conditions: usize,
    /// The generator of the test starts.
    pub test_seed: u64,
    /// The cost (DDPG's reward is its negative).
    pub cost: ReacherCost,
    /// The stated final distance (m) that `samples_to_target` counts samples to.
    pub target: f64,
}

impl Default for ReacherSettings {
    /// MDGPS with [`reacher_config`] on 24 training conditions; DDPG with [`ReacherDdpg`]'s
    /// defaults (50,000 steps measured every 2,500); 300 test targets; target 0.08 m.
    fn default() -> Self {
        Self {
            mdgps: reacher_config(),
            conditions: 24,
            ddpg: ReacherDdpg::default(),
            test_conditions: REACHER_TEST_CONDITIONS,
            test_seed: REACHER_TEST_SEED,
            cost: ReacherCost::default(),
            target: 0.08,
        }
    }
}

impl ReacherSettings {
    fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Error::input(what, m);
        self.mdgps.validate().map_err(|e| bad(e.to_string()))?;
        self.cost.validate().map_err(bad)?;
        self.ddpg.validate().map_err(|e| bad(e.to_string()))?;
        if self.conditions == 0 || self.test_conditions == 0 {
            return Err(bad("conditions and test_conditions must be positive".into()));
        }
        if self.mdgps_samples().is_none() {
            return Err(bad(format!(
                "mdgps.local.iterations {} x mdgps.local.samples {} x conditions {} x {} steps \
                 overflows",
                self.mdgps.local.iterations,
                self.mdgps.local.samples,
                self.conditions,
                REACHER_HORIZON
            )));
        }
        if !(self.target.is_finite() && self.target > 0.0) {
            return Err(bad(format!(
                "target {} must be finite and > 0",
                self.target
            )));
        }
        // Fails early without the `mujoco` feature (or without the assets), before any directory.
        reacher_problem(self.cost, 1, 0).map_err(|e| bad(e.to_string()))?;
        Ok(())
    }

    /// Real samples (time steps) of one MDGPS run.
    fn mdgps_samples(&self) -> Option<u64> {
        let l = &self.mdgps.local;
        let n = l
            .iterations
            .checked_mul(l.samples)?
            .checked_mul(self.conditions)?
            .checked_mul(REACHER_HORIZON)?;
        u64::try_from(n).ok()
    }

    /// Real samples (time steps) of one run of `method`.
    fn budget(&self, method: &str) -> u64 {
        if method == "ddpg" {
            self.ddpg.steps
        } else {
            // Checked by `validate`.
            self.mdgps_samples().unwrap_or(u64::MAX)
        }
    }
}

/// What a finished run leaves.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReacherRecord {
    /// One of [`METHODS`].
    pub method: String,
    /// The seed.
    pub seed: u64,
    /// The policy's mean final distance on the test targets against real samples (time steps).
    pub curve: Vec<TestedPoint>,
    /// MDGPS: the local controllers' mean final distance on their own samples, per iteration.
    pub local_measure: Vec<f64>,
    /// MDGPS: local updates that failed numerically (the controller was kept).
    pub failed_updates: usize,
    /// Wall time of the run, seconds (MDGPS: summed over every process that ran it; DDPG: of the
    /// last process).
    pub wall_seconds: f64,
}

impl ReacherRecord {
    /// Samples at the first point at or below `level`.
    fn samples_to(&self, level: f64) -> Option<u64> {
        self.curve
            .iter()
            .find(|p| p.test_measure <= level)
            .map(|p| p.samples)
    }

    fn final_measure(&self) -> f64 {
        self.curve.last().map_or(f64::NAN, |p| p.test_measure)
    }
}

/// The study, from a preset (`None`: the default, and a resumed run keeps what its
/// `config.json` records).
#[derive(Debug, Default)]
pub struct ReacherStudy {
    /// The settings it starts from.
    pub preset: Option<Preset>,
}

/// The authors' preset, TOML applied over [`ReacherSettings::default`] ([`Preset::Authors`]).
pub(crate) const AUTHORS: &str = include_str!("../presets/p4-reacher-authors.toml");

impl Study for ReacherStudy {
    type Settings = ReacherSettings;
    type Record = ReacherRecord;

    fn name(&self) -> &str {
        "p4-reacher"
    }

    fn default_seeds(&self) -> u64 {
        3
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<ReacherSettings> {
        let preset = self.preset.unwrap_or_default();
        let mut base = preset.apply(ReacherSettings::default(), AUTHORS, "p4-reacher")?;
        if quick {
            base.conditions = 2;
            base.mdgps.local.iterations = 2;
            base.mdgps.local.samples = 2;
            base.mdgps.policy.epochs = 5;
            base.test_conditions = 20;
            base.ddpg.steps = 400;
            base.ddpg.eval_every = 200;
            base.ddpg.agent.actor_hidden = vec![32, 32];
            base.ddpg.agent.critic_hidden = vec![32, 32];
            base.ddpg.agent.batch_size = 32;
        }
        let s = harness::read_overrides(base, config)?;
        let what = harness::settings_name(config);
        s.validate(&what)?;
        Ok(s)
    }

    fn overrides_settings(&self) -> bool {
        self.preset.is_some()
    }

    fn memory(&self, s: &ReacherSettings, run: &str) -> Result<MemoryEstimate> {
        let problem = reacher_problem(s.cost, 1, 0).map_err(Error::other)?;
        let (sd, ad) = (problem.system.state_dim(), problem.system.action_dim());
        let test = MemoryEstimate::new().f32s(
            "test_conditions (starts and final states)",
            &[4, s.test_conditions, sd],
        );
        Ok(if run == "ddpg" {
            test.with("ddpg.agent.", s.ddpg.agent.memory(sd, ad))
        } else {
            test.with(
                "mdgps.",
                s.mdgps.memory(s.conditions, problem.horizon, sd, ad, sd),
            )
        })
    }

    fn jobs(&self, _s: &ReacherSettings, _seed: u64) -> Vec<Vec<String>> {
        METHODS.iter().map(|m| vec![m.to_string()]).collect()
    }

    fn length(&self, s: &ReacherSettings, run: &str) -> u64 {
        s.budget(run)
    }

    fn run(
        &self,
        s: &ReacherSettings,
        run_name: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<ReacherRecord, JobError> {
        let test = reacher_test_set(s.test_conditions, s.test_seed);
        let (curve, local_measure, failed_updates, wall_seconds) = if run_name == "ddpg" {
            let start = std::time::Instant::now();
            let curve = train_ddpg_reacher(s.cost, &s.ddpg, &test, seed, store, progress)?;
            (curve, Vec::new(), 0, start.elapsed().as_secs_f64())
        } else {
            let method = run_name
                .strip_prefix("mdgps_")
                .and_then(LocalMethod::from_name)
                .ok_or_else(|| JobError::Failed(format!("unknown run {run_name}")))?;
            let problem = reacher_problem(s.cost, s.conditions, seed)?;
            let steps = REACHER_HORIZON as u64;
            let run = train_mdgps(
                method,
                &problem,
                &test,
                &s.mdgps,
                seed,
                store,
                &mut |episodes| progress(episodes * steps),
            )?;
            let curve = run
                .curve
                .iter()
                .map(|p| TestedPoint {
                    samples: p.samples * steps,
                    test_measure: p.test_measure,
                })
                .collect();
            let local = run.curve.iter().map(|p| p.local_measure).collect();
            (curve, local, run.failed_updates, run.wall_seconds)
        };
        Ok(ReacherRecord {
            method: run_name.into(),
            seed,
            curve,
            local_measure,
            failed_updates,
            wall_seconds,
        })
    }

    fn curve(&self, r: &ReacherRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        let rows = r
            .curve
            .iter()
            .map(|p| vec![p.samples as f64, p.test_measure])
            .collect();
        (vec!["samples", "test_distance"], rows)
    }

    fn report_files(&self) -> &'static [&'static str] {
        &["table.json", "table.md", "fig4.svg"]
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &ReacherSettings,
        records: &[ReacherRecord],
        wall: f64,
    ) -> Result<String> {
        let table = ReacherTable::new(s, records);
        let json = to_json_pretty(&table).map_err(|e| Error::Other(e.to_string()))?;
        harness::write(dir, "table.json", &json)?;
        let md = table.markdown(s, records, wall);
        harness::write(dir, "table.md", &md)?;
        let curves = METHODS
            .iter()
            .filter_map(|m| {
                let seeds: Vec<Vec<(u64, f64)>> = records
                    .iter()
                    .filter(|r| r.method == *m)
                    .map(|r| {
                        r.curve
                            .iter()
                            .map(|p| (p.samples, p.test_measure))
                            .collect()
                    })
                    .collect();
                (!seeds.is_empty()).then(|| {
                    // A log axis: log10 of the samples (the untrained policy at 0 left out).
                    let mut c = Curve::mean_over_seeds(m, &seeds);
                    c.points.retain(|p| p.x > 0.0);
                    for p in &mut c.points {
                        p.x = p.x.log10();
                    }
                    c
                })
            })
            .collect();
        let fig = Figure {
            title: format!(
                "p4-reacher: mean final distance on {} test targets",
                s.test_conditions
            ),
            x_label: "log10 samples (time steps)".into(),
            y_label: "final fingertip–target distance (m)".into(),
            curves,
        };
        harness::write(dir, "fig4.svg", &fig.svg())?;
        Ok(md)
    }
}

/// One method's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReacherMethodFigures {
    /// Samples (time steps) until the test distance was at or below the target (`null` per seed
    /// where it never was).
    pub samples_to_target: SamplesToTarget,
    /// The final test distance.
    #[serde(rename = "final")]
    pub final_measure: SeedFigure,
    /// Samples of a run.
    pub budget: u64,
    /// Seeds.
    pub seeds: Vec<u64>,
}

/// p4's comparison: the samples DDPG needs to reach MDGPS-PILQR's final mean distance, over the
/// samples MDGPS-PILQR needs to reach it (means over the seeds that reached it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SampleRatio {
    /// MDGPS-PILQR's final mean test distance (m).
    pub level: f64,
    /// MDGPS-PILQR's samples to that level.
    pub mdgps_pilqr: SamplesToTarget,
    /// DDPG's samples to that level.
    pub ddpg: SamplesToTarget,
    /// `ddpg.mean / mdgps_pilqr.mean` (`null` where either never reached it).
    pub ratio: Option<f64>,
}

/// `table.json` of `tandem reproduce p4-reacher`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReacherTable {
    /// The measure.
    pub measure: String,
    /// The stated target (m).
    pub target: f64,
    /// Test targets.
    pub test_conditions: usize,
    /// Per method key.
    pub methods: BTreeMap<String, ReacherMethodFigures>,
    /// p4's ratio (DDPG over MDGPS-PILQR), where both ran.
    pub ddpg_over_mdgps_pilqr: Option<SampleRatio>,
}

impl ReacherTable {
    fn new(s: &ReacherSettings, records: &[ReacherRecord]) -> Self {
        let runs =
            |m: &str| -> Vec<&ReacherRecord> { records.iter().filter(|r| r.method == m).collect() };
        let to = |runs: &[&ReacherRecord], level: f64, budget: u64| {
            SamplesToTarget::from_seeds(
                level,
                runs.iter().map(|r| r.samples_to(level)).collect(),
                budget,
            )
        };
        let mut methods = BTreeMap::new();
        for m in METHODS {
            let rs = runs(m);
            if rs.is_empty() {
                continue;
            }
            let budget = s.budget(m);
            methods.insert(
                m.to_string(),
                ReacherMethodFigures {
                    samples_to_target: to(&rs, s.target, budget),
                    final_measure: SeedFigure::new(rs.iter().map(|r| r.final_measure()).collect()),
                    budget,
                    seeds: rs.iter().map(|r| r.seed).collect(),
                },
            );
        }
        let ratio = match (methods.get("mdgps_pilqr"), methods.get("ddpg")) {
            (Some(p), Some(_)) if p.final_measure.mean.is_finite() => {
                let level = p.final_measure.mean;
                let pilqr = to(&runs("mdgps_pilqr"), level, s.budget("mdgps_pilqr"));
                let ddpg = to(&runs("ddpg"), level, s.budget("ddpg"));
                let ratio = match (ddpg.mean, pilqr.mean) {
                    (Some(d), Some(p)) if p > 0.0 => Some(d / p),
                    _ => None,
                };
                Some(SampleRatio {
                    level,
                    mdgps_pilqr: pilqr,
                    ddpg,
                    ratio,
                })
            }
            _ => None,
        };
        Self {
            measure: "mean final fingertip–target distance on the test targets (m)".into(),
            target: s.target,
            test_conditions: s.test_conditions,
            methods,
            ddpg_over_mdgps_pilqr: ratio,
        }
    }

    fn markdown(&self, s: &ReacherSettings, records: &[ReacherRecord], wall: f64) -> String {
        let label = |k: &str| match k {
            "mdgps_lqr_flm" => "MDGPS, LQR-FLM",
            "mdgps_pi2" => "MDGPS, PI²",
            "mdgps_pilqr" => "MDGPS, PILQR",
            _ => "DDPG",
        };
        let seeds = self
            .methods
            .values()
            .map(|m| m.seeds.len())
            .max()
            .unwrap_or(0);
        let l = &s.mdgps.local;
        let mut md = format!(
            "# p4-reacher ({seeds} seeds)\n\nNeural policies for gymnasium's reacher, measured by \
             the mean final fingertip–target distance of their deterministic actions on the same \
             {} random test targets. Samples are real time steps (50 per episode). MDGPS: {} \
             training conditions, {} iterations of {} trajectories each ({} samples); DDPG: {} \
             steps. Mean ± standard error over seeds.\n\n\
             | method | final distance | samples to {} m | seeds that reached it |\n|---|---|---|---|\n",
            self.test_conditions,
            s.conditions,
            l.iterations,
            l.samples,
            s.budget("mdgps"),
            s.ddpg.steps,
            self.target
        );
        for m in METHODS {
            let Some(f) = self.methods.get(m) else {
                continue;
            };
            md.push_str(&figure_row(
                label(m),
                &f.final_measure,
                &f.samples_to_target,
                4,
            ));
        }
        if let Some(r) = &self.ddpg_over_mdgps_pilqr {
            let show = |t: &SamplesToTarget| {
                t.mean.map_or(format!("not reached (0/{})", t.seeds), |v| {
                    format!("{v:.0} ({}/{} seeds)", t.reached, t.seeds)
                })
            };
            md.push_str(&format!(
                "\n**p4's comparison**: to MDGPS-PILQR's final mean distance {:.4} m, MDGPS-PILQR \
                 needs {} samples and DDPG {}: DDPG / MDGPS-PILQR = {} (p4: about 25).\n",
                r.level,
                show(&r.mdgps_pilqr),
                show(&r.ddpg),
                r.ratio.map_or("—".into(), |v| format!("{v:.2}"))
            ));
        }
        let failed: usize = records.iter().map(|r| r.failed_updates).sum();
        let run_wall: f64 = records.iter().map(|r| r.wall_seconds).sum();
        md.push_str(&format!(
            "\nMDGPS local updates that failed numerically (controller kept): {failed}. Runs took \
             {run_wall:.0} s in all; the study's wall time {wall:.0} s.\n"
        ));
        md
    }
}
