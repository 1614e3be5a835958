//! Drag per unit length on one element: with a drag coefficient `c`, the force
//! `−c (r_{n+1} − r_n)/Δt` per unit length through the consistent pattern,
//! `F_l = −(c h/Δt) Σ_m M2[l][m] u_m` on the two ends. Linear in the increments; its work
//! over a step, `Σ_l F_l·u_l ≤ 0`, is part of the dissipation D.
//!
//! The host adds these rows after the element kernel on the CPU path
//! (`integrator::simulation::drag`); the GPU element kernel adds them with the element's own
//! (`shaders/element.wgsl`, `E_DRAG`), the twin of [`add_drag_rows`].

use super::{u_idx, ElementEval, M2};
use crate::model::{ElementProps, Vec3};

/// The drag forces `F_l` on the two ends at the end increments `u`.
pub fn drag_forces(props: &ElementProps, u: &[Vec3; 2], dt: f64) -> [Vec3; 2] {
    let k = props.drag * props.h / dt;
    std::array::from_fn(|l| -(u[0] * M2[l][0] + u[1] * M2[l][1]) * k)
}

/// The energy the drag takes out over the step, `−Σ_l F_l·u_l ≥ 0`.
pub fn drag_dissipation(props: &ElementProps, u: &[Vec3; 2], dt: f64) -> f64 {
    let f = drag_forces(props, u, dt);
    -(f[0].dot(&u[0]) + f[1].dot(&u[1]))
}

/// Adds the drag rows `−F_l` to an element evaluation, the largest component of `F_l` to
/// the row scales of end `l`'s translations, and (with `want_tangent`) the `(u_l, u_m)`
/// blocks `(c h/Δt) M2[l][m] I`: what the GPU element kernel adds.
pub fn add_drag_rows(
    props: &ElementProps,
    u: &[Vec3; 2],
    dt: f64,
    want_tangent: bool,
    out: &mut ElementEval,
) {
    if props.drag == 0.0 {
        return;
    }
    let k = props.drag * props.h / dt;
    let f = drag_forces(props, u, dt);
    for l in 0..2 {
        let fmax = f[l].amax();
        for c in 0..3 {
            let i = u_idx(l) + c;
            out.r[i] -= f[l][c];
            out.scale[i] = out.scale[i].max(fmax);
            if want_tangent {
                for m in 0..2 {
                    out.k[(i, u_idx(m) + c)] += k * M2[l][m];
                }
            }
        }
    }
}
