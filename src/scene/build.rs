//! Validation pass: checks every value of a [`RawScene`] and builds the [`Model`] and
//! [`IntegratorParams`]. Every error names its key path; the document tree gives it a
//! `line:column`.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Display;

use nalgebra::Matrix2;

use super::raw::{
    RawContact, RawInitialVelocity, RawIntegrator, RawLineLoad, RawLink, RawLoad, RawMaterial,
    RawObstacle, RawProbe, RawRod, RawScene, RawSection, RawSupport,
};
use super::span::{Doc, KeyPath};
use super::{fmt_num, key_name, Probe, Scene, SceneError};
use crate::integrator::params::{IntegratorParams, NewtonVariant, Scheme, Strategy};
use crate::model::{
    Element, ElementProps, LineLoad, Link, Mat3, Model, NodalLoad, Plane, Ramp, RodInfo,
    ShapeSetup, Slide, Support, SupportDrive, TimeTable, Vec3,
};

type Result<T> = std::result::Result<T, SceneError>;

/// Relative tolerance (× model size) for merging nodes and matching `at` points.
const MERGE_TOL: f64 = 1e-9;
/// Below this `|sin|` of the angle between `d1` and a segment, `d1` counts as parallel.
const PARALLEL_TOL: f64 = 1e-6;
/// Cap on elements per segment (guards against a typo allocating the machine away); the
/// scene as a whole has the same cap ([`super::limits::MAX_SCENE_ELEMENTS`]).
const MAX_ELEMENTS: i64 = super::limits::MAX_SCENE_ELEMENTS as i64;

/// Error factory: knows the file name and the document for spans.
struct Ctx<'a, 'i> {
    file: &'a str,
    doc: &'a Doc<'i>,
}

fn fmt_v(v: &Vec3) -> String {
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
    fn err(&self, path: &KeyPath, reason: impl Display) -> SceneError {
        self.doc.error(
            self.file,
            self.doc.span_of(path).map(|s| s.start),
            key_name(path),
            super::cap_echoes(&reason.to_string()),
        )
    }

    fn required<T>(&self, path: &KeyPath, v: Option<T>) -> Result<T> {
        v.ok_or_else(|| self.err(path, "required key missing"))
    }

    fn finite(&self, path: &KeyPath, x: f64) -> Result<f64> {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be finite (got {})", fmt_num(x))))
        }
    }

    fn positive(&self, path: &KeyPath, x: f64) -> Result<f64> {
        let x = self.finite(path, x)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be > 0 (got {})", fmt_num(x))))
        }
    }

    fn non_negative(&self, path: &KeyPath, x: f64) -> Result<f64> {
        let x = self.finite(path, x)?;
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(self.err(path, format!("must be >= 0 (got {})", fmt_num(x))))
        }
    }

    fn req_positive(&self, path: &KeyPath, v: Option<f64>) -> Result<f64> {
        let x = self.required(path, v)?;
        self.positive(path, x)
    }

    fn opt_non_negative(&self, path: &KeyPath, v: Option<f64>) -> Result<f64> {
        v.map_or(Ok(0.0), |x| self.non_negative(path, x))
    }

    fn vec3(&self, path: &KeyPath, v: &[f64]) -> Result<Vec3> {
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

    fn opt_vec3(&self, path: &KeyPath, v: &Option<Vec<f64>>) -> Result<Option<Vec3>> {
        v.as_deref().map(|v| self.vec3(path, v)).transpose()
    }

    fn count(&self, path: &KeyPath, v: Option<i64>, default: usize) -> Result<usize> {
        match v {
            None => Ok(default),
            Some(n) if n >= 1 => usize::try_from(n).map_err(|_| self.err(path, "too large")),
            Some(n) => Err(self.err(path, format!("must be >= 1 (got {n})"))),
        }
    }

    /// A count bounded by [`MAX_ITERATION_CAP`].
    fn iteration_cap(&self, path: &KeyPath, v: Option<i64>, default: usize) -> Result<usize> {
        match v {
            Some(n) if n > MAX_ITERATION_CAP => {
                Err(self.err(path, format!("must be <= {MAX_ITERATION_CAP} (got {n})")))
            }
            _ => self.count(path, v, default),
        }
    }

    /// A relative tolerance: finite, and at least [`MIN_TOLERANCE`].
    fn tolerance(&self, path: &KeyPath, x: f64) -> Result<f64> {
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
    fn name(&self, path: &KeyPath, name: &str, forbidden: &[char]) -> Result<()> {
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

/// A validated material.
struct Material {
    e: f64,
    g: f64,
    density: f64,
    damping: f64,
}

/// A validated section.
struct Section {
    a: f64,
    i11: f64,
    i22: f64,
    i12: f64,
    j: f64,
    a1: f64,
    a2: f64,
    rho_inertia: Matrix2<f64>,
}

fn material(cx: &Ctx, path: &KeyPath, m: &RawMaterial) -> Result<Material> {
    let e = cx.req_positive(&path.key("E"), m.e)?;
    let density = cx.req_positive(&path.key("density"), m.density)?;
    let g = match (m.nu, m.g) {
        (Some(_), Some(_)) => {
            return Err(cx.err(&path.key("G"), "give exactly one of `nu` and `G`, not both"))
        }
        (None, None) => {
            return Err(cx.err(
                &path.key("nu"),
                "required key missing (give Poisson's ratio `nu` or shear modulus `G`)",
            ))
        }
        (Some(nu), None) => {
            let p = path.key("nu");
            let nu = cx.finite(&p, nu)?;
            if !(nu > -1.0 && nu <= 0.5) {
                return Err(cx.err(&p, format!("must be in (-1, 0.5] (got {nu})")));
            }
            e / (2.0 * (1.0 + nu))
        }
        (None, Some(g)) => cx.positive(&path.key("G"), g)?,
    };
    let damping = cx.opt_non_negative(&path.key("damping"), m.damping)?;
    Ok(Material {
        e,
        g,
        density,
        damping,
    })
}

fn section(cx: &Ctx, path: &KeyPath, s: &RawSection) -> Result<Section> {
    let a = cx.req_positive(&path.key("A"), s.a)?;
    let i11 = cx.req_positive(&path.key("I11"), s.i11)?;
    let i22 = cx.req_positive(&path.key("I22"), s.i22)?;
    let i12 = match s.i12 {
        Some(x) => cx.finite(&path.key("I12"), x)?,
        None => 0.0,
    };
    if !(i11 * i22).is_normal() {
        // The product underflows: the smaller moment is the one out of range.
        let (k, x) = if i11 <= i22 {
            ("I11", i11)
        } else {
            ("I22", i22)
        };
        return Err(cx.err(
            &path.key(k),
            format!(
                "too small: I11*I22 = {} underflows double precision (got {k} = {}); give moments of area with I11*I22 >= {:e}",
                fmt_num(i11 * i22),
                fmt_num(x),
                f64::MIN_POSITIVE
            ),
        ));
    }
    if i11 * i22 - i12 * i12 <= 0.0 {
        return Err(cx.err(
            &path.key("I12"),
            format!(
                "I11*I22 - I12^2 must be > 0 (got {})",
                i11 * i22 - i12 * i12
            ),
        ));
    }
    let j = cx.req_positive(&path.key("J"), s.j)?;
    let (a1, a2) = match (s.shear_factor, s.a1, s.a2) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(cx.err(
                &path.key("shear_factor"),
                "give either `shear_factor` or `A1` and `A2`, not both",
            ))
        }
        (Some(k), None, None) => {
            let k = cx.positive(&path.key("shear_factor"), k)?;
            (k * a, k * a)
        }
        (None, None, None) => (a, a),
        (None, Some(a1), Some(a2)) => (
            cx.positive(&path.key("A1"), a1)?,
            cx.positive(&path.key("A2"), a2)?,
        ),
        (None, Some(_), None) => {
            return Err(cx.err(&path.key("A2"), "required key missing (A1 is given)"))
        }
        (None, None, Some(_)) => {
            return Err(cx.err(&path.key("A1"), "required key missing (A2 is given)"))
        }
    };
    let rho_inertia = match &s.rho_inertia {
        None => Matrix2::new(i22, -i12, -i12, i11),
        Some(rows) => {
            let p = path.key("rho_inertia");
            if rows.len() != 2 || rows.iter().any(|r| r.len() != 2) {
                return Err(cx.err(&p, "expected a 2x2 array [[a11, a12], [a21, a22]]"));
            }
            for (i, r) in rows.iter().enumerate() {
                for (k, &x) in r.iter().enumerate() {
                    cx.finite(&p.idx(i).idx(k), x)?;
                }
            }
            let m = Matrix2::new(rows[0][0], rows[0][1], rows[1][0], rows[1][1]);
            let scale = m.abs().max();
            if (m[(0, 1)] - m[(1, 0)]).abs() > 1e-12 * scale {
                return Err(cx.err(
                    &p,
                    format!(
                        "must be symmetric (got a12 = {}, a21 = {})",
                        m[(0, 1)],
                        m[(1, 0)]
                    ),
                ));
            }
            let sym = Matrix2::new(m[(0, 0)], m[(0, 1)], m[(0, 1)], m[(1, 1)]);
            if !(sym[(0, 0)] > 0.0 && sym.determinant() > 0.0) {
                return Err(cx.err(&p, "must be positive definite"));
            }
            sym
        }
    };
    Ok(Section {
        a,
        i11,
        i22,
        i12,
        j,
        a1,
        a2,
        rho_inertia,
    })
}

/// A rod's checked geometry before meshing.
struct RodPlan {
    name: String,
    points: Vec<Vec3>,
    counts: Vec<usize>,
    d1: Option<Vec3>,
    curvature: Vec3,
    drag: f64,
    props_key: (String, String),
    path: KeyPath,
}

fn elements_list(cx: &Ctx, path: &KeyPath, v: &toml::Value, n_seg: usize) -> Result<Vec<usize>> {
    let one = |p: &KeyPath, v: &toml::Value| -> Result<usize> {
        match v {
            toml::Value::Integer(n) if (1..=MAX_ELEMENTS).contains(n) => Ok(*n as usize),
            toml::Value::Integer(n) if *n > MAX_ELEMENTS => Err(cx.err(
                p,
                format!("must be <= {MAX_ELEMENTS} per segment (got {n})"),
            )),
            toml::Value::Integer(n) => Err(cx.err(p, format!("must be >= 1 (got {n})"))),
            other => Err(cx.err(
                p,
                format!("expected a positive integer (got {})", other.type_str()),
            )),
        }
    };
    match v {
        toml::Value::Array(items) => {
            if items.len() != n_seg {
                return Err(cx.err(
                    path,
                    format!(
                        "expected one count per segment: {n_seg} (got {})",
                        items.len()
                    ),
                ));
            }
            items
                .iter()
                .enumerate()
                .map(|(i, x)| one(&path.idx(i), x))
                .collect()
        }
        other => Ok(vec![one(path, other)?; n_seg]),
    }
}

fn plan_rod(
    cx: &Ctx,
    path: &KeyPath,
    index: usize,
    r: &RawRod,
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
) -> Result<RodPlan> {
    if let Some(n) = &r.name {
        cx.name(&path.key("name"), n, &[])?;
    }
    let name = r.name.clone().unwrap_or_else(|| format!("rod{index}"));
    let known = |names: Vec<&String>| {
        if names.is_empty() {
            "none defined".to_string()
        } else {
            names
                .iter()
                .map(|s| format!("`{s}`"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    let mat = cx.required(&path.key("material"), r.material.clone())?;
    if !materials.contains_key(&mat) {
        return Err(cx.err(
            &path.key("material"),
            format!(
                "unknown material `{mat}` (known: {})",
                known(materials.keys().collect())
            ),
        ));
    }
    let sec = cx.required(&path.key("section"), r.section.clone())?;
    if !sections.contains_key(&sec) {
        return Err(cx.err(
            &path.key("section"),
            format!(
                "unknown section `{sec}` (known: {})",
                known(sections.keys().collect())
            ),
        ));
    }
    let pp = path.key("points");
    let raw_points = cx.required(&pp, r.points.as_ref())?;
    if raw_points.len() < 2 {
        return Err(cx.err(
            &pp,
            format!("a rod needs at least 2 points (got {})", raw_points.len()),
        ));
    }
    let points = raw_points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let v = cx.vec3(&pp.idx(i), p)?;
            if let Some(k) = (0..3).find(|&k| v[k].abs() > MAX_COORDINATE) {
                return Err(cx.err(
                    &pp.idx(i).idx(k),
                    format!(
                        "coordinate out of range: |{}| > {MAX_COORDINATE:e} (coordinates must be at most {MAX_COORDINATE:e} in magnitude, so that distances between points stay representable)",
                        fmt_num(v[k])
                    ),
                ));
            }
            Ok(v)
        })
        .collect::<Result<Vec<_>>>()?;
    let ep = path.key("elements");
    let counts = elements_list(
        cx,
        &ep,
        cx.required(&ep, r.elements.as_ref())?,
        points.len() - 1,
    )?;
    let d1 = cx.opt_vec3(&path.key("d1"), &r.d1)?;
    let curvature = cx
        .opt_vec3(&path.key("curvature"), &r.curvature)?
        .unwrap_or_else(Vec3::zeros);
    let drag = cx.opt_non_negative(&path.key("drag"), r.drag)?;
    Ok(RodPlan {
        name,
        points,
        counts,
        d1,
        curvature,
        drag,
        props_key: (mat, sec),
        path: path.clone(),
    })
}

/// Nodes with merging of coincident points through a uniform grid of cell size `tol`.
struct NodeSet {
    nodes: Vec<Vec3>,
    grid: HashMap<[i64; 3], Vec<usize>>,
    origin: Vec3,
    tol: f64,
}

impl NodeSet {
    fn new(origin: Vec3, tol: f64) -> Self {
        Self {
            nodes: Vec::new(),
            grid: HashMap::new(),
            origin,
            tol,
        }
    }

    fn cell(&self, p: &Vec3) -> [i64; 3] {
        let q = (p - self.origin) / self.tol;
        // `as` saturates far away points; they then simply match nothing.
        [q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64]
    }

    /// The nearest node within `tol` of `p`.
    fn find(&self, p: &Vec3) -> Option<usize> {
        let c = self.cell(p);
        let mut best: Option<(usize, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    for &a in self.grid.get(&key).into_iter().flatten() {
                        let d = (self.nodes[a] - p).norm();
                        if d <= self.tol && best.is_none_or(|b| d < b.1) {
                            best = Some((a, d));
                        }
                    }
                }
            }
        }
        best.map(|b| b.0)
    }

    fn get_or_insert(&mut self, p: Vec3) -> usize {
        if let Some(a) = self.find(&p) {
            return a;
        }
        let a = self.nodes.len();
        self.nodes.push(p);
        let c = self.cell(&p);
        self.grid.entry(c).or_default().push(a);
        a
    }

    /// The nearest node to `p` and its distance (linear scan; for error messages).
    fn nearest(&self, p: &Vec3) -> Option<(usize, f64)> {
        self.nodes
            .iter()
            .enumerate()
            .map(|(a, q)| (a, (q - p).norm()))
            .min_by(|x, y| x.1.total_cmp(&y.1))
    }
}

fn node_at(cx: &Ctx, nodes: &NodeSet, path: &KeyPath, at: &Option<Vec<f64>>) -> Result<usize> {
    let p = cx.required(path, cx.opt_vec3(path, at)?)?;
    if let Some(a) = nodes.find(&p) {
        return Ok(a);
    }
    let near = match nodes.nearest(&p) {
        Some((a, d)) => format!(
            " (nearest node {a} at {}, distance {})",
            fmt_v(&nodes.nodes[a]),
            fmt_num(d)
        ),
        None => String::new(),
    };
    Err(cx.err(path, format!("{} is not a node{near}", fmt_v(&p))))
}

/// The default `d1` of a rod: of e3, e1, e2 (in that order of preference) the one whose
/// smallest angle to the rod's segments is largest.
fn default_d1(tangents: &[Vec3]) -> (Vec3, f64) {
    let mut best = (Vec3::z(), -1.0);
    for cand in [Vec3::z(), Vec3::x(), Vec3::y()] {
        let worst = tangents
            .iter()
            .map(|t| cand.cross(t).norm())
            .fold(f64::INFINITY, f64::min);
        if worst > best.1 {
            best = (cand, worst);
        }
    }
    best
}

fn load(cx: &Ctx, nodes: &NodeSet, path: &KeyPath, l: &RawLoad) -> Result<NodalLoad> {
    let node = node_at(cx, nodes, &path.key("at"), &l.at)?;
    let force = cx.opt_vec3(&path.key("force"), &l.force)?;
    let moment = cx.opt_vec3(&path.key("moment"), &l.moment)?;
    if force.is_none() && moment.is_none() {
        return Err(cx.err(
            &path.key("force"),
            "required key missing (give `force`, `moment` or both)",
        ));
    }
    let table = time_table(cx, path, &l.time, &l.factor)?;
    Ok(NodalLoad {
        node,
        force: force.unwrap_or_else(Vec3::zeros),
        moment: moment.unwrap_or_else(Vec3::zeros),
        table,
    })
}

/// The sliding axis of a `[[clamp]]` entry (`slide`, `spin`), if it slides.
fn slide(
    cx: &Ctx,
    path: &KeyPath,
    kind: &str,
    node: usize,
    c: &RawSupport,
    params: &IntegratorParams,
) -> Result<Option<Slide>> {
    let Some(v) = &c.slide else {
        if c.spin.is_some() {
            return Err(cx.err(&path.key("spin"), "only with `slide`"));
        }
        return Ok(None);
    };
    let sp = path.key("slide");
    if kind == "pin" {
        return Err(cx.err(
            &sp,
            "a sliding support is a [[clamp]] (it holds the rotation); a pin that slides needs no support across the axis either",
        ));
    }
    let v = cx.vec3(&sp, v)?;
    let n = v.norm();
    if !(n > 0.0 && n.is_finite()) {
        return Err(cx.err(
            &sp,
            format!("{} is not an axis: give a nonzero vector", fmt_v(&v)),
        ));
    }
    // Snap a vector within 1e-12 of a coordinate axis onto it (that slide removes
    // unknowns instead of constraining rows).
    let axis = match (0..3).find(|&k| (v[k].abs() - n).abs() <= 1e-12 * n) {
        Some(k) => Vec3::from_fn(|c, _| if c == k { v[k].signum() } else { 0.0 }),
        None => v / n,
    };
    if c.displacement.is_some() || c.rotation.is_some() {
        return Err(cx.err(&sp, "a sliding clamp cannot also be driven"));
    }
    let spin = c.spin.unwrap_or(false);
    if matches!(params.scheme, Scheme::GenAlpha { .. }) {
        return Err(cx.err(
            &sp,
            "gen-alpha does not support sliding clamps; use em, edmc1, edmc2 or midpoint",
        ));
    }
    if spin && params.scheme.director_dissipation() {
        return Err(cx.err(
            &path.key("spin"),
            "a spinning sliding clamp is not supported with director dissipation (chi_nu, alpha_gn, alpha_on)",
        ));
    }
    Ok(Some(Slide { node, axis, spin }))
}

/// The prescribed motion of a `[[clamp]]` / `[[pin]]` entry, if it moves.
fn support_drive(
    cx: &Ctx,
    path: &KeyPath,
    kind: &str,
    node: usize,
    c: &RawSupport,
) -> Result<Option<SupportDrive>> {
    let displacement = cx.opt_vec3(&path.key("displacement"), &c.displacement)?;
    let rotation = cx.opt_vec3(&path.key("rotation"), &c.rotation)?;
    if kind == "pin" && rotation.is_some() {
        return Err(cx.err(
            &path.key("rotation"),
            "a pin leaves the rotation free: drive a rotation with a [[clamp]]",
        ));
    }
    if displacement.is_none() && rotation.is_none() {
        for (key, present) in [
            ("time", c.time.is_some()),
            ("factor", c.factor.is_some()),
            ("ramp", c.ramp.is_some()),
        ] {
            if present {
                return Err(cx.err(
                    &path.key(key),
                    "only for a moving support (give `displacement` or `rotation`)",
                ));
            }
        }
        return Ok(None);
    }
    if c.time.is_none() && c.factor.is_none() {
        return Err(cx.err(
            &path.key("time"),
            "required key missing: a moving support needs its `time` and `factor` table",
        ));
    }
    let table = time_table(cx, path, &c.time, &c.factor)?;
    let ramp = ramp(cx, path, &c.ramp)?;
    Ok(Some(SupportDrive {
        node,
        displacement: displacement.unwrap_or_else(Vec3::zeros),
        rotation: rotation.unwrap_or_else(Vec3::zeros),
        table,
        ramp,
    }))
}

/// The `ramp` key under `path` (default linear).
fn ramp(cx: &Ctx, path: &KeyPath, r: &Option<String>) -> Result<Ramp> {
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
fn time_table(
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

/// The elements a `rod` (and optional `segment`) key pair names.
fn rod_elements(
    cx: &Ctx,
    path: &KeyPath,
    rod: &Option<String>,
    segment: Option<i64>,
    plans: &[RodPlan],
    rods: &[RodInfo],
) -> Result<Vec<usize>> {
    let rp = path.key("rod");
    let rod = cx.required(&rp, rod.as_ref())?;
    let Some(ri) = rods.iter().position(|r| &r.name == rod) else {
        let names: Vec<&str> = rods.iter().map(|r| r.name.as_str()).collect();
        return Err(cx.err(
            &rp,
            format!("no rod named `{rod}` (rods: {})", names.join(", ")),
        ));
    };
    let range = rods[ri].elements.clone();
    match segment {
        None => Ok(range.collect()),
        Some(sg) => {
            let counts = &plans[ri].counts;
            if sg < 0 || sg as usize >= counts.len() {
                return Err(cx.err(
                    &path.key("segment"),
                    format!(
                        "rod `{rod}` has segments 0..{} (got {sg})",
                        counts.len() - 1
                    ),
                ));
            }
            let sg = sg as usize;
            let start = range.start + counts[..sg].iter().sum::<usize>();
            Ok((start..start + counts[sg]).collect())
        }
    }
}

fn line_load(
    cx: &Ctx,
    path: &KeyPath,
    l: &RawLineLoad,
    plans: &[RodPlan],
    rods: &[RodInfo],
) -> Result<LineLoad> {
    let elements = rod_elements(cx, path, &l.rod, l.segment, plans, rods)?;
    let force = cx.opt_vec3(&path.key("force"), &l.force)?;
    let moment = cx.opt_vec3(&path.key("moment"), &l.moment)?;
    if force.is_none() && moment.is_none() {
        return Err(cx.err(
            &path.key("force"),
            "required key missing (give `force`, `moment` or both)",
        ));
    }
    Ok(LineLoad {
        elements,
        force: force.unwrap_or_else(Vec3::zeros),
        moment: moment.unwrap_or_else(Vec3::zeros),
        follower: l.follower.unwrap_or(false),
        table: time_table(cx, path, &l.time, &l.factor)?,
    })
}

fn integrator(cx: &Ctx, ip: &KeyPath, r: &RawIntegrator) -> Result<(IntegratorParams, usize)> {
    let k = |name: &str| ip.key(name);
    let scheme_name = cx.required(&k("scheme"), r.scheme.as_deref())?;
    let all_params: [(&str, Option<f64>, &str); 10] = [
        ("alpha", r.alpha, "edmc2"),
        ("alpha_gv", r.alpha_gv, "edmc2"),
        ("alpha_gn", r.alpha_gn, "edmc2"),
        ("alpha_ov", r.alpha_ov, "edmc2"),
        ("alpha_on", r.alpha_on, "edmc2"),
        ("chi_gamma", r.chi_gamma, "edmc1"),
        ("chi_omega", r.chi_omega, "edmc1"),
        ("chi_v", r.chi_v, "edmc1"),
        ("chi_nu", r.chi_nu, "edmc1"),
        ("rho_inf", r.rho_inf, "gen-alpha"),
    ];
    if !matches!(
        scheme_name,
        "em" | "edmc1" | "edmc2" | "midpoint" | "gen-alpha"
    ) {
        return Err(cx.err(
            &k("scheme"),
            format!(
                "unknown scheme `{scheme_name}` (expected \"em\", \"edmc1\", \"edmc2\", \"midpoint\" or \"gen-alpha\")"
            ),
        ));
    }
    for (name, value, owner) in all_params {
        if value.is_some() && owner != scheme_name {
            return Err(cx.err(
                &k(name),
                format!("not a parameter of scheme {scheme_name} (it belongs to {owner})"),
            ));
        }
    }
    let scheme = match scheme_name {
        "em" => Scheme::Em,
        "midpoint" => Scheme::Midpoint,
        "gen-alpha" => {
            let rho_inf = r
                .rho_inf
                .unwrap_or(crate::integrator::gen_alpha::DEFAULT_RHO_INF);
            if !(0.0..=1.0).contains(&rho_inf) {
                return Err(cx.err(&k("rho_inf"), format!("must be in [0, 1] (got {rho_inf})")));
            }
            Scheme::GenAlpha { rho_inf }
        }
        "edmc1" => Scheme::Edmc1 {
            chi_gamma: cx.opt_non_negative(&k("chi_gamma"), r.chi_gamma)?,
            chi_omega: cx.opt_non_negative(&k("chi_omega"), r.chi_omega)?,
            chi_v: cx.opt_non_negative(&k("chi_v"), r.chi_v)?,
            chi_nu: cx.opt_non_negative(&k("chi_nu"), r.chi_nu)?,
        },
        _ => {
            if r.alpha.is_some() && r.alpha_gv.is_some() {
                return Err(cx.err(
                    &k("alpha_gv"),
                    "give `alpha` (shorthand for alpha_gv) or `alpha_gv`, not both",
                ));
            }
            let alpha_gv = match r.alpha {
                Some(a) => cx.non_negative(&k("alpha"), a)?,
                None => cx.opt_non_negative(&k("alpha_gv"), r.alpha_gv)?,
            };
            Scheme::Edmc2 {
                alpha_gv,
                alpha_gn: cx.opt_non_negative(&k("alpha_gn"), r.alpha_gn)?,
                alpha_ov: cx.opt_non_negative(&k("alpha_ov"), r.alpha_ov)?,
                alpha_on: cx.opt_non_negative(&k("alpha_on"), r.alpha_on)?,
            }
        }
    };
    let dt = cx.req_positive(&k("dt"), r.dt)?;
    let t_end = cx.req_positive(&k("t_end"), r.t_end)?;
    if dt > t_end {
        return Err(cx.err(
            &k("dt"),
            format!(
                "must not exceed t_end = {} (got {}): the run would take no step",
                fmt_num(t_end),
                fmt_num(dt)
            ),
        ));
    }
    if t_end / dt > super::limits::MAX_STEPS {
        return Err(cx.err(
            &k("dt"),
            format!(
                "t_end / dt = {:e} steps, above the limit of {:e} steps per run",
                t_end / dt,
                super::limits::MAX_STEPS
            ),
        ));
    }
    let mut p = IntegratorParams::new(scheme, dt, t_end);
    if let Some(s) = r.strategy.as_deref() {
        p.strategy = match s {
            "monolithic" => Strategy::Monolithic,
            "staggered" => Strategy::Staggered,
            "inexact" => Strategy::Inexact,
            "auto" => Strategy::Auto,
            other => {
                return Err(cx.err(
                    &k("strategy"),
                    format!(
                        "unknown strategy `{other}` (expected \"auto\", \"staggered\", \"monolithic\" or \"inexact\")"
                    ),
                ))
            }
        };
    }
    if let Some(f) = r.fallback {
        p.fallback = f;
    }
    if let Some(n) = r.cutback {
        p.cutback = match n {
            0..=20 => n as usize,
            _ => {
                return Err(cx.err(
                    &k("cutback"),
                    format!("must be between 0 and 20 halvings (got {n})"),
                ))
            }
        };
    }
    if let Some(s) = r.newton.as_deref() {
        p.newton = match s {
            "full" => NewtonVariant::Full,
            "fresh" => NewtonVariant::Fresh,
            "modified" => NewtonVariant::Modified,
            other => {
                return Err(cx.err(
                    &k("newton"),
                    format!(
                        "unknown Newton variant `{other}` (expected \"full\", \"fresh\" or \"modified\")"
                    ),
                ))
            }
        };
    }
    if let Some(x) = r.newton_tol {
        p.newton_tol = cx.tolerance(&k("newton_tol"), x)?;
    }
    if let Some(x) = r.outer_tol {
        p.outer_tol = cx.tolerance(&k("outer_tol"), x)?;
    }
    if let Some(x) = r.energy_tol {
        p.energy_tol = cx.tolerance(&k("energy_tol"), x)?;
    }
    p.max_iter = cx.iteration_cap(&k("max_iter"), r.max_iter, p.max_iter)?;
    p.max_outer = cx.iteration_cap(&k("max_outer"), r.max_outer, p.max_outer)?;
    p.max_link_rounds =
        cx.iteration_cap(&k("max_link_rounds"), r.max_link_rounds, p.max_link_rounds)?;
    let output_every = cx.count(&k("output_every"), r.output_every, 1)?;
    Ok((p, output_every))
}

/// Checks a rod's segments (length, `d1` transverse) and returns each segment's
/// reference triad `[d1°, d2°, d3°]`.
fn rod_triads(cx: &Ctx, plan: &RodPlan, tol: f64) -> Result<Vec<Mat3>> {
    let pp = plan.path.key("points");
    let mut tangents = Vec::with_capacity(plan.points.len() - 1);
    for (s, w) in plan.points.windows(2).enumerate() {
        let len = (w[1] - w[0]).norm();
        if len <= tol {
            return Err(cx.err(
                &pp.idx(s + 1),
                format!(
                    "zero-length segment: point {} {} repeats point {} {}",
                    s + 1,
                    fmt_v(&w[1]),
                    s,
                    fmt_v(&w[0])
                ),
            ));
        }
        let h = len / plan.counts[s] as f64;
        if h <= tol {
            let ep = plan.path.key("elements");
            return Err(cx.err(
                &ep,
                format!(
                    "elements of length {h:e} on segment {s} are below the merge tolerance {tol:e}"
                ),
            ));
        }
        tangents.push((w[1] - w[0]) / len);
    }
    let d1 = match plan.d1 {
        Some(d1) => {
            let n = d1.norm();
            if n <= 0.0 {
                return Err(cx.err(&plan.path.key("d1"), "must not be the zero vector"));
            }
            for (s, t) in tangents.iter().enumerate() {
                if d1.cross(t).norm() / n < PARALLEL_TOL {
                    return Err(cx.err(
                        &plan.path.key("d1"),
                        format!(
                            "{} is parallel to segment {s} (direction {}); d1 must be transverse to every segment",
                            fmt_v(&d1),
                            fmt_v(t)
                        ),
                    ));
                }
            }
            d1 / n
        }
        None => {
            let (d1, worst) = default_d1(&tangents);
            if worst < PARALLEL_TOL {
                return Err(cx.err(
                    &plan.path.key("d1"),
                    "required key missing: no coordinate axis is transverse to every segment; give d1",
                ));
            }
            d1
        }
    };
    Ok(tangents
        .iter()
        .map(|d3| {
            let d1 = (d1 - d3 * d1.dot(d3)).normalize();
            let d2 = d3.cross(&d1);
            Mat3::from_columns(&[d1, d2, *d3])
        })
        .collect())
}

/// The continuum constants of an element of length `h`.
fn element_props(mat: &Material, sec: &Section, h: f64, drag: f64) -> ElementProps {
    let (e, g) = (mat.e, mat.g);
    ElementProps {
        h,
        a_rho: mat.density * sec.a,
        i_rho: sec.rho_inertia * mat.density,
        c_gamma: Vec3::new(g * sec.a1, g * sec.a2, e * sec.a),
        c_omega: Mat3::new(
            e * sec.i11,
            e * sec.i12,
            0.0,
            e * sec.i12,
            e * sec.i22,
            0.0,
            0.0,
            0.0,
            g * sec.j,
        ),
        damping: mat.damping,
        drag,
    }
}

/// Meshes every rod: subdivides segments, merges coincident nodes, builds elements.
fn mesh(
    cx: &Ctx,
    plans: &[RodPlan],
    triads: &[Vec<Mat3>],
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
    nodes: &mut NodeSet,
) -> Result<(Vec<Element>, Vec<RodInfo>)> {
    let mut elements = Vec::new();
    let mut rods = Vec::with_capacity(plans.len());
    for (ri, plan) in plans.iter().enumerate() {
        let mat = &materials[&plan.props_key.0];
        let sec = &sections[&plan.props_key.1];
        let first = elements.len();
        for (s, w) in plan.points.windows(2).enumerate() {
            let n = plan.counts[s];
            let h = (w[1] - w[0]).norm() / n as f64;
            let props = element_props(mat, sec, h, plan.drag);
            let triad = triads[ri][s];
            let point = |j: usize| {
                if j == n {
                    w[1]
                } else {
                    w[0] + (w[1] - w[0]) * (j as f64 / n as f64)
                }
            };
            let mut a = nodes.get_or_insert(point(0));
            for j in 1..=n {
                let b = nodes.get_or_insert(point(j));
                if a == b {
                    return Err(cx.err(
                        &plan.path.key("points"),
                        format!("element {} of segment {s} collapses onto one node", j - 1),
                    ));
                }
                elements.push(Element {
                    nodes: [a, b],
                    ref_triad: [triad, triad],
                    props: props.clone(),
                    rod: ri,
                });
                a = b;
            }
        }
        rods.push(RodInfo {
            name: plan.name.clone(),
            elements: first..elements.len(),
        });
    }
    Ok((elements, rods))
}

/// The nodes of a rod in order along it (`N` elements: `N + 1` entries; a closed rod
/// repeats its first node at the end).
fn rod_chain(elements: &[Element], info: &RodInfo) -> Vec<usize> {
    let els = &elements[info.elements.clone()];
    let mut chain = Vec::with_capacity(els.len() + 1);
    chain.push(els[0].nodes[0]);
    chain.extend(els.iter().map(|e| e.nodes[1]));
    chain
}

/// A per-node table of vectors: exactly `n` entries.
fn node_table(
    cx: &Ctx,
    path: &KeyPath,
    rows: &[Vec<f64>],
    n: usize,
    what: &str,
) -> Result<Vec<Vec3>> {
    if rows.len() != n {
        return Err(cx.err(
            path,
            format!(
                "expected one vector per node of {what}: {n} (got {})",
                rows.len()
            ),
        ));
    }
    rows.iter()
        .enumerate()
        .map(|(i, v)| cx.vec3(&path.idx(i), v))
        .collect()
}

/// Unit tangents at the nodes of a chain of elements with unit chord directions `chord`:
/// the bisector of the two chords at an interior node, and at an end the chord reflected
/// about the bisector next to it (exact on a circular arc, second order on a smooth curve).
/// A zero vector marks a node where the chain turns back on itself.
fn node_tangents(chord: &[Vec3]) -> Vec<Vec3> {
    let n = chord.len();
    let unit = |v: Vec3| {
        let l = v.norm();
        if l > 1e-12 {
            v / l
        } else {
            Vec3::zeros()
        }
    };
    let mut t = Vec::with_capacity(n + 1);
    t.push(chord[0]);
    for j in 1..n {
        t.push(unit(chord[j - 1] + chord[j]));
    }
    t.push(chord[n - 1]);
    if n >= 2 {
        for (end, c, inner) in [(0, chord[0], t[1]), (n, chord[n - 1], t[n - 1])] {
            if inner != Vec3::zeros() {
                t[end] = unit(2.0 * c.dot(&inner) * c - inner);
            }
        }
    }
    t
}

/// The rotation taking unit vector `a` onto unit vector `b` about `a × b` (the identity
/// when they are equal); `None` when they are opposite.
fn minimal_rotation(a: &Vec3, b: &Vec3) -> Option<Mat3> {
    if a.norm() < 0.5 || b.norm() < 0.5 {
        return None;
    }
    let c = a.dot(b);
    if c <= -1.0 + 1e-12 {
        return None;
    }
    let k = a.cross(b);
    let kx = crate::math::hat(&k);
    Some(Mat3::identity() + kx + kx * kx / (1.0 + c))
}

/// Initial configuration and intrinsic curvature of every rod (`[rod.initial]`,
/// `curvature`), checked for consistency where rods share nodes.
#[allow(clippy::too_many_arguments)]
fn shape_setup(
    cx: &Ctx,
    raw: &[RawRod],
    plans: &[RodPlan],
    elements: &[Element],
    rods: &[RodInfo],
    nodes: &NodeSet,
) -> Result<ShapeSetup> {
    let n = nodes.nodes.len();
    let mut curvature = vec![Vec3::zeros(); elements.len()];
    for (plan, info) in plans.iter().zip(rods) {
        for k in &mut curvature[info.elements.clone()] {
            *k = plan.curvature;
        }
    }
    let mut positions = nodes.nodes.clone();
    let mut rotations = vec![Mat3::identity(); n];
    // Which rod's `[rod.initial]` set each node.
    let mut set_by: Vec<Option<usize>> = vec![None; n];
    let mut any = false;
    for (ri, (r, info)) in raw.iter().zip(rods).enumerate() {
        let Some(init) = &r.initial else { continue };
        any = true;
        let path = plans[ri].path.key("initial");
        let chain = rod_chain(elements, info);
        let nn = chain.len();
        let what = format!("rod `{}`", info.name);
        let reference: Vec<Vec3> = chain.iter().map(|&a| nodes.nodes[a]).collect();
        let table = |key: &str, v: &Option<Vec<Vec<f64>>>| -> Result<Option<Vec<Vec3>>> {
            v.as_deref()
                .map(|rows| node_table(cx, &path.key(key), rows, nn, &what))
                .transpose()
        };
        let given = table("positions", &init.positions)?;
        let displacement = table("displacement", &init.displacement)?;
        let rot_table = table("rotations", &init.rotations)?;
        if given.is_some() {
            for (key, present) in [
                ("stretch", init.stretch.is_some()),
                ("origin", init.origin.is_some()),
                ("displacement", init.displacement.is_some()),
            ] {
                if present {
                    return Err(cx.err(
                        &path.key(key),
                        "not with `positions` (a table of positions is the whole initial shape)",
                    ));
                }
            }
        }
        if init.origin.is_some() && init.stretch.is_none() {
            return Err(cx.err(&path.key("origin"), "only with `stretch`"));
        }
        if init.center.is_some() && init.rotation.is_none() {
            return Err(cx.err(&path.key("center"), "only with `rotation`"));
        }
        let mut x: Vec<Vec3> = match &given {
            Some(p) => p.clone(),
            None => {
                let mut x = reference.clone();
                if let Some(l) = init.stretch {
                    let l = cx.positive(&path.key("stretch"), l)?;
                    let o = cx
                        .opt_vec3(&path.key("origin"), &init.origin)?
                        .unwrap_or(plans[ri].points[0]);
                    x.iter_mut().for_each(|p| *p = o + (*p - o) * l);
                }
                if let Some(d) = &displacement {
                    x.iter_mut().zip(d).for_each(|(p, d)| *p += d);
                }
                x
            }
        };
        // Nodal rotations: the table, or directors following the tangent.
        let els = &elements[info.elements.clone()];
        let mut lam: Vec<Mat3> = match &rot_table {
            Some(t) => t.iter().map(crate::math::exp_so3).collect(),
            None => {
                let key = if given.is_some() {
                    "positions"
                } else {
                    "displacement"
                };
                let mut chord = Vec::with_capacity(els.len());
                for (j, w) in x.windows(2).enumerate() {
                    let len = (w[1] - w[0]).norm();
                    if len <= nodes.tol {
                        return Err(cx.err(
                            &path.key(key),
                            format!("element {j} of {what} has zero length in the initial configuration"),
                        ));
                    }
                    chord.push((w[1] - w[0]) / len);
                }
                let reference: Vec<Vec3> = els
                    .iter()
                    .map(|e| e.ref_triad[0].column(2).into_owned())
                    .collect();
                let (t0, t1) = (node_tangents(&reference), node_tangents(&chord));
                let mut lam = Vec::with_capacity(nn);
                for j in 0..nn {
                    let rot = minimal_rotation(&t0[j], &t1[j]).ok_or_else(|| {
                        cx.err(
                            &path.key(key),
                            format!("the rod turns back on itself at node {j} of {what}: the directors cannot follow its tangent (give `rotations`)"),
                        )
                    })?;
                    lam.push(rot);
                }
                lam
            }
        };
        if let Some(phi) = cx.opt_vec3(&path.key("rotation"), &init.rotation)? {
            let c = cx
                .opt_vec3(&path.key("center"), &init.center)?
                .unwrap_or_else(Vec3::zeros);
            let q = crate::math::exp_so3(&phi);
            x.iter_mut().for_each(|p| *p = c + q * (*p - c));
            lam.iter_mut().for_each(|l| *l = q * *l);
        }
        if let Some(t) = cx.opt_vec3(&path.key("translation"), &init.translation)? {
            x.iter_mut().for_each(|p| *p += t);
        }
        for (j, w) in x.windows(2).enumerate() {
            if (w[1] - w[0]).norm() <= nodes.tol {
                return Err(cx.err(
                    &path,
                    format!("element {j} of {what} has zero length in the initial configuration"),
                ));
            }
        }
        for (j, &a) in chain.iter().enumerate() {
            match set_by[a] {
                Some(other)
                    if (positions[a] - x[j]).norm() > nodes.tol
                        || (rotations[a] - lam[j]).amax() > 1e-9 =>
                {
                    let whose = if other == ri {
                        "the rod's own first node (a closed rod must close in its initial configuration too)".to_string()
                    } else {
                        format!("rod[{other}] `{}`", rods[other].name)
                    };
                    return Err(cx.err(
                        &path,
                        format!(
                            "node {a} (reference {}) gets initial position {} here but {} from {whose}; rods meeting at a node must agree on its initial position and rotation",
                            fmt_v(&nodes.nodes[a]),
                            fmt_v(&x[j]),
                            fmt_v(&positions[a])
                        ),
                    ));
                }
                _ => {
                    positions[a] = x[j];
                    rotations[a] = lam[j];
                    set_by[a] = Some(ri);
                }
            }
        }
    }
    // A rod without `[rod.initial]` keeps its nodes at the reference: a node it shares
    // with a moved rod must not have moved.
    if any {
        for (ri, (r, info)) in raw.iter().zip(rods).enumerate() {
            if r.initial.is_some() {
                continue;
            }
            for a in rod_chain(elements, info) {
                if let Some(other) = set_by[a] {
                    if (positions[a] - nodes.nodes[a]).norm() > nodes.tol
                        || (rotations[a] - Mat3::identity()).amax() > 1e-9
                    {
                        return Err(cx.err(
                            &plans[other].path.key("initial"),
                            format!(
                                "moves node {a} (reference {}), which rod[{ri}] `{}` shares but does not move (it has no [rod.initial]); rods meeting at a node must agree on its initial position and rotation",
                                fmt_v(&nodes.nodes[a]),
                                info.name
                            ),
                        ));
                    }
                }
            }
        }
    }
    let (positions, rotations) = if any {
        (positions, rotations)
    } else {
        (vec![], vec![])
    };
    let curvature = if curvature.iter().any(|k| *k != Vec3::zeros()) {
        curvature
    } else {
        vec![]
    };
    Ok(ShapeSetup {
        positions,
        rotations,
        curvature,
    })
}

/// Initial nodal velocities and angular velocities from the `[[initial_velocity]]`
/// entries; rigid motions act about the nodes' initial positions `x0`.
#[allow(clippy::too_many_arguments)]
fn initial_velocities(
    cx: &Ctx,
    entries: &[RawInitialVelocity],
    nodes: &NodeSet,
    x0: &[Vec3],
    supports: &[Support],
    plans: &[RodPlan],
    elements: &[Element],
    rods: &[RodInfo],
) -> Result<(Vec<Vec3>, Vec<Vec3>)> {
    let root = KeyPath::root();
    let n = nodes.nodes.len();
    let mut velocity0 = vec![Vec3::zeros(); n];
    let mut omega0 = vec![Vec3::zeros(); n];
    for (i, iv) in entries.iter().enumerate() {
        let path = root.key("initial_velocity").idx(i);
        let v = cx
            .opt_vec3(&path.key("v"), &iv.v)?
            .unwrap_or_else(Vec3::zeros);
        let w = cx
            .opt_vec3(&path.key("omega"), &iv.omega)?
            .unwrap_or_else(Vec3::zeros);
        let center = cx.opt_vec3(&path.key("center"), &iv.center)?;
        let all = iv.all == Some(true);
        let targets = [
            ("at", iv.at.is_some()),
            ("all", all),
            ("rod", iv.rod.is_some()),
        ];
        let given: Vec<&str> = targets.iter().filter(|t| t.1).map(|t| t.0).collect();
        if given.len() > 1 {
            return Err(cx.err(
                &path.key(given[1]),
                format!(
                    "give one of `at`, `all = true` and `rod`, not `{}` and `{}`",
                    given[0], given[1]
                ),
            ));
        }
        if iv.rod.is_none() {
            for (key, present) in [
                ("segment", iv.segment.is_some()),
                ("v_nodes", iv.v_nodes.is_some()),
                ("omega_nodes", iv.omega_nodes.is_some()),
            ] {
                if present {
                    return Err(cx.err(&path.key(key), "only with `rod`"));
                }
            }
        }
        if let Some(rod) = &iv.rod {
            let rp = path.key("rod");
            let Some(ri) = rods.iter().position(|r| &r.name == rod) else {
                let names: Vec<&str> = rods.iter().map(|r| r.name.as_str()).collect();
                return Err(cx.err(
                    &rp,
                    format!("no rod named `{rod}` (rods: {})", names.join(", ")),
                ));
            };
            let chain = rod_chain(elements, &rods[ri]);
            let (sel, what) = match iv.segment {
                None => (chain, format!("rod `{rod}`")),
                Some(sg) => {
                    let counts = &plans[ri].counts;
                    if sg < 0 || sg as usize >= counts.len() {
                        return Err(cx.err(
                            &path.key("segment"),
                            format!(
                                "rod `{rod}` has segments 0..{} (got {sg})",
                                counts.len() - 1
                            ),
                        ));
                    }
                    let sg = sg as usize;
                    let start: usize = counts[..sg].iter().sum();
                    (
                        chain[start..=start + counts[sg]].to_vec(),
                        format!("segment {sg} of rod `{rod}`"),
                    )
                }
            };
            let vt = iv
                .v_nodes
                .as_deref()
                .map(|t| node_table(cx, &path.key("v_nodes"), t, sel.len(), &what))
                .transpose()?;
            let wt = iv
                .omega_nodes
                .as_deref()
                .map(|t| node_table(cx, &path.key("omega_nodes"), t, sel.len(), &what))
                .transpose()?;
            let c = center.unwrap_or_else(Vec3::zeros);
            // A node listed twice (a closed rod) gets its share once.
            let mut seen = std::collections::HashSet::new();
            for (j, &a) in sel.iter().enumerate() {
                if !seen.insert(a) {
                    continue;
                }
                let wa = w + wt.as_ref().map_or(Vec3::zeros(), |t| t[j]);
                let va = v + w.cross(&(x0[a] - c)) + vt.as_ref().map_or(Vec3::zeros(), |t| t[j]);
                check_supported(cx, &rp, a, nodes, supports[a], &va, &wa)?;
                velocity0[a] += va;
                omega0[a] += wa;
            }
            continue;
        }
        if all {
            let c = center.unwrap_or_else(Vec3::zeros);
            for a in 0..n {
                let va = v + w.cross(&(x0[a] - c));
                check_supported(cx, &path.key("all"), a, nodes, supports[a], &va, &w)?;
                velocity0[a] += va;
                omega0[a] += w;
            }
            continue;
        }
        if center.is_some() {
            return Err(cx.err(
                &path.key("center"),
                "only allowed with `all = true` or `rod`",
            ));
        }
        if iv.at.is_none() {
            return Err(cx.err(
                &path.key("at"),
                "required key missing (or give `all = true` or `rod`)",
            ));
        }
        let a = node_at(cx, nodes, &path.key("at"), &iv.at)?;
        check_supported(cx, &path.key("at"), a, nodes, supports[a], &v, &w)?;
        velocity0[a] += v;
        omega0[a] += w;
    }

    Ok((velocity0, omega0))
}

/// Default penalty `κ` of a `[[link]]` (DESIGN §6: 1e5 for the mechanism).
const LINK_PENALTY: f64 = 1e5;
/// Default tolerance on a link's `|g|`.
const LINK_TOL: f64 = 1e-10;

fn link(cx: &Ctx, nodes: &NodeSet, path: &KeyPath, l: &RawLink) -> Result<Link> {
    let pp = path.key("pivot");
    let pivot = cx.required(&pp, cx.opt_vec3(&pp, &l.pivot)?)?;
    let node = node_at(cx, nodes, &path.key("at"), &l.at)?;
    let length = (nodes.nodes[node] - pivot).norm();
    if length <= nodes.tol {
        return Err(cx.err(
            &pp,
            "the pivot coincides with the linked node (zero length)",
        ));
    }
    let penalty = match l.penalty {
        Some(k) => cx.positive(&path.key("penalty"), k)?,
        None => LINK_PENALTY,
    };
    let tol = match l.tol {
        Some(t) => cx.positive(&path.key("tol"), t)?,
        None => LINK_TOL,
    };
    Ok(Link {
        node,
        pivot,
        length,
        penalty,
        tol,
    })
}

fn plane(cx: &Ctx, path: &KeyPath, name: &str) -> Result<Plane> {
    let normal = match name {
        "e2e3" | "e3e2" => 0,
        "e1e3" | "e3e1" => 1,
        "e1e2" | "e2e1" => 2,
        other => {
            return Err(cx.err(
                path,
                format!("unknown plane `{other}` (expected \"e2e3\", \"e1e3\" or \"e1e2\")"),
            ))
        }
    };
    Ok(Plane { normal })
}

/// A planar scene must be planar: every point, velocity, load, the gravity and the links
/// in the plane, every spin and moment about its normal, and the normal a principal axis
/// of every section (so that in-plane bending does not couple out of the plane). Then
/// removing the out-of-plane unknowns is exact, not an approximation.
#[allow(clippy::too_many_arguments)]
fn check_planar(
    cx: &Ctx,
    p: Plane,
    nodes: &NodeSet,
    elements: &[Element],
    loads: &[NodalLoad],
    links: &[Link],
    velocity0: &[Vec3],
    omega0: &[Vec3],
    gravity: &Vec3,
) -> Result<()> {
    let root = KeyPath::root();
    let k = p.normal;
    let off = |v: &Vec3| v[k].abs() > MERGE_TOL * v.norm().max(1.0);
    let tilted = |v: &Vec3| (0..3).any(|c| c != k && v[c].abs() > MERGE_TOL * v.norm().max(1.0));
    let why = |what: String| format!("scene is planar = \"{}\" but {what}", p.name());
    let plane_coord = nodes.nodes.first().map_or(0.0, |x| x[k]);
    let size = nodes.tol / MERGE_TOL;
    for (a, x) in nodes.nodes.iter().enumerate() {
        if (x[k] - plane_coord).abs() > MERGE_TOL * size.max(1.0) {
            return Err(cx.err(
                &root.key("planar"),
                why(format!("node {a} at {} is out of the plane", fmt_v(x))),
            ));
        }
    }
    for (e, el) in elements.iter().enumerate() {
        let tri = el.ref_triad[0];
        let n = tri.transpose() * Vec3::from_fn(|c, _| if c == k { 1.0 } else { 0.0 });
        // The normal in section coordinates must be d1 or d2 (n3 = 0 holds: in plane).
        let sec = &el.props;
        let principal = n[0].abs() < 1e-9 || n[1].abs() < 1e-9;
        let isotropic = sec.c_omega[(0, 1)] == 0.0
            && sec.c_omega[(0, 0)] == sec.c_omega[(1, 1)]
            && sec.c_gamma[0] == sec.c_gamma[1]
            && sec.i_rho[(0, 1)] == 0.0
            && sec.i_rho[(0, 0)] == sec.i_rho[(1, 1)];
        let aligned = principal && sec.c_omega[(0, 1)] == 0.0 && sec.i_rho[(0, 1)] == 0.0;
        if !(aligned || isotropic) {
            return Err(cx.err(
                &root.key("rod").idx(el.rod).key("d1"),
                why(format!(
                    "element {e}: the plane's normal is not a principal axis of the section (give d1 along or across the normal)"
                )),
            ));
        }
    }
    if off(gravity) {
        return Err(cx.err(
            &root.key("gravity"),
            why("gravity has an out-of-plane component".into()),
        ));
    }
    for (i, l) in loads.iter().enumerate() {
        if off(&l.force) {
            return Err(cx.err(
                &root.key("load").idx(i).key("force"),
                why("the force leaves the plane".into()),
            ));
        }
        if tilted(&l.moment) {
            return Err(cx.err(
                &root.key("load").idx(i).key("moment"),
                why("the moment is not about the normal".into()),
            ));
        }
    }
    for (i, l) in links.iter().enumerate() {
        if (l.pivot[k] - plane_coord).abs() > MERGE_TOL * size.max(1.0) {
            return Err(cx.err(
                &root.key("link").idx(i).key("pivot"),
                why("the pivot is out of the plane".into()),
            ));
        }
    }
    for (a, (v, w)) in velocity0.iter().zip(omega0).enumerate() {
        if off(v) || tilted(w) {
            return Err(cx.err(
                &root.key("initial_velocity"),
                why(format!("node {a} starts with v = {} and omega = {} (must stay in the plane and spin about its normal)", fmt_v(v), fmt_v(w))),
            ));
        }
    }
    Ok(())
}

/// A planar scene's initial configuration stays in the plane: positions in it, nodal
/// rotations about its normal, intrinsic curvature about its normal.
fn check_planar_shape(
    cx: &Ctx,
    p: Plane,
    plans: &[RodPlan],
    elements: &[Element],
    rods: &[RodInfo],
    shape: &ShapeSetup,
) -> Result<()> {
    let k = p.normal;
    let why = |what: String| format!("scene is planar = \"{}\" but {what}", p.name());
    let normal = Vec3::from_fn(|c, _| if c == k { 1.0 } else { 0.0 });
    if let Some(x) = shape.positions.first() {
        let plane_coord = x[k];
        let scale = shape.positions.iter().fold(1.0f64, |m, x| m.max(x.norm()));
        for (a, (x, r)) in shape.positions.iter().zip(&shape.rotations).enumerate() {
            if (x[k] - plane_coord).abs() > MERGE_TOL * scale || (r * normal - normal).amax() > 1e-9
            {
                let rod = rods
                    .iter()
                    .position(|info| rod_chain(elements, info).contains(&a))
                    .unwrap_or(0);
                return Err(cx.err(
                    &plans[rod].path.key("initial"),
                    why(format!(
                        "node {a} starts out of the plane or rotated about an in-plane axis (initial position {})",
                        fmt_v(x)
                    )),
                ));
            }
        }
    }
    for (plan, info) in plans.iter().zip(rods) {
        for el in &elements[info.elements.clone()] {
            let spatial = el.ref_triad[0] * plan.curvature;
            if (0..3).any(|c| c != k && spatial[c].abs() > 1e-12 * spatial.norm()) {
                return Err(cx.err(
                    &plan.path.key("curvature"),
                    why(format!(
                        "the intrinsic curvature {} bends about {} in space, not about the normal",
                        fmt_v(&plan.curvature),
                        fmt_v(&spatial)
                    )),
                ));
            }
        }
    }
    Ok(())
}

/// A planar scene's line loads push in the plane and turn about its normal (follower
/// loads: checked in the reference frame of every element they act on).
fn check_planar_line_loads(
    cx: &Ctx,
    p: Plane,
    elements: &[Element],
    line_loads: &[LineLoad],
) -> Result<()> {
    let k = p.normal;
    let off = |v: &Vec3| v[k].abs() > MERGE_TOL * v.norm().max(1.0);
    let tilted = |v: &Vec3| (0..3).any(|c| c != k && v[c].abs() > MERGE_TOL * v.norm().max(1.0));
    for (i, ll) in line_loads.iter().enumerate() {
        let path = KeyPath::root().key("line_load").idx(i);
        for &e in &ll.elements {
            let q = if ll.follower {
                elements[e].ref_triad[0]
            } else {
                Mat3::identity()
            };
            let (f, m) = (q * ll.force, q * ll.moment);
            let why = |what: &str| format!("scene is planar = \"{}\" but {what}", p.name());
            if off(&f) {
                return Err(cx.err(
                    &path.key("force"),
                    why(&format!("the force leaves the plane (on element {e})")),
                ));
            }
            if tilted(&m) {
                return Err(cx.err(
                    &path.key("moment"),
                    why(&format!(
                        "the moment is not about the normal (on element {e})"
                    )),
                ));
            }
        }
    }
    Ok(())
}

/// A planar scene's moving supports move in the plane and turn about its normal.
fn check_planar_drives(cx: &Ctx, p: Plane, raw: &RawScene, drives: &[SupportDrive]) -> Result<()> {
    let k = p.normal;
    let off = |v: &Vec3| v[k].abs() > MERGE_TOL * v.norm().max(1.0);
    let tilted = |v: &Vec3| (0..3).any(|c| c != k && v[c].abs() > MERGE_TOL * v.norm().max(1.0));
    let why = |what: &str| format!("scene is planar = \"{}\" but {what}", p.name());
    // Drives come in scene order: clamps with a motion, then pins with a motion.
    let moving = |list: &[RawSupport], kind: &'static str| -> Vec<KeyPath> {
        list.iter()
            .enumerate()
            .filter(|(_, c)| c.displacement.is_some() || c.rotation.is_some())
            .map(|(i, _)| KeyPath::root().key(kind).idx(i))
            .collect()
    };
    let mut paths = moving(&raw.clamp, "clamp");
    paths.extend(moving(&raw.pin, "pin"));
    for (d, path) in drives.iter().zip(paths) {
        if off(&d.displacement) {
            return Err(cx.err(
                &path.key("displacement"),
                why("the support moves out of the plane"),
            ));
        }
        if tilted(&d.rotation) {
            return Err(cx.err(
                &path.key("rotation"),
                why("the support turns about an in-plane axis"),
            ));
        }
    }
    Ok(())
}

/// The `cutback` of a scene with friction that does not set one (docs/scenes.md,
/// "Friction").
pub const FRICTION_CUTBACK: usize = 6;

/// A unit vector from `v` (error naming the key when it is zero).
fn unit(cx: &Ctx, path: &KeyPath, v: &[f64]) -> Result<Vec3> {
    let v = cx.vec3(path, v)?;
    let n = v.norm();
    if !(n > 0.0 && n.is_finite()) {
        return Err(cx.err(
            path,
            format!("{} is not a direction: give a nonzero vector", fmt_v(&v)),
        ));
    }
    Ok(v / n)
}

/// An `[[obstacle]]`: its shape, penalty and friction, and the contact nodes of its rods
/// (every node of the named rods, or of all rods) with their contact radius and
/// tributary length.
#[allow(clippy::too_many_arguments)]
fn obstacle(
    cx: &Ctx,
    path: &KeyPath,
    o: &RawObstacle,
    plans: &[RodPlan],
    rods: &[RodInfo],
    elements: &[Element],
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
) -> Result<crate::obstacle::Obstacle> {
    use crate::obstacle::{ContactNode, Obstacle, Shape};
    let kind = cx.required(&path.key("kind"), o.kind.as_deref())?;
    // Keys each kind takes (the others are an error naming the key).
    let allowed: &[&str] = match kind {
        "plane" => &["point", "normal"],
        "sphere" => &["center", "radius"],
        "cylinder" => &["point", "axis", "radius"],
        other => {
            return Err(cx.err(
                &path.key("kind"),
                format!(
                "unknown obstacle kind `{other}` (expected \"plane\", \"sphere\" or \"cylinder\")"
            ),
            ))
        }
    };
    for (key, given) in [
        ("point", o.point.is_some()),
        ("normal", o.normal.is_some()),
        ("center", o.center.is_some()),
        ("axis", o.axis.is_some()),
        ("radius", o.radius.is_some()),
    ] {
        if given && !allowed.contains(&key) {
            return Err(cx.err(
                &path.key(key),
                format!("a {kind} has no `{key}` (it takes {})", allowed.join(", ")),
            ));
        }
    }
    let req_vec = |key: &str, v: &Option<Vec<f64>>| -> Result<Vec3> {
        let p = path.key(key);
        cx.vec3(&p, cx.required(&p, v.as_deref())?)
    };
    let req_unit = |key: &str, v: &Option<Vec<f64>>| -> Result<Vec3> {
        let p = path.key(key);
        unit(cx, &p, cx.required(&p, v.as_deref())?)
    };
    let shape = match kind {
        "plane" => Shape::Plane {
            point: req_vec("point", &o.point)?,
            normal: req_unit("normal", &o.normal)?,
        },
        "sphere" => Shape::Sphere {
            center: req_vec("center", &o.center)?,
            radius: cx.req_positive(&path.key("radius"), o.radius)?,
        },
        _ => Shape::Cylinder {
            point: req_vec("point", &o.point)?,
            axis: req_unit("axis", &o.axis)?,
            radius: cx.req_positive(&path.key("radius"), o.radius)?,
        },
    };
    // The rods it acts on.
    let which: Vec<usize> = match &o.rods {
        None => (0..plans.len()).collect(),
        Some(names) => {
            if names.is_empty() {
                return Err(cx.err(
                    &path.key("rods"),
                    "empty list: name at least one rod (or leave `rods` out for all)",
                ));
            }
            names
                .iter()
                .enumerate()
                .map(|(i, n)| {
                    plans.iter().position(|p| &p.name == n).ok_or_else(|| {
                        cx.err(
                            &path.key("rods").idx(i),
                            format!(
                                "no rod named `{n}` (rods: {})",
                                plans
                                    .iter()
                                    .map(|p| p.name.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        )
                    })
                })
                .collect::<Result<_>>()?
        }
    };
    let radius_override = o
        .contact_radius
        .map(|r| cx.positive(&path.key("contact_radius"), r))
        .transpose()?;
    let mut per_node: BTreeMap<usize, (f64, f64)> = BTreeMap::new();
    let mut e_max: f64 = 0.0;
    for &ri in &which {
        let plan = &plans[ri];
        let sec = &sections[&plan.props_key.1];
        e_max = e_max.max(materials[&plan.props_key.0].e);
        let rho = radius_override.unwrap_or_else(|| (sec.a / std::f64::consts::PI).sqrt());
        for el in &elements[rods[ri].elements.clone()] {
            for &a in &el.nodes {
                let entry = per_node.entry(a).or_insert((0.0, 0.0));
                entry.0 = entry.0.max(rho);
                entry.1 += 0.5 * el.props.h;
            }
        }
    }
    let stiffness = match o.stiffness {
        None => e_max,
        Some(k) => cx.positive(&path.key("stiffness"), k)?,
    };
    let friction = cx.opt_non_negative(&path.key("friction"), o.friction)?;
    let slip = match o.slip {
        None => 1e-3,
        Some(s) => cx.positive(&path.key("slip"), s)?,
    };
    if o.slip.is_some() && friction == 0.0 {
        return Err(cx.err(&path.key("slip"), "only with `friction` > 0"));
    }
    let motion = match cx.opt_vec3(&path.key("displacement"), &o.displacement)? {
        None => {
            for (key, present) in [
                ("time", o.time.is_some()),
                ("factor", o.factor.is_some()),
                ("ramp", o.ramp.is_some()),
            ] {
                if present {
                    return Err(cx.err(
                        &path.key(key),
                        "only for a moving obstacle (give `displacement`)",
                    ));
                }
            }
            None
        }
        Some(displacement) => {
            if o.time.is_none() && o.factor.is_none() {
                return Err(cx.err(
                    &path.key("time"),
                    "required key missing: a moving obstacle needs its `time` and `factor` table",
                ));
            }
            Some(crate::obstacle::ObstacleMotion {
                displacement,
                table: time_table(cx, path, &o.time, &o.factor)?,
                ramp: ramp(cx, path, &o.ramp)?,
            })
        }
    };
    Ok(Obstacle {
        motion,
        shape,
        stiffness,
        friction,
        slip,
        nodes: per_node
            .into_iter()
            .map(|(node, (radius, length))| ContactNode {
                node,
                radius,
                length,
            })
            .collect(),
    })
}

/// A `[[contact]]`: the contact spheres of its rod(s) (nodes and points between them, at
/// most one contact radius apart), checked not to start overlapping.
#[allow(clippy::too_many_arguments)]
fn rod_contact(
    cx: &Ctx,
    path: &KeyPath,
    c: &RawContact,
    plans: &[RodPlan],
    rods: &[RodInfo],
    elements: &[Element],
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
    start: &[Vec3],
    spheres_so_far: &mut f64,
) -> Result<crate::rod_contact::RodContact> {
    use crate::rod_contact::{RodContact, SamplePoint};
    let rp = path.key("rods");
    let names = cx.required(&rp, c.rods.as_ref())?;
    if names.is_empty() || names.len() > 2 {
        return Err(cx.err(
            &rp,
            format!(
                "give one rod (contact with itself) or two (contact between them), got {}",
                names.len()
            ),
        ));
    }
    if names.len() == 2 && names[0] == names[1] {
        return Err(cx.err(
            &rp.idx(1),
            format!(
                "`{}` twice: for contact of a rod with itself give it once",
                names[0]
            ),
        ));
    }
    let friction = cx.opt_non_negative(&path.key("friction"), c.friction)?;
    let slip = match c.slip {
        None => 1e-3,
        Some(s) => cx.positive(&path.key("slip"), s)?,
    };
    if c.slip.is_some() && friction == 0.0 {
        return Err(cx.err(&path.key("slip"), "only with `friction` > 0"));
    }
    let which: Vec<usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            plans.iter().position(|p| &p.name == n).ok_or_else(|| {
                cx.err(
                    &rp.idx(i),
                    format!(
                        "no rod named `{n}` (rods: {})",
                        plans
                            .iter()
                            .map(|p| p.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })
        })
        .collect::<Result<_>>()?;
    let radius_override = c
        .contact_radius
        .map(|r| cx.positive(&path.key("contact_radius"), r))
        .transpose()?;
    // Count the spheres (in f64: a tiny radius overflows nothing) and their density along
    // the rods before allocating any of them.
    let radius_of = |ri: usize| {
        radius_override
            .unwrap_or_else(|| (sections[&plans[ri].props_key.1].a / std::f64::consts::PI).sqrt())
    };
    let mut count = 0.0f64;
    let mut per_diameter = 0.0f64;
    for &ri in &which {
        let rho = radius_of(ri);
        for el in &elements[rods[ri].elements.clone()] {
            let m = (el.props.h / rho).ceil().max(1.0);
            count += m;
            per_diameter = per_diameter.max(2.0 * rho * m / el.props.h);
        }
        count += 1.0;
    }
    *spheres_so_far += count;
    super::limits::check_contact_spheres(*spheres_so_far, per_diameter).map_err(|e| {
        let why = if radius_override.is_some() {
            String::new()
        } else {
            " (no `contact_radius` given: the default is each section's √(A/π))".to_string()
        };
        cx.err(&path.key("contact_radius"), format!("{e}{why}"))
    })?;
    let mut points = Vec::with_capacity(count as usize);
    let mut split = 0;
    let mut e_max: f64 = 0.0;
    for (k, &ri) in which.iter().enumerate() {
        let plan = &plans[ri];
        e_max = e_max.max(materials[&plan.props_key.0].e);
        let rho = radius_of(ri);
        let els = &elements[rods[ri].elements.clone()];
        let mut arc = 0.0;
        for (n, el) in els.iter().enumerate() {
            let h = el.props.h;
            let m = (h / rho).ceil().max(1.0) as usize;
            let last = n + 1 == els.len();
            for s in 0..m + usize::from(last) {
                points.push(SamplePoint {
                    nodes: el.nodes,
                    xi: s as f64 / m as f64,
                    radius: rho,
                    spacing: h / m as f64,
                    arc: arc + h * s as f64 / m as f64,
                });
            }
            arc += h;
        }
        if k == 0 {
            split = points.len();
        }
    }
    let stiffness = match c.stiffness {
        None => e_max,
        Some(k) => cx.positive(&path.key("stiffness"), k)?,
    };
    let contact = RodContact {
        rods: names.clone(),
        stiffness,
        friction,
        slip,
        split: if which.len() == 1 {
            points.len()
        } else {
            split
        },
        points,
    };
    if let Some(&(i, j)) = contact.candidates(start, 0.0).first() {
        let (a, b) = (contact.points[i].at(start), contact.points[j].at(start));
        return Err(cx.err(
            &rp,
            format!(
                "the rods start overlapping: contact spheres at {} and {} are {:.3e} apart, closer than their contact diameter {}",
                fmt_v(&a),
                fmt_v(&b),
                (a - b).norm(),
                fmt_num(contact.points[i].radius + contact.points[j].radius)
            ),
        ));
    }
    Ok(contact)
}

/// No node may start inside an obstacle (the penalty would throw it out at the first
/// step); resting on the surface is fine.
fn check_obstacle_start(
    cx: &Ctx,
    path: &KeyPath,
    o: &crate::obstacle::Obstacle,
    start: &[Vec3],
) -> Result<()> {
    for n in &o.nodes {
        let g = o.gap(n, &start[n.node]);
        if g < -1e-6 * n.radius {
            return Err(cx.err(
                &path.key("kind"),
                format!(
                    "node {} at {} starts inside the {} (penetration {:.3e} m, contact radius {}): start the rod at or outside its surface",
                    n.node,
                    fmt_v(&start[n.node]),
                    o.shape.name(),
                    -g,
                    fmt_num(n.radius)
                ),
            ));
        }
    }
    Ok(())
}

/// A planar scene's obstacles push in the plane: a plane's normal lies in it, a
/// cylinder's axis is its normal, a sphere's centre lies in it.
fn check_planar_obstacles(
    cx: &Ctx,
    p: Plane,
    obstacles: &[crate::obstacle::Obstacle],
    start: &[Vec3],
) -> Result<()> {
    use crate::obstacle::Shape;
    let k = p.normal;
    let why = |what: &str| format!("scene is planar = \"{}\" but {what}", p.name());
    let level = start.first().map_or(0.0, |x| x[k]);
    for (i, o) in obstacles.iter().enumerate() {
        let path = KeyPath::root().key("obstacle").idx(i);
        match &o.shape {
            Shape::Plane { normal, .. } if normal[k].abs() > MERGE_TOL => {
                return Err(cx.err(
                    &path.key("normal"),
                    why("the plane's normal leaves the plane"),
                ));
            }
            Shape::Cylinder { axis, .. } if (axis[k].abs() - 1.0).abs() > MERGE_TOL => {
                return Err(cx.err(
                    &path.key("axis"),
                    why("the cylinder's axis is not the plane's normal"),
                ));
            }
            Shape::Sphere { center, .. }
                if (center[k] - level).abs() > MERGE_TOL * center.norm().max(1.0) =>
            {
                return Err(cx.err(
                    &path.key("center"),
                    why("the sphere's centre is not in the plane"),
                ));
            }
            _ => {}
        }
        if let Some(m) = &o.motion {
            if m.displacement[k].abs() > MERGE_TOL * m.displacement.norm().max(1.0) {
                return Err(cx.err(
                    &path.key("displacement"),
                    why("the obstacle moves out of the plane"),
                ));
            }
        }
    }
    Ok(())
}

/// A planar scene's sliding clamps slide in the plane and spin (if at all) about its
/// normal, which only a slide along the normal would do: so no `spin`.
fn check_planar_slides(cx: &Ctx, p: Plane, raw: &RawScene, slides: &[Slide]) -> Result<()> {
    let why = |what: &str| format!("scene is planar = \"{}\" but {what}", p.name());
    let paths = raw
        .clamp
        .iter()
        .enumerate()
        .filter(|(_, c)| c.slide.is_some())
        .map(|(i, _)| KeyPath::root().key("clamp").idx(i));
    for (sl, path) in slides.iter().zip(paths) {
        if sl.axis[p.normal].abs() > MERGE_TOL {
            return Err(cx.err(&path.key("slide"), why("the clamp slides out of the plane")));
        }
        if sl.spin {
            return Err(cx.err(
                &path.key("spin"),
                why("a clamp sliding in the plane would spin about an in-plane axis"),
            ));
        }
    }
    Ok(())
}

/// A supported node cannot start moving in the directions its support fixes.
fn check_supported(
    cx: &Ctx,
    path: &KeyPath,
    a: usize,
    nodes: &NodeSet,
    support: Support,
    v: &Vec3,
    omega: &Vec3,
) -> Result<()> {
    let what = if support.translation && *v != Vec3::zeros() {
        Some(("translation", "v", v))
    } else if support.rotation && *omega != Vec3::zeros() {
        Some(("rotation", "omega", omega))
    } else {
        None
    };
    match what {
        Some((dof, key, value)) => Err(cx.err(
            path,
            format!(
                "node {a} at {} has its {dof} fixed by a support but would get {key} = {}",
                fmt_v(&nodes.nodes[a]),
                fmt_v(value)
            ),
        )),
        None => Ok(()),
    }
}

/// Validates `raw` and builds the scene.
pub(crate) fn build(raw: RawScene, doc: &Doc<'_>, file: &str) -> Result<Scene> {
    let cx = Ctx { file, doc };
    let root = KeyPath::root();

    let name = match &raw.name {
        Some(n) if n.trim().is_empty() => {
            return Err(cx.err(&root.key("name"), "must not be empty"))
        }
        Some(n) if n.len() > MAX_NAME_BYTES => {
            return Err(cx.err(
                &root.key("name"),
                format!(
                    "must be at most {MAX_NAME_BYTES} bytes long (got {} bytes)",
                    n.len()
                ),
            ))
        }
        Some(n) => n.clone(),
        None => {
            let stem = file.strip_prefix("builtin:").unwrap_or(file);
            std::path::Path::new(stem)
                .file_stem()
                .map_or_else(|| stem.to_string(), |s| s.to_string_lossy().into_owned())
        }
    };
    let gravity = cx
        .opt_vec3(&root.key("gravity"), &raw.gravity)?
        .unwrap_or_else(Vec3::zeros);

    let mut materials = BTreeMap::new();
    for (n, m) in &raw.material {
        materials.insert(n.clone(), material(&cx, &root.key("material").key(n), m)?);
    }
    let mut sections = BTreeMap::new();
    for (n, s) in &raw.section {
        sections.insert(n.clone(), section(&cx, &root.key("section").key(n), s)?);
    }

    // Integrator first: a missing table is a whole-file problem worth reporting early.
    let ip = root.key("integrator");
    let raw_int = raw.integrator.as_ref().ok_or_else(|| {
        cx.err(
            &ip,
            "required table [integrator] missing (scheme, dt, t_end)",
        )
    })?;
    let (mut params, output_every) = integrator(&cx, &ip, raw_int)?;

    if raw.rod.is_empty() {
        return Err(cx.err(&root.key("rod"), "no rods: give at least one [[rod]]"));
    }
    let mut plans = Vec::with_capacity(raw.rod.len());
    let mut names: HashMap<String, usize> = HashMap::new();
    for (i, r) in raw.rod.iter().enumerate() {
        let path = root.key("rod").idx(i);
        let plan = plan_rod(&cx, &path, i, r, &materials, &sections)?;
        if let Some(&j) = names.get(&plan.name) {
            return Err(cx.err(
                &path.key("name"),
                format!("duplicate rod name `{}` (also rod[{j}])", plan.name),
            ));
        }
        names.insert(plan.name.clone(), i);
        plans.push(plan);
    }
    // The whole scene's size, before meshing allocates anything per element.
    let mut total = 0usize;
    for (i, plan) in plans.iter().enumerate() {
        total = total.saturating_add(plan.counts.iter().sum::<usize>());
        if total > super::limits::MAX_SCENE_ELEMENTS {
            return Err(cx.err(
                &root.key("rod").idx(i).key("elements"),
                format!(
                    "the scene would have {total} or more elements, above the limit of {} for a whole scene",
                    super::limits::MAX_SCENE_ELEMENTS
                ),
            ));
        }
    }

    // Its memory, before meshing: a run holds its elements' solver data (check, run and
    // the members of a sweep alike).
    super::limits::check_batch(
        "this scene",
        1,
        &super::limits::Footprint::elements(total as u64),
    )
    .map_err(|e| cx.err(&root.key("rod"), e.to_string()))?;

    // Model size and merge tolerance from the bounding box of all rod points.
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in plans.iter().flat_map(|r| &r.points) {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let size = (hi - lo).norm();
    let tol = MERGE_TOL * size;

    let triads = plans
        .iter()
        .map(|plan| rod_triads(&cx, plan, tol))
        .collect::<Result<Vec<_>>>()?;

    let mut nodes = NodeSet::new(lo, tol.max(f64::MIN_POSITIVE));
    let (elements, rods) = mesh(&cx, &plans, &triads, &materials, &sections, &mut nodes)?;
    let n = nodes.nodes.len();

    let mut supports = vec![Support::default(); n];
    let mut drives: Vec<SupportDrive> = Vec::new();
    let mut slides: Vec<Slide> = Vec::new();
    let mut driven_by: HashMap<usize, KeyPath> = HashMap::new();
    for (kind, list) in [("clamp", &raw.clamp), ("pin", &raw.pin)] {
        for (i, c) in list.iter().enumerate() {
            let path = root.key(kind).idx(i);
            let a = node_at(&cx, &nodes, &path.key("at"), &c.at)?;
            supports[a].translation = true;
            supports[a].rotation |= kind == "clamp";
            if let Some(sl) = slide(&cx, &path, kind, a, c, &params)? {
                slides.push(sl);
            }
            if let Some(d) = support_drive(&cx, &path, kind, a, c)? {
                if let Some(other) = driven_by.get(&a) {
                    return Err(cx.err(
                        &path,
                        format!(
                            "node {a} is already driven by {}; give one moving support per node",
                            key_name(other)
                        ),
                    ));
                }
                driven_by.insert(a, path.clone());
                drives.push(d);
            }
        }
    }
    // A pin driven with a rotation would need a clamp; a clamp and a pin on one node give a
    // clamp, which holds the rotation the drive leaves at zero.

    let mut point_mass = vec![0.0; n];
    for (i, pm) in raw.point_mass.iter().enumerate() {
        let path = root.key("point_mass").idx(i);
        let a = node_at(&cx, &nodes, &path.key("at"), &pm.at)?;
        point_mass[a] += cx.req_positive(&path.key("mass"), pm.mass)?;
    }

    let loads = raw
        .load
        .iter()
        .enumerate()
        .map(|(i, l)| load(&cx, &nodes, &root.key("load").idx(i), l))
        .collect::<Result<Vec<_>>>()?;

    let shape = shape_setup(&cx, &raw.rod, &plans, &elements, &rods, &nodes)?;
    let x0: Vec<Vec3> = if shape.positions.is_empty() {
        nodes.nodes.clone()
    } else {
        shape.positions.clone()
    };
    let (velocity0, omega0) = initial_velocities(
        &cx,
        &raw.initial_velocity,
        &nodes,
        &x0,
        &supports,
        &plans,
        &elements,
        &rods,
    )?;

    let line_loads = raw
        .line_load
        .iter()
        .enumerate()
        .map(|(i, l)| line_load(&cx, &root.key("line_load").idx(i), l, &plans, &rods))
        .collect::<Result<Vec<_>>>()?;
    if matches!(params.scheme, Scheme::GenAlpha { .. }) {
        if let Some((_, path)) = driven_by.iter().min_by_key(|(a, _)| **a) {
            return Err(cx.err(
                path,
                "gen-alpha does not support moving supports; use em, edmc1, edmc2 or midpoint",
            ));
        }
        if let Some(i) = plans.iter().position(|p| p.drag != 0.0) {
            return Err(cx.err(
                &root.key("rod").idx(i).key("drag"),
                "gen-alpha does not support drag; use em, edmc1, edmc2 or midpoint",
            ));
        }
        if let Some((name, _)) = materials.iter().find(|(_, m)| m.damping != 0.0) {
            return Err(cx.err(
                &root.key("material").key(name).key("damping"),
                "gen-alpha does not support material damping; use em, edmc1, edmc2 or midpoint",
            ));
        }
    }
    if let Some(i) = line_loads.iter().position(|l| l.follower) {
        if matches!(params.scheme, Scheme::GenAlpha { .. }) {
            return Err(cx.err(
                &root.key("line_load").idx(i).key("follower"),
                "gen-alpha does not support follower loads; use em, edmc1, edmc2 or midpoint",
            ));
        }
    }

    let links = raw
        .link
        .iter()
        .enumerate()
        .map(|(i, l)| link(&cx, &nodes, &root.key("link").idx(i), l))
        .collect::<Result<Vec<_>>>()?;
    if !links.is_empty() && matches!(params.scheme, Scheme::GenAlpha { .. }) {
        // The baseline has no treatment of rigid links; `run` would fail at step 1.
        return Err(cx.err(
            &ip.key("scheme"),
            "gen-alpha does not support rigid links ([[link]]); use em, edmc1, edmc2 or midpoint",
        ));
    }
    let start: &[Vec3] = if shape.positions.is_empty() {
        &nodes.nodes
    } else {
        &shape.positions
    };
    let obstacles = raw
        .obstacle
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let path = root.key("obstacle").idx(i);
            let ob = obstacle(
                &cx, &path, o, &plans, &rods, &elements, &materials, &sections,
            )?;
            check_obstacle_start(&cx, &path, &ob, start)?;
            Ok(ob)
        })
        .collect::<Result<Vec<_>>>()?;
    let mut spheres = 0.0;
    let rod_contacts = raw
        .contact
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let path = root.key("contact").idx(i);
            rod_contact(
                &cx,
                &path,
                c,
                &plans,
                &rods,
                &elements,
                &materials,
                &sections,
                start,
                &mut spheres,
            )
        })
        .collect::<Result<Vec<_>>>()?;
    if !rod_contacts.is_empty() {
        let footprint = super::limits::Footprint {
            contact_spheres: rod_contacts.iter().map(|c| c.points.len() as u64).sum(),
            ..super::limits::Footprint::elements(elements.len() as u64)
        };
        super::limits::check_batch("this scene", 1, &footprint)
            .map_err(|e| cx.err(&root.key("contact"), e.to_string()))?;
    }
    // Friction's stick–slip transitions are hard on Newton's method: a scene with friction
    // cuts a failed step back (up to 64 sub-steps) unless it says otherwise.
    let friction =
        obstacles.iter().any(|o| o.friction > 0.0) || rod_contacts.iter().any(|c| c.friction > 0.0);
    if friction && raw_int.cutback.is_none() {
        params.cutback = FRICTION_CUTBACK;
    }
    if !rod_contacts.is_empty() && matches!(params.scheme, Scheme::GenAlpha { .. }) {
        return Err(cx.err(
            &ip.key("scheme"),
            "gen-alpha does not support contact between rods ([[contact]]); use em, edmc1, edmc2 or midpoint",
        ));
    }
    if !obstacles.is_empty() && matches!(params.scheme, Scheme::GenAlpha { .. }) {
        return Err(cx.err(
            &ip.key("scheme"),
            "gen-alpha does not support contact with obstacles ([[obstacle]]); use em, edmc1, edmc2 or midpoint",
        ));
    }
    let planar = match &raw.planar {
        None => None,
        Some(name) => {
            let p = plane(&cx, &root.key("planar"), name)?;
            check_planar(
                &cx, p, &nodes, &elements, &loads, &links, &velocity0, &omega0, &gravity,
            )?;
            check_planar_shape(&cx, p, &plans, &elements, &rods, &shape)?;
            check_planar_line_loads(&cx, p, &elements, &line_loads)?;
            check_planar_drives(&cx, p, &raw, &drives)?;
            check_planar_slides(&cx, p, &raw, &slides)?;
            check_planar_obstacles(&cx, p, &obstacles, start)?;
            Some(p)
        }
    };

    let mut probes: Vec<Probe> = Vec::with_capacity(raw.probe.len());
    for (i, p) in raw.probe.iter().enumerate() {
        let path = root.key("probe").idx(i);
        let pr = probe(&cx, &nodes, &elements, &rods, &path, i, p)?;
        if let Some(j) = probes.iter().position(|q| q.name == pr.name) {
            return Err(cx.err(
                &path.key("name"),
                format!("duplicate probe name `{}` (also probe[{j}])", pr.name),
            ));
        }
        probes.push(pr);
    }

    let model = Model {
        nodes: nodes.nodes,
        elements,
        supports,
        point_mass,
        loads,
        gravity,
        velocity0,
        omega0,
        rods,
        links,
        planar,
        shape,
        line_loads,
        drives,
        slides,
        obstacles,
        rod_contacts,
    };
    Ok(Scene {
        name,
        source: file.to_string(),
        description: raw.description.unwrap_or_default(),
        model,
        params,
        output_every,
        probes,
        cutback_set: raw_int.cutback.is_some(),
    })
}

/// A `[[probe]]`: `at` a node, or along a rod by `node` index (negative: from the end) or
/// arc length `s` (which must land on a node).
fn probe(
    cx: &Ctx,
    nodes: &NodeSet,
    elements: &[crate::model::Element],
    rods: &[crate::model::RodInfo],
    path: &KeyPath,
    i: usize,
    p: &RawProbe,
) -> Result<Probe> {
    let name = match &p.name {
        Some(n) => {
            cx.name(&path.key("name"), n, &[',', '"'])?;
            n.clone()
        }
        None => format!("probe{i}"),
    };
    let node = match (&p.at, &p.rod) {
        (Some(_), Some(_)) => {
            return Err(cx.err(&path.key("rod"), "give `at` or `rod`, not both"));
        }
        (None, None) => {
            return Err(cx.err(
                &path.key("at"),
                "required key missing (give `at`, or `rod` with `node` or `s`)",
            ));
        }
        (Some(_), None) => {
            if p.node.is_some() || p.s.is_some() {
                let k = if p.node.is_some() { "node" } else { "s" };
                return Err(cx.err(&path.key(k), "only with `rod`, not with `at`"));
            }
            node_at(cx, nodes, &path.key("at"), &p.at)?
        }
        (None, Some(rod)) => {
            let Some(info) = rods.iter().find(|r| &r.name == rod) else {
                let names: Vec<&str> = rods.iter().map(|r| r.name.as_str()).collect();
                return Err(cx.err(
                    &path.key("rod"),
                    format!("no rod named `{rod}` (rods: {})", names.join(", ")),
                ));
            };
            let els = &elements[info.elements.clone()];
            let mut chain = vec![els[0].nodes[0]];
            let mut arc = vec![0.0];
            for el in els {
                chain.push(el.nodes[1]);
                arc.push(arc.last().copied().unwrap_or(0.0) + el.props.h);
            }
            match (p.node, p.s) {
                (Some(_), Some(_)) => {
                    return Err(cx.err(&path.key("s"), "give `node` or `s`, not both"))
                }
                (None, None) => {
                    return Err(cx.err(
                        &path.key("node"),
                        "required key missing (give `node` or `s` with `rod`)",
                    ))
                }
                (Some(k), None) => {
                    let n = chain.len() as i64;
                    let j = if k < 0 { n + k } else { k };
                    if !(0..n).contains(&j) {
                        return Err(cx.err(
                            &path.key("node"),
                            format!(
                                "rod `{rod}` has nodes 0..{} (or -{n}..-1 from the end; got {k})",
                                n - 1
                            ),
                        ));
                    }
                    chain[j as usize]
                }
                (None, Some(s)) => {
                    let s = cx.finite(&path.key("s"), s)?;
                    let total = *arc.last().unwrap_or(&0.0);
                    let j = arc
                        .iter()
                        .enumerate()
                        .min_by(|a, b| (a.1 - s).abs().total_cmp(&(b.1 - s).abs()))
                        .map_or(0, |(j, _)| j);
                    if (arc[j] - s).abs() > 1e-9 * total.max(f64::MIN_POSITIVE) {
                        let below = arc.iter().rev().find(|&&x| x <= s).copied().unwrap_or(0.0);
                        let above = arc.iter().find(|&&x| x >= s).copied().unwrap_or(total);
                        return Err(cx.err(
                            &path.key("s"),
                            format!(
                                "s = {} is not at a node of rod `{rod}` (length {}; nearest nodes at s = {} and {})",
                                fmt_num(s),
                                fmt_num(total),
                                fmt_num(below),
                                fmt_num(above)
                            ),
                        ));
                    }
                    chain[j]
                }
            }
        }
    };
    Ok(Probe { name, node })
}
