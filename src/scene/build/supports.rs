//! Supports on the mesh: `[[clamp]]` and `[[pin]]` entries (fixed, sliding or driven)
//! and `[[link]]` constraints to fixed pivots.

use std::collections::HashMap;

use super::check::{fmt_v, ramp, time_table, Ctx, Result};
use super::mesh::{node_at, NodeSet};
use crate::integrator::params::{IntegratorParams, Scheme};
use crate::model::{Link, Slide, Support, SupportDrive, Vec3};
use crate::scene::key_name;
use crate::scene::raw::{RawLink, RawScene, RawSupport};
use crate::scene::span::KeyPath;

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
    let spin = c.spin.unwrap_or(false);
    // Driven while it slides: moved only across the axis and turned only about it (a
    // coordinate axis, whose other components are removed and take the prescribed
    // motion; an oblique slide's constraint rows hold no motion).
    if c.displacement.is_some() || c.rotation.is_some() {
        let Some(k) = (0..3).find(|&k| (0..3).all(|j| j == k || axis[j] == 0.0)) else {
            return Err(cx.err(
                &sp,
                format!(
                    "{}: a driven sliding clamp needs a coordinate axis ([1, 0, 0], [0, 1, 0], [0, 0, 1] or their negatives)",
                    fmt_v(&v)
                ),
            ));
        };
        let along = |key: &str, raw: &Option<Vec<f64>>| -> Result<Option<Vec3>> {
            raw.as_ref().map(|r| cx.vec3(&path.key(key), r)).transpose()
        };
        if let Some(d) = along("displacement", &c.displacement)? {
            if d[k] != 0.0 {
                return Err(cx.err(
                    &path.key("displacement"),
                    format!(
                        "{}: a sliding clamp is driven only across its axis (component {} along it)",
                        fmt_v(&d),
                        d[k]
                    ),
                ));
            }
        }
        if let Some(r) = along("rotation", &c.rotation)? {
            if spin && r != Vec3::zeros() {
                return Err(cx.err(
                    &path.key("rotation"),
                    "a spinning sliding clamp turns freely about its axis: it cannot also be turned",
                ));
            }
            if (0..3).any(|j| j != k && r[j] != 0.0) {
                return Err(cx.err(
                    &path.key("rotation"),
                    format!(
                        "{}: a sliding clamp is turned only about its axis",
                        fmt_v(&r)
                    ),
                ));
            }
        }
    }
    if matches!(params.scheme, Scheme::GenAlpha { .. }) {
        return Err(cx.err(
            &sp,
            "gen-alpha does not support sliding clamps; use em, edmc1, edmc2 or midpoint",
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

/// Default penalty `κ` of a `[[link]]` (DESIGN §6: 1e5 for the mechanism).
const LINK_PENALTY: f64 = 1e5;
/// Default tolerance on a link's `|g|`.
const LINK_TOL: f64 = 1e-10;

pub(super) fn link(cx: &Ctx, nodes: &NodeSet, path: &KeyPath, l: &RawLink) -> Result<Link> {
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

/// The supports of a scene's nodes: what each fixes, and the moving and sliding ones.
pub(super) struct Supports {
    /// Per node: the translation and rotation it fixes.
    pub(super) supports: Vec<Support>,
    /// Moving supports, clamps first, then pins, each in scene order.
    pub(super) drives: Vec<SupportDrive>,
    /// Sliding clamps in scene order.
    pub(super) slides: Vec<Slide>,
    /// The entry driving each driven node.
    pub(super) driven_by: HashMap<usize, KeyPath>,
}

/// The `[[clamp]]` and `[[pin]]` entries, clamps first: at most one moving support a node.
pub(super) fn supports(
    cx: &Ctx,
    raw: &RawScene,
    nodes: &NodeSet,
    params: &IntegratorParams,
) -> Result<Supports> {
    let root = KeyPath::root();
    let n = nodes.nodes.len();
    let mut supports = vec![Support::default(); n];
    let mut drives: Vec<SupportDrive> = Vec::new();
    let mut slides: Vec<Slide> = Vec::new();
    let mut driven_by: HashMap<usize, KeyPath> = HashMap::new();
    for (kind, list) in [("clamp", &raw.clamp), ("pin", &raw.pin)] {
        for (i, c) in list.iter().enumerate() {
            let path = root.key(kind).idx(i);
            let a = node_at(cx, nodes, &path.key("at"), &c.at)?;
            supports[a].translation = true;
            supports[a].rotation |= kind == "clamp";
            if let Some(sl) = slide(cx, &path, kind, a, c, params)? {
                slides.push(sl);
            }
            if let Some(d) = support_drive(cx, &path, kind, a, c)? {
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
    Ok(Supports {
        supports,
        drives,
        slides,
        driven_by,
    })
}
