//! Sharded sweeps as Slurm job arrays: the job script (one array task per shard), its
//! submission (`sbatch --parsable`) and waiting for the array to leave the queue
//! (`squeue`, then `scontrol show job` for each task's end state). Nothing here runs
//! unless called; the rest of the program never needs Slurm.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Name of the job script `cosserat sweep slurm` writes into the output folder.
pub const SCRIPT_FILE: &str = "sweep.sbatch";

/// Folder (inside the output folder) of the tasks' logs, `shard-I.log`.
pub const LOGS_DIR: &str = "logs";

/// Environment variable that overrides the script's `--backend` at submission
/// (`sbatch --export=ALL,COSSERAT_BACKEND=gpu --gres=gpu:1 --array=0-1 DIR/sweep.sbatch`).
pub const BACKEND_VAR: &str = "COSSERAT_BACKEND";

/// Errors of the Slurm helpers.
#[derive(Debug, thiserror::Error)]
pub enum SlurmError {
    /// A job-script option has a value Slurm would misread.
    #[error("{option}: {reason}")]
    Option {
        /// The option, e.g. `--time`.
        option: String,
        /// Why.
        reason: String,
    },
    /// A Slurm command could not be started (not installed, not on PATH).
    #[error(
        "cannot run `{program}` ({error}): is Slurm installed here, and is this a submit host?"
    )]
    Missing {
        /// The program.
        program: String,
        /// The underlying error.
        #[source]
        error: std::io::Error,
    },
    /// A Slurm command failed.
    #[error("`{command}` failed ({status}): {stderr}")]
    Failed {
        /// The command line.
        command: String,
        /// Its exit status.
        status: String,
        /// What it printed on stderr.
        stderr: String,
    },
    /// Writing the job script failed.
    #[error("cannot write {path}: {error}")]
    Write {
        /// The path.
        path: String,
        /// The underlying error.
        #[source]
        error: std::io::Error,
    },
}

/// What goes into the job script.
#[derive(Clone, Debug, Default)]
pub struct JobSpec {
    /// The sweep file (absolute: tasks may start in another directory).
    pub sweep: PathBuf,
    /// The output folder (absolute, on a file system every node sees).
    pub out: PathBuf,
    /// The `cosserat` executable the tasks run (absolute).
    pub exe: PathBuf,
    /// Number of shards = array tasks.
    pub shards: usize,
    /// `--job-name`.
    pub job_name: String,
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time` (Slurm's forms: `MM`, `HH:MM:SS`, `D-HH:MM`, …).
    pub time: Option<String>,
    /// `--cpus-per-task` (also the task's thread count, `RAYON_NUM_THREADS`).
    pub cpus_per_task: Option<usize>,
    /// `--mem` (per node, e.g. `4G`).
    pub mem: Option<String>,
    /// `--gres` (e.g. `gpu:1`).
    pub gres: Option<String>,
    /// At most this many tasks at once (`--array=0-(N-1)%K`).
    pub max_running: Option<usize>,
    /// Further `#SBATCH` lines, each an sbatch option (`--account=proj`, `--qos=low`).
    pub extra: Vec<String>,
    /// The backend of every shard (`cpu`, `gpu`, `auto`); [`BACKEND_VAR`] overrides it.
    pub backend: String,
    /// Further arguments of every shard's `cosserat sweep` (`--newton modified`, …).
    pub shard_args: Vec<String>,
}

/// A value that goes on an `#SBATCH` line: one token, printable, not empty.
fn directive_value(option: &str, v: &str) -> Result<(), SlurmError> {
    let bad = |reason: &str| SlurmError::Option {
        option: option.to_string(),
        reason: format!("{reason} (got {v:?})"),
    };
    if v.is_empty() {
        return Err(bad("must not be empty"));
    }
    if v.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return Err(bad(
            "must be one word without spaces or control characters (it becomes an #SBATCH line)",
        ));
    }
    Ok(())
}

/// Quotes a word for the shell (single quotes).
fn sh_quote(s: &str) -> String {
    if !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"/._-+=:,@%".contains(&b))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// A path for the shell and for `#SBATCH` lines, which Slurm does not unquote.
fn path_text(option: &str, p: &Path) -> Result<String, SlurmError> {
    let s = p.to_str().ok_or_else(|| SlurmError::Option {
        option: option.to_string(),
        reason: format!("{} is not valid UTF-8", p.display()),
    })?;
    if s.chars().any(|c| c.is_control()) {
        return Err(SlurmError::Option {
            option: option.to_string(),
            reason: format!("{s:?} holds control characters"),
        });
    }
    Ok(s.to_string())
}

/// The job script: an array of `shards` tasks, task I running shard I/N with `--resume`
/// (so a requeued or resubmitted task goes on where it stopped), logs appended to
/// `OUT/logs/shard-I.log`.
pub fn script(job: &JobSpec) -> Result<String, SlurmError> {
    if job.shards == 0 {
        return Err(SlurmError::Option {
            option: "--shards".into(),
            reason: "must be ≥ 1".into(),
        });
    }
    let out = path_text("--out", &job.out)?;
    let sweep = path_text("SWEEP", &job.sweep)?;
    let exe = path_text("--exe", &job.exe)?;
    let logs = job.out.join(LOGS_DIR);
    let logs = path_text("--out", &logs)?;
    if logs.contains([' ', '%']) {
        return Err(SlurmError::Option {
            option: "--out".into(),
            reason: format!(
                "{logs} holds a space or `%`, which #SBATCH --output cannot take: choose another folder"
            ),
        });
    }
    directive_value("--job-name", &job.job_name)?;
    let n = job.shards;
    let mut d: Vec<String> = vec![
        format!("--job-name={}", job.job_name),
        match job.max_running {
            Some(k) => format!("--array=0-{}%{k}", n - 1),
            None => format!("--array=0-{}", n - 1),
        },
        format!("--output={logs}/shard-%a.log"),
        "--open-mode=append".into(),
        "--requeue".into(),
    ];
    let opt = |name: &str, v: &Option<String>, d: &mut Vec<String>| -> Result<(), SlurmError> {
        if let Some(v) = v {
            directive_value(&format!("--{name}"), v)?;
            d.push(format!("--{name}={v}"));
        }
        Ok(())
    };
    opt("partition", &job.partition, &mut d)?;
    opt("time", &job.time, &mut d)?;
    if let Some(c) = job.cpus_per_task {
        d.push(format!("--cpus-per-task={c}"));
    }
    opt("mem", &job.mem, &mut d)?;
    opt("gres", &job.gres, &mut d)?;
    for e in &job.extra {
        directive_value("--sbatch", e)?;
        if !e.starts_with('-') {
            return Err(SlurmError::Option {
                option: "--sbatch".into(),
                reason: format!("must be an sbatch option such as --account=NAME (got {e:?})"),
            });
        }
        d.push(e.clone());
    }
    let mut cmd = vec![
        sh_quote(&exe),
        "sweep".into(),
        sh_quote(&sweep),
        "--out".into(),
        sh_quote(&out),
        "--shard".into(),
        format!("\"$SLURM_ARRAY_TASK_ID/{n}\""),
        "--resume".into(),
        "--backend".into(),
        format!("\"${{{BACKEND_VAR}:-{}}}\"", job.backend),
    ];
    cmd.extend(job.shard_args.iter().map(|a| sh_quote(a)));
    let mut s = String::new();
    s.push_str("#!/bin/bash\n");
    s.push_str(&format!(
        "# Written by `cosserat sweep slurm`: {n} array tasks, task I runs shard I/{n} of\n# {sweep}\n# (the members whose index is ≡ I mod {n}) into {out}/shards/.\n"
    ));
    s.push_str(&format!(
        "#   submit:            sbatch {}\n",
        sh_quote(&format!("{out}/{SCRIPT_FILE}"))
    ));
    s.push_str(&format!(
        "#   re-run shard I:    sbatch --array=I {}   (it resumes; nothing is lost or run twice)\n",
        sh_quote(&format!("{out}/{SCRIPT_FILE}"))
    ));
    s.push_str(&format!(
        "#   on GPUs:           sbatch --gres=gpu:1 --export=ALL,{BACKEND_VAR}=gpu {}\n",
        sh_quote(&format!("{out}/{SCRIPT_FILE}"))
    ));
    s.push_str(&format!(
        "#   when all are done: {} sweep merge {}\n",
        sh_quote(&exe),
        sh_quote(&out)
    ));
    for line in &d {
        s.push_str(&format!("#SBATCH {line}\n"));
    }
    s.push_str("set -eu\n");
    s.push_str("# One worker thread per allocated CPU (Slurm may not pin the task to its CPUs).\n");
    s.push_str("export RAYON_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n");
    s.push_str(&format!(
        "echo \"[$(date -u +%FT%TZ)] shard $SLURM_ARRAY_TASK_ID/{n}: job ${{SLURM_JOB_ID:-?}} on $(hostname), restart ${{SLURM_RESTART_COUNT:-0}}, backend ${{{BACKEND_VAR}:-{}}}\"\n",
        job.backend
    ));
    s.push_str(&format!("exec {}\n", cmd.join(" ")));
    Ok(s)
}

/// Writes [`script`] to `OUT/sweep.sbatch` (and creates `OUT/logs/`); returns its path.
pub fn write_script(job: &JobSpec) -> Result<PathBuf, SlurmError> {
    let text = script(job)?;
    let werr = |path: &Path| {
        let path = path.display().to_string();
        move |error| SlurmError::Write { path, error }
    };
    let logs = job.out.join(LOGS_DIR);
    std::fs::create_dir_all(&logs).map_err(werr(&logs))?;
    let path = job.out.join(SCRIPT_FILE);
    super::run::write_atomic(&path, &text).map_err(werr(&path))?;
    Ok(path)
}

/// Runs a Slurm command, returning its stdout.
fn slurm(program: &str, args: &[&str]) -> Result<String, SlurmError> {
    let o = Command::new(program)
        .args(args)
        .output()
        .map_err(|error| SlurmError::Missing {
            program: program.to_string(),
            error,
        })?;
    if !o.status.success() {
        return Err(SlurmError::Failed {
            command: format!("{program} {}", args.join(" ")),
            status: o.status.to_string(),
            stderr: String::from_utf8_lossy(&o.stderr).trim().to_string(),
        });
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

/// Submits a job script with `sbatch --parsable` (plus `args`, e.g. `--array=2`) and
/// returns the job id.
pub fn submit(script: &Path, args: &[&str]) -> Result<String, SlurmError> {
    let path = script.to_string_lossy();
    let mut all = vec!["--parsable"];
    all.extend_from_slice(args);
    all.push(&path);
    let out = slurm("sbatch", &all)?;
    // `--parsable` prints `JOBID` or `JOBID;CLUSTER`.
    let id = out
        .trim()
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_string();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(SlurmError::Failed {
            command: format!("sbatch {}", all.join(" ")),
            status: "0".into(),
            stderr: format!("unexpected output {:?} (expected a job id)", out.trim()),
        });
    }
    Ok(id)
}

/// Tasks of a job still in the queue.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Queue {
    /// Tasks waiting to start (a pending array range counts each task).
    pub pending: usize,
    /// Tasks running (or completing).
    pub running: usize,
}

/// How one task of a job ended (from `scontrol show job`, while Slurm keeps the record).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TaskEnd {
    /// The array task id (the shard index).
    pub task: usize,
    /// `COMPLETED`, `FAILED`, `CANCELLED`, `TIMEOUT`, …
    pub state: String,
    /// `EXIT:SIGNAL`.
    pub exit_code: String,
}

/// Number of tasks in an `squeue` array id such as `12_[0-3,5%2]`, `12_4` or `12`.
fn task_count(id: &str) -> usize {
    let Some(ranges) = id.split_once("_[").map(|(_, r)| r.trim_end_matches(']')) else {
        return 1;
    };
    let ranges = ranges.split('%').next().unwrap_or("");
    ranges
        .split(',')
        .map(|r| match r.split_once('-') {
            Some((a, b)) => match (a.parse::<usize>(), b.parse::<usize>()) {
                (Ok(a), Ok(b)) if b >= a => b - a + 1,
                _ => 1,
            },
            None => 1,
        })
        .sum()
}

/// The job's tasks still queued; `None` once none is.
pub fn queue(job: &str) -> Result<Option<Queue>, SlurmError> {
    match slurm("squeue", &["-h", "-j", job, "-o", "%i %t"]) {
        Ok(text) => {
            let mut q = Queue::default();
            for l in text.lines() {
                let mut f = l.split_whitespace();
                let (Some(id), Some(state)) = (f.next(), f.next()) else {
                    continue;
                };
                match state {
                    "PD" => q.pending += task_count(id),
                    _ => q.running += task_count(id),
                }
            }
            Ok((q.pending + q.running > 0).then_some(q))
        }
        // A job that left the queue long ago is unknown to squeue.
        Err(SlurmError::Failed { stderr, .. }) if stderr.contains("Invalid job id") => Ok(None),
        Err(e) => Err(e),
    }
}

/// Each task's end state, while Slurm still holds the records (`MinJobAge`); empty when it
/// no longer does.
pub fn task_ends(job: &str) -> Vec<TaskEnd> {
    let Ok(text) = slurm("scontrol", &["-o", "show", "job", job]) else {
        return vec![];
    };
    let field = |l: &str, k: &str| {
        l.split_whitespace()
            .find_map(|w| w.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            .map(str::to_string)
    };
    let mut ends: Vec<TaskEnd> = text
        .lines()
        .filter_map(|l| {
            Some(TaskEnd {
                task: field(l, "ArrayTaskId")?.parse().ok()?,
                state: field(l, "JobState")?,
                exit_code: field(l, "ExitCode").unwrap_or_default(),
            })
        })
        .collect();
    ends.sort_by_key(|t| t.task);
    ends
}

/// Waits until no task of `job` is queued or running, polling `squeue` every 0.5 s at
/// first and up to every 10 s on long waits (`on_poll` sees each answer), then returns each
/// task's end state ([`task_ends`]). A controller that does not answer for 5 minutes in a
/// row is an error.
pub fn wait(job: &str, mut on_poll: impl FnMut(Queue)) -> Result<Vec<TaskEnd>, SlurmError> {
    let start = Instant::now();
    let mut last_ok = Instant::now();
    loop {
        match queue(job) {
            Ok(None) => break,
            Ok(Some(q)) => {
                last_ok = Instant::now();
                on_poll(q);
            }
            Err(e @ SlurmError::Missing { .. }) => return Err(e),
            Err(e) if last_ok.elapsed() > Duration::from_secs(300) => return Err(e),
            Err(_) => {}
        }
        let t = start.elapsed().as_secs_f64();
        std::thread::sleep(Duration::from_secs_f64((0.5 + t / 30.0).min(10.0)));
    }
    Ok(task_ends(job))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_ids_count_their_tasks() {
        assert_eq!(task_count("12"), 1);
        assert_eq!(task_count("12_3"), 1);
        assert_eq!(task_count("12_[0-3]"), 4);
        assert_eq!(task_count("12_[1-3,7,9-10%2]"), 6);
    }

    #[test]
    fn quoting() {
        assert_eq!(sh_quote("/a/b-c.toml"), "/a/b-c.toml");
        assert_eq!(sh_quote("/a b/it's"), "'/a b/it'\\''s'");
    }
}
