//! The element kernel four elements at a time (`F64x4` lanes) equals four one-element
//! (`f64`) evaluations bit for bit: kinematics, residual, row scales and tangent, for
//! every scheme family (EM, EDMC-1, EDMC-2 with translational and director dissipation,
//! the mid-point rule with Kelvin–Voigt damping), clamped and free ends mixed across the
//! lanes, and elements of different sections in one group; the same for the planar
//! element kernel. The CPU assembly relies on it: a run's outputs do not depend on
//! whether its elements went through the lanes.

mod common;

use nalgebra::{Vector3, Vector6};

use cosserat::element::lanes::{pack3, pack6};
use cosserat::element::planar::{
    self, PConfig, PElementEval, PIncrement, PState, PlanarData, PlanarMap, V2,
};
use cosserat::element::strain::Config;
use cosserat::element::{
    kinematics_core, residual_tangent_into, strains6, ElementData, ElementEval, ElementState,
    FrozenScalars, Increment, StepConsts,
};
use cosserat::integrator::Scheme;
use cosserat::math::cay;
use cosserat::math::lane::{F64x4, LANES};
use cosserat::math::rng::Rng;
use cosserat::model::{Mat3, Vec3};

fn v3(rng: &mut Rng, s: f64) -> Vec3 {
    Vec3::new(rng.symmetric(), rng.symmetric(), rng.symmetric()) * s
}

/// One element's inputs; `free` sets which end rotations move, `damping` the Kelvin–Voigt
/// time.
fn element(rng: &mut Rng, free: [bool; 2], damping: f64) -> (ElementData, ElementState, Increment) {
    let h = 0.05 + rng.uniform();
    let a = 1e-3 + 1e-2 * rng.uniform();
    let i1 = 1e-6 + 1e-5 * rng.uniform();
    let i12 = 0.2 * i1 * rng.symmetric();
    let e = 1e5 + 1e7 * rng.uniform();
    let rho = 100.0 + 1000.0 * rng.uniform();
    let props = common::anisotropic_props(h, a, i1, i12, e, rho, damping);
    let tri = cay(&v3(rng, 1.0));
    let r0 = v3(rng, 1.0);
    let r1 = r0 + tri.column(2) * h;
    let reference = Config {
        r: [r0, r1],
        d: [tri, tri],
    };
    let data = ElementData {
        eps0: strains6(&reference, h),
        props,
        rot_free: free,
        measure: Default::default(),
    };
    // Moved, rotated, slightly non-orthonormal triads.
    let mut distort = || Mat3::identity() + Mat3::from_fn(|_, _| 1e-3 * rng.symmetric());
    let (q0, q1) = (distort(), distort());
    let cfg = Config {
        r: [r0 + v3(rng, 0.05), r1 + v3(rng, 0.05)],
        d: [cay(&v3(rng, 0.3)) * tri * q0, cay(&v3(rng, 0.3)) * tri * q1],
    };
    let vd = [0, 1].map(|l| [0, 1].map(|_| if free[l] { v3(rng, 0.5) } else { Vec3::zeros() }));
    let st = ElementState {
        cfg,
        v: [v3(rng, 1.0), v3(rng, 1.0)],
        vd,
    };
    let th = |rng: &mut Rng, f: bool| if f { v3(rng, 0.2) } else { Vec3::zeros() };
    let inc = Increment {
        u: [v3(rng, 0.05), v3(rng, 0.05)],
        theta: [th(rng, free[0]), th(rng, free[1])],
        g: [v3(rng, 0.1), v3(rng, 0.1)],
    };
    (data, st, inc)
}

/// The scheme families the lane tests cycle through.
fn schemes() -> [Scheme; 4] {
    [
        Scheme::Em,
        Scheme::Midpoint,
        Scheme::Edmc1 {
            chi_gamma: 0.3,
            chi_omega: 0.4,
            chi_v: 0.5,
            chi_nu: 0.2,
        },
        Scheme::Edmc2 {
            alpha_gv: 0.5,
            alpha_gn: 0.3,
            alpha_ov: 0.2,
            alpha_on: 0.6,
        },
    ]
}

/// Frozen scalars of lane `lane` with Kelvin–Voigt β `kv`: random under a dissipative
/// scheme, lane 1 without director dissipation (c_ν = 0) beside lanes with it (the
/// director-dissipation branch runs for the group and must add exact zeros in that lane).
fn frozen(rng: &mut Rng, scheme: Scheme, kv: f64, lane: usize) -> FrozenScalars {
    if scheme.is_dissipative() {
        FrozenScalars {
            beta_gamma: rng.uniform() + kv,
            beta_omega: rng.uniform() + kv,
            c_v: 0.3 * rng.uniform(),
            c_nu: if scheme.director_dissipation() && lane != 1 {
                0.3 * rng.uniform()
            } else {
                0.0
            },
        }
    } else {
        FrozenScalars {
            beta_gamma: kv,
            beta_omega: kv,
            ..FrozenScalars::default()
        }
    }
}

/// The 16 lane groups of a test, cycling through [`schemes`]: per group its step constants,
/// its four elements from `make(rng, free ends, Kelvin–Voigt time)` and their frozen
/// scalars. Each lane has its own section and end conditions (rotated per group); under
/// the mid-point rule and EDMC-2 some lanes only have Kelvin–Voigt damping, so β differs
/// across the lanes (zero in some, where a β ≠ 0 branch then runs for the group).
#[allow(clippy::type_complexity)]
fn lane_groups<E>(
    rng: &mut Rng,
    make: impl Fn(&mut Rng, [bool; 2], f64) -> E,
    damping: impl Fn(&E) -> f64,
) -> Vec<(StepConsts, Vec<E>, Vec<FrozenScalars>)> {
    let free_sets = [[true, true], [false, true], [true, false], [false, false]];
    let mut groups = Vec::new();
    for (n, scheme) in schemes().into_iter().cycle().take(16).enumerate() {
        let k = StepConsts {
            dt: 1e-3 + 0.05 * rng.uniform(),
            scheme,
        };
        let elems: Vec<E> = (0..LANES)
            .map(|i| {
                let eta = if n % 2 == 1 && i % 2 == 0 { 1e-3 } else { 0.0 };
                make(rng, free_sets[(i + n) % 4], eta)
            })
            .collect();
        let s = (0..LANES)
            .map(|i| frozen(rng, scheme, 2.0 * damping(&elems[i]) / k.dt, i))
            .collect();
        groups.push((k, elems, s));
    }
    groups
}

fn same(what: &str, lane: usize, a: f64, b: f64) {
    assert!(
        a.to_bits() == b.to_bits(),
        "{what}, lane {lane}: {a:e} (lanes) vs {b:e} (one element)"
    );
}

#[test]
fn four_lanes_equal_four_single_evaluations_bit_for_bit() {
    let mut rng = Rng::new(7);
    let mut compared = 0usize;
    for (k, elems, s) in lane_groups(&mut rng, element, |e| e.0.props.damping) {
        let trans = k.scheme.translational_dissipation();
        let eps_n: Vec<Vector6<f64>> = elems
            .iter()
            .map(|(d, st, _)| strains6(&st.cfg, d.props.h))
            .collect();
        let arr = |f: &dyn Fn(usize) -> usize| -> [usize; LANES] { std::array::from_fn(f) };
        let idx = arr(&|i| i);
        let data = ElementData::<F64x4>::pack(idx.map(|i| &elems[i].0));
        let st = ElementState::pack(&idx.map(|i| elems[i].1));
        let inc = Increment::pack(&idx.map(|i| elems[i].2));
        let sl = FrozenScalars::pack(&idx.map(|i| s[i]));
        let el = pack6(&idx.map(|i| eps_n[i]));
        for tangent in [false, true] {
            let kin = kinematics_core(&data, &st, &el, &inc, sl.c_nu, k.dt);
            let mut ev = ElementEval::<F64x4>::zeros();
            residual_tangent_into(&data, &st, &kin, &sl, &k, trans, tangent, &mut ev);
            for i in 0..LANES {
                let (d, st1, inc1) = &elems[i];
                let kin1 = kinematics_core(d, st1, &eps_n[i], inc1, s[i].c_nu, k.dt);
                for (a, b) in kin.cfg1.d[0].iter().zip(kin1.cfg1.d[0].iter()) {
                    same("director at n+1", i, a.lane(i), *b);
                }
                for (a, b) in kin.eps1.iter().zip(kin1.eps1.iter()) {
                    same("strain at n+1", i, a.lane(i), *b);
                }
                for l in 0..2 {
                    for a in 0..2 {
                        for c in 0..3 {
                            same(
                                "director velocity",
                                i,
                                kin.vd1[l][a][c].lane(i),
                                kin1.vd1[l][a][c],
                            );
                        }
                    }
                }
                let mut one = ElementEval::<f64>::zeros();
                residual_tangent_into(d, st1, &kin1, &s[i], &k, trans, tangent, &mut one);
                let lane = ev.lane(i);
                for r in 0..18 {
                    same("residual", i, lane.r[r], one.r[r]);
                    same("row scale", i, lane.scale[r], one.scale[r]);
                    compared += 2;
                }
                if tangent {
                    assert!(lane.k.iter().any(|&x| x != 0.0));
                    for (x, y) in lane.k.iter().zip(one.k.iter()) {
                        same("tangent", i, *x, *y);
                    }
                    compared += 18 * 18;
                }
            }
        }
    }
    // 16 groups × 4 lanes × (36 residual and scale entries twice + 324 tangent entries).
    assert_eq!(compared, 16 * 4 * (2 * 36 + 324));
}

#[test]
fn lane_flags_give_each_end_its_director_dissipation_factor() {
    let mut rng = Rng::new(3);
    let sets = [[true, true], [false, true], [true, false], [false, false]];
    let elems: Vec<_> = sets.iter().map(|&f| element(&mut rng, f, 0.0).0).collect();
    let data = ElementData::<F64x4>::pack(std::array::from_fn(|i| &elems[i]));
    let kappa = data.kappa();
    for (i, e) in elems.iter().enumerate() {
        assert_eq!([kappa[0].lane(i), kappa[1].lane(i)], e.kappa());
    }
    // DESIGN §4: 1 on both free ends, 1.5 on the free end beside a clamp, 0 on a clamp.
    assert_eq!(elems[1].kappa(), [0.0, 1.5]);
    assert_eq!(elems[2].kappa(), [1.5, 0.0]);
    assert_eq!(elems[3].kappa(), [0.0, 0.0]);
}

fn v2(rng: &mut Rng, s: f64) -> V2 {
    V2::new(rng.symmetric(), rng.symmetric()) * s
}

/// `a` turned by `phi`.
fn turn(phi: f64, a: V2) -> V2 {
    let (s, c) = phi.sin_cos();
    V2::new(c * a.x - s * a.y, s * a.x + c * a.y)
}

/// One planar element's inputs; `free` sets which end rotations move.
fn planar_element(
    rng: &mut Rng,
    free: [bool; 2],
    damping: f64,
) -> (PlanarData, PState, Vector3<f64>, PIncrement) {
    let h = 0.05 + rng.uniform();
    let kappa = match free {
        [true, true] => [1.0, 1.0],
        [true, false] => [1.5, 0.0],
        [false, true] => [0.0, 1.5],
        [false, false] => [0.0, 0.0],
    };
    let phi0 = 3.0 * rng.symmetric();
    let t_ref = turn(phi0, V2::new(1.0, 0.0));
    let r0 = v2(rng, 1.0);
    let r1 = r0 + t_ref * h;
    let reference = PConfig {
        r: [r0, r1],
        d: [[turn(phi0, V2::new(0.0, 1.0)), t_ref]; 2],
    };
    let mut data = PlanarData {
        h,
        a_rho: 0.5 + rng.uniform(),
        i_s: 0.01 + 0.1 * rng.uniform(),
        i_amax: 0.2,
        c: Vector3::new(
            1e3 * (1.0 + rng.uniform()),
            2e3 * (1.0 + rng.uniform()),
            10.0 * (1.0 + rng.uniform()),
        ),
        eps0: Vector3::zeros(),
        damping,
        rot_free: free,
        kappa,
        map: PlanarMap {
            axes: [0, 1],
            normal: 2,
            coef: [1.0, 0.0],
        },
    };
    data.eps0 = planar::strains3(&reference, h);
    // Moved, turned, slightly stretched directors.
    let mut dir = |a: V2| turn(0.3 * rng.symmetric(), a) * (1.0 + 1e-3 * rng.symmetric());
    let d = [
        [dir(reference.d[0][0]), dir(reference.d[0][1])],
        [dir(reference.d[1][0]), dir(reference.d[1][1])],
    ];
    let cfg = PConfig {
        r: [r0 + v2(rng, 0.05), r1 + v2(rng, 0.05)],
        d,
    };
    let vs = [0, 1].map(|l| if free[l] { v2(rng, 0.5) } else { V2::zeros() });
    let st = PState {
        cfg,
        v: [v2(rng, 1.0), v2(rng, 1.0)],
        vs,
    };
    let th = |rng: &mut Rng, f: bool| if f { 0.2 * rng.symmetric() } else { 0.0 };
    let inc = PIncrement {
        u: [v2(rng, 0.05), v2(rng, 0.05)],
        theta: [th(rng, free[0]), th(rng, free[1])],
        g: [v2(rng, 0.1), v2(rng, 0.1)],
    };
    let eps_n = planar::strains3(&st.cfg, h);
    (data, st, eps_n, inc)
}

#[test]
fn planar_lanes_equal_single_evaluations_bit_for_bit() {
    let mut rng = Rng::new(11);
    let mut compared = 0usize;
    for (k, elems, s) in lane_groups(&mut rng, planar_element, |e| e.0.damping) {
        let trans = k.scheme.translational_dissipation();
        let [a, b, c, d] = [0, 1, 2, 3].map(|i| &elems[i]);
        let data = PlanarData::pack([&a.0, &b.0, &c.0, &d.0]);
        let st = PState::pack([&a.1, &b.1, &c.1, &d.1]);
        let eps_n = pack3([&a.2, &b.2, &c.2, &d.2]);
        let inc = PIncrement::from_locals(&[a.3, b.3, c.3, d.3].map(|x| x.to_local()));
        let sl = FrozenScalars::pack(&[s[0], s[1], s[2], s[3]]);
        for tangent in [false, true] {
            let kin = planar::kinematics_core(&data, &st, &eps_n, &inc, sl.c_nu, k.dt);
            let mut ev = PElementEval::<F64x4>::zeros();
            planar::residual_tangent_into(&data, &st, &kin, &sl, &k, trans, tangent, &mut ev);
            for (i, (d1, st1, eps1, inc1)) in elems.iter().enumerate() {
                let kin1 = planar::kinematics_core(d1, st1, eps1, inc1, s[i].c_nu, k.dt);
                for l in 0..2 {
                    for c in 0..2 {
                        same(
                            "s at n+1",
                            i,
                            kin.cfg1.d[l][0][c].lane(i),
                            kin1.cfg1.d[l][0][c],
                        );
                        same("s velocity", i, kin.vs1[l][c].lane(i), kin1.vs1[l][c]);
                    }
                }
                for (x, y) in kin.eps1.iter().zip(kin1.eps1.iter()) {
                    same("planar strain at n+1", i, x.lane(i), *y);
                }
                let one = planar::residual_tangent(d1, st1, &kin1, &s[i], &k, trans, tangent);
                // Without translational dissipation the g rows are not written.
                let rows = if trans { 10 } else { 6 };
                for r in 0..rows {
                    same("planar residual", i, ev.r[r].lane(i), one.r[r]);
                    same("planar row scale", i, ev.scale[r].lane(i), one.scale[r]);
                    compared += 2;
                }
                if tangent {
                    assert!(one.k.iter().any(|&x| x != 0.0));
                    for cc in 0..rows {
                        for r in 0..rows {
                            same("planar tangent", i, ev.k[(r, cc)].lane(i), one.k[(r, cc)]);
                            compared += 1;
                        }
                    }
                }
            }
        }
    }
    // 16 groups × 4 lanes: 8 of them with g rows (EDMC-1, EDMC-2).
    assert_eq!(
        compared,
        4 * (8 * (2 * 2 * 10 + 100) + 8 * (2 * 2 * 6 + 36))
    );
}

/// Whole runs with and without the four-element kernel calls: every state field of every
/// step, the iterations and the residuals are the same bit for bit, on the 3D and the
/// planar kernel, under EM (frozen scalars throughout), with rigid links, with contact,
/// with the staggered EDMC-2 loop (frozen scalars with dissipation) and with the
/// monolithic one (consistent scalars, their linearization added as each lane's tangent is
/// scattered, with and without director dissipation). This covers what
/// the kernel-level test above does not: the packing per step and per assembly, the
/// reused evaluation buffers and the scatter of each lane.
#[test]
fn runs_are_the_same_with_and_without_lanes() {
    use cosserat::integrator::{Simulation, Strategy};
    use cosserat::scene::load_scene;
    let edmc2 = Scheme::Edmc2 {
        alpha_gv: 0.5,
        alpha_gn: 0.5,
        alpha_ov: 0.5,
        alpha_on: 0.5,
    };
    // The paper's single α (translational dissipation only).
    let edmc2_gv = Scheme::Edmc2 {
        alpha_gv: 0.5,
        alpha_gn: 0.0,
        alpha_ov: 0.0,
        alpha_on: 0.0,
    };
    let (stag, mono) = (Strategy::Staggered, Strategy::Monolithic);
    // The monolithic cases assemble with consistent scalars and their linearization
    // (planar and 3D kernels, with and without director dissipation).
    // (scene, scheme and strategy if not the scene's, steps)
    type Case = (&'static str, Option<(Scheme, Strategy)>, usize);
    let cases: [Case; 10] = [
        ("cantilever_planar", None, 40),
        ("cantilever", None, 25),
        ("mechanism", None, 40),
        ("bounce", None, 40),
        ("arch", Some((edmc2, stag)), 30),
        ("frame", Some((edmc2, stag)), 15),
        ("cantilever_planar", Some((edmc2_gv, mono)), 30),
        ("cantilever_planar", Some((edmc2, mono)), 20),
        ("cantilever", Some((edmc2_gv, mono)), 20),
        ("frame", Some((edmc2, mono)), 15),
    ];
    for (name, scheme, steps) in cases {
        let scene = load_scene(name).unwrap();
        let mut params = scene.params;
        if let Some((s, strategy)) = scheme {
            params.scheme = s;
            params.strategy = strategy;
        }
        let sims: Vec<Simulation> = [true, false]
            .into_iter()
            .map(|on| {
                let mut sim = Simulation::new(scene.model.clone(), params).unwrap();
                sim.set_lanes(on);
                assert_eq!(sim.lanes(), on);
                sim
            })
            .collect();
        let [mut on, mut off] = <[Simulation; 2]>::try_from(sims).ok().unwrap();
        assert!(
            scene.model.elements.len() >= LANES,
            "{name}: no full lane group"
        );
        let bits = |s: &Simulation| -> Vec<u64> {
            let st = s.state();
            st.r.iter()
                .chain(&st.v)
                .flat_map(|x| x.iter().copied())
                .chain(
                    st.d.iter()
                        .flat_map(|d| d.iter().flat_map(|m| m.iter().copied())),
                )
                .chain(st.vd.iter().flat_map(|v| {
                    v.iter()
                        .flat_map(|e| e.iter().flat_map(|x| x.iter().copied()))
                }))
                .chain(st.eps.iter().flat_map(|x| x.iter().copied()))
                .map(f64::to_bits)
                .collect()
        };
        for step in 1..=steps {
            let (a, b) = (on.step(), off.step());
            let (a, b) = (
                a.unwrap_or_else(|f| panic!("{name} step {step}: {}", f.reason)),
                b.unwrap_or_else(|f| panic!("{name} step {step}: {}", f.reason)),
            );
            assert_eq!(
                a.newton_iters, b.newton_iters,
                "{name} step {step}: iterations"
            );
            assert_eq!(
                a.residual.to_bits(),
                b.residual.to_bits(),
                "{name} step {step}"
            );
            assert!(
                bits(&on) == bits(&off),
                "{name} step {step}: the states differ with and without lanes"
            );
        }
    }
}
