//! [`Adapted`]: what a pipeline puts between a task and an off-policy agent, without touching
//! either: observation features of order one (scaled components, `(cos, sin)` of angles), a reward
//! scale for the learner, and exploration noise the pipeline can change between phases (p0 uses
//! more noise for learning from scratch than for fine-tuning). The environment, the replay buffer
//! and every reported return stay in the task's units.

use crate::{
    Agent, AgentError, Batch, Metrics, Mode, Noise, NoiseConfig, OffPolicyAgent, Result, Resumable,
};
use serde::{Deserialize, Serialize};
use tandem_core::{Action, Rng, Space};
use tandem_nn::Checkpoint;

/// One observation feature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Feature {
    /// `scale * obs[index]`.
    Linear {
        /// Observation component.
        index: usize,
        /// Factor.
        scale: f64,
    },
    /// `cos(obs[index])` and `sin(obs[index])`: an angle without its ±π seam.
    CosSin {
        /// Observation component holding an angle.
        index: usize,
    },
}

/// Number of features `features` produce.
pub fn feature_dim(features: &[Feature]) -> usize {
    features
        .iter()
        .map(|f| match f {
            Feature::Linear { .. } => 1,
            Feature::CosSin { .. } => 2,
        })
        .sum()
}

/// Writes the features of `obs` into `out` (cleared first).
pub fn features_of(features: &[Feature], obs: &[f64], out: &mut Vec<f64>) {
    out.clear();
    for f in features {
        match *f {
            Feature::Linear { index, scale } => {
                out.push(scale * obs.get(index).copied().unwrap_or(f64::NAN))
            }
            Feature::CosSin { index } => {
                let a = obs.get(index).copied().unwrap_or(f64::NAN);
                out.push(a.cos());
                out.push(a.sin());
            }
        }
    }
}

/// An agent `A` (acting deterministically; exploration is added here) behind observation
/// features, a reward scale and settable exploration noise. `A` must have been built for
/// observations of [`feature_dim`] components and the task's action space.
#[derive(Debug, Clone)]
pub struct Adapted<A> {
    inner: A,
    features: Vec<Feature>,
    reward_scale: f64,
    low: Vec<f64>,
    high: Vec<f64>,
    noise: Noise,
    rng: Rng,
    scratch: Option<Batch>,
    obs: Vec<f64>,
}

impl<A> Adapted<A> {
    /// Wraps `inner` for a task whose action space is `action_space` (a bounded box).
    pub fn new(
        inner: A,
        features: Vec<Feature>,
        reward_scale: f64,
        action_space: &Space,
        noise: NoiseConfig,
        rng: Rng,
    ) -> Result<Self> {
        let (low, high) = match action_space {
            Space::Box { low, high, .. }
                if low.iter().chain(high).all(|v| v.is_finite())
                    && low.iter().zip(high).all(|(l, h)| l < h) =>
            {
                (low.clone(), high.clone())
            }
            _ => {
                return Err(AgentError::Config {
                    field: "action_space",
                    value: action_space.describe(),
                    reason: "exploration noise needs a bounded box action space",
                })
            }
        };
        if !(reward_scale > 0.0 && reward_scale.is_finite()) {
            return Err(AgentError::Config {
                field: "reward_scale",
                value: reward_scale.to_string(),
                reason: "must be positive and finite",
            });
        }
        Ok(Self {
            noise: Noise::new(noise, low.len())?,
            inner,
            features,
            reward_scale,
            low,
            high,
            rng,
            scratch: None,
            obs: Vec::new(),
        })
    }

    /// Replaces the exploration noise (its state starts afresh).
    pub fn set_noise(&mut self, noise: NoiseConfig) -> Result<()> {
        self.noise = Noise::new(noise, self.low.len())?;
        Ok(())
    }

    /// The wrapped agent.
    pub fn inner(&self) -> &A {
        &self.inner
    }
}

/// The wrapped agent's state plus the wrapper's exploration noise and generator.
impl<A: Resumable> Resumable for Adapted<A> {
    fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        self.inner.save(ckpt)?;
        ckpt.put_json("adapter.noise", &self.noise)?;
        ckpt.put_json("adapter.rng", &self.rng)?;
        Ok(())
    }

    fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let noise: Noise = ckpt.get_json("adapter.noise")?;
        let rng: Rng = ckpt.get_json("adapter.rng")?;
        if noise.dim() != self.low.len() {
            return Err(AgentError::Checkpoint(format!(
                "the saved exploration noise has {} dimensions, this agent's actions {}",
                noise.dim(),
                self.low.len()
            )));
        }
        self.inner.load(ckpt)?;
        self.noise = noise;
        self.rng = rng;
        Ok(())
    }
}

impl<A: Agent> Agent for Adapted<A> {
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    /// The wrapped agent's deterministic action on the features of `obs`; in
    /// [`Mode::Explore`], plus noise added in `[-1, 1]` units of the action box and clipped to it.
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        features_of(&self.features, obs, &mut self.obs);
        let a = self.inner.act(&self.obs, Mode::Deterministic)?;
        if mode == Mode::Deterministic {
            return Ok(a);
        }
        let Action::Continuous(mut v) = a else {
            return Ok(a);
        };
        let n = self.noise.sample(&mut self.rng);
        for (i, x) in v.iter_mut().enumerate() {
            let (l, h) = (self.low[i], self.high[i]);
            let u = (2.0 * (*x - l) / (h - l) - 1.0 + n[i]).clamp(-1.0, 1.0);
            *x = l + (u + 1.0) * 0.5 * (h - l);
        }
        Ok(Action::Continuous(v))
    }

    fn reset_episode(&mut self) {
        self.noise.reset();
        self.inner.reset_episode();
    }
}

impl<A: OffPolicyAgent> OffPolicyAgent for Adapted<A> {
    /// Updates the wrapped agent on the batch with features in place of observations and scaled
    /// rewards.
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        let fd = feature_dim(&self.features);
        let n = batch.len();
        let b = self
            .scratch
            .get_or_insert_with(|| Batch::zeros(n, fd, batch.act_dim()));
        if b.len() != n || b.act_dim() != batch.act_dim() {
            *b = Batch::zeros(n, fd, batch.act_dim());
        }
        let mut tmp = Vec::with_capacity(fd);
        let mut row = vec![0.0f64; batch.obs_dim()];
        for (src, dst) in [(&batch.obs, &mut b.obs), (&batch.next_obs, &mut b.next_obs)] {
            for (s, mut d) in src.outer_iter().zip(dst.outer_iter_mut()) {
                for (r, v) in row.iter_mut().zip(s.iter()) {
                    *r = f64::from(*v);
                }
                features_of(&self.features, &row, &mut tmp);
                for (dv, f) in d.iter_mut().zip(&tmp) {
                    *dv = *f as f32;
                }
            }
        }
        b.actions.assign(&batch.actions);
        b.terminated.assign(&batch.terminated);
        let rs = self.reward_scale as f32;
        b.rewards.zip_mut_with(&batch.rewards, |d, s| *d = s * rs);
        self.inner.update(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_core::seeding::rng_from_seed;

    /// Records what it was given; acts with a fixed action.
    #[derive(Default)]
    struct Probe {
        seen_obs: Vec<f64>,
        seen_batch: Option<Batch>,
    }
    impl Agent for Probe {
        fn name(&self) -> &'static str {
            "probe"
        }
        fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
            assert_eq!(mode, Mode::Deterministic, "exploration is the adapter's");
            self.seen_obs = obs.to_vec();
            Ok(Action::Continuous(vec![2.5]))
        }
    }
    impl OffPolicyAgent for Probe {
        fn update(&mut self, batch: &Batch) -> Result<Metrics> {
            self.seen_batch = Some(batch.clone());
            batch.check(3, 1).map(|_| Metrics::default())
        }
    }

    fn adapted(noise: NoiseConfig) -> Adapted<Probe> {
        let feats = vec![
            Feature::CosSin { index: 0 },
            Feature::Linear {
                index: 1,
                scale: 0.1,
            },
        ];
        Adapted::new(
            Probe::default(),
            feats,
            0.01,
            &Space::symmetric(1, 3.0),
            noise,
            rng_from_seed(0),
        )
        .unwrap()
    }

    #[test]
    fn features_and_reward_scale_reach_the_agent_and_nothing_else() {
        let mut a = adapted(NoiseConfig::Gaussian { sigma: 0.0 });
        let act = a
            .act(&[std::f64::consts::FRAC_PI_2, 30.0], Mode::Explore)
            .unwrap();
        assert_eq!(act, Action::Continuous(vec![2.5]));
        let o = &a.inner().seen_obs;
        assert!(o[0].abs() < 1e-12 && (o[1] - 1.0).abs() < 1e-12 && (o[2] - 3.0).abs() < 1e-12);
        let mut b = Batch::zeros(2, 2, 1);
        b.obs[[1, 0]] = std::f32::consts::PI;
        b.next_obs[[0, 1]] = -20.0;
        b.actions[[1, 0]] = 0.7;
        b.rewards[1] = -50.0;
        b.terminated[0] = 1.0;
        a.update(&b).unwrap();
        let seen = a.inner().seen_batch.clone().unwrap();
        assert!((seen.obs[[1, 0]] + 1.0).abs() < 1e-6 && seen.obs[[1, 1]].abs() < 1e-6);
        assert_eq!(seen.obs[[0, 0]], 1.0);
        assert!((seen.next_obs[[0, 2]] + 2.0).abs() < 1e-6);
        assert_eq!((seen.actions[[1, 0]], seen.terminated[0]), (0.7, 1.0));
        assert!((seen.rewards[1] + 0.5).abs() < 1e-6);
    }

    #[test]
    fn noise_is_added_in_unit_box_and_clipped_and_can_be_changed() {
        let mut a = adapted(NoiseConfig::Gaussian { sigma: 0.5 });
        let acts: Vec<f64> = (0..2000)
            .map(|_| {
                a.act(&[0.0, 0.0], Mode::Explore)
                    .unwrap()
                    .as_continuous()
                    .unwrap()[0]
            })
            .collect();
        assert!(acts.iter().all(|v| (-3.0..=3.0).contains(v)));
        assert!(acts.contains(&3.0), "2.5 V + noise must clip at 3 V");
        let low = acts.iter().filter(|v| **v < 2.5).count();
        assert!(low > 800 && low < 1200, "{low}");
        assert_eq!(
            a.act(&[0.0, 0.0], Mode::Deterministic).unwrap(),
            Action::Continuous(vec![2.5])
        );
        a.set_noise(NoiseConfig::Gaussian { sigma: 0.0 }).unwrap();
        assert_eq!(
            a.act(&[0.0, 0.0], Mode::Explore).unwrap(),
            Action::Continuous(vec![2.5])
        );
        assert!(Adapted::new(
            Probe::default(),
            vec![],
            0.0,
            &Space::symmetric(1, 1.0),
            NoiseConfig::default(),
            rng_from_seed(0)
        )
        .is_err());
        assert!(Adapted::new(
            Probe::default(),
            vec![],
            1.0,
            &Space::discrete(2),
            NoiseConfig::default(),
            rng_from_seed(0)
        )
        .is_err());
    }
}
