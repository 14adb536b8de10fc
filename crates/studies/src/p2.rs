//! `tandem reproduce p2-cartpole` and `tandem reproduce p2-maze`: p2's two experiments, each the
//! model-free agent alone (`model_free`) and with episodes imagined by the learned model
//! (`with_model`), over seeds:
//!
//! - CartPole-v1 (Sec. 4.1, Fig. 6): REINFORCE, the MLP model of `(s', r, done)`;
//! - the pixel maze `PixelMaze-v0`, or with `--env PixelMaze-v1` the authors' released layout
//!   (Sec. 4.2, Fig. 7 and 8): DQN from 16×16 RGB frames, the pixel
//!   model; plus the pixel model's own experiment, its F1 per channel on held-out transitions
//!   after 10, 100 and 300 training episodes, and its predicted frames (Fig. 7).
//!
//! Both run through the shared [`crate::harness`] (checkpoints, `--resume`, one process per seed,
//! `tandem reproduce merge`), each method and seed a job, and write in the output directory,
//! besides the harness' `config.json` and `state/`:
//!
//! - `runs/<method>__seed<k>/record.json` and `curve.csv`: each run's return per real episode;
//!   on the maze also `runs/model_f1__seed<k>/` for the seeds of the F1 experiment
//!   ([`QualityConfig::seeds`], seed 0 by default);
//! - `table.md`, `table.json`: real episodes to solve per method (`episodes_to_solve`: mean and
//!   standard error over the seeds that solved it, `per_seed` with `null` where a seed never
//!   did), the ratio of the means, with-model over model-free, and for the maze `f1`;
//! - `fig6.svg` (CartPole) or `fig8.svg` (maze): the mean over seeds of the windowed training
//!   return against real episodes; for the maze also `fig7.svg` (true and predicted frames) and
//!   `quality.json` (the F1 experiment per seed).
//!
//! "Solved" is the mean return of the last 100 real episodes reaching 475 on CartPole
//! (gymnasium's threshold) and 20 on `PixelMaze-v0`, 35 on `PixelMaze-v1` (ours, about half the
//! best return); p2 defines neither. A run checkpoints every `checkpoint_every` real episodes
//! (50 by default); the F1 experiment keeps no checkpoints (its copies of the model are not in
//! them) and starts again when resumed.

use std::path::Path;

use crate::report::{ensure_finite, to_json_pretty, words, Curve, Figure, SamplesToTarget};
use crate::run::RunDir;
use serde::{Deserialize, Serialize};
use tandem_algos::imagined_episodes::{cartpole, Event, Method, P2Config, RunRecord};
use tandem_algos::imagined_pixels::{self, MazeConfig, Quality, QualityConfig};
use tandem_algos::{Checkpoints, Result as AlgoResult};
use tandem_robots::PixelMazeEnv;

use crate::harness::{self, JobError, Study};
use crate::{Error, Result};
use tandem_nn::budget::MemoryEstimate;

/// Which of p2's experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Experiment {
    /// REINFORCE on CartPole-v1 (Sec. 4.1).
    CartPole,
    /// DQN on the pixel maze (Sec. 4.2).
    Maze,
}

impl Experiment {
    /// The command's name, the default output directory's prefix.
    pub fn name(self) -> &'static str {
        match self {
            Experiment::CartPole => "p2-cartpole",
            Experiment::Maze => "p2-maze",
        }
    }

    fn agent(self) -> &'static str {
        match self {
            Experiment::CartPole => "REINFORCE",
            Experiment::Maze => "DQN",
        }
    }

    /// p2's real episodes to solve: alone, with the model.
    fn paper(self) -> (u64, u64) {
        match self {
            Experiment::CartPole => (650, 400),
            Experiment::Maze => (700, 250),
        }
    }

    /// The learning-curve figure: file and p2's number.
    fn figure(self) -> (&'static str, u32) {
        match self {
            Experiment::CartPole => ("fig6.svg", 6),
            Experiment::Maze => ("fig8.svg", 8),
        }
    }
}

/// The settings of either experiment: `config.json`'s `config` is CartPole's [`P2Config`]
/// itself, the maze's `{runs, quality}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Settings {
    /// The maze's, with the pixel model's F1 experiment.
    Maze {
        /// The runs.
        runs: Box<MazeConfig>,
        /// The F1 experiment.
        quality: QualityConfig,
    },
    /// CartPole's.
    CartPole(P2Config),
}

impl Settings {
    /// The settings of `exp`: its defaults (`--quick`'s sizes with `quick`), on the maze those
    /// of `env` (`--env`, else the `--config` file's `env`, else `PixelMaze-v0`), then the
    /// file's overrides. A maze file holds [`MazeConfig`]'s keys at its top and the F1
    /// experiment's ([`QualityConfig`]) in a `[quality]` table; keys not given keep their
    /// defaults, unknown ones are errors.
    fn new(exp: Experiment, quick: bool, env: Option<&str>, config: Option<&Path>) -> Result<Self> {
        let what = harness::settings_name(config);
        let settings = match exp {
            Experiment::CartPole => {
                if env.is_some() {
                    return Err(Error::input(
                        "--env",
                        "--env applies to p2-maze only (p2-cartpole runs CartPole-v1)",
                    ));
                }
                let base = if quick {
                    quick_config()
                } else {
                    P2Config::default()
                };
                Settings::CartPole(harness::read_overrides(base, config)?)
            }
            Experiment::Maze => {
                let mut over = config
                    .map(harness::read_table)
                    .transpose()?
                    .unwrap_or_default();
                let file_env = match over.get("env") {
                    None => None,
                    Some(toml::Value::String(e)) => Some(e.clone()),
                    Some(v) => {
                        return Err(Error::input(
                            &what,
                            format!("env = {v}: the maze's id is a string"),
                        ))
                    }
                };
                let env = match (env, file_env.as_deref()) {
                    (Some(a), Some(b)) if a != b => {
                        return Err(Error::input(
                            "--env",
                            format!("{a}, but {what} says env = \"{b}\""),
                        ))
                    }
                    (Some(e), _) | (None, Some(e)) => e,
                    (None, None) => PixelMazeEnv::ID,
                };
                let mut runs =
                    MazeConfig::for_env(env).map_err(|e| Error::input("--env", e.to_string()))?;
                let mut quality = QualityConfig::default();
                if quick {
                    let (q_runs, q_quality) = quick_maze_config();
                    runs = MazeConfig {
                        env: runs.env,
                        ..q_runs
                    };
                    quality = q_quality;
                }
                if let Some(q) = over.remove("quality") {
                    let toml::Value::Table(q) = q else {
                        return Err(Error::input(&what, "quality must be a table, [quality]"));
                    };
                    quality = harness::override_with_table(&quality, q, &what)?;
                }
                Settings::Maze {
                    runs: Box::new(harness::override_with_table(&runs, over, &what)?),
                    quality,
                }
            }
        };
        settings
            .validate()
            .map_err(|e| Error::input(&what, e.to_string()))?;
        Ok(settings)
    }

    /// The environment's id.
    fn env(&self) -> &str {
        match self {
            Settings::CartPole(_) => "CartPole-v1",
            Settings::Maze { runs, .. } => &runs.env,
        }
    }

    fn validate(&self) -> AlgoResult<()> {
        match self {
            Settings::CartPole(c) => c.validate(),
            Settings::Maze { runs, quality } => {
                runs.validate()?;
                quality.validate()
            }
        }
    }

    fn solved(&self) -> (f64, usize, u64) {
        match self {
            Settings::CartPole(c) => (c.solved_return, c.solved_window, c.max_real_episodes),
            Settings::Maze { runs: c, .. } => {
                (c.solved_return, c.solved_window, c.max_real_episodes)
            }
        }
    }

    fn solved_text(&self) -> String {
        let (target, window, _) = self.solved();
        match self {
            Settings::CartPole(_) => format!(
                "mean return of the last {window} real episodes >= {target} (p2 gives no \
                 definition; gymnasium's CartPole-v1 reward threshold)"
            ),
            Settings::Maze { runs, .. } if runs.env == PixelMazeEnv::ID_V1 => format!(
                "mean training return of the last {window} real episodes >= {target} (p2 gives \
                 no definition; ours: about half the best return, 70 from the fixed start, \
                 fixed before any run)"
            ),
            Settings::Maze { .. } => format!(
                "mean training return of the last {window} real episodes >= {target} (p2 gives \
                 no definition; ours: about half the best return, 36 to 49 by the start cell, \
                 fixed before any run)"
            ),
        }
    }

    fn run(
        &self,
        method: Method,
        seed: u64,
        store: &mut dyn Checkpoints,
        on_event: &mut dyn FnMut(Event),
    ) -> AlgoResult<RunRecord> {
        match self {
            Settings::CartPole(c) => cartpole(method, c, seed, store, on_event),
            Settings::Maze { runs, .. } => {
                imagined_pixels::run(method, runs, seed, store, on_event)
            }
        }
    }

    /// The settings that matter, in words.
    fn describe(&self) -> String {
        match self {
            Settings::CartPole(cfg) => format!(
                "REINFORCE {} hidden, Adam {}, γ = {}, {}, an update every {} \
                 episode(s); model {} hidden, {}; the first {} episodes real only, then {} \
                 imagined per {} real; model refit every {} real episode(s), {} epoch(s) over at \
                 most {} real transitions drawn from all, minibatch {}; at most {} real episodes \
                 per run, each run stops once solved (later points of the curves average the \
                 seeds still running)",
                words::list(&cfg.reinforce.hidden),
                cfg.reinforce.learning_rate,
                cfg.reinforce.gamma,
                words::baseline(&cfg.reinforce.baseline),
                cfg.reinforce.episodes_per_update,
                words::list(&cfg.model.hidden),
                words::optimizer(&cfg.model.optimizer),
                cfg.real_only_episodes,
                cfg.imagined_per_cycle,
                cfg.real_per_cycle,
                cfg.fit_every,
                cfg.fit.epochs,
                cfg.fit_rows,
                cfg.fit.batch_size,
                cfg.max_real_episodes,
            ),
            Settings::Maze { runs: c, quality } => format!(
                "DQN (conv Q-network {} channels, {} hidden; Adam {}, constant; γ = {}; \
                 double DQN; replay {}; ε {} → {} over {} agent steps, imagined steps \
                 included; an update every {} steps after {} warm-up steps; target copy every \
                 {}); pixel model {} channels, {} features, {} factors, {}, threshold {}; \
                 the first {} episodes real only, then {} imagined per {} real, imagined \
                 transitions in the same replay buffer; model refit every {} real episode(s), \
                 {} minibatches of {} drawn from all real transitions; at most {} real episodes \
                 per run, each run stops once solved. F1 experiment: a with-model run of seed(s) \
                 {} that goes on past solved; copies of the model after {} real episodes, \
                 each scored on the next {} real episodes",
                words::list(&c.dqn.conv.channels),
                words::list(&c.dqn.hidden),
                c.dqn.learning_rate,
                c.dqn.gamma,
                c.dqn.buffer_size,
                c.dqn.exploration_initial_eps,
                c.dqn.exploration_final_eps,
                c.dqn.exploration_steps,
                c.dqn.train_freq,
                c.dqn.learning_starts,
                c.dqn.target_update_interval,
                words::list(&c.model.channels),
                c.model.features,
                c.model.factors,
                words::optimizer(&c.model.optimizer),
                c.model.threshold,
                c.real_only_episodes,
                c.imagined_per_cycle,
                c.real_per_cycle,
                c.fit_every,
                c.fit.steps,
                c.fit.batch_size,
                c.max_real_episodes,
                words::list(&quality.seeds),
                words::list(&quality.checkpoints),
                quality.heldout_episodes,
            ),
        }
    }
}

/// The maze's `--quick` configuration: a tiny model, 20 real episodes, F1 after 2 and 5.
pub fn quick_maze_config() -> (MazeConfig, QualityConfig) {
    let mut c = MazeConfig::default();
    c.model.channels = [4, 4, 4];
    c.model.features = 16;
    c.model.factors = 16;
    c.fit.steps = 2;
    c.real_only_episodes = 5;
    c.max_real_episodes = 20;
    c.solved_window = 10;
    c.dqn.learning_starts = 100;
    c.dqn.buffer_size = 2000;
    let q = QualityConfig {
        checkpoints: vec![2, 5],
        heldout_episodes: 2,
        ..QualityConfig::default()
    };
    (c, q)
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

/// F1 per channel of the pixel model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct F1Row {
    /// The agent (blue).
    pub agent: f64,
    /// The obstacles (red).
    pub obstacles: f64,
    /// The goal (green).
    pub goal: f64,
}

/// p2's table: the two methods and their ratio (and for the maze the pixel model's F1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct P2Table {
    /// The agent alone.
    pub model_free: MethodRow,
    /// The agent with imagined episodes.
    pub with_model: MethodRow,
    /// With-model over model-free mean episodes to solve.
    pub with_model_over_model_free: Ratio,
    /// The definition of "solved".
    pub solved: String,
    /// The maze's pixel model: F1 after `after_<n>` training episodes, mean over the seeds of
    /// the F1 experiment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f1: Option<std::collections::BTreeMap<String, F1Row>>,
}

/// The F1 table from the F1 experiment's seeds: means per number of training episodes.
pub fn f1_table(qs: &[Quality]) -> Option<std::collections::BTreeMap<String, F1Row>> {
    let first = qs.first()?;
    let n = qs.len() as f64;
    Some(
        first
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mean = |f: fn(&tandem_algos::imagined_pixels::QualityPoint) -> f64| {
                    qs.iter()
                        .filter_map(|q| q.points.get(i))
                        .map(f)
                        .sum::<f64>()
                        / n
                };
                (
                    format!("after_{}", p.episodes),
                    F1Row {
                        agent: mean(|p| p.agent),
                        obstacles: mean(|p| p.obstacles),
                        goal: mean(|p| p.goal),
                    },
                )
            })
            .collect(),
    )
}

fn method_row(records: &[RunRecord], m: Method, target: f64) -> (MethodRow, f64, bool) {
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
        episodes_to_solve: SamplesToTarget::from_seeds(target, per_seed, searched),
        mean_real_samples: runs.iter().map(|r| r.real_samples as f64).sum::<f64>() / n,
        mean_imagined_episodes: runs.iter().map(|r| r.imagined_episodes as f64).sum::<f64>() / n,
        seeds: runs.iter().map(|r| r.seed).collect(),
    };
    let short = runs.iter().any(|r| r.solved_at.is_none());
    (row, used.iter().sum::<f64>() / n, short)
}

/// The table from the runs' records, with "solved" at `target` (described by `solved`).
pub fn table(records: &[RunRecord], target: f64, solved: String) -> P2Table {
    let (model_free, mf, mf_short) = method_row(records, Method::ModelFree, target);
    let (with_model, wm, wm_short) = method_row(records, Method::WithModel, target);
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
        solved,
        f1: None,
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

/// p2's F1 table (Sec. 4.2): agent, obstacles, goal after 10, 100 and 300 training episodes.
const PAPER_F1: [(u64, [f64; 3]); 3] = [
    (10, [0.83, 0.22, 0.97]),
    (100, [0.92, 0.83, 0.99]),
    (300, [0.98, 0.93, 1.0]),
];

/// The table as Markdown, with the settings that matter and the wall time.
pub fn markdown(t: &P2Table, exp: Experiment, env: &str, settings: &str, wall: f64) -> String {
    let (paper_mf, paper_wm) = exp.paper();
    let agent = exp.agent();
    let alone = format!("{agent} alone");
    let with = format!("{agent} with the model");
    let rows = [
        (alone.as_str(), &t.model_free, paper_mf),
        (with.as_str(), &t.with_model, paper_wm),
    ];
    let n = t.model_free.seeds.len().max(t.with_model.seeds.len());
    let mut s = format!(
        "# p2 {}: real episodes to solve ({n} seeds)\n\nSolved: {}. Real episodes \
         are counted exactly; imagined episodes cost none. Mean ± standard error over the \
         seeds that solved it.\n\n| Method | Real episodes to solve | Paper | Imagined \
         episodes (mean) |\n|---|---|---|---|\n",
        env, t.solved
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
        "\nWith the model over alone ({}): {bound}{} (paper {paper_wm} / {paper_mf} = {:.2}).\n",
        q.note,
        q.ratio.map_or("n/a".into(), |r| format!("{r:.2}")),
        paper_wm as f64 / paper_mf as f64,
    ));
    if let Some(f1) = &t.f1 {
        s.push_str(
            "\nPixel model, F1 per channel on held-out real transitions (mean over the F1 \
             experiment's seeds; p2's in brackets):\n\n| Training episodes | Agent | Obstacles \
             | Goal |\n|---|---|---|---|\n",
        );
        for (key, r) in f1 {
            let eps: u64 = key.trim_start_matches("after_").parse().unwrap_or(0);
            let paper = PAPER_F1.iter().find(|(e, _)| *e == eps).map(|(_, v)| *v);
            let c = |v: f64, i: usize| match paper {
                Some(p) => format!("{v:.2} ({:.2})", p[i]),
                None => format!("{v:.2}"),
            };
            s.push_str(&format!(
                "| {eps} | {} | {} | {} |\n",
                c(r.agent, 0),
                c(r.obstacles, 1),
                c(r.goal, 2)
            ));
        }
    }
    s.push_str(&format!("\nSettings: {settings}. Wall time {wall:.0} s.\n"));
    s
}

/// Fig. 6 (CartPole) or 8 (maze): the mean over seeds of the training return (mean of the last
/// `window` real episodes) against real episodes, every 10 episodes.
pub fn curves(records: &[RunRecord], exp: Experiment, env: &str, window: usize) -> Figure {
    let w = window;
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
        title: format!(
            "p2 Fig. {}: {} on {}, alone and with the learned model",
            exp.figure().1,
            exp.agent(),
            env
        ),
        x_label: "real episodes".into(),
        y_label: format!("training return (mean of the last {w} real episodes)"),
        curves,
    }
}

/// Fig. 7: for each point of the F1 experiment, the shown held-out transition's last input
/// frame, its true next frame and the model's prediction (probabilities as colour intensity,
/// pixels at or above the threshold outlined). Channels are drawn as colours (red obstacles,
/// green goal, blue agent).
pub fn fig7(q: &Quality, threshold: f64) -> String {
    use std::fmt::Write as _;
    const PX: usize = 8; // screen pixels per image pixel
    let side = 16;
    let img = side * PX;
    let gap = 24;
    let cols = 3;
    let w = cols * img + (cols + 1) * gap + 110;
    let h = q.points.len() * (img + gap) + 2 * gap + 20;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        s,
        r#"<text x="{gap}" y="16">p2 Fig. 7: the pixel model's next frame after N training episodes (seed {})</text>"#,
        q.seed
    );
    for (c, label) in ["input (last frame)", "true next frame", "predicted"]
        .iter()
        .enumerate()
    {
        let x = 110 + gap + c * (img + gap);
        let _ = writeln!(s, r#"<text x="{x}" y="{}">{label}</text>"#, 2 * gap + 4);
    }
    let draw = |s: &mut String, x0: usize, y0: usize, frame: &[f32], outline: bool| {
        let _ = writeln!(
            s,
            r#"<rect x="{x0}" y="{y0}" width="{img}" height="{img}" fill="black"/>"#
        );
        for y in 0..side {
            for x in 0..side {
                let v = |c: usize| frame.get((y * side + x) * 3 + c).copied().unwrap_or(0.0);
                let (r, g, b) = (v(0), v(1), v(2));
                if r.max(g).max(b) <= 0.02 {
                    continue;
                }
                let q8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                let on = outline && f64::from(r.max(g).max(b)) >= threshold;
                let _ = writeln!(
                    s,
                    r##"<rect x="{}" y="{}" width="{PX}" height="{PX}" fill="#{:02x}{:02x}{:02x}"{}/>"##,
                    x0 + x * PX,
                    y0 + y * PX,
                    q8(r),
                    q8(g),
                    q8(b),
                    if on {
                        r#" stroke="white" stroke-width="0.5""#
                    } else {
                        ""
                    }
                );
            }
        }
    };
    for (i, p) in q.points.iter().enumerate() {
        let y0 = 2 * gap + 14 + i * (img + gap);
        let _ = writeln!(
            s,
            r#"<text x="{gap}" y="{}">after {}</text><text x="{gap}" y="{}">episodes</text>"#,
            y0 + img / 2 - 6,
            p.episodes,
            y0 + img / 2 + 10
        );
        let x = |c: usize| 110 + gap + c * (img + gap);
        draw(&mut s, x(0), y0, &p.shown_input, false);
        draw(&mut s, x(1), y0, &p.shown_truth, false);
        draw(&mut s, x(2), y0, &p.predicted, true);
    }
    s.push_str("</svg>\n");
    s
}

/// The F1 experiment's run (`runs/model_f1__seed<k>/`).
pub const F1_RUN: &str = "model_f1";

/// What a finished run leaves in `record.json`: a method's run, or the maze's F1 experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum P2Record {
    /// The pixel model's F1 experiment.
    Quality(Quality),
    /// A method's run.
    Run(RunRecord),
}

/// `tandem reproduce p2-cartpole` or `p2-maze` as a study of the shared [`harness`]: one job per
/// method and seed, and on the maze the F1 experiment on [`QualityConfig::seeds`].
pub struct P2Study {
    exp: Experiment,
    env: Option<String>,
}

impl P2Study {
    /// `exp`, on the maze `env` (`None`: the `--config` file's, `PixelMaze-v0`, or on
    /// `--resume` the recorded one).
    pub fn new(exp: Experiment, env: Option<String>) -> Self {
        Self { exp, env }
    }
}

impl Study for P2Study {
    type Settings = Settings;
    type Record = P2Record;

    fn name(&self) -> &str {
        self.exp.name()
    }

    fn default_seeds(&self) -> u64 {
        10
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<Settings> {
        Settings::new(self.exp, quick, self.env.as_deref(), config)
    }

    fn overrides_settings(&self) -> bool {
        self.env.is_some()
    }

    fn jobs(&self, s: &Settings, seed: u64) -> Vec<Vec<String>> {
        // The F1 experiment first: its job is the longest on PixelMaze-v0.
        let f1 = matches!(s, Settings::Maze { quality, .. } if quality.seeds.contains(&seed));
        f1.then(|| vec![F1_RUN.to_string()])
            .into_iter()
            .chain(Method::ALL.iter().map(|m| vec![m.name().to_string()]))
            .collect()
    }

    fn memory(&self, s: &Settings, run: &str) -> Result<MemoryEstimate> {
        let env = match s {
            Settings::CartPole(_) => tandem_envs::make("CartPole-v1")?,
            Settings::Maze { runs, .. } => tandem_robots::make(&runs.env)?,
        };
        let steps = env.max_episode_steps().unwrap_or(1000);
        Ok(match s {
            Settings::CartPole(c) => {
                let od = env.observation_space().flat_dim();
                let n = match env.action_space() {
                    tandem_core::Space::Discrete { n } => *n,
                    space => space.flat_dim(),
                };
                c.memory(od, n, steps)
            }
            Settings::Maze { runs, quality } => {
                let (episodes, prefix) = if run == F1_RUN {
                    (quality.episodes(), "quality: ")
                } else {
                    (runs.max_real_episodes, "")
                };
                MemoryEstimate::new().with(prefix, runs.memory(episodes, steps))
            }
        })
    }

    fn length(&self, s: &Settings, run: &str) -> u64 {
        match s {
            Settings::Maze { quality, .. } if run == F1_RUN => quality.episodes(),
            _ => s.solved().2,
        }
    }

    fn run(
        &self,
        s: &Settings,
        run: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<P2Record, JobError> {
        let mut on_event = |e: Event| {
            if let Event::Real { episode, .. } = e {
                progress(episode + 1);
            }
        };
        if run == F1_RUN {
            let Settings::Maze { runs, quality } = s else {
                return Err(JobError::Failed(format!("{run} runs on the maze only")));
            };
            let q = imagined_pixels::model_quality(runs, quality, seed, &*store, &mut on_event)?;
            return Ok(P2Record::Quality(q));
        }
        let method = Method::ALL
            .into_iter()
            .find(|m| m.name() == run)
            .ok_or_else(|| JobError::Failed(format!("unknown run {run}")))?;
        Ok(P2Record::Run(s.run(method, seed, store, &mut on_event)?))
    }

    fn curve(&self, r: &P2Record) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        match r {
            P2Record::Run(r) => {
                let rows = r
                    .real_returns
                    .iter()
                    .enumerate()
                    .map(|(k, ret)| vec![(k + 1) as f64, *ret])
                    .collect();
                (vec!["real_episode", "return"], rows)
            }
            P2Record::Quality(q) => {
                let rows = q
                    .points
                    .iter()
                    .map(|p| vec![p.episodes as f64, p.agent, p.obstacles, p.goal])
                    .collect();
                (
                    vec!["training_episodes", "agent", "obstacles", "goal"],
                    rows,
                )
            }
        }
    }

    fn report_files(&self) -> &'static [&'static str] {
        match self.exp {
            Experiment::CartPole => &["table.json", "table.md", "fig6.svg"],
            Experiment::Maze => &[
                "table.json",
                "table.md",
                "fig7.svg",
                "fig8.svg",
                "quality.json",
            ],
        }
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &Settings,
        records: &[P2Record],
        wall: f64,
    ) -> Result<String> {
        let exp = self.exp;
        let mut runs = Vec::new();
        let mut qualities = Vec::new();
        for r in records {
            match r {
                P2Record::Run(r) => runs.push(r.clone()),
                P2Record::Quality(q) => qualities.push(q.clone()),
            }
        }
        let (target, window, _) = s.solved();
        let mut t = table(&runs, target, s.solved_text());
        t.f1 = f1_table(&qualities);
        ensure_finite(&t).map_err(Error::other)?;
        let md = markdown(&t, exp, s.env(), &s.describe(), wall);
        let json = to_json_pretty(&t).map_err(|e| Error::Other(format!("table.json: {e}")))?;
        harness::write(dir, "table.json", &json)?;
        harness::write(dir, "table.md", &md)?;
        harness::write(
            dir,
            exp.figure().0,
            &curves(&runs, exp, s.env(), window).svg(),
        )?;
        if let (Settings::Maze { runs, .. }, Some(q)) = (s, qualities.first()) {
            harness::write(dir, "fig7.svg", &fig7(q, runs.model.threshold))?;
            let text = to_json_pretty(&qualities)
                .map_err(|e| Error::Other(format!("quality.json: {e}")))?;
            harness::write(dir, "quality.json", &text)?;
        }
        Ok(md)
    }
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
        let solved = Settings::CartPole(cfg.clone()).solved_text();
        let recs = [
            // Model-free: 600 and never within its 2000 episodes.
            record(Method::ModelFree, 0, 600, Some(600)),
            record(Method::ModelFree, 1, 2000, None),
            // With the model: 300 and 500.
            record(Method::WithModel, 0, 300, Some(300)),
            record(Method::WithModel, 1, 500, Some(500)),
        ];
        let t = table(&recs, cfg.solved_return, solved);
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
        let md = markdown(&t, Experiment::CartPole, "CartPole-v1", "s", 1.0);
        assert!(md.contains("at most 0.31"), "{md}");
        assert!(md.contains("- REINFORCE alone: 600, never"), "{md}");
        // The JSON keys each method's episodes to solve, null for the seed that never solved it.
        let v: serde_json::Value = serde_json::from_str(&to_json_pretty(&t).unwrap()).unwrap();
        assert_eq!(
            v["model_free"]["episodes_to_solve"]["per_seed"][1],
            serde_json::Value::Null
        );
        assert_eq!(v["with_model"]["episodes_to_solve"]["mean"], 400.0);
    }

    fn point(episodes: u64, agent: f64) -> tandem_algos::imagined_pixels::QualityPoint {
        let mut truth = vec![0.0f32; 768];
        truth[(3 * 16 + 5) * 3 + 2] = 1.0; // one blue (agent) pixel at row 3, column 5
        tandem_algos::imagined_pixels::QualityPoint {
            episodes,
            transitions: 10 * episodes,
            heldout_transitions: 100,
            agent,
            obstacles: 0.5,
            goal: 1.0,
            shown_input: vec![0.0; 768],
            shown_truth: truth,
            predicted: vec![0.0; 768],
        }
    }

    #[test]
    fn the_f1_table_averages_the_seeds_and_fig7_draws_the_frames() {
        let q = |seed, a10, a100| Quality {
            seed,
            points: vec![point(10, a10), point(100, a100)],
            real_returns: vec![],
            wall_seconds: 1.0,
        };
        let t = f1_table(&[q(0, 0.2, 0.8), q(1, 0.4, 1.0)]).unwrap();
        assert_eq!(t.keys().collect::<Vec<_>>(), ["after_10", "after_100"]);
        assert!((t["after_10"].agent - 0.3).abs() < 1e-12);
        assert!((t["after_100"].agent - 0.9).abs() < 1e-12);
        assert_eq!(t["after_100"].goal, 1.0);
        assert!(f1_table(&[]).is_none());
        let svg = fig7(&q(0, 0.2, 0.8), 0.2);
        // The one lit pixel of the true frame, blue, at 8 screen pixels per image pixel.
        assert_eq!(svg.matches("fill=\"#0000ff\"").count(), 2, "{svg}");
        assert!(svg.contains("after 100") && svg.ends_with("</svg>\n"));
    }

    /// The committed maze results (`results/p2-maze/`) read back as a table, with the F1 table.
    #[test]
    fn the_committed_maze_table_reads_back() {
        let text = include_str!("../../../results/p2-maze/table.json");
        let t: P2Table = serde_json::from_str(text).unwrap();
        assert_eq!(t.model_free.episodes_to_solve.seeds, 10);
        let f1 = t.f1.as_ref().unwrap();
        assert_eq!(
            f1.keys().collect::<Vec<_>>(),
            ["after_10", "after_100", "after_300"]
        );
        assert_eq!(to_json_pretty(&t).unwrap().trim_end(), text.trim_end());
    }

    /// The settings line of every committed p2 table, including those whose runs are not
    /// committed and so cannot be merged again, is what `describe` writes today for the
    /// settings its `config.json` records.
    #[test]
    fn the_committed_tables_state_their_settings_as_described() {
        let dirs = [
            (
                include_str!("../../../results/p2-cartpole/config.json"),
                include_str!("../../../results/p2-cartpole/table.md"),
            ),
            (
                include_str!("../../../results/p2-maze/config.json"),
                include_str!("../../../results/p2-maze/table.md"),
            ),
            (
                include_str!("../../../results/p2-maze-v1/layers/full/config.json"),
                include_str!("../../../results/p2-maze-v1/layers/full/table.md"),
            ),
            (
                include_str!("../../../results/p2-maze-v1/layers/strided/config.json"),
                include_str!("../../../results/p2-maze-v1/layers/strided/table.md"),
            ),
        ];
        for (config, table) in dirs {
            let config: serde_json::Value = serde_json::from_str(config).unwrap();
            let settings: Settings = serde_json::from_value(config["config"].clone()).unwrap();
            let line = format!("Settings: {}.", settings.describe());
            assert!(table.contains(&line), "{line}\nnot in\n{table}");
            assert!(!line.contains("Config {"), "{line}");
        }
    }

    /// The committed results (`results/p2-cartpole/`) read back as a table.
    #[test]
    fn the_committed_table_reads_back() {
        let text = include_str!("../../../results/p2-cartpole/table.json");
        let t: P2Table = serde_json::from_str(text).unwrap();
        assert_eq!(t.model_free.episodes_to_solve.seeds, 10);
        assert_eq!(t.with_model.episodes_to_solve.seeds, 10);
        assert_eq!(to_json_pretty(&t).unwrap().trim_end(), text.trim_end());
    }
}
