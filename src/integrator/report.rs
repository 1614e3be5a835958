//! What a step reports: its outcome ([`StepReport`]), why it failed ([`StepFailure`]) and
//! where a simulation's Newton time went ([`SolveTimers`]). A leaf module: the step's
//! stages and the generalized-α baseline both report through it.

/// Why a step could not be accepted.
#[derive(Clone, Debug, PartialEq)]
pub struct StepFailure {
    /// Human-readable reason.
    pub reason: String,
    /// Residual norms (relative to the force scale) of the Newton iterations of the last
    /// attempt.
    pub residuals: Vec<f64>,
}

/// What an accepted step reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Newton iterations (all outer rounds and predictor retries).
    pub newton_iters: usize,
    /// Outer rounds (staggered), 1 otherwise.
    pub outer_iters: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Dissipation predicted by DESIGN §4 at the accepted state.
    pub dissipation: f64,
    /// Work of the external loads over the step, including the work of driven supports.
    pub external_work: f64,
    /// The part of `external_work` done by driven supports (prescribed motion).
    pub support_work: f64,
    /// The part of `dissipation` taken by friction against obstacles and between rods
    /// (≥ 0).
    pub friction: f64,
    /// Acceleration norms over the step.
    pub acc_trans: f64,
    /// Director acceleration norm.
    pub acc_rot: f64,
    /// Largest `|g|` of the rigid links at the accepted state (0 without links).
    pub max_link_g: f64,
    /// Augmented-Lagrangian rounds the step took (1 without links).
    pub link_rounds: usize,
    /// True when the step's strategy failed on it and the fallback strategy (monolithic
    /// for staggered and inexact, staggered for monolithic;
    /// [`crate::integrator::IntegratorParams::fallback`]) solved it.
    pub fallback: bool,
    /// Sub-steps the step was cut into (`IntegratorParams::cutback`); 1 for a step taken
    /// at the full Δt.
    pub substeps: usize,
}

/// Where a simulation's Newton time went (accumulated over its life; thread time, so a
/// batch sums them over members). The generalized-α baseline's own Newton loop is not
/// timed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolveTimers {
    /// Residual (and tangent) assembly on this simulation's own thread: element kernel (on
    /// the CPU), request packing, scatter, nodal and link terms.
    pub assemble_s: f64,
    /// Waiting for an element evaluator outside the simulation (GPU: the dispatch; in a
    /// lockstep batch also the other members' work before it), not counted in
    /// `assemble_s`.
    pub evaluate_wait_s: f64,
    /// LU factorizations.
    pub factor_s: f64,
    /// Triangular solves (with their backward-error checks).
    pub solve_s: f64,
    /// Factorizations done.
    pub factorizations: u64,
    /// Solves done (more than factorizations under modified Newton).
    pub solves: u64,
    /// Full-Newton iterations that assembled the residual without the tangent because the
    /// residual history predicted acceptance, or (CPU path) a residual near the
    /// tolerance …
    pub tangents_skipped: u64,
    /// … of those, the ones whose residual was neither accepted nor within 10× the
    /// tolerance (the tangent was then assembled at the same iterate) …
    pub tangent_skip_misses: u64,
    /// … and the ones whose residual was not accepted but within 10× the tolerance:
    /// corrected with the last factorization instead (a chord step; no tangent is
    /// assembled for them).
    pub chord_corrections: u64,
    /// Newton solves stopped because their residual had not decreased for several
    /// iterations (the step moved on to its next predictor or its fallback strategy).
    pub stagnation_stops: u64,
    /// Newton corrections that did not reduce the residual and were backtracked (a line
    /// search) …
    pub line_searches: u64,
    /// … and the residual evaluations those line searches took (one per trial, one more
    /// where no trial was accepted and the full correction was taken after all).
    pub line_search_evaluations: u64,
}

impl SolveTimers {
    /// Field-wise sum (a batch's total).
    pub fn add(&mut self, o: &SolveTimers) {
        self.assemble_s += o.assemble_s;
        self.evaluate_wait_s += o.evaluate_wait_s;
        self.factor_s += o.factor_s;
        self.solve_s += o.solve_s;
        self.factorizations += o.factorizations;
        self.solves += o.solves;
        self.tangents_skipped += o.tangents_skipped;
        self.tangent_skip_misses += o.tangent_skip_misses;
        self.chord_corrections += o.chord_corrections;
        self.stagnation_stops += o.stagnation_stops;
        self.line_searches += o.line_searches;
        self.line_search_evaluations += o.line_search_evaluations;
    }
}

/// A Newton residual that stops falling below this multiple of the tolerance is at its
/// round-off floor (see `newton`).
pub(crate) const ROUNDOFF_RESIDUAL: f64 = 1e5;
