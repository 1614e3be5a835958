//! The records observers produce and outputs consume.

use serde::Serialize;

use crate::integrator::params::IntegratorParams;
use crate::model::Vec3;

/// Observables of one time level (row `step` of `history.csv`; row 0 is the initial state).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepRecord {
    /// Step index (0 = initial state).
    pub step: usize,
    /// Time.
    pub t: f64,
    /// Kinetic energy K.
    pub kinetic: f64,
    /// Stored (strain) energy V.
    pub potential: f64,
    /// Total energy H = K + V.
    pub total: f64,
    /// Linear momentum L.
    pub l: Vec3,
    /// Angular momentum J about the origin.
    pub j: Vec3,
    /// Dissipation D predicted by DESIGN §4 for the step that ended here (0 at row 0).
    pub dissipation: f64,
    /// Work of the external loads over the step that ended here.
    pub external_work: f64,
    /// L2 norm over the rods of the translational acceleration (v_{n+1} − v_n)/Δt.
    pub acc_trans: f64,
    /// L2 norm over the rods of the director acceleration (director analogue).
    pub acc_rot: f64,
    /// Newton iterations spent on the step (all outer rounds together).
    pub newton_iters: usize,
    /// Outer (staggered) rounds of the step; 1 for EM and the monolithic strategy.
    pub outer_iters: usize,
    /// Final residual norm ‖R‖∞ of the step.
    pub residual: f64,
    /// Largest rigid-link strain `|g|` at this level (0 without links).
    pub max_link_g: f64,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// Reached the end time.
    Completed,
    /// Stopped at a step that could not be accepted.
    Failed,
}

/// Everything `summary.json` reports about a run.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    /// Scene name or path.
    pub scene: String,
    /// How the run ended.
    pub status: RunStatus,
    /// Time of the last accepted step.
    pub t_reached: f64,
    /// Number of accepted steps.
    pub steps: usize,
    /// Why the run failed (`None` when completed).
    pub reason: Option<String>,
    /// Residual norms of the Newton iterations of the failing step (empty when completed).
    pub failed_step_residuals: Vec<f64>,
    /// Wall-clock time of the time loop in seconds.
    pub wall_s: f64,
    /// Scheme name (`em`, `edmc1`, `edmc2`).
    pub scheme: String,
    /// All integrator parameters (scheme constants, Δt, tolerances, strategy).
    pub params: IntegratorParams,
    /// Nodes, elements and unknowns of the model.
    pub nodes: usize,
    /// Number of elements.
    pub elements: usize,
    /// Number of Newton unknowns.
    pub dofs: usize,
    /// Total Newton iterations over the run.
    pub newton_iters_total: usize,
    /// Largest relative per-step change of |L| (relative to max(|L|, scale)).
    pub max_rel_dl: f64,
    /// Largest relative per-step change of |J|.
    pub max_rel_dj: f64,
    /// H at the start and at the last accepted step.
    pub energy_initial: f64,
    /// H at the last accepted step.
    pub energy_final: f64,
    /// Largest rigid-link strain `|g|` over the accepted steps (0 without links).
    pub max_link_g: f64,
    /// Where the element kernel ran (`cpu` or `gpu: ADAPTER, f64`).
    pub backend: String,
    /// The Newton linear solver (`dense`, `sparse`, `block-tridiagonal-B`).
    pub linear_solver: String,
    /// Factorizations the block-tridiagonal solver handed to its pivoting fallback.
    pub linear_solver_fallbacks: usize,
    /// Where the Newton time went (assembly, factorizations, solves).
    pub timers: crate::integrator::SolveTimers,
}
