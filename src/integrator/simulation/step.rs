//! Stage 1 of a step: the loads at the mid-step, the Newton predictors (the previous
//! step's increment, then zero), and the augmented-Lagrangian rounds of rigid links, each
//! round a complete checked solve ([`super::strategy`]) with the multipliers fixed. The
//! generalized-α baseline steps through its own Newton loop instead.

use super::{Backend, Mode, Simulation};
use crate::integrator::evaluate::now;
use crate::integrator::invariants::{acceleration_norms, invariants};
use crate::integrator::report::{StepFailure, StepReport};
use crate::integrator::{finite, links};
use crate::model::Vec3;

impl Simulation {
    /// Advances one step of Δt. On failure the state is left at the last accepted step.
    ///
    /// # Panics
    /// If the simulation is attached to a lockstep batch driver
    /// ([`Simulation::set_port`]): such a simulation is stepped by its driver through
    /// [`Self::step_async`].
    pub fn step(&mut self) -> Result<StepReport, StepFailure> {
        now(self.step_async())
    }

    /// [`Self::step`] as a future that waits wherever the element evaluation is posted to
    /// a lockstep batch driver (on the CPU kernel or a direct backend it never waits).
    pub async fn step_async(&mut self) -> Result<StepReport, StepFailure> {
        // `--solve whole`: the whole step on the device where it covers it.
        if self.device_steps {
            if let Some(out) = self.device_step().await {
                return out;
            }
        }
        let fail = match self.step_at_dt().await {
            Ok(rep) => return Ok(rep),
            Err(f) => f,
        };
        let cutback = self.params.cutback;
        if cutback == 0 || self.gen_alpha.is_some() || !matches!(self.backend, Backend::Cpu) {
            return Err(fail);
        }
        // Cut-back: redo the step as 2, 4, … 2^cutback complete sub-steps.
        let dt = self.params.dt;
        let saved = (
            self.state.clone(),
            self.inv,
            self.prev.clone(),
            self.frozen.clone(),
        );
        for k in 1..=cutback.min(20) {
            let n = 1usize << k;
            self.params.dt = dt / n as f64;
            self.prev.iter_mut().for_each(|x| *x /= n as f64);
            let mut agg = StepReport {
                substeps: n,
                ..StepReport::default()
            };
            let mut ok = true;
            for _ in 0..n {
                match self.step_at_dt().await {
                    Ok(r) => {
                        agg.newton_iters += r.newton_iters;
                        agg.outer_iters = agg.outer_iters.max(r.outer_iters);
                        agg.residual = agg.residual.max(r.residual);
                        agg.dissipation += r.dissipation;
                        agg.external_work += r.external_work;
                        agg.support_work += r.support_work;
                        agg.friction += r.friction;
                        agg.acc_trans = agg.acc_trans.max(r.acc_trans);
                        agg.acc_rot = agg.acc_rot.max(r.acc_rot);
                        agg.max_link_g = agg.max_link_g.max(r.max_link_g);
                        agg.link_rounds = agg.link_rounds.max(r.link_rounds);
                        agg.fallback |= r.fallback;
                    }
                    Err(_) => {
                        ok = false;
                        break;
                    }
                }
            }
            self.params.dt = dt;
            if ok {
                // The next full step predicts from a full-step increment.
                self.prev.iter_mut().for_each(|x| *x *= n as f64);
                self.state.t = saved.0.t + dt;
                return Ok(agg);
            }
            (self.state, self.inv, self.prev, self.frozen) = saved.clone();
            self.state_version += 1;
        }
        Err(StepFailure {
            reason: format!(
                "{} (cut back to {} sub-steps, it failed too)",
                fail.reason,
                1usize << cutback.min(20)
            ),
            residuals: fail.residuals,
        })
    }

    /// One step of the current Δt (no cut-back).
    async fn step_at_dt(&mut self) -> Result<StepReport, StepFailure> {
        if self.gen_alpha.is_some() {
            if !self.model.links.is_empty() {
                // The baseline has no augmented-Lagrangian treatment of rigid links;
                // ignoring them would simulate a different mechanism.
                return Err(StepFailure {
                    reason: "gen-alpha does not support rigid links ([[link]]); use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            if !self.model.drives.is_empty() {
                return Err(StepFailure {
                    reason: "gen-alpha does not support moving supports; use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            if self.model.has_material_damping() || self.model.has_drag() {
                return Err(StepFailure {
                    reason: "gen-alpha does not support material damping or drag; use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            if !self.model.obstacles.is_empty() || !self.model.rod_contacts.is_empty() {
                return Err(StepFailure {
                    reason: "gen-alpha does not support contact ([[obstacle]], [[contact]]); use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            if self.model.has_follower_loads() {
                return Err(StepFailure {
                    reason: "gen-alpha does not support follower loads ([[line_load]] follower = true); use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            return self.step_gen_alpha();
        }
        self.fell_back = false;
        self.mid_step_loads();
        if let Err(reason) = self.refresh_rod_pairs() {
            return Err(StepFailure {
                reason,
                residuals: vec![],
            });
        }

        let mut predictors = vec![self.prev.clone()];
        if self.prev.iter().any(|&x| x != 0.0) {
            predictors.push(vec![0.0; self.dofs.n]);
        }
        let mut total_iters = 0;
        let mut last = StepFailure {
            reason: "no attempt".into(),
            residuals: vec![],
        };
        let (lambda0, inv0) = (self.state.lambda.clone(), self.inv);
        // Each predictor starts from the step's scalars (a monolithic solve moves the
        // director factors along its iterates).
        let frozen0 = self.frozen.clone();
        self.step_start = true;
        let n_predictors = predictors.len();
        for (k, pred) in predictors.into_iter().enumerate() {
            self.last_predictor = k + 1 == n_predictors;
            if k > 0 {
                self.frozen.clone_from(&frozen0);
            }
            let mut q = pred;
            let mut multipliers = links::MultiplierIteration::default();
            // Augmented-Lagrangian rounds (a single round without links): each round is a
            // complete, checked solve with the multipliers fixed, so the energy identity of
            // every round is exact; the multipliers move between rounds until every link
            // holds its tolerance.
            for round in 1..=self.params.max_link_rounds.max(1) {
                let (next, inv, diss, w, outer, res, consistent) = match self
                    .solve_with_fixed_multipliers(&mut q, &mut total_iters)
                    .await
                {
                    Ok(x) => x,
                    Err(f) => {
                        last = f;
                        break;
                    }
                };
                let g1: Vec<f64> = self
                    .model
                    .links
                    .iter()
                    .map(|l| l.strain(&next.r[l.node]))
                    .collect();
                let max_link_g = g1.iter().fold(0.0f64, |m, g| m.max(g.abs()));
                // The driven supports' share of W, with the scalars the step was solved
                // with (frozen, unless the monolithic strategy, its fallback or an inexact
                // solve on its floor accepted it).
                let mode = if self.params.scheme.is_dissipative() && self.solved_consistent {
                    Mode::Consistent
                } else {
                    Mode::Frozen
                };
                let support_work = self.support_work(&q, mode) + self.obstacle_work(&q);
                let friction = self.contact_friction_work(&q);
                if multipliers.update(&self.model.links, &g1, &mut self.state.lambda) {
                    let (at, ar) = acceleration_norms(&self.model, &self.data, &self.state, &next);
                    let report = StepReport {
                        newton_iters: total_iters,
                        outer_iters: outer,
                        residual: res,
                        dissipation: diss,
                        external_work: w,
                        support_work,
                        friction,
                        acc_trans: at,
                        acc_rot: ar,
                        max_link_g,
                        link_rounds: round,
                        fallback: self.fell_back,
                        substeps: 1,
                    };
                    if let Err(f) = finite::check_step(&next, &inv, &report) {
                        self.state.lambda.clone_from(&lambda0);
                        self.inv = inv0;
                        return Err(f);
                    }
                    // `--solve whole`: the device's last evaluated iterate is `q` (it ran
                    // this step's Newton solve and the step needed no fallback), so its
                    // state advances by it as this one does.
                    // (Not where a dissipative scheme accepted it with the consistent
                    // scalars: the advance pass forms the frozen-scalar kinematics.)
                    self.advanced_version = (self.device_advance
                        && self.device_resident()
                        && !self.fell_back
                        && !(self.params.scheme.is_dissipative() && self.solved_consistent)
                        && self.sent_version == Some(self.state_version))
                    .then_some(self.state_version + 1);
                    self.state = next;
                    self.state_version += 1;
                    self.inv = inv;
                    self.prev = q;
                    self.frozen = consistent;
                    return Ok(report);
                }
                // H_n with the new multipliers: the next round's energy identity is
                // measured against it.
                self.inv = invariants(&self.model, &self.data, &self.state);
                last = StepFailure {
                    reason: format!(
                        "augmented Lagrangian: links still violated after {round} rounds (max |g| = {max_link_g:.3e})"
                    ),
                    residuals: vec![res],
                };
            }
            self.state.lambda.clone_from(&lambda0);
            self.inv = inv0;
        }
        Err(last)
    }

    /// A generalized-α step (loads at `t_{n+1}`; no energy acceptance check: the scheme
    /// does not control energy).
    pub(super) fn step_gen_alpha(&mut self) -> Result<StepReport, StepFailure> {
        let p = self.params;
        let nn = self.model.n_nodes();
        let mut loads = [(); 2].map(|_| (vec![Vec3::zeros(); nn], vec![Vec3::zeros(); nn]));
        for (k, (f, m)) in loads.iter_mut().enumerate() {
            self.model
                .external_loads(self.state.t + k as f64 * p.dt, f, m);
        }
        let Some(ga) = self.gen_alpha.as_mut() else {
            unreachable!("step_gen_alpha without generalized-α state");
        };
        let out = ga.step(
            &self.model,
            &self.data,
            &self.state,
            p.dt,
            p.newton_tol,
            p.max_iter,
            (&loads[0].0, &loads[0].1),
            (&loads[1].0, &loads[1].1),
        )?;
        let (at, ar) = acceleration_norms(&self.model, &self.data, &self.state, &out.state);
        let inv = invariants(&self.model, &self.data, &out.state);
        let report = StepReport {
            newton_iters: out.newton_iters,
            outer_iters: 1,
            residual: out.residual,
            dissipation: 0.0,
            external_work: out.external_work,
            support_work: 0.0,
            friction: 0.0,
            acc_trans: at,
            acc_rot: ar,
            max_link_g: 0.0,
            link_rounds: 1,
            fallback: false,
            substeps: 1,
        };
        finite::check_step(&out.state, &inv, &report)?;
        self.inv = inv;
        self.state = out.state;
        self.state_version += 1;
        Ok(report)
    }

    /// The external loads at the middle of the coming step and the prescribed motion of
    /// driven supports over it (the step uses them; so do the test entry points of
    /// `probe`).
    pub(super) fn mid_step_loads(&mut self) {
        let t_mid = self.state.t + 0.5 * self.params.dt;
        let (mut f, mut m) = (
            std::mem::take(&mut self.force),
            std::mem::take(&mut self.moment),
        );
        self.model.external_loads(t_mid, &mut f, &mut m);
        self.force = f;
        self.moment = m;
        let t = self.state.t;
        for p in &mut self.prescribed {
            *p = [Vec3::zeros(); 2];
        }
        for d in &self.model.drives {
            let (u, th) = d.increment(t, t + self.params.dt);
            self.prescribed[d.node] = [u, th];
        }
        self.commanded_increments(t, self.params.dt);
    }
}
