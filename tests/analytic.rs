//! Independent reference: the clamped cantilever's first bending frequency against
//! Timoshenko beam theory (0.176794 Hz for the `cantilever` section: L = 1, R = 0.02,
//! E = 1e6, ν = 0.5, ρ = 1000, shear factor 1). The element's one-point stress rule
//! and linear directors give an O(h²) spatial error: an independent implementation of
//! the same element found +1.2e-3, 3.0e-4, 7.6e-5 relative at 10, 20, 40 elements. Here
//! EM runs each mesh from the Euler–Bernoulli first mode shape at small amplitude with
//! Δt = T/800 (EM's period error (ωΔt)²/12 ≈ 5e-6) and the period is the least-squares
//! spacing of the tip's zero crossings; the test asserts the error against Timoshenko,
//! its sign and its fitted order.
use cosserat::integrator::run::run;
use cosserat::integrator::Simulation;
use cosserat::model::Vec3;
use cosserat::observe::record::{RunStatus, StepRecord};
use cosserat::scene::parse_scene;

const TIMOSHENKO_F1: f64 = 0.176794;

fn scene(elements: usize) -> String {
    let r: f64 = 0.02;
    let a = std::f64::consts::PI * r * r;
    let i = a * r * r / 4.0;
    format!(
        "name = \"cantilever{elements}\"\n[material.m]\nE = 1e6\nnu = 0.5\ndensity = 1000\n\
         [section.s]\nA = {a:e}\nI11 = {i:e}\nI22 = {i:e}\nJ = {j:e}\n\
         [[rod]]\nname = \"beam\"\nmaterial = \"m\"\nsection = \"s\"\n\
         points = [[0, 0, 0], [1, 0, 0]]\nelements = {elements}\nd1 = [0, 0, 1]\n\
         [[clamp]]\nat = [0, 0, 0]\n[integrator]\nscheme = \"em\"\ndt = 0.01\nt_end = 1\n",
        j = 2.0 * i
    )
}

/// Euler–Bernoulli clamped–free first mode φ(x) and φ'(x), x = s/L.
fn mode(x: f64) -> (f64, f64) {
    let b = 1.875_104_068_711_961_f64;
    let sigma = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let y = b * x;
    (
        y.cosh() - y.cos() - sigma * (y.sinh() - y.sin()),
        b * (y.sinh() + y.sin() - sigma * (y.cosh() - y.cos())),
    )
}

/// First bending frequency [Hz] of the discrete rod, from the tip's zero crossings.
fn measured_f1(elements: usize) -> f64 {
    let s = parse_scene(&scene(elements), "cantilever.toml").unwrap();
    let mut model = s.model.clone();
    let f_guess = TIMOSHENKO_F1;
    let period = 1.0 / f_guess;
    let amp = 1e-4; // tip velocity amplitude / (ω L): linear regime
    let w = 2.0 * std::f64::consts::PI * f_guess;
    let (phi_tip, _) = mode(1.0);
    // Motion along y (d2 = z × x = y for d1 = z): bending about d1.
    for a in 0..model.n_nodes() {
        let x = model.nodes[a].x;
        let (phi, dphi) = mode(x);
        let v = w * amp / phi_tip;
        model.velocity0[a] = Vec3::new(0.0, v * phi, 0.0);
        model.omega0[a] = Vec3::new(0.0, 0.0, v * dphi);
    }
    let mut params = s.params;
    params.dt = period / 800.0;
    params.t_end = 2.6 * period;
    let mut sim = Simulation::new(model, params).unwrap();
    let tip = sim.model().n_nodes() - 1;
    let mut prev: (f64, f64) = (0.0, 0.0);
    let mut crossings: Vec<f64> = Vec::new();
    let out = run(&mut sim, 1, |r: &StepRecord, s: &Simulation| {
        let y = s.state().r[tip].y;
        let (t0, y0) = prev;
        if r.t > 0.25 * period && y0 != 0.0 && y0.signum() != y.signum() {
            crossings.push(t0 + (r.t - t0) * y0 / (y0 - y));
        }
        prev = (r.t, y);
        Ok::<(), ()>(())
    })
    .unwrap();
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.reason);
    assert!(crossings.len() >= 4, "{crossings:?}");
    // Least-squares slope of crossing time against index = half a period.
    let n = crossings.len() as f64;
    let mk = (n - 1.0) / 2.0;
    let mt = crossings.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, t) in crossings.iter().enumerate() {
        sxy += (k as f64 - mk) * (t - mt);
        sxx += (k as f64 - mk).powi(2);
    }
    1.0 / (2.0 * sxy / sxx)
}

#[test]
fn first_bending_frequency_converges_to_timoshenko_at_order_two() {
    let meshes = [10usize, 20, 40];
    let errs: Vec<f64> = meshes
        .iter()
        .map(|&n| measured_f1(n) / TIMOSHENKO_F1 - 1.0)
        .collect();
    eprintln!("relative errors against Timoshenko at {meshes:?} elements: {errs:?}");
    // Above Timoshenko (the element is stiff), as the independent implementation found:
    // +1.2e-3, 3.0e-4, 7.6e-5.
    for (&n, &e) in meshes.iter().zip(&errs) {
        assert!(e > 0.0, "{n} elements: f1 below Timoshenko by {e:e}");
    }
    let reference = [1.2e-3, 3.0e-4, 7.6e-5];
    for ((&n, &e), &r) in meshes.iter().zip(&errs).zip(&reference) {
        assert!(
            (e / r - 1.0).abs() < 0.05,
            "{n} elements: error {e:e} against the independent {r:e}"
        );
    }
    // Measured here: +1.198e-3, 3.00e-4, 7.42e-5 (within 2.3 % of the independent figures).
    // Fitted order of the spatial error over the three meshes (measured 2.006).
    let pts: Vec<(f64, f64)> = meshes
        .iter()
        .zip(&errs)
        .map(|(&n, &e)| ((1.0 / n as f64).ln(), e.ln()))
        .collect();
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / 3.0;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / 3.0;
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
        / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    eprintln!("fitted order {slope:.3}");
    assert!((slope - 2.0).abs() < 0.05, "order {slope}");
}
