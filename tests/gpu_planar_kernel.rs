//! GPU planar element kernel ≡ CPU planar element kernel.
//!
//! On seeded random planar elements (random sections, turned and slightly non-unit
//! directors, velocities, increments, frozen dissipation scalars, EM/EDMC stresses and the
//! mid-point rule, clamped/free ends, with and without translational dissipation), the WGSL
//! twin (`shaders/planar.wgsl`) returns the residual, row scales and tangent of
//! [`cosserat::element::planar`] to `PARITY_RTOL` relative to the largest entry of each; a
//! residual-only dispatch returns the same residual. Without an adapter the test prints
//! `skipped: no adapter` unless `COSSERAT_REQUIRE_GPU` is set.

use cosserat::element::planar::{
    kinematics_core, residual_tangent, strains3, PConfig, PIncrement, PState, PlanarData,
    PlanarMap, V2,
};
use cosserat::element::{FrozenScalars, StepConsts};
use cosserat::gpu::planar::{PlanarInput, PlanarKernelGpu};
use cosserat::gpu::{gpu_required, GpuContext, Precision};
use cosserat::integrator::Scheme;
use nalgebra::Vector3;

/// f64 parity (same operations in the same order; the difference is the compilers'
/// contractions): measured ≤ 4e-16 on lavapipe.
const PARITY_RTOL: f64 = 4e-15;

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
    fn v2(&mut self, s: f64) -> V2 {
        V2::new(self.sym(s), self.sym(s))
    }
}

fn turn(phi: f64, a: V2) -> V2 {
    let (s, c) = phi.sin_cos();
    V2::new(c * a.x - s * a.y, s * a.x + c * a.y)
}

fn case(rng: &mut Rng, idx: usize) -> (PlanarInput, StepConsts, bool) {
    let h = 0.1 + rng.next();
    let rot_free = match idx % 4 {
        0 => [true, true],
        1 => [false, true],
        2 => [true, false],
        _ => [true, true],
    };
    let kappa = match rot_free {
        [true, true] => [1.0, 1.0],
        [true, false] => [1.5, 0.0],
        [false, true] => [0.0, 1.5],
        [false, false] => [0.0, 0.0],
    };
    let phi0 = rng.sym(3.0);
    let t_ref = turn(phi0, V2::new(1.0, 0.0));
    let r0 = rng.v2(1.0);
    let r1 = r0 + t_ref * h;
    let ref_cfg = PConfig {
        r: [r0, r1],
        d: [[turn(phi0, V2::new(0.0, 1.0)), t_ref]; 2],
    };
    let mut data = PlanarData {
        h,
        a_rho: 0.5 + rng.next(),
        i_s: 0.01 + 0.1 * rng.next(),
        i_amax: 0.2,
        c: Vector3::new(
            1e3 * (1.0 + rng.next()),
            2e3 * (1.0 + rng.next()),
            10.0 * (1.0 + rng.next()),
        ),
        eps0: Vector3::zeros(),
        damping: 0.0,
        rot_free,
        kappa,
        map: PlanarMap {
            axes: [0, 1],
            normal: 2,
            coef: [1.0, 0.0],
        },
    };
    data.eps0 = strains3(&ref_cfg, h);
    let dir = |rng: &mut Rng, a: V2| turn(rng.sym(0.3), a) * (1.0 + rng.sym(1e-3));
    let cfg = PConfig {
        r: [r0 + rng.v2(0.05), r1 + rng.v2(0.05)],
        d: [
            [dir(rng, ref_cfg.d[0][0]), dir(rng, ref_cfg.d[0][1])],
            [dir(rng, ref_cfg.d[1][0]), dir(rng, ref_cfg.d[1][1])],
        ],
    };
    let vs = std::array::from_fn(|l| {
        if rot_free[l] {
            rng.v2(0.5)
        } else {
            V2::zeros()
        }
    });
    let st = PState {
        cfg,
        v: [rng.v2(1.0), rng.v2(1.0)],
        vs,
    };
    let trans = idx % 3 == 1;
    let inc = PIncrement {
        u: [rng.v2(0.01), rng.v2(0.01)],
        theta: [rng.sym(0.05), rng.sym(0.05)],
        g: if trans {
            [rng.v2(0.01), rng.v2(0.01)]
        } else {
            [V2::zeros(); 2]
        },
    };
    let scheme = if idx % 5 == 4 {
        Scheme::Midpoint
    } else {
        Scheme::Em
    };
    let s = FrozenScalars {
        beta_gamma: rng.next(),
        beta_omega: rng.next(),
        c_v: 0.3 * rng.next(),
        c_nu: 0.3 * rng.next(),
    };
    let k = StepConsts {
        dt: 0.01 + 0.2 * rng.next(),
        scheme,
    };
    let eps_n = strains3(&cfg, h);
    (
        PlanarInput {
            data,
            st,
            eps_n,
            inc,
            s,
        },
        k,
        trans,
    )
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

#[test]
fn gpu_planar_kernel_matches_cpu() {
    let Some(ctx) = context() else { return };
    if ctx.precision != Precision::F64 {
        // CI requires the GPU tests: an adapter without f64 must not pass silently.
        assert!(
            !gpu_required(),
            "COSSERAT_REQUIRE_GPU is set but the adapter has no SHADER_F64"
        );
        println!("skipped: adapter without SHADER_F64");
        return;
    }
    let kernel = PlanarKernelGpu::new(&ctx).unwrap();
    let mut rng = Rng(0x853c49e6748fea9b);
    let mut worst = [0.0f64; 3];
    for idx in 0..240 {
        let (input, k, trans) = case(&mut rng, idx);
        let kin = kinematics_core(
            &input.data,
            &input.st,
            &input.eps_n,
            &input.inc,
            input.s.c_nu,
            k.dt,
        );
        let cpu = residual_tangent(&input.data, &input.st, &kin, &input.s, &k, trans, true);
        let gpu = kernel.evaluate(&[input], &k, trans, true).unwrap();
        let gpu_r = kernel.evaluate(&[input], &k, trans, false).unwrap();
        let d = [
            rel(gpu[0].r.as_slice(), cpu.r.as_slice()),
            rel(gpu[0].scale.as_slice(), cpu.scale.as_slice()),
            rel(gpu[0].k.as_slice(), cpu.k.as_slice()),
        ];
        assert_eq!(
            gpu_r[0].r, gpu[0].r,
            "case {idx}: residual-only dispatch differs"
        );
        for (w, x) in worst.iter_mut().zip(d) {
            *w = w.max(x);
        }
        assert!(
            d.iter().all(|&x| x <= PARITY_RTOL),
            "case {idx}: residual {:.1e}, scales {:.1e}, tangent {:.1e}",
            d[0],
            d[1],
            d[2]
        );
    }
    println!(
        "GPU vs CPU planar kernel, 240 elements: residual {:.1e}, scales {:.1e}, tangent {:.1e}",
        worst[0], worst[1], worst[2]
    );
}
