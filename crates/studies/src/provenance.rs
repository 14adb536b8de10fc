//! Which build produced a study's numbers: the git commit of the workspace, whether its tracked
//! files differed from that commit, and the optional features on. A study records its build in
//! `config.json` when it starts ([`Build::current`], written by the build script of this crate);
//! a merge keeps the builds of its parts.
//!
//! The numbers are bit-reproducible at the recorded commit (for a fixed seed and settings; the
//! thread count `--jobs` only distributes whole runs), and only statistically after it, since a
//! later commit may change element-wise arithmetic.

use serde::{Deserialize, Serialize};

/// The commit when it cannot be known: no git, or a source tree outside its repository.
pub const UNKNOWN: &str = "unknown";

/// A build of the studies, as `config.json` records it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Build {
    /// The workspace's git commit (`git rev-parse HEAD`), or `unknown`.
    pub commit: String,
    /// Whether tracked files differed from `commit` when the studies were built.
    pub dirty: bool,
    /// The optional features on (`mujoco`).
    pub features: Vec<String>,
    /// Where `commit` comes from when not from the build itself, for directories written before
    /// builds were recorded: `stated` (a commit message names it), `added` (the commit that
    /// first held the run's files; the build was that commit or an earlier one) or `unrecorded`
    /// (resumed by a recording build; nothing is known of the first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commit_source: Option<String>,
    /// A remark on a recorded-after-the-fact build.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// The builds that continued the study (`--resume`) when they differ from the one before:
    /// runs finished after a resume carry that build's numbers, and the report is the last
    /// build's.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub resumed_by: Vec<Build>,
}

impl Build {
    /// The build of this program.
    pub fn current() -> Self {
        let mut features = Vec::new();
        if cfg!(feature = "mujoco") {
            features.push("mujoco".to_string());
        }
        Self {
            commit: env!("TANDEM_BUILD_COMMIT").to_string(),
            dirty: env!("TANDEM_BUILD_DIRTY") == "true",
            features,
            commit_source: None,
            note: None,
            resumed_by: Vec::new(),
        }
    }

    /// A study's build without a record: nothing known but that it predates recording.
    fn unrecorded() -> Self {
        Self {
            commit: UNKNOWN.to_string(),
            dirty: false,
            features: Vec::new(),
            commit_source: Some("unrecorded".to_string()),
            note: None,
            resumed_by: Vec::new(),
        }
    }

    /// Whether `self` and `other` are the same program: commit, dirty flag and features.
    pub fn same_program(&self, other: &Build) -> bool {
        (&self.commit, self.dirty, &self.features) == (&other.commit, other.dirty, &other.features)
    }

    /// The last build that worked on the study: the last resume's, or the first.
    pub fn last(&self) -> &Build {
        self.resumed_by.last().unwrap_or(self)
    }

    /// The commits of this build and its resumes, first seen first.
    pub fn commits(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for b in std::iter::once(self).chain(&self.resumed_by) {
            if !out.contains(&b.commit.as_str()) {
                out.push(&b.commit);
            }
        }
        out
    }

    /// Short words for messages: the commit's first 12 characters, `+dirty`, the features.
    pub fn describe(&self) -> String {
        let mut s = short_commit(&self.commit);
        if self.dirty {
            s.push_str(" (dirty)");
        }
        if !self.features.is_empty() {
            s.push_str(&format!(" [{}]", self.features.join(",")));
        }
        s
    }
}

/// A commit's first 12 characters, for messages.
pub fn short_commit(commit: &str) -> String {
    commit.chars().take(12).collect()
}

/// What a resume does to a study's recorded `build`: a build other than the last one recorded
/// is appended to `resumed_by` (a study without a record gets an `unrecorded` first build), and
/// the note to print says so. `None` when the same program resumes.
pub fn on_resume(recorded: &mut Option<Build>, now: Build) -> Option<String> {
    let first = recorded.get_or_insert_with(Build::unrecorded);
    if first.last().same_program(&now) {
        return None;
    }
    let before = first.last().describe();
    let note = format!(
        "note: the study was run by the build {before}, and is continued by {}; runs finished \
         from now on carry the new build's numbers (config.json lists it under build.resumed_by)",
        now.describe()
    );
    first.resumed_by.push(now);
    Some(note)
}

/// A merge's record of one part's build: the part's directory (as in the merge's `parts`) and
/// its build.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PartBuild {
    /// The directory whose process ran the part.
    pub part: String,
    /// Its build.
    #[serde(flatten)]
    pub build: Build,
}

/// The distinct commits of `builds` (with their resumes), first seen first: more than one means
/// the merged numbers do not all come from one program.
pub fn distinct_commits(builds: &[PartBuild]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for b in builds {
        for c in b.build.commits() {
            if !out.iter().any(|o| o == c) {
                out.push(c.to_string());
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_current_build_names_a_commit_or_unknown() {
        let b = Build::current();
        let hex =
            matches!(b.commit.len(), 40 | 64) && b.commit.bytes().all(|c| c.is_ascii_hexdigit());
        assert!(hex || b.commit == UNKNOWN, "{}", b.commit);
        assert_eq!(
            b.features.contains(&"mujoco".to_string()),
            cfg!(feature = "mujoco")
        );
    }

    #[test]
    fn a_resume_by_another_build_is_appended_once() {
        let a = Build {
            commit: "a".repeat(40),
            ..Build::current()
        };
        let b = Build {
            commit: "b".repeat(40),
            ..Build::current()
        };
        let mut rec = Some(a.clone());
        assert!(on_resume(&mut rec, a.clone()).is_none());
        assert!(on_resume(&mut rec, b.clone()).is_some());
        assert!(on_resume(&mut rec, b.clone()).is_none());
        let rec = rec.unwrap();
        assert_eq!(rec.commit, a.commit);
        assert_eq!(rec.resumed_by, vec![b.clone()]);
        assert_eq!(rec.commits(), [a.commit.as_str(), b.commit.as_str()]);
        // A study recorded before builds were gets an unrecorded first build.
        let mut old = None;
        assert!(on_resume(&mut old, a.clone()).is_some());
        let old = old.unwrap();
        assert_eq!(old.commit_source.as_deref(), Some("unrecorded"));
        assert_eq!(old.resumed_by, vec![a]);
    }
}
