//! Contact with rigid obstacles (part of stage 4, [`super::assemble`]; the friction's work
//! is counted in stage 5, [`super::accept`]): every contact node feels the obstacle's
//! discrete-gradient penalty force and its friction over the step
//! ([`crate::obstacle`]), a nodal term like drag. The penalty energy is part of the
//! stored energy `V`, so without friction EM keeps `H` to round-off through impacts; the
//! friction's work is part of the dissipation `D` (and of the history's `friction`
//! column). Under the elastic-stick law each contact node's anchor is part of the state:
//! the step's forces use the anchors at its start, and [`Simulation::advance`] writes the
//! returned ones into the state it produces. A scene without obstacles pays nothing.

use super::Simulation;
use crate::integrator::dofs::NONE;
use crate::model::Vec3;
use crate::obstacle::{Anchor, NodeContact};

impl Simulation {
    /// Slots of the `(u, u)` block of every contact node, per obstacle.
    pub(super) fn contact_slots(&self) -> Vec<Vec<[[usize; 3]; 3]>> {
        self.model
            .obstacles
            .iter()
            .map(|o| {
                o.nodes
                    .iter()
                    .map(|n| {
                        let ix = self.dofs.nodes[n.node].u;
                        std::array::from_fn(|c| {
                            std::array::from_fn(|d| {
                                if ix[c] == NONE || ix[d] == NONE {
                                    NONE
                                } else {
                                    self.solver.slot(ix[c], ix[d])
                                }
                            })
                        })
                    })
                    .collect()
            })
            .collect()
    }

    /// The force of every obstacle on every one of its nodes over the step at `q` (a
    /// moving obstacle: the node's motion relative to it, `x − p(t)` at both ends).
    fn contact_forces(&self, q: &[f64], jacobian: bool) -> Vec<Vec<NodeContact>> {
        let dt = self.params.dt;
        let t = self.state.t;
        self.model
            .obstacles
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let (p0, p1) = (o.offset(t), o.offset(t + dt));
                let anchors = self.state.anchors.get(i).map_or(&[][..], |a| &a[..]);
                o.nodes
                    .iter()
                    .enumerate()
                    .map(|(k, n)| {
                        let (u, _) = self.node_increment(n.node, q);
                        let x0 = self.state.r[n.node];
                        let a = anchors.get(k).and_then(Option::as_ref);
                        o.node_force(n, &(x0 - p0), &(x0 + u - p1), dt, jacobian, a)
                    })
                    .collect()
            })
            .collect()
    }

    /// The elastic-stick anchors after the step at `q` (per obstacle and contact node;
    /// empty lists for obstacles without the stick law).
    pub(super) fn contact_anchors(&self, q: &[f64]) -> Vec<Vec<Option<Anchor>>> {
        if !self.model.obstacles.iter().any(|o| o.has_anchors()) {
            return vec![Vec::new(); self.model.obstacles.len()];
        }
        self.model
            .obstacles
            .iter()
            .zip(self.contact_forces(q, false))
            .map(|(o, fs)| {
                if o.has_anchors() {
                    fs.iter().map(|f| f.anchor).collect()
                } else {
                    Vec::new()
                }
            })
            .collect()
    }

    /// Work the moving obstacles do over the step at `q`: `Σ F·Δp` over their nodes (the
    /// penalty energy changes by `−F_n·(Δx − Δp)`, the friction takes `−f·(Δx − Δp)`, so
    /// `ΔH = W − D` holds with this work in `W`). Zero for fixed obstacles.
    pub(super) fn obstacle_work(&self, q: &[f64]) -> f64 {
        if self.model.obstacles.iter().all(|o| o.motion.is_none()) {
            return 0.0;
        }
        let (t, dt) = (self.state.t, self.params.dt);
        self.model
            .obstacles
            .iter()
            .zip(self.contact_forces(q, false))
            .filter(|(o, _)| o.motion.is_some())
            .map(|(o, fs)| {
                let dp = o.offset(t + dt) - o.offset(t);
                fs.iter().map(|f| f.force.dot(&dp)).sum::<f64>()
            })
            .sum()
    }

    /// Adds the contact rows (`−F`), row scales and, with `tangent`, the `(u, u)` blocks.
    pub(super) fn add_contact_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        if self.model.obstacles.is_empty() {
            return;
        }
        if self.contact_slots.is_empty() {
            self.contact_slots = self.contact_slots();
        }
        let forces = self.contact_forces(q, tangent);
        let vals = self.solver.values_mut();
        for ((o, fs), slots) in self
            .model
            .obstacles
            .iter()
            .zip(&forces)
            .zip(&self.contact_slots)
        {
            for ((n, f), s) in o.nodes.iter().zip(fs).zip(slots) {
                let ix = self.dofs.nodes[n.node].u;
                for c in 0..3 {
                    if ix[c] == NONE {
                        continue;
                    }
                    r[ix[c]] -= f.force[c];
                    scale[0] = scale[0].max(f.force[c].abs());
                    if tangent {
                        for d in 0..3 {
                            if s[c][d] != NONE {
                                vals[s[c][d]] -= f.jacobian[(c, d)];
                            }
                        }
                    }
                }
            }
        }
    }

    /// Energy friction (against obstacles and between rods) takes out over the step at
    /// `q` (≥ 0).
    pub(super) fn contact_friction_work(&self, q: &[f64]) -> f64 {
        if !self.model.has_friction() {
            return 0.0;
        }
        self.contact_forces(q, false)
            .iter()
            .flatten()
            .map(|f| f.friction_work)
            .sum::<f64>()
            + self.rod_friction_work(q)
    }

    /// Contact force on every node at `q` (zero without obstacles).
    pub(super) fn contact_node_forces(&self, q: &[f64]) -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); self.model.n_nodes()];
        if !self.model.obstacles.is_empty() {
            for (o, fs) in self
                .model
                .obstacles
                .iter()
                .zip(self.contact_forces(q, false))
            {
                for (n, f) in o.nodes.iter().zip(fs) {
                    out[n.node] += f.force;
                }
            }
        }
        out
    }
}
