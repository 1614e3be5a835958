//! Programmatic models for the physics tests (independent of the scene parser).
#![allow(dead_code)]

use cosserat::model::{Element, ElementProps, Mat3, Model, RodInfo, Support, Vec3};
use nalgebra::{Matrix2, Matrix3};

/// Section/material constants for tests: E, ν, ρ, A, I (I11 = I22), J.
pub fn props(e: f64, nu: f64, rho: f64, a: f64, i: f64, j: f64, h: f64) -> ElementProps {
    let g = e / (2.0 * (1.0 + nu));
    ElementProps {
        h,
        a_rho: rho * a,
        i_rho: Matrix2::new(rho * i, 0.0, 0.0, rho * i),
        c_gamma: Vec3::new(g * a, g * a, e * a),
        c_omega: Matrix3::new(e * i, 0.0, 0.0, 0.0, e * i, 0.0, 0.0, 0.0, g * j),
        damping: 0.0,
        drag: 0.0,
    }
}

/// An anisotropic section for kernel tests: area `a`, second moments `i1`, `1.3 i1` with
/// product `i12`, shear areas 0.4 and 0.38 of `a`, torsion 0.8 `i1`; modulus `e`, density
/// `rho`, length `h`, Kelvin–Voigt time `damping`.
pub fn anisotropic_props(
    h: f64,
    a: f64,
    i1: f64,
    i12: f64,
    e: f64,
    rho: f64,
    damping: f64,
) -> ElementProps {
    ElementProps {
        h,
        a_rho: rho * a,
        i_rho: Matrix2::new(rho * i1, rho * i12, rho * i12, rho * 1.3 * i1),
        c_gamma: Vec3::new(0.4 * e * a, 0.38 * e * a, e * a),
        c_omega: Mat3::new(
            e * i1,
            e * i12,
            0.0,
            e * i12,
            1.3 * e * i1,
            0.0,
            0.0,
            0.0,
            0.8 * e * i1,
        ),
        damping,
        drag: 0.0,
    }
}

/// Triad with d3 along `t`, d1 from `d1` projected.
pub fn triad(t: Vec3, d1: Vec3) -> Mat3 {
    let d3 = t.normalize();
    let d1 = (d1 - d3 * d3.dot(&d1)).normalize();
    let d2 = d3.cross(&d1);
    Mat3::from_columns(&[d1, d2, d3])
}

/// A model from polylines (each (points, elements per segment, d1)), merging
/// coincident nodes; material (E, ν, ρ, A, I, J).
pub fn polylines(rods: &[(Vec<Vec3>, usize, Vec3)], mat: (f64, f64, f64, f64, f64, f64)) -> Model {
    let mut nodes: Vec<Vec3> = Vec::new();
    let find = |x: Vec3, nodes: &mut Vec<Vec3>| -> usize {
        if let Some(k) = nodes.iter().position(|y| (y - x).norm() < 1e-9) {
            k
        } else {
            nodes.push(x);
            nodes.len() - 1
        }
    };
    let mut elements = Vec::new();
    let mut infos = Vec::new();
    for (ri, (pts, ne, d1)) in rods.iter().enumerate() {
        let start = elements.len();
        for s in 0..pts.len() - 1 {
            let (p0, p1) = (pts[s], pts[s + 1]);
            let tri = triad(p1 - p0, *d1);
            for k in 0..*ne {
                let xa = p0 + (p1 - p0) * (k as f64 / *ne as f64);
                let xb = p0 + (p1 - p0) * ((k + 1) as f64 / *ne as f64);
                let a = find(xa, &mut nodes);
                let b = find(xb, &mut nodes);
                let h = (xb - xa).norm();
                let (e, nu, rho, area, i, j) = mat;
                elements.push(Element {
                    nodes: [a, b],
                    ref_triad: [tri, tri],
                    props: props(e, nu, rho, area, i, j, h),
                    rod: ri,
                });
            }
        }
        infos.push(RodInfo {
            name: format!("rod{ri}"),
            elements: start..elements.len(),
            curvature_measure: Default::default(),
        });
    }
    let n = nodes.len();
    Model {
        nodes,
        elements,
        supports: vec![Support::default(); n],
        point_mass: vec![0.0; n],
        loads: vec![],
        gravity: Vec3::zeros(),
        velocity0: vec![Vec3::zeros(); n],
        omega0: vec![Vec3::zeros(); n],
        rods: infos,
        links: vec![],
        planar: None,
        shape: Default::default(),
        line_loads: vec![],
        drives: vec![],
        slides: vec![],
        obstacles: vec![],
        rod_contacts: vec![],
    }
}

/// The paper's free-flying frame (DESIGN §6.1, staircase reconstruction).
pub fn frame() -> Model {
    let l = 10.0;
    let (a, b, c, d) = (
        Vec3::zeros(),
        Vec3::new(l, 0.0, 0.0),
        Vec3::new(l, l, 0.0),
        Vec3::new(l, l, l),
    );
    let mut m = polylines(
        &[
            (vec![a, b], 5, Vec3::new(0.0, 1.0, 0.0)),
            (vec![b, c], 5, Vec3::new(0.0, 0.0, 1.0)),
            (vec![c, d], 5, Vec3::new(1.0, 0.0, 0.0)),
        ],
        (5e5, 0.3, 500.0, 0.005, 2e-5, 4e-5),
    );
    let idx = |m: &Model, x: Vec3| m.nodes.iter().position(|y| (y - x).norm() < 1e-9).unwrap();
    let (ia, ib, ic) = (idx(&m, a), idx(&m, b), idx(&m, c));
    m.velocity0[ia] = Vec3::new(0.0, 0.0, -1.0);
    m.velocity0[ib] = Vec3::new(0.0, 0.0, 2.0);
    m.velocity0[ic] = Vec3::new(0.0, -1.0, 0.0);
    m
}

/// The GPU executor, or `None` (printing `skipped: no adapter`) when no usable adapter
/// exists and `COSSERAT_REQUIRE_GPU` is not set; with it set, a missing adapter panics.
pub fn gpu() -> Option<cosserat::batch::Executor> {
    use cosserat::batch::{BackendChoice, Executor};
    match Executor::resolve(BackendChoice::Gpu, None) {
        Ok((e, _)) => Some(e),
        Err(e) if !cosserat::gpu::gpu_required() => {
            println!("skipped: no adapter ({e})");
            None
        }
        Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no usable adapter: {e}"),
    }
}

/// Decodes a PNG into (width, height, RGB bytes) (chart tests).
pub fn image_rgb(path: &std::path::Path) -> (usize, usize, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    let rgb: Vec<u8> = buf[..info.buffer_size()]
        .chunks(ch)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    (info.width as usize, info.height as usize, rgb)
}

/// Runs `c` with its output captured; a run past `limit` is killed and fails the test (a
/// hang fails the case instead of stalling the suite). `address_space`: the most bytes of
/// address space the process may map (`ulimit -v`), so that an allocation no estimate
/// foresaw aborts it instead of passing.
pub fn run_limited(
    mut c: std::process::Command,
    address_space: Option<u64>,
    limit: std::time::Duration,
) -> std::process::Output {
    use std::os::unix::process::CommandExt;
    use std::process::Stdio;
    if let Some(bytes) = address_space {
        // SAFETY: setrlimit is async-signal-safe; the closure allocates nothing.
        unsafe {
            c.pre_exec(move || {
                let r = libc::rlimit {
                    rlim_cur: bytes as libc::rlim_t,
                    rlim_max: bytes as libc::rlim_t,
                };
                if libc::setrlimit(libc::RLIMIT_AS, &r) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            panic!("hangs: {c:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// Runs `sim` to its end, keeping every step's record.
pub fn run_recording(
    sim: &mut cosserat::integrator::Simulation,
) -> (
    cosserat::integrator::run::RunOutcome,
    Vec<cosserat::observe::record::StepRecord>,
) {
    use cosserat::integrator::Simulation;
    use cosserat::observe::record::StepRecord;
    let mut recs = Vec::new();
    let out = cosserat::integrator::run::run(sim, 1, |r: &StepRecord, _: &Simulation| {
        recs.push(r.clone());
        Ok::<(), ()>(())
    })
    .unwrap();
    (out, recs)
}

/// Every file below `dir`, relative to it, sorted.
pub fn files_below(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// Rows of a sweep's `members.csv` by member, without the wall time (column 7).
pub fn member_rows(out: &std::path::Path) -> Vec<(usize, String)> {
    let csv = std::fs::read_to_string(out.join("members.csv")).unwrap();
    let mut v: Vec<(usize, String)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(7);
            (f[0].parse().unwrap(), f.join(","))
        })
        .collect();
    v.sort();
    v
}

/// Scene text (TOML) built from the tables the scene tests repeat. Numbers are written
/// with `Display`, so a literal given as a string stays that literal.
pub mod scene_text {
    use std::fmt::Display;

    /// `[material.NAME]` with `E`, `nu` and `density` (more keys may follow on the next
    /// lines).
    pub fn material(
        name: &str,
        e: impl Display,
        nu: impl Display,
        density: impl Display,
    ) -> String {
        format!("[material.{name}]\nE = {e}\nnu = {nu}\ndensity = {density}\n")
    }

    /// `[section.NAME]` with `A`, `I11 = I22 = i` and `J`.
    pub fn section(name: &str, a: impl Display, i: impl Display, j: impl Display) -> String {
        format!("[section.{name}]\nA = {a}\nI11 = {i}\nI22 = {i}\nJ = {j}\n")
    }

    /// `[section.NAME]` of a solid round section of radius `r`: `A = π r²`,
    /// `I11 = I22 = A r²/4`, `J = 2 I11`.
    pub fn round_section(name: &str, r: f64) -> String {
        let a = std::f64::consts::PI * r * r;
        let i = a * r * r / 4.0;
        section(name, a, i, 2.0 * i)
    }

    /// A `[[rod]]` named `name` of material `m` and section `s` through `points` (a TOML
    /// array), `elements` elements, transverse `d1` (a TOML array).
    pub fn rod(name: &str, points: &str, elements: impl Display, d1: &str) -> String {
        format!(
            "[[rod]]\nname = \"{name}\"\nmaterial = \"m\"\nsection = \"s\"\npoints = {points}\nelements = {elements}\nd1 = {d1}\n"
        )
    }

    /// `[material.soft]` (E = 1e6, ν = 0.5, ρ = 1000) and `[section.round]` (solid, radius
    /// 2 cm).
    pub fn soft_round() -> String {
        material("soft", "1e6", "0.5", "1000")
            + "\n"
            + &section(
                "round",
                "1.2566370614359173e-3",
                "1.2566370614359173e-7",
                "2.5132741228718346e-7",
            )
    }

    /// Scene `name`: the tables `material` and `section` (named `m` and `s`), a 1 m rod
    /// `rod` along e1 (d1 = e3) of `elements` elements, then the tables `extra`, then
    /// `[integrator]` with the keys `integrator`.
    pub fn rod_scene(
        name: &str,
        material: &str,
        section: &str,
        elements: usize,
        extra: &str,
        integrator: &str,
    ) -> String {
        format!(
            "name = \"{name}\"\n{material}\n{section}\n{}\n{extra}\n\n[integrator]\n{integrator}\n",
            rod("rod", "[[0, 0, 0], [1, 0, 0]]", elements, "[0, 0, 1]"),
        )
    }

    /// [`rod_scene`] of material `m` (E = 1e6, ν = 0.5, ρ = 1000) and section `s` (solid
    /// round, radius 0.02).
    pub fn straight_rod(name: &str, elements: usize, extra: &str, integrator: &str) -> String {
        rod_scene(
            name,
            &material("m", 1e6, 0.5, 1000.0),
            &round_section("s", 0.02),
            elements,
            extra,
            integrator,
        )
    }
}

/// A xorshift generator for reproducible random test inputs, uniform on [0, 1).
pub struct Rng(pub u64);

impl Rng {
    /// The next number, uniform on [0, 1).
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Largest difference of `b` from `a`, relative to the largest |a|.
pub fn rel(a: impl Iterator<Item = f64> + Clone, b: impl Iterator<Item = f64>) -> f64 {
    let scale = a.clone().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

// ---- GPU batch parity (tests/resident_step.rs, tests/whole_step.rs) ----

use cosserat::batch::{
    run_members, BatchOptions, BatchStats, Executor, Member, MemberResult, SolveMode,
};
use cosserat::integrator::{NewtonVariant, Scheme, Strategy};
use cosserat::model::NodalLoad;
use cosserat::table::TimeTable;

/// The bound on final states against the CPU path with the same strategy and
/// Newton variant.
pub const STATE_RTOL: f64 = 1e-10;

/// The built-in frame as one batch member, run for `steps` of its Δt; `set` adjusts its
/// parameters (scheme, strategy) before the member is made.
pub fn frame_member(
    steps: f64,
    set: impl FnOnce(&mut cosserat::integrator::IntegratorParams),
) -> Member {
    let text = cosserat::scene::builtin_scenes()
        .iter()
        .find(|b| b.name == "frame")
        .expect("the built-in frame scene exists")
        .toml;
    let scene = cosserat::scene::parse_scene(text, "builtin:frame").unwrap();
    let mut params = scene.params;
    params.t_end = steps * params.dt;
    set(&mut params);
    Member {
        model: scene.model,
        params,
    }
}

/// How [`mix`] draws its 14 members.
#[derive(Clone, Copy, Debug)]
pub struct Mix {
    /// The random stream's seed (kicks, stiffnesses, time steps, tip loads).
    pub seed: u64,
    /// Members 0..9 carry a random tip force and moment ramping up over the run.
    pub loads: bool,
    /// Member 10 may fall back to the monolithic strategy (`false`: it fails on its
    /// staggered cap).
    pub fallback: bool,
    /// Every member's scheme but 12's (`None`: the bench's EDMC-2).
    pub scheme: Option<Scheme>,
    /// Every member's strategy.
    pub strategy: Strategy,
}

/// 14 cantilevers of 10 elements with random kicks, stiffnesses, time steps and, with
/// [`Mix::loads`], ramped tip loads on 0..9; 9 ends after 3 steps, 10's staggered cap is
/// too low for its kick (it needs the monolithic fallback), 11 fails on its Newton cap, 12
/// is generalized-α (CPU kernel), 13 carries a follower line load (the element kernel's)
/// and its clamp is carried and turned (host solve: the device solve does not move
/// supports); 5 has a tip point mass (on the device, the element kernel's).
pub fn mix(o: Mix) -> Vec<Member> {
    let mut ms = cosserat::batch::bench_members(14, 10, 6).unwrap();
    let mut rng = Rng(o.seed);
    for (i, m) in ms.iter_mut().enumerate() {
        if let Some(s) = o.scheme {
            m.params.scheme = s;
        }
        m.params.strategy = o.strategy;
        if o.loads && i < 9 {
            let tip = m.model.n_nodes() - 1;
            let mut v = || Vec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
            let (force, moment) = (2.0 * v(), 0.5 * v());
            m.model.loads.push(NodalLoad {
                node: tip,
                force,
                moment,
                table: TimeTable {
                    times: vec![0.0, 0.1],
                    values: vec![0.2, 1.0],
                },
            });
        }
        let kick = 0.5 + 1.5 * rng.next();
        m.model.velocity0.iter_mut().for_each(|v| *v *= kick);
        let stiff = 0.5 + rng.next();
        for e in m.model.elements.iter_mut() {
            e.props.c_gamma *= stiff;
            e.props.c_omega *= stiff;
        }
        m.params.dt *= 0.5 + rng.next();
        m.params.t_end = 6.0 * m.params.dt;
        match i {
            9 => m.params.t_end = 3.0 * m.params.dt,
            10 => {
                m.params.max_outer = 3;
                m.params.fallback = o.fallback;
                m.model.velocity0.iter_mut().for_each(|v| *v *= 4.0);
            }
            11 => {
                m.params.max_iter = 2;
                m.params.fallback = false;
            }
            5 => {
                let tip = m.model.point_mass.len() - 1;
                m.model.point_mass[tip] = 0.05;
            }

            12 => m.params.scheme = Scheme::GenAlpha { rho_inf: 0.8 },
            13 => {
                m.model.line_loads.push(cosserat::model::LineLoad {
                    elements: (0..m.model.elements.len()).collect(),
                    force: Vec3::new(0.0, 0.2, 0.1),
                    moment: Vec3::zeros(),
                    follower: true,
                    table: TimeTable {
                        times: vec![0.0],
                        values: vec![1.0],
                    },
                });
                // The clamp carried sideways and turned (smoothly, from rest).
                let t1 = m.params.t_end;
                m.model.drives.push(cosserat::model::SupportDrive {
                    node: 0,
                    displacement: Vec3::new(0.0, 0.02, 0.0),
                    rotation: Vec3::new(0.0, 0.0, 0.05),
                    table: TimeTable {
                        times: vec![0.0, t1],
                        values: vec![0.0, 1.0],
                    },
                    ramp: cosserat::table::Ramp::Smooth,
                });
            }
            _ => {}
        }
    }
    ms
}

/// [`mix`] with tip loads and the fallback (EDMC-2 unless `scheme` says otherwise).
pub fn batch_mix(scheme: Option<Scheme>, strategy: Strategy) -> Vec<Member> {
    mix(Mix {
        seed: 0x5e51_de7f,
        loads: true,
        fallback: true,
        scheme,
        strategy,
    })
}

/// Runs `ms` on `exec` with `newton`, `solve` and `workers` slots ([`run_batch_with`]).
pub fn run_batch(
    ms: &[Member],
    exec: &Executor,
    newton: NewtonVariant,
    solve: SolveMode,
    workers: usize,
) -> (Vec<MemberResult>, BatchStats) {
    run_batch_with(
        ms,
        exec,
        BatchOptions {
            workers,
            newton: Some(newton),
            solve,
            ..Default::default()
        },
    )
}

/// Runs `ms` with `opts` (keeping every member's history and final state), each result in
/// its member's place; asserts each member reports exactly once.
pub fn run_batch_with(
    ms: &[Member],
    exec: &Executor,
    opts: BatchOptions,
) -> (Vec<MemberResult>, BatchStats) {
    let mut out: Vec<Option<MemberResult>> = vec![None; ms.len()];
    let stats = run_members(
        ms,
        exec,
        BatchOptions {
            keep_history: true,
            keep_state: true,
            ..opts
        },
        |r| {
            let i = r.index;
            assert!(out[i].is_none(), "member {i} reported twice");
            out[i] = Some(r);
        },
    )
    .unwrap();
    let out = out
        .into_iter()
        .enumerate()
        .map(|(i, r)| r.unwrap_or_else(|| panic!("member {i} never reported")))
        .collect();
    (out, stats)
}

/// The largest relative difference of final positions, directors, velocities and energy
/// histories, after asserting equal status, reason, steps and Newton iterations.
pub fn compare_results(tag: &str, a: &MemberResult, b: &MemberResult) -> f64 {
    assert_eq!(
        a.outcome.status, b.outcome.status,
        "{tag}: {:?}",
        b.outcome.reason
    );
    assert_eq!(a.outcome.reason, b.outcome.reason, "{tag}");
    assert_eq!(a.outcome.steps, b.outcome.steps, "{tag}");
    assert_eq!(
        a.outcome.newton_iters_total, b.outcome.newton_iters_total,
        "{tag}"
    );
    assert_eq!(a.outcome.fallback_steps, b.outcome.fallback_steps, "{tag}");
    assert_eq!(a.history.len(), b.history.len(), "{tag}");
    let (sa, sb) = (a.state.as_ref().unwrap(), b.state.as_ref().unwrap());
    assert_eq!(sa.t, sb.t, "{tag}");
    [
        rel(
            sa.r.iter().flat_map(|x| x.iter().copied()),
            sb.r.iter().flat_map(|x| x.iter().copied()),
        ),
        rel(
            sa.d.iter()
                .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
            sb.d.iter()
                .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
        ),
        rel(
            sa.v.iter().flat_map(|x| x.iter().copied()),
            sb.v.iter().flat_map(|x| x.iter().copied()),
        ),
        rel(
            a.history.iter().map(|h| h.total),
            b.history.iter().map(|h| h.total),
        ),
    ]
    .into_iter()
    .fold(0.0, f64::max)
}
