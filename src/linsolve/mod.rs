//! Sparse linear solves for the Newton method.
//!
//! [`SparseSolver`] holds a square, real, unsymmetric matrix with a *fixed* sparsity pattern
//! (the Newton tangent) and analyses that pattern once at construction. Each new set of
//! values is factorized by [`SparseSolver::factor`]; [`SparseSolver::solve`] then solves
//! with that factorization as often as needed (modified Newton reuses it across
//! iterations); [`SparseSolver::factor_solve`] does both.
//!
//! # Backends (chosen once, from the pattern)
//!
//! * `n <= DENSE_MAX_DIM` ([`DENSE_MAX_DIM`] = 64): the values are scattered into a reused
//!   dense column-major buffer and factorized with faer's dense LU with partial pivoting
//!   (`faer::linalg::lu::partial_pivoting::factor::lu_in_place`). For tiny systems this beats
//!   any sparse code (no index chasing, no symbolic overhead).
//! * a pattern that couples only neighbouring node blocks ([`SparseSolver::with_blocks`]; a
//!   rod, or a chain of rods, numbered node by node): the block-tridiagonal LU of
//!   `block_tridiagonal.rs` (block Thomas, pivoting inside the node blocks), its every solve
//!   checked by the backward error and redone with faer's pivoted sparse LU when the check
//!   fails. One 30-element rod with 9 unknowns per node (270 unknowns, `cargo bench --bench
//!   gpu -- rod_solve`): factorization + solve 34.7 µs against 84.6 µs for the supernodal LU
//!   below; a solve alone (modified Newton) a few µs.
//! * otherwise: faer's sparse LU with partial pivoting, symbolic analysis (COLAMD column
//!   ordering, elimination tree, supernode partition) computed once in `new` with
//!   `faer::sparse::linalg::lu::factorize_symbolic_lu`, forced to the **supernodal** variant;
//!   the numeric factorization `SymbolicLu::factorize_numeric_lu` reuses the
//!   `NumericLu` storage and one `MemBuffer` scratch across calls.
//!
//! Measured on the project's 2-core machine (`--release`, best of 3×(200…5000) calls while
//! other builds were running, 6×6 block-tridiagonal patterns, random unsymmetric values with
//! and without a dominant diagonal; factorization + solve only):
//!
//! | n      | dense LU      | simplicial (COLAMD / AMD) | supernodal   |
//! |--------|---------------|---------------------------|--------------|
//! | 48     | 6.5–7.4 µs    | 14–23 / 9.5–17 µs          | 9.5–12 µs    |
//! | 72     | 14–16 µs      | 20–36 / 14–26 µs           | 14–17 µs     |
//! | 96     | 24–27 µs      | 27–47 / 19–37 µs           | 19–24 µs     |
//! | 306    | 330–370 µs    | 78–148 / 63–124 µs         | 60–85 µs     |
//! | 6000   | —             | 1.6–2.9 / 1.3–2.6 ms       | 1.2–1.7 ms   |
//! | 60000  | —             | 16–31 / 20–34 ms           | 21–31 ms     |
//!
//! The lower figure of each range is the diagonally dominant case (pivots stay on the
//! diagonal), the upper one the non-dominant case (row interchanges create fill). The
//! simplicial variant (which faer's automatic heuristic selects for these patterns) suffers
//! most from pivoting fill, so the supernodal variant is forced. Dense and supernodal cross
//! over around n ≈ 72; 64 is used as the threshold.
//!
//! With the checks below, `factor_solve` as shipped measured 64–66 µs (dominant) and 90 µs
//! (non-dominant) at n = 306, 1.34 ms and 1.9 ms at n = 6000; the checks cost ≈ 6 %
//! (4 µs at n = 306, 77 µs at n = 6000).
//!
//! # Failure detection
//!
//! `factor` and `solve` never return NaNs: they reject (with [`LinsolveError::Singular`])
//! non-finite matrix or right-hand-side entries, a structurally singular pivot sequence
//! reported by faer, a numerically zero pivot (dense backend), a non-finite solution, and a solve
//! whose normwise backward error exceeds [`MAX_BACKWARD_ERROR`]. On error the right-hand
//! side is left unchanged. (No condition-number test: the Newton unknowns mix units —
//! displacements, rotations, velocity corrections — so `‖A‖‖x‖/‖b‖` is large for healthy
//! tangents; a singular tangent shows up as a zero pivot, a non-finite solution or a
//! large backward error.)

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::lu::partial_pivoting::{factor as dense_factor, solve as dense_solve};
use faer::sparse::linalg::lu::{
    factorize_symbolic_lu, LuRef, LuSymbolicParams, NumericLu, SymbolicLu,
};
use faer::sparse::linalg::{LuError, SupernodalThreshold};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, Mat, MatMut, Par};

pub mod batched;
mod block_tridiagonal;
use block_tridiagonal::BlockLu;

/// Largest dimension factorized with the dense LU backend (see the module documentation for
/// the measurements behind it).
pub const DENSE_MAX_DIM: usize = 64;

/// Largest accepted normwise backward error `‖b − A x‖₁ / (‖A‖₁‖x‖₁ + ‖b‖₁)`.
///
/// (1-norms because the column sums of a compressed-column matrix are contiguous; any
/// operator norm gives a valid backward error and condition bound.)
///
/// LU with partial pivoting is backward stable: the error is `O(w·ε·ρ)` with `w` the
/// number of entries per row of the factors and `ρ` the pivot growth, i.e. ≈ 1e-15 here. A
/// value of 1e-10 (≈ 5e5 ε) therefore only trips on catastrophic pivot growth.
pub const MAX_BACKWARD_ERROR: f64 = 1e-10;

/// Errors of the linear solver.
#[derive(Debug, thiserror::Error)]
pub enum LinsolveError {
    /// The matrix (or its factorization, or the solution) is singular, ill-conditioned or
    /// non-finite.
    #[error("singular or ill-conditioned tangent: {0}")]
    Singular(String),
    /// The sparsity pattern given to [`SparseSolver::new`] is unusable.
    #[error("invalid sparsity pattern: {0}")]
    Pattern(String),
}

/// Index type of the compressed-column pattern.
type Ix = usize;

/// faer's sparse supernodal LU with partial pivoting: symbolic analysis once, numeric
/// storage and scratch reused across refactorizations.
struct FaerLu {
    symbolic: SymbolicLu<Ix>,
    /// Boxed: the struct is large.
    numeric: Box<NumericLu<Ix, f64>>,
    mem: MemBuffer,
}

impl FaerLu {
    fn new(pattern: faer::sparse::SymbolicSparseColMatRef<'_, Ix>) -> Result<Self, LinsolveError> {
        let params = LuSymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_lu(pattern, params)
            .map_err(|e| LinsolveError::Pattern(format!("symbolic LU analysis failed: {e:?}")))?;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let mem = MemBuffer::try_new(req).map_err(|_| {
            LinsolveError::Pattern(format!(
                "cannot allocate LU scratch for n = {}",
                pattern.nrows()
            ))
        })?;
        Ok(Self {
            symbolic,
            numeric: Box::new(NumericLu::new()),
            mem,
        })
    }

    fn factor(
        &mut self,
        a: faer::sparse::SparseColMatRef<'_, Ix, f64>,
    ) -> Result<(), LinsolveError> {
        self.symbolic
            .factorize_numeric_lu(
                &mut self.numeric,
                a,
                Par::Seq,
                MemStack::new(&mut self.mem),
                Default::default(),
            )
            .map(|_| ())
            .map_err(|e| match e {
                LuError::SymbolicSingular { index } => LinsolveError::Singular(format!(
                    "no nonzero pivot available at elimination step {index}"
                )),
                LuError::Generic(e) => LinsolveError::Singular(format!("sparse LU failed: {e:?}")),
            })
    }

    fn solve(&mut self, rhs: &mut [f64]) {
        let n = rhs.len();
        LuRef::new_unchecked(&self.symbolic, &self.numeric).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
    }
}

/// Factorization backend; see the module documentation.
enum Backend {
    /// Dense LU with partial pivoting for small systems.
    Dense {
        /// Dense copy of the matrix, overwritten by its LU factors.
        lu: Mat<f64>,
        /// Row permutation (forward).
        perm: Vec<Ix>,
        /// Row permutation (inverse).
        perm_inv: Vec<Ix>,
        /// Scratch of the dense factorization and solve.
        mem: MemBuffer,
    },
    /// faer's sparse supernodal LU with partial pivoting.
    Sparse(FaerLu),
    /// Block-tridiagonal LU, checked by the backward error, with faer's pivoted sparse LU
    /// (built on first need) as the fallback for the factorizations it cannot handle.
    Blocks {
        blocks: Box<dyn BlockLu>,
        fallback: Option<FaerLu>,
        /// The current factorization is the fallback's.
        on_fallback: bool,
    },
}

/// Which backend a solver uses (chosen once, from the pattern; see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverKind {
    /// Dense LU with partial pivoting.
    Dense,
    /// faer's sparse supernodal LU.
    Sparse,
    /// Block-tridiagonal LU with node blocks padded to this size.
    BlockTridiagonal(usize),
}

impl std::fmt::Display for SolverKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SolverKind::Dense => write!(f, "dense"),
            SolverKind::Sparse => write!(f, "sparse"),
            SolverKind::BlockTridiagonal(b) => write!(f, "block-tridiagonal-{b}"),
        }
    }
}

/// How [`SparseSolver::with_choice`] picks the backend (tests force each one).
#[derive(Clone, Copy, Debug)]
enum Choice<'a> {
    Dense,
    #[cfg_attr(not(test), allow(dead_code))]
    Sparse,
    /// The block-tridiagonal backend if the pattern is block-tridiagonal in these blocks,
    /// else sparse.
    Blocks(&'a [usize]),
}

/// Sparse LU solver for a fixed sparsity pattern: new values are factorized by
/// [`factor`](Self::factor) and any number of right-hand sides solved with that
/// factorization by [`solve`](Self::solve) (modified Newton reuses one factorization over
/// several iterations); [`factor_solve`](Self::factor_solve) does both.
pub struct SparseSolver {
    /// Pattern (compressed sparse column, sorted, no duplicates) and values.
    a: SparseColMat<Ix, f64>,
    /// Numeric backend.
    backend: Backend,
    /// `‖A‖₁` of the factorized values; `None` until a factorization succeeded (and after
    /// one failed).
    factored_norm: Option<f64>,
    /// Copy of the right-hand side (restored into `rhs` on error).
    b: Vec<f64>,
    /// Residual `b − A x`.
    r: Vec<f64>,
    /// Solves the block backend handed to its fallback (backward error or singular block).
    fallbacks: usize,
}

impl std::fmt::Debug for SparseSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseSolver")
            .field("dim", &self.dim())
            .field("nnz", &self.nnz())
            .field("backend", &self.kind())
            .finish()
    }
}

impl SparseSolver {
    /// Analyses the sparsity pattern of an `n × n` matrix: dense LU up to
    /// [`DENSE_MAX_DIM`], faer's sparse LU beyond.
    ///
    /// `entries`: (row, col) pairs of the pattern in any order, duplicates allowed (merged).
    /// Fails with [`LinsolveError::Pattern`] if an index is out of range or a row or column
    /// is empty (the matrix would be structurally singular).
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, LinsolveError> {
        Self::with_blocks(n, entries, &[])
    }

    /// As [`new`](Self::new), with the unknowns partitioned into consecutive blocks of
    /// `block_sizes` (one per node; zeros allowed): above [`DENSE_MAX_DIM`], a pattern that
    /// only couples neighbouring blocks (a rod numbered node by node) gets the
    /// block-tridiagonal LU.
    pub fn with_blocks(
        n: usize,
        entries: &[(usize, usize)],
        block_sizes: &[usize],
    ) -> Result<Self, LinsolveError> {
        let choice = if n <= DENSE_MAX_DIM {
            Choice::Dense
        } else {
            Choice::Blocks(block_sizes)
        };
        Self::with_choice(n, entries, choice)
    }

    fn with_choice(
        n: usize,
        entries: &[(usize, usize)],
        choice: Choice<'_>,
    ) -> Result<Self, LinsolveError> {
        if let Some(&(r, c)) = entries.iter().find(|&&(r, c)| r >= n || c >= n) {
            return Err(LinsolveError::Pattern(format!(
                "entry ({r}, {c}) out of range for dimension {n}"
            )));
        }
        // Sorted by (col, row) with duplicates merged: bucketed by column (a counting
        // sort), then each column's rows sorted on their own. A rod's pattern has ~10⁴
        // entries, most of them repeated by the neighbouring element, and one sort of them
        // all was most of a member's setup; its columns hold a few dozen.
        let mut bucket: Vec<Ix> = vec![0; n + 1];
        for &(_, c) in entries {
            bucket[c + 1] += 1;
        }
        for j in 0..n {
            bucket[j + 1] += bucket[j];
        }
        let mut rows: Vec<Ix> = vec![0; entries.len()];
        let mut fill = bucket.clone();
        for &(r, c) in entries {
            rows[fill[c]] = r;
            fill[c] += 1;
        }
        let mut col_ptr: Vec<Ix> = vec![0; n + 1];
        let mut row_idx: Vec<Ix> = Vec::with_capacity(entries.len());
        let mut row_seen = vec![false; n];
        for c in 0..n {
            let col = &mut rows[bucket[c]..bucket[c + 1]];
            if col.is_empty() {
                return Err(LinsolveError::Pattern(format!("column {c} is empty")));
            }
            col.sort_unstable();
            let start = row_idx.len();
            for &r in col.iter() {
                if row_idx.len() == start || row_idx[row_idx.len() - 1] != r {
                    row_idx.push(r);
                    row_seen[r] = true;
                }
            }
            col_ptr[c + 1] = row_idx.len();
        }
        if let Some(i) = row_seen.iter().position(|&seen| !seen) {
            return Err(LinsolveError::Pattern(format!("row {i} is empty")));
        }
        let nnz = row_idx.len();
        let blocks = match choice {
            Choice::Blocks(sizes) => block_tridiagonal::analyse(n, &col_ptr, &row_idx, sizes),
            _ => None,
        };
        let pattern = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let a = SparseColMat::new(pattern, vec![0.0; nnz]);

        let backend = match (choice, blocks) {
            (_, Some(blocks)) => Backend::Blocks {
                blocks,
                fallback: None,
                on_fallback: false,
            },
            (Choice::Dense, _) => {
                let req = StackReq::any_of(&[
                    dense_factor::lu_in_place_scratch::<Ix, f64>(
                        n,
                        n,
                        Par::Seq,
                        Default::default(),
                    ),
                    dense_solve::solve_in_place_scratch::<Ix, f64>(n, 1, Par::Seq),
                ]);
                Backend::Dense {
                    lu: Mat::zeros(n, n),
                    perm: vec![0; n],
                    perm_inv: vec![0; n],
                    mem: MemBuffer::try_new(req).map_err(|_| {
                        LinsolveError::Pattern(format!("cannot allocate LU scratch for n = {n}"))
                    })?,
                }
            }
            _ => Backend::Sparse(FaerLu::new(a.symbolic())?),
        };
        Ok(Self {
            a,
            backend,
            factored_norm: None,
            b: vec![0.0; n],
            r: vec![0.0; n],
            fallbacks: 0,
        })
    }

    /// The backend chosen for the pattern.
    pub fn kind(&self) -> SolverKind {
        match &self.backend {
            Backend::Dense { .. } => SolverKind::Dense,
            Backend::Sparse(_) => SolverKind::Sparse,
            Backend::Blocks { blocks, .. } => SolverKind::BlockTridiagonal(blocks.block_size()),
        }
    }

    /// How many factorizations the block backend handed to its pivoting fallback so far.
    pub fn fallbacks(&self) -> usize {
        self.fallbacks
    }

    /// Dimension `n` of the matrix.
    pub fn dim(&self) -> usize {
        self.a.nrows()
    }

    /// Number of distinct entries of the pattern.
    pub fn nnz(&self) -> usize {
        self.a.val().len()
    }

    /// Index into [`values_mut`](Self::values_mut) of entry `(row, col)`.
    ///
    /// # Panics
    /// If `(row, col)` is not in the pattern.
    pub fn slot(&self, row: usize, col: usize) -> usize {
        let pattern = self.a.symbolic();
        assert!(
            col < self.dim(),
            "linsolve: column {col} out of range (n = {})",
            self.dim()
        );
        let (start, end) = (pattern.col_ptr()[col], pattern.col_ptr()[col + 1]);
        match pattern.row_idx()[start..end].binary_search(&row) {
            Ok(k) => start + k,
            Err(_) => panic!("linsolve: entry ({row}, {col}) is not in the sparsity pattern"),
        }
    }

    /// A lookup of [`slot`](Self::slot)s for many entries at once: it maps one column's
    /// rows at a time, so a run of lookups in the same column costs one array read each
    /// instead of a binary search (a member's setup looks up every entry of every element
    /// and node block, ~2·10⁴ for a 30-element rod). Look entries up column by column.
    pub fn slot_lookup(&self) -> SlotLookup<'_> {
        let pattern = self.a.symbolic();
        SlotLookup {
            col_ptr: pattern.col_ptr(),
            row_idx: pattern.row_idx(),
            col: usize::MAX,
            map: vec![(usize::MAX, 0); self.dim()],
        }
    }

    /// The pattern's `(row, col)` entries in value order.
    pub fn entries(&self) -> Vec<(usize, usize)> {
        let pattern = self.a.symbolic();
        let mut out = Vec::with_capacity(self.nnz());
        for col in 0..self.dim() {
            let (start, end) = (pattern.col_ptr()[col], pattern.col_ptr()[col + 1]);
            out.extend(pattern.row_idx()[start..end].iter().map(|&row| (row, col)));
        }
        out
    }

    /// Index into [`values_mut`](Self::values_mut) of entry `(row, col)`, `None` if it is
    /// not in the pattern.
    pub fn try_slot(&self, row: usize, col: usize) -> Option<usize> {
        let pattern = self.a.symbolic();
        if col >= self.dim() {
            return None;
        }
        let (start, end) = (pattern.col_ptr()[col], pattern.col_ptr()[col + 1]);
        pattern.row_idx()[start..end]
            .binary_search(&row)
            .ok()
            .map(|k| start + k)
    }

    /// Values in pattern order (compressed sparse column), writable. Writing invalidates
    /// the factorization only once [`factor`](Self::factor) is called again: until then
    /// [`solve`](Self::solve) keeps using the factors (and checks its backward error
    /// against the factorized matrix: the block backend against the blocks it loaded,
    /// the others against these values; so change them only together with a new
    /// factorization).
    pub fn values_mut(&mut self) -> &mut [f64] {
        self.a.val_mut()
    }

    /// Values in pattern order (compressed sparse column).
    pub fn values(&self) -> &[f64] {
        self.a.val()
    }

    /// Numeric LU of the current values (reusing the symbolic analysis of `new`).
    pub fn factor(&mut self) -> Result<(), LinsolveError> {
        self.factored_norm = None;
        let n = self.dim();
        if n == 0 {
            self.factored_norm = Some(0.0);
            return Ok(());
        }
        let a = self.a.as_ref();
        let col_ptr = a.symbolic().col_ptr();
        let row_idx = a.symbolic().row_idx();
        let vals = a.val();

        // ‖A‖₁ (largest column sum of |a_ij|; contiguous in CSC storage, unlike ‖A‖∞). A
        // column sum is finite iff its entries are (barring overflow), so this is also the
        // finiteness test of the matrix.
        let mut norm_a = 0.0f64;
        let mut finite = true;
        for j in 0..n {
            let sum: f64 = vals[col_ptr[j]..col_ptr[j + 1]]
                .iter()
                .map(|v| v.abs())
                .sum();
            finite &= sum.is_finite();
            norm_a = norm_a.max(sum);
        }
        if !finite {
            return Err(LinsolveError::Singular(
                match vals.iter().position(|v| !v.is_finite()) {
                    Some(p) => format!(
                        "non-finite matrix entry {} at ({}, {})",
                        vals[p],
                        row_idx[p],
                        col_ptr.partition_point(|&c| c <= p) - 1
                    ),
                    None => "matrix norm overflows".to_string(),
                },
            ));
        }
        match &mut self.backend {
            Backend::Dense {
                lu,
                perm,
                perm_inv,
                mem,
            } => {
                lu.fill(0.0);
                for j in 0..n {
                    for p in col_ptr[j]..col_ptr[j + 1] {
                        lu[(row_idx[p], j)] = vals[p];
                    }
                }
                dense_factor::lu_in_place(
                    lu.as_mut(),
                    perm,
                    perm_inv,
                    Par::Seq,
                    MemStack::new(mem),
                    Default::default(),
                );
                // A zero pivot makes the later ones inf/NaN, hence the finiteness test.
                let (mut pmin, mut pmax, mut pivots_finite) = (f64::INFINITY, 0.0f64, true);
                for k in 0..n {
                    let d = lu[(k, k)].abs();
                    pivots_finite &= d.is_finite();
                    pmin = pmin.min(d);
                    pmax = pmax.max(d);
                }
                if !pivots_finite || pmin <= f64::EPSILON * pmax {
                    return Err(LinsolveError::Singular(format!(
                        "numerically zero pivot in dense LU (min |u_kk| = {pmin:e}, \
                         max |u_kk| = {pmax:e})"
                    )));
                }
            }
            Backend::Sparse(f) => f.factor(a)?,
            Backend::Blocks {
                blocks,
                fallback,
                on_fallback,
            } => {
                *on_fallback = blocks.factor(vals).is_err();
                if *on_fallback {
                    self.fallbacks += 1;
                    factor_fallback(fallback, a)?;
                }
            }
        }
        self.factored_norm = Some(norm_a);
        Ok(())
    }

    /// Solves `A x = b` in place with the last factorization (`rhs`: b on entry, x on
    /// successful return; unchanged on error). The solution is checked (finite, backward
    /// error at most [`MAX_BACKWARD_ERROR`] against the factorized matrix; see
    /// [`values_mut`](Self::values_mut)); a block
    /// factorization that fails the check is replaced by the pivoted fallback, which then
    /// serves until the next [`factor`](Self::factor).
    ///
    /// # Panics
    /// If `rhs.len() != self.dim()`.
    pub fn solve(&mut self, rhs: &mut [f64]) -> Result<(), LinsolveError> {
        let n = self.dim();
        assert_eq!(
            rhs.len(),
            n,
            "linsolve: right-hand side has the wrong length"
        );
        let Some(norm_a) = self.factored_norm else {
            return Err(LinsolveError::Singular(
                "no valid factorization (the last one failed)".into(),
            ));
        };
        if n == 0 {
            return Ok(());
        }
        if let Some(i) = rhs.iter().position(|v| !v.is_finite()) {
            return Err(LinsolveError::Singular(format!(
                "non-finite right-hand side entry {} at {i}",
                rhs[i]
            )));
        }
        let norm_b = norm_1(rhs);
        self.b.copy_from_slice(rhs);
        let a = self.a.as_ref();
        let check = |x: &[f64], r: &mut [f64]| {
            check_solution(
                a.symbolic().col_ptr(),
                a.symbolic().row_idx(),
                a.val(),
                &self.b,
                x,
                r,
                norm_a,
                norm_b,
            )
        };
        let verdict = match &mut self.backend {
            Backend::Dense {
                lu,
                perm,
                perm_inv,
                mem,
            } => {
                let row_perm = faer::perm::PermRef::new_checked(perm, perm_inv, n);
                dense_solve::solve_in_place_with_conj(
                    lu.as_ref(),
                    lu.as_ref(),
                    row_perm,
                    Conj::No,
                    MatMut::from_column_major_slice_mut(rhs, n, 1),
                    Par::Seq,
                    MemStack::new(mem),
                );
                check(rhs, &mut self.r)
            }
            Backend::Sparse(f) => {
                f.solve(rhs);
                check(rhs, &mut self.r)
            }
            Backend::Blocks {
                blocks,
                fallback,
                on_fallback,
            } => {
                if !*on_fallback {
                    blocks.solve(rhs);
                    blocks.residual(&self.b, rhs, &mut self.r);
                    if judge_solution(rhs, &self.r, norm_a, norm_b).is_err() {
                        // Pivoting only inside the node blocks was not enough (an
                        // indefinite tangent, a buckling rod): redo it with full pivoting.
                        self.fallbacks += 1;
                        *on_fallback = true;
                        rhs.copy_from_slice(&self.b);
                        factor_fallback(fallback, a)?;
                    }
                }
                if *on_fallback {
                    let f = fallback.as_mut().expect("fallback factorized above");
                    f.solve(rhs);
                    check(rhs, &mut self.r)
                } else {
                    Ok(())
                }
            }
        };
        if verdict.is_err() {
            rhs.copy_from_slice(&self.b);
        }
        verdict
    }

    /// [`factor`](Self::factor) then [`solve`](Self::solve).
    ///
    /// # Panics
    /// If `rhs.len() != self.dim()`.
    pub fn factor_solve(&mut self, rhs: &mut [f64]) -> Result<(), LinsolveError> {
        assert_eq!(
            rhs.len(),
            self.dim(),
            "linsolve: right-hand side has the wrong length"
        );
        self.factor()?;
        self.solve(rhs)
    }
}

/// Factorizes `a` with the block backend's pivoting fallback (built on first use).
fn factor_fallback(
    fallback: &mut Option<FaerLu>,
    a: faer::sparse::SparseColMatRef<'_, Ix, f64>,
) -> Result<(), LinsolveError> {
    if fallback.is_none() {
        *fallback = Some(FaerLu::new(a.symbolic())?);
    }
    fallback.as_mut().expect("just built").factor(a)
}

/// `‖v‖₁ = Σ |v_i|` (NaN if any `v_i` is NaN).
fn norm_1(v: &[f64]) -> f64 {
    v.iter().map(|x| x.abs()).sum()
}

/// Checks finiteness, backward error and the condition lower bound of the solution `x` of
/// `A x = b` (A in compressed sparse column form, `norm_a = ‖A‖₁`, `norm_b = ‖b‖₁`). `r` is
/// workspace for the residual.
#[allow(clippy::too_many_arguments)]
fn check_solution(
    col_ptr: &[Ix],
    row_idx: &[Ix],
    vals: &[f64],
    b: &[f64],
    x: &[f64],
    r: &mut [f64],
    norm_a: f64,
    norm_b: f64,
) -> Result<(), LinsolveError> {
    r.copy_from_slice(b);
    for (j, &xj) in x.iter().enumerate() {
        let range = col_ptr[j]..col_ptr[j + 1];
        for (&i, &v) in row_idx[range.clone()].iter().zip(&vals[range]) {
            r[i] -= v * xj;
        }
    }
    judge_solution(x, r, norm_a, norm_b)
}

/// The verdict of [`check_solution`] on the solution `x` and its residual `r = b − A x`
/// (computed by the caller: from the compressed columns, or block by block).
fn judge_solution(x: &[f64], r: &[f64], norm_a: f64, norm_b: f64) -> Result<(), LinsolveError> {
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(LinsolveError::Singular(format!(
            "non-finite solution component {} at {i}",
            x[i]
        )));
    }
    let norm_r = norm_1(r);
    let norm_x = norm_1(x);
    let scale = norm_a * norm_x + norm_b;
    // The residual is NaN if A x overflowed (inf − inf).
    if norm_r.is_nan() || norm_r > MAX_BACKWARD_ERROR * scale {
        return Err(LinsolveError::Singular(format!(
            "backward error {:e} of the LU solve exceeds {MAX_BACKWARD_ERROR:e}",
            norm_r / scale
        )));
    }
    Ok(())
}

/// Column-by-column slot lookups ([`SparseSolver::slot_lookup`]).
pub struct SlotLookup<'a> {
    col_ptr: &'a [Ix],
    row_idx: &'a [Ix],
    /// The column the lookups are in (`usize::MAX`: none yet).
    col: usize,
    /// Row → (column, slot) of the last column that row was mapped for: valid for the
    /// current column only where the column matches (no clearing between columns).
    map: Vec<(usize, usize)>,
}

impl SlotLookup<'_> {
    /// Index into [`SparseSolver::values_mut`] of entry `(row, col)`, the same as
    /// [`SparseSolver::slot`].
    ///
    /// # Panics
    /// If `(row, col)` is not in the pattern.
    pub fn slot(&mut self, row: usize, col: usize) -> usize {
        if col != self.col {
            assert!(
                col < self.map.len(),
                "linsolve: column {col} out of range (n = {})",
                self.map.len()
            );
            let (start, end) = (self.col_ptr[col], self.col_ptr[col + 1]);
            for (k, &r) in self.row_idx[start..end].iter().enumerate() {
                self.map[r] = (col, start + k);
            }
            self.col = col;
        }
        match self.map.get(row) {
            Some(&(c, k)) if c == col => k,
            _ => panic!("linsolve: entry ({row}, {col}) is not in the sparsity pattern"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tolerance on the normwise backward error `‖A x − b‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞)`.
    ///
    /// LU with partial pivoting gives `(A + ΔA) x = b` with `|ΔA| ≤ γ_w |L||U|`,
    /// `γ_w = w ε / (1 − w ε)`, `w` the largest number of entries in a row of L or column
    /// of U (Higham, Accuracy and Stability, Thm. 9.3), so the backward error is at most
    /// about `w ε ‖|L||U|‖/‖A‖ ≈ w ε ρ`. For 6×6 block-tridiagonal matrices, with fill from
    /// pivoting, `w ≤ 3·12 = 36` on the sparse path; the dense path is only used up to
    /// n = 306 in these tests but its per-entry error is also driven by the accumulated
    /// length of the dot products (≤ 306). With ε = 2.2e-16 and a pivot growth ρ ≤ 10,
    /// `306 · 2.2e-16 · 10 ≈ 7e-13 < 1e-12`. (Observed: 3e-17 … 2e-16 on these matrices.)
    const TEST_BACKWARD_TOL: f64 = 1e-12;

    use crate::math::rng::Rng;

    /// Pattern of a block-tridiagonal matrix of `nb` blocks of size `bs`, row-major order.
    fn block_tridiag_pattern(nb: usize, bs: usize) -> Vec<(usize, usize)> {
        variable_block_pattern(&vec![bs; nb])
    }

    /// Fills random unsymmetric values into the pattern `entries` (accumulating, as the
    /// assembly does); `diag_shift` is added to every diagonal entry (0 = not dominant).
    fn fill_random(
        s: &mut SparseSolver,
        entries: &[(usize, usize)],
        rng: &mut Rng,
        diag_shift: f64,
    ) {
        let slots: Vec<usize> = entries.iter().map(|&(r, c)| s.slot(r, c)).collect();
        let v = s.values_mut();
        v.fill(0.0);
        for (&(r, c), &k) in entries.iter().zip(&slots) {
            v[k] += rng.symmetric() + if r == c { diag_shift } else { 0.0 };
        }
    }

    /// `A x` for the solver's current values.
    fn matvec(s: &SparseSolver, x: &[f64]) -> Vec<f64> {
        let pattern = s.a.symbolic();
        let mut y = vec![0.0; s.dim()];
        for (j, &xj) in x.iter().enumerate() {
            for p in pattern.col_ptr()[j]..pattern.col_ptr()[j + 1] {
                y[pattern.row_idx()[p]] += s.values()[p] * xj;
            }
        }
        y
    }

    /// `max_i |v_i|`.
    fn inf_norm(v: &[f64]) -> f64 {
        v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
    }

    /// `‖A‖∞` for the solver's current values.
    fn norm_a(s: &SparseSolver) -> f64 {
        let pattern = s.a.symbolic();
        let mut rows = vec![0.0; s.dim()];
        for (p, &i) in pattern.row_idx().iter().enumerate() {
            rows[i] += s.values()[p].abs();
        }
        inf_norm(&rows)
    }

    /// Normwise backward error of `x` as a solution of `A x = b`.
    fn backward_error(s: &SparseSolver, x: &[f64], b: &[f64]) -> f64 {
        let ax = matvec(s, x);
        let r: Vec<f64> = ax.iter().zip(b).map(|(p, q)| p - q).collect();
        inf_norm(&r) / (norm_a(s) * inf_norm(x) + inf_norm(b))
    }

    fn random_vec(n: usize, rng: &mut Rng) -> Vec<f64> {
        (0..n).map(|_| rng.symmetric()).collect()
    }

    #[test]
    fn solves_random_block_tridiagonal_both_backends() {
        let mut rng = Rng::new(1);
        for &nb in &[1usize, 10, 51, 500] {
            let n = 6 * nb;
            let entries = block_tridiag_pattern(nb, 6);
            for dense in [true, false] {
                if dense && n > 306 {
                    continue; // O(n^3): pointless for large n
                }
                let mut s = SparseSolver::with_choice(
                    n,
                    &entries,
                    if dense { Choice::Dense } else { Choice::Sparse },
                )
                .unwrap();
                assert_eq!(s.dim(), n);
                assert_eq!(s.nnz(), entries.len());
                for shift in [8.0, 0.0] {
                    fill_random(&mut s, &entries, &mut rng, shift);
                    let b = random_vec(n, &mut rng);
                    let mut x = b.clone();
                    s.factor_solve(&mut x).unwrap_or_else(|e| {
                        panic!("n = {n}, dense = {dense}, shift = {shift}: {e}")
                    });
                    let eta = backward_error(&s, &x, &b);
                    assert!(
                        eta <= TEST_BACKWARD_TOL,
                        "n = {n}, dense = {dense}, shift = {shift}: backward error {eta:e}"
                    );
                }
            }
        }
    }

    /// Pattern of a block-tridiagonal matrix with blocks of the given sizes (zeros allowed:
    /// a clamped node; its neighbours are then not coupled).
    fn variable_block_pattern(sizes: &[usize]) -> Vec<(usize, usize)> {
        let starts: Vec<usize> = sizes
            .iter()
            .scan(0, |s, &k| {
                *s += k;
                Some(*s - k)
            })
            .collect();
        let mut e = Vec::new();
        for bi in 0..sizes.len() {
            for bj in bi.saturating_sub(1)..(bi + 2).min(sizes.len()) {
                for i in 0..sizes[bi] {
                    for j in 0..sizes[bj] {
                        e.push((starts[bi] + i, starts[bj] + j));
                    }
                }
            }
        }
        e
    }

    /// The column-wise lookup answers every entry as [`SparseSolver::slot`] does, in
    /// any order (columns revisited, rows in any order), and refuses entries outside the
    /// pattern.
    #[test]
    fn slot_lookup_matches_slot_in_any_order() {
        let entries = variable_block_pattern(&[6, 9, 9, 3, 9]);
        let s = SparseSolver::new(36, &entries).unwrap();
        let mut rng = Rng::new(31);
        let mut order = entries.clone();
        // A shuffle, then runs of one column as the setup does.
        for i in (1..order.len()).rev() {
            let j = ((rng.uniform() * (i + 1) as f64) as usize).min(i);
            order.swap(i, j);
        }
        let mut look = s.slot_lookup();
        for &(r, c) in order.iter().chain(&entries) {
            assert_eq!(look.slot(r, c), s.slot(r, c), "entry ({r}, {c})");
        }
        let missing = std::panic::catch_unwind(move || look.slot(0, 35));
        assert!(missing.is_err(), "(0, 35) is outside the pattern");
    }

    /// The block backend checks each solve with `b − A x` formed from its node blocks
    /// (the diagonal blocks kept from before the factorization overwrote them): it equals
    /// the residual from the compressed columns, for every block layout, padded
    /// and empty blocks included.
    #[test]
    fn the_block_residual_is_the_compressed_columns_one() {
        let mut rng = Rng::new(23);
        let cases: Vec<Vec<usize>> = vec![
            vec![6; 20],
            vec![9; 12],
            vec![3; 15],
            [vec![0], vec![5; 10], vec![3], vec![0]].concat(),
            (0..20).map(|i| [9, 6, 0, 3, 9][i % 5]).collect(),
        ];
        for sizes in cases {
            let n: usize = sizes.iter().sum();
            let entries = variable_block_pattern(&sizes);
            let mut s = SparseSolver::with_choice(n, &entries, Choice::Blocks(&sizes)).unwrap();
            fill_random(&mut s, &entries, &mut rng, 4.0);
            s.factor().unwrap();
            let Backend::Blocks { blocks, .. } = &s.backend else {
                panic!("{sizes:?}: not the block backend");
            };
            let (b, x) = (random_vec(n, &mut rng), random_vec(n, &mut rng));
            let mut r = vec![f64::NAN; n];
            blocks.residual(&b, &x, &mut r);
            let ax = matvec(&s, &x);
            let worst = (0..n).fold(0.0f64, |m, i| m.max((r[i] - (b[i] - ax[i])).abs()));
            eprintln!("{sizes:?}: block vs compressed-column residual {worst:.1e}");
            // Same products summed in another order: round-off of entries of size ≈ 10
            // (measured 1.3e-15 … 3.6e-15; dropping the sub-diagonal blocks gives 2.7).
            assert!(worst <= 2e-14, "{sizes:?}: residuals differ by {worst:e}");
        }
    }

    #[test]
    fn block_tridiagonal_backend_matches_the_pivoted_ones() {
        let mut rng = Rng::new(11);
        // Node blocks as the integrator makes them: 9 (u θ g), 6 (u θ), 3 and 5 (planar),
        // and 0 (clamped node) — padded to 3, 6 or 9.
        let cases: Vec<(Vec<usize>, usize)> = vec![
            (vec![6; 51], 6),
            (vec![9; 40], 9),
            (vec![3; 30], 3),
            ([vec![0], vec![5; 30], vec![3], vec![0]].concat(), 6),
            ((0..40).map(|i| [9, 6, 0, 3, 9][i % 5]).collect(), 9),
        ];
        for (sizes, padded) in cases {
            let n: usize = sizes.iter().sum();
            let entries = variable_block_pattern(&sizes);
            let mut blocks = SparseSolver::with_blocks(n, &entries, &sizes).unwrap();
            assert_eq!(blocks.kind(), SolverKind::BlockTridiagonal(padded));
            let mut sparse = SparseSolver::with_choice(n, &entries, Choice::Sparse).unwrap();
            for shift in [8.0, 0.5] {
                fill_random(&mut blocks, &entries, &mut rng, shift);
                sparse.values_mut().copy_from_slice(blocks.values());
                let b = random_vec(n, &mut rng);
                let (mut x, mut y) = (b.clone(), b.clone());
                blocks.factor_solve(&mut x).unwrap();
                sparse.factor_solve(&mut y).unwrap();
                assert!(backward_error(&blocks, &x, &b) <= TEST_BACKWARD_TOL);
                let diff = x
                    .iter()
                    .zip(&y)
                    .map(|(p, q)| (p - q).abs())
                    .fold(0.0, f64::max);
                assert!(
                    diff <= 1e-9 * inf_norm(&y),
                    "{sizes:?}, shift {shift}: {diff:e}"
                );
                // The factorization serves further right-hand sides (modified Newton).
                let c = random_vec(n, &mut rng);
                let mut z = c.clone();
                blocks.solve(&mut z).unwrap();
                assert!(backward_error(&blocks, &z, &c) <= TEST_BACKWARD_TOL);
            }
        }
    }

    #[test]
    fn block_backend_falls_back_to_pivoting_when_a_block_is_singular() {
        // Diagonal blocks that are singular on their own (zero diagonal, coupling only
        // through the neighbours): the block LU cannot pivot across nodes, the fallback can.
        let sizes = vec![2usize; 40];
        let n = 80;
        let entries = variable_block_pattern(&sizes);
        let mut s = SparseSolver::with_blocks(n, &entries, &sizes).unwrap();
        s.values_mut().fill(0.0);
        for i in 0..n {
            // A permutation matrix pairing node k with node k+1 (or k−1): nonsingular.
            let j = if (i / 2) % 2 == 0 { i + 2 } else { i - 2 };
            let k = s.slot(i, j);
            s.values_mut()[k] = 1.0 + i as f64;
        }
        let b: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let mut x = b.clone();
        s.factor_solve(&mut x).unwrap();
        assert!(backward_error(&s, &x, &b) <= TEST_BACKWARD_TOL);
        assert_eq!(s.fallbacks(), 1);
    }

    #[test]
    fn patterns_that_are_not_block_tridiagonal_use_the_sparse_lu() {
        let sizes = vec![6usize; 20];
        let mut entries = variable_block_pattern(&sizes);
        entries.push((0, 119)); // couples the first and the last node
        let s = SparseSolver::with_blocks(120, &entries, &sizes).unwrap();
        assert_eq!(s.kind(), SolverKind::Sparse);
        let small = SparseSolver::with_blocks(60, &variable_block_pattern(&[6; 10]), &[6; 10]);
        assert_eq!(small.unwrap().kind(), SolverKind::Dense);
    }

    #[test]
    fn solve_without_a_valid_factorization_is_an_error() {
        let entries = block_tridiag_pattern(20, 6);
        let mut s = SparseSolver::with_blocks(120, &entries, &[6; 20]).unwrap();
        let mut x = vec![1.0; 120];
        assert!(matches!(s.solve(&mut x), Err(LinsolveError::Singular(_))));
        s.values_mut()[0] = f64::NAN;
        assert!(s.factor().is_err());
        assert!(s.solve(&mut x).is_err());
        assert_eq!(x, vec![1.0; 120]);
    }

    #[test]
    fn recovers_known_solution_of_dominant_system() {
        // Diagonally dominant (shift 40 > 18 off-diagonal entries of size ≤ 1 per row):
        // κ∞ ≤ 40+18 / (40−18) ≈ 2.6, so the forward error is ≲ κ · backward error.
        let mut rng = Rng::new(2);
        for &nb in &[1usize, 51] {
            let n = 6 * nb;
            let entries = block_tridiag_pattern(nb, 6);
            let mut s = SparseSolver::new(n, &entries).unwrap();
            fill_random(&mut s, &entries, &mut rng, 40.0);
            let x_true = random_vec(n, &mut rng);
            let mut x = matvec(&s, &x_true);
            s.factor_solve(&mut x).unwrap();
            let err = x
                .iter()
                .zip(&x_true)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max);
            assert!(
                err <= 3.0 * TEST_BACKWARD_TOL,
                "n = {n}: forward error {err:e}"
            );
        }
    }

    #[test]
    fn duplicates_are_merged() {
        // 1-D Laplacian-like tridiagonal pattern given in scrambled order with repeats.
        let n: usize = 100;
        let mut entries = Vec::new();
        for i in 0..n {
            for j in i.saturating_sub(1)..(i + 2).min(n) {
                entries.push((i, j));
            }
        }
        let unique = entries.len();
        let mut scrambled: Vec<(usize, usize)> = entries.iter().rev().copied().collect();
        scrambled.extend(entries.iter().step_by(3).copied());
        scrambled.extend(entries.iter().step_by(7).copied());
        let mut s = SparseSolver::new(n, &scrambled).unwrap();
        assert_eq!(s.nnz(), unique);
        // Every slot distinct and in range.
        let mut slots: Vec<usize> = entries.iter().map(|&(r, c)| s.slot(r, c)).collect();
        slots.sort_unstable();
        slots.dedup();
        assert_eq!(slots.len(), unique);
        assert!(slots.iter().all(|&k| k < unique));
        // Assemble A = tridiag(-1, 3, -1) through the repeated entries (each occurrence
        // adds its share), solve with x_true = 1..n.
        let mut count = vec![0usize; unique];
        for &(r, c) in &scrambled {
            count[s.slot(r, c)] += 1;
        }
        s.values_mut().fill(0.0);
        for &(r, c) in &scrambled {
            let k = s.slot(r, c);
            let target = if r == c { 3.0 } else { -1.0 };
            s.values_mut()[k] += target / count[k] as f64;
        }
        let x_true: Vec<f64> = (1..=n).map(|i| i as f64).collect();
        let mut x = matvec(&s, &x_true);
        s.factor_solve(&mut x).unwrap();
        for (p, q) in x.iter().zip(&x_true) {
            assert!((p - q).abs() <= 1e-12 * n as f64, "{p} vs {q}");
        }
    }

    #[test]
    fn refactorization_with_new_values_on_same_pattern() {
        let mut rng = Rng::new(3);
        for &nb in &[10usize, 51] {
            let n = 6 * nb;
            let entries = block_tridiag_pattern(nb, 6);
            let mut s = SparseSolver::new(n, &entries).unwrap();
            for iter in 0..4 {
                // Alternate dominant / non-dominant values so the pivot sequence changes.
                let shift = if iter % 2 == 0 { 8.0 } else { 0.0 };
                fill_random(&mut s, &entries, &mut rng, shift);
                let b = random_vec(n, &mut rng);
                let mut x = b.clone();
                s.factor_solve(&mut x).unwrap();
                assert!(backward_error(&s, &x, &b) <= TEST_BACKWARD_TOL);
                // A fresh solver on the same values gives the same answer.
                let mut fresh = SparseSolver::new(n, &entries).unwrap();
                fresh.values_mut().copy_from_slice(s.values());
                let mut y = b.clone();
                fresh.factor_solve(&mut y).unwrap();
                assert_eq!(x, y, "n = {n}, iteration {iter}");
            }
        }
    }

    #[test]
    fn zero_row_is_singular_and_rhs_is_kept() {
        let mut rng = Rng::new(4);
        for &nb in &[1usize, 10, 51] {
            let n = 6 * nb;
            let entries = block_tridiag_pattern(nb, 6);
            for dense in [true, false] {
                let mut s = SparseSolver::with_choice(
                    n,
                    &entries,
                    if dense { Choice::Dense } else { Choice::Sparse },
                )
                .unwrap();
                fill_random(&mut s, &entries, &mut rng, 2.0);
                let zero_row = n / 2 + 1;
                for &(r, c) in &entries {
                    if r == zero_row {
                        let k = s.slot(r, c);
                        s.values_mut()[k] = 0.0;
                    }
                }
                let b = random_vec(n, &mut rng);
                let mut x = b.clone();
                let res = s.factor_solve(&mut x);
                assert!(
                    matches!(res, Err(LinsolveError::Singular(_))),
                    "n = {n}, dense = {dense}: {res:?}"
                );
                assert_eq!(x, b);
                // The solver recovers once the values are fixed.
                fill_random(&mut s, &entries, &mut rng, 8.0);
                s.factor_solve(&mut x).unwrap();
                assert!(backward_error(&s, &x, &b) <= TEST_BACKWARD_TOL);
            }
        }
    }

    #[test]
    fn structurally_singular_pattern_is_an_error_not_a_panic() {
        // Tridiagonal, except that columns 0 and 1 only touch row 0 and row 1 only touches
        // column 2: no empty row or column, but structural rank n − 1.
        let n: usize = 100;
        let mut entries = vec![(0, 0), (0, 1), (1, 2)];
        for i in 2..n {
            for j in i.saturating_sub(1).max(2)..(i + 2).min(n) {
                entries.push((i, j));
            }
        }
        let mut rng = Rng::new(8);
        for dense in [true, false] {
            match SparseSolver::with_choice(
                n,
                &entries,
                if dense { Choice::Dense } else { Choice::Sparse },
            ) {
                Err(e) => assert!(matches!(e, LinsolveError::Pattern(_))),
                Ok(mut s) => {
                    fill_random(&mut s, &entries, &mut rng, 4.0);
                    let mut x = random_vec(n, &mut rng);
                    let res = s.factor_solve(&mut x);
                    assert!(matches!(res, Err(LinsolveError::Singular(_))), "{res:?}");
                }
            }
        }
    }

    #[test]
    fn non_finite_input_is_rejected() {
        let n = 12;
        let entries = block_tridiag_pattern(2, 6);
        let mut s = SparseSolver::new(n, &entries).unwrap();
        let mut rng = Rng::new(6);
        fill_random(&mut s, &entries, &mut rng, 8.0);
        let k = s.slot(3, 9);
        s.values_mut()[k] = f64::NAN;
        let mut x = vec![1.0; n];
        let err = s.factor_solve(&mut x).unwrap_err();
        assert!(err.to_string().contains("(3, 9)"), "{err}");
        s.values_mut()[k] = 0.5;
        x[4] = f64::INFINITY;
        assert!(matches!(
            s.factor_solve(&mut x),
            Err(LinsolveError::Singular(_))
        ));
    }

    #[test]
    fn invalid_patterns_are_rejected() {
        assert!(matches!(
            SparseSolver::new(3, &[(0, 0), (1, 1), (2, 3)]),
            Err(LinsolveError::Pattern(_))
        ));
        // Row 2 empty.
        assert!(matches!(
            SparseSolver::new(3, &[(0, 0), (1, 1), (0, 2), (1, 2)]),
            Err(LinsolveError::Pattern(_))
        ));
        // Column 1 empty.
        assert!(matches!(
            SparseSolver::new(3, &[(0, 0), (1, 0), (2, 2), (1, 2)]),
            Err(LinsolveError::Pattern(_))
        ));
        // Empty system is fine.
        let mut s = SparseSolver::new(0, &[]).unwrap();
        s.factor_solve(&mut []).unwrap();
    }

    #[test]
    #[should_panic(expected = "not in the sparsity pattern")]
    fn slot_panics_outside_pattern() {
        let s = SparseSolver::new(2, &[(0, 0), (1, 1)]).unwrap();
        let _ = s.slot(0, 1);
    }
}
