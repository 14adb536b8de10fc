//! Row-major f32 matrix products over the `gemm` crate's kernels (the same kernels candle uses on
//! CPU), without candle's per-op allocation and dispatch.
//!
//! All matrices are dense, row-major slices. `gemm` computes `dst := alpha·dst + beta·lhs·rhs`
//! for arbitrary strides, so transposes are free: they are only a change of strides.

use std::sync::atomic::{AtomicUsize, Ordering};

static GEMM_THREADS: AtomicUsize = AtomicUsize::new(1);

/// Sets how many threads the hand-derived MLP's matrix products use (default 1).
///
/// On the 2-core machines this project targets, one thread per training loop was measured to be
/// best (`notes/candle-on-cpu.md`: a second thread never helped and collapses when another process
/// is busy) for training-sized products; large batched predictions (a planner's population of
/// 500 through 400-wide layers) can gain from 2. Values above 1 use `gemm`'s rayon parallelism
/// for products of at least 2^21 multiply-adds. Global to the process.
pub fn set_gemm_threads(n: usize) {
    GEMM_THREADS.store(n.max(1), Ordering::Relaxed);
}

/// The thread count set by [`set_gemm_threads`].
pub fn gemm_threads() -> usize {
    GEMM_THREADS.load(Ordering::Relaxed)
}

/// Products smaller than this many multiply-adds always run on one thread: below it, waking a
/// second thread costs more than it saves (a 256×256×256 product is 16.8M).
const PARALLEL_MIN_MACS: usize = 1 << 21;

#[inline]
fn parallelism(m: usize, n: usize, k: usize) -> gemm::Parallelism {
    match GEMM_THREADS.load(Ordering::Relaxed) {
        0 | 1 => gemm::Parallelism::None,
        _ if m * n * k < PARALLEL_MIN_MACS => gemm::Parallelism::None,
        t => gemm::Parallelism::Rayon(t),
    }
}

/// Strides of an operand, in elements: (row stride, column stride).
#[derive(Clone, Copy)]
struct Strides {
    rs: isize,
    cs: isize,
}

/// `c (m×n) = [c +] op(a) · op(b)` with the given operand strides. Lengths are checked by the
/// callers (debug-asserted here).
#[allow(clippy::too_many_arguments)]
#[inline]
fn gemm_raw(
    m: usize,
    n: usize,
    k: usize,
    c: &mut [f32],
    accumulate: bool,
    a: &[f32],
    sa: Strides,
    b: &[f32],
    sb: Strides,
) {
    debug_assert!(c.len() >= m * n);
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            c[..m * n].fill(0.0);
        }
        return;
    }
    debug_assert!(a.len() >= m * k);
    debug_assert!(b.len() >= k * n);
    // SAFETY: the strides describe matrices fully inside `a` (m×k), `b` (k×n) and `c` (m×n), as
    // the callers guarantee (lengths asserted in debug builds); `c` does not alias `a` or `b`
    // because it is a unique borrow.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.as_ptr(),
            sa.cs,
            sa.rs,
            b.as_ptr(),
            sb.cs,
            sb.rs,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            parallelism(m, n, k),
        );
    }
}

/// `c (m×n) = [c +] a (m×k) · bᵀ` where `b` is stored n×k. (Forward: `Y = X Wᵀ`.)
pub(crate) fn gemm_nt(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    b: &[f32],
    c: &mut [f32],
    acc: bool,
) {
    gemm_raw(
        m,
        n,
        k,
        c,
        acc,
        a,
        Strides {
            rs: k as isize,
            cs: 1,
        },
        b,
        Strides {
            rs: 1,
            cs: k as isize,
        },
    );
}

/// `c (m×n) = [c +] aᵀ · b` where `a` is stored k×m and `b` k×n. (Weight gradient: `dW = dZᵀ X`.)
pub(crate) fn gemm_tn(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    b: &[f32],
    c: &mut [f32],
    acc: bool,
) {
    gemm_raw(
        m,
        n,
        k,
        c,
        acc,
        a,
        Strides {
            rs: 1,
            cs: m as isize,
        },
        b,
        Strides {
            rs: n as isize,
            cs: 1,
        },
    );
}

/// `c (m×n) = [c +] a (m×k) · b (k×n)`. (Input gradient: `dX = dZ W`.)
pub(crate) fn gemm_nn(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    b: &[f32],
    c: &mut [f32],
    acc: bool,
) {
    gemm_raw(
        m,
        n,
        k,
        c,
        acc,
        a,
        Strides {
            rs: k as isize,
            cs: 1,
        },
        b,
        Strides {
            rs: n as isize,
            cs: 1,
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(
        m: usize,
        n: usize,
        k: usize,
        a: impl Fn(usize, usize) -> f32,
        b: impl Fn(usize, usize) -> f32,
    ) -> Vec<f32> {
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                let mut s = 0.0f64;
                for p in 0..k {
                    s += f64::from(a(i, p)) * f64::from(b(p, j));
                }
                c[i * n + j] = s as f32;
            }
        }
        c
    }

    #[test]
    fn two_thread_products_match_naive_loops() {
        // Large enough to cross the parallel threshold. (Only products this large are affected by
        // the global setting, and no other test uses one.)
        let (m, n, k) = (256, 160, 128);
        let a: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.013).sin()).collect();
        let b: Vec<f32> = (0..n * k).map(|i| (i as f32 * 0.007).cos()).collect();
        let want = naive(m, n, k, |i, p| a[i * k + p], |p, j| b[j * k + p]);
        set_gemm_threads(2);
        assert_eq!(gemm_threads(), 2);
        let mut c = vec![0.0; m * n];
        gemm_nt(m, n, k, &a, &b, &mut c, false);
        set_gemm_threads(1);
        for (x, y) in c.iter().zip(&want) {
            assert!((x - y).abs() < 1e-3);
        }
    }

    #[test]
    fn products_match_naive_loops() {
        let (m, n, k) = (5, 7, 3);
        let a: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
        let bt: Vec<f32> = (0..n * k).map(|i| (i as f32 * 0.11).cos()).collect(); // n×k
        let bn: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.23).cos()).collect(); // k×n
        let at: Vec<f32> = (0..k * m).map(|i| (i as f32 * 0.31).sin()).collect(); // k×m

        let mut c = vec![0.0; m * n];
        gemm_nt(m, n, k, &a, &bt, &mut c, false);
        let want = naive(m, n, k, |i, p| a[i * k + p], |p, j| bt[j * k + p]);
        for (x, y) in c.iter().zip(&want) {
            assert!((x - y).abs() < 1e-5);
        }

        gemm_nn(m, n, k, &a, &bn, &mut c, false);
        let want = naive(m, n, k, |i, p| a[i * k + p], |p, j| bn[p * n + j]);
        for (x, y) in c.iter().zip(&want) {
            assert!((x - y).abs() < 1e-5);
        }

        // Accumulating adds to what is there.
        let before = c.clone();
        gemm_tn(m, n, k, &at, &bn, &mut c, true);
        let want = naive(m, n, k, |i, p| at[p * m + i], |p, j| bn[p * n + j]);
        for ((x, y), b0) in c.iter().zip(&want).zip(&before) {
            assert!((x - (y + b0)).abs() < 1e-5);
        }
    }
}
