//! A controller in the loop (`Simulation::set_load`, `add_load`, `set_support_motion`,
//! `Model::control_support`): a load set between steps gives bit for bit the trajectory of
//! a scene whose load table is that piecewise-constant function, and its work is in `W`
//! (EM closes `ΔH = W` to round-off); a commanded clamp sits exactly at its targets, a
//! velocity command equals the scene's linear drive to round-off, the support's work
//! closes the balance; a drivable clamp that is never commanded is the fixed clamp; bad
//! commands are refused with the load or node and the reason.

use cosserat::integrator::{RotationCommand, Simulation, TranslationCommand};
use cosserat::math::cay;
use cosserat::model::{Mat3, Vec3};
use cosserat::scene::{parse_scene, Scene};

mod common;

const DT: f64 = 0.01;
const STEPS: usize = 30;

fn scene(extra: &str, scheme: &str) -> Scene {
    let text = common::scene_text::straight_rod(
        "control",
        10,
        extra,
        &format!(
            "scheme = \"{scheme}\"\ndt = {DT:?}\nt_end = {:?}",
            DT * STEPS as f64
        ),
    );
    parse_scene(&text, "control.toml").unwrap()
}

/// The controller's load history: a tip force along −e3 of `f(k)` over step `k`.
fn f(k: usize) -> f64 {
    0.05 * (0.7 * k as f64).sin() + 0.02
}

/// Energy-balance tolerance of EM relative to the largest of |H| and |W| over the run:
/// round-off of the energies over 30 steps (measured up to 4e-14).
const BALANCE_RTOL: f64 = 1e-13;

#[test]
fn a_load_set_between_steps_equals_its_piecewise_table() {
    // The same load history as a table of jumps at every level t_k = k Δt.
    let (mut times, mut values) = (vec![], vec![]);
    for k in 0..STEPS {
        for t in [k as f64 * DT, (k + 1) as f64 * DT] {
            times.push(format!("{t:?}"));
            values.push(format!("{:?}", f(k)));
        }
    }
    let table = format!(
        "[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, 0, -1]\ntime = [{}]\nfactor = [{}]",
        times.join(", "),
        values.join(", ")
    );
    let steady = "[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, 0, -1]";
    for scheme in ["em", "edmc2"] {
        let a = scene(&table, scheme);
        let b = scene(steady, scheme);
        let mut by_table = Simulation::new(a.model, a.params).unwrap();
        let mut by_hand = Simulation::new(b.model, b.params).unwrap();
        let h0 = by_hand.invariants().total();
        let (mut w, mut worst_res, mut scale) = (0.0, 0.0f64, h0.abs());
        for k in 0..STEPS {
            by_hand
                .set_load(0, Some(Vec3::new(0.0, 0.0, -f(k))), None)
                .unwrap();
            let ra = by_table.step().unwrap();
            let rb = by_hand.step().unwrap();
            assert_eq!(ra.external_work, rb.external_work, "{scheme} step {k}");
            assert_eq!(by_table.state().r, by_hand.state().r, "{scheme} step {k}");
            assert_eq!(by_table.state().d, by_hand.state().d, "{scheme} step {k}");
            w += rb.external_work;
            if scheme == "em" {
                let res = by_hand.invariants().total() - h0 - w;
                worst_res = worst_res.max(res.abs());
                scale = scale.max(w.abs()).max(by_hand.invariants().total().abs());
            }
        }
        assert!(w.abs() > 1e-4, "the load did work ({w:e})");
        assert!(
            worst_res <= BALANCE_RTOL * scale,
            "{scheme}: ΔH − W up to {worst_res:e} of {scale:e}"
        );
    }
}

#[test]
fn an_added_load_is_a_scene_load() {
    let with = scene(
        "[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, 0.03, 0]\nmoment = [0.001, 0, 0]",
        "em",
    );
    let without = scene("[[clamp]]\nat = [0, 0, 0]", "em");
    let tip = without.model.n_nodes() - 1;
    assert_eq!(without.model.nodes[tip], Vec3::new(1.0, 0.0, 0.0));
    let mut a = Simulation::new(with.model, with.params).unwrap();
    let mut b = Simulation::new(without.model, without.params).unwrap();
    let i = b
        .add_load(tip, Vec3::new(0.0, 0.03, 0.0), Vec3::new(0.001, 0.0, 0.0))
        .unwrap();
    assert_eq!(i, 0);
    for _ in 0..10 {
        a.step().unwrap();
        b.step().unwrap();
    }
    assert_eq!(a.state().r, b.state().r);
}

/// The scene's moving clamp at the tip: carried by `d` and turned by `phi` about a fixed
/// axis, linearly over the run.
fn driven_tip(d: Vec3, phi: Vec3) -> String {
    format!(
        "[[clamp]]\nat = [0, 0, 0]\n\n[[clamp]]\nat = [1, 0, 0]\ndisplacement = [{:?}, {:?}, {:?}]\nrotation = [{:?}, {:?}, {:?}]\ntime = [0, {:?}]\nfactor = [0, 1]",
        d.x,
        d.y,
        d.z,
        phi.x,
        phi.y,
        phi.z,
        DT * STEPS as f64
    )
}

#[test]
fn a_velocity_command_equals_the_scenes_linear_drive() {
    let (d, phi) = (Vec3::new(-0.02, 0.05, 0.03), Vec3::new(0.4, 0.0, 0.2));
    let fixed_tip = "[[clamp]]\nat = [0, 0, 0]\n\n[[clamp]]\nat = [1, 0, 0]";
    for scheme in ["em", "edmc2"] {
        let a = scene(&driven_tip(d, phi), scheme);
        let mut b = scene(fixed_tip, scheme);
        let tip = b.model.n_nodes() - 1;
        b.model.control_support(tip).unwrap();
        let mut by_table = Simulation::new(a.model, a.params).unwrap();
        let mut by_hand = Simulation::new(b.model, b.params).unwrap();
        let t = DT * STEPS as f64;
        by_hand
            .set_support_motion(
                tip,
                Some(TranslationCommand::Velocity(d / t)),
                Some(RotationCommand::AngularVelocity(phi / t)),
            )
            .unwrap();
        let h0 = by_hand.invariants().total();
        let (mut w, mut worst_res, mut scale) = (0.0, 0.0f64, h0.abs());
        for _ in 0..STEPS {
            by_table.step().unwrap();
            let rep = by_hand.step().unwrap();
            w += rep.support_work;
            assert_eq!(rep.support_work, rep.external_work, "no loads");
            if scheme == "em" {
                let res = by_hand.invariants().total() - h0 - w;
                worst_res = worst_res.max(res.abs());
                scale = scale.max(w.abs()).max(by_hand.invariants().total().abs());
            }
        }
        assert!(w.abs() > 1e-5, "the clamp did work ({w:e})");
        assert!(
            worst_res <= BALANCE_RTOL * scale,
            "{scheme}: ΔH − W up to {worst_res:e} of {scale:e}"
        );
        let worst = by_table
            .state()
            .r
            .iter()
            .zip(&by_hand.state().r)
            .map(|(x, y)| (x - y).amax())
            .fold(0.0, f64::max);
        // Round-off of Δs·d against (d/T)·Δt, carried along the run (measured 2.8e-16 m).
        assert!(worst <= 1e-14, "{scheme}: positions differ by {worst:e}");
        let end = by_hand.state().r[tip] - Vec3::new(1.0, 0.0, 0.0);
        assert!((end - d).amax() <= 1e-14, "tip at {end:?}");
        let turned = by_hand.node_rotation(tip);
        assert!((turned - exp(&phi)).amax() <= 1e-13);
    }
}

/// `exp(φ̂)` through the Cayley map (`cay(2 tan(|φ|/2) φ/|φ|)`).
fn exp(phi: &Vec3) -> Mat3 {
    let a = phi.norm();
    cay(&(phi * (2.0 * (0.5 * a).tan() / a)))
}

#[test]
fn a_commanded_clamp_sits_at_its_targets() {
    let mut s = scene("[[clamp]]\nat = [0, 0, 0]\n\n[[pin]]\nat = [1, 0, 0]", "em");
    let tip = s.model.n_nodes() - 1;
    s.model.control_support(0).unwrap();
    s.model.control_support(tip).unwrap();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let h0 = sim.invariants().total();
    let (mut w, mut worst_res, mut scale) = (0.0, 0.0f64, h0.abs());
    for k in 1..=STEPS {
        let x = k as f64 / STEPS as f64;
        let p = Vec3::new(0.01 * x, 0.03 * (3.0 * x).sin(), -0.02 * x);
        let r = exp(&Vec3::new(0.0, 0.3 * x, 0.5 * x * x));
        sim.set_support_motion(
            0,
            Some(TranslationCommand::Position(p)),
            Some(RotationCommand::Rotation(r)),
        )
        .unwrap();
        sim.set_support_motion(
            tip,
            Some(TranslationCommand::Position(Vec3::new(1.0, 0.0, 0.01 * x))),
            None,
        )
        .unwrap();
        let rep = sim.step().unwrap();
        w += rep.external_work;
        assert!((sim.state().r[0] - p).amax() <= 1e-15, "step {k}");
        assert!((sim.node_rotation(0) - r).amax() <= 1e-14, "step {k}");
        assert_eq!(sim.state().r[tip].z, 0.01 * x);
        let res = sim.invariants().total() - h0 - w;
        worst_res = worst_res.max(res.abs());
        scale = scale.max(w.abs()).max(sim.invariants().total().abs());
    }
    assert!(
        worst_res <= BALANCE_RTOL * scale,
        "ΔH − W up to {worst_res:e} of {scale:e}"
    );
    // A reached target is held.
    let (r0, d0) = (sim.state().r[0], sim.node_rotation(0));
    sim.step().unwrap();
    assert_eq!(sim.state().r[0], r0);
    assert!((sim.node_rotation(0) - d0).amax() <= 1e-15);
}

#[test]
fn a_drivable_clamp_never_commanded_is_the_fixed_clamp() {
    let plain = scene(
        "[[clamp]]\nat = [0, 0, 0]\n\n[[load]]\nat = [1, 0, 0]\nforce = [0, 0.02, -0.03]",
        "em",
    );
    let mut drivable = plain.clone();
    drivable.model.control_support(0).unwrap();
    // Idempotent.
    drivable.model.control_support(0).unwrap();
    assert_eq!(drivable.model.drives.len(), 1);
    let mut a = Simulation::new(plain.model, plain.params).unwrap();
    let mut b = Simulation::new(drivable.model, drivable.params).unwrap();
    for _ in 0..10 {
        a.step().unwrap();
        b.step().unwrap();
    }
    assert_eq!(a.state().r, b.state().r);
    assert_eq!(a.state().d, b.state().d);
}

#[test]
fn bad_commands_are_refused_with_the_reason() {
    let mut s = scene("[[clamp]]\nat = [0, 0, 0]\n\n[[pin]]\nat = [1, 0, 0]", "em");
    let tip = s.model.n_nodes() - 1;
    let msg = s.model.control_support(3).unwrap_err().to_string();
    assert!(msg.starts_with("node 3: not a support"), "{msg}");
    s.model.control_support(tip).unwrap();
    let mut sim = Simulation::new(s.model, s.params).unwrap();
    let cases = [
        (
            sim.set_load(0, None, None).unwrap_err(),
            "load 0: no such load (the model has 0)",
        ),
        (
            sim.set_support_motion(0, Some(TranslationCommand::Velocity(Vec3::x())), None)
                .unwrap_err(),
            "support at node 0: not a driven support",
        ),
        (
            sim.set_support_motion(tip, None, Some(RotationCommand::AngularVelocity(Vec3::x())))
                .unwrap_err(),
            "support at node 10: a pin leaves the rotation free",
        ),
        (
            sim.add_load(tip, Vec3::new(f64::NAN, 0.0, 0.0), Vec3::zeros())
                .unwrap_err(),
            "node 10: force: not finite",
        ),
    ];
    for (err, start) in cases {
        assert!(
            err.to_string().starts_with(start),
            "{err} (expected {start}…)"
        );
    }
    let mut c = scene("[[clamp]]\nat = [0, 0, 0]", "em");
    c.model.control_support(0).unwrap();
    let mut sim = Simulation::new(c.model, c.params).unwrap();
    let half = exp(&Vec3::new(0.0, 0.0, 3.13));
    let err = sim
        .set_support_motion(0, None, Some(RotationCommand::Rotation(half)))
        .unwrap_err();
    assert!(err.reason.contains("half a turn"), "{err}");
    let skew = Mat3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    let err = sim
        .set_support_motion(0, None, Some(RotationCommand::Rotation(skew)))
        .unwrap_err();
    assert!(err.reason.contains("not a rotation matrix"), "{err}");
}
