//! Where the element kernel runs for frozen-scalar assembly. By default the CPU kernel, in
//! line. A simulation can instead hand its elements to an evaluator outside it, two ways:
//!
//! * **direct** ([`ElementBackend`], attached with
//!   [`crate::integrator::Simulation::set_backend`]): the call evaluates and returns at
//!   once (one simulation on a GPU, `run --backend gpu`);
//! * **lockstep** ([`EvalPort`]): the simulation posts an [`EvalRequest`] and *awaits*
//!   the answer. Its step is an `async fn`; a batch driver ([`crate::batch`]) polls every
//!   member until each is waiting, serves all posted requests in one dispatch, and polls
//!   again. The Newton loop, strategies and acceptance checks are the same code on every
//!   path: only this await point differs.
//!
//! Either way the evaluator returns the elements already summed per node
//! ([`AssembledSystem`]).

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll, Waker};

use nalgebra::Vector6;

use crate::element::{ElementState, FrozenScalars};

/// What the kernel needs per element besides the run constants registered beforehand
/// (the Newton increment comes per node).
#[derive(Clone, Copy, Debug)]
pub struct ElementInput {
    /// State at `n`.
    pub st: ElementState,
    /// Raw strains at `n`.
    pub eps_n: Vector6<f64>,
    /// Frozen dissipation scalars.
    pub s: FrozenScalars,
}

/// One evaluation of a simulation's elements (frozen scalars), as posted to an evaluator.
#[derive(Clone, Debug, Default)]
pub struct EvalRequest {
    /// Per element: state at `n` and raw strains at `n`. Sent only when they changed
    /// since this simulation's last request (once per step); `None` means "as before".
    pub states: Option<Vec<(ElementState, Vector6<f64>)>>,
    /// `--solve whole` (with `states` `None`): the state changed by the step that
    /// accepted the iterate this simulation's last evaluation evaluated; the evaluator
    /// advances its copy of the state by that iterate (the same kinematics) instead.
    pub advance: bool,
    /// Per element: the frozen dissipation scalars.
    pub scalars: Vec<FrozenScalars>,
    /// Evaluate with the scalars consistent with the increment instead of `scalars`, the
    /// tangent without their linearization (the inexact strategy's iterations).
    pub consistent: bool,
    /// Per node: the Newton increment in node-local order `u0..2 θ0..2 g0..2` (zero for
    /// removed unknowns).
    pub increments: Vec<[f64; 9]>,
    /// Whether the tangent blocks are wanted (else residual rows and scales only).
    pub tangent: bool,
    /// Device solve (`--solve device`): the evaluator also solves `K x = −(R + extra)`
    /// with the assembled tangent `K` (factorized when `tangent`, else the factors it kept
    /// from this member's last tangent) and answers the solution instead of the blocks.
    /// Per node: `extra`, the host's nodal residual terms (loads, moments) in node-local
    /// order. `None`: the host solves. Empty: as in this member's previous request (the
    /// later requests of a device-resident Newton solve, whose nodal terms are constant).
    pub device_extra: Option<Vec<[f64; 9]>>,
    /// Per element, the follower line loads the kernel adds (force and moment per unit
    /// length in the element's director frame, their tables' factors at the step's middle
    /// included), where they changed since this member's last request; `None`: unchanged.
    pub follower: Option<Vec<[f64; 6]>>,
    /// Device-resident Newton (with `device_extra`): the device keeps the increment, adds
    /// its own correction after the solve and answers the relative residual only
    /// ([`ResidentAnswer`]). `None`: the host keeps the increment.
    pub resident: Option<Resident>,
    /// `--solve whole`, a member's whole step on the device ([`DeviceStep`]); the answer
    /// is [`AssembledSystem::step`]. With `advance` set (the device advances its state by
    /// the step accepted last first); nothing else of the request is read.
    pub device_step: Option<DeviceStep>,
    /// `--solve whole`: no evaluation; hand the member's state on the device back
    /// ([`AssembledSystem::pulled`]).
    pub pull: Option<Pull>,
    /// With `device_step`: the driven supports' prescribed increments over this step, one
    /// per removed translation or rotation unknown of a driven node (the device's copy of
    /// those unknowns is set to them before its first iteration; only changed values
    /// cross the bus).
    pub prescribed: Vec<Prescribed>,
}

/// A removed unknown's prescribed increment over a step ([`EvalRequest::prescribed`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prescribed {
    /// The node (in the member's node order).
    pub node: usize,
    /// The node-local row: 0..3 translation, 3..6 rotation.
    pub row: usize,
    /// The increment.
    pub value: f64,
}

/// A whole step on the device ([`EvalRequest::device_step`]): Newton from the device's
/// own iterate (the last step's increment: the predictor) with the member's Newton test,
/// then the records of the iterate it stopped at, the state at `n` kept.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceStep {
    /// The row scales (u, θ, g) of the host's nodal terms (as in [`Resident::scale`]).
    pub scale: [f64; 3],
}

/// Which increments a state hand-back brings ([`EvalRequest::pull`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pull {
    /// The increments the device held at the start of its last step (that step's
    /// predictor; its Newton solve failed) instead of its current ones (the last accepted
    /// step's).
    pub saved: bool,
}

/// The answer to a [`DeviceStep`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeviceStepAnswer {
    /// Per Newton iteration the device ran: the relative residual of the evaluated
    /// iterate and whether its solve succeeded.
    pub iterations: Vec<(f64, bool)>,
    /// `Σ |R_i q_i|` at the last evaluated iterate (the energy check's residual work).
    pub residual_work: f64,
    /// The work of the dead loads (nodal loads, dead line loads, gravity) over the step at that iterate:
    /// `Σ F·u + M·θ` with the loads the device holds (the host's at the middle of the
    /// step where they have not changed since they went up).
    pub external_work: f64,
    /// `Σ R_i q_i` over the removed translation and rotation unknowns at that iterate, with
    /// `R` the element passes' rows alone (elements, point masses, drag, follower loads):
    /// the driven supports' work less that of the loads the host applies at their nodes
    /// (zero without a prescribed increment).
    pub support_reaction_work: f64,
    /// The records of the step to that iterate (the state at `n+1` is not formed).
    pub record: MemberRecord,
}

/// A member's state handed back by the device ([`EvalRequest::pull`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Pulled {
    /// Per element: its state and raw strains at the device's level.
    pub states: Vec<(ElementState, Vector6<f64>)>,
    /// Per node: the increments ([`Pull::saved`]), node-local order.
    pub increments: Vec<[f64; 9]>,
    /// Per element, for a dissipative scheme (empty otherwise): the frozen scalars its
    /// last device step started from ([`Pull::saved`]), or those it ended with.
    pub scalars: Vec<FrozenScalars>,
}

/// A device-resident Newton request ([`EvalRequest::resident`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Resident {
    /// The request's increments are the host's (the start of a Newton solve): the device
    /// starts from them. Otherwise it iterates from its own and `increments` is empty.
    pub upload: bool,
    /// Before evaluating, go back to the iterate before the device's last correction
    /// (modified Newton undoing a correction made with a kept tangent).
    pub restore: bool,
    /// The host's row scales (u, θ, g) of its nodal terms (they join the element scales
    /// in the relative residual).
    pub scale: [f64; 3],
    /// No evaluation: answer the iterate evaluated last before the device's last correction
    /// (the one the host accepted) and its residual work ([`ResidentAnswer::Fetched`]).
    pub fetch: bool,
    /// The host expects to accept this iterate (full Newton's quadratic prediction, as the
    /// CPU path's tangent skip): evaluate the residual only, neither factorize nor solve
    /// nor update, and send the iterate back with the report
    /// ([`ResidentAnswer::Iterated::iterate`]), which saves the fetch's round trip.
    pub predict_accept: bool,
    /// Send the evaluated iterate back with the report even though it is solved and
    /// updated as usual (the host may accept it: a speculative fetch, 72 bytes per node,
    /// that saves a round trip when it does).
    pub send_iterate: bool,
}

/// The answer to a device-resident request.
#[derive(Clone, Debug, PartialEq)]
pub enum ResidentAnswer {
    /// An iteration: the relative residual `max_i |R_i| / scale(kind of i)` of the iterate
    /// evaluated, and the outcome of the solve (on success the device added the
    /// correction to its iterate; the error is the host solver's message).
    Iterated {
        /// Relative residual of the evaluated iterate.
        residual: f64,
        /// The device solve's outcome.
        solve: Result<(), String>,
        /// With [`Resident::predict_accept`] or [`Resident::send_iterate`]: the evaluated
        /// iterate per node and its residual work.
        iterate: Option<(Vec<[f64; 9]>, f64)>,
    },
    /// A fetch: the accepted iterate per node (node-local order) and `Σ |R_i q_i|` there.
    Fetched {
        /// Per node: the increment.
        q: Vec<[f64; 9]>,
        /// The residual work of the energy check.
        residual_work: f64,
    },
}

/// The answer of a device solve: the Newton correction per node (node-local order,
/// zero for removed unknowns), or why the solve failed (the message of the host
/// solver's error for the same failure).
pub type DeviceSolution = Result<Vec<[f64; 9]>, String>;

/// The element contributions of one simulation summed into its block system, in
/// node-local order `u0..2 θ0..2 g0..2` (removed unknowns included; the caller skips them).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AssembledSystem {
    /// Per node: the sum of its incident elements' residual rows.
    pub node_r: Vec<[f64; 9]>,
    /// Per node: its diagonal 9×9 block (row-major), the sum of its incident elements'
    /// (l, l) sub-blocks. Empty without the tangent.
    pub node_k: Vec<[f64; 81]>,
    /// Per element: its off-diagonal blocks (end 0, end 1) and (end 1, end 0), row-major.
    /// Empty without the tangent.
    pub off_k: Vec<[[f64; 81]; 2]>,
    /// Largest element row scale of each kind (u, θ, g) over the rows that are unknowns.
    pub scale: [f64; 3],
    /// The solution of a device solve ([`EvalRequest::device_extra`]); then the blocks
    /// are left empty.
    pub solution: Option<DeviceSolution>,
    /// The answer to a device-resident request ([`EvalRequest::resident`]); then the
    /// residual rows and blocks are left empty.
    pub resident: Option<ResidentAnswer>,
    /// The answer to a [`DeviceStep`].
    pub step: Option<DeviceStepAnswer>,
    /// The answer to a [`Pull`].
    pub pulled: Option<Pulled>,
}

/// Evaluates all elements of one simulation at once (frozen scalars), synchronously.
pub trait ElementBackend: Send + Sync {
    /// Assembled residual, row scales and (if `req.tangent`) blocks of the elements of
    /// the simulation in `slot`. An error fails the Newton solve (the step is rejected).
    fn evaluate_assembled(&self, slot: usize, req: EvalRequest) -> Result<AssembledSystem, String>;

    /// Where the elements are evaluated, for every output (e.g. `gpu: ADAPTER, f64`).
    fn describe(&self) -> String;
}

#[derive(Debug, Default)]
struct Exchange {
    request: Option<EvalRequest>,
    response: Option<Result<AssembledSystem, String>>,
}

/// A simulation's mailbox at a lockstep batch driver: the simulation posts a request and
/// awaits; the driver takes every posted request ([`Self::take_request`]), evaluates them
/// together and answers each ([`Self::respond`]).
#[derive(Clone, Debug)]
pub struct EvalPort {
    inner: Arc<Mutex<Exchange>>,
    describe: Arc<str>,
}

impl EvalPort {
    /// A new, empty mailbox; `describe` names the evaluator in every output.
    pub fn new(describe: &str) -> Self {
        Self {
            inner: Arc::default(),
            describe: describe.into(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Exchange> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The evaluator's description.
    pub fn describe(&self) -> &str {
        &self.describe
    }

    /// Driver side: the posted request, if the simulation is waiting on one.
    pub fn take_request(&self) -> Option<EvalRequest> {
        self.lock().request.take()
    }

    /// Driver side: answers the request taken last.
    pub fn respond(&self, r: Result<AssembledSystem, String>) {
        self.lock().response = Some(r);
    }

    /// Simulation side: posts `req` and waits until the driver has answered it.
    pub(crate) async fn evaluate(&self, req: EvalRequest) -> Result<AssembledSystem, String> {
        {
            let mut g = self.lock();
            g.response = None;
            g.request = Some(req);
        }
        Answer(self).await
    }
}

/// Ready once the driver has answered.
struct Answer<'a>(&'a EvalPort);

impl Future for Answer<'_> {
    type Output = Result<AssembledSystem, String>;
    fn poll(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Self::Output> {
        match self.0.lock().response.take() {
            Some(r) => Poll::Ready(r),
            None => Poll::Pending,
        }
    }
}

/// Polls `fut` once (a batch driver polls again after serving the posted requests; no
/// waker is needed since the driver knows when it answered).
pub fn poll_once<F: Future + ?Sized>(fut: Pin<&mut F>) -> Poll<F::Output> {
    fut.poll(&mut Context::from_waker(Waker::noop()))
}

/// Runs `fut` to completion when it never waits on a lockstep driver (the CPU kernel or a
/// direct backend).
///
/// # Panics
/// If the future waits: a simulation attached to a lockstep [`EvalPort`] must be stepped
/// by its batch driver, not through the synchronous API.
pub fn now<F: Future>(fut: F) -> F::Output {
    let mut fut = std::pin::pin!(fut);
    match poll_once(fut.as_mut()) {
        Poll::Ready(x) => x,
        Poll::Pending => panic!(
            "a simulation attached to a lockstep batch evaluator must be stepped by its batch driver"
        ),
    }
}

/// One member slot's record of an advanced step (the GPU advance pass): the
/// sums over its element slots, in element order, of their terms of the invariants at
/// `n+1` ([`crate::integrator::invariants::Invariants`] without links, point masses and
/// contact) and of their dissipation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MemberRecord {
    /// Kinetic energy.
    pub kinetic: f64,
    /// Strain energy.
    pub potential: f64,
    /// Linear momentum.
    pub l: crate::model::Vec3,
    /// Angular momentum about the origin.
    pub j: crate::model::Vec3,
    /// Predicted dissipation of the step.
    pub dissipation: f64,
    /// The sums under the square roots of the step's acceleration norms (translational,
    /// rotational: [`crate::integrator::invariants::acceleration_norms`]).
    pub acc_sums: [f64; 2],
    /// Sum over the elements of how far the cosine of the turn between their end triads
    /// lies below the limit's (positive: some element turned too far).
    pub turn: f64,
    /// Work of the follower line loads over the step (`Σ F·u + M·θ`).
    pub follower_work: f64,
}

impl MemberRecord {
    /// The record from its fields, in this order (the advance pass's layout).
    pub fn from_fields(r: &[f64]) -> Self {
        MemberRecord {
            kinetic: r[0],
            potential: r[1],
            l: crate::model::Vec3::new(r[2], r[3], r[4]),
            j: crate::model::Vec3::new(r[5], r[6], r[7]),
            dissipation: r[8],
            acc_sums: [r[9], r[10]],
            turn: r[11],
            follower_work: r[12],
        }
    }
}
