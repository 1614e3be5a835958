//! Numbering of the Newton unknowns: per node `u` (3, unless the translation is
//! supported; a sliding clamp keeps the component along a coordinate axis, or all three
//! along an oblique one), `θ` (3, unless
//! clamped; a spinning sliding clamp keeps the one about its axis), `g` (3, only with translational dissipation and a
//! free translation). A planar model also drops the out-of-plane translation (and its
//! `g`) and the two rotations about in-plane axes. Removed unknowns are zero.

use crate::element::{g_idx, th_idx, u_idx, NDOF};
use crate::model::Model;

/// Marks an element-local unknown that does not exist.
pub const NONE: usize = usize::MAX;

/// Global index of each component of each block of a node ([`NONE`] where removed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeDofs {
    /// Components of `u`.
    pub u: [usize; 3],
    /// Components of `θ`.
    pub th: [usize; 3],
    /// Components of `g`.
    pub g: [usize; 3],
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
    /// Per element: a bit per element-local row that is an unknown (bit `r` set when row
    /// `r` of the element's 18 is numbered), the activity mask the GPU kernels use.
    pub fn element_row_masks(&self) -> Vec<u32> {
        self.elements
            .iter()
            .map(|m| {
                m.iter()
                    .enumerate()
                    .filter(|(_, &i)| i != NONE)
                    .fold(0u32, |acc, (r, _)| acc | (1 << r))
            })
            .collect()
    }

    /// Numbers the unknowns node by node (keeps the matrix block-banded along a rod).
    pub fn new(model: &Model, with_g: bool) -> Self {
        let mut n = 0;
        let mut take = |free: bool| {
            if free {
                n += 1;
                n - 1
            } else {
                NONE
            }
        };
        let plane = model.planar;
        let in_plane = |c: usize| plane.is_none_or(|p| p.keeps_translation(c));
        let about_normal = |c: usize| plane.is_none_or(|p| p.keeps_rotation(c));
        // Sliding clamps free single components of a clamped node.
        let mut slide_u = vec![[false; 3]; model.supports.len()];
        let mut slide_th = vec![[false; 3]; model.supports.len()];
        for sl in &model.slides {
            match sl.coordinate_axis() {
                Some(k) => {
                    slide_u[sl.node][k] = true;
                    slide_th[sl.node][k] = sl.spin;
                }
                // An oblique axis keeps every component; the assembled rows carry the
                // constraint (`simulation::slide`).
                None => {
                    slide_u[sl.node] = [true; 3];
                    slide_th[sl.node] = [sl.spin; 3];
                }
            }
        }
        // A driven support's translation is prescribed, but its velocity is not: with
        // translational dissipation the velocity update `u/Δt = ½(v_n + v_n+1) + g`
        // needs its `g` (removing it would impose the conserving update at that node and
        // break the dissipation identity).
        let mut driven = vec![false; model.supports.len()];
        for d in &model.drives {
            driven[d.node] = true;
        }
        let nodes: Vec<NodeDofs> = model
            .supports
            .iter()
            .enumerate()
            .map(|(a, s)| {
                let free_u = |c: usize| (!s.translation || slide_u[a][c]) && in_plane(c);
                NodeDofs {
                    u: std::array::from_fn(|c| take(free_u(c))),
                    th: std::array::from_fn(|c| {
                        take((!s.rotation || slide_th[a][c]) && about_normal(c))
                    }),
                    g: std::array::from_fn(|c| {
                        take(with_g && (free_u(c) || (driven[a] && in_plane(c))))
                    }),
                }
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
                        m[u_idx(l) + c] = nd.u[c];
                        m[th_idx(l) + c] = nd.th[c];
                        m[g_idx(l) + c] = nd.g[c];
                    }
                }
                m
            })
            .collect();
        Self { nodes, elements, n }
    }

    /// Unknowns per node, in numbering order (the node blocks of the block-tridiagonal
    /// solver: a node's unknowns are numbered consecutively).
    pub fn node_block_sizes(&self) -> Vec<usize> {
        self.nodes
            .iter()
            .map(|nd| {
                [nd.u, nd.th, nd.g]
                    .iter()
                    .flatten()
                    .filter(|&&i| i != NONE)
                    .count()
            })
            .collect()
    }

    /// Sparsity pattern: every pair of unknowns of a common element.
    pub fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = Vec::with_capacity(self.elements.len() * NDOF * NDOF);
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
