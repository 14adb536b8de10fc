//! Row-major f32 matrix products over the `gemm` crate's kernels (the same kernels candle uses on
//! CPU), without candle's per-op allocation and dispatch.
//!
//! All matrices are dense, row-major slices. `gemm` computes `dst := alpha·dst + beta·lhs·rhs`
//! for arbitrary strides, so transposes are free: they are only a change of strides.
//!
//! # The same bits on every x86-64 CPU
//!
//! `gemm` is built with its `x86-v4` feature, so on CPUs with AVX-512 its 16-lane kernels run
//! (about twice the speed of its 8-lane AVX2 kernels on the tall products of ensembles and
//! rollouts). Its main kernels give every output element one fused multiply-add chain over the
//! contraction in order, whatever the lane count, so they agree bit for bit with the AVX2 kernels;
//! two things of `gemm` do not, and this module takes them over:
//!
//! - **Dot-product kernels.** Where the contraction runs along unit stride in both operands (the
//!   forward `X Wᵀ`) and the output is small (at most 256 elements) or one row or column, `gemm`
//!   sums lane-wise partial dot products, with as many lanes as the CPU's vectors. These products
//!   run here in the order of `gemm`'s AVX2 kernels ([`dot_small`], [`dot_rows`]), on any CPU.
//! - **Blocks of the contraction.** A contraction longer than 512 is cut into blocks whose size
//!   `gemm` derives from the kernel's shape and the CPU's caches. Here it is cut before `gemm` sees
//!   it, into the blocks `gemm` chooses with 512 as the limit ([`k_blocks`]), each block one pass
//!   of `gemm`.
//!
//! So a product gives the same bits with or without AVX-512, and on any cache sizes (tests check
//! the dot-product orders against plain loops written in that order).

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::simd::multiversion;

static GEMM_THREADS: AtomicUsize = AtomicUsize::new(1);

/// Sets how many threads the hand-derived MLP's matrix products use (default 1).
///
/// On the 2-core machines this project targets, one thread per training loop was measured to be
/// best (a second thread never helped, and it collapses when another process
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
    // The contraction along unit stride in both operands: `gemm`'s dot-product kernels.
    let dot = sa.cs == 1 && sb.rs == 1;
    if dot && m * n <= SMALL_DOT {
        dot_small(m, n, k, c, accumulate, a, sa.rs as usize, b, sb.cs as usize);
        return;
    }
    if k > 2 && dot && (m == 1 || n == 1) {
        dot_rows(m, n, k, c, accumulate, a, sa.rs as usize, b, sb.cs as usize);
        return;
    }
    let (first, rest) = k_blocks(m, n, k);
    let mut start = 0;
    let mut kb = first;
    while start < k {
        let len = kb.min(k - start);
        // SAFETY: the strides describe matrices fully inside `a` (m×k), `b` (k×n) and `c` (m×n),
        // as the callers guarantee (lengths asserted in debug builds), and a block of the
        // contraction `start..start + len` stays inside them; `c` does not alias `a` or `b`
        // because it is a unique borrow.
        unsafe {
            gemm::gemm(
                m,
                n,
                len,
                c.as_mut_ptr(),
                1,
                n as isize,
                accumulate || start > 0,
                a.as_ptr().offset(start as isize * sa.cs),
                sa.cs,
                sa.rs,
                b.as_ptr().offset(start as isize * sb.rs),
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
        start += len;
        kb = rest;
    }
}

/// Which code computes `gemm_nt(m, n, k, …)`. Each element's arithmetic depends only on the
/// route and `k`, not on `m`: row blocks of a product give the whole product's bits exactly when
/// they take its route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NtRoute {
    /// [`dot_small`]: `m·n ≤ 256`.
    DotSmall,
    /// [`dot_rows`]: one row or one column, `k > 2`.
    DotRows,
    /// `gemm`'s outer-product path: `k ≤ 2`.
    Outer,
    /// `gemm`'s main kernels: one fused multiply-add chain per element and contraction block,
    /// whatever the operands' layout, so `cᵀ = b aᵀ` through [`gemm_nn`] gives the same bits.
    Main,
}

pub(crate) fn nt_route(m: usize, n: usize, k: usize) -> NtRoute {
    if m * n <= SMALL_DOT {
        NtRoute::DotSmall
    } else if k <= 2 {
        NtRoute::Outer
    } else if m == 1 || n == 1 {
        NtRoute::DotRows
    } else {
        NtRoute::Main
    }
}

/// Largest output (elements) that `gemm` computes with its dot-product ("horizontal") kernels.
const SMALL_DOT: usize = 16 * 16;

/// The blocks `gemm` cuts a contraction of `k` into, as (first block, later blocks), with 512 as
/// the largest block: a product of at most 64 × 64 takes blocks of 512 and the remainder; a larger
/// one the fewest equal blocks of at most 512.
pub(crate) fn k_blocks(m: usize, n: usize, k: usize) -> (usize, usize) {
    const KC: usize = 512;
    if k <= KC {
        (k, k)
    } else if m <= 64 && n <= 64 {
        (KC, KC)
    } else {
        let kc = k.div_ceil(k.div_ceil(KC));
        (kc, kc)
    }
}

/// `c (m×n) = [c +] a · bᵀ` for `m·n <= 256`, row `i` of `a` at `a[i·lda..]` and row `j` of `b`
/// at `b[j·ldb..]`, both `k` long: `gemm`'s AVX2 "horizontal" kernel. Each element sums eight lanes
/// (lane `l` a fused multiply-add chain over `l, l + 8, …` within blocks of 1024), adds them as
/// `((l0 + l4) + (l2 + l6)) + ((l1 + l5) + (l3 + l7))`, and adds the blocks to `c` one by one.
#[allow(clippy::too_many_arguments)]
fn dot_small(
    m: usize,
    n: usize,
    k: usize,
    c: &mut [f32],
    accumulate: bool,
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
) {
    const KC: usize = 1024;
    for i in 0..m {
        for j in 0..n {
            let (x, y) = (&a[i * lda..i * lda + k], &b[j * ldb..j * ldb + k]);
            let mut add = accumulate;
            for (xb, yb) in x.chunks(KC).zip(y.chunks(KC)) {
                let lanes = fma_lanes8(xb, yb);
                let s = ((lanes[0] + lanes[4]) + (lanes[2] + lanes[6]))
                    + ((lanes[1] + lanes[5]) + (lanes[3] + lanes[7]));
                let out = &mut c[i * n + j];
                *out = if add { *out + s } else { s };
                add = true;
            }
        }
    }
}

/// `c (m×n) = [c +] a · bᵀ` for `m == 1` or `n == 1` (and `k > 2`), strides as [`dot_small`]:
/// `gemm`'s AVX2 dot-product gemv. Each element runs eight 8-lane accumulators over blocks of 64,
/// adds them pairwise (`((0+1) + (2+3)) + ((4+5) + (6+7))`), goes on with that one accumulator over
/// whole groups of 8, adds its lanes in order, then adds the last `k mod 8` products one by one.
#[allow(clippy::too_many_arguments)]
fn dot_rows(
    m: usize,
    n: usize,
    k: usize,
    c: &mut [f32],
    accumulate: bool,
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
) {
    for i in 0..m {
        for j in 0..n {
            let s = dot_gemv8(&a[i * lda..i * lda + k], &b[j * ldb..j * ldb + k]);
            let out = &mut c[i * n + j];
            *out = if accumulate { s + *out } else { s };
        }
    }
}

multiversion! {
    /// Eight lanes, lane `l` the fused multiply-add chain of `x[p]·y[p]` over `p ≡ l (mod 8)`.
    fn fma_lanes8(x: &[f32], y: &[f32]) -> [f32; 8] {
        let mut acc = [0.0f32; 8];
        let (xc, xt) = x.as_chunks::<8>();
        let (yc, yt) = y.as_chunks::<8>();
        for (xv, yv) in xc.iter().zip(yc) {
            for l in 0..8 {
                acc[l] = xv[l].mul_add(yv[l], acc[l]);
            }
        }
        for (l, (xs, ys)) in xt.iter().zip(yt).enumerate() {
            acc[l] = xs.mul_add(*ys, acc[l]);
        }
        acc
    }
}

multiversion! {
    /// The dot product of `x` and `y` in the order of `gemm`'s AVX2 gemv (see [`dot_rows`]).
    fn dot_gemv8(x: &[f32], y: &[f32]) -> f32 {
        #[inline(always)]
        fn add(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
            std::array::from_fn(|l| a[l] + b[l])
        }
        let k = x.len();
        let mut acc = [[0.0f32; 8]; 8];
        let (x64, _) = x.as_chunks::<64>();
        let (y64, _) = y.as_chunks::<64>();
        for (xv, yv) in x64.iter().zip(y64) {
            for (r, accr) in acc.iter_mut().enumerate() {
                for l in 0..8 {
                    accr[l] = xv[8 * r + l].mul_add(yv[8 * r + l], accr[l]);
                }
            }
        }
        let mut v = add(
            add(add(acc[0], acc[1]), add(acc[2], acc[3])),
            add(add(acc[4], acc[5]), add(acc[6], acc[7])),
        );
        let mut depth = x64.len() * 64;
        while depth + 8 <= k {
            for l in 0..8 {
                v[l] = x[depth + l].mul_add(y[depth + l], v[l]);
            }
            depth += 8;
        }
        let mut s = v[0];
        for lane in &v[1..] {
            s += lane;
        }
        for p in depth..k {
            s = x[p].mul_add(y[p], s);
        }
        s
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

    /// `gemm`'s main kernels in scalar form: each element a fused multiply-add chain over the
    /// contraction in order, restarted at each block of [`k_blocks`] and added to the output.
    fn fma_chains(
        m: usize,
        n: usize,
        k: usize,
        a: impl Fn(usize, usize) -> f32,
        b: impl Fn(usize, usize) -> f32,
        c0: &[f32],
        acc: bool,
    ) -> Vec<f32> {
        let (first, rest) = k_blocks(m, n, k);
        let mut c = c0.to_vec();
        for i in 0..m {
            for j in 0..n {
                let (mut start, mut kb, mut add) = (0, first, acc);
                while start < k {
                    let end = (start + kb).min(k);
                    let mut s = 0.0f32;
                    for p in start..end {
                        s = a(i, p).mul_add(b(p, j), s);
                    }
                    c[i * n + j] = if add { c[i * n + j] + s } else { s };
                    (start, kb, add) = (end, rest, true);
                }
            }
        }
        c
    }

    fn data(len: usize, f: f32) -> Vec<f32> {
        (0..len).map(|i| (i as f32 * f).sin()).collect()
    }

    fn same_bits(got: &[f32], want: &[f32], what: &str) {
        let bad = got
            .iter()
            .zip(want)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count();
        assert_eq!(bad, 0, "{what}: {bad} of {} elements differ", want.len());
    }

    /// Outside the dot-product cases every product, on whichever kernels this CPU runs (AVX-512,
    /// AVX2), gives each element exactly one fused multiply-add chain per contraction block: the
    /// property that makes the bits independent of the lane count. Shapes cover the large-product
    /// blocks (k = 700, 1300), the small-product blocks (512 and the rest) and single blocks.
    #[test]
    fn main_kernels_are_one_fma_chain_per_block_on_this_cpu() {
        for (m, n, k) in [
            (37, 70, 200),
            (300, 36, 23),
            (9, 65, 700),
            (70, 20, 1300),
            (8, 40, 1100),
        ] {
            let c0 = data(m * n, 0.05);
            for acc in [false, true] {
                let (a, bt) = (data(m * k, 0.37), data(n * k, 0.11)); // m×k, n×k
                let mut c = c0.clone();
                gemm_nt(m, n, k, &a, &bt, &mut c, acc);
                let want = fma_chains(m, n, k, |i, p| a[i * k + p], |p, j| bt[j * k + p], &c0, acc);
                same_bits(&c, &want, &format!("nt {m}×{n}×{k}"));

                let (at, bn) = (data(k * m, 0.31), data(k * n, 0.23)); // k×m, k×n
                let mut c = c0.clone();
                gemm_tn(m, n, k, &at, &bn, &mut c, acc);
                let want = fma_chains(
                    m,
                    n,
                    k,
                    |i, p| at[p * m + i],
                    |p, j| bn[p * n + j],
                    &c0,
                    acc,
                );
                same_bits(&c, &want, &format!("tn {m}×{n}×{k}"));

                let mut c = c0.clone();
                gemm_nn(m, n, k, &a, &bn, &mut c, acc);
                let want = fma_chains(m, n, k, |i, p| a[i * k + p], |p, j| bn[p * n + j], &c0, acc);
                same_bits(&c, &want, &format!("nn {m}×{n}×{k}"));
            }
        }
    }

    /// On [`NtRoute::Main`], `Y = X Wᵀ` (row-major) and `Yᵀ = W Xᵀ` (feature-major, as
    /// [`crate::Mlp`]'s inference keeps its activations) are the same bits.
    #[test]
    fn main_kernel_products_give_the_same_bits_feature_major() {
        let mut checked = 0;
        for m in [2, 3, 7, 16, 17, 50, 100, 129, 256, 500] {
            for n in [2, 5, 6, 17, 36, 64, 200, 256] {
                for k in [3, 4, 23, 200, 513, 1100] {
                    if nt_route(m, n, k) != NtRoute::Main || m * n * k > 30_000_000 {
                        continue;
                    }
                    let (x, w) = (data(m * k, 0.37), data(n * k, 0.11));
                    let mut xt = vec![0.0; m * k];
                    for i in 0..m {
                        for p in 0..k {
                            xt[p * m + i] = x[i * k + p];
                        }
                    }
                    let (mut y, mut yt) = (vec![0.0; m * n], vec![0.0; m * n]);
                    gemm_nt(m, n, k, &x, &w, &mut y, false);
                    gemm_nn(n, m, k, &w, &xt, &mut yt, false);
                    let back: Vec<f32> = (0..m * n).map(|e| yt[(e % n) * m + e / n]).collect();
                    same_bits(&back, &y, &format!("{m}×{n}×{k}"));
                    checked += 1;
                }
            }
        }
        assert!(checked > 300, "only {checked} shapes checked");
    }

    /// The dot-product products follow `gemm`'s AVX2 orders, written here as plain index loops:
    /// eight strided lanes added as a tree (small outputs, blocks of 1024), and eight 8-lane
    /// accumulators over blocks of 64, a tree, whole groups of 8, the lanes in order and the rest
    /// one by one (single rows and columns).
    #[test]
    fn dot_products_follow_the_avx2_orders() {
        fn lanes(x: &[f32], y: &[f32]) -> f32 {
            let mut l = [0.0f32; 8];
            for p in 0..x.len() {
                l[p % 8] = x[p].mul_add(y[p], l[p % 8]);
            }
            ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7]))
        }
        // Index loops on purpose: the reference spells out which element goes to which lane.
        #[allow(clippy::needless_range_loop)]
        fn gemv(x: &[f32], y: &[f32]) -> f32 {
            let k = x.len();
            let mut acc = [[0.0f32; 8]; 8];
            let mut d = 0;
            while d + 64 <= k {
                for r in 0..8 {
                    for l in 0..8 {
                        let p = d + 8 * r + l;
                        acc[r][l] = x[p].mul_add(y[p], acc[r][l]);
                    }
                }
                d += 64;
            }
            let mut v = [0.0f32; 8];
            for l in 0..8 {
                v[l] = ((acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]))
                    + ((acc[4][l] + acc[5][l]) + (acc[6][l] + acc[7][l]));
            }
            while d + 8 <= k {
                for l in 0..8 {
                    v[l] = x[d + l].mul_add(y[d + l], v[l]);
                }
                d += 8;
            }
            let mut s = v[0];
            for lane in &v[1..] {
                s += lane;
            }
            for p in d..k {
                s = x[p].mul_add(y[p], s);
            }
            s
        }
        for (m, n, k) in [
            (16, 16, 203),
            (3, 5, 2500),
            (7, 2, 1),
            (1, 300, 131),
            (257, 1, 64),
            (1, 1, 9),
        ] {
            let (a, bt) = (data(m * k, 0.37), data(n * k, 0.11));
            let c0 = data(m * n, 0.05);
            for acc in [false, true] {
                let mut c = c0.clone();
                gemm_nt(m, n, k, &a, &bt, &mut c, acc);
                let mut want = c0.clone();
                for i in 0..m {
                    for j in 0..n {
                        let (x, y) = (&a[i * k..(i + 1) * k], &bt[j * k..(j + 1) * k]);
                        let mut add = acc;
                        if m * n <= SMALL_DOT {
                            for (xb, yb) in x.chunks(1024).zip(y.chunks(1024)) {
                                let s = lanes(xb, yb);
                                want[i * n + j] = if add { want[i * n + j] + s } else { s };
                                add = true;
                            }
                        } else {
                            let s = gemv(x, y);
                            want[i * n + j] = if add { s + want[i * n + j] } else { s };
                        }
                    }
                }
                same_bits(&c, &want, &format!("nt {m}×{n}×{k}"));
            }
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
