//! The lockstep GPU batch driver: one host thread advances every member in flight
//! evaluation by evaluation.
//!
//! Each batch iteration:
//! 1. **admit**: free slots take the next queued members (their simulations are set up in
//!    parallel, then registered on the GPU evaluator);
//! 2. **member phase**: every member in flight is polled once, in parallel (rayon). A poll
//!    runs that member's own CPU work — scatter of its last answer, factorization, solve,
//!    convergence, staggered-loop and acceptance bookkeeping, observers — up to its next
//!    element evaluation (posted to its mailbox) or to the end of its run;
//! 3. **retire**: finished members report and leave their slot;
//! 4. **serve**: every posted request goes into one dispatch (element and assembly
//!    passes) and each member gets its answer.
//!
//! A member whose scheme has no GPU kernel runs on the CPU kernel within its first poll.

use std::future::Future;
use std::pin::Pin;
use std::task::Poll;
use std::time::Instant;

use rayon::prelude::*;

use super::gpu::GpuEvaluator;
use super::{run_member, setup, setup_failure, BatchOptions, BatchStats, Member, MemberResult};
use crate::gpu::driver::{driver_thread_s, driver_wall_s, thread_cpu_s};
use crate::gpu::{GpuContext, GpuError};
use crate::integrator::evaluate::poll_once;

type MemberFuture<'a> = Pin<Box<dyn Future<Output = MemberResult> + Send + 'a>>;

/// A member in flight.
struct InFlight<'a> {
    /// Its GPU slot (`None`: runs on the CPU kernel, holds no slot).
    slot: Option<usize>,
    run: MemberFuture<'a>,
    done: Option<MemberResult>,
}

/// Runs `members` on `ctx` in lockstep; `on_done` sees each result as its member finishes.
pub(super) fn run(
    members: &[Member],
    ctx: &GpuContext,
    opts: BatchOptions,
    on_done: &mut dyn FnMut(MemberResult),
) -> Result<BatchStats, GpuError> {
    let mut stats = BatchStats::default();
    if members.is_empty() {
        return Ok(stats);
    }
    // A feature the kernels do not implement refuses the whole batch, by name, before
    // anything runs (members of schemes without a GPU kernel run on the CPU anyway).
    if let Some(feature) = members
        .iter()
        .filter(|m| m.params.scheme.has_gpu_kernel())
        .find_map(|m| m.model.gpu_unsupported())
    {
        return Err(GpuError::Unsupported {
            feature: feature.into(),
        });
    }
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
    let cap = GpuEvaluator::max_slots(ctx, per_slot, nodes_per_slot).max(1);
    let want = if opts.workers == 0 {
        super::DEFAULT_GPU_SLOTS
    } else {
        opts.workers
    };
    let slots = want.min(cap).min(members.len()).max(1);
    let t0 = Instant::now();
    let mut gpu = GpuEvaluator::new(ctx, slots, per_slot, nodes_per_slot)?;
    if opts.solve.on_device() {
        gpu.enable_device_solve(ctx)?;
        gpu.set_resident(!opts.host_update);
        if opts.solve.multi_iteration() {
            gpu.set_iterations_per_submission(super::resident_k());
        }
        gpu.set_device_advance(opts.solve == super::SolveMode::Whole);
    }
    stats.setup_s = t0.elapsed().as_secs_f64();
    stats.slots = slots;

    let mut free: Vec<usize> = (0..slots).rev().collect();
    let mut next = 0usize;
    let mut flight: Vec<InFlight> = Vec::with_capacity(slots);
    loop {
        // 1. Admit queued members into free slots.
        let t0 = Instant::now();
        let admit: Vec<(usize, usize)> = std::iter::from_fn(|| {
            (next < members.len()).then_some(())?;
            let slot = free.pop()?;
            next += 1;
            Some((slot, next - 1))
        })
        .collect();
        let sims: Vec<_> = admit
            .par_iter()
            .map(|&(_, i)| setup(&members[i], opts))
            .collect();
        for ((slot, index), sim) in admit.into_iter().zip(sims) {
            let attached = sim.and_then(|mut sim| match gpu.attach(slot, &mut sim) {
                Ok(on_gpu) => Ok((sim, on_gpu)),
                Err(e) => Err(e.to_string()),
            });
            match attached {
                Ok((sim, on_gpu)) => {
                    if !on_gpu {
                        free.push(slot);
                    }
                    flight.push(InFlight {
                        slot: on_gpu.then_some(slot),
                        run: Box::pin(run_member(index, sim, opts)),
                        done: None,
                    });
                }
                Err(e) => {
                    free.push(slot);
                    on_done(MemberResult {
                        index,
                        outcome: setup_failure(e),
                        history: vec![],
                        state: None,
                    });
                }
            }
        }
        stats.admit_s += t0.elapsed().as_secs_f64();
        if flight.is_empty() {
            if next >= members.len() {
                break;
            }
            continue;
        }

        // 2. Member phase: every member's CPU work up to its next evaluation.
        let t0 = Instant::now();
        let cpu_ns = std::sync::atomic::AtomicU64::new(0);
        let polled = flight.len();
        // In chunks of members, a few per pool thread: the thread's CPU clock (a system
        // call, not a vDSO read) is read twice per chunk rather than per member.
        let chunk = flight
            .len()
            .div_ceil(4 * rayon::current_num_threads())
            .max(1);
        flight.par_chunks_mut(chunk).for_each(|ms| {
            let c0 = thread_cpu_s();
            for m in ms {
                if let Poll::Ready(r) = poll_once(m.run.as_mut()) {
                    m.done = Some(r);
                }
            }
            let ns = (1e9 * (thread_cpu_s() - c0)).max(0.0) as u64;
            cpu_ns.fetch_add(ns, std::sync::atomic::Ordering::Relaxed);
        });
        let member_wall_s = t0.elapsed().as_secs_f64();
        stats.host_s += member_wall_s;
        let member_cpu_s = 1e-9 * cpu_ns.into_inner() as f64;
        stats.member_cpu_s += member_cpu_s;
        stats.polls += flight.len() as u64;
        stats.iterations += 1;

        // 3. Retire finished members.
        let mut i = 0;
        while i < flight.len() {
            if let Some(r) = flight[i].done.take() {
                let m = flight.swap_remove(i);
                if let Some(slot) = m.slot {
                    gpu.detach(slot);
                    free.push(slot);
                }
                on_done(r);
            } else {
                i += 1;
            }
        }

        // 4. Serve every posted evaluation in one dispatch.
        // (Served from this thread, outside the pool: serving from a pool thread, inside
        // `rayon::scope`, cut the host's wall time per dispatch by a third at 256 members
        // and added 3–7 % at 1024 on the 2-core machine; docs/journal.md.)
        let steady = gpu.steps_only;
        let (c0, d0, w0) = (thread_cpu_s(), driver_thread_s(), driver_wall_s());
        let t1 = Instant::now();
        let served = gpu.serve();
        let serve_wall_s = t1.elapsed().as_secs_f64() - (driver_wall_s() - w0);
        let (serve_s, driver_s) = (thread_cpu_s() - c0, driver_thread_s() - d0);
        stats.serve_thread_s += serve_s;
        stats.serve_driver_s += driver_s;
        // (Only where every member polled took a device step and posts the next: no host
        // step's poll, no member's last, in the figure.)
        if steady > 0 && gpu.steps_only == steady && polled == steady {
            let serve_own_s = serve_s - driver_s;
            let per_step = |s: f64| 1e6 * s / steady as f64;
            stats
                .device_step_host_us
                .push(per_step(member_cpu_s + serve_own_s));
            stats.device_step_serve_us.push(per_step(serve_own_s));
            stats
                .device_step_critical_us
                .push(1e6 * (member_wall_s + serve_wall_s));
        }
        if served == 0 && !flight.is_empty() {
            // Every member in flight is waiting, so each posted a request; none did.
            unreachable!("lockstep batch: members waiting without a posted evaluation");
        }
    }
    stats.gpu = gpu.timers();
    stats.serve = gpu.serve_timers;
    stats.device_members = gpu.device_members;
    stats.host_step_reasons = gpu
        .host_step_reasons
        .iter()
        .map(|(k, v)| (k.to_string(), *v))
        .collect();
    Ok(stats)
}
