//! TEMPORARY dense stand-in (replaced by the faer sparse solver).
#![allow(missing_docs)]
#[derive(Debug, thiserror::Error)]
pub enum LinsolveError {
    #[error("singular or ill-conditioned tangent: {0}")]
    Singular(String),
    #[error("invalid sparsity pattern: {0}")]
    Pattern(String),
}
pub struct SparseSolver { n: usize, entries: Vec<(usize, usize)>, vals: Vec<f64> }
impl SparseSolver {
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, LinsolveError> {
        let mut e = entries.to_vec(); e.sort(); e.dedup();
        let m = e.len();
        Ok(Self { n, entries: e, vals: vec![0.0; m] })
    }
    pub fn dim(&self) -> usize { self.n }
    pub fn slot(&self, row: usize, col: usize) -> usize { self.entries.binary_search(&(row, col)).unwrap() }
    pub fn values_mut(&mut self) -> &mut [f64] { &mut self.vals }
    pub fn values(&self) -> &[f64] { &self.vals }
    pub fn factor_solve(&mut self, rhs: &mut [f64]) -> Result<(), LinsolveError> {
        let n = self.n;
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        for (k, &(i, j)) in self.entries.iter().enumerate() { a[(i, j)] += self.vals[k]; }
        let b = nalgebra::DVector::from_column_slice(rhs);
        let x = a.lu().solve(&b).ok_or_else(|| LinsolveError::Singular("lu".into()))?;
        rhs.copy_from_slice(x.as_slice());
        Ok(())
    }
}
