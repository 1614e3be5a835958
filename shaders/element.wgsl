// ELEMENT KERNEL, WGSL twin of `src/element/{mod,strain,dissipation,drag,point_mass}.rs` (and of the
// Cayley helpers of `src/math/mod.rs`). Same arithmetic, term by term: kinematics, strains,
// mid-point strain gradient, stresses, EDMC local scalars (incl. the 4×4 EDMC-2 solve),
// element residual (18), row scales (18) and tangent (18×18). Rational operations and sqrt
// only (lavapipe's f64 transcendentals are wrong; the scheme needs none).
//
// Two passes, so that no invocation holds the 18×18 tangent (docs/gpu.md, "Kernels"):
// * `residual_main`, one invocation per element slot: kinematics, (consistent) scalars,
//   stresses, residual, row scales; when the dispatch wants a tangent, also the few values
//   the tangent needs (new configuration, Cayley factors, stresses, director forces: NT
//   fields) into the intermediate buffer (binding 5).
// * `tangent_prep_main`, two invocations per listed element slot (binding 6; dispatch
//   y = the node): the reduced strain gradients of the node into the intermediate buffer.
// * `tangent_main`, four invocations per listed element slot (dispatch y = the block):
//   one 9×9 node block each, read from the intermediate buffer and the state.
// * `advance_main`, one invocation per listed element slot (binding 6), after an accepted
//   Newton solve: the state at n+1 of the slot's increment (the same kinematics) over its
//   state at n (binding 1), and the element's terms of the invariants at n+1 and its
//   dissipation into the intermediate buffer (T_ADV); `record_main`, one invocation per
//   member slot, sums those of its active element slots (T_REC).
//
// Buffers are struct-of-arrays, field-major: field `f` of element `i` is `buf[f * n + i]`
// (coalesced loads on a real GPU). Field offsets are the constants below; their Rust twin is
// `src/gpu/layout.rs`. `Real` is rewritten to `f32` by `src/gpu/kernel.rs` on adapters
// without SHADER_F64 (measured error: docs/gpu.md).

alias Real = f64;
alias V3 = vec3<Real>;
alias Tri = array<V3, 3>;

// Substituted together with `Real` for f32.
const TINY: Real = 1e-300;
// Stands for infinity: no finite factor reaches it (1e30 in f32).
const HUGE: Real = 1e300;
const CNU_TOL: Real = 1e-15;

// ---- element constants (binding 0), NE fields ----
const E_H: u32 = 0u;
const E_ARHO: u32 = 1u;
const E_IRHO: u32 = 2u;   // 4: (0,0) (0,1) (1,0) (1,1)
const E_CG: u32 = 6u;     // 3: diagonal of C_Γ
const E_CO: u32 = 9u;     // 9: C_Ω row-major
const E_EPS0: u32 = 18u;  // 6
const E_ROTFREE: u32 = 24u; // 2: 1 = free
const E_DT: u32 = 26u;
const E_TRANS: u32 = 27u; // 1 = translational dissipation rows on
const E_SCHEME: u32 = 28u; // 0 EM, 1 EDMC-1, 2 EDMC-2
const E_SP: u32 = 29u;    // 4 scheme constants (χ_Γ χ_Ω χ_v χ_ν | α_Γv α_Γν α_Ωv α_Ων)
const E_DIRDISS: u32 = 33u; // 1 = director dissipation on
const E_DAMP: u32 = 34u;    // Kelvin–Voigt retardation time η
const E_DRAG: u32 = 35u;    // drag per unit length c (twin of element::drag)
const E_PMASS: u32 = 36u;   // 2: point masses carried by the ends (twin of element::point_mass)
const E_FOLLOW: u32 = 38u;  // 6: follower line load f, m per length in the director frame (twin of element::follower)
// ---- state at n (binding 1), NS fields ----
const S_R: u32 = 0u;      // 6: r_0, r_1
const S_D: u32 = 6u;      // 18: d[l] column i component c at 9l + 3i + c
const S_V: u32 = 24u;     // 6
const S_VD: u32 = 30u;    // 12: vd[l][α] component c at 6l + 3α + c
const S_EPS: u32 = 42u;   // 6
// ---- per Newton iteration (binding 2), NI fields ----
const I_X: u32 = 0u;      // 18: element-local increment (u0 θ0 u1 θ1 g0 g1)
const I_S: u32 = 18u;     // 4: frozen β_Γ β_Ω c_v c_ν
const I_ACTIVE: u32 = 22u; // 1 = evaluate this element; 2 = evaluate it with consistent scalars;
                           // 3 = freeze the consistent scalars at this iterate, then as 1;
                           // 0 = skip it; −2 = skip it, its iterate accepted with consistent
                           // scalars (the advance's and records' kinematics)
// ---- output (binding 3), NO fields ----
const O_R: u32 = 0u;      // 18
const O_SC: u32 = 18u;    // 18
const O_K: u32 = 36u;     // 324 row-major
const O_S: u32 = 360u;    // 4: the scalars used (frozen or consistent)
// ---- residual pass → tangent pass (binding 5), NT fields ----
const T_C1: u32 = 0u;     // 24: new configuration r0 r1, d0 columns, d1 columns
const T_A: u32 = 24u;     // 18: (I − ½ hat θ_l)⁻¹ columns, l = 0, 1
const T_SS: u32 = 42u;    // 6: stresses S*
const T_F: u32 = 48u;     // 18: director forces f[2..8] (stress + inertia)
// ---- tangent prep → tangent blocks (binding 5) ----
const T_BT: u32 = 66u;    // 72: B̃_½ columns of nodes 0, 1 (36 n + 6 k + 3 g + c)
const T_DB: u32 = 138u;   // 72: D B̃_{n+1} columns of nodes 0, 1 (same order)
// ---- advance pass → record pass (binding 5) ----
const T_ADV: u32 = 48u;   // 13: per element: kinetic, stored energy, L (3), J (3), dissipation,
                          // the two acceleration-norm sums, the turn beyond MAX_TURN_COS,
                          // the follower loads' work
const T_REC: u32 = 61u;   // 13: per member slot (index = member slot): the sums of T_ADV
const N_ADV: u32 = 13u;
// ---- advance pass → state hand-back (binding 5), dissipative schemes ----
const T_FS: u32 = 210u;   // 4: the frozen scalars a step on the device started from
// cos of the largest turn between an element's end triads a step may produce (twin of
// `MAX_ELEMENT_TURN` in src/integrator/simulation/accept.rs: cos 2).
const MAX_TURN_COS: Real = -0.4161468365471424;

struct Params {
    n: u32,
    // 1: the residual pass also writes the intermediate buffer (a tangent pass follows).
    want_tangent: u32,
    // 0: frozen scalars from binding 2; 1: consistent scalars (DESIGN §4 local law).
    mode: u32,
    // Element slots listed for the tangent pass (binding 6).
    n_tan: u32,
    // Element slots per member slot (the record pass).
    per_member: u32,
    // 1: the advance pass writes the records only, not the state (the state at n stays
    // until the host has read the step's record), and the record pass sums every element
    // slot of a member (the advance cleared the fields of the unlisted ones).
    dry: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> elem: array<Real>;
// Written by the advance pass only.
@group(0) @binding(1) var<storage, read_write> state: array<Real>;
// Written by the residual pass (I_ACTIVE 3: the polish round's frozen scalars) and the
// advance pass (a dissipative scheme's frozen scalars for the next step).
@group(0) @binding(2) var<storage, read_write> iter: array<Real>;
@group(0) @binding(3) var<storage, read_write> outp: array<Real>;
@group(0) @binding(4) var<uniform> prm: Params;
@group(0) @binding(5) var<storage, read_write> tmid: array<Real>;
@group(0) @binding(6) var<storage, read> tan_list: array<u32>;

var<private> gi: u32;

fn ld_e(f: u32) -> Real { return elem[f * prm.n + gi]; }
fn ld_s(f: u32) -> Real { return state[f * prm.n + gi]; }
fn ld_i(f: u32) -> Real { return iter[f * prm.n + gi]; }
fn st_i(f: u32, x: Real) { iter[f * prm.n + gi] = x; }
fn st_o(f: u32, x: Real) { outp[f * prm.n + gi] = x; }
fn ld_t(f: u32) -> Real { return tmid[f * prm.n + gi]; }
fn st_t(f: u32, x: Real) { tmid[f * prm.n + gi] = x; }
fn st_t3(f: u32, v: V3) { st_t(f, v.x); st_t(f + 1u, v.y); st_t(f + 2u, v.z); }
fn ld_s3(f: u32) -> V3 { return V3(ld_s(f), ld_s(f + 1u), ld_s(f + 2u)); }
fn ld_i3(f: u32) -> V3 { return V3(ld_i(f), ld_i(f + 1u), ld_i(f + 2u)); }

// ---- small algebra (twin of src/math/mod.rs); a Tri holds the columns ----
fn norm(v: V3) -> Real { return sqrt(dot(v, v)); }
fn amax(v: V3) -> Real { return max(max(abs(v.x), abs(v.y)), abs(v.z)); }
fn mv(m: Tri, x: V3) -> V3 { return m[0] * x.x + m[1] * x.y + m[2] * x.z; }
fn mtv(m: Tri, x: V3) -> V3 { return V3(dot(m[0], x), dot(m[1], x), dot(m[2], x)); }
fn mm(a: Tri, b: Tri) -> Tri { return Tri(mv(a, b[0]), mv(a, b[1]), mv(a, b[2])); }
fn madd(a: Tri, b: Tri) -> Tri { return Tri(a[0] + b[0], a[1] + b[1], a[2] + b[2]); }
fn mscale(a: Tri, s: Real) -> Tri { return Tri(a[0] * s, a[1] * s, a[2] * s); }
fn mt(a: Tri) -> Tri {
    return Tri(V3(a[0].x, a[1].x, a[2].x), V3(a[0].y, a[1].y, a[2].y), V3(a[0].z, a[1].z, a[2].z));
}
fn eye() -> Tri { return Tri(V3(1.0, 0.0, 0.0), V3(0.0, 1.0, 0.0), V3(0.0, 0.0, 1.0)); }
fn hat(a: V3) -> Tri { return Tri(V3(0.0, a.z, -a.y), V3(-a.z, 0.0, a.x), V3(a.y, -a.x, 0.0)); }
fn cay(th: V3) -> Tri {
    let t = hat(th);
    let s = 1.0 / (1.0 + 0.25 * dot(th, th));
    return madd(eye(), mscale(madd(t, mm(mscale(t, 0.5), t)), s));
}
fn inv_i_minus_half_hat(th: V3) -> Tri {
    let t = hat(th);
    let s = 1.0 / (1.0 + 0.25 * dot(th, th));
    return madd(eye(), mscale(madd(mscale(t, 0.5), mm(mscale(t, 0.25), t)), s));
}
fn m2(l: u32, m: u32) -> Real {
    if l == m { return 2.0 / 6.0; }
    return 1.0 / 6.0;
}
fn irho(a: u32, b: u32) -> Real { return ld_e(E_IRHO + 2u * a + b); }
// Drag row of end l, −F_l = (c h/Δt) Σ_m M2[l][m] u_m, for k = c h/Δt (twin of
// element::drag::drag_forces).
fn drag_row(l: u32, u0: V3, u1: V3, k: Real) -> V3 { return (u0 * m2(l, 0u) + u1 * m2(l, 1u)) * k; }
// A follower line load on an end (twin of element::follower::end_load): w Σ_i v_i d_i over
// the end's mid-step directors d (columns), v the load per length in the director frame.
fn follower_row(d: Tri, v: V3, w: Real) -> V3 { return (d[0] * v.x + d[1] * v.y + d[2] * v.z) * w; }
fn ld_e3(f: u32) -> V3 { return V3(ld_e(f), ld_e(f + 1u), ld_e(f + 2u)); }
fn has_follower(f: V3, m: V3) -> bool { return any(f != V3(0.0, 0.0, 0.0)) || any(m != V3(0.0, 0.0, 0.0)); }
// Its derivative with respect to the end's rotation increment, negated (the residual
// row is −F): ½w Σ_i v_i A hat(d_i), A = (I − ½θ̂)⁻¹.
fn follower_block(a: Tri, d: Tri, v: V3, w: Real) -> Tri {
    var b = mscale(mm(a, hat(d[0])), v.x);
    b = madd(b, mscale(mm(a, hat(d[1])), v.y));
    b = madd(b, mscale(mm(a, hat(d[2])), v.z));
    return mscale(b, 0.5 * w);
}
fn irho_amax() -> Real {
    return max(max(abs(irho(0u, 0u)), abs(irho(0u, 1u))), max(abs(irho(1u, 0u)), abs(irho(1u, 1u))));
}
fn c_omega_mv(x: V3) -> V3 {
    return V3(
        ld_e(E_CO) * x.x + ld_e(E_CO + 1u) * x.y + ld_e(E_CO + 2u) * x.z,
        ld_e(E_CO + 3u) * x.x + ld_e(E_CO + 4u) * x.y + ld_e(E_CO + 5u) * x.z,
        ld_e(E_CO + 6u) * x.x + ld_e(E_CO + 7u) * x.y + ld_e(E_CO + 8u) * x.z,
    );
}

// ---- strains (twin of src/element/strain.rs); fields R0 R1 A0..A2 B0..B2 = 0..7 ----
struct Cfg { r0: V3, r1: V3, d0: Tri, d1: Tri, }

fn cfg_mean(a: Cfg, b: Cfg) -> Cfg {
    return Cfg(0.5 * (a.r0 + b.r0), 0.5 * (a.r1 + b.r1), mscale(madd(a.d0, b.d0), 0.5), mscale(madd(a.d1, b.d1), 0.5));
}
fn cfg_r(c: Cfg, l: u32) -> V3 { if l == 0u { return c.r0; } return c.r1; }
fn cfg_d(c: Cfg, l: u32) -> Tri { if l == 0u { return c.d0; } return c.d1; }

struct Eps6 { g: V3, o: V3, }

fn raw_strains(c: Cfg, h: Real) -> Eps6 {
    let dr = (c.r1 - c.r0) / h;
    let a = c.d0;
    let b = c.d1;
    let gamma = V3(0.5 * dot(a[0] + b[0], dr), 0.5 * dot(a[1] + b[1], dr), 0.5 * dot(a[2] + b[2], dr));
    let s = 0.5 / h;
    let omega = V3(
        s * (dot(a[2], b[1]) - dot(a[1], b[2])),
        s * (dot(a[0], b[2]) - dot(a[2], b[0])),
        s * (dot(a[1], b[0]) - dot(a[0], b[1])),
    );
    return Eps6(gamma, omega);
}

// Strain gradient B (twin of strain_gradient), 6 rows × 8 fields of 3: rows 0..2 (Γ_k)
// have R0: −d̄_k/h, R1: d̄_k/h (d̄_k = ½(a_k + b_k)), A_k and B_k: ½ (r1 − r0)/h; row 3 + k
// (Ω_k, (k, i, j) cyclic) has A_j: s b_i, B_i: s a_j, A_i: −(s b_j), B_j: −(s a_i) with
// s = 1/(2h); every other entry is 0. Each nonzero entry is a single term. The passes never
// hold B: they use it written out (stress forces in `residual`, `btilde` in the tangent
// prep), the nonzero terms of each sum in ascending row order (the zeros add exact zeros),
// so the sums are those of the CPU kernel's full products.

// ---- dissipation (twin of src/element/dissipation.rs) ----
struct Inputs { v_n: Real, v_n1: Real, nu_n: Real, nu_n1: Real, x_g: Real, x_o: Real, }
struct Local { beta_g: Real, beta_o: Real, dv: Real, dnu: Real, }

fn ratio(num: Real, den: Real) -> Real {
    if den > TINY { return num / den; }
    return 0.0;
}

// EDMC-2's law M s = r, M = [[I, M12], [M21, M22]] in 2×2 blocks (row-major m), by its
// 2×2 Schur complement S = M22 − M21 M12 (twin of element::dissipation::LawFactors, the
// same operations in the same order); zeros if S is singular.
fn solve_law(m: array<Real, 16>, r: array<Real, 4>) -> array<Real, 4> {
    let s00 = m[10] - (m[8] * m[2] + m[9] * m[6]);
    let s01 = m[11] - (m[8] * m[3] + m[9] * m[7]);
    let s10 = m[14] - (m[12] * m[2] + m[13] * m[6]);
    let s11 = m[15] - (m[12] * m[3] + m[13] * m[7]);
    let det = s00 * s11 - s01 * s10;
    if det == 0.0 { return array<Real, 4>(0.0, 0.0, 0.0, 0.0); }
    let inv = 1.0 / det;
    let i00 = s11 * inv;
    let i01 = -s01 * inv;
    let i10 = -s10 * inv;
    let i11 = s00 * inv;
    let b0 = r[2] - (m[8] * r[0] + m[9] * r[1]);
    let b1 = r[3] - (m[12] * r[0] + m[13] * r[1]);
    let y0 = i00 * b0 + i01 * b1;
    let y1 = i10 * b0 + i11 * b1;
    return array<Real, 4>(
        r[0] - (m[2] * y0 + m[3] * y1),
        r[1] - (m[6] * y0 + m[7] * y1),
        y0,
        y1,
    );
}

// s = 3ρ² − 2ρ³ for ρ = V/F < 1, else 1 (twin of element::dissipation::fade).
fn fade(speed: Real, forcing: Real) -> Real {
    if forcing <= 0.0 || speed >= forcing {
        return 1.0;
    }
    let rho = speed / forcing;
    return rho * rho * (3.0 - 2.0 * rho);
}

// The scheme's local law plus Kelvin–Voigt material damping, whose viscous stresses
// η C Δε/Δt = ½ (2η/Δt) C Δε add 2η/Δt to both β (twin of the addition in
// element::consistent_scalars_at).
fn local_law(inp: Inputs, a_rho: Real, dt_h: Real, dt: Real) -> Local {
    var loc = local_scalars(inp, a_rho, dt_h);
    let kv = 2.0 * ld_e(E_DAMP) / dt;
    loc.beta_g += kv;
    loc.beta_o += kv;
    return loc;
}

fn local_scalars(inp: Inputs, a_rho: Real, dt_h: Real) -> Local {
    let kind = u32(ld_e(E_SCHEME));
    let p0 = ld_e(E_SP);
    let p1 = ld_e(E_SP + 1u);
    let p2 = ld_e(E_SP + 2u);
    let p3 = ld_e(E_SP + 3u);
    if kind == 1u {
        return Local(p0, p1, p2 * (inp.v_n1 - inp.v_n), p3 * (inp.nu_n1 - inp.nu_n));
    }
    if kind == 2u {
        let xg = inp.x_g;
        let xo = inp.x_o;
        // The velocity couplings faded where the point is slower than the law's own
        // dissipative speed (twin of element::dissipation::fade).
        let a0gv = p0 * dt_h;
        let a0gn = p1 * dt_h;
        let a0ov = p2 * dt_h;
        let a0on = p3 * dt_h;
        let sv = fade(inp.v_n + inp.v_n1, (a0gv * xg + a0ov * xo) / a_rho);
        let snu = fade(inp.nu_n + inp.nu_n1, (a0gn * xg + a0on * xo) / a_rho);
        let agv = sv * a0gv;
        let agn = snu * a0gn;
        let aov = sv * a0ov;
        let aon = snu * a0on;
        let m = array<Real, 16>(
            1.0, 0.0, -agv, -agn,
            0.0, 1.0, -aov, -aon,
            agv * xg, aov * xo, a_rho, 0.0,
            agn * xg, aon * xo, 0.0, a_rho,
        );
        let rhs = array<Real, 4>(
            -agv * inp.v_n1 - agn * inp.nu_n1,
            -aov * inp.v_n1 - aon * inp.nu_n1,
            a_rho * inp.v_n + agv * xg + aov * xo,
            a_rho * inp.nu_n + agn * xg + aon * xo,
        );
        let s = solve_law(m, rhs);
        return Local(s[0], s[1], s[2] - inp.v_n, s[3] - inp.nu_n);
    }
    return Local(0.0, 0.0, 0.0, 0.0);
}

// ---- kinematics (twin of element::kinematics) ----
struct St { cfg: Cfg, v0: V3, v1: V3, vd: array<V3, 4>, eps: Eps6, }
struct Kin {
    cfg1: Cfg,
    mid: Cfg,
    amat0: Tri,
    amat1: Tri,
    eps1: Eps6,
    v10: V3,
    v11: V3,
    vd1: array<V3, 4>, // [l][α] at 2l + α
    inputs: Inputs,
}

fn load_state() -> St {
    let cfg = Cfg(
        ld_s3(S_R), ld_s3(S_R + 3u),
        Tri(ld_s3(S_D), ld_s3(S_D + 3u), ld_s3(S_D + 6u)),
        Tri(ld_s3(S_D + 9u), ld_s3(S_D + 12u), ld_s3(S_D + 15u)),
    );
    let vd = array<V3, 4>(ld_s3(S_VD), ld_s3(S_VD + 3u), ld_s3(S_VD + 6u), ld_s3(S_VD + 9u));
    let eps = Eps6(ld_s3(S_EPS), ld_s3(S_EPS + 3u));
    return St(cfg, ld_s3(S_V), ld_s3(S_V + 3u), vd, eps);
}

fn kappa(l: u32) -> Real {
    let f0 = ld_e(E_ROTFREE) != 0.0;
    let f1 = ld_e(E_ROTFREE + 1u) != 0.0;
    if f0 && f1 { return 1.0; }
    if l == 0u && f0 { return 1.5; }
    if l == 1u && f1 { return 1.5; }
    return 0.0;
}

fn director_speed(a: V3, b: V3, a_rho: Real) -> Real {
    var s: Real = 0.0;
    s += irho(0u, 0u) * dot(a, a);
    s += irho(0u, 1u) * dot(a, b);
    s += irho(1u, 0u) * dot(b, a);
    s += irho(1u, 1u) * dot(b, b);
    return sqrt(max(s, 0.0) / a_rho);
}

fn kinematics(st: St, x: array<Real, 18>, c_nu: Real, dt: Real) -> Kin {
    let h = ld_e(E_H);
    let a_rho = ld_e(E_ARHO);
    let u0 = V3(x[0], x[1], x[2]);
    let th0 = V3(x[3], x[4], x[5]);
    let u1 = V3(x[6], x[7], x[8]);
    let th1 = V3(x[9], x[10], x[11]);
    let g0 = V3(x[12], x[13], x[14]);
    let g1 = V3(x[15], x[16], x[17]);
    let cfg1 = Cfg(st.cfg.r0 + u0, st.cfg.r1 + u1, mm(cay(th0), st.cfg.d0), mm(cay(th1), st.cfg.d1));
    let mid = cfg_mean(st.cfg, cfg1);
    let eps1 = raw_strains(cfg1, h);
    let v10 = 2.0 * u0 / dt - st.v0 - 2.0 * g0;
    let v11 = 2.0 * u1 / dt - st.v1 - 2.0 * g1;
    let k0 = kappa(0u);
    let k1 = kappa(1u);
    let ksum = k0 + k1;
    var w: array<V3, 2>;
    var vd1: array<V3, 4>;
    for (var a = 0u; a < 2u; a++) {
        let dd0 = cfg1.d0[a] - st.cfg.d0[a];
        let dd1 = cfg1.d1[a] - st.cfg.d1[a];
        let y = (dd0 + dd1) / dt;
        w[a] = y * (c_nu / (1.0 + ksum * c_nu));
        vd1[a] = 2.0 * dd0 / dt - st.vd[a] - 2.0 * k0 * w[a];
        vd1[2u + a] = 2.0 * dd1 / dt - st.vd[2u + a] - 2.0 * k1 * w[a];
    }
    let vh_n = 0.5 * (st.v0 + st.v1);
    let vh_1 = 0.5 * (v10 + v11);
    let vdh_n0 = 0.5 * (st.vd[0] + st.vd[2]);
    let vdh_n1 = 0.5 * (st.vd[1] + st.vd[3]);
    let vdh_10 = 0.5 * (vd1[0] + vd1[2]);
    let vdh_11 = 0.5 * (vd1[1] + vd1[3]);
    let dg = eps1.g - st.eps.g;
    let dom = eps1.o - st.eps.o;
    let cg = V3(ld_e(E_CG), ld_e(E_CG + 1u), ld_e(E_CG + 2u));
    let inputs = Inputs(
        norm(vh_n),
        norm(vh_1),
        director_speed(vdh_n0, vdh_n1, a_rho),
        director_speed(vdh_10, vdh_11, a_rho),
        dot(dg, cg * dg),
        dot(dom, c_omega_mv(dom)),
    );
    return Kin(cfg1, mid, inv_i_minus_half_hat(th0), inv_i_minus_half_hat(th1), eps1, v10, v11, vd1, inputs);
}

// Twin of element::consistent_scalars: returns (β_Γ, β_Ω, c_v, c_ν) and the kinematics.
struct Consistent { s: array<Real, 4>, kin: Kin, }

// c_ν's local law at the kinematics of c (the map F of element::director_factor).
fn cnu_law(st: St, x: array<Real, 18>, c: Real, dt: Real) -> Real {
    let kin = kinematics(st, x, c, dt);
    let loc = local_scalars(kin.inputs, ld_e(E_ARHO), dt / ld_e(E_H));
    return ratio(0.5 * loc.dnu, kin.inputs.nu_n + kin.inputs.nu_n1);
}

fn cnu_tol(c: Real) -> Real { return CNU_TOL * (1.0 + abs(c)); }

// Twin of element::director_factor::solve_fixed_point: a few fixed-point steps, then a
// bracket walked away from 0 and the Illinois regula falsi.
fn solve_cnu(st: St, x: array<Real, 18>, dt: Real) -> Real {
    let ksum = kappa(0u) + kappa(1u);
    let has_min = ksum > 0.0;
    var c_min: Real = 0.0;
    if has_min { c_min = -1.0 / ksum; }
    let f0 = cnu_law(st, x, 0.0, dt);
    if abs(f0) <= cnu_tol(0.0) { return f0; }
    var c = f0;
    for (var it = 0u; it < 6u; it++) {
        let next = cnu_law(st, x, c, dt);
        if abs(next - c) <= cnu_tol(c) { return next; }
        c = next;
    }
    var a: Real;
    var ga: Real;
    var b: Real;
    var gb: Real;
    if f0 > 0.0 {
        a = 0.0;
        ga = f0;
        b = f0;
        gb = cnu_law(st, x, b, dt) - b;
        for (var k = 0u; k < 60u && gb > 0.0; k++) {
            a = b;
            ga = gb;
            b = 2.0 * b + TINY;
            gb = cnu_law(st, x, b, dt) - b;
        }
    } else {
        b = 0.0;
        gb = f0;
        if !has_min || f0 > c_min { a = f0; } else { a = 0.5 * c_min; }
        ga = cnu_law(st, x, a, dt) - a;
        for (var k = 0u; k < 60u && ga < 0.0; k++) {
            b = a;
            gb = ga;
            if has_min { a = 0.5 * (a + c_min); } else { a = 2.0 * a - TINY; }
            ga = cnu_law(st, x, a, dt) - a;
        }
    }
    if !(ga >= 0.0 && gb <= 0.0) { return c; }
    return cnu_illinois(st, x, dt, a, ga, b, gb);
}

// Illinois regula falsi on g(c) = F(c) − c over a bracket with g(a) ≥ 0 ≥ g(b) (either
// order of a, b): twin of element::director_factor::illinois.
fn cnu_illinois(st: St, x: array<Real, 18>, dt: Real, a0: Real, ga0: Real, b0: Real, gb0: Real) -> Real {
    var a = a0;
    var ga = ga0;
    var b = b0;
    var gb = gb0;
    var side = 0i;
    for (var it = 0u; it < 200u; it++) {
        var xc: Real;
        if ga - gb > 0.0 { xc = (a * (-gb) + b * ga) / (ga - gb); } else { xc = 0.5 * (a + b); }
        let gx = cnu_law(st, x, xc, dt) - xc;
        if abs(gx) <= cnu_tol(xc) || abs(b - a) <= cnu_tol(xc) { return xc; }
        if gx > 0.0 {
            a = xc;
            ga = gx;
            if side == 1i { gb *= 0.5; }
            side = 1i;
        } else {
            b = xc;
            gb = gx;
            if side == -1i { ga *= 0.5; }
            side = -1i;
        }
    }
    return 0.5 * (a + b);
}

// The root of c = F(c) nearest c_ref, the factor the iterate was solved with: twin of
// element::director_factor::solve_fixed_point_near (successive iterates stay on one branch
// where the equation has several roots).
fn solve_cnu_near(st: St, x: array<Real, 18>, dt: Real, c_ref: Real) -> Real {
    let c0 = solve_cnu(st, x, dt);
    let ksum = kappa(0u) + kappa(1u);
    var c_min: Real = -HUGE;
    if ksum > 0.0 { c_min = -1.0 / ksum; }
    let d = abs(c0 - c_ref);
    // `c_ref == c_ref` is false for NaN; |c_ref| < HUGE stands for finiteness.
    if !(c_ref == c_ref && abs(c_ref) < HUGE && c_ref > c_min) || d <= 1e-12 * (1.0 + abs(c0)) {
        return c0;
    }
    let gr = cnu_law(st, x, c_ref, dt) - c_ref;
    if abs(gr) <= cnu_tol(c_ref) { return c_ref; }
    var delta = d / 8.0;
    var up_prev = c_ref;
    var lo_prev = c_ref;
    var lo = c_ref;
    for (var k = 0u; k < 64u && delta < d; k++) {
        let up = c_ref + delta;
        let gu = cnu_law(st, x, up, dt) - up;
        if c_ref - delta > c_min { lo = c_ref - delta; } else { lo = 0.5 * (lo + c_min); }
        let gl = cnu_law(st, x, lo, dt) - lo;
        var found = false;
        var near: Real = 0.0;
        var far: Real = 0.0;
        var gfar: Real = 0.0;
        if (gu > 0.0) != (gr > 0.0) {
            found = true;
            near = up_prev;
            far = up;
            gfar = gu;
        } else if (gl > 0.0) != (gr > 0.0) {
            found = true;
            near = lo_prev;
            far = lo;
            gfar = gl;
        }
        if found {
            let gnear = cnu_law(st, x, near, dt) - near;
            if gnear >= 0.0 {
                return cnu_illinois(st, x, dt, near, gnear, far, gfar);
            }
            return cnu_illinois(st, x, dt, far, gfar, near, gnear);
        }
        up_prev = up;
        lo_prev = lo;
        delta *= 2.0;
    }
    return c0;
}

fn consistent_scalars(st: St, x: array<Real, 18>, dt: Real, c_ref: Real) -> Consistent {
    let h = ld_e(E_H);
    let a_rho = ld_e(E_ARHO);
    let dt_h = dt / h;
    var c_nu: Real = 0.0;
    if ld_e(E_DIRDISS) != 0.0 {
        c_nu = solve_cnu_near(st, x, dt, c_ref);
    }
    let kin = kinematics(st, x, c_nu, dt);
    let loc = local_law(kin.inputs, a_rho, dt_h, dt);
    let c_v = ratio(0.5 * loc.dv, kin.inputs.v_n + kin.inputs.v_n1);
    return Consistent(array<Real, 4>(loc.beta_g, loc.beta_o, c_v, c_nu), kin);
}

// ---- residual (twin of element::residual_tangent without the tangent) ----
fn u_idx(l: u32) -> u32 { return 6u * l; }
fn th_idx(l: u32) -> u32 { return 6u * l + 3u; }
fn g_idx(l: u32) -> u32 { return 12u + 3u * l; }
fn kin_v1(k: Kin, l: u32) -> V3 { if l == 0u { return k.v10; } return k.v11; }
fn st_v(s: St, l: u32) -> V3 { if l == 0u { return s.v0; } return s.v1; }
fn kin_g(st: St, k: Kin, m: u32, dt: Real) -> V3 {
    return (cfg_r(k.cfg1, m) - cfg_r(st.cfg, m)) / dt - 0.5 * (st_v(st, m) + kin_v1(k, m));
}

// Weight of the gross stress forces in the row scales (GROSS_WEIGHT in src/element/mod.rs).
const GROSS_WEIGHT = 1e-4;

// Stresses S* = C (ε̄ − ε0 + ½ β Δε) (6).
fn stresses(st: St, eps1: Eps6, beta_g: Real, beta_o: Real) -> array<Real, 6> {
    let eps0g = V3(ld_e(E_EPS0), ld_e(E_EPS0 + 1u), ld_e(E_EPS0 + 2u));
    let eps0o = V3(ld_e(E_EPS0 + 3u), ld_e(E_EPS0 + 4u), ld_e(E_EPS0 + 5u));
    let mean_g = 0.5 * (st.eps.g + eps1.g) - eps0g;
    let mean_o = 0.5 * (st.eps.o + eps1.o) - eps0o;
    let gg = mean_g + 0.5 * beta_g * (eps1.g - st.eps.g);
    let oo = mean_o + 0.5 * beta_o * (eps1.o - st.eps.o);
    let cg = V3(ld_e(E_CG), ld_e(E_CG + 1u), ld_e(E_CG + 2u));
    let nn = cg * gg;
    let mmm = c_omega_mv(oo);
    return array<Real, 6>(nn.x, nn.y, nn.z, mmm.x, mmm.y, mmm.z);
}

// Residual pass body: residual, row scales and scalars into the output buffer; with
// `keep` also what the tangent pass needs into the intermediate buffer (T_* fields).
fn residual(st: St, kin: Kin, s: array<Real, 4>, dt: Real, keep: bool) {
    let h = ld_e(E_H);
    let a_rho = ld_e(E_ARHO);
    let trans = ld_e(E_TRANS) != 0.0;
    let beta_g = s[0];
    let beta_o = s[1];
    let c_v = s[2];
    let eps0g = V3(ld_e(E_EPS0), ld_e(E_EPS0 + 1u), ld_e(E_EPS0 + 2u));
    let eps0o = V3(ld_e(E_EPS0 + 3u), ld_e(E_EPS0 + 4u), ld_e(E_EPS0 + 5u));
    let cg = V3(ld_e(E_CG), ld_e(E_CG + 1u), ld_e(E_CG + 2u));
    let sstar = stresses(st, kin.eps1, beta_g, beta_o);

    // Stress forces f_q = Σ_k B[k][q] h S*_k and their round-off floor
    // Σ_k |B[k][q]| h gross_k (GROSS_WEIGHT × the twin of `gross_stress` in
    // src/element/mod.rs), written out from the sparsity of B (above): the nonzero terms
    // in ascending k, the others add exact zeros.
    let eg = abs(0.5 * (st.eps.g + kin.eps1.g)) + abs(eps0g);
    let eo = abs(0.5 * (st.eps.o + kin.eps1.o)) + abs(eps0o);
    let gn = abs(cg) * eg;
    let gross = array<Real, 6>(
        gn.x,
        gn.y,
        gn.z,
        abs(ld_e(E_CO)) * eo.x + abs(ld_e(E_CO + 1u)) * eo.y + abs(ld_e(E_CO + 2u)) * eo.z,
        abs(ld_e(E_CO + 3u)) * eo.x + abs(ld_e(E_CO + 4u)) * eo.y + abs(ld_e(E_CO + 5u)) * eo.z,
        abs(ld_e(E_CO + 6u)) * eo.x + abs(ld_e(E_CO + 7u)) * eo.y + abs(ld_e(E_CO + 8u)) * eo.z,
    );
    let c = kin.mid;
    let hs = array<Real, 6>(h * sstar[0], h * sstar[1], h * sstar[2], h * sstar[3], h * sstar[4], h * sstar[5]);
    let dh0 = 0.5 * (c.d0[0] + c.d1[0]) / h;
    let dh1 = 0.5 * (c.d0[1] + c.d1[1]) / h;
    let dh2 = 0.5 * (c.d0[2] + c.d1[2]) / h;
    let hdr = 0.5 * ((c.r1 - c.r0) / h);
    let sc = 0.5 / h;
    let a0 = sc * c.d0[0];
    let a1 = sc * c.d0[1];
    let a2 = sc * c.d0[2];
    let b0 = sc * c.d1[0];
    let b1 = sc * c.d1[1];
    let b2 = sc * c.d1[2];
    var f: array<V3, 8>;
    f[0] = -dh0 * hs[0] + -dh1 * hs[1] + -dh2 * hs[2];
    f[1] = dh0 * hs[0] + dh1 * hs[1] + dh2 * hs[2];
    f[2] = hdr * hs[0] + b2 * hs[4] + -b1 * hs[5];
    f[3] = hdr * hs[1] + -b2 * hs[3] + b0 * hs[5];
    f[4] = hdr * hs[2] + b1 * hs[3] + -b0 * hs[4];
    f[5] = hdr * hs[0] + -a2 * hs[4] + a1 * hs[5];
    f[6] = hdr * hs[1] + a2 * hs[3] + -a0 * hs[5];
    f[7] = hdr * hs[2] + -a1 * hs[3] + a0 * hs[4];
    let fg_r = amax(dh0) * h * gross[0] + amax(dh1) * h * gross[1] + amax(dh2) * h * gross[2];
    let mdr = amax(hdr);
    var f_gross = array<Real, 8>(
        fg_r,
        fg_r,
        mdr * h * gross[0] + amax(b2) * h * gross[4] + amax(b1) * h * gross[5],
        mdr * h * gross[1] + amax(b2) * h * gross[3] + amax(b0) * h * gross[5],
        mdr * h * gross[2] + amax(b1) * h * gross[3] + amax(b0) * h * gross[4],
        mdr * h * gross[0] + amax(a2) * h * gross[4] + amax(a1) * h * gross[5],
        mdr * h * gross[1] + amax(a2) * h * gross[3] + amax(a0) * h * gross[5],
        mdr * h * gross[2] + amax(a1) * h * gross[3] + amax(a0) * h * gross[4],
    );
    let stress_scale = array<Real, 2>(
        max(amax(f[0]), GROSS_WEIGHT * f_gross[0]),
        max(amax(f[1]), GROSS_WEIGHT * f_gross[1]),
    );
    var inertia_r: array<V3, 2>;
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) {
            let c = a_rho * h * m2(l, m) / dt;
            inertia_r[l] += c * (kin_v1(kin, m) - st_v(st, m));
        }
    }
    // Drag (twin of element::drag::add_drag_rows): F_l = −(c h/Δt) Σ_m M2[l][m] u_m, its
    // rows −F_l; kept apart from inertia for the row scales, as the host's own term.
    var drag_r: array<V3, 2>;
    let drag = ld_e(E_DRAG);
    if drag != 0.0 {
        let k = drag * h / dt;
        let u0 = ld_i3(I_X);
        let u1 = ld_i3(I_X + 6u);
        for (var l = 0u; l < 2u; l++) { drag_r[l] = drag_row(l, u0, u1, k); }
    }
    // Point masses carried by the ends (twin of element::point_mass::add_point_mass_rows):
    // m (2u/Δt − 2v − 2g)/Δt on the translations, kept apart for the row scales.
    var pm_r: array<V3, 2>;
    for (var l = 0u; l < 2u; l++) {
        let mp = ld_e(E_PMASS + l);
        if mp != 0.0 {
            var g = V3(0.0, 0.0, 0.0);
            if trans { g = ld_i3(I_X + g_idx(l)); }
            pm_r[l] = mp * (2.0 * ld_i3(I_X + u_idx(l)) / dt - 2.0 * st_v(st, l) - 2.0 * g) / dt;
        }
    }
    // Follower line loads (twin of element::follower::end_load): F_l and M_l over the
    // end's mid-step directors, their rows −F_l and −M_l; kept apart for the row scales.
    var fol_f: array<V3, 2>;
    var fol_m: array<V3, 2>;
    let ff = ld_e3(E_FOLLOW);
    let fm = ld_e3(E_FOLLOW + 3u);
    if has_follower(ff, fm) {
        for (var l = 0u; l < 2u; l++) {
            fol_f[l] = follower_row(cfg_d(kin.mid, l), ff, 0.5 * h);
            fol_m[l] = follower_row(cfg_d(kin.mid, l), fm, 0.5 * h);
        }
    }
    var fd_scale = array<Real, 2>(0.0, 0.0);
    let ira = irho_amax();
    for (var l = 0u; l < 2u; l++) {
        let base = 2u + 3u * l;
        for (var a = 0u; a < 2u; a++) {
            var fi = V3(0.0, 0.0, 0.0);
            for (var m = 0u; m < 2u; m++) {
                for (var b = 0u; b < 2u; b++) {
                    fi += (h * m2(l, m) * irho(a, b) / dt) * (kin.vd1[2u * m + b] - st.vd[2u * m + b]);
                }
            }
            let rate = h * ira * (amax(st.vd[2u * l + a]) + amax(kin.vd1[2u * l + a])) / dt;
            fd_scale[l] = max(max(max(max(fd_scale[l], amax(fi)), amax(f[base + a])), rate), GROSS_WEIGHT * f_gross[base + a]);
            f[base + a] += fi;
        }
        fd_scale[l] = max(max(fd_scale[l], amax(f[base + 2u])), GROSS_WEIGHT * f_gross[base + 2u]);
    }
    for (var l = 0u; l < 2u; l++) {
        let fr = f[l] + inertia_r[l] + drag_r[l] + pm_r[l] - fol_f[l];
        let base = 2u + 3u * l;
        let dm = cfg_d(kin.mid, l);
        var rt = V3(0.0, 0.0, 0.0);
        for (var i = 0u; i < 3u; i++) { rt += cross(dm[i], f[base + i]); }
        rt -= fol_m[l];
        let momentum_rate = a_rho * h * (amax(st_v(st, l)) + amax(kin_v1(kin, l))) / dt;
        let su = max(max(max(max(max(stress_scale[l], amax(inertia_r[l])), momentum_rate), amax(drag_r[l])), amax(pm_r[l])), amax(fol_f[l]));
        let dnorm = max(max(norm(dm[0]), norm(dm[1])), norm(dm[2]));
        for (var c = 0u; c < 3u; c++) {
            st_o(O_R + u_idx(l) + c, fr[c]);
            st_o(O_R + th_idx(l) + c, rt[c]);
            st_o(O_SC + u_idx(l) + c, su);
            st_o(O_SC + th_idx(l) + c, max(fd_scale[l] * dnorm, amax(fol_m[l])));
        }
    }
    let vsum = 0.5 * (st.v0 + st.v1) + 0.5 * (kin.v10 + kin.v11);
    for (var l = 0u; l < 2u; l++) {
        var rg = V3(0.0, 0.0, 0.0);
        var sg: Real = 0.0;
        if trans {
            let bb = 0.5 * h * a_rho * c_v * vsum;
            var mg = V3(0.0, 0.0, 0.0);
            for (var m = 0u; m < 2u; m++) { mg += a_rho * h * m2(l, m) * kin_g(st, kin, m, dt); }
            rg = mg - bb;
            var momentum = 0.5 * a_rho * h * max(amax(st_v(st, l)), amax(kin_v1(kin, l)));
            var psum: Real = 0.0;
            for (var m = 0u; m < 2u; m++) {
                psum += amax((cfg_r(kin.cfg1, m) - cfg_r(st.cfg, m)) / dt) + amax(kin_g(st, kin, m, dt));
            }
            let pieces = 0.5 * h * a_rho * abs(c_v) * psum;
            momentum = max(momentum, pieces);
            sg = max(max(amax(mg), amax(bb)), momentum);
            let mp = ld_e(E_PMASS + l);
            if mp != 0.0 {
                let pg = mp * ld_i3(I_X + g_idx(l));
                rg += pg;
                sg = max(sg, amax(pg));
            }
        }
        for (var c = 0u; c < 3u; c++) {
            st_o(O_R + g_idx(l) + c, rg[c]);
            st_o(O_SC + g_idx(l) + c, sg);
        }
    }
    for (var i = 0u; i < 4u; i++) { st_o(O_S + i, s[i]); }
    if keep {
        st_t3(T_C1, kin.cfg1.r0);
        st_t3(T_C1 + 3u, kin.cfg1.r1);
        for (var i = 0u; i < 3u; i++) {
            st_t3(T_C1 + 6u + 3u * i, kin.cfg1.d0[i]);
            st_t3(T_C1 + 15u + 3u * i, kin.cfg1.d1[i]);
            st_t3(T_A + 3u * i, kin.amat0[i]);
            st_t3(T_A + 9u + 3u * i, kin.amat1[i]);
        }
        for (var k = 0u; k < 6u; k++) { st_t(T_SS + k, sstar[k]); }
        for (var q = 0u; q < 6u; q++) { st_t3(T_F + 3u * q, f[2u + q]); }
    }
}

@compute @workgroup_size(64)
fn residual_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n { return; }
    gi = gid.x;
    if ld_i(I_ACTIVE) <= 0.0 { return; }
    let dt = ld_e(E_DT);
    let st = load_state();
    var x: array<Real, 18>;
    for (var i = 0u; i < 18u; i++) { x[i] = ld_i(I_X + i); }
    let keep = prm.want_tangent != 0u;
    var act = ld_i(I_ACTIVE);
    if act == 3.0 {
        // A step on the device (the inexact strategy, `spec_record` in blocktri.wgsl): its
        // polish round freezes the scalars consistent with this iterate (the host's
        // `advance(q, Consistent)`, on the branch of the step's frozen c_ν) and evaluates
        // with them frozen from here on.
        let c = consistent_scalars(st, x, dt, ld_i(I_S + 3u));
        for (var i = 0u; i < 4u; i++) { st_i(I_S + i, c.s[i]); }
        st_i(I_ACTIVE, 1.0);
        act = 1.0;
    }
    if prm.mode == 1u || act == 2.0 {
        let c = consistent_scalars(st, x, dt, ld_i(I_S + 3u));
        residual(st, c.kin, c.s, dt, keep);
    } else {
        let s = array<Real, 4>(ld_i(I_S), ld_i(I_S + 1u), ld_i(I_S + 2u), ld_i(I_S + 3u));
        let kin = kinematics(st, x, s[3], dt);
        residual(st, kin, s, dt, keep);
    }
}

// ---- tangent (twin of element::tangent), one 9×9 node block per invocation ----
//
// Invocation (x, y) handles block (l, m) = (y / 2, y % 2) of element slot tan_list[x]:
// rows of node l (u_l θ_l g_l), columns of node m, of the row-major 18×18 output
// (element-local order u0 θ0 u1 θ1 g0 g1). Neighbouring invocations share the block (no
// divergence within a SIMD group or warp) and read neighbouring slots. Each entry is the
// sum of the CPU kernel (src/element/mod.rs) in its order: material h B̃ᵀ D B̃, then
// Tᵀ G_s J over the field pairs, then the θθ stress block, then the g rows. Live values:
// B̃ of node l and D B̃ of node m (6×6 each), one 3×3 block and a few 3×3 factors.

fn ld_o(f: u32) -> Real { return outp[f * prm.n + gi]; }
fn kset(i: u32, j: u32, x: Real) { st_o(O_K + 18u * i + j, x); }
fn ld_t3(f: u32) -> V3 { return V3(ld_t(f), ld_t(f + 1u), ld_t(f + 2u)); }
fn ld_tri(f: u32) -> Tri { return Tri(ld_t3(f), ld_t3(f + 3u), ld_t3(f + 6u)); }

// T_q (−hat of the mid-point director of field q; identity for R0, R1).
fn tmat_of(mid: Cfg, q: u32) -> Tri {
    if q < 2u { return eye(); }
    let l = (q - 2u) / 3u;
    let i = (q - 2u) % 3u;
    return mscale(hat(cfg_d(mid, l)[i]), -1.0);
}

// Tangent prep, one invocation per (listed element, node n): the reduced strain-gradient
// columns of node n, B̃_½ = B(Φ_½) T (T_BT) and D B̃_{n+1} = ½(1+β) C B(Φ_{n+1}) J (T_DB),
// 6 rows × (3 u_n + 3 θ_n) each, computed once per element and node instead of once per
// block. Index of row k, column group g (0: u_n, 1: θ_n), component c: 36 n + 6 k + 3 g + c.
// Reduced strain-gradient columns of node n at configuration c: row k of u_n (B[k][R_n])
// and of θ_n (Σ_a X_aᵀ B[k][director a of node n], X_a = T_a or J_a), written out from
// the sparsity of B (above) so that no row or field index is dynamic; the θ sums run
// over the nonzero terms in the order of the full sum (the others add exact zeros).
struct Bt { u: array<V3, 6>, t: array<V3, 6>, }

fn btilde(c: Cfg, h: Real, n: u32, x0: Tri, x1: Tri, x2: Tri) -> Bt {
    var bt: Bt;
    let half_dr = 0.5 * ((c.r1 - c.r0) / h);
    let s = 0.5 / h;
    var o = c.d1; // directors of the other end
    var sg: Real = -1.0;
    if n == 1u { o = c.d0; sg = 1.0; }
    bt.u[0] = sg * (0.5 * (c.d0[0] + c.d1[0])) / h;
    bt.u[1] = sg * (0.5 * (c.d0[1] + c.d1[1])) / h;
    bt.u[2] = sg * (0.5 * (c.d0[2] + c.d1[2])) / h;
    bt.t[0] = mtv(x0, half_dr);
    bt.t[1] = mtv(x1, half_dr);
    bt.t[2] = mtv(x2, half_dr);
    // Ω rows (k, i, j) cyclic: end 0 has +s o_i at a = j and −s o_j at a = i; end 1 the
    // opposite signs at b = j and b = i.
    bt.t[3] = mtv(x1, sg * (s * o[2])) + mtv(x2, -sg * (s * o[1]));
    bt.t[4] = mtv(x0, -sg * (s * o[2])) + mtv(x2, sg * (s * o[0]));
    bt.t[5] = mtv(x0, sg * (s * o[1])) + mtv(x1, -sg * (s * o[0]));
    return bt;
}

fn tangent_prep(n: u32) {
    let h = ld_e(E_H);
    let beta_g = ld_o(O_S);
    let beta_o = ld_o(O_S + 1u);
    let st = load_state();
    let cfg1 = Cfg(ld_t3(T_C1), ld_t3(T_C1 + 3u), ld_tri(T_C1 + 6u), ld_tri(T_C1 + 15u));
    let mid = cfg_mean(st.cfg, cfg1);
    let amat_n = ld_tri(T_A + 9u * n);
    let t0 = tmat_of(mid, 2u + 3u * n);
    let t1 = tmat_of(mid, 3u + 3u * n);
    let t2 = tmat_of(mid, 4u + 3u * n);
    // D B̃_{n+1}: B at Φ_{n+1} with J_a = A_n T_a, then ½(1+β) C.
    let b1 = btilde(cfg1, h, n, mm(amat_n, t0), mm(amat_n, t1), mm(amat_n, t2));
    let sg = 0.5 * (1.0 + beta_g);
    let so = 0.5 * (1.0 + beta_o);
    let base = T_DB + 36u * n;
    for (var i = 0u; i < 3u; i++) {
        let cgi = sg * ld_e(E_CG + i);
        st_t3(base + 6u * i, cgi * b1.u[i]);
        st_t3(base + 6u * i + 3u, cgi * b1.t[i]);
        let c0 = so * ld_e(E_CO + 3u * i);
        let c1 = so * ld_e(E_CO + 3u * i + 1u);
        let c2 = so * ld_e(E_CO + 3u * i + 2u);
        st_t3(base + 6u * (3u + i), V3(0.0, 0.0, 0.0) + c0 * b1.u[3] + c1 * b1.u[4] + c2 * b1.u[5]);
        st_t3(base + 6u * (3u + i) + 3u, V3(0.0, 0.0, 0.0) + c0 * b1.t[3] + c1 * b1.t[4] + c2 * b1.t[5]);
    }
    // B̃_½: B at Φ_½ with T_a.
    let bm = btilde(mid, h, n, t0, t1, t2);
    let bb = T_BT + 36u * n;
    for (var k = 0u; k < 6u; k++) {
        st_t3(bb + 6u * k, bm.u[k]);
        st_t3(bb + 6u * k + 3u, bm.t[k]);
    }
}

@compute @workgroup_size(64)
fn tangent_prep_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_tan { return; }
    gi = tan_list[gid.x];
    if ld_i(I_ACTIVE) <= 0.0 { return; }
    tangent_prep(gid.y);
}

// h B̃_½ᵀ D B̃ for one 3×3 field block: column c = Σ_k (h b_k) (d_k)_c, k ascending.
fn mat_blk(b: array<V3, 6>, d: array<V3, 6>, h: Real) -> Tri {
    let b0 = h * b[0];
    let b1 = h * b[1];
    let b2 = h * b[2];
    let b3 = h * b[3];
    let b4 = h * b[4];
    let b5 = h * b[5];
    let z = V3(0.0, 0.0, 0.0);
    return Tri(
        z + b0 * d[0].x + b1 * d[1].x + b2 * d[2].x + b3 * d[3].x + b4 * d[4].x + b5 * d[5].x,
        z + b0 * d[0].y + b1 * d[1].y + b2 * d[2].y + b3 * d[3].y + b4 * d[4].y + b5 * d[5].y,
        z + b0 * d[0].z + b1 * d[1].z + b2 * d[2].z + b3 * d[3].z + b4 * d[4].z + b5 * d[5].z,
    );
}

fn ld_cols(f: u32) -> array<V3, 6> {
    return array<V3, 6>(ld_t3(f), ld_t3(f + 6u), ld_t3(f + 12u), ld_t3(f + 18u), ld_t3(f + 24u), ld_t3(f + 30u));
}

fn st_blk(r0: u32, c0: u32, b: Tri) {
    for (var c = 0u; c < 3u; c++) {
        kset(r0, c0 + c, b[c].x);
        kset(r0 + 1u, c0 + c, b[c].y);
        kset(r0 + 2u, c0 + c, b[c].z);
    }
}

// v0 (the stress part of G_s) plus the director masses between director a of end l and
// director b of end m (a, b < 2), added in the CPU kernel's order over the summed end m'.
fn dir_mass(v0: Real, l: u32, m: u32, a: u32, b: u32, h: Real, dt: Real, dw: Real, kap0: Real, kap1: Real, free_m: bool) -> Real {
    var v = v0;
    let i_ab = irho(a, b);
    let mass0 = h * m2(l, 0u) * i_ab / dt;
    if m == 0u { v += mass0 * 2.0 / dt; }
    if free_m { v -= mass0 * 2.0 * kap0 * dw; }
    let mass1 = h * m2(l, 1u) * i_ab / dt;
    if m == 1u { v += mass1 * 2.0 / dt; }
    if free_m { v -= mass1 * 2.0 * kap1 * dw; }
    return v;
}

fn tangent_block(l: u32, m: u32) {
    let h = ld_e(E_H);
    let a_rho = ld_e(E_ARHO);
    let dt = ld_e(E_DT);
    let c_v = ld_o(O_S + 2u);
    let c_nu = ld_o(O_S + 3u);
    let st = load_state();
    let cfg1 = Cfg(ld_t3(T_C1), ld_t3(T_C1 + 3u), ld_tri(T_C1 + 6u), ld_tri(T_C1 + 15u));
    let mid = cfg_mean(st.cfg, cfg1);
    let amat_l = ld_tri(T_A + 9u * l);
    let amat_m = ld_tri(T_A + 9u * m);
    let ch = 0.5 / h;
    let hh = 0.5 * h;
    let kap0 = kappa(0u);
    let kap1 = kappa(1u);
    let ksum = kap0 + kap1;
    let free_m = ld_e(E_ROTFREE + m) != 0.0;
    let dw = c_nu / (dt * (1.0 + ksum * c_nu));
    // Stress forces n (per director index) and moments m' (hat form) of G_s, before ½h.
    let n = V3(ld_t(T_SS), ld_t(T_SS + 1u), ld_t(T_SS + 2u)) * ch;
    let mo = V3(ld_t(T_SS + 3u), ld_t(T_SS + 4u), ld_t(T_SS + 5u)) * ch;
    // T_i (node l, test side) and J_j = A_m T_j (node m, trial side).
    let dl = cfg_d(mid, l);
    let dm = cfg_d(mid, m);
    let t0 = mscale(hat(dl[0]), -1.0);
    let t1 = mscale(hat(dl[1]), -1.0);
    let t2 = mscale(hat(dl[2]), -1.0);
    let j0 = mm(amat_m, mscale(hat(dm[0]), -1.0));
    let j1 = mm(amat_m, mscale(hat(dm[1]), -1.0));
    let j2 = mm(amat_m, mscale(hat(dm[2]), -1.0));
    let bu = ld_cols(T_BT + 36u * l);
    let bt = ld_cols(T_BT + 36u * l + 3u);
    let du = ld_cols(T_DB + 36u * m);
    let dt3 = ld_cols(T_DB + 36u * m + 3u);
    let r0 = 6u * l;
    let c0 = 6u * m;
    // Each block: material, then G_s terms over its field pairs in the CPU kernel's order
    // (pairs with G_s = 0 add exact zeros; products with an identity T or J are exact).
    // u_l × u_m: translational mass.
    var guu = 2.0 / (dt * dt) * a_rho * h * m2(l, m) + ld_e(E_DRAG) * h / dt * m2(l, m);
    // A point mass carried by end l (twin of element::point_mass::add_point_mass_rows).
    var mp: Real = 0.0;
    if l == m { mp = ld_e(E_PMASS + l); }
    guu += 2.0 * mp / (dt * dt);
    st_blk(r0, c0, madd(mat_blk(bu, du, h), mscale(eye(), guu)));
    // u_l × θ_m: stress forces (+ at end 1, − at end 0).
    var sl: Real = -1.0;
    if l == 1u { sl = 1.0; }
    var sm: Real = -1.0;
    if m == 1u { sm = 1.0; }
    var b = mat_blk(bu, dt3, h);
    b = madd(b, mscale(j0, (sl * n.x) * hh));
    b = madd(b, mscale(j1, (sl * n.y) * hh));
    b = madd(b, mscale(j2, (sl * n.z) * hh));
    // Follower line loads (twin of element::follower::end_load): −∂F_l/∂θ_l.
    let ff = ld_e3(E_FOLLOW);
    let fm = ld_e3(E_FOLLOW + 3u);
    let follow = l == m && (has_follower(ff, fm));
    if follow { b = madd(b, follower_block(amat_l, dl, ff, hh)); }
    st_blk(r0, c0 + 3u, b);
    // θ_l × u_m.
    b = mat_blk(bt, du, h);
    b = madd(b, mscale(mt(t0), (sm * n.x) * hh));
    b = madd(b, mscale(mt(t1), (sm * n.y) * hh));
    b = madd(b, mscale(mt(t2), (sm * n.z) * hh));
    st_blk(r0 + 3u, c0, b);
    // θ_l × θ_m: moments couple A_a with B_b (G[a][b] = hat(m')[a][b], transposed for
    // l = 1), then the director masses (directors 0 and 1 of each end).
    var hm = Tri(V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 0.0));
    if l == 0u && m == 1u { hm = hat(mo); }
    if l == 1u && m == 0u { hm = mt(hat(mo)); }
    // g_ij = hm[j][i] (column j, row i), times ½h, plus masses.
    let g00 = dir_mass(hm[0].x * hh, l, m, 0u, 0u, h, dt, dw, kap0, kap1, free_m);
    let g01 = dir_mass(hm[1].x * hh, l, m, 0u, 1u, h, dt, dw, kap0, kap1, free_m);
    let g10 = dir_mass(hm[0].y * hh, l, m, 1u, 0u, h, dt, dw, kap0, kap1, free_m);
    let g11 = dir_mass(hm[1].y * hh, l, m, 1u, 1u, h, dt, dw, kap0, kap1, free_m);
    b = mat_blk(bt, dt3, h);
    let tt0 = mt(t0);
    let tt1 = mt(t1);
    let tt2 = mt(t2);
    b = madd(b, mscale(mm(tt0, j0), g00));
    b = madd(b, mscale(mm(tt0, j1), g01));
    b = madd(b, mscale(mm(tt0, j2), hm[2].x * hh));
    b = madd(b, mscale(mm(tt1, j0), g10));
    b = madd(b, mscale(mm(tt1, j1), g11));
    b = madd(b, mscale(mm(tt1, j2), hm[2].y * hh));
    b = madd(b, mscale(mm(tt2, j0), hm[0].z * hh));
    b = madd(b, mscale(mm(tt2, j1), hm[1].z * hh));
    b = madd(b, mscale(mm(tt2, j2), hm[2].z * hh));
    if l == m {
        let f = T_F + 9u * l;
        var th = Tri(V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 0.0));
        th = madd(th, mm(mm(hat(ld_t3(f)), amat_l), hat(dl[0])));
        th = madd(th, mm(mm(hat(ld_t3(f + 3u)), amat_l), hat(dl[1])));
        th = madd(th, mm(mm(hat(ld_t3(f + 6u)), amat_l), hat(dl[2])));
        b = madd(b, mscale(th, 0.5));
    }
    if follow { b = madd(b, follower_block(amat_l, dl, fm, hh)); }
    st_blk(r0 + 3u, c0 + 3u, b);
    // g rows and columns: translational dissipation terms on the diagonals (the other
    // entries of these rows and columns, and θ_l × g_m, g_l × θ_m, are structurally zero:
    // the tangent pass never writes them, and the output buffer starts zeroed).
    let trans = ld_e(E_TRANS) != 0.0;
    let mmass = a_rho * h * m2(l, m);
    let cv = 0.5 * h * a_rho * c_v;
    var ug: Real = 0.0;
    var gu: Real = 0.0;
    var gg: Real = 0.0;
    if trans {
        ug = -2.0 * mmass / dt - 2.0 * mp / dt;
        gu = -cv / dt;
        gg = mmass + cv + mp;
    }
    for (var c = 0u; c < 3u; c++) {
        kset(u_idx(l) + c, g_idx(m) + c, ug);
        kset(g_idx(l) + c, u_idx(m) + c, gu);
        kset(g_idx(l) + c, g_idx(m) + c, gg);
    }
}

@compute @workgroup_size(64)
fn tangent_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_tan { return; }
    gi = tan_list[gid.x];
    if ld_i(I_ACTIVE) <= 0.0 { return; }
    tangent_block(gid.y / 2u, gid.y % 2u);
}

// ---- step advance and records (twin of Simulation::advance and of the element terms of
// integrator::invariants) ----

fn st_s3(f: u32, v: V3) {
    state[f * prm.n + gi] = v.x;
    state[(f + 1u) * prm.n + gi] = v.y;
    state[(f + 2u) * prm.n + gi] = v.z;
}

// The state of the current slot at n+1 over its state at n.
fn st_next(k: Kin) {
    st_s3(S_R, k.cfg1.r0);
    st_s3(S_R + 3u, k.cfg1.r1);
    for (var i = 0u; i < 3u; i++) {
        st_s3(S_D + 3u * i, k.cfg1.d0[i]);
        st_s3(S_D + 9u + 3u * i, k.cfg1.d1[i]);
    }
    st_s3(S_V, k.v10);
    st_s3(S_V + 3u, k.v11);
    for (var a = 0u; a < 4u; a++) { st_s3(S_VD + 3u * a, k.vd1[a]); }
    st_s3(S_EPS, k.eps1.g);
    st_s3(S_EPS + 3u, k.eps1.o);
}

@compute @workgroup_size(64)
fn advance_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_tan { return; }
    gi = tan_list[gid.x];
    let dt = ld_e(E_DT);
    let h = ld_e(E_H);
    let a_rho = ld_e(E_ARHO);
    let st = load_state();
    var x: array<Real, 18>;
    for (var i = 0u; i < 18u; i++) { x[i] = ld_i(I_X + i); }
    // On the branch of the director factor the increment was solved with; the frozen
    // kinematics differ from the consistent ones only through c_ν.
    let c_frozen = ld_i(I_S + 3u);
    let c = consistent_scalars(st, x, dt, c_frozen);
    let loc = local_law(c.kin.inputs, a_rho, dt / h, dt);
    let inp = c.kin.inputs;
    var diss = h * (0.5 * a_rho * loc.dv * (inp.v_n1 - inp.v_n)
        + 0.5 * a_rho * loc.dnu * (inp.nu_n1 - inp.nu_n)
        + 0.5 * loc.beta_g * inp.x_g
        + 0.5 * loc.beta_o * inp.x_o);
    // Drag's share of D (twin of element::drag::drag_dissipation).
    let drag = ld_e(E_DRAG);
    if drag != 0.0 {
        let u0 = V3(x[0], x[1], x[2]);
        let u1 = V3(x[6], x[7], x[8]);
        let k = drag * h / dt;
        diss += dot(drag_row(0u, u0, u1, k), u0) + dot(drag_row(1u, u0, u1, k), u1);
    }
    var kin = c.kin;
    if prm.mode == 0u && abs(ld_i(I_ACTIVE)) != 2.0 && c_frozen != c.s[3] {
        kin = kinematics(st, x, c_frozen, dt);
    }
    // (Everything below reads `kin` and `st`, not the state: in place is safe.)
    if prm.dry == 0u {
        st_next(kin);
        // A dissipative scheme's next step starts from the scalars consistent with the
        // accepted increment (the host's step: `frozen = consistent`); T_FS keeps them
        // for a hand-back of that step to the host.
        if ld_e(E_SCHEME) != 0.0 {
            for (var i = 0u; i < 4u; i++) {
                st_i(I_S + i, c.s[i]);
                st_t(T_FS + i, c.s[i]);
            }
        }
    }
    // Invariants' element terms at n+1 (two-point rule for K, L, J; one-point for V).
    var kinetic: Real = 0.0;
    var lm = V3(0.0, 0.0, 0.0);
    var jm = V3(0.0, 0.0, 0.0);
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) {
            let w = h * m2(l, m);
            let rl = cfg_r(kin.cfg1, l);
            let vl = kin_v1(kin, l);
            let vm = kin_v1(kin, m);
            kinetic += 0.5 * w * a_rho * dot(vl, vm);
            lm += w * a_rho * vm;
            jm += w * a_rho * cross(rl, vm);
            let dl = cfg_d(kin.cfg1, l);
            for (var a = 0u; a < 2u; a++) {
                for (var b = 0u; b < 2u; b++) {
                    let ir = w * irho(a, b);
                    let vlb = kin.vd1[2u * m + b];
                    kinetic += 0.5 * ir * dot(kin.vd1[2u * l + a], vlb);
                    jm += ir * cross(dl[a], vlb);
                }
            }
        }
    }
    let dg = kin.eps1.g - V3(ld_e(E_EPS0), ld_e(E_EPS0 + 1u), ld_e(E_EPS0 + 2u));
    let dom = kin.eps1.o - V3(ld_e(E_EPS0 + 3u), ld_e(E_EPS0 + 4u), ld_e(E_EPS0 + 5u));
    let cg = V3(ld_e(E_CG), ld_e(E_CG + 1u), ld_e(E_CG + 2u));
    let stored = 0.5 * h * (dot(dg, cg * dg) + dot(dom, c_omega_mv(dom)));
    // Point masses carried by the ends (twin of integrator::invariants): ½ m |v|², m v,
    // r × m v at n+1.
    for (var l = 0u; l < 2u; l++) {
        let mp = ld_e(E_PMASS + l);
        if mp != 0.0 {
            let vl = kin_v1(kin, l);
            kinetic += 0.5 * mp * dot(vl, vl);
            lm += mp * vl;
            jm += mp * cross(cfg_r(kin.cfg1, l), vl);
        }
    }
    st_t(T_ADV, kinetic);
    st_t(T_ADV + 1u, stored);
    st_t3(T_ADV + 2u, lm);
    st_t3(T_ADV + 5u, jm);
    st_t(T_ADV + 8u, diss);
    // Acceleration norms' sums (twin of integrator::invariants::acceleration_norms).
    var at: Real = 0.0;
    var ar: Real = 0.0;
    let acc0 = (kin.v10 - st.v0) / dt;
    let acc1 = (kin.v11 - st.v1) / dt;
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) {
            let w = h * m2(l, m);
            var al = acc0;
            if l == 1u { al = acc1; }
            var am = acc0;
            if m == 1u { am = acc1; }
            at += w * dot(al, am);
            for (var a = 0u; a < 2u; a++) {
                let dl = (kin.vd1[2u * l + a] - st.vd[2u * l + a]) / dt;
                let dm = (kin.vd1[2u * m + a] - st.vd[2u * m + a]) / dt;
                ar += w * dot(dl, dm);
            }
        }
    }
    st_t(T_ADV + 9u, at);
    st_t(T_ADV + 10u, ar);
    // How far the end triads' relative turn passes the limit (cos δ below MAX_TURN_COS).
    let d0 = kin.cfg1.d0;
    let d1 = kin.cfg1.d1;
    let cos_turn = (dot(d0[0], d1[0]) + dot(d0[1], d1[1]) + dot(d0[2], d1[2]) - 1.0) / 2.0;
    st_t(T_ADV + 11u, max(MAX_TURN_COS - cos_turn, 0.0));
    // The follower loads' work F·u + M·θ over the step (twin of the host's follower_work).
    var fwork: Real = 0.0;
    let ff = ld_e3(E_FOLLOW);
    let fm = ld_e3(E_FOLLOW + 3u);
    if has_follower(ff, fm) {
        for (var l = 0u; l < 2u; l++) {
            let d = cfg_d(kin.mid, l);
            fwork += dot(follower_row(d, ff, 0.5 * h), V3(x[u_idx(l)], x[u_idx(l) + 1u], x[u_idx(l) + 2u]));
            fwork += dot(follower_row(d, fm, 0.5 * h), V3(x[th_idx(l)], x[th_idx(l) + 1u], x[th_idx(l) + 2u]));
        }
    }
    st_t(T_ADV + 12u, fwork);
}

@compute @workgroup_size(64)
fn record_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let m = gid.x;
    let per = prm.per_member;
    if per == 0u || m >= prm.n / per { return; }
    for (var k = 0u; k < N_ADV; k++) {
        var sum: Real = 0.0;
        for (var e = 0u; e < per; e++) {
            let i = m * per + e;
            if prm.dry != 0u || iter[I_ACTIVE * prm.n + i] > 0.0 { sum += tmid[(T_ADV + k) * prm.n + i]; }
        }
        tmid[(T_REC + k) * prm.n + m] = sum;
    }
}
