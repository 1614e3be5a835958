//! Path safety for everything written from user input: a scene (or rod) name becomes a
//! file stem through [`safe_stem`], and every output path is built by [`join_under`],
//! which refuses a relative name that would leave the output folder. Nothing derived from
//! a scene or sweep file is joined to `--out` any other way.

use std::path::{Component, Path, PathBuf};

/// Longest file stem [`safe_stem`] returns (in characters).
pub const MAX_STEM_CHARS: usize = 100;

/// A file stem made from `name`: letters and digits (any script), `-`, `_` and `.` are
/// kept, every other character (path separators, control characters, spaces, quotes…)
/// becomes `_`; leading dots are dropped (no hidden files, no `..`), the result is cut to
/// [`MAX_STEM_CHARS`] characters and is never empty (`"scene"`).
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
    let cut: String = trimmed.chars().take(MAX_STEM_CHARS).collect();
    let cut = cut.trim_end_matches('.').to_string();
    if cut.is_empty() {
        "scene".into()
    } else {
        cut
    }
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
            assert!(join_under(Path::new("o"), &s).is_ok(), "{name:?} -> {s:?}");
        }
        assert_eq!(safe_stem("名前"), "名前");
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
