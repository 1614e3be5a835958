//! Speed of the planar element kernel against the 3D kernel on the same planar scene
//! (criterion): one EM step of the built-in `cantilever_planar` (50 elements, Δt = 1e-2)
//!
//! * `planar_kernel/cantilever50/planar`: the planar kernel (the default for a planar
//!   scene on the CPU path);
//! * `…/3d-kernel`: the same planar model with the 3D kernel (out-of-plane unknowns
//!   removed from the Newton system, elements still 3D);
//! * `…/full-3d`: the same scene without `planar` (6 unknowns per node).
//!
//! All three give the same trajectory to round-off (`tests/planar_kernel.rs`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use cosserat::integrator::Simulation;
use cosserat::scene::load_scene;

fn cantilever(c: &mut Criterion) {
    let scene = load_scene("cantilever_planar").unwrap();
    let mut g = c.benchmark_group("planar_kernel");
    g.throughput(Throughput::Elements(scene.model.elements.len() as u64));
    for kind in ["planar", "3d-kernel", "full-3d"] {
        let fresh = || {
            let mut model = scene.model.clone();
            if kind == "full-3d" {
                model.planar = None;
            }
            let mut sim = Simulation::new(model, scene.params).unwrap();
            sim.set_planar_kernel(kind == "planar");
            sim
        };
        let mut sim = fresh();
        g.bench_function(format!("cantilever50/{kind}"), |b| {
            b.iter(|| {
                if sim.state().t >= scene.params.t_end - 1e-9 || sim.step().is_err() {
                    sim = fresh();
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, cantilever);
criterion_main!(benches);
