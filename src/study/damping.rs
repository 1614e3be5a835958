//! The dissipation guide: how fast each dissipation parameter damps the first axial and
//! the first bending mode of a clamped rod (`cosserat study damping`).
//!
//! The scene must be one straight, uniform rod clamped at its first node and otherwise
//! free (no loads, gravity, links or point masses): the built-in `cantilever` is one. For
//! each mode the rod starts undeformed with the velocity field of the Euler–Bernoulli /
//! bar mode shape (first axial: `sin(πs/2L)` along the axis; first bending: the clamped–
//! free beam mode `φ(s)` along the rod's `d2`, with the sections turning at `φ'(s)`), of
//! amplitude `tip displacement = amplitude · L`. The run goes `periods` periods of the
//! mode's analytic frequency `ω` at `steps_per_period` steps each (so `ωΔt = 2π /
//! steps_per_period`), and the decay rate `r` is the least-squares slope of `ln H(t)`.
//! Reported: the equivalent modal damping ratio `ζ = r / 2ω` and the fraction of energy
//! lost per period, `1 − e^{−rT} = 1 − exp(−4πζ)`.
//!
//! EDMC-1's χ's act linearly (ζ does not depend on the amplitude); EDMC-2's α's act
//! through the strain and velocity *increments*, so their ζ grows with the amplitude and
//! with `ωΔt`: they remove what the step does not resolve and leave slow, small motions
//! nearly undamped. Physical (material) damping is a scene feature, not a scheme one.

use super::{parallel_map, StudyError};
use crate::integrator::run::run;
use crate::integrator::{Scheme, Simulation};
use crate::model::Vec3;
use crate::observe::record::{RunStatus, StepRecord};
use crate::scene::Scene;

/// The two modes of the guide.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModeKind {
    /// First axial (bar) mode of the clamped–free rod: `ω = (π/2L) √(EA/ρA)`.
    Axial,
    /// First bending mode (in the `d1`–axis plane, along `d2`): `ω = 1.8751² √(EI₁₁/ρA L⁴)`.
    Bending,
}

impl ModeKind {
    /// Name in the CSV and chart.
    pub fn name(self) -> &'static str {
        match self {
            ModeKind::Axial => "axial",
            ModeKind::Bending => "bending",
        }
    }
}

/// One dissipation parameter of the guide: its name and the scheme with only it set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Parameter {
    /// Scene key (`chi_gamma`, …, `alpha_on`).
    pub key: &'static str,
    /// Symbol for the chart.
    pub symbol: &'static str,
    /// What it damps, for the docs and the chart legend.
    pub acts_on: &'static str,
}

/// Every dissipation parameter, EDMC-1's four then EDMC-2's four.
pub const PARAMETERS: [Parameter; 8] = [
    Parameter {
        key: "chi_gamma",
        symbol: "EDMC-1 χ_Γ",
        acts_on: "force strains Γ (axial, shear)",
    },
    Parameter {
        key: "chi_omega",
        symbol: "EDMC-1 χ_Ω",
        acts_on: "moment strains Ω (bending, torsion)",
    },
    Parameter {
        key: "chi_v",
        symbol: "EDMC-1 χ_v",
        acts_on: "translational speed",
    },
    Parameter {
        key: "chi_nu",
        symbol: "EDMC-1 χ_ν",
        acts_on: "director speed",
    },
    Parameter {
        key: "alpha_gv",
        symbol: "EDMC-2 α_Γv",
        acts_on: "Γ, as the translational speed changes",
    },
    Parameter {
        key: "alpha_gn",
        symbol: "EDMC-2 α_Γν",
        acts_on: "Γ, as the director speed changes",
    },
    Parameter {
        key: "alpha_ov",
        symbol: "EDMC-2 α_Ωv",
        acts_on: "Ω, as the translational speed changes",
    },
    Parameter {
        key: "alpha_on",
        symbol: "EDMC-2 α_Ων",
        acts_on: "Ω, as the director speed changes",
    },
];

impl Parameter {
    /// The scheme with this parameter at `value` and every other one zero.
    pub fn scheme(&self, value: f64) -> Scheme {
        let mut c = [0.0; 4];
        let k = PARAMETERS
            .iter()
            .position(|p| p.key == self.key)
            .unwrap_or(0);
        c[k % 4] = value;
        if k < 4 {
            Scheme::Edmc1 {
                chi_gamma: c[0],
                chi_omega: c[1],
                chi_v: c[2],
                chi_nu: c[3],
            }
        } else {
            Scheme::Edmc2 {
                alpha_gv: c[0],
                alpha_gn: c[1],
                alpha_ov: c[2],
                alpha_on: c[3],
            }
        }
    }
}

/// Settings of the damping study.
#[derive(Clone, Debug, PartialEq)]
pub struct DampingConfig {
    /// Parameter values (each > 0).
    pub values: Vec<f64>,
    /// Periods of the mode each run covers.
    pub periods: f64,
    /// Steps per period (`ωΔt = 2π / steps_per_period`).
    pub steps_per_period: usize,
    /// Tip displacement amplitude of the mode, relative to the rod length.
    pub amplitude: f64,
    /// Threads.
    pub jobs: usize,
}

/// One run of the study.
#[derive(Clone, Debug, PartialEq)]
pub struct DampingRow {
    /// Mode.
    pub mode: ModeKind,
    /// Parameter key (`em` for the undamped reference).
    pub param: &'static str,
    /// Parameter value.
    pub value: f64,
    /// Analytic mode frequency [rad/s].
    pub omega: f64,
    /// Time step.
    pub dt: f64,
    /// Fitted decay rate `r` of `H` (`H ∝ e^{−r t}`) [1/s]; NaN when the run failed.
    pub energy_decay_rate: f64,
    /// Equivalent modal damping ratio `ζ = r / 2ω`.
    pub zeta: f64,
    /// Fraction of the energy lost per period, `1 − exp(−4πζ)`.
    pub loss_per_period: f64,
    /// Completed or failed.
    pub status: RunStatus,
    /// Why it failed.
    pub reason: Option<String>,
}

/// The whole study.
#[derive(Clone, Debug, PartialEq)]
pub struct Damping {
    /// Scene name.
    pub scene: String,
    /// Settings.
    pub config: DampingConfig,
    /// Rows: per mode, EM first, then every parameter at every value.
    pub rows: Vec<DampingRow>,
}

/// The straight clamped rod a damping study needs: length, axis, transverse direction
/// (`d2`), `EA`, `EI₁₁`, `ρA`.
struct Rod {
    length: f64,
    axis: Vec3,
    d2: Vec3,
    ea: f64,
    ei: f64,
    a_rho: f64,
}

fn rod_of(scene: &Scene) -> Result<Rod, StudyError> {
    let m = &scene.model;
    let bad = |why: &str| {
        StudyError::Invalid(format!(
            "study damping needs one straight uniform rod clamped at its first node and otherwise free; scene `{}` {why}",
            scene.name
        ))
    };
    if m.rods.len() != 1 || m.elements.is_empty() {
        return Err(bad("does not have exactly one rod"));
    }
    if !m.links.is_empty() || !m.loads.is_empty() || m.gravity != Vec3::zeros() {
        return Err(bad("has links, loads or gravity"));
    }
    if m.point_mass.iter().any(|&x| x != 0.0) {
        return Err(bad("has point masses"));
    }
    let s0 = m.supports[0];
    if !(s0.translation && s0.rotation)
        || m.supports[1..].iter().any(|s| s.translation || s.rotation)
    {
        return Err(bad("is not clamped at its first node only"));
    }
    let (r0, rn) = (m.nodes[0], m.nodes[m.n_nodes() - 1]);
    let length = (rn - r0).norm();
    let axis = (rn - r0) / length;
    for r in &m.nodes {
        let off = (r - r0) - axis * (r - r0).dot(&axis);
        if off.norm() > 1e-9 * length {
            return Err(bad("is not straight"));
        }
    }
    let p = &m.elements[0].props;
    if m.elements.iter().any(|e| {
        e.props.c_gamma != p.c_gamma || e.props.c_omega != p.c_omega || e.props.a_rho != p.a_rho
    }) {
        return Err(bad("is not uniform"));
    }
    Ok(Rod {
        length,
        axis,
        d2: m.elements[0].ref_triad[0].column(1).into_owned(),
        ea: p.c_gamma[2],
        ei: p.c_omega[(0, 0)],
        a_rho: p.a_rho,
    })
}

/// `βL` of the first clamped–free beam mode.
const BETA_L: f64 = 1.875_104_068_711_961;

/// The clamped–free beam mode `φ(x)` and `φ'(x)` for `x = s/L`, scaled by `β`.
fn beam_mode(x: f64) -> (f64, f64) {
    let b = BETA_L;
    let sigma = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let y = b * x;
    let phi = y.cosh() - y.cos() - sigma * (y.sinh() - y.sin());
    let dphi = b * (y.sinh() + y.sin() - sigma * (y.cosh() - y.cos()));
    (phi, dphi)
}

fn omega_of(rod: &Rod, mode: ModeKind) -> f64 {
    let l = rod.length;
    match mode {
        ModeKind::Axial => std::f64::consts::FRAC_PI_2 / l * (rod.ea / rod.a_rho).sqrt(),
        ModeKind::Bending => BETA_L * BETA_L * (rod.ei / (rod.a_rho * l.powi(4))).sqrt(),
    }
}

/// The scene started in `mode` with tip displacement amplitude `amp · L`.
fn excited(scene: &Scene, rod: &Rod, mode: ModeKind, amp: f64) -> Scene {
    let mut s = scene.clone();
    let m = &mut s.model;
    let l = rod.length;
    let w = omega_of(rod, mode);
    let r0 = m.nodes[0];
    let (phi_tip, _) = beam_mode(1.0);
    for a in 0..m.n_nodes() {
        let x = (m.nodes[a] - r0).dot(&rod.axis) / l;
        match mode {
            ModeKind::Axial => {
                // u(s, t) = U sin(πs/2L) sin ωt: v(s, 0) = ω U sin(πs/2L), U = amp L.
                m.velocity0[a] = rod.axis * (w * amp * l * (std::f64::consts::FRAC_PI_2 * x).sin());
                m.omega0[a] = Vec3::zeros();
            }
            ModeKind::Bending => {
                let (phi, dphi) = beam_mode(x);
                let v = w * amp * l / phi_tip;
                m.velocity0[a] = rod.d2 * (v * phi);
                // The section turns with the slope: θ = w' (axis × d2), w' = v φ'/L.
                m.omega0[a] = rod.axis.cross(&rod.d2) * (v * dphi / l);
            }
        }
    }
    s
}

/// Least-squares slope of `ln H` against `t` (H > 0 samples).
fn log_slope(points: &[(f64, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(_, h)| *h > 0.0 && h.is_finite())
        .map(|&(t, h)| (t, h.ln()))
        .collect();
    let n = pts.len() as f64;
    if n < 2.0 {
        return f64::NAN;
    }
    let (mt, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mt) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mt).powi(2)).sum();
    sxy / sxx
}

/// One run: the energy decay of `mode` under `scheme`.
fn run_one(
    scene: &Scene,
    rod: &Rod,
    mode: ModeKind,
    param: &'static str,
    value: f64,
    scheme: Scheme,
    cfg: &DampingConfig,
) -> Result<DampingRow, StudyError> {
    let s = excited(scene, rod, mode, cfg.amplitude);
    let omega = omega_of(rod, mode);
    let period = 2.0 * std::f64::consts::PI / omega;
    let dt = period / cfg.steps_per_period as f64;
    let mut params = s.params;
    params.scheme = scheme;
    params.dt = dt;
    params.t_end = cfg.periods * period;
    let mut sim = Simulation::new(s.model.clone(), params)?;
    let mut h: Vec<(f64, f64)> = vec![(0.0, sim.invariants().total())];
    let out = run(
        &mut sim,
        1,
        |r: &StepRecord, _: &Simulation| -> Result<(), std::convert::Infallible> {
            h.push((r.t, r.total));
            Ok(())
        },
    )
    .unwrap_or_else(|never| match never {});
    let (rate, zeta) = if out.status == RunStatus::Completed {
        let r = -log_slope(&h);
        (r, r / (2.0 * omega))
    } else {
        (f64::NAN, f64::NAN)
    };
    Ok(DampingRow {
        mode,
        param,
        value,
        omega,
        dt,
        energy_decay_rate: rate,
        zeta,
        loss_per_period: 1.0 - (-4.0 * std::f64::consts::PI * zeta).exp(),
        status: out.status,
        reason: out.reason,
    })
}

/// Runs the damping study on `scene` (see the module).
pub fn damping(scene: &Scene, cfg: &DampingConfig) -> Result<Damping, StudyError> {
    if cfg.values.is_empty() || cfg.values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(StudyError::Invalid(
            "study damping: --values must be finite numbers > 0".into(),
        ));
    }
    if !(cfg.periods.is_finite() && cfg.periods > 0.0) || cfg.steps_per_period < 4 {
        return Err(StudyError::Invalid(
            "study damping: --periods must be > 0 and --steps-per-period ≥ 4".into(),
        ));
    }
    if !(cfg.amplitude.is_finite() && cfg.amplitude > 0.0) {
        return Err(StudyError::Invalid(
            "study damping: --amplitude must be > 0".into(),
        ));
    }
    let rod = rod_of(scene)?;
    let mut jobs: Vec<(ModeKind, &'static str, f64, Scheme)> = Vec::new();
    for mode in [ModeKind::Axial, ModeKind::Bending] {
        jobs.push((mode, "em", 0.0, Scheme::Em));
        for p in &PARAMETERS {
            for &v in &cfg.values {
                jobs.push((mode, p.key, v, p.scheme(v)));
            }
        }
    }
    let rows = parallel_map(&jobs, cfg.jobs, |&(mode, key, v, scheme)| {
        run_one(scene, &rod, mode, key, v, scheme, cfg)
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    Ok(Damping {
        scene: scene.name.clone(),
        config: cfg.clone(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_mode_is_clamped_and_free() {
        let (phi0, dphi0) = beam_mode(0.0);
        assert!(phi0.abs() < 1e-15 && dphi0.abs() < 1e-15);
        // Free end: φ'' = φ''' = 0; check φ'' by differences of φ'.
        let h = 1e-6;
        let d2 = (beam_mode(1.0).1 - beam_mode(1.0 - h).1) / h;
        assert!(d2.abs() < 1e-4 * beam_mode(1.0).0, "φ''(L) = {d2}");
    }

    #[test]
    fn every_parameter_sets_only_itself() {
        for (k, p) in PARAMETERS.iter().enumerate() {
            let s = p.scheme(0.5);
            let v = match s {
                Scheme::Edmc1 {
                    chi_gamma,
                    chi_omega,
                    chi_v,
                    chi_nu,
                } => [chi_gamma, chi_omega, chi_v, chi_nu],
                Scheme::Edmc2 {
                    alpha_gv,
                    alpha_gn,
                    alpha_ov,
                    alpha_on,
                } => [alpha_gv, alpha_gn, alpha_ov, alpha_on],
                _ => panic!("{s:?}"),
            };
            assert_eq!(v.iter().filter(|&&x| x == 0.5).count(), 1);
            assert_eq!(v[k % 4], 0.5);
        }
    }
}
