//! Reproduction reports, shared by every `tandem reproduce <paper>`: a results [`Table`] (the
//! methods' figures at a fixed sample budget and at a fixed target return, an optional reference
//! level, and sample ratios between methods) and a [`Figure`] of learning curves. Each is a typed
//! value; the table is written as JSON ([`Table::to_json`], read back by [`Table::from_json`])
//! and rendered as Markdown ([`Table::markdown`]), the figure as SVG ([`Figure::svg`]). A paper
//! supplies only its words ([`MarkdownText`]) and the per-seed figures.
//!
//! Every number is checked before it is written ([`finite`]): a NaN would otherwise reach the
//! JSON as `null`, indistinguishable from "not reached".

pub mod finite;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::run::{svg_chart, Series};

pub mod gait;
pub mod words;

pub use finite::{ensure_finite, to_json_pretty, NonFinite};

/// Why a report could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A number about to be written is NaN or infinite.
    #[error(transparent)]
    NonFinite(#[from] NonFinite),
    /// A table file that does not have a table's shape.
    #[error("{what}: {message}")]
    Malformed {
        /// The file.
        what: String,
        /// What is wrong, naming the key.
        message: String,
    },
}

/// Mean and standard error of the mean (sample standard deviation over √n; 0 for one value,
/// NaN for none).
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

/// The return each seed reached with a fixed sample budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnAtBudget {
    /// The budget (samples of the system the paper counts).
    pub budget: u64,
    /// One return per seed, in seed order (before the mean, so that a missing seed is the
    /// number a finiteness check names).
    pub per_seed: Vec<f64>,
    /// Mean over seeds.
    pub mean: f64,
    /// Standard error of that mean.
    pub stderr: f64,
}

impl ReturnAtBudget {
    /// The figure from one return per seed.
    pub fn from_seeds(budget: u64, per_seed: Vec<f64>) -> Self {
        let (mean, stderr) = mean_stderr(&per_seed);
        Self {
            budget,
            mean,
            stderr,
            per_seed,
        }
    }
}

/// The samples each seed needed to reach a fixed target return.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SamplesToTarget {
    /// The target return.
    pub target: f64,
    /// Mean over the seeds that reached it (`None` if none did).
    pub mean: Option<f64>,
    /// Standard error of that mean (`None` if no seed reached it).
    pub stderr: Option<f64>,
    /// Per seed, `None` where the seed never reached the target.
    pub per_seed: Vec<Option<u64>>,
    /// How many seeds reached it.
    pub reached: usize,
    /// How many seeds ran.
    pub seeds: usize,
    /// The most samples any seed used: a seed that never reached the target needs more.
    pub searched_up_to: u64,
}

impl SamplesToTarget {
    /// The figure from the per-seed samples (`None`: never reached within `searched_up_to`).
    pub fn from_seeds(target: f64, per_seed: Vec<Option<u64>>, searched_up_to: u64) -> Self {
        let reached: Vec<f64> = per_seed.iter().flatten().map(|&v| v as f64).collect();
        let (mean, stderr) = mean_stderr(&reached);
        let some = !reached.is_empty();
        Self {
            target,
            mean: some.then_some(mean),
            stderr: some.then_some(stderr),
            seeds: per_seed.len(),
            reached: reached.len(),
            per_seed,
            searched_up_to,
        }
    }
}

/// One method's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodFigures {
    /// Return at the fixed budget.
    pub return_at_budget: ReturnAtBudget,
    /// Samples to the fixed target.
    pub samples_to_target: SamplesToTarget,
    /// The seeds, in the order of the per-seed lists.
    pub seeds: Vec<u64>,
    /// Mean return over the seeds at each epoch where every seed was evaluated (p3's leg:
    /// return against epochs); empty, and left out of the JSON, where a study has no epochs.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub return_at_epoch: BTreeMap<u64, f64>,
}

/// What one seed's run of a method contributes to [`MethodFigures::from_runs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeedRun {
    /// The seed.
    pub seed: u64,
    /// Samples the run used in all.
    pub samples: u64,
    /// Its return at the budget (`NaN` if it has none: the finiteness check of the table names
    /// it).
    pub return_at_budget: f64,
    /// Samples at its first evaluation that reached the target.
    pub samples_to_target: Option<u64>,
}

impl MethodFigures {
    /// A method's figures from its seeds' runs, with the mean samples to the target where a seed
    /// that never reached it counts at the samples it used, and whether any seed fell short (the
    /// inputs of a [`Comparison`]).
    pub fn from_runs(budget: u64, target: f64, runs: &[SeedRun]) -> (Self, f64, bool) {
        let to: Vec<Option<u64>> = runs.iter().map(|r| r.samples_to_target).collect();
        let searched = runs.iter().map(|r| r.samples).max().unwrap_or(0);
        let used: Vec<f64> = runs
            .iter()
            .map(|r| r.samples_to_target.unwrap_or(r.samples) as f64)
            .collect();
        let mean_used = used.iter().sum::<f64>() / used.len().max(1) as f64;
        let short = to.iter().any(Option::is_none);
        let figures = Self {
            return_at_budget: ReturnAtBudget::from_seeds(
                budget,
                runs.iter().map(|r| r.return_at_budget).collect(),
            ),
            samples_to_target: SamplesToTarget::from_seeds(target, to, searched),
            seeds: runs.iter().map(|r| r.seed).collect(),
            return_at_epoch: BTreeMap::new(),
        };
        (figures, mean_used, short)
    }
}

/// A reference level the methods are measured against (e.g. a baseline after all its samples).
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// What the reference is, in words.
    pub what: String,
    /// Samples used to reach it.
    pub true_samples: u64,
    /// How many final evaluations are averaged per seed.
    pub last_evaluations: usize,
    /// Mean over seeds.
    pub mean: f64,
    /// Standard error of that mean.
    pub stderr: f64,
    /// One value per seed.
    pub per_seed: Vec<f64>,
    /// Per method, |return at budget − reference| / |reference| (`None`: not defined);
    /// written as `<method>_relative_gap`.
    pub relative_gaps: BTreeMap<String, Option<f64>>,
}

/// How many times more samples a baseline needed to reach the target than a method.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The baseline (numerator); with `method`, the JSON key is `<baseline>_over_<method>`.
    pub baseline: String,
    /// The method (denominator).
    pub method: String,
    /// `baseline_mean_samples / method_mean_samples` (`None` when the method needed none).
    pub ratio: Option<f64>,
    /// The baseline's mean samples to the target.
    pub baseline_mean_samples: f64,
    /// The method's mean samples to the target (written as `<method>_mean_samples`).
    pub method_mean_samples: f64,
    /// Whether the ratio is only a lower bound (a baseline seed never reached the target and
    /// counts with the samples it used, while every seed of the method reached it).
    pub lower_bound: bool,
    /// How the means were taken.
    pub note: String,
}

impl Comparison {
    /// The comparison of `baseline` with `method` from their mean samples and whether any of
    /// their seeds fell short (and so counts with the samples it used).
    pub fn new(
        (baseline, baseline_mean, baseline_short): (&str, f64, bool),
        (method, method_mean, method_short): (&str, f64, bool),
        note: &str,
    ) -> Self {
        Self {
            baseline: baseline.into(),
            method: method.into(),
            ratio: (method_mean > 0.0).then(|| baseline_mean / method_mean),
            baseline_mean_samples: baseline_mean,
            method_mean_samples: method_mean,
            lower_bound: baseline_short && !method_short,
            note: note.into(),
        }
    }

    /// `"<label> 2.5×"` (`"<label> ≥ 2.5×"` for a lower bound), `label` naming the baseline;
    /// `None` without a ratio.
    pub fn ratio_text(&self, label: &str) -> Option<String> {
        let ge = if self.lower_bound { "≥ " } else { "" };
        Some(format!("{label} {ge}{:.1}×", self.ratio?))
    }
}

/// A results table: methods by name, an optional reference, comparisons.
///
/// JSON: one object whose keys are the method names, `reference`, and `<baseline>_over_<method>`
/// for each comparison (so a method's name must not be `reference` nor contain `_over_`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    /// Each method's figures, by name.
    pub methods: BTreeMap<String, MethodFigures>,
    /// The reference level, if the paper has one.
    pub reference: Option<Reference>,
    /// Sample ratios between methods.
    pub comparisons: Vec<Comparison>,
}

const REFERENCE: &str = "reference";
const OVER: &str = "_over_";
const GAP: &str = "_relative_gap";
const MEAN_SAMPLES: &str = "_mean_samples";

fn malformed(what: &str, message: impl std::fmt::Display) -> ReportError {
    ReportError::Malformed {
        what: what.into(),
        message: message.to_string(),
    }
}

/// A JSON value from anything serializable (numbers already checked finite).
fn value(v: impl Serialize) -> Value {
    serde_json::to_value(v).unwrap_or(Value::Null)
}

/// The reference's JSON fields other than the gaps.
#[derive(Serialize, Deserialize)]
struct ReferenceFields {
    what: String,
    true_samples: u64,
    last_evaluations: usize,
    mean: f64,
    stderr: f64,
    per_seed: Vec<f64>,
    #[serde(flatten)]
    rest: BTreeMap<String, Option<f64>>,
}

/// A comparison's JSON fields other than the method's mean.
#[derive(Serialize, Deserialize)]
struct ComparisonFields {
    ratio: Option<f64>,
    baseline_mean_samples: f64,
    lower_bound: bool,
    note: String,
    #[serde(flatten)]
    rest: BTreeMap<String, f64>,
}

impl Table {
    /// The table as a JSON object (keys sorted), or an error naming a non-finite number.
    pub fn to_json_value(&self) -> Result<Value, ReportError> {
        ensure_finite(&self.methods)?;
        let mut out = serde_json::Map::new();
        for (name, m) in &self.methods {
            out.insert(name.clone(), value(m));
        }
        if let Some(r) = &self.reference {
            let rest = r
                .relative_gaps
                .iter()
                .map(|(m, g)| (format!("{m}{GAP}"), *g))
                .collect();
            let fields = ReferenceFields {
                what: r.what.clone(),
                true_samples: r.true_samples,
                last_evaluations: r.last_evaluations,
                mean: r.mean,
                stderr: r.stderr,
                per_seed: r.per_seed.clone(),
                rest,
            };
            ensure_finite(&fields).map_err(|e| e.within(REFERENCE))?;
            out.insert(REFERENCE.into(), value(fields));
        }
        for c in &self.comparisons {
            let key = format!("{}{OVER}{}", c.baseline, c.method);
            let fields = ComparisonFields {
                ratio: c.ratio,
                baseline_mean_samples: c.baseline_mean_samples,
                lower_bound: c.lower_bound,
                note: c.note.clone(),
                rest: [(format!("{}{MEAN_SAMPLES}", c.method), c.method_mean_samples)].into(),
            };
            ensure_finite(&fields).map_err(|e| e.within(&key))?;
            out.insert(key, value(fields));
        }
        Ok(Value::Object(out))
    }

    /// The table as pretty JSON (`table.json`).
    pub fn to_json(&self) -> Result<String, ReportError> {
        let v = self.to_json_value()?;
        serde_json::to_string_pretty(&v).map_err(|e| malformed("table", e))
    }

    /// Reads a table written by [`Table::to_json`]; `what` names the input in errors.
    pub fn from_json(text: &str, what: &str) -> Result<Self, ReportError> {
        let map: BTreeMap<String, Value> =
            serde_json::from_str(text).map_err(|e| malformed(what, e))?;
        let mut t = Table::default();
        for (key, v) in map {
            let bad = |e: serde_json::Error| malformed(what, format!("`{key}`: {e}"));
            if key == REFERENCE {
                let f: ReferenceFields = serde_json::from_value(v).map_err(bad)?;
                let mut relative_gaps = BTreeMap::new();
                for (k, g) in f.rest {
                    let m = k.strip_suffix(GAP).ok_or_else(|| {
                        malformed(what, format!("`{REFERENCE}.{k}`: unknown key"))
                    })?;
                    relative_gaps.insert(m.to_string(), g);
                }
                t.reference = Some(Reference {
                    what: f.what,
                    true_samples: f.true_samples,
                    last_evaluations: f.last_evaluations,
                    mean: f.mean,
                    stderr: f.stderr,
                    per_seed: f.per_seed,
                    relative_gaps,
                });
            } else if let Some((baseline, method)) = key.split_once(OVER) {
                let f: ComparisonFields = serde_json::from_value(v).map_err(bad)?;
                let mean_key = format!("{method}{MEAN_SAMPLES}");
                let method_mean_samples = match f.rest.get(&mean_key) {
                    Some(&x) if f.rest.len() == 1 => x,
                    _ => {
                        return Err(malformed(
                            what,
                            format!("`{key}`: expected `{mean_key}` and no other extra key"),
                        ))
                    }
                };
                t.comparisons.push(Comparison {
                    baseline: baseline.into(),
                    method: method.into(),
                    ratio: f.ratio,
                    baseline_mean_samples: f.baseline_mean_samples,
                    method_mean_samples,
                    lower_bound: f.lower_bound,
                    note: f.note,
                });
            } else {
                t.methods
                    .insert(key.clone(), serde_json::from_value(v).map_err(bad)?);
            }
        }
        Ok(t)
    }

    /// The table as Markdown: the figures at the fixed budget and at the fixed return (one row
    /// per method, in `text.labels` order), the samples to the target per seed, the comparisons,
    /// then the paper's closing paragraphs.
    pub fn markdown(&self, text: &MarkdownText) -> String {
        let rows: Vec<(&str, &MethodFigures)> = text
            .labels
            .iter()
            .filter_map(|(name, label)| Some((*label, self.methods.get(*name)?)))
            .collect();
        let mut s = format!(
            "# {}\n\n{}\n\n| Method | Sample budget | Return |\n|---|---|---|\n",
            text.title, text.intro
        );
        s.push_str("| *Fixed budget* | | |\n");
        for (label, m) in &rows {
            let r = &m.return_at_budget;
            s.push_str(&format!(
                "| {label} | {} | {:.1} ± {:.1} |\n",
                r.budget, r.mean, r.stderr
            ));
        }
        s.push_str("| *Fixed return* | | |\n");
        for (label, m) in &rows {
            let r = &m.samples_to_target;
            let cell = match r.mean {
                Some(mean) => format!(
                    "{mean:.0} ± {:.0} ({}/{} seeds reached it)",
                    r.stderr.unwrap_or(0.0),
                    r.reached,
                    r.seeds
                ),
                None => format!("> {} (no seed reached it)", r.searched_up_to),
            };
            s.push_str(&format!("| {label} | {cell} | {:.1} |\n", r.target));
        }
        s.push_str("\nTrue samples to the target, per seed:\n\n");
        for (label, m) in &rows {
            let per_seed: Vec<String> = m
                .samples_to_target
                .per_seed
                .iter()
                .map(|x| x.map_or("never".to_string(), |v| v.to_string()))
                .collect();
            s.push_str(&format!("- {label}: {}\n", per_seed.join(", ")));
        }
        let ratios: Vec<String> = text
            .comparison_order
            .iter()
            .filter_map(|b| {
                let c = self.comparisons.iter().find(|c| c.baseline == *b)?;
                c.ratio_text(text.label(b))
            })
            .collect();
        if !ratios.is_empty() {
            s.push_str(&format!(
                "\n{}: {}.\n",
                text.comparison_intro,
                ratios.join(", ")
            ));
        }
        for p in &text.closing {
            s.push('\n');
            s.push_str(p);
            s.push('\n');
        }
        s
    }
}

/// A paper's words around its table.
#[derive(Debug, Clone)]
pub struct MarkdownText<'a> {
    /// The heading.
    pub title: String,
    /// The paragraph under it (what the return is, how samples are counted).
    pub intro: String,
    /// `(method name, label)`, in row order.
    pub labels: &'a [(&'a str, &'a str)],
    /// The sentence introducing the comparisons, without the final colon.
    pub comparison_intro: String,
    /// The baselines whose comparisons the sentence lists, in order.
    pub comparison_order: &'a [&'a str],
    /// Paragraphs after the table (reference, how the runs were evaluated, wall time).
    pub closing: Vec<String>,
}

impl MarkdownText<'_> {
    /// The label of method `name` (the name itself if it has none).
    pub fn label<'s>(&'s self, name: &'s str) -> &'s str {
        self.labels
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(name, |(_, l)| l)
    }
}

/// One point of a mean learning curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Samples.
    pub x: f64,
    /// Mean over the seeds that have a point at `x`.
    pub mean: f64,
    /// Standard error of that mean.
    pub stderr: f64,
}

/// A method's learning curve: mean ± standard error over seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// Legend text.
    pub name: String,
    /// Points in increasing `x`.
    pub points: Vec<CurvePoint>,
}

impl Curve {
    /// The mean curve of several seeds' curves (`(samples, return)` points each): at every
    /// sample count where some seed has a point, the mean and standard error over those seeds.
    pub fn mean_over_seeds(name: &str, seeds: &[Vec<(u64, f64)>]) -> Self {
        let mut xs: Vec<u64> = seeds.iter().flatten().map(|p| p.0).collect();
        xs.sort_unstable();
        xs.dedup();
        let points = xs
            .into_iter()
            .map(|x| {
                let ys: Vec<f64> = seeds
                    .iter()
                    .filter_map(|c| c.iter().find(|p| p.0 == x))
                    .map(|p| p.1)
                    .collect();
                let (mean, stderr) = mean_stderr(&ys);
                CurvePoint {
                    x: x as f64,
                    mean,
                    stderr,
                }
            })
            .collect();
        Self {
            name: name.into(),
            points,
        }
    }
}

/// A figure of learning curves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    /// The title.
    pub title: String,
    /// The x axis' label.
    pub x_label: String,
    /// The y axis' label.
    pub y_label: String,
    /// One curve per method.
    pub curves: Vec<Curve>,
}

impl Figure {
    /// The figure as SVG: each curve's mean as a line, ± standard error as a band.
    pub fn svg(&self) -> String {
        let series: Vec<Series> = self
            .curves
            .iter()
            .map(|c| Series {
                name: c.name.clone(),
                points: c.points.iter().map(|p| (p.x, p.mean)).collect(),
                band: c
                    .points
                    .iter()
                    .map(|p| (p.x, p.mean - p.stderr, p.mean + p.stderr))
                    .collect(),
            })
            .collect();
        svg_chart(&self.title, &self.x_label, &self.y_label, &series)
    }
}
