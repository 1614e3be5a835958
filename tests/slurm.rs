//! Sharded sweeps on a real Slurm (slurmctld + slurmd; `.ci/run` starts a one-node
//! cluster with `.ci/slurm-single-node.sh`): `cosserat sweep slurm --shards 4 --submit
//! --wait` runs a 4-task job array and merges it into the `members.csv` of the same sweep
//! run in one process (every value but the wall time equal, rows in member order); a task
//! killed mid-run (`scancel`) leaves a shard that `sweep merge` refuses by name, and
//! resubmitting only that shard (`sbatch --array=K`) resumes it (its recorded members are
//! skipped) and merges to the same result.
//!
//! Skipped, saying so, when `sbatch` is absent or no cluster answers — unless
//! `COSSERAT_REQUIRE_SLURM=1` (CI), which turns either into a failure.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use cosserat::sweep::slurm;

/// 16 members of the free-flying frame (100 steps each, a fraction of a second).
const SWEEP: &str = "base = \"frame\"\nmode = \"grid\"\n\n[[vary]]\nkey = \"integrator.alpha\"\nvalues = [0.0, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5]\n\n[[vary]]\nkey = \"integrator.t_end\"\nvalues = [16.0, 20.0]\n";

fn required() -> bool {
    std::env::var("COSSERAT_REQUIRE_SLURM").is_ok_and(|v| v == "1")
}

/// Whether a Slurm cluster answers here; prints why not (or panics when it is required).
fn slurm_here() -> bool {
    let why = match Command::new("sbatch").arg("--version").output() {
        Err(e) => format!("no `sbatch` ({e})"),
        Ok(o) if !o.status.success() => format!(
            "sbatch is installed but does not run, no cluster configured? ({})",
            text(&o).trim()
        ),
        Ok(_) => match Command::new("sinfo").args(["-h", "-o", "%t"]).output() {
            Ok(o) if o.status.success() && !o.stdout.is_empty() => return true,
            Ok(o) => format!(
                "sbatch is installed but no cluster answers (sinfo: {})",
                text(&o)
            ),
            Err(e) => format!("sbatch is installed but not sinfo ({e})"),
        },
    };
    if required() {
        panic!("COSSERAT_REQUIRE_SLURM=1 but {why}; start one with .ci/slurm-single-node.sh");
    }
    println!("skipped: {why} (set COSSERAT_REQUIRE_SLURM=1 to make this a failure)");
    false
}

fn cosserat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A folder the cluster's tasks can write (the test runs on the cluster's only node).
fn workdir() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("cosserat-slurm-")
        .tempdir()
        .unwrap()
}

/// members.csv rows without the wall time (column 7), in file order.
fn rows(csv: &Path) -> Vec<String> {
    std::fs::read_to_string(csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(7);
            f.join(",")
        })
        .collect()
}

fn by_member(mut v: Vec<String>) -> Vec<String> {
    v.sort_by_key(|l| l.split(',').next().unwrap().parse::<usize>().unwrap());
    v
}

/// The sweep run in one process (the reference), its wall time.
fn one_process(file: &Path, out: &Path) -> f64 {
    let t = Instant::now();
    let o = cosserat()
        .arg("sweep")
        .arg(file)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    t.elapsed().as_secs_f64()
}

/// `sweep slurm --shards n --submit --wait`: its wall time and output.
fn array(file: &Path, out: &Path, n: usize) -> (f64, String) {
    let t = Instant::now();
    let o = cosserat()
        .args(["sweep", "slurm"])
        .arg(file)
        .args(["--shards", &n.to_string(), "--wait", "--out"])
        .arg(out)
        .output()
        .unwrap();
    let wall = t.elapsed().as_secs_f64();
    assert!(o.status.success(), "{}", text(&o));
    (wall, text(&o))
}

/// Rows recorded so far in each shard's file (complete lines after the identity line and
/// the header).
fn recorded(out: &Path, n: usize) -> Vec<usize> {
    (0..n)
        .map(|i| {
            std::fs::read_to_string(out.join(format!("shards/{i}-of-{n}.csv")))
                .map(|t| t.matches('\n').count().saturating_sub(2))
                .unwrap_or(0)
        })
        .collect()
}

#[test]
fn a_job_array_merges_to_the_one_process_sweep_and_a_killed_task_resumes() {
    if !slurm_here() {
        return;
    }
    let dir = workdir();
    let file = dir.path().join("s.toml");
    std::fs::write(&file, SWEEP).unwrap();
    let reference = dir.path().join("ref");
    let t_one = one_process(&file, &reference);
    let want = by_member(rows(&reference.join("members.csv")));
    assert_eq!(want.len(), 16);

    // 1. The whole array, submitted, waited for and merged by one command.
    let out = dir.path().join("array");
    let (t_array, said) = array(&file, &out, 4);
    assert!(said.contains("merged 4 shards"), "{said}");
    assert_eq!(rows(&out.join("members.csv")), want, "{said}");
    for i in 0..4 {
        let log = std::fs::read_to_string(out.join(format!("logs/shard-{i}.log"))).unwrap();
        assert!(log.contains(&format!("shard {i}/4: job")), "{log}");
    }
    println!(
        "array of 4 shards, 16 members: {t_array:.1} s from submission to merged ({:.2} members/s); one process: {t_one:.1} s ({:.2} members/s)",
        16.0 / t_array,
        16.0 / t_one
    );

    // 2. One task killed mid-run.
    let out = dir.path().join("killed");
    let o = cosserat()
        .args(["sweep", "slurm"])
        .arg(&file)
        .args(["--shards", "4", "--submit", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let said = text(&o);
    let job = said
        .lines()
        .find_map(|l| l.strip_prefix("submitted job "))
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("no job id in {said}"))
        .to_string();
    // The first shard seen with some but not all of its 4 members recorded.
    let start = Instant::now();
    let victim = loop {
        if let Some(k) = recorded(&out, 4).iter().position(|&r| (1..4).contains(&r)) {
            break k;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no shard was seen mid-run: {:?}",
            recorded(&out, 4)
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let o = Command::new("scancel")
        .arg(format!("{job}_{victim}"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let ends = slurm::wait(&job, |_| {}).unwrap();
    let before = recorded(&out, 4)[victim];
    assert!(
        before < 4,
        "shard {victim} finished before it was cancelled"
    );
    let state = |k: usize| ends.iter().find(|t| t.task == k).map(|t| t.state.clone());
    assert_eq!(state(victim).as_deref(), Some("CANCELLED"), "{ends:?}");
    for k in (0..4).filter(|&k| k != victim) {
        assert_eq!(state(k).as_deref(), Some("COMPLETED"), "{ends:?}");
    }
    // Merge refuses, naming the shard and how to resume it.
    let o = cosserat()
        .args(["sweep", "merge"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let e = text(&o);
    assert!(e.contains(&format!("shard {victim}-of-4: ")), "{e}");
    assert!(e.contains("incomplete") || e.contains("torn"), "{e}");
    assert!(e.contains(&format!("sbatch --array={victim} ")), "{e}");
    assert!(!out.join("members.csv").exists());
    // Resubmit that shard only: it resumes, and the merge is the one-process result.
    let script: PathBuf = out.join(slurm::SCRIPT_FILE);
    let again = slurm::submit(&script, &[&format!("--array={victim}")]).unwrap();
    let ends = slurm::wait(&again, |_| {}).unwrap();
    assert!(
        ends.iter()
            .all(|t| t.state == "COMPLETED" && t.exit_code == "0:0"),
        "{ends:?}"
    );
    let log = std::fs::read_to_string(out.join(format!("logs/shard-{victim}.log"))).unwrap();
    let skipped: usize = log
        .lines()
        .filter(|l| l.contains(" skipped (already recorded)"))
        .filter_map(|l| {
            l.split(" skipped (")
                .next()?
                .rsplit(", ")
                .next()?
                .parse()
                .ok()
        })
        .next_back()
        .unwrap_or_else(|| panic!("no summary line in\n{log}"));
    assert!(
        skipped >= 1 && skipped <= before,
        "the resubmitted shard skipped {skipped} of the {before} members recorded before the kill:\n{log}"
    );
    let o = cosserat()
        .args(["sweep", "merge"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(rows(&out.join("members.csv")), want);
    println!(
        "killed shard {victim} after {before} of 4 members; resubmitted, it skipped {skipped} and merged to the one-process result"
    );
}

/// Members per second against the number of shards (docs/cluster.md). Run with
/// `cargo test --test slurm -- --ignored --nocapture` on a cluster.
#[test]
#[ignore]
fn sharding_throughput_against_n() {
    if !slurm_here() {
        return;
    }
    let dir = workdir();
    let file = dir.path().join("s.toml");
    let big = SWEEP.replace("values = [16.0, 20.0]", "values = [16.0, 20.0, 24.0, 28.0]");
    std::fs::write(&file, big).unwrap();
    let t = one_process(&file, &dir.path().join("ref"));
    println!(
        "one process (all cores): 32 members in {t:.1} s, {:.2} members/s",
        32.0 / t
    );
    for n in [1, 2, 4, 8] {
        let (t, _) = array(&file, &dir.path().join(format!("n{n}")), n);
        println!("N = {n}: 32 members in {t:.1} s, {:.2} members/s", 32.0 / t);
    }
}
