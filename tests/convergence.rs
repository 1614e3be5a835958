//! Observed temporal order (DESIGN §5): EM and EDMC-2 converge at order 2 in Δt, EDMC-1
//! (with χ_Γ > 0) at order 1. Self-convergence of the tip position of a clamped rod
//! started with a smooth velocity field (a problem inside the asymptotic range, unlike the
//! frame whose highest mode sits at ≈310 rad/s).
mod common;

use cosserat::integrator::{IntegratorParams, Scheme, Simulation};
use cosserat::model::{Support, Vec3};

fn tip_at_end(scheme: Scheme, dt: f64, t_end: f64) -> Vec3 {
    let len = 1.0;
    let mut m = common::polylines(
        &[(
            vec![Vec3::zeros(), Vec3::new(len, 0.0, 0.0)],
            8,
            Vec3::new(0.0, 1.0, 0.0),
        )],
        (1e4, 0.3, 10.0, 1e-2, 1e-4, 2e-4),
    );
    m.supports[0] = Support {
        translation: true,
        rotation: true,
    };
    for (a, x) in m.nodes.clone().iter().enumerate() {
        let s = x.x / len;
        m.velocity0[a] = Vec3::new(0.0, 0.3 * s * s, 0.2 * s * s);
    }
    let tip = m
        .nodes
        .iter()
        .position(|x| (x.x - len).abs() < 1e-12)
        .unwrap();
    let mut p = IntegratorParams::new(scheme, dt, t_end);
    p.newton_tol = 1e-11;
    let mut sim = Simulation::new(m, p).unwrap();
    for _ in 0..sim.params().n_steps() {
        sim.step()
            .unwrap_or_else(|f| panic!("{scheme:?} dt={dt}: {f:?}"));
    }
    sim.state().r[tip]
}

fn observed_order(scheme: Scheme) -> f64 {
    let t_end = 0.05;
    let dts = [4e-4, 2e-4, 1e-4];
    let reference = tip_at_end(scheme, 1.25e-5, t_end);
    let err: Vec<f64> = dts
        .iter()
        .map(|&dt| (tip_at_end(scheme, dt, t_end) - reference).norm())
        .collect();
    println!("{scheme:?}: errors {err:?}");
    (err[1] / err[2]).log2()
}

#[test]
fn em_is_second_order() {
    let p = observed_order(Scheme::Em);
    assert!((p - 2.0).abs() < 0.25, "EM order {p}");
}

#[test]
fn edmc2_is_second_order() {
    let p = observed_order(Scheme::Edmc2 {
        alpha_gv: 0.5,
        alpha_gn: 0.0,
        alpha_ov: 0.0,
        alpha_on: 0.0,
    });
    assert!((p - 2.0).abs() < 0.25, "EDMC-2 order {p}");
}

#[test]
fn edmc1_is_first_order() {
    let p = observed_order(Scheme::Edmc1 {
        chi_gamma: 0.2,
        chi_omega: 0.2,
        chi_v: 0.0,
        chi_nu: 0.0,
    });
    assert!((p - 1.0).abs() < 0.25, "EDMC-1 order {p}");
}
