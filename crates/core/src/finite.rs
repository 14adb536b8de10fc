//! Finiteness scans over whole buffers: every input, output and gradient tandem checks.

use num_traits::Float;

/// Index of the first NaN or infinite element of `x`, if any. Vectorizes: a first pass sums
/// `x * 0` in eight lanes, which is NaN exactly when some element is NaN or infinite; only then
/// is the position searched.
pub fn first_non_finite<F: Float>(x: &[F]) -> Option<usize> {
    let zero = F::zero();
    let mut acc = [zero; 8];
    let chunks = x.chunks_exact(8);
    let rem = chunks.remainder();
    for c in chunks {
        for k in 0..8 {
            acc[k] = acc[k] + c[k] * zero;
        }
    }
    let s = acc.iter().chain(rem).fold(zero, |s, &v| s + v * zero);
    if s == zero {
        None
    } else {
        x.iter().position(|v| !v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agrees with the element-by-element scan for every bad value at every position of the
    /// chunked part and the remainder, in both widths.
    #[test]
    fn finds_the_first_bad_element_as_a_plain_scan_does() {
        fn check<F: Float + std::fmt::Debug>() {
            for len in [0, 1, 7, 8, 9, 23, 64] {
                let clean: Vec<F> = (0..len)
                    .map(|i| F::from(i as f64 * 1e30 - 3.0).unwrap())
                    .collect();
                assert_eq!(first_non_finite(&clean), None);
                for bad in [F::nan(), F::infinity(), F::neg_infinity()] {
                    for at in 0..len {
                        let mut x = clean.clone();
                        x[at] = bad;
                        if at + 2 < len {
                            x[at + 2] = F::nan();
                        }
                        let plain = x.iter().position(|v| !v.is_finite());
                        assert_eq!(first_non_finite(&x), plain);
                        assert_eq!(plain, Some(at));
                    }
                }
            }
        }
        check::<f32>();
        check::<f64>();
    }

    /// The largest finite values and subnormals are finite: `x * 0` is 0 for them.
    #[test]
    fn extreme_finite_values_pass() {
        let x = [f64::MAX, f64::MIN, f64::MIN_POSITIVE / 4.0, -0.0, 0.0];
        assert_eq!(first_non_finite(&x), None);
        let y = [f32::MAX, f32::MIN, f32::MIN_POSITIVE / 4.0, -0.0];
        assert_eq!(first_non_finite(&y), None);
    }
}
