//! CPU twin of `shaders/blocktri.wgsl`: block-tridiagonal LU and solve of one member of a
//! batch, on the flat buffers the device uses (the same operations in the same order, so
//! that the device solver is pinned to it by `tests/gpu_blocktri.rs`).
//!
//! A member is a rod numbered node by node with 9 node-local unknowns per node
//! (u0..2 θ0..2 g0..2). Its system lies where the GPU assembly pass writes it
//! ([`crate::gpu::layout::AsmLayout`]): node `j`'s residual at `m·RPM + 9 j`, its diagonal
//! block (row-major 9×9) at `K + m·KPM + 81 j`, element `e`'s off-diagonal blocks
//! `U_e = A(e, e+1)` and `L_e = A(e+1, e)` at `K + m·KPM + 81 NPN + 81 (2 e + h)`.
//! Rows and columns whose bit in the node's mask is clear read as identity rows and columns
//! with a zero right-hand side (fixed degrees of freedom; their solution is 0), as the
//! padded blocks of `block_tridiagonal.rs`.
//!
//! Block Thomas with partial pivoting inside the 9×9 diagonal blocks (the first entry of
//! largest magnitude, whole rows swapped):
//!
//! ```text
//! S_0 = D_0,   W_i = S_i⁻¹ U_i,   S_{i+1} = D_{i+1} − L_i W_i
//! forward:  S_i y_i = b_i − L_{i−1} y_{i−1}
//! backward: x_i = y_i − W_i x_{i+1}
//! ```
//!
//! About 3 400 flops per node to factorize, 500 to solve (plus 500 for the backward error).

/// Status of a member: factorized / solved.
pub const OK: u32 = 0;
/// Status bit of a solve whose solution (or backward error) is not finite.
pub const NONFINITE: u32 = 0x8000_0000;

/// Where a member's system and factors lie in the flat buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchLayout {
    /// Node slots per member (NPN).
    pub npn: usize,
    /// Start of the tangent region of the system buffer (K).
    pub k_start: usize,
    /// Scalars per member of the tangent region (KPM ≥ 81 (NPN + 2 (NPN − 1))).
    pub kpm: usize,
    /// Scalars per member of the residual region (RPM ≥ 9 NPN).
    pub rpm: usize,
    /// The right-hand side is minus the stored residual.
    pub negate: bool,
}

impl BatchLayout {
    /// Scalars of the factor buffer per member (`S_i`, `W_i`, `L_i`).
    pub fn fac_per_member(&self) -> usize {
        243 * self.npn
    }
    /// Entries of the pivot and solution buffers per member.
    pub fn x_per_member(&self) -> usize {
        9 * self.npn
    }
}

/// Entry `(r, c)` of a block with row mask `mr` and column mask `mc` as the masked
/// system sees it (`diag`: a diagonal block, identity where masked).
#[inline]
fn masked(v: f64, mr: u32, mc: u32, r: usize, c: usize, diag: bool) -> f64 {
    if (mr >> r) & 1 != 0 && (mc >> c) & 1 != 0 {
        v
    } else if diag && r == c {
        1.0
    } else {
        0.0
    }
}

/// Applies `S⁻¹` (pivots `p`, factors `s`: unit lower and upper, row-major) in place to the
/// 9-vector `v[at + st·k]`.
fn lu_apply(s: &[f64], p: &[u32], v: &mut [f64], at: usize, st: usize) {
    for k in 0..9 {
        let q = p[k] as usize;
        if q != k {
            v.swap(at + st * k, at + st * q);
        }
    }
    for r in 1..9 {
        let mut acc = v[at + st * r];
        for c in 0..r {
            acc -= s[9 * r + c] * v[at + st * c];
        }
        v[at + st * r] = acc;
    }
    for r in (0..9).rev() {
        let mut acc = v[at + st * r];
        for c in r + 1..9 {
            acc -= s[9 * r + c] * v[at + st * c];
        }
        v[at + st * r] = acc / s[9 * r + r];
    }
}

/// Factorizes member `m` (`n` nodes) of the system `sys` into its slices of `fac` and
/// `piv` (whole buffers, laid out by `l`); `mask` holds one mask per node slot. Returns
/// [`OK`] or `1 + i` for a zero or non-finite pivot in the Schur complement of node block
/// `i`.
pub fn factor(
    l: &BatchLayout,
    sys: &[f64],
    mask: &[u32],
    m: usize,
    n: usize,
    fac: &mut [f64],
    piv: &mut [u32],
) -> u32 {
    let npn = l.npn;
    let f = &mut fac[m * l.fac_per_member()..(m + 1) * l.fac_per_member()];
    let piv = &mut piv[m * l.x_per_member()..(m + 1) * l.x_per_member()];
    let a = l.k_start + m * l.kpm;
    let masks = &mask[m * npn..(m + 1) * npn];
    for i in 0..n {
        let mi = masks[i];
        for r in 0..9 {
            for c in 0..9 {
                f[81 * i + 9 * r + c] = masked(sys[a + 81 * i + 9 * r + c], mi, mi, r, c, true);
            }
        }
        if i + 1 < n {
            let mj = masks[i + 1];
            let off = a + 81 * npn + 162 * i;
            for r in 0..9 {
                for c in 0..9 {
                    f[81 * (npn + i) + 9 * r + c] =
                        masked(sys[off + 9 * r + c], mi, mj, r, c, false);
                    f[81 * (2 * npn + i) + 9 * r + c] =
                        masked(sys[off + 81 + 9 * r + c], mj, mi, r, c, false);
                }
            }
        }
    }
    for i in 0..n {
        let p = &mut piv[9 * i..9 * i + 9];
        {
            let s = &mut f[81 * i..81 * i + 81];
            for k in 0..9 {
                let mut q = k;
                let mut best = s[9 * k + k].abs();
                for r in k + 1..9 {
                    let v = s[9 * r + k].abs();
                    if v > best {
                        best = v;
                        q = r;
                    }
                }
                p[k] = q as u32;
                if !(best > 0.0 && best.is_finite()) {
                    return 1 + i as u32;
                }
                if q != k {
                    for c in 0..9 {
                        s.swap(9 * k + c, 9 * q + c);
                    }
                }
                let d = s[9 * k + k];
                for r in k + 1..9 {
                    let lv = s[9 * r + k] / d;
                    s[9 * r + k] = lv;
                    for c in k + 1..9 {
                        s[9 * r + c] -= lv * s[9 * k + c];
                    }
                }
            }
        }
        if i + 1 < n {
            let (head, tail) = f.split_at_mut(81 * npn);
            let s: &[f64] = &head[81 * i..81 * i + 81];
            let w0 = 81 * i;
            for c in 0..9 {
                lu_apply(s, p, tail, w0 + c, 9);
            }
            let mut upd = [0.0; 81];
            for r in 0..9 {
                for c in 0..9 {
                    let mut acc = 0.0;
                    for k in 0..9 {
                        acc += tail[81 * (npn + i) + 9 * r + k] * tail[w0 + 9 * k + c];
                    }
                    upd[9 * r + c] = acc;
                }
            }
            for (d, u) in head[81 * (i + 1)..81 * (i + 2)].iter_mut().zip(&upd) {
                *d -= u;
            }
        }
    }
    OK
}

/// The masked right-hand side entry `r` of node `i` of member `m`: ± (stored residual +
/// extra).
#[inline]
fn rhs(io: &SolveIo, m: usize, i: usize, r: usize) -> f64 {
    let (l, sys, mask) = (io.l, io.sys, io.mask);
    if (mask[m * l.npn + i] >> r) & 1 == 0 {
        return 0.0;
    }
    let v = sys[m * l.rpm + 9 * i + r] + io.extra.map_or(0.0, |e| e[9 * (m * l.npn + i) + r]);
    if l.negate {
        -v
    } else {
        v
    }
}

/// The read-only inputs of a solve.
#[derive(Clone, Copy, Debug)]
pub struct SolveIo<'a> {
    /// The layout.
    pub l: &'a BatchLayout,
    /// The system buffer.
    pub sys: &'a [f64],
    /// One mask per node slot.
    pub mask: &'a [u32],
    /// Per node slot 9 values added to the stored residual (`None`: zeros).
    pub extra: Option<&'a [f64]>,
    /// The factor buffer.
    pub fac: &'a [f64],
    /// The pivot buffer.
    pub piv: &'a [u32],
}

/// Solves member `m` (`n` nodes) with its factors into its slice of `xs`. Returns the
/// status ([`OK`] or [`NONFINITE`]) and the normwise backward error
/// `‖b − A x‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞)` of the masked system.
pub fn solve(io: &SolveIo, m: usize, n: usize, xs: &mut [f64]) -> (u32, f64) {
    let (l, sys, mask, fac, piv) = (io.l, io.sys, io.mask, io.fac, io.piv);
    let npn = l.npn;
    let f = &fac[m * l.fac_per_member()..(m + 1) * l.fac_per_member()];
    let piv = &piv[m * l.x_per_member()..(m + 1) * l.x_per_member()];
    let x = &mut xs[m * l.x_per_member()..(m + 1) * l.x_per_member()];
    let a = l.k_start + m * l.kpm;
    for i in 0..n {
        for r in 0..9 {
            let mut acc = rhs(io, m, i, r);
            if i > 0 {
                let lb = 81 * (2 * npn + i - 1);
                for c in 0..9 {
                    acc -= f[lb + 9 * r + c] * x[9 * (i - 1) + c];
                }
            }
            x[9 * i + r] = acc;
        }
        lu_apply(&f[81 * i..81 * i + 81], &piv[9 * i..9 * i + 9], x, 9 * i, 1);
    }
    for i in (0..n.saturating_sub(1)).rev() {
        let w = 81 * (npn + i);
        for r in 0..9 {
            let mut acc = x[9 * i + r];
            for c in 0..9 {
                acc -= f[w + 9 * r + c] * x[9 * (i + 1) + c];
            }
            x[9 * i + r] = acc;
        }
    }
    let (mut res, mut anorm, mut xnorm, mut bnorm) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut finite = true;
    for i in 0..n {
        let mi = mask[m * npn + i];
        for r in 0..9 {
            let b = rhs(io, m, i, r);
            let mut acc = b;
            let mut rs = 0.0;
            for c in 0..9 {
                let v = masked(sys[a + 81 * i + 9 * r + c], mi, mi, r, c, true);
                acc -= v * x[9 * i + c];
                rs += v.abs();
            }
            if i + 1 < n {
                let mj = mask[m * npn + i + 1];
                let off = a + 81 * npn + 162 * i;
                for c in 0..9 {
                    let v = masked(sys[off + 9 * r + c], mi, mj, r, c, false);
                    acc -= v * x[9 * (i + 1) + c];
                    rs += v.abs();
                }
            }
            if i > 0 {
                let lb = 81 * (2 * npn + i - 1);
                for c in 0..9 {
                    let v = f[lb + 9 * r + c];
                    acc -= v * x[9 * (i - 1) + c];
                    rs += v.abs();
                }
            }
            let xv = x[9 * i + r];
            finite &= xv.is_finite();
            res = res.max(acc.abs());
            anorm = anorm.max(rs);
            xnorm = xnorm.max(xv.abs());
            bnorm = bnorm.max(b.abs());
        }
    }
    let den = anorm * xnorm + bnorm;
    let e = if den > 0.0 { res / den } else { 0.0 };
    if !finite || !e.is_finite() {
        return (NONFINITE, e);
    }
    (OK, e)
}
