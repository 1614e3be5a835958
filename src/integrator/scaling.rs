//! When a Newton residual may be accepted. The relative residual of a step is measured
//! against each row's force scale, floored by the f64 round-off of the stress forces
//! (`element::stress_force_floor`, ~1e-15 of the "gross" forces `h|B|ᵀ|C|(|ε| + |ε0|)`).
//! For a very stiff material (E = 1e20) that floor exceeds the inertia and the loads, so
//! the residual of the *predictor* already reads as converged: a free body would stop
//! dead after 0 iterations. The floor says how far Newton *can* go, not that the predictor
//! got there: a residual is accepted only after at least one Newton correction.
//!
//! Where the round-off of the stresses exceeds the forces that drive a step, no Newton
//! iteration resolves it: the accepted increment is noise (a free frame at E = 1e20 gains
//! 17 % energy in ten steps). The energy checks allow the work of the final residual
//! `Σ|Rᵢ qᵢ|` on top of their tolerances (it is what an exact f64 solution may miss);
//! [`check_resolved`] fails a step whose residual work exceeds [`MAX_RESIDUAL_WORK`] of
//! the energy: f64 cannot resolve it, and saying so beats a wrong "completed".

/// Newton corrections a step computes before its residual may be accepted.
pub const MIN_CORRECTIONS: usize = 1;

/// Whether a residual at Newton iteration `it` (0 = the predictor) may be accepted.
pub fn may_accept(it: usize) -> bool {
    it >= MIN_CORRECTIONS
}

/// Largest work of the accepted residual, relative to the step's energy scale
/// `max(|H_n|, |H_n+1|, |W|)`, for which a step still counts as resolved. Measured
/// maxima: 5e-8 (arch at t = 0, the stiffest built-in case), 2e-12 (frame); a frame at
/// E = 1e16 reaches 1e2 and at E = 1e20 4e6; a translating rod at E = 1e16 (momentum kept to 6e-8) 1.5e-6.
pub const MAX_RESIDUAL_WORK: f64 = 1e-5;

/// `Err` with the reason when the residual's work swamps the energy (see the module).
pub fn check_resolved(residual_work: f64, href: f64) -> Result<(), String> {
    if residual_work <= MAX_RESIDUAL_WORK * href {
        return Ok(());
    }
    Err(format!(
        "unresolved in f64: the converged residual's work {residual_work:.3e} is {:.1e} of the energy {href:.3e} (limit {MAX_RESIDUAL_WORK:.0e}); the stiffness is too large for f64 to resolve this step's inertia and loads (lower E, or raise the loads or Δt)",
        residual_work / href
    ))
}
