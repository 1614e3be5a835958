//! The `sweep` and `bench` subcommands and the `--backend` switch of `run` (GPU batch
//! path). No physics: argument handling, progress and printing only.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};

use cosserat::batch::{
    bench_members, run_members, BackendChoice, BatchOptions, BatchStats, Executor, GpuBatcher,
};
use cosserat::gpu::kernel::KernelTimers;
use cosserat::integrator::Simulation;
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
    #[arg(long, default_value_t = 64)]
    pub rods: usize,
    /// Elements per rod.
    #[arg(long, default_value_t = 30)]
    pub elements: usize,
    /// Time steps.
    #[arg(long, default_value_t = 20)]
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

fn timed(
    members: &[cosserat::batch::Member],
    exec: &Executor,
    modified_newton: bool,
) -> Result<(BatchStats, usize, usize)> {
    let (mut iters, mut failed) = (0usize, 0usize);
    let opts = BatchOptions {
        modified_newton,
        ..Default::default()
    };
    let stats = run_members(members, exec, opts, |r| {
        iters += r.outcome.newton_iters_total;
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
    Ok((stats, iters, failed))
}

/// Bytes uploaded and read back per element slot per dispatch (`elements` slots: every
/// member in flight at once).
fn per_element_dispatch(t: &KernelTimers, elements: usize) -> (f64, f64) {
    let n = (t.dispatches as f64 * elements as f64).max(1.0);
    (t.bytes_up as f64 / n, t.bytes_down as f64 / n)
}

/// `cosserat bench`: the same batch on the CPU path and on the GPU path.
pub fn bench_command(a: BenchArgs) -> Result<ExitCode> {
    let members = bench_members(a.rods, a.elements, a.steps);
    let work = (a.rods * a.elements * a.steps) as f64;
    let (cpu, cpu_iters, cpu_failed) = timed(&members, &Executor::Cpu, a.modified_newton)?;
    let cpu_rate = work / cpu.wall_s;
    let gpu_exec = if a.cpu_only {
        Ok((Executor::Cpu, None))
    } else {
        Executor::resolve(BackendChoice::Gpu, a.adapter.as_deref())
    };
    let (adapter, f64_ok, gpu) = match &gpu_exec {
        Ok((Executor::Gpu(ctx), _)) => {
            let r = timed(
                &members,
                &gpu_exec.as_ref().map(|e| e.0.clone()).unwrap(),
                a.modified_newton,
            )
            .context("GPU batch")?;
            (ctx.describe(), ctx.is_f64(), Some(r))
        }
        Ok((Executor::Cpu, _)) => ("none".into(), false, None),
        Err(e) => (format!("none ({e})"), false, None),
    };
    let gpu_rate = gpu.as_ref().map(|g| work / g.0.wall_s);
    if a.json {
        let mut obj = serde_json::json!({
            "rods": a.rods,
            "elements": a.elements,
            "steps": a.steps,
            "cpu_element_steps_per_s": cpu_rate,
            "gpu_element_steps_per_s": gpu_rate,
            "ratio": gpu_rate.map(|g| g / cpu_rate),
            "adapter": adapter,
            "f64": f64_ok,
            "cpu_threads": rayon::current_num_threads(),
            "modified_newton": a.modified_newton,
            "cpu_wall_s": cpu.wall_s,
            "cpu_newton_iters": cpu_iters,
            "cpu_failed": cpu_failed,
        });
        if let Some((g, it, f)) = &gpu {
            obj["gpu_wall_s"] = g.wall_s.into();
            obj["gpu_newton_iters"] = (*it).into();
            obj["gpu_failed"] = (*f).into();
            obj["gpu_setup_s"] = g.setup_s.into();
            obj["gpu_upload_s"] = g.gpu.upload_s.into();
            obj["gpu_kernel_s"] = g.gpu.kernel_s.into();
            obj["gpu_readback_s"] = g.gpu.readback_s.into();
            obj["gpu_dispatches"] = g.gpu.dispatches.into();
            obj["gpu_bytes_up"] = g.gpu.bytes_up.into();
            obj["gpu_bytes_down"] = g.gpu.bytes_down.into();
            obj["gpu_unpack_s"] = g.gpu.unpack_s.into();
            let (up, down) = per_element_dispatch(&g.gpu, a.rods * a.elements);
            obj["gpu_bytes_up_per_element_dispatch"] = up.into();
            obj["gpu_bytes_down_per_element_dispatch"] = down.into();
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
            "cpu ({} threads): {:.3} s, {:.0} element-steps/s, {} Newton iterations, {} failed",
            rayon::current_num_threads(),
            cpu.wall_s,
            cpu_rate,
            cpu_iters,
            cpu_failed
        );
        match (&gpu, gpu_rate) {
            (Some((g, it, f)), Some(rate)) => {
                println!(
                    "gpu ({adapter}): {:.3} s, {:.0} element-steps/s, {} Newton iterations, {} failed; ratio gpu/cpu {:.2}",
                    g.wall_s, rate, it, f, rate / cpu_rate
                );
                let other = g.wall_s
                    - g.setup_s
                    - g.gpu.upload_s
                    - g.gpu.kernel_s
                    - g.gpu.readback_s
                    - g.gpu.unpack_s;
                let (up, down) = per_element_dispatch(&g.gpu, a.rods * a.elements);
                println!(
                    "gpu time: pipeline setup {:.3} s, upload {:.3} s, kernel+assembly+copy {:.3} s, readback {:.3} s, unpack {:.3} s ({} dispatches, {:.1} MB up, {:.1} MB down; per element per dispatch {:.0} B up, {:.0} B down); host gather+scatter+solve+barrier {:.3} s",
                    g.setup_s,
                    g.gpu.upload_s,
                    g.gpu.kernel_s,
                    g.gpu.readback_s,
                    g.gpu.unpack_s,
                    g.gpu.dispatches,
                    g.gpu.bytes_up as f64 / 1e6,
                    g.gpu.bytes_down as f64 / 1e6,
                    up,
                    down,
                    other
                );
            }
            _ => println!("gpu: not run ({adapter})"),
        }
    }
    Ok(ExitCode::SUCCESS)
}
