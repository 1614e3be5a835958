//! The rational curvature measure (`[[rod]] curvature_measure = "rational"`; docs/theory.md
//! §2, "The rational curvature measure").
//!
//! The sine measure `q = Ω` of [`super::strain::raw_strains`] (bilinear in the directors)
//! divided by the objective scalar
//!
//! ```text
//! n = ½ + ⅙ Σ_i a_i·b_i          (= (2 + cos δ)/3 for end triads turned δ apart)
//! Ω̃ = q / n                      (= 3 sin δ / ((2 + cos δ) h) · axis)
//! ```
//!
//! `q` and `n` are both quadratic in the nodal directors, so their mid-point gradients are
//! exact discrete derivatives, and so is the algebraic combination
//!
//! ```text
//! Ω̃₁ − Ω̃₀ = B̄ (Φ₁ − Φ₀),   B̄ = [n̄ Dq(Φ_½) − q̄ ⊗ Dn(Φ_½)] / (n₀ n₁),
//! n̄ = ½(n₀ + n₁),  q̄ = ½(q₀ + q₁).
//! ```
//!
//! With `B̄` in place of the mid-point gradient of the moment rows and the mean of the
//! (rational) strains as stress, EM's energy identity holds exactly; `q` and `n` are
//! invariant under rigid motions, so `B̄ᵀ M` annihilates them and `L`, `J` are conserved.
//! `n ≥ ⅓` for any pair of rotations (the measure is defined for every turn).
//!
//! Only the moment rows change; the force strains Γ are the sine element's. The moment
//! rows here are EM only; they run in the four-element lanes after the rest of the element
//! (the sine kernel with `C_Ω = 0`), or one element at a time.

use nalgebra::{Matrix3, Vector3, Vector6};

use super::strain::{raw_strains, stress_hessian, Config, A0, B0};
use super::{
    amax3, th_idx, ElementData, ElementEval, ElementState, FrozenScalars, Kinematics, StepConsts,
    GROSS_WEIGHT,
};
use crate::math::lane::{zeros, Lane};
use crate::math::{hat, hat_mul, mul_hat};
use crate::model::{Mat3, Vec3};

/// The objective denominator `n = ½ + ⅙ Σ_i d_i⁰·d_i¹` of a configuration.
#[inline]
pub fn denominator<T: Lane>(c: &Config<T>) -> T {
    let mut s = T::zero();
    for i in 0..3 {
        s += c.d[0].column(i).dot(&c.d[1].column(i));
    }
    T::splat(0.5) + s * T::splat(1.0 / 6.0)
}

/// Raw strains `(Γ, Ω̃)` with the rational moment strains `Ω̃ = q/n`.
#[inline]
pub fn rational_strains<T: Lane>(c: &Config<T>, h: T) -> Vector6<T> {
    let (g, o) = raw_strains(c, h);
    let n = denominator(c);
    Vector6::new(g.x, g.y, g.z, o.x / n, o.y / n, o.z / n)
}

/// `∂n/∂d` on the six director fields (`a_1..a_3, b_1..b_3`): `∂n/∂a_i = b_i/6`,
/// `∂n/∂b_i = a_i/6`.
#[inline]
fn denominator_gradient<T: Lane>(c: &Config<T>) -> [Vector3<T>; 6] {
    let s = T::splat(1.0 / 6.0);
    // (Loops into zeroed arrays, not `from_fn`: that moves each lane value through a
    // buffer.)
    let mut g = [zeros(); 6];
    for p in 0..3 {
        g[p] = c.d[1].column(p) * s;
        g[3 + p] = c.d[0].column(p) * s;
    }
    g
}

/// `∂q_k/∂d` of the sine moment strains on the six director fields: for the even
/// permutation `(k, i, j)`, `q_k = (a_j·b_i − a_i·b_j)/(2h)`, so `∂q_k/∂a_j = b_i/(2h)`,
/// `∂q_k/∂a_i = −b_j/(2h)`, `∂q_k/∂b_i = a_j/(2h)`, `∂q_k/∂b_j = −a_i/(2h)`, and zero on
/// `a_k`, `b_k` (the moment rows of [`super::strain::strain_gradient`]).
#[inline]
fn sine_gradient<T: Lane>(c: &Config<T>, h: T) -> [[Vector3<T>; 6]; 3] {
    let s = T::splat(0.5) / h;
    let (a, b) = (&c.d[0], &c.d[1]);
    let mut g = [[zeros(); 6]; 3];
    for (k, row) in g.iter_mut().enumerate() {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        row[j] = b.column(i) * s;
        row[i] = -(b.column(j) * s);
        row[3 + i] = a.column(j) * s;
        row[3 + j] = -(a.column(i) * s);
    }
    g
}

/// `q` (the sine moment strains) of a configuration.
#[inline]
fn sine_omega<T: Lane>(c: &Config<T>, h: T) -> Vector3<T> {
    raw_strains(c, h).1
}

/// The algebraic discrete gradient `B̄` of the rational moment strains between `c0` and
/// `c1` (rows k = 0..3, the six director fields): `B̄ (Φ₁ − Φ₀) = Ω̃₁ − Ω̃₀` exactly.
pub fn discrete_gradient(c0: &Config, c1: &Config, h: f64) -> [[Vec3; 6]; 3] {
    let mid = c0.mean(c1);
    let (q0, q1) = (sine_omega(c0, h), sine_omega(c1, h));
    let (n0, n1) = (denominator(c0), denominator(c1));
    let (nbar, qbar) = (0.5 * (n0 + n1), 0.5 * (q0 + q1));
    let (dq, dn) = (sine_gradient(&mid, h), denominator_gradient(&mid));
    let inv = 1.0 / (n0 * n1);
    std::array::from_fn(|k| std::array::from_fn(|p| (dq[k][p] * nbar - dn[p] * qbar[k]) * inv))
}

/// The gradient `∂Ω̃/∂d` of the rational moment strains at one configuration.
pub fn gradient(c: &Config, h: f64) -> [[Vec3; 6]; 3] {
    let q = sine_omega(c, h);
    let n = denominator(c);
    let (dq, dn) = (sine_gradient(c, h), denominator_gradient(c));
    std::array::from_fn(|k| std::array::from_fn(|p| (dq[k][p] - dn[p] * (q[k] / n)) / n))
}

/// Element residual and tangent of an element with the rational measure: the sine
/// kernel ([`super::residual_tangent_into`]) with the moment stiffness removed, plus the
/// moment rows of [`add_moment_terms`].
#[allow(clippy::too_many_arguments)]
pub fn residual_tangent_into(
    data: &ElementData,
    st: &ElementState,
    kin: &Kinematics,
    s: &FrozenScalars,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
    out: &mut ElementEval,
) {
    let mut base = data.clone();
    base.props.c_omega = Mat3::zeros();
    super::residual_tangent_into(&base, st, kin, s, k, trans_diss, want_tangent, out);
    add_moment_terms(&data.props.c_omega, data, st, kin, s, want_tangent, out);
}

/// Adds the rational measure's moment rows to `out`, an evaluation of the sine kernel
/// with the moment stiffness removed (`c_Ω = 0`; one element, or a lane of four, whose
/// `data` carry `C_Ω = 0`, so the moment stiffness `c_omega` comes apart): the moment rows
/// `h B̄ᵀ M*` projected onto the rotations with the mid-point directors, and (with
/// `want_tangent`) their exact linearization. `M* = C_Ω(½(Ω̃_n + Ω̃_{n+1}) − Ω̃° +
/// ½ β_Ω ΔΩ̃)` (EM with Kelvin–Voigt damping, the mean of the strains).
///
/// Generic over the kernel's [`Lane`]: a lane of four gives each element the numbers of
/// the one-element evaluation, bit for bit (the same operations in the same order).
pub fn add_moment_terms<T: Lane>(
    c_omega: &Matrix3<T>,
    data: &ElementData<T>,
    st: &ElementState<T>,
    kin: &Kinematics<T>,
    s: &FrozenScalars<T>,
    want_tangent: bool,
    out: &mut ElementEval<T>,
) {
    let h = data.props.h;
    let half = T::splat(0.5);
    let (c0, c1, mid) = (&st.cfg, &kin.cfg1, &kin.mid);
    let (q0, q1) = (sine_omega(c0, h), sine_omega(c1, h));
    let (n0, n1) = (denominator(c0), denominator(c1));
    let (nbar, qbar) = (half * (n0 + n1), (q0 + q1) * half);
    let (dq_mid, dn_mid) = (sine_gradient(mid, h), denominator_gradient(mid));
    let inv = T::one() / (n0 * n1);
    let mut bbar = [[zeros::<T, 3, 1>(); 6]; 3];
    for kk in 0..3 {
        for f in 0..6 {
            bbar[kk][f] = (dq_mid[kk][f] * nbar - dn_mid[f] * qbar[kk]) * inv;
        }
    }
    // Stresses from the mean of the strains the kinematics carries (the rational ones).
    let om_n: Vector3<T> = kin.eps_n.fixed_rows::<3>(3).into_owned();
    let om_1: Vector3<T> = kin.eps1.fixed_rows::<3>(3).into_owned();
    let om0_ref: Vector3<T> = data.eps0.fixed_rows::<3>(3).into_owned();
    let mean = (om_n + om_1) * half;
    let mstar = c_omega * (mean - om0_ref + (om_1 - om_n) * (half * s.beta_omega));
    // Forces on the six director fields.
    let mut f = [zeros::<T, 3, 1>(); 6];
    for (ff, x) in f.iter_mut().enumerate() {
        *x = bbar[0][ff] * (h * mstar[0]);
        *x += bbar[1][ff] * (h * mstar[1]);
        *x += bbar[2][ff] * (h * mstar[2]);
    }
    // Round-off floor, as the sine kernel's (GROSS_WEIGHT · h |B̄|ᵀ |C| (|Ω̃| + |Ω̃°|)).
    let gross = c_omega.map(T::abs) * (mean.map(T::abs) + om0_ref.map(T::abs));
    let gw = T::splat(GROSS_WEIGHT);
    let mut floor = [T::zero(); 6];
    for (ff, x) in floor.iter_mut().enumerate() {
        *x = gw * amax3(&bbar[0][ff]) * h * gross[0];
        *x += gw * amax3(&bbar[1][ff]) * h * gross[1];
        *x += gw * amax3(&bbar[2][ff]) * h * gross[2];
    }
    let dcol = |l: usize, i: usize| -> Vector3<T> { mid.d[l].column(i).into_owned() };
    for l in 0..2 {
        let mut rt = zeros::<T, 3, 1>();
        let mut fmax = T::zero();
        let mut dmax = T::zero();
        for i in 0..3 {
            rt += dcol(l, i).cross(&f[3 * l + i]);
            fmax = fmax.max(amax3(&f[3 * l + i])).max(floor[3 * l + i]);
            let d = dcol(l, i);
            dmax = dmax.max(d.dot(&d));
        }
        let dnorm = dmax.sqrt();
        for cc in 0..3 {
            out.r[th_idx(l) + cc] += rt[cc];
            out.scale[th_idx(l) + cc] = out.scale[th_idx(l) + cc].max(fmax * dnorm);
        }
    }
    if !want_tangent {
        return;
    }
    let (dq_1, dn_1) = (sine_gradient(c1, h), denominator_gradient(c1));
    let amat = kin.amat;
    let at = [amat[0].transpose(), amat[1].transpose()];
    // Material part: h B̄ᵀ (½(1 + β_Ω) C_Ω) DΩ̃(Φ_{n+1}), reduced to (θ_0, θ_1): the
    // gradient at the end of the step ([`gradient`], from the pieces at hand).
    let mut d1 = [[zeros::<T, 3, 1>(); 6]; 3];
    for kk in 0..3 {
        for f in 0..6 {
            d1[kk][f] = (dq_1[kk][f] - dn_1[f] * (q1[kk] / n1)) / n1;
        }
    }
    let mut tb = [[zeros::<T, 3, 1>(); 2]; 3];
    let mut jb = [[zeros::<T, 3, 1>(); 2]; 3];
    for kk in 0..3 {
        for l in 0..2 {
            for i in 0..3 {
                tb[kk][l] += dcol(l, i).cross(&bbar[kk][3 * l + i]);
                jb[kk][l] += dcol(l, i).cross(&(at[l] * d1[kk][3 * l + i]));
            }
        }
    }
    let cm = c_omega * (half * h * (T::one() + s.beta_omega));
    for l in 0..2 {
        for m in 0..2 {
            let mut blk = zeros::<T, 3, 3>();
            for k1 in 0..3 {
                for k2 in 0..3 {
                    if cm[(k1, k2)].any_nonzero() {
                        blk += tb[k1][l] * jb[k2][m].transpose() * cm[(k1, k2)];
                    }
                }
            }
            let mut v = out.k.fixed_view_mut::<3, 3>(th_idx(l), th_idx(m));
            v += blk;
        }
    }
    // Geometric part in field space: G_pq = ∂f_p/∂d_{q,n+1} (3×3 per pair of director
    // fields), then K_{θl θm} += −Σ_{p∈l, q∈m} \hat{d_p} G_pq A_m \hat{d_q}.
    let mut qm = [zeros::<T, 3, 1>(); 6];
    let mut q1m = [zeros::<T, 3, 1>(); 6];
    for ff in 0..6 {
        qm[ff] = dq_mid[0][ff] * mstar[0];
        qm[ff] += dq_mid[1][ff] * mstar[1];
        qm[ff] += dq_mid[2][ff] * mstar[2];
        q1m[ff] = dq_1[0][ff] * mstar[0];
        q1m[ff] += dq_1[1][ff] * mstar[1];
        q1m[ff] += dq_1[2][ff] * mstar[2];
    }
    let c_half = half * h * inv;
    let z = T::zero();
    let hq = stress_hessian(&Vector6::new(z, z, z, mstar[0], mstar[1], mstar[2]), h);
    let mq = mstar.dot(&qbar);
    let sixth = T::splat(1.0 / 6.0);
    // G_pq = a_p ⊗ ∂n/∂d_q(Φ_{n+1}) + b_p ⊗ (∂q/∂d_q(Φ_{n+1}))ᵀM* + s_pq I with
    // a_p = ½h/(n₀n₁) q_p·M* (mid) − f_p/n₁ and b_p = −½h/(n₀n₁) ∂n/∂d_p (mid), so each
    // block is two outer products, \hat{d}(a ⊗ w) Y = (d × a) ⊗ (Yᵀw), plus the scalar
    // part Σ_ij s_pq \hat{d_p} Y_q = Σ_j \hat{v_q} Y_q, v_q = Σ_i s_pq d_p (â is linear
    // in a). The scalar s_pq: the stress Hessian of q and, between a_i and b_i, that of n.
    let sc = |pf: usize, qf: usize| -> T {
        let mut x = c_half * nbar * hq[(A0 + pf, A0 + qf)];
        if pf % 3 == qf % 3 && pf / 3 != qf / 3 {
            x -= c_half * mq * sixth;
        }
        x
    };
    debug_assert_eq!(A0 + 3, B0);
    // Y_q = A_m \hat{d_q}, once per director field.
    let mut ad = [zeros::<T, 3, 3>(); 6];
    for (qf, y) in ad.iter_mut().enumerate() {
        *y = mul_hat(&amat[qf / 3], &dcol(qf / 3, qf % 3));
    }
    let mut u = [[zeros::<T, 3, 1>(); 2]; 2];
    let mut w = [[zeros::<T, 3, 1>(); 2]; 2];
    for l in 0..2 {
        for i in 0..3 {
            let pf = 3 * l + i;
            let a = qm[pf] * c_half - f[pf] / n1;
            let b = dn_mid[pf] * (-c_half);
            u[l][0] += dcol(l, i).cross(&a);
            u[l][1] += dcol(l, i).cross(&b);
            w[l][0] += ad[pf].tr_mul(&dn_1[pf]);
            w[l][1] += ad[pf].tr_mul(&q1m[pf]);
        }
    }
    for l in 0..2 {
        for m in 0..2 {
            let mut blk = u[l][0] * w[m][0].transpose() + u[l][1] * w[m][1].transpose();
            for j in 0..3 {
                let qf = 3 * m + j;
                let mut v = dcol(l, 0) * sc(3 * l, qf);
                v += dcol(l, 1) * sc(3 * l + 1, qf);
                v += dcol(l, 2) * sc(3 * l + 2, qf);
                blk += hat_mul(&v, &ad[qf]);
            }
            let mut kv = out.k.fixed_view_mut::<3, 3>(th_idx(l), th_idx(m));
            kv -= blk;
        }
    }
    // Projection: d/dθ of Σ_i d_{i,½} × f_i at fixed f: ½ Σ_i \hat{f_i} A_l \hat{d_i}.
    for l in 0..2 {
        let mut blk = zeros::<T, 3, 3>();
        for i in 0..3 {
            blk += hat(&f[3 * l + i]) * mul_hat(&amat[l], &dcol(l, i));
        }
        let mut v = out.k.fixed_view_mut::<3, 3>(th_idx(l), th_idx(l));
        v += blk * half;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::cay;

    fn rotated(q: &Mat3, c: &Config) -> Config {
        Config {
            r: [q * c.r[0], q * c.r[1]],
            d: [q * c.d[0], q * c.d[1]],
        }
    }

    fn sample(seed: f64) -> Config {
        let t0 = cay(&Vec3::new(0.3 * seed, -0.2, 0.5));
        let t1 = cay(&Vec3::new(-0.4, 0.9 * seed, 0.1));
        Config {
            r: [Vec3::new(0.1, 0.2, -0.3 * seed), Vec3::new(0.9, 0.4, 0.1)],
            d: [t0, t1],
        }
    }

    #[test]
    fn a_pure_turn_gives_three_sine_over_two_plus_cosine() {
        let h = 0.3;
        for delta in [0.01, 0.5, 1.0, 1.5, 2.5, 3.1] {
            for axis in [Vec3::x(), Vec3::y(), Vec3::z()] {
                let base = cay(&Vec3::new(0.2, -0.7, 0.4));
                let turn = nalgebra::Rotation3::from_axis_angle(
                    &nalgebra::Unit::new_normalize(base * axis),
                    delta,
                );
                let c = Config {
                    r: [Vec3::zeros(), base * Vec3::z() * h],
                    d: [base, turn.matrix() * base],
                };
                let om = rational_strains(&c, h).fixed_rows::<3>(3).into_owned();
                let want = axis * (3.0 * delta.sin() / ((2.0 + delta.cos()) * h));
                assert!((om - want).norm() < 1e-13 / h, "{delta}: {om} vs {want}");
            }
        }
    }

    #[test]
    fn discrete_gradient_gives_the_exact_strain_difference() {
        let h = 0.7;
        for (s0, s1) in [(0.3, -0.8), (1.5, 2.0), (-2.0, 0.1)] {
            let (c0, c1) = (sample(s0), sample(s1));
            let bb = discrete_gradient(&c0, &c1, h);
            let dd: [Vec3; 6] = std::array::from_fn(|p| {
                let (l, i) = (p / 3, p % 3);
                c1.d[l].column(i) - c0.d[l].column(i)
            });
            let lhs = Vec3::from_fn(|k, _| (0..6).map(|p| bb[k][p].dot(&dd[p])).sum());
            let rhs = rational_strains(&c1, h).fixed_rows::<3>(3).into_owned()
                - rational_strains(&c0, h).fixed_rows::<3>(3).into_owned();
            assert!(
                (lhs - rhs).norm() < 1e-14 * (1.0 + rhs.norm()),
                "{lhs} vs {rhs}"
            );
        }
    }

    #[test]
    fn discrete_gradient_annihilates_infinitesimal_rotations() {
        let h = 0.4;
        let (c0, c1) = (sample(0.7), sample(-1.3));
        let mid = c0.mean(&c1);
        let bb = discrete_gradient(&c0, &c1, h);
        let w = Vec3::new(0.3, -1.1, 0.6);
        let rot = Vec3::from_fn(|k, _| {
            (0..6)
                .map(|p| bb[k][p].dot(&w.cross(&mid.d[p / 3].column(p % 3).into_owned())))
                .sum()
        });
        let size: f64 = bb.iter().flatten().map(|v| v.norm()).sum();
        assert!(rot.norm() < 1e-15 * size * w.norm(), "{rot}");
    }

    #[test]
    fn rational_strains_are_frame_indifferent() {
        let c = sample(0.4);
        let q = cay(&Vec3::new(0.7, -0.4, 1.3));
        let (e0, e1) = (
            rational_strains(&c, 0.5),
            rational_strains(&rotated(&q, &c), 0.5),
        );
        assert!((e0 - e1).norm() < 1e-14 * e0.norm());
    }

    #[test]
    fn gradient_is_the_derivative_of_the_strains() {
        let h = 0.6;
        let c = sample(0.9);
        let g = gradient(&c, h);
        let pert: [Vec3; 6] =
            std::array::from_fn(|p| Vec3::new(0.3 * p as f64, -0.2, 0.1 + 0.05 * p as f64));
        let shifted = |e: f64| {
            let mut x = c;
            for p in 0..6 {
                let mut col = x.d[p / 3].column_mut(p % 3);
                col += pert[p] * e;
            }
            rational_strains(&x, h).fixed_rows::<3>(3).into_owned()
        };
        let e = 1e-6;
        let fd = (shifted(e) - shifted(-e)) / (2.0 * e);
        let an = Vec3::from_fn(|k, _| (0..6).map(|p| g[k][p].dot(&pert[p])).sum());
        assert!((fd - an).norm() < 1e-8 * an.norm(), "{fd} vs {an}");
    }

    #[test]
    fn small_turns_agree_with_the_sine_measure_to_second_order() {
        // Ω̃ − Ω = Ω (1/n − 1) = O(δ³/h): the ratio of the differences at δ and δ/2 is 8.
        let h = 1.0;
        let diff = |delta: f64| {
            let c = Config {
                r: [Vec3::zeros(), Vec3::z()],
                d: [Mat3::identity(), cay(&(Vec3::new(0.3, -0.5, 0.8) * delta))],
            };
            (rational_strains(&c, h) - super::super::strains6(&c, h)).norm()
        };
        let ratio = diff(1e-2) / diff(5e-3);
        assert!((ratio - 8.0).abs() < 1e-3, "{ratio}");
    }
}
