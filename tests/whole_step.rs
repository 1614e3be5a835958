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
//! Without an adapter the test prints `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU`
//! is set, in which case it fails.

mod common;

use common::{rel, Rng};
use cosserat::batch::bench_members;
use cosserat::element::{FrozenScalars, StepConsts};
use cosserat::gpu::kernel::KernelMode;
use cosserat::gpu::{gpu_required, ElementKernel, GpuContext};
use cosserat::integrator::state::State;
use cosserat::integrator::{Scheme, Simulation};

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

/// The flattened element fields of `state` (positions, triads, velocities, director
/// velocities, strains) of every element.
fn element_fields(sim: &Simulation, state: &State) -> Vec<f64> {
    let model = sim.model();
    (0..model.elements.len())
        .flat_map(|e| {
            let st = state.element(model, e);
            let mut v: Vec<f64> = Vec::new();
            for l in 0..2 {
                v.extend(st.cfg.r[l].iter());
                v.extend(st.cfg.d[l].iter());
                v.extend(st.v[l].iter());
                v.extend(st.vd[l].iter().flat_map(|x| x.iter().copied()));
            }
            v.extend(state.eps[e].iter());
            v
        })
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
                .flat_map(|(st, eps)| {
                    let mut v: Vec<f64> = Vec::new();
                    for l in 0..2 {
                        v.extend(st.cfg.r[l].iter());
                        v.extend(st.cfg.d[l].iter());
                        v.extend(st.v[l].iter());
                        v.extend(st.vd[l].iter().flat_map(|x| x.iter().copied()));
                    }
                    v.extend(eps.iter());
                    v
                })
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
