//! Building, checking and splitting [`Transitions`].

use ndarray::{Array1, Array2, ArrayView2, Axis};
use rand::seq::SliceRandom;
use tandem_core::{first_non_finite, Rng};

use crate::model::{ModelError, ModelInput, Transitions};

/// Checks a `rows x cols` array: the column count, then every value finite (the first bad row is
/// named).
pub(crate) fn check_array(
    what: &str,
    a: ArrayView2<'_, f64>,
    rows: usize,
    cols: usize,
) -> Result<(), ModelError> {
    if a.ncols() != cols {
        return Err(ModelError::Dim {
            what: format!("{what} (columns)"),
            expected: cols,
            got: a.ncols(),
        });
    }
    if a.nrows() != rows {
        return Err(ModelError::Dim {
            what: format!("{what} (rows)"),
            expected: rows,
            got: a.nrows(),
        });
    }
    let bad_row = match a.as_slice() {
        Some(all) => first_non_finite(all).map(|i| i / cols),
        None => a
            .outer_iter()
            .position(|r| r.iter().any(|v| !v.is_finite())),
    };
    if let Some(row) = bad_row {
        return Err(ModelError::NonFinite {
            what: what.to_string(),
            row,
        });
    }
    Ok(())
}

/// Checks a prediction batch against a model's widths; returns the batch size.
pub(crate) fn check_input(
    input: &ModelInput<'_>,
    state_dim: usize,
    action_dim: usize,
) -> Result<usize, ModelError> {
    let b = input.states.nrows();
    check_array("input states", input.states, b, state_dim)?;
    check_array("input actions", input.actions, b, action_dim)?;
    Ok(b)
}

/// The arrays as named tensors (`f64`, `terminated` as bytes). Loading checks the shapes
/// against each other and the values for finiteness (a non-empty set must pass
/// [`Transitions::validate`]).
impl tandem_nn::Checkpointable for Transitions {
    fn save_to(&self, prefix: &str, ckpt: &mut tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        for (name, a) in self.matrices() {
            let flat: Vec<f64> = a.iter().copied().collect();
            ckpt.put_f64(&format!("{prefix}.{name}"), &[a.nrows(), a.ncols()], &flat)?;
        }
        let n = self.rewards.len();
        ckpt.put_f64(&format!("{prefix}.rewards"), &[n], &self.rewards.to_vec())?;
        let done: Vec<u8> = self.terminated.iter().map(|&t| u8::from(t)).collect();
        ckpt.put_bytes(&format!("{prefix}.terminated"), &done)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &tandem_nn::Checkpoint) -> tandem_nn::Result<()> {
        let matrix = |name: &str| -> tandem_nn::Result<Array2<f64>> {
            let name = format!("{prefix}.{name}");
            let shape = ckpt.shape(&name)?.to_vec();
            let data = ckpt.get_f64(&name, None)?;
            match shape[..] {
                [r, c] => Ok(Array2::from_shape_vec((r, c), data).expect("shape checked on read")),
                _ => Err(tandem_nn::NnError::Checkpoint(format!(
                    "`{name}` has shape {shape:?}, a matrix was expected"
                ))),
            }
        };
        let t = Transitions {
            states: matrix("states")?,
            actions: matrix("actions")?,
            next_states: matrix("next_states")?,
            rewards: Array1::from(ckpt.get_f64(&format!("{prefix}.rewards"), None)?),
            terminated: ckpt
                .get_bytes(&format!("{prefix}.terminated"))?
                .iter()
                .map(|&b| b != 0)
                .collect(),
        };
        if !t.is_empty() {
            t.validate(t.state_dim(), t.action_dim())
                .map_err(|e| tandem_nn::NnError::Checkpoint(format!("`{prefix}`: {e}")))?;
        }
        *self = t;
        Ok(())
    }
}

impl Transitions {
    fn matrices(&self) -> [(&'static str, &Array2<f64>); 3] {
        [
            ("states", &self.states),
            ("actions", &self.actions),
            ("next_states", &self.next_states),
        ]
    }

    /// Number of transitions (rows).
    pub fn len(&self) -> usize {
        self.states.nrows()
    }

    /// Whether there are no transitions.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Length of the state vector (columns of `states`).
    pub fn state_dim(&self) -> usize {
        self.states.ncols()
    }

    /// Length of the action vector (columns of `actions`).
    pub fn action_dim(&self) -> usize {
        self.actions.ncols()
    }

    /// Checks that the dataset is non-empty, that every array has `len()` rows and the given
    /// state and action widths, and that every value is finite. Errors name the array and the
    /// first bad row.
    pub fn validate(&self, state_dim: usize, action_dim: usize) -> Result<(), ModelError> {
        let n = self.len();
        if n == 0 {
            return Err(ModelError::Empty);
        }
        check_array("states", self.states.view(), n, state_dim)?;
        check_array("actions", self.actions.view(), n, action_dim)?;
        check_array("next_states", self.next_states.view(), n, state_dim)?;
        if self.rewards.len() != n {
            return Err(ModelError::Dim {
                what: "rewards (rows)".into(),
                expected: n,
                got: self.rewards.len(),
            });
        }
        if let Some(row) = self.rewards.iter().position(|r| !r.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "rewards".into(),
                row,
            });
        }
        if self.terminated.len() != n {
            return Err(ModelError::Dim {
                what: "terminated (rows)".into(),
                expected: n,
                got: self.terminated.len(),
            });
        }
        Ok(())
    }

    /// The transitions of one episode: `states` holds `T + 1` states `s_0..s_T`, `actions` the
    /// `T` actions, `rewards` the `T` rewards; `terminated` says whether `s_T` is terminal (only
    /// the last transition is marked).
    pub fn from_episode(
        states: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
        rewards: &[f64],
        terminated: bool,
    ) -> Result<Self, ModelError> {
        let t = actions.nrows();
        if states.nrows() != t + 1 {
            return Err(ModelError::Dim {
                what: "episode states (rows, one more than actions)".into(),
                expected: t + 1,
                got: states.nrows(),
            });
        }
        if rewards.len() != t {
            return Err(ModelError::Dim {
                what: "episode rewards (rows)".into(),
                expected: t,
                got: rewards.len(),
            });
        }
        let mut b = TransitionsBuilder::new(states.ncols(), actions.ncols());
        for (i, &reward) in rewards.iter().enumerate() {
            b.push(
                states.row(i).to_vec(),
                &actions.row(i).to_vec(),
                &states.row(i + 1).to_vec(),
                reward,
                i + 1 == t && terminated,
            )?;
        }
        Ok(b.build())
    }

    /// The rows `idx`, in that order.
    pub fn select(&self, idx: &[usize]) -> Self {
        Self {
            states: self.states.select(Axis(0), idx),
            actions: self.actions.select(Axis(0), idx),
            next_states: self.next_states.select(Axis(0), idx),
            rewards: self.rewards.select(Axis(0), idx),
            terminated: self.terminated.select(Axis(0), idx),
        }
    }

    /// Appends the rows of `other` (same widths).
    pub fn extend(&mut self, other: &Transitions) -> Result<(), ModelError> {
        if self.is_empty() && self.state_dim() == 0 && self.action_dim() == 0 {
            *self = other.clone();
            return Ok(());
        }
        other.validate(self.state_dim(), self.action_dim())?;
        let cat = |a: &Array2<f64>, b: &Array2<f64>| {
            ndarray::concatenate(Axis(0), &[a.view(), b.view()]).expect("widths checked")
        };
        self.states = cat(&self.states, &other.states);
        self.actions = cat(&self.actions, &other.actions);
        self.next_states = cat(&self.next_states, &other.next_states);
        self.rewards = ndarray::concatenate(Axis(0), &[self.rewards.view(), other.rewards.view()])
            .expect("1-D");
        self.terminated =
            ndarray::concatenate(Axis(0), &[self.terminated.view(), other.terminated.view()])
                .expect("1-D");
        Ok(())
    }

    /// Splits into `(train, holdout)` with `round(fraction * len)` random rows held out (at most
    /// `len - 1`, so training keeps a row). The split is drawn from `rng`.
    pub fn split_holdout(&self, fraction: f64, rng: &mut Rng) -> (Self, Self) {
        let (train, hold) = holdout_indices(self.len(), fraction, rng);
        (self.select(&train), self.select(&hold))
    }
}

/// Random `(train, holdout)` index sets for `n` rows and a holdout fraction (clamped to
/// `[0, 1]`); the holdout has `round(fraction * n)` rows, at most `n - 1`.
pub fn holdout_indices(n: usize, fraction: f64, rng: &mut Rng) -> (Vec<usize>, Vec<usize>) {
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(rng);
    let f = if fraction.is_finite() {
        fraction.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let k = ((f * n as f64).round() as usize).min(n.saturating_sub(1));
    let hold = idx.split_off(n - k);
    (idx, hold)
}

/// Builds [`Transitions`] row by row. [`TransitionsBuilder::with_prev_action`] records each
/// state with the action applied before it (zero at an episode's start), for models that
/// condition on it.
///
/// ```
/// use tandem_models::TransitionsBuilder;
///
/// let mut b = TransitionsBuilder::with_prev_action(2, 1);
/// b.push(&[0.0, 0.0], &[1.0], &[0.1, 1.0], -1.0, false).unwrap();
/// b.push(&[0.1, 1.0], &[0.5], &[0.2, 1.5], -1.0, true).unwrap();
/// let data = b.build();
/// assert_eq!(data.len(), 2);
/// // Rows are [s, a_{t-1}] --a_t--> [s', a_t].
/// assert_eq!(data.states.row(0).to_vec(), [0.0, 0.0, 0.0]);
/// assert_eq!(data.states.row(1).to_vec(), [0.1, 1.0, 1.0]);
/// assert_eq!(data.next_states.row(1).to_vec(), [0.2, 1.5, 0.5]);
/// ```
#[derive(Debug, Clone)]
pub struct TransitionsBuilder {
    state_dim: usize,
    action_dim: usize,
    /// `Some(a_{t−1})` when states carry the previous action.
    last_action: Option<Vec<f64>>,
    states: Vec<f64>,
    actions: Vec<f64>,
    next_states: Vec<f64>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
}

impl TransitionsBuilder {
    /// An empty builder for the given widths.
    pub fn new(state_dim: usize, action_dim: usize) -> Self {
        Self {
            state_dim,
            action_dim,
            last_action: None,
            states: Vec::new(),
            actions: Vec::new(),
            next_states: Vec::new(),
            rewards: Vec::new(),
            terminated: Vec::new(),
        }
    }

    /// An empty builder whose rows are `[s, a_{t−1}] --a_t--> [s', a_t]`: pushed states of
    /// `state_dim` come out `state_dim + action_dim` wide, the previous action of an episode's
    /// first row (and of a new builder's) zero. This is the data of a model of the state
    /// extended by the previous action ([`crate::IncrementalModel`]).
    pub fn with_prev_action(state_dim: usize, action_dim: usize) -> Self {
        Self {
            last_action: Some(vec![0.0; action_dim]),
            ..Self::new(state_dim, action_dim)
        }
    }

    /// Number of rows pushed so far.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// Whether no row was pushed.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Appends one transition `(s, a, s', r, terminated)`. A row with a wrong width or a
    /// non-finite value is refused (error naming it, with the row it would have been) and
    /// nothing is appended. A terminated row ends the episode.
    pub fn push(
        &mut self,
        state: impl AsRef<[f64]>,
        action: &[f64],
        next_state: &[f64],
        reward: f64,
        terminated: bool,
    ) -> Result<(), ModelError> {
        let state = state.as_ref();
        let row = self.len();
        for (what, v, n) in [
            ("state", state, self.state_dim),
            ("action", action, self.action_dim),
            ("next_state", next_state, self.state_dim),
            ("reward", std::slice::from_ref(&reward), 1),
        ] {
            if v.len() != n {
                return Err(ModelError::Dim {
                    what: format!("{what} of row {row}"),
                    expected: n,
                    got: v.len(),
                });
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(ModelError::NonFinite {
                    what: what.to_string(),
                    row,
                });
            }
        }
        self.states.extend_from_slice(state);
        self.actions.extend_from_slice(action);
        self.next_states.extend_from_slice(next_state);
        if let Some(last) = &mut self.last_action {
            self.states.extend_from_slice(last);
            self.next_states.extend_from_slice(action);
            last.copy_from_slice(action);
        }
        self.rewards.push(reward);
        self.terminated.push(terminated);
        if terminated {
            self.end_episode();
        }
        Ok(())
    }

    /// Marks the end of an episode (terminated or truncated): the next row's previous action is
    /// zero.
    pub fn end_episode(&mut self) {
        if let Some(last) = &mut self.last_action {
            last.iter_mut().for_each(|a| *a = 0.0);
        }
    }

    /// A new builder of the same kind, empty (the previous action starts at zero).
    pub fn empty_like(&self) -> Self {
        match self.last_action {
            Some(_) => Self::with_prev_action(self.state_dim, self.action_dim),
            None => Self::new(self.state_dim, self.action_dim),
        }
    }

    /// The dataset.
    pub fn build(self) -> Transitions {
        let n = self.rewards.len();
        let s = self.state_dim + self.last_action.as_ref().map_or(0, Vec::len);
        let m = |v: Vec<f64>, c: usize| Array2::from_shape_vec((n, c), v).expect("sizes kept");
        Transitions {
            states: m(self.states, s),
            actions: m(self.actions, self.action_dim),
            next_states: m(self.next_states, s),
            rewards: Array1::from(self.rewards),
            terminated: Array1::from(self.terminated),
        }
    }
}

/// Column means and standard deviations of `x` (std floored at `min_std`), for normalizing.
#[allow(dead_code)] // used by the learned models
pub(crate) fn column_stats(x: ArrayView2<'_, f64>, min_std: f64) -> (Array1<f64>, Array1<f64>) {
    let n = x.nrows().max(1) as f64;
    let mean = x.sum_axis(Axis(0)) / n;
    let mut var = Array1::zeros(x.ncols());
    for r in x.outer_iter() {
        for ((v, &xi), &mi) in var.iter_mut().zip(r.iter()).zip(mean.iter()) {
            let d: f64 = xi - mi;
            *v += d * d;
        }
    }
    let std = var.mapv(|v: f64| (v / n).sqrt().max(min_std));
    (mean, std)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;
    use tandem_core::seeding::rng_from_seed;

    #[test]
    fn from_episode_sets_the_terminal_flag() {
        let s = array![[0.0], [1.0], [2.0], [3.0]];
        let a = array![[0.5], [0.6], [0.7]];
        let d = Transitions::from_episode(s.view(), a.view(), &[1.0, 2.0, 3.0], true).unwrap();
        assert_eq!(d.len(), 3);
        assert_eq!(d.next_states.column(0).to_vec(), vec![1.0, 2.0, 3.0]);
        assert_eq!(d.terminated.to_vec(), vec![false, false, true]);
        d.validate(1, 1).unwrap();
        assert!(matches!(
            Transitions::from_episode(s.view(), a.view(), &[1.0], true),
            Err(ModelError::Dim { .. })
        ));
    }

    /// With the previous action in the state, each row carries the action of the row before it
    /// in its episode: zero after an end (terminated or marked) and in a fresh builder.
    #[test]
    fn the_previous_action_restarts_at_each_episode() {
        let mut b = TransitionsBuilder::with_prev_action(1, 1);
        b.push([0.0], &[1.0], &[1.0], 0.0, false).unwrap();
        b.push([1.0], &[2.0], &[2.0], 0.0, true).unwrap();
        b.push([2.0], &[3.0], &[3.0], 0.0, false).unwrap();
        b.end_episode();
        b.push([3.0], &[4.0], &[4.0], 0.0, false).unwrap();
        b.push([4.0], &[5.0], &[5.0], 0.0, false).unwrap();
        let mut fresh = b.empty_like();
        fresh.push([5.0], &[6.0], &[6.0], 0.0, false).unwrap();
        let d = b.build();
        assert_eq!(d.states.column(1).to_vec(), [0.0, 1.0, 0.0, 0.0, 4.0]);
        assert_eq!(d.next_states.column(1).to_vec(), [1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(d.states.column(0).to_vec(), [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(fresh.build().states.row(0).to_vec(), [5.0, 0.0]);
        // Pushed rows keep the task's width: the previous action is the builder's to add.
        let mut b = TransitionsBuilder::with_prev_action(1, 1);
        assert!(b.push([0.0, 0.0], &[1.0], &[1.0, 1.0], 0.0, false).is_err());
        assert!(b.is_empty());
    }

    #[test]
    fn validate_names_array_and_row() {
        let mut b = TransitionsBuilder::new(2, 1);
        for i in 0..4 {
            let x = i as f64;
            b.push([x, x], &[x], &[x + 1.0, x], 0.0, false).unwrap();
        }
        let mut d = b.build();
        d.validate(2, 1).unwrap();
        assert!(matches!(
            d.validate(3, 1),
            Err(ModelError::Dim {
                expected: 3,
                got: 2,
                ..
            })
        ));
        d.next_states[[2, 1]] = f64::NAN;
        assert_eq!(
            d.validate(2, 1),
            Err(ModelError::NonFinite {
                what: "next_states".into(),
                row: 2
            })
        );
        assert_eq!(
            Transitions::default().validate(2, 1),
            Err(ModelError::Empty)
        );
    }

    #[test]
    fn builder_refuses_bad_rows_without_appending() {
        let mut b = TransitionsBuilder::new(2, 1);
        assert!(b.push([0.0], &[0.0], &[0.0, 0.0], 0.0, false).is_err());
        assert!(b
            .push([0.0, f64::INFINITY], &[0.0], &[0.0, 0.0], 0.0, false)
            .is_err());
        assert!(b.is_empty());
    }

    #[test]
    fn holdout_split_partitions_rows() {
        let mut rng = rng_from_seed(1);
        let (tr, ho) = holdout_indices(10, 0.3, &mut rng);
        assert_eq!((tr.len(), ho.len()), (7, 3));
        let mut all: Vec<usize> = tr.iter().chain(&ho).copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..10).collect::<Vec<_>>());
        let (tr, ho) = holdout_indices(1, 0.5, &mut rng);
        assert_eq!((tr.len(), ho.len()), (1, 0));
    }
}
