//! Settings that change with training progress.

use serde::{Deserialize, Serialize};

/// A value that moves linearly with the epoch, as MBPO's rollout-length schedule
/// `[from_epoch, to_epoch, start, end]`: `start` up to `from_epoch`, `end` from `to_epoch` on,
/// linear in between and rounded down.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearSchedule {
    /// The last epoch at `start` (epochs count from 0).
    pub from_epoch: u64,
    /// The first epoch at `end`.
    pub to_epoch: u64,
    /// The value up to `from_epoch`.
    pub start: usize,
    /// The value from `to_epoch` on.
    pub end: usize,
}

impl LinearSchedule {
    /// The same value at every epoch.
    pub fn constant(v: usize) -> Self {
        Self {
            from_epoch: 0,
            to_epoch: 1,
            start: v,
            end: v,
        }
    }

    /// The value at `epoch`.
    pub fn at(&self, epoch: u64) -> usize {
        if epoch <= self.from_epoch {
            return self.start;
        }
        let span = self.to_epoch.saturating_sub(self.from_epoch).max(1) as f64;
        let dx = ((epoch - self.from_epoch) as f64 / span).min(1.0);
        let y = self.start as f64 + dx * (self.end as f64 - self.start as f64);
        y.floor() as usize
    }

    /// The largest value it takes.
    pub fn max(&self) -> usize {
        self.start.max(self.end)
    }

    /// An error naming `what` unless `from_epoch < to_epoch` and both values are at least 1.
    pub fn validate(&self, what: &str) -> Result<(), String> {
        if self.from_epoch >= self.to_epoch || self.start == 0 || self.end == 0 {
            return Err(format!(
                "{what}: need from_epoch < to_epoch and start, end >= 1, got {self:?}"
            ));
        }
        Ok(())
    }
}
