//! The paper's three examples (DESIGN §6) on the built-in scenes, asserted as our runs
//! show them (the honesty rule of issue 3: where the paper's EM failures do not appear, the
//! test pins what does happen, with the reason in a comment).
use cosserat::integrator::run::{run, RunOutcome};
use cosserat::integrator::{Scheme, Simulation, Strategy};
use cosserat::observe::record::{RunStatus, StepRecord};
use cosserat::scene::load_scene;

mod common;

/// Runs a built-in scene with `scheme`, `dt`, `t_end` (staggered EDMC with the default
/// monolithic fallback); every level recorded.
fn simulate(
    scene: &str,
    scheme: Scheme,
    dt: f64,
    t_end: f64,
    planar: bool,
) -> (RunOutcome, Vec<StepRecord>, Simulation) {
    simulate_with(scene, scheme, dt, t_end, planar, Strategy::Staggered, true)
}

fn simulate_with(
    scene: &str,
    scheme: Scheme,
    dt: f64,
    t_end: f64,
    planar: bool,
    strategy: Strategy,
    fallback: bool,
) -> (RunOutcome, Vec<StepRecord>, Simulation) {
    let s = load_scene(scene).unwrap();
    let mut params = s.params;
    params.strategy = strategy;
    params.fallback = fallback;
    params.scheme = scheme;
    params.dt = dt;
    params.t_end = t_end;
    let mut model = s.model.clone();
    if !planar {
        model.planar = None;
    }
    let mut sim = Simulation::new(model, params).unwrap();
    let (out, recs) = common::run_recording(&mut sim);
    (out, recs, sim)
}

/// Largest change of H from the first record, and largest change per step, both relative
/// to the first record's H (printed beside the EM energy assertions).
fn energy_drift(recs: &[&StepRecord]) -> (f64, f64) {
    let h = recs[0].total;
    let drift = recs
        .iter()
        .map(|r| (r.total - h).abs() / h)
        .fold(0.0, f64::max);
    let per_step = recs
        .windows(2)
        .map(|w| (w[1].total - w[0].total).abs() / h)
        .fold(0.0, f64::max);
    (drift, per_step)
}

/// Largest per-step increase of H relative to max |H|, over steps after `t_load_end`.
fn max_growth_after(recs: &[StepRecord], t_load_end: f64) -> f64 {
    let href = recs.iter().fold(0.0f64, |m, r| m.max(r.total.abs()));
    recs.windows(2)
        .filter(|w| w[0].t >= t_load_end - 1e-12)
        .map(|w| (w[1].total - w[0].total) / href)
        .fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn frame_conserves_momenta_and_energy_as_the_paper_says() {
    for alpha in [0.0, 0.5] {
        let scheme = if alpha == 0.0 {
            Scheme::Em
        } else {
            Scheme::edmc2(alpha)
        };
        let (out, recs, _) = simulate("frame", scheme, 0.2, 10.0, false);
        assert_eq!(out.status, RunStatus::Completed);
        assert_eq!(out.steps, 50);
        let (l0, j0) = (recs[0].l, recs[0].j);
        let h0 = recs[0].total;
        eprintln!(
            "frame α={alpha}: max L drift {:.1e}, J drift {:.1e}, max |ΔH| per step {:.1e} of H0",
            recs.iter()
                .map(|r| (r.l - l0).norm() / l0.norm())
                .fold(0.0, f64::max),
            recs.iter()
                .map(|r| (r.j - j0).norm() / j0.norm())
                .fold(0.0, f64::max),
            recs.windows(2)
                .map(|w| (w[1].total - w[0].total).abs() / h0)
                .fold(0.0, f64::max)
        );
        for r in &recs {
            // Round-off: measured ≤ 1.9e-15 (L), 3.0e-15 (J) over the 50 steps.
            assert!(
                (r.l - l0).norm() <= 2e-14 * l0.norm(),
                "α={alpha} L drift at t={}",
                r.t
            );
            assert!(
                (r.j - j0).norm() <= 2e-14 * j0.norm(),
                "α={alpha} J drift at t={}",
                r.t
            );
        }
        for w in recs.windows(2) {
            if alpha == 0.0 {
                // Round-off: measured ≤ 5.8e-13 per step.
                assert!(
                    (w[1].total - w[0].total).abs() <= 5e-12 * h0,
                    "EM: H not exact at t={}",
                    w[1].t
                );
            } else {
                assert!(w[1].total <= w[0].total, "EDMC-2: H grew at t={}", w[1].t);
            }
        }
        if alpha > 0.0 {
            // Independent reference (DESIGN §6): 9.15148 at t = 10.
            assert!((recs.last().unwrap().total - 9.15148).abs() < 5e-6);
        }
    }
}

#[test]
fn arch_edmc2_runs_to_2000_and_snaps_through() {
    let (out, recs, _) = simulate("arch", Scheme::edmc2(1.0), 1.0, 2000.0, true);
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.reason);
    assert_eq!(out.steps, 2000);
    // Unloaded after t = 1000: energy never grows; EDMC-2 dissipates, but (DESIGN §6) very
    // little — its dissipation follows changes of speed, not the snap-through itself.
    assert!(max_growth_after(&recs, 1000.0) <= 1e-9);
    let at = |t: f64| recs.iter().find(|r| (r.t - t).abs() < 1e-9).unwrap().total;
    let (h_unload, h_end) = (at(1001.0), at(2000.0));
    assert!(h_end <= h_unload && (h_unload - h_end) < 8e-7 * h_unload);
    // The apex (node 15, rise 3.15) went through the chord: the arch snapped.
    let (_, _, sim_1100) = simulate("arch", Scheme::edmc2(1.0), 1.0, 1087.0, true);
    eprintln!("arch apex at t = 1087: {}", sim_1100.state().r[15].z);
    // Measured −3.11 (the apex far through, as docs/benchmarks.md says: below −3).
    assert!(
        sim_1100.state().r[15].z < -3.0,
        "apex at {}",
        sim_1100.state().r[15].z
    );
}

/// EM in the arch, as observed: it does NOT fail (the paper reports a failure after
/// t ≈ 1163). With our reconstruction (rise 3.15, DESIGN §6.2) and a standard Newton, EM
/// completes to t = 2000 with the energy held to round-off after the load is removed; an
/// independent implementation saw the same. The paper's failure may depend on its solver or
/// on geometry its text does not give.
#[test]
fn arch_em_completes_with_exact_energy_as_observed() {
    let (out, recs, _) = simulate("arch", Scheme::Em, 1.0, 2000.0, true);
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.reason);
    let after: Vec<&StepRecord> = recs.iter().filter(|r| r.t >= 1001.0).collect();
    let h = after[0].total;
    let (drift, per_step) = energy_drift(&after);
    eprintln!("arch EM: max |H − H(1001)| {drift:.1e} of H, max per step {per_step:.1e}");
    // Round-off over 1000 steps: measured ≤ 2.1e-12.
    for r in &after {
        assert!(
            (r.total - h).abs() <= 2e-11 * h,
            "EM energy moved at t={}",
            r.t
        );
    }
}

/// The mechanisms at the paper's three steps. Observed (and asserted), with the coupler's
/// 4 elements guarded against the director interpolation's soft branch (an accepted step
/// never turns an element's end triads more than 2 rad apart, see
/// `accept::MAX_ELEMENT_TURN`):
/// * square parallelogram (`mechanism`): both schemes complete at Δt = 0.005 (coupler
///   length ≤ 1.04, element turns ≤ 0.54 rad). At Δt = 0.05 the paper's pure staggered
///   loop fails at t = 5.5 (Newton), the monolithic fallback's solution of that step would
///   turn element 2 by 2.16 rad and is refused; EM fails near t = 6.75 (Newton). At
///   Δt = 0.01 both schemes are refused where the coupler starts to stretch (EM t = 6.44,
///   EDMC-2 α = 5 t = 8.07). Before the guard these runs "completed" with the unit
///   coupler stretched to 28 (Δt = 0.01) and 77 (Δt = 0.05) units, every energy law held:
///   the square four-bar passes its flat (change-point) configuration every half turn and
///   must bend the coupler hard, which 4 elements resolve only at the small step.
/// * half hexagon (`mechanism_hexagon`): both schemes complete at all three steps
///   (coupler length ≤ 1.07, turns ≤ 0.5 rad).
///
/// In every accepted step every link holds its tolerance, and with the load gone
/// (t > 0.5) the energy never grows (EDMC-2) or stays constant (EM) up to the multiplier
/// update between steps (|Δλ|·|g| with |g| ≤ 1e-10).
#[test]
fn mechanisms_as_observed() {
    const NEWTON: &str = "Newton did not converge";
    const TURN: &str = "end triads are turned";
    /// Failure window (t_lo, t_hi) and a word of the reason; `None`: the run completes.
    type Failure = Option<(f64, f64, &'static str)>;
    let cases: [(&str, bool, f64, f64, Failure); 11] = [
        // (scene, em?, alpha, dt, None = completes | Some(failure window, reason)); EDMC-2
        // staggered with the default fallback, except the first row (the paper's pure
        // staggered loop).
        ("mechanism", false, 0.5, 0.05, Some((5.4, 5.6, NEWTON))),
        ("mechanism", false, 0.5, 0.05, Some((5.4, 5.6, TURN))),
        ("mechanism", true, 0.0, 0.05, Some((6.6, 6.9, NEWTON))),
        ("mechanism", false, 5.0, 0.01, Some((7.9, 8.2, TURN))),
        ("mechanism", true, 0.0, 0.01, Some((6.3, 6.6, TURN))),
        ("mechanism", false, 5.0, 0.005, None),
        ("mechanism", true, 0.0, 0.005, None),
        ("mechanism_hexagon", false, 0.5, 0.05, None),
        ("mechanism_hexagon", true, 0.0, 0.05, None),
        ("mechanism_hexagon", false, 5.0, 0.01, None),
        ("mechanism_hexagon", false, 5.0, 0.005, None),
    ];
    let monolithic = [
        ("mechanism", 0.5, 0.05, Some((5.4, 5.6, TURN))),
        ("mechanism", 5.0, 0.01, Some((9.1, 9.4, TURN))),
        ("mechanism_hexagon", 0.5, 0.05, None),
    ];
    let all = cases
        .iter()
        .enumerate()
        .map(|(i, &(sc, em, a, dt, f))| (sc, em, a, dt, f, Strategy::Staggered, i != 0))
        .chain(
            monolithic
                .iter()
                .map(|&(sc, a, dt, f)| (sc, false, a, dt, f, Strategy::Monolithic, true)),
        );
    for (scene, em, alpha, dt, failure, strategy, fallback) in all {
        let scheme = if em { Scheme::Em } else { Scheme::edmc2(alpha) };
        let (out, recs, sim) = simulate_with(scene, scheme, dt, 10.0, true, strategy, fallback);
        let scheme_name = format!("{} {strategy:?} fallback {fallback}", scheme.name());
        let tag = format!("{scene} {scheme_name} α={alpha} Δt={dt}");
        match failure {
            None => assert_eq!(out.status, RunStatus::Completed, "{tag}: {:?}", out.reason),
            Some((lo, hi, why)) => {
                assert_eq!(
                    out.status,
                    RunStatus::Failed,
                    "{tag} was expected to fail (as observed)"
                );
                assert!(
                    out.t_reached > lo && out.t_reached < hi,
                    "{tag}: failed at t = {} outside the observed window ({lo}, {hi})",
                    out.t_reached
                );
                let reason = out.reason.as_deref().unwrap_or("");
                assert!(reason.contains(why), "{tag}: unexpected reason {reason}");
            }
        }
        // The coupler keeps its length in every accepted state (measured ≤ 1.21 where a
        // run is refused, ≤ 1.07 in the completed runs).
        let st = sim.state();
        let len: f64 = sim
            .model()
            .elements
            .iter()
            .map(|e| (st.r[e.nodes[1]] - st.r[e.nodes[0]]).norm())
            .sum();
        assert!(
            len < 1.3 * sim.model().rods.len() as f64,
            "{tag}: coupler length {len}"
        );
        for r in &recs {
            assert!(
                r.max_link_g <= 1e-10,
                "{tag}: link strain {} at t={}",
                r.max_link_g,
                r.t
            );
        }
        for link in &sim.model().links {
            assert!(link.strain(&sim.state().r[link.node]).abs() <= link.tol);
        }
        let growth = max_growth_after(&recs, 0.5);
        eprintln!(
            "{tag}: max growth after the load {growth:.1e}, max link g {:.1e}",
            recs.iter().map(|r| r.max_link_g).fold(0.0, f64::max)
        );
        assert!(
            growth <= 1e-9,
            "{tag}: energy grew by {growth:e} (relative) after the load"
        );
        if em {
            let after: Vec<&StepRecord> = recs.iter().filter(|r| r.t >= 0.5 - 1e-12).collect();
            let h = after[0].total;
            let (drift, per_step) = energy_drift(&after);
            eprintln!("{tag}: EM max |H − H(0.5)| {drift:.1e} of H, per step {per_step:.1e}");
            for r in &after {
                assert!(
                    (r.total - h).abs() <= 1e-8 * h,
                    "{tag}: EM energy moved at t={}",
                    r.t
                );
            }
        }
    }
}

/// The square mechanism with its coupler meshed by 16 elements instead of the paper's 4:
/// the buckled coupler that the 4-element mesh cannot represent (at t ≈ 5.3 it bends by
/// ≈ 2 rad over 4 elements; the next step would turn one element 2.16 rad, the soft
/// branch, and a Newton step limiter converges to the same root) is resolved, and EDMC-2
/// runs the paper's three steps to t = 10 as the paper reports (α = 0.5 at Δt = 0.05,
/// α = 5 at 0.01 and 0.005), physically: the coupler's length stays within 10 % of 1
/// (measured 0.977–1.021, 0.961–1.038, 0.920–1.072; EA = 2000 against the masses'
/// inertia) and no element turns more than 0.3 rad (measured 0.087, 0.101, 0.246);
/// energy never grows once the load is gone and D ≥ 0 every step.
#[test]
fn square_mechanism_with_a_resolved_coupler_runs_as_the_paper_says() {
    let text = cosserat::scene::builtin_scenes()
        .iter()
        .find(|b| b.name == "mechanism")
        .unwrap()
        .toml
        .replace("elements = 4", "elements = 16");
    assert!(
        text.contains("elements = 16"),
        "the coupler's mesh was not refined"
    );
    for (alpha, dt) in [(0.5, 0.05), (5.0, 0.01), (5.0, 0.005)] {
        let s = cosserat::scene::parse_scene(&text, "mechanism16.toml").unwrap();
        assert_eq!(s.model.elements.len(), 16);
        let mut params = s.params;
        params.scheme = Scheme::edmc2(alpha);
        params.dt = dt;
        params.t_end = 10.0;
        let mut sim = Simulation::new(s.model, params).unwrap();
        let (mut lmin, mut lmax, mut turn) = (f64::INFINITY, 0.0f64, 0.0f64);
        let mut recs = Vec::new();
        let out = run(&mut sim, 1, |r: &StepRecord, sim: &Simulation| {
            recs.push(r.clone());
            let st = sim.state();
            let els = &sim.model().elements;
            let len: f64 = els
                .iter()
                .map(|e| (st.r[e.nodes[1]] - st.r[e.nodes[0]]).norm())
                .sum();
            lmin = lmin.min(len);
            lmax = lmax.max(len);
            for e in 0..els.len() {
                // Planar (about e1): the end triads' angle apart from d3·d3.
                let c = st.d[e][0].column(2).dot(&st.d[e][1].column(2));
                turn = turn.max(c.clamp(-1.0, 1.0).acos());
            }
            Ok::<(), ()>(())
        })
        .unwrap();
        let tag = format!("16-element coupler, EDMC-2 α={alpha} Δt={dt}");
        println!(
            "{tag}: {:?}, length {lmin:.4}–{lmax:.4}, max turn {turn:.3}",
            out.status
        );
        assert_eq!(out.status, RunStatus::Completed, "{tag}: {:?}", out.reason);
        assert!(
            lmin > 0.9 && lmax < 1.1,
            "{tag}: coupler length {lmin}–{lmax}"
        );
        assert!(turn < 0.3, "{tag}: element turn {turn}");
        let growth = max_growth_after(&recs, 0.5);
        eprintln!(
            "{tag}: max growth after the load {growth:.1e}, max link g {:.1e}",
            recs.iter().map(|r| r.max_link_g).fold(0.0, f64::max)
        );
        assert!(
            growth <= 1e-9,
            "{tag}: energy grew by {growth:e} after the load"
        );
        assert!(recs.iter().all(|r| r.dissipation >= 0.0), "{tag}: D < 0");
    }
}

/// Planar mode removes only unknowns the plane cannot excite: the planar and the full 3D
/// systems give the same motion to round-off (over a horizon short enough that round-off
/// does not grow chaotically), with half the unknowns.
#[test]
fn planar_equals_full_3d_to_round_off() {
    for (scene, dt, t_end) in [("arch", 1.0, 1000.0), ("mechanism_hexagon", 0.05, 2.0)] {
        let (o2, r2, s2) = simulate(scene, Scheme::edmc2(0.5), dt, t_end, true);
        let (o3, r3, s3) = simulate(scene, Scheme::edmc2(0.5), dt, t_end, false);
        assert_eq!(o2.status, RunStatus::Completed);
        assert_eq!(o3.status, RunStatus::Completed);
        // Per free node: u, θ, g (EDMC-2 α_Γv dissipates translationally) = 9 unknowns in
        // 3D; the plane keeps u2, u3, θ1, g2, g3 = 5.
        assert_eq!(
            9 * s2.n_dofs(),
            5 * s3.n_dofs(),
            "{scene}: planar keeps 5 of 9 per node"
        );
        let size = s2.state().r.iter().fold(0.0f64, |m, x| m.max(x.norm()));
        for (a, b) in s2.state().r.iter().zip(&s3.state().r) {
            // Measured ≤ 2.4e-13 relative (the arch through its snap-through, which
            // amplifies round-off: 7.4e-14 before the planar tangent's summation order
            // changed with its four-element form).
            assert!(
                (a - b).norm() <= 1.5e-12 * size,
                "{scene}: positions differ by {}",
                (a - b).norm()
            );
            assert_eq!(b.x, 0.0, "{scene}: the 3D run left the plane");
        }
        let dx = s2
            .state()
            .r
            .iter()
            .zip(&s3.state().r)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).norm()));
        eprintln!("{scene}: planar vs 3D max position difference {:.2e} (relative {:.2e}), unknowns {} vs {}", dx, dx / size, s2.n_dofs(), s3.n_dofs());
        let href = r2.iter().fold(0.0f64, |m, r| m.max(r.total.abs()));
        eprintln!(
            "{scene}: planar vs 3D max H difference {:.1e} of max H",
            r2.iter()
                .zip(&r3)
                .map(|(a, b)| (a.total - b.total).abs() / href)
                .fold(0.0, f64::max)
        );
        // Measured ≤ 6.9e-12 of max H (the arch).
        for (a, b) in r2.iter().zip(&r3) {
            assert!(
                (a.total - b.total).abs() <= 5e-11 * href,
                "{scene} t={}: H {} vs {}",
                a.t,
                a.total,
                b.total
            );
        }
    }
}
