//! Outputs a researcher reads back: `trajectory.npz` holds the run's states at the output
//! times (positions and velocities bit for bit the simulation's, times exactly `n·Δt`), a thinned
//! `history.csv` closes the energy balance with its running totals, `summary.json`
//! balances L and J against the applied impulse to round-off, the `.vtu` files have one
//! point per node, and a failed run's last accepted step ends every output.
use std::path::Path;

use cosserat::driver::{run_sim_to_dir, RunOptions, RunResult};
use cosserat::integrator::Simulation;
use cosserat::output::{read_history, CosseratBenchOptions, OutputTimes};
use cosserat::scene::{builtin_scenes, parse_scene, Scene};
use ndarray::{Array1, Array3, Array4};
use ndarray_npy::NpzReader;

fn builtin(name: &str) -> &'static str {
    builtin_scenes()
        .iter()
        .find(|s| s.name == name)
        .unwrap()
        .toml
}

/// The free-flying frame pushed by a ramped force and moment at its free end (no
/// supports: momenta change by exactly the applied impulse).
fn pushed_frame(scheme: &str, t_end: f64) -> Scene {
    let text = builtin("frame")
        .replace(
            "scheme = \"edmc2\"\nalpha = 0.5",
            &format!("scheme = \"{scheme}\"\nalpha = 0.5"),
        )
        .replace("t_end = 10.0", &format!("t_end = {t_end}"))
        .replace(
            "[integrator]",
            r#"[[load]]
at = [10, 10, 10]
force = [0.3, -0.2, 0.5]
moment = [0.1, 0.0, 0.05]
time = [0, 1, 2]
factor = [0, 1, 0.25]

[integrator]"#,
        );
    let text = if scheme == "edmc2" {
        text
    } else {
        text.replace("alpha = 0.5\n", "")
    };
    parse_scene(&text, "pushed_frame.toml").unwrap()
}

fn run(scene: &Scene, out: &Path, opts: &RunOptions) -> (RunResult, Simulation) {
    let mut sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
    let r = run_sim_to_dir(scene, &mut sim, out, opts).unwrap();
    (r, sim)
}

#[test]
fn trajectory_npz_reads_back_the_states_at_exact_step_times() {
    let scene = pushed_frame("edmc2", 2.0);
    let dir = tempfile::tempdir().unwrap();
    let dt = scene.params.dt;
    let opts = RunOptions {
        trajectory: Some(OutputTimes::from_dt(0.6, dt).unwrap()),
        cosseratbench: Some(CosseratBenchOptions {
            scenario_digest: Some("0123456789abcdef".into()),
            experiment: Some("cantilever".into()),
            values: serde_json::from_str(r#"{"force": 0.5}"#).unwrap(),
        }),
        ..RunOptions::default()
    };
    let (res, sim) = run(&scene, dir.path(), &opts);
    assert_eq!(res.summary.steps, 10);
    let mut npz =
        NpzReader::new(std::fs::File::open(dir.path().join("trajectory.npz")).unwrap()).unwrap();
    let times: Array1<f64> = npz.by_name("times").unwrap();
    let steps: Array1<i64> = npz.by_name("steps").unwrap();
    // Every 3rd step (0.6 / 0.2) and the last one.
    assert_eq!(steps.to_vec(), vec![0, 3, 6, 9, 10]);
    for (t, n) in times.iter().zip(&steps) {
        assert_eq!(*t, *n as f64 * dt, "t must be n·Δt exactly");
    }
    let pos: Array3<f64> = npz.by_name("positions").unwrap();
    let vel: Array3<f64> = npz.by_name("velocities").unwrap();
    let dirs: Array4<f64> = npz.by_name("directors").unwrap();
    let n = sim.model().n_nodes();
    assert_eq!(pos.shape(), &[5, n, 3]);
    assert_eq!(dirs.shape(), &[5, n, 3, 3]);
    let st = sim.state();
    let last = pos.shape()[0] - 1;
    for a in 0..n {
        for c in 0..3 {
            assert!(pos[[last, a, c]] == st.r[a][c]);
            assert!(vel[[last, a, c]] == st.v[a][c]);
        }
    }
    // Row 0 is the reference configuration; directors are the element triads (orthonormal).
    for a in 0..n {
        for c in 0..3 {
            assert_eq!(pos[[0, a, c]], sim.model().nodes[a][c]);
        }
        for k in 0..3 {
            for m in 0..3 {
                let dot: f64 = (0..3)
                    .map(|c| dirs[[last, a, k, c]] * dirs[[last, a, m, c]])
                    .sum();
                let want = if k == m { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-12, "node {a}: d{k}·d{m} = {dot}");
            }
        }
    }
    let rod_id: Array1<i64> = npz.by_name("rod_id").unwrap();
    assert_eq!(rod_id.len(), n);
    let rod2: Array1<i64> = npz.by_name("rod2_nodes").unwrap();
    assert_eq!(rod2.len(), 6, "5 elements: 6 nodes along the rod");
    assert_eq!(rod_id[rod2[5] as usize], 2, "the free end belongs to rod 2");

    // cosseratbench layout: rod{i} [T, N_i, 3], rod{i}_directors [T, N_i − 1, 3].
    let cb = dir.path().join("cosseratbench");
    let mut npz = NpzReader::new(std::fs::File::open(cb.join("trajectory.npz")).unwrap()).unwrap();
    let rod0: Array3<f64> = npz.by_name("rod0").unwrap();
    let d0: Array3<f64> = npz.by_name("rod0_directors").unwrap();
    assert_eq!(rod0.shape(), &[5, 6, 3]);
    assert_eq!(d0.shape(), &[5, 5, 3]);
    let rod0_nodes: Array1<i64> =
        NpzReader::new(std::fs::File::open(dir.path().join("trajectory.npz")).unwrap())
            .unwrap()
            .by_name("rod0_nodes")
            .unwrap();
    for (j, &a) in rod0_nodes.iter().enumerate() {
        for c in 0..3 {
            assert_eq!(rod0[[last, j, c]], st.r[a as usize][c]);
        }
    }
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cb.join("result.json")).unwrap()).unwrap();
    // The keys of cosseratbench 0.3's `Result.summary()`, no more and no fewer, with its
    // types (the map reads back sorted).
    let mut keys: Vec<&str> = result
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    keys.sort_unstable();
    let mut suite = [
        "experiment",
        "solver",
        "outcome",
        "n_elements",
        "n_frames",
        "values",
        "options",
        "missing",
        "failure",
        "diverged_at",
        "wall_time",
        "metrics",
        "observations",
        "provenance",
        "jobs",
        "settings",
    ];
    suite.sort_unstable();
    assert_eq!(keys, suite);
    assert_eq!(result["experiment"], "cantilever");
    assert_eq!(result["outcome"], "completed");
    assert_eq!(result["solver"], "cosserat");
    // Elements per rod, as the suite's resolution (each of the frame's three rods has 5).
    assert_eq!(result["n_elements"], 5);
    assert_eq!(result["n_frames"], times.len());
    assert_eq!(result["values"]["force"], 0.5);
    // Solver options are the suite's constructor options: none were given.
    assert_eq!(result["options"], serde_json::json!({}));
    assert_eq!(result["missing"], serde_json::json!([]));
    assert!(result["failure"].is_null() && result["diverged_at"].is_null());
    assert!(result["wall_time"].as_f64().unwrap() >= 0.0);
    assert!(result["metrics"].as_object().unwrap().is_empty());
    assert!(result["observations"].as_object().unwrap().is_empty());
    assert_eq!(result["provenance"]["scenario"], "0123456789abcdef");
    assert!(result["provenance"]["code"].is_null());
    assert_eq!(result["jobs"], 1);
    // The numerical choices read as summary.json states them.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(result["settings"]["scheme"], "edmc2");
    assert_eq!(
        result["settings"]["scheme"],
        summary["params"]["scheme"]["name"]
    );
    assert_eq!(result["settings"]["dt"], dt);
    assert_eq!(result["settings"]["strategy"], summary["strategy"]);
}

#[test]
fn cosseratbench_result_reads_the_suites_experiment_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("experiment.json");
    std::fs::write(
        &path,
        r#"{"name": "twist", "values": {"tension": 1.0, "twist": 1.02}, "varied": {}}"#,
    )
    .unwrap();
    let mut cb = CosseratBenchOptions::default();
    cb.read_experiment(&path).unwrap();
    assert_eq!(cb.experiment.as_deref(), Some("twist"));
    assert_eq!(cb.values["twist"], 1.02);
    std::fs::write(&path, r#"{"name": "twist", "values": {"twist": "high"}}"#).unwrap();
    let e = cb.read_experiment(&path).unwrap_err();
    assert!(
        e.contains("experiment.json") && e.contains("values.twist"),
        "{e}"
    );
    std::fs::write(&path, r#"{"values": {}}"#).unwrap();
    let e = cb.read_experiment(&path).unwrap_err();
    assert!(e.contains("key `name`"), "{e}");
}

#[test]
fn output_times_must_land_on_steps() {
    assert_eq!(OutputTimes::from_dt(0.6, 0.2), Ok(OutputTimes::Every(3)));
    let e = OutputTimes::from_dt(0.5, 0.2).unwrap_err();
    assert!(
        e.contains("not a whole multiple") && e.contains("nearest: 0.4 and 0.6"),
        "{e}"
    );
    assert_eq!(
        OutputTimes::from_times(&[1.0, 0.2, 0.2], 0.2, 10),
        Ok(OutputTimes::Steps(vec![1, 5]))
    );
    let e = OutputTimes::from_times(&[0.3], 0.2, 10).unwrap_err();
    assert!(
        e.contains("does not land on a step") && e.contains("0.2 and 0.4"),
        "{e}"
    );
    let e = OutputTimes::from_times(&[2.2], 0.2, 10).unwrap_err();
    assert!(e.contains("after the end time"), "{e}");
}

#[test]
fn thinned_history_closes_the_energy_balance() {
    // EDMC-2 on the pushed frame: work in, dissipation out.
    let scene = pushed_frame("edmc2", 3.0);
    let (full_dir, thin_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    run(&scene, full_dir.path(), &RunOptions::default());
    let thin = RunOptions {
        every: 4,
        ..RunOptions::default()
    };
    let (res, _) = run(&scene, thin_dir.path(), &thin);
    let full = read_history(&full_dir.path().join("history.csv")).unwrap();
    let rows = read_history(&thin_dir.path().join("history.csv")).unwrap();
    assert_eq!(
        rows.iter().map(|r| r.step).collect::<Vec<_>>(),
        vec![0, 4, 8, 12, 15]
    );
    let (h0, dt) = (rows[0].total, scene.params.dt);
    let mut worst: f64 = 0.0;
    for r in &rows {
        assert_eq!(r.t, r.step as f64 * dt);
        // The running totals do not depend on the thinning.
        let f = &full[r.step];
        assert_eq!(
            (r.work_total, r.dissipation_total),
            (f.work_total, f.dissipation_total)
        );
        let sum_w: f64 = full[1..=r.step].iter().map(|x| x.external_work).sum();
        assert!((r.work_total - sum_w).abs() <= 1e-15 * sum_w.abs().max(1.0));
        let scale = h0.abs().max(r.total.abs()).max(r.work_total.abs());
        worst = worst.max((r.total - h0 - r.work_total + r.dissipation_total).abs() / scale);
    }
    assert!(rows.last().unwrap().work_total > 1e-3, "the load did work");
    assert!(rows.last().unwrap().dissipation_total > 0.0);
    // The default strategy on the CPU (monolithic) solves each step's identity to its
    // round-off floor: measured 2.4e-14 over the 15 steps (the staggered loop closes it to
    // outer_tol = 1e-10 relative: 1.6e-10).
    assert!(worst < 2e-13, "energy balance residual {worst:e}");
    let e = &res.summary.energy_balance;
    assert!(e.max_rel_residual < 1e-9, "{e:?}");
}

#[test]
fn summary_balances_momenta_against_the_applied_impulse() {
    let dir = tempfile::tempdir().unwrap();
    for scheme in ["em", "edmc2", "midpoint"] {
        let scene = pushed_frame(scheme, 3.0);
        let (res, _) = run(&scene, dir.path(), &RunOptions::default());
        let b = &res.summary.impulse_balance;
        assert!(!b.reactions);
        let applied = b
            .applied_impulse_l
            .iter()
            .map(|x| x * x)
            .sum::<f64>()
            .sqrt();
        assert!(applied > 0.1, "{scheme}: the load must push ({applied})");
        // Measured ≤ 1.6e-15 relative (EM, EDMC-2, mid-point): exact algebra.
        assert!(
            b.max_rel_residual_l < 1e-14 && b.max_rel_residual_j < 1e-14,
            "{scheme}: {b:?}"
        );
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert!(v["impulse_balance"]["max_rel_residual_j"].is_number());
    assert!(v.get("max_rel_dl").is_none(), "raw drift is not reported");
}

/// Reads a `.vtu` written with raw appended data: the XML header, and the arrays by name.
struct Vtu {
    xml: String,
    data: Vec<u8>,
}

impl Vtu {
    fn read(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap();
        let marker = b"<AppendedData encoding=\"raw\">";
        let at = bytes
            .windows(marker.len())
            .position(|w| w == marker)
            .expect("appended data");
        let underscore = at + bytes[at..].iter().position(|&b| b == b'_').unwrap();
        Self {
            xml: String::from_utf8(bytes[..at].to_vec()).unwrap(),
            data: bytes[underscore + 1..].to_vec(),
        }
    }
    fn attr(&self, tag_start: &str, attr: &str) -> String {
        let i = self
            .xml
            .find(tag_start)
            .unwrap_or_else(|| panic!("{tag_start}"));
        let tag = &self.xml[i..i + self.xml[i..].find('>').unwrap()];
        let j = tag.find(&format!("{attr}=\"")).unwrap() + attr.len() + 2;
        tag[j..j + tag[j..].find('"').unwrap()].to_string()
    }
    fn block(&self, name: &str) -> &[u8] {
        let off: usize = self
            .attr(&format!("Name=\"{name}\""), "offset")
            .parse()
            .unwrap();
        let len = u64::from_le_bytes(self.data[off..off + 8].try_into().unwrap()) as usize;
        &self.data[off + 8..off + 8 + len]
    }
    fn f64s(&self, name: &str) -> Vec<f64> {
        self.block(name)
            .chunks(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
    fn i64s(&self, name: &str) -> Vec<i64> {
        self.block(name)
            .chunks(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
}

#[test]
fn vtu_has_one_point_per_node_and_the_state() {
    let scene = parse_scene(builtin("mechanism"), "mechanism.toml").unwrap();
    let mut scene = scene;
    scene.params.t_end = 10.0 * scene.params.dt;
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        every: 5,
        vtk_every: Some(5),
        ..RunOptions::default()
    };
    let (_, sim) = run(&scene, dir.path(), &opts);
    let (model, st) = (sim.model(), sim.state());
    let vtu = Vtu::read(
        &dir.path()
            .join("vtk")
            .join(format!("{}_000010.vtu", scene.name)),
    );
    let (n, nl, ne) = (model.n_nodes(), model.links.len(), model.elements.len());
    assert!(nl > 0, "the mechanism has rigid links");
    let n_points: usize = vtu.attr("<Piece", "NumberOfPoints").parse().unwrap();
    assert_eq!(
        n_points,
        n + nl,
        "one point per node, plus one per link pivot"
    );
    let n_cells: usize = vtu.attr("<Piece", "NumberOfCells").parse().unwrap();
    assert_eq!(n_cells, ne + nl);
    let pts = vtu.f64s("Points");
    for a in 0..n {
        for c in 0..3 {
            assert_eq!(pts[3 * a + c], st.r[a][c]);
        }
    }
    // Element cells connect the element's own nodes: shared points, no duplicates.
    let conn = vtu.i64s("connectivity");
    for (e, el) in model.elements.iter().enumerate() {
        assert_eq!(
            [conn[2 * e], conn[2 * e + 1]],
            [el.nodes[0] as i64, el.nodes[1] as i64]
        );
    }
    assert_eq!(
        vtu.i64s("node_id")[..n],
        (0..n as i64).collect::<Vec<_>>()[..]
    );
    let disp = vtu.f64s("displacement");
    assert_eq!(disp[3], st.r[1][0] - model.nodes[1][0]);
    assert_eq!(vtu.f64s("strain_Gamma").len(), 3 * n_cells);
    let pvd = std::fs::read_to_string(dir.path().join("vtk").join(format!("{}.pvd", scene.name)))
        .unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 3, "steps 0, 5, 10");
}

#[test]
fn failed_run_ends_every_output_at_the_last_accepted_step() {
    // One Newton iteration per step cannot converge: the run fails early.
    let text = builtin("frame").replace("t_end = 10.0", "t_end = 10.0\nmax_iter = 2");
    let scene = parse_scene(&text, "stiff.toml").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        every: 1000,
        vtk_every: Some(1000),
        trajectory: Some(OutputTimes::Every(1000)),
        ..RunOptions::default()
    };
    let (res, sim) = run(&scene, dir.path(), &opts);
    let s = &res.summary;
    assert_eq!(s.status, cosserat::observe::record::RunStatus::Failed);
    let last = s.last_accepted.step;
    assert_eq!(last, s.steps);
    assert!(
        s.last_accepted.note.contains("failed"),
        "{}",
        s.last_accepted.note
    );
    let hist = read_history(&dir.path().join("history.csv")).unwrap();
    assert_eq!(hist.last().unwrap().step, last);
    let mut npz =
        NpzReader::new(std::fs::File::open(dir.path().join("trajectory.npz")).unwrap()).unwrap();
    let steps: Array1<i64> = npz.by_name("steps").unwrap();
    assert_eq!(*steps.last().unwrap(), last as i64);
    let pos: Array3<f64> = npz.by_name("positions").unwrap();
    assert_eq!(pos[[steps.len() - 1, 15, 2]], sim.state().r[15][2]);
    let vtu = dir
        .path()
        .join("vtk")
        .join(format!("{}_{last:06}.vtu", scene.name));
    assert!(vtu.exists(), "{} missing", vtu.display());
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(v["last_accepted"]["step"], last);
    assert!(v["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f.as_str().unwrap().starts_with("trajectory.npz")));
}

fn with_probes(probes: &str) -> Result<Scene, String> {
    let text = builtin("frame")
        .replace("t_end = 10.0", "t_end = 1.0")
        .replace("[integrator]", &format!("{probes}\n[integrator]"));
    parse_scene(&text, "probed.toml").map_err(|e| e.to_string())
}

#[test]
fn probes_csv_reads_back_every_step() {
    let scene = with_probes(
        r#"[[probe]]
name = "tip"
rod = "rod3"
node = -1

[[probe]]
rod = "rod2"
s = 4.0

[[probe]]
name = "corner"
at = [10, 10, 0]"#,
    )
    .unwrap();
    let tip = scene.probes[0].node;
    assert_eq!(scene.probes[1].name, "probe1");
    let dir = tempfile::tempdir().unwrap();
    // Thinned history: probes still come every step.
    let opts = RunOptions {
        every: 3,
        ..RunOptions::default()
    };
    let (_, sim) = run(&scene, dir.path(), &opts);
    let text = std::fs::read_to_string(dir.path().join("probes.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.len(), 2 + 3 * 12);
    assert_eq!(&header[..5], &["step", "t", "tip_x", "tip_y", "tip_z"]);
    assert!(header.contains(&"probe1_rz") && header.contains(&"corner_vx"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 6, "steps 0..=5");
    let dt = scene.params.dt;
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r[0], k as f64);
        assert_eq!(r[1], k as f64 * dt, "t = n·Δt exactly");
    }
    let (model, st) = (sim.model(), sim.state());
    let last = rows.last().unwrap();
    // Positions and velocities are written with round-trip precision: read back bit for
    // bit; the displacement is the same subtraction.
    for c in 0..3 {
        assert_eq!(last[2 + c], st.r[tip][c]);
        assert_eq!(last[5 + c], st.r[tip][c] - model.nodes[tip][c]);
        assert_eq!(last[11 + c], st.v[tip][c]);
    }
    // The rotation vector maps the tip's reference triad onto its current one.
    let rv = nalgebra::Vector3::new(last[8], last[9], last[10]);
    let rot = nalgebra::Rotation3::from_scaled_axis(rv);
    let e = model.elements.len() - 1;
    let err = (rot.matrix() * model.elements[e].ref_triad[1] - st.d[e][1])
        .abs()
        .max();
    eprintln!("probe rotation vector: triad reproduced to {err:.1e}");
    // Measured 8.1e-16.
    assert!(err < 8e-15, "rotation vector off by {err:e}");
    assert!(rv.norm() > 1e-3, "the tip turned");
}

#[test]
fn bad_probes_are_refused_naming_the_key() {
    for (probe, want) in [
        ("rod = \"rodX\"\nnode = 0", "probe[0].rod: no rod named `rodX`"),
        ("rod = \"rod1\"\nnode = 6", "probe[0].node: rod `rod1` has nodes 0..5"),
        (
            "rod = \"rod1\"\ns = 3.0",
            "probe[0].s: s = 3 is not at a node of rod `rod1` (length 10; nearest nodes at s = 2 and 4)",
        ),
        ("at = [10, 0, 0]\nrod = \"rod1\"", "give `at` or `rod`, not both"),
        ("at = [1, 0, 0]", "probe[0].at: (1, 0, 0) is not a node"),
        ("rod = \"rod1\"", "required key missing (give `node` or `s` with `rod`)"),
        ("name = \"a,b\"\nat = [0, 0, 0]", "probe[0].name: must be a non-empty name"),
        ("at = [0, 0, 0]\ncolour = 1", "unknown field `colour`"),
    ] {
        let e = with_probes(&format!("[[probe]]\n{probe}")).unwrap_err();
        assert!(e.contains(want), "{probe}: {e}");
    }
    let e = with_probes(
        "[[probe]]\nname = \"p\"\nat = [0, 0, 0]\n[[probe]]\nname = \"p\"\nat = [10, 0, 0]",
    )
    .unwrap_err();
    assert!(e.contains("probe[1].name: duplicate probe name `p`"), "{e}");
}

#[test]
fn set_overrides_scene_keys_with_sweep_validation() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let cosserat = || std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"));
    let st = cosserat()
        .args([
            "run",
            "frame",
            "--set",
            "integrator.t_end=0.4",
            "--set",
            "rod.rod1.elements=8",
            "--set",
            "rod[2].elements=2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["elements"], 8 + 5 + 2);
    assert_eq!(s["steps"], 2);
    for (set, want) in [
        (
            "rod.rodX.elements=3",
            "no entry named `rodX` here (named entries: rod1, rod2, rod3)",
        ),
        ("integrator.dt=-1", "integrator.dt: must be > 0 (got -1)"),
        ("integrator.alfa=1", "integrator.alfa: unknown field `alfa`"),
        ("integrator.dt=abc", "integrator.dt: `abc` is not a number"),
        ("rod[7].elements=3", "index 7 out of range"),
    ] {
        let st = cosserat()
            .args(["run", "frame", "--set", set, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(st.status.code(), Some(2), "{set}");
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(err.contains(want), "{set}: {err}");
    }
}

#[test]
fn check_reports_unknowns_frequency_and_costs() {
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["check", "frame"])
        .output()
        .unwrap();
    assert!(st.status.success());
    let text = String::from_utf8_lossy(&st.stdout);
    for want in [
        "nodes: 16",
        "Newton unknowns per step: 144",
        "mass 7.500000e1, centre of mass (8.333333, 5.000000, 1.666667)",
        "EDMC-2 α_Γv = 0.5",
        // The frame's highest mode is ≈ 310 rad/s (shear–rotation); the estimate 315.
        "highest frequency (estimate): 3.1489e2 rad/s",
        "ω_max·Δt = 62.977",
        "time estimate:",
        "for 50 steps",
    ] {
        assert!(text.contains(want), "missing `{want}` in\n{text}");
    }
}

#[test]
fn animation_gif_has_one_moving_frame_per_sample() {
    let mut scene = parse_scene(builtin("frame"), "frame.toml").unwrap();
    scene.params.t_end = 4.0;
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        animate_every: Some(5),
        ..RunOptions::default()
    };
    run(&scene, dir.path(), &opts);
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::RGBA);
    let file = std::fs::File::open(dir.path().join("animation.gif")).unwrap();
    let mut dec = options.read_info(file).unwrap();
    let mut frames: Vec<Vec<u8>> = Vec::new();
    while let Some(f) = dec.read_next_frame().unwrap() {
        frames.push(f.buffer.to_vec());
    }
    assert_eq!(frames.len(), 5, "steps 0, 5, 10, 15, 20");
    // The rods are drawn in the first colour of the snapshot palette (31, 119, 180).
    let rod_pixels = |f: &[u8]| {
        f.chunks(4)
            .filter(|p| {
                (p[0] as i32 - 31).abs() < 8
                    && (p[1] as i32 - 119).abs() < 8
                    && (p[2] as i32 - 180).abs() < 8
            })
            .count()
    };
    for (k, f) in frames.iter().enumerate() {
        assert!(
            rod_pixels(f) > 200,
            "frame {k}: {} rod pixels",
            rod_pixels(f)
        );
    }
    for k in 1..frames.len() {
        let changed = frames[k]
            .chunks(4)
            .zip(frames[k - 1].chunks(4))
            .filter(|(a, b)| a != b)
            .count();
        assert!(changed > 500, "frame {k} equals frame {}", k - 1);
    }
}

/// The cells of one CSV record per RFC 4180 (quoted cells may hold `,`, `""`, CR, LF),
/// and the rest of the text after it.
fn csv_record(text: &str) -> (Vec<String>, &str) {
    let (mut cells, mut cell, mut quoted, mut chars) = (
        Vec::new(),
        String::new(),
        false,
        text.char_indices().peekable(),
    );
    while let Some((i, c)) = chars.next() {
        match (quoted, c) {
            (true, '"') if chars.peek().map(|p| p.1) == Some('"') => {
                chars.next();
                cell.push('"');
            }
            (true, '"') => quoted = false,
            (true, c) => cell.push(c),
            (false, '"') if cell.is_empty() => quoted = true,
            (false, ',') => cells.push(std::mem::take(&mut cell)),
            // A line break ends the record: LF, CRLF or a bare CR (as Python's csv reads).
            (false, '\n' | '\r') => {
                cells.push(cell);
                let skip = if c == '\r' && text[i + 1..].starts_with('\n') {
                    2
                } else {
                    1
                };
                return (cells, &text[i + skip..]);
            }
            (false, c) => cell.push(c),
        }
    }
    cells.push(cell);
    (cells, "")
}

#[test]
fn probe_names_with_control_characters_stay_one_csv_cell() {
    // A scene file cannot name a probe so (the key is refused)...
    let e = with_probes("[[probe]]\nname = \"a\\rb\"\nat = [10, 10, 0]").unwrap_err();
    assert!(e.contains("probe[0].name"), "{e}");
    // ...but a scene built in code can: the writer quotes every text cell.
    let mut scene = with_probes("[[probe]]\nname = \"ab\"\nat = [10, 10, 0]").unwrap();
    scene.probes[0].name = "a\rb".into();
    let dir = tempfile::tempdir().unwrap();
    run(&scene, dir.path(), &RunOptions::default());
    let text = std::fs::read_to_string(dir.path().join("probes.csv")).unwrap();
    let (header, mut rest) = csv_record(&text);
    assert_eq!(header.len(), 2 + 12, "{header:?}");
    assert_eq!(&header[..3], &["step", "t", "a\rb_x"]);
    assert_eq!(header[13], "a\rb_vz");
    let mut rows = 0;
    while !rest.is_empty() {
        let (row, r) = csv_record(rest);
        assert_eq!(row.len(), header.len());
        assert_eq!(row[0].parse::<usize>().unwrap(), rows);
        (rest, rows) = (r, rows + 1);
    }
    assert_eq!(rows, scene.params.n_steps() + 1);
}

#[test]
fn probe_rotation_vectors_are_accurate_from_tiny_to_large_angles() {
    use cosserat::observe::probe::{node_director_ends, probe_values};
    let scene = parse_scene(builtin("cantilever"), "c.toml").unwrap();
    let sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
    let model = sim.model();
    let (ends, _) = node_director_ends(model);
    let tip = model.n_nodes() - 1;
    let (e, l) = ends[tip];
    let n = nalgebra::Vector3::new(0.3, -0.5, 0.81).normalize();
    for theta in [1e-12, 1e-10, 1e-8, 1e-7, 1e-5, 1e-3, 0.1, 1.0, 2.0, 3.0] {
        let rot = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(n), theta);
        let mut st = sim.state().clone();
        st.d[e][l] = rot.matrix() * model.elements[e].ref_triad[l];
        let v = probe_values(model, &st, tip, ends[tip]).rotation;
        let err = (v - n * theta).norm() / theta;
        assert!(err < 1e-12, "θ = {theta:e}: relative error {err:e}");
    }
}

#[test]
fn pvd_is_replaced_whole_never_rewritten_in_place() {
    use cosserat::output::VtkSeries;
    let scene = parse_scene(builtin("cantilever"), "c.toml").unwrap();
    let sim = Simulation::new(scene.model.clone(), scene.params).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut vtk = VtkSeries::new(dir.path(), "c").unwrap();
    let frames = 64; // the collection is rewritten every 64 frames
    for k in 0..frames {
        vtk.write_frame(&sim, k, k as f64).unwrap();
    }
    // A reader holding the collection written after `frames` frames (a hard link to it)
    // keeps that whole file when the collection is rewritten.
    let held = dir.path().join("held.pvd");
    std::fs::hard_link(vtk.pvd_path(), &held).unwrap();
    vtk.write_frame(&sim, frames, frames as f64).unwrap();
    vtk.finish().unwrap();
    let count = |p: &Path| {
        std::fs::read_to_string(p)
            .unwrap()
            .matches("<DataSet ")
            .count()
    };
    assert_eq!(
        count(&held),
        frames,
        "the old collection was rewritten in place"
    );
    assert_eq!(count(&vtk.pvd_path()), frames + 1);
    assert!(!dir.path().join("c.pvd.tmp").exists());
}
