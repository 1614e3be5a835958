//! One time step: assemble element residuals/tangents, Newton on the nodal increments,
//! the staggered or monolithic treatment of the dissipation, and the acceptance checks
//! (a step whose energy grows or whose dissipation identity misses its tolerance is a
//! failed step, never an accepted one).

use std::sync::Arc;
use std::time::Instant;

use crate::element::strain::Config;
use crate::element::{
    consistent_scalars, g_idx, kinematics, monolithic_correction, residual_tangent, strains6,
    th_idx, u_idx, ElementData, ElementEval, FrozenScalars, Increment, StepConsts, NDOF,
};
use crate::integrator::backend::{AssembledSystem, ElementBackend, ElementInput};
use crate::integrator::dofs::{DofMap, NodeDofs, NONE};
use crate::integrator::gen_alpha::GenAlpha;
use crate::integrator::links;
use crate::integrator::params::{IntegratorParams, Scheme, Strategy};
use crate::integrator::state::State;
use crate::linsolve::{SolverKind, SparseSolver};
use crate::model::{Model, Vec3};
use crate::observe::{acceleration_norms, invariants, Invariants};

/// Why a step could not be accepted.
#[derive(Clone, Debug, PartialEq)]
pub struct StepFailure {
    /// Human-readable reason.
    pub reason: String,
    /// Residual norms (relative to the force scale) of the Newton iterations of the last
    /// attempt.
    pub residuals: Vec<f64>,
}

/// What an accepted step reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Newton iterations (all outer rounds and predictor retries).
    pub newton_iters: usize,
    /// Outer rounds (staggered), 1 otherwise.
    pub outer_iters: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Dissipation predicted by DESIGN §4 at the accepted state.
    pub dissipation: f64,
    /// Work of the external loads over the step.
    pub external_work: f64,
    /// Acceleration norms over the step.
    pub acc_trans: f64,
    /// Director acceleration norm.
    pub acc_rot: f64,
    /// Largest `|g|` of the rigid links at the accepted state (0 without links).
    pub max_link_g: f64,
    /// Augmented-Lagrangian rounds the step took (1 without links).
    pub link_rounds: usize,
}

/// Where a simulation's Newton time went (accumulated over its life; thread time, so a
/// batch sums them over members). The generalized-α baseline's own Newton loop is not
/// timed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolveTimers {
    /// Residual (and tangent) assembly: element kernel, scatter, nodal and link terms. On
    /// the GPU path this includes the wait for the batch's dispatch.
    pub assemble_s: f64,
    /// LU factorizations.
    pub factor_s: f64,
    /// Triangular solves (with their backward-error checks).
    pub solve_s: f64,
    /// Factorizations done.
    pub factorizations: u64,
    /// Solves done (more than factorizations under modified Newton).
    pub solves: u64,
}

impl SolveTimers {
    /// Field-wise sum (a batch's total).
    pub fn add(&mut self, o: &SolveTimers) {
        self.assemble_s += o.assemble_s;
        self.factor_s += o.factor_s;
        self.solve_s += o.solve_s;
        self.factorizations += o.factorizations;
        self.solves += o.solves;
    }
}

/// How the dissipation scalars are treated in one Newton solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Scalars held at `self.frozen`.
    Frozen,
    /// Scalars re-evaluated from the iterate and linearized (monolithic).
    Consistent,
}

/// A simulation: the model, its element constants, the unknown numbering, the linear
/// solver (symbolic analysis done once) and the current state.
pub struct Simulation {
    model: Model,
    params: IntegratorParams,
    data: Vec<ElementData>,
    dofs: DofMap,
    solver: SparseSolver,
    /// Per element: solver slot of each element-local (i, j) pair, [`NONE`] if inactive.
    slots: Vec<Vec<usize>>,
    /// Per node: slots of the diagonal entries of the (u,u), (u,g), (g,u), (g,g) blocks.
    node_slots: Vec<[[usize; 3]; 4]>,
    /// Per node: solver slot of each entry of its node-local 9×9 diagonal block
    /// (`u0..2 θ0..2 g0..2`, row-major), [`NONE`] if inactive (a backend's assembled
    /// blocks are scattered through it).
    node_block_slots: Vec<[usize; 81]>,
    /// Per element: solver slots of its node-local off-diagonal blocks (end 0, end 1) and
    /// (end 1, end 0), [`NONE`] if inactive.
    off_block_slots: Vec<[[usize; 81]; 2]>,
    /// Residual of the last converged Newton solve (for the residual work in `check`).
    last_residual: Vec<f64>,
    /// Per rigid link: slots of its node's (u, u) block.
    link_slots: Vec<[[usize; 3]; 3]>,
    /// Kind of each global row (0 = u, 1 = θ, 2 = g), for the per-kind residual scale.
    row_kinds: Vec<usize>,
    state: State,
    inv: Invariants,
    trans_diss: bool,
    /// Previous step's unknowns (the Newton predictor).
    prev: Vec<f64>,
    /// Frozen dissipation scalars per element (staggered strategy).
    frozen: Vec<FrozenScalars>,
    force: Vec<Vec3>,
    moment: Vec<Vec3>,
    /// The generalized-α baseline's own state and Newton machinery (only for
    /// [`Scheme::GenAlpha`], which steps through it instead of the element kernel's
    /// mid-point residual).
    gen_alpha: Option<GenAlpha>,
    /// Element evaluator replacing the CPU kernel in frozen-scalar assembly, and this
    /// simulation's slot in it (the GPU batch path).
    backend: Option<(Arc<dyn ElementBackend>, usize)>,
    /// Reuse the tangent across Newton iterations (see [`Simulation::set_modified_newton`]).
    modified_newton: bool,
    /// Time spent per Newton stage.
    timers: SolveTimers,
}

/// Modified Newton takes a fresh tangent when the last iteration reduced the residual by
/// less than this factor.
const MODIFIED_NEWTON_RATE: f64 = 0.2;

impl Simulation {
    /// Sets up a simulation of `model` with `params` (the linear solver's symbolic
    /// analysis is done here, once).
    pub fn new(
        model: Model,
        params: IntegratorParams,
    ) -> Result<Self, crate::linsolve::LinsolveError> {
        let data: Vec<ElementData> = model
            .elements
            .iter()
            .map(|e| {
                let cfg = Config {
                    r: [model.nodes[e.nodes[0]], model.nodes[e.nodes[1]]],
                    d: e.ref_triad,
                };
                ElementData {
                    props: e.props.clone(),
                    eps0: strains6(&cfg, e.props.h),
                    rot_free: [
                        !model.supports[e.nodes[0]].rotation,
                        !model.supports[e.nodes[1]].rotation,
                    ],
                }
            })
            .collect();
        let trans_diss = params.scheme.translational_dissipation();
        let dofs = DofMap::new(&model, trans_diss);
        let mut pattern = dofs.pattern();
        for i in 0..dofs.n {
            pattern.push((i, i));
        }
        let link_dofs: Vec<[usize; 3]> = model.links.iter().map(|l| dofs.nodes[l.node].u).collect();
        for ix in &link_dofs {
            for &i in ix.iter().filter(|&&i| i != NONE) {
                for &j in ix.iter().filter(|&&j| j != NONE) {
                    pattern.push((i, j));
                }
            }
        }
        let solver = SparseSolver::with_blocks(dofs.n, &pattern, &dofs.node_block_sizes())?;
        let slots = dofs
            .elements
            .iter()
            .map(|m| {
                let mut s = vec![NONE; NDOF * NDOF];
                for i in 0..NDOF {
                    for j in 0..NDOF {
                        if m[i] != NONE && m[j] != NONE {
                            s[i * NDOF + j] = solver.slot(m[i], m[j]);
                        }
                    }
                }
                s
            })
            .collect();
        let node_slots = dofs
            .nodes
            .iter()
            .map(|nd| {
                let slot = |a: [usize; 3], b: [usize; 3], c: usize| {
                    if a[c] == NONE || b[c] == NONE {
                        NONE
                    } else {
                        solver.slot(a[c], b[c])
                    }
                };
                [
                    std::array::from_fn(|c| slot(nd.u, nd.u, c)),
                    std::array::from_fn(|c| slot(nd.u, nd.g, c)),
                    std::array::from_fn(|c| slot(nd.g, nd.u, c)),
                    std::array::from_fn(|c| slot(nd.g, nd.g, c)),
                ]
            })
            .collect();
        let (node_block_slots, off_block_slots) = Self::block_slots(&model, &dofs, &solver);
        let link_slots = link_dofs
            .iter()
            .map(|ix| {
                std::array::from_fn(|c| {
                    std::array::from_fn(|d| {
                        if ix[c] == NONE || ix[d] == NONE {
                            NONE
                        } else {
                            solver.slot(ix[c], ix[d])
                        }
                    })
                })
            })
            .collect();
        let state = State::initial(&model, &data);
        let inv = invariants(&model, &data, &state);
        let nn = model.n_nodes();
        let gen_alpha = match params.scheme {
            Scheme::GenAlpha { rho_inf } => {
                let (mut f, mut m) = (vec![Vec3::zeros(); nn], vec![Vec3::zeros(); nn]);
                model.external_loads(0.0, &mut f, &mut m);
                Some(GenAlpha::new(&model, &data, &state, rho_inf, &f, &m)?)
            }
            _ => None,
        };
        Ok(Self {
            gen_alpha,
            row_kinds: Self::row_kinds(&dofs),
            frozen: vec![FrozenScalars::default(); model.elements.len()],
            prev: vec![0.0; dofs.n],
            last_residual: vec![0.0; dofs.n],
            force: vec![Vec3::zeros(); nn],
            moment: vec![Vec3::zeros(); nn],
            model,
            params,
            data,
            dofs,
            solver,
            slots,
            node_slots,
            node_block_slots,
            off_block_slots,
            link_slots,
            state,
            inv,
            trans_diss,
            backend: None,
            modified_newton: false,
            timers: SolveTimers::default(),
        })
    }

    /// Time spent so far in assembly, factorization and solves.
    pub fn solve_timers(&self) -> SolveTimers {
        self.timers
    }

    /// Where the element kernel runs: `cpu`, or the attached backend's description (the
    /// baselines and the monolithic strategy's consistent assembly stay on the CPU kernel).
    pub fn backend_name(&self) -> String {
        self.backend
            .as_ref()
            .map_or_else(|| "cpu".to_string(), |(b, _)| b.describe())
    }

    /// The linear solver chosen for this model's tangent, and how many factorizations it
    /// has handed to its pivoting fallback so far (block-tridiagonal backend only).
    pub fn linear_solver(&self) -> (SolverKind, usize) {
        let s = self.gen_alpha.as_ref().map_or(&self.solver, |g| g.solver());
        (s.kind(), s.fallbacks())
    }

    /// Evaluates the elements through `backend` (slot `slot`) whenever the dissipation
    /// scalars are frozen (EM, staggered); monolithic assembly stays on the CPU kernel.
    /// Returns false (and attaches nothing) for schemes the GPU kernel does not implement
    /// (the mid-point and generalized-α baselines), which then run on the CPU kernel.
    pub fn set_backend(&mut self, backend: Arc<dyn ElementBackend>, slot: usize) -> bool {
        if !self.params.scheme.has_gpu_kernel() {
            return false;
        }
        self.backend = Some((backend, slot));
        true
    }

    /// Modified Newton (default off): from the third iteration of a solve on, the last
    /// tangent is kept (not re-evaluated; the matrix is refactorized) as long as the previous
    /// iteration reduced the relative residual by at least a factor 5; a slower iteration
    /// triggers a fresh tangent. Saves the element tangents (on the GPU: their kernel work and readback).
    pub fn set_modified_newton(&mut self, on: bool) {
        self.modified_newton = on;
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// Element constants (reference strains, section constants).
    pub fn element_data(&self) -> &[ElementData] {
        &self.data
    }
    /// Integrator parameters.
    pub fn params(&self) -> &IntegratorParams {
        &self.params
    }
    /// Current state.
    pub fn state(&self) -> &State {
        &self.state
    }
    /// Energies and momenta of the current state.
    pub fn invariants(&self) -> Invariants {
        self.inv
    }
    /// Number of Newton unknowns.
    pub fn n_dofs(&self) -> usize {
        self.dofs.n
    }
    /// The numbering of the Newton unknowns.
    pub fn dof_map(&self) -> &DofMap {
        &self.dofs
    }

    /// Solver slots of the node-local blocks: each node's 9×9 diagonal block (entries
    /// exist only where the node has an element) and each element's two off-diagonal
    /// blocks.
    #[allow(clippy::type_complexity)]
    fn block_slots(
        model: &Model,
        dofs: &DofMap,
        solver: &SparseSolver,
    ) -> (Vec<[usize; 81]>, Vec<[[usize; 81]; 2]>) {
        let table = |a: &[usize; 9], b: &[usize; 9]| -> [usize; 81] {
            std::array::from_fn(|f| {
                let (i, j) = (a[f / 9], b[f % 9]);
                if i == NONE || j == NONE {
                    NONE
                } else {
                    solver.slot(i, j)
                }
            })
        };
        let mut has_element = vec![false; dofs.nodes.len()];
        for e in &model.elements {
            e.nodes.iter().for_each(|&a| has_element[a] = true);
        }
        let node = dofs
            .nodes
            .iter()
            .zip(&has_element)
            .map(|(nd, &has)| {
                if has {
                    let ix = node_local(nd);
                    table(&ix, &ix)
                } else {
                    [NONE; 81]
                }
            })
            .collect();
        let off = model
            .elements
            .iter()
            .map(|e| {
                let (a, b) = (
                    node_local(&dofs.nodes[e.nodes[0]]),
                    node_local(&dofs.nodes[e.nodes[1]]),
                );
                [table(&a, &b), table(&b, &a)]
            })
            .collect();
        (node, off)
    }

    /// Replaces the current state (e.g. to start from a prescribed motion in tests).
    /// Not supported for [`Scheme::GenAlpha`], whose nodal rotations, velocities and
    /// accelerations live in its own state: there it only replaces the observed state.
    pub fn set_state(&mut self, state: State) {
        self.inv = invariants(&self.model, &self.data, &state);
        self.state = state;
        self.prev.iter_mut().for_each(|x| *x = 0.0);
        self.frozen
            .iter_mut()
            .for_each(|s| *s = FrozenScalars::default());
    }

    fn gather(&self, e: usize, q: &[f64]) -> Increment {
        let m = &self.dofs.elements[e];
        let mut x = crate::element::ElemVec::zeros();
        for i in 0..NDOF {
            if m[i] != NONE {
                x[i] = q[m[i]];
            }
        }
        Increment::from_local(&x)
    }

    fn consts(&self) -> StepConsts {
        StepConsts {
            dt: self.params.dt,
            scheme: self.params.scheme,
        }
    }

    /// Assembles residual `r`, the row scales and (if `tangent`) the matrix values.
    /// Returns the relative residual `max_i |R_i| / scale(kind of i)` and the per-kind
    /// scales (u, θ, g).
    fn assemble(&mut self, q: &[f64], mode: Mode, tangent: bool, r: &mut [f64]) -> (f64, [f64; 3]) {
        let k = self.consts();
        let dt = k.dt;
        r.iter_mut().for_each(|x| *x = 0.0);
        let mut scale = [0.0f64; 3]; // u, θ, g rows
        if tangent {
            self.solver.values_mut().iter_mut().for_each(|x| *x = 0.0);
        }
        let backend = match (&self.backend, mode) {
            (Some((b, slot)), Mode::Frozen) => Some((b.clone(), *slot)),
            _ => None,
        };
        // With a backend the elements arrive already summed per node; the CPU kernel
        // loop below is skipped.
        let n_cpu = if backend.is_some() {
            0
        } else {
            self.model.elements.len()
        };
        if let Some((b, slot)) = backend {
            let inputs: Vec<ElementInput> = (0..self.model.elements.len())
                .map(|e| ElementInput {
                    st: self.state.element(&self.model, e),
                    eps_n: self.state.eps[e],
                    s: self.frozen[e],
                })
                .collect();
            let increments: Vec<[f64; 9]> = self
                .dofs
                .nodes
                .iter()
                .map(|nd| node_local(nd).map(|i| if i == NONE { 0.0 } else { q[i] }))
                .collect();
            match b.evaluate_assembled(slot, &inputs, &increments, tangent) {
                Ok(sys) => self.scatter_assembled(&sys, tangent, r, &mut scale),
                Err(_) => return (f64::NAN, scale),
            }
        }
        for e in 0..n_cpu {
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            let (s, kin) = match mode {
                Mode::Frozen => {
                    let s = self.frozen[e];
                    (s, kinematics(data, &st, &eps_n, &inc, s.c_nu, dt))
                }
                Mode::Consistent => {
                    let (s, _, kin) = consistent_scalars(data, &st, &eps_n, &inc, &k);
                    (s, kin)
                }
            };
            let mut ev = residual_tangent(data, &st, &kin, &s, &k, self.trans_diss, tangent);
            let map = &self.dofs.elements[e];
            if tangent && mode == Mode::Consistent && k.scheme.is_dissipative() {
                let active: [bool; NDOF] = std::array::from_fn(|i| map[i] != NONE);
                monolithic_correction(
                    data,
                    &st,
                    &eps_n,
                    &inc,
                    &k,
                    self.trans_diss,
                    &active,
                    &mut ev.k,
                );
            }
            self.scatter(e, &ev, tangent, r, &mut scale);
        }
        // Nodal terms: point masses and external loads.
        for (a, nd) in self.dofs.nodes.iter().enumerate() {
            let m = self.model.point_mass[a];
            let u = gather3(q, &nd.u);
            let g = gather3(q, &nd.g);
            let inertia = m * (2.0 * u / dt - 2.0 * self.state.v[a] - 2.0 * g) / dt;
            let s = self.node_slots[a];
            for c in 0..3 {
                if nd.u[c] != NONE {
                    r[nd.u[c]] += inertia[c] - self.force[a][c];
                    scale[0] = scale[0].max(inertia[c].abs()).max(self.force[a][c].abs());
                    if tangent && m != 0.0 {
                        let vals = self.solver.values_mut();
                        vals[s[0][c]] += 2.0 * m / (dt * dt);
                        if s[1][c] != NONE {
                            vals[s[1][c]] += -2.0 * m / dt;
                            vals[s[3][c]] += m;
                        }
                    }
                }
                if nd.g[c] != NONE {
                    r[nd.g[c]] += m * g[c];
                    scale[2] = scale[2].max((m * g[c]).abs());
                }
                if nd.th[c] != NONE {
                    r[nd.th[c]] -= self.moment[a][c];
                    scale[1] = scale[1].max(self.moment[a][c].abs());
                }
            }
        }
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
        let mut worst: f64 = 0.0;
        for (i, &ri) in r.iter().enumerate() {
            let s = scale[self.row_kinds[i]].max(1e-300);
            let rel = ri.abs() / s;
            if !rel.is_finite() {
                return (f64::INFINITY, scale);
            }
            worst = worst.max(rel);
        }
        (worst, scale)
    }

    /// Adds one element's residual, row scales and (if `tangent`) tangent into the
    /// global system.
    fn scatter(
        &mut self,
        e: usize,
        ev: &ElementEval,
        tangent: bool,
        r: &mut [f64],
        scale: &mut [f64; 3],
    ) {
        let map = &self.dofs.elements[e];
        for i in 0..NDOF {
            if map[i] == NONE {
                continue;
            }
            r[map[i]] += ev.r[i];
            let kind = kind_of_local(i);
            scale[kind] = scale[kind].max(ev.scale[i]);
            if tangent {
                let vals = self.solver.values_mut();
                let srow = &self.slots[e][i * NDOF..(i + 1) * NDOF];
                for j in 0..NDOF {
                    if srow[j] != NONE {
                        vals[srow[j]] += ev.k[(i, j)];
                    }
                }
            }
        }
    }

    /// Adds a backend's assembled system (node blocks, off-diagonal blocks, residual rows
    /// and per-kind scales) into the global system.
    fn scatter_assembled(
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

    fn row_kinds(dofs: &DofMap) -> Vec<usize> {
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

    /// Newton from `q` (overwritten with the solution). Returns iterations and the
    /// relative residual history.
    fn newton(&mut self, q: &mut [f64], mode: Mode) -> Result<(usize, Vec<f64>), StepFailure> {
        let n = self.dofs.n;
        let mut r = vec![0.0; n];
        let mut history = Vec::new();
        let tol = self.params.newton_tol;
        for it in 0..=self.params.max_iter {
            // Modified Newton: keep the last tangent while the residual contracts fast.
            let fresh = !self.modified_newton
                || it < 2
                || history[it - 1] > MODIFIED_NEWTON_RATE * history[it - 2];
            let t0 = Instant::now();
            let (res, _) = self.assemble(q, mode, fresh, &mut r);
            self.timers.assemble_s += t0.elapsed().as_secs_f64();
            history.push(res);
            if !res.is_finite() {
                return Err(StepFailure {
                    reason: "non-finite residual (Newton diverged)".into(),
                    residuals: history,
                });
            }
            // Newton converges quadratically: from a residual of 1e5·tol the next one is
            // far below tol. A residual that stops falling there sits on its f64 floor
            // (stiff members under small loads: the arch at t ≈ 0), so accept it; the energy
            // checks that follow still apply.
            let stalled = it >= 2 && res <= ROUNDOFF_RESIDUAL * tol && res >= 0.5 * history[it - 1];
            if (res <= tol && super::scaling::may_accept(it)) || stalled {
                self.last_residual.clone_from(&r);
                return Ok((it, history));
            }
            if it == self.params.max_iter {
                break;
            }
            r.iter_mut().for_each(|x| *x = -*x);
            // A reused tangent keeps its factorization too (modified Newton).
            let t0 = Instant::now();
            let factored = if fresh {
                self.timers.factorizations += 1;
                self.solver.factor()
            } else {
                Ok(())
            };
            let t1 = Instant::now();
            let solved = factored.and_then(|_| self.solver.solve(&mut r));
            self.timers.solves += 1;
            self.timers.factor_s += (t1 - t0).as_secs_f64();
            self.timers.solve_s += t1.elapsed().as_secs_f64();
            if let Err(e) = solved {
                return Err(StepFailure {
                    reason: format!("linear solve failed: {e}"),
                    residuals: history,
                });
            }
            for (qi, di) in q.iter_mut().zip(&r) {
                *qi += di;
            }
        }
        Err(StepFailure {
            reason: format!(
                "Newton did not converge in {} iterations (relative residual {:.3e} > {:.1e})",
                self.params.max_iter,
                history.last().copied().unwrap_or(f64::NAN),
                tol
            ),
            residuals: history,
        })
    }

    /// The state an increment produces (with the frozen scalars of `mode`), the
    /// predicted dissipation at it, and the consistent scalars.
    fn advance(&self, q: &[f64], mode: Mode) -> (State, f64, Vec<FrozenScalars>) {
        let k = self.consts();
        let dt = k.dt;
        let mut next = self.state.clone();
        next.t = self.state.t + dt;
        let mut diss = 0.0;
        let mut consistent = Vec::with_capacity(self.model.elements.len());
        let mut node_done = vec![false; self.model.n_nodes()];
        for e in 0..self.model.elements.len() {
            let inc = self.gather(e, q);
            let st = self.state.element(&self.model, e);
            let eps_n = self.state.eps[e];
            let data = &self.data[e];
            let (sc, loc, kin_c) = consistent_scalars(data, &st, &eps_n, &inc, &k);
            diss += data.props.h * loc.dissipation_density(&kin_c.inputs, data.props.a_rho);
            consistent.push(sc);
            let kin = match mode {
                Mode::Consistent => kin_c,
                Mode::Frozen => kinematics(data, &st, &eps_n, &inc, self.frozen[e].c_nu, dt),
            };
            next.d[e] = kin.cfg1.d;
            next.vd[e] = kin.vd1;
            next.eps[e] = kin.eps1;
            for l in 0..2 {
                let a = self.model.elements[e].nodes[l];
                if !node_done[a] {
                    node_done[a] = true;
                    next.r[a] = kin.cfg1.r[l];
                    next.v[a] = kin.v1[l];
                }
            }
        }
        (next, diss, consistent)
    }

    fn external_work(&self, q: &[f64]) -> f64 {
        let mut w = 0.0;
        for (a, nd) in self.dofs.nodes.iter().enumerate() {
            w += self.force[a].dot(&gather3(q, &nd.u));
            w += self.moment[a].dot(&gather3(q, &nd.th));
        }
        w
    }

    /// Checks energy and the dissipation identity of a converged increment; on success
    /// returns the new state, its invariants, D and W.
    fn check(
        &self,
        q: &[f64],
        mode: Mode,
    ) -> Result<(State, Invariants, f64, f64, Vec<FrozenScalars>), String> {
        let (next, diss, consistent) = self.advance(q, mode);
        let inv = invariants(&self.model, &self.data, &next);
        let w = self.external_work(q);
        let (h0, h1) = (self.inv.total(), inv.total());
        let href = h0.abs().max(h1.abs()).max(w.abs()).max(1e-300);
        // The discrete energy identity holds exactly for an exact solution; a converged
        // increment q with residual R misses it by R·q. Allow that much on top of the
        // relative tolerances: it matters only when H is tiny against the forces (a stiff
        // structure at the start of a slow load ramp, residual at its f64 floor).
        let residual_work: f64 = self
            .last_residual
            .iter()
            .zip(q)
            .map(|(r, x)| (r * x).abs())
            .sum::<f64>();
        let growth = h1 - h0 - w;
        super::scaling::check_resolved(residual_work, href)?;
        if self.params.scheme.controls_energy()
            && growth > self.params.energy_tol * href + residual_work
        {
            return Err(format!(
                "energy grew by {growth:.3e} beyond the external work ({:.3e} relative)",
                growth / href
            ));
        }
        if self.params.scheme.is_dissipative() {
            let miss = (h0 - h1 + w - diss).abs();
            if miss > self.params.outer_tol * href + residual_work {
                return Err(format!(
                    "dissipation identity missed: H_n − H_n+1 + W − D = {:.3e} ({:.3e} relative)",
                    h0 - h1 + w - diss,
                    miss / href
                ));
            }
        }
        Ok((next, inv, diss, w, consistent))
    }

    /// Advances one step of Δt. On failure the state is left at the last accepted step.
    pub fn step(&mut self) -> Result<StepReport, StepFailure> {
        if self.gen_alpha.is_some() {
            if !self.model.links.is_empty() {
                // The baseline has no augmented-Lagrangian treatment of rigid links;
                // ignoring them would simulate a different mechanism.
                return Err(StepFailure {
                    reason: "gen-alpha does not support rigid links ([[link]]); use em, edmc1, edmc2 or midpoint".into(),
                    residuals: vec![],
                });
            }
            return self.step_gen_alpha();
        }
        let dt = self.params.dt;
        let t_mid = self.state.t + 0.5 * dt;
        let (mut force, mut moment) = (
            std::mem::take(&mut self.force),
            std::mem::take(&mut self.moment),
        );
        self.model.external_loads(t_mid, &mut force, &mut moment);
        self.force = force;
        self.moment = moment;

        let mut predictors = vec![self.prev.clone()];
        if self.prev.iter().any(|&x| x != 0.0) {
            predictors.push(vec![0.0; self.dofs.n]);
        }
        let mut total_iters = 0;
        let mut last = StepFailure {
            reason: "no attempt".into(),
            residuals: vec![],
        };
        let (lambda0, inv0) = (self.state.lambda.clone(), self.inv);
        for pred in predictors {
            let mut q = pred;
            let mut multipliers = links::MultiplierIteration::default();
            // Augmented-Lagrangian rounds (a single round without links): each round is a
            // complete, checked solve with the multipliers fixed, so the energy identity of
            // every round is exact; the multipliers move between rounds until every link
            // holds its tolerance.
            for round in 1..=self.params.max_link_rounds.max(1) {
                let (next, inv, diss, w, outer, res, consistent) =
                    match self.solve_with_fixed_multipliers(&mut q, &mut total_iters) {
                        Ok(x) => x,
                        Err(f) => {
                            last = f;
                            break;
                        }
                    };
                let g1: Vec<f64> = self
                    .model
                    .links
                    .iter()
                    .map(|l| l.strain(&next.r[l.node]))
                    .collect();
                let max_link_g = g1.iter().fold(0.0f64, |m, g| m.max(g.abs()));
                if multipliers.update(&self.model.links, &g1, &mut self.state.lambda) {
                    let (at, ar) = acceleration_norms(&self.model, &self.data, &self.state, &next);
                    let report = StepReport {
                        newton_iters: total_iters,
                        outer_iters: outer,
                        residual: res,
                        dissipation: diss,
                        external_work: w,
                        acc_trans: at,
                        acc_rot: ar,
                        max_link_g,
                        link_rounds: round,
                    };
                    if let Err(f) = super::finite::check_step(&next, &inv, &report) {
                        self.state.lambda.clone_from(&lambda0);
                        self.inv = inv0;
                        return Err(f);
                    }
                    self.state = next;
                    self.inv = inv;
                    self.prev = q;
                    self.frozen = consistent;
                    return Ok(report);
                }
                // H_n with the new multipliers: the next round's energy identity is
                // measured against it.
                self.inv = invariants(&self.model, &self.data, &self.state);
                last = StepFailure {
                    reason: format!(
                        "augmented Lagrangian: links still violated after {round} rounds (max |g| = {max_link_g:.3e})"
                    ),
                    residuals: vec![res],
                };
            }
            self.state.lambda.clone_from(&lambda0);
            self.inv = inv0;
        }
        Err(last)
    }

    /// One checked solve of the step with the link multipliers held fixed.
    #[allow(clippy::type_complexity)]
    fn solve_with_fixed_multipliers(
        &mut self,
        q: &mut [f64],
        total_iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        if !self.params.scheme.is_dissipative() {
            self.frozen
                .iter_mut()
                .for_each(|s| *s = FrozenScalars::default());
            return self.solve_once(q, Mode::Frozen, total_iters);
        }
        match self.params.strategy {
            Strategy::Monolithic => self.solve_once(q, Mode::Consistent, total_iters),
            Strategy::Staggered => self.solve_staggered(q, total_iters),
        }
    }

    /// A generalized-α step (loads at `t_{n+1}`; no energy acceptance check: the scheme
    /// does not control energy).
    fn step_gen_alpha(&mut self) -> Result<StepReport, StepFailure> {
        let p = self.params;
        let nn = self.model.n_nodes();
        let mut loads = [(); 2].map(|_| (vec![Vec3::zeros(); nn], vec![Vec3::zeros(); nn]));
        for (k, (f, m)) in loads.iter_mut().enumerate() {
            self.model
                .external_loads(self.state.t + k as f64 * p.dt, f, m);
        }
        let Some(ga) = self.gen_alpha.as_mut() else {
            unreachable!("step_gen_alpha without generalized-α state");
        };
        let out = ga.step(
            &self.model,
            &self.data,
            &self.state,
            p.dt,
            p.newton_tol,
            p.max_iter,
            (&loads[0].0, &loads[0].1),
            (&loads[1].0, &loads[1].1),
        )?;
        let (at, ar) = acceleration_norms(&self.model, &self.data, &self.state, &out.state);
        let inv = invariants(&self.model, &self.data, &out.state);
        let report = StepReport {
            newton_iters: out.newton_iters,
            outer_iters: 1,
            residual: out.residual,
            dissipation: 0.0,
            external_work: out.external_work,
            acc_trans: at,
            acc_rot: ar,
            max_link_g: 0.0,
            link_rounds: 1,
        };
        super::finite::check_step(&out.state, &inv, &report)?;
        self.inv = inv;
        self.state = out.state;
        Ok(report)
    }

    #[allow(clippy::type_complexity)]
    fn solve_once(
        &mut self,
        q: &mut [f64],
        mode: Mode,
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        let (it, hist) = self.newton(q, mode)?;
        *iters += it;
        let res = *hist.last().unwrap_or(&0.0);
        match self.check(q, mode) {
            Ok((s, inv, d, w, c)) => Ok((s, inv, d, w, 1, res, c)),
            Err(reason) => Err(StepFailure {
                reason,
                residuals: hist,
            }),
        }
    }

    #[allow(clippy::type_complexity)]
    fn solve_staggered(
        &mut self,
        q: &mut [f64],
        iters: &mut usize,
    ) -> Result<(State, Invariants, f64, f64, usize, f64, Vec<FrozenScalars>), StepFailure> {
        // Start from the scalars consistent with the predictor.
        let (_, _, c0) = self.advance(q, Mode::Consistent);
        self.frozen = c0;
        let mut last_reason = String::new();
        let mut hist_all = Vec::new();
        for outer in 1..=self.params.max_outer {
            let (it, hist) = self.newton(q, Mode::Frozen)?;
            *iters += it;
            let res = *hist.last().unwrap_or(&0.0);
            hist_all.extend(hist);
            match self.check(q, Mode::Frozen) {
                Ok((s, inv, d, w, c)) => return Ok((s, inv, d, w, outer, res, c)),
                Err(reason) => {
                    last_reason = reason;
                    let (_, _, c) = self.advance(q, Mode::Frozen);
                    self.frozen = c;
                }
            }
        }
        Err(StepFailure {
            reason: format!(
                "staggered loop hit its cap of {} outer rounds: {last_reason}",
                self.params.max_outer
            ),
            residuals: hist_all,
        })
    }

    /// Position and triad updates of a global increment applied to the current state
    /// (for tests of the tangent).
    pub fn residual_at(&mut self, q: &[f64], consistent: bool) -> Vec<f64> {
        let mut r = vec![0.0; self.dofs.n];
        self.mid_step_loads();
        let mode = if consistent {
            Mode::Consistent
        } else {
            Mode::Frozen
        };
        self.assemble(q, mode, true, &mut r);
        r
    }

    /// Dense copy of the assembled tangent at `q` (tests only; small models).
    pub fn dense_tangent_at(&mut self, q: &[f64], consistent: bool) -> Vec<Vec<f64>> {
        let _ = self.residual_at(q, consistent);
        let n = self.dofs.n;
        let mut dense = vec![vec![0.0; n]; n];
        for e in 0..self.model.elements.len() {
            let map = &self.dofs.elements[e];
            for i in 0..NDOF {
                for j in 0..NDOF {
                    if map[i] != NONE && map[j] != NONE {
                        let v = self.solver.values()[self.slots[e][i * NDOF + j]];
                        dense[map[i]][map[j]] = v;
                    }
                }
            }
        }
        dense
    }

    /// Residual, per-kind row scales (u, θ, g) and matrix values (pattern order)
    /// assembled at `q` with the frozen scalars: through the backend when one is attached,
    /// else on the CPU kernel (tests compare the two).
    /// Without `tangent` the values are left out (empty).
    pub fn frozen_system_at(&mut self, q: &[f64], tangent: bool) -> (Vec<f64>, [f64; 3], Vec<f64>) {
        let mut r = vec![0.0; self.dofs.n];
        self.mid_step_loads();
        let (_, scale) = self.assemble(q, Mode::Frozen, tangent, &mut r);
        let values = if tangent {
            self.solver.values().to_vec()
        } else {
            Vec::new()
        };
        (r, scale, values)
    }

    /// The external loads at the middle of the coming step (for the test helpers).
    fn mid_step_loads(&mut self) {
        let t_mid = self.state.t + 0.5 * self.params.dt;
        let (mut f, mut m) = (
            std::mem::take(&mut self.force),
            std::mem::take(&mut self.moment),
        );
        self.model.external_loads(t_mid, &mut f, &mut m);
        self.force = f;
        self.moment = m;
    }

    /// Sets the frozen dissipation scalars of every element (tests of the staggered
    /// tangent).
    pub fn set_frozen(&mut self, s: FrozenScalars) {
        self.frozen.iter_mut().for_each(|x| *x = s);
    }
}

/// A Newton residual that stops falling below this multiple of the tolerance is at its
/// round-off floor (see `newton`).
pub(crate) const ROUNDOFF_RESIDUAL: f64 = 1e5;

/// The components `idx` of `q` as a vector (zero where removed).
#[inline]
fn gather3(q: &[f64], idx: &[usize; 3]) -> Vec3 {
    Vec3::from_fn(|c, _| if idx[c] == NONE { 0.0 } else { q[idx[c]] })
}

/// The global unknowns of a node in node-local order `u0..2 θ0..2 g0..2`.
#[inline]
fn node_local(nd: &NodeDofs) -> [usize; 9] {
    std::array::from_fn(|k| match k / 3 {
        0 => nd.u[k % 3],
        1 => nd.th[k % 3],
        _ => nd.g[k % 3],
    })
}

/// Kind of an element-local row: 0 = u, 1 = θ, 2 = g.
#[inline]
fn kind_of_local(i: usize) -> usize {
    if i >= g_idx(0) {
        2
    } else if (i >= th_idx(0) && i < u_idx(1)) || i >= th_idx(1) {
        1
    } else {
        0
    }
}
