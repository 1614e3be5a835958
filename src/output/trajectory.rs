//! `trajectory.npz`: node positions, directors and velocities at chosen output times, in
//! NumPy's `.npz` format (written with the `ndarray-npy` crate), and the exporter to the
//! file layout of the `cosseratbench` suite.
//!
//! **Node directors.** Directors live on element *ends* (a node at a rigid corner has one
//! triad per element). The director triad of a node is the one of the end of the
//! lowest-numbered element that touches it, i.e. along a rod the triad of the element that
//! *leaves* the node (the last node of a rod takes the triad of the element that arrives).
//! Inside a straight segment the two triads at a node coincide (they share the node's
//! rotation and their reference triad), so the choice matters only at corners and
//! polyline kinks, where `vtk/` and the per-element arrays keep both.
//!
//! Arrays (T output times, N nodes, R rods):
//! `times` [T], `steps` [T] (int64), `node_id` [N], `rod_id` [N] (int64: the rod of the
//! element that gives the node its directors), `positions` [T, N, 3], `velocities`
//! [T, N, 3], `directors` [T, N, 3, 3] with `directors[t, a, k]` the vector `d_{k+1}`, and
//! per rod `rod{i}_nodes` [N_i] (int64: its node ids in order along the rod).

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use ndarray::{Array1, Array3, Array4};
use ndarray_npy::NpzWriter;

use super::{num, OutputError};
use crate::integrator::state::State;
use crate::model::Model;
use crate::observe::probe::node_director_ends;

/// When output frames are taken: every `k`-th step or at listed steps (the initial level
/// and the last accepted step are always included).
#[derive(Clone, Debug, PartialEq)]
pub enum OutputTimes {
    /// Every `k`-th step (`--output-dt`: `k = output_dt / Δt`).
    Every(usize),
    /// These steps (`--times`), ascending.
    Steps(Vec<usize>),
}

impl OutputTimes {
    /// Output every `output_dt`, which must be a whole multiple of `dt` (to 1e-9
    /// relative): otherwise an error that says which steps are near.
    pub fn from_dt(output_dt: f64, dt: f64) -> Result<Self, String> {
        if !(output_dt.is_finite() && output_dt > 0.0) {
            return Err(format!(
                "must be a positive number (got {})",
                num(output_dt)
            ));
        }
        let k = (output_dt / dt).round();
        if k < 1.0 || (k * dt - output_dt).abs() > 1e-9 * output_dt {
            let q = output_dt / dt;
            return Err(format!(
                "{} is not a whole multiple of Δt = {} (nearest: {} and {})",
                num(output_dt),
                num(dt),
                short(q.floor().max(1.0) * dt),
                short(q.ceil().max(1.0) * dt)
            ));
        }
        Ok(Self::Every(k as usize))
    }

    /// Output at the listed times, each of which must land on a step (`t = n·Δt` to 1e-9
    /// of Δt) within `[0, t_end]`.
    pub fn from_times(times: &[f64], dt: f64, n_steps: usize) -> Result<Self, String> {
        let mut steps = Vec::with_capacity(times.len());
        for &t in times {
            if !t.is_finite() || t < 0.0 {
                return Err(format!("time {} must be a finite number ≥ 0", num(t)));
            }
            let n = (t / dt).round();
            if (n * dt - t).abs() > 1e-9 * dt {
                return Err(format!(
                    "time {} does not land on a step of Δt = {} (nearest: {} and {})",
                    num(t),
                    num(dt),
                    short((t / dt).floor() * dt),
                    short((t / dt).ceil() * dt)
                ));
            }
            if n as usize > n_steps {
                return Err(format!(
                    "time {} is after the end time {}",
                    num(t),
                    short(n_steps as f64 * dt)
                ));
            }
            steps.push(n as usize);
        }
        steps.sort_unstable();
        steps.dedup();
        Ok(Self::Steps(steps))
    }

    /// Whether `step` is an output step.
    pub fn contains(&self, step: usize) -> bool {
        match self {
            Self::Every(k) => step.is_multiple_of((*k).max(1)),
            Self::Steps(s) => s.binary_search(&step).is_ok(),
        }
    }
}

/// `x` rounded to 12 significant digits (no `0.6000000000000001` in messages), as
/// [`num`] writes it.
fn short(x: f64) -> String {
    num(format!("{x:.11e}").parse().unwrap_or(x))
}

/// The rods of a model as node chains: per rod its node ids in order and its elements.
fn rod_chains(model: &Model) -> Vec<Vec<usize>> {
    model
        .rods
        .iter()
        .map(|rod| {
            let els = &model.elements[rod.elements.clone()];
            let mut nodes: Vec<usize> = Vec::with_capacity(els.len() + 1);
            for el in els {
                if nodes.last() != Some(&el.nodes[0]) {
                    nodes.push(el.nodes[0]);
                }
                nodes.push(el.nodes[1]);
            }
            nodes
        })
        .collect()
}

/// Collects output frames during a run and writes them at the end.
#[derive(Clone, Debug)]
pub struct TrajectoryRecorder {
    /// Per node: (element, end) whose triad is the node's director triad.
    node_end: Vec<(usize, usize)>,
    rod_of_node: Vec<i64>,
    chains: Vec<Vec<usize>>,
    times: Vec<f64>,
    steps: Vec<i64>,
    positions: Vec<f64>,
    velocities: Vec<f64>,
    directors: Vec<f64>,
    /// Per frame and element: unit `d1` at the element's middle (cosseratbench layout).
    element_d1: Vec<f64>,
}

impl TrajectoryRecorder {
    /// A recorder for `model`.
    pub fn new(model: &Model) -> Self {
        let (node_end, rod_of_node) = node_director_ends(model);
        Self {
            node_end,
            rod_of_node,
            chains: rod_chains(model),
            times: vec![],
            steps: vec![],
            positions: vec![],
            velocities: vec![],
            directors: vec![],
            element_d1: vec![],
        }
    }

    /// Number of frames recorded.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// True before the first frame.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The step of the last frame recorded.
    pub fn last_step(&self) -> Option<usize> {
        self.steps.last().map(|&s| s as usize)
    }

    /// Records `state` as the frame of `step` at time `t` (`t_0 + step·Δt`).
    pub fn push(&mut self, step: usize, t: f64, state: &State) {
        self.times.push(t);
        self.steps.push(step as i64);
        for (a, &(e, l)) in self.node_end.iter().enumerate() {
            self.positions.extend(state.r[a].iter());
            self.velocities.extend(state.v[a].iter());
            if e == usize::MAX {
                // A node without elements (a point mass on its own): no directors.
                self.directors.extend([f64::NAN; 9]);
            } else {
                let d = &state.d[e][l];
                for k in 0..3 {
                    self.directors.extend(d.column(k).iter());
                }
            }
        }
        for d in &state.d {
            let mid = 0.5 * (d[0].column(0) + d[1].column(0));
            let unit = mid / mid.norm().max(1e-300);
            self.element_d1.extend(unit.iter());
        }
    }

    /// Writes `trajectory.npz` (arrays in the module documentation).
    pub fn write(&self, path: &Path) -> Result<(), OutputError> {
        let (t, n) = (self.times.len(), self.node_end.len());
        let shape = |e: ndarray::ShapeError| OutputError::Npz {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let mut npz = npz_create(path)?;
        put(&mut npz, path, "times", &Array1::from(self.times.clone()))?;
        put(&mut npz, path, "steps", &Array1::from(self.steps.clone()))?;
        let ids: Array1<i64> = (0..n as i64).collect();
        put(&mut npz, path, "node_id", &ids)?;
        put(
            &mut npz,
            path,
            "rod_id",
            &Array1::from(self.rod_of_node.clone()),
        )?;
        let pos = Array3::from_shape_vec((t, n, 3), self.positions.clone()).map_err(shape)?;
        put(&mut npz, path, "positions", &pos)?;
        let vel = Array3::from_shape_vec((t, n, 3), self.velocities.clone()).map_err(shape)?;
        put(&mut npz, path, "velocities", &vel)?;
        let dir = Array4::from_shape_vec((t, n, 3, 3), self.directors.clone()).map_err(shape)?;
        put(&mut npz, path, "directors", &dir)?;
        for (i, chain) in self.chains.iter().enumerate() {
            let ids: Array1<i64> = chain.iter().map(|&a| a as i64).collect();
            put(&mut npz, path, &format!("rod{i}_nodes"), &ids)?;
        }
        npz_finish(npz, path)
    }

    /// Writes the `cosseratbench` layout into `dir`: `trajectory.npz` with `times` `[T]`,
    /// per rod `rod{i}` `[T, N_i, 3]` (its node positions in order) and `rod{i}_directors`
    /// `[T, N_i − 1, 3]` (unit `d1` at the middle of each element), and `result.json` from
    /// `result` (see [`CosseratBenchResult`]).
    pub fn write_cosseratbench(
        &self,
        model: &Model,
        dir: &Path,
        result: &CosseratBenchResult,
    ) -> Result<(), OutputError> {
        std::fs::create_dir_all(dir).map_err(|e| OutputError::io(dir, e))?;
        let path = dir.join("trajectory.npz");
        let (t, n, ne) = (self.times.len(), self.node_end.len(), model.elements.len());
        let mut npz = npz_create(&path)?;
        put(&mut npz, &path, "times", &Array1::from(self.times.clone()))?;
        for (i, (chain, rod)) in self.chains.iter().zip(&model.rods).enumerate() {
            let mut pos = Array3::<f64>::zeros((t, chain.len(), 3));
            for k in 0..t {
                for (j, &a) in chain.iter().enumerate() {
                    for c in 0..3 {
                        pos[[k, j, c]] = self.positions[(k * n + a) * 3 + c];
                    }
                }
            }
            let els = rod.elements.clone();
            let mut d1 = Array3::<f64>::zeros((t, els.len(), 3));
            for k in 0..t {
                for (j, e) in els.clone().enumerate() {
                    for c in 0..3 {
                        d1[[k, j, c]] = self.element_d1[(k * ne + e) * 3 + c];
                    }
                }
            }
            put(&mut npz, &path, &format!("rod{i}"), &pos)?;
            put(&mut npz, &path, &format!("rod{i}_directors"), &d1)?;
        }
        npz_finish(npz, &path)?;
        let json = dir.join("result.json");
        let mut text = serde_json::to_string_pretty(result).map_err(|error| OutputError::Json {
            path: json.clone(),
            error,
        })?;
        text.push('\n');
        std::fs::write(&json, text).map_err(|e| OutputError::io(&json, e))
    }
}

fn put<S, D>(
    npz: &mut NpzWriter<BufWriter<File>>,
    path: &Path,
    name: &str,
    array: &ndarray::ArrayBase<S, D>,
) -> Result<(), OutputError>
where
    S: ndarray::Data,
    S::Elem: ndarray_npy::WritableElement,
    D: ndarray::Dimension,
{
    npz.add_array(name, array).map_err(|e| OutputError::Npz {
        path: path.to_path_buf(),
        message: format!("array {name}: {e}"),
    })
}

fn npz_finish(npz: NpzWriter<BufWriter<File>>, path: &Path) -> Result<(), OutputError> {
    use std::io::Write as _;
    let mut out = npz.finish().map_err(|e| OutputError::Npz {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    out.flush().map_err(|e| OutputError::io(path, e))
}

fn npz_create(path: &Path) -> Result<NpzWriter<BufWriter<File>>, OutputError> {
    let file = File::create(path).map_err(|e| OutputError::io(path, e))?;
    Ok(NpzWriter::new(BufWriter::new(file)))
}

/// `result.json` of the `cosseratbench` layout: the fields, order and types of the suite's
/// `Result.summary()`, so its `rescore` and viewer read it as one of its own runs.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CosseratBenchResult {
    /// The suite's experiment (from its `experiment.json`; else our scene name).
    pub experiment: String,
    /// Always `cosserat`.
    pub solver: String,
    /// `completed` or `diverged`.
    pub outcome: String,
    /// Elements per rod (the suite's resolution; the first rod's count).
    pub n_elements: usize,
    /// Frames in `trajectory.npz`.
    pub n_frames: usize,
    /// The experiment's parameter values (from its `experiment.json`; else empty).
    pub values: serde_json::Map<String, serde_json::Value>,
    /// The suite's solver options as run (its `time_step_scale` and the like): none, `{}`.
    pub options: serde_json::Map<String, serde_json::Value>,
    /// Missing capabilities (none).
    pub missing: Vec<String>,
    /// Why the run failed (`null` when completed).
    pub failure: Option<String>,
    /// Time of the failing step (`null` when completed).
    pub diverged_at: Option<f64>,
    /// Wall time of the time loop, s.
    pub wall_time: f64,
    /// Left empty: cosseratbench computes its metrics from the trajectory (`rescore`).
    pub metrics: serde_json::Map<String, serde_json::Value>,
    /// Left empty, as `metrics`.
    pub observations: serde_json::Map<String, serde_json::Value>,
    /// `scenario`: the digest given with `--scenario-digest` (cosseratbench's own digest of
    /// the experiment's scenario, which its `rescore` compares) or `null`; `code`: `null`;
    /// `solver_version`: `cosserat VERSION`.
    pub provenance: serde_json::Value,
    /// Runs going at once when this one was timed: 1.
    pub jobs: usize,
    /// Our numerical choices, as `summary.json` states them: `scheme` (its name), `dt`,
    /// `strategy` (`null` for a scheme without one), `t_end`.
    pub settings: serde_json::Value,
}

/// What `--cosseratbench` writes into `result.json` beyond the run itself.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CosseratBenchOptions {
    /// The suite's digest of the matching scenario (`provenance.scenario`; `None`: `null`).
    pub scenario_digest: Option<String>,
    /// The suite's experiment name (`None`: the scene name).
    pub experiment: Option<String>,
    /// The experiment's parameter values.
    pub values: serde_json::Map<String, serde_json::Value>,
}

impl CosseratBenchOptions {
    /// Reads `name` and `values` from the `experiment.json` the suite writes into each
    /// variant's folder (`RESULTS/EXPERIMENT/VARIANT/experiment.json`).
    pub fn read_experiment(&mut self, path: &Path) -> Result<(), String> {
        let shown = path.display();
        let text = std::fs::read_to_string(path).map_err(|e| format!("{shown}: {e}"))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| format!("{shown}: not JSON: {e}"))?;
        let name = v
            .get("name")
            .and_then(|n| n.as_str())
            .ok_or_else(|| format!("{shown}: key `name`: missing or not a string"))?;
        let values = v
            .get("values")
            .and_then(|n| n.as_object())
            .ok_or_else(|| format!("{shown}: key `values`: missing or not an object"))?;
        if let Some((k, _)) = values.iter().find(|(_, x)| !x.is_number()) {
            return Err(format!("{shown}: key `values.{k}`: not a number"));
        }
        self.experiment = Some(name.to_string());
        self.values = values.clone();
        Ok(())
    }
}
