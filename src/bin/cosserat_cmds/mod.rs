//! The `sweep` and `bench` subcommands and the `--backend` switch of `run` (GPU batch
//! path). No physics: argument handling, progress and printing only.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};

use cosserat::batch::{
    bench_members, run_members, BackendChoice, BatchOptions, BatchStats, Executor, GpuBatcher,
};
use cosserat::gpu::kernel::KernelTimers;
use cosserat::integrator::{Simulation, SolveTimers};
use cosserat::observe::record::RunStatus;
use cosserat::sweep::{load_sweep, run_sweep, SweepOptions};

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

/// Resolves `--backend`/`--adapter`, printing the note of an `auto` fallback.
pub fn executor(backend: BackendArg, adapter: Option<&str>) -> Result<Executor> {
    let (exec, note) = Executor::resolve(backend.choice(), adapter)?;
    if let Some(n) = note {
        eprintln!("{n}");
    }
    Ok(exec)
}

/// `run --backend gpu|auto`: attaches a one-slot GPU batch to `sim` (kept alive by the
/// returned handle) and prints the backend line.
pub fn attach(
    sim: &mut Simulation,
    backend: BackendArg,
    adapter: Option<&str>,
) -> Result<Option<Arc<GpuBatcher>>> {
    if backend == BackendArg::Cpu {
        return Ok(None);
    }
    let exec = executor(backend, adapter)?;
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
            b.register(0, sim)?;
            let _ = sim.set_backend(b.clone(), 0);
            Ok(Some(b))
        }
    }
}

/// A count that must be ≥ 1 (`--every`, `--snapshots`, `--rods`, …).
pub fn at_least_one(s: &str) -> Result<usize, String> {
    match s.trim().parse::<i128>() {
        Ok(n) if n >= 1 && n <= usize::MAX as i128 => Ok(n as usize),
        Ok(n) => Err(format!("must be an integer ≥ 1 (got {n})")),
        Err(_) => Err(format!("must be an integer ≥ 1 (got `{s}`)")),
    }
}

/// Arguments of `cosserat sweep`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Sweep file (TOML: base scene + parameters to vary; README, "Sweeps").
    pub sweep: PathBuf,
    /// Output directory (members.csv, member_<i>/history.csv).
    #[arg(long)]
    pub out: PathBuf,
    /// Where the element kernel runs.
    #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
    pub backend: BackendArg,
    /// GPU adapter: first adapter whose name contains this (case-insensitive).
    #[arg(long)]
    pub adapter: Option<String>,
    /// Skip members already recorded in DIR/members.csv.
    #[arg(long)]
    pub resume: bool,
    /// Also write DIR/member_<i>/history.csv for every member.
    #[arg(long)]
    pub histories: bool,
}

/// `cosserat sweep`.
pub fn sweep_command(a: SweepArgs) -> Result<ExitCode> {
    let spec = load_sweep(&a.sweep)?;
    let exec = executor(a.backend, a.adapter.as_deref())?;
    println!(
        "sweep {}: {} members over {} ({}), backend {}",
        spec.source,
        spec.len(),
        spec.params
            .iter()
            .map(|p| p.key.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        spec.base,
        exec.describe()
    );
    let bar = ProgressBar::new(spec.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} members  {msg}  elapsed {elapsed_precise}  ETA {eta_precise}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let (mut done, mut failed) = (0usize, 0usize);
    let opts = SweepOptions {
        resume: a.resume,
        histories: a.histories,
        workers: 0,
    };
    let summary = run_sweep(&spec, &exec, &a.out, &opts, |row| {
        done += 1;
        if row.status == RunStatus::Failed {
            failed += 1;
        }
        bar.inc(1);
        bar.set_message(format!("done {done}, failed {failed}"));
    })?;
    bar.finish_and_clear();
    if summary.repaired_bytes > 0 {
        eprintln!(
            "note: {}: cut a torn last row ({} bytes, a member being recorded when the sweep was stopped); that member ran again",
            a.out.join("members.csv").display(),
            summary.repaired_bytes
        );
    }
    if summary.stale_histories > 0 {
        eprintln!(
            "note: {}: removed {} member history file(s) of the previous sweep in this folder",
            a.out.display(),
            summary.stale_histories
        );
    }
    println!(
        "{} members: {} completed, {} failed, {} skipped (already recorded) in {:.2} s. Results in {}",
        summary.members,
        summary.completed,
        summary.failed,
        summary.skipped,
        summary.wall_s,
        a.out.join("members.csv").display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Arguments of `cosserat bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Rods (batch members).
    #[arg(long, default_value_t = 64, value_parser = at_least_one, allow_negative_numbers = true)]
    pub rods: usize,
    /// Elements per rod (at most 1 000 000).
    #[arg(long, default_value_t = 30, value_parser = at_least_one, allow_negative_numbers = true)]
    pub elements: usize,
    /// Time steps.
    #[arg(long, default_value_t = 20, value_parser = at_least_one, allow_negative_numbers = true)]
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
    /// Modified Newton: reuse the tangent while the residual contracts by ≥ 5× per
    /// iteration.
    #[arg(long)]
    pub modified_newton: bool,
}

/// One timed batch: its stats, Newton iterations, failed members and the members' summed
/// Newton stage timers.
struct Timed {
    stats: BatchStats,
    iters: usize,
    failed: usize,
    stages: SolveTimers,
}

fn timed(
    members: &[cosserat::batch::Member],
    exec: &Executor,
    modified_newton: bool,
) -> Result<Timed> {
    let (mut iters, mut failed) = (0usize, 0usize);
    let mut stages = SolveTimers::default();
    let opts = BatchOptions {
        modified_newton,
        ..Default::default()
    };
    let stats = run_members(members, exec, opts, |r| {
        iters += r.outcome.newton_iters_total;
        stages.add(&r.outcome.timers);
        if r.outcome.status == RunStatus::Failed {
            if failed == 0 {
                eprintln!(
                    "member {} failed: {}",
                    r.index,
                    r.outcome.reason.as_deref().unwrap_or("")
                );
            }
            failed += 1;
        }
    })?;
    Ok(Timed {
        stats,
        iters,
        failed,
        stages,
    })
}

/// `assembly …, factor …, solve …` of summed stage timers (thread-seconds).
fn stages_line(t: &SolveTimers) -> String {
    format!(
        "assembly {:.3} s, factor {:.3} s ({} factorizations), solve {:.3} s ({} solves) [thread-s]",
        t.assemble_s, t.factor_s, t.factorizations, t.solve_s, t.solves
    )
}

/// The stage timers as JSON fields prefixed with `p`.
fn stages_json(obj: &mut serde_json::Value, p: &str, t: &SolveTimers) {
    obj[format!("{p}_assemble_s")] = t.assemble_s.into();
    obj[format!("{p}_factor_s")] = t.factor_s.into();
    obj[format!("{p}_solve_s")] = t.solve_s.into();
    obj[format!("{p}_factorizations")] = t.factorizations.into();
    obj[format!("{p}_solves")] = t.solves.into();
}

/// Bytes uploaded and read back per element slot per dispatch (`elements` slots: every
/// member in flight at once).
fn per_element_dispatch(t: &KernelTimers, elements: usize) -> (f64, f64) {
    let n = (t.dispatches as f64 * elements as f64).max(1.0);
    (t.bytes_up as f64 / n, t.bytes_down as f64 / n)
}

/// `cosserat bench`: the same batch on the CPU path and on the GPU path.
pub fn bench_command(a: BenchArgs) -> Result<ExitCode> {
    use cosserat::scene::limits;
    if a.elements > limits::MAX_SCENE_ELEMENTS {
        bail!(
            "--elements: {} elements per rod, above the limit of {} for one scene",
            a.elements,
            limits::MAX_SCENE_ELEMENTS
        );
    }
    if a.rods as u64 > limits::MAX_MEMBERS {
        bail!(
            "--rods: {} rods, above the limit of {} members per batch",
            a.rods,
            limits::MAX_MEMBERS
        );
    }
    limits::check_memory("bench", a.rods as u64, a.elements as u64)
        .context("--rods × --elements")?;
    let members = bench_members(a.rods, a.elements, a.steps);
    // Fail loudly rather than time another size than asked.
    if let Some(m) = members
        .iter()
        .find(|m| m.model.elements.len() != a.elements)
    {
        bail!(
            "bench: the cantilever was built with {} elements, not the {} asked for",
            m.model.elements.len(),
            a.elements
        );
    }
    let work = (a.rods * a.elements * a.steps) as f64;
    let rod_steps = (a.rods * a.steps) as f64;
    let cpu = timed(&members, &Executor::Cpu, a.modified_newton)?;
    let cpu_rate = work / cpu.stats.wall_s;
    let gpu_exec = if a.cpu_only {
        Ok((Executor::Cpu, None))
    } else {
        Executor::resolve(BackendChoice::Gpu, a.adapter.as_deref())
    };
    let (adapter, f64_ok, gpu) = match &gpu_exec {
        Ok((exec @ Executor::Gpu(ctx), _)) => {
            let r = timed(&members, exec, a.modified_newton).context("GPU batch")?;
            (ctx.describe(), ctx.is_f64(), Some(r))
        }
        Ok((Executor::Cpu, _)) => ("none".into(), false, None),
        Err(e) => (format!("none ({e})"), false, None),
    };
    let gpu_rate = gpu.as_ref().map(|g| work / g.stats.wall_s);
    if a.json {
        let mut obj = serde_json::json!({
            "rods": a.rods,
            "elements": a.elements,
            "steps": a.steps,
            "cpu_element_steps_per_s": cpu_rate,
            "gpu_element_steps_per_s": gpu_rate,
            "cpu_rod_steps_per_s": rod_steps / cpu.stats.wall_s,
            "gpu_rod_steps_per_s": gpu.as_ref().map(|g| rod_steps / g.stats.wall_s),
            "ratio": gpu_rate.map(|g| g / cpu_rate),
            "adapter": adapter,
            "f64": f64_ok,
            "cpu_threads": rayon::current_num_threads(),
            "modified_newton": a.modified_newton,
            "cpu_wall_s": cpu.stats.wall_s,
            "cpu_newton_iters": cpu.iters,
            "cpu_failed": cpu.failed,
        });
        stages_json(&mut obj, "cpu", &cpu.stages);
        if let Some(g) = &gpu {
            let k = &g.stats.gpu;
            obj["gpu_wall_s"] = g.stats.wall_s.into();
            obj["gpu_newton_iters"] = g.iters.into();
            obj["gpu_failed"] = g.failed.into();
            obj["gpu_setup_s"] = g.stats.setup_s.into();
            obj["gpu_upload_s"] = k.upload_s.into();
            obj["gpu_kernel_s"] = k.kernel_s.into();
            obj["gpu_readback_s"] = k.readback_s.into();
            obj["gpu_dispatches"] = k.dispatches.into();
            obj["gpu_bytes_up"] = k.bytes_up.into();
            obj["gpu_bytes_down"] = k.bytes_down.into();
            obj["gpu_unpack_s"] = k.unpack_s.into();
            let (up, down) = per_element_dispatch(k, a.rods * a.elements);
            obj["gpu_bytes_up_per_element_dispatch"] = up.into();
            obj["gpu_bytes_down_per_element_dispatch"] = down.into();
            stages_json(&mut obj, "gpu", &g.stages);
        }
        println!("{obj}");
    } else {
        println!(
            "batch: {} rods × {} elements × {} steps (EDMC-2 α = 0.5, staggered, Δt = 0.01){}",
            a.rods,
            a.elements,
            a.steps,
            if a.modified_newton {
                ", modified Newton"
            } else {
                ""
            }
        );
        println!(
            "cpu ({} threads): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed",
            rayon::current_num_threads(),
            cpu.stats.wall_s,
            cpu_rate,
            rod_steps / cpu.stats.wall_s,
            cpu.iters,
            cpu.failed
        );
        println!("cpu stages: {}", stages_line(&cpu.stages));
        match (&gpu, gpu_rate) {
            (Some(g), Some(rate)) => {
                let (w, k) = (&g.stats, &g.stats.gpu);
                println!(
                    "gpu ({adapter}): {:.3} s, {:.0} rod·element·steps/s ({:.0} rod-steps/s), {} Newton iterations, {} failed; ratio gpu/cpu {:.2}",
                    w.wall_s, rate, rod_steps / w.wall_s, g.iters, g.failed, rate / cpu_rate
                );
                let other =
                    w.wall_s - w.setup_s - k.upload_s - k.kernel_s - k.readback_s - k.unpack_s;
                let (up, down) = per_element_dispatch(k, a.rods * a.elements);
                println!(
                    "gpu time: pipeline setup {:.3} s, upload {:.3} s, kernel+assembly+copy {:.3} s, readback {:.3} s, unpack {:.3} s ({} dispatches, {:.1} MB up, {:.1} MB down; per element per dispatch {:.0} B up, {:.0} B down); host gather+scatter+solve+barrier {:.3} s",
                    w.setup_s,
                    k.upload_s,
                    k.kernel_s,
                    k.readback_s,
                    k.unpack_s,
                    k.dispatches,
                    k.bytes_up as f64 / 1e6,
                    k.bytes_down as f64 / 1e6,
                    up,
                    down,
                    other
                );
                println!(
                    "gpu stages (assembly includes the wait at the batch barrier): {}",
                    stages_line(&g.stages)
                );
            }
            _ => println!("gpu: not run ({adapter})"),
        }
    }
    Ok(ExitCode::SUCCESS)
}
