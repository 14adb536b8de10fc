//! Checkpoints in the safetensors format: named tensors (f32, f64, u64, raw bytes) plus string
//! metadata, written and read bit-exactly (little-endian, as the format prescribes).
//!
//! A [`Checkpoint`] is an in-memory collection; components implement [`Checkpointable`] to put
//! their state under a name prefix (`"actor"`, `"critic1"`, `"critic1_opt"`, ...), so one file
//! holds a whole agent. The files are ordinary safetensors: candle (`candle_core::safetensors::load`)
//! and Python's `safetensors` read them too.
//!
//! ```
//! use tandem_nn::{Checkpoint, Checkpointable, Mlp, MlpConfig};
//! use tandem_core::seeding::rng_from_seed;
//!
//! let net = Mlp::new(MlpConfig::new(&[3, 8, 1]), &mut rng_from_seed(0)).unwrap();
//! let mut ckpt = Checkpoint::new();
//! net.save_to("critic", &mut ckpt).unwrap();
//! let bytes = ckpt.to_bytes().unwrap();
//!
//! let mut other = Mlp::zeros(MlpConfig::new(&[3, 8, 1])).unwrap();
//! other.load_from("critic", &Checkpoint::from_bytes(&bytes).unwrap()).unwrap();
//! assert_eq!(net.params(), other.params());
//!
//! // Another architecture is an error naming the tensor.
//! let mut wrong = Mlp::zeros(MlpConfig::new(&[3, 16, 1])).unwrap();
//! let err = wrong.load_from("critic", &Checkpoint::from_bytes(&bytes).unwrap()).unwrap_err();
//! assert!(err.to_string().contains("critic.layers.0.weight"));
//! ```

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use safetensors::tensor::{Dtype, TensorView};

use crate::error::{NnError, Result};

/// Something whose state can be stored in and restored from a [`Checkpoint`].
pub trait Checkpointable {
    /// Puts the state under names starting with `prefix`.
    fn save_to(&self, prefix: &str, ckpt: &mut Checkpoint) -> Result<()>;
    /// Restores the state saved under `prefix`. Errors (missing tensor, shape mismatch naming the
    /// tensor) leave `self` unchanged.
    fn load_from(&mut self, prefix: &str, ckpt: &Checkpoint) -> Result<()>;
}

#[derive(Debug, Clone, PartialEq)]
struct Entry {
    dtype: Dtype,
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

/// An in-memory set of named tensors and metadata that (de)serializes to safetensors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Checkpoint {
    tensors: BTreeMap<String, Entry>,
    metadata: BTreeMap<String, String>,
}

fn numel(shape: &[usize]) -> usize {
    shape.iter().product()
}

fn shape_str(shape: &[usize]) -> String {
    format!("{shape:?}")
}

impl Checkpoint {
    /// An empty checkpoint.
    pub fn new() -> Self {
        Self::default()
    }

    fn put(
        &mut self,
        name: &str,
        dtype: Dtype,
        shape: &[usize],
        n: usize,
        bytes: Vec<u8>,
    ) -> Result<()> {
        if numel(shape) != n {
            return Err(NnError::ShapeMismatch {
                what: name.to_string(),
                expected: format!("{} elements for shape {}", numel(shape), shape_str(shape)),
                got: format!("{n} elements"),
            });
        }
        self.tensors.insert(
            name.to_string(),
            Entry {
                dtype,
                shape: shape.to_vec(),
                bytes,
            },
        );
        Ok(())
    }

    /// Stores an f32 tensor (replacing one of the same name).
    pub fn put_f32(&mut self, name: &str, shape: &[usize], data: &[f32]) -> Result<()> {
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.put(name, Dtype::F32, shape, data.len(), bytes)
    }

    /// Stores an f64 tensor.
    pub fn put_f64(&mut self, name: &str, shape: &[usize], data: &[f64]) -> Result<()> {
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.put(name, Dtype::F64, shape, data.len(), bytes)
    }

    /// Stores a u64 tensor (step counters, indices).
    pub fn put_u64(&mut self, name: &str, shape: &[usize], data: &[u64]) -> Result<()> {
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.put(name, Dtype::U64, shape, data.len(), bytes)
    }

    /// Stores raw bytes as a 1-D u8 tensor.
    pub fn put_bytes(&mut self, name: &str, data: &[u8]) -> Result<()> {
        self.put(name, Dtype::U8, &[data.len()], data.len(), data.to_vec())
    }

    /// Stores any serde value as JSON bytes (e.g. an RNG state, a config).
    pub fn put_json<T: serde::Serialize>(&mut self, name: &str, value: &T) -> Result<()> {
        let bytes = serde_json::to_vec(value)
            .map_err(|e| NnError::Checkpoint(format!("serializing `{name}`: {e}")))?;
        self.put_bytes(name, &bytes)
    }

    /// Sets a metadata string (stored in the safetensors header).
    pub fn set_metadata(&mut self, key: &str, value: &str) {
        self.metadata.insert(key.to_string(), value.to_string());
    }

    /// A metadata string, if present.
    pub fn metadata(&self, key: &str) -> Option<&str> {
        self.metadata.get(key).map(String::as_str)
    }

    /// Whether a tensor called `name` exists.
    pub fn contains(&self, name: &str) -> bool {
        self.tensors.contains_key(name)
    }

    /// All tensor names, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// The shape of tensor `name`.
    pub fn shape(&self, name: &str) -> Result<&[usize]> {
        Ok(&self.entry(name)?.shape)
    }

    fn entry(&self, name: &str) -> Result<&Entry> {
        self.tensors
            .get(name)
            .ok_or_else(|| NnError::MissingTensor(name.to_string()))
    }

    fn checked(&self, name: &str, dtype: Dtype, shape: Option<&[usize]>) -> Result<&Entry> {
        let e = self.entry(name)?;
        if e.dtype != dtype {
            return Err(NnError::ShapeMismatch {
                what: name.to_string(),
                expected: format!("dtype {dtype:?}"),
                got: format!("dtype {:?}", e.dtype),
            });
        }
        if let Some(shape) = shape {
            if e.shape != shape {
                return Err(NnError::ShapeMismatch {
                    what: name.to_string(),
                    expected: shape_str(shape),
                    got: shape_str(&e.shape),
                });
            }
        }
        Ok(e)
    }

    /// Reads an f32 tensor, checking its shape when `shape` is given.
    pub fn get_f32(&self, name: &str, shape: Option<&[usize]>) -> Result<Vec<f32>> {
        let e = self.checked(name, Dtype::F32, shape)?;
        Ok(e.bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }

    /// Reads an f32 tensor of exactly `shape` into `out` (whose length must match).
    pub fn read_f32_into(&self, name: &str, shape: &[usize], out: &mut [f32]) -> Result<()> {
        let e = self.checked(name, Dtype::F32, Some(shape))?;
        if out.len() != numel(shape) {
            return Err(NnError::ShapeMismatch {
                what: name.to_string(),
                expected: format!("destination of {} elements", numel(shape)),
                got: format!("{} elements", out.len()),
            });
        }
        for (o, c) in out.iter_mut().zip(e.bytes.chunks_exact(4)) {
            *o = f32::from_le_bytes(c.try_into().expect("4 bytes"));
        }
        Ok(())
    }

    /// Reads an f64 tensor, checking its shape when `shape` is given.
    pub fn get_f64(&self, name: &str, shape: Option<&[usize]>) -> Result<Vec<f64>> {
        let e = self.checked(name, Dtype::F64, shape)?;
        Ok(e.bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }

    /// Reads a u64 tensor, checking its shape when `shape` is given.
    pub fn get_u64(&self, name: &str, shape: Option<&[usize]>) -> Result<Vec<u64>> {
        let e = self.checked(name, Dtype::U64, shape)?;
        Ok(e.bytes
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }

    /// Reads raw bytes stored by [`Checkpoint::put_bytes`].
    pub fn get_bytes(&self, name: &str) -> Result<&[u8]> {
        Ok(&self.checked(name, Dtype::U8, None)?.bytes)
    }

    /// Reads a serde value stored by [`Checkpoint::put_json`].
    pub fn get_json<T: serde::de::DeserializeOwned>(&self, name: &str) -> Result<T> {
        serde_json::from_slice(self.get_bytes(name)?)
            .map_err(|e| NnError::Checkpoint(format!("decoding `{name}`: {e}")))
    }

    /// Serializes to safetensors bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let mut views = Vec::with_capacity(self.tensors.len());
        for (name, e) in &self.tensors {
            let view = TensorView::new(e.dtype, e.shape.clone(), &e.bytes)
                .map_err(|err| NnError::Checkpoint(format!("tensor `{name}`: {err}")))?;
            views.push((name.clone(), view));
        }
        let meta: Option<HashMap<String, String>> = if self.metadata.is_empty() {
            None
        } else {
            Some(self.metadata.clone().into_iter().collect())
        };
        safetensors::serialize(views, meta).map_err(|e| NnError::Checkpoint(e.to_string()))
    }

    /// Parses safetensors bytes (any dtype is kept as stored; the typed getters check it).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let st = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| NnError::Checkpoint(format!("not a safetensors file: {e}")))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| NnError::Checkpoint(format!("not a safetensors file: {e}")))?;
        let mut ckpt = Checkpoint::new();
        for (name, view) in st.tensors() {
            ckpt.tensors.insert(
                name,
                Entry {
                    dtype: view.dtype(),
                    shape: view.shape().to_vec(),
                    bytes: view.data().to_vec(),
                },
            );
        }
        if let Some(m) = header.metadata() {
            ckpt.metadata = m.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        }
        Ok(ckpt)
    }

    /// Writes a safetensors file (via a temporary file and rename, so a crash never leaves a
    /// half-written checkpoint under `path`).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let bytes = self.to_bytes()?;
        let tmp = path.with_extension("safetensors.tmp");
        std::fs::write(&tmp, &bytes)
            .and_then(|_| std::fs::rename(&tmp, path))
            .map_err(|e| NnError::Checkpoint(format!("writing {}: {e}", path.display())))
    }

    /// Reads a safetensors file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path)
            .map_err(|e| NnError::Checkpoint(format!("reading {}: {e}", path.display())))?;
        Self::from_bytes(&bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_bit_exact_for_all_dtypes() {
        let mut c = Checkpoint::new();
        let f = [1.0f32, -0.0, f32::MIN_POSITIVE, 1e-45, 3.4e38, 0.1];
        let d = [0.1f64, -2.5e-300, 7.0];
        c.put_f32("a.f", &[2, 3], &f).unwrap();
        c.put_f64("a.d", &[3], &d).unwrap();
        c.put_u64("a.t", &[1], &[u64::MAX]).unwrap();
        c.put_bytes("a.b", b"hello").unwrap();
        c.put_json("a.j", &vec![1u32, 2, 3]).unwrap();
        c.set_metadata("format", "tandem-v1");
        let back = Checkpoint::from_bytes(&c.to_bytes().unwrap()).unwrap();
        assert_eq!(back, c);
        let f2 = back.get_f32("a.f", Some(&[2, 3])).unwrap();
        assert!(f.iter().zip(&f2).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert_eq!(back.get_u64("a.t", None).unwrap(), vec![u64::MAX]);
        assert_eq!(back.get_json::<Vec<u32>>("a.j").unwrap(), vec![1, 2, 3]);
        assert_eq!(back.metadata("format"), Some("tandem-v1"));
    }

    #[test]
    fn wrong_shape_dtype_or_name_is_an_error_naming_the_tensor() {
        let mut c = Checkpoint::new();
        assert!(c.put_f32("x", &[2, 2], &[1.0; 3]).is_err());
        c.put_f32("x", &[2, 2], &[1.0; 4]).unwrap();
        let e = c.get_f32("x", Some(&[4])).unwrap_err();
        assert!(matches!(e, NnError::ShapeMismatch { ref what, .. } if what == "x"));
        assert!(c.get_f64("x", None).is_err());
        assert_eq!(
            c.get_f32("y", None).unwrap_err(),
            NnError::MissingTensor("y".into())
        );
        assert!(Checkpoint::from_bytes(b"garbage").is_err());
    }

    #[test]
    fn file_round_trip() {
        let dir = std::env::temp_dir().join(format!("tandem-nn-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.safetensors");
        let mut c = Checkpoint::new();
        c.put_f32("w", &[3], &[1.5, -2.0, 0.25]).unwrap();
        c.save(&path).unwrap();
        assert_eq!(Checkpoint::load(&path).unwrap(), c);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
