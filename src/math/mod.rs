//! Small fixed-size algebra on SO(3). The scheme needs only rational functions of the
//! rotation increment (the Cayley transform), never `exp`/`log`: this keeps the CPU and
//! GPU kernels to `+ − × ÷` and `sqrt`.

pub mod rng;

use crate::model::{Mat3, Vec3};

/// Skew matrix `â` with `â b = a × b`.
#[inline]
pub fn hat(a: &Vec3) -> Mat3 {
    Mat3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
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
}
