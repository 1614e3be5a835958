//! Every resource is sized before it is allocated: scenes, runs, sweeps, benches and studies
//! near and beyond each limit (elements, contact spheres, output frames, members, the memory
//! estimate) either run or exit 2 naming the key or option and the figure — under a 4 GiB
//! address-space limit (`ulimit -v`), so an allocation that escaped the estimate aborts the
//! case (exit 134) instead of passing, and within a watchdog that fails a hang.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use cosserat::scene::limits::{self, Footprint};
use proptest::prelude::*;

mod common;

/// The address-space limit every case runs under.
const AS_LIMIT: u64 = 4 << 30;

/// The binary under `ulimit -v 4G`, killed (and the case failed) after 120 s.
fn run_bounded(args: &[&str], env: &[(&str, &str)], dir: &Path) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    c.args(args).current_dir(dir).env_remove(limits::MEMORY_ENV);
    for (k, v) in env {
        c.env(k, v);
    }
    common::run_limited(c, Some(AS_LIMIT), Duration::from_secs(120))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A straight clamped rod of `n` elements and section area `a`, optionally in contact with
/// itself at `radius` (`None`: the default radius √(A/π)).
fn rod_scene(n: u64, a: f64, contact: Option<Option<f64>>) -> String {
    let mut s = format!(
        "name = \"rod\"\n[material.m]\nE = 1e6\nnu = 0.5\ndensity = 1000\n\n[section.s]\nA = {a:e}\nI11 = 1e-8\nI22 = 1e-8\nJ = 2e-8\n\n[[rod]]\nname = \"rod\"\nmaterial = \"m\"\nsection = \"s\"\npoints = [[0, 0, 0], [1, 0, 0]]\nelements = {n}\nd1 = [0, 1, 0]\n\n[[clamp]]\nat = [0, 0, 0]\n\n[integrator]\nscheme = \"em\"\ndt = 0.01\nt_end = 0.01\n"
    );
    match contact {
        None => {}
        Some(None) => s.push_str("\n[[contact]]\nrods = [\"rod\"]\n"),
        Some(Some(r)) => s.push_str(&format!(
            "\n[[contact]]\nrods = [\"rod\"]\ncontact_radius = {r:e}\n"
        )),
    }
    s
}

fn assert_refused(o: &Output, needle: &str, what: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert!(err.contains(needle), "{what}: `{needle}` not in {err}");
    assert_eq!(err.lines().count(), 1, "{what}: one line: {err}");
}

/// The audit's cases: a contact radius of 1e-9, 5e-324 or 1e-6 (2 000 042 spheres), and a
/// valid section of A = 1e-20 (its default radius √(A/π) ≈ 5.6e-11), used to allocate until
/// the machine ran out; a 10⁶-element rod (the element limit) needs 12 GB and aborted
/// `check` under a 4 GiB limit. All are refused at once, by `check` and `run` alike.
#[test]
fn contact_chains_and_huge_rods_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(String, &str)> = vec![
        (rod_scene(100, 1e-4, Some(Some(1e-9))), "contact_radius"),
        (rod_scene(100, 1e-4, Some(Some(5e-324))), "contact_radius"),
        (rod_scene(100, 1e-4, Some(Some(1e-6))), "1000001 spheres"),
        (rod_scene(100, 1e-20, Some(None)), "√(A/π)"),
        (
            rod_scene(100, 1e-4, Some(Some(10.0))),
            "within one contact diameter",
        ),
        (
            rod_scene(1_000_000, 1e-4, None),
            "half of the address-space limit",
        ),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        let f = dir.path().join(format!("s{i}.toml"));
        std::fs::write(&f, text).unwrap();
        for cmd in ["check", "run"] {
            let o = run_bounded(
                &[cmd, f.to_str().unwrap(), "--out", "o"][..if cmd == "check" { 2 } else { 4 }],
                &[],
                dir.path(),
            );
            assert_refused(&o, needle, &format!("{cmd} case {i}"));
            assert!(stderr(&o).contains(&format!("s{i}.toml")), "{}", stderr(&o));
        }
    }
    assert!(
        !dir.path().join("o").exists(),
        "a refused run wrote its folder"
    );
}

/// Output frames held until the end of a run (trajectory, snapshots) are sized too: a
/// trajectory of 10⁹ frames is refused naming the options, before the folder is made.
#[test]
fn output_frames_are_sized_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (
            vec![
                "--trajectory",
                "--output-dt",
                "1e-6",
                "--dt",
                "1e-6",
                "--t-end",
                "1000",
            ],
            "--trajectory/--output-dt/--times: this run would need",
        ),
        (
            vec!["--snapshots", "1", "--dt", "1e-5", "--t-end", "1000"],
            "--snapshots/--animate-every: this run would need",
        ),
    ] {
        let mut a = vec!["run", "frame", "--out", "o"];
        a.extend(args);
        let o = run_bounded(&a, &[], dir.path());
        assert_refused(&o, needle, &format!("{a:?}"));
    }
    assert!(!dir.path().join("o").exists());
}

/// `COSSERAT_MAX_MEMORY` applies to `check` and `run` as it does to sweeps, and the
/// default follows the address-space limit.
#[test]
fn the_memory_limit_applies_to_single_runs_and_follows_ulimit() {
    let (limit, why) = {
        // What a child under ulimit -v 4G gets: half of it.
        (AS_LIMIT / 2, "half of the address-space limit")
    };
    assert!(limit < limits::DEFAULT_MAX_MEMORY);
    let dir = tempfile::tempdir().unwrap();
    // 200 000 elements ≈ 2.2 GiB: above half of 4 GiB, far below the element limit.
    std::fs::write(dir.path().join("big.toml"), rod_scene(200_000, 1e-4, None)).unwrap();
    let o = run_bounded(&["check", "big.toml"], &[], dir.path());
    assert_refused(&o, why, "200k elements under ulimit -v 4G");
    let o = run_bounded(
        &["check", "big.toml"],
        &[(limits::MEMORY_ENV, "1G")],
        dir.path(),
    );
    assert_refused(&o, "COSSERAT_MAX_MEMORY=1G", "200k elements, 1G");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, failure_persistence: None, ..ProptestConfig::default() })]

    /// Near the memory limit (made small with `COSSERAT_MAX_MEMORY` so that accepted cases
    /// are cheap), `check` accepts exactly the scenes whose estimate fits and refuses the
    /// others naming the key, the figure and the limit; never an abort.
    #[test]
    fn check_accepts_exactly_what_the_estimate_fits(
        n in 500u64..4000,
        spheres_per_element in 0u64..6,
        limit_mb in 8u64..48,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let h = 1.0 / n as f64;
        // `spheres_per_element` spheres per element (0: no contact); a radius a little
        // above h/k gives k per element.
        let (text, fp) = if spheres_per_element == 0 {
            (rod_scene(n, 1e-4, None), Footprint::elements(n))
        } else {
            let r = h / spheres_per_element as f64 * (1.0 + 1e-6);
            (
                rod_scene(n, 1e-4, Some(Some(r))),
                Footprint {
                    contact_spheres: n * spheres_per_element + 1,
                    ..Footprint::elements(n)
                },
            )
        };
        std::fs::write(dir.path().join("s.toml"), &text).unwrap();
        let env = format!("{limit_mb}M");
        let o = run_bounded(&["check", "s.toml"], &[(limits::MEMORY_ENV, &env)], dir.path());
        let fits = limits::estimate_batch(1, &fp) <= limit_mb << 20;
        if fits {
            prop_assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        } else {
            let err = stderr(&o);
            prop_assert_eq!(o.status.code(), Some(2), "{}", err);
            // The elements are sized before meshing, the contact chains once they are counted.
            let by_elements = limits::estimate_batch(1, &Footprint::elements(n)) > limit_mb << 20;
            let key = if by_elements { ": rod: " } else { ": contact: " };
            prop_assert!(err.contains(key) && err.contains(&env) && err.contains("would need about"), "{}", err);
        }
    }

    /// Sweeps and benches are sized by the same estimate (members × footprint): beyond it,
    /// exit 2 naming the limit, before any member runs or any file is written.
    #[test]
    fn benches_beyond_the_estimate_are_refused(
        rods in 1u64..5000,
        elements in 1u64..200,
        limit_mb in 4u64..64,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let env = format!("{limit_mb}M");
        let fits = limits::estimate(rods, elements) <= limit_mb << 20;
        prop_assume!(!fits);
        let o = run_bounded(
            &["bench", "--rods", &rods.to_string(), "--elements", &elements.to_string(), "--steps", "1"],
            &[(limits::MEMORY_ENV, &env)],
            dir.path(),
        );
        prop_assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        prop_assert!(stderr(&o).contains(&env), "{}", stderr(&o));
    }
}
