//! A sweep killed (SIGKILL) at random moments and resumed each time ends with every
//! member recorded exactly once, with the values of an uninterrupted run, and with a
//! complete `member_<i>/history.csv` for every recorded member (a member is recorded only
//! after its history is written).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::member_rows as rows;

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

/// The moments a sweep is killed at: events in its folder, never wall-clock windows, so
/// the test means the same on a loaded machine.
#[derive(Clone, Copy, Debug)]
enum Event {
    /// `members.csv` has appeared (its header renamed into place; no member recorded yet
    /// on a fresh sweep).
    Header,
    /// A member's history is being written (`member_<i>/history.csv.tmp` exists).
    HistoryInFlight,
    /// `members.csv` has gained this many complete rows since the process started.
    Rows(usize),
}

/// Complete rows in `members.csv` (0 while it is missing).
fn complete_rows(out: &Path) -> usize {
    std::fs::read_to_string(out.join("members.csv"))
        .map(|csv| csv.matches('\n').count().saturating_sub(1))
        .unwrap_or(0)
}

fn history_in_flight(out: &Path) -> bool {
    std::fs::read_dir(out)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| e.path().is_dir() && e.path().join("history.csv.tmp").exists())
}

#[test]
fn killed_sweeps_resume_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s.toml");
    std::fs::write(&file, SWEEP).unwrap();
    let reference = dir.path().join("ref");
    assert!(sweep(&file, &reference, false).status().unwrap().success());
    let want = rows(&reference);
    assert_eq!(want.len(), 12);

    let out = dir.path().join("killed");
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let mut kills = 0;
    let mut resume = false;
    // A hang detector only: the events below decide when to kill.
    let deadline = Instant::now() + Duration::from_secs(900);
    loop {
        // The first kill is at the header of the fresh sweep (before any member is
        // recorded); later ones at a history in flight or after a few more rows.
        let event = match (kills, rng.next() % 3) {
            (0, _) => Event::Header,
            (_, 0) => Event::HistoryInFlight,
            (_, k) => Event::Rows(k as usize),
        };
        let before = complete_rows(&out);
        let mut child = sweep(&file, &out, resume).spawn().unwrap();
        resume = true;
        let finished = loop {
            if let Some(status) = child.try_wait().unwrap() {
                assert!(status.success());
                break true;
            }
            let seen = match event {
                Event::Header => out.join("members.csv").exists(),
                Event::HistoryInFlight => history_in_flight(&out),
                Event::Rows(k) => complete_rows(&out) >= before + k,
            };
            if seen {
                break false;
            }
            assert!(Instant::now() < deadline, "the sweep hangs ({event:?})");
            std::thread::sleep(Duration::from_millis(1));
        };
        if finished {
            break;
        }
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        kills += 1;
        check_interrupted(&out);
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
