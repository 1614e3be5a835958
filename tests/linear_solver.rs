//! The Newton linear solver on the built-in scenes: rods numbered node by node get the
//! block-tridiagonal LU, and modified Newton reuses its factorization (fewer
//! factorizations than solves) while reproducing the full-Newton trajectory.
use cosserat::integrator::{NewtonVariant, Scheme, Simulation};
use cosserat::linsolve::SolverKind;
use cosserat::scene::load_scene;

/// Both Newton variants converge to 1e-11 of the force scale; the levels they reach
/// differ by round-off amplified over the run.
const HISTORY_RTOL: f64 = 1e-11;

fn sim(name: &str, scheme: Scheme, steps: usize) -> Simulation {
    sim_with(name, scheme, steps, NewtonVariant::Full)
}

fn sim_with(name: &str, scheme: Scheme, steps: usize, newton: NewtonVariant) -> Simulation {
    let scene = load_scene(name).unwrap();
    let mut p = scene.params;
    p.scheme = scheme;
    p.t_end = p.dt * steps as f64;
    p.newton = newton;
    Simulation::new(scene.model, p).unwrap()
}

#[test]
fn rods_get_the_block_tridiagonal_solver() {
    // (scene, scheme, padded block): 6 = u θ, 9 = u θ g, planar arch 3 = u₂ θ₁ and
    // 6 ⊇ u₂ θ₁ g₂; the mechanisms are small enough for the dense LU.
    let cases = [
        ("frame", Scheme::Em, SolverKind::BlockTridiagonal(6)),
        ("frame", Scheme::edmc2(0.5), SolverKind::BlockTridiagonal(9)),
        ("cantilever", Scheme::Em, SolverKind::BlockTridiagonal(6)),
        ("arch", Scheme::Em, SolverKind::BlockTridiagonal(3)),
        ("arch", Scheme::edmc2(1.0), SolverKind::BlockTridiagonal(6)),
        ("mechanism", Scheme::Em, SolverKind::Dense),
    ];
    for (name, scheme, kind) in cases {
        assert_eq!(sim(name, scheme, 1).linear_solver().0, kind, "{name}");
    }
}

#[test]
fn modified_newton_reuses_the_factorization_and_follows_full_newton() {
    for (name, steps) in [("frame", 40), ("cantilever", 30)] {
        // `fresh`: every correction with a fresh tangent (`full` reuses one at a step's
        // start, see below).
        let mut full = sim_with(name, Scheme::edmc2(0.5), steps, NewtonVariant::Fresh);
        let mut modified = sim_with(name, Scheme::edmc2(0.5), steps, NewtonVariant::Modified);
        let mut worst = 0.0f64;
        for step in 0..steps {
            full.step().unwrap();
            modified.step().unwrap();
            let (a, b) = (full.invariants().total(), modified.invariants().total());
            worst = worst.max((a - b).abs() / a.abs());
            assert!(
                (a - b).abs() <= HISTORY_RTOL * a.abs(),
                "{name} step {step}: H {a} vs {b}"
            );
        }
        // Measured 1.4e-12 (frame), 2.2e-13 (cantilever; 4.0e-14 before the reciprocal
        // 1/Δt, 1/h of the element kernel); bound HISTORY_RTOL = 1e-11.
        eprintln!("{name}: modified vs full Newton energy history {worst:.1e}");
        let (tf, tm) = (full.solve_timers(), modified.solve_timers());
        assert_eq!(tf.factorizations, tf.solves, "{name}: fresh Newton");
        assert!(
            tm.factorizations < tm.solves,
            "{name}: modified Newton factorized {} times for {} solves",
            tm.factorizations,
            tm.solves
        );
        assert_eq!(
            full.linear_solver().1,
            0,
            "{name}: block LU needed its fallback"
        );
    }
}

/// `full` Newton on the CPU path: a step's first correction reuses the last step's
/// factorization where that step's predictor was far from its solution (the cantilever's
/// are, at relative residual ≈ 1.5). Same corrections, a third fewer factorizations and
/// tangents, the same trajectory, EM's energy still to round-off.
#[test]
fn full_newton_reuses_the_last_factorization_at_a_step_start() {
    let steps = 100;
    let mut full = sim_with("cantilever", Scheme::Em, steps, NewtonVariant::Full);
    let mut fresh = sim_with("cantilever", Scheme::Em, steps, NewtonVariant::Fresh);
    let h0 = full.invariants().total();
    let (mut worst_diff, mut worst_step) = (0.0f64, 0.0f64);
    let mut h_prev = h0;
    for step in 0..steps {
        full.step().unwrap();
        fresh.step().unwrap();
        let (a, b) = (full.invariants().total(), fresh.invariants().total());
        worst_diff = worst_diff.max((a - b).abs() / h0);
        worst_step = worst_step.max((a - h_prev).abs() / h0);
        h_prev = a;
        let r = full
            .state()
            .r
            .iter()
            .zip(&fresh.state().r)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).norm()));
        assert!(r <= 1e-12, "step {step}: positions differ by {r:e}");
    }
    let (tf, tr) = (full.solve_timers(), fresh.solve_timers());
    eprintln!(
        "cantilever, {steps} EM steps: full {} factorizations / {} solves, fresh {} / {}; \
         H full vs fresh {worst_diff:.1e}, full's largest step change {worst_step:.1e}",
        tf.factorizations, tf.solves, tr.factorizations, tr.solves
    );
    assert_eq!(tr.factorizations, tr.solves);
    // Measured: 3 corrections per step on both; 201 against 300 factorizations; H apart
    // by 2.0e-13 of H (9.0e-14 before the reciprocal 1/Δt, 1/h of the element kernel),
    // full's largest change of H in a step 2.9e-14.
    assert_eq!(
        tf.solves, tr.solves,
        "the kept first correction costs a correction"
    );
    assert!(
        3 * tf.factorizations <= 2 * tr.factorizations + 3,
        "full Newton factorized {} times (fresh {})",
        tf.factorizations,
        tr.factorizations
    );
    assert!(worst_diff <= 5e-13, "H full vs fresh {worst_diff:e}");
    assert!(
        worst_step <= 1e-13,
        "EM energy changed by {worst_step:e} in a step"
    );
}
