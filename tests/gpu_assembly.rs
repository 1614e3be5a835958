//! The GPU assembly pass ≡ the CPU scatter, and the bus traffic it promises.
//!
//! * For random states (a few CPU steps from rest, then random frozen scalars) and random
//!   increments, on a frame with a three-element junction (EDMC-2: g unknowns), the
//!   clamped cantilever (EM: no g unknowns; and EDMC-2) and the planar arch (removed
//!   unknowns), the residual, the per-kind row-scale maxima and the CSC matrix values
//!   assembled through the GPU (element pass + assembly pass, one-slot batch) equal the
//!   CPU-assembled ones to `ASSEMBLY_RTOL` (residual relative to the largest row scale,
//!   i.e. the largest element force, as the kernel parity of `tests/gpu_kernel.rs`;
//!   scales and matrix relative to their largest entry), with and without the tangent.
//! * A residual-only iteration reads back exactly the waiting member's node residuals and
//!   row scales (8 bytes each), an iteration with the tangent also its node and
//!   off-diagonal blocks, nothing of the other member slots; an iteration at an unchanged
//!   state uploads only the frozen scalars per element and the increments of the nodes
//!   that moved.
//! * A dispatch in which only some members want the tangent gives those members exactly
//!   the systems of a dispatch in which all do, and the others exactly their residuals
//!   and scales; the tangent pass runs over the wanting members' elements only, and not
//!   at all when none wants it.
//! * The field offsets of the bookkeeping shaders match `src/gpu/layout.rs`.
//!
//! Without an adapter the tests print `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case they fail.

use std::sync::Arc;

use cosserat::batch::{BackendChoice, Executor, GpuBatcher};
use cosserat::element::{FrozenScalars, StepConsts};
use cosserat::gpu::layout::{I_S, NI, NS};
use cosserat::gpu::{gpu_required, Assembler, ElementKernel};
use cosserat::integrator::dofs::NONE;
use cosserat::integrator::evaluate::AssembledSystem;
use cosserat::integrator::{IntegratorParams, Scheme, Simulation};
use cosserat::math::rng::Rng;
use cosserat::model::Model;
use cosserat::scene::{builtin_scenes, load_scene, parse_scene};

/// GPU and CPU element kernels agree to round-off; the sums are the same sums.
const ASSEMBLY_RTOL: f64 = 1e-12;

fn gpu() -> Option<Arc<cosserat::gpu::GpuContext>> {
    match Executor::resolve(BackendChoice::Gpu, None) {
        Ok((Executor::Gpu(c), _)) => Some(c),
        Ok((Executor::Cpu, _)) => unreachable!("BackendChoice::Gpu never falls back"),
        Err(e) if !gpu_required() => {
            println!("skipped: no adapter ({e})");
            None
        }
        Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no usable adapter: {e}"),
    }
}

/// The frame with a fourth rod at corner B: B has three incident elements.
fn tee() -> (Model, IntegratorParams) {
    let text = builtin_scenes()
        .iter()
        .find(|b| b.name == "frame")
        .unwrap()
        .toml
        .to_string()
        + r#"
[[rod]]
name = "rod4"
material = "frame"
section = "frame"
points = [[10, 0, 0], [10, 0, -10]]
elements = 4
d1 = [1, 0, 0]
"#;
    let s = parse_scene(&text, "test:tee").unwrap();
    let b = s
        .model
        .nodes
        .iter()
        .position(|p| (p - nalgebra::Vector3::new(10.0, 0.0, 0.0)).norm() < 1e-12)
        .unwrap();
    let incident = s
        .model
        .elements
        .iter()
        .filter(|e| e.nodes.contains(&b))
        .count();
    assert_eq!(incident, 3, "corner B of the tee");
    (s.model, s.params)
}

fn scene(name: &str, scheme: Option<Scheme>) -> (Model, IntegratorParams) {
    let s = load_scene(name).unwrap();
    let mut p = s.params;
    if let Some(sc) = scheme {
        p.scheme = sc;
    }
    (s.model, p)
}

/// A simulation at the state `steps` CPU steps from the scene's start, and a twin of it
/// in slot `slot` of a GPU batch of `slots` slots (the other slots' workers have left).
fn twins(
    model: Model,
    params: IntegratorParams,
    steps: usize,
    ctx: &cosserat::gpu::GpuContext,
    (slot, slots): (usize, usize),
) -> (Simulation, Simulation, Arc<GpuBatcher>) {
    let mut base = Simulation::new(model.clone(), params).unwrap();
    for _ in 0..steps {
        base.step().expect("CPU step");
    }
    let mut cpu = Simulation::new(model.clone(), params).unwrap();
    let mut gpu = Simulation::new(model, params).unwrap();
    cpu.set_state(base.state().clone());
    gpu.set_state(base.state().clone());
    let b = Arc::new(
        GpuBatcher::new(
            ctx,
            slots,
            gpu.model().elements.len(),
            gpu.model().n_nodes(),
        )
        .unwrap(),
    );
    b.register(slot, &gpu).unwrap();
    assert!(gpu.set_backend(b.clone(), slot));
    (cpu, gpu, b)
}

/// `max |a − b| / max |a|`.
fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let m = a.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |w, (x, y)| w.max((x - y).abs()))
        / m
}

fn check_scene(
    label: &str,
    model: Model,
    params: IntegratorParams,
    steps: usize,
    ctx: &cosserat::gpu::GpuContext,
) {
    let (mut cpu, mut gpu, _b) = twins(model, params, steps, ctx, (0, 1));
    let n = cpu.n_dofs();
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15 ^ n as u64);
    let mut worst = [0.0f64; 3];
    for trial in 0..4 {
        if params.scheme.is_dissipative() {
            let s = FrozenScalars {
                beta_gamma: 0.3 * (1.0 + rng.symmetric()),
                beta_omega: 0.3 * (1.0 + rng.symmetric()),
                c_v: 0.2 * (1.0 + rng.symmetric()),
                c_nu: 0.2 * (1.0 + rng.symmetric()),
            };
            cpu.set_frozen(s);
            gpu.set_frozen(s);
        }
        let amp = 10f64.powi(-trial - 2);
        let q: Vec<f64> = (0..n).map(|_| amp * rng.symmetric()).collect();
        for tangent in [true, false] {
            let (rc, sc, kc) = cpu.frozen_system_at(&q, tangent);
            let (rg, sg, kg) = gpu.frozen_system_at(&q, tangent);
            // Residual relative to the largest row scale (the largest element force, as
            // the kernel parity of `tests/gpu_kernel.rs` measures it): near equilibrium
            // the residual is a cancellation of such forces.
            let force = sc.iter().fold(0.0f64, |m, x| m.max(*x)).max(1e-300);
            let dr = rc
                .iter()
                .zip(&rg)
                .fold(0.0f64, |w, (x, y)| w.max((x - y).abs()))
                / force;
            let ds = rel_diff(&sc, &sg);
            let dk = if tangent { rel_diff(&kc, &kg) } else { 0.0 };
            assert!(
                dr <= ASSEMBLY_RTOL && ds <= ASSEMBLY_RTOL && dk <= ASSEMBLY_RTOL,
                "{label} trial {trial} tangent {tangent}: residual {dr:.2e}, scales {ds:.2e} ({sc:?} vs {sg:?}), matrix {dk:.2e}"
            );
            for (w, d) in worst.iter_mut().zip([dr, ds, dk]) {
                *w = w.max(d);
            }
        }
    }
    println!(
        "{label}: {n} unknowns, GPU vs CPU assembly: residual {:.1e}, scales {:.1e}, matrix {:.1e}",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn gpu_assembly_matches_cpu_scatter() {
    let Some(ctx) = gpu() else { return };
    let (m, mut p) = tee();
    p.scheme = Scheme::edmc2(0.5);
    check_scene("tee EDMC-2", m, p, 2, &ctx);
    let (m, p) = scene("cantilever", Some(Scheme::Em));
    check_scene("cantilever EM", m, p, 3, &ctx);
    let (m, p) = scene("cantilever", Some(Scheme::edmc2(0.5)));
    check_scene("cantilever EDMC-2", m, p, 3, &ctx);
    let (m, p) = scene("arch", None);
    let removed = 9 * m.n_nodes() - Simulation::new(m.clone(), p).unwrap().n_dofs();
    assert!(removed > 0, "the arch has removed unknowns");
    check_scene("arch (planar, supported)", m, p, 2, &ctx);
}

#[test]
fn readback_and_upload_bytes_follow_the_layout() {
    let Some(ctx) = gpu() else { return };
    let (m, p) = scene("cantilever", Some(Scheme::edmc2(0.5)));
    // Slot 1 of 3: only the waiting member's ranges come back.
    let (_cpu, mut gpu, b) = twins(m, p, 1, &ctx, (1, 3));
    let (ne, nn) = (gpu.model().elements.len(), gpu.model().n_nodes());
    let l = b.layout();
    assert_eq!((l.nodes_per_slot, l.members, l.per_slot), (nn, 3, ne));
    let (q1, q2) = (vec![1e-4; gpu.n_dofs()], vec![2e-4; gpu.n_dofs()]);
    let t0 = b.timers();
    gpu.frozen_system_at(&q1, true);
    let t1 = b.timers();
    gpu.frozen_system_at(&q2, false);
    let t2 = b.timers();
    let with = t1.bytes_down - t0.bytes_down;
    let without = t2.bytes_down - t1.bytes_down;
    assert_eq!(
        with,
        8 * (l.residual_per_member() + l.tangent_per_member()) as u64
    );
    assert_eq!(l.tangent_per_member(), 81 * (nn + 2 * ne));
    assert_eq!(without, 8 * (9 * nn + 3) as u64);
    println!(
        "cantilever ({ne} elements): bytes down per element per iteration {:.1} with the tangent, {:.1} without (raw element output: {} / {})",
        with as f64 / ne as f64,
        without as f64 / ne as f64,
        364 * 8,
        40 * 8
    );
    // The first run uploaded constants, state and iteration data (and the tangent pass's
    // element list, 4 bytes per element); neither the state nor the frozen scalars have
    // changed since, and the member's elements stay active between its evaluations, so
    // the next iteration uploads only 9 increments per node whose increment changed
    // (every node with an unknown: here one run of adjacent node slots, so one scatter
    // run of 32 bytes for all nine fields, after the 32-byte header) and the member's
    // tangent flag (4 bytes: set, then cleared).
    let moved = gpu
        .dof_map()
        .nodes
        .iter()
        .filter(|nd| nd.u.iter().chain(&nd.th).chain(&nd.g).any(|&i| i != NONE))
        .count();
    let up = t2.bytes_up - t1.bytes_up;
    assert_eq!(up, 8 * (9 * moved) as u64 + 32 * (1 + 1) + 4);
    // In two copies (the values and the run list), not one per field and run.
    assert_eq!(t2.copies - t1.copies, 2);
    assert!(t1.bytes_up - t0.bytes_up >= 8 * ((NS + NI - I_S) * ne) as u64 + 4 * ne as u64);
    println!(
        "bytes up per element per iteration at an unchanged state: {:.1} (per-element increments: {})",
        up as f64 / ne as f64,
        8 * NI
    );
}

#[test]
fn tangent_for_some_members_equals_tangent_for_all() {
    let Some(ctx) = gpu() else { return };
    let (model, params) = scene("cantilever", Some(Scheme::edmc2(0.5)));
    // Three members at different states.
    let sims: Vec<Simulation> = [1usize, 3, 2]
        .iter()
        .map(|&steps| {
            let mut s = Simulation::new(model.clone(), params).unwrap();
            for _ in 0..steps {
                s.step().expect("CPU step");
            }
            s
        })
        .collect();
    let (ne, nn) = (model.elements.len(), model.n_nodes());
    let mut kern = ElementKernel::new(&ctx, 3 * ne).unwrap();
    let mut asm = Assembler::new(&ctx, &mut kern, 3, ne, nn).unwrap();
    let k = StepConsts {
        dt: params.dt,
        scheme: params.scheme,
    };
    let trans = k.scheme.translational_dissipation();
    let ends: Vec<[usize; 2]> = model.elements.iter().map(|e| e.nodes).collect();
    for (m, sim) in sims.iter().enumerate() {
        let masks = sim.dof_map().element_row_masks();
        asm.set_member(m, nn, &ends, &masks).unwrap();
        for e in 0..ne {
            kern.set_element(m * ne + e, &sim.element_data()[e], &k, trans);
            kern.set_state(
                m * ne + e,
                &sim.state().element(&model, e),
                &sim.state().eps[e],
            );
        }
    }
    let mut rng = Rng::new(0x5eed_0011);
    let s = FrozenScalars {
        beta_gamma: 0.4,
        beta_omega: 0.3,
        c_v: 0.2,
        c_nu: 0.1,
    };
    let incs: Vec<Vec<[f64; 9]>> = (0..3)
        .map(|_| {
            (0..nn)
                .map(|_| std::array::from_fn(|_| 1e-3 * rng.symmetric()))
                .collect()
        })
        .collect();
    let mut run = |pending: &[(usize, bool)]| -> (Vec<AssembledSystem>, u64) {
        for (m, x) in incs.iter().enumerate() {
            (0..ne).for_each(|e| kern.set_scalars(m * ne + e, &s));
            asm.set_increments(m, x);
        }
        let t0 = kern.timers.tangent_elements;
        asm.run(&mut kern, pending).unwrap();
        let systems = pending
            .iter()
            .map(|&(m, t)| asm.system(m, nn, ne, t))
            .collect();
        (systems, kern.timers.tangent_elements - t0)
    };
    let (all, n_all) = run(&[(0, true), (1, true), (2, true)]);
    let (some, n_some) = run(&[(0, false), (1, true), (2, false)]);
    let (none, n_none) = run(&[(0, false), (1, false), (2, false)]);
    assert_eq!((n_all, n_some, n_none), (3 * ne as u64, ne as u64, 0));
    assert!(all[1].node_k.len() == nn && all[1].off_k.len() == ne);
    assert_eq!(
        some[1], all[1],
        "member 1 wants the tangent in both dispatches"
    );
    for m in [0, 2] {
        assert!(some[m].node_k.is_empty() && some[m].off_k.is_empty());
        assert_eq!(
            (&some[m].node_r, some[m].scale),
            (&all[m].node_r, all[m].scale)
        );
    }
    for m in 0..3 {
        assert_eq!(
            (&none[m].node_r, none[m].scale),
            (&all[m].node_r, all[m].scale)
        );
    }
}

/// The element-output and iteration field offsets the bookkeeping shaders read or write
/// are those of `src/gpu/layout.rs` (no adapter needed).
#[test]
fn bookkeeping_shaders_match_rust_layout() {
    use cosserat::gpu::assemble::{ASSEMBLE_WGSL, GATHER_WGSL};
    use cosserat::gpu::layout::{I_X, O_K, O_R, O_SC};
    for (src, name, val) in [
        (ASSEMBLE_WGSL, "O_R", O_R),
        (ASSEMBLE_WGSL, "O_SC", O_SC),
        (ASSEMBLE_WGSL, "O_K", O_K),
        (GATHER_WGSL, "I_X", I_X),
    ] {
        let needle = format!("const {name}: u32 = {val}u;");
        assert!(src.contains(&needle), "shader lacks `{needle}`");
    }
}
