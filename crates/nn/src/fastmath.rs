//! Element-wise `exp`, `exp_m1`, `ln_1p`, `softplus`, `sigmoid`, `silu` and `tanh` in f32, written
//! so that the compiler vectorizes them (the standard library calls scalar libm for each element:
//! a SiLU layer of 500×400 cost more than its matrix product, the Gaussian head's `log1pf` and
//! `expf` a tenth of an ensemble's fit).
//!
//! Every function is branch-free (selects, not jumps), uses no float-to-int conversion (whose NaN
//! handling stops vectorization) and no fused multiply-add, so a loop over them gives the same
//! bits with 1, 4, 8 or 16 lanes ([`crate::simd`]).
//!
//! Accuracy, against the f64 functions of libm rounded to f32, in units in the last place of the
//! f32 result (ulps), over every f32 input (`accurate_over_every_input`, run by hand in release:
//! `cargo test --release -p tandem-nn fastmath -- --ignored`, 15 minutes; `cargo test` checks every
//! 9973rd):
//!
//! | function | max error (ulps) | at |
//! |---|---|---|
//! | `exp` | 0.99 | 70.4 |
//! | `exp_m1` | 1.57 | 0.353 |
//! | `ln_1p` | 0.86 | 0.406 |
//! | `softplus` | 1.65 | −1.27 |
//! | `sigmoid` | 2.83 | −1.95 |
//! | `silu` | 3.47 | −5.18 |
//! | `tanh` | 2.50 | 4.51 |
//!
//! ±0, ±∞ and NaN give what libm gives (`silu(-∞)` is `-0`, its limit), and results that are
//! subnormal in f32 are computed, not flushed.
//!
//! `exp` reduces `x = n ln2 + r`, `|r| ≤ ln2/2`, with `ln2` split in two (Cody and Waite) and
//! evaluates `e^r = 1 + r + r²·P(r)` with Cephes' degree-5 minimax `P`; `exp_m1` keeps `e^r - 1 =
//! r + r²·P(r)` apart from the 1 and scales it as `2^n(e^r - 1) + (2^n - 1)`, exact for `n = 0`.
//! `ln_1p` is fdlibm's scheme: `1 + x = 2^k(1 + f)` with `√2/2 ≤ 1 + f < √2`, a correction for the
//! rounding of `1 + x`, and `ln(1 + f) = f - f²/2 + s(f²/2 + R(s²))` with `s = f/(2 + f)`.

/// `ln 2` split so that `n · LN2_HI` is exact for `|n| < 512`.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
const LOG2E: f32 = std::f32::consts::LOG2_E;
/// 1.5·2^23: adding and subtracting it rounds to the nearest integer.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// Cephes' `expf` coefficients: `e^r ≈ 1 + r + r²(P0 + r(P1 + …))` on `|r| ≤ ln2/2`.
const EXP_P: [f32; 6] = [
    0.5,
    1.666_666_5e-1,
    4.166_579_6e-2,
    8.333_452e-3,
    1.398_2e-3,
    1.987_569_1e-4,
];

/// `(n, r, r + r²P(r))` for `x = n ln2 + r`, with `n` as an integer-valued float and as its bits
/// offset from [`ROUND_MAGIC`]'s (the integer itself, for `|n| < 2^22`).
#[inline(always)]
fn reduce(x: f32) -> (i32, f32) {
    let t = x * LOG2E + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p =
        EXP_P[0] + r * (EXP_P[1] + r * (EXP_P[2] + r * (EXP_P[3] + r * (EXP_P[4] + r * EXP_P[5]))));
    // `t` lies in [2^23, 2^24), where one unit of the mantissa is 1: its bits are ROUND_MAGIC's
    // plus `n`.
    let k = t.to_bits().wrapping_sub(ROUND_MAGIC.to_bits()) as i32;
    (k, r + r * r * p)
}

/// `2^k` for `k` in `[-126, 127]`.
#[inline(always)]
fn pow2(k: i32) -> f32 {
    f32::from_bits((k.wrapping_add(127) as u32) << 23)
}

/// `e^x`.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    let (m, s) = exp_parts(x);
    m * s
}

/// `(m, s)` with `e^x = m·s` and `m` a normal float: `s` is 1 but where `e^x` is subnormal
/// (2^-64) or near overflow (2). A product that scales `e^x` can then round once, by the last
/// factor `s`, instead of twice.
#[inline(always)]
fn exp_parts(x: f32) -> (f32, f32) {
    // Beyond these e^x is 0 or ∞ in f32; the clamp keeps `n` small (NaN passes through).
    let (k, q) = reduce(x.clamp(-112.0, 89.0));
    let low = k < -126;
    let high = k > 127;
    let k1 = if low {
        k + 64
    } else if high {
        k - 1
    } else {
        k
    };
    let s = if low {
        f32::from_bits(0x1f80_0000) // 2^-64
    } else if high {
        2.0
    } else {
        1.0
    };
    ((1.0 + q) * pow2(k1), s)
}

/// [`exp_parts`] for `x ≤ 0` (or NaN), with no overflow to mind: `e^-|x|` in the logistic
/// functions, where the fewer selects are a tenth of the work.
#[inline(always)]
fn exp_parts_nonpositive(x: f32) -> (f32, f32) {
    let (k, q) = reduce(if x < -112.0 { -112.0 } else { x });
    let low = k < -126;
    let k1 = if low { k + 64 } else { k };
    let s = if low {
        f32::from_bits(0x1f80_0000) // 2^-64
    } else {
        1.0
    };
    ((1.0 + q) * pow2(k1), s)
}

/// `e^x - 1`, to a few ulps also near 0.
#[inline(always)]
pub fn exp_m1(x: f32) -> f32 {
    // Below -17.5 the result rounds to -1; above 89 it overflows.
    let (k, q) = reduce(x.clamp(-20.0, 89.0));
    // 2^k (q + 1) - 1 = 2^k q + (2^k - 1), exact but for the last addition when |k| ≤ 24; at
    // k = 128, 2·(2^127 q + 2^127 - 1/2).
    let high = k > 127;
    let s = pow2(if high { k - 1 } else { k });
    let one = if high { 0.5 } else { 1.0 };
    let y = (s * q + (s - one)) * if high { 2.0 } else { 1.0 };
    // Tiny arguments (±0 among them) are their own result.
    if x.abs() < 2.980_232_2e-8 {
        x
    } else {
        y
    }
}

/// `ln(1 + x)`.
#[inline(always)]
pub fn ln_1p(x: f32) -> f32 {
    const SQRT2_HALF_BITS: u32 = 0x3f35_04f3;
    const LG: [f32; 4] = [0.666_666_6, 0.400_009_72, 0.284_987_87, 0.242_790_79];
    let u = 1.0 + x;
    // u = 2^k (1 + f), 1 + f in [√2/2, √2): shift the bits so the exponent field gives k.
    let iu = u.to_bits().wrapping_add(0x3f80_0000 - SQRT2_HALF_BITS);
    let k = (iu >> 23) as i32 - 127;
    let f = f32::from_bits((iu & 0x007f_ffff) + SQRT2_HALF_BITS) - 1.0;
    // What rounding 1 + x lost, relative to u (exact subtractions in each case).
    let c = if k >= 2 { 1.0 - (u - x) } else { x - (u - 1.0) } / u;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let r = z * (LG[0] + w * LG[2]) + w * (LG[1] + w * LG[3]);
    let hfsq = 0.5 * f * f;
    let dk = k as f32;
    let y = s * (hfsq + r) + (dk * LN2_LO + c) - hfsq + f + dk * LN2_HI;
    if x.abs() < 2.980_232_2e-8 || x.is_nan() || x == f32::INFINITY {
        x
    } else if x == -1.0 {
        f32::NEG_INFINITY
    } else if x < -1.0 {
        f32::NAN
    } else {
        y
    }
}

/// `ln(1 + e^x)`, stable for every `x`.
#[inline(always)]
pub fn softplus(x: f32) -> f32 {
    softplus_and_sigmoid(x).0
}

/// What the logistic functions share: `e^-|x| = m·scale` ([`exp_parts`]), `r = 1/(1 + e^-|x|)`
/// and the logistic function itself, `r` or `e^-|x|·r` by the sign of `x`. One piece, so that
/// every form of the logistic function here has the same bits.
struct Logistic {
    m: f32,
    scale: f32,
    e: f32,
    r: f32,
    sigmoid: f32,
}

#[inline(always)]
fn logistic(x: f32) -> Logistic {
    let (m, scale) = exp_parts_nonpositive(-x.abs());
    let e = m * scale;
    let r = 1.0 / (1.0 + e);
    let sigmoid = if x >= 0.0 { r } else { e * r };
    Logistic {
        m,
        scale,
        e,
        r,
        sigmoid,
    }
}

/// `(ln(1 + e^x), 1/(1 + e^-x))` from one `exp(-|x|)`: the softplus and its derivative, the
/// logistic function.
#[inline(always)]
pub fn softplus_and_sigmoid(x: f32) -> (f32, f32) {
    let l = logistic(x);
    // `max` ignores a NaN; the `ln_1p` term carries it.
    (x.max(0.0) + ln_1p(l.e), l.sigmoid)
}

/// The logistic function `1 / (1 + e^-x)`, from `e^-|x|` so that it is accurate for negative `x`
/// too (where it is `e^x / (1 + e^x)`).
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    logistic(x).sigmoid
}

/// `x · sigmoid(x)` (SiLU, swish).
#[inline(always)]
pub fn silu(x: f32) -> f32 {
    silu_and_sigmoid(x).0
}

/// `(x · sigmoid(x), sigmoid(x))` from one `exp` (SiLU and what its derivative needs). For
/// `x < 0`, SiLU is `x e^x / (1 + e^x)` with `e^x`'s scale applied last, so that results in the
/// subnormal range round once.
#[inline(always)]
pub fn silu_and_sigmoid(x: f32) -> (f32, f32) {
    let l = logistic(x);
    let xr = x * l.r;
    let silu = if x >= 0.0 {
        xr
    } else if x < -111.0 {
        // Below about -110, x e^x rounds to -0 (the clamp inside `exp_parts` would not).
        -0.0
    } else {
        xr * l.m * l.scale
    };
    (silu, l.sigmoid)
}

/// `tanh(x) = -m / (2 + m)` with `m = e^{-2|x|} - 1`, signed.
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    let m = exp_m1(-2.0 * x.abs());
    (-m / (2.0 + m)).copysign(x)
}

/// One of this module's functions, to [`apply`] over a slice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Function {
    /// [`exp`].
    Exp,
    /// [`exp_m1`].
    ExpM1,
    /// [`ln_1p`].
    Ln1p,
    /// [`softplus`].
    Softplus,
    /// [`sigmoid`].
    Sigmoid,
    /// [`silu`].
    Silu,
    /// [`tanh`].
    Tanh,
}

crate::simd::multiversion! {
    /// `x ← f(x)` for every element, in the widest vectors the CPU has (the same bits as one call
    /// at a time).
    pub fn apply(f: Function, x: &mut [f32]) {
        macro_rules! each {
            ($f:expr) => {
                for v in x.iter_mut() {
                    *v = $f(*v);
                }
            };
        }
        match f {
            Function::Exp => each!(exp),
            Function::ExpM1 => each!(exp_m1),
            Function::Ln1p => each!(ln_1p),
            Function::Softplus => each!(softplus),
            Function::Sigmoid => each!(sigmoid),
            Function::Silu => each!(silu),
            Function::Tanh => each!(tanh),
        }
    }
}

#[cfg(test)]
mod tests {
    /// The error of `got` against the exact `want`, in ulps of f32 at `want` (the spacing of f32
    /// in `want`'s binade; 2^-149 among the subnormals).
    fn ulps(got: f32, want: f64) -> f64 {
        if want.is_nan() || got.is_nan() {
            return if want.is_nan() && got.is_nan() {
                0.0
            } else {
                f64::INFINITY
            };
        }
        // Beyond f32's range the right answer is the rounded one (±∞ or ±MAX).
        let rounded = want as f32;
        if rounded.is_infinite() || got.is_infinite() {
            return if got == rounded { 0.0 } else { f64::INFINITY };
        }
        let e = want.abs().log2().floor().max(-126.0);
        (f64::from(got) - want).abs() / (e - 23.0).exp2()
    }

    type Pair = (&'static str, fn(f32) -> f32, fn(f64) -> f64, f64);

    fn sigmoid64(x: f64) -> f64 {
        if x >= 0.0 {
            1.0 / (1.0 + (-x).exp())
        } else {
            x.exp() / (1.0 + x.exp())
        }
    }

    /// Each function, its f64 reference through libm, and its stated maximal error in ulps.
    const FUNCTIONS: [Pair; 7] = [
        ("exp", super::exp, f64::exp, 1.0),
        ("exp_m1", super::exp_m1, f64::exp_m1, 1.6),
        ("ln_1p", super::ln_1p, f64::ln_1p, 0.9),
        (
            "softplus",
            super::softplus,
            |x| x.max(0.0) + (-x.abs()).exp().ln_1p(),
            1.7,
        ),
        ("sigmoid", super::sigmoid, sigmoid64, 2.9),
        (
            "silu",
            super::silu,
            |x| {
                if x == f64::NEG_INFINITY {
                    -0.0
                } else {
                    x * sigmoid64(x)
                }
            },
            3.5,
        ),
        ("tanh", super::tanh, f64::tanh, 2.5),
    ];

    /// The largest error of each function over the f32 inputs whose bits are multiples of
    /// `stride`, and the input where it occurs.
    fn worst(stride: usize) -> Vec<(f64, f32)> {
        FUNCTIONS
            .iter()
            .map(|(_, f, reference, _)| {
                let mut w = (0.0, 0.0);
                for bits in (0..=u32::MAX).step_by(stride) {
                    let x = f32::from_bits(bits);
                    let e = ulps(f(x), reference(f64::from(x)));
                    if e > w.0 || e.is_nan() {
                        w = (e, x);
                    }
                }
                w
            })
            .collect()
    }

    fn assert_within_stated(stride: usize) {
        let worst = worst(stride);
        for ((name, _, _, _), (e, x)) in FUNCTIONS.iter().zip(&worst) {
            println!("{name}: {e:.3} ulps at {x:e}");
        }
        for ((name, _, _, bound), (e, x)) in FUNCTIONS.iter().zip(worst) {
            assert!(e <= *bound, "{name}: {e} ulps at {x:e} (stated {bound})");
        }
    }

    #[test]
    fn accurate_over_a_sample_of_every_binade() {
        assert_within_stated(9973);
    }

    #[test]
    #[ignore = "every f32 input: about 15 minutes in release"]
    fn accurate_over_every_input() {
        assert_within_stated(1);
    }

    #[test]
    fn special_values_as_libm() {
        let specials = [
            0.0f32,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::from_bits(0x8000_0001),
            f32::MAX,
            f32::MIN,
            -1.0,
            -1.5,
            88.72,
            88.73,
            -103.9,
            -104.1,
        ];
        for (name, f, reference, _) in FUNCTIONS {
            for x in specials {
                let (got, want) = (f(x), reference(f64::from(x)) as f32);
                let same = got.to_bits() == want.to_bits()
                    || (got.is_nan() && want.is_nan())
                    || (got != 0.0 && ulps(got, reference(f64::from(x))) <= 3.0);
                assert!(same, "{name}({x:e}) = {got:e}, libm {want:e}");
            }
        }
    }

    #[test]
    fn vectorized_loops_give_the_bits_of_single_calls() {
        let x: Vec<f32> = (0..20_011)
            .map(|i| f32::from_bits((i as u32).wrapping_mul(214_739)))
            .chain((0..4000).map(|i| (i as f32 - 2000.0) * 0.0537))
            .collect();
        let all = [
            super::Function::Exp,
            super::Function::ExpM1,
            super::Function::Ln1p,
            super::Function::Softplus,
            super::Function::Sigmoid,
            super::Function::Silu,
            super::Function::Tanh,
        ];
        for (&which, (name, f, _, _)) in all.iter().zip(&FUNCTIONS) {
            let mut out = x.clone();
            super::apply(which, &mut out);
            for (&got, &v) in out.iter().zip(&x) {
                let want = f(std::hint::black_box(v));
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{name}({v:e}): loop {got:e}, call {want:e}"
                );
            }
        }
    }
}
