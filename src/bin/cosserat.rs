//! `cosserat`: command-line front end. No physics here: it parses arguments, loads a
//! scene, runs the integrator and hands records to the output writers.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};

use cosserat::driver::{run_sim_to_dir, RunOptions};
use cosserat::integrator::{IntegratorParams, Scheme, Simulation};
use cosserat::observe::record::{RunStatus, RunSummary};
use cosserat::output::{CosseratBenchOptions, OutputTimes};
use cosserat::reproduce::reproduce;
use cosserat::scene::{builtin_scenes, load_scene, printable, Scene};
use cosserat::study;

/// `println!` for this program: a stdout whose reader has gone (`cosserat check frame |
/// head -1`) ends the program quietly with exit code 0 ([`stdout_write`]), instead of
/// std's panic.
macro_rules! println {
    () => {
        $crate::stdout_write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::stdout_write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` for this program (see [`println!`]).
macro_rules! print {
    ($($arg:tt)*) => {
        $crate::stdout_write(format_args!($($arg)*))
    };
}

#[path = "cosserat_cmds/mod.rs"]
mod cmds;

/// Writes `args` to stdout (flushing it). A closed pipe (EPIPE: the reader, e.g. `head`,
/// has read what it wanted) is a normal end: exit code 0, no message. Any other write
/// error ends the program with a message and exit code 2.
fn stdout_write(args: std::fmt::Arguments) {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_fmt(args).and_then(|()| out.flush()) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => {
            eprintln!("error: cannot write to stdout: {e}");
            std::process::exit(2)
        }
    }
}

/// A number as error messages echo it: shortest round-trip text, scientific notation
/// outside `[1e-5, 1e16)`, never hundreds of digits.
fn num(x: f64) -> String {
    cosserat::output::num(x)
}

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
    /// Run the paper's examples (frame, arch, mechanism) into DIR with figures and a
    /// generated DIR/REPORT.md.
    Reproduce {
        /// Output directory.
        #[arg(long, default_value = "out/reproduce")]
        out: PathBuf,
        /// Shorter runs (arch to t = 1200, mechanisms to t = 6 at Δt = 0.05 only).
        #[arg(long)]
        quick: bool,
        /// Skip the ParaView (VTK) files, which are on by default.
        #[arg(long)]
        no_vtk: bool,
    },
    /// Run a parameter sweep (a base scene + parameters to vary) as one batch and write
    /// DIR/members.csv.
    Sweep(cmds::SweepArgs),
    /// Time the same batch on the CPU path and on the GPU path.
    Bench(cmds::BenchArgs),
    /// Speed-vs-accuracy and stability studies over the schemes.
    #[command(subcommand)]
    Study(StudyCommand),
    /// List the GPU adapters wgpu sees, say which one `--backend auto` would use and why,
    /// and diagnose a host whose NVIDIA GPU is not a Vulkan adapter.
    Gpu(cmds::gpu::GpuArgs),
}

#[derive(Subcommand, Debug)]
enum StudyCommand {
    /// Error against wall time for several schemes and time steps: writes
    /// work_precision.csv and work_precision.png.
    WorkPrecision(WorkPrecisionArgs),
    /// Fraction of the run completed over a grid Δt × dissipation parameter per scheme:
    /// writes stability.csv and stability.png.
    Stability(StabilityArgs),
    /// A scene loaded from rest under EM and each dissipation parameter alone, over a log
    /// grid of Δt, with fixed steps: each cell completes or fails with its reason
    /// classified as the scheme's (a limit its checks refuse) or a solver stall; writes
    /// from_rest.csv and from_rest.png.
    FromRest(FromRestArgs),
    /// The dissipation guide: modal damping ratio of the first axial and bending mode of
    /// a clamped rod under each dissipation parameter: writes damping.csv and damping.png.
    Damping(DampingArgs),
}

#[derive(clap::Args, Debug)]
struct DampingArgs {
    /// Scene file or built-in name: one straight uniform rod clamped at its first node.
    #[arg(default_value = "cantilever")]
    scene: String,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Values of each dissipation parameter (χ or α).
    #[arg(long, value_delimiter = ',', default_value = "0.01,0.1,0.5,1")]
    values: Vec<f64>,
    /// Periods of the mode each run covers.
    #[arg(long, default_value_t = 4.0)]
    periods: f64,
    /// Time steps per period of the mode (ωΔt = 2π / this).
    #[arg(long, default_value_t = 16, value_parser = cmds::at_least_one)]
    steps_per_period: usize,
    /// Tip displacement amplitude of the mode relative to the rod length.
    #[arg(long, default_value_t = 0.01)]
    amplitude: f64,
    /// Parallel runs (default: the number of cores).
    #[arg(long, value_parser = cmds::at_least_one)]
    jobs: Option<usize>,
}

/// Options every study takes.
#[derive(clap::Args, Debug)]
struct StudyCommon {
    /// Scene file or built-in name.
    scene: String,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// End time (default: the scene's).
    #[arg(long)]
    t_end: Option<f64>,
    /// Relative Newton tolerance of every run (default: the scene's).
    #[arg(long)]
    newton_tol: Option<f64>,
    /// Parallel runs (default: the number of cores).
    #[arg(long, value_parser = cmds::at_least_one)]
    jobs: Option<usize>,
    /// Newton variant of every run (default: the scene's, else full).
    #[arg(long, value_enum)]
    newton: Option<cmds::NewtonArg>,
    /// Dissipation strategy of every run (default: the scene's, else auto: monolithic on
    /// the CPU kernel, staggered with a GPU evaluator).
    #[arg(long, value_enum)]
    strategy: Option<cmds::StrategyArg>,
    /// No fallback strategy when the run's strategy fails on a step (maps of a pure
    /// strategy, e.g. the paper's staggered one with `--strategy staggered`; default: the
    /// scene's, else fallback on).
    #[arg(long)]
    no_fallback: bool,
    /// Step cut-back of every run: a failed step is redone as up to 2^N sub-steps
    /// (default: the scene's, else 0 = off: a stability map shows where the fixed-step
    /// scheme fails, unlike `run` and `sweep`, which cut back by default).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=20))]
    cutback: Option<u8>,
}

#[derive(clap::Args, Debug)]
struct WorkPrecisionArgs {
    #[command(flatten)]
    common: StudyCommon,
    /// Schemes with parameters, `NAME[:PARAM]` (edmc1: χ_Γ = χ_Ω, edmc2: α_Γv,
    /// gen-alpha: ρ∞).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "em,edmc1:0.2,edmc2:0.5,midpoint,gen-alpha:0.8"
    )]
    schemes: Vec<String>,
    /// Time steps (default: the scene's Δt times 1, ½, ¼, ⅛).
    #[arg(long, value_delimiter = ',')]
    dts: Option<Vec<f64>>,
    /// Δt of the EM reference run (default: the smallest Δt / 8).
    #[arg(long)]
    reference_dt: Option<f64>,
}

#[derive(clap::Args, Debug)]
struct StabilityArgs {
    #[command(flatten)]
    common: StudyCommon,
    /// Scheme families, one chart panel each.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "em,edmc1,edmc2,midpoint,gen-alpha"
    )]
    schemes: Vec<String>,
    /// Dissipation parameters of edmc1 (χ_Γ = χ_Ω) and edmc2 (α_Γv).
    #[arg(long, value_delimiter = ',', default_value = "0,0.5,1,2")]
    params: Vec<f64>,
    /// ρ∞ values of gen-alpha.
    #[arg(long, value_delimiter = ',', default_value = "0,0.5,0.8,1")]
    rho_inf: Vec<f64>,
    /// Time steps (default: the scene's Δt times ¼, ½, 1, 2, 4).
    #[arg(long, value_delimiter = ',')]
    dts: Option<Vec<f64>>,
    /// Where the grid runs: `gpu`/`auto` run it as one batch whose EM/EDMC members share
    /// each GPU element dispatch (baselines use the CPU kernel inside the batch).
    #[arg(long, value_enum, default_value_t = cmds::BackendArg::Cpu)]
    backend: cmds::BackendArg,
    /// GPU adapter: first adapter whose name contains this (case-insensitive).
    #[arg(long)]
    adapter: Option<String>,
}

#[derive(clap::Args, Debug)]
struct FromRestArgs {
    #[command(flatten)]
    common: StudyCommon,
    /// Rows of the map: `em` and dissipation parameters, each alone at `--value`
    /// (chi_gamma, chi_omega, chi_v, chi_nu: EDMC-1; alpha_gv, alpha_gn, alpha_ov,
    /// alpha_on: EDMC-2).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "em,chi_gamma,chi_omega,chi_v,chi_nu,alpha_gv,alpha_gn,alpha_ov,alpha_on"
    )]
    params: Vec<String>,
    /// Value of each dissipation parameter.
    #[arg(long, default_value_t = 0.5)]
    value: f64,
    /// Time steps (default: `--dt-range`).
    #[arg(long, value_delimiter = ',', conflicts_with = "dt_range")]
    dts: Option<Vec<f64>>,
    /// Log grid of time steps `MIN,MAX,COUNT` (default: the scene's Δt/4 to 4Δt, 9 values).
    #[arg(long, value_delimiter = ',', value_name = "MIN,MAX,COUNT")]
    dt_range: Option<Vec<f64>>,
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Scene file or built-in name (see `cosserat scenes`).
    scene: String,
    /// Time-stepping scheme (default: the scene's `[integrator] scheme`).
    #[arg(long, value_enum)]
    scheme: Option<SchemeArg>,
    /// EDMC-2 dissipation α_Γv (the paper's single parameter); implies `--scheme edmc2`
    /// when the scene's scheme is not EDMC-2 and no `--scheme` is given. Conflicts with
    /// `--rho-inf` (another scheme's parameter).
    #[arg(long, conflicts_with = "rho_inf")]
    alpha: Option<f64>,
    /// Time step Δt (default: the scene's).
    #[arg(long)]
    dt: Option<f64>,
    /// End time (default: the scene's).
    #[arg(long)]
    t_end: Option<f64>,
    /// Generalized-α spectral radius ρ∞ ∈ [0, 1]; implies `--scheme gen-alpha` when no
    /// `--scheme` is given.
    #[arg(long)]
    rho_inf: Option<f64>,
    /// Dissipation strategy (default: the scene's, else auto: monolithic on the CPU
    /// kernel, staggered with a GPU evaluator).
    #[arg(long, value_enum)]
    strategy: Option<cmds::StrategyArg>,
    /// Newton variant (default: the scene's `[integrator] newton`, else full).
    #[arg(long, value_enum)]
    newton: Option<cmds::NewtonArg>,
    /// No fallback strategy when the run's strategy fails on a step (monolithic for
    /// staggered, staggered for monolithic): the pure strategy, e.g. the paper's staggered
    /// one (default: the scene's `[integrator] fallback`, else on).
    #[arg(long)]
    no_fallback: bool,
    /// Step cut-back: redo a failed step as 2, 4, … 2^N sub-steps of the same scheme
    /// before reporting the failure (default: the scene's `[integrator] cutback`, else 4;
    /// 0 = off; CPU element kernel only).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=20))]
    cutback: Option<u8>,
    /// Output directory (default: `out/<scene name>`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write every N-th step to history.csv (default: the scene's `output_every`).
    #[arg(long, value_parser = cmds::at_least_one)]
    every: Option<usize>,
    /// Also write ParaView files: `vtk/NAME_STEP.vtu` at every saved step and `vtk/NAME.pvd`.
    #[arg(long)]
    vtk: bool,
    /// Draw `snapshots.png` with the deformed rods every N steps.
    #[arg(long, value_name = "N", value_parser = cmds::at_least_one)]
    snapshots: Option<usize>,
    /// Write `animation.gif`: the deformed rods at ≈ 100 times over the run (or every N
    /// steps with `--animate-every N`).
    #[arg(long)]
    animate: bool,
    /// Animation frame every N steps (implies `--animate`).
    #[arg(long, value_name = "N", value_parser = cmds::at_least_one)]
    animate_every: Option<usize>,
    /// Write `trajectory.npz`: node positions, directors and velocities at the output times
    /// (default: every `--every`-th step; always the last accepted step).
    #[arg(long)]
    trajectory: bool,
    /// Trajectory output interval, a whole multiple of Δt (implies `--trajectory`).
    #[arg(long, value_name = "DT", conflicts_with = "times")]
    output_dt: Option<f64>,
    /// Trajectory output times, comma-separated, each on a step (implies `--trajectory`).
    #[arg(long, value_name = "T,T,...", value_delimiter = ',')]
    times: Option<Vec<f64>>,
    /// Also write `cosseratbench/trajectory.npz` and `cosseratbench/result.json` in the
    /// layout of the cosseratbench suite (implies `--trajectory`).
    #[arg(long)]
    cosseratbench: bool,
    /// cosseratbench's digest of the matching scenario, written to its `result.json`.
    #[arg(long, value_name = "HEX", requires = "cosseratbench")]
    scenario_digest: Option<String>,
    /// The suite's `experiment.json` of the matching variant: its `name` and `values` go
    /// to `result.json`'s `experiment` and `values`.
    #[arg(long, value_name = "PATH", requires = "cosseratbench")]
    experiment_json: Option<PathBuf>,
    /// Override a numeric scene key before the run, with the key paths and checks of sweep
    /// files (`--set integrator.dt=0.1`, `--set rod.beam.elements=100`); repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_set)]
    sets: Vec<(String, f64)>,
    /// Where the element kernel runs (`auto`: the GPU when an f64 adapter exists).
    #[arg(long, value_enum, default_value_t = cmds::BackendArg::Cpu)]
    backend: cmds::BackendArg,
    /// GPU adapter: first adapter whose name contains this (case-insensitive).
    #[arg(long)]
    adapter: Option<String>,
    /// GPU path: where the Newton systems are solved (docs/gpu.md, "Device solve").
    #[arg(long, value_enum, default_value_t = cmds::SolveArg::Host)]
    solve: cmds::SolveArg,
}

/// `KEY=VALUE` of `--set`: VALUE must be a finite number.
fn parse_set(s: &str) -> Result<(String, f64), String> {
    let (k, v) = s
        .split_once('=')
        .ok_or_else(|| format!("`{}` is not KEY=VALUE", cmds::echo(s)))?;
    let x: f64 = v.trim().parse().map_err(|_| {
        format!(
            "{}: `{}` is not a number",
            cmds::echo(k.trim()),
            cmds::echo(v.trim())
        )
    })?;
    if !x.is_finite() {
        return Err(format!(
            "{}: must be finite (got {})",
            cmds::echo(k.trim()),
            num(x)
        ));
    }
    Ok((k.trim().to_string(), x))
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
enum SchemeArg {
    Em,
    Edmc1,
    Edmc2,
    /// Baseline: plain implicit mid-point rule (stresses from the mid-point strains).
    Midpoint,
    /// Baseline: Lie-group generalized-α (`--rho-inf`).
    GenAlpha,
}

/// A build for AVX2 (`.cargo/config.toml`'s `x86-64-v3`) on a CPU without it would stop
/// at its first AVX instruction with "illegal instruction": say why instead, first thing.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
fn require_build_target_cpu() -> Option<ExitCode> {
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        return None;
    }
    eprintln!(
        "error: this cosserat binary was built for x86-64-v3 (AVX2) CPUs and this CPU lacks \
         AVX2; rebuild it for this machine with \
         RUSTFLAGS=\"-C target-cpu=native\" cargo build --release (docs/benchmarks.md)"
    );
    Some(ExitCode::from(2))
}

#[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
fn require_build_target_cpu() -> Option<ExitCode> {
    None
}

/// Whether `a` takes numbers (its value parser yields an integer or a float).
fn is_numeric(a: &clap::Arg) -> bool {
    use std::any::TypeId;
    let t = a.get_value_parser().type_id();
    [
        TypeId::of::<f64>(),
        TypeId::of::<f32>(),
        TypeId::of::<usize>(),
        TypeId::of::<u64>(),
        TypeId::of::<u32>(),
        TypeId::of::<u8>(),
        TypeId::of::<i64>(),
    ]
    .iter()
    .any(|id| t == *id)
}

/// The command line, with one setting for every option that takes a number: a value
/// starting with `-` (`--output-dt -0.1`, `--times -1`, `--cutback -1`, `--dt -inf`) is
/// its value, which then gets the option's own range error (exit code 2) instead of
/// clap's "unexpected argument". Other options accept negative numbers as values too.
fn cli_command() -> clap::Command {
    fn hyphens(cmd: clap::Command) -> clap::Command {
        cmd.mut_args(|a| {
            if !a.get_action().takes_values() {
                a
            } else if is_numeric(&a) {
                a.allow_hyphen_values(true)
            } else {
                a.allow_negative_numbers(true)
            }
        })
        .mut_subcommands(hyphens)
    }
    hyphens(<Cli as clap::CommandFactory>::command())
}

/// Parses the command line. `--help` and `--version` print as clap prints them; every
/// other error is one line, as the program's own errors are (`error: … tip: …`), exit 2.
fn parse_cli() -> Cli {
    use clap::error::ErrorKind;
    use clap::FromArgMatches as _;
    let parsed = cli_command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    match parsed {
        Ok(cli) => cli,
        Err(e)
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) =>
        {
            e.exit()
        }
        Err(e) => {
            eprintln!("{}", one_line(&e.render().to_string()));
            std::process::exit(2)
        }
    }
}

/// A clap error as one line: its message and tips, without the usage block and the
/// pointer to `--help`.
fn one_line(rendered: &str) -> String {
    let mut parts: Vec<&str> = Vec::new();
    for l in rendered.lines().map(str::trim) {
        if l.starts_with("Usage:") || l.starts_with("For more information") {
            break;
        }
        if !l.is_empty() {
            parts.push(l);
        }
    }
    let mut out = String::new();
    for p in parts {
        if !out.is_empty() {
            out.push_str(if out.ends_with(':') { " " } else { "; " });
        }
        out.push_str(p);
    }
    printable(&out)
}

/// Mesa's Vulkan device-select layer prints two `XDG_RUNTIME_DIR` lines on every adapter
/// enumeration when that variable is unset (containers, CI); the layer only orders the
/// adapters, which `--adapter` does here, so it is switched off (`NODEVICE_SELECT=1`)
/// unless the environment sets the variable itself. Called first thing, before any
/// thread or adapter exists.
fn quiet_mesa_device_select() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

/// Whether the command may open a GPU: `gpu`, `bench`, and `run`, `sweep` and `study
/// stability` with a backend other than `cpu`.
fn may_use_gpu(cmd: &Option<Command>) -> bool {
    use cmds::BackendArg::Cpu;
    match cmd {
        Some(Command::Gpu(a)) => !a.enumerate_only(),
        Some(Command::Bench(_)) => true,
        Some(Command::Run(a)) => a.backend != Cpu,
        Some(Command::Sweep(a)) => a.member.backend != Cpu,
        Some(Command::Study(StudyCommand::Stability(a))) => a.backend != Cpu,
        _ => false,
    }
}

/// On a host whose NVIDIA GPU the default Vulkan setup does not list, the routes of
/// `cosserat::gpu::reach` (an ICD file naming the driver's EGL library, …), tried before
/// any thread exists: the first that lists the GPU stays in `VK_DRIVER_FILES`.
fn reach_gpu() -> cosserat::gpu::reach::Reach {
    let facts = cosserat::gpu::inventory::HostFacts::of_this_host();
    let root = std::env::var_os("COSSERAT_GPU_HOST_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/"));
    cosserat::gpu::reach::reach_nvidia_gpu(
        &facts,
        &root,
        cosserat::gpu::context::pipeline_cache_dir().as_deref(),
    )
}

fn main() -> ExitCode {
    if let Some(code) = require_build_target_cpu() {
        return code;
    }
    quiet_mesa_device_select();
    let cli = parse_cli();
    let reach = if may_use_gpu(&cli.command) {
        reach_gpu()
    } else {
        Default::default()
    };
    if !matches!(cli.command, Some(Command::Gpu(_))) {
        if let Some(line) = reach.summary() {
            eprintln!("{line}");
        }
    }
    let result = match cli.command {
        None => run_command(RunArgs {
            scene: "frame".into(),
            scheme: Some(SchemeArg::Edmc2),
            alpha: Some(0.5),
            dt: None,
            t_end: None,
            rho_inf: None,
            strategy: None,
            newton: None,
            no_fallback: false,
            cutback: None,
            out: Some(PathBuf::from("out/frame")),
            every: None,
            vtk: false,
            snapshots: Some(10),
            animate: false,
            animate_every: None,
            trajectory: false,
            output_dt: None,
            times: None,
            cosseratbench: false,
            scenario_digest: None,
            experiment_json: None,
            sets: vec![],
            backend: cmds::BackendArg::Cpu,
            adapter: None,
            solve: cmds::SolveArg::Host,
        }),
        Some(Command::Run(a)) => run_command(a),
        Some(Command::Check { scene }) => check_command(&scene),
        Some(Command::Reproduce { out, quick, no_vtk }) => reproduce_command(&out, quick, !no_vtk),
        Some(Command::Study(StudyCommand::WorkPrecision(a))) => work_precision_command(&a),
        Some(Command::Study(StudyCommand::Stability(a))) => stability_command(&a),
        Some(Command::Study(StudyCommand::FromRest(a))) => from_rest_command(&a),
        Some(Command::Study(StudyCommand::Damping(a))) => damping_command(&a),
        Some(Command::Sweep(a)) => cmds::sweep_command(a),
        Some(Command::Bench(a)) => cmds::bench_command(a),
        Some(Command::Gpu(a)) => cmds::gpu::gpu_command(a, reach),
        Some(Command::Scenes) => {
            let scenes = builtin_scenes();
            let width = scenes
                .iter()
                .map(|s| s.name.chars().count())
                .max()
                .unwrap_or(0);
            for s in scenes {
                println!("{:<width$}  {}", s.name, s.description);
            }
            Ok(ExitCode::SUCCESS)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            // Names and values echoed from a scene file cannot drive the terminal.
            eprintln!("error: {}", printable(&format!("{e:#}")));
            ExitCode::from(2)
        }
    }
}

fn check_command(spec: &str) -> Result<ExitCode> {
    let scene = load_scene(spec)?;
    print!("{}", scene.describe());
    let mut sim = Simulation::new(scene.model.clone(), scene.params)
        .context("cannot set up the linear solver")?;
    let report = cosserat::observe::report::model_report(
        &scene.model,
        &scene.params,
        sim.n_dofs(),
        &sim.linear_solver().0.to_string(),
    );
    print!("{report}");
    let inv = sim.invariants();
    let v3 = |v: &cosserat::model::Vec3| format!("({:.6e}, {:.6e}, {:.6e})", v.x, v.y, v.z);
    println!(
        "  initial state: energy H = {:.9e} (kinetic {:.9e}, stored {:.9e}); L = {}; J = {} (about the origin)",
        inv.total(),
        inv.kinetic,
        inv.potential,
        v3(&inv.l),
        v3(&inv.j)
    );
    // Time estimate: a few trial steps of the real run (debug builds are ≈ 50× slower).
    let trial = scene.params.n_steps().min(5);
    let start = std::time::Instant::now();
    let mut done = 0;
    let mut failed = None;
    for _ in 0..trial {
        match sim.step() {
            Ok(_) => done += 1,
            Err(f) => {
                failed = Some(f.reason);
                break;
            }
        }
    }
    let per_step = start.elapsed().as_secs_f64() / done.max(1) as f64;
    match failed {
        Some(reason) if done == 0 => {
            println!("  time estimate: the first step already fails: {reason}")
        }
        _ => println!(
            "  time estimate: {:.3e} s per step from {done} trial step(s) → ≈ {:.3} s for {} steps{}",
            per_step,
            per_step * scene.params.n_steps() as f64,
            scene.params.n_steps(),
            if cfg!(debug_assertions) {
                " (debug build)"
            } else {
                ""
            }
        ),
    }
    Ok(ExitCode::SUCCESS)
}

/// The scheme a run uses: `--scheme` replaces the scene's scheme (keeping the scene's
/// constants when it names the same scheme, zero otherwise); `--alpha` sets α_Γv.
fn resolve_params(scene: &Scene, a: &RunArgs) -> Result<IntegratorParams> {
    let mut p = scene.params;
    let wanted = a
        .scheme
        .or(match (a.alpha, p.scheme) {
            (Some(_), Scheme::Edmc2 { .. }) | (None, _) => None,
            (Some(_), _) => Some(SchemeArg::Edmc2),
        })
        .or(match (a.rho_inf, p.scheme) {
            (Some(_), Scheme::GenAlpha { .. }) | (None, _) => None,
            (Some(_), _) => Some(SchemeArg::GenAlpha),
        });
    if let Some(s) = wanted {
        p.scheme = match (s, p.scheme) {
            (SchemeArg::Em, _) => Scheme::Em,
            (SchemeArg::Midpoint, _) => Scheme::Midpoint,
            (SchemeArg::GenAlpha, s @ Scheme::GenAlpha { .. }) => s,
            (SchemeArg::GenAlpha, _) => Scheme::GenAlpha {
                rho_inf: cosserat::integrator::gen_alpha::DEFAULT_RHO_INF,
            },
            (SchemeArg::Edmc1, s @ Scheme::Edmc1 { .. }) => s,
            (SchemeArg::Edmc1, _) => Scheme::Edmc1 {
                chi_gamma: 0.0,
                chi_omega: 0.0,
                chi_v: 0.0,
                chi_nu: 0.0,
            },
            (SchemeArg::Edmc2, s @ Scheme::Edmc2 { .. }) => s,
            (SchemeArg::Edmc2, _) => Scheme::edmc2(0.0),
        };
    }
    if let Some(alpha) = a.alpha {
        if !(alpha.is_finite() && alpha >= 0.0) {
            bail!("--alpha: must be a finite number ≥ 0 (got {})", num(alpha));
        }
        match &mut p.scheme {
            Scheme::Edmc2 { alpha_gv, .. } => *alpha_gv = alpha,
            other => bail!(
                "--alpha sets the EDMC-2 parameter α_Γv, but the scheme is {}",
                other.name()
            ),
        }
    }
    if let Some(rho) = a.rho_inf {
        if !(0.0..=1.0).contains(&rho) {
            bail!("--rho-inf: must be in [0, 1] (got {})", num(rho));
        }
        match &mut p.scheme {
            Scheme::GenAlpha { rho_inf } => *rho_inf = rho,
            other => bail!(
                "--rho-inf sets the generalized-α parameter ρ∞, but the scheme is {}",
                other.name()
            ),
        }
    }
    if let Some(dt) = a.dt {
        if !(dt.is_finite() && dt > 0.0) {
            bail!("--dt: must be a finite number > 0 (got {})", num(dt));
        }
        p.dt = dt;
    }
    if let Some(t) = a.t_end {
        if !(t.is_finite() && t > 0.0) {
            bail!("--t-end: must be a finite number > 0 (got {})", num(t));
        }
        p.t_end = t;
    }
    if p.dt > p.t_end {
        bail!(
            "--dt: Δt = {} exceeds t_end = {}: the run would take no step",
            num(p.dt),
            num(p.t_end)
        );
    }
    if p.t_end / p.dt > cosserat::scene::limits::MAX_STEPS {
        bail!(
            "--dt/--t-end: t_end / Δt = {:e} steps, above the limit of {:e} steps per run",
            p.t_end / p.dt,
            cosserat::scene::limits::MAX_STEPS
        );
    }
    if matches!(p.scheme, Scheme::GenAlpha { .. }) && !scene.model.links.is_empty() {
        bail!(
            "{}: gen-alpha does not support rigid links ([[link]]); use em, edmc1, edmc2 or midpoint",
            scene.source
        );
    }
    if let Some(r) = scene.model.rational_curvature_rod() {
        if p.scheme != Scheme::Em {
            bail!(
                "{}: rod `{}`: curvature_measure = \"rational\" runs with scheme em only (got {}); use --scheme em",
                scene.source,
                scene.model.rods[r].name,
                p.scheme.name()
            );
        }
    }
    if let Some(s) = a.strategy {
        p.strategy = s.strategy();
    }
    if let Some(n) = a.newton {
        p.newton = n.variant();
    }
    if a.no_fallback {
        p.fallback = false;
    }
    // Cut-back is on by default for `run` (cosserat::scene::RUN_CUTBACK halvings).
    p.cutback = a.cutback.map_or_else(|| scene.run_cutback(), usize::from);
    Ok(p)
}

fn run_command(a: RunArgs) -> Result<ExitCode> {
    let scene = if a.sets.is_empty() {
        load_scene(&a.scene)?
    } else {
        cosserat::sweep::scene_with_overrides(&a.scene, &a.sets).map_err(|e| anyhow!("{e}"))?
    };
    let params = resolve_params(&scene, &a)?;
    let out = match a.out.clone() {
        Some(o) => o,
        None => cosserat::paths::join_under(Path::new("out"), scene.file_stem())?,
    };
    let every = a.every.unwrap_or(scene.output_every).max(1);
    let trajectory = if let Some(dt) = a.output_dt {
        Some(OutputTimes::from_dt(dt, params.dt).map_err(|e| anyhow!("--output-dt: {e}"))?)
    } else if let Some(times) = &a.times {
        Some(
            OutputTimes::from_times(times, params.dt, params.n_steps())
                .map_err(|e| anyhow!("--times: {e}"))?,
        )
    } else {
        (a.trajectory || a.cosseratbench).then_some(OutputTimes::Every(every))
    };
    let cosseratbench = if a.cosseratbench {
        let mut cb = CosseratBenchOptions {
            scenario_digest: a.scenario_digest.clone(),
            ..Default::default()
        };
        if let Some(path) = &a.experiment_json {
            cb.read_experiment(path)
                .map_err(|e| anyhow!("--experiment-json: {e}"))?;
        }
        Some(cb)
    } else {
        None
    };
    let opts = RunOptions {
        every,
        vtk_every: a.vtk.then_some(every),
        snapshot_every: a.snapshots,
        label: scene.name.clone(),
        length_unit: "m".into(),
        trajectory,
        animate_every: match (a.animate_every, a.animate) {
            (Some(n), _) => Some(n),
            (None, true) => Some(params.n_steps().div_ceil(100).max(1)),
            (None, false) => None,
        },
        cosseratbench,
    };
    // The frames kept for the outputs, sized before anything is set up or written.
    if let Err(e) = opts.check_memory(&scene.model, params.n_steps()) {
        let fp = opts.footprint(&scene.model, params.n_steps());
        // Blame the options behind the largest part of the estimate, else the scene.
        let largest = fp.parts().into_iter().next().map(|(w, _)| w);
        let what = match largest.as_deref() {
            Some(w) if w.contains("trajectory frame") => "--trajectory/--output-dt/--times",
            Some(w) if w.contains("snapshot frame") => "--snapshots/--animate-every",
            _ => scene.source.as_str(),
        };
        bail!("{what}: {e}");
    }
    let mut sim =
        Simulation::new(scene.model.clone(), params).with_context(|| {
            format!(
                "{}: (model): cannot set up the linear solver for this scene (material and section values too small or too large for f64?)",
                scene.source
            )
        })?;
    // Keeps the GPU batch (if any) alive for the run.
    let _gpu = cmds::attach(&mut sim, a.backend, a.adapter.as_deref(), a.solve)?;
    let result = run_sim_to_dir(&scene, &mut sim, &out, &opts)?;
    print_summary(&result.summary, &out);
    Ok(ExitCode::SUCCESS)
}

fn reproduce_command(out: &Path, quick: bool, vtk: bool) -> Result<ExitCode> {
    let start = std::time::Instant::now();
    let done = reproduce(out, quick, vtk, |f| {
        let sm = &f.result.summary;
        let status = match sm.status {
            RunStatus::Completed => "completed".to_string(),
            RunStatus::Failed => format!("FAILED at t = {:.4}", sm.t_reached),
        };
        println!(
            "{:<18} {:<22} {status:<24} H {:.6e} → {:.6e}  ({:.2} s)",
            f.run.scene, f.run.folder, sm.energy_initial, sm.energy_final, sm.wall_s
        );
    })?;
    println!(
        "{} runs in {:.1} s; report: {}",
        done.len(),
        start.elapsed().as_secs_f64(),
        out.join("REPORT.md").display()
    );
    Ok(ExitCode::SUCCESS)
}

fn print_summary(s: &RunSummary, out: &Path) {
    let status = match s.status {
        RunStatus::Completed => "completed".to_string(),
        RunStatus::Failed => format!("FAILED ({})", s.reason.as_deref().unwrap_or("")),
    };
    let (e, i) = (&s.energy_balance, &s.impulse_balance);
    let momenta = if i.reactions {
        "L, J balance includes support/link/contact reactions".to_string()
    } else {
        format!(
            "L, J minus applied impulse: {:.1e}, {:.1e} (relative)",
            i.max_rel_residual_l, i.max_rel_residual_j
        )
    };
    println!(
        "{}: scheme {} Δt = {} — {status}; reached t = {} in {} steps, {} Newton iterations, {:.3} s. \
         H {:.9e} → {:.9e} (work {:+.3e}, dissipation {:.3e}, balance residual {:.1e}); {momenta}. \
         Outputs in {}.",
        s.scene,
        s.scheme,
        s.params.dt,
        s.t_reached,
        s.steps,
        s.newton_iters_total,
        s.wall_s,
        e.energy_initial,
        e.energy_final,
        e.work_total,
        e.dissipation_total,
        e.max_abs_residual,
        out.display()
    );
    if s.cutback_steps > 0 {
        println!(
            "{} of {} steps were cut back into sub-steps (cutback = {}; --cutback 0 turns it off).",
            s.cutback_steps, s.steps, s.params.cutback
        );
    }
    if s.timers.line_searches > 0 {
        println!(
            "{} Newton corrections that did not reduce the residual were shortened by a line search ({} evaluations).",
            s.timers.line_searches, s.timers.line_search_evaluations
        );
    }
}

fn default_jobs(jobs: Option<usize>) -> usize {
    jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1)
}

/// Loads a study's scene and applies the options every study takes (`--newton-tol`,
/// `--newton`, `--strategy`, `--no-fallback`, `--cutback`), after checking `--t-end` and
/// `--newton-tol`. Creates nothing: see [`write_study_summary`].
fn study_scene(c: &StudyCommon) -> Result<Scene> {
    let mut scene = load_scene(&c.scene)?;
    if let Some(t) = c.t_end {
        if !(t.is_finite() && t > 0.0) {
            bail!("--t-end: must be a finite number > 0 (got {})", num(t));
        }
    }
    if let Some(tol) = c.newton_tol {
        if !(tol.is_finite() && tol > 0.0) {
            bail!(
                "--newton-tol: must be a finite number > 0 (got {})",
                num(tol)
            );
        }
        scene.params.newton_tol = tol;
    }
    if let Some(n) = c.newton {
        scene.params.newton = n.variant();
    }
    if let Some(s) = c.strategy {
        scene.params.strategy = s.strategy();
    }
    if c.no_fallback {
        scene.params.fallback = false;
    }
    if let Some(n) = c.cutback {
        scene.params.cutback = n.into();
    }
    Ok(scene)
}

/// `OPTION: every value must be a finite number > 0` for a list option given on the
/// command line (`--dts`), or for a single value (`--reference-dt`).
fn check_positive(option: &str, values: &[f64]) -> Result<()> {
    if values.is_empty() {
        bail!("{option}: empty list");
    }
    if let Some(x) = values.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        bail!(
            "{option}: every value must be a finite number > 0 (got {})",
            num(*x)
        );
    }
    Ok(())
}

/// Creates a study's output directory (once every option has been checked) and records
/// the solver settings every run of the study shares in its `summary.json` (`study`,
/// `scene`, `params`: the integrator parameters with `newton`, `newton_tol`, `strategy`,
/// `fallback`, `cutback`; `strategy`: the one the dissipative runs use, `auto` resolved
/// for the GPU path when `gpu`, else the CPU path).
fn write_study_summary(
    c: &StudyCommon,
    study: &str,
    scene: &Scene,
    t_end: f64,
    gpu: bool,
) -> Result<()> {
    create_out(&c.out)?;
    let summary = serde_json::json!({
        "study": study,
        "scene": scene.name,
        "t_end": t_end,
        "params": scene.params,
        "strategy": scene.params.strategy.resolve(gpu).name(),
    });
    let path = c.out.join("summary.json");
    std::fs::write(&path, format!("{summary:#}\n"))
        .with_context(|| format!("cannot write {}", path.display()))
}

fn create_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory {}", out.display()))
}

fn work_precision_command(a: &WorkPrecisionArgs) -> Result<ExitCode> {
    // Every option is checked before the output directory is created.
    let scene = study_scene(&a.common)?;
    let schemes = a
        .schemes
        .iter()
        .map(|s| study::SchemeSpec::parse(s))
        .collect::<Result<Vec<_>, _>>()
        .context("--schemes")?;
    if let Some(dts) = &a.dts {
        check_positive("--dts", dts)?;
    }
    if let Some(r) = a.reference_dt {
        check_positive("--reference-dt", &[r])?;
    }
    let dt0 = scene.params.dt;
    let dts = a
        .dts
        .clone()
        .unwrap_or_else(|| vec![dt0, dt0 / 2.0, dt0 / 4.0, dt0 / 8.0]);
    let smallest = dts.iter().copied().fold(f64::INFINITY, f64::min);
    let cfg = study::WorkPrecisionConfig {
        schemes,
        t_end: a.common.t_end.unwrap_or(scene.params.t_end),
        reference_dt: a.reference_dt.unwrap_or(smallest / 8.0),
        dts,
        jobs: default_jobs(a.common.jobs),
    };
    cfg.check()?;
    write_study_summary(&a.common, "work-precision", &scene, cfg.t_end, false)?;
    let wp = study::work_precision(&scene, &cfg)?;
    study::write_work_precision_csv(&a.common.out.join("work_precision.csv"), &wp)?;
    study::plot_work_precision(&a.common.out.join("work_precision.png"), &wp)?;
    study::write_failures(&a.common.out.join("failures.txt"), &wp.failures())?;
    let mut seen = Vec::new();
    for r in &wp.rows {
        if !seen.contains(&r.spec) {
            seen.push(r.spec);
            let runs: Vec<_> = wp.rows.iter().filter(|x| x.spec == r.spec).collect();
            let failed = runs
                .iter()
                .filter(|x| x.status == RunStatus::Failed)
                .count();
            let order = if r.observed_order.is_finite() {
                format!(
                    "observed order {:>6.3} (fit over Δt {}–{})",
                    r.observed_order,
                    num(r.fit_dt_min),
                    num(r.fit_dt_max)
                )
            } else {
                "no asymptotic range".to_string()
            };
            println!(
                "{:<18} {order}   errors {}   ({} of {} runs failed)",
                r.spec.label(),
                runs.iter()
                    .map(|x| format!("{:.2e}", x.error))
                    .collect::<Vec<_>>()
                    .join(" "),
                failed,
                runs.len()
            );
        }
    }
    println!(
        "{}: work–precision study, reference EM Δt = {:e}; outputs in {}",
        scene.name,
        wp.reference_dt,
        a.common.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn damping_command(a: &DampingArgs) -> Result<ExitCode> {
    let scene = load_scene(&a.scene)?;
    let cfg = study::DampingConfig {
        values: a.values.clone(),
        periods: a.periods,
        steps_per_period: a.steps_per_period,
        amplitude: a.amplitude,
        jobs: default_jobs(a.jobs),
    };
    // Nothing is written until the study has run (a refused scene leaves no folder).
    let d = study::damping(&scene, &cfg)?;
    create_out(&a.out)?;
    study::write_damping_csv(&a.out.join("damping.csv"), &d)?;
    study::plot_damping(&a.out.join("damping.png"), &d)?;
    for mode in [study::ModeKind::Axial, study::ModeKind::Bending] {
        let rows: Vec<_> = d.rows.iter().filter(|r| r.mode == mode).collect();
        if let Some(r) = rows.first() {
            println!(
                "first {} mode: ω = {:.4e} rad/s, Δt = {:.4e} (ωΔt = {:.3})",
                mode.name(),
                r.omega,
                r.dt,
                r.omega * r.dt
            );
        }
        for r in rows {
            println!(
                "  {:<10} {:>8}  ζ = {:>10.3e}  energy lost per period {:>9.3e}{}",
                r.param,
                r.value,
                r.zeta,
                r.loss_per_period,
                r.reason
                    .as_deref()
                    .map(|w| format!("  FAILED: {w}"))
                    .unwrap_or_default()
            );
        }
    }
    println!(
        "{}: damping study; outputs in {}",
        scene.name,
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn from_rest_command(a: &FromRestArgs) -> Result<ExitCode> {
    // Every option is checked before the output directory is created.
    let scene = study_scene(&a.common)?;
    let rows = a
        .params
        .iter()
        .map(|k| study::FromRestRow::parse(k, a.value))
        .collect::<Result<Vec<_>, _>>()
        .context("--params")?;
    let dt0 = scene.params.dt;
    let dts = match (&a.dts, &a.dt_range) {
        (Some(d), _) => {
            check_positive("--dts", d)?;
            d.clone()
        }
        (None, Some(r)) => {
            if r.len() != 3 {
                bail!(
                    "--dt-range: expected MIN,MAX,COUNT (got {} values)",
                    r.len()
                );
            }
            check_positive("--dt-range", &r[..2])?;
            let n = r[2];
            if !(n >= 1.0 && n.fract() == 0.0 && n <= 1000.0) {
                bail!(
                    "--dt-range: COUNT must be a whole number from 1 to 1000 (got {})",
                    num(n)
                );
            }
            study::log_grid(r[0], r[1], n as usize)
        }
        (None, None) => study::log_grid(dt0 / 4.0, 4.0 * dt0, 9),
    };
    let cfg = study::FromRestConfig {
        rows,
        dts,
        t_end: a.common.t_end.unwrap_or(scene.params.t_end),
        jobs: default_jobs(a.common.jobs),
    };
    cfg.check()?;
    write_study_summary(&a.common, "from-rest", &scene, cfg.t_end, false)?;
    let fr = study::from_rest(&scene, &cfg)?;
    study::write_from_rest_csv(&a.common.out.join("from_rest.csv"), &fr)?;
    study::plot_from_rest(&a.common.out.join("from_rest.png"), &fr)?;
    study::write_failures(&a.common.out.join("failures.txt"), &fr.failures())?;
    let counts = fr
        .counts()
        .iter()
        .map(|(o, n)| format!("{} {n}", o.name()))
        .collect::<Vec<_>>()
        .join(", ");
    println!(
        "{}: from-rest map, {} cells: {counts}; outputs in {}",
        scene.name,
        fr.cells.len(),
        a.common.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn stability_command(a: &StabilityArgs) -> Result<ExitCode> {
    // Every option is checked before the output directory is created.
    let scene = study_scene(&a.common)?;
    let kinds = a
        .schemes
        .iter()
        .map(|s| {
            study::SchemeKind::parse(s.trim()).with_context(|| {
                format!("--schemes: unknown scheme `{s}` (expected em, edmc1, edmc2, midpoint or gen-alpha)")
            })
        })
        .collect::<Result<Vec<_>>>()?;
    if let Some(dts) = &a.dts {
        check_positive("--dts", dts)?;
    }
    let dt0 = scene.params.dt;
    let cfg = study::StabilityConfig {
        kinds,
        params: a.params.clone(),
        rho_infs: a.rho_inf.clone(),
        dts: a
            .dts
            .clone()
            .unwrap_or_else(|| vec![dt0 / 4.0, dt0 / 2.0, dt0, 2.0 * dt0, 4.0 * dt0]),
        t_end: a.common.t_end.unwrap_or(scene.params.t_end),
        jobs: default_jobs(a.common.jobs),
    };
    cfg.check()?;
    let exec = cmds::executor(a.backend, a.adapter.as_deref())?;
    write_study_summary(
        &a.common,
        "stability",
        &scene,
        cfg.t_end,
        matches!(exec, cosserat::batch::Executor::Gpu(_)),
    )?;
    if a.backend != cmds::BackendArg::Cpu {
        println!("backend: {}", exec.describe());
    }
    let st = study::stability_on(&scene, &cfg, &exec)?;
    study::write_stability_csv(&a.common.out.join("stability.csv"), &st)?;
    study::plot_stability(&a.common.out.join("stability.png"), &st)?;
    study::write_failures(&a.common.out.join("failures.txt"), &st.failures())?;
    let done = st
        .cells
        .iter()
        .filter(|c| c.status == RunStatus::Completed)
        .count();
    println!(
        "{}: stability study, {done} of {} runs completed; outputs in {}",
        scene.name,
        st.cells.len(),
        a.common.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
