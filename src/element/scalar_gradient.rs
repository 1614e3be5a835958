//! The derivative of an element's consistent dissipation scalars with respect to its
//! local unknowns, in closed form: what the monolithic tangent multiplies the residual's
//! dependence on the scalars by (`scalar_correction`).
//!
//! The scalars `σ = (β_Γ, β_Ω, c_v, φ)` (`φ = c_ν/(1 + K c_ν)`) depend on the increment
//! only through five numbers:
//!
//! * `v_{n+1} = |v^h_{n+1}|`, with `v^h_{n+1} = ½(v^0_{n+1} + v^1_{n+1})` affine in `u, g`;
//! * the strain-increment energies `X_Γ, X_Ω`, through the strains at `n+1`;
//! * `P₂ = Σ_αβ Iρ^{αβ} Y_α·Y_β` and `P₁ = Σ_αβ Iρ^{αβ} (Y_α·m_β + m_α·Y_β)`, with
//!   `Y_α = Σ_l (d^l_{α,n+1} − d^l_{α,n})/Δt` and `m_α = ½ Σ_l v^l_{α,n}`. The director
//!   velocity at the quadrature point is `t Y_α − m_α` with `t = 1/(1 + K c_ν)`, so
//!   `Aρ ν²_{n+1} = t² P₂ − t P₁ + P₀` (`P₀` fixed within a step).
//!
//! Their derivatives with respect to `(u, θ, g)` come from the kinematics (`∂v^h/∂u_l =
//! I/Δt`, `∂v^h/∂g_l = −I`, `∂d^l_{n+1}/∂θ_l = −A_l \hat{d^l_{n+½}}`, the strain gradient
//! at `n+1`); the scalars' derivatives with respect to the five numbers come from the
//! local law's Jacobian (`local_scalars_jacobian`) and, for `c_ν`,
//! the implicit derivative of its fixed point `c = F(c, w)`:
//! `dc = (∂F/∂w) dw / (1 − ∂F/∂c)`.

use super::dissipation::{local_scalars_jacobian, LocalInputs};
use super::strain::{strain_gradient, A0, B0, GRADIENT_FIELDS, NFIELDS, R0, R1};
use super::{field_forces, g_idx, th_idx, u_idx, ElemVec, ElementData, ElementState};
use super::{FrozenScalars, Kinematics, StepConsts, M2, NDOF};
use crate::model::Vec3;
use nalgebra::Vector6;

/// The five numbers the scalars depend on: `v_{n+1}, X_Γ, X_Ω, P₂, P₁`.
const NW: usize = 5;
pub(crate) const W_V: usize = 0;
pub(crate) const W_XG: usize = 1;
pub(crate) const W_XO: usize = 2;
pub(crate) const W_P2: usize = 3;
pub(crate) const W_P1: usize = 4;

/// `∂σ_i/∂x_j` for `σ = (β_Γ, β_Ω, c_v, φ = c_ν/(1 + K c_ν))` and the element's local
/// unknowns `x = (u, θ, g)` (row `j` of the result), at the kinematics `kin` of the
/// consistent scalars `s` ([`super::consistent_scalars`] returns both). Kelvin–Voigt
/// damping adds a constant to the β and drops out.
pub fn scalar_gradient(
    data: &ElementData,
    st: &ElementState,
    kin: &Kinematics,
    s: &FrozenScalars,
    k: &StepConsts,
) -> [[f64; 4]; NDOF] {
    let p = &data.props;
    let (h, dt) = (p.h, k.dt);
    let kappa = data.kappa();

    // The director speed's quadratic: Y_α, m_α, P₂, P₁.
    let y = director_rates(st, kin, dt);
    let m: [Vec3; 2] = std::array::from_fn(|a| 0.5 * (st.vd[0][a] + st.vd[1][a]));
    let ir = &p.i_rho;
    let mut p2 = 0.0;
    let mut p1 = 0.0;
    for a in 0..2 {
        for b in 0..2 {
            p2 += ir[(a, b)] * y[a].dot(&y[b]);
            p1 += ir[(a, b)] * (y[a].dot(&m[b]) + m[a].dot(&y[b]));
        }
    }
    let dsigma_dw = sigma_over_inputs(
        k,
        &kin.inputs,
        p.a_rho,
        h,
        kappa[0] + kappa[1],
        s.c_nu,
        [p2, p1],
    );

    // dw/dx, one gradient per number, formed only for the numbers some scalar depends
    // on (`needed`): a scheme with the stress or director dissipation off has no scalar
    // that varies with X_Γ, X_Ω or P₂, P₁, and their gradients (a strain gradient, the
    // director maps) would be multiplied by zeros.
    let needed = needed_numbers(&dsigma_dw);
    let mut dw = [[0.0f64; NDOF]; NW];
    let vh = 0.5 * (kin.v1[0] + kin.v1[1]);
    let vn = vh.norm();
    if needed[W_V] && vn > 0.0 {
        let vhat = vh / vn;
        for l in 0..2 {
            for c in 0..3 {
                dw[W_V][u_idx(l) + c] = vhat[c] / dt;
                dw[W_V][g_idx(l) + c] = -vhat[c];
            }
        }
    }
    let dcol: [[Vec3; 3]; 2] =
        std::array::from_fn(|l| std::array::from_fn(|i| kin.mid.d[l].column(i).into_owned()));
    let at = [kin.amat[0].transpose(), kin.amat[1].transpose()];
    // A gradient with respect to director d^l_{i,n+1} maps to θ_l as d^l_{i,½} × (A_lᵀ ·).
    let to_theta = |l: usize, i: usize, gvec: &Vec3| dcol[l][i].cross(&(at[l] * gvec));
    // X_Γ = ΔΓ·C_Γ ΔΓ, X_Ω = ΔΩ·C_Ω ΔΩ: gradients (C + Cᵀ)Δ through the strains at n+1.
    let de = kin.eps1 - kin.eps_n;
    let dg = de.fixed_rows::<3>(0).into_owned();
    let dom = de.fixed_rows::<3>(3).into_owned();
    let cg = 2.0 * p.c_gamma.component_mul(&dg);
    let co = (p.c_omega + p.c_omega.transpose()) * dom;
    let b_end = (needed[W_XG] || needed[W_XO]).then(|| strain_gradient(&kin.cfg1, h));
    for (wi, coef, rows) in [(W_XG, cg, 0..3), (W_XO, co, 3..6)] {
        let Some(b_end) = b_end.as_ref().filter(|_| needed[wi]) else {
            continue;
        };
        let mut field = [Vec3::zeros(); NFIELDS];
        for kk in rows {
            let c = coef[kk % 3];
            for q in GRADIENT_FIELDS[kk] {
                field[q] += c * b_end[kk][q];
            }
        }
        for (q, fv) in field.iter().enumerate() {
            match q {
                R0 | R1 => {
                    let l = q - R0;
                    for c in 0..3 {
                        dw[wi][u_idx(l) + c] += fv[c];
                    }
                }
                _ => {
                    let (l, i) = if q < B0 { (0, q - A0) } else { (1, q - B0) };
                    let g = to_theta(l, i, fv);
                    for c in 0..3 {
                        dw[wi][th_idx(l) + c] += g[c];
                    }
                }
            }
        }
    }
    // P₂ and P₁ through Y_α (∂Y_α/∂d^l_{α,n+1} = I/Δt).
    if needed[W_P2] || needed[W_P1] {
        for l in 0..2 {
            for a in 0..2 {
                let mut g2 = Vec3::zeros();
                let mut g1 = Vec3::zeros();
                for b in 0..2 {
                    let i_ab = ir[(a, b)] + ir[(b, a)];
                    g2 += i_ab * y[b];
                    g1 += i_ab * m[b];
                }
                let g2 = to_theta(l, a, &(g2 / dt));
                let g1 = to_theta(l, a, &(g1 / dt));
                for c in 0..3 {
                    dw[W_P2][th_idx(l) + c] += g2[c];
                    dw[W_P1][th_idx(l) + c] += g1[c];
                }
            }
        }
    }

    chain(&dsigma_dw, &dw, &needed)
}

/// `∂σ/∂w`: the derivative of `σ = (β_Γ, β_Ω, c_v, φ)` with respect to the five numbers
/// `w = (v_{n+1}, X_Γ, X_Ω, P₂, P₁)` (the module's introduction), at the local inputs
/// `inp` of the consistent scalars with director factor `c_nu`; `p = [P₂, P₁]`,
/// `ksum = K`. Shared by the 3D and the planar kernel, which differ only in `∂w/∂x`.
pub(crate) fn sigma_over_inputs(
    k: &StepConsts,
    inp: &LocalInputs,
    a_rho: f64,
    h: f64,
    ksum: f64,
    c_nu: f64,
    p: [f64; 2],
) -> [[f64; NW]; 4] {
    let [p2, p1] = p;
    // ∂(β_Γ, β_Ω, ṽ − v_n, ν̃ − ν_n)/∂(v_{n+1}, ν_{n+1}, X_Γ, X_Ω), and the law's values.
    let (law, jac) = local_scalars_jacobian(&k.scheme, inp, a_rho, k.dt / h);
    let t = 1.0 / (1.0 + ksum * c_nu);
    // dν = a_p2 dP₂ + a_p1 dP₁ + a_c dc_ν (zero at ν = 0, where the speed has a kink).
    let nu1 = inp.nu_n1;
    let (a_p2, a_p1, a_c) = if nu1 > 0.0 {
        let f = 1.0 / (2.0 * a_rho * nu1);
        (f * t * t, -f * t, f * (2.0 * t * p2 - p1) * (-ksum * t * t))
    } else {
        (0.0, 0.0, 0.0)
    };
    let mut dnu = [0.0; NW];
    dnu[W_P2] = a_p2;
    dnu[W_P1] = a_p1;

    // Law outputs as linear forms in dw, given dν: d(law_i) = jac[i]·(dv, dν, dX_Γ, dX_Ω).
    let through_law = |i: usize, dnu: &[f64; NW]| -> [f64; NW] {
        let mut d = [0.0; NW];
        d[W_V] += jac[i][0];
        d[W_XG] += jac[i][2];
        d[W_XO] += jac[i][3];
        for (dj, nj) in d.iter_mut().zip(dnu) {
            *dj += jac[i][1] * nj;
        }
        d
    };
    // c_ν = ½ (ν̃ − ν_n)/(ν_n + ν_{n+1}), its fixed point solved implicitly.
    let den_nu = inp.nu_n + nu1;
    let mut dc = [0.0; NW];
    if k.scheme.director_dissipation() && den_nu > 1e-300 {
        // F(c, w) = H(v, ν(c, w), X): ∂H/∂ν includes the ratio's denominator.
        let dh_dnu = 0.5 * jac[3][1] / den_nu - 0.5 * law.dnu / (den_nu * den_nu);
        let mut rhs = [0.0; NW];
        rhs[W_V] = 0.5 * jac[3][0] / den_nu;
        rhs[W_XG] = 0.5 * jac[3][2] / den_nu;
        rhs[W_XO] = 0.5 * jac[3][3] / den_nu;
        rhs[W_P2] = dh_dnu * a_p2;
        rhs[W_P1] = dh_dnu * a_p1;
        let denom = 1.0 - dh_dnu * a_c;
        if denom.is_finite() && denom != 0.0 {
            for (d, r) in dc.iter_mut().zip(rhs) {
                *d = r / denom;
            }
        }
        for (n, c) in dnu.iter_mut().zip(&dc) {
            *n += a_c * c;
        }
    }
    let d_bg = through_law(0, &dnu);
    let d_bo = through_law(1, &dnu);
    let d_dv = through_law(2, &dnu);
    // c_v = ½ (ṽ − v_n)/(v_n + v_{n+1}).
    let den_v = inp.v_n + inp.v_n1;
    let mut d_cv = [0.0; NW];
    if den_v > 1e-300 {
        for (c, d) in d_cv.iter_mut().zip(&d_dv) {
            *c = 0.5 * d / den_v;
        }
        d_cv[W_V] -= 0.5 * law.dv / (den_v * den_v);
    }
    let d_phi: [f64; NW] = std::array::from_fn(|i| dc[i] * t * t);
    [d_bg, d_bo, d_cv, d_phi]
}

/// Which of the five numbers `w` some scalar depends on (a nonzero column of
/// `∂σ/∂w`): the gradients of the others are left at zero (shared by both kernels).
pub(crate) fn needed_numbers(dsigma_dw: &[[f64; NW]; 4]) -> [bool; NW] {
    std::array::from_fn(|w| dsigma_dw.iter().any(|row| row[w] != 0.0))
}

/// `Y_α = Σ_l (d^l_{α,n+1} − d^l_{α,n})/Δt` (α = 1, 2): the director rates the director
/// factor scales (`w_α = φ Y_α`).
fn director_rates(st: &ElementState, kin: &Kinematics, dt: f64) -> [Vec3; 2] {
    std::array::from_fn(|a| {
        (kin.cfg1.d[0].column(a) - st.cfg.d[0].column(a) + kin.cfg1.d[1].column(a)
            - st.cfg.d[1].column(a))
            / dt
    })
}

/// `∂σ/∂x = (∂σ/∂w)(∂w/∂x)`, row `j` of the result for unknown `j`, summed over the
/// numbers marked `needed` ([`needed_numbers`]: the others' columns of `∂σ/∂w` are zero).
pub(crate) fn chain<const N: usize>(
    dsigma_dw: &[[f64; NW]; 4],
    dw: &[[f64; N]; NW],
    needed: &[bool; NW],
) -> [[f64; 4]; N] {
    let mut out = [[0.0f64; 4]; N];
    for w in (0..NW).filter(|&w| needed[w]) {
        for (j, row) in out.iter_mut().enumerate() {
            for (i, o) in row.iter_mut().enumerate() {
                *o += dsigma_dw[i][w] * dw[w][j];
            }
        }
    }
    out
}

/// `∂R/∂σ_i` of the element residual for `σ = (β_Γ, β_Ω, c_v, φ)` at the kinematics
/// `kin` (the residual is affine in σ, so these are exact and independent of σ):
///
/// * `β_Γ, β_Ω`: the stresses change by `½ C_Γ ΔΓ` and `½ C_Ω ΔΩ`; their forces
///   `h B_{n+½}ᵀ ΔS` are projected on `(u, θ)` like the stress forces;
/// * `c_v`: the `g` rows change by `−½ h Aρ (v^h_n + v^h_{n+1})`;
/// * `φ`: the director velocities at `n+1` change by `−2 κ_l Y_α`, and with them the
///   director inertia forces.
///
/// Only the derivatives marked in `which` are formed (the others are zero): the
/// monolithic tangent needs those of the scalars that vary.
pub fn residual_scalar_derivatives(
    data: &ElementData,
    st: &ElementState,
    kin: &Kinematics,
    k: &StepConsts,
    trans_diss: bool,
    which: [bool; 4],
) -> [ElemVec; 4] {
    let p = &data.props;
    let (h, dt) = (p.h, k.dt);
    let dmid = [kin.mid.d[0], kin.mid.d[1]];
    let project = |f: &[Vec3; NFIELDS]| {
        let mut r = ElemVec::zeros();
        for l in 0..2 {
            let (rl, base) = if l == 0 { (R0, A0) } else { (R1, B0) };
            r.fixed_rows_mut::<3>(u_idx(l)).copy_from(&f[rl]);
            let mut rt = Vec3::zeros();
            for i in 0..3 {
                rt += dmid[l].column(i).cross(&f[base + i]);
            }
            r.fixed_rows_mut::<3>(th_idx(l)).copy_from(&rt);
        }
        r
    };
    let mut out = [ElemVec::zeros(); 4];
    if which[0] || which[1] {
        let b_mid = strain_gradient(&kin.mid, h);
        let de = kin.eps1 - kin.eps_n;
        let dn = 0.5 * p.c_gamma.component_mul(&de.fixed_rows::<3>(0).into_owned());
        let dm = 0.5 * p.c_omega * de.fixed_rows::<3>(3).into_owned();
        let ds_gamma = Vector6::new(dn.x, dn.y, dn.z, 0.0, 0.0, 0.0);
        let ds_omega = Vector6::new(0.0, 0.0, 0.0, dm.x, dm.y, dm.z);
        if which[0] {
            out[0] = project(&field_forces(&b_mid, &ds_gamma, h));
        }
        if which[1] {
            out[1] = project(&field_forces(&b_mid, &ds_omega, h));
        }
    }
    if trans_diss && which[2] {
        let vsum = 0.5 * (st.v[0] + st.v[1]) + 0.5 * (kin.v1[0] + kin.v1[1]);
        let dg = -0.5 * h * p.a_rho * vsum;
        for l in 0..2 {
            out[2].fixed_rows_mut::<3>(g_idx(l)).copy_from(&dg);
        }
    }
    let kappa = data.kappa();
    if which[3] && (kappa[0] != 0.0 || kappa[1] != 0.0) {
        let y = director_rates(st, kin, dt);
        let mut f = [Vec3::zeros(); NFIELDS];
        for l in 0..2 {
            let base = if l == 0 { A0 } else { B0 };
            for a in 0..2 {
                for m in 0..2 {
                    for b in 0..2 {
                        f[base + a] +=
                            (h * M2[l][m] * p.i_rho[(a, b)] / dt) * (-2.0 * kappa[m]) * y[b];
                    }
                }
            }
        }
        out[3] = project(&f);
    }
    out
}
