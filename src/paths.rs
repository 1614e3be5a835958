//! Path safety for everything written from user input: a scene (or rod) name becomes a
//! file stem through [`safe_stem`], and every output path is built by [`join_under`],
//! which refuses a relative name that would leave the output folder. Nothing derived from
//! a scene or sweep file is joined to `--out` any other way. Files that must never be
//! seen half-written are replaced through [`write_atomic`].

use std::io::Write;
use std::path::{Component, Path, PathBuf};

/// Longest file stem [`safe_stem`] returns (in characters).
pub const MAX_STEM_CHARS: usize = 100;

/// Longest file name most file systems accept (ext4, XFS, APFS, NTFS: 255 bytes).
pub const MAX_FILE_NAME_BYTES: usize = 255;

/// Room left after a stem for the longest suffix an output adds to it: `_STEP.vtu` with a
/// step of up to 20 digits (25 bytes), `.pvd` plus the `.tmp` of [`write_atomic`]
/// (8 bytes); every suffix an output appends to a stem is at most this long.
pub const MAX_SUFFIX_BYTES: usize = 55;

/// Longest file stem [`safe_stem`] returns, in bytes of UTF-8: a stem plus any output
/// suffix ([`MAX_SUFFIX_BYTES`]) fits in [`MAX_FILE_NAME_BYTES`].
pub const MAX_STEM_BYTES: usize = MAX_FILE_NAME_BYTES - MAX_SUFFIX_BYTES;

/// A file stem made from `name`: letters and digits (any script), `-`, `_` and `.` are
/// kept, every other character (path separators, control characters, spaces, quotes…)
/// becomes `_`; leading dots are dropped (no hidden files, no `..`), the result is cut to
/// [`MAX_STEM_CHARS`] characters and [`MAX_STEM_BYTES`] bytes (on a character boundary)
/// and is never empty (`"scene"`).
///
/// ```
/// use cosserat::paths::safe_stem;
/// assert_eq!(safe_stem("../../x"), "_.._x");
/// assert_eq!(safe_stem("frame"), "frame");
/// assert_eq!(safe_stem("a b/c\u{1b}[31m"), "a_b_c__31m");
/// ```
pub fn safe_stem(name: &str) -> String {
    let mapped: String = name
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let trimmed = mapped.trim_start_matches('.');
    let mut cut = String::new();
    for c in trimmed.chars().take(MAX_STEM_CHARS) {
        if cut.len() + c.len_utf8() > MAX_STEM_BYTES {
            break;
        }
        cut.push(c);
    }
    let cut = cut.trim_end_matches('.').to_string();
    if cut.is_empty() {
        "scene".into()
    } else {
        cut
    }
}

/// Writes `data` to `path` through `PATH.tmp` (synced, then renamed over `path`): a
/// reader, or a kill at any moment, sees either the previous whole file or the new whole
/// file, never a truncated one. The temporary file is removed when the write fails.
pub fn write_atomic(path: &Path, data: &[u8]) -> std::io::Result<()> {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    let tmp = path.with_file_name(name);
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        f.write_all(data)?;
        f.sync_all()
    });
    written
        .and_then(|()| std::fs::rename(&tmp, path))
        .inspect_err(|_| {
            let _ = std::fs::remove_file(&tmp);
        })
}

/// A relative name that would leave (or replace) the output folder.
#[derive(Debug, thiserror::Error)]
#[error("refusing to write `{name}` under {}: {reason}", out.display())]
pub struct PathEscape {
    /// The output folder.
    pub out: PathBuf,
    /// The name as given.
    pub name: String,
    /// Why it is refused.
    pub reason: &'static str,
}

/// `out/rel`, provided `rel` is a relative path of plain components (no `..`, no root,
/// no drive prefix, not empty): the result always lies inside `out`.
///
/// ```
/// use std::path::Path;
/// use cosserat::paths::join_under;
/// assert!(join_under(Path::new("o"), "vtk/a.vtu").is_ok());
/// assert!(join_under(Path::new("o"), "../x").is_err());
/// assert!(join_under(Path::new("o"), "/etc/x").is_err());
/// ```
pub fn join_under(out: &Path, rel: impl AsRef<Path>) -> Result<PathBuf, PathEscape> {
    let rel = rel.as_ref();
    let err = |reason| PathEscape {
        out: out.to_path_buf(),
        name: rel.display().to_string(),
        reason,
    };
    let mut n = 0;
    for c in rel.components() {
        match c {
            Component::Normal(_) => n += 1,
            Component::CurDir => {}
            Component::ParentDir => return Err(err("it contains `..`")),
            Component::RootDir | Component::Prefix(_) => return Err(err("it is an absolute path")),
        }
    }
    if n == 0 {
        return Err(err("it names no file"));
    }
    Ok(out.join(rel))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stems_never_contain_separators_or_start_with_a_dot() {
        for name in [
            "../../x",
            "/etc/passwd",
            "..",
            ".",
            "",
            "a\\b",
            "C:\\x",
            "\u{0}",
            "\n",
            "名前",
            "x".repeat(500).as_str(),
        ] {
            let s = safe_stem(name);
            assert!(!s.is_empty(), "{name:?}");
            assert!(!s.contains('/') && !s.contains('\\') && !s.starts_with('.'));
            assert!(s.chars().count() <= MAX_STEM_CHARS);
            assert!(s.len() <= MAX_STEM_BYTES);
            assert!(join_under(Path::new("o"), &s).is_ok(), "{name:?} -> {s:?}");
        }
        assert_eq!(safe_stem("名前"), "名前");
    }

    #[test]
    fn stems_fit_a_file_name_with_any_suffix_in_bytes() {
        // 100 three-byte characters: 300 bytes, under the character limit.
        let s = safe_stem(&"名".repeat(100));
        assert!(s.len() <= MAX_STEM_BYTES, "{} bytes", s.len());
        assert_eq!(s, "名".repeat(MAX_STEM_BYTES / 3));
        // Four-byte characters are cut on a character boundary.
        let s = safe_stem(&"𝔸".repeat(100));
        assert_eq!(s, "𝔸".repeat(MAX_STEM_BYTES / 4));
        let longest = format!("{s}_{}.vtu", usize::MAX);
        assert!(longest.len() <= MAX_FILE_NAME_BYTES);
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(&longest), "x").unwrap();
        write_atomic(&dir.path().join(format!("{s}.pvd")), b"x").unwrap();
    }

    #[test]
    fn write_atomic_replaces_the_file_whole_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.pvd");
        write_atomic(&p, b"first").unwrap();
        // A reader holding the old file (a hard link to it) keeps the whole old text.
        std::fs::hard_link(&p, dir.path().join("old")).unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        assert_eq!(std::fs::read(dir.path().join("old")).unwrap(), b"first");
        assert!(!dir.path().join("a.pvd.tmp").exists());
        let e = write_atomic(&dir.path().join("no/such/x"), b"x").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::NotFound);
    }

    #[test]
    fn join_under_refuses_escapes_with_the_reason() {
        let o = Path::new("out");
        assert_eq!(join_under(o, "a/b").unwrap(), Path::new("out/a/b"));
        let e = join_under(o, "a/../../b").unwrap_err().to_string();
        assert!(e.contains("contains `..`"), "{e}");
        let e = join_under(o, "/tmp/x").unwrap_err().to_string();
        assert!(e.contains("absolute"), "{e}");
        let e = join_under(o, "").unwrap_err().to_string();
        assert!(e.contains("names no file"), "{e}");
    }
}
