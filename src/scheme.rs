//! The time-stepping schemes and how each forms the element stresses: plain data shared
//! by the element kernel (below) and the integrator (above), importing neither.

use serde::Serialize;

/// The time-stepping scheme (DESIGN §3–4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "name", rename_all = "lowercase")]
pub enum Scheme {
    /// Energy–momentum: mean of the strains, no dissipation.
    Em,
    /// First-order energy-dissipative momentum-conserving scheme.
    Edmc1 {
        /// Stress dissipation of the force strains Γ (β_Γ = χ_Γ).
        chi_gamma: f64,
        /// Stress dissipation of the moment strains Ω (β_Ω = χ_Ω).
        chi_omega: f64,
        /// Translational velocity dissipation (ṽ − v_n = χ_v (v_{n+1} − v_n)).
        chi_v: f64,
        /// Director velocity dissipation (ν̃ − ν_n = χ_ν (ν_{n+1} − ν_n)).
        chi_nu: f64,
    },
    /// Second-order energy-dissipative momentum-conserving scheme.
    Edmc2 {
        /// α_Γv: couples force strains to translational speed (the paper's single α).
        alpha_gv: f64,
        /// α_Γν: couples force strains to director speed.
        alpha_gn: f64,
        /// α_Ωv: couples moment strains to translational speed.
        alpha_ov: f64,
        /// α_Ων: couples moment strains to director speed.
        alpha_on: f64,
    },
    /// Baseline: the plain implicit mid-point rule on the same discretization. Stresses
    /// come from the strains of the mid-point configuration `Φ_{n+½}` instead of the mean
    /// of the strains: momenta are still conserved, energy is not.
    Midpoint,
    /// Baseline: a Lie-group generalized-α scheme (Brüls–Cardona–Arnold) on the nodal
    /// `(r, Λ)`, same elements, strains and consistent mass (module
    /// [`crate::integrator::gen_alpha`]). Neither energy nor momenta are exact.
    #[serde(rename = "gen-alpha")]
    GenAlpha {
        /// Spectral radius at infinite frequency ρ∞ ∈ [0, 1] (1: no numerical damping).
        rho_inf: f64,
    },
}

impl Scheme {
    /// EDMC-2 with the paper's single parameter α_Γv and the other three α zero.
    pub fn edmc2(alpha_gv: f64) -> Self {
        Scheme::Edmc2 {
            alpha_gv,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        }
    }

    /// Short name as used on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Scheme::Em => "em",
            Scheme::Edmc1 { .. } => "edmc1",
            Scheme::Edmc2 { .. } => "edmc2",
            Scheme::Midpoint => "midpoint",
            Scheme::GenAlpha { .. } => "gen-alpha",
        }
    }

    /// True when the scheme guarantees `H_{n+1} ≤ H_n + W` (EM and the EDMC schemes), so
    /// that a step whose energy grows is rejected. False for the baselines (mid-point,
    /// generalized-α), whose energy is not controlled by construction.
    pub fn controls_energy(&self) -> bool {
        !matches!(self, Scheme::Midpoint | Scheme::GenAlpha { .. })
    }

    /// Whether the WGSL element kernel implements this scheme (EM, EDMC-1, EDMC-2). The
    /// baselines run on the CPU path only.
    pub fn has_gpu_kernel(&self) -> bool {
        self.controls_energy()
    }

    /// How the element kernel forms the stresses (mean of the strains for EM/EDMC, strain
    /// of the mid-point configuration for [`Scheme::Midpoint`]).
    pub fn stress_rule(&self) -> StressRule {
        match self {
            Scheme::Midpoint => StressRule::MidpointStrain,
            _ => StressRule::MeanOfStrains,
        }
    }

    /// True when the translational velocity equation carries a dissipative correction `g`
    /// (an extra three unknowns per translationally free node).
    pub fn translational_dissipation(&self) -> bool {
        match *self {
            Scheme::Em | Scheme::Midpoint | Scheme::GenAlpha { .. } => false,
            Scheme::Edmc1 { chi_v, .. } => chi_v != 0.0,
            Scheme::Edmc2 {
                alpha_gv, alpha_ov, ..
            } => alpha_gv != 0.0 || alpha_ov != 0.0,
        }
    }

    /// True when director velocities carry a dissipative correction.
    pub fn director_dissipation(&self) -> bool {
        match *self {
            Scheme::Em | Scheme::Midpoint | Scheme::GenAlpha { .. } => false,
            Scheme::Edmc1 { chi_nu, .. } => chi_nu != 0.0,
            Scheme::Edmc2 {
                alpha_gn, alpha_on, ..
            } => alpha_gn != 0.0 || alpha_on != 0.0,
        }
    }

    /// True when any dissipation is switched on (otherwise the scheme is EM).
    pub fn is_dissipative(&self) -> bool {
        match *self {
            Scheme::Em | Scheme::Midpoint | Scheme::GenAlpha { .. } => false,
            Scheme::Edmc1 {
                chi_gamma,
                chi_omega,
                chi_v,
                chi_nu,
            } => chi_gamma != 0.0 || chi_omega != 0.0 || chi_v != 0.0 || chi_nu != 0.0,
            Scheme::Edmc2 {
                alpha_gv,
                alpha_gn,
                alpha_ov,
                alpha_on,
            } => alpha_gv != 0.0 || alpha_gn != 0.0 || alpha_ov != 0.0 || alpha_on != 0.0,
        }
    }
}

/// Which strains the element stresses are formed from: the only difference between the
/// energy–momentum scheme and the plain implicit mid-point rule on this discretization.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StressRule {
    /// `S = C(½(ε_n + ε_{n+1}) − ε°)`: the mean of the strains (EM, EDMC-1, EDMC-2;
    /// energy-consistent because `B_{n+½}(Φ_{n+1} − Φ_n) = ε_{n+1} − ε_n`).
    MeanOfStrains,
    /// `S = C(ε(Φ_{n+½}) − ε°)`: the strain of the mid-point configuration (the plain
    /// mid-point rule; momenta still conserved, energy not).
    MidpointStrain,
}
