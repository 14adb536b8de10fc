//! candle for the networks that need general autograd (convolutional Q-networks, p2's pixel
//! model), made seeded and plugged into this crate's optimizers and checkpoints.
//!
//! * [`configure_cpu_threads`]: the start-up settings candle needs on a CPU (without
//!   `RAYON_NUM_THREADS`, candle re-reads `/proc/cpuinfo` on every matmul: 7 µs → 94 µs).
//! * [`ParamSet`]: named candle [`Var`]s created with PyTorch-default initialization drawn from
//!   our [`Rng`] (candle's CPU generator cannot be seeded), plus [`ParamSet::step`], which runs
//!   any [`Optimizer`] of this crate over the flattened parameters and writes them back. Flat
//!   views also make polyak updates ([`ParamSet::params_flat`]/[`ParamSet::set_params_flat`])
//!   and checkpoints ([`Checkpointable`]) the same as for [`Mlp`](crate::Mlp).
//!
//! ```
//! use candle_core::{Device, Module, Tensor};
//! use tandem_core::seeding::rng_from_seed;
//! use tandem_nn::candle_ext::ParamSet;
//! use tandem_nn::{Adam, AdamConfig};
//!
//! let mut rng = rng_from_seed(0);
//! let mut ps = ParamSet::new();
//! let conv = ps.conv2d("conv", 3, 4, 3, Default::default(), &mut rng).unwrap();
//! let mut opt = Adam::new(AdamConfig::with_lr(1e-3), ps.num_params()).unwrap();
//! let x = Tensor::ones((2, 3, 8, 8), candle_core::DType::F32, &Device::Cpu).unwrap();
//! let loss = conv.forward(&x).unwrap().sqr().unwrap().mean_all().unwrap();
//! let grads = loss.backward().unwrap();
//! ps.step(&mut opt, &grads).unwrap();
//! ```

use std::sync::Once;

use candle_core::backprop::GradStore;
use candle_core::{DType, Device, Shape, Tensor, Var};
use rand::Rng as _;
use tandem_core::seeding::Rng;

use crate::checkpoint::{Checkpoint, Checkpointable};
use crate::error::{check_finite, check_len, NnError, Result};
use crate::optim::Optimizer;

static THREADS: Once = Once::new();

/// Sets `RAYON_NUM_THREADS` (to the number of available cores) and `CANDLE_NUM_THREADS` (to 1)
/// unless already set. Call it at the start of `main`, before any thread or candle op exists;
/// later calls do nothing. Measured effect (notes): batch-1 inference 94 µs → 7 µs, batch-500
/// forward 3.4 ms → 2.2 ms.
pub fn configure_cpu_threads() {
    THREADS.call_once(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if std::env::var_os("RAYON_NUM_THREADS").is_none() {
            std::env::set_var("RAYON_NUM_THREADS", cores.to_string());
        }
        if std::env::var_os("CANDLE_NUM_THREADS").is_none() {
            std::env::set_var("CANDLE_NUM_THREADS", "1");
        }
    });
}

/// A tensor of i.i.d. `U(lo, hi)` f32 values drawn from `rng` (row-major order).
pub fn uniform_tensor(rng: &mut Rng, shape: &[usize], lo: f32, hi: f32) -> Result<Tensor> {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| lo + (hi - lo) * rng.random::<f32>())
        .collect();
    Ok(Tensor::from_vec(data, shape, &Device::Cpu)?)
}

/// A tensor of i.i.d. `N(mean, std²)` f32 values drawn from `rng`.
pub fn normal_tensor(rng: &mut Rng, shape: &[usize], mean: f32, std: f32) -> Result<Tensor> {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| mean + std * rng.sample::<f32, _>(rand_distr::StandardNormal))
        .collect();
    Ok(Tensor::from_vec(data, shape, &Device::Cpu)?)
}

/// Named, seeded candle parameters with a flat view for this crate's optimizers.
#[derive(Debug, Clone, Default)]
pub struct ParamSet {
    names: Vec<String>,
    vars: Vec<Var>,
    sizes: Vec<usize>,
    flat: Vec<f32>,
    grads: Vec<f32>,
}

impl ParamSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a parameter initialized from `init` (any f32 CPU tensor); names must be unique.
    pub fn add(&mut self, name: &str, init: &Tensor) -> Result<Var> {
        if self.names.iter().any(|n| n == name) {
            return Err(NnError::InvalidConfig(format!(
                "duplicate parameter name `{name}`"
            )));
        }
        let init = init.to_dtype(DType::F32)?.contiguous()?;
        let data = init.flatten_all()?.to_vec1::<f32>()?;
        check_finite(&format!("parameter `{name}`"), &data)?;
        let var = Var::from_tensor(&init)?;
        self.names.push(name.to_string());
        self.sizes.push(data.len());
        self.flat.extend_from_slice(&data);
        self.grads.resize(self.flat.len(), 0.0);
        self.vars.push(var.clone());
        Ok(var)
    }

    /// A linear layer `in → out` with PyTorch's default init (`U(±1/√in)` for weight and bias);
    /// parameters `{name}.weight` (`[out, in]`) and `{name}.bias`.
    pub fn linear(
        &mut self,
        name: &str,
        fan_in: usize,
        fan_out: usize,
        rng: &mut Rng,
    ) -> Result<candle_nn::Linear> {
        let b = 1.0 / (fan_in as f32).sqrt();
        let w = self.add(
            &format!("{name}.weight"),
            &uniform_tensor(rng, &[fan_out, fan_in], -b, b)?,
        )?;
        let bias = self.add(
            &format!("{name}.bias"),
            &uniform_tensor(rng, &[fan_out], -b, b)?,
        )?;
        Ok(candle_nn::Linear::new(
            w.as_tensor().clone(),
            Some(bias.as_tensor().clone()),
        ))
    }

    /// A 2-D convolution `c_in → c_out` with a `k × k` kernel and PyTorch's default init
    /// (`U(±1/√(c_in·k²/groups))`); parameters `{name}.weight` (`[c_out, c_in/groups, k, k]`)
    /// and `{name}.bias`.
    pub fn conv2d(
        &mut self,
        name: &str,
        c_in: usize,
        c_out: usize,
        k: usize,
        cfg: candle_nn::Conv2dConfig,
        rng: &mut Rng,
    ) -> Result<candle_nn::Conv2d> {
        let groups = cfg.groups.max(1);
        if !c_in.is_multiple_of(groups) || !c_out.is_multiple_of(groups) {
            return Err(NnError::InvalidConfig(format!(
                "conv2d `{name}`: channels {c_in}→{c_out} not divisible by groups {groups}"
            )));
        }
        let fan_in = c_in / groups * k * k;
        let b = 1.0 / (fan_in as f32).sqrt();
        let w = self.add(
            &format!("{name}.weight"),
            &uniform_tensor(rng, &[c_out, c_in / groups, k, k], -b, b)?,
        )?;
        let bias = self.add(
            &format!("{name}.bias"),
            &uniform_tensor(rng, &[c_out], -b, b)?,
        )?;
        Ok(candle_nn::Conv2d::new(
            w.as_tensor().clone(),
            Some(bias.as_tensor().clone()),
            cfg,
        ))
    }

    /// A 2-D transposed convolution `c_in → c_out`, `k × k`, with PyTorch's default init (fan-in
    /// `c_out·k²`, as `torch.nn.ConvTranspose2d` computes it); parameters `{name}.weight`
    /// (`[c_in, c_out, k, k]`) and `{name}.bias`.
    pub fn conv_transpose2d(
        &mut self,
        name: &str,
        c_in: usize,
        c_out: usize,
        k: usize,
        cfg: candle_nn::ConvTranspose2dConfig,
        rng: &mut Rng,
    ) -> Result<candle_nn::ConvTranspose2d> {
        let b = 1.0 / ((c_out * k * k) as f32).sqrt();
        let w = self.add(
            &format!("{name}.weight"),
            &uniform_tensor(rng, &[c_in, c_out, k, k], -b, b)?,
        )?;
        let bias = self.add(
            &format!("{name}.bias"),
            &uniform_tensor(rng, &[c_out], -b, b)?,
        )?;
        Ok(candle_nn::ConvTranspose2d::new(
            w.as_tensor().clone(),
            Some(bias.as_tensor().clone()),
            cfg,
        ))
    }

    /// The variables, in insertion order.
    pub fn vars(&self) -> &[Var] {
        &self.vars
    }

    /// The parameter names, in insertion order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Total number of scalars.
    pub fn num_params(&self) -> usize {
        self.flat.len()
    }

    /// All parameters, flattened in insertion order (kept in sync with the variables by every
    /// method of this type; call [`ParamSet::sync_from_vars`] if you set a `Var` yourself).
    pub fn params_flat(&self) -> &[f32] {
        &self.flat
    }

    /// Re-reads the flat copy from the variables.
    pub fn sync_from_vars(&mut self) -> Result<()> {
        let mut off = 0;
        for (v, &n) in self.vars.iter().zip(&self.sizes) {
            let data = v.as_tensor().flatten_all()?.to_vec1::<f32>()?;
            self.flat[off..off + n].copy_from_slice(&data);
            off += n;
        }
        Ok(())
    }

    /// Overwrites all parameters from a flat slice (e.g. after a polyak update of a copy).
    pub fn set_params_flat(&mut self, p: &[f32]) -> Result<()> {
        check_len("candle parameters", self.flat.len(), p.len())?;
        check_finite("candle parameters", p)?;
        self.flat.copy_from_slice(p);
        self.write_back()
    }

    fn write_back(&self) -> Result<()> {
        let mut off = 0;
        for (v, &n) in self.vars.iter().zip(&self.sizes) {
            let t = Tensor::from_slice(
                &self.flat[off..off + n],
                v.as_tensor().shape(),
                &Device::Cpu,
            )?;
            v.set(&t)?;
            off += n;
        }
        Ok(())
    }

    /// Flattens the gradients in `grads` (zeros for a parameter the loss does not reach) into
    /// `out` (length [`ParamSet::num_params`]).
    pub fn grads_flat(&self, grads: &GradStore, out: &mut [f32]) -> Result<()> {
        check_len("candle gradient buffer", self.flat.len(), out.len())?;
        let mut off = 0;
        for (v, &n) in self.vars.iter().zip(&self.sizes) {
            match grads.get(v.as_tensor()) {
                Some(g) => {
                    let data = g.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
                    out[off..off + n].copy_from_slice(&data);
                }
                None => out[off..off + n].fill(0.0),
            }
            off += n;
        }
        Ok(())
    }

    /// One optimizer step from a candle backward pass: flattens the gradients, steps the flat
    /// parameters, writes them back into the variables. A non-finite gradient is an error and
    /// changes nothing.
    pub fn step(&mut self, opt: &mut impl Optimizer, grads: &GradStore) -> Result<()> {
        let mut g = std::mem::take(&mut self.grads);
        let r = self
            .grads_flat(grads, &mut g)
            .and_then(|_| opt.step(&mut self.flat, &g));
        self.grads = g;
        r?;
        self.write_back()
    }

    /// Like [`ParamSet::step`] with a gradient already flattened (e.g. after clipping).
    pub fn step_flat(&mut self, opt: &mut impl Optimizer, grads: &[f32]) -> Result<()> {
        opt.step(&mut self.flat, grads)?;
        self.write_back()
    }
}

impl Checkpointable for ParamSet {
    /// Writes `{prefix}.{name}` for every parameter with its candle shape.
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        let mut off = 0;
        for ((name, v), &n) in self.names.iter().zip(&self.vars).zip(&self.sizes) {
            ckpt.put_f32(
                &format!("{prefix}.{name}"),
                v.as_tensor().dims(),
                &self.flat[off..off + n],
            )?;
            off += n;
        }
        Ok(())
    }

    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        let mut new = self.flat.clone();
        let mut off = 0;
        for ((name, v), &n) in self.names.iter().zip(&self.vars).zip(&self.sizes) {
            let shape: &Shape = v.as_tensor().shape();
            ckpt.read_f32_into(
                &format!("{prefix}.{name}"),
                shape.dims(),
                &mut new[off..off + n],
            )?;
            off += n;
        }
        check_finite(&format!("{prefix} parameters from checkpoint"), &new)?;
        self.flat = new;
        self.write_back()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::{Mlp, MlpConfig};
    use crate::optim::{Adam, AdamConfig};
    use candle_core::Module;
    use tandem_core::seeding::rng_from_seed;

    #[test]
    fn candle_linear_net_trains_like_the_hand_derived_mlp() {
        // The same 3→8→2 ReLU network as candle modules and as an Mlp: identical parameters,
        // identical gradients, identical Adam trajectories.
        let mut ps = ParamSet::new();
        let l1 = ps.linear("l1", 3, 8, &mut rng_from_seed(1)).unwrap();
        let l2 = ps.linear("l2", 8, 2, &mut rng_from_seed(2)).unwrap();
        let mut mlp = Mlp::zeros(MlpConfig::new(&[3, 8, 2])).unwrap();
        mlp.set_params(ps.params_flat()).unwrap();
        let x: Vec<f32> = (0..15).map(|i| (i as f32 * 0.7).sin()).collect();
        let y: Vec<f32> = (0..10).map(|i| (i as f32 * 0.3).cos()).collect();
        let xt = Tensor::from_slice(&x, (5, 3), &Device::Cpu).unwrap();
        let yt = Tensor::from_slice(&y, (5, 2), &Device::Cpu).unwrap();
        let mut opt_c = Adam::new(AdamConfig::with_lr(1e-2), ps.num_params()).unwrap();
        let mut opt_m = Adam::new(AdamConfig::with_lr(1e-2), mlp.num_params()).unwrap();
        let mut ws = mlp.workspace();
        let mut g = mlp.zero_grads();
        let mut d = vec![0.0; 10];
        for _ in 0..5 {
            let out = l2
                .forward(&l1.forward(&xt).unwrap().relu().unwrap())
                .unwrap();
            let loss = (out - &yt).unwrap().sqr().unwrap().mean_all().unwrap();
            ps.step(&mut opt_c, &loss.backward().unwrap()).unwrap();
            let pred = mlp.forward_train(&x, 5, &mut ws, None).unwrap();
            crate::loss::mse(pred, &y, Some(&mut d)).unwrap();
            mlp.backward(&mut ws, &d, Some(&mut g), None).unwrap();
            opt_m.step(mlp.params_mut(), &g).unwrap();
        }
        for (a, b) in ps.params_flat().iter().zip(mlp.params()) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // The variables hold what the flat view says.
        let w1 = ps.vars()[0]
            .as_tensor()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(&w1[..], &ps.params_flat()[..24]);
    }

    #[test]
    fn conv_init_is_seeded_and_torch_bounded_and_checkpoints_round_trip() {
        let make = |seed| {
            let mut ps = ParamSet::new();
            ps.conv2d("c", 3, 16, 3, Default::default(), &mut rng_from_seed(seed))
                .unwrap();
            ps.conv_transpose2d("d", 16, 3, 4, Default::default(), &mut rng_from_seed(seed))
                .unwrap();
            ps
        };
        let (a, b, c) = (make(5), make(5), make(6));
        assert_eq!(a.params_flat(), b.params_flat());
        assert_ne!(a.params_flat(), c.params_flat());
        let bound = 1.0 / 27f32.sqrt();
        assert!(a.params_flat()[..16 * 27].iter().all(|v| v.abs() <= bound));
        assert_eq!(a.num_params(), 16 * 27 + 16 + 16 * 3 * 16 + 3);
        let mut ck = Checkpoint::new();
        a.save_to("q", &mut ck).unwrap();
        let ck = Checkpoint::from_bytes(&ck.to_bytes().unwrap()).unwrap();
        assert_eq!(ck.shape("q.c.weight").unwrap(), &[16, 3, 3, 3]);
        let mut d = make(7);
        d.load_from("q", &ck).unwrap();
        assert_eq!(d.params_flat(), a.params_flat());
        let v = d.vars()[0]
            .as_tensor()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(&v[..], &a.params_flat()[..16 * 27]);
        // Another architecture: error naming the tensor, nothing changed.
        let mut other = ParamSet::new();
        other
            .conv2d("c", 3, 8, 3, Default::default(), &mut rng_from_seed(1))
            .unwrap();
        let before = other.params_flat().to_vec();
        let e = other.load_from("q", &ck).unwrap_err();
        assert!(e.to_string().contains("q.c.weight"), "{e}");
        assert_eq!(other.params_flat(), &before[..]);
        assert!(other
            .add(
                "c.weight",
                &Tensor::zeros(1, DType::F32, &Device::Cpu).unwrap()
            )
            .is_err());
    }

    #[test]
    fn non_finite_gradient_changes_nothing() {
        let mut ps = ParamSet::new();
        let l = ps.linear("l", 2, 1, &mut rng_from_seed(0)).unwrap();
        let before = ps.params_flat().to_vec();
        let x = Tensor::new(&[[f32::INFINITY, 1.0]], &Device::Cpu).unwrap();
        let loss = l.forward(&x).unwrap().sum_all().unwrap();
        let mut opt = Adam::new(AdamConfig::default(), ps.num_params()).unwrap();
        assert!(ps.step(&mut opt, &loss.backward().unwrap()).is_err());
        assert_eq!(ps.params_flat(), &before[..]);
        let v = ps.vars()[0]
            .as_tensor()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(&v[..], &before[..2]);
    }
}
