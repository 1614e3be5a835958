//! Stage 4 of a step: residual, row scales and tangent of the whole system at an
//! increment. Element contributions come from the CPU kernel in line or from an
//! evaluator (direct, or a lockstep batch driver awaited here), then the nodal terms
//! (point masses, external loads) and the rigid links' bar forces; the relative residual
//! is measured against per-kind (u, θ, g) force scales.

use nalgebra::Matrix3;
use std::time::Instant;

use super::{gather3, kind_of_local, node_local, Backend, Mode, Simulation};
use crate::element::lanes::pack6;
use crate::element::point_mass;
use crate::element::rational::add_moment_terms;
use crate::element::{
    consistent_director_factor, consistent_scalars_at, consistent_scalars_near, kinematics_core,
    monolithic_correction, monolithic_terms, residual_tangent_into, residual_tangent_measured_into,
    ElementData, ElementEval, ElementState, FrozenScalars, Increment, ScalarCorrection, NDOF,
};
use crate::integrator::dofs::{DofMap, NONE};
use crate::integrator::evaluate::{AssembledSystem, EvalRequest, Resident, ResidentAnswer};
use crate::integrator::links;
use crate::math::lane::{F64x4, Lane, LANES};
use crate::model::{CurvatureMeasure, Mat3, Vec3};

/// Whether the four-element lanes pay: with AVX an [`F64x4`] is one register and the
/// kernel runs 2.1–2.35× faster per element; with SSE2 only (two registers per value)
/// the residual runs slower than one element at a time (docs/benchmarks.md, "Four
/// elements per kernel call"). Results are the same either way, bit for bit.
pub(super) const LANES_PAY: bool = cfg!(target_feature = "avx");

impl Simulation {
    /// Assembles residual `r`, the row scales and (if `tangent`) the matrix values.
    /// Returns the relative residual `max_i |R_i| / scale(kind of i)` and the per-kind
    /// scales (u, θ, g).
    ///
    /// Frozen-scalar element evaluation goes to the attached evaluator, if any (a
    /// lockstep driver's answer is awaited here: the one point where a step can wait).
    /// An evaluator error makes the residual NaN (the Newton solve fails).
    pub(super) async fn assemble(
        &mut self,
        q: &[f64],
        mode: Mode,
        tangent: bool,
        r: &mut [f64],
    ) -> (f64, [f64; 3]) {
        let k = self.consts();
        let dt = k.dt;
        r.iter_mut().for_each(|x| *x = 0.0);
        // Per-kind scales: u, θ, g rows.
        let mut scale = [0.0f64; 3];
        // With an evaluator the elements arrive already summed per node; the CPU kernel
        // loop below is skipped. So do the inexact strategy's consistent-scalar
        // iterations: their tangent is the frozen-scalar one at the consistent scalars,
        // which the GPU kernel evaluates.
        let external = (mode == Mode::Frozen || self.inexact_on_gpu(mode))
            && !matches!(self.backend, Backend::Cpu);
        // A device solve needs the nodal terms before the evaluation (they join the
        // right-hand side on the device); the host then neither assembles nor
        // factorizes the matrix.
        let device = external && self.device_solve;
        self.device_x = None;
        if tangent {
            // The values are about to change: the factorization no longer matches them
            // (the solver checks each solve against the current values).
            self.factored = None;
            if !device {
                self.solver.values_mut().iter_mut().for_each(|x| *x = 0.0);
            }
        }
        let resident = device && self.resident_now;
        // Inside a device-resident Newton solve the nodal terms cannot change: the device
        // solve covers no nodal term that depends on the iterate (`device_solve_refusal`:
        // no links or follower line loads; no contact on the GPU; drag and point masses are
        // the element kernel's), and loads
        // change per step. They go up with the solve's first request; the later ones send
        // none (the device keeps them) and reuse their row scales.
        let keep_nodal = resident && !self.resident_next.upload;
        if keep_nodal {
            scale = self.resident_scale;
        } else if device {
            self.nodal_terms(q, false, false, r, &mut scale);
            self.resident_scale = scale;
            if self.device_steps {
                // What the device's nodal terms now hold: the loads of this step.
                self.device_loads = Some(self.load_factors().collect());
            }
        }
        if external {
            let upload = !resident || self.resident_next.upload;
            let mut req = self.eval_request(upload.then_some(q), tangent);
            if resident {
                req.resident = Some(Resident {
                    scale,
                    predict_accept: self.resident_next.predict_accept && !tangent,
                    ..self.resident_next
                });
            }
            if device {
                req.device_extra = Some(if keep_nodal {
                    Vec::new()
                } else {
                    self.node_rows(r)
                });
            }
            let t0 = Instant::now();
            let answer = match &self.backend {
                Backend::Direct(b, slot) => b.evaluate_assembled(*slot, req),
                Backend::Lockstep(port) => port.evaluate(req).await,
                Backend::Cpu => unreachable!("external evaluation without an evaluator"),
            };
            self.timers.evaluate_wait_s += t0.elapsed().as_secs_f64();
            match answer {
                Ok(AssembledSystem {
                    resident:
                        Some(ResidentAnswer::Iterated {
                            residual,
                            solve,
                            iterate,
                        }),
                    ..
                }) if resident => {
                    // The device evaluated the iterate it holds (the host's `q` is stale
                    // until fetched) and added the correction if the solve succeeded (or,
                    // predicted to be accepted, sent the iterate back instead).
                    self.resident_next.upload = false;
                    self.resident_next.restore = false;
                    self.resident_iterate = iterate;
                    self.device_x = Some(solve.map(|()| Vec::new()));
                    return (residual, scale);
                }
                Ok(mut sys) => {
                    if keep_nodal {
                        // (Not expected: a resident request answered as a host one.)
                        self.nodal_terms(q, false, false, r, &mut scale);
                    }
                    if device {
                        self.device_x = Some(sys.solution.take().unwrap_or_else(|| {
                            Err("the evaluator did not solve on the device".into())
                        }));
                    }
                    self.scatter_assembled(&sys, tangent && !device, r, &mut scale)
                }
                Err(_) => {
                    // The evaluator may not hold this state any more.
                    self.sent_version = None;
                    self.advanced_version = None;
                    self.follower_sent = None;
                    return (f64::NAN, scale);
                }
            }
        }
        let n_cpu = if external {
            0
        } else if self.planar_kernel() {
            self.assemble_planar(q, mode, tangent, r, &mut scale);
            0
        } else {
            self.model.elements.len()
        };
        // The elements go through the kernel four at a time, one per lane (bit-identical
        // to one at a time); the rest one by one below.
        let first_single = if self.lanes {
            self.assemble_lanes(q, n_cpu, mode, tangent, r, &mut scale)
        } else {
            0
        };
        // One element buffer for the whole loop (no per-element allocation or copy).
        let mut ev = ElementEval::zeros();
        for e in first_single..n_cpu {
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            let (s, kin) = match mode {
                Mode::Frozen => {
                    let s = self.frozen[e];
                    (s, kinematics_core(data, &st, &eps_n, &inc, s.c_nu, dt))
                }
                Mode::Consistent => {
                    let (s, _, kin) =
                        consistent_scalars_near(data, &st, &eps_n, &inc, &k, self.frozen[e].c_nu);
                    (s, kin)
                }
            };
            residual_tangent_measured_into(
                data,
                &st,
                &kin,
                &s,
                &k,
                self.trans_diss,
                tangent,
                &mut ev,
            );
            // The next iterate's director factor follows this one's branch.
            self.frozen[e].c_nu = s.c_nu;
            if tangent
                && mode == Mode::Consistent
                && k.scheme.is_dissipative()
                && !self.inexact_tangent
            {
                let map = &self.dofs.elements[e];
                let active: [bool; NDOF] = std::array::from_fn(|i| map[i] != NONE);
                monolithic_correction(data, &st, &s, &kin, &k, self.trans_diss, &active, &mut ev.k);
            }
            self.scatter(e, &ev, tangent, r, &mut scale);
        }
        if !device {
            // The GPU element kernel adds the drag and the point masses itself (a device
            // solve needs them there: they depend on the iterate).
            self.nodal_terms(q, tangent, !external, r, &mut scale);
        }
        self.constrain_slides(q, tangent && !device, r);
        // max_i |R_i| / s_kind(i), as the largest |R_i| of each kind over its scale: the
        // same number (a correctly rounded division by a positive number is monotone),
        // three divisions instead of one per row.
        let mut largest = [0.0f64; 3];
        for (&ri, &kind) in r.iter().zip(&self.row_kinds) {
            if !ri.is_finite() {
                return (f64::INFINITY, scale);
            }
            largest[kind] = largest[kind].max(ri.abs());
        }
        let mut worst: f64 = 0.0;
        for (m, s) in largest.iter().zip(scale) {
            let rel = m / s.max(1e-300);
            if !rel.is_finite() {
                return (f64::INFINITY, scale);
            }
            worst = worst.max(rel);
        }
        (worst, scale)
    }

    /// Whether frozen-scalar elements go through the kernel four at a time, one per
    /// [`F64x4`] lane (both the 3D and the planar kernel).
    pub fn lanes(&self) -> bool {
        self.lanes
    }

    /// Switches the four-element kernel calls on or off. The default is on where the
    /// build targets AVX (where they pay: docs/benchmarks.md, "Four elements per kernel
    /// call") and off elsewhere. Either way every result is the same bit for bit
    /// (`tests/lanes.rs` runs scenes both ways); off serves comparisons and tests.
    pub fn set_lanes(&mut self, on: bool) {
        self.lanes = on && Self::lanes_fit(&self.data);
    }

    /// Whether the elements can go through the lanes: all of one curvature measure (the
    /// rational measure's elements run the sine kernel with `C_Ω = 0` in lanes and add
    /// their moment rows in the same lanes; a model mixing measures goes one by one).
    pub(super) fn lanes_fit(data: &[ElementData]) -> bool {
        data.windows(2).all(|w| w[0].measure == w[1].measure)
    }

    /// The elements `0..4⌊n/4⌋` through the kernel by groups of four, one element per
    /// [`F64x4`] lane, scattered like [`Self::scatter`]. Returns the first element left
    /// for the one-by-one loop.
    ///
    /// With consistent scalars the kinematics run in lanes at each element's director
    /// factor (solved element by element where director dissipation is on), the local
    /// law completes the scalars element by element from its lane of the kinematics, and
    /// the monolithic linearization is added to each lane's tangent as it is scattered
    /// ([`ScalarCorrection::entry`]): every number is the one-element path's, bit for bit.
    fn assemble_lanes(
        &mut self,
        q: &[f64],
        n: usize,
        mode: Mode,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) -> usize {
        let k = self.consts();
        let groups = n / LANES;
        let consistent = mode == Mode::Consistent;
        // The rational measure (EM only, frozen scalars): its moment rows are added to
        // each lane's evaluation of the sine kernel without moment stiffness.
        let rational = self
            .data
            .first()
            .is_some_and(|d| d.measure == CurvatureMeasure::Rational);
        if rational && consistent {
            return 0;
        }
        let correct = tangent && consistent && k.scheme.is_dissipative() && !self.inexact_tangent;
        let mut ev = ElementEval::<F64x4>::zeros();
        let mut corr = Vec::with_capacity(if correct { LANES } else { 0 });
        for g in 0..groups {
            let e0 = g * LANES;
            // (Array literals, not `from_fn`: that moves each element through a buffer.)
            let incs = [
                self.gather(e0, q),
                self.gather(e0 + 1, q),
                self.gather(e0 + 2, q),
                self.gather(e0 + 3, q),
            ];
            let inc = Increment::pack(&incs);
            let (m, sv) = (&self.model, &self.state);
            let sts = [
                sv.element(m, e0),
                sv.element(m, e0 + 1),
                sv.element(m, e0 + 2),
                sv.element(m, e0 + 3),
            ];
            let st = ElementState::pack(&sts);
            let eps = &sv.eps[e0..e0 + LANES];
            let eps_n = pack6(eps.try_into().unwrap());
            let data = &self.data_lanes[g];
            if !consistent {
                let s = FrozenScalars::pack(self.frozen[e0..e0 + LANES].try_into().unwrap());
                let kin = kinematics_core(data, &st, &eps_n, &inc, s.c_nu, k.dt);
                residual_tangent_into(data, &st, &kin, &s, &k, self.trans_diss, tangent, &mut ev);
                if rational {
                    let c_omega = Matrix3::from_fn(|a, b| {
                        F64x4::new(std::array::from_fn(|i| {
                            self.data[e0 + i].props.c_omega[(a, b)]
                        }))
                    });
                    add_moment_terms(&c_omega, data, &st, &kin, &s, tangent, &mut ev);
                }
                for i in 0..LANES {
                    self.scatter_lane(e0 + i, &ev, i, tangent, r, scale);
                }
                continue;
            }
            let c_nu: [f64; LANES] = std::array::from_fn(|i| {
                let e = e0 + i;
                consistent_director_factor(
                    &self.data[e],
                    &sts[i],
                    &eps[i],
                    &incs[i],
                    &k,
                    self.frozen[e].c_nu,
                )
            });
            let kin = kinematics_core(data, &st, &eps_n, &inc, F64x4::new(c_nu), k.dt);
            let mut s1 = [FrozenScalars::default(); LANES];
            corr.clear();
            for i in 0..LANES {
                let e = e0 + i;
                let (s, _, kin_i) =
                    consistent_scalars_at(&self.data[e], &sts[i], kin.lane(i), &k, c_nu[i]);
                // The next iterate's director factor follows this one's branch.
                self.frozen[e].c_nu = s.c_nu;
                s1[i] = s;
                if correct {
                    let map = &self.dofs.elements[e];
                    let active: [bool; NDOF] = std::array::from_fn(|j| map[j] != NONE);
                    corr.push(monolithic_terms(
                        &self.data[e],
                        &sts[i],
                        &s,
                        &kin_i,
                        &k,
                        self.trans_diss,
                        &active,
                    ));
                }
            }
            let s = FrozenScalars::pack(&s1);
            residual_tangent_into(data, &st, &kin, &s, &k, self.trans_diss, tangent, &mut ev);
            for i in 0..LANES {
                if correct {
                    self.scatter_lane_corrected(e0 + i, &ev, i, &corr[i], r, scale);
                } else {
                    self.scatter_lane(e0 + i, &ev, i, tangent, r, scale);
                }
            }
        }
        groups * LANES
    }

    /// [`Self::scatter_lane`] with the tangent, each entry corrected by the scalars'
    /// linearization `c` ([`ScalarCorrection::entry`]).
    fn scatter_lane_corrected(
        &mut self,
        e: usize,
        ev: &ElementEval<F64x4>,
        lane: usize,
        c: &ScalarCorrection<NDOF>,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        let (lo, hi) = (self.scatter_off[e], self.scatter_off[e + 1]);
        add_element_corrected(
            (ev.r.as_slice(), ev.scale.as_slice(), ev.k.as_slice()),
            lane,
            &self.row_map[lo.0..hi.0],
            kind_of_local,
            &self.tangent_map[lo.1..hi.1],
            c,
            r,
            scale,
            self.solver.values_mut(),
        );
    }

    /// [`ElementData`] by full groups of four consecutive elements, one per lane (the last
    /// `n mod 4` elements go one by one).
    ///
    /// Groups of the rational measure carry no moment stiffness (`C_Ω = 0`): the lanes
    /// evaluate the rest of the element, [`add_moment_terms`] the moment rows.
    pub(super) fn lane_groups(data: &[ElementData]) -> Vec<ElementData<F64x4>> {
        data.chunks_exact(LANES)
            .map(|c| {
                if c.iter().all(|d| d.measure == CurvatureMeasure::Rational) {
                    let base: [ElementData; LANES] = std::array::from_fn(|i| {
                        let mut d = c[i].clone();
                        d.props.c_omega = Mat3::zeros();
                        d
                    });
                    ElementData::pack([&base[0], &base[1], &base[2], &base[3]])
                } else {
                    ElementData::pack([&c[0], &c[1], &c[2], &c[3]])
                }
            })
            .collect()
    }

    /// The rows of `r` per node in node-local order (u, θ, g; 0 where a component is not an
    /// unknown): the nodal terms as the device takes them.
    pub(super) fn node_rows(&self, r: &[f64]) -> Vec<[f64; 9]> {
        self.dofs
            .nodes
            .iter()
            .map(|nd| node_local(nd).map(|i| if i == NONE { 0.0 } else { r[i] }))
            .collect()
    }

    /// Adds the nodal terms (point masses, external loads and moments) and the rigid
    /// links' bar forces to `r`, the scales and (if `tangent`) the matrix values.
    /// `on_host`: whether the drag, the point masses and the follower line loads go in here
    /// (not when the GPU element kernel evaluated the elements: it adds them with the
    /// element's own rows).
    pub(super) fn nodal_terms(
        &mut self,
        q: &[f64],
        tangent: bool,
        on_host: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        let dt = self.consts().dt;
        // Nodal terms: point masses and external loads (their scales kept in registers
        // and merged once: max is order-free).
        let mut own = [0.0f64; 3];
        for (a, nd) in self.dofs.nodes.iter().enumerate() {
            let m = if on_host {
                self.model.point_mass[a]
            } else {
                0.0
            };
            let g = gather3(q, &nd.g);
            // (Most nodes carry no point mass: no inertia to evaluate, divisions saved.)
            let inertia = if m != 0.0 {
                let u = gather3(q, &nd.u);
                point_mass::inertia_force(m, &u, &self.state.v[a], &g, dt)
            } else {
                Vec3::zeros()
            };
            let s = self.node_slots[a];
            for c in 0..3 {
                if nd.u[c] != NONE {
                    r[nd.u[c]] += inertia[c] - self.force[a][c];
                    own[0] = own[0].max(inertia[c].abs()).max(self.force[a][c].abs());
                    if tangent && m != 0.0 {
                        let vals = self.solver.values_mut();
                        vals[s[0][c]] += 2.0 * m / (dt * dt);
                        if s[1][c] != NONE {
                            vals[s[1][c]] += -2.0 * m / dt;
                        }
                    }
                }
                if nd.g[c] != NONE {
                    r[nd.g[c]] += m * g[c];
                    own[2] = own[2].max((m * g[c]).abs());
                    // (Whether or not the translation is held: a clamped or driven node's
                    // dissipation unknowns stay.)
                    if tangent && m != 0.0 {
                        self.solver.values_mut()[s[3][c]] += m;
                    }
                }
                if nd.th[c] != NONE {
                    r[nd.th[c]] -= self.moment[a][c];
                    own[1] = own[1].max(self.moment[a][c].abs());
                }
            }
        }
        for (s, o) in scale.iter_mut().zip(own) {
            *s = s.max(o);
        }
        if on_host {
            self.add_follower_terms(q, tangent, r, scale);
            self.add_drag_terms(q, tangent, r, scale);
        }
        self.add_contact_terms(q, tangent, r, scale);
        self.add_rod_contact_terms(q, tangent, r, scale);
        self.add_rod_friction_terms(q, tangent, r, scale);
        // Rigid links: the mid-point bar force (exactly energy-consistent, see `Link`).
        for (i, link) in self.model.links.iter().enumerate() {
            let a = link.node;
            let ix = self.dofs.nodes[a].u;
            let bar = links::bar_terms(
                link,
                self.state.lambda[i],
                &self.state.r[a],
                &gather3(q, &ix),
            );
            for c in 0..3 {
                if ix[c] == NONE {
                    continue;
                }
                r[ix[c]] += bar.force[c];
                scale[0] = scale[0].max(bar.force[c].abs());
                if tangent {
                    let vals = self.solver.values_mut();
                    for d in 0..3 {
                        if ix[d] != NONE {
                            vals[self.link_slots[i][c][d]] += bar.stiffness[(c, d)];
                        }
                    }
                }
            }
        }
    }

    /// Device-resident Newton: fetches the iterate the host accepted (the device's iterate
    /// before its last correction) into `q`, with its residual work.
    pub(super) async fn fetch_resident(&mut self, q: &mut [f64]) -> Result<(), String> {
        let req = EvalRequest {
            resident: Some(Resident {
                fetch: true,
                ..Resident::default()
            }),
            ..EvalRequest::default()
        };
        let t0 = Instant::now();
        let answer = match &self.backend {
            Backend::Direct(b, slot) => b.evaluate_assembled(*slot, req),
            Backend::Lockstep(port) => port.evaluate(req).await,
            Backend::Cpu => Err("device-resident Newton without an evaluator".into()),
        };
        self.timers.evaluate_wait_s += t0.elapsed().as_secs_f64();
        match answer? {
            AssembledSystem {
                resident:
                    Some(ResidentAnswer::Fetched {
                        q: nodes,
                        residual_work,
                    }),
                ..
            } => {
                self.take_resident_iterate(q, &nodes, residual_work);
                Ok(())
            }
            _ => Err("the evaluator did not return the device's iterate".into()),
        }
    }

    /// Takes the device's iterate (per node, node-local order) into `q`, with its residual
    /// work; the next Newton solve starts from the host's iterate again.
    pub(super) fn take_resident_iterate(
        &mut self,
        q: &mut [f64],
        nodes: &[[f64; 9]],
        residual_work: f64,
    ) {
        for (nd, x) in self.dofs.nodes.iter().zip(nodes) {
            for (&i, &v) in node_local(nd).iter().zip(x) {
                if i != NONE {
                    q[i] = v;
                }
            }
        }
        self.residual_work = Some(residual_work);
        self.resident_next.upload = true;
    }

    /// Whether an assembly in `mode` is one of the inexact strategy's consistent-scalar
    /// iterations, which an attached evaluator runs like a frozen-scalar one (its kernel
    /// evaluates the consistent scalars itself).
    pub(super) fn inexact_on_gpu(&self, mode: Mode) -> bool {
        mode == Mode::Consistent && self.inexact_tangent
    }

    /// What an evaluator needs for this iteration: the element states only when they
    /// changed since the last request, the frozen scalars (or the flag to use the
    /// consistent ones), the increments per node (none without `q`: a device-resident
    /// iteration continues from the device's).
    pub(super) fn eval_request(&mut self, q: Option<&[f64]>, tangent: bool) -> EvalRequest {
        // `--solve whole`: the evaluator advances its copy by the iterate it evaluated last
        // (the one the last step accepted) instead.
        let advance = self.sent_version.is_some()
            && self.sent_version != Some(self.state_version)
            && self.advanced_version == Some(self.state_version);
        let states = (!advance && self.sent_version != Some(self.state_version)).then(|| {
            (0..self.model.elements.len())
                .map(|e| (self.state.element(&self.model, e), self.state.eps[e]))
                .collect()
        });
        self.sent_version = Some(self.state_version);
        EvalRequest {
            states,
            advance,
            scalars: self.frozen.clone(),
            // Removed unknowns are zero, except those of a driven support: they move by the
            // prescribed increment (as in [`Simulation::gather`]).
            increments: q.map_or_else(Vec::new, |q| {
                self.dofs
                    .nodes
                    .iter()
                    .zip(&self.prescribed)
                    .map(|(nd, [pu, pt])| {
                        let idx = node_local(nd);
                        std::array::from_fn(|k| match (idx[k], k / 3) {
                            (NONE, 0) => pu[k % 3],
                            (NONE, 1) => pt[k % 3],
                            (NONE, _) => 0.0,
                            (i, _) => q[i],
                        })
                    })
                    .collect()
            }),
            tangent,
            consistent: self.inexact_tangent,
            follower: self.follower_update(),
            device_extra: None,
            resident: None,
            device_step: None,
            pull: None,
            prescribed: Vec::new(),
        }
    }

    /// Adds one element's residual, row scales and (if `tangent`) tangent into the
    /// global system.
    pub(super) fn scatter(
        &mut self,
        e: usize,
        ev: &ElementEval,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        self.scatter_lane(e, ev, 0, tangent, r, scale);
    }

    /// [`Self::scatter`] of lane `lane` of an evaluation (of the `f64` itself: lane 0).
    fn scatter_lane<T: Lane>(
        &mut self,
        e: usize,
        ev: &ElementEval<T>,
        lane: usize,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        let (lo, hi) = (self.scatter_off[e], self.scatter_off[e + 1]);
        let runs = &self.tangent_map[lo.1..hi.1];
        add_element(
            (ev.r.as_slice(), ev.scale.as_slice(), ev.k.as_slice()),
            lane,
            &self.row_map[lo.0..hi.0],
            kind_of_local,
            tangent.then_some(runs),
            r,
            scale,
            self.solver.values_mut(),
        );
    }

    /// Adds a backend's assembled system (node blocks, off-diagonal blocks, residual rows
    /// and per-kind scales) into the global system.
    pub(super) fn scatter_assembled(
        &mut self,
        sys: &AssembledSystem,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        for (nd, nr) in self.dofs.nodes.iter().zip(&sys.node_r) {
            for (&i, &x) in node_local(nd).iter().zip(nr) {
                if i != NONE {
                    r[i] += x;
                }
            }
        }
        for (s, &x) in scale.iter_mut().zip(&sys.scale) {
            *s = s.max(x);
        }
        if !tangent {
            return;
        }
        let vals = self.solver.values_mut();
        let add = |vals: &mut [f64], slots: &[usize; 81], block: &[f64; 81]| {
            for (&s, &x) in slots.iter().zip(block) {
                if s != NONE {
                    vals[s] += x;
                }
            }
        };
        for (slots, block) in self.node_block_slots.iter().zip(&sys.node_k) {
            add(vals, slots, block);
        }
        for (slots, blocks) in self.off_block_slots.iter().zip(&sys.off_k) {
            add(vals, &slots[0], &blocks[0]);
            add(vals, &slots[1], &blocks[1]);
        }
    }

    pub(super) fn row_kinds(dofs: &DofMap) -> Vec<usize> {
        let mut k = vec![0; dofs.n];
        for nd in &dofs.nodes {
            for (idx, kind) in [(nd.u, 0), (nd.th, 1), (nd.g, 2)] {
                for i in idx.into_iter().filter(|&i| i != NONE) {
                    k[i] = kind;
                }
            }
        }
        k
    }
}

/// [`add_element`] of a lane's evaluation with its tangent, each active entry `(i, j)`
/// corrected by the scalars' linearization `c` on the way ([`ScalarCorrection::entry`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn add_element_corrected<const N: usize>(
    (er, es, ek): (&[F64x4], &[F64x4], &[F64x4]),
    lane: usize,
    rows: &[(usize, usize)],
    kind: impl Fn(usize) -> usize,
    runs: &[(usize, usize, usize)],
    c: &ScalarCorrection<N>,
    r: &mut [f64],
    scale: &mut [f64; 3],
    vals: &mut [f64],
) {
    add_element((er, es, ek), lane, rows, kind, None, r, scale, vals);
    let w = LANES;
    let ks = F64x4::flat(ek);
    for &(src, dst, len) in runs {
        // Entry `src` of the column-major element matrix, then on down the column (a run
        // may cross into the next one).
        let (mut row, mut col) = (src % N, src / N);
        for (x, v) in (src..src + len).zip(&mut vals[dst..dst + len]) {
            *v += c.entry(row, col, ks[x * w + lane]);
            row += 1;
            if row == N {
                (row, col) = (0, col + 1);
            }
        }
    }
}

/// Adds lane `lane` of one element's evaluation `(residual, row scales, tangent)` into the
/// global system: its active rows `rows` (local row, global row; `kind` gives a local
/// row's scale kind) and, with `runs`, its active tangent entries as runs contiguous in
/// the column-major element matrix and in the solver's values `vals` (first local index,
/// first slot, length). The lanes are read with plain loads ([`Lane::flat`]); the
/// element's largest scales are kept in registers and merged once (max is order-free).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn add_element<T: Lane>(
    (er, es, ek): (&[T], &[T], &[T]),
    lane: usize,
    rows: &[(usize, usize)],
    kind: impl Fn(usize) -> usize,
    runs: Option<&[(usize, usize, usize)]>,
    r: &mut [f64],
    scale: &mut [f64; 3],
    vals: &mut [f64],
) {
    let w = T::WIDTH;
    let (er, es) = (T::flat(er), T::flat(es));
    let mut own = [0.0f64; 3];
    for &(i, g) in rows {
        r[g] += er[i * w + lane];
        let k = kind(i);
        own[k] = own[k].max(es[i * w + lane]);
    }
    for (s, o) in scale.iter_mut().zip(own) {
        *s = s.max(o);
    }
    let Some(runs) = runs else {
        return;
    };
    let ks = T::flat(ek);
    for &(src, dst, len) in runs {
        let (out, from) = (&mut vals[dst..dst + len], &ks[src * w..(src + len) * w]);
        if w == 1 {
            // One element: contiguous on both sides.
            out.iter_mut().zip(from).for_each(|(v, k)| *v += k);
        } else {
            out.iter_mut()
                .zip(from.chunks_exact(w))
                .for_each(|(v, k)| *v += k[lane]);
        }
    }
}
