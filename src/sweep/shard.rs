//! Sharded sweeps: one sweep split into N shards that run anywhere (other machines, Slurm
//! array tasks) and are merged back into the `members.csv` of a one-machine run.
//!
//! Shard I of N runs the members whose index is ≡ I mod N (round-robin, so that members
//! whose cost grows along a grid axis — a smaller Δt, a longer `t_end` — spread over all
//! shards). Each shard writes only its own files, so shards never write the same file:
//!
//! ```text
//! DIR/shards/I-of-N.csv    its identity line (`# cosserat sweep ID shard I/N`), then
//!                          members.csv's header and rows, appended as members finish
//! DIR/shards/I-of-N.id     its identity: the sweep's (`sweep.id`) plus `shard I/N`
//! DIR/shards/I-of-N.json   what its last invocation did (backend, counts, wall time)
//! DIR/shards/I-of-N.lock   held while it runs
//! DIR/member_<i>/          its members' histories (`--histories`), as unsharded
//! ```
//!
//! N is at most the number of members. [`merge_shards`] checks that every shard is
//! present, of this sweep (every file's identity and I/N, every row's values against the
//! sweep file), not torn and complete, and that no member is missing or twice, then
//! writes `DIR/members.csv` (rows in member order), `DIR/sweep.id` and `DIR/sweep.json`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use super::run::{
    check_row, header_of, run_identity, split_csv, try_lock_file, write_atomic, MemberStatus,
};
use super::{load_sweep, SweepError, SweepOptions, SweepSpec, IDENTITY_FILE, LOCK_FILE};

pub use super::split::{check_count, file, Shard, SHARDS_DIR};
use super::split::{check_ids, tag, IdFile};

/// Checks that `out` can take `count` shards of `spec` run with `opts`: the shards
/// already there (if any) are of this sweep, with these overrides, split into `count`
/// (what `cosserat sweep slurm` checks before writing its job script).
pub fn check_shard_folder(
    out: &Path,
    spec: &SweepSpec,
    opts: &SweepOptions,
    count: usize,
) -> Result<(), SweepError> {
    check_ids(out, &run_identity(spec, opts), count, None)
}

/// What [`merge_shards`] wrote.
#[derive(Clone, Debug, Default)]
pub struct MergeSummary {
    /// Members of the sweep (rows of the merged `members.csv`).
    pub members: usize,
    /// Rows with status `completed`.
    pub completed: usize,
    /// Rows with status `failed`.
    pub failed: usize,
    /// Rows with status `rejected`.
    pub rejected: usize,
    /// Number of shards merged.
    pub shards: usize,
    /// The sweep file the shards were run from (as they recorded it).
    pub sweep: String,
    /// The distinct backends of the shards' last invocations.
    pub backends: Vec<String>,
}

/// How to finish one shard, for error messages.
fn resume_hint(out: &Path, sweep: &str, sh: Shard) -> String {
    let script = out.join(super::slurm::SCRIPT_FILE);
    let slurm = if script.exists() {
        format!(
            "`sbatch --array={} {}` (Slurm), or ",
            sh.index,
            script.display()
        )
    } else {
        String::new()
    };
    format!(
        "resume it: {slurm}`cosserat sweep {sweep} --shard {sh} --out {} --resume` with the shard's other options",
        out.display()
    )
}

/// Names the shards of `out/shards` whose lock is held by a running process.
fn running_shards(out: &Path) -> Vec<(Shard, PathBuf)> {
    let mut running = Vec::new();
    let Ok(entries) = std::fs::read_dir(out.join(SHARDS_DIR)) else {
        return running;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        if let Some((sh, "lock")) = Shard::from_file_name(&name.to_string_lossy()) {
            let busy = std::fs::OpenOptions::new()
                .write(true)
                .open(e.path())
                .is_ok_and(|f| matches!(f.try_lock(), Err(std::fs::TryLockError::WouldBlock)));
            if busy {
                running.push((sh, e.path()));
            }
        }
    }
    running.sort();
    running
}

/// Merges the shards in `out/shards` into `out/members.csv`, `out/sweep.id` and
/// `out/sweep.json`, as a one-machine run of the sweep writes them (rows in member order,
/// each row as its shard recorded it). The sweep file is the one the shards recorded
/// (`sweep` in their identity files); [`merge_shards_from`] names another path to it.
pub fn merge_shards(out: &Path) -> Result<MergeSummary, SweepError> {
    merge_shards_from(out, None)
}

/// Tries, 10 ms apart, to take the folder's lock before merge says a shard still runs.
const LOCK_GRACE_TRIES: usize = 30;

/// At most this many shards are named in a message (then a count).
const NAMED: usize = 5;

/// `a, b, c, …` of at most [`NAMED`] names, `…` when `total` is more.
fn some_names(names: impl Iterator<Item = String>, total: usize) -> String {
    let names: Vec<String> = names.take(NAMED).collect();
    let more = if total > names.len() { ", …" } else { "" };
    format!("{}{more}", names.join(", "))
}

/// [`merge_shards`], reading the sweep from `sweep` when given (the file moved since the
/// shards ran).
///
/// Refuses, naming the shard and what to do: a shard still running, shards of two splits,
/// more shards than members, a missing shard (no `.id` or `.csv`; the first few are named
/// and the rest counted), a foreign one (another sweep's identity, or another shard's, in
/// its `.id`, `.csv` or `.json`), a torn last row, a row that is not one of the shard's
/// members, is recorded twice or whose values are not that member's in this sweep, and an
/// incomplete shard (members missing). Also refuses when the sweep file is not the one
/// the shards ran (another identity), and when `out/sweep.id` holds another sweep's
/// results. Nothing is written unless every check passes; each file is replaced whole
/// (written to a temporary file, then renamed). Nothing is allocated or iterated in
/// proportion to a shard count read from file names beyond the files that exist, or the
/// sweep's member count.
pub fn merge_shards_from(out: &Path, sweep: Option<&Path>) -> Result<MergeSummary, SweepError> {
    let start = std::time::Instant::now();
    let dir = out.join(SHARDS_DIR);
    if !dir.is_dir() {
        return Err(SweepError::Invalid {
            file: dir.display().to_string(),
            location: None,
            key: "(shards)".into(),
            reason: format!(
                "no shards to merge: run `cosserat sweep SWEEP --shard I/N --out {}` for every I (or `cosserat sweep slurm`) first",
                out.display()
            ),
        });
    }
    // A shard that has just ended can hold its locks a moment longer (a process forked
    // at that moment holds a copy of the descriptor until it starts its program): a
    // short grace before "still running".
    let mut held = try_lock_file(&out.join(LOCK_FILE), true)?;
    for _ in 0..LOCK_GRACE_TRIES {
        if held.is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
        held = try_lock_file(&out.join(LOCK_FILE), true)?;
    }
    let _lock = match held {
        Some(f) => f,
        None => {
            let running = running_shards(out);
            return Err(match running.first() {
                Some((sh, path)) => SweepError::Shard {
                    file: path.display().to_string(),
                    shard: sh.name(),
                    reason: format!(
                        "still running ({} of this folder's shards are: {}); merge once they have finished (`squeue` on Slurm)",
                        running.len(),
                        some_names(running.iter().map(|(s, _)| s.name()), running.len())
                    ),
                },
                None => SweepError::Locked {
                    dir: out.display().to_string(),
                },
            });
        }
    };
    // Which split: every shard file must name the same N. Per shard, which of its `.id`
    // and `.csv` exist.
    let mut splits: BTreeMap<usize, BTreeMap<Shard, (bool, bool)>> = BTreeMap::new();
    let entries = std::fs::read_dir(&dir).map_err(|error| SweepError::Output {
        context: format!("cannot read {}", dir.display()),
        error,
    })?;
    for e in entries.flatten() {
        let name = e.file_name();
        if let Some((sh, ext @ ("csv" | "id"))) = Shard::from_file_name(&name.to_string_lossy()) {
            if !e.path().is_file() {
                continue;
            }
            let has = splits.entry(sh.count).or_default().entry(sh).or_default();
            match ext {
                "id" => has.0 = true,
                _ => has.1 = true,
            }
        }
    }
    let Some((&count, _)) = splits.iter().max_by_key(|(_, s)| s.len()) else {
        return Err(SweepError::Invalid {
            file: dir.display().to_string(),
            location: None,
            key: "(shards)".into(),
            reason: "no shard files (I-of-N.csv, I-of-N.id) here".into(),
        });
    };
    if let Some((_, other)) = splits.iter().find(|(&n, _)| n != count) {
        let sh = *other.keys().next().unwrap_or_else(|| unreachable!());
        return Err(SweepError::Shard {
            file: dir.display().to_string(),
            shard: sh.name(),
            reason: format!(
                "this folder holds shards of two splits ({} of {} shards, {} of {count}): one folder holds one split of one sweep; delete the stale shard files",
                other.len(),
                sh.count,
                splits[&count].len()
            ),
        });
    }
    let found = &splits[&count];
    // The identity files that exist (no more than the files in the folder).
    let ids: BTreeMap<Shard, IdFile> = found
        .iter()
        .filter(|(_, has)| has.0)
        .filter_map(|(&sh, _)| IdFile::read(&file(out, sh, "id")).map(|f| (sh, f)))
        .collect();
    // The sweep: the identity most shards record.
    let mut votes: BTreeMap<&str, usize> = BTreeMap::new();
    for f in ids.values() {
        *votes.entry(f.get("id")).or_default() += 1;
    }
    let sweep_id = votes
        .iter()
        .max_by_key(|(_, &n)| n)
        .map(|(id, _)| id.to_string())
        .unwrap_or_default();
    let Some((&ref_shard, reference)) = ids.iter().find(|(_, f)| f.get("id") == sweep_id) else {
        let sh = *found.keys().next().unwrap_or_else(|| unreachable!());
        return Err(SweepError::Shard {
            file: dir.display().to_string(),
            shard: sh.name(),
            reason: "no shard identity file can be read".into(),
        });
    };
    let ref_file = file(out, ref_shard, "id").display().to_string();
    let sweep_file = match sweep {
        Some(p) => p.display().to_string(),
        None => reference.get("sweep").to_string(),
    };
    // The sweep itself: its members' values check every row.
    let spec = load_sweep(Path::new(&sweep_file)).map_err(|e| SweepError::Shard {
        file: ref_file.clone(),
        shard: ref_shard.name(),
        reason: format!(
            "cannot load the sweep file the shards were run from ({e}); if it moved, name it: `cosserat sweep merge {} --sweep FILE`",
            out.display()
        ),
    })?;
    let own = spec.identity();
    if sweep_id != own && !sweep_id.starts_with(&format!("{own}+")) {
        return Err(SweepError::Shard {
            file: ref_file.clone(),
            shard: ref_shard.name(),
            reason: format!(
                "the shards are sweep id {sweep_id}, but {sweep_file} is now id {own}: the sweep file or its base scene changed since the shards ran; merge with the sweep file they ran (--sweep FILE)"
            ),
        });
    }
    let members = spec.len();
    if count > members {
        let sh = *found.keys().next().unwrap_or_else(|| unreachable!());
        return Err(SweepError::Shard {
            file: dir.display().to_string(),
            shard: sh.name(),
            reason: format!(
                "the shard files split the sweep into {count} shards, but it has {members} members (at most one shard per member): they were not written by this sweep's shards; delete them"
            ),
        });
    }
    // Present: identity and rows of every shard. Missing ones are found without walking
    // all N: the present ones are known.
    let present = found.values().filter(|h| h.0 && h.1).count();
    if present < count {
        let missing = (0..count)
            .map(|index| Shard { index, count })
            .filter(|sh| found.get(sh).is_none_or(|h| !(h.0 && h.1)));
        let first = missing.clone().next().unwrap_or_else(|| unreachable!());
        let what = if found.get(&first).is_some_and(|h| h.0) {
            "csv"
        } else {
            "id"
        };
        let n = count - present;
        return Err(SweepError::Shard {
            file: file(out, first, what).display().to_string(),
            shard: first.name(),
            reason: format!(
                "missing: the file does not exist (the shard never ran here, or was stopped before it began){}; {}",
                if n > 1 {
                    format!(
                        " — {n} of {count} shards are missing: {}",
                        some_names(missing.map(|s| s.name()), n)
                    )
                } else {
                    String::new()
                },
                resume_hint(out, &sweep_file, first)
            ),
        });
    }
    let shards: Vec<Shard> = (0..count).map(|index| Shard { index, count }).collect();
    for sh in &shards {
        let path = file(out, *sh, "id");
        let fail = |reason: String| SweepError::Shard {
            file: path.display().to_string(),
            shard: sh.name(),
            reason,
        };
        let Some(f) = ids.get(sh) else {
            return Err(fail("cannot be read".into()));
        };
        if f.get("id") != sweep_id {
            return Err(fail(format!(
                "foreign: it belongs to another sweep (id {}, from {}) than the other shards (id {sweep_id}, from {sweep_file}); delete it and run this sweep's shard {sh} instead",
                f.get("id"),
                f.get("sweep")
            )));
        }
        if f.get("shard") != sh.to_string() {
            return Err(fail(format!(
                "foreign: it records shard `{}`, not {sh}: the file was renamed or copied from another shard; delete it and run shard {sh} instead",
                f.get("shard")
            )));
        }
    }
    let head = format!(
        "{}\n",
        header_of(spec.params.iter().map(|p| p.key.as_str()))
    );
    // Rows, shard by shard.
    let mut rows: Vec<(usize, String)> = Vec::new();
    let (mut completed, mut failed, mut rejected) = (0usize, 0usize, 0usize);
    let mut shard_info = Vec::new();
    let mut backends: Vec<String> = Vec::new();
    let mut strategies: Vec<String> = Vec::new();
    let mut template: Option<serde_json::Value> = None;
    let mut wall_max = 0.0f64;
    for &sh in &shards {
        let path = file(out, sh, "csv");
        let name = path.display().to_string();
        let fail = |reason: String| SweepError::Shard {
            file: name.clone(),
            shard: sh.name(),
            reason,
        };
        let bytes = std::fs::read(&path).map_err(|error| SweepError::Output {
            context: format!("cannot read {name}"),
            error,
        })?;
        let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        if complete < bytes.len() {
            return Err(fail(format!(
                "torn: {} bytes after the last newline (the shard was stopped while writing a row); {}",
                bytes.len() - complete,
                resume_hint(out, &sweep_file, sh)
            )));
        }
        let text = String::from_utf8_lossy(&bytes);
        let mut lines = text.lines();
        let want_tag = tag(&sweep_id, sh);
        match lines.next() {
            Some(t) if t == want_tag => {}
            Some(t) => {
                return Err(fail(format!(
                    "foreign: its first line `{}` is not this shard's identity `{want_tag}`: the file is another sweep's or another shard's (or was written by an older cosserat); delete it and run shard {sh} instead",
                    t.chars().take(200).collect::<String>()
                )))
            }
            None => {
                return Err(fail(format!(
                    "torn: the file is empty; {}",
                    resume_hint(out, &sweep_file, sh)
                )))
            }
        }
        match lines.next() {
            Some(h) if format!("{h}\n") == head => {}
            Some(h) => {
                return Err(fail(format!(
                    "foreign: its columns `{}` are not the sweep's `{}`",
                    h.chars().take(500).collect::<String>(),
                    head.trim_end()
                )))
            }
            None => {
                return Err(fail(format!(
                    "torn: the file has no header; {}",
                    resume_hint(out, &sweep_file, sh)
                )))
            }
        }
        let mut seen = BTreeSet::new();
        let (mut c, mut f, mut r) = (0usize, 0usize, 0usize);
        for (k, l) in lines.enumerate() {
            let at = format!("line {}", k + 3);
            let (i, status) = check_row(&split_csv(l), &spec, Some(sh))
                .map_err(|e| fail(format!("{at}: {e}")))?;
            if !seen.insert(i) {
                return Err(fail(format!("{at}: member {i} is recorded twice")));
            }
            match status {
                MemberStatus::Completed => c += 1,
                MemberStatus::Failed => f += 1,
                MemberStatus::Rejected => r += 1,
            }
            rows.push((i, l.to_string()));
        }
        let want = sh.len_of(members);
        if seen.len() != want {
            // At most `seen.len() + 8` candidates are looked at.
            let absent: Vec<String> = (sh.index..members)
                .step_by(count)
                .filter(|i| !seen.contains(i))
                .take(8)
                .map(|i| i.to_string())
                .collect();
            let more = want - seen.len() > absent.len();
            return Err(fail(format!(
                "incomplete: {} of its {want} members recorded (missing: {}{}); it was stopped before the end — {}",
                seen.len(),
                absent.join(", "),
                if more { ", …" } else { "" },
                resume_hint(out, &sweep_file, sh)
            )));
        }
        completed += c;
        failed += f;
        rejected += r;
        // The shard's last invocation, when it recorded one: of this sweep and shard.
        let json_path = file(out, sh, "json");
        let info: Option<serde_json::Value> = std::fs::read_to_string(&json_path)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        if let Some(v) = &info {
            let (id, its) = (v["id"].as_str(), v["shard"].as_str());
            if id != Some(sweep_id.as_str()) || its != Some(sh.to_string().as_str()) {
                return Err(SweepError::Shard {
                    file: json_path.display().to_string(),
                    shard: sh.name(),
                    reason: format!(
                        "foreign: it records sweep id {} shard {}, not id {sweep_id} shard {sh}; delete it and run shard {sh} with --resume",
                        id.unwrap_or("?"),
                        its.unwrap_or("?")
                    ),
                });
            }
        }
        // A text field of the shard's record, also collected (once each) into `seen`.
        let field = |key: &str, seen: &mut Vec<String>| {
            let v = info
                .as_ref()
                .and_then(|v| v[key].as_str())
                .map(str::to_string);
            if let Some(x) = v.as_ref().filter(|x| !seen.contains(x)) {
                seen.push(x.clone());
            }
            v
        };
        let backend = field("backend", &mut backends);
        let strategy = field("strategy", &mut strategies);
        let wall = info.as_ref().and_then(|v| v["wall_s"].as_f64());
        wall_max = wall_max.max(wall.unwrap_or(0.0));
        if template.is_none() {
            template = info.clone();
        }
        shard_info.push(serde_json::json!({
            "shard": sh.to_string(),
            "members": want,
            "completed": c,
            "failed": f,
            "rejected": r,
            "backend": backend,
            "strategy": strategy,
            "wall_s": wall,
        }));
    }
    rows.sort_by_key(|(i, _)| *i);
    debug_assert_eq!(rows.len(), members);
    // A folder already holding another sweep's merged or unsharded results is not
    // overwritten.
    let id_path = out.join(IDENTITY_FILE);
    if let Some(existing) = IdFile::read(&id_path) {
        if existing.get("id") != sweep_id {
            return Err(SweepError::Invalid {
                file: id_path.display().to_string(),
                location: None,
                key: "id".into(),
                reason: format!(
                    "the folder already holds another sweep's members.csv (id {}, from {}); the shards are id {sweep_id}: move those results away, then merge",
                    existing.get("id"),
                    existing.get("sweep")
                ),
            });
        }
    }
    let csv: String = std::iter::once(head)
        .chain(rows.into_iter().map(|(_, l)| l + "\n"))
        .collect();
    let out_err = |path: &Path| {
        let context = format!("cannot write {}", path.display());
        move |error| SweepError::Output { context, error }
    };
    let csv_path = out.join("members.csv");
    let json_path = out.join("sweep.json");
    let t = template.unwrap_or(serde_json::Value::Null);
    let info = serde_json::json!({
        "sweep": reference.get("sweep"),
        "id": sweep_id,
        "newton": t["newton"],
        "fallback": t["fallback"],
        "cutback": t["cutback"],
        "base": t["base"],
        "mode": t["mode"],
        "parameters": spec.params.iter().map(|p| p.key.clone()).collect::<Vec<_>>(),
        "members": members,
        "completed": completed,
        "failed": failed,
        "rejected": rejected,
        "skipped": 0,
        "repaired_bytes": 0,
        "backend": backends.join(" + "),
        "strategy": (!strategies.is_empty()).then(|| strategies.join(" + ")),
        "wall_s": wall_max,
        "merged_shards": count,
        "merge_wall_s": start.elapsed().as_secs_f64(),
        "shards": shard_info,
    });
    // As a fresh sweep: no earlier sweep.json beside the new members.csv.
    match std::fs::remove_file(&json_path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(SweepError::Output {
                context: format!("cannot remove {}", json_path.display()),
                error: e,
            })
        }
        _ => {}
    }
    write_atomic(&id_path, &reference.sweep_text()).map_err(out_err(&id_path))?;
    write_atomic(&csv_path, &csv).map_err(out_err(&csv_path))?;
    write_atomic(&json_path, &format!("{info:#}\n")).map_err(out_err(&json_path))?;
    Ok(MergeSummary {
        members,
        completed,
        failed,
        rejected,
        shards: count,
        sweep: reference.get("sweep").to_string(),
        backends,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_the_members() {
        for total in [0, 1, 5, 12, 13] {
            for n in 1..=6 {
                let mut hits = vec![0; total];
                let mut sum = 0;
                for i in 0..n {
                    let sh = Shard::new(i, n).unwrap();
                    sum += sh.len_of(total);
                    (0..total)
                        .filter(|&m| sh.contains(m))
                        .for_each(|m| hits[m] += 1);
                }
                assert_eq!(sum, total, "{total} members in {n} shards");
                assert!(hits.iter().all(|&h| h == 1));
            }
        }
    }

    #[test]
    fn parse_and_names() {
        assert_eq!(Shard::parse("2/4").unwrap(), Shard { index: 2, count: 4 });
        assert_eq!(Shard::parse("2/4").unwrap().name(), "2-of-4");
        assert!(Shard::parse("4/4").unwrap_err().contains("numbered 0 to 3"));
        assert!(Shard::parse("0/0").unwrap_err().contains("≥ 1"));
        assert!(Shard::parse("x/4")
            .unwrap_err()
            .contains("`x` is not a whole number"));
        assert!(Shard::parse("3").unwrap_err().contains("is not I/N"));
        assert_eq!(
            Shard::from_file_name("10-of-12.csv"),
            Some((
                Shard {
                    index: 10,
                    count: 12
                },
                "csv"
            ))
        );
        assert_eq!(Shard::from_file_name("a-of-12.csv"), None);
        assert_eq!(Shard::from_file_name("12-of-12.csv"), None);
    }
}
