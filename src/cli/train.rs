//! `tandem train`: train one model-free agent on one environment and write a run directory
//! (`config.toml`, `metrics.csv`, `episodes.csv`, `summary.json`, `curve.svg`,
//! `checkpoint.safetensors`).
//!
//! A `--config` file has two optional tables, both checked for unknown keys:
//! `[agent]` (the algorithm's `Config` fields, e.g. `learning_rate = 1e-3`) and `[train]`
//! (the loop's `TrainSettings`, e.g. `eval_interval = 2000`). Without `--config`, the tuned
//! preset for the (algorithm, environment) pair is used where one exists ([`super::presets`]);
//! stderr, `config.toml` (`config_source`) and `summary.json` say which settings were used.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use tandem::algos::driver::{drive, Algorithm};
use tandem::algos::model_free::{Event, ModelFree, RunLog, TrainSettings, Trained};
use tandem::algos::{AlgoError, Checkpoints, Result as AlgoResult};
use tandem::make_env as make;
use tandem::studies::interrupt::{Stop, EXIT_SIGINT};
use tandem::studies::report::{ensure_finite, to_json_pretty, NonFinite};
use tandem::studies::run::{csv, svg_chart, Existing, Layout, RunDir, Series};
use tandem_agents::{Algo, AlgoConfig};
use tandem_nn::Checkpoint;

use super::presets::{self, Preset};
use super::{CliError, IoOp, Result};

/// Arguments of `tandem train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Algorithm: ddpg, sac, dqn or reinforce.
    #[arg(long, required_unless_present = "resume")]
    pub algo: Option<String>,
    /// Registered environment id (see `tandem envs`).
    #[arg(long, required_unless_present = "resume")]
    pub env: Option<String>,
    /// Environment steps (real samples) to train for.
    #[arg(long, required_unless_present = "resume", value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: Option<u64>,
    /// Run seed (agent, environment resets, minibatches all derive from it) [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// TOML file with `[agent]` and `[train]` overrides of the defaults. Without it, the tuned
    /// preset for the (algorithm, environment) pair is used when there is one (the files in
    /// `crates/agents/presets/`, built into the program). At most 1 MiB.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Without `--config`, use the algorithm's defaults even where a preset exists.
    #[arg(long, conflicts_with_all = ["config", "resume"])]
    pub no_preset: bool,
    /// Output directory (default `runs/<env>__<algo>__<seed>__<time>/`).
    #[arg(long, conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the run in DIR (interrupted or killed) from its latest checkpoint, with the
    /// settings its `config.toml` records. `--algo`, `--env`, `--steps`, `--seed` and `--config`
    /// may be given and must then agree with them. The finished run's files equal those of an
    /// uninterrupted run (timings aside).
    #[arg(long, value_name = "DIR", conflicts_with = "overwrite")]
    pub resume: Option<PathBuf>,
    /// Replace the run in an existing `--out` directory (without it, an existing run there is an
    /// error).
    #[arg(long)]
    pub overwrite: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The `--config` file.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    #[serde(default)]
    agent: Option<toml::Table>,
    #[serde(default)]
    train: Option<TrainSettings>,
}

/// The files `tandem train` writes into its directory (what `--overwrite` removes).
pub const LAYOUT: Layout = Layout {
    owned: &[
        "config.toml",
        "metrics.csv",
        "episodes.csv",
        "summary.json",
        "curve.svg",
        "checkpoint.safetensors",
    ],
    resumable: true,
};

/// Rejects a non-finite number anywhere in the settings (TOML accepts `nan` and `inf`), naming
/// its key, before any work starts.
pub fn ensure_finite_config(
    source: &ConfigSource,
    agent: &AlgoConfig,
    train: &TrainSettings,
) -> Result<()> {
    let named = |table: &str, e: NonFinite| {
        CliError::input(
            format!("config ({})", source.label()),
            format!("{table}.{e}"),
        )
    };
    ensure_finite(agent).map_err(|e| named("agent", e))?;
    ensure_finite(train).map_err(|e| named("train", e))
}

/// What `summary.json` holds.
#[derive(Debug, Serialize)]
struct Summary<'a> {
    env: &'a str,
    algo: &'a str,
    /// `complete`, or `interrupted` (by SIGINT/SIGTERM; the checkpoint resumes it).
    status: Status,
    config_source: String,
    seed: u64,
    steps: u64,
    episodes: u64,
    updates: u64,
    /// The step of the evaluation reported below (the last one, when interrupted; none if the
    /// run was interrupted before its first).
    eval_step: Option<u64>,
    eval_episodes: usize,
    eval_return_mean: Option<f64>,
    eval_return_std: Option<f64>,
    eval_returns: &'a [f64],
    real_samples: u64,
    wall_seconds: f64,
    train_seconds: f64,
    env_steps_per_second: f64,
    solved_threshold: Option<f64>,
    solved_at_episode: Option<u64>,
    best_window_return_mean: Option<f64>,
    solved_window: usize,
    checkpoint: String,
}

/// What `config.toml` records: everything needed to repeat the run, and what `--resume`
/// continues with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResolvedConfig {
    /// Where the settings came from: `--config`'s path, `preset:<file>` or `defaults`.
    pub config_source: String,
    /// The algorithm's name.
    pub algo: String,
    /// The environment's id.
    pub env: String,
    /// The step budget.
    pub steps: u64,
    /// The run seed.
    pub seed: u64,
    /// The agent's configuration.
    pub agent: AlgoConfig,
    /// The loop's settings.
    pub train: TrainSettings,
}

/// Reads the algorithm's config and the loop settings from the text of a `--config` file
/// (`what` names the file in errors).
pub fn parse_config(algo: Algo, text: &str, what: &str) -> Result<(AlgoConfig, TrainSettings)> {
    let file: ConfigFile =
        toml::from_str(text).map_err(|e| CliError::input(what, e.to_string().trim()))?;
    let agent = match file.agent {
        Some(t) => AlgoConfig::from_toml(algo, t).map_err(CliError::other)?,
        None => AlgoConfig::default_for(algo),
    };
    let train = file.train.unwrap_or_default();
    Ok((agent, train))
}

/// Where a run's settings came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// `--config FILE`.
    File(PathBuf),
    /// The embedded preset for the (algorithm, environment) pair.
    Preset(&'static Preset),
    /// The algorithm's `Config::default()` and `TrainSettings::default()`.
    Defaults,
}

impl ConfigSource {
    /// Picks the source as rl-baselines3-zoo does: `--config` if given, else the preset for
    /// (`algo`, `env`) unless `no_preset`, else the defaults.
    pub fn choose(config: Option<&Path>, no_preset: bool, algo: Algo, env: &str) -> Self {
        match (config, presets::find(algo.name(), env)) {
            (Some(p), _) => ConfigSource::File(p.to_path_buf()),
            (None, Some(preset)) if !no_preset => ConfigSource::Preset(preset),
            _ => ConfigSource::Defaults,
        }
    }

    /// How `config.toml` and `summary.json` name the source: the file's path,
    /// `preset:<file>`, or `defaults`.
    pub fn label(&self) -> String {
        match self {
            ConfigSource::File(p) => p.display().to_string(),
            ConfigSource::Preset(p) => format!("preset:{}", p.file),
            ConfigSource::Defaults => "defaults".into(),
        }
    }

    /// Reads the algorithm's config and the loop settings from this source.
    pub fn read(&self, algo: Algo) -> Result<(AlgoConfig, TrainSettings)> {
        match self {
            ConfigSource::File(p) => {
                let text = tandem_core::read_file_capped(p, tandem_core::MAX_CONFIG_BYTES)
                    .map_err(|source| CliError::io(IoOp::Read, p, source))?;
                parse_config(algo, &text, &format!("config file {}", p.display()))
            }
            ConfigSource::Preset(p) => parse_config(algo, p.text, &format!("preset {}", p.file)),
            ConfigSource::Defaults => Ok((AlgoConfig::default_for(algo), TrainSettings::default())),
        }
    }
}

fn other(e: impl std::fmt::Display) -> CliError {
    CliError::other(e)
}

/// How the run ends: all steps taken, or stopped by a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
enum Status {
    Complete,
    Interrupted,
}

/// The settings of a new run from the command line: `--config`, a preset or the defaults.
fn fresh(args: &TrainArgs) -> Result<ResolvedConfig> {
    let (Some(algo), Some(env), Some(steps)) = (&args.algo, &args.env, args.steps) else {
        return Err(CliError::Other(
            "--algo, --env and --steps are required without --resume".into(),
        ));
    };
    let algo: Algo = algo.parse().map_err(other)?;
    let source = ConfigSource::choose(args.config.as_deref(), args.no_preset, algo, env);
    let (agent, train) = source.read(algo)?;
    ensure_finite_config(&source, &agent, &train)?;
    if let ConfigSource::Preset(p) = &source {
        eprintln!(
            "using preset {} for {} on {env} (tuned for --steps {}); --config FILE or --no-preset \
             to choose other settings",
            p.file,
            algo.name(),
            p.steps
        );
        if steps != p.steps {
            eprintln!(
                "note: --steps {steps} differs from the {} steps preset {} was tuned for",
                p.steps, p.file
            );
        }
    }
    Ok(ResolvedConfig {
        config_source: source.label(),
        algo: algo.name().into(),
        env: env.clone(),
        steps,
        seed: args.seed.unwrap_or(0),
        agent,
        train,
    })
}

/// The settings recorded in the run directory `dir`, checked against whatever the command line
/// also says: a different algorithm, environment, step budget, seed or configuration is refused.
fn recorded(args: &TrainArgs, dir: &Path) -> Result<ResolvedConfig> {
    let what = format!("--resume {}", dir.display());
    let path = dir.join("config.toml");
    let text =
        tandem_core::read_file_capped(&path, tandem_core::MAX_CONFIG_BYTES).map_err(|e| {
            CliError::input(
                &what,
                format!(
                    "{} cannot be read ({e}): not a `tandem train` run directory",
                    path.display()
                ),
            )
        })?;
    let rc: ResolvedConfig = toml::from_str(&text)
        .map_err(|e| CliError::input(format!("{}", path.display()), e.to_string().trim()))?;
    let mut conflicts = Vec::new();
    let mut differs = |name: &str, given: Option<String>, run: String| {
        if let Some(g) = given.filter(|g| *g != run) {
            conflicts.push(format!("--{name} {g} (the run has {run})"));
        }
    };
    differs("algo", args.algo.clone(), rc.algo.clone());
    differs("env", args.env.clone(), rc.env.clone());
    differs(
        "steps",
        args.steps.map(|v| v.to_string()),
        rc.steps.to_string(),
    );
    differs(
        "seed",
        args.seed.map(|v| v.to_string()),
        rc.seed.to_string(),
    );
    if let Some(p) = &args.config {
        let algo: Algo = rc.algo.parse().map_err(other)?;
        let (agent, train) = ConfigSource::File(p.clone()).read(algo)?;
        if agent != rc.agent || train != rc.train {
            conflicts.push(format!(
                "--config {} (its settings differ from the run's config.toml)",
                p.display()
            ));
        }
    }
    if !conflicts.is_empty() {
        return Err(CliError::input(
            what,
            format!(
                "conflicts with the run being resumed: {}; a resumed run keeps its settings \
                 (start a new run with --out to change them)",
                conflicts.join(", ")
            ),
        ));
    }
    Ok(rc)
}

/// The name of the checkpoint file in a run directory.
const CHECKPOINT: &str = "checkpoint.safetensors";

/// Runs `tandem train`.
pub fn run(args: &TrainArgs) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let stop = Stop::on_signals().map_err(|e| CliError::Other(format!("signal handlers: {e}")))?;
    let rc = match &args.resume {
        Some(dir) => recorded(args, dir)?,
        None => fresh(args)?,
    };
    let algo: Algo = rc.algo.parse().map_err(other)?;
    let run = fresh_run(&rc)?;
    let (out, existing) = match (&args.resume, args.overwrite) {
        (Some(dir), _) => (Some(dir.as_path()), Existing::Resume),
        (None, true) => (args.out.as_deref(), Existing::Overwrite),
        (None, false) => (args.out.as_deref(), Existing::Refuse),
    };
    let name = format!("{}__{}__{}", rc.env, algo.name(), rc.seed);
    let dir = RunDir::create(out, &name, LAYOUT, existing).map_err(other)?;
    if let Some(pid) = dir.stale_lock_taken_over() {
        eprintln!(
            "note: took over {} from process {pid}, which is no longer running",
            dir.path().display()
        );
    }
    let ckpt_path = dir.path().join(CHECKPOINT);
    let resuming = args.resume.is_some() && ckpt_path.exists();
    if resuming {
        eprintln!(
            "resuming {} from its checkpoint ({} steps in all)",
            dir.path().display(),
            rc.steps
        );
    } else {
        dir.write("config.toml", &toml::to_string(&rc).map_err(other)?)
            .map_err(io(dir.path()))?;
    }

    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(rc.steps)
    };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} steps ({per_sec}, eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let start = Instant::now();
    let (mut train_end, mut steps_run) = (start, 0u64);
    let (mut episodes, mut window, mut eval) = (0, None, None);
    let mut on_event = |e: Event| {
        let (steps, evaluated) = match e {
            Event::Step(n) => {
                (train_end, steps_run) = (Instant::now(), steps_run + 1);
                (n, false)
            }
            Event::Episode(r) => {
                (episodes, window) = (r.episode + 1, Some(r.ret_window_mean));
                return;
            }
            Event::Evaluation(r) => {
                eval = Some(r.mean);
                (r.step, true)
            }
        };
        if evaluated || steps.is_multiple_of(100) {
            bar.set_position(steps);
            let shown = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.1}"));
            bar.set_message(format!(
                "{} {} ep {episodes} train {} eval {}",
                algo.name(),
                rc.env,
                shown(window),
                shown(eval),
            ));
        }
    };
    let mut files = RunFiles {
        dir: &dir,
        stop: &stop,
        resume: resuming,
    };
    let (status, trained) = match drive(run, &mut files, &mut on_event) {
        Ok(t) => (Status::Complete, t),
        Err(AlgoError::Stopped) => (Status::Interrupted, restored(&rc, &ckpt_path)?),
        Err(e @ AlgoError::Checkpoint(_)) if resuming => {
            return Err(CliError::input(
                format!("--resume {}", ckpt_path.display()),
                e.to_string(),
            ))
        }
        Err(e) => return Err(other(e)),
    };
    let train_seconds = train_end.duration_since(start).as_secs_f64();
    let wall_seconds = start.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let log = &trained.log;
    let final_eval = log.evals.last();
    let best_window = log
        .episodes
        .iter()
        .filter(|e| e.episode + 1 >= rc.train.solved_window as u64)
        .map(|e| e.ret_window_mean)
        .fold(f64::NEG_INFINITY, f64::max);
    let summary = Summary {
        env: &rc.env,
        algo: algo.name(),
        status,
        config_source: rc.config_source.clone(),
        seed: rc.seed,
        steps: trained.steps,
        episodes: trained.episodes,
        updates: trained.updates,
        eval_step: final_eval.map(|e| e.step),
        eval_episodes: rc.train.eval_episodes,
        eval_return_mean: final_eval.map(|e| e.mean),
        eval_return_std: final_eval.map(|e| e.std),
        eval_returns: final_eval.map_or(&[], |e| &e.returns),
        real_samples: trained.steps,
        wall_seconds,
        train_seconds,
        env_steps_per_second: steps_run as f64 / wall_seconds,
        solved_threshold: rc.train.solved_threshold,
        solved_at_episode: log.solved_at_episode,
        best_window_return_mean: best_window.is_finite().then_some(best_window),
        solved_window: rc.train.solved_window,
        checkpoint: ckpt_path.display().to_string(),
    };
    let text =
        to_json_pretty(&summary).map_err(|e| CliError::Other(format!("summary.json: {e}")))?;
    dir.write("summary.json", &text).map_err(io(dir.path()))?;
    write_curve(&dir, log, &rc)?;

    if status == Status::Interrupted {
        return Err(CliError::Interrupted {
            what: format!(
                "checkpoint at step {} of {} written to {}; continue with `tandem train --resume {}`",
                trained.steps,
                rc.steps,
                dir.path().display(),
                dir.path().display()
            ),
            code: stop.exit_code().unwrap_or(EXIT_SIGINT),
        });
    }
    println!("{text}");
    println!("run written to {}", dir.path().display());
    Ok(())
}

/// A fresh run of the recorded settings.
fn fresh_run(rc: &ResolvedConfig) -> Result<ModelFree> {
    let (env, eval_env) = (make(&rc.env)?, make(&rc.env)?);
    let (agent, train) = (rc.agent.clone(), rc.train.clone());
    ModelFree::new(agent, train, env, eval_env, rc.steps, rc.seed).map_err(other)
}

/// The run as its checkpoint at `path` left it (a stopped run saves where it stopped).
fn restored(rc: &ResolvedConfig, path: &Path) -> Result<Trained> {
    let mut run = fresh_run(rc)?;
    let ckpt = tandem_nn::Checkpoint::load(path).map_err(other)?;
    run.load(&ckpt).map_err(other)?;
    run.finish(0.0).map_err(other)
}

/// The run directory as the loop's checkpoint store: the checkpoint, with `metrics.csv` and
/// `episodes.csv` as they stand beside it; it asks to stop on SIGINT/SIGTERM.
struct RunFiles<'a> {
    dir: &'a RunDir,
    stop: &'a Stop,
    /// Whether the checkpoint there continues this run.
    resume: bool,
}

impl Checkpoints for RunFiles<'_> {
    fn load(&mut self, _key: &str) -> AlgoResult<Option<Checkpoint>> {
        let path = self.dir.path().join(CHECKPOINT);
        Ok(match self.resume {
            true => Some(Checkpoint::load(path)?),
            false => None,
        })
    }

    /// Writes the checkpoint (atomically, the previous one kept until the new one is complete),
    /// then the logs as they stand.
    fn save(&mut self, _key: &str, ckpt: &Checkpoint) -> AlgoResult<()> {
        ckpt.save(self.dir.path().join(CHECKPOINT))?;
        write_logs(self.dir, &RunLog::from_checkpoint(ckpt)?)
            .map_err(|e| AlgoError::Checkpoint(e.to_string()))
    }

    fn stop_requested(&self) -> bool {
        self.stop.requested()
    }
}

/// A failed write into the run directory `path`.
fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CliError {
    let path = path.to_path_buf();
    move |source| CliError::io(IoOp::Write, path, source)
}

/// `metrics.csv` (one row per evaluation) and `episodes.csv` as `log` stands.
fn write_logs(dir: &RunDir, log: &RunLog) -> Result<()> {
    // metrics.csv: one row per evaluation, with the last update's figures.
    let mut names: Vec<String> = Vec::new();
    for e in &log.evals {
        for (k, _) in &e.last_update {
            if !names.contains(k) {
                names.push(k.clone());
            }
        }
    }
    let mut header = vec![
        "step",
        "episodes",
        "updates",
        "eval_return_mean",
        "eval_return_std",
        "train_return_window_mean",
    ];
    header.extend(names.iter().map(String::as_str));
    let rows: Vec<Vec<f64>> = log
        .evals
        .iter()
        .map(|e| {
            let window = log
                .episodes
                .iter()
                .rev()
                .find(|r| r.step <= e.step)
                .map_or(f64::NAN, |r| r.ret_window_mean);
            let mut r = vec![
                e.step as f64,
                e.episodes as f64,
                e.updates as f64,
                e.mean,
                e.std,
                window,
            ];
            for n in &names {
                r.push(
                    e.last_update
                        .iter()
                        .find(|(k, _)| k == n)
                        .map_or(f64::NAN, |(_, v)| *v),
                );
            }
            r
        })
        .collect();
    dir.write("metrics.csv", &csv(&header, &rows))
        .map_err(io(dir.path()))?;
    let ep_rows: Vec<Vec<f64>> = log
        .episodes
        .iter()
        .map(|e| {
            vec![
                e.episode as f64,
                e.step as f64,
                e.ret,
                e.length as f64,
                e.ret_window_mean,
            ]
        })
        .collect();
    dir.write(
        "episodes.csv",
        &csv(
            &["episode", "step", "return", "length", "return_window_mean"],
            &ep_rows,
        ),
    )
    .map_err(io(dir.path()))?;
    Ok(())
}

/// `curve.svg`: evaluations (mean ± std) and the windowed training return against steps.
fn write_curve(dir: &RunDir, log: &RunLog, rc: &ResolvedConfig) -> Result<()> {
    let eval_series = Series {
        name: format!(
            "evaluation ({} deterministic episodes, mean ± std)",
            rc.train.eval_episodes
        ),
        points: log.evals.iter().map(|e| (e.step as f64, e.mean)).collect(),
        band: log
            .evals
            .iter()
            .map(|e| (e.step as f64, e.mean - e.std, e.mean + e.std))
            .collect(),
    };
    let train_series = Series {
        name: format!("training return ({}-episode mean)", rc.train.solved_window),
        points: log
            .episodes
            .iter()
            .map(|e| (e.step as f64, e.ret_window_mean))
            .collect(),
        band: Vec::new(),
    };
    let svg = svg_chart(
        &format!("{} on {} (seed {})", rc.algo, rc.env, rc.seed),
        "environment steps",
        "return",
        &[eval_series, train_series],
    );
    dir.write("curve.svg", &svg).map_err(io(dir.path()))?;
    Ok(())
}
