//! `[[probe]]` entries: named nodes observed every step.

use super::check::{Ctx, Result};
use super::mesh::{node_at, rod_index, NodeSet};
use crate::model::{Element, RodInfo};
use crate::scene::fmt_num;
use crate::scene::raw::RawProbe;
use crate::scene::span::KeyPath;
use crate::scene::Probe;

/// A `[[probe]]`: `at` a node, or along a rod by `node` index (negative: from the end) or
/// arc length `s` (which must land on a node).
fn probe(
    cx: &Ctx,
    nodes: &NodeSet,
    elements: &[Element],
    rods: &[RodInfo],
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
            let info = &rods[rod_index(cx, &path.key("rod"), rod, rods)?];
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

/// The `[[probe]]` entries, names unique.
pub(super) fn probes(
    cx: &Ctx,
    raw: &[RawProbe],
    nodes: &NodeSet,
    elements: &[Element],
    rods: &[RodInfo],
) -> Result<Vec<Probe>> {
    let root = KeyPath::root();
    let mut probes: Vec<Probe> = Vec::with_capacity(raw.len());
    for (i, p) in raw.iter().enumerate() {
        let path = root.key("probe").idx(i);
        let pr = probe(cx, nodes, elements, rods, &path, i, p)?;
        if let Some(j) = probes.iter().position(|q| q.name == pr.name) {
            return Err(cx.err(
                &path.key("name"),
                format!("duplicate probe name `{}` (also probe[{j}])", pr.name),
            ));
        }
        probes.push(pr);
    }
    Ok(probes)
}
