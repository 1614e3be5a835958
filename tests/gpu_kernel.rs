//! GPU element kernel ≡ CPU element kernel.
//!
//! On seeded random elements (random sections, distorted triads, velocities, increments,
//! every scheme, clamped/free ends, with and without translational dissipation and
//! Kelvin–Voigt damping, drag or point masses), the WGSL
//! kernel (`shaders/element.wgsl`: residual pass, then the tangent pass by 9×9 node
//! blocks) returns the residual, row scales, tangent and — in consistent mode — the EDMC
//! local scalars of [`cosserat::element`] to `KERNEL_PARITY_RTOL` (f64; the scalars, which
//! come out of a fixed-point iteration, to `SCALARS_RTOL`), measured relative to the
//! largest entry of each quantity. A residual-only dispatch returns the same residual as
//! one with the tangent. The f32 fallback is measured on the same elements and must stay
//! within `F32_RTOL` (docs/gpu.md, "Kernels"). A software adapter says it is one, and the
//! pipeline cache lands in the folder it is given, as one complete file per adapter and
//! shader revision that a second context reads back. Without an adapter the GPU tests print
//! `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU` is set, in which case they fail.

mod common;

use cosserat::element::drag::add_drag_rows;
use cosserat::element::follower::add_follower_rows;
use cosserat::element::point_mass::add_point_mass_rows;
use cosserat::element::scalar_gradient::{residual_scalar_derivatives, scalar_gradient};
use cosserat::element::strain::Config;
use cosserat::element::{
    consistent_scalars, consistent_scalars_near, kinematics, kinematics_at, monolithic_correction,
    residual_tangent, strains6, ElemVec, ElementData, ElementEval, ElementState, FrozenScalars,
    Increment, StepConsts, NDOF,
};
use cosserat::gpu::kernel::{KernelMode, ELEMENT_WGSL};
use cosserat::gpu::{gpu_required, layout, ElementKernel, GpuContext, Precision};
use cosserat::integrator::Scheme;
use cosserat::math::cay;
use cosserat::model::{Mat3, Vec3};
use nalgebra::{SVector, Vector6};

/// f64 parity of residual, scales and tangent: measured ≤ 5.8e-16 on lavapipe (the same
/// operations in the same order; the difference is the compilers' contractions).
const KERNEL_PARITY_RTOL: f64 = 5e-15;
/// f64 parity of the consistent EDMC scalars: measured 7.6e-15 (the fixed-point
/// iteration on c_ν amplifies round-off).
const SCALARS_RTOL: f64 = 5e-14;
/// f32 fallback bound: measured 3.1e-6 (residual and scales), 2.7e-7 (tangent).
const F32_RTOL: f64 = 3e-5;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn sym(&mut self, s: f64) -> f64 {
        s * (2.0 * self.next() - 1.0)
    }
    fn v3(&mut self, s: f64) -> Vec3 {
        Vec3::new(self.sym(s), self.sym(s), self.sym(s))
    }
}

#[derive(Clone)]
struct Case {
    data: ElementData,
    st: ElementState,
    eps_n: Vector6<f64>,
    inc: Increment,
    s: FrozenScalars,
    k: StepConsts,
    trans: bool,
    /// Point masses carried by the two ends.
    pm: [f64; 2],
    /// Follower line loads: force and moment per unit length in the director frame.
    fol: [f64; 6],
}

fn case(rng: &mut Rng, idx: usize) -> Case {
    let h = 0.2 + rng.next();
    let a = 1e-3 + 1e-2 * rng.next();
    let i1 = 1e-6 + 1e-5 * rng.next();
    let i12 = 0.2 * i1 * rng.sym(1.0);
    let e = 1e5 + 1e6 * rng.next();
    let rho = 100.0 + 1000.0 * rng.next();
    let props = common::anisotropic_props(h, a, i1, i12, e, rho, 0.0);
    let tri0 = cay(&rng.v3(1.0));
    let r0 = rng.v3(1.0);
    let r1 = r0 + tri0.column(2) * h;
    let ref_cfg = Config {
        r: [r0, r1],
        d: [tri0, tri0],
    };
    let rot_free = match idx % 4 {
        0 => [true, true],
        1 => [false, true],
        2 => [true, false],
        _ => [true, true],
    };
    let mut data = ElementData {
        eps0: strains6(&ref_cfg, h),
        props,
        rot_free,
        measure: Default::default(),
    };
    // Current state: moved, rotated and slightly non-orthonormal triads.
    let distort = |rng: &mut Rng| Mat3::identity() + Mat3::from_fn(|_, _| rng.sym(1e-3));
    let d0 = cay(&rng.v3(0.3)) * tri0 * distort(rng);
    let d1 = cay(&rng.v3(0.3)) * tri0 * distort(rng);
    let cfg = Config {
        r: [r0 + rng.v3(0.05), r1 + rng.v3(0.05)],
        d: [d0, d1],
    };
    let vd = std::array::from_fn(|l| {
        std::array::from_fn(|_| {
            if rot_free[l] {
                rng.v3(0.5)
            } else {
                Vec3::zeros()
            }
        })
    });
    let st = ElementState {
        cfg,
        v: [rng.v3(1.0), rng.v3(1.0)],
        vd,
    };
    let eps_n = strains6(&cfg, h);
    let dt = 0.01 + 0.2 * rng.next();
    // Every fifth case with Kelvin–Voigt damping (its 2η/Δt adds to both β: in the
    // consistent scalars, the residual and the dissipation).
    if idx % 5 == 3 {
        data.props.damping = 0.3 * dt;
    }
    // Every seventh case with drag (rows, tangent and row scales of the translations).
    if idx % 7 == 2 {
        data.props.drag = 10.0 * a * rho * rng.next();
    }
    let scheme = match idx % 3 {
        0 => Scheme::Em,
        1 => Scheme::Edmc1 {
            chi_gamma: rng.next(),
            chi_omega: rng.next(),
            chi_v: rng.next(),
            chi_nu: if idx.is_multiple_of(2) {
                rng.next()
            } else {
                0.0
            },
        },
        _ => Scheme::Edmc2 {
            alpha_gv: rng.next(),
            alpha_gn: if idx.is_multiple_of(2) {
                rng.next()
            } else {
                0.0
            },
            alpha_ov: rng.next(),
            alpha_on: rng.next(),
        },
    };
    let trans = scheme.translational_dissipation();
    let th = |rng: &mut Rng, free: bool| if free { rng.v3(0.2) } else { Vec3::zeros() };
    let inc = Increment {
        u: [rng.v3(0.05), rng.v3(0.05)],
        theta: [th(rng, rot_free[0]), th(rng, rot_free[1])],
        g: if trans {
            [rng.v3(0.1), rng.v3(0.1)]
        } else {
            [Vec3::zeros(); 2]
        },
    };
    let s = if scheme.is_dissipative() {
        FrozenScalars {
            beta_gamma: rng.next(),
            beta_omega: rng.next(),
            c_v: 0.3 * rng.next(),
            c_nu: if scheme.director_dissipation() {
                0.3 * rng.next()
            } else {
                0.0
            },
        }
    } else {
        FrozenScalars::default()
    };
    // Every sixth case with point masses on one end or both (inertia rows, tangent, and
    // the translational dissipation rows where the scheme has them).
    let mass = a * rho * h;
    let pm = match idx % 6 {
        // (EM: no translational dissipation rows. A fixed value: another draw here would
        // move every later case's numbers.)
        3 => [0.0, 0.6 * mass],
        4 => [mass * rng.next(), 0.0],
        5 if idx % 12 == 11 => [mass * rng.next(), 2.0 * mass * rng.next()],
        _ => [0.0; 2],
    };
    // Every fifth case with a follower line load (rows over the ends' mid-step directors,
    // their θ-tangent); derived from the case's own numbers (no further draw).
    let fol = if idx % 5 == 2 {
        let w = a * rho * 9.81 * (1.0 + (idx % 7) as f64);
        [w, -0.5 * w, 0.3 * w, 0.1 * w * h, 0.0, -0.2 * w * h]
    } else {
        [0.0; 6]
    };
    Case {
        data,
        st,
        eps_n,
        inc,
        s,
        k: StepConsts { dt, scheme },
        trans,
        pm,
        fol,
    }
}

fn context() -> Option<GpuContext> {
    match GpuContext::new(None) {
        Ok(c) => Some(c),
        Err(e) if !gpu_required() => {
            println!("skipped: no adapter ({e})");
            None
        }
        Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no adapter: {e}"),
    }
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Worst relative difference (residual, scales, tangent, scalars) over all cases.
fn worst_error(ctx: &GpuContext, cases: &[Case], mode: KernelMode) -> [f64; 4] {
    let mut kern = ElementKernel::new(ctx, cases.len()).unwrap();
    for (i, c) in cases.iter().enumerate() {
        kern.set_element(i, &c.data, &c.k, c.trans);
        kern.set_point_masses(i, c.pm);
        kern.set_follower(i, &c.fol);
        kern.set_state(i, &c.st, &c.eps_n);
        kern.set_iter(i, &c.inc, &c.s);
    }
    // Residual-only readback first (modified Newton), then everything.
    kern.run(mode, false).unwrap();
    let r_only: Vec<ElementEval> = (0..cases.len()).map(|i| kern.eval(i, false)).collect();
    kern.run(mode, true).unwrap();
    for (i, e) in r_only.iter().enumerate() {
        assert_eq!(
            e.r,
            kern.eval(i, true).r,
            "residual-only readback of element {i}"
        );
    }
    let mut worst = [0.0f64; 4];
    for (i, c) in cases.iter().enumerate() {
        let (s, kin) = match mode {
            KernelMode::Frozen => (
                c.s,
                kinematics(&c.data, &c.st, &c.eps_n, &c.inc, c.s.c_nu, c.k.dt),
            ),
            KernelMode::Consistent => {
                // The kernel follows the branch of the uploaded (frozen) c_ν, as the CPU
                // path does with its frozen scalars.
                let (s, _, kin) =
                    consistent_scalars_near(&c.data, &c.st, &c.eps_n, &c.inc, &c.k, c.s.c_nu);
                (s, kin)
            }
        };
        let mut cpu: ElementEval = residual_tangent(&c.data, &c.st, &kin, &s, &c.k, c.trans, true);
        add_drag_rows(&c.data.props, &c.inc.u, c.k.dt, true, &mut cpu);
        add_point_mass_rows(c.pm, &c.st, &c.inc, c.k.dt, c.trans, true, &mut cpu);
        add_follower_rows(&c.fol, &c.st, &c.inc, c.data.props.h, true, &mut cpu);
        let gpu = kern.eval(i, true);
        let gs = kern.scalars(i);
        let errs = [
            rel(gpu.r.as_slice(), cpu.r.as_slice()),
            rel(gpu.scale.as_slice(), cpu.scale.as_slice()),
            rel(gpu.k.as_slice(), cpu.k.as_slice()),
            rel(
                &[gs.beta_gamma, gs.beta_omega, gs.c_v, gs.c_nu],
                &[s.beta_gamma, s.beta_omega, s.c_v, s.c_nu],
            ),
        ];
        for q in 0..4 {
            worst[q] = worst[q].max(errs[q]);
        }
    }
    worst
}

fn cases(n: usize, seed: u64) -> Vec<Case> {
    let mut rng = Rng(seed);
    (0..n).map(|i| case(&mut rng, i)).collect()
}

#[test]
fn gpu_matches_cpu_element_kernel_f64() {
    let Some(ctx) = context() else { return };
    if !ctx.is_f64() {
        // CI requires the GPU tests: an adapter without f64 must not pass silently.
        assert!(
            !gpu_required(),
            "COSSERAT_REQUIRE_GPU is set but adapter {} has no SHADER_F64",
            ctx.describe()
        );
        println!(
            "skipped: adapter {} has no SHADER_F64 (f64 parity not applicable)",
            ctx.describe()
        );
        return;
    }
    let cs = cases(240, 0x9E37_79B9_7F4A_7C15);
    for mode in [KernelMode::Frozen, KernelMode::Consistent] {
        let w = worst_error(&ctx, &cs, mode);
        println!(
            "{mode:?}: worst relative error r {:.2e} scale {:.2e} K {:.2e} scalars {:.2e} on {}",
            w[0],
            w[1],
            w[2],
            w[3],
            ctx.describe()
        );
        for (q, name) in ["residual", "scales", "tangent", "scalars"]
            .iter()
            .enumerate()
        {
            let bound = if q == 3 {
                SCALARS_RTOL
            } else {
                KERNEL_PARITY_RTOL
            };
            assert!(w[q] <= bound, "{mode:?} {name}: {:.3e}", w[q]);
        }
    }
}

#[test]
fn gpu_f32_fallback_error_is_bounded() {
    let Some(ctx) = context() else { return };
    let ctx32 = ctx.with_precision(Precision::F32);
    let cs = cases(240, 0x0123_4567_89AB_CDEF);
    let w = worst_error(&ctx32, &cs, KernelMode::Frozen);
    println!(
        "f32 fallback: worst relative error r {:.2e} scale {:.2e} K {:.2e}",
        w[0], w[1], w[2]
    );
    for (q, name) in ["residual", "scales", "tangent"].iter().enumerate() {
        assert!(w[q] <= F32_RTOL, "f32 {name}: {:.3e}", w[q]);
    }
}

#[test]
fn software_adapter_and_pipeline_cache_file() {
    let Some(ctx) = context() else { return };
    let name = ctx.info.name.to_lowercase();
    if ["llvmpipe", "lavapipe", "swiftshader", "warp"]
        .iter()
        .any(|s| name.contains(s))
    {
        assert!(
            ctx.is_software(),
            "{} is a software adapter",
            ctx.describe()
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let cached = GpuContext::with_cache_dir(None, Some(dir.path().join("cache"))).unwrap();
    let Some(path) = cached.pipeline_cache_path().map(|p| p.to_path_buf()) else {
        println!("{}: no PIPELINE_CACHE, nothing cached", ctx.describe());
        return;
    };
    ElementKernel::new(&cached, 8).unwrap();
    let files: Vec<_> = std::fs::read_dir(dir.path().join("cache"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(
        files,
        vec![path.clone()],
        "one cache file, no temporary left"
    );
    let name = path.file_name().unwrap().to_str().unwrap();
    assert!(name.starts_with("wgpu_pipeline_cache_") && name.ends_with(".bin"));
    let len = std::fs::metadata(&path).unwrap().len();
    println!("pipeline cache of {}: {len} bytes", ctx.describe());
    assert!(len > 0);
    // A second context reads it back and builds the same pipelines.
    let again = GpuContext::with_cache_dir(None, Some(dir.path().join("cache"))).unwrap();
    assert_eq!(again.pipeline_cache_path(), Some(path.as_path()));
    ElementKernel::new(&again, 8).unwrap();
    assert!(GpuContext::with_cache_dir(None, None)
        .unwrap()
        .pipeline_cache_path()
        .is_none());
}

/// The shader's field offsets are the Rust layout's (no GPU needed).
#[test]
fn shader_layout_matches_rust_layout() {
    let consts: Vec<(&str, usize)> = vec![
        ("E_H", layout::E_H),
        ("E_ARHO", layout::E_ARHO),
        ("E_IRHO", layout::E_IRHO),
        ("E_CG", layout::E_CG),
        ("E_CO", layout::E_CO),
        ("E_EPS0", layout::E_EPS0),
        ("E_ROTFREE", layout::E_ROTFREE),
        ("E_DT", layout::E_DT),
        ("E_TRANS", layout::E_TRANS),
        ("E_SCHEME", layout::E_SCHEME),
        ("E_SP", layout::E_SP),
        ("E_DIRDISS", layout::E_DIRDISS),
        ("E_DAMP", layout::E_DAMP),
        ("E_DRAG", layout::E_DRAG),
        ("E_PMASS", layout::E_PMASS),
        ("E_FOLLOW", layout::E_FOLLOW),
        ("S_R", layout::S_R),
        ("S_D", layout::S_D),
        ("S_V", layout::S_V),
        ("S_VD", layout::S_VD),
        ("S_EPS", layout::S_EPS),
        ("I_X", layout::I_X),
        ("I_S", layout::I_S),
        ("I_ACTIVE", layout::I_ACTIVE),
        ("O_R", layout::O_R),
        ("O_SC", layout::O_SC),
        ("O_K", layout::O_K),
        ("O_S", layout::O_S),
        ("T_C1", layout::T_C1),
        ("T_A", layout::T_A),
        ("T_SS", layout::T_SS),
        ("T_F", layout::T_F),
        ("T_BT", layout::T_BT),
        ("T_DB", layout::T_DB),
        ("T_ADV", layout::T_ADV),
        ("T_REC", layout::T_REC),
        ("T_FS", layout::T_FS),
    ];
    for (name, val) in consts {
        let needle = format!("const {name}: u32 = {val}u;");
        assert!(ELEMENT_WGSL.contains(&needle), "shader lacks `{needle}`");
    }
}

/// The monolithic linearization `(∂R/∂s)(∂s/∂q)` (CPU kernel, no GPU needed) uses that the
/// residual is affine in `(β_Γ, β_Ω, c_v, c_ν/(1 + K c_ν))`: it equals differencing whole
/// residuals at the perturbed scalars, `(R(s(q + h e_j)) − R(s(q − h e_j)))/2h` (what it
/// replaced), on every dissipative case. That difference sets the bound: its round-off
/// `ε |R| / h` (measured 3.54 with the closed form, which differences nothing; 1.22 while
/// the correction differenced the same scalars; the scalars' own round-off, amplified by
/// the law, adds to the reference's error).
#[test]
fn monolithic_correction_is_the_whole_residual_difference() {
    let mut worst: f64 = 0.0;
    let mut checked = 0;
    for c in cases(240, 0x0005_EED0_F5CA_1A25)
        .iter()
        .filter(|c| c.k.scheme.is_dissipative())
    {
        let active = [true; NDOF];
        let mut kt = nalgebra::SMatrix::<f64, NDOF, NDOF>::zeros();
        let (s0, _, kin0) = consistent_scalars(&c.data, &c.st, &c.eps_n, &c.inc, &c.k);
        monolithic_correction(&c.data, &c.st, &s0, &kin0, &c.k, c.trans, &active, &mut kt);
        let x0 = c.inc.to_local();
        let mut noise: f64 = 0.0;
        let mut err: f64 = 0.0;
        for j in 0..NDOF {
            let hstep = 1e-7 * (1.0 + x0[j].abs());
            let r = |sign: f64| {
                let mut x = x0;
                x[j] += sign * hstep;
                let (s, _, _) =
                    consistent_scalars(&c.data, &c.st, &c.eps_n, &Increment::from_local(&x), &c.k);
                let kin = kinematics(&c.data, &c.st, &c.eps_n, &c.inc, s.c_nu, c.k.dt);
                residual_tangent(&c.data, &c.st, &kin, &s, &c.k, c.trans, false).r
            };
            let (rp, rm) = (r(1.0), r(-1.0));
            let col = (rp - rm) * (0.5 / hstep);
            noise = noise.max(f64::EPSILON * rp.amax().max(rm.amax()) / hstep);
            err = err.max((kt.column(j) - col).amax());
        }
        worst = worst.max(err / noise);
        checked += 1;
    }
    println!("monolithic correction vs whole-residual differences: worst {worst:.2e} of ε|R|/h over {checked} cases");
    assert!(checked >= 100, "only {checked} dissipative cases");
    assert!(
        worst <= 8.0,
        "monolithic correction differs by {worst:e} of ε|R|/h"
    );
}

/// `σ = (β_Γ, β_Ω, c_v, φ = c_ν/(1 + K c_ν))`: the scalars the residual is affine in.
fn sigma_of(s: &FrozenScalars, ksum: f64) -> [f64; 4] {
    [
        s.beta_gamma,
        s.beta_omega,
        s.c_v,
        s.c_nu / (1.0 + ksum * s.c_nu),
    ]
}

/// Reference for the closed-form `∂σ/∂x_j` (row `j`): central differences (step
/// `1e-7 (1 + |x_j|)`) of the consistent scalars `scalars_at(x)` at the unknowns `x0`.
fn scalar_gradient_fd(
    x0: &SVector<f64, NDOF>,
    ksum: f64,
    scalars_at: impl Fn(&SVector<f64, NDOF>) -> FrozenScalars,
) -> [[f64; 4]; NDOF] {
    let mut dsigma = [[0.0f64; 4]; NDOF];
    for (j, row) in dsigma.iter_mut().enumerate() {
        let hstep = 1e-7 * (1.0 + x0[j].abs());
        let at = |sign: f64| {
            let mut x = *x0;
            x[j] += sign * hstep;
            sigma_of(&scalars_at(&x), ksum)
        };
        let (sp, sm) = (at(1.0), at(-1.0));
        for i in 0..4 {
            row[i] = (sp[i] - sm[i]) * (0.5 / hstep);
        }
    }
    dsigma
}

/// Reference for the closed-form `∂R/∂σ_i`: `R(σ + e_i) − R(σ)` (exact: the residual is
/// affine in σ), with `residual_at(s, φ)` the residual at the iterate with the frozen
/// scalars `s` and the director factor φ in its kinematics.
fn residual_differences(
    s0: &FrozenScalars,
    ksum: f64,
    residual_at: impl Fn(&FrozenScalars, f64) -> SVector<f64, NDOF>,
) -> [SVector<f64, NDOF>; 4] {
    let phi0 = sigma_of(s0, ksum)[3];
    let r0 = residual_at(s0, phi0);
    std::array::from_fn(|i| {
        let (mut s, mut phi) = (*s0, phi0);
        match i {
            0 => s.beta_gamma += 1.0,
            1 => s.beta_omega += 1.0,
            2 => s.c_v += 1.0,
            _ => phi += 1.0,
        }
        residual_at(&s, phi) - r0
    })
}

/// The dissipative cases, each also with both ends' rotations fixed (`K = 0`: the director
/// factor then leaves the kinematics) and with Kelvin–Voigt damping (a constant added to
/// the β), which the shared case set does not draw.
fn dissipative_variants() -> Vec<Case> {
    let mut out = Vec::new();
    for c in cases(240, 0x0005_EED0_F5CA_1A25)
        .into_iter()
        .filter(|c| c.k.scheme.is_dissipative())
    {
        let mut clamped = c.clone();
        clamped.data.rot_free = [false, false];
        let mut damped = c.clone();
        damped.data.props.damping = 0.3 * c.k.dt;
        out.extend([c, clamped, damped]);
    }
    out
}

/// The closed-form derivative of the consistent scalars `σ = (β_Γ, β_Ω, c_v, φ)` with
/// respect to the element's unknowns ([`scalar_gradient`]: the law's Jacobian, the
/// implicit derivative of the director factor's fixed point, the kinematics' derivatives)
/// equals central differences of the consistent scalars ([`scalar_gradient_fd`], step
/// 1e-7) on every dissipative case, relative to the largest entry of each σ's gradient.
/// The differences set the level: `c_ν` is solved to `1e-15 (1 + |c_ν|)`, which a step
/// of 1e-7 turns into ~1e-8 of the gradient, more where `c_ν` is large (measured 2.1e-7
/// at `c_ν` = 144, ≤ 4.2e-8 elsewhere, ≤ 1.4e-9 without director dissipation), on the
/// cases with fixed rotations and with Kelvin–Voigt damping too.
#[test]
fn scalar_gradient_is_the_difference_of_the_consistent_scalars() {
    let mut worst: f64 = 0.0;
    let mut checked = 0;
    for c in &dissipative_variants() {
        let (s0, _, kin0) = consistent_scalars(&c.data, &c.st, &c.eps_n, &c.inc, &c.k);
        let exact = scalar_gradient(&c.data, &c.st, &kin0, &s0, &c.k);
        let ksum: f64 = c.data.kappa().iter().sum();
        let fd = scalar_gradient_fd(&c.inc.to_local(), ksum, |x| {
            consistent_scalars(&c.data, &c.st, &c.eps_n, &Increment::from_local(x), &c.k).0
        });
        for i in 0..4 {
            let size = (0..NDOF).map(|j| fd[j][i].abs()).fold(0.0, f64::max);
            for j in 0..NDOF {
                let err = (exact[j][i] - fd[j][i]).abs();
                if size > 0.0 {
                    worst = worst.max(err / size);
                } else {
                    assert_eq!(err, 0.0, "σ_{i} is constant but its gradient is not");
                }
            }
        }
        checked += 1;
    }
    println!("closed-form scalar gradient vs central differences: worst {worst:.2e} of the gradient over {checked} cases");
    assert!(checked >= 100, "only {checked} dissipative cases");
    assert!(
        worst <= 5e-7,
        "scalar gradient differs by {worst:e} of the gradient"
    );
}

/// The closed-form `∂R/∂σ_i` ([`residual_scalar_derivatives`]) equals the residual's
/// change under a unit change of each of `σ = (β_Γ, β_Ω, c_v, φ)` ([`residual_differences`],
/// exact because the residual is affine in σ) on every dissipative case, within that
/// difference's round-off `ε |R|` (measured 3.81), on the cases with fixed rotations and with
/// Kelvin–Voigt damping too.
#[test]
fn residual_scalar_derivatives_are_the_residual_differences() {
    let mut worst: f64 = 0.0;
    let mut checked = 0;
    for c in &dissipative_variants() {
        let (s0, _, kin0) = consistent_scalars(&c.data, &c.st, &c.eps_n, &c.inc, &c.k);
        let exact = residual_scalar_derivatives(&c.data, &c.st, &kin0, &c.k, c.trans, [true; 4]);
        // Asked for one derivative at a time, each is the same to the bit and the rest zero.
        for i in 0..4 {
            let which: [bool; 4] = std::array::from_fn(|j| j == i);
            let one = residual_scalar_derivatives(&c.data, &c.st, &kin0, &c.k, c.trans, which);
            for j in 0..4 {
                let want = if j == i { exact[j] } else { ElemVec::zeros() };
                assert_eq!(one[j], want, "derivative {j} asked for {which:?}");
            }
        }
        let ksum: f64 = c.data.kappa().iter().sum();
        let size = std::cell::Cell::new(0.0f64);
        let diff = residual_differences(&s0, ksum, |s, phi| {
            let kin = kinematics_at(&c.data, &c.st, &c.eps_n, &c.inc, |_| phi, c.k.dt);
            let r = residual_tangent(&c.data, &c.st, &kin, s, &c.k, c.trans, false).r;
            size.set(size.get().max(r.amax()));
            r
        });
        let size = size.get();
        for i in 0..4 {
            worst = worst.max((exact[i] - diff[i]).amax() / (f64::EPSILON * size));
        }
        checked += 1;
    }
    println!(
        "closed-form ∂R/∂σ vs residual differences: worst {worst:.2e} of ε|R| over {checked} cases"
    );
    assert!(checked >= 100, "only {checked} dissipative cases");
    assert!(worst <= 8.0, "∂R/∂σ differs by {worst:e} of ε|R|");
}
