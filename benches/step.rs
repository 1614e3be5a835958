//! Speed of one time step on the CPU reference path (criterion).
//!
//! * `em_step/cantilever50`: one EM step of the built-in clamped 50-element 3D cantilever
//!   at Δt = 1e-2 (issue goal: ≤ 0.25 ms on the 2-core machine).
//! * `edmc2_step/frame`: one EDMC-2 (α = 0.5) step of the free-flying frame, both
//!   dissipation strategies.
//! * `planar_vs_3d`: whole runs of the planar arch and mechanism with the planar unknowns
//!   only and with the full 3D system (same results to round-off, see
//!   `tests/paper_examples.rs`).
//! * `assembly+solve` breakdown: residual/tangent assembly vs sparse LU for the cantilever.
//!
//! Throughput in rods·elements·steps per second is printed by criterion as
//! "elements" throughput (1 rod).

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

criterion_group!(benches, cantilever, frame, planar);
criterion_main!(benches);
