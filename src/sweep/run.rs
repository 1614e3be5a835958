//! Running a sweep: members as one batch, `members.csv` appended as they finish,
//! `--resume` skipping members already recorded, optional per-member histories.

use std::collections::HashSet;
use std::fs::OpenOptions;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;

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
    /// Members in the sweep.
    pub members: usize,
    /// Members skipped because `members.csv` already had them (`--resume`).
    pub skipped: usize,
    /// Members completed in this invocation.
    pub completed: usize,
    /// Members failed in this invocation.
    pub failed: usize,
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

fn csv_escape(s: &str) -> String {
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
    let mut cols: Vec<String> = CSV_COLUMNS.iter().map(|s| s.to_string()).collect();
    cols.extend(spec.params.iter().map(|p| p.key.clone()));
    cols.push("reason".into());
    cols.join(",")
}

/// Member indices already recorded in `path` (whose header must be this sweep's).
fn recorded(path: &Path, head: &str) -> Result<HashSet<usize>, SweepError> {
    let io = |error| SweepError::Output {
        context: format!("cannot read {}", path.display()),
        error,
    };
    let f = std::fs::File::open(path).map_err(io)?;
    let mut lines = BufReader::new(f).lines();
    match lines.next() {
        Some(Ok(h)) if h == head => {}
        Some(Ok(h)) => {
            return Err(SweepError::Invalid {
                file: path.display().to_string(),
                location: Some((1, 1)),
                key: "(header)".into(),
                reason: format!("--resume: columns `{h}` are not this sweep's `{head}`"),
            })
        }
        Some(Err(e)) => return Err(io(e)),
        None => return Ok(HashSet::new()),
    }
    let mut done = HashSet::new();
    for l in lines {
        let l = l.map_err(io)?;
        if let Some(Ok(i)) = l.split(',').next().map(|x| x.parse::<usize>()) {
            done.insert(i);
        }
    }
    Ok(done)
}

/// Runs every member of `spec` not yet recorded, appending one row per finished member
/// to `out/members.csv` (flushed at once, so an interrupted sweep loses nothing), then
/// writes `out/sweep.json` (counts of this invocation, backend and adapter).
/// `on_row` sees each row (progress display).
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
    std::fs::create_dir_all(out).map_err(ctx(format!("cannot create {}", out.display())))?;
    let csv_path = out.join("members.csv");
    let head = header(spec);
    let done = if opts.resume && csv_path.exists() {
        recorded(&csv_path, &head)?
    } else {
        HashSet::new()
    };
    let fresh = !(opts.resume && csv_path.exists());
    let mut csv = OpenOptions::new()
        .create(true)
        .append(!fresh)
        .write(true)
        .truncate(fresh)
        .open(&csv_path)
        .map_err(ctx(format!("cannot open {}", csv_path.display())))?;
    let wr = |csv: &mut std::fs::File, line: &str| {
        writeln!(csv, "{line}")
            .and_then(|_| csv.flush())
            .map_err(ctx(format!("cannot write {}", csv_path.display())))
    };
    if fresh {
        wr(&mut csv, &head)?;
    }
    let mut summary = SweepSummary {
        members: spec.len(),
        skipped: done.len(),
        ..Default::default()
    };
    // Build the members; a member whose values the scene rejects is a failed row.
    let mut members = Vec::new();
    let mut ids = Vec::new();
    for i in (0..spec.len()).filter(|i| !done.contains(i)) {
        match spec.member_scene(i) {
            Ok(scene) => {
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
            ..Default::default()
        },
        |r: MemberResult| {
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
            match o.status {
                RunStatus::Completed => summary.completed += 1,
                RunStatus::Failed => summary.failed += 1,
            }
            if write_err.is_none() {
                if let Err(e) = wr(&mut csv, &row.csv()) {
                    write_err = Some(e);
                }
            }
            if opts.histories && write_err.is_none() {
                let dir = out.join(format!("member_{id}"));
                let res = std::fs::create_dir_all(&dir)
                    .map_err(|e| e.to_string())
                    .and_then(|_| {
                        let mut h = HistoryWriter::create(&dir.join("history.csv"))
                            .map_err(|e| e.to_string())?;
                        r.history
                            .iter()
                            .try_for_each(|rec| h.push(rec))
                            .map_err(|e| e.to_string())
                    });
                if let Err(e) = res {
                    write_err = Some(SweepError::Output {
                        context: format!("cannot write {}", dir.display()),
                        error: std::io::Error::other(e),
                    });
                }
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
        "base": spec.base,
        "mode": format!("{:?}", spec.mode).to_lowercase(),
        "parameters": spec.params.iter().map(|p| p.key.clone()).collect::<Vec<_>>(),
        "members": summary.members,
        "completed": summary.completed,
        "failed": summary.failed,
        "skipped": summary.skipped,
        "backend": exec.describe(),
        "wall_s": summary.wall_s,
    });
    let path = out.join("sweep.json");
    std::fs::write(&path, format!("{info:#}\n"))
        .map_err(ctx(format!("cannot write {}", path.display())))?;
    Ok(summary)
}
