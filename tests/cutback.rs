//! Step cut-back (issue 15): a step that fails at the fixed Δt is redone as 2, 4, …
//! complete sub-steps of the same scheme, so the run goes on with the scheme's invariants
//! intact: in free flight L and J stay constant to round-off across the sub-steps and EM
//! keeps H. Off by default in the library (the fixed-Δt failure is still reported
//! without it); `cosserat run` and `sweep` cut back up to 4 halvings unless the scene or
//! `--cutback` says otherwise.
use cosserat::integrator::run::RunOutcome;
use cosserat::integrator::{Scheme, Simulation};
use cosserat::observe::record::{RunStatus, StepRecord};
use cosserat::scene::load_scene;

mod common;

fn frame(scheme: Scheme, dt: f64, cutback: usize) -> (RunOutcome, Vec<StepRecord>) {
    let s = load_scene("frame").unwrap();
    let mut params = s.params;
    params.scheme = scheme;
    params.dt = dt;
    params.cutback = cutback;
    let mut sim = Simulation::new(s.model.clone(), params).unwrap();
    let (out, recs) = common::run_recording(&mut sim);
    (out, recs)
}

#[test]
fn frame_at_half_a_second_fails_without_and_completes_with_cutback() {
    let (out, _) = frame(Scheme::Em, 0.5, 0);
    assert_eq!(out.status, RunStatus::Failed);
    assert_eq!(out.steps, 4, "{:?}", out.reason);
    assert!(out.reason.unwrap().contains("Newton did not converge"));

    for (name, scheme) in [("em", Scheme::Em), ("edmc2", Scheme::edmc2(0.5))] {
        let (out, recs) = frame(scheme, 0.5, 3);
        assert_eq!(out.status, RunStatus::Completed, "{name}: {:?}", out.reason);
        let cut: Vec<&StepRecord> = recs.iter().filter(|r| r.substeps > 1).collect();
        eprintln!(
            "{name}: {} cut steps, smallest {:?}, dL {:e} dJ {:e}",
            out.cutback_steps, out.smallest_substep, out.max_rel_dl, out.max_rel_dj
        );
        assert!(out.cutback_steps > 0, "{name}");
        assert_eq!(cut.len(), out.cutback_steps, "{name}");
        let smallest = out.smallest_substep.unwrap();
        assert!((0.5 / 8.0..0.5).contains(&smallest), "{name}: {smallest}");
        assert!(recs.iter().skip(1).all(|r| r.substeps >= 1));
        // Free flight: momenta per step (cut or not) to round-off (measured ≤ 1.5e-15).
        assert!(out.max_rel_dl <= 1e-14, "{name}: dL {:e}", out.max_rel_dl);
        assert!(out.max_rel_dj <= 1e-14, "{name}: dJ {:e}", out.max_rel_dj);
        // Times stay on the Δt grid; the energy law holds across the cut steps.
        let h0 = recs[0].total;
        for (k, r) in recs.iter().enumerate() {
            assert_eq!(r.t, k as f64 * 0.5);
            match name {
                "em" => assert!((r.total - h0).abs() <= 1e-10 * h0, "em H at t = {}", r.t),
                _ => assert!(
                    (r.total - h0 + r.dissipation_total).abs() <= 1e-9 * h0,
                    "edmc2 balance at t = {}",
                    r.t
                ),
            }
        }
    }
}

/// The CLI: `--cutback 2` completes the run, `summary.json` counts the cut steps and
/// their smallest sub-step, `history.csv` has each step's `substeps`.
#[test]
fn cli_cutback_reports_cut_steps() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args([
            "run",
            "frame",
            "--scheme",
            "em",
            "--dt",
            "0.5",
            "--cutback",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["status"], "completed", "{s}");
    assert_eq!(s["params"]["cutback"], 2);
    let n = s["cutback_steps"].as_u64().unwrap();
    assert!(n > 0);
    assert_eq!(s["smallest_substep"].as_f64(), Some(0.25));
    let csv = std::fs::read_to_string(out.join("history.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "substeps").unwrap();
    let cut = csv
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(col).is_some_and(|v| v != "0" && v != "1"))
        .count();
    assert_eq!(cut as u64, n);
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["run", "frame", "--cutback", "21"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
}

/// `cosserat run` cuts back by default (4 halvings): EM on the frame at Δt = 0.5, which
/// fails at a fixed step (t = 2.0), completes with its cut-back steps counted in
/// summary.json, marked in history.csv (on the Δt grid) and named on the terminal;
/// `--cutback 0` reports the fixed-step failure.
#[test]
fn run_cuts_back_by_default_and_cutback_0_turns_it_off() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
            .args([
                "run", "frame", "--scheme", "em", "--dt", "0.5", "--every", "1",
            ])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        let csv = std::fs::read_to_string(out.join("history.csv")).unwrap();
        (st, s, csv)
    };
    let (st, s, csv) = run(&[], "default");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert_eq!(s["status"], "completed", "{s}");
    assert_eq!(s["params"]["cutback"], 4);
    let n = s["cutback_steps"].as_u64().unwrap();
    assert!(n > 0, "{s}");
    let stdout = String::from_utf8_lossy(&st.stdout);
    assert!(
        stdout.contains(&format!("{n} of 20 steps were cut back")),
        "{stdout}"
    );
    // Outputs on the Δt grid: one row per step (and t = 0), at multiples of 0.5.
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let (tc, sc) = (
        header.iter().position(|c| *c == "t").unwrap(),
        header.iter().position(|c| *c == "substeps").unwrap(),
    );
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 21);
    for (k, r) in rows.iter().enumerate() {
        assert!(
            (r[tc] - 0.5 * k as f64).abs() < 1e-9,
            "row {k}: t = {}",
            r[tc]
        );
    }
    assert_eq!(rows.iter().filter(|r| r[sc] > 1.0).count() as u64, n);
    let (st, s, _) = run(&["--cutback", "0"], "off");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert_eq!(s["status"], "failed", "{s}");
    assert_eq!(s["cutback_steps"], 0);
    assert_eq!(s["params"]["cutback"], 0);
}

/// Runs the CLI on the frame with `args` (every step in `history.csv`) and returns
/// `summary.json` and the history's rows as column name → values.
fn cli_frame(
    args: &[&str],
) -> (
    serde_json::Value,
    Vec<std::collections::HashMap<String, f64>>,
) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["run", "frame", "--every", "1"])
        .args(args)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(out.join("history.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(|v| v.parse::<f64>().unwrap()))
                .collect()
        })
        .collect();
    (s, rows)
}

/// `summary.json`'s step statistics are what its `history.csv` (every step) gives:
/// `accepted.max_energy_growth` and `max_rel_energy_growth` are the largest
/// `H_n − H_{n−1} − W_n` and the same over `max(|H_{n−1}|, |H_n|, |W_n|)` (a one-step run
/// and a long one), and `smallest_substep` is Δt over the largest `substeps`, a power of
/// two.
#[test]
fn cli_summary_statistics_equal_the_history() {
    for args in [
        &["--scheme", "edmc2", "--dt", "0.5", "--t-end", "0.5"][..],
        &["--scheme", "edmc2", "--dt", "0.5", "--cutback", "3"][..],
        &["--scheme", "em", "--dt", "0.5", "--cutback", "3"][..],
    ] {
        let (s, rows) = cli_frame(args);
        assert_eq!(s["status"], "completed", "{args:?}: {s}");
        assert!(rows.len() >= 2, "{args:?}");
        let (mut g, mut rel) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for w in rows.windows(2) {
            let (h0, h1, work) = (w[0]["total"], w[1]["total"], w[1]["external_work"]);
            let growth = h1 - h0 - work;
            let href = h0.abs().max(h1.abs()).max(work.abs());
            g = g.max(growth);
            rel = rel.max(growth / href.max(1e-300));
        }
        let acc = &s["accepted"];
        let (sg, srel) = (
            acc["max_energy_growth"].as_f64().unwrap(),
            acc["max_rel_energy_growth"].as_f64().unwrap(),
        );
        eprintln!(
            "{args:?}: H0 = {:e}, growth {sg:e} (history {g:e}), rel {srel:e} (history {rel:e})",
            rows[0]["total"]
        );
        // JSON and CSV both print shortest round-trip decimals: equal to a few ulps.
        assert!(
            (sg - g).abs() <= 1e-12 * g.abs(),
            "{args:?}: {sg:e} vs {g:e}"
        );
        assert!(
            (srel - rel).abs() <= 1e-12 * rel.abs(),
            "{args:?}: {srel:e} vs {rel:e}"
        );
        let most = rows.iter().map(|r| r["substeps"]).fold(0.0, f64::max);
        match s["smallest_substep"].as_f64() {
            None => assert!(most <= 1.0, "{args:?}: cut steps but no smallest_substep"),
            Some(h) => {
                assert!(
                    most >= 2.0 && most.log2().fract() == 0.0,
                    "{args:?}: {most}"
                );
                assert_eq!(h, 0.5 / most, "{args:?}");
            }
        }
    }
}
