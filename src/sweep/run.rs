//! Running a sweep: members as one batch, `members.csv` appended as they finish,
//! `--resume` skipping members already recorded, optional per-member histories.

use std::collections::HashSet;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::Path;

use super::shard::{self, Shard};
use super::{SweepError, SweepSpec};
use crate::batch::{run_members, BatchOptions, Executor, Member, MemberResult};
use crate::gpu::kernel::KernelTimers;
use crate::observe::record::RunStatus;
use crate::output::HistoryWriter;

/// The fixed leading columns of `members.csv` (then one column per varied parameter,
/// then `reason`).
pub const CSV_COLUMNS: [&str; 8] = [
    "member",
    "status",
    "t_reached",
    "final_total",
    "max_rel_dL",
    "max_rel_dJ",
    "newton_iters_total",
    "wall_s",
];

/// Options of [`run_sweep`].
#[derive(Clone, Copy, Debug, Default)]
pub struct SweepOptions {
    /// Skip members already in `members.csv` (and append to it) instead of starting a
    /// new file.
    pub resume: bool,
    /// Also write `member_<i>/history.csv` per member.
    pub histories: bool,
    /// GPU path: members in flight at once (0 = all).
    pub workers: usize,
    /// Overrides every member's Newton variant when set.
    pub newton: Option<crate::integrator::NewtonVariant>,
    /// Overrides every member's solver fallback when set (`IntegratorParams::fallback`).
    pub fallback: Option<bool>,
    /// Overrides every member's step cut-back when set (`IntegratorParams::cutback`).
    pub cutback: Option<usize>,
    /// Run only this shard's members (member index ≡ I mod N) into
    /// `DIR/shards/I-of-N.{csv,id,json}` ([`crate::sweep::shard`]); `None`: every member
    /// into `DIR/members.csv`.
    pub shard: Option<Shard>,
    /// GPU path: where the Newton systems are solved (recorded in `sweep.json`).
    pub solve: crate::batch::SolveMode,
}

/// One row of `members.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct MemberRow {
    /// Member index in the sweep.
    pub member: usize,
    /// `completed` or `failed`.
    pub status: RunStatus,
    /// Time of the last accepted step.
    pub t_reached: f64,
    /// Total energy at `t_reached`.
    pub final_total: f64,
    /// Largest per-step relative change of L.
    pub max_rel_dl: f64,
    /// Largest per-step relative change of J.
    pub max_rel_dj: f64,
    /// Newton iterations over the run.
    pub newton_iters_total: usize,
    /// Wall time of the member's time loop.
    pub wall_s: f64,
    /// The member's values of the varied parameters.
    pub values: Vec<f64>,
    /// Why it failed (scene rejected its values, or the step that failed).
    pub reason: Option<String>,
}

/// What a sweep did.
#[derive(Clone, Debug, Default)]
pub struct SweepSummary {
    /// Members in the sweep (in the shard, when sharded).
    pub members: usize,
    /// Members skipped because `members.csv` already had them (`--resume`).
    pub skipped: usize,
    /// Members completed in this invocation.
    pub completed: usize,
    /// Members failed in this invocation.
    pub failed: usize,
    /// Bytes of a torn last row cut from `members.csv` on `--resume` (0: none).
    pub repaired_bytes: usize,
    /// `member_<i>/history.csv` files of a previous sweep removed by a fresh start.
    pub stale_histories: usize,
    /// Wall time.
    pub wall_s: f64,
    /// GPU stage timers (zero on the CPU).
    pub gpu: KernelTimers,
}

/// Shortest round-trip text of a number, in exponent form outside [1e-3, 1e6).
fn num(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() || (1e-3..1e6).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

pub(super) fn csv_escape(s: &str) -> String {
    format!("\"{}\"", s.replace('"', "\"\"").replace('\n', " "))
}

impl MemberRow {
    fn csv(&self) -> String {
        let status = match self.status {
            RunStatus::Completed => "completed",
            RunStatus::Failed => "failed",
        };
        let mut s = format!(
            "{},{status},{},{},{},{},{},{}",
            self.member,
            num(self.t_reached),
            num(self.final_total),
            num(self.max_rel_dl),
            num(self.max_rel_dj),
            self.newton_iters_total,
            num(self.wall_s)
        );
        for v in &self.values {
            s.push_str(&format!(",{}", num(*v)));
        }
        s.push(',');
        s.push_str(&csv_escape(self.reason.as_deref().unwrap_or("")));
        s
    }
}

fn header(spec: &SweepSpec) -> String {
    header_of(spec.params.iter().map(|p| p.key.as_str()))
}

/// The `members.csv` header of a sweep varying `keys`.
pub(super) fn header_of<'a>(keys: impl Iterator<Item = &'a str>) -> String {
    let mut cols: Vec<String> = CSV_COLUMNS.iter().map(|s| s.to_string()).collect();
    cols.extend(keys.map(str::to_string));
    cols.push("reason".into());
    cols.join(",")
}

/// What `--resume` found in `members.csv`.
#[derive(Debug, Default)]
struct Recorded {
    /// Members with a complete row.
    done: HashSet<usize>,
    /// Bytes of a torn last row removed (0: none).
    torn_bytes: usize,
    /// Whether the file needs its header written (it was empty or held a torn header).
    needs_header: bool,
}

/// Splits a CSV row into fields (double-quoted fields may hold commas and `""`).
pub(super) fn split_csv(line: &str) -> Vec<String> {
    let mut out = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                out.last_mut().unwrap().push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(String::new()),
            (c, _) => out.last_mut().unwrap().push(c),
        }
    }
    out
}

/// Reads `members.csv` for `--resume`: the header must be this sweep's, every complete
/// row must name a member of this sweep with this sweep's values, and a torn last row
/// (a kill between the start of a row and its newline) is cut off the file so that its
/// member runs again.
fn recorded(
    path: &Path,
    head: &str,
    spec: &SweepSpec,
    shard: Option<Shard>,
) -> Result<Recorded, SweepError> {
    let file = path.display().to_string();
    let io = |error| SweepError::Output {
        context: format!("cannot read {file}"),
        error,
    };
    let bytes = std::fs::read(path).map_err(io)?;
    let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let mut rec = Recorded {
        torn_bytes: bytes.len() - complete,
        ..Default::default()
    };
    let text = String::from_utf8_lossy(&bytes[..complete]);
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h == head => {}
        Some(h) => {
            return Err(SweepError::Invalid {
                file,
                location: Some((1, 1)),
                key: "(header)".into(),
                reason: format!("--resume: columns `{h}` are not this sweep's `{head}`"),
            })
        }
        None => {
            // Zero bytes, or a header cut short by a kill: nothing recorded yet.
            let torn = String::from_utf8_lossy(&bytes);
            if !head.starts_with(torn.as_ref()) {
                return Err(SweepError::Invalid {
                    file,
                    location: Some((1, 1)),
                    key: "(header)".into(),
                    reason: format!(
                        "--resume: `{torn}` is not the start of this sweep's header `{head}`"
                    ),
                });
            }
            rec.torn_bytes = 0;
            rec.needs_header = true;
        }
    }
    let n_params = spec.params.len();
    for (k, l) in lines.enumerate() {
        let line_no = k + 2;
        let bad = |reason: String| SweepError::Invalid {
            file: file.clone(),
            location: Some((line_no, 1)),
            key: "(row)".into(),
            reason: format!("--resume: {reason}"),
        };
        let f = split_csv(l);
        if f.len() != CSV_COLUMNS.len() + n_params + 1 {
            return Err(bad(format!(
                "{} fields, expected {} (the file was edited or is not this sweep's)",
                f.len(),
                CSV_COLUMNS.len() + n_params + 1
            )));
        }
        let i: usize = f[0]
            .parse()
            .ok()
            .filter(|&i| i < spec.len())
            .ok_or_else(|| {
                bad(format!(
                    "member `{}` is not one of this sweep's 0..{}",
                    f[0],
                    spec.len()
                ))
            })?;
        if let Some(sh) = shard.filter(|sh| !sh.contains(i)) {
            return Err(bad(format!(
                "member {i} is not one of shard {sh}'s (members ≡ {} mod {}): the file was edited or copied from another shard",
                sh.index, sh.count
            )));
        }
        for (j, p) in spec.params.iter().enumerate() {
            let got: Option<f64> = f[CSV_COLUMNS.len() + j].parse().ok();
            let want = spec.values[i][j];
            if got.map(f64::to_bits) != Some(want.to_bits()) {
                return Err(bad(format!(
                    "member {i} has {} = {} here but {} in this sweep: the folder holds another sweep's results",
                    p.key,
                    f[CSV_COLUMNS.len() + j],
                    num(want)
                )));
            }
        }
        if !rec.done.insert(i) {
            return Err(bad(format!("member {i} is recorded twice")));
        }
    }
    Ok(rec)
}

/// Name of the file that records which sweep a folder holds.
pub const IDENTITY_FILE: &str = "sweep.id";

/// Name of the lock file a running sweep holds exclusively.
pub const LOCK_FILE: &str = ".sweep.lock";

/// Opens (creating) a lock file and tries to lock it, exclusively or shared. `Ok(None)`:
/// another process holds a conflicting lock.
pub(super) fn try_lock_file(
    path: &Path,
    exclusive: bool,
) -> Result<Option<std::fs::File>, SweepError> {
    let f = OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(path)
        .map_err(|error| SweepError::Output {
            context: format!("cannot open {}", path.display()),
            error,
        })?;
    let got = if exclusive {
        f.try_lock()
    } else {
        f.try_lock_shared()
    };
    match got {
        Ok(()) => Ok(Some(f)),
        Err(std::fs::TryLockError::WouldBlock) => Ok(None),
        Err(std::fs::TryLockError::Error(error)) => Err(SweepError::Output {
            context: format!("cannot lock {}", path.display()),
            error,
        }),
    }
}

/// Takes the folder's locks, held until the returned files are dropped and released by
/// the system when the process dies, however it dies. An unsharded sweep (and `sweep
/// merge`) holds `DIR/.sweep.lock` exclusively; a shard holds it shared (shards of one
/// folder run side by side) plus its own `DIR/shards/I-of-N.lock` exclusively.
fn lock(out: &Path, shard: Option<Shard>) -> Result<Vec<std::fs::File>, SweepError> {
    let Some(folder) = try_lock_file(&out.join(LOCK_FILE), shard.is_none())? else {
        return Err(SweepError::Locked {
            dir: out.display().to_string(),
        });
    };
    let mut held = vec![folder];
    if let Some(sh) = shard {
        let path = shard::file(out, sh, "lock");
        match try_lock_file(&path, true)? {
            Some(f) => held.push(f),
            None => {
                return Err(SweepError::Shard {
                    file: path.display().to_string(),
                    shard: sh.name(),
                    reason: format!("shard {sh} is already running in this folder (another process holds this lock); wait for it to finish"),
                })
            }
        }
    }
    Ok(held)
}

/// Writes `text` to `path` through a temporary file renamed over it, synced, so the file
/// is either the old one or the whole new one.
pub(super) fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// The identity of a sweep run: the sweep's own ([`SweepSpec::identity`]) and the
/// command-line overrides that change its results (`--newton`, `--no-fallback`,
/// `--cutback`), so that `--resume` with other overrides is refused, not mixed in.
pub(super) fn run_identity(spec: &SweepSpec, opts: &SweepOptions) -> String {
    let mut id = spec.identity();
    if let Some(n) = opts.newton {
        id += &format!("+newton={}", n.name());
    }
    if let Some(f) = opts.fallback {
        id += &format!("+fallback={f}");
    }
    if let Some(c) = opts.cutback {
        id += &format!("+cutback={c}");
    }
    id
}

/// The identity text of a sweep as recorded in [`IDENTITY_FILE`] (a shard's adds a line
/// `shard I/N`).
fn identity_text(spec: &SweepSpec, opts: &SweepOptions) -> String {
    let shard = opts
        .shard
        .map(|sh| format!("shard {sh}\n"))
        .unwrap_or_default();
    format!(
        "id {}\nmembers {}\nparameters {}\nsweep {}\n{shard}",
        run_identity(spec, opts),
        spec.len(),
        spec.params
            .iter()
            .map(|p| p.key.as_str())
            .collect::<Vec<_>>()
            .join(","),
        spec.source
    )
}

/// On `--resume`: the folder (or the shard's identity file `path`) must hold this sweep
/// (same identity).
fn check_identity(path: &Path, spec: &SweepSpec, opts: &SweepOptions) -> Result<(), SweepError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| SweepError::Invalid {
        file: file.clone(),
        location: None,
        key: "id".into(),
        reason: format!(
            "--resume: cannot read the folder's sweep identity ({e}); the folder was not written by `cosserat sweep`, or by an older version: run without --resume or use another --out"
        ),
    })?;
    let recorded = text
        .lines()
        .find_map(|l| l.strip_prefix("id "))
        .unwrap_or("")
        .trim();
    let want = run_identity(spec, opts);
    if recorded != want {
        let line = |k: &str| {
            text.lines()
                .find_map(|l| l.strip_prefix(k))
                .unwrap_or("?")
                .trim()
                .to_string()
        };
        return Err(SweepError::Invalid {
            file,
            location: None,
            key: "id".into(),
            reason: format!(
                "--resume: the folder holds another sweep (id {recorded}: {} members over {}, from {}); {} is id {want} ({} members over {}): its base scene, member values or overrides (--newton, --no-fallback, --cutback) differ. Run it into another --out, or without --resume to start afresh",
                line("members "),
                line("parameters "),
                line("sweep "),
                spec.source,
                spec.len(),
                spec.params.iter().map(|p| p.key.as_str()).collect::<Vec<_>>().join(",")
            ),
        });
    }
    Ok(())
}

/// A fresh start removes the previous sweep's `member_<i>/history.csv` (and their
/// temporary files and then-empty folders), so the folder never mixes two sweeps. A
/// shard removes only those of its own member indices (the shards together remove all).
fn remove_stale_histories(out: &Path, shard: Option<Shard>) -> std::io::Result<usize> {
    let mut n = 0;
    for entry in std::fs::read_dir(out)? {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let member = name
            .strip_prefix("member_")
            .filter(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
            .map(|d| d.parse::<usize>().unwrap_or(usize::MAX));
        let ours = match (member, shard) {
            (None, _) => false,
            (Some(_), None) => true,
            (Some(i), Some(sh)) => sh.contains(i),
        };
        if !ours || !entry.file_type()?.is_dir() {
            continue;
        }
        for f in ["history.csv", "history.csv.tmp"] {
            match std::fs::remove_file(entry.path().join(f)) {
                Ok(()) => n += usize::from(f == "history.csv"),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
        let _ = std::fs::remove_dir(entry.path()); // only if now empty
    }
    Ok(n)
}

/// Writes one member's history to `dir/history.csv` through a temporary file, so a
/// history file that exists is complete.
fn write_history(dir: &Path, history: &[crate::observe::record::StepRecord]) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    let tmp = dir.join("history.csv.tmp");
    {
        let mut h = HistoryWriter::create(&tmp).map_err(|e| e.to_string())?;
        history
            .iter()
            .try_for_each(|rec| h.push(rec))
            .map_err(|e| e.to_string())?;
    }
    std::fs::File::open(&tmp)
        .and_then(|f| f.sync_all())
        .and_then(|_| std::fs::rename(&tmp, dir.join("history.csv")))
        .map_err(|e| e.to_string())
}

/// Runs every member of `spec` not yet recorded, appending one row per finished member
/// to `out/members.csv`, then writes `out/sweep.json` (counts of this invocation, backend
/// and adapter). `on_row` sees each row (progress display).
///
/// What survives a kill (`docs/guarantees.md`): the folder is locked exclusively while a
/// sweep runs (a second one is refused); each row is one `write` of a whole line, synced
/// before the next member is recorded; a member's history file (`--histories`) is
/// complete before its row is written; `--resume` checks the folder's identity
/// (`sweep.id`) and every recorded row's values against this sweep and cuts a torn last
/// row, whose member then runs again.
///
/// With [`SweepOptions::shard`] only that shard's members run, into
/// `out/shards/I-of-N.{csv,id,json}` (member histories still in `out/member_<i>/`); the
/// shard holds the folder lock shared and its own lock exclusively, refuses a folder whose
/// other shards belong to another sweep or another split, and `--resume` checks its own
/// identity file and that every recorded row is one of its members.
/// [`merge_shards`](crate::sweep::merge_shards) joins the shards into `out/members.csv`.
pub fn run_sweep(
    spec: &SweepSpec,
    exec: &Executor,
    out: &Path,
    opts: &SweepOptions,
    mut on_row: impl FnMut(&MemberRow),
) -> Result<SweepSummary, SweepError> {
    let start = std::time::Instant::now();
    let ctx = |what: String| {
        move |error| SweepError::Output {
            context: what,
            error,
        }
    };
    let shard = opts.shard;
    let (csv_path, id_path, json_path) = match shard {
        None => (
            out.join("members.csv"),
            out.join(IDENTITY_FILE),
            out.join("sweep.json"),
        ),
        Some(sh) => (
            shard::file(out, sh, "csv"),
            shard::file(out, sh, "id"),
            shard::file(out, sh, "json"),
        ),
    };
    let dir = csv_path.parent().unwrap_or(out);
    std::fs::create_dir_all(dir).map_err(ctx(format!("cannot create {}", dir.display())))?;
    let _lock = lock(out, shard)?;
    if let Some(sh) = shard {
        shard::check_siblings(out, &run_identity(spec, opts), sh)?;
    }
    let in_scope = |i: &usize| shard.is_none_or(|sh| sh.contains(*i));
    let scope = shard.map_or(spec.len(), |sh| sh.len_of(spec.len()));
    let head = header(spec);
    let resuming = opts.resume && csv_path.exists();
    let rec = if resuming {
        check_identity(&id_path, spec, opts)?;
        recorded(&csv_path, &head, spec, shard)?
    } else {
        Recorded {
            needs_header: true,
            ..Default::default()
        }
    };
    if !resuming {
        // A fresh start: the identity first, then a members.csv holding only the header
        // (renamed into place: a kill leaves either no file or a whole header).
        write_atomic(&id_path, &identity_text(spec, opts))
            .map_err(ctx(format!("cannot write {}", id_path.display())))?;
        write_atomic(&csv_path, &format!("{head}\n"))
            .map_err(ctx(format!("cannot write {}", csv_path.display())))?;
    }
    let stale_histories = if resuming {
        0
    } else {
        remove_stale_histories(out, shard)
            .map_err(ctx(format!("cannot clean {}", out.display())))?
    };
    let mut csv = OpenOptions::new()
        .append(true)
        .open(&csv_path)
        .map_err(ctx(format!("cannot open {}", csv_path.display())))?;
    if resuming && rec.torn_bytes > 0 {
        let keep = csv
            .metadata()
            .map_err(ctx(format!("cannot read {}", csv_path.display())))?
            .len()
            - rec.torn_bytes as u64;
        csv.set_len(keep)
            .and_then(|_| csv.sync_all())
            .map_err(ctx(format!("cannot repair {}", csv_path.display())))?;
    }
    // One row = one write of a whole line, synced before the next member is recorded.
    let wr = |csv: &mut std::fs::File, line: &str| {
        csv.write_all(format!("{line}\n").as_bytes())
            .and_then(|_| csv.sync_data())
            .map_err(ctx(format!("cannot write {}", csv_path.display())))
    };
    if resuming && rec.needs_header {
        csv.set_len(0)
            .map_err(ctx(format!("cannot repair {}", csv_path.display())))?;
        wr(&mut csv, &head)?;
    }
    let done = rec.done;
    let mut summary = SweepSummary {
        members: scope,
        skipped: done.len(),
        repaired_bytes: rec.torn_bytes,
        stale_histories,
        ..Default::default()
    };
    // Memory of the members this invocation will hold at once, before building them.
    let todo = (scope - done.len()) as u64;
    if todo > 0 {
        let elements = spec.base_elements() as u64;
        crate::scene::limits::check_memory("this sweep", todo, elements).map_err(|e| {
            SweepError::Invalid {
                file: spec.source.clone(),
                location: None,
                key: "(members)".into(),
                reason: e.to_string(),
            }
        })?;
    }
    // Build the members; a member whose values the scene rejects is a failed row.
    let mut members = Vec::new();
    let mut ids = Vec::new();
    let mut elements_total = 0u64;
    for i in (0..spec.len()).filter(|i| in_scope(i) && !done.contains(i)) {
        match spec.member_scene(i) {
            Ok(scene) => {
                // Members may differ in size (a varied element count): count what is built.
                elements_total += scene.model.elements.len() as u64;
                let per = elements_total / (members.len() as u64 + 1);
                crate::scene::limits::check_memory("this sweep", todo, per).map_err(|e| {
                    SweepError::Invalid {
                        file: spec.source.clone(),
                        location: None,
                        key: "(members)".into(),
                        reason: e.to_string(),
                    }
                })?;
                members.push(Member {
                    model: scene.model,
                    params: scene.params,
                });
                ids.push(i);
            }
            Err(e) => {
                let row = MemberRow {
                    member: i,
                    status: RunStatus::Failed,
                    t_reached: 0.0,
                    final_total: f64::NAN,
                    max_rel_dl: f64::NAN,
                    max_rel_dj: f64::NAN,
                    newton_iters_total: 0,
                    wall_s: 0.0,
                    values: spec.values[i].clone(),
                    reason: Some(format!("scene rejected the member's values: {e}")),
                };
                wr(&mut csv, &row.csv())?;
                summary.failed += 1;
                on_row(&row);
            }
        }
    }
    let mut write_err: Option<SweepError> = None;
    let stats = run_members(
        &members,
        exec,
        BatchOptions {
            keep_history: opts.histories,
            workers: opts.workers,
            newton: opts.newton,
            fallback: opts.fallback,
            cutback: opts.cutback,
            solve: opts.solve,
            ..Default::default()
        },
        |r: MemberResult| {
            if write_err.is_some() {
                return;
            }
            let id = ids[r.index];
            let o = &r.outcome;
            let row = MemberRow {
                member: id,
                status: o.status,
                t_reached: o.t_reached,
                final_total: o.energy_final,
                max_rel_dl: o.max_rel_dl,
                max_rel_dj: o.max_rel_dj,
                newton_iters_total: o.newton_iters_total,
                wall_s: o.wall_s,
                values: spec.values[id].clone(),
                reason: o.reason.clone(),
            };
            // Every file of a member is complete before its row says it is done.
            if opts.histories {
                let dir = match crate::paths::join_under(out, format!("member_{id}")) {
                    Ok(d) => d,
                    Err(e) => {
                        write_err = Some(SweepError::Output {
                            context: e.to_string(),
                            error: std::io::Error::other("path outside the output folder"),
                        });
                        return;
                    }
                };
                if let Err(e) = write_history(&dir, &r.history) {
                    write_err = Some(SweepError::Output {
                        context: format!("cannot write {}", dir.display()),
                        error: std::io::Error::other(e),
                    });
                    return;
                }
            }
            if let Err(e) = wr(&mut csv, &row.csv()) {
                write_err = Some(e);
                return;
            }
            match o.status {
                RunStatus::Completed => summary.completed += 1,
                RunStatus::Failed => summary.failed += 1,
            }
            on_row(&row);
        },
    )?;
    if let Some(e) = write_err {
        return Err(e);
    }
    summary.gpu = stats.gpu;
    summary.wall_s = start.elapsed().as_secs_f64();
    let info = serde_json::json!({
        "sweep": spec.source,
        "id": run_identity(spec, opts),
        "newton": opts.newton.map(|n| n.name()),
        "fallback": opts.fallback,
        "cutback": opts.cutback,
        "base": spec.base,
        "mode": format!("{:?}", spec.mode).to_lowercase(),
        "shard": shard.map(|sh| sh.to_string()),
        "parameters": spec.params.iter().map(|p| p.key.clone()).collect::<Vec<_>>(),
        "members": summary.members,
        "completed": summary.completed,
        "failed": summary.failed,
        "skipped": summary.skipped,
        "repaired_bytes": summary.repaired_bytes,
        "backend": exec.describe(),
        // The dissipation strategy of the members (`auto` resolved for this backend:
        // staggered with the GPU evaluator, monolithic on the CPU kernel); `null` for
        // conserving schemes.
        "strategy": members.iter().find_map(|m| member_strategy(m, exec)),
        "solve": opts.solve.name(),
        "wall_s": summary.wall_s,
    });
    write_atomic(&json_path, &format!("{info:#}\n"))
        .map_err(ctx(format!("cannot write {}", json_path.display())))?;
    Ok(summary)
}

/// The dissipation strategy `m` runs with on `exec`: its parameters' choice with `auto`
/// resolved (staggered where the GPU kernel evaluates it, monolithic on the CPU kernel);
/// `None` for a conserving scheme, which solves no dissipation scalars.
fn member_strategy(m: &crate::batch::Member, exec: &Executor) -> Option<&'static str> {
    let p = &m.params;
    let gpu = matches!(exec, Executor::Gpu(_)) && p.scheme.has_gpu_kernel();
    p.scheme
        .is_dissipative()
        .then(|| p.strategy.resolve(gpu).name())
}
