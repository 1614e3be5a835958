//! Stage 2 of a step: one checked solve with the link multipliers fixed, by the
//! dissipation strategy — frozen scalars for the conserving schemes, the paper's
//! staggered loop (freeze the local scalars, Newton, re-evaluate, until the dissipation
//! identity holds), the monolithic Newton with the scalars linearized inside it, or the
//! inexact strategy (the monolithic equations with the frozen-scalar tangent, then a
//! frozen-scalar polish round where it stopped within the tolerance). With the fallback on,
//! a step one strategy fails is retried with the other (staggered and inexact fall back
//! to the monolithic Newton from the same predictor, the monolithic Newton to the
//! staggered loop once it failed from every predictor).

use super::{Mode, Simulation};
use crate::element::FrozenScalars;
use crate::integrator::invariants::Invariants;
use crate::integrator::params::Strategy;
use crate::integrator::report::StepFailure;
use crate::integrator::state::State;

impl Simulation {
    /// One checked solve of the step with the link multipliers held fixed.
    #[allow(clippy::type_complexity)]
    pub(super) async fn solve_with_fixed_multipliers(
        &mut self,
        q: &mut [f64],
        total_iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        if !self.params.scheme.is_dissipative() {
            // Only Kelvin–Voigt damping (a constant β = 2η/Δt) dissipates.
            let dt = self.params.dt;
            for (s, d) in self.frozen.iter_mut().zip(&self.data) {
                let kv = crate::element::kelvin_voigt_beta(&d.props, dt);
                *s = FrozenScalars {
                    beta_gamma: kv,
                    beta_omega: kv,
                    ..FrozenScalars::default()
                };
            }
            return self.solve_once(q, Mode::Frozen, total_iters).await;
        }
        // Fallback: a step the strategy fails (outer cap, Newton failure, acceptance
        // check) is retried from the same predictor with the other one, which solves the
        // same scheme's equations: staggered and inexact fall back to the monolithic
        // Newton (scalars linearized), the monolithic Newton to the staggered loop (which
        // carries some violent steps further: the frame at Δt = 0.5, docs/benchmarks.md),
        // the latter only once the monolithic Newton has failed from every predictor.
        let strategy = self.strategy();
        let (fallback, name) = match strategy {
            Strategy::Monolithic => (Strategy::Staggered, "staggered"),
            _ => (Strategy::Monolithic, "monolithic"),
        };
        if !self.params.fallback || (strategy == Strategy::Monolithic && !self.last_predictor) {
            return self.solve_by(strategy, q, total_iters).await;
        }
        let q0 = q.to_vec();
        let frozen0 = self.frozen.clone();
        self.fallback_pending = true;
        let first = self.solve_by(strategy, q, total_iters).await;
        self.fallback_pending = false;
        match first {
            Ok(x) => Ok(x),
            Err(first) => {
                q.copy_from_slice(&q0);
                self.frozen.clone_from(&frozen0);
                match self.solve_by(fallback, q, total_iters).await {
                    Ok(x) => {
                        self.fell_back = true;
                        Ok(x)
                    }
                    Err(second) => {
                        self.frozen = frozen0;
                        self.solved_consistent = strategy == Strategy::Monolithic;
                        Err(StepFailure {
                            reason: format!(
                                "{} (the {name} fallback failed too: {})",
                                first.reason, second.reason
                            ),
                            residuals: second.residuals,
                        })
                    }
                }
            }
        }
    }

    /// One checked solve by `strategy` alone: the monolithic Newton, or the staggered
    /// loop / inexact strategy ([`Self::solve_first`]).
    #[allow(clippy::type_complexity)]
    async fn solve_by(
        &mut self,
        strategy: Strategy,
        q: &mut [f64],
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        self.solved_consistent = strategy == Strategy::Monolithic;
        match strategy {
            Strategy::Monolithic => self.solve_once(q, Mode::Consistent, iters).await,
            _ => self.solve_first(strategy, q, iters).await,
        }
    }

    /// The staggered loop, or the inexact strategy: Newton on the monolithic equations
    /// with the frozen-scalar tangent, then the staggered loop's rounds from the scalars
    /// consistent with its solution (normally one round of one or two iterations: it
    /// takes the residual from the Newton tolerance to its round-off floor with the
    /// scalars frozen, where momenta are conserved to round-off).
    #[allow(clippy::type_complexity)]
    async fn solve_first(
        &mut self,
        strategy: Strategy,
        q: &mut [f64],
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        if strategy != Strategy::Inexact {
            let (_, _, c0) = self.advance(q, Mode::Consistent);
            self.frozen = c0;
            return self.staggered_rounds(q, iters).await;
        }
        self.inexact_tangent = true;
        let solved = self.newton(q, Mode::Consistent).await;
        self.inexact_tangent = false;
        let (it, hist) = solved?;
        *iters += it;
        let res = *hist.last().unwrap_or(&0.0);
        if res > self.params.newton_tol {
            // Accepted on its round-off floor: nothing left to polish.
            match self.check(q, Mode::Consistent) {
                Ok((s, inv, d, w, c)) => {
                    self.solved_consistent = true;
                    return Ok((s, inv, d, w, 1, res, c));
                }
                Err(refused) => self.frozen = refused.consistent,
            }
        } else {
            // Within the tolerance but possibly just below it (the inexact iteration
            // contracts linearly): one frozen-scalar correction with the kept
            // factorization takes it to the floor, where momenta hold to round-off.
            let (_, _, c0) = self.advance(q, Mode::Consistent);
            self.frozen = c0;
            self.polish = true;
        }
        let out = self.staggered_rounds(q, iters).await;
        self.polish = false;
        out
    }

    #[allow(clippy::type_complexity)]
    pub(super) async fn solve_once(
        &mut self,
        q: &mut [f64],
        mode: Mode,
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        let (it, hist) = self.newton(q, mode).await?;
        *iters += it;
        let res = *hist.last().unwrap_or(&0.0);
        match self.check(q, mode) {
            Ok((s, inv, d, w, c)) => Ok((s, inv, d, w, 1, res, c)),
            Err(refused) => Err(StepFailure {
                reason: refused.reason,
                residuals: hist,
            }),
        }
    }

    /// The staggered loop's rounds from the current frozen scalars.
    async fn staggered_rounds(
        &mut self,
        q: &mut [f64],
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        let mut last_reason = String::new();
        let mut hist_all = Vec::new();
        for outer in 1..=self.params.max_outer {
            let (it, hist) = self.newton(q, Mode::Frozen).await?;
            *iters += it;
            let res = *hist.last().unwrap_or(&0.0);
            hist_all.extend(hist);
            match self.check(q, Mode::Frozen) {
                Ok((s, inv, d, w, c)) => return Ok((s, inv, d, w, outer, res, c)),
                Err(refused) => {
                    // The next round freezes the scalars consistent with this increment
                    // (the check computed them).
                    last_reason = refused.reason;
                    self.frozen = refused.consistent;
                }
            }
        }
        Err(StepFailure {
            reason: format!(
                "staggered loop hit its cap of {} outer rounds: {last_reason}",
                self.params.max_outer
            ),
            residuals: hist_all,
        })
    }
}
