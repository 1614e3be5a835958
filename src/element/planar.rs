//! The planar element kernel: the exact restriction of the 3D kernel ([`super`]) to a
//! rod that moves in a coordinate plane.
//!
//! In a planar model (the scene's `planar = "e1e2"` …) every position, velocity and
//! load lies in the plane and every rotation is about its normal `n`; the scene checks
//! that `n` is a principal axis of every section (or the section is isotropic). Then, per
//! element end, one director is `±n` for all time and the other two — the tangent
//! director `t = d_3` and the transverse director `s` (`d_1` or `d_2`, or for an
//! isotropic section the combination of both that lies in the plane) — stay in the plane.
//! Of the six strains only three are not identically zero:
//!
//! ```text
//! Γ_s = ½ (s_0 + s_1)·(r_1 − r_0)/h      (shear)
//! Γ_t = ½ (t_0 + t_1)·(r_1 − r_0)/h      (axial)
//! κ   = (t_0·s_1 − s_0·t_1)/(2h)          (bending about n)
//! ```
//!
//! and the element works with 2-vectors: per end the in-plane position, the in-plane
//! translational velocity, the two in-plane directors and the velocity of `s` (the normal
//! director has none). The unknowns per end are `u` (2), the scalar Cayley increment `θ`
//! about `n` (`cay(θ n)` rotates the plane by `φ`, `tan(φ/2) = θ/2`) and, with
//! translational dissipation, `g` (2): 10 per element instead of 18. Every formula below is
//! the 3D one with the out-of-plane components dropped (they are zero, not neglected), so
//! the residual rows and the tangent equal the planar rows/columns of the 3D kernel to
//! round-off, for every scheme (EM, EDMC-1, EDMC-2, the mid-point baseline) and both
//! dissipation strategies.

use nalgebra::{Matrix2, SMatrix, SVector, Vector2, Vector3};

use super::dissipation::{local_scalars, LocalInputs, LocalScalars};
use super::strain::Config;
use super::{ElementData, ElementState, FrozenScalars, StepConsts, StressRule, M2};
use crate::math::lane::{zeros, Lane};
use crate::model::{Mat3, Plane, Vec3};

/// 2-vector of `f64` (in-plane components along the plane's two axes).
pub type V2 = Vector2<f64>;
/// Unknowns of one planar element: per end `u` (2), `θ` (1); then per end `g` (2).
pub const NDOF_P: usize = 10;
/// Planar element residual (one entry per lane for a [`Lane`] type).
pub type PElemVec<T = f64> = SVector<T, NDOF_P>;
/// Planar element tangent.
pub type PElemMat<T = f64> = SMatrix<T, NDOF_P, NDOF_P>;

/// Local row/column of planar `u^l` component 0.
#[inline]
pub const fn pu_idx(l: usize) -> usize {
    3 * l
}
/// Local row/column of planar `θ^l`.
#[inline]
pub const fn pth_idx(l: usize) -> usize {
    3 * l + 2
}
/// Local row/column of planar `g^l` component 0.
#[inline]
pub const fn pg_idx(l: usize) -> usize {
    6 + 2 * l
}

/// Kind of a planar element-local row: 0 = u, 1 = θ, 2 = g.
#[inline]
pub const fn pkind(i: usize) -> usize {
    if i >= 6 {
        2
    } else if i % 3 == 2 {
        1
    } else {
        0
    }
}

/// Vector fields of a planar element: positions, then per end `(s, t)`.
const R0: usize = 0;
const R1: usize = 1;
/// Field of director `s` (0) or `t` (1) of end `l`.
#[inline]
const fn dfield(l: usize, i: usize) -> usize {
    2 + 2 * l + i
}
const NF: usize = 6;

/// `a × b · n` for in-plane `a, b` (the plane's axes are ordered so `e_i × e_j = n`).
#[inline(always)]
fn cross2<T: Lane>(a: &Vector2<T>, b: &Vector2<T>) -> T {
    a.x * b.y - a.y * b.x
}
/// `n × a`: the in-plane vector `a` turned by +90°.
#[inline(always)]
fn perp<T: Lane>(a: &Vector2<T>) -> Vector2<T> {
    Vector2::new(-a.y, a.x)
}

/// How an element's 3D data map to the plane: the plane's axes and the combination
/// `s = c_1 d_1 + c_2 d_2` that is the in-plane transverse director.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarMap {
    /// Global axes `(i, j)` of the plane, ordered so that `e_i × e_j = n`.
    pub axes: [usize; 2],
    /// The normal axis.
    pub normal: usize,
    /// `s = coef[0] d_1 + coef[1] d_2`.
    pub coef: [f64; 2],
}

impl PlanarMap {
    /// In-plane components of a 3-vector.
    #[inline]
    pub fn v2(&self, v: &Vec3) -> V2 {
        V2::new(v[self.axes[0]], v[self.axes[1]])
    }
    /// The 3-vector with in-plane components `a` and normal component `z`.
    #[inline]
    pub fn v3(&self, a: &V2, z: f64) -> Vec3 {
        let mut v = Vec3::zeros();
        v[self.axes[0]] = a.x;
        v[self.axes[1]] = a.y;
        v[self.normal] = z;
        v
    }
}

/// Constant data of one planar element (of four, one per lane, for [`F64x4`]:
/// [`PlanarData::pack`]).
///
/// [`F64x4`]: crate::math::lane::F64x4
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarData<T: Lane = f64> {
    /// Element reference length.
    pub h: T,
    /// `Aρ`.
    pub a_rho: T,
    /// Director inertia `Iρ` of `s`.
    pub i_s: T,
    /// Largest entry of the 3D `Iρ` (round-off floor of the θ rows, as in 3D).
    pub i_amax: T,
    /// Stiffnesses of `(Γ_s, Γ_t, κ)`: `G A_s, E A, E I_n`.
    pub c: Vector3<T>,
    /// Reference strains `(Γ_s°, Γ_t°, κ°)` (with the intrinsic curvature about the
    /// normal in `κ°`).
    pub eps0: Vector3<T>,
    /// Kelvin–Voigt retardation time `η` ([`crate::model::ElementProps::damping`]).
    pub damping: T,
    /// Whether the rotation of each end node is free.
    pub rot_free: [T::Flag; 2],
    /// Director-dissipation mass factors (as [`ElementData::kappa`]).
    pub kappa: [T; 2],
    /// The map from 3D (of a lane group: its first element's; the kernel reads none).
    pub map: PlanarMap,
}

/// Configuration of a planar element: end positions and in-plane directors `s`, `t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PConfig<T: Lane = f64> {
    /// Positions.
    pub r: [Vector2<T>; 2],
    /// Directors `[l][0] = s`, `[l][1] = t`.
    pub d: [[Vector2<T>; 2]; 2],
}

impl<T: Lane> PConfig<T> {
    #[inline(always)]
    fn mean(&self, o: &PConfig<T>) -> PConfig<T> {
        let half = T::splat(0.5);
        let m = |a: &Vector2<T>, b: &Vector2<T>| (a + b) * half;
        PConfig {
            r: [m(&self.r[0], &o.r[0]), m(&self.r[1], &o.r[1])],
            d: [
                [m(&self.d[0][0], &o.d[0][0]), m(&self.d[0][1], &o.d[0][1])],
                [m(&self.d[1][0], &o.d[1][0]), m(&self.d[1][1], &o.d[1][1])],
            ],
        }
    }
}

/// State of a planar element at time level `n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PState<T: Lane = f64> {
    /// Configuration.
    pub cfg: PConfig<T>,
    /// Translational end velocities.
    pub v: [Vector2<T>; 2],
    /// Velocity of director `s` per end.
    pub vs: [Vector2<T>; 2],
}

/// Increment of a planar element.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PIncrement<T: Lane = f64> {
    /// `u^l`.
    pub u: [Vector2<T>; 2],
    /// Cayley increments about the normal.
    pub theta: [T; 2],
    /// Dissipative velocity corrections.
    pub g: [Vector2<T>; 2],
}

impl PIncrement {
    /// Reads the increment from a planar element-local vector.
    pub fn from_local(x: &PElemVec) -> Self {
        let v = |i: usize| V2::new(x[i], x[i + 1]);
        Self {
            u: [v(pu_idx(0)), v(pu_idx(1))],
            theta: [x[pth_idx(0)], x[pth_idx(1)]],
            g: [v(pg_idx(0)), v(pg_idx(1))],
        }
    }
    /// Writes the increment into a planar element-local vector.
    pub fn to_local(&self) -> PElemVec {
        let mut x = PElemVec::zeros();
        for l in 0..2 {
            x.fixed_rows_mut::<2>(pu_idx(l)).copy_from(&self.u[l]);
            x[pth_idx(l)] = self.theta[l];
            x.fixed_rows_mut::<2>(pg_idx(l)).copy_from(&self.g[l]);
        }
        x
    }
}

/// Builds the planar data of an element of a planar model (the scene has checked that the
/// plane's normal is a principal axis of the section, or that the section is isotropic,
/// and that the intrinsic curvature `curvature` — material components, as
/// [`crate::model::ShapeSetup::curvature`] — bends about the normal).
pub fn planar_data(
    data: &ElementData,
    reference: &Config,
    plane: Plane,
    curvature: &Vec3,
) -> PlanarData {
    let ref_triad = &reference.d[0];
    let k = plane.normal;
    let map0 = PlanarMap {
        axes: [(k + 1) % 3, (k + 2) % 3],
        normal: k,
        coef: [1.0, 0.0],
    };
    let p = &data.props;
    // Components of the normal along d1, d2: the transverse director is the other one.
    let (n1, n2) = (ref_triad[(k, 0)], ref_triad[(k, 1)]);
    let isotropic = p.c_omega[(0, 1)] == 0.0
        && p.c_omega[(0, 0)] == p.c_omega[(1, 1)]
        && p.c_gamma[0] == p.c_gamma[1]
        && p.i_rho[(0, 1)] == 0.0
        && p.i_rho[(0, 0)] == p.i_rho[(1, 1)];
    let (coef, m) = if n1.abs() <= 1e-9 {
        ([1.0, 0.0], 0) // d1 in the plane, d2 = ±n
    } else if n2.abs() <= 1e-9 {
        ([0.0, 1.0], 1) // d2 in the plane, d1 = ±n
    } else {
        assert!(
            isotropic,
            "planar element with a tilted anisotropic section"
        );
        // Isotropic and tilted: s = unit in-plane combination of d1, d2 (⊥ n).
        let nn = (n1 * n1 + n2 * n2).sqrt();
        ([-n2 / nn, n1 / nn], 0)
    };
    let nidx = 1 - m;
    let map = PlanarMap { coef, ..map0 };
    let (i_s, ei) = (p.i_rho[(m, m)], p.c_omega[(nidx, nidx)]);
    let mut pd = PlanarData {
        h: p.h,
        a_rho: p.a_rho,
        i_s,
        i_amax: p.i_rho.amax(),
        c: Vector3::new(p.c_gamma[m], p.c_gamma[2], ei),
        eps0: Vector3::zeros(),
        damping: p.damping,
        rot_free: data.rot_free,
        kappa: data.kappa(),
        map,
    };
    let cfg = pd.config(reference);
    pd.eps0 = strains3(&cfg, pd.h);
    // κ is the turn about n·(s × t) (`strains3`); the intrinsic curvature's spatial
    // vector `Λ°K` lies along the normal.
    let orient = cross2(&cfg.d[0][0], &cfg.d[0][1]).signum();
    pd.eps0[2] += orient * (ref_triad * curvature)[k];
    pd
}

impl PlanarData {
    /// The planar view of a 3D configuration.
    pub fn config(&self, c: &Config) -> PConfig {
        self.config_of([&c.r[0], &c.r[1]], &c.d)
    }

    /// [`Self::config`] of end positions and triads.
    #[inline]
    fn config_of(&self, r: [&Vec3; 2], d: &[Mat3; 2]) -> PConfig {
        let m = &self.map;
        let [i, j] = m.axes;
        // s = c_1 d_1 + c_2 d_2, in-plane components only.
        let s = |l: usize| {
            let k = |a: usize| m.coef[0] * d[l][(a, 0)] + m.coef[1] * d[l][(a, 1)];
            V2::new(k(i), k(j))
        };
        let t = |l: usize| V2::new(d[l][(i, 2)], d[l][(j, 2)]);
        PConfig {
            r: [m.v2(r[0]), m.v2(r[1])],
            d: [[s(0), t(0)], [s(1), t(1)]],
        }
    }

    /// The planar view of a 3D element state.
    pub fn state(&self, st: &ElementState) -> PState {
        self.state_of(
            [&st.cfg.r[0], &st.cfg.r[1]],
            &st.cfg.d,
            [&st.v[0], &st.v[1]],
            &st.vd,
        )
    }

    /// [`Self::state`] of the 3D state's pieces (end positions, triads, end velocities,
    /// director velocities), read in place.
    #[inline]
    pub fn state_of(
        &self,
        r: [&Vec3; 2],
        d: &[Mat3; 2],
        v: [&Vec3; 2],
        vd: &[[Vec3; 2]; 2],
    ) -> PState {
        let m = &self.map;
        let [i, j] = m.axes;
        let vs = |l: usize| {
            let k = |a: usize| m.coef[0] * vd[l][0][a] + m.coef[1] * vd[l][1][a];
            V2::new(k(i), k(j))
        };
        PState {
            cfg: self.config_of(r, d),
            v: [m.v2(v[0]), m.v2(v[1])],
            vs: [vs(0), vs(1)],
        }
    }
}

/// Planar strains `(Γ_s, Γ_t, κ)` of a configuration (raw, reference not subtracted).
#[inline]
pub fn strains3<T: Lane>(c: &PConfig<T>, h: T) -> Vector3<T> {
    let half = T::splat(0.5);
    let dr = (c.r[1] - c.r[0]) / h;
    let (a, b) = (&c.d[0], &c.d[1]);
    Vector3::new(
        half * (a[0] + b[0]).dot(&dr),
        half * (a[1] + b[1]).dot(&dr),
        (a[1].dot(&b[0]) - a[0].dot(&b[1])) * (half / h),
    )
}

/// `B = ∂(Γ_s, Γ_t, κ)/∂Φ`: row `k`, field `p` gives a 2-vector.
type PGrad<T> = [[Vector2<T>; NF]; 3];

#[inline]
fn gradient<T: Lane>(c: &PConfig<T>, h: T) -> PGrad<T> {
    let half = T::splat(0.5);
    let z = zeros::<T, 2, 1>();
    let mut bm = [[z; NF]; 3];
    let dr = (c.r[1] - c.r[0]) / h;
    let (a, b) = (&c.d[0], &c.d[1]);
    for i in 0..2 {
        let di = (a[i] + b[i]) * half;
        bm[i][R0] = -di / h;
        bm[i][R1] = di / h;
        bm[i][dfield(0, i)] = dr * half;
        bm[i][dfield(1, i)] = dr * half;
    }
    // κ = (t_0·s_1 − s_0·t_1)/(2h)
    let s = half / h;
    bm[2][dfield(0, 1)] = b[0] * s;
    bm[2][dfield(1, 0)] = a[1] * s;
    bm[2][dfield(0, 0)] = b[1] * -s;
    bm[2][dfield(1, 1)] = a[0] * -s;
    bm
}

/// Hessian of `S·ε` (scalar 6×6, times `I₂`).
#[inline]
fn hessian<T: Lane>(sv: &Vector3<T>, h: T) -> SMatrix<T, NF, NF> {
    let mut hs = zeros::<T, NF, NF>();
    let c = T::splat(0.5) / h;
    for i in 0..2 {
        let n = sv[i] * c;
        for p in [dfield(0, i), dfield(1, i)] {
            hs[(R1, p)] += n;
            hs[(p, R1)] += n;
            hs[(R0, p)] -= n;
            hs[(p, R0)] -= n;
        }
    }
    let m = sv[2] * c;
    let (t0, s1, s0, t1) = (dfield(0, 1), dfield(1, 0), dfield(0, 0), dfield(1, 1));
    hs[(t0, s1)] += m;
    hs[(s1, t0)] += m;
    hs[(s0, t1)] -= m;
    hs[(t1, s0)] -= m;
    hs
}

/// What the planar kinematic update gives.
#[derive(Clone, Copy, Debug)]
pub struct PKinematics<T: Lane = f64> {
    /// Configuration at `n+1`.
    pub cfg1: PConfig<T>,
    /// Mid-point configuration.
    pub mid: PConfig<T>,
    /// `(I − ½θ n̂)⁻¹` restricted to the plane, per end.
    pub amat: [Matrix2<T>; 2],
    /// Planar strains at `n`.
    pub eps_n: Vector3<T>,
    /// Planar strains at `n+1`.
    pub eps1: Vector3<T>,
    /// Translational velocities at `n+1`.
    pub v1: [Vector2<T>; 2],
    /// Velocities of `s` at `n+1`.
    pub vs1: [Vector2<T>; 2],
    /// Director dissipative velocity `w` of `s`.
    pub w: Vector2<T>,
    /// Local dissipation inputs ([`kinematics`] only: default for
    /// [`kinematics_core`] and for lanes).
    pub inputs: LocalInputs,
}

/// `cay(θ n)` on the plane: `(c, s)` with `c = (1 − θ²/4)/(1 + θ²/4)`, `s = θ/(1 + θ²/4)`.
#[inline(always)]
pub fn cay2<T: Lane>(theta: T) -> (T, T) {
    let one = T::one();
    let q = T::splat(0.25) * theta * theta;
    let den = one / (one + q);
    ((one - q) * den, theta * den)
}

/// Rotates an in-plane vector by `(cos φ, sin φ)`.
#[inline(always)]
pub fn rotate<T: Lane>(cs: (T, T), a: &Vector2<T>) -> Vector2<T> {
    Vector2::new(cs.0 * a.x - cs.1 * a.y, cs.1 * a.x + cs.0 * a.y)
}

/// Planar kinematic update (the restriction of [`super::kinematics`]).
pub fn kinematics(
    pd: &PlanarData,
    st: &PState,
    eps_n: &Vector3<f64>,
    inc: &PIncrement,
    c_nu: f64,
    dt: f64,
) -> PKinematics {
    let mut kin = kinematics_core(pd, st, eps_n, inc, c_nu, dt);
    kin.inputs = local_inputs(pd, st, &kin);
    kin
}

/// The local dissipation inputs of a kinematic update (speeds, strain-increment energies).
fn local_inputs(pd: &PlanarData, st: &PState, kin: &PKinematics) -> LocalInputs {
    let vh_n = 0.5 * (st.v[0] + st.v[1]);
    let vh_1 = 0.5 * (kin.v1[0] + kin.v1[1]);
    let vsh_n = 0.5 * (st.vs[0] + st.vs[1]);
    let vsh_1 = 0.5 * (kin.vs1[0] + kin.vs1[1]);
    let de = kin.eps1 - kin.eps_n;
    let nu = |x: &V2| ((pd.i_s * x.dot(x)).max(0.0) / pd.a_rho).sqrt();
    LocalInputs {
        v_n: vh_n.norm(),
        v_n1: vh_1.norm(),
        nu_n: nu(&vsh_n),
        nu_n1: nu(&vsh_1),
        x_gamma: pd.c[0] * de[0] * de[0] + pd.c[1] * de[1] * de[1],
        x_omega: pd.c[2] * de[2] * de[2],
    }
}

/// [`kinematics`] without the local dissipation inputs (left at their default): what the
/// frozen-scalar residual and tangent need.
#[inline]
pub fn kinematics_core<T: Lane>(
    pd: &PlanarData<T>,
    st: &PState<T>,
    eps_n: &Vector3<T>,
    inc: &PIncrement<T>,
    c_nu: T,
    dt: f64,
) -> PKinematics<T> {
    kinematics_at(
        pd,
        st,
        eps_n,
        inc,
        |ksum| c_nu / (T::one() + ksum * c_nu),
        dt,
    )
}

/// [`kinematics_core`] with the director factor `φ = c_ν/(1 + K c_ν)` given as a function
/// of `K` (as the 3D kernel's).
#[inline(always)]
fn kinematics_at<T: Lane>(
    pd: &PlanarData<T>,
    st: &PState<T>,
    eps_n: &Vector3<T>,
    inc: &PIncrement<T>,
    phi: impl FnOnce(T) -> T,
    dt: f64,
) -> PKinematics<T> {
    let (two, half, dt) = (T::splat(2.0), T::splat(0.5), T::splat(dt));
    let rot = [cay2(inc.theta[0]), cay2(inc.theta[1])];
    let d = &st.cfg.d;
    let cfg1 = PConfig {
        r: [st.cfg.r[0] + inc.u[0], st.cfg.r[1] + inc.u[1]],
        d: [
            [rotate(rot[0], &d[0][0]), rotate(rot[0], &d[0][1])],
            [rotate(rot[1], &d[1][0]), rotate(rot[1], &d[1][1])],
        ],
    };
    let mid = st.cfg.mean(&cfg1);
    let eps1 = strains3(&cfg1, pd.h);
    let v1 = [
        inc.u[0] * two / dt - st.v[0] - inc.g[0] * two,
        inc.u[1] * two / dt - st.v[1] - inc.g[1] * two,
    ];
    let kappa = pd.kappa;
    let ksum = kappa[0] + kappa[1];
    let dd = [cfg1.d[0][0] - st.cfg.d[0][0], cfg1.d[1][0] - st.cfg.d[1][0]];
    let y = (dd[0] + dd[1]) / dt;
    let w = y * phi(ksum);
    let vs1 = [
        dd[0] * two / dt - st.vs[0] - w * (two * kappa[0]),
        dd[1] * two / dt - st.vs[1] - w * (two * kappa[1]),
    ];
    // (I − ½θ n̂)⁻¹ on the plane, from the Cayley factors: 1/(1 + θ²/4) = (1 + c)/2.
    let am = |l: usize| {
        let (den, th) = (half * (T::one() + rot[l].0), inc.theta[l]);
        Matrix2::new(den, -half * th * den, half * th * den, den)
    };
    let amat = [am(0), am(1)];
    PKinematics {
        cfg1,
        mid,
        amat,
        eps_n: *eps_n,
        eps1,
        v1,
        vs1,
        w,
        inputs: LocalInputs::default(),
    }
}

/// Planar twin of [`super::consistent_scalars`].
pub fn consistent_scalars(
    pd: &PlanarData,
    st: &PState,
    eps_n: &Vector3<f64>,
    inc: &PIncrement,
    k: &StepConsts,
) -> (FrozenScalars, LocalScalars, PKinematics) {
    consistent_scalars_near(pd, st, eps_n, inc, k, f64::NAN)
}

/// Planar twin of [`super::consistent_scalars_near`].
pub fn consistent_scalars_near(
    pd: &PlanarData,
    st: &PState,
    eps_n: &Vector3<f64>,
    inc: &PIncrement,
    k: &StepConsts,
    c_nu_ref: f64,
) -> (FrozenScalars, LocalScalars, PKinematics) {
    let c_nu = consistent_director_factor(pd, st, eps_n, inc, k, c_nu_ref);
    consistent_scalars_at(
        pd,
        st,
        kinematics_core(pd, st, eps_n, inc, c_nu, k.dt),
        k,
        c_nu,
    )
}

/// Planar twin of [`super::consistent_director_factor`].
pub fn consistent_director_factor(
    pd: &PlanarData,
    st: &PState,
    eps_n: &Vector3<f64>,
    inc: &PIncrement,
    k: &StepConsts,
    c_nu_ref: f64,
) -> f64 {
    if !k.scheme.director_dissipation() {
        return 0.0;
    }
    let dt_h = k.dt / pd.h;
    // The same root solve as the 3D kernel (plain iteration oscillates at reversals).
    let law = |c: f64| {
        let kin = kinematics(pd, st, eps_n, inc, c, k.dt);
        local_scalars(&k.scheme, &kin.inputs, pd.a_rho, dt_h).c_nu(&kin.inputs)
    };
    let ksum = pd.kappa[0] + pd.kappa[1];
    let c_min = if ksum > 0.0 {
        -1.0 / ksum
    } else {
        f64::NEG_INFINITY
    };
    super::director_factor::solve_fixed_point_near(law, c_min, c_nu_ref)
}

/// Planar twin of [`super::consistent_scalars_at`].
pub fn consistent_scalars_at(
    pd: &PlanarData,
    st: &PState,
    mut kin: PKinematics,
    k: &StepConsts,
    c_nu: f64,
) -> (FrozenScalars, LocalScalars, PKinematics) {
    let dt_h = k.dt / pd.h;
    kin.inputs = local_inputs(pd, st, &kin);
    let mut loc = local_scalars(&k.scheme, &kin.inputs, pd.a_rho, dt_h);
    // Kelvin–Voigt material damping (as the 3D kernel): β += 2η/Δt.
    let kv = 2.0 * pd.damping / k.dt;
    loc.beta_gamma += kv;
    loc.beta_omega += kv;
    let frozen = FrozenScalars {
        beta_gamma: loc.beta_gamma,
        beta_omega: loc.beta_omega,
        c_v: loc.c_v(&kin.inputs),
        c_nu,
    };
    (frozen, loc, kin)
}

/// Gross-force weight (as the 3D kernel's `GROSS_WEIGHT`).
const GROSS_WEIGHT: f64 = 1e-4;

/// Output of [`residual_tangent`] (one entry per lane for a [`Lane`] type).
#[derive(Clone, Debug)]
pub struct PElementEval<T: Lane = f64> {
    /// Residual.
    pub r: PElemVec<T>,
    /// Row scales (as the 3D kernel's).
    pub scale: PElemVec<T>,
    /// Tangent (zero when not requested).
    pub k: PElemMat<T>,
}

impl<T: Lane> PElementEval<T> {
    /// All zero.
    pub fn zeros() -> Self {
        Self {
            r: zeros(),
            scale: zeros(),
            k: zeros(),
        }
    }
}

/// Planar element residual (and tangent if `want_tangent`) for frozen scalars: the
/// planar rows of [`super::residual_tangent`].
pub fn residual_tangent(
    pd: &PlanarData,
    st: &PState,
    kin: &PKinematics,
    s: &FrozenScalars,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
) -> PElementEval {
    let mut out = PElementEval::zeros();
    residual_tangent_into(pd, st, kin, s, k, trans_diss, want_tangent, &mut out);
    out
}

/// [`residual_tangent`] into a caller's buffer, for one element (`f64`) or four (lanes).
/// Without translational dissipation the `g` rows and columns of `out` are left as they
/// were (there are no `g` unknowns); with it the tangent is cleared first.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn residual_tangent_into<T: Lane>(
    pd: &PlanarData<T>,
    st: &PState<T>,
    kin: &PKinematics<T>,
    s: &FrozenScalars<T>,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
    out: &mut PElementEval<T>,
) {
    let c = T::splat;
    let (half, h, dt) = (c(0.5), pd.h, c(k.dt));
    let mean = match k.scheme.stress_rule() {
        StressRule::MeanOfStrains => (kin.eps_n + kin.eps1) * half,
        StressRule::MidpointStrain => strains3(&kin.mid, h),
    } - pd.eps0;
    let de = kin.eps1 - kin.eps_n;
    let sstar = Vector3::new(
        pd.c[0] * (mean[0] + half * s.beta_gamma * de[0]),
        pd.c[1] * (mean[1] + half * s.beta_gamma * de[1]),
        pd.c[2] * (mean[2] + half * s.beta_omega * de[2]),
    );
    let b_mid = gradient(&kin.mid, h);
    // Stress forces h Bᵀ S* and their round-off floor (as `stress_force_floor`), over the
    // nonzero entries of B only.
    let eps_abs = ((kin.eps_n + kin.eps1) * half).map(T::abs) + pd.eps0.map(T::abs);
    let gross = pd.c.component_mul(&eps_abs) * (c(GROSS_WEIGHT) * h);
    let mut f = [zeros::<T, 2, 1>(); NF];
    let mut f_gross = [T::zero(); NF];
    for i in 0..2 {
        let (hs, g) = (h * sstar[i], gross[i]);
        for p in [R0, R1, dfield(0, i), dfield(1, i)] {
            f[p] += b_mid[i][p] * hs;
            f_gross[p] += amax2(&b_mid[i][p]) * g;
        }
    }
    let (hs, g) = (h * sstar[2], gross[2]);
    for p in 2..NF {
        f[p] += b_mid[2][p] * hs;
        f_gross[p] += amax2(&b_mid[2][p]) * g;
    }
    let stress_scale = [
        amax2(&f[R0]).max(f_gross[R0]),
        amax2(&f[R1]).max(f_gross[R1]),
    ];
    let mut inertia_r = [zeros::<T, 2, 1>(); 2];
    for l in 0..2 {
        for m in 0..2 {
            inertia_r[l] += (kin.v1[m] - st.v[m]) * (pd.a_rho * h * c(M2[l][m]) / dt);
        }
    }
    let mut fd_scale = [T::zero(); 2];
    for l in 0..2 {
        let fs = dfield(l, 0);
        let mut fi = zeros::<T, 2, 1>();
        for m in 0..2 {
            fi += (kin.vs1[m] - st.vs[m]) * (h * c(M2[l][m]) * pd.i_s / dt);
        }
        let rate = h * pd.i_amax * (amax2(&st.vs[l]) + amax2(&kin.vs1[l])) / dt;
        fd_scale[l] = amax2(&fi)
            .max(amax2(&f[fs]))
            .max(rate)
            .max(f_gross[fs])
            .max(amax2(&f[dfield(l, 1)]))
            .max(f_gross[dfield(l, 1)]);
        f[fs] += fi;
    }
    let (r, scale) = (&mut out.r, &mut out.scale);
    for l in 0..2 {
        let fr = f[l] + inertia_r[l];
        r[pu_idx(l)] = fr.x;
        r[pu_idx(l) + 1] = fr.y;
        let dm = &kin.mid.d[l];
        r[pth_idx(l)] = cross2(&dm[0], &f[dfield(l, 0)]) + cross2(&dm[1], &f[dfield(l, 1)]);
        let momentum_rate = pd.a_rho * h * (amax2(&st.v[l]) + amax2(&kin.v1[l])) / dt;
        let su = stress_scale[l].max(amax2(&inertia_r[l])).max(momentum_rate);
        // The normal director (norm 1) is among the 3D kernel's mid-point directors.
        // √ of the largest square: the largest norm, bit for bit (√ is monotone).
        let dnorm = dm[0]
            .dot(&dm[0])
            .max(dm[1].dot(&dm[1]))
            .max(T::one())
            .sqrt();
        scale[pu_idx(l)] = su;
        scale[pu_idx(l) + 1] = su;
        scale[pth_idx(l)] = fd_scale[l] * dnorm;
    }
    if trans_diss {
        let vsum = (st.v[0] + st.v[1]) * half + (kin.v1[0] + kin.v1[1]) * half;
        let b = vsum * (half * h * pd.a_rho * s.c_v);
        let gm = |m: usize| (kin.cfg1.r[m] - st.cfg.r[m]) / dt - (st.v[m] + kin.v1[m]) * half;
        let gm = [gm(0), gm(1)];
        let piece = |m: usize| amax2(&((kin.cfg1.r[m] - st.cfg.r[m]) / dt)) + amax2(&gm[m]);
        let pieces = half * h * pd.a_rho * s.c_v.abs() * (piece(0) + piece(1));
        for l in 0..2 {
            let mut mg = zeros::<T, 2, 1>();
            for m in 0..2 {
                mg += gm[m] * (pd.a_rho * h * c(M2[l][m]));
            }
            let rg = mg - b;
            r[pg_idx(l)] = rg.x;
            r[pg_idx(l) + 1] = rg.y;
            let momentum =
                (half * pd.a_rho * h * amax2(&st.v[l]).max(amax2(&kin.v1[l]))).max(pieces);
            let sc = amax2(&mg).max(amax2(&b)).max(momentum);
            scale[pg_idx(l)] = sc;
            scale[pg_idx(l) + 1] = sc;
        }
    }
    if want_tangent {
        if trans_diss {
            out.k = zeros();
        }
        tangent(pd, kin, s, k, trans_diss, &sstar, &b_mid, &f, &mut out.k);
    }
}

/// `max(|x|, |y|)` with a plain compare (as the 3D kernel's `amax3`: a NaN entry makes the
/// residual NaN, which fails the Newton test whatever the scale).
#[inline(always)]
fn amax2<T: Lane>(v: &Vector2<T>) -> T {
    v.x.abs().max_gt(v.y.abs())
}

/// Local column of field `p`'s unknown: positions 2 columns at `pu_idx`, directors the
/// single `θ` column of their end.
#[inline(always)]
const fn field_end(p: usize) -> usize {
    match p {
        R0 => 0,
        R1 => 1,
        _ => (p - 2) / 2,
    }
}

/// The reduced strain gradient `B̃` (3 rows × the 6 columns u0 u0 θ0 u1 u1 θ1) of a
/// gradient `b`: position fields as they are, director fields through their `θ` column
/// along `dir` (`δd = δθ dir`).
#[inline(always)]
fn reduced<T: Lane>(b: &PGrad<T>, dir: &[Vector2<T>; NF]) -> SMatrix<T, 3, 6> {
    let mut bt = zeros::<T, 3, 6>();
    for kk in 0..3 {
        for l in 0..2 {
            bt[(kk, pu_idx(l))] = b[kk][l].x;
            bt[(kk, pu_idx(l) + 1)] = b[kk][l].y;
        }
        for p in 2..NF {
            bt[(kk, pth_idx(field_end(p)))] += b[kk][p].dot(&dir[p]);
        }
    }
    bt
}

/// `aᵀ diag(w) b` of two reduced gradients (6 × 6).
#[inline(always)]
fn weighted_gram<T: Lane>(
    a: &SMatrix<T, 3, 6>,
    w: [T; 3],
    b: &SMatrix<T, 3, 6>,
) -> SMatrix<T, 6, 6> {
    let mut out = zeros::<T, 6, 6>();
    for kk in 0..3 {
        for j in 0..6 {
            let wb = w[kk] * b[(kk, j)];
            for i in 0..6 {
                out[(i, j)] += a[(kk, i)] * wb;
            }
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn tangent<T: Lane>(
    pd: &PlanarData<T>,
    kin: &PKinematics<T>,
    s: &FrozenScalars<T>,
    k: &StepConsts,
    trans_diss: bool,
    sstar: &Vector3<T>,
    b_mid: &PGrad<T>,
    f: &[Vector2<T>; NF],
    kt: &mut PElemMat<T>,
) {
    let c = T::splat;
    let (half, two, h, dt) = (c(0.5), c(2.0), pd.h, c(k.dt));
    let b1 = match k.scheme.stress_rule() {
        StressRule::MeanOfStrains => gradient(&kin.cfg1, h),
        StressRule::MidpointStrain => *b_mid,
    };
    // Director fields: test map T = n × d_½ (δd = δθ n × d_½), trial map J = A_l T.
    let mut tvec = [zeros::<T, 2, 1>(); NF];
    let mut jvec = [zeros::<T, 2, 1>(); NF];
    for p in 2..NF {
        let (l, i) = ((p - 2) / 2, (p - 2) % 2);
        tvec[p] = perp(&kin.mid.d[l][i]);
        jvec[p] = kin.amat[l] * tvec[p];
    }
    let bt_mid = reduced(b_mid, &tvec) * h;
    let bt_1 = reduced(&b1, &jvec);
    // Material part (as the 3D kernel): ½(1+β) C B̃_1 with the mean of the strains;
    // ½ C B̃_½J + ½ β C B̃_1 with the strain of the mid-point configuration.
    let mean = k.scheme.stress_rule() == StressRule::MeanOfStrains;
    let (bg, bo) = (s.beta_gamma, s.beta_omega);
    let own = |beta_g: T, beta_o: T| {
        [
            half * beta_g * pd.c[0],
            half * beta_g * pd.c[1],
            half * beta_o * pd.c[2],
        ]
    };
    let one = T::one();
    let mut km = if mean {
        weighted_gram(&bt_mid, own(one + bg, one + bo), &bt_1)
    } else {
        weighted_gram(&bt_mid, own(one, one), &bt_1)
    };
    // (Taken for a lane group where any lane has β ≠ 0: an exact zero in the others.)
    if !mean && (bg.any_nonzero() || bo.any_nonzero()) {
        let bt_end = reduced(&gradient(&kin.cfg1, h), &jvec);
        km += weighted_gram(&bt_mid, own(bg, bo), &bt_end);
    }
    kt.fixed_view_mut::<6, 6>(0, 0).copy_from(&km);

    let mut gs = hessian(sstar, h) * (half * h);
    let two_dt2 = two / (dt * dt);
    for l in 0..2 {
        for m in 0..2 {
            gs[(l, m)] += two_dt2 * pd.a_rho * h * c(M2[l][m]);
        }
    }
    let kappa = pd.kappa;
    let ksum = kappa[0] + kappa[1];
    let dw = s.c_nu / (dt * (one + ksum * s.c_nu));
    for l in 0..2 {
        for m in 0..2 {
            let mass = h * c(M2[l][m]) * pd.i_s / dt;
            let (pl, qm) = (dfield(l, 0), dfield(m, 0));
            gs[(pl, qm)] += mass * two / dt;
            for qq in 0..2 {
                let x = mass * two * kappa[m] * dw;
                gs[(pl, dfield(qq, 0))] -= T::select_or_zero(pd.rot_free[qq], x);
            }
        }
    }
    for pf in 0..NF {
        for qf in 0..NF {
            let g = gs[(pf, qf)];
            let (lp, lq) = (field_end(pf), field_end(qf));
            match (pf < 2, qf < 2) {
                (true, true) => {
                    kt[(pu_idx(lp), pu_idx(lq))] += g;
                    kt[(pu_idx(lp) + 1, pu_idx(lq) + 1)] += g;
                }
                (true, false) => {
                    kt[(pu_idx(lp), pth_idx(lq))] += g * jvec[qf].x;
                    kt[(pu_idx(lp) + 1, pth_idx(lq))] += g * jvec[qf].y;
                }
                (false, true) => {
                    kt[(pth_idx(lp), pu_idx(lq))] += g * tvec[pf].x;
                    kt[(pth_idx(lp), pu_idx(lq) + 1)] += g * tvec[pf].y;
                }
                (false, false) => {
                    kt[(pth_idx(lp), pth_idx(lq))] += g * tvec[pf].dot(&jvec[qf]);
                }
            }
        }
    }
    // Projection term: d/dθ of Σ_i (d_{i,½} × f_i)·n at fixed f.
    for l in 0..2 {
        let mut x = T::zero();
        for i in 0..2 {
            x += cross2(&jvec[dfield(l, i)], &f[dfield(l, i)]);
        }
        kt[(pth_idx(l), pth_idx(l))] += half * x;
    }
    if trans_diss {
        let cv = half * h * pd.a_rho * s.c_v;
        for l in 0..2 {
            for m in 0..2 {
                let mm = pd.a_rho * h * c(M2[l][m]);
                for cc in 0..2 {
                    kt[(pu_idx(l) + cc, pg_idx(m) + cc)] += -two * mm / dt;
                    kt[(pg_idx(l) + cc, pu_idx(m) + cc)] += -cv / dt;
                    kt[(pg_idx(l) + cc, pg_idx(m) + cc)] += mm + cv;
                }
            }
        }
    }
}

/// Planar twin of [`super::monolithic_correction`] (over the planar unknowns marked
/// `active`; `scalar_correction` with both factors in closed form). `s` and `kin`
/// are the consistent scalars at the iterate and their kinematics, as
/// [`consistent_scalars`] returns them.
#[allow(clippy::too_many_arguments)]
pub fn monolithic_correction(
    pd: &PlanarData,
    st: &PState,
    s: &FrozenScalars,
    kin: &PKinematics,
    k: &StepConsts,
    trans_diss: bool,
    active: &[bool; NDOF_P],
    kt: &mut PElemMat,
) {
    let c = monolithic_terms(pd, st, s, kin, k, trans_diss, active);
    super::scalar_correction(&c.dsigma, &c.d_r, active, c.varies, kt);
}

/// Planar twin of [`super::monolithic_terms`].
#[allow(clippy::too_many_arguments)]
pub fn monolithic_terms(
    pd: &PlanarData,
    st: &PState,
    s: &FrozenScalars,
    kin: &PKinematics,
    k: &StepConsts,
    trans_diss: bool,
    active: &[bool; NDOF_P],
) -> super::ScalarCorrection<NDOF_P> {
    let dsigma = scalar_gradient(pd, st, kin, s, k);
    let varies = super::scalars_varying(&dsigma, active);
    let d_r = residual_scalar_derivatives(pd, st, kin, k, trans_diss, varies);
    super::ScalarCorrection {
        dsigma,
        d_r,
        varies,
    }
}

/// Planar twin of [`super::scalar_gradient::scalar_gradient`]: `∂σ/∂x_j` (row `j`) over
/// the planar unknowns, at the kinematics `kin` of the consistent scalars `s`. The
/// director speed is that of `s` alone: `P₂ = Iρ_s Y·Y`, `P₁ = 2 Iρ_s Y·m`.
pub(crate) fn scalar_gradient(
    pd: &PlanarData,
    st: &PState,
    kin: &PKinematics,
    s: &FrozenScalars,
    k: &StepConsts,
) -> [[f64; 4]; NDOF_P] {
    use super::scalar_gradient::{
        chain, needed_numbers, sigma_over_inputs, W_P1, W_P2, W_V, W_XG, W_XO,
    };
    let (h, dt) = (pd.h, k.dt);
    let y = director_rate(st, kin, dt);
    let m = 0.5 * (st.vs[0] + st.vs[1]);
    let p2 = pd.i_s * y.dot(&y);
    let p1 = 2.0 * pd.i_s * y.dot(&m);
    let dsigma_dw = sigma_over_inputs(
        k,
        &kin.inputs,
        pd.a_rho,
        h,
        pd.kappa[0] + pd.kappa[1],
        s.c_nu,
        [p2, p1],
    );
    // Only the gradients of the numbers some scalar depends on (as in 3D).
    let needed = needed_numbers(&dsigma_dw);
    let mut dw = [[0.0f64; NDOF_P]; 5];
    let vh = 0.5 * (kin.v1[0] + kin.v1[1]);
    let vn = vh.norm();
    if needed[W_V] && vn > 0.0 {
        let vhat = vh / vn;
        for l in 0..2 {
            for c in 0..2 {
                dw[W_V][pu_idx(l) + c] = vhat[c] / dt;
                dw[W_V][pg_idx(l) + c] = -vhat[c];
            }
        }
    }
    // ∂d^l_{i,n+1}/∂θ_l = A_l (n × d^l_{i,½}).
    let jvec = |l: usize, i: usize| kin.amat[l] * perp(&kin.mid.d[l][i]);
    // X_Γ = Σ c_k Δ_k² (k = 0, 1), X_Ω = c_2 Δ_2², through the strains at n+1.
    let de = kin.eps1 - kin.eps_n;
    let b_end = (needed[W_XG] || needed[W_XO]).then(|| gradient(&kin.cfg1, h));
    for (wi, rows) in [(W_XG, 0..2), (W_XO, 2..3)] {
        let Some(b_end) = b_end.as_ref().filter(|_| needed[wi]) else {
            continue;
        };
        for kk in rows {
            let coef = 2.0 * pd.c[kk] * de[kk];
            for l in 0..2 {
                for c in 0..2 {
                    dw[wi][pu_idx(l) + c] += coef * b_end[kk][l][c];
                }
                for i in 0..2 {
                    dw[wi][pth_idx(l)] += coef * b_end[kk][dfield(l, i)].dot(&jvec(l, i));
                }
            }
        }
    }
    // P₂, P₁ through Y (∂Y/∂s^l_{n+1} = I/Δt).
    if needed[W_P2] || needed[W_P1] {
        for l in 0..2 {
            let j = jvec(l, 0) / dt;
            dw[W_P2][pth_idx(l)] += 2.0 * pd.i_s * y.dot(&j);
            dw[W_P1][pth_idx(l)] += 2.0 * pd.i_s * m.dot(&j);
        }
    }
    chain(&dsigma_dw, &dw, &needed)
}

/// `Y = Σ_l (s^l_{n+1} − s^l_n)/Δt`: the rate of `s` the director factor scales.
fn director_rate(st: &PState, kin: &PKinematics, dt: f64) -> V2 {
    (kin.cfg1.d[0][0] - st.cfg.d[0][0] + kin.cfg1.d[1][0] - st.cfg.d[1][0]) / dt
}

/// Planar twin of [`super::scalar_gradient::residual_scalar_derivatives`]: `∂R/∂σ_i` of
/// the planar residual for `σ = (β_Γ, β_Ω, c_v, φ)` at the kinematics `kin`, those
/// marked in `which` only (the others are zero).
pub(crate) fn residual_scalar_derivatives(
    pd: &PlanarData,
    st: &PState,
    kin: &PKinematics,
    k: &StepConsts,
    trans_diss: bool,
    which: [bool; 4],
) -> [PElemVec; 4] {
    let (h, dt) = (pd.h, k.dt);
    let project = |f: &[V2; NF]| {
        let mut r = PElemVec::zeros();
        for l in 0..2 {
            r.fixed_rows_mut::<2>(pu_idx(l)).copy_from(&f[l]);
            let dm = &kin.mid.d[l];
            r[pth_idx(l)] = cross2(&dm[0], &f[dfield(l, 0)]) + cross2(&dm[1], &f[dfield(l, 1)]);
        }
        r
    };
    let mut out = [PElemVec::zeros(); 4];
    if which[0] || which[1] {
        let b_mid = gradient(&kin.mid, h);
        let de = kin.eps1 - kin.eps_n;
        let forces = |rows: std::ops::Range<usize>| {
            let mut f = [V2::zeros(); NF];
            for kk in rows {
                let hs = h * 0.5 * pd.c[kk] * de[kk];
                for (p, fp) in f.iter_mut().enumerate() {
                    *fp += b_mid[kk][p] * hs;
                }
            }
            project(&f)
        };
        if which[0] {
            out[0] = forces(0..2);
        }
        if which[1] {
            out[1] = forces(2..3);
        }
    }
    if trans_diss && which[2] {
        let vsum = 0.5 * (st.v[0] + st.v[1]) + 0.5 * (kin.v1[0] + kin.v1[1]);
        let dg = -0.5 * h * pd.a_rho * vsum;
        for l in 0..2 {
            out[2].fixed_rows_mut::<2>(pg_idx(l)).copy_from(&dg);
        }
    }
    let kappa = pd.kappa;
    if which[3] && (kappa[0] != 0.0 || kappa[1] != 0.0) {
        let y = director_rate(st, kin, dt);
        let mut f = [V2::zeros(); NF];
        for l in 0..2 {
            for m in 0..2 {
                f[dfield(l, 0)] += (h * M2[l][m] * pd.i_s / dt) * (-2.0 * kappa[m]) * y;
            }
        }
        out[3] = project(&f);
    }
    out
}

/// The 3D element-local index (of the 18) each planar local unknown stands for.
pub fn full_index(map: &PlanarMap) -> [usize; NDOF_P] {
    use super::{g_idx, th_idx, u_idx};
    std::array::from_fn(|i| {
        if i >= 6 {
            let l = (i - 6) / 2;
            g_idx(l) + map.axes[(i - 6) % 2]
        } else if i % 3 == 2 {
            th_idx(i / 3) + map.normal
        } else {
            u_idx(i / 3) + map.axes[i % 3]
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scheme::Scheme;

    /// `∂σ/∂x` where the mean end speed at `n+1` is exactly zero while it was not at `n`
    /// (translational velocity dissipation on): `|v^h_{n+1}|` has a kink there and the
    /// gradient takes its zero subgradient — every entry finite and the `g` rows (which
    /// see the scalars only through `v_{n+1}`) exactly zero. Just off the kink the same
    /// rows are nonzero, so the speed's gradient is live at this state.
    #[test]
    fn scalar_gradient_at_zero_mean_speed_takes_the_zero_subgradient() {
        let pd = PlanarData {
            h: 0.5,
            a_rho: 2.0,
            i_s: 0.01,
            i_amax: 0.01,
            c: Vector3::new(10.0, 10.0, 1.0),
            eps0: Vector3::zeros(),
            damping: 0.0,
            rot_free: [false, false],
            kappa: [0.0, 0.0],
            map: PlanarMap {
                axes: [0, 1],
                normal: 2,
                coef: [1.0, 0.0],
            },
        };
        let d = [V2::new(0.0, 1.0), V2::new(1.0, 0.0)];
        let st = PState {
            cfg: PConfig {
                r: [V2::new(0.0, 0.0), V2::new(0.5, 0.0)],
                d: [d, d],
            },
            v: [V2::new(1.0, 0.25), V2::new(1.0, 0.25)],
            vs: [V2::zeros(), V2::zeros()],
        };
        let k = StepConsts {
            dt: 0.1,
            scheme: Scheme::Edmc1 {
                chi_gamma: 0.0,
                chi_omega: 0.0,
                chi_v: 0.5,
                chi_nu: 0.0,
            },
        };
        let eps_n = strains3(&st.cfg, pd.h);
        let gradient_at = |gy: f64| {
            // v_{n+1} = 2u/Δt − v_n − 2g = 0 at u = 0, g = −v_n/2 (exactly, in binary).
            let g = V2::new(-0.5, -0.125 + gy);
            let inc = PIncrement {
                u: [V2::zeros(); 2],
                theta: [0.0; 2],
                g: [g, g],
            };
            let (s, _, kin) = consistent_scalars(&pd, &st, &eps_n, &inc, &k);
            (kin.inputs.v_n1, scalar_gradient(&pd, &st, &kin, &s, &k))
        };
        let g_rows = |grad: &[[f64; 4]; NDOF_P]| {
            (0..2)
                .flat_map(|l| (0..2).map(move |c| pg_idx(l) + c))
                .map(|j| grad[j].iter().fold(0.0f64, |m, v| m.max(v.abs())))
                .fold(0.0f64, f64::max)
        };
        let (v1, grad) = gradient_at(0.0);
        assert_eq!(v1, 0.0, "the state must sit on the kink");
        assert!(
            grad.iter().flatten().all(|v| v.is_finite()),
            "non-finite gradient at v = 0: {grad:?}"
        );
        assert_eq!(g_rows(&grad), 0.0, "{grad:?}");
        let (v1, near) = gradient_at(1e-3);
        assert!(v1 > 0.0);
        assert!(g_rows(&near) > 0.1, "{near:?}");
    }
}
