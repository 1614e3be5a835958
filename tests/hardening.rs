//! Nothing lost, nothing written where it should not be (issue 14): scene names cannot
//! steer output paths out of `--out`; a sweep folder is locked, identified and repaired on
//! `--resume` (torn rows, empty files, another sweep's folder); charts finish on subnormal
//! data; sizes are refused before allocation; non-finite values never reach the outputs of
//! a completed run; and the command line checks its numbers and counts. Every failure
//! path asserts its reason.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use cosserat::batch::Executor;
use cosserat::sweep::{load_sweep, run_sweep, SweepOptions};

mod common;
use common::{files_below, member_rows as rows};

fn cosserat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn frame_with(from: &str, to: &str) -> String {
    let base = include_str!("../scenes/frame.toml");
    assert!(base.contains(from), "frame.toml has no `{from}`");
    base.replacen(from, to, 1)
}

// ---- 1. Path traversal ------------------------------------------------------------

#[test]
fn scene_name_cannot_steer_outputs_out_of_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("a/b");
    std::fs::create_dir_all(&work).unwrap();
    let scene = write(
        &work,
        "s.toml",
        &frame_with("name = \"frame\"", "name = \"../../x\""),
    );
    // Default folder (out/<name>) and an explicit --out, both with VTK files.
    for out in [None, Some(work.join("o"))] {
        let mut c = cosserat();
        c.current_dir(&work)
            .arg("run")
            .arg(&scene)
            .args(["--t-end", "0.4", "--vtk"]);
        if let Some(o) = &out {
            c.arg("--out").arg(o);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
    for f in files_below(dir.path()) {
        let s = f.to_string_lossy().into_owned();
        assert!(
            s == "a/b/s.toml" || s.starts_with("a/b/out/") || s.starts_with("a/b/o/"),
            "written outside the output folder: {s}"
        );
    }
    assert!(work.join("o/vtk/_.._x.pvd").exists());
    assert!(work.join("out/_.._x/history.csv").exists());
}

// ---- sweeps --------------------------------------------------------------------------

const SWEEP: &str = "base = \"frame\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.25, 0.5]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.4]\n";

fn sweep_into(spec_path: &Path, out: &Path, resume: bool) -> cosserat::sweep::SweepSummary {
    let spec = load_sweep(spec_path).unwrap();
    let opts = SweepOptions {
        resume,
        ..Default::default()
    };
    run_sweep(&spec, &Executor::Cpu, out, &opts, |_| {}).unwrap()
}

#[test]
fn resume_cuts_a_torn_last_row_and_runs_its_member_again() {
    let dir = tempfile::tempdir().unwrap();
    let sp = write(dir.path(), "s.toml", SWEEP);
    let out = dir.path().join("o");
    sweep_into(&sp, &out, false);
    let full = rows(&out);
    assert_eq!(full.len(), 3);
    // A kill between the start of the last row and its newline.
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let torn = &csv[..csv.len() - 9];
    std::fs::write(out.join("members.csv"), torn).unwrap();
    let s = sweep_into(&sp, &out, true);
    assert_eq!((s.skipped, s.completed), (2, 1));
    assert_eq!(s.repaired_bytes, torn.len() - torn.rfind('\n').unwrap() - 1);
    assert_eq!(rows(&out), full, "every member once, same values");
}

#[test]
fn resume_from_an_empty_or_header_only_members_csv_runs_everything() {
    let dir = tempfile::tempdir().unwrap();
    let sp = write(dir.path(), "s.toml", SWEEP);
    let out = dir.path().join("o");
    sweep_into(&sp, &out, false);
    let full = rows(&out);
    let header = std::fs::read_to_string(out.join("members.csv"))
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    for content in [
        String::new(),
        format!("{header}\n"),
        header[..10].to_string(),
    ] {
        std::fs::write(out.join("members.csv"), &content).unwrap();
        let s = sweep_into(&sp, &out, true);
        assert_eq!((s.skipped, s.completed), (0, 3), "from {content:?}");
        assert_eq!(rows(&out), full);
    }
}

#[test]
fn resume_refuses_another_sweeps_folder_naming_the_identity_file() {
    let dir = tempfile::tempdir().unwrap();
    let sp = write(dir.path(), "s.toml", SWEEP);
    let out = dir.path().join("o");
    sweep_into(&sp, &out, false);
    // Same header, other values.
    let other = write(dir.path(), "t.toml", &SWEEP.replace("0.25", "0.3"));
    let o = cosserat()
        .arg("sweep")
        .arg(&other)
        .arg("--out")
        .arg(&out)
        .arg("--resume")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("sweep.id: id: --resume: the folder holds another sweep"),
        "{e}"
    );
    // A row whose values are not this sweep's (sweep.id intact) is refused by line.
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    std::fs::write(out.join("members.csv"), csv.replacen(",0.25,", ",0.3,", 1)).unwrap();
    let o = cosserat()
        .arg("sweep")
        .arg(&sp)
        .arg("--out")
        .arg(&out)
        .arg("--resume")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("members.csv:") && e.contains(":1: (row): --resume: member 1 has integrator.alpha = 0.3 here but 0.25 in this sweep"),
        "{e}"
    );
    // The same sweep resumed with an override that changes results is another sweep.
    let out2 = dir.path().join("o2");
    sweep_into(&sp, &out2, false);
    for flag in [
        &["--newton", "modified"][..],
        &["--no-fallback"][..],
        &["--cutback", "2"][..],
    ] {
        let o = cosserat()
            .arg("sweep")
            .arg(&sp)
            .arg("--out")
            .arg(&out2)
            .arg("--resume")
            .args(flag)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{flag:?}");
        let e = stderr(&o);
        assert!(
            e.contains("--resume: the folder holds another sweep") && e.contains("overrides"),
            "{flag:?}: {e}"
        );
    }
}

#[test]
fn a_second_sweep_on_a_running_folder_exits_2_and_the_first_finishes_intact() {
    let dir = tempfile::tempdir().unwrap();
    // Long enough (a few seconds) for the second to start while the first runs.
    let sp = write(
        dir.path(),
        "s.toml",
        &SWEEP.replace("values = [0.4]", "values = [100.0]"),
    );
    let out = dir.path().join("o");
    let mut first = cosserat()
        .arg("sweep")
        .arg(&sp)
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while !out.join("members.csv").exists() {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "first sweep never started"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = cosserat()
        .arg("sweep")
        .arg(&sp)
        .arg("--out")
        .arg(&out)
        .arg("--resume")
        .output()
        .unwrap();
    let still_running = first.try_wait().unwrap().is_none();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("another `cosserat sweep` is running in this folder"),
        "{}",
        stderr(&o)
    );
    assert!(still_running, "the first sweep ended before the check");
    assert!(first.wait().unwrap().success());
    let ids: Vec<usize> = rows(&out).iter().map(|r| r.0).collect();
    assert_eq!(ids, [0, 1, 2]);
}

// ---- 6. Charts on subnormal data --------------------------------------------------

#[test]
fn charts_of_subnormal_values_finish() {
    let dir = tempfile::tempdir().unwrap();
    let recs: Vec<_> = (0..20)
        .map(|i| cosserat::observe::record::StepRecord {
            step: i,
            t: i as f64,
            kinetic: 5e-324 * (i % 3) as f64,
            potential: 1e-310,
            total: 1e-310 + 5e-324 * (i % 3) as f64,
            ..Default::default()
        })
        .collect();
    let path = dir.path().join("energy.png");
    let (tx, rx) = std::sync::mpsc::channel();
    let p = path.clone();
    std::thread::spawn(move || {
        let r = cosserat::output::plot_energy(&p, &recs, "subnormal")
            .and_then(|_| cosserat::output::plot_momenta(&p, &recs, "subnormal"));
        let _ = tx.send(r.map_err(|e| e.to_string()));
    });
    let r = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("chart drawing hangs on subnormal values");
    r.unwrap();
    // And end to end: a scene whose energies are subnormal.
    let scene = write(
        dir.path(),
        "d.toml",
        &frame_with("density = 500", "density = 1e-308"),
    );
    let mut child = cosserat()
        .arg("run")
        .arg(&scene)
        .args(["--t-end", "0.4", "--out"])
        .arg(dir.path().join("o"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("run with density 1e-308 hangs");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success());
    assert!(dir.path().join("o/summary.json").exists());
}

// ---- 8. Sizes refused before allocation -------------------------------------------

#[test]
fn oversized_inputs_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    let random = write(
        dir.path(),
        "r.toml",
        "base = \"frame\"\nmode = \"random\"\nsamples = 10000000000\n[[vary]]\nkey = \"integrator.alpha\"\nrange = [0, 1]\n",
    );
    let grid_values = format!(
        "values = [{}]",
        (0..1000)
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",")
    );
    let grid = write(
        dir.path(),
        "g.toml",
        &format!(
            "base = \"frame\"\n[[vary]]\nkey = \"integrator.alpha\"\n{grid_values}\n[[vary]]\nkey = \"initial_velocity[0].v[0]\"\n{grid_values}\n"
        ),
    );
    let grid3 = write(
        dir.path(),
        "g3.toml",
        &format!(
            "base = \"frame\"\n[[vary]]\nkey = \"integrator.alpha\"\n{grid_values}\n[[vary]]\nkey = \"initial_velocity[0].v[0]\"\n{grid_values}\n[[vary]]\nkey = \"initial_velocity[0].v[1]\"\n{grid_values}\n"
        ),
    );
    let mid = write(
        dir.path(),
        "m.toml",
        "base = \"frame\"\nmode = \"random\"\nsamples = 1000\n[[vary]]\nkey = \"integrator.alpha\"\nrange = [0, 1]\n",
    );
    // (arguments, environment, expected error)
    type Case<'a> = (Vec<String>, Vec<(&'a str, &'a str)>, &'a str);
    let cases: Vec<Case> = vec![
        (
            vec!["sweep".into(), random.display().to_string()],
            vec![],
            "r.toml:3:11: samples: 10000000000 members, above the limit of 10000000",
        ),
        (
            vec!["sweep".into(), grid3.display().to_string()],
            vec![],
            "g3.toml: vary: 1000000000 members, above the limit of 10000000 members per sweep",
        ),
        (
            vec!["sweep".into(), grid.display().to_string()],
            vec![("COSSERAT_MAX_MEMORY", "4G")],
            "g.toml: vary: this sweep would need about 8.0 GiB of memory (1000000 member(s); per member: 15 element(s)",
        ),
        (
            vec!["sweep".into(), mid.display().to_string()],
            vec![("COSSERAT_MAX_MEMORY", "10M")],
            "m.toml:3:11: samples: this sweep would need about 369.1 MiB of memory (1000 member(s); per member: 15 element(s) ≈ 175.8 KiB), above the limit of 10.0 MiB (COSSERAT_MAX_MEMORY=10M; set COSSERAT_MAX_MEMORY",
        ),
        (
            vec!["sweep".into(), mid.display().to_string()],
            vec![("COSSERAT_MAX_MEMORY", "lots")],
            "COSSERAT_MAX_MEMORY: cannot read `lots` as a size",
        ),
        (
            vec!["bench".into(), "--elements".into(), "2000000".into()],
            vec![],
            "--elements: 2000000 elements per rod, above the limit of 1000000",
        ),
        (
            vec!["bench".into(), "--rods".into(), "1000000000".into()],
            vec![],
            "--rods: 1000000000 rods, above the limit of 10000000",
        ),
        (
            vec!["bench".into(), "--rods".into(), "2000000".into()],
            vec![],
            "bench would need about 26.4 GiB of memory (2000000 member(s); per member: 30 element(s)",
        ),
    ];
    for (args, env, want) in cases {
        let mut c = cosserat();
        c.args(&args).envs(env);
        if args[0] == "sweep" {
            c.arg("--out").arg(dir.path().join("o"));
        }
        let o = c.output().unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(want), "{args:?}\nwant {want}\ngot  {e}");
    }
    // A scene whose rods together exceed the whole-scene limit.
    let big = write(
        dir.path(),
        "big.toml",
        &include_str!("../scenes/frame.toml").replace("elements = 5", "elements = 400000"),
    );
    let o = cosserat().arg("check").arg(&big).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("rod[2].elements: the scene would have 1200000 or more elements, above the limit of 1000000"),
        "{}",
        stderr(&o)
    );
    // Refused, not attempted: all of the above in well under the time one would take.
    assert!(t0.elapsed() < Duration::from_secs(60));
}

// ---- 9. Non-finite values never reach a completed run's outputs -------------------

#[test]
fn huge_masses_give_finite_outputs_or_a_failed_step() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (from, to)) in [
        ("density = 500", "density = 1e305"),
        ("v = [0, 0, -1]", "v = [0, 0, -1e200]"),
    ]
    .into_iter()
    .enumerate()
    {
        let scene = write(dir.path(), &format!("s{i}.toml"), &frame_with(from, to));
        let out = dir.path().join(format!("o{i}"));
        let o = cosserat()
            .arg("run")
            .arg(&scene)
            .args(["--t-end", "0.4", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let sum: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        let hist = std::fs::read_to_string(out.join("history.csv")).unwrap();
        for l in hist.lines().skip(1) {
            for x in l.split(',') {
                let v: f64 = x.parse().unwrap();
                assert!(v.is_finite(), "{to}: non-finite in history row {l}");
            }
        }
        if sum["status"] == "completed" {
            for k in ["energy_initial", "energy_final"] {
                assert!(
                    sum[k].as_f64().is_some_and(f64::is_finite),
                    "{to}: {k} = {}",
                    sum[k]
                );
            }
            let ib = &sum["impulse_balance"];
            for k in ["max_residual_l", "max_residual_j", "max_rel_residual_l"] {
                assert!(
                    ib[k].as_f64().is_some_and(f64::is_finite),
                    "{to}: impulse_balance.{k} = {}",
                    ib[k]
                );
            }
        } else {
            let r = sum["reason"].as_str().unwrap();
            assert!(r.contains("non-finite"), "{to}: {r}");
        }
    }
}

// ---- 10. Smaller ones -------------------------------------------------------------

#[test]
fn negative_and_zero_arguments_get_their_own_errors() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["run", "frame", "--dt", "-0.1"],
            "--dt: must be a finite number > 0 (got -0.1)",
        ),
        (
            &["run", "frame", "--t-end", "-1"],
            "--t-end: must be a finite number > 0 (got -1)",
        ),
        (
            &["run", "frame", "--alpha", "-2"],
            "--alpha: must be a finite number ≥ 0 (got -2)",
        ),
        (
            &["run", "frame", "--dt", "20"],
            "--dt: Δt = 20 exceeds t_end = 10: the run would take no step",
        ),
        (
            &["run", "frame", "--every", "0"],
            "invalid value '0' for '--every <EVERY>': must be an integer ≥ 1 (got 0)",
        ),
        (
            &["run", "frame", "--snapshots", "0"],
            "invalid value '0' for '--snapshots <N>': must be an integer ≥ 1 (got 0)",
        ),
        (
            &["run", "frame", "--every", "-3"],
            "must be an integer ≥ 1 (got -3)",
        ),
        (&["bench", "--rods", "0"], "must be an integer ≥ 1 (got 0)"),
        (
            &["run", "mechanism", "--scheme", "gen-alpha"],
            "gen-alpha does not support rigid links",
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (args, want) in cases {
        let mut c = cosserat();
        c.args(*args);
        if args[0] == "run" {
            c.arg("--out").arg(dir.path().join("o"));
        }
        let o = c.output().unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(want), "{args:?}\nwant {want}\ngot  {e}");
        assert!(!dir.path().join("o/history.csv").exists());
    }
}

#[test]
fn check_refuses_what_run_cannot_do_and_escapes_control_characters() {
    let dir = tempfile::tempdir().unwrap();
    let mech = include_str!("../scenes/mechanism.toml");
    let ga = write(
        dir.path(),
        "ga.toml",
        &mech
            .lines()
            .filter(|l| !l.trim_start().starts_with("alpha"))
            .collect::<Vec<_>>()
            .join("\n")
            .replace("scheme = \"edmc2\"", "scheme = \"gen-alpha\""),
    );
    let o = cosserat().arg("check").arg(&ga).output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(
        stderr(&o).contains("integrator.scheme: gen-alpha does not support rigid links"),
        "{}",
        stderr(&o)
    );
    let dt = write(dir.path(), "dt.toml", &frame_with("dt = 0.2", "dt = 20.0"));
    let o = cosserat().arg("check").arg(&dt).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains(
            "integrator.dt: must not exceed t_end = 10 (got 20): the run would take no step"
        ),
        "{}",
        stderr(&o)
    );
    let esc = write(
        dir.path(),
        "esc.toml",
        &frame_with(
            "description = \"free-flying",
            "description = \"\\u001b[2J\\u001b]0;pwned\\u0007free-flying",
        ),
    );
    let o = cosserat().arg("check").arg(&esc).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!out.contains('\u{1b}') && !out.contains('\u{7}'), "{out:?}");
    assert!(out.contains("\\u{1b}[2J"), "{out}");
}

#[test]
fn a_reused_folder_holds_only_the_new_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let run = |t_end: &str| {
        cosserat()
            .args(["run", "frame", "--vtk", "--t-end", t_end, "--out"])
            .arg(&out)
            .output()
            .unwrap()
    };
    assert!(run("1.0").status.success());
    assert_eq!(std::fs::read_dir(out.join("vtk")).unwrap().count(), 7);
    let o = run("0.4");
    assert!(o.status.success());
    assert!(
        stderr(&o).contains("removed the previous run's files (history.csv, summary.json, energy.png, momenta.png, accelerations.png, vtk/: 7 files)"),
        "{}",
        stderr(&o)
    );
    let mut vtk: Vec<String> = std::fs::read_dir(out.join("vtk"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    vtk.sort();
    assert_eq!(
        vtk,
        [
            "frame.pvd",
            "frame_000000.vtu",
            "frame_000001.vtu",
            "frame_000002.vtu"
        ]
    );
    // A run killed before it ends leaves no summary.json (of this or the previous run).
    let mut child = cosserat()
        .args(["run", "frame", "--t-end", "1000", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while std::fs::read_to_string(out.join("history.csv")).map_or(0, |h| h.lines().count()) < 6
    // the previous run's history has 4 lines
    {
        assert!(t0.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!out.join("summary.json").exists());
    assert!(!out.join("vtk/frame_000002.vtu").exists());
}

/// A write error (a full disk, simulated by a file-size limit of 0 or 1 KiB: every write
/// past it fails with "File too large", stdout's file included): the sweep exits 2 with
/// one `error: …` line that names the file and gives the reason once, and leaves no
/// temporary file behind.
#[test]
fn a_write_error_is_one_clean_error_line_and_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let short = write(dir.path(), "s.toml", SWEEP);
    // Members of 2 s: their histories are larger than 1 KiB, sweep.id and members.csv not.
    let long = write(dir.path(), "l.toml", &SWEEP.replace("[0.4]", "[2.0]"));
    for (kib, histories, names) in [(0, false, "sweep.id"), (1, true, "history.csv")] {
        let sp = if histories { &long } else { &short };
        let out = dir.path().join(format!("o{kib}"));
        let mut c = Command::new("bash");
        c.arg("-c")
            .arg(format!("trap '' XFSZ; ulimit -f {kib}; exec \"$0\" \"$@\""))
            .arg(env!("CARGO_BIN_EXE_cosserat"))
            .arg("sweep")
            .arg(sp)
            .arg("--out")
            .arg(&out);
        if histories {
            c.arg("--histories");
        }
        // Its stdout on the "full disk" too: the status lines cannot be written either.
        c.stdout(std::fs::File::create(dir.path().join(format!("stdout{kib}"))).unwrap());
        let o = c.output().unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{kib} KiB: {e}");
        assert!(e.starts_with("error: cannot write "), "{kib} KiB: {e}");
        assert_eq!(e.lines().count(), 1, "{kib} KiB: {e}");
        assert!(e.contains(names), "{kib} KiB: {e}");
        assert_eq!(e.matches("File too large").count(), 1, "{kib} KiB: {e}");
        let left: Vec<PathBuf> = files_below(&out)
            .into_iter()
            .filter(|f| f.to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(left.is_empty(), "{kib} KiB: left {left:?}");
    }
}

// ---- Scene files: size, kind, names, --set locations ------------------------------

#[test]
fn scene_files_are_read_with_a_size_cap_and_only_when_regular() {
    // A device would be read forever: refused before reading.
    if Path::new("/dev/zero").exists() {
        let o = cosserat().args(["check", "/dev/zero"]).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains("/dev/zero: not a regular file"),
            "{}",
            stderr(&o)
        );
    }
    // A (sparse) file over 64 MiB: refused by size, for `check` and for `run --set`.
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.toml");
    std::fs::File::create(&big)
        .unwrap()
        .set_len((64 << 20) + 1)
        .unwrap();
    for args in [&["check"][..], &["run", "--set", "integrator.dt=0.1"][..]] {
        let o = cosserat().args(args).arg(&big).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains("big.toml: scene file larger than 64 MiB"),
            "{}",
            stderr(&o)
        );
    }
    // The same for a sweep file and a sweep's base scene.
    std::fs::write(
        dir.path().join("s.toml"),
        "base = \"big.toml\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.1]\n",
    )
    .unwrap();
    for (file, want) in [
        (
            dir.path().join("s.toml"),
            "big.toml: scene file larger than 64 MiB",
        ),
        (big.clone(), "big.toml: scene file larger than 64 MiB"),
        (PathBuf::from("/dev/zero"), "/dev/zero: not a regular file"),
    ] {
        if !file.exists() {
            continue;
        }
        let o = cosserat()
            .arg("sweep")
            .arg(&file)
            .arg("--out")
            .arg(dir.path().join("o"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(want), "{}", stderr(&o));
    }
}

#[test]
fn a_scene_name_over_256_bytes_is_refused_by_run() {
    let dir = tempfile::tempdir().unwrap();
    let long = "n".repeat(100_000);
    let scene = write(
        dir.path(),
        "s.toml",
        &frame_with("name = \"frame\"", &format!("name = \"{long}\"")),
    );
    let o = cosserat()
        .arg("run")
        .arg(&scene)
        .arg("--out")
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("name: must be at most 256 bytes long (got 100000 bytes)"),
        "{e}"
    );
    assert!(e.len() < 500, "{e}");
    assert!(!dir.path().join("o").exists());
}

#[test]
fn run_set_errors_point_into_the_file_or_name_the_set() {
    let dir = tempfile::tempdir().unwrap();
    let text = frame_with("E = 5e5", "E = -5e5");
    let scene = write(dir.path(), "s.toml", &text);
    let line = text
        .lines()
        .position(|l| l.starts_with("E = -5e5"))
        .unwrap()
        + 1;
    let o = cosserat()
        .arg("run")
        .arg(&scene)
        .args(["--set", "integrator.dt=0.1", "--out"])
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!(
            "s.toml:{line}:5: material.frame.E: must be > 0 (got -500000)"
        )),
        "{}",
        stderr(&o)
    );
    let scene = write(dir.path(), "t.toml", &frame_with("E = 5e5", "E = 5e5"));
    let o = cosserat()
        .arg("run")
        .arg(&scene)
        .args(["--set", "integrator.dt=-1", "--out"])
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--set integrator.dt=-1 (on ")
            && stderr(&o).contains("t.toml): integrator.dt: must be > 0 (got -1)"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn long_multibyte_scene_names_fit_every_output_file_name() {
    let dir = tempfile::tempdir().unwrap();
    // 85 characters of 3 bytes: within the name limit (256 bytes), 255 bytes of file name
    // before the suffixes.
    let name = "名".repeat(85);
    let scene = write(
        dir.path(),
        "cjk.toml",
        &frame_with("name = \"frame\"", &format!("name = \"{name}\"")),
    );
    let o = cosserat().arg("check").arg(&scene).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    // The default folder out/<stem> and the VTK files vtk/<stem>_STEP.vtu, <stem>.pvd.
    let o = cosserat()
        .arg("run")
        .arg(&scene)
        .args(["--t-end", "0.4", "--vtk"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let files = files_below(&dir.path().join("out"));
    let ext = |e: &str| {
        files
            .iter()
            .filter(|f| f.extension().is_some_and(|x| x == e))
            .count()
    };
    assert!(ext("vtu") >= 2 && ext("pvd") == 1, "{files:?}");
    for f in &files {
        for c in f.iter() {
            assert!(c.len() <= cosserat::paths::MAX_FILE_NAME_BYTES, "{f:?}");
        }
    }
}

#[test]
fn summary_json_writes_no_null_for_a_non_finite_number() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(
        dir.path(),
        "v.toml",
        &frame_with("v = [0, 0, -1]", "v = [0, 0, -1e200]"),
    );
    let out = dir.path().join("o");
    let o = cosserat()
        .arg("run")
        .arg(&scene)
        .args(["--t-end", "0.4", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["status"], "failed");
    assert!(s["reason"].as_str().unwrap().contains("non-finite"), "{s}");
    // The non-finite energy is named, not hidden as null.
    assert_eq!(s["energy_initial"], "inf", "{s}");
    assert_eq!(s["energy_final"], "inf", "{s}");
    // null only where docs/outputs.md documents it: an absent value.
    fn nulls(v: &serde_json::Value, path: String, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Null => out.push(path),
            serde_json::Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    nulls(x, format!("{path}[{i}]"), out);
                }
            }
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    nulls(x, p, out);
                }
            }
            _ => {}
        }
    }
    let mut found = Vec::new();
    nulls(&s, String::new(), &mut found);
    for p in &found {
        assert!(
            ["reason", "smallest_substep", "strategy"].contains(&p.as_str()),
            "null at {p}"
        );
    }
}
