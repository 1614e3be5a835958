//! Stage 3 of a step: Newton on the nodal increments. Fresh Newton takes a fresh tangent
//! every iteration; full Newton too, except that on the CPU path a step's first
//! correction far from the solution reuses the last step's factorization
//! ([`REUSE_FIRST_FROM`]), and so does a correction from an iterate just above the
//! tolerance (a chord step, [`CHORD_NEAR_TOL`]). Modified Newton keeps the last factorized tangent — across iterations,
//! staggered rounds and steps — as long as each correction made with it cuts the residual
//! by at least [`MODIFIED_NEWTON_RATE`]; the iterations that keep it assemble the residual
//! only.

use std::time::Instant;

use super::{Backend, Mode, Simulation};
use crate::integrator::dofs::NONE;
use crate::integrator::evaluate::Resident;
use crate::integrator::params::NewtonVariant;
use crate::integrator::report::{StepFailure, ROUNDOFF_RESIDUAL};
use crate::integrator::scaling;

/// Modified Newton takes a fresh tangent when the last correction (made with a kept
/// tangent) reduced the residual by less than this factor.
const MODIFIED_NEWTON_RATE: f64 = 0.2;

/// Full Newton: a step's first correction reuses the previous step's last factorization
/// (and assembles the residual only) when the previous step's predictor residual was at
/// least this. Far from the solution the first correction gains about as much with the
/// slightly older tangent as with a fresh one (the 50-element cantilever: 1.5 → 0.11 either
/// way, the same three corrections per step with two factorizations instead of three);
/// close to it a fresh tangent converges quadratically where the kept one would cost an
/// extra correction (the arch's predictors sit at 1e-4–1e-2).
const REUSE_FIRST_FROM: f64 = 1e-2;

/// After such a kept first correction a residual is accepted below this fraction of the
/// tolerance (or on its round-off floor).
const KEPT_FIRST_TOL: f64 = 0.1;

impl Simulation {
    /// Newton from `q` (overwritten with the solution). Returns iterations and the
    /// relative residual history.
    pub(super) async fn newton(
        &mut self,
        q: &mut [f64],
        mode: Mode,
    ) -> Result<(usize, Vec<f64>), StepFailure> {
        // Device-resident evaluations exist only inside a Newton solve (the test entry
        // points of `probe.rs` assemble on the host's `q` and read the residual back).
        self.resident_now = self.device_resident()
            && (mode == Mode::Frozen || self.inexact_on_gpu(mode))
            && !matches!(self.backend, Backend::Cpu);
        let out = self.newton_iterations(q, mode).await;
        self.resident_now = false;
        out
    }

    async fn newton_iterations(
        &mut self,
        q: &mut [f64],
        mode: Mode,
    ) -> Result<(usize, Vec<f64>), StepFailure> {
        let n = self.dofs.n;
        let mut r = vec![0.0; n];
        let mut history = Vec::new();
        let tol = self.params.newton_tol;
        let modified = self.params.newton == NewtonVariant::Modified;
        // Modified Newton and the inexact strategy's tangent (the scalars' linearization
        // left out) contract linearly: no quadratic-rate signs.
        let linear = modified || (self.inexact_tangent && mode == Mode::Consistent);
        let quadratic = !linear;
        // Whether the correction that led to the current iterate was made with a kept
        // (not freshly evaluated) tangent, and the iterate before it.
        let mut last_kept = false;
        // Whether that correction was a chord step near the tolerance.
        let mut last_chord = false;
        // The step's first correction was made with the last step's factorization: the
        // quadratic-rate signs then read the history from the first fresh correction on
        // ([`after_kept_first`]), and a residual is accepted below a tenth of the tolerance.
        let mut kept_first = false;
        let accept_tol = |kept_first: bool| {
            if kept_first {
                KEPT_FIRST_TOL * tol
            } else {
                tol
            }
        };
        let mut q_prev = vec![0.0; n];
        // Device-resident Newton: the device holds the iterate from the first evaluation
        // on (uploaded then), adds its own corrections, and the host fetches the iterate
        // it accepts; `q` is stale in between.
        let resident = self.resident_now;
        // (Not where the device solves: its factors are not the host's.)
        let polish = std::mem::take(&mut self.polish) && !self.device_solve;
        // A step's first solve on the CPU kernel: where the last step's predictor was far
        // from its solution, the first correction reuses that step's last factorization
        // (if this predictor is far too; otherwise the tangent is assembled after all).
        // The iterate it leads to is never accepted: a kept tangent contracts linearly, and
        // an iterate just inside the tolerance misses EM's energy balance by the
        // tolerance's residual work, where a fresh correction lands on the round-off floor
        // (the featured frame: 1e-12 instead of 5e-15).
        let step_start = std::mem::take(&mut self.step_start);
        let reuse_first = step_start
            && self.params.newton == NewtonVariant::Full
            && matches!(self.backend, Backend::Cpu)
            && self.step_r0 >= REUSE_FIRST_FROM;
        self.resident_next = Resident {
            upload: true,
            ..Resident::default()
        };
        self.residual_work = None;
        let frictional = self.model.has_friction();
        for it in 0..=self.params.max_iter {
            // Modified Newton keeps the factorized tangent of this mode (from an earlier
            // iteration, outer round or step) and evaluates the residual only.
            // Polishing an inexact solution: its first correction reuses the inexact
            // solve's last factorization (the frozen-scalar tangent of a nearby iterate).
            let mut reuse = (modified && self.factored == Some(mode))
                || (polish && it == 0 && self.factored.is_some())
                || (reuse_first && it == 0 && self.factored == Some(mode));
            kept_first |= reuse_first && reuse && it == 0;
            // Full Newton on the CPU kernel skips the tangent of an iterate whose residual
            // the history predicts to be accepted (and assembles it after all if not);
            // device-resident Newton skips the factorization and solve there, and the
            // iterate comes back with the report.
            let skip = (quadratic
                && (resident || matches!(self.backend, Backend::Cpu))
                && expect_accept(
                    after_kept_first(&history, kept_first),
                    accept_tol(kept_first),
                ))
                || (polish && it == 1);
            // Full Newton on the host: an iterate the history predicts to land near the
            // tolerance is evaluated without the tangent too; if it lands just above the
            // tolerance, its correction reuses the last factorization ([`CHORD_NEAR_TOL`]).
            let chord_ready = self.params.newton == NewtonVariant::Full
                && quadratic
                && !resident
                && !polish
                && matches!(self.backend, Backend::Cpu)
                && !last_kept
                && self.factored == Some(mode);
            let near = !skip
                && !reuse
                && chord_ready
                && expect_accept(after_kept_first(&history, kept_first), CHORD_PREDICT * tol);
            self.timers.tangents_skipped += u64::from(skip || near);
            self.resident_next.predict_accept = skip;
            // Device-resident: an iterate that may well be accepted comes back with its
            // report, which saves the fetch's round trip.
            self.resident_next.send_iterate =
                resident && scaling::may_accept(it) && may_be_accepted(&history, tol, linear);
            let mut res = self
                .timed_assemble(q, mode, !reuse && !skip && !near, &mut r)
                .await;
            if step_start && it == 0 {
                self.step_r0 = res;
                if kept_first && res < REUSE_FIRST_FROM {
                    // Close to the solution: a fresh tangent converges quadratically.
                    res = self.timed_assemble(q, mode, true, &mut r).await;
                    (reuse, kept_first) = (false, false);
                }
            }
            self.resident_next.predict_accept = false;
            self.resident_next.send_iterate = false;
            let accepted = |res: f64, history: &[f64]| {
                (res <= accept_tol(kept_first)
                    && scaling::may_accept(it)
                    && !(kept_first && it == 1))
                    || at_floor(after_kept_first(history, kept_first), res, tol, quadratic)
            };
            // A correction made with a kept tangent that did not cut the residual by
            // MODIFIED_NEWTON_RATE is undone; a chord correction that lands on an accepted
            // residual within CHORD_NEAR_TOL·tol is kept even where it contracted less (the
            // floor stops it), one that lands above that is undone.
            let near_tol = res <= CHORD_NEAR_TOL * tol;
            let undo = last_kept
                && !history
                    .last()
                    .is_some_and(|&prev| res <= MODIFIED_NEWTON_RATE * prev)
                && !(last_chord && near_tol && accepted(res, &history));
            let mut chord = false;
            if (skip || near) && !undo && !accepted(res, &history) {
                if chord_ready && near_tol {
                    // Not accepted, within CHORD_NEAR_TOL·tol: the last factorization
                    // corrects this iterate onto the floor (its tangent differs by the
                    // last correction's size, so the chord contracts by about that much).
                    (reuse, chord) = (true, true);
                } else {
                    self.timers.tangent_skip_misses += 1;
                    res = self.timed_assemble(q, mode, true, &mut r).await;
                }
            }
            // A fresh-tangent correction that did not reduce the merit ½·res² (the
            // convergence test's scaled norm) is shortened by halving ([`LINE_SEARCH_TRIALS`]);
            // every correction that reduces it is taken whole, as before. (Not on the
            // device-resident path, where the device holds the iterate.)
            // Only in scenes with friction (against obstacles or between rods: stick–slip):
            // elsewhere a solve that wanders is left to the stagnation stop, the fallback and
            // cut-back.
            if !undo && !resident && it > 0 && !last_kept && frictional {
                if let Some(&prev) = history.last() {
                    if (res >= prev || res.is_nan()) && !accepted(res, &history) {
                        res = self
                            .line_search(q, &q_prev, mode, !reuse, (prev, res), &mut r)
                            .await;
                    }
                }
            }
            let mut fresh = !reuse;
            if undo {
                // The kept tangent no longer contracts fast enough (or sent the iterate
                // astray): undo its correction and take a fresh tangent there (that
                // iterate's residual is already in the history).
                if resident {
                    self.resident_next.restore = true;
                } else {
                    q.copy_from_slice(&q_prev);
                }
                // That iterate's residual was finite: a non-finite one now is the
                // evaluator failing.
                if !self.timed_assemble(q, mode, true, &mut r).await.is_finite() {
                    self.resident_next.restore = false;
                    return Err(StepFailure {
                        reason: "the evaluation failed while undoing a correction made with a \
                                 kept tangent"
                            .into(),
                        residuals: history,
                    });
                }
                fresh = true;
            } else {
                history.push(res);
                if !res.is_finite() {
                    return Err(StepFailure {
                        reason: "non-finite residual (Newton diverged)".into(),
                        residuals: history,
                    });
                }
                if accepted(res, &history[..history.len() - 1]) {
                    if let (true, Some((nodes, rw))) = (resident, self.resident_iterate.take()) {
                        self.take_resident_iterate(q, &nodes, rw);
                    } else if resident {
                        if let Err(e) = self.fetch_resident(q).await {
                            return Err(StepFailure {
                                reason: format!("device-resident Newton: {e}"),
                                residuals: history,
                            });
                        }
                    } else {
                        self.last_residual.clone_from(&r);
                    }
                    return Ok((it, history));
                }
                // Only where the step has somewhere to move on to (its next predictor or
                // its fallback strategy): otherwise the solve goes on (it may still converge,
                // as the catenary's first step from rest does after rising 30-fold), and a
                // failure after max_iter goes to cut-back as before.
                if !self.last_predictor && rose_from_start(&history) {
                    // Outside the predictor's basin from the start: move on at once.
                    self.timers.stagnation_stops += 1;
                    return Err(StepFailure {
                        reason: format!(
                            "Newton did not converge: its residual rose on each of its first {RISES_FROM_START} corrections (relative residual {res:.3e} > {tol:.1e})"
                        ),
                        residuals: history,
                    });
                }
                if (!self.last_predictor || self.fallback_pending)
                    && stagnated(&history, STAGNATION_ITERS)
                {
                    // Wandering: move on (next predictor, fallback, cut-back) instead of
                    // spending the remaining iterations.
                    self.timers.stagnation_stops += 1;
                    return Err(StepFailure {
                        reason: format!(
                            "Newton did not converge: its residual has not decreased for {STAGNATION_ITERS} iterations (relative residual {res:.3e} > {tol:.1e} at iteration {it})"
                        ),
                        residuals: history,
                    });
                }
            }
            if it == self.params.max_iter {
                break;
            }
            r.iter_mut().for_each(|x| *x = -*x);
            // A reused tangent keeps its factorization too (modified Newton).
            let t0 = Instant::now();
            let mut t1 = t0;
            let solved = if let Some(sol) = self.device_x.take() {
                // The device factorized (fresh tangent) or reused its factors, and solved
                // with the same right-hand side: take its correction.
                if fresh {
                    self.timers.factorizations += 1;
                    self.factored = None;
                }
                sol.map(|x| {
                    if fresh {
                        self.factored = Some(mode);
                    }
                    // (Device-resident: the device added the correction itself; `x` is
                    // empty.)
                    for (nd, xn) in self.dofs.nodes.iter().zip(&x) {
                        for (&i, &v) in super::node_local(nd).iter().zip(xn) {
                            if i != NONE {
                                r[i] = v;
                            }
                        }
                    }
                })
            } else {
                let factored = if fresh {
                    self.timers.factorizations += 1;
                    self.factored = None;
                    let f = self.solver.factor();
                    if f.is_ok() {
                        self.factored = Some(mode);
                    }
                    f
                } else {
                    Ok(())
                };
                t1 = Instant::now();
                factored
                    .and_then(|_| self.solver.solve(&mut r))
                    .map_err(|e| e.to_string())
            };
            self.timers.solves += 1;
            self.timers.factor_s += (t1 - t0).as_secs_f64();
            self.timers.solve_s += t1.elapsed().as_secs_f64();
            if let Err(e) = solved {
                return Err(StepFailure {
                    reason: format!("linear solve failed: {e}"),
                    residuals: history,
                });
            }
            self.timers.chord_corrections += u64::from(chord);
            if !resident {
                q_prev.copy_from_slice(q);
                for (qi, di) in q.iter_mut().zip(&r) {
                    *qi += di;
                }
            }
            last_kept = !fresh;
            last_chord = chord;
        }
        Err(StepFailure {
            reason: format!(
                "Newton did not converge in {} iterations (relative residual {:.3e} > {:.1e})",
                self.params.max_iter,
                history.last().copied().unwrap_or(f64::NAN),
                tol
            ),
            residuals: history,
        })
    }

    /// Backtracking on the correction `q − q_prev` that raised the relative residual from
    /// `r0` to `r1`: halves it until the merit ½·res² meets Armijo's condition
    /// `res² ≤ (1 − 2cα)·r0²` ([`ARMIJO`]), one evaluation (with the tangent where
    /// `tangent`) per trial. Leaves `q` and `r` at the accepted trial and returns its
    /// residual; if none is accepted, at the full correction again (re-evaluated), `r1`.
    async fn line_search(
        &mut self,
        q: &mut [f64],
        q_prev: &[f64],
        mode: Mode,
        tangent: bool,
        (r0, r1): (f64, f64),
        r: &mut [f64],
    ) -> f64 {
        let full = q.to_vec();
        self.timers.line_searches += 1;
        let mut alpha = 1.0;
        for _ in 0..LINE_SEARCH_TRIALS {
            alpha *= 0.5;
            for ((qi, &p), &f) in q.iter_mut().zip(q_prev).zip(&full) {
                *qi = p + alpha * (f - p);
            }
            self.timers.line_search_evaluations += 1;
            let res = self.timed_assemble(q, mode, tangent, r).await;
            if res * res <= (1.0 - 2.0 * ARMIJO * alpha) * r0 * r0 {
                return res;
            }
        }
        q.copy_from_slice(&full);
        self.timers.line_search_evaluations += 1;
        let res = self.timed_assemble(q, mode, tangent, r).await;
        // (The same iterate, the same evaluation: the same residual.)
        debug_assert!(res.to_bits() == r1.to_bits() || !r1.is_finite());
        res
    }

    /// [`Self::assemble`] with its own time (not the wait for an evaluator) counted as
    /// assembly. Returns the relative residual.
    async fn timed_assemble(&mut self, q: &[f64], mode: Mode, tangent: bool, r: &mut [f64]) -> f64 {
        let (t0, wait0) = (Instant::now(), self.timers.evaluate_wait_s);
        let (res, _) = self.assemble(q, mode, tangent, r).await;
        let waited = self.timers.evaluate_wait_s - wait0;
        self.timers.assemble_s += t0.elapsed().as_secs_f64() - waited;
        res
    }
}

/// Line search: how many halvings of a correction that did not reduce the residual are
/// tried (each one evaluation) before the full correction is taken after all. At a
/// stick–slip transition the friction force turns from sliding to sticking over a slip
/// much shorter than a correction's (the regularized law's `ε Δt` per step; the stick
/// law's spring at the Coulomb cone): whole corrections overshoot it, and the iterates
/// cycle between the two sides. Measured on the friction
/// scenes' default runs (bounce μ = 0.5, crossing with rod friction μ = 0.5, the
/// capstans with both laws; 5 200 searches): every search accepted a step of 1/64 of the
/// correction or more (1/32 on the crossing's stick–slip steps, where 4 halvings stopped
/// at 1/16, took the whole correction and cycled until cut back), none needed more than 6
/// halvings; 8 leaves a margin at no measured cost.
const LINE_SEARCH_TRIALS: usize = 8;

/// Armijo's sufficient-decrease constant `c` for the merit ½·res² along the Newton
/// correction (whose directional derivative there is −res²).
const ARMIJO: f64 = 1e-4;

/// A Newton solve that has somewhere to move on to (the step's next predictor, or the
/// fallback strategy) stops once its residual has stayed at or above its best earlier value for this many
/// iterations. Measured (relative residual histories, every built-in scene's default run
/// and the frame's staggered run): converging solves stay above their best for at most 3
/// iterations (the frame's, the mechanism's; 10 once in the capstan's 1000 friction
/// solves, whose step then converges from the next predictor), while the solves that fail
/// wander from their first iterations on (the frame's between 0.7 and 2.3 for 25
/// iterations, never below the predictor's 0.68–0.83). Re-measured on the ten built-in
/// scenes' default runs (about 10 000 solves): none that converged stayed at or above its
/// best for 4 iterations.
pub(super) const STAGNATION_ITERS: usize = 5;

/// A solve from the step's first predictor (the zero predictor follows) stops when each of
/// its first this many corrections raised the residual. Measured on the ten built-in
/// scenes' default runs: none of the 9 557 first-predictor solves that converged did so
/// (the frame's first correction raises the residual in 19 of its 50 steps, the second then
/// lowers it), while two of the frame's three first-predictor solves that failed did
/// (0.77 → 0.99 → 1.63, 0.68 → 0.76 → 1.24). Not applied to the last predictor (two
/// zero-predictor solves of the mechanism rose twice and converged) nor to a solve whose
/// fallback is pending: there it stopped converging solves of the from-rest roll-up with
/// χ_v (docs/damping.md). On the from-rest frame at Δt = 0.52 (beyond Newton's reach there)
/// one χ_Γ run now fails at t = 5.7 instead of 8.3.
const RISES_FROM_START: usize = 2;

/// Whether the residual `history` rose on each of its first [`RISES_FROM_START`]
/// corrections (checked once, when it has exactly that many).
pub(super) fn rose_from_start(history: &[f64]) -> bool {
    history.len() == RISES_FROM_START + 1 && history.windows(2).all(|w| w[1] > w[0])
}

/// Whether the residual `history` has not decreased for `k` iterations: its last `k`
/// entries are all at or above the smallest before them.
pub(super) fn stagnated(history: &[f64], k: usize) -> bool {
    let h = history.len();
    if k == 0 || h <= k {
        return false;
    }
    let best = history[..h - k]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    history[h - k..].iter().all(|&r| r >= best)
}

/// The part of a solve's residual history after a kept first correction (all of it
/// otherwise): the residuals that fresh-tangent corrections produced from there on.
fn after_kept_first(history: &[f64], kept_first: bool) -> &[f64] {
    &history[usize::from(kept_first).min(history.len())..]
}

/// Whether the residual `res` that follows `history` sits on its f64 round-off floor, where
/// further corrections do not reduce it: accept it (the energy checks that follow still
/// apply). Two signs, each after at least two corrections:
///
/// * it stopped falling (less than halved) while within `ROUNDOFF_RESIDUAL`·`tol`: Newton
///   converges quadratically, so from there the next residual would be far below `tol`
///   (stiff members under small loads: the arch at t ≈ 0);
/// * (full Newton, `quadratic_rate`: modified Newton contracts linearly) it is within
///   10·`tol` and a thousand times above what quadratic convergence predicts
///   from the last two residuals (`r₁³/r₂²`): the correction that led here was at the
///   round-off level (the 50-element cantilever at `tol` = 1e-11: 0.11 → 1e-8 → 3e-11,
///   where a further correction leaves 3e-11 again).
pub(super) fn at_floor(history: &[f64], res: f64, tol: f64, quadratic_rate: bool) -> bool {
    let h = history.len();
    if h < 2 {
        return false;
    }
    let (r2, r1) = (history[h - 2], history[h - 1]);
    (res <= ROUNDOFF_RESIDUAL * tol && res >= 0.5 * r1)
        || (quadratic_rate
            && res <= FLOOR_NEAR_TOL * tol
            && r1 < r2
            && res >= FLOOR_EXCESS * quadratic(r2, r1))
}

/// Full Newton: an iterate whose residual lands within this multiple of the tolerance
/// (not accepted) is corrected with the last factorization instead of a fresh tangent.
/// Monolithic EDMC-2 steps whose floor sits at the tolerance often end, after a kept first
/// correction, 0.12 → 2.6e-5 → 9.6e-12 (inside the tolerance, not below a tenth of it, not
/// yet recognized as the floor) → 1.3e-11: that last correction is at the round-off level,
/// and the tangent of the previous iterate makes it as well as a fresh one (it differs by
/// the size of the last correction, 1e-5 relative).
const CHORD_NEAR_TOL: f64 = FLOOR_NEAR_TOL;

/// An iterate is evaluated without its tangent when quadratic convergence from the last two
/// residuals predicts its residual within this multiple of the tolerance
/// ([`expect_accept`] at `CHORD_PREDICT · tol`; 2.6e-5 after 0.12
/// predicts 1.2e-12): a miss costs one residual-only evaluation. 1e3 took 9 more chords in
/// 200 steps of the 30-element cantilever and 28–46 more misses on the mechanisms.
const CHORD_PREDICT: f64 = 1e2;

/// [`at_floor`]'s second sign: how close to `tol` the floor must be …
const FLOOR_NEAR_TOL: f64 = 10.0;
/// … and by how much it exceeds the quadratic prediction.
const FLOOR_EXCESS: f64 = 1e3;

/// The residual after `r1` that quadratic convergence predicts from the last two, `r2` and
/// `r1`: `K r1²` with `K = r1 / r2²`.
fn quadratic(r2: f64, r1: f64) -> f64 {
    r1 * (r1 / r2) * (r1 / r2)
}

/// Whether the next residual after `history` may well be accepted (device-resident Newton
/// then has the iterate sent back with its report): full Newton, the last residual within
/// `√tol` (quadratic convergence with a unit constant reaches tol); a linearly contracting
/// iteration (modified Newton, the inexact strategy's tangent), the last contraction rate
/// carried once more reaches tol.
fn may_be_accepted(history: &[f64], tol: f64, linear: bool) -> bool {
    match (history, linear) {
        ([.., r1], false) => r1 * r1 <= tol,
        ([.., r2, r1], true) => r1 < r2 && r1 * (r1 / r2) <= tol,
        _ => false,
    }
}

/// Whether the next residual after `history` is expected to be accepted: quadratic
/// convergence takes it below `tol` (or onto the floor [`at_floor`] recognizes).
fn expect_accept(history: &[f64], tol: f64) -> bool {
    let h = history.len();
    if h < 2 {
        return false;
    }
    let (r2, r1) = (history[h - 2], history[h - 1]);
    r1 < r2 && quadratic(r2, r1) <= tol
}

#[cfg(test)]
mod tests {
    use super::{
        at_floor, expect_accept, may_be_accepted, rose_from_start, stagnated, CHORD_PREDICT,
    };

    const TOL: f64 = 1e-11;

    /// The cantilever's history (measured): 1.5 → 0.11 → 1e-8 → 3e-11 is on the floor,
    /// and the iterate after 1e-8 is predicted to be accepted (its tangent is skipped).
    #[test]
    fn the_cantilever_floor_is_recognized_one_correction_early() {
        assert!(expect_accept(&[1.5, 0.11, 1e-8], TOL));
        assert!(at_floor(&[1.5, 0.11, 1e-8], 3e-11, TOL, true));
        // Modified Newton contracts linearly: the quadratic sign does not apply.
        assert!(!at_floor(&[1.5, 0.11, 1e-8], 3e-11, TOL, false));
        // Not after a single correction, and not from a predictor alone.
        assert!(!at_floor(&[1.5], 3e-11, TOL, true));
        assert!(!expect_accept(&[1.5], TOL));
        assert!(!expect_accept(&[1.5, 0.11], TOL));
    }

    /// Monolithic EDMC-2 histories (measured): after a kept first correction, 0.12 →
    /// 2.6e-5 predicts 1.2e-12, near the tolerance but not below the tenth of it such a
    /// step needs; 0.13 → 4.1e-4 predicts 4.1e-9, not near (the tangent is assembled);
    /// far out, or while diverging, nothing is expected.
    #[test]
    fn a_residual_near_the_tolerance_is_expected_from_the_history() {
        let near = |h: &[f64]| expect_accept(h, CHORD_PREDICT * TOL);
        assert!(near(&[0.12, 2.6e-5]));
        assert!(!expect_accept(&[0.12, 2.6e-5], 0.1 * TOL));
        assert!(!near(&[0.13, 4.1e-4]));
        assert!(!near(&[1.3, 0.13]));
        assert!(!near(&[2.6e-5, 0.12]));
        assert!(!near(&[2.6e-5]));
    }

    /// Device-resident Newton has the iterate sent back when the next residual may be
    /// accepted: full Newton within √tol, modified Newton by its last contraction rate.
    #[test]
    fn an_iterate_is_sent_back_when_it_may_be_accepted() {
        assert!(!may_be_accepted(&[], TOL, false));
        assert!(may_be_accepted(&[3e-6], TOL, false));
        assert!(!may_be_accepted(&[4e-6], TOL, false));
        // Modified: 1e-9 at a rate of 1e-3 gives 1e-12.
        assert!(may_be_accepted(&[1e-6, 1e-9], TOL, true));
        assert!(!may_be_accepted(&[1e-7, 1e-9], TOL, true));
        assert!(!may_be_accepted(&[1e-9], TOL, true));
    }

    /// The quadratic sign accepts only within 10·tol, and only far above the prediction:
    /// a slowly converging sequence is not mistaken for the floor.
    #[test]
    fn the_floor_is_bounded_near_tol_and_far_above_the_prediction() {
        // Within 10·tol, far above the prediction 1e-6·(1e-5)² = 1e-16: floor.
        assert!(at_floor(&[1e-1, 1e-6], 9e-11, TOL, true));
        // Above 10·tol: not the floor, however far above the prediction.
        assert!(!at_floor(&[1e-1, 1e-6], 2e-10, TOL, true));
        // Within 10·tol but less than 1000× the prediction 1e-5·(1e-3)² = 1e-11: a slowly
        // converging sequence, not the floor.
        assert!(!at_floor(&[1e-2, 1e-5], 5e-11, TOL, true));
        // The stall sign: a residual that no longer halves within 1e5·tol.
        assert!(at_floor(&[1e-3, 4e-7], 3e-7, TOL, false));
        assert!(!at_floor(&[1e-3, 4e-7], 1e-7, TOL, false));
        assert!(!at_floor(&[1e-3, 4e-6], 3e-6, TOL, false));
    }

    /// The frame's failing solve (measured) stagnates after 5 iterations above its
    /// predictor's residual; the capstan's slow converging solve does not stop while it
    /// still finds new minima, nor does a converging history.
    #[test]
    fn a_wandering_solve_is_stopped_after_k_iterations_without_decrease() {
        let frame = [0.68, 0.76, 1.2, 1.5, 1.7, 1.9, 0.9, 1.9];
        assert!(!stagnated(&frame[..5], 5));
        assert!(stagnated(&frame[..6], 5));
        // Equal to the best counts as no decrease.
        assert!(stagnated(&[1.0, 2.0, 1.0, 1.0, 3.0, 1.0], 5));
        // A new minimum within the last k restarts the count.
        assert!(!stagnated(&[1.0, 2.0, 2.0, 2.0, 2.0, 0.9], 5));
        assert!(!stagnated(&[1.5, 0.11, 1e-8, 3e-11], 5));
        assert!(!stagnated(&[1.0; 3], 0));
    }

    /// The frame's failing first-predictor solves (measured) rise on each of their first
    /// two corrections; its converging solves that rise once and then fall, a converging
    /// history, and a history past its first two corrections are not stopped by the rule.
    #[test]
    fn a_solve_that_rises_on_its_first_two_corrections_is_stopped() {
        assert!(rose_from_start(&[0.773, 0.988, 1.63]));
        assert!(rose_from_start(&[0.677, 0.763, 1.24]));
        // The frame's converging zero-predictor solve at t = 8.8: up once, then down.
        assert!(!rose_from_start(&[0.401, 1.07, 0.455]));
        assert!(!rose_from_start(&[0.825, 0.936, 0.772]));
        assert!(!rose_from_start(&[1.5, 0.11, 1e-8]));
        // Checked only at exactly two corrections.
        assert!(!rose_from_start(&[0.773, 0.988]));
        assert!(!rose_from_start(&[0.773, 0.988, 1.63, 2.33]));
    }
}
