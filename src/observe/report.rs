//! The model report of `cosserat check`: what a run of the scene will solve and what it
//! will cost, before running it.
//!
//! Frequencies are **estimates** from the element constants (not an eigenvalue solve):
//! the highest wave frequency of a two-node element with consistent mass, `2√3 c / h` with
//! `c² = stiffness / inertia` for the axial, shear, bending and torsion pairs, and the
//! shear cut-off `sqrt(G A / Iρ)` of the director (thickness-shear) mode, combined as
//! `sqrt(ω_cut² + ω_wave²)`. On the frame this gives 315 rad/s against the ≈ 310 rad/s of
//! its highest mode.

use std::fmt;

use crate::integrator::params::{IntegratorParams, Scheme};
use crate::model::{Model, Vec3};

/// What `check` reports beyond the scene's own description.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelReport {
    /// Newton unknowns per step (after supports, the plane and dissipation unknowns).
    pub unknowns: usize,
    /// The linear solver the Newton steps will use.
    pub linear_solver: String,
    /// Total mass (rods and point masses).
    pub mass: f64,
    /// Centre of mass (centerlines and point masses).
    pub center_of_mass: Vec3,
    /// Principal moments of inertia about the centre of mass of the centerlines and point
    /// masses (cross-section rotary inertia not included), ascending.
    pub principal_inertia: [f64; 3],
    /// Dissipation parameters and what they act on, one line each (empty for EM).
    pub dissipation: Vec<String>,
    /// Estimated highest frequency ω_max in rad/s and the element where it is reached
    /// (`usize::MAX`: a rigid link).
    pub omega_max: (f64, usize),
    /// `ω_max Δt`.
    pub omega_dt: f64,
    /// Steps of the run.
    pub steps: usize,
    /// Bytes of `history.csv` when every step is written (≈ 420 bytes per row).
    pub history_bytes: u64,
    /// Bytes of `trajectory.npz` per frame.
    pub trajectory_bytes_per_frame: u64,
    /// Bytes of one `.vtu` frame.
    pub vtu_bytes_per_frame: u64,
}

/// Builds the report of `model` run with `params` (`unknowns` and `linear_solver` from the
/// simulation set up for it).
pub fn model_report(
    model: &Model,
    params: &IntegratorParams,
    unknowns: usize,
    linear_solver: &str,
) -> ModelReport {
    // Mass, centre and inertia of the centerlines (linear density, exact for segments)
    // and point masses.
    let mut mass = 0.0;
    let mut first = Vec3::zeros();
    let mut second = nalgebra::Matrix3::<f64>::zeros();
    for el in &model.elements {
        let m = el.props.a_rho * el.props.h;
        let (a, b) = (
            model.initial_position(el.nodes[0]),
            model.initial_position(el.nodes[1]),
        );
        mass += m;
        first += m * 0.5 * (a + b);
        // ∫₀¹ (a + s(b−a))(a + s(b−a))ᵀ ds = (a aᵀ + b bᵀ)/3 + (a bᵀ + b aᵀ)/6.
        second += m
            * ((a * a.transpose() + b * b.transpose()) / 3.0
                + (a * b.transpose() + b * a.transpose()) / 6.0);
    }
    for (a, &m) in model.point_mass.iter().enumerate() {
        mass += m;
        let x = model.initial_position(a);
        first += m * x;
        second += m * x * x.transpose();
    }
    let com = if mass > 0.0 {
        first / mass
    } else {
        Vec3::zeros()
    };
    let cov = second - mass * com * com.transpose();
    let inertia = nalgebra::Matrix3::identity() * cov.trace() - cov;
    let mut principal: Vec<f64> = inertia.symmetric_eigenvalues().iter().copied().collect();
    principal.sort_by(f64::total_cmp);

    let mut omega_max = (0.0f64, 0);
    for (e, el) in model.elements.iter().enumerate() {
        let p = &el.props;
        let ir = p.i_rho.symmetric_eigenvalues();
        let ir_min = ir.min().max(1e-300);
        let bend = p.c_omega.fixed_view::<2, 2>(0, 0).into_owned();
        let bend_max = bend.symmetric_eigenvalues().max();
        let shear = p.c_gamma.x.max(p.c_gamma.y);
        let k = 2.0 * 3f64.sqrt() / p.h;
        let wave = [
            k * (p.c_gamma.z / p.a_rho).sqrt(),
            k * (shear / p.a_rho).sqrt(),
            k * (bend_max / ir_min).sqrt(),
            k * (p.c_omega[(2, 2)] / ir.sum().max(1e-300)).sqrt(),
        ]
        .into_iter()
        .fold(0.0f64, f64::max);
        let cut = (shear / ir_min).sqrt();
        let w = (cut * cut + wave * wave).sqrt();
        if w > omega_max.0 {
            omega_max = (w, e);
        }
    }

    // Rigid links: the bar's axial stiffness κ/ℓ² against the mass at its node.
    for link in &model.links {
        let a = link.node;
        let m_node = model.point_mass[a]
            + model
                .elements
                .iter()
                .filter(|el| el.nodes.contains(&a))
                .map(|el| 0.5 * el.props.a_rho * el.props.h)
                .sum::<f64>();
        let w = (link.penalty / (link.length * link.length * m_node.max(1e-300))).sqrt();
        if w > omega_max.0 {
            omega_max = (w, usize::MAX);
        }
    }

    let mut dissipation: Vec<String> = match params.scheme {
        Scheme::Em => vec![],
        Scheme::Midpoint => vec!["none (baseline: energy is not controlled)".into()],
        Scheme::GenAlpha { rho_inf } => vec![format!(
            "numerical damping of high frequencies: ρ∞ = {rho_inf} (1: none); acts on every mode above ≈ 1/Δt"
        )],
        Scheme::Edmc1 {
            chi_gamma,
            chi_omega,
            chi_v,
            chi_nu,
        } => [
            (chi_gamma, "χ_Γ", "rates of the force strains Γ (axial and shear)"),
            (chi_omega, "χ_Ω", "rates of the moment strains Ω (bending and torsion)"),
            (chi_v, "χ_v", "changes of translational speed |v|"),
            (chi_nu, "χ_ν", "changes of director speed ν"),
        ]
        .into_iter()
        .filter(|(x, _, _)| *x != 0.0)
        .map(|(x, n, what)| format!("EDMC-1 {n} = {x}: damps {what} (first order)"))
        .collect(),
        Scheme::Edmc2 {
            alpha_gv,
            alpha_gn,
            alpha_ov,
            alpha_on,
        } => [
            (alpha_gv, "α_Γv", "force strains Γ", "translational speed"),
            (alpha_gn, "α_Γν", "force strains Γ", "director speed"),
            (alpha_ov, "α_Ωv", "moment strains Ω", "translational speed"),
            (alpha_on, "α_Ων", "moment strains Ω", "director speed"),
        ]
        .into_iter()
        .filter(|(x, ..)| *x != 0.0)
        .map(|(x, n, s, v)| {
            format!("EDMC-2 {n} = {x}: dissipates in the {s} as the {v} changes (second order; a = αΔt/h)")
        })
        .collect(),
    };
    let eta = model
        .elements
        .iter()
        .fold(0.0f64, |m, e| m.max(e.props.damping));
    if eta > 0.0 {
        let w = omega_max.0;
        dissipation.push(format!(
            "Kelvin–Voigt material damping, η up to {eta:e} s: modal ratio ζ = η ω/2 (ζ = {:.3e} at the highest frequency)",
            0.5 * eta * w
        ));
    }

    let steps = params.n_steps();
    let (n, ne, nl) = (
        model.n_nodes() as u64,
        model.elements.len() as u64,
        model.links.len() as u64,
    );
    ModelReport {
        unknowns,
        linear_solver: linear_solver.to_string(),
        mass,
        center_of_mass: com,
        principal_inertia: [principal[0], principal[1], principal[2]],
        dissipation,
        omega_max,
        omega_dt: omega_max.0 * params.dt,
        steps,
        history_bytes: 420 * (steps as u64 + 1),
        trajectory_bytes_per_frame: n * 15 * 8 + 16,
        vtu_bytes_per_frame: 3000
            + (n + nl) * (2 * 8 + 5 * 24)
            + (ne + nl) * (2 * 8 + 1 + 4 * 24 + 2 * 8 + 8 + 1),
    }
}

fn bytes(b: u64) -> String {
    match b {
        b if b >= 1 << 30 => format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64),
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

impl fmt::Display for ModelReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "model report:")?;
        writeln!(
            f,
            "  Newton unknowns per step: {} ({} linear solver)",
            self.unknowns, self.linear_solver
        )?;
        let c = self.center_of_mass;
        let [i1, i2, i3] = self.principal_inertia;
        writeln!(
            f,
            "  mass {:.6e}, centre of mass ({:.6}, {:.6}, {:.6}); principal moments of inertia about it {:.4e}, {:.4e}, {:.4e} (centerlines and point masses)",
            self.mass, c.x, c.y, c.z, i1, i2, i3
        )?;
        if self.dissipation.is_empty() {
            writeln!(f, "  dissipation: none (EM conserves energy)")?;
        }
        for d in &self.dissipation {
            writeln!(f, "  dissipation: {d}")?;
        }
        let (w, e) = self.omega_max;
        let at = if e == usize::MAX {
            "a rigid link".to_string()
        } else {
            format!("element {e}")
        };
        writeln!(
            f,
            "  highest frequency (estimate): {w:.4e} rad/s at {at} (period {:.4e}); ω_max·Δt = {:.3} ({})",
            2.0 * std::f64::consts::PI / w.max(1e-300),
            self.omega_dt,
            if self.omega_dt > 2.0 {
                "the step does not resolve it: implicit schemes stay stable, accuracy there is lost"
            } else {
                "resolved"
            }
        )?;
        writeln!(
            f,
            "  outputs: history.csv ≈ {} (every step); trajectory.npz ≈ {} per frame; .vtu ≈ {} per frame",
            bytes(self.history_bytes),
            bytes(self.trajectory_bytes_per_frame),
            bytes(self.vtu_bytes_per_frame)
        )
    }
}
