//! `planar = "..."`: the plane, and the checks that everything the scene holds (nodes,
//! sections, loads, links, initial state, supports, obstacles) stays in it, so that
//! removing the out-of-plane unknowns is exact.

use super::check::{fmt_v, Ctx, Result};
use super::mesh::{rod_chain, NodeSet, MERGE_TOL};
use super::rods::RodPlan;
use crate::model::{
    Element, LineLoad, Link, Mat3, NodalLoad, Plane, RodInfo, ShapeSetup, Slide, SupportDrive, Vec3,
};
use crate::scene::raw::{RawScene, RawSupport};
use crate::scene::span::KeyPath;

pub(super) fn plane(cx: &Ctx, path: &KeyPath, name: &str) -> Result<Plane> {
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
pub(super) fn check_planar(
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
pub(super) fn check_planar_shape(
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
pub(super) fn check_planar_line_loads(
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
pub(super) fn check_planar_drives(
    cx: &Ctx,
    p: Plane,
    raw: &RawScene,
    drives: &[SupportDrive],
) -> Result<()> {
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

/// A planar scene's obstacles push in the plane: a plane's normal lies in it, a
/// cylinder's axis is its normal, a sphere's centre lies in it.
pub(super) fn check_planar_obstacles(
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
pub(super) fn check_planar_slides(
    cx: &Ctx,
    p: Plane,
    raw: &RawScene,
    slides: &[Slide],
) -> Result<()> {
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
