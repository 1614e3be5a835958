//! Conservation invariants of DESIGN §5 on the free-flying frame (staircase, 15
//! elements), asserted at ≤ 10× their measured level (issue 20): L and J to ≤ 5e-14
//! relative per step for EM, EDMC-1 and EDMC-2 under both dissipation strategies (measured
//! ≤ 8.0e-15); H exact for EM (≤ 4e-12 per step, measured 4.4e-13); for EDMC, H never grows
//! and its drop equals the predicted dissipation D to ≤ 1e-9 of H0 with the staggered
//! loop, which closes the identity to `outer_tol` = 1e-10 (measured 9.9e-11), and to
//! ≤ 1e-11 with the monolithic Newton (measured 9.8e-13).
mod common;

use cosserat::integrator::{IntegratorParams, Scheme, Simulation, Strategy};
use cosserat::model::Vec3;

/// Per-step relative change of L and J: round-off (measured ≤ 8.0e-15).
const MOMENTUM_RTOL: f64 = 5e-14;
/// Per-step relative change of H for EM: round-off (measured ≤ 4.4e-13).
const EM_ENERGY_RTOL: f64 = 4e-12;
/// Miss of the identity H_n − H_{n+1} = D relative to H0, staggered loop: closed to
/// `outer_tol` = 1e-10 per step (measured ≤ 9.9e-11).
const DISSIPATION_RTOL: f64 = 1e-9;
/// The same with the monolithic Newton, which solves the identity with the step
/// (measured ≤ 9.8e-13).
const DISSIPATION_RTOL_MONOLITHIC: f64 = 1e-11;

struct Level {
    h: f64,
    d: f64,
    l: Vec3,
    j: Vec3,
}

fn run(
    model: cosserat::model::Model,
    scheme: Scheme,
    strategy: Strategy,
    dt: f64,
    steps: usize,
) -> Vec<Level> {
    let mut p = IntegratorParams::new(scheme, dt, dt * steps as f64);
    p.strategy = strategy;
    let mut sim = Simulation::new(model, p).unwrap();
    let inv = sim.invariants();
    let mut out = vec![Level {
        h: inv.total(),
        d: 0.0,
        l: inv.l,
        j: inv.j,
    }];
    for _ in 0..steps {
        let rep = sim
            .step()
            .unwrap_or_else(|f| panic!("{scheme:?} {strategy:?}: {f:?}"));
        let inv = sim.invariants();
        out.push(Level {
            h: inv.total(),
            d: rep.dissipation,
            l: inv.l,
            j: inv.j,
        });
    }
    out
}

/// The frame with a spin added, so that director velocities (and director dissipation)
/// are exercised from the first step.
fn spinning_frame() -> cosserat::model::Model {
    let mut m = common::frame();
    for w in m.omega0.iter_mut() {
        *w = Vec3::new(0.05, -0.02, 0.03);
    }
    m
}

fn check_invariants(levels: &[Level], dissipative: bool, label: &str) {
    let h0 = levels[0].h;
    // Per step: relative changes of L and J, and EM's relative change of H or EDMC's
    // identity miss relative to H0.
    let steps: Vec<(f64, f64, f64)> = levels
        .windows(2)
        .map(|w| {
            let (a, b) = (&w[0], &w[1]);
            let e = if dissipative {
                (a.h - b.h - b.d).abs() / h0
            } else {
                (b.h - a.h).abs() / a.h
            };
            (
                (b.l - a.l).norm() / a.l.norm(),
                (b.j - a.j).norm() / a.j.norm(),
                e,
            )
        })
        .collect();
    // Largest measured values, printed for docs/testing.md (`--nocapture`).
    let max = |f: fn(&(f64, f64, f64)) -> f64| steps.iter().map(f).fold(0.0, f64::max);
    eprintln!(
        "{label}: max dL {:.1e}, dJ {:.1e}, {} {:.1e}",
        max(|s| s.0),
        max(|s| s.1),
        if dissipative { "identity miss" } else { "dH" },
        max(|s| s.2)
    );
    let lower = label.to_lowercase();
    let identity_rtol = if lower.contains("monolithic") || lower.contains("inexact") {
        DISSIPATION_RTOL_MONOLITHIC
    } else {
        DISSIPATION_RTOL
    };
    for (n, (w, &(dl, dj, e))) in levels.windows(2).zip(&steps).enumerate() {
        let (a, b) = (&w[0], &w[1]);
        assert!(dl <= MOMENTUM_RTOL, "{label} step {n}: dL {dl:e}");
        assert!(dj <= MOMENTUM_RTOL, "{label} step {n}: dJ {dj:e}");
        if dissipative {
            assert!(b.h <= a.h, "{label} step {n}: energy grew {:e}", b.h - a.h);
            assert!(e <= identity_rtol, "{label} step {n}: identity miss {e:e}");
        } else {
            assert!(e <= EM_ENERGY_RTOL, "{label} step {n}: dH {e:e}");
        }
    }
}

#[test]
fn frame_initial_values_match_reference() {
    let sim =
        Simulation::new(common::frame(), IntegratorParams::new(Scheme::Em, 0.2, 1.0)).unwrap();
    let inv = sim.invariants();
    // Reference values of an independent implementation (DESIGN §6).
    assert!((inv.total() - 9.166_666_666_666_666).abs() < 1e-12);
    assert!((inv.l - Vec3::new(0.0, -5.0, 7.5)).norm() < 1e-12);
    assert!((inv.j - Vec3::new(5.0, -95.0, -50.0)).norm() < 1e-10);
}

#[test]
fn em_conserves_energy_and_momenta() {
    for dt in [0.2, 0.05] {
        let lv = run(spinning_frame(), Scheme::Em, Strategy::Monolithic, dt, 50);
        check_invariants(&lv, false, &format!("em dt={dt}"));
    }
}

#[test]
fn edmc2_frame_matches_reference_and_dissipates_monotonically() {
    let s = Scheme::Edmc2 {
        alpha_gv: 0.5,
        alpha_gn: 0.0,
        alpha_ov: 0.0,
        alpha_on: 0.0,
    };
    for strategy in [Strategy::Monolithic, Strategy::Staggered, Strategy::Inexact] {
        let lv = run(common::frame(), s, strategy, 0.2, 50);
        check_invariants(&lv, true, &format!("edmc2 {strategy:?}"));
        // Independent implementation: H(t=10) = 9.15148.
        let hend = lv.last().unwrap().h;
        assert!(
            (hend - 9.15148).abs() < 5e-6,
            "{strategy:?}: H(10) = {hend}"
        );
    }
}

#[test]
fn edmc2_all_four_alphas_conserve_momenta_and_dissipate() {
    let s = Scheme::Edmc2 {
        alpha_gv: 0.5,
        alpha_gn: 0.3,
        alpha_ov: 0.2,
        alpha_on: 0.4,
    };
    for strategy in [Strategy::Monolithic, Strategy::Inexact] {
        let lv = run(spinning_frame(), s, strategy, 0.2, 30);
        check_invariants(&lv, true, &format!("edmc2 coupled {strategy:?}"));
        assert!(
            lv[0].h - lv.last().unwrap().h > 1e-6,
            "coupled EDMC-2 must dissipate"
        );
    }
}

#[test]
fn edmc1_conserves_momenta_and_dissipates() {
    let s = Scheme::Edmc1 {
        chi_gamma: 0.1,
        chi_omega: 0.1,
        chi_v: 0.2,
        chi_nu: 0.2,
    };
    for strategy in [Strategy::Monolithic, Strategy::Staggered, Strategy::Inexact] {
        let lv = run(spinning_frame(), s, strategy, 0.2, 30);
        check_invariants(&lv, true, &format!("edmc1 {strategy:?}"));
        assert!(lv[0].h - lv.last().unwrap().h > 1e-4);
    }
}

#[test]
fn momenta_are_independent_of_dt_and_alpha() {
    for (dt, alpha) in [(0.2, 2.0), (0.01, 0.5), (0.1, 5.0)] {
        let s = Scheme::Edmc2 {
            alpha_gv: alpha,
            alpha_gn: 0.0,
            alpha_ov: 0.0,
            alpha_on: 0.0,
        };
        for strategy in [Strategy::Monolithic, Strategy::Staggered, Strategy::Inexact] {
            let lv = run(common::frame(), s, strategy, dt, 10);
            check_invariants(&lv, true, &format!("dt={dt} alpha={alpha} {strategy:?}"));
        }
    }
}

/// A straight unstressed rod spinning about its own axis is a relative equilibrium:
/// strains stay constant, speeds stay constant, and no scheme dissipates anything.
#[test]
fn relative_equilibrium_dissipates_nothing() {
    let mut m = common::polylines(
        &[(
            vec![Vec3::zeros(), Vec3::new(2.0, 0.0, 0.0)],
            6,
            Vec3::new(0.0, 1.0, 0.0),
        )],
        (1e4, 0.3, 100.0, 0.01, 1e-5, 2e-5),
    );
    for w in m.omega0.iter_mut() {
        *w = Vec3::new(3.0, 0.0, 0.0);
    }
    let s = Scheme::Edmc2 {
        alpha_gv: 1.0,
        alpha_gn: 1.0,
        alpha_ov: 1.0,
        alpha_on: 1.0,
    };
    let lv = run(m, s, Strategy::Monolithic, 0.05, 40);
    let h0 = lv[0].h;
    assert!(h0 > 0.0);
    let (md, mh) = lv.iter().fold((0.0f64, 0.0f64), |(a, b), l| {
        (a.max(l.d.abs() / h0), b.max((l.h - h0).abs() / h0))
    });
    eprintln!("relative equilibrium: max D {md:.1e}, max |H − H0| {mh:.1e} of H0");
    // D vanishes by structure (measured 4.1e-46 of H0: round-off of zero); H is constant
    // to round-off (measured 3.9e-15).
    for l in &lv {
        assert!(l.d.abs() <= 1e-40 * h0, "dissipation {:e}", l.d);
        assert!((l.h - h0).abs() <= 4e-14 * h0);
    }
}
