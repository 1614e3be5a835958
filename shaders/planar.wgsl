// PLANAR ELEMENT KERNEL, WGSL twin of `src/element/planar.rs` for frozen dissipation
// scalars: kinematics (Cayley turn about the normal), planar strains (Γ_s, Γ_t, κ),
// mid-point gradient, stresses (mean of the strains or mid-point strain), residual (10),
// row scales (10) and tangent (10×10). Same arithmetic, term by term; rational operations
// only. One invocation per element; array-of-structs buffers (element i's inputs at
// `inp[NIN * i ..]`, its outputs at `out[NOUT * i ..]`, layout in `src/gpu/planar.rs`).

alias Real = f64;
alias V2 = vec2<Real>;

const NIN: u32 = 56u;
const NOUT: u32 = 120u;
const GROSS_WEIGHT: Real = 1e-4;

// ---- input fields ----
const I_H: u32 = 0u;
const I_ARHO: u32 = 1u;
const I_IS: u32 = 2u;
const I_IAMAX: u32 = 3u;
const I_C: u32 = 4u;       // 3
const I_EPS0: u32 = 7u;    // 3
const I_KAPPA: u32 = 10u;  // 2
const I_ROTFREE: u32 = 12u; // 2 (1 = free)
const I_R: u32 = 14u;      // 4: r0, r1
const I_D: u32 = 18u;      // 8: s0, t0, s1, t1
const I_V: u32 = 26u;      // 4
const I_VS: u32 = 30u;     // 4
const I_EPSN: u32 = 34u;   // 3
const I_X: u32 = 37u;      // 10: planar increment (u0 θ0 u1 θ1 g0 g1)
const I_S: u32 = 47u;      // 4: β_Γ β_Ω c_v c_ν
const I_DT: u32 = 51u;
const I_MIDPOINT: u32 = 52u; // 1 = mid-point strain rule
const I_TRANS: u32 = 53u;    // 1 = translational dissipation rows
const I_TANGENT: u32 = 54u;  // 1 = tangent wanted

@group(0) @binding(0) var<storage, read> inp: array<Real>;
@group(0) @binding(1) var<storage, read_write> out: array<Real>;

var<private> base: u32;
var<private> kt: array<Real, 100>;

fn at(f: u32) -> Real { return inp[base + f]; }
fn at2(f: u32) -> V2 { return V2(inp[base + f], inp[base + f + 1u]); }
fn cross2(a: V2, b: V2) -> Real { return a.x * b.y - a.y * b.x; }
fn perp(a: V2) -> V2 { return V2(-a.y, a.x); }
fn amax2(a: V2) -> Real { return max(abs(a.x), abs(a.y)); }
fn m2(l: u32, m: u32) -> Real { if l == m { return 2.0 / 6.0; } return 1.0 / 6.0; }
fn pu(l: u32) -> u32 { return 3u * l; }
fn pth(l: u32) -> u32 { return 3u * l + 2u; }
fn pg(l: u32) -> u32 { return 6u + 2u * l; }
// Fields: 0 r0, 1 r1, then per end (s, t): 2 s0, 3 t0, 4 s1, 5 t1.
fn dfield(l: u32, i: u32) -> u32 { return 2u + 2u * l + i; }
fn field_end(p: u32) -> u32 { if p < 2u { return p; } return (p - 2u) / 2u; }

struct Cfg { r: array<V2, 2>, d: array<V2, 4> }  // d[2l + i]

fn strains(c: Cfg, h: Real) -> vec3<Real> {
    let dr = (c.r[1] - c.r[0]) / h;
    return vec3<Real>(
        0.5 * dot(c.d[0] + c.d[2], dr),
        0.5 * dot(c.d[1] + c.d[3], dr),
        (dot(c.d[1], c.d[2]) - dot(c.d[0], c.d[3])) * (0.5 / h));
}

// B: row k (0 Γ_s, 1 Γ_t, 2 κ), field p → 2-vector, stored at 6k + p.
fn gradient(c: Cfg, h: Real) -> array<V2, 18> {
    var bm: array<V2, 18>;
    let dr = (c.r[1] - c.r[0]) / h;
    for (var i = 0u; i < 2u; i++) {
        let di = 0.5 * (c.d[i] + c.d[2u + i]);
        bm[6u * i + 0u] = -di / h;
        bm[6u * i + 1u] = di / h;
        bm[6u * i + dfield(0u, i)] = 0.5 * dr;
        bm[6u * i + dfield(1u, i)] = 0.5 * dr;
    }
    let s = 0.5 / h;
    bm[12u + dfield(0u, 1u)] = s * c.d[2];
    bm[12u + dfield(1u, 0u)] = s * c.d[1];
    bm[12u + dfield(0u, 0u)] = -s * c.d[3];
    bm[12u + dfield(1u, 1u)] = -s * c.d[0];
    return bm;
}

fn hessian(sv: vec3<Real>, h: Real) -> array<Real, 36> {
    var hs: array<Real, 36>;
    let c = 0.5 / h;
    for (var i = 0u; i < 2u; i++) {
        let n = sv[i] * c;
        for (var e = 0u; e < 2u; e++) {
            let p = dfield(e, i);
            hs[6u * 1u + p] += n;
            hs[6u * p + 1u] += n;
            hs[p] -= n;
            hs[6u * p] -= n;
        }
    }
    let m = sv[2] * c;
    let t0 = dfield(0u, 1u);
    let s1 = dfield(1u, 0u);
    let s0 = dfield(0u, 0u);
    let t1 = dfield(1u, 1u);
    hs[6u * t0 + s1] += m;
    hs[6u * s1 + t0] += m;
    hs[6u * s0 + t1] -= m;
    hs[6u * t1 + s0] -= m;
    return hs;
}

fn cay2(theta: Real) -> V2 {
    let q = 0.25 * theta * theta;
    let den = 1.0 / (1.0 + q);
    return V2((1.0 - q) * den, theta * den);
}
fn rotate(cs: V2, a: V2) -> V2 {
    return V2(cs.x * a.x - cs.y * a.y, cs.y * a.x + cs.x * a.y);
}
fn kadd(i: u32, j: u32, x: Real) { kt[10u * i + j] += x; }

@compute @workgroup_size(64)
fn planar_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    if e >= arrayLength(&inp) / NIN { return; }
    base = NIN * e;
    let ob = NOUT * e;
    let h = at(I_H);
    let dt = at(I_DT);
    let a_rho = at(I_ARHO);
    let i_s = at(I_IS);
    let cc = vec3<Real>(at(I_C), at(I_C + 1u), at(I_C + 2u));
    let eps0 = vec3<Real>(at(I_EPS0), at(I_EPS0 + 1u), at(I_EPS0 + 2u));
    let kappa = V2(at(I_KAPPA), at(I_KAPPA + 1u));
    let beta_g = at(I_S);
    let beta_o = at(I_S + 1u);
    let c_v = at(I_S + 2u);
    let c_nu = at(I_S + 3u);
    let trans = at(I_TRANS) != 0.0;

    // ---- state and increment ----
    var c0: Cfg;
    c0.r[0] = at2(I_R);
    c0.r[1] = at2(I_R + 2u);
    for (var j = 0u; j < 4u; j++) { c0.d[j] = at2(I_D + 2u * j); }
    var v = array<V2, 2>(at2(I_V), at2(I_V + 2u));
    var vs = array<V2, 2>(at2(I_VS), at2(I_VS + 2u));
    let eps_n = vec3<Real>(at(I_EPSN), at(I_EPSN + 1u), at(I_EPSN + 2u));
    var u = array<V2, 2>(at2(I_X + 0u), at2(I_X + 3u));
    var th = array<Real, 2>(at(I_X + 2u), at(I_X + 5u));
    var g = array<V2, 2>(at2(I_X + 6u), at2(I_X + 8u));

    // ---- kinematics ----
    var rot = array<V2, 2>(cay2(th[0]), cay2(th[1]));
    var c1: Cfg;
    var mid: Cfg;
    for (var l = 0u; l < 2u; l++) {
        c1.r[l] = c0.r[l] + u[l];
        mid.r[l] = 0.5 * (c0.r[l] + c1.r[l]);
        for (var i = 0u; i < 2u; i++) {
            c1.d[2u * l + i] = rotate(rot[l], c0.d[2u * l + i]);
            mid.d[2u * l + i] = 0.5 * (c0.d[2u * l + i] + c1.d[2u * l + i]);
        }
    }
    let eps1 = strains(c1, h);
    var v1: array<V2, 2>;
    for (var l = 0u; l < 2u; l++) { v1[l] = 2.0 * u[l] / dt - v[l] - 2.0 * g[l]; }
    let ksum = kappa.x + kappa.y;
    var dd = array<V2, 2>(c1.d[0] - c0.d[0], c1.d[2] - c0.d[2]);
    let y = (dd[0] + dd[1]) / dt;
    let w = y * (c_nu / (1.0 + ksum * c_nu));
    var vs1: array<V2, 2>;
    for (var l = 0u; l < 2u; l++) { vs1[l] = 2.0 * dd[l] / dt - vs[l] - 2.0 * kappa[l] * w; }

    // ---- stresses and forces ----
    var mean = 0.5 * (eps_n + eps1);
    if at(I_MIDPOINT) != 0.0 { mean = strains(mid, h); }
    mean = mean - eps0;
    let de = eps1 - eps_n;
    let sstar = vec3<Real>(
        cc.x * (mean.x + 0.5 * beta_g * de.x),
        cc.y * (mean.y + 0.5 * beta_g * de.y),
        cc.z * (mean.z + 0.5 * beta_o * de.z));
    var bm = gradient(mid, h);
    let eps_abs = abs(0.5 * (eps_n + eps1)) + abs(eps0);
    let gross = cc * eps_abs * (GROSS_WEIGHT * h);
    var f: array<V2, 6>;
    var fgross: array<Real, 6>;
    for (var i = 0u; i < 2u; i++) {
        let hs = h * sstar[i];
        var fl = array<u32, 4>(0u, 1u, dfield(0u, i), dfield(1u, i));
        for (var q = 0u; q < 4u; q++) {
            let p = fl[q];
            f[p] += bm[6u * i + p] * hs;
            fgross[p] += amax2(bm[6u * i + p]) * gross[i];
        }
    }
    for (var p = 2u; p < 6u; p++) {
        f[p] += bm[12u + p] * (h * sstar.z);
        fgross[p] += amax2(bm[12u + p]) * gross.z;
    }
    var stress_scale = array<Real, 2>(max(amax2(f[0]), fgross[0]), max(amax2(f[1]), fgross[1]));
    var inertia_r: array<V2, 2>;
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) {
            inertia_r[l] += (a_rho * h * m2(l, m) / dt) * (v1[m] - v[m]);
        }
    }
    var fd_scale: array<Real, 2>;
    for (var l = 0u; l < 2u; l++) {
        let fs = dfield(l, 0u);
        var fi = V2(0.0, 0.0);
        for (var m = 0u; m < 2u; m++) { fi += (h * m2(l, m) * i_s / dt) * (vs1[m] - vs[m]); }
        let rate = h * at(I_IAMAX) * (amax2(vs[l]) + amax2(vs1[l])) / dt;
        fd_scale[l] = max(max(max(amax2(fi), amax2(f[fs])), max(rate, fgross[fs])),
                          max(amax2(f[dfield(l, 1u)]), fgross[dfield(l, 1u)]));
        f[fs] += fi;
    }
    var r: array<Real, 10>;
    var sc: array<Real, 10>;
    for (var l = 0u; l < 2u; l++) {
        let fr = f[l] + inertia_r[l];
        r[pu(l)] = fr.x;
        r[pu(l) + 1u] = fr.y;
        r[pth(l)] = cross2(mid.d[2u * l], f[dfield(l, 0u)]) + cross2(mid.d[2u * l + 1u], f[dfield(l, 1u)]);
        let momentum_rate = a_rho * h * (amax2(v[l]) + amax2(v1[l])) / dt;
        let su = max(max(stress_scale[l], amax2(inertia_r[l])), momentum_rate);
        let dnorm = max(max(length(mid.d[2u * l]), length(mid.d[2u * l + 1u])), 1.0);
        sc[pu(l)] = su;
        sc[pu(l) + 1u] = su;
        sc[pth(l)] = fd_scale[l] * dnorm;
    }
    if trans {
        let vsum = 0.5 * (v[0] + v[1]) + 0.5 * (v1[0] + v1[1]);
        let b = 0.5 * h * a_rho * c_v * vsum;
        var gm: array<V2, 2>;
        var pieces = Real(0.0);
        for (var m = 0u; m < 2u; m++) {
            gm[m] = (c1.r[m] - c0.r[m]) / dt - 0.5 * (v[m] + v1[m]);
            pieces += amax2((c1.r[m] - c0.r[m]) / dt) + amax2(gm[m]);
        }
        pieces *= 0.5 * h * a_rho * abs(c_v);
        for (var l = 0u; l < 2u; l++) {
            var mg = V2(0.0, 0.0);
            for (var m = 0u; m < 2u; m++) { mg += a_rho * h * m2(l, m) * gm[m]; }
            let rg = mg - b;
            r[pg(l)] = rg.x;
            r[pg(l) + 1u] = rg.y;
            let momentum = max(0.5 * a_rho * h * max(amax2(v[l]), amax2(v1[l])), pieces);
            let s = max(max(amax2(mg), amax2(b)), momentum);
            sc[pg(l)] = s;
            sc[pg(l) + 1u] = s;
        }
    }
    for (var i = 0u; i < 10u; i++) {
        out[ob + i] = r[i];
        out[ob + 10u + i] = sc[i];
    }
    if at(I_TANGENT) == 0.0 { return; }

    // ---- tangent ----
    // Trial side: the strains at n+1 (mean of the strains); with the mid-point strain the
    // elastic part varies with Φ_½ and only the dissipative ½ β C Δε with the end strains.
    let midpoint = at(I_MIDPOINT) != 0.0;
    let bend = gradient(c1, h);
    var b1 = bend;
    if midpoint { b1 = bm; }
    var amat: array<mat2x2<Real>, 2>;
    for (var l = 0u; l < 2u; l++) {
        let den = 0.5 * (1.0 + rot[l].x);
        // Column-major: columns (den, ½θ den) and (−½θ den, den).
        amat[l] = mat2x2<Real>(den, 0.5 * th[l] * den, -0.5 * th[l] * den, den);
    }
    var tvec: array<V2, 6>;
    var jvec: array<V2, 6>;
    for (var p = 2u; p < 6u; p++) {
        tvec[p] = perp(mid.d[p - 2u]);
        jvec[p] = amat[(p - 2u) / 2u] * tvec[p];
    }
    var btm: array<Real, 18>;  // 3 × 6
    var bt1: array<Real, 18>;
    var bte: array<Real, 18>;
    for (var k = 0u; k < 3u; k++) {
        for (var l = 0u; l < 2u; l++) {
            for (var c = 0u; c < 2u; c++) {
                btm[6u * k + pu(l) + c] = bm[6u * k + l][c];
                bt1[6u * k + pu(l) + c] = b1[6u * k + l][c];
                bte[6u * k + pu(l) + c] = bend[6u * k + l][c];
            }
        }
        for (var p = 2u; p < 6u; p++) {
            let col = pth(field_end(p));
            btm[6u * k + col] += dot(bm[6u * k + p], tvec[p]);
            bt1[6u * k + col] += dot(b1[6u * k + p], jvec[p]);
            bte[6u * k + col] += dot(bend[6u * k + p], jvec[p]);
        }
    }
    // Material part: ½(1+β) C B̃_1 (mean of the strains); ½ C B̃_½J + ½ β C B̃_1
    // (mid-point strain).
    var fg = 1.0 + beta_g;
    var fo = 1.0 + beta_o;
    var eg = Real(0.0);
    var eo = Real(0.0);
    if midpoint {
        fg = 1.0;
        fo = 1.0;
        eg = beta_g;
        eo = beta_o;
    }
    let dmat = vec3<Real>(0.5 * fg * cc.x, 0.5 * fg * cc.y, 0.5 * fo * cc.z);
    let demat = vec3<Real>(0.5 * eg * cc.x, 0.5 * eg * cc.y, 0.5 * eo * cc.z);
    for (var i = 0u; i < 100u; i++) { kt[i] = 0.0; }
    for (var i = 0u; i < 6u; i++) {
        for (var j = 0u; j < 6u; j++) {
            var s = Real(0.0);
            for (var k = 0u; k < 3u; k++) {
                s += btm[6u * k + i] * (dmat[k] * bt1[6u * k + j] + demat[k] * bte[6u * k + j]);
            }
            kt[10u * i + j] = h * s;
        }
    }
    var gs = hessian(sstar, h);
    for (var i = 0u; i < 36u; i++) { gs[i] *= 0.5 * h; }
    let two_dt2 = 2.0 / (dt * dt);
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) { gs[6u * l + m] += two_dt2 * a_rho * h * m2(l, m); }
    }
    let dw = c_nu / (dt * (1.0 + ksum * c_nu));
    for (var l = 0u; l < 2u; l++) {
        for (var m = 0u; m < 2u; m++) {
            let mass = h * m2(l, m) * i_s / dt;
            let pl = dfield(l, 0u);
            gs[6u * pl + dfield(m, 0u)] += mass * 2.0 / dt;
            for (var qq = 0u; qq < 2u; qq++) {
                if at(I_ROTFREE + qq) != 0.0 {
                    gs[6u * pl + dfield(qq, 0u)] -= mass * 2.0 * kappa[m] * dw;
                }
            }
        }
    }
    for (var pf = 0u; pf < 6u; pf++) {
        for (var qf = 0u; qf < 6u; qf++) {
            let gv = gs[6u * pf + qf];
            if gv == 0.0 { continue; }
            let lp = field_end(pf);
            let lq = field_end(qf);
            if pf < 2u && qf < 2u {
                kadd(pu(lp), pu(lq), gv);
                kadd(pu(lp) + 1u, pu(lq) + 1u, gv);
            } else if pf < 2u {
                for (var c = 0u; c < 2u; c++) { kadd(pu(lp) + c, pth(lq), gv * jvec[qf][c]); }
            } else if qf < 2u {
                for (var c = 0u; c < 2u; c++) { kadd(pth(lp), pu(lq) + c, gv * tvec[pf][c]); }
            } else {
                kadd(pth(lp), pth(lq), gv * dot(tvec[pf], jvec[qf]));
            }
        }
    }
    for (var l = 0u; l < 2u; l++) {
        var x = Real(0.0);
        for (var i = 0u; i < 2u; i++) {
            x += cross2(amat[l] * perp(mid.d[2u * l + i]), f[dfield(l, i)]);
        }
        kadd(pth(l), pth(l), 0.5 * x);
    }
    if trans {
        let cv = 0.5 * h * a_rho * c_v;
        for (var l = 0u; l < 2u; l++) {
            for (var m = 0u; m < 2u; m++) {
                let mm = a_rho * h * m2(l, m);
                for (var c = 0u; c < 2u; c++) {
                    kadd(pu(l) + c, pg(m) + c, -2.0 * mm / dt);
                    kadd(pg(l) + c, pu(m) + c, -cv / dt);
                    kadd(pg(l) + c, pg(m) + c, mm + cv);
                }
            }
        }
    }
    for (var i = 0u; i < 100u; i++) { out[ob + 20u + i] = kt[i]; }
}
