//! Validation pass: checks every value of a [`RawScene`] and builds the [`Model`] and
//! [`IntegratorParams`]. Every error names its key path; the document tree gives it a
//! `line:column`.
//!
//! [`build`] runs the stages in data-flow order, one file each: the shared value checks
//! (`check`), the `[integrator]` table (`integrator`), materials, sections and rod plans
//! (`rods`), meshing (`mesh`), supports and links (`supports`), point masses and loads
//! (`loads`), the initial state (`initial`), contact (`contact`), the planar checks
//! (`planar`) and probes (`probes`). A stage uses only the stages before it; the order of
//! the calls here is the order in which errors are found.

mod check;
mod contact;
mod initial;
mod integrator;
mod loads;
mod mesh;
mod planar;
mod probes;
mod rods;
mod supports;

use std::collections::BTreeMap;

use self::check::{Ctx, Result, MAX_NAME_BYTES};
use self::contact::{check_obstacle_start, obstacle, rod_contact, FRICTION_CUTBACK};
use self::initial::{initial_velocities, shape_setup};
use self::integrator::integrator;
use self::loads::{line_load, load};
use self::planar::{
    check_planar, check_planar_drives, check_planar_line_loads, check_planar_obstacles,
    check_planar_shape, check_planar_slides, plane,
};
use self::rods::{material, section};
use self::supports::{link, Supports};
use super::raw::RawScene;
use super::span::{Doc, KeyPath};
use super::{limits, Scene};
use crate::integrator::params::Scheme;
use crate::model::{CurvatureMeasure, Model, Vec3};

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

    let plans = rods::plan_rods(&cx, &raw.rod, &materials, &sections)?;
    if let Some(i) = plans
        .iter()
        .position(|p| p.curvature_measure == CurvatureMeasure::Rational)
    {
        let path = root.key("rod").idx(i).key("curvature_measure");
        if params.scheme != Scheme::Em {
            return Err(cx.err(
                &path,
                format!(
                    "the rational curvature measure runs with scheme em only (got {}); use em or curvature_measure = \"sine\"",
                    params.scheme.name()
                ),
            ));
        }
        if raw.planar.is_some() {
            return Err(cx.err(
                &path,
                "the rational curvature measure has no planar kernel; remove [planar] or use curvature_measure = \"sine\"",
            ));
        }
    }
    let (nodes, elements, rods) = mesh::mesh_rods(&cx, &plans, &materials, &sections)?;

    let Supports {
        supports,
        drives,
        slides,
        driven_by,
    } = supports::supports(&cx, &raw, &nodes, &params)?;

    let point_mass = loads::point_masses(&cx, &raw.point_mass, &nodes)?;

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
        let footprint = limits::Footprint {
            contact_spheres: rod_contacts.iter().map(|c| c.points.len() as u64).sum(),
            ..limits::Footprint::elements(elements.len() as u64)
        };
        limits::check_batch("this scene", 1, &footprint)
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

    let probes = probes::probes(&cx, &raw.probe, &nodes, &elements, &rods)?;

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
