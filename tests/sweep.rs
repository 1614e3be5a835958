//! Sweeps: bad sweep files give scene-quality errors (`FILE:LINE:COL: KEY: REASON`,
//! exit code 2 from the CLI); a grid sweep writes one `members.csv` row per member with
//! the documented columns plus one per varied parameter; `--resume` runs only the members
//! not yet recorded; `--backend auto` runs whether or not an adapter exists (falling back
//! to the CPU with a note when none does), `--backend gpu` without one exits with code 2;
//! a member whose scene rejects its values is a `rejected` row (the first included) with
//! empty cells; a refused sweep changes nothing in its folder and a fresh one removes the
//! old `sweep.json` before its first row; a missing adapter is named (`sweep`, `bench`);
//! a sweep stopped from another thread records the members under way, no more, and
//! `resume` completes it with the rows of an uninterrupted sweep.

mod common;

use std::path::Path;
use std::process::Command;

use cosserat::batch::Executor;
use cosserat::sweep::{
    load_sweep, merge_shards, run_sweep, run_sweep_until, MemberStatus, Shard, SweepOptions,
    CSV_COLUMNS,
};

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn err(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "s.toml", text);
    match load_sweep(&p) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string().replace(&p.display().to_string(), "s.toml"),
    }
}

const GOOD: &str = "base = \"frame\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.5]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.6]\n";

#[test]
fn bad_sweep_files_name_file_line_key_and_reason() {
    let cases: &[(&str, &str)] = &[
        ("base = \"frame\"\nvry = 1\n", "s.toml:2:1: vry: unknown field `vry`"),
        ("base = \"nope\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [1]\n", "s.toml:1:8: base: no scene file"),
        ("base = \"frame\"\nmode = \"grd\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [1]\n", "s.toml:2:8: mode: must be \"grid\", \"list\" or \"random\" (got \"grd\")"),
        ("base = \"frame\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = []\n", "s.toml:4:10: vary[0].values: must not be empty"),
        ("base = \"frame\"\n[[vary]]\nkey = \"integrator.alfa\"\nvalues = [1]\n", "s.toml:3:7: vary[0].key: base scene rejects it: builtin:frame"),
        ("base = \"frame\"\n[[vary]]\nkey = \"rod[7].elements\"\nvalues = [3]\n", "s.toml:3:7: vary[0].key: index 7 out of range"),
        ("base = \"frame\"\n[[vary]]\nkey = \"name\"\nvalues = [3]\n", "vary[0].key: the base scene's value there is a string, not a number"),
        ("base = \"frame\"\nmode = \"random\"\nsamples = 4\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [1]\n", "s.toml:5:7: vary[0]: mode random needs `range = [lo, hi]`"),
        ("base = \"frame\"\nmode = \"random\"\nsamples = 4\n[[vary]]\nkey = \"integrator.dt\"\nrange = [0.2, 0.1]\n", "s.toml:6:9: vary[0].range: must be [lo, hi]"),
        ("base = \"frame\"\nmode = \"list\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.1, 0.2]\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [1]\n", "s.toml:8:10: vary[1].values: mode list needs equal lengths"),
        ("base = \"frame\"\n", "s.toml: vary: no [[vary]] table"),
        ("base = \"frame\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [\"x\"]\n", "s.toml:4:11: vary[0].values: invalid type"),
        ("base = \"frame\n", "s.toml:1:"),
    ];
    for (text, want) in cases {
        let got = err(text);
        assert!(
            got.contains(want),
            "for\n{text}\nwant `{want}`\ngot  `{got}`"
        );
    }
}

#[test]
fn a_stopped_sweep_keeps_its_rows_and_resume_completes_it() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let dir = tempfile::tempdir().unwrap();
    let text = "base = \"frame\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.2]\n";
    let p = write(dir.path(), "g.toml", text);
    let spec = load_sweep(&p).unwrap();
    let rows = |out: &Path| -> Vec<String> {
        let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
        // Every cell but wall_s (column 7).
        let mut r: Vec<String> = csv
            .lines()
            .skip(1)
            .map(|l| {
                let mut c: Vec<&str> = l.split(',').collect();
                c[7] = "";
                c.join(",")
            })
            .collect();
        r.sort_by_key(|l| l.split(',').next().unwrap().parse::<usize>().unwrap());
        r
    };
    let whole = dir.path().join("whole");
    run_sweep(
        &spec,
        &Executor::Cpu,
        &whole,
        &SweepOptions::default(),
        |_| {},
    )
    .unwrap();
    let out = dir.path().join("out");
    let stop = AtomicBool::new(false);
    let mut seen = 0;
    let s = run_sweep_until(
        &spec,
        &Executor::Cpu,
        &out,
        &SweepOptions::default(),
        Some(&stop),
        |_| {
            seen += 1;
            stop.store(true, Ordering::SeqCst);
        },
    )
    .unwrap();
    // The first group (twice the worker threads) ran, no more.
    let group = 2 * rayon::current_num_threads();
    assert!(s.stopped);
    assert_eq!(s.completed, group.min(10));
    assert_eq!(seen, s.completed);
    assert!(out.join("sweep.json").exists());
    if group < 10 {
        let s = run_sweep(
            &spec,
            &Executor::Cpu,
            &out,
            &SweepOptions {
                resume: true,
                ..Default::default()
            },
            |_| {},
        )
        .unwrap();
        assert!(!s.stopped);
        assert_eq!((s.skipped, s.completed), (group, 10 - group));
    }
    assert_eq!(rows(&out), rows(&whole));
}

#[test]
fn grid_random_and_list_member_counts() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "g.toml", GOOD);
    assert_eq!(load_sweep(&p).unwrap().len(), 2);
    let r = "base = \"frame\"\nmode = \"random\"\nseed = 3\nsamples = 5\n[[vary]]\nkey = \"integrator.alpha\"\nrange = [0.1, 1.0]\nlog = true\n";
    let p = write(dir.path(), "r.toml", r);
    let a = load_sweep(&p).unwrap();
    let b = load_sweep(&p).unwrap();
    assert_eq!(a.len(), 5);
    assert_eq!(a.values, b.values, "seeded samples repeat");
    assert!(a.values.iter().all(|v| (0.1..=1.0).contains(&v[0])));
}

#[test]
fn sweep_writes_rows_and_resume_skips_recorded_members() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "g.toml", GOOD);
    let spec = load_sweep(&p).unwrap();
    let out = dir.path().join("out");
    let opts = SweepOptions {
        histories: true,
        ..Default::default()
    };
    let s = run_sweep(&spec, &Executor::Cpu, &out, &opts, |_| {}).unwrap();
    assert_eq!((s.completed, s.failed), (2, 0));
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&head[..8], &CSV_COLUMNS);
    assert_eq!(
        &head[8..],
        &["integrator.alpha", "integrator.t_end", "reason"]
    );
    assert_eq!(lines.clone().count(), 2);
    assert!(out.join("member_1/history.csv").exists());
    let info = std::fs::read_to_string(out.join("sweep.json")).unwrap();
    assert!(info.contains("\"backend\": \"cpu\""), "{info}");
    // The frame's EDMC-2 members on the CPU: `auto` ran the monolithic Newton.
    assert!(info.contains("\"strategy\": \"monolithic\""), "{info}");
    // Drop member 1's row, resume: only member 1 runs again.
    let kept: Vec<&str> = csv.lines().filter(|l| !l.starts_with("1,")).collect();
    std::fs::write(out.join("members.csv"), kept.join("\n") + "\n").unwrap();
    let opts = SweepOptions {
        resume: true,
        ..Default::default()
    };
    let s = run_sweep(&spec, &Executor::Cpu, &out, &opts, |_| {}).unwrap();
    assert_eq!((s.skipped, s.completed), (1, 1));
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let mut ids: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    ids.sort();
    assert_eq!(ids, ["0", "1"]);
}

#[test]
fn cli_sweep_exit_codes_and_auto_backend() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(dir.path(), "bad.toml", "base = \"frame\"\nvry = 1\n");
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["sweep"])
        .arg(&bad)
        .args(["--out"])
        .arg(dir.path().join("o1"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("bad.toml:2:1: vry: unknown field"), "{e}");
    let good = write(dir.path(), "g.toml", GOOD);
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["sweep"])
        .arg(&good)
        .args(["--backend", "auto", "--out"])
        .arg(dir.path().join("o2"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(dir.path().join("o2/members.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert!(
        csv.lines().skip(1).all(|l| l.contains(",completed,")),
        "{csv}"
    );

    // No adapter at all (Vulkan pointed at a missing driver): `auto` falls back and says
    // so; `gpu` is an error (exit code 2).
    for (backend, code) in [("auto", 0), ("gpu", 2)] {
        let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
            .env("WGPU_BACKEND", "vulkan")
            .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
            .args(["sweep"])
            .arg(&good)
            .args(["--backend", backend, "--out"])
            .arg(dir.path().join(format!("o3{backend}")))
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{backend}: {e}");
        let want = if code == 0 {
            "backend auto: using the CPU (no GPU adapter"
        } else {
            "error: no GPU adapter"
        };
        assert!(e.contains(want), "{backend}: {e}");
    }
}

/// A member that fails at run time is a result: the sweep goes on, the member's row says
/// `failed` with the time reached and the reason (Newton's, here: EM on the frame at
/// Δt = 0.5 fails in its fifth step, from t = 2 to 2.5; tests/cutback.rs), its history
/// ends at the last accepted step, and the members before and after it complete. The
/// sweep runs with `cutback: Some(0)` (the fixed-step scheme): by default a sweep cuts a
/// failed step back, and that member would complete.
#[test]
fn a_member_failing_at_run_time_is_recorded_with_its_reason_and_the_sweep_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let text = "base = \"frame\"\nmode = \"list\"\n\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.2, 0.5, 0.1]\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.0, 0.0]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [4.0, 4.0, 4.0]\n";
    let p = write(dir.path(), "f.toml", text);
    let spec = load_sweep(&p).unwrap();
    let out = dir.path().join("out");
    let opts = SweepOptions {
        histories: true,
        cutback: Some(0),
        ..Default::default()
    };
    let s = run_sweep(&spec, &Executor::Cpu, &out, &opts, |_| {}).unwrap();
    assert_eq!((s.completed, s.failed), (2, 1));
    // By default the sweep cuts the failing step back, and every member completes.
    let default = run_sweep(
        &spec,
        &Executor::Cpu,
        &dir.path().join("cut"),
        &SweepOptions::default(),
        |_| {},
    )
    .unwrap();
    assert_eq!((default.completed, default.failed), (3, 0));
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert_eq!(rows.len(), 3);
    let by_member = |m: &str| rows.iter().find(|r| r[0] == m).unwrap();
    for m in ["0", "2"] {
        assert_eq!(by_member(m)[col("status")], "completed", "member {m}");
    }
    let failed = by_member("1");
    assert_eq!(failed[col("status")], "failed");
    let t: f64 = failed[col("t_reached")].parse().unwrap();
    assert!((t - 2.0).abs() < 1e-12, "t_reached {t}");
    let reason = &failed[col("reason")];
    assert!(reason.contains("Newton did not converge"), "{reason}");
    // The failed member's history ends at its last accepted step.
    let hist = std::fs::read_to_string(out.join("member_1/history.csv")).unwrap();
    let last = hist.lines().last().unwrap();
    assert!(last.starts_with("4,2,"), "{last}");
}

/// A member whose scene rejects its values is a result, whichever member it is (the first
/// included): a `rejected` row with the reason and empty result cells (no `NaN` in the
/// file), in a one-process sweep, a resumed one and merged shards alike. A key the base
/// scene has no room for, or an invalid base scene, is still the sweep file's error.
#[test]
fn rejected_members_are_rows_first_or_not_with_empty_cells() {
    let dir = tempfile::tempdir().unwrap();
    let text = "base = \"frame\"\nmode = \"list\"\n\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [-0.1, 0.2, 0.0]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.6, 0.6, 0.6]\n";
    let p = write(dir.path(), "r.toml", text);
    let spec = load_sweep(&p).unwrap();
    let out = dir.path().join("out");
    let mut seen = Vec::new();
    let s = run_sweep(&spec, &Executor::Cpu, &out, &SweepOptions::default(), |r| {
        seen.push((r.member, r.status))
    })
    .unwrap();
    assert_eq!((s.completed, s.failed, s.rejected), (1, 0, 2));
    seen.sort_by_key(|x| x.0);
    assert_eq!(
        seen,
        [
            (0, MemberStatus::Rejected),
            (1, MemberStatus::Completed),
            (2, MemberStatus::Rejected)
        ]
    );
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    assert!(!csv.to_lowercase().contains("nan"), "{csv}");
    assert!(!csv.contains("inf"), "{csv}");
    let row = |m: &str| -> Vec<String> {
        csv.lines()
            .find(|l| l.starts_with(&format!("{m},")))
            .unwrap()
            .split(',')
            .map(str::to_string)
            .collect()
    };
    let r0 = row("0");
    assert_eq!(r0[1], "rejected", "{csv}");
    assert!(r0[2..8].iter().all(|c| c.is_empty()), "{csv}");
    assert_eq!(&r0[8..10], ["-0.1", "0.6"], "{csv}");
    assert!(
        r0[10].contains("integrator.dt: must be > 0 (got -0.1)"),
        "{csv}"
    );
    assert_eq!(row("2")[1], "rejected");
    assert_eq!(row("1")[1], "completed");
    let info = std::fs::read_to_string(out.join("sweep.json")).unwrap();
    assert!(info.contains("\"rejected\": 2"), "{info}");
    // Recorded like any row: a resume skips them.
    let opts = SweepOptions {
        resume: true,
        ..Default::default()
    };
    let s = run_sweep(&spec, &Executor::Cpu, &out, &opts, |_| {}).unwrap();
    assert_eq!((s.skipped, s.rejected), (3, 0));
    // As shards, merged: the same rows.
    let sh = dir.path().join("sh");
    for i in 0..2 {
        let opts = SweepOptions {
            shard: Some(Shard::new(i, 2).unwrap()),
            ..Default::default()
        };
        run_sweep(&spec, &Executor::Cpu, &sh, &opts, |_| {}).unwrap();
    }
    let m = merge_shards(&sh).unwrap();
    assert_eq!((m.completed, m.failed, m.rejected), (1, 0, 2));
    let merged = std::fs::read_to_string(sh.join("members.csv")).unwrap();
    assert_eq!(
        merged.lines().filter(|l| l.contains(",rejected,")).count(),
        2
    );
    // The CLI: exit 0, the count said.
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .arg("sweep")
        .arg(&p)
        .arg("--out")
        .arg(dir.path().join("cli"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(said.contains("1 completed, 0 failed, 2 rejected"), "{said}");
    // Still errors of the sweep file: a key the scene format lacks, an invalid base scene.
    for (text, want) in [
        (
            "base = \"frame\"\n[[vary]]\nkey = \"integrator.alfa\"\nvalues = [1]\n",
            "vary[0].key: base scene rejects it:",
        ),
        (
            "base = \"bad.toml\"\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.1]\n",
            "base: base scene:",
        ),
    ] {
        write(dir.path(), "bad.toml", "[integrator]\ndt = -1\n");
        let p = write(dir.path(), "k.toml", text);
        let e = load_sweep(&p).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
}

/// A fresh sweep over an old sweep's folder: the old `sweep.json` is gone (and `sweep.id`
/// is the new sweep's) before the first new row exists, so a kill at any moment never
/// leaves one sweep's record beside another's rows.
#[test]
fn a_fresh_sweep_replaces_the_old_record_before_its_first_row() {
    let dir = tempfile::tempdir().unwrap();
    let old = write(dir.path(), "old.toml", GOOD);
    let new = write(
        dir.path(),
        "new.toml",
        &GOOD.replace("[0.0, 0.5]", "[0.25, 1.0]"),
    );
    let out = dir.path().join("out");
    run_sweep(
        &load_sweep(&old).unwrap(),
        &Executor::Cpu,
        &out,
        &SweepOptions::default(),
        |_| {},
    )
    .unwrap();
    assert!(out.join("sweep.json").exists());
    let spec = load_sweep(&new).unwrap();
    let mut checked = 0;
    run_sweep(
        &spec,
        &Executor::Cpu,
        &out,
        &SweepOptions::default(),
        |_| {
            assert!(
                !out.join("sweep.json").exists(),
                "the old sweep.json beside the new rows"
            );
            let id = std::fs::read_to_string(out.join("sweep.id")).unwrap();
            assert!(id.contains(&spec.identity()), "{id}");
            checked += 1;
        },
    )
    .unwrap();
    assert_eq!(checked, 2);
    let info = std::fs::read_to_string(out.join("sweep.json")).unwrap();
    assert!(info.contains("new.toml"), "{info}");
}

/// A sweep refused by a check (here the memory of its members, known once they are built;
/// a GPU backend that refuses the batch is another) leaves an earlier sweep's files in the
/// folder as they were; a GPU that cannot be had exits 2 naming `--adapter` (sweep and
/// bench) or `--gpu-only`, and bench runs nothing then.
#[test]
fn a_refused_sweep_changes_nothing_and_a_missing_adapter_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "g.toml", GOOD);
    let out = dir.path().join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .arg("sweep")
        .arg(&good)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let files = ["members.csv", "sweep.id", "sweep.json"];
    let before: Vec<Vec<u8>> = files
        .iter()
        .map(|f| std::fs::read(out.join(f)).unwrap())
        .collect();
    // Members of 2 and 150 elements: the base scene and each member fit 4 MiB, the
    // members together do not (a member that alone exceeds the limit is a rejected row).
    let big = write(
        dir.path(),
        "big.toml",
        "base = \"frame\"\nmode = \"list\"\n[[vary]]\nkey = \"rod[0].elements\"\nvalues = [2, 150, 150, 150]\n",
    );
    let refused = |args: &[&str], env: &[(&str, &str)], sweep: &Path| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
        c.arg("sweep").arg(sweep).arg("--out").arg(&out).args(args);
        for (k, v) in env {
            c.env(k, v);
        }
        let o = c.output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        for (f, b) in files.iter().zip(&before) {
            assert_eq!(
                &std::fs::read(out.join(f)).unwrap(),
                b,
                "{args:?} changed {f}"
            );
        }
        e
    };
    let e = refused(&[], &[("COSSERAT_MAX_MEMORY", "4M")], &big);
    assert!(
        e.contains("big.toml: (members): this sweep would need"),
        "{e}"
    );
    let e = refused(
        &["--backend", "gpu", "--adapter", "no-such-adapter-xyz"],
        &[],
        &good,
    );
    assert!(
        e.contains("error: --adapter: no GPU adapter's name contains `no-such-adapter-xyz`"),
        "{e}"
    );
    let e = refused(
        &["--backend", "gpu"],
        &[
            ("WGPU_BACKEND", "vulkan"),
            ("VK_ICD_FILENAMES", "/nonexistent/icd.json"),
        ],
        &good,
    );
    assert!(e.contains("error: no GPU adapter"), "{e}");

    // bench: nothing runs, exit 2.
    let bench = |args: &[&str], env: &[(&str, &str)]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
        c.args(["bench", "--rods", "1", "--elements", "2", "--steps", "1"])
            .args(args);
        for (k, v) in env {
            c.env(k, v);
        }
        let o = c.output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(
            o.stdout.is_empty(),
            "{args:?} ran: {}",
            String::from_utf8_lossy(&o.stdout)
        );
        e
    };
    for args in [
        &["--gpu-only", "--adapter", "no-such-adapter-xyz"][..],
        &["--adapter", "no-such-adapter-xyz"],
    ] {
        let e = bench(args, &[]);
        assert!(
            e.contains("--adapter: no GPU adapter's name contains `no-such-adapter-xyz`;"),
            "{e}"
        );
    }
    let e = bench(
        &["--gpu-only"],
        &[
            ("WGPU_BACKEND", "vulkan"),
            ("VK_ICD_FILENAMES", "/nonexistent/icd.json"),
        ],
    );
    assert!(
        e.contains("error: --gpu-only: no GPU to time: no GPU adapter"),
        "{e}"
    );
}

/// A GPU batch refused as a whole (the kernels have no contact with obstacles) leaves an
/// earlier sweep's files in the folder as they were. Needs an adapter (skips without one).
#[test]
fn a_gpu_refusing_the_batch_leaves_the_folder_as_it_was() {
    let Some(gpu) = common::gpu() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "b.toml",
        "base = \"bounce\"\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.001, 0.0015]\n",
    );
    let spec = load_sweep(&p).unwrap();
    let out = dir.path().join("out");
    run_sweep(
        &spec,
        &Executor::Cpu,
        &out,
        &SweepOptions::default(),
        |_| {},
    )
    .unwrap();
    let files = ["members.csv", "sweep.id", "sweep.json"];
    let before: Vec<Vec<u8>> = files
        .iter()
        .map(|f| std::fs::read(out.join(f)).unwrap())
        .collect();
    let e = match run_sweep(&spec, &gpu, &out, &SweepOptions::default(), |_| {}) {
        Ok(_) => panic!("the GPU ran contact with obstacles"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("contact with obstacles"), "{e}");
    for (f, b) in files.iter().zip(&before) {
        assert_eq!(
            &std::fs::read(out.join(f)).unwrap(),
            b,
            "the refused GPU sweep changed {f}"
        );
    }
}
