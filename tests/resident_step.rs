//! `--solve resident` ≡ the CPU path, member by member, with one host sync per Newton
//! solve.
//!
//! Device-resident members with full Newton run up to K Newton iterations per submission:
//! the device stops each member where the host's Newton loop stops (the same test on the
//! same residuals) and the host reads the iterations back once. Checked here, on lavapipe:
//!
//! * a cantilever batch with seeded random kicks, stiffnesses, time steps and tip loads,
//!   members that end early, fail (staggered cap, Newton cap), fall back to the monolithic
//!   strategy on the CPU kernel for a step and finish, run on the CPU kernel (generalized-α)
//!   or are solved on the host (a carried clamp; its follower line load the kernel's): every member ends as on the CPU path (status,
//!   reason, steps, Newton iterations, states within `STATE_RTOL`) and exactly as with
//!   `--solve device`; no iteration the host asked for was missing on the device;
//! * EM (no dissipation scalars: one Newton solve per step): one host sync per step for the
//!   whole batch; the inexact EDMC strategy (a consistent-scalar Newton solve, then one
//!   frozen-scalar round from the scalars the host computes from its solution): two;
//!   states as on the CPU path;
//! * the paper's frame, 15 steps.
//!
//! Without an adapter the test prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case it fails.

mod common;

use common::gpu;
use common::{
    batch_mix as members, compare_results as compare, frame_member, run_batch as run, STATE_RTOL,
};
use cosserat::batch::{BatchStats, Executor, Member, MemberResult, SolveMode};
use cosserat::integrator::{NewtonVariant, Scheme, Strategy};
use cosserat::observe::record::RunStatus;

/// Resident against the CPU path (the host's `fresh` Newton: the GPU paths run `full` as
/// `fresh`, docs/gpu.md) and against `--solve device`, which asks the device for the same
/// iterations one dispatch at a time; `workers` slots.
fn check_batch(
    label: &str,
    ms: &[Member],
    exec: &Executor,
    workers: usize,
) -> (Vec<MemberResult>, BatchStats) {
    let (cpu, _) = run(ms, &Executor::Cpu, NewtonVariant::Fresh, SolveMode::Host, 0);
    let (dev, ds) = run(ms, exec, NewtonVariant::Full, SolveMode::Device, workers);
    let (res, rs) = run(ms, exec, NewtonVariant::Full, SolveMode::Resident, workers);
    assert_eq!(rs.device_members, ds.device_members, "{label}");
    let sv = &rs.serve;
    assert_eq!(sv.multi_mismatches, 0, "{label}");
    assert!(
        sv.multi_solves > 0 && sv.multi_answers > 0,
        "{label}: {sv:?}"
    );
    let (mut worst_cpu, mut worst_dev) = (0.0f64, 0.0f64);
    for ((c, d), r) in cpu.iter().zip(&dev).zip(&res) {
        let i = c.index;
        worst_cpu = worst_cpu.max(compare(&format!("{label}, member {i}, cpu"), c, r));
        worst_dev = worst_dev.max(compare(&format!("{label}, member {i}, device"), d, r));
    }
    println!(
        "{label}: resident vs CPU {worst_cpu:.3e}, vs device {worst_dev:.3e}; dispatches {} (device {}), {} Newton solves in {} multi-iteration dispatches, {} device iterations, {} answered without a dispatch",
        sv.dispatches, ds.serve.dispatches, sv.multi_solves, sv.multi_dispatches, sv.multi_iterations, sv.multi_answers
    );
    assert!(
        worst_cpu <= STATE_RTOL,
        "{label}: {worst_cpu:.3e} from the CPU path"
    );
    // The same iterations on the same device kernels: identical.
    assert_eq!(
        worst_dev, 0.0,
        "{label}: resident differs from --solve device"
    );
    assert!(
        sv.dispatches < ds.serve.dispatches,
        "{label}: {} dispatches, device {}",
        sv.dispatches,
        ds.serve.dispatches
    );
    (res, rs)
}

#[test]
fn resident_staggered_batch_with_failures_and_fallbacks_ends_as_on_the_cpu_path() {
    let Some(exec) = gpu() else { return };
    let ms = members(None, Strategy::Staggered);
    // 5 slots for 14 members: the queue streams through.
    let (res, rs) = check_batch("EDMC-2 staggered", &ms, &exec, 5);
    assert_eq!(rs.device_members, (13, 0));
    // The mix exercises what it claims to: a member whose device step failed and that
    // finished on the CPU (monolithic fallback, CPU kernel and host solve), two that fail.
    assert_eq!(res[10].outcome.status, RunStatus::Completed);
    assert!(res[10].outcome.fallback_steps > 0, "{:?}", res[10].outcome);
    assert_eq!(res[11].outcome.status, RunStatus::Failed);
    assert!(res[..9]
        .iter()
        .all(|r| r.outcome.status == RunStatus::Completed));
}

#[test]
fn resident_em_batch_syncs_once_per_step() {
    let Some(exec) = gpu() else { return };
    let mut ms = members(Some(Scheme::Em), Strategy::Staggered);
    // The device-covered members that complete 6 steps, one slot each: their steps line
    // up.
    ms.truncate(9);
    let (res, rs) = check_batch("EM", &ms, &exec, ms.len());
    let steps = res.iter().map(|r| r.outcome.steps).max().unwrap() as u64;
    // One Newton solve per step (no scalars): one sync per step for the whole batch,
    // plus one per Newton solve the device stopped short of the host's acceptance.
    let extra = rs.serve.dispatches - rs.serve.multi_dispatches;
    println!(
        "EM: {} dispatches for {steps} steps ({} multi-iteration, {extra} single)",
        rs.serve.dispatches, rs.serve.multi_dispatches
    );
    assert_eq!(rs.serve.multi_dispatches, steps);
    assert_eq!(extra, 0);
}

#[test]
fn resident_inexact_batch_syncs_once_per_step() {
    let Some(exec) = gpu() else { return };
    let mut ms = members(None, Strategy::Inexact);
    ms.truncate(9);
    let (res, rs) = check_batch("EDMC-2 inexact", &ms, &exec, ms.len());
    let steps = res.iter().map(|r| r.outcome.steps).max().unwrap() as u64;
    println!(
        "inexact: {} dispatches for {steps} steps",
        rs.serve.dispatches
    );
    // Two Newton solves per step (the consistent-scalar solve, then one frozen-scalar
    // round from the scalars the host computes from its solution): one sync each.
    assert_eq!(rs.serve.multi_solves, 2 * steps * ms.len() as u64);
    assert_eq!(rs.serve.dispatches, 2 * steps);
}

#[test]
fn resident_frame_matches_cpu() {
    let Some(exec) = gpu() else { return };
    let ms = vec![frame_member(15.0, |p| p.strategy = Strategy::Staggered)];
    let (res, rs) = check_batch("frame", &ms, &exec, 1);
    assert_eq!(rs.device_members, (1, 0), "the frame is covered");
    assert_eq!(res[0].outcome.status, RunStatus::Completed);
    assert_eq!(res[0].outcome.steps, 15);
}

/// `run --solve resident` records where its Newton systems were solved: `resident` in
/// summary.json, with the same history as `--solve device` (the same solves).
#[test]
fn run_records_the_resident_solve() {
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut outs = vec![];
    for solve in ["device", "resident"] {
        let out = dir.path().join(solve);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
            .args([
                "run",
                "frame",
                "--backend",
                "gpu",
                "--solve",
                solve,
                "--t-end",
                "2",
            ])
            .arg("--out")
            .arg(&out)
            .env("NODEVICE_SELECT", "1")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(s["solve"], solve);
        outs.push(std::fs::read_to_string(out.join("history.csv")).unwrap());
    }
    assert_eq!(outs[0], outs[1]);
}
