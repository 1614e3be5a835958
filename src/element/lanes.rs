//! Four elements in one kernel call: packing their inputs into [`F64x4`] lanes (lane `i`
//! is element `i` of the group) and reading lane results back. The kernel itself is the
//! one in [`super`], instantiated for `F64x4`; each lane's result equals the `f64`
//! evaluation of that element bit for bit (`tests/lanes.rs`).

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3, Vector6};

use super::planar::{
    pg_idx, pth_idx, pu_idx, PConfig, PElemVec, PIncrement, PKinematics, PState, PlanarData,
};
use super::strain::Config;
use super::{ElementData, ElementEval, ElementState, FrozenScalars, Increment, Kinematics, NDOF};
use crate::element::dissipation::LocalInputs;
use crate::math::lane::{F64x4, Lane, LANES};
use crate::model::ElementProps;

/// Packs a 6-vector per lane.
#[inline]
pub fn pack6(v: &[Vector6<f64>; LANES]) -> Vector6<F64x4> {
    let l = |r: usize| F64x4::new([v[0][r], v[1][r], v[2][r], v[3][r]]);
    Vector6::new(l(0), l(1), l(2), l(3), l(4), l(5))
}

impl ElementData<F64x4> {
    /// The constant data of four elements, one per lane.
    pub fn pack(d: [&ElementData; LANES]) -> Self {
        let [a, b, c, e] = d.map(|x| &x.props);
        let s = |f: fn(&ElementProps) -> f64| F64x4::new([f(a), f(b), f(c), f(e)]);
        ElementData {
            props: ElementProps {
                h: s(|p| p.h),
                a_rho: s(|p| p.a_rho),
                i_rho: Matrix2::from_fn(|r, col| {
                    F64x4::new([a, b, c, e].map(|p| p.i_rho[(r, col)]))
                }),
                c_gamma: v3([&a.c_gamma, &b.c_gamma, &c.c_gamma, &e.c_gamma]),
                c_omega: m3([&a.c_omega, &b.c_omega, &c.c_omega, &e.c_omega]),
                damping: s(|p| p.damping),
                drag: s(|p| p.drag),
            },
            eps0: pack6(&d.map(|x| x.eps0)),
            rot_free: [0, 1].map(|l| d.map(|x| x.rot_free[l])),
            // (Four elements of one measure: the rational measure's without `C_Ω`,
            // their moment rows added lane by lane.)
            measure: d[0].measure,
        }
    }
}

/// `[a.x, b.x, c.x, d.x]`, … for four vectors.
#[inline(always)]
fn v3(v: [&Vector3<f64>; LANES]) -> Vector3<F64x4> {
    let l = |r: usize| F64x4::new([v[0][r], v[1][r], v[2][r], v[3][r]]);
    Vector3::new(l(0), l(1), l(2))
}

/// Lane packing of four 3×3 matrices.
#[inline(always)]
fn m3(m: [&Matrix3<f64>; LANES]) -> Matrix3<F64x4> {
    let l = |k: usize| {
        let [a, b, c, d] = m;
        F64x4::new([
            a.as_slice()[k],
            b.as_slice()[k],
            c.as_slice()[k],
            d.as_slice()[k],
        ])
    };
    Matrix3::from_column_slice(&[l(0), l(1), l(2), l(3), l(4), l(5), l(6), l(7), l(8)])
}

impl ElementState<F64x4> {
    /// The states of four elements, one per lane.
    #[inline]
    pub fn pack(s: &[ElementState; LANES]) -> Self {
        let [a, b, c, d] = s;
        let r = |l: usize| v3([&a.cfg.r[l], &b.cfg.r[l], &c.cfg.r[l], &d.cfg.r[l]]);
        let dm = |l: usize| m3([&a.cfg.d[l], &b.cfg.d[l], &c.cfg.d[l], &d.cfg.d[l]]);
        let v = |l: usize| v3([&a.v[l], &b.v[l], &c.v[l], &d.v[l]]);
        let vd = |l: usize, k: usize| v3([&a.vd[l][k], &b.vd[l][k], &c.vd[l][k], &d.vd[l][k]]);
        ElementState {
            cfg: Config {
                r: [r(0), r(1)],
                d: [dm(0), dm(1)],
            },
            v: [v(0), v(1)],
            vd: [[vd(0, 0), vd(0, 1)], [vd(1, 0), vd(1, 1)]],
        }
    }
}

impl Increment<F64x4> {
    /// The increments of four elements, one per lane.
    #[inline]
    pub fn pack(x: &[Increment; LANES]) -> Self {
        let [a, b, c, d] = x;
        let u = |l: usize| v3([&a.u[l], &b.u[l], &c.u[l], &d.u[l]]);
        let t = |l: usize| v3([&a.theta[l], &b.theta[l], &c.theta[l], &d.theta[l]]);
        let g = |l: usize| v3([&a.g[l], &b.g[l], &c.g[l], &d.g[l]]);
        Increment {
            u: [u(0), u(1)],
            theta: [t(0), t(1)],
            g: [g(0), g(1)],
        }
    }
}

impl FrozenScalars<F64x4> {
    /// The frozen scalars of four elements, one per lane.
    #[inline]
    pub fn pack(s: &[FrozenScalars; LANES]) -> Self {
        let [a, b, c, d] = s;
        FrozenScalars {
            beta_gamma: F64x4::new([a.beta_gamma, b.beta_gamma, c.beta_gamma, d.beta_gamma]),
            beta_omega: F64x4::new([a.beta_omega, b.beta_omega, c.beta_omega, d.beta_omega]),
            c_v: F64x4::new([a.c_v, b.c_v, c.c_v, d.c_v]),
            c_nu: F64x4::new([a.c_nu, b.c_nu, c.c_nu, d.c_nu]),
        }
    }
}

impl ElementEval<F64x4> {
    /// Lane `i`'s result as a one-element evaluation.
    pub fn lane(&self, i: usize) -> ElementEval {
        ElementEval {
            r: SVector::<f64, NDOF>::from_fn(|r, _| self.r[r].lane(i)),
            scale: SVector::<f64, NDOF>::from_fn(|r, _| self.scale[r].lane(i)),
            k: SMatrix::<f64, NDOF, NDOF>::from_fn(|r, c| self.k[(r, c)].lane(i)),
        }
    }

    /// Lane `i`'s residual and row scales (and with `tangent` its tangent) into `out`.
    pub fn lane_into(&self, i: usize, tangent: bool, out: &mut ElementEval) {
        let flat = |x: &[F64x4], y: &mut [f64]| {
            for (v, a) in y
                .iter_mut()
                .zip(F64x4::flat(x).iter().skip(i).step_by(LANES))
            {
                *v = *a;
            }
        };
        flat(self.r.as_slice(), out.r.as_mut_slice());
        flat(self.scale.as_slice(), out.scale.as_mut_slice());
        if tangent {
            flat(self.k.as_slice(), out.k.as_mut_slice());
        }
    }
}

/// `[a.x, b.x, c.x, d.x]`, … for four 2-vectors.
#[inline(always)]
fn v2(v: [&Vector2<f64>; LANES]) -> Vector2<F64x4> {
    let l = |r: usize| F64x4::new([v[0][r], v[1][r], v[2][r], v[3][r]]);
    Vector2::new(l(0), l(1))
}

/// One number of four elements.
#[inline(always)]
fn s4(x: [f64; LANES]) -> F64x4 {
    F64x4::new(x)
}

impl PlanarData<F64x4> {
    /// The planar data of four elements, one per lane (the map is the first one's: the
    /// kernel reads none).
    pub fn pack(d: [&PlanarData; LANES]) -> Self {
        let [a, b, c, e] = d;
        let s = |f: fn(&PlanarData) -> f64| s4([f(a), f(b), f(c), f(e)]);
        PlanarData {
            h: s(|p| p.h),
            a_rho: s(|p| p.a_rho),
            i_s: s(|p| p.i_s),
            i_amax: s(|p| p.i_amax),
            c: v3([&a.c, &b.c, &c.c, &e.c]),
            eps0: v3([&a.eps0, &b.eps0, &c.eps0, &e.eps0]),
            damping: s(|p| p.damping),
            rot_free: [0, 1].map(|l| d.map(|x| x.rot_free[l])),
            kappa: [s(|p| p.kappa[0]), s(|p| p.kappa[1])],
            map: a.map,
        }
    }
}

impl PState<F64x4> {
    /// The planar states of four elements, one per lane.
    #[inline]
    pub fn pack(s: [&PState; LANES]) -> Self {
        let [a, b, c, d] = s;
        let r = |l: usize| v2([&a.cfg.r[l], &b.cfg.r[l], &c.cfg.r[l], &d.cfg.r[l]]);
        let dir = |l: usize, i: usize| {
            v2([
                &a.cfg.d[l][i],
                &b.cfg.d[l][i],
                &c.cfg.d[l][i],
                &d.cfg.d[l][i],
            ])
        };
        let v = |l: usize| v2([&a.v[l], &b.v[l], &c.v[l], &d.v[l]]);
        let vs = |l: usize| v2([&a.vs[l], &b.vs[l], &c.vs[l], &d.vs[l]]);
        PState {
            cfg: PConfig {
                r: [r(0), r(1)],
                d: [[dir(0, 0), dir(0, 1)], [dir(1, 0), dir(1, 1)]],
            },
            v: [v(0), v(1)],
            vs: [vs(0), vs(1)],
        }
    }
}

/// Packs a 3-vector per lane (the planar strains).
#[inline]
pub fn pack3(v: [&Vector3<f64>; LANES]) -> Vector3<F64x4> {
    v3(v)
}

impl PIncrement<F64x4> {
    /// The increments of four elements, one per lane, from their planar element-local
    /// vectors (as [`PIncrement::from_local`]).
    #[inline]
    pub fn from_locals(x: &[PElemVec; LANES]) -> Self {
        let l = |i: usize| s4([x[0][i], x[1][i], x[2][i], x[3][i]]);
        let v = |i: usize| Vector2::new(l(i), l(i + 1));
        PIncrement {
            u: [v(pu_idx(0)), v(pu_idx(1))],
            theta: [l(pth_idx(0)), l(pth_idx(1))],
            g: [v(pg_idx(0)), v(pg_idx(1))],
        }
    }
}

/// Lane `i` of a 3-vector.
#[inline(always)]
fn lane3(v: &Vector3<F64x4>, i: usize) -> Vector3<f64> {
    Vector3::new(v.x.lane(i), v.y.lane(i), v.z.lane(i))
}

/// Lane `i` of a 2-vector.
#[inline(always)]
fn lane2(v: &Vector2<F64x4>, i: usize) -> Vector2<f64> {
    Vector2::new(v.x.lane(i), v.y.lane(i))
}

/// Lane `i` of a 3×3 matrix.
#[inline(always)]
fn lane33(m: &Matrix3<F64x4>, i: usize) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m[(r, c)].lane(i))
}

impl Kinematics<F64x4> {
    /// Lane `i`'s kinematics as a one-element update (the local dissipation inputs at
    /// their default, as [`super::kinematics_core`] leaves them).
    pub fn lane(&self, i: usize) -> Kinematics {
        let cfg = |c: &Config<F64x4>| Config {
            r: [lane3(&c.r[0], i), lane3(&c.r[1], i)],
            d: [lane33(&c.d[0], i), lane33(&c.d[1], i)],
        };
        let v6 = |v: &Vector6<F64x4>| Vector6::from_fn(|r, _| v[r].lane(i));
        Kinematics {
            cfg1: cfg(&self.cfg1),
            mid: cfg(&self.mid),
            amat: [lane33(&self.amat[0], i), lane33(&self.amat[1], i)],
            eps_n: v6(&self.eps_n),
            eps1: v6(&self.eps1),
            v1: [lane3(&self.v1[0], i), lane3(&self.v1[1], i)],
            vd1: [0, 1].map(|l| [lane3(&self.vd1[l][0], i), lane3(&self.vd1[l][1], i)]),
            w: [lane3(&self.w[0], i), lane3(&self.w[1], i)],
            inputs: LocalInputs::default(),
        }
    }
}

impl PKinematics<F64x4> {
    /// Lane `i`'s planar kinematics as a one-element update (the local dissipation inputs
    /// at their default, as [`super::planar::kinematics_core`] leaves them).
    pub fn lane(&self, i: usize) -> PKinematics {
        let cfg = |c: &PConfig<F64x4>| PConfig {
            r: [lane2(&c.r[0], i), lane2(&c.r[1], i)],
            d: [0, 1].map(|l| [lane2(&c.d[l][0], i), lane2(&c.d[l][1], i)]),
        };
        let m2 = |m: &Matrix2<F64x4>| Matrix2::from_fn(|r, c| m[(r, c)].lane(i));
        PKinematics {
            cfg1: cfg(&self.cfg1),
            mid: cfg(&self.mid),
            amat: [m2(&self.amat[0]), m2(&self.amat[1])],
            eps_n: lane3(&self.eps_n, i),
            eps1: lane3(&self.eps1, i),
            v1: [lane2(&self.v1[0], i), lane2(&self.v1[1], i)],
            vs1: [lane2(&self.vs1[0], i), lane2(&self.vs1[1], i)],
            w: lane2(&self.w, i),
            inputs: LocalInputs::default(),
        }
    }
}
