//! `tandem train`: train one model-free agent on one environment and write a run directory
//! (`config.toml`, `metrics.csv`, `episodes.csv`, `summary.json`, `curve.svg`,
//! `checkpoint.safetensors`).
//!
//! A `--config` file has two optional tables, both checked for unknown keys:
//! `[agent]` (the algorithm's `Config` fields, e.g. `learning_rate = 1e-3`) and `[train]`
//! (the loop's `TrainSettings`, e.g. `eval_interval = 2000`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use tandem::run::{csv, svg_chart, RunDir, Series};
use tandem_agents::{Algo, AlgoConfig, TrainSettings, Trainer};
use tandem_envs::make;

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
    /// TOML file with `[agent]` and `[train]` overrides.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory (default `runs/<env>__<algo>__<seed>__<time>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Resume from a checkpoint written by an earlier run with the same configuration.
    #[arg(long)]
    pub resume: Option<PathBuf>,
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

/// What `config.toml` records: everything needed to repeat the run.
#[derive(Debug, Serialize)]
struct ResolvedConfig<'a> {
    algo: &'a str,
    env: &'a str,
    steps: u64,
    seed: u64,
    agent: &'a AlgoConfig,
    train: &'a TrainSettings,
}

/// Reads the algorithm's config and the loop settings from `path` (or the defaults).
pub fn read_config(algo: Algo, path: Option<&Path>) -> Result<(AlgoConfig, TrainSettings)> {
    let Some(p) = path else {
        return Ok((AlgoConfig::default_for(algo), TrainSettings::default()));
    };
    let text = std::fs::read_to_string(p).map_err(|source| CliError::Io {
        path: p.to_path_buf(),
        source,
    })?;
    parse_config(algo, &text, &format!("config file {}", p.display()))
}

/// Parses the text of a `--config` file (`what` names it in errors).
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

fn other(e: impl std::fmt::Display) -> CliError {
    CliError::other(e)
}

/// Runs `tandem train`.
pub fn run(args: &TrainArgs) -> Result<()> {
    tandem_nn::set_gemm_threads(1);
    let algo: Algo = args.algo.parse().map_err(other)?;
    let (agent_cfg, settings) = read_config(algo, args.config.as_deref())?;
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
    let dir = RunDir::create(args.out.as_deref(), &args.env, algo.name(), args.seed).map_err(
        |source| CliError::Io {
            path: args.out.clone().unwrap_or_else(|| PathBuf::from("runs")),
            source,
        },
    )?;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CliError::Io { path, source }
    };
    let resolved = ResolvedConfig {
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
    let summary = serde_json::json!({
        "env": args.env,
        "algo": algo.name(),
        "seed": args.seed,
        "steps": trainer.steps(),
        "episodes": trainer.episodes(),
        "updates": trainer.updates(),
        "eval_episodes": final_eval.returns.len(),
        "eval_return_mean": final_eval.mean,
        "eval_return_std": final_eval.std,
        "eval_returns": final_eval.returns,
        "real_samples": trainer.steps(),
        "wall_seconds": wall_seconds,
        "train_seconds": train_seconds,
        "env_steps_per_second": steps_run as f64 / wall_seconds,
        "solved_threshold": settings.solved_threshold,
        "solved_at_episode": log.solved_at_episode,
        "best_window_return_mean": if best_window.is_finite() { Some(best_window) } else { None },
        "solved_window": settings.solved_window,
        "checkpoint": ckpt_path.display().to_string(),
    });
    let text = serde_json::to_string_pretty(&summary).map_err(other)?;
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
