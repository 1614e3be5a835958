//! The batch benchmark of `cosserat bench` as a library call (the command and the Python
//! package run this one): the benchmark cantilever ([`crate::batch::bench_members`]) as a
//! batch of rods, timed on the CPU path and on the GPU path, and the JSON object
//! `cosserat bench --json` prints ([`BenchRun::json`]).

use crate::batch::{
    bench_members, run_members, BackendChoice, BatchOptions, BatchStats, Executor, SolveMode,
};
use crate::gpu::GpuError;
use crate::integrator::{NewtonVariant, SolveTimers, Strategy};
use crate::observe::record::RunStatus;
use crate::scene::limits;

/// Where the GPU batches of a benchmark solve their Newton systems.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchSolve {
    /// The host solves (one GPU batch).
    Host,
    /// The device solves (one GPU batch).
    Device,
    /// Both, one after the other.
    Both,
    /// Device solves, then several Newton iterations per submission (`--solve resident`),
    /// one after the other.
    Resident,
    /// Only `--solve whole` (EM members the device step covers run their steps entirely
    /// on the device): the quick measurement of that mode (JSON: the `whole` object).
    Whole,
}

/// What to time: the options of `cosserat bench`.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchOptions {
    /// Rods (batch members); default 64.
    pub rods: usize,
    /// Elements per rod; default 30.
    pub elements: usize,
    /// Time steps; default 20.
    pub steps: usize,
    /// GPU adapter: the first whose name contains this (None: the default adapter).
    pub adapter: Option<String>,
    /// Time the CPU path only.
    pub cpu_only: bool,
    /// Time the GPU path only.
    pub gpu_only: bool,
    /// Newton variant; default full.
    pub newton: NewtonVariant,
    /// Dissipation strategy of the EDMC-2 members; default auto.
    pub strategy: Strategy,
    /// GPU path: members in flight (0: as many as fit).
    pub slots: usize,
    /// GPU path: where the Newton systems are solved; default host.
    pub solve: BenchSolve,
    /// Device solve with the host adding each correction.
    pub host_update: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            rods: 64,
            elements: 30,
            steps: 20,
            adapter: None,
            cpu_only: false,
            gpu_only: false,
            newton: NewtonVariant::Full,
            strategy: Strategy::Auto,
            slots: 0,
            solve: BenchSolve::Host,
            host_update: false,
        }
    }
}

/// Why a benchmark did not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// An option out of range (`key` names it: `elements`, `rods`).
    #[error("{key}: {reason}")]
    Option {
        /// The option.
        key: &'static str,
        /// Why.
        reason: String,
    },
    /// The batch would not fit in the memory limit.
    #[error(transparent)]
    Limit(#[from] limits::LimitError),
    /// The benchmark scene could not be built.
    #[error("the benchmark cantilever: {0}")]
    Scene(#[from] crate::scene::SceneError),
    /// The adapter named in [`BenchOptions::adapter`] was not found, or
    /// [`BenchOptions::gpu_only`] found no GPU.
    #[error("no GPU to time: {0}")]
    NoGpu(GpuError),
    /// A batch failed on the device (`what`: `GPU batch`, `GPU batch, device solve`).
    #[error("{what}: {error}")]
    Batch {
        /// Which batch.
        what: &'static str,
        /// The device error.
        error: GpuError,
    },
}

/// One timed batch: its stats, Newton iterations, failed members (with the first one's
/// reason), the members' summed Newton stage timers and the process's peak resident memory
/// after it.
#[derive(Clone, Debug)]
pub struct Timed {
    /// The batch's statistics.
    pub stats: BatchStats,
    /// Newton iterations over all members.
    pub iters: usize,
    /// Failed members.
    pub failed: usize,
    /// The first failed member and its reason.
    pub first_failure: Option<(usize, String)>,
    /// Summed Newton stage timers.
    pub stages: SolveTimers,
    /// Peak resident set size after the batch (Linux), if known.
    pub peak_rss: Option<u64>,
}

fn timed(
    members: &[crate::batch::Member],
    exec: &Executor,
    newton: NewtonVariant,
    slots: usize,
    solve: SolveMode,
    host_update: bool,
) -> Result<Timed, GpuError> {
    let (mut iters, mut failed) = (0usize, 0usize);
    let mut first_failure = None;
    let mut stages = SolveTimers::default();
    let opts = BatchOptions {
        newton: Some(newton),
        workers: slots,
        solve,
        host_update,
        ..Default::default()
    };
    let stats = run_members(members, exec, opts, |r| {
        iters += r.outcome.newton_iters_total;
        stages.add(&r.outcome.timers);
        if r.outcome.status == RunStatus::Failed {
            if failed == 0 {
                first_failure = Some((r.index, r.outcome.reason.clone().unwrap_or_default()));
            }
            failed += 1;
        }
    })?;
    Ok(Timed {
        stats,
        iters,
        failed,
        first_failure,
        stages,
        peak_rss: peak_rss_bytes(),
    })
}

/// The benchmark members' scheme: EDMC-2 α = 0.5, or EM with `COSSERAT_BENCH_SCHEME=em`
/// (for measurements of `--solve whole`, which keeps EM members' states on the device).
pub fn bench_scheme() -> crate::integrator::Scheme {
    match std::env::var("COSSERAT_BENCH_SCHEME")
        .as_deref()
        .map(str::trim)
    {
        Ok("em") => crate::integrator::Scheme::Em,
        _ => crate::integrator::Scheme::edmc2(0.5),
    }
}

/// The benchmark's gravity: `COSSERAT_BENCH_GRAVITY=1` hangs the cantilevers under
/// gravity (9.81 m/s² across them), a dead load `--solve whole` forms on the device;
/// otherwise none.
pub fn bench_gravity() -> crate::model::Vec3 {
    match std::env::var("COSSERAT_BENCH_GRAVITY")
        .as_deref()
        .map(str::trim)
    {
        Ok("1") => crate::model::Vec3::new(0.0, 0.0, -9.81),
        _ => crate::model::Vec3::zeros(),
    }
}

/// The process's peak resident set size (Linux `VmHWM`), if known.
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// A finished benchmark: the options, the timed batches and the adapter.
#[derive(Clone, Debug)]
pub struct BenchRun {
    /// What was timed.
    pub opts: BenchOptions,
    /// The CPU batch (None with `gpu_only`).
    pub cpu: Option<Timed>,
    /// The GPU batch with host solves (None without a GPU or without it in `solve`).
    pub gpu: Option<Timed>,
    /// The GPU batch with device solves.
    pub device: Option<Timed>,
    /// The GPU batch with resident Newton iterations (`BenchSolve::Resident`).
    pub resident: Option<Timed>,
    /// The same with the EM members' states kept on the device (`--solve whole`, timed
    /// with `BenchSolve::Resident`): EM members the device step covers run their steps
    /// entirely on the device.
    pub whole: Option<Timed>,
    /// `--solve whole` without whole steps on the device (the host runs every step, the
    /// device keeps the state): the comparison run, timed first.
    pub whole_host_steps: Option<Timed>,
    /// The adapter's description, `none`, or `none (why)`.
    pub adapter: String,
    /// Whether the adapter has f64 shaders.
    pub f64: bool,
    /// Peak resident memory before the first batch.
    pub peak_rss_before: Option<u64>,
}

/// Runs the benchmark: checks the sizes against the limits, builds the members, times the
/// CPU batch, then the GPU batch(es) where a GPU exists (an adapter that is named, or
/// `gpu_only`, and not found is an error before the CPU batch runs).
pub fn run(opts: &BenchOptions) -> Result<BenchRun, BenchError> {
    if opts.elements > limits::MAX_SCENE_ELEMENTS {
        return Err(BenchError::Option {
            key: "elements",
            reason: format!(
                "{} elements per rod, above the limit of {} for one scene",
                opts.elements,
                limits::MAX_SCENE_ELEMENTS
            ),
        });
    }
    if opts.rods as u64 > limits::MAX_MEMBERS {
        return Err(BenchError::Option {
            key: "rods",
            reason: format!(
                "{} rods, above the limit of {} members per batch",
                opts.rods,
                limits::MAX_MEMBERS
            ),
        });
    }
    for (key, v) in [
        ("rods", opts.rods),
        ("elements", opts.elements),
        ("steps", opts.steps),
    ] {
        if v == 0 {
            return Err(BenchError::Option {
                key,
                reason: "must be an integer ≥ 1 (got 0)".into(),
            });
        }
    }
    limits::check_memory("bench", opts.rods as u64, opts.elements as u64)?;
    let mut members = bench_members(opts.rods, opts.elements, opts.steps)?;
    let (scheme, gravity) = (bench_scheme(), bench_gravity());
    for m in &mut members {
        m.params.strategy = opts.strategy;
        m.params.scheme = scheme;
        m.model.gravity = gravity;
    }
    let gpu_exec = if opts.cpu_only {
        Ok((Executor::Cpu, None))
    } else {
        Executor::resolve(BackendChoice::Gpu, opts.adapter.as_deref())
    };
    let gpu_exec = match gpu_exec {
        Err(e) if opts.adapter.is_some() || opts.gpu_only => return Err(BenchError::NoGpu(e)),
        other => other,
    };
    let peak_rss_before = peak_rss_bytes();
    let batch = |what: &'static str| move |error| BenchError::Batch { what, error };
    let cpu = if opts.gpu_only {
        None
    } else {
        Some(
            timed(
                &members,
                &Executor::Cpu,
                opts.newton,
                opts.slots,
                SolveMode::Host,
                false,
            )
            .map_err(batch("CPU batch"))?,
        )
    };
    let (host_solve, device_solve) = match opts.solve {
        BenchSolve::Host => (true, false),
        BenchSolve::Device => (false, true),
        BenchSolve::Both => (true, true),
        BenchSolve::Resident => (false, true),
        BenchSolve::Whole => (false, false),
    };
    let resident_solve = opts.solve == BenchSolve::Resident;
    let (adapter, f64_ok, gpu, device, (resident, whole, whole_host_steps)) = match &gpu_exec {
        Ok((exec @ Executor::Gpu(ctx), _)) => {
            let g = if host_solve {
                Some(
                    timed(
                        &members,
                        exec,
                        opts.newton,
                        opts.slots,
                        SolveMode::Host,
                        false,
                    )
                    .map_err(batch("GPU batch"))?,
                )
            } else {
                None
            };
            let d = if device_solve {
                Some(
                    timed(
                        &members,
                        exec,
                        opts.newton,
                        opts.slots,
                        SolveMode::Device,
                        opts.host_update,
                    )
                    .map_err(batch("GPU batch, device solve"))?,
                )
            } else {
                None
            };
            // `--solve whole`, with steps on the device or (`device_steps` false) on the host.
            let whole = |device_steps: bool, what: &'static str| {
                crate::batch::gpu::set_device_steps(device_steps);
                let t = timed(
                    &members,
                    exec,
                    opts.newton,
                    opts.slots,
                    SolveMode::Whole,
                    false,
                );
                crate::batch::gpu::set_device_steps(true);
                t.map_err(batch(what))
            };
            let r = if resident_solve {
                let resident = timed(
                    &members,
                    exec,
                    opts.newton,
                    opts.slots,
                    SolveMode::Resident,
                    false,
                )
                .map_err(batch("GPU batch, resident"))?;
                let before = whole(false, "GPU batch, whole (host steps)")?;
                let after = whole(true, "GPU batch, whole")?;
                (Some(resident), Some(after), Some(before))
            } else if opts.solve == BenchSolve::Whole {
                (None, Some(whole(true, "GPU batch, whole")?), None)
            } else {
                (None, None, None)
            };
            (ctx.describe(), ctx.is_f64(), g, d, r)
        }
        Ok((Executor::Cpu, _)) => ("none".into(), false, None, None, (None, None, None)),
        Err(e) => (format!("none ({e})"), false, None, None, (None, None, None)),
    };
    Ok(BenchRun {
        opts: opts.clone(),
        cpu,
        gpu,
        device,
        resident,
        whole,
        whole_host_steps,
        adapter,
        f64: f64_ok,
        peak_rss_before,
    })
}

/// The stage timers as JSON fields prefixed with `p`.
fn stages_json(obj: &mut serde_json::Value, p: &str, t: &SolveTimers) {
    obj[format!("{p}_assemble_s")] = t.assemble_s.into();
    obj[format!("{p}_evaluate_wait_s")] = t.evaluate_wait_s.into();
    obj[format!("{p}_factor_s")] = t.factor_s.into();
    obj[format!("{p}_solve_s")] = t.solve_s.into();
    obj[format!("{p}_factorizations")] = t.factorizations.into();
    obj[format!("{p}_solves")] = t.solves.into();
    obj[format!("{p}_chord_corrections")] = t.chord_corrections.into();
    obj[format!("{p}_stagnation_stops")] = t.stagnation_stops.into();
    obj[format!("{p}_line_searches")] = t.line_searches.into();
    obj[format!("{p}_line_search_evaluations")] = t.line_search_evaluations.into();
    obj[format!("{p}_factor_us_each")] =
        (1e6 * t.factor_s / (t.factorizations.max(1) as f64)).into();
    obj[format!("{p}_solve_us_each")] = (1e6 * t.solve_s / (t.solves.max(1) as f64)).into();
}

/// The inputs of the batch throughput model (docs/gpu.md, "Throughput model") measured on
/// a GPU batch: per element evaluation, per member poll, per dispatch.
fn gpu_model_json(obj: &mut serde_json::Value, g: &Timed, o: &BenchOptions) {
    let (w, k, sv) = (&g.stats, &g.stats.gpu, &g.stats.serve);
    let evals = sv.element_evals.max(1) as f64;
    let threads = rayon::current_num_threads() as f64;
    let member_steps = (o.rods * o.steps) as f64;
    obj["gpu_wall_s"] = w.wall_s.into();
    obj["gpu_newton_iters"] = g.iters.into();
    obj["gpu_failed"] = g.failed.into();
    obj["gpu_setup_s"] = w.setup_s.into();
    obj["gpu_admit_s"] = w.admit_s.into();
    obj["gpu_slots"] = w.slots.into();
    obj["gpu_upload_s"] = k.upload_s.into();
    obj["gpu_kernel_s"] = k.kernel_s.into();
    obj["gpu_readback_s"] = k.readback_s.into();
    obj["gpu_unpack_s"] = k.unpack_s.into();
    obj["gpu_pack_s"] = sv.pack_s.into();
    obj["gpu_host_member_phase_s"] = w.host_s.into();
    obj["gpu_dispatches"] = k.dispatches.into();
    obj["gpu_batch_iterations"] = w.iterations.into();
    obj["gpu_bytes_up"] = k.bytes_up.into();
    obj["gpu_bytes_down"] = k.bytes_down.into();
    obj["gpu_copies"] = k.copies.into();
    obj["gpu_readback_copies"] = k.readback_copies.into();
    obj["gpu_requests"] = sv.requests.into();
    obj["gpu_tangent_requests"] = sv.tangent_requests.into();
    obj["gpu_element_evals"] = sv.element_evals.into();
    obj["gpu_element_tangent_evals"] = sv.element_tangent_evals.into();
    // Model inputs.
    obj["model_copies_per_dispatch"] = (k.copies as f64 / k.dispatches.max(1) as f64).into();
    obj["model_readback_copies_per_dispatch"] =
        (k.readback_copies as f64 / k.dispatches.max(1) as f64).into();
    obj["model_kernel_us_per_element_eval"] = (1e6 * k.kernel_s / evals).into();
    obj["model_tangent_fraction"] = (sv.element_tangent_evals as f64 / evals).into();
    obj["model_bytes_up_per_element_eval"] = (k.bytes_up as f64 / evals).into();
    obj["model_bytes_down_per_element_eval"] = (k.bytes_down as f64 / evals).into();
    let reqs = sv.requests.max(1) as f64;
    obj["model_bytes_up_per_member_iteration"] = (k.bytes_up as f64 / reqs).into();
    obj["model_bytes_down_per_member_iteration"] = (k.bytes_down as f64 / reqs).into();
    obj["model_evals_per_member_step"] = (sv.requests as f64 / member_steps).into();
    obj["model_dispatches_per_step"] = (k.dispatches as f64 / o.steps.max(1) as f64).into();
    obj["model_host_thread_us_per_member_poll"] =
        (1e6 * w.host_s * threads / (w.polls.max(1) as f64)).into();
    obj["model_serve_thread_us_per_dispatch"] =
        (1e6 * w.serve_thread_s / (k.dispatches.max(1) as f64)).into();
    obj["model_serve_thread_us_per_request"] =
        (1e6 * w.serve_thread_s / (sv.requests.max(1) as f64)).into();
    obj["model_pack_us_per_request"] = (1e6 * sv.pack_s / (sv.requests.max(1) as f64)).into();
    obj["model_unpack_us_per_request"] = (1e6 * k.unpack_s / (sv.requests.max(1) as f64)).into();
    obj["model_dispatch_overhead_us"] =
        (1e6 * (k.upload_s + k.readback_s) / (k.dispatches.max(1) as f64)).into();
    obj["model_host_own_assemble_us_per_eval"] =
        (1e6 * g.stages.assemble_s / (sv.requests.max(1) as f64)).into();
    obj["gpu_peak_rss_bytes"] = g.peak_rss.into();
    // The whole-step figures (docs/gpu.md, "Whole step on the device").
    obj["host_syncs"] = sv.dispatches.into();
    obj["host_syncs_per_step"] = (sv.dispatches as f64 / o.steps.max(1) as f64).into();
    obj["host_thread_us_per_member_step"] =
        (1e6 * (w.host_s * threads + w.serve_thread_s) / member_steps).into();
    // The host's own share per member-step: the member polls' CPU time (not the pool's
    // idle time) and the driver thread's CPU time outside the graphics driver's
    // submissions and waits (on a software adapter those run the device's work itself).
    obj["host_own_us_per_member_step"] =
        (1e6 * (w.member_cpu_s + w.serve_thread_s - w.serve_driver_s) / member_steps).into();
    // Per device step in the steady state (batch iterations that served device steps
    // only, after one that did too): the median and the 90th percentile over those
    // iterations, robust to the preemptions a loaded machine adds to a mean.
    let quantile = |v: &[f64], q: f64| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v.get(((v.len() as f64 - 1.0) * q).round() as usize)
            .copied()
    };
    obj["device_step_rounds"] = w.device_step_host_us.len().into();
    obj["host_own_us_per_device_step"] = quantile(&w.device_step_host_us, 0.5).into();
    obj["host_own_us_per_device_step_p90"] = quantile(&w.device_step_host_us, 0.9).into();
    obj["serve_own_us_per_device_step"] = quantile(&w.device_step_serve_us, 0.5).into();
    // The host's wall time per steady batch iteration outside the driver: what it adds to
    // the device's time per step (the model's T_host).
    obj["host_wall_us_per_dispatch"] = quantile(&w.device_step_critical_us, 0.5).into();
    obj["member_cpu_us_per_member_step"] = (1e6 * w.member_cpu_s / member_steps).into();
    obj["serve_own_us_per_member_step"] =
        (1e6 * (w.serve_thread_s - w.serve_driver_s) / member_steps).into();
    obj["driver_thread_us_per_member_step"] = (1e6 * w.serve_driver_s / member_steps).into();
    obj["driver_thread_us_per_dispatch"] =
        (1e6 * w.serve_driver_s / (k.dispatches.max(1) as f64)).into();
    // In dispatches of device steps only: what a device step costs once a member runs.
    let (dup, dn) = sv.device_step_bytes_up;
    if dn > 0 {
        obj["device_step_bytes_up_per_step"] = (dup as f64 / dn as f64).into();
    }
    obj["bus_bytes_per_member_step"] = ((k.bytes_up + k.bytes_down) as f64 / member_steps).into();
    obj["bus_bytes_up_per_member_step"] = (k.bytes_up as f64 / member_steps).into();
    obj["bus_bytes_down_per_member_step"] = (k.bytes_down as f64 / member_steps).into();
    obj["device_pass_s"] = k.kernel_s.into();
    obj["gpu_wall_over_device_pass"] = ((w.wall_s - w.setup_s) / k.kernel_s.max(1e-12)).into();
    obj["multi_dispatches"] = sv.multi_dispatches.into();
    obj["multi_solves"] = sv.multi_solves.into();
    obj["multi_iterations"] = sv.multi_iterations.into();
    obj["multi_answers"] = sv.multi_answers.into();
    obj["multi_bytes_down_per_solve"] =
        (sv.multi_bytes_down as f64 / sv.multi_solves.max(1) as f64).into();
    obj["multi_mismatches"] = sv.multi_mismatches.into();
    obj["device_steps"] = sv.device_steps.into();
    obj["device_step_handoffs"] = sv.device_step_handoffs.into();
    obj["device_step_bytes_down_per_step"] =
        (sv.device_step_bytes_down as f64 / sv.device_steps.max(1) as f64).into();
    obj["state_pulls"] = sv.state_pulls.into();
    obj["state_pull_bytes_down"] = sv.pull_bytes_down.into();
    stages_json(obj, "gpu", &g.stages);
}

impl BenchRun {
    /// Element-steps (rods × elements × steps) of the batch.
    fn work(&self) -> f64 {
        (self.opts.rods * self.opts.elements * self.opts.steps) as f64
    }

    /// Rod-steps (rods × steps) of the batch.
    fn rod_steps(&self) -> f64 {
        (self.opts.rods * self.opts.steps) as f64
    }

    /// Element-steps per second of the CPU batch.
    pub fn cpu_rate(&self) -> Option<f64> {
        self.cpu.as_ref().map(|c| self.work() / c.stats.wall_s)
    }

    /// Element-steps per second of the GPU batch (host solves).
    pub fn gpu_rate(&self) -> Option<f64> {
        self.gpu.as_ref().map(|g| self.work() / g.stats.wall_s)
    }

    /// Element-steps per second of the GPU batch with device solves.
    pub fn device_rate(&self) -> Option<f64> {
        self.device.as_ref().map(|g| self.work() / g.stats.wall_s)
    }

    /// Element-steps per second of the GPU batch with resident Newton iterations.
    pub fn resident_rate(&self) -> Option<f64> {
        self.resident.as_ref().map(|g| self.work() / g.stats.wall_s)
    }

    /// The object `cosserat bench --json` prints.
    pub fn json(&self) -> serde_json::Value {
        let o = &self.opts;
        let rod_steps = self.rod_steps();
        let cpu_rate = self.cpu_rate();
        let gpu_rate = self.gpu_rate();
        let dev_rate = self.device_rate();
        let ratio = gpu_rate.zip(cpu_rate).map(|(g, c)| g / c);
        let dev_ratio = dev_rate.zip(cpu_rate).map(|(g, c)| g / c);
        let mut obj = serde_json::json!({
            "rods": o.rods,
            "elements": o.elements,
            "steps": o.steps,
            "newton": o.newton.name(),
            "strategy": o.strategy.name(),
            "scheme": bench_scheme().name(),
            "gravity": bench_gravity().z,
            "cpu_strategy": self.cpu.as_ref().map(|_| o.strategy.resolve(false).name()),
            "gpu_strategy": (self.gpu.is_some() || self.device.is_some() || self.resident.is_some())
                .then(|| o.strategy.resolve(true).name()),
            "cpu_element_steps_per_s": cpu_rate,
            "gpu_element_steps_per_s": gpu_rate,
            "cpu_rod_steps_per_s": self.cpu.as_ref().map(|c| rod_steps / c.stats.wall_s),
            "gpu_rod_steps_per_s": self.gpu.as_ref().map(|g| rod_steps / g.stats.wall_s),
            "ratio": ratio,
            "adapter": self.adapter,
            "f64": self.f64,
            "cpu_threads": rayon::current_num_threads(),
            "peak_rss_bytes_before": self.peak_rss_before,
        });
        if let Some(c) = &self.cpu {
            obj["cpu_wall_s"] = c.stats.wall_s.into();
            obj["cpu_newton_iters"] = c.iters.into();
            obj["cpu_failed"] = c.failed.into();
            obj["cpu_peak_rss_bytes"] = c.peak_rss.into();
            obj["cpu_thread_us_per_member_iteration"] =
                (1e6 * c.stats.wall_s * rayon::current_num_threads() as f64
                    / (c.iters.max(1) as f64))
                    .into();
            obj["cpu_thread_us_per_member_step"] =
                (1e6 * c.stats.wall_s * rayon::current_num_threads() as f64 / rod_steps).into();
            stages_json(&mut obj, "cpu", &c.stages);
        }
        if let Some(g) = &self.gpu {
            gpu_model_json(&mut obj, g, o);
        }
        if let Some(d) = &self.device {
            let mut v = serde_json::json!({
                "solve": "device",
                "element_steps_per_s": dev_rate,
                "rod_steps_per_s": rod_steps / d.stats.wall_s,
                "ratio": dev_ratio,
                "members_device_solved": d.stats.device_members.0,
                "members_host_solved": d.stats.device_members.1,
                "host_update": o.host_update,
                "resident_iterations": d.stats.serve.resident_iterations,
                "resident_bytes_down_per_iteration": d.stats.serve.resident_bytes_down as f64
                    / d.stats.serve.resident_iterations.max(1) as f64,
                "fetches": d.stats.serve.fetches,
                "iterates_sent": d.stats.serve.iterates_sent,
                "fetch_bytes_down_each": d.stats.serve.fetch_bytes_down as f64
                    / (d.stats.serve.fetches + d.stats.serve.iterates_sent).max(1) as f64,
            });
            gpu_model_json(&mut v, d, o);
            obj["device"] = v;
        }
        if let Some(d) = &self.resident {
            let res_rate = self.resident_rate();
            let mut v = serde_json::json!({
                "solve": "resident",
                "iterations_per_submission": crate::batch::resident_k(),
                "element_steps_per_s": res_rate,
                "rod_steps_per_s": rod_steps / d.stats.wall_s,
                "ratio": res_rate.zip(cpu_rate).map(|(g, c)| g / c),
                "members_device_solved": d.stats.device_members.0,
                "members_host_solved": d.stats.device_members.1,
            });
            gpu_model_json(&mut v, d, o);
            obj["resident"] = v;
        }
        for (key, d) in [
            ("whole", &self.whole),
            ("whole_host_steps", &self.whole_host_steps),
        ] {
            let Some(d) = d else { continue };
            let rate = self.work() / d.stats.wall_s;
            let mut v = serde_json::json!({
                "solve": "whole",
                // (`auto` is the inexact strategy under `--solve whole`.)
                "strategy": o.strategy.resolve_for(true, true).name(),
                "iterations_per_submission": crate::batch::resident_k(),
                "element_steps_per_s": rate,
                "rod_steps_per_s": rod_steps / d.stats.wall_s,
                "ratio": cpu_rate.map(|c| rate / c),
                "members_device_solved": d.stats.device_members.0,
                "members_host_solved": d.stats.device_members.1,
                "device_advances": d.stats.serve.device_advances,
                "advance_submits": d.stats.serve.advance_submits,
            });
            gpu_model_json(&mut v, d, o);
            obj[key] = v;
        }
        obj
    }
}
