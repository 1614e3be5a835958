//! Small fixed-size algebra on SO(3). The scheme needs only rational functions of the
//! rotation increment (the Cayley transform), never `exp`/`log`: this keeps the CPU and
//! GPU kernels to `+ − × ÷` and `sqrt`.

pub mod lane;
pub mod rng;

use crate::model::{Mat3, Vec3};
use lane::{identity3, Lane};
use nalgebra::{Matrix3, Vector3};

/// Skew matrix `â` with `â b = a × b`.
#[inline]
pub fn hat<T: Lane>(a: &Vector3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(z, -a.z, a.y, a.z, z, -a.x, -a.y, a.x, z)
}

/// `â M` without forming `â`: the cross product of `a` with each column of `M`
/// (27 flops instead of a 3×3 product's 45).
#[inline]
pub fn hat_mul<T: Lane>(a: &Vector3<T>, m: &Matrix3<T>) -> Matrix3<T> {
    Matrix3::from_columns(&[
        a.cross(&m.column(0)),
        a.cross(&m.column(1)),
        a.cross(&m.column(2)),
    ])
}

/// `M v̂` without forming `v̂`: column j is `M (v × e_j)`, a combination of two columns
/// of `M` (27 flops instead of a 3×3 product's 45).
#[inline]
pub fn mul_hat<T: Lane>(m: &Matrix3<T>, v: &Vector3<T>) -> Matrix3<T> {
    let (c0, c1, c2) = (m.column(0), m.column(1), m.column(2));
    Matrix3::from_columns(&[
        c1 * v.z - c2 * v.y,
        c2 * v.x - c0 * v.z,
        c0 * v.y - c1 * v.x,
    ])
}

/// Cayley transform `cay(θ) = (I − ½θ̂)⁻¹(I + ½θ̂) = I + (θ̂ + ½θ̂²)/(1 + ¼|θ|²)`.
#[inline]
pub fn cay(theta: &Vec3) -> Mat3 {
    let t = hat(theta);
    let s = 1.0 / (1.0 + 0.25 * theta.norm_squared());
    Mat3::identity() + (t + 0.5 * t * t) * s
}

/// `(I − ½θ̂)⁻¹ = I + (½θ̂ + ¼θ̂²)/(1 + ¼|θ|²)`: the derivative of `cay(θ) d` with respect
/// to θ is `−(I − ½θ̂)⁻¹ \hat{d_{n+½}}` (differentiate `d_{n+1} − d_n = θ × d_{n+½}`).
#[inline]
pub fn inv_i_minus_half_hat(theta: &Vec3) -> Mat3 {
    let t = hat(theta);
    let s = 1.0 / (1.0 + 0.25 * theta.norm_squared());
    Mat3::identity() + (0.5 * t + 0.25 * t * t) * s
}

/// [`cay`] and [`inv_i_minus_half_hat`] of the same θ at the cost of one (they share
/// `θ̂²` and the factor `1/(1 + ¼|θ|²)`; bit-identical to the two calls: the factors ½ and
/// ¼ are exact in binary).
#[inline]
pub fn cay_with_factor<T: Lane>(theta: &Vector3<T>) -> (Matrix3<T>, Matrix3<T>) {
    let t = hat(theta);
    let tt = t * t;
    let c = T::splat;
    // (`dot` of θ with itself is `norm_squared` bit for bit: both sum the three squares.)
    let s = c(1.0) / (c(1.0) + c(0.25) * theta.dot(theta));
    (
        identity3() + (t + tt * c(0.5)) * s,
        identity3() + (t * c(0.5) + tt * c(0.25)) * s,
    )
}

/// Inverse Cayley map: the θ with `cay(θ) = R` for a rotation `R` (no half-turns),
/// `θ̂ = 2 (R − I)(R + I)⁻¹`.
pub fn cay_inv(r: &Mat3) -> Vec3 {
    let i = Mat3::identity();
    let m = 2.0 * (r - i) * (r + i).try_inverse().unwrap_or(i);
    Vec3::new(
        0.5 * (m[(2, 1)] - m[(1, 2)]),
        0.5 * (m[(0, 2)] - m[(2, 0)]),
        0.5 * (m[(1, 0)] - m[(0, 1)]),
    )
}

/// Exponential map of SO(3) (Rodrigues): `exp(θ̂) = I + sin|θ|/|θ| θ̂ + (1 − cos|θ|)/|θ|² θ̂²`.
/// Used only by the generalized-α baseline (CPU only); the EM/EDMC schemes use [`cay`].
pub fn exp_so3(theta: &Vec3) -> Mat3 {
    let t = hat(theta);
    let a2 = theta.norm_squared();
    let a = a2.sqrt();
    // Series below |θ| = 1e-4 (relative error of the truncated terms < 1e-17).
    let (s, c) = if a < 1e-4 {
        (1.0 - a2 / 6.0, 0.5 - a2 / 24.0)
    } else {
        (a.sin() / a, (1.0 - a.cos()) / a2)
    };
    Mat3::identity() + t * s + t * t * c
}

/// `|v|` computed as `max|vᵢ| · |v / max|vᵢ||`: finite for every finite `v` (the plain
/// sum of squares overflows from about 1e154 on) and equal to `|v|` to round-off.
pub fn scaled_norm(v: &Vec3) -> f64 {
    let m = v.amax();
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    m * (v / m).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cayley_is_a_rotation_and_inverts() {
        let th = Vec3::new(0.3, -1.2, 0.7);
        let r = cay(&th);
        assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        assert!((cay_inv(&r) - th).norm() < 1e-13);
        // d_{n+1} − d_n = θ × d_{n+½}
        let d = Vec3::new(0.2, 0.5, -0.9);
        let d1 = r * d;
        assert!(((d1 - d) - th.cross(&(0.5 * (d + d1)))).norm() < 1e-14);
        let a = inv_i_minus_half_hat(&th);
        assert!(((Mat3::identity() - 0.5 * hat(&th)) * a - Mat3::identity()).norm() < 1e-14);
    }

    #[test]
    fn exponential_is_a_rotation_about_its_axis() {
        for th in [Vec3::new(0.3, -1.2, 0.7), Vec3::new(1e-6, 2e-6, -1e-6)] {
            let r = exp_so3(&th);
            assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-14);
            assert!((r * th - th).norm() < 1e-14);
            // exp(θ̂) = cay(θ') with |θ'| = 2 tan(|θ|/2) along the same axis.
            let n = th.norm();
            let c = cay(&(th * (2.0 * (0.5 * n).tan() / n)));
            assert!((r - c).norm() < 1e-13);
        }
    }

    #[test]
    fn skew_products_match_the_skew_matrix() {
        let a = Vec3::new(0.3, -1.2, 0.7);
        let m = Mat3::new(1.0, 2.0, -3.0, 0.5, -4.0, 6.0, 7.0, 0.25, -1.5);
        assert!((hat_mul(&a, &m) - hat(&a) * m).norm() < 1e-14);
        assert!((mul_hat(&m, &a) - m * hat(&a)).norm() < 1e-14);
        // Not symmetric in the roles: a wrong column pairing is caught.
        assert!((mul_hat(&m, &a) - hat(&a) * m).norm() > 1.0);
    }
}
