//! The GPU batch path runs the scene features that enter the element kernel through data
//! it already receives — an initial configuration apart from the reference, intrinsic
//! curvature (the reference strains), Kelvin–Voigt damping (the frozen scalars), line
//! loads (nodal terms on the CPU), drag (the element kernel's on the GPU), sliding clamps, spinning or not (the unknown numbering), and
//! driven supports (their prescribed increments travel with the Newton increments) — with
//! CPU parity.
//!
//! Without an adapter the test prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case it fails.

mod common;
use common::gpu;
use cosserat::batch::{run_members, BatchOptions, Executor, Member, MemberResult};
use cosserat::integrator::{NewtonVariant, Strategy};
use cosserat::scene::parse_scene;

/// Final positions agree to this (measured 1.1e-16 to 2.2e-16 on lavapipe over these 10 steps; the
/// longer lockstep runs of `tests/gpu_lockstep.rs` drift to 1.8e-11).
const STATE_RTOL: f64 = 1e-15;

fn scene(scheme: &str, extra: &str) -> String {
    use common::scene_text::{material, rod, section};
    format!(
        r#"name = "features"
gravity = [0, 0, -9.81]
{material}damping = 0.01

{section}
{rod}curvature = [0.3, 0.1, 0.2]
drag = 0.3

[rod.initial]
stretch = 1.001
displacement = [[0, 0, 0], [0, 0.01, 0], [0, 0.02, 0.01], [0, 0.03, 0], [0, 0.04, 0], [0, 0.05, 0.01], [0, 0.06, 0], [0, 0.07, 0], [0, 0.08, 0]]

[[clamp]]
at = [0, 0, 0]

[[line_load]]
rod = "rod"
force = [0, 0.5, 0.2]
moment = [0.01, 0, 0]
follower = true

{extra}

[integrator]
{scheme}
dt = 0.01
t_end = 0.1
"#,
        material = material("m", "1e6", "0.3", "1000"),
        section = section("s", "1.2566e-3", "1.2566e-7", "2.5133e-7"),
        rod = rod("rod", "[[0, 0, 0], [1, 0, 0]]", 8, "[0, 0, 1]"),
    )
}

fn members(extra: &str) -> Vec<Member> {
    [
        "scheme = \"em\"",
        "scheme = \"edmc2\"\nalpha = 0.5",
        // The director dissipation (α_Ων, α_Γν): a spinning end takes its share of it.
        "scheme = \"edmc2\"\nalpha_on = 0.5\nalpha_gn = 0.5",
    ]
    .iter()
    .map(|s| {
        let sc = parse_scene(&scene(s, extra), "t.toml").unwrap();
        let mut params = sc.params;
        // The same strategy on both paths (the default `auto` is monolithic on the CPU,
        // staggered with a GPU evaluator).
        params.strategy = Strategy::Staggered;
        Member {
            model: sc.model,
            params,
        }
    })
    .collect()
}

fn run(ms: &[Member], exec: &Executor) -> Result<Vec<MemberResult>, String> {
    let mut out: Vec<Option<MemberResult>> = vec![None; ms.len()];
    run_members(
        ms,
        exec,
        BatchOptions {
            keep_history: true,
            keep_state: true,
            workers: 2,
            // `full` reuses a factorization at a step's start on the CPU path only: the
            // GPU paths run it as `fresh`.
            newton: Some(NewtonVariant::Fresh),
            fallback: None,
            cutback: None,
            solve: Default::default(),
            host_update: false,
        },
        |r| {
            let i = r.index;
            out[i] = Some(r);
        },
    )
    .map_err(|e| e.to_string())?;
    Ok(out.into_iter().map(|r| r.unwrap()).collect())
}

/// Asserts that a member ran its 10 steps alike on both paths; returns the largest
/// difference of the final positions relative to their size.
fn same_run(c: &MemberResult, g: &MemberResult) -> f64 {
    assert_eq!(c.outcome.status, g.outcome.status, "{:?}", g.outcome.reason);
    assert_eq!(c.outcome.steps, 10, "{:?}", c.outcome.reason);
    assert_eq!(c.outcome.steps, g.outcome.steps);
    let (sc, sg) = (c.state.as_ref().unwrap(), g.state.as_ref().unwrap());
    let scale = sc.r.iter().fold(0.0f64, |m, x| m.max(x.amax()));
    let d =
        sc.r.iter()
            .zip(&sg.r)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).amax()));
    d / scale
}

#[test]
fn gpu_runs_reference_shapes_damping_and_line_loads_like_the_cpu() {
    let Some(exec) = gpu() else { return };
    let mut ms = members("");
    // The same with the free end guided by a clamp sliding along e3 (a different set of
    // unknowns: the GPU's row masks come from the same numbering).
    ms.extend(members("[[clamp]]\nat = [1, 0, 0]\nslide = [0, 0, 1]"));
    // And along an oblique axis (all components unknown; the host constrains the rows of
    // the assembled system the GPU returns).
    ms.extend(members("[[clamp]]\nat = [1, 0, 0]\nslide = [0, 1, 2]"));
    // And spinning about an oblique slide axis: the end's directors turn about the axis,
    // and EDMC-2's director dissipation (α_Ων, α_Γν) takes the end's share through the
    // element data both kernels read.
    ms.extend(members(
        "[[clamp]]\nat = [1, 0, 0]\nslide = [0, 1, 2]\nspin = true",
    ));
    let cpu = run(&ms, &Executor::Cpu).unwrap();
    let gpu = run(&ms, &exec).unwrap();
    let mut worst = 0.0f64;
    let mut worst_d = 0.0f64;
    for (c, g) in cpu.iter().zip(&gpu) {
        worst = worst.max(same_run(c, g));
        let (hc, hg) = (c.history.last().unwrap(), g.history.last().unwrap());
        assert!(hc.dissipation_total > 0.0, "damping dissipates");
        worst_d =
            worst_d.max((hc.dissipation_total - hg.dissipation_total).abs() / hc.dissipation_total);
        assert!(
            // Measured ≤ 1.1e-15.
            (hc.dissipation_total - hg.dissipation_total).abs() <= 1e-14 * hc.dissipation_total,
            "D {} vs {}",
            hc.dissipation_total,
            hg.dissipation_total
        );
    }
    println!("GPU vs CPU positions: {worst:e}, dissipation {worst_d:.1e}");
    assert!(worst < STATE_RTOL, "positions differ by {worst:e}");
}

/// The inexact strategy (the residual pass evaluates the consistent scalars) with
/// Kelvin–Voigt damping: the device's consistent scalars carry the damping's 2η/Δt as the
/// CPU's do, so every step goes as on the CPU path: the same Newton iterations, no
/// fallback (without it the device's steps missed the dissipation identity and fell back
/// to the monolithic Newton).
#[test]
fn gpu_inexact_strategy_with_damping_runs_like_the_cpu() {
    let Some(exec) = gpu() else { return };
    let ms: Vec<Member> = members("")
        .into_iter()
        .filter(|m| m.params.scheme.is_dissipative())
        .map(|mut m| {
            m.params.strategy = Strategy::Inexact;
            m
        })
        .collect();
    assert_eq!(ms.len(), 2);
    let cpu = run(&ms, &Executor::Cpu).unwrap();
    let gpu = run(&ms, &exec).unwrap();
    let mut worst = 0.0f64;
    for (c, g) in cpu.iter().zip(&gpu) {
        worst = worst.max(same_run(c, g));
        assert_eq!(
            c.outcome.newton_iters_total, g.outcome.newton_iters_total,
            "Newton iterations"
        );
        assert_eq!(
            g.outcome.fallback_steps, 0,
            "fallback steps on the GPU path"
        );
    }
    println!("GPU vs CPU positions, inexact with damping: {worst:e}");
    assert!(worst < STATE_RTOL, "positions differ by {worst:e}");
}

#[test]
fn gpu_runs_driven_supports_like_the_cpu() {
    let Some(exec) = gpu() else { return };
    // The far end twisted and swung by a driven clamp (rotation about e1 and e2, smooth
    // ramp) and the near end carried by a driven pin: the kernels get the prescribed
    // increments of those nodes with the Newton increments.
    let ms = members(
        "[[clamp]]\nat = [1, 0, 0]\nrotation = [0.3, 0.2, 0]\ntime = [0, 0.1]\nfactor = [0, 1]\nramp = \"smooth\"",
    );
    let cpu = run(&ms, &Executor::Cpu).unwrap();
    let gpu = run(&ms, &exec).unwrap();
    let mut worst = 0.0f64;
    let mut worst_wh = (0.0f64, 0.0f64);
    for (c, g) in cpu.iter().zip(&gpu) {
        worst = worst.max(same_run(c, g));
        let (hc, hg) = (c.history.last().unwrap(), g.history.last().unwrap());
        // The support did work, and the same on both paths.
        let w: f64 = c.history.iter().map(|h| h.support_work).sum();
        let wg: f64 = g.history.iter().map(|h| h.support_work).sum();
        assert!(w.abs() > 1e-6, "support work {w:e}");
        worst_wh = (
            worst_wh.0.max((w - wg).abs() / w.abs()),
            worst_wh.1.max((hc.total - hg.total).abs() / hc.total.abs()),
        );
        // Measured ≤ 1.1e-14 (W_sup) and 9.1e-16 (H).
        assert!((w - wg).abs() <= 1e-13 * w.abs(), "W_sup {w:e} vs {wg:e}");
        assert!(
            (hc.total - hg.total).abs() <= 9e-15 * hc.total.abs(),
            "H {} vs {}",
            hc.total,
            hg.total
        );
    }
    println!(
        "GPU vs CPU positions (driven supports): {worst:e}, W_sup {:.1e}, H {:.1e}",
        worst_wh.0, worst_wh.1
    );
    assert!(worst < STATE_RTOL, "positions differ by {worst:e}");
}
