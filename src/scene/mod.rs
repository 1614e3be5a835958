//! Scene files: a TOML description of rods, materials, sections, supports, loads, initial
//! velocities and integrator settings, parsed and validated into a [`Model`] and
//! [`IntegratorParams`]. This module knows no physics; it only builds and checks data.
//!
//! The format is documented key by key in `docs/scenes.md`. Parsing happens in three
//! stages:
//!
//! 1. toml parses the text into its spanned document tree (syntax errors stop here, with
//!    `line:column`);
//! 2. serde structs with `deny_unknown_fields` (`raw.rs`) reject unknown keys and wrong
//!    types — the error's byte span is mapped back to the key path;
//! 3. a validation pass (`build/`) checks every value and builds the model; each error
//!    names the key path and, through the document tree, its `line:column`.
//!
//! Every error reads `FILE[:LINE:COL]: KEY: REASON`, e.g.
//! `scenes/bad.toml:12:7: integrator.dt: must be > 0 (got -0.1)`.

mod build;
pub mod limits;
mod raw;
pub(crate) mod set;
mod span;

use std::borrow::Cow;
use std::fmt::Write as _;
use std::io::Read as _;
use std::path::Path;

use serde::Deserialize;

use crate::integrator::params::{IntegratorParams, Scheme, Strategy};
use crate::model::{Model, Vec3};

/// A loaded and validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Scene name (`name` key, else the file stem).
    pub name: String,
    /// Where it came from: the path as given, or `builtin:NAME`.
    pub source: String,
    /// Optional free text (`description` key; empty when absent).
    pub description: String,
    /// The discretized problem.
    pub model: Model,
    /// Time integration parameters.
    pub params: IntegratorParams,
    /// Record every `output_every`-th step (≥ 1, default 1).
    pub output_every: usize,
    /// `[[probe]]` nodes whose state goes to `probes.csv` every step.
    pub probes: Vec<Probe>,
    /// Whether the scene's `[integrator]` table sets `cutback` (else `params.cutback` is
    /// the library's default: 0, or 6 with friction; `run` and `sweep` then cut back up to
    /// [`RUN_CUTBACK`] halvings).
    pub cutback_set: bool,
}

/// The step cut-back `cosserat run` and `cosserat sweep` use when neither the scene nor
/// `--cutback` sets one: a step Newton cannot solve at Δt is redone as up to 2⁴ = 16
/// sub-steps, so that a run does not die where a smaller step passes (outputs stay on the Δt
/// grid; cut-back steps are counted). The stability study keeps it off.
pub const RUN_CUTBACK: usize = 4;

impl Scene {
    /// The cut-back of a `run` or `sweep` member of this scene when `--cutback` is not
    /// given: the scene's own where it sets one, else at least [`RUN_CUTBACK`].
    pub fn run_cutback(&self) -> usize {
        if self.cutback_set {
            self.params.cutback
        } else {
            self.params.cutback.max(RUN_CUTBACK)
        }
    }
}

/// A `[[probe]]`: a named node observed every step.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    /// Column prefix in `probes.csv` (`probe{i}` by default).
    pub name: String,
    /// The node.
    pub node: usize,
}

/// A scene shipped inside the binary.
#[derive(Clone, Copy, Debug)]
pub struct BuiltinScene {
    /// Name accepted by [`load_scene`].
    pub name: &'static str,
    /// One-line description.
    pub description: &'static str,
    /// The scene file's text.
    pub toml: &'static str,
}

static BUILTINS: &[BuiltinScene] = &[
    BuiltinScene {
        name: "frame",
        description:
            "free-flying frame of three rods at two right angles (paper §5.1; reconstruction in docs/theory.md)",
        toml: include_str!("../../scenes/frame.toml"),
    },
    BuiltinScene {
        name: "cantilever",
        description: "clamped 50-element 3D cantilever, tip kicked obliquely (speed benchmark)",
        toml: include_str!("../../scenes/cantilever.toml"),
    },
    BuiltinScene {
        name: "cantilever_planar",
        description: "clamped 50-element cantilever moving in the e1-e2 plane (planar kernel speed benchmark)",
        toml: include_str!("../../scenes/cantilever_planar.toml"),
    },
    BuiltinScene {
        name: "arch",
        description: "shallow arch snap-through under a ramped apex load (paper §5.2; reconstruction in docs/theory.md)",
        toml: include_str!("../../scenes/arch.toml"),
    },
    BuiltinScene {
        name: "mechanism",
        description:
            "plane four-bar: flexible coupler, rigid links, point masses (paper §5.3, square)",
        toml: include_str!("../../scenes/mechanism.toml"),
    },
    BuiltinScene {
        name: "mechanism_hexagon",
        description: "plane four-bar, half-hexagon reading that bends the coupler (paper §5.3)",
        toml: include_str!("../../scenes/mechanism_hexagon.toml"),
    },
    BuiltinScene {
        name: "bounce",
        description: "tilted elastic rod dropped onto a rigid frictionless floor (contact)",
        toml: include_str!("../../scenes/bounce.toml"),
    },
    BuiltinScene {
        name: "capstan",
        description: "cable over a fixed drum with friction, end tensions near the capstan limit (contact)",
        toml: include_str!("../../scenes/capstan.toml"),
    },
    BuiltinScene {
        name: "crossing",
        description: "two crossing rods thrown at each other in free flight, off-centre (contact between rods)",
        toml: include_str!("../../scenes/crossing.toml"),
    },
    BuiltinScene {
        name: "plectoneme",
        description: "clamped rod twisted 5 turns while its ends close in: a self-contacting plectoneme (contact)",
        toml: include_str!("../../scenes/plectoneme.toml"),
    },
];

/// Everything that can go wrong loading a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file could not be read.
    #[error("cannot read {path}: {error}")]
    Io {
        /// The path as given.
        path: String,
        /// The underlying error.
        #[source]
        error: std::io::Error,
    },
    /// The spec is neither an existing file nor a built-in scene name.
    #[error(
        "unknown scene `{}`: no such file and no built-in scene of that name (built-in scenes: {})",
        echo(.name), .available.join(", ")
    )]
    UnknownBuiltin {
        /// The spec as given.
        name: String,
        /// Names of the built-in scenes.
        available: Vec<String>,
    },
    /// The text is not valid TOML.
    #[error("{}: {reason}", located(.file, *.location))]
    Syntax {
        /// Path of the file (or `builtin:NAME`).
        file: String,
        /// 1-based line and column, when toml gives a span.
        location: Option<(usize, usize)>,
        /// toml's message.
        reason: String,
    },
    /// A key is unknown, has the wrong type, is missing, or has an invalid value.
    #[error("{}: {key}: {reason}", located(.file, *.location))]
    Invalid {
        /// Path of the file (or `builtin:NAME`).
        file: String,
        /// 1-based line and column of the key's value (or of its nearest enclosing table).
        location: Option<(usize, usize)>,
        /// Key path, e.g. `rod[1].points` or `integrator.dt` (`(top level)` for the root).
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A value given on the command line (`--set KEY=VALUE`) is invalid, or cannot be
    /// written into the scene.
    #[error("--set {set} (on {file}): {key}: {reason}")]
    Set {
        /// Path of the scene file (or `builtin:NAME`) the override applies to.
        file: String,
        /// The override as `KEY=VALUE`.
        set: String,
        /// Key path of the value, e.g. `integrator.dt` (for a value the override wrote,
        /// the key as resolved in the scene, e.g. `rod[0].elements` for `rod.beam.elements`).
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The scene file is larger than [`MAX_SCENE_BYTES`].
    #[error("{path}: scene file larger than {} MiB", MAX_SCENE_BYTES >> 20)]
    TooLarge {
        /// The path as given.
        path: String,
    },
}

/// Largest scene file read, in bytes (64 MiB): a larger file (or an endless one) is
/// refused after reading one byte more than this.
pub const MAX_SCENE_BYTES: u64 = 64 << 20;

/// Longest value (in characters) an error message echoes whole; longer ones are cut by
/// [`echo`].
pub(crate) const MAX_ECHO: usize = 60;

/// `s` as an error message echoes it: whole when at most [`MAX_ECHO`] characters long,
/// else its first characters and `… (N bytes)`.
pub(crate) fn echo(s: &str) -> Cow<'_, str> {
    match s.char_indices().nth(MAX_ECHO) {
        None => Cow::Borrowed(s),
        Some(_) => {
            let cut = s
                .char_indices()
                .nth(MAX_ECHO - 12)
                .map_or(s.len(), |(i, _)| i);
            Cow::Owned(format!("{}… ({} bytes)", &s[..cut], s.len()))
        }
    }
}

/// An error reason with everything it echoes cut by [`echo`]: each quoted part (between
/// backticks or double quotes) and each other word longer than [`MAX_ECHO`] characters, so
/// that a long key, string or number is never echoed whole.
pub(crate) fn cap_echoes(msg: &str) -> String {
    let words = |s: &str| -> String { s.split(' ').map(|w| echo(w)).collect::<Vec<_>>().join(" ") };
    let mut out = String::with_capacity(msg.len().min(8 * MAX_ECHO));
    let mut rest = msg;
    while let Some(open) = rest.find(['`', '"']) {
        let q = if rest[open..].starts_with('`') {
            '`'
        } else {
            '"'
        };
        out.push_str(&words(&rest[..open]));
        out.push(q);
        rest = &rest[open + 1..];
        match rest.find(q) {
            Some(close) => {
                out.push_str(&echo(&rest[..close]));
                out.push(q);
                rest = &rest[close + 1..];
            }
            None => {
                out.push_str(&echo(rest));
                return out;
            }
        }
    }
    out.push_str(&words(rest));
    out
}

/// Reads a scene file: a regular file of at most [`MAX_SCENE_BYTES`] bytes of UTF-8
/// (a device, pipe or directory is refused before reading, so nothing endless is read).
pub fn read_scene_file(path: &Path) -> Result<String, SceneError> {
    let shown = path.display().to_string();
    let io = |error| SceneError::Io {
        path: shown.clone(),
        error,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file",
        )));
    }
    if meta.len() > MAX_SCENE_BYTES {
        return Err(SceneError::TooLarge { path: shown });
    }
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::new();
    file.take(MAX_SCENE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_SCENE_BYTES {
        return Err(SceneError::TooLarge { path: shown });
    }
    String::from_utf8(bytes).map_err(|e| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text ({e})"),
        ))
    })
}

fn located(file: &str, location: Option<(usize, usize)>) -> String {
    match location {
        Some((l, c)) => format!("{file}:{l}:{c}"),
        None => file.to_string(),
    }
}

impl SceneError {
    /// The key path the error is about, when it is about one.
    pub fn key(&self) -> Option<&str> {
        match self {
            SceneError::Invalid { key, .. } | SceneError::Set { key, .. } => Some(key),
            _ => None,
        }
    }

    /// 1-based `(line, column)` of the error, when known.
    pub fn location(&self) -> Option<(usize, usize)> {
        match self {
            SceneError::Syntax { location, .. } | SceneError::Invalid { location, .. } => *location,
            _ => None,
        }
    }
}

/// The scenes shipped with the crate.
pub fn builtin_scenes() -> &'static [BuiltinScene] {
    BUILTINS
}

/// Loads a scene from a file path or a built-in name. A path that exists wins over a
/// built-in of the same name.
pub fn load_scene(spec: &str) -> Result<Scene, SceneError> {
    let path = Path::new(spec);
    if path.exists() {
        let text = read_scene_file(path)?;
        return parse_scene(&text, spec);
    }
    if let Some(b) = BUILTINS.iter().find(|b| b.name == spec) {
        return parse_scene(b.toml, &format!("builtin:{}", b.name));
    }
    let looks_like_path =
        spec.contains('/') || spec.contains(std::path::MAIN_SEPARATOR) || spec.ends_with(".toml");
    if looks_like_path {
        // Let the OS say why (normally "No such file or directory").
        let error = std::fs::read_to_string(path)
            .err()
            .unwrap_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"));
        return Err(SceneError::Io {
            path: spec.to_string(),
            error,
        });
    }
    Err(SceneError::UnknownBuiltin {
        name: spec.to_string(),
        available: BUILTINS.iter().map(|b| b.name.to_string()).collect(),
    })
}

/// Parses and validates scene text. `source` names it in errors and in [`Scene::source`]
/// (a path, or `builtin:NAME`); its file stem is the default scene name.
pub fn parse_scene(text: &str, source: &str) -> Result<Scene, SceneError> {
    parse_scene_with_sets(text, source, &[])
}

/// The first stage of [`parse_scene`] alone: TOML syntax, known keys and value types,
/// without the checks of the values themselves (ranges, references, geometry). What a
/// sweep checks to tell a key the scene format does not have from a value it rejects.
pub fn check_scene_keys(text: &str, source: &str) -> Result<(), SceneError> {
    parse_raw(text, source, &[], &[]).map(drop)
}

/// [`parse_scene`] with numbers written at scene key paths first (`--set KEY=VALUE`:
/// `integrator.dt`, `rod[0].elements`, or `rod.beam.elements` for the rod named `beam`).
/// The overrides are written into the parsed document of `text` itself, so an error about
/// a value of the file gives its `FILE:LINE:COL` in `text`, and an error about a value an
/// override wrote (or an override that cannot be written) is a [`SceneError::Set`] naming
/// that override.
pub fn parse_scene_with_sets(
    text: &str,
    source: &str,
    sets: &[(String, f64)],
) -> Result<Scene, SceneError> {
    let numbers: Vec<set::NumberText> =
        sets.iter().map(|(_, x)| set::NumberText::new(*x)).collect();
    let (raw, doc) = parse_raw(text, source, sets, &numbers)?;
    build::build(raw, &doc, source)
}

fn parse_raw<'t>(
    text: &'t str,
    source: &str,
    sets: &[(String, f64)],
    numbers: &'t [set::NumberText],
) -> Result<(raw::RawScene, span::Doc<'t>), SceneError> {
    let labels: Vec<String> = sets
        .iter()
        .map(|(k, x)| format!("{}={x}", echo(k)))
        .collect();
    let mut root = toml::de::DeTable::parse(text).map_err(|e| SceneError::Syntax {
        file: source.to_string(),
        location: e.span().map(|s| span::line_col(text, s.start)),
        reason: cap_echoes(e.message().trim()),
    })?;
    for (k, ((key, _), num)) in sets.iter().zip(numbers).enumerate() {
        set::set_in(root.get_mut(), key, num, span::Doc::set_span(text.len(), k)).map_err(
            |reason| SceneError::Set {
                file: source.to_string(),
                set: labels[k].clone(),
                key: echo(key).into_owned(),
                reason,
            },
        )?;
    }
    let doc = span::Doc::with_sets(text, root, labels);
    let raw = raw::RawScene::deserialize(toml::de::Deserializer::from(doc.root().clone()))
        .map_err(|e| {
            let key = e
                .span()
                .map_or_else(span::KeyPath::root, |s| doc.path_at(s.start));
            doc.error(
                source,
                e.span().map(|s| s.start),
                key_name(&key),
                cap_echoes(e.message().trim()),
            )
        })?;
    Ok((raw, doc))
}

pub(crate) fn key_name(path: &span::KeyPath) -> String {
    if path.is_root() {
        "(top level)".to_string()
    } else {
        path.to_string()
    }
}

fn fmt_vec(v: &Vec3) -> String {
    format!("({}, {}, {})", v.x, v.y, v.z)
}

/// At most this many lines per list in [`Scene::describe`].
const LIST_MAX: usize = 12;

impl Scene {
    /// A multi-line human summary (what `cosserat check` prints): rods, mesh size and
    /// degrees of freedom, supports, point masses, loads, gravity, initial velocities and
    /// integrator parameters.
    pub fn describe(&self) -> String {
        let m = &self.model;
        let mut s = String::new();
        let _ = writeln!(s, "scene {} ({})", self.name, self.source);
        if !self.description.is_empty() {
            let _ = writeln!(s, "  {}", self.description.trim());
        }

        let rod_mass: f64 = m.elements.iter().map(|e| e.props.a_rho * e.props.h).sum();
        let point_mass: f64 = m.point_mass.iter().sum();
        let _ = writeln!(s, "rods: {}", m.rods.len());
        for r in &m.rods {
            let els = &m.elements[r.elements.clone()];
            let length: f64 = els.iter().map(|e| e.props.h).sum();
            let mut nodes: Vec<usize> = els.iter().flat_map(|e| e.nodes).collect();
            nodes.sort_unstable();
            nodes.dedup();
            let _ = writeln!(
                s,
                "  {}: {} elements, {} nodes, length {}",
                r.name,
                els.len(),
                nodes.len(),
                fmt_num(length)
            );
        }
        // Newton unknowns (u, θ) per node without the translational-dissipation g, which
        // exists only for schemes that need it.
        let dofs = crate::integrator::dofs::DofMap::new(m, false);
        let removed = 6 * m.n_nodes() - dofs.n;
        let _ = writeln!(s, "nodes: {}", m.n_nodes());
        let _ = writeln!(s, "elements: {}", m.elements.len());
        let why = match m.planar {
            Some(p) => format!("by supports and the plane {}", p.name()),
            None => "by supports".to_string(),
        };
        let _ = writeln!(
            s,
            "DOFs: {} (6 per node = {}, {removed} removed {why}; EDMC translational dissipation adds a g unknown per free translation)",
            dofs.n,
            6 * m.n_nodes(),
        );
        if let Some(p) = m.planar {
            let _ = writeln!(
                s,
                "planar: {} (normal e{}; CPU path: planar element kernel, 3 unknowns per free node)",
                p.name(),
                p.normal + 1
            );
        }
        let _ = writeln!(
            s,
            "mass: {} (rods {}, point masses {})",
            fmt_num(rod_mass + point_mass),
            fmt_num(rod_mass),
            fmt_num(point_mass)
        );

        let supports: Vec<(usize, &str)> = m
            .supports
            .iter()
            .enumerate()
            .filter_map(|(a, sp)| match (sp.translation, sp.rotation) {
                (true, true) => Some((a, "clamp")),
                (true, false) => Some((a, "pin")),
                (false, true) => Some((a, "rotation fixed")),
                (false, false) => None,
            })
            .collect();
        let n_clamp = supports.iter().filter(|x| x.1 == "clamp").count();
        let n_pin = supports.iter().filter(|x| x.1 == "pin").count();
        let _ = writeln!(s, "supports: {n_clamp} clamps, {n_pin} pins");
        list(&mut s, supports.iter(), |(a, kind)| {
            let slide = m
                .slides
                .iter()
                .find(|sl| sl.node == *a)
                .map_or_else(String::new, |sl| {
                    let axis = sl
                        .coordinate_axis()
                        .map_or_else(|| fmt_vec(&sl.axis), |k| format!("e{}", k + 1));
                    format!(
                        ", sliding along {axis}{}",
                        if sl.spin { " and turning about it" } else { "" }
                    )
                });
            format!("{kind} at node {a} {}{slide}", fmt_vec(&m.nodes[*a]))
        });

        if !m.drives.is_empty() {
            let _ = writeln!(s, "moving supports: {}", m.drives.len());
            list(&mut s, m.drives.iter(), |d| {
                format!(
                    "node {} {}: displacement {}, rotation {} at factor 1, {} ramp over t = {} … {}",
                    d.node,
                    fmt_vec(&m.nodes[d.node]),
                    fmt_vec(&d.displacement),
                    fmt_vec(&d.rotation),
                    match d.ramp {
                        crate::model::Ramp::Linear => "linear",
                        crate::model::Ramp::Smooth => "smooth",
                    },
                    fmt_num(d.table.times[0]),
                    fmt_num(*d.table.times.last().unwrap_or(&0.0))
                )
            });
        }

        let masses: Vec<(usize, f64)> = m
            .point_mass
            .iter()
            .enumerate()
            .filter(|(_, &x)| x != 0.0)
            .map(|(a, &x)| (a, x))
            .collect();
        let _ = writeln!(s, "point masses: {}", masses.len());
        list(&mut s, masses.iter(), |(a, x)| {
            format!("{} at node {a} {}", fmt_num(*x), fmt_vec(&m.nodes[*a]))
        });

        let _ = writeln!(s, "rigid links: {}", m.links.len());
        list(&mut s, m.links.iter(), |l| {
            format!(
                "pivot {} — node {} {}, length {}, penalty {}, tol {}",
                fmt_vec(&l.pivot),
                l.node,
                fmt_vec(&m.nodes[l.node]),
                fmt_num(l.length),
                fmt_num(l.penalty),
                fmt_num(l.tol)
            )
        });

        let _ = writeln!(s, "loads: {}", m.loads.len());
        list(&mut s, m.loads.iter(), |l| {
            let table = if l.table == crate::model::TimeTable::constant_one() {
                "constant factor 1".to_string()
            } else {
                let pts: Vec<String> = l
                    .table
                    .times
                    .iter()
                    .zip(&l.table.values)
                    .map(|(t, f)| format!("({}, {})", fmt_num(*t), fmt_num(*f)))
                    .collect();
                format!("factor table (t, f): {}", pts.join(" "))
            };
            format!(
                "node {} {}: force {}, moment {}, {}",
                l.node,
                fmt_vec(&m.nodes[l.node]),
                fmt_vec(&l.force),
                fmt_vec(&l.moment),
                table
            )
        });

        if !m.line_loads.is_empty() {
            let _ = writeln!(s, "line loads: {}", m.line_loads.len());
            list(&mut s, m.line_loads.iter(), |l| {
                format!(
                    "{} on {} elements: force {} and moment {} per length{}",
                    if l.follower {
                        "follower (director components)"
                    } else {
                        "dead"
                    },
                    l.elements.len(),
                    fmt_vec(&l.force),
                    fmt_vec(&l.moment),
                    if l.table == crate::model::TimeTable::constant_one() {
                        ""
                    } else {
                        ", scaled by a time table"
                    },
                )
            });
        }
        if !m.obstacles.is_empty() {
            let _ = writeln!(s, "obstacles: {}", m.obstacles.len());
            list(&mut s, m.obstacles.iter(), |o| {
                use crate::obstacle::Shape;
                let geometry = match &o.shape {
                    Shape::Plane { point, normal } => {
                        format!(
                            "plane through {} normal {}",
                            fmt_vec(point),
                            fmt_vec(normal)
                        )
                    }
                    Shape::Sphere { center, radius } => {
                        format!("sphere at {} radius {}", fmt_vec(center), fmt_num(*radius))
                    }
                    Shape::Cylinder {
                        point,
                        axis,
                        radius,
                    } => format!(
                        "cylinder through {} axis {} radius {}",
                        fmt_vec(point),
                        fmt_vec(axis),
                        fmt_num(*radius)
                    ),
                };
                let friction = if o.friction > 0.0 {
                    match o.law {
                        crate::obstacle::FrictionLaw::Regularized => format!(
                            "friction μ = {} (slip {} m/s)",
                            fmt_num(o.friction),
                            fmt_num(o.slip)
                        ),
                        crate::obstacle::FrictionLaw::Stick { stiffness } => format!(
                            "friction μ = {} (stick, tangential stiffness {} N/m²)",
                            fmt_num(o.friction),
                            fmt_num(stiffness)
                        ),
                    }
                } else {
                    "frictionless".to_string()
                };
                format!(
                    "{geometry}: {} contact nodes, stiffness {} N/m², {friction}",
                    o.nodes.len(),
                    fmt_num(o.stiffness)
                )
            });
        }
        if !m.rod_contacts.is_empty() {
            let _ = writeln!(s, "contact between rods: {}", m.rod_contacts.len());
            list(&mut s, m.rod_contacts.iter(), |c| {
                let what = match c.model {
                    crate::rod_contact::ContactModel::Spheres => "contact spheres",
                    crate::rod_contact::ContactModel::Line => "line-contact quadrature points",
                    crate::rod_contact::ContactModel::Smooth => "smooth-contact quadrature points",
                };
                format!(
                    "{}: {} {what} of radius up to {}, stiffness {} N/m², frictionless",
                    if c.is_self() {
                        format!("rod {} with itself", c.rods[0])
                    } else {
                        format!("rods {} and {}", c.rods[0], c.rods[1])
                    },
                    c.points.len(),
                    fmt_num(c.max_radius()),
                    fmt_num(c.stiffness)
                )
            });
        }
        if m.gravity == Vec3::zeros() {
            let _ = writeln!(s, "gravity: none");
        } else {
            let _ = writeln!(s, "gravity: {}", fmt_vec(&m.gravity));
        }

        let sh = &m.shape;
        if sh.positions.is_empty() {
            let _ = writeln!(s, "initial configuration: the reference");
        } else {
            let (mut dx, mut dphi, mut moved) = (0.0f64, 0.0f64, 0usize);
            for a in 0..m.n_nodes() {
                let d = (m.initial_position(a) - m.nodes[a]).norm();
                let phi = ((m.initial_rotation(a).trace() - 1.0) / 2.0)
                    .clamp(-1.0, 1.0)
                    .acos();
                dx = dx.max(d);
                dphi = dphi.max(phi);
                moved += usize::from(d > 0.0 || phi > 0.0);
            }
            let _ = writeln!(
                s,
                "initial configuration: {moved} of {} nodes away from the reference (largest displacement {}, largest rotation {} rad)",
                m.n_nodes(),
                fmt_num(dx),
                fmt_num(dphi)
            );
        }
        let curved = sh.curvature.iter().filter(|k| **k != Vec3::zeros()).count();
        if curved > 0 {
            let _ = writeln!(s, "intrinsic curvature: on {curved} elements");
        }

        let moving: Vec<usize> = (0..m.n_nodes())
            .filter(|&a| m.velocity0[a] != Vec3::zeros() || m.omega0[a] != Vec3::zeros())
            .collect();
        let _ = writeln!(
            s,
            "initial velocities: {} of {} nodes moving",
            moving.len(),
            m.n_nodes()
        );
        list(&mut s, moving.iter(), |&&a| {
            format!(
                "node {a} {}: v {}, omega {}",
                fmt_vec(&m.nodes[a]),
                fmt_vec(&m.velocity0[a]),
                fmt_vec(&m.omega0[a])
            )
        });
        if m.is_free_flight() {
            let _ = writeln!(s, "free flight: momenta are conserved");
        }

        let p = &self.params;
        let scheme = match p.scheme {
            Scheme::Em => "em".to_string(),
            Scheme::Edmc1 {
                chi_gamma,
                chi_omega,
                chi_v,
                chi_nu,
            } => format!(
                "edmc1 (chi_gamma {chi_gamma}, chi_omega {chi_omega}, chi_v {chi_v}, chi_nu {chi_nu})"
            ),
            Scheme::Edmc2 {
                alpha_gv,
                alpha_gn,
                alpha_ov,
                alpha_on,
            } => format!(
                "edmc2 (alpha_gv {alpha_gv}, alpha_gn {alpha_gn}, alpha_ov {alpha_ov}, alpha_on {alpha_on})"
            ),
            Scheme::Midpoint => "midpoint".to_string(),
            Scheme::GenAlpha { rho_inf } => format!("gen-alpha (rho_inf {rho_inf})"),
        };
        let strategy = match p.strategy {
            Strategy::Auto if p.fallback => {
                "auto (monolithic on the CPU kernel, staggered on a GPU; with fallback)"
            }
            Strategy::Auto => {
                "auto (monolithic on the CPU kernel, staggered on a GPU; no fallback)"
            }
            Strategy::Monolithic if p.fallback => "monolithic (staggered fallback)",
            Strategy::Monolithic => "monolithic (no fallback)",
            Strategy::Staggered if p.fallback => "staggered (monolithic fallback)",
            Strategy::Staggered => "staggered (no fallback)",
            Strategy::Inexact if p.fallback => "inexact (monolithic fallback)",
            Strategy::Inexact => "inexact (no fallback)",
        };
        let _ = writeln!(s, "integrator: {scheme}");
        let _ = writeln!(
            s,
            "  dt {}, t_end {} ({} steps), output every {} step(s)",
            p.dt,
            p.t_end,
            p.n_steps(),
            self.output_every
        );
        let _ = writeln!(
            s,
            "  strategy {strategy}, newton {}, newton_tol {:e}, max_iter {}, outer_tol {:e}, max_outer {}, energy_tol {:e}",
            p.newton.name(),
            p.newton_tol, p.max_iter, p.outer_tol, p.max_outer, p.energy_tol
        );
        printable(&s)
    }

    /// The scene name as a file stem that cannot leave an output folder
    /// ([`crate::paths::safe_stem`]): what `run` names its default folder and VTK files by.
    pub fn file_stem(&self) -> String {
        crate::paths::safe_stem(&self.name)
    }
}

/// `text` with every control character except newline shown as an escape (`\u{1b}`),
/// so a scene's name or description cannot drive the terminal.
pub fn printable(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_control() && c != '\n' {
                c.escape_unicode().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// Seven significant digits, printed shortest; scientific notation outside [1e-4, 1e9)
/// (`10.000000000000002` → `10`, `3.2e-12` stays short).
pub(crate) fn fmt_num(x: f64) -> String {
    let r: f64 = format!("{x:.6e}").parse().unwrap_or(x);
    if r == 0.0 {
        "0".to_string()
    } else if !r.is_finite() || (1e-4..1e9).contains(&r.abs()) {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

fn list<T>(s: &mut String, items: impl ExactSizeIterator<Item = T>, f: impl Fn(&T) -> String) {
    let n = items.len();
    for item in items.take(LIST_MAX) {
        let _ = writeln!(s, "  {}", f(&item));
    }
    if n > LIST_MAX {
        let _ = writeln!(s, "  … and {} more", n - LIST_MAX);
    }
}

#[cfg(test)]
mod tests;
