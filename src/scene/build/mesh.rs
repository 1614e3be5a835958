//! Meshing: segment triads, nodes merged through a grid, elements with their continuum
//! constants; and the lookups of nodes and elements that later stages name by point, rod
//! and segment.

use std::collections::{BTreeMap, HashMap};

use super::check::{fmt_v, Ctx, Result};
use super::rods::{Material, RodPlan, Section};
use crate::model::{Element, ElementProps, Mat3, RodInfo, Vec3};
use crate::scene::fmt_num;
use crate::scene::span::KeyPath;

/// Relative tolerance (× model size) for merging nodes and matching `at` points.
pub(super) const MERGE_TOL: f64 = 1e-9;
/// Below this `|sin|` of the angle between `d1` and a segment, `d1` counts as parallel.
const PARALLEL_TOL: f64 = 1e-6;

/// Nodes with merging of coincident points through a uniform grid of cell size `tol`.
pub(super) struct NodeSet {
    pub(super) nodes: Vec<Vec3>,
    pub(super) grid: HashMap<[i64; 3], Vec<usize>>,
    pub(super) origin: Vec3,
    pub(super) tol: f64,
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

pub(super) fn node_at(
    cx: &Ctx,
    nodes: &NodeSet,
    path: &KeyPath,
    at: &Option<Vec<f64>>,
) -> Result<usize> {
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

/// The elements a `rod` (and optional `segment`) key pair names.
pub(super) fn rod_elements(
    cx: &Ctx,
    path: &KeyPath,
    rod: &Option<String>,
    segment: Option<i64>,
    plans: &[RodPlan],
    rods: &[RodInfo],
) -> Result<Vec<usize>> {
    let rp = path.key("rod");
    let rod = cx.required(&rp, rod.as_ref())?;
    let ri = rod_index(cx, &rp, rod, rods)?;
    let range = rods[ri].elements.clone();
    match segment {
        None => Ok(range.collect()),
        Some(sg) => {
            let counts = &plans[ri].counts;
            let (sg, offset) = rod_segment(cx, path, rod, sg, counts)?;
            let start = range.start + offset;
            Ok((start..start + counts[sg]).collect())
        }
    }
}

/// The index of the rod named `rod` (the error, at `path`, lists the rods).
pub(super) fn rod_index(cx: &Ctx, path: &KeyPath, rod: &str, rods: &[RodInfo]) -> Result<usize> {
    rods.iter().position(|r| r.name == rod).ok_or_else(|| {
        let names: Vec<&str> = rods.iter().map(|r| r.name.as_str()).collect();
        cx.err(
            path,
            format!("no rod named `{rod}` (rods: {})", names.join(", ")),
        )
    })
}

/// Segment `sg` (the `segment` key under `path`) of rod `rod`, whose segments have
/// `counts` elements: its index, and the number of elements before it along the rod.
pub(super) fn rod_segment(
    cx: &Ctx,
    path: &KeyPath,
    rod: &str,
    sg: i64,
    counts: &[usize],
) -> Result<(usize, usize)> {
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
    Ok((sg, counts[..sg].iter().sum()))
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
            curvature_measure: plan.curvature_measure,
        });
    }
    Ok((elements, rods))
}

/// The nodes of a rod in order along it (`N` elements: `N + 1` entries; a closed rod
/// repeats its first node at the end).
pub(super) fn rod_chain(elements: &[Element], info: &RodInfo) -> Vec<usize> {
    let els = &elements[info.elements.clone()];
    let mut chain = Vec::with_capacity(els.len() + 1);
    chain.push(els[0].nodes[0]);
    chain.extend(els.iter().map(|e| e.nodes[1]));
    chain
}

/// Meshes the planned rods: the model size and merge tolerance from the bounding box of
/// all rod points, each segment's triad, then the merged nodes and the elements.
pub(super) fn mesh_rods(
    cx: &Ctx,
    plans: &[RodPlan],
    materials: &BTreeMap<String, Material>,
    sections: &BTreeMap<String, Section>,
) -> Result<(NodeSet, Vec<Element>, Vec<RodInfo>)> {
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
        .map(|plan| rod_triads(cx, plan, tol))
        .collect::<Result<Vec<_>>>()?;

    let mut nodes = NodeSet::new(lo, tol.max(f64::MIN_POSITIVE));
    let (elements, rods) = mesh(cx, plans, &triads, materials, sections, &mut nodes)?;
    Ok((nodes, elements, rods))
}
