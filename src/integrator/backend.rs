//! A pluggable evaluator of the element kernel for frozen-scalar assembly: the CPU kernel
//! by default, the GPU batch ([`crate::batch`]) when one is attached with
//! [`crate::integrator::Simulation::set_backend`]. The Newton loop, strategies and
//! acceptance checks stay those of [`crate::integrator::Simulation`].

use nalgebra::Vector6;

use crate::element::{ElementEval, ElementState, FrozenScalars, Increment};

/// What the kernel needs per element besides the run constants registered beforehand.
#[derive(Clone, Copy, Debug)]
pub struct ElementInput {
    /// State at `n`.
    pub st: ElementState,
    /// Raw strains at `n`.
    pub eps_n: Vector6<f64>,
    /// Current Newton increment.
    pub inc: Increment,
    /// Frozen dissipation scalars.
    pub s: FrozenScalars,
}

/// Evaluates all elements of one simulation at once (frozen scalars).
pub trait ElementBackend: Send + Sync {
    /// Residuals, scales and (if `tangent`) tangents of the elements of the simulation in
    /// `slot`, in element order. An error fails the Newton solve (the step is rejected).
    fn evaluate(
        &self,
        slot: usize,
        inputs: &[ElementInput],
        tangent: bool,
    ) -> Result<Vec<ElementEval>, String>;
}
