//! Reference against initial configuration (`[rod.initial]`, `curvature`) and initial
//! fields (`[[initial_velocity]]` on a rod or segment, per-node tables): the stored energy
//! is measured from the stress-free reference, not from the starting shape; a rigid
//! motion of the reference stores nothing; a pre-stretched rod released from rest rings
//! axially at the analytic period `4L/c`; rigid initial spins give the rigid-body L, J.

use cosserat::integrator::Simulation;
use cosserat::model::Vec3;
use cosserat::scene::parse_scene;

mod common;

const E: f64 = 1e6;
const RHO: f64 = 1000.0;
const R: f64 = 0.02;

/// A 1 m rod along e1 of a round section (radius `R`), with `extra` appended.
fn scene(elements: usize, extra: &str, integrator: &str) -> String {
    common::scene_text::straight_rod("shape", elements, extra, integrator)
}

const EM: &str = "scheme = \"em\"\ndt = 1e-3\nt_end = 1";

fn area() -> f64 {
    std::f64::consts::PI * R * R
}

fn inertia() -> f64 {
    area() * R * R / 4.0
}

#[test]
fn stretch_stores_exactly_the_axial_energy_of_the_reference() {
    let s = parse_scene(&scene(10, "[rod.initial]\nstretch = 1.001", EM), "t.toml").unwrap();
    let sim = Simulation::new(s.model, s.params).unwrap();
    let inv = sim.invariants();
    let expect = 0.5 * E * area() * 1e-6 * 1.0;
    assert!(
        (inv.potential - expect).abs() < 1e-12 * expect,
        "V = {} vs {expect}",
        inv.potential
    );
    assert_eq!(inv.kinetic, 0.0);
    // The state starts stretched; the reference is not moved.
    let tip = sim.state().r[sim.model().n_nodes() - 1];
    assert!((tip.x - 1.001).abs() < 1e-14, "tip {tip}");
    assert_eq!(sim.model().nodes[sim.model().n_nodes() - 1], Vec3::x());
}

#[test]
fn rigid_motion_of_the_reference_stores_nothing() {
    let extra =
        "[rod.initial]\nrotation = [0.3, -0.5, 1.1]\ncenter = [0.2, 0, 0]\ntranslation = [1, 2, 3]";
    let s = parse_scene(&scene(8, extra, EM), "t.toml").unwrap();
    let sim = Simulation::new(s.model, s.params).unwrap();
    let v = sim.invariants().potential;
    assert!(v.abs() < 1e-20, "V = {v}");
    let r = sim.state().r.clone();
    assert!(((r[8] - r[0]).norm() - 1.0).abs() < 1e-14);
}

/// Positions on an arc of radius `rho` (angle `phi`), one per node of `n` elements.
fn arc(n: usize, rho: f64) -> String {
    let phi = 1.0 / rho;
    let pts: Vec<String> = (0..=n)
        .map(|j| {
            let a = phi * j as f64 / n as f64;
            format!("[{}, {}, 0]", rho * a.sin(), rho * (1.0 - a.cos()))
        })
        .collect();
    format!("[{}]", pts.join(", "))
}

#[test]
fn straight_reference_started_as_an_arc_stores_bending_energy() {
    let (n, rho) = (40, 2.0);
    let extra = format!("[rod.initial]\npositions = {}", arc(n, rho));
    let s = parse_scene(&scene(n, &extra, EM), "t.toml").unwrap();
    let sim = Simulation::new(s.model.clone(), s.params).unwrap();
    // Bending about d2 (d1 = e3 is the arc's normal: bending in the e1-e2 plane is about
    // e3 = d1, stiffness E I11).
    let expect = 0.5 * E * inertia() / (rho * rho) * 1.0;
    let v = sim.invariants().potential;
    assert!((v - expect).abs() < 2.5e-4 * expect, "V = {v} vs {expect}");

    // The same arc with intrinsic curvature 1/rho about d1 is (nearly) stress-free.
    let extra = format!("curvature = [{}, 0, 0]\n{extra}", 1.0 / rho);
    let s2 = parse_scene(&scene(n, &extra, EM), "t.toml").unwrap();
    let sim2 = Simulation::new(s2.model, s2.params).unwrap();
    let v2 = sim2.invariants().potential;
    assert!(
        v2 < 1e-4 * expect,
        "pre-curved arc stores {v2} (straight: {v})"
    );
}

#[test]
fn pre_stretched_rod_rings_at_the_analytic_axial_period() {
    // Clamped at x = 0, stretched by 1e-3 and released: the tip moves on a triangle wave
    // of period 4 L / c, c = sqrt(E / rho).
    let n = 50;
    let c = (E / RHO).sqrt();
    let period = 4.0 / c;
    let dt = period / 400.0;
    let integ = format!("scheme = \"em\"\ndt = {dt}\nt_end = {}", 2.6 * period);
    let extra = "[rod.initial]\nstretch = 1.001\n\n[[clamp]]\nat = [0, 0, 0]";
    let s = parse_scene(&scene(n, extra, &integ), "t.toml").unwrap();
    let steps = s.params.n_steps();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let h0 = sim.invariants().total();
    let tip = n;
    let mut prev = (0.0, sim.state().r[tip].x - 1.0);
    let mut crossings = Vec::new();
    for _ in 0..steps {
        sim.step().unwrap();
        let t = sim.state().t;
        let u = sim.state().r[tip].x - 1.0;
        if prev.1 * u < 0.0 {
            crossings.push(prev.0 + (t - prev.0) * prev.1 / (prev.1 - u));
        }
        prev = (t, u);
    }
    let h1 = sim.invariants().total();
    assert!((h1 - h0).abs() < 1e-9 * h0, "EM energy drift {}", h1 - h0);
    assert!(crossings.len() >= 5, "crossings {crossings:?}");
    // Zero crossings at T/4, 3T/4, 5T/4, …
    for (k, t) in crossings.iter().enumerate() {
        let expect = (2 * k + 1) as f64 * period / 4.0;
        assert!(
            (t - expect).abs() < 1e-3 * period,
            "crossing {k} at {t}, analytic {expect} (period {period})"
        );
    }
    let measured = (crossings[4] - crossings[0]) / 2.0;
    let rel = (measured - period) / period;
    assert!(rel.abs() < 5e-5, "period {measured} vs {period} ({rel:e})");
}

#[test]
fn rod_spin_about_an_axis_gives_rigid_body_momenta() {
    // Whole rod spinning about e3 through its middle, started rotated: L = 0 and
    // J = I_zz ω about the centre (rotary inertia of the section included).
    let extra = "[rod.initial]\ntranslation = [0, 0, 2]\n\n[[initial_velocity]]\nrod = \"rod\"\ncenter = [0.5, 0, 2]\nomega = [0, 0, 3]";
    let s = parse_scene(&scene(20, extra, EM), "t.toml").unwrap();
    let sim = Simulation::new(s.model, s.params).unwrap();
    let inv = sim.invariants();
    let m = RHO * area();
    // Centerline (consistent mass, exact for linear fields): m L^3/12; section: rho I.
    let jz = 3.0 * (m / 12.0 + RHO * inertia());
    assert!(inv.l.norm() < 1e-14, "L = {}", inv.l);
    // J about the origin = J about the centre + c × L; L = 0.
    assert!(
        (inv.j - Vec3::new(0.0, 0.0, jz)).norm() < 1e-12 * jz,
        "J = {} vs {jz}",
        inv.j
    );
    let k = 0.5 * 3.0 * jz;
    assert!(
        (inv.kinetic - k).abs() < 1e-12 * k,
        "K = {} vs {k}",
        inv.kinetic
    );
}

#[test]
fn per_node_velocity_table_on_a_segment() {
    // Two segments; a table on segment 1 only (its 3 nodes), a uniform v on the whole rod.
    let text = scene(4, "", EM)
        .replace("points = [[0, 0, 0], [1, 0, 0]]", "points = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]")
        .replace("elements = 4", "elements = 2")
        + "\n[[initial_velocity]]\nrod = \"rod\"\nsegment = 1\nv_nodes = [[0, 0, 0], [0, 1, 0], [0, 0, 0]]\n\n[[initial_velocity]]\nrod = \"rod\"\nv = [1, 0, 0]\n";
    let s = parse_scene(&text, "t.toml").unwrap();
    let m = &s.model;
    assert_eq!(m.n_nodes(), 5);
    assert_eq!(m.velocity0[3], Vec3::new(1.0, 1.0, 0.0));
    assert_eq!(m.velocity0[1], Vec3::new(1.0, 0.0, 0.0));
    assert_eq!(m.velocity0[4], Vec3::new(1.0, 0.0, 0.0));
}

#[test]
fn bad_initial_shapes_are_named() {
    let cases = [
        (
            "[rod.initial]\npositions = [[0, 0, 0], [1, 0, 0]]",
            "rod[0].initial.positions: expected one vector per node of rod `rod`: 5 (got 2)",
        ),
        (
            "[rod.initial]\nstretch = -1",
            "rod[0].initial.stretch: must be > 0 (got -1)",
        ),
        (
            "[rod.initial]\npositions = [[0,0,0],[1,0,0],[2,0,0],[3,0,0],[4,0,0]]\nstretch = 2",
            "rod[0].initial.stretch: not with `positions`",
        ),
        (
            "[rod.initial]\ncenter = [0, 0, 0]",
            "rod[0].initial.center: only with `rotation`",
        ),
        (
            "[rod.initial]\ndisplacement = [[0,0,0],[-0.25,0,0],[0,0,0],[0,0,0],[0,0,0]]",
            "rod[0].initial.displacement: element 0 of rod `rod` has zero length",
        ),
        (
            "[rod.initial]\npositions = [[0,0,0],[1,0,0],[0.5,0,0],[1,0,0],[2,0,0]]",
            "turns back on itself at node 1 of rod `rod`",
        ),
        (
            "[[initial_velocity]]\nrod = \"nope\"\nv = [1, 0, 0]",
            "initial_velocity[0].rod: no rod named `nope` (rods: rod)",
        ),
        (
            "[[initial_velocity]]\nrod = \"rod\"\nsegment = 1",
            "initial_velocity[0].segment: rod `rod` has segments 0..0 (got 1)",
        ),
        (
            "[[initial_velocity]]\nrod = \"rod\"\nv_nodes = [[0, 0, 0]]",
            "initial_velocity[0].v_nodes: expected one vector per node of rod `rod`: 5 (got 1)",
        ),
        (
            "[[initial_velocity]]\nat = [0, 0, 0]\nv_nodes = [[0, 0, 0]]",
            "initial_velocity[0].v_nodes: only with `rod`",
        ),
        (
            "[[initial_velocity]]\nall = true\nrod = \"rod\"",
            "initial_velocity[0].rod: give one of `at`, `all = true` and `rod`, not `all` and `rod`",
        ),
        (
            "[[clamp]]\nat = [0, 0, 0]\n\n[[initial_velocity]]\nrod = \"rod\"\nv = [0, 1, 0]",
            "initial_velocity[0].rod: node 0 at (0, 0, 0) has its translation fixed",
        ),
    ];
    for (extra, want) in cases {
        let err = parse_scene(&scene(4, extra, EM), "bad.toml")
            .expect_err(extra)
            .to_string();
        assert!(err.starts_with("bad.toml:"), "{err}");
        assert!(err.contains(want), "{extra}\n got: {err}\nwant: {want}");
    }
}

#[test]
fn rods_sharing_a_node_must_agree_on_its_initial_state() {
    let text = scene(2, "[rod.initial]\ntranslation = [0, 0, 1]", EM)
        + "\n[[rod]]\nname = \"b\"\nmaterial = \"m\"\nsection = \"s\"\npoints = [[1, 0, 0], [1, 1, 0]]\nelements = 2\n";
    let err = parse_scene(&text, "bad.toml").unwrap_err().to_string();
    assert!(
        err.contains("rod[0].initial: moves node 2") && err.contains("rod[1] `b`"),
        "{err}"
    );
}

/// A straight rod twisted by `theta` about its axis, uniformly (each node turned by its
/// share `theta·s/L`), stores `(sin δ / δ)²` of the continuum `GJθ²/(2L)`, `δ = θ/n` the
/// twist per element: the two-node element's twist strain is `sin δ / h` (docs/theory.md
/// §2, "Torsion at coarse meshes"). Measured to round-off at n = 50, 100, 200 (the twist
/// experiment's 15.64 rad: 0.968, 0.992, 0.998), and the factor is below 1, so coarse
/// meshes are soft in torsion.
#[test]
fn uniform_twist_stores_the_sin_delta_over_delta_squared_share_of_the_continuum_energy() {
    let theta: f64 = 15.64;
    let g = E / 3.0; // nu = 0.5
    let gj = g * 2.0 * inertia();
    let continuum = 0.5 * gj * theta * theta / 1.0;
    let mut factors = vec![];
    for n in [50usize, 100, 200] {
        let rotations: Vec<String> = (0..=n)
            .map(|j| format!("[{}, 0, 0]", theta * j as f64 / n as f64))
            .collect();
        let extra = format!("[rod.initial]\nrotations = [{}]", rotations.join(", "));
        let s = parse_scene(&scene(n, &extra, EM), "t.toml").unwrap();
        let sim = Simulation::new(s.model, s.params).unwrap();
        let v = sim.invariants().potential;
        let delta = theta / n as f64;
        let expect = (delta.sin() / delta).powi(2);
        let measured = v / continuum;
        assert!(
            (measured - expect).abs() < 1e-12,
            "n = {n}: V/(GJθ²/2L) = {measured}, (sin δ/δ)² = {expect}"
        );
        factors.push(measured);
    }
    // Soft at coarse meshes, converging at second order: 1 − f ≈ δ²/3 − 2δ⁴/45 nearly
    // quarters as n doubles (log₂ ratio 1.986 from n = 50 to 100).
    assert!(factors[0] < factors[1] && factors[1] < factors[2] && factors[2] < 1.0);
    let order = ((1.0 - factors[0]) / (1.0 - factors[1])).log2();
    assert!((order - 1.986).abs() < 2e-3, "order {order}");
}

/// One element bent by `δ` (its second end triad turned about e2, the chord along the
/// bisector and lengthened by 1/cos(δ/2) so that the shrunk mean director `d₃ʰ` sees no
/// stretch and no shear) stores `½ EI sin²δ / h`: the element's curvature is `sin δ / h`
/// (docs/theory.md §2, "Folds past π/4 per element"). Its moment `dV/dδ = EI sin 2δ / 2h`
/// therefore peaks at δ = π/4 and falls beyond: a fold that needs more than π/4 per
/// element concentrates in one element. Measured to round-off from 0.1 to 2 rad.
#[test]
fn one_element_bent_by_delta_stores_half_ei_sin_squared_delta_over_h() {
    let ei = E * inertia();
    let energy = |delta: f64| {
        let c = 1.0 / (delta / 2.0).cos();
        let (x, z) = (c * (delta / 2.0).cos(), -c * (delta / 2.0).sin());
        let extra = format!(
            "[rod.initial]\npositions = [[0, 0, 0], [{x}, 0, {z}]]\nrotations = [[0, 0, 0], [0, {delta}, 0]]"
        );
        let s = parse_scene(&scene(1, &extra, EM), "t.toml").unwrap();
        Simulation::new(s.model, s.params)
            .unwrap()
            .invariants()
            .potential
    };
    for delta in [0.1, 0.5, std::f64::consts::FRAC_PI_4, 1.2, 2.0] {
        let expect = 0.5 * ei * delta.sin().powi(2);
        let v = energy(delta);
        assert!(
            (v - expect).abs() < 1e-12 * expect,
            "δ = {delta}: V = {v}, ½EI sin²δ/h = {expect}"
        );
    }
    // The moment (central difference of V) rises to π/4 and falls beyond it.
    let moment = |d: f64| (energy(d + 1e-6) - energy(d - 1e-6)) / 2e-6;
    let peak = moment(std::f64::consts::FRAC_PI_4);
    assert!((peak - 0.5 * ei).abs() < 1e-6 * ei, "{peak}");
    assert!(moment(0.6) < peak && moment(1.0) < peak && moment(1.5) < moment(1.0));
}
