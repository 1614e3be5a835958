//! A sweep killed (SIGKILL) at random moments and resumed each time ends with every
//! member recorded exactly once, with the values of an uninterrupted run, and with a
//! complete `member_<i>/history.csv` for every recorded member (a member is recorded only
//! after its history is written).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const SWEEP: &str = "base = \"frame\"\nmode = \"random\"\nseed = 11\nsamples = 12\n\n[[vary]]\nkey = \"integrator.alpha\"\nrange = [0.0, 1.0]\n\n[[vary]]\nkey = \"integrator.t_end\"\nrange = [4.0, 12.0]\n";

fn sweep(file: &Path, out: &Path, resume: bool) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    c.arg("sweep")
        .arg(file)
        .arg("--out")
        .arg(out)
        .arg("--histories")
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    if resume {
        c.arg("--resume");
    }
    c
}

/// members.csv rows by member, without the wall time (column 7).
fn rows(out: &Path) -> Vec<(usize, String)> {
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let mut v: Vec<(usize, String)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(7);
            (f[0].parse().unwrap(), f.join(","))
        })
        .collect();
    v.sort();
    v
}

/// A small seeded generator (xorshift) for the kill times: the test repeats exactly.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// What a killed sweep leaves: every complete row names a distinct member whose history
/// file is complete (its last row is at the row's `t_reached`); at most the last line is
/// partial.
fn check_interrupted(out: &Path) {
    let Ok(csv) = std::fs::read_to_string(out.join("members.csv")) else {
        return; // killed before the header was renamed into place
    };
    let complete = &csv[..csv.rfind('\n').map_or(0, |i| i + 1)];
    let mut seen = std::collections::HashSet::new();
    for l in complete.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        let i: usize = f[0].parse().unwrap();
        assert!(seen.insert(i), "member {i} recorded twice");
        let h = std::fs::read_to_string(out.join(format!("member_{i}/history.csv")))
            .unwrap_or_else(|e| panic!("member {i} recorded without its history: {e}"));
        let last_t: f64 = h
            .lines()
            .last()
            .unwrap()
            .split(',')
            .nth(1)
            .unwrap()
            .parse()
            .unwrap();
        let t_reached: f64 = f[2].parse().unwrap();
        assert_eq!(last_t, t_reached, "member {i}'s history is incomplete");
    }
}

#[test]
fn killed_sweeps_resume_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s.toml");
    std::fs::write(&file, SWEEP).unwrap();
    let reference = dir.path().join("ref");
    let t0 = Instant::now();
    assert!(sweep(&file, &reference, false).status().unwrap().success());
    let full_time = t0.elapsed();
    let want = rows(&reference);
    assert_eq!(want.len(), 12);

    let out = dir.path().join("killed");
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let mut kills = 0;
    let mut resume = false;
    let start = Instant::now();
    loop {
        let mut child = sweep(&file, &out, resume).spawn().unwrap();
        resume = true;
        // Kill anywhere from at once to well into the run.
        let frac = (rng.next() % 1000) as f64 / 1000.0;
        let wait = full_time.mul_f64(0.6 * frac);
        std::thread::sleep(wait);
        match child.try_wait().unwrap() {
            Some(status) => {
                assert!(status.success());
                break;
            }
            None => {
                child.kill().unwrap(); // SIGKILL
                child.wait().unwrap();
                kills += 1;
                check_interrupted(&out);
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(50),
            "no run finished after {kills} kills"
        );
        if kills >= 8 {
            // Enough interruptions: let the last one finish.
            assert!(sweep(&file, &out, true).status().unwrap().success());
            break;
        }
    }
    assert!(kills >= 1, "the sweep was never killed");
    eprintln!("{kills} kills");
    let got = rows(&out);
    assert_eq!(got, want, "after {kills} kills");
    for (i, _) in &got {
        let a = std::fs::read_to_string(reference.join(format!("member_{i}/history.csv"))).unwrap();
        let b = std::fs::read_to_string(out.join(format!("member_{i}/history.csv"))).unwrap();
        assert_eq!(a, b, "member {i}'s history");
        assert!(!out.join(format!("member_{i}/history.csv.tmp")).exists());
    }
}
