//! The `sweep` and `bench` subcommands and the `--backend` switch of `run` (GPU batch
//! path). No physics: argument handling, progress and printing only.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};

use cosserat::batch::{BackendChoice, Executor, GpuBatcher, SolveMode};
use cosserat::integrator::{NewtonVariant, Simulation, SolveTimers, Strategy};
use cosserat::sweep::slurm::{self, JobSpec};
use cosserat::sweep::{
    check_shard_folder, load_sweep, merge_shards_from, run_sweep, MemberStatus, Shard, SweepOptions,
};

pub mod gpu;

/// Prints a status line on stdout. A stdout that cannot be written (redirected to a full
/// disk) does not stop a sweep or a merge: their results are their files, whose write
/// errors are errors.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

/// Where the element kernel runs.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq, Default)]
pub enum BackendArg {
    /// CPU kernel (members in parallel).
    #[default]
    Cpu,
    /// GPU kernel (error when no adapter with SHADER_F64 exists).
    Gpu,
    /// GPU when an f64 adapter exists, else the CPU (saying so).
    Auto,
}

impl BackendArg {
    fn choice(self) -> BackendChoice {
        match self {
            BackendArg::Cpu => BackendChoice::Cpu,
            BackendArg::Gpu => BackendChoice::Gpu,
            BackendArg::Auto => BackendChoice::Auto,
        }
    }
}

/// Newton variant (`--newton`).
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum NewtonArg {
    /// A fresh tangent and LU factorization every iteration, except (CPU path) a step's
    /// first correction far from the solution and a last one just above the tolerance,
    /// which reuse the last factorization.
    Full,
    /// A fresh tangent and LU factorization every iteration, a step's first included
    /// (what the GPU paths run for `full`).
    Fresh,
    /// Keep the tangent and its factorization while the residual contracts ≥ 5× per
    /// iteration (those iterations evaluate the residual only).
    Modified,
}

impl NewtonArg {
    /// The integrator's variant.
    pub fn variant(self) -> NewtonVariant {
        match self {
            NewtonArg::Full => NewtonVariant::Full,
            NewtonArg::Fresh => NewtonVariant::Fresh,
            NewtonArg::Modified => NewtonVariant::Modified,
        }
    }
}

/// Dissipation strategy (`--strategy`; docs/theory.md §4, docs/benchmarks.md "Inexact strategy").
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum StrategyArg {
    /// Monolithic on the CPU element kernel, staggered where a GPU evaluator is attached.
    Auto,
    /// The paper's staggered loop: freeze the scalars, Newton, re-evaluate, repeat.
    Staggered,
    /// Newton on the monolithic equations, the scalars linearized in the tangent.
    Monolithic,
    /// The monolithic equations with the frozen-scalar tangent (one solve, no rounds).
    Inexact,
}

impl StrategyArg {
    /// The integrator's strategy.
    pub fn strategy(self) -> Strategy {
        match self {
            StrategyArg::Auto => Strategy::Auto,
            StrategyArg::Staggered => Strategy::Staggered,
            StrategyArg::Monolithic => Strategy::Monolithic,
            StrategyArg::Inexact => Strategy::Inexact,
        }
    }
}

/// `auto (cpu: monolithic, gpu: staggered)`, or the one strategy's name.
fn strategy_label(s: Strategy) -> String {
    if s == Strategy::Auto {
        format!(
            "auto (cpu: {}, gpu: {})",
            s.resolve(false).name(),
            s.resolve(true).name()
        )
    } else {
        s.name().to_string()
    }
}

/// Where a GPU batch solves its Newton systems (`--solve`).
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum SolveArg {
    /// The host factorizes and solves each member's assembled system.
    Host,
    /// The device factorizes and solves the block-tridiagonal systems; only corrections,
    /// statuses and backward errors come back (docs/gpu.md, "Device solve").
    Device,
    /// As `device`, with several Newton iterations per submission: one host sync per
    /// step (docs/gpu.md, "Whole step on the device").
    Resident,
    /// As `resident`, and EM members keep their state on the device (the device advances
    /// it after each step; docs/gpu.md, "Whole step on the device").
    Whole,
}

impl SolveArg {
    /// The batch option.
    pub fn mode(self) -> SolveMode {
        match self {
            SolveArg::Host => SolveMode::Host,
            SolveArg::Device => SolveMode::Device,
            SolveArg::Resident => SolveMode::Resident,
            SolveArg::Whole => SolveMode::Whole,
        }
    }
}

/// `--solve device` needs the GPU path: an error (exit 2) on the CPU path.
pub fn check_solve(solve: SolveArg, exec: &Executor) -> Result<SolveMode> {
    if solve != SolveArg::Host && matches!(exec, Executor::Cpu) {
        let name = solve.mode().name();
        bail!("--solve {name}: the device solve runs on the GPU path; add --backend gpu (or auto with a GPU present)");
    }
    Ok(solve.mode())
}

/// Resolves `--backend`/`--adapter`, printing the note of an `auto` fallback.
pub fn executor(backend: BackendArg, adapter: Option<&str>) -> Result<Executor> {
    let (exec, note) = Executor::resolve(backend.choice(), adapter).map_err(adapter_error)?;
    if let Some(n) = note {
        eprintln!("{n}");
    }
    Ok(exec)
}

/// A GPU that cannot be had, as an error naming the option: `--adapter NAME` that matches
/// no adapter (listing those that exist, or saying there is none).
pub fn adapter_error(e: cosserat::gpu::GpuError) -> anyhow::Error {
    match e {
        cosserat::gpu::GpuError::NoAdapter {
            filter: Some(f),
            available,
        } => anyhow::anyhow!(
            "--adapter: no GPU adapter's name contains `{f}`; {}",
            if available.is_empty() {
                "this machine has no GPU adapter".to_string()
            } else {
                format!("the adapters here: {}", available.join("; "))
            }
        ),
        e => e.into(),
    }
}

/// `run --backend gpu|auto`: attaches a one-slot GPU batch to `sim` (kept alive by the
/// returned handle) and prints the backend line.
pub fn attach(
    sim: &mut Simulation,
    backend: BackendArg,
    adapter: Option<&str>,
    solve: SolveArg,
) -> Result<Option<Arc<GpuBatcher>>> {
    if backend == BackendArg::Cpu {
        check_solve(solve, &Executor::Cpu)?;
        return Ok(None);
    }
    let exec = executor(backend, adapter)?;
    let solve = check_solve(solve, &exec)?;
    println!("backend: {}", exec.describe());
    match exec {
        Executor::Cpu => Ok(None),
        Executor::Gpu(ctx) => {
            if !sim.params().scheme.has_gpu_kernel() {
                eprintln!(
                    "note: scheme {} has no GPU kernel; the run uses the CPU kernel",
                    sim.params().scheme.name()
                );
                return Ok(None);
            }
            let b = Arc::new(GpuBatcher::new(
                &ctx,
                1,
                sim.model().elements.len(),
                sim.model().n_nodes(),
            )?);
            let _ = sim.set_backend(b.clone(), 0);
            if solve.on_device() {
                b.enable_device_solve(&ctx)?;
                if solve.multi_iteration() {
                    b.set_iterations_per_submission(cosserat::batch::resident_k());
                }
                b.set_device_advance(solve == SolveMode::Whole);
                if !b.register_device(0, sim)? {
                    let why = cosserat::batch::gpu::device_solve_refusal(sim).unwrap_or("");
                    let name = solve.name();
                    bail!("--solve {name}: the device solver does not cover this scene ({why}); run it with --solve host");
                }
                // (`--solve whole`: the evaluator recorded why the steps stay on the host.)
                if let Some(why) = b.host_step_reasons().keys().next() {
                    eprintln!(
                        "note: --solve whole: this scene's steps run on the host, each Newton solve on the GPU ({why}; docs/gpu.md, \"Whole step on the device\")"
                    );
                }
            } else {
                b.register(0, sim)?;
            }
            Ok(Some(b))
        }
    }
}

/// A count that must be ≥ 1 (`--every`, `--snapshots`, `--rods`, `--jobs`, …).
pub fn at_least_one(s: &str) -> Result<usize, String> {
    match s.trim().parse::<i128>() {
        Ok(n) if n >= 1 && n <= usize::MAX as i128 => Ok(n as usize),
        Ok(n) => Err(format!("must be an integer ≥ 1 (got {n})")),
        Err(_) => Err(format!("must be an integer ≥ 1 (got `{}`)", echo(s))),
    }
}

/// A count that may be 0 (`--slots`).
pub fn at_least_zero(s: &str) -> Result<usize, String> {
    match s.trim().parse::<i128>() {
        Ok(n) if n >= 0 && n <= usize::MAX as i128 => Ok(n as usize),
        Ok(n) => Err(format!("must be an integer ≥ 0 (got {n})")),
        Err(_) => Err(format!("must be an integer ≥ 0 (got `{}`)", echo(s))),
    }
}

/// Longest text an error message echoes from the command line (in characters).
pub const MAX_ECHO_CHARS: usize = 60;

/// `s` as an error message echoes it: cut to [`MAX_ECHO_CHARS`] characters (with `…`).
pub fn echo(s: &str) -> String {
    match s.char_indices().nth(MAX_ECHO_CHARS) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}

/// Options of every member of a sweep, sharded or not (forwarded to Slurm array tasks).
#[derive(clap::Args, Debug, Clone)]
pub struct MemberOpts {
    /// Where the element kernel runs.
    #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
    pub backend: BackendArg,
    /// GPU adapter: first adapter whose name contains this (case-insensitive).
    #[arg(long)]
    pub adapter: Option<String>,
    /// Also write DIR/member_<i>/history.csv for every member.
    #[arg(long)]
    pub histories: bool,
    /// Newton variant of every member (default: each member's scene, else full).
    #[arg(long, value_enum)]
    pub newton: Option<NewtonArg>,
    /// No fallback strategy in any member (a pure strategy: the paper's staggered one with
    /// `strategy = "staggered"` in the base scene; default: each member's scene, else
    /// fallback on).
    #[arg(long)]
    pub no_fallback: bool,
    /// Step cut-back in every member: a failed step is redone as up to 2^N sub-steps
    /// (default: each member's scene, else 4; 0 = off).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=20))]
    pub cutback: Option<u8>,
    /// GPU path: where the Newton systems are solved (docs/gpu.md, "Device solve").
    #[arg(long, value_enum, default_value_t = SolveArg::Host)]
    pub solve: SolveArg,
}

impl MemberOpts {
    fn sweep_options(&self, resume: bool, shard: Option<Shard>, solve: SolveMode) -> SweepOptions {
        SweepOptions {
            solve,
            resume,
            histories: self.histories,
            workers: 0,
            newton: self.newton.map(NewtonArg::variant),
            fallback: self.no_fallback.then_some(false),
            cutback: self.cutback.map(usize::from),
            shard,
        }
    }

    /// These options as `cosserat sweep` arguments (all but `--backend`).
    fn args(&self) -> Vec<String> {
        let mut a = Vec::new();
        if let Some(ad) = &self.adapter {
            a.extend(["--adapter".into(), ad.clone()]);
        }
        if self.histories {
            a.push("--histories".into());
        }
        if let Some(n) = self.newton {
            let v = n.to_possible_value().map(|v| v.get_name().to_string());
            a.extend(["--newton".into(), v.unwrap_or_default()]);
        }
        if self.no_fallback {
            a.push("--no-fallback".into());
        }
        if let Some(c) = self.cutback {
            a.extend(["--cutback".into(), c.to_string()]);
        }
        if self.solve != SolveArg::Host {
            a.extend(["--solve".into(), self.solve.mode().name().into()]);
        }
        a
    }
}

/// Arguments of `cosserat sweep`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SweepArgs {
    /// Merge shards, or run the sweep as a Slurm job array.
    #[command(subcommand)]
    pub action: Option<SweepAction>,
    /// Sweep file (TOML: base scene + parameters to vary; docs/cli.md, "sweep").
    #[arg(required = true)]
    pub sweep: Option<PathBuf>,
    /// Output directory (members.csv, member_<i>/history.csv; shards/ when sharded).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Skip members already recorded in DIR/members.csv (DIR/shards/I-of-N.csv with
    /// --shard).
    #[arg(long)]
    pub resume: bool,
    /// Run only shard I of N (members whose index is ≡ I mod N) into
    /// DIR/shards/I-of-N.csv; `cosserat sweep merge DIR` joins the shards.
    #[arg(long, value_name = "I/N", value_parser = Shard::parse)]
    pub shard: Option<Shard>,
    #[command(flatten)]
    pub member: MemberOpts,
}

/// Subcommands of `cosserat sweep`.
#[derive(clap::Subcommand, Debug)]
pub enum SweepAction {
    /// Check that every shard in DIR/shards is present, of one sweep and complete, and
    /// write DIR/members.csv, sweep.id and sweep.json as a one-machine run does.
    Merge {
        /// The sweep's output directory (the --out of its shards).
        dir: PathBuf,
        /// The sweep file, when it is no longer where the shards recorded it (every row is
        /// checked against its members' values).
        #[arg(long, value_name = "FILE")]
        sweep: Option<PathBuf>,
    },
    /// Write DIR/sweep.sbatch, a Slurm job array with one task per shard, and print the
    /// commands to submit and merge it (`--submit`, `--wait`: do them).
    Slurm(Box<SlurmArgs>),
}

/// Arguments of `cosserat sweep slurm`.
#[derive(clap::Args, Debug)]
pub struct SlurmArgs {
    /// Sweep file.
    pub sweep: PathBuf,
    /// Number of shards (array tasks), at most the number of members.
    #[arg(long, value_parser = at_least_one)]
    pub shards: usize,
    /// Output directory, on a file system every node sees.
    #[arg(long)]
    pub out: PathBuf,
    /// Slurm partition (`#SBATCH --partition`).
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit per task (`#SBATCH --time`, e.g. 30, 2:00:00, 1-00:00).
    #[arg(long)]
    pub time: Option<String>,
    /// CPUs per task, also each task's thread count (`#SBATCH --cpus-per-task`).
    #[arg(long, value_parser = at_least_one)]
    pub cpus_per_task: Option<usize>,
    /// Memory per task's node (`#SBATCH --mem`, e.g. 4G).
    #[arg(long)]
    pub mem: Option<String>,
    /// Generic resources per task (`#SBATCH --gres`, e.g. gpu:1; use with --backend gpu).
    #[arg(long)]
    pub gres: Option<String>,
    /// At most K tasks at once (`--array=0-(N-1)%K`).
    #[arg(long, value_name = "K", value_parser = at_least_one)]
    pub max_running: Option<usize>,
    /// Job name (default: cosserat-<sweep file stem>).
    #[arg(long)]
    pub job_name: Option<String>,
    /// Further sbatch option for the script, e.g. --sbatch=--account=proj (repeatable).
    #[arg(long = "sbatch", value_name = "OPTION", allow_hyphen_values = true)]
    pub sbatch: Vec<String>,
    /// The cosserat executable the tasks run (default: this one).
    #[arg(long)]
    pub exe: Option<PathBuf>,
    /// Submit the script (`sbatch --parsable`) and print the job id.
    #[arg(long)]
    pub submit: bool,
    /// Submit, wait until every task has left the queue, then merge (implies --submit).
    #[arg(long)]
    pub wait: bool,
    #[command(flatten)]
    pub member: MemberOpts,
}

/// `cosserat sweep` (and its `merge` and `slurm` subcommands).
pub fn sweep_command(a: SweepArgs) -> Result<ExitCode> {
    match a.action {
        Some(SweepAction::Merge { dir, sweep }) => return merge_command(&dir, sweep.as_deref()),
        Some(SweepAction::Slurm(s)) => return slurm_command(*s),
        None => {}
    }
    let (Some(file), Some(out)) = (a.sweep.as_ref(), a.out.as_ref()) else {
        bail!("sweep: a sweep file and --out DIR are required");
    };
    let spec = load_sweep(file)?;
    if let Some(sh) = a.shard {
        cosserat::sweep::shard::check_count(&spec, sh)?;
    }
    let exec = executor(a.member.backend, a.member.adapter.as_deref())?;
    let scope = match a.shard {
        Some(sh) => format!(
            "shard {sh}: {} of {} members",
            sh.len_of(spec.len()),
            spec.len()
        ),
        None => format!("{} members", spec.len()),
    };
    let solve = check_solve(a.member.solve, &exec)?;
    say!(
        "sweep {}: {scope} over {} ({}), backend {}",
        spec.source,
        spec.params
            .iter()
            .map(|p| p.key.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        spec.base,
        exec.describe()
    );
    let total = a.shard.map_or(spec.len(), |sh| sh.len_of(spec.len()));
    let bar = ProgressBar::new(total as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} members  {msg}  elapsed {elapsed_precise}  ETA {eta_precise}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let (mut done, mut failed, mut rejected) = (0usize, 0usize, 0usize);
    let opts = a.member.sweep_options(a.resume, a.shard, solve);
    let summary = run_sweep(&spec, &exec, out, &opts, |row| {
        done += 1;
        match row.status {
            MemberStatus::Completed => {}
            MemberStatus::Failed => failed += 1,
            MemberStatus::Rejected => rejected += 1,
        }
        bar.inc(1);
        bar.set_message(format!("done {done}, failed {failed}, rejected {rejected}"));
    });
    // Cleared on an error too: the error line stands alone.
    bar.finish_and_clear();
    let summary = summary?;
    let csv = match a.shard {
        Some(sh) => cosserat::sweep::shard::file(out, sh, "csv"),
        None => out.join("members.csv"),
    };
    if summary.repaired_bytes > 0 {
        eprintln!(
            "note: {}: cut a torn last row ({} bytes, a member being recorded when the sweep was stopped); that member ran again",
            csv.display(),
            summary.repaired_bytes
        );
    }
    if !summary.host_steps.is_empty() {
        let why: Vec<String> = summary
            .host_steps
            .iter()
            .map(|(k, n)| format!("{n} × {k}"))
            .collect();
        eprintln!(
            "note: --solve whole: the steps of some members ran on the host, each Newton solve on the GPU ({}; docs/gpu.md, \"Whole step on the device\")",
            why.join("; ")
        );
    }
    if summary.stale_histories > 0 {
        eprintln!(
            "note: {}: removed {} member history file(s) of the previous sweep in this folder",
            out.display(),
            summary.stale_histories
        );
    }
    say!(
        "{} members: {} completed, {} failed, {} rejected, {} skipped (already recorded) in {:.2} s. Results in {}",
        summary.members,
        summary.completed,
        summary.failed,
        summary.rejected,
        summary.skipped,
        summary.wall_s,
        csv.display()
    );
    if a.shard.is_some() {
        say!(
            "when every shard has run: cosserat sweep merge {}",
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `cosserat sweep merge DIR`.
fn merge_command(dir: &std::path::Path, sweep: Option<&std::path::Path>) -> Result<ExitCode> {
    let m = merge_shards_from(dir, sweep)?;
    say!(
        "merged {} shards of {}: {} members ({} completed, {} failed, {} rejected), backend {}. Results in {}",
        m.shards,
        m.sweep,
        m.members,
        m.completed,
        m.failed,
        m.rejected,
        if m.backends.is_empty() {
            "unknown".to_string()
        } else {
            m.backends.join(" + ")
        },
        dir.join("members.csv").display()
    );
    Ok(ExitCode::SUCCESS)
}

/// An absolute form of `p` (the tasks may start in another directory).
fn absolute(p: &std::path::Path, what: &str) -> Result<PathBuf> {
    std::path::absolute(p).with_context(|| format!("{what}: cannot make {} absolute", p.display()))
}

/// `cosserat sweep slurm`.
fn slurm_command(a: SlurmArgs) -> Result<ExitCode> {
    let spec = load_sweep(&a.sweep)?;
    if a.shards > spec.len() {
        bail!(
            "--shards: {} shards for {} members: at most one shard per member",
            a.shards,
            spec.len()
        );
    }
    let opts = a.member.sweep_options(true, None, a.member.solve.mode());
    check_shard_folder(&a.out, &spec, &opts, a.shards)?;
    let exe = match &a.exe {
        Some(e) => absolute(e, "--exe")?,
        None => std::env::current_exe().context("cannot find this program's path (use --exe)")?,
    };
    let stem = a
        .sweep
        .file_stem()
        .map(|s| cosserat::paths::safe_stem(&s.to_string_lossy()))
        .unwrap_or_else(|| "sweep".into());
    let backend = a
        .member
        .backend
        .to_possible_value()
        .map(|v| v.get_name().to_string())
        .unwrap_or_else(|| "cpu".into());
    let job = JobSpec {
        sweep: absolute(&a.sweep, "SWEEP")?,
        out: absolute(&a.out, "--out")?,
        exe,
        shards: a.shards,
        job_name: a.job_name.clone().unwrap_or(format!("cosserat-{stem}")),
        partition: a.partition.clone(),
        time: a.time.clone(),
        cpus_per_task: a.cpus_per_task,
        mem: a.mem.clone(),
        gres: a.gres.clone(),
        max_running: a.max_running,
        extra: a.sbatch.clone(),
        backend,
        shard_args: a.member.args(),
    };
    // Validate every option before creating anything.
    slurm::script(&job)?;
    std::fs::create_dir_all(&job.out)
        .with_context(|| format!("cannot create {}", job.out.display()))?;
    let script = slurm::write_script(&job)?;
    let per = spec.len().div_ceil(a.shards);
    println!(
        "wrote {}: {} array tasks, task I runs shard I/{} (members ≡ I mod {}, ≤ {per} each) of {} members",
        script.display(),
        a.shards,
        a.shards,
        a.shards,
        spec.len()
    );
    println!("submit:           sbatch {}", script.display());
    println!("re-run shard I:   sbatch --array=I {}", script.display());
    println!(
        "merge when done:  {} sweep merge {}",
        job.exe.display(),
        job.out.display()
    );
    if !(a.submit || a.wait) {
        return Ok(ExitCode::SUCCESS);
    }
    let id = slurm::submit(&script, &[])?;
    println!("submitted job {id} ({} tasks)", a.shards);
    if !a.wait {
        return Ok(ExitCode::SUCCESS);
    }
    let start = std::time::Instant::now();
    let mut last = None;
    let ends = slurm::wait(&id, |q| {
        if last != Some(q) {
            println!(
                "[{:>6.1} s] job {id}: {} running, {} pending",
                start.elapsed().as_secs_f64(),
                q.running,
                q.pending
            );
            last = Some(q);
        }
    })?;
    let bad: Vec<String> = ends
        .iter()
        .filter(|t| t.state != "COMPLETED" || t.exit_code != "0:0")
        .map(|t| format!("task {} {} (exit {})", t.task, t.state, t.exit_code))
        .collect();
    println!(
        "job {id} left the queue after {:.1} s{}",
        start.elapsed().as_secs_f64(),
        if bad.is_empty() {
            String::new()
        } else {
            format!("; {}", bad.join(", "))
        }
    );
    merge_command(&job.out, None).with_context(|| {
        format!(
            "job {id} ended but its shards do not merge{}; logs in {}",
            if bad.is_empty() {
                String::new()
            } else {
                format!(" ({})", bad.join(", "))
            },
            job.out.join(slurm::LOGS_DIR).display()
        )
    })
}

/// Arguments of `cosserat bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Rods (batch members).
    #[arg(long, default_value_t = 64, value_parser = at_least_one)]
    pub rods: usize,
    /// Elements per rod (at most 1 000 000).
    #[arg(long, default_value_t = 30, value_parser = at_least_one)]
    pub elements: usize,
    /// Time steps.
    #[arg(long, default_value_t = 20, value_parser = at_least_one)]
    pub steps: usize,
    /// GPU adapter: first adapter whose name contains this.
    #[arg(long)]
    pub adapter: Option<String>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Time the CPU path only (e.g. to measure its scaling with rods and threads).
    #[arg(long)]
    pub cpu_only: bool,
    /// Time the GPU path only.
    #[arg(long, conflicts_with = "cpu_only")]
    pub gpu_only: bool,
    /// Newton variant (default: full).
    #[arg(long, value_enum, default_value_t = NewtonArg::Full)]
    pub newton: NewtonArg,
    /// The same as `--newton modified`: the option's earlier name, kept (hidden) for the
    /// scripts that still pass it.
    #[arg(long, hide = true, conflicts_with = "newton")]
    pub modified_newton: bool,
    /// Dissipation strategy of the benchmark's EDMC-2 members (default: auto, i.e.
    /// monolithic in the CPU batch, staggered in the GPU batch). The monolithic strategy
    /// evaluates its elements on the CPU kernel, also in a GPU batch.
    #[arg(long, value_enum, default_value_t = StrategyArg::Auto)]
    pub strategy: StrategyArg,
    /// GPU path: members in flight at once (0, the default: as many as fit, at most
    /// 4096).
    #[arg(long, default_value_t = 0, value_parser = at_least_zero)]
    pub slots: usize,
    /// GPU path: where the Newton systems are solved; `both` times the host-solve and the
    /// device-solve GPU batches side by side (JSON: `gpu_*` and the `device` object).
    #[arg(long, value_enum, default_value_t = BenchSolveArg::Host)]
    pub solve: BenchSolveArg,
    /// Device solve with the host adding each Newton correction (correction and residual
    /// rows read back every iteration): the earlier shape of `--solve device`, for
    /// side-by-side comparison with the device-resident default (docs/gpu.md).
    #[arg(long)]
    pub host_update: bool,
}

/// `bench --solve`.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum BenchSolveArg {
    /// Host solves.
    Host,
    /// Device solves.
    Device,
    /// Both, one after the other in this process.
    Both,
    /// Device solves, then several Newton iterations per submission (`--solve
    /// resident`), then that with EM members' states kept on the device (`--solve whole`),
    /// one after the other in this process (JSON: the `device`, `resident` and `whole`
    /// objects).
    Resident,
    /// Only `--solve whole`: EM members the device step covers run their steps entirely
    /// on the device (JSON: the `whole` object).
    Whole,
}

/// `assembly …, factor …, solve …` of summed stage timers (thread-seconds).
fn stages_line(t: &SolveTimers) -> String {
    format!(
        "assembly {:.3} s, factor {:.3} s ({} factorizations), solve {:.3} s ({} solves) [thread-s]",
        t.assemble_s, t.factor_s, t.factorizations, t.solve_s, t.solves
    )
}

/// `cosserat bench`: the same batch on the CPU path and on the GPU path.
pub fn bench_command(a: BenchArgs) -> Result<ExitCode> {
    use cosserat::bench::{BenchError, BenchOptions, BenchSolve};
    let newton = if a.modified_newton {
        NewtonArg::Modified
    } else {
        a.newton
    }
    .variant();
    let opts = BenchOptions {
        rods: a.rods,
        elements: a.elements,
        steps: a.steps,
        adapter: a.adapter.clone(),
        cpu_only: a.cpu_only,
        gpu_only: a.gpu_only,
        newton,
        strategy: a.strategy.strategy(),
        slots: a.slots,
        solve: match a.solve {
            BenchSolveArg::Host => BenchSolve::Host,
            BenchSolveArg::Device => BenchSolve::Device,
            BenchSolveArg::Both => BenchSolve::Both,
            BenchSolveArg::Resident => BenchSolve::Resident,
            BenchSolveArg::Whole => BenchSolve::Whole,
        },
        host_update: a.host_update,
    };
    // The GPU first: `--gpu-only`, or an `--adapter` named, that finds no GPU runs nothing
    // (exit 2, before the CPU path's time is spent).
    let run = match cosserat::bench::run(&opts) {
        Ok(r) => r,
        Err(BenchError::Option { key, reason }) => bail!("--{key}: {reason}"),
        Err(BenchError::Limit(e)) => {
            return Err(anyhow::Error::from(e).context("--rods × --elements"))
        }
        Err(BenchError::Scene(e)) => {
            return Err(anyhow::Error::from(e).context("bench: the benchmark cantilever"))
        }
        Err(BenchError::NoGpu(e)) if a.adapter.is_some() => return Err(adapter_error(e)),
        Err(BenchError::NoGpu(e)) => bail!("--gpu-only: no GPU to time: {e}"),
        Err(BenchError::Batch {
            what: "CPU batch",
            error,
        }) => return Err(error.into()),
        Err(BenchError::Batch { what, error }) => {
            return Err(anyhow::Error::from(error).context(what))
        }
    };
    for t in [&run.cpu, &run.gpu, &run.device, &run.resident]
        .into_iter()
        .flatten()
    {
        if let Some((i, reason)) = &t.first_failure {
            eprintln!("member {i} failed: {reason}");
        }
    }
    let (cpu, gpu, dev, adapter) = (&run.cpu, &run.gpu, &run.device, &run.adapter);
    let rod_steps = (a.rods * a.steps) as f64;
    let (cpu_rate, gpu_rate, dev_rate) = (run.cpu_rate(), run.gpu_rate(), run.device_rate());
    let ratio = gpu_rate.zip(cpu_rate).map(|(g, c)| g / c);
    let dev_ratio = dev_rate.zip(cpu_rate).map(|(g, c)| g / c);
    let (host_solve, device_solve) = match opts.solve {
        BenchSolve::Host => (true, false),
        BenchSolve::Device => (false, true),
        BenchSolve::Both => (true, true),
        BenchSolve::Resident => (false, true),
        BenchSolve::Whole => (false, false),
    };
    let resident_solve = opts.solve == BenchSolve::Resident;
    let res = &run.resident;
    let res_rate = run.resident_rate();
    let res_ratio = res_rate.zip(cpu_rate).map(|(g, c)| g / c);
    if a.json {
        println!("{}", run.json());
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "batch: {} rods × {} elements × {} steps (EDMC-2 α = 0.5, Δt = 0.01), {} Newton, strategy {}",
        a.rods,
        a.elements,
        a.steps,
        newton.name(),
        strategy_label(a.strategy.strategy()),
    );
    if let (Some(c), Some(rate)) = (cpu, cpu_rate) {
        println!(
            "cpu ({} threads): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed",
            rayon::current_num_threads(),
            c.stats.wall_s,
            rate,
            rod_steps / c.stats.wall_s,
            c.iters,
            c.failed
        );
        println!("cpu stages: {}", stages_line(&c.stages));
    }
    match (gpu, gpu_rate) {
        (Some(g), Some(rate)) => {
            let (w, k, sv) = (&g.stats, &g.stats.gpu, &g.stats.serve);
            let ratio = ratio.map_or_else(String::new, |r| format!("; ratio gpu/cpu {r:.2}"));
            println!(
                "gpu ({adapter}): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed{ratio}",
                w.wall_s, rate, rod_steps / w.wall_s, g.iters, g.failed
            );
            let evals = sv.element_evals.max(1) as f64;
            println!(
                "gpu time: pipeline setup {:.3} s, member set-up {:.3} s, member phases {:.3} s, pack {:.3} s, upload {:.3} s, kernel+assembly+copy {:.3} s, readback {:.3} s, unpack {:.3} s",
                w.setup_s, w.admit_s, w.host_s, sv.pack_s, k.upload_s, k.kernel_s, k.readback_s, k.unpack_s
            );
            println!(
                "gpu traffic: {} dispatches over {} slots, {} member evaluations ({} with tangent); per element evaluation {:.0} B up, {:.0} B down, kernel {:.2} µs",
                k.dispatches,
                w.slots,
                sv.requests,
                sv.tangent_requests,
                k.bytes_up as f64 / evals,
                k.bytes_down as f64 / evals,
                1e6 * k.kernel_s / evals
            );
            println!("gpu stages: {}", stages_line(&g.stages));
        }
        _ if host_solve => println!("gpu: not run ({adapter})"),
        _ => {}
    }
    match (dev, dev_rate) {
        (Some(g), Some(rate)) => {
            let (w, k, sv) = (&g.stats, &g.stats.gpu, &g.stats.serve);
            let ratio =
                dev_ratio.map_or_else(String::new, |r| format!("; ratio device/cpu {r:.2}"));
            println!(
                "gpu, device solve ({adapter}): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed{ratio}",
                w.wall_s, rate, rod_steps / w.wall_s, g.iters, g.failed
            );
            let reqs = sv.requests.max(1) as f64;
            println!(
                "device solve: {} members on the device, {} on the host; {} dispatches; per member-iteration {:.0} B up, {:.0} B down; member phases {:.3} s, kernel+solve {:.3} s, readback {:.3} s",
                w.device_members.0,
                w.device_members.1,
                k.dispatches,
                k.bytes_up as f64 / reqs,
                k.bytes_down as f64 / reqs,
                w.host_s,
                k.kernel_s,
                k.readback_s
            );
            if sv.resident_iterations > 0 {
                println!(
                    "device-resident Newton: {} iterations at {:.0} B down each; iterates back: {} with their report, {} fetched alone, {:.0} B each",
                    sv.resident_iterations,
                    sv.resident_bytes_down as f64 / sv.resident_iterations as f64,
                    sv.iterates_sent,
                    sv.fetches,
                    sv.fetch_bytes_down as f64 / (sv.fetches + sv.iterates_sent).max(1) as f64
                );
            }
            println!("device solve stages: {}", stages_line(&g.stages));
        }
        _ if device_solve => println!("gpu, device solve: not run ({adapter})"),
        _ => {}
    }
    if let (Some(g), Some(rate)) = (&res, res_rate) {
        let (w, k, sv) = (&g.stats, &g.stats.gpu, &g.stats.serve);
        let ratio = res_ratio.map_or_else(String::new, |r| format!("; ratio resident/cpu {r:.2}"));
        println!(
            "gpu, resident ({adapter}, K = {}): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed{ratio}",
            cosserat::batch::resident_k(), w.wall_s, rate, rod_steps / w.wall_s, g.iters, g.failed
        );
        let member_steps = rod_steps.max(1.0);
        println!(
            "resident: {:.2} host syncs per step, {:.0} host thread µs per member-step, {:.0} B per member-step over the bus; {} Newton solves in {} multi-iteration dispatches ({} device iterations, {} answered without a dispatch, {} mismatches)",
            sv.dispatches as f64 / a.steps.max(1) as f64,
            1e6 * (w.host_s * rayon::current_num_threads() as f64 + w.serve_thread_s) / member_steps,
            (k.bytes_up + k.bytes_down) as f64 / member_steps,
            sv.multi_solves,
            sv.multi_dispatches,
            sv.multi_iterations,
            sv.multi_answers,
            sv.multi_mismatches
        );
    } else if resident_solve {
        println!("gpu, resident: not run ({adapter})");
    }
    if let Some(g) = &run.whole {
        let (w, k, sv) = (&g.stats, &g.stats.gpu, &g.stats.serve);
        let member_steps = rod_steps.max(1.0);
        println!(
            "gpu, whole ({adapter}): {:.3} s ({:.0} rod-steps/s), {} Newton iterations, {} failed; {} device steps ({} handed to the host); {:.2} host syncs per step, {:.1} host thread µs per member-step ({:.1} the host's own, {:.1} in the driver), {:.0} B per member-step over the bus",
            w.wall_s,
            rod_steps / w.wall_s,
            g.iters,
            g.failed,
            sv.device_steps,
            sv.device_step_handoffs,
            sv.dispatches as f64 / a.steps.max(1) as f64,
            1e6 * (w.host_s * rayon::current_num_threads() as f64 + w.serve_thread_s) / member_steps,
            1e6 * (w.member_cpu_s + w.serve_thread_s - w.serve_driver_s) / member_steps,
            1e6 * w.serve_driver_s / member_steps,
            (k.bytes_up + k.bytes_down) as f64 / member_steps,
        );
    } else if opts.solve == BenchSolve::Whole {
        println!("gpu, whole: not run ({adapter})");
    }
    Ok(ExitCode::SUCCESS)
}
