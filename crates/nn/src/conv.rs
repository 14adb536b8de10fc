//! 2-D convolution and transposed convolution for candle on the CPU, as im2col / col2im around
//! one matrix product each, with their gradients: a faster drop-in for `Tensor::conv2d` and
//! `Tensor::conv_transpose2d` (stride and padding, dilation 1, one group) in training.
//!
//! # What it computes
//!
//! * [`conv2d`]: `x` `[n, c_in, h, w]` (NCHW, f32) and `kernel` `[c_out, c_in, k_h, k_w]` give
//!   `y` `[n, c_out, h_out, w_out]` with `y[b, o, i, j] = Σ_{c, u, v} kernel[o, c, u, v] ·
//!   x[b, c, s·i + u − p, s·j + v − p]` (zero outside the image), `h_out = (h + 2p − k_h) / s + 1`
//!   (and the same for widths): PyTorch's and candle's `conv2d` without bias.
//! * [`conv_transpose2d`]: `x` `[n, c_in, h, w]` and `kernel` `[c_in, c_out, k_h, k_w]` (PyTorch's
//!   and candle's layout) give `[n, c_out, (h − 1)·s − 2p + k_h + output_padding, …]`: the adjoint
//!   of the convolution with the same kernel, PyTorch's `conv_transpose2d` without bias.
//! * [`conv2d_layer`] and [`conv_transpose2d_layer`]: a `candle_nn` layer's weight and settings
//!   through the two functions above and its bias through [`add_channel_bias`], so a network
//!   keeps its `candle_nn` layers (and so its parameter names and shapes) and swaps only the
//!   forward call.
//!
//! Both are candle custom ops ([`candle_core::CustomOp2`] on `(input, kernel)`), so they compose
//! with candle's autograd (`Var`, `backward()`): everything around them (batch normalization,
//! linear layers, losses) stays in candle. The gradients are themselves these ops: with `C(x, k)`
//! the convolution, `A(y, k)` its adjoint in `x` (the transposed convolution) and `G(x, y)` its
//! adjoint in `k` (the kernel gradient, `G(x, y)[o, c, u, v] = Σ_{b,i,j} y[b, o, i, j] ·
//! x[b, c, s·i + u − p, s·j + v − p]`), the three are bilinear and each one's derivatives are the
//! other two (e.g. `∂C/∂x = A(dy, k)`, `∂C/∂k = G(x, dy)`), so second derivatives through them
//! are right too. A gradient is skipped for an argument candle does not track (the input frames of
//! a network's first layer).
//!
//! # How
//!
//! The batch's patches are unfolded once into an `(n · h_out · w_out) × (c_in · k_h · k_w)`
//! matrix (im2col: one row per output position, in the kernel's `c, u, v` order), so each of the
//! three products is one matrix product over the whole batch, over this crate's `gemm` wrappers
//! (the `gemm` crate's kernels, the ones candle uses for its matmul; [`crate::set_gemm_threads`]
//! sets their threads):
//!
//! * convolution: `Y = cols(x) · Kᵀ` (`K` the kernel as `c_out × c_in·k_h·k_w`), rows reordered
//!   to NCHW;
//! * adjoint: `D = Y · K`, folded back onto the image by col2im (overlapping patches add up);
//! * kernel gradient: `Yᵀ · cols(x)`.
//!
//! # Why not candle's own
//!
//! candle 0.11's CPU `conv_transpose2d` is a direct seven-deep loop, and `conv2d`'s backward pass
//! uses it for the input gradient (and a `conv2d` with batch and channels swapped for the kernel
//! gradient). Expressing the transposed convolution as dilation + `conv2d` in candle was slower
//! still. Measured (`cargo bench --bench nn -- conv --quick`, one thread, a busy 2-core machine),
//! forward and backward of p2's pixel-model layers at batch 32: the three convolutions 1.7, 1.7,
//! 2.4 ms here against 6.1, 4.8, 4.9 ms in candle, the three transposed ones 2.0, 1.6, 1.0 ms
//! against 5.1, 7.2, 1.9 ms.
//!
//! Biases: [`add_channel_bias`] (used by the layer functions) adds a `[c]` bias over batch and
//! pixels with a custom op, because the gradient of candle's `broadcast_add` sums over dimensions
//! 0, 2 and 3, and candle reduces over any but the last dimensions with two integer divisions per
//! element and dimension (on the pixel model, such reductions were most of a training step once
//! the convolutions were fast).
//!
//! Shapes and settings are checked: a wrong rank, mismatched channels, a kernel larger than the
//! padded image, stride 0, an output padding not below the stride, a dtype other than f32 or a
//! device other than the CPU are errors, never panics.
//!
//! ```
//! use candle_core::{Device, Tensor, Var};
//! use tandem_nn::conv::{conv2d, conv_transpose2d};
//!
//! let dev = &Device::Cpu;
//! let x = Var::from_tensor(&Tensor::randn(0f32, 1.0, (2, 3, 8, 8), dev).unwrap()).unwrap();
//! let k = Var::from_tensor(&Tensor::randn(0f32, 1.0, (4, 3, 4, 4), dev).unwrap()).unwrap();
//! let y = conv2d(x.as_tensor(), k.as_tensor(), 2, 1).unwrap(); // 8×8 → 4×4
//! assert_eq!(y.dims(), &[2, 4, 4, 4]);
//! // The same values as candle's convolution.
//! let want = x.as_tensor().conv2d(k.as_tensor(), 1, 2, 1, 1).unwrap();
//! let diff = (&y - &want).unwrap().abs().unwrap().max_all().unwrap();
//! assert!(diff.to_scalar::<f32>().unwrap() < 1e-4);
//! // Back up with the same kernel (its layout for a transposed convolution is [c_in, c_out, ..]).
//! let z = conv_transpose2d(&y, k.as_tensor(), 2, 1, 0).unwrap();
//! assert_eq!(z.dims(), &[2, 3, 8, 8]);
//! // Gradients through candle's autograd.
//! let grads = z.sqr().unwrap().sum_all().unwrap().backward().unwrap();
//! assert_eq!(grads.get(k.as_tensor()).unwrap().dims(), &[4, 3, 4, 4]);
//! assert_eq!(grads.get(x.as_tensor()).unwrap().dims(), &[2, 3, 8, 8]);
//! ```

use std::ops::Range;

use candle_core::backend::BackendStorage;
use candle_core::{bail, CpuStorage, CustomOp2, DType, Device, Layout, Result, Shape, Tensor};

use crate::kernels::{gemm_nn, gemm_nt, gemm_tn};

/// The geometry of one convolution `image → out`: the image `[n, c_in, h, w]`, the kernel
/// `[c_out, c_in, k_h, k_w]`, the output `[n, c_out, out_h, out_w]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Geom {
    n: usize,
    c_in: usize,
    h: usize,
    w: usize,
    c_out: usize,
    k_h: usize,
    k_w: usize,
    stride: usize,
    padding: usize,
    out_h: usize,
    out_w: usize,
}

impl Geom {
    /// The convolution of an image `[n, c_in, h, w]` with a kernel `[c_out, c_in, k_h, k_w]`.
    fn of_conv(image: &[usize], kernel: &[usize], stride: usize, padding: usize) -> Result<Self> {
        let (&[n, c_in, h, w], &[c_out, kc, k_h, k_w]) = (image, kernel) else {
            bail!("conv2d: input {image:?} and kernel {kernel:?} must both have rank 4 (NCHW)")
        };
        if kc != c_in {
            bail!("conv2d: input {image:?} has {c_in} channels, the kernel {kernel:?} takes {kc}")
        }
        if stride == 0 || k_h == 0 || k_w == 0 || c_out == 0 {
            bail!("conv2d: kernel {kernel:?} and stride {stride} must be positive")
        }
        if h + 2 * padding < k_h || w + 2 * padding < k_w {
            bail!("conv2d: kernel {kernel:?} larger than the input {image:?} padded by {padding}")
        }
        Ok(Self {
            n,
            c_in,
            h,
            w,
            c_out,
            k_h,
            k_w,
            stride,
            padding,
            out_h: (h + 2 * padding - k_h) / stride + 1,
            out_w: (w + 2 * padding - k_w) / stride + 1,
        })
    }

    /// The convolution whose adjoint is the transposed convolution of `x` `[n, c_in, h, w]` with
    /// `kernel` `[c_in, c_out, k_h, k_w]`: its image is the transposed convolution's output.
    fn of_transposed(
        x: &[usize],
        kernel: &[usize],
        stride: usize,
        padding: usize,
        output_padding: usize,
    ) -> Result<Self> {
        let (&[n, c_in, h, w], &[kc, c_out, k_h, k_w]) = (x, kernel) else {
            bail!("conv_transpose2d: input {x:?} and kernel {kernel:?} must both have rank 4")
        };
        if kc != c_in {
            bail!("conv_transpose2d: input {x:?} has {c_in} channels, the kernel {kernel:?} takes {kc}")
        }
        if stride == 0 || output_padding >= stride {
            bail!(
                "conv_transpose2d: stride {stride} must be positive and the output padding \
                 {output_padding} below it"
            )
        }
        let full = |i: usize, k: usize| (i.max(1) - 1) * stride + k + output_padding;
        let (fh, fw) = (full(h, k_h), full(w, k_w));
        if fh <= 2 * padding || fw <= 2 * padding {
            bail!("conv_transpose2d: padding {padding} leaves no output for input {x:?} and kernel {kernel:?}")
        }
        let g = Self::of_conv(
            &[n, c_out, fh - 2 * padding, fw - 2 * padding],
            &[c_in, c_out, k_h, k_w],
            stride,
            padding,
        )?;
        if (g.out_h, g.out_w) != (h, w) {
            bail!("conv_transpose2d: input {x:?} and kernel {kernel:?} give no consistent output")
        }
        Ok(g)
    }

    fn image_dims(&self) -> [usize; 4] {
        [self.n, self.c_in, self.h, self.w]
    }

    fn out_dims(&self) -> [usize; 4] {
        [self.n, self.c_out, self.out_h, self.out_w]
    }

    fn kernel_dims(&self) -> [usize; 4] {
        [self.c_out, self.c_in, self.k_h, self.k_w]
    }

    /// Length of one patch: `c_in · k_h · k_w` (a kernel row).
    fn patch(&self) -> usize {
        self.c_in * self.k_h * self.k_w
    }

    /// Output positions of the batch: `n · out_h · out_w` (the patch matrix's rows).
    fn outputs(&self) -> usize {
        self.n * self.out_h * self.out_w
    }

    /// For output column `ox`, the kernel columns `v` whose image column `s·ox + v − p` lies in
    /// the image, and that column for `v = 0` (possibly negative).
    fn cols_inside(&self, ox: usize) -> (Range<usize>, isize) {
        let ix0 = (ox * self.stride) as isize - self.padding as isize;
        let lo = (-ix0).max(0) as usize;
        let hi = (self.w as isize - ix0).clamp(0, self.k_w as isize) as usize;
        (lo.min(hi)..hi, ix0)
    }

    /// Calls `f(patch offset, image offset, len)` for every stretch of a patch row that lies
    /// inside the image: per output position (the patch matrix's rows, in order), per channel `c`
    /// and kernel row `u` whose image row is inside, the kernel columns inside (see
    /// [`Geom::cols_inside`]). Everything else is outside the image: zero in the patch matrix,
    /// nothing to add back in the image.
    fn for_each_segment(&self, mut f: impl FnMut(usize, usize, usize)) {
        let (plane, patch) = (self.h * self.w, self.patch());
        for r in 0..self.outputs() {
            let b = r / (self.out_h * self.out_w);
            let oy = (r / self.out_w) % self.out_h;
            let (inside, ix0) = self.cols_inside(r % self.out_w);
            if inside.is_empty() {
                continue;
            }
            let ix = (ix0 + inside.start as isize) as usize;
            for c in 0..self.c_in {
                for u in 0..self.k_h {
                    let iy = (oy * self.stride + u) as isize - self.padding as isize;
                    if iy < 0 || iy >= self.h as isize {
                        continue;
                    }
                    let col = r * patch + (c * self.k_h + u) * self.k_w + inside.start;
                    let img = (b * self.c_in + c) * plane + iy as usize * self.w + ix;
                    f(col, img, inside.len());
                }
            }
        }
    }
}

/// im2col: the patch matrix `rows × patch` of the image `x` (zeros outside the image).
fn im2col(g: &Geom, x: &[f32]) -> Vec<f32> {
    let mut cols = vec![0f32; g.outputs() * g.patch()];
    g.for_each_segment(|col, img, len| copy_short(&mut cols[col..col + len], &x[img..img + len]));
    cols
}

/// `dst.copy_from_slice(src)` for the short stretches of im2col (a kernel row: 3 or 4 values in
/// the pixel model) as inline moves: the general copy is a `memcpy` call, which made up a third
/// of im2col's time.
#[inline(always)]
fn copy_short(dst: &mut [f32], src: &[f32]) {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match src.len() {
                $($n => dst[..$n].copy_from_slice(&src[..$n]),)*
                _ => dst.copy_from_slice(src),
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8);
}

/// col2im: the image whose patches sum to `cols` (the adjoint of [`im2col`]).
fn col2im(g: &Geom, cols: &[f32]) -> Vec<f32> {
    let mut x = vec![0f32; g.image_dims().iter().product()];
    g.for_each_segment(|col, img, len| {
        for (d, s) in x[img..img + len].iter_mut().zip(&cols[col..col + len]) {
            *d += s;
        }
    });
    x
}

/// `[n, c, p]` → `[n·p, c]` (channels last).
fn to_rows(t: &[f32], n: usize, c: usize, p: usize) -> Vec<f32> {
    let mut out = vec![0f32; n * c * p];
    for b in 0..n {
        let (src, dst) = (&t[b * c * p..][..c * p], &mut out[b * c * p..][..c * p]);
        for ch in 0..c {
            for (i, &v) in src[ch * p..][..p].iter().enumerate() {
                dst[i * c + ch] = v;
            }
        }
    }
    out
}

/// `[n·p, c]` → `[n, c, p]` (the inverse of [`to_rows`]).
fn from_rows(t: &[f32], n: usize, c: usize, p: usize) -> Vec<f32> {
    let mut out = vec![0f32; n * c * p];
    for b in 0..n {
        let (src, dst) = (&t[b * c * p..][..c * p], &mut out[b * c * p..][..c * p]);
        for (i, row) in src.chunks_exact(c).enumerate() {
            for (ch, &v) in row.iter().enumerate() {
                dst[ch * p + i] = v;
            }
        }
    }
    out
}

/// The convolution `C(x, k)`: `[n, c_out, out_h, out_w]`.
fn conv_forward(g: &Geom, x: &[f32], k: &[f32]) -> Vec<f32> {
    let cols = im2col(g, x);
    let mut rows = vec![0f32; g.outputs() * g.c_out];
    gemm_nt(g.outputs(), g.c_out, g.patch(), &cols, k, &mut rows, false);
    from_rows(&rows, g.n, g.c_out, g.out_h * g.out_w)
}

/// The adjoint in the image `A(y, k)`: `[n, c_in, h, w]` (the transposed convolution).
fn conv_adjoint(g: &Geom, y: &[f32], k: &[f32]) -> Vec<f32> {
    let rows = to_rows(y, g.n, g.c_out, g.out_h * g.out_w);
    let mut cols = vec![0f32; g.outputs() * g.patch()];
    gemm_nn(g.outputs(), g.patch(), g.c_out, &rows, k, &mut cols, false);
    col2im(g, &cols)
}

/// The adjoint in the kernel `G(x, y)`: `[c_out, c_in, k_h, k_w]` (the kernel gradient).
fn conv_kernel_grad(g: &Geom, x: &[f32], y: &[f32]) -> Vec<f32> {
    let cols = im2col(g, x);
    let rows = to_rows(y, g.n, g.c_out, g.out_h * g.out_w);
    let mut k = vec![0f32; g.c_out * g.patch()];
    gemm_tn(g.c_out, g.patch(), g.outputs(), &rows, &cols, &mut k, false);
    k
}

/// Which of the three bilinear maps of a convolution, by its two arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Map {
    /// `(image, kernel) → out`.
    Conv,
    /// `(out, kernel) → image`.
    Adjoint,
    /// `(image, out) → kernel`.
    KernelGrad,
}

impl Map {
    fn name(self) -> &'static str {
        match self {
            Map::Conv => "tandem-conv2d",
            Map::Adjoint => "tandem-conv2d-adjoint",
            Map::KernelGrad => "tandem-conv2d-kernel-grad",
        }
    }
}

/// One of the three maps of a geometry as a candle op.
#[derive(Debug, Clone, Copy)]
struct ConvOp {
    geom: Geom,
    map: Map,
}

impl ConvOp {
    /// The expected dimensions of the two arguments and of the result.
    fn dims(&self) -> ([usize; 4], [usize; 4], [usize; 4]) {
        let g = &self.geom;
        let (image, out, kernel) = (g.image_dims(), g.out_dims(), g.kernel_dims());
        match self.map {
            Map::Conv => (image, kernel, out),
            Map::Adjoint => (out, kernel, image),
            Map::KernelGrad => (image, out, kernel),
        }
    }

    /// Applies the op to `a` and `b` (made contiguous), recording it for autograd.
    fn apply(self, a: &Tensor, b: &Tensor) -> Result<Tensor> {
        a.contiguous()?.apply_op2(&b.contiguous()?, self)
    }

    /// The op `map` of the same geometry on `(a, b)`, or `None` when `wanted` is false.
    fn other(&self, map: Map, wanted: bool, a: &Tensor, b: &Tensor) -> Result<Option<Tensor>> {
        if !wanted {
            return Ok(None);
        }
        let op = ConvOp {
            geom: self.geom,
            map,
        };
        op.apply(a, b).map(Some)
    }
}

/// The f32 values of a contiguous CPU tensor with the expected dimensions.
fn f32_slice<'a>(op: &str, s: &'a CpuStorage, l: &Layout, dims: &[usize]) -> Result<&'a [f32]> {
    let CpuStorage::F32(v) = s else {
        bail!("{op}: f32 tensors only, got {:?}", s.dtype())
    };
    if l.dims() != dims {
        bail!(
            "{op}: expected an argument of shape {dims:?}, got {:?}",
            l.dims()
        )
    }
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&v[a..b]),
        None => bail!("{op}: arguments must be contiguous"),
    }
}

impl CustomOp2 for ConvOp {
    fn name(&self) -> &'static str {
        self.map.name()
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (d1, d2, d_out) = self.dims();
        let a = f32_slice(self.name(), s1, l1, &d1)?;
        let b = f32_slice(self.name(), s2, l2, &d2)?;
        let g = &self.geom;
        let out = match self.map {
            Map::Conv => conv_forward(g, a, b),
            Map::Adjoint => conv_adjoint(g, a, b),
            Map::KernelGrad => conv_kernel_grad(g, a, b),
        };
        Ok((CpuStorage::F32(out), Shape::from(d_out.to_vec())))
    }

    fn bwd(
        &self,
        a: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (ta, tb) = (a.track_op(), b.track_op());
        Ok(match self.map {
            // C(x, k): dx = A(dy, k), dk = G(x, dy).
            Map::Conv => (
                self.other(Map::Adjoint, ta, grad, b)?,
                self.other(Map::KernelGrad, tb, a, grad)?,
            ),
            // A(y, k) (image-shaped): dy = C(dx, k), dk = G(dx, y).
            Map::Adjoint => (
                self.other(Map::Conv, ta, grad, b)?,
                self.other(Map::KernelGrad, tb, grad, a)?,
            ),
            // G(x, y) (kernel-shaped): dx = A(y, dk), dy = C(x, dk).
            Map::KernelGrad => (
                self.other(Map::Adjoint, ta, b, grad)?,
                self.other(Map::Conv, tb, a, grad)?,
            ),
        })
    }
}

/// Both tensors f32 on the CPU.
fn check_f32_cpu(op: &str, x: &Tensor, kernel: &Tensor) -> Result<()> {
    for t in [x, kernel] {
        if t.dtype() != DType::F32 || !matches!(t.device(), Device::Cpu) {
            bail!(
                "{op}: f32 CPU tensors only, got {:?} on {:?}",
                t.dtype(),
                t.device()
            )
        }
    }
    Ok(())
}

/// 2-D convolution of `x` `[n, c_in, h, w]` with `kernel` `[c_out, c_in, k_h, k_w]`, stride and
/// zero padding on both axes, no bias: `[n, c_out, (h + 2p − k_h)/s + 1, (w + 2p − k_w)/s + 1]`,
/// the values of candle's `x.conv2d(kernel, padding, stride, 1, 1)` (see the module
/// documentation). Differentiable in both arguments.
pub fn conv2d(x: &Tensor, kernel: &Tensor, stride: usize, padding: usize) -> Result<Tensor> {
    check_f32_cpu("conv2d", x, kernel)?;
    let geom = Geom::of_conv(x.dims(), kernel.dims(), stride, padding)?;
    ConvOp {
        geom,
        map: Map::Conv,
    }
    .apply(x, kernel)
}

/// 2-D transposed convolution of `x` `[n, c_in, h, w]` with `kernel` `[c_in, c_out, k_h, k_w]`,
/// no bias: `[n, c_out, (h − 1)s − 2p + k_h + output_padding, …]`, the values of candle's
/// `x.conv_transpose2d(kernel, padding, output_padding, stride, 1)`; `output_padding` must be
/// below `stride` (as in PyTorch). Differentiable in both arguments.
pub fn conv_transpose2d(
    x: &Tensor,
    kernel: &Tensor,
    stride: usize,
    padding: usize,
    output_padding: usize,
) -> Result<Tensor> {
    check_f32_cpu("conv_transpose2d", x, kernel)?;
    let geom = Geom::of_transposed(x.dims(), kernel.dims(), stride, padding, output_padding)?;
    ConvOp {
        geom,
        map: Map::Adjoint,
    }
    .apply(x, kernel)
}

/// Adds a per-channel bias to an NCHW tensor: the op behind [`add_channel_bias`].
#[derive(Debug, Clone, Copy)]
struct AddChannelBias;

impl CustomOp2 for AddChannelBias {
    fn name(&self) -> &'static str {
        "tandem-add-channel-bias"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let dims = l1.dims().to_vec();
        let y = f32_slice(self.name(), s1, l1, &dims)?;
        let b = f32_slice(self.name(), s2, l2, &dims[1..2])?;
        let plane: usize = dims[2..].iter().product();
        let mut out = y.to_vec();
        if plane > 0 {
            for (i, chunk) in out.chunks_exact_mut(plane).enumerate() {
                let bias = b[i % b.len()];
                chunk.iter_mut().for_each(|v| *v += bias);
            }
        }
        Ok((CpuStorage::F32(out), Shape::from(dims)))
    }

    fn bwd(
        &self,
        y: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let db = if b.track_op() {
            Some(channel_sum(grad)?)
        } else {
            None
        };
        Ok((y.track_op().then(|| grad.clone()), db))
    }
}

/// Sum over batch and pixels of an NCHW tensor: `[c]`. As candle reductions over the last
/// dimension, then over the (short) batch: candle reduces over its last dimensions with a
/// vectorized loop, over any other dimension with two integer divisions per element.
pub fn channel_sum(t: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = t.dims4()?;
    t.reshape((n, c, h * w))?.sum(2)?.sum(0)
}

/// `y + bias` with `y` `[n, c, h, w]` and `bias` `[c]` broadcast over batch and pixels: the same
/// values as candle's `y.broadcast_add(&bias.reshape((1, c, 1, 1)))`, with a faster bias
/// gradient ([`channel_sum`]; candle's broadcast backward sums over dimensions 0, 2 and 3 with
/// its slow general loop).
pub fn add_channel_bias(y: &Tensor, bias: &Tensor) -> Result<Tensor> {
    let (_, c, _, _) = y.dims4()?;
    check_f32_cpu("add_channel_bias", y, bias)?;
    if bias.dims() != [c] {
        bail!("add_channel_bias: bias {:?} for {c} channels", bias.dims())
    }
    y.contiguous()?
        .apply_op2(&bias.contiguous()?, AddChannelBias)
}

/// Adds `bias`, if any (see [`add_channel_bias`]).
fn add_bias(y: Tensor, bias: Option<&Tensor>) -> Result<Tensor> {
    match bias {
        Some(b) => add_channel_bias(&y, b),
        None => Ok(y),
    }
}

/// `layer`'s forward pass (weight, stride, padding, bias) through [`conv2d`]; the same values as
/// `layer.forward(x)`. Dilation and groups other than 1 are errors.
pub fn conv2d_layer(layer: &candle_nn::Conv2d, x: &Tensor) -> Result<Tensor> {
    let cfg = layer.config();
    if cfg.dilation != 1 || cfg.groups != 1 {
        bail!(
            "conv2d_layer: dilation {} and groups {} must be 1",
            cfg.dilation,
            cfg.groups
        )
    }
    add_bias(
        conv2d(x, layer.weight(), cfg.stride, cfg.padding)?,
        layer.bias(),
    )
}

/// `layer`'s forward pass (weight, stride, padding, output padding, bias) through
/// [`conv_transpose2d`]; the same values as `layer.forward(x)`. Dilation other than 1 is an
/// error.
pub fn conv_transpose2d_layer(layer: &candle_nn::ConvTranspose2d, x: &Tensor) -> Result<Tensor> {
    let cfg = layer.config();
    if cfg.dilation != 1 {
        bail!(
            "conv_transpose2d_layer: dilation {} must be 1",
            cfg.dilation
        )
    }
    add_bias(
        conv_transpose2d(
            x,
            layer.weight(),
            cfg.stride,
            cfg.padding,
            cfg.output_padding,
        )?,
        layer.bias(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::candle_ext::uniform_tensor;
    use candle_core::Var;
    use tandem_core::seeding::{rng_from_seed, Rng};

    fn rand(rng: &mut Rng, dims: &[usize]) -> Tensor {
        uniform_tensor(rng, dims, -1.0, 1.0).unwrap()
    }

    fn values(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    /// Same shape, and every value within `tol` of the largest magnitude (at least 1).
    fn assert_close(got: &Tensor, want: &Tensor, tol: f32, what: &str) {
        assert_eq!(got.dims(), want.dims(), "{what}");
        let (g, w) = (values(got), values(want));
        let scale = w.iter().fold(1f32, |m, v| m.max(v.abs()));
        let worst = g
            .iter()
            .zip(&w)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(
            worst <= tol * scale,
            "{what}: off by {worst} (scale {scale})"
        );
    }

    /// `(x, kernel, stride, padding)` of a convolution.
    type ConvCase = ([usize; 4], [usize; 4], usize, usize);
    /// `(x, kernel, stride, padding, output_padding)` of a transposed convolution.
    type TransposedCase = ([usize; 4], [usize; 4], usize, usize, usize);

    /// Convolutions: the pixel model's three, odd sizes, batch 1, padding larger than needed.
    fn conv_cases() -> Vec<ConvCase> {
        vec![
            ([32, 12, 16, 16], [32, 12, 4, 4], 2, 1),
            ([32, 32, 8, 8], [64, 32, 4, 4], 2, 1),
            ([32, 64, 4, 4], [64, 64, 3, 3], 1, 1),
            ([1, 3, 7, 7], [2, 3, 3, 3], 2, 0),
            ([2, 2, 9, 9], [3, 2, 3, 3], 1, 2),
            ([3, 4, 5, 5], [5, 4, 1, 1], 1, 0),
            ([2, 3, 6, 6], [4, 3, 2, 2], 3, 1),
            ([2, 2, 1, 2], [3, 2, 5, 5], 1, 2),
        ]
    }

    /// Transposed convolutions: the pixel model's three, output paddings, odd sizes, batch 1.
    fn transposed_cases() -> Vec<TransposedCase> {
        vec![
            ([32, 64, 4, 4], [64, 64, 3, 3], 1, 1, 0),
            ([32, 64, 4, 4], [64, 32, 4, 4], 2, 1, 0),
            ([32, 32, 8, 8], [32, 3, 4, 4], 2, 1, 0),
            ([1, 2, 3, 3], [2, 3, 3, 3], 2, 1, 1),
            ([2, 3, 5, 5], [3, 2, 2, 2], 3, 0, 2),
            ([3, 4, 4, 4], [4, 2, 3, 3], 1, 0, 0),
            ([2, 2, 5, 5], [2, 3, 5, 5], 1, 2, 0),
        ]
    }

    #[test]
    fn convolution_matches_candle() {
        let mut rng = rng_from_seed(1);
        for (xd, kd, s, p) in conv_cases() {
            let (x, k) = (rand(&mut rng, &xd), rand(&mut rng, &kd));
            let want = x.conv2d(&k, p, s, 1, 1).unwrap();
            let got = conv2d(&x, &k, s, p).unwrap();
            assert_close(&got, &want, 1e-5, &format!("conv {xd:?} {kd:?} s{s} p{p}"));
        }
        // Rectangles (candle's forward handles them; its backward does not, see below).
        let (x, k) = (
            rand(&mut rng, &[2, 3, 7, 10]),
            rand(&mut rng, &[4, 3, 3, 2]),
        );
        let want = x.conv2d(&k, 1, 2, 1, 1).unwrap();
        assert_close(&conv2d(&x, &k, 2, 1).unwrap(), &want, 1e-5, "rectangle");
        // A non-contiguous input is read through its layout.
        let xt = rand(&mut rng, &[3, 2, 6, 6]).transpose(0, 1).unwrap();
        let k = rand(&mut rng, &[2, 3, 3, 3]);
        let want = xt.conv2d(&k, 1, 1, 1, 1).unwrap();
        assert_close(
            &conv2d(&xt, &k, 1, 1).unwrap(),
            &want,
            1e-5,
            "transposed view",
        );
    }

    #[test]
    fn transposed_convolution_matches_candle() {
        let mut rng = rng_from_seed(2);
        for (xd, kd, s, p, op) in transposed_cases() {
            let (x, k) = (rand(&mut rng, &xd), rand(&mut rng, &kd));
            let want = x.conv_transpose2d(&k, p, op, s, 1).unwrap();
            let got = conv_transpose2d(&x, &k, s, p, op).unwrap();
            let what = format!("transposed {xd:?} {kd:?} s{s} p{p} op{op}");
            assert_close(&got, &want, 1e-5, &what);
        }
        let (x, k) = (rand(&mut rng, &[2, 3, 3, 5]), rand(&mut rng, &[3, 2, 4, 3]));
        let want = x.conv_transpose2d(&k, 1, 1, 2, 1).unwrap();
        assert_close(
            &conv_transpose2d(&x, &k, 2, 1, 1).unwrap(),
            &want,
            1e-5,
            "rectangle",
        );
    }

    /// `Σ r ⊙ y²` for a fixed random `r`: a loss with nonzero, position-dependent gradients.
    fn weighted_square(y: &Tensor, rng: &mut Rng) -> Tensor {
        let r = rand(rng, y.dims());
        y.sqr().unwrap().mul(&r).unwrap().sum_all().unwrap()
    }

    /// Gradients of `loss(x, k)` w.r.t. `x` and `k` (both variables).
    fn grads_of(
        x: &Tensor,
        k: &Tensor,
        loss: impl Fn(&Tensor, &Tensor) -> Tensor,
    ) -> (Tensor, Tensor) {
        let (xv, kv) = (Var::from_tensor(x).unwrap(), Var::from_tensor(k).unwrap());
        let g = loss(xv.as_tensor(), kv.as_tensor()).backward().unwrap();
        (
            g.get(xv.as_tensor()).unwrap().clone(),
            g.get(kv.as_tensor()).unwrap().clone(),
        )
    }

    #[test]
    fn gradients_match_candles_autograd() {
        for (i, (xd, kd, s, p)) in conv_cases().into_iter().enumerate() {
            let mut rng = rng_from_seed(10 + i as u64);
            let (x, k) = (rand(&mut rng, &xd), rand(&mut rng, &kd));
            let ours = grads_of(&x, &k, |x, k| {
                weighted_square(&conv2d(x, k, s, p).unwrap(), &mut rng_from_seed(99))
            });
            let theirs = grads_of(&x, &k, |x, k| {
                weighted_square(&x.conv2d(k, p, s, 1, 1).unwrap(), &mut rng_from_seed(99))
            });
            let what = format!("conv {xd:?} {kd:?} s{s} p{p}");
            assert_close(&ours.0, &theirs.0, 1e-5, &format!("{what}: d/dx"));
            assert_close(&ours.1, &theirs.1, 1e-5, &format!("{what}: d/dk"));
        }
        for (i, (xd, kd, s, p, op)) in transposed_cases().into_iter().enumerate() {
            let mut rng = rng_from_seed(20 + i as u64);
            let (x, k) = (rand(&mut rng, &xd), rand(&mut rng, &kd));
            let ours = grads_of(&x, &k, |x, k| {
                let y = conv_transpose2d(x, k, s, p, op).unwrap();
                weighted_square(&y, &mut rng_from_seed(98))
            });
            let theirs = grads_of(&x, &k, |x, k| {
                let y = x.conv_transpose2d(k, p, op, s, 1).unwrap();
                weighted_square(&y, &mut rng_from_seed(98))
            });
            let what = format!("transposed {xd:?} {kd:?} s{s} p{p} op{op}");
            assert_close(&ours.0, &theirs.0, 1e-5, &format!("{what}: d/dx"));
            assert_close(&ours.1, &theirs.1, 1e-5, &format!("{what}: d/dk"));
        }
    }

    /// Central differences of `loss` at `x` (every element) and `k` (every element).
    fn finite_differences(
        x: &Tensor,
        k: &Tensor,
        loss: impl Fn(&Tensor, &Tensor) -> f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let eps = 1e-2f32;
        let fd = |t: &Tensor, f: &dyn Fn(&Tensor) -> f64| -> Vec<f64> {
            let v = values(t);
            (0..v.len())
                .map(|i| {
                    let mut up = v.clone();
                    up[i] += eps;
                    let mut down = v.clone();
                    down[i] -= eps;
                    let t_up = Tensor::from_vec(up, t.dims(), &Device::Cpu).unwrap();
                    let t_down = Tensor::from_vec(down, t.dims(), &Device::Cpu).unwrap();
                    (f(&t_up) - f(&t_down)) / (2.0 * f64::from(eps))
                })
                .collect()
        };
        (fd(x, &|x| loss(x, k)), fd(k, &|k| loss(x, k)))
    }

    fn assert_fd(analytic: &Tensor, fd: &[f64], what: &str) {
        for (i, (a, f)) in values(analytic).iter().zip(fd).enumerate() {
            let a = f64::from(*a);
            assert!(
                (a - f).abs() <= 1e-3 * (1.0 + f.abs()),
                "{what}[{i}]: {a} vs {f}"
            );
        }
    }

    #[test]
    fn gradients_match_finite_differences_on_rectangles() {
        // Rectangular images with stride 2 and an output padding: shapes candle's own backward
        // gets wrong (it derives one output padding from the heights). The loss is quadratic, so
        // central differences are exact up to rounding.
        let mut rng = rng_from_seed(3);
        let (x, k) = (rand(&mut rng, &[2, 2, 5, 8]), rand(&mut rng, &[3, 2, 3, 2]));
        let loss = |x: &Tensor, k: &Tensor| {
            let l = weighted_square(&conv2d(x, k, 2, 1).unwrap(), &mut rng_from_seed(7));
            f64::from(l.to_scalar::<f32>().unwrap())
        };
        let (dx, dk) = grads_of(&x, &k, |x, k| {
            weighted_square(&conv2d(x, k, 2, 1).unwrap(), &mut rng_from_seed(7))
        });
        assert_eq!(dx.dims(), &[2, 2, 5, 8]);
        let (fx, fk) = finite_differences(&x, &k, loss);
        assert_fd(&dx, &fx, "conv d/dx");
        assert_fd(&dk, &fk, "conv d/dk");

        let (x, k) = (rand(&mut rng, &[2, 3, 3, 4]), rand(&mut rng, &[3, 2, 3, 4]));
        let y = |x: &Tensor, k: &Tensor| conv_transpose2d(x, k, 2, 1, 1).unwrap();
        assert_eq!(y(&x, &k).dims(), &[2, 2, 6, 9]);
        let loss = |x: &Tensor, k: &Tensor| {
            let l = weighted_square(&y(x, k), &mut rng_from_seed(8));
            f64::from(l.to_scalar::<f32>().unwrap())
        };
        let (dx, dk) = grads_of(&x, &k, |x, k| {
            weighted_square(&y(x, k), &mut rng_from_seed(8))
        });
        let (fx, fk) = finite_differences(&x, &k, loss);
        assert_fd(&dx, &fx, "transposed d/dx");
        assert_fd(&dk, &fk, "transposed d/dk");
    }

    #[test]
    fn second_derivatives_match_candles() {
        // d/dk of a loss of dL/dx and d/dx of a loss of dL/dk: the backward passes' own
        // backward passes (all three maps), against candle's double backward.
        let mut rng = rng_from_seed(4);
        let (x, k) = (rand(&mut rng, &[2, 3, 5, 5]), rand(&mut rng, &[4, 3, 3, 3]));
        let v_x = rand(&mut rng, &[2, 3, 5, 5]);
        let v_k = rand(&mut rng, &[4, 3, 3, 3]);
        let second = |conv: &dyn Fn(&Tensor, &Tensor) -> Tensor| {
            let (xv, kv) = (Var::from_tensor(&x).unwrap(), Var::from_tensor(&k).unwrap());
            let l = weighted_square(&conv(xv.as_tensor(), kv.as_tensor()), &mut rng_from_seed(5));
            let g = l.backward().unwrap();
            let (gx, gk) = (
                g.get(xv.as_tensor()).unwrap(),
                g.get(kv.as_tensor()).unwrap(),
            );
            let outer = gx.mul(&v_x).unwrap().sum_all().unwrap();
            let outer = outer
                .add(&gk.mul(&v_k).unwrap().sum_all().unwrap())
                .unwrap();
            let h = outer.backward().unwrap();
            (
                h.get(xv.as_tensor()).unwrap().clone(),
                h.get(kv.as_tensor()).unwrap().clone(),
            )
        };
        let ours = second(&|x, k| conv2d(x, k, 1, 1).unwrap());
        let theirs = second(&|x, k| x.conv2d(k, 1, 1, 1, 1).unwrap());
        assert_close(&ours.0, &theirs.0, 1e-5, "conv: x");
        assert_close(&ours.1, &theirs.1, 1e-5, "conv: k");
        let kt = k.transpose(0, 1).unwrap().contiguous().unwrap(); // [3, 4, 3, 3]
        let xt = rand(&mut rng, &[2, 3, 5, 5]);
        let second_t = |conv: &dyn Fn(&Tensor, &Tensor) -> Tensor| {
            let (xv, kv) = (
                Var::from_tensor(&xt).unwrap(),
                Var::from_tensor(&kt).unwrap(),
            );
            let l = weighted_square(&conv(xv.as_tensor(), kv.as_tensor()), &mut rng_from_seed(6));
            let g = l.backward().unwrap();
            let (gx, gk) = (
                g.get(xv.as_tensor()).unwrap(),
                g.get(kv.as_tensor()).unwrap(),
            );
            let outer = gx.sqr().unwrap().sum_all().unwrap();
            let outer = outer.add(&gk.sqr().unwrap().sum_all().unwrap()).unwrap();
            let h = outer.backward().unwrap();
            (
                h.get(xv.as_tensor()).unwrap().clone(),
                h.get(kv.as_tensor()).unwrap().clone(),
            )
        };
        let ours = second_t(&|x, k| conv_transpose2d(x, k, 1, 1, 0).unwrap());
        let theirs = second_t(&|x, k| x.conv_transpose2d(k, 1, 0, 1, 1).unwrap());
        assert_close(&ours.0, &theirs.0, 1e-4, "transposed: x");
        assert_close(&ours.1, &theirs.1, 1e-4, "transposed: k");
    }

    #[test]
    fn layers_match_candle_nn_and_bad_settings_are_errors() {
        let mut rng = rng_from_seed(5);
        let mut ps = crate::candle_ext::ParamSet::new();
        let down = candle_nn::Conv2dConfig {
            padding: 1,
            stride: 2,
            ..Default::default()
        };
        let up = candle_nn::ConvTranspose2dConfig {
            padding: 1,
            stride: 2,
            output_padding: 1,
            ..Default::default()
        };
        let conv = ps.conv2d("c", 3, 4, 3, down, &mut rng).unwrap();
        let tconv = ps.conv_transpose2d("t", 4, 2, 3, up, &mut rng).unwrap();
        let x = rand(&mut rng, &[2, 3, 8, 8]);
        let y = conv2d_layer(&conv, &x).unwrap();
        assert_close(
            &y,
            &candle_core::Module::forward(&conv, &x).unwrap(),
            1e-5,
            "conv",
        );
        let z = conv_transpose2d_layer(&tconv, &y).unwrap();
        let want = candle_core::Module::forward(&tconv, &y).unwrap();
        assert_close(&z, &want, 1e-5, "transposed");
        assert_eq!(z.dims(), &[2, 2, 8, 8]);
        let dilated = candle_nn::Conv2d::new(
            conv.weight().clone(),
            None,
            candle_nn::Conv2dConfig {
                dilation: 2,
                ..down
            },
        );
        assert!(conv2d_layer(&dilated, &x).is_err());
        let dilated_t = candle_nn::ConvTranspose2d::new(
            tconv.weight().clone(),
            None,
            candle_nn::ConvTranspose2dConfig { dilation: 2, ..up },
        );
        assert!(conv_transpose2d_layer(&dilated_t, &y).is_err());
    }

    #[test]
    fn channel_bias_and_its_gradients_match_candle() {
        let mut rng = rng_from_seed(7);
        let (y, b) = (rand(&mut rng, &[3, 4, 5, 6]), rand(&mut rng, &[4]));
        let ours = grads_of(&y, &b, |y, b| {
            weighted_square(&add_channel_bias(y, b).unwrap(), &mut rng_from_seed(1))
        });
        let theirs = grads_of(&y, &b, |y, b| {
            let sum = y.broadcast_add(&b.reshape((1, 4, 1, 1)).unwrap()).unwrap();
            weighted_square(&sum, &mut rng_from_seed(1))
        });
        assert_close(&ours.0, &theirs.0, 1e-5, "d/dy");
        assert_close(&ours.1, &theirs.1, 1e-5, "d/dbias");
        let want = y.broadcast_add(&b.reshape((1, 4, 1, 1)).unwrap()).unwrap();
        assert_close(&add_channel_bias(&y, &b).unwrap(), &want, 1e-6, "values");
        // channel_sum by hand: every value of channel 2 is 2.
        let t = Tensor::arange(0f32, 4.0, &Device::Cpu)
            .unwrap()
            .reshape((1, 4, 1, 1))
            .unwrap()
            .broadcast_as((3, 4, 2, 5))
            .unwrap();
        assert_eq!(values(&channel_sum(&t).unwrap()), [0.0, 30.0, 60.0, 90.0]);
        assert!(add_channel_bias(&y, &rand(&mut rng, &[5])).is_err());
        assert!(add_channel_bias(&y.flatten_all().unwrap(), &b).is_err());
    }

    #[test]
    fn bad_shapes_and_settings_are_errors() {
        let mut rng = rng_from_seed(6);
        let x = rand(&mut rng, &[2, 3, 6, 6]);
        let k = rand(&mut rng, &[4, 3, 3, 3]);
        assert!(conv2d(&x, &k, 1, 1).is_ok());
        let rank3 = rand(&mut rng, &[3, 6, 6]);
        let wrong_channels = rand(&mut rng, &[4, 2, 3, 3]);
        let huge = rand(&mut rng, &[4, 3, 9, 9]);
        for (x, k, s, p) in [
            (&rank3, &k, 1, 1),
            (&x, &rank3, 1, 1),
            (&x, &wrong_channels, 1, 1),
            (&x, &huge, 1, 1),
            (&x, &k, 0, 1),
        ] {
            assert!(
                conv2d(x, k, s, p).is_err(),
                "{:?} {:?} s{s} p{p}",
                x.dims(),
                k.dims()
            );
        }
        let f64_x = x.to_dtype(DType::F64).unwrap();
        let e = conv2d(&f64_x, &k, 1, 1).unwrap_err();
        assert!(e.to_string().contains("f32"), "{e}");
        // Transposed: kernel [c_in, c_out, ..].
        let y = rand(&mut rng, &[2, 4, 3, 3]);
        assert!(conv_transpose2d(&y, &k, 2, 1, 1).is_ok());
        for (s, p, op) in [(2, 1, 2), (0, 0, 0), (1, 0, 1), (1, 3, 0)] {
            assert!(
                conv_transpose2d(&y, &k, s, p, op).is_err(),
                "s{s} p{p} op{op}"
            );
        }
        assert!(conv_transpose2d(&x, &k, 1, 1, 0).is_err()); // 3 channels, kernel takes 4
        assert!(conv_transpose2d(&rank3, &k, 1, 1, 0).is_err());
        // An empty batch is an empty result.
        let empty = Tensor::zeros((0, 3, 6, 6), DType::F32, &Device::Cpu).unwrap();
        assert_eq!(conv2d(&empty, &k, 1, 1).unwrap().dims(), &[0, 4, 6, 6]);
    }
}
