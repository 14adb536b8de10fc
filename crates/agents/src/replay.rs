//! Replay storage: a ring buffer of transitions in `ndarray` columns, seeded uniform minibatches,
//! and the mixed sampler that draws a set fraction of each minibatch from each of two buffers
//! (`D_env ∪ D_model`, p1 Algorithm 1 and p3).
//!
//! Every transition also keeps the action taken one step before it (zeros at an episode's start):
//! p1's incremental model learns from `Δa_t = a_t - a_{t-1}`.

use ndarray::{Array1, Array2};
use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_core::{first_non_finite, Rng};

use crate::agent::Batch;
use crate::error::{ensure, AgentError, Result};

/// One transition, borrowed, in the environment's `f64`.
#[derive(Debug, Clone, Copy)]
pub struct TransitionRef<'a> {
    /// Observation `s`.
    pub obs: &'a [f64],
    /// Action `a` (a discrete action as a one-element slice holding its index).
    pub action: &'a [f64],
    /// Reward.
    pub reward: f64,
    /// Next observation `s'`.
    pub next_obs: &'a [f64],
    /// `s'` is terminal.
    pub terminated: bool,
}

/// A fixed-capacity ring buffer of transitions; the oldest is overwritten when full.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayBuffer {
    capacity: usize,
    len: usize,
    next: usize,
    obs: Array2<f32>,
    actions: Array2<f32>,
    rewards: Array1<f32>,
    next_obs: Array2<f32>,
    terminated: Array1<f32>,
}

impl ReplayBuffer {
    /// An empty buffer for `capacity` transitions of the given dimensions.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Result<Self> {
        ensure(capacity > 0, "buffer_size", capacity, "must be at least 1")?;
        ensure(obs_dim > 0, "obs_dim", obs_dim, "must be at least 1")?;
        ensure(act_dim > 0, "act_dim", act_dim, "must be at least 1")?;
        tandem_nn::budget::MemoryEstimate::new()
            .part("transitions", Self::bytes(capacity, obs_dim, act_dim))
            .check(&format!(
                "replay buffer of {capacity} transitions (obs {obs_dim}, act {act_dim})"
            ))?;
        Ok(Self {
            capacity,
            len: 0,
            next: 0,
            obs: Array2::zeros((capacity, obs_dim)),
            actions: Array2::zeros((capacity, act_dim)),
            rewards: Array1::zeros(capacity),
            next_obs: Array2::zeros((capacity, obs_dim)),
            terminated: Array1::zeros(capacity),
        })
    }

    /// Bytes a buffer of `capacity` transitions allocates (`f32` columns: observation, next
    /// observation, action, reward, terminated); `None` on overflow.
    pub fn bytes(capacity: usize, obs_dim: usize, act_dim: usize) -> Option<u64> {
        let width = obs_dim
            .checked_mul(2)?
            .checked_add(act_dim)?
            .checked_add(2)?;
        tandem_nn::budget::f32_bytes(&[capacity, width])
    }

    /// Maximum number of transitions held.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Number of transitions held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` when nothing has been stored.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Observation dimension.
    pub fn obs_dim(&self) -> usize {
        self.obs.ncols()
    }

    /// Action dimension.
    pub fn act_dim(&self) -> usize {
        self.actions.ncols()
    }

    /// Stores a transition (overwriting the oldest when full). Errors on wrong lengths or
    /// non-finite numbers; nothing is stored then.
    pub fn push(&mut self, t: TransitionRef<'_>) -> Result<()> {
        let (od, ad) = (self.obs_dim(), self.act_dim());
        for (what, v, d) in [
            ("replay observation", t.obs, od),
            ("replay next observation", t.next_obs, od),
            ("replay action", t.action, ad),
        ] {
            if v.len() != d {
                return Err(AgentError::Dim {
                    what,
                    expected: d,
                    got: v.len(),
                });
            }
            if let Some(k) = first_non_finite(v) {
                return Err(AgentError::NonFinite { what, value: v[k] });
            }
        }
        if !t.reward.is_finite() {
            return Err(AgentError::NonFinite {
                what: "replay reward",
                value: t.reward,
            });
        }
        let i = self.next;
        let copy = |dst: &mut Array2<f32>, src: &[f64]| {
            let mut row = dst.row_mut(i);
            let row = row.as_slice_mut().expect("buffers are row-major");
            for (d, s) in row.iter_mut().zip(src) {
                *d = *s as f32;
            }
        };
        copy(&mut self.obs, t.obs);
        copy(&mut self.actions, t.action);
        copy(&mut self.next_obs, t.next_obs);
        self.rewards[i] = t.reward as f32;
        self.terminated[i] = if t.terminated { 1.0 } else { 0.0 };
        self.next = (self.next + 1) % self.capacity;
        self.len = (self.len + 1).min(self.capacity);
        Ok(())
    }

    /// A buffer of `capacity` transitions holding the newest `min(len, capacity)` of these, in
    /// the same order (MBPO reallocates its model buffer when the rollout length changes).
    pub fn resized(&self, capacity: usize) -> Result<Self> {
        let mut out = Self::new(capacity, self.obs_dim(), self.act_dim())?;
        let keep = self.len.min(capacity);
        for (dst, k) in (self.len - keep..self.len).enumerate() {
            let src = self.slot(k);
            out.obs.row_mut(dst).assign(&self.obs.row(src));
            out.actions.row_mut(dst).assign(&self.actions.row(src));
            out.next_obs.row_mut(dst).assign(&self.next_obs.row(src));
            out.rewards[dst] = self.rewards[src];
            out.terminated[dst] = self.terminated[src];
        }
        out.len = keep;
        out.next = keep % capacity;
        Ok(out)
    }

    /// Index in storage of the `k`-th oldest transition held.
    fn slot(&self, k: usize) -> usize {
        if self.len < self.capacity {
            k
        } else {
            (self.next + k) % self.capacity
        }
    }

    /// The `k`-th oldest transition held, as a one-row batch (for inspection and tests).
    pub fn get(&self, k: usize) -> Option<Batch> {
        if k >= self.len {
            return None;
        }
        let mut b = Batch::zeros(1, self.obs_dim(), self.act_dim());
        self.copy_row(self.slot(k), &mut b, 0);
        Some(b)
    }

    fn copy_row(&self, src: usize, b: &mut Batch, dst: usize) {
        b.obs.row_mut(dst).assign(&self.obs.row(src));
        b.actions.row_mut(dst).assign(&self.actions.row(src));
        b.next_obs.row_mut(dst).assign(&self.next_obs.row(src));
        b.rewards[dst] = self.rewards[src];
        b.terminated[dst] = self.terminated[src];
    }

    /// A minibatch of `n` transitions drawn uniformly with replacement.
    pub fn sample(&self, n: usize, rng: &mut Rng) -> Result<Batch> {
        let mut b = Batch::zeros(n, self.obs_dim(), self.act_dim());
        self.sample_into(rng, &mut b, 0..n)?;
        Ok(b)
    }

    /// Fills rows `rows` of `batch` with transitions drawn uniformly with replacement; no
    /// allocation. `batch` must have this buffer's widths.
    pub fn sample_into(
        &self,
        rng: &mut Rng,
        batch: &mut Batch,
        rows: std::ops::Range<usize>,
    ) -> Result<()> {
        if self.is_empty() {
            return Err(AgentError::Empty("replay buffer"));
        }
        if batch.obs_dim() != self.obs_dim() || batch.act_dim() != self.act_dim() {
            return Err(AgentError::Dim {
                what: "minibatch width",
                expected: self.obs_dim() + self.act_dim(),
                got: batch.obs_dim() + batch.act_dim(),
            });
        }
        for r in rows {
            let k = rng.random_range(0..self.len);
            self.copy_row(k, batch, r);
        }
        Ok(())
    }
}

/// Draws minibatches with a set fraction from a first buffer (e.g. real data `D_env`) and the
/// rest from a second (e.g. model data `D_model`), as in p1's Algorithm 1 and MBPO-style loops.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MixedSampler {
    /// Fraction of each minibatch drawn from the first buffer, in `[0, 1]`.
    pub first_fraction: f64,
}

impl MixedSampler {
    /// A sampler drawing `first_fraction` of each minibatch from the first buffer.
    pub fn new(first_fraction: f64) -> Result<Self> {
        ensure(
            (0.0..=1.0).contains(&first_fraction),
            "first_fraction",
            first_fraction,
            "must lie in [0, 1]",
        )?;
        Ok(Self { first_fraction })
    }

    /// How many of `n` rows come from the first buffer: `round(n * first_fraction)`, all of them
    /// when the second buffer is empty and none when the first is.
    pub fn split(&self, n: usize, first_len: usize, second_len: usize) -> usize {
        if second_len == 0 {
            n
        } else if first_len == 0 {
            0
        } else {
            ((n as f64) * self.first_fraction).round() as usize
        }
    }

    /// Fills `batch` (rows first from `first`, then from `second`).
    pub fn sample_into(
        &self,
        first: &ReplayBuffer,
        second: &ReplayBuffer,
        rng: &mut Rng,
        batch: &mut Batch,
    ) -> Result<()> {
        let n = batch.len();
        let k = self.split(n, first.len(), second.len());
        if k > 0 {
            first.sample_into(rng, batch, 0..k)?;
        }
        if k < n {
            second.sample_into(rng, batch, k..n)?;
        }
        Ok(())
    }

    /// A fresh minibatch of `n` rows.
    pub fn sample(
        &self,
        first: &ReplayBuffer,
        second: &ReplayBuffer,
        n: usize,
        rng: &mut Rng,
    ) -> Result<Batch> {
        let mut b = Batch::zeros(n, first.obs_dim(), first.act_dim());
        self.sample_into(first, second, rng, &mut b)?;
        Ok(b)
    }
}

impl ReplayBuffer {
    /// Stores the buffer (only the filled rows) under `prefix`.
    pub fn save_to(&self, prefix: &str, ckpt: &mut tandem_nn::Checkpoint) -> Result<()> {
        let (n, od, ad) = (self.len, self.obs_dim(), self.act_dim());
        let rows =
            |a: &Array2<f32>, w: usize| a.as_slice().expect("standard layout")[..n * w].to_vec();
        ckpt.put_u64(
            &format!("{prefix}.counters"),
            &[5],
            &[
                self.capacity as u64,
                n as u64,
                self.next as u64,
                od as u64,
                ad as u64,
            ],
        )?;
        ckpt.put_f32(&format!("{prefix}.obs"), &[n, od], &rows(&self.obs, od))?;
        ckpt.put_f32(
            &format!("{prefix}.actions"),
            &[n, ad],
            &rows(&self.actions, ad),
        )?;
        ckpt.put_f32(
            &format!("{prefix}.next_obs"),
            &[n, od],
            &rows(&self.next_obs, od),
        )?;
        ckpt.put_f32(
            &format!("{prefix}.rewards"),
            &[n],
            &self.rewards.as_slice().expect("contiguous")[..n],
        )?;
        ckpt.put_f32(
            &format!("{prefix}.terminated"),
            &[n],
            &self.terminated.as_slice().expect("contiguous")[..n],
        )?;
        Ok(())
    }

    /// Restores what [`ReplayBuffer::save_to`] stored; errors when capacity or widths differ.
    pub fn load_from(&mut self, prefix: &str, ckpt: &tandem_nn::Checkpoint) -> Result<()> {
        let c = ckpt.get_u64(&format!("{prefix}.counters"), Some(&[5]))?;
        let (od, ad) = (self.obs_dim(), self.act_dim());
        if c[0] as usize != self.capacity || c[3] as usize != od || c[4] as usize != ad {
            return Err(AgentError::Checkpoint(format!(
                "replay buffer of capacity {} and widths {}/{} cannot load one of capacity {} and widths {}/{}",
                self.capacity, od, ad, c[0], c[3], c[4]
            )));
        }
        let n = c[1] as usize;
        let mut fresh = Self::new(self.capacity, od, ad)?;
        let fill = |a: &mut Array2<f32>, name: &str, w: usize| -> Result<()> {
            let v = ckpt.get_f32(&format!("{prefix}.{name}"), Some(&[n, w]))?;
            a.as_slice_mut().expect("standard layout")[..n * w].copy_from_slice(&v);
            Ok(())
        };
        fill(&mut fresh.obs, "obs", od)?;
        fill(&mut fresh.actions, "actions", ad)?;
        fill(&mut fresh.next_obs, "next_obs", od)?;
        let r = ckpt.get_f32(&format!("{prefix}.rewards"), Some(&[n]))?;
        fresh.rewards.as_slice_mut().expect("contiguous")[..n].copy_from_slice(&r);
        let t = ckpt.get_f32(&format!("{prefix}.terminated"), Some(&[n]))?;
        fresh.terminated.as_slice_mut().expect("contiguous")[..n].copy_from_slice(&t);
        fresh.len = n;
        fresh.next = c[2] as usize;
        *self = fresh;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_core::seeding::rng_from_seed;

    fn push_k(buf: &mut ReplayBuffer, k: f64) {
        buf.push(TransitionRef {
            obs: &[k, -k],
            action: &[k * 10.0],
            reward: k,
            next_obs: &[k + 1.0, -k - 1.0],
            terminated: k as i64 % 3 == 0,
        })
        .unwrap();
    }

    #[test]
    fn ring_overwrites_oldest_and_keeps_fields_together() {
        let mut b = ReplayBuffer::new(3, 2, 1).unwrap();
        for k in 0..5 {
            push_k(&mut b, k as f64);
        }
        assert_eq!(b.len(), 3);
        // Held: 2, 3, 4 (oldest first).
        for (i, k) in [2.0f32, 3.0, 4.0].into_iter().enumerate() {
            let t = b.get(i).unwrap();
            assert_eq!(t.obs.row(0).to_vec(), vec![k, -k]);
            assert_eq!(t.actions[[0, 0]], k * 10.0);
            assert_eq!(t.next_obs.row(0).to_vec(), vec![k + 1.0, -k - 1.0]);
            assert_eq!(t.rewards[0], k);
            assert_eq!(t.terminated[0], if k as i64 % 3 == 0 { 1.0 } else { 0.0 });
        }
        assert!(b.get(3).is_none());
    }

    #[test]
    fn a_resized_buffer_keeps_the_newest_in_order() {
        let mut b = ReplayBuffer::new(4, 2, 1).unwrap();
        for k in 0..6 {
            push_k(&mut b, k as f64); // holds 2, 3, 4, 5
        }
        let small = b.resized(2).unwrap();
        let big = b.resized(6).unwrap();
        let rewards = |r: &ReplayBuffer| -> Vec<f32> {
            (0..r.len()).map(|k| r.get(k).unwrap().rewards[0]).collect()
        };
        assert_eq!(rewards(&small), [4.0, 5.0]);
        assert_eq!(rewards(&big), [2.0, 3.0, 4.0, 5.0]);
        assert_eq!(big.get(1), b.get(1));
        // Pushing on continues as a ring: the small one overwrites its oldest, the big one grows.
        let (mut small, mut big) = (small, big);
        push_k(&mut small, 6.0);
        push_k(&mut big, 6.0);
        assert_eq!(rewards(&small), [5.0, 6.0]);
        assert_eq!(rewards(&big), [2.0, 3.0, 4.0, 5.0, 6.0]);
        assert!(b.resized(0).is_err());
    }

    #[test]
    fn sampling_is_seeded_uniform_and_consistent() {
        let mut b = ReplayBuffer::new(10, 2, 1).unwrap();
        for k in 0..10 {
            push_k(&mut b, k as f64);
        }
        let s1 = b.sample(4000, &mut rng_from_seed(1)).unwrap();
        let s2 = b.sample(4000, &mut rng_from_seed(1)).unwrap();
        assert_eq!(s1, s2);
        let mut counts = [0usize; 10];
        for r in 0..s1.len() {
            let k = s1.rewards[r];
            // Each row is one transition: the fields belong together.
            assert_eq!(s1.obs[[r, 0]], k);
            assert_eq!(s1.actions[[r, 0]], k * 10.0);
            counts[k as usize] += 1;
        }
        // Uniform: each of 10 expected 400 times; 5 sigma is about 95.
        for c in counts {
            assert!((305..=495).contains(&c), "{counts:?}");
        }
    }

    #[test]
    fn bad_transitions_are_rejected_without_storing() {
        let mut b = ReplayBuffer::new(4, 2, 1).unwrap();
        let bad = TransitionRef {
            obs: &[0.0],
            action: &[0.0],
            reward: 0.0,
            next_obs: &[0.0, 0.0],
            terminated: false,
        };
        assert!(matches!(b.push(bad), Err(AgentError::Dim { .. })));
        let nan = TransitionRef {
            obs: &[0.0, 0.0],
            reward: f64::NAN,
            ..bad
        };
        assert!(matches!(b.push(nan), Err(AgentError::NonFinite { .. })));
        assert!(b.is_empty());
        assert!(matches!(
            b.sample(2, &mut rng_from_seed(0)),
            Err(AgentError::Empty(_))
        ));
        assert!(ReplayBuffer::new(0, 2, 1).is_err());
    }

    #[test]
    fn mixed_sampler_draws_the_set_fraction_from_each() {
        let mut real = ReplayBuffer::new(10, 2, 1).unwrap();
        let mut model = ReplayBuffer::new(10, 2, 1).unwrap();
        for k in 0..5 {
            push_k(&mut real, k as f64); // rewards 0..5
            push_k(&mut model, 100.0 + k as f64); // rewards 100..105
        }
        let s = MixedSampler::new(0.25).unwrap();
        let b = s.sample(&real, &model, 256, &mut rng_from_seed(3)).unwrap();
        let from_real = b.rewards.iter().filter(|r| **r < 50.0).count();
        assert_eq!(from_real, 64);
        let empty = ReplayBuffer::new(10, 2, 1).unwrap();
        let b = s.sample(&real, &empty, 8, &mut rng_from_seed(3)).unwrap();
        assert!(b.rewards.iter().all(|r| *r < 50.0));
        assert!(MixedSampler::new(1.5).is_err());
    }
}
