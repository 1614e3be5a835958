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
        assert!(
            smallest >= 0.5 / 8.0 && smallest < 0.5,
            "{name}: {smallest}"
        );
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
