//! Neural-network building blocks shared by `tandem-models` and `tandem-agents`.
//!
//! What this crate owns:
//! * [`Mlp`]: fully connected networks with flat `f32` parameters, seeded initialization
//!   ([`Init`]: PyTorch default, Xavier, orthogonal, uniform), hidden-layer dropout, and a
//!   hand-derived, allocation-free forward/backward over the `gemm` kernels
//!   ([`Mlp::forward`], [`Mlp::forward_train`], [`Mlp::backward`] with optional `dL/dinput`).
//! * Optimizers updating flat buffers in place ([`Adam`], [`AdaGrad`], [`Sgd`] behind
//!   [`Optimizer`]), [`clip_grad_norm`], [`polyak_update`].
//! * Distribution heads with gradients ([`TanhGaussian`] for SAC, [`GaussianHead`] for PETS-style
//!   models, [`Categorical`]) and losses ([`mse`], [`huber`], [`bce_with_logits`],
//!   [`gaussian_nll`]).
//! * [`RunningNormalizer`]: running mean/variance (f64, Chan merge) for inputs and targets;
//!   defined in `tandem-core` (shared with `tandem-envs`' observation wrapper), checkpointed here.
//! * Checkpoints ([`Checkpoint`], [`Checkpointable`]) in the safetensors format, bit-exact,
//!   deterministic bytes with a CRC-32 (`crc32fast`: the checksum crate the Rust ecosystem
//!   uses, SIMD-accelerated), written atomically ([`write_atomic`]).
//! * [`candle_ext`]: seeded candle parameters ([`candle_ext::ParamSet`]: linear, conv,
//!   transposed conv) stepped by the same optimizers, and [`candle_ext::configure_cpu_threads`].
//! * `conv` (feature `pixels`): convolution and transposed convolution as candle custom ops
//!   (im2col / col2im and one `gemm` product each, gradients included; 2–4× faster than candle's
//!   own for a training pass on the CPU), and a per-channel bias add with a fast gradient.
//! * [`SharedWorkspace`]: a network workspace behind a mutex, for inference through `&self`
//!   (models' `predict`, agents' batched acting).
//! * [`RowDealer`]: the rows of several batched passes (an ensemble's members) dealt in equal
//!   blocks to threads, cut only where a block keeps the numbers of its whole pass;
//!   [`map_side_by_side`]: independent items (members in training) on threads.
//! * [`join`]: run two closures on two threads, e.g. SAC's twin critics; on two-thread machines
//!   the second runs on a helper that stays awake between calls ([`pair`]).
//! * [`fastmath`]: vectorizable `exp`, `exp_m1`, `ln_1p`, `softplus`, `sigmoid`, `silu` and
//!   `tanh`, within 3.5 ulps of libm over every f32 input: the activations, the Gaussian head and its
//!   loss.
//! * Errors: one enum, [`NnError`]; shape mismatches and non-finite numbers are errors.
//! * [`budget`]: memory estimates checked against a limit (default 8 GiB,
//!   `TANDEM_MEMORY_LIMIT`) before networks and buffers are allocated.
//!
//! Why a hand-derived MLP rather than candle modules: on the 2-core CPUs this project runs on,
//! candle's per-op allocation and dispatch dominate RL-sized networks (measured when it was written:
//! a 23→256→256→1 critic update takes 3.9 ms in candle, about 1 ms hand-derived; PyTorch 1.27 ms).
//! The hand-derived gradients are tested against candle's autograd. candle remains the library for
//! what needs general autograd (convolutional nets) and is used as the gradient oracle in tests.
//!
//! # Performance notes (measured on the 2-core AMD EPYC dev machine)
//!
//! `gemm` runs a 256×256×256 f32 product at about 93–96 GFLOP/s on one core (matrixmultiply:
//! ~10% slower; batch-1 products 6x slower), so the hand-derived passes are within a few percent of
//! the matrix-product time. A SAC update with stable-baselines3's sizes (batch 256, 2×256 hidden,
//! twin critics) is about 0.55 GFLOP, i.e. ≈ 5.8 ms of pure matrix products on one core: reaching
//! ≤ 6 ms needs the second core. `benches/nn.rs` shows the pattern: the two critics' work (target
//! pass, critic step, actor-loss pass) side by side with [`join`], noise drawn up front so the
//! result does not depend on scheduling. [`set_gemm_threads`] (default 1) splits large single
//! products (e.g. a planner's batch of 500 through 400-wide layers) over threads instead.
//! [`Mlp::backward`] runs a layer's weight-gradient and input-gradient products side by side when
//! both are needed and each has at least 2^21 multiply-adds (e.g. SAC's actor step), whenever
//! rayon has a second thread. [`Mlp::forward`] and [`Mlp::forward_train`] (without dropout) run
//! the two row halves of a batch side by side when the pass has at least 2^22 multiply-adds and
//! each half 64 rows (a planner's population, MBPO's imagined rows): `gemm` gives a row the same
//! bits in any product of more than about 22 rows, so the numbers are the whole pass's. The
//! element-wise loops (activations, bias gradients, Adam, polyak) are compiled three times,
//! baseline, AVX2 and AVX-512, and the widest the CPU runs is picked at run time (`simd.rs`), with
//! bit-identical results. Inference passes on `gemm`'s main kernels keep their activations
//! feature-major between layers (the rows along the kernels' vector lanes; `Mlp`'s
//! `forward_feature_major` says why), and a pass split over two threads hands each thread its
//! row half through all layers at once; the kernels' arithmetic, and so the bits, do not change. The ReLU backward writes a separate buffer through a select: the in-place conditional
//! store compiled to branches (about 11% of a single-thread SAC update in `perf`) and, with AVX2,
//! to masked stores (4.5%; slow on AMD cores); the select costs 2.3%.
//!
//! On CPUs with AVX-512 (the Intel Xeon machines this project also runs on), `gemm`'s 16-lane
//! kernels run (its `x86-v4` feature): a 20 000 × 200 × 200 product at about 90 GFLOP/s on one
//! core against 37–41 with the AVX2 kernels, 256 × 200 × 200 at 140 against 79. `kernels.rs`
//! keeps the numbers those of the AVX2 kernels bit for bit: it runs the products whose order
//! depends on the lane count (dot-product forms) itself in the AVX2 order, and cuts contractions
//! longer than 512 into blocks that do not depend on the CPU's caches (before, `gemm` sized them
//! from the caches, so products with such contractions, e.g. weight gradients of batches over 512,
//! could differ between machines; on the Xeon their bits changed with this).
//!
//! Networks compute in `f32`; physics and planning stay in `f64` and convert at the boundary.
//! candle's CPU generator cannot be seeded, so every random number here (initialization, dropout,
//! sampling noise) comes from [`tandem_core::seeding::Rng`].
//!
//! # Example: fit `y = 2x - 1` with a tiny MLP
//!
//! ```
//! use tandem_core::seeding::rng_from_seed;
//! use tandem_nn::{Adam, AdamConfig, Mlp, MlpConfig, Optimizer};
//!
//! let mut rng = rng_from_seed(0);
//! let mut net = Mlp::new(MlpConfig::new(&[1, 16, 1]), &mut rng).unwrap();
//! let mut opt = Adam::new(AdamConfig::with_lr(1e-2), net.num_params()).unwrap();
//! let mut ws = net.workspace();
//! let mut grads = net.zero_grads();
//!
//! let x: Vec<f32> = (0..32).map(|i| i as f32 / 16.0 - 1.0).collect();
//! let y: Vec<f32> = x.iter().map(|v| 2.0 * v - 1.0).collect();
//! let mut d_out = vec![0.0; 32];
//! for _ in 0..500 {
//!     let pred = net.forward_train(&x, 32, &mut ws, None).unwrap();
//!     // Mean squared error and its gradient dL/dpred.
//!     for ((d, p), t) in d_out.iter_mut().zip(pred).zip(&y) {
//!         *d = 2.0 * (p - t) / 32.0;
//!     }
//!     net.backward(&mut ws, &d_out, Some(&mut grads), None).unwrap();
//!     opt.step(net.params_mut(), &grads).unwrap();
//! }
//! let pred = net.forward(&[0.5], 1, &mut ws).unwrap();
//! assert!((pred[0] - 0.0).abs() < 0.05);
//! ```
//!
//! Dependencies: `gemm` (the matrix kernels candle itself uses on CPU; with `x86-v4` for its
//! AVX-512 kernels), `safetensors` (the
//! checkpoint format; already a dependency of candle), `candle-core`/`candle-nn` (general
//! autograd, gradient oracle), `rand`/`rand_distr` (seeded initialization and noise), `serde`,
//! `serde_json` (JSON payloads inside checkpoints), `thiserror`, `rayon` (two-thread task
//! parallelism; already in the tree through candle and gemm).

#![warn(missing_docs)]

pub mod budget;
pub mod candle_ext;
pub mod checkpoint;
#[cfg(feature = "pixels")]
pub mod conv;
pub mod error;
pub mod fastmath;
pub mod heads;
mod kernels;
pub mod loss;
pub mod mlp;
pub mod normalizer;
pub mod optim;
pub mod pair;
pub mod row_deal;
pub mod shared;
mod simd;

/// `f` on a rayon pool of `threads` threads (the crate's tests of split and paired work).
#[cfg(test)]
pub(crate) fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

pub use pair::join;

pub use checkpoint::{write_atomic, Checkpoint, Checkpointable, CHECKSUM_KEY};
pub use error::{check_finite, NnError, Result};
pub use heads::{
    fill_standard_normal, log1m_tanh_sq, softplus, tanh_and_log1m_tanh_sq, Categorical,
    GaussianHead, GaussianOutput, TanhGaussian, TanhGaussianSample,
};
pub use kernels::{gemm_threads, set_gemm_threads};
pub use loss::{bce_with_logits, gaussian_nll, huber, mse};
pub use mlp::{sigmoid, Activation, Init, LayerShape, Mlp, MlpConfig, MlpWorkspace};
pub use normalizer::{NormalizerError, NormalizerState, RunningNormalizer};
pub use optim::{
    clip_grad_norm, clip_grad_norm_many, grad_norm, polyak_update, AdaGrad, AdaGradConfig, Adam,
    AdamConfig, Optimizer, Sgd, SgdConfig,
};
pub use row_deal::{map_side_by_side, RowBlock, RowDealer};
pub use shared::SharedWorkspace;
