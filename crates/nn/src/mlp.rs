//! A fully connected network with a hand-derived forward and backward pass over `gemm`.
//!
//! Why not candle here: on the 2-core CPUs this project targets, candle's per-op allocation and
//! dispatch dominate RL-sized networks (measured when this crate was written: critic update 3.9 ms in candle,
//! 1.0 ms hand-derived). The gradients are checked against candle's autograd in this crate's tests.
//!
//! Layout: parameters live in one flat `Vec<f32>`: for each layer `l`, the weight `W_l`
//! (`out × in`, row-major, PyTorch's `nn.Linear` layout) followed by the bias `b_l` (`out`).
//! Optimizers, gradient clipping and polyak updates are then plain loops over slices, and the
//! gradient buffer has exactly the same layout.
//!
//! Batches are row-major `batch × features` slices. Layer `l` computes
//! `y_l = act_l(x_l W_lᵀ + b_l)`, then (hidden layers only, training only) inverted dropout.

use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_core::seeding::Rng;

use crate::checkpoint::{Checkpoint, Checkpointable};
use crate::error::{check_finite, check_len, NnError, Result};
use crate::fastmath;
use crate::kernels::{gemm_nn, gemm_nt, gemm_tn, k_blocks, nt_route, NtRoute};
use crate::simd::multiversion;

/// Element-wise activation of a layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// `x` (no activation; the usual output layer).
    Identity,
    /// `max(x, 0)`.
    #[default]
    Relu,
    /// `tanh(x)`.
    Tanh,
    /// `1 / (1 + e^-x)`.
    Sigmoid,
    /// `x` for `x > 0`, `e^x - 1` otherwise (α = 1).
    Elu,
    /// `x · sigmoid(x)` (swish; PETS's activation).
    Silu,
}

impl Activation {
    /// The activation of a scalar (through [`crate::fastmath`], as in the batched passes).
    #[inline(always)]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Activation::Identity => x,
            Activation::Relu => x.max(0.0),
            Activation::Tanh => fastmath::tanh(x),
            Activation::Sigmoid => fastmath::sigmoid(x),
            Activation::Elu => {
                if x > 0.0 {
                    x
                } else {
                    fastmath::exp_m1(x)
                }
            }
            Activation::Silu => fastmath::silu(x),
        }
    }

    /// Whether the derivative needs `σ(z)` kept from the forward pass (only SiLU's: `σ + y(1 -
    /// σ)`); the others' derivatives are functions of `y`.
    fn keeps_sigmoid(self) -> bool {
        matches!(self, Activation::Silu)
    }
}

/// Numerically safe logistic function.
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// Weight initialization of a layer. Biases follow the scheme's convention.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// PyTorch's `nn.Linear` default: weights and biases `U(-1/√fan_in, 1/√fan_in)`
    /// (kaiming-uniform with a = √5 reduces to this bound).
    #[default]
    TorchDefault,
    /// Glorot/Xavier uniform: `U(±gain·√(6/(fan_in+fan_out)))`, biases zero.
    XavierUniform {
        /// Gain (1 for linear/sigmoid, 5/3 for tanh, √2 for ReLU).
        gain: f32,
    },
    /// Orthogonal weights (QR of a Gaussian matrix, signs fixed by R's diagonal, as
    /// `torch.nn.init.orthogonal_`) scaled by `gain`; biases zero.
    Orthogonal {
        /// Gain (stable-baselines3 uses √2 for hidden layers, 0.01 for policy outputs).
        gain: f32,
    },
    /// Weights and biases `U(-bound, bound)` (DDPG's final layers: bound 3e-3).
    Uniform {
        /// Half-width of the interval.
        bound: f32,
    },
}

/// The shape and behaviour of an [`Mlp`]. Serde-readable (TOML/JSON), unknown keys rejected.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MlpConfig {
    /// Layer widths: `[input, hidden..., output]`; at least two entries, all positive.
    pub sizes: Vec<usize>,
    /// Activation after every hidden layer.
    #[serde(default)]
    pub hidden_activation: Activation,
    /// Activation after the output layer (usually `Identity`).
    #[serde(default = "identity")]
    pub output_activation: Activation,
    /// Dropout probability on hidden layers during [`Mlp::forward_train`] with an RNG (p0: 0.3);
    /// 0 disables it. Must be in `[0, 1)`.
    #[serde(default)]
    pub dropout: f32,
    /// Initialization of all layers.
    #[serde(default)]
    pub init: Init,
    /// Initialization of the output layer, if different from `init`.
    #[serde(default)]
    pub output_init: Option<Init>,
}

fn identity() -> Activation {
    Activation::Identity
}

impl MlpConfig {
    /// ReLU hidden layers, identity output, no dropout, PyTorch-default initialization.
    pub fn new(sizes: &[usize]) -> Self {
        Self {
            sizes: sizes.to_vec(),
            hidden_activation: Activation::Relu,
            output_activation: Activation::Identity,
            dropout: 0.0,
            init: Init::TorchDefault,
            output_init: None,
        }
    }

    /// Sets the hidden activation.
    pub fn hidden(mut self, a: Activation) -> Self {
        self.hidden_activation = a;
        self
    }

    /// Sets the output activation.
    pub fn output(mut self, a: Activation) -> Self {
        self.output_activation = a;
        self
    }

    /// Sets the hidden-layer dropout probability.
    pub fn dropout(mut self, p: f32) -> Self {
        self.dropout = p;
        self
    }

    /// Sets the initialization of all layers.
    pub fn init(mut self, init: Init) -> Self {
        self.init = init;
        self
    }

    /// Sets a separate initialization for the output layer.
    pub fn output_init(mut self, init: Init) -> Self {
        self.output_init = Some(init);
        self
    }

    /// Checks sizes, dropout and init parameters.
    pub fn validate(&self) -> Result<()> {
        if self.sizes.len() < 2 {
            return Err(NnError::InvalidConfig(format!(
                "mlp sizes need at least input and output, got {:?}",
                self.sizes
            )));
        }
        if self.sizes.contains(&0) {
            return Err(NnError::InvalidConfig(format!(
                "mlp sizes must be positive, got {:?}",
                self.sizes
            )));
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return Err(NnError::InvalidConfig(format!(
                "dropout must be in [0, 1), got {}",
                self.dropout
            )));
        }
        for init in std::iter::once(&self.init).chain(self.output_init.iter()) {
            let v = match *init {
                Init::TorchDefault => 1.0,
                Init::XavierUniform { gain } | Init::Orthogonal { gain } => gain,
                Init::Uniform { bound } => bound,
            };
            if !v.is_finite() || v < 0.0 {
                return Err(NnError::InvalidConfig(format!(
                    "init parameter must be finite and non-negative, got {init:?}"
                )));
            }
        }
        Ok(())
    }
}

/// Shape and offsets of one layer inside the flat parameter vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LayerShape {
    /// Input width.
    pub fan_in: usize,
    /// Output width.
    pub fan_out: usize,
    /// Offset of `W` (`fan_out × fan_in`, row-major) in the flat parameters.
    pub weight_offset: usize,
    /// Offset of `b` (`fan_out`) in the flat parameters.
    pub bias_offset: usize,
}

/// One layer's output rows and, when kept, SiLU's `σ(z)`.
type LayerOut<'a> = (&'a mut [f32], Option<&'a mut [f32]>);

/// A multilayer perceptron with flat `f32` parameters and hand-derived gradients.
///
/// * [`Mlp::forward`]: inference (no dropout), allocation-free once the workspace has seen the
///   batch size.
/// * [`Mlp::forward_train`] then [`Mlp::backward`]: gradients of any loss given `dL/doutput`,
///   into a flat buffer laid out like [`Mlp::params`], and optionally `dL/dinput`.
///
/// Cloning gives an independent copy (a target network).
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    config: MlpConfig,
    layers: Vec<LayerShape>,
    params: Vec<f32>,
}

impl Mlp {
    /// A network initialized from `rng` as `config.init` says. Draws happen layer by layer,
    /// weights (row-major) before biases, so the same seed gives bit-identical parameters.
    pub fn new(config: MlpConfig, rng: &mut Rng) -> Result<Self> {
        let mut net = Self::zeros(config)?;
        net.reinitialize(rng);
        Ok(net)
    }

    /// A network with all parameters zero (to be filled by [`Mlp::set_params`] or a checkpoint).
    pub fn zeros(config: MlpConfig) -> Result<Self> {
        config.validate()?;
        // The parameter vector is the allocation here; refuse it before making it.
        crate::budget::MemoryEstimate::new()
            .mlp("parameters", &config.sizes, 1, 0)
            .check(&format!("mlp {:?}", config.sizes))
            .map_err(|e| NnError::InvalidConfig(e.to_string()))?;
        let mut layers = Vec::with_capacity(config.sizes.len() - 1);
        let mut off = 0;
        for w in config.sizes.windows(2) {
            let (fan_in, fan_out) = (w[0], w[1]);
            layers.push(LayerShape {
                fan_in,
                fan_out,
                weight_offset: off,
                bias_offset: off + fan_in * fan_out,
            });
            off += fan_in * fan_out + fan_out;
        }
        Ok(Self {
            config,
            layers,
            params: vec![0.0; off],
        })
    }

    /// Draws fresh parameters from `rng` (same order as [`Mlp::new`]).
    pub fn reinitialize(&mut self, rng: &mut Rng) {
        let n_layers = self.layers.len();
        for (l, shape) in self.layers.clone().into_iter().enumerate() {
            let init = if l + 1 == n_layers {
                self.config.output_init.unwrap_or(self.config.init)
            } else {
                self.config.init
            };
            let (w, b) = self.params[shape.weight_offset..shape.bias_offset + shape.fan_out]
                .split_at_mut(shape.fan_in * shape.fan_out);
            init_layer(init, shape.fan_in, shape.fan_out, w, b, rng);
        }
    }

    /// The configuration this network was built from.
    pub fn config(&self) -> &MlpConfig {
        &self.config
    }

    /// Input width.
    pub fn input_dim(&self) -> usize {
        self.config.sizes[0]
    }

    /// Output width.
    pub fn output_dim(&self) -> usize {
        *self
            .config
            .sizes
            .last()
            .expect("validated: at least 2 sizes")
    }

    /// Number of linear layers.
    pub fn num_layers(&self) -> usize {
        self.layers.len()
    }

    /// Shapes and offsets of all layers.
    pub fn layers(&self) -> &[LayerShape] {
        &self.layers
    }

    /// Total number of parameters (length of [`Mlp::params`] and of gradient buffers).
    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// All parameters, flat (see the module docs for the layout).
    pub fn params(&self) -> &[f32] {
        &self.params
    }

    /// All parameters, mutable (for optimizers and polyak updates).
    pub fn params_mut(&mut self) -> &mut [f32] {
        &mut self.params
    }

    /// Replaces all parameters; errors on a length mismatch or non-finite values.
    pub fn set_params(&mut self, p: &[f32]) -> Result<()> {
        check_len("mlp parameters", self.params.len(), p.len())?;
        check_finite("mlp parameters", p)?;
        self.params.copy_from_slice(p);
        Ok(())
    }

    /// A zeroed gradient buffer with the parameters' layout.
    pub fn zero_grads(&self) -> Vec<f32> {
        vec![0.0; self.params.len()]
    }

    /// Weight of layer `l` (`fan_out × fan_in`, row-major). Panics if `l` is out of range.
    pub fn weight(&self, l: usize) -> &[f32] {
        let s = self.layers[l];
        &self.params[s.weight_offset..s.bias_offset]
    }

    /// Bias of layer `l`. Panics if `l` is out of range.
    pub fn bias(&self, l: usize) -> &[f32] {
        let s = self.layers[l];
        &self.params[s.bias_offset..s.bias_offset + s.fan_out]
    }

    /// A workspace sized for this network (buffers grow on first use with a larger batch).
    pub fn workspace(&self) -> MlpWorkspace {
        MlpWorkspace::default()
    }

    fn activation(&self, l: usize) -> Activation {
        if l + 1 == self.layers.len() {
            self.config.output_activation
        } else {
            self.config.hidden_activation
        }
    }

    fn fingerprint(&self) -> u64 {
        // Cheap identity of the architecture, to catch a workspace used across networks.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for &s in &self.config.sizes {
            h = (h ^ s as u64).wrapping_mul(0x0100_0000_01b3);
        }
        h = (h ^ self.config.hidden_activation as u64).wrapping_mul(0x0100_0000_01b3);
        (h ^ self.config.output_activation as u64).wrapping_mul(0x0100_0000_01b3)
    }

    /// Inference: the outputs (`batch × output_dim`) for `input` (`batch × input_dim`), without
    /// dropout. Allocation-free once `ws` has seen a batch this large. Invalidates any tape in `ws`.
    ///
    /// Errors: input length, non-finite input or output.
    pub fn forward<'w>(
        &self,
        input: &[f32],
        batch: usize,
        ws: &'w mut MlpWorkspace,
    ) -> Result<&'w [f32]> {
        self.run_forward(input, batch, ws, false, None)?;
        Ok(ws.output(self, batch))
    }

    /// Training forward pass: like [`Mlp::forward`], but records what [`Mlp::backward`] needs in
    /// `ws`. With `dropout_rng = Some(rng)` and `config.dropout > 0`, hidden layers drop units with
    /// masks drawn from `rng` (inverted dropout); with `None` the pass is deterministic (use this
    /// for a critic you only differentiate through, e.g. SAC's actor loss).
    pub fn forward_train<'w>(
        &self,
        input: &[f32],
        batch: usize,
        ws: &'w mut MlpWorkspace,
        dropout_rng: Option<&mut Rng>,
    ) -> Result<&'w [f32]> {
        self.run_forward(input, batch, ws, true, dropout_rng)?;
        Ok(ws.output(self, batch))
    }

    fn run_forward(
        &self,
        input: &[f32],
        batch: usize,
        ws: &mut MlpWorkspace,
        train: bool,
        mut rng: Option<&mut Rng>,
    ) -> Result<()> {
        ws.tape = None;
        check_len("mlp input", batch * self.input_dim(), input.len())?;
        check_finite("mlp input", input)?;
        let n_layers = self.layers.len();
        let drop_p = if train && rng.is_some() {
            self.config.dropout
        } else {
            0.0
        };
        let dropout = DropoutSampler::new(drop_p);
        // Row blocks are independent unless dropout draws masks in row order.
        let split = (!dropout.active() && self.splits_rows(batch)).then_some(batch / 2);
        // Inference on `gemm`'s main kernels: feature-major (see `forward_feature_major`). A
        // split's halves take the whole batch's routes (`splits_rows`), so they run there too.
        let feature_major = !train
            && self
                .layers
                .iter()
                .all(|s| nt_route(batch, s.fan_out, s.fan_in) == NtRoute::Main);
        ws.ensure(self, batch, train, feature_major);
        if train {
            ws.x0[..input.len()].copy_from_slice(input);
        }
        if feature_major {
            let last = n_layers - 1;
            let out_dim = self.output_dim();
            let out = &mut ws.layers[last].y[..batch * out_dim];
            let [fm1, fm2] = &mut ws.fm;
            match split {
                Some(h) => {
                    let (o1, o2) = out.split_at_mut(h * out_dim);
                    let (x1, x2) = input.split_at(h * self.input_dim());
                    crate::join(
                        || self.forward_feature_major(h, x1, fm1, o1),
                        || self.forward_feature_major(batch - h, x2, fm2, o2),
                    );
                }
                None => self.forward_feature_major(batch, input, fm1, out),
            }
            for buf in &mut ws.layers[..n_layers] {
                buf.dropped = false;
            }
        } else if let Some(h) = split {
            // A large batch: the two row halves through all layers side by side (one hand-over
            // per pass, not one per layer). Each row's numbers are the whole pass's: every layer
            // takes the same kernel route for both halves as for the whole batch.
            let mut halves: [Vec<LayerOut<'_>>; 2] = [Vec::new(), Vec::new()];
            for (l, buf) in ws.layers[..n_layers].iter_mut().enumerate() {
                let s = self.layers[l];
                let n = batch * s.fan_out;
                buf.dropped = false;
                let (y1, y2) = buf.y[..n].split_at_mut(h * s.fan_out);
                let (sig1, sig2) = if train && self.activation(l).keeps_sigmoid() {
                    let (sig1, sig2) = buf.sig[..n].split_at_mut(h * s.fan_out);
                    (Some(sig1), Some(sig2))
                } else {
                    (None, None)
                };
                halves[0].push((y1, sig1));
                halves[1].push((y2, sig2));
            }
            let [first, second] = &mut halves;
            let (x1, x2) = input.split_at(h * self.input_dim());
            crate::join(
                || self.layers_forward(h, x1, first),
                || self.layers_forward(batch - h, x2, second),
            );
        } else {
            for l in 0..n_layers {
                let s = self.layers[l];
                let (prev, rest) = ws.layers.split_at_mut(l);
                let cur = &mut rest[0];
                let x: &[f32] = if l == 0 {
                    input
                } else {
                    prev[l - 1].input_of_next()
                };
                let n = batch * s.fan_out;
                let sig = (train && self.activation(l).keeps_sigmoid()).then(|| &mut cur.sig[..n]);
                self.layer_forward(l, batch, &x[..batch * s.fan_in], &mut cur.y[..n], sig);
                cur.dropped = false;
                if l + 1 < n_layers && dropout.active() {
                    let r = rng.as_deref_mut().expect("dropout active only with an rng");
                    dropout.fill_mask(&mut cur.mask[..n], r);
                    for ((h, y), m) in cur.h[..n].iter_mut().zip(&cur.y[..n]).zip(&cur.mask[..n]) {
                        *h = y * m;
                    }
                    cur.dropped = true;
                }
            }
        }
        let out = &ws.layers[n_layers - 1].y[..batch * self.output_dim()];
        check_finite("mlp output", out)?;
        if train {
            ws.tape = Some(Tape {
                fingerprint: self.fingerprint(),
                batch,
            });
        }
        Ok(())
    }

    /// Layer `l` over `rows` rows without dropout: `y = act(x Wᵀ + b)`, keeping SiLU's
    /// `σ(x Wᵀ + b)` when given.
    fn layer_forward(
        &self,
        l: usize,
        rows: usize,
        x: &[f32],
        y: &mut [f32],
        sig: Option<&mut [f32]>,
    ) {
        let s = self.layers[l];
        let b = &self.params[s.bias_offset..s.bias_offset + s.fan_out];
        let w = &self.params[s.weight_offset..s.bias_offset];
        gemm_nt(rows, s.fan_out, s.fan_in, x, w, y, false);
        bias_activation(y, b, self.activation(l), sig);
    }

    /// Inference over one block of `rows` rows (`input` and `out` row-major) with the activations
    /// feature-major in between (`features × rows`): `gemm` then runs the rows along its vector
    /// lanes and reads the row-major `W` as it is. Row-major activations put the features there
    /// instead, so `gemm` packed `W` into its kernel's layout element by element on every product
    /// (an eighth of a CEM plan through the ensemble) and ran the last 8 of a 200-wide layer's
    /// features in a half-empty 16-lane kernel. Every layer must be on [`NtRoute::Main`] at
    /// `rows`, so each element is the same fused multiply-add chain as in the row-major pass: the
    /// same bits.
    ///
    /// The rows go through all layers in tiles of about [`FEATURE_MAJOR_TILE`], each tile's
    /// activations small enough to stay in the core's cache between layers (100 000 rows
    /// through 256-wide layers are 100 MB a layer otherwise). A tile takes the whole block's
    /// kernel routes ([`Mlp::rows_run_apart`]), so the bits are those of one pass.
    fn forward_feature_major(
        &self,
        rows: usize,
        input: &[f32],
        bufs: &mut [Vec<f32>; 2],
        out: &mut [f32],
    ) {
        let tile = FEATURE_MAJOR_TILE;
        let tile =
            if self.rows_run_apart(rows, tile) && self.rows_run_apart(rows, rows % tile + tile) {
                tile
            } else {
                rows
            };
        let widest = self
            .layers
            .iter()
            .fold(self.input_dim(), |w, s| w.max(s.fan_out));
        for b in bufs.iter_mut() {
            if b.len() < widest * (2 * tile).min(rows) {
                b.resize(widest * (2 * tile).min(rows), 0.0);
            }
        }
        let (din, dout) = (self.input_dim(), self.output_dim());
        let mut start = 0;
        while start < rows {
            // The last tile takes the remainder, so no tile is shorter than `tile`.
            let len = if rows - start < 2 * tile {
                rows - start
            } else {
                tile
            };
            self.feature_major_tile(
                len,
                &input[start * din..(start + len) * din],
                bufs,
                &mut out[start * dout..(start + len) * dout],
            );
            start += len;
        }
    }

    /// [`Mlp::forward_feature_major`] over one tile of `rows` rows.
    fn feature_major_tile(
        &self,
        rows: usize,
        input: &[f32],
        bufs: &mut [Vec<f32>; 2],
        out: &mut [f32],
    ) {
        let [x, y] = bufs;
        let (mut x, mut y) = (x, y);
        let din = self.input_dim();
        for (r, row) in input.chunks_exact(din).enumerate() {
            for (p, v) in row.iter().enumerate() {
                x[p * rows + r] = *v;
            }
        }
        for (l, s) in self.layers.iter().enumerate() {
            let w = &self.params[s.weight_offset..s.bias_offset];
            let b = &self.params[s.bias_offset..s.bias_offset + s.fan_out];
            let yl = &mut y[..s.fan_out * rows];
            gemm_nn(
                s.fan_out,
                rows,
                s.fan_in,
                w,
                &x[..s.fan_in * rows],
                yl,
                false,
            );
            bias_activation_by_row(yl, rows, b, self.activation(l));
            std::mem::swap(&mut x, &mut y);
        }
        let dout = self.output_dim();
        for (r, row) in out.chunks_exact_mut(dout).enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = x[j * rows + r];
            }
        }
    }

    /// All layers over one block of `rows` rows, each writing its `(y, σ)` of `bufs`.
    fn layers_forward(&self, rows: usize, input: &[f32], bufs: &mut [LayerOut<'_>]) {
        for l in 0..bufs.len() {
            let (prev, rest) = bufs.split_at_mut(l);
            let x: &[f32] = if l == 0 { input } else { prev[l - 1].0 };
            let (y, sig) = &mut rest[0];
            self.layer_forward(l, rows, x, y, sig.as_deref_mut());
        }
    }

    /// Whether a forward pass over `batch` rows runs its two row halves on two threads:
    /// [`split_rows`], and each half runs apart from the whole batch ([`Mlp::rows_run_apart`]),
    /// so each row's numbers are those of one thread.
    fn splits_rows(&self, batch: usize) -> bool {
        let h = batch / 2;
        split_rows(batch, self.num_params())
            && self.rows_run_apart(batch, h)
            && self.rows_run_apart(batch, batch - h)
    }

    /// Whether an inference pass over a block of `part` rows gives each of them exactly the
    /// numbers of a pass over all `whole` rows: every layer's product takes the same kernel route
    /// at both sizes (see `kernels::NtRoute`; a few hundred rows through 200-wide layers
    /// do, while 64 rows × 4 outputs take a dot-product kernel where 128 take `gemm`'s), and
    /// `gemm` cuts its contraction into the same blocks (a layer wider than 512 is cut one way
    /// in products of at most 64 × 64 and another in larger ones). A caller may then cut a batch
    /// into such blocks and run them apart, on other threads, without changing a bit.
    ///
    /// ```
    /// use tandem_nn::{Mlp, MlpConfig};
    /// let net = Mlp::new(MlpConfig::new(&[4, 200, 200, 6]), &mut tandem_core::seeding::rng_from_seed(0))?;
    /// assert!(net.rows_run_apart(100, 48));
    /// # Ok::<(), tandem_nn::NnError>(())
    /// ```
    pub fn rows_run_apart(&self, whole: usize, part: usize) -> bool {
        let numbers = |rows: usize, s: &LayerShape| {
            (
                nt_route(rows, s.fan_out, s.fan_in),
                k_blocks(rows, s.fan_out, s.fan_in),
            )
        };
        self.layers
            .iter()
            .all(|s| numbers(part, s) == numbers(whole, s))
    }

    /// Backward pass after [`Mlp::forward_train`] on the same `ws` (and unchanged parameters).
    ///
    /// * `d_output`: `dL/doutput`, `batch × output_dim`.
    /// * `grads`: if given, **overwritten** with `dL/dparams` (length [`Mlp::num_params`], same
    ///   layout as the parameters). Pass `None` to skip the weight gradients (half the cost) when
    ///   only `dL/dinput` is needed.
    /// * `d_input`: if given, overwritten with `dL/dinput` (`batch × input_dim`).
    ///
    /// Errors: no matching tape, length mismatches, non-finite `d_output`.
    pub fn backward(
        &self,
        ws: &mut MlpWorkspace,
        d_output: &[f32],
        mut grads: Option<&mut [f32]>,
        mut d_input: Option<&mut [f32]>,
    ) -> Result<()> {
        let batch = match ws.tape {
            Some(t) if t.fingerprint == self.fingerprint() => t.batch,
            Some(_) => {
                return Err(NnError::NoTape(
                    "the workspace holds a forward pass of a different architecture".into(),
                ))
            }
            None => {
                return Err(NnError::NoTape(
                    "no forward_train since the last forward/backward".into(),
                ))
            }
        };
        check_len("mlp d_output", batch * self.output_dim(), d_output.len())?;
        check_finite("mlp d_output", d_output)?;
        if let Some(g) = grads.as_deref() {
            check_len("mlp grads", self.params.len(), g.len())?;
        }
        if let Some(d) = d_input.as_deref() {
            check_len("mlp d_input", batch * self.input_dim(), d.len())?;
        }
        let n_layers = self.layers.len();
        let MlpWorkspace {
            x0,
            layers,
            g_a,
            g_b,
            g_c,
            ..
        } = ws;
        // g_a holds dL/d(output of layer l) on entry to iteration l.
        g_a[..d_output.len()].copy_from_slice(d_output);
        for l in (0..n_layers).rev() {
            let s = self.layers[l];
            let n = batch * s.fan_out;
            let cur = &layers[l];
            // Through dropout (hidden layers only) and the activation: g_a becomes dL/dz.
            {
                let g = &mut g_a[..n];
                if cur.dropped {
                    for (gv, m) in g.iter_mut().zip(&cur.mask[..n]) {
                        *gv *= m;
                    }
                }
                let act = self.activation(l);
                if act != Activation::Identity {
                    let sig: &[f32] = if act.keeps_sigmoid() {
                        &cur.sig[..n]
                    } else {
                        &[]
                    };
                    activation_backward(act, g, &cur.y[..n], sig, &mut g_c[..n]);
                    std::mem::swap(g_a, g_c);
                }
            }
            let x: &[f32] = if l == 0 {
                &x0[..batch * s.fan_in]
            } else {
                &layers[l - 1].input_of_next()[..batch * s.fan_in]
            };
            let w = &self.params[s.weight_offset..s.bias_offset];
            let g = &g_a[..n];
            // The weight gradient `dZᵀ X` and the input gradient `dZ W` are independent products;
            // when both are large they run side by side (no effect on the numbers).
            let weight_grad = |gr: &mut [f32]| {
                let (gw, gb) = gr[s.weight_offset..s.bias_offset + s.fan_out]
                    .split_at_mut(s.fan_in * s.fan_out);
                gemm_tn(s.fan_out, s.fan_in, batch, g, x, gw, false);
                column_sums(g, s.fan_out, gb);
            };
            let d_in: Option<&mut [f32]> = if l > 0 {
                Some(&mut g_b[..batch * s.fan_in])
            } else {
                d_input.as_deref_mut()
            };
            let input_grad = |d: &mut [f32]| gemm_nn(batch, s.fan_in, s.fan_out, g, w, d, false);
            match (grads.as_deref_mut(), d_in) {
                (Some(gr), Some(d)) if split_backward(batch * s.fan_in * s.fan_out) => {
                    crate::join(|| weight_grad(gr), || input_grad(d));
                }
                (gr, d) => {
                    if let Some(gr) = gr {
                        weight_grad(gr);
                    }
                    if let Some(d) = d {
                        input_grad(d);
                    }
                }
            }
            if l > 0 {
                std::mem::swap(g_a, g_b);
            }
        }
        ws.tape = None;
        Ok(())
    }
}

/// Whether a backward layer's two products of `macs` multiply-adds each run on two threads: only
/// when rayon has a second thread and each product is large enough (2^21 multiply-adds, a
/// 128×128×128 product) to pay for handing work over.
fn split_backward(macs: usize) -> bool {
    macs >= 1 << 21 && rayon::current_num_threads() > 1
}

/// The fewest rows of either half of a split pass. `gemm` gives a row the same bits in products
/// of any row count from about 22 rows up (measured: below that, and at one row, it may pick
/// other kernels), so halves of at least this many rows keep the numbers of the whole pass.
const MIN_BLOCK: usize = 64;

/// Rows per tile of the feature-major inference pass: a tile of a 256-wide layer is 256 KiB, so
/// a layer's input and output stay in a core's L2 cache.
const FEATURE_MAJOR_TILE: usize = 256;

/// Whether a forward pass over `batch` rows of a network with `params` parameters runs its two
/// row halves on two threads (an idle thread steals the second half; a busy pool runs both in
/// turn): when rayon has a second thread, the pass has at least 2^22 multiply-adds (a planner's
/// 500 rows through two 200-wide layers, MBPO's 100 000 imagined rows) and each half at least
/// [`MIN_BLOCK`] rows.
fn split_rows(batch: usize, params: usize) -> bool {
    batch >= 2 * MIN_BLOCK && batch * params >= 1 << 22 && rayon::current_num_threads() > 1
}

/// Runs the loop macro `$each` with the scalar form of activation `$act` (through
/// [`fastmath`]): one loop per activation with the match outside it, since a per-element match does
/// not vectorize. The batched activation kernels below share this one table.
macro_rules! by_activation {
    ($act:expr, $each:ident) => {
        match $act {
            Activation::Identity => $each!(|v: f32| v),
            Activation::Relu => $each!(|v: f32| v.max(0.0)),
            Activation::Tanh => $each!(fastmath::tanh),
            Activation::Sigmoid => $each!(fastmath::sigmoid),
            Activation::Elu => $each!(|v: f32| if v > 0.0 { v } else { fastmath::exp_m1(v) }),
            Activation::Silu => $each!(fastmath::silu),
        }
    };
}

multiversion! {
    /// `y[j, :] = act(y[j, :] + b[j])` over feature-major rows of `width` values (the element-wise
    /// operations of [`bias_activation`], bias per row instead of per column).
    fn bias_activation_by_row(y: &mut [f32], width: usize, b: &[f32], act: Activation) {
        macro_rules! rows {
            ($f:expr) => {
                for (yr, bv) in y.chunks_exact_mut(width).zip(b) {
                    for yv in yr.iter_mut() {
                        *yv = $f(*yv + bv);
                    }
                }
            };
        }
        by_activation!(act, rows);
    }
}

multiversion! {
    /// `y[r, :] = act(y[r, :] + b)`; with `sig`, the activation is SiLU and `sig` keeps `σ(y + b)`
    /// for the backward pass (from the same `exp` as the output).
    fn bias_activation(y: &mut [f32], b: &[f32], act: Activation, sig: Option<&mut [f32]>) {
        let width = b.len();
        if let Some(sig) = sig {
            debug_assert_eq!(act, Activation::Silu);
            for (yr, sr) in y.chunks_exact_mut(width).zip(sig.chunks_exact_mut(width)) {
                for ((yv, sv), bv) in yr.iter_mut().zip(sr.iter_mut()).zip(b) {
                    (*yv, *sv) = fastmath::silu_and_sigmoid(*yv + bv);
                }
            }
            return;
        }
        macro_rules! rows {
            ($f:expr) => {
                for yr in y.chunks_exact_mut(width) {
                    for (yv, bv) in yr.iter_mut().zip(b) {
                        *yv = $f(*yv + bv);
                    }
                }
            };
        }
        by_activation!(act, rows);
    }
}

multiversion! {
    /// `out = g · act'(z)` from the output `y = act(z)` (and SiLU's kept `σ(z)`; not called for the
    /// identity). Writes a separate buffer with selects, not in-place conditional stores: those
    /// compile to masked stores, which are slow on AMD cores.
    fn activation_backward(act: Activation, g: &[f32], y: &[f32], sig: &[f32], out: &mut [f32]) {
        match act {
            Activation::Identity => out.copy_from_slice(g),
            Activation::Relu => {
                for ((o, gv), yv) in out.iter_mut().zip(g).zip(y) {
                    *o = if *yv > 0.0 { *gv } else { 0.0 };
                }
            }
            Activation::Tanh => {
                for ((o, gv), yv) in out.iter_mut().zip(g).zip(y) {
                    *o = gv * (1.0 - yv * yv);
                }
            }
            Activation::Sigmoid => {
                for ((o, gv), yv) in out.iter_mut().zip(g).zip(y) {
                    *o = gv * (yv * (1.0 - yv));
                }
            }
            Activation::Elu => {
                for ((o, gv), yv) in out.iter_mut().zip(g).zip(y) {
                    *o = if *yv > 0.0 { *gv } else { gv * (yv + 1.0) };
                }
            }
            Activation::Silu => {
                // d(zσ)/dz = σ + zσ(1 - σ) = σ + y(1 - σ).
                for (((o, gv), yv), s) in out.iter_mut().zip(g).zip(y).zip(sig) {
                    *o = gv * (s + yv * (1.0 - s));
                }
            }
        }
    }
}

multiversion! {
    /// `out[j] = Σ_r g[r, j]` (rows added in order, so the sums do not depend on the lane count).
    fn column_sums(g: &[f32], width: usize, out: &mut [f32]) {
        out.fill(0.0);
        for row in g.chunks_exact(width) {
            for (o, v) in out.iter_mut().zip(row) {
                *o += v;
            }
        }
    }
}

/// Bernoulli keep-masks from 16-bit slices of 64-bit draws (4 decisions per draw): the drop
/// probability is quantized to 1/65536 and the kept units are scaled by exactly 1/keep-rate, so
/// the expectation of every unit is unchanged.
struct DropoutSampler {
    threshold: u32,
    scale: f32,
}

impl DropoutSampler {
    fn new(p: f32) -> Self {
        let threshold = (f64::from(p) * 65536.0).round().clamp(0.0, 65535.0) as u32;
        let keep = 1.0 - f64::from(threshold) / 65536.0;
        Self {
            threshold,
            scale: (1.0 / keep) as f32,
        }
    }

    fn active(&self) -> bool {
        self.threshold > 0
    }

    fn fill_mask(&self, mask: &mut [f32], rng: &mut Rng) {
        let mut chunks = mask.chunks_exact_mut(4);
        for c in &mut chunks {
            let r: u64 = rng.random();
            for (k, m) in c.iter_mut().enumerate() {
                let u = ((r >> (16 * k)) & 0xffff) as u32;
                *m = if u < self.threshold { 0.0 } else { self.scale };
            }
        }
        let rem = chunks.into_remainder();
        if !rem.is_empty() {
            let r: u64 = rng.random();
            for (k, m) in rem.iter_mut().enumerate() {
                let u = ((r >> (16 * k)) & 0xffff) as u32;
                *m = if u < self.threshold { 0.0 } else { self.scale };
            }
        }
    }
}

fn init_layer(
    init: Init,
    fan_in: usize,
    fan_out: usize,
    w: &mut [f32],
    b: &mut [f32],
    rng: &mut Rng,
) {
    let uniform = |bound: f32, out: &mut [f32], rng: &mut Rng| {
        for v in out.iter_mut() {
            let u: f32 = rng.random();
            *v = (2.0 * u - 1.0) * bound;
        }
    };
    match init {
        Init::TorchDefault => {
            let bound = 1.0 / (fan_in as f32).sqrt();
            uniform(bound, w, rng);
            uniform(bound, b, rng);
        }
        Init::XavierUniform { gain } => {
            let bound = gain * (6.0 / (fan_in + fan_out) as f32).sqrt();
            uniform(bound, w, rng);
            b.fill(0.0);
        }
        Init::Orthogonal { gain } => {
            orthogonal(fan_out, fan_in, gain, w, rng);
            b.fill(0.0);
        }
        Init::Uniform { bound } => {
            uniform(bound, w, rng);
            uniform(bound, b, rng);
        }
    }
}

/// Fills `w` (`rows × cols`, row-major) with a (semi-)orthogonal matrix times `gain`: orthonormal
/// columns if `rows ≥ cols`, orthonormal rows otherwise. Modified Gram–Schmidt in f64 on a
/// Gaussian matrix; R's diagonal is positive by construction, which is the sign convention of
/// `torch.nn.init.orthogonal_`.
fn orthogonal(rows: usize, cols: usize, gain: f32, w: &mut [f32], rng: &mut Rng) {
    let (big, small) = if rows >= cols {
        (rows, cols)
    } else {
        (cols, rows)
    };
    // q: `small` vectors of length `big`.
    let mut q: Vec<Vec<f64>> = (0..small)
        .map(|_| {
            (0..big)
                .map(|_| rng.sample::<f64, _>(rand_distr::StandardNormal))
                .collect()
        })
        .collect();
    for j in 0..small {
        let (done, rest) = q.split_at_mut(j);
        let v = &mut rest[0];
        for _pass in 0..2 {
            for u in done.iter() {
                let d: f64 = u.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
                for (vi, ui) in v.iter_mut().zip(u) {
                    *vi -= d * ui;
                }
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
        for vi in v.iter_mut() {
            *vi /= norm;
        }
    }
    for r in 0..rows {
        for c in 0..cols {
            let val = if rows >= cols { q[c][r] } else { q[r][c] };
            w[r * cols + c] = (val * f64::from(gain)) as f32;
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Tape {
    fingerprint: u64,
    batch: usize,
}

#[derive(Debug, Clone, Default)]
struct LayerBuf {
    /// Post-activation output (before dropout).
    y: Vec<f32>,
    /// SiLU's `σ(z)`, kept for the backward pass in training.
    sig: Vec<f32>,
    /// Post-dropout output (only when `dropped`).
    h: Vec<f32>,
    /// Dropout mask: 0 or 1/keep.
    mask: Vec<f32>,
    dropped: bool,
}

impl LayerBuf {
    fn input_of_next(&self) -> &[f32] {
        if self.dropped {
            &self.h
        } else {
            &self.y
        }
    }
}

/// Scratch memory of an [`Mlp`]'s forward and backward passes: layer outputs, dropout masks, the
/// backward tape. Reuse one per network and call site; buffers grow to the largest batch seen and
/// are never shrunk, so steady-state passes do not allocate.
#[derive(Debug, Clone, Default)]
pub struct MlpWorkspace {
    x0: Vec<f32>,
    layers: Vec<LayerBuf>,
    g_a: Vec<f32>,
    g_b: Vec<f32>,
    g_c: Vec<f32>,
    tape: Option<Tape>,
    /// Ping-pong buffers of the feature-major inference pass, one pair per row half.
    fm: [[Vec<f32>; 2]; 2],
}

impl MlpWorkspace {
    /// Grows what a pass over `batch` rows uses: a training pass everything the backward pass
    /// reads, an inference pass the layer outputs (only the last one when `feature_major`).
    fn ensure(&mut self, net: &Mlp, batch: usize, train: bool, feature_major: bool) {
        let n_layers = net.layers.len();
        if self.layers.len() < n_layers {
            self.layers.resize_with(n_layers, LayerBuf::default);
        }
        let grow = |v: &mut Vec<f32>, n: usize| {
            if v.len() < n {
                v.resize(n, 0.0);
            }
        };
        let last = n_layers - 1;
        if !train {
            for (l, s) in net.layers.iter().enumerate() {
                if l == last || !feature_major {
                    grow(&mut self.layers[l].y, batch * s.fan_out);
                }
            }
            return;
        }
        grow(&mut self.x0, batch * net.input_dim());
        let mut widest = net.input_dim();
        for (l, s) in net.layers.iter().enumerate() {
            let n = batch * s.fan_out;
            widest = widest.max(s.fan_out);
            let buf = &mut self.layers[l];
            grow(&mut buf.y, n);
            if net.activation(l).keeps_sigmoid() {
                grow(&mut buf.sig, n);
            }
            if l < last && net.config.dropout > 0.0 {
                grow(&mut buf.h, n);
                grow(&mut buf.mask, n);
            }
        }
        grow(&mut self.g_a, batch * widest);
        grow(&mut self.g_b, batch * widest);
        grow(&mut self.g_c, batch * widest);
    }

    fn output(&self, net: &Mlp, batch: usize) -> &[f32] {
        &self.layers[net.layers.len() - 1].y[..batch * net.output_dim()]
    }

    /// Whether a training forward pass is recorded and not yet consumed by a backward pass.
    pub fn has_tape(&self) -> bool {
        self.tape.is_some()
    }
}

impl Checkpointable for Mlp {
    /// Writes `{prefix}.layers.{l}.weight` (`[out, in]`) and `{prefix}.layers.{l}.bias` (`[out]`),
    /// the names and shapes of PyTorch's `nn.Sequential` of `nn.Linear`s modulo indices.
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        for (l, s) in self.layers.iter().enumerate() {
            ckpt.put_f32(
                &format!("{prefix}.layers.{l}.weight"),
                &[s.fan_out, s.fan_in],
                self.weight(l),
            )?;
            ckpt.put_f32(
                &format!("{prefix}.layers.{l}.bias"),
                &[s.fan_out],
                self.bias(l),
            )?;
        }
        Ok(())
    }

    /// Reads what [`Checkpointable::save_to`] wrote. A different architecture (a missing, extra
    /// or differently shaped layer) is an error naming the tensor; on error `self` is unchanged.
    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let extra = format!("{prefix}.layers.{}.weight", self.layers.len());
        if ckpt.contains(&extra) {
            return Err(NnError::ShapeMismatch {
                what: extra,
                expected: format!("no such tensor (network has {} layers)", self.layers.len()),
                got: "a tensor".into(),
            });
        }
        let mut new = self.params.clone();
        for (l, s) in self.layers.iter().enumerate() {
            ckpt.read_f32_into(
                &format!("{prefix}.layers.{l}.weight"),
                &[s.fan_out, s.fan_in],
                &mut new[s.weight_offset..s.bias_offset],
            )?;
            ckpt.read_f32_into(
                &format!("{prefix}.layers.{l}.bias"),
                &[s.fan_out],
                &mut new[s.bias_offset..s.bias_offset + s.fan_out],
            )?;
        }
        check_finite(&format!("{prefix} parameters from checkpoint"), &new)?;
        self.params = new;
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use crate::on_threads;
    use candle_core::{Device, Tensor, Var};
    use tandem_core::seeding::rng_from_seed;

    fn random_vec(n: usize, rng: &mut Rng) -> Vec<f32> {
        (0..n).map(|_| rng.random::<f32>() * 2.0 - 1.0).collect()
    }

    /// Gradients of `L = Σ out ⊙ R` from candle's autograd (in f64), given dropout masks per
    /// hidden layer (`None` = no dropout).
    fn candle_grads(
        net: &Mlp,
        x: &[f32],
        batch: usize,
        r: &[f32],
        masks: &[Option<Vec<f32>>],
    ) -> (Vec<f64>, Vec<f64>) {
        let dev = Device::Cpu;
        let to64 = |v: &[f32]| v.iter().map(|&a| f64::from(a)).collect::<Vec<f64>>();
        let xv =
            Var::from_tensor(&Tensor::from_vec(to64(x), (batch, net.input_dim()), &dev).unwrap())
                .unwrap();
        let mut vars = Vec::new();
        let mut h = xv.as_tensor().clone();
        for (l, s) in net.layers().iter().enumerate() {
            let w = Var::from_tensor(
                &Tensor::from_vec(to64(net.weight(l)), (s.fan_out, s.fan_in), &dev).unwrap(),
            )
            .unwrap();
            let b =
                Var::from_tensor(&Tensor::from_vec(to64(net.bias(l)), s.fan_out, &dev).unwrap())
                    .unwrap();
            let z = h
                .matmul(&w.as_tensor().t().unwrap())
                .unwrap()
                .broadcast_add(b.as_tensor())
                .unwrap();
            let a = match net.activation(l) {
                Activation::Identity => z,
                Activation::Relu => z.relu().unwrap(),
                Activation::Tanh => z.tanh().unwrap(),
                Activation::Sigmoid => ((z.neg().unwrap().exp().unwrap() + 1.0).unwrap())
                    .recip()
                    .unwrap(),
                Activation::Elu => {
                    // relu(z) + exp(min(z, 0)) - 1, from ops whose backward candle has.
                    let neg_part = z.neg().unwrap().relu().unwrap().neg().unwrap();
                    ((z.relu().unwrap() + neg_part.exp().unwrap()).unwrap() - 1.0).unwrap()
                }
                Activation::Silu => {
                    let sg = ((z.neg().unwrap().exp().unwrap() + 1.0).unwrap())
                        .recip()
                        .unwrap();
                    (z * sg).unwrap()
                }
            };
            h = match &masks[l] {
                Some(m) => {
                    (a * Tensor::from_vec(to64(m), (batch, s.fan_out), &dev).unwrap()).unwrap()
                }
                None => a,
            };
            vars.push((w, b));
        }
        let rt = Tensor::from_vec(to64(r), (batch, net.output_dim()), &dev).unwrap();
        let loss = (h * rt).unwrap().sum_all().unwrap();
        let g = loss.backward().unwrap();
        let mut flat = Vec::new();
        for (w, b) in &vars {
            flat.extend(
                g.get(w.as_tensor())
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1::<f64>()
                    .unwrap(),
            );
            flat.extend(g.get(b.as_tensor()).unwrap().to_vec1::<f64>().unwrap());
        }
        let dx = g
            .get(xv.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        (flat, dx)
    }

    /// The bias-and-activation kernels (wide copies, whole-block or per-row loops) give exactly
    /// `act(y + b)` of the scalar [`Activation::apply`], element by element, for every
    /// activation and for widths that leave vector tails, with and without keeping SiLU's `σ`.
    #[test]
    fn bias_activation_kernels_give_the_bits_of_the_scalar_activation() {
        let mut rng = rng_from_seed(8);
        for act in [
            Activation::Identity,
            Activation::Relu,
            Activation::Tanh,
            Activation::Sigmoid,
            Activation::Elu,
            Activation::Silu,
        ] {
            for (rows, width) in [(1, 1), (3, 7), (100, 200), (37, 100), (5, 33)] {
                let y0: Vec<f32> = random_vec(rows * width, &mut rng)
                    .iter()
                    .map(|v| 12.0 * v)
                    .collect();
                let b = random_vec(width, &mut rng);
                let want: Vec<f32> = y0
                    .iter()
                    .enumerate()
                    .map(|(i, v)| act.apply(std::hint::black_box(v + b[i % width])))
                    .collect();
                let same = |what: &str, got: &[f32]| {
                    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                        assert_eq!(
                            g.to_bits(),
                            w.to_bits(),
                            "{act:?} {what} {rows}x{width} [{i}]"
                        );
                    }
                };
                let mut y = y0.clone();
                bias_activation(&mut y, &b, act, None);
                same("row-major", &y);
                if act == Activation::Silu {
                    let mut y = y0.clone();
                    let mut sig = vec![0.0; y.len()];
                    bias_activation(&mut y, &b, act, Some(&mut sig));
                    same("row-major keeping σ", &y);
                    for (i, (s, v)) in sig.iter().zip(&y0).enumerate() {
                        let want = fastmath::sigmoid(std::hint::black_box(v + b[i % width]));
                        assert_eq!(s.to_bits(), want.to_bits(), "σ {rows}x{width} [{i}]");
                    }
                }
                // Feature-major: the transpose, bias per row.
                let mut yt = vec![0.0; y0.len()];
                for r in 0..rows {
                    for j in 0..width {
                        yt[j * rows + r] = y0[r * width + j];
                    }
                }
                bias_activation_by_row(&mut yt, rows, &b, act);
                let back: Vec<f32> = (0..rows * width)
                    .map(|i| yt[(i % width) * rows + i / width])
                    .collect();
                same("feature-major", &back);
            }
        }
    }

    /// A large forward pass (inference or training) runs its two row halves on two threads with
    /// the bits of the whole pass on one thread, and so do the gradients after it, for each
    /// activation (an odd batch: halves of unequal size). The inference pass goes in tiles (two
    /// of 256 rows and the rest on one thread; one of 256 and the rest in each half on two) with
    /// the bits of the training pass, which multiplies the whole batch at once.
    #[test]
    fn split_passes_give_the_numbers_of_one_thread() {
        let mut rng = rng_from_seed(11);
        for act in [Activation::Relu, Activation::Silu, Activation::Tanh] {
            let net = Mlp::new(
                MlpConfig::new(&[23, 200, 200, 200, 36]).hidden(act),
                &mut rng,
            )
            .unwrap();
            let batch = 1001;
            assert_eq!(FEATURE_MAJOR_TILE, 256);
            let x = random_vec(batch * 23, &mut rng);
            let run = |threads: usize| {
                on_threads(threads, || {
                    assert_eq!(split_rows(batch, net.num_params()), threads > 1);
                    let mut ws = net.workspace();
                    let out = net.forward(&x, batch, &mut ws).unwrap().to_vec();
                    // A training pass (whole-batch products: the reference) and its gradients.
                    let train_out = net
                        .forward_train(&x, batch, &mut ws, None)
                        .unwrap()
                        .to_vec();
                    let d_out: Vec<f32> = train_out.iter().map(|v| v - 0.5).collect();
                    let mut grads = net.zero_grads();
                    let mut d_in = vec![0.0; x.len()];
                    net.backward(&mut ws, &d_out, Some(&mut grads), Some(&mut d_in))
                        .unwrap();
                    [out, train_out, grads, d_in]
                })
            };
            let same = |what: &str, a: &[f32], b: &[f32]| {
                assert_eq!(a.len(), b.len());
                for (i, (a, b)) in a.iter().zip(b).enumerate() {
                    assert_eq!(a.to_bits(), b.to_bits(), "{act:?}, {what} element {i}");
                }
            };
            let (one, two) = (run(1), run(2));
            // Inference and training passes agree.
            same("inference", &one[0], &one[1]);
            for (what, (a, b)) in ["output", "training output", "grads", "d_input"]
                .iter()
                .zip(one.iter().zip(&two))
            {
                same(what, a, b);
            }
        }
    }

    /// A batch whose halves would take another kernel route than the whole (64 rows × 4 outputs
    /// is a dot-product product, 128 × 4 `gemm`'s main kernel) is not split: two threads give the
    /// numbers of one.
    #[test]
    fn halves_on_another_kernel_route_are_not_split() {
        let mut rng = rng_from_seed(5);
        let net = Mlp::new(MlpConfig::new(&[23, 200, 200, 4]), &mut rng).unwrap();
        for batch in [128, 129, 130, 200] {
            let x = random_vec(batch * 23, &mut rng);
            let run = |threads: usize| {
                on_threads(threads, || {
                    let mut ws = net.workspace();
                    (
                        net.splits_rows(batch),
                        net.forward(&x, batch, &mut ws).unwrap().to_vec(),
                    )
                })
            };
            let ((split1, one), (split2, two)) = (run(1), run(2));
            assert!(!split1);
            assert_eq!(split2, batch >= 130, "batch {batch}");
            for (i, (a, b)) in one.iter().zip(&two).enumerate() {
                assert_eq!(a.to_bits(), b.to_bits(), "batch {batch}, element {i}");
            }
        }
    }

    /// A contraction longer than 512 is cut into other blocks in a product of at most 64 × 64
    /// than in a larger one, so 64 rows into 8 outputs do not get the bits of the same rows in a
    /// pass of 128, and `rows_run_apart` says so.
    #[test]
    fn wide_contractions_cut_apart_differently_are_not_run_apart() {
        let mut rng = rng_from_seed(6);
        let net = Mlp::new(MlpConfig::new(&[600, 8]), &mut rng).unwrap();
        let x = random_vec(128 * 600, &mut rng);
        let mut ws = net.workspace();
        let whole = net.forward(&x, 128, &mut ws).unwrap()[..64 * 8].to_vec();
        let part = net.forward(&x[..64 * 600], 64, &mut ws).unwrap().to_vec();
        assert!(whole
            .iter()
            .zip(&part)
            .any(|(a, b)| a.to_bits() != b.to_bits()));
        assert!(!net.rows_run_apart(128, 64));
        assert!(net.rows_run_apart(128, 80));
    }

    fn assert_close(what: &str, got: &[f32], want: &[f64], tol: f64) {
        assert_eq!(got.len(), want.len(), "{what}: length");
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-3);
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            let err = (f64::from(*g) - w).abs();
            assert!(
                err <= tol * scale,
                "{what}[{i}]: got {g}, want {w} (scale {scale})"
            );
        }
    }

    #[test]
    fn gradients_match_candle_autograd_for_every_activation() {
        let mut rng = rng_from_seed(11);
        for (k, act) in [
            Activation::Relu,
            Activation::Tanh,
            Activation::Sigmoid,
            Activation::Elu,
            Activation::Silu,
            Activation::Identity,
        ]
        .into_iter()
        .enumerate()
        {
            let out_act = if k % 2 == 0 {
                Activation::Identity
            } else {
                Activation::Tanh
            };
            let cfg = MlpConfig::new(&[5, 16, 12, 3]).hidden(act).output(out_act);
            let net = Mlp::new(cfg, &mut rng).unwrap();
            let batch = 7;
            let x = random_vec(batch * 5, &mut rng);
            let r = random_vec(batch * 3, &mut rng);
            let mut ws = net.workspace();
            net.forward_train(&x, batch, &mut ws, None).unwrap();
            let mut grads = net.zero_grads();
            let mut dx = vec![0.0; batch * 5];
            net.backward(&mut ws, &r, Some(&mut grads), Some(&mut dx))
                .unwrap();
            let (want_g, want_dx) = candle_grads(&net, &x, batch, &r, &[None, None, None]);
            assert_close(&format!("{act:?} param grads"), &grads, &want_g, 1e-5);
            assert_close(&format!("{act:?} input grads"), &dx, &want_dx, 1e-5);
        }
    }

    #[test]
    fn gradients_with_dropout_match_candle_given_the_same_masks() {
        let mut rng = rng_from_seed(5);
        let cfg = MlpConfig::new(&[4, 32, 32, 2]).dropout(0.3);
        let net = Mlp::new(cfg, &mut rng).unwrap();
        let batch = 9;
        let x = random_vec(batch * 4, &mut rng);
        let r = random_vec(batch * 2, &mut rng);
        let mut ws = net.workspace();
        let mut drop_rng = rng_from_seed(99);
        let mut replay = drop_rng.clone();
        net.forward_train(&x, batch, &mut ws, Some(&mut drop_rng))
            .unwrap();
        // Recreate the masks from the same stream, as the forward pass drew them.
        let sampler = DropoutSampler::new(0.3);
        let mut masks = Vec::new();
        for _ in 0..2 {
            let mut m = vec![0.0; batch * 32];
            sampler.fill_mask(&mut m, &mut replay);
            masks.push(Some(m));
        }
        masks.push(None);
        let dropped = masks[0]
            .as_ref()
            .unwrap()
            .iter()
            .filter(|v| **v == 0.0)
            .count();
        assert!(dropped > 0 && dropped < batch * 32);
        let mut grads = net.zero_grads();
        let mut dx = vec![0.0; batch * 4];
        net.backward(&mut ws, &r, Some(&mut grads), Some(&mut dx))
            .unwrap();
        let (want_g, want_dx) = candle_grads(&net, &x, batch, &r, &masks);
        assert_close("dropout param grads", &grads, &want_g, 1e-5);
        assert_close("dropout input grads", &dx, &want_dx, 1e-5);
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        let mut rng = rng_from_seed(3);
        let net = Mlp::new(
            MlpConfig::new(&[3, 20, 1]).hidden(Activation::Tanh),
            &mut rng,
        )
        .unwrap();
        let x = random_vec(3, &mut rng);
        let mut ws = net.workspace();
        net.forward_train(&x, 1, &mut ws, None).unwrap();
        let mut dx = vec![0.0; 3];
        net.backward(&mut ws, &[1.0], None, Some(&mut dx)).unwrap();
        for i in 0..3 {
            let h = 1e-2f32;
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += h;
            xm[i] -= h;
            let fp = net.forward(&xp, 1, &mut ws).unwrap()[0];
            let fm = net.forward(&xm, 1, &mut ws).unwrap()[0];
            let fd = (fp - fm) / (2.0 * h);
            assert!((fd - dx[i]).abs() < 1e-3, "dx[{i}]: fd {fd} vs {}", dx[i]);
        }
    }

    #[test]
    fn forward_matches_manual_computation() {
        let mut net = Mlp::zeros(MlpConfig::new(&[2, 2, 1])).unwrap();
        // W0 = [[1, -1], [2, 0.5]], b0 = [0.5, -3], W1 = [[1, 2]], b1 = [0.25]
        net.set_params(&[1.0, -1.0, 2.0, 0.5, 0.5, -3.0, 1.0, 2.0, 0.25])
            .unwrap();
        let mut ws = net.workspace();
        let out = net.forward(&[1.0, 2.0, -1.0, 0.0], 2, &mut ws).unwrap();
        // x=(1,2): h = relu(1-2+0.5, 2+1-3) = (0, 0) -> 0.25
        // x=(-1,0): h = relu(-1+0.5, -2-3) = (0, 0) -> 0.25
        assert_eq!(out, &[0.25, 0.25]);
        let out = net.forward(&[3.0, 1.0], 1, &mut ws).unwrap();
        // h = relu(3-1+0.5, 6+0.5-3) = (2.5, 3.5) -> 2.5 + 7 + 0.25
        assert_eq!(out, &[9.75]);
    }

    #[test]
    fn same_seed_gives_identical_init_and_torch_default_bounds() {
        let cfg = MlpConfig::new(&[23, 256, 256, 1]);
        let a = Mlp::new(cfg.clone(), &mut rng_from_seed(42)).unwrap();
        let b = Mlp::new(cfg.clone(), &mut rng_from_seed(42)).unwrap();
        let c = Mlp::new(cfg, &mut rng_from_seed(43)).unwrap();
        assert!(a
            .params()
            .iter()
            .zip(b.params())
            .all(|(x, y)| x.to_bits() == y.to_bits()));
        assert_ne!(a.params(), c.params());
        for (l, s) in a.layers().iter().enumerate() {
            let bound = 1.0 / (s.fan_in as f32).sqrt();
            let w = a.weight(l);
            assert!(w.iter().all(|v| v.abs() <= bound));
            // Uniform on [-b, b]: variance b²/3.
            let var = w.iter().map(|v| v * v).sum::<f32>() / w.len() as f32;
            assert!(
                (var / (bound * bound / 3.0) - 1.0).abs() < 0.1,
                "layer {l}: var {var}"
            );
        }
    }

    #[test]
    fn orthogonal_and_xavier_inits() {
        let mut rng = rng_from_seed(1);
        for sizes in [[6usize, 10, 4], [10, 6, 4]] {
            let net = Mlp::new(
                MlpConfig::new(&sizes).init(Init::Orthogonal { gain: 2.0 }),
                &mut rng,
            )
            .unwrap();
            let s = net.layers()[0];
            let w = net.weight(0);
            // Gram matrix over the smaller dimension is gain² I.
            let small = s.fan_in.min(s.fan_out);
            for i in 0..small {
                for j in 0..small {
                    let d: f32 = if s.fan_out >= s.fan_in {
                        (0..s.fan_out)
                            .map(|r| w[r * s.fan_in + i] * w[r * s.fan_in + j])
                            .sum()
                    } else {
                        (0..s.fan_in)
                            .map(|c| w[i * s.fan_in + c] * w[j * s.fan_in + c])
                            .sum()
                    };
                    let want = if i == j { 4.0 } else { 0.0 };
                    assert!((d - want).abs() < 1e-4, "{sizes:?} gram[{i},{j}] = {d}");
                }
            }
            assert!(net.bias(0).iter().all(|b| *b == 0.0));
        }
        let net = Mlp::new(
            MlpConfig::new(&[30, 50, 2])
                .init(Init::XavierUniform { gain: 1.0 })
                .output_init(Init::Uniform { bound: 3e-3 }),
            &mut rng,
        )
        .unwrap();
        let bound = (6.0f32 / 80.0).sqrt();
        assert!(net.weight(0).iter().all(|v| v.abs() <= bound));
        assert!(net.weight(0).iter().any(|v| v.abs() > 0.5 * bound));
        assert!(net
            .weight(1)
            .iter()
            .chain(net.bias(1))
            .all(|v| v.abs() <= 3e-3));
    }

    #[test]
    fn dropout_drops_the_right_fraction_and_is_seeded() {
        let mut rng = rng_from_seed(2);
        let net = Mlp::new(MlpConfig::new(&[3, 400, 1]).dropout(0.3), &mut rng).unwrap();
        let sampler = DropoutSampler::new(0.3);
        let mut m = vec![0.0; 100_000];
        sampler.fill_mask(&mut m, &mut rng_from_seed(8));
        let frac = m.iter().filter(|v| **v == 0.0).count() as f64 / m.len() as f64;
        assert!((frac - 0.3).abs() < 0.01, "dropped {frac}");
        // Kept units are scaled so that the mean mask is 1.
        let mean = m.iter().map(|v| f64::from(*v)).sum::<f64>() / m.len() as f64;
        assert!((mean - 1.0).abs() < 0.02);

        let x = random_vec(3 * 8, &mut rng);
        let mut ws = net.workspace();
        let a = net
            .forward_train(&x, 8, &mut ws, Some(&mut rng_from_seed(4)))
            .unwrap()
            .to_vec();
        let b = net
            .forward_train(&x, 8, &mut ws, Some(&mut rng_from_seed(4)))
            .unwrap()
            .to_vec();
        let c = net
            .forward_train(&x, 8, &mut ws, Some(&mut rng_from_seed(5)))
            .unwrap()
            .to_vec();
        let eval = net.forward(&x, 8, &mut ws).unwrap().to_vec();
        let no_rng = net.forward_train(&x, 8, &mut ws, None).unwrap().to_vec();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(eval, no_rng);
        assert_ne!(a, eval);
    }

    #[test]
    fn same_seed_gives_bit_identical_training_with_dropout() {
        let run = |seed: u64| -> Vec<f32> {
            let mut rng = rng_from_seed(seed);
            let mut net = Mlp::new(MlpConfig::new(&[6, 32, 32, 3]).dropout(0.3), &mut rng).unwrap();
            let mut opt =
                crate::optim::Adam::new(crate::optim::AdamConfig::with_lr(1e-3), net.num_params())
                    .unwrap();
            let mut ws = net.workspace();
            let mut g = net.zero_grads();
            let mut d = vec![0.0; 16 * 3];
            for _ in 0..20 {
                let x = random_vec(16 * 6, &mut rng);
                let y = random_vec(16 * 3, &mut rng);
                let p = net.forward_train(&x, 16, &mut ws, Some(&mut rng)).unwrap();
                crate::loss::mse(p, &y, Some(&mut d)).unwrap();
                net.backward(&mut ws, &d, Some(&mut g), None).unwrap();
                crate::optim::Optimizer::step(&mut opt, net.params_mut(), &g).unwrap();
            }
            net.params().to_vec()
        };
        let (a, b, c) = (run(1), run(1), run(2));
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert_ne!(a, c);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut rng = rng_from_seed(0);
        assert!(Mlp::new(MlpConfig::new(&[3]), &mut rng).is_err());
        assert!(Mlp::new(MlpConfig::new(&[3, 0, 1]), &mut rng).is_err());
        assert!(Mlp::new(MlpConfig::new(&[3, 4, 1]).dropout(1.0), &mut rng).is_err());
        let net = Mlp::new(MlpConfig::new(&[3, 4, 2]), &mut rng).unwrap();
        let mut ws = net.workspace();
        assert!(matches!(
            net.forward(&[1.0; 5], 2, &mut ws),
            Err(NnError::ShapeMismatch { .. })
        ));
        assert!(matches!(
            net.forward(&[1.0, f32::NAN, 0.0], 1, &mut ws),
            Err(NnError::NonFinite { index: 1, .. })
        ));
        // backward without a training pass, after an inference pass, or with a wrong d_output
        assert!(matches!(
            net.backward(&mut ws, &[0.0; 2], None, None),
            Err(NnError::NoTape(_))
        ));
        net.forward_train(&[1.0; 3], 1, &mut ws, None).unwrap();
        assert!(net.backward(&mut ws, &[0.0; 3], None, None).is_err());
        assert!(net
            .backward(&mut ws, &[f32::INFINITY, 0.0], None, None)
            .is_err());
        let mut short = vec![0.0; 3];
        assert!(net
            .backward(&mut ws, &[0.0; 2], Some(&mut short), None)
            .is_err());
        let other = Mlp::new(MlpConfig::new(&[3, 5, 2]), &mut rng).unwrap();
        assert!(matches!(
            other.backward(&mut ws, &[0.0; 2], None, None),
            Err(NnError::NoTape(_))
        ));
        net.forward(&[1.0; 3], 1, &mut ws).unwrap();
        assert!(!ws.has_tape());
        let mut bad = net.clone();
        assert!(bad.set_params(&vec![f32::NAN; net.num_params()]).is_err());
    }

    #[test]
    fn config_reads_from_toml_like_json_and_rejects_unknown_keys() {
        let c: MlpConfig = serde_json::from_str(
            r#"{"sizes":[23,400,400,400,17],"dropout":0.3,"hidden_activation":"relu"}"#,
        )
        .unwrap();
        assert_eq!(c.output_activation, Activation::Identity);
        assert_eq!(c.init, Init::TorchDefault);
        assert!(serde_json::from_str::<MlpConfig>(r#"{"sizes":[1,1],"dropot":0.3}"#).is_err());
    }

    #[test]
    fn checkpoint_round_trip_and_architecture_mismatch() {
        let mut rng = rng_from_seed(9);
        let net = Mlp::new(MlpConfig::new(&[4, 8, 8, 2]), &mut rng).unwrap();
        let mut ck = Checkpoint::new();
        net.save_to("q", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        let mut back = Mlp::zeros(MlpConfig::new(&[4, 8, 8, 2])).unwrap();
        back.load_from("q", &ck).unwrap();
        assert!(back
            .params()
            .iter()
            .zip(net.params())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let mut shallow = Mlp::zeros(MlpConfig::new(&[4, 8, 2])).unwrap();
        let e = shallow.load_from("q", &ck).unwrap_err();
        assert!(e.to_string().contains("q.layers"), "{e}");
        assert!(shallow.params().iter().all(|v| *v == 0.0));
        let mut deep = Mlp::zeros(MlpConfig::new(&[4, 8, 8, 8, 2])).unwrap();
        let e = deep.load_from("q", &ck).unwrap_err();
        assert!(e.to_string().contains("q.layers.2.weight"), "{e}");
        assert!(matches!(
            back.load_from("other", &ck),
            Err(NnError::MissingTensor(_))
        ));
    }
}
