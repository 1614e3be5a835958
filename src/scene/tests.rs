use super::*;
use crate::integrator::NewtonVariant;
use crate::model::Mat3;
use nalgebra::Matrix2;

fn frame() -> Scene {
    load_scene("frame").expect("built-in frame loads")
}

/// Consistent-mass kinetic energy, linear and angular momentum from nodal velocities
/// (two-point rule; directors start at rest).
fn momenta(m: &Model) -> (f64, Vec3, Vec3) {
    let (mut h, mut l, mut j) = (0.0, Vec3::zeros(), Vec3::zeros());
    for e in &m.elements {
        let [a, b] = e.nodes;
        let (va, vb) = (m.velocity0[a], m.velocity0[b]);
        let (ra, rb) = (m.nodes[a], m.nodes[b]);
        let c = e.props.a_rho * e.props.h / 6.0;
        h += 0.5 * c * (2.0 * va.norm_squared() + 2.0 * vb.norm_squared() + 2.0 * va.dot(&vb));
        l += e.props.a_rho * e.props.h / 2.0 * (va + vb);
        j += c * ((2.0 * ra + rb).cross(&va) + (ra + 2.0 * rb).cross(&vb));
    }
    (h, l, j)
}

#[test]
fn frame_initial_invariants_match_reference() {
    let s = frame();
    let (h, l, j) = momenta(&s.model);
    assert!((h - 9.16667).abs() < 1e-5, "H0 = {h}");
    assert!((h - 55.0 / 6.0).abs() < 1e-12, "H0 = {h}");
    assert!((l - Vec3::new(0.0, -5.0, 7.5)).norm() < 1e-12, "L0 = {l}");
    assert!(
        (j - Vec3::new(5.0, -95.0, -50.0)).norm() < 1e-10,
        "J0 = {j}"
    );
    assert!(s.model.omega0.iter().all(|w| *w == Vec3::zeros()));
}

#[test]
fn frame_mesh_is_the_staircase() {
    let s = frame();
    let m = &s.model;
    assert_eq!(s.name, "frame");
    assert_eq!(s.source, "builtin:frame");
    assert_eq!(m.n_nodes(), 16);
    assert_eq!(m.elements.len(), 15);
    assert_eq!(m.rods.len(), 3);
    assert_eq!(m.rods[1].name, "rod2");
    assert_eq!(m.rods[1].elements, 5..10);
    assert!(m.is_free_flight());
    // Rigid corners: rod2 starts at rod1's last node, rod3 at rod2's last node.
    assert_eq!(m.elements[4].nodes[1], m.elements[5].nodes[0]);
    assert_eq!(m.elements[9].nodes[1], m.elements[10].nodes[0]);
    assert_eq!(
        m.nodes[m.elements[14].nodes[1]],
        Vec3::new(10.0, 10.0, 10.0)
    );
    // Consecutive elements chain along each rod.
    for w in m.elements.windows(2) {
        assert_eq!(w[0].nodes[1], w[1].nodes[0]);
    }
    let g = 5e5 / 2.6;
    for e in &m.elements {
        assert!((e.props.h - 2.0).abs() < 1e-12);
        assert!((e.props.a_rho - 2.5).abs() < 1e-12);
        assert!((e.props.i_rho - Matrix2::identity() * 0.01).norm() < 1e-15);
        assert!((e.props.c_gamma - Vec3::new(g * 0.005, g * 0.005, 2500.0)).norm() < 1e-9);
        let co = Mat3::from_diagonal(&Vec3::new(10.0, 10.0, g * 4e-5));
        assert!((e.props.c_omega - co).norm() < 1e-9);
        let t = e.ref_triad[0];
        assert_eq!(t, e.ref_triad[1]);
        // Orthonormal, right-handed, d3 along the element.
        assert!((t.transpose() * t - Mat3::identity()).norm() < 1e-14);
        assert!((t.determinant() - 1.0).abs() < 1e-14);
        let d3 = (m.nodes[e.nodes[1]] - m.nodes[e.nodes[0]]) / e.props.h;
        assert!((t.column(2) - d3).norm() < 1e-14);
    }
    // rod1: d1 = e2, d2 = e3; rod2: d1 = e3, d2 = e1; rod3: d1 = e1, d2 = e2.
    assert_eq!(
        m.elements[0].ref_triad[0],
        Mat3::new(0., 0., 1., 1., 0., 0., 0., 1., 0.)
    );
    assert_eq!(
        m.elements[5].ref_triad[0],
        Mat3::new(0., 1., 0., 0., 0., 1., 1., 0., 0.)
    );
    assert_eq!(m.elements[10].ref_triad[0], Mat3::identity());
    match s.params.scheme {
        Scheme::Edmc2 {
            alpha_gv,
            alpha_gn,
            alpha_ov,
            alpha_on,
        } => {
            assert_eq!(
                (alpha_gv, alpha_gn, alpha_ov, alpha_on),
                (0.5, 0.0, 0.0, 0.0)
            );
        }
        other => panic!("frame scheme {other:?}"),
    }
    assert_eq!(s.params.dt, 0.2);
    assert_eq!(s.params.t_end, 10.0);
    assert_eq!(s.params.n_steps(), 50);
    assert_eq!(s.params.strategy, Strategy::Auto);
    assert_eq!(s.params.strategy.resolve(false), Strategy::Monolithic);
    assert_eq!(s.params.strategy.resolve(true), Strategy::Staggered);
    assert!(s.params.fallback, "the fallback is on by default");
    assert_eq!(s.output_every, 1);
}

#[test]
fn every_builtin_parses_and_describes() {
    for b in builtin_scenes() {
        let s = load_scene(b.name).unwrap_or_else(|e| panic!("{}: {e}", b.name));
        let d = s.describe();
        assert!(d.contains("nodes: "), "{d}");
        assert!(d.contains("DOFs: "), "{d}");
    }
    let d = frame().describe();
    assert!(d.contains("DOFs: 96"), "{d}");
    assert!(d.contains("rod1: 5 elements, 6 nodes, length 10"), "{d}");
    assert!(
        d.contains("initial velocities: 3 of 16 nodes moving"),
        "{d}"
    );
}

const BASE: &str = r#"
[material.m]
E = 100.0
G = 40.0
density = 2.0
[section.s]
A = 0.5
I11 = 0.1
I22 = 0.2
I12 = 0.05
J = 0.3
"#;

const INTEGRATOR: &str = "[integrator]\nscheme = \"em\"\ndt = 0.1\nt_end = 1.0\n";

fn scene(body: &str) -> Result<Scene, SceneError> {
    parse_scene(&format!("{BASE}{body}\n{INTEGRATOR}"), "test.toml")
}

#[test]
fn polyline_vertices_and_touching_rods_merge() {
    let s = scene(
        r#"
[[rod]]
material = "m"
section = "s"
points = [[0,0,0],[1,0,0],[1,1,0]]
elements = [2, 3]
[[rod]]
material = "m"
section = "s"
points = [[1,1,0],[1,1,1]]
elements = 1
[[rod]]
material = "m"
section = "s"
points = [[0.5,0,0],[0.5,0,-1]]
elements = 1
[[clamp]]
at = [0,0,0]
[[pin]]
at = [1,1,1]
[[point_mass]]
at = [1,1,1]
mass = 1.5
[[point_mass]]
at = [1,1,1]
mass = 0.5
[[load]]
at = [1,0,0]
moment = [0,0,1]
"#,
    )
    .unwrap();
    let m = &s.model;
    // rod0: 2 + 3 elements, 6 nodes; rod1 adds 1 node; rod2 starts at rod0's midpoint
    // node of segment 0 (a T-junction) and adds 1 node.
    assert_eq!(m.elements.len(), 7);
    assert_eq!(m.n_nodes(), 8);
    assert_eq!(m.rods[0].name, "rod0");
    assert_eq!(m.rods[2].name, "rod2");
    assert_eq!(m.elements[6].nodes[0], 1);
    assert_eq!(m.elements[5].nodes[0], m.elements[4].nodes[1]);
    assert!(m.supports[0].translation && m.supports[0].rotation);
    let tip = m.elements[5].nodes[1];
    assert!(m.supports[tip].translation && !m.supports[tip].rotation);
    assert_eq!(m.point_mass[tip], 2.0);
    assert_eq!(m.loads.len(), 1);
    assert_eq!(m.loads[0].node, 2);
    assert_eq!(m.loads[0].force, Vec3::zeros());
    assert_eq!(m.loads[0].table, crate::model::TimeTable::constant_one());
    // Default d1: e3 for rods in the xy plane, e1 for the rod along e3.
    assert_eq!(m.elements[0].ref_triad[0].column(0), Vec3::z());
    assert_eq!(m.elements[5].ref_triad[0].column(0), Vec3::x());
    // Default rho_inertia [[I22, -I12], [-I12, I11]] times density, shear areas = A, G given.
    let p = &m.elements[0].props;
    assert_eq!(p.i_rho, Matrix2::new(0.4, -0.1, -0.1, 0.2));
    assert_eq!(p.c_gamma, Vec3::new(20.0, 20.0, 50.0));
    assert_eq!(p.c_omega[(0, 1)], 5.0);
    assert_eq!(p.c_omega[(2, 2)], 12.0);
    assert!((p.h - 0.5).abs() < 1e-15);
    assert!((m.elements[2].props.h - 1.0 / 3.0).abs() < 1e-15);
    assert_eq!(s.name, "test");
    assert!(!m.is_free_flight());
}

#[test]
fn d1_is_projected_orthogonal_to_the_tangent() {
    let s = scene(
        r#"
[[rod]]
material = "m"
section = "s"
points = [[0,0,0],[3,4,0]]
elements = 1
d1 = [1, 0, 0]
"#,
    )
    .unwrap();
    let t = s.model.elements[0].ref_triad[0];
    let d3 = Vec3::new(0.6, 0.8, 0.0);
    assert!((t.column(2) - d3).norm() < 1e-15);
    assert!((t.column(0) - Vec3::new(0.8, -0.6, 0.0)).norm() < 1e-15);
    assert!((t.column(1) - Vec3::new(0.0, 0.0, -1.0)).norm() < 1e-15);
}

#[test]
fn rigid_initial_motion_and_integrator_options() {
    let s = parse_scene(
        &format!(
            r#"gravity = [0, 0, -9.81]
{BASE}
[section.t]
A = 1.0
I11 = 1.0
I22 = 1.0
J = 1.0
shear_factor = 0.5
rho_inertia = [[3.0, 0.0], [0.0, 4.0]]
[[rod]]
name = "a"
material = "m"
section = "t"
points = [[0,0,0],[2,0,0]]
elements = 2
[[initial_velocity]]
all = true
center = [1, 0, 0]
v = [0, 0, 1]
omega = [0, 0, 2]
[[initial_velocity]]
at = [2, 0, 0]
v = [1, 0, 0]
[[load]]
at = [2, 0, 0]
force = [0, 0, -1]
time = [0, 1, 1]
factor = [0, 2, 0]
[integrator]
scheme = "edmc1"
chi_gamma = 0.1
chi_v = 0.2
strategy = "staggered"
fallback = false
dt = 0.01
t_end = 2
max_iter = 7
newton_tol = 1e-9
outer_tol = 1e-8
max_outer = 4
energy_tol = 1e-6
output_every = 5
"#
        ),
        "dir/opts.toml",
    )
    .unwrap();
    let m = &s.model;
    assert_eq!(m.gravity, Vec3::new(0.0, 0.0, -9.81));
    assert_eq!(m.velocity0[0], Vec3::new(0.0, -2.0, 1.0));
    assert_eq!(m.velocity0[1], Vec3::new(0.0, 0.0, 1.0));
    assert_eq!(m.velocity0[2], Vec3::new(1.0, 2.0, 1.0));
    assert!(m.omega0.iter().all(|w| *w == Vec3::new(0.0, 0.0, 2.0)));
    let p = &m.elements[0].props;
    assert_eq!(p.c_gamma, Vec3::new(20.0, 20.0, 100.0));
    assert_eq!(p.i_rho, Matrix2::new(6.0, 0.0, 0.0, 8.0));
    assert_eq!(m.loads[0].table.times, vec![0.0, 1.0, 1.0]);
    assert_eq!(
        s.params.scheme,
        Scheme::Edmc1 {
            chi_gamma: 0.1,
            chi_omega: 0.0,
            chi_v: 0.2,
            chi_nu: 0.0
        }
    );
    assert_eq!(s.params.strategy, Strategy::Staggered);
    assert!(!s.params.fallback);
    assert_eq!(s.params.max_iter, 7);
    assert_eq!(s.params.max_outer, 4);
    assert_eq!(s.params.newton_tol, 1e-9);
    assert_eq!(s.params.outer_tol, 1e-8);
    assert_eq!(s.params.energy_tol, 1e-6);
    assert_eq!(s.output_every, 5);
    assert_eq!(s.name, "opts");
    let d = s.describe();
    assert!(d.contains("gravity: (0, 0, -9.81)"), "{d}");
    assert!(d.contains("factor table"), "{d}");
    assert!(d.contains("staggered"), "{d}");
}

#[test]
fn errors_carry_file_line_column_key() {
    let text = "[integrator]\nscheme = \"em\"\ndt = -0.1\nt_end = 1\n";
    let e = parse_scene(text, "scenes/bad.toml").unwrap_err();
    assert_eq!(
        e.to_string(),
        "scenes/bad.toml:3:6: integrator.dt: must be > 0 (got -0.1)"
    );
    assert_eq!(e.key(), Some("integrator.dt"));
    assert_eq!(e.location(), Some((3, 6)));
}

#[test]
fn syntax_errors_have_a_location() {
    let e = parse_scene("a = \n", "x.toml").unwrap_err();
    assert!(matches!(e, SceneError::Syntax { .. }), "{e:?}");
    assert!(e.to_string().starts_with("x.toml:1:"), "{e}");
}

#[test]
fn builtin_source_names_default_scene_name() {
    let text = builtin_scenes()[0].toml.replace("name = \"frame\"\n", "");
    let s = parse_scene(&text, "builtin:frame").unwrap();
    assert_eq!(s.name, "frame");
}

#[test]
fn strategy_inexact_parses_and_unknown_strategies_list_the_four() {
    let text = |strategy: &str| {
        format!(
            "{BASE}[[rod]]\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0,0,0],[1,0,0]]\n\
             elements = 2\n[integrator]\nscheme = \"edmc2\"\nalpha_gv = 0.5\ndt = 0.1\n\
             t_end = 1\nstrategy = \"{strategy}\"\n"
        )
    };
    let s = parse_scene(&text("inexact"), "in.toml").unwrap();
    assert_eq!(s.params.strategy, Strategy::Inexact);
    assert!(s.describe().contains("inexact (monolithic fallback)"));
    let s = parse_scene(&text("auto"), "in.toml").unwrap();
    assert_eq!(s.params.strategy, Strategy::Auto);
    let e = parse_scene(&text("lagged"), "in.toml").unwrap_err();
    assert_eq!(e.key(), Some("integrator.strategy"));
    assert!(
        e.to_string().contains(
            "unknown strategy `lagged` (expected \"auto\", \"staggered\", \"monolithic\" or \"inexact\")"
        ),
        "{e}"
    );
}

#[test]
fn newton_fresh_parses_and_unknown_variants_list_the_three() {
    let text = |newton: &str| {
        format!(
            "{BASE}[[rod]]\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0,0,0],[1,0,0]]\n\
             elements = 2\n[integrator]\nscheme = \"em\"\ndt = 0.1\nt_end = 1\n\
             newton = \"{newton}\"\n"
        )
    };
    for (name, variant) in [
        ("full", NewtonVariant::Full),
        ("fresh", NewtonVariant::Fresh),
        ("modified", NewtonVariant::Modified),
    ] {
        let s = parse_scene(&text(name), "in.toml").unwrap();
        assert_eq!(s.params.newton, variant);
        assert_eq!(variant.name(), name);
    }
    let e = parse_scene(&text("quasi"), "in.toml").unwrap_err();
    assert_eq!(e.key(), Some("integrator.newton"));
    assert!(
        e.to_string().contains(
            "unknown Newton variant `quasi` (expected \"full\", \"fresh\" or \"modified\")"
        ),
        "{e}"
    );
}
