//! Memory estimates, checked before anything is allocated.
//!
//! A configuration can ask for more memory than a machine has: `hidden = [16384, 16384, 16384,
//! 16384]` is 805 million parameters per network (3.2 GB, and an agent keeps several copies:
//! gradients, Adam's moments, target networks), a conv layer of 100,000 channels makes feature
//! maps of gigabytes per minibatch, a replay buffer of 10^9 transitions tens of gigabytes. The
//! allocator then aborts the process, or the OOM killer ends it, with no word on which setting
//! was to blame. So constructors and config validators first add up what they are about to
//! allocate in a [`MemoryEstimate`] and [`MemoryEstimate::check`] it against [`memory_limit`]:
//! over the limit is a [`MemoryError`] naming the estimate, its largest part and the limit.
//!
//! The limit is a setting: [`DEFAULT_MEMORY_LIMIT`] (8 GiB) unless the environment variable
//! [`MEMORY_LIMIT_ENV`] (`TANDEM_MEMORY_LIMIT`) says otherwise (`16GiB`, `512MiB`, `2TiB`,
//! `64KiB` or a plain number of bytes), or a program calls [`set_memory_limit`]. Estimates are
//! deliberately simple (sizes of the large buffers, in bytes) and meant to catch mistakes of
//! orders of magnitude, not to account for every allocation.
//!
//! ```
//! use tandem_nn::budget::MemoryEstimate;
//!
//! // Four hidden layers of 16384 units: params, gradients and Adam's two moments.
//! let est = MemoryEstimate::new().mlp("critic", &[20, 16384, 16384, 16384, 16384, 1], 4, 256);
//! let err = est.check_against("sac", 8 << 30).unwrap_err();
//! assert!(err.to_string().contains("critic"));
//! assert!(MemoryEstimate::new().mlp("critic", &[20, 256, 256, 1], 4, 256).check("sac").is_ok());
//! ```

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// The limit when neither [`set_memory_limit`] nor [`MEMORY_LIMIT_ENV`] sets one: 8 GiB, a third
/// of the 24 GB machines this project runs on, and far above what the papers' configurations
/// need (the largest, p2's conv DQN with a 10^5 replay, estimates about 0.6 GiB).
pub const DEFAULT_MEMORY_LIMIT: u64 = 8 << 30;

/// The environment variable that sets the limit (`16GiB`, `512MiB`, or bytes).
pub const MEMORY_LIMIT_ENV: &str = "TANDEM_MEMORY_LIMIT";

/// Bytes of an `f32`: every network parameter, activation and replay entry.
const F32: u64 = 4;

/// Activation buffers kept per layer during a training pass (outputs, the pre-activation or
/// mask the backward pass reads, and the gradient flowing back).
const ACTIVATION_BUFFERS: u64 = 3;

/// 0: no override, use the environment variable or the default.
static OVERRIDE: AtomicU64 = AtomicU64::new(0);

/// Why an estimate was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MemoryError {
    /// The estimate is above the limit (or does not even fit in 64 bits).
    #[error(
        "{what}: estimated memory {} exceeds the limit of {} (largest part: {largest}, {}); \
         use smaller sizes, or raise the limit with {MEMORY_LIMIT_ENV} (e.g. {MEMORY_LIMIT_ENV}=32GiB)",
        show(*estimate), show(Some(*limit)), show(*largest_bytes)
    )]
    OverLimit {
        /// What was being built (e.g. `"sac (obs 17, act 6)"`).
        what: String,
        /// The total in bytes; `None` when it overflows `u64`.
        estimate: Option<u64>,
        /// The limit in bytes.
        limit: u64,
        /// The name of the largest part.
        largest: String,
        /// Its size in bytes (`None`: overflows).
        largest_bytes: Option<u64>,
    },
    /// [`MEMORY_LIMIT_ENV`] holds something that is not a size.
    #[error("{MEMORY_LIMIT_ENV}={value:?} is not a memory size (write e.g. 8GiB, 512MiB or a number of bytes, at least 1)")]
    BadSetting {
        /// The variable's value.
        value: String,
    },
}

/// `bytes` for people: `1.50 GiB`.
pub fn show_bytes(bytes: u64) -> String {
    show(Some(bytes))
}

/// `bytes` for people: `1.50 GiB`, `"more than 16 EiB"` for an overflow.
fn show(bytes: Option<u64>) -> String {
    let Some(b) = bytes else {
        return "more than 16 EiB".into();
    };
    const UNITS: [&str; 5] = ["KiB", "MiB", "GiB", "TiB", "PiB"];
    if b < 1024 {
        return format!("{b} B");
    }
    let mut x = b as f64 / 1024.0;
    let mut unit = UNITS[0];
    for u in &UNITS[1..] {
        if x < 1024.0 {
            break;
        }
        x /= 1024.0;
        unit = u;
    }
    format!("{x:.2} {unit}")
}

/// Reads a size: a non-negative number (decimals allowed) with an optional binary unit
/// (`KiB`, `MiB`, `GiB`, `TiB`, case-insensitive, `B` or nothing for bytes). `None` if it is
/// not one, is zero, or does not fit in `u64`.
pub fn parse_size(text: &str) -> Option<u64> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let scale: u64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "kib" => 1 << 10,
        "mib" => 1 << 20,
        "gib" => 1 << 30,
        "tib" => 1 << 40,
        _ => return None,
    };
    let x: f64 = num.parse().ok()?;
    let bytes = (x * scale as f64).round();
    // 2^64 is exactly representable; anything at or above it does not fit.
    (1.0..18_446_744_073_709_551_616.0)
        .contains(&bytes)
        .then_some(bytes as u64)
}

/// The limit in bytes: the one set by [`set_memory_limit`], else [`MEMORY_LIMIT_ENV`] (read once),
/// else [`DEFAULT_MEMORY_LIMIT`]. A malformed variable is an error rather than silently ignored.
pub fn memory_limit() -> Result<u64, MemoryError> {
    match OVERRIDE.load(Ordering::Relaxed) {
        0 => {}
        set => return Ok(set),
    }
    static FROM_ENV: OnceLock<Result<u64, MemoryError>> = OnceLock::new();
    FROM_ENV
        .get_or_init(|| match std::env::var(MEMORY_LIMIT_ENV) {
            Err(_) => Ok(DEFAULT_MEMORY_LIMIT),
            Ok(v) => parse_size(&v).ok_or(MemoryError::BadSetting { value: v }),
        })
        .clone()
}

/// Sets the process-wide limit in bytes (`None`: back to the environment variable or the
/// default). For programs that know their machine; a single estimate can also be checked
/// against any limit with [`MemoryEstimate::check_against`].
pub fn set_memory_limit(bytes: Option<u64>) {
    OVERRIDE.store(bytes.unwrap_or(0), Ordering::Relaxed);
}

/// Number of parameters of an MLP with layer widths `sizes` (`Σ in·out + out`), `None` on
/// overflow.
pub fn mlp_params(sizes: &[usize]) -> Option<u64> {
    sizes.windows(2).try_fold(0u64, |acc, w| {
        let (i, o) = (w[0] as u64, w[1] as u64);
        acc.checked_add(i.checked_mul(o)?.checked_add(o)?)
    })
}

/// The layer widths of an MLP from `input` through `hidden` to `output`.
pub fn widths(input: usize, hidden: &[usize], output: usize) -> Vec<usize> {
    let mut w = Vec::with_capacity(hidden.len() + 2);
    w.push(input);
    w.extend(hidden);
    w.push(output);
    w
}

/// Bytes of `f32` buffers holding the product of `dims` numbers, `None` on overflow.
pub fn f32_bytes(dims: &[usize]) -> Option<u64> {
    dims.iter()
        .try_fold(F32, |acc, &d| acc.checked_mul(d as u64))
}

/// A sum of named allocations, in bytes; a part that overflows `u64` makes the total unknown
/// (and over any limit).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MemoryEstimate {
    parts: Vec<(String, Option<u64>)>,
}

impl MemoryEstimate {
    /// An empty estimate.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a part of `bytes` (`None`: it overflowed while being computed).
    pub fn part(mut self, what: impl Into<String>, bytes: Option<u64>) -> Self {
        self.parts.push((what.into(), bytes));
        self
    }

    /// Adds `f32` buffers holding the product of `dims` numbers (e.g. a replay column
    /// `[capacity, obs_dim]`).
    pub fn f32s(self, what: impl Into<String>, dims: &[usize]) -> Self {
        self.part(what, f32_bytes(dims))
    }

    /// Adds an MLP with layer widths `sizes` trained on minibatches of `batch` rows: `copies`
    /// parameter-sized buffers (1 for the parameters alone; 4 with gradients and Adam's two
    /// moments; 5 with a target network too) and the activations of one training pass.
    pub fn mlp(self, what: impl Into<String>, sizes: &[usize], copies: u64, batch: usize) -> Self {
        let params = mlp_params(sizes).and_then(|p| p.checked_mul(copies * F32));
        let widths = sizes
            .iter()
            .try_fold(0u64, |acc, &w| acc.checked_add(w as u64));
        let acts = widths
            .and_then(|w| w.checked_mul(batch as u64))
            .and_then(|n| n.checked_mul(ACTIVATION_BUFFERS * F32));
        self.part(what, params.and_then(|p| p.checked_add(acts?)))
    }

    /// Adds every part of `other`, each name prefixed with `prefix` (e.g. `"p3.base.sac: "`), so
    /// that a study's estimate names the setting each part comes from.
    pub fn with(mut self, prefix: &str, other: MemoryEstimate) -> Self {
        self.parts.extend(
            other
                .parts
                .into_iter()
                .map(|(what, b)| (format!("{prefix}{what}"), b)),
        );
        self
    }

    /// Every part `n` times over (`n` copies of the same allocation, e.g. one per condition),
    /// named `"<n> x <part>"`.
    pub fn times(self, n: u64) -> Self {
        if n == 1 {
            return self;
        }
        Self {
            parts: self
                .parts
                .into_iter()
                .map(|(what, b)| (format!("{n} x {what}"), b.and_then(|b| b.checked_mul(n))))
                .collect(),
        }
    }

    /// The total in bytes, `None` if it overflows `u64`.
    pub fn total(&self) -> Option<u64> {
        self.parts
            .iter()
            .try_fold(0u64, |acc, (_, b)| acc.checked_add((*b)?))
    }

    /// The parts added so far, in order.
    pub fn parts(&self) -> &[(String, Option<u64>)] {
        &self.parts
    }

    /// `Ok(total)` if the total is within [`memory_limit`], otherwise an error naming `what`.
    pub fn check(&self, what: &str) -> Result<u64, MemoryError> {
        self.check_against(what, memory_limit()?)
    }

    /// `Ok(total)` if the total is within `limit` bytes, otherwise an error naming `what`, the
    /// estimate, the largest part and the limit.
    pub fn check_against(&self, what: &str, limit: u64) -> Result<u64, MemoryError> {
        match self.total() {
            Some(t) if t <= limit => Ok(t),
            estimate => {
                // The largest part; an overflowed one (None) counts as the largest.
                let (largest, largest_bytes) = self
                    .parts
                    .iter()
                    .max_by_key(|(_, b)| b.map_or(u128::MAX, u128::from))
                    .cloned()
                    .unwrap_or_default();
                Err(MemoryError::OverLimit {
                    what: what.to_string(),
                    estimate,
                    limit,
                    largest,
                    largest_bytes,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mlp_parameters_are_counted_by_hand() {
        // 3→4→2: 3·4 + 4 + 4·2 + 2 = 26.
        assert_eq!(mlp_params(&[3, 4, 2]), Some(26));
        assert_eq!(mlp_params(&[7]), Some(0));
        assert_eq!(mlp_params(&[usize::MAX, usize::MAX]), None);
        // 26 params × 4 copies × 4 B + (3 + 4 + 2) widths × 10 rows × 3 buffers × 4 B.
        let e = MemoryEstimate::new().mlp("net", &[3, 4, 2], 4, 10);
        assert_eq!(e.total(), Some(26 * 16 + 9 * 10 * 12));
    }

    #[test]
    fn the_reported_configs_are_over_the_default_limit_and_the_defaults_are_not() {
        // hidden = [16384; 4] on a 17-dim observation: 805,748,742 params × 4 copies × 4 B
        // = 12.0 GiB, plus 0.19 GiB of activations.
        let big = MemoryEstimate::new().mlp("actor", &[17, 16384, 16384, 16384, 16384, 6], 4, 256);
        let e = big.check_against("sac", DEFAULT_MEMORY_LIMIT).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("sac: estimated memory 12.19 GiB"), "{msg}");
        assert!(
            msg.contains("limit of 8.00 GiB") && msg.contains("actor"),
            "{msg}"
        );
        assert!(msg.contains(MEMORY_LIMIT_ENV), "{msg}");
        let small = MemoryEstimate::new()
            .mlp("actor", &[17, 256, 256, 12], 4, 256)
            .f32s("replay", &[1_000_000, 2 * 17 + 2 * 6 + 2]);
        assert_eq!(
            small.check_against("sac", DEFAULT_MEMORY_LIMIT).ok(),
            small.total()
        );
    }

    #[test]
    fn overflow_is_over_any_limit_and_named() {
        let e = MemoryEstimate::new()
            .f32s("small", &[10])
            .f32s("replay", &[usize::MAX, 3]);
        assert_eq!(e.total(), None);
        let err = e.check_against("dqn", u64::MAX).unwrap_err();
        assert!(
            matches!(&err, MemoryError::OverLimit { largest, estimate: None, .. } if largest == "replay")
        );
        assert!(err.to_string().contains("more than 16 EiB"), "{err}");
        // At the limit is accepted, one byte over is not.
        let e = MemoryEstimate::new().part("x", Some(100));
        assert_eq!(e.check_against("t", 100), Ok(100));
        assert!(e.check_against("t", 99).is_err());
    }

    #[test]
    fn sizes_parse_with_binary_units() {
        assert_eq!(parse_size("8GiB"), Some(8 << 30));
        assert_eq!(parse_size(" 512 mib "), Some(512 << 20));
        assert_eq!(parse_size("1.5KiB"), Some(1536));
        assert_eq!(parse_size("1000"), Some(1000));
        assert_eq!(parse_size("16384TiB"), Some(1 << 54));
        for bad in [
            "",
            "0",
            "-1GiB",
            "8 GB",
            "lots",
            "1e30",
            "NaN",
            "99999999TiB",
        ] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn sizes_show_in_binary_units() {
        assert_eq!(show(Some(512)), "512 B");
        assert_eq!(show(Some(1536)), "1.50 KiB");
        assert_eq!(show(Some(8 << 30)), "8.00 GiB");
        assert_eq!(show(None), "more than 16 EiB");
    }
}
