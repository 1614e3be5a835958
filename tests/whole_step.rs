//! The step's advance on the device ≡ the CPU's, element by element and member by member.
//!
//! `advance_main` (shaders/element.wgsl) forms each element's state at `n+1` from its
//! increment with the same kinematics as the residual pass and writes it over the state at
//! `n` on the device; `record_main` sums the elements' terms of the invariants at `n+1` and
//! their dissipation per member. Checked here against the host's advance
//! (`Simulation::advanced_at`) and `invariants`, on lavapipe: cantilevers after a few CPU
//! steps, EM and EDMC-2 (frozen scalars apart from the consistent ones, so that both
//! kinematics branches run), members of different lengths in one kernel (inactive slots
//! keep their state and add nothing), two advances in a row (the second starts from the
//! state the first left on the device).
//!
//! `--solve whole` (EM members keep their state on the device, which advances it after
//! each step instead of the host uploading it): an EM cantilever batch with seeded random
//! kicks, stiffnesses, time steps and time-tabled tip loads, members that end early, fail
//! on the device and finish on the CPU (monolithic fallback), fail, run on the CPU kernel
//! or are solved on the host, through 5 slots, and the paper's frame: every member ends
//! as on the CPU path (status, reason, steps, Newton iterations, fallback steps; states
//! and energy histories within `STATE_RTOL`), as with `--solve resident`, with one host
//! sync per step and no state uploads for the steps the device advanced. Device steps
//! (the whole step on the device, the host reading records only): unloaded batches, the
//! frame kicked hard (steps handed back), and cantilevers under gravity with constant or
//! ramped tip loads (a step whose loads changed sends its nodal terms up with its request;
//! their work against the CPU path's and EM's balance H − H₀ = W), with drag, Kelvin–Voigt
//! damping, point masses, dead line loads or a sliding clamp besides.
//!
//! Without an adapter the test prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case it fails.

mod common;

use common::{batch_mix, compare_results, frame_member, gpu, rel, run_batch, Rng, STATE_RTOL};
use cosserat::batch::{bench_members, Executor, Member, SolveMode};
use cosserat::element::{ElementState, FrozenScalars, StepConsts};
use cosserat::gpu::kernel::KernelMode;
use cosserat::gpu::{gpu_required, ElementKernel, GpuContext};
use cosserat::integrator::state::State;
use cosserat::integrator::{NewtonVariant, Scheme, Simulation, Strategy};
use cosserat::observe::record::RunStatus;
use nalgebra::Vector6;

/// Bound on states and records against the CPU (round-off of the same arithmetic; the
/// records sum in another association).
const RTOL: f64 = 1e-13;

fn context() -> Option<GpuContext> {
    match GpuContext::new(None) {
        Ok(c) => Some(c),
        Err(e) if !gpu_required() => {
            println!("skipped: no adapter ({e})");
            None
        }
        Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no adapter: {e}"),
    }
}

/// The flattened fields of one element state (positions, triads, velocities, director
/// velocities) and its strains.
fn fields(st: &ElementState, eps: &Vector6<f64>) -> Vec<f64> {
    let mut v: Vec<f64> = Vec::new();
    for l in 0..2 {
        v.extend(st.cfg.r[l].iter());
        v.extend(st.cfg.d[l].iter());
        v.extend(st.v[l].iter());
        v.extend(st.vd[l].iter().flat_map(|x| x.iter().copied()));
    }
    v.extend(eps.iter());
    v
}

/// [`fields`] of every element of `state`.
fn element_fields(sim: &Simulation, state: &State) -> Vec<f64> {
    (0..sim.model().elements.len())
        .flat_map(|e| fields(&state.element(sim.model(), e), &state.eps[e]))
        .collect()
}

#[test]
fn device_advance_and_records_match_the_cpu() {
    let Some(ctx) = context() else { return };
    // Three members: EM and EDMC-2 cantilevers of 10 elements, an EM one of 6.
    let mut ms = bench_members(2, 10, 4).unwrap();
    ms[0].params.scheme = Scheme::Em;
    let mut short = bench_members(1, 6, 4).unwrap().remove(0);
    short.params.scheme = Scheme::Em;
    ms.push(short);
    let mut rng = Rng(0xad7a_11ce);
    let mut sims: Vec<Simulation> = ms
        .into_iter()
        .map(|m| {
            let mut sim = Simulation::new(m.model, m.params).unwrap();
            for _ in 0..3 {
                sim.step().unwrap();
            }
            sim
        })
        .collect();
    let per = 10;
    let mut kern = ElementKernel::new(&ctx, per * sims.len()).unwrap();
    for round in 0..2 {
        let mut want = Vec::new();
        for (m, sim) in sims.iter_mut().enumerate() {
            let p = *sim.params();
            let k = StepConsts {
                dt: p.dt,
                scheme: p.scheme,
            };
            let trans = p.scheme.translational_dissipation();
            // Frozen scalars apart from the consistent ones (EDMC-2): the advance takes
            // the frozen kinematics where c_ν differs.
            let frozen = FrozenScalars {
                beta_gamma: 0.1 * rng.next(),
                beta_omega: 0.1 * rng.next(),
                c_v: 0.1 * rng.next(),
                c_nu: 0.05 * rng.next(),
            };
            sim.set_frozen(frozen);
            let q: Vec<f64> = (0..sim.dof_map().n)
                .map(|_| 2e-3 * (rng.next() - 0.5))
                .collect();
            let (next, inv, diss) = sim.advanced_at(&q);
            let incs = sim.element_increments(&q);
            let state = sim.state().clone();
            for (e, d) in sim.element_data().iter().enumerate() {
                let i = m * per + e;
                if round == 0 {
                    kern.set_element(i, d, &k, trans);
                    kern.set_state(i, &state.element(sim.model(), e), &state.eps[e]);
                }
                kern.set_iter(i, &incs[e], &frozen);
            }
            want.push((next, inv, diss));
        }
        let got = kern.advance(KernelMode::Frozen, per).unwrap();
        for (m, (sim, (next, inv, diss))) in sims.iter_mut().zip(want).enumerate() {
            let n_el = sim.model().elements.len();
            let dev: Vec<f64> = got.states[m * per..m * per + n_el]
                .iter()
                .flat_map(|(st, eps)| fields(st, eps))
                .collect();
            let host = element_fields(sim, &next);
            let e_state = rel(host.iter().copied(), dev.iter().copied());
            let r = got.records[m];
            let h_ref = inv.kinetic.abs().max(inv.potential.abs());
            let e_energy =
                ((r.kinetic - inv.kinetic).abs() + (r.potential - inv.potential).abs()) / h_ref;
            let e_l = (r.l - inv.l).norm() / inv.l.norm().max(1e-300);
            let e_j = (r.j - inv.j).norm() / inv.j.norm().max(1e-300);
            let e_d = (r.dissipation - diss).abs() / h_ref;
            println!(
                "round {round} member {m} ({}): state {e_state:.2e}, energy {e_energy:.2e}, L {e_l:.2e}, J {e_j:.2e}, D {e_d:.2e} (D = {diss:.3e})",
                sim.params().scheme.name()
            );
            assert!(e_state <= RTOL, "member {m}: states differ by {e_state:e}");
            assert!(
                e_energy <= RTOL,
                "member {m}: energies differ by {e_energy:e}"
            );
            assert!(e_l <= RTOL && e_j <= RTOL, "member {m}: momenta differ");
            assert!(e_d <= RTOL, "member {m}: dissipation differs by {e_d:e}");
            if sim.params().scheme == Scheme::Em {
                assert_eq!(r.dissipation, 0.0, "EM dissipates nothing");
            } else {
                assert!(diss != 0.0, "the EDMC member dissipates");
            }
            // Inactive slots add nothing and keep their (zero) state.
            for (st, eps) in &got.states[m * per + n_el..(m + 1) * per] {
                assert!(st.cfg.r[0].norm() == 0.0 && eps.norm() == 0.0);
            }
            // The next round starts from the advanced state, on both sides.
            sim.set_state(next);
        }
    }
}

/// `--solve whole` against the CPU path (`fresh` Newton: the GPU paths run `full` as
/// `fresh`) and `--solve resident`; `workers` slots. Returns the worst relative
/// difference from the CPU path and from resident, and the whole run's stats.
fn check_whole(
    label: &str,
    ms: &[Member],
    exec: &Executor,
    workers: usize,
) -> (
    Vec<cosserat::batch::MemberResult>,
    cosserat::batch::BatchStats,
) {
    let (cpu, _) = run_batch(ms, &Executor::Cpu, NewtonVariant::Fresh, SolveMode::Host, 0);
    let (res, rs) = run_batch(ms, exec, NewtonVariant::Full, SolveMode::Resident, workers);
    let (whole, ws) = run_batch(ms, exec, NewtonVariant::Full, SolveMode::Whole, workers);
    assert_eq!(ws.device_members, rs.device_members, "{label}");
    assert_eq!(ws.serve.multi_mismatches, 0, "{label}");
    let (mut worst_cpu, mut worst_res) = (0.0f64, 0.0f64);
    for ((c, r), w) in cpu.iter().zip(&res).zip(&whole) {
        let i = c.index;
        worst_cpu = worst_cpu.max(compare_results(&format!("{label}, member {i}, cpu"), c, w));
        worst_res = worst_res.max(compare_results(
            &format!("{label}, member {i}, resident"),
            r,
            w,
        ));
    }
    let (kw, kr) = (&ws.gpu, &rs.gpu);
    println!(
        "{label}: whole vs CPU {worst_cpu:.3e}, vs resident {worst_res:.3e}; {} member-steps advanced on the device in {} submissions; dispatches {} (resident {}); bytes up {} (resident {}), down {} (resident {})",
        ws.serve.device_advances, ws.serve.advance_submits, ws.serve.dispatches, rs.serve.dispatches,
        kw.bytes_up, kr.bytes_up, kw.bytes_down, kr.bytes_down
    );
    assert!(
        worst_cpu <= STATE_RTOL,
        "{label}: {worst_cpu:.3e} from the CPU path"
    );
    assert!(
        ws.serve.device_advances > 0,
        "{label}: nothing advanced on the device"
    );
    // (State hand-backs of members whose steps ran on the device are syncs of their own,
    // and so is the attempt of a device step handed back to the host. Where members stream
    // through fewer slots than there are members, one whose steps ran on the device frees
    // its slot at another dispatch than with `resident`, and the next member's first
    // request can miss a dispatch it shared there: one sync of slack for the streaming
    // mix (measured: 49 dispatches, 11 pulls, none handed back, against 37).)
    let slack = u64::from(ms.len() > workers);
    assert!(
        ws.serve
            .dispatches
            .saturating_sub(ws.serve.state_pulls + ws.serve.device_step_handoffs)
            <= rs.serve.dispatches + slack,
        "{label}: syncs (dispatches {}, pulls {}, handed back {}, device steps {})",
        ws.serve.dispatches,
        ws.serve.state_pulls,
        ws.serve.device_step_handoffs,
        ws.serve.device_steps
    );
    assert!(
        kw.bytes_up < kr.bytes_up,
        "{label}: no fewer bytes up than resident"
    );
    (whole, ws)
}

#[test]
fn whole_em_batch_with_failures_and_fallbacks_ends_as_on_the_cpu_path() {
    let Some(exec) = gpu() else { return };
    let ms = batch_mix(Some(Scheme::Em), Strategy::Staggered);
    // 5 slots for 14 members: the queue streams through (a slot's next member uploads
    // its states).
    let (whole, ws) = check_whole("EM", &ms, &exec, 5);
    assert_eq!(ws.device_members, (13, 0));
    assert_eq!(whole[11].outcome.status, RunStatus::Failed);
    assert!(whole[..9]
        .iter()
        .all(|r| r.outcome.status == RunStatus::Completed));
    for r in &whole {
        println!(
            "member {}: {:?}, {} steps, {} Newton iterations, {} fallback steps",
            r.index,
            r.outcome.status,
            r.outcome.steps,
            r.outcome.newton_iters_total,
            r.outcome.fallback_steps
        );
    }
}

#[test]
fn whole_em_batch_syncs_once_per_step_and_uploads_no_states() {
    let Some(exec) = gpu() else { return };
    let mut ms = batch_mix(Some(Scheme::Em), Strategy::Staggered);
    ms.truncate(9);
    let (whole, ws) = check_whole("EM aligned", &ms, &exec, ms.len());
    let steps = whole.iter().map(|r| r.outcome.steps).max().unwrap() as u64;
    // One sync per step for the whole batch, besides each member's state coming back for
    // its result at the end.
    assert!(ws.serve.state_pulls <= whole.len() as u64);
    assert_eq!(ws.serve.dispatches - ws.serve.state_pulls, steps);
    // Every step after a member's first starts from the device's advance, and runs on the
    // device: the members' tip loads ramp over the whole run, so each step sends its nodal
    // terms up with its request.
    let member_steps: u64 = whole.iter().map(|r| r.outcome.steps as u64).sum();
    assert_eq!(ws.serve.device_advances, member_steps - whole.len() as u64);
    assert_eq!(ws.serve.device_steps, member_steps - whole.len() as u64);
    assert_eq!(ws.serve.device_step_handoffs, 0);
}

#[test]
fn whole_frame_matches_cpu() {
    let Some(exec) = gpu() else { return };
    let ms = vec![frame_member(15.0, |p| p.scheme = Scheme::Em)];
    let (whole, ws) = check_whole("frame", &ms, &exec, 1);
    assert_eq!(ws.device_members, (1, 0), "the frame is covered");
    assert_eq!(whole[0].outcome.status, RunStatus::Completed);
    assert_eq!(whole[0].outcome.steps, 15);
}

/// `--solve whole` with whole steps on the device: an EM cantilever batch (seeded random
/// kicks, stiffnesses and time steps) whose unloaded members the device step covers (the
/// host reads their records only), loaded ones (their tip loads ramp over the whole run:
/// each device step sends the step's nodal terms up), a member that ends
/// early, one whose Newton cap the device's iterations pass (handed back to the host's
/// step, which fails it as the CPU path does), one kicked hard, one on the CPU kernel
/// (gen-α) and one host-solved (a carried clamp), through `workers` slots: every member ends as
/// on the CPU path.
fn device_step_mix() -> Vec<Member> {
    let mut ms = batch_mix(Some(Scheme::Em), Strategy::Staggered);
    for (i, m) in ms.iter_mut().enumerate() {
        if i < 5 {
            m.model.loads.clear();
        }
        if i == 10 {
            // Kicked hard: long Newton solves (past the device step's iterations, some).
            m.model.velocity0.iter_mut().for_each(|v| *v *= 3.0);
            m.params.dt *= 2.0;
            m.params.t_end = 6.0 * m.params.dt;
        }
    }
    ms
}

fn check_device_steps(label: &str, ms: &[Member], workers: usize) -> cosserat::batch::BatchStats {
    let Some(exec) = gpu() else {
        return Default::default();
    };
    let (cpu, _) = run_batch(ms, &Executor::Cpu, NewtonVariant::Fresh, SolveMode::Host, 0);
    let (whole, ws) = run_batch(ms, &exec, NewtonVariant::Full, SolveMode::Whole, workers);
    let mut worst = 0.0f64;
    for (c, w) in cpu.iter().zip(&whole) {
        let i = c.index;
        worst = worst.max(compare_results(&format!("{label}, member {i}"), c, w));
        println!(
            "{label} member {i}: {:?}, {} steps, {} Newton iterations",
            w.outcome.status, w.outcome.steps, w.outcome.newton_iters_total
        );
    }
    let st = &ws.serve;
    println!(
        "{label}: vs CPU {worst:.3e}; device steps {} ({} handed back), state pulls {} ({} B), dispatches {}, multi dispatches {}, bytes up {}, down {}",
        st.device_steps,
        st.device_step_handoffs,
        st.state_pulls,
        st.pull_bytes_down,
        st.dispatches,
        st.multi_dispatches,
        ws.gpu.bytes_up,
        ws.gpu.bytes_down
    );
    assert!(
        worst <= STATE_RTOL,
        "{label}: {worst:.3e} from the CPU path"
    );
    assert!(st.device_steps > 0, "{label}: no step ran on the device");
    ws
}

#[test]
fn whole_device_steps_end_as_on_the_cpu_path() {
    let ms = device_step_mix();
    let ws = check_device_steps("device steps", &ms, 5);
    if ws.serve.device_steps == 0 {
        return;
    }
    // Member 11's Newton cap (2) is passed on the device: handed back, fails as on the CPU.
    assert!(ws.serve.device_step_handoffs >= 1);
}

#[test]
fn whole_device_steps_sync_once_per_step_and_read_records_only() {
    // Unloaded members only, one slot each: every step after a member's first is a device
    // step; one sync per step, plus one state hand-back per member at its end.
    let ms: Vec<Member> = device_step_mix().into_iter().take(5).collect();
    let ws = check_device_steps("device steps aligned", &ms, ms.len());
    if ws.serve.device_steps == 0 {
        return;
    }
    let st = &ws.serve;
    let steps = 6u64;
    assert_eq!(st.device_step_handoffs, 0);
    assert_eq!(st.device_steps, (steps - 1) * ms.len() as u64);
    assert_eq!(st.state_pulls, ms.len() as u64);
    assert_eq!(st.dispatches - st.state_pulls, steps);
    // What a device step reads back per member: the iteration history, the residual
    // work and the record.
    assert!(st.device_step_bytes_down / st.device_steps <= 512);
    // What goes up with dispatches of device steps only: operation words and slot lists,
    // no states, increments or iteration rows (measured 115 bytes per device step: 4
    // each after a member's first, whose slot lists go up once; 451 when the iteration
    // rows the device stopped went up again with every step).
    let (up, n) = st.device_step_bytes_up;
    assert_eq!(
        n, st.device_steps,
        "device steps in dispatches of their own"
    );
    println!("bytes up per device step: {:.1}", up as f64 / n as f64);
    assert!(
        up / n <= 200,
        "{} bytes up per device step",
        up as f64 / n as f64
    );
}

/// The paper's frame unloaded and kicked hard: some of its Newton solves take more
/// iterations than a device step runs (those steps are handed back to the host's step and
/// go on from there), the others are taken from the device's records; it ends as on the
/// CPU path.
#[test]
fn whole_frame_without_loads_runs_on_the_device_as_on_the_cpu() {
    let mut m = frame_member(15.0, |p| p.scheme = Scheme::Em);
    m.model.loads.clear();
    // (Unloaded, the frame at rest stays at rest: kick it.)
    let n = m.model.velocity0.len();
    m.model.velocity0[n / 2] = cosserat::model::Vec3::new(0.3, -0.2, 0.1);
    let ws = check_device_steps("frame, unloaded", &[m], 1);
    if ws.serve.device_steps == 0 {
        return;
    }
    let st = &ws.serve;
    assert!(st.device_step_handoffs >= 1, "no step handed back");
    assert!(
        st.device_steps > st.device_step_handoffs,
        "no step taken from the device"
    );
    // One hand-back per handed-back step, one at the end.
    assert_eq!(st.state_pulls, st.device_step_handoffs + 1);
}

/// EM cantilevers under gravity with dead tip loads: constant (the device holds the loads
/// from the member's first step on) or ramped over the first steps and constant after
/// (while the load changes, each device step sends the step's nodal terms up with its
/// request); kicked, with random stiffnesses and time steps.
fn loaded_mix() -> Vec<Member> {
    let mut ms = batch_mix(Some(Scheme::Em), Strategy::Staggered);
    ms.truncate(9);
    for (i, m) in ms.iter_mut().enumerate() {
        m.model.gravity = cosserat::model::Vec3::new(0.0, 0.0, -9.81);
        let dt = m.params.dt;
        let load = &mut m.model.loads[0];
        load.table = if i % 2 == 0 {
            cosserat::table::TimeTable {
                times: vec![0.0],
                values: vec![1.0],
            }
        } else {
            cosserat::table::TimeTable {
                times: vec![0.0, 2.0 * dt],
                values: vec![0.2, 1.0],
            }
        };
        m.params.t_end = 8.0 * dt;
    }
    ms
}

/// What [`check_loaded`] measured: the largest differences from the CPU path (states,
/// the loads' work W and the dissipation D per step), the largest miss of H − H₀ = W − D
/// along the runs, and the batch's counters.
struct Loaded {
    worst: f64,
    worst_w: f64,
    worst_d: f64,
    worst_balance: f64,
    /// The least dissipation of any step of any member.
    least_d: f64,
    stats: cosserat::batch::BatchStats,
}

/// Runs `ms` on the CPU path and with `--solve whole` (5 slots): every member completes
/// and ends as on the CPU path (status, steps, iterations; [`compare_results`]); `None`
/// without an adapter.
fn check_loaded(label: &str, ms: &[Member]) -> Option<Loaded> {
    let exec = gpu()?;
    let (cpu, _) = run_batch(ms, &Executor::Cpu, NewtonVariant::Fresh, SolveMode::Host, 0);
    let (whole, stats) = run_batch(ms, &exec, NewtonVariant::Full, SolveMode::Whole, 5);
    let mut out = Loaded {
        worst: 0.0,
        worst_w: 0.0,
        worst_d: 0.0,
        worst_balance: 0.0,
        least_d: f64::INFINITY,
        stats,
    };
    for (c, w) in cpu.iter().zip(&whole) {
        let i = c.index;
        assert_eq!(
            w.outcome.status,
            RunStatus::Completed,
            "{label}, member {i}"
        );
        out.worst = out
            .worst
            .max(compare_results(&format!("{label}, member {i}"), c, w));
        let per_step = |f: fn(&cosserat::integrator::record::StepRecord) -> f64| {
            rel(c.history.iter().map(f), w.history.iter().map(f))
        };
        out.worst_w = out.worst_w.max(per_step(|h| h.external_work));
        out.worst_d = out.worst_d.max(per_step(|h| h.dissipation));
        let least = w.history[1..]
            .iter()
            .map(|h| h.dissipation)
            .fold(f64::INFINITY, f64::min);
        out.least_d = out.least_d.min(least);
        let h0 = w.history[0].total;
        let scale = w
            .history
            .iter()
            .map(|h| h.total.abs().max(h.work_total.abs()))
            .fold(h0.abs(), f64::max);
        for h in &w.history {
            let gap = (h.total - h0 - (h.work_total - h.dissipation_total)).abs() / scale;
            out.worst_balance = out.worst_balance.max(gap);
        }
    }
    let st = &out.stats.serve;
    println!(
        "{label}: vs CPU {:.3e}, W {:.3e}, D {:.3e}, balance {:.3e}; device steps {} ({} handed back), state pulls {}",
        out.worst,
        out.worst_w,
        out.worst_d,
        out.worst_balance,
        st.device_steps,
        st.device_step_handoffs,
        st.state_pulls
    );
    assert!(
        out.worst <= STATE_RTOL,
        "{label}: {:.3e} from the CPU path",
        out.worst
    );
    assert!(
        out.worst_w <= STATE_RTOL,
        "{label}: W {:.3e} from the CPU path",
        out.worst_w
    );
    assert!(
        out.worst_d <= STATE_RTOL,
        "{label}: D {:.3e} from the CPU path",
        out.worst_d
    );
    assert!(
        out.worst_balance <= 1e-12,
        "{label}: energy balance {:.3e}",
        out.worst_balance
    );
    Some(out)
}

/// The least accepted device steps of the loaded batches: 9 members × 7 steps after their
/// first, less one handed back (measured: 62 or 63 of 63 on each variant).
const ACCEPTED: u64 = 9 * 7 - 1;

/// Asserts that at least `least` device steps were accepted (run on the device and not
/// handed back to the host).
fn assert_accepted_device_steps(l: &Loaded, least: u64) {
    let st = &l.stats.serve;
    assert!(
        st.device_steps - st.device_step_handoffs >= least,
        "{} device steps, {} handed back",
        st.device_steps,
        st.device_step_handoffs
    );
}

#[test]
fn whole_device_steps_with_dead_loads_end_as_on_the_cpu_path() {
    let Some(l) = check_loaded("loaded", &loaded_mix()) else {
        return;
    };
    // Every step after a member's first, constant or ramped loads: 7 of 8 for each of the
    // 9 members (measured: one handed back to the host).
    let st = &l.stats.serve;
    assert_eq!(st.device_steps, 9 * 7, "device steps");
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with Kelvin–Voigt damping (relaxation time 2Δt) in every element.
fn damped_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for m in &mut ms {
        let dt = m.params.dt;
        for e in &mut m.model.elements {
            e.props.damping = 2.0 * dt;
        }
    }
    ms
}

/// Kelvin–Voigt damping on device steps: the element passes dissipate, the records pass
/// sums D, and the host replays the dissipation identity H_n − H_n+1 + W = D on the
/// device's numbers. The members end as on the CPU path, dissipate on every step, and
/// H − H₀ = W − D holds along the run.
#[test]
fn whole_device_steps_with_kelvin_voigt_damping_end_as_on_the_cpu_path() {
    let ms = damped_mix();
    let Some(l) = check_loaded("damped", &ms) else {
        return;
    };
    assert!(l.least_d > 0.0, "a step without dissipation");
    // As the undamped loaded batch: every member from its second step; the host's checks
    // accept them (measured: all).
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with drag on every element: `c = ρA/(4Δt)`, so that the drag's
/// `c h/Δt` is an eighth of the translational mass term `2ρAh/Δt²`.
fn dragged_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for m in &mut ms {
        let dt = m.params.dt;
        for e in &mut m.model.elements {
            e.props.drag = e.props.a_rho / (4.0 * dt);
        }
    }
    ms
}

/// Drag on device steps: the element passes add its rows, tangent and dissipation (it
/// depends on the iterate, so the device solve needs it there) and the records pass sums
/// D with the rest. The members end as on the CPU path, where the host adds the drag after
/// the element kernel, dissipate on every step, and H − H₀ = W − D holds along the run.
#[test]
fn whole_device_steps_with_drag_end_as_on_the_cpu_path() {
    let ms = dragged_mix();
    let Some(l) = check_loaded("dragged", &ms) else {
        return;
    };
    assert!(l.least_d > 0.0, "a step without dissipation");
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with a point mass at the tip of each member, of a fifth of its rod's mass
/// (the element kernel carries it on the last element's free end), and one of a tenth at
/// its middle node.
fn tip_mass_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for m in &mut ms {
        let rod: f64 = m
            .model
            .elements
            .iter()
            .map(|e| e.props.a_rho * e.props.h)
            .sum();
        let tip = m.model.n_nodes() - 1;
        m.model.point_mass[tip] = 0.2 * rod;
        // And one on an interior node, which two elements join (the first carries it).
        m.model.point_mass[tip / 2] = 0.1 * rod;
    }
    ms
}

/// Point masses on device steps: the element passes add their inertia rows and tangent,
/// and the advance pass their kinetic energy and momenta to the records, so the host's
/// energy check sees the whole H. The members end as on the CPU path, where the host adds
/// the point masses at their nodes, with H − H₀ = W along the run.
#[test]
fn whole_device_steps_with_point_masses_end_as_on_the_cpu_path() {
    let Some(l) = check_loaded("tip masses", &tip_mass_mix()) else {
        return;
    };
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with each member's tip guided by a sliding clamp along e3 (spinning
/// about it on every other member): the held components are removed unknowns, as a
/// clamp's, and the support does no work.
fn guided_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for (i, m) in ms.iter_mut().enumerate() {
        let tip = m.model.n_nodes() - 1;
        m.model.supports[tip] = cosserat::model::Support {
            translation: true,
            rotation: true,
        };
        m.model.slides.push(cosserat::model::Slide {
            node: tip,
            axis: cosserat::model::Vec3::new(0.0, 0.0, 1.0),
            spin: i % 2 == 1,
        });
    }
    ms
}

/// Sliding clamps along a coordinate axis on device steps: the members end as on the CPU
/// path with H − H₀ = W (the loads' work along the slide) along the run.
#[test]
fn whole_device_steps_with_sliding_clamps_end_as_on_the_cpu_path() {
    let Some(l) = check_loaded("guided", &guided_mix()) else {
        return;
    };
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with each member's root support driven by a time table: carried at
/// constant velocity along e2 on the even members (the same increment every step: nothing
/// goes up after the first), carried and turned about e3 along a smooth ramp on the odd
/// ones (new increments every step); on every third member the root is a pin (its
/// rotation free: the device's iterate of those unknowns stays as the prescribed ones are
/// set beside them).
fn driven_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for (i, m) in ms.iter_mut().enumerate() {
        let t1 = m.params.t_end;
        let pin = i % 3 == 0;
        if pin {
            m.model.supports[0].rotation = false;
        }
        let (rotation, ramp) = if i % 2 == 1 && !pin {
            (
                cosserat::model::Vec3::new(0.0, 0.0, 0.1),
                cosserat::table::Ramp::Smooth,
            )
        } else {
            (
                cosserat::model::Vec3::zeros(),
                cosserat::table::Ramp::Linear,
            )
        };
        m.model.drives.push(cosserat::model::SupportDrive {
            node: 0,
            displacement: cosserat::model::Vec3::new(0.0, 0.01, 0.005),
            rotation,
            table: cosserat::table::TimeTable {
                times: vec![0.0, t1],
                values: vec![0.0, 1.0],
            },
            ramp,
        });
        // A force and a moment at the driven node of every third member (from the
        // second): they work on its prescribed motion, which the host takes out of the
        // device's reaction work.
        if i % 3 == 1 {
            let table = m.model.loads[0].table.clone();
            m.model.loads.push(cosserat::model::NodalLoad {
                node: 0,
                force: cosserat::model::Vec3::new(0.3, -0.2, 0.1),
                moment: cosserat::model::Vec3::new(0.02, 0.01, -0.03),
                table,
            });
        }
    }
    ms
}

/// Driven supports on device steps: each step's request carries the prescribed
/// increments that changed, the update pass sums the reactions' work over the removed
/// unknowns, and the host takes the work of its loads at the driven nodes from it. The
/// members end as on the CPU path, their support work per step too, with H − H₀ = W along
/// the run (W with the supports' work), one sync per step and ≤ 512 bytes up per device
/// step.
#[test]
fn whole_device_steps_with_driven_supports_end_as_on_the_cpu_path() {
    let ms = driven_mix();
    let Some(l) = check_loaded("driven", &ms) else {
        return;
    };
    // (Measured: all 63 device steps, none handed back.)
    assert_accepted_device_steps(&l, ACCEPTED);
    let exec = gpu().expect("an adapter: check_loaded ran");
    let (cpu, _) = run_batch(
        &ms,
        &Executor::Cpu,
        NewtonVariant::Fresh,
        SolveMode::Host,
        0,
    );
    let (whole, stats) = run_batch(&ms, &exec, NewtonVariant::Full, SolveMode::Whole, 5);
    let mut worst = 0.0f64;
    for (c, w) in cpu.iter().zip(&whole) {
        let f = |h: &cosserat::integrator::record::StepRecord| h.support_work;
        worst = worst.max(rel(c.history.iter().map(f), w.history.iter().map(f)));
        let total: f64 = w.history.iter().map(f).sum();
        assert!(
            total.abs() > 1e-9,
            "member {}: support work {total:e}",
            c.index
        );
    }
    let (up, n) = stats.serve.device_step_bytes_up;
    println!(
        "driven: support work per step vs CPU {worst:.3e}; {:.0} bytes up per device step",
        up as f64 / n.max(1) as f64
    );
    assert!(
        worst <= STATE_RTOL,
        "support work {worst:.3e} from the CPU path"
    );
    assert!(n > 0 && up <= 512 * n, "{up} bytes up for {n} device steps");
}

/// [`loaded_mix`] with a line load on every element besides (a distributed force `force`
/// and moment `moment` per unit mass, on the nodal loads' time table: constant on the even
/// members, ramped on the odd ones), dead or `follower`.
fn with_line_load(
    follower: bool,
    force: cosserat::model::Vec3,
    moment: cosserat::model::Vec3,
) -> Vec<Member> {
    let mut ms = loaded_mix();
    for m in &mut ms {
        let arho = m.model.elements[0].props.a_rho;
        let table = m.model.loads[0].table.clone();
        m.model.line_loads.push(cosserat::model::LineLoad {
            elements: (0..m.model.elements.len()).collect(),
            force: force * arho,
            moment: moment * arho,
            follower,
            table,
        });
    }
    ms
}

/// [`loaded_mix`] with a dead line load on every element besides (a distributed force
/// across the rod and a distributed moment): its nodal terms go up with the others and the
/// device sums their work with them.
fn line_loaded_mix() -> Vec<Member> {
    with_line_load(
        false,
        cosserat::model::Vec3::new(0.0, 3.0, 1.0),
        cosserat::model::Vec3::new(0.0, 0.0, 0.02),
    )
}

/// Dead line loads on device steps: their nodal terms are dead nodal terms (no tangent),
/// so the device solve and the device steps cover them; the members end as on the CPU
/// path, with the loads' work per step as the CPU's and H − H₀ = W.
#[test]
fn whole_device_steps_with_dead_line_loads_end_as_on_the_cpu_path() {
    let Some(l) = check_loaded("line-loaded", &line_loaded_mix()) else {
        return;
    };
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// [`loaded_mix`] with a follower line load on every element besides: a force across the
/// rod and a moment about it in the director frame, turning with the rod (its factors go
/// up with each step's request while the odd members' tables ramp).
fn follower_mix() -> Vec<Member> {
    with_line_load(
        true,
        cosserat::model::Vec3::new(2.0, 1.0, 0.0),
        cosserat::model::Vec3::new(0.0, 0.0, 0.02),
    )
}

/// Follower line loads on device steps: the element passes add their rows and tangent
/// (over the ends' mid-step directors) and the records pass their work; the members end as
/// on the CPU path, with the loads' work per step as the CPU's (nodal loads, gravity and
/// the followers) and H − H₀ = W.
#[test]
fn whole_device_steps_with_follower_line_loads_end_as_on_the_cpu_path() {
    let Some(l) = check_loaded("follower", &follower_mix()) else {
        return;
    };
    let st = &l.stats.serve;
    assert_eq!(st.device_steps, 9 * 7, "device steps");
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// `bench --solve whole` times that mode alone: EM cantilevers (`COSSERAT_BENCH_SCHEME=em`)
/// under gravity (`COSSERAT_BENCH_GRAVITY=1`) take every step after their first on the
/// device, and the JSON `whole` object reports the figures of docs/gpu.md.
#[test]
fn bench_solve_whole_reports_device_steps() {
    if gpu().is_none() {
        return;
    }
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["bench", "--rods", "3", "--elements", "6", "--steps", "4"])
        .args(["--solve", "whole", "--gpu-only", "--json"])
        .env("COSSERAT_BENCH_SCHEME", "em")
        .env("COSSERAT_BENCH_GRAVITY", "1")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let json: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    assert_eq!(json["scheme"], "em");
    assert_eq!(json["gravity"], -9.81);
    assert!(
        json["resident"].is_null() && json["device"].is_null(),
        "{json}"
    );
    let w = &json["whole"];
    assert_eq!(w["device_steps"], 9, "{w}");
    assert_eq!(w["host_syncs_per_step"], 1.0, "{w}");
    for key in [
        "host_own_us_per_member_step",
        "member_cpu_us_per_member_step",
        "serve_own_us_per_member_step",
        "driver_thread_us_per_member_step",
        "device_step_bytes_up_per_step",
        "gpu_wall_over_device_pass",
        "host_own_us_per_device_step",
        "host_own_us_per_device_step_p90",
        "serve_own_us_per_device_step",
        "host_wall_us_per_dispatch",
    ] {
        assert!(w[key].as_f64().is_some_and(f64::is_finite), "{key}: {w}");
    }
    // The steady state: the batch iterations of steps 3 and 4 (step 2's followed the
    // first step's host dispatches); the median lies within the percentile, the driver
    // thread's share within the whole.
    assert_eq!(w["device_step_rounds"], 2, "{w}");
    let f = |k: &str| w[k].as_f64().unwrap();
    assert!(f("host_own_us_per_device_step") <= f("host_own_us_per_device_step_p90"));
    assert!(f("serve_own_us_per_device_step") <= f("host_own_us_per_device_step_p90"));
    assert!(f("host_own_us_per_device_step") > 0.0, "{w}");
}

/// [`loaded_mix`] in the dissipative schemes with the inexact strategy: EDMC-2 (the
/// bench's α) on the even members, EDMC-1 with all four χ on the odd ones.
fn inexact_mix() -> Vec<Member> {
    let mut ms = loaded_mix();
    for (i, m) in ms.iter_mut().enumerate() {
        m.params.scheme = if i % 2 == 0 {
            Scheme::Edmc2 {
                alpha_gv: 0.5,
                alpha_gn: 0.5,
                alpha_ov: 0.5,
                alpha_on: 0.5,
            }
        } else {
            Scheme::Edmc1 {
                chi_gamma: 0.1,
                chi_omega: 0.1,
                chi_v: 0.1,
                chi_nu: 0.1,
            }
        };
        m.params.strategy = Strategy::Inexact;
    }
    ms
}

/// EDMC-1 and EDMC-2 on device steps (the inexact strategy): the device runs the
/// consistent-scalar iterations, freezes the scalars consistent with the iterate they
/// accept and runs the polish round, and the records pass sums D; the host replays both
/// Newton tests and the dissipation identity H_n − H_n+1 + W = D on the device's numbers.
/// The members end as on the CPU path with the same strategy, dissipate on every step and
/// H − H₀ = W − D holds along the run.
#[test]
fn whole_device_steps_of_edmc_with_the_inexact_strategy_end_as_on_the_cpu_path() {
    let ms = inexact_mix();
    let Some(l) = check_loaded("inexact EDMC", &ms) else {
        return;
    };
    assert!(l.least_d > 0.0, "a step without dissipation");
    let st = &l.stats.serve;
    assert_eq!(st.device_steps, 9 * 7, "device steps");
    // Measured: 62 of 63 accepted; one step's inexact iterations wander from the
    // predictor (the host's step then moves on to its next predictor).
    assert_accepted_device_steps(&l, ACCEPTED);
}

/// The 14-member mix in EDMC-2 with the inexact strategy: members that end early, one that
/// falls back to the monolithic strategy on the CPU and finishes, one that fails on its
/// Newton cap, a generalized-α member (CPU kernel) and one with a carried clamp (host
/// solve), through 5 slots: every member ends as on the CPU path, and the steps the device
/// cannot finish are handed back.
#[test]
fn whole_device_steps_of_edmc_with_failures_end_as_on_the_cpu_path() {
    let ms = batch_mix(None, Strategy::Inexact);
    check_device_steps("inexact EDMC mix", &ms, 5);
}

/// The bench's EDMC-2 cantilevers (30 elements, gravity) with the inexact strategy: their
/// round-off floor lies at the Newton tolerance, so many steps accept their
/// consistent-scalar iterate on the floor above the tolerance, where the host's step
/// checks it with the consistent scalars and polishes nothing; the device step stops there
/// too (its element slots keep "consistent" for the records and the next advance). Which
/// iterate a step accepts on its floor is decided by round-off (the CPU path and `--solve
/// resident` differ by a Newton iteration on 4 of these 6 members as well), so the members
/// are compared by status, steps, final states and energy histories (within
/// `STATE_RTOL`), not by Newton iterations. No device step goes back to the host. The
/// members run 3 to 12 steps, so that some end on a step accepted on the floor (the host's
/// copy of the final state then forms with the consistent scalars too).
#[test]
fn whole_device_steps_of_edmc_accepted_on_the_floor_end_as_on_the_cpu_path() {
    let Some(exec) = gpu() else {
        return;
    };
    // All four α (c_ν ≠ 0: the consistent kinematics differ from the frozen ones).
    let mut ms = bench_members(10, 30, 8).unwrap();
    for (i, m) in ms.iter_mut().enumerate() {
        m.params.t_end = (3 + i) as f64 * m.params.dt;
        m.params.strategy = Strategy::Inexact;
        m.params.scheme = Scheme::Edmc2 {
            alpha_gv: 0.5,
            alpha_gn: 0.5,
            alpha_ov: 0.5,
            alpha_on: 0.5,
        };
    }
    let tol = ms[0].params.newton_tol;
    let (cpu, _) = run_batch(
        &ms,
        &Executor::Cpu,
        NewtonVariant::Fresh,
        SolveMode::Host,
        0,
    );
    let (whole, ws) = run_batch(&ms, &exec, NewtonVariant::Full, SolveMode::Whole, 6);
    let mut worst = 0.0f64;
    let mut on_floor = 0;
    for (c, w) in cpu.iter().zip(&whole) {
        let i = c.index;
        assert_eq!(w.outcome.status, RunStatus::Completed, "member {i}");
        assert_eq!(c.outcome.steps, w.outcome.steps, "member {i}");
        let (sc, sw) = (c.state.as_ref().unwrap(), w.state.as_ref().unwrap());
        let flat = |s: &State| -> Vec<f64> {
            s.r.iter()
                .chain(&s.v)
                .flat_map(|x| x.iter().copied())
                .chain(
                    s.d.iter()
                        .flat_map(|d| d.iter().flat_map(|x| x.iter().copied())),
                )
                .collect()
        };
        worst = worst.max(rel(flat(sc).into_iter(), flat(sw).into_iter()));
        let energy = |r: &cosserat::batch::MemberResult| -> Vec<f64> {
            r.history
                .iter()
                .flat_map(|h| [h.total, h.dissipation_total])
                .collect()
        };
        worst = worst.max(rel(energy(c).into_iter(), energy(w).into_iter()));
        // (The steps after each member's first: device steps.)
        on_floor += w
            .history
            .iter()
            .skip(2)
            .filter(|h| h.residual > tol)
            .count();
    }
    let st = &ws.serve;
    println!(
        "EDMC on the floor: vs CPU {worst:.3e}; steps accepted above the tolerance {on_floor}; device steps {} ({} handed back)",
        st.device_steps, st.device_step_handoffs
    );
    assert!(worst <= STATE_RTOL, "{worst:.3e} from the CPU path");
    assert!(
        on_floor > 0,
        "no step accepted on the floor: the test misses its case"
    );
    assert_eq!(st.device_steps, (2..12).sum::<u64>(), "device steps");
    assert_eq!(st.device_step_handoffs, 0, "steps handed back");
}
