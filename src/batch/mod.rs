//! Batches of independent simulations ("members"): the same [`Simulation`] step
//! (Newton, staggered/monolithic strategy, acceptance checks) per member, run either on
//! the CPU (members in parallel with rayon) or with the element kernel of all members
//! evaluated together on the GPU ([`gpu::GpuBatcher`]).
//!
//! Every member has its own Newton convergence: a member that converged stops iterating
//! while others continue, a member whose step fails is recorded as failed and the batch
//! goes on. Results come back member by member as they finish.
//!
//! GPU path, per Newton iteration of the batch: each member gathers its element inputs
//! (state at `n`, increment, frozen scalars), one dispatch evaluates every element of
//! every waiting member and a second pass sums them into each member's block system (node
//! diagonal blocks, element off-diagonal blocks, nodal residuals, row-scale maxima); only
//! that comes back (without the tangent: residuals and scales only). Each member scatters
//! its blocks into its own sparse system and solves it on its own worker thread (CPU). A
//! member's state is uploaded only when it changed (once per step, that member's ranges
//! only); the increments of the waiting members every iteration.

pub mod gpu;

use std::convert::Infallible;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Instant;

use rayon::prelude::*;

use crate::gpu::kernel::KernelTimers;
use crate::gpu::{GpuContext, GpuError};
use crate::integrator::run::{run, RunOutcome};
use crate::integrator::{IntegratorParams, Simulation};
use crate::model::Model;
use crate::observe::record::{RunStatus, StepRecord};
pub use gpu::GpuBatcher;

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
    /// Returns the executor and, for `Auto` falling back, a note saying why. The batch
    /// integrator needs f64 (Newton to 1e-11): an adapter without `SHADER_F64` is an error
    /// for `Gpu` and a fallback for `Auto`.
    pub fn resolve(
        choice: BackendChoice,
        adapter: Option<&str>,
    ) -> Result<(Self, Option<String>), GpuError> {
        if choice == BackendChoice::Cpu {
            return Ok((Executor::Cpu, None));
        }
        let ctx = GpuContext::new(adapter).and_then(|c| {
            if c.is_f64() {
                Ok(c)
            } else {
                Err(GpuError::Device {
                    adapter: c.describe(),
                    reason: "the batch integrator needs SHADER_F64 (f32 cannot reach the Newton tolerance)".into(),
                })
            }
        });
        match (ctx, choice) {
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
}

/// Options of a batch run.
#[derive(Clone, Copy, Debug, Default)]
pub struct BatchOptions {
    /// Keep every member's step records in [`MemberResult::history`].
    pub keep_history: bool,
    /// GPU path: worker threads (members in flight at once); 0 = all members, capped by
    /// the adapter's buffer limit and 4096.
    pub workers: usize,
    /// Modified Newton (tangent reuse, [`Simulation::set_modified_newton`]).
    pub modified_newton: bool,
}

/// What the batch as a whole measured.
#[derive(Clone, Copy, Debug, Default)]
pub struct BatchStats {
    /// Wall time of the batch.
    pub wall_s: f64,
    /// GPU path: pipeline and buffer creation (shader compilation included).
    pub setup_s: f64,
    /// GPU stage timers (zero on the CPU path).
    pub gpu: KernelTimers,
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
    }
}

/// Runs one member to its end time, optionally on a GPU slot.
fn run_member(
    index: usize,
    m: &Member,
    opts: BatchOptions,
    gpu: Option<(&Arc<GpuBatcher>, usize)>,
) -> MemberResult {
    let keep_history = opts.keep_history;
    let mut sim = match Simulation::new(m.model.clone(), m.params) {
        Ok(s) => s,
        Err(e) => {
            return MemberResult {
                index,
                outcome: setup_failure(e),
                history: vec![],
            }
        }
    };
    sim.set_modified_newton(opts.modified_newton);
    // Baseline schemes have no GPU kernel: such a member runs on the CPU kernel and never
    // joins the batcher (whose barrier waits only for registered members).
    if let Some((b, slot)) = gpu.filter(|_| m.params.scheme.has_gpu_kernel()) {
        if let Err(e) = b.register(slot, &sim) {
            return MemberResult {
                index,
                outcome: setup_failure(e),
                history: vec![],
            };
        }
        let _ = sim.set_backend(b.clone(), slot);
    }
    let mut history = Vec::new();
    let outcome = run(&mut sim, 1, |rec: &StepRecord, _: &Simulation| {
        if keep_history {
            history.push(rec.clone());
        }
        Ok::<(), Infallible>(())
    })
    .unwrap_or_else(|e| match e {});
    MemberResult {
        index,
        outcome,
        history,
    }
}

/// Decrements the batcher's live count when a worker ends (also on panic).
struct Leave<'a>(&'a GpuBatcher);
impl Drop for Leave<'_> {
    fn drop(&mut self) {
        self.0.leave();
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
    let (tx, rx) = mpsc::channel::<MemberResult>();
    let mut stats = BatchStats::default();
    match exec {
        Executor::Cpu => std::thread::scope(|sc| {
            sc.spawn(move || {
                members
                    .par_iter()
                    .enumerate()
                    .for_each_with(tx, |tx, (i, m)| {
                        let _ = tx.send(run_member(i, m, opts, None));
                    });
            });
            for r in rx {
                on_done(r);
            }
        }),
        Executor::Gpu(ctx) => {
            let per_slot = members
                .iter()
                .map(|m| m.model.elements.len())
                .max()
                .unwrap_or(1)
                .max(1);
            let nodes_per_slot = members
                .iter()
                .map(|m| m.model.n_nodes())
                .max()
                .unwrap_or(1)
                .max(1);
            let cap = GpuBatcher::max_slots(ctx, per_slot, nodes_per_slot).clamp(1, 4096);
            let want = if opts.workers == 0 {
                members.len()
            } else {
                opts.workers
            };
            let workers = want.min(cap).min(members.len()).max(1);
            let t0 = Instant::now();
            let batcher = Arc::new(GpuBatcher::new(ctx, workers, per_slot, nodes_per_slot)?);
            stats.setup_s = t0.elapsed().as_secs_f64();
            let next = AtomicUsize::new(0);
            std::thread::scope(|sc| {
                for slot in 0..workers {
                    let tx = tx.clone();
                    let (batcher, next) = (&batcher, &next);
                    std::thread::Builder::new()
                        .stack_size(4 << 20)
                        .spawn_scoped(sc, move || {
                            let _leave = Leave(batcher);
                            loop {
                                let i = next.fetch_add(1, Ordering::Relaxed);
                                if i >= members.len() {
                                    break;
                                }
                                let r = run_member(i, &members[i], opts, Some((batcher, slot)));
                                let _ = tx.send(r);
                            }
                        })
                        .expect("cannot spawn a batch worker thread");
                }
                drop(tx);
                for r in rx {
                    on_done(r);
                }
            });
            stats.gpu = batcher.timers();
        }
    }
    stats.wall_s = start.elapsed().as_secs_f64();
    Ok(stats)
}

/// The benchmark batch of `cosserat bench`: `rods` clamped 3D cantilevers of `elements`
/// elements each (the built-in `cantilever` scene's rod and section), EDMC-2 α = 0.5,
/// staggered, Δt = 0.01, `steps` steps, each member's tip kicked with a different speed
/// (so the members need different Newton iteration counts, as in a real sweep).
pub fn bench_members(rods: usize, elements: usize, steps: usize) -> Vec<Member> {
    let base = crate::scene::load_scene("cantilever").expect("built-in scene");
    let text = crate::scene::builtin_scenes()
        .iter()
        .find(|b| b.name == "cantilever")
        .expect("built-in scene")
        .toml
        .replace("elements = 50", &format!("elements = {}", elements.max(1)));
    let scene = crate::scene::parse_scene(&text, "builtin:cantilever").unwrap_or(base);
    let mut params = scene.params;
    params.scheme = crate::integrator::Scheme::edmc2(0.5);
    params.dt = 0.01;
    params.t_end = steps as f64 * params.dt;
    (0..rods)
        .map(|i| {
            let mut model = scene.model.clone();
            let s = 0.5 + (i % 16) as f64 / 16.0;
            model.velocity0.iter_mut().for_each(|v| *v *= s);
            Member { model, params }
        })
        .collect()
}
