//! `tandem reproduce p2-cartpole`: p2's CartPole experiment (Sec. 4.1, Fig. 6). REINFORCE alone
//! (`model_free`) and REINFORCE with episodes imagined by the learned model (`with_model`), over
//! seeds, on gymnasium's CartPole-v1; writes in the output directory:
//!
//! - `config.json`: the [`P2Config`] used, seeds, status and wall time;
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's return per real episode;
//! - `table.md`, `table.json`: real episodes to solve per method (`episodes_to_solve`: mean and
//!   standard error over the seeds that solved it, `per_seed` with `null` where a seed never
//!   did) and the ratio of the means, with-model over model-free;
//! - `fig6.svg`: p2's Fig. 6, the mean over seeds of the windowed training return against real
//!   episodes.
//!
//! "Solved" is the mean return of the last 100 real episodes reaching 475 (p2 gives no
//! definition; this is gymnasium's CartPole-v1 threshold). SIGINT or SIGTERM stops the jobs
//! between episodes and exits with 130 or 143; this command keeps no checkpoints on disk (no
//! `--resume`): a stopped reproduction is started again.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use tandem::interrupt::{Stop, EXIT_SIGINT};
use tandem::pipelines::p2::{cartpole, Event, Method, P2Config, RunRecord};
use tandem::pipelines::{Checkpoints, Result as PipelineResult};
use tandem::report::{ensure_finite, to_json_pretty, Curve, Figure, SamplesToTarget};
use tandem::run::{csv, Existing, Layout, RunDir};
use tandem_nn::Checkpoint;

use super::{CliError, Result};

/// Arguments of `tandem reproduce p2-cartpole`.
#[derive(Debug, Args)]
pub struct P2Args {
    /// Number of seeds (0, 1, ..., N-1) [default: 10, as p2 averages over 10 runs].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: Option<u64>,
    /// Small smoke configuration (a small model, 20 real episodes; numbers are meaningless).
    #[arg(long)]
    pub quick: bool,
    /// Output directory (default `runs/p2-cartpole__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Parallel jobs, one thread each (one job per method and seed).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Replace the reproduction in an existing `--out` directory; without it, an existing
    /// reproduction there is an error.
    #[arg(long)]
    pub overwrite: bool,
    /// TOML file of settings (`P2Config`; fields not given keep their defaults, unknown keys
    /// are errors). Not with `--quick`.
    #[arg(long, conflicts_with = "quick")]
    pub config: Option<PathBuf>,
}

/// The `--quick` configuration: the same loop with a small model and 20 real episodes.
pub fn quick_config() -> P2Config {
    let mut c = P2Config::default();
    c.model.hidden = vec![32, 32];
    c.real_only_episodes = 5;
    c.max_real_episodes = 20;
    c.solved_window = 10;
    c.fit_rows = 256;
    c
}

/// The files and folders `tandem reproduce p2-cartpole` writes (what `--overwrite` removes).
pub const LAYOUT: Layout = Layout {
    owned: &["config.json", "runs", "table.json", "table.md", "fig6.svg"],
    resumable: false,
};

/// One method's figures in `table.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodRow {
    /// Real episodes to solve: `target` is the solved level, `per_seed` is `null` where a seed
    /// never solved it within `searched_up_to` real episodes.
    pub episodes_to_solve: SamplesToTarget,
    /// Mean real samples (steps) per seed over its whole run.
    pub mean_real_samples: f64,
    /// Mean imagined episodes per seed.
    pub mean_imagined_episodes: f64,
    /// The seeds, in the order of `per_seed`.
    pub seeds: Vec<u64>,
}

/// `with_model_over_model_free` in `table.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Ratio {
    /// Mean real episodes to solve with the model over that without (the paper's 400 / 650).
    pub ratio: Option<f64>,
    /// Model-free mean episodes to solve, a seed that never solved it counted at the episodes
    /// it ran.
    pub model_free_mean_episodes: f64,
    /// The same with the model.
    pub with_model_mean_episodes: f64,
    /// Whether seeds that never solved it make the ratio a bound rather than a value: `"upper"`
    /// (only model-free fell short), `"lower"` (only with-model did), `"unknown"` (both did),
    /// `null` (every seed solved it: the ratio is exact).
    pub bound: Option<String>,
    /// How the means are taken.
    pub note: String,
}

/// p2's CartPole table: the two methods and their ratio.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct P2Table {
    /// REINFORCE alone.
    pub model_free: MethodRow,
    /// REINFORCE with imagined episodes.
    pub with_model: MethodRow,
    /// With-model over model-free mean episodes to solve.
    pub with_model_over_model_free: Ratio,
    /// The definition of "solved".
    pub solved: String,
}

fn method_row(records: &[RunRecord], m: Method, cfg: &P2Config) -> (MethodRow, f64, bool) {
    let runs: Vec<&RunRecord> = records.iter().filter(|r| r.method == m).collect();
    let per_seed: Vec<Option<u64>> = runs.iter().map(|r| r.solved_at).collect();
    let used: Vec<f64> = runs
        .iter()
        .map(|r| r.solved_at.unwrap_or(r.real_returns.len() as u64) as f64)
        .collect();
    let searched = runs
        .iter()
        .map(|r| r.real_returns.len() as u64)
        .max()
        .unwrap_or(0);
    let n = runs.len().max(1) as f64;
    let row = MethodRow {
        episodes_to_solve: SamplesToTarget::from_seeds(cfg.solved_return, per_seed, searched),
        mean_real_samples: runs.iter().map(|r| r.real_samples as f64).sum::<f64>() / n,
        mean_imagined_episodes: runs.iter().map(|r| r.imagined_episodes as f64).sum::<f64>() / n,
        seeds: runs.iter().map(|r| r.seed).collect(),
    };
    let short = runs.iter().any(|r| r.solved_at.is_none());
    (row, used.iter().sum::<f64>() / n, short)
}

/// The table from the runs' records.
pub fn table(records: &[RunRecord], cfg: &P2Config) -> P2Table {
    let (model_free, mf, mf_short) = method_row(records, Method::ModelFree, cfg);
    let (with_model, wm, wm_short) = method_row(records, Method::WithModel, cfg);
    let bound = match (mf_short, wm_short) {
        (false, false) => None,
        (true, false) => Some("upper"),
        (false, true) => Some("lower"),
        (true, true) => Some("unknown"),
    };
    P2Table {
        model_free,
        with_model,
        with_model_over_model_free: Ratio {
            ratio: (mf > 0.0).then(|| wm / mf),
            model_free_mean_episodes: mf,
            with_model_mean_episodes: wm,
            bound: bound.map(str::to_string),
            note: "means over all seeds, a seed that never solved it counted at the real \
                   episodes it ran"
                .into(),
        },
        solved: format!(
            "mean return of the last {} real episodes >= {} (p2 gives no definition; \
             gymnasium's CartPole-v1 reward threshold)",
            cfg.solved_window, cfg.solved_return
        ),
    }
}

fn cell(e: &SamplesToTarget) -> String {
    match e.mean {
        Some(m) => format!(
            "{m:.0} ± {:.0} ({}/{} seeds solved it)",
            e.stderr.unwrap_or(0.0),
            e.reached,
            e.seeds
        ),
        None => format!("> {} (no seed solved it)", e.searched_up_to),
    }
}

/// The table as Markdown, with the settings that matter and the wall time.
pub fn markdown(t: &P2Table, cfg: &P2Config, wall: f64) -> String {
    let rows = [
        ("REINFORCE alone", &t.model_free, 650),
        ("REINFORCE with the model", &t.with_model, 400),
    ];
    let n = t.model_free.seeds.len().max(t.with_model.seeds.len());
    let mut s = format!(
        "# p2 CartPole-v1: real episodes to solve ({n} seeds)\n\nSolved: {}. Real episodes \
         are counted exactly; imagined episodes cost none. Mean ± standard error over the \
         seeds that solved it.\n\n| Method | Real episodes to solve | Paper | Imagined \
         episodes (mean) |\n|---|---|---|---|\n",
        t.solved
    );
    for (label, r, paper) in rows {
        s.push_str(&format!(
            "| {label} | {} | {paper} | {:.0} |\n",
            cell(&r.episodes_to_solve),
            r.mean_imagined_episodes
        ));
    }
    s.push_str("\nReal episodes to solve, per seed:\n\n");
    for (label, r, _) in rows {
        let v: Vec<String> = r
            .episodes_to_solve
            .per_seed
            .iter()
            .map(|x| x.map_or("never".into(), |v| v.to_string()))
            .collect();
        s.push_str(&format!("- {label}: {}\n", v.join(", ")));
    }
    let q = &t.with_model_over_model_free;
    let bound = match q.bound.as_deref() {
        Some("upper") => "at most ",
        Some("lower") => "at least ",
        Some(_) => "unbounded either way, ",
        None => "",
    };
    s.push_str(&format!(
        "\nWith the model over alone ({}): {bound}{} (paper 400 / 650 = 0.62).\n",
        q.note,
        q.ratio.map_or("n/a".into(), |r| format!("{r:.2}")),
    ));
    s.push_str(&format!(
        "\nSettings: REINFORCE {:?} hidden, Adam {}, γ = {}, {:?} baseline, an update every {} \
         episode(s); model {:?} hidden, {:?}; the first {} episodes real only, then {} imagined \
         per {} real; model refit every {} real episode(s), {} epoch(s) over at most {} real \
         transitions drawn from all, minibatch {}; at most {} real episodes per run, each run \
         stops once solved (later points of the curves average the seeds still running). Wall \
         time {wall:.0} s.\n",
        cfg.reinforce.hidden,
        cfg.reinforce.learning_rate,
        cfg.reinforce.gamma,
        cfg.reinforce.baseline,
        cfg.reinforce.episodes_per_update,
        cfg.model.hidden,
        cfg.model.optimizer,
        cfg.real_only_episodes,
        cfg.imagined_per_cycle,
        cfg.real_per_cycle,
        cfg.fit_every,
        cfg.fit.epochs,
        cfg.fit_rows,
        cfg.fit.batch_size,
        cfg.max_real_episodes,
    ));
    s
}

/// Fig. 6: the mean over seeds of the training return (mean of the last `solved_window` real
/// episodes) against real episodes, every 10 episodes.
pub fn fig6(records: &[RunRecord], cfg: &P2Config) -> Figure {
    let w = cfg.solved_window;
    let curves = Method::ALL
        .iter()
        .map(|&m| {
            let seeds: Vec<Vec<(u64, f64)>> = records
                .iter()
                .filter(|r| r.method == m)
                .map(|r| {
                    (1..=r.real_returns.len())
                        .filter(|k| k % 10 == 0 || *k == r.real_returns.len())
                        .map(|k| {
                            let tail = &r.real_returns[k.saturating_sub(w)..k];
                            (k as u64, tail.iter().sum::<f64>() / tail.len() as f64)
                        })
                        .collect()
                })
                .collect();
            Curve::mean_over_seeds(m.name(), &seeds)
        })
        .collect();
    Figure {
        title: "p2 Fig. 6: REINFORCE on CartPole-v1, alone and with the learned model".into(),
        x_label: "real episodes".into(),
        y_label: format!("training return (mean of the last {w} real episodes)"),
        curves,
    }
}

/// Keeps no checkpoints; stops on SIGINT/SIGTERM.
struct StopOnSignal(Stop);

impl Checkpoints for StopOnSignal {
    fn load(&mut self, _key: &str) -> PipelineResult<Option<Checkpoint>> {
        Ok(None)
    }
    fn save(&mut self, _key: &str, _ckpt: &Checkpoint) -> PipelineResult<()> {
        Ok(())
    }
    fn stop_requested(&self) -> bool {
        self.0.requested()
    }
}

fn io_err(path: PathBuf) -> impl FnOnce(std::io::Error) -> CliError {
    move |source| CliError::Io { path, source }
}

/// Writes a finished run's `curve.csv` and `record.json`.
fn write_record(dir: &RunDir, r: &RunRecord) -> Result<()> {
    let sub = dir
        .path()
        .join("runs")
        .join(format!("{}__seed{}", r.method.name(), r.seed));
    std::fs::create_dir_all(&sub).map_err(io_err(sub.clone()))?;
    let rows: Vec<Vec<f64>> = r
        .real_returns
        .iter()
        .enumerate()
        .map(|(k, ret)| vec![(k + 1) as f64, *ret])
        .collect();
    let curve = csv(&["real_episode", "return"], &rows);
    let path = sub.join("curve.csv");
    tandem_nn::write_atomic(&path, curve.as_bytes()).map_err(io_err(path))?;
    let text = to_json_pretty(r).map_err(|e| CliError::Other(format!("record.json: {e}")))?;
    let path = sub.join("record.json");
    tandem_nn::write_atomic(&path, text.as_bytes()).map_err(io_err(path))
}

/// What `config.json` records.
#[derive(Debug, Serialize)]
struct RunConfig<'a> {
    config: &'a P2Config,
    seeds: u64,
    quick: bool,
    jobs: u64,
    status: &'a str,
    wall_seconds: Option<f64>,
}

/// Runs `tandem reproduce p2-cartpole`.
pub fn p2_cartpole(args: &P2Args) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let stop = Stop::on_signals().map_err(|e| CliError::Other(format!("signal handlers: {e}")))?;
    let cfg = match (&args.config, args.quick) {
        (Some(path), _) => {
            let what = format!("--config {}", path.display());
            let text = std::fs::read_to_string(path).map_err(io_err(path.clone()))?;
            toml::from_str(&text).map_err(|e| CliError::input(&what, e.to_string()))?
        }
        (None, true) => quick_config(),
        (None, false) => P2Config::default(),
    };
    cfg.validate().map_err(CliError::other)?;
    ensure_finite(&cfg).map_err(CliError::other)?;
    let seeds = args.seeds.unwrap_or(10);
    let existing = if args.overwrite {
        Existing::Overwrite
    } else {
        Existing::Refuse
    };
    let dir = RunDir::create(args.out.as_deref(), "p2-cartpole", LAYOUT, existing)
        .map_err(CliError::other)?;
    let write_config = |status: &str, wall: Option<f64>| -> Result<()> {
        let rc = RunConfig {
            config: &cfg,
            seeds,
            quick: args.quick,
            jobs: args.jobs,
            status,
            wall_seconds: wall,
        };
        let text = to_json_pretty(&rc).map_err(|e| CliError::Other(format!("config.json: {e}")))?;
        dir.write("config.json", &text)
            .map(drop)
            .map_err(io_err(dir.path().join("config.json")))
    };
    write_config("running", None)?;
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
    let records: Mutex<Vec<RunRecord>> = Mutex::new(Vec::new());
    let errors: Mutex<Vec<(u64, String)>> = Mutex::new(Vec::new());
    let jobs = 2 * seeds;
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.min(jobs) {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed) as u64;
                if k >= jobs || stop.requested() {
                    break;
                }
                let (seed, m) = (k / 2, Method::ALL[(k % 2) as usize]);
                let bar = multi.add(ProgressBar::new(cfg.max_real_episodes));
                bar.set_style(style.clone());
                bar.set_prefix(format!("seed {seed} {}", m.name()));
                let mut store = StopOnSignal(stop.clone());
                let r = cartpole(m, &cfg, seed, &mut store, &mut |e| {
                    if let Event::Real { episode, ret, .. } = e {
                        bar.set_position(episode + 1);
                        bar.set_message(format!("return {ret:.0}"));
                    }
                });
                bar.finish();
                let r = r.map_err(|e| e.to_string()).and_then(|r| {
                    write_record(&dir, &r).map_err(|e| e.to_string())?;
                    Ok(r)
                });
                match r {
                    Ok(r) => records.lock().expect("no panics holding it").push(r),
                    Err(_) if stop.requested() => {}
                    Err(e) => errors.lock().expect("no panics holding it").push((seed, e)),
                }
            });
        }
    });
    let wall = start.elapsed().as_secs_f64();
    let mut errors = errors.into_inner().expect("threads joined");
    errors.sort();
    if let Some((seed, e)) = errors.first() {
        return Err(CliError::Other(format!("seed {seed}: {e}")));
    }
    if stop.requested() {
        write_config("interrupted", Some(wall))?;
        return Err(CliError::Interrupted {
            what: format!(
                "finished runs are in {}; start the reproduction again to complete it",
                dir.path().display()
            ),
            code: stop.exit_code().unwrap_or(EXIT_SIGINT),
        });
    }
    let mut records = records.into_inner().expect("threads joined");
    records.sort_by_key(|r| (r.seed, r.method.name()));
    let t = table(&records, &cfg);
    ensure_finite(&t).map_err(CliError::other)?;
    let md = markdown(&t, &cfg, wall);
    let json = to_json_pretty(&t).map_err(|e| CliError::Other(format!("table.json: {e}")))?;
    for (name, text) in [
        ("table.json", json),
        ("table.md", md.clone()),
        ("fig6.svg", fig6(&records, &cfg).svg()),
    ] {
        dir.write(name, &text)
            .map_err(io_err(dir.path().join(name)))?;
    }
    write_config("complete", Some(wall))?;
    println!("{md}");
    println!("wrote {}", dir.path().display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(method: Method, seed: u64, episodes: usize, solved_at: Option<u64>) -> RunRecord {
        RunRecord {
            method,
            seed,
            real_returns: vec![100.0; episodes],
            real_samples: 100 * episodes as u64,
            imagined_episodes: if method == Method::WithModel { 50 } else { 0 },
            imagined_steps: 0,
            solved_at,
            fit_losses: vec![],
            wall_seconds: 0.0,
        }
    }

    #[test]
    fn the_table_counts_episodes_to_solve_and_bounds_the_ratio() {
        let cfg = P2Config::default();
        let recs = [
            // Model-free: 600 and never within its 2000 episodes.
            record(Method::ModelFree, 0, 600, Some(600)),
            record(Method::ModelFree, 1, 2000, None),
            // With the model: 300 and 500.
            record(Method::WithModel, 0, 300, Some(300)),
            record(Method::WithModel, 1, 500, Some(500)),
        ];
        let t = table(&recs, &cfg);
        let mf = &t.model_free.episodes_to_solve;
        assert_eq!(mf.per_seed, [Some(600), None]);
        assert_eq!(
            (mf.mean, mf.stderr, mf.reached),
            (Some(600.0), Some(0.0), 1)
        );
        let wm = &t.with_model.episodes_to_solve;
        // Mean 400, standard error = sd / √2 = 141.42... / 1.414... = 100.
        assert_eq!(wm.mean, Some(400.0));
        assert!((wm.stderr.unwrap() - 100.0).abs() < 1e-9);
        assert_eq!(t.with_model.mean_imagined_episodes, 50.0);
        assert_eq!(t.model_free.mean_real_samples, 130_000.0);
        // (300 + 500) / 2 over (600 + 2000) / 2: an upper bound (model-free fell short).
        let q = &t.with_model_over_model_free;
        assert!((q.ratio.unwrap() - 400.0 / 1300.0).abs() < 1e-12);
        assert_eq!(q.bound.as_deref(), Some("upper"));
        let md = markdown(&t, &cfg, 1.0);
        assert!(md.contains("at most 0.31"), "{md}");
        assert!(md.contains("- REINFORCE alone: 600, never"), "{md}");
        // The JSON has the keys the issue names, with null for the seed that never solved it.
        let v: serde_json::Value = serde_json::from_str(&to_json_pretty(&t).unwrap()).unwrap();
        assert_eq!(
            v["model_free"]["episodes_to_solve"]["per_seed"][1],
            serde_json::Value::Null
        );
        assert_eq!(v["with_model"]["episodes_to_solve"]["mean"], 400.0);
    }

    /// The committed results (`results/p2-cartpole/`) read back as a table.
    #[test]
    fn the_committed_table_reads_back() {
        let text = include_str!("../../results/p2-cartpole/table.json");
        let t: P2Table = serde_json::from_str(text).unwrap();
        assert_eq!(t.model_free.episodes_to_solve.seeds, 10);
        assert_eq!(t.with_model.episodes_to_solve.seeds, 10);
        assert_eq!(to_json_pretty(&t).unwrap().trim_end(), text.trim_end());
    }
}
