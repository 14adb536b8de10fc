//! `tandem reproduce p1`: p1's comparison (its Fig. 1) of Dyna-SAC with the deep incremental
//! model against SAC and MBPO on a gymnasium MuJoCo task, on the same seeds, real-step budget and
//! SAC updates per real step, through the shared [`crate::harness`] (resume, separate processes
//! per seed, merge).
//!
//! Writes, besides the harness' `config.json`, `runs/` and `state/`:
//!
//! - `table.md`, `table.json`: per method (`sac`, `mbpo`, `incremental_dyna`) the return at the
//!   budget and the real steps to SAC's mean return at the budget (p0's table layout), and how
//!   many times more real steps SAC and MBPO needed than Dyna-SAC;
//! - `fig1.svg`: the mean return against real steps with ± standard error bands (p1 Fig. 1).
//!
//! SAC and MBPO run the shared loop with the settings `p3-mujoco` uses on the same task, so their
//! runs are number for number those of `tandem reproduce p3-mujoco` for the same seeds.

use std::path::Path;

use crate::report::{words, Figure, MarkdownText};
use crate::run::RunDir;
use serde::{Deserialize, Serialize};
use tandem_algos::incremental_dyna::{run, Method, P1Config};
use tandem_algos::mbpo::{mujoco_problem, RunRecord};
use tandem_algos::Checkpoints;

use crate::harness::{self, JobError, Study};
use crate::p3::{
    check_target_method, loop_sentence, mujoco_ids, mujoco_loop, quick_loop, rates_and_wall,
    runs_table, seconds_per_seed, step_progress, target_of, target_sentence,
};
use crate::{Error, Result};
use tandem_nn::budget::MemoryEstimate;

/// Everything that decides a p1 study's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct P1Settings {
    /// The gymnasium MuJoCo task.
    pub env: String,
    /// The loop all methods share (`p3-mujoco`'s for the task) and the incremental model.
    pub p1: P1Config,
    /// The return whose first evaluation at or above it counts as reached, where
    /// `target_method` has no runs.
    pub target_return: f64,
    /// The run whose mean return at the budget is the target (`sac`: "reaches SAC's final return
    /// in half the real steps"); `None`: `target_return`.
    pub target_method: Option<String>,
}

impl P1Settings {
    /// p1's settings on the MuJoCo task `env`; `None` for a task the study does not run.
    pub fn mujoco(env: &str) -> Option<Self> {
        let (base, target_return) = mujoco_loop(env)?;
        Some(Self {
            env: env.into(),
            p1: P1Config {
                base,
                ..P1Config::default()
            },
            target_return,
            target_method: Some(Method::Sac.name().into()),
        })
    }

    /// The `--quick` settings: the loop at toy sizes, the incremental model 16×16.
    pub fn quick(mut self) -> Self {
        quick_loop(&mut self.p1.base);
        self.p1.model.hidden = vec![16, 16];
        self
    }

    /// Checks what the runs rely on.
    fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::input(what, m));
        self.p1
            .validate()
            .map_err(|e| Error::input(what, e.to_string()))?;
        if mujoco_loop(&self.env).is_none() {
            return bad(format!("env {}: p1 runs {}", self.env, mujoco_ids()));
        }
        if let Err(e) = mujoco_problem(&self.env) {
            return bad(e.to_string());
        }
        if !self.target_return.is_finite() {
            return bad(format!(
                "target_return {} must be finite",
                self.target_return
            ));
        }
        let known: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        check_target_method(self.target_method.as_deref(), &known).or_else(bad)?;
        Ok(())
    }
}

/// The p1 study on a MuJoCo task (`None`: HalfCheetah-v5, or the recorded task on `--resume`).
pub struct P1Study {
    env: Option<String>,
}

impl P1Study {
    /// `p1` on `env`.
    pub fn new(env: Option<String>) -> Self {
        Self { env }
    }
}

/// The default task.
const DEFAULT_ENV: &str = "HalfCheetah-v5";

impl Study for P1Study {
    type Settings = P1Settings;
    type Record = RunRecord;

    fn name(&self) -> &str {
        "p1"
    }

    fn default_seeds(&self) -> u64 {
        3
    }

    fn settings(&self, quick: bool, config: Option<&Path>) -> Result<P1Settings> {
        let env = self.env.as_deref().unwrap_or(DEFAULT_ENV);
        let base = P1Settings::mujoco(env)
            .ok_or_else(|| Error::input("--env", format!("{env}: p1 runs {}", mujoco_ids())))?;
        let base = if quick { base.quick() } else { base };
        let s = harness::read_overrides(base, config)?;
        let what = harness::settings_name(config);
        s.validate(&what)?;
        Ok(s)
    }

    fn overrides_settings(&self) -> bool {
        self.env.is_some()
    }

    fn jobs(&self, _s: &P1Settings, _seed: u64) -> Vec<Vec<String>> {
        Method::ALL
            .iter()
            .map(|m| vec![m.name().to_string()])
            .collect()
    }

    fn memory(&self, s: &P1Settings, run: &str) -> Result<MemoryEstimate> {
        let method = Method::ALL
            .into_iter()
            .find(|m| m.name() == run)
            .ok_or_else(|| Error::Other(format!("unknown run {run}")))?;
        let (od, ad) = crate::p3::mujoco_dims(&s.env)?;
        Ok(MemoryEstimate::new().with("p1.", s.p1.memory(method, od, ad)))
    }

    fn length(&self, s: &P1Settings, _run: &str) -> u64 {
        s.p1.base.real_steps
    }

    fn run(
        &self,
        s: &P1Settings,
        run_name: &str,
        seed: u64,
        store: &mut dyn Checkpoints,
        progress: &mut dyn FnMut(u64),
    ) -> std::result::Result<RunRecord, JobError> {
        let method = Method::ALL
            .into_iter()
            .find(|m| m.name() == run_name)
            .ok_or_else(|| JobError::Failed(format!("unknown run {run_name}")))?;
        let problem = mujoco_problem(&s.env)?;
        Ok(run(
            method,
            &problem,
            &s.p1,
            seed,
            store,
            &mut step_progress(progress),
        )?)
    }

    fn curve(&self, r: &RunRecord) -> (Vec<&'static str>, Vec<Vec<f64>>) {
        harness::curve_rows("real_steps", &r.curve)
    }

    fn report_files(&self) -> &'static [&'static str] {
        &["table.json", "table.md", "fig1.svg"]
    }

    fn report(
        &self,
        dir: &RunDir,
        s: &P1Settings,
        records: &[RunRecord],
        wall: f64,
    ) -> Result<String> {
        let b = &s.p1.base;
        let target = target_of(
            records,
            b.real_steps,
            s.target_return,
            s.target_method.as_deref(),
        );
        let names: Vec<String> = Method::ALL.iter().map(|m| m.name().to_string()).collect();
        let t = runs_table(
            records,
            &names,
            b.real_steps,
            target,
            None,
            Method::IncrementalDyna.name(),
            &[Method::Sac.name(), Method::Mbpo.name()],
        );
        let md = markdown(&t, s, records, wall);
        harness::write_table(dir, &t, &md)?;
        let main: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        let curves = harness::mean_curves(records, &main, |r| (r.method.as_str(), &r.curve));
        let fig = Figure {
            title: format!("p1 Fig. 1: {}, SAC, MBPO and incremental Dyna-SAC", s.env),
            x_label: "real steps".into(),
            y_label: "return per episode".into(),
            curves,
        };
        harness::write(dir, "fig1.svg", &fig.svg())?;
        Ok(md)
    }
}

/// The labels of the three methods.
const LABELS: [(&str, &str); 3] = [
    ("sac", "SAC"),
    ("mbpo", "MBPO"),
    ("incremental_dyna", "Dyna-SAC, incremental model"),
];

/// The table as Markdown with p1's words, the settings that matter and the wall time.
fn markdown(t: &crate::report::Table, s: &P1Settings, records: &[RunRecord], wall: f64) -> String {
    let b = &s.p1.base;
    let n_seeds = t.methods.values().map(|m| m.seeds.len()).max().unwrap_or(0);
    let m = &s.p1.model;
    let closing = vec![
        format!(
            "{}, minibatches {} % real data for the model-based methods; models refit every {} \
             real steps on all real data; MBPO an ensemble of {} ({} elites) of {}, {} \
             rollouts per real step of length {} → {}; Dyna-SAC the incremental model \
             `s + L(s, a_prev) Δa` ({} {} units, {} L), {} one-step rollouts per real \
             step, the task's reward.",
            loop_sentence(b),
            b.real_ratio * 100.0,
            b.model_train_freq,
            b.ensemble.members,
            b.ensemble.elites,
            words::list(&b.ensemble.hidden),
            b.rollouts_per_step,
            b.rollout_length.start,
            b.rollout_length.end,
            words::list(&m.hidden),
            words::activation(m.activation),
            words::gain_structure(m.structure),
            b.rollouts_per_step,
        ),
        target_sentence(t, s.target_method.as_deref(), &LABELS),
        format!(
            "p1 reports its method faster than SAC and close to MBPO. {}",
            rates_and_wall(records, &LABELS, wall)
        ),
        seconds_per_seed(records, &LABELS),
    ];
    t.markdown(&MarkdownText {
        title: format!("p1 on {} ({n_seeds} seeds)", s.env),
        intro: "Mean return of the deterministic policy over episodes of the task. Real steps \
                are counted exactly; model transitions cost none. Mean ± standard error over \
                seeds."
            .into(),
        labels: &LABELS,
        comparison_intro: "Real steps to the target relative to Dyna-SAC with the incremental \
                           model (means over seeds; a seed that never reached it counts at the \
                           steps it used)"
            .into(),
        comparison_order: &["sac", "mbpo"],
        closing,
    })
}
