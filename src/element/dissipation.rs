//! The four local EDMC scalars at an element's stress quadrature point (DESIGN §4).
//!
//! Given the speeds `v_n, v_{n+1}` (translational), `ν_n, ν_{n+1}` (director) and the
//! strain-increment energies `X_Γ = ΔΓ·C_Γ ΔΓ`, `X_Ω`, every scheme reduces to four
//! numbers: `β_Γ, β_Ω` (stress dissipation) and `ṽ − v_n`, `ν̃ − ν_n` (velocity
//! dissipation). Everything else in the element uses only these.

use nalgebra::{Matrix4, Vector4};

use crate::scheme::Scheme;

/// Inputs of the local dissipation law at one quadrature point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LocalInputs {
    /// `|v^h_n|`.
    pub v_n: f64,
    /// `|v^h_{n+1}|`.
    pub v_n1: f64,
    /// `ν_n = sqrt(v_α·Iρ^{αβ} v_β / Aρ)` at `n`.
    pub nu_n: f64,
    /// `ν_{n+1}`.
    pub nu_n1: f64,
    /// `X_Γ = ΔΓ·C_Γ ΔΓ`.
    pub x_gamma: f64,
    /// `X_Ω = ΔΩ·C_Ω ΔΩ`.
    pub x_omega: f64,
}

/// The local dissipation scalars.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LocalScalars {
    /// `β_Γ`: `N_diss = ½ β_Γ C_Γ ΔΓ`.
    pub beta_gamma: f64,
    /// `β_Ω`: `M_diss = ½ β_Ω C_Ω ΔΩ`.
    pub beta_omega: f64,
    /// `ṽ − v_n`.
    pub dv: f64,
    /// `ν̃ − ν_n`.
    pub dnu: f64,
}

impl LocalScalars {
    /// `c_v = ½(ṽ − v_n)/(v_n + v_{n+1})`: `v_diss = c_v (v^h_n + v^h_{n+1})`. Zero where the
    /// direction is undefined (`v_n + v_{n+1} = 0`).
    pub fn c_v(&self, inp: &LocalInputs) -> f64 {
        ratio(0.5 * self.dv, inp.v_n + inp.v_n1)
    }

    /// `c_ν`, the director analogue of [`Self::c_v`].
    pub fn c_nu(&self, inp: &LocalInputs) -> f64 {
        ratio(0.5 * self.dnu, inp.nu_n + inp.nu_n1)
    }

    /// Dissipation density per unit length (multiply by `h`) in the form valid for every
    /// scheme: `½Aρ(ṽ−v_n)(v_{n+1}−v_n) + ½Aρ(ν̃−ν_n)(ν_{n+1}−ν_n) + ½β_Γ X_Γ + ½β_Ω X_Ω`.
    pub fn dissipation_density(&self, inp: &LocalInputs, a_rho: f64) -> f64 {
        0.5 * a_rho * self.dv * (inp.v_n1 - inp.v_n)
            + 0.5 * a_rho * self.dnu * (inp.nu_n1 - inp.nu_n)
            + 0.5 * self.beta_gamma * inp.x_gamma
            + 0.5 * self.beta_omega * inp.x_omega
    }
}

/// `num/den`, or 0 when the denominator vanishes (no direction to dissipate along).
#[inline]
fn ratio(num: f64, den: f64) -> f64 {
    if den > 1e-300 {
        num / den
    } else {
        0.0
    }
}

/// Evaluates the local law of `scheme` at one quadrature point. `dt_over_h = Δt/h`.
pub fn local_scalars(
    scheme: &Scheme,
    inp: &LocalInputs,
    a_rho: f64,
    dt_over_h: f64,
) -> LocalScalars {
    match *scheme {
        Scheme::Em | Scheme::Midpoint | Scheme::GenAlpha { .. } => LocalScalars::default(),
        Scheme::Edmc1 {
            chi_gamma,
            chi_omega,
            chi_v,
            chi_nu,
        } => LocalScalars {
            beta_gamma: chi_gamma,
            beta_omega: chi_omega,
            dv: chi_v * (inp.v_n1 - inp.v_n),
            dnu: chi_nu * (inp.nu_n1 - inp.nu_n),
        },
        Scheme::Edmc2 { .. } => {
            let (m, rhs, _, _) = edmc2_system(scheme, inp, a_rho, dt_over_h);
            // The matrix is I + (rank-2 coupling) with a positive Aρ block: always regular
            // for X ≥ 0 (its determinant is Aρ² + Aρ Σ a² X > 0 in the single-α case).
            let s = LawFactors::new(&m)
                .map(|f| f.solve(&rhs))
                .unwrap_or_else(Vector4::zeros);
            LocalScalars {
                beta_gamma: s[0],
                beta_omega: s[1],
                dv: s[2] - inp.v_n,
                dnu: s[3] - inp.nu_n,
            }
        }
    }
}

/// EDMC-2's local law as the linear system `M s = r` in the unknowns
/// `s = (β_Γ, β_Ω, ṽ, ν̃)`, its scaled constants `[a_Γv, a_Γν, a_Ωv, a_Ων]` and the
/// law's [`Fades`]:
///
/// ```text
/// β_Γ − a_Γv ṽ − a_Γν ν̃ = −a_Γv v_{n+1} − a_Γν ν_{n+1}
/// β_Ω − a_Ωv ṽ − a_Ων ν̃ = −a_Ωv v_{n+1} − a_Ων ν_{n+1}
/// a_Γv X_Γ β_Γ + a_Ωv X_Ω β_Ω + Aρ ṽ = Aρ v_n + a_Γv X_Γ + a_Ωv X_Ω
/// a_Γν X_Γ β_Γ + a_Ων X_Ω β_Ω + Aρ ν̃ = Aρ ν_n + a_Γν X_Γ + a_Ων X_Ω
/// ```
///
/// with `a_xv = s_v α_xv Δt/h` and `a_xν = s_ν α_xν Δt/h`, the velocity couplings faded
/// where the point's speed is below the law's own dissipative speed ([`fade`]).
///
/// `scheme` must be EDMC-2 (other schemes give the zero system).
fn edmc2_system(
    scheme: &Scheme,
    inp: &LocalInputs,
    a_rho: f64,
    dt_over_h: f64,
) -> (Matrix4<f64>, Vector4<f64>, [f64; 4], Fades) {
    let Scheme::Edmc2 {
        alpha_gv,
        alpha_gn,
        alpha_ov,
        alpha_on,
    } = *scheme
    else {
        return (
            Matrix4::zeros(),
            Vector4::zeros(),
            [0.0; 4],
            Fades::default(),
        );
    };
    let (xg, xo) = (inp.x_gamma, inp.x_omega);
    let a0 = [
        alpha_gv * dt_over_h,
        alpha_gn * dt_over_h,
        alpha_ov * dt_over_h,
        alpha_on * dt_over_h,
    ];
    let fades = Fades::new(a0, inp, a_rho);
    let (agv, agn, aov, aon) = (
        fades.v.0 * a0[0],
        fades.nu.0 * a0[1],
        fades.v.0 * a0[2],
        fades.nu.0 * a0[3],
    );
    let m = Matrix4::new(
        1.0,
        0.0,
        -agv,
        -agn,
        0.0,
        1.0,
        -aov,
        -aon,
        agv * xg,
        aov * xo,
        a_rho,
        0.0,
        agn * xg,
        aon * xo,
        0.0,
        a_rho,
    );
    let rhs = Vector4::new(
        -agv * inp.v_n1 - agn * inp.nu_n1,
        -aov * inp.v_n1 - aon * inp.nu_n1,
        a_rho * inp.v_n + agv * xg + aov * xo,
        a_rho * inp.nu_n + agn * xg + aon * xo,
    );
    (m, rhs, a0, fades)
}

/// The solver of EDMC-2's law `M s = r` ([`edmc2_system`]): `M = [[I, M₁₂], [M₂₁, Aρ I]]`
/// in 2 × 2 blocks, solved by eliminating `(β_Γ, β_Ω)`: `S (ṽ, ν̃) = r₂ − M₂₁ r₁` with the
/// 2 × 2 Schur complement `S = Aρ I − M₂₁ M₁₂` (its inverse in closed form), then
/// `(β_Γ, β_Ω) = r₁ − M₁₂ (ṽ, ν̃)`. `S` is `Aρ I` plus a positive semi-definite product
/// for `X ≥ 0` (single α: `Aρ + a² X`), so no pivoting is needed; the general 4 × 4 LU it
/// replaces cost as much as the rest of the local law.
#[derive(Clone, Copy, Debug)]
struct LawFactors {
    m12: [[f64; 2]; 2],
    m21: [[f64; 2]; 2],
    /// `S⁻¹`.
    s_inv: [[f64; 2]; 2],
}

impl LawFactors {
    /// The factors of `m` (of [`edmc2_system`]'s form); `None` if `S` is singular.
    #[inline]
    fn new(m: &Matrix4<f64>) -> Option<Self> {
        debug_assert!(m[(0, 0)] == 1.0 && m[(1, 1)] == 1.0 && m[(0, 1)] == 0.0 && m[(1, 0)] == 0.0);
        let m12 = [[m[(0, 2)], m[(0, 3)]], [m[(1, 2)], m[(1, 3)]]];
        let m21 = [[m[(2, 0)], m[(2, 1)]], [m[(3, 0)], m[(3, 1)]]];
        let sch = |i: usize, j: usize| {
            m[(2 + i, 2 + j)] - (m21[i][0] * m12[0][j] + m21[i][1] * m12[1][j])
        };
        let (s00, s01, s10, s11) = (sch(0, 0), sch(0, 1), sch(1, 0), sch(1, 1));
        let det = s00 * s11 - s01 * s10;
        if det == 0.0 {
            return None;
        }
        let inv = 1.0 / det;
        Some(Self {
            m12,
            m21,
            s_inv: [[s11 * inv, -s01 * inv], [-s10 * inv, s00 * inv]],
        })
    }

    /// `M⁻¹ r`.
    #[inline]
    fn solve(&self, r: &Vector4<f64>) -> Vector4<f64> {
        let (m12, m21, si) = (&self.m12, &self.m21, &self.s_inv);
        let b0 = r[2] - (m21[0][0] * r[0] + m21[0][1] * r[1]);
        let b1 = r[3] - (m21[1][0] * r[0] + m21[1][1] * r[1]);
        let y0 = si[0][0] * b0 + si[0][1] * b1;
        let y1 = si[1][0] * b0 + si[1][1] * b1;
        Vector4::new(
            r[0] - (m12[0][0] * y0 + m12[0][1] * y1),
            r[1] - (m12[1][0] * y0 + m12[1][1] * y1),
            y0,
            y1,
        )
    }
}

/// The fade of EDMC-2's velocity couplings, `(s, ∂s/∂V, ∂s/∂F)`: `s = 3ρ² − 2ρ³` for
/// `ρ = V/F < 1` and `s = 1` from `ρ = 1` on (continuously differentiable), for the
/// point's speed sum `V = v_n + v_{n+1}` and the law's own dissipative speed at rest
/// `F = (a_Γv X_Γ + a_Ωv X_Ω)/Aρ` (the ṽ equation's forcing; likewise with ν and the
/// `a_xν`); `s = 1` where `F = 0`.
///
/// The paper's law asks, at a point at rest (`v_n = 0`), for a dissipative speed
/// `ṽ − v_n → a X/(Aρ + a²X) ≠ 0` as `v_{n+1} → 0`, along `v^h_{n+1}/v_{n+1}`: the
/// dissipative velocity jumps as the point's velocity passes through zero, and where a
/// point's new speed lands within that jump the step has no solution (a roll-up from rest
/// failed at step 1 for some Δt only, docs/damping.md). Scaling the couplings `a_xv` by
/// `s` keeps the law's structure, so the dissipation identity, D ≥ 0 (its sum of squares)
/// and the momenta hold as before, while `ṽ − v_n = O(V²)` and `c_v = O(V/F)` below `F`:
/// the dissipative velocity is continuous and vanishes with the speed. Wherever the point
/// moves faster than `F` (`F = O(Δt³)`) the law is the paper's, bit for bit.
fn fade(speed: f64, forcing: f64) -> (f64, f64, f64) {
    if forcing <= 0.0 || speed >= forcing {
        return (1.0, 0.0, 0.0);
    }
    let rho = speed / forcing;
    let ds = 6.0 * rho * (1.0 - rho);
    (
        rho * rho * (3.0 - 2.0 * rho),
        ds / forcing,
        -ds * rho / forcing,
    )
}

/// The two fades of EDMC-2's law (translational and director velocity couplings), each
/// `(s, ∂s/∂w)` for `w = (v_{n+1}, ν_{n+1}, X_Γ, X_Ω)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Fades {
    v: (f64, [f64; 4]),
    nu: (f64, [f64; 4]),
}

impl Default for Fades {
    fn default() -> Self {
        Fades {
            v: (1.0, [0.0; 4]),
            nu: (1.0, [0.0; 4]),
        }
    }
}

impl Fades {
    /// The fades at `inp` for the unfaded constants `a0 = [a_Γv, a_Γν, a_Ωv, a_Ων]`.
    fn new(a0: [f64; 4], inp: &LocalInputs, a_rho: f64) -> Self {
        let (xg, xo) = (inp.x_gamma, inp.x_omega);
        let one = |speed: f64, ag: f64, ao: f64, speed_index: usize| {
            let (s, ds_dv, ds_df) = fade(speed, (ag * xg + ao * xo) / a_rho);
            let mut d = [0.0; 4];
            d[speed_index] = ds_dv;
            d[2] = ds_df * ag / a_rho;
            d[3] = ds_df * ao / a_rho;
            (s, d)
        };
        Fades {
            v: one(inp.v_n + inp.v_n1, a0[0], a0[2], 0),
            nu: one(inp.nu_n + inp.nu_n1, a0[1], a0[3], 1),
        }
    }
}

/// [`local_scalars`] and its derivative with respect to the inputs that vary with the
/// increment: `d[i][j] = ∂s_i/∂w_j` for `s = (β_Γ, β_Ω, ṽ − v_n, ν̃ − ν_n)` and
/// `w = (v_{n+1}, ν_{n+1}, X_Γ, X_Ω)` (the speeds at `n` are fixed within a step).
///
/// EDMC-2's law is the linear system `M(X) s = r(w)` of [`local_scalars`], so
/// `∂s/∂w_j = M⁻¹ (∂r/∂w_j − (∂M/∂w_j) s)`: one factorization (the law's own), four
/// more solves.
pub(crate) fn local_scalars_jacobian(
    scheme: &Scheme,
    inp: &LocalInputs,
    a_rho: f64,
    dt_over_h: f64,
) -> (LocalScalars, [[f64; 4]; 4]) {
    let mut d = [[0.0; 4]; 4];
    match *scheme {
        Scheme::Em | Scheme::Midpoint | Scheme::GenAlpha { .. } | Scheme::Edmc1 { .. } => {
            if let Scheme::Edmc1 { chi_v, chi_nu, .. } = *scheme {
                d[2][0] = chi_v;
                d[3][1] = chi_nu;
            }
            (local_scalars(scheme, inp, a_rho, dt_over_h), d)
        }
        Scheme::Edmc2 { .. } => {
            let (m, rhs, a0, fades) = edmc2_system(scheme, inp, a_rho, dt_over_h);
            let (sv, snu) = (fades.v.0, fades.nu.0);
            let (agv, agn, aov, aon) = (sv * a0[0], snu * a0[1], sv * a0[2], snu * a0[3]);
            let lu = LawFactors::new(&m);
            // As `local_scalars` (the same factorization and solve, so the same values).
            let s = lu.map(|f| f.solve(&rhs)).unwrap_or_else(Vector4::zeros);
            let law = LocalScalars {
                beta_gamma: s[0],
                beta_omega: s[1],
                dv: s[2] - inp.v_n,
                dnu: s[3] - inp.nu_n,
            };
            // Columns ∂r/∂w_j − (∂M/∂w_j) s at fixed fades: the speeds enter r's first two
            // rows, the X both r and M's last two rows (through β_Γ X_Γ and β_Ω X_Ω).
            let mut cols = Matrix4::new(
                -agv,
                -agn,
                0.0,
                0.0,
                -aov,
                -aon,
                0.0,
                0.0,
                0.0,
                0.0,
                agv * (1.0 - s[0]),
                aov * (1.0 - s[1]),
                0.0,
                0.0,
                agn * (1.0 - s[0]),
                aon * (1.0 - s[1]),
            );
            // The fades' own variation: ∂r/∂s_v − (∂M/∂s_v) s (likewise s_ν) times ∂s/∂w.
            let (xg, xo) = (inp.x_gamma, inp.x_omega);
            let by_sv = Vector4::new(
                a0[0] * (s[2] - inp.v_n1),
                a0[2] * (s[2] - inp.v_n1),
                a0[0] * xg * (1.0 - s[0]) + a0[2] * xo * (1.0 - s[1]),
                0.0,
            );
            let by_snu = Vector4::new(
                a0[1] * (s[3] - inp.nu_n1),
                a0[3] * (s[3] - inp.nu_n1),
                0.0,
                a0[1] * xg * (1.0 - s[0]) + a0[3] * xo * (1.0 - s[1]),
            );
            for j in 0..4 {
                let add = by_sv * fades.v.1[j] + by_snu * fades.nu.1[j];
                for i in 0..4 {
                    cols[(i, j)] += add[i];
                }
            }
            if let Some(f) = lu {
                for j in 0..4 {
                    let ds = f.solve(&cols.column(j).into_owned());
                    for (i, row) in d.iter_mut().enumerate() {
                        row[j] = ds[i];
                    }
                }
            }
            (law, d)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_alpha_matches_closed_form_and_positive_form() {
        let scheme = Scheme::Edmc2 {
            alpha_gv: 0.7,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        };
        let inp = LocalInputs {
            v_n: 1.3,
            v_n1: 0.4,
            nu_n: 0.0,
            nu_n1: 0.0,
            x_gamma: 2.5,
            x_omega: 0.8,
        };
        let (a_rho, dt_h) = (3.0, 0.4);
        let s = local_scalars(&scheme, &inp, a_rho, dt_h);
        // (V = 1.7 exceeds the law's speed at rest F = a X/Aρ = 0.23: no fade.)
        let a = 0.7 * dt_h;
        let x = inp.x_gamma;
        let vt = (a_rho * inp.v_n + a * x * (1.0 + a * inp.v_n1)) / (a_rho + a * a * x);
        let beta = a * (a_rho * (inp.v_n - inp.v_n1) + a * x) / (a_rho + a * a * x);
        assert!((s.dv - (vt - inp.v_n)).abs() < 1e-14);
        assert!((s.beta_gamma - beta).abs() < 1e-14);
        let d = s.dissipation_density(&inp, a_rho);
        let positive = 0.5 * a_rho * s.dv * s.dv + 0.5 * s.beta_gamma.powi(2) * x;
        assert!((d - positive).abs() < 1e-13 * positive.abs().max(1.0));
    }

    /// Local inputs with every kind of dissipation active and the scalars coupled.
    fn coupled_inputs() -> LocalInputs {
        LocalInputs {
            v_n: 0.3,
            v_n1: 0.9,
            nu_n: 0.2,
            nu_n1: 0.05,
            x_gamma: 1.5,
            x_omega: 2.0,
        }
    }

    #[test]
    fn coupled_edmc2_dissipation_is_the_positive_form() {
        let scheme = Scheme::Edmc2 {
            alpha_gv: 0.5,
            alpha_gn: 0.3,
            alpha_ov: 0.2,
            alpha_on: 0.9,
        };
        let inp = coupled_inputs();
        let s = local_scalars(&scheme, &inp, 2.0, 0.3);
        let d = s.dissipation_density(&inp, 2.0);
        let positive = 0.5 * 2.0 * (s.dv * s.dv + s.dnu * s.dnu)
            + 0.5 * s.beta_gamma.powi(2) * inp.x_gamma
            + 0.5 * s.beta_omega.powi(2) * inp.x_omega;
        assert!(positive > 0.0);
        assert!((d - positive).abs() < 1e-13);
    }

    /// From rest (`v_n = 0`) the paper's law kept a dissipative speed
    /// `ṽ − v_n → a X/(Aρ + a²X)` as `v_{n+1} → 0`, along a direction that flips there;
    /// the faded law's dissipative velocity `c_v (v^h_n + v^h_{n+1})` vanishes with the
    /// speed (`c_v ≤ ¼`, `c_v → 0`), and its D keeps the positive form.
    #[test]
    fn the_dissipative_velocity_vanishes_with_the_speed_from_rest() {
        let scheme = Scheme::Edmc2 {
            alpha_gv: 0.0,
            alpha_gn: 0.0,
            alpha_ov: 0.5,
            alpha_on: 0.0,
        };
        // The roll-up's element 42 at Δt = 0.113: Aρ = 1.2566, a = 2.825, X_Ω = 8.08e-6
        // (F = 1.8e-5).
        let (a_rho, dt_h) = (1.2566, 5.65);
        let mut last_cv = f64::INFINITY;
        for k in 0..12 {
            let v1 = 1e-3 * 0.1f64.powi(k);
            let inp = LocalInputs {
                v_n: 0.0,
                v_n1: v1,
                x_omega: 8.08e-6,
                ..LocalInputs::default()
            };
            let s = local_scalars(&scheme, &inp, a_rho, dt_h);
            let cv = s.c_v(&inp);
            // |v_diss| = c_v v_{n+1}: c_v ≈ ½ s F/V = ½ρ(3 − 2ρ) ≤ 9/16 (ρ = V/F).
            assert!((0.0..=0.57).contains(&cv), "c_v = {cv} at v = {v1}");
            if v1 < 1e-6 {
                assert!(cv < last_cv, "c_v = {cv} at v = {v1}: not falling");
            }
            last_cv = cv;
            let d = s.dissipation_density(&inp, a_rho);
            let positive = 0.5 * a_rho * s.dv * s.dv + 0.5 * s.beta_omega.powi(2) * inp.x_omega;
            // (d is a difference of terms of size ½|β|X: compare at their round-off.)
            let terms = 0.5 * a_rho * (s.dv * v1).abs() + 0.5 * (s.beta_omega * inp.x_omega).abs();
            assert!(
                (d - positive).abs() <= 1e-14 * terms,
                "D = {d:e}, positive form {positive:e}, terms {terms:e} at v = {v1}"
            );
        }
        assert!(last_cv < 1e-5, "c_v = {last_cv} at v = 1e-14");
        // Where the point moves faster than F the law is the paper's.
        let inp = LocalInputs {
            v_n: 2e-5,
            v_n1: 1e-6,
            x_omega: 8.08e-6,
            ..LocalInputs::default()
        };
        let a = 0.5 * dt_h;
        let x = inp.x_omega;
        let paper = (a_rho * inp.v_n + a * x * (1.0 + a * inp.v_n1)) / (a_rho + a * a * x);
        let faded = local_scalars(&scheme, &inp, a_rho, dt_h).dv + inp.v_n;
        assert!((faded - paper).abs() <= 1e-14 * paper);
    }

    /// The law's Jacobian equals central differences of the law on coupled EDMC-2 and
    /// EDMC-1 inputs (1e-8 of the largest entry; measured 2.2e-10, the differences' own
    /// error), and the law
    /// it returns is [`local_scalars`]' bit for bit.
    #[test]
    fn jacobian_is_the_difference_of_the_law() {
        let schemes = [
            Scheme::Edmc2 {
                alpha_gv: 0.5,
                alpha_gn: 0.3,
                alpha_ov: 0.2,
                alpha_on: 0.9,
            },
            Scheme::Edmc1 {
                chi_gamma: 0.3,
                chi_omega: 0.1,
                chi_v: 0.7,
                chi_nu: 0.4,
            },
        ];
        // Coupled inputs, and inputs where both fades act (V/F ≈ 0.5).
        let slow = LocalInputs {
            v_n: 0.005,
            v_n1: 0.008,
            nu_n: 0.005,
            nu_n1: 0.02,
            x_gamma: 0.2,
            x_omega: 0.3,
        };
        let out = |s: &LocalScalars| [s.beta_gamma, s.beta_omega, s.dv, s.dnu];
        let mut worst: f64 = 0.0;
        for (scheme, inp) in schemes
            .iter()
            .flat_map(|s| [(*s, coupled_inputs()), (*s, slow)])
        {
            let (law, d) = local_scalars_jacobian(&scheme, &inp, 2.0, 0.3);
            assert_eq!(law, local_scalars(&scheme, &inp, 2.0, 0.3));
            let size = d.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
            for j in 0..4 {
                let at = |sign: f64| {
                    let mut x = inp;
                    let h = 1e-6 * sign;
                    match j {
                        0 => x.v_n1 += h,
                        1 => x.nu_n1 += h,
                        2 => x.x_gamma += h,
                        _ => x.x_omega += h,
                    }
                    out(&local_scalars(&scheme, &x, 2.0, 0.3))
                };
                let (p, m) = (at(1.0), at(-1.0));
                for i in 0..4 {
                    let fd = (p[i] - m[i]) / 2e-6;
                    worst = worst.max((fd - d[i][j]).abs() / size);
                }
            }
        }
        assert!(worst <= 1e-8, "law Jacobian differs by {worst:e}");
    }
}
