//! Contact between rods and of a rod with itself (part of stage 4, [`super::assemble`];
//! the pair search runs once per step in stage 1, [`super::step`], and its completeness is
//! checked in stage 5, [`super::accept`]). Each `[[contact]]` is a chain of contact spheres
//! per rod ([`crate::rod_contact`]); a pair's discrete-gradient force is a nodal term that
//! couples the four nodes of its two elements, so the first time two elements come close
//! their couplings are added to the linear system's pattern (which then only grows). A
//! scene without `[[contact]]` pays nothing.

use std::collections::BTreeSet;

use super::Simulation;
use crate::integrator::dofs::NONE;
use crate::model::Vec3;

impl Simulation {
    /// The pairs of every rod contact that the coming step considers: those closer than
    /// their contact distance plus a reach of three times the largest nodal increment of
    /// the predictor plus a quarter of the largest contact radius (`check` refuses a step
    /// that brought another pair into contact). Adds the pairs' node couplings to the
    /// linear system's pattern where they are new. Runs once per state.
    pub(super) fn refresh_rod_pairs(&mut self) -> Result<(), String> {
        if self.model.rod_contacts.is_empty() || self.rod_pairs_version == Some(self.state_version)
        {
            return Ok(());
        }
        let umax = self
            .dofs
            .nodes
            .iter()
            .map(|nd| super::gather3(&self.prev, &nd.u).norm())
            .fold(0.0f64, f64::max);
        let mut needed: BTreeSet<(usize, usize)> = BTreeSet::new();
        let mut lists = Vec::with_capacity(self.model.rod_contacts.len());
        for c in &self.model.rod_contacts {
            let reach = 3.0 * umax + 0.25 * c.max_radius();
            let pairs = c.candidates(&self.state.r, reach);
            for &(i, j) in &pairs {
                for (a, wa) in c.points[i].weights() {
                    for (b, wb) in c.points[j].weights() {
                        if wa == 0.0 || wb == 0.0 {
                            continue;
                        }
                        let (ua, ub) = (self.dofs.nodes[a].u, self.dofs.nodes[b].u);
                        for x in ua.iter().filter(|&&x| x != NONE) {
                            for y in ub.iter().filter(|&&y| y != NONE) {
                                if self.solver.try_slot(*x, *y).is_none() {
                                    needed.insert((*x, *y));
                                    needed.insert((*y, *x));
                                }
                            }
                        }
                    }
                }
            }
            lists.push(pairs);
        }
        if !needed.is_empty() {
            let mut extra: BTreeSet<(usize, usize)> = self.extra_pattern.iter().copied().collect();
            extra.extend(needed);
            self.rebuild_pattern(extra.into_iter().collect())
                .map_err(|e| {
                    format!("contact: the linear system could not take the new couplings: {e}")
                })?;
        }
        self.rod_pairs = lists;
        self.rod_pairs_version = Some(self.state_version);
        Ok(())
    }

    /// Node positions at the end of the step at `q`.
    fn end_positions(&self, q: &[f64]) -> Vec<Vec3> {
        (0..self.model.n_nodes())
            .map(|a| self.state.r[a] + self.node_increment(a, q).0)
            .collect()
    }

    /// Adds the rod-contact rows (`−F`), row scales and, with `tangent`, the couplings.
    pub(super) fn add_rod_contact_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        if self.model.rod_contacts.is_empty() {
            return;
        }
        let r1 = self.end_positions(q);
        let r0 = &self.state.r;
        for (c, pairs) in self.model.rod_contacts.iter().zip(&self.rod_pairs) {
            for &(i, j) in pairs {
                let f = c.pair_force(i, j, r0, &r1, tangent);
                if f.force == Vec3::zeros() && !tangent {
                    continue;
                }
                let ends = [(i, 1.0), (j, -1.0)];
                for &(p, sp) in &ends {
                    for (a, wa) in c.points[p].weights() {
                        let ua = self.dofs.nodes[a].u;
                        for k in 0..3 {
                            if ua[k] == NONE {
                                continue;
                            }
                            let fa = sp * wa * f.force[k];
                            r[ua[k]] -= fa;
                            scale[0] = scale[0].max(fa.abs());
                        }
                        if !tangent || f.jacobian == nalgebra::Matrix3::zeros() {
                            continue;
                        }
                        for &(p2, sq) in &ends {
                            for (b, wb) in c.points[p2].weights() {
                                let ub = self.dofs.nodes[b].u;
                                let w = sp * sq * wa * wb;
                                if w == 0.0 {
                                    continue;
                                }
                                for k in 0..3 {
                                    for l in 0..3 {
                                        if ua[k] == NONE || ub[l] == NONE {
                                            continue;
                                        }
                                        let slot = self
                                            .solver
                                            .try_slot(ua[k], ub[l])
                                            .expect("contact coupling in the pattern");
                                        self.solver.values_mut()[slot] -= w * f.jacobian[(k, l)];
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// The rod-contact force on every node at `q` (zero without rod contact).
    pub(super) fn rod_contact_node_forces(&self, q: &[f64]) -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); self.model.n_nodes()];
        if self.model.rod_contacts.is_empty() {
            return out;
        }
        let r1 = self.end_positions(q);
        for (c, pairs) in self.model.rod_contacts.iter().zip(&self.rod_pairs) {
            for &(i, j) in pairs {
                let f = c.pair_force(i, j, &self.state.r, &r1, false).force;
                for (p, sp) in [(i, 1.0), (j, -1.0)] {
                    for (a, wa) in c.points[p].weights() {
                        out[a] += sp * wa * f;
                    }
                }
            }
        }
        out
    }

    /// `Err` when the state `next` puts a pair in contact that the step did not consider
    /// (a node moved farther than the pair search's reach).
    pub(super) fn check_rod_pairs(&self, next: &[Vec3]) -> Result<(), String> {
        for (c, pairs) in self.model.rod_contacts.iter().zip(&self.rod_pairs) {
            for (i, j) in c.candidates(next, 0.0) {
                if pairs.binary_search(&(i, j)).is_err() {
                    return Err(format!(
                        "contact {}: sample points {i} and {j} came into contact during the step but were beyond the pair search's reach (nodes moved farther than the reach: use a smaller Δt or --cutback)",
                        c.rods.join("–")
                    ));
                }
            }
        }
        Ok(())
    }
}
