//! Parameter sweeps: a base scene plus parameters to vary (a grid, explicit lists, or
//! seeded random samples) over any numeric scene key (`integrator.alpha`, `integrator.dt`,
//! `material.soft.E`, `initial_velocity[0].v[2]`, …). Each member is the base scene with
//! its values written in and validated by the scene parser; members run as one batch
//! ([`crate::batch`]) and `DIR/members.csv` grows by one row per finished member. A sweep
//! can also run as shards on many machines and be merged back ([`shard`]), for instance as
//! a Slurm job array ([`slurm`]).
//!
//! File format (`docs/sweeps.md` is not separate: README, "Sweeps"):
//!
//! ```toml
//! base = "frame"            # built-in name, or a scene path relative to this file
//! mode = "grid"             # "grid" (all combinations, default), "list" (zip), "random"
//! seed = 7                  # random mode: seed of the sampler
//! samples = 16              # random mode: number of members
//!
//! [[vary]]
//! key = "integrator.alpha"
//! values = [0.1, 0.5, 1.0]  # grid and list modes
//!
//! [[vary]]
//! key = "integrator.dt"
//! range = [0.05, 0.2]       # random mode: uniform in [lo, hi] (`log = true`: log-uniform)
//! ```
//!
//! Every error names the file, `line:column`, the key and the reason, like scene errors:
//! `sweep.toml:7:7: vary[0].key: base scene rejects it: builtin:frame: integrator.alpha: …`.

mod run;
pub mod shard;
pub mod slurm;
mod split;

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::math::rng::Rng;
use crate::scene::set::{parse_key, Step};
use crate::scene::{builtin_scenes, parse_scene, Scene, SceneError};
pub use run::{
    run_sweep, run_sweep_until, MemberRow, MemberStatus, SweepOptions, SweepSummary, CSV_COLUMNS,
    IDENTITY_FILE, LOCK_FILE,
};
pub use shard::{check_shard_folder, merge_shards, merge_shards_from, MergeSummary, Shard};

/// Everything that can go wrong reading a sweep file (or its output directory).
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The file cannot be read.
    #[error("cannot read {path}: {error}")]
    Io {
        /// Path as given.
        path: String,
        /// The underlying error (shown in the message, so not also a `source`: an error
        /// chain printed whole says the reason once).
        error: std::io::Error,
    },
    /// TOML syntax error.
    #[error("{file}{}: {reason}", loc(*.location))]
    Syntax {
        /// File.
        file: String,
        /// 1-based line and column.
        location: Option<(usize, usize)>,
        /// Why.
        reason: String,
    },
    /// A key is unknown, missing, of the wrong type or has an invalid value.
    #[error("{file}{}: {key}: {reason}", loc(*.location))]
    Invalid {
        /// File.
        file: String,
        /// 1-based line and column of the value (or enclosing table).
        location: Option<(usize, usize)>,
        /// Key path in the sweep file, e.g. `vary[1].values`.
        key: String,
        /// Why.
        reason: String,
    },
    /// Writing the results failed.
    #[error("{context}: {error}")]
    Output {
        /// What was being written.
        context: String,
        /// The underlying error (shown in the message, so not also a `source`).
        error: std::io::Error,
    },
    /// Another sweep holds the folder's lock.
    #[error("{dir}: another `cosserat sweep` is running in this folder (it holds {dir}/.sweep.lock); wait for it to finish or use another --out")]
    Locked {
        /// The output folder.
        dir: String,
    },
    /// A shard of a sharded sweep is missing, torn, incomplete, foreign or running.
    #[error("{file}: shard {shard}: {reason}")]
    Shard {
        /// The shard's file (or folder) the problem was found in.
        file: String,
        /// The shard, `I-of-N`.
        shard: String,
        /// Why, and what to do.
        reason: String,
    },
    /// The GPU backend failed as a whole.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
}

fn loc(l: Option<(usize, usize)>) -> String {
    match l {
        Some((a, b)) => format!(":{a}:{b}"),
        None => String::new(),
    }
}

/// How the varied values combine into members.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepMode {
    /// Cartesian product of every parameter's `values`.
    Grid,
    /// The `values` lists zipped (all of one length).
    List,
    /// `samples` members, each parameter drawn from its `range` by a seeded generator.
    Random,
}

/// One varied parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct VaryParam {
    /// Scene key path (`integrator.alpha`, `rod[0].elements`, …).
    pub key: String,
}

/// A validated sweep: its members' values, ready to build scenes.
#[derive(Clone, Debug)]
pub struct SweepSpec {
    /// Path of the sweep file.
    pub source: String,
    /// The base scene as named in the file.
    pub base: String,
    base_text: String,
    base_source: String,
    /// How members are formed.
    pub mode: SweepMode,
    /// The varied parameters (CSV column order).
    pub params: Vec<VaryParam>,
    /// Per member, one value per parameter.
    pub values: Vec<Vec<f64>>,
    /// What a member of the base scene holds (for the memory estimate).
    base_footprint: crate::scene::limits::Footprint,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    base: Spanned<String>,
    mode: Option<Spanned<String>>,
    seed: Option<Spanned<i64>>,
    samples: Option<Spanned<i64>>,
    #[serde(default)]
    vary: Vec<Spanned<RawVary>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVary {
    key: Spanned<String>,
    values: Option<Spanned<Vec<f64>>>,
    range: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    log: bool,
}

/// Writes `x` at `key` into a scene document. The parent must exist; the leaf may be new
/// (a table key) or must be a number (an array entry). Integers stay integers when `x` is
/// integral. `Ok(true)`: the leaf existed (its value was replaced); `Ok(false)`: it was
/// added. The errors do not depend on `x`.
fn set_in(root: &mut toml::Value, key: &str, x: f64) -> Result<bool, String> {
    let steps = parse_key(key).ok_or_else(|| {
        format!("`{key}` is not a key path (expected e.g. `integrator.alpha` or `rod[0].elements`)")
    })?;
    let new = |old: Option<&toml::Value>| -> Result<toml::Value, String> {
        match old {
            Some(toml::Value::Integer(_)) if x.fract() == 0.0 && x.abs() < 9e15 => {
                Ok(toml::Value::Integer(x as i64))
            }
            Some(toml::Value::Integer(_)) | Some(toml::Value::Float(_)) | None => {
                Ok(toml::Value::Float(x))
            }
            Some(v) => Err(format!(
                "the base scene's value there is a {}, not a number",
                v.type_str()
            )),
        }
    };
    let mut cur = root;
    for (i, st) in steps.iter().enumerate() {
        let last = i + 1 == steps.len();
        match st {
            Step::Key(k) if cur.is_array() && !last => {
                // An array of tables by name: `rod.beam.elements` is the rod named `beam`.
                let a = cur.as_array_mut().unwrap_or_else(|| unreachable!());
                let names: Vec<String> = a
                    .iter()
                    .filter_map(|v| v.get("name").and_then(|n| n.as_str()).map(String::from))
                    .collect();
                cur = a
                    .iter_mut()
                    .find(|v| v.get("name").and_then(|n| n.as_str()) == Some(k.as_str()))
                    .ok_or_else(|| {
                        format!(
                            "no entry named `{k}` here (named entries: {})",
                            if names.is_empty() {
                                "none".to_string()
                            } else {
                                names.join(", ")
                            }
                        )
                    })?;
            }
            Step::Key(k) => {
                let t = cur
                    .as_table_mut()
                    .ok_or_else(|| format!("`{k}` is not inside a table in the base scene"))?;
                if last {
                    let existed = t.contains_key(k);
                    let v = new(t.get(k))?;
                    t.insert(k.clone(), v);
                    return Ok(existed);
                }
                cur = t
                    .get_mut(k)
                    .ok_or_else(|| format!("the base scene has no `{k}` here"))?;
            }
            Step::Index(j) => {
                let a = cur
                    .as_array_mut()
                    .ok_or_else(|| format!("[{j}]: the base scene has no array here"))?;
                let n = a.len();
                let v = a
                    .get_mut(*j)
                    .ok_or_else(|| format!("index {j} out of range (the array has {n} entries)"))?;
                if last {
                    *v = new(Some(v))?;
                    return Ok(true);
                }
                cur = v;
            }
        }
    }
    Ok(true)
}

/// The key path of the value at a byte offset: `KEY` at top level, `vary[i].KEY` inside
/// the i-th `[[vary]]` table (the sweep format has no deeper nesting).
fn key_at(text: &str, offset: usize) -> String {
    let before = &text[..offset.min(text.len())];
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    let line_end = text[line_start..]
        .find('\n')
        .map(|i| line_start + i)
        .unwrap_or(text.len());
    let line = &text[line_start..line_end];
    let key = line.split('=').next().unwrap_or("").trim().to_string();
    let tables = before[..line_start]
        .lines()
        .filter(|l| l.trim_start().starts_with("[[vary]]"))
        .count();
    match (tables, line.contains('=')) {
        (0, _) => key,
        (n, true) => format!("vary[{}].{key}", n - 1),
        (n, false) => format!("vary[{}]", n - 1),
    }
}

/// 1-based line and column (in characters) of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().unwrap_or("").chars().count() + 1;
    (line, col)
}

impl SweepSpec {
    /// Number of members.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True when the sweep has no members.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Elements of the base scene.
    pub fn base_elements(&self) -> usize {
        self.base_footprint.elements as usize
    }

    /// What a member of the base scene holds (elements, nodes, contact spheres).
    pub fn base_footprint(&self) -> crate::scene::limits::Footprint {
        self.base_footprint
    }

    /// The sweep's identity: a hash of what determines its results — the base scene
    /// (normalized: parsed and re-serialized, so comments and layout do not count), the
    /// varied keys and every member's values (bit for bit). Recorded in `sweep.id` and
    /// checked by `--resume`.
    pub fn identity(&self) -> String {
        let base = self
            .base_text
            .parse::<toml::Table>()
            .map(|t| toml::to_string(&t).unwrap_or_default())
            .unwrap_or_else(|_| self.base_text.clone());
        let mut h = Fnv1a::default();
        h.write(b"cosserat-sweep-v1\0");
        h.write(base.as_bytes());
        h.write(b"\0");
        for p in &self.params {
            h.write(p.key.as_bytes());
            h.write(b"\0");
        }
        h.write(&(self.values.len() as u64).to_le_bytes());
        for v in self.values.iter().flatten() {
            h.write(&v.to_bits().to_le_bytes());
        }
        format!("{:016x}", h.0)
    }

    /// The scene of member `i` (the base scene with the member's values written in).
    pub fn member_scene(&self, i: usize) -> Result<Scene, SceneError> {
        let text = self
            .member_text(&self.values[i])
            .map_err(|reason| SceneError::Invalid {
                file: self.base_source.clone(),
                location: None,
                key: "(sweep)".into(),
                reason,
            })?;
        parse_scene(&text, &format!("{}#member{i}", self.base_source))
    }

    fn member_text(&self, vals: &[f64]) -> Result<String, String> {
        let mut doc: toml::Table = self.base_text.parse().map_err(|e| format!("{e}"))?;
        for (p, &x) in self.params.iter().zip(vals) {
            set_value_table(&mut doc, &p.key, x)?;
        }
        toml::to_string(&doc).map_err(|e| e.to_string())
    }
}

/// 64-bit FNV-1a: a stable hash (unlike `std`'s `DefaultHasher`, whose output may change
/// between Rust releases) for the sweep identity; not a defence against forgery.
struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// [`set_in`] on a table (keeps the table in place).
fn set_value_table(doc: &mut toml::Table, key: &str, x: f64) -> Result<bool, String> {
    let mut root = toml::Value::Table(std::mem::take(doc));
    let r = set_in(&mut root, key, x);
    if let toml::Value::Table(t) = root {
        *doc = t;
    }
    r
}

/// The scene `spec` (a file path or a built-in name, as for
/// [`load_scene`](crate::scene::load_scene)) with numbers written at scene key paths
/// (`integrator.dt`, `rod[0].elements`, `rod.beam.elements` for the rod named `beam`),
/// exactly as a sweep file's `[[vary]]` keys are written into its base scene, then
/// validated by the scene parser ([`crate::scene::parse_scene_with_sets`]): an error about
/// a value of the file gives its `FILE:LINE:COL` in the file as written, one about a value
/// from `sets` (or a key that cannot be set) names `--set KEY=VALUE`.
pub fn scene_with_overrides(spec: &str, sets: &[(String, f64)]) -> Result<Scene, String> {
    let path = Path::new(spec);
    let (text, source) = if path.exists() {
        (
            crate::scene::read_scene_file(path).map_err(|e| e.to_string())?,
            spec.to_string(),
        )
    } else if let Some(b) = builtin_scenes().iter().find(|b| b.name == spec) {
        (b.toml.to_string(), format!("builtin:{}", b.name))
    } else {
        return crate::scene::load_scene(spec).map_err(|e| e.to_string());
    };
    crate::scene::parse_scene_with_sets(&text, &source, sets).map_err(|e| e.to_string())
}

/// Reads a sweep file or its base scene as the scene loader does: a regular file of at
/// most [`crate::scene::MAX_SCENE_BYTES`] bytes (a device or pipe is refused unread).
fn read_capped(path: &Path) -> Result<String, SweepError> {
    crate::scene::read_scene_file(path).map_err(|e| match e {
        SceneError::Io { path, error } => SweepError::Io { path, error },
        other => SweepError::Io {
            path: path.display().to_string(),
            error: std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                other
                    .to_string()
                    .rsplit(": ")
                    .next()
                    .unwrap_or_default()
                    .to_string(),
            ),
        },
    })
}

/// Reads and validates a sweep file: syntax, keys, modes, ranges, that the base scene is
/// valid and that it accepts every varied key. The members' values are not checked here:
/// a member whose scene rejects its values is a `rejected` row of [`run_sweep`].
pub fn load_sweep(path: &Path) -> Result<SweepSpec, SweepError> {
    let file = path.display().to_string();
    let text = read_capped(path)?;
    let at = |off: usize| Some(line_col(&text, off));
    let invalid =
        |span: Option<std::ops::Range<usize>>, key: &str, reason: String| SweepError::Invalid {
            file: file.clone(),
            location: span.and_then(|s| at(s.start)),
            key: key.to_string(),
            reason,
        };
    let raw: RawSweep = toml::from_str(&text).map_err(|e| {
        let location = e.span().and_then(|s| at(s.start));
        let msg = e.message().trim().to_string();
        // serde reports unknown/missing/mistyped keys; name the key when it says which.
        let key = e
            .span()
            .map(|sp| key_at(&text, sp.start))
            .or_else(|| {
                msg.split('`')
                    .nth(1)
                    .filter(|_| msg.starts_with("missing field"))
                    .map(str::to_string)
            })
            .unwrap_or_else(|| "(top level)".into());
        if toml::de::DeTable::parse(&text).is_err() {
            SweepError::Syntax {
                file: file.clone(),
                location,
                reason: msg,
            }
        } else {
            SweepError::Invalid {
                file: file.clone(),
                location,
                key,
                reason: msg,
            }
        }
    })?;
    // Base scene: a path relative to the sweep file, else a built-in name.
    let base = raw.base.get_ref().clone();
    let rel: PathBuf = path.parent().unwrap_or(Path::new(".")).join(&base);
    let (base_text, base_source) = if rel.is_file() {
        let t = read_capped(&rel)?;
        (t, rel.display().to_string())
    } else if let Some(b) = builtin_scenes().iter().find(|b| b.name == base) {
        (b.toml.to_string(), format!("builtin:{}", b.name))
    } else {
        let names: Vec<&str> = builtin_scenes().iter().map(|b| b.name).collect();
        return Err(invalid(
            Some(raw.base.span()),
            "base",
            format!(
                "no scene file {} and no built-in scene `{base}` (built-in: {})",
                rel.display(),
                names.join(", ")
            ),
        ));
    };
    let mode = match raw.mode.as_ref().map(|m| m.get_ref().as_str()) {
        None | Some("grid") => SweepMode::Grid,
        Some("list") => SweepMode::List,
        Some("random") => SweepMode::Random,
        Some(other) => {
            return Err(invalid(
                raw.mode.as_ref().map(|m| m.span()),
                "mode",
                format!("must be \"grid\", \"list\" or \"random\" (got \"{other}\")"),
            ))
        }
    };
    if raw.vary.is_empty() {
        return Err(invalid(
            None,
            "vary",
            "no [[vary]] table: name at least one parameter to vary".into(),
        ));
    }
    let mut params = Vec::new();
    let mut lists: Vec<Vec<f64>> = Vec::new();
    let mut ranges: Vec<(f64, f64, bool)> = Vec::new();
    for (i, v) in raw.vary.iter().enumerate() {
        let v = v.get_ref();
        let k = v.key.get_ref();
        if parse_key(k).is_none() {
            return Err(invalid(
                Some(v.key.span()),
                &format!("vary[{i}].key"),
                format!("`{k}` is not a key path (expected e.g. `integrator.alpha` or `rod[0].elements`)"),
            ));
        }
        if params.iter().any(|p: &VaryParam| p.key == *k) {
            return Err(invalid(
                Some(v.key.span()),
                &format!("vary[{i}].key"),
                format!("`{k}` is varied twice"),
            ));
        }
        params.push(VaryParam { key: k.clone() });
        match mode {
            SweepMode::Grid | SweepMode::List => {
                let Some(vals) = &v.values else {
                    return Err(invalid(
                        Some(v.key.span()),
                        &format!("vary[{i}]"),
                        format!("mode {mode:?} needs `values = [...]`").to_lowercase(),
                    ));
                };
                if vals.get_ref().is_empty() {
                    return Err(invalid(
                        Some(vals.span()),
                        &format!("vary[{i}].values"),
                        "must not be empty".into(),
                    ));
                }
                if let Some(x) = vals.get_ref().iter().find(|x| !x.is_finite()) {
                    return Err(invalid(
                        Some(vals.span()),
                        &format!("vary[{i}].values"),
                        format!("must be finite numbers (got {x})"),
                    ));
                }
                lists.push(vals.get_ref().clone());
            }
            SweepMode::Random => {
                let Some(r) = &v.range else {
                    return Err(invalid(
                        Some(v.key.span()),
                        &format!("vary[{i}]"),
                        "mode random needs `range = [lo, hi]`".into(),
                    ));
                };
                let rv = r.get_ref();
                let ok = rv.len() == 2
                    && rv.iter().all(|x| x.is_finite())
                    && rv[0] <= rv[1]
                    && (!v.log || rv[0] > 0.0);
                if !ok {
                    return Err(invalid(
                        Some(r.span()),
                        &format!("vary[{i}].range"),
                        format!(
                            "must be [lo, hi] with finite lo ≤ hi{} (got {rv:?})",
                            if v.log {
                                " and lo > 0 (log = true)"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
                ranges.push((rv[0], rv[1], v.log));
            }
        }
    }
    // The number of members and their memory, before allocating anything per member.
    let (count, count_key, count_span) = match mode {
        SweepMode::Grid => (
            lists
                .iter()
                .fold(1u64, |a, l| a.saturating_mul(l.len() as u64)),
            "vary",
            None,
        ),
        SweepMode::List => (lists[0].len() as u64, "vary", None),
        SweepMode::Random => match &raw.samples {
            Some(s) => (
                u64::try_from(*s.get_ref()).unwrap_or(0),
                "samples",
                Some(s.span()),
            ),
            None => (0, "samples", None),
        },
    };
    if count > crate::scene::limits::MAX_MEMBERS {
        return Err(invalid(
            count_span.clone(),
            count_key,
            format!(
                "{count} members, above the limit of {} members per sweep",
                crate::scene::limits::MAX_MEMBERS
            ),
        ));
    }
    let base_scene = parse_scene(&base_text, &base_source)
        .map_err(|e| invalid(Some(raw.base.span()), "base", format!("base scene: {e}")))?;
    let base_footprint = crate::scene::limits::Footprint::of_model(&base_scene.model);
    drop(base_scene);
    crate::scene::limits::check_batch("this sweep", count, &base_footprint)
        .map_err(|e| invalid(count_span, count_key, e.to_string()))?;
    let values: Vec<Vec<f64>> = match mode {
        SweepMode::Grid => {
            let mut out = vec![vec![]];
            for l in &lists {
                out = out
                    .into_iter()
                    .flat_map(|pre| {
                        l.iter().map(move |&x| {
                            let mut p = pre.clone();
                            p.push(x);
                            p
                        })
                    })
                    .collect();
            }
            out
        }
        SweepMode::List => {
            let n = lists[0].len();
            if let Some((i, l)) = lists.iter().enumerate().find(|(_, l)| l.len() != n) {
                return Err(invalid(
                    raw.vary[i].get_ref().values.as_ref().map(|v| v.span()),
                    &format!("vary[{i}].values"),
                    format!(
                        "mode list needs equal lengths: {} values here, {n} in vary[0]",
                        l.len()
                    ),
                ));
            }
            (0..n)
                .map(|m| lists.iter().map(|l| l[m]).collect())
                .collect()
        }
        SweepMode::Random => {
            let Some(samples) = &raw.samples else {
                return Err(invalid(
                    None,
                    "samples",
                    "mode random needs `samples = N`".into(),
                ));
            };
            let n = *samples.get_ref();
            if n < 1 {
                return Err(invalid(
                    Some(samples.span()),
                    "samples",
                    format!("must be ≥ 1 (got {n})"),
                ));
            }
            let seed = raw.seed.as_ref().map(|s| *s.get_ref()).unwrap_or(0);
            let mut rng = Rng::new(seed as u64);
            (0..n)
                .map(|_| {
                    ranges
                        .iter()
                        .map(|&(lo, hi, log)| {
                            let u = rng.uniform();
                            if log {
                                // exp/ln only here, on the host.
                                (lo.ln() + u * (hi.ln() - lo.ln())).exp()
                            } else {
                                lo + u * (hi - lo)
                            }
                        })
                        .collect()
                })
                .collect()
        }
    };
    let spec = SweepSpec {
        source: file.clone(),
        base,
        base_text,
        base_source,
        mode,
        params,
        values,
        base_footprint,
    };
    // Every key must be one the base scene has room for: the path must lead into the
    // base scene (checked by writing the first member's value; the path errors do not
    // depend on the value), and a key the base scene does not have yet must be one the
    // scene format knows. Whether a member's *values* are valid is that member's result
    // (a `rejected` row), the first member's as any other's.
    for (i, p) in spec.params.iter().enumerate() {
        let span = Some(raw.vary[i].get_ref().key.span());
        let mut doc: toml::Table = spec
            .base_text
            .parse()
            .map_err(|e| invalid(None, "base", format!("base scene: {e}")))?;
        let existed = set_value_table(&mut doc, &p.key, spec.values[0][i])
            .map_err(|r| invalid(span.clone(), &format!("vary[{i}].key"), r))?;
        if existed {
            continue;
        }
        let t = toml::to_string(&doc).map_err(|e| invalid(None, "base", e.to_string()))?;
        crate::scene::check_scene_keys(&t, &spec.base_source).map_err(|e| {
            invalid(
                span.clone(),
                &format!("vary[{i}].key"),
                format!("base scene rejects it: {e}"),
            )
        })?;
    }
    Ok(spec)
}
