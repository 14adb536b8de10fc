//! `tandem reproduce`: whole-paper reproductions. `tandem reproduce p0-pendulum` runs p0's three
//! methods (cold start, warm start, difference model) over seeds on the DC-motor pendulum and
//! writes, in the output directory:
//!
//! - `config.json`: the [`P0Config`] used, seeds, and wall time;
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's learning curve (return of
//!   the deterministic policy on the true system against true training samples);
//! - `table.md`, `table.json`: p0's Table II (return at the fixed budget; true samples to the
//!   fixed target return);
//! - `fig5.svg`: p0's Fig. 5 (mean return on the true system against true samples, ± standard
//!   error across seeds).
//!
//! Evaluation episodes run on a separate copy of the true system and are not counted as training
//! samples.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use clap::{Args, Subcommand};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use serde_json::{json, Value};
use tandem::pipelines::p0::{
    ddpg_agent, pendulum_problem, run_seed, Method, P0Config, RunRecord, Tick,
};
use tandem::run::{csv, svg_chart, RunDir, Series};

use super::{CliError, Result};

/// The reproductions.
#[derive(Debug, Subcommand)]
pub enum ReproduceCommand {
    /// p0 (difference models) on the DC-motor pendulum: cold start, warm start and the
    /// difference-model method over seeds; Table II and Fig. 5.
    P0Pendulum(P0Args),
}

/// Arguments of `tandem reproduce p0-pendulum`.
#[derive(Debug, Args)]
pub struct P0Args {
    /// Number of seeds (0, 1, ..., N-1).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// Small smoke configuration (small networks, short budgets; numbers are meaningless).
    #[arg(long)]
    pub quick: bool,
    /// Output directory (default `runs/p0-pendulum__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Parallel jobs, one thread each (per seed, the cold start and the pre-trained pair of warm
    /// start and difference model are separate jobs).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// TOML file overriding fields of the configuration (`P0Config`; unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs a reproduction.
pub fn run(cmd: ReproduceCommand) -> Result<()> {
    match cmd {
        ReproduceCommand::P0Pendulum(args) => p0_pendulum(&args),
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

fn other(e: impl std::fmt::Display) -> CliError {
    CliError::other(e)
}

fn read_config(quick: bool, path: Option<&Path>) -> Result<P0Config> {
    let base = if quick {
        quick_config()
    } else {
        P0Config::default()
    };
    let Some(p) = path else { return Ok(base) };
    let text = std::fs::read_to_string(p).map_err(|source| CliError::Io {
        path: p.to_path_buf(),
        source,
    })?;
    parse_config(base, &text, &format!("--config {}", p.display()))
}

/// Applies the overrides in `text` (a `--config` file, named `what` in errors) to `base` and
/// validates the result.
pub fn parse_config(base: P0Config, text: &str, what: &str) -> Result<P0Config> {
    // Overrides on top of `base`: merge the file's table into the serialized base.
    let mut v = toml::Value::try_from(&base).map_err(other)?;
    let over: toml::Table =
        toml::from_str(text).map_err(|e| CliError::input(what, e.to_string()))?;
    merge(&mut v, toml::Value::Table(over));
    let cfg: P0Config = v
        .try_into()
        .map_err(|e: toml::de::Error| CliError::input(what, e.to_string()))?;
    cfg.validate()
        .map_err(|e| CliError::input(what, e.to_string()))?;
    Ok(cfg)
}

fn merge(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(b), toml::Value::Table(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(bv) if bv.is_table() && v.is_table() => merge(bv, v),
                    _ => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, o) => *b = o,
    }
}

/// Mean and standard error (sample standard deviation over √n; 0 for one value).
pub fn mean_stderr(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// Table II as JSON: per method `return_at_budget` {mean, stderr, per_seed} and
/// `samples_to_target` {mean over the seeds that reached it, per_seed with null where never
/// reached, reached, searched_up_to}.
pub fn table_json(records: &[RunRecord], cfg: &P0Config) -> Value {
    let mut out = serde_json::Map::new();
    // Per method: mean true samples to the target with a seed that never reached it counted at
    // the samples it used, whether any seed did so, and the mean return at the budget.
    let mut summary: Vec<(Method, f64, bool, f64)> = Vec::new();
    for m in Method::ALL {
        let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == m).collect();
        if runs.is_empty() {
            continue;
        }
        let ret: Vec<f64> = runs
            .iter()
            .map(|r| r.return_at(cfg.real_budget).unwrap_or(f64::NAN))
            .collect();
        let (mean, se) = mean_stderr(&ret);
        let to: Vec<Option<u64>> = runs
            .iter()
            .map(|r| r.samples_to(cfg.target_return))
            .collect();
        let reached: Vec<f64> = to.iter().flatten().map(|v| *v as f64).collect();
        let (tm, tse) = mean_stderr(&reached);
        let searched = runs.iter().map(|r| r.true_samples).max().unwrap_or(0);
        let used: Vec<f64> = runs
            .iter()
            .zip(&to)
            .map(|(r, t)| t.unwrap_or(r.true_samples) as f64)
            .collect();
        let used_mean = used.iter().sum::<f64>() / used.len() as f64;
        summary.push((m, used_mean, reached.len() < runs.len(), mean));
        out.insert(
            m.name().into(),
            json!({
                "return_at_budget": {"budget": cfg.real_budget, "mean": mean, "stderr": se, "per_seed": ret},
                "samples_to_target": {
                    "target": cfg.target_return,
                    "mean": if reached.is_empty() { Value::Null } else { json!(tm) },
                    "stderr": if reached.is_empty() { Value::Null } else { json!(tse) },
                    "per_seed": to,
                    "reached": reached.len(),
                    "seeds": runs.len(),
                    "searched_up_to": searched,
                },
                "seeds": runs.iter().map(|r| r.seed).collect::<Vec<_>>(),
            }),
        );
    }
    // μ^true: the cold start's converged return after all of its samples.
    let cold: Vec<&RunRecord> = records
        .iter()
        .filter(|r| r.method == Method::Cold)
        .collect();
    if !cold.is_empty() {
        let per_seed: Vec<f64> = cold
            .iter()
            .map(|r| r.final_return(cfg.reference_evals))
            .collect();
        let (mean, se) = mean_stderr(&per_seed);
        let gap = summary
            .iter()
            .find(|x| x.0 == Method::Difference)
            .map(|x| (x.3 - mean).abs() / mean.abs());
        out.insert(
            "reference".into(),
            json!({
                "what": "cold start after all its true samples: mean of its last evaluations",
                "true_samples": cold.iter().map(|r| r.true_samples).max().unwrap_or(0),
                "last_evaluations": cfg.reference_evals,
                "mean": mean,
                "stderr": se,
                "per_seed": per_seed,
                "difference_relative_gap": gap,
            }),
        );
    }
    // How many times more true samples a baseline needed than the difference method. A seed
    // that never reached the target counts with the samples it used, so the ratio is then a
    // lower bound.
    if let Some(&(_, d, d_bound, _)) = summary.iter().find(|x| x.0 == Method::Difference) {
        for &(m, b, b_bound, _) in summary.iter().filter(|x| x.0 != Method::Difference) {
            let ratio = if d > 0.0 { json!(b / d) } else { Value::Null };
            out.insert(
                format!("{}_over_difference", m.name()),
                json!({
                    "ratio": ratio,
                    "baseline_mean_samples": b,
                    "difference_mean_samples": d,
                    "lower_bound": b_bound && !d_bound,
                    "note": "per-seed samples to the target, a seed that never reached it counted at the samples it used",
                }),
            );
        }
    }
    Value::Object(out)
}

/// Table II as Markdown, from [`table_json`].
pub fn table_md(t: &Value, cfg: &P0Config, n_seeds: u64, wall: f64) -> String {
    let label = |m: &str| match m {
        "cold" => "Cold start",
        "warm" => "Warm start",
        _ => "Difference model",
    };
    let mut s = format!(
        "# p0 Table II on the DC-motor pendulum ({n_seeds} seeds)\n\n\
         Return of the deterministic policy on the true system (undiscounted, one 400-step episode \
         from (π, 0)). True samples are training samples on the true system, counted exactly; \
         evaluation episodes are not counted. Mean ± standard error over seeds.\n\n\
         | Method | Sample budget | Return |\n|---|---|---|\n"
    );
    s.push_str("| *Fixed budget* | | |\n");
    for m in ["cold", "warm", "difference"] {
        if let Some(v) = t.get(m) {
            let r = &v["return_at_budget"];
            s.push_str(&format!(
                "| {} | {} | {:.1} ± {:.1} |\n",
                label(m),
                cfg.real_budget,
                r["mean"].as_f64().unwrap_or(f64::NAN),
                r["stderr"].as_f64().unwrap_or(f64::NAN)
            ));
        }
    }
    s.push_str("| *Fixed return* | | |\n");
    for m in ["cold", "warm", "difference"] {
        if let Some(v) = t.get(m) {
            let r = &v["samples_to_target"];
            let reached = r["reached"].as_u64().unwrap_or(0);
            let seeds = r["seeds"].as_u64().unwrap_or(0);
            let cell = match r["mean"].as_f64() {
                Some(mean) => format!(
                    "{mean:.0} ± {:.0} ({reached}/{seeds} seeds reached it)",
                    r["stderr"].as_f64().unwrap_or(0.0)
                ),
                None => format!(
                    "> {} (no seed reached it)",
                    r["searched_up_to"].as_u64().unwrap_or(0)
                ),
            };
            s.push_str(&format!(
                "| {} | {cell} | {:.1} |\n",
                label(m),
                cfg.target_return
            ));
        }
    }
    let per_seed = |m: &str| -> Vec<String> {
        t.get(m)
            .and_then(|v| v["samples_to_target"]["per_seed"].as_array().cloned())
            .unwrap_or_default()
            .iter()
            .map(|x| x.as_u64().map_or("never".to_string(), |v| v.to_string()))
            .collect()
    };
    s.push_str("\nTrue samples to the target, per seed:\n\n");
    for m in ["cold", "warm", "difference"] {
        if t.get(m).is_some() {
            s.push_str(&format!("- {}: {}\n", label(m), per_seed(m).join(", ")));
        }
    }
    let ratios: Vec<String> = ["warm", "cold"]
        .iter()
        .filter_map(|m| {
            let r = t.get(format!("{m}_over_difference"))?;
            let x = r["ratio"].as_f64()?;
            let ge = if r["lower_bound"].as_bool() == Some(true) {
                "≥ "
            } else {
                ""
            };
            Some(format!("{} {ge}{x:.1}×", label(m)))
        })
        .collect();
    if !ratios.is_empty() {
        s.push_str(&format!(
            "\nTrue samples to the target relative to the difference method (means over seeds; a \
             seed that never reached it counts at the samples it used): {}.\n",
            ratios.join(", ")
        ));
    }
    if let Some(r) = t.get("reference") {
        s.push_str(&format!(
            "\nReference μ^true (cold start after {} true samples, mean of its last {} \
             evaluations): {:.1} ± {:.1}; the difference method at the budget is {} from it.\n",
            r["true_samples"].as_u64().unwrap_or(0),
            cfg.reference_evals,
            r["mean"].as_f64().unwrap_or(f64::NAN),
            r["stderr"].as_f64().unwrap_or(f64::NAN),
            r["difference_relative_gap"]
                .as_f64()
                .map_or("n/a".to_string(), |g| format!("{:.1} %", 100.0 * g)),
        ));
    }
    s.push_str(&format!(
        "\nCold and warm runs are evaluated every {} true samples; warm runs stop once they have \
         reached the target and used the budget ({}), cold runs use all {} true samples; the \
         difference method is evaluated after each model update ({} true samples each, {} in \
         all). Wall time {:.0} s.\n",
        cfg.eval_interval,
        cfg.baseline_stop_early,
        cfg.baseline_max_samples,
        cfg.real_batch,
        cfg.real_budget,
        wall
    ));
    s
}

/// Fig. 5: the mean return on the true system against true samples, per method, with ± standard
/// error bands over the seeds that have a point at that sample count.
pub fn fig5_svg(records: &[RunRecord]) -> String {
    let mut series = Vec::new();
    for m in Method::ALL {
        let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == m).collect();
        if runs.is_empty() {
            continue;
        }
        let mut xs: Vec<u64> = runs
            .iter()
            .flat_map(|r| r.curve.iter().map(|p| p.true_samples))
            .collect();
        xs.sort_unstable();
        xs.dedup();
        let mut points = Vec::new();
        let mut band = Vec::new();
        for x in xs {
            let ys: Vec<f64> = runs
                .iter()
                .filter_map(|r| r.curve.iter().find(|p| p.true_samples == x))
                .map(|p| p.eval_return)
                .collect();
            let (m, se) = mean_stderr(&ys);
            points.push((x as f64, m));
            band.push((x as f64, m - se, m + se));
        }
        series.push(Series {
            name: m.name().to_string(),
            points,
            band,
        });
    }
    svg_chart(
        "p0 Fig. 5: DC-motor pendulum, policies evaluated on the true system",
        "true-system training samples",
        "return on the true system",
        &series,
    )
}

/// One job's seed and its records (or its error).
type JobResult = (u64, std::result::Result<Vec<RunRecord>, String>);

fn p0_pendulum(args: &P0Args) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let cfg = read_config(args.quick, args.config.as_deref())?;
    cfg.validate().map_err(other)?;
    let dir = match &args.out {
        Some(p) => RunDir::create(Some(p), "", "", 0),
        None => {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0);
            let p =
                PathBuf::from("runs").join(format!("p0-pendulum__{}", tandem::run::utc_stamp(now)));
            RunDir::create(Some(&p), "", "", 0)
        }
    }
    .map_err(|source| CliError::Io {
        path: args.out.clone().unwrap_or_else(|| PathBuf::from("runs")),
        source,
    })?;
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |source| CliError::Io { path: p, source }
    };
    let start = Instant::now();
    let multi = MultiProgress::new();
    if args.quiet {
        multi.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let style =
        ProgressStyle::with_template("{prefix:>22} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");

    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<JobResult>> = Mutex::new(Vec::new());
    let problem_for = pendulum_problem;
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.min(2 * args.seeds) {
            scope.spawn(|| loop {
                // Jobs: per seed, the cold start alone, and warm start with the difference method
                // (they share one pre-training).
                let k = next.fetch_add(1, Ordering::Relaxed) as u64;
                if k >= 2 * args.seeds {
                    break;
                }
                let (seed, methods): (u64, &[Method]) = if k % 2 == 0 {
                    (k / 2, &[Method::Warm, Method::Difference])
                } else {
                    (k / 2, &[Method::Cold])
                };
                let problem = problem_for();
                let bar = |name: String, len: u64| {
                    let b = multi.add(ProgressBar::new(len));
                    b.set_style(style.clone());
                    b.set_prefix(name);
                    b
                };
                let pre = if methods.contains(&Method::Cold) {
                    ProgressBar::hidden()
                } else {
                    bar(format!("seed {seed} pretrain"), cfg.pretrain_steps)
                };
                let mut bars: Vec<(Method, ProgressBar)> = Vec::new();
                let r = run_seed(
                    &problem,
                    &cfg,
                    methods,
                    seed,
                    &|m, s| ddpg_agent(&cfg, &problem.task, m, s),
                    &mut |t| match t {
                        Tick::Pretrain(k) => {
                            if k % 100 == 0 || k == cfg.pretrain_steps {
                                pre.set_position(k);
                            }
                        }
                        Tick::True(m, n) => {
                            if !bars.iter().any(|(bm, _)| *bm == m) {
                                pre.finish();
                                let len = if m == Method::Difference {
                                    cfg.real_budget
                                } else {
                                    cfg.baseline_max_samples
                                };
                                bars.push((m, bar(format!("seed {seed} {}", m.name()), len)));
                            }
                            if n % 50 == 0 {
                                if let Some((_, b)) = bars.iter().find(|(bm, _)| *bm == m) {
                                    b.set_position(n);
                                }
                            }
                        }
                    },
                );
                for (_, b) in &bars {
                    b.finish();
                }
                results
                    .lock()
                    .expect("no panics while holding the lock")
                    .push((seed, r.map_err(|e| e.to_string())));
            });
        }
    });
    let wall = start.elapsed().as_secs_f64();
    let mut results = results.into_inner().expect("threads joined");
    results.sort_by_key(|(s, _)| *s);
    let mut records = Vec::new();
    for (seed, r) in results {
        records.extend(r.map_err(|e| CliError::Other(format!("seed {seed}: {e}")))?);
    }
    records.sort_by_key(|r| (r.seed, Method::ALL.iter().position(|m| *m == r.method)));

    // Per-run output.
    for r in &records {
        let sub = dir
            .path()
            .join("runs")
            .join(format!("{}__seed{}", r.method.name(), r.seed));
        std::fs::create_dir_all(&sub).map_err(io(&sub))?;
        let rows: Vec<Vec<f64>> = r
            .curve
            .iter()
            .map(|p| vec![p.true_samples as f64, p.eval_return])
            .collect();
        std::fs::write(
            sub.join("curve.csv"),
            csv(&["true_samples", "eval_return"], &rows),
        )
        .map_err(io(&sub))?;
        let text = serde_json::to_string_pretty(r).map_err(other)?;
        std::fs::write(sub.join("record.json"), text).map_err(io(&sub))?;
    }
    let table = table_json(&records, &cfg);
    let md = table_md(&table, &cfg, args.seeds, wall);
    let w = |name: &str, text: &str| dir.write(name, text).map_err(io(dir.path()));
    w(
        "config.json",
        &serde_json::to_string_pretty(&json!({
            "config": &cfg,
            "seeds": args.seeds,
            "jobs": args.jobs,
            "quick": args.quick,
            "wall_seconds": wall,
            "note": "evaluation episodes on the true system are not counted as training samples",
        }))
        .map_err(other)?,
    )?;
    w(
        "table.json",
        &serde_json::to_string_pretty(&table).map_err(other)?,
    )?;
    w("table.md", &md)?;
    w("fig5.svg", &fig5_svg(&records))?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
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
        let t = table_json(&recs, &cfg);
        let close = |v: &Value, x: f64| (v.as_f64().unwrap() - x).abs() < 1e-12;
        // Cold: (1200 + 1600) / 2 over 400, a lower bound (seed 1 never reached it).
        assert!(close(&t["cold_over_difference"]["ratio"], 3.5));
        assert_eq!(t["cold_over_difference"]["lower_bound"], json!(true));
        assert!(close(&t["warm_over_difference"]["ratio"], 1.5));
        assert_eq!(t["warm_over_difference"]["lower_bound"], json!(false));
        assert_eq!(
            t["cold"]["samples_to_target"]["per_seed"],
            json!([1200, null])
        );
        // Reference: the mean of the cold runs' last two evaluations, per seed.
        assert!(close(&t["reference"]["per_seed"][0], -800.0));
        assert!(close(&t["reference"]["per_seed"][1], -2250.0));
        let (r, d) = (-1525.0, -680.0);
        assert!(close(&t["reference"]["mean"], r));
        assert!(close(
            &t["reference"]["difference_relative_gap"],
            (d - r) / -r
        ));
        let md = table_md(&t, &cfg, 2, 1.0);
        assert!(md.contains("Cold start ≥ 3.5×"), "{md}");
        assert!(md.contains("Warm start 1.5×"), "{md}");
    }
}
