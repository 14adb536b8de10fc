//! Run directories: `runs/<env>__<algo>__<seed>__<time>/` (CleanRL's naming) holding the config a
//! run used, metrics as CSV, a summary as JSON and learning curves as SVG, written by hand (a few
//! lines of SVG need no plotting library).
//!
//! No run is overwritten or shared by accident ([`RunDir::create`]): a directory that already
//! holds files is an error unless the caller passes [`Existing::Overwrite`] or
//! [`Existing::Resume`], a lock file holding the writer's process id stops a second writer, and
//! default names are made unique.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::IoOp;

/// `YYYYMMDD-HHMMSS` in UTC for seconds since the Unix epoch (Howard Hinnant's civil-from-days).
pub fn utc_stamp(unix_seconds: u64) -> String {
    let days = (unix_seconds / 86_400) as i64;
    let secs = unix_seconds % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        secs / 3600,
        (secs / 60) % 60,
        secs % 60
    )
}

/// What to do when the output directory already holds a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    /// Refuse: a directory that holds files is an error (the default, so no run is overwritten
    /// by accident).
    Refuse,
    /// `--overwrite`: delete the files and folders this kind of run writes, then write anew.
    Overwrite,
    /// `--resume`: continue the run in place; its files are rewritten.
    Resume,
}

/// Why a run directory could not be made ready.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// The directory already holds a run (or other files) and neither `--overwrite` nor
    /// `--resume` was given.
    #[error(
        "{} already holds a run ({}); pass --overwrite to replace it{}, or choose another --out",
        path.display(), entries.join(", "), if *resumable { " or --resume to continue it" } else { "" }
    )]
    Exists {
        /// The directory.
        path: PathBuf,
        /// Up to a few of the entries found there.
        entries: Vec<String>,
        /// Whether the command has a `--resume`.
        resumable: bool,
    },
    /// `--overwrite` on a directory holding files that this kind of run does not write.
    #[error(
        "{} holds files a run does not write ({}); --overwrite only replaces a run's own files: \
         choose another --out",
        path.display(), entries.join(", ")
    )]
    Foreign {
        /// The directory.
        path: PathBuf,
        /// The entries that are not the run's.
        entries: Vec<String>,
    },
    /// Another process holds the directory's lock.
    #[error(
        "{} is in use by process {pid} (lock file {}); wait for it to finish or choose another --out",
        path.display(), lock.display()
    )]
    Locked {
        /// The directory.
        path: PathBuf,
        /// The lock file.
        lock: PathBuf,
        /// The process that holds it.
        pid: u32,
    },
    /// The lock was left by a process that is no longer running (a killed run).
    #[error(
        "{} has a stale lock: process {pid}, which wrote {}, is no longer running (the run was \
         interrupted); pass --overwrite{} to take the directory over, or delete the lock file",
        path.display(), lock.display(), if *resumable { " or --resume" } else { "" }
    )]
    StaleLock {
        /// The directory.
        path: PathBuf,
        /// The lock file.
        lock: PathBuf,
        /// The process that wrote it.
        pid: u32,
        /// Whether the command has a `--resume`.
        resumable: bool,
    },
    /// A file-system operation failed.
    #[error("cannot {op} {}: {source}", path.display())]
    Io {
        /// What was being done.
        op: IoOp,
        /// The file or directory.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
}

/// Whether `name` is a temporary file left by an interrupted atomic write
/// ([`tandem_nn::write_atomic`] writes `.<name>.tmp` before renaming): part of the run, removed
/// by `--overwrite`.
fn is_partial_write(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".tmp")
}

/// The lock file's name inside a run directory: it holds the writer's process id.
pub const LOCK_FILE: &str = ".tandem.lock";

/// What a kind of run writes into its directory, so that `--overwrite` removes exactly that.
#[derive(Debug, Clone, Copy)]
pub struct Layout {
    /// The files and folders the run writes (a folder is removed with its contents).
    pub owned: &'static [&'static str],
    /// Whether the command has a `--resume` (named in error messages).
    pub resumable: bool,
}

/// A directory that a run writes its files into. While this value lives, the directory's lock
/// file stops a second `tandem` from writing there; dropping it removes the lock.
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    lock: PathBuf,
    stale_lock: Option<u32>,
}

/// Whether process `pid` is running. On Linux `/proc/<pid>` tells; elsewhere it cannot be told
/// without a system call, so the process is assumed alive (the lock is then reported, never
/// taken over).
fn process_alive(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.is_dir() || proc.join(pid.to_string()).exists()
}

impl RunDir {
    /// Prepares the directory a run writes into and locks it.
    ///
    /// With `out`, that directory: created if missing; if it already holds files, `existing`
    /// decides (an error, removing the run's own files per `layout`, or continuing in place).
    /// Without `out`, a new `runs/<name>__<YYYYMMDD-HHMMSS>/` (CleanRL's naming), with `-2`,
    /// `-3`, ... appended when a run started in the same second took that name: the directory
    /// is created exclusively, so two runs never share one.
    pub fn create(
        out: Option<&Path>,
        name: &str,
        layout: Layout,
        existing: Existing,
    ) -> Result<Self, RunDirError> {
        let io = |op: IoOp, path: &Path| {
            let path = path.to_path_buf();
            move |source| RunDirError::Io { op, path, source }
        };
        let Some(out) = out else {
            let root = Path::new("runs");
            std::fs::create_dir_all(root).map_err(io(IoOp::Create, root))?;
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0);
            let base = format!("{name}__{}", utc_stamp(now));
            for k in 1u32.. {
                let path = if k == 1 {
                    root.join(&base)
                } else {
                    root.join(format!("{base}-{k}"))
                };
                match std::fs::create_dir(&path) {
                    Ok(()) => return Self::lock(path, layout, Existing::Refuse),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return Err(io(IoOp::Create, &path)(e)),
                }
            }
            unreachable!("some suffix is free");
        };
        std::fs::create_dir_all(out).map_err(io(IoOp::Create, out))?;
        let dir = Self::lock(out.to_path_buf(), layout, existing)?;
        let mut entries: Vec<String> = std::fs::read_dir(out)
            .map_err(io(IoOp::Read, out))?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != LOCK_FILE)
            .collect();
        entries.sort();
        if entries.is_empty() || existing == Existing::Resume {
            return Ok(dir);
        }
        if existing == Existing::Refuse {
            entries.truncate(5);
            return Err(RunDirError::Exists {
                path: out.to_path_buf(),
                entries,
                resumable: layout.resumable,
            });
        }
        let foreign: Vec<String> = entries
            .iter()
            .filter(|n| !layout.owned.contains(&n.as_str()) && !is_partial_write(n))
            .cloned()
            .collect();
        if !foreign.is_empty() {
            return Err(RunDirError::Foreign {
                path: out.to_path_buf(),
                entries: foreign,
            });
        }
        for n in &entries {
            let p = out.join(n);
            let r = if p.is_dir() {
                std::fs::remove_dir_all(&p)
            } else {
                std::fs::remove_file(&p)
            };
            r.map_err(io(IoOp::Remove, &p))?;
        }
        Ok(dir)
    }

    /// Takes `path`'s lock: creates the lock file exclusively and writes this process's id.
    fn lock(path: PathBuf, layout: Layout, existing: Existing) -> Result<Self, RunDirError> {
        use std::io::Write as _;
        let lock = path.join(LOCK_FILE);
        let mut stale_lock = None;
        loop {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&lock)
            {
                Ok(mut f) => {
                    // From here on, dropping `dir` removes the lock.
                    let dir = Self {
                        path,
                        lock,
                        stale_lock,
                    };
                    writeln!(f, "{}", std::process::id()).map_err(|source| RunDirError::Io {
                        op: IoOp::Write,
                        path: dir.lock.clone(),
                        source,
                    })?;
                    return Ok(dir);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let text = std::fs::read_to_string(&lock).unwrap_or_default();
                    // An empty lock is one being written right now: in use.
                    let pid: u32 = text.trim().parse().unwrap_or(0);
                    if pid == 0 || process_alive(pid) {
                        return Err(RunDirError::Locked { path, lock, pid });
                    }
                    if existing == Existing::Refuse || stale_lock.is_some() {
                        return Err(RunDirError::StaleLock {
                            path,
                            lock,
                            pid,
                            resumable: layout.resumable,
                        });
                    }
                    std::fs::remove_file(&lock).map_err(|source| RunDirError::Io {
                        op: IoOp::Remove,
                        path: lock.clone(),
                        source,
                    })?;
                    stale_lock = Some(pid);
                }
                Err(source) => {
                    return Err(RunDirError::Io {
                        op: IoOp::Create,
                        path: lock,
                        source,
                    })
                }
            }
        }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The process id of a stale lock (left by a run that was killed) that `--overwrite` or
    /// `--resume` removed, for the program to report.
    pub fn stale_lock_taken_over(&self) -> Option<u32> {
        self.stale_lock
    }

    /// Writes `contents` to `name` inside the directory, atomically (a crash leaves the previous
    /// file or the new one, never a half-written one), and returns the file's path.
    pub fn write(&self, name: &str, contents: &str) -> std::io::Result<PathBuf> {
        let p = self.path.join(name);
        tandem_nn::write_atomic(&p, contents.as_bytes())?;
        Ok(p)
    }
}

impl Drop for RunDir {
    /// Removes the lock, if it is still this process's.
    fn drop(&mut self) {
        let ours = std::fs::read_to_string(&self.lock)
            .is_ok_and(|t| t.trim() == std::process::id().to_string());
        if ours {
            let _ = std::fs::remove_file(&self.lock);
        }
    }
}

/// A CSV table: a header line, then one line per row; numbers in Rust's shortest round-trip form
/// (empty cell for NaN, meaning "not reported").
pub fn csv(header: &[&str], rows: &[Vec<f64>]) -> String {
    let mut s = header.join(",");
    s.push('\n');
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .map(|v| {
                if v.is_nan() {
                    String::new()
                } else {
                    format!("{v}")
                }
            })
            .collect();
        s.push_str(&cells.join(","));
        s.push('\n');
    }
    s
}

/// One line of a chart: a name and its points.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// `(x, y)` points, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// Optional `(x, low, high)` band drawn behind the line (e.g. mean ± std).
    pub band: Vec<(f64, f64, f64)>,
}

fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / n as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    // Each tick is k · step rounded to the step's decimals, so that labels read 0.6, not
    // 0.6000000000000001 (no sum of steps, no accumulated rounding).
    let scale = 10f64.powi((-step.log10().floor()).max(0.0) as i32);
    let first = (lo / step).ceil() as i64;
    let mut out = Vec::new();
    for k in first.. {
        let t = ((k as f64 * step) * scale).round() / scale;
        if t > hi + 1e-9 * span {
            break;
        }
        out.push(if t.abs() < 1e-12 * span { 0.0 } else { t });
    }
    out
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A small SVG line chart (640x400) with axes, ticks, a legend and optional bands.
pub fn svg_chart(title: &str, x_label: &str, y_label: &str, series: &[Series]) -> String {
    const W: f64 = 640.0;
    const H: f64 = 400.0;
    const L: f64 = 70.0;
    const R: f64 = 20.0;
    const T: f64 = 40.0;
    const B: f64 = 50.0;
    let colors = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd"];
    let xs = series.iter().flat_map(|s| {
        s.points
            .iter()
            .map(|p| p.0)
            .chain(s.band.iter().map(|b| b.0))
    });
    let ys = series.iter().flat_map(|s| {
        s.points
            .iter()
            .map(|p| p.1)
            .chain(s.band.iter().flat_map(|b| [b.1, b.2]))
    });
    let fin = |v: &f64| v.is_finite();
    let (mut x0, mut x1) = xs
        .filter(fin)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (mut y0, mut y1) = ys
        .filter(fin)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y0 -= 1.0;
        y1 += 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let px = |x: f64| L + (x - x0) / (x1 - x0) * (W - L - R);
    let py = |y: f64| H - B - (y - y0) / (y1 - y0) * (H - T - B);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="24" text-anchor="middle" font-size="15">{}</text>"#,
        W / 2.0,
        escape(title)
    );
    for t in nice_ticks(x0, x1, 6) {
        let x = px(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{T}" x2="{x:.1}" y2="{}" stroke="#eee"/>"##,
            H - B
        );
        let _ = writeln!(
            s,
            r#"<text x="{x:.1}" y="{}" text-anchor="middle">{t}</text>"#,
            H - B + 16.0
        );
    }
    for t in nice_ticks(y0, y1, 6) {
        let y = py(t);
        let _ = writeln!(
            s,
            r##"<line x1="{L}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#eee"/>"##,
            W - R
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{:.1}" text-anchor="end">{t}</text>"#,
            L - 6.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        s,
        r#"<rect x="{L}" y="{T}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        W - L - R,
        H - T - B
    );
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        (L + W - R) / 2.0,
        H - 12.0,
        escape(x_label)
    );
    let _ = writeln!(
        s,
        r#"<text x="16" y="{0}" text-anchor="middle" transform="rotate(-90 16 {0})">{1}</text>"#,
        (T + H - B) / 2.0,
        escape(y_label)
    );
    for (i, se) in series.iter().enumerate() {
        let c = colors[i % colors.len()];
        let band: Vec<&(f64, f64, f64)> = se
            .band
            .iter()
            .filter(|b| b.1.is_finite() && b.2.is_finite())
            .collect();
        if band.len() > 1 {
            let mut d = String::new();
            for b in &band {
                let _ = write!(d, "{:.1},{:.1} ", px(b.0), py(b.2));
            }
            for b in band.iter().rev() {
                let _ = write!(d, "{:.1},{:.1} ", px(b.0), py(b.1));
            }
            let _ = writeln!(
                s,
                r#"<polygon points="{}" fill="{c}" fill-opacity="0.15" stroke="none"/>"#,
                d.trim()
            );
        }
        let mut d = String::new();
        for p in se
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
        {
            let _ = write!(d, "{:.1},{:.1} ", px(p.0), py(p.1));
        }
        let _ = writeln!(
            s,
            r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="1.5"/>"#,
            d.trim()
        );
        let ly = T + 16.0 + 16.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{}" y1="{ly}" x2="{}" y2="{ly}" stroke="{c}" stroke-width="2"/>"#,
            L + 10.0,
            L + 30.0
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}">{}</text>"#,
            L + 36.0,
            ly + 4.0,
            escape(&se.name)
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_numbers() {
        let labels: Vec<String> = nice_ticks(0.4, 1.05, 6)
            .iter()
            .map(|t| t.to_string())
            .collect();
        assert_eq!(labels, ["0.4", "0.6", "0.8", "1"]);
        let labels: Vec<String> = nice_ticks(-0.35, 0.2, 6)
            .iter()
            .map(|t| t.to_string())
            .collect();
        assert_eq!(labels, ["-0.3", "-0.2", "-0.1", "0", "0.1", "0.2"]);
        assert_eq!(nice_ticks(0.0, 400.0, 6), [0.0, 100.0, 200.0, 300.0, 400.0]);
    }

    #[test]
    fn utc_stamp_matches_known_dates() {
        assert_eq!(utc_stamp(0), "19700101-000000");
        // 2000-02-29 12:34:56 UTC = 951827696.
        assert_eq!(utc_stamp(951_827_696), "20000229-123456");
    }

    const LAYOUT: Layout = Layout {
        owned: &["table.json", "runs"],
        resumable: false,
    };

    /// A fresh directory holding an earlier 5-seed reproduction: a table and seed folders.
    fn earlier_run(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("tandem-run-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("runs/cold__seed4")).unwrap();
        std::fs::write(d.join("runs/cold__seed4/curve.csv"), "x").unwrap();
        std::fs::write(d.join("table.json"), "{}").unwrap();
        // A write that a second signal cut short.
        std::fs::write(d.join(".table.json.tmp"), "{").unwrap();
        d
    }

    #[test]
    fn an_earlier_run_is_refused_kept_or_cleared_and_the_lock_lives_with_the_value() {
        let d = earlier_run("modes");
        let e = RunDir::create(Some(&d), "x", LAYOUT, Existing::Refuse).unwrap_err();
        assert!(
            matches!(&e, RunDirError::Exists { entries, .. } if entries == &[".table.json.tmp", "runs", "table.json"])
        );
        assert!(!e.to_string().contains("--resume"), "{e}");
        assert!(d.join("runs/cold__seed4").exists() && !d.join(LOCK_FILE).exists());

        let dir = RunDir::create(Some(&d), "x", LAYOUT, Existing::Resume).unwrap();
        assert!(d.join("runs/cold__seed4").exists());
        let pid = std::fs::read_to_string(d.join(LOCK_FILE)).unwrap();
        assert_eq!(pid.trim(), std::process::id().to_string());
        // A second writer while the first holds the lock.
        let e = RunDir::create(Some(&d), "x", LAYOUT, Existing::Overwrite).unwrap_err();
        assert!(matches!(e, RunDirError::Locked { pid, .. } if pid == std::process::id()));
        drop(dir);
        assert!(!d.join(LOCK_FILE).exists());

        // Overwrite: the stale seed folders and the partial write go with the table.
        let dir = RunDir::create(Some(&d), "x", LAYOUT, Existing::Overwrite).unwrap();
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, [LOCK_FILE]);
        assert_eq!(dir.stale_lock_taken_over(), None);
        drop(dir);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn csv_and_svg_are_well_formed() {
        let c = csv(&["a", "b"], &[vec![1.0, f64::NAN], vec![0.5, -2.0]]);
        assert_eq!(c, "a,b\n1,\n0.5,-2\n");
        let s = svg_chart(
            "t <1>",
            "steps",
            "return",
            &[Series {
                name: "eval".into(),
                points: vec![(0.0, -1000.0), (1000.0, -150.0)],
                band: vec![(0.0, -1100.0, -900.0), (1000.0, -160.0, -140.0)],
            }],
        );
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        assert!(s.contains("t &lt;1&gt;") && s.contains("<polyline") && s.contains("<polygon"));
        assert_eq!(
            nice_ticks(0.0, 1000.0, 5),
            vec![0.0, 200.0, 400.0, 600.0, 800.0, 1000.0]
        );
    }
}
