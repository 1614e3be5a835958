//! Element kernel and per-rod solve costs (criterion), the pieces of a batch step:
//!
//! * `element_kernel/cpu/N`: the CPU kernel (kinematics + residual + tangent) over N
//!   elements of the benchmark cantilever (30 elements per rod) — one thread.
//! * `element_kernel/gpu/N`: the same N elements in one GPU dispatch (upload of the
//!   increments, kernel, readback of residuals and tangents); skipped without an adapter.
//! * `rod_solve/30`: one sparse LU refactorization + solve of a 30-element rod's Newton
//!   system (symbolic analysis reused), what each member does per Newton iteration.
//!
//! Throughput is in elements (or rods for the solve).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

use cosserat::batch::bench_members;
use cosserat::element::{kinematics, residual_tangent, FrozenScalars, Increment, StepConsts};
use cosserat::gpu::kernel::KernelMode;
use cosserat::gpu::{ElementKernel, GpuContext};
use cosserat::integrator::dofs::DofMap;
use cosserat::integrator::Simulation;
use cosserat::linsolve::SparseSolver;
use cosserat::model::Vec3;

fn kernels(c: &mut Criterion) {
    let m = &bench_members(1, 30, 1)[0];
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
    let m = &bench_members(1, 30, 1)[0];
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

criterion_group!(benches, kernels, solves);
criterion_main!(benches);
