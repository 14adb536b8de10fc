//! Checkpointing of the shared [`RunningNormalizer`] (statistics in `tandem-core`, so that
//! `tandem-envs` normalizes observations with the same type).

pub use tandem_core::normalizer::{NormalizerError, NormalizerState, RunningNormalizer};

use crate::checkpoint::{Checkpoint, Checkpointable};
use crate::error::{NnError, Result};

impl From<NormalizerError> for NnError {
    fn from(e: NormalizerError) -> Self {
        match e {
            NormalizerError::ShapeMismatch {
                what,
                expected,
                got,
            } => NnError::ShapeMismatch {
                what,
                expected,
                got,
            },
            NormalizerError::NonFinite { what, index } => NnError::NonFinite { what, index },
            NormalizerError::InvalidConfig(m) => NnError::InvalidConfig(m),
        }
    }
}

impl Checkpointable for RunningNormalizer {
    /// Writes `{prefix}.count` (`[1]`), `{prefix}.mean`, `{prefix}.m2` (`[dim]`, f64) and
    /// `{prefix}.config` (`[eps, clip or NaN]`, f64).
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        let s = self.state();
        ckpt.put_f64(&format!("{prefix}.count"), &[1], &[s.count])?;
        ckpt.put_f64(&format!("{prefix}.mean"), &[s.dim], &s.mean)?;
        ckpt.put_f64(&format!("{prefix}.m2"), &[s.dim], &s.m2)?;
        ckpt.put_f64(
            &format!("{prefix}.config"),
            &[2],
            &[s.eps, s.clip.unwrap_or(f64::NAN)],
        )
    }

    /// Restores what `save_to` wrote (the frozen flag is kept); errors on another dimension or
    /// non-finite statistics, leaving `self` unchanged.
    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let dim = self.dim();
        let cfg = ckpt.get_f64(&format!("{prefix}.config"), Some(&[2]))?;
        let state = NormalizerState {
            dim,
            count: ckpt.get_f64(&format!("{prefix}.count"), Some(&[1]))?[0],
            mean: ckpt.get_f64(&format!("{prefix}.mean"), Some(&[dim]))?,
            m2: ckpt.get_f64(&format!("{prefix}.m2"), Some(&[dim]))?,
            eps: cfg[0],
            clip: if cfg[1].is_nan() { None } else { Some(cfg[1]) },
            frozen: self.is_frozen(),
        };
        *self = RunningNormalizer::try_from(state)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkpoints_round_trip_and_reject_another_dimension() {
        let mut n = RunningNormalizer::new(2).with_clip(3.0).unwrap();
        n.update_f64(&[1.0, 2.0, 4.0, -1.0]).unwrap();
        let mut ck = Checkpoint::new();
        n.save_to("obs_norm", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        let mut c = RunningNormalizer::new(2);
        c.load_from("obs_norm", &ck).unwrap();
        assert_eq!(c, n);
        let mut wrong = RunningNormalizer::new(3);
        assert!(wrong.load_from("obs_norm", &ck).is_err());
        assert_eq!(wrong, RunningNormalizer::new(3));
    }
}
