//! Python bindings of the `cosserat` crate: scenes, one simulation stepped from Python with
//! its state as NumPy arrays, and sweeps. A thin layer: every number comes from the engine
//! (`cosserat::integrator::Simulation::step`, `cosserat::integrator::run::RunLog`,
//! `cosserat::sweep::run_sweep`); nothing here computes physics.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use cosserat::batch::{BackendChoice, Executor, GpuBatcher};
use cosserat::integrator::record::StepRecord;
use cosserat::integrator::run::RunLog;
use cosserat::integrator::{IntegratorParams, Scheme};
use cosserat::output::{history_values, HISTORY_COLUMNS};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList};

create_exception!(
    _cosserat,
    SceneError,
    PyValueError,
    "A scene (or a value set in it) is invalid. The message reads `FILE[:LINE:COL]: KEY: REASON`; the attributes `file`, `key`, `line`, `column` and `reason` give the parts (None when not known)."
);

/// How often a long run looks at Python's signal handlers (Ctrl-C).
const SIGNAL_CHECK: Duration = Duration::from_millis(20);

fn scene_error(e: &cosserat::scene::SceneError, file: &str) -> PyErr {
    let err = SceneError::new_err(e.to_string());
    Python::with_gil(|py| {
        let v = err.value(py);
        let (line, column) = e.location().unzip();
        let msg = e.to_string();
        let reason = match e.key() {
            Some(k) => msg
                .split_once(&format!("{k}: "))
                .map_or(msg.clone(), |(_, r)| r.to_string()),
            None => msg
                .rsplit_once(": ")
                .map_or(msg.clone(), |(_, r)| r.to_string()),
        };
        let _ = v.setattr("file", file);
        let _ = v.setattr("key", e.key());
        let _ = v.setattr("line", line);
        let _ = v.setattr("column", column);
        let _ = v.setattr("reason", reason);
    });
    err
}

/// A validated scene: its TOML text, where it came from and the values set in it.
#[pyclass(module = "cosserat")]
#[derive(Clone)]
struct Scene {
    text: String,
    source: String,
    sets: Vec<(String, f64)>,
    scene: cosserat::scene::Scene,
}

impl Scene {
    fn parse(text: String, source: String, sets: Vec<(String, f64)>) -> PyResult<Self> {
        let scene = cosserat::scene::parse_scene_with_sets(&text, &source, &sets)
            .map_err(|e| scene_error(&e, &source))?;
        Ok(Self {
            text,
            source,
            sets,
            scene,
        })
    }
}

#[pymethods]
impl Scene {
    /// A built-in scene by name (`cosserat.builtin_scenes()` lists them).
    #[staticmethod]
    fn builtin(name: &str) -> PyResult<Self> {
        let b = cosserat::scene::builtin_scenes()
            .iter()
            .find(|b| b.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = cosserat::scene::builtin_scenes()
                    .iter()
                    .map(|b| b.name)
                    .collect();
                let e = SceneError::new_err(format!(
                    "unknown built-in scene `{name}` (built-in scenes: {})",
                    names.join(", ")
                ));
                Python::with_gil(|py| {
                    let v = e.value(py);
                    let _ = v.setattr("file", format!("builtin:{name}"));
                    let _ = v.setattr("key", py.None());
                    let _ = v.setattr("line", py.None());
                    let _ = v.setattr("column", py.None());
                    let _ = v.setattr("reason", "no built-in scene of that name");
                });
                e
            })?;
        Self::parse(b.toml.to_string(), format!("builtin:{}", b.name), vec![])
    }

    /// A scene file.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let source = path.display().to_string();
        let text = cosserat::scene::read_scene_file(&path).map_err(|e| scene_error(&e, &source))?;
        Self::parse(text, source, vec![])
    }

    /// A scene from TOML text; `source` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, source = "<string>"))]
    fn from_toml(text: String, source: &str) -> PyResult<Self> {
        Self::parse(text, source.to_string(), vec![])
    }

    /// Writes the number `value` at the key path `key` (`integrator.dt`,
    /// `rod[0].elements`, `rod.beam.elements`), with the checks of `cosserat run --set`;
    /// an invalid value raises SceneError and leaves the scene as it was.
    fn set(&mut self, key: &str, value: f64) -> PyResult<()> {
        let mut sets = self.sets.clone();
        sets.push((key.to_string(), value));
        *self = Self::parse(self.text.clone(), self.source.clone(), sets)?;
        Ok(())
    }

    /// A copy of the scene (the values set so far included).
    fn copy(&self) -> Self {
        self.clone()
    }

    /// The human summary `cosserat check` prints (the scene is valid, or it would not exist).
    fn check(&self) -> String {
        self.scene.describe()
    }

    /// The TOML text as given (values set with `set` are not written into it).
    #[getter]
    fn text(&self) -> &str {
        &self.text
    }

    /// Scene name.
    #[getter]
    fn name(&self) -> &str {
        &self.scene.name
    }

    /// Where the scene came from: the path as given, `builtin:NAME` or `<string>`.
    #[getter]
    fn source(&self) -> &str {
        &self.source
    }

    /// The values set with `set`, in order, as (key, value).
    #[getter]
    fn sets(&self) -> Vec<(String, f64)> {
        self.sets.clone()
    }

    /// Time step Δt.
    #[getter]
    fn dt(&self) -> f64 {
        self.scene.params.dt
    }

    /// End time.
    #[getter]
    fn t_end(&self) -> f64 {
        self.scene.params.t_end
    }

    /// The scheme's name (`em`, `edmc1`, `edmc2`, `midpoint`, `gen-alpha`).
    #[getter]
    fn scheme(&self) -> &'static str {
        self.scene.params.scheme.name()
    }

    /// Number of nodes.
    #[getter]
    fn nodes(&self) -> usize {
        self.scene.model.n_nodes()
    }

    /// Number of elements.
    #[getter]
    fn elements(&self) -> usize {
        self.scene.model.elements.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?} from {}, {} nodes, {} elements, {} Δt = {}, t_end = {}{})",
            self.scene.name,
            self.source,
            self.scene.model.n_nodes(),
            self.scene.model.elements.len(),
            self.scene.params.scheme.name(),
            self.scene.params.dt,
            self.scene.params.t_end,
            if self.sets.is_empty() {
                String::new()
            } else {
                format!(", sets {:?}", self.sets)
            }
        )
    }
}

/// The scheme a run uses, as `cosserat run --scheme/--alpha/--rho-inf/--dt/--t-end` resolve
/// it: a named scheme replaces the scene's (keeping its constants when it is the same
/// scheme, zero otherwise); `alpha` sets EDMC-2's α_Γv and implies `edmc2`; `rho_inf`
/// sets generalized-α's ρ∞ and implies `gen-alpha`.
fn resolve_params(
    scene: &cosserat::scene::Scene,
    scheme: Option<&str>,
    alpha: Option<f64>,
    rho_inf: Option<f64>,
    dt: Option<f64>,
    t_end: Option<f64>,
) -> PyResult<IntegratorParams> {
    let bad = |m: String| PyValueError::new_err(m);
    let mut p = scene.params;
    if alpha.is_some() && rho_inf.is_some() {
        return Err(bad(
            "alpha and rho_inf set parameters of two different schemes".into(),
        ));
    }
    let wanted = match scheme {
        Some(s) => Some(s.to_ascii_lowercase()),
        None => match (alpha, rho_inf, p.scheme) {
            (Some(_), _, Scheme::Edmc2 { .. }) | (_, Some(_), Scheme::GenAlpha { .. }) => None,
            (Some(_), _, _) => Some("edmc2".into()),
            (_, Some(_), _) => Some("gen-alpha".into()),
            _ => None,
        },
    };
    if let Some(s) = wanted {
        p.scheme = match (s.as_str(), p.scheme) {
            ("em", _) => Scheme::Em,
            ("midpoint", _) => Scheme::Midpoint,
            ("gen-alpha" | "gen_alpha", s @ Scheme::GenAlpha { .. }) => s,
            ("gen-alpha" | "gen_alpha", _) => Scheme::GenAlpha {
                rho_inf: cosserat::integrator::gen_alpha::DEFAULT_RHO_INF,
            },
            ("edmc1", s @ Scheme::Edmc1 { .. }) => s,
            ("edmc1", _) => Scheme::Edmc1 {
                chi_gamma: 0.0,
                chi_omega: 0.0,
                chi_v: 0.0,
                chi_nu: 0.0,
            },
            ("edmc2", s @ Scheme::Edmc2 { .. }) => s,
            ("edmc2", _) => Scheme::edmc2(0.0),
            (other, _) => {
                return Err(bad(format!(
                    "scheme: unknown scheme `{other}` (expected em, edmc1, edmc2, midpoint or gen-alpha)"
                )))
            }
        };
    }
    if let Some(a) = alpha {
        if !(a.is_finite() && a >= 0.0) {
            return Err(bad(format!("alpha: must be a finite number ≥ 0 (got {a})")));
        }
        match &mut p.scheme {
            Scheme::Edmc2 { alpha_gv, .. } => *alpha_gv = a,
            other => {
                return Err(bad(format!(
                    "alpha sets the EDMC-2 parameter α_Γv, but the scheme is {}",
                    other.name()
                )))
            }
        }
    }
    if let Some(r) = rho_inf {
        if !(0.0..=1.0).contains(&r) {
            return Err(bad(format!("rho_inf: must be in [0, 1] (got {r})")));
        }
        match &mut p.scheme {
            Scheme::GenAlpha { rho_inf } => *rho_inf = r,
            other => {
                return Err(bad(format!(
                    "rho_inf sets the generalized-α parameter ρ∞, but the scheme is {}",
                    other.name()
                )))
            }
        }
    }
    if let Some(dt) = dt {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(bad(format!("dt: must be a finite number > 0 (got {dt})")));
        }
        p.dt = dt;
    }
    if let Some(t) = t_end {
        if !(t.is_finite() && t > 0.0) {
            return Err(bad(format!("t_end: must be a finite number > 0 (got {t})")));
        }
        p.t_end = t;
    }
    if matches!(p.scheme, Scheme::GenAlpha { .. }) && !scene.model.links.is_empty() {
        return Err(bad(format!(
            "{}: gen-alpha does not support rigid links ([[link]]); use em, edmc1, edmc2 or midpoint",
            scene.source
        )));
    }
    Ok(p)
}

fn backend_choice(backend: &str) -> PyResult<BackendChoice> {
    match backend {
        "cpu" => Ok(BackendChoice::Cpu),
        "gpu" => Ok(BackendChoice::Gpu),
        "auto" => Ok(BackendChoice::Auto),
        other => Err(PyValueError::new_err(format!(
            "backend: unknown backend `{other}` (expected cpu, gpu or auto)"
        ))),
    }
}

/// The node `at` names: an index, or a reference position (a node of the mesh within the
/// scene's merge tolerance, 1e-9 × the model size, as a scene's `at`).
fn node_of(model: &cosserat::model::Model, at: &Bound<'_, PyAny>, key: &str) -> PyResult<usize> {
    let n = model.n_nodes();
    if let Ok(i) = at.extract::<i64>() {
        return usize::try_from(i).ok().filter(|&i| i < n).ok_or_else(|| {
            PyValueError::new_err(format!("{key}: node {i}: no such node (the model has {n})"))
        });
    }
    let p: [f64; 3] = at.extract().map_err(|_| {
        PyValueError::new_err(format!(
            "{key}: expected a node index or a position [x, y, z], got {}",
            at.repr()
                .map_or_else(|_| "?".to_string(), |r| r.to_string())
        ))
    })?;
    let p = cosserat::model::Vec3::from(p);
    let (lo, hi) = model.nodes.iter().fold(
        (
            cosserat::model::Vec3::repeat(f64::INFINITY),
            cosserat::model::Vec3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), x| (lo.inf(x), hi.sup(x)),
    );
    let tol = 1e-9 * (hi - lo).norm();
    let nearest = model
        .nodes
        .iter()
        .enumerate()
        .map(|(a, x)| (a, (x - p).norm()))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match nearest {
        Some((a, d)) if d <= tol => Ok(a),
        Some((a, d)) => Err(PyValueError::new_err(format!(
            "{key}: {:?} is not a node (nearest node {a} at {:?}, distance {d:e})",
            p.as_slice(),
            model.nodes[a].as_slice()
        ))),
        None => Err(PyValueError::new_err(format!(
            "{key}: the model has no nodes"
        ))),
    }
}

fn vec3_of(v: Option<[f64; 3]>) -> Option<cosserat::model::Vec3> {
    v.map(cosserat::model::Vec3::from)
}

/// A rotation given as a rotation vector (axis × angle, less than a half turn) or a
/// rotation matrix.
fn rotation_of(r: &Bound<'_, PyAny>) -> PyResult<cosserat::model::Mat3> {
    if let Ok(v) = r.extract::<[f64; 3]>() {
        let phi = cosserat::model::Vec3::from(v);
        let a = phi.norm();
        if a.is_nan() || a >= std::f64::consts::PI {
            return Err(PyValueError::new_err(format!(
                "rotation: a rotation vector shorter than π (a half turn) is expected, got |φ| = {a}"
            )));
        }
        let theta = if a > 0.0 {
            phi * (2.0 * (0.5 * a).tan() / a)
        } else {
            phi
        };
        return Ok(cosserat::math::cay(&theta));
    }
    let m: [[f64; 3]; 3] = r.extract().map_err(|_| {
        PyValueError::new_err(
            "rotation: expected a rotation vector [3] or a rotation matrix [3, 3]",
        )
    })?;
    Ok(cosserat::model::Mat3::from_fn(|i, j| m[i][j]))
}

fn vec_array<'py>(py: Python<'py>, v: &cosserat::model::Vec3) -> Bound<'py, numpy::PyArray1<f64>> {
    Array1::from_vec(v.as_slice().to_vec()).into_pyarray(py)
}

fn mat_array<'py>(py: Python<'py>, m: &cosserat::model::Mat3) -> Bound<'py, numpy::PyArray2<f64>> {
    Array2::from_shape_fn((3, 3), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// How the last `run` ended, or `"ready"` before any.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Status {
    Ready,
    Completed,
    Stopped,
    Interrupted,
    Failed,
}

impl Status {
    fn name(self) -> &'static str {
        match self {
            Status::Ready => "ready",
            Status::Completed => "completed",
            Status::Stopped => "stopped",
            Status::Interrupted => "interrupted",
            Status::Failed => "failed",
        }
    }
}

fn record_dict<'py>(py: Python<'py>, r: &StepRecord) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in HISTORY_COLUMNS.iter().zip(history_values(r)) {
        match *k {
            "step" | "newton_iters" | "outer_iters" | "substeps" => d.set_item(k, v as u64)?,
            "fallback" => d.set_item(k, v != 0.0)?,
            _ => d.set_item(k, v)?,
        }
    }
    Ok(d)
}

/// One simulation of a scene, stepped from Python.
#[pyclass(module = "cosserat", subclass)]
struct Simulation {
    sim: cosserat::integrator::Simulation,
    /// Keeps the GPU batch alive while the simulation uses it.
    _gpu: Option<Arc<GpuBatcher>>,
    scene_source: String,
    scene_name: String,
    node_end: Vec<(usize, usize)>,
    /// Step index, time grid and running totals, kept as `cosserat run` keeps them.
    log: RunLog,
    records: Vec<StepRecord>,
    /// Whether each kept record also keeps the state (`Simulation(trajectory=True)`).
    trajectory: bool,
    /// Per kept record: positions, velocities and node directors, flattened.
    frames: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)>,
    /// The record of the current level when `records` (thinned) does not end with it.
    last: StepRecord,
    status: Status,
    reason: Option<String>,
    failed_step_residuals: Vec<f64>,
    newton_iters_total: usize,
    energy_initial: f64,
    wall_s: f64,
}

impl Simulation {
    /// One step, recorded like `cosserat::integrator::run::run` records it (`t = t_0 +
    /// step·Δt`, running totals of work and dissipation). `Err(reason)` on a failed step,
    /// the state left at the last accepted level.
    fn advance(&mut self) -> Result<(), String> {
        if self.status == Status::Failed {
            return Err(self
                .reason
                .clone()
                .unwrap_or_else(|| "the simulation failed".into()));
        }
        match self.sim.step() {
            Ok(rep) => {
                self.log.accept(&rep);
                self.newton_iters_total += rep.newton_iters;
                self.last = self.log.record(&self.sim, Some(&rep));
                Ok(())
            }
            Err(f) => {
                let reason = self.log.failure(&f.reason);
                self.status = Status::Failed;
                self.reason = Some(reason.clone());
                self.failed_step_residuals = f.residuals;
                Err(reason)
            }
        }
    }

    fn keep_last(&mut self) {
        if self.records.last().map(|r| r.step) != Some(self.last.step) {
            self.keep();
        }
    }

    /// Appends the current level to the history (and its state to the trajectory).
    fn keep(&mut self) {
        self.records.push(self.last.clone());
        if self.trajectory {
            let frame = self.frame();
            self.frames.push(frame);
        }
    }

    /// The current state: positions, velocities, node directors (flattened, row-major).
    fn frame(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let s = self.sim.state();
        let r = s.r.iter().flat_map(|x| [x.x, x.y, x.z]).collect();
        let v = s.v.iter().flat_map(|x| [x.x, x.y, x.z]).collect();
        let mut d = Vec::with_capacity(self.node_end.len() * 9);
        for &(e, l) in &self.node_end {
            if e == usize::MAX {
                d.extend([f64::NAN; 9]);
            } else {
                for k in 0..3 {
                    d.extend(s.d[e][l].column(k).iter());
                }
            }
        }
        (r, v, d)
    }

    fn n_nodes(&self) -> usize {
        self.sim.model().n_nodes()
    }
}

#[pymethods]
impl Simulation {
    /// A simulation of `scene` at its initial state. `scheme`, `alpha`, `rho_inf`, `dt` and
    /// `t_end` override the scene's integrator settings as `cosserat run` does; `backend`
    /// is where the element kernel runs (`cpu`, `gpu`, `auto`), `adapter` picks a GPU by
    /// name. `trajectory=True` keeps the state of every recorded step (`_trajectory`).
    /// `controlled` lists the fixed clamps and pins (node indices or reference positions)
    /// a controller moves with `set_support` (the scene's moving supports can be moved
    /// without it).
    #[new]
    #[pyo3(signature = (scene, scheme = None, alpha = None, rho_inf = None, dt = None, t_end = None, backend = "cpu", adapter = None, trajectory = false, controlled = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        scene: &Scene,
        scheme: Option<&str>,
        alpha: Option<f64>,
        rho_inf: Option<f64>,
        dt: Option<f64>,
        t_end: Option<f64>,
        backend: &str,
        adapter: Option<&str>,
        trajectory: bool,
        controlled: Option<Vec<Bound<'_, PyAny>>>,
    ) -> PyResult<Self> {
        let s = &scene.scene;
        let params = resolve_params(s, scheme, alpha, rho_inf, dt, t_end)?;
        let choice = backend_choice(backend)?;
        let mut model = s.model.clone();
        for at in controlled.iter().flatten() {
            let node = node_of(&model, at, "controlled")?;
            if matches!(params.scheme, Scheme::GenAlpha { .. }) {
                return Err(PyValueError::new_err(
                    "controlled: gen-alpha does not support moving supports; use em, edmc1, edmc2 or midpoint",
                ));
            }
            model
                .control_support(node)
                .map_err(|e| PyValueError::new_err(format!("controlled: {e}")))?;
        }
        let mut sim = cosserat::integrator::Simulation::new(model, params).map_err(|e| {
            PyValueError::new_err(format!(
                "{}: (model): cannot set up the linear solver for this scene: {e}",
                s.source
            ))
        })?;
        let mut gpu = None;
        if choice != BackendChoice::Cpu {
            let (exec, _note) = Executor::resolve(choice, adapter)
                .map_err(|e| PyRuntimeError::new_err(format!("backend: {e}")))?;
            if let Executor::Gpu(ctx) = exec {
                if sim.params().scheme.has_gpu_kernel() {
                    let b = Arc::new(
                        GpuBatcher::new(&ctx, 1, sim.model().elements.len(), sim.model().n_nodes())
                            .map_err(|e| PyRuntimeError::new_err(format!("backend: {e}")))?,
                    );
                    let _ = sim.set_backend(b.clone(), 0);
                    b.register(0, &sim)
                        .map_err(|e| PyRuntimeError::new_err(format!("backend: {e}")))?;
                    gpu = Some(b);
                }
            }
        }
        let log = RunLog::new(&sim);
        let rec0 = log.record(&sim, None);
        let (node_end, _) = cosserat::observe::probe::node_director_ends(sim.model());
        let mut this = Self {
            log,
            energy_initial: rec0.total,
            sim,
            _gpu: gpu,
            scene_source: s.source.clone(),
            scene_name: s.name.clone(),
            node_end,
            records: vec![],
            trajectory,
            frames: vec![],
            last: rec0,
            status: Status::Ready,
            reason: None,
            failed_step_residuals: vec![],
            newton_iters_total: 0,
            wall_s: 0.0,
        };
        this.keep();
        Ok(this)
    }

    /// Takes one time step. Returns True when it was accepted; False when Newton failed
    /// (then `status` is `"failed"`, `reason` says why, and the state stays at the last
    /// accepted level). Every step is appended to `history`.
    fn step(&mut self, py: Python<'_>) -> bool {
        let ok = py.allow_threads(|| self.advance().is_ok());
        if ok {
            self.keep();
        }
        ok
    }

    /// Steps until `t_end` (default: the end time of the scene or of `Simulation(t_end=)`,
    /// counted from the initial time, as `cosserat run` counts its steps) or the first
    /// failed step. Keeps every `every`-th step in `history` (and the last accepted one);
    /// `callback(record)` is called with each kept record (a dict of the history columns)
    /// and stops the run when it returns False. The GIL is released between callbacks.
    /// Ctrl-C raises KeyboardInterrupt with the state at the last accepted step. Returns
    /// the summary dict.
    #[pyo3(signature = (t_end = None, every = 1, callback = None, progress = false))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        t_end: Option<f64>,
        every: usize,
        callback: Option<PyObject>,
        progress: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        if every == 0 {
            return Err(PyValueError::new_err("every: must be ≥ 1"));
        }
        let t_end = t_end.unwrap_or(self.sim.params().t_end);
        if !t_end.is_finite() {
            return Err(PyValueError::new_err(format!(
                "t_end: must be finite (got {t_end})"
            )));
        }
        let dt = self.sim.params().dt;
        let target = (((t_end - self.log.time(0)) / dt) - 1e-9).ceil().max(0.0) as usize;
        if target > cosserat::scene::limits::MAX_STEPS as usize {
            return Err(PyValueError::new_err(format!(
                "t_end: {target} steps, above the limit of {:e} steps per run",
                cosserat::scene::limits::MAX_STEPS
            )));
        }
        let start = Instant::now();
        let bar = progress.then(|| {
            cosserat::output::Progress::with_lines(
                target.saturating_sub(self.log.step()) as u64,
                &self.scene_name,
            )
        });
        // Ok(true): stopped by the callback.
        let outcome: PyResult<bool> = py.allow_threads(|| {
            let mut last_check = Instant::now();
            while self.log.step() < target {
                if self.advance().is_err() {
                    break;
                }
                if let Some(b) = &bar {
                    b.step(self.last.t, self.last.newton_iters);
                }
                let kept = self.log.step().is_multiple_of(every) || self.log.step() == target;
                if kept {
                    self.keep();
                    if let Some(cb) = &callback {
                        let go = Python::with_gil(|py| -> PyResult<bool> {
                            let r = cb.call1(py, (record_dict(py, &self.last)?,))?;
                            // Only `False` itself stops (None, the usual return, goes on).
                            Ok(!r.bind(py).downcast::<PyBool>().is_ok_and(|b| !b.is_true()))
                        })?;
                        if !go {
                            return Ok(true);
                        }
                    }
                }
                if last_check.elapsed() >= SIGNAL_CHECK {
                    last_check = Instant::now();
                    Python::with_gil(|py| py.check_signals())?;
                }
            }
            Ok(false)
        });
        if let Some(b) = &bar {
            b.finish();
        }
        self.wall_s += start.elapsed().as_secs_f64();
        self.keep_last();
        match outcome {
            Ok(stopped) => {
                if self.status != Status::Failed {
                    self.status = if stopped {
                        Status::Stopped
                    } else {
                        Status::Completed
                    };
                }
                self.summary(py)
            }
            Err(e) => {
                if e.is_instance_of::<PyKeyboardInterrupt>(py) {
                    self.status = Status::Interrupted;
                }
                Err(e)
            }
        }
    }

    /// `"ready"` (no run yet), `"completed"`, `"stopped"` (by the callback),
    /// `"interrupted"` (Ctrl-C) or `"failed"` (a step could not be accepted).
    #[getter]
    fn status(&self) -> &'static str {
        self.status.name()
    }

    /// Why the simulation failed (None unless `status == "failed"`).
    #[getter]
    fn reason(&self) -> Option<String> {
        self.reason.clone()
    }

    /// Time of the current (last accepted) level.
    #[getter]
    fn t(&self) -> f64 {
        self.last.t
    }

    /// Accepted steps so far.
    #[getter]
    fn steps(&self) -> usize {
        self.log.step()
    }

    /// Time step Δt.
    #[getter]
    fn dt(&self) -> f64 {
        self.sim.params().dt
    }

    /// Node positions, float64 [nodes, 3] (a copy).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<f64>> {
        let r = &self.sim.state().r;
        let flat: Vec<f64> = r.iter().flat_map(|x| [x.x, x.y, x.z]).collect();
        Array2::from_shape_vec((r.len(), 3), flat)
            .expect("[nodes, 3]")
            .into_pyarray(py)
    }

    /// Node velocities, float64 [nodes, 3] (a copy). Assigning an array [nodes, 3] sets
    /// them (an initial velocity field; supported nodes must stay at rest).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<f64>> {
        let v = &self.sim.state().v;
        let flat: Vec<f64> = v.iter().flat_map(|x| [x.x, x.y, x.z]).collect();
        Array2::from_shape_vec((v.len(), 3), flat)
            .expect("[nodes, 3]")
            .into_pyarray(py)
    }

    #[setter]
    fn set_velocities(&mut self, v: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        let n = self.n_nodes();
        let a = v.as_array();
        if a.shape() != [n, 3] {
            return Err(PyValueError::new_err(format!(
                "velocities: expected an array of shape ({n}, 3), got {:?}",
                a.shape()
            )));
        }
        if matches!(self.sim.params().scheme, Scheme::GenAlpha { .. }) {
            return Err(PyValueError::new_err(
                "velocities: gen-alpha keeps its own nodal state; set initial velocities in the scene",
            ));
        }
        let model = self.sim.model();
        let mut state = self.sim.state().clone();
        for i in 0..n {
            let x = cosserat::model::Vec3::new(a[[i, 0]], a[[i, 1]], a[[i, 2]]);
            if !x.iter().all(|c| c.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "velocities: node {i}: not finite ({x:?})"
                )));
            }
            if model.supports[i].translation && x != cosserat::model::Vec3::zeros() {
                return Err(PyValueError::new_err(format!(
                    "velocities: node {i} is supported (its translation is fixed); its velocity must be 0"
                )));
            }
            state.v[i] = x;
        }
        self.sim.set_state(state);
        // The current level's record now has the new energies.
        let rec = self.log.record(&self.sim, None);
        self.energy_initial = if self.log.step() == 0 {
            rec.total
        } else {
            self.energy_initial
        };
        self.last = rec;
        if self.records.last().map(|r| r.step) == Some(self.log.step()) {
            self.records.pop();
            if self.trajectory {
                self.frames.pop();
            }
        }
        self.keep();
        Ok(())
    }

    /// Node director triads, float64 [nodes, 3, 3]: `directors[a, k]` is the vector
    /// `d_{k+1}` at node `a` (the triad of the lowest-numbered element touching it; NaN
    /// for a node outside every element), as in `trajectory.npz`.
    #[getter]
    fn directors<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray3<f64>> {
        let s = self.sim.state();
        let mut flat = Vec::with_capacity(self.node_end.len() * 9);
        for &(e, l) in &self.node_end {
            if e == usize::MAX {
                flat.extend([f64::NAN; 9]);
            } else {
                let d = &s.d[e][l];
                for k in 0..3 {
                    flat.extend(d.column(k).iter());
                }
            }
        }
        Array3::from_shape_vec((self.node_end.len(), 3, 3), flat)
            .expect("[nodes, 3, 3]")
            .into_pyarray(py)
    }

    /// The nodal loads (`[[load]]` in scene order, then those added with `add_load`),
    /// each a dict `{"index", "node", "force", "moment"}` with the values at the current
    /// level (float64 [3] arrays).
    #[getter]
    fn loads<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let t = self.sim.state().t;
        let out = PyList::empty(py);
        for (i, l) in self.sim.model().loads.iter().enumerate() {
            let s = l.table.eval(t);
            let d = PyDict::new(py);
            d.set_item("index", i)?;
            d.set_item("node", l.node)?;
            d.set_item("force", vec_array(py, &(l.force * s)))?;
            d.set_item("moment", vec_array(py, &(l.moment * s)))?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Sets load `index` (see `loads`) to a constant force and/or moment from the current
    /// level on: the next steps apply it (at mid-step, like every load) until it is set
    /// again; a part not given keeps its current value. Its work is in `work_total`.
    #[pyo3(signature = (index, force = None, moment = None))]
    fn set_load(
        &mut self,
        index: usize,
        force: Option<[f64; 3]>,
        moment: Option<[f64; 3]>,
    ) -> PyResult<()> {
        self.sim
            .set_load(index, vec3_of(force), vec3_of(moment))
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Adds a constant nodal force and/or moment at `at` (a node index or a node's
    /// reference position) from the current level on; returns its index in `loads`.
    #[pyo3(signature = (at, force = None, moment = None))]
    fn add_load(
        &mut self,
        at: &Bound<'_, PyAny>,
        force: Option<[f64; 3]>,
        moment: Option<[f64; 3]>,
    ) -> PyResult<usize> {
        let node = node_of(self.sim.model(), at, "at")?;
        let z = cosserat::model::Vec3::zeros();
        self.sim
            .add_load(
                node,
                vec3_of(force).unwrap_or(z),
                vec3_of(moment).unwrap_or(z),
            )
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The supported nodes, each a dict `{"node", "kind"` (`clamp` or `pin`), `"position"`
    /// [3], `"rotation"` [3, 3] (the node's rotation: its directors are this times the
    /// reference triads), `"driven"` (a moving support of the scene or one named in
    /// `controlled=`: `set_support` can move it)`}`.
    #[getter]
    fn supports<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let m = self.sim.model();
        let out = PyList::empty(py);
        for (a, s) in m.supports.iter().enumerate() {
            if !(s.translation || s.rotation) {
                continue;
            }
            let d = PyDict::new(py);
            d.set_item("node", a)?;
            d.set_item("kind", if s.rotation { "clamp" } else { "pin" })?;
            d.set_item("position", vec_array(py, &self.sim.state().r[a]))?;
            d.set_item("rotation", mat_array(py, &self.sim.node_rotation(a)))?;
            d.set_item("driven", m.drives.iter().any(|dr| dr.node == a))?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Moves the driven support at `at` (a node index or a node's reference position;
    /// see `supports`) from the current level on: `position` [3] and/or `rotation` (a
    /// rotation vector [3] or matrix [3, 3]) are reached at the next level and then held;
    /// `velocity` [3] (m/s) and/or `angular_velocity` [3] (rad/s, spatial) hold until
    /// commanded again. A part not given keeps its current command (at first, the
    /// scene's motion). The support's work is in `work_total` (`support_work` per step).
    #[pyo3(signature = (at, position = None, rotation = None, velocity = None, angular_velocity = None))]
    fn set_support(
        &mut self,
        at: &Bound<'_, PyAny>,
        position: Option<[f64; 3]>,
        rotation: Option<Bound<'_, PyAny>>,
        velocity: Option<[f64; 3]>,
        angular_velocity: Option<[f64; 3]>,
    ) -> PyResult<()> {
        use cosserat::integrator::{RotationCommand, TranslationCommand};
        let node = node_of(self.sim.model(), at, "at")?;
        if position.is_some() && velocity.is_some() {
            return Err(PyValueError::new_err(
                "set_support: give a position or a velocity, not both",
            ));
        }
        if rotation.is_some() && angular_velocity.is_some() {
            return Err(PyValueError::new_err(
                "set_support: give a rotation or an angular velocity, not both",
            ));
        }
        let translation = match (vec3_of(position), vec3_of(velocity)) {
            (Some(p), _) => Some(TranslationCommand::Position(p)),
            (_, Some(v)) => Some(TranslationCommand::Velocity(v)),
            _ => None,
        };
        let rot = match (rotation, vec3_of(angular_velocity)) {
            (Some(r), _) => Some(RotationCommand::Rotation(rotation_of(&r)?)),
            (_, Some(w)) => Some(RotationCommand::AngularVelocity(w)),
            _ => None,
        };
        self.sim
            .set_support_motion(node, translation, rot)
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Kinetic, potential and total energy of the current level, as a dict.
    #[getter]
    fn energy<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("kinetic", self.last.kinetic)?;
        d.set_item("potential", self.last.potential)?;
        d.set_item("total", self.last.total)?;
        Ok(d)
    }

    /// The recorded steps as a dict of float64 arrays (int64 for counts), one per column
    /// of `history.csv`.
    fn _history<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let rows: Vec<[f64; 25]> = self.records.iter().map(history_values).collect();
        for (c, k) in HISTORY_COLUMNS.iter().enumerate() {
            let col: Vec<f64> = rows.iter().map(|r| r[c]).collect();
            match *k {
                "step" | "newton_iters" | "outer_iters" | "substeps" | "fallback" => {
                    let ints: Vec<i64> = col.iter().map(|&x| x as i64).collect();
                    d.set_item(k, Array1::from_vec(ints).into_pyarray(py))?
                }
                _ => d.set_item(k, Array1::from_vec(col).into_pyarray(py))?,
            }
        }
        Ok(d)
    }

    /// The states kept with the history (`Simulation(trajectory=True)`): `times` [T],
    /// `steps` [T] (int64), `positions` and `velocities` [T, nodes, 3], `directors`
    /// [T, nodes, 3, 3], as in `trajectory.npz`.
    fn _trajectory<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        if !self.trajectory {
            return Err(PyValueError::new_err(
                "trajectory: not recorded; create the simulation with Simulation(..., trajectory=True)",
            ));
        }
        let (t, n) = (self.frames.len(), self.node_end.len());
        let cat = |k: usize| -> Vec<f64> {
            self.frames
                .iter()
                .flat_map(|f| [&f.0, &f.1, &f.2][k].iter().copied())
                .collect()
        };
        let shape_err = |e: numpy::ndarray::ShapeError| PyRuntimeError::new_err(e.to_string());
        let d = PyDict::new(py);
        let times: Vec<f64> = self.records.iter().map(|r| r.t).collect();
        let steps: Vec<i64> = self.records.iter().map(|r| r.step as i64).collect();
        d.set_item("times", Array1::from_vec(times).into_pyarray(py))?;
        d.set_item("steps", Array1::from_vec(steps).into_pyarray(py))?;
        d.set_item(
            "positions",
            Array3::from_shape_vec((t, n, 3), cat(0))
                .map_err(shape_err)?
                .into_pyarray(py),
        )?;
        d.set_item(
            "velocities",
            Array3::from_shape_vec((t, n, 3), cat(1))
                .map_err(shape_err)?
                .into_pyarray(py),
        )?;
        d.set_item(
            "directors",
            numpy::ndarray::Array4::from_shape_vec((t, n, 3, 3), cat(2))
                .map_err(shape_err)?
                .into_pyarray(py),
        )?;
        Ok(d)
    }

    /// What the simulation did so far, with the keys of `summary.json` it can fill.
    #[getter]
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let p = self.sim.params();
        d.set_item("scene", &self.scene_source)?;
        d.set_item("name", &self.scene_name)?;
        d.set_item("status", self.status.name())?;
        d.set_item("reason", self.reason.clone())?;
        d.set_item(
            "failed_step_residuals",
            PyList::new(py, &self.failed_step_residuals)?,
        )?;
        d.set_item("t_reached", self.last.t)?;
        d.set_item("steps", self.log.step())?;
        d.set_item("scheme", p.scheme.name())?;
        d.set_item("dt", p.dt)?;
        d.set_item("t_end", p.t_end)?;
        d.set_item("nodes", self.sim.model().n_nodes())?;
        d.set_item("elements", self.sim.model().elements.len())?;
        d.set_item("dofs", self.sim.n_dofs())?;
        d.set_item("newton_iters_total", self.newton_iters_total)?;
        d.set_item("energy_initial", self.energy_initial)?;
        d.set_item("energy_final", self.last.total)?;
        d.set_item("work_total", self.last.work_total)?;
        d.set_item("dissipation_total", self.last.dissipation_total)?;
        d.set_item("wall_s", self.wall_s)?;
        d.set_item("backend", self.sim.backend_name())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "Simulation({} {} Δt = {}, t = {}, {} steps, {})",
            self.scene_name,
            self.sim.params().scheme.name(),
            self.sim.params().dt,
            self.last.t,
            self.log.step(),
            self.status.name()
        )
    }
}

/// Runs the sweep file `sweep` into the folder `out` as `cosserat sweep` does (same files,
/// resume and streaming guarantees); the GIL is released while it runs. Ctrl-C stops it
/// cleanly: no further member starts, the members under way finish and are recorded, then
/// KeyboardInterrupt is raised (`resume=True` runs the rest). `progress=True` shows a bar
/// on stderr (plain lines when stderr is not a terminal). Returns the summary as a dict;
/// the members are in `out/members.csv`.
#[pyfunction]
#[pyo3(signature = (sweep, out, backend = "auto", adapter = None, resume = false, histories = false, progress = false))]
#[allow(clippy::too_many_arguments)]
fn _run_sweep<'py>(
    py: Python<'py>,
    sweep: PathBuf,
    out: PathBuf,
    backend: &str,
    adapter: Option<&str>,
    resume: bool,
    histories: bool,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let choice = backend_choice(backend)?;
    let spec = cosserat::sweep::load_sweep(&sweep).map_err(|e| {
        let err = SceneError::new_err(e.to_string());
        let v = err.value(py);
        let _ = v.setattr("file", sweep.display().to_string());
        let _ = v.setattr("key", py.None());
        let _ = v.setattr("line", py.None());
        let _ = v.setattr("column", py.None());
        let _ = v.setattr("reason", e.to_string());
        err
    })?;
    let (exec, note) = Executor::resolve(choice, adapter)
        .map_err(|e| PyRuntimeError::new_err(format!("backend: {e}")))?;
    let opts = cosserat::sweep::SweepOptions {
        resume,
        histories,
        ..Default::default()
    };
    let described = exec.describe();
    let stop = AtomicBool::new(false);
    let bar = progress.then(|| cosserat::output::Progress::with_lines(spec.len() as u64, "sweep"));
    let (result, interrupt) = py.allow_threads(|| {
        std::thread::scope(|s| {
            let worker = s.spawn(|| {
                let (mut done, mut failed, mut rejected) = (0, 0, 0);
                cosserat::sweep::run_sweep_until(&spec, &exec, &out, &opts, Some(&stop), |row| {
                    match row.status {
                        cosserat::sweep::MemberStatus::Completed => done += 1,
                        cosserat::sweep::MemberStatus::Failed => failed += 1,
                        cosserat::sweep::MemberStatus::Rejected => rejected += 1,
                    }
                    if let Some(b) = &bar {
                        b.advance(&format!(
                            "completed {done}, failed {failed}, rejected {rejected}"
                        ));
                    }
                })
            });
            let mut interrupt: Option<PyErr> = None;
            while !worker.is_finished() {
                std::thread::sleep(SIGNAL_CHECK);
                if interrupt.is_none() {
                    if let Err(e) = Python::with_gil(|py| py.check_signals()) {
                        stop.store(true, Ordering::SeqCst);
                        interrupt = Some(e);
                    }
                }
            }
            let result = worker
                .join()
                .unwrap_or_else(|p| std::panic::resume_unwind(p));
            (result, interrupt)
        })
    });
    if let Some(b) = &bar {
        b.finish();
    }
    let summary = result.map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    if let Some(e) = interrupt {
        return Err(e);
    }
    let d = PyDict::new(py);
    d.set_item("members", summary.members)?;
    d.set_item("skipped", summary.skipped)?;
    d.set_item("completed", summary.completed)?;
    d.set_item("failed", summary.failed)?;
    d.set_item("rejected", summary.rejected)?;
    d.set_item("wall_s", summary.wall_s)?;
    d.set_item("stopped", summary.stopped)?;
    d.set_item("backend", described)?;
    d.set_item("note", note)?;
    Ok(d)
}

/// Runs `scene` into the folder `out` as `cosserat run SCENE --out OUT` does (the scene's
/// own integrator settings; `history.csv`, `summary.json`, the charts), in process, the
/// GIL released. `output_dt` keeps `trajectory.npz` frames at that spacing (`--output-dt`);
/// `cosseratbench=True` also writes the suite's layout into `out/cosseratbench/`
/// (`--cosseratbench`, with `scenario_digest` and `experiment` in its `result.json`).
/// Returns `summary.json`'s object as a JSON string.
#[pyfunction]
#[pyo3(signature = (scene, out, output_dt = None, cosseratbench = false, scenario_digest = None, experiment = None))]
fn _run_to_dir(
    py: Python<'_>,
    scene: &Scene,
    out: PathBuf,
    output_dt: Option<f64>,
    cosseratbench: bool,
    scenario_digest: Option<String>,
    experiment: Option<String>,
) -> PyResult<String> {
    use cosserat::output::{CosseratBenchOptions, OutputTimes};
    let s = &scene.scene;
    let params = s.params;
    let every = s.output_every.max(1);
    let trajectory = match output_dt {
        Some(dt) => Some(
            OutputTimes::from_dt(dt, params.dt)
                .map_err(|e| PyValueError::new_err(format!("output_dt: {e}")))?,
        ),
        None => cosseratbench.then_some(OutputTimes::Every(every)),
    };
    let opts = cosserat::driver::RunOptions {
        every,
        label: s.name.clone(),
        trajectory,
        cosseratbench: cosseratbench.then(|| CosseratBenchOptions {
            scenario_digest,
            experiment,
            ..Default::default()
        }),
        ..Default::default()
    };
    let result = py
        .allow_threads(|| cosserat::driver::run_to_dir(s, params, &out, &opts))
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    serde_json::to_string(&result.summary).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// Times the benchmark batch of `cosserat bench` (the benchmark cantilever as `rods` members of `elements` elements over `steps` steps, EDMC-2) on the CPU path
/// and, where a GPU exists, the GPU path; the GIL is released while it runs. Returns the
/// object `cosserat bench --json` prints, as a JSON string.
#[pyfunction]
#[pyo3(signature = (rods = 64, elements = 30, steps = 20, adapter = None, cpu_only = false, gpu_only = false, newton = "full", strategy = "auto", slots = 0, solve = "host", host_update = false))]
#[allow(clippy::too_many_arguments)]
fn _bench(
    py: Python<'_>,
    rods: i64,
    elements: i64,
    steps: i64,
    adapter: Option<String>,
    cpu_only: bool,
    gpu_only: bool,
    newton: &str,
    strategy: &str,
    slots: i64,
    solve: &str,
    host_update: bool,
) -> PyResult<String> {
    use cosserat::bench::{BenchError, BenchOptions, BenchSolve};
    use cosserat::integrator::{NewtonVariant, Strategy};
    let count = |key: &str, v: i64, min: i64| -> PyResult<usize> {
        if v < min {
            return Err(PyValueError::new_err(format!(
                "{key}: must be an integer ≥ {min} (got {v})"
            )));
        }
        Ok(v as usize)
    };
    if cpu_only && gpu_only {
        return Err(PyValueError::new_err(
            "cpu_only and gpu_only exclude each other",
        ));
    }
    let opts = BenchOptions {
        rods: count("rods", rods, 1)?,
        elements: count("elements", elements, 1)?,
        steps: count("steps", steps, 1)?,
        adapter,
        cpu_only,
        gpu_only,
        newton: match newton {
            "full" => NewtonVariant::Full,
            "fresh" => NewtonVariant::Fresh,
            "modified" => NewtonVariant::Modified,
            other => {
                return Err(PyValueError::new_err(format!(
                    "newton: unknown variant `{other}` (expected full, fresh or modified)"
                )))
            }
        },
        strategy: match strategy {
            "auto" => Strategy::Auto,
            "staggered" => Strategy::Staggered,
            "monolithic" => Strategy::Monolithic,
            "inexact" => Strategy::Inexact,
            other => {
                return Err(PyValueError::new_err(format!(
                    "strategy: unknown strategy `{other}` (expected auto, staggered, monolithic or inexact)"
                )))
            }
        },
        slots: count("slots", slots, 0)?,
        solve: match solve {
            "host" => BenchSolve::Host,
            "device" => BenchSolve::Device,
            "both" => BenchSolve::Both,
            "resident" => BenchSolve::Resident,
            "whole" => BenchSolve::Whole,
            other => {
                return Err(PyValueError::new_err(format!(
                    "solve: unknown mode `{other}` (expected host, device, both, resident or whole)"
                )))
            }
        },
        host_update,
    };
    let run = py
        .allow_threads(|| cosserat::bench::run(&opts))
        .map_err(|e| match e {
            BenchError::Option { .. } | BenchError::Limit(_) => {
                PyValueError::new_err(e.to_string())
            }
            _ => PyRuntimeError::new_err(e.to_string()),
        })?;
    Ok(run.json().to_string())
}

/// Names of the built-in scenes.
#[pyfunction]
fn builtin_scenes() -> Vec<&'static str> {
    cosserat::scene::builtin_scenes()
        .iter()
        .map(|b| b.name)
        .collect()
}

/// The `cosserat._cosserat` extension module.
#[pymodule]
fn _cosserat(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_class::<Simulation>()?;
    m.add_function(wrap_pyfunction!(builtin_scenes, m)?)?;
    m.add_function(wrap_pyfunction!(_run_sweep, m)?)?;
    m.add_function(wrap_pyfunction!(_bench, m)?)?;
    m.add_function(wrap_pyfunction!(_run_to_dir, m)?)?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
