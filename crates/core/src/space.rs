//! Observation and action spaces with gymnasium's meaning, and the [`Action`] type.

use serde::{Deserialize, Serialize};

/// Why an action or observation does not belong to a space.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpaceError {
    /// A continuous action given to a discrete space or the reverse.
    #[error("expected a {expected} action, got a {got} one")]
    WrongKind {
        /// The kind the space holds.
        expected: &'static str,
        /// The kind that was given.
        got: &'static str,
    },
    /// A vector of the wrong length.
    #[error("expected {expected} components, got {got}")]
    WrongDim {
        /// The space's dimension.
        expected: usize,
        /// The length that was given.
        got: usize,
    },
    /// A NaN or infinite component.
    #[error("component {index} is not finite ({value})")]
    NonFinite {
        /// Index of the offending component.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A discrete action outside `0..n`.
    #[error("discrete action {action} is outside 0..{n}")]
    OutOfRange {
        /// The action that was given.
        action: usize,
        /// Number of actions.
        n: usize,
    },
}

/// A space of observations or actions (gymnasium's `Box` and `Discrete`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Space {
    /// A box of real vectors, `low[i] <= x[i] <= high[i]`; bounds may be infinite. `shape` is the
    /// logical shape (e.g. `[16, 16, 3]` for an image); data is stored flat, row-major.
    Box {
        /// Lower bounds, one per component.
        low: Vec<f64>,
        /// Upper bounds, one per component.
        high: Vec<f64>,
        /// Logical shape; its product equals `low.len()`.
        shape: Vec<usize>,
    },
    /// `n` discrete choices `0..n`.
    Discrete {
        /// Number of choices.
        n: usize,
    },
}

impl Space {
    /// A flat box with the given bounds.
    pub fn boxed(low: Vec<f64>, high: Vec<f64>) -> Self {
        assert_eq!(low.len(), high.len(), "box bounds of different lengths");
        let shape = vec![low.len()];
        Space::Box { low, high, shape }
    }

    /// A flat box `[-b, b]^n` with the same bound on every component.
    pub fn symmetric(n: usize, b: f64) -> Self {
        Self::boxed(vec![-b; n], vec![b; n])
    }

    /// A flat box of `n` components without bounds: an observation space where none is known.
    pub fn unbounded(n: usize) -> Self {
        Self::boxed(vec![f64::NEG_INFINITY; n], vec![f64::INFINITY; n])
    }

    /// A discrete space of `n` choices.
    pub fn discrete(n: usize) -> Self {
        Space::Discrete { n }
    }

    /// Number of components of a flat vector in this space (`1` for a discrete space, whose
    /// element is one index).
    pub fn flat_dim(&self) -> usize {
        match self {
            Space::Box { low, .. } => low.len(),
            Space::Discrete { .. } => 1,
        }
    }

    /// `true` for a discrete space.
    pub fn is_discrete(&self) -> bool {
        matches!(self, Space::Discrete { .. })
    }

    /// Checks that `action` is of this space's kind and dimension and is finite. A continuous
    /// action outside the bounds is allowed (environments clip, as gymnasium's do).
    pub fn check(&self, action: &Action) -> Result<(), SpaceError> {
        match (self, action) {
            (Space::Box { low, .. }, Action::Continuous(a)) => {
                if a.len() != low.len() {
                    return Err(SpaceError::WrongDim {
                        expected: low.len(),
                        got: a.len(),
                    });
                }
                if let Some((index, &value)) = a.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    return Err(SpaceError::NonFinite { index, value });
                }
                Ok(())
            }
            (Space::Discrete { n }, Action::Discrete(k)) => {
                if k < n {
                    Ok(())
                } else {
                    Err(SpaceError::OutOfRange { action: *k, n: *n })
                }
            }
            (Space::Box { .. }, Action::Discrete(_)) => Err(SpaceError::WrongKind {
                expected: "continuous",
                got: "discrete",
            }),
            (Space::Discrete { .. }, Action::Continuous(_)) => Err(SpaceError::WrongKind {
                expected: "discrete",
                got: "continuous",
            }),
        }
    }

    /// A short human-readable description, e.g. `Box(3) [-1, 1]` or `Discrete(2)`.
    pub fn describe(&self) -> String {
        match self {
            Space::Box { low, high, shape } => {
                let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
                // Long boxes with one bound for every component (images) print it once.
                let fmt = |v: &[f64]| {
                    if v.len() > 8 && v.iter().all(|x| x.to_bits() == v[0].to_bits()) {
                        return format!("{} (every component)", v[0]);
                    }
                    let s: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
                    format!("[{}]", s.join(", "))
                };
                format!(
                    "Box({}) low={} high={}",
                    dims.join("x"),
                    fmt(low),
                    fmt(high)
                )
            }
            Space::Discrete { n } => format!("Discrete({n})"),
        }
    }
}

/// An action: a real vector for a box space, an index for a discrete one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Action {
    /// An index in `0..n`.
    Discrete(usize),
    /// A real vector.
    Continuous(Vec<f64>),
}

impl Action {
    /// The real vector of a continuous action, `None` for a discrete one.
    pub fn as_continuous(&self) -> Option<&[f64]> {
        match self {
            Action::Continuous(v) => Some(v),
            Action::Discrete(_) => None,
        }
    }

    /// The index of a discrete action, `None` for a continuous one.
    pub fn as_discrete(&self) -> Option<usize> {
        match self {
            Action::Discrete(k) => Some(*k),
            Action::Continuous(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_reports_each_problem() {
        let b = Space::symmetric(2, 1.0);
        assert!(b.check(&Action::Continuous(vec![0.5, 3.0])).is_ok());
        assert_eq!(
            b.check(&Action::Continuous(vec![0.5])),
            Err(SpaceError::WrongDim {
                expected: 2,
                got: 1
            })
        );
        assert!(matches!(
            b.check(&Action::Continuous(vec![0.5, f64::NAN])),
            Err(SpaceError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            b.check(&Action::Discrete(0)),
            Err(SpaceError::WrongKind { .. })
        ));
        let d = Space::discrete(2);
        assert!(d.check(&Action::Discrete(1)).is_ok());
        assert_eq!(
            d.check(&Action::Discrete(2)),
            Err(SpaceError::OutOfRange { action: 2, n: 2 })
        );
    }

    #[test]
    fn describe_prints_shape_and_a_uniform_bound_of_an_image_once() {
        assert_eq!(
            Space::symmetric(2, 3.0).describe(),
            "Box(2) low=[-3, -3] high=[3, 3]"
        );
        let img = Space::Box {
            low: vec![0.0; 768],
            high: vec![1.0; 768],
            shape: vec![16, 16, 3],
        };
        assert_eq!(
            img.describe(),
            "Box(16x16x3) low=0 (every component) high=1 (every component)"
        );
        assert_eq!(Space::discrete(5).describe(), "Discrete(5)");
    }
}
