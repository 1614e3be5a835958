//! Numbering of the Newton unknowns: per node `u` (3, unless the translation is
//! supported), `θ` (3, unless clamped), `g` (3, only with translational dissipation and a
//! free translation). Removed unknowns are zero.

use crate::element::{g_idx, th_idx, u_idx, NDOF};
use crate::model::Model;

/// Marks an element-local unknown that does not exist.
pub const NONE: usize = usize::MAX;

/// Global index of the first component of each block of a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeDofs {
    /// Start of `u`, or [`NONE`].
    pub u: usize,
    /// Start of `θ`, or [`NONE`].
    pub th: usize,
    /// Start of `g`, or [`NONE`].
    pub g: usize,
}

/// The unknown numbering of a model.
#[derive(Clone, Debug)]
pub struct DofMap {
    /// Per node.
    pub nodes: Vec<NodeDofs>,
    /// Per element: global index of each element-local unknown, or [`NONE`].
    pub elements: Vec<[usize; NDOF]>,
    /// Total number of unknowns.
    pub n: usize,
}

impl DofMap {
    /// Numbers the unknowns node by node (keeps the matrix block-banded along a rod).
    pub fn new(model: &Model, with_g: bool) -> Self {
        let mut n = 0;
        let mut take = |free: bool| {
            if free {
                n += 3;
                n - 3
            } else {
                NONE
            }
        };
        let nodes: Vec<NodeDofs> = model
            .supports
            .iter()
            .map(|s| NodeDofs {
                u: take(!s.translation),
                th: take(!s.rotation),
                g: take(with_g && !s.translation),
            })
            .collect();
        let elements = model
            .elements
            .iter()
            .map(|e| {
                let mut m = [NONE; NDOF];
                for l in 0..2 {
                    let nd = nodes[e.nodes[l]];
                    for c in 0..3 {
                        let add = |base: usize| if base == NONE { NONE } else { base + c };
                        m[u_idx(l) + c] = add(nd.u);
                        m[th_idx(l) + c] = add(nd.th);
                        m[g_idx(l) + c] = add(nd.g);
                    }
                }
                m
            })
            .collect();
        Self { nodes, elements, n }
    }

    /// Sparsity pattern: every pair of unknowns of a common element.
    pub fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = Vec::new();
        for m in &self.elements {
            for &i in m.iter().filter(|&&i| i != NONE) {
                for &j in m.iter().filter(|&&j| j != NONE) {
                    p.push((i, j));
                }
            }
        }
        p
    }
}
