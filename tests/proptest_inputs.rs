//! Inputs across the valid/invalid boundary (zeros, negatives, subnormals, 1e300, NaN and
//! infinity literals, huge counts, odd and unicode names, escape sequences) never panic,
//! hang or abort: `cosserat run` and `cosserat sweep` either exit 2 with an error naming
//! the file and the key, or finish (exit 0) with every output inside `--out` and every
//! number of a completed run finite.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use proptest::prelude::*;

mod common;

/// Runs the binary with a 60 s limit (a hang fails the case).
fn run_limited(c: Command) -> Output {
    common::run_limited(c, None, Duration::from_secs(60))
}

/// `error: …FILE[:L:C]: KEY: REASON`.
fn names_file_and_key(err: &str, file: &str) -> bool {
    let Some(i) = err.find(file) else {
        return false;
    };
    let mut rest = &err[i + file.len()..];
    // Optional `:line:col`.
    for _ in 0..2 {
        if let Some(r) = rest.strip_prefix(':') {
            let digits = r.bytes().take_while(u8::is_ascii_digit).count();
            if digits > 0 {
                rest = &r[digits..];
            }
        }
    }
    let Some(rest) = rest.strip_prefix(": ") else {
        return false;
    };
    rest.find(": ").is_some_and(|k| k > 0)
}

/// Every file below `dir` (relative).
fn files_below(dir: &Path) -> Vec<String> {
    common::files_below(dir)
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect()
}

fn all_finite(v: &serde_json::Value, path: &str, bad: &mut Vec<String>) {
    match v {
        // Documented nulls: no failure reason, no step cut back, no dissipation strategy
        // (a conserving scheme).
        serde_json::Value::Null if !matches!(path, "reason" | "smallest_substep" | "strategy") => {
            bad.push(path.to_string())
        }
        serde_json::Value::Number(n) if !n.as_f64().is_some_and(f64::is_finite) => {
            bad.push(path.to_string())
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                all_finite(x, &format!("{path}[{i}]"), bad)
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                all_finite(x, k, bad)
            }
        }
        _ => {}
    }
}

/// Checks a finished run's folder: history rows finite; a completed run's summary finite.
fn check_run_outputs(out: &Path) {
    let sum: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let hist = std::fs::read_to_string(out.join("history.csv")).unwrap();
    for l in hist.lines().skip(1) {
        assert!(
            l.split(',')
                .all(|x| x.parse::<f64>().is_ok_and(f64::is_finite)),
            "non-finite history row {l}"
        );
    }
    if sum["status"] == "completed" {
        let mut bad = Vec::new();
        all_finite(&sum, "", &mut bad);
        assert!(bad.is_empty(), "completed with non-finite {bad:?}");
    } else {
        assert!(sum["reason"].as_str().is_some_and(|r| !r.is_empty()));
    }
}

const NUMBERS: &[&str] = &[
    "1", "0", "-1", "5e-324", "1e-310", "1e-300", "1e300", "1.7e308", "nan", "inf", "-inf",
    "\"1\"", "1e20", "1e-3",
];
const STIFF: &[&str] = &[
    "1e6", "1e6", "1e6", "0", "-1", "5e-324", "1e300", "nan", "1e20", "1e-3",
];
const DT: &[&str] = &[
    "0.01", "0.01", "0.005", "0", "-0.1", "5e-324", "1e300", "nan", "inf",
];
const T_END: &[&str] = &["0.02", "0.02", "0.01", "1e300", "-1", "0"];
const COUNTS: &[&str] = &["2", "2", "3", "0", "-1", "10000000000", "1e3", "2000000"];
const NAMES: &[&str] = &[
    "\"beam\"",
    "\"../../x\"",
    "\"\"",
    "\"名前\"",
    "\"a/b\\\\c\"",
    "\"\\u001b[31mred\"",
    "\"/etc/passwd\"",
    "\".\"",
];
const SCHEMES: &[&str] = &[
    "\"em\"",
    "\"edmc2\"",
    "\"gen-alpha\"",
    "\"midpoint\"",
    "\"nope\"",
];

#[allow(clippy::too_many_arguments)]
fn scene(
    name: &str,
    e: &str,
    rho: &str,
    a: &str,
    len: &str,
    n: &str,
    v: &str,
    scheme: &str,
    dt: &str,
    t_end: &str,
) -> String {
    format!(
        "name = {name}\ndescription = {name}\n\n[material.m]\nE = {e}\nnu = 0.3\ndensity = {rho}\n\n[section.s]\nA = {a}\nI11 = 1e-8\nI22 = 1e-8\nJ = 2e-8\n\n[[rod]]\nname = {name}\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0, 0, 0], [{len}, 0, 0]]\nelements = {n}\nd1 = [0, 1, 0]\n\n[[clamp]]\nat = [0, 0, 0]\n\n[[initial_velocity]]\nat = [{len}, 0, 0]\nv = [0, {v}, 0]\n\n[integrator]\nscheme = {scheme}\ndt = {dt}\nt_end = {t_end}\n"
    )
}

fn pick(pool: &'static [&'static str]) -> impl Strategy<Value = &'static str> {
    proptest::sample::select(pool)
}

/// Mostly the ordinary value, sometimes one from the boundary pool: most cases then
/// change one or two keys, so that accepted inputs really run.
fn mostly(
    ordinary: &'static str,
    pool: &'static [&'static str],
) -> impl Strategy<Value = &'static str> {
    prop_oneof![5 => Just(ordinary), 1 => proptest::sample::select(pool)]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn scenes_exit_2_naming_file_and_key_or_run_to_finite_outputs(
        name in mostly("\"beam\"", NAMES),
        e in mostly("1e6", STIFF),
        rho in mostly("1000", &["0", "1e-308", "1e305", "nan", "-5", "5e-324"]),
        a in mostly("1e-4", &["5e-324", "0", "1e300", "1e-300"]),
        len in mostly("1", &["0", "-1", "1e-300", "1e300", "1e-8"]),
        n in mostly("2", COUNTS),
        v in mostly("0.3", NUMBERS),
        scheme in mostly("\"edmc2\"", SCHEMES),
        dt in mostly("0.01", DT),
        t_end in mostly("0.02", T_END),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let text = scene(name, e, rho, a, len, n, v, scheme, dt, t_end);
        std::fs::write(dir.path().join("scene.toml"), &text).unwrap();
        let out = dir.path().join("o");
        let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
        c.arg("run").arg(dir.path().join("scene.toml")).arg("--vtk").arg("--out").arg(&out);
        let o = run_limited(c);
        let err = String::from_utf8_lossy(&o.stderr);
        prop_assert!(!err.contains("panicked"), "panic for\n{text}\n{err}");
        if std::env::var_os("PROPTEST_SHOW").is_some() {
            eprintln!("exit {:?}: {}", o.status.code(), err.lines().next().unwrap_or("(ran)"));
        }
        match o.status.code() {
            Some(2) => prop_assert!(names_file_and_key(&err, "scene.toml"), "no file/key in `{err}` for\n{text}"),
            Some(0) => check_run_outputs(&out),
            other => prop_assert!(false, "exit {other:?} for\n{text}\n{err}"),
        }
        for f in files_below(dir.path()) {
            prop_assert!(f == "scene.toml" || f.starts_with("o/"), "{f} written outside --out");
        }
    }

    #[test]
    fn sweep_files_exit_2_naming_file_and_key_or_record_every_member(
        key in pick(&["integrator.dt", "material.m.E", "rod[0].elements", "initial_velocity[0].v[1]", "nope.key", "rod[5].elements", "name"]),
        values in pick(&["[0.01]", "[0, -1]", "[5e-324, 1e300]", "[1e10]", "[]", "[nan]", "[0.005, 0.01]", "[\"x\"]"]),
        mode in pick(&["grid", "list", "random", "zigzag"]),
        samples in pick(&["3", "0", "-1", "10000000000", "1e3", "2"]),
        range in pick(&["[0.005, 0.01]", "[1, 0]", "[0, 1e300]", "[nan, 1]"]),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let base = scene("\"beam\"", "1e6", "1000", "1e-4", "1", "2", "0.3", "\"edmc2\"", "0.01", "0.02");
        std::fs::write(dir.path().join("base.toml"), base).unwrap();
        let text = format!(
            "base = \"base.toml\"\nmode = \"{mode}\"\nsamples = {samples}\n\n[[vary]]\nkey = \"{key}\"\nvalues = {values}\nrange = {range}\n"
        );
        std::fs::write(dir.path().join("sweep.toml"), &text).unwrap();
        let out = dir.path().join("o");
        let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
        c.arg("sweep").arg(dir.path().join("sweep.toml")).arg("--histories").arg("--out").arg(&out);
        let o = run_limited(c);
        let err = String::from_utf8_lossy(&o.stderr);
        prop_assert!(!err.contains("panicked"), "panic for\n{text}\n{err}");
        match o.status.code() {
            Some(2) => prop_assert!(names_file_and_key(&err, "sweep.toml"), "no file/key in `{err}` for\n{text}"),
            Some(0) => {
                let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
                let info: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
                let n = info["members"].as_u64().unwrap() as usize;
                let mut ids: Vec<usize> = csv.lines().skip(1).map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
                ids.sort();
                prop_assert_eq!(ids, (0..n).collect::<Vec<_>>());
                for l in csv.lines().skip(1).filter(|l| l.contains(",completed,")) {
                    let f: Vec<&str> = l.split(',').collect();
                    prop_assert!(f[2..7].iter().all(|x| x.parse::<f64>().is_ok_and(f64::is_finite)), "{}", l);
                }
            }
            other => prop_assert!(false, "exit {other:?} for\n{text}\n{err}"),
        }
        for f in files_below(dir.path()) {
            prop_assert!(f == "sweep.toml" || f == "base.toml" || f.starts_with("o/"), "{f} written outside --out");
        }
    }
}

/// A scene of two rods (`a` clamped at its start, `b` crossing above it) with the blocks
/// the generators give: contact, an obstacle, a support, a probe.
fn featured_scene(contact: &str, obstacle: &str, support: &str, probe: &str) -> String {
    format!(
        "name = \"featured\"\n\n[material.m]\nE = 1e6\nnu = 0.3\ndensity = 1000\n\n[section.s]\nA = 1e-4\nI11 = 1e-8\nI22 = 1e-8\nJ = 2e-8\n\n[[rod]]\nname = \"a\"\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0, 0, 0], [1, 0, 0]]\nelements = 4\nd1 = [0, 1, 0]\n\n[[rod]]\nname = \"b\"\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0.5, -0.5, 0.2], [0.5, 0.5, 0.2]]\nelements = 4\nd1 = [1, 0, 0]\n\n[[clamp]]\nat = [0, 0, 0]\n\n[[initial_velocity]]\nat = [1, 0, 0]\nv = [0, 0.3, -0.2]\n\n{contact}\n{obstacle}\n{support}\n{probe}\n[integrator]\nscheme = \"em\"\ndt = 0.01\nt_end = 0.03\n"
    )
}

const CONTACTS: &[&str] = &[
    "",
    "[[contact]]\nrods = [\"a\", \"b\"]\n",
    "[[contact]]\nrods = [\"a\"]\ncontact_radius = 0.005\nfriction = 0.3\n",
    "[[contact]]\nrods = [\"a\", \"b\"]\ncontact_radius = 1e-9\n",
    "[[contact]]\nrods = [\"a\"]\ncontact_radius = 5e-324\n",
    "[[contact]]\nrods = [\"a\"]\ncontact_radius = 1e3\n",
    "[[contact]]\nrods = [\"a\", \"b\"]\ncontact_radius = 0.5\n",
    "[[contact]]\nrods = [\"a\", \"a\"]\n",
    "[[contact]]\nrods = [\"a\"]\nfriction = nan\n",
    "[[contact]]\nrods = [\"a\"]\nslip = 1e-3\n",
    "[[contact]]\nrods = []\n",
    "[[contact]]\nrods = [\"zz\"]\nstiffness = -1\n",
];
const OBSTACLES: &[&str] = &[
    "",
    "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, -0.1]\nnormal = [0, 0, 1]\nfriction = 0.5\n",
    "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, 0.1]\nnormal = [0, 0, 1]\n",
    "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, -0.1]\nnormal = [0, 0, 0]\n",
    "[[obstacle]]\nkind = \"sphere\"\ncenter = [0.5, 0, -1]\nradius = 0.9\ncontact_radius = 1e-300\n",
    "[[obstacle]]\nkind = \"cylinder\"\npoint = [0, 0, -0.2]\naxis = [0, 1, 0]\nradius = 1e300\n",
    "[[obstacle]]\nkind = \"cone\"\n",
    "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, -0.1]\nnormal = [0, 0, 1]\ndisplacement = [0, 0, 0.05]\ntime = [0, 0.02]\nfactor = [0, 1]\n",
    "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, -0.1]\nnormal = [0, 0, 1]\ndisplacement = [0, 0, 1e300]\ntime = [0, 0.02]\nfactor = [0, inf]\n",
];
const SUPPORTS: &[&str] = &[
    "",
    "[[pin]]\nat = [0.5, 0.5, 0.2]\n",
    "[[clamp]]\nat = [0.5, 0.5, 0.2]\nslide = [0, 0, 1]\nspin = true\n",
    "[[clamp]]\nat = [0.5, 0.5, 0.2]\nslide = [0, 0, 0]\n",
    "[[clamp]]\nat = [0.5, 0.5, 0.2]\nslide = [0, 1, 1]\n",
    "[[clamp]]\nat = [0.5, 0.5, 0.2]\nrotation = [0.5, 0, 0]\ntime = [0, 0.03]\nfactor = [0, 1]\nramp = \"smooth\"\n",
    "[[pin]]\nat = [0.5, 0.5, 0.2]\ndisplacement = [0, 1e200, 0]\ntime = [0, 0.01]\nfactor = [0, 1]\n",
    "[[pin]]\nat = [9, 9, 9]\n",
    "[[clamp]]\nat = [0.5, 0.5, 0.2]\nslide = [0, 0, 1]\nrotation = [1, 0, 0]\ntime = [0, 1]\nfactor = [0, 1]\n",
    "[[pin]]\nat = [0.5, 0.5, 0.2]\ntime = [1, 0]\nfactor = [0, 1]\ndisplacement = [0, 0.1, 0]\n",
];
const PROBES: &[&str] = &[
    "",
    "[[probe]]\nname = \"tip\"\nrod = \"a\"\nnode = -1\n",
    "[[probe]]\nname = \"a\\rb\"\nat = [1, 0, 0]\n",
    "[[probe]]\nname = \"x,y\\n\\\"q\\\"\"\nat = [1, 0, 0]\n",
    "[[probe]]\nname = \"\"\nat = [1, 0, 0]\n",
    "[[probe]]\nrod = \"b\"\ns = 0.33\n",
    "[[probe]]\nrod = \"b\"\nnode = 99\n",
    "[[probe]]\nname = \"t\"\nat = [1, 0, 0]\n\n[[probe]]\nname = \"t\"\nat = [0, 0, 0]\n",
];
/// Output options: trajectories and their times, good and bad.
const TRAJECTORY: &[&[&str]] = &[
    &[],
    &["--trajectory"],
    &["--trajectory", "--output-dt", "0.02"],
    &["--output-dt", "0.01"],
    &["--output-dt", "-0.1"],
    &["--output-dt", "5e-324"],
    &["--times", "0,0.01,0.03"],
    &["--times", "-1"],
    &["--times", "0.015"],
    &["--trajectory", "--cosseratbench"],
    &["--vtk", "--every", "2"],
];
/// `--set` edits of the new keys, good and bad.
const SETS: &[&[&str]] = &[
    &[],
    &["--set", "integrator.dt=0.005"],
    &["--set", "rod[0].elements=0"],
    &["--set", "nope=1"],
    &["--set", "contact[0].contact_radius=1e-9"],
    &["--set", "obstacle[0].radius=0.5"],
    &["--set", "material.m.E=nan"],
    &["--set", "integrator.max_iter=9223372036854775807"],
    &["--set", "probe[0].node=1"],
    &["--set", "clamp[1].slide=[0,0,1]"],
];

/// `run` on generated scenes with contact, obstacles, supports and probes, with output and
/// `--set` options: completed, failed with a named reason, or rejected with one line
/// naming the file and key (or the option); never a panic, abort, hang, non-finite number
/// in a data file, or a file outside `--out`.
fn check_featured(
    contact: &str,
    obstacle: &str,
    support: &str,
    probe: &str,
    traj: &[&str],
    set: &[&str],
) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let text = featured_scene(contact, obstacle, support, probe);
    std::fs::write(dir.path().join("scene.toml"), &text).unwrap();
    let out = dir.path().join("o");
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    c.arg("run")
        .arg(dir.path().join("scene.toml"))
        .args(traj)
        .args(set)
        .arg("--out")
        .arg(&out);
    let o = run_limited(c);
    let err = String::from_utf8_lossy(&o.stderr);
    let case = format!("{traj:?} {set:?}\n{text}");
    prop_assert!(!err.contains("panicked"), "panic for {case}\n{err}");
    if std::env::var_os("PROPTEST_SHOW").is_some() {
        eprintln!(
            "exit {:?}: {}",
            o.status.code(),
            err.lines().next().unwrap_or("(ran)")
        );
    }
    match o.status.code() {
        Some(2) => {
            prop_assert_eq!(err.lines().count(), 1, "one line for {}\n{}", case, err);
            prop_assert!(
                names_file_and_key(&err, "scene.toml")
                    || (err.starts_with("error: ") && err.contains("--")),
                "no file/key or option in `{}` for {}",
                err,
                case
            );
            prop_assert!(!out.exists(), "a rejected run made its folder: {}", case);
        }
        Some(0) => {
            check_run_outputs(&out);
            if out.join("probes.csv").exists() {
                let probes = std::fs::read_to_string(out.join("probes.csv")).unwrap();
                let mut rows = csv_records(&probes).into_iter();
                let head = rows.next().unwrap();
                for r in rows {
                    prop_assert_eq!(r.len(), head.len(), "probes.csv row width: {}", case);
                    prop_assert!(
                        r[1..]
                            .iter()
                            .all(|x| x.parse::<f64>().is_ok_and(f64::is_finite)),
                        "probes.csv {:?}",
                        r
                    );
                }
            }
        }
        other => prop_assert!(false, "exit {other:?} for {case}\n{err}"),
    }
    for f in files_below(dir.path()) {
        prop_assert!(
            f == "scene.toml" || f.starts_with("o/"),
            "{f} written outside --out"
        );
    }
    Ok(())
}

/// Splits CSV text into records (RFC 4180: quoted cells may hold commas, quotes and line
/// breaks).
fn csv_records(text: &str) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    let mut row = Vec::new();
    let mut cell = String::new();
    let mut quoted = false;
    let mut chars = text.chars().peekable();
    while let Some(ch) = chars.next() {
        match (quoted, ch) {
            (true, '"') if chars.peek() == Some(&'"') => {
                chars.next();
                cell.push('"');
            }
            (true, '"') => quoted = false,
            (true, c) => cell.push(c),
            (false, '"') => quoted = true,
            (false, ',') => row.push(std::mem::take(&mut cell)),
            (false, '\n') => {
                row.push(std::mem::take(&mut cell));
                rows.push(std::mem::take(&mut row));
            }
            (false, '\r') => {}
            (false, c) => cell.push(c),
        }
    }
    if !cell.is_empty() || !row.is_empty() {
        row.push(cell);
        rows.push(row);
    }
    rows
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn featured_scenes_complete_fail_with_a_reason_or_are_rejected_in_one_line(
        contact in prop_oneof![3 => Just(""), 2 => pick(CONTACTS)],
        obstacle in prop_oneof![3 => Just(""), 2 => pick(OBSTACLES)],
        support in prop_oneof![3 => Just(""), 2 => pick(SUPPORTS)],
        probe in prop_oneof![3 => Just(""), 2 => pick(PROBES)],
        traj in prop_oneof![2 => Just(TRAJECTORY[0]), 3 => proptest::sample::select(TRAJECTORY)],
        set in prop_oneof![4 => Just(SETS[0]), 1 => proptest::sample::select(SETS)],
    ) {
        check_featured(contact, obstacle, support, probe, traj, set)?;
    }
}

/// Keys of the featured scene a sweep may vary, with values good and bad.
const SWEEP_KEYS: &[&str] = &[
    "contact[0].contact_radius",
    "contact[0].stiffness",
    "obstacle[0].radius",
    "obstacle[0].friction",
    "probe[0].node",
    "integrator.dt",
    "rod[1].elements",
    "contact[3].stiffness",
];
const SWEEP_VALUES: &[&str] = &[
    "[0.004, 0.005, 0.006]",
    "[1e-300, 0.005]",
    "[0.5, 5e-324, -1]",
    "[2, 3, 4, 1]",
    "[1e6, 1e300]",
    "[0.01, 0.005, 0.02]",
];
/// How a shard run is damaged before `merge`.
#[derive(Clone, Copy, Debug)]
enum Tamper {
    None,
    /// Delete the last shard's results.
    Missing,
    /// Replace the last shard's results with the same shard of another sweep.
    Foreign,
    /// Change a value in a row of the first shard.
    EditedValue,
    /// Cut the first shard's results in the middle of a row.
    Torn,
}

/// Runs `cosserat` in `dir`: (exit code, stderr).
fn cosserat_in(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    c.current_dir(dir).args(args);
    let o = run_limited(c);
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A command's outcome: exit 0, or exit 2 with one line; never a panic or abort.
fn one_line_or_ok(code: Option<i32>, err: &str, what: &str) -> Result<bool, TestCaseError> {
    prop_assert!(!err.contains("panicked"), "panic: {} {}", what, err);
    match code {
        Some(0) => Ok(true),
        Some(2) => {
            prop_assert_eq!(err.trim_end().lines().count(), 1, "{}: {}", what, err);
            prop_assert!(err.starts_with("error: "), "{}: {}", what, err);
            Ok(false)
        }
        other => Err(TestCaseError::fail(format!(
            "{what}: exit {other:?}: {err}"
        ))),
    }
}

/// The fields of one CSV line as written (quoted fields keep their quotes; a comma inside
/// quotes does not split).
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '"' => {
                quoted = !quoted;
                fields.last_mut().unwrap().push(c);
            }
            ',' if !quoted => fields.push(String::new()),
            _ => fields.last_mut().unwrap().push(c),
        }
    }
    fields
}

/// A shard's rows with their varied value (the column before `reason`; a reason may hold
/// commas inside its quotes) replaced by another.
fn edit_values(text: &str) -> String {
    text.lines()
        .map(|l| {
            if !l.starts_with(|c: char| c.is_ascii_digit()) {
                return l.to_string();
            }
            let mut fields = csv_fields(l);
            let k = fields.len() - 2;
            fields[k] = "0.123456".into();
            fields.join(",")
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

fn shard_sweep(dir: &Path, name: &str, key: &str, values: &str) {
    let base = featured_scene(
        CONTACTS[1],
        OBSTACLES[1],
        "",
        PROBES[5].replace("s = 0.33", "node = 2").as_str(),
    );
    std::fs::write(dir.join("base.toml"), base).unwrap();
    std::fs::write(
        dir.join(name),
        format!("base = \"base.toml\"\nmode = \"list\"\n\n[[vary]]\nkey = \"{key}\"\nvalues = {values}\n"),
    )
    .unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, failure_persistence: None, ..ProptestConfig::default() })]

    /// Sharded sweeps over the new keys, run shard by shard, optionally damaged, then
    /// merged: every command completes or exits 2 in one line naming what it refuses;
    /// a merge that succeeds holds each member exactly once with this sweep's values and no
    /// NaN; a damaged set of shards never merges; nothing is written outside `--out`.
    #[test]
    fn shards_and_merges_never_mix_or_lie(
        key in pick(SWEEP_KEYS),
        values in pick(SWEEP_VALUES),
        n in pick(&["1", "2", "3", "5", "0", "18446744073709551615", "-1", "x"]),
        tamper in proptest::sample::select(vec![Tamper::None, Tamper::None, Tamper::Missing, Tamper::Foreign, Tamper::EditedValue, Tamper::Torn]),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        shard_sweep(d, "s.toml", key, values);
        let count: usize = n.parse().unwrap_or(0).min(8);
        let mut all_ran = true;
        for i in 0..count.max(1) {
            let shard = format!("{i}/{n}");
            let (code, err) = cosserat_in(d, &["sweep", "s.toml", "--out", "o", "--shard", &shard]);
            let ran = one_line_or_ok(code, &err, &format!("shard {shard}"))?;
            all_ran &= ran;
            if std::env::var_os("PROPTEST_SHOW").is_some() {
                eprintln!("shard {shard} of {key}={values}: exit {code:?} {}", err.lines().next().unwrap_or(""));
            }
            if !ran {
                break;
            }
        }
        if all_ran && count > 0 {
            let last = count - 1;
            let shards = d.join("o/shards");
            match tamper {
                Tamper::None => {}
                Tamper::Missing => std::fs::remove_file(shards.join(format!("{last}-of-{n}.csv"))).unwrap(),
                Tamper::Foreign => {
                    // The same key with other values, as shard `last` of its own sweep.
                    let other = d.join("other");
                    std::fs::create_dir(&other).unwrap();
                    shard_sweep(&other, "s.toml", key, "[0.0041, 0.0051, 0.0061, 3]");
                    let shard = format!("{last}/{n}");
                    let (code, err) = cosserat_in(&other, &["sweep", "s.toml", "--out", "o", "--shard", &shard]);
                    if one_line_or_ok(code, &err, "foreign shard")? {
                        for ext in ["csv", "id", "json"] {
                            let f = format!("{last}-of-{n}.{ext}");
                            std::fs::copy(other.join("o/shards").join(&f), shards.join(&f)).unwrap();
                        }
                    }
                }
                Tamper::EditedValue | Tamper::Torn => {
                    let f = shards.join(format!("0-of-{n}.csv"));
                    let text = std::fs::read_to_string(&f).unwrap();
                    let damaged = match tamper {
                        Tamper::Torn => text[..text.len() - 7.min(text.len())].to_string(),
                        _ => edit_values(&text),
                    };
                    std::fs::write(&f, damaged).unwrap();
                }
            }
            let (code, err) = cosserat_in(d, &["sweep", "merge", "o"]);
            let merged = one_line_or_ok(code, &err, "merge")?;
            if std::env::var_os("PROPTEST_SHOW").is_some() {
                eprintln!("merge after {tamper:?}: exit {code:?} {}", err.lines().next().unwrap_or(""));
            }
            let damaged = !matches!(tamper, Tamper::None);
            let rows_damaged = matches!(tamper, Tamper::EditedValue)
                && std::fs::read_to_string(d.join(format!("o/shards/0-of-{n}.csv"))).unwrap().lines().filter(|l| l.starts_with(|c: char| c.is_ascii_digit())).count() > 0;
            let torn_matters = matches!(tamper, Tamper::Torn);
            prop_assert!(
                !(merged && (matches!(tamper, Tamper::Missing | Tamper::Foreign) || rows_damaged || torn_matters)) || !damaged,
                "{:?} shards merged: {}",
                tamper,
                err
            );
            if merged {
                let csv = std::fs::read_to_string(d.join("o/members.csv")).unwrap();
                let members = values.matches(',').count() + 1;
                let mut ids: Vec<usize> = csv.lines().skip(1).map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
                ids.sort();
                prop_assert_eq!(ids, (0..members).collect::<Vec<_>>(), "{}", csv);
                prop_assert!(!csv.to_ascii_lowercase().contains("nan"), "{}", csv);
            } else {
                prop_assert!(!d.join("o/members.csv").exists(), "a refused merge wrote members.csv");
            }
        }
        for f in files_below(d) {
            prop_assert!(
                f == "s.toml" || f == "base.toml" || f.starts_with("o/") || f.starts_with("other/"),
                "{f} written outside --out"
            );
        }
    }
}

/// The shard tamper edits the varied value even where the member's reason holds commas
/// (a rejected member's reason quoting coordinates): the merge then refuses.
#[test]
fn an_edited_value_before_a_reason_with_commas_is_refused() {
    let fields = csv_fields("0,rejected,,,,,,,0.5,\"apart: (0, 0, 0) and (1, 2, 3)\"");
    assert_eq!(fields.len(), 10);
    assert_eq!(fields[8], "0.5");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    shard_sweep(
        d,
        "s.toml",
        "contact[0].contact_radius",
        "[0.5, 5e-324, -1]",
    );
    for i in 0..3 {
        let (code, err) = cosserat_in(
            d,
            &[
                "sweep",
                "s.toml",
                "--out",
                "o",
                "--shard",
                &format!("{i}/3"),
            ],
        );
        assert_eq!(code, Some(0), "{err}");
    }
    let f = d.join("o/shards/0-of-3.csv");
    let text = std::fs::read_to_string(&f).unwrap();
    assert!(
        text.contains("(0, 0, 0)"),
        "the case's reason holds commas: {text}"
    );
    assert!(
        edit_values(&text).contains(",0.123456,\"scene rejects"),
        "the value edited"
    );
    std::fs::write(&f, edit_values(&text)).unwrap();
    let (code, err) = cosserat_in(d, &["sweep", "merge", "o"]);
    assert_eq!(code, Some(2), "an edited value merged: {err}");
}
