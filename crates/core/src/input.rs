//! Bounded reading of input files: [`read_capped`] and the caps the command line uses.
//!
//! Every file a user names (configs, states, actions, scenes) is read through [`read_capped`], so
//! a huge file or an endless stream (`/dev/zero`, a pipe that never closes) is refused after
//! `cap + 1` bytes instead of filling memory.

use std::io::{self, Read};
use std::path::Path;

/// Largest configuration file accepted (1 MiB): `--config` of `tandem train` and of the studies,
/// a run directory's `config.toml`. Real ones are a few kilobytes.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Largest data file accepted (64 MiB): states, action sequences (`tandem env replay --state`,
/// `--actions`, also from stdin; `tandem urdf eval --states`) and MJCF scenes, as the URDF
/// loader's limit. A 1000-step episode of 100-dimensional actions is about 2 MiB of JSON.
pub const MAX_INPUT_BYTES: u64 = 64 << 20;

/// Reads `reader` to the end as UTF-8 text, refusing more than `cap` bytes.
///
/// At most `cap + 1` bytes are read. Too much input is an error of kind
/// [`io::ErrorKind::FileTooLarge`] whose message states the cap; callers add the file's name
/// (their I/O errors already carry it).
///
/// ```
/// use tandem_core::read_capped;
///
/// assert_eq!(read_capped(&b"[1, 2]"[..], 6).unwrap(), "[1, 2]");
/// let err = read_capped(&b"[1, 2]"[..], 5).unwrap_err();
/// assert_eq!(err.kind(), std::io::ErrorKind::FileTooLarge);
/// assert!(err.to_string().contains("5 bytes"));
/// ```
pub fn read_capped(reader: impl Read, cap: u64) -> io::Result<String> {
    let mut bytes = Vec::new();
    reader.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(io::Error::new(
            io::ErrorKind::FileTooLarge,
            format!("larger than the limit of {}", show_bytes(cap)),
        ));
    }
    String::from_utf8(bytes)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("not UTF-8 text: {e}")))
}

/// [`read_capped`] of the file at `path`.
pub fn read_file_capped(path: &Path, cap: u64) -> io::Result<String> {
    read_capped(std::fs::File::open(path)?, cap)
}

/// `cap` in bytes, with MiB or KiB when it is a whole number of them.
fn show_bytes(cap: u64) -> String {
    match cap {
        c if c >= 1 << 20 && c % (1 << 20) == 0 => format!("{} MiB ({c} bytes)", c >> 20),
        c if c >= 1 << 10 && c % (1 << 10) == 0 => format!("{} KiB ({c} bytes)", c >> 10),
        c => format!("{c} bytes"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_stream_is_refused_after_the_cap() {
        let err = read_capped(io::repeat(b'x'), MAX_CONFIG_BYTES).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::FileTooLarge);
        assert!(err.to_string().contains("1 MiB (1048576 bytes)"), "{err}");
    }

    #[test]
    fn input_at_the_cap_is_read_whole() {
        let text = "a".repeat(2048);
        assert_eq!(read_capped(text.as_bytes(), 2048).unwrap(), text);
        let err = read_capped(text.as_bytes(), 2047).unwrap_err();
        assert!(err.to_string().contains("2047 bytes"), "{err}");
    }

    #[test]
    fn missing_files_and_binary_data_are_errors() {
        let missing = read_file_capped(Path::new("/nonexistent/tandem"), 10).unwrap_err();
        assert_eq!(missing.kind(), io::ErrorKind::NotFound);
        let binary = read_capped(&[0xff, 0xfe][..], 10).unwrap_err();
        assert_eq!(binary.kind(), io::ErrorKind::InvalidData);
    }
}
