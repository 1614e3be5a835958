//! The state of a run at one time level.

use nalgebra::Vector6;

use crate::element::strain::Config;
use crate::element::{ElementData, ElementState};
use crate::model::{Mat3, Model, Vec3};
use crate::obstacle::Anchor;

/// Nodal positions/velocities and per-element-end director triads/velocities at `t`.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Time.
    pub t: f64,
    /// Node positions.
    pub r: Vec<Vec3>,
    /// Node velocities.
    pub v: Vec<Vec3>,
    /// Director triads per element end (`[e][l]`, columns `d_1, d_2, d_3`).
    pub d: Vec<[Mat3; 2]>,
    /// Director velocities per element end (`[e][l][α]`, α = 0, 1).
    pub vd: Vec<[[Vec3; 2]; 2]>,
    /// Raw strains `(Γ, Ω)` per element (cached: every step needs `ε_n`).
    pub eps: Vec<Vector6<f64>>,
    /// Augmented-Lagrangian multiplier `λ` of each rigid link (the bar force factor).
    pub lambda: Vec<f64>,
    /// Elastic-stick anchors per obstacle and contact node (`[o][k]`, `None`: not in
    /// contact; an obstacle without the stick law has an empty list). Part of the state:
    /// the stick energy depends on them.
    pub anchors: Vec<Vec<Option<Anchor>>>,
}

impl State {
    /// The state `dt` later before its element fields are written: time, nodal positions
    /// and velocities (nodes outside every element keep theirs), link multipliers and
    /// stick anchors copied; triads, director velocities and strains empty, with room for every
    /// element, for the caller to push in element order (nothing copied only to be
    /// overwritten).
    pub fn successor_frame(&self, dt: f64) -> State {
        let n = self.d.len();
        State {
            t: self.t + dt,
            r: self.r.clone(),
            v: self.v.clone(),
            d: Vec::with_capacity(n),
            vd: Vec::with_capacity(n),
            eps: Vec::with_capacity(n),
            lambda: self.lambda.clone(),
            anchors: self.anchors.clone(),
        }
    }

    /// The initial state of a model: its initial configuration (the reference unless the
    /// scene gives another, [`Model::initial_position`], [`Model::initial_triads`]), given
    /// nodal velocities and director velocities `ω × d` from the nodal angular velocities.
    pub fn initial(model: &Model, data: &[ElementData]) -> Self {
        let d: Vec<[Mat3; 2]> = (0..model.elements.len())
            .map(|e| model.initial_triads(e))
            .collect();
        let vd = rigid_director_velocities(model, &d, |a| model.omega0[a]);
        let mut s = Self {
            t: 0.0,
            r: (0..model.n_nodes())
                .map(|a| model.initial_position(a))
                .collect(),
            v: model.velocity0.clone(),
            d,
            vd,
            eps: Vec::new(),
            lambda: vec![0.0; model.links.len()],
            anchors: Vec::new(),
        };
        s.eps = s.strains(model, data);
        s.anchors = model
            .obstacles
            .iter()
            .map(|o| o.initial_anchors(&s.r, 0.0))
            .collect();
        // Supported nodes do not move.
        for (a, sup) in model.supports.iter().enumerate() {
            if sup.translation {
                s.v[a] = Vec3::zeros();
            }
        }
        for (e, el) in model.elements.iter().enumerate() {
            for l in 0..2 {
                if model.supports[el.nodes[l]].rotation {
                    s.vd[e][l] = [Vec3::zeros(); 2];
                }
            }
        }
        s
    }

    /// Raw strains `(Γ, Ω)` of every element of this state.
    pub fn strains(&self, model: &Model, data: &[ElementData]) -> Vec<Vector6<f64>> {
        (0..model.elements.len())
            .map(|e| data[e].strains(&self.config(model, e)))
            .collect()
    }

    /// Configuration of element `e`.
    #[inline]
    pub fn config(&self, model: &Model, e: usize) -> Config {
        let n = model.elements[e].nodes;
        Config {
            r: [self.r[n[0]], self.r[n[1]]],
            d: self.d[e],
        }
    }

    /// Element-local view of the state.
    #[inline]
    pub fn element(&self, model: &Model, e: usize) -> ElementState {
        let n = model.elements[e].nodes;
        ElementState {
            cfg: self.config(model, e),
            v: [self.v[n[0]], self.v[n[1]]],
            vd: self.vd[e],
        }
    }
}

/// Director velocities `ω^A × d_α^{(e)l}` of a rigid cross-section motion, per element end,
/// for nodal spatial angular velocities `omega(A)` and triads `d` (`[e][l]`).
pub fn rigid_director_velocities(
    model: &Model,
    d: &[[Mat3; 2]],
    omega: impl Fn(usize) -> Vec3,
) -> Vec<[[Vec3; 2]; 2]> {
    model
        .elements
        .iter()
        .zip(d)
        .map(|(e, tri)| {
            std::array::from_fn(|l| {
                let w = omega(e.nodes[l]);
                std::array::from_fn(|a| w.cross(&tri[l].column(a).into_owned()))
            })
        })
        .collect()
}
