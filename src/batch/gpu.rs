//! The GPU element evaluator of a batch: slots of members on one element kernel and its
//! assembly pass. [`GpuEvaluator`] serves every posted request of its attached members in
//! one dispatch (the lockstep driver calls [`GpuEvaluator::serve`] once per batch
//! iteration); [`GpuBatcher`] wraps it as a synchronous [`ElementBackend`] for one
//! simulation at a time (`run --backend gpu`, tests).

use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use rayon::prelude::*;

use crate::element::StepConsts;
use crate::gpu::assemble::MemberIncrements;
use crate::gpu::blocktri::{
    Readback, Report, SpecParams, OP_CONSISTENT, OP_FACTOR, OP_POLISH, OP_REACTIVATE, OP_RESTORE,
    OP_SOLVE, OP_SPEC, OP_UPDATE,
};
use crate::gpu::kernel::{KernelMode, KernelTimers, MemberPack, SCATTER_GAP};
use crate::gpu::layout::{AsmLayout, A_NODE};
use crate::gpu::{Around, Assembler, BlockTriSolver, ElementKernel, GpuContext, GpuError};
use crate::integrator::evaluate::{
    AssembledSystem, DeviceSolution, DeviceStepAnswer, ElementBackend, EvalPort, EvalRequest, Pull,
    Pulled, ResidentAnswer,
};
use crate::integrator::Simulation;
use crate::linsolve::batched::{BatchLayout, NONFINITE, OK};
use crate::linsolve::MAX_BACKWARD_ERROR;

/// Host-side costs of serving requests (on top of the kernel's own stage timers).
#[derive(Clone, Copy, Debug, Default)]
pub struct ServeTimers {
    /// Copying the posted requests into the kernel's host buffers.
    pub pack_s: f64,
    /// Requests served (member evaluations).
    pub requests: u64,
    /// Of which wanted the tangent.
    pub tangent_requests: u64,
    /// Element evaluations served (elements of the served requests).
    pub element_evals: u64,
    /// Of which with the tangent.
    pub element_tangent_evals: u64,
    /// Device-resident Newton iterations served (requests that kept the iterate on the
    /// device) and the bytes their reports brought back.
    pub resident_iterations: u64,
    /// Bytes read back for [`Self::resident_iterations`] (16 per iteration).
    pub resident_bytes_down: u64,
    /// Accepted iterates fetched (one per converged device-resident Newton solve) and the
    /// bytes they brought back.
    pub fetches: u64,
    /// Iterates sent back with their report (the host expected or might accept them).
    pub iterates_sent: u64,
    /// Bytes read back for [`Self::fetches`] and [`Self::iterates_sent`] (72 per node slot
    /// and 8 each).
    pub fetch_bytes_down: u64,
    /// Dispatches (each ends in one read-back that waits: a host sync).
    pub dispatches: u64,
    /// `--solve resident`: dispatches that ran several Newton iterations.
    pub multi_dispatches: u64,
    /// `--solve resident`: Newton solves started with a multi-iteration submission.
    pub multi_solves: u64,
    /// `--solve resident`: Newton iterations the device ran in them.
    pub multi_iterations: u64,
    /// `--solve resident`: the host's Newton iterations answered from them without a
    /// dispatch.
    pub multi_answers: u64,
    /// `--solve resident`: bytes read back for them (iteration histories and the
    /// accepted iterates).
    pub multi_bytes_down: u64,
    /// `--solve resident`: the host asked for an iterate the device had moved past (its
    /// Newton test stopped later than the device's): the step fails. Expected 0.
    pub multi_mismatches: u64,
    /// `--solve whole`: member-steps whose state the device advanced (no states uploaded).
    pub device_advances: u64,
    /// `--solve whole`: submissions of the advance pass (one ahead of a dispatch that
    /// starts the next steps of advanced members; no wait).
    pub advance_submits: u64,
    /// `--solve whole`: member-steps run entirely on the device (their records read
    /// back; the host's step runs only for those handed back).
    pub device_steps: u64,
    /// Of [`Self::device_steps`]: handed back to the host's step (a test of the host's
    /// step would not accept the device's iterate as it stands).
    pub device_step_handoffs: u64,
    /// Bytes read back for [`Self::device_steps`] (iteration history, residual work and
    /// records).
    pub device_step_bytes_down: u64,
    /// Bytes sent up in dispatches that held device steps only (operation words, slot
    /// lists: no states, increments or iteration rows), and the device steps they held.
    pub device_step_bytes_up: (u64, u64),
    /// `--solve whole`: members' states handed back to the host (a failed device step, or
    /// the member's end), each one read-back that waits, and their bytes.
    pub state_pulls: u64,
    /// Bytes read back for [`Self::state_pulls`].
    pub pull_bytes_down: u64,
}

/// `--solve resident`: a member's Newton solve as its multi-iteration submission ran it
/// on the device; the host's Newton loop then reads it iteration by iteration without a
/// dispatch.
#[derive(Clone, Debug)]
struct MultiRun {
    /// Per device iteration: its report.
    reports: Vec<Report>,
    /// The next iteration to answer.
    next: usize,
    /// The iteration answered last.
    last: usize,
    /// The iterate evaluated in the last device iteration and its residual work.
    iterate: Option<(Vec<[f64; 9]>, f64)>,
    /// The device found the last iterate accepted (and neither factorized nor solved
    /// there): the host's Newton loop stops there too.
    accepted_last: bool,
}

/// The host's Newton acceptance test (`newton.rs`, `accepted`, for full or fresh Newton
/// on the device) on a multi-iteration run's residuals: whether iteration `c` (residual
/// `res`, after `hist`) is accepted. The twin of `spec_accepts` in `shaders/blocktri.wgsl`.
fn run_accepts(hist: &[f64], res: f64, tol: f64, quadratic: bool) -> bool {
    use crate::integrator::scaling::MIN_CORRECTIONS;
    let c = hist.len();
    if res <= tol && c >= MIN_CORRECTIONS {
        return true;
    }
    if c < 2 {
        return false;
    }
    let (r2, r1) = (hist[c - 2], hist[c - 1]);
    (res <= 1e5 * tol && res >= 0.5 * r1)
        || (quadratic && res <= 10.0 * tol && r1 < r2 && res >= 1e3 * (r1 * (r1 / r2) * (r1 / r2)))
}

/// `slots` members of at most `per_slot` elements and `nodes_per_slot` nodes each on one
/// GPU element kernel and assembly pass.
pub struct GpuEvaluator {
    kernel: ElementKernel,
    assembler: Assembler,
    per_slot: usize,
    /// Per slot: elements and nodes of the registered member.
    sizes: Vec<(usize, usize)>,
    /// Per slot: the mailbox of the member attached there (lockstep driving).
    ports: Vec<Option<EvalPort>>,
    /// `gpu: ADAPTER, PRECISION`.
    adapter: String,
    /// Host-side serving costs.
    pub serve_timers: ServeTimers,
    /// `--solve device`: the block solver over the assembled buffer.
    solver: Option<BlockTriSolver>,
    /// Per slot: its member's systems are solved on the device.
    device: Vec<bool>,
    /// Per slot: its elements are active in the kernel (they stay active from one
    /// evaluation to the next, so that an iterating member uploads nothing for them).
    active: Vec<bool>,
    /// Device solves keep the Newton iterate on the device (device-resident Newton, the
    /// default; `false`: the correction comes back every iteration and the host adds it).
    resident: bool,
    /// Members attached with a device solve, and with a host solve although device
    /// solves were asked for (a feature the device solver does not cover).
    pub device_members: (u64, u64),
    /// `--solve whole`: members the device solve covers whose steps run on the host, by
    /// the reason ([`device_step_refusal`], or the Newton variant).
    pub host_step_reasons: std::collections::BTreeMap<&'static str, u64>,
    /// `--solve whole`: the device steps of the last [`Self::serve`] when it served
    /// nothing else (no host step's request, no state taken back), else 0.
    pub steps_only: usize,
    /// `--solve resident`: Newton iterations per submission (0: one per dispatch).
    multi_k: usize,
    /// Per slot: the Newton tolerance of its member when it runs several iterations per
    /// submission (full or fresh Newton, device-resident), else `None`.
    multi_tol: Vec<Option<f64>>,
    /// Per slot: its Newton solve's multi-iteration run being read.
    multi: Vec<Option<MultiRun>>,
    /// Requests held back (lockstep): they wait while other members read their runs.
    deferred: Vec<(usize, EvalRequest)>,
    /// `--solve whole`: EM members with multi-iteration Newton get their state advanced on
    /// the device ([`Self::set_device_advance`]).
    whole: bool,
    /// Per slot: its member's state is advanced on the device.
    advance_ok: Vec<bool>,
    /// Slots whose requests of the dispatch being packed asked for the advance.
    to_advance: Vec<usize>,
    /// Per slot: its member's steps run entirely on the device
    /// ([`crate::integrator::evaluate::DeviceStep`]).
    fast: Vec<bool>,
    /// Per slot: its device steps run the inexact strategy with its polish round (a
    /// dissipative scheme: [`crate::gpu::blocktri::OP_POLISH`]).
    polish: Vec<bool>,
    /// Per slot: the device stopped its element slots (`I_ACTIVE` 0) in a step on the
    /// device and the host did not send its rows again: the slot's next step on the device
    /// sets them again there ([`crate::gpu::blocktri::OP_REACTIVATE`]), any other
    /// evaluation sends the host's rows first.
    device_stopped: Vec<bool>,
    /// Per slot: the Newton iterations its member's last device step recorded
    /// ([`DEVICE_STEP_MARGIN`]; [`DEVICE_STEP_K`] before its first).
    fast_need: Vec<usize>,
    /// The node increments as they were at the start of the last dispatch with device
    /// steps (a failed device step's predictor, for the host's step).
    saved_increments: Option<wgpu::Buffer>,
}

/// `--solve whole`: whether EM members the device step covers run their steps entirely on
/// the device (default on; `bench` turns it off for its side-by-side "before" run).
static DEVICE_STEPS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Turns whole steps on the device on or off for evaluators created from now on (process
/// wide; `bench --solve whole` compares both in one process).
pub fn set_device_steps(on: bool) {
    DEVICE_STEPS.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Newton iterations a whole step on the device runs at most in its submission (a step
/// that needs more goes to the host's step).
pub const DEVICE_STEP_K: usize = 8;

/// As [`DEVICE_STEP_K`] for a dispatch with device steps of the inexact strategy: its
/// linearly contracting iterations and the polish round (2) in one submission (measured
/// on the test batches of EDMC-1 and EDMC-2 cantilevers under gravity and tip loads: 5–12
/// and 2; at a cap of 12, 31 of 63 steps went back to the host).
pub const DEVICE_STEP_K_POLISH: usize = crate::gpu::blocktri::RESIDENT_MAX_K;

/// Device steps record the most iterations their members' last device steps recorded (each
/// member's own) plus this margin, at least [`DEVICE_STEP_MIN_K`] and at most [`DEVICE_STEP_K`]:
/// each recorded iteration costs the host its encoding (11 dispatches at 31 nodes) whether
/// or not a member still iterates.
const DEVICE_STEP_MARGIN: usize = 2;

/// As [`DEVICE_STEP_MARGIN`] for a dispatch with device steps of the inexact strategy,
/// whose polish round takes 2 or 3 iterations after a linearly contracting count (with a
/// margin of 2, 4 of 42 steps of the test batch on the floor went back to the host for
/// want of their last iteration).
const DEVICE_STEP_MARGIN_POLISH: usize = 3;

/// See [`DEVICE_STEP_MARGIN`].
const DEVICE_STEP_MIN_K: usize = 4;

/// Why a whole step on the device does not cover `sim` (`None`: it does, given a device
/// solve with several iterations per submission): EM (no dissipation to evaluate between
/// rounds; Kelvin–Voigt damping, drag and point masses are the element passes' own), or
/// EDMC-1 and EDMC-2 with the inexact strategy (its consistent-scalar iterations and its
/// polish round, whose scalars the element passes evaluate); dead loads only
/// (nodal, line and gravity) or follower line loads (the element passes' own, their
/// factors sent with the request where their tables move); supports moved by their time
/// tables (the request carries the step's prescribed increments of the removed unknowns,
/// and the update pass sums the supports' reaction work); no sliding clamps along an
/// oblique axis (one along a coordinate axis removes unknowns, like a clamp), links,
/// contact or control commands (supports moved by a controller that reads the state,
/// which stays on the device); planar models are covered (the 3D kernel with the planar
/// unknowns, as in every GPU evaluation). (A step whose loads differ from those the
/// device holds sends the step's nodal terms with its request: `Simulation::device_step`.)
pub fn device_step_refusal(sim: &Simulation) -> Option<&'static str> {
    let m = sim.model();
    let scheme = sim.params().scheme;
    if scheme != crate::integrator::Scheme::Em {
        if !scheme.is_dissipative() {
            return Some("a scheme other than EM, EDMC-1 and EDMC-2");
        }
        if sim.strategy() != crate::integrator::params::Strategy::Inexact {
            return Some("EDMC with a strategy other than inexact: use --strategy inexact");
        }
    }
    if sim.has_commands() {
        return Some("control commands");
    }
    if m.slides.iter().any(|s| s.coordinate_axis().is_none()) {
        return Some("a sliding clamp along an oblique axis");
    }
    if !m.links.is_empty() || !m.obstacles.is_empty() || !m.rod_contacts.is_empty() {
        return Some("links or contact");
    }
    None
}

/// Why the device block solver does not cover `sim` (`None`: it does): it needs a single
/// rod numbered node by node (element `e` joins nodes `e` and `e + 1`) and no rigid links (a
/// dead line load is a nodal term like a nodal load; drag, point masses and follower line
/// loads are the element kernel's).
pub fn device_solve_refusal(sim: &Simulation) -> Option<&'static str> {
    let model = sim.model();
    if model.n_nodes() < 2
        || model
            .elements
            .iter()
            .enumerate()
            .any(|(e, el)| el.nodes != [e, e + 1])
    {
        return Some("topology is not one rod numbered node by node (block-tridiagonal)");
    }
    if !model.links.is_empty() {
        return Some("rigid links");
    }
    if model.slides.iter().any(|s| s.coordinate_axis().is_none()) {
        return Some("a sliding clamp along an oblique axis");
    }
    // (A driven support's removed unknowns hold its prescribed increment: the host's
    // increments go up with each Newton solve's first request, and the device's updates
    // touch only the unknowns.)
    None
}

/// The host solver's message for a failed device solve (same wording as
/// [`crate::linsolve::LinsolveError::Singular`]), or the solution.
fn device_outcome(status: u32, berr: f64, x: &[f64], n_nodes: usize) -> DeviceSolution {
    let fail = |why: String| Err(format!("singular or ill-conditioned tangent: {why}"));
    if status == NONFINITE {
        return fail("non-finite solution of the device block solve".into());
    }
    if status != OK {
        return fail(format!(
            "singular Schur complement of node block {}",
            status - 1
        ));
    }
    if berr > MAX_BACKWARD_ERROR {
        return fail(format!(
            "backward error {berr:.2e} of the device block solve exceeds {MAX_BACKWARD_ERROR:e}"
        ));
    }
    Ok((0..n_nodes)
        .map(|j| std::array::from_fn(|k| x[9 * j + k]))
        .collect())
}

/// [`device_outcome`] of a device-resident iteration's [`Report`].
fn resident_outcome(r: &Report, iterate: Option<(Vec<[f64; 9]>, f64)>) -> ResidentAnswer {
    ResidentAnswer::Iterated {
        residual: r.residual,
        solve: device_outcome(r.status, r.berr, &[], 0).map(|_| ()),
        iterate,
    }
}

impl GpuEvaluator {
    /// Kernel and assembly buffers for `slots` members of at most `per_slot` elements and
    /// `nodes_per_slot` nodes.
    pub fn new(
        ctx: &GpuContext,
        slots: usize,
        per_slot: usize,
        nodes_per_slot: usize,
    ) -> Result<Self, GpuError> {
        let mut kernel = ElementKernel::new(ctx, slots * per_slot)?;
        let assembler = Assembler::new(ctx, &mut kernel, slots, per_slot, nodes_per_slot)?;
        Ok(Self {
            kernel,
            assembler,
            per_slot,
            sizes: vec![(0, 0); slots],
            ports: vec![None; slots],
            adapter: format!("gpu: {}", ctx.describe()),
            serve_timers: ServeTimers::default(),
            solver: None,
            device: vec![false; slots],
            active: vec![false; slots],
            resident: true,
            device_members: (0, 0),
            host_step_reasons: Default::default(),
            steps_only: 0,
            multi_k: 0,
            multi_tol: vec![None; slots],
            multi: vec![None; slots],
            deferred: Vec::new(),
            whole: false,
            advance_ok: vec![false; slots],
            to_advance: Vec::new(),
            fast: vec![false; slots],
            polish: vec![false; slots],
            device_stopped: vec![false; slots],
            fast_need: vec![DEVICE_STEP_K; slots],
            saved_increments: None,
        })
    }

    /// `--solve device`: builds the block solver over the assembled buffer; members
    /// attached from now on that it covers ([`device_solve_refusal`]) are solved on the
    /// device, the others on the host within the same batch.
    pub fn enable_device_solve(&mut self, ctx: &GpuContext) -> Result<(), GpuError> {
        let l = self.assembler.layout();
        let layout = BatchLayout {
            npn: l.nodes_per_slot,
            k_start: l.tangent_start(),
            kpm: l.tangent_per_member(),
            rpm: l.residual_per_member(),
            negate: true,
        };
        self.solver = Some(BlockTriSolver::new(
            ctx,
            l.members,
            layout,
            self.assembler.buffer(),
            Some(self.assembler.increments_buffer()),
            Some((
                self.kernel.iter_buffer(),
                self.kernel.capacity(),
                self.per_slot,
            )),
        )?);
        Ok(())
    }

    /// Whether device solves keep the Newton iterate on the device (default `true`; set
    /// before attaching members). `false` reads the correction and the residual rows back
    /// every iteration and leaves the update to the host, the earlier shape of
    /// `--solve device`, kept for comparison (`tests/device_solve.rs`).
    pub fn set_resident(&mut self, on: bool) {
        self.resident = on;
    }

    /// `--solve resident`: device-resident members with full or fresh Newton run up to
    /// `k` Newton iterations per submission (0 or 1: one), the device stopping each where
    /// the host's Newton loop stops; set before attaching members.
    pub fn set_iterations_per_submission(&mut self, k: usize) {
        self.multi_k = k.min(crate::gpu::blocktri::RESIDENT_MAX_K);
    }

    /// `--solve whole`: members attached from now on that run several Newton iterations
    /// per submission ([`Self::set_iterations_per_submission`]) with the EM scheme keep
    /// their state on the device: after a step that accepted the device's iterate, the
    /// advance pass forms the state at `n+1` from it (the kinematics of the element
    /// passes) instead of the host uploading it; set before attaching members.
    pub fn set_device_advance(&mut self, on: bool) {
        self.whole = on;
        // A clean slot between two changed ones must not go up with them: the device's
        // copy of an advanced member's state is newer than the host mirror.
        self.kernel.set_state_gap(if on { 0 } else { SCATTER_GAP });
    }

    /// Largest number of slots of `per_slot` elements and `nodes_per_slot` nodes that fits
    /// one kernel and its assembled buffer on `ctx`.
    pub fn max_slots(ctx: &GpuContext, per_slot: usize, nodes_per_slot: usize) -> usize {
        (ElementKernel::max_capacity(ctx) / per_slot.max(1)).min(Assembler::max_members(
            ctx,
            per_slot,
            nodes_per_slot,
        ))
    }

    /// Number of slots.
    pub fn slots(&self) -> usize {
        self.sizes.len()
    }

    /// `gpu: ADAPTER, PRECISION`.
    pub fn describe(&self) -> &str {
        &self.adapter
    }

    /// Uploads the element constants and the node incidence of `sim` into `slot` (once per
    /// member; a slot is reused by the next member after [`Self::detach`]).
    pub fn register(&mut self, slot: usize, sim: &Simulation) -> Result<(), GpuError> {
        if let Some(feature) = sim.model().gpu_unsupported() {
            return Err(GpuError::Unsupported {
                feature: feature.into(),
            });
        }
        let k = StepConsts {
            dt: sim.params().dt,
            scheme: sim.params().scheme,
        };
        let ends: Vec<[usize; 2]> = sim.model().elements.iter().map(|e| e.nodes).collect();
        // Each point mass rides on the first end incident to its node (element order).
        let mut carried = vec![[0.0; 2]; ends.len()];
        for (a, &m) in sim.model().point_mass.iter().enumerate() {
            if m == 0.0 {
                continue;
            }
            let first = ends
                .iter()
                .enumerate()
                .find_map(|(e, nodes)| nodes.iter().position(|&n| n == a).map(|l| (e, l)));
            match first {
                Some((e, l)) => carried[e][l] = m,
                None => {
                    return Err(GpuError::Unsupported {
                        feature: format!("a point mass on node {a}, which no element joins"),
                    })
                }
            }
        }
        let trans = sim.params().scheme.translational_dissipation();
        // The slot's previous member may have had more elements: none stays active.
        self.deactivate(slot);
        let masks = sim.dof_map().element_row_masks();
        let n_nodes = sim.model().n_nodes();
        self.assembler.set_member(slot, n_nodes, &ends, &masks)?;
        for (e, d) in sim.element_data().iter().enumerate() {
            self.kernel
                .set_element(slot * self.per_slot + e, d, &k, trans);
        }
        for (e, m) in carried.into_iter().enumerate() {
            if m != [0.0; 2] {
                self.kernel.set_point_masses(slot * self.per_slot + e, m);
            }
        }
        self.sizes[slot] = (ends.len(), n_nodes);
        Ok(())
    }

    /// Registers `sim` in `slot` and connects it for lockstep driving: its step will post
    /// its element evaluations here. Returns false (and attaches nothing) for a scheme
    /// without a GPU kernel, which then runs on the CPU kernel.
    pub fn attach(&mut self, slot: usize, sim: &mut Simulation) -> Result<bool, GpuError> {
        if !sim.params().scheme.has_gpu_kernel() {
            return Ok(false);
        }
        self.register(slot, sim)?;
        let port = EvalPort::new(&self.adapter);
        sim.set_port(port.clone());
        self.connect_device(slot, sim);
        self.ports[slot] = Some(port);
        Ok(true)
    }

    /// With a device solver: registers `slot`'s node masks and switches `sim` to device
    /// solves when the solver covers it ([`device_solve_refusal`]); returns whether it
    /// does.
    fn connect_device(&mut self, slot: usize, sim: &mut Simulation) -> bool {
        // (`auto` resolves to the inexact strategy under `--solve whole`.)
        sim.set_whole_mode(self.whole);
        let on = match &mut self.solver {
            Some(solver) if device_solve_refusal(sim).is_none() => {
                let masks: Vec<u32> = sim
                    .dof_map()
                    .nodes
                    .iter()
                    .map(|nd| {
                        let loc = [nd.u, nd.th, nd.g].concat();
                        loc.iter()
                            .enumerate()
                            .filter(|(_, &i)| i != crate::integrator::dofs::NONE)
                            .fold(0u32, |m, (k, _)| m | 1 << k)
                    })
                    .collect();
                solver.set_member(slot, &masks);
                self.device_members.0 += 1;
                true
            }
            Some(solver) => {
                solver.set_member(slot, &[]);
                self.device_members.1 += 1;
                false
            }
            None => false,
        };
        self.device[slot] = on;
        let p = sim.params();
        self.multi_tol[slot] = (on
            && self.resident
            && self.multi_k > 1
            && p.newton != crate::integrator::NewtonVariant::Modified)
            .then_some(p.newton_tol);
        self.multi[slot] = None;
        sim.set_device_solve(on);
        sim.set_device_resident(on && self.resident);
        sim.set_multi_iteration(self.multi_tol[slot].is_some());
        // EM members keep their state on the device whether or not their steps run there;
        // a dissipative scheme's members where their steps run there (whose advance
        // pass also freezes the next step's scalars).
        let em = sim.params().scheme == crate::integrator::Scheme::Em;
        let steps = self.whole
            && self.multi_tol[slot].is_some()
            && DEVICE_STEPS.load(std::sync::atomic::Ordering::Relaxed)
            && device_step_refusal(sim).is_none();
        self.advance_ok[slot] = self.whole && self.multi_tol[slot].is_some() && (em || steps);
        sim.set_device_advance(self.advance_ok[slot]);
        self.fast[slot] = steps;
        self.polish[slot] = steps && !em;
        if self.whole && on && !steps && DEVICE_STEPS.load(std::sync::atomic::Ordering::Relaxed) {
            let why = device_step_refusal(sim).unwrap_or(
                if sim.params().newton == crate::integrator::NewtonVariant::Modified {
                    "modified Newton"
                } else {
                    "one Newton iteration per submission"
                },
            );
            *self.host_step_reasons.entry(why).or_default() += 1;
        }
        self.fast_need[slot] = DEVICE_STEP_K;
        sim.set_device_steps(self.fast[slot]);
        self.assembler.set_device_owned(slot, on && self.resident);
        on
    }

    /// Marks every element slot of member slot `slot` inactive (the kernel skips them).
    fn deactivate(&mut self, slot: usize) {
        let base = slot * self.per_slot;
        for e in 0..self.per_slot {
            self.kernel.set_inactive(base + e);
        }
        self.active[slot] = false;
        // The host's mirror goes to 0 and up: the device's rows match it again.
        self.device_stopped[slot] = false;
    }

    /// Frees `slot` (its member finished).
    pub fn detach(&mut self, slot: usize) {
        self.ports[slot] = None;
        self.multi[slot] = None;
        self.multi_tol[slot] = None;
        self.advance_ok[slot] = false;
        self.fast[slot] = false;
        self.polish[slot] = false;
        self.deactivate(slot);
        if self.device[slot] {
            // The device changed the slot's increments: the next member uploads all.
            self.assembler.invalidate_increments(slot);
            self.assembler.set_device_owned(slot, false);
        }
        self.device[slot] = false;
    }

    /// Stage timers and traffic so far.
    pub fn timers(&self) -> KernelTimers {
        self.kernel.timers
    }

    /// Layout of the assembled buffer.
    pub fn layout(&self) -> AsmLayout {
        self.assembler.layout()
    }

    /// Whether `req` fits `slot` (an error names what did not fit).
    fn fits(&self, slot: usize, req: &EvalRequest) -> Result<(), String> {
        let (n_elems, n_nodes) = self.sizes[slot];
        let states_ok = req.states.as_ref().is_none_or(|s| s.len() == n_elems);
        let resident = req.resident.filter(|_| self.device[slot]);
        let upload = resident.is_none_or(|r| r.upload);
        if !states_ok || req.scalars.len() != n_elems || (upload && req.increments.len() != n_nodes)
        {
            return Err(format!(
                "GPU slot {slot} holds (elements, nodes) ({n_elems}, {n_nodes}), ({}, {}) submitted",
                req.scalars.len(),
                req.increments.len()
            ));
        }
        Ok(())
    }

    /// Writes every request that fits its slot into the host buffers — states, frozen
    /// scalars, increments — in parallel over members (their slots are contiguous in the
    /// host mirrors); one outcome per request (fetches write nothing).
    fn pack(&mut self, reqs: &[(usize, EvalRequest)]) -> Vec<Result<(), String>> {
        let slots = self.sizes.len();
        let mut members: Vec<Option<MemberPack<'_>>> = vec![None; slots];
        let mut increments: Vec<Option<MemberIncrements<'_>>> = vec![None; slots];
        // The host's nodal terms of device-solved members (the right-hand side's extra).
        let mut extras: Vec<Option<&[[f64; A_NODE]]>> = vec![None; slots];
        // The driven supports' prescribed increments of the steps on the device.
        let mut prescribed: Vec<(usize, &[crate::integrator::evaluate::Prescribed])> = Vec::new();
        let outcomes = reqs
            .iter()
            .map(|(slot, req)| {
                let resident = req.resident.filter(|_| self.device[*slot]);
                if resident.is_some_and(|r| r.fetch) {
                    return Ok(());
                }
                // Follower line loads whose factors moved: the element constants go up.
                if let Some(f) = &req.follower {
                    if f.len() != self.sizes[*slot].0 {
                        return Err(format!(
                            "GPU slot {slot}: follower loads for {} elements, the member has {}",
                            f.len(),
                            self.sizes[*slot].0
                        ));
                    }
                    for (e, fm) in f.iter().enumerate() {
                        self.kernel.set_follower(*slot * self.per_slot + e, fm);
                    }
                }
                if req.device_step.is_some() {
                    if !self.fast[*slot] {
                        return Err(format!(
                            "GPU slot {slot}: a step on the device asked of a member it does not cover"
                        ));
                    }
                    if req.advance {
                        self.to_advance.push(*slot);
                    }
                    // New loads for this step (a tabled load whose factor changed).
                    extras[*slot] = req.device_extra.as_deref();
                    if !req.prescribed.is_empty() {
                        prescribed.push((*slot, &req.prescribed));
                    }
                    // The inexact strategy after a step the host ran: its scalars (those
                    // the advance pass forms too, sent up after it) and the consistent flag.
                    if !req.scalars.is_empty() {
                        if req.scalars.len() != self.sizes[*slot].0 {
                            return Err(format!(
                                "GPU slot {slot}: {} frozen scalars for {} elements",
                                req.scalars.len(),
                                self.sizes[*slot].0
                            ));
                        }
                        members[*slot] = Some(MemberPack {
                            states: None,
                            scalars: &req.scalars,
                            consistent: req.consistent,
                        });
                    }
                    return Ok(());
                }
                self.fits(*slot, req)?;
                if req.advance {
                    if !self.advance_ok[*slot] {
                        return Err(format!(
                            "GPU slot {slot}: a state advance asked of a member whose state the device does not keep"
                        ));
                    }
                    self.to_advance.push(*slot);
                }
                if self.device[*slot] {
                    extras[*slot] = req.device_extra.as_deref();
                }
                members[*slot] = Some(MemberPack {
                    states: req.states.as_deref(),
                    scalars: &req.scalars,
                    consistent: req.consistent,
                });
                increments[*slot] = match resident {
                    // The device's copy may differ from the host's mirror.
                    Some(r) if r.upload => Some((&req.increments, true)),
                    Some(_) => None,
                    // A host-side request on a slot the device owns (the test entry points
                    // of a resident member): the host copy is stale, upload everything.
                    None => Some((&req.increments, self.device[*slot] && self.resident)),
                };
                Ok(())
            })
            .collect();
        self.kernel.pack_members(self.per_slot, &members);
        self.assembler.pack_increments(&increments);
        for (slot, rows) in prescribed {
            self.assembler.set_prescribed(&mut self.kernel, slot, rows);
        }
        if let Some(solver) = &mut self.solver {
            solver.set_extras(&extras);
        }
        outcomes
    }

    /// `--solve resident`: the answer to `req` from `slot`'s multi-iteration run, when it
    /// holds one (`None`: the request goes to a dispatch, and the run is over).
    fn answer_from_run(
        &mut self,
        slot: usize,
        req: &EvalRequest,
    ) -> Option<Result<AssembledSystem, String>> {
        let r = req.resident.filter(|_| self.device[slot])?;
        let run = self.multi[slot].as_mut()?;
        let n = run.reports.len();
        let st = &mut self.serve_timers;
        if r.fetch {
            // The host accepted the iterate answered last: the device holds it if that was
            // its last iteration.
            let out = match (&run.iterate, run.last + 1 == n) {
                (Some((q, rw)), true) => Ok(AssembledSystem {
                    resident: Some(ResidentAnswer::Fetched {
                        q: q.clone(),
                        residual_work: *rw,
                    }),
                    ..AssembledSystem::default()
                }),
                _ => {
                    st.multi_mismatches += 1;
                    Err(format!(
                        "the host accepted Newton iteration {} but the device went on to {}",
                        run.last, n
                    ))
                }
            };
            self.multi[slot] = None;
            st.multi_answers += 1;
            return Some(out);
        }
        if run.next >= n && run.accepted_last && !r.upload {
            // The device stopped where the host's test accepts, without a correction; the
            // host went on: its iterate is not on the device.
            st.multi_mismatches += 1;
            self.multi[slot] = None;
            return Some(Err(
                "the device stopped its Newton iterations where the host went on".into(),
            ));
        }
        if r.upload || r.restore || req.states.is_some() || run.next >= n {
            self.multi[slot] = None;
            return None;
        }
        let j = run.next;
        let residual_only = r.predict_accept && !req.tangent;
        let mut report = run.reports[j];
        if residual_only {
            // (A dispatch would neither factorize nor solve: the outcome reads 0.)
            (report.status, report.berr) = (crate::linsolve::batched::OK, 0.0);
        } else {
            run.next += 1;
        }
        run.last = j;
        let iterate = ((r.predict_accept || r.send_iterate) && j + 1 == n)
            .then(|| run.iterate.clone())
            .flatten();
        st.multi_answers += 1;
        Some(Ok(AssembledSystem {
            resident: Some(resident_outcome(&report, iterate)),
            ..AssembledSystem::default()
        }))
    }

    /// Evaluates the given (slot, request) pairs in one dispatch; one answer per pair, in
    /// order. Device-resident fetches ([`crate::integrator::evaluate::Resident::fetch`])
    /// evaluate nothing: their iterates are read back with the dispatch's results.
    fn evaluate(
        &mut self,
        reqs: Vec<(usize, EvalRequest)>,
    ) -> Vec<(usize, Result<AssembledSystem, String>)> {
        let t0 = Instant::now();
        let up0 = self.kernel.timers.bytes_up;
        // `--solve resident`: iterations the device already ran are answered from there.
        let mut answers = Vec::with_capacity(reqs.len());
        let reqs: Vec<(usize, EvalRequest)> = reqs
            .into_iter()
            .filter_map(|(slot, req)| match self.answer_from_run(slot, &req) {
                Some(a) => {
                    answers.push((slot, a));
                    None
                }
                None => Some((slot, req)),
            })
            .collect();
        if reqs.is_empty() {
            return answers;
        }
        // Slots active from an earlier evaluation that evaluate nothing now go inactive
        // (the evaluating ones are activated by packing).
        let evaluating: Vec<bool> = {
            let mut v = vec![false; self.sizes.len()];
            for (slot, req) in &reqs {
                let fetch = req.resident.is_some_and(|r| r.fetch) && self.device[*slot];
                v[*slot] |= !fetch;
            }
            v
        };
        for slot in 0..self.sizes.len() {
            if self.active[slot] && !evaluating[slot] {
                self.deactivate(slot);
            }
        }
        let mut pending = Vec::with_capacity(reqs.len());
        let mut ops: Vec<(usize, u32)> = Vec::new();
        // Device-resident slots of this dispatch: iterating, fetching, and iterating with
        // the iterate sent back (predicted acceptance).
        let mut iterating: Vec<usize> = Vec::new();
        let mut fetching: Vec<usize> = Vec::new();
        let mut with_iterate: Vec<usize> = Vec::new();
        // `--solve resident`: Newton solves starting here that run several iterations.
        let mut multi: Vec<usize> = Vec::new();
        // `--solve whole`: whole steps on the device.
        let mut fast: Vec<usize> = Vec::new();
        // Device steps record as many iterations as their members needed last time (the
        // most of them), with a margin (a step that needs more goes to the host's step;
        // the next records more).
        let polishing = reqs
            .iter()
            .any(|(slot, req)| req.device_step.is_some() && self.polish[*slot]);
        let need = reqs
            .iter()
            .filter(|(_, req)| req.device_step.is_some())
            .map(|(slot, _)| self.fast_need[*slot])
            .max()
            .unwrap_or(DEVICE_STEP_K);
        let (cap, margin) = if polishing {
            (DEVICE_STEP_K_POLISH, DEVICE_STEP_MARGIN_POLISH)
        } else {
            (DEVICE_STEP_K, DEVICE_STEP_MARGIN)
        };
        let fast_k = (need + margin).clamp(
            DEVICE_STEP_MIN_K,
            self.multi_k
                .clamp(cap, crate::gpu::blocktri::RESIDENT_MAX_K),
        );
        // Their Newton tests (tolerance, quadratic convergence).
        let mut multi_test: Vec<(f64, bool)> = vec![(0.0, false); self.sizes.len()];
        let multi_k = self.multi_k;
        // Slots the device stopped in a step on the device: a step on the device sets
        // them again there, any other evaluation sends the host's rows first.
        let mut reactivate = vec![false; self.sizes.len()];
        for (slot, req) in &reqs {
            if std::mem::take(&mut self.device_stopped[*slot]) {
                if req.device_step.is_some() {
                    reactivate[*slot] = true;
                } else {
                    let lo = slot * self.per_slot;
                    self.kernel.touch_iter(lo, lo + self.per_slot);
                }
            }
        }
        let packed = self.pack(&reqs);
        for (&(slot, ref req), packed) in reqs.iter().zip(packed) {
            let resident = req.resident.filter(|_| self.device[slot]);
            if resident.is_some_and(|r| r.fetch) {
                fetching.push(slot);
                continue;
            }
            match packed {
                Ok(()) if req.device_step.is_some() => {
                    let (Some(solver), Some(ds)) = (&mut self.solver, req.device_step) else {
                        answers.push((slot, Err("no device solver for a device step".into())));
                        continue;
                    };
                    solver.set_host_scale(slot, ds.scale);
                    // The inexact strategy's iterations contract linearly; its polish
                    // round (quadratic) is the device's own switch.
                    let polish = self.polish[slot];
                    solver.set_spec(
                        slot,
                        SpecParams {
                            tol: self.multi_tol[slot].unwrap_or(0.0),
                            quadratic: !polish,
                            min_corrections: crate::integrator::scaling::MIN_CORRECTIONS,
                            k: fast_k,
                        },
                    );
                    let react = if reactivate[slot] { OP_REACTIVATE } else { 0 };
                    let inexact = if polish { OP_CONSISTENT | OP_POLISH } else { 0 };
                    ops.push((
                        slot,
                        OP_FACTOR | OP_SOLVE | OP_UPDATE | OP_SPEC | react | inexact,
                    ));
                    fast.push(slot);
                    let n = self.sizes[slot].0 as u64;
                    let st = &mut self.serve_timers;
                    st.requests += 1;
                    st.tangent_requests += 1;
                    st.element_evals += n;
                    st.element_tangent_evals += n;
                    st.device_steps += 1;
                    pending.push((slot, true));
                }
                Ok(()) => {
                    if let (Some(_), Some(solver), true) =
                        (&req.device_extra, &mut self.solver, self.device[slot])
                    {
                        let mut op = if req.tangent {
                            OP_FACTOR | OP_SOLVE
                        } else {
                            OP_SOLVE
                        };
                        let multi_tol = self.multi_tol[slot].filter(|_| {
                            resident.is_some_and(|r| {
                                r.upload && !r.restore && !r.predict_accept && req.tangent
                            })
                        });
                        if let (Some(r), Some(tol)) = (resident, multi_tol) {
                            solver.set_host_scale(slot, r.scale);
                            solver.set_spec(
                                slot,
                                SpecParams {
                                    tol,
                                    // (The inexact strategy's tangent leaves the scalars'
                                    // linearization out: it contracts linearly.)
                                    quadratic: !req.consistent,
                                    min_corrections: crate::integrator::scaling::MIN_CORRECTIONS,
                                    k: multi_k,
                                },
                            );
                            op |= OP_UPDATE | OP_SPEC;
                            multi.push(slot);
                            multi_test[slot] = (tol, !req.consistent);
                        } else if let Some(r) = resident {
                            solver.set_host_scale(slot, r.scale);
                            op |= OP_UPDATE;
                            if r.restore {
                                op |= OP_RESTORE;
                            }
                            if r.predict_accept && !req.tangent {
                                op &= !OP_SOLVE;
                                with_iterate.push(slot);
                            } else if r.send_iterate {
                                with_iterate.push(slot);
                            }
                            iterating.push(slot);
                        }
                        ops.push((slot, op));
                    }
                    let n = self.sizes[slot].0 as u64;
                    let st = &mut self.serve_timers;
                    st.requests += 1;
                    st.element_evals += n;
                    if req.tangent {
                        st.tangent_requests += 1;
                        st.element_tangent_evals += n;
                    }
                    pending.push((slot, req.tangent));
                }
                Err(e) => answers.push((slot, Err(e))),
            }
        }
        // The requests' vectors were allocated by the member threads: freeing them is
        // per-member work, done on the pool, not on this (the driver's) thread.
        rayon::spawn(move || drop(reqs));
        // `--solve whole`: the advance of the members whose last step accepted the
        // device's iterate, ahead of this dispatch (whose gather overwrites the iterate).
        // (Recorded at the head of this dispatch's submission, or submitted on its own
        // when the dispatch solves nothing on the device.)
        let per = self.per_slot;
        let sizes = &self.sizes;
        let slots_of = |ms: &[usize]| -> Vec<u32> {
            ms.iter()
                .flat_map(|&m| (0..sizes[m].0).map(move |e| (m * per + e) as u32))
                .collect()
        };
        let mut advance = (!self.to_advance.is_empty()).then(|| slots_of(&self.to_advance));
        // The records of this dispatch's device steps, after its last iteration.
        let records = (!fast.is_empty()).then(|| slots_of(&fast));
        if advance.is_some() {
            self.serve_timers.device_advances += self.to_advance.len() as u64;
            self.serve_timers.advance_submits += 1;
            self.to_advance.clear();
        }
        let in_dispatch = !pending.is_empty() && self.solver.is_some() && !ops.is_empty();
        if let Some(list) = advance.as_ref().filter(|_| !in_dispatch) {
            self.kernel.submit_advance(list);
            advance = None;
        }
        self.serve_timers.pack_s += t0.elapsed().as_secs_f64();
        if pending.is_empty() && fetching.is_empty() {
            return answers;
        }
        let device = &self.device;
        let mut resident_slot = vec![false; self.sizes.len()];
        for &m in iterating.iter().chain(&multi).chain(&fast) {
            resident_slot[m] = true;
        }
        let mut multi_slot = vec![false; self.sizes.len()];
        for &m in multi.iter().chain(&fast) {
            multi_slot[m] = true;
        }
        let repeats = if !fast.is_empty() && multi.is_empty() {
            fast_k
        } else if !fast.is_empty() {
            multi_k.max(fast_k)
        } else if multi.is_empty() {
            1
        } else {
            multi_k
        };
        // The node increments at the start of a dispatch with device steps: a failed
        // step's predictor, handed to the host's step with the state.
        let save = if fast.is_empty() {
            None
        } else {
            let src = self.assembler.increments_buffer().clone();
            let dst = self
                .saved_increments
                .get_or_insert_with(|| {
                    self.kernel.device().create_buffer(&wgpu::BufferDescriptor {
                        label: Some("saved increments"),
                        size: src.size(),
                        usage: wgpu::BufferUsages::STORAGE
                            | wgpu::BufferUsages::COPY_DST
                            | wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    })
                })
                .clone();
            Some((src, dst))
        };
        self.serve_timers.dispatches += 1;
        if !multi.is_empty() {
            self.serve_timers.multi_dispatches += 1;
            self.serve_timers.multi_solves += multi.len() as u64;
        }
        let is_resident = |m: usize| resident_slot[m];
        // A dispatch of device-resident members only reads nothing back before its last
        // read: from here to there the thread waits for the device (a software adapter
        // may run the passes inside the submissions), encodes and submits. The device's
        // pass time is that span less the thread's own CPU time in it.
        let span = (
            Instant::now(),
            crate::gpu::driver::thread_cpu_s() - crate::gpu::driver::driver_thread_s(),
            self.kernel.timers.kernel_s,
        );
        let res = if pending.is_empty() {
            Ok(None)
        } else {
            match &mut self.solver {
                Some(solver) if !ops.is_empty() => {
                    // Restores go ahead of the gather pass that reads the increments, the
                    // solves (and resident updates) after the assembly.
                    let solver = std::cell::RefCell::new(solver);
                    self.assembler.run_with(
                        &mut self.kernel,
                        &pending,
                        &|m| !device[m],
                        &|m| !is_resident(m),
                        Around {
                            head: &mut |k, enc| {
                                if let Some(list) = advance.take() {
                                    k.encode_advance(
                                        enc,
                                        KernelMode::Frozen,
                                        &list,
                                        0,
                                        false,
                                        false,
                                    );
                                }
                            },
                            before: &mut |enc| {
                                if let Some((src, dst)) = &save {
                                    enc.copy_buffer_to_buffer(src, 0, dst, 0, src.size());
                                }
                                let mut s = solver.borrow_mut();
                                s.encode_restore(enc, &ops);
                                if repeats > 1 {
                                    s.encode_spec_reset(enc, &ops);
                                }
                            },
                            more: &mut |enc| {
                                let mut s = solver.borrow_mut();
                                if repeats > 1 {
                                    s.encode_iteration(enc, &ops);
                                } else {
                                    s.encode(enc, &ops);
                                }
                            },
                            tail: &mut |k, enc| {
                                if let Some(list) = &records {
                                    k.encode_advance(
                                        enc,
                                        KernelMode::Frozen,
                                        list,
                                        per,
                                        false,
                                        true,
                                    );
                                }
                            },
                            keep: true,
                        },
                        repeats,
                    )
                }
                _ => self
                    .assembler
                    .run(&mut self.kernel, &pending)
                    .map(|()| None),
            }
        };
        // The dispatch's command buffer when nothing was read back yet: the solver's
        // read-back goes at its end (one submission).
        let mut kept = None;
        let mut res = res.map(|k| kept = k);
        // Device solves: statuses and corrections of the per-iteration members, reports of
        // the resident ones, iterates of the fetching ones.
        // `--solve whole`: the records of the device steps' last iterates (states kept).
        let fast_runs = crate::gpu::kernel::index_runs(fast.iter().copied());
        let mut extra = Vec::new();
        if res.is_ok() && !fast.is_empty() {
            let cap = self.kernel.capacity() as u64;
            let tmid = self.kernel.tmid_buffer().clone();
            for &(lo, hi) in &fast_runs {
                for k in 0..crate::gpu::layout::N_ADV as u64 {
                    let f = crate::gpu::layout::T_REC as u64 + k;
                    extra.push((
                        tmid.clone(),
                        8 * (f * cap + lo as u64),
                        8 * (hi - lo) as u64,
                    ));
                }
            }
        }
        let mut solved = None;
        if let (Ok(()), Some(solver)) = (&res, &mut self.solver) {
            let per_iteration: Vec<usize> = ops
                .iter()
                .map(|o| o.0)
                .filter(|&m| !is_resident(m))
                .collect();
            let what = Readback {
                status: !per_iteration.is_empty(),
                x: per_iteration,
                report: iterating.clone(),
                fetch: fetching
                    .iter()
                    .chain(&with_iterate)
                    .chain(&multi)
                    .copied()
                    .collect(),
                hist: multi.iter().chain(&fast).copied().collect(),
                rwork: fast.clone(),
                extra,
            };
            let t0 = Instant::now();
            let npn = self.assembler.layout().nodes_per_slot as u64;
            let st = &mut self.serve_timers;
            st.resident_iterations += what.report.len() as u64;
            st.resident_bytes_down += 16 * what.report.len() as u64;
            st.fetches += fetching.len() as u64;
            st.iterates_sent += with_iterate.len() as u64;
            st.fetch_bytes_down += (72 * npn + 8) * (what.fetch.len() - multi.len()) as u64;
            // (Each history goes whole: `HSTRIDE` values, whatever its count.)
            let hist = 8 * crate::gpu::blocktri::HSTRIDE as u64;
            st.multi_bytes_down += (72 * npn + 8 + hist) * multi.len() as u64;
            st.device_step_bytes_down +=
                (hist + 8 + 8 * crate::gpu::layout::N_ADV as u64) * fast.len() as u64;
            match solver.read_back(&what, kept.take()) {
                Ok(s) => solved = Some(s),
                Err(e) => res = Err(e),
            }
            self.kernel.timers.bytes_down += solver.last_bytes_down;
            self.kernel.timers.bytes_up += std::mem::take(&mut solver.bytes_up);
            self.kernel.timers.copies += std::mem::take(&mut solver.copies_up);
            self.kernel.timers.readback_copies += solver.last_copies_down;
            // When every evaluated member is device-resident the assembly read nothing
            // back, so this read is where the wait for the passes happens: kernel time.
            let waited = t0.elapsed().as_secs_f64();
            if !pending.is_empty() && iterating.len() + multi.len() + fast.len() == pending.len() {
                let own = crate::gpu::driver::thread_cpu_s()
                    - crate::gpu::driver::driver_thread_s()
                    - span.1;
                let device_s = (span.0.elapsed().as_secs_f64() - own).max(0.0);
                self.kernel.timers.kernel_s = span.2 + device_s;
            } else {
                self.kernel.timers.readback_s += waited;
            }
        }
        if let Some(enc) = kept {
            crate::gpu::driver::submit(self.kernel.queue(), enc.finish());
        }
        let t0 = Instant::now();
        // Unpacking is per member and independent: in parallel.
        let (asm, sizes, device) = (&self.assembler, &self.sizes, &self.device);
        let npn = self.assembler.layout().nodes_per_slot;
        // Reports and iterates by slot (a slot posts one request per dispatch, so an
        // iterate read back belongs to its fetch or rides with its report).
        let mut report_of: Vec<Option<&Report>> = vec![None; sizes.len()];
        let mut iterate_of: Vec<Option<(&[f64], f64)>> = vec![None; sizes.len()];
        if let Some(s) = &solved {
            for (m, r) in &s.reports {
                report_of[*m] = Some(r);
            }
            for (m, q, rw) in s.iterates() {
                iterate_of[m] = Some((q, rw));
            }
        }
        // A fetched iterate's node rows (the member's own nodes of its slot).
        let rows = |q: &[f64], n_nodes: usize| -> Vec<[f64; 9]> {
            q[..9 * n_nodes]
                .chunks_exact(9)
                .map(|r| std::array::from_fn(|k| r[k]))
                .collect()
        };
        let (solved, report_of, iterate_of) = (&solved, &report_of, &iterate_of);
        let (multi_slot, multi_test) = (&multi_slot, &multi_test);
        answers.par_extend(pending.par_iter().filter(|p| !multi_slot[p.0]).map(
            |&(slot, tangent)| {
                let (n_elems, n_nodes) = sizes[slot];
                let out = match &res {
                    Ok(()) if is_resident(slot) => {
                        let iterate = iterate_of[slot].map(|(q, rw)| (rows(q, n_nodes), rw));
                        match report_of[slot] {
                            Some(r) => Ok(AssembledSystem {
                                resident: Some(resident_outcome(r, iterate)),
                                ..AssembledSystem::default()
                            }),
                            None => Err("the device did not report a resident iteration".into()),
                        }
                    }
                    Ok(()) if device[slot] => {
                        let mut sys = asm.system(slot, n_nodes, n_elems, false);
                        // (No status read back: this request did not ask the device to solve.)
                        sys.solution = solved.as_ref().filter(|s| !s.status.is_empty()).map(|s| {
                            let x = s.x.as_deref().unwrap_or(&[]);
                            device_outcome(
                                s.status[slot],
                                s.berr[slot],
                                &x[9 * npn * slot..9 * npn * (slot + 1)],
                                n_nodes,
                            )
                        });
                        Ok(sys)
                    }
                    Ok(()) => Ok(asm.system(slot, n_nodes, n_elems, tangent)),
                    Err(e) => Err(e.to_string()),
                };
                (slot, out)
            },
        ));
        answers.par_extend(fetching.par_iter().map(|&slot| {
            let n_nodes = sizes[slot].1;
            let out = match (&res, solved.as_ref()) {
                (Ok(()), Some(_)) => match iterate_of[slot] {
                    Some((q, residual_work)) => Ok(AssembledSystem {
                        resident: Some(ResidentAnswer::Fetched {
                            q: rows(q, n_nodes),
                            residual_work,
                        }),
                        ..AssembledSystem::default()
                    }),
                    None => Err("the device did not return a resident iterate".into()),
                },
                (Err(e), _) => Err(e.to_string()),
                (Ok(()), None) => Err("no device solver for a resident fetch".into()),
            };
            (slot, out)
        }));
        if repeats > 1 {
            // The device deactivated the element slots of the members it stopped: the
            // host's rows go back up with the next dispatch.
            // A step on the device sets them again itself in its next submission.
            let mut on_device = vec![false; self.sizes.len()];
            for &m in &fast {
                on_device[m] = true;
            }
            for &(slot, _) in &pending {
                if on_device[slot] {
                    self.device_stopped[slot] = true;
                } else {
                    let lo = slot * self.per_slot;
                    self.kernel.touch_iter(lo, lo + self.per_slot);
                }
            }
        }
        // Multi-iteration runs: each member's first iteration is answered now, the
        // others as its Newton loop asks for them.
        let hist_of: &[(usize, Vec<Report>, f64, f64)] = solved.as_ref().map_or(&[], |s| &s.hist);
        // Each slot's history, load work and support reaction work, by slot (a search per
        // member would be quadratic in them).
        let mut hist_at: Vec<Option<(&Vec<Report>, f64, f64)>> = vec![None; sizes.len()];
        for (m, reports, load_work, support) in hist_of {
            hist_at[*m] = Some((reports, *load_work, *support));
        }
        let hist_at = &hist_at;
        if !fast.is_empty() {
            let mut rec_of: Vec<Option<[f64; crate::gpu::layout::N_ADV]>> = vec![None; sizes.len()];
            let mut rw_of: Vec<f64> = vec![f64::NAN; sizes.len()];
            if let Some(s) = &solved {
                let mut at = 0usize;
                for &(lo, hi) in &fast_runs {
                    let n = hi - lo;
                    for (i, m) in (lo..hi).enumerate() {
                        rec_of[m] = s
                            .extra
                            .get(at..at + crate::gpu::layout::N_ADV * n)
                            .map(|v| std::array::from_fn(|k| v[k * n + i]));
                    }
                    at += crate::gpu::layout::N_ADV * n;
                }
                for &(m, w) in &s.rwork {
                    rw_of[m] = w;
                }
            }
            let (rec_of, rw_of) = (&rec_of, &rw_of);
            answers.par_extend(fast.par_iter().map(|&slot| {
                let out = match (&res, hist_at[slot], rec_of[slot]) {
                    (Err(e), _, _) => Err(e.to_string()),
                    (Ok(()), Some((reports, load_work, support)), Some(rec)) => {
                        Ok(AssembledSystem {
                            step: Some(DeviceStepAnswer {
                                iterations: reports
                                    .iter()
                                    .map(|r| {
                                        let ok = device_outcome(r.status, r.berr, &[], 0).is_ok();
                                        (r.residual, ok)
                                    })
                                    .collect(),
                                residual_work: rw_of[slot],
                                external_work: load_work,
                                support_reaction_work: support,
                                record: crate::gpu::kernel::MemberRecord::from_fields(&rec),
                            }),
                            ..AssembledSystem::default()
                        })
                    }
                    _ => Err("the device did not report the step".into()),
                };
                (slot, out)
            }));
            self.serve_timers.multi_iterations += fast
                .iter()
                .filter_map(|&m| hist_at[m])
                .map(|h| h.0.len() as u64)
                .sum::<u64>();
            for &m in &fast {
                if let Some(h) = hist_at[m] {
                    self.fast_need[m] = h.0.len();
                }
            }
        }
        let runs: Vec<(usize, Result<MultiRun, String>)> = multi
            .par_iter()
            .map(|&slot| {
                let run = match (&res, hist_at[slot]) {
                    (Err(e), _) => Err(e.to_string()),
                    (Ok(()), Some((reports, _, _))) if !reports.is_empty() => {
                        let res: Vec<f64> = reports.iter().map(|r| r.residual).collect();
                        let (last, before) = res.split_last().expect("not empty");
                        let (tol, quadratic) = multi_test[slot];
                        Ok(MultiRun {
                            reports: reports.clone(),
                            next: 0,
                            last: 0,
                            iterate: iterate_of[slot].map(|(q, rw)| (rows(q, sizes[slot].1), rw)),
                            accepted_last: run_accepts(before, *last, tol, quadratic),
                        })
                    }
                    _ => Err("the device did not report a resident iteration".into()),
                };
                (slot, run)
            })
            .collect();
        for (slot, run) in runs {
            match run {
                Ok(run) => {
                    self.serve_timers.multi_iterations += run.reports.len() as u64;
                    let mut run = run;
                    let first = run.reports[0];
                    run.next = 1;
                    answers.push((
                        slot,
                        Ok(AssembledSystem {
                            resident: Some(resident_outcome(&first, None)),
                            ..AssembledSystem::default()
                        }),
                    ));
                    self.multi[slot] = Some(run);
                }
                Err(e) => answers.push((slot, Err(e))),
            }
        }
        for &(slot, _) in &pending {
            self.active[slot] = true;
        }
        if !fast.is_empty() && fast.len() == pending.len() && fetching.is_empty() {
            self.steps_only = fast.len();
            let b = &mut self.serve_timers.device_step_bytes_up;
            b.0 += self.kernel.timers.bytes_up - up0;
            b.1 += fast.len() as u64;
        }
        self.kernel.timers.unpack_s += t0.elapsed().as_secs_f64();
        answers
    }

    /// `--solve whole`: `slot`'s member's element states on the device and its node
    /// increments (the saved ones: the predictor of its last device step), in one read.
    fn pull(&mut self, slot: usize, pull: Pull) -> Result<Pulled, GpuError> {
        let (n_elems, n_nodes) = self.sizes[slot];
        let lo = slot * self.per_slot;
        let npn = self.assembler.layout().nodes_per_slot as u64;
        let nn = self.sizes.len() as u64 * npn;
        let inc = match (&self.saved_increments, pull.saved) {
            (Some(b), true) => b.clone(),
            (None, true) => {
                return Err(GpuError::Kernel("no saved increments to hand back".into()))
            }
            _ => self.assembler.increments_buffer().clone(),
        };
        let mut copies = self.kernel.state_copies(lo, lo + n_elems);
        // A dissipative scheme's frozen scalars: those its last device step started from
        // (a hand-back), or those it ended with.
        let scalars = self.polish[slot];
        if scalars {
            copies.extend(self.kernel.scalar_copies(lo, lo + n_elems, pull.saved));
        }
        for k in 0..9u64 {
            copies.push((
                inc.clone(),
                8 * (k * nn + slot as u64 * npn),
                8 * n_nodes as u64,
            ));
        }
        let bytes: u64 = copies.iter().map(|c| c.2).sum();
        let v = self.kernel.read_f64(&copies)?;
        self.serve_timers.state_pulls += 1;
        self.serve_timers.device_step_handoffs += u64::from(pull.saved);
        self.serve_timers.pull_bytes_down += bytes;
        self.serve_timers.dispatches += 1;
        let (sv, rest) = v.split_at(crate::gpu::layout::NS * n_elems);
        let (fv, iv) = rest.split_at(if scalars { 4 * n_elems } else { 0 });
        Ok(Pulled {
            states: ElementKernel::states_from(sv, n_elems),
            scalars: (0..fv.len() / 4)
                .map(|e| crate::element::FrozenScalars {
                    beta_gamma: fv[e],
                    beta_omega: fv[n_elems + e],
                    c_v: fv[2 * n_elems + e],
                    c_nu: fv[3 * n_elems + e],
                })
                .collect(),
            increments: (0..n_nodes)
                .map(|j| std::array::from_fn(|k| iv[k * n_nodes + j]))
                .collect(),
        })
    }

    /// Serves every request posted by the attached members in one dispatch and answers
    /// each. Returns the number of requests served (0: nobody was waiting).
    ///
    /// `--solve resident`: requests that members' multi-iteration runs answer are answered
    /// without a dispatch; while there are such, the others wait (so that the members'
    /// next Newton solves start in one dispatch: one sync per step for the batch).
    pub fn serve(&mut self) -> usize {
        self.steps_only = 0;
        // Taking the requests and answering them is per member: in parallel.
        let reqs: Vec<(usize, EvalRequest)> = self
            .ports
            .par_iter()
            .enumerate()
            .filter_map(|(slot, p)| Some((slot, p.as_ref()?.take_request()?)))
            .collect();
        let mut n = reqs.len();
        let mut answered = 0usize;
        for (slot, req) in reqs {
            if let Some(pull) = req.pull {
                answered += 1;
                let a = self.pull(slot, pull).map_err(|e| e.to_string());
                if let Some(p) = &self.ports[slot] {
                    p.respond(a.map(|pulled| AssembledSystem {
                        pulled: Some(pulled),
                        ..AssembledSystem::default()
                    }));
                }
                continue;
            }
            match self.answer_from_run(slot, &req) {
                Some(a) => {
                    answered += 1;
                    if let Some(p) = &self.ports[slot] {
                        p.respond(a);
                    }
                }
                None => self.deferred.push((slot, req)),
            }
        }
        if answered == 0 && !self.deferred.is_empty() {
            let reqs = std::mem::take(&mut self.deferred);
            n += reqs.len();
            let answers = self.evaluate(reqs);
            let ports = &self.ports;
            answers.into_par_iter().for_each(|(slot, answer)| {
                if let Some(p) = &ports[slot] {
                    p.respond(answer);
                }
            });
        }
        n
    }
}

/// A [`GpuEvaluator`] behind a lock, as a synchronous [`ElementBackend`]: each call
/// evaluates one simulation's elements in its own dispatch (one simulation on the GPU;
/// batches use the lockstep driver, [`crate::batch::run_members`]).
pub struct GpuBatcher {
    inner: Mutex<GpuEvaluator>,
    adapter: String,
}

impl GpuBatcher {
    /// See [`GpuEvaluator::new`].
    pub fn new(
        ctx: &GpuContext,
        slots: usize,
        per_slot: usize,
        nodes_per_slot: usize,
    ) -> Result<Self, GpuError> {
        let ev = GpuEvaluator::new(ctx, slots, per_slot, nodes_per_slot)?;
        Ok(Self {
            adapter: ev.adapter.clone(),
            inner: Mutex::new(ev),
        })
    }

    fn lock(&self) -> MutexGuard<'_, GpuEvaluator> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// See [`GpuEvaluator::register`].
    pub fn register(&self, slot: usize, sim: &Simulation) -> Result<(), GpuError> {
        self.lock().register(slot, sim)
    }

    /// `--solve device`: builds the device block solver ([`GpuEvaluator::enable_device_solve`]).
    pub fn enable_device_solve(&self, ctx: &GpuContext) -> Result<(), GpuError> {
        self.lock().enable_device_solve(ctx)
    }

    /// Registers `sim` in `slot` and, with a device solver that covers it, switches it to
    /// device solves. Returns whether its systems are solved on the device; the reason
    /// when not is [`device_solve_refusal`].
    pub fn register_device(&self, slot: usize, sim: &mut Simulation) -> Result<bool, GpuError> {
        let mut g = self.lock();
        g.register(slot, sim)?;
        Ok(g.connect_device(slot, sim))
    }

    /// See [`GpuEvaluator::set_iterations_per_submission`].
    pub fn set_iterations_per_submission(&self, k: usize) {
        self.lock().set_iterations_per_submission(k)
    }

    /// See [`GpuEvaluator::set_device_advance`].
    pub fn set_device_advance(&self, on: bool) {
        self.lock().set_device_advance(on)
    }

    /// See [`GpuEvaluator::host_step_reasons`].
    pub fn host_step_reasons(&self) -> std::collections::BTreeMap<&'static str, u64> {
        self.lock().host_step_reasons.clone()
    }

    /// Layout of the assembled buffer.
    pub fn layout(&self) -> AsmLayout {
        self.lock().layout()
    }

    /// Stage timers and traffic so far.
    pub fn timers(&self) -> KernelTimers {
        self.lock().timers()
    }
}

impl ElementBackend for GpuBatcher {
    fn describe(&self) -> String {
        self.adapter.clone()
    }

    fn evaluate_assembled(&self, slot: usize, req: EvalRequest) -> Result<AssembledSystem, String> {
        self.lock()
            .evaluate(vec![(slot, req)])
            .pop()
            .map_or_else(|| Err("GPU batch lost the request".into()), |(_, r)| r)
    }
}
