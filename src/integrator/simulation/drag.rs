//! Drag per unit length (part of stage 4, [`super::assemble`]): on every element with a
//! drag coefficient `c`, the force `−c (r_{n+1} − r_n)/Δt` per unit length through the
//! consistent pattern, `F_l = −(c h/Δt) Σ_m M2[l][m] u_m`. It is linear in the
//! increments, and its work over a step, `−(c h/Δt) Σ_lm M2[l][m] u_l·u_m ≤ 0`, is counted
//! in the dissipation D (so `ΔH = W − D` still closes exactly); for the momenta it is an
//! external impulse.
//!
//! On the GPU path the element kernel adds the same rows, tangent and dissipation with the
//! element's own (`shaders/element.wgsl`, `E_DRAG`: a device solve needs them there, since
//! they depend on the iterate); the host then adds none (`Simulation::assemble`).

use super::Simulation;
use crate::element::drag as element_drag;
use crate::element::{u_idx, M2, NDOF};
use crate::integrator::dofs::NONE;
use crate::model::Vec3;

impl Simulation {
    /// Drag forces `F_l` on the two ends of element `e` at increment `q`.
    fn drag_forces(&self, e: usize, q: &[f64]) -> [Vec3; 2] {
        let u = self.gather(e, q).u;
        element_drag::drag_forces(&self.model.elements[e].props, &u, self.params.dt)
    }

    /// Adds the drag rows (`−F`), row scales and, with `tangent`, the `(u, u)` blocks.
    pub(super) fn add_drag_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        if !self.model.has_drag() {
            return;
        }
        let dt = self.params.dt;
        for e in 0..self.model.elements.len() {
            let p = &self.model.elements[e].props;
            if p.drag == 0.0 {
                continue;
            }
            let k = p.drag * p.h / dt;
            let f = self.drag_forces(e, q);
            let map = self.dofs.elements[e];
            for l in 0..2 {
                // The row scale of an end's translations: its force's largest component, as
                // the GPU element kernel takes it (`element::drag::add_drag_rows`).
                let fmax = f[l].amax();
                for c in 0..3 {
                    let i = u_idx(l) + c;
                    if map[i] == NONE {
                        continue;
                    }
                    r[map[i]] -= f[l][c];
                    scale[0] = scale[0].max(fmax);
                    if tangent {
                        for m in 0..2 {
                            let j = u_idx(m) + c;
                            let slot = self.slots[e][i * NDOF + j];
                            if slot != NONE {
                                self.solver.values_mut()[slot] += k * M2[l][m];
                            }
                        }
                    }
                }
            }
        }
    }

    /// Energy the drag takes out over the step at `q` (≥ 0), part of the dissipation D.
    pub(super) fn drag_dissipation(&self, q: &[f64]) -> f64 {
        if !self.model.has_drag() {
            return 0.0;
        }
        (0..self.model.elements.len())
            .filter(|&e| self.model.elements[e].props.drag != 0.0)
            .map(|e| {
                let u = self.gather(e, q).u;
                element_drag::drag_dissipation(&self.model.elements[e].props, &u, self.params.dt)
            })
            .sum()
    }

    /// Drag force on every node at `q` (zero without drag).
    pub(super) fn drag_node_forces(&self, q: &[f64]) -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); self.model.n_nodes()];
        if self.model.has_drag() {
            for (e, el) in self.model.elements.iter().enumerate() {
                if el.props.drag != 0.0 {
                    let f = self.drag_forces(e, q);
                    out[el.nodes[0]] += f[0];
                    out[el.nodes[1]] += f[1];
                }
            }
        }
        out
    }
}
