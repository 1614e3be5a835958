//! Block-tridiagonal LU (the block Thomas algorithm) for one rod's Newton tangent.
//!
//! Numbered node by node, a rod's tangent couples each node only with its two neighbours:
//! with `D_i` the diagonal blocks, `U_i = A(i, i+1)` and `L_i = A(i+1, i)`,
//!
//! ```text
//! S_0 = D_0,   W_i = S_i⁻¹ U_i,   S_{i+1} = D_{i+1} − L_i W_i
//! forward:  S_i y_i = b_i − L_{i−1} y_{i−1}
//! backward: x_i = y_i − W_i x_{i+1}
//! ```
//!
//! About `4.7 B³` flops per node (B ≤ 9), against the band LU's `2·n·kl·(kl+ku)` with
//! `kl = 2B−1` that ignores the block structure, and without the index chasing of a
//! general sparse LU. Pivoting happens only inside the diagonal blocks (a fixed-size LU
//! with partial pivoting, [`BlockFactors`], whose triangular solves run on all `B` columns
//! of `U_i` at once; 3 × 3 blocks — planar rods without translational dissipation — are
//! inverted in closed form instead, 1.6× cheaper on the planar cantilever), so the
//! factorization is not backward stable for every matrix: [`super::SparseSolver`] checks
//! the backward error of each solve and falls back to faer's pivoted sparse LU when it is
//! too large.
//!
//! Blocks are stored padded to a fixed size `B` ∈ {3, 6, 9} (the largest node block rounded
//! up): padded rows and columns hold an identity diagonal and are decoupled from the rest,
//! so they change neither the solution nor the pivots of the real unknowns.

use nalgebra::{Const, DimMin, SMatrix, SVector};

/// A factorization of a block-tridiagonal matrix given in compressed sparse column form.
pub(super) trait BlockLu: Send + Sync {
    /// Copies the CSC values into the blocks and factorizes; an error names the block
    /// whose Schur complement is singular.
    fn factor(&mut self, vals: &[f64]) -> Result<(), String>;
    /// Solves `A x = b` in place with the last factorization.
    fn solve(&self, rhs: &mut [f64]);
    /// `r = b − A x` with the matrix of the last factorization, block by block (the
    /// backward-error check of a solve: dense node blocks instead of the compressed
    /// columns' index chasing).
    fn residual(&self, b: &[f64], x: &[f64], r: &mut [f64]);
    /// Padded block size.
    fn block_size(&self) -> usize;
}

/// Builds the block factorization of the CSC pattern (`col_ptr`, `row_idx`) of an `n × n`
/// matrix partitioned into consecutive blocks of `sizes` (empty blocks allowed), or `None`
/// when some entry couples two blocks that are not neighbours (after dropping the empty
/// ones), a block is larger than 9, or there are fewer than two blocks.
pub(super) fn analyse(
    n: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
    sizes: &[usize],
) -> Option<Box<dyn BlockLu>> {
    let sizes: Vec<usize> = sizes.iter().copied().filter(|&s| s > 0).collect();
    let largest = sizes.iter().copied().max()?;
    if sizes.len() < 2 || sizes.iter().sum::<usize>() != n || largest > 9 {
        return None;
    }
    match largest {
        0..=3 => BlockTri::<3>::new(col_ptr, row_idx, &sizes).map(|b| Box::new(b) as _),
        4..=6 => BlockTri::<6>::new(col_ptr, row_idx, &sizes).map(|b| Box::new(b) as _),
        _ => BlockTri::<9>::new(col_ptr, row_idx, &sizes).map(|b| Box::new(b) as _),
    }
}

type Block<const B: usize> = SMatrix<f64, B, B>;

/// Block Thomas factorization with blocks padded to `B × B`.
struct BlockTri<const B: usize>
where
    Const<B>: DimMin<Const<B>, Output = Const<B>>,
{
    /// Global index of the first unknown of each block.
    starts: Vec<usize>,
    /// Unknowns per block (≤ B).
    sizes: Vec<usize>,
    /// Per CSC entry: index into `blocks` (`which · B² + column-major position`).
    dest: Vec<usize>,
    /// `D_0 … D_{m−1}` (overwritten by the Schur complements `S_i`), then
    /// `U_0 … U_{m−2}`, then `L_0 … L_{m−2}`.
    blocks: Vec<Block<B>>,
    /// `W_i = S_i⁻¹ U_i`.
    w: Vec<Block<B>>,
    /// LU factors of the `S_i` (blocks larger than 3 × 3).
    lu: Vec<BlockFactors<B>>,
    /// Inverses of the `S_i` (3 × 3 blocks: closed form, cheaper than LU and its solves).
    inv: Vec<Block<B>>,
    /// The diagonal blocks `D_i` as loaded (the factorization overwrites them).
    diag: Vec<Block<B>>,
}

impl<const B: usize> BlockTri<B>
where
    Const<B>: DimMin<Const<B>, Output = Const<B>>,
{
    fn new(col_ptr: &[usize], row_idx: &[usize], sizes: &[usize]) -> Option<Self> {
        let m = sizes.len();
        let mut starts = Vec::with_capacity(m);
        let mut block_of = Vec::new();
        for (k, &s) in sizes.iter().enumerate() {
            starts.push(block_of.len());
            block_of.extend(std::iter::repeat_n(k, s));
        }
        let mut dest = Vec::with_capacity(row_idx.len());
        for (c, w) in col_ptr.windows(2).enumerate() {
            let bc = block_of[c];
            for &r in &row_idx[w[0]..w[1]] {
                let br = block_of[r];
                let which = if br == bc {
                    br
                } else if bc == br + 1 {
                    m + br
                } else if br == bc + 1 {
                    2 * m - 1 + bc
                } else {
                    return None;
                };
                dest.push(which * B * B + (c - starts[bc]) * B + (r - starts[br]));
            }
        }
        Some(Self {
            starts,
            sizes: sizes.to_vec(),
            dest,
            blocks: vec![Block::<B>::zeros(); 3 * m - 2],
            w: vec![Block::<B>::zeros(); m - 1],
            lu: Vec::with_capacity(m),
            inv: Vec::with_capacity(m),
            diag: Vec::with_capacity(m),
        })
    }

    fn m(&self) -> usize {
        self.sizes.len()
    }

    fn load(&mut self, vals: &[f64]) {
        let m = self.m();
        for (i, d) in self.blocks[..m].iter_mut().enumerate() {
            *d = Block::<B>::zeros();
            for k in self.sizes[i]..B {
                d[(k, k)] = 1.0;
            }
        }
        self.blocks[m..]
            .iter_mut()
            .for_each(|b| *b = Block::<B>::zeros());
        // The blocks are contiguous column-major `B × B` arrays, so `dest` indexes them
        // as one flat slice (no division per entry).
        let flat: &mut [f64] = bytemuck::cast_slice_mut(&mut self.blocks);
        for (&p, &v) in self.dest.iter().zip(vals) {
            flat[p] = v;
        }
    }

    fn rhs_block(&self, rhs: &[f64], i: usize) -> SVector<f64, B> {
        let mut b = SVector::<f64, B>::zeros();
        let (s, k) = (self.starts[i], self.sizes[i]);
        b.as_mut_slice()[..k].copy_from_slice(&rhs[s..s + k]);
        b
    }
}

impl<const B: usize> BlockLu for BlockTri<B>
where
    Const<B>: DimMin<Const<B>, Output = Const<B>>,
{
    fn factor(&mut self, vals: &[f64]) -> Result<(), String> {
        self.load(vals);
        let m = self.m();
        self.diag.clear();
        self.diag.extend_from_slice(&self.blocks[..m]);
        self.lu.clear();
        self.inv.clear();
        for i in 0..m {
            let singular = || format!("singular Schur complement of node block {i}");
            if B <= 3 {
                // Closed-form inverse (cofactors); its accuracy is checked with every
                // solve's backward error like the LU's.
                let inv = self.blocks[i].try_inverse().ok_or_else(singular)?;
                if i + 1 < m {
                    let w = inv * self.blocks[m + i];
                    let update = self.blocks[2 * m - 1 + i] * w;
                    self.blocks[i + 1] -= update;
                    self.w[i] = w;
                }
                self.inv.push(inv);
                continue;
            }
            let lu = BlockFactors::new(self.blocks[i]).ok_or_else(singular)?;
            if i + 1 < m {
                let mut w = self.blocks[m + i];
                lu.solve_columns(&mut w);
                let update = self.blocks[2 * m - 1 + i] * w;
                self.blocks[i + 1] -= update;
                self.w[i] = w;
            }
            self.lu.push(lu);
        }
        Ok(())
    }

    fn solve(&self, rhs: &mut [f64]) {
        let m = self.m();
        let mut y: Vec<SVector<f64, B>> = Vec::with_capacity(m);
        for i in 0..m {
            let mut b = self.rhs_block(rhs, i);
            if i > 0 {
                b -= self.blocks[2 * m - 1 + (i - 1)] * y[i - 1];
            }
            if B <= 3 {
                b = self.inv[i] * b;
            } else {
                self.lu[i].solve_columns(&mut b);
            }
            y.push(b);
        }
        for i in (0..m - 1).rev() {
            let next = y[i + 1];
            y[i] -= self.w[i] * next;
        }
        for (i, yi) in y.iter().enumerate() {
            let (s, k) = (self.starts[i], self.sizes[i]);
            rhs[s..s + k].copy_from_slice(&yi.as_slice()[..k]);
        }
    }

    fn residual(&self, b: &[f64], x: &[f64], r: &mut [f64]) {
        let m = self.m();
        let xb: Vec<SVector<f64, B>> = (0..m).map(|i| self.rhs_block(x, i)).collect();
        for i in 0..m {
            let mut ax = self.diag[i] * xb[i];
            if i + 1 < m {
                ax += self.blocks[m + i] * xb[i + 1];
            }
            if i > 0 {
                ax += self.blocks[2 * m - 1 + (i - 1)] * xb[i - 1];
            }
            let (s, k) = (self.starts[i], self.sizes[i]);
            for c in 0..k {
                r[s + c] = b[s + c] - ax[c];
            }
        }
    }

    fn block_size(&self) -> usize {
        B
    }
}

/// The LU factorization with partial (row) pivoting of one `B × B` block, `P S = L U`: `L`
/// (unit diagonal) below the diagonal of `lu`, `U` on and above it, the reciprocals of
/// `U`'s diagonal in `inv_diag`, and the row swapped with row `k` at step `k` in `pivots`.
/// Written for the block sizes the rods have (6, 9): fixed-size loops over contiguous
/// columns, which the compiler unrolls and vectorizes, where nalgebra's `LU` solves one
/// right-hand side at a time through its generic triangular solvers.
#[derive(Clone, Debug)]
struct BlockFactors<const B: usize> {
    lu: Block<B>,
    inv_diag: [f64; B],
    pivots: [usize; B],
}

impl<const B: usize> BlockFactors<B> {
    /// Factorizes `a`; `None` when a pivot is zero (the block is singular).
    #[inline]
    fn new(mut a: Block<B>) -> Option<Self> {
        let mut pivots = [0; B];
        let mut inv_diag = [0.0; B];
        let s = a.as_mut_slice();
        for k in 0..B {
            // The largest |entry| of column k on or below the diagonal (the first one on
            // ties; NaN is never larger).
            let mut p = k;
            let mut big = s[k * B + k].abs();
            for i in k + 1..B {
                let v = s[k * B + i].abs();
                if v > big {
                    (p, big) = (i, v);
                }
            }
            pivots[k] = p;
            if p != k {
                for j in 0..B {
                    s.swap(j * B + k, j * B + p);
                }
            }
            let pivot = s[k * B + k];
            if pivot == 0.0 {
                return None;
            }
            let inv = 1.0 / pivot;
            inv_diag[k] = inv;
            for i in k + 1..B {
                s[k * B + i] *= inv;
            }
            // Column-wise update of the trailing block (contiguous columns).
            let (left, right) = s.split_at_mut((k + 1) * B);
            let lcol = &left[k * B..(k + 1) * B];
            for col in right.chunks_exact_mut(B) {
                let ukj = col[k];
                for i in k + 1..B {
                    col[i] -= lcol[i] * ukj;
                }
            }
        }
        Some(Self {
            lu: a,
            inv_diag,
            pivots,
        })
    }

    /// Solves `S X = R` in place for the `C` columns of `r`.
    #[inline]
    fn solve_columns<const C: usize>(&self, r: &mut SMatrix<f64, B, C>) {
        let f = self.lu.as_slice();
        for col in r.as_mut_slice().chunks_exact_mut(B) {
            for k in 0..B {
                col.swap(k, self.pivots[k]);
            }
            // L y = P r (unit lower triangle), by columns of L.
            for k in 0..B {
                let yk = col[k];
                let lcol = &f[k * B..(k + 1) * B];
                for i in k + 1..B {
                    col[i] -= lcol[i] * yk;
                }
            }
            // U x = y, by columns of U.
            for k in (0..B).rev() {
                let xk = col[k] * self.inv_diag[k];
                col[k] = xk;
                let ucol = &f[k * B..(k + 1) * B];
                for i in 0..k {
                    col[i] -= ucol[i] * xk;
                }
            }
        }
    }
}
