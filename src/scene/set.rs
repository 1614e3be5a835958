//! Command-line overrides (`--set KEY=VALUE`) written into the parsed document tree of
//! the scene file itself, so that every value read from the file keeps its own
//! `line:column` and every value that came from `--set` can be blamed on it.
//!
//! The value of the k-th override gets a byte span past the end of the text
//! ([`super::span::Doc::set_span`]); [`super::span::Doc::origin`] maps it back to the
//! override.

use std::borrow::Cow;
use std::ops::Range;

use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// A path step of a scene key (`--set` and a sweep's `[[vary]] key`).
pub(crate) enum Step {
    Key(String),
    Index(usize),
}

/// `integrator.dt`, `rod[0].elements`, `rod.beam.elements` as steps; `None` when it is
/// not a key path.
pub(crate) fn parse_key(key: &str) -> Option<Vec<Step>> {
    let mut out = Vec::new();
    for part in key.split('.') {
        let (name, mut rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if name.is_empty() {
            return None;
        }
        out.push(Step::Key(name.to_string()));
        while !rest.is_empty() {
            let close = rest.find(']')?;
            if !rest.starts_with('[') {
                return None;
            }
            out.push(Step::Index(rest[1..close].trim().parse().ok()?));
            rest = &rest[close + 1..];
        }
    }
    Some(out)
}

/// The TOML text of the number `x`: `int` is an integer (only when `x` is integral and
/// exactly representable), `float` a float.
pub(crate) struct NumberText {
    pub(crate) int: Option<String>,
    pub(crate) float: String,
}

impl NumberText {
    /// Both spellings of `x`.
    pub(crate) fn new(x: f64) -> Self {
        let int = (x.fract() == 0.0 && x.abs() < 9e15).then(|| format!("{}", x as i64));
        Self {
            int,
            float: format!("{x:?}"),
        }
    }
}

fn parsed<'i>(text: &'i str, span: &Range<usize>) -> Result<Spanned<DeValue<'i>>, String> {
    let v = DeValue::parse(text).map_err(|e| format!("`{text}`: {}", e.message().trim()))?;
    Ok(Spanned::new(span.clone(), v.into_inner()))
}

/// Writes the number `x` (spelled in `num`) at `key` into the document `root`, with the
/// byte span `span`. The parent must exist; the leaf may be new (a table key) or must be a
/// number (an array entry). Integers stay integers, and new keys are integers, when `x` is
/// integral. Tables in an
/// array of tables can be named by their `name` key (`rod.beam.elements`).
pub(crate) fn set_in<'i>(
    root: &mut DeTable<'i>,
    key: &str,
    num: &'i NumberText,
    span: Range<usize>,
) -> Result<(), String> {
    let steps = parse_key(key).ok_or_else(|| {
        format!(
            "`{}` is not a key path (expected e.g. `integrator.alpha` or `rod[0].elements`)",
            super::echo(key)
        )
    })?;
    let new = |old: Option<&DeValue<'i>>| -> Result<Spanned<DeValue<'i>>, String> {
        match (old, &num.int) {
            // An integer stays an integer, and a new key gets one when `x` is integral
            // (counts are integers; a float key reads an integer as well).
            (Some(DeValue::Integer(_)) | None, Some(i)) => parsed(i, &span),
            (Some(DeValue::Integer(_)) | Some(DeValue::Float(_)) | None, _) => {
                parsed(&num.float, &span)
            }
            (Some(v), _) => Err(format!(
                "the scene's value there is a {}, not a number",
                v.type_str()
            )),
        }
    };
    // The last step acts on a table (insert or replace) or an array (replace).
    let (last, walk) = steps.split_last().ok_or("empty key")?;
    let mut table: Option<&mut DeTable<'i>> = Some(root);
    let mut array: Option<&mut [Spanned<DeValue<'i>>]> = None;
    for st in walk {
        let next: &mut Spanned<DeValue<'i>> = match (st, table.take(), array.take()) {
            (Step::Key(k), Some(t), _) => t
                .get_mut(k.as_str())
                .ok_or_else(|| format!("the scene has no `{}` here", super::echo(k)))?,
            (Step::Key(k), None, Some(a)) => {
                // An array of tables by name: `rod.beam.elements` is the rod named `beam`.
                let names: Vec<String> = a
                    .iter()
                    .filter_map(|v| name_of(v.get_ref()).map(|n| super::echo(n).into_owned()))
                    .collect();
                a.iter_mut()
                    .find(|v| name_of(v.get_ref()) == Some(k.as_str()))
                    .ok_or_else(|| {
                        format!(
                            "no entry named `{}` here (named entries: {})",
                            super::echo(k),
                            if names.is_empty() {
                                "none".to_string()
                            } else {
                                names.join(", ")
                            }
                        )
                    })?
            }
            (Step::Index(j), _, Some(a)) => {
                let n = a.len();
                a.get_mut(*j)
                    .ok_or_else(|| format!("index {j} out of range (the array has {n} entries)"))?
            }
            (Step::Key(k), None, None) => {
                return Err(format!(
                    "`{}` is not inside a table in the scene",
                    super::echo(k)
                ))
            }
            (Step::Index(j), _, None) => return Err(format!("[{j}]: the scene has no array here")),
        };
        match next.get_mut() {
            DeValue::Table(t) => table = Some(t),
            DeValue::Array(a) => array = Some(a.as_mut()),
            _ => {}
        }
    }
    match (last, table, array) {
        (Step::Key(k), Some(t), _) => {
            let v = new(t.get(k.as_str()).map(|v| v.get_ref()))?;
            match t.get_mut(k.as_str()) {
                Some(slot) => *slot = v,
                None => {
                    t.insert(Spanned::new(span.clone(), Cow::Owned(k.clone())), v);
                }
            }
            Ok(())
        }
        (Step::Index(j), _, Some(a)) => {
            let n = a.len();
            let slot = a
                .get_mut(*j)
                .ok_or_else(|| format!("index {j} out of range (the array has {n} entries)"))?;
            *slot = new(Some(slot.get_ref()))?;
            Ok(())
        }
        (Step::Key(k), None, _) => Err(format!(
            "`{}` is not inside a table in the scene",
            super::echo(k)
        )),
        (Step::Index(j), _, None) => Err(format!("[{j}]: the scene has no array here")),
    }
}

fn name_of<'a>(v: &'a DeValue<'_>) -> Option<&'a str> {
    v.as_table()
        .and_then(|t| t.get("name"))
        .and_then(|n| n.get_ref().as_str())
}
