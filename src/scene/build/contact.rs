//! Contact: `[[obstacle]]` entries (shape, penalty, friction, motion, contact nodes) and
//! `[[contact]]` entries between rods (contact spheres), each checked not to start
//! penetrating.

use std::collections::BTreeMap;

use super::check::{fmt_v, ramp, time_table, Ctx, Result};
use super::rods::{Material, RodPlan, Section};
use crate::model::{Element, RodInfo, Vec3};
use crate::scene::fmt_num;
use crate::scene::limits;
use crate::scene::raw::{RawContact, RawObstacle};
use crate::scene::span::KeyPath;

/// The `cutback` of a scene with friction that does not set one (docs/scenes.md,
/// "Friction").
pub const FRICTION_CUTBACK: usize = 6;

/// Most quadrature points per contact radius of line contact (`points_per_radius`).
const MAX_POINTS_PER_RADIUS: i64 = 64;

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
pub(super) fn obstacle(
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
    let law = match o.friction_law.as_deref() {
        None | Some("regularized") => {
            if o.tangential_stiffness.is_some() {
                return Err(cx.err(
                    &path.key("tangential_stiffness"),
                    "only with friction_law = \"stick\"",
                ));
            }
            crate::obstacle::FrictionLaw::Regularized
        }
        Some("stick") => {
            if friction == 0.0 {
                return Err(cx.err(&path.key("friction_law"), "only with `friction` > 0"));
            }
            if o.slip.is_some() {
                return Err(cx.err(
                    &path.key("slip"),
                    "only with friction_law = \"regularized\" (the stick law has no slip speed)",
                ));
            }
            crate::obstacle::FrictionLaw::Stick {
                stiffness: match o.tangential_stiffness {
                    None => stiffness,
                    Some(k) => cx.positive(&path.key("tangential_stiffness"), k)?,
                },
            }
        }
        Some(other) => {
            return Err(cx.err(
                &path.key("friction_law"),
                format!("unknown friction law `{other}` (expected \"regularized\" or \"stick\")"),
            ))
        }
    };
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
        law,
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
pub(super) fn rod_contact(
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
    use crate::rod_contact::{ContactModel, RodContact, SamplePoint, Stencil};
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
    let model = match c.model.as_deref() {
        None | Some("spheres") => ContactModel::Spheres,
        Some("line") => ContactModel::Line,
        Some("smooth") => ContactModel::Smooth,
        Some(other) => {
            return Err(cx.err(
                &path.key("model"),
                format!("unknown contact model `{other}` (models: spheres, line, smooth)"),
            ))
        }
    };
    // Line contact's quadrature points per contact radius along each element.
    let per_radius = match c.points_per_radius {
        None => 16.0,
        Some(_) if model == ContactModel::Spheres => {
            return Err(cx.err(
                &path.key("points_per_radius"),
                "only with `model = \"line\"` or `\"smooth\"`",
            ))
        }
        Some(n) if (1..=MAX_POINTS_PER_RADIUS).contains(&n) => n as f64,
        Some(n) => {
            return Err(cx.err(
                &path.key("points_per_radius"),
                format!("must be an integer from 1 to {MAX_POINTS_PER_RADIUS}, got {n}"),
            ))
        }
    };
    // Points on an element of length `h` at contact radius `ρ`: spheres at most `ρ` apart
    // (both ends included where the rod ends), or line contact's midpoint rule.
    let per_element = |h: f64, rho: f64| -> f64 {
        match model {
            ContactModel::Spheres => (h / rho).ceil().max(1.0),
            ContactModel::Line | ContactModel::Smooth => (per_radius * h / rho).ceil().max(1.0),
        }
    };
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
            let m = per_element(el.props.h, rho);
            count += m;
            per_diameter = per_diameter.max(2.0 * rho * m / el.props.h);
        }
        count += 1.0;
    }
    *spheres_so_far += count;
    limits::check_contact_spheres(*spheres_so_far, per_diameter).map_err(|e| {
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
        if model == ContactModel::Smooth {
            let chain = super::mesh::rod_chain(elements, &rods[ri]);
            let h: Vec<f64> = els.iter().map(|el| el.props.h).collect();
            points.extend(crate::rod_contact::smooth_points(
                &chain, &h, rho, per_radius,
            ));
            if k == 0 {
                split = points.len();
            }
            continue;
        }
        let mut arc = 0.0;
        for (n, el) in els.iter().enumerate() {
            let h = el.props.h;
            let m = per_element(h, rho) as usize;
            if model == ContactModel::Line {
                for s in 0..m {
                    let xi = (s as f64 + 0.5) / m as f64;
                    points.push(SamplePoint {
                        nodes: el.nodes,
                        xi,
                        stencil: Stencil::linear(el.nodes, xi),
                        radius: rho,
                        spacing: h / m as f64,
                        arc: arc + h * xi,
                    });
                }
                arc += h;
                continue;
            }
            let last = n + 1 == els.len();
            for s in 0..m + usize::from(last) {
                points.push(SamplePoint {
                    nodes: el.nodes,
                    xi: s as f64 / m as f64,
                    stencil: Stencil::linear(el.nodes, s as f64 / m as f64),
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
        model,
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
                "the rods start overlapping: contact points at {} and {} are {:.3e} apart, closer than their contact diameter {}",
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
pub(super) fn check_obstacle_start(
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
