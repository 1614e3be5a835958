//! A point mass at a node (`[[point_mass]]`). The host adds it at its node
//! (`Simulation::nodal_terms`); the GPU element kernel carries it on one end of one element
//! incident to the node (`shaders/element.wgsl`, `E_PMASS`: a device solve needs its rows
//! there, since they depend on the iterate), the twin of [`add_point_mass_rows`]. Both use
//! [`inertia_force`].

use super::{g_idx, u_idx, ElementEval, ElementState, Increment};
use crate::model::Vec3;

/// The inertia force of a point mass `m` at a node with increment `u`, velocity `v` at `n`
/// and translational dissipation unknown `g`: `m (2u/Δt − 2v − 2g)/Δt = m (v_{n+1} − v_n)/Δt`.
#[inline]
pub fn inertia_force(m: f64, u: &Vec3, v: &Vec3, g: &Vec3, dt: f64) -> Vec3 {
    m * (2.0 * u / dt - 2.0 * v - 2.0 * g) / dt
}

/// Adds the point masses `m[l]` carried by the element's ends to an element evaluation: the
/// inertia rows of end `l`'s translations and their row scales (the largest component), the
/// rows `m g_l` of the translational dissipation unknowns where `trans`, and with
/// `want_tangent` the blocks `(u_l, u_l) 2m/Δt² I`, `(u_l, g_l) −2m/Δt I` and
/// `(g_l, g_l) m I` (the last two where `trans`): what the GPU element kernel adds.
pub fn add_point_mass_rows(
    m: [f64; 2],
    st: &ElementState,
    inc: &Increment,
    dt: f64,
    trans: bool,
    want_tangent: bool,
    out: &mut ElementEval,
) {
    for l in 0..2 {
        let mp = m[l];
        if mp == 0.0 {
            continue;
        }
        let g = if trans { inc.g[l] } else { Vec3::zeros() };
        let f = inertia_force(mp, &inc.u[l], &st.v[l], &g, dt);
        let (fmax, gmax) = (f.amax(), (g * mp).amax());
        for c in 0..3 {
            let (iu, ig) = (u_idx(l) + c, g_idx(l) + c);
            out.r[iu] += f[c];
            out.scale[iu] = out.scale[iu].max(fmax);
            if trans {
                out.r[ig] += mp * g[c];
                out.scale[ig] = out.scale[ig].max(gmax);
            }
            if want_tangent {
                out.k[(iu, iu)] += 2.0 * mp / (dt * dt);
                if trans {
                    out.k[(iu, ig)] += -2.0 * mp / dt;
                    out.k[(ig, ig)] += mp;
                }
            }
        }
    }
}
