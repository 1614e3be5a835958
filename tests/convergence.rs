//! Observed temporal order (DESIGN §5): EM and EDMC-2 converge at order 2 in Δt, EDMC-1
//! (with χ_Γ > 0) at order 1: the slope fitted over four step sizes of the tip position's
//! error against an independently integrated reference (generalized-α), for a clamped rod
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

/// The reference solution, computed independently of the schemes under test: the Lie-group
/// generalized-α integrator (ρ∞ = 1, a Newmark-type scheme on `(r, Λ)`, not the director
/// formulation's time discretization) at Δt = 3.125e-6, whose own error is ≈ 1e-3 of the
/// finest error below.
fn reference() -> Vec3 {
    static REF: std::sync::OnceLock<Vec3> = std::sync::OnceLock::new();
    *REF.get_or_init(|| tip_at_end(Scheme::GenAlpha { rho_inf: 1.0 }, 3.125e-6, T_END))
}

const T_END: f64 = 0.05;

/// Step sizes inside each order's asymptotic range: at 4e-4 the second-order error still
/// falls by 4.2× per halving, and EDMC-1's first-order error by only 1.75× (its Δt² part).
const SECOND_ORDER_DTS: [f64; 4] = [2e-4, 1e-4, 5e-5, 2.5e-5];
const FIRST_ORDER_DTS: [f64; 4] = [1e-4, 5e-5, 2.5e-5, 1.25e-5];

/// Least-squares slope of log(error) against log(Δt) over `dts`.
fn observed_order(scheme: Scheme, dts: [f64; 4]) -> f64 {
    let reference = reference();
    let err: Vec<f64> = dts
        .iter()
        .map(|&dt| (tip_at_end(scheme, dt, T_END) - reference).norm())
        .collect();
    let pts: Vec<(f64, f64)> = dts
        .iter()
        .zip(&err)
        .map(|(d, e)| (d.ln(), e.ln()))
        .collect();
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
        / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    eprintln!("{scheme:?}: errors {err:?}, fitted order {slope:.3}");
    slope
}

// Windows at ≤ 10× the measured deviation from the theoretical order (measured: EM 2.015,
// EDMC-2 2.015, EDMC-1 0.980; see the printed fits).
const ORDER_WINDOW: f64 = 0.05;

#[test]
fn em_is_second_order() {
    let p = observed_order(Scheme::Em, SECOND_ORDER_DTS);
    assert!((p - 2.0).abs() < ORDER_WINDOW, "EM order {p}");
}

#[test]
fn edmc2_is_second_order() {
    let p = observed_order(
        Scheme::Edmc2 {
            alpha_gv: 0.5,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        },
        SECOND_ORDER_DTS,
    );
    assert!((p - 2.0).abs() < ORDER_WINDOW, "EDMC-2 order {p}");
}

#[test]
fn edmc1_is_first_order() {
    let p = observed_order(
        Scheme::Edmc1 {
            chi_gamma: 0.2,
            chi_omega: 0.2,
            chi_v: 0.0,
            chi_nu: 0.0,
        },
        FIRST_ORDER_DTS,
    );
    assert!((p - 1.0).abs() < ORDER_WINDOW, "EDMC-1 order {p}");
}
