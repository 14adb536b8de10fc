//! `tandem reproduce p0-pendulum` and `tandem reproduce p0-leo`: p0's three methods (cold start,
//! warm start, difference model) over seeds, through one pipeline ([`tandem_algos::difference_models`])
//! on either problem. In the output directory:
//!
//! - `config.json`: the [`P0Config`] used, seeds, status (`running`, `interrupted`, `complete`)
//!   and wall time;
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's learning curve (return of
//!   the deterministic policy on the true system against true training samples); for Leo the
//!   record also holds its first and last policy's episode (return, walked distance, work per
//!   metre, frames of the gait);
//! - `table.md`, `table.json`: p0's Table II (pendulum) or Table IV (Leo): the return at the
//!   fixed budget and the true samples to the fixed target return, a typed
//!   [`crate::report::Table`] rendered by the shared report code with p0's words;
//! - pendulum: `fig5.svg`, p0's Fig. 5 (mean return on the true system against true samples,
//!   ± standard error across seeds);
//! - Leo: `fig8.svg` (p0's Fig. 8, the same plot), `table3.json` and a Table III section in
//!   `table.md` (return, walked distance `L` and work per metre `E` of `μ^idl`, `μ^d` and
//!   `μ^true` on the true system), and `gait.svg`, the first seed's three gaits.
//!
//! With [`P0Config::small_batch`] set (the pendulum's default: 400, one episode), the difference
//! method also runs with that batch (`difference_small_batch`), so that its sample counts are
//! not quantized at 3750.
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

use std::collections::BTreeMap;
use std::path::Path;

use crate::report::gait::{filmstrip_svg, GaitRow};
use crate::report::{
    mean_stderr, Comparison, Figure, MarkdownText, MethodFigures, Reference, SeedRun, Table,
};
use crate::run::RunDir;
use serde::{Deserialize, Serialize};
use tandem_algos::difference_models::{
    ddpg_agent, leo_problem, pendulum_problem, run_seed, Method, P0Config, PolicyEval, RunRecord,
    SimToReal, Tick, LEO_MEASURES,
};
use tandem_algos::Checkpoints;
use tandem_dynamics::rigid_plant::{Overrides, RigidPlantConfig};
use tandem_robots::leo::{leo_plant, skeleton};

use crate::harness::{self, JobError, Study};
use crate::{Error, IoOp, Result};
use tandem_nn::budget::MemoryEstimate;

/// The problem a p0 study runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum P0Task {
    /// The DC-motor pendulum (p0 §IV-A): Table II, Fig. 5.
    Pendulum,
    /// The Leo-like biped (p0 §IV-B): Tables III and IV, Fig. 8.
    Leo,
}

/// A p0 study: per seed, the cold start, and the warm start with the difference method(s) (one
/// job: they share the pre-trained agent).
pub struct P0Study(pub P0Task);

/// The `--quick` configuration: the same loop with small networks and budgets, for smoke tests.
pub fn quick_config() -> P0Config {
    let mut c = P0Config::default().with_networks(QUICK_HIDDEN, QUICK_BUFFER);
    c.pretrain_steps = 800;
    c.real_batch = 400;
    c.real_budget = 800;
    c.baseline_max_samples = 1200;
    c.eval_interval = 400;
    c.model_steps = 400;
    c.fit.epochs = 3;
    c
}

/// The `--quick` configuration of `p0-leo`: Leo's settings with small networks and budgets.
pub fn leo_quick_config() -> P0Config {
    let mut c = P0Config::leo().with_networks(QUICK_HIDDEN, QUICK_BUFFER);
    c.pretrain_steps = 700;
    c.real_batch = 700;
    c.real_budget = 1400;
    c.baseline_max_samples = 1400;
    c.eval_interval = 700;
    c.model_steps = 300;
    c.fit.epochs = 2;
    // Leo's warm-up of 20 000 transitions would leave pre-training and cold start without updates.
    c.ddpg.learning_starts = 300;
    c
}

/// The `--quick` networks: 32×32 actor, critic and difference network.
const QUICK_HIDDEN: &[usize] = &[32, 32];
/// The `--quick` replay buffer.
const QUICK_BUFFER: usize = 10_000;

/// Applies the overrides in `text` (a `--config` file, named `what` in errors) to `base` and
/// validates the result.
pub fn parse_config(base: P0Config, text: &str, what: &str) -> Result<P0Config> {
    let cfg = harness::override_settings(&base, text, what)?;
    checked(cfg, what)
}

/// `cfg` if valid, else an error naming `what`.
fn checked(cfg: P0Config, what: &str) -> Result<P0Config> {
    cfg.validate()
        .map_err(|e| Error::input(what, e.to_string()))?;
    Ok(cfg)
}

/// p0's methods as the table names them, in row order.
const LABELS: &[(&str, &str)] = &[
    ("cold", "Cold start"),
    ("warm", "Warm start"),
    ("difference", "Difference model"),
    ("difference_small_batch", "Difference model, small batch"),
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
    // Cold and warm start over each difference method (the batch of p0 first: the Markdown
    // sentence names the first comparison of each baseline).
    for &(d, d_mean, d_short) in used.iter().filter(|x| x.0.is_difference()) {
        for &(b, b_mean, b_short) in used.iter().filter(|x| !x.0.is_difference()) {
            t.comparisons.push(Comparison::new(
                (b.name(), b_mean, b_short),
                (d.name(), d_mean, d_short),
                RATIO_NOTE,
            ));
        }
    }
    t
}

/// Table II (pendulum) or Table IV (Leo) as Markdown: the shared rendering with p0's words;
/// `wall` is the run's wall time.
pub fn markdown(task: P0Task, t: &Table, cfg: &P0Config, wall: f64) -> String {
    let n_seeds = t.methods.values().map(|m| m.seeds.len()).max().unwrap_or(0);
    let (title, intro) = match task {
        P0Task::Pendulum => (
            format!("p0 Table II on the DC-motor pendulum ({n_seeds} seeds)"),
            "Return of the deterministic policy on the true system (undiscounted, one \
             400-step episode from (π, 0)). True samples are training samples on the true \
             system, counted exactly; evaluation episodes are not counted. Mean ± standard \
             error over seeds.",
        ),
        P0Task::Leo => (
            format!("p0 Table IV on the Leo-like biped ({n_seeds} seeds)"),
            "Return of the deterministic policy on the true biped (undiscounted, one 20 s \
             episode of 667 steps from mid-step). True samples are training samples on the \
             true biped, counted exactly; evaluation episodes are not counted. Mean ± standard \
             error over seeds.",
        ),
    };
    let mut text = MarkdownText {
        title,
        intro: intro.into(),
        labels: LABELS,
        comparison_intro: "True samples to the target relative to the difference method (means \
                           over seeds; a seed that never reached it counts at the samples it \
                           used)"
            .into(),
        comparison_order: &["warm", "cold"],
        closing: Vec::new(),
    };
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
    // The sentence under the table names each baseline's first comparison (with p0's batch);
    // those with the small batch get their own.
    let small = Method::DifferenceSmallBatch.name();
    let small_ratios: Vec<String> = text
        .comparison_order
        .iter()
        .filter_map(|b| {
            t.comparisons
                .iter()
                .find(|c| c.baseline == *b && c.method == small)?
                .ratio_text(text.label(b))
        })
        .collect();
    if let (Some(b), false) = (cfg.small_batch, small_ratios.is_empty()) {
        closing.push(format!(
            "Relative to the difference method with a batch of {b} true samples: {}.",
            small_ratios.join(", ")
        ));
    }
    let small_sentence = match cfg.small_batch {
        Some(b) => format!(", and with a batch of {b} after each of its updates"),
        None => String::new(),
    };
    closing.push(format!(
        "Cold and warm runs are evaluated every {} true samples; warm runs stop once they have \
         reached the target and used the budget ({}), cold runs use all {} true samples; the \
         difference method is evaluated after each model update ({} true samples each, {} in \
         all){small_sentence}. Wall time {wall:.0} s.",
        cfg.eval_interval,
        cfg.baseline_stop_early,
        cfg.baseline_max_samples,
        cfg.real_batch,
        cfg.real_budget,
    ));
    text.closing = closing;
    t.markdown(&text)
}

/// Fig. 5 (pendulum) or Fig. 8 (Leo): the mean return on the true system against true samples,
/// per method, with ± standard error bands over the seeds that have a point at that sample
/// count.
pub fn figure(task: P0Task, records: &[RunRecord]) -> Figure {
    let names = Method::ALL.map(Method::name);
    let curves = harness::mean_curves(records, &names, |r| (r.method.name(), &r.curve));
    let title = match task {
        P0Task::Pendulum => "p0 Fig. 5: DC-motor pendulum, policies evaluated on the true system",
        P0Task::Leo => "p0 Fig. 8: Leo-like biped, policies evaluated on the true biped",
    };
    Figure {
        title: title.into(),
        x_label: "true-system training samples".into(),
        y_label: "return on the true system".into(),
        curves,
    }
}

/// Mean, standard error and per-seed values of one figure of Table III; a seed without the
/// figure (no forward walking, so no work per metre) is `null` and left out of the mean.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// Mean over the seeds that have the figure (`null` if none has).
    pub mean: Option<f64>,
    /// Standard error of that mean.
    pub stderr: Option<f64>,
    /// Per seed, in seed order.
    pub per_seed: Vec<Option<f64>>,
}

impl Figures {
    fn of(per_seed: Vec<Option<f64>>) -> Self {
        let have: Vec<f64> = per_seed.iter().flatten().copied().collect();
        let (mean, stderr) = if have.is_empty() {
            (None, None)
        } else {
            let (m, s) = mean_stderr(&have);
            (Some(m), Some(s))
        };
        Self {
            mean,
            stderr,
            per_seed,
        }
    }
}

/// One policy's row of Table III.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyRow {
    /// Where the policy comes from.
    pub policy: String,
    /// The seeds.
    pub seeds: Vec<u64>,
    /// Return of its episode on the true biped.
    #[serde(rename = "return")]
    pub eval_return: Figures,
    /// Walked distance `L` (m).
    pub distance_m: Figures,
    /// Electrical work per metre walked `E` (J/m).
    pub work_per_metre_j: Figures,
    /// Seeds whose episode ended in a fall.
    pub falls: usize,
}

/// The three policies of Table III: `μ^idl` (the pre-trained policy, from the warm start's
/// records), `μ^d` (the difference method's last policy) and `μ^true` (the cold start's last
/// policy, trained on the true biped with all its samples). Keys `mu_idl`, `mu_d`, `mu_true`.
pub fn table3(records: &[RunRecord]) -> BTreeMap<String, PolicyRow> {
    // (key, where it comes from, the run, whether it is the run's first policy or its last)
    let pick = [
        (
            "mu_idl",
            "pre-trained on the idealized biped (warm start's first policy)",
            Method::Warm,
            true,
        ),
        (
            "mu_d",
            "difference method after its last model update",
            Method::Difference,
            false,
        ),
        (
            "mu_true",
            "cold start after all its true samples",
            Method::Cold,
            false,
        ),
    ];
    let mut out = BTreeMap::new();
    for (key, what, method, first) in pick {
        let evals: Vec<(u64, &PolicyEval)> = records
            .iter()
            .filter(|r| r.method == method)
            .filter_map(|r| {
                let e = if first { &r.start } else { &r.last };
                Some((r.seed, e.as_ref()?))
            })
            .collect();
        if evals.is_empty() {
            continue;
        }
        let measure = |k: &str| -> Vec<Option<f64>> {
            evals
                .iter()
                .map(|(_, e)| e.measures.get(k).copied().filter(|v| v.is_finite()))
                .collect()
        };
        let row = PolicyRow {
            policy: what.into(),
            seeds: evals.iter().map(|(s, _)| *s).collect(),
            eval_return: Figures::of(evals.iter().map(|(_, e)| Some(e.eval_return)).collect()),
            distance_m: Figures::of(measure(LEO_MEASURES[0])),
            work_per_metre_j: Figures::of(measure(LEO_MEASURES[1])),
            falls: measure(LEO_MEASURES[3])
                .iter()
                .filter(|f| f.is_some_and(|f| f > 0.5))
                .count(),
        };
        out.insert(key.to_string(), row);
    }
    out
}

/// Table III as a Markdown section.
pub fn table3_markdown(rows: &BTreeMap<String, PolicyRow>) -> String {
    let cell = |f: &Figures, digits: usize| match (f.mean, f.stderr) {
        (Some(m), Some(s)) => {
            let missing = f.per_seed.iter().filter(|v| v.is_none()).count();
            let note = if missing > 0 {
                format!(" ({missing} seed(s) without)")
            } else {
                String::new()
            };
            format!("{m:.digits$} ± {s:.digits$}{note}")
        }
        _ => "n/a".to_string(),
    };
    let mut s = String::from(
        "\n## p0 Table III: the policies on the true biped\n\nOne deterministic 20 s episode \
         per seed. L: forward distance of the torso (m); E: the six motors' electrical work \
         divided by L (J/m). Mean ± standard error over seeds.\n\n\
         | Policy | Return | L (m) | E (J/m) | Falls |\n|---|---|---|---|---|\n",
    );
    for (key, label) in [
        ("mu_idl", "μ^idl (idealized)"),
        ("mu_d", "μ^d (difference)"),
        ("mu_true", "μ^true (true)"),
    ] {
        if let Some(r) = rows.get(key) {
            s.push_str(&format!(
                "| {label} | {} | {} | {} | {}/{} |\n",
                cell(&r.eval_return, 1),
                cell(&r.distance_m, 2),
                cell(&r.work_per_metre_j, 1),
                r.falls,
                r.seeds.len()
            ));
        }
    }
    s
}

/// `gait.svg`: the first seed's `μ^idl`, `μ^d` and `μ^true` on the true biped, a figure every
/// 0.3 s over the first 6 s of their episodes.
pub fn gait_svg(records: &[RunRecord]) -> Result<String> {
    let plant = leo_plant(RigidPlantConfig::default(), &Overrides::default())
        .map_err(|e| Error::Other(format!("gait.svg: {e}")))?;
    let Some(seed) = records.iter().map(|r| r.seed).min() else {
        return Ok(filmstrip_svg("no runs", &[]));
    };
    let find = |m: Method| records.iter().find(|r| r.seed == seed && r.method == m);
    let picks = [
        ("μ^idl", find(Method::Warm).and_then(|r| r.start.as_ref())),
        (
            "μ^d",
            find(Method::Difference).and_then(|r| r.last.as_ref()),
        ),
        ("μ^true", find(Method::Cold).and_then(|r| r.last.as_ref())),
    ];
    let mut rows = Vec::new();
    for (name, eval) in picks {
        let Some(e) = eval else { continue };
        // Frames every `frame_every` steps of 30 ms: keep one every 0.3 s up to 6 s.
        let stride = (10 / e.frame_every.max(1)).max(1);
        let upto = 200 / e.frame_every.max(1);
        let frames = e
            .frames
            .iter()
            .take(upto + 1)
            .step_by(stride)
            .map(|q| skeleton(plant.model(), q))
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| Error::Other(format!("gait.svg: {e}")))?;
        let m = |k: &str| e.measures.get(k).copied();
        let work = m(LEO_MEASURES[1]).map_or("n/a".into(), |w| format!("{w:.0} J/m"));
        rows.push(GaitRow {
            label: format!(
                "{name}: return {:.0}, L {:.2} m, E {work}{}",
                e.eval_return,
                m(LEO_MEASURES[0]).unwrap_or(f64::NAN),
                if m(LEO_MEASURES[3]).is_some_and(|f| f > 0.5) {
                    ", fell"
                } else {
                    ""
                }
            ),
            frames,
        });
    }
    Ok(filmstrip_svg(
        &format!("Leo-like biped on the true model, seed {seed}: the first 6 s, every 0.3 s"),
        &rows,
    ))
}

/// Runs `run` of `problem` for `seed` (the harness's job body, for either problem).
fn run_problem<P, T, F>(
    problem: &SimToReal<P, T, F>,
    cfg: &P0Config,
    run: &str,
    seed: u64,
    store: &mut dyn Checkpoints,
    progress: &mut dyn FnMut(u64),
) -> std::result::Result<RunRecord, JobError>
where
    P: tandem_dynamics::Plant + Clone,
    T: tandem_envs::Task + Clone,
    F: Fn() -> std::result::Result<Box<dyn tandem_envs::Env>, tandem_envs::EnvError>,
{
    let m = Method::from_name(run).ok_or_else(|| JobError::Failed(format!("unknown run {run}")))?;
    let mut records = run_seed(
        problem,
        cfg,
        &[m],
        seed,
        &|m, s| ddpg_agent(cfg, &problem.real.task, m, s),
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

impl Study for P0Study {
    type Settings = P0Config;
    type Record = RunRecord;

    fn name(&self) -> &str {
        match self.0 {
            P0Task::Pendulum => "p0-pendulum",
            P0Task::Leo => "p0-leo",
        }
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<P0Config> {
        let base = match (self.0, quick) {
            (P0Task::Pendulum, false) => P0Config::default(),
            (P0Task::Pendulum, true) => quick_config(),
            (P0Task::Leo, false) => P0Config::leo(),
            (P0Task::Leo, true) => leo_quick_config(),
        };
        let Some(path) = config else { return Ok(base) };
        let text = tandem_core::read_file_capped(path, tandem_core::MAX_CONFIG_BYTES)
            .map_err(|source| Error::io(IoOp::Read, path, source))?;
        parse_config(base, &text, &format!("--config {}", path.display()))
    }

    fn jobs(&self, cfg: &P0Config, _seed: u64) -> Vec<Vec<String>> {
        let pretrained = cfg
            .methods()
            .into_iter()
            .filter(|&m| m != Method::Cold)
            .map(|m| m.name().to_string())
            .collect();
        vec![pretrained, vec![Method::Cold.name().to_string()]]
    }

    fn memory(&self, cfg: &P0Config, _run: &str) -> Result<MemoryEstimate> {
        let env = match self.0 {
            P0Task::Pendulum => (pendulum_problem().real.env)(),
            P0Task::Leo => (leo_problem().map_err(Error::other)?.real.env)(),
        }?;
        let sd = env.observation_space().flat_dim();
        let ad = env.action_space().flat_dim();
        Ok(cfg.memory(sd, ad))
    }

    fn length(&self, cfg: &P0Config, run: &str) -> u64 {
        match Method::from_name(run) {
            Some(m) if m.is_difference() => cfg.real_budget,
            _ => cfg.baseline_max_samples,
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
        match self.0 {
            P0Task::Pendulum => run_problem(&pendulum_problem(), cfg, run, seed, store, progress),
            P0Task::Leo => {
                let problem = leo_problem().map_err(|e| JobError::Failed(e.to_string()))?;
                run_problem(&problem, cfg, run, seed, store, progress)
            }
        }
    }

    fn curve(&self, r: &RunRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        harness::curve_rows("true_samples", &r.curve)
    }

    fn report_files(&self) -> &'static [&'static str] {
        match self.0 {
            P0Task::Pendulum => &["table.json", "table.md", "fig5.svg"],
            P0Task::Leo => &[
                "table.json",
                "table.md",
                "table3.json",
                "fig8.svg",
                "gait.svg",
            ],
        }
    }

    fn report(
        &self,
        dir: &RunDir,
        cfg: &P0Config,
        records: &[RunRecord],
        wall: f64,
    ) -> Result<String> {
        let table = table(records, cfg);
        let mut md = markdown(self.0, &table, cfg, wall);
        match self.0 {
            P0Task::Pendulum => {
                harness::write_table(dir, &table, &md)?;
                harness::write(dir, "fig5.svg", &figure(self.0, records).svg())?;
            }
            P0Task::Leo => {
                let t3 = table3(records);
                md.push_str(&table3_markdown(&t3));
                harness::write_table(dir, &table, &md)?;
                let json = crate::report::finite::to_json_pretty(&t3)
                    .map_err(|e| Error::Other(format!("table3.json: {e}")))?;
                harness::write(dir, "table3.json", &json)?;
                harness::write(dir, "fig8.svg", &figure(self.0, records).svg())?;
                harness::write(dir, "gait.svg", &gait_svg(records)?)?;
            }
        }
        Ok(md)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_core::CurvePoint;

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
            start: None,
            last: None,
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
        let md = markdown(P0Task::Pendulum, &t, &cfg, 1.0);
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

    /// The committed p0 results (`results/p0-pendulum/`), 5 seeds, 5078 s wall time.
    const COMMITTED_JSON: &str = include_str!("../../../results/p0-pendulum/table.json");
    const COMMITTED_MD: &str = include_str!("../../../results/p0-pendulum/table.md");

    #[test]
    fn the_committed_table_reads_back_and_renders_to_the_committed_files() {
        let t = Table::from_json(COMMITTED_JSON, "table.json").unwrap();
        assert_eq!(t.methods.len(), 4);
        assert_eq!(t.comparisons.len(), 4);
        assert_eq!(t.to_json().unwrap().trim_end(), COMMITTED_JSON.trim_end());
        // The footer's figures are P0Config's defaults, which the committed run used.
        let md = markdown(P0Task::Pendulum, &t, &P0Config::default(), 5078.0);
        assert_eq!(md, COMMITTED_MD);
        // A batch of one episode: the target after 400 true samples on every seed that needed
        // any (seed 4's pre-trained policy already reached it).
        let small = &t.methods["difference_small_batch"].samples_to_target;
        assert_eq!(
            small.per_seed,
            [Some(400), Some(400), Some(400), Some(400), Some(0)]
        );
    }
}
