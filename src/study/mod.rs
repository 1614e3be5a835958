//! Speed-versus-accuracy and stability studies over time integrators on one scene.
//!
//! * [`work_precision`]: every scheme/parameter at every Δt; the error of each run is the
//!   **L2-in-time error of all nodal positions** against a reference run (EM at a much
//!   smaller Δt):
//!
//!   ```text
//!   error = sqrt( 1/K Σ_k 1/N Σ_a |r_a(t_k) − r_a^ref(t_k)|² )
//!   ```
//!
//!   over the `K` sample times `t_k = k·Δt_s ≤ t_end` (`Δt_s` the largest Δt of the study;
//!   a run whose levels miss a sample time is linearly interpolated there) and the `N`
//!   nodes; units of length. Beside the error: wall time, Newton iterations and the
//!   observed order of each scheme/parameter, fitted over its asymptotic range only
//!   ([`asymptotic_fit`]: the longest run of its finest Δt whose local orders agree).
//! * [`stability`]: a grid Δt × dissipation parameter per scheme; each run reports how far
//!   it got and the largest relative growth of `H − H_0 − W` (energy created beyond the
//!   external work).
//!
//! * [`from_rest`]: a scene loaded from rest under EM and each dissipation parameter
//!   alone, over a log grid of Δt; each failure classified as the scheme's or a solver
//!   stall ([`Outcome`]).
//!
//! * [`damping`]: the dissipation guide, the modal damping ratio of the first axial and
//!   bending mode of a clamped rod under each dissipation parameter.
//!
//! Each member is one [`run_member`] call (a plain function of scene, scheme, parameter,
//! Δt and end time), run on `jobs` threads ([`parallel_map`]); nothing else is shared.

mod damping;
mod from_rest;
mod plot;
mod write;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

pub use damping::{damping, Damping, DampingConfig, DampingRow, ModeKind, Parameter, PARAMETERS};
pub use from_rest::{
    default_rows, from_rest, log_grid, run_cell, FromRest, FromRestCell, FromRestConfig,
    FromRestRow, Outcome, STALL_RESIDUAL,
};
pub use plot::{plot_damping, plot_from_rest, plot_stability, plot_work_precision};
pub use write::{
    write_damping_csv, write_failures, write_from_rest_csv, write_stability_csv,
    write_work_precision_csv, DAMPING_COLUMNS, FROM_REST_COLUMNS, STABILITY_COLUMNS,
    WORK_PRECISION_COLUMNS,
};

use crate::batch::{run_members, BatchOptions, Executor, Member};
use crate::integrator::gen_alpha::DEFAULT_RHO_INF;
use crate::integrator::run::run;
use crate::integrator::{IntegratorParams, Scheme, Simulation};
use crate::model::Vec3;
use crate::observe::record::{RunStatus, StepRecord};
use crate::output::num;
use crate::scene::limits::Footprint;
use crate::scene::Scene;

/// Errors of the study drivers.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// A scheme specification could not be parsed.
    #[error("bad scheme `{spec}`: {reason}")]
    SchemeSpec {
        /// The text given.
        spec: String,
        /// What is wrong.
        reason: String,
    },
    /// A study parameter is out of range (empty list, Δt ≤ 0, …).
    #[error("{0}")]
    Invalid(String),
    /// The reference run of a work–precision study did not reach the end time.
    #[error("reference run (EM, Δt = {}) failed: {reason}", num(*dt))]
    Reference {
        /// Its Δt.
        dt: f64,
        /// Why.
        reason: String,
    },
    /// The linear solver could not be set up for the scene.
    #[error("cannot set up the linear solver: {0}")]
    Solver(#[from] crate::linsolve::LinsolveError),
    /// Writing an output failed.
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    /// The GPU batch could not be set up.
    #[error("GPU batch: {0}")]
    Gpu(#[from] crate::gpu::GpuError),
}

/// A scheme family of a study; the one number that varies in it is the `param` of
/// [`SchemeKind::scheme`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SchemeKind {
    /// Energy–momentum (no parameter).
    Em,
    /// EDMC-1 with `χ_Γ = χ_Ω = param` (stress dissipation; velocity χ's zero).
    Edmc1,
    /// EDMC-2 with `α_Γv = param` (the paper's single α).
    Edmc2,
    /// Plain mid-point rule (no parameter).
    Midpoint,
    /// Generalized-α with `ρ∞ = param`.
    GenAlpha,
}

impl SchemeKind {
    /// All kinds, in chart order.
    pub const ALL: [SchemeKind; 5] = [
        SchemeKind::Em,
        SchemeKind::Edmc1,
        SchemeKind::Edmc2,
        SchemeKind::Midpoint,
        SchemeKind::GenAlpha,
    ];

    /// Command-line name (as `--scheme`).
    pub fn name(self) -> &'static str {
        match self {
            SchemeKind::Em => "em",
            SchemeKind::Edmc1 => "edmc1",
            SchemeKind::Edmc2 => "edmc2",
            SchemeKind::Midpoint => "midpoint",
            SchemeKind::GenAlpha => "gen-alpha",
        }
    }

    /// Parses a command-line name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the kind has a parameter (EM and mid-point have none).
    pub fn has_param(self) -> bool {
        !matches!(self, SchemeKind::Em | SchemeKind::Midpoint)
    }

    /// Symbol of the parameter for labels.
    pub fn param_symbol(self) -> &'static str {
        match self {
            SchemeKind::Edmc1 => "χ",
            SchemeKind::Edmc2 => "α",
            SchemeKind::GenAlpha => "ρ∞",
            SchemeKind::Em | SchemeKind::Midpoint => "",
        }
    }

    /// Parameter used when none is given: χ = 0.2, α = 0.5, ρ∞ = 0.8, else 0.
    pub fn default_param(self) -> f64 {
        match self {
            SchemeKind::Edmc1 => 0.2,
            SchemeKind::Edmc2 => 0.5,
            SchemeKind::GenAlpha => DEFAULT_RHO_INF,
            SchemeKind::Em | SchemeKind::Midpoint => 0.0,
        }
    }

    /// The scheme of this kind with parameter `param` (ignored by EM and mid-point).
    pub fn scheme(self, param: f64) -> Scheme {
        match self {
            SchemeKind::Em => Scheme::Em,
            SchemeKind::Midpoint => Scheme::Midpoint,
            SchemeKind::Edmc1 => Scheme::Edmc1 {
                chi_gamma: param,
                chi_omega: param,
                chi_v: 0.0,
                chi_nu: 0.0,
            },
            SchemeKind::Edmc2 => Scheme::edmc2(param),
            SchemeKind::GenAlpha => Scheme::GenAlpha { rho_inf: param },
        }
    }

    /// The order of accuracy of the family on a smooth solution: 1 for EDMC-1 (its
    /// dissipation is O(Δt)), 2 for the others (measured in `tests/study.rs`).
    pub fn nominal_order(self) -> u32 {
        match self {
            SchemeKind::Edmc1 => 1,
            _ => 2,
        }
    }

    /// Checks a parameter value (≥ 0; ρ∞ ∈ [0, 1]).
    pub fn check_param(self, param: f64) -> Result<(), String> {
        let ok = match self {
            SchemeKind::GenAlpha => (0.0..=1.0).contains(&param),
            _ => param.is_finite() && param >= 0.0,
        };
        if ok {
            Ok(())
        } else if self == SchemeKind::GenAlpha {
            Err(format!("ρ∞ must be in [0, 1] (got {})", num(param)))
        } else {
            Err(format!(
                "parameter must be a finite number ≥ 0 (got {})",
                num(param)
            ))
        }
    }
}

/// One scheme with its parameter, e.g. `edmc2:0.5`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SchemeSpec {
    /// Family.
    pub kind: SchemeKind,
    /// Parameter (0 for EM and mid-point).
    pub param: f64,
}

impl SchemeSpec {
    /// Parses `NAME` or `NAME:PARAM` (`em`, `midpoint`, `edmc1:0.2`, `edmc2:0.5`,
    /// `gen-alpha:0.8`); a missing parameter takes [`SchemeKind::default_param`].
    pub fn parse(spec: &str) -> Result<Self, StudyError> {
        let bad = |reason: String| StudyError::SchemeSpec {
            spec: spec.to_string(),
            reason,
        };
        let (name, param) = match spec.split_once(':') {
            Some((n, p)) => (n.trim(), Some(p.trim())),
            None => (spec.trim(), None),
        };
        let kind = SchemeKind::parse(name).ok_or_else(|| {
            bad("unknown scheme (expected em, edmc1, edmc2, midpoint or gen-alpha)".into())
        })?;
        let param = match param {
            None => kind.default_param(),
            Some(_) if !kind.has_param() => {
                return Err(bad(format!("{name} takes no parameter")));
            }
            Some(p) => p
                .parse::<f64>()
                .map_err(|e| bad(format!("parameter `{p}`: {e}")))?,
        };
        kind.check_param(param).map_err(bad)?;
        Ok(Self { kind, param })
    }

    /// Label for charts, e.g. `EDMC-2 α=0.5`.
    pub fn label(&self) -> String {
        let base = match self.kind {
            SchemeKind::Em => "EM",
            SchemeKind::Edmc1 => "EDMC-1",
            SchemeKind::Edmc2 => "EDMC-2",
            SchemeKind::Midpoint => "mid-point",
            SchemeKind::GenAlpha => "gen-α",
        };
        if self.kind.has_param() {
            format!("{base} {}={}", self.kind.param_symbol(), self.param)
        } else {
            base.to_string()
        }
    }
}

/// The result of one study member.
#[derive(Clone, Debug, PartialEq)]
pub struct MemberResult {
    /// Scheme family.
    pub kind: SchemeKind,
    /// Its parameter.
    pub param: f64,
    /// Time step.
    pub dt: f64,
    /// Requested end time.
    pub t_end: f64,
    /// Completed or failed.
    pub status: RunStatus,
    /// Time of the last accepted step.
    pub t_reached: f64,
    /// Failure reason (`None` when completed).
    pub reason: Option<String>,
    /// Wall time of the time loop in seconds.
    pub wall_s: f64,
    /// Total Newton iterations.
    pub newton_iters_total: usize,
    /// `max_k (H_k − H_0 − W_{0→k}) / |H_0|` over the accepted levels (≤ 0: no energy
    /// created; `|H_0|` replaced by the largest |H_k| when H_0 = 0).
    pub max_energy_growth: f64,
    /// H at the start.
    pub energy_initial: f64,
    /// H at the last accepted level.
    pub energy_final: f64,
    /// Largest per-step change of L relative to the momentum scale.
    pub max_rel_dl: f64,
    /// Largest per-step change of J relative to the angular momentum scale.
    pub max_rel_dj: f64,
    /// Nodal positions at the sample times (`samples[k]` at `k·sample_dt`, k ≥ 1) up to
    /// the last accepted level; empty when no sampling was asked for.
    pub samples: Vec<Vec<Vec3>>,
}

impl MemberResult {
    /// Fraction of the run completed, `t_reached / t_end`.
    pub fn fraction(&self) -> f64 {
        (self.t_reached / self.t_end).clamp(0.0, 1.0)
    }
}

/// Largest energy created over a run: `max_k (H_k − H_0 − W_{0→k})`, fed one accepted
/// level at a time (row 0 first).
#[derive(Clone, Copy, Debug)]
struct EnergyGrowth {
    h0: f64,
    work: f64,
    growth: f64,
    hmax: f64,
}

impl EnergyGrowth {
    fn new() -> Self {
        Self {
            h0: f64::NAN,
            work: 0.0,
            growth: f64::NEG_INFINITY,
            hmax: 0.0,
        }
    }

    fn push(&mut self, rec: &StepRecord) {
        if rec.step == 0 {
            self.h0 = rec.total;
        } else {
            self.work += rec.external_work;
        }
        self.hmax = self.hmax.max(rec.total.abs());
        self.growth = self.growth.max(rec.total - self.h0 - self.work);
    }

    /// Relative to `|H_0|` (or the largest `|H_k|` when `H_0 = 0`).
    fn relative(&self) -> f64 {
        let href = if self.h0.abs() > 0.0 {
            self.h0.abs()
        } else {
            self.hmax
        };
        if href > 0.0 {
            self.growth / href
        } else {
            0.0
        }
    }
}

/// Runs one member: `scene` with the scheme `kind(param)`, time step `dt`, to `t_end`
/// (all other integrator settings from the scene). With `sample_dt`, the nodal positions
/// are recorded at every multiple of it (linear interpolation between levels when a
/// multiple falls between two). A failed step is a result, not an error.
pub fn run_member(
    scene: &Scene,
    kind: SchemeKind,
    param: f64,
    dt: f64,
    t_end: f64,
    sample_dt: Option<f64>,
) -> Result<MemberResult, StudyError> {
    let mut params: IntegratorParams = scene.params;
    params.scheme = kind.scheme(param);
    params.dt = dt;
    params.t_end = t_end;
    let mut sim = Simulation::new(scene.model.clone(), params)?;
    let mut samples: Vec<Vec<Vec3>> = Vec::new();
    let mut prev: Option<(f64, Vec<Vec3>)> = None;
    let mut growth = EnergyGrowth::new();
    let outcome = run(
        &mut sim,
        1,
        |rec: &StepRecord, s: &Simulation| -> Result<(), std::convert::Infallible> {
            growth.push(rec);
            let r = &s.state().r;
            if let (Some(sdt), Some((t0, r0))) = (sample_dt, prev.as_ref()) {
                // Every sample time in (t0, t] (tolerance: round-off of accumulated t).
                let tol = 1e-9 * dt;
                loop {
                    let ts = (samples.len() + 1) as f64 * sdt;
                    if ts > rec.t + tol || ts > t_end + tol {
                        break;
                    }
                    let w = ((ts - t0) / (rec.t - t0)).clamp(0.0, 1.0);
                    samples.push(r0.iter().zip(r).map(|(a, b)| a + (b - a) * w).collect());
                }
            }
            prev = Some((rec.t, r.clone()));
            Ok(())
        },
    )
    .unwrap_or_else(|never| match never {});
    Ok(MemberResult {
        kind,
        param,
        dt,
        t_end,
        status: outcome.status,
        t_reached: outcome.t_reached,
        reason: outcome.reason,
        wall_s: outcome.wall_s,
        newton_iters_total: outcome.newton_iters_total,
        max_energy_growth: growth.relative(),
        energy_initial: outcome.energy_initial,
        energy_final: outcome.energy_final,
        max_rel_dl: outcome.max_rel_dl,
        max_rel_dj: outcome.max_rel_dj,
        samples,
    })
}

/// Maps `f` over `items` on `jobs` threads (at least 1), keeping the order.
pub fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1).min(items.len().max(1)) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= items.len() {
                    break;
                }
                let r = f(&items[i]);
                if let Ok(mut o) = out.lock() {
                    o[i] = Some(r);
                }
            });
        }
    });
    out.into_inner()
        .unwrap_or_default()
        .into_iter()
        .map(|r| r.expect("every item mapped"))
        .collect()
}

/// Settings of a work–precision study.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkPrecisionConfig {
    /// Schemes with their parameters.
    pub schemes: Vec<SchemeSpec>,
    /// Time steps.
    pub dts: Vec<f64>,
    /// End time.
    pub t_end: f64,
    /// Δt of the EM reference run (default in the CLI: smallest Δt / 16).
    pub reference_dt: f64,
    /// Worker threads.
    pub jobs: usize,
}

impl WorkPrecisionConfig {
    /// Checks the settings without running anything: the end time, the time steps and the
    /// reference Δt finite and > 0 (each error names its setting), at least one scheme, and
    /// no Δt above the end time.
    pub fn check(&self) -> Result<(), StudyError> {
        check_list("t_end", &[self.t_end], true)?;
        check_list("dt", &self.dts, true)?;
        check_list("reference dt", &[self.reference_dt], true)?;
        if self.schemes.is_empty() {
            return Err(StudyError::Invalid("schemes: empty list".into()));
        }
        let sample_dt = self.dts.iter().copied().fold(0.0, f64::max);
        if sample_dt > self.t_end {
            return Err(StudyError::Invalid(format!(
                "the largest Δt ({}) exceeds the end time ({})",
                num(sample_dt),
                num(self.t_end)
            )));
        }
        Ok(())
    }
}

/// One row of `work_precision.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkPrecisionRow {
    /// Scheme and parameter.
    pub spec: SchemeSpec,
    /// Time step.
    pub dt: f64,
    /// L2-in-time position error against the reference (NaN when the run failed).
    pub error: f64,
    /// Wall time of the run in seconds.
    pub wall_s: f64,
    /// Completed or failed.
    pub status: RunStatus,
    /// Total Newton iterations.
    pub newton_iters_total: usize,
    /// Observed order of this row's scheme/parameter over its asymptotic range (same on
    /// all its rows; NaN when it has none, see [`asymptotic_fit`]).
    pub observed_order: f64,
    /// Smallest Δt of the range the order was fitted over (NaN when none).
    pub fit_dt_min: f64,
    /// Largest Δt of the range the order was fitted over (NaN when none).
    pub fit_dt_max: f64,
    /// Failure reason, if any.
    pub reason: Option<String>,
}

/// The result of a work–precision study.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkPrecision {
    /// Scene name.
    pub scene: String,
    /// One row per scheme/parameter and Δt.
    pub rows: Vec<WorkPrecisionRow>,
    /// Δt of the reference run.
    pub reference_dt: f64,
    /// Sampling interval of the error.
    pub sample_dt: f64,
    /// End time.
    pub t_end: f64,
}

/// Least-squares slope of `ln y` against `ln x` over the finite positive pairs (NaN with
/// fewer than two).
pub fn loglog_slope(points: &[(f64, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if pts.len() < 2 {
        return f64::NAN;
    }
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        f64::NAN
    }
}

/// The local orders of an asymptotic range may spread (largest − smallest) by at most this
/// fraction of their mean (see [`asymptotic_fit`]).
pub const ORDER_AGREEMENT: f64 = 0.15;

/// The observed order of a convergence series and the Δt range it was fitted over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrderFit {
    /// Least-squares slope of log error against log Δt over the range.
    pub order: f64,
    /// Smallest Δt of the range.
    pub dt_min: f64,
    /// Largest Δt of the range.
    pub dt_max: f64,
}

impl OrderFit {
    /// Whether `dt` lies in the fitted range (to round-off).
    pub fn contains(&self, dt: f64) -> bool {
        dt >= self.dt_min * (1.0 - 1e-12) && dt <= self.dt_max * (1.0 + 1e-12)
    }
}

/// Local orders `ln(e_i/e_{i+1}) / ln(Δt_i/Δt_{i+1})` of `(Δt, error)` pairs sorted by
/// decreasing Δt.
pub fn local_orders(sorted: &[(f64, f64)]) -> Vec<f64> {
    sorted
        .windows(2)
        .map(|w| (w[0].1 / w[1].1).ln() / (w[0].0 / w[1].0).ln())
        .collect()
}

/// The observed order over the **asymptotic range** of `(Δt, error)` pairs: the longest
/// run of the finest Δt (at least three, i.e. two intervals) whose local orders are
/// positive and all within [`ORDER_AGREEMENT`] × their mean of each other; the order is
/// the least-squares slope of log error against log Δt over that run. Failed runs (error
/// NaN or ≤ 0) are left out first. `None` when no such run exists: the error at these Δt
/// is not yet (or no longer, at a tolerance floor) a power of Δt.
pub fn asymptotic_fit(points: &[(f64, f64)]) -> Option<OrderFit> {
    let mut pts: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(h, e)| h.is_finite() && e.is_finite() && *h > 0.0 && *e > 0.0)
        .collect();
    pts.sort_by(|a, b| b.0.total_cmp(&a.0));
    pts.dedup_by(|a, b| a.0 == b.0);
    let n = pts.len();
    // Longest first: the runs pts[start..] ending at the finest Δt.
    (0..n.saturating_sub(2)).find_map(|start| {
        let run = &pts[start..];
        let local = local_orders(run);
        let mean = local.iter().sum::<f64>() / local.len() as f64;
        let lo = local.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = local.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo > 0.0 && hi - lo <= ORDER_AGREEMENT * mean).then(|| OrderFit {
            order: loglog_slope(run),
            dt_min: run[run.len() - 1].0,
            dt_max: run[0].0,
        })
    })
}

/// L2-in-time error between two sampled trajectories over the first `k` samples.
fn l2_error(a: &[Vec<Vec3>], b: &[Vec<Vec3>]) -> f64 {
    let k = a.len().min(b.len());
    if k == 0 {
        return f64::NAN;
    }
    let mut s = 0.0;
    for (ra, rb) in a.iter().zip(b).take(k) {
        let n = ra.len().max(1) as f64;
        s += ra
            .iter()
            .zip(rb)
            .map(|(x, y)| (x - y).norm_squared())
            .sum::<f64>()
            / n;
    }
    (s / k as f64).sqrt()
}

fn check_list(name: &str, v: &[f64], positive: bool) -> Result<(), StudyError> {
    if v.is_empty() {
        return Err(StudyError::Invalid(format!("{name}: empty list")));
    }
    if let Some(x) = v
        .iter()
        .find(|x| !x.is_finite() || (positive && **x <= 0.0))
    {
        return Err(StudyError::Invalid(format!(
            "{name}: every value must be a finite number{} (got {})",
            if positive { " > 0" } else { "" },
            num(*x)
        )));
    }
    Ok(())
}

/// Runs a work–precision study of `scene` (see the module docs for the error measure).
pub fn work_precision(
    scene: &Scene,
    cfg: &WorkPrecisionConfig,
) -> Result<WorkPrecision, StudyError> {
    cfg.check()?;
    let sample_dt = cfg.dts.iter().copied().fold(0.0, f64::max);
    // Every member keeps its samples (nodal positions every `sample_dt`) to the end.
    let count = (cfg.schemes.len() as u64)
        .saturating_mul(cfg.dts.len() as u64)
        .saturating_add(1);
    let samples = (cfg.t_end / sample_dt).min(u64::MAX as f64) as u64 + 2;
    let member = Footprint {
        kept_bytes: samples.saturating_mul(24 * scene.model.nodes.len() as u64),
        ..Footprint::of_model(&scene.model)
    };
    crate::scene::limits::check_batch("this study", count, &member)
        .map_err(|e| StudyError::Invalid(e.to_string()))?;
    let mut members: Vec<(SchemeKind, f64, f64)> = vec![(SchemeKind::Em, 0.0, cfg.reference_dt)];
    for s in &cfg.schemes {
        for &dt in &cfg.dts {
            members.push((s.kind, s.param, dt));
        }
    }
    let results = parallel_map(&members, cfg.jobs, |&(k, p, dt)| {
        run_member(scene, k, p, dt, cfg.t_end, Some(sample_dt))
    });
    let mut results = results.into_iter().collect::<Result<Vec<_>, _>>()?;
    let reference = results.remove(0);
    if reference.status != RunStatus::Completed {
        return Err(StudyError::Reference {
            dt: cfg.reference_dt,
            reason: reference.reason.unwrap_or_default(),
        });
    }
    let mut rows: Vec<WorkPrecisionRow> = results
        .into_iter()
        .map(|m| {
            let error = if m.status == RunStatus::Completed {
                l2_error(&m.samples, &reference.samples)
            } else {
                f64::NAN
            };
            WorkPrecisionRow {
                spec: SchemeSpec {
                    kind: m.kind,
                    param: m.param,
                },
                dt: m.dt,
                error,
                wall_s: m.wall_s,
                status: m.status,
                newton_iters_total: m.newton_iters_total,
                observed_order: f64::NAN,
                fit_dt_min: f64::NAN,
                fit_dt_max: f64::NAN,
                reason: m.reason,
            }
        })
        .collect();
    for s in &cfg.schemes {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.spec == *s)
            .map(|r| (r.dt, r.error))
            .collect();
        let fit = asymptotic_fit(&pts);
        rows.iter_mut().filter(|r| r.spec == *s).for_each(|r| {
            r.observed_order = fit.map_or(f64::NAN, |f| f.order);
            r.fit_dt_min = fit.map_or(f64::NAN, |f| f.dt_min);
            r.fit_dt_max = fit.map_or(f64::NAN, |f| f.dt_max);
        });
    }
    Ok(WorkPrecision {
        scene: scene.name.clone(),
        rows,
        reference_dt: cfg.reference_dt,
        sample_dt,
        t_end: cfg.t_end,
    })
}

/// Settings of a stability study.
#[derive(Clone, Debug, PartialEq)]
pub struct StabilityConfig {
    /// Scheme families (one chart panel each).
    pub kinds: Vec<SchemeKind>,
    /// Dissipation parameters of EDMC-1 (χ) and EDMC-2 (α).
    pub params: Vec<f64>,
    /// ρ∞ values of generalized-α.
    pub rho_infs: Vec<f64>,
    /// Time steps.
    pub dts: Vec<f64>,
    /// End time.
    pub t_end: f64,
    /// Worker threads.
    pub jobs: usize,
}

impl StabilityConfig {
    /// Checks the settings without running anything: the end time and the time steps
    /// finite and > 0, at least one scheme, and every family's parameter values present
    /// and in its range.
    pub fn check(&self) -> Result<(), StudyError> {
        check_list("t_end", &[self.t_end], true)?;
        check_list("dt", &self.dts, true)?;
        if self.kinds.is_empty() {
            return Err(StudyError::Invalid("schemes: empty list".into()));
        }
        for &k in &self.kinds {
            let ps = self.params_of(k);
            if ps.is_empty() {
                return Err(StudyError::Invalid(format!(
                    "no parameter values for {}",
                    k.name()
                )));
            }
            for p in ps {
                k.check_param(p).map_err(|reason| StudyError::SchemeSpec {
                    spec: format!("{}:{}", k.name(), num(p)),
                    reason,
                })?;
            }
        }
        Ok(())
    }

    /// The parameter axis of a family (a single 0 for EM and mid-point).
    pub fn params_of(&self, kind: SchemeKind) -> Vec<f64> {
        match kind {
            SchemeKind::Em | SchemeKind::Midpoint => vec![0.0],
            SchemeKind::GenAlpha => self.rho_infs.clone(),
            SchemeKind::Edmc1 | SchemeKind::Edmc2 => self.params.clone(),
        }
    }
}

/// The result of a stability study: one member per grid cell, in the order
/// kind → parameter → Δt.
#[derive(Clone, Debug, PartialEq)]
pub struct Stability {
    /// Scene name.
    pub scene: String,
    /// The grid.
    pub config: StabilityConfig,
    /// Members.
    pub cells: Vec<MemberResult>,
}

/// Runs a stability study of `scene` on the CPU (`cfg.jobs` threads).
pub fn stability(scene: &Scene, cfg: &StabilityConfig) -> Result<Stability, StudyError> {
    stability_on(scene, cfg, &Executor::Cpu)
}

/// Runs a stability study of `scene` on `exec`. On the GPU the grid is one batch
/// ([`crate::batch::run_members`]): the members of the schemes the GPU kernel implements
/// (EM, EDMC-1, EDMC-2) share each element dispatch; the baselines run on the CPU kernel
/// inside the same batch. The cells are the same as on the CPU path.
pub fn stability_on(
    scene: &Scene,
    cfg: &StabilityConfig,
    exec: &Executor,
) -> Result<Stability, StudyError> {
    cfg.check()?;
    // The grid's size before it is built; on the GPU every member keeps its history.
    let count = cfg
        .kinds
        .iter()
        .map(|&k| cfg.params_of(k).len() as u64)
        .sum::<u64>()
        .saturating_mul(cfg.dts.len() as u64);
    let steps = cfg
        .dts
        .iter()
        .map(|dt| (cfg.t_end / dt).min(u64::MAX as f64) as u64 + 1)
        .max()
        .unwrap_or(0);
    let member = Footprint {
        kept_bytes: if matches!(exec, Executor::Gpu(_)) {
            steps.saturating_mul(crate::scene::limits::BYTES_PER_RECORD)
        } else {
            0
        },
        ..Footprint::of_model(&scene.model)
    };
    crate::scene::limits::check_batch("this study", count, &member)
        .map_err(|e| StudyError::Invalid(e.to_string()))?;
    let mut members = Vec::new();
    for &k in &cfg.kinds {
        for p in cfg.params_of(k) {
            for &dt in &cfg.dts {
                members.push((k, p, dt));
            }
        }
    }
    let cells = match exec {
        Executor::Cpu => parallel_map(&members, cfg.jobs, |&(k, p, dt)| {
            run_member(scene, k, p, dt, cfg.t_end, None)
        })
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?,
        Executor::Gpu(_) => batched_cells(scene, &members, cfg.t_end, exec)?,
    };
    Ok(Stability {
        scene: scene.name.clone(),
        config: cfg.clone(),
        cells,
    })
}

/// The grid `(kind, param, dt)` as one batch on `exec`, turned into study cells.
fn batched_cells(
    scene: &Scene,
    grid: &[(SchemeKind, f64, f64)],
    t_end: f64,
    exec: &Executor,
) -> Result<Vec<MemberResult>, StudyError> {
    let members: Vec<Member> = grid
        .iter()
        .map(|&(k, p, dt)| {
            let mut params: IntegratorParams = scene.params;
            params.scheme = k.scheme(p);
            params.dt = dt;
            params.t_end = t_end;
            Member {
                model: scene.model.clone(),
                params,
            }
        })
        .collect();
    let opts = BatchOptions {
        keep_history: true,
        ..Default::default()
    };
    let mut out: Vec<Option<MemberResult>> = vec![None; grid.len()];
    run_members(&members, exec, opts, |r| {
        let (kind, param, dt) = grid[r.index];
        let mut growth = EnergyGrowth::new();
        r.history.iter().for_each(|rec| growth.push(rec));
        let o = r.outcome;
        out[r.index] = Some(MemberResult {
            kind,
            param,
            dt,
            t_end,
            status: o.status,
            t_reached: o.t_reached,
            reason: o.reason,
            wall_s: o.wall_s,
            newton_iters_total: o.newton_iters_total,
            max_energy_growth: growth.relative(),
            energy_initial: o.energy_initial,
            energy_final: o.energy_final,
            max_rel_dl: o.max_rel_dl,
            max_rel_dj: o.max_rel_dj,
            samples: Vec::new(),
        });
    })?;
    Ok(out
        .into_iter()
        .map(|c| c.expect("every member reports"))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scheme_specs_parse_with_defaults_and_ranges() {
        let s = SchemeSpec::parse("edmc2:0.7").unwrap();
        assert_eq!((s.kind, s.param), (SchemeKind::Edmc2, 0.7));
        assert_eq!(
            SchemeSpec::parse("gen-alpha").unwrap().param,
            DEFAULT_RHO_INF
        );
        assert_eq!(SchemeSpec::parse("em").unwrap().label(), "EM");
        assert!(SchemeSpec::parse("em:1").is_err());
        assert!(SchemeSpec::parse("gen-alpha:1.5").is_err());
        assert!(SchemeSpec::parse("edmc1:-1").is_err());
        assert!(SchemeSpec::parse("rk4").is_err());
    }

    #[test]
    fn loglog_slope_recovers_a_power_law() {
        let pts: Vec<(f64, f64)> = [0.1, 0.05, 0.025]
            .iter()
            .map(|&h| (h, 3.0 * h * h))
            .collect();
        assert!((loglog_slope(&pts) - 2.0).abs() < 1e-12);
        // Failed runs (NaN) are ignored; one point is not a fit.
        assert!(loglog_slope(&[(0.1, 1.0), (0.05, f64::NAN)]).is_nan());
    }

    /// `(Δt, error)` for `dts` with the given local orders, finest last.
    fn series(dts: &[f64], local: &[f64]) -> Vec<(f64, f64)> {
        let mut e = 1.0;
        let mut out = vec![(dts[0], e)];
        for (w, p) in dts.windows(2).zip(local) {
            e *= (w[1] / w[0]).powf(*p);
            out.push((w[1], e));
        }
        out
    }

    #[test]
    fn asymptotic_fit_takes_the_longest_agreeing_run_of_finest_steps() {
        let dts = [0.08, 0.04, 0.02, 0.01, 0.005];
        // Pre-asymptotic at the coarse end, then order 2 (local orders within 15 %).
        let f = asymptotic_fit(&series(&dts, &[0.3, 1.2, 2.1, 1.95])).unwrap();
        assert_eq!((f.dt_min, f.dt_max), (0.005, 0.02));
        assert!((f.order - 2.0).abs() < 0.15, "{f:?}");
        assert!(f.contains(0.01) && !f.contains(0.04));
        // Every interval agrees: the whole series; order as the plain fit.
        let pts = series(&dts, &[2.0, 2.05, 1.98, 2.02]);
        let f = asymptotic_fit(&pts).unwrap();
        assert_eq!((f.dt_min, f.dt_max), (0.005, 0.08));
        assert!((f.order - loglog_slope(&pts)).abs() < 1e-12);
        // Failed runs are dropped before the ranges are formed (a failed coarse step).
        let mut pts = series(&dts, &[2.0, 2.0, 2.0, 2.0]);
        pts[0].1 = f64::NAN;
        assert_eq!(asymptotic_fit(&pts).unwrap().dt_max, 0.04);
    }

    #[test]
    fn no_asymptotic_range_when_the_finest_orders_disagree_or_stall() {
        let dts = [0.1, 0.05, 0.025, 0.0125];
        // The frame's EM (orders 0.31, 1.23, 1.01): the finest two differ by 20 %.
        assert_eq!(asymptotic_fit(&series(&dts, &[0.31, 1.23, 1.01])), None);
        // A tolerance floor: the error stops falling at the finest step.
        assert_eq!(asymptotic_fit(&series(&dts, &[2.0, 2.0, 0.0])), None);
        // The error grows under refinement.
        assert_eq!(asymptotic_fit(&series(&dts, &[-1.0, -1.0, -1.0])), None);
        // Two intervals are the least: three points with agreeing orders fit, two do not.
        assert!(asymptotic_fit(&series(&dts[1..], &[1.0, 1.0])).is_some());
        assert_eq!(asymptotic_fit(&series(&dts[2..], &[1.0])), None);
    }
}
