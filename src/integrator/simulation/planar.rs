//! The planar element kernel in a simulation (stage 4 for planar models): a planar model
//! evaluated on the CPU runs [`crate::element::planar`] (10 unknowns per element instead
//! of 18) instead of the 3D kernel with its out-of-plane unknowns removed. The state stays
//! 3D (observers, outputs and the acceptance stage are unchanged); the planar view of each
//! element's state at `n` is taken once per step.

use nalgebra::Vector3;

use super::{Mode, Simulation};
use crate::element::planar::{
    self, full_index, pkind, planar_data, PElemMat, PIncrement, PState, PlanarData, NDOF_P,
};
use crate::element::strain::Config;
use crate::element::{ElementData, NDOF};
use crate::integrator::dofs::{DofMap, NONE};
use crate::model::Model;

/// Planar kernel data of a simulation.
pub(super) struct PlanarKernel {
    /// Whether assembly uses it (on by default for planar models).
    pub(super) enabled: bool,
    data: Vec<PlanarData>,
    /// Per element: global unknown of each planar local unknown ([`NONE`] if removed).
    dofs: Vec<[usize; NDOF_P]>,
    /// Per element: solver slot of each planar local (i, j) pair.
    slots: Vec<[usize; NDOF_P * NDOF_P]>,
    /// Planar view of the element states at `n` and their strains, for `version`.
    states: Vec<(PState, Vector3<f64>)>,
    version: Option<u64>,
}

impl PlanarKernel {
    /// The planar kernel of a planar model (`None` for a 3D model).
    pub(super) fn new(
        model: &Model,
        data: &[ElementData],
        dofs: &DofMap,
        slots: &[Vec<usize>],
    ) -> Option<Self> {
        let plane = model.planar?;
        let pdata: Vec<PlanarData> = model
            .elements
            .iter()
            .zip(data)
            .map(|(e, d)| {
                let cfg = Config {
                    r: [model.nodes[e.nodes[0]], model.nodes[e.nodes[1]]],
                    d: e.ref_triad,
                };
                planar_data(d, &cfg, plane)
            })
            .collect();
        let mut pdofs = Vec::with_capacity(pdata.len());
        let mut pslots = Vec::with_capacity(pdata.len());
        for (e, pd) in pdata.iter().enumerate() {
            let full = full_index(&pd.map);
            let m = &dofs.elements[e];
            pdofs.push(std::array::from_fn(|i| m[full[i]]));
            pslots.push(std::array::from_fn(|ij| {
                slots[e][full[ij / NDOF_P] * NDOF + full[ij % NDOF_P]]
            }));
        }
        Some(Self {
            enabled: true,
            data: pdata,
            dofs: pdofs,
            slots: pslots,
            states: Vec::new(),
            version: None,
        })
    }
}

impl Simulation {
    /// Whether element assembly runs the planar kernel (a planar model on the CPU kernel).
    pub fn planar_kernel(&self) -> bool {
        self.planar.as_ref().is_some_and(|p| p.enabled)
    }

    /// Switches the planar kernel of a planar model on (the default) or off (the 3D kernel
    /// with the out-of-plane unknowns removed, the same scheme to round-off). Returns
    /// whether the model has a planar kernel at all.
    pub fn set_planar_kernel(&mut self, on: bool) -> bool {
        match &mut self.planar {
            Some(p) => {
                p.enabled = on;
                true
            }
            None => false,
        }
    }

    /// The element loop of [`Simulation::assemble`] with the planar kernel.
    pub(super) fn assemble_planar(
        &mut self,
        q: &[f64],
        mode: Mode,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        let k = self.consts();
        let dt = k.dt;
        let Some(pk) = self.planar.as_mut() else {
            return;
        };
        if pk.version != Some(self.state_version) || pk.states.len() != pk.data.len() {
            pk.states.clear();
            for (e, pd) in pk.data.iter().enumerate() {
                let st = pd.state(&self.state.element(&self.model, e));
                let eps = planar::strains3(&st.cfg, pd.h);
                pk.states.push((st, eps));
            }
            pk.version = Some(self.state_version);
        }
        let vals = self.solver.values_mut();
        for (e, pd) in pk.data.iter().enumerate() {
            let map = &pk.dofs[e];
            let mut x = planar::PElemVec::zeros();
            for i in 0..NDOF_P {
                if map[i] != NONE {
                    x[i] = q[map[i]];
                }
            }
            let inc = PIncrement::from_local(&x);
            let (st, eps_n) = &pk.states[e];
            let (s, kin) = match mode {
                Mode::Frozen => {
                    let s = self.frozen[e];
                    (s, planar::kinematics(pd, st, eps_n, &inc, s.c_nu, dt))
                }
                Mode::Consistent => {
                    let (s, _, kin) = planar::consistent_scalars(pd, st, eps_n, &inc, &k);
                    (s, kin)
                }
            };
            let mut ev = planar::residual_tangent(pd, st, &kin, &s, &k, self.trans_diss, tangent);
            if tangent && mode == Mode::Consistent && k.scheme.is_dissipative() {
                let active: [bool; NDOF_P] = std::array::from_fn(|i| map[i] != NONE);
                planar::monolithic_correction(
                    pd,
                    st,
                    eps_n,
                    &inc,
                    &k,
                    self.trans_diss,
                    &active,
                    &mut ev.k,
                );
            }
            let slots = &pk.slots[e];
            let kmat: &PElemMat = &ev.k;
            for i in 0..NDOF_P {
                if map[i] == NONE {
                    continue;
                }
                r[map[i]] += ev.r[i];
                let kind = pkind(i);
                scale[kind] = scale[kind].max(ev.scale[i]);
                if tangent {
                    for j in 0..NDOF_P {
                        let s = slots[i * NDOF_P + j];
                        if s != NONE {
                            vals[s] += kmat[(i, j)];
                        }
                    }
                }
            }
        }
    }
}
