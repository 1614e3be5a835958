//! Materials, sections and rod plans: each `[material.*]`, `[section.*]` and `[[rod]]`
//! checked on its own, before anything is meshed; then the scene's size against its limits.

use std::collections::{BTreeMap, HashMap};

use nalgebra::Matrix2;

use super::check::{Ctx, Result, MAX_COORDINATE};
use crate::model::{CurvatureMeasure, Vec3};
use crate::scene::fmt_num;
use crate::scene::limits;
use crate::scene::raw::{RawMaterial, RawRod, RawSection};
use crate::scene::span::KeyPath;

/// Cap on elements per segment (guards against a typo allocating the machine away); the
/// scene as a whole has the same cap ([`limits::MAX_SCENE_ELEMENTS`]).
const MAX_ELEMENTS: i64 = limits::MAX_SCENE_ELEMENTS as i64;

/// A validated material.
pub(super) struct Material {
    pub(super) e: f64,
    pub(super) g: f64,
    pub(super) density: f64,
    pub(super) damping: f64,
}

/// A validated section.
pub(super) struct Section {
    pub(super) a: f64,
    pub(super) i11: f64,
    pub(super) i22: f64,
    pub(super) i12: f64,
    pub(super) j: f64,
    pub(super) a1: f64,
    pub(super) a2: f64,
    pub(super) rho_inertia: Matrix2<f64>,
}

pub(super) fn material(cx: &Ctx, path: &KeyPath, m: &RawMaterial) -> Result<Material> {
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

pub(super) fn section(cx: &Ctx, path: &KeyPath, s: &RawSection) -> Result<Section> {
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
pub(super) struct RodPlan {
    pub(super) name: String,
    pub(super) points: Vec<Vec3>,
    pub(super) counts: Vec<usize>,
    pub(super) d1: Option<Vec3>,
    pub(super) curvature: Vec3,
    pub(super) curvature_measure: CurvatureMeasure,
    pub(super) drag: f64,
    pub(super) props_key: (String, String),
    pub(super) path: KeyPath,
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
    let curvature_measure = match r.curvature_measure.as_deref() {
        None | Some("sine") => CurvatureMeasure::Sine,
        Some("rational") => CurvatureMeasure::Rational,
        Some(other) => {
            return Err(cx.err(
                &path.key("curvature_measure"),
                format!("unknown curvature measure `{other}` (known: `sine`, `rational`)"),
            ))
        }
    };
    let drag = cx.opt_non_negative(&path.key("drag"), r.drag)?;
    Ok(RodPlan {
        name,
        points,
        counts,
        d1,
        curvature,
        curvature_measure,
        drag,
        props_key: (mat, sec),
        path: path.clone(),
    })
}

/// Plans every `[[rod]]` (at least one, names unique), then checks the whole scene's size
/// and memory before meshing allocates anything per element.
pub(super) fn plan_rods(
    cx: &Ctx,
    raw: &[RawRod],
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
) -> Result<Vec<RodPlan>> {
    let root = KeyPath::root();
    if raw.is_empty() {
        return Err(cx.err(&root.key("rod"), "no rods: give at least one [[rod]]"));
    }
    let mut plans = Vec::with_capacity(raw.len());
    let mut names: HashMap<String, usize> = HashMap::new();
    for (i, r) in raw.iter().enumerate() {
        let path = root.key("rod").idx(i);
        let plan = plan_rod(cx, &path, i, r, materials, sections)?;
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
        if total > limits::MAX_SCENE_ELEMENTS {
            return Err(cx.err(
                &root.key("rod").idx(i).key("elements"),
                format!(
                    "the scene would have {total} or more elements, above the limit of {} for a whole scene",
                    limits::MAX_SCENE_ELEMENTS
                ),
            ));
        }
    }

    // Its memory, before meshing: a run holds its elements' solver data (check, run and
    // the members of a sweep alike).
    limits::check_batch("this scene", 1, &limits::Footprint::elements(total as u64))
        .map_err(|e| cx.err(&root.key("rod"), e.to_string()))?;
    Ok(plans)
}
