//! A stability study run as one GPU batch gives the same cells as on the CPU: the same
//! status and time reached in every cell, energy growth equal to round-off (both Newton
//! solves converge to 1e-11 of the force scale from round-off-different element blocks).
//! The baseline (mid-point) member rides in the batch on the CPU kernel.
//!
//! Without an adapter this prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU` is
//! set (CI sets it), in which case it fails.
use cosserat::batch::{BackendChoice, Executor};
use cosserat::integrator::{NewtonVariant, Strategy};
use cosserat::scene::load_scene;
use cosserat::study::{stability, stability_on, SchemeKind, StabilityConfig};

#[test]
fn stability_grid_on_the_gpu_matches_the_cpu() {
    let exec = match Executor::resolve(BackendChoice::Gpu, None) {
        Ok((e, _)) => e,
        Err(e) if std::env::var_os("COSSERAT_REQUIRE_GPU").is_none() => {
            println!("skipped: no adapter ({e})");
            return;
        }
        Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no usable adapter: {e}"),
    };
    let mut scene = load_scene("frame").unwrap();
    // `full` reuses a factorization at a step's start on the CPU path only (the GPU paths
    // run it as `fresh`): compare like with like.
    scene.params.newton = NewtonVariant::Fresh;
    // The same strategy on both paths (the default `auto` is monolithic on the CPU,
    // staggered with a GPU evaluator).
    scene.params.strategy = Strategy::Staggered;
    let cfg = StabilityConfig {
        kinds: vec![SchemeKind::Em, SchemeKind::Edmc2, SchemeKind::Midpoint],
        params: vec![0.5],
        rho_infs: vec![],
        dts: vec![0.2, 0.8],
        t_end: 1.6,
        jobs: 2,
    };
    let gpu = stability_on(&scene, &cfg, &exec).unwrap();
    let cpu = stability(&scene, &cfg).unwrap();
    assert_eq!(gpu.cells.len(), cpu.cells.len());
    let worst = gpu
        .cells
        .iter()
        .zip(&cpu.cells)
        .map(|(g, c)| {
            (g.max_energy_growth - c.max_energy_growth).abs() / c.max_energy_growth.abs().max(1.0)
        })
        .fold(0.0f64, f64::max);
    // Measured 2.7e-15 (bound 2e-14 below).
    println!("stability grid GPU vs CPU: max energy growth differs by {worst:.1e}");
    for (g, c) in gpu.cells.iter().zip(&cpu.cells) {
        let tag = format!("{} {} Δt={}", g.kind.name(), g.param, g.dt);
        assert_eq!((g.kind, g.param, g.dt), (c.kind, c.param, c.dt));
        assert_eq!(g.status, c.status, "{tag}");
        assert!((g.t_reached - c.t_reached).abs() < 1e-12, "{tag}");
        assert!(
            (g.max_energy_growth - c.max_energy_growth).abs()
                <= 2e-14 * c.max_energy_growth.abs().max(1.0),
            "{tag}: growth {} vs {}",
            g.max_energy_growth,
            c.max_energy_growth
        );
    }
    // The grid holds both outcomes, so the comparison covers failed members too.
    assert!(cpu.cells.iter().any(|c| c.fraction() < 1.0));
    assert!(cpu.cells.iter().any(|c| c.fraction() == 1.0));
}
