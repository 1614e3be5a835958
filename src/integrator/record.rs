//! The records a run produces (per step, per run) and outputs consume: the integrator
//! fills them, observers add balances; also reachable as `observe::record`.

use serde::{Serialize, Serializer};

use crate::integrator::params::IntegratorParams;
use crate::model::Vec3;

/// Observables of one time level (row `step` of `history.csv`; row 0 is the initial state).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepRecord {
    /// Step index (0 = initial state).
    pub step: usize,
    /// Time `t_0 + step·Δt`, computed from the step index (never accumulated).
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
    /// Work of the external loads over the step that ended here (driven supports
    /// included).
    pub external_work: f64,
    /// The part of `external_work` done by driven supports (prescribed motion).
    pub support_work: f64,
    /// The part of `dissipation` taken by friction against obstacles and between rods
    /// (≥ 0).
    pub friction: f64,
    /// Work of the external loads from row 0 to here (sum of `external_work` over every
    /// accepted step, thinned or not).
    pub work_total: f64,
    /// Dissipation from row 0 to here (sum of `dissipation` over every accepted step).
    pub dissipation_total: f64,
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
    /// True when the step that ended here was solved by the fallback strategy after the
    /// run's strategy failed on it (`IntegratorParams::fallback`).
    pub fallback: bool,
    /// Sub-steps the step that ended here was cut into (1: taken at the full Δt; row 0: 0).
    pub substeps: usize,
}

/// JSON writing of the numbers of [`RunSummary`]: serde_json writes a non-finite `f64` as
/// `null`, indistinguishable from "not applicable". These write it as the string `"NaN"`,
/// `"inf"` or `"-inf"` instead (finite numbers as numbers), so `null` in `summary.json`
/// only ever means an absent value (`reason`, `smallest_substep`, `strategy`).
mod json_num {
    use super::{Serialize, Serializer};

    /// One number, finite or not.
    struct Num(f64);

    impl Serialize for Num {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            let x = self.0;
            if x.is_finite() {
                s.serialize_f64(x)
            } else if x.is_nan() {
                s.serialize_str("NaN")
            } else if x > 0.0 {
                s.serialize_str("inf")
            } else {
                s.serialize_str("-inf")
            }
        }
    }

    pub fn one<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        Num(*x).serialize(s)
    }

    pub fn opt<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        x.map(Num).serialize(s)
    }

    pub fn seq<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|&x| Num(x)))
    }

    pub fn three<S: Serializer>(v: &[f64; 3], s: S) -> Result<S::Ok, S::Error> {
        seq(v, s)
    }
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

/// Everything `summary.json` reports about a run. Its numbers are written as JSON
/// numbers when finite and as the strings `"NaN"`, `"inf"`, `"-inf"` otherwise (a failed
/// run's non-finite initial state or residual), never as `null`.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    /// Scene name or path.
    pub scene: String,
    /// How the run ended.
    pub status: RunStatus,
    /// Time of the last accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub t_reached: f64,
    /// Number of accepted steps.
    pub steps: usize,
    /// Why the run failed (`None` when completed).
    pub reason: Option<String>,
    /// Residual norms of the Newton iterations of the failing step (empty when completed;
    /// a non-finite one is written as `"NaN"`, `"inf"` or `"-inf"`, as every number of
    /// `summary.json`).
    #[serde(serialize_with = "json_num::seq")]
    pub failed_step_residuals: Vec<f64>,
    /// Wall-clock time of the time loop in seconds.
    #[serde(serialize_with = "json_num::one")]
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
    /// Largest per-step change of L relative to the run's momentum scale (not written to
    /// `summary.json`: on a loaded or supported run it is the applied impulse, not an
    /// error; see [`impulse_balance`](Self::impulse_balance)).
    #[serde(skip)]
    pub max_rel_dl: f64,
    /// Largest per-step change of J (relative; not written, like `max_rel_dl`).
    #[serde(skip)]
    pub max_rel_dj: f64,
    /// Energy balance `H_n − H_0 = W − D` over the accepted steps.
    pub energy_balance: EnergyBalance,
    /// Momentum balance against the applied impulse over the accepted steps.
    pub impulse_balance: ImpulseBalance,
    /// The last accepted level: every output of the run ends there.
    pub last_accepted: LastAccepted,
    /// The files this run wrote into its output folder (relative paths).
    pub outputs: Vec<String>,
    /// H at the start and at the last accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub energy_initial: f64,
    /// H at the last accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub energy_final: f64,
    /// Largest rigid-link strain `|g|` over the accepted steps (0 without links).
    #[serde(serialize_with = "json_num::one")]
    pub max_link_g: f64,
    /// Steps the run's strategy could not solve and the fallback strategy did (0 when the
    /// fallback is off or never needed).
    pub fallback_steps: usize,
    /// What the acceptance checks let through over the run: the largest energy growth
    /// beyond the external work and the largest final Newton residual of an accepted step.
    pub accepted: AcceptedExtremes,
    /// Steps redone as sub-steps (`IntegratorParams::cutback`; 0 when off or never needed).
    pub cutback_steps: usize,
    /// The smallest sub-step Δt taken (`null` when no step was cut back).
    #[serde(serialize_with = "json_num::opt")]
    pub smallest_substep: Option<f64>,
    /// Where the element kernel ran (`cpu` or `gpu: ADAPTER, f64`).
    pub backend: String,
    /// The dissipation strategy the run used (`params.strategy` resolved: `auto` is
    /// `monolithic` on the CPU kernel, `staggered` with a GPU evaluator); `null` for the
    /// conserving schemes (EM, midpoint, generalized-α), which solve no dissipation scalars.
    pub strategy: Option<String>,
    /// The Newton linear solver (`dense`, `sparse`, `block-tridiagonal-B`).
    pub linear_solver: String,
    /// Where the frozen-scalar Newton systems were solved: `host`, or `device`
    /// (`--solve device`: the GPU's block-tridiagonal solver).
    pub solve: String,
    /// Factorizations the block-tridiagonal solver handed to its pivoting fallback.
    pub linear_solver_fallbacks: usize,
    /// Where the Newton time went (assembly, factorizations, solves).
    pub timers: crate::integrator::SolveTimers,
}

/// `H_n − H_0 = W_n − D_n`: the energy balance of the accepted steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EnergyBalance {
    /// `H_0`.
    #[serde(serialize_with = "json_num::one")]
    pub energy_initial: f64,
    /// `H` at the last accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub energy_final: f64,
    /// External work over the run, `W`.
    #[serde(serialize_with = "json_num::one")]
    pub work_total: f64,
    /// Dissipation over the run, `D` (0 for EM; not reported by the baselines).
    #[serde(serialize_with = "json_num::one")]
    pub dissipation_total: f64,
    /// `H_n − H_0 − W + D` at the last accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub residual: f64,
    /// Largest `|H_k − H_0 − W_k + D_k|` over the accepted steps.
    #[serde(serialize_with = "json_num::one")]
    pub max_abs_residual: f64,
    /// Step where it was reached.
    pub max_abs_residual_step: usize,
    /// Largest residual relative to `max(|H_0|, |H_k|, |W_k|, |D_k|)`.
    #[serde(serialize_with = "json_num::one")]
    pub max_rel_residual: f64,
}

/// Momenta against the applied impulse (loads at `t_{n+½}`) over the accepted steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ImpulseBalance {
    /// The discrete impulse rule used.
    pub rule: String,
    /// True when supports, rigid links or obstacles act on the model: their reactions'
    /// impulse is then part of the residual (which is then not an error).
    pub reactions: bool,
    /// Accepted steps summed.
    pub steps: usize,
    /// `L_n − L_0`.
    #[serde(serialize_with = "json_num::three")]
    pub change_l: [f64; 3],
    /// `J_n − J_0` (about the origin).
    #[serde(serialize_with = "json_num::three")]
    pub change_j: [f64; 3],
    /// Impulse of the loads, `Σ Δt F(t_{n+½})`.
    #[serde(serialize_with = "json_num::three")]
    pub applied_impulse_l: [f64; 3],
    /// Angular impulse of the loads, `Σ Δt (r_{n+½} × F + M)`.
    #[serde(serialize_with = "json_num::three")]
    pub applied_impulse_j: [f64; 3],
    /// `L_n − L_0 − I_L` at the last accepted step.
    #[serde(serialize_with = "json_num::three")]
    pub residual_l: [f64; 3],
    /// `J_n − J_0 − I_J` at the last accepted step.
    #[serde(serialize_with = "json_num::three")]
    pub residual_j: [f64; 3],
    /// Largest `|L_k − L_0 − I_L,k|` over the steps.
    #[serde(serialize_with = "json_num::one")]
    pub max_residual_l: f64,
    /// Step where it was reached.
    pub max_residual_l_step: usize,
    /// Largest `|J_k − J_0 − I_J,k|`.
    #[serde(serialize_with = "json_num::one")]
    pub max_residual_j: f64,
    /// Step where it was reached.
    pub max_residual_j_step: usize,
    /// `max_residual_l` relative to the largest `|L|` or `|I_L|` of the run.
    #[serde(serialize_with = "json_num::one")]
    pub max_rel_residual_l: f64,
    /// `max_residual_j` relative to the largest `|J|` or `|I_J|` of the run.
    #[serde(serialize_with = "json_num::one")]
    pub max_rel_residual_j: f64,
}

/// The largest deviations the acceptance checks let through over a run's accepted steps
/// (docs/theory.md, "Tolerances", states the bounds they are held to).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct AcceptedExtremes {
    /// Largest `H_{n+1} − H_n − W` of an accepted step (≤ 0 means energy never grew
    /// beyond the external work; for a dissipative scheme it is at most `−D` plus the
    /// tolerances).
    #[serde(serialize_with = "json_num::one")]
    pub max_energy_growth: f64,
    /// The same growth relative to `max(|H_n|, |H_{n+1}|, |W|)` of its step (the largest
    /// such ratio of the run).
    #[serde(serialize_with = "json_num::one")]
    pub max_rel_energy_growth: f64,
    /// Largest final relative Newton residual of an accepted step.
    #[serde(serialize_with = "json_num::one")]
    pub max_residual: f64,
}

/// Where the outputs of a run end.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LastAccepted {
    /// Step index of the last accepted level (the run's end when completed).
    pub step: usize,
    /// Its time `t_0 + step·Δt`.
    #[serde(serialize_with = "json_num::one")]
    pub t: f64,
    /// What the outputs hold, in words (e.g. for a failed run: every file ends at this
    /// level; the failing step is not in any output).
    pub note: String,
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_step_record_fits_the_memory_estimates_share() {
        let size = std::mem::size_of::<super::StepRecord>() as u64;
        assert!(
            size <= crate::scene::limits::BYTES_PER_RECORD,
            "StepRecord is {size} B: raise limits::BYTES_PER_RECORD"
        );
    }
}
