//! Stage 5 of a step: the state a converged increment produces and its acceptance. A
//! step whose energy grows beyond the external work (energy-controlling schemes) or whose
//! dissipation identity misses its tolerance is refused, never accepted.

use super::{Mode, Simulation};
use crate::element::{consistent_scalars_near, kinematics, FrozenScalars};
use crate::integrator::invariants::{invariants, Invariants};
use crate::integrator::state::State;

impl Simulation {
    /// The state an increment produces (with the frozen scalars of `mode`), the
    /// predicted dissipation at it, and the consistent scalars.
    pub(super) fn advance(&self, q: &[f64], mode: Mode) -> (State, f64, Vec<FrozenScalars>) {
        if let Some((mut next, diss, consistent)) = self.advance_planar(q, mode) {
            let extra = self.drag_dissipation(q) + self.contact_friction_work(q);
            next.anchors = self.contact_anchors(q);
            return (next, diss + extra, consistent);
        }
        let k = self.consts();
        let dt = k.dt;
        // Triads, director velocities and strains are pushed below, element by element.
        let mut next = self.state.successor_frame(dt);
        let mut diss = 0.0;
        let mut consistent = Vec::with_capacity(self.model.elements.len());
        let mut node_done = vec![false; self.model.n_nodes()];
        for e in 0..self.model.elements.len() {
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            // On the branch of the director factor the increment was solved with.
            let (sc, loc, kin_c) =
                consistent_scalars_near(data, &st, &eps_n, &inc, &k, self.frozen[e].c_nu);
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
            next.d.push(kin.cfg1.d);
            next.vd.push(kin.vd1);
            next.eps.push(kin.eps1);
            for l in 0..2 {
                let a = self.model.elements[e].nodes[l];
                if !node_done[a] {
                    node_done[a] = true;
                    next.r[a] = kin.cfg1.r[l];
                    next.v[a] = kin.v1[l];
                }
            }
        }
        diss += self.drag_dissipation(q) + self.contact_friction_work(q);
        next.anchors = self.contact_anchors(q);
        (next, diss, consistent)
    }

    /// Work over the step at `q` of the loads (nodal, line, gravity), of the driven
    /// supports ([`Self::support_work`]) and of the moving obstacles
    /// ([`Self::obstacle_work`]).
    pub(super) fn external_work(&self, q: &[f64], mode: Mode) -> f64 {
        let mut w = 0.0;
        for a in 0..self.dofs.nodes.len() {
            // Loads at a driven support work on its prescribed motion.
            let (u, th) = self.node_increment(a, q);
            w += self.force[a].dot(&u);
            w += self.moment[a].dot(&th);
        }
        w + self.follower_work(q) + self.support_work(q, mode) + self.obstacle_work(q)
    }

    /// Checks energy and the dissipation identity of a converged increment; on success
    /// returns the new state, its invariants, D, W and the consistent scalars. A refusal
    /// carries the consistent scalars too: the staggered loop's next frozen scalars.
    pub(super) fn check(
        &self,
        q: &[f64],
        mode: Mode,
    ) -> Result<(State, Invariants, f64, f64, Vec<FrozenScalars>), Refusal> {
        let (next, diss, consistent) = self.advance(q, mode);
        match self.check_advanced(q, mode, &next, diss) {
            Ok((inv, w)) => Ok((next, inv, diss, w, consistent)),
            Err(reason) => Err(Refusal { reason, consistent }),
        }
    }

    /// The checks of [`Self::check`] on the state `next` that `q` produces, with its
    /// predicted dissipation `diss`: its invariants and W, or why it is refused.
    fn check_advanced(
        &self,
        q: &[f64],
        mode: Mode,
        next: &State,
        diss: f64,
    ) -> Result<(Invariants, f64), String> {
        check_element_turn(next)?;
        self.check_rod_pairs(&next.r)?;
        let inv = invariants(&self.model, &self.data, next);
        let w = self.external_work(q, mode);
        let (h0, h1) = (self.inv.total(), inv.total());
        // The discrete energy identity holds exactly for an exact solution; a converged
        // increment q with residual R misses it by R·q. Allow that much on top of the
        // relative tolerances: it matters only when H is tiny against the forces (a stiff
        // structure at the start of a slow load ramp, residual at its f64 floor).
        // (Device-resident Newton: summed on the device, where the residual stayed.)
        let residual_work: f64 = self.residual_work.unwrap_or_else(|| {
            self.last_residual
                .iter()
                .zip(q)
                .map(|(r, x)| (r * x).abs())
                .sum::<f64>()
        });
        self.check_energy(h0, h1, w, diss, residual_work)?;
        Ok((inv, w))
    }

    /// The step's energy checks from `H_n` = `h0`, `H_n+1` = `h1`, the external work `w`,
    /// the dissipation `diss` and the residual work Σ|R·q| of the accepted iterate: the
    /// residual resolved against the energy, no energy growth beyond the work (schemes
    /// that control the energy), and the dissipation identity `H_n − H_n+1 + W = D` where
    /// the scheme or a damping mechanism dissipates. (The host's step and a step the
    /// device ran, from its record, go through these same checks.)
    pub(super) fn check_energy(
        &self,
        h0: f64,
        h1: f64,
        w: f64,
        diss: f64,
        residual_work: f64,
    ) -> Result<(), String> {
        let href = h0.abs().max(h1.abs()).max(w.abs()).max(1e-300);
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
        let damped = self.params.scheme.controls_energy() && self.damped_model;
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
        Ok(())
    }
}

/// A converged increment the step's checks refuse: why, and the scalars consistent with it.
pub(super) struct Refusal {
    /// Which check failed, with its numbers.
    pub reason: String,
    /// The dissipation scalars consistent with the refused increment, per element.
    pub consistent: Vec<FrozenScalars>,
}

/// Largest angle (rad) between the two end triads of one element that a step may produce.
///
/// The element interpolates the directors linearly between its ends, so where the end
/// triads are turned δ apart the interpolated directors shrink by cos(δ/2), and so does
/// the element's stiffness against stretching (Γ₃ = d₃ʰ·φ′): at δ → π an element stretches
/// at almost no energy. Steps can land on that soft branch with every energy law held —
/// measured: a roll-up with EDMC-1 at Δt = 0.5 grew to 28 times its length in 20 s, and the
/// square mechanism's unit coupler (4 elements) to 77 at Δt = 0.05 and 28 at Δt = 0.01 —
/// so a step that turns any element's triads further apart than this is refused (cut-back,
/// when on, retries it in sub-steps). At 2 rad the interpolated directors have lost 46 %
/// of their length. A resolved curvature turns an element by h·κ, far less: the full
/// roll-up with 20 elements turns each by 2π/20 = 0.31 rad; under-resolved passages reach
/// 1.7 rad (the roll-up's dynamic overshoot) and are still accepted.
pub const MAX_ELEMENT_TURN: f64 = 2.0;

/// `Err` naming the first element whose end triads are turned more than
/// [`MAX_ELEMENT_TURN`] apart in `state`.
fn check_element_turn(state: &State) -> Result<(), String> {
    // δ > limit ⇔ cos δ < cos(limit): the arc cosine only for the message.
    let cos_limit = MAX_ELEMENT_TURN.cos();
    for (e, d) in state.d.iter().enumerate() {
        // cos δ = (tr(D₀ᵀ D₁) − 1)/2 for the relative rotation D₁ D₀ᵀ (the trace of
        // D₀ᵀ D₁ is the entrywise product sum of D₀ and D₁).
        let c = ((d[0].dot(&d[1]) - 1.0) / 2.0).clamp(-1.0, 1.0);
        if c < cos_limit {
            let delta = c.acos();
            return Err(format!(
                "element {e}: its end triads are turned {delta:.3} rad apart (limit {MAX_ELEMENT_TURN:.3}): the element's linear director interpolation cannot represent that (use more elements or a smaller Δt, or --cutback)"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::cay;
    use crate::model::{Mat3, Vec3};

    fn two_triads(angle: f64) -> State {
        let r = cay(&Vec3::new(0.3, -0.2, 0.5));
        // Turn the second end about an oblique axis by `angle` (Cayley: |θ| = 2 tan(angle/2)).
        let axis = Vec3::new(1.0, 2.0, -1.0).normalize();
        let turn = cay(&(axis * 2.0 * (angle / 2.0).tan()));
        State {
            t: 0.0,
            r: vec![Vec3::zeros(); 2],
            v: vec![Vec3::zeros(); 2],
            d: vec![[r, turn * r], [Mat3::identity(), Mat3::identity()]],
            vd: vec![[[Vec3::zeros(); 2]; 2]; 2],
            eps: vec![nalgebra::Vector6::zeros(); 2],
            lambda: vec![],
            anchors: vec![],
        }
    }

    #[test]
    fn element_turn_limit_names_the_element() {
        assert!(check_element_turn(&two_triads(0.31)).is_ok());
        assert!(check_element_turn(&two_triads(MAX_ELEMENT_TURN - 1e-6)).is_ok());
        let err = check_element_turn(&two_triads(MAX_ELEMENT_TURN + 1e-3)).unwrap_err();
        assert!(
            err.starts_with("element 0: its end triads are turned 2.001 rad apart (limit 2.000)"),
            "{err}"
        );
        let err = check_element_turn(&two_triads(3.0)).unwrap_err();
        assert!(err.contains("turned 3.000 rad"), "{err}");
    }

    /// The cantilever (its tip kicked) with `scheme`, and an increment `q` that moves every
    /// free node by `s · v_n Δt` (no Newton solution: the acceptance stage must judge it).
    fn crafted(scheme: crate::integrator::Scheme, s: f64) -> (super::Simulation, Vec<f64>) {
        let sc = crate::scene::load_scene("cantilever").unwrap();
        let mut params = sc.params;
        params.scheme = scheme;
        let sim = super::Simulation::new(sc.model, params).unwrap();
        let mut q = vec![0.0; sim.n_dofs()];
        let dt = sim.params.dt;
        for (a, nd) in sim.dofs.nodes.iter().enumerate() {
            for c in 0..3 {
                if nd.u[c] != crate::integrator::dofs::NONE {
                    q[nd.u[c]] = s * sim.state.v[a][c] * dt;
                }
            }
        }
        (sim, q)
    }

    #[test]
    fn a_step_whose_energy_grows_is_refused_with_its_growth() {
        // Moving the kicked nodes 3 Δt v_n in one step gives them v = 5 v_n: K grows 25×.
        let (sim, q) = crafted(crate::integrator::Scheme::Em, 3.0);
        let h0 = sim.inv.total();
        let err = sim.check(&q, super::Mode::Frozen).err().unwrap().reason;
        assert!(err.starts_with("energy grew by "), "{err}");
        let growth: f64 = err["energy grew by ".len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(growth > 20.0 * h0, "growth {growth:e} of H0 {h0:e}");
        // Newton's answer for the same step is accepted.
        let (mut sim, _) = crafted(crate::integrator::Scheme::Em, 1.0);
        assert!(sim.step().is_ok());
    }

    #[test]
    fn a_step_that_misses_the_dissipation_identity_is_refused_naming_it() {
        // EDMC-2 (α = 0.5): no displacement, and the translational corrections g = −½ v_n
        // stop the kicked tip (v_n+1 = 2u/Δt − v_n − 2g = 0). H drops by all of K while
        // the strain energy is unchanged — not the D the scheme predicts.
        let (sim, mut q) = crafted(crate::integrator::Scheme::edmc2(0.5), 0.0);
        for (a, nd) in sim.dofs.nodes.iter().enumerate() {
            for c in 0..3 {
                if nd.g[c] != crate::integrator::dofs::NONE {
                    q[nd.g[c]] = -0.5 * sim.state.v[a][c];
                }
            }
        }
        let next = sim.advance(&q, super::Mode::Frozen).0;
        let h1 = crate::integrator::invariants::invariants(&sim.model, &sim.data, &next).total();
        assert!(
            h1 < 1e-3 * sim.inv.total(),
            "the crafted step keeps H = {h1:e}"
        );
        let err = sim.check(&q, super::Mode::Frozen).err().unwrap().reason;
        assert!(
            err.starts_with("dissipation identity missed: H_n − H_n+1 + W − D = "),
            "{err}"
        );
    }

    /// Newton's increment for the first step of `scheme` on the kicked cantilever, the
    /// crafted direction `δ = v_n Δt` (free nodes), and a simulation at the start.
    fn near_solution(scheme: crate::integrator::Scheme) -> (super::Simulation, Vec<f64>, Vec<f64>) {
        let (mut solved, _) = crafted(scheme, 1.0);
        solved.step().unwrap();
        let (sim, delta) = crafted(scheme, 1.0);
        (sim, solved.prev.clone(), delta)
    }

    /// The ε for which `f(q + ε δ) = target` (secant; `f` is smooth and nearly linear in
    /// ε this close to the solution).
    fn solve_eps(f: impl Fn(f64) -> f64, target: f64) -> f64 {
        let (mut a, mut b) = (0.0, 1e-6);
        let (mut fa, mut fb) = (f(a) - target, f(b) - target);
        for _ in 0..50 {
            if fb == fa {
                break;
            }
            let c = b - fb * (b - a) / (fb - fa);
            (a, fa) = (b, fb);
            (b, fb) = (c, f(c) - target);
            if fb.abs() <= 1e-4 * target.abs() {
                break;
            }
        }
        b
    }

    fn shifted(q: &[f64], delta: &[f64], eps: f64) -> Vec<f64> {
        q.iter().zip(delta).map(|(a, d)| a + eps * d).collect()
    }

    /// The relative number a refusal message reports in its parentheses.
    fn reported_relative(err: &str) -> f64 {
        let i = err.rfind('(').unwrap();
        err[i + 1..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    }

    /// README's promise at its own level: with the default `energy_tol` (1e-9 of H_ref) an
    /// EM step whose energy grows by 2e-9 of H_ref beyond the external work is refused,
    /// one that grows by 0.5e-9 is accepted.
    #[test]
    fn energy_growth_is_refused_just_above_energy_tol_and_accepted_just_below() {
        let (sim, q0, delta) = near_solution(crate::integrator::Scheme::Em);
        assert_eq!(sim.params.energy_tol, 1e-9, "documented default");
        let rel_growth = |eps: f64| {
            let q = shifted(&q0, &delta, eps);
            let next = sim.advance(&q, super::Mode::Frozen).0;
            let h1 =
                crate::integrator::invariants::invariants(&sim.model, &sim.data, &next).total();
            let h0 = sim.inv.total();
            let w = sim.external_work(&q, super::Mode::Frozen);
            (h1 - h0 - w) / h0.abs().max(h1.abs()).max(w.abs())
        };
        // Newton's own answer grows by round-off only.
        assert!(rel_growth(0.0).abs() < 1e-13, "{:e}", rel_growth(0.0));
        for (target, refused) in [(2e-9, true), (0.5e-9, false)] {
            let eps = solve_eps(rel_growth, target);
            let q = shifted(&q0, &delta, eps);
            match sim.check(&q, super::Mode::Frozen) {
                Err(super::Refusal { reason: e, .. }) => {
                    assert!(refused, "growth {target:e} refused: {e}");
                    assert!(e.starts_with("energy grew by "), "{e}");
                    let r = reported_relative(&e);
                    assert!(
                        (r / target - 1.0).abs() < 1e-2,
                        "reported {r:e} for {target:e}"
                    );
                }
                Ok(_) => assert!(!refused, "growth {target:e} accepted"),
            }
        }
    }

    /// The dissipation identity at its own level: with the default `outer_tol` (1e-10 of
    /// H_ref) an EDMC-2 step that misses `H_n − H_n+1 + W = D` by 2e-10 of H_ref is refused,
    /// one that misses it by 0.5e-10 is accepted.
    #[test]
    fn identity_miss_is_refused_just_above_outer_tol_and_accepted_just_below() {
        let scheme = crate::integrator::Scheme::edmc2(0.5);
        let (sim, q0, delta) = near_solution(scheme);
        assert_eq!(sim.params.outer_tol, 1e-10, "documented default");
        let mode = super::Mode::Consistent;
        let rel_miss = |eps: f64| {
            let q = shifted(&q0, &delta, eps);
            let (next, diss, _) = sim.advance(&q, mode);
            let h1 =
                crate::integrator::invariants::invariants(&sim.model, &sim.data, &next).total();
            let h0 = sim.inv.total();
            let w = sim.external_work(&q, mode);
            (h0 - h1 + w - diss) / h0.abs().max(h1.abs()).max(w.abs())
        };
        assert!(rel_miss(0.0).abs() < 1e-10, "{:e}", rel_miss(0.0));
        for (target, refused) in [(2e-10, true), (-2e-10, true), (0.5e-10, false)] {
            let eps = solve_eps(rel_miss, target);
            let q = shifted(&q0, &delta, eps);
            match sim.check(&q, mode) {
                Err(super::Refusal { reason: e, .. }) => {
                    assert!(refused, "miss {target:e} refused: {e}");
                    assert!(e.starts_with("dissipation identity missed: "), "{e}");
                    let r = reported_relative(&e);
                    assert!(
                        (r / target.abs() - 1.0).abs() < 1e-2,
                        "reported {r:e} for {target:e}"
                    );
                }
                Ok(_) => assert!(!refused, "miss {target:e} accepted"),
            }
        }
    }
}
