//! Batches of independent simulations ("members"): the same [`Simulation`] step
//! (Newton, staggered/monolithic strategy, acceptance checks) per member, run either on
//! the CPU (members in parallel with rayon) or with the element kernel of all members
//! evaluated together on the GPU (`lockstep`).
//!
//! Every member has its own Newton convergence: a member that converged stops iterating
//! while others continue, a member whose step fails is recorded as failed and the batch
//! goes on. Results come back member by member as they finish.
//!
//! GPU path (lockstep, one host thread driving): each member's run is a future that
//! waits wherever its step posts an element evaluation. Per batch iteration the driver
//! polls every member in parallel (rayon: each member does its CPU work — scatter, LU
//! solve, convergence and acceptance checks — up to its next evaluation or its end), then
//! serves every posted request in one dispatch (element pass + assembly pass; only the
//! node blocks, residuals and scales come back, without the tangent for members that keep
//! theirs). Members that finish leave their slot to the next queued member (streaming),
//! so a sweep larger than the GPU's buffers flows through one batch. No OS thread per
//! member, no barrier.

pub mod gpu;
mod lockstep;

use std::convert::Infallible;
use std::sync::{mpsc, Arc};
use std::time::Instant;

use rayon::prelude::*;

use crate::gpu::kernel::KernelTimers;
use crate::gpu::{GpuContext, GpuError};
use crate::integrator::evaluate::now;
use crate::integrator::run::{run_async, RunOutcome};
use crate::integrator::state::State;
use crate::integrator::{IntegratorParams, NewtonVariant, Simulation};
use crate::model::Model;
use crate::observe::record::{RunStatus, StepRecord};
pub use gpu::{GpuBatcher, GpuEvaluator, ServeTimers};

/// One member of a batch: a model and its integrator parameters.
#[derive(Clone, Debug)]
pub struct Member {
    /// The problem.
    pub model: Model,
    /// Its time integration.
    pub params: IntegratorParams,
}

/// Which path evaluates the elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    /// CPU kernel, members in parallel (rayon).
    Cpu,
    /// GPU kernel (fails when no adapter with f64 exists).
    Gpu,
    /// GPU when an f64 adapter exists, else CPU (with a note saying so).
    Auto,
}

/// A resolved backend.
#[derive(Clone, Debug)]
pub enum Executor {
    /// CPU path.
    Cpu,
    /// GPU path on this device.
    Gpu(Arc<GpuContext>),
}

impl Executor {
    /// Resolves a choice: opens the adapter (`adapter`: name substring) for `Gpu`/`Auto`.
    /// Returns the executor and, for `Auto`, a note saying which path it chose and why.
    /// The batch integrator needs f64 (Newton to 1e-11): an adapter without `SHADER_F64`
    /// is an error for `Gpu` and a fallback for `Auto`. `Auto` never picks a software
    /// adapter (lavapipe, llvmpipe, WARP, SwiftShader: slower than the CPU path on the same
    /// cores) unless `adapter` names it.
    pub fn resolve(
        choice: BackendChoice,
        adapter: Option<&str>,
    ) -> Result<(Self, Option<String>), GpuError> {
        if choice == BackendChoice::Cpu {
            return Ok((Executor::Cpu, None));
        }
        let ctx = GpuContext::new(adapter).and_then(|c| {
            if !c.is_f64() {
                Err(GpuError::Device {
                    adapter: c.describe(),
                    reason: "the batch integrator needs SHADER_F64 (f32 cannot reach the Newton tolerance)".into(),
                })
            } else if choice == BackendChoice::Auto && adapter.is_none() && c.is_software() {
                Err(GpuError::Device {
                    adapter: c.describe(),
                    reason: "a software adapter runs on the CPU's own cores and is slower than the CPU path; name it with --adapter or use --backend gpu to use it anyway".into(),
                })
            } else {
                Ok(c)
            }
        });
        match (ctx, choice) {
            (Ok(c), BackendChoice::Auto) => {
                let note = format!("backend auto: using the GPU ({})", c.describe());
                Ok((Executor::Gpu(Arc::new(c)), Some(note)))
            }
            (Ok(c), _) => Ok((Executor::Gpu(Arc::new(c)), None)),
            (Err(e), BackendChoice::Auto) => Ok((
                Executor::Cpu,
                Some(format!("backend auto: using the CPU ({e})")),
            )),
            (Err(e), _) => Err(e),
        }
    }

    /// `cpu` or the adapter description.
    pub fn describe(&self) -> String {
        match self {
            Executor::Cpu => "cpu".into(),
            Executor::Gpu(c) => format!("gpu: {}", c.describe()),
        }
    }
}

/// What one member produced.
#[derive(Clone, Debug)]
pub struct MemberResult {
    /// Index of the member in the batch.
    pub index: usize,
    /// How its run ended (status, time reached, momentum drifts, Newton iterations…).
    pub outcome: RunOutcome,
    /// Every accepted level (only when histories were requested).
    pub history: Vec<StepRecord>,
    /// The state at the last accepted step (only when requested:
    /// [`BatchOptions::keep_state`]).
    pub state: Option<State>,
}

/// Options of a batch run.
#[derive(Clone, Copy, Debug, Default)]
pub struct BatchOptions {
    /// Keep every member's step records in [`MemberResult::history`].
    pub keep_history: bool,
    /// Keep every member's final state in [`MemberResult::state`].
    pub keep_state: bool,
    /// GPU path: slots (members in flight at once; the others wait in the queue and take
    /// the slot of a member that finished); 0 = as many as the adapter's buffer limits
    /// allow, at most [`DEFAULT_GPU_SLOTS`].
    pub workers: usize,
    /// Overrides every member's Newton variant when set.
    pub newton: Option<NewtonVariant>,
    /// Overrides every member's solver fallback when set.
    pub fallback: Option<bool>,
    /// Overrides every member's step cut-back when set (CPU path only; members on the
    /// GPU path do not cut back).
    pub cutback: Option<usize>,
    /// GPU path: where the Newton systems are solved (`--solve`).
    pub solve: SolveMode,
    /// `--solve device`: the host adds each Newton correction (read back with the residual
    /// rows every iteration) instead of the device keeping the iterate — the earlier
    /// shape of the device solve, kept for side-by-side comparison (`bench --host-update`).
    pub host_update: bool,
}

/// Where a GPU batch solves its members' Newton systems (`--solve host|device`,
/// docs/gpu.md "Device solve").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SolveMode {
    /// The host factorizes and solves each member's assembled system (default).
    #[default]
    Host,
    /// The device factorizes and solves the assembled systems (block-tridiagonal LU) and
    /// sends back the corrections instead of the blocks; members it does not cover are
    /// solved on the host within the same batch.
    Device,
    /// As [`Self::Device`], and the members with full or fresh Newton run up to
    /// [`RESIDENT_K`] Newton iterations per submission: the device stops each member where
    /// the host's Newton loop stops, and the host reads the iterations back once
    /// (docs/gpu.md, "Whole step on the device").
    Resident,
    /// As [`Self::Resident`], and the EM members it covers keep their state on the
    /// device: after each step the device advances it by the accepted iterate (the
    /// element passes' kinematics) instead of the host uploading it (docs/gpu.md, "Whole
    /// step on the device").
    Whole,
}

impl SolveMode {
    /// `host`, `device`, `resident` or `whole` (as on the command line and in
    /// `summary.json`).
    pub fn name(self) -> &'static str {
        match self {
            SolveMode::Host => "host",
            SolveMode::Device => "device",
            SolveMode::Resident => "resident",
            SolveMode::Whole => "whole",
        }
    }

    /// Whether members run several Newton iterations per submission (`resident`,
    /// `whole`).
    pub fn multi_iteration(self) -> bool {
        matches!(self, SolveMode::Resident | SolveMode::Whole)
    }

    /// Whether the device solves the Newton systems (`device`, `resident` or `whole`).
    pub fn on_device(self) -> bool {
        self != SolveMode::Host
    }
}

/// `--solve resident`: Newton iterations per submission (`COSSERAT_RESIDENT_K` overrides
/// it, 2–16, for measurements).
pub const RESIDENT_K: usize = 6;

/// [`RESIDENT_K`] or its override.
pub fn resident_k() -> usize {
    std::env::var("COSSERAT_RESIDENT_K")
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .map_or(RESIDENT_K, |k| {
            k.clamp(2, crate::gpu::blocktri::RESIDENT_MAX_K)
        })
}

/// Members in flight at once on the GPU path unless [`BatchOptions::workers`] says
/// otherwise (the adapter's buffer limits may allow fewer).
pub const DEFAULT_GPU_SLOTS: usize = 4096;

/// What the batch as a whole measured.
#[derive(Clone, Debug, Default)]
pub struct BatchStats {
    /// Wall time of the batch.
    pub wall_s: f64,
    /// GPU path: pipeline and buffer creation (shader compilation included).
    pub setup_s: f64,
    /// GPU stage timers (zero on the CPU path).
    pub gpu: KernelTimers,
    /// GPU path: host-side serving costs (packing requests).
    pub serve: ServeTimers,
    /// GPU path: wall time of the parallel member phases (every member's CPU work between
    /// two evaluations: scatter, factorization, solve, checks, bookkeeping).
    pub host_s: f64,
    /// GPU path: CPU time of the member polls themselves, summed over the threads that
    /// ran them (the member phase's work without the pool's idle and wake-up time that
    /// [`Self::host_s`] × threads also counts).
    pub member_cpu_s: f64,
    /// GPU path: member polls (one per member and batch iteration).
    pub polls: u64,
    /// GPU path: batch iterations (parallel member phase + one dispatch).
    pub iterations: u64,
    /// GPU path: CPU time of the driver thread serving the dispatches (taking requests,
    /// uploads, encoding, submission, read-back, answers; not the time it waits for the
    /// device, nor the parallel packing and unpacking it hands to the rayon pool): the
    /// sequential host share of a batch iteration.
    pub serve_thread_s: f64,
    /// GPU path: of [`Self::serve_thread_s`], the part inside the graphics driver's
    /// submissions and waits ([`crate::gpu::driver`]): on a software adapter the
    /// device's own work, run on the driver thread.
    pub serve_driver_s: f64,
    /// GPU path: members in flight at once (slots).
    pub slots: usize,
    /// Simulation set-up (linear solver analysis, GPU registration), wall time.
    pub admit_s: f64,
    /// `--solve device`: members solved on the device, and members solved on the host
    /// because the device solver does not cover them.
    pub device_members: (u64, u64),
    /// `--solve whole`: members whose steps ran on the host (each Newton solve on the
    /// device), by the reason the device step does not cover them.
    pub host_step_reasons: std::collections::BTreeMap<String, u64>,
    /// `--solve whole`: per batch iteration whose dispatch served device steps only and
    /// followed one that did too, every member polled among them (the steady state: each
    /// member's poll takes its last device step's answer and posts its next one), the
    /// host's own CPU time per device step in µs: the member polls' and the serving
    /// thread's, outside the graphics driver's submissions and waits.
    pub device_step_host_us: Vec<f64>,
    /// Of [`Self::device_step_host_us`], per the same batch iteration: the serving
    /// thread's share.
    pub device_step_serve_us: Vec<f64>,
    /// Per the same batch iteration: the host's wall time on the step's critical path in
    /// µs, the member phase plus the dispatch outside the graphics driver's submissions
    /// and waits (the device idles meanwhile, on any adapter).
    pub device_step_critical_us: Vec<f64>,
}

fn setup_failure(e: impl std::fmt::Display) -> RunOutcome {
    RunOutcome {
        status: RunStatus::Failed,
        t_reached: 0.0,
        steps: 0,
        reason: Some(format!("setup failed: {e}")),
        failed_step_residuals: vec![],
        newton_iters_total: 0,
        max_rel_dl: 0.0,
        max_rel_dj: 0.0,
        energy_initial: f64::NAN,
        energy_final: f64::NAN,
        wall_s: 0.0,
        max_link_g: 0.0,
        timers: Default::default(),
        fallback_steps: 0,
        accepted: Default::default(),
        cutback_steps: 0,
        smallest_substep: None,
    }
}

/// A member's simulation, set up (or why it could not be).
fn setup(m: &Member, opts: BatchOptions) -> Result<Simulation, String> {
    let mut params = m.params;
    if let Some(v) = opts.newton {
        params.newton = v;
    }
    if let Some(f) = opts.fallback {
        params.fallback = f;
    }
    if let Some(n) = opts.cutback {
        params.cutback = n;
    }
    Simulation::new(m.model.clone(), params).map_err(|e| e.to_string())
}

/// Runs one member's simulation to its end time (a future: on the GPU path it waits on
/// the lockstep driver at every element evaluation).
async fn run_member(index: usize, mut sim: Simulation, opts: BatchOptions) -> MemberResult {
    let mut history = Vec::new();
    let outcome = run_async(&mut sim, 1, |rec: &StepRecord, _: &Simulation| {
        if opts.keep_history {
            history.push(rec.clone());
        }
        Ok::<(), Infallible>(())
    })
    .await
    .unwrap_or_else(|e| match e {});
    // `--solve whole`: the state comes back from the device for the result only.
    let synced = !opts.keep_state || sim.sync_device_state().await.is_ok();
    MemberResult {
        index,
        outcome,
        history,
        state: (opts.keep_state && synced).then(|| sim.state().clone()),
    }
}

/// Runs every member; `on_done` sees each result on the calling thread as soon as the
/// member finishes (in completion order).
pub fn run_members(
    members: &[Member],
    exec: &Executor,
    opts: BatchOptions,
    mut on_done: impl FnMut(MemberResult),
) -> Result<BatchStats, GpuError> {
    let start = Instant::now();
    let mut stats = match exec {
        Executor::Cpu => {
            let (tx, rx) = mpsc::channel::<MemberResult>();
            std::thread::scope(|sc| {
                sc.spawn(move || {
                    members
                        .par_iter()
                        .enumerate()
                        .for_each_with(tx, |tx, (i, m)| {
                            let r = match setup(m, opts) {
                                Ok(sim) => now(run_member(i, sim, opts)),
                                Err(e) => MemberResult {
                                    index: i,
                                    outcome: setup_failure(e),
                                    history: vec![],
                                    state: None,
                                },
                            };
                            let _ = tx.send(r);
                        });
                });
                for r in rx {
                    on_done(r);
                }
            });
            BatchStats::default()
        }
        Executor::Gpu(ctx) => lockstep::run(members, ctx, opts, &mut on_done)?,
    };
    stats.wall_s = start.elapsed().as_secs_f64();
    Ok(stats)
}

/// The benchmark batch of `cosserat bench`: `rods` clamped 3D cantilevers of `elements`
/// elements each (the built-in `cantilever` scene's rod and section), EDMC-2 α = 0.5
/// (the default strategy), Δt = 0.01, `steps` steps, each member's tip kicked with a different speed
/// (so the members need different Newton iteration counts, as in a real sweep).
///
/// An error (never another size than asked) when the scene with `elements` elements does
/// not build.
pub fn bench_members(
    rods: usize,
    elements: usize,
    steps: usize,
) -> Result<Vec<Member>, crate::scene::SceneError> {
    let text = crate::scene::builtin_scenes()
        .iter()
        .find(|b| b.name == "cantilever")
        .expect("the built-in cantilever scene exists")
        .toml
        .replace("elements = 50", &format!("elements = {}", elements.max(1)));
    let scene = crate::scene::parse_scene(&text, "builtin:cantilever")?;
    assert_eq!(
        scene.model.elements.len(),
        elements.max(1),
        "the benchmark cantilever's element count is its `elements = 50` line"
    );
    let mut params = scene.params;
    params.scheme = crate::integrator::Scheme::edmc2(0.5);
    params.dt = 0.01;
    params.t_end = steps as f64 * params.dt;
    Ok((0..rods)
        .map(|i| {
            let mut model = scene.model.clone();
            let s = 0.5 + (i % 16) as f64 / 16.0;
            model.velocity0.iter_mut().for_each(|v| *v *= s);
            Member { model, params }
        })
        .collect())
}
