//! A pluggable evaluator of the element kernel for frozen-scalar assembly: the CPU kernel
//! by default, the GPU batch ([`crate::batch`]) when one is attached with
//! [`crate::integrator::Simulation::set_backend`]. The backend returns the elements
//! already summed per node ([`AssembledSystem`]); the Newton loop, strategies and
//! acceptance checks stay those of [`crate::integrator::Simulation`].

use nalgebra::Vector6;

use crate::element::{ElementState, FrozenScalars};

/// What the kernel needs per element besides the run constants registered beforehand
/// (the Newton increment comes per node).
#[derive(Clone, Copy, Debug)]
pub struct ElementInput {
    /// State at `n`.
    pub st: ElementState,
    /// Raw strains at `n`.
    pub eps_n: Vector6<f64>,
    /// Frozen dissipation scalars.
    pub s: FrozenScalars,
}

/// The element contributions of one simulation summed into its block system, in
/// node-local order `u0..2 θ0..2 g0..2` (removed unknowns included; the caller skips them).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AssembledSystem {
    /// Per node: the sum of its incident elements' residual rows.
    pub node_r: Vec<[f64; 9]>,
    /// Per node: its diagonal 9×9 block (row-major), the sum of its incident elements'
    /// (l, l) sub-blocks. Empty without the tangent.
    pub node_k: Vec<[f64; 81]>,
    /// Per element: its off-diagonal blocks (end 0, end 1) and (end 1, end 0), row-major.
    /// Empty without the tangent.
    pub off_k: Vec<[[f64; 81]; 2]>,
    /// Largest element row scale of each kind (u, θ, g) over the rows that are unknowns.
    pub scale: [f64; 3],
}

/// Evaluates all elements of one simulation at once (frozen scalars) and sums them.
pub trait ElementBackend: Send + Sync {
    /// Assembled residual, row scales and (if `tangent`) blocks of the elements of the
    /// simulation in `slot` (`inputs` in element order; `increments`: the current Newton
    /// increment per node, node-local order, zero for removed unknowns). An error fails
    /// the Newton solve (the step is rejected).
    fn evaluate_assembled(
        &self,
        slot: usize,
        inputs: &[ElementInput],
        increments: &[[f64; 9]],
        tangent: bool,
    ) -> Result<AssembledSystem, String>;

    /// Where the elements are evaluated, for every output (e.g. `gpu: ADAPTER, f64`).
    fn describe(&self) -> String;
}
