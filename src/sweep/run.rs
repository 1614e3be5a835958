//! Running a sweep: members as one batch, `members.csv` appended as they finish,
//! `--resume` skipping members already recorded, optional per-member histories.

use std::collections::HashSet;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::Path;

use super::split::{self, Shard};
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

/// How a member ended: the `status` column of `members.csv`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemberStatus {
    /// It ran to its end time.
    Completed,
    /// A step failed (the reason says which and why).
    Failed,
    /// Its scene (the base scene with its values written in) is invalid, so it never ran.
    Rejected,
}

impl MemberStatus {
    /// The word in `members.csv`.
    pub fn name(self) -> &'static str {
        match self {
            MemberStatus::Completed => "completed",
            MemberStatus::Failed => "failed",
            MemberStatus::Rejected => "rejected",
        }
    }

    /// The status named `s` in `members.csv`.
    pub fn parse(s: &str) -> Option<MemberStatus> {
        [
            MemberStatus::Completed,
            MemberStatus::Failed,
            MemberStatus::Rejected,
        ]
        .into_iter()
        .find(|m| m.name() == s)
    }
}

impl From<RunStatus> for MemberStatus {
    fn from(s: RunStatus) -> Self {
        match s {
            RunStatus::Completed => MemberStatus::Completed,
            RunStatus::Failed => MemberStatus::Failed,
        }
    }
}

/// One row of `members.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct MemberRow {
    /// Member index in the sweep.
    pub member: usize,
    /// `completed`, `failed` or `rejected`.
    pub status: MemberStatus,
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
    /// Why it failed (the step that failed) or was rejected (what its scene rejects).
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
    /// Members rejected in this invocation (their scene is invalid).
    pub rejected: usize,
    /// Bytes of a torn last row cut from `members.csv` on `--resume` (0: none).
    pub repaired_bytes: usize,
    /// `member_<i>/history.csv` files of a previous sweep removed by a fresh start.
    pub stale_histories: usize,
    /// Wall time.
    pub wall_s: f64,
    /// GPU stage timers (zero on the CPU).
    pub gpu: KernelTimers,
    /// The sweep was stopped ([`run_sweep_until`]) before every member ran; the members
    /// recorded so far are kept and `resume` runs the others.
    pub stopped: bool,
    /// `--solve whole`: members whose steps ran on the host, by the reason (recorded in
    /// `sweep.json` as `host_steps`).
    pub host_steps: std::collections::BTreeMap<String, u64>,
}

/// Shortest round-trip text of a number, in exponent form outside [1e-3, 1e6); a
/// non-finite number (a quantity a member never reached) is an empty cell, so no data file
/// holds `NaN` or `inf`.
fn num(x: f64) -> String {
    let a = x.abs();
    if !x.is_finite() {
        String::new()
    } else if x == 0.0 || (1e-3..1e6).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

pub(super) fn csv_escape(s: &str) -> String {
    format!("\"{}\"", s.replace('"', "\"\"").replace('\n', " "))
}

impl MemberRow {
    /// A member whose scene was rejected: it never ran, so its result cells are empty.
    fn rejected(member: usize, values: Vec<f64>, reason: String) -> MemberRow {
        MemberRow {
            member,
            status: MemberStatus::Rejected,
            t_reached: f64::NAN,
            final_total: f64::NAN,
            max_rel_dl: f64::NAN,
            max_rel_dj: f64::NAN,
            newton_iters_total: 0,
            wall_s: f64::NAN,
            values,
            reason: Some(reason),
        }
    }

    fn csv(&self) -> String {
        let iters = match self.status {
            MemberStatus::Rejected => String::new(),
            _ => self.newton_iters_total.to_string(),
        };
        let mut s = format!(
            "{},{},{},{},{},{},{iters},{}",
            self.member,
            self.status.name(),
            num(self.t_reached),
            num(self.final_total),
            num(self.max_rel_dl),
            num(self.max_rel_dj),
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

/// Checks one row of `members.csv` (or of a shard's file) against `spec`: its field count,
/// that it names a member of the sweep (of `shard`, when given) and that its values are
/// that member's, bit for bit. Returns the member and its status.
pub(super) fn check_row(
    fields: &[String],
    spec: &SweepSpec,
    shard: Option<Shard>,
) -> Result<(usize, MemberStatus), String> {
    let want = CSV_COLUMNS.len() + spec.params.len() + 1;
    if fields.len() != want {
        return Err(format!(
            "{} fields, expected {want} (the file was edited or is not this sweep's)",
            fields.len()
        ));
    }
    let i: usize = fields[0]
        .parse()
        .ok()
        .filter(|&i| i < spec.len())
        .ok_or_else(|| {
            format!(
                "member `{}` is not one of this sweep's 0..{}",
                fields[0],
                spec.len()
            )
        })?;
    if let Some(sh) = shard.filter(|sh| !sh.contains(i)) {
        return Err(format!(
            "member {i} is not one of shard {sh}'s (members ≡ {} mod {}): the file was edited or copied from another shard",
            sh.index, sh.count
        ));
    }
    let status = MemberStatus::parse(&fields[1]).ok_or_else(|| {
        format!(
            "member {i}: status `{}` is not completed, failed or rejected",
            fields[1]
        )
    })?;
    for (j, p) in spec.params.iter().enumerate() {
        let got: Option<f64> = fields[CSV_COLUMNS.len() + j].parse().ok();
        let want = spec.values[i][j];
        if got.map(f64::to_bits) != Some(want.to_bits()) {
            return Err(format!(
                "member {i} has {} = {} here but {} in this sweep: the row is another sweep's result",
                p.key,
                fields[CSV_COLUMNS.len() + j],
                num(want)
            ));
        }
    }
    Ok((i, status))
}

/// Reads `members.csv` for `--resume`: the file must begin with `head` (the header; a
/// shard's file has its identity line first), every complete row must name a member of
/// this sweep with this sweep's values, and a torn last row (a kill between the start of
/// a row and its newline) is cut off the file so that its member runs again.
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
    let head_nl = format!("{head}\n");
    let head_lines = head.lines().count();
    if !bytes.starts_with(head_nl.as_bytes()) {
        // Zero bytes, or a head cut short by a kill: nothing recorded yet.
        if head_nl.as_bytes().starts_with(&bytes) {
            rec.torn_bytes = 0;
            rec.needs_header = true;
            return Ok(rec);
        }
        let text = String::from_utf8_lossy(&bytes);
        let (k, (got, want)) = text
            .lines()
            .zip(head.lines())
            .enumerate()
            .find(|(_, (g, w))| g != w)
            .unwrap_or((0, (text.lines().next().unwrap_or(""), head)));
        let what = if want.starts_with('#') {
            "the identity line"
        } else {
            "the columns"
        };
        return Err(SweepError::Invalid {
            file,
            location: Some((k + 1, 1)),
            key: "(header)".into(),
            reason: format!("--resume: {what} `{got}` are not this sweep's `{want}`"),
        });
    }
    let text = String::from_utf8_lossy(&bytes[head_nl.len()..complete.max(head_nl.len())]);
    for (k, l) in text.lines().enumerate() {
        let line_no = k + 1 + head_lines;
        let bad = |reason: String| SweepError::Invalid {
            file: file.clone(),
            location: Some((line_no, 1)),
            key: "(row)".into(),
            reason: format!("--resume: {reason}"),
        };
        let (i, _) = check_row(&split_csv(l), spec, shard).map_err(bad)?;
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
        let path = split::file(out, sh, "lock");
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
/// On an error (a full disk) the temporary file is removed and `path` is left as it was.
pub(super) fn write_atomic(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = tmp_path(path);
    let r = std::fs::File::create(&tmp)
        .and_then(|mut f| {
            f.write_all(text.as_bytes())?;
            f.sync_all()
        })
        .and_then(|_| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// The temporary name of `path` while it is written: `NAME.tmp` beside it.
fn tmp_path(path: &Path) -> std::path::PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    path.with_file_name(name)
}

/// Removes `path`; a file that does not exist is not an error.
fn remove_if_present(path: &Path) -> std::io::Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
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
    let r = HistoryWriter::create(&tmp)
        .map_err(|e| e.to_string())
        .and_then(|mut h| {
            history
                .iter()
                .try_for_each(|rec| h.push(rec))
                .map_err(|e| e.to_string())
        })
        .and_then(|_| {
            std::fs::File::open(&tmp)
                .and_then(|f| f.sync_all())
                .and_then(|_| std::fs::rename(&tmp, dir.join("history.csv")))
                .map_err(|e| e.to_string())
        });
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// Runs every member of `spec` not yet recorded, appending one row per finished member
/// to `out/members.csv`, then writes `out/sweep.json` (counts of this invocation, backend
/// and adapter). `on_row` sees each row (progress display).
///
/// A member whose scene rejects its values (the base scene with them written in) is a
/// `rejected` row with the reason, whichever member it is; its result cells are empty.
///
/// What survives a kill (`docs/guarantees.md`): the folder is locked exclusively while a
/// sweep runs (a second one is refused); nothing in it changes before every check has
/// passed and the batch has started (a refused backend leaves an earlier sweep's files as
/// they were); a fresh start removes the previous `sweep.json` and writes `sweep.id`
/// before its `members.csv` appears; each row is one `write` of a whole line, synced
/// before the next member is recorded; a member's history file (`--histories`) is
/// complete before its row is written; `--resume` checks the folder's identity
/// (`sweep.id`) and every recorded row's values against this sweep and cuts a torn last
/// row, whose member then runs again. A write error leaves no temporary file.
///
/// With [`SweepOptions::shard`] (at most one shard per member) only that shard's members
/// run, into `out/shards/I-of-N.{csv,id,json}` (member histories still in
/// `out/member_<i>/`; the rows file begins with the shard's identity line); the
/// shard holds the folder lock shared and its own lock exclusively, refuses a folder whose
/// other shards belong to another sweep or another split, and `--resume` checks its own
/// identity file and that every recorded row is one of its members.
/// [`merge_shards`](crate::sweep::merge_shards) joins the shards into `out/members.csv`.
pub fn run_sweep(
    spec: &SweepSpec,
    exec: &Executor,
    out: &Path,
    opts: &SweepOptions,
    on_row: impl FnMut(&MemberRow),
) -> Result<SweepSummary, SweepError> {
    run_sweep_until(spec, exec, out, opts, None, on_row)
}

/// [`run_sweep`] that can be stopped from another thread: once `stop` is set, no further
/// member starts; the members under way finish and are recorded (on the CPU path the
/// members run in groups of twice the worker threads, on the GPU path in groups of its
/// slots, and `stop` is looked at between groups), `sweep.json` is written for what ran
/// and the summary says [`SweepSummary::stopped`]. The folder is then what a killed sweep
/// leaves, with no torn row: `resume` runs the remaining members. `None` runs them all
/// at once, as [`run_sweep`].
pub fn run_sweep_until(
    spec: &SweepSpec,
    exec: &Executor,
    out: &Path,
    opts: &SweepOptions,
    stop: Option<&std::sync::atomic::AtomicBool>,
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
    if let Some(sh) = shard {
        split::check_count(spec, sh)?;
    }
    let (csv_path, id_path, json_path) = match shard {
        None => (
            out.join("members.csv"),
            out.join(IDENTITY_FILE),
            out.join("sweep.json"),
        ),
        Some(sh) => (
            split::file(out, sh, "csv"),
            split::file(out, sh, "id"),
            split::file(out, sh, "json"),
        ),
    };
    let dir = csv_path.parent().unwrap_or(out);
    std::fs::create_dir_all(dir).map_err(ctx(format!("cannot create {}", dir.display())))?;
    let _lock = lock(out, shard)?;
    if let Some(sh) = shard {
        split::check_siblings(out, &run_identity(spec, opts), sh)?;
    }
    let in_scope = |i: &usize| shard.is_none_or(|sh| sh.contains(*i));
    let scope = shard.map_or(spec.len(), |sh| sh.len_of(spec.len()));
    let head = file_head(spec, opts);
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
    let done = &rec.done;
    // Memory of the members this invocation will hold at once, before building them.
    let todo = (scope - done.len()) as u64;
    if todo > 0 {
        crate::scene::limits::check_batch("this sweep", todo, &spec.base_footprint()).map_err(
            |e| SweepError::Invalid {
                file: spec.source.clone(),
                location: None,
                key: "(members)".into(),
                reason: e.to_string(),
            },
        )?;
    }
    // Build the members; a member whose scene rejects its values is a `rejected` row.
    let mut members = Vec::new();
    let mut ids = Vec::new();
    let mut rejected = Vec::new();
    let mut total = crate::scene::limits::Footprint::default();
    for i in (0..spec.len()).filter(|i| in_scope(i) && !done.contains(i)) {
        match spec.member_scene(i) {
            Ok(scene) => {
                // Members may differ in size (a varied element count): count what is built.
                let fp = crate::scene::limits::Footprint::of_model(&scene.model);
                total.elements += fp.elements;
                total.nodes += fp.nodes;
                total.contact_spheres += fp.contact_spheres;
                let n = members.len() as u64 + 1;
                let per = crate::scene::limits::Footprint {
                    elements: total.elements / n,
                    nodes: total.nodes / n,
                    contact_spheres: total.contact_spheres / n,
                    ..Default::default()
                };
                crate::scene::limits::check_batch("this sweep", todo, &per).map_err(|e| {
                    SweepError::Invalid {
                        file: spec.source.clone(),
                        location: None,
                        key: "(members)".into(),
                        reason: e.to_string(),
                    }
                })?;
                // Cut-back on by default (`--cutback` overrides it in every member).
                let mut params = scene.params;
                params.cutback = scene.run_cutback();
                members.push(Member {
                    model: scene.model,
                    params,
                });
                ids.push(i);
            }
            Err(e) => rejected.push(MemberRow::rejected(
                i,
                spec.values[i].clone(),
                format!("scene rejects the member's values: {e}"),
            )),
        }
    }
    // Nothing in the folder has changed so far. It changes when the batch has started (a
    // GPU backend that refuses the batch refuses it before its first result) or has ended
    // without running anything.
    let mut rows = Rows {
        csv_path: &csv_path,
        id_path: &id_path,
        json_path: &json_path,
        out,
        shard,
        resuming,
        rec: &rec,
        head: &head,
        identity: identity_text(spec, opts),
        csv: None,
        pending: rejected,
        summary: SweepSummary {
            members: scope,
            skipped: done.len(),
            repaired_bytes: rec.torn_bytes,
            ..Default::default()
        },
    };
    let mut write_err: Option<SweepError> = None;
    let group = match (stop, exec) {
        (None, _) => members.len().max(1),
        (Some(_), Executor::Cpu) => 2 * rayon::current_num_threads().max(1),
        (Some(_), Executor::Gpu(_)) => match opts.workers {
            0 => crate::batch::DEFAULT_GPU_SLOTS,
            w => w,
        },
    };
    let mut stats = crate::batch::BatchStats::default();
    let mut first = 0;
    loop {
        if stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::SeqCst)) {
            rows.summary.stopped = true;
            break;
        }
        let last = (first + group).min(members.len());
        let part = run_members(
            &members[first..last],
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
                if let Err(e) = rows.begin(&mut on_row) {
                    write_err = Some(e);
                    return;
                }
                let id = ids[first + r.index];
                let o = &r.outcome;
                let row = MemberRow {
                    member: id,
                    status: o.status.into(),
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
                            context: format!("cannot write {}", dir.join("history.csv").display()),
                            error: std::io::Error::other(e),
                        });
                        return;
                    }
                }
                if let Err(e) = rows.write(&row, &mut on_row) {
                    write_err = Some(e);
                }
            },
        )?;
        if first == 0 {
            stats = part;
        } else {
            add_kernel_timers(&mut stats.gpu, &part.gpu);
            for (why, n) in part.host_step_reasons {
                *stats.host_step_reasons.entry(why).or_default() += n;
            }
        }
        if let Some(e) = write_err {
            return Err(e);
        }
        first = last;
        if first >= members.len() {
            break;
        }
    }
    rows.begin(&mut on_row)?;
    let mut summary = rows.summary;
    summary.gpu = stats.gpu;
    summary.host_steps = stats.host_step_reasons;
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
        "rejected": summary.rejected,
        "skipped": summary.skipped,
        "repaired_bytes": summary.repaired_bytes,
        "backend": exec.describe(),
        // The dissipation strategy of the members (`auto` resolved for this backend:
        // staggered with the GPU evaluator, inexact with `--solve whole`, monolithic on the
        // CPU kernel); `null` for conserving schemes.
        "strategy": members.iter().find_map(|m| member_strategy(m, exec, opts.solve)),
        "solve": opts.solve.name(),
        // `--solve whole`: members whose steps ran on the host, by the reason.
        "host_steps": summary.host_steps,
        "wall_s": summary.wall_s,
    });
    write_atomic(&json_path, &format!("{info:#}\n"))
        .map_err(ctx(format!("cannot write {}", json_path.display())))?;
    Ok(summary)
}

/// Adds the kernel timers of a later group of members to `total`.
fn add_kernel_timers(total: &mut KernelTimers, t: &KernelTimers) {
    total.upload_s += t.upload_s;
    total.kernel_s += t.kernel_s;
    total.readback_s += t.readback_s;
    total.unpack_s += t.unpack_s;
    total.dispatches += t.dispatches;
    total.bytes_up += t.bytes_up;
    total.bytes_down += t.bytes_down;
    total.copies += t.copies;
    total.readback_copies += t.readback_copies;
    total.tangent_elements += t.tangent_elements;
}

/// What a sweep's rows file begins with: the header, after the identity line
/// ([`split::tag`]) in a shard's file.
fn file_head(spec: &SweepSpec, opts: &SweepOptions) -> String {
    match opts.shard {
        None => header(spec),
        Some(sh) => format!(
            "{}\n{}",
            split::tag(&run_identity(spec, opts), sh),
            header(spec)
        ),
    }
}

/// The rows file of a running sweep, opened by [`Rows::begin`] when the folder may change.
struct Rows<'a> {
    csv_path: &'a Path,
    id_path: &'a Path,
    json_path: &'a Path,
    out: &'a Path,
    shard: Option<Shard>,
    resuming: bool,
    rec: &'a Recorded,
    head: &'a str,
    identity: String,
    /// Open for appending once begun.
    csv: Option<std::fs::File>,
    /// Rows to write when begun (the rejected members).
    pending: Vec<MemberRow>,
    summary: SweepSummary,
}

impl Rows<'_> {
    /// The first change to the folder (once; later calls do nothing). A fresh start
    /// removes the previous sweep's `sweep.json`, writes the identity, then a rows file
    /// holding its head only (renamed into place: a kill leaves the old file or a whole
    /// head, never two sweeps' files beside each other with the new rows), and removes the
    /// previous sweep's member histories. `--resume` cuts a torn last row (or rewrites a
    /// torn head). Then the rejected members' rows.
    fn begin(&mut self, on_row: &mut impl FnMut(&MemberRow)) -> Result<(), SweepError> {
        if self.csv.is_some() {
            return Ok(());
        }
        let ctx = |what: &str, path: &Path| {
            let context = format!("cannot {what} {}", path.display());
            move |error| SweepError::Output { context, error }
        };
        if !self.resuming {
            remove_if_present(self.json_path).map_err(ctx("remove", self.json_path))?;
            write_atomic(self.id_path, &self.identity).map_err(ctx("write", self.id_path))?;
            write_atomic(self.csv_path, &format!("{}\n", self.head))
                .map_err(ctx("write", self.csv_path))?;
            self.summary.stale_histories =
                remove_stale_histories(self.out, self.shard).map_err(ctx("clean", self.out))?;
        }
        let mut csv = OpenOptions::new()
            .append(true)
            .open(self.csv_path)
            .map_err(ctx("open", self.csv_path))?;
        if self.resuming && self.rec.needs_header {
            csv.set_len(0).map_err(ctx("repair", self.csv_path))?;
            write_line(&mut csv, self.head).map_err(ctx("write", self.csv_path))?;
        } else if self.resuming && self.rec.torn_bytes > 0 {
            let keep = csv
                .metadata()
                .map_err(ctx("read", self.csv_path))?
                .len()
                .saturating_sub(self.rec.torn_bytes as u64);
            csv.set_len(keep)
                .and_then(|_| csv.sync_all())
                .map_err(ctx("repair", self.csv_path))?;
        }
        self.csv = Some(csv);
        for row in std::mem::take(&mut self.pending) {
            self.write(&row, on_row)?;
        }
        Ok(())
    }

    /// Appends one row (one write of a whole line, synced before the next member is
    /// recorded) and counts it.
    fn write(
        &mut self,
        row: &MemberRow,
        on_row: &mut impl FnMut(&MemberRow),
    ) -> Result<(), SweepError> {
        self.begin(on_row)?;
        let csv = self.csv.as_mut().unwrap_or_else(|| unreachable!("begun"));
        write_line(csv, &row.csv()).map_err(|error| SweepError::Output {
            context: format!("cannot write {}", self.csv_path.display()),
            error,
        })?;
        match row.status {
            MemberStatus::Completed => self.summary.completed += 1,
            MemberStatus::Failed => self.summary.failed += 1,
            MemberStatus::Rejected => self.summary.rejected += 1,
        }
        on_row(row);
        Ok(())
    }
}

/// One row: one `write` of the whole line, then synced.
fn write_line(csv: &mut std::fs::File, line: &str) -> std::io::Result<()> {
    csv.write_all(format!("{line}\n").as_bytes())
        .and_then(|_| csv.sync_data())
}

/// The dissipation strategy `m` runs with on `exec`: its parameters' choice with `auto`
/// resolved (staggered where the GPU kernel evaluates it, monolithic on the CPU kernel);
/// `None` for a conserving scheme, which solves no dissipation scalars.
fn member_strategy(
    m: &crate::batch::Member,
    exec: &Executor,
    solve: crate::batch::SolveMode,
) -> Option<&'static str> {
    let p = &m.params;
    let gpu = matches!(exec, Executor::Gpu(_)) && p.scheme.has_gpu_kernel();
    let whole = gpu && solve == crate::batch::SolveMode::Whole;
    p.scheme
        .is_dissipative()
        .then(|| p.strategy.resolve_for(gpu, whole).name())
}
