//! Step cut-back (issue 15): a step that fails at the fixed Δt is redone as 2, 4, …
//! complete sub-steps of the same scheme, so the run goes on with the scheme's invariants
//! intact: in free flight L and J stay constant to round-off across the sub-steps and EM
//! keeps H; off by default, so the fixed-Δt failure is still reported without it.
use cosserat::integrator::run::{run, RunOutcome};
use cosserat::integrator::{Scheme, Simulation};
use cosserat::observe::record::{RunStatus, StepRecord};
use cosserat::scene::load_scene;

fn frame(scheme: Scheme, dt: f64, cutback: usize) -> (RunOutcome, Vec<StepRecord>) {
    let s = load_scene("frame").unwrap();
    let mut params = s.params;
    params.scheme = scheme;
    params.dt = dt;
    params.cutback = cutback;
    let mut sim = Simulation::new(s.model.clone(), params).unwrap();
    let mut recs = Vec::new();
    let out = run(&mut sim, 1, |r: &StepRecord, _: &Simulation| {
        recs.push(r.clone());
        Ok::<(), ()>(())
    })
    .unwrap();
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
