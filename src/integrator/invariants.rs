//! Energies and momenta of a state and the accelerations between two states: what the
//! step's acceptance tests and the observers ([`crate::observe`]) both read.
//!
//! Kinetic energy, `L` and `J` use the two-point rule (the consistent mass, exact for
//! these products); the stored energy uses the one-point rule, as the stresses do
//! (DESIGN §2).

use crate::element::{ElementData, M2};
use crate::integrator::state::State;
use crate::model::{Model, Vec3};

/// Energies and momenta of one state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Invariants {
    /// Kinetic energy.
    pub kinetic: f64,
    /// Stored energy (strain energy of the rods, the `λg + ½κg²` of rigid links and the
    /// penalty and stick energy of contact with obstacles and between rods).
    pub potential: f64,
    /// Linear momentum.
    pub l: Vec3,
    /// Angular momentum about the origin.
    pub j: Vec3,
}

impl Invariants {
    /// `H = K + V`.
    pub fn total(&self) -> f64 {
        self.kinetic + self.potential
    }
}

/// Kinetic and stored energy, linear and angular momentum of `state`.
pub fn invariants(model: &Model, data: &[ElementData], state: &State) -> Invariants {
    let mut out = Invariants::default();
    for (e, el) in model.elements.iter().enumerate() {
        let p = &data[e].props;
        let n = el.nodes;
        for l in 0..2 {
            for m in 0..2 {
                let w = p.h * M2[l][m];
                let (rl, vl, vm) = (state.r[n[l]], state.v[n[l]], state.v[n[m]]);
                out.kinetic += 0.5 * w * p.a_rho * vl.dot(&vm);
                out.l += w * p.a_rho * vm;
                out.j += w * p.a_rho * rl.cross(&vm);
                for a in 0..2 {
                    for b in 0..2 {
                        let ir = w * p.i_rho[(a, b)];
                        let (dla, vlb) = (state.d[e][l].column(a), state.vd[e][m][b]);
                        out.kinetic += 0.5 * ir * state.vd[e][l][a].dot(&vlb);
                        out.j += ir * dla.cross(&vlb);
                    }
                }
            }
        }
        let de = state.eps[e] - data[e].eps0;
        let (g, o) = (
            de.fixed_rows::<3>(0).into_owned(),
            de.fixed_rows::<3>(3).into_owned(),
        );
        out.potential +=
            0.5 * p.h * (g.dot(&p.c_gamma.component_mul(&g)) + o.dot(&(p.c_omega * o)));
    }
    for (link, &lambda) in model.links.iter().zip(&state.lambda) {
        out.potential += link.energy(lambda, &state.r[link.node]);
    }
    for (i, o) in model.obstacles.iter().enumerate() {
        out.potential += o.energy(&state.r, state.t);
        if let Some(a) = state.anchors.get(i) {
            out.potential += o.stick_energy(&state.r, state.t, a);
        }
    }
    for c in &model.rod_contacts {
        out.potential += c.energy(&state.r);
    }
    for (a, &m) in model.point_mass.iter().enumerate() {
        if m != 0.0 {
            out.kinetic += 0.5 * m * state.v[a].norm_squared();
            out.l += m * state.v[a];
            out.j += m * state.r[a].cross(&state.v[a]);
        }
    }
    out
}

/// L2 norms over the rods of the translational and director accelerations
/// `(v_{n+1} − v_n)/Δt` between two states (two-point rule).
pub fn acceleration_norms(
    model: &Model,
    data: &[ElementData],
    s0: &State,
    s1: &State,
) -> (f64, f64) {
    let dt = s1.t - s0.t;
    if dt <= 0.0 {
        return (0.0, 0.0);
    }
    let (mut at, mut ar) = (0.0, 0.0);
    for (e, el) in model.elements.iter().enumerate() {
        let h = data[e].props.h;
        let n = el.nodes;
        // Each acceleration once (the divisions dominate the cost).
        let acc = |a: usize| (s1.v[n[a]] - s0.v[n[a]]) / dt;
        let acc = [acc(0), acc(1)];
        let accd = |l: usize, a: usize| (s1.vd[e][l][a] - s0.vd[e][l][a]) / dt;
        let accd = [[accd(0, 0), accd(0, 1)], [accd(1, 0), accd(1, 1)]];
        for l in 0..2 {
            for m in 0..2 {
                let w = h * M2[l][m];
                at += w * acc[l].dot(&acc[m]);
                for a in 0..2 {
                    ar += w * accd[l][a].dot(&accd[m][a]);
                }
            }
        }
    }
    (at.max(0.0).sqrt(), ar.max(0.0).sqrt())
}
