//! How a sweep is split into shards: [`Shard`] (I of N), the shards' file names in
//! `DIR/shards/`, and the checks that a folder's shards are of one sweep and one split.
//! Below both the sweep runner (which runs one shard) and the merge
//! ([`super::shard`]), which read and write those files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{SweepError, SweepSpec};

/// Folder (inside the sweep's `--out`) that holds the shards' files.
pub const SHARDS_DIR: &str = "shards";

/// Shard `index` of `count`: the members whose index is ≡ `index` mod `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Shard {
    /// This shard, 0-based (`0 ≤ index < count`).
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl Shard {
    /// Shard `index` of `count`, checked.
    pub fn new(index: usize, count: usize) -> Result<Shard, String> {
        if count == 0 {
            return Err("the number of shards must be ≥ 1".into());
        }
        if index >= count {
            return Err(format!(
                "shard {index} of {count} does not exist (shards are numbered 0 to {})",
                count - 1
            ));
        }
        Ok(Shard { index, count })
    }

    /// Parses `I/N` (the form of `--shard`).
    pub fn parse(s: &str) -> Result<Shard, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}` is not I/N (e.g. 0/4: shard 0 of 4)"))?;
        let num = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}` is not I/N: `{}` is not a whole number", t.trim()))
        };
        Shard::new(num(i)?, num(n)?)
    }

    /// Whether member `i` belongs to this shard.
    pub fn contains(&self, i: usize) -> bool {
        i % self.count == self.index
    }

    /// Number of this shard's members in a sweep of `total` members.
    pub fn len_of(&self, total: usize) -> usize {
        total.saturating_sub(self.index).div_ceil(self.count)
    }

    /// The stem of the shard's files, `I-of-N`.
    pub fn name(&self) -> String {
        format!("{}-of-{}", self.index, self.count)
    }

    /// Parses a file name `I-of-N.EXT` into the shard and `EXT`.
    pub(super) fn from_file_name(name: &str) -> Option<(Shard, &str)> {
        let (stem, ext) = name.split_once('.')?;
        let (i, n) = stem.split_once("-of-")?;
        let digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
        if !digits(i) || !digits(n) {
            return None;
        }
        Some((Shard::new(i.parse().ok()?, n.parse().ok()?).ok()?, ext))
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The identity line a shard's rows file (`I-of-N.csv`) begins with, before the header:
/// the sweep's identity (as in `sweep.id`) and the shard, so that merge and `--resume`
/// recognize another sweep's or another shard's file.
pub(super) fn tag(id: &str, sh: Shard) -> String {
    format!("# cosserat sweep {id} shard {sh}")
}

/// A sweep is split into at most one shard per member: `--shard I/N` with N above the
/// number of members is refused (naming the sweep file, `--shard` and the member count).
pub fn check_count(spec: &SweepSpec, sh: Shard) -> Result<(), SweepError> {
    if sh.count <= spec.len() {
        return Ok(());
    }
    Err(SweepError::Invalid {
        file: spec.source.clone(),
        location: None,
        key: "--shard".into(),
        reason: format!(
            "{sh}: {} shards for {} members: at most one shard per member (N ≤ {})",
            sh.count,
            spec.len(),
            spec.len()
        ),
    })
}

/// `out/shards/I-of-N.EXT`.
pub fn file(out: &Path, shard: Shard, ext: &str) -> PathBuf {
    out.join(SHARDS_DIR).join(format!("{}.{ext}", shard.name()))
}

/// A shard identity file's lines.
pub(super) struct IdFile {
    text: String,
}

impl IdFile {
    pub(super) fn read(path: &Path) -> Option<IdFile> {
        std::fs::read_to_string(path)
            .ok()
            .map(|text| IdFile { text })
    }
    pub(super) fn get(&self, key: &str) -> &str {
        self.text
            .lines()
            .find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
            .unwrap_or("")
            .trim()
    }
    /// The sweep's identity text (`sweep.id` of an unsharded run): without the shard line.
    pub(super) fn sweep_text(&self) -> String {
        self.text
            .lines()
            .filter(|l| !l.starts_with("shard "))
            .map(|l| format!("{l}\n"))
            .collect()
    }
}

/// The shards' identity files found in `out/shards` (any split), by shard.
fn id_files(out: &Path) -> BTreeMap<Shard, PathBuf> {
    let mut found = BTreeMap::new();
    let Ok(entries) = std::fs::read_dir(out.join(SHARDS_DIR)) else {
        return found;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        if let Some((sh, "id")) = Shard::from_file_name(&name.to_string_lossy()) {
            found.insert(sh, e.path());
        }
    }
    found
}

/// The folder holds one split of one sweep: every shard identity file in `out/shards`
/// must record identity `id` and `count` shards (`skip`: the caller's own shard, which it
/// is about to write or check itself).
pub(super) fn check_ids(
    out: &Path,
    id: &str,
    count: usize,
    skip: Option<Shard>,
) -> Result<(), SweepError> {
    let remedy = format!(
        "one folder holds one split of one sweep: use another --out, or delete {} (and {}/member_*) if those results are not needed",
        out.join(SHARDS_DIR).display(),
        out.display()
    );
    for (sh, path) in id_files(out) {
        if Some(sh) == skip {
            continue;
        }
        let Some(f) = IdFile::read(&path) else {
            continue;
        };
        if sh.count != count {
            return Err(SweepError::Shard {
                file: path.display().to_string(),
                shard: sh.name(),
                reason: format!(
                    "this folder's shards split the sweep into {} shards, this run into {count}: {remedy}",
                    sh.count
                ),
            });
        }
        if f.get("id") != id {
            return Err(SweepError::Shard {
                file: path.display().to_string(),
                shard: sh.name(),
                reason: format!(
                    "belongs to another sweep (id {}: {} members over {}, from {}); this one is id {id}: its base scene, member values or overrides (--newton, --no-fallback, --cutback) differ. {remedy}",
                    f.get("id"),
                    f.get("members"),
                    f.get("parameters"),
                    f.get("sweep")
                ),
            });
        }
    }
    Ok(())
}

/// Before a shard runs: the folder's other shards (if any) are of this sweep and split.
pub(super) fn check_siblings(out: &Path, id: &str, shard: Shard) -> Result<(), SweepError> {
    check_ids(out, id, shard.count, Some(shard))
}
