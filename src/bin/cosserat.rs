//! `cosserat`: command-line front end. No physics here: it parses arguments, loads a
//! scene, runs the integrator and hands records to the output writers.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};

use cosserat::integrator::run::{run, RunOutcome};
use cosserat::integrator::{IntegratorParams, Scheme, Simulation, Strategy};
use cosserat::observe::record::{RunStatus, RunSummary, StepRecord};
use cosserat::output::{plot_energy, plot_momenta, write_summary, HistoryWriter, Progress};
use cosserat::scene::{builtin_scenes, load_scene, Scene};

#[path = "cosserat_cmds/mod.rs"]
mod cmds;

/// Nonlinear dynamics of geometrically exact (Cosserat) rods with energy-momentum and
/// energy-dissipative momentum-conserving time stepping. With no arguments: runs the
/// built-in `frame` scene with EDMC-2 α = 0.5 into `out/frame/`.
#[derive(Parser, Debug)]
#[command(name = "cosserat", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a scene (a file path or a built-in name) and write history.csv, summary.json,
    /// energy.png and momenta.png.
    Run(RunArgs),
    /// Validate a scene and print what it contains.
    Check {
        /// Scene file or built-in name.
        scene: String,
    },
    /// List the built-in scenes.
    Scenes,
    /// Run a parameter sweep (a base scene + parameters to vary) as one batch and write
    /// DIR/members.csv.
    Sweep(cmds::SweepArgs),
    /// Time the same batch on the CPU path and on the GPU path.
    Bench(cmds::BenchArgs),
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Scene file or built-in name (see `cosserat scenes`).
    scene: String,
    /// Time-stepping scheme (default: the scene's `[integrator] scheme`).
    #[arg(long, value_enum)]
    scheme: Option<SchemeArg>,
    /// EDMC-2 dissipation α_Γv (the paper's single parameter); implies `--scheme edmc2`
    /// when the scene's scheme is not EDMC-2 and no `--scheme` is given.
    #[arg(long)]
    alpha: Option<f64>,
    /// Time step Δt (default: the scene's).
    #[arg(long)]
    dt: Option<f64>,
    /// End time (default: the scene's).
    #[arg(long)]
    t_end: Option<f64>,
    /// Dissipation strategy (default: the scene's, else staggered).
    #[arg(long, value_enum)]
    strategy: Option<StrategyArg>,
    /// Output directory (default: `out/<scene name>`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write every N-th step to history.csv (default: the scene's `output_every`).
    #[arg(long)]
    every: Option<usize>,
    /// Where the element kernel runs (`auto`: the GPU when an f64 adapter exists).
    #[arg(long, value_enum, default_value_t = cmds::BackendArg::Cpu)]
    backend: cmds::BackendArg,
    /// GPU adapter: first adapter whose name contains this (case-insensitive).
    #[arg(long)]
    adapter: Option<String>,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
enum SchemeArg {
    Em,
    Edmc1,
    Edmc2,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
enum StrategyArg {
    Staggered,
    Monolithic,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => run_command(RunArgs {
            scene: "frame".into(),
            scheme: Some(SchemeArg::Edmc2),
            alpha: Some(0.5),
            dt: None,
            t_end: None,
            strategy: None,
            out: Some(PathBuf::from("out/frame")),
            every: None,
            backend: cmds::BackendArg::Cpu,
            adapter: None,
        }),
        Some(Command::Run(a)) => run_command(a),
        Some(Command::Check { scene }) => check_command(&scene),
        Some(Command::Sweep(a)) => cmds::sweep_command(a),
        Some(Command::Bench(a)) => cmds::bench_command(a),
        Some(Command::Scenes) => {
            for s in builtin_scenes() {
                println!("{:<12} {}", s.name, s.description);
            }
            Ok(ExitCode::SUCCESS)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn check_command(spec: &str) -> Result<ExitCode> {
    let scene = load_scene(spec)?;
    print!("{}", scene.describe());
    Ok(ExitCode::SUCCESS)
}

/// The scheme a run uses: `--scheme` replaces the scene's scheme (keeping the scene's
/// constants when it names the same scheme, zero otherwise); `--alpha` sets α_Γv.
fn resolve_params(scene: &Scene, a: &RunArgs) -> Result<IntegratorParams> {
    let mut p = scene.params;
    let wanted = a.scheme.or(match (a.alpha, p.scheme) {
        (Some(_), Scheme::Edmc2 { .. }) | (None, _) => None,
        (Some(_), _) => Some(SchemeArg::Edmc2),
    });
    if let Some(s) = wanted {
        p.scheme = match (s, p.scheme) {
            (SchemeArg::Em, _) => Scheme::Em,
            (SchemeArg::Edmc1, s @ Scheme::Edmc1 { .. }) => s,
            (SchemeArg::Edmc1, _) => Scheme::Edmc1 {
                chi_gamma: 0.0,
                chi_omega: 0.0,
                chi_v: 0.0,
                chi_nu: 0.0,
            },
            (SchemeArg::Edmc2, s @ Scheme::Edmc2 { .. }) => s,
            (SchemeArg::Edmc2, _) => Scheme::Edmc2 {
                alpha_gv: 0.0,
                alpha_gn: 0.0,
                alpha_ov: 0.0,
                alpha_on: 0.0,
            },
        };
    }
    if let Some(alpha) = a.alpha {
        if !(alpha.is_finite() && alpha >= 0.0) {
            bail!("--alpha: must be a finite number ≥ 0 (got {alpha})");
        }
        match &mut p.scheme {
            Scheme::Edmc2 { alpha_gv, .. } => *alpha_gv = alpha,
            other => bail!(
                "--alpha sets the EDMC-2 parameter α_Γv, but the scheme is {}",
                other.name()
            ),
        }
    }
    if let Some(dt) = a.dt {
        if !(dt.is_finite() && dt > 0.0) {
            bail!("--dt: must be a finite number > 0 (got {dt})");
        }
        p.dt = dt;
    }
    if let Some(t) = a.t_end {
        if !(t.is_finite() && t > 0.0) {
            bail!("--t-end: must be a finite number > 0 (got {t})");
        }
        p.t_end = t;
    }
    if let Some(s) = a.strategy {
        p.strategy = match s {
            StrategyArg::Staggered => Strategy::Staggered,
            StrategyArg::Monolithic => Strategy::Monolithic,
        };
    }
    Ok(p)
}

fn run_command(a: RunArgs) -> Result<ExitCode> {
    let scene = load_scene(&a.scene)?;
    let params = resolve_params(&scene, &a)?;
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join(&scene.name));
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    let every = a.every.unwrap_or(scene.output_every).max(1);
    let mut sim =
        Simulation::new(scene.model.clone(), params).context("cannot set up the linear solver")?;
    let _gpu = cmds::attach(&mut sim, a.backend, a.adapter.as_deref())?;
    let outcome = simulate(&mut sim, &out, every, &scene.name)?;
    let summary = summarize(&scene, &sim, &outcome);
    write_summary(&out.join("summary.json"), &summary)?;
    print_summary(&summary, &out);
    Ok(ExitCode::SUCCESS)
}

/// Runs the time loop, streaming history.csv, then draws the charts from what was
/// written (also after a failed step: every accepted level is kept).
fn simulate(sim: &mut Simulation, out: &Path, every: usize, label: &str) -> Result<RunOutcome> {
    let mut history = HistoryWriter::create(&out.join("history.csv"))?;
    let mut records: Vec<StepRecord> = Vec::new();
    let progress = Progress::new(sim.params().n_steps() as u64, label);
    let outcome = run(
        sim,
        every,
        |rec: &StepRecord, _sim: &Simulation| -> Result<()> {
            history.push(rec)?;
            progress.step(rec.t, rec.newton_iters);
            records.push(rec.clone());
            Ok(())
        },
    )?;
    progress.finish();
    let title = format!("{label}: {}", sim.params().scheme.name());
    plot_energy(&out.join("energy.png"), &records, &title)?;
    plot_momenta(&out.join("momenta.png"), &records, &title)?;
    Ok(outcome)
}

fn summarize(scene: &Scene, sim: &Simulation, o: &RunOutcome) -> RunSummary {
    RunSummary {
        scene: scene.source.clone(),
        status: o.status,
        t_reached: o.t_reached,
        steps: o.steps,
        reason: o.reason.clone(),
        failed_step_residuals: o.failed_step_residuals.clone(),
        wall_s: o.wall_s,
        scheme: sim.params().scheme.name().to_string(),
        params: *sim.params(),
        nodes: sim.model().n_nodes(),
        elements: sim.model().elements.len(),
        dofs: sim.n_dofs(),
        newton_iters_total: o.newton_iters_total,
        max_rel_dl: o.max_rel_dl,
        max_rel_dj: o.max_rel_dj,
        energy_initial: o.energy_initial,
        energy_final: o.energy_final,
    }
}

fn print_summary(s: &RunSummary, out: &Path) {
    let status = match s.status {
        RunStatus::Completed => "completed".to_string(),
        RunStatus::Failed => format!("FAILED ({})", s.reason.as_deref().unwrap_or("")),
    };
    println!(
        "{}: scheme {} Δt = {} — {status}; reached t = {:.6} in {} steps, {} Newton iterations, {:.3} s. \
         H {:.9e} → {:.9e} (change {:+.3e}); max per-step drift |ΔL| {:.1e}, |ΔJ| {:.1e} (relative). \
         Outputs in {}.",
        s.scene,
        s.scheme,
        s.params.dt,
        s.t_reached,
        s.steps,
        s.newton_iters_total,
        s.wall_s,
        s.energy_initial,
        s.energy_final,
        s.energy_final - s.energy_initial,
        s.max_rel_dl,
        s.max_rel_dj,
        out.display()
    );
}
