//! The time loop: step until `t_end` or the first step that cannot be accepted, hand
//! every accepted level to an observer, and report how the run ended. A failed step is a
//! *result* (status `failed`, reason, residual history), not an error.

use std::time::Instant;

use crate::integrator::evaluate::now;
use crate::integrator::invariants::Invariants;
use crate::integrator::record::{RunStatus, StepRecord};
use crate::integrator::Simulation;

/// How a run ended and what it measured along the way.
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutcome {
    /// Completed or failed.
    pub status: RunStatus,
    /// Time of the last accepted step.
    pub t_reached: f64,
    /// Accepted steps.
    pub steps: usize,
    /// Failure reason.
    pub reason: Option<String>,
    /// Relative residual history of the failing step.
    pub failed_step_residuals: Vec<f64>,
    /// Total Newton iterations.
    pub newton_iters_total: usize,
    /// Largest per-step change of L relative to the momentum scale.
    pub max_rel_dl: f64,
    /// Largest per-step change of J relative to the angular momentum scale.
    pub max_rel_dj: f64,
    /// Initial H.
    pub energy_initial: f64,
    /// Final H.
    pub energy_final: f64,
    /// Wall time of the loop.
    pub wall_s: f64,
    /// Largest rigid-link strain `|g|` over the accepted steps.
    pub max_link_g: f64,
    /// Where the simulation's Newton time went (whole life of the simulation).
    pub timers: crate::integrator::SolveTimers,
    /// Accepted steps that needed the monolithic fallback.
    pub fallback_steps: usize,
    /// Accepted steps redone as sub-steps (cut-back).
    pub cutback_steps: usize,
    /// Smallest sub-step Δt of a cut-back step.
    pub smallest_substep: Option<f64>,
    /// Largest energy growth and residual the acceptance checks let through.
    pub accepted: crate::integrator::record::AcceptedExtremes,
}

/// Where a run stands: the index of its last accepted step, the exact time grid
/// `t_0 + k·Δt` of its levels and the running totals of work and dissipation. The one
/// bookkeeping of [`run_async`] and of drivers that step a simulation themselves (the Python
/// bindings), so that both record the same levels and name a failed step alike.
#[derive(Clone, Copy, Debug)]
pub struct RunLog {
    t0: f64,
    dt: f64,
    step: usize,
    work_total: f64,
    dissipation_total: f64,
}

impl RunLog {
    /// A run starting at the current level of `sim` (step 0, totals 0).
    pub fn new(sim: &Simulation) -> Self {
        RunLog {
            t0: sim.state().t,
            dt: sim.params().dt,
            step: 0,
            work_total: 0.0,
            dissipation_total: 0.0,
        }
    }

    /// Counts an accepted step: its index and its work and dissipation into the totals.
    pub fn accept(&mut self, rep: &crate::integrator::StepReport) {
        self.step += 1;
        self.work_total += rep.external_work;
        self.dissipation_total += rep.dissipation;
    }

    /// The index of the last accepted step (0 before any).
    pub fn step(&self) -> usize {
        self.step
    }

    /// The time of level `k` on the run's grid, `t_0 + k·Δt`.
    pub fn time(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    /// The record of the current level of `sim` (`rep`: the step that reached it), on the
    /// time grid and with the running totals.
    pub fn record(
        &self,
        sim: &Simulation,
        rep: Option<&crate::integrator::StepReport>,
    ) -> StepRecord {
        let mut rec = record_of(sim, self.step, rep);
        rec.t = self.time(self.step);
        rec.work_total = self.work_total;
        rec.dissipation_total = self.dissipation_total;
        rec
    }

    /// The reason a run reports for a failed next step: `step k (t = a → b) failed: …`.
    pub fn failure(&self, reason: &str) -> String {
        let k = self.step + 1;
        format!(
            "step {k} (t = {:.6} → {:.6}) failed: {reason}",
            self.time(k - 1),
            self.time(k)
        )
    }
}

/// The record of the current level of `sim` (its `t` is the state's; the running totals are
/// left at 0: [`run`] fills both).
pub fn record_of(
    sim: &Simulation,
    step: usize,
    rep: Option<&crate::integrator::StepReport>,
) -> StepRecord {
    let inv = sim.invariants();
    let rep = rep.copied().unwrap_or_default();
    StepRecord {
        step,
        t: sim.state().t,
        kinetic: inv.kinetic,
        potential: inv.potential,
        total: inv.total(),
        l: inv.l,
        j: inv.j,
        dissipation: rep.dissipation,
        external_work: rep.external_work,
        support_work: rep.support_work,
        friction: rep.friction,
        work_total: 0.0,
        dissipation_total: 0.0,
        acc_trans: rep.acc_trans,
        acc_rot: rep.acc_rot,
        newton_iters: rep.newton_iters,
        outer_iters: rep.outer_iters,
        residual: rep.residual,
        max_link_g: rep.max_link_g,
        fallback: rep.fallback,
        substeps: rep.substeps,
    }
}

/// Euclidean norm without overflow of the squares (finite for every finite vector).
fn norm(v: &crate::model::Vec3) -> f64 {
    crate::math::scaled_norm(v)
}

/// The model's mass and size (the extent of its reference nodes), fixed over a run: what
/// [`momentum_scales`] measures the momenta against.
fn mass_and_size(sim: &Simulation) -> (f64, f64) {
    let m = sim.model();
    let mass: f64 = m
        .elements
        .iter()
        .map(|e| e.props.a_rho * e.props.h)
        .sum::<f64>()
        + m.point_mass.iter().sum::<f64>();
    let (lo, hi) = m.nodes.iter().fold(
        (
            crate::model::Vec3::repeat(f64::INFINITY),
            crate::model::Vec3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), x| (lo.inf(x), hi.sup(x)),
    );
    (mass, norm(&(hi - lo)).max(1e-300))
}

/// Scales against which momentum drifts are measured: `|L|` or, if the body is nearly
/// at rest in the mean, `sqrt(2 K m)`; `J` likewise times the model's size
/// (`(mass, size)` from [`mass_and_size`]).
fn momentum_scales((mass, size): (f64, f64), inv: &Invariants) -> (f64, f64) {
    // sqrt(2 K m) as a product of roots: K·m alone overflows for masses near 1e300.
    let p = (2.0 * inv.kinetic.max(0.0)).sqrt() * mass.sqrt();
    (
        norm(&inv.l).max(p).max(1e-300),
        norm(&inv.j).max(p * size).max(1e-300),
    )
}

/// Runs `sim` to its end time. `observer` sees row 0 and every accepted step (its
/// error aborts the run, e.g. a full disk); `every` thins what it sees (the last accepted
/// step is always shown). Records carry `t = t_0 + step·Δt` (not the accumulated state
/// time) and the running totals of external work and dissipation over *every* accepted
/// step, so a thinned record stream still closes the energy balance.
///
/// # Panics
/// If `sim` is attached to a lockstep batch driver (see [`run_async`]).
pub fn run<E>(
    sim: &mut Simulation,
    every: usize,
    observer: impl FnMut(&StepRecord, &Simulation) -> Result<(), E>,
) -> Result<RunOutcome, E> {
    now(run_async(sim, every, observer))
}

/// [`run`] as a future: it waits wherever a step waits on a lockstep batch driver
/// ([`Simulation::step_async`]); the batch driver polls it.
pub async fn run_async<E>(
    sim: &mut Simulation,
    every: usize,
    mut observer: impl FnMut(&StepRecord, &Simulation) -> Result<(), E>,
) -> Result<RunOutcome, E> {
    let start = Instant::now();
    let n_steps = sim.params().n_steps();
    let inv0 = sim.invariants();
    // Drifts are measured against the largest momentum scale the run reaches (a loaded
    // structure starts at rest: its initial scale is zero).
    let body = mass_and_size(sim);
    let (mut l_ref, mut j_ref) = momentum_scales(body, &inv0);
    let (mut max_dl, mut max_dj) = (0.0f64, 0.0f64);
    let dt = sim.params().dt;
    let mut log = RunLog::new(sim);
    let mut out = RunOutcome {
        status: RunStatus::Completed,
        t_reached: sim.state().t,
        steps: 0,
        reason: None,
        failed_step_residuals: vec![],
        newton_iters_total: 0,
        max_rel_dl: 0.0,
        max_rel_dj: 0.0,
        energy_initial: inv0.total(),
        energy_final: inv0.total(),
        wall_s: 0.0,
        max_link_g: 0.0,
        timers: Default::default(),
        fallback_steps: 0,
        accepted: Default::default(),
        cutback_steps: 0,
        smallest_substep: None,
    };
    if let Some(field) = crate::integrator::finite::record_non_finite(&record_of(sim, 0, None)) {
        out.status = RunStatus::Failed;
        out.reason = Some(format!(
            "the initial state has a non-finite {field}: the inputs' magnitudes overflow f64"
        ));
        out.wall_s = start.elapsed().as_secs_f64();
        return Ok(out);
    }
    observer(&log.record(sim, None), sim)?;
    let mut prev = inv0;
    let every = every.max(1);
    // The last accepted level not yet shown to the observer (thinning), with its step.
    let mut unshown: Option<(RunLog, crate::integrator::StepReport)> = None;
    for step in 1..=n_steps {
        match sim.step_async().await {
            Ok(rep) => {
                let inv = sim.invariants();
                let (ls, js) = momentum_scales(body, &inv);
                (l_ref, j_ref) = (l_ref.max(ls), j_ref.max(js));
                max_dl = max_dl.max(norm(&(inv.l - prev.l)));
                max_dj = max_dj.max(norm(&(inv.j - prev.j)));
                out.max_rel_dl = max_dl / l_ref;
                out.max_rel_dj = max_dj / j_ref;
                out.newton_iters_total += rep.newton_iters;
                out.max_link_g = out.max_link_g.max(rep.max_link_g);
                out.fallback_steps += usize::from(rep.fallback);
                if rep.substeps > 1 {
                    out.cutback_steps += 1;
                    let h = dt / rep.substeps as f64;
                    out.smallest_substep = Some(out.smallest_substep.map_or(h, |m| m.min(h)));
                }
                let (h0, h1) = (prev.total(), inv.total());
                let growth = h1 - h0 - rep.external_work;
                let href = h0.abs().max(h1.abs()).max(rep.external_work.abs());
                let acc = &mut out.accepted;
                if out.steps == 0 {
                    acc.max_energy_growth = growth;
                    acc.max_rel_energy_growth = growth / href.max(1e-300);
                } else {
                    acc.max_energy_growth = acc.max_energy_growth.max(growth);
                    acc.max_rel_energy_growth =
                        acc.max_rel_energy_growth.max(growth / href.max(1e-300));
                }
                acc.max_residual = acc.max_residual.max(rep.residual);
                log.accept(&rep);
                out.steps = step;
                out.t_reached = log.time(step);
                out.energy_final = inv.total();
                prev = inv;
                if step % every == 0 || step == n_steps {
                    observer(&log.record(sim, Some(&rep)), sim)?;
                    unshown = None;
                } else {
                    unshown = Some((log, rep));
                }
            }
            Err(f) => {
                // Keep the last accepted level in the output even when thinning.
                if let Some((at, rep)) = unshown.take() {
                    observer(&at.record(sim, Some(&rep)), sim)?;
                }
                out.status = RunStatus::Failed;
                out.reason = Some(log.failure(&f.reason));
                out.failed_step_residuals = f.residuals;
                break;
            }
        }
    }
    out.wall_s = start.elapsed().as_secs_f64();
    out.timers = sim.solve_timers();
    Ok(out)
}
