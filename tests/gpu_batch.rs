//! GPU batch ≡ CPU batch, and the invariants of DESIGN §5 on the GPU path.
//!
//! * A 64-member EDMC-2 batch of the free-flying frame (α_Γv and the initial-velocity
//!   scale varied per member, α_Ων on for half of them) run on the GPU path gives every
//!   member's history (H, K, V, L, J) of the CPU path to `PARITY_RTOL` (same steps, same
//!   status).
//! * Modified Newton (tangent reuse) gives the full-Newton histories to `HISTORY_RTOL` on
//!   the CPU path (no adapter needed) and on the GPU path.
//! * On the GPU path, in free flight: L and J are constant step to step
//!   (`MOMENTUM_RTOL`); EDMC-2 energy never increases; EM energy is constant
//!   (`EM_ENERGY_RTOL`).
//!
//! Without an adapter the tests print `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case they fail.

mod common;
use common::gpu;
use cosserat::batch::{run_members, BatchOptions, Executor, Member, MemberResult};
use cosserat::integrator::{NewtonVariant, Scheme, Strategy};
use cosserat::observe::record::RunStatus;
use cosserat::scene::load_scene;

/// GPU and CPU histories (every column: H, K, V, L, J): both Newton solves converge from
/// round-off-different element blocks, to the same iterates up to round-off (measured
/// ≤ 4.0e-14, lavapipe; 2.5e-14 before the CPU path took chord corrections, which the GPU
/// path does not).
const PARITY_RTOL: f64 = 2e-13;
/// Modified against full Newton: the same solution to the Newton tolerance (measured
/// ≤ 8.2e-12).
const HISTORY_RTOL: f64 = 5e-11;
/// L and J per step on the GPU path: round-off (measured ≤ 9.0e-16).
const MOMENTUM_RTOL: f64 = 8e-15;
/// EM energy on the GPU path (measured ≤ 5.1e-13 of H0 over the run).
const EM_ENERGY_RTOL: f64 = 4e-12;

/// Largest difference between two histories over H, K, V (relative to max |H|) and L, J
/// (relative to their norms).
fn history_difference(
    a: &[cosserat::observe::record::StepRecord],
    b: &[cosserat::observe::record::StepRecord],
) -> f64 {
    let h = a.iter().map(|r| r.total.abs()).fold(1e-300, f64::max);
    let l = a.iter().map(|r| r.l.norm()).fold(1e-300, f64::max);
    let j = a.iter().map(|r| r.j.norm()).fold(1e-300, f64::max);
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            [
                (x.total - y.total).abs() / h,
                (x.kinetic - y.kinetic).abs() / h,
                (x.potential - y.potential).abs() / h,
                (x.l - y.l).norm() / l,
                (x.j - y.j).norm() / j,
            ]
            .into_iter()
            .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

fn members(n: usize, scheme_of: impl Fn(usize) -> Scheme, t_end: f64) -> Vec<Member> {
    let scene = load_scene("frame").unwrap();
    (0..n)
        .map(|i| {
            let mut model = scene.model.clone();
            let s = 0.6 + 0.8 * (i as f64) / (n as f64);
            model.velocity0.iter_mut().for_each(|v| *v *= s);
            let mut params = scene.params;
            params.scheme = scheme_of(i);
            params.t_end = t_end;
            // The same strategy on both paths (the default `auto` is monolithic on the CPU,
            // staggered with a GPU evaluator).
            params.strategy = Strategy::Staggered;
            Member { model, params }
        })
        .collect()
}

fn run_all(ms: &[Member], exec: &Executor) -> Vec<MemberResult> {
    run_opts(ms, exec, NewtonVariant::Full)
}

fn run_opts(ms: &[Member], exec: &Executor, newton: NewtonVariant) -> Vec<MemberResult> {
    let mut out: Vec<Option<MemberResult>> = vec![None; ms.len()];
    run_members(
        ms,
        exec,
        BatchOptions {
            keep_history: true,
            newton: Some(newton),
            ..Default::default()
        },
        |r| {
            let i = r.index;
            out[i] = Some(r);
        },
    )
    .unwrap();
    out.into_iter().map(|r| r.unwrap()).collect()
}

fn edmc2(i: usize) -> Scheme {
    Scheme::Edmc2 {
        alpha_gv: 0.1 + 0.9 * (i % 8) as f64 / 8.0,
        alpha_gn: 0.0,
        alpha_ov: 0.0,
        alpha_on: if i.is_multiple_of(2) { 0.3 } else { 0.0 },
    }
}

#[test]
fn gpu_batch_energy_histories_match_cpu() {
    let Some(exec) = gpu() else { return };
    let ms = members(64, edmc2, 2.0);
    let cpu = run_all(&ms, &Executor::Cpu);
    let gpu = run_all(&ms, &exec);
    let mut worst = 0.0f64;
    let completed = cpu
        .iter()
        .filter(|c| c.outcome.status == RunStatus::Completed)
        .count();
    // A member whose step fails is recorded and the batch goes on (both paths agree on it).
    assert!(completed >= 48, "only {completed} of 64 completed");
    for (c, g) in cpu.iter().zip(&gpu) {
        assert_eq!(
            g.outcome.status, c.outcome.status,
            "member {}: {:?}",
            g.index, g.outcome.reason
        );
        assert_eq!(g.history.len(), c.history.len());
        worst = worst.max(history_difference(&c.history, &g.history));
    }
    println!("64 EDMC-2 members ({completed} completed): worst relative history difference GPU vs CPU {worst:.2e}");
    assert!(worst <= PARITY_RTOL, "{worst:.3e}");
}

#[test]
fn gpu_path_conserves_momenta_and_dissipates() {
    let Some(exec) = gpu() else { return };
    let em = members(4, |_| Scheme::Em, 2.0);
    let ed = members(4, edmc2, 2.0);
    let (mut ml, mut mh) = (0.0f64, 0.0f64);
    for (ms, dissipative) in [(em, false), (ed, true)] {
        for r in run_all(&ms, &exec) {
            let o = &r.outcome;
            ml = ml.max(o.max_rel_dl).max(o.max_rel_dj);
            if !dissipative {
                let h0 = r.history[0].total;
                mh = r
                    .history
                    .iter()
                    .map(|x| (x.total - h0).abs() / h0)
                    .fold(mh, f64::max);
            }
            assert_eq!(o.status, RunStatus::Completed, "{:?}", o.reason);
            assert!(
                o.max_rel_dl <= MOMENTUM_RTOL,
                "L drift {:.3e}",
                o.max_rel_dl
            );
            assert!(
                o.max_rel_dj <= MOMENTUM_RTOL,
                "J drift {:.3e}",
                o.max_rel_dj
            );
            let h0 = r.history[0].total;
            for w in r.history.windows(2) {
                if dissipative {
                    assert!(
                        w[1].total <= w[0].total + EM_ENERGY_RTOL * h0,
                        "energy grew"
                    );
                } else {
                    let rel = (w[1].total - h0).abs() / h0;
                    assert!(rel <= EM_ENERGY_RTOL, "EM energy drift {rel:.3e}");
                }
            }
            if dissipative {
                assert!(r.history.last().unwrap().total < h0);
            }
        }
    }
    println!("GPU path: max L/J change per step {ml:.1e}, EM energy drift {mh:.1e}");
}

#[test]
fn cli_run_with_gpu_backend_matches_cpu_run() {
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut totals = Vec::new();
    for backend in ["cpu", "gpu"] {
        let (s, stdout) = frame_run(
            &dir.path().join(backend),
            backend,
            &["--strategy", "staggered"],
        );
        if backend == "gpu" {
            assert!(stdout.contains("backend: gpu:"), "{stdout}");
        }
        // The summary names where the kernel ran (the adapter on the GPU path).
        let named = s["backend"].as_str().unwrap();
        assert!(named.starts_with(backend), "summary backend {named}");
        totals.push(s["energy_final"].as_f64().unwrap());
    }
    let rel = (totals[0] - totals[1]).abs() / totals[0].abs();
    println!("run --backend gpu vs cpu: final energy differs by {rel:.1e}");
    assert!(rel <= PARITY_RTOL, "cpu {} gpu {}", totals[0], totals[1]);
}

/// `cosserat run frame --t-end 1 --backend BACKEND` with `extra` into `out`: it completes;
/// its summary.json and stdout.
fn frame_run(out: &std::path::Path, backend: &str, extra: &[&str]) -> (serde_json::Value, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["run", "frame", "--t-end", "1", "--backend", backend])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("completed"), "{backend}: {stdout}");
    let s =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    (s, stdout)
}

/// The default strategy `auto` resolves by backend: a `run --backend gpu` of the frame
/// (EDMC-2 α = 0.5) runs the staggered loop, whose frozen-scalar system the GPU kernel
/// evaluates, and the same run on the CPU the monolithic Newton; `summary.json` records
/// the requested `auto` and the strategy that ran. The two agree to the staggered loop's
/// `outer_tol` (1e-10 of the dissipation identity; measured: final energies 1.1e-10 apart).
#[test]
fn the_default_strategy_is_staggered_on_the_gpu_and_monolithic_on_the_cpu() {
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut totals = Vec::new();
    for (backend, strategy) in [("cpu", "monolithic"), ("gpu", "staggered")] {
        let (s, _) = frame_run(&dir.path().join(backend), backend, &[]);
        assert_eq!(s["status"], "completed", "{backend}: {s}");
        assert_eq!(s["params"]["strategy"], "auto", "{backend}");
        assert_eq!(s["strategy"], strategy, "{backend}");
        totals.push(s["energy_final"].as_f64().unwrap());
    }
    let rel = (totals[0] - totals[1]).abs() / totals[0].abs();
    println!("default strategy, gpu (staggered) vs cpu (monolithic): final energy {rel:.1e}");
    assert!(rel <= 1e-9, "cpu {} gpu {}", totals[0], totals[1]);
}

#[test]
fn modified_newton_matches_full_newton() {
    let ms = members(8, edmc2, 1.0);
    let full = run_all(&ms, &Executor::Cpu);
    let mut paths = vec![(
        "cpu",
        run_opts(&ms, &Executor::Cpu, NewtonVariant::Modified),
    )];
    if let Some(exec) = gpu() {
        paths.push(("gpu", run_opts(&ms, &exec, NewtonVariant::Modified)));
    }
    let mut worst = 0.0f64;
    for (name, got) in paths {
        for (a, b) in full.iter().zip(&got) {
            assert_eq!(
                a.outcome.status, b.outcome.status,
                "{name} member {}: {:?}",
                a.index, b.outcome.reason
            );
            let rel = history_difference(&a.history, &b.history);
            worst = worst.max(rel);
            assert!(rel <= HISTORY_RTOL, "{name} member {}: {rel:.3e}", a.index);
        }
    }
    println!("modified vs full Newton: worst relative history difference {worst:.1e}");
}
