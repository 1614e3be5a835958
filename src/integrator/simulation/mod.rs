//! A simulation and its time step. The step is a sequence of named stages, each in a file
//! named for it (in the order a step runs them):
//!
//! 1. [`step`]: loads at the mid-step, Newton predictors, augmented-Lagrangian rounds for
//!    rigid links (or the generalized-α baseline's own step);
//! 2. [`strategy`]: the dissipation treatment of one checked solve — frozen scalars (EM),
//!    the paper's staggered loop, or the monolithic Newton;
//! 3. [`newton`]: Newton on the nodal increments, full or modified (tangent and its LU
//!    factorization kept while the residual contracts fast);
//! 4. [`assemble`]: residual, row scales and tangent from the element kernel (in line on
//!    the CPU, or through an evaluator: a direct backend, or a lockstep batch driver that
//!    the step *awaits*), nodal and link terms, scatter into the sparse system;
//! 5. [`accept`]: the state an increment produces and the acceptance checks (energy never
//!    grows beyond the external work; the dissipation identity).
//!
//! [`probe`] holds the test entry points (residual, tangent and assembled system at a
//! given increment). The step is an `async fn` only so that a batch driver can suspend it
//! at the element evaluation; on the CPU it never waits and [`Simulation::step`] runs it
//! in line.

mod accept;
mod assemble;
mod contact;
mod control;
mod device_step;
mod drag;
mod drive;
mod follower;
mod newton;
mod planar;
mod probe;
mod rod_contact;
mod slide;
mod step;
mod strategy;

use std::sync::Arc;

pub use control::{ControlError, RotationCommand, TranslationCommand};

use crate::element::{
    g_idx, th_idx, u_idx, ElementData, FrozenScalars, Increment, StepConsts, NDOF,
};
use crate::integrator::dofs::{DofMap, NodeDofs, NONE};
use crate::integrator::evaluate::{ElementBackend, EvalPort};
use crate::integrator::gen_alpha::GenAlpha;
use crate::integrator::invariants::{invariants, Invariants};
use crate::integrator::params::{IntegratorParams, Scheme, Strategy};
use crate::integrator::report::SolveTimers;
use crate::integrator::state::State;
use crate::linsolve::{SlotLookup, SolverKind, SparseSolver};
use crate::math::lane::F64x4;
use crate::model::{Model, Vec3};

/// The pattern-dependent structures of a simulation's linear system
/// ([`Simulation::system_parts`]).
struct SystemParts {
    solver: SparseSolver,
    slots: Vec<Vec<usize>>,
    row_map: Vec<(usize, usize)>,
    tangent_map: Vec<(usize, usize, usize)>,
    scatter_off: Vec<(usize, usize)>,
    node_slots: Vec<[[usize; 3]; 4]>,
    node_block_slots: Vec<[usize; 81]>,
    off_block_slots: Vec<[[usize; 81]; 2]>,
    link_slots: Vec<[[usize; 3]; 3]>,
    slide_blocks: Vec<slide::SlideBlock>,
    planar: Option<planar::PlanarKernel>,
}

/// How the dissipation scalars are treated in one Newton solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Scalars held at `self.frozen`.
    Frozen,
    /// Scalars re-evaluated from the iterate and linearized (monolithic).
    Consistent,
}

/// Where frozen-scalar element evaluation runs (monolithic assembly always stays on the
/// CPU kernel).
enum Backend {
    /// The CPU kernel, in line.
    Cpu,
    /// A synchronous evaluator and this simulation's slot in it.
    Direct(Arc<dyn ElementBackend>, usize),
    /// A lockstep batch driver's mailbox (the step awaits its answer).
    Lockstep(EvalPort),
}

/// A simulation: the model, its element constants, the unknown numbering, the linear
/// solver (symbolic analysis done once) and the current state.
pub struct Simulation {
    model: Model,
    params: IntegratorParams,
    data: Vec<ElementData>,
    /// [`Self::data`] by full groups of four elements, one per lane: the CPU assembly's
    /// SIMD path.
    data_lanes: Vec<ElementData<F64x4>>,
    dofs: DofMap,
    solver: SparseSolver,
    /// Per element: solver slot of each element-local (i, j) pair, [`NONE`] if inactive.
    slots: Vec<Vec<usize>>,
    /// Active rows of every element, `(local row, global row)`, element after element
    /// (element `e`'s from `scatter_off[e].0`).
    row_map: Vec<(usize, usize)>,
    /// Active tangent entries of every element as runs `(column-major index into the
    /// 18×18 element matrix, solver slot, length)` that are contiguous on both sides,
    /// element after element (from `scatter_off[e].1`). An element column's (u, θ) entries
    /// form one run where its two nodes' rows are neighbours in the sorted matrix column
    /// (12 runs of 12 per interior cantilever element); `g` rows start runs of their own.
    tangent_map: Vec<(usize, usize, usize)>,
    /// Start of each element's entries in `row_map` and `tangent_map` (one past the last
    /// element at the end).
    scatter_off: Vec<(usize, usize)>,
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
    /// The constrained blocks of oblique sliding clamps ([`slide`]).
    slide_blocks: Vec<slide::SlideBlock>,
    /// Per rigid link: slots of its node's (u, u) block.
    link_slots: Vec<[[usize; 3]; 3]>,
    /// Per obstacle and contact node: slots of the node's (u, u) block (filled at the
    /// first assembly).
    contact_slots: Vec<Vec<[[usize; 3]; 3]>>,
    /// Couplings added to the element pattern for contact between rods (sorted, unique).
    extra_pattern: Vec<(usize, usize)>,
    /// Per rod contact: the sample-point pairs the current step considers.
    rod_pairs: Vec<Vec<(usize, usize)>>,
    /// The state version `rod_pairs` was searched at.
    rod_pairs_version: Option<u64>,
    /// Rod contact: the matrix slots of node pairs' `(u, θ) × (u, θ)` blocks (`NONE`
    /// where not in the pattern), found as they are first needed; cleared with the
    /// pattern.
    node_pair_slots: std::collections::HashMap<(usize, usize), [[usize; 6]; 6]>,
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
    /// Prescribed increment `(u, θ)` of every node over the coming step (nonzero only at
    /// driven supports; [`Model::drives`]).
    prescribed: Vec<[Vec3; 2]>,
    /// Motions commanded between steps for driven supports ([`control`]), replacing
    /// their scene motion in `prescribed`.
    commands: Vec<control::NodeCommand>,
    /// The generalized-α baseline's own state and Newton machinery (only for
    /// [`Scheme::GenAlpha`], which steps through it instead of the element kernel's
    /// mid-point residual).
    gen_alpha: Option<GenAlpha>,
    /// Where frozen-scalar element evaluation runs.
    backend: Backend,
    /// Bumped whenever the state at `n` changes (an evaluator outside the simulation is
    /// sent the element states only when this moved since its last request).
    state_version: u64,
    /// The state version the attached evaluator holds (`None`: nothing sent yet).
    sent_version: Option<u64>,
    /// `--solve whole`: the attached evaluator advances its copy of the state by the
    /// iterate it evaluated last when the next request says so ([`Self::set_device_advance`]).
    device_advance: bool,
    /// The state version the evaluator's copy reaches by that advance (set when a step
    /// accepts the device's iterate; the next request then sends no states).
    advanced_version: Option<u64>,
    /// `--solve whole`: steps whose start the device holds run entirely on the device
    /// ([`Self::set_device_steps`]).
    device_steps: bool,
    /// The host's state arrays are behind the device's (steps ran on the device: the
    /// time and the invariants are current, the rest is taken back by
    /// [`Self::sync_device_state`]).
    host_stale: bool,
    /// Time spent per Newton stage.
    timers: SolveTimers,
    /// The mode whose tangent the solver holds factorized (modified Newton reuses it);
    /// `None` before the first factorization or after a failed one.
    factored: Option<Mode>,
    /// Set when the current step's strategy failed and the fallback strategy solved it
    /// (reset at the start of every step).
    fell_back: bool,
    /// Whether the model dissipates by itself (material damping, drag or friction): the
    /// energy check then also holds the dissipation identity. Fixed with the model (its
    /// scans read every element: once here, not at every step).
    damped_model: bool,
    /// The step is on its last predictor: the monolithic strategy falls back to the
    /// staggered loop only then (its other predictors come first).
    last_predictor: bool,
    /// Whether the solve under way is the step's first strategy with its fallback still to
    /// come (a stagnation stop then moves on to it).
    fallback_pending: bool,
    /// The last checked solve was accepted with the consistent scalars (monolithic, its
    /// fallback, or an inexact solve on its floor), not frozen ones: the mode of the
    /// step's support work.
    solved_consistent: bool,
    /// Consistent-mode tangents leave out the scalars' linearization (the inexact
    /// strategy's solve; false otherwise).
    inexact_tangent: bool,
    /// Frozen-scalar elements go through the kernel four at a time (one per `F64x4`
    /// lane); on by default where the build targets AVX ([`Simulation::set_lanes`]).
    lanes: bool,
    /// The next Newton solve polishes an inexact solution: its first correction reuses
    /// the kept factorization and its next iterate is expected to be accepted.
    polish: bool,
    /// Set at the start of a step, taken by its first Newton solve: that solve's first
    /// correction reuses the last factorization (of the previous step) where it exists.
    step_start: bool,
    /// The relative residual of the last step's predictor (its first Newton iterate).
    step_r0: f64,
    /// The planar element kernel of a planar model (`None` for a 3D model).
    planar: Option<planar::PlanarKernel>,
    /// `--solve device`: the attached lockstep evaluator also solves each frozen-scalar
    /// Newton system on the device ([`Self::set_device_solve`]).
    device_solve: bool,
    /// The device's solution of the last evaluation, when it solved one (empty on success
    /// when the device kept it: device-resident Newton).
    device_x: Option<crate::integrator::evaluate::DeviceSolution>,
    /// Device-resident Newton: the device keeps the Newton iterate and adds its own
    /// corrections; only the relative residual comes back per iteration
    /// ([`Self::set_device_resident`]).
    device_resident: bool,
    /// `--solve resident`: the device runs several Newton iterations per submission for
    /// this member ([`Self::set_multi_iteration`]); recorded in `summary.json`.
    multi_iteration: bool,
    /// Device-resident Newton is in progress (set by `newton` for the duration of a solve).
    resident_now: bool,
    /// Device-resident Newton: what the next evaluation asks of the device (upload the
    /// host's iterate, restore, predicted acceptance, send the iterate back; its `scale`
    /// is filled in when it is posted).
    resident_next: crate::integrator::evaluate::Resident,
    /// The row scales of the nodal terms sent with the current resident solve's first
    /// request (the later requests reuse them).
    resident_scale: [f64; 3],
    /// The dead loads' time-table factors (`load_factors`: nodal loads, then dead line
    /// loads) whose nodal terms went up last with a device solve's request (`--solve
    /// whole`: a step on the device uses those terms; gravity is constant).
    device_loads: Option<Vec<f64>>,
    /// The middle time of the step whose requests went up last to an attached evaluator,
    /// and the follower line loads per element (`follower_constants`) the evaluator then
    /// held (`None`: none went up since it was attached).
    follower_sent: Option<(f64, Vec<[f64; 6]>)>,
    /// The last step the device ran was accepted with the consistent scalars (the inexact
    /// strategy on its round-off floor): the host's copy of its state forms that way.
    device_step_consistent: bool,
    /// Registered with a `--solve whole` evaluator ([`Self::set_whole_mode`]).
    whole_mode: bool,
    /// The iterate (per node) and its residual work sent back with the last report.
    resident_iterate: Option<(Vec<[f64; 9]>, f64)>,
    /// `Σ |R_i q_i|` of the accepted iterate when the device computed it (device-resident
    /// Newton); `None`: from `last_residual`.
    residual_work: Option<f64>,
}

impl Simulation {
    /// Sets up a simulation of `model` with `params` (the linear solver's symbolic
    /// analysis is done here, once).
    pub fn new(
        model: Model,
        params: IntegratorParams,
    ) -> Result<Self, crate::linsolve::LinsolveError> {
        let data = ElementData::for_model(&model);
        let lanes = assemble::LANES_PAY && Self::lanes_fit(&data);
        let trans_diss = params.scheme.translational_dissipation();
        let dofs = DofMap::new(&model, trans_diss);
        let parts = Self::system_parts(&model, &data, &dofs, &[])?;
        let state = State::initial(&model, &data);
        let inv = invariants(&model, &data, &state);
        let nn = model.n_nodes();
        let model_damped = model.has_material_damping() || model.has_drag() || model.has_friction();
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
            prescribed: vec![[Vec3::zeros(); 2]; nn],
            commands: Vec::new(),
            model,
            params,
            data_lanes: Self::lane_groups(&data),
            data,
            dofs,
            solver: parts.solver,
            slots: parts.slots,
            row_map: parts.row_map,
            tangent_map: parts.tangent_map,
            scatter_off: parts.scatter_off,
            node_slots: parts.node_slots,
            node_block_slots: parts.node_block_slots,
            off_block_slots: parts.off_block_slots,
            link_slots: parts.link_slots,
            contact_slots: Vec::new(),
            extra_pattern: Vec::new(),
            rod_pairs: Vec::new(),
            rod_pairs_version: None,
            node_pair_slots: std::collections::HashMap::new(),
            slide_blocks: parts.slide_blocks,
            state,
            inv,
            trans_diss,
            backend: Backend::Cpu,
            state_version: 0,
            sent_version: None,
            device_advance: false,
            advanced_version: None,
            device_steps: false,
            host_stale: false,
            timers: SolveTimers::default(),
            factored: None,
            fell_back: false,
            damped_model: model_damped,
            last_predictor: true,
            fallback_pending: false,
            solved_consistent: false,
            inexact_tangent: false,
            lanes,
            polish: false,
            step_start: false,
            step_r0: 0.0,
            planar: parts.planar,
            device_solve: false,
            device_x: None,
            device_resident: false,
            multi_iteration: false,
            resident_now: false,
            resident_next: Default::default(),
            resident_scale: [0.0; 3],
            device_loads: None,
            follower_sent: None,
            device_step_consistent: false,
            whole_mode: false,
            resident_iterate: None,
            residual_work: None,
        })
    }

    /// The linear system's structures for the element pattern plus `extra` (row, col)
    /// couplings (contact between rods): the solver (symbolic analysis) and every slot
    /// table into its values.
    fn system_parts(
        model: &Model,
        data: &[ElementData],
        dofs: &DofMap,
        extra: &[(usize, usize)],
    ) -> Result<SystemParts, crate::linsolve::LinsolveError> {
        let mut pattern = dofs.pattern();
        pattern.reserve(dofs.n + 9 * model.links.len() + extra.len());
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
        pattern.extend_from_slice(extra);
        let solver = SparseSolver::with_blocks(dofs.n, &pattern, &dofs.node_block_sizes())?;
        // The element and node-block tables (≈ 2·10⁴ entries for a 30-element rod) are
        // looked up column by column through one lookup table; the few node and link
        // entries, whose columns change with every entry, by binary search.
        let mut look = solver.slot_lookup();
        let slots: Vec<Vec<usize>> = dofs
            .elements
            .iter()
            .map(|m| {
                let mut s = vec![NONE; NDOF * NDOF];
                for j in (0..NDOF).filter(|&j| m[j] != NONE) {
                    for i in (0..NDOF).filter(|&i| m[i] != NONE) {
                        s[i * NDOF + j] = look.slot(m[i], m[j]);
                    }
                }
                s
            })
            .collect();
        let (row_map, tangent_map, scatter_off) = Self::scatter_maps(dofs, &slots);
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
        let (node_block_slots, off_block_slots) = Self::block_slots(model, dofs, &mut look);
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
        let planar = planar::PlanarKernel::new(model, data, dofs, &slots);
        let slide_blocks = slide::SlideBlock::build(model, dofs, &solver);
        Ok(SystemParts {
            solver,
            slots,
            row_map,
            tangent_map,
            scatter_off,
            node_slots,
            node_block_slots,
            off_block_slots,
            link_slots,
            slide_blocks,
            planar,
        })
    }

    /// Rebuilds the linear system for the element pattern plus `extra` couplings (kept
    /// sorted and unique; the pattern only grows). The planar kernel keeps its switch;
    /// the next Newton iteration assembles and factorizes afresh.
    fn rebuild_pattern(
        &mut self,
        extra: Vec<(usize, usize)>,
    ) -> Result<(), crate::linsolve::LinsolveError> {
        let parts = Self::system_parts(&self.model, &self.data, &self.dofs, &extra)?;
        let planar_on = self.planar.as_ref().is_none_or(|p| p.enabled);
        self.solver = parts.solver;
        self.node_pair_slots.clear();
        self.slots = parts.slots;
        self.row_map = parts.row_map;
        self.tangent_map = parts.tangent_map;
        self.scatter_off = parts.scatter_off;
        self.node_slots = parts.node_slots;
        self.node_block_slots = parts.node_block_slots;
        self.off_block_slots = parts.off_block_slots;
        self.link_slots = parts.link_slots;
        self.slide_blocks = parts.slide_blocks;
        self.planar = parts.planar;
        if let Some(p) = self.planar.as_mut() {
            p.enabled = planar_on;
        }
        self.contact_slots.clear();
        self.extra_pattern = extra;
        self.factored = None;
        Ok(())
    }

    /// Time spent so far in assembly, factorization and solves.
    pub fn solve_timers(&self) -> SolveTimers {
        self.timers
    }

    /// Where the element kernel runs: `cpu`, or the attached evaluator's description (the
    /// baselines and the monolithic strategy's consistent assembly stay on the CPU kernel).
    pub fn backend_name(&self) -> String {
        match &self.backend {
            Backend::Cpu => "cpu".to_string(),
            Backend::Direct(b, _) => b.describe(),
            Backend::Lockstep(p) => p.describe().to_string(),
        }
    }

    /// The dissipation strategy the dissipative steps use: the parameters' choice, with
    /// [`Strategy::Auto`] resolved for this backend (staggered where a GPU evaluator is
    /// attached, inexact where it is a `--solve whole` one, monolithic on the CPU kernel).
    pub fn strategy(&self) -> Strategy {
        self.params
            .strategy
            .resolve_for(!matches!(self.backend, Backend::Cpu), self.whole_mode)
    }

    /// `--solve whole` (set by the batch evaluator it is registered with): the `auto`
    /// strategy is the inexact one, whose steps run on the device.
    pub fn set_whole_mode(&mut self, on: bool) {
        self.whole_mode = on;
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
        self.attach(Backend::Direct(backend, slot))
    }

    /// Like [`Self::set_backend`] for a lockstep batch driver: the step posts its element
    /// evaluations to `port` and waits for the driver's answer, so this simulation must be
    /// stepped by that driver ([`crate::batch`]), not by [`Self::step`].
    pub fn set_port(&mut self, port: EvalPort) -> bool {
        self.attach(Backend::Lockstep(port))
    }

    /// Whether the device solves this simulation's block-tridiagonal Newton systems
    /// (`--solve device`); only meaningful with an evaluator attached, and only for a
    /// member the device solver covers (see `crate::batch::gpu::GpuEvaluator::attach`).
    pub fn set_device_solve(&mut self, on: bool) {
        self.device_solve = on;
        self.device_x = None;
    }

    /// Whether the device solves this simulation's Newton systems.
    pub fn device_solve(&self) -> bool {
        self.device_solve
    }

    /// Device-resident Newton (with a device solve, [`Self::set_device_solve`]): the
    /// device keeps each Newton iterate, adds its own corrections and answers only the
    /// relative residual and the solve's outcome per iteration; the host fetches the
    /// iterate it accepts. Only for members whose nodal terms do not depend on the
    /// iterate (every member the device solver covers).
    pub fn set_device_resident(&mut self, on: bool) {
        self.device_resident = on;
    }

    /// Whether the device keeps this simulation's Newton iterates.
    pub fn device_resident(&self) -> bool {
        self.device_resident && self.device_solve
    }

    /// Marks this simulation as solved with several device Newton iterations per
    /// submission (`--solve resident`, set by the batch evaluator that runs it so).
    pub fn set_multi_iteration(&mut self, on: bool) {
        self.multi_iteration = on;
    }

    /// `--solve whole` (set by the batch evaluator, for members it covers): after a step
    /// that accepted the device's Newton iterate, the next request asks the device to
    /// advance its copy of the state by that iterate instead of sending the states.
    pub fn set_device_advance(&mut self, on: bool) {
        self.device_advance = on;
        self.advanced_version = None;
    }

    /// Where its Newton systems are solved, as `summary.json` records it: `host`,
    /// `device`, `resident` (device, several iterations per submission) or `whole`
    /// (resident, and the device advances the state).
    pub fn solve_label(&self) -> &'static str {
        match (self.device_solve, self.multi_iteration) {
            _ if self.device_advance && self.device_solve => "whole",
            (false, _) => "host",
            (true, false) => "device",
            (true, true) => "resident",
        }
    }

    fn attach(&mut self, backend: Backend) -> bool {
        if !self.params.scheme.has_gpu_kernel() {
            return false;
        }
        self.backend = backend;
        self.follower_sent = None;
        self.sent_version = None;
        self.advanced_version = None;
        true
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
    /// Current state (`--solve whole`: after steps on the device, its time only, until
    /// [`Self::sync_device_state`] takes the rest back).
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

    /// The compact scatter lists of the elements (see the fields `row_map`,
    /// `tangent_map`, `scatter_off`): only active entries, so the assembly loop has no
    /// tests for removed unknowns.
    #[allow(clippy::type_complexity)]
    fn scatter_maps(
        dofs: &DofMap,
        slots: &[Vec<usize>],
    ) -> (
        Vec<(usize, usize)>,
        Vec<(usize, usize, usize)>,
        Vec<(usize, usize)>,
    ) {
        let (mut rows, mut tan, mut off) = (Vec::new(), Vec::new(), Vec::new());
        for (map, sl) in dofs.elements.iter().zip(slots) {
            off.push((rows.len(), tan.len()));
            rows.extend((0..NDOF).filter(|&i| map[i] != NONE).map(|i| (i, map[i])));
            let first = tan.len();
            for j in 0..NDOF {
                for i in 0..NDOF {
                    let (src, dst) = (j * NDOF + i, sl[i * NDOF + j]);
                    if dst == NONE {
                        continue;
                    }
                    extend_runs(&mut tan, first, src, dst);
                }
            }
        }
        off.push((rows.len(), tan.len()));
        (rows, tan, off)
    }

    /// Solver slots of the node-local blocks: each node's 9×9 diagonal block (entries
    /// exist only where the node has an element) and each element's two off-diagonal
    /// blocks.
    #[allow(clippy::type_complexity)]
    fn block_slots(
        model: &Model,
        dofs: &DofMap,
        look: &mut SlotLookup<'_>,
    ) -> (Vec<[usize; 81]>, Vec<[[usize; 81]; 2]>) {
        // Entry f = 9 i + j of a table is (a_i, b_j); looked up column by column.
        let mut table = |a: &[usize; 9], b: &[usize; 9]| -> [usize; 81] {
            let mut t = [NONE; 81];
            for (j, &bj) in b.iter().enumerate().filter(|&(_, &bj)| bj != NONE) {
                for (i, &ai) in a.iter().enumerate().filter(|&(_, &ai)| ai != NONE) {
                    t[9 * i + j] = look.slot(ai, bj);
                }
            }
            t
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
        self.state_version += 1;
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
        if !self.model.drives.is_empty() {
            // Removed unknowns of a driven support move by the prescribed increment.
            for (l, &a) in self.model.elements[e].nodes.iter().enumerate() {
                let [u, th] = self.prescribed[a];
                for c in 0..3 {
                    if m[u_idx(l) + c] == NONE {
                        x[u_idx(l) + c] = u[c];
                    }
                    if m[th_idx(l) + c] == NONE {
                        x[th_idx(l) + c] = th[c];
                    }
                }
            }
        }
        Increment::from_local(&x)
    }

    /// The increment `(u, θ)` of node `a` at `q`: the unknowns where they exist, the
    /// prescribed motion of a driven support where they were removed.
    fn node_increment(&self, a: usize, q: &[f64]) -> (Vec3, Vec3) {
        let nd = &self.dofs.nodes[a];
        let [pu, pt] = self.prescribed[a];
        let pick = |idx: &[usize; 3], p: &Vec3| {
            Vec3::from_fn(|c, _| if idx[c] == NONE { p[c] } else { q[idx[c]] })
        };
        (pick(&nd.u, &pu), pick(&nd.th, &pt))
    }

    fn consts(&self) -> StepConsts {
        StepConsts {
            dt: self.params.dt,
            scheme: self.params.scheme,
        }
    }
}

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

/// Appends the tangent entry `src` (index in the column-major element matrix) → `dst`
/// (solver slot) to the run list `runs` of (first source, first slot, length): it extends
/// the last run where both sides continue it and that run is the element's own (from
/// index `first` on), else starts a new one.
pub(super) fn extend_runs(
    runs: &mut Vec<(usize, usize, usize)>,
    first: usize,
    src: usize,
    dst: usize,
) {
    let own = runs.len() > first;
    match runs.last_mut() {
        Some((s, d, len)) if own && *s + *len == src && *d + *len == dst => *len += 1,
        _ => runs.push((src, dst, 1)),
    }
}

#[cfg(test)]
mod tests {
    use super::Simulation;
    use crate::element::NDOF;
    use crate::integrator::dofs::NONE;
    use crate::scene::load_scene;

    /// The scatter runs cover exactly the active (entry, slot) pairs of every element, in
    /// the element matrix's column-major order; on the clamped cantilever an interior
    /// element's 12 active columns are 12 runs of 12 (its two nodes' rows are neighbours
    /// in each sorted matrix column).
    #[test]
    fn scatter_runs_are_the_active_pairs() {
        let scene = load_scene("cantilever").unwrap();
        let sim = Simulation::new(scene.model, scene.params).unwrap();
        for (e, (map, sl)) in sim.dofs.elements.iter().zip(&sim.slots).enumerate() {
            let (lo, hi) = (sim.scatter_off[e].1, sim.scatter_off[e + 1].1);
            let runs = &sim.tangent_map[lo..hi];
            let expanded: Vec<(usize, usize)> = runs
                .iter()
                .flat_map(|&(s, d, len)| (0..len).map(move |k| (s + k, d + k)))
                .collect();
            let pairs: Vec<(usize, usize)> = (0..NDOF)
                .flat_map(|j| (0..NDOF).map(move |i| (j * NDOF + i, sl[i * NDOF + j])))
                .filter(|&(_, d)| d != NONE)
                .collect();
            assert_eq!(expanded, pairs, "element {e}");
            if e > 0 && e + 1 < sim.dofs.elements.len() {
                assert_eq!(map.iter().filter(|&&i| i != NONE).count(), 12);
                assert_eq!(runs.len(), 12, "element {e}: {runs:?}");
                assert!(runs.iter().all(|r| r.2 == 12), "element {e}: {runs:?}");
            }
        }
    }
}
