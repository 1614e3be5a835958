//! Solver fallback (issue 15): a step the paper's staggered loop cannot solve is solved by
//! the monolithic Newton of the *same* scheme, so the run goes on where the scheme itself
//! would; every fallback step still holds the dissipation identity and the energy law,
//! and with the fallback off the staggered failure is reported as before. The square
//! mechanism at Δt = 0.05 with EDMC-2 needed the fallback once before t = 5.5 (at t = 4.3)
//! until EDMC-2's velocity couplings faded where a point is slower than the law's own
//! dissipative speed (docs/damping.md): the staggered loop now solves that step alone.
//! With EDMC-1's director dissipation χ_ν = 0.5 it needs the fallback twice before
//! t = 6.3 (t = 4.15 and 4.9). At t = 5.5 the EDMC-2 monolithic
//! solution would turn a coupler element's end triads 2.16 rad apart (the director
//! interpolation's soft branch, on which the coupler used to stretch to 77 times its
//! length) and is refused, so that run now fails there, saying why. The monolithic
//! strategy falls back to the staggered loop the same way.
use cosserat::integrator::run::RunOutcome;
use cosserat::integrator::{Scheme, Simulation, Strategy};
use cosserat::observe::record::{RunStatus, StepRecord};
use cosserat::scene::{load_scene, parse_scene};

mod common;

fn simulate(
    scene: &str,
    scheme: Scheme,
    dt: f64,
    t_end: f64,
    fallback: bool,
) -> (RunOutcome, Vec<StepRecord>) {
    simulate_with(scene, scheme, dt, t_end, fallback, Strategy::Staggered)
}

fn simulate_with(
    scene: &str,
    scheme: Scheme,
    dt: f64,
    t_end: f64,
    fallback: bool,
    strategy: Strategy,
) -> (RunOutcome, Vec<StepRecord>) {
    let s = load_scene(scene).unwrap();
    let mut params = s.params;
    params.strategy = strategy;
    params.scheme = scheme;
    params.dt = dt;
    params.t_end = t_end;
    params.fallback = fallback;
    let mut sim = Simulation::new(s.model.clone(), params).unwrap();
    let (out, recs) = common::run_recording(&mut sim);
    (out, recs)
}

/// Largest per-step miss of `H_n − H_{n+1} + W − D = 0`, relative to the step's energy
/// scale, and the largest growth beyond the external work (relative).
fn identity_and_growth(recs: &[StepRecord]) -> (f64, f64) {
    let (mut miss, mut growth) = (0.0f64, f64::NEG_INFINITY);
    for w in recs.windows(2) {
        let (h0, h1) = (w[0].total, w[1].total);
        let href = h0.abs().max(h1.abs()).max(w[1].external_work.abs());
        miss = miss.max((h0 - h1 + w[1].external_work - w[1].dissipation).abs() / href);
        growth = growth.max((h1 - h0 - w[1].external_work) / href);
    }
    (miss, growth)
}

/// The mechanism with EDMC-1 χ_ν = 0.5 (no α): `scenes/mechanism.toml` with its
/// integrator edited.
fn mechanism_chi_nu() -> String {
    let text = include_str!("../scenes/mechanism.toml");
    assert!(text.contains("scheme = \"edmc2\"\nalpha = 0.5\n"));
    text.replace(
        "scheme = \"edmc2\"\nalpha = 0.5\n",
        "scheme = \"edmc1\"\nchi_nu = 0.5\n",
    )
}

/// The staggered loop fails two steps of the mechanism with director dissipation from its
/// first predictor (t = 4.15 and 4.9, measured); its monolithic fallback solves them from
/// the same predictor, each holding the dissipation identity and the energy law.
#[test]
fn the_fallback_solves_the_staggered_failures_of_director_dissipation() {
    let s = parse_scene(&mechanism_chi_nu(), "mechanism_chi_nu.toml").unwrap();
    let mut params = s.params;
    params.strategy = Strategy::Staggered;
    params.t_end = 6.3;
    let mut sim = Simulation::new(s.model.clone(), params).unwrap();
    let (out, recs) = common::run_recording(&mut sim);
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.reason);
    eprintln!("fallback steps {}", out.fallback_steps);
    assert!(out.fallback_steps > 0, "no step needed the fallback");
    assert_eq!(
        recs.iter().filter(|r| r.fallback).count(),
        out.fallback_steps
    );
    let (miss, growth) = identity_and_growth(&recs);
    eprintln!("identity miss {miss:e}, growth {growth:e}");
    assert!(miss <= 1e-9, "dissipation identity missed by {miss:e}");
    assert!(growth <= 0.0, "energy grew by {growth:e}");
}

#[test]
fn mechanism_edmc2_at_large_step_refuses_the_soft_branch() {
    let scheme = Scheme::edmc2(0.5);
    let (out, recs) = simulate("mechanism", scheme, 0.05, 10.0, true);
    assert_eq!(out.status, RunStatus::Failed);
    let reason = out.reason.clone().unwrap();
    assert!(
        out.t_reached > 5.4 && out.t_reached < 5.6,
        "t = {}: {reason}",
        out.t_reached
    );
    assert!(
        reason.contains("monolithic fallback failed too: element 2: its end triads are turned"),
        "{reason}"
    );
    let fell_back = recs.iter().filter(|r| r.fallback).count();
    eprintln!(
        "fallback steps {} (records {fell_back}), accepted {:?}",
        out.fallback_steps, out.accepted
    );
    // Measured: the staggered loop solves every step before t = 5.5 alone (it failed
    // t = 4.3 before EDMC-2's velocity couplings faded at slow points, and the fallback
    // solved it).
    assert_eq!(out.fallback_steps, 0);
    assert_eq!(fell_back, out.fallback_steps);
    let (miss, growth) = identity_and_growth(&recs);
    eprintln!("identity miss {miss:e}, growth {growth:e}");
    assert!(miss <= 1e-9, "dissipation identity missed by {miss:e}");
    assert!(growth <= 0.0, "energy grew by {growth:e}");
    assert!(recs.last().unwrap().dissipation_total > 0.0);
}

/// The fallback the other way: the frame at Δt = 0.5 (its highest mode far outside the
/// step) defeats the monolithic Newton at t = 2.0; retrying such a step with the staggered
/// loop (after the monolithic Newton failed from each of the step's predictors) carries
/// the run further, every step holding the dissipation identity and the energy law.
#[test]
fn a_monolithic_failure_falls_back_to_the_staggered_loop() {
    let scheme = Scheme::edmc2(0.5);
    let (alone, _) = simulate_with("frame", scheme, 0.5, 10.0, false, Strategy::Monolithic);
    assert_eq!(alone.status, RunStatus::Failed);
    assert_eq!(alone.fallback_steps, 0);
    let reason = alone.reason.unwrap();
    assert!(!reason.contains("fallback"), "{reason}");
    let (out, recs) = simulate_with("frame", scheme, 0.5, 10.0, true, Strategy::Monolithic);
    eprintln!(
        "monolithic alone: t = {}; with fallback: t = {}, {} fallback steps: {:?}",
        alone.t_reached, out.t_reached, out.fallback_steps, out.reason
    );
    // Measured: t = 2.0 alone, 3.5 with 1 fallback step.
    assert!(
        out.t_reached > alone.t_reached + 1.0,
        "{} vs {}",
        out.t_reached,
        alone.t_reached
    );
    assert!(out.fallback_steps > 0);
    assert_eq!(
        recs.iter().filter(|r| r.fallback).count(),
        out.fallback_steps
    );
    assert!(
        out.reason
            .unwrap()
            .contains("the staggered fallback failed too"),
        "the run should end where both strategies fail"
    );
    let (miss, growth) = identity_and_growth(&recs);
    eprintln!("identity miss {miss:e}, growth {growth:e}");
    assert!(miss <= 1e-9, "dissipation identity missed by {miss:e}");
    assert!(growth <= 0.0, "energy grew by {growth:e}");
}

#[test]
fn without_the_fallback_the_staggered_loop_fails_as_in_the_paper() {
    let (out, recs) = simulate("mechanism", Scheme::edmc2(0.5), 0.05, 10.0, false);
    assert_eq!(out.status, RunStatus::Failed);
    assert_eq!(out.fallback_steps, 0);
    assert!(recs.iter().all(|r| !r.fallback));
    let reason = out.reason.unwrap();
    eprintln!("t = {}: {reason}", out.t_reached);
    assert!(
        out.t_reached > 5.0 && out.t_reached < 6.0,
        "failed at t = {}",
        out.t_reached
    );
    assert!(reason.contains("Newton did not converge"), "{reason}");
    assert!(!reason.contains("fallback"), "{reason}");
}

/// `cosserat run mechanism --scheme edmc2 --alpha 0.5 --dt 0.05 --strategy staggered`
/// with `extra`: its summary.json and history.csv.
fn cosserat_run(extra: &[&str], out: &std::path::Path) -> (serde_json::Value, String) {
    let args: Vec<&str> = ["--strategy", "staggered"]
        .iter()
        .chain(extra)
        .copied()
        .collect();
    mechanism_run(&args, out)
}

/// `cosserat run mechanism --scheme edmc2 --alpha 0.5 --dt 0.05 --cutback 0` with `extra`
/// (these tests are about where the fixed-step scheme fails: no cut-back, which `run`
/// turns on by default).
fn mechanism_run(extra: &[&str], out: &std::path::Path) -> (serde_json::Value, String) {
    let args: Vec<&str> = [
        "--scheme",
        "edmc2",
        "--alpha",
        "0.5",
        "--dt",
        "0.05",
        "--cutback",
        "0",
    ]
    .iter()
    .chain(extra)
    .copied()
    .collect();
    scene_run("mechanism", &args, out)
}

/// `cosserat run SCENE` with `extra`: its summary.json and history.csv.
fn scene_run(scene: &str, extra: &[&str], out: &std::path::Path) -> (serde_json::Value, String) {
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["run", scene])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let summary =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(out.join("history.csv")).unwrap();
    (summary, csv)
}

/// The run failed on the refusal of a step that turns an element's end triads.
fn assert_turn_refusal(s: &serde_json::Value) {
    assert_eq!(s["status"], "failed", "{s}");
    assert!(
        s["reason"]
            .as_str()
            .unwrap_or("")
            .contains("end triads are turned"),
        "{s}"
    );
}

/// The CLI: the staggered run counts its fallback steps in summary.json and marks them in
/// history.csv (the mechanism with χ_ν); the EDMC-2 run stops at t = 5.5 on the
/// soft-branch refusal, and `--no-fallback` reproduces the paper's staggered failure at
/// the same time.
#[test]
fn cli_run_of_the_mechanism_counts_fallback_steps_and_fails_without_fallback() {
    let dir = tempfile::tempdir().unwrap();
    let (s, _) = cosserat_run(&[], &dir.path().join("turn"));
    assert_turn_refusal(&s);
    assert_eq!(s["fallback_steps"], 0, "{s}");
    let scene = dir.path().join("mechanism_chi_nu.toml");
    std::fs::write(&scene, mechanism_chi_nu()).unwrap();
    let (s, csv) = scene_run(
        scene.to_str().unwrap(),
        &[
            "--strategy",
            "staggered",
            "--t-end",
            "6.3",
            "--cutback",
            "0",
        ],
        &dir.path().join("a"),
    );
    assert_eq!(s["status"], "completed", "{s}");
    let n = s["fallback_steps"].as_u64().unwrap();
    assert!(n > 0);
    assert_eq!(s["params"]["fallback"], true);
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "fallback").unwrap();
    let marked = csv
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(col) == Some("1"))
        .count();
    assert_eq!(marked as u64, n);
    // Energy never grew beyond the external work in an accepted step; residuals converged
    // (measured: growth ≤ −1.7e-12, residual ≤ 7.7e-13).
    assert!(
        s["accepted"]["max_energy_growth"].as_f64().unwrap() <= 0.0,
        "{s}"
    );
    assert!(
        s["accepted"]["max_residual"].as_f64().unwrap() <= 1e-11,
        "{s}"
    );

    let (s, csv) = cosserat_run(&["--no-fallback"], &dir.path().join("b"));
    assert_eq!(s["status"], "failed", "{s}");
    assert_eq!(s["fallback_steps"], 0);
    assert_eq!(s["params"]["fallback"], false);
    assert!(s["t_reached"].as_f64().unwrap() > 5.0);
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "fallback").unwrap();
    assert!(csv
        .lines()
        .skip(1)
        .all(|l| l.split(',').nth(col) == Some("0")));
}

/// `check` says whether the fallback is on.
#[test]
fn check_names_the_fallback() {
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["check", "mechanism"])
        .output()
        .unwrap();
    assert!(st.status.success());
    let text = String::from_utf8_lossy(&st.stdout);
    assert!(
        text.contains(
            "strategy auto (monolithic on the CPU kernel, staggered on a GPU; with fallback)"
        ),
        "{text}"
    );
}

/// The default strategy resolves to the monolithic Newton on the CPU kernel, recorded in
/// summary.json beside the requested `auto`: the mechanism run is refused at t = 5.5 for
/// its element turn, as the staggered run with its fallback is.
#[test]
fn the_default_strategy_runs_monolithic_on_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let (s, _) = mechanism_run(&[], &dir.path().join("a"));
    assert_eq!(s["params"]["strategy"], "auto");
    assert_eq!(s["strategy"], "monolithic");
    // Neither the staggered loop nor the monolithic Newton needs its fallback before
    // t = 5.5.
    assert_eq!(s["fallback_steps"], 0, "{s}");
    assert_turn_refusal(&s);
    assert!((s["t_reached"].as_f64().unwrap() - 5.5).abs() < 1e-9, "{s}");
    assert!(
        s["accepted"]["max_energy_growth"].as_f64().unwrap() <= 0.0,
        "{s}"
    );
}

/// The stability study: the default cell, the staggered cell with its fallback and the
/// `--strategy staggered --no-fallback` cell (the paper's pure staggered strategy) all fail
/// at t = 5.5, the first two refused for the element turn, the last failing its Newton
/// solve; the study's summary.json records the strategy.
#[test]
fn stability_study_maps_the_pure_staggered_strategy_with_no_fallback() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (flags, (strategy, ran), reason)) in [
        (&[][..], ("auto", "monolithic"), "end triads are turned"),
        (
            &["--strategy", "staggered"][..],
            ("staggered", "staggered"),
            "end triads are turned",
        ),
        (
            &["--strategy", "staggered", "--no-fallback"][..],
            ("staggered", "staggered"),
            "Newton did not converge",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let out = dir.path().join(i.to_string());
        let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
            .args(["study", "stability", "mechanism", "--schemes", "edmc2"])
            .args(["--params", "0.5", "--dts", "0.05", "--t-end", "6"])
            .args(flags)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let csv = std::fs::read_to_string(out.join("stability.csv")).unwrap();
        assert!(
            csv.lines()
                .nth(1)
                .unwrap()
                .starts_with("edmc2,0.5,0.05,5.5,6,failed,"),
            "{flags:?}: {csv}"
        );
        let failures = std::fs::read_to_string(out.join("failures.txt")).unwrap();
        assert!(failures.contains(reason), "{flags:?}: {failures}");
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(s["params"]["strategy"], strategy, "{flags:?}");
        assert_eq!(s["strategy"], ran, "{flags:?}");
    }
}

/// The staggered loop's cap is a failure path of its own: with `max_outer = 2` and no
/// fallback, the frame's first EDMC-2 step (5–6 outer rounds at the start) fails naming
/// the cap and the last round's reason; with the fallback on, the monolithic Newton
/// solves that step instead.
#[test]
fn staggered_cap_is_reported_naming_the_cap() {
    let scene = load_scene("frame").unwrap();
    let mut p = scene.params;
    p.scheme = Scheme::edmc2(0.5);
    p.strategy = Strategy::Staggered;
    p.max_outer = 2;
    p.fallback = false;
    let mut sim = Simulation::new(scene.model.clone(), p).unwrap();
    let err = sim.step().unwrap_err();
    assert!(
        err.reason
            .starts_with("staggered loop hit its cap of 2 outer rounds: "),
        "{}",
        err.reason
    );
    p.fallback = true;
    let mut sim = Simulation::new(scene.model, p).unwrap();
    let rep = sim.step().unwrap();
    assert!(rep.fallback, "the monolithic fallback solved the step");
}
