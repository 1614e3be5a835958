//! Follower line loads inside a step (part of stage 4, [`super::assemble`]): on every
//! element end the load is `(h/2) f(t_{n+½}) Σ_i f_i d_{i,n+½}` with the end's mid-step
//! directors `d_{n+½} = ½(d_n + cay(θ) d_n)`, so it depends on the rotation increment of
//! the end's node. Its residual rows, its tangent (`∂d_{n+½}/∂θ = −½ A(θ) \hat{d_{n+½}}`,
//! `A = (I − ½θ̂)⁻¹`) and its work `F·u + M·θ` all come from the same expression, so
//! the energy balance of a converged step closes with that work.

use super::Simulation;
use crate::element::follower::{mid_directors, EndLoad};
use crate::integrator::dofs::NONE;
use crate::model::{Mat3, Vec3};

/// The load of a follower line load on one element end from the end's directors at `n`
/// and its node's rotation increment `θ` ([`crate::element::follower::end_load`]).
fn end_load(d_n: &Mat3, theta: &Vec3, f: &Vec3, m: &Vec3, w: f64, tangent: bool) -> EndLoad {
    let (half, a) = mid_directors(d_n, theta);
    crate::element::follower::end_load(&half, &a, f, m, w, tangent)
}

impl Simulation {
    /// Per element, the follower line loads it carries at the middle of the coming step:
    /// force and moment per unit length in its director frame, their time tables' factors
    /// included (what the GPU element kernel adds itself: `E_FOLLOW`). Empty without
    /// follower loads.
    pub(super) fn follower_constants(&self) -> Vec<[f64; 6]> {
        if !self.model.has_follower_loads() {
            return Vec::new();
        }
        let t = self.state.t + 0.5 * self.params.dt;
        let mut out = vec![[0.0; 6]; self.model.elements.len()];
        for ll in self.model.line_loads.iter().filter(|l| l.follower) {
            let s = ll.table.eval(t);
            for &e in &ll.elements {
                for c in 0..3 {
                    out[e][c] += s * ll.force[c];
                    out[e][3 + c] += s * ll.moment[c];
                }
            }
        }
        out
    }

    /// The follower line loads per element for a request to an attached evaluator, where
    /// they differ from those it holds (a time table moved, or none went up yet). Formed
    /// once per step: the later requests of a step (same middle time) send nothing.
    pub(super) fn follower_update(&mut self) -> Option<Vec<[f64; 6]>> {
        if !self.model.has_follower_loads() {
            return None;
        }
        let t_mid = self.state.t + 0.5 * self.params.dt;
        if self
            .follower_sent
            .as_ref()
            .is_some_and(|(t, _)| *t == t_mid)
        {
            return None;
        }
        let now = self.follower_constants();
        let same = self.follower_sent.as_ref().is_some_and(|(_, f)| *f == now);
        self.follower_sent = Some((t_mid, now.clone()));
        (!same).then_some(now)
    }

    /// Adds the follower line loads' residual rows (`−F`, `−M`), row scales and, with
    /// `tangent`, their tangent blocks at increment `q`.
    pub(super) fn add_follower_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        if !self.model.has_follower_loads() {
            return;
        }
        let t = self.state.t + 0.5 * self.params.dt;
        for ll in self.model.line_loads.iter().filter(|l| l.follower) {
            let s = ll.table.eval(t);
            if s == 0.0 {
                continue;
            }
            for &e in &ll.elements {
                let el = &self.model.elements[e];
                let w = 0.5 * el.props.h * s;
                for l in 0..2 {
                    let a = el.nodes[l];
                    let nd = self.dofs.nodes[a];
                    let (_, th) = self.node_increment(a, q);
                    let x = end_load(&self.state.d[e][l], &th, &ll.force, &ll.moment, w, tangent);
                    for c in 0..3 {
                        if nd.u[c] != NONE {
                            r[nd.u[c]] -= x.force[c];
                            scale[0] = scale[0].max(x.force[c].abs());
                        }
                        if nd.th[c] != NONE {
                            r[nd.th[c]] -= x.moment[c];
                            scale[1] = scale[1].max(x.moment[c].abs());
                        }
                    }
                    if !tangent {
                        continue;
                    }
                    let slots = &self.node_block_slots[a];
                    let vals = self.solver.values_mut();
                    for c in 0..3 {
                        for k in 0..3 {
                            // Rows u_c and θ_c, column θ_k (node-local order u, θ, g).
                            for (row, dm) in [(c, &x.d_force), (3 + c, &x.d_moment)] {
                                let slot = slots[row * 9 + 3 + k];
                                if slot != NONE {
                                    vals[slot] -= dm[(c, k)];
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Nodal forces and moments of the follower line loads at increment `q` (zero without
    /// follower loads).
    pub(super) fn follower_node_loads(&self, q: &[f64]) -> (Vec<Vec3>, Vec<Vec3>) {
        let n = self.model.n_nodes();
        let (mut f, mut m) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        if !self.model.has_follower_loads() {
            return (f, m);
        }
        let t = self.state.t + 0.5 * self.params.dt;
        for ll in self.model.line_loads.iter().filter(|l| l.follower) {
            let s = ll.table.eval(t);
            for &e in &ll.elements {
                let el = &self.model.elements[e];
                let w = 0.5 * el.props.h * s;
                for l in 0..2 {
                    let a = el.nodes[l];
                    let (_, th) = self.node_increment(a, q);
                    let x = end_load(&self.state.d[e][l], &th, &ll.force, &ll.moment, w, false);
                    f[a] += x.force;
                    m[a] += x.moment;
                }
            }
        }
        (f, m)
    }

    /// Work `Σ F·u + M·θ` of the follower line loads over the step at increment `q`.
    pub(super) fn follower_work(&self, q: &[f64]) -> f64 {
        if !self.model.has_follower_loads() {
            return 0.0;
        }
        let t = self.state.t + 0.5 * self.params.dt;
        let mut work = 0.0;
        for ll in self.model.line_loads.iter().filter(|l| l.follower) {
            let s = ll.table.eval(t);
            for &e in &ll.elements {
                let el = &self.model.elements[e];
                let w = 0.5 * el.props.h * s;
                for l in 0..2 {
                    let (u, th) = self.node_increment(el.nodes[l], q);
                    let x = end_load(&self.state.d[e][l], &th, &ll.force, &ll.moment, w, false);
                    work += x.force.dot(&u) + x.moment.dot(&th);
                }
            }
        }
        work
    }
}
