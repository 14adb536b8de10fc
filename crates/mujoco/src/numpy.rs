//! NumPy's summation order, so that rewards summed here round exactly as gymnasium's do.
//!
//! `np.sum` over a contiguous array is a pairwise sum: fewer than 8 terms are added left to
//! right; up to 128 terms go into 8 strided accumulators combined as
//! `((r0+r1)+(r2+r3))+((r4+r5)+(r6+r7))`, the remainder added after them; longer arrays are split
//! in two (the first part a multiple of 8 long) and the halves summed recursively. gymnasium's
//! control costs are sums of `float32` squares, so the same order is also given in `f32`.

/// NumPy's block length below which the 8-accumulator loop runs without splitting.
const BLOCK: usize = 128;

macro_rules! pairwise {
    ($name:ident, $t:ty) => {
        /// `np.sum` of a contiguous 1-D array, in NumPy's pairwise order.
        pub fn $name(a: &[$t]) -> $t {
            let n = a.len();
            if n < 8 {
                let mut res: $t = 0.0;
                for &v in a {
                    res += v;
                }
                res
            } else if n <= BLOCK {
                let mut r: [$t; 8] = [0.0; 8];
                r.copy_from_slice(&a[..8]);
                let full = n - n % 8;
                for chunk in a[8..full].chunks_exact(8) {
                    for (acc, v) in r.iter_mut().zip(chunk) {
                        *acc += v;
                    }
                }
                let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
                for &v in &a[full..] {
                    res += v;
                }
                res
            } else {
                let mut n2 = n / 2;
                n2 -= n2 % 8;
                $name(&a[..n2]) + $name(&a[n2..])
            }
        }
    };
}

pairwise!(np_sum_f64, f64);
pairwise!(np_sum_f32, f32);

/// `np.sum(np.square(a))` of a `float32` action, in `float32` as NumPy computes it. At most 32
/// components (every task here has at most 8); longer actions are summed in chunks of 32.
pub fn np_sum_squares_f32(a: &[f32]) -> f32 {
    let mut sq = [0.0f32; 32];
    if a.len() <= sq.len() {
        for (s, v) in sq.iter_mut().zip(a) {
            *s = v * v;
        }
        return np_sum_f32(&sq[..a.len()]);
    }
    let squares: Vec<f32> = a.iter().map(|v| v * v).collect();
    np_sum_f32(&squares)
}

/// `np.linalg.norm` of a 3-vector: the square root of the sum of squares, added left to right.
/// NumPy calls BLAS's `dot`, whose order may differ in the last bit (about 1e-16 relative).
pub fn norm3(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values whose sum depends on the order: 1 followed by many halves of an ulp of 1.
    fn tricky(n: usize) -> Vec<f64> {
        let mut v = vec![f64::EPSILON / 2.0; n];
        v[0] = 1.0;
        v
    }

    #[test]
    fn short_sums_run_left_to_right() {
        // Left to right, every half-ulp is lost against the leading 1.
        assert_eq!(np_sum_f64(&tricky(7)), 1.0);
        assert_eq!(np_sum_f64(&[]), 0.0);
    }

    #[test]
    fn eight_accumulators_keep_what_a_sequential_sum_loses() {
        // n = 16: accumulator 0 holds 1 + h (= 1), accumulators 1..7 hold h + h = ulp each:
        // ((1 + ulp) + 2ulp) + (2ulp + 2ulp) = 1 + 7 ulp exactly (hand computed).
        let v = tricky(16);
        let seq: f64 = v.iter().sum();
        assert_eq!(seq, 1.0);
        assert_eq!(np_sum_f64(&v), 1.0 + 7.0 * f64::EPSILON);
        // n = 10: r = [1, h, .., h] combines to 1 + 3 ulp (1 + h ties to even: 1); then the two
        // remainder half-ulps: 1 + 3ulp + h ties to the even 1 + 4ulp, and 1 + 4ulp + h stays.
        assert_eq!(np_sum_f64(&tricky(10)), 1.0 + 4.0 * f64::EPSILON);
    }

    #[test]
    fn long_sums_split_at_a_multiple_of_eight() {
        // 200 ones sum exactly whatever the order; the split points are checked through a
        // recursion twin written from NumPy's source independently of the macro.
        fn twin(a: &[f64]) -> f64 {
            if a.len() <= 128 {
                return np_sum_f64(a);
            }
            let n2 = (a.len() / 2) / 8 * 8;
            twin(&a[..n2]) + twin(&a[n2..])
        }
        let v: Vec<f64> = (0..300).map(|i| 1.0 / (1.0 + i as f64)).collect();
        assert_eq!(np_sum_f64(&v), twin(&v));
        assert_eq!(np_sum_f64(&vec![1.0; 200]), 200.0);
    }

    #[test]
    fn f32_squares_stay_in_f32() {
        let a = [0.1f32, 0.2, 0.3];
        let expected = (0.1f32 * 0.1f32 + 0.2f32 * 0.2f32) + 0.3f32 * 0.3f32;
        assert_eq!(np_sum_squares_f32(&a), expected);
        assert_ne!(
            np_sum_squares_f32(&a) as f64,
            0.1 * 0.1 + 0.2 * 0.2 + 0.3 * 0.3
        );
        let long = vec![0.5f32; 40];
        assert_eq!(np_sum_squares_f32(&long), 10.0);
    }

    #[test]
    fn norm_of_a_pythagorean_triple() {
        assert_eq!(norm3([3.0, 4.0, 12.0]), 13.0);
    }
}
