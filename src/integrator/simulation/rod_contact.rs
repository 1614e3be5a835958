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
            // The node pairs the pairs couple (once each): a stencil wider than its
            // element (the smooth model's) also couples nodes of one point that no
            // element joins.
            let mut couples: std::collections::HashSet<(usize, usize)> =
                std::collections::HashSet::new();
            for &(i, j) in &pairs {
                let (si, sj) = (c.points[i].weights(), c.points[j].weights());
                let wide = si.len() > 2 || sj.len() > 2;
                let live = |&(_, w): &(usize, f64)| w != 0.0;
                for (a, _) in si
                    .into_iter()
                    .chain(sj.into_iter().filter(|_| wide))
                    .filter(live)
                {
                    for (b, _) in sj
                        .into_iter()
                        .chain(si.into_iter().filter(|_| wide))
                        .filter(live)
                    {
                        couples.insert((a, b));
                    }
                }
            }
            for (a, b) in couples {
                let (na, nb) = (&self.dofs.nodes[a], &self.dofs.nodes[b]);
                // Friction also couples the rotations (its moments and the slip).
                let (ua, ub): (Vec<usize>, Vec<usize>) = if c.friction > 0.0 {
                    (
                        na.u.iter().chain(&na.th).copied().collect(),
                        nb.u.iter().chain(&nb.th).copied().collect(),
                    )
                } else {
                    (na.u.to_vec(), nb.u.to_vec())
                };
                for x in ua.iter().filter(|&&x| x != NONE) {
                    for y in ub.iter().filter(|&&y| y != NONE) {
                        if self.solver.try_slot(*x, *y).is_none() {
                            needed.insert((*x, *y));
                            needed.insert((*y, *x));
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
        for ci in 0..self.model.rod_contacts.len() {
            for pi in 0..self.rod_pairs[ci].len() {
                let (i, j) = self.rod_pairs[ci][pi];
                let c = &self.model.rod_contacts[ci];
                let f = c.pair_force(i, j, &self.state.r, &r1, tangent);
                if f.force == Vec3::zeros() && !tangent {
                    continue;
                }
                let ends = [(i, 1.0), (j, -1.0)];
                let wts = [c.points[i].weights(), c.points[j].weights()];
                for (&(_, sp), wp) in ends.iter().zip(&wts) {
                    for &(a, wa) in wp {
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
                        for (&(_, sq), wq) in ends.iter().zip(&wts) {
                            for &(b, wb) in wq {
                                let ub = self.dofs.nodes[b].u;
                                let w = sp * sq * wa * wb;
                                if w == 0.0 {
                                    continue;
                                }
                                let blk = self.pair_block(a, b);
                                let vals = self.solver.values_mut();
                                for k in 0..3 {
                                    for l in 0..3 {
                                        if ua[k] == NONE || ub[l] == NONE {
                                            continue;
                                        }
                                        let slot = blk[k][l];
                                        assert!(slot != NONE, "contact coupling in the pattern");
                                        vals[slot] -= w * f.jacobian[(k, l)];
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// The matrix slots of the `(u, θ) × (u, θ)` block of nodes `a` (rows) and `b`
    /// (columns), `NONE` where an unknown is removed or the coupling is not in the
    /// pattern (cached until the pattern changes).
    fn pair_block(&mut self, a: usize, b: usize) -> [[usize; 6]; 6] {
        if let Some(blk) = self.node_pair_slots.get(&(a, b)) {
            return *blk;
        }
        let (na, nb) = (&self.dofs.nodes[a], &self.dofs.nodes[b]);
        let rows: [usize; 6] = std::array::from_fn(|k| if k < 3 { na.u[k] } else { na.th[k - 3] });
        let cols: [usize; 6] = std::array::from_fn(|k| if k < 3 { nb.u[k] } else { nb.th[k - 3] });
        let blk = std::array::from_fn(|k| {
            std::array::from_fn(|l| {
                if rows[k] == NONE || cols[l] == NONE {
                    NONE
                } else {
                    self.solver.try_slot(rows[k], cols[l]).unwrap_or(NONE)
                }
            })
        });
        self.node_pair_slots.insert((a, b), blk);
        blk
    }

    /// Node rotation increments at `q` (prescribed where removed).
    fn end_rotations(&self, q: &[f64]) -> Vec<Vec3> {
        (0..self.model.n_nodes())
            .map(|a| self.node_increment(a, q).1)
            .collect()
    }

    /// Nodal (force, moment) of the friction of pair `(i, j)` of contact `c` over the step
    /// to `r1`, `th`, added into `out` (local nodes by index), and its work.
    fn friction_loads(
        &self,
        c: usize,
        (i, j): (usize, usize),
        r1: &[Vec3],
        th: &[Vec3],
        out: &mut dyn FnMut(usize, Vec3, Vec3),
    ) -> f64 {
        let rc = &self.model.rod_contacts[c];
        let dt = self.params.dt;
        let Some(f) = rc.pair_friction(i, j, &self.state.r, r1, &|a| th[a], dt) else {
            return 0.0;
        };
        for (p, sp) in [(i, 1.0), (j, -1.0)] {
            for (a, wa) in rc.points[p].weights() {
                if wa != 0.0 {
                    out(a, sp * wa * f.force, wa * f.moment);
                }
            }
        }
        f.work
    }

    /// Adds the friction of the rod contacts: rows (`−F`, `−M`), scales and, with
    /// `tangent`, its Jacobian by central differences over the unknowns of the pair's
    /// (at most four) nodes.
    pub(super) fn add_rod_friction_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        if !self.model.rod_contacts.iter().any(|c| c.friction > 0.0) {
            return;
        }
        let mut r1 = self.end_positions(q);
        let mut th = self.end_rotations(q);
        for c in 0..self.model.rod_contacts.len() {
            if self.model.rod_contacts[c].friction == 0.0 {
                continue;
            }
            for pi in 0..self.rod_pairs[c].len() {
                let pair = self.rod_pairs[c][pi];
                let mut loads: Vec<(usize, Vec3, Vec3)> = Vec::new();
                self.friction_loads(c, pair, &r1, &th, &mut |a, f, m| loads.push((a, f, m)));
                if loads.is_empty() {
                    continue;
                }
                for &(a, f, m) in &loads {
                    let nd = &self.dofs.nodes[a];
                    for k in 0..3 {
                        if nd.u[k] != NONE {
                            r[nd.u[k]] -= f[k];
                            scale[0] = scale[0].max(f[k].abs());
                        }
                        if nd.th[k] != NONE {
                            r[nd.th[k]] -= m[k];
                            scale[1] = scale[1].max(m[k].abs());
                        }
                    }
                }
                if !tangent {
                    continue;
                }
                // The pair's nodes and their unknowns (u, then θ).
                let mut nodes: Vec<usize> = loads.iter().map(|l| l.0).collect();
                nodes.sort_unstable();
                nodes.dedup();
                // Central differences resolve the friction law's regularization (slip
                // increments of ε Δt) with a step well inside it.
                let rc = &self.model.rod_contacts[c];
                let h = (0.01 * rc.slip * self.params.dt).min(1e-7);
                for &b in &nodes {
                    let nb = self.dofs.nodes[b];
                    for (col, kind, comp) in (0..3)
                        .map(|k| (nb.u[k], 0, k))
                        .chain((0..3).map(|k| (nb.th[k], 1, k)))
                    {
                        if col == NONE {
                            continue;
                        }
                        let mut diff: Vec<(usize, Vec3, Vec3)> = Vec::new();
                        for sign in [1.0, -1.0] {
                            if kind == 0 {
                                r1[b][comp] += sign * h;
                            } else {
                                th[b][comp] += sign * h;
                            }
                            self.friction_loads(c, pair, &r1, &th, &mut |a, f, m| {
                                diff.push((a, sign * f / (2.0 * h), sign * m / (2.0 * h)))
                            });
                            if kind == 0 {
                                r1[b][comp] -= sign * h;
                            } else {
                                th[b][comp] -= sign * h;
                            }
                        }
                        let lc = kind * 3 + comp;
                        for (a, df, dm) in diff {
                            let na = self.dofs.nodes[a];
                            let blk = self.pair_block(a, b);
                            let vals = self.solver.values_mut();
                            for k in 0..3 {
                                for (row, lr, v) in [(na.u[k], k, df[k]), (na.th[k], 3 + k, dm[k])]
                                {
                                    if row == NONE {
                                        continue;
                                    }
                                    let slot = blk[lr][lc];
                                    assert!(slot != NONE, "friction coupling in the pattern");
                                    vals[slot] -= v;
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Energy the friction between rods takes out over the step at `q` (≥ 0).
    pub(super) fn rod_friction_work(&self, q: &[f64]) -> f64 {
        if !self.model.rod_contacts.iter().any(|c| c.friction > 0.0) {
            return 0.0;
        }
        let (r1, th) = (self.end_positions(q), self.end_rotations(q));
        let mut work = 0.0;
        for (c, pairs) in self.rod_pairs.iter().enumerate() {
            for &pair in pairs {
                work += self.friction_loads(c, pair, &r1, &th, &mut |_, _, _| {});
            }
        }
        work
    }

    /// The rod-contact force and moment on every node at `q` (zero without rod contact).
    pub(super) fn rod_contact_node_loads(&self, q: &[f64]) -> (Vec<Vec3>, Vec<Vec3>) {
        let n = self.model.n_nodes();
        let (mut out, mut mom) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        if self.model.rod_contacts.is_empty() {
            return (out, mom);
        }
        let r1 = self.end_positions(q);
        let th = self.end_rotations(q);
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
        for c in 0..self.rod_pairs.len() {
            for &pair in &self.rod_pairs[c] {
                self.friction_loads(c, pair, &r1, &th, &mut |a, f, m| {
                    out[a] += f;
                    mom[a] += m;
                });
            }
        }
        (out, mom)
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
