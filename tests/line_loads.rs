//! Line loads (`[[line_load]]`): a dead line load enters exactly like gravity (same
//! consistent load vector, same trajectory); a follower force on a spinning rod turns with
//! it and drives the centre of mass along the analytic curve; the follower terms' tangent
//! equals finite differences of the residual; the energy balance `ΔH = W` and the impulse
//! balance close to round-off with follower loads.

use cosserat::integrator::Simulation;
use cosserat::model::Vec3;
use cosserat::observe::balance::BalanceObserver;
use cosserat::scene::parse_scene;

mod common;

const RHO: f64 = 1000.0;
const A: f64 = 1e-3;

fn scene(elements: usize, extra: &str, integrator: &str) -> String {
    use common::scene_text::{material, rod_scene, section};
    rod_scene(
        "ll",
        &material("m", "1e6", "0.3", RHO),
        &section("s", A, "1e-7", "2e-7"),
        elements,
        extra,
        integrator,
    )
}

fn run(text: &str) -> Simulation {
    let s = parse_scene(text, "t.toml").unwrap();
    let steps = s.params.n_steps();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    for _ in 0..steps {
        sim.step().unwrap();
    }
    sim
}

#[test]
fn dead_line_load_is_gravity() {
    let em = "scheme = \"em\"\ndt = 0.01\nt_end = 0.3";
    let g = 9.81;
    let with_gravity = scene(10, "[[clamp]]\nat = [0, 0, 0]", em).replace(
        "name = \"ll\"",
        &format!("name = \"ll\"\ngravity = [0, 0, -{g}]"),
    );
    let with_load = scene(
        10,
        &format!(
            "[[clamp]]\nat = [0, 0, 0]\n\n[[line_load]]\nrod = \"rod\"\nforce = [0, 0, {}]",
            -RHO * A * g
        ),
        em,
    );
    let (a, b) = (run(&with_gravity), run(&with_load));
    let tip = a.state().r[10];
    assert!(tip.z < -1e-3, "the cantilever sags: {tip}");
    for (x, y) in a.state().r.iter().zip(&b.state().r) {
        assert!((x - y).norm() < 1e-15, "{x} vs {y}"); // measured: identical
    }
}

#[test]
fn follower_force_turns_with_a_spinning_rod() {
    // A free rod spinning about its axis e1 at ω, pushed along its director d1 (= e3 at
    // t = 0) by a follower line force f: the centre of mass moves with
    // v(t) = f/(ρA ω) [sin ωt e3 + (cos ωt − 1) e2].
    let (w, f, dt, t_end) = (2.0 * std::f64::consts::PI, 0.01, 1e-3, 0.5);
    let extra = format!(
        "[[line_load]]\nrod = \"rod\"\nforce = [{f}, 0, 0]\nfollower = true\n\n[[initial_velocity]]\nrod = \"rod\"\nomega = [{w}, 0, 0]"
    );
    let text = scene(
        4,
        &extra,
        &format!("scheme = \"em\"\ndt = {dt}\nt_end = {t_end}"),
    );
    let s = parse_scene(&text, "t.toml").unwrap();
    let steps = s.params.n_steps();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let inv0 = sim.invariants();
    let mut obs = BalanceObserver::new(sim.model(), sim.state(), dt, inv0.l, inv0.j, inv0.total());
    let (mut work, mut worst_energy) = (0.0, 0.0f64);
    for k in 1..=steps {
        let h0 = sim.invariants().total();
        let rep = sim.step().unwrap();
        work += rep.external_work;
        let h1 = sim.invariants().total();
        worst_energy = worst_energy.max((h1 - h0 - rep.external_work).abs() / h1.abs());
        let inv = sim.invariants();
        obs.step(
            sim.model(),
            sim.state(),
            k,
            inv.l,
            inv.j,
            inv.total(),
            work,
            0.0,
        );
    }
    let m = RHO * A;
    let v = sim.invariants().l / m;
    let t = sim.state().t;
    let expect = f / (RHO * A * w) * Vec3::new(0.0, (w * t).cos() - 1.0, (w * t).sin());
    // Measured: velocity error 5.2e-6 (Δt = 1e-3, second order), ΔH − W per step 7e-14,
    // impulse residuals 2e-15 (L) and 1.1e-13 (J), energy balance 3.8e-13.
    let err = (v - expect).norm() / expect.norm();
    assert!(err < 1e-5, "v = {v}, analytic {expect} ({err:e})");
    assert!(worst_energy < 5e-13, "ΔH − W per step {worst_energy:e}");
    let imp = obs.impulse();
    assert!(
        imp.max_rel_residual_l < 1e-13 && imp.max_rel_residual_j < 1e-12,
        "impulse residuals L {:e}, J {:e}",
        imp.max_rel_residual_l,
        imp.max_rel_residual_j
    );
    let e = obs.energy();
    assert!(
        e.max_rel_residual < 1e-12,
        "energy balance {:e}",
        e.max_rel_residual
    );
}

#[test]
fn follower_tangent_matches_finite_differences() {
    // A clamped rod started bent, with a follower force and moment per length.
    let extra = "[rod.initial]\ndisplacement = [[0, 0, 0], [0, 0.02, 0.01], [0, 0.05, 0.03], [0, 0.1, 0.02]]\n\n[[clamp]]\nat = [0, 0, 0]\n\n[[line_load]]\nrod = \"rod\"\nforce = [0.3, -0.2, 0.5]\nmoment = [0.05, 0.1, -0.07]\nfollower = true";
    let s = parse_scene(
        &scene(3, extra, "scheme = \"em\"\ndt = 0.01\nt_end = 1"),
        "t.toml",
    )
    .unwrap();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let n = sim.n_dofs();
    let q: Vec<f64> = (0..n).map(|i| 1e-2 * ((i as f64 * 0.7).sin())).collect();
    let k = sim.dense_tangent_at(&q, false);
    let h = 1e-6;
    let mut worst = 0.0f64;
    let kmax = k.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for j in 0..n {
        let (mut qp, mut qm) = (q.clone(), q.clone());
        qp[j] += h;
        qm[j] -= h;
        let (rp, rm) = (sim.residual_at(&qp, false), sim.residual_at(&qm, false));
        for i in 0..n {
            let fd = (rp[i] - rm[i]) / (2.0 * h);
            worst = worst.max((fd - k[i][j]).abs() / kmax);
        }
    }
    // Measured 2.5e-11 (central differences, h = 1e-6).
    assert!(worst < 2.5e-10, "tangent vs finite differences: {worst:e}");
}

#[test]
fn bad_line_loads_are_named() {
    let em = "scheme = \"em\"\ndt = 0.01\nt_end = 1";
    let cases = [
        (
            "[[line_load]]\nforce = [0, 0, 1]",
            "line_load[0].rod: required key missing",
        ),
        (
            "[[line_load]]\nrod = \"x\"\nforce = [0, 0, 1]",
            "line_load[0].rod: no rod named `x` (rods: rod)",
        ),
        (
            "[[line_load]]\nrod = \"rod\"",
            "line_load[0].force: required key missing (give `force`, `moment` or both)",
        ),
        (
            "[[line_load]]\nrod = \"rod\"\nforce = [0, 0, 1]\ntime = [0, 1]",
            "line_load[0].factor: required key missing (`time` is given)",
        ),
        (
            "[[line_load]]\nrod = \"rod\"\nforce = [0, 0, 1]\nsegment = 2",
            "line_load[0].segment: rod `rod` has segments 0..0 (got 2)",
        ),
    ];
    for (extra, want) in cases {
        let err = parse_scene(&scene(4, extra, em), "bad.toml")
            .expect_err(extra)
            .to_string();
        assert!(err.contains(want), "{extra}\n got: {err}\nwant: {want}");
    }
    let ga = "scheme = \"gen-alpha\"\ndt = 0.01\nt_end = 1";
    let err = parse_scene(
        &scene(
            4,
            "[[line_load]]\nrod = \"rod\"\nforce = [0, 0, 1]\nfollower = true",
            ga,
        ),
        "bad.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("line_load[0].follower: gen-alpha does not support follower loads"),
        "{err}"
    );
}
