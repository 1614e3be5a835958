//! `work_precision.csv`, `stability.csv`, `from_rest.csv` and `damping.csv`.

use std::io::Write;
use std::path::Path;

use super::{Damping, FromRest, Stability, WorkPrecision};
use crate::observe::record::RunStatus;
use crate::output::OutputError;

/// Header of `work_precision.csv`. `error` is NaN for a failed run; `observed_order` is
/// the order of the row's scheme/parameter fitted over its asymptotic range, whose
/// smallest and largest Δt are `fit_dt_min` and `fit_dt_max` (all three repeated on each
/// of its rows; NaN when it has no asymptotic range).
pub const WORK_PRECISION_COLUMNS: [&str; 10] = [
    "scheme",
    "param",
    "dt",
    "error",
    "wall_s",
    "status",
    "newton_iters_total",
    "observed_order",
    "fit_dt_min",
    "fit_dt_max",
];

/// Header of `stability.csv`.
pub const STABILITY_COLUMNS: [&str; 7] = [
    "scheme",
    "param",
    "dt",
    "t_reached",
    "t_end",
    "status",
    "max_energy_growth",
];

fn status(s: RunStatus) -> &'static str {
    match s {
        RunStatus::Completed => "completed",
        RunStatus::Failed => "failed",
    }
}

fn write_lines(path: &Path, header: &[&str], lines: &[String]) -> Result<(), OutputError> {
    let mut text = header.join(",");
    text.push('\n');
    for l in lines {
        text.push_str(l);
        text.push('\n');
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .map_err(|e| OutputError::io(path, e))
}

/// Writes `work_precision.csv` (columns [`WORK_PRECISION_COLUMNS`]).
pub fn write_work_precision_csv(path: &Path, wp: &WorkPrecision) -> Result<(), OutputError> {
    let lines: Vec<String> = wp
        .rows
        .iter()
        .map(|r| {
            format!(
                "{},{},{},{:e},{:.6},{},{},{:.4},{},{}",
                r.spec.kind.name(),
                r.spec.param,
                r.dt,
                r.error,
                r.wall_s,
                status(r.status),
                r.newton_iters_total,
                r.observed_order,
                r.fit_dt_min,
                r.fit_dt_max
            )
        })
        .collect();
    write_lines(path, &WORK_PRECISION_COLUMNS, &lines)
}

/// Writes `stability.csv` (columns [`STABILITY_COLUMNS`]).
pub fn write_stability_csv(path: &Path, st: &Stability) -> Result<(), OutputError> {
    let lines: Vec<String> = st
        .cells
        .iter()
        .map(|c| {
            format!(
                "{},{},{},{},{},{},{:e}",
                c.kind.name(),
                c.param,
                c.dt,
                c.t_reached,
                c.t_end,
                status(c.status),
                c.max_energy_growth
            )
        })
        .collect();
    write_lines(path, &STABILITY_COLUMNS, &lines)
}

/// Writes `failures.txt`: one line per failed run of a study, `scheme param dt: reason`
/// (empty file when every run completed), so that a tolerance floor can be told from a
/// divergence.
pub fn write_failures(
    path: &Path,
    failures: &[(String, f64, f64, String)],
) -> Result<(), OutputError> {
    let text: String = failures
        .iter()
        .map(|(s, p, dt, r)| format!("{s} {p} dt={dt}: {r}\n"))
        .collect();
    std::fs::write(path, text).map_err(|e| OutputError::io(path, e))
}

impl WorkPrecision {
    /// `(scheme, param, dt, reason)` of every failed run.
    pub fn failures(&self) -> Vec<(String, f64, f64, String)> {
        self.rows
            .iter()
            .filter(|r| r.status == RunStatus::Failed)
            .map(|r| {
                (
                    r.spec.kind.name().to_string(),
                    r.spec.param,
                    r.dt,
                    r.reason.clone().unwrap_or_default(),
                )
            })
            .collect()
    }
}

impl Stability {
    /// `(scheme, param, dt, reason)` of every failed run.
    pub fn failures(&self) -> Vec<(String, f64, f64, String)> {
        self.cells
            .iter()
            .filter(|c| c.status == RunStatus::Failed)
            .map(|c| {
                (
                    c.kind.name().to_string(),
                    c.param,
                    c.dt,
                    c.reason.clone().unwrap_or_default(),
                )
            })
            .collect()
    }
}

/// Header of `damping.csv`.
pub const DAMPING_COLUMNS: [&str; 11] = [
    "mode",
    "param",
    "value",
    "omega",
    "dt",
    "omega_dt",
    "energy_decay_rate",
    "zeta",
    "loss_per_period",
    "status",
    "reason",
];

/// Writes `damping.csv` (columns [`DAMPING_COLUMNS`]; NaN rates for failed runs).
pub fn write_damping_csv(path: &Path, d: &Damping) -> Result<(), OutputError> {
    let lines: Vec<String> = d
        .rows
        .iter()
        .map(|r| {
            format!(
                "{},{},{},{:.9e},{:.9e},{:.6},{:.9e},{:.9e},{:.9e},{},\"{}\"",
                r.mode.name(),
                r.param,
                r.value,
                r.omega,
                r.dt,
                r.omega * r.dt,
                r.energy_decay_rate,
                r.zeta,
                r.loss_per_period,
                status(r.status),
                r.reason.as_deref().unwrap_or("").replace('"', "'")
            )
        })
        .collect();
    write_lines(path, &DAMPING_COLUMNS, &lines)
}

/// Header of `from_rest.csv`: one row per cell; `class` is `completed`, a scheme's limit
/// (`element_turn`, `energy_growth`, `non_finite`) or `solver_stall`
/// ([`super::Outcome`]); `reason` the failure's text (quoted, empty when completed).
pub const FROM_REST_COLUMNS: [&str; 11] = [
    "param",
    "value",
    "dt",
    "t_reached",
    "t_end",
    "class",
    "scheme_limit",
    "newton_iters_total",
    "cutback_steps",
    "max_energy_growth",
    "reason",
];

/// Writes `from_rest.csv` (columns [`FROM_REST_COLUMNS`]).
pub fn write_from_rest_csv(path: &Path, fr: &FromRest) -> Result<(), OutputError> {
    let lines: Vec<String> = fr
        .cells
        .iter()
        .map(|c| {
            format!(
                "{},{},{},{},{},{},{},{},{},{:e},\"{}\"",
                c.row.key,
                c.row.value,
                c.dt,
                c.t_reached,
                c.t_end,
                c.outcome.name(),
                c.outcome.is_scheme(),
                c.newton_iters_total,
                c.cutback_steps,
                c.max_energy_growth,
                c.reason.as_deref().unwrap_or("").replace('"', "'")
            )
        })
        .collect();
    write_lines(path, &FROM_REST_COLUMNS, &lines)
}
