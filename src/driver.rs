//! Runs one simulation into a folder: the time loop with every observer the outputs need
//! (`history.csv` streamed row by row, snapshots, VTK frames), then the charts and
//! `summary.json`. Shared by `cosserat run` and `cosserat reproduce`, so both write the
//! same files in the same way. A failed step is a result (status `failed`), never an error:
//! errors here are only I/O and set-up failures.

use std::path::{Path, PathBuf};

use crate::integrator::run::{run, RunOutcome};
use crate::integrator::{IntegratorParams, Simulation};
use crate::observe::balance::BalanceObserver;
use crate::observe::record::{LastAccepted, RunStatus, RunSummary, StepRecord};
use crate::output::{
    animate_snapshots, plot_accelerations, plot_energy, plot_momenta, plot_snapshots,
    write_summary, CosseratBenchOptions, CosseratBenchResult, HistoryWriter, OutputError,
    OutputTimes, ProbeWriter, Progress, Snapshot, TrajectoryRecorder, VtkSeries,
};
use crate::scene::limits::Footprint;
use crate::scene::Scene;

/// What to write besides `history.csv`, `summary.json`, `energy.png`, `momenta.png` and
/// `accelerations.png` (always written).
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Write every N-th step to `history.csv` (the last accepted step always).
    pub every: usize,
    /// Write `vtk/NAME_STEP.vtu` every this many steps and `vtk/NAME.pvd` (`None`: no VTK).
    pub vtk_every: Option<usize>,
    /// Draw `snapshots.png` from the levels at every this many steps (`None`: none).
    pub snapshot_every: Option<usize>,
    /// Label of the progress bar and chart titles.
    pub label: String,
    /// Unit of length on snapshot axes.
    pub length_unit: String,
    /// Write `trajectory.npz` with frames at these steps (`None`: no trajectory).
    pub trajectory: Option<OutputTimes>,
    /// Write `animation.gif` from the levels at every this many steps (`None`: none).
    pub animate_every: Option<usize>,
    /// Also write the `cosseratbench` layout into `cosseratbench/` (needs `trajectory`),
    /// with these identities in its `result.json`.
    pub cosseratbench: Option<CosseratBenchOptions>,
}

impl Default for RunOptions {
    /// Every step to `history.csv`, no VTK, snapshots or trajectory.
    fn default() -> Self {
        Self {
            every: 1,
            vtk_every: None,
            snapshot_every: None,
            label: String::new(),
            length_unit: "m".into(),
            trajectory: None,
            animate_every: None,
            cosseratbench: None,
        }
    }
}

impl RunOptions {
    /// What a run of `model` over `n_steps` steps with these options holds in memory: the
    /// model's elements and contact spheres, and the frames kept for `trajectory.npz`,
    /// `snapshots.png` and `animation.gif` until the run ends (`history.csv`, VTK frames
    /// and probes are streamed; chart records are capped).
    pub fn footprint(&self, model: &crate::model::Model, n_steps: usize) -> Footprint {
        let n = n_steps as u64;
        let every = |k: Option<usize>| k.map_or(0, |k| n / (k.max(1) as u64) + 2);
        Footprint {
            trajectory_frames: match &self.trajectory {
                None => 0,
                Some(OutputTimes::Every(k)) => every(Some(*k)),
                Some(OutputTimes::Steps(v)) => v.len() as u64 + 2,
            },
            snapshot_frames: every(self.snapshot_every).saturating_add(every(self.animate_every)),
            records: every(Some(self.every)).min(MAX_CHART_RECORDS as u64 + 1),
            ..Footprint::of_model(model)
        }
    }

    /// Refuses a run whose [`Self::footprint`] exceeds the memory limit in force
    /// (`docs/guarantees.md`), before anything is written.
    pub fn check_memory(
        &self,
        model: &crate::model::Model,
        n_steps: usize,
    ) -> Result<(), crate::scene::limits::LimitError> {
        crate::scene::limits::check_batch("this run", 1, &self.footprint(model, n_steps))
    }
}

/// Errors that stop a run before it could finish writing (not a failed step).
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// Writing an output failed.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The linear solver could not be set up.
    #[error("cannot set up the linear solver: {0}")]
    Setup(#[from] crate::linsolve::LinsolveError),
    /// An output name would leave the output folder.
    #[error(transparent)]
    Path(#[from] crate::paths::PathEscape),
    /// The run would need more memory than the limit in force.
    #[error(transparent)]
    Limit(#[from] crate::scene::limits::LimitError),
    /// The output folder could not be created.
    #[error("cannot create output directory {}: {error}", path.display())]
    Dir {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
}

/// What a finished (completed or failed) run leaves for reports.
#[derive(Clone, Debug)]
pub struct RunResult {
    /// The summary also written to `summary.json`.
    pub summary: RunSummary,
    /// The records written to `history.csv` (all of them up to [`MAX_CHART_RECORDS`],
    /// thinned evenly beyond).
    pub records: Vec<StepRecord>,
    /// Whether the model flies freely (momenta are then conserved and their drift means
    /// something).
    pub free_flight: bool,
}

/// Runs `scene` with `params` into `out` (created if missing).
pub fn run_to_dir(
    scene: &Scene,
    params: IntegratorParams,
    out: &Path,
    opts: &RunOptions,
) -> Result<RunResult, DriverError> {
    let mut sim = Simulation::new(scene.model.clone(), params)?;
    run_sim_to_dir(scene, &mut sim, out, opts)
}

/// Like [`run_to_dir`] for a simulation already set up (e.g. with a GPU element backend
/// attached); `sim` must have been built from `scene.model`.
pub fn run_sim_to_dir(
    scene: &Scene,
    sim: &mut Simulation,
    out: &Path,
    opts: &RunOptions,
) -> Result<RunResult, DriverError> {
    opts.check_memory(sim.model(), sim.params().n_steps())?;
    std::fs::create_dir_all(out).map_err(|error| DriverError::Dir {
        path: out.to_path_buf(),
        error,
    })?;
    let mut written: Vec<String> = vec!["history.csv".into()];
    let removed = remove_previous_outputs(out)?;
    if !removed.is_empty() {
        eprintln!(
            "note: {}: removed the previous run's files ({}) so that the folder holds only this run",
            out.display(),
            removed.join(", ")
        );
    }
    let mut history = HistoryWriter::create(&out.join("history.csv"))?;
    let mut vtk = match opts.vtk_every {
        Some(_) => {
            // The stem is sanitized; join_under proves the files stay inside `out`.
            let stem = scene.file_stem();
            let pvd = crate::paths::join_under(out, format!("vtk/{stem}.pvd"))?;
            let dir = pvd.parent().unwrap_or(out);
            Some(VtkSeries::new(dir, &stem)?)
        }
        None => None,
    };
    let mut trajectory = opts
        .trajectory
        .as_ref()
        .map(|_| TrajectoryRecorder::new(sim.model()));
    let mut probes = if scene.probes.is_empty() {
        None
    } else {
        written.push("probes.csv".into());
        Some(ProbeWriter::create(
            &out.join("probes.csv"),
            sim.model(),
            &scene.probes,
        )?)
    };
    let mut records = ChartRecords::new(MAX_CHART_RECORDS);
    let mut last_written: Option<usize> = None;
    let mut last_seen: Option<StepRecord> = None;
    let mut last_vtk: Option<usize> = None;
    let mut snapshots: Vec<Snapshot> = Vec::new();
    let mut frames: Vec<Snapshot> = Vec::new();
    let progress = Progress::new(sim.params().n_steps() as u64, &opts.label);
    let every = opts.every.max(1);
    let mut balance: Option<BalanceObserver> = None;
    // The observer sees every accepted step (the balances need consecutive levels); each
    // output thins on its own stride, and every output gets the last accepted level.
    let outcome: RunOutcome = run(sim, 1, |rec: &StepRecord, s: &Simulation| {
        let on = |k: Option<usize>| k.is_some_and(|k| rec.step.is_multiple_of(k.max(1)));
        let last = rec.step == s.params().n_steps();
        match balance.as_mut() {
            None => {
                balance = Some(BalanceObserver::new(
                    s.model(),
                    s.state(),
                    s.params().dt,
                    rec.l,
                    rec.j,
                    rec.total,
                ))
            }
            Some(b) => b.step(
                s.model(),
                s.state(),
                rec.step,
                rec.l,
                rec.j,
                rec.total,
                rec.work_total,
                rec.dissipation_total,
            ),
        }
        if let Some(p) = probes.as_mut() {
            p.push(rec.step, rec.t, s.model(), s.state())?;
        }
        if rec.step.is_multiple_of(every) || last {
            history.push(rec)?;
            records.push(rec);
            last_written = Some(rec.step);
        }
        if on(opts.snapshot_every) {
            snapshots.push(Snapshot::of(s));
        }
        if on(opts.animate_every) {
            frames.push(Snapshot::of(s));
        }
        if let (Some(v), true) = (vtk.as_mut(), on(opts.vtk_every) || last) {
            v.write_frame(s, rec.step, rec.t)?;
            last_vtk = Some(rec.step);
        }
        if let (Some(tr), Some(times)) = (trajectory.as_mut(), opts.trajectory.as_ref()) {
            if times.contains(rec.step) || last {
                tr.push(rec.step, rec.t, s.state());
            }
        }
        progress.step(rec.t, rec.newton_iters);
        last_seen = Some(rec.clone());
        Ok::<(), DriverError>(())
    })?;
    progress.finish();
    // A failed run: the simulation is left at the last accepted level; make it the last
    // entry of every output.
    if let Some(rec) = &last_seen {
        if last_written != Some(rec.step) {
            history.push(rec)?;
        }
        records.keep_last(rec.clone());
        if let Some(v) = vtk.as_mut() {
            if last_vtk != Some(rec.step) {
                v.write_frame(sim, rec.step, rec.t)?;
            }
        }
        if let Some(tr) = trajectory.as_mut() {
            if tr.last_step() != Some(rec.step) {
                tr.push(rec.step, rec.t, sim.state());
            }
        }
    }
    if let Some(v) = &vtk {
        v.finish()?;
        written.push(format!("vtk/{}", v.pvd_file_name()));
        written.push(format!(
            "vtk/{}_STEP.vtu ({} frames)",
            scene.name,
            v.frames()
        ));
    }
    let records = records.into_vec();
    let title = format!("{}: {}", opts.label, sim.params().scheme.name());
    plot_energy(&out.join("energy.png"), &records, &title)?;
    plot_momenta(&out.join("momenta.png"), &records, &title)?;
    plot_accelerations(&out.join("accelerations.png"), &records, &title)?;
    written.extend(["energy.png", "momenta.png", "accelerations.png"].map(String::from));
    if opts.snapshot_every.is_some() {
        if snapshots.last().map(|s| s.t) != Some(sim.state().t) {
            snapshots.push(Snapshot::of(sim));
        }
        plot_snapshots(
            &out.join("snapshots.png"),
            &title,
            &snapshots,
            sim.model().planar,
            &opts.length_unit,
        )?;
        written.push("snapshots.png".into());
    }
    if opts.animate_every.is_some() {
        if frames.last().map(|s| s.t) != Some(sim.state().t) {
            frames.push(Snapshot::of(sim));
        }
        animate_snapshots(
            &out.join("animation.gif"),
            &title,
            &frames,
            sim.model().planar,
            &opts.length_unit,
        )?;
        written.push(format!("animation.gif ({} frames)", frames.len()));
    }
    if let Some(tr) = &trajectory {
        tr.write(&out.join("trajectory.npz"))?;
        written.push(format!("trajectory.npz ({} frames)", tr.len()));
        if let Some(cbo) = &opts.cosseratbench {
            let cb = cosseratbench_result(scene, sim, &outcome, cbo, tr.len());
            tr.write_cosseratbench(sim.model(), &out.join("cosseratbench"), &cb)?;
            written.push("cosseratbench/trajectory.npz".into());
            written.push("cosseratbench/result.json".into());
        }
    }
    written.push("summary.json".into());
    let mut summary = summarize(scene, sim, &outcome);
    if let Some(b) = &balance {
        summary.energy_balance = b.energy().clone();
        summary.impulse_balance = b.impulse().clone();
    }
    let last = last_seen.as_ref().map_or(0, |r| r.step);
    summary.last_accepted = LastAccepted {
        step: last,
        t: last_seen.as_ref().map_or(0.0, |r| r.t),
        note: match outcome.status {
            RunStatus::Completed => "the run completed; every output ends at its last step".into(),
            RunStatus::Failed => format!(
                "step {} failed; every output (history.csv, charts{}{}) ends at step {last}, the last accepted level",
                last + 1,
                if vtk.is_some() { ", vtk/" } else { "" },
                if trajectory.is_some() { ", trajectory.npz" } else { "" },
            ),
        },
    };
    summary.outputs = written;
    // Written last and renamed into place: a summary.json in the folder means this run
    // finished writing (completed or failed), and it is whole.
    let tmp = out.join("summary.json.tmp");
    write_summary(&tmp, &summary)?;
    let path = out.join("summary.json");
    std::fs::rename(&tmp, &path).map_err(|e| OutputError::Io { path, error: e })?;
    Ok(RunResult {
        summary,
        records,
        free_flight: scene.model.is_free_flight(),
    })
}

fn cosseratbench_result(
    scene: &Scene,
    sim: &Simulation,
    o: &RunOutcome,
    cb: &CosseratBenchOptions,
    n_frames: usize,
) -> CosseratBenchResult {
    let failed = o.status == RunStatus::Failed;
    let p = sim.params();
    CosseratBenchResult {
        experiment: cb.experiment.clone().unwrap_or_else(|| scene.name.clone()),
        solver: "cosserat".into(),
        outcome: if failed { "diverged" } else { "completed" }.into(),
        n_elements: sim.model().rods.first().map_or(0, |r| r.elements.len()),
        n_frames,
        values: cb.values.clone(),
        options: Default::default(),
        missing: vec![],
        failure: o.reason.clone(),
        diverged_at: failed.then_some(o.t_reached + p.dt),
        wall_time: o.wall_s,
        metrics: Default::default(),
        observations: Default::default(),
        provenance: serde_json::json!({
            "scenario": cb.scenario_digest,
            "code": null,
            "solver_version": format!("cosserat {}", env!("CARGO_PKG_VERSION")),
        }),
        jobs: 1,
        settings: serde_json::json!({
            "scheme": p.scheme.name(),
            "dt": p.dt,
            "t_end": p.t_end,
            "strategy": p.scheme.is_dissipative().then(|| sim.strategy().name()),
        }),
    }
}

/// Most step records a run keeps in memory for its charts (and [`RunResult::records`]);
/// beyond it every second one is dropped and only every second one is kept from then on,
/// so a run of any length holds between half and all of this many (first and last kept).
/// `history.csv` always gets every row.
pub const MAX_CHART_RECORDS: usize = 200_000;

/// The records of a run kept for its charts, thinned to at most `cap`.
#[derive(Debug)]
pub struct ChartRecords {
    recs: Vec<StepRecord>,
    cap: usize,
    stride: usize,
    offered: usize,
}

impl ChartRecords {
    /// An empty buffer of at most `cap` (≥ 2) records.
    pub fn new(cap: usize) -> Self {
        Self {
            recs: Vec::new(),
            cap: cap.max(2),
            stride: 1,
            offered: 0,
        }
    }

    /// Offers the next record (kept when it falls on the current stride).
    pub fn push(&mut self, rec: &StepRecord) {
        if self.offered.is_multiple_of(self.stride) {
            if self.recs.len() == self.cap {
                // Keep the even-indexed ones (the first included); double the stride.
                let mut i = 0;
                self.recs.retain(|_| {
                    i += 1;
                    (i - 1) % 2 == 0
                });
                self.stride *= 2;
            }
            if self.offered.is_multiple_of(self.stride) {
                self.recs.push(rec.clone());
            }
        }
        self.offered += 1;
    }

    /// Makes `rec` the last record (the final level of a run is always charted).
    pub fn keep_last(&mut self, rec: StepRecord) {
        if self.recs.last().map(|r| r.step) != Some(rec.step) {
            if self.recs.len() == self.cap {
                self.recs.pop();
            }
            self.recs.push(rec);
        }
    }

    /// Records kept so far.
    pub fn len(&self) -> usize {
        self.recs.len()
    }

    /// True when none is kept.
    pub fn is_empty(&self) -> bool {
        self.recs.is_empty()
    }

    /// The kept records, in order.
    pub fn into_vec(self) -> Vec<StepRecord> {
        self.recs
    }
}

/// Files a run writes in its folder (and `vtk/*.vtu`, `vtk/*.pvd`).
pub const RUN_FILES: &[&str] = &[
    "history.csv",
    "summary.json",
    "summary.json.tmp",
    "energy.png",
    "momenta.png",
    "accelerations.png",
    "snapshots.png",
    "trajectory.npz",
    "probes.csv",
    "animation.gif",
    "cosseratbench/trajectory.npz",
    "cosseratbench/result.json",
];

/// Removes a previous run's files from `out` (only the names a run writes, and only
/// `.vtu`/`.pvd` files and `.pvd.tmp` leftovers in `out/vtk`), so that a reused folder never mixes two runs.
/// Returns what it removed, for the message.
pub fn remove_previous_outputs(out: &Path) -> Result<Vec<String>, OutputError> {
    let mut removed = Vec::new();
    let rm = |p: &Path| match std::fs::remove_file(p) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(OutputError::Io {
            path: p.to_path_buf(),
            error: e,
        }),
    };
    for f in RUN_FILES {
        if rm(&out.join(f))? {
            removed.push(f.to_string());
        }
    }
    let vtk = out.join("vtk");
    if vtk.is_dir() {
        let mut n = 0;
        let entries = std::fs::read_dir(&vtk).map_err(|e| OutputError::Io {
            path: vtk.clone(),
            error: e,
        })?;
        for entry in entries.flatten() {
            let p = entry.path();
            let ext = p.extension().and_then(|e| e.to_str());
            // `NAME.pvd.tmp`: a collection being rewritten when a run was killed.
            let pvd_tmp = p.to_string_lossy().ends_with(".pvd.tmp");
            if (matches!(ext, Some("vtu" | "pvd")) || pvd_tmp) && rm(&p)? {
                n += 1;
            }
        }
        if n > 0 {
            removed.push(format!("vtk/: {n} files"));
        }
    }
    Ok(removed)
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
        energy_balance: Default::default(),
        impulse_balance: Default::default(),
        last_accepted: Default::default(),
        outputs: vec![],
        energy_initial: o.energy_initial,
        energy_final: o.energy_final,
        max_link_g: o.max_link_g,
        fallback_steps: o.fallback_steps,
        cutback_steps: o.cutback_steps,
        smallest_substep: o.smallest_substep,
        accepted: o.accepted,
        backend: sim.backend_name(),
        strategy: sim
            .params()
            .scheme
            .is_dissipative()
            .then(|| sim.strategy().name().into()),
        linear_solver: sim.linear_solver().0.to_string(),
        solve: sim.solve_label().into(),
        linear_solver_fallbacks: sim.linear_solver().1,
        timers: o.timers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(step: usize) -> StepRecord {
        StepRecord {
            step,
            ..Default::default()
        }
    }

    #[test]
    fn chart_records_stay_under_their_cap_evenly_with_first_and_last() {
        let mut c = ChartRecords::new(100);
        for s in 0..10_000 {
            c.push(&rec(s));
            assert!(c.len() <= 100);
        }
        c.keep_last(rec(10_000));
        let v = c.into_vec();
        assert!(v.len() > 50 && v.len() <= 100, "{}", v.len());
        assert_eq!(v[0].step, 0);
        assert_eq!(v.last().unwrap().step, 10_000);
        // Evenly thinned: one stride between all kept records but the last.
        let stride = v[1].step - v[0].step;
        assert!(v[..v.len() - 1]
            .windows(2)
            .all(|w| w[1].step - w[0].step == stride));
        assert_eq!(stride, 128);
    }
}
