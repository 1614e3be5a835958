//! Objective strains of one element at its single stress quadrature point (DESIGN §1–2).
//!
//! With two-node interpolation of `r` and of all three directors, and the one-point rule
//! (`N_l = ½`, `N_l' = ∓1/h`), writing `a_i = d_i^{(e)0}`, `b_i = d_i^{(e)1}`:
//!
//! ```text
//! Γ_i = ½ (a_i + b_i) · (r_1 − r_0) / h
//! Ω_k = ε_kij (a_j · b_i) / (2h)     e.g. Ω_1 = (a_3·b_2 − a_2·b_3)/(2h)
//! ```
//!
//! Both are bilinear in the eight vector fields `(r_0, r_1, a_1, a_2, a_3, b_1, b_2, b_3)`,
//! so `B(Φ_{n+½})(Φ_{n+1} − Φ_n) = ε(Φ_{n+1}) − ε(Φ_n)` exactly, and the Hessian of
//! `S·ε` is a constant 8×8 scalar matrix times `I₃`.

use nalgebra::{Matrix3, SMatrix, Vector3, Vector6};

use crate::math::lane::{zeros, Lane};
use crate::model::Vec3;

/// Index of a vector field of the element: `R0, R1` node positions, `A0+i` director `i`
/// of end 0, `B0+i` director `i` of end 1.
pub const R0: usize = 0;
/// Position of end 1.
pub const R1: usize = 1;
/// First director field of end 0 (`a_1`); `a_i` is `A0 + i`.
pub const A0: usize = 2;
/// First director field of end 1 (`b_1`); `b_i` is `B0 + i`.
pub const B0: usize = 5;
/// Number of vector fields.
pub const NFIELDS: usize = 8;

/// Element end a field belongs to.
#[inline]
pub fn field_end(p: usize) -> usize {
    match p {
        R0 => 0,
        R1 => 1,
        2..=4 => 0,
        _ => 1,
    }
}

/// Configuration of one element: end positions and end triads (columns `d_1, d_2, d_3`).
/// Generic over the kernel's [`Lane`] (one element per lane); `Config` is one element.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config<T: Lane = f64> {
    /// Positions of the two ends.
    pub r: [Vector3<T>; 2],
    /// Director triads of the two ends (columns are `d_1, d_2, d_3`; not assumed
    /// orthonormal).
    pub d: [Matrix3<T>; 2],
}

impl Config {
    /// Field `p` as a vector.
    #[inline]
    pub fn field(&self, p: usize) -> Vec3 {
        match p {
            R0 => self.r[0],
            R1 => self.r[1],
            2..=4 => self.d[0].column(p - A0).into(),
            _ => self.d[1].column(p - B0).into(),
        }
    }
}

impl<T: Lane> Config<T> {
    /// Componentwise mean `½(self + other)` (the mid-point configuration).
    #[inline]
    pub fn mean(&self, other: &Config<T>) -> Config<T> {
        let half = T::splat(0.5);
        Config {
            r: [
                (self.r[0] + other.r[0]) * half,
                (self.r[1] + other.r[1]) * half,
            ],
            d: [
                (self.d[0] + other.d[0]) * half,
                (self.d[1] + other.d[1]) * half,
            ],
        }
    }
}

/// Raw strains `(Γ, Ω)` of a configuration (without subtracting the reference values).
#[inline]
pub fn raw_strains<T: Lane>(c: &Config<T>, h: T) -> (Vector3<T>, Vector3<T>) {
    let dr = (c.r[1] - c.r[0]).map(|x| x / h);
    let a = &c.d[0];
    let b = &c.d[1];
    let mut gamma = zeros();
    for i in 0..3 {
        gamma[i] = T::splat(0.5) * (a.column(i) + b.column(i)).dot(&dr);
    }
    let ab = |j: usize, i: usize| a.column(j).dot(&b.column(i));
    let s = T::splat(0.5) / h;
    let omega = Vector3::new(
        s * (ab(2, 1) - ab(1, 2)),
        s * (ab(0, 2) - ab(2, 0)),
        s * (ab(1, 0) - ab(0, 1)),
    );
    (gamma, omega)
}

/// Strain gradient `B = ∂(Γ, Ω)/∂Φ` at configuration `c`: row `k` (0–2 Γ, 3–5 Ω),
/// field `p` gives the 3-vector `B[k][p]`.
pub type StrainGradient<T = f64> = [[Vector3<T>; NFIELDS]; 6];

/// `B(Φ)` for the bilinear strains of [`raw_strains`].
///
/// Built as one array expression, every entry written once (the structural zeros too):
/// no zero fill before and no copy after, which for [`Lane`]s of four elements are
/// 4.6 kB each. The Ω entries are `0 ± …` as if accumulated onto zeros (that keeps the
/// sign of a zero entry, bit for bit).
#[inline]
pub fn strain_gradient<T: Lane>(c: &Config<T>, h: T) -> StrainGradient<T> {
    let z: Vector3<T> = zeros();
    let half = T::splat(0.5);
    // 1/h once (divisions cost several multiplications' throughput).
    let inv_h = T::one() / h;
    let dr = (c.r[1] - c.r[0]) * inv_h;
    let a = &c.d[0];
    let b = &c.d[1];
    let dr_half = dr * half;
    let gamma_row = |i: usize| -> [Vector3<T>; NFIELDS] {
        let di: Vector3<T> = (a.column(i) + b.column(i)) * half;
        let on = |j: usize| if j == i { dr_half } else { z };
        [
            -di * inv_h,
            di * inv_h,
            on(0),
            on(1),
            on(2),
            on(0),
            on(1),
            on(2),
        ]
    };
    // Ω_k = ε_kij a_j·b_i /(2h): ∂/∂a_j = ε_kij b_i/(2h), ∂/∂b_i = ε_kij a_j/(2h).
    let s = half / h;
    let omega_row = |(_k, i, j): (usize, usize, usize)| -> [Vector3<T>; NFIELDS] {
        // ε_kij = +1 and ε_kji = −1
        let mut row = [z; NFIELDS];
        row[A0 + j] = z + b.column(i) * s;
        row[B0 + i] = z + a.column(j) * s;
        row[A0 + i] = z - b.column(j) * s;
        row[B0 + j] = z - a.column(i) * s;
        row
    };
    [
        gamma_row(0),
        gamma_row(1),
        gamma_row(2),
        omega_row(EPS_POSITIVE[0]),
        omega_row(EPS_POSITIVE[1]),
        omega_row(EPS_POSITIVE[2]),
    ]
}

/// The even permutations `(k, i, j)` of `(0, 1, 2)` (where `ε_kij = +1`).
const EPS_POSITIVE: [(usize, usize, usize); 3] = [(0, 1, 2), (1, 2, 0), (2, 0, 1)];

/// The fields on which each strain row of [`strain_gradient`] can be nonzero (the other
/// four entries of a row are exact zeros): `Γ_i` depends on `r_0, r_1, a_i, b_i`, `Ω_k`
/// on the two directors of each end other than the `k`-th.
pub const GRADIENT_FIELDS: [[usize; 4]; 6] = [
    [R0, R1, A0, B0],
    [R0, R1, A0 + 1, B0 + 1],
    [R0, R1, A0 + 2, B0 + 2],
    [A0 + 1, A0 + 2, B0 + 1, B0 + 2],
    [A0, A0 + 2, B0, B0 + 2],
    [A0, A0 + 1, B0, B0 + 1],
];

/// Hessian of `S·ε(Φ)` with respect to the fields, as the scalar 8×8 matrix `H_s` with
/// `∂²(S·ε)/∂Φ_p∂Φ_q = H_s[p, q] I₃`. `s = (N, M)`. Constant in Φ because ε is bilinear.
pub fn stress_hessian<T: Lane>(s: &Vector6<T>, h: T) -> SMatrix<T, NFIELDS, NFIELDS> {
    let mut hs = zeros::<T, NFIELDS, NFIELDS>();
    let c = T::splat(0.5) / h;
    for i in 0..3 {
        let n = s[i] * c;
        for p in [A0 + i, B0 + i] {
            hs[(R1, p)] += n;
            hs[(p, R1)] += n;
            hs[(R0, p)] -= n;
            hs[(p, R0)] -= n;
        }
    }
    for (k, i, j) in EPS_POSITIVE {
        let m = s[3 + k] * c;
        // +m a_j·b_i − m a_i·b_j
        hs[(A0 + j, B0 + i)] += m;
        hs[(B0 + i, A0 + j)] += m;
        hs[(A0 + i, B0 + j)] -= m;
        hs[(B0 + j, A0 + i)] -= m;
    }
    hs
}

/// `B·δΦ` for a field perturbation (used by tests and the dissipation derivatives).
pub fn apply_gradient(bm: &StrainGradient, dphi: &[Vec3; NFIELDS]) -> Vector6<f64> {
    let mut out = Vector6::zeros();
    for (k, row) in bm.iter().enumerate() {
        out[k] = row.iter().zip(dphi).map(|(b, x)| b.dot(x)).sum();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::cay;
    use crate::model::Mat3;

    fn sample(seed: f64) -> Config {
        let m = |x: f64| {
            Mat3::new(
                1.0 + 0.1 * x,
                0.2 * x,
                -0.3,
                0.1,
                0.9 - 0.2 * x,
                0.4 * x,
                0.05,
                -0.1 * x,
                1.1,
            )
        };
        Config {
            r: [
                Vec3::new(0.1, 0.2 * seed, -0.3),
                Vec3::new(1.1, 0.4, 0.2 * seed),
            ],
            d: [m(seed), m(seed + 0.7)],
        }
    }

    fn as_fields(c: &Config) -> [Vec3; NFIELDS] {
        std::array::from_fn(|p| c.field(p))
    }

    fn strains6(c: &Config, h: f64) -> Vector6<f64> {
        let (g, o) = raw_strains(c, h);
        Vector6::new(g.x, g.y, g.z, o.x, o.y, o.z)
    }

    #[test]
    fn gradient_vanishes_off_its_listed_fields() {
        let bm = strain_gradient(&sample(0.6), 0.8);
        for (k, row) in bm.iter().enumerate() {
            for (q, b) in row.iter().enumerate() {
                if !GRADIENT_FIELDS[k].contains(&q) {
                    assert_eq!(*b, Vec3::zeros(), "row {k} field {q}");
                }
            }
        }
    }

    #[test]
    fn midpoint_gradient_gives_exact_strain_difference() {
        let (c0, c1) = (sample(0.3), sample(-0.8));
        let h = 0.7;
        let mid = c0.mean(&c1);
        let f0 = as_fields(&c0);
        let f1 = as_fields(&c1);
        let d: [Vec3; NFIELDS] = std::array::from_fn(|p| f1[p] - f0[p]);
        let lhs = apply_gradient(&strain_gradient(&mid, h), &d);
        let rhs = strains6(&c1, h) - strains6(&c0, h);
        assert!((lhs - rhs).norm() < 1e-14 * (1.0 + rhs.norm()));
    }

    #[test]
    fn strains_are_frame_indifferent() {
        let c = sample(0.4);
        let q = cay(&Vec3::new(0.7, -0.4, 1.3));
        let t = Vec3::new(3.0, -2.0, 5.0);
        let moved = Config {
            r: [q * c.r[0] + t, q * c.r[1] + t],
            d: [q * c.d[0], q * c.d[1]],
        };
        let e0 = strains6(&c, 0.5);
        let e1 = strains6(&moved, 0.5);
        assert!((e0 - e1).norm() < 1e-14 * e0.norm());
    }

    #[test]
    fn hessian_is_derivative_of_gradient() {
        let c = sample(0.1);
        let h = 0.9;
        let s = Vector6::new(1.0, -2.0, 0.5, 0.3, 1.7, -0.8);
        let hs = stress_hessian(&s, h);
        // d/dε of (B(Φ + ε e)ᵀ s) along a random perturbation of every field.
        let bm0 = strain_gradient(&c, h);
        let pert: [Vec3; NFIELDS] =
            std::array::from_fn(|p| Vec3::new(0.3 * p as f64, -0.2, 0.1 + 0.05 * p as f64));
        let fields = as_fields(&c);
        let shifted = |eps: f64| {
            let f: [Vec3; NFIELDS] = std::array::from_fn(|p| fields[p] + eps * pert[p]);
            Config {
                r: [f[R0], f[R1]],
                d: [
                    Mat3::from_columns(&[f[2], f[3], f[4]]),
                    Mat3::from_columns(&[f[5], f[6], f[7]]),
                ],
            }
        };
        let bm1 = strain_gradient(&shifted(1.0), h);
        for p in 0..NFIELDS {
            let mut fd = Vec3::zeros();
            for k in 0..6 {
                fd += (bm1[k][p] - bm0[k][p]) * s[k];
            }
            let mut an = Vec3::zeros();
            for q in 0..NFIELDS {
                an += hs[(p, q)] * pert[q];
            }
            assert!((fd - an).norm() < 1e-13, "field {p}: {fd} vs {an}");
        }
    }
}
