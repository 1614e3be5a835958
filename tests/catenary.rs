//! A cable whose stress-free shape is straight, released from a circular arc between two
//! pins under gravity, settles (Kelvin–Voigt damping and drag) onto the analytic
//! **elastic catenary** (Irvine: an extensible, perfectly flexible cable) at second order
//! in the element length. The cable keeps a bending stiffness whose boundary length
//! `ℓ = sqrt(EI/T)` the mesh resolves (`h < 2ℓ`, docs/scenes.md "Cables"); its own effect
//! on the sag, −3.9e-5 relative, was measured with an independent multiple-shooting solve
//! of the continuum rod (docs/scenes.md), far below the bounds here.

use cosserat::integrator::Simulation;
use cosserat::scene::parse_scene;

/// Span between the pins, cable length (reference), weight per length, axial stiffness.
const SPAN: f64 = 0.8;
const LEN: f64 = 1.0;
const RHO_A: f64 = 0.1;
const G: f64 = 9.81;
const EA: f64 = 5e3;
const EI: f64 = 9e-5;

/// The scene: a straight reference along e1, started as the circular arc of the same
/// length through both pins (sagging along −e3).
fn scene(n: usize) -> String {
    // Arc of length LEN on the chord SPAN: sin(φ)/φ = SPAN/LEN, radius LEN/(2φ).
    let (mut lo, mut hi) = (0.5f64, 1.5f64);
    for _ in 0..100 {
        let m = 0.5 * (lo + hi);
        if m.sin() / m > SPAN / LEN {
            lo = m;
        } else {
            hi = m;
        }
    }
    let phi = 0.5 * (lo + hi);
    let rho = LEN / (2.0 * phi);
    let pts: Vec<String> = (0..=n)
        .map(|i| {
            let (x, z) = if i == 0 {
                (0.0, 0.0)
            } else if i == n {
                (SPAN, 0.0)
            } else {
                let a = -phi + 2.0 * phi * i as f64 / n as f64;
                (
                    0.5 * SPAN + rho * a.sin(),
                    -(rho * a.cos() - rho * phi.cos()),
                )
            };
            format!("[{x:e}, 0, {z:e}]")
        })
        .collect();
    let (e, a) = (5e7, 1e-4);
    let i = EI / e;
    format!(
        r#"name = "catenary"
gravity = [0, 0, -{G}]
[material.cable]
E = {e}
nu = 0.3
density = {rho_dens}
damping = 0.002

[section.wire]
A = {a}
I11 = {i}
I22 = {i}
J = {j}

[[rod]]
name = "cable"
material = "cable"
section = "wire"
points = [[0, 0, 0], [{LEN}, 0, 0]]
elements = {n}
d1 = [0, 1, 0]
drag = 0.6

[rod.initial]
positions = [{pts}]

[[pin]]
at = [0, 0, 0]

[[pin]]
at = [{LEN}, 0, 0]

[integrator]
scheme = "em"
dt = 0.02
t_end = 20
"#,
        rho_dens = RHO_A / a,
        j = 2.0 * i,
        pts = pts.join(", ")
    )
}

/// The elastic catenary through (0, 0) and (SPAN, 0): position of the material point at
/// reference arc length `s` (Irvine, *Cable Structures*, eqs. 2.3–2.4; z measured up).
struct Catenary {
    h: f64,
    w: f64,
}

impl Catenary {
    fn solve() -> Self {
        let w = RHO_A * G;
        let v = 0.5 * w * LEN;
        let span = |h: f64| h * LEN / EA + 2.0 * (h / w) * (v / h).asinh();
        let (mut lo, mut hi) = (1e-3, 10.0);
        for _ in 0..200 {
            let m = 0.5 * (lo + hi);
            if span(m) < SPAN {
                lo = m;
            } else {
                hi = m;
            }
        }
        Self {
            h: 0.5 * (lo + hi),
            w,
        }
    }

    fn at(&self, s: f64) -> (f64, f64) {
        let (h, w) = (self.h, self.w);
        let v = 0.5 * w * LEN;
        let x = h * s / EA + (h / w) * ((v / h).asinh() - ((v - w * s) / h).asinh());
        let sag = (w * s / EA) * (v / w - 0.5 * s)
            + (h / w) * ((1.0 + (v / h).powi(2)).sqrt() - (1.0 + ((v - w * s) / h).powi(2)).sqrt());
        (x, -sag)
    }
}

/// Runs the scene with `n` elements to rest; returns (relative midspan sag error, largest
/// node distance from the catenary / sag, largest distance a node moves in the last
/// step / sag).
fn settle(n: usize) -> (f64, f64, f64) {
    let s = parse_scene(&scene(n), "catenary.toml").unwrap();
    let steps = s.params.n_steps();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    for k in 0..steps {
        sim.step()
            .unwrap_or_else(|f| panic!("{n} elements, step {k}: {f:?}"));
    }
    let cat = Catenary::solve();
    let sag = -cat.at(0.5 * LEN).1;
    let st = sim.state();
    let mid = st.r[n / 2];
    let mut worst = 0.0f64;
    for (i, r) in st.r.iter().enumerate() {
        let (x, z) = cat.at(LEN * i as f64 / n as f64);
        worst = worst.max(((r.x - x).powi(2) + r.y.powi(2) + (r.z - z).powi(2)).sqrt() / sag);
    }
    // What is left of the motion: the mid-point rule rings the stiffest modes by flipping
    // their velocity each step (≈ 1e-3 m/s next to a pin), a tiny displacement.
    let vmax = st.v.iter().fold(0.0f64, |m, v| m.max(v.norm()));
    (-mid.z / sag - 1.0, worst, vmax * 0.02 / sag)
}

#[test]
fn cable_released_from_an_arc_settles_to_the_elastic_catenary_at_second_order() {
    let (e50, d50, v50) = settle(50);
    let (e100, d100, v100) = settle(100);
    println!(
        "sag error 50: {e50:e}, 100: {e100:e}; shape 50: {d50:e}, 100: {d100:e}; motion {v50:e} {v100:e}"
    );
    // Measured: sag +6.51e-4 (50 elements), +1.33e-4 (100); node distance from the
    // catenary 7.0e-4 and 3.2e-4 of the sag; last-step motion 1.2e-4 and 2.2e-4 of it.
    assert!(e50.abs() < 1e-3, "sag at 50 elements off by {e50:e}");
    assert!(d50 < 1.5e-3, "shape at 50 elements off by {d50:e}");
    assert!(d100 < 6e-4, "shape at 100 elements off by {d100:e}");
    assert!(e100.abs() < 2.5e-4, "sag at 100 elements off by {e100:e}");
    let order = (e50 / e100).log2();
    assert!(order > 1.8, "sag error order {order}");
    assert!(v50 < 1e-3 && v100 < 1e-3, "not at rest: {v50:e} {v100:e}");
}
