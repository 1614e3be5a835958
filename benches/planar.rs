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
//!
//! Before criterion runs, `side by side` prints the three (and the planar and 3D kernels
//! with `--newton modified`) interleaved (one step of each in
//! turn, 3000 steps each, the scene's 1000 steps repeated): the best, 10th-percentile and
//! median step time and their ratios to the planar kernel's. On a shared machine the
//! interleaving keeps load changes out of the ratios, and the best/10th-percentile figures
//! estimate the unloaded cost (a step is ~0.1–1 ms, shorter than a scheduler slice).

use criterion::{criterion_group, Criterion, Throughput};

use std::time::Instant;

use cosserat::integrator::{NewtonVariant, Simulation};
use cosserat::scene::load_scene;

const KINDS: [&str; 5] = [
    "planar",
    "3d-kernel",
    "full-3d",
    "planar+modified",
    "3d-kernel+modified",
];

fn fresh(scene: &cosserat::scene::Scene, kind: &str) -> Simulation {
    let mut model = scene.model.clone();
    if kind == "full-3d" {
        model.planar = None;
    }
    let mut params = scene.params;
    if kind.ends_with("+modified") {
        params.newton = NewtonVariant::Modified;
    }
    let mut sim = Simulation::new(model, params).unwrap();
    sim.set_planar_kernel(kind.starts_with("planar"));
    sim
}

/// The three variants interleaved step by step; prints µs per step.
fn side_by_side() {
    let scene = load_scene("cantilever_planar").unwrap();
    let mut sims: Vec<Simulation> = KINDS.iter().map(|k| fresh(&scene, k)).collect();
    let mut blocks: Vec<Vec<f64>> = vec![Vec::new(); KINDS.len()];
    let mut iters = vec![0usize; KINDS.len()];
    for _ in 0..3000 {
        for (i, sim) in sims.iter_mut().enumerate() {
            if sim.state().t >= scene.params.t_end - 1e-9 {
                *sim = fresh(&scene, KINDS[i]);
            }
            let t0 = Instant::now();
            iters[i] += sim.step().expect("cantilever_planar step").newton_iters;
            blocks[i].push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    let stats: Vec<[f64; 3]> = blocks
        .iter_mut()
        .map(|b| {
            b.sort_by(f64::total_cmp);
            [b[0], b[b.len() / 10], b[b.len() / 2]]
        })
        .collect();
    println!(
        "side by side (cantilever_planar, EM, 50 elements, µs per step: best / p10 / median):"
    );
    for (i, k) in KINDS.iter().enumerate() {
        let [b, p, m] = stats[i];
        let [b0, p0, m0] = stats[0];
        println!(
            "  {k:>18}: {b:7.1} / {p:7.1} / {m:7.1}   ratio to planar {:.2} / {:.2} / {:.2}   {:.2} Newton iterations per step",
            b / b0,
            p / p0,
            m / m0,
            iters[i] as f64 / 3000.0,
        );
    }
}

fn cantilever(c: &mut Criterion) {
    let scene = load_scene("cantilever_planar").unwrap();
    let mut g = c.benchmark_group("planar_kernel");
    g.throughput(Throughput::Elements(scene.model.elements.len() as u64));
    for kind in &KINDS[..3] {
        let mut sim = fresh(&scene, kind);
        g.bench_function(format!("cantilever50/{kind}"), |b| {
            b.iter(|| {
                if sim.state().t >= scene.params.t_end - 1e-9 || sim.step().is_err() {
                    sim = fresh(&scene, kind);
                }
            })
        });
    }
    g.finish();
}

/// The element kernel alone on the planar cantilever's 50 elements at a mid-size increment
/// (EM, frozen scalars): the planar kernel against the 3D kernel on the same elements,
/// residual only and residual + tangent.
fn element(c: &mut Criterion) {
    use cosserat::element::lanes::{pack3, pack6};
    use cosserat::element::planar::{self, PElementEval, PIncrement, PState, PlanarData};
    use cosserat::element::{
        kinematics_core, residual_tangent_into, ElementData, ElementEval, ElementState,
        FrozenScalars, Increment, StepConsts,
    };
    use cosserat::integrator::Scheme;
    use cosserat::math::lane::F64x4;
    use cosserat::model::Vec3;
    let scene = load_scene("cantilever_planar").unwrap();
    let model = &scene.model;
    let plane = model.planar.expect("planar scene");
    let data = ElementData::for_model(model);
    let state = cosserat::integrator::state::State::initial(model, &data);
    let n = model.elements.len();
    let k = StepConsts {
        dt: 1e-2,
        scheme: Scheme::Em,
    };
    let s = FrozenScalars::default();
    let st3: Vec<_> = (0..n).map(|e| state.element(model, e)).collect();
    let pd: Vec<_> = (0..n)
        .map(|e| {
            planar::planar_data(
                &data[e],
                &state.config(model, e),
                plane,
                &model.intrinsic_curvature(e),
            )
        })
        .collect();
    let pst: Vec<_> = (0..n).map(|e| pd[e].state(&st3[e])).collect();
    let peps: Vec<_> = (0..n)
        .map(|e| planar::strains3(&pst[e].cfg, pd[e].h))
        .collect();
    // A mid-size in-plane increment (millimetres, milliradians), different per element.
    let pinc: Vec<PIncrement> = (0..n)
        .map(|e| {
            let x = e as f64 / n as f64;
            PIncrement {
                u: [
                    planar::V2::new(1e-3 * x, 2e-3),
                    planar::V2::new(2e-3, -1e-3 * x),
                ],
                theta: [1e-3 * x, -2e-3],
                g: Default::default(),
            }
        })
        .collect();
    let inc3: Vec<Increment> = (0..n)
        .map(|e| {
            let m = pd[e].map;
            Increment {
                u: [m.v3(&pinc[e].u[0], 0.0), m.v3(&pinc[e].u[1], 0.0)],
                theta: [
                    m.v3(&planar::V2::zeros(), pinc[e].theta[0]),
                    m.v3(&planar::V2::zeros(), pinc[e].theta[1]),
                ],
                g: [Vec3::zeros(); 2],
            }
        })
        .collect();
    let mut g = c.benchmark_group("planar_element");
    g.throughput(Throughput::Elements(n as u64));
    for tangent in [false, true] {
        let label = if tangent { "tangent" } else { "residual" };
        g.bench_function(format!("planar/{label}"), |b| {
            b.iter(|| {
                for e in 0..n {
                    let kin =
                        planar::kinematics_core(&pd[e], &pst[e], &peps[e], &pinc[e], 0.0, k.dt);
                    let ev =
                        planar::residual_tangent(&pd[e], &pst[e], &kin, &s, &k, false, tangent);
                    std::hint::black_box(&ev);
                }
            })
        });
        // Four elements per kernel call (the assembly's path with frozen scalars).
        let groups: Vec<_> = (0..n / 4)
            .map(|g| {
                let e = 4 * g;
                let four = |i: usize| e + i;
                (
                    PlanarData::pack([&pd[e], &pd[e + 1], &pd[e + 2], &pd[e + 3]]),
                    PState::pack([&pst[e], &pst[e + 1], &pst[e + 2], &pst[e + 3]]),
                    pack3([&peps[e], &peps[e + 1], &peps[e + 2], &peps[e + 3]]),
                    PIncrement::from_locals(&[0, 1, 2, 3].map(|i| pinc[four(i)].to_local())),
                )
            })
            .collect();
        let s4 = FrozenScalars::<F64x4>::default();
        let mut ev4 = PElementEval::<F64x4>::zeros();
        g.bench_function(format!("planar-f64x4/{label}"), |b| {
            b.iter(|| {
                for (d, st, eps, inc) in &groups {
                    let kin = planar::kinematics_core(d, st, eps, inc, s4.c_nu, k.dt);
                    planar::residual_tangent_into(d, st, &kin, &s4, &k, false, tangent, &mut ev4);
                    std::hint::black_box(&ev4);
                }
            })
        });
        let groups3: Vec<_> = (0..n / 4)
            .map(|g| {
                let e = 4 * g;
                (
                    ElementData::<F64x4>::pack([
                        &data[e],
                        &data[e + 1],
                        &data[e + 2],
                        &data[e + 3],
                    ]),
                    ElementState::pack(&[st3[e], st3[e + 1], st3[e + 2], st3[e + 3]]),
                    pack6(&[
                        state.eps[e],
                        state.eps[e + 1],
                        state.eps[e + 2],
                        state.eps[e + 3],
                    ]),
                    Increment::pack(&[inc3[e], inc3[e + 1], inc3[e + 2], inc3[e + 3]]),
                )
            })
            .collect();
        let mut ev34 = ElementEval::<F64x4>::zeros();
        g.bench_function(format!("3d-f64x4/{label}"), |b| {
            b.iter(|| {
                for (d, st, eps, inc) in &groups3 {
                    let kin = kinematics_core(d, st, eps, inc, s4.c_nu, k.dt);
                    residual_tangent_into(d, st, &kin, &s4, &k, false, tangent, &mut ev34);
                    std::hint::black_box(&ev34);
                }
            })
        });
        let mut ev = ElementEval::<f64>::zeros();
        g.bench_function(format!("3d/{label}"), |b| {
            b.iter(|| {
                for e in 0..n {
                    let kin =
                        kinematics_core(&data[e], &st3[e], &state.eps[e], &inc3[e], 0.0, k.dt);
                    residual_tangent_into(&data[e], &st3[e], &kin, &s, &k, false, tangent, &mut ev);
                    std::hint::black_box(&ev);
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, cantilever, element);

fn main() {
    if !std::env::args().any(|a| a.contains("element")) {
        side_by_side();
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
