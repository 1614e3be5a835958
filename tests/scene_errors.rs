//! Contract: every malformed scene is rejected with an error whose text names the file, the
//! key path, the reason and (where the key exists in the file) its `line:column`.

use cosserat::scene::{builtin_scenes, load_scene, parse_scene, parse_scene_with_sets, SceneError};

/// A valid scene; each test breaks one thing in it.
const GOOD: &str = r#"name = "t"
gravity = [0, 0, -9.81]

[material.soft]
E = 5e5
nu = 0.3
density = 500

[section.thin]
A = 0.005
I11 = 2e-5
I22 = 2e-5
J = 4e-5

[[rod]]
name = "a"
material = "soft"
section = "thin"
points = [[0, 0, 0], [10, 0, 0]]
elements = 5
d1 = [0, 1, 0]

[[rod]]
name = "b"
material = "soft"
section = "thin"
points = [[10, 0, 0], [10, 10, 0]]
elements = 4

[[clamp]]
at = [0, 0, 0]

[[load]]
at = [10, 10, 0]
force = [0, 0, -1]
time = [0, 1, 1]
factor = [0, 2, 0]

[integrator]
scheme = "edmc2"
alpha = 0.5
dt = 0.2
t_end = 10.0
"#;

const FILE: &str = "scenes/bad.toml";

/// `GOOD` with the first occurrence of `from` replaced by `to` (which must exist).
fn edit(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "test bug: {from:?} not in GOOD");
    GOOD.replacen(from, to, 1)
}

/// 1-based line and column of the first occurrence of `needle` in `text`; when `needle`
/// contains a `^`, of the character after it (the `^` itself is not searched for).
fn loc(text: &str, needle: &str) -> (usize, usize) {
    let (search, shift) = match needle.find('^') {
        Some(i) => (needle.replacen('^', "", 1), i),
        None => (needle.to_string(), 0),
    };
    let at = text.find(&search).expect("needle in text") + shift;
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let col = at - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, col)
}

/// Parses `text`, expects an error, checks it names the file, `key` and `reason`, and
/// returns the message.
fn fails(text: &str, key: &str, reason: &str) -> String {
    let err = parse_scene(text, FILE).expect_err("scene should be rejected");
    let msg = err.to_string();
    assert!(msg.starts_with(FILE), "no file name in: {msg}");
    assert!(
        msg.contains(&format!(": {key}: ")),
        "no key `{key}` in: {msg}"
    );
    assert!(msg.contains(reason), "no reason {reason:?} in: {msg}");
    assert_eq!(err.key(), Some(key), "{msg}");
    msg
}

/// Like [`fails`], and the error points at the first occurrence of `at` in `text`.
fn fails_at(text: &str, key: &str, reason: &str, at: &str) -> String {
    let msg = fails(text, key, reason);
    let (l, c) = loc(text, at);
    assert!(
        msg.starts_with(&format!("{FILE}:{l}:{c}: ")),
        "expected {FILE}:{l}:{c} in: {msg}"
    );
    msg
}

#[test]
fn the_template_is_valid() {
    let s = parse_scene(GOOD, FILE).unwrap();
    assert_eq!(s.model.elements.len(), 9);
    assert_eq!(s.model.n_nodes(), 10);
}

#[test]
fn unknown_top_level_key() {
    let t = edit("gravity = ", "gravty = ");
    fails_at(&t, "gravty", "unknown field `gravty`", "gravty");
}

#[test]
fn unknown_key_in_rod() {
    let t = edit("elements = 4\n", "elements = 4\ncolor = \"red\"\n");
    fails_at(&t, "rod[1].color", "unknown field `color`", "color");
}

#[test]
fn wrong_type_string_for_e() {
    let t = edit("E = 5e5", "E = \"stiff\"");
    fails_at(&t, "material.soft.E", "invalid type: string", "\"stiff\"");
}

#[test]
fn missing_integrator() {
    let t = GOOD[..GOOD.find("[integrator]").unwrap()].to_string();
    fails(&t, "integrator", "required table [integrator] missing");
}

#[test]
fn missing_rods() {
    let start = GOOD.find("[[rod]]").unwrap();
    let end = GOOD.find("[integrator]").unwrap();
    let t = format!("{}{}", &GOOD[..start], &GOOD[end..]);
    fails(&t, "rod", "no rods");
}

#[test]
fn negative_young_modulus() {
    let t = edit("E = 5e5", "E = -5e5");
    fails_at(&t, "material.soft.E", "must be > 0 (got -500000)", "-5e5");
}

#[test]
fn zero_time_step() {
    let t = edit("dt = 0.2", "dt = 0.0");
    fails_at(&t, "integrator.dt", "must be > 0 (got 0)", "dt = ^0.0");
}

#[test]
fn negative_time_step() {
    let t = edit("dt = 0.2", "dt = -0.1");
    let msg = fails_at(&t, "integrator.dt", "must be > 0 (got -0.1)", "-0.1");
    // The documented example form.
    let (l, c) = loc(&t, "-0.1");
    assert_eq!(
        msg,
        format!("{FILE}:{l}:{c}: integrator.dt: must be > 0 (got -0.1)")
    );
}

#[test]
fn nan_in_load_factor_table() {
    let t = edit("factor = [0, 2, 0]", "factor = [0, nan, 0]");
    fails_at(&t, "load[0].factor[1]", "must be finite (got NaN)", "nan");
}

#[test]
fn inf_in_points() {
    let t = edit("[10, 10, 0]]", "[10, inf, 0]]");
    fails_at(&t, "rod[1].points[1][1]", "must be finite (got inf)", "inf");
}

#[test]
fn zero_length_rod() {
    let t = edit("[[10, 0, 0], [10, 10, 0]]", "[[10, 0, 0], [10, 0, 0]]");
    fails_at(
        &t,
        "rod[1].points[1]",
        "zero-length segment",
        "[[10, 0, 0], ^[10, 0, 0]]",
    );
}

#[test]
fn rod_with_one_point() {
    let t = edit("[[10, 0, 0], [10, 10, 0]]", "[[10, 0, 0]]");
    fails_at(
        &t,
        "rod[1].points",
        "at least 2 points (got 1)",
        "[[10, 0, 0]]",
    );
}

#[test]
fn clamp_point_not_a_node() {
    let t = edit("at = [0, 0, 0]", "at = [1, 2, 3]");
    let msg = fails_at(&t, "clamp[0].at", "(1, 2, 3) is not a node", "[1, 2, 3]");
    assert!(
        msg.contains("nearest node 0 at (0, 0, 0), distance"),
        "{msg}"
    );
}

#[test]
fn unknown_material_name() {
    let t = edit(
        "material = \"soft\"\nsection = \"thin\"\npoints = [[10",
        "material = \"hard\"\nsection = \"thin\"\npoints = [[10",
    );
    fails_at(
        &t,
        "rod[1].material",
        "unknown material `hard` (known: `soft`)",
        "\"hard\"",
    );
}

#[test]
fn time_factor_length_mismatch() {
    let t = edit("factor = [0, 2, 0]", "factor = [0, 2]");
    fails_at(
        &t,
        "load[0].factor",
        "same length as `time` (3) (got 2)",
        "[0, 2]",
    );
}

#[test]
fn decreasing_times() {
    let t = edit("time = [0, 1, 1]", "time = [0, 1, 0.5]");
    fails_at(
        &t,
        "load[0].time[2]",
        "non-decreasing (got 0.5 after 1)",
        "0.5]",
    );
}

#[test]
fn poisson_ratio_out_of_range() {
    let t = edit("nu = 0.3", "nu = 0.7");
    fails_at(
        &t,
        "material.soft.nu",
        "must be in (-1, 0.5] (got 0.7)",
        "0.7",
    );
}

#[test]
fn nu_and_g_both_given() {
    let t = edit("nu = 0.3", "nu = 0.3\nG = 2e5");
    fails_at(&t, "material.soft.G", "exactly one of `nu` and `G`", "2e5");
}

#[test]
fn edmc1_key_with_edmc2() {
    let t = edit("alpha = 0.5", "alpha = 0.5\nchi_v = 0.1");
    fails_at(
        &t,
        "integrator.chi_v",
        "not a parameter of scheme edmc2 (it belongs to edmc1)",
        "0.1",
    );
}

#[test]
fn alpha_and_alpha_gv_both() {
    let t = edit("alpha = 0.5", "alpha = 0.5\nalpha_gv = 0.5");
    fails(&t, "integrator.alpha_gv", "not both");
}

#[test]
fn unknown_scheme() {
    let t = edit("scheme = \"edmc2\"", "scheme = \"rk4\"");
    fails_at(&t, "integrator.scheme", "unknown scheme `rk4`", "\"rk4\"");
}

#[test]
fn zero_elements() {
    let t = edit("elements = 4", "elements = 0");
    fails_at(
        &t,
        "rod[1].elements",
        "must be >= 1 (got 0)",
        "elements = ^0",
    );
}

#[test]
fn element_list_of_wrong_length() {
    let t = edit("elements = 4", "elements = [2, 2]");
    fails_at(
        &t,
        "rod[1].elements",
        "one count per segment: 1 (got 2)",
        "[2, 2]",
    );
}

#[test]
fn d1_parallel_to_a_segment() {
    let t = edit("d1 = [0, 1, 0]", "d1 = [2, 0, 0]");
    fails_at(&t, "rod[0].d1", "parallel to segment 0", "[2, 0, 0]");
}

#[test]
fn duplicate_rod_names() {
    let t = edit("name = \"b\"", "name = \"a\"");
    fails(&t, "rod[1].name", "duplicate rod name `a`");
}

#[test]
fn missing_required_key_points_at_its_table() {
    let t = edit("dt = 0.2\n", "");
    let msg = fails(&t, "integrator.dt", "required key missing");
    let (l, _) = loc(&t, "[integrator]");
    assert!(msg.starts_with(&format!("{FILE}:{l}:")), "{msg}");
}

#[test]
fn initial_velocity_at_a_clamped_node() {
    let t = format!("{GOOD}\n[[initial_velocity]]\nat = [0, 0, 0]\nv = [1, 0, 0]\n");
    fails_at(
        &t,
        "initial_velocity[0].at",
        "node 0 at (0, 0, 0) has its translation fixed by a support",
        "at = ^[0, 0, 0]\nv",
    );
}

#[test]
fn vector_of_wrong_length() {
    let t = edit("force = [0, 0, -1]", "force = [0, -1]");
    fails_at(&t, "load[0].force", "expected 3 numbers", "[0, -1]");
}

#[test]
fn negative_integer_count() {
    let t = edit("t_end = 10.0", "t_end = 10.0\nmax_iter = -3");
    fails_at(&t, "integrator.max_iter", "must be >= 1 (got -3)", "-3");
}

#[test]
fn toml_syntax_error_has_line_and_column() {
    let t = edit("J = 4e-5", "J = 4e-5 5");
    let err = parse_scene(&t, FILE).unwrap_err();
    assert!(matches!(err, SceneError::Syntax { .. }), "{err:?}");
    let (l, _) = loc(&t, "J = 4e-5 5");
    let msg = err.to_string();
    assert!(msg.starts_with(&format!("{FILE}:{l}:")), "{msg}");
}

#[test]
fn builtin_frame_loads_and_unknown_name_lists_builtins() {
    let s = load_scene("frame").unwrap();
    assert_eq!(s.source, "builtin:frame");
    assert_eq!(s.model.elements.len(), 15);
    let err = load_scene("nope").unwrap_err();
    assert!(matches!(err, SceneError::UnknownBuiltin { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("nope") && msg.contains("frame"), "{msg}");
}

#[test]
fn missing_file_is_an_io_error() {
    let err = load_scene("no/such/dir/scene.toml").unwrap_err();
    assert!(matches!(err, SceneError::Io { .. }), "{err:?}");
    assert!(
        err.to_string()
            .starts_with("cannot read no/such/dir/scene.toml: "),
        "{err}"
    );
}

#[test]
fn files_load_by_path_and_name_defaults_to_stem() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("my_frame.toml");
    std::fs::write(&path, GOOD.replacen("name = \"t\"\n", "", 1)).unwrap();
    let s = load_scene(path.to_str().unwrap()).unwrap();
    assert_eq!(s.name, "my_frame");
    assert_eq!(s.source, path.to_str().unwrap());
    // Errors from a file name that file.
    std::fs::write(&path, edit("dt = 0.2", "dt = -1")).unwrap();
    let msg = load_scene(path.to_str().unwrap()).unwrap_err().to_string();
    assert!(msg.starts_with(path.to_str().unwrap()), "{msg}");
}

#[test]
fn every_builtin_scene_parses() {
    assert!(builtin_scenes().iter().any(|b| b.name == "frame"));
    for b in builtin_scenes() {
        let s = parse_scene(b.toml, &format!("builtin:{}", b.name))
            .unwrap_or_else(|e| panic!("{}: {e}", b.name));
        assert!(!s.model.elements.is_empty());
        assert!(!b.description.is_empty());
    }
}

#[test]
fn shipped_scene_files_parse() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            load_scene(path.to_str().unwrap()).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

#[test]
fn complete_example_in_docs_matches_builtin_frame() {
    let doc = include_str!("../docs/scenes.md");
    let start = doc.find("## A complete example").expect("section in docs");
    let block = &doc[start..];
    let open = block.find("```toml\n").unwrap() + "```toml\n".len();
    let close = open + block[open..].find("```").unwrap();
    let from_docs = parse_scene(&block[open..close], "docs/scenes.md").unwrap();
    let builtin = load_scene("frame").unwrap();
    assert_eq!(from_docs.model, builtin.model);
    assert_eq!(from_docs.params, builtin.params);
}

/// The built-in mechanism (planar, rigid links) as a template for the planar/link keys.
const MECH: &str = include_str!("../scenes/mechanism.toml");

fn mech_edit(from: &str, to: &str) -> String {
    assert!(
        MECH.contains(from),
        "test bug: {from:?} not in the mechanism scene"
    );
    MECH.replacen(from, to, 1)
}

#[test]
fn unknown_plane() {
    let t = mech_edit("planar = \"e2e3\"", "planar = \"xy\"");
    fails_at(&t, "planar", "unknown plane `xy`", "\"xy\"");
}

#[test]
fn planar_scene_with_out_of_plane_load() {
    let t = mech_edit("force = [0, -25, 2]", "force = [1, -25, 2]");
    fails(&t, "load[0].force", "the force leaves the plane");
}

#[test]
fn planar_scene_with_out_of_plane_rod() {
    let t = mech_edit(
        "points = [[0, 0, 1], [0, 1, 1]]",
        "points = [[0, 0, 1], [0.5, 1, 1]]",
    );
    // The point masses and link still sit at (0, 1, 1), which is no longer a node.
    let err = parse_scene(&t, FILE).expect_err("rejected").to_string();
    assert!(
        err.contains("is not a node") || err.contains("out of the plane"),
        "{err}"
    );
}

#[test]
fn link_with_negative_penalty() {
    let t = mech_edit("penalty = 1e5", "penalty = -1e5");
    fails_at(&t, "link[0].penalty", "must be > 0", "-1e5");
}

#[test]
fn link_with_nan_tolerance() {
    let t = mech_edit("tol = 1e-10", "tol = nan");
    fails_at(&t, "link[0].tol", "must be finite", "nan");
}

#[test]
fn link_to_a_point_that_is_not_a_node() {
    let t = mech_edit(
        "pivot = [0, 0, 0]\nat = [0, 0, 1]",
        "pivot = [0, 0, 0]\nat = [0, 0.1, 1]",
    );
    fails(&t, "link[0].at", "is not a node");
}

#[test]
fn link_of_zero_length() {
    let t = mech_edit(
        "pivot = [0, 0, 0]\nat = [0, 0, 1]",
        "pivot = [0, 0, 1]\nat = [0, 0, 1]",
    );
    fails(&t, "link[0].pivot", "zero length");
}

#[test]
fn link_missing_pivot() {
    let t = mech_edit("pivot = [0, 0, 0]\n", "");
    fails(&t, "link[0].pivot", "required key missing");
}

#[test]
fn unknown_key_in_link() {
    let t = mech_edit("tol = 1e-10", "tol = 1e-10\nstiffness = 3");
    fails_at(
        &t,
        "link[0].stiffness",
        "unknown field `stiffness`",
        "stiffness",
    );
}

#[test]
fn rho_inf_out_of_range() {
    let t = edit(
        "scheme = \"edmc2\"\nalpha = 0.5",
        "scheme = \"gen-alpha\"\nrho_inf = 1.5",
    );
    fails(&t, "integrator.rho_inf", "must be in [0, 1] (got 1.5)");
}

#[test]
fn rho_inf_belongs_to_gen_alpha() {
    let t = edit("alpha = 0.5", "rho_inf = 0.5");
    fails(
        &t,
        "integrator.rho_inf",
        "not a parameter of scheme edmc2 (it belongs to gen-alpha)",
    );
}

#[test]
fn baseline_schemes_parse() {
    let t = edit("scheme = \"edmc2\"\nalpha = 0.5", "scheme = \"midpoint\"");
    assert_eq!(
        parse_scene(&t, FILE).unwrap().params.scheme,
        cosserat::integrator::Scheme::Midpoint
    );
    let t = edit(
        "scheme = \"edmc2\"\nalpha = 0.5",
        "scheme = \"gen-alpha\"\nrho_inf = 0.25",
    );
    assert_eq!(
        parse_scene(&t, FILE).unwrap().params.scheme,
        cosserat::integrator::Scheme::GenAlpha { rho_inf: 0.25 }
    );
}

// ---- Names, ranges, key attribution, echo caps, iteration bounds -----------------------

#[test]
fn empty_rod_name_is_refused() {
    let t = edit("name = \"a\"", "name = \"\"");
    fails_at(&t, "rod[0].name", "must not be empty", "name = ^\"\"");
}

#[test]
fn names_with_control_characters_are_refused() {
    let t = edit("name = \"b\"", "name = \"b\\tc\"");
    fails_at(
        &t,
        "rod[1].name",
        "must not contain control characters (got \\u{9})",
        "\"b\\tc\"",
    );
    let probe = "[[probe]]\nname = \"tip\\u001b[2J\"\nat = [10, 10, 0]\n\n[integrator]";
    let t = edit("[integrator]", probe);
    fails_at(
        &t,
        "probe[0].name",
        "must not contain control characters (got \\u{1b})",
        "\"tip",
    );
}

#[test]
fn names_longer_than_256_bytes_are_refused() {
    let long = "n".repeat(257);
    let t = edit("name = \"t\"", &format!("name = \"{long}\""));
    let msg = fails(&t, "name", "must be at most 256 bytes long (got 257 bytes)");
    assert!(msg.len() < 300, "the name is echoed whole: {msg}");
    let t = edit("name = \"a\"", &format!("name = \"{long}\""));
    fails(
        &t,
        "rod[0].name",
        "must be at most 256 bytes long (got 257 bytes)",
    );
    // 256 bytes are fine.
    let t = edit("name = \"t\"", &format!("name = \"{}\"", &long[..256]));
    assert_eq!(parse_scene(&t, FILE).unwrap().name.len(), 256);
}

#[test]
fn a_coordinate_out_of_range_is_blamed_on_itself() {
    let t = edit("[[0, 0, 0], [10, 0, 0]]", "[[0, 0, 0], [10, 1e200, 0]]");
    let msg = fails_at(
        &t,
        "rod[0].points[1][1]",
        "coordinate out of range: |1e200| > 1e100",
        "1e200",
    );
    assert!(!msg.contains("zero-length"), "{msg}");
    assert!(msg.len() < 300, "{msg}");
    // Up to the limit, the rod is fine.
    let t = edit("[[0, 0, 0], [10, 0, 0]]", "[[0, 0, 0], [1e100, 0, 0]]");
    let t = t.replace(
        "[[10, 0, 0], [10, 10, 0]]",
        "[[1e100, 0, 0], [1e100, 1e99, 0]]",
    );
    let t = t.replace("at = [10, 10, 0]", "at = [1e100, 1e99, 0]");
    parse_scene(&t, FILE).unwrap();
}

#[test]
fn an_underflowing_moment_of_area_is_blamed_on_itself() {
    let t = edit("I11 = 2e-5", "I11 = 5e-324");
    fails_at(
        &t,
        "section.thin.I11",
        "too small: I11*I22 = 0 underflows double precision",
        "5e-324",
    );
    let t = edit("I22 = 2e-5", "I22 = 1e-305");
    fails_at(&t, "section.thin.I22", "too small", "1e-305");
    // A product I12 makes non-positive is still I12's.
    let t = edit("J = 4e-5", "I12 = 3e-5\nJ = 4e-5");
    fails_at(
        &t,
        "section.thin.I12",
        "I11*I22 - I12^2 must be > 0",
        "3e-5",
    );
}

/// Every kind of rejection that echoes what the file says echoes at most a bounded part.
#[test]
fn long_values_are_echoed_cut() {
    let big = "x".repeat(100_000);
    let cases = [
        (
            edit("scheme = \"edmc2\"", &format!("scheme = \"{big}\"")),
            "integrator.scheme",
        ),
        (
            edit("material = \"soft\"", &format!("material = \"{big}\"")),
            "rod[0].material",
        ),
        (edit("gravity = ", &format!("{big} = ")), ""),
        (
            edit("E = 5e5", &format!("E = \"{big}\"")),
            "material.soft.E",
        ),
        (
            edit("[material.soft]", &format!("[material.{big}]")),
            "rod[0].material",
        ),
        (
            edit(
                "at = [0, 0, 0]",
                &format!("at = [{}0]", "0.5, ".repeat(20_000)),
            ),
            "clamp[0].at",
        ),
        (
            edit("dt = 0.2", &format!("dt = -1{}", "0".repeat(300))),
            "integrator.dt",
        ),
    ];
    for (text, key) in cases {
        let err = parse_scene(&text, FILE).expect_err("rejected");
        let msg = err.to_string();
        assert!(
            msg.len() < 600,
            "{} bytes: {}",
            msg.len(),
            msg.chars().take(600).collect::<String>()
        );
        if !key.is_empty() {
            assert_eq!(err.key(), Some(key), "{msg}");
        }
    }
    let msg = fails(
        &edit("scheme = \"edmc2\"", &format!("scheme = \"{big}\"")),
        "integrator.scheme",
        "unknown scheme `xxxx",
    );
    assert!(msg.contains("… (100000 bytes)`"), "{msg}");
}

#[test]
fn iteration_caps_and_tolerances_are_bounded() {
    let with = |line: &str| edit("t_end = 10.0", &format!("t_end = 10.0\n{line}"));
    fails_at(
        &with("max_iter = 9223372036854775807"),
        "integrator.max_iter",
        "must be <= 1000 (got 9223372036854775807)",
        "9223372036854775807",
    );
    fails(
        &with("max_outer = 1001"),
        "integrator.max_outer",
        "must be <= 1000",
    );
    fails(
        &with("max_link_rounds = 5000"),
        "integrator.max_link_rounds",
        "must be <= 1000",
    );
    for key in ["newton_tol", "outer_tol", "energy_tol"] {
        fails_at(
            &with(&format!("{key} = 1e-300")),
            &format!("integrator.{key}"),
            "must be >= 1e-15 (got 1e-300)",
            "1e-300",
        );
    }
    let s = parse_scene(&with("max_iter = 1000\nnewton_tol = 1e-15"), FILE).unwrap();
    assert_eq!((s.params.max_iter, s.params.newton_tol), (1000, 1e-15));
}

/// `--set` values are written into the file's own document: errors about the file's
/// values keep their `line:column`, errors about a `--set` value name the `--set`.
#[test]
fn set_overrides_keep_the_files_locations() {
    // A file value below the overridden one.
    let t = edit("J = 4e-5", "J = -4e-5");
    let err =
        parse_scene_with_sets(&t, FILE, &[("integrator.dt".into(), 0.1)]).expect_err("rejected");
    let (l, c) = loc(&t, "-4e-5");
    assert_eq!(
        err.to_string(),
        format!("{FILE}:{l}:{c}: section.thin.J: must be > 0 (got -4e-5)")
    );
    // A new key inserted by --set before the file's bad value.
    let t = edit("dt = 0.2", "dt = -0.2");
    let err = parse_scene_with_sets(&t, FILE, &[("integrator.max_iter".into(), 3.0)])
        .expect_err("rejected");
    assert_eq!(err.location(), Some(loc(&t, "-0.2")), "{err}");
    // The --set value itself.
    let err =
        parse_scene_with_sets(GOOD, FILE, &[("integrator.dt".into(), -1.0)]).expect_err("rejected");
    assert!(matches!(err, SceneError::Set { .. }), "{err:?}");
    assert_eq!(
        err.to_string(),
        format!("--set integrator.dt=-1 (on {FILE}): integrator.dt: must be > 0 (got -1)")
    );
    // A rod named by its name resolves to its index; a type error is the --set's.
    let err =
        parse_scene_with_sets(GOOD, FILE, &[("rod.b.elements".into(), 0.0)]).expect_err("rejected");
    assert_eq!(err.key(), Some("rod[1].elements"), "{err}");
    assert!(
        err.to_string().starts_with("--set rod.b.elements=0 "),
        "{err}"
    );
    let err = parse_scene_with_sets(GOOD, FILE, &[("integrator.cutback".into(), 0.5)])
        .expect_err("rejected");
    assert!(
        err.to_string().starts_with(
            "--set integrator.cutback=0.5 (on scenes/bad.toml): integrator.cutback: invalid type"
        ),
        "{err}"
    );
    let err = parse_scene_with_sets(GOOD, FILE, &[("name".into(), 1.0)]).expect_err("rejected");
    assert_eq!(
        err.to_string(),
        "--set name=1 (on scenes/bad.toml): name: the scene's value there is a string, not a number"
    );
    // Accepted overrides take effect.
    let s = parse_scene_with_sets(GOOD, FILE, &[("rod[0].elements".into(), 7.0)]).unwrap();
    assert_eq!(s.model.elements.len(), 7 + 4);
}
