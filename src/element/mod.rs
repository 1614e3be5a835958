//! The element kernel: the only physics of the crate (its WGSL twin will be
//! `shaders/element.wgsl`).
//!
//! One call evaluates, for one two-node element and given nodal increments
//! `(u^l, θ^l, g^l)` of its two ends, the element residual (18 rows: per end `R_u`, `R_θ`,
//! then per end `R_g`) and optionally its consistent tangent (18×18), following DESIGN §3–4:
//!
//! * kinematics: `r_{n+1} = r_n + u`, `d_{n+1} = cay(θ) d_n`,
//!   `v_{n+1} = 2u/Δt − v_n − 2g`, director velocities
//!   `v_{α,n+1} = 2(d_{α,n+1} − d_{α,n})/Δt − v_{α,n} − 2κ_l w_α`;
//! * stresses from the **mean of the strains** plus the dissipative parts (EM/EDMC), or
//!   from the strains of the mid-point configuration for the plain mid-point baseline
//!   ([`StressRule`]);
//! * generalized forces on the eight vector fields projected onto `(u, θ)` with the
//!   mid-point directors (`δd = δθ × d_{n+½}`).
//!
//! The dissipation enters only through four frozen scalars ([`FrozenScalars`]); the
//! monolithic strategy re-evaluates them from the iterate and adds their linearization
//! ([`monolithic_correction`]).
//!
//! The kinematics, residual and tangent are written once, generic over the scalar
//! [`Lane`]: `f64` evaluates one element, [`crate::math::lane::F64x4`] four at a time (one
//! per lane, bit-identical to four `f64` calls; [`lanes`] packs their inputs). The CPU
//! assembly uses the four-element form for frozen scalars where the build targets AVX.

pub mod director_factor;
pub mod dissipation;
pub mod drag;
pub mod follower;
pub mod lanes;
pub mod planar;
pub mod point_mass;
pub mod rational;
pub mod scalar_gradient;
pub mod strain;

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector3, Vector6};

use crate::math::lane::{identity3, zeros, Lane};
use crate::math::{cay_with_factor, hat, hat_mul, mul_hat};
use crate::model::{CurvatureMeasure, ElementProps, Mat3, Vec3};
use crate::scheme::Scheme;
pub use crate::scheme::StressRule;
use dissipation::{local_scalars, LocalInputs, LocalScalars};
use strain::{
    raw_strains, strain_gradient, stress_hessian, Config, A0, B0, GRADIENT_FIELDS, NFIELDS, R0, R1,
};

/// Unknowns of one element: per end `u` (3), `θ` (3); then per end `g` (3).
pub const NDOF: usize = 18;
/// Element residual vector.
pub type ElemVec = SVector<f64, NDOF>;
/// Element tangent matrix.
pub type ElemMat = SMatrix<f64, NDOF, NDOF>;

/// Local row/column of `u^l` component 0.
#[inline]
pub const fn u_idx(l: usize) -> usize {
    6 * l
}
/// Local row/column of `θ^l` component 0.
#[inline]
pub const fn th_idx(l: usize) -> usize {
    6 * l + 3
}
/// Local row/column of `g^l` component 0.
#[inline]
pub const fn g_idx(l: usize) -> usize {
    12 + 3 * l
}

/// The consistent-mass pattern `[[2, 1], [1, 2]] / 6` of a two-node element (the
/// two-point rule for inertia, `K`, `L`, `J`; shared with the observers).
pub const M2: [[f64; 2]; 2] = [[2.0 / 6.0, 1.0 / 6.0], [1.0 / 6.0, 2.0 / 6.0]];

/// Constant data of one element in a run (generic over the kernel's [`Lane`]: one
/// element per lane).
#[derive(Clone, Debug, PartialEq)]
pub struct ElementData<T: Lane = f64> {
    /// Material and section constants.
    pub props: ElementProps<T>,
    /// Raw strains `(Γ°, Ω°)` of the reference configuration.
    pub eps0: Vector6<T>,
    /// Whether the directors of each end node move: its rotation is free (not clamped),
    /// driven by a time table, or free about a sliding clamp's axis (`spin`). Such an end takes its share of the director
    /// dissipation ([`ElementData::kappa`]).
    pub rot_free: [T::Flag; 2],
    /// How the element measures curvature and twist (the rational measure runs on the
    /// `f64` kernel only: [`rational`]).
    pub measure: CurvatureMeasure,
}

impl<T: Lane> ElementData<T> {
    /// Director-dissipation mass factors `κ_l` (DESIGN §4): `g_α^l = κ_l w_α` keeps
    /// `M_e g = ∫ N_l w` on the free ends: 1 on both ends when both are free, 1.5 on the
    /// free end of an element whose other end is clamped, 0 on a clamped end.
    #[inline]
    pub fn kappa(&self) -> [T; 2] {
        let [f0, f1] = self.rot_free;
        let (one, one_half, zero) = (T::splat(1.0), T::splat(1.5), T::zero());
        [
            T::choose(f0, T::choose(f1, one, one_half), zero),
            T::choose(f1, T::choose(f0, one, one_half), zero),
        ]
    }

    /// Raw strains `(Γ, Ω)` of a configuration with this element's curvature measure.
    #[inline]
    pub fn strains(&self, cfg: &Config<T>) -> Vector6<T> {
        match self.measure {
            CurvatureMeasure::Sine => strains6(cfg, self.props.h),
            CurvatureMeasure::Rational => rational::rational_strains(cfg, self.props.h),
        }
    }
}

impl ElementData {
    /// The constant data of every element of `model`, in element order: section
    /// constants, reference strains of the reference configuration, end rotations free.
    pub fn for_model(model: &crate::model::Model) -> Vec<ElementData> {
        // A clamp turned by a time table, or spinning about its sliding axis: its
        // directors move (prescribed, or free about the axis), and their velocities take
        // the director dissipation like a free end's.
        let mut turned = vec![false; model.n_nodes()];
        for d in &model.drives {
            turned[d.node] |= d.rotation != crate::model::Vec3::zeros();
        }
        for s in &model.slides {
            turned[s.node] |= s.spin;
        }
        let moves = |a: usize| !model.supports[a].rotation || turned[a];
        model
            .elements
            .iter()
            .enumerate()
            .map(|(ie, e)| {
                let cfg = Config {
                    r: [model.nodes[e.nodes[0]], model.nodes[e.nodes[1]]],
                    d: e.ref_triad,
                };
                // Raw reference strains plus the rod's intrinsic curvature and twist.
                let measure = model.curvature_measure(ie);
                let mut eps0 = match measure {
                    CurvatureMeasure::Sine => strains6(&cfg, e.props.h),
                    CurvatureMeasure::Rational => rational::rational_strains(&cfg, e.props.h),
                };
                let k = model.intrinsic_curvature(ie);
                for c in 0..3 {
                    eps0[3 + c] += k[c];
                }
                ElementData {
                    props: e.props.clone(),
                    eps0,
                    rot_free: [moves(e.nodes[0]), moves(e.nodes[1])],
                    measure,
                }
            })
            .collect()
    }
}

/// State of one element at time level `n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElementState<T: Lane = f64> {
    /// Configuration (end positions and triads).
    pub cfg: Config<T>,
    /// Translational velocities of the end nodes.
    pub v: [Vector3<T>; 2],
    /// Director velocities `v_α^{(e)l}` (index `[l][α]`, α = 0, 1).
    pub vd: [[Vector3<T>; 2]; 2],
}

/// Increments of the two end nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Increment<T: Lane = f64> {
    /// `u^l = r^l_{n+1} − r^l_n`.
    pub u: [Vector3<T>; 2],
    /// Spatial Cayley increments `θ^l`.
    pub theta: [Vector3<T>; 2],
    /// Dissipative velocity corrections `g^l` (zero unless translational dissipation).
    pub g: [Vector3<T>; 2],
}

impl Increment {
    /// Reads the increment from an element-local vector.
    pub fn from_local(x: &ElemVec) -> Self {
        let v = |i: usize| Vec3::new(x[i], x[i + 1], x[i + 2]);
        Self {
            u: [v(u_idx(0)), v(u_idx(1))],
            theta: [v(th_idx(0)), v(th_idx(1))],
            g: [v(g_idx(0)), v(g_idx(1))],
        }
    }

    /// Writes the increment into an element-local vector.
    pub fn to_local(&self) -> ElemVec {
        let mut x = ElemVec::zeros();
        for l in 0..2 {
            x.fixed_rows_mut::<3>(u_idx(l)).copy_from(&self.u[l]);
            x.fixed_rows_mut::<3>(th_idx(l)).copy_from(&self.theta[l]);
            x.fixed_rows_mut::<3>(g_idx(l)).copy_from(&self.g[l]);
        }
        x
    }
}

/// The frozen dissipation scalars of one element: `β_Γ, β_Ω` and the velocity factors
/// `c_v, c_ν` (`v_diss = c_v (v^h_n + v^h_{n+1})`, `w = c_ν (v^h_{α,n} + v^h_{α,n+1})`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrozenScalars<T: Lane = f64> {
    /// `β_Γ`.
    pub beta_gamma: T,
    /// `β_Ω`.
    pub beta_omega: T,
    /// `c_v`.
    pub c_v: T,
    /// `c_ν`.
    pub c_nu: T,
}

/// Everything the kinematic update gives for an increment and frozen scalars.
#[derive(Clone, Copy, Debug)]
pub struct Kinematics<T: Lane = f64> {
    /// Configuration at `n+1`.
    pub cfg1: Config<T>,
    /// Mid-point configuration `Φ_{n+½}`.
    pub mid: Config<T>,
    /// `(I − ½θ̂^l)⁻¹` per end.
    pub amat: [Matrix3<T>; 2],
    /// Raw strains at `n` and `n+1`.
    pub eps_n: Vector6<T>,
    /// Raw strains at `n+1`.
    pub eps1: Vector6<T>,
    /// Translational end velocities at `n+1`.
    pub v1: [Vector3<T>; 2],
    /// Director end velocities at `n+1` (`[l][α]`).
    pub vd1: [[Vector3<T>; 2]; 2],
    /// Director dissipative velocity `w_α` at the quadrature point.
    pub w: [Vector3<T>; 2],
    /// Local dissipation inputs (speeds and strain-increment energies; one element's,
    /// left at their default by [`kinematics_core`] and in lane evaluations).
    pub inputs: LocalInputs,
}

/// Per-step constants shared by all elements.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConsts {
    /// Time step.
    pub dt: f64,
    /// Scheme and its constants.
    pub scheme: Scheme,
}

fn director_speed(vh: &[Vec3; 2], i_rho: &Matrix2<f64>, a_rho: f64) -> f64 {
    let mut s = 0.0;
    for a in 0..2 {
        for b in 0..2 {
            s += i_rho[(a, b)] * vh[a].dot(&vh[b]);
        }
    }
    (s.max(0.0) / a_rho).sqrt()
}

/// `(Γ, Ω)` as one 6-vector.
#[inline]
pub fn strains6<T: Lane>(cfg: &Config<T>, h: T) -> Vector6<T> {
    let (g, o) = raw_strains(cfg, h);
    Vector6::new(g.x, g.y, g.z, o.x, o.y, o.z)
}

/// Stiffness-weighted square `x·C x` of the Γ part (0) and Ω part (1) of a strain vector.
fn strain_energies(de: &Vector6<f64>, p: &ElementProps) -> (f64, f64) {
    let dg = de.fixed_rows::<3>(0).into_owned();
    let dom = de.fixed_rows::<3>(3).into_owned();
    (
        dg.dot(&p.c_gamma.component_mul(&dg)),
        dom.dot(&(p.c_omega * dom)),
    )
}

/// Kinematic update of one element for an increment, with the director-dissipation
/// factor `c_ν` given (it enters the director velocities at `n+1`).
#[inline]
pub fn kinematics(
    data: &ElementData,
    st: &ElementState,
    eps_n: &Vector6<f64>,
    inc: &Increment,
    c_nu: f64,
    dt: f64,
) -> Kinematics {
    let mut kin = kinematics_core(data, st, eps_n, inc, c_nu, dt);
    kin.inputs = local_inputs(data, st, &kin);
    kin
}

/// The local dissipation inputs of a kinematic update (speeds and strain-increment
/// energies): what the dissipation scalars are computed from.
#[inline]
fn local_inputs(data: &ElementData, st: &ElementState, kin: &Kinematics) -> LocalInputs {
    let p = &data.props;
    let vh_n = 0.5 * (st.v[0] + st.v[1]);
    let vh_1 = 0.5 * (kin.v1[0] + kin.v1[1]);
    let vdh_n = [
        0.5 * (st.vd[0][0] + st.vd[1][0]),
        0.5 * (st.vd[0][1] + st.vd[1][1]),
    ];
    let vdh_1 = [
        0.5 * (kin.vd1[0][0] + kin.vd1[1][0]),
        0.5 * (kin.vd1[0][1] + kin.vd1[1][1]),
    ];
    let (x_gamma, x_omega) = strain_energies(&(kin.eps1 - kin.eps_n), p);
    LocalInputs {
        v_n: vh_n.norm(),
        v_n1: vh_1.norm(),
        nu_n: director_speed(&vdh_n, &p.i_rho, p.a_rho),
        nu_n1: director_speed(&vdh_1, &p.i_rho, p.a_rho),
        x_gamma,
        x_omega,
    }
}

/// [`kinematics`] without the local dissipation inputs (left at their default): what the
/// frozen-scalar residual and tangent need (they skip four square roots and the strain
/// energies).
#[inline]
pub fn kinematics_core<T: Lane>(
    data: &ElementData<T>,
    st: &ElementState<T>,
    eps_n: &Vector6<T>,
    inc: &Increment<T>,
    c_nu: T,
    dt: f64,
) -> Kinematics<T> {
    kinematics_at(
        data,
        st,
        eps_n,
        inc,
        |ksum| c_nu / (T::one() + ksum * c_nu),
        dt,
    )
}

/// [`kinematics_core`] with the factor `φ = c_ν/(1 + K c_ν)` of the director dissipative
/// velocity `w_α = φ Y_α` given as a function of `K = Σ κ_l`. The update is affine in φ
/// (so is the residual: [`scalar_gradient::residual_scalar_derivatives`]; the tests check
/// it against residuals at perturbed φ).
#[inline]
pub fn kinematics_at<T: Lane>(
    data: &ElementData<T>,
    st: &ElementState<T>,
    eps_n: &Vector6<T>,
    inc: &Increment<T>,
    phi: impl FnOnce(T) -> T,
    dt: f64,
) -> Kinematics<T> {
    let two = T::splat(2.0);
    let (rot0, amat0) = cay_with_factor(&inc.theta[0]);
    let (rot1, amat1) = cay_with_factor(&inc.theta[1]);
    let rot = [rot0, rot1];
    let cfg1 = Config {
        r: [st.cfg.r[0] + inc.u[0], st.cfg.r[1] + inc.u[1]],
        d: [rot[0] * st.cfg.d[0], rot[1] * st.cfg.d[1]],
    };
    let mid = st.cfg.mean(&cfg1);
    let eps1 = data.strains(&cfg1);
    let inv_dt = T::splat(1.0 / dt);
    let v1 = [
        inc.u[0] * two * inv_dt - st.v[0] - inc.g[0] * two,
        inc.u[1] * two * inv_dt - st.v[1] - inc.g[1] * two,
    ];
    let kappa = data.kappa();
    let ksum = kappa[0] + kappa[1];
    let phi = phi(ksum);
    // v^h_{α,n} + v^h_{α,n+1} = Y_α/(1 + K c_ν), Y_α = Σ_l (d^l_{α,n+1} − d^l_{α,n})/Δt.
    let mut w = [zeros(); 2];
    let mut vd1 = [[zeros(); 2]; 2];
    for a in 0..2 {
        let dd = [
            cfg1.d[0].column(a) - st.cfg.d[0].column(a),
            cfg1.d[1].column(a) - st.cfg.d[1].column(a),
        ];
        let y = (dd[0] + dd[1]) * inv_dt;
        w[a] = y * phi;
        for l in 0..2 {
            vd1[l][a] = dd[l] * two * inv_dt - st.vd[l][a] - w[a] * (two * kappa[l]);
        }
    }
    Kinematics {
        cfg1,
        mid,
        amat: [amat0, amat1],
        eps_n: *eps_n,
        eps1,
        v1,
        vd1,
        w,
        inputs: LocalInputs::default(),
    }
}

/// The stress-dissipation factor `β = 2η/Δt` of Kelvin–Voigt material damping with
/// retardation time `η` ([`ElementProps::damping`]): `½ β C Δε = η C Δε/Δt`.
pub fn kelvin_voigt_beta(p: &ElementProps, dt: f64) -> f64 {
    2.0 * p.damping / dt
}

/// Evaluates the scheme's local law at the state an increment produces and returns the
/// scalars consistent with it (what the staggered loop converges to and what the
/// monolithic Newton uses). The director factor `c_ν` enters the director speeds it is
/// computed from; that scalar equation is solved here to round-off
/// ([`director_factor::solve_fixed_point`]: plain iteration oscillates at
/// turning points of the director motion).
pub fn consistent_scalars(
    data: &ElementData,
    st: &ElementState,
    eps_n: &Vector6<f64>,
    inc: &Increment,
    k: &StepConsts,
) -> (FrozenScalars, LocalScalars, Kinematics) {
    consistent_scalars_near(data, st, eps_n, inc, k, f64::NAN)
}

/// [`consistent_scalars`] with the director factor on the branch of `c_nu_ref`, the
/// factor the current iterate was solved with: where its equation has several roots (at
/// a turning point of the director motion), the one nearest the reference
/// ([`director_factor::solve_fixed_point_near`]), so that the scalars follow one branch
/// from iterate to iterate instead of jumping between roots. `NaN`: no reference (as
/// [`consistent_scalars`]).
pub fn consistent_scalars_near(
    data: &ElementData,
    st: &ElementState,
    eps_n: &Vector6<f64>,
    inc: &Increment,
    k: &StepConsts,
    c_nu_ref: f64,
) -> (FrozenScalars, LocalScalars, Kinematics) {
    let c_nu = consistent_director_factor(data, st, eps_n, inc, k, c_nu_ref);
    consistent_scalars_at(
        data,
        st,
        kinematics_core(data, st, eps_n, inc, c_nu, k.dt),
        k,
        c_nu,
    )
}

/// The director factor `c_ν` of [`consistent_scalars_near`] (zero without director
/// dissipation).
pub fn consistent_director_factor(
    data: &ElementData,
    st: &ElementState,
    eps_n: &Vector6<f64>,
    inc: &Increment,
    k: &StepConsts,
    c_nu_ref: f64,
) -> f64 {
    if !k.scheme.director_dissipation() {
        return 0.0;
    }
    let p = &data.props;
    let dt_h = k.dt / p.h;
    let law = |c: f64| {
        let kin = kinematics(data, st, eps_n, inc, c, k.dt);
        local_scalars(&k.scheme, &kin.inputs, p.a_rho, dt_h).c_nu(&kin.inputs)
    };
    // The update divides by 1 + K c_ν (K = Σ κ_l): the domain is c_ν > −1/K.
    let ksum: f64 = data.kappa().iter().sum();
    let c_min = if ksum > 0.0 {
        -1.0 / ksum
    } else {
        f64::NEG_INFINITY
    };
    director_factor::solve_fixed_point_near(law, c_min, c_nu_ref)
}

/// The rest of [`consistent_scalars_near`]: the consistent scalars from the kinematics
/// [`kinematics_core`] gives at the consistent director factor `c_nu` (the four-element
/// assembly computes those in lanes; this completes them element by element).
pub fn consistent_scalars_at(
    data: &ElementData,
    st: &ElementState,
    mut kin: Kinematics,
    k: &StepConsts,
    c_nu: f64,
) -> (FrozenScalars, LocalScalars, Kinematics) {
    let p = &data.props;
    let dt_h = k.dt / p.h;
    kin.inputs = local_inputs(data, st, &kin);
    let mut loc = local_scalars(&k.scheme, &kin.inputs, p.a_rho, dt_h);
    // Kelvin–Voigt material damping: viscous stresses η C Δε/Δt = ½ (2η/Δt) C Δε add to
    // the scheme's β (its work ½ β X is part of the dissipation D).
    let kv = kelvin_voigt_beta(p, k.dt);
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

/// Generalized stresses `S* = (N*, M*)`: the strains of `rule` (mean of the strains, or
/// the strain of the mid-point configuration) plus the dissipative parts.
#[inline]
pub fn stresses<T: Lane>(
    data: &ElementData<T>,
    kin: &Kinematics<T>,
    s: &FrozenScalars<T>,
    rule: StressRule,
) -> Vector6<T> {
    let p = &data.props;
    let half = T::splat(0.5);
    let mean = match rule {
        StressRule::MeanOfStrains => (kin.eps_n + kin.eps1) * half,
        StressRule::MidpointStrain => strains6(&kin.mid, p.h),
    } - data.eps0;
    let de = kin.eps1 - kin.eps_n;
    let g = mean.fixed_rows::<3>(0) + de.fixed_rows::<3>(0) * (half * s.beta_gamma);
    let o = mean.fixed_rows::<3>(3) + de.fixed_rows::<3>(3) * (half * s.beta_omega);
    constitutive(p, &g.into_owned(), &o.into_owned())
}

/// `(N, M) = (C_Γ Γ, C_Ω Ω)` for strains measured from the reference.
fn constitutive<T: Lane>(
    p: &ElementProps<T>,
    gamma: &Vector3<T>,
    omega: &Vector3<T>,
) -> Vector6<T> {
    let n = p.c_gamma.component_mul(gamma);
    let m = p.c_omega * omega;
    Vector6::new(n.x, n.y, n.z, m.x, m.y, m.z)
}

/// Weight of the gross stress forces in the residual scale: with it, the default Newton
/// tolerance `1e-11` sits about 10× above the f64 round-off floor (`~1e-16` of the gross
/// forces) instead of below it.
pub(crate) const GROSS_WEIGHT: f64 = 1e-4;

/// Round-off floor of the stress forces on the eight fields: `GROSS_WEIGHT · h |B|ᵀ |C|
/// (|ε| + |ε0|)`, with `ε` the strains the stresses are computed from. In f64 the forces
/// are uncertain by ~1e-16 of the "gross" forces, whatever the load.
#[inline]
pub fn stress_force_floor<T: Lane>(
    data: &ElementData<T>,
    b: &strain::StrainGradient<T>,
    eps: &Vector6<T>,
) -> [T; NFIELDS] {
    let p = &data.props;
    let e = eps.map(T::abs) + data.eps0.map(T::abs);
    let n = p.c_gamma.map(T::abs).component_mul(&e.fixed_rows::<3>(0));
    let m = p.c_omega.map(T::abs) * e.fixed_rows::<3>(3);
    let gross = [n.x, n.y, n.z, m.x, m.y, m.z];
    let mut f = [T::zero(); NFIELDS];
    let weight = T::splat(GROSS_WEIGHT);
    for k in 0..6 {
        for j in 0..4 {
            let q = GRADIENT_FIELDS[k][j];
            f[q] += weight * amax3(&b[k][q]) * p.h * gross[k];
        }
    }
    f
}

/// `max_i |v_i|` of a 3-vector: nalgebra's `amax` for finite entries, with plain compares
/// instead of `f64::max`'s NaN handling (a NaN entry here makes the forces, hence the
/// residual, NaN, and the Newton test fails on the residual whatever the scale).
#[inline(always)]
pub(crate) fn amax3<T: Lane>(v: &Vector3<T>) -> T {
    let (x, y, z) = (v.x.abs(), v.y.abs(), v.z.abs());
    x.max_gt(y).max_gt(z)
}

/// Generalized stress forces `h Bᵀ S` on the eight vector fields of an element
/// (one-point rule).
#[inline]
pub fn field_forces<T: Lane>(
    b: &strain::StrainGradient<T>,
    s: &Vector6<T>,
    h: T,
) -> [Vector3<T>; NFIELDS] {
    let mut f = [zeros(); NFIELDS];
    for k in 0..6 {
        let hs = h * s[k];
        for j in 0..4 {
            let q = GRADIENT_FIELDS[k][j];
            f[q] += b[k][q] * hs;
        }
    }
    f
}

/// Elastic forces of one element at a single configuration: `h B(Φ)ᵀ C(ε(Φ) − ε°)` on the
/// eight fields, the stresses `S = C(ε(Φ) − ε°)` and the forces' round-off floor
/// ([`stress_force_floor`]). Used by the generalized-α baseline, which balances inertia
/// against the elastic forces *at* `t_{n+1}`.
pub fn elastic_field_forces(
    data: &ElementData,
    cfg: &Config,
) -> ([Vec3; NFIELDS], Vector6<f64>, [f64; NFIELDS]) {
    let p = &data.props;
    let eps = strains6(cfg, p.h);
    let de = eps - data.eps0;
    let s = constitutive(
        p,
        &de.fixed_rows::<3>(0).into_owned(),
        &de.fixed_rows::<3>(3).into_owned(),
    );
    let b = strain_gradient(cfg, p.h);
    (
        field_forces(&b, &s, p.h),
        s,
        stress_force_floor(data, &b, &eps),
    )
}

/// Derivative of [`elastic_field_forces`] with respect to the fields:
/// `∂f_p/∂Φ_q = h Σ_kk' B[k][p] C_kk' B[k'][q]ᵀ + h H_s[p, q] I₃` (material and geometric
/// stiffness; `s` the stresses at `cfg`). Block `[p][q]` is 3×3.
pub fn elastic_field_stiffness(
    data: &ElementData,
    cfg: &Config,
    s: &Vector6<f64>,
) -> [[Mat3; NFIELDS]; NFIELDS] {
    let p = &data.props;
    let h = p.h;
    let b = strain_gradient(cfg, h);
    let mut c = nalgebra::Matrix6::<f64>::zeros();
    for i in 0..3 {
        c[(i, i)] = p.c_gamma[i];
    }
    c.fixed_view_mut::<3, 3>(3, 3).copy_from(&p.c_omega);
    let hs = stress_hessian(s, h);
    std::array::from_fn(|pf| {
        std::array::from_fn(|qf| {
            let mut k = Mat3::identity() * (h * hs[(pf, qf)]);
            for (k1, row1) in b.iter().enumerate() {
                for (k2, row2) in b.iter().enumerate() {
                    if c[(k1, k2)] != 0.0 {
                        k += row1[pf] * row2[qf].transpose() * (h * c[(k1, k2)]);
                    }
                }
            }
            k
        })
    })
}

/// Output of [`residual_tangent`].
#[derive(Clone, Debug)]
pub struct ElementEval<T: Lane = f64> {
    /// Element residual.
    pub r: SVector<T, NDOF>,
    /// Absolute size of the largest force term entering each residual row (for the
    /// relative Newton tolerance).
    pub scale: SVector<T, NDOF>,
    /// Element tangent (zero when not requested).
    pub k: SMatrix<T, NDOF, NDOF>,
}

impl<T: Lane> ElementEval<T> {
    /// All zeros (a buffer for [`residual_tangent_into`]).
    pub fn zeros() -> Self {
        Self {
            r: zeros(),
            scale: zeros(),
            k: zeros(),
        }
    }
}

/// Element residual (and tangent if `want_tangent`) for frozen dissipation scalars.
/// `trans_diss` switches the `g` rows on.
pub fn residual_tangent(
    data: &ElementData,
    st: &ElementState,
    kin: &Kinematics,
    s: &FrozenScalars,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
) -> ElementEval {
    let mut out = ElementEval::zeros();
    residual_tangent_measured_into(data, st, kin, s, k, trans_diss, want_tangent, &mut out);
    out
}

/// [`residual_tangent_into`] for one element with either curvature measure (the rational
/// one through [`rational::residual_tangent_into`]).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn residual_tangent_measured_into(
    data: &ElementData,
    st: &ElementState,
    kin: &Kinematics,
    s: &FrozenScalars,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
    out: &mut ElementEval,
) {
    match data.measure {
        CurvatureMeasure::Sine => {
            residual_tangent_into(data, st, kin, s, k, trans_diss, want_tangent, out)
        }
        CurvatureMeasure::Rational => {
            rational::residual_tangent_into(data, st, kin, s, k, trans_diss, want_tangent, out)
        }
    }
}

/// [`residual_tangent`] into a caller's buffer (the assembly loop reuses one): `out.r`
/// and `out.scale` are overwritten, and `out.k` too when `want_tangent` (otherwise it is
/// left as it was), except, without translational dissipation (`trans_diss` false), its
/// `g` rows and columns: there are no such unknowns, and they are left as they were (zero
/// in a buffer from [`ElementEval::zeros`]).
#[allow(clippy::too_many_arguments)]
pub fn residual_tangent_into<T: Lane>(
    data: &ElementData<T>,
    st: &ElementState<T>,
    kin: &Kinematics<T>,
    s: &FrozenScalars<T>,
    k: &StepConsts,
    trans_diss: bool,
    want_tangent: bool,
    out: &mut ElementEval<T>,
) {
    let p = &data.props;
    let (h, dt) = (p.h, k.dt);
    let c = T::splat;
    let half = c(0.5);
    let sstar = stresses(data, kin, s, k.scheme.stress_rule());
    let b_mid = strain_gradient(&kin.mid, h);

    // Generalized forces on the eight fields: stress part h B_{n+½}ᵀ S*, then inertia.
    let mut f = field_forces(&b_mid, &sstar, h);
    // Round-off floor of the stress forces: S* is C times a difference of strains of size
    // |ε| (not |ε − ε0|), so in f64 the forces are uncertain by ~1e-16 of the "gross"
    // forces h |B|ᵀ |C| (|ε̄| + |ε0|). Stiff, barely loaded members (the arch at t = 0:
    // EA = 2e8, load 1.25) otherwise never reach a relative tolerance measured against
    // the load alone.
    let f_gross = stress_force_floor(data, &b_mid, &((kin.eps_n + kin.eps1) * half));
    let scale = &mut out.scale;
    *scale = zeros();
    let stress_scale = [
        amax3(&f[R0]).max(f_gross[R0]),
        amax3(&f[R1]).max(f_gross[R1]),
    ];
    // 1/Δt once: a division costs several multiplications' throughput, and the kernel
    // has dozens of them per element.
    let inv_dt = c(1.0 / dt);
    let mut inertia_r = [zeros(); 2];
    for l in 0..2 {
        for m in 0..2 {
            let cm = p.a_rho * h * c(M2[l][m]) * inv_dt;
            inertia_r[l] += (kin.v1[m] - st.v[m]) * cm;
        }
    }
    let mut i_rho_max = T::zero();
    for &x in p.i_rho.iter() {
        i_rho_max = i_rho_max.max(x.abs());
    }
    let mut fd_scale = [T::zero(); 2];
    for l in 0..2 {
        let base = if l == 0 { A0 } else { B0 };
        for a in 0..2 {
            let mut fi = zeros();
            for m in 0..2 {
                for b in 0..2 {
                    fi += (kin.vd1[m][b] - st.vd[m][b])
                        * (h * c(M2[l][m]) * p.i_rho[(a, b)] * inv_dt);
                }
            }
            let rate = h * i_rho_max * (amax3(&st.vd[l][a]) + amax3(&kin.vd1[l][a])) * inv_dt;
            fd_scale[l] = fd_scale[l]
                .max(amax3(&fi))
                .max(amax3(&f[base + a]))
                .max(rate)
                .max(f_gross[base + a]);
            f[base + a] += fi;
        }
        fd_scale[l] = fd_scale[l].max(amax3(&f[base + 2])).max(f_gross[base + 2]);
    }

    let r = &mut out.r;
    *r = zeros();
    let dmid = [kin.mid.d[0], kin.mid.d[1]];
    for l in 0..2 {
        let fr = f[if l == 0 { R0 } else { R1 }] + inertia_r[l];
        r.fixed_rows_mut::<3>(u_idx(l)).copy_from(&fr);
        let base = if l == 0 { A0 } else { B0 };
        let mut rt = zeros();
        for i in 0..3 {
            rt += dmid[l].column(i).cross(&f[base + i]);
        }
        r.fixed_rows_mut::<3>(th_idx(l)).copy_from(&rt);
        // Round-off floor: the inertia term is a difference of terms of size
        // Aρ h |v|/Δt, which dominate it when Δt is small.
        let momentum_rate = p.a_rho * h * (amax3(&st.v[l]) + amax3(&kin.v1[l])) * inv_dt;
        let su = stress_scale[l].max(amax3(&inertia_r[l])).max(momentum_rate);
        // The largest director length: √ of the largest square (√ is monotone and
        // correctly rounded, so this is the largest of the three norms, bit for bit).
        let sq = |i: usize| dmid[l].column(i).dot(&dmid[l].column(i));
        let dnorm = sq(0).max(sq(1)).max(sq(2)).sqrt();
        for cc in 0..3 {
            scale[u_idx(l) + cc] = su;
            scale[th_idx(l) + cc] = fd_scale[l] * dnorm;
        }
    }
    let vsum = (st.v[0] + st.v[1]) * half + (kin.v1[0] + kin.v1[1]) * half;
    if trans_diss {
        let b = vsum * (half * h * p.a_rho * s.c_v);
        for l in 0..2 {
            let mut mg = zeros();
            for m in 0..2 {
                mg += kin_g(st, kin, m, inv_dt) * (p.a_rho * h * c(M2[l][m]));
            }
            r.fixed_rows_mut::<3>(g_idx(l)).copy_from(&(mg - b));
            // The g rows balance momenta: measure them against the element's momentum,
            // not against g itself (which vanishes where nothing dissipates).
            let momentum = half * p.a_rho * h * amax3(&st.v[l]).max(amax3(&kin.v1[l]));
            // b is c_v times a difference of u/Δt and g, each possibly much larger.
            let pieces = half
                * h
                * p.a_rho
                * s.c_v.abs()
                * (0..2)
                    .map(|m| {
                        amax3(&((kin.cfg1.r[m] - st.cfg.r[m]) * inv_dt))
                            + amax3(&kin_g(st, kin, m, inv_dt))
                    })
                    .fold(T::zero(), |acc, x| acc + x);
            let momentum = momentum.max(pieces);
            for cc in 0..3 {
                scale[g_idx(l) + cc] = amax3(&mg).max(amax3(&b)).max(momentum);
            }
        }
    }

    if want_tangent {
        // The (u, θ) block is written whole by the material term (a product with β = 0,
        // which never reads it); only the g rows and columns are cleared here, column by
        // column on the contiguous (column-major) storage: a strided view's `fill` walks
        // nalgebra's element iterator, ≈ 10 instructions per entry. Without translational
        // dissipation there are no g unknowns: the g part is neither cleared nor written.
        let g_part = if trans_diss { NDOF } else { 0 };
        for (cc, col) in out
            .k
            .as_mut_slice()
            .chunks_exact_mut(NDOF)
            .take(g_part)
            .enumerate()
        {
            if cc < 12 {
                col[12..].fill(T::zero());
            } else {
                col.fill(T::zero());
            }
        }
        tangent(data, kin, s, k, trans_diss, &sstar, &b_mid, &f, &mut out.k);
    }
}

/// The `g` an element end carries, recovered from `v_{n+1} = 2u/Δt − v_n − 2g`
/// (kinematics stores `v_{n+1}`; the increment is not kept).
#[inline]
fn kin_g<T: Lane>(st: &ElementState<T>, kin: &Kinematics<T>, m: usize, inv_dt: T) -> Vector3<T> {
    // g = u/Δt − ½(v_n + v_{n+1}) and u = r_{n+1} − r_n.
    (kin.cfg1.r[m] - st.cfg.r[m]) * inv_dt - (st.v[m] + kin.v1[m]) * T::splat(0.5)
}

/// Block of the tangent a field maps to: (row/col start of its unknown, is director).
#[inline]
fn field_block(p: usize) -> (usize, Option<(usize, usize)>) {
    match p {
        R0 => (u_idx(0), None),
        R1 => (u_idx(1), None),
        2..=4 => (th_idx(0), Some((0, p - A0))),
        _ => (th_idx(1), Some((1, p - B0))),
    }
}

#[allow(clippy::too_many_arguments)]
fn tangent<T: Lane>(
    data: &ElementData<T>,
    kin: &Kinematics<T>,
    s: &FrozenScalars<T>,
    k: &StepConsts,
    trans_diss: bool,
    sstar: &Vector6<T>,
    b_mid: &strain::StrainGradient<T>,
    f: &[Vector3<T>; NFIELDS],
    kt: &mut SMatrix<T, NDOF, NDOF>,
) {
    let p = &data.props;
    let (h, dt) = (p.h, k.dt);
    let c = T::splat;
    let half = c(0.5);
    // Trial side: ∂ε/∂Φ_{n+1} = ½ B(Φ_{n+1}) for the mean of the strains, ½ B(Φ_{n+½})
    // for the strain of the mid-point configuration (the ½ is in `dmat` below).
    // (By reference: a copy of the gradient is 1.2 kB, 4.6 kB in lanes.)
    let b_end_own;
    let b1 = match k.scheme.stress_rule() {
        StressRule::MeanOfStrains => {
            b_end_own = strain_gradient(&kin.cfg1, h);
            &b_end_own
        }
        StressRule::MidpointStrain => b_mid,
    };
    // Mid-point directors d_{l,i} and the transposed Cayley factors A_lᵀ.
    // (Entry by entry: nalgebra's `into_owned` of a view goes through an iterator, slow
    // for lanes.)
    let col = |l: usize, i: usize| -> Vector3<T> {
        let m = &kin.mid.d[l];
        Vector3::new(m[(0, i)], m[(1, i)], m[(2, i)])
    };
    let dcol: [[Vector3<T>; 3]; 2] = [
        [col(0, 0), col(0, 1), col(0, 2)],
        [col(1, 0), col(1, 1), col(1, 2)],
    ];
    let amat = kin.amat;
    let at = [amat[0].transpose(), amat[1].transpose()];

    // Test-side map T (δΦ = T δq) and trial-side map J (dΦ_{n+1} = J dq) per field:
    // positions: T = J = I; directors: T = −\hat{d_½}, J = A_l (−\hat{d_½}). They are
    // never formed: Tᵀ b = d_½ × b and Jᵀ b = d_½ × (A_lᵀ b).
    //
    // Reduced strain gradients B̃ = B T (mid) and B J (n+1), 6 rows × 12 columns.
    let mut bt_mid = zeros::<T, 6, 12>();
    let mut bt_1 = zeros::<T, 6, 12>();
    for kk in 0..6 {
        for q in GRADIENT_FIELDS[kk] {
            let (c0, dir) = field_block(q);
            let (a, b) = match dir {
                None => (b_mid[kk][q], b1[kk][q]),
                Some((l, i)) => (
                    dcol[l][i].cross(&b_mid[kk][q]),
                    dcol[l][i].cross(&(at[l] * b1[kk][q])),
                ),
            };
            for cc in 0..3 {
                bt_mid[(kk, c0 + cc)] += a[cc];
                bt_1[(kk, c0 + cc)] += b[cc];
            }
        }
    }
    // Material part: h B̃_½ᵀ (∂S*/∂q). With the mean of the strains ∂S*/∂q = ½(1+β) C B̃_1;
    // with the strain of the mid-point configuration the dissipative part ½ β C Δε still
    // varies with the strains at n+1: ∂S*/∂q = ½ C B̃_½J + ½ β C B̃_1 (β from Kelvin–Voigt
    // damping). C is diagonal on Γ, a 3×3 block on Ω: applied by rows.
    // D B̃ into `db` (overwritten, or added to when `add`).
    let scaled = |db: &mut SMatrix<T, 6, 12>, bt: &SMatrix<T, 6, 12>, fg: T, fo: T, add: bool| {
        for i in 0..3 {
            let f = fg * p.c_gamma[i];
            for cc in 0..12 {
                let x = bt[(i, cc)] * f;
                db[(i, cc)] = if add { db[(i, cc)] + x } else { x };
            }
        }
        let co = p.c_omega * fo;
        for cc in 0..12 {
            let col = bt.fixed_view::<3, 1>(3, cc);
            let om = co * col;
            for i in 0..3 {
                let x = om[i];
                db[(3 + i, cc)] = if add { db[(3 + i, cc)] + x } else { x };
            }
        }
    };
    let (bg, bo) = (s.beta_gamma, s.beta_omega);
    let mean = k.scheme.stress_rule() == StressRule::MeanOfStrains;
    let mut db = zeros::<T, 6, 12>();
    if mean {
        scaled(
            &mut db,
            &bt_1,
            half * h * (T::one() + bg),
            half * h * (T::one() + bo),
            false,
        );
    } else {
        scaled(&mut db, &bt_1, half * h, half * h, false);
    }
    // (Lanes with β = 0 add exact zeros.)
    if !mean && (bg.any_nonzero() || bo.any_nonzero()) {
        let b_end = strain_gradient(&kin.cfg1, h);
        let mut bt_end = zeros::<T, 6, 12>();
        for kk in 0..6 {
            for q in GRADIENT_FIELDS[kk] {
                let (c0, dir) = field_block(q);
                let b = match dir {
                    None => b_end[kk][q],
                    Some((l, i)) => dcol[l][i].cross(&(at[l] * b_end[kk][q])),
                };
                for cc in 0..3 {
                    bt_end[(kk, c0 + cc)] += b[cc];
                }
            }
        }
        scaled(&mut db, &bt_end, half * h * bg, half * h * bo, true);
    }
    // Written in place (no 12×12 temporary, no transposed copy); β = 0 overwrites the block.
    kt.fixed_view_mut::<12, 12>(0, 0)
        .gemm_tr(T::one(), &bt_mid, &db, T::zero());

    // Scalar field couplings G_s ⊗ I₃: geometric stiffness ½ h H(S*) and inertia.
    let mut gs = stress_hessian(sstar, h) * (half * h);
    let inv_dt = c(1.0 / dt);
    let two_dt2 = c(2.0) * inv_dt * inv_dt;
    for l in 0..2 {
        for m in 0..2 {
            gs[(l, m)] += two_dt2 * p.a_rho * h * c(M2[l][m]);
        }
    }
    let kappa = data.kappa();
    let ksum = kappa[0] + kappa[1];
    // dw_α/dd^q_{α,n+1} = c_ν/(Δt(1+K c_ν)) on rotation-free ends.
    let dw = s.c_nu / (c(dt) * (T::one() + ksum * s.c_nu));
    // (Without director dissipation dw = 0: nothing to subtract below; a lane with
    // dw = 0, or a clamped end, subtracts an exact zero.)
    let director_diss = dw.any_nonzero();
    for l in 0..2 {
        for m in 0..2 {
            for a in 0..2 {
                for b in 0..2 {
                    let mass = h * c(M2[l][m]) * p.i_rho[(a, b)] * inv_dt;
                    let (pl, qm) = (field_of(l, a), field_of(m, b));
                    gs[(pl, qm)] += mass * (c(2.0) * inv_dt);
                    if director_diss {
                        for qq in 0..2 {
                            let d = mass * c(2.0) * kappa[m] * dw;
                            gs[(pl, field_of(qq, b))] -= T::select_or_zero(data.rot_free[qq], d);
                        }
                    }
                }
            }
        }
    }
    // Σ_{p∈rows(l), q∈cols(m)} g_pq T_pᵀ J_q, summed over the fields of a column block
    // first (T and J are linear in the directors):
    //   (u_l, u_m) = g I,  (θ_l, u_m) = \hat{Σ_i g d_li},  (u_l, θ_m) = −A_m \hat{Σ_j g d_mj},
    //   (θ_l, θ_m) = −Σ_i \hat{d_li} A_m \hat{Σ_j g d_mj}.
    for l in 0..2 {
        let rl = if l == 0 { R0 } else { R1 };
        for m in 0..2 {
            let rm = if m == 0 { R0 } else { R1 };
            let vsum = |pf: usize| -> Vector3<T> {
                let mut acc: Vector3<T> = zeros();
                for j in 0..3 {
                    acc += dcol[m][j] * gs[(pf, field_of(m, j))];
                }
                acc
            };
            // (u_l, u_m)
            let g_uu = gs[(rl, rm)];
            for cc in 0..3 {
                kt[(u_idx(l) + cc, u_idx(m) + cc)] += g_uu;
            }
            // (θ_l, u_m)
            let mut w: Vector3<T> = zeros();
            for i in 0..3 {
                w += dcol[l][i] * gs[(field_of(l, i), rm)];
            }
            let mut view = kt.fixed_view_mut::<3, 3>(th_idx(l), u_idx(m));
            view += hat(&w);
            // (u_l, θ_m)
            let mut view = kt.fixed_view_mut::<3, 3>(u_idx(l), th_idx(m));
            view -= mul_hat(&amat[m], &vsum(rl));
            // (θ_l, θ_m)
            let mut blk = zeros();
            for i in 0..3 {
                blk += hat_mul(&dcol[l][i], &mul_hat(&amat[m], &vsum(field_of(l, i))));
            }
            let mut view = kt.fixed_view_mut::<3, 3>(th_idx(l), th_idx(m));
            view -= blk;
        }
    }
    // Projection term: d/dθ of Σ_i d_{i,½} × f_i at fixed f: ½ Σ_i \hat{f_i} A_l \hat{d_i}.
    for l in 0..2 {
        let base = if l == 0 { A0 } else { B0 };
        let mut blk = zeros();
        for i in 0..3 {
            blk += hat_mul(&f[base + i], &mul_hat(&amat[l], &dcol[l][i]));
        }
        let mut view = kt.fixed_view_mut::<3, 3>(th_idx(l), th_idx(l));
        view += blk * half;
    }

    if trans_diss {
        let i3 = identity3::<T>();
        let cv = half * h * p.a_rho * s.c_v;
        for l in 0..2 {
            for m in 0..2 {
                let mm = p.a_rho * h * c(M2[l][m]);
                let mut v = kt.fixed_view_mut::<3, 3>(u_idx(l), g_idx(m));
                v += i3 * (c(-2.0) * mm * inv_dt);
                let mut v = kt.fixed_view_mut::<3, 3>(g_idx(l), u_idx(m));
                v += i3 * (-cv * inv_dt);
                let mut v = kt.fixed_view_mut::<3, 3>(g_idx(l), g_idx(m));
                v += i3 * (mm + cv);
            }
        }
    }
}

/// Field index of director `a` of end `l`.
#[inline]
fn field_of(l: usize, a: usize) -> usize {
    if l == 0 {
        A0 + a
    } else {
        B0 + a
    }
}

/// Monolithic strategy: the change of the element residual caused by the dependence of
/// the dissipation scalars on the increment, `(∂R/∂s)(∂s/∂q)`, added to a frozen-scalar
/// tangent (`scalar_correction`, both factors in closed form:
/// [`scalar_gradient::scalar_gradient`] and [`scalar_gradient::residual_scalar_derivatives`]).
/// `s` and `kin` are the consistent scalars at the iterate and their kinematics, as
/// [`consistent_scalars`] returns them; `active` marks the element-local unknowns that
/// exist.
#[allow(clippy::too_many_arguments)]
pub fn monolithic_correction(
    data: &ElementData,
    st: &ElementState,
    s: &FrozenScalars,
    kin: &Kinematics,
    k: &StepConsts,
    trans_diss: bool,
    active: &[bool; NDOF],
    kt: &mut ElemMat,
) {
    let c = monolithic_terms(data, st, s, kin, k, trans_diss, active);
    scalar_correction(&c.dsigma, &c.d_r, active, c.varies, kt);
}

/// The two factors of [`monolithic_correction`], for adding their product where the
/// frozen-scalar tangent is read (the four-element assembly scatters each lane's tangent
/// with it, [`ScalarCorrection::entry`]).
#[derive(Clone, Debug)]
pub struct ScalarCorrection<const N: usize> {
    /// `∂σ/∂x_j` (row `j`).
    pub dsigma: [[f64; 4]; N],
    /// `∂R/∂σ_i` (zero where `varies[i]` is false).
    pub d_r: [SVector<f64, N>; 4],
    /// Which scalars vary with the active unknowns (`scalars_varying`).
    pub varies: [bool; 4],
}

impl<const N: usize> ScalarCorrection<N> {
    /// Entry `(row, col)` of the corrected tangent from the frozen-scalar entry `k`: the
    /// same operations in the same order as `scalar_correction`'s column updates, so the
    /// same number bit for bit. `col` must be an active unknown.
    #[inline(always)]
    pub fn entry(&self, row: usize, col: usize, k: f64) -> f64 {
        let mut v = k;
        let ds = &self.dsigma[col];
        for i in 0..4 {
            if self.varies[i] {
                // (`a·x + v`, as `axpy`; IEEE addition commutes.)
                v += ds[i] * self.d_r[i].as_slice()[row];
            }
        }
        v
    }
}

/// [`ScalarCorrection`] of an element (the factors of [`monolithic_correction`]).
#[allow(clippy::too_many_arguments)]
pub fn monolithic_terms(
    data: &ElementData,
    st: &ElementState,
    s: &FrozenScalars,
    kin: &Kinematics,
    k: &StepConsts,
    trans_diss: bool,
    active: &[bool; NDOF],
) -> ScalarCorrection<NDOF> {
    let dsigma = scalar_gradient::scalar_gradient(data, st, kin, s, k);
    let varies = scalars_varying(&dsigma, active);
    let d_r = scalar_gradient::residual_scalar_derivatives(data, st, kin, k, trans_diss, varies);
    ScalarCorrection {
        dsigma,
        d_r,
        varies,
    }
}

/// Which of `σ = (β_Γ, β_Ω, c_v, φ)` vary with the unknowns marked `active`.
pub(crate) fn scalars_varying<const N: usize>(
    dsigma: &[[f64; 4]; N],
    active: &[bool; N],
) -> [bool; 4] {
    let mut varies = [false; 4];
    for j in (0..N).filter(|&j| active[j]) {
        for i in 0..4 {
            varies[i] |= dsigma[j][i] != 0.0;
        }
    }
    varies
}

/// `(∂R/∂s)(∂s/∂q)` of an element, added to `kt` over the unknowns marked `active`;
/// shared by the 3D and the planar kernel. `dsigma[j]` is `∂σ/∂x_j` and `d_r[i]` is
/// `∂R/∂σ_i` for `σ = (β_Γ, β_Ω, c_v, φ = c_ν/(1 + K c_ν))`, the scalars the residual is
/// affine in: column j is `Σ_i ∂R/∂σ_i ∂σ_i/∂x_j`, the same quantity as differencing
/// whole residuals at the perturbed scalars, `(R(s(x + h e_j)) − R(s(x − h e_j)))/2h`,
/// without two residuals per column and without that difference's cancellation.
/// `varies` is [`scalars_varying`] of `dsigma` and `active` (the terms of the other
/// scalars are zero).
pub(crate) fn scalar_correction<const N: usize>(
    dsigma: &[[f64; 4]; N],
    d_r: &[SVector<f64, N>; 4],
    active: &[bool; N],
    varies: [bool; 4],
    kt: &mut SMatrix<f64, N, N>,
) {
    for j in (0..N).filter(|&j| active[j]) {
        let mut c = kt.column_mut(j);
        for i in (0..4).filter(|&i| varies[i]) {
            c.axpy(dsigma[j][i], &d_r[i], 1.0);
        }
    }
}
