//! Probes: the state of single nodes, cheap enough to take every step.
//!
//! Node directors and rotations come from the element ends: the triad of a node is that of
//! the end of the lowest-numbered element touching it (the same choice as
//! `trajectory.npz` and the VTK files), and its rotation is `Λ = D D°ᵀ` with `D°` that
//! end's reference triad, reported as a rotation vector (axis × angle, |angle| ≤ π,
//! [`rotation_vector`]).

use crate::integrator::state::State;
use crate::model::{Mat3, Model, Vec3};

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
        rotation_vector(&(state.d[e][l] * model.elements[e].ref_triad[l].transpose()))
    };
    ProbeValues {
        position: state.r[a],
        displacement: state.r[a] - model.nodes[a],
        rotation,
        velocity: state.v[a],
    }
}

/// The rotation vector `θ n` (axis × angle, `0 ≤ θ ≤ π`) of the rotation matrix `r`: its
/// logarithm, accurate to round-off relative to `θ` at every angle. The angle is
/// `atan2(|a|, (tr r − 1)/2)` with `a` the axial vector of `(r − rᵀ)/2` (`= sin θ n`),
/// so small angles keep their digits (an `acos` of the trace loses them below ≈ 1e-4 rad
/// and returns 0 below ≈ 1e-8 rad); near π, where `a` vanishes, the axis comes from the
/// symmetric part `(r + rᵀ)/2 − cos θ I = (1 − cos θ) n nᵀ`.
pub fn rotation_vector(r: &Mat3) -> Vec3 {
    let a = 0.5
        * Vec3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
    let s = a.norm();
    let c = 0.5 * (r.trace() - 1.0);
    let theta = s.atan2(c);
    if c >= 0.0 {
        // θ ≤ π/2: sin θ = s carries the axis to full relative accuracy.
        return if s > 0.0 {
            a * (theta / s)
        } else {
            Vec3::zeros()
        };
    }
    // θ > π/2: the axis from the largest column of (1 − cos θ) n nᵀ, signed along a.
    let b = 0.5 * (r + r.transpose()) - Mat3::identity() * c;
    let k = (0..3)
        .max_by(|&i, &j| b[(i, i)].total_cmp(&b[(j, j)]))
        .unwrap_or(0);
    let col = b.column(k).into_owned();
    let norm = col.norm();
    if norm.is_nan() || norm <= 0.0 {
        return Vec3::zeros();
    }
    let n = col / norm;
    let n = if n.dot(&a) < 0.0 { -n } else { n };
    n * theta
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn rotation_vector_is_accurate_from_tiny_to_half_turn_angles() {
        let axes = [
            Vec3::x(),
            Vec3::new(0.3, -0.5, 0.81).normalize(),
            Vec3::new(-1.0, 2.0, 0.5).normalize(),
        ];
        for n in axes {
            for theta in [
                1e-300,
                1e-12,
                1e-8,
                1e-7,
                1e-4,
                0.1,
                1.0,
                1.5,
                2.0,
                3.0,
                3.1,
                std::f64::consts::PI - 1e-7,
            ] {
                let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(n), theta);
                let v = rotation_vector(r.matrix());
                let err = (v - n * theta).norm() / theta;
                assert!(
                    err < 1e-12,
                    "θ = {theta:e}, n = {n:?}: relative error {err:e}"
                );
            }
        }
        assert_eq!(rotation_vector(&Mat3::identity()), Vec3::zeros());
        // A half turn: the axis up to its sign, the angle π.
        let v = rotation_vector(&Mat3::from_diagonal(&Vec3::new(1.0, -1.0, -1.0)));
        assert!((v.x.abs() - std::f64::consts::PI).abs() < 1e-15 && v.y == 0.0 && v.z == 0.0);
    }
}
