//! The value checks every stage shares: the error factory [`Ctx`] (file name and document
//! for `line:column`), finite/positive/vector/count/name checks, and the `time`/`factor`
//! tables and `ramp` keys of loads, moving supports and moving obstacles.

use std::fmt::Display;

use crate::model::{Ramp, TimeTable, Vec3};
use crate::scene::span::{Doc, KeyPath};
use crate::scene::{fmt_num, key_name, SceneError};

pub(super) type Result<T> = std::result::Result<T, SceneError>;

/// Error factory: knows the file name and the document for spans.
pub(super) struct Ctx<'a, 'i> {
    pub(super) file: &'a str,
    pub(super) doc: &'a Doc<'i>,
}

/// A vector as `(x, y, z)` for error messages.
pub(super) fn fmt_v(v: &Vec3) -> String {
    format!("({}, {}, {})", fmt_num(v.x), fmt_num(v.y), fmt_num(v.z))
}

/// Longest rod, probe or scene name, in bytes.
pub(crate) const MAX_NAME_BYTES: usize = 256;

/// Largest magnitude of a rod point's coordinate: differences of coordinates, and the sums
/// of their squares that give lengths, stay far from overflow.
pub(crate) const MAX_COORDINATE: f64 = 1e100;

/// Most Newton iterations per solve, staggered outer rounds and link rounds per step
/// (`max_iter`, `max_outer`, `max_link_rounds`).
pub(crate) const MAX_ITERATION_CAP: i64 = 1000;

/// Smallest relative tolerance (`newton_tol`, `outer_tol`, `energy_tol`): tolerances are
/// relative to a force or energy scale, and a few ulps (f64's ε ≈ 2.2e-16) is the round-off
/// floor no solve can be asked to beat.
pub(crate) const MIN_TOLERANCE: f64 = 1e-15;

impl Ctx<'_, '_> {
    pub(super) fn err(&self, path: &KeyPath, reason: impl Display) -> SceneError {
        self.doc.error(
            self.file,
            self.doc.span_of(path).map(|s| s.start),
            key_name(path),
            crate::scene::cap_echoes(&reason.to_string()),
        )
    }

    pub(super) fn required<T>(&self, path: &KeyPath, v: Option<T>) -> Result<T> {
        v.ok_or_else(|| self.err(path, "required key missing"))
    }

    pub(super) fn finite(&self, path: &KeyPath, x: f64) -> Result<f64> {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be finite (got {})", fmt_num(x))))
        }
    }

    pub(super) fn positive(&self, path: &KeyPath, x: f64) -> Result<f64> {
        let x = self.finite(path, x)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be > 0 (got {})", fmt_num(x))))
        }
    }

    pub(super) fn non_negative(&self, path: &KeyPath, x: f64) -> Result<f64> {
        let x = self.finite(path, x)?;
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be >= 0 (got {})", fmt_num(x))))
        }
    }

    pub(super) fn req_positive(&self, path: &KeyPath, v: Option<f64>) -> Result<f64> {
        let x = self.required(path, v)?;
        self.positive(path, x)
    }

    pub(super) fn opt_non_negative(&self, path: &KeyPath, v: Option<f64>) -> Result<f64> {
        v.map_or(Ok(0.0), |x| self.non_negative(path, x))
    }

    pub(super) fn vec3(&self, path: &KeyPath, v: &[f64]) -> Result<Vec3> {
        if v.len() != 3 {
            return Err(self.err(
                path,
                format!("expected 3 numbers [x, y, z] (got {})", v.len()),
            ));
        }
        for (i, &x) in v.iter().enumerate() {
            self.finite(&path.idx(i), x)?;
        }
        Ok(Vec3::new(v[0], v[1], v[2]))
    }

    pub(super) fn opt_vec3(&self, path: &KeyPath, v: &Option<Vec<f64>>) -> Result<Option<Vec3>> {
        v.as_deref().map(|v| self.vec3(path, v)).transpose()
    }

    pub(super) fn count(&self, path: &KeyPath, v: Option<i64>, default: usize) -> Result<usize> {
        match v {
            None => Ok(default),
            Some(n) if n >= 1 => usize::try_from(n).map_err(|_| self.err(path, "too large")),
            Some(n) => Err(self.err(path, format!("must be >= 1 (got {n})"))),
        }
    }

    /// A count bounded by [`MAX_ITERATION_CAP`].
    pub(super) fn iteration_cap(
        &self,
        path: &KeyPath,
        v: Option<i64>,
        default: usize,
    ) -> Result<usize> {
        match v {
            Some(n) if n > MAX_ITERATION_CAP => {
                Err(self.err(path, format!("must be <= {MAX_ITERATION_CAP} (got {n})")))
            }
            _ => self.count(path, v, default),
        }
    }

    /// A relative tolerance: finite, and at least [`MIN_TOLERANCE`].
    pub(super) fn tolerance(&self, path: &KeyPath, x: f64) -> Result<f64> {
        let x = self.positive(path, x)?;
        if x < MIN_TOLERANCE {
            return Err(self.err(
                path,
                format!(
                    "must be >= {MIN_TOLERANCE:e} (got {}): the tolerance is relative, and double precision cannot resolve less",
                    fmt_num(x)
                ),
            ));
        }
        Ok(x)
    }

    /// A name (of a rod, a probe, the scene): not blank, at most [`MAX_NAME_BYTES`]
    /// bytes, no control characters, none of `forbidden`.
    pub(super) fn name(&self, path: &KeyPath, name: &str, forbidden: &[char]) -> Result<()> {
        if name.trim().is_empty() {
            return Err(self.err(path, "must not be empty"));
        }
        if name.len() > MAX_NAME_BYTES {
            return Err(self.err(
                path,
                format!(
                    "must be at most {MAX_NAME_BYTES} bytes long (got {} bytes)",
                    name.len()
                ),
            ));
        }
        if let Some(c) = name.chars().find(|c| c.is_control()) {
            return Err(self.err(
                path,
                format!(
                    "must not contain control characters (got {})",
                    c.escape_unicode()
                ),
            ));
        }
        if let Some(c) = name.chars().find(|c| forbidden.contains(c)) {
            let list: Vec<String> = forbidden.iter().map(|f| format!("{f:?}")).collect();
            return Err(self.err(
                path,
                format!(
                    "must be a non-empty name without {} or control characters (got {c:?})",
                    list.join(", ")
                ),
            ));
        }
        Ok(())
    }
}

/// The `ramp` key under `path` (default linear).
pub(super) fn ramp(cx: &Ctx, path: &KeyPath, r: &Option<String>) -> Result<Ramp> {
    match r.as_deref() {
        None | Some("linear") => Ok(Ramp::Linear),
        Some("smooth") => Ok(Ramp::Smooth),
        Some(other) => Err(cx.err(
            &path.key("ramp"),
            format!("unknown ramp `{other}` (expected \"linear\" or \"smooth\")"),
        )),
    }
}

/// A `time`/`factor` pair of keys under `path`: both or neither (constant factor 1).
pub(super) fn time_table(
    cx: &Ctx,
    path: &KeyPath,
    time: &Option<Vec<f64>>,
    factor: &Option<Vec<f64>>,
) -> Result<TimeTable> {
    Ok(match (time, factor) {
        (None, None) => TimeTable::constant_one(),
        (Some(_), None) => {
            return Err(cx.err(
                &path.key("factor"),
                "required key missing (`time` is given)",
            ))
        }
        (None, Some(_)) => {
            return Err(cx.err(
                &path.key("time"),
                "required key missing (`factor` is given)",
            ))
        }
        (Some(times), Some(values)) => {
            let (tp, fp) = (path.key("time"), path.key("factor"));
            if times.is_empty() {
                return Err(cx.err(&tp, "must have at least one entry"));
            }
            if times.len() != values.len() {
                return Err(cx.err(
                    &fp,
                    format!(
                        "must have the same length as `time` ({}) (got {})",
                        times.len(),
                        values.len()
                    ),
                ));
            }
            for (i, &t) in times.iter().enumerate() {
                cx.finite(&tp.idx(i), t)?;
                if i > 0 && t < times[i - 1] {
                    return Err(cx.err(
                        &tp.idx(i),
                        format!(
                            "times must be non-decreasing (got {t} after {})",
                            times[i - 1]
                        ),
                    ));
                }
            }
            for (i, &f) in values.iter().enumerate() {
                cx.finite(&fp.idx(i), f)?;
            }
            TimeTable {
                times: times.clone(),
                values: values.clone(),
            }
        }
    })
}
