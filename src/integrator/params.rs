//! Time-stepping parameters: the scheme, its dissipation constants, the Newton and
//! outer-loop tolerances. One `Copy` struct; every default is documented on its field.

use serde::Serialize;

pub use crate::scheme::Scheme;

/// How the dissipative terms are solved together with the conserving Newton problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// The default: [`Strategy::Monolithic`] where the CPU element kernel evaluates the
    /// elements (1.1–3× faster than the staggered loop on the paper's scenes, ≈ 2.4× on
    /// the CPU batch: docs/benchmarks.md, "Dissipation strategies"), [`Strategy::Staggered`]
    /// where a GPU evaluator is attached (its kernel evaluates the frozen-scalar system;
    /// a monolithic member's elements would run on the CPU). [`Strategy::resolve`] picks
    /// one; `summary.json` records which ran.
    Auto,
    /// The paper's staggered loop: freeze the local dissipation scalars, solve Newton,
    /// re-evaluate the scalars, repeat until the dissipation identity holds to
    /// `outer_tol` (at most `max_outer` rounds).
    Staggered,
    /// One Newton iteration on everything, the local dissipation scalars linearized
    /// inside it.
    Monolithic,
    /// The monolithic equations (the local dissipation scalars re-evaluated at every
    /// Newton iterate) solved with the frozen-scalar tangent: an inexact Newton that
    /// leaves out the scalars' linearization. Each iteration costs what a staggered one
    /// costs plus the scalars' local solve, and one solve replaces the staggered loop's
    /// rounds; the accepted step passes the same checks (energy, dissipation identity to
    /// `outer_tol`). An attached GPU evaluator runs its iterations too (its kernel
    /// evaluates the consistent scalars); with `fallback` a failed step is retried with
    /// the monolithic strategy.
    Inexact,
}

impl Strategy {
    /// The strategy that runs: `self`, or for [`Strategy::Auto`] the staggered loop where
    /// a GPU evaluator is attached (`gpu_evaluator`) and the monolithic Newton otherwise.
    pub fn resolve(self, gpu_evaluator: bool) -> Strategy {
        self.resolve_for(gpu_evaluator, false)
    }

    /// As [`Self::resolve`], and with `--solve whole` (`whole`, a GPU evaluator attached)
    /// [`Strategy::Auto`] is the inexact strategy, whose steps run on the device.
    pub fn resolve_for(self, gpu_evaluator: bool, whole: bool) -> Strategy {
        match self {
            Strategy::Auto if gpu_evaluator && whole => Strategy::Inexact,
            Strategy::Auto if gpu_evaluator => Strategy::Staggered,
            Strategy::Auto => Strategy::Monolithic,
            s => s,
        }
    }

    /// The name scene files, the CLI and `summary.json` use.
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Auto => "auto",
            Strategy::Staggered => "staggered",
            Strategy::Monolithic => "monolithic",
            Strategy::Inexact => "inexact",
        }
    }
}

/// How Newton treats the tangent within one solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum NewtonVariant {
    /// A fresh tangent (and LU factorization) every iteration, except on the CPU path a
    /// step's first correction where the previous step's predictor was far from its
    /// solution (relative residual ≥ 1e-2): it reuses that step's last factorization and
    /// assembles the residual only, and the solve then accepts below a tenth of the
    /// tolerance or on its round-off floor (the 50-element cantilever: 3 corrections per
    /// step with 2 factorizations instead of 3). Also on the CPU path, an iterate whose
    /// residual lands within 10× the tolerance without being accepted is corrected with
    /// the last factorization (a chord step onto the round-off floor; `timers.chord_corrections`).
    /// The GPU paths run it as [`Self::Fresh`].
    #[default]
    Full,
    /// A fresh tangent (and LU factorization) every iteration, a step's first and the last
    /// included.
    Fresh,
    /// From the third iteration of a solve on, the last tangent *and its factorization*
    /// are kept while each iteration cuts the relative residual by at least 5×; a slower
    /// iteration takes a fresh one. Iterations that keep it evaluate the residual only
    /// (on the GPU: a residual-only dispatch and readback). The acceptance checks are
    /// unchanged; the converged state differs from full Newton's by at most the Newton
    /// tolerance.
    Modified,
}

impl NewtonVariant {
    /// `full`, `fresh` or `modified`.
    pub fn name(&self) -> &'static str {
        match self {
            NewtonVariant::Full => "full",
            NewtonVariant::Fresh => "fresh",
            NewtonVariant::Modified => "modified",
        }
    }
}

/// All parameters of a run's time integration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct IntegratorParams {
    /// Scheme and its dissipation constants.
    pub scheme: Scheme,
    /// Time step Δt (> 0).
    pub dt: f64,
    /// End time (> 0); the run takes `ceil(t_end/dt − 1e-9)` steps.
    pub t_end: f64,
    /// Newton converges when `‖R‖∞ ≤ newton_tol · F_ref`, `F_ref` the largest force term
    /// balanced in the residual. Default `1e-11`.
    pub newton_tol: f64,
    /// Newton iteration cap per solve. Default 25.
    pub max_iter: usize,
    /// Newton variant. Default [`NewtonVariant::Full`]: modified Newton is up to 1.24×
    /// faster on the paper's scenes but leaves EM's energy conserved only to the Newton
    /// tolerance (4.7e-12 instead of 3.4e-15 over the cantilever's 1000 steps);
    /// docs/benchmarks.md, "Newton variant", has the measurements.
    pub newton: NewtonVariant,
    /// Dissipative solution strategy. Default [`Strategy::Auto`]: the monolithic Newton
    /// on the CPU element kernel, the paper's staggered loop where a GPU evaluator is
    /// attached (its kernel evaluates the frozen-scalar system).
    pub strategy: Strategy,
    /// Staggered loop: relative tolerance on the dissipation identity (and on the change
    /// of the frozen scalars). Default `1e-10`.
    pub outer_tol: f64,
    /// Staggered loop: cap on outer rounds. Default 30.
    pub max_outer: usize,
    /// A step whose energy grows by more than `energy_tol · H_ref` (beyond the external
    /// work) is rejected as failed. Default `1e-9`.
    pub energy_tol: f64,
    /// Rigid links: cap on augmented-Lagrangian rounds (solve, then `λ ← λ + κ g/2`)
    /// per step before the step fails. Default 50.
    pub max_link_rounds: usize,
    /// Solver fallback: when the staggered loop (or the inexact strategy) fails on a step
    /// (outer-round cap, Newton failure, or an acceptance check), the same step is
    /// retried with the monolithic strategy before the step is reported as failed; a
    /// monolithic failure is retried with the staggered loop. The scheme, and so every
    /// energy and momentum guarantee, is the same; only the way the dissipation scalars
    /// are solved differs. Default `true`; `false` (scene `fallback = false`, CLI
    /// `--no-fallback`) gives the pure strategy (the paper's, for staggered).
    pub fallback: bool,
    /// Step cut-back: a step that fails at Δt is redone as 2, 4, … 2^cutback sub-steps of
    /// the same scheme (each a complete, checked step, so momenta and the energy law hold
    /// across them) before the run reports the failure. Default 0 (off: fixed-Δt results
    /// stay the paper's). CPU element kernel only.
    pub cutback: usize,
}

impl IntegratorParams {
    /// Defaults for everything but scheme, Δt and end time.
    pub fn new(scheme: Scheme, dt: f64, t_end: f64) -> Self {
        Self {
            scheme,
            dt,
            t_end,
            newton_tol: 1e-11,
            max_iter: 25,
            newton: NewtonVariant::Full,
            strategy: Strategy::Auto,
            outer_tol: 1e-10,
            max_outer: 30,
            energy_tol: 1e-9,
            max_link_rounds: 50,
            fallback: true,
            cutback: 0,
        }
    }

    /// Number of steps to reach `t_end`.
    pub fn n_steps(&self) -> usize {
        ((self.t_end / self.dt) - 1e-9).ceil().max(0.0) as usize
    }
}
