//! A convolutional Q-network for image observations (p2's 16×16 RGB maze).
//!
//! Architecture: `conv → ReLU` layers, flatten, `linear → ReLU` hidden layers, a linear output of
//! one Q-value per action. The default encoder is p2's (section 3.2: "three convolutional layers
//! followed by a fully connected layer", there for the maze's dynamics model; p2 does not give its
//! DQN's layers, so the Q-network reuses that encoder): 3×3 kernels with 16, 32, 32 channels and
//! strides 1, 2, 2 ("same" padding), so a 16×16 image becomes 32 × 4 × 4 features.
//!
//! Observations arrive flat and row-major as `height × width × channels` (the environment's
//! `Box` shape, gymnasium's image layout) and are permuted to candle's `N × C × H × W`.
//!
//! Parameters live in a [`ParamSet`] (seeded PyTorch-default initialization from our generator,
//! flat view for this crate's optimizers, checkpoints), so training is stepped by the same Adam
//! as the MLPs and a run is bit-reproducible. Gradients come from candle's autograd: for an
//! upstream gradient `D = ∂L/∂Q` (computed by the agent, as for the MLP) the backward pass
//! differentiates `Σ Q ⊙ D`, whose parameter gradient is `Jᵀ D = ∂L/∂θ`.

use candle_core::{DType, Device, Module, Tensor};
use serde::{Deserialize, Serialize};
use tandem_core::seeding::rng_from_seed;
use tandem_core::{Rng, Space};
use tandem_nn::budget::MemoryEstimate;
use tandem_nn::candle_ext::ParamSet;
use tandem_nn::{Checkpoint, Checkpointable};

use crate::error::{ensure, AgentError, Result};

/// The layers of a [`ConvQNet`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConvQNetConfig {
    /// Observation image shape `[height, width, channels]` (flat, row-major in observations).
    pub image: [usize; 3],
    /// Output channels of each convolution (each followed by ReLU).
    pub channels: Vec<usize>,
    /// Square kernel size of each convolution (odd: "same" padding `(k - 1) / 2`).
    pub kernels: Vec<usize>,
    /// Stride of each convolution.
    pub strides: Vec<usize>,
}

impl Default for ConvQNetConfig {
    /// p2's maze: 16×16 RGB images, its encoder's three convolutions (3×3; 16, 32, 32 channels;
    /// strides 1, 2, 2).
    fn default() -> Self {
        Self {
            image: [16, 16, 3],
            channels: vec![16, 32, 32],
            kernels: vec![3, 3, 3],
            strides: vec![1, 2, 2],
        }
    }
}

impl ConvQNetConfig {
    /// Checks the layer lists; returns the feature map size `(channels, height, width)` after
    /// the last convolution.
    pub fn validate(&self) -> Result<(usize, usize, usize)> {
        let maps = self.feature_maps()?;
        Ok(*maps.last().expect("the image and at least one convolution"))
    }

    /// Checks the layer lists; returns the shape `(channels, height, width)` of the image and
    /// of each convolution's output.
    fn feature_maps(&self) -> Result<Vec<(usize, usize, usize)>> {
        let [h, w, c] = self.image;
        ensure(
            h >= 1 && w >= 1 && c >= 1,
            "conv.image",
            format!("{:?}", self.image),
            "every dimension must be >= 1",
        )?;
        ensure(
            !self.channels.is_empty(),
            "conv.channels",
            format!("{:?}", self.channels),
            "needs at least one convolution",
        )?;
        ensure(
            self.kernels.len() == self.channels.len() && self.strides.len() == self.channels.len(),
            "conv.kernels",
            format!("{:?} / strides {:?}", self.kernels, self.strides),
            "needs one kernel size and one stride per entry of conv.channels",
        )?;
        let mut maps = vec![(c, h, w)];
        let (mut hh, mut ww) = (h, w);
        for ((&co, &k), &s) in self.channels.iter().zip(&self.kernels).zip(&self.strides) {
            ensure(co >= 1, "conv.channels", co, "must be >= 1")?;
            ensure(k % 2 == 1, "conv.kernels", k, "must be odd (same padding)")?;
            ensure(s >= 1, "conv.strides", s, "must be >= 1")?;
            let p = (k - 1) / 2;
            // candle's conv2d backward pass derives one output padding from the height and
            // uses it for the width too, so both must leave the same remainder.
            ensure(
                (hh + 2 * p - k) % s == (ww + 2 * p - k) % s,
                "conv.image",
                format!("{:?}", self.image),
                "height and width must leave the same remainder at every strided layer \
                 (candle's conv2d gradient assumes it); square images always do",
            )?;
            hh = (hh + 2 * p - k) / s + 1;
            ww = (ww + 2 * p - k) / s + 1;
            maps.push((co, hh, ww));
        }
        Ok(maps)
    }

    /// Adds to `est` a Q-network of these convolutions followed by fully connected `hidden`
    /// layers and `n_actions` outputs: `copies` parameter-sized buffers (see
    /// [`MemoryEstimate::mlp`]) and the feature maps of a `batch`-image training pass. A
    /// config that does not validate adds nothing (its error comes from [`Self::validate`]).
    pub fn memory(
        &self,
        est: MemoryEstimate,
        hidden: &[usize],
        n_actions: usize,
        copies: u64,
        batch: usize,
    ) -> MemoryEstimate {
        let Ok(maps) = self.feature_maps() else {
            return est;
        };
        let size =
            |&(c, h, w): &(usize, usize, usize)| c.checked_mul(h).and_then(|x| x.checked_mul(w));
        // Conv weights c_in·c_out·k² + c_out per layer, then the fully connected layers.
        let conv_params = maps
            .windows(2)
            .zip(&self.kernels)
            .try_fold(0u64, |acc, (m, &k)| {
                let (ci, co) = (m[0].0 as u64, m[1].0 as u64);
                let kk = (k as u64).checked_mul(k as u64)?;
                acc.checked_add(ci.checked_mul(co)?.checked_mul(kk)?.checked_add(co)?)
            });
        let flat = maps.last().and_then(size);
        let est = est.part(
            "convolution parameters",
            conv_params
                .and_then(|p| p.checked_mul(copies))
                .and_then(|p| p.checked_mul(4)),
        );
        let feature_elems = maps
            .iter()
            .try_fold(0usize, |acc, m| acc.checked_add(size(m)?));
        let est = est.part(
            "convolution feature maps",
            feature_elems.and_then(|n| tandem_nn::budget::f32_bytes(&[n, batch, 3])),
        );
        match flat {
            Some(f) => {
                let mut sizes = vec![f];
                sizes.extend(hidden);
                sizes.push(n_actions);
                est.mlp("fully connected layers", &sizes, copies, batch)
            }
            None => est.part("fully connected layers", None),
        }
    }

    /// Checks that `space` is a `Box` of exactly this image shape.
    pub fn check_space(&self, space: &Space) -> Result<()> {
        match space {
            Space::Box { shape, .. } if shape[..] == self.image[..] => Ok(()),
            _ => Err(AgentError::WrongObservationSpace {
                agent: "dqn",
                got: format!(
                    "{} (the conv Q-network is configured for images of shape {:?} = [height, \
                     width, channels])",
                    space.describe(),
                    self.image
                ),
                reason: "a conv Q-network needs a Box observation space whose shape is \
                         conv.image",
            }),
        }
    }
}

/// A convolutional Q-network (see the module documentation).
#[derive(Debug)]
pub struct ConvQNet {
    config: ConvQNetConfig,
    hidden: Vec<usize>,
    n_actions: usize,
    ps: ParamSet,
    convs: Vec<candle_nn::Conv2d>,
    fcs: Vec<candle_nn::Linear>,
    out: Option<Tensor>,
    values: Vec<f32>,
}

impl Clone for ConvQNet {
    /// A deep copy (candle variables are shared handles, so cloning them would tie the copy to
    /// the original's parameters).
    fn clone(&self) -> Self {
        let mut c = Self::new(
            self.config.clone(),
            &self.hidden,
            self.n_actions,
            &mut rng_from_seed(0),
        )
        .expect("the architecture was valid when built");
        c.ps.set_params_flat(self.ps.params_flat())
            .expect("same architecture, finite parameters");
        c
    }
}

impl ConvQNet {
    /// A network for `config`'s images with fully connected `hidden` layers after the
    /// convolutions and `n_actions` outputs, initialized from `rng`.
    pub fn new(
        config: ConvQNetConfig,
        hidden: &[usize],
        n_actions: usize,
        rng: &mut Rng,
    ) -> Result<Self> {
        let (fc, fh, fw) = config.validate()?;
        ensure(n_actions >= 1, "n_actions", n_actions, "must be >= 1")?;
        // What this constructor allocates: the parameters, before any of them.
        config
            .memory(MemoryEstimate::new(), hidden, n_actions, 1, 0)
            .check(&format!("conv Q-network {:?}", config.channels))?;
        let mut ps = ParamSet::new();
        let mut convs = Vec::new();
        let mut c_in = config.image[2];
        for (i, ((&co, &k), &s)) in config
            .channels
            .iter()
            .zip(&config.kernels)
            .zip(&config.strides)
            .enumerate()
        {
            let cfg = candle_nn::Conv2dConfig {
                padding: (k - 1) / 2,
                stride: s,
                ..Default::default()
            };
            convs.push(ps.conv2d(&format!("conv{i}"), c_in, co, k, cfg, rng)?);
            c_in = co;
        }
        let mut fcs = Vec::new();
        let mut fan_in = fc * fh * fw;
        for (i, &hdim) in hidden.iter().chain(std::iter::once(&n_actions)).enumerate() {
            ensure(hdim >= 1, "hidden", hdim, "layer sizes must be >= 1")?;
            fcs.push(ps.linear(&format!("fc{i}"), fan_in, hdim, rng)?);
            fan_in = hdim;
        }
        Ok(Self {
            config,
            hidden: hidden.to_vec(),
            n_actions,
            ps,
            convs,
            fcs,
            out: None,
            values: Vec::new(),
        })
    }

    /// Flat observation length (`height · width · channels`).
    pub fn input_dim(&self) -> usize {
        self.config.image.iter().product()
    }

    /// Number of outputs.
    pub fn n_actions(&self) -> usize {
        self.n_actions
    }

    /// Total number of parameters.
    pub fn num_params(&self) -> usize {
        self.ps.num_params()
    }

    /// The flat parameters (insertion order: convolutions, then linear layers; weight, bias).
    pub fn params(&self) -> &[f32] {
        self.ps.params_flat()
    }

    /// Overwrites the parameters (e.g. a target copy).
    pub fn set_params(&mut self, p: &[f32]) -> Result<()> {
        Ok(self.ps.set_params_flat(p)?)
    }

    fn graph(&self, x: &[f32], n: usize) -> Result<Tensor> {
        let [h, w, c] = self.config.image;
        if x.len() != n * h * w * c || n == 0 {
            return Err(AgentError::Dim {
                what: "conv Q-network input (n × height × width × channels)",
                expected: n.max(1) * h * w * c,
                got: x.len(),
            });
        }
        let cv = |e: candle_core::Error| AgentError::Nn(e.into());
        let mut t = Tensor::from_slice(x, (n, h, w, c), &Device::Cpu)
            .and_then(|t| t.permute((0, 3, 1, 2)))
            .and_then(|t| t.contiguous())
            .map_err(cv)?;
        for conv in &self.convs {
            t = conv.forward(&t).and_then(|t| t.relu()).map_err(cv)?;
        }
        t = t.flatten_from(1).map_err(cv)?;
        let last = self.fcs.len() - 1;
        for (i, fc) in self.fcs.iter().enumerate() {
            t = fc.forward(&t).map_err(cv)?;
            if i < last {
                t = t.relu().map_err(cv)?;
            }
        }
        Ok(t)
    }

    fn read(t: &Tensor, out: &mut Vec<f32>) -> Result<()> {
        let v = t
            .to_dtype(DType::F32)
            .and_then(|t| t.flatten_all())
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|e| AgentError::Nn(e.into()))?;
        *out = v;
        Ok(())
    }

    /// Q-values of `n` flat images (`n × n_actions`, row-major) through `&self` (batched
    /// acting), into a new vector.
    pub fn infer(&self, x: &[f32], n: usize) -> Result<Vec<f32>> {
        let mut v = Vec::new();
        Self::read(&self.graph(x, n)?, &mut v)?;
        Ok(v)
    }

    /// Q-values of `n` flat images (`n × n_actions`, row-major), without keeping the graph.
    pub fn forward(&mut self, x: &[f32], n: usize) -> Result<&[f32]> {
        let t = self.graph(x, n)?;
        Self::read(&t, &mut self.values)?;
        Ok(&self.values)
    }

    /// Like [`ConvQNet::forward`], keeping the graph for [`ConvQNet::backward`].
    pub fn forward_train(&mut self, x: &[f32], n: usize) -> Result<&[f32]> {
        let t = self.graph(x, n)?;
        Self::read(&t, &mut self.values)?;
        self.out = Some(t);
        Ok(&self.values)
    }

    /// The parameter gradient `∂L/∂θ` for `d_out = ∂L/∂Q` of the last
    /// [`ConvQNet::forward_train`] (same layout as its output), written into `grads`
    /// (length [`ConvQNet::num_params`]).
    pub fn backward(&mut self, d_out: &[f32], grads: &mut [f32]) -> Result<()> {
        let out = self.out.take().ok_or(AgentError::Empty(
            "conv Q-network graph (call forward_train before backward)",
        ))?;
        let cv = |e: candle_core::Error| AgentError::Nn(e.into());
        if d_out.len() != out.elem_count() {
            return Err(AgentError::Dim {
                what: "conv Q-network output gradient",
                expected: out.elem_count(),
                got: d_out.len(),
            });
        }
        let d = Tensor::from_slice(d_out, out.shape(), &Device::Cpu).map_err(cv)?;
        let store = out
            .mul(&d)
            .and_then(|p| p.sum_all())
            .and_then(|l| l.backward())
            .map_err(cv)?;
        self.ps.grads_flat(&store, grads)?;
        Ok(())
    }

    /// Writes the parameters under `{prefix}.{layer}.{weight|bias}`.
    pub fn save(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        Ok(self.ps.save_to(prefix, ckpt)?)
    }

    /// Reads what [`ConvQNet::save`] wrote; an error (nothing changed) for another architecture.
    pub fn load(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        self.ps.load_from(prefix, ckpt).map_err(|e| {
            AgentError::Checkpoint(format!("does not match this agent's conv Q-network: {e}"))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;

    fn tiny() -> ConvQNetConfig {
        ConvQNetConfig {
            image: [4, 4, 2],
            channels: vec![3, 2],
            kernels: vec![3, 1],
            strides: vec![1, 2],
        }
    }

    fn images(n: usize, dim: usize, seed: u64) -> Vec<f32> {
        let mut rng = rng_from_seed(seed);
        (0..n * dim).map(|_| rng.random::<f32>()).collect()
    }

    #[test]
    fn shapes_follow_the_layers_and_rows_are_independent() {
        let cfg = ConvQNetConfig::default();
        assert_eq!(cfg.validate().unwrap(), (32, 4, 4));
        let mut q = ConvQNet::new(cfg, &[64], 5, &mut rng_from_seed(0)).unwrap();
        let n_params = (16 * 3 * 9 + 16) + (32 * 16 * 9 + 32) + (32 * 32 * 9 + 32);
        assert_eq!(q.num_params(), n_params + (512 * 64 + 64) + (64 * 5 + 5));
        let x = images(3, 768, 1);
        let all = q.forward(&x, 3).unwrap().to_vec();
        assert_eq!(all.len(), 15);
        // The second image alone gives the second row.
        let one = q.forward(&x[768..1536], 1).unwrap().to_vec();
        for (a, b) in one.iter().zip(&all[5..10]) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        assert!(matches!(
            q.forward(&x[..700], 1),
            Err(AgentError::Dim {
                expected: 768,
                got: 700,
                ..
            })
        ));
        // The input is read as height × width × channels: moving one pixel's channel value
        // to another channel changes the output.
        let mut y = x[..768].to_vec();
        y.swap(0, 1);
        assert_ne!(q.forward(&y, 1).unwrap(), &one[..]);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let cfg = tiny();
        let (n, na) = (3, 2);
        let mut q = ConvQNet::new(cfg, &[4], na, &mut rng_from_seed(7)).unwrap();
        let x = images(n, 32, 2);
        let d: Vec<f32> = (0..n * na).map(|i| ((i as f32) * 0.9).sin()).collect();
        let loss = |q: &mut ConvQNet| -> f64 {
            let out = q.forward(&x, n).unwrap();
            out.iter()
                .zip(&d)
                .map(|(o, g)| f64::from(*o) * f64::from(*g))
                .sum()
        };
        q.forward_train(&x, n).unwrap();
        let mut g = vec![0.0; q.num_params()];
        q.backward(&d, &mut g).unwrap();
        let p0 = q.params().to_vec();
        let eps = 1e-4f32;
        let mut worst = f64::NEG_INFINITY;
        for i in 0..p0.len() {
            let mut p = p0.clone();
            p[i] += eps;
            q.set_params(&p).unwrap();
            let lp = loss(&mut q);
            p[i] -= 2.0 * eps;
            q.set_params(&p).unwrap();
            let lm = loss(&mut q);
            let fd = (lp - lm) / (2.0 * f64::from(eps));
            // f32 forward passes: ~1e-4 of rounding noise in `fd` at this step; a larger step
            // crosses ReLU kinks of this tiny net.
            let err = (fd - f64::from(g[i])).abs() - 2e-2 * fd.abs();
            worst = worst.max(err);
        }
        assert!(
            worst < 5e-4,
            "worst error beyond 2% of the difference quotient: {worst}"
        );
        // A second backward without a new forward_train is an error, not a stale gradient.
        assert!(q.backward(&d, &mut g).is_err());
    }

    #[test]
    fn seeded_deep_clone_and_checkpoint_round_trip() {
        let make = |s| ConvQNet::new(tiny(), &[4], 3, &mut rng_from_seed(s)).unwrap();
        let (a, b) = (make(1), make(1));
        assert_eq!(a.params(), b.params());
        assert_ne!(a.params(), make(2).params());
        // A clone is independent of the original.
        let mut c = a.clone();
        let mut p = c.params().to_vec();
        p[0] += 1.0;
        c.set_params(&p).unwrap();
        assert_ne!(a.params(), c.params());
        let x = images(2, 32, 3);
        let mut a2 = a.clone();
        assert_eq!(a2.forward(&x, 2).unwrap(), make(1).forward(&x, 2).unwrap());
        // Checkpoint round trip into a differently seeded net.
        let mut ck = Checkpoint::new();
        a.save("q", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        let mut d = make(9);
        d.load("q", &ck).unwrap();
        assert_eq!(d.params(), a.params());
        assert_eq!(d.forward(&x, 2).unwrap(), a2.forward(&x, 2).unwrap());
        // Another architecture: a checkpoint error, parameters unchanged.
        let mut other = ConvQNet::new(tiny(), &[5], 3, &mut rng_from_seed(1)).unwrap();
        let before = other.params().to_vec();
        assert!(matches!(
            other.load("q", &ck),
            Err(AgentError::Checkpoint(_))
        ));
        assert_eq!(other.params(), &before[..]);
    }

    #[test]
    fn bad_configs_and_spaces_are_errors() {
        let bad = [
            ConvQNetConfig {
                kernels: vec![2, 3, 3],
                ..Default::default()
            },
            ConvQNetConfig {
                strides: vec![1, 2],
                ..Default::default()
            },
            ConvQNetConfig {
                channels: vec![],
                kernels: vec![],
                strides: vec![],
                ..Default::default()
            },
            ConvQNetConfig {
                image: [16, 0, 3],
                ..Default::default()
            },
            ConvQNetConfig {
                image: [4, 5, 2],
                ..tiny()
            },
        ];
        for c in bad {
            assert!(
                matches!(c.validate(), Err(AgentError::Config { .. })),
                "{c:?}"
            );
        }
        let cfg = ConvQNetConfig::default();
        let flat = Space::symmetric(768, 1.0);
        let e = cfg.check_space(&flat).unwrap_err();
        assert!(matches!(e, AgentError::WrongObservationSpace { .. }));
        assert!(e.to_string().contains("[16, 16, 3]"), "{e}");
        assert!(cfg.check_space(&Space::discrete(4)).is_err());
        let img = Space::Box {
            low: vec![0.0; 768],
            high: vec![1.0; 768],
            shape: vec![16, 16, 3],
        };
        cfg.check_space(&img).unwrap();
        let chw = Space::Box {
            low: vec![0.0; 768],
            high: vec![1.0; 768],
            shape: vec![3, 16, 16],
        };
        assert!(cfg.check_space(&chw).is_err());
    }
}
