//! Sharded sweeps without Slurm: the shards of a sweep (`--shard I/N`) merged by
//! `sweep merge` give the `members.csv` (every value but the wall time, in member order)
//! and `sweep.id` of the same sweep run in one process; merge refuses a missing, torn,
//! incomplete, foreign, duplicated, mixed-split or running shard naming it, and writes
//! nothing then; a shard's `--resume` checks its identity and repairs a torn row; the job
//! script of `sweep slurm` runs every shard when executed by hand (no Slurm needed); bad
//! options exit 2 naming the option; a shard runs on the backend it is given; N is at most
//! the member count, and merge stays small whatever N the file names claim; merge checks
//! every shard file's identity and every row's values against the sweep.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use cosserat::batch::Executor;
use cosserat::sweep::{load_sweep, merge_shards, run_sweep, Shard, SweepOptions, SweepSummary};

/// 7 members (3 steps each): some complete, the last two fail on their first step.
const SWEEP: &str = "base = \"frame\"\nmode = \"list\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.25, 0.5, 1.0, 2.0, 0.5, 0.5]\n\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.2, 0.2, 0.1, 0.2, 0.2, 5.0, 8.0]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.6, 0.6, 0.3, 0.6, 0.6, 10.0, 16.0]\n";

/// Another sweep (other values).
const OTHER: &str = "base = \"frame\"\nmode = \"list\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]\n\n[[vary]]\nkey = \"integrator.dt\"\nvalues = [0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.4, 0.4, 0.4, 0.4, 0.4, 0.4, 0.4]\n";

fn cosserat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn run(file: &Path, out: &Path, shard: Option<Shard>, resume: bool) -> SweepSummary {
    let spec = load_sweep(file).unwrap();
    let opts = SweepOptions {
        shard,
        resume,
        ..Default::default()
    };
    run_sweep(&spec, &Executor::Cpu, out, &opts, |_| {}).unwrap()
}

fn run_err(file: &Path, out: &Path, opts: SweepOptions) -> String {
    let spec = load_sweep(file).unwrap();
    match run_sweep(&spec, &Executor::Cpu, out, &opts, |_| {}) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    }
}

fn shard(i: usize, n: usize) -> Option<Shard> {
    Some(Shard::new(i, n).unwrap())
}

/// members.csv rows without the wall time (column 7), in file order (a shard's file: after
/// its identity line).
fn rows(csv: &Path) -> Vec<String> {
    std::fs::read_to_string(csv)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("# "))
        .skip(1)
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(7);
            f.join(",")
        })
        .collect()
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort_by_key(|l| l.split(',').next().unwrap().parse::<usize>().unwrap());
    v
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}

fn merge_err(out: &Path) -> String {
    match merge_shards(out) {
        Ok(_) => panic!("merged {}", out.display()),
        Err(e) => {
            assert!(
                !out.join("members.csv").exists(),
                "a refused merge wrote members.csv"
            );
            e.to_string()
        }
    }
}

#[test]
fn shards_merge_to_the_one_process_result() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    let reference = dir.path().join("ref");
    let s = run(&file, &reference, None, false);
    assert_eq!((s.completed, s.failed), (5, 2), "the sweep's mix changed");
    let want = sorted(rows(&reference.join("members.csv")));
    let out = dir.path().join("sharded");
    for i in 0..3 {
        let s = run(&file, &out, shard(i, 3), false);
        assert_eq!(s.members, [3, 2, 2][i]);
        assert_eq!(s.completed + s.failed, s.members);
    }
    let m = merge_shards(&out).unwrap();
    assert_eq!((m.members, m.completed, m.failed, m.shards), (7, 5, 2, 3));
    // Every value but the wall time, rows in member order.
    assert_eq!(rows(&out.join("members.csv")), want);
    let head = |p: &Path| {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .next()
            .map(String::from)
    };
    assert_eq!(
        head(&out.join("members.csv")),
        head(&reference.join("members.csv"))
    );
    assert_eq!(
        std::fs::read_to_string(out.join("sweep.id")).unwrap(),
        std::fs::read_to_string(reference.join("sweep.id")).unwrap()
    );
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    assert_eq!(info["members"], 7);
    assert_eq!(info["merged_shards"], 3);
    assert_eq!(info["backend"], "cpu");
    assert_eq!(info["strategy"], "monolithic");
    assert_eq!(info["shards"].as_array().unwrap().len(), 3);
    // The merged folder is a one-machine sweep's: `--resume` finds every member recorded.
    let s = run(&file, &out, None, true);
    assert_eq!((s.skipped, s.completed, s.failed), (7, 0, 0));
    // Merging again gives the same file.
    let before = std::fs::read(out.join("members.csv")).unwrap();
    merge_shards(&out).unwrap();
    assert_eq!(std::fs::read(out.join("members.csv")).unwrap(), before);
}

#[test]
fn merge_refuses_bad_shards_naming_them_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    let other = write(dir.path(), "o.toml", OTHER);
    let good = dir.path().join("good");
    for i in 0..3 {
        run(&file, &good, shard(i, 3), false);
    }
    let foreign = dir.path().join("foreign");
    run(&other, &foreign, shard(1, 3), false);
    let case = |name: &str, edit: &dyn Fn(&Path)| -> String {
        let d = dir.path().join(name);
        copy_dir(&good, &d);
        edit(&d.join("shards"));
        merge_err(&d)
    };
    let cut = |p: &Path, n: usize| {
        let t = std::fs::read(p).unwrap();
        std::fs::write(p, &t[..t.len() - n]).unwrap();
    };

    let e = case("missing", &|s| {
        std::fs::remove_file(s.join("1-of-3.csv")).unwrap()
    });
    assert!(e.contains("1-of-3.csv: shard 1-of-3: missing"), "{e}");
    assert!(e.contains("--shard 1/3") && e.contains("--resume"), "{e}");

    let e = case("torn", &|s| cut(&s.join("2-of-3.csv"), 5));
    assert!(
        e.contains("2-of-3.csv: shard 2-of-3: torn: ")
            && e.contains("bytes after the last newline"),
        "{e}"
    );

    let e = case("incomplete", &|s| {
        let t = std::fs::read_to_string(s.join("0-of-3.csv")).unwrap();
        let kept: Vec<&str> = t.lines().filter(|l| !l.starts_with("3,")).collect();
        std::fs::write(s.join("0-of-3.csv"), kept.join("\n") + "\n").unwrap();
    });
    assert!(
        e.contains("shard 0-of-3: incomplete: 2 of its 3 members recorded (missing: 3)"),
        "{e}"
    );

    let e = case("twice", &|s| {
        let t = std::fs::read_to_string(s.join("1-of-3.csv")).unwrap();
        let last = t.lines().last().unwrap().to_string();
        std::fs::write(s.join("1-of-3.csv"), format!("{t}{last}\n")).unwrap();
    });
    assert!(
        e.contains("shard 1-of-3: line 5: member") && e.contains("recorded twice"),
        "{e}"
    );

    let e = case("not-its-member", &|s| {
        let t = std::fs::read_to_string(s.join("2-of-3.csv")).unwrap();
        let t = t.replacen("\n2,", "\n3,", 1);
        std::fs::write(s.join("2-of-3.csv"), t).unwrap();
    });
    assert!(
        e.contains("shard 2-of-3: line ")
            && e.contains("member 3 is not one of shard 2/3's (members ≡ 2 mod 3)"),
        "{e}"
    );

    let e = case("with-foreign", &|s| {
        for ext in ["csv", "id"] {
            let f = format!("1-of-3.{ext}");
            std::fs::copy(foreign.join("shards").join(&f), s.join(&f)).unwrap();
        }
    });
    assert!(
        e.contains("1-of-3.id: shard 1-of-3: foreign: it belongs to another sweep"),
        "{e}"
    );
    assert!(e.contains("o.toml"), "{e}");

    let e = case("two-splits", &|s| {
        std::fs::copy(s.join("0-of-3.id"), s.join("0-of-2.id")).unwrap();
    });
    assert!(
        e.contains("shard 0-of-2: this folder holds shards of two splits"),
        "{e}"
    );

    let e = case("merged-over-another-sweep", &|s| {
        std::fs::write(s.join("../sweep.id"), "id 0123456789abcdef\nsweep x.toml\n").unwrap();
    });
    assert!(
        e.contains("sweep.id: id: the folder already holds another sweep"),
        "{e}"
    );

    // A shard still running (it holds its lock, and the folder's lock shared).
    let d = dir.path().join("running");
    copy_dir(&good, &d);
    let folder = std::fs::File::create(d.join(".sweep.lock")).unwrap();
    folder.lock_shared().unwrap();
    let own = std::fs::File::create(d.join("shards/2-of-3.lock")).unwrap();
    own.lock().unwrap();
    let e = merge_err(&d);
    assert!(
        e.contains("2-of-3.lock: shard 2-of-3: still running"),
        "{e}"
    );
    drop((folder, own));
    merge_shards(&d).unwrap();

    // No shards at all, via the CLI: exit 2.
    let o = cosserat()
        .args(["sweep", "merge"])
        .arg(dir.path().join("nothing"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("no shards to merge"), "{}", text(&o));
}

#[test]
fn a_shard_checks_its_identity_repairs_a_torn_row_and_refuses_other_sweeps_shards() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    let other = write(dir.path(), "o.toml", OTHER);
    let out = dir.path().join("o");
    run(&file, &out, shard(0, 3), false);
    let csv = out.join("shards/0-of-3.csv");
    let full = rows(&csv);
    assert_eq!(full.len(), 3);

    // A torn last row is cut and its member runs again.
    let t = std::fs::read(&csv).unwrap();
    std::fs::write(&csv, &t[..t.len() - 7]).unwrap();
    let s = run(&file, &out, shard(0, 3), true);
    assert_eq!(
        (s.skipped, s.completed + s.failed, s.repaired_bytes > 0),
        (2, 1, true)
    );
    assert_eq!(sorted(rows(&csv)), sorted(full.clone()));

    // Resuming with an override that changes results is another sweep.
    let e = run_err(
        &file,
        &out,
        SweepOptions {
            shard: shard(0, 3),
            resume: true,
            cutback: Some(2),
            ..Default::default()
        },
    );
    assert!(
        e.contains("0-of-3.id: id: --resume: the folder holds another sweep"),
        "{e}"
    );

    // A row of another shard's member is refused by line.
    let t = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(&csv, t.replacen("\n3,", "\n4,", 1)).unwrap();
    let e = run_err(
        &file,
        &out,
        SweepOptions {
            shard: shard(0, 3),
            resume: true,
            ..Default::default()
        },
    );
    assert!(
        e.contains("member 4 is not one of shard 0/3's (members ≡ 0 mod 3)"),
        "{e}"
    );
    std::fs::write(&csv, t).unwrap();

    // Another sweep's shard, or this sweep split otherwise, cannot join the folder.
    let e = run_err(
        &other,
        &out,
        SweepOptions {
            shard: shard(1, 3),
            ..Default::default()
        },
    );
    assert!(
        e.contains("0-of-3.id: shard 0-of-3: belongs to another sweep"),
        "{e}"
    );
    let e = run_err(
        &file,
        &out,
        SweepOptions {
            shard: shard(1, 2),
            ..Default::default()
        },
    );
    assert!(
        e.contains("split the sweep into 3 shards, this run into 2"),
        "{e}"
    );
    assert!(!out.join("shards/1-of-3.csv").exists() && !out.join("shards/1-of-2.csv").exists());

    // The same shard twice at once: the second is refused.
    let held = std::fs::File::create(out.join("shards/0-of-3.lock")).unwrap();
    held.lock().unwrap();
    let e = run_err(
        &file,
        &out,
        SweepOptions {
            shard: shard(0, 3),
            resume: true,
            ..Default::default()
        },
    );
    assert!(
        e.contains("shard 0-of-3: shard 0/3 is already running"),
        "{e}"
    );
    drop(held);

    // Bad --shard values exit 2 naming the option.
    for (v, want) in [
        ("3/3", "shard 3 of 3 does not exist"),
        ("1", "is not I/N"),
        ("0/0", "must be ≥ 1"),
    ] {
        let o = cosserat()
            .arg("sweep")
            .arg(&file)
            .arg("--out")
            .arg(dir.path().join("cli"))
            .args(["--shard", v])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{v}: {}", text(&o));
        assert!(
            text(&o).contains("--shard") && text(&o).contains(want),
            "{v}: {}",
            text(&o)
        );
    }
}

#[test]
fn the_slurm_job_script_runs_every_shard_by_hand_and_bad_options_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    let reference = dir.path().join("ref");
    run(&file, &reference, None, false);
    let out = dir.path().join("arr");
    let o = cosserat()
        .args(["sweep", "slurm"])
        .arg(&file)
        .args(["--shards", "3", "--out"])
        .arg(&out)
        .args([
            "--partition",
            "debug",
            "--time",
            "10",
            "--cpus-per-task",
            "2",
            "--mem",
            "1G",
            "--max-running",
            "2",
            "--sbatch=--account=proj",
            "--histories",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let script = out.join("sweep.sbatch");
    let say = text(&o);
    assert!(
        say.contains(&format!("sbatch {}", script.display())),
        "{say}"
    );
    assert!(
        say.contains(&format!("sweep merge {}", out.display())),
        "{say}"
    );
    let s = std::fs::read_to_string(&script).unwrap();
    for want in [
        "#SBATCH --array=0-2%2\n",
        "#SBATCH --partition=debug\n",
        "#SBATCH --time=10\n",
        "#SBATCH --cpus-per-task=2\n",
        "#SBATCH --mem=1G\n",
        "#SBATCH --account=proj\n",
        "#SBATCH --requeue\n",
        "#SBATCH --open-mode=append\n",
        "/logs/shard-%a.log\n",
        "RAYON_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"",
        "--shard \"$SLURM_ARRAY_TASK_ID/3\" --resume --backend \"${COSSERAT_BACKEND:-cpu}\" --histories\n",
    ] {
        assert!(s.contains(want), "no `{want}` in\n{s}");
    }
    assert!(out.join("logs").is_dir());
    // The script itself, run by hand as Slurm would run each task.
    for i in 0..3 {
        let o = Command::new("bash")
            .arg(&script)
            .env("SLURM_ARRAY_TASK_ID", i.to_string())
            .env("SLURM_CPUS_PER_TASK", "1")
            .output()
            .unwrap();
        assert!(o.status.success(), "task {i}: {}", text(&o));
    }
    let o = cosserat()
        .args(["sweep", "merge"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("merged 3 shards"), "{}", text(&o));
    assert!((0..7).all(|i| out.join(format!("member_{i}/history.csv")).is_file()));
    assert_eq!(
        rows(&out.join("members.csv")),
        sorted(rows(&reference.join("members.csv")))
    );

    // Bad options: exit 2 naming the option, nothing written.
    let bad = dir.path().join("bad");
    let cases: &[(&[&str], &str)] = &[
        (&["--shards", "8"], "--shards: 8 shards for 7 members"),
        (&["--shards", "0"], "--shards"),
        (
            &["--shards", "2", "--time", "1 day"],
            "--time: must be one word",
        ),
        (
            &["--shards", "2", "--gres", ""],
            "--gres: must not be empty",
        ),
        (
            &["--shards", "2", "--sbatch", "account=x"],
            "--sbatch: must be an sbatch option",
        ),
    ];
    for (args, want) in cases {
        let o = cosserat()
            .args(["sweep", "slurm"])
            .arg(&file)
            .arg("--out")
            .arg(&bad)
            .args(*args)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(want), "{args:?}: {}", text(&o));
        assert!(
            !bad.join("sweep.sbatch").exists(),
            "{args:?} wrote the script"
        );
    }
    // Another split of the same folder is refused before writing.
    let o = cosserat()
        .args(["sweep", "slurm"])
        .arg(&file)
        .args(["--shards", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("into 3 shards, this run into 2"),
        "{}",
        text(&o)
    );
    // --submit where Slurm is not installed: exit 2 saying so.
    let empty = dir.path().join("empty-path");
    std::fs::create_dir_all(&empty).unwrap();
    let o = cosserat()
        .env("PATH", &empty)
        .args(["sweep", "slurm"])
        .arg(&file)
        .args(["--shards", "2", "--submit", "--out"])
        .arg(dir.path().join("nosbatch"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("cannot run `sbatch`"), "{}", text(&o));
}

#[test]
fn a_shard_runs_on_the_backend_it_is_given() {
    let Some(gpu) = common::gpu() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // The same strategy on both backends (the default `auto` is monolithic on the CPU,
    // staggered with a GPU evaluator): the frame with `strategy = "staggered"`.
    let frame = cosserat::scene::builtin_scenes()
        .iter()
        .find(|b| b.name == "frame")
        .unwrap()
        .toml
        .replace("[integrator]\n", "[integrator]\nstrategy = \"staggered\"\n");
    assert!(frame.contains("strategy = \"staggered\""));
    write(dir.path(), "frame_staggered.toml", &frame);
    let file = write(
        dir.path(),
        "s.toml",
        &SWEEP.replace("base = \"frame\"", "base = \"frame_staggered.toml\""),
    );
    let spec = load_sweep(&file).unwrap();
    let reference = dir.path().join("ref");
    run(&file, &reference, None, false);
    let out = dir.path().join("mixed");
    run(&file, &out, shard(0, 2), false);
    let opts = SweepOptions {
        shard: shard(1, 2),
        ..Default::default()
    };
    run_sweep(&spec, &gpu, &out, &opts, |_| {}).unwrap();
    let m = merge_shards(&out).unwrap();
    assert_eq!(m.backends.len(), 2, "{:?}", m.backends);
    assert!(m.backends[1].starts_with("gpu"), "{:?}", m.backends);
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    assert_eq!(
        info["strategy"], "staggered",
        "the scene names it for both backends"
    );
    // GPU members agree with the CPU ones (to round-off, not bit for bit).
    let want = sorted(rows(&reference.join("members.csv")));
    let got = rows(&out.join("members.csv"));
    let mut worst = 0.0f64;
    for (a, b) in want.iter().zip(&got) {
        let (fa, fb): (Vec<&str>, Vec<&str>) = (a.split(',').collect(), b.split(',').collect());
        assert_eq!(fa[..3], fb[..3], "member, status, t_reached");
        if fa[1] == "completed" {
            let (x, y): (f64, f64) = (fa[3].parse().unwrap(), fb[3].parse().unwrap());
            worst = worst.max((x - y).abs() / x.abs());
            // Measured ≤ 1.1e-14.
            assert!((x - y).abs() <= 1e-13 * x.abs(), "final_total {x} vs {y}");
        }
    }
    println!("GPU shard vs CPU: final energy {worst:.1e}");
}

/// `--shard I/N` takes at most one shard per member: a larger N is refused (exit 2, naming
/// `--shard` and the member count) before anything is written; `sweep merge` of shard
/// files whose names claim a huge N refuses at once with a short message, and names the
/// missing shards of a real split compactly (the first few and a count).
#[test]
fn shard_counts_are_bounded_by_the_members_and_merge_stays_small() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    for n in ["18446744073709551615", "1000000000", "8"] {
        let out = dir.path().join(format!("cli-{n}"));
        let o = cosserat()
            .arg("sweep")
            .arg(&file)
            .arg("--out")
            .arg(&out)
            .args(["--shard", &format!("0/{n}")])
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{n}: {t}");
        assert!(
            t.contains(&format!("s.toml: --shard: 0/{n}: {n} shards for 7 members")),
            "{n}: {t}"
        );
        assert!(
            !out.exists(),
            "{n}: the refused shard wrote {}",
            out.display()
        );
    }
    // The library refuses it too.
    let e = run_err(
        &file,
        &dir.path().join("lib"),
        SweepOptions {
            shard: shard(3, 8),
            ..Default::default()
        },
    );
    assert!(e.contains("--shard: 3/8: 8 shards for 7 members"), "{e}");

    // Shard files named with a huge N (one real shard's files, renamed).
    let good = dir.path().join("good");
    run(&file, &good, shard(0, 3), false);
    for n in ["18446744073709551615", "10000000"] {
        let d = dir.path().join(format!("forged-{n}"));
        std::fs::create_dir_all(d.join("shards")).unwrap();
        for ext in ["csv", "id"] {
            std::fs::copy(
                good.join(format!("shards/0-of-3.{ext}")),
                d.join(format!("shards/0-of-{n}.{ext}")),
            )
            .unwrap();
        }
        let o = cosserat()
            .args(["sweep", "merge"])
            .arg(&d)
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{n}: {}",
            t.chars().take(2000).collect::<String>()
        );
        assert!(t.len() < 2000, "{n}: a {} byte message", t.len());
        assert!(
            t.contains(&format!(
                "split the sweep into {n} shards, but it has 7 members"
            )),
            "{n}: {t}"
        );
        assert!(!d.join("members.csv").exists());
    }

    // A real split with most shards missing: the first few are named, the rest counted.
    let many = "base = \"frame\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.5]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2, 2.4, 2.6, 2.8, 3.0, 3.2, 3.4, 3.6, 3.8, 4.0]\n";
    let many = write(dir.path(), "many.toml", many);
    let d = dir.path().join("sparse");
    run(&many, &d, shard(0, 40), false);
    let e = merge_err(&d);
    assert!(
        e.contains("1-of-40.id: shard 1-of-40: missing")
            && e.contains(
                "39 of 40 shards are missing: 1-of-40, 2-of-40, 3-of-40, 4-of-40, 5-of-40, …;"
            ),
        "{e}"
    );
    assert!(!e.contains("6-of-40"), "{e}");
}

/// Every shard file carries the sweep's identity and its own shard: merge refuses (naming
/// the file, writing nothing) a rows file of another sweep under this sweep's identity
/// file, a row whose values are not that member's, an identity file of another shard, and
/// a record of another sweep; a folder merged from its shards resumes as the one-process
/// sweep's.
#[test]
fn merge_checks_every_shard_file_and_row_against_the_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "s.toml", SWEEP);
    let other = write(dir.path(), "o.toml", OTHER);
    let good = dir.path().join("good");
    for i in 0..3 {
        run(&file, &good, shard(i, 3), false);
    }
    let first = std::fs::read_to_string(good.join("shards/1-of-3.csv")).unwrap();
    let id = std::fs::read_to_string(good.join("shards/1-of-3.id")).unwrap();
    let id = id.lines().next().unwrap().strip_prefix("id ").unwrap();
    assert!(
        first.starts_with(&format!("# cosserat sweep {id} shard 1/3\nmember,status,")),
        "{first}"
    );
    let foreign = dir.path().join("foreign");
    run(&other, &foreign, shard(1, 3), false);
    let case = |name: &str, edit: &dyn Fn(&Path)| -> String {
        let d = dir.path().join(name);
        copy_dir(&good, &d);
        edit(&d.join("shards"));
        merge_err(&d)
    };

    // Another sweep's rows under this sweep's identity file.
    let e = case("foreign-rows", &|s| {
        std::fs::copy(foreign.join("shards/1-of-3.csv"), s.join("1-of-3.csv")).unwrap();
    });
    assert!(
        e.contains("1-of-3.csv: shard 1-of-3: foreign: its first line"),
        "{e}"
    );
    // The same rows with this sweep's identity line: the values give them away.
    let e = case("foreign-values", &|s| {
        let theirs = std::fs::read_to_string(foreign.join("shards/1-of-3.csv")).unwrap();
        let ours = std::fs::read_to_string(s.join("1-of-3.csv")).unwrap();
        let tag = ours.lines().next().unwrap();
        let rest: Vec<&str> = theirs.lines().skip(1).collect();
        std::fs::write(
            s.join("1-of-3.csv"),
            format!("{tag}\n{}\n", rest.join("\n")),
        )
        .unwrap();
    });
    assert!(
        e.contains("1-of-3.csv: shard 1-of-3: line 3: member ")
            && e.contains("has integrator.alpha = ")
            && e.contains("in this sweep: the row is another sweep's result"),
        "{e}"
    );
    // Another shard's files under this shard's name.
    let e = case("renamed", &|s| {
        std::fs::copy(s.join("0-of-3.id"), s.join("1-of-3.id")).unwrap();
    });
    assert!(
        e.contains("1-of-3.id: shard 1-of-3: foreign: it records shard `0/3`, not 1/3"),
        "{e}"
    );
    let e = case("renamed-rows", &|s| {
        std::fs::copy(s.join("0-of-3.csv"), s.join("2-of-3.csv")).unwrap();
    });
    assert!(
        e.contains("2-of-3.csv: shard 2-of-3: foreign: its first line"),
        "{e}"
    );
    let e = case("foreign-record", &|s| {
        std::fs::copy(foreign.join("shards/1-of-3.json"), s.join("1-of-3.json")).unwrap();
    });
    assert!(
        e.contains("1-of-3.json: shard 1-of-3: foreign: it records sweep id"),
        "{e}"
    );

    // The merged folder resumes cleanly, and merge writes what the one-process sweep has.
    let m = merge_shards(&good).unwrap();
    assert_eq!(m.members, 7);
    let s = run(&file, &good, None, true);
    assert_eq!((s.skipped, s.completed + s.failed + s.rejected), (7, 0));
}
