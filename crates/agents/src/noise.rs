//! Exploration noise for deterministic policies: Ornstein–Uhlenbeck (temporally correlated, as in
//! DDPG and p0) and independent Gaussian.

use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use tandem_core::Rng;

use crate::error::{ensure, Result};

/// Which exploration noise a deterministic-policy agent adds to its actions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum NoiseConfig {
    /// Ornstein–Uhlenbeck: `x <- x + theta (mu - x) dt + sigma sqrt(dt) N(0, 1)`.
    OrnsteinUhlenbeck {
        /// Mean reversion rate θ.
        theta: f64,
        /// Scale σ.
        sigma: f64,
        /// Time step of the discretization (1 in Lillicrap et al.'s DDPG).
        dt: f64,
    },
    /// Independent `N(0, sigma^2)` per step and component.
    Gaussian {
        /// Standard deviation.
        sigma: f64,
    },
}

impl Default for NoiseConfig {
    /// p0 §IV: Ornstein–Uhlenbeck with σ = 0.12, θ = 0.15 (dt = 1 as in Lillicrap et al. 2016).
    fn default() -> Self {
        NoiseConfig::OrnsteinUhlenbeck {
            theta: 0.15,
            sigma: 0.12,
            dt: 1.0,
        }
    }
}

impl NoiseConfig {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<()> {
        match *self {
            NoiseConfig::OrnsteinUhlenbeck { theta, sigma, dt } => {
                ensure(
                    theta > 0.0 && theta * dt <= 1.0,
                    "noise.theta",
                    theta,
                    "must satisfy 0 < theta*dt <= 1",
                )?;
                ensure(
                    sigma >= 0.0 && sigma.is_finite(),
                    "noise.sigma",
                    sigma,
                    "must be >= 0",
                )?;
                ensure(dt > 0.0 && dt.is_finite(), "noise.dt", dt, "must be > 0")
            }
            NoiseConfig::Gaussian { sigma } => ensure(
                sigma >= 0.0 && sigma.is_finite(),
                "noise.sigma",
                sigma,
                "must be >= 0",
            ),
        }
    }
}

impl NoiseConfig {
    /// The standard deviation of one component of the noise at a step far from the episode's
    /// start: `sigma` for Gaussian noise; for Ornstein–Uhlenbeck the stationary value of the AR(1)
    /// process `x' = phi x + sigma sqrt(dt) N(0, 1)`, `phi = 1 - theta dt`:
    /// `sigma sqrt(dt / (1 - phi^2))`. What the batched, stateless acting path of DDPG adds per row.
    pub fn stationary_std(&self) -> f64 {
        match *self {
            NoiseConfig::OrnsteinUhlenbeck { theta, sigma, dt } => {
                let phi = 1.0 - theta * dt;
                sigma * (dt / (1.0 - phi * phi)).sqrt()
            }
            NoiseConfig::Gaussian { sigma } => sigma,
        }
    }
}

/// Noise state: the OU process's current value (empty state for Gaussian noise).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Noise {
    config: NoiseConfig,
    state: Vec<f64>,
}

impl Noise {
    /// Noise of dimension `dim`, starting at zero.
    pub fn new(config: NoiseConfig, dim: usize) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            state: vec![0.0; dim],
        })
    }

    /// The configuration.
    pub fn config(&self) -> NoiseConfig {
        self.config
    }

    /// The dimension (of the actions it perturbs).
    pub fn dim(&self) -> usize {
        self.state.len()
    }

    /// Restarts the process at zero (each episode's start).
    pub fn reset(&mut self) {
        self.state.iter_mut().for_each(|x| *x = 0.0);
    }

    /// Advances one step and returns the noise to add.
    pub fn sample(&mut self, rng: &mut Rng) -> &[f64] {
        match self.config {
            NoiseConfig::OrnsteinUhlenbeck { theta, sigma, dt } => {
                let s = sigma * dt.sqrt();
                for x in &mut self.state {
                    let n: f64 = StandardNormal.sample(rng);
                    *x += theta * (0.0 - *x) * dt + s * n;
                }
            }
            NoiseConfig::Gaussian { sigma } => {
                for x in &mut self.state {
                    let n: f64 = StandardNormal.sample(rng);
                    *x = sigma * n;
                }
            }
        }
        &self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem_core::seeding::rng_from_seed;

    /// The discretized OU process is AR(1) with coefficient `phi = 1 - theta dt`: stationary
    /// variance `sigma^2 dt / (1 - phi^2)` and lag-1 autocorrelation `phi`.
    #[test]
    fn ou_matches_ar1_stationary_moments() {
        let (theta, sigma, dt) = (0.15, 0.12, 1.0);
        let mut n = Noise::new(NoiseConfig::OrnsteinUhlenbeck { theta, sigma, dt }, 1).unwrap();
        let mut rng = rng_from_seed(0);
        for _ in 0..1000 {
            n.sample(&mut rng);
        }
        let xs: Vec<f64> = (0..200_000).map(|_| n.sample(&mut rng)[0]).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        let cov1 = xs
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / (xs.len() - 1) as f64;
        let phi: f64 = 1.0 - theta * dt;
        let want_var = sigma * sigma * dt / (1.0 - phi * phi);
        assert!((var / want_var - 1.0).abs() < 0.05, "{var} vs {want_var}");
        assert!((cov1 / var - phi).abs() < 0.02);
        assert!(mean.abs() < 0.02);
        n.reset();
        assert_eq!(n.state, vec![0.0]);
    }

    #[test]
    fn stationary_std_is_the_long_run_std_of_the_process() {
        // phi = 0.85: var = 0.12^2 / (1 - 0.7225); Gaussian: sigma itself.
        let ou = NoiseConfig::default();
        assert!((ou.stationary_std() - 0.12 / 0.2775f64.sqrt()).abs() < 1e-12);
        assert_eq!(NoiseConfig::Gaussian { sigma: 0.3 }.stationary_std(), 0.3);
    }

    #[test]
    fn gaussian_is_independent_with_set_std() {
        let mut n = Noise::new(NoiseConfig::Gaussian { sigma: 0.3 }, 2).unwrap();
        let mut rng = rng_from_seed(1);
        let xs: Vec<f64> = (0..100_000).map(|_| n.sample(&mut rng)[1]).collect();
        let var = xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64;
        assert!((var.sqrt() - 0.3).abs() < 0.005);
        let c = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / xs.len() as f64;
        assert!((c / var).abs() < 0.02);
    }

    #[test]
    fn out_of_range_noise_is_rejected() {
        assert!(Noise::new(NoiseConfig::Gaussian { sigma: -1.0 }, 1).is_err());
        let bad = NoiseConfig::OrnsteinUhlenbeck {
            theta: 2.0,
            sigma: 0.1,
            dt: 1.0,
        };
        assert!(bad.validate().is_err());
    }
}
