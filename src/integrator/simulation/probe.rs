//! Entry points for tests: the residual, the dense tangent and the assembled system at a
//! given increment (with the loads of the coming mid-step), and frozen scalars set by
//! hand.

use super::{Mode, Simulation};
use crate::element::{FrozenScalars, Increment};
use crate::integrator::evaluate::now;
use crate::integrator::invariants::{invariants, Invariants};
use crate::integrator::state::State;

impl Simulation {
    /// Position and triad updates of a global increment applied to the current state
    /// (for tests of the tangent).
    pub fn residual_at(&mut self, q: &[f64], consistent: bool) -> Vec<f64> {
        let mut r = vec![0.0; self.dofs.n];
        self.mid_step_loads();
        self.refresh_rod_pairs().expect("contact pairs");
        let mode = if consistent {
            Mode::Consistent
        } else {
            Mode::Frozen
        };
        now(self.assemble(q, mode, true, &mut r));
        r
    }

    /// Dense copy of the assembled tangent at `q` (tests only; small models).
    pub fn dense_tangent_at(&mut self, q: &[f64], consistent: bool) -> Vec<Vec<f64>> {
        let _ = self.residual_at(q, consistent);
        let n = self.dofs.n;
        let mut dense = vec![vec![0.0; n]; n];
        for ((row, col), v) in self.solver.entries().into_iter().zip(self.solver.values()) {
            dense[row][col] = *v;
        }
        dense
    }

    /// Residual, per-kind row scales (u, θ, g) and matrix values (pattern order)
    /// assembled at `q` with the frozen scalars: through the backend when one is attached,
    /// else on the CPU kernel (tests compare the two).
    /// Without `tangent` the values are left out (empty).
    pub fn frozen_system_at(&mut self, q: &[f64], tangent: bool) -> (Vec<f64>, [f64; 3], Vec<f64>) {
        let mut r = vec![0.0; self.dofs.n];
        self.mid_step_loads();
        let (_, scale) = now(self.assemble(q, Mode::Frozen, tangent, &mut r));
        let values = if tangent {
            self.solver.values().to_vec()
        } else {
            Vec::new()
        };
        (r, scale, values)
    }

    /// The step's advance from the current state by the increment `q` with the frozen
    /// scalars (loads and support motion of the coming mid-step): the state at `n+1`, its
    /// invariants and the predicted dissipation (tests of the device's advance).
    pub fn advanced_at(&mut self, q: &[f64]) -> (State, Invariants, f64) {
        self.mid_step_loads();
        let (next, diss, _) = self.advance(q, Mode::Frozen);
        let inv = invariants(&self.model, &self.data, &next);
        (next, inv, diss)
    }

    /// Per element: its element-local increment of `q` (after [`Self::advanced_at`] or
    /// another entry point that set the coming step's support motion).
    pub fn element_increments(&self, q: &[f64]) -> Vec<Increment> {
        (0..self.model.elements.len())
            .map(|e| self.gather(e, q))
            .collect()
    }

    /// Sets the frozen dissipation scalars of every element (tests of the staggered
    /// tangent).
    pub fn set_frozen(&mut self, s: FrozenScalars) {
        self.frozen.iter_mut().for_each(|x| *x = s);
    }
}
