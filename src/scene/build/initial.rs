//! The initial state on the mesh: each rod's initial configuration and intrinsic curvature
//! (`[rod.initial]`, `curvature`), and the `[[initial_velocity]]` entries, checked against
//! the supports.

use super::check::{fmt_v, Ctx, Result};
use super::mesh::{node_at, rod_chain, rod_index, rod_segment, NodeSet};
use super::rods::RodPlan;
use crate::model::{Element, Mat3, RodInfo, ShapeSetup, Support, Vec3};
use crate::scene::raw::{RawInitialVelocity, RawRod};
use crate::scene::span::KeyPath;

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
pub(super) fn shape_setup(
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
pub(super) fn initial_velocities(
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
            let ri = rod_index(cx, &rp, rod, rods)?;
            let chain = rod_chain(elements, &rods[ri]);
            let (sel, what) = match iv.segment {
                None => (chain, format!("rod `{rod}`")),
                Some(sg) => {
                    let counts = &plans[ri].counts;
                    let (sg, start) = rod_segment(cx, &path, rod, sg, counts)?;
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
