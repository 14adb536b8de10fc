//! p2's pixel model (section 3.2, figure 4): an action-conditioned encoder–decoder that predicts
//! the next frame of an image environment from the last four, with heads for the reward and the
//! termination.
//!
//! Architecture (p2 after Oh et al.): the `frames` most recent `H × W × C` frames, stacked along
//! channels (oldest first), go through three convolutions and a fully connected layer (ReLU after
//! each) to the encoding `h_enc`; the action (one-hot) enters multiplicatively,
//!
//! `h_dec = W_dec (W_enc h_enc ⊙ W_a a) + b`,
//!
//! then a fully connected layer and three transposed convolutions (the encoder's mirror, ReLU
//! between them) give one logit per pixel and channel of the next frame. Two linear heads on
//! `h_dec` give the reward (squared error) and the termination logit (binary cross-entropy). The
//! frame loss is p2's multi-label binary cross-entropy, summed over the pixels of a frame; a pixel
//! is predicted "on" when its probability reaches [`PixelModelConfig::threshold`] (p2: 0.2, which
//! they found to recall agents, obstacles and the goal much better than L1 or L2 losses on this
//! stochastic environment). The layers: `k4 s2` convolutions halve the image twice and a `k3 s1`
//! one keeps it (`16 → 8 → 4 → 4`), mirrored by the decoder; frames may be rectangular
//! ([`PixelLayers`] also offers the authors' released layout, stride 1 throughout). p2 puts
//! batch normalization after every layer; this model puts it after every layer but the first and
//! the outputs ([`PixelModelConfig::batch_norm`], on by default). Frames must be binary (0 or 1
//! per pixel and channel): the targets of a multi-label classifier.
//!
//! The network is a candle graph (autograd for the gradient) except for its convolutions, which
//! run through [`tandem_nn::conv`] (im2col and one matrix product per pass; candle's CPU
//! transposed convolution, which its convolution's gradient also uses, is a direct loop), and the
//! batch normalizations lay activations out channels first so that candle's reductions take
//! their fast path. Both cut one training step of the default model on a minibatch of 32 from
//! about 65 ms to about 22–25 ms (one thread, measured side by side on a busy 2-core machine;
//! `benches/models.rs` has the step). The losses are candle's up to float rounding (the first
//! step's loss agrees to 7 digits).
//!
//! Data: [`PixelEpisodes`] keeps whole episodes as frames of bytes and builds the stacks on
//! demand (the first frame repeated before an episode's start), so a run's real data costs one
//! byte per pixel and channel.
//!
//! [`PixelModelEnv`] runs the model as an [`Env`]: it starts from a frame of a real episode
//! (drawn from a pool of real start frames by the reset seed, or given to
//! [`Env::set_state`] as a whole stack), and each step feeds back its own thresholded prediction;
//! its reward and termination are the heads' (terminal at probability 0.5).
//!
//! ```
//! use tandem_core::{seeding::rng_from_seed, Action};
//! use tandem_envs::Env;
//! use tandem_models::{PixelEpisodes, PixelFit, PixelModel, PixelModelConfig, PixelModelEnv};
//!
//! // Three episodes of random binary 16×16 RGB frames (p2's maze, `tandem-robots`' pixel maze,
//! // gives real ones).
//! let mut rng = rng_from_seed(0);
//! let mut frame = || -> Vec<f64> {
//!     (0..768).map(|_| f64::from(rand::Rng::random_range(&mut rng, 0..2u8))).collect()
//! };
//! let mut data = PixelEpisodes::new(16 * 16 * 3);
//! for _ in 0..3 {
//!     let frames: Vec<Vec<f64>> = (0..11).map(|_| frame()).collect();
//!     let actions: Vec<usize> = (0..10).map(|k| k % 5).collect();
//!     data.push_episode(&frames, &actions, &[0.0; 10], false).unwrap();
//! }
//! let cfg = PixelModelConfig { channels: [8, 8, 8], features: 32, factors: 32, ..Default::default() };
//! let mut model = PixelModel::new(cfg).unwrap();
//! let loss = model.fit(&data, &PixelFit { steps: 2, batch_size: 8, seed: 1 }).unwrap();
//! assert!(loss.is_finite());
//! let f1 = model.f1(&data).unwrap(); // one score per channel
//! assert!(f1.iter().all(|f| (0.0..=1.0).contains(f)));
//! // Imagined episodes start from real first frames.
//! let starts = vec![frame()];
//! let mut imagined = PixelModelEnv::new(model, starts, Some(50)).unwrap();
//! let obs = imagined.reset(Some(3));
//! let step = imagined.step(&Action::Discrete(4)).unwrap();
//! assert_eq!((obs.len(), step.observation.len()), (768, 768));
//! ```

use candle_core::{DType, Device, Module, Tensor};
use rand::Rng as _;
use serde::{Deserialize, Serialize};
use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Space};
use tandem_envs::{Env, EnvError, Step};
use tandem_nn::budget::MemoryEstimate;
use tandem_nn::candle_ext::{uniform_tensor, ParamSet};
use tandem_nn::conv::{conv2d_layer, conv_transpose2d_layer};
use tandem_nn::{Checkpoint, Checkpointable};

use crate::model::ModelError;
use crate::train::{nn_other, Opt, OptimizerConfig};

/// Settings of a [`PixelModel`]. `Default` is p2's maze: 16×16 RGB frames, 4 of them, 5 actions,
/// batch normalization, threshold 0.2 (p2); the layer widths and Adam's learning rate are ours
/// (p2 gives none). Measured on the maze (F1 of agent / obstacles after 100 random-policy
/// episodes, 16 minibatches of 32 after each): Adam 1e-3 without batch normalization 0.49 / 0.66,
/// with it 0.63 / 0.73, at 3e-3 0.76 / 0.80, at 1e-2 0.82 / 0.82 (without it 1e-2 lost the
/// obstacles: 0.01); channels `[16, 32, 32]` and 128 features learned slower at every rate
/// tried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PixelModelConfig {
    /// One frame's shape `[height, width, channels]` (flat, row-major in observations);
    /// height and width divisible by 4.
    pub image: [usize; 3],
    /// Frames stacked as the input (p2: 4).
    pub frames: usize,
    /// Number of discrete actions.
    pub n_actions: usize,
    /// Output channels of the three encoder convolutions (mirrored by the decoder).
    pub channels: [usize; 3],
    /// How the convolutions shape the image: halving it twice (ours, the default) or keeping
    /// nearly full resolution (the authors' released maze model).
    pub layers: PixelLayers,
    /// Width of the encoding `h_enc` and of `h_dec`.
    pub features: usize,
    /// Width of the multiplicative action interaction `W_enc h_enc ⊙ W_a a`.
    pub factors: usize,
    /// The optimizer.
    pub optimizer: OptimizerConfig,
    /// Weight of the reward's squared error in the loss.
    pub reward_weight: f64,
    /// Weight of the termination's cross-entropy in the loss.
    pub done_weight: f64,
    /// A pixel is predicted on when its probability reaches this (p2: 0.2).
    pub threshold: f64,
    /// Batch normalization after every layer but the first and the outputs (p2 §3.2: "to
    /// stabilize learning and ensure better gradient flows"): batch statistics in training,
    /// running averages (momentum 0.1, PyTorch's) when predicting.
    pub batch_norm: bool,
    /// Every pixel's predicted probability before training (the output biases' start; ours:
    /// about the fraction of pixels on in p2's maze).
    pub initial_pixel_probability: f64,
    /// Seed of the weight initialization.
    pub seed: u64,
}

impl Default for PixelModelConfig {
    fn default() -> Self {
        Self {
            image: [16, 16, 3],
            frames: 4,
            n_actions: 5,
            channels: [32, 64, 64],
            layers: PixelLayers::Strided,
            features: 256,
            factors: 256,
            optimizer: OptimizerConfig::adam(1e-2),
            reward_weight: 1.0,
            done_weight: 1.0,
            threshold: 0.2,
            initial_pixel_probability: 0.03,
            batch_norm: true,
            seed: 0,
        }
    }
}

/// The convolutions' strides and kernels, mirrored by the transposed convolutions of the decoder.
///
/// `Strided` (the default) halves the image twice: `k4 s2 p1`, `k4 s2 p1`, `k3 s1 p1`
/// (`16 → 8 → 4 → 4`), so the fully connected layers see a `4 × 4` map; it is cheap and learns
/// v0's maze of 2 × 2-pixel cells. `FullResolution` is the layout of the model p2's authors
/// released for their maze: stride 1 without padding, `k4`, `k3`, `k3` (`16 → 13 → 11 → 9`), so
/// a one-pixel object keeps its own place in the `9 × 9` map; at the default widths p2's F1
/// experiment on the maze took about twice as long with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PixelLayers {
    /// `16 → 8 → 4 → 4` (height and width multiples of 4).
    #[default]
    Strided,
    /// `16 → 13 → 11 → 9` (height and width at least 8).
    FullResolution,
}

impl PixelLayers {
    /// The height and width of the last convolution's map for an `h × w` image of a size the
    /// layout takes ([`PixelModelConfig::validate`]); an image too small for it gives an empty
    /// map.
    pub fn map_size(self, h: usize, w: usize) -> (usize, usize) {
        match self {
            Self::Strided => (h / 4, w / 4),
            Self::FullResolution => (h.saturating_sub(7), w.saturating_sub(7)),
        }
    }
}

impl PixelModelConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::Other(format!("pixel model config: {m}")));
        let [h, w, c] = self.image;
        let (fits, layers, need) = match self.layers {
            PixelLayers::Strided => (
                h > 0 && w > 0 && h % 4 == 0 && w % 4 == 0,
                "strided",
                "positive multiples of 4",
            ),
            PixelLayers::FullResolution => (h >= 8 && w >= 8, "full_resolution", "at least 8"),
        };
        if !fits || c == 0 {
            return bad(format!(
                "image {:?}: with {layers} layers height and width must be {need}, channels >= 1",
                self.image
            ));
        }
        if self.frames == 0 || self.n_actions == 0 {
            return bad("frames and n_actions must be >= 1".into());
        }
        if self.channels.contains(&0) || self.features == 0 || self.factors == 0 {
            return bad("channels, features and factors must be >= 1".into());
        }
        for (name, v) in [
            ("threshold", self.threshold),
            ("initial_pixel_probability", self.initial_pixel_probability),
        ] {
            if !(v > 0.0 && v < 1.0) {
                return bad(format!("{name} {v} must lie in (0, 1)"));
            }
        }
        for (name, v) in [
            ("reward_weight", self.reward_weight),
            ("done_weight", self.done_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{name} {v} must be finite and >= 0"));
            }
        }
        Ok(())
    }

    /// The memory of the model trained on minibatches of `batch` stacks: the encoder's and the
    /// decoder's convolutions and fully connected layers with their optimizer state, and the
    /// feature maps of a training pass (estimated by sizes, to catch orders of magnitude).
    pub fn memory(&self, batch: usize) -> MemoryEstimate {
        let [h, w, c] = self.image;
        let [c1, c2, c3] = self.channels;
        let in_c = self.frames.saturating_mul(c);
        let (mh, mw) = self.layers.map_size(h, w);
        let map = mh.saturating_mul(mw).saturating_mul(c3);
        let conv = [
            in_c.saturating_mul(c1).saturating_mul(16),
            c1.saturating_mul(c2).saturating_mul(16),
            c2.saturating_mul(c3).saturating_mul(9),
        ];
        let fc = [
            map.saturating_mul(self.features),
            self.features.saturating_mul(self.factors),
            self.n_actions.saturating_mul(self.factors),
        ];
        let copies = self.optimizer.copies() as usize;
        let params = |v: [usize; 3]| {
            v.iter()
                .try_fold(0usize, |a, &x| a.checked_add(x))
                .unwrap_or(usize::MAX)
        };
        let maps = h
            .saturating_mul(w)
            .saturating_mul(c1)
            .saturating_add((h / 2).saturating_mul(w / 2).saturating_mul(c2))
            .saturating_add(map);
        MemoryEstimate::new()
            .f32s(
                format!("pixel model convolutions (channels {:?})", self.channels),
                &[2, copies, params(conv)],
            )
            .f32s(
                format!(
                    "pixel model dense layers (features {}, factors {})",
                    self.features, self.factors
                ),
                &[2, copies, params(fc)],
            )
            .f32s("pixel model feature maps (x batch)", &[6, batch, maps])
    }

    /// Values per frame (`height · width · channels`).
    pub fn frame_len(&self) -> usize {
        self.image.iter().product()
    }

    /// Values per input stack (`frames · frame_len`).
    pub fn stack_len(&self) -> usize {
        self.frames * self.frame_len()
    }
}

/// Real episodes of an image environment, kept as binary frames (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelEpisodes {
    frame_len: usize,
    /// All frames, episode after episode (an episode of `T` steps keeps `T + 1` frames).
    frames: Vec<u8>,
    /// Per transition: its frame index `t`, the index of its episode's first frame, the action,
    /// the reward and whether `t + 1` is terminal.
    rows: Vec<Row>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    frame: usize,
    first: usize,
    action: usize,
    reward: f32,
    terminated: bool,
}

impl PixelEpisodes {
    /// No episodes yet, for frames of `frame_len` values.
    pub fn new(frame_len: usize) -> Self {
        Self {
            frame_len,
            ..Self::default()
        }
    }

    /// Values per frame.
    pub fn frame_len(&self) -> usize {
        self.frame_len
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// No transitions.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Adds an episode: `frames` are the `T + 1` observations (the reset's first), `actions` and
    /// `rewards` the `T` steps', `terminated` whether its last frame is terminal (a time-limit cut
    /// is not). Frames must be binary; on an error nothing is added.
    pub fn push_episode<F: AsRef<[f64]>>(
        &mut self,
        frames: &[F],
        actions: &[usize],
        rewards: &[f64],
        terminated: bool,
    ) -> Result<(), ModelError> {
        let t = actions.len();
        if frames.len() != t + 1 || rewards.len() != t || t == 0 {
            return Err(ModelError::Dim {
                what: format!(
                    "episode of {} frames, {} actions, {} rewards (frames = actions + 1 = \
                     rewards + 1, at least one step)",
                    frames.len(),
                    t,
                    rewards.len()
                ),
                expected: t + 1,
                got: frames.len(),
            });
        }
        let mut bytes = Vec::with_capacity(frames.len() * self.frame_len);
        for (i, f) in frames.iter().enumerate() {
            let f = f.as_ref();
            if f.len() != self.frame_len {
                return Err(ModelError::Dim {
                    what: format!("frame {i}"),
                    expected: self.frame_len,
                    got: f.len(),
                });
            }
            for &v in f {
                match v {
                    0.0 => bytes.push(0),
                    1.0 => bytes.push(1),
                    _ => {
                        return Err(ModelError::Other(format!(
                            "frame {i} has the value {v}: the pixel model learns binary \
                             frames (every value 0 or 1)"
                        )))
                    }
                }
            }
        }
        if let Some(i) = rewards.iter().position(|r| !r.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "rewards".into(),
                row: i,
            });
        }
        let first = self.frames.len() / self.frame_len.max(1);
        self.frames.extend(bytes);
        for (k, (&a, &r)) in actions.iter().zip(rewards).enumerate() {
            self.rows.push(Row {
                frame: first + k,
                first,
                action: a,
                reward: r as f32,
                terminated: terminated && k + 1 == t,
            });
        }
        Ok(())
    }

    /// The first frame of every episode, in the order they were added (as `f64`, the
    /// observations' type): where imagined episodes may start.
    pub fn first_frames(&self) -> impl Iterator<Item = Vec<f64>> + '_ {
        let n = self.frame_len;
        // An episode's first transition is the one that starts at its first frame.
        self.rows
            .iter()
            .filter(|r| r.frame == r.first)
            .map(move |r| {
                self.frames[r.first * n..(r.first + 1) * n]
                    .iter()
                    .map(|&b| f64::from(b))
                    .collect()
            })
    }

    /// Writes the input stack of transition `i` (`frames` frames ending at its frame, the
    /// episode's first repeated before it) into `out`.
    fn stack_into(&self, i: usize, frames: usize, out: &mut [f32]) {
        let r = self.rows[i];
        let n = self.frame_len;
        for (j, chunk) in out.chunks_exact_mut(n).enumerate().take(frames) {
            let back = frames - 1 - j;
            let f = r.frame.saturating_sub(back).max(r.first);
            for (o, &b) in chunk.iter_mut().zip(&self.frames[f * n..(f + 1) * n]) {
                *o = f32::from(b);
            }
        }
    }

    /// The frame after transition `i`.
    fn next_frame(&self, i: usize) -> &[u8] {
        let f = self.rows[i].frame + 1;
        &self.frames[f * self.frame_len..(f + 1) * self.frame_len]
    }

    /// The input stacks, actions, next frames, rewards and terminal flags of rows `idx`.
    pub fn batch(&self, idx: &[usize], frames: usize) -> PixelBatch {
        let n = self.frame_len;
        let mut b = PixelBatch {
            stacks: vec![0.0; idx.len() * frames * n],
            actions: Vec::with_capacity(idx.len()),
            next: Vec::with_capacity(idx.len() * n),
            rewards: Vec::with_capacity(idx.len()),
            terminated: Vec::with_capacity(idx.len()),
        };
        for (k, &i) in idx.iter().enumerate() {
            self.stack_into(
                i,
                frames,
                &mut b.stacks[k * frames * n..(k + 1) * frames * n],
            );
            let r = self.rows[i];
            b.actions.push(r.action);
            b.next
                .extend(self.next_frame(i).iter().map(|&v| f32::from(v)));
            b.rewards.push(r.reward);
            b.terminated.push(r.terminated);
        }
        b
    }
}

impl Checkpointable for PixelEpisodes {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        ckpt.put_u64(
            &format!("{prefix}.frame_len"),
            &[1],
            &[self.frame_len as u64],
        )?;
        ckpt.put_bytes(&format!("{prefix}.frames"), &self.frames)?;
        let mut ints = Vec::with_capacity(self.rows.len() * 4);
        let mut rewards = Vec::with_capacity(self.rows.len());
        for r in &self.rows {
            ints.extend([
                r.frame as u64,
                r.first as u64,
                r.action as u64,
                u64::from(r.terminated),
            ]);
            rewards.push(r.reward);
        }
        ckpt.put_u64(&format!("{prefix}.rows"), &[self.rows.len(), 4], &ints)?;
        ckpt.put_f32(&format!("{prefix}.rewards"), &[self.rows.len()], &rewards)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let frame_len = ckpt.get_u64(&format!("{prefix}.frame_len"), Some(&[1]))?[0] as usize;
        let frames = ckpt.get_bytes(&format!("{prefix}.frames"))?.to_vec();
        let ints = ckpt.get_u64(&format!("{prefix}.rows"), None)?;
        let rewards = ckpt.get_f32(&format!("{prefix}.rewards"), Some(&[ints.len() / 4]))?;
        let n_frames = frames.len().checked_div(frame_len).unwrap_or(0);
        let corrupt = |m: String| tandem_nn::NnError::Checkpoint(format!("{prefix}: {m}"));
        if frame_len == 0 || frames.len() % frame_len != 0 || rewards.len() * 4 != ints.len() {
            return Err(corrupt(format!(
                "{} frame bytes of {frame_len} per frame, {} row values for {} rewards",
                frames.len(),
                ints.len(),
                rewards.len()
            )));
        }
        let mut rows = Vec::with_capacity(rewards.len());
        for (c, &reward) in ints.chunks_exact(4).zip(&rewards) {
            let (frame, first) = (c[0] as usize, c[1] as usize);
            if frame + 1 >= n_frames || first > frame || c[3] > 1 {
                return Err(corrupt(format!(
                    "a transition refers to frame {frame} of {n_frames}"
                )));
            }
            rows.push(Row {
                frame,
                first,
                action: c[2] as usize,
                reward,
                terminated: c[3] == 1,
            });
        }
        *self = Self {
            frame_len,
            frames,
            rows,
        };
        Ok(())
    }
}

/// Rows of [`PixelEpisodes`] as the network takes them.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelBatch {
    /// Input stacks, `n × frames · frame_len`.
    pub stacks: Vec<f32>,
    /// Actions.
    pub actions: Vec<usize>,
    /// Next frames, `n × frame_len`.
    pub next: Vec<f32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// Terminal flags.
    pub terminated: Vec<bool>,
}

/// Settings of one [`PixelModel::fit`]: `steps` minibatches of `batch_size` transitions drawn
/// uniformly (with replacement) from all the data, from the generator seeded by `seed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PixelFit {
    /// Optimizer steps.
    pub steps: usize,
    /// Transitions per step.
    pub batch_size: usize,
    /// Seed of the draws.
    pub seed: u64,
}

impl Default for PixelFit {
    fn default() -> Self {
        Self {
            steps: 16,
            batch_size: 32,
            seed: 0,
        }
    }
}

/// What the model predicts for a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelPrediction {
    /// Probability of each pixel and channel of the next frame being on, `n × frame_len`
    /// (`H × W × C` per row, the observations' layout).
    pub frame_probs: Vec<f32>,
    /// Predicted rewards.
    pub rewards: Vec<f32>,
    /// Predicted probabilities that the next frame is terminal.
    pub done_probs: Vec<f32>,
}

/// p2's pixel model (see the module documentation).
#[derive(Debug)]
pub struct PixelModel {
    config: PixelModelConfig,
    ps: ParamSet,
    enc: [candle_nn::Conv2d; 3],
    fc_enc: candle_nn::Linear,
    w_enc: candle_nn::Linear,
    w_a: candle_nn::Linear,
    w_dec: candle_nn::Linear,
    fc_dec: candle_nn::Linear,
    dec: [candle_nn::ConvTranspose2d; 3],
    reward_head: candle_nn::Linear,
    done_head: candle_nn::Linear,
    /// The batch normalizations, in the order the graph applies them (empty without).
    norms: Vec<Norm>,
    opt: Opt,
}

/// Number of batch normalizations: after enc1, enc2, fc_enc, w_dec, fc_dec, dec0, dec1.
const NORMS: usize = 7;
const BN_EPS: f64 = 1e-5;
const BN_MOMENTUM: f32 = 0.1;

/// One batch normalization: scale and shift (parameters) and running statistics.
#[derive(Debug, Clone)]
struct Norm {
    gamma: Tensor,
    beta: Tensor,
    mean: Vec<f32>,
    var: Vec<f32>,
}

/// The batch statistics one training pass used: per norm, mean, biased variance and the number
/// of values per channel.
type BatchStats = Vec<(Tensor, Tensor, usize)>;

impl Clone for PixelModel {
    /// A deep copy (candle variables are shared handles).
    fn clone(&self) -> Self {
        let mut c = Self::new(self.config.clone()).expect("the config was valid when built");
        c.ps.set_params_flat(self.ps.params_flat())
            .expect("same architecture, finite parameters");
        c.opt = self.opt.clone();
        for (n, m) in c.norms.iter_mut().zip(&self.norms) {
            n.mean.clone_from(&m.mean);
            n.var.clone_from(&m.var);
        }
        c
    }
}

impl Norm {
    fn new(ps: &mut ParamSet, i: usize, width: usize) -> Result<Self, ModelError> {
        let dev = &Device::Cpu;
        let ones = Tensor::ones(width, DType::F32, dev).map_err(cv)?;
        let zeros = Tensor::zeros(width, DType::F32, dev).map_err(cv)?;
        let g = ps.add(&format!("bn{i}.gamma"), &ones).map_err(nn_other)?;
        let b = ps.add(&format!("bn{i}.beta"), &zeros).map_err(nn_other)?;
        Ok(Self {
            gamma: g.as_tensor().clone(),
            beta: b.as_tensor().clone(),
            mean: vec![0.0; width],
            var: vec![1.0; width],
        })
    }

    /// Normalizes `x` (`n × c` or `n × c × h × w`) per channel: with the batch's statistics
    /// (pushed to `stats`) when training, else with the running ones. Computed on `x` laid out
    /// channels first (`c × n·h·w`), so that every reduction, in the forward pass and in the
    /// gradients of the broadcasts, runs over the last dimension: candle's fast case (its general
    /// reduction costs two integer divisions per element and dimension, which made these
    /// normalizations most of a training step).
    fn forward(&self, x: &Tensor, stats: Option<&mut BatchStats>) -> candle_core::Result<Tensor> {
        let c = self.mean.len();
        let dims = x.dims().to_vec();
        let per_channel = x.elem_count() / c.max(1);
        let rows = if x.rank() == 4 {
            x.transpose(0, 1)?.reshape((c, per_channel))?
        } else {
            x.t()?.contiguous()?
        };
        let (mean, var) = match stats {
            Some(stats) => {
                let m = rows.mean_keepdim(1)?;
                let v = rows.broadcast_sub(&m)?.sqr()?.mean_keepdim(1)?;
                stats.push((m.detach(), v.detach(), per_channel));
                (m, v)
            }
            None => (
                Tensor::from_slice(&self.mean, (c, 1), x.device())?,
                Tensor::from_slice(&self.var, (c, 1), x.device())?,
            ),
        };
        let y = rows
            .broadcast_sub(&mean)?
            .broadcast_div(&var.affine(1.0, BN_EPS)?.sqrt()?)?
            .broadcast_mul(&self.gamma.reshape((c, 1))?)?
            .broadcast_add(&self.beta.reshape((c, 1))?)?;
        if x.rank() == 4 {
            y.reshape((c, dims[0], dims[2], dims[3]))?.transpose(0, 1)
        } else {
            y.t()
        }
    }

    /// Moves the running statistics towards a batch's (PyTorch: the unbiased variance).
    fn update(&mut self, mean: &Tensor, var: &Tensor, count: usize) -> candle_core::Result<()> {
        let m = mean.flatten_all()?.to_vec1::<f32>()?;
        let v = var.flatten_all()?.to_vec1::<f32>()?;
        let unbias = count as f32 / (count.max(2) - 1) as f32;
        for (r, b) in self.mean.iter_mut().zip(m) {
            *r = (1.0 - BN_MOMENTUM) * *r + BN_MOMENTUM * b;
        }
        for (r, b) in self.var.iter_mut().zip(v) {
            *r = (1.0 - BN_MOMENTUM) * *r + BN_MOMENTUM * b * unbias;
        }
        Ok(())
    }
}

fn cv(e: candle_core::Error) -> ModelError {
    ModelError::Other(format!("pixel model: {e}"))
}

/// Rescales the initialization for a deep ReLU network on sparse binary frames: the hidden layers'
/// weights to He's variance `2 / fan_in` (PyTorch's default uniform has `1 / (3 fan_in)`, and
/// over the eight layers from the frames to the logits the one-pixel signal of an agent fades
/// below the biases) and their biases to zero; the output biases to the logit of
/// `p0` (every pixel starts near 0.5 otherwise, and the first steps' push of every logit down
/// goes through the hidden biases and kills the ReLUs). Measured on a walking pixel: without
/// either the model predicted the same frame whatever its input.
fn he_init(ps: &mut ParamSet, p0: f64) -> Result<(), ModelError> {
    let logit = (p0 / (1.0 - p0)).ln();
    for (name, var) in ps.names().to_vec().iter().zip(ps.vars().to_vec()) {
        if name.starts_with("bn") {
            continue;
        }
        let t = var.as_tensor();
        let hidden =
            !(name.starts_with("dec2") || name.starts_with("reward") || name.starts_with("done"));
        let new = if name.ends_with(".bias") {
            if name == "dec2.bias" {
                Some(t.ones_like().and_then(|o| o.affine(logit, 0.0)))
            } else if hidden {
                Some(t.zeros_like())
            } else {
                None
            }
        } else if hidden {
            Some(t.affine(6f64.sqrt(), 0.0))
        } else {
            None
        };
        if let Some(new) = new {
            var.set(&new.map_err(cv)?).map_err(cv)?;
        }
    }
    ps.sync_from_vars().map_err(nn_other)
}

/// A weight matrix without bias (`W_enc`, `W_a`: p2's product has one bias, after `W_dec`).
fn weight_only(
    ps: &mut ParamSet,
    name: &str,
    fan_in: usize,
    fan_out: usize,
    rng: &mut tandem_core::Rng,
) -> Result<candle_nn::Linear, ModelError> {
    let b = 1.0 / (fan_in as f32).sqrt();
    let init = uniform_tensor(rng, &[fan_out, fan_in], -b, b).map_err(nn_other)?;
    let w = ps.add(&format!("{name}.weight"), &init).map_err(nn_other)?;
    Ok(candle_nn::Linear::new(w.as_tensor().clone(), None))
}

impl PixelModel {
    /// A model with weights drawn from `config.seed`.
    pub fn new(config: PixelModelConfig) -> Result<Self, ModelError> {
        config.validate()?;
        let mut rng = rng_from_seed(config.seed);
        let rng = &mut rng;
        let [h, w, c] = config.image;
        let [c1, c2, c3] = config.channels;
        let (f, k) = (config.features, config.factors);
        let (mh, mw) = config.layers.map_size(h, w);
        let flat = c3 * mh * mw;
        let mut ps = ParamSet::new();
        // (kernel, stride, padding) of the three convolutions; the decoder mirrors them.
        let spec: [(usize, usize, usize); 3] = match config.layers {
            PixelLayers::Strided => [(4, 2, 1), (4, 2, 1), (3, 1, 1)],
            PixelLayers::FullResolution => [(4, 1, 0), (3, 1, 0), (3, 1, 0)],
        };
        let conv = |(_, stride, padding): (usize, usize, usize)| candle_nn::Conv2dConfig {
            padding,
            stride,
            ..Default::default()
        };
        let conv_t =
            |(_, stride, padding): (usize, usize, usize)| candle_nn::ConvTranspose2dConfig {
                padding,
                stride,
                ..Default::default()
            };
        let e = nn_other;
        let enc = [
            ps.conv2d("enc0", config.frames * c, c1, spec[0].0, conv(spec[0]), rng)
                .map_err(e)?,
            ps.conv2d("enc1", c1, c2, spec[1].0, conv(spec[1]), rng)
                .map_err(e)?,
            ps.conv2d("enc2", c2, c3, spec[2].0, conv(spec[2]), rng)
                .map_err(e)?,
        ];
        let fc_enc = ps.linear("fc_enc", flat, f, rng).map_err(e)?;
        let w_enc = weight_only(&mut ps, "w_enc", f, k, rng)?;
        let w_a = weight_only(&mut ps, "w_a", config.n_actions, k, rng)?;
        let w_dec = ps.linear("w_dec", k, f, rng).map_err(e)?;
        let fc_dec = ps.linear("fc_dec", f, flat, rng).map_err(e)?;
        let dec = [
            ps.conv_transpose2d("dec0", c3, c2, spec[2].0, conv_t(spec[2]), rng)
                .map_err(e)?,
            ps.conv_transpose2d("dec1", c2, c1, spec[1].0, conv_t(spec[1]), rng)
                .map_err(e)?,
            ps.conv_transpose2d("dec2", c1, c, spec[0].0, conv_t(spec[0]), rng)
                .map_err(e)?,
        ];
        let reward_head = ps.linear("reward", f, 1, rng).map_err(e)?;
        let done_head = ps.linear("done", f, 1, rng).map_err(e)?;
        let mut norms = Vec::new();
        if config.batch_norm {
            for (i, width) in [c2, c3, f, f, c3, c2, c1].into_iter().enumerate() {
                norms.push(Norm::new(&mut ps, i, width)?);
            }
        }
        debug_assert!(norms.is_empty() || norms.len() == NORMS);
        he_init(&mut ps, config.initial_pixel_probability)?;
        let opt = config.optimizer.build(ps.num_params())?;
        Ok(Self {
            config,
            ps,
            enc,
            fc_enc,
            w_enc,
            w_a,
            w_dec,
            fc_dec,
            dec,
            reward_head,
            done_head,
            norms,
            opt,
        })
    }

    /// The settings.
    pub fn config(&self) -> &PixelModelConfig {
        &self.config
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.ps.num_params()
    }

    /// The flat parameters (insertion order of the layers).
    pub fn params(&self) -> &[f32] {
        self.ps.params_flat()
    }

    /// Overwrites the parameters.
    pub fn set_params(&mut self, p: &[f32]) -> Result<(), ModelError> {
        self.ps.set_params_flat(p).map_err(nn_other)
    }

    fn check_inputs(&self, stacks: &[f32], actions: &[usize]) -> Result<(), ModelError> {
        let n = actions.len();
        let sl = self.config.stack_len();
        if n == 0 {
            return Err(ModelError::Empty);
        }
        if stacks.len() != n * sl {
            return Err(ModelError::Dim {
                what: "pixel model input stacks (n × frames · height · width · channels)".into(),
                expected: n * sl,
                got: stacks.len(),
            });
        }
        if let Some(i) = actions.iter().position(|&a| a >= self.config.n_actions) {
            return Err(ModelError::Other(format!(
                "pixel model: action {} of row {i} is out of range (n_actions = {})",
                actions[i], self.config.n_actions
            )));
        }
        if let Some(i) = stacks.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "pixel model input stacks".into(),
                row: i / sl,
            });
        }
        Ok(())
    }

    /// The graph: next-frame logits `n × C × H × W`, reward `n × 1`, termination logit `n × 1`.
    /// With `stats` (training), batch normalization uses the batch's statistics and pushes them
    /// there; without, the running ones.
    fn graph(
        &self,
        stacks: &[f32],
        actions: &[usize],
        mut stats: Option<&mut BatchStats>,
    ) -> candle_core::Result<[Tensor; 3]> {
        let n = actions.len();
        let [h, w, c] = self.config.image;
        let fr = self.config.frames;
        let dev = &Device::Cpu;
        let mut k = 0;
        // Batch normalization number `k`, if any, then ReLU.
        let mut norm_relu = |x: Tensor| -> candle_core::Result<Tensor> {
            let x = match self.norms.get(k) {
                Some(nm) => nm.forward(&x, stats.as_deref_mut())?,
                None => x,
            };
            k += 1;
            x.relu()
        };
        // n × frames × H × W × C → n × frames × C × H × W → n × (frames · C) × H × W.
        let mut x = Tensor::from_slice(stacks, (n, fr, h, w, c), dev)?
            .permute((0, 1, 4, 2, 3))?
            .reshape((n, fr * c, h, w))?;
        for (i, conv) in self.enc.iter().enumerate() {
            x = conv2d_layer(conv, &x)?;
            x = if i == 0 { x.relu()? } else { norm_relu(x)? };
        }
        let h_enc = norm_relu(self.fc_enc.forward(&x.flatten_from(1)?)?)?;
        let mut onehot = vec![0f32; n * self.config.n_actions];
        for (i, &a) in actions.iter().enumerate() {
            onehot[i * self.config.n_actions + a] = 1.0;
        }
        let a = Tensor::from_slice(&onehot, (n, self.config.n_actions), dev)?;
        let joint = self.w_enc.forward(&h_enc)?.mul(&self.w_a.forward(&a)?)?;
        let h_dec = norm_relu(self.w_dec.forward(&joint)?)?;
        let [_, _, c3] = self.config.channels;
        let (mh, mw) = self.config.layers.map_size(h, w);
        let mut y = self.fc_dec.forward(&h_dec)?.reshape((n, c3, mh, mw))?;
        y = norm_relu(y)?;
        for (i, d) in self.dec.iter().enumerate() {
            y = conv_transpose2d_layer(d, &y)?;
            if i + 1 < self.dec.len() {
                y = norm_relu(y)?;
            }
        }
        let reward = self.reward_head.forward(&h_dec)?;
        let done = self.done_head.forward(&h_dec)?;
        Ok([y, reward, done])
    }

    /// Predicts the next frame, reward and termination for `n` input stacks (`n × stack_len`,
    /// each `frames` frames oldest first, `H × W × C` per frame) and actions.
    pub fn predict(
        &self,
        stacks: &[f32],
        actions: &[usize],
    ) -> Result<PixelPrediction, ModelError> {
        self.check_inputs(stacks, actions)?;
        let [y, r, d] = self.graph(stacks, actions, None).map_err(cv)?;
        let read = |t: Tensor| -> candle_core::Result<Vec<f32>> {
            t.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()
        };
        let probs = candle_nn::ops::sigmoid(&y.permute((0, 2, 3, 1)).map_err(cv)?)
            .and_then(read)
            .map_err(cv)?;
        let done = candle_nn::ops::sigmoid(&d).and_then(read).map_err(cv)?;
        Ok(PixelPrediction {
            frame_probs: probs,
            rewards: read(r).map_err(cv)?,
            done_probs: done,
        })
    }

    /// The loss of a batch as a graph (mean over rows of: frame cross-entropy summed over pixels,
    /// `reward_weight` × squared reward error, `done_weight` × termination cross-entropy).
    fn loss(&self, b: &PixelBatch, stats: Option<&mut BatchStats>) -> candle_core::Result<Tensor> {
        let n = b.actions.len();
        let [h, w, c] = self.config.image;
        let dev = &Device::Cpu;
        let [y, r, d] = self.graph(&b.stacks, &b.actions, stats)?;
        let target = Tensor::from_slice(&b.next, (n, h, w, c), dev)?.permute((0, 3, 1, 2))?;
        let frame = bce_with_logits(&y, &target)?.sum_all()?;
        let rt = Tensor::from_slice(&b.rewards, (n, 1), dev)?;
        let reward = r.sub(&rt)?.sqr()?.sum_all()?;
        let dt: Vec<f32> = b
            .terminated
            .iter()
            .map(|&t| f32::from(u8::from(t)))
            .collect();
        let dt = Tensor::from_slice(&dt, (n, 1), dev)?;
        let done = bce_with_logits(&d, &dt)?.sum_all()?;
        let total = frame
            .add(&reward.affine(self.config.reward_weight, 0.0)?)?
            .add(&done.affine(self.config.done_weight, 0.0)?)?;
        total.affine(1.0 / n as f64, 0.0)
    }

    /// The loss of rows `idx` of `data` (no update; batch normalization with the running
    /// statistics).
    pub fn loss_on(&self, data: &PixelEpisodes, idx: &[usize]) -> Result<f64, ModelError> {
        self.check_data(data)?;
        let b = data.batch(idx, self.config.frames);
        self.check_inputs(&b.stacks, &b.actions)?;
        let l = self
            .loss(&b, None)
            .and_then(|l| l.to_scalar::<f32>())
            .map_err(cv)?;
        Ok(f64::from(l))
    }

    fn check_data(&self, data: &PixelEpisodes) -> Result<(), ModelError> {
        if data.frame_len() != self.config.frame_len() {
            return Err(ModelError::Dim {
                what: "pixel episodes' frame length".into(),
                expected: self.config.frame_len(),
                got: data.frame_len(),
            });
        }
        if data.is_empty() {
            return Err(ModelError::Empty);
        }
        Ok(())
    }

    /// The gradient of the training loss of `b` with respect to the flat parameters, and the
    /// loss; the batch statistics go to `stats`.
    fn gradient(
        &self,
        b: &PixelBatch,
        grads: &mut [f32],
        stats: &mut BatchStats,
    ) -> Result<f64, ModelError> {
        let l = self.loss(b, Some(stats)).map_err(cv)?;
        let store = l.backward().map_err(cv)?;
        self.ps.grads_flat(&store, grads).map_err(nn_other)?;
        Ok(f64::from(l.to_scalar::<f32>().map_err(cv)?))
    }

    /// [`PixelFit::steps`] optimizer steps on minibatches of `data`; returns the mean training
    /// loss of the steps. Continues from the current weights and optimizer state; a loss that
    /// turns non-finite is [`ModelError::Diverged`] and leaves the model as it was.
    pub fn fit(&mut self, data: &PixelEpisodes, fit: &PixelFit) -> Result<f64, ModelError> {
        self.check_data(data)?;
        if fit.steps == 0 || fit.batch_size == 0 {
            return Err(ModelError::Other(
                "pixel fit: steps and batch_size must be >= 1".into(),
            ));
        }
        let (before, opt_before) = (self.ps.params_flat().to_vec(), self.opt.clone());
        let norms_before = self.norms.clone();
        let mut rng = rng_from_seed(fit.seed);
        let mut grads = vec![0f32; self.ps.num_params()];
        let mut sum = 0.0;
        for step in 0..fit.steps {
            let idx: Vec<usize> = (0..fit.batch_size)
                .map(|_| rng.random_range(0..data.len()))
                .collect();
            let b = data.batch(&idx, self.config.frames);
            let mut stats = BatchStats::new();
            let l = self.gradient(&b, &mut grads, &mut stats)?;
            let stepped = if l.is_finite() && grads.iter().all(|g| g.is_finite()) {
                let mut p = self.ps.params_flat().to_vec();
                self.opt
                    .step(&mut p, &grads)
                    .ok()
                    .and_then(|_| self.ps.set_params_flat(&p).ok())
            } else {
                None
            };
            if stepped.is_none() {
                self.ps
                    .set_params_flat(&before)
                    .expect("the parameters before the fit were finite");
                self.opt = opt_before;
                self.norms = norms_before;
                return Err(ModelError::Diverged { epoch: 0, step });
            }
            for (nm, (mean, var, count)) in self.norms.iter_mut().zip(&stats) {
                nm.update(mean, var, *count).map_err(cv)?;
            }
            sum += l;
        }
        Ok(sum / fit.steps as f64)
    }

    /// F1 score per channel of the next-frame predictions on all transitions of `data`
    /// (a pixel is predicted on at probability ≥ the threshold), counted over every pixel of
    /// every transition: `2 TP / (2 TP + FP + FN)`, and 1 for a channel with nothing to find and
    /// nothing predicted. Batches of 256 transitions.
    pub fn f1(&self, data: &PixelEpisodes) -> Result<Vec<f64>, ModelError> {
        self.check_data(data)?;
        let c = self.config.image[2];
        let mut counts = vec![[0u64; 3]; c]; // TP, FP, FN per channel
        let all: Vec<usize> = (0..data.len()).collect();
        for idx in all.chunks(256) {
            let b = data.batch(idx, self.config.frames);
            let p = self.predict(&b.stacks, &b.actions)?;
            for (k, (&prob, &truth)) in p.frame_probs.iter().zip(&b.next).enumerate() {
                let on = f64::from(prob) >= self.config.threshold;
                let cnt = &mut counts[k % c];
                match (on, truth == 1.0) {
                    (true, true) => cnt[0] += 1,
                    (true, false) => cnt[1] += 1,
                    (false, true) => cnt[2] += 1,
                    (false, false) => {}
                }
            }
        }
        Ok(counts
            .iter()
            .map(|&[tp, fp, fn_]| f1_score(tp, fp, fn_))
            .collect())
    }
}

/// `2 TP / (2 TP + FP + FN)`; 1 when all three are zero.
pub fn f1_score(tp: u64, fp: u64, fn_: u64) -> f64 {
    let d = 2 * tp + fp + fn_;
    if d == 0 {
        1.0
    } else {
        (2 * tp) as f64 / d as f64
    }
}

/// Elementwise binary cross-entropy of logits `x` against targets `t`, in the stable form
/// `max(x, 0) − x t + ln(1 + e^{−|x|})`.
fn bce_with_logits(x: &Tensor, t: &Tensor) -> candle_core::Result<Tensor> {
    let soft = x.abs()?.neg()?.exp()?.affine(1.0, 1.0)?.log()?;
    x.relu()?.sub(&x.mul(t)?)?.add(&soft)
}

impl Checkpointable for PixelModel {
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> tandem_nn::Result<()> {
        self.ps.save_to(&format!("{prefix}.params"), ckpt)?;
        for (i, nm) in self.norms.iter().enumerate() {
            ckpt.put_f32(
                &format!("{prefix}.bn{i}.running_mean"),
                &[nm.mean.len()],
                &nm.mean,
            )?;
            ckpt.put_f32(
                &format!("{prefix}.bn{i}.running_var"),
                &[nm.var.len()],
                &nm.var,
            )?;
        }
        self.opt.save_to(&format!("{prefix}.opt"), ckpt)
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> tandem_nn::Result<()> {
        let mut ps = self.ps.clone();
        ps.load_from(&format!("{prefix}.params"), ckpt)?;
        let mut opt = self.opt.clone();
        opt.load_from(&format!("{prefix}.opt"), ckpt)?;
        let mut norms = self.norms.clone();
        for (i, nm) in norms.iter_mut().enumerate() {
            let w = [nm.mean.len()];
            nm.mean = ckpt.get_f32(&format!("{prefix}.bn{i}.running_mean"), Some(&w))?;
            nm.var = ckpt.get_f32(&format!("{prefix}.bn{i}.running_var"), Some(&w))?;
        }
        self.ps.set_params_flat(ps.params_flat())?;
        self.opt = opt;
        self.norms = norms;
        Ok(())
    }
}

/// A [`PixelModel`] as an environment: imagined episodes from real start frames (see the module
/// documentation). Observations are single frames, as the real environment's.
#[derive(Debug, Clone)]
pub struct PixelModelEnv {
    model: PixelModel,
    starts: Vec<Vec<f64>>,
    /// The last `frames` frames, oldest first, as the model takes them.
    history: Vec<f32>,
    limit: Option<usize>,
    obs_space: Space,
    act_space: Space,
    ready: bool,
}

impl PixelModelEnv {
    /// Imagination with `model`, starting from one of `starts` (real first frames) at each
    /// seeded reset; episodes end at the model's termination or after `limit` steps (reported
    /// through [`Env::max_episode_steps`]).
    pub fn new(
        model: PixelModel,
        starts: Vec<Vec<f64>>,
        limit: Option<usize>,
    ) -> Result<Self, ModelError> {
        let [h, w, c] = model.config.image;
        let n = model.config.frame_len();
        let mut env = Self {
            obs_space: Space::Box {
                low: vec![0.0; n],
                high: vec![1.0; n],
                shape: vec![h, w, c],
            },
            act_space: Space::discrete(model.config.n_actions),
            history: vec![0.0; model.config.stack_len()],
            model,
            starts: Vec::new(),
            limit,
            ready: false,
        };
        for s in starts {
            env.add_start(s)?;
        }
        Ok(env)
    }

    /// Adds a real first frame to the pool resets draw from.
    pub fn add_start(&mut self, frame: Vec<f64>) -> Result<(), ModelError> {
        let n = self.model.config.frame_len();
        if frame.len() != n {
            return Err(ModelError::Dim {
                what: "start frame".into(),
                expected: n,
                got: frame.len(),
            });
        }
        if frame.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "start frame".into(),
                row: 0,
            });
        }
        self.starts.push(frame);
        Ok(())
    }

    /// The start frames.
    pub fn starts(&self) -> &[Vec<f64>] {
        &self.starts
    }

    /// The model.
    pub fn model(&self) -> &PixelModel {
        &self.model
    }

    /// The model, to refit it.
    pub fn model_mut(&mut self) -> &mut PixelModel {
        &mut self.model
    }

    fn newest(&self) -> Vec<f64> {
        let n = self.model.config.frame_len();
        self.history[self.history.len() - n..]
            .iter()
            .map(|&v| f64::from(v))
            .collect()
    }

    fn start_from(&mut self, frame: &[f64]) {
        let n = self.model.config.frame_len();
        for chunk in self.history.chunks_exact_mut(n) {
            for (h, &v) in chunk.iter_mut().zip(frame) {
                *h = v as f32;
            }
        }
        self.ready = true;
    }
}

impl Env for PixelModelEnv {
    fn id(&self) -> &str {
        "PixelModel"
    }

    fn observation_space(&self) -> &Space {
        &self.obs_space
    }

    fn action_space(&self) -> &Space {
        &self.act_space
    }

    /// Starts from a start frame drawn uniformly by `seed` (the first one without a seed), the
    /// frame repeated over the whole history. Without start frames this returns an all-zero
    /// frame and the next step is an error.
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if self.starts.is_empty() {
            self.ready = false;
            return vec![0.0; self.model.config.frame_len()];
        }
        let i = seed.map_or(0, |s| rng_from_seed(s).random_range(0..self.starts.len()));
        let f = self.starts[i].clone();
        self.start_from(&f);
        f
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        if !self.ready {
            return Err(EnvError::NeedsReset {
                env: self.id().to_string(),
                when: "before reset (or without start frames)",
            });
        }
        self.act_space
            .check(action)
            .map_err(|source| EnvError::InvalidAction {
                env: self.id().to_string(),
                source,
            })?;
        let a = action.as_discrete().unwrap_or(0);
        let p = self
            .model
            .predict(&self.history, &[a])
            .map_err(|e| EnvError::InvalidState {
                env: "PixelModel".into(),
                reason: e.to_string(),
            })?;
        let n = self.model.config.frame_len();
        let th = self.model.config.threshold as f32;
        self.history.copy_within(n.., 0);
        let len = self.history.len();
        for (h, &q) in self.history[len - n..].iter_mut().zip(&p.frame_probs) {
            *h = if q >= th { 1.0 } else { 0.0 };
        }
        Ok(Step {
            observation: self.newest(),
            reward: f64::from(p.rewards[0]),
            terminated: p.done_probs[0] >= 0.5,
            truncated: false,
        })
    }

    /// The whole input stack (`frames` frames, oldest first), as `f64`.
    fn state(&self) -> Vec<f64> {
        self.history.iter().map(|&v| f64::from(v)).collect()
    }

    /// Starts from a whole input stack (`frames · frame_len` values, oldest first).
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        tandem_envs::check_state(self.id(), state, self.history.len())?;
        for (h, &v) in self.history.iter_mut().zip(state) {
            *h = v as f32;
        }
        self.ready = true;
        Ok(self.newest())
    }

    fn max_episode_steps(&self) -> Option<usize> {
        self.limit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny model: 4×4 single-channel frames, 2 of them, 3 actions.
    fn tiny(seed: u64) -> PixelModelConfig {
        PixelModelConfig {
            image: [4, 4, 1],
            frames: 2,
            n_actions: 3,
            channels: [2, 3, 2],
            features: 5,
            factors: 4,
            seed,
            ..PixelModelConfig::default()
        }
    }

    /// One pixel walking on an `s × s` torus: actions 0 right, 1 down, 2 stay; reward 1 on the
    /// top-left pixel; terminal when it reaches the bottom-right one.
    fn walker_episode(
        s: usize,
        start: usize,
        actions: &[usize],
    ) -> (Vec<Vec<f64>>, Vec<f64>, bool) {
        let frame = |p: usize| {
            let mut f = vec![0.0; s * s];
            f[p] = 1.0;
            f
        };
        let mut p = start;
        let (mut frames, mut rewards) = (vec![frame(p)], vec![]);
        for &a in actions {
            let (x, y) = (p % s, p / s);
            p = match a {
                0 => y * s + (x + 1) % s,
                1 => ((y + 1) % s) * s + x,
                _ => p,
            };
            frames.push(frame(p));
            rewards.push(if p == 0 { 1.0 } else { 0.0 });
            if p == s * s - 1 {
                return (frames, rewards, true);
            }
        }
        (frames, rewards, false)
    }

    fn walker_data(s: usize, episodes: u64, seed: u64) -> PixelEpisodes {
        let mut rng = rng_from_seed(seed);
        let mut d = PixelEpisodes::new(s * s);
        for _ in 0..episodes {
            let start = rng.random_range(0..s * s - 1);
            let actions: Vec<usize> = (0..12).map(|_| rng.random_range(0..3)).collect();
            let (frames, rewards, term) = walker_episode(s, start, &actions);
            let used = &actions[..rewards.len()];
            d.push_episode(&frames, used, &rewards, term).unwrap();
        }
        d
    }

    #[test]
    fn stacks_repeat_the_first_frame_and_respect_episode_boundaries() {
        let mut d = PixelEpisodes::new(2);
        let f = |a: f64, b: f64| vec![a, b];
        d.push_episode(
            &[f(1., 0.), f(0., 1.), f(1., 1.)],
            &[0, 1],
            &[0.5, -1.0],
            true,
        )
        .unwrap();
        d.push_episode(&[f(0., 0.), f(1., 0.)], &[2], &[2.0], false)
            .unwrap();
        assert_eq!(d.len(), 3);
        let b = d.batch(&[0, 1, 2], 3);
        // Row 0: [f0, f0, f0]; row 1: [f0, f0, f1]; row 2 (second episode): [g0, g0, g0].
        assert_eq!(
            b.stacks,
            [1., 0., 1., 0., 1., 0., 1., 0., 1., 0., 0., 1., 0., 0., 0., 0., 0., 0.]
        );
        assert_eq!(b.next, [0., 1., 1., 1., 1., 0.]);
        assert_eq!(d.first_frames().collect::<Vec<_>>(), [f(1., 0.), f(0., 0.)]);
        assert_eq!(b.actions, [0, 1, 2]);
        assert_eq!(b.rewards, [0.5, -1.0, 2.0]);
        // Only the last step of a terminated episode is terminal.
        assert_eq!(b.terminated, [false, true, false]);
        // Bad episodes are errors that add nothing.
        assert!(d
            .push_episode(&[f(0.5, 0.), f(0., 0.)], &[0], &[0.], false)
            .is_err());
        assert!(d.push_episode(&[f(0., 0.)], &[0], &[0.], false).is_err());
        assert!(d
            .push_episode(&[vec![0.0; 3], f(0., 0.)], &[0], &[0.], false)
            .is_err());
        assert!(d
            .push_episode(&[f(0., 0.), f(0., 0.)], &[0], &[f64::NAN], false)
            .is_err());
        assert_eq!(d.len(), 3);
    }

    #[test]
    fn f1_counts() {
        assert_eq!(f1_score(0, 0, 0), 1.0);
        assert_eq!(f1_score(3, 1, 1), 0.75);
        assert_eq!(f1_score(0, 2, 0), 0.0);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        assert_gradient_matches_finite_differences(tiny(3), &walker_data(4, 3, 1));
    }

    /// The walker's `s × s` frames widened to `s × 2s` (an empty right half), one transition per
    /// episode.
    fn widened(d: &PixelEpisodes, s: usize) -> PixelEpisodes {
        let widen = |f: &[f32]| -> Vec<f64> {
            f.chunks(s)
                .flat_map(|row| row.iter().map(|&v| f64::from(v)).chain(vec![0.0; s]))
                .collect()
        };
        let mut wide = PixelEpisodes::new(2 * s * s);
        for t in 0..d.len() {
            let b = d.batch(&[t], 1);
            let rewards = [f64::from(b.rewards[0])];
            let frames = [widen(&b.stacks), widen(&b.next)];
            wide.push_episode(&frames, &b.actions, &rewards, b.terminated[0])
                .unwrap();
        }
        wide
    }

    #[test]
    fn rectangular_frames_train_with_exact_gradients() {
        // 4×8 frames: the convolutions' gradients derive each axis's shape separately.
        let cfg = PixelModelConfig {
            image: [4, 8, 1],
            ..tiny(4)
        };
        let wide = widened(&walker_data(4, 5, 4), 4);
        assert_gradient_matches_finite_differences(cfg.clone(), &wide);
        let mut m = PixelModel::new(cfg).unwrap();
        let first = m.loss_on(&wide, &[0, 1, 2]).unwrap();
        m.fit(&wide, &PixelFit::default()).unwrap();
        assert!(m.loss_on(&wide, &[0, 1, 2]).unwrap() < first);
        let p = m.predict(&[0.0; 64], &[0]).unwrap();
        assert_eq!(p.frame_probs.len(), 32);
    }

    #[test]
    fn full_resolution_layers_keep_the_map_and_train_with_exact_gradients() {
        // 8×16 frames: stride-1 convolutions without padding leave a 1×9 map, and the decoder's
        // transposed convolutions must give back exactly 8×16.
        let cfg = PixelModelConfig {
            image: [8, 16, 1],
            layers: PixelLayers::FullResolution,
            ..tiny(5)
        };
        assert_eq!(cfg.layers.map_size(8, 16), (1, 9));
        assert_eq!(cfg.layers.map_size(4, 16), (0, 9));
        let wide = widened(&walker_data(8, 5, 5), 8);
        assert_gradient_matches_finite_differences(cfg.clone(), &wide);
        let mut m = PixelModel::new(cfg).unwrap();
        let p = m.predict(&[0.0; 2 * 128], &[1]).unwrap();
        assert_eq!(p.frame_probs.len(), 128);
        let first = m.loss_on(&wide, &[0, 1, 2]).unwrap();
        m.fit(&wide, &PixelFit::default()).unwrap();
        assert!(m.loss_on(&wide, &[0, 1, 2]).unwrap() < first);
    }

    #[test]
    fn each_layout_states_the_frames_it_takes() {
        let with = |image, layers| PixelModelConfig {
            image,
            layers,
            ..tiny(0)
        };
        // Any size from 8 up at full resolution, multiples of 4 strided.
        assert!(PixelModel::new(with([9, 10, 1], PixelLayers::FullResolution)).is_ok());
        assert!(PixelModel::new(with([8, 8, 1], PixelLayers::Strided)).is_ok());
        for (image, layers) in [
            ([7, 8, 1], PixelLayers::FullResolution),
            ([9, 10, 1], PixelLayers::Strided),
        ] {
            let err = PixelModel::new(with(image, layers))
                .unwrap_err()
                .to_string();
            assert!(err.contains("layers height and width must be"), "{err}");
        }
        // The setting reads from a configuration file by name; the default is `strided`.
        let c: PixelModelConfig = serde_json::from_str(r#"{"layers": "full_resolution"}"#).unwrap();
        assert_eq!(c.layers, PixelLayers::FullResolution);
        assert_eq!(PixelModelConfig::default().layers, PixelLayers::Strided);
    }

    /// The gradient of a model built from `cfg` on (the first six transitions of) `d` agrees with
    /// central differences for nearly every parameter.
    fn assert_gradient_matches_finite_differences(cfg: PixelModelConfig, d: &PixelEpisodes) {
        let mut m = PixelModel::new(cfg).unwrap();
        let idx: Vec<usize> = (0..d.len().min(6)).collect();
        let b = d.batch(&idx, 2);
        let mut g = vec![0f32; m.num_params()];
        m.gradient(&b, &mut g, &mut BatchStats::new()).unwrap();
        let p0 = m.params().to_vec();
        let eps = 1e-3f32;
        let loss = |m: &PixelModel| {
            let l = m.loss(&b, Some(&mut BatchStats::new())).unwrap();
            f64::from(l.to_scalar::<f32>().unwrap())
        };
        let mut checked = 0;
        for i in 0..p0.len() {
            let mut p = p0.clone();
            p[i] += eps;
            m.set_params(&p).unwrap();
            let lp = loss(&m);
            p[i] -= 2.0 * eps;
            m.set_params(&p).unwrap();
            let lm = loss(&m);
            let fd = (lp - lm) / (2.0 * f64::from(eps));
            let an = f64::from(g[i]);
            // ReLU kinks make a few central differences meaningless; count the agreements.
            if (fd - an).abs() <= 2e-2 * (1.0 + an.abs()) {
                checked += 1;
            }
        }
        m.set_params(&p0).unwrap();
        assert!(
            checked as f64 >= 0.97 * p0.len() as f64,
            "{checked} of {} parameters agree with finite differences",
            p0.len()
        );
    }

    #[test]
    fn learns_a_deterministic_pixel_world() {
        // A pixel walking on a 4×4 torus: next frame, reward and termination are functions of
        // the last frame and the action, so a trained model predicts them exactly.
        let cfg = PixelModelConfig {
            image: [8, 8, 1],
            frames: 2,
            n_actions: 3,
            channels: [8, 16, 16],
            features: 64,
            factors: 64,
            optimizer: OptimizerConfig::adam(3e-3),
            ..PixelModelConfig::default()
        };
        let mut m = PixelModel::new(cfg).unwrap();
        let train = walker_data(8, 100, 2);
        let test = walker_data(8, 20, 3);
        let before = m.f1(&test).unwrap()[0];
        for k in 0..50 {
            let fit = PixelFit {
                steps: 20,
                batch_size: 32,
                seed: k,
            };
            m.fit(&train, &fit).unwrap();
        }
        let after = m.f1(&test).unwrap()[0];
        assert!(after > 0.95 && before < 0.1, "F1 {before} -> {after}");
        // The heads: rewards within 0.5 and terminations on the right side of 0.5 for nearly
        // every held-out transition (both events are rare: a few percent of the rows).
        let all: Vec<usize> = (0..test.len()).collect();
        let b = test.batch(&all, 2);
        let p = m.predict(&b.stacks, &b.actions).unwrap();
        let n = all.len() as f64;
        let reward_ok = (0..all.len())
            .filter(|&i| (p.rewards[i] - b.rewards[i]).abs() < 0.5)
            .count();
        let done_ok = (0..all.len())
            .filter(|&i| (p.done_probs[i] >= 0.5) == b.terminated[i])
            .count();
        assert!(reward_ok as f64 >= 0.97 * n, "{reward_ok} of {n} rewards");
        assert!(done_ok as f64 >= 0.97 * n, "{done_ok} of {n} terminations");
    }

    #[test]
    fn checkpoints_restore_predictions_and_data() {
        let mut m = PixelModel::new(tiny(5)).unwrap();
        let d = walker_data(4, 5, 4);
        m.fit(&d, &PixelFit::default()).unwrap();
        let mut ck = Checkpoint::new();
        m.save_to("m", &mut ck).unwrap();
        d.save_to("d", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        let mut m2 = PixelModel::new(tiny(6)).unwrap();
        m2.load_from("m", &ck).unwrap();
        let mut d2 = PixelEpisodes::default();
        d2.load_from("d", &ck).unwrap();
        assert_eq!(d2, d);
        assert_eq!(m2.params(), m.params());
        // The optimizer state came back too: the next fit is the same.
        let fit = PixelFit {
            seed: 9,
            ..PixelFit::default()
        };
        assert_eq!(m.fit(&d, &fit).unwrap(), m2.fit(&d2, &fit).unwrap());
        assert_eq!(m2.params(), m.params());
        // Another architecture does not load.
        let mut other = PixelModel::new(PixelModelConfig {
            features: 6,
            ..tiny(0)
        })
        .unwrap();
        assert!(other.load_from("m", &ck).is_err());
    }

    #[test]
    fn bad_input_is_an_error_and_a_diverging_fit_changes_nothing() {
        let d = walker_data(4, 3, 7);
        let mut m = PixelModel::new(tiny(1)).unwrap();
        let x = vec![0f32; 32];
        assert!(matches!(
            m.predict(&x, &[0, 1]),
            Err(ModelError::Dim { .. })
        ));
        assert!(m.predict(&x[..16], &[3]).is_err());
        assert!(matches!(m.predict(&x[..0], &[]), Err(ModelError::Empty)));
        let mut nan = x[..32].to_vec();
        nan[20] = f32::NAN;
        assert!(matches!(
            m.predict(&nan, &[0]),
            Err(ModelError::NonFinite { row: 0, .. })
        ));
        assert!(m
            .fit(&PixelEpisodes::new(16), &PixelFit::default())
            .is_err());
        assert!(m.fit(&PixelEpisodes::new(9), &PixelFit::default()).is_err());
        assert!(PixelModel::new(PixelModelConfig {
            image: [6, 6, 1],
            ..tiny(0)
        })
        .is_err());
        assert!(PixelModel::new(PixelModelConfig {
            threshold: 1.0,
            ..tiny(0)
        })
        .is_err());
        // An absurd learning rate overflows the weights: an error, the model as it was.
        let mut wild = PixelModel::new(PixelModelConfig {
            optimizer: OptimizerConfig::adam(3e38),
            ..tiny(1)
        })
        .unwrap();
        let p0 = wild.params().to_vec();
        let fit = PixelFit {
            steps: 50,
            ..PixelFit::default()
        };
        assert!(matches!(
            wild.fit(&d, &fit),
            Err(ModelError::Diverged { .. })
        ));
        assert_eq!(wild.params(), &p0[..]);
    }

    #[test]
    fn the_model_environment_feeds_back_thresholded_frames() {
        let d = walker_data(4, 30, 8);
        let mut m = PixelModel::new(tiny(2)).unwrap();
        m.fit(&d, &PixelFit::default()).unwrap();
        let start = walker_episode(4, 5, &[]).0.remove(0);
        let mut env = PixelModelEnv::new(m.clone(), vec![], Some(3)).unwrap();
        env.reset(Some(0));
        assert!(matches!(
            env.step(&Action::Discrete(0)),
            Err(EnvError::NeedsReset { .. })
        ));
        env.add_start(start.clone()).unwrap();
        assert!(env.add_start(vec![0.0; 3]).is_err());
        let obs = env.reset(Some(4));
        assert_eq!(obs, start);
        assert!(matches!(
            env.step(&Action::Discrete(3)),
            Err(EnvError::InvalidAction { .. })
        ));
        assert!(env.step(&Action::Continuous(vec![0.0])).is_err());
        let st = env.step(&Action::Discrete(1)).unwrap();
        // The observation is the model's prediction for [start, start] and action 1, at the
        // threshold; the history shifted by one frame.
        let mut stack: Vec<f32> = start.iter().map(|&v| v as f32).collect();
        stack.extend(stack.clone());
        let p = m.predict(&stack, &[1]).unwrap();
        let expect: Vec<f64> = p
            .frame_probs
            .iter()
            .map(|&q| if q >= 0.2 { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(st.observation, expect);
        assert_eq!(st.reward, f64::from(p.rewards[0]));
        let state = env.state();
        assert_eq!(&state[..16], &start[..]);
        assert_eq!(&state[16..], &expect[..]);
        // set_state starts from a whole stack.
        assert_eq!(env.set_state(&state).unwrap(), expect);
        assert!(env.set_state(&state[..5]).is_err());
        assert_eq!(env.max_episode_steps(), Some(3));
    }
}
