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
use tandem::make_env as make;
use tandem::report::{ensure_finite, to_json_pretty, NonFinite};
use tandem::run::{csv, svg_chart, Existing, Layout, RunDir, Series};
use tandem_agents::{Algo, AlgoConfig, TrainSettings, Trainer};

use super::presets::{self, Preset};
use super::{CliError, Result};

/// Arguments of `tandem train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Algorithm: ddpg, sac, dqn or reinforce.
    #[arg(long)]
    pub algo: String,
    /// Registered environment id (see `tandem envs`).
    #[arg(long)]
    pub env: String,
    /// Environment steps (real samples) to train for.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: u64,
    /// Run seed (agent, environment resets, minibatches all derive from it).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// TOML file with `[agent]` and `[train]` overrides of the defaults. Without it, the tuned
    /// preset for the (algorithm, environment) pair is used when there is one (the files in
    /// `crates/agents/presets/`, built into the program).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Without `--config`, use the algorithm's defaults even where a preset exists.
    #[arg(long, conflicts_with = "config")]
    pub no_preset: bool,
    /// Output directory (default `runs/<env>__<algo>__<seed>__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Resume from a checkpoint written by an earlier run with the same configuration; `--out`
    /// may then name that run's directory, whose files are rewritten.
    #[arg(long)]
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
    config_source: String,
    seed: u64,
    steps: u64,
    episodes: u64,
    updates: u64,
    eval_episodes: usize,
    eval_return_mean: f64,
    eval_return_std: f64,
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

/// What `config.toml` records: everything needed to repeat the run.
#[derive(Debug, Serialize)]
struct ResolvedConfig<'a> {
    /// Where the settings came from: `--config`'s path, `preset:<file>` or `defaults`.
    config_source: String,
    algo: &'a str,
    env: &'a str,
    steps: u64,
    seed: u64,
    agent: &'a AlgoConfig,
    train: &'a TrainSettings,
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
                let text = std::fs::read_to_string(p).map_err(|source| CliError::Io {
                    path: p.clone(),
                    source,
                })?;
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

/// Runs `tandem train`.
pub fn run(args: &TrainArgs) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let algo: Algo = args.algo.parse().map_err(other)?;
    let source = ConfigSource::choose(args.config.as_deref(), args.no_preset, algo, &args.env);
    let (agent_cfg, settings) = source.read(algo)?;
    ensure_finite_config(&source, &agent_cfg, &settings)?;
    if let ConfigSource::Preset(p) = &source {
        eprintln!(
            "using preset {} for {} on {} (tuned for --steps {}); --config FILE or --no-preset to \
             choose other settings",
            p.file,
            algo.name(),
            args.env,
            p.steps
        );
        if args.steps != p.steps {
            eprintln!(
                "note: --steps {} differs from the {} steps preset {} was tuned for",
                args.steps, p.steps, p.file
            );
        }
    }
    let mut env = make(&args.env)?;
    let mut eval_env = make(&args.env)?;
    let mut trainer =
        Trainer::new(agent_cfg.clone(), settings.clone(), &*env, args.seed).map_err(other)?;
    if let Some(p) = &args.resume {
        let ckpt = tandem_nn::Checkpoint::load(p)
            .map_err(|e| CliError::input(format!("--resume {}", p.display()), e.to_string()))?;
        trainer
            .load(&ckpt, &mut *env)
            .map_err(|e| CliError::input(format!("--resume {}", p.display()), e.to_string()))?;
    }
    let existing = match (args.overwrite, &args.resume) {
        (true, _) => Existing::Overwrite,
        (false, Some(_)) => Existing::Resume,
        (false, None) => Existing::Refuse,
    };
    let name = format!("{}__{}__{}", args.env, algo.name(), args.seed);
    let dir = RunDir::create(args.out.as_deref(), &name, LAYOUT, existing).map_err(other)?;
    if let Some(pid) = dir.stale_lock_taken_over() {
        eprintln!(
            "note: took over {} from process {pid}, which is no longer running",
            dir.path().display()
        );
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CliError::Io { path, source }
    };
    let resolved = ResolvedConfig {
        config_source: source.label(),
        algo: algo.name(),
        env: &args.env,
        steps: args.steps,
        seed: args.seed,
        agent: &agent_cfg,
        train: &settings,
    };
    let cfg_text = toml::to_string(&resolved).map_err(other)?;
    dir.write("config.toml", &cfg_text)
        .map_err(io(dir.path()))?;

    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(args.steps)
    };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} steps ({per_sec}, eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_position(trainer.steps());
    let start = Instant::now();
    let start_step = trainer.steps();
    let mut last_evals = 0;
    trainer
        .run(&mut *env, &mut *eval_env, args.steps, &mut |t| {
            if t.steps() % 100 == 0 || t.log().evals.len() != last_evals {
                bar.set_position(t.steps());
                let ev = t.log().evals.last().map(|e| e.mean);
                let tr = t.log().episodes.last().map(|e| e.ret_window_mean);
                bar.set_message(format!(
                    "{} {} ep {} train {} eval {}",
                    algo.name(),
                    args.env,
                    t.episodes(),
                    tr.map_or("-".into(), |v| format!("{v:.1}")),
                    ev.map_or("-".into(), |v| format!("{v:.1}")),
                ));
                last_evals = t.log().evals.len();
            }
        })
        .map_err(other)?;
    let train_seconds = start.elapsed().as_secs_f64();
    // Final deterministic evaluation (unless the last step just did one).
    let final_eval = match trainer.log().evals.last() {
        Some(e) if e.step == trainer.steps() => e.clone(),
        _ => trainer.evaluate(&mut *eval_env).map_err(other)?,
    };
    let wall_seconds = start.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let ckpt = trainer.save(&*env).map_err(other)?;
    let ckpt_path = dir.path().join("checkpoint.safetensors");
    ckpt.save(&ckpt_path).map_err(other)?;

    let log = trainer.log().clone();
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

    let steps_run = trainer.steps() - start_step;
    let best_window = log
        .episodes
        .iter()
        .filter(|e| e.episode + 1 >= settings.solved_window as u64)
        .map(|e| e.ret_window_mean)
        .fold(f64::NEG_INFINITY, f64::max);
    let summary = Summary {
        env: &args.env,
        algo: algo.name(),
        config_source: source.label(),
        seed: args.seed,
        steps: trainer.steps(),
        episodes: trainer.episodes(),
        updates: trainer.updates(),
        eval_episodes: final_eval.returns.len(),
        eval_return_mean: final_eval.mean,
        eval_return_std: final_eval.std,
        eval_returns: &final_eval.returns,
        real_samples: trainer.steps(),
        wall_seconds,
        train_seconds,
        env_steps_per_second: steps_run as f64 / wall_seconds,
        solved_threshold: settings.solved_threshold,
        solved_at_episode: log.solved_at_episode,
        best_window_return_mean: best_window.is_finite().then_some(best_window),
        solved_window: settings.solved_window,
        checkpoint: ckpt_path.display().to_string(),
    };
    let text =
        to_json_pretty(&summary).map_err(|e| CliError::Other(format!("summary.json: {e}")))?;
    dir.write("summary.json", &text).map_err(io(dir.path()))?;

    let eval_series = Series {
        name: "evaluation (10 deterministic episodes, mean ± std)"
            .replace("10", &settings.eval_episodes.to_string()),
        points: log.evals.iter().map(|e| (e.step as f64, e.mean)).collect(),
        band: log
            .evals
            .iter()
            .map(|e| (e.step as f64, e.mean - e.std, e.mean + e.std))
            .collect(),
    };
    let train_series = Series {
        name: format!("training return ({}-episode mean)", settings.solved_window),
        points: log
            .episodes
            .iter()
            .map(|e| (e.step as f64, e.ret_window_mean))
            .collect(),
        band: Vec::new(),
    };
    let svg = svg_chart(
        &format!("{} on {} (seed {})", algo.name(), args.env, args.seed),
        "environment steps",
        "return",
        &[eval_series, train_series],
    );
    dir.write("curve.svg", &svg).map_err(io(dir.path()))?;

    println!("{text}");
    println!("run written to {}", dir.path().display());
    Ok(())
}
