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

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;

use safetensors::tensor::Dtype;

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

/// The metadata key holding a checkpoint's CRC-32 (8 hex digits), written by
/// [`Checkpoint::to_bytes`] and checked by [`Checkpoint::from_bytes`].
pub const CHECKSUM_KEY: &str = "tandem.crc32";

/// Writes `bytes` to `path` atomically (temporary file in the same directory, `fsync`, rename,
/// directory `fsync`); on any error the temporary file is removed and `path` is untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("the path names no file"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    // Make the rename itself durable; a directory that cannot be opened for syncing (some
    // platforms) does not make the write fail.
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

fn dtype_size(dtype: Dtype) -> Result<usize> {
    match dtype {
        Dtype::U8 | Dtype::I8 | Dtype::BOOL => Ok(1),
        Dtype::F16 | Dtype::BF16 | Dtype::I16 | Dtype::U16 => Ok(2),
        Dtype::F32 | Dtype::I32 | Dtype::U32 => Ok(4),
        Dtype::F64 | Dtype::I64 | Dtype::U64 => Ok(8),
        other => Err(NnError::Checkpoint(format!(
            "dtype {other:?} is not supported in checkpoints"
        ))),
    }
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

    /// Serializes to safetensors bytes, deterministically: tensors in name order, metadata keys
    /// sorted, and a CRC-32 of everything else stored under the metadata key [`CHECKSUM_KEY`]
    /// (so equal checkpoints are equal bytes, and [`Checkpoint::from_bytes`] detects any changed
    /// byte).
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let mut sealed = self.clone();
        sealed.metadata.remove(CHECKSUM_KEY);
        let body = sealed.canonical_bytes()?;
        let crc = crc32fast::hash(&body);
        sealed
            .metadata
            .insert(CHECKSUM_KEY.to_string(), format!("{crc:08x}"));
        sealed.canonical_bytes()
    }

    /// The safetensors layout written by hand (the format is an 8-byte little-endian header
    /// length, a JSON header padded with spaces to a multiple of 8 bytes, then the tensors'
    /// bytes back to back), so that the header's order never depends on a hash map's.
    fn canonical_bytes(&self) -> Result<Vec<u8>> {
        let json = |s: &str| serde_json::to_string(s).expect("a string serializes");
        let mut header = String::from("{");
        let mut first = true;
        let mut sep = |header: &mut String| {
            if !std::mem::take(&mut first) {
                header.push(',');
            }
        };
        if !self.metadata.is_empty() {
            sep(&mut header);
            header.push_str("\"__metadata__\":{");
            for (i, (k, v)) in self.metadata.iter().enumerate() {
                if i > 0 {
                    header.push(',');
                }
                header.push_str(&format!("{}:{}", json(k), json(v)));
            }
            header.push('}');
        }
        let mut offset = 0usize;
        for (name, e) in &self.tensors {
            if e.bytes.len() != numel(&e.shape) * dtype_size(e.dtype)? {
                return Err(NnError::Checkpoint(format!(
                    "tensor `{name}`: {} bytes for shape {}",
                    e.bytes.len(),
                    shape_str(&e.shape)
                )));
            }
            sep(&mut header);
            let end = offset + e.bytes.len();
            header.push_str(&format!(
                "{}:{{\"dtype\":{},\"shape\":{},\"data_offsets\":[{offset},{end}]}}",
                json(name),
                serde_json::to_string(&e.dtype)
                    .map_err(|err| NnError::Checkpoint(err.to_string()))?,
                shape_str(&e.shape).replace(' ', ""),
            ));
            offset = end;
        }
        header.push('}');
        while header.len() % 8 != 0 {
            header.push(' ');
        }
        let mut out = Vec::with_capacity(8 + header.len() + offset);
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        for e in self.tensors.values() {
            out.extend_from_slice(&e.bytes);
        }
        Ok(out)
    }

    /// Parses safetensors bytes (any dtype is kept as stored; the typed getters check it). A
    /// checkpoint written by [`Checkpoint::to_bytes`] carries a checksum, and any changed byte is
    /// an error; files from other writers (no checksum) are read as they are.
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
        if let Some(stored) = ckpt.metadata.remove(CHECKSUM_KEY) {
            let crc = crc32fast::hash(&ckpt.canonical_bytes()?);
            if stored != format!("{crc:08x}") {
                return Err(NnError::Checkpoint(format!(
                    "checksum mismatch (stored {stored}, computed {crc:08x}): the checkpoint is \
                     corrupt or was edited"
                )));
            }
        }
        Ok(ckpt)
    }

    /// Writes a safetensors file atomically: the bytes go to a temporary file beside `path`,
    /// are flushed to disk (`fsync`), and the temporary file is renamed over `path` (then the
    /// directory is synced). A crash or a full disk leaves either the previous file or the new
    /// one under `path`, never a mix, and a failed write removes its temporary file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        write_atomic(path, &self.to_bytes()?)
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
    fn equal_checkpoints_are_equal_bytes_and_any_changed_byte_is_caught() {
        let build = |order: &[(&str, &str)]| {
            let mut c = Checkpoint::new();
            for (k, v) in order {
                c.set_metadata(k, v);
            }
            c.put_f32("w", &[2], &[0.5, -1.0]).unwrap();
            c.put_u64("step", &[1], &[42]).unwrap();
            c.to_bytes().unwrap()
        };
        let a = build(&[("algo", "sac"), ("env", "Pendulum-v1"), ("z", "1")]);
        let b = build(&[("z", "1"), ("env", "Pendulum-v1"), ("algo", "sac")]);
        assert_eq!(a, b);
        // The safetensors crate itself reads the hand-written layout.
        let st = safetensors::SafeTensors::deserialize(&a).unwrap();
        assert_eq!(st.tensor("w").unwrap().shape(), &[2]);
        let back = Checkpoint::from_bytes(&a).unwrap();
        assert_eq!(
            back.metadata(CHECKSUM_KEY),
            None,
            "the checksum is not user metadata"
        );
        assert_eq!(back.to_bytes().unwrap(), a);
        // Flip every bit of the data section, one at a time: the checksum catches each.
        let header_len = u64::from_le_bytes(a[..8].try_into().unwrap()) as usize;
        for i in 8 + header_len..a.len() {
            for bit in 0..8 {
                let mut bad = a.clone();
                bad[i] ^= 1 << bit;
                let err = Checkpoint::from_bytes(&bad).unwrap_err().to_string();
                assert!(
                    err.contains("checksum mismatch"),
                    "byte {i} bit {bit}: {err}"
                );
            }
        }
        // An edited metadata value that still parses is caught too.
        let at = a.windows(11).position(|w| w == b"Pendulum-v1").unwrap();
        let mut edited = a.clone();
        edited[at + 9] = b'2';
        let err = Checkpoint::from_bytes(&edited).unwrap_err().to_string();
        assert!(err.contains("checksum mismatch"), "{err}");
    }

    #[test]
    fn a_failed_save_leaves_no_temporary_file_and_keeps_the_previous_one() {
        let dir = std::env::temp_dir().join(format!("tandem-nn-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut c = Checkpoint::new();
        c.put_f32("w", &[1], &[1.0]).unwrap();
        // A directory in the way: the rename fails after the temporary file was written.
        let blocked = dir.join("ckpt.safetensors");
        std::fs::create_dir_all(blocked.join("inner")).unwrap();
        assert!(c.save(&blocked).is_err());
        let mut names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["ckpt.safetensors"]);
        assert!(blocked.join("inner").is_dir());
        // Saving over an existing checkpoint replaces it whole.
        let path = dir.join("good.safetensors");
        c.save(&path).unwrap();
        c.put_f32("w", &[1], &[2.0]).unwrap();
        c.save(&path).unwrap();
        assert_eq!(Checkpoint::load(&path).unwrap(), c);
        std::fs::remove_dir_all(&dir).unwrap();
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
