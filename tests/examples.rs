//! The shipped example sweep files (`examples/sweeps/*.toml`, used in docs/cli.md and
//! docs/gpu.md) run as documented: every member they declare is recorded once, a failed
//! member names its reason, and every completed member of the free-flying frame keeps its
//! momenta to round-off.

use std::path::Path;
use std::process::Command;

/// Runs `cosserat sweep FILE --out DIR` and returns members.csv as header + rows.
fn sweep(file: &Path, out: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .arg("sweep")
        .arg(file)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run cosserat sweep");
    assert!(
        o.status.success(),
        "{}: exit {:?}\n{}",
        file.display(),
        o.status.code(),
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(out.join("members.csv")).expect("members.csv");
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_string)
        .collect();
    // The reason is the last column and may contain commas inside its quotes.
    let rows = lines
        .map(|l| {
            let (head, reason) = match l.find('"') {
                Some(i) => (&l[..i], l[i..].trim_matches('"').to_string()),
                None => (l, String::new()),
            };
            let mut cells: Vec<String> = head
                .trim_end_matches(',')
                .split(',')
                .map(str::to_string)
                .collect();
            cells.push(reason);
            cells
        })
        .collect();
    (header, rows)
}

#[test]
fn example_sweeps_record_every_member_once() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/sweeps");
    // (file, members it declares: grid 4 × 3, random 64 samples)
    for (name, members) in [("frame_alpha.toml", 12), ("frame_random.toml", 64)] {
        let out = tempfile::tempdir().unwrap();
        let (header, rows) = sweep(&dir.join(name), &out.path().join("o"));
        let col = |k: &str| {
            header
                .iter()
                .position(|h| h == k)
                .unwrap_or_else(|| panic!("{name}: no column {k} in {header:?}"))
        };
        let (member, status, reason) = (col("member"), col("status"), col("reason"));
        let (dl, dj) = (col("max_rel_dL"), col("max_rel_dJ"));
        assert_eq!(rows.len(), members, "{name}: rows");
        let mut seen: Vec<usize> = rows.iter().map(|r| r[member].parse().unwrap()).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..members).collect::<Vec<_>>(), "{name}: members");
        let mut completed = 0;
        for r in &rows {
            match r[status].as_str() {
                "completed" => {
                    completed += 1;
                    // Free flight: L and J conserved to round-off (measured ≤ 3.4e-15 over both files).
                    for c in [dl, dj] {
                        let v: f64 = r[c].parse().unwrap();
                        assert!(
                            v <= 1e-14,
                            "{name} member {}: {} = {v}",
                            r[member],
                            header[c]
                        );
                    }
                }
                "failed" => assert!(
                    !r[reason].is_empty(),
                    "{name} member {}: failed without a reason",
                    r[member]
                ),
                s => panic!("{name} member {}: status {s}", r[member]),
            }
        }
        assert!(
            completed * 2 > members,
            "{name}: {completed} of {members} completed"
        );
    }
}

/// docs/cli.md's table of built-in scenes is the binary's `cosserat scenes` list, row for
/// row, so that the docs cannot drift from the binary.
#[test]
fn cli_docs_list_every_builtin_scene() {
    let o = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .arg("scenes")
        .output()
        .expect("run cosserat scenes");
    assert!(o.status.success());
    let listed: Vec<(String, String)> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let (name, what) = l.split_once(' ').expect("name and description");
            (name.to_string(), what.trim().to_string())
        })
        .collect();
    assert!(listed.len() >= 10, "{listed:?}");
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/cli.md")).unwrap();
    let section = doc
        .split("## `cosserat scenes`")
        .nth(1)
        .and_then(|s| s.split("\n## ").next())
        .expect("docs/cli.md has a `cosserat scenes` section");
    let documented: Vec<(String, String)> = section
        .lines()
        .filter_map(|l| {
            let l = l.strip_prefix("| `")?;
            let (name, rest) = l.split_once("` | ")?;
            Some((name.to_string(), rest.trim_end_matches(" |").to_string()))
        })
        .collect();
    assert_eq!(
        documented, listed,
        "docs/cli.md's scene table differs from `cosserat scenes`"
    );
}
