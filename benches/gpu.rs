//! Element kernel and per-rod solve costs (criterion), the pieces of a batch step:
//!
//! * `element_kernel/cpu/N`: the CPU kernel (kinematics + residual + tangent) over N
//!   elements of the benchmark cantilever (30 elements per rod) — one thread.
//! * `element_kernel/gpu/N`: the same N elements in one GPU dispatch (upload of the
//!   increments, kernel, readback of residuals and tangents); skipped without an adapter.
//! * `dispatch/{residual,tangent}/64x30`: one batch dispatch of 64 rods × 30 elements
//!   through the element and assembly passes ([`Assembler::run`]), as a Newton iteration
//!   of the batch path does it (frozen scalars and node increments uploaded, the assembled
//!   systems read back): every member residual-only (modified Newton) or every member with
//!   the tangent. The tangent passes cost the difference. Bytes read back per element are
//!   printed once per variant, and so is the process CPU time per element and dispatch
//!   (user + system, all threads: on a software adapter the kernels run on the host's
//!   threads, and CPU time is far less disturbed than wall time when other processes
//!   share the cores). Skipped without an adapter.
//! * `rod_solve/30`: one sparse LU refactorization + solve of a 30-element rod's Newton
//!   system (symbolic analysis reused), what each member does per Newton iteration.
//!
//! * `pipelines` (printed once, not a criterion measurement): device creation and the
//!   build of the element and assembly pipelines in a fresh process, the cost a run pays
//!   before its first step (with the pipeline cache and the driver's own disk cache as
//!   they are on this machine).
//!
//! Throughput is in elements (or rods for the solve).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

use cosserat::batch::bench_members;
use cosserat::element::{kinematics, residual_tangent, FrozenScalars, Increment, StepConsts};
use cosserat::gpu::kernel::KernelMode;
use cosserat::gpu::{Assembler, ElementKernel, GpuContext};
use cosserat::integrator::dofs::DofMap;
use cosserat::integrator::Simulation;
use cosserat::linsolve::SparseSolver;
use cosserat::model::Vec3;

fn kernels(c: &mut Criterion) {
    let m = &bench_members(1, 30, 1).unwrap()[0];
    let sim = Simulation::new(m.model.clone(), m.params).unwrap();
    let k = StepConsts {
        dt: m.params.dt,
        scheme: m.params.scheme,
    };
    let trans = k.scheme.translational_dissipation();
    let s = FrozenScalars {
        beta_gamma: 0.1,
        beta_omega: 0.1,
        c_v: 0.05,
        c_nu: 0.0,
    };
    let ne = m.model.elements.len();
    let inc = |e: usize| Increment {
        u: [
            Vec3::new(1e-4, 2e-4 * e as f64, 0.0),
            Vec3::new(0.0, 1e-4, 3e-4),
        ],
        theta: [Vec3::new(1e-3, 0.0, 2e-3), Vec3::new(0.0, 1e-3, 1e-3)],
        g: [Vec3::zeros(); 2],
    };
    let ctx = GpuContext::new(None).ok();
    let mut g = c.benchmark_group("element_kernel");
    for n in [480usize, 3840] {
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new("cpu", n), &n, |b, &n| {
            b.iter(|| {
                let mut acc = 0.0;
                for i in 0..n {
                    let e = i % ne;
                    let st = sim.state().element(&m.model, e);
                    let eps = sim.state().eps[e];
                    let d = &sim.element_data()[e];
                    let kin = kinematics(d, &st, &eps, &inc(e), s.c_nu, k.dt);
                    acc += residual_tangent(d, &st, &kin, &s, &k, trans, true).k[(0, 0)];
                }
                acc
            })
        });
        if let Some(ctx) = &ctx {
            let mut kern = ElementKernel::new(ctx, n).unwrap();
            for i in 0..n {
                let e = i % ne;
                kern.set_element(i, &sim.element_data()[e], &k, trans);
                kern.set_state(i, &sim.state().element(&m.model, e), &sim.state().eps[e]);
            }
            g.bench_with_input(BenchmarkId::new("gpu", n), &n, |b, &n| {
                b.iter(|| {
                    for i in 0..n {
                        kern.set_iter(i, &inc(i % ne), &s);
                    }
                    kern.run(KernelMode::Frozen, true).unwrap();
                    kern.eval(0, true).k[(0, 0)]
                })
            });
        }
    }
    g.finish();
}

/// One rod's Newton solve (30 elements, 9 unknowns per node): faer's pivoted sparse LU
/// against the block-tridiagonal LU, and a solve that reuses the factorization (modified
/// Newton).
fn solves(c: &mut Criterion) {
    let m = &bench_members(1, 30, 1).unwrap()[0];
    let dofs = DofMap::new(&m.model, true);
    let mut pattern = dofs.pattern();
    for i in 0..dofs.n {
        pattern.push((i, i));
    }
    let mut g = c.benchmark_group("rod_solve");
    g.throughput(Throughput::Elements(1));
    let sparse = SparseSolver::new(dofs.n, &pattern).unwrap();
    let blocks = SparseSolver::with_blocks(dofs.n, &pattern, &dofs.node_block_sizes()).unwrap();
    for mut solver in [sparse, blocks] {
        let slots: Vec<(usize, usize, usize)> = pattern
            .iter()
            .map(|&(i, j)| (i, j, solver.slot(i, j)))
            .collect();
        let vals = solver.values_mut();
        vals.iter_mut().for_each(|x| *x = 0.0);
        for &(i, j, sl) in &slots {
            vals[sl] += if i == j {
                10.0
            } else {
                0.01 * ((i + 2 * j) % 7) as f64
            };
        }
        let kind = format!("{:?}", solver.kind());
        let rhs0: Vec<f64> = (0..dofs.n).map(|i| (i % 5) as f64).collect();
        g.bench_function(format!("30/factor_solve/{kind}"), |b| {
            b.iter(|| {
                let mut rhs = rhs0.clone();
                solver.factor_solve(&mut rhs).unwrap();
                rhs[0]
            })
        });
        g.bench_function(format!("30/solve_only/{kind}"), |b| {
            b.iter(|| {
                let mut rhs = rhs0.clone();
                solver.solve(&mut rhs).unwrap();
                rhs[0]
            })
        });
    }
    g.finish();
}

/// Device creation and pipeline build times of this process (printed).
fn pipelines(_: &mut Criterion) {
    let t0 = std::time::Instant::now();
    let Ok(ctx) = GpuContext::new(None) else {
        println!("pipelines: skipped (no adapter)");
        return;
    };
    let t1 = std::time::Instant::now();
    let mut kern = ElementKernel::new(&ctx, 64).unwrap();
    let t2 = std::time::Instant::now();
    let _asm = Assembler::new(&ctx, &mut kern, 2, 32, 33).unwrap();
    let t3 = std::time::Instant::now();
    println!(
        "pipelines: device {:.3} s, element passes {:.3} s, gather + assembly {:.3} s (pipeline cache: {})",
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        (t3 - t2).as_secs_f64(),
        ctx.pipeline_cache_path()
            .map_or("none".into(), |p| p.display().to_string())
    );
}

/// One batch dispatch (gather, element and assembly passes, readback) of `rods` rods of
/// 30 elements, residual-only or with the tangent for every member.
fn dispatches(c: &mut Criterion) {
    let Ok(ctx) = GpuContext::new(None) else {
        println!("dispatch: skipped (no adapter)");
        return;
    };
    let rods = 64;
    let members = bench_members(rods, 30, 1).unwrap();
    let sims: Vec<Simulation> = members
        .iter()
        .map(|m| Simulation::new(m.model.clone(), m.params).unwrap())
        .collect();
    let (ne, nn) = (sims[0].model().elements.len(), sims[0].model().n_nodes());
    let mut kern = ElementKernel::new(&ctx, rods * ne).unwrap();
    let mut asm = Assembler::new(&ctx, &mut kern, rods, ne, nn).unwrap();
    let s = FrozenScalars {
        beta_gamma: 0.1,
        beta_omega: 0.1,
        c_v: 0.05,
        c_nu: 0.02,
    };
    for (m, sim) in sims.iter().enumerate() {
        let k = StepConsts {
            dt: sim.params().dt,
            scheme: sim.params().scheme,
        };
        let trans = k.scheme.translational_dissipation();
        let ends: Vec<[usize; 2]> = sim.model().elements.iter().map(|e| e.nodes).collect();
        let masks = sim.dof_map().element_row_masks();
        asm.set_member(m, nn, &ends, &masks).unwrap();
        for e in 0..ne {
            kern.set_element(m * ne + e, &sim.element_data()[e], &k, trans);
            kern.set_state(
                m * ne + e,
                &sim.state().element(sim.model(), e),
                &sim.state().eps[e],
            );
        }
    }
    let mut g = c.benchmark_group("dispatch");
    g.throughput(Throughput::Elements((rods * ne) as u64));
    for tangent in [false, true] {
        let pending: Vec<(usize, bool)> = (0..rods).map(|m| (m, tangent)).collect();
        let mut it = 0usize;
        let mut iterate = |kern: &mut ElementKernel, asm: &mut Assembler| {
            it += 1;
            let a = 1e-5 * (1 + it % 3) as f64;
            for m in 0..rods {
                for e in 0..ne {
                    kern.set_scalars(m * ne + e, &s);
                }
                let x: Vec<[f64; 9]> = (0..nn)
                    .map(|j| std::array::from_fn(|k| a * ((j + k) % 5) as f64))
                    .collect();
                asm.set_increments(m, &x);
            }
            asm.run(kern, &pending).unwrap();
        };
        iterate(&mut kern, &mut asm);
        let before = kern.timers;
        iterate(&mut kern, &mut asm);
        let down = kern.timers.bytes_down - before.bytes_down;
        let up = kern.timers.bytes_up - before.bytes_up;
        let name = if tangent { "tangent" } else { "residual" };
        println!(
            "dispatch/{name}: {:.1} bytes read back, {:.1} bytes uploaded per element ({} elements, {})",
            down as f64 / (rods * ne) as f64,
            up as f64 / (rods * ne) as f64,
            rods * ne,
            ctx.describe()
        );
        if let Some(c0) = cpu_seconds() {
            let (mut n, t0) = (0usize, std::time::Instant::now());
            while n < 20 || (t0.elapsed().as_secs_f64() < 3.0 && n < 2000) {
                iterate(&mut kern, &mut asm);
                n += 1;
            }
            if let Some(c1) = cpu_seconds() {
                println!(
                    "dispatch/{name}: {:.2} µs CPU time per element and dispatch ({n} dispatches)",
                    1e6 * (c1 - c0) / (n * rods * ne) as f64
                );
            }
        }
        g.bench_function(format!("{name}/{rods}x{ne}"), |b| {
            b.iter(|| iterate(&mut kern, &mut asm))
        });
    }
    g.finish();
}

/// User + system CPU time of this process so far (all threads), from `/proc/self/stat`
/// (clock ticks of 10 ms); `None` where that file does not exist.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may contain spaces) start at field 3.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

criterion_group!(benches, pipelines, kernels, dispatches, solves);
criterion_main!(benches);
