//! Key paths (`rod[1].points[0]`) and their source locations.
//!
//! The scene text is parsed once into toml's spanned document tree ([`DeTable`]); that tree
//! maps a key path to a byte span (for validation errors) and a byte offset back to the key
//! path (for errors toml reports from deserialization). Byte offsets become `line:column`
//! here, both 1-based, the column counted in characters.

use std::fmt;
use std::ops::Range;

use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// One step of a key path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Seg {
    /// A table key.
    Key(String),
    /// An array index (0-based).
    Index(usize),
}

/// A path from the document root to a value, e.g. `rod[1].points`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct KeyPath(pub(crate) Vec<Seg>);

impl KeyPath {
    /// The document root (empty path).
    pub(crate) fn root() -> Self {
        Self(Vec::new())
    }

    /// This path extended by a table key.
    pub(crate) fn key(&self, k: &str) -> Self {
        let mut v = self.0.clone();
        v.push(Seg::Key(k.to_string()));
        Self(v)
    }

    /// This path extended by an array index.
    pub(crate) fn idx(&self, i: usize) -> Self {
        let mut v = self.0.clone();
        v.push(Seg::Index(i));
        Self(v)
    }

    /// True for the document root.
    pub(crate) fn is_root(&self) -> bool {
        self.0.is_empty()
    }
}

fn is_bare_key(k: &str) -> bool {
    !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

impl fmt::Display for KeyPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, seg) in self.0.iter().enumerate() {
            match seg {
                Seg::Key(k) => {
                    if i > 0 {
                        f.write_str(".")?;
                    }
                    // A key is echoed at most `super::MAX_ECHO` characters long.
                    let k = super::echo(k);
                    if is_bare_key(&k) {
                        f.write_str(&k)?;
                    } else {
                        write!(f, "{k:?}")?;
                    }
                }
                Seg::Index(n) => write!(f, "[{n}]")?,
            }
        }
        Ok(())
    }
}

/// The parsed document with its spans, used only to locate keys.
pub(crate) struct Doc<'i> {
    text: &'i str,
    root: Spanned<DeTable<'i>>,
    /// `KEY=VALUE` of each command-line override written into `root`; the k-th one's
    /// value has the span [`Doc::set_span`]`(text.len(), k)`, past the end of the text.
    sets: Vec<String>,
}

/// Where a byte offset of a [`Doc`] came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Origin {
    /// 1-based line and column in the scene text.
    File(usize, usize),
    /// The k-th command-line override.
    Set(usize),
}

fn table_get<'a, 'i>(t: &'a DeTable<'i>, key: &str) -> Option<&'a Spanned<DeValue<'i>>> {
    t.iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(_, v)| v)
}

fn non_empty(r: Range<usize>) -> Option<Range<usize>> {
    // toml gives an empty span for values it synthesised (implicit tables).
    (r.end > r.start).then_some(r)
}

impl<'i> Doc<'i> {
    /// Wraps a parsed document.
    #[cfg(test)]
    pub(crate) fn new(text: &'i str, root: Spanned<DeTable<'i>>) -> Self {
        Self::with_sets(text, root, Vec::new())
    }

    /// Wraps a parsed document into which the overrides `sets` (`KEY=VALUE`, in order)
    /// were written with the spans [`Doc::set_span`].
    pub(crate) fn with_sets(text: &'i str, root: Spanned<DeTable<'i>>, sets: Vec<String>) -> Self {
        Self { text, root, sets }
    }

    /// The span given to the value of the k-th override of a text of `text_len` bytes:
    /// one byte, past the end of the text (and past the end-of-file offset).
    pub(crate) fn set_span(text_len: usize, k: usize) -> Range<usize> {
        text_len + 1 + k..text_len + 2 + k
    }

    /// Where byte `offset` came from: the text (line and column) or an override.
    pub(crate) fn origin(&self, offset: usize) -> Origin {
        if offset > self.text.len() && offset - self.text.len() - 1 < self.sets.len() {
            Origin::Set(offset - self.text.len() - 1)
        } else {
            let (l, c) = line_col(self.text, offset);
            Origin::File(l, c)
        }
    }

    /// The error about `key`, located at byte `offset`: in the file (`FILE:LINE:COL`, or
    /// `FILE` without an offset) or, for a value that came from an override, on that
    /// override (`--set KEY=VALUE`).
    pub(crate) fn error(
        &self,
        file: &str,
        offset: Option<usize>,
        key: String,
        reason: String,
    ) -> super::SceneError {
        match offset.map(|o| self.origin(o)) {
            Some(Origin::Set(k)) => super::SceneError::Set {
                file: file.to_string(),
                set: self.sets.get(k).cloned().unwrap_or_default(),
                key,
                reason,
            },
            Some(Origin::File(l, c)) => super::SceneError::Invalid {
                file: file.to_string(),
                location: Some((l, c)),
                key,
                reason,
            },
            None => super::SceneError::Invalid {
                file: file.to_string(),
                location: None,
                key,
                reason,
            },
        }
    }

    /// The spanned document tree.
    pub(crate) fn root(&self) -> &Spanned<DeTable<'i>> {
        &self.root
    }

    /// Byte span of the value at `path`, or of its nearest ancestor that has one.
    /// `None` when not even the first key of the path exists.
    pub(crate) fn span_of(&self, path: &KeyPath) -> Option<Range<usize>> {
        let mut best: Option<Range<usize>> = None;
        let mut table: Option<&DeTable<'i>> = Some(self.root.get_ref());
        let mut array: Option<&[Spanned<DeValue<'i>>]> = None;
        for seg in &path.0 {
            let next = match seg {
                Seg::Key(k) => table.and_then(|t| table_get(t, k)),
                Seg::Index(n) => array.and_then(|a| a.get(*n)),
            };
            let Some(v) = next else { break };
            if let Some(r) = non_empty(v.span()) {
                best = Some(r);
            }
            table = v.get_ref().as_table();
            array = v.get_ref().as_array().map(|a| &a[..]);
        }
        best
    }

    /// The key path of the smallest key or value whose span contains byte `offset`
    /// (the root when none does).
    pub(crate) fn path_at(&self, offset: usize) -> KeyPath {
        let mut best: Option<(usize, usize, KeyPath)> = None;
        visit_table(self.root.get_ref(), &KeyPath::root(), &mut |path, span| {
            if span.end > span.start && span.start <= offset && offset < span.end {
                let len = span.end - span.start;
                let depth = path.0.len();
                let better = best
                    .as_ref()
                    .is_none_or(|(l, d, _)| len < *l || (len == *l && depth > *d));
                if better {
                    best = Some((len, depth, path.clone()));
                }
            }
        });
        best.map(|(_, _, p)| p).unwrap_or_default()
    }
}

fn visit_table(t: &DeTable<'_>, path: &KeyPath, f: &mut dyn FnMut(&KeyPath, Range<usize>)) {
    for (k, v) in t.iter() {
        let p = path.key(k.get_ref());
        f(&p, k.span());
        visit_value(v, &p, f);
    }
}

fn visit_value(
    v: &Spanned<DeValue<'_>>,
    path: &KeyPath,
    f: &mut dyn FnMut(&KeyPath, Range<usize>),
) {
    f(path, v.span());
    match v.get_ref() {
        DeValue::Table(t) => visit_table(t, path, f),
        DeValue::Array(a) => {
            for (i, item) in a.iter().enumerate() {
                visit_value(item, &path.idx(i), f);
            }
        }
        _ => {}
    }
}

/// 1-based `(line, column)` of a byte offset in `text` (column in characters).
pub(crate) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let col = text[line_start..offset].chars().count() + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_render_like_toml() {
        let p = KeyPath::root().key("rod").idx(1).key("points").idx(0);
        assert_eq!(p.to_string(), "rod[1].points[0]");
        let q = KeyPath::root().key("material").key("my mat").key("E");
        assert_eq!(q.to_string(), "material.\"my mat\".E");
    }

    #[test]
    fn line_col_counts_from_one() {
        let t = "a = 1\nbé = 2\n";
        assert_eq!(line_col(t, 0), (1, 1));
        assert_eq!(line_col(t, 6), (2, 1));
        assert_eq!(line_col(t, 9), (2, 3));
    }

    #[test]
    fn spans_and_paths_round_trip() {
        let text =
            "x = 1\n[[rod]]\npoints = [[0,0,0],[1,0,0]]\n[[rod]]\npoints = [[0,0,0],[2,0,0]]\n";
        let doc = Doc::new(text, DeTable::parse(text).unwrap());
        let p = KeyPath::root().key("rod").idx(1).key("points").idx(1);
        let span = doc.span_of(&p).unwrap();
        assert_eq!(&text[span.clone()], "[2,0,0]");
        assert_eq!(
            doc.path_at(span.start + 1).to_string(),
            "rod[1].points[1][0]"
        );
        assert_eq!(line_col(text, span.start), (5, 19));
    }
}
