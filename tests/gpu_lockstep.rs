//! Lockstep GPU batch ≡ CPU path, member by member.
//!
//! A batch of cantilevers (EDMC-2 α = 0.5, each tip kicked differently) mixed with the
//! cases a streaming lockstep driver must get right: members that end early (shorter
//! `t_end`), a member that fails mid-run (its staggered loop capped at 3 rounds, while its
//! second step needs 4, and no monolithic fallback), members whose scheme
//! has no GPU kernel (generalized-α, run on the CPU kernel inside the batch), and more
//! members than slots (3 slots: the queue streams through). For full and modified
//! Newton, every member ends the same way on both paths — status, steps, Newton
//! iterations (modified Newton: within 2 % + 2) — and its final state (positions, directors, velocities) and energies agree
//! to `STATE_RTOL`.
//!
//! Without an adapter the test prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case it fails.

mod common;

use common::gpu;
use common::rel;
use cosserat::batch::{bench_members, run_members, BatchOptions, Executor, Member, MemberResult};
use cosserat::integrator::{NewtonVariant, Scheme, Strategy};
use cosserat::observe::record::RunStatus;

/// Final states of the two paths: both Newton solves converge to 1e-11 of the force scale
/// from element blocks that differ by round-off (measured on lavapipe: 1.8e-11, the test
/// prints it).
const STATE_RTOL: f64 = 5e-11;

/// 10 members: 0..5 full length, 5..7 end after 3 steps, 7 fails at step 2, 8 and 9 are
/// generalized-α (no GPU kernel).
fn members() -> Vec<Member> {
    let mut ms = bench_members(10, 10, 8).unwrap();
    for (i, m) in ms.iter_mut().enumerate() {
        // The same strategy on both paths (the default `auto` is monolithic on the CPU,
        // staggered with a GPU evaluator).
        m.params.strategy = Strategy::Staggered;
        match i {
            5 | 6 => m.params.t_end = 3.0 * m.params.dt,
            7 => {
                // A stronger kick: its first step takes 3 staggered rounds, the second 4;
                // without the monolithic fallback (which would solve that step) it fails.
                m.params.max_outer = 3;
                m.params.fallback = false;
                m.model.velocity0.iter_mut().for_each(|v| *v *= 3.0);
            }
            8 | 9 => m.params.scheme = Scheme::GenAlpha { rho_inf: 0.8 },
            _ => {}
        }
    }
    ms
}

fn run(ms: &[Member], exec: &Executor, newton: NewtonVariant, slots: usize) -> Vec<MemberResult> {
    let mut out: Vec<Option<MemberResult>> = vec![None; ms.len()];
    run_members(
        ms,
        exec,
        BatchOptions {
            keep_history: true,
            keep_state: true,
            workers: slots,
            newton: Some(newton),
            fallback: None,
            cutback: None,
            solve: Default::default(),
            host_update: false,
        },
        |r| {
            let i = r.index;
            assert!(out[i].is_none(), "member {i} reported twice");
            out[i] = Some(r);
        },
    )
    .unwrap();
    out.into_iter()
        .enumerate()
        .map(|(i, r)| r.unwrap_or_else(|| panic!("member {i} never reported")))
        .collect()
}

/// `max |a − b| / max(|a|, 1e-300)` over the flattened values.
#[test]
fn lockstep_gpu_batch_matches_cpu_member_by_member() {
    let Some(exec) = gpu() else { return };
    let ms = members();
    let mut worst = 0.0f64;
    for newton in [NewtonVariant::Full, NewtonVariant::Modified] {
        let cpu = run(&ms, &Executor::Cpu, newton, 0);
        let gpu = run(&ms, &exec, newton, 3);
        // The mix exercises what it claims to.
        assert_eq!(
            cpu[5].outcome.steps, 3,
            "early member ran {} steps",
            cpu[5].outcome.steps
        );
        let failing = &cpu[7].outcome;
        assert_eq!(failing.status, RunStatus::Failed, "member 7 should fail");
        assert!(
            failing.steps == 1
                && failing
                    .reason
                    .as_deref()
                    .unwrap_or("")
                    .contains("staggered loop hit its cap of 3"),
            "member 7 should fail at step 2 on its staggered cap: {:?} after {} steps",
            failing.reason,
            failing.steps
        );
        for (c, g) in cpu.iter().zip(&gpu) {
            let i = c.index;
            let tag = format!("{} Newton, member {i}", newton.name());
            assert_eq!(
                c.outcome.status, g.outcome.status,
                "{tag}: {:?}",
                g.outcome.reason
            );
            assert_eq!(c.outcome.steps, g.outcome.steps, "{tag}");
            // Full Newton takes the same iterations on both paths. Modified Newton decides
            // by comparing residuals (keep the tangent while they fall ≥ 5× per
            // iteration): a round-off difference can flip a decision and cost or save an
            // iteration; the converged states still agree (below).
            let (ic, ig) = (c.outcome.newton_iters_total, g.outcome.newton_iters_total);
            match newton {
                NewtonVariant::Full | NewtonVariant::Fresh => assert_eq!(ic, ig, "{tag}"),
                NewtonVariant::Modified => {
                    assert!(
                        ic.abs_diff(ig) <= 2 + ic / 50,
                        "{tag}: {ic} vs {ig} iterations"
                    )
                }
            }
            assert_eq!(c.history.len(), g.history.len(), "{tag}");
            let (sc, sg) = (c.state.as_ref().unwrap(), g.state.as_ref().unwrap());
            assert_eq!(sc.t, sg.t, "{tag}");
            let pos = rel(
                sc.r.iter().flat_map(|x| x.iter().copied()),
                sg.r.iter().flat_map(|x| x.iter().copied()),
            );
            let dir = rel(
                sc.d.iter()
                    .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
                sg.d.iter()
                    .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
            );
            let vel = rel(
                sc.v.iter().flat_map(|x| x.iter().copied()),
                sg.v.iter().flat_map(|x| x.iter().copied()),
            );
            let energy = rel(
                c.history.iter().map(|h| h.total),
                g.history.iter().map(|h| h.total),
            );
            for (what, x) in [
                ("positions", pos),
                ("directors", dir),
                ("velocities", vel),
                ("energy history", energy),
            ] {
                assert!(x <= STATE_RTOL, "{tag}: {what} differ by {x:.3e}");
                worst = worst.max(x);
            }
        }
    }
    println!("largest relative difference GPU vs CPU: {worst:.3e}");
}
