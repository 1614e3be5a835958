//! The rational curvature measure (`[[rod]] curvature_measure = "rational"`,
//! docs/theory.md §2): `Ω̃ = 3 sin δ / ((2 + cos δ) h)` per element. EM keeps its energy
//! identity and momenta to round-off with it (the algebraic discrete gradient), its Newton
//! tangent is the derivative of the residual, small turns follow the sine measure to
//! second order, a fold past π/4 per element that the sine measure refuses holds, and a
//! uniform twist stores `(f(δ)/δ)² = 1 − δ⁴/90 + …` of the continuum energy.
use cosserat::integrator::{IntegratorParams, Scheme, Simulation};
use cosserat::model::{CurvatureMeasure, Model, Support, Vec3};
use cosserat::scene::parse_scene;

mod common;

const E: f64 = 1e6;
const R: f64 = 0.02;
const EM: &str = "scheme = \"em\"\ndt = 1e-3\nt_end = 1";
/// The rod key, placed first in a [`scene`]'s `extra` (it belongs to the `[[rod]]` table).
const RATIONAL: &str = "curvature_measure = \"rational\"\n";

fn scene(elements: usize, extra: &str, integrator: &str) -> String {
    common::scene_text::straight_rod("rational", elements, extra, integrator)
}

fn inertia() -> f64 {
    let a = std::f64::consts::PI * R * R;
    a * R * R / 4.0
}

/// The rational measure's `f(δ) = 3 sin δ / (2 + cos δ)`.
fn f(delta: f64) -> f64 {
    3.0 * delta.sin() / (2.0 + delta.cos())
}

fn rational(mut m: Model) -> Model {
    for r in &mut m.rods {
        r.curvature_measure = CurvatureMeasure::Rational;
    }
    m
}

/// Seeded xorshift in [-1, 1).
fn rng(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// Largest |K − FD| relative to the largest |K| entry, at a random increment.
fn tangent_error(m: Model, dt: f64, lanes: bool) -> f64 {
    let mut sim = Simulation::new(m, IntegratorParams::new(Scheme::Em, dt, 1.0)).unwrap();
    sim.set_lanes(lanes);
    assert_eq!(sim.lanes(), lanes);
    let n = sim.n_dofs();
    let mut seed = 0x9e3779b97f4a7c15u64;
    let q: Vec<f64> = (0..n).map(|_| 0.3 * rng(&mut seed)).collect();
    let k = sim.dense_tangent_at(&q, true);
    let kmax = k.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut worst: f64 = 0.0;
    for j in 0..n {
        let h = 1e-6;
        let mut qp = q.clone();
        qp[j] += h;
        let rp = sim.residual_at(&qp, true);
        qp[j] -= 2.0 * h;
        let rm = sim.residual_at(&qp, true);
        for i in 0..n {
            worst = worst.max((k[i][j] - (rp[i] - rm[i]) / (2.0 * h)).abs());
        }
    }
    worst / kmax
}

/// The frame of tests/tangent.rs and tests/conservation.rs with the rational measure:
/// free, then clamped and pinned with a point mass, then with Kelvin–Voigt damping
/// (β_Ω ≠ 0). Increments of 0.3 rad per node (turns far from the linear range).
/// Measured ≤ 3e-10; the bound is the sine kernel's `TANGENT_RTOL` (tests/tangent.rs).
#[test]
fn em_tangent_matches_finite_differences() {
    for case in 0..3 {
        let mut m = rational(common::frame());
        for (a, w) in m.omega0.iter_mut().enumerate() {
            *w = Vec3::new(0.1 * a as f64, -0.05, 0.02 * (a % 3) as f64);
        }
        if case >= 1 {
            m.supports[0] = Support {
                translation: true,
                rotation: true,
            };
            let last = m.n_nodes() - 1;
            m.supports[last] = Support {
                translation: true,
                rotation: false,
            };
            m.velocity0[0] = Vec3::zeros();
            m.point_mass[5] = 2.0;
        }
        if case == 2 {
            for e in &mut m.elements {
                e.props.damping = 0.02;
            }
        }
        // One element at a time, and four per kernel call (the sine kernel without C_Ω
        // in lanes, the rational moment rows added on the same lanes).
        for lanes in [false, true] {
            let e = tangent_error(m.clone(), 0.05, lanes);
            eprintln!("case {case}, lanes {lanes}: tangent vs central differences {e:.1e}");
            assert!(e < 3e-9, "case {case}, lanes {lanes}: {e:e}");
        }
    }
}

/// A violent free flight: the paper's frame (thrown by its corners at 1–2 m/s) with
/// random velocities (up to 0.3 m/s) and spins (up to 0.1 rad/s) added at each node. EM conserves H, L
/// and J to round-off step by step (bounds of tests/conservation.rs).
#[test]
fn em_conserves_energy_and_momenta_in_a_violent_run() {
    let mut m = rational(common::frame());
    let mut seed = 0x2545f4914f6cdd1du64;
    for a in 0..m.n_nodes() {
        let mut noise = || Vec3::new(rng(&mut seed), rng(&mut seed), rng(&mut seed));
        m.omega0[a] += noise() * 0.1;
        m.velocity0[a] += noise() * 0.3;
    }
    let mut sim = Simulation::new(m, IntegratorParams::new(Scheme::Em, 0.05, 8.0)).unwrap();
    let mut inv0 = sim.invariants();
    let mut worst = [0.0f64; 3];
    let mut widest: f64 = 0.0;
    for step in 0..160 {
        sim.step().unwrap_or_else(|e| panic!("step {step}: {e:?}"));
        let inv = sim.invariants();
        let dh = (inv.total() - inv0.total()).abs() / inv0.total();
        let dl = (inv.l - inv0.l).norm() / inv0.l.norm();
        let dj = (inv.j - inv0.j).norm() / inv0.j.norm();
        worst = [worst[0].max(dh), worst[1].max(dl), worst[2].max(dj)];
        assert!(dh <= 4e-12, "step {step}: dH {dh:e}");
        assert!(
            dl <= 5e-14 && dj <= 5e-14,
            "step {step}: dL {dl:e}, dJ {dj:e}"
        );
        inv0 = inv;
        let model = sim.model().clone();
        for e in 0..model.elements.len() {
            let c = sim.state().element(&model, e).cfg;
            let tr = (c.d[0].transpose() * c.d[1]).trace();
            widest = widest.max(((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos());
        }
    }
    eprintln!(
        "violent run: max dH {:.1e}, dL {:.1e}, dJ {:.1e}; widest element turn {widest:.2} rad",
        worst[0], worst[1], worst[2]
    );
    assert!(widest > 0.5, "the run must turn elements far ({widest})");
}

/// The rational measure's elements through the four-element lanes: every step the same,
/// bit for bit, as one element at a time (the violent frame run's first steps).
#[test]
fn lanes_step_bit_for_bit_as_one_element_at_a_time() {
    let mut m = rational(common::frame());
    let mut seed = 0x2545f4914f6cdd1du64;
    for a in 0..m.n_nodes() {
        let mut noise = || Vec3::new(rng(&mut seed), rng(&mut seed), rng(&mut seed));
        m.omega0[a] += noise() * 0.1;
        m.velocity0[a] += noise() * 0.3;
    }
    assert!(m.elements.len() >= 8, "two lane groups at least");
    let sims: Vec<Simulation> = [true, false]
        .into_iter()
        .map(|on| {
            let mut sim =
                Simulation::new(m.clone(), IntegratorParams::new(Scheme::Em, 0.05, 8.0)).unwrap();
            sim.set_lanes(on);
            assert_eq!(sim.lanes(), on);
            sim
        })
        .collect();
    let [mut on, mut off] = <[Simulation; 2]>::try_from(sims).ok().unwrap();
    let bits = |s: &Simulation| -> Vec<u64> {
        let st = s.state();
        st.r.iter()
            .chain(&st.v)
            .flat_map(|x| x.iter().copied())
            .chain(
                st.d.iter()
                    .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
            )
            .chain(st.eps.iter().flat_map(|x| x.iter().copied()))
            .map(f64::to_bits)
            .collect()
    };
    for step in 0..40 {
        let (a, b) = (on.step().unwrap(), off.step().unwrap());
        assert_eq!(a.newton_iters, b.newton_iters, "step {step}");
        assert!(bits(&on) == bits(&off), "step {step}: the states differ");
    }
}

/// A cantilever under a time-varying tip force and moment and gravity: EM's per-step
/// balance `H_{n+1} − H_n = W` to round-off (tests/external_work.rs's bound).
#[test]
fn em_balances_external_work_exactly() {
    let extra = format!(
        "{RATIONAL}\n[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, 0.01, -0.006]\nmoment = [0.004, 0, 0.008]\ntime = [0, 0.2, 0.4]\nfactor = [0, 1, 0]"
    );
    let text = format!(
        "gravity = [0, 0, -0.5]\n{}",
        scene(8, &extra, "scheme = \"em\"\ndt = 0.01\nt_end = 0.6")
    );
    let s = parse_scene(&text, "t.toml").unwrap();
    assert_eq!(
        s.model.rods[0].curvature_measure,
        CurvatureMeasure::Rational
    );
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let mut h0 = sim.invariants().total();
    let (mut worst, mut total_w) = (0.0f64, 0.0);
    for _ in 0..s.params.n_steps() {
        let rep = sim.step().unwrap();
        let h1 = sim.invariants().total();
        let scale = h1.abs().max(h0.abs()).max(rep.external_work.abs());
        worst = worst.max((h1 - h0 - rep.external_work).abs() / scale);
        total_w += rep.external_work;
        h0 = h1;
    }
    eprintln!("rational cantilever: worst balance miss per step {worst:.1e}, W = {total_w:.3e}");
    assert!(worst <= 1e-12, "{worst:e}");
    assert!(total_w.abs() > 1e-4, "the loads must do work ({total_w:e})");
}

/// Frame indifference at the scene level: a rigid motion of the reference stores
/// nothing, and a bent start rotated rigidly stores what it stores unrotated.
#[test]
fn rigid_motions_store_nothing_and_move_no_energy() {
    let energy = |initial: &str| {
        let s = parse_scene(&scene(6, &format!("{RATIONAL}{initial}"), EM), "t.toml").unwrap();
        Simulation::new(s.model, s.params)
            .unwrap()
            .invariants()
            .potential
    };
    let v = energy("[rod.initial]\nrotation = [0.3, -0.5, 1.1]\ntranslation = [1, 2, 3]");
    assert!(v.abs() < 1e-20, "V = {v}");
    let bent = "[rod.initial]\nrotations = [[0, 0, 0], [0, 0.4, 0.1], [0, 0.9, 0.3], [0.2, 1.5, 0.2], [0.1, 2.0, 0], [0, 2.6, 0], [0, 3.0, 0.1]]";
    let (v0, v1) = (
        energy(bent),
        energy(&format!("{bent}\nrotation = [0.7, -0.2, 0.4]")),
    );
    assert!(v0 > 1e-4, "{v0}");
    assert!((v0 - v1).abs() < 1e-13 * v0, "{v0} vs {v1}");
}

/// Small turns: the two measures give the same motion up to the measure's `O(δ²)`
/// relative difference. A cantilever set ringing by a tip impulse of amplitude `a` and
/// `a/2`: the tip trajectories' relative difference quarters (ratio measured 4.00).
#[test]
fn small_strain_limit_follows_the_sine_measure() {
    let tip = |measure: &str, amp: f64| -> Vec<Vec3> {
        let extra = format!(
            "curvature_measure = \"{measure}\"\n[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, {}, {}]\nmoment = [{}, 0, 0]\ntime = [0, 0.05, 0.1]\nfactor = [0, 1, 0]",
            0.4 * amp,
            -0.3 * amp,
            0.02 * amp
        );
        let s = parse_scene(
            &scene(10, &extra, "scheme = \"em\"\ndt = 0.01\nt_end = 1"),
            "t.toml",
        )
        .unwrap();
        let mut sim = Simulation::new(s.model, s.params).unwrap();
        let last = sim.model().n_nodes() - 1;
        (0..s.params.n_steps())
            .map(|_| {
                sim.step().unwrap();
                sim.state().r[last] - Vec3::x()
            })
            .collect()
    };
    let rel = |amp: f64| {
        let (a, b) = (tip("sine", amp), tip("rational", amp));
        let diff = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max);
        let size = a.iter().map(|x| x.norm()).fold(0.0, f64::max);
        diff / size
    };
    let (r1, r2) = (rel(1.0), rel(0.5));
    eprintln!(
        "small strain: relative tip difference {r1:.2e} (a), {r2:.2e} (a/2), ratio {:.2}",
        r1 / r2
    );
    assert!(r1 < 1e-2, "{r1}");
    assert!((r1 / r2 - 4.0).abs() < 0.2, "ratio {}", r1 / r2);
}

/// A cantilever of 4 elements rolled up by a tip moment `M = (EI/h) f(δ*) f'(δ*)` with
/// δ* = 1.2 rad per element (4.8 rad in all), ramped in and held under material damping.
/// The sine measure carries at most `EI/(2h)` per element (0.46 M): its fold
/// concentrates and a step is refused. The rational measure settles with every element
/// turned δ* (its exact discrete equilibrium).
#[test]
fn a_fold_past_a_quarter_turn_per_element_holds() {
    let n = 4usize;
    let h = 1.0 / n as f64;
    let ei = E * inertia();
    let delta: f64 = 1.2;
    let fp = 3.0 * (2.0 * delta.cos() + 1.0) / (2.0 + delta.cos()).powi(2);
    let moment = ei / h * f(delta) * fp;
    assert!(
        0.5 * ei / h < 0.5 * moment,
        "past the sine element's capacity"
    );
    let run = |measure: &str| -> Result<Vec<f64>, String> {
        let extra = format!(
            "curvature_measure = \"{measure}\"\n[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nmoment = [0, {}, 0]\ntime = [0, 20, 60]\nfactor = [0, 1, 1]",
            -moment
        );
        let text = scene(n, &extra, "scheme = \"em\"\ndt = 0.05\nt_end = 60")
            .replace("density = 1000", "density = 1000\ndamping = 1.0");
        let s = parse_scene(&text, "t.toml").unwrap();
        assert_eq!(s.model.elements[0].props.damping, 1.0);
        let mut sim = Simulation::new(s.model, s.params).map_err(|e| e.to_string())?;
        for step in 0..s.params.n_steps() {
            sim.step().map_err(|e| format!("step {step}: {e:?}"))?;
        }
        let model = sim.model().clone();
        Ok((0..n)
            .map(|e| {
                let c = sim.state().element(&model, e).cfg;
                let tr = (c.d[0].transpose() * c.d[1]).trace();
                ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos()
            })
            .collect())
    };
    let turns = run("rational").unwrap();
    eprintln!("rolled up: element turns {turns:?} (δ* = {delta})");
    for t in &turns {
        assert!((t - delta).abs() < 1e-6, "{turns:?}");
    }
    let sine = run("sine");
    eprintln!("sine measure: {sine:?}");
    assert!(sine.is_err(), "{sine:?}");
}

/// A straight rod twisted uniformly by 15.64 rad stores `(f(δ)/δ)²` of `GJθ²/(2L)` to
/// round-off (the sine measure: `(sin δ/δ)²` = 0.968, 0.992, 0.998 at n = 50, 100, 200;
/// tests/scene_shapes.rs). The shortfall `1 − (f/δ)² ≈ δ⁴/90` falls 16× per halving.
#[test]
fn uniform_twist_stores_the_rational_share_of_the_continuum_energy() {
    let theta: f64 = 15.64;
    let gj = E / 3.0 * 2.0 * inertia();
    let continuum = 0.5 * gj * theta * theta;
    let mut factors = vec![];
    for n in [50usize, 100, 200] {
        let rotations: Vec<String> = (0..=n)
            .map(|j| format!("[{}, 0, 0]", theta * j as f64 / n as f64))
            .collect();
        let extra = format!(
            "{RATIONAL}[rod.initial]\nrotations = [{}]",
            rotations.join(", ")
        );
        let s = parse_scene(&scene(n, &extra, EM), "t.toml").unwrap();
        let v = Simulation::new(s.model, s.params)
            .unwrap()
            .invariants()
            .potential;
        let delta = theta / n as f64;
        let expect = (f(delta) / delta).powi(2);
        let measured = v / continuum;
        assert!(
            (measured - expect).abs() < 1e-12,
            "n = {n}: {measured} vs {expect}"
        );
        factors.push(measured);
    }
    eprintln!("uniform twist 15.64 rad: V/(GJθ²/2L) = {factors:?} at n = 50, 100, 200");
    let order = ((1.0 - factors[0]) / (1.0 - factors[1])).log2();
    assert!((order - 4.0).abs() < 0.02, "order {order}");
}

/// One element bent δ stores `½ EI f(δ)² / h` to round-off; its moment `EI f f'/h`
/// still rises at 1.2 rad and peaks at 1.42 rad (the sine element's at π/4).
#[test]
fn one_element_bent_by_delta_stores_half_ei_f_squared_over_h() {
    let ei = E * inertia();
    let energy = |delta: f64| {
        let c = 1.0 / (delta / 2.0).cos();
        let (x, z) = (c * (delta / 2.0).cos(), -c * (delta / 2.0).sin());
        let extra = format!(
            "{RATIONAL}[rod.initial]\npositions = [[0, 0, 0], [{x}, 0, {z}]]\nrotations = [[0, 0, 0], [0, {delta}, 0]]"
        );
        let s = parse_scene(&scene(1, &extra, EM), "t.toml").unwrap();
        Simulation::new(s.model, s.params)
            .unwrap()
            .invariants()
            .potential
    };
    for delta in [0.1, 0.5, 1.2, 2.0, 3.0] {
        let expect = 0.5 * ei * f(delta).powi(2);
        let v = energy(delta);
        assert!(
            (v - expect).abs() < 1e-12 * expect,
            "δ = {delta}: {v} vs {expect}"
        );
    }
    let moment = |d: f64| (energy(d + 1e-6) - energy(d - 1e-6)) / 2e-6;
    assert!(moment(0.785) < moment(1.2) && moment(1.2) < moment(1.42));
    assert!(moment(1.6) < moment(1.42));
}

/// The key's errors name the file, the key and the reason.
#[test]
fn bad_uses_of_the_key_are_named() {
    let err =
        |extra: &str, integrator: &str| match parse_scene(&scene(4, extra, integrator), "bad.toml")
        {
            Ok(_) => panic!("must be refused: {extra}"),
            Err(e) => e.to_string(),
        };
    let e = err("curvature_measure = \"exact\"\n", EM);
    assert!(
        e.contains("bad.toml") && e.contains("curvature_measure") && e.contains("`exact`"),
        "{e}"
    );
    let e = err(RATIONAL, "scheme = \"edmc1\"\ndt = 1e-3\nt_end = 1");
    assert!(
        e.contains("curvature_measure") && e.contains("scheme em only"),
        "{e}"
    );
    let e = err(
        &format!("{RATIONAL}[rod.initial]\nstretch = 1.0"),
        "scheme = \"gen-alpha\"\ndt = 1e-3\nt_end = 1",
    );
    assert!(
        e.contains("curvature_measure") && e.contains("em only"),
        "{e}"
    );
    // The GPU path names it too.
    let s = parse_scene(&scene(4, RATIONAL, EM), "t.toml").unwrap();
    assert!(s.model.gpu_unsupported().unwrap().contains("rational"));
}
