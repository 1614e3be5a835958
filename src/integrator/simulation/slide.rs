//! Sliding clamps along an oblique axis (part of stage 4, [`super::assemble`]). A clamp
//! sliding along a coordinate axis simply removes the other two components from the
//! unknowns ([`crate::integrator::dofs`]). Along any other unit axis `a` the node keeps all
//! its components, and once the system is assembled each of its constrained blocks
//! (`u`; `g` with translational dissipation; `θ` when it spins) has its rows replaced:
//!
//! * the first by `a · R` (and `a · K`): the balance along the axis, which the support
//!   does not touch;
//! * the others by the constraints `b_k · x = 0` for an orthonormal basis `b_k` of the
//!   directions across `a` (times a stiffness `k`, so the row is a force like its
//!   neighbours).
//!
//! The constraints are linear, so Newton meets them exactly, and the support's reaction
//! (the dropped rows) is normal to the motion: it does no work and EM keeps its energy to
//! round-off.

use super::Simulation;
use crate::integrator::dofs::{DofMap, NONE};
use crate::linsolve::SparseSolver;
use crate::model::Model;

/// One constrained block (3 rows) of an oblique sliding clamp.
#[derive(Clone, Debug)]
pub(super) struct SlideBlock {
    /// The block's global rows, in component order (NONE where a planar model removed it).
    rows: Vec<usize>,
    /// Per row: `a` and the cross directions `b_k`, restricted to the numbered components.
    /// Row 0 takes `a`, the others the constraints.
    dirs: Vec<Vec<f64>>,
    /// Columns of these rows in the sparsity pattern (every row of a node block has the
    /// same columns) and, per row, the solver slot of each column.
    cols: Vec<usize>,
    slots: Vec<Vec<usize>>,
    /// Scale of the constraint rows: the largest diagonal entry of the block's own rows
    /// in the first assembled tangent (an element stiffness before it), so they
    /// weigh like their neighbours in the residual norm and the LU.
    stiffness: f64,
    /// Whether `stiffness` was taken from an assembled tangent (it then stays: the
    /// constraint rows are one fixed linear function of the increments for the run).
    measured: bool,
}

impl SlideBlock {
    /// The blocks of every oblique sliding clamp of `model`.
    pub(super) fn build(model: &Model, dofs: &DofMap, solver: &SparseSolver) -> Vec<Self> {
        // The element pattern, only where an oblique slide needs its columns (a member's
        // whole pattern is ~10⁴ entries: building it for nothing was a tenth of setup).
        let mut pattern: Option<Vec<(usize, usize)>> = None;
        let mut out = Vec::new();
        for sl in model
            .slides
            .iter()
            .filter(|s| s.coordinate_axis().is_none())
        {
            let nd = &dofs.nodes[sl.node];
            // Stiffest element at the node (translational, rotational): the constraint
            // rows' scale until a tangent gives the rows' own diagonal.
            let (kt, kr) = model
                .elements
                .iter()
                .filter(|e| e.nodes.contains(&sl.node))
                .map(|e| {
                    let p = &e.props;
                    (p.c_gamma.max() / p.h, p.c_omega.amax() / p.h)
                })
                .fold((0.0f64, 0.0f64), |(a, b), (x, y)| (a.max(x), b.max(y)));
            let mut blocks = vec![(nd.u, kt), (nd.g, kt)];
            if sl.spin {
                blocks.push((nd.th, kr));
            }
            for (idx, stiffness) in blocks {
                let comps: Vec<usize> = (0..3).filter(|&c| idx[c] != NONE).collect();
                if comps.len() < 2 {
                    // Not numbered (no g), or a single component (nothing to constrain).
                    continue;
                }
                let rows: Vec<usize> = comps.iter().map(|&c| idx[c]).collect();
                let a: Vec<f64> = comps.iter().map(|&c| sl.axis[c]).collect();
                let dirs = complement(&a);
                let mut cols: Vec<usize> = pattern
                    .get_or_insert_with(|| dofs.pattern())
                    .iter()
                    .filter(|(i, _)| *i == rows[0])
                    .map(|&(_, j)| j)
                    .collect();
                cols.push(rows[0]);
                cols.sort_unstable();
                cols.dedup();
                let slots = rows
                    .iter()
                    .map(|&i| cols.iter().map(|&j| solver.slot(i, j)).collect())
                    .collect();
                out.push(Self {
                    rows,
                    dirs,
                    cols,
                    slots,
                    stiffness,
                    measured: false,
                });
            }
        }
        out
    }
}

/// `a` (unit, in the span of the numbered components) followed by an orthonormal basis
/// of the directions across it, by Gram–Schmidt on the coordinate directions.
fn complement(a: &[f64]) -> Vec<Vec<f64>> {
    let m = a.len();
    let n = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let a: Vec<f64> = a.iter().map(|x| x / n).collect();
    let mut basis = vec![a];
    for c in 0..m {
        if basis.len() == m {
            break;
        }
        let mut v: Vec<f64> = (0..m).map(|k| if k == c { 1.0 } else { 0.0 }).collect();
        for b in &basis {
            let d: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
            v.iter_mut().zip(b).for_each(|(x, y)| *x -= d * y);
        }
        let nv = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if nv > 0.5 {
            basis.push(v.iter().map(|x| x / nv).collect());
        }
    }
    basis
}

impl Simulation {
    /// Replaces the rows of the oblique sliding clamps' blocks in the assembled residual
    /// `r` (increment `q`) and, with `tangent`, in the matrix values (module docs).
    pub(super) fn constrain_slides(&mut self, q: &[f64], tangent: bool, r: &mut [f64]) {
        if self.slide_blocks.is_empty() {
            return;
        }
        let mut vals = tangent.then(|| self.solver.values_mut());
        for b in &mut self.slide_blocks {
            let m = b.rows.len();
            if let Some(vals) = vals.as_deref_mut() {
                let diag = (0..m)
                    .map(|c| {
                        let jj = b
                            .cols
                            .binary_search(&b.rows[c])
                            .expect("diagonal in pattern");
                        vals[b.slots[c][jj]].abs()
                    })
                    .fold(0.0f64, f64::max);
                if !b.measured && diag > 0.0 && diag.is_finite() {
                    b.stiffness = diag;
                    b.measured = true;
                }
                for (jj, &j) in b.cols.iter().enumerate() {
                    let old: Vec<f64> = (0..m).map(|c| vals[b.slots[c][jj]]).collect();
                    for (k, d) in b.dirs.iter().enumerate() {
                        vals[b.slots[k][jj]] = if k == 0 {
                            d.iter().zip(&old).map(|(u, v)| u * v).sum()
                        } else {
                            // The constraint's gradient: b_k on the block's own columns.
                            b.rows
                                .iter()
                                .position(|&i| i == j)
                                .map_or(0.0, |c| b.stiffness * d[c])
                        };
                    }
                }
            }
            let x: Vec<f64> = b.rows.iter().map(|&i| q[i]).collect();
            let old: Vec<f64> = b.rows.iter().map(|&i| r[i]).collect();
            for (k, d) in b.dirs.iter().enumerate() {
                r[b.rows[k]] = if k == 0 {
                    d.iter().zip(&old).map(|(u, v)| u * v).sum()
                } else {
                    b.stiffness * d.iter().zip(&x).map(|(u, v)| u * v).sum::<f64>()
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::complement;

    #[test]
    fn complement_is_orthonormal() {
        for a in [vec![1.0, 1.0, 0.0], vec![0.3, -0.2, 0.9], vec![0.6, 0.8]] {
            let b = complement(&a);
            assert_eq!(b.len(), a.len());
            for i in 0..b.len() {
                for j in 0..b.len() {
                    let d: f64 = b[i].iter().zip(&b[j]).map(|(x, y)| x * y).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((d - want).abs() < 1e-14, "{i} {j} {d}");
                }
            }
        }
    }
}
