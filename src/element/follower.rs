//! Follower line loads on one element end (twin of the follower rows of the WGSL element
//! kernel, `shaders/element.wgsl`, and of its tangent's): the end carries
//! `w Σ_i f_i d_{i,n+½}` and `w Σ_i m_i d_{i,n+½}`, `w` its share of the element's length
//! (h/2), `f`, `m` the load per unit length in the director frame (its time table's
//! factor at the step's middle included) and `d_{n+½} = ½(d_n + cay(θ) d_n)` the end's
//! mid-step directors, so the load turns with the end's rotation increment θ. Its
//! derivative: `∂d_{i,n+½}/∂θ = −½ A(θ) \hat{d_{i,n+½}}`, `A = (I − ½θ̂)⁻¹`.

use crate::model::{Mat3, Vec3};

/// Force and moment of a follower load on one element end, and their derivatives with
/// respect to the end's rotation increment `θ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndLoad {
    /// `w Σ_i f_i d_{i,n+½}`.
    pub force: Vec3,
    /// `w Σ_i m_i d_{i,n+½}`.
    pub moment: Vec3,
    /// `∂force/∂θ` (zero unless asked for).
    pub d_force: Mat3,
    /// `∂moment/∂θ` (zero unless asked for).
    pub d_moment: Mat3,
}

/// The load on an end whose mid-step directors are the columns of `half`, with
/// `a = (I − ½θ̂)⁻¹` of its rotation increment; the derivatives only with `tangent`.
pub fn end_load(half: &Mat3, a: &Mat3, f: &Vec3, m: &Vec3, w: f64, tangent: bool) -> EndLoad {
    let (mut d_force, mut d_moment) = (Mat3::zeros(), Mat3::zeros());
    if tangent {
        for i in 0..3 {
            let k = a * crate::math::hat(&half.column(i).into_owned()) * (-0.5 * w);
            d_force += k * f[i];
            d_moment += k * m[i];
        }
    }
    EndLoad {
        force: half * f * w,
        moment: half * m * w,
        d_force,
        d_moment,
    }
}

/// The end's mid-step directors `½(d_n + cay(θ) d_n)` and `(I − ½θ̂)⁻¹` for
/// [`end_load`].
pub fn mid_directors(d_n: &Mat3, theta: &Vec3) -> (Mat3, Mat3) {
    (
        0.5 * (d_n + crate::math::cay(theta) * d_n),
        crate::math::inv_i_minus_half_hat(theta),
    )
}

/// Adds the follower line loads `fm` (force, then moment per unit length in the director
/// frame, factors included) of an element of length `h` at state `st` and increment `inc`
/// to its evaluation: the rows `−F_l`, `−M_l`, their row scales and (with `tangent`)
/// `−∂F_l/∂θ_l`, `−∂M_l/∂θ_l` (the GPU element kernel's follower rows; the host adds the
/// same loads per node from [`end_load`]).
pub fn add_follower_rows(
    fm: &[f64; 6],
    st: &super::ElementState,
    inc: &super::Increment,
    h: f64,
    tangent: bool,
    out: &mut super::ElementEval,
) {
    if fm.iter().all(|&x| x == 0.0) {
        return;
    }
    let f = Vec3::new(fm[0], fm[1], fm[2]);
    let m = Vec3::new(fm[3], fm[4], fm[5]);
    for l in 0..2 {
        let (half, a) = mid_directors(&st.cfg.d[l], &inc.theta[l]);
        let x = end_load(&half, &a, &f, &m, 0.5 * h, tangent);
        let (u, th) = (super::u_idx(l), super::th_idx(l));
        let (fmax, mmax) = (x.force.amax(), x.moment.amax());
        for c in 0..3 {
            out.r[u + c] -= x.force[c];
            out.r[th + c] -= x.moment[c];
            out.scale[u + c] = out.scale[u + c].max(fmax);
            out.scale[th + c] = out.scale[th + c].max(mmax);
            if tangent {
                for k in 0..3 {
                    out.k[(u + c, th + k)] -= x.d_force[(c, k)];
                    out.k[(th + c, th + k)] -= x.d_moment[(c, k)];
                }
            }
        }
    }
}
