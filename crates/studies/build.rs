// The studies' build script: the MuJoCo crate's (with the `mujoco` feature it puts the folder of
// libmujoco on the run path of this crate's tests, which run p4's MuJoCo scenes), then the git
// commit of the workspace, which every study records in its `config.json` (`provenance.rs`):
//
// - `TANDEM_BUILD_COMMIT`: `git rev-parse HEAD`, or `unknown` without git or outside the
//   workspace's own repository (a source tarball, a crate inside another project's repository);
// - `TANDEM_BUILD_DIRTY`: `true` when `git status --porcelain --untracked-files=no` lists a
//   change (or cannot tell), else `false`.
//
// It never fails the build. It reruns when HEAD, the branch it points to or a tracked
// source file of `crates/` changes (the code the studies' numbers come from), not on every build.

#[path = "../mujoco/build.rs"]
mod mujoco;

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    mujoco::main();
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest.join("../..");
    let (commit, dirty) = match workspace_repo(&root) {
        Some(top) => {
            watch(&top);
            match git(&top, &["rev-parse", "--verify", "HEAD"]).filter(|c| is_hash(c)) {
                // `--no-optional-locks`: status must not rewrite the index it watches.
                Some(c) => {
                    let status = git(
                        &top,
                        &[
                            "--no-optional-locks",
                            "status",
                            "--porcelain",
                            "--untracked-files=no",
                        ],
                    );
                    (c, status.is_none_or(|s| !s.is_empty()))
                }
                None => ("unknown".to_string(), false),
            }
        }
        None => ("unknown".to_string(), false),
    };
    println!("cargo::rustc-env=TANDEM_BUILD_COMMIT={commit}");
    println!("cargo::rustc-env=TANDEM_BUILD_DIRTY={dirty}");
}

/// `git -C dir args...`'s trimmed output, or `None` if git is missing or fails.
fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(args)
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    String::from_utf8(out.stdout)
        .ok()
        .map(|s| s.trim().to_string())
}

fn is_hash(s: &str) -> bool {
    matches!(s.len(), 40 | 64) && s.bytes().all(|b| b.is_ascii_hexdigit())
}

/// The top of the git repository whose top is the workspace `root`, if any: an enclosing
/// repository of something else (tandem unpacked inside another project) does not count.
fn workspace_repo(root: &Path) -> Option<PathBuf> {
    let root = root.canonicalize().ok()?;
    let top = PathBuf::from(git(&root, &["rev-parse", "--show-toplevel"])?);
    (top.canonicalize().ok()? == root).then_some(root)
}

/// `cargo::rerun-if-changed` on what moves the commit or the dirty flag. Only existing paths:
/// cargo reruns a script on every build while a watched path is missing.
fn watch(top: &Path) {
    let git_path = |name: &str| {
        git(top, &["rev-parse", "--git-path", name]).map(|p| {
            let p = PathBuf::from(p);
            if p.is_absolute() {
                p
            } else {
                top.join(p)
            }
        })
    };
    // Not the index: git rewrites it on a mere `git status`, which would rebuild this crate and
    // the program; the tracked sources below catch the edits that make the tree dirty.
    let mut paths: Vec<PathBuf> = ["HEAD", "packed-refs"]
        .into_iter()
        .filter_map(git_path)
        .collect();
    if let Some(branch) = git(top, &["symbolic-ref", "-q", "HEAD"]) {
        if let Some(loose) = git_path(&branch) {
            // A packed branch has no file of its own until its next commit creates one.
            match loose.exists() {
                true => paths.push(loose),
                false => paths.extend(loose.parent().map(Path::to_path_buf)),
            }
        }
    }
    // Tracked sources under crates/ (not tests, benches or examples): an edit there rebuilds
    // this crate anyway, and without it `dirty` would keep the value of the last commit.
    if let Some(files) = git(top, &["ls-files", "-z", "crates"]) {
        paths.extend(
            files
                .split('\0')
                .filter(|f| !f.is_empty())
                .filter(|f| {
                    !f.split('/')
                        .any(|c| matches!(c, "tests" | "benches" | "examples"))
                })
                .map(|f| top.join(f)),
        );
    }
    paths.extend(["Cargo.toml", "Cargo.lock"].map(|f| top.join(f)));
    for p in paths.into_iter().filter(|p| p.exists()) {
        println!("cargo::rerun-if-changed={}", p.display());
    }
}
