//! The planar element kernel in a simulation (stage 4 for planar models): a planar model
//! evaluated on the CPU runs [`crate::element::planar`] (10 unknowns per element instead
//! of 18) instead of the 3D kernel with its out-of-plane unknowns removed. The state stays
//! 3D (observers, outputs and the acceptance stage are unchanged); the planar view of each
//! element's state at `n` is taken once per step.

use nalgebra::Vector3;

use super::assemble::{add_element, add_element_corrected};
use super::{extend_runs, Mode, Simulation};
use crate::element::dissipation::LocalScalars;
use crate::element::lanes::pack3;
use crate::element::planar::{
    self, full_index, pkind, planar_data, PElemVec, PElementEval, PIncrement, PState, PlanarData,
    NDOF_P,
};
use crate::element::strain::Config;
use crate::element::{strains6, ElementData, FrozenScalars, ScalarCorrection, NDOF};
use crate::integrator::dofs::{DofMap, NONE};
use crate::integrator::state::State;
use crate::math::lane::{F64x4, Lane, LANES};
use crate::model::Model;
use crate::model::{Mat3, Vec3};

/// Planar kernel data of a simulation.
pub(super) struct PlanarKernel {
    /// Whether assembly uses it (on by default for planar models).
    pub(super) enabled: bool,
    data: Vec<PlanarData>,
    /// [`Self::data`] by full groups of four consecutive elements, one per lane.
    groups: Vec<PlanarData<F64x4>>,
    /// Per element: global unknown of each planar local unknown ([`NONE`] if removed).
    dofs: Vec<[usize; NDOF_P]>,
    /// The active rows of all elements, element after element: (local row, global row).
    rows: Vec<(usize, usize)>,
    /// The active tangent entries, element after element, as runs contiguous in the
    /// column-major element matrix and in the solver's values: (first index in the
    /// element matrix, first solver slot, length).
    entries: Vec<(usize, usize, usize)>,
    /// Where each element's rows and entries start (one more than the elements).
    offsets: Vec<(usize, usize)>,
    /// Planar view of the element states at `n` and their strains, for `version`.
    states: Vec<(PState, Vector3<f64>)>,
    /// The same by groups of four ([`Self::groups`]).
    lane_states: Vec<(PState<F64x4>, Vector3<F64x4>)>,
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
            .enumerate()
            .map(|(i, (e, d))| {
                let cfg = Config {
                    r: [model.nodes[e.nodes[0]], model.nodes[e.nodes[1]]],
                    d: e.ref_triad,
                };
                planar_data(d, &cfg, plane, &model.intrinsic_curvature(i))
            })
            .collect();
        let mut pdofs = Vec::with_capacity(pdata.len());
        let (mut rows, mut entries, mut offsets) = (Vec::new(), Vec::new(), vec![(0, 0)]);
        for (e, pd) in pdata.iter().enumerate() {
            let full = full_index(&pd.map);
            let m = &dofs.elements[e];
            let global: [usize; NDOF_P] = std::array::from_fn(|i| m[full[i]]);
            for i in (0..NDOF_P).filter(|&i| global[i] != NONE) {
                rows.push((i, global[i]));
            }
            // Column-major, as the element matrix is stored.
            let first = entries.len();
            for j in 0..NDOF_P {
                for i in 0..NDOF_P {
                    let (src, dst) = (i + j * NDOF_P, slots[e][full[i] * NDOF + full[j]]);
                    if global[i] != NONE && dst != NONE {
                        extend_runs(&mut entries, first, src, dst);
                    }
                }
            }
            offsets.push((rows.len(), entries.len()));
            pdofs.push(global);
        }
        let groups = pdata
            .chunks_exact(LANES)
            .map(|c| PlanarData::pack([&c[0], &c[1], &c[2], &c[3]]))
            .collect();
        Some(Self {
            enabled: true,
            data: pdata,
            groups,
            dofs: pdofs,
            rows,
            entries,
            offsets,
            states: Vec::new(),
            lane_states: Vec::new(),
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

    /// Refreshes the planar view of the element states at `n` (once per step).
    fn planar_states(&mut self) {
        let Some(pk) = self.planar.as_mut() else {
            return;
        };
        if pk.version != Some(self.state_version) || pk.states.len() != pk.data.len() {
            pk.states.clear();
            let sv = &self.state;
            for (e, pd) in pk.data.iter().enumerate() {
                let n = self.model.elements[e].nodes;
                let st = pd.state_of(
                    [&sv.r[n[0]], &sv.r[n[1]]],
                    &sv.d[e],
                    [&sv.v[n[0]], &sv.v[n[1]]],
                    &sv.vd[e],
                );
                let eps = planar::strains3(&st.cfg, pd.h);
                pk.states.push((st, eps));
            }
            pk.lane_states = pk
                .states
                .chunks_exact(LANES)
                .map(|c| {
                    let st = PState::pack([&c[0].0, &c[1].0, &c[2].0, &c[3].0]);
                    (st, pack3([&c[0].1, &c[1].1, &c[2].1, &c[3].1]))
                })
                .collect();
            pk.version = Some(self.state_version);
        }
    }

    /// [`Simulation::advance`] with the planar kernel: the new 3D state (positions,
    /// velocities, triads turned about the normal, director velocities, 3D strains for the
    /// observers), the predicted dissipation and the consistent scalars. `None` when the
    /// planar view of the state is not current (the caller uses the 3D kernel).
    pub(super) fn advance_planar(
        &self,
        q: &[f64],
        mode: Mode,
    ) -> Option<(State, f64, Vec<FrozenScalars>)> {
        let pk = self.planar.as_ref().filter(|p| p.enabled)?;
        if pk.version != Some(self.state_version) || pk.states.len() != pk.data.len() {
            return None;
        }
        let k = self.consts();
        let dt = k.dt;
        let n = pk.data.len();
        let sv = &self.state;
        let mut next = sv.successor_frame(dt);
        let mut diss = 0.0;
        let mut consistent = Vec::with_capacity(pk.data.len());
        let mut node_done = vec![false; self.model.n_nodes()];
        for (e, pd) in pk.data.iter().enumerate() {
            let inc = PIncrement::from_local(&self.gather_planar(pk, e, q));
            let (st, eps_n) = &pk.states[e];
            // On the branch of the director factor the increment was solved with.
            let (sc, loc, kin_c): (FrozenScalars, LocalScalars, _) =
                planar::consistent_scalars_near(pd, st, eps_n, &inc, &k, self.frozen[e].c_nu);
            diss += pd.h * loc.dissipation_density(&kin_c.inputs, pd.a_rho);
            consistent.push(sc);
            // The frozen kinematics differ from the consistent ones only through c_ν
            // (equal, e.g. always for EM: nothing to recompute; as the 3D `advance`).
            let (kin, c_nu) = match mode {
                Mode::Frozen if self.frozen[e].c_nu != sc.c_nu => {
                    let c = self.frozen[e].c_nu;
                    (planar::kinematics(pd, st, eps_n, &inc, c, dt), c)
                }
                _ => (kin_c, sc.c_nu),
            };
            let map = &pd.map;
            let nodes = self.model.elements[e].nodes;
            // Triads: each column turned in the plane by cay(θ n); normal parts unchanged.
            let d_n = &self.state.d[e];
            let [a0, a1] = map.axes;
            let mut d1: [Mat3; 2] = *d_n;
            for (l, m) in d1.iter_mut().enumerate() {
                let (c, s) = planar::cay2(inc.theta[l]);
                for i in 0..3 {
                    let (x, y) = (d_n[l][(a0, i)], d_n[l][(a1, i)]);
                    m[(a0, i)] = c * x - s * y;
                    m[(a1, i)] = s * x + c * y;
                }
            }
            let kappa = pd.kappa;
            let ksum = kappa[0] + kappa[1];
            let phi = c_nu / (1.0 + ksum * c_nu);
            let mut vd1 = [[Vec3::zeros(); 2]; 2];
            for a in 0..2 {
                let dd = [
                    d1[0].column(a) - d_n[0].column(a),
                    d1[1].column(a) - d_n[1].column(a),
                ];
                let w = (dd[0] + dd[1]) / dt * phi;
                for l in 0..2 {
                    vd1[l][a] = 2.0 * dd[l] / dt - sv.vd[e][l][a] - 2.0 * kappa[l] * w;
                }
            }
            next.vd.push(vd1);
            next.d.push(d1);
            for l in 0..2 {
                let a = nodes[l];
                if !node_done[a] {
                    node_done[a] = true;
                    let r = &self.state.r[a];
                    next.r[a] = map.v3(&kin.cfg1.r[l], r[map.normal]);
                    next.v[a] = map.v3(&kin.v1[l], -self.state.v[a][map.normal]);
                }
            }
        }
        next.eps = (0..n)
            .map(|e| strains6(&next.config(&self.model, e), self.data[e].props.h))
            .collect();
        Some((next, diss, consistent))
    }

    /// The element loop of [`Simulation::assemble`] with the planar kernel: with frozen
    /// scalars four elements per kernel call (one per [`F64x4`] lane, bit-identical to
    /// one at a time), the rest one by one.
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
        self.planar_states();
        let Some(pk) = self.planar.as_ref() else {
            return;
        };
        // Driven supports: the increments with the prescribed motion, gathered before the
        // matrix values are borrowed (no allocation without drives).
        let driven: Option<Vec<PElemVec>> = (!self.model.drives.is_empty()).then(|| {
            (0..pk.data.len())
                .map(|e| self.gather_planar(pk, e, q))
                .collect()
        });
        let local = |e: usize| match &driven {
            Some(x) => x[e],
            None => gather_free(&pk.dofs[e], q),
        };
        let vals = self.solver.values_mut();
        let consistent = mode == Mode::Consistent;
        let correct = tangent && consistent && k.scheme.is_dissipative() && !self.inexact_tangent;
        // Four elements per kernel call; with consistent scalars as in the 3D
        // `assemble_lanes` (kinematics in lanes, the local law and the scalars'
        // linearization element by element, added to each lane's tangent as it is
        // scattered): the one-element path's numbers bit for bit.
        let first_single = if self.lanes {
            let mut ev = PElementEval::<F64x4>::zeros();
            let mut corr = Vec::with_capacity(if correct { LANES } else { 0 });
            for (g, data) in pk.groups.iter().enumerate() {
                let e0 = g * LANES;
                let locals = [local(e0), local(e0 + 1), local(e0 + 2), local(e0 + 3)];
                let inc = PIncrement::from_locals(&locals);
                let (st, eps_n) = &pk.lane_states[g];
                if !consistent {
                    let s = FrozenScalars::pack(self.frozen[e0..e0 + LANES].try_into().unwrap());
                    let kin = planar::kinematics_core(data, st, eps_n, &inc, s.c_nu, dt);
                    planar::residual_tangent_into(
                        data,
                        st,
                        &kin,
                        &s,
                        &k,
                        self.trans_diss,
                        tangent,
                        &mut ev,
                    );
                    for i in 0..LANES {
                        pk.scatter(e0 + i, &ev, i, tangent, r, scale, vals);
                    }
                    continue;
                }
                let c_nu: [f64; LANES] = std::array::from_fn(|i| {
                    let e = e0 + i;
                    let (st_e, eps_e) = &pk.states[e];
                    planar::consistent_director_factor(
                        &pk.data[e],
                        st_e,
                        eps_e,
                        &PIncrement::from_local(&locals[i]),
                        &k,
                        self.frozen[e].c_nu,
                    )
                });
                let kin = planar::kinematics_core(data, st, eps_n, &inc, F64x4::new(c_nu), dt);
                let mut s1 = [FrozenScalars::default(); LANES];
                corr.clear();
                for i in 0..LANES {
                    let e = e0 + i;
                    let (pd, st_e) = (&pk.data[e], &pk.states[e].0);
                    let (s, _, kin_i) =
                        planar::consistent_scalars_at(pd, st_e, kin.lane(i), &k, c_nu[i]);
                    // The next iterate's director factor follows this one's branch.
                    self.frozen[e].c_nu = s.c_nu;
                    s1[i] = s;
                    if correct {
                        let active: [bool; NDOF_P] = std::array::from_fn(|j| pk.dofs[e][j] != NONE);
                        corr.push(planar::monolithic_terms(
                            pd,
                            st_e,
                            &s,
                            &kin_i,
                            &k,
                            self.trans_diss,
                            &active,
                        ));
                    }
                }
                let s = FrozenScalars::pack(&s1);
                planar::residual_tangent_into(
                    data,
                    st,
                    &kin,
                    &s,
                    &k,
                    self.trans_diss,
                    tangent,
                    &mut ev,
                );
                for i in 0..LANES {
                    if correct {
                        pk.scatter_corrected(e0 + i, &ev, i, &corr[i], r, scale, vals);
                    } else {
                        pk.scatter(e0 + i, &ev, i, tangent, r, scale, vals);
                    }
                }
            }
            pk.groups.len() * LANES
        } else {
            0
        };
        let mut ev = PElementEval::zeros();
        for (e, pd) in pk.data.iter().enumerate().skip(first_single) {
            let inc = PIncrement::from_local(&local(e));
            let (st, eps_n) = &pk.states[e];
            let (s, kin) = match mode {
                Mode::Frozen => {
                    let s = self.frozen[e];
                    (s, planar::kinematics_core(pd, st, eps_n, &inc, s.c_nu, dt))
                }
                Mode::Consistent => {
                    let (s, _, kin) = planar::consistent_scalars_near(
                        pd,
                        st,
                        eps_n,
                        &inc,
                        &k,
                        self.frozen[e].c_nu,
                    );
                    // The next iterate's director factor follows this one's branch.
                    self.frozen[e].c_nu = s.c_nu;
                    (s, kin)
                }
            };
            planar::residual_tangent_into(pd, st, &kin, &s, &k, self.trans_diss, tangent, &mut ev);
            if tangent
                && mode == Mode::Consistent
                && k.scheme.is_dissipative()
                && !self.inexact_tangent
            {
                let map = &pk.dofs[e];
                let active: [bool; NDOF_P] = std::array::from_fn(|i| map[i] != NONE);
                planar::monolithic_correction(
                    pd,
                    st,
                    &s,
                    &kin,
                    &k,
                    self.trans_diss,
                    &active,
                    &mut ev.k,
                );
            }
            pk.scatter(e, &ev, 0, tangent, r, scale, vals);
        }
    }
}

impl PlanarKernel {
    /// Adds element `e`'s residual, row scales and (if `tangent`) tangent into the global
    /// system: lane `lane` of the evaluation (of the `f64` itself: lane 0), active rows
    /// and entries only.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn scatter<T: Lane>(
        &self,
        e: usize,
        ev: &PElementEval<T>,
        lane: usize,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
        vals: &mut [f64],
    ) {
        let (lo, hi) = (self.offsets[e], self.offsets[e + 1]);
        add_element(
            (ev.r.as_slice(), ev.scale.as_slice(), ev.k.as_slice()),
            lane,
            &self.rows[lo.0..hi.0],
            pkind,
            tangent.then_some(&self.entries[lo.1..hi.1]),
            r,
            scale,
            vals,
        );
    }
}

impl PlanarKernel {
    /// [`Self::scatter`] of a lane with its tangent, each entry corrected by the scalars'
    /// linearization `c` ([`ScalarCorrection::entry`]).
    #[allow(clippy::too_many_arguments)]
    fn scatter_corrected(
        &self,
        e: usize,
        ev: &PElementEval<F64x4>,
        lane: usize,
        c: &ScalarCorrection<NDOF_P>,
        r: &mut [f64],
        scale: &mut [f64; 3],
        vals: &mut [f64],
    ) {
        let (lo, hi) = (self.offsets[e], self.offsets[e + 1]);
        add_element_corrected(
            (ev.r.as_slice(), ev.scale.as_slice(), ev.k.as_slice()),
            lane,
            &self.rows[lo.0..hi.0],
            pkind,
            &self.entries[lo.1..hi.1],
            c,
            r,
            scale,
            vals,
        );
    }
}

impl Simulation {
    /// The planar element-local increment vector of element `e` at `q`: the unknowns where
    /// they exist, the prescribed increment of a driven support where they were removed
    /// (as [`Simulation::gather`]), zero elsewhere.
    #[inline]
    fn gather_planar(&self, pk: &PlanarKernel, e: usize, q: &[f64]) -> PElemVec {
        if !self.model.drives.is_empty() {
            let full = full_index(&pk.data[e].map);
            let x = self.gather(e, q).to_local();
            return PElemVec::from_fn(|i, _| x[full[i]]);
        }
        gather_free(&pk.dofs[e], q)
    }
}

/// The planar element-local increment vector without drives (zero for removed unknowns).
#[inline]
fn gather_free(map: &[usize; NDOF_P], q: &[f64]) -> PElemVec {
    PElemVec::from_fn(|i, _| if map[i] == NONE { 0.0 } else { q[map[i]] })
}
