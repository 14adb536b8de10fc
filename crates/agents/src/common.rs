//! Pieces the agents share: space checks, action scaling, a network bundled with its optimizer,
//! workspace and gradient buffer, and checkpoint helpers.

use ndarray::{Array2, ArrayView2};
use tandem_core::{Rng, Space};
use tandem_nn::{
    Adam, AdamConfig, Checkpoint, Checkpointable, Mlp, MlpConfig, MlpWorkspace, SharedWorkspace,
};

use crate::error::{AgentError, Result};

/// The flat dimension of a box observation space; an error for a discrete one.
pub(crate) fn obs_dim(agent: &'static str, space: &Space) -> Result<usize> {
    match space {
        Space::Box { low, .. } if !low.is_empty() => Ok(low.len()),
        _ => Err(AgentError::WrongObservationSpace {
            agent,
            got: space.describe(),
            reason: "needs a non-empty Box of real vectors",
        }),
    }
}

/// Affine map between an environment's box `[low, high]` and the networks' `[-1, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ActionScale {
    center: Vec<f64>,
    half: Vec<f64>,
}

impl ActionScale {
    /// The scale of a bounded box action space; an error for a discrete or unbounded one.
    pub(crate) fn new(agent: &'static str, space: &Space) -> Result<Self> {
        match space {
            Space::Box { low, high, .. }
                if !low.is_empty()
                    && low
                        .iter()
                        .zip(high)
                        .all(|(l, h)| l.is_finite() && h.is_finite() && h > l) =>
            {
                Ok(Self {
                    center: low.iter().zip(high).map(|(l, h)| 0.5 * (l + h)).collect(),
                    half: low.iter().zip(high).map(|(l, h)| 0.5 * (h - l)).collect(),
                })
            }
            _ => Err(AgentError::WrongActionSpace {
                agent,
                expected: "continuous, bounded (Box with finite low < high)",
                got: space.describe(),
            }),
        }
    }

    /// Number of action components.
    pub(crate) fn dim(&self) -> usize {
        self.center.len()
    }

    /// `[-1, 1]` to environment units.
    pub(crate) fn to_env(&self, a: &[f32]) -> Vec<f64> {
        a.iter()
            .zip(self.center.iter().zip(&self.half))
            .map(|(x, (c, h))| c + h * f64::from(*x))
            .collect()
    }

    /// Rows of `[-1, 1]` actions (`n x dim`, row-major) in environment units, `n x dim`.
    pub(crate) fn to_env_rows(&self, a: &[f32]) -> Array2<f64> {
        let d = self.dim();
        let mut out = Array2::zeros((a.len() / d, d));
        for (mut o, x) in out.rows_mut().into_iter().zip(a.chunks_exact(d)) {
            for k in 0..d {
                o[k] = self.center[k] + self.half[k] * f64::from(x[k]);
            }
        }
        out
    }

    /// Environment-unit rows (`n x dim`) to `[-1, 1]`, row-major `f32`.
    pub(crate) fn normalize_view(&self, rows: ArrayView2<'_, f64>) -> Vec<f32> {
        let mut out = Vec::with_capacity(rows.len());
        for r in rows.rows() {
            for k in 0..self.dim() {
                out.push(((r[k] - self.center[k]) / self.half[k]) as f32);
            }
        }
        out
    }

    /// Environment units to `[-1, 1]`, row by row in place (`n x dim`).
    pub(crate) fn normalize_rows(&self, rows: &[f32], out: &mut [f32]) {
        let d = self.dim();
        for (o, x) in out.chunks_exact_mut(d).zip(rows.chunks_exact(d)) {
            for k in 0..d {
                o[k] = ((f64::from(x[k]) - self.center[k]) / self.half[k]) as f32;
            }
        }
    }
}

/// The number of choices of a discrete action space; an error for a box.
pub(crate) fn discrete_n(agent: &'static str, space: &Space) -> Result<usize> {
    match space {
        Space::Discrete { n } if *n >= 1 => Ok(*n),
        _ => Err(AgentError::WrongActionSpace {
            agent,
            expected: "discrete",
            got: space.describe(),
        }),
    }
}

/// A trained network: parameters, its Adam state, a workspace and a gradient buffer, and a
/// second workspace behind a mutex for inference through `&self` ([`Net::infer`]).
#[derive(Debug, Clone)]
pub(crate) struct Net {
    pub(crate) mlp: Mlp,
    pub(crate) opt: Adam,
    pub(crate) ws: MlpWorkspace,
    pub(crate) grads: Vec<f32>,
    shared: SharedWorkspace,
}

impl Net {
    pub(crate) fn new(config: MlpConfig, lr: f64, rng: &mut Rng) -> Result<Self> {
        Self::with_adam(config, AdamConfig::with_lr(lr as f32), rng)
    }

    /// [`Net::new`] with a full Adam configuration (e.g. weight decay).
    pub(crate) fn with_adam(config: MlpConfig, adam: AdamConfig, rng: &mut Rng) -> Result<Self> {
        let mlp = Mlp::new(config, rng)?;
        let opt = Adam::new(adam, mlp.num_params())?;
        let ws = mlp.workspace();
        let grads = mlp.zero_grads();
        Ok(Self {
            mlp,
            opt,
            ws,
            grads,
            shared: SharedWorkspace::default(),
        })
    }

    /// The outputs for `n` rows of `x` through `&self` (the batched acting and critic paths).
    pub(crate) fn infer(&self, x: &[f32], n: usize) -> Result<Vec<f32>> {
        self.shared
            .with(|_, ws| Ok(self.mlp.forward(x, n, ws)?.to_vec()))
    }

    /// Checks the rows of `obs` (`B x dim`) and runs them through `&self`: the `f32` rows and the
    /// outputs ([`crate::agent::infer_rows`]).
    pub(crate) fn infer_obs(
        &self,
        obs: ArrayView2<'_, f64>,
        dim: usize,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        crate::agent::infer_rows(obs, dim, |x, n| self.infer(x, n))
    }

    /// Applies the gradient in `self.grads` with Adam.
    pub(crate) fn step(&mut self) -> Result<()> {
        use tandem_nn::Optimizer as _;
        self.opt.step(self.mlp.params_mut(), &self.grads)?;
        Ok(())
    }

    pub(crate) fn save(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        self.mlp.save_to(prefix, ckpt)?;
        self.opt.save_to(&format!("{prefix}_opt"), ckpt)?;
        Ok(())
    }

    pub(crate) fn load(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        self.mlp.load_from(prefix, ckpt).map_err(arch_err)?;
        self.opt
            .load_from(&format!("{prefix}_opt"), ckpt)
            .map_err(arch_err)?;
        Ok(())
    }
}

/// A network that only follows another (a target network): parameters and a workspace.
#[derive(Debug, Clone)]
pub(crate) struct Target {
    pub(crate) mlp: Mlp,
    pub(crate) ws: MlpWorkspace,
}

impl Target {
    pub(crate) fn of(net: &Net) -> Self {
        Self {
            mlp: net.mlp.clone(),
            ws: net.mlp.workspace(),
        }
    }

    pub(crate) fn polyak(&mut self, source: &Net, tau: f64) -> Result<()> {
        tandem_nn::polyak_update(self.mlp.params_mut(), source.mlp.params(), tau as f32)?;
        Ok(())
    }

    pub(crate) fn save(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()> {
        self.mlp.save_to(prefix, ckpt)?;
        Ok(())
    }

    pub(crate) fn load(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()> {
        self.mlp.load_from(prefix, ckpt).map_err(arch_err)
    }
}

fn arch_err(e: tandem_nn::NnError) -> AgentError {
    AgentError::Checkpoint(format!(
        "does not match this agent's architecture or state: {e}"
    ))
}

/// Writes the identity of an agent (algorithm, config as JSON, dimensions) into the metadata and
/// the generator's state as a JSON tensor.
pub(crate) fn save_header<C: serde::Serialize>(
    ckpt: &mut Checkpoint,
    algo: &str,
    config: &C,
    dims: (usize, usize),
    rng: &Rng,
) -> Result<()> {
    ckpt.set_metadata("algo", algo);
    ckpt.set_metadata(
        "config",
        &serde_json::to_string(config).map_err(|e| AgentError::Checkpoint(e.to_string()))?,
    );
    ckpt.set_metadata("dims", &format!("{} {}", dims.0, dims.1));
    ckpt.put_json("rng", rng)?;
    Ok(())
}

/// Checks that a checkpoint belongs to `algo` with the same dimensions and returns the saved
/// generator.
pub(crate) fn check_header(ckpt: &Checkpoint, algo: &str, dims: (usize, usize)) -> Result<Rng> {
    match ckpt.metadata("algo") {
        Some(a) if a == algo => {}
        Some(a) => {
            return Err(AgentError::Checkpoint(format!(
                "written by a `{a}` agent, cannot load into `{algo}`"
            )))
        }
        None => {
            return Err(AgentError::Checkpoint(
                "has no `algo` metadata: not an agent checkpoint".into(),
            ))
        }
    }
    let want = format!("{} {}", dims.0, dims.1);
    match ckpt.metadata("dims") {
        Some(d) if d == want => {}
        d => {
            return Err(AgentError::Checkpoint(format!(
                "observation/action dimensions {} differ from this agent's {want}",
                d.unwrap_or("(missing)")
            )))
        }
    }
    Ok(ckpt.get_json("rng")?)
}

/// `dst[i, :] = [a[i, :], b[i, :]]` for row-major `a` (`n x da`) and `b` (`n x db`).
pub(crate) fn concat_rows(a: &[f32], da: usize, b: &[f32], db: usize, dst: &mut [f32]) {
    for ((d, x), y) in dst
        .chunks_exact_mut(da + db)
        .zip(a.chunks_exact(da))
        .zip(b.chunks_exact(db))
    {
        d[..da].copy_from_slice(x);
        d[da..].copy_from_slice(y);
    }
}

/// Resizes `v` to `n` (reuses the allocation when large enough).
pub(crate) fn fit(v: &mut Vec<f32>, n: usize) {
    if v.len() != n {
        v.resize(n, 0.0);
    }
}
