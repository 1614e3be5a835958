//! Inputs across the valid/invalid boundary (zeros, negatives, subnormals, 1e300, NaN and
//! infinity literals, huge counts, odd and unicode names, escape sequences) never panic,
//! hang or abort: `cosserat run` and `cosserat sweep` either exit 2 with an error naming
//! the file and the key, or finish (exit 0) with every output inside `--out` and every
//! number of a completed run finite.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use proptest::prelude::*;

/// Runs the binary with a 60 s limit (a hang fails the case).
fn run_limited(mut c: Command) -> Output {
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t0.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("hangs: {c:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
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
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    out
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
