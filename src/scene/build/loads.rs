//! Point masses, nodal loads (`[[load]]`) and line loads (`[[line_load]]`) on the mesh.

use super::check::{time_table, Ctx, Result};
use super::mesh::{node_at, rod_elements, NodeSet};
use super::rods::RodPlan;
use crate::model::{LineLoad, NodalLoad, RodInfo, Vec3};
use crate::scene::raw::{RawLineLoad, RawLoad, RawPointMass};
use crate::scene::span::KeyPath;

pub(super) fn load(cx: &Ctx, nodes: &NodeSet, path: &KeyPath, l: &RawLoad) -> Result<NodalLoad> {
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

pub(super) fn line_load(
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

/// The `[[point_mass]]` entries, summed per node.
pub(super) fn point_masses(cx: &Ctx, raw: &[RawPointMass], nodes: &NodeSet) -> Result<Vec<f64>> {
    let root = KeyPath::root();
    let mut point_mass = vec![0.0; nodes.nodes.len()];
    for (i, pm) in raw.iter().enumerate() {
        let path = root.key("point_mass").idx(i);
        let a = node_at(cx, nodes, &path.key("at"), &pm.at)?;
        point_mass[a] += cx.req_positive(&path.key("mass"), pm.mass)?;
    }
    Ok(point_mass)
}
