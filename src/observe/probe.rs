//! Probes: the state of single nodes, cheap enough to take every step.
//!
//! Node directors and rotations come from the element ends: the triad of a node is that of
//! the end of the lowest-numbered element touching it (the same choice as
//! `trajectory.npz` and the VTK files), and its rotation is `Λ = D D°ᵀ` with `D°` that
//! end's reference triad, reported as a rotation vector (axis × angle, |angle| ≤ π).

use nalgebra::Rotation3;

use crate::integrator::state::State;
use crate::model::{Model, Vec3};

/// Per node: the (element, end) whose director triad is the node's (the lowest-numbered
/// element touching it; `(usize::MAX, 0)` for a node without elements) and that element's
/// rod (`-1` without elements).
pub fn node_director_ends(model: &Model) -> (Vec<(usize, usize)>, Vec<i64>) {
    let n = model.n_nodes();
    let mut node_end = vec![(usize::MAX, 0); n];
    let mut rod_of_node = vec![-1i64; n];
    for (e, el) in model.elements.iter().enumerate() {
        for (l, &a) in el.nodes.iter().enumerate() {
            if node_end[a].0 == usize::MAX {
                node_end[a] = (e, l);
                rod_of_node[a] = el.rod as i64;
            }
        }
    }
    (node_end, rod_of_node)
}

/// What a probe reports about its node.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeValues {
    /// Position `r`.
    pub position: Vec3,
    /// Displacement `r − r°`.
    pub displacement: Vec3,
    /// Rotation vector of `Λ = D D°ᵀ` (zero for a node without elements).
    pub rotation: Vec3,
    /// Velocity `v`.
    pub velocity: Vec3,
}

/// The values of node `a` in `state`; `end` is its entry of [`node_director_ends`].
pub fn probe_values(model: &Model, state: &State, a: usize, end: (usize, usize)) -> ProbeValues {
    let (e, l) = end;
    let rotation = if e == usize::MAX {
        Vec3::zeros()
    } else {
        let lam = state.d[e][l] * model.elements[e].ref_triad[l].transpose();
        Rotation3::from_matrix_unchecked(lam).scaled_axis()
    };
    ProbeValues {
        position: state.r[a],
        displacement: state.r[a] - model.nodes[a],
        rotation,
        velocity: state.v[a],
    }
}
