//! Speed of one time step on the CPU reference path (criterion).
//!
//! * `em_step/cantilever50`: one EM step of the built-in clamped 50-element 3D cantilever
//!   at Δt = 1e-2 (issue goal: ≤ 0.25 ms on the 2-core machine).
//! * `edmc2_step/frame`: one EDMC-2 (α = 0.5) step of the free-flying frame, both
//!   dissipation strategies.
//! * `planar_vs_3d`: whole runs of the planar arch and mechanism with the planar unknowns
//!   only and with the full 3D system (same results to round-off, see
//!   `tests/paper_examples.rs`).
//! * `assembly/cantilever50/{residual,tangent}`: the element kernel + scatter over the 50
//!   elements of the cantilever at a mid-size increment, residual only (a modified-Newton
//!   iteration that keeps its tangent) and residual + tangent (a full-Newton iteration);
//!   throughput in elements, so criterion's time per element is the per-element cost
//!   (the tangent variant includes one copy of the matrix values, ≈ 5k numbers).
//!
//! Throughput in rods·elements·steps per second is printed by criterion as
//! "elements" throughput (1 rod).

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use cosserat::integrator::{Scheme, Simulation, Strategy};
use cosserat::scene::load_scene;

fn cantilever(c: &mut Criterion) {
    let scene = load_scene("cantilever").unwrap();
    let mut g = c.benchmark_group("em_step");
    g.throughput(Throughput::Elements(scene.model.elements.len() as u64));
    let mut sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
    g.bench_function("cantilever50", |b| {
        b.iter(|| {
            if sim.step().is_err() {
                sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
            }
        })
    });
    // The same step in this thread's CPU time (see `thread_cpu_ns`).
    g.bench_function("cantilever50/cpu", |b| {
        b.iter_custom(|iters| {
            let t0 = thread_cpu_ns();
            for _ in 0..iters {
                if sim.step().is_err() {
                    sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
                }
            }
            Duration::from_nanos(thread_cpu_ns().saturating_sub(t0))
        })
    });
    g.finish();
}

fn frame(c: &mut Criterion) {
    let scene = load_scene("frame").unwrap();
    let mut g = c.benchmark_group("edmc2_step");
    g.throughput(Throughput::Elements(scene.model.elements.len() as u64));
    for strategy in [Strategy::Staggered, Strategy::Monolithic] {
        let mut p = scene.params;
        p.scheme = Scheme::Edmc2 {
            alpha_gv: 0.5,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        };
        p.strategy = strategy;
        let fresh = || Simulation::new(scene.model.clone(), p).unwrap();
        let mut sim = fresh();
        g.bench_function(format!("frame/{strategy:?}"), |b| {
            b.iter(|| {
                // The frame is run for its 50 documented steps, then restarted.
                if sim.state().t >= p.t_end - 1e-9 || sim.step().is_err() {
                    sim = fresh();
                }
            })
        });
    }
    g.finish();
}

/// Planar mode against the full 3D system on the same planar scenes: 200 steps of the arch
/// (EDMC-2 α = 1, Δt = 1) and 40 of the half-hexagon mechanism (EDMC-2 α = 0.5, Δt = 0.05).
fn planar(c: &mut Criterion) {
    let mut g = c.benchmark_group("planar_vs_3d");
    g.sample_size(10);
    for (name, alpha, t_end) in [("arch", 1.0, 200.0), ("mechanism_hexagon", 0.5, 2.0)] {
        let scene = load_scene(name).unwrap();
        let mut p = scene.params;
        p.scheme = Scheme::Edmc2 {
            alpha_gv: alpha,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        };
        p.t_end = t_end;
        // The staggered loop, as these figures were first measured (the default `auto` is
        // monolithic on the CPU).
        p.strategy = Strategy::Staggered;
        g.throughput(Throughput::Elements(
            (scene.model.elements.len() * p.n_steps()) as u64,
        ));
        for planar in [true, false] {
            let mut model = scene.model.clone();
            if !planar {
                model.planar = None;
            }
            let label = if planar { "planar" } else { "3d" };
            g.bench_function(format!("{name}/{label}"), |b| {
                b.iter(|| {
                    let mut sim = Simulation::new(model.clone(), p).unwrap();
                    for _ in 0..p.n_steps() {
                        sim.step().unwrap();
                    }
                })
            });
        }
    }
    g.finish();
}

/// Element kernel + scatter of the cantilever's 50 elements at a fixed increment (what one
/// Newton iteration assembles), with and without the tangent.
fn assembly(c: &mut Criterion) {
    let scene = load_scene("cantilever").unwrap();
    let mut sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
    for _ in 0..5 {
        sim.step().unwrap();
    }
    let n = sim.n_dofs();
    // A deterministic increment of the size a step takes (1e-3 of the element length).
    let q: Vec<f64> = (0..n)
        .map(|i| 1e-3 * ((i * 7919) % 13) as f64 / 13.0)
        .collect();
    let mut g = c.benchmark_group("assembly");
    g.throughput(Throughput::Elements(scene.model.elements.len() as u64));
    for (label, tangent) in [("residual", false), ("tangent", true)] {
        g.bench_function(format!("cantilever50/{label}"), |b| {
            b.iter(|| sim.frozen_system_at(&q, tangent).0[0])
        });
        // The same in this thread's CPU time: on a shared machine the wall time above also
        // counts the time other processes hold the core.
        g.bench_function(format!("cantilever50/{label}/cpu"), |b| {
            b.iter_custom(|iters| {
                let t0 = thread_cpu_ns();
                for _ in 0..iters {
                    std::hint::black_box(sim.frozen_system_at(&q, tangent).0[0]);
                }
                Duration::from_nanos(thread_cpu_ns().saturating_sub(t0))
            })
        });
    }
    g.finish();
}

/// This thread's CPU time in ns (`CLOCK_THREAD_CPUTIME_ID`).
fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

criterion_group!(benches, cantilever, frame, planar, assembly);
criterion_main!(benches);
