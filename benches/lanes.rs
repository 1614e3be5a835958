//! The element kernel four elements at a time (criterion): four `f64` evaluations
//! against one `F64x4` evaluation of the same four elements (bit-identical results,
//! `tests/lanes.rs`), residual only and residual + tangent, EM at Δt = 1e-2 on the
//! built-in cantilever's elements at their first step's predictor.
//!
//! ```sh
//! cargo bench --bench lanes
//! ```

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use cosserat::element::lanes::pack6;
use cosserat::element::{
    kinematics_core, residual_tangent_into, ElementData, ElementEval, ElementState, FrozenScalars,
    Increment, StepConsts,
};
use cosserat::integrator::Scheme;
use cosserat::math::lane::F64x4;
use cosserat::model::Vec3;
use cosserat::scene::load_scene;

struct Four {
    data: [ElementData; 4],
    st: [ElementState; 4],
    eps_n: [nalgebra::Vector6<f64>; 4],
    inc: [Increment; 4],
    s: [FrozenScalars; 4],
}

fn four() -> Four {
    let scene = load_scene("cantilever").unwrap();
    let data = ElementData::for_model(&scene.model);
    let state = cosserat::integrator::state::State::initial(&scene.model, &data);
    let pick = [10usize, 20, 30, 40];
    let st: [ElementState; 4] = std::array::from_fn(|i| state.element(&scene.model, pick[i]));
    // A mid-size increment: a few millimetres and a few milliradians, different per lane.
    let inc = std::array::from_fn(|i| Increment {
        u: [
            Vec3::new(1e-3, 2e-3, -1e-3 * i as f64),
            Vec3::new(2e-3, 1e-3, 3e-3),
        ],
        theta: [
            Vec3::new(1e-3, -2e-3, 5e-4),
            Vec3::new(-1e-3 * i as f64, 3e-3, 1e-3),
        ],
        g: [Vec3::zeros(); 2],
    });
    Four {
        data: std::array::from_fn(|i| data[pick[i]].clone()),
        eps_n: std::array::from_fn(|i| state.eps[pick[i]]),
        st,
        inc,
        s: [FrozenScalars::default(); 4],
    }
}

fn kernel(c: &mut Criterion) {
    let f = four();
    let k = StepConsts {
        dt: 1e-2,
        scheme: Scheme::Em,
    };
    let mut g = c.benchmark_group("kernel4");
    g.throughput(Throughput::Elements(4));
    for tangent in [false, true] {
        let label = if tangent { "tangent" } else { "residual" };
        let mut ev = ElementEval::<f64>::zeros();
        g.bench_function(format!("f64/{label}"), |b| {
            b.iter(|| {
                for i in 0..4 {
                    let kin =
                        kinematics_core(&f.data[i], &f.st[i], &f.eps_n[i], &f.inc[i], 0.0, k.dt);
                    residual_tangent_into(
                        &f.data[i], &f.st[i], &kin, &f.s[i], &k, false, tangent, &mut ev,
                    );
                    std::hint::black_box(&ev);
                }
            })
        });
        let data = ElementData::<F64x4>::pack(std::array::from_fn(|i| &f.data[i]));
        let mut evl = ElementEval::<F64x4>::zeros();
        g.bench_function(format!("f64x4/{label}"), |b| {
            b.iter(|| {
                let st = ElementState::pack(&f.st);
                let inc = Increment::pack(&f.inc);
                let eps_n = pack6(&f.eps_n);
                let s = FrozenScalars::pack(&f.s);
                let kin = kinematics_core(&data, &st, &eps_n, &inc, s.c_nu, k.dt);
                residual_tangent_into(&data, &st, &kin, &s, &k, false, tangent, &mut evl);
                std::hint::black_box(&evl);
            })
        });
    }
    g.finish();
}

criterion_group!(benches, kernel);
criterion_main!(benches);
