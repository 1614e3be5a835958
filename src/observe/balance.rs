//! Energy and impulse balances of a run, accumulated step by step.
//!
//! Energy: `H_n − H_0 = W_n − D_n` with the running totals of external work and
//! dissipation (exact for EM/EDMC up to the acceptance tolerances, theory.md §3–5; for the
//! baselines the residual *is* their energy error).
//!
//! Impulse: the loads act at `t_{n+½}` (theory.md §3), so a step changes the momenta by
//! `ΔL = Δt Σ_A F^A_{n+½}` and `ΔJ = Δt Σ_A (r^A_{n+½} × F^A_{n+½} + M^A_{n+½})` plus the
//! impulse of the support and link reactions. The residual `L_n − L_0 − I_L,n` is
//! therefore round-off for a model without supports and links (EM, EDMC, mid-point), and
//! the reactions' impulse otherwise. Generalized-α applies its loads at `t_{n+1}` with its
//! own weights, so its residual also contains that difference of quadrature (and its J
//! drift). Follower line loads act with the mid-step directors `½(d_n + d_{n+1})`, the
//! same ones the step used.

use crate::element::M2;
use crate::integrator::state::State;
use crate::math::scaled_norm;
use crate::model::{Mat3, Model, Vec3};
use crate::observe::record::{EnergyBalance, ImpulseBalance};

/// Accumulates the applied impulse and the momentum residuals over accepted steps. Feed
/// it every accepted step in order ([`step`](Self::step)); thinning is not allowed (the
/// mid-point positions need consecutive levels).
#[derive(Clone, Debug)]
pub struct BalanceObserver {
    dt: f64,
    t0: f64,
    l0: Vec3,
    j0: Vec3,
    h0: f64,
    impulse_l: Vec3,
    impulse_j: Vec3,
    r_prev: Vec<Vec3>,
    /// Director triads of the previous level (only with follower loads, which act with
    /// the mid-step directors).
    d_prev: Vec<[Mat3; 2]>,
    force: Vec<Vec3>,
    moment: Vec<Vec3>,
    last_step: usize,
    scale_l: f64,
    scale_j: f64,
    impulse: ImpulseBalance,
    energy: EnergyBalance,
}

impl BalanceObserver {
    /// Starts at the initial level: its state, momenta `l0`, `j0` and energy `h0`.
    pub fn new(model: &Model, state: &State, dt: f64, l0: Vec3, j0: Vec3, h0: f64) -> Self {
        let n = model.n_nodes();
        let reactions = model.supports.iter().any(|s| s.translation || s.rotation)
            || !model.links.is_empty()
            || !model.obstacles.is_empty();
        Self {
            dt,
            t0: state.t,
            l0,
            j0,
            h0,
            impulse_l: Vec3::zeros(),
            impulse_j: Vec3::zeros(),
            r_prev: state.r.clone(),
            d_prev: if model.has_follower_loads() {
                state.d.clone()
            } else {
                Vec::new()
            },
            force: vec![Vec3::zeros(); n],
            moment: vec![Vec3::zeros(); n],
            last_step: 0,
            scale_l: scaled_norm(&l0),
            scale_j: scaled_norm(&j0),
            impulse: ImpulseBalance {
                rule: "ΔL = Δt Σ F(t_{n+½}), ΔJ = Δt Σ (r_{n+½} × F(t_{n+½}) + M(t_{n+½}))".into(),
                reactions,
                ..Default::default()
            },
            energy: EnergyBalance {
                energy_initial: h0,
                energy_final: h0,
                ..Default::default()
            },
        }
    }

    /// Adds accepted step `step` (the level `state` with momenta `l`, `j`, energy `h`, and
    /// the running totals of work and dissipation after it).
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        model: &Model,
        state: &State,
        step: usize,
        l: Vec3,
        j: Vec3,
        h: f64,
        work_total: f64,
        dissipation_total: f64,
    ) {
        debug_assert_eq!(step, self.last_step + 1, "balance needs every step");
        let t_mid = self.t0 + (step as f64 - 0.5) * self.dt;
        model.external_loads(t_mid, &mut self.force, &mut self.moment);
        if model.has_follower_loads() {
            let d_mid: Vec<[Mat3; 2]> = self
                .d_prev
                .iter()
                .zip(&state.d)
                .map(|(a, b)| [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])])
                .collect();
            model.follower_loads(t_mid, &d_mid, &mut self.force, &mut self.moment);
            self.d_prev.clone_from(&state.d);
        }
        // Drag: −(c h/Δt) M2 (r_{n+1} − r_n) on the element ends, an external force.
        for el in model.elements.iter().filter(|e| e.props.drag != 0.0) {
            let k = el.props.drag * el.props.h / self.dt;
            let du = [
                state.r[el.nodes[0]] - self.r_prev[el.nodes[0]],
                state.r[el.nodes[1]] - self.r_prev[el.nodes[1]],
            ];
            for l in 0..2 {
                let f = -(du[0] * M2[l][0] + du[1] * M2[l][1]) * k;
                self.force[el.nodes[l]] += f;
            }
        }
        for (a, (f, m)) in self.force.iter().zip(&self.moment).enumerate() {
            let r_mid = 0.5 * (self.r_prev[a] + state.r[a]);
            self.impulse_l += self.dt * f;
            self.impulse_j += self.dt * (r_mid.cross(f) + m);
        }
        self.r_prev.copy_from_slice(&state.r);
        self.last_step = step;
        self.scale_l = self
            .scale_l
            .max(scaled_norm(&l))
            .max(scaled_norm(&self.impulse_l));
        self.scale_j = self
            .scale_j
            .max(scaled_norm(&j))
            .max(scaled_norm(&self.impulse_j));

        let res_l = l - self.l0 - self.impulse_l;
        let res_j = j - self.j0 - self.impulse_j;
        let b = &mut self.impulse;
        b.steps = step;
        b.change_l = (l - self.l0).into();
        b.change_j = (j - self.j0).into();
        b.applied_impulse_l = self.impulse_l.into();
        b.applied_impulse_j = self.impulse_j.into();
        b.residual_l = res_l.into();
        b.residual_j = res_j.into();
        if scaled_norm(&res_l) > b.max_residual_l {
            b.max_residual_l = scaled_norm(&res_l);
            b.max_residual_l_step = step;
        }
        if scaled_norm(&res_j) > b.max_residual_j {
            b.max_residual_j = scaled_norm(&res_j);
            b.max_residual_j_step = step;
        }
        b.max_rel_residual_l = b.max_residual_l / self.scale_l.max(1e-300);
        b.max_rel_residual_j = b.max_residual_j / self.scale_j.max(1e-300);

        let e = &mut self.energy;
        e.energy_final = h;
        e.work_total = work_total;
        e.dissipation_total = dissipation_total;
        let res = h - self.h0 - work_total + dissipation_total;
        e.residual = res;
        if res.abs() > e.max_abs_residual {
            e.max_abs_residual = res.abs();
            e.max_abs_residual_step = step;
        }
        let scale = self
            .h0
            .abs()
            .max(h.abs())
            .max(work_total.abs())
            .max(dissipation_total.abs())
            .max(1e-300);
        e.max_rel_residual = e.max_rel_residual.max(res.abs() / scale);
    }

    /// The impulse balance so far.
    pub fn impulse(&self) -> &ImpulseBalance {
        &self.impulse
    }

    /// The energy balance so far.
    pub fn energy(&self) -> &EnergyBalance {
        &self.energy
    }
}
