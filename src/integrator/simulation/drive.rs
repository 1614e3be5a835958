//! Driven supports (part of stage 5, [`super::accept`]): a clamp or pin whose motion
//! follows a time table moves its node by the prescribed increment (the removed unknowns
//! are not zero but that increment, [`Simulation::gather`]). The support then does work:
//! its reaction is the residual of the removed rows, `R^A` (elements, point mass
//! inertia, loads and link forces at the node), and over a step it does
//! `W_sup = Σ_removed R_i q_i`. Since every row satisfies `Σ_i R_i q_i = ΔH − W_loads (+ D)`
//! and the free rows vanish, `ΔH = W_loads + W_sup − D` closes exactly.

use super::{Mode, Simulation};
use crate::element::{
    consistent_scalars_near, kinematics, point_mass, residual_tangent, th_idx, u_idx,
};
use crate::integrator::dofs::NONE;
use crate::integrator::links;
use crate::model::Vec3;

impl Simulation {
    /// Work of the driven supports over the step at increment `q`, with the dissipation
    /// scalars of `mode` (those the step was solved with).
    pub(super) fn support_work(&self, q: &[f64], mode: Mode) -> f64 {
        if self.model.drives.is_empty() {
            return 0.0;
        }
        let k = self.consts();
        let dt = k.dt;
        let n = self.model.n_nodes();
        let mut driven = vec![None; n];
        for (i, d) in self.model.drives.iter().enumerate() {
            driven[d.node] = Some(i);
        }
        // Reaction (force, moment) of every driven node.
        let mut reaction = vec![[Vec3::zeros(); 2]; self.model.drives.len()];
        for (e, el) in self.model.elements.iter().enumerate() {
            if el.nodes.iter().all(|&a| driven[a].is_none()) {
                continue;
            }
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            let (s, kin) = match mode {
                Mode::Frozen => {
                    let s = self.frozen[e];
                    (s, kinematics(data, &st, &eps_n, &inc, s.c_nu, dt))
                }
                Mode::Consistent => {
                    let (s, _, kin) =
                        consistent_scalars_near(data, &st, &eps_n, &inc, &k, self.frozen[e].c_nu);
                    (s, kin)
                }
            };
            let ev = residual_tangent(data, &st, &kin, &s, &k, self.trans_diss, false);
            for (l, &a) in el.nodes.iter().enumerate() {
                if let Some(i) = driven[a] {
                    reaction[i][0] += ev.r.fixed_rows::<3>(u_idx(l)).into_owned();
                    reaction[i][1] += ev.r.fixed_rows::<3>(th_idx(l)).into_owned();
                }
            }
        }
        let (fl, ml) = self.follower_node_loads(q);
        let drag = self.drag_node_forces(q);
        let contact = self.contact_node_forces(q);
        let (rod_contact, rod_moment) = self.rod_contact_node_loads(q);
        let mut work = 0.0;
        for (i, d) in self.model.drives.iter().enumerate() {
            let a = d.node;
            let (u, th) = self.node_increment(a, q);
            let m = self.model.point_mass[a];
            let g = super::gather3(q, &self.dofs.nodes[a].g);
            let inertia = point_mass::inertia_force(m, &u, &self.state.v[a], &g, dt);
            let mut ru = reaction[i][0] + inertia
                - self.force[a]
                - fl[a]
                - drag[a]
                - contact[a]
                - rod_contact[a];
            let rt = reaction[i][1] - self.moment[a] - ml[a] - rod_moment[a];
            for (j, link) in self.model.links.iter().enumerate() {
                if link.node == a {
                    ru += links::bar_terms(link, self.state.lambda[j], &self.state.r[a], &u).force;
                }
            }
            let nd = &self.dofs.nodes[a];
            for c in 0..3 {
                if nd.u[c] == NONE {
                    work += ru[c] * u[c];
                }
                if nd.th[c] == NONE {
                    work += rt[c] * th[c];
                }
            }
        }
        work
    }
}
