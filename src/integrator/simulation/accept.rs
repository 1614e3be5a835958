//! Stage 5 of a step: the state a converged increment produces and its acceptance. A
//! step whose energy grows beyond the external work (energy-controlling schemes) or whose
//! dissipation identity misses its tolerance is refused, never accepted.

use super::{Mode, Simulation};
use crate::element::{consistent_scalars, kinematics, FrozenScalars};
use crate::integrator::state::State;
use crate::observe::{invariants, Invariants};

impl Simulation {
    /// The state an increment produces (with the frozen scalars of `mode`), the
    /// predicted dissipation at it, and the consistent scalars.
    pub(super) fn advance(&self, q: &[f64], mode: Mode) -> (State, f64, Vec<FrozenScalars>) {
        if let Some(planar) = self.advance_planar(q, mode) {
            return planar;
        }
        let k = self.consts();
        let dt = k.dt;
        let mut next = self.state.clone();
        next.t = self.state.t + dt;
        let mut diss = 0.0;
        let mut consistent = Vec::with_capacity(self.model.elements.len());
        let mut node_done = vec![false; self.model.n_nodes()];
        for e in 0..self.model.elements.len() {
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            let (sc, loc, kin_c) = consistent_scalars(data, &st, &eps_n, &inc, &k);
            diss += data.props.h * loc.dissipation_density(&kin_c.inputs, data.props.a_rho);
            consistent.push(sc);
            // The frozen kinematics differ from the consistent ones only through c_ν
            // (equal, e.g. always for EM: nothing to recompute).
            let kin = match mode {
                Mode::Frozen if self.frozen[e].c_nu != sc.c_nu => {
                    kinematics(data, &st, &eps_n, &inc, self.frozen[e].c_nu, dt)
                }
                _ => kin_c,
            };
            next.d[e] = kin.cfg1.d;
            next.vd[e] = kin.vd1;
            next.eps[e] = kin.eps1;
            for l in 0..2 {
                let a = self.model.elements[e].nodes[l];
                if !node_done[a] {
                    node_done[a] = true;
                    next.r[a] = kin.cfg1.r[l];
                    next.v[a] = kin.v1[l];
                }
            }
        }
        diss += self.drag_dissipation(q);
        (next, diss, consistent)
    }

    /// Work over the step at `q` of the loads (nodal, line, gravity) and of the driven
    /// supports ([`Self::support_work`]).
    pub(super) fn external_work(&self, q: &[f64], mode: Mode) -> f64 {
        let mut w = 0.0;
        for a in 0..self.dofs.nodes.len() {
            // Loads at a driven support work on its prescribed motion.
            let (u, th) = self.node_increment(a, q);
            w += self.force[a].dot(&u);
            w += self.moment[a].dot(&th);
        }
        w + self.follower_work(q) + self.support_work(q, mode)
    }

    /// Checks energy and the dissipation identity of a converged increment; on success
    /// returns the new state, its invariants, D and W.
    pub(super) fn check(
        &self,
        q: &[f64],
        mode: Mode,
    ) -> Result<(State, Invariants, f64, f64, Vec<FrozenScalars>), String> {
        let (next, diss, consistent) = self.advance(q, mode);
        let inv = invariants(&self.model, &self.data, &next);
        let w = self.external_work(q, mode);
        let (h0, h1) = (self.inv.total(), inv.total());
        let href = h0.abs().max(h1.abs()).max(w.abs()).max(1e-300);
        // The discrete energy identity holds exactly for an exact solution; a converged
        // increment q with residual R misses it by R·q. Allow that much on top of the
        // relative tolerances: it matters only when H is tiny against the forces (a stiff
        // structure at the start of a slow load ramp, residual at its f64 floor).
        let residual_work: f64 = self
            .last_residual
            .iter()
            .zip(q)
            .map(|(r, x)| (r * x).abs())
            .sum::<f64>();
        let growth = h1 - h0 - w;
        crate::integrator::scaling::check_resolved(residual_work, href)?;
        if self.params.scheme.controls_energy()
            && growth > self.params.energy_tol * href + residual_work
        {
            return Err(format!(
                "energy grew by {growth:.3e} beyond the external work ({:.3e} relative)",
                growth / href
            ));
        }
        let damped = self.params.scheme.controls_energy()
            && (self.model.has_material_damping() || self.model.has_drag());
        if self.params.scheme.is_dissipative() || damped {
            let miss = (h0 - h1 + w - diss).abs();
            if miss > self.params.outer_tol * href + residual_work {
                return Err(format!(
                    "dissipation identity missed: H_n − H_n+1 + W − D = {:.3e} ({:.3e} relative)",
                    h0 - h1 + w - diss,
                    miss / href
                ));
            }
        }
        Ok((next, inv, diss, w, consistent))
    }
}
