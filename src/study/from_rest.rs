//! The from-rest stability map (`cosserat study from-rest`): a scene that starts at rest
//! and is loaded by a ramp (a roll-up by an end moment, a cantilever by a tip force, a
//! frame by force pulses, the arch by its apex load), run under EM and under each
//! dissipation parameter alone at one value, at every Δt of a grid, with fixed steps.
//!
//! Each cell completes or fails, and a failure is classified by its reason ([`Outcome`]):
//! the scheme's (a documented limit the step's checks refuse: an element's end triads
//! turned past the element limit (2 rad, docs/theory.md), energy created by an
//! energy-controlling scheme, a non-finite value) or the solver's: Newton diverged (every
//! attempt's residual stayed large: the step is beyond Newton's reach from its predictors)
//! or a solver stall (an attempt came close and still did not converge: the signature of
//! a defect, which the map exists to show there are none of).

use super::{parallel_map, EnergyGrowth, StudyError, PARAMETERS};
use crate::integrator::run::run;
use crate::integrator::{IntegratorParams, Scheme, Simulation};
use crate::observe::record::{RunStatus, StepRecord};
use crate::output::num;
use crate::scene::limits::Footprint;
use crate::scene::Scene;

/// What became of one cell of the map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Outcome {
    /// The run reached its end time.
    Completed,
    /// The scheme's limit: a converged step turned an element's end triads further apart
    /// than the linear director interpolation represents (the step's check refuses it).
    ElementTurn,
    /// The scheme's limit: a converged step of an energy-controlling scheme created
    /// energy beyond the external work (refused).
    EnergyGrowth,
    /// The scheme's limit: a step's result overflowed f64 (a diverging motion).
    NonFinite,
    /// A solver stall: no predictor, strategy or fallback found a solution the checks
    /// accept, and no check of the scheme refused one, while some attempt came close (a
    /// Newton residual below [`STALL_RESIDUAL`], or a staggered loop whose Newton solves
    /// converged but whose scalars never settled): the signature of a defect (a scalar
    /// that jumps, a missing solution near the step's start).
    SolverStall,
    /// Newton diverged: every attempt's residual stayed at or above [`STALL_RESIDUAL`]
    /// (no solution near the predictors: the step is beyond Newton's reach; a smaller
    /// step, e.g. by cut-back, passes).
    NewtonDivergence,
}

/// A failed attempt whose relative Newton residual got below this came close to a
/// solution ([`Outcome::SolverStall`]); above it, Newton diverged
/// ([`Outcome::NewtonDivergence`]).
pub const STALL_RESIDUAL: f64 = 1e-3;

/// The relative residuals a failure reason reports (`relative residual X`), in order.
fn reported_residuals(reason: &str) -> Vec<f64> {
    reason
        .split("relative residual ")
        .skip(1)
        .filter_map(|t| {
            let end = t.find([' ', ')', ',']).unwrap_or(t.len());
            t[..end].parse::<f64>().ok()
        })
        .collect()
}

impl Outcome {
    /// Every outcome, in legend order.
    pub const ALL: [Outcome; 6] = [
        Outcome::Completed,
        Outcome::ElementTurn,
        Outcome::EnergyGrowth,
        Outcome::NonFinite,
        Outcome::NewtonDivergence,
        Outcome::SolverStall,
    ];

    /// Name in the CSV (`class` column).
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Completed => "completed",
            Outcome::ElementTurn => "element_turn",
            Outcome::EnergyGrowth => "energy_growth",
            Outcome::NonFinite => "non_finite",
            Outcome::SolverStall => "solver_stall",
            Outcome::NewtonDivergence => "newton_divergence",
        }
    }

    /// Legend text.
    pub fn label(self) -> &'static str {
        match self {
            Outcome::Completed => "completed",
            Outcome::ElementTurn => "scheme: element end triads turned past the limit",
            Outcome::EnergyGrowth => "scheme: energy growth refused",
            Outcome::NonFinite => "scheme: non-finite (diverged)",
            Outcome::SolverStall => "solver stall (came close, did not converge)",
            Outcome::NewtonDivergence => "Newton diverged (Δt beyond its reach)",
        }
    }

    /// Whether a failure of this class is the scheme's (documented) rather than the
    /// solver's.
    pub fn is_scheme(self) -> bool {
        matches!(
            self,
            Outcome::ElementTurn | Outcome::EnergyGrowth | Outcome::NonFinite
        )
    }

    /// Classifies a run by its status and failure reason. A step's reason names every
    /// attempt of its last predictor (the strategy's, then its fallback's); if any of them
    /// was refused by a check of the scheme, the failure is the scheme's: a solution of
    /// the step exists and the scheme rejects it.
    pub fn classify(status: RunStatus, reason: Option<&str>) -> Outcome {
        if status == RunStatus::Completed {
            return Outcome::Completed;
        }
        let r = reason.unwrap_or("");
        if r.contains("end triads are turned") {
            Outcome::ElementTurn
        } else if r.contains("energy grew by") {
            Outcome::EnergyGrowth
        } else if r.contains("non-finite value") {
            Outcome::NonFinite
        } else if r.contains("staggered loop hit its cap")
            || reported_residuals(r).iter().any(|&x| x < STALL_RESIDUAL)
        {
            Outcome::SolverStall
        } else if r.contains("Newton did not converge") {
            Outcome::NewtonDivergence
        } else {
            Outcome::SolverStall
        }
    }
}

/// One row of the map: EM, or one dissipation parameter alone at a value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FromRestRow {
    /// `em` or a key of [`PARAMETERS`] (`chi_gamma`, …, `alpha_on`).
    pub key: &'static str,
    /// The parameter's value (0 for EM).
    pub value: f64,
}

impl FromRestRow {
    /// Parses `em` or a parameter key of [`PARAMETERS`], at `value`.
    pub fn parse(key: &str, value: f64) -> Result<Self, StudyError> {
        let key = key.trim();
        if key == "em" {
            return Ok(Self {
                key: "em",
                value: 0.0,
            });
        }
        let p = PARAMETERS.iter().find(|p| p.key == key).ok_or_else(|| {
            StudyError::Invalid(format!(
                "unknown parameter `{key}` (expected em, {})",
                PARAMETERS.map(|p| p.key).join(", ")
            ))
        })?;
        if !(value.is_finite() && value >= 0.0) {
            return Err(StudyError::Invalid(format!(
                "{key}: the value must be a finite number ≥ 0 (got {})",
                num(value)
            )));
        }
        Ok(Self { key: p.key, value })
    }

    /// The scheme of the row.
    pub fn scheme(&self) -> Scheme {
        PARAMETERS
            .iter()
            .find(|p| p.key == self.key)
            .map_or(Scheme::Em, |p| p.scheme(self.value))
    }

    /// Label for the chart, e.g. `EDMC-1 χ_ν = 0.5`, `EM`.
    pub fn label(&self) -> String {
        PARAMETERS
            .iter()
            .find(|p| p.key == self.key)
            .map_or("EM".to_string(), |p| {
                format!("{} = {}", p.symbol, num(self.value))
            })
    }
}

/// The rows of the default map: EM and each of the eight dissipation parameters alone
/// at `value`.
pub fn default_rows(value: f64) -> Vec<FromRestRow> {
    std::iter::once(FromRestRow {
        key: "em",
        value: 0.0,
    })
    .chain(PARAMETERS.iter().map(|p| FromRestRow { key: p.key, value }))
    .collect()
}

/// `n` log-spaced time steps from `lo` to `hi` (both included; `lo` alone when `n` = 1).
pub fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n <= 1 {
        return vec![lo];
    }
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

/// Settings of a from-rest map.
#[derive(Clone, Debug, PartialEq)]
pub struct FromRestConfig {
    /// Rows (EM and dissipation parameters).
    pub rows: Vec<FromRestRow>,
    /// Time steps (columns).
    pub dts: Vec<f64>,
    /// End time.
    pub t_end: f64,
    /// Worker threads.
    pub jobs: usize,
}

impl FromRestConfig {
    /// Checks the settings without running anything.
    pub fn check(&self) -> Result<(), StudyError> {
        super::check_list("t_end", &[self.t_end], true)?;
        super::check_list("dt", &self.dts, true)?;
        if self.rows.is_empty() {
            return Err(StudyError::Invalid("params: empty list".into()));
        }
        Ok(())
    }
}

/// One cell of the map.
#[derive(Clone, Debug, PartialEq)]
pub struct FromRestCell {
    /// Its row.
    pub row: FromRestRow,
    /// Time step.
    pub dt: f64,
    /// Requested end time.
    pub t_end: f64,
    /// Time of the last accepted step.
    pub t_reached: f64,
    /// Completed or the class of its failure.
    pub outcome: Outcome,
    /// Failure reason (`None` when completed).
    pub reason: Option<String>,
    /// Total Newton iterations.
    pub newton_iters_total: usize,
    /// Steps redone in sub-steps (0 with cut-back off, the map's default).
    pub cutback_steps: usize,
    /// `max_k (H_k − H_0 − W_{0→k})` relative to the largest |H| (≤ 0: none created).
    pub max_energy_growth: f64,
}

/// The result of a from-rest map: one cell per row and Δt, in the order row → Δt.
#[derive(Clone, Debug, PartialEq)]
pub struct FromRest {
    /// Scene name.
    pub scene: String,
    /// The grid.
    pub config: FromRestConfig,
    /// Step cut-back of every run (0: fixed step).
    pub cutback: usize,
    /// Cells.
    pub cells: Vec<FromRestCell>,
}

impl FromRest {
    /// How many cells have each outcome, in [`Outcome::ALL`] order.
    pub fn counts(&self) -> Vec<(Outcome, usize)> {
        Outcome::ALL
            .iter()
            .map(|&o| (o, self.cells.iter().filter(|c| c.outcome == o).count()))
            .collect()
    }

    /// `(row key, value, dt, reason)` of every failed cell.
    pub fn failures(&self) -> Vec<(String, f64, f64, String)> {
        self.cells
            .iter()
            .filter(|c| c.outcome != Outcome::Completed)
            .map(|c| {
                (
                    format!("{} [{}]", c.row.key, c.outcome.name()),
                    c.row.value,
                    c.dt,
                    c.reason.clone().unwrap_or_default(),
                )
            })
            .collect()
    }
}

/// Runs one cell: `scene` under the row's scheme at `dt` to `t_end` (every other setting
/// the scene's, cut-back included).
pub fn run_cell(scene: &Scene, row: FromRestRow, dt: f64, t_end: f64) -> FromRestCell {
    let mut params: IntegratorParams = scene.params;
    params.scheme = row.scheme();
    params.dt = dt;
    params.t_end = t_end;
    let mut growth = EnergyGrowth::new();
    let outcome = Simulation::new(scene.model.clone(), params)
        .map_err(|e| e.to_string())
        .map(|mut sim| {
            run(
                &mut sim,
                1,
                |rec: &StepRecord, _: &Simulation| -> Result<(), std::convert::Infallible> {
                    growth.push(rec);
                    Ok(())
                },
            )
            .unwrap_or_else(|never| match never {})
        });
    match outcome {
        Ok(o) => FromRestCell {
            row,
            dt,
            t_end,
            t_reached: o.t_reached,
            outcome: Outcome::classify(o.status, o.reason.as_deref()),
            reason: o.reason,
            newton_iters_total: o.newton_iters_total,
            cutback_steps: o.cutback_steps,
            max_energy_growth: growth.relative(),
        },
        // The solver could not be set up: no step ran.
        Err(reason) => FromRestCell {
            row,
            dt,
            t_end,
            t_reached: 0.0,
            outcome: Outcome::SolverStall,
            reason: Some(reason),
            newton_iters_total: 0,
            cutback_steps: 0,
            max_energy_growth: f64::NAN,
        },
    }
}

/// Runs a from-rest map of `scene` on `cfg.jobs` threads.
pub fn from_rest(scene: &Scene, cfg: &FromRestConfig) -> Result<FromRest, StudyError> {
    cfg.check()?;
    let count = (cfg.rows.len() as u64).saturating_mul(cfg.dts.len() as u64);
    crate::scene::limits::check_batch("this study", count, &Footprint::of_model(&scene.model))
        .map_err(|e| StudyError::Invalid(e.to_string()))?;
    let grid: Vec<(FromRestRow, f64)> = cfg
        .rows
        .iter()
        .flat_map(|&r| cfg.dts.iter().map(move |&dt| (r, dt)))
        .collect();
    let cells = parallel_map(&grid, cfg.jobs, |&(row, dt)| {
        run_cell(scene, row, dt, cfg.t_end)
    });
    Ok(FromRest {
        scene: scene.name.clone(),
        config: cfg.clone(),
        cutback: scene.params.cutback,
        cells,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_are_classified_by_the_check_that_refused() {
        let f = RunStatus::Failed;
        let turn = "step 3 failed: Newton did not converge in 25 iterations (relative residual 1e-3 > 1e-11) (the staggered fallback failed too: staggered loop hit its cap of 30 outer rounds: element 4: its end triads are turned 2.100 rad apart (limit 2.000): …)";
        assert_eq!(Outcome::classify(f, Some(turn)), Outcome::ElementTurn);
        assert_eq!(
            Outcome::classify(
                f,
                Some("step 2 failed: energy grew by 1e-3 beyond the external work (2e-3 relative)")
            ),
            Outcome::EnergyGrowth
        );
        let stall = "step 6 failed: Newton did not converge: its residual has not decreased for 5 iterations (the staggered fallback failed too: staggered loop hit its cap of 30 outer rounds: dissipation identity missed: H_n − H_n+1 + W − D = 2.2e-12 (2e-7 relative))";
        assert_eq!(Outcome::classify(f, Some(stall)), Outcome::SolverStall);
        assert!(!Outcome::SolverStall.is_scheme() && Outcome::ElementTurn.is_scheme());
        assert!(!Outcome::NewtonDivergence.is_scheme());
        let far = "step 21 (t = 5.760986 → 6.049035) failed: Newton did not converge in 25 iterations (relative residual 1.372e0 > 1.0e-11)";
        assert_eq!(Outcome::classify(f, Some(far)), Outcome::NewtonDivergence);
        let close = "step 6 failed: Newton did not converge: its residual has not decreased for 5 iterations (relative residual 9.473e-6 > 1.0e-11 at iteration 18)";
        assert_eq!(Outcome::classify(f, Some(close)), Outcome::SolverStall);
        assert_eq!(reported_residuals(far), vec![1.372]);
        // Anything else that is not a check of the scheme counts as a stall.
        assert_eq!(
            Outcome::classify(
                f,
                Some("augmented Lagrangian: links still violated after 8 rounds")
            ),
            Outcome::SolverStall
        );
        assert_eq!(
            Outcome::classify(RunStatus::Completed, None),
            Outcome::Completed
        );
    }

    #[test]
    fn rows_parse_and_the_grid_is_log_spaced() {
        assert_eq!(FromRestRow::parse("em", 0.5).unwrap().scheme(), Scheme::Em);
        let r = FromRestRow::parse("chi_nu", 0.5).unwrap();
        assert_eq!(
            r.scheme(),
            Scheme::Edmc1 {
                chi_gamma: 0.0,
                chi_omega: 0.0,
                chi_v: 0.0,
                chi_nu: 0.5
            }
        );
        assert_eq!(r.label(), "EDMC-1 χ_ν = 0.5");
        assert!(FromRestRow::parse("alpha", 0.5).is_err());
        assert!(FromRestRow::parse("alpha_ov", -1.0).is_err());
        assert_eq!(default_rows(0.5).len(), 9);
        let g = log_grid(0.02, 0.3, 40);
        assert_eq!(g.len(), 40);
        assert!((g[0] - 0.02).abs() < 1e-15 && (g[39] - 0.3).abs() < 1e-15);
        let ratio = g[1] / g[0];
        assert!(g.windows(2).all(|w| (w[1] / w[0] - ratio).abs() < 1e-12));
    }
}
