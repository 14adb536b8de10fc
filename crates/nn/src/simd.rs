//! Runtime-dispatched wide vectors for the element-wise loops (activations, bias gradients, Adam,
//! polyak updates).
//!
//! The workspace compiles for baseline x86-64 (SSE2: 4 lanes). [`multiversion!`] compiles a
//! function's body again with AVX2 and FMA enabled (8 lanes) and with AVX-512F too (16 lanes),
//! and picks the widest copy the CPU runs. Results are bit-identical between the copies: Rust never
//! contracts `a*b+c` into a fused multiply-add nor reassociates float operations, so each element
//! sees exactly the same IEEE operations in the same order; only the number of lanes per
//! instruction changes. An explicit `mul_add` is one rounding in both copies (an instruction in
//! the wide one, a call to libm's `fmaf` in the baseline one).

/// Defines `fn name(args) -> ret { body }` that runs an AVX-512-compiled copy of `body` on a CPU
/// with AVX-512F and FMA, an AVX2-and-FMA-compiled copy on one with those (each checked once by
/// the standard library, then a cached load), and the baseline copy otherwise. Arguments must be
/// plain identifiers; the body is inlined into all three copies.
macro_rules! multiversion {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            #[allow(clippy::too_many_arguments)]
            fn body($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn wide512($($arg: $ty),*) $(-> $ret)? {
                    body($($arg),*)
                }
                if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
                    // SAFETY: `wide512` needs AVX-512F (which implies AVX2) and FMA, just checked.
                    return unsafe { wide512($($arg),*) };
                }
                #[target_feature(enable = "avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn wide($($arg: $ty),*) $(-> $ret)? {
                    body($($arg),*)
                }
                if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                    // SAFETY: `wide` only needs AVX2 and FMA, which the CPU was just checked to have.
                    return unsafe { wide($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

pub(crate) use multiversion;

#[cfg(test)]
mod tests {
    multiversion! {
        /// A loop with division and square roots, the operations most likely to differ.
        fn kernel(x: &[f32], out: &mut [f32]) {
            for (o, v) in out.iter_mut().zip(x) {
                *o = 0.3 * *v / ((*v * *v).sqrt() * 1.7 + 1e-8) + *v * 0.9;
            }
        }
    }

    #[test]
    fn wide_copy_is_bit_identical_to_scalar_reference() {
        let x: Vec<f32> = (0..1003).map(|i| (i as f32 * 0.731).sin() * 1e3).collect();
        let mut got = vec![0.0; x.len()];
        kernel(&x, &mut got);
        for (v, g) in x.iter().zip(&got) {
            // One element at a time through a black box: no vectorization possible.
            let v = std::hint::black_box(*v);
            let want = 0.3 * v / ((v * v).sqrt() * 1.7 + 1e-8) + v * 0.9;
            assert_eq!(g.to_bits(), want.to_bits());
        }
    }
}
