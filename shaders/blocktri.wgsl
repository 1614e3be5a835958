// BATCHED BLOCK-TRIDIAGONAL LU AND SOLVE: one invocation per member (a rod numbered node by
// node), block Thomas with partial pivoting inside the 9×9 diagonal blocks, the WGSL twin of
// `src/linsolve/batched.rs` (same operations in the same order) and the device counterpart
// of `src/linsolve/block_tridiagonal.rs`:
//
//   S_0 = D_0,   W_i = S_i⁻¹ U_i,   S_{i+1} = D_{i+1} − L_i W_i
//   forward:  S_i y_i = b_i − L_{i−1} y_{i−1}
//   backward: x_i = y_i − W_i x_{i+1}
//
// The system is read where the assembly pass writes it (`assemble.wgsl`, Rust twin
// `AsmLayout`): member m's node j residual at m·RPM + 9 j, its diagonal block (row-major
// 9×9) at K + m·KPM + 81 j, element e's off-diagonal blocks (0,1) = U_e and (1,0) = L_e at
// K + m·KPM + 81 NPN + 81 (2 e + h): element e joins nodes e and e+1.
//
// Rows and columns that are not unknowns (bit k of the node's mask clear: a fixed degree of
// freedom, an unused node slot) read as an identity row/column with a zero right-hand side,
// exactly as the padded blocks of the CPU block LU: they change neither the solution nor the
// pivots of the real unknowns, and their solution is 0.
//
// f64 only (rational operations; the adapter must offer SHADER_F64).
//
// Chunks: a dispatch processes the nodes [lo, hi) of every member (the host dispatches the
// chunks in order: factor and forward sweep ascending, backward sweep descending, the
// backward error ascending), so that one invocation never runs more than a few ten
// thousand loop iterations: Mesa's llvmpipe/lavapipe stops any invocation after 65 535
// loop iterations (its infinite-loop guard), which cut the factorization of rods longer
// than ≈ 44 nodes when one invocation did the whole member. The factorization goes in
// chunks of 32 nodes (measured: 32 pass on ill-conditioned members, 64 are cut short),
// the sweeps and the backward error (≤ 300 iterations per node) in chunks of 128
// (`CHUNK_NODES`, `SWEEP_CHUNK_NODES` in `src/gpu/blocktri.rs`).

alias Real = f64;

// Largest finite f64 (a pivot larger than this is +inf).
const BIG: Real = 1.7976931348623157e308;

// Status codes (per member; written by `factor_main`, `solve_main` may add NONFINITE).
const OK: u32 = 0u;
// 1 + i: singular (zero or non-finite pivot) Schur complement of node block i.
const NONFINITE: u32 = 0x80000000u;

struct Params {
    // Member slots.
    n_member: u32,
    // Node slots per member (NPN).
    npn: u32,
    // Start of the tangent region of `sys` (K).
    k_start: u32,
    // Scalars per member of the tangent region (KPM).
    kpm: u32,
    // Scalars per member of the residual region (RPM).
    rpm: u32,
    // 1: the right-hand side is minus the stored residual.
    negate: u32,
    // This dispatch's node chunk [lo, hi) (see "Chunks" above).
    lo: u32,
    hi: u32,
}

@group(0) @binding(0) var<storage, read> sys: array<Real>;
// Per member 3·81·NPN: the LU factors of S_i at 81 i (L unit lower, U upper, row-major),
// W_i at 81 (NPN + i), the masked L_i at 81 (2 NPN + i).
@group(0) @binding(1) var<storage, read_write> fac: array<Real>;
// Per member 9·NPN: the row chosen at step k of block i's elimination at 9 i + k.
@group(0) @binding(2) var<storage, read_write> piv: array<u32>;
// Per member 9·NPN: the solution.
@group(0) @binding(3) var<storage, read_write> xs: array<Real>;
// Per node slot: bit k set when node-local unknown k is an unknown.
@group(0) @binding(4) var<storage, read> mask: array<u32>;
// Per member slot: its number of nodes (0: inactive).
@group(0) @binding(5) var<storage, read> member_n: array<u32>;
// Per member slot: bit 0 factorize, bit 1 solve in this dispatch (bits 2–4: below). The
// passes of a multi-iteration submission clear a member's word when it stops (SPEC).
@group(0) @binding(6) var<storage, read_write> ops: array<u32>;
// Per member slot: status code.
@group(0) @binding(7) var<storage, read_write> status: array<u32>;
// Per member slot: normwise backward error of the last solve,
// ‖b − A x‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞).
@group(0) @binding(8) var<storage, read_write> berr: array<Real>;
@group(0) @binding(9) var<uniform> prm: Params;
// Per node slot 9 values added to the stored residual before it becomes the right-hand
// side (the host's nodal terms: external loads, moments).
@group(0) @binding(10) var<storage, read> extra: array<Real>;
// Per member slot: running backward-error terms (residual, ‖A‖, ‖x‖, ‖b‖; the last is
// negative once a non-finite value was seen).
@group(0) @binding(11) var<storage, read_write> acc: array<Real>;

fn fbase(m: u32) -> u32 { return m * 243u * prm.npn; }
fn kbase(m: u32) -> u32 { return prm.k_start + m * prm.kpm; }

// Entry (r, c) of a block with row mask `mr` and column mask `mc` as the masked system
// sees it: `diag` for diagonal blocks (identity where masked).
fn masked(v: Real, mr: u32, mc: u32, r: u32, c: u32, diag: bool) -> Real {
    if ((mr >> r) & 1u) != 0u && ((mc >> c) & 1u) != 0u { return v; }
    if diag && r == c { return 1.0; }
    return 0.0;
}

fn is_finite(v: Real) -> bool { return abs(v) <= BIG; }

// Applies S_i⁻¹ (pivots, unit lower, upper) in place to the 9-vector of `fac` at `at` with
// stride `st` (a column of W_i), or of `xs` when `in_x`.
fn lu_apply_fac(s: u32, p: u32, at: u32, st: u32) {
    for (var k = 0u; k < 9u; k++) {
        let q = piv[p + k];
        if q != k {
            let t = fac[at + st * k];
            fac[at + st * k] = fac[at + st * q];
            fac[at + st * q] = t;
        }
    }
    for (var r = 1u; r < 9u; r++) {
        var acc = fac[at + st * r];
        for (var c = 0u; c < r; c++) { acc -= fac[s + 9u * r + c] * fac[at + st * c]; }
        fac[at + st * r] = acc;
    }
    for (var ri = 0u; ri < 9u; ri++) {
        let r = 8u - ri;
        var acc = fac[at + st * r];
        for (var c = r + 1u; c < 9u; c++) { acc -= fac[s + 9u * r + c] * fac[at + st * c]; }
        fac[at + st * r] = acc / fac[s + 9u * r + r];
    }
}

fn lu_apply_x(s: u32, p: u32, at: u32) {
    for (var k = 0u; k < 9u; k++) {
        let q = piv[p + k];
        if q != k {
            let t = xs[at + k];
            xs[at + k] = xs[at + q];
            xs[at + q] = t;
        }
    }
    for (var r = 1u; r < 9u; r++) {
        var acc = xs[at + r];
        for (var c = 0u; c < r; c++) { acc -= fac[s + 9u * r + c] * xs[at + c]; }
        xs[at + r] = acc;
    }
    for (var ri = 0u; ri < 9u; ri++) {
        let r = 8u - ri;
        var acc = xs[at + r];
        for (var c = r + 1u; c < 9u; c++) { acc -= fac[s + 9u * r + c] * xs[at + c]; }
        xs[at + r] = acc / fac[s + 9u * r + r];
    }
}

// Copies node i's masked blocks: D_i into the S slot, U_i into the W slot, L_i into the
// L slot.
fn load_node(m: u32, n: u32, i: u32) {
    let f = fbase(m);
    let a = kbase(m);
    let npn = prm.npn;
    let mi = mask[m * npn + i];
    for (var r = 0u; r < 9u; r++) {
        for (var c = 0u; c < 9u; c++) {
            fac[f + 81u * i + 9u * r + c] =
                masked(sys[a + 81u * i + 9u * r + c], mi, mi, r, c, true);
        }
    }
    if i + 1u < n {
        let mj = mask[m * npn + i + 1u];
        let off = a + 81u * npn + 162u * i;
        for (var r = 0u; r < 9u; r++) {
            for (var c = 0u; c < 9u; c++) {
                fac[f + 81u * (npn + i) + 9u * r + c] =
                    masked(sys[off + 9u * r + c], mi, mj, r, c, false);
                fac[f + 81u * (2u * npn + i) + 9u * r + c] =
                    masked(sys[off + 81u + 9u * r + c], mj, mi, r, c, false);
            }
        }
    }
}

// Factorization steps lo ≤ i < hi of member m (n nodes); returns its status. Step i
// needs S_i (D_i minus the update of step i − 1), U_i, L_i and D_{i+1}: a chunk loads the
// blocks of nodes lo + 1 … hi (and node 0 in the first chunk) before its steps.
fn factor(m: u32, n: u32, lo: u32, hi: u32) -> u32 {
    let f = fbase(m);
    let npn = prm.npn;
    if lo == 0u { load_node(m, n, 0u); }
    for (var i = lo + 1u; i < min(hi + 1u, n); i++) { load_node(m, n, i); }
    for (var i = lo; i < hi; i++) {
        let s = f + 81u * i;
        let p = m * 9u * npn + 9u * i;
        // LU of S_i with partial pivoting (first largest magnitude), rows swapped whole.
        for (var k = 0u; k < 9u; k++) {
            var q = k;
            var best = abs(fac[s + 9u * k + k]);
            for (var r = k + 1u; r < 9u; r++) {
                let v = abs(fac[s + 9u * r + k]);
                if v > best { best = v; q = r; }
            }
            piv[p + k] = q;
            if !(best > 0.0) || !is_finite(best) { return 1u + i; }
            if q != k {
                for (var c = 0u; c < 9u; c++) {
                    let t = fac[s + 9u * k + c];
                    fac[s + 9u * k + c] = fac[s + 9u * q + c];
                    fac[s + 9u * q + c] = t;
                }
            }
            let d = fac[s + 9u * k + k];
            for (var r = k + 1u; r < 9u; r++) {
                let l = fac[s + 9u * r + k] / d;
                fac[s + 9u * r + k] = l;
                for (var c = k + 1u; c < 9u; c++) {
                    fac[s + 9u * r + c] -= l * fac[s + 9u * k + c];
                }
            }
        }
        if i + 1u < n {
            let w = f + 81u * (npn + i);
            for (var c = 0u; c < 9u; c++) { lu_apply_fac(s, p, w + c, 9u); }
            let l = f + 81u * (2u * npn + i);
            let s1 = s + 81u;
            for (var r = 0u; r < 9u; r++) {
                for (var c = 0u; c < 9u; c++) {
                    var acc: Real = 0.0;
                    for (var k = 0u; k < 9u; k++) { acc += fac[l + 9u * r + k] * fac[w + 9u * k + c]; }
                    fac[s1 + 9u * r + c] -= acc;
                }
            }
        }
    }
    return OK;
}

// The masked right-hand side entry r of node i of member m: ± (stored residual + extra).
fn rhs(m: u32, i: u32, r: u32) -> Real {
    let mi = mask[m * prm.npn + i];
    if ((mi >> r) & 1u) == 0u { return 0.0; }
    let v = sys[m * prm.rpm + 9u * i + r] + extra[9u * (m * prm.npn + i) + r];
    if prm.negate != 0u { return -v; }
    return v;
}

// Forward sweep over nodes lo ≤ i < hi of member m: y_i = S_i⁻¹ (b_i − L_{i−1} y_{i−1}).
fn forward(m: u32, lo: u32, hi: u32) {
    let f = fbase(m);
    let npn = prm.npn;
    let x = m * 9u * npn;
    for (var i = lo; i < hi; i++) {
        for (var r = 0u; r < 9u; r++) {
            var a = rhs(m, i, r);
            if i > 0u {
                let l = f + 81u * (2u * npn + i - 1u);
                for (var c = 0u; c < 9u; c++) { a -= fac[l + 9u * r + c] * xs[x + 9u * (i - 1u) + c]; }
            }
            xs[x + 9u * i + r] = a;
        }
        lu_apply_x(f + 81u * i, m * 9u * npn + 9u * i, x + 9u * i);
    }
}

// Backward sweep over nodes hi > i ≥ lo (i < n − 1) of member m: x_i = y_i − W_i x_{i+1}.
fn backward(m: u32, n: u32, lo: u32, hi: u32) {
    let f = fbase(m);
    let npn = prm.npn;
    let x = m * 9u * npn;
    for (var ii = lo; ii < hi; ii++) {
        let i = hi - 1u - (ii - lo);
        if i + 1u >= n { continue; }
        let w = f + 81u * (npn + i);
        for (var r = 0u; r < 9u; r++) {
            var a = xs[x + 9u * i + r];
            for (var c = 0u; c < 9u; c++) { a -= fac[w + 9u * r + c] * xs[x + 9u * (i + 1u) + c]; }
            xs[x + 9u * i + r] = a;
        }
    }
}

// Backward-error terms of nodes lo ≤ i < hi of member m against the masked system
// (diagonal and upper blocks from `sys`, the masked lower blocks kept in `fac`),
// accumulated in `acc`; the last chunk writes the backward error and returns the status.
fn backward_error(m: u32, n: u32, lo: u32, hi: u32) -> u32 {
    let f = fbase(m);
    let a = kbase(m);
    let npn = prm.npn;
    let x = m * 9u * npn;
    var res: Real = 0.0;
    var anorm: Real = 0.0;
    var xnorm: Real = 0.0;
    var bnorm: Real = 0.0;
    var finite = true;
    if lo > 0u {
        res = acc[4u * m];
        anorm = acc[4u * m + 1u];
        xnorm = acc[4u * m + 2u];
        bnorm = acc[4u * m + 3u];
        finite = bnorm >= 0.0;
        bnorm = abs(bnorm);
    }
    for (var i = lo; i < hi; i++) {
        let mi = mask[m * npn + i];
        for (var r = 0u; r < 9u; r++) {
            let b = rhs(m, i, r);
            var t = b;
            var rs: Real = 0.0;
            for (var c = 0u; c < 9u; c++) {
                let v = masked(sys[a + 81u * i + 9u * r + c], mi, mi, r, c, true);
                t -= v * xs[x + 9u * i + c];
                rs += abs(v);
            }
            if i + 1u < n {
                let mj = mask[m * npn + i + 1u];
                let off = a + 81u * npn + 162u * i;
                for (var c = 0u; c < 9u; c++) {
                    let v = masked(sys[off + 9u * r + c], mi, mj, r, c, false);
                    t -= v * xs[x + 9u * (i + 1u) + c];
                    rs += abs(v);
                }
            }
            if i > 0u {
                let l = f + 81u * (2u * npn + i - 1u);
                for (var c = 0u; c < 9u; c++) {
                    let v = fac[l + 9u * r + c];
                    t -= v * xs[x + 9u * (i - 1u) + c];
                    rs += abs(v);
                }
            }
            let xv = xs[x + 9u * i + r];
            finite = finite && is_finite(xv);
            res = max(res, abs(t));
            anorm = max(anorm, rs);
            xnorm = max(xnorm, abs(xv));
            bnorm = max(bnorm, abs(b));
        }
    }
    if hi < n {
        acc[4u * m] = res;
        acc[4u * m + 1u] = anorm;
        acc[4u * m + 2u] = xnorm;
        if finite { acc[4u * m + 3u] = bnorm; } else { acc[4u * m + 3u] = -bnorm - 1.0; }
        return OK;
    }
    let den = anorm * xnorm + bnorm;
    var e: Real = 0.0;
    if den > 0.0 { e = res / den; }
    berr[m] = e;
    if !finite || !is_finite(e) { return NONFINITE; }
    return OK;
}

// The member of this invocation and its chunk [lo, hi) clipped to its n nodes, or
// n = 0 when it has nothing to do in this dispatch (bit: the operation).
struct Job { m: u32, n: u32, lo: u32, hi: u32 }

fn job(gid: u32, bit: u32) -> Job {
    var j = Job(gid, 0u, 0u, 0u);
    if gid >= prm.n_member { return j; }
    let n = member_n[gid];
    if n == 0u || (ops[gid] & bit) == 0u || prm.lo >= n { return j; }
    j.n = n;
    j.lo = prm.lo;
    j.hi = min(prm.hi, n);
    return j;
}

fn factor_job(gid: u32) {
    let j = job(gid, 1u);
    if j.n == 0u { return; }
    if j.lo == 0u { status[j.m] = OK; }
    if status[j.m] != OK { return; }
    status[j.m] = factor(j.m, j.n, j.lo, j.hi);
}

@compute @workgroup_size(64)
fn factor_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    factor_job(gid.x);
}

// An iteration of a multi-iteration submission: `spec_check_main`'s check, then the first
// chunk's factorization, in one pass (per member: neither reads another member's data).
@compute @workgroup_size(64)
fn check_factor_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_member { return; }
    if prm.lo == 0u { spec_check(gid.x); }
    factor_job(gid.x);
}

@compute @workgroup_size(64)
fn forward_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = job(gid.x, 2u);
    if j.n == 0u { return; }
    // A solve with kept factors starts from their status: a non-finite earlier solve
    // (NONFINITE comes from solves only) does not carry over, as in the CPU twin.
    if j.lo == 0u && (ops[j.m] & 1u) == 0u && status[j.m] == NONFINITE { status[j.m] = OK; }
    if status[j.m] != OK { return; }
    forward(j.m, j.lo, j.hi);
}

@compute @workgroup_size(64)
fn backward_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = job(gid.x, 2u);
    if j.n == 0u || status[j.m] != OK { return; }
    backward(j.m, j.n, j.lo, j.hi);
}

@compute @workgroup_size(64)
fn berr_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = job(gid.x, 2u);
    if j.n == 0u || status[j.m] != OK { return; }
    status[j.m] = backward_error(j.m, j.n, j.lo, j.hi);
}

// ---------------------------------------------------------------------------------------
// DEVICE-RESIDENT NEWTON (ops bits 2 and 3; `src/gpu/blocktri.rs`, host side in
// `src/integrator/simulation/newton.rs`). The member's Newton increment lives in the
// assembly's node increments `node_x` (field-major: component k of node slot s at
// k·(n_member·NPN) + s, the buffer the gather pass reads), so an iteration needs nothing
// from the host but its operation word, and returns 16 bytes: `report`.
//
// UPDATE (bit 2), after the solve: over the member's unknowns, with r = stored residual +
// extra (the residual of the iterate just evaluated, before negation) and the row scale
// s_k = max(assembled scale of kind k, host scale of kind k, 1e-300) (kinds u, θ, g: rows
// 0–2, 3–5, 6–8 of a node):
//   report[2m]     = max |r| / s_k        (the host's relative residual; −1 if not finite)
//   report[2m + 1] = backward error of the solve when it succeeded, −status otherwise
//   rwork[m]       = Σ |r · q|             (the residual work of the energy check)
// then q_prev2 ← q_prev, q_prev ← q (the evaluated iterate, which a fetch reads) and, if a
// solve ran and succeeded, q ← q + x (without a solve in the operation word — an iterate
// the host expects to accept — the iterate stays). RESTORE (bit 3),
// before the gather pass: q ← q_prev2 (modified Newton's undo of the correction made with
// a kept tangent that led to the iterate evaluated last, whose own correction the device
// already applied).

// Per node slot, field-major (as the gather pass reads them): the Newton increments.
@group(0) @binding(12) var<storage, read_write> node_x: array<Real>;
// Per member 9·NPN (node-local order): the iterate before the last update.
@group(0) @binding(13) var<storage, read_write> q_prev: array<Real>;
// Per member 3: the host's row scales (u, θ, g) of its nodal terms.
@group(0) @binding(14) var<storage, read> host_scale: array<Real>;
// Per member 2: relative residual and solve outcome (see above).
@group(0) @binding(15) var<storage, read_write> report: array<Real>;
// Per member: Σ |r · q| of the iterate evaluated last.
@group(0) @binding(16) var<storage, read_write> rwork: array<Real>;
// Per member 9·NPN: the iterate before `q_prev`.
@group(0) @binding(17) var<storage, read_write> q_prev2: array<Real>;

// Index of node-local unknown r of node i of member m in `node_x`.
fn qidx(m: u32, i: u32, r: u32) -> u32 {
    return r * (prm.n_member * prm.npn) + m * prm.npn + i;
}

@compute @workgroup_size(64)
fn restore_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let m = gid.x;
    if m >= prm.n_member { return; }
    let n = member_n[m];
    if n == 0u || (ops[m] & 8u) == 0u { return; }
    for (var i = 0u; i < n; i++) {
        let mi = mask[m * prm.npn + i];
        for (var r = 0u; r < 9u; r++) {
            if ((mi >> r) & 1u) != 0u {
                node_x[qidx(m, i, r)] = q_prev2[9u * (m * prm.npn + i) + r];
            }
        }
    }
}

// The row scales of member m's relative residual (per unknown kind: u, θ, g), the
// device's assembled maxima against the host's, floored.
fn member_scales(m: u32) -> array<Real, 3> {
    let sc = m * prm.rpm + 9u * prm.npn;
    var s: array<Real, 3>;
    for (var k = 0u; k < 3u; k++) {
        s[k] = max(max(sys[sc + k], host_scale[3u * m + k]), 1e-300);
    }
    return s;
}

// Row r of node i of member m's residual: the assembled row plus the host's nodal terms.
fn row_residual(m: u32, i: u32, r: u32) -> Real {
    return sys[m * prm.rpm + 9u * i + r] + extra[9u * (m * prm.npn + i) + r];
}

@compute @workgroup_size(64)
fn update_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_member { return; }
    update(gid.x);
}

// An iteration of a multi-iteration submission: the update, then `spec_gate_main`'s gate,
// in one pass (per member).
@compute @workgroup_size(64)
fn update_gate_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_member { return; }
    update(gid.x);
    gate(gid.x);
}

fn update(m: u32) {
    let n = member_n[m];
    if n == 0u || (ops[m] & 4u) == 0u { return; }
    let s = member_scales(m);
    var worst: Real = 0.0;
    var finite = true;
    var work: Real = 0.0;
    // Σ extra · q over the u and θ rows: minus the work of the host's dead loads (their
    // nodal terms are −F and −M where no point mass sits: `nodal_terms`).
    var lwork: Real = 0.0;
    // Σ r · q over the removed u and θ rows (the assembled rows alone): the work of the
    // driven supports' reactions from the element passes (zero where the removed unknowns
    // hold no prescribed increment; the host adds its loads at those nodes).
    var swork: Real = 0.0;
    for (var i = 0u; i < n; i++) {
        let mi = mask[m * prm.npn + i];
        for (var r = 0u; r < 9u; r++) {
            if ((mi >> r) & 1u) == 0u {
                if r < 6u { swork += sys[m * prm.rpm + 9u * i + r] * node_x[qidx(m, i, r)]; }
                continue;
            }
            let v = row_residual(m, i, r);
            let rel = abs(v) / s[r / 3u];
            finite = finite && is_finite(rel);
            worst = max(worst, rel);
            let q = node_x[qidx(m, i, r)];
            work += abs(v * q);
            if r < 6u { lwork += extra[9u * (m * prm.npn + i) + r] * q; }
        }
    }
    if !finite { worst = -1.0; }
    report[2u * m] = worst;
    rwork[m] = work;
    if (ops[m] & 16u) != 0u {
        hist[m * HSTRIDE + HSTRIDE - 1u] = -lwork;
        hist[m * HSTRIDE + HSTRIDE - 3u] = swork;
    }
    // Without a solve in the operation word (an iterate the host expects to accept) the
    // iterate stays; a failed solve leaves it too.
    let solved = (ops[m] & 2u) != 0u;
    let st = status[m];
    var apply = false;
    if !solved {
        report[2u * m + 1u] = 0.0;
    } else if st != OK {
        report[2u * m + 1u] = -Real(st);
    } else {
        report[2u * m + 1u] = berr[m];
        apply = true;
    }
    let x = m * 9u * prm.npn;
    for (var i = 0u; i < n; i++) {
        let mi = mask[m * prm.npn + i];
        for (var r = 0u; r < 9u; r++) {
            if ((mi >> r) & 1u) == 0u { continue; }
            let at = qidx(m, i, r);
            let q = node_x[at];
            let p = 9u * (m * prm.npn + i) + r;
            q_prev2[p] = q_prev[p];
            q_prev[p] = q;
            if apply { node_x[at] = q + xs[x + 9u * i + r]; }
        }
    }
    if (ops[m] & 16u) != 0u {
        // (Without a solve: `spec_check_main` found the iterate accepted.)
        spec_record(m, worst, report[2u * m + 1u], finite && (apply || !solved));
    }
}

// ---------------------------------------------------------------------------------------
// SEVERAL NEWTON ITERATIONS PER SUBMISSION (ops bit 4, SPEC; `--solve resident`,
// `src/batch/gpu.rs`). The host records K iterations (gather → element passes → assembly
// → factor → solve → update) into one command buffer. Per member, `hist` holds the count c
// of iterations done and, per iteration, the report pair (relative residual, solve
// outcome) of the update pass. After recording iteration c the update pass stops the
// member — clears its operation word, so that every later solver pass skips it — when the
// residual is not finite, the solve failed, c reached the member's K, or the host's Newton
// loop would accept the iterate just evaluated (`newton.rs`, `accepted`: the same test on
// the same f64 values):
//   res ≤ tol and c ≥ min corrections, or (c ≥ 2, r2 = hist[c−2], r1 = hist[c−1])
//   res ≤ 1e5·tol and res ≥ ½ r1 (the round-off floor), or (quadratic convergence only)
//   res ≤ 10·tol, r1 < r2 and res ≥ 1e3 · r1 (r1/r2)².
// The stopping iteration still applies its correction (as every resident iteration does),
// so `q_prev` holds the iterate the host accepts, and a host that goes on finds the next
// iterate in `node_x`.
// A POLISH member (ops bit 128: a step on the device of the inexact strategy) whose
// consistent-scalar iterations accept an iterate with res ≤ tol goes on instead, as the
// host's step does, with a polish round: its element slots get I_ACTIVE = 3 (the next
// residual pass freezes the scalars consistent with this iterate), its count so far is
// kept as the round's start (the tests above then read the round's own iterations, with
// quadratic convergence), and its factorization and solve are on again. One that accepts
// an iterate on its round-off floor above the tolerance stops there as the host's step
// does (checked with the consistent scalars): its element slots get I_ACTIVE = −2, which
// the records and the next step's advance read as "consistent kinematics".

// Iterations a submission holds at most (`RESIDENT_MAX_K` in `src/gpu/blocktri.rs`).
const KMAX: u32 = 16u;
const HSTRIDE: u32 = 36u; // 1 + 2 KMAX + 3

// Per member HSTRIDE: the count c, then (residual, outcome) per iteration, then the
// driven supports' reaction work (removed rows) at the iterate evaluated last, the
// polish round's first iteration (0: none), then (last) the work of the dead loads over
// the step at the iterate evaluated last.
@group(0) @binding(18) var<storage, read_write> hist: array<Real>;
// Per member 4: Newton tolerance, 1 for quadratic convergence (full Newton), the
// corrections before a residual may be accepted, this submission's K; then the element
// kernel's slot count and element slots per member (0, 0 without a kernel).
@group(0) @binding(19) var<storage, read> spec: array<Real>;
// The element kernel's iteration buffer (field-major, `src/gpu/layout.rs`): a stopped
// member's element slots get I_ACTIVE = 0, so that the element passes of the later
// iterations skip them (the host re-uploads the field after the submission, or, for a
// step on the device, REACTIVATE sets it again in the next one).
@group(0) @binding(20) var<storage, read_write> kiter: array<Real>;
const I_ACTIVE: u32 = 22u;

fn deactivate(m: u32) {
    let cap = u32(spec[4u * prm.n_member]);
    let per = u32(spec[4u * prm.n_member + 1u]);
    for (var e = 0u; e < per; e++) {
        kiter[I_ACTIVE * cap + m * per + e] = 0.0;
    }
}

// The element slots of member m's elements (one per node after the first) get flag v.
fn set_active(m: u32, v: Real) {
    let n = member_n[m];
    if n < 2u { return; }
    let cap = u32(spec[4u * prm.n_member]);
    let per = u32(spec[4u * prm.n_member + 1u]);
    for (var e = 0u; e < min(n - 1u, per); e++) {
        kiter[I_ACTIVE * cap + m * per + e] = v;
    }
}

fn spec_accepts(m: u32, hb: u32, c_all: u32, res: Real) -> bool {
    let tol = spec[4u * m];
    // Within the polish round: its own iterations, frozen scalars (quadratic).
    let p = u32(hist[hb + HSTRIDE - 2u]);
    let c = c_all - p;
    if res <= tol && Real(c) >= spec[4u * m + 2u] { return true; }
    if c < 2u { return false; }
    let r2 = hist[hb + 1u + 2u * (c_all - 2u)];
    let r1 = hist[hb + 1u + 2u * (c_all - 1u)];
    if res <= 1e5 * tol && res >= 0.5 * r1 { return true; }
    if (spec[4u * m + 1u] != 0.0 || p != 0u) && res <= 10.0 * tol && r1 < r2 {
        let q = r1 * (r1 / r2) * (r1 / r2);
        if res >= 1e3 * q { return true; }
    }
    return false;
}

fn spec_record(m: u32, res: Real, code: Real, ok: bool) {
    let hb = m * HSTRIDE;
    let c = u32(hist[hb]);
    hist[hb + 1u + 2u * c] = res;
    hist[hb + 2u + 2u * c] = code;
    hist[hb] = Real(c + 1u);
    let last = Real(c + 1u) >= spec[4u * m + 3u] || c + 1u >= KMAX;
    let accept = ok && spec_accepts(m, hb, c, res);
    if accept && (ops[m] & 128u) != 0u && hist[hb + HSTRIDE - 2u] == 0.0 {
        if res > spec[4u * m] {
            // Accepted on the floor above the tolerance (on the last recorded iteration
            // too): stopped with consistent kinematics.
            ops[m] = 0u;
            set_active(m, -2.0);
            return;
        }
        if !last {
            hist[hb + HSTRIDE - 2u] = Real(c + 1u);
            ops[m] = ops[m] | 3u;
            set_active(m, 3.0);
            return;
        }
    }
    if !ok || last || accept {
        ops[m] = 0u;
        deactivate(m);
    }
}

// After the assembly, before the factorization: a SPEC member whose iterate the host's
// Newton loop will accept skips the factorization and the solve (the update pass then
// records the iteration with outcome 0 and stops it), as `--solve device` does for an
// iterate the host predicts to accept.
@compute @workgroup_size(64)
fn spec_check_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_member { return; }
    spec_check(gid.x);
}

fn spec_check(m: u32) {
    let n = member_n[m];
    if n == 0u || (ops[m] & 16u) == 0u { return; }
    let s = member_scales(m);
    var worst: Real = 0.0;
    for (var i = 0u; i < n; i++) {
        let mi = mask[m * prm.npn + i];
        for (var r = 0u; r < 9u; r++) {
            if ((mi >> r) & 1u) == 0u { continue; }
            let v = row_residual(m, i, r);
            let rel = abs(v) / s[r / 3u];
            if !is_finite(rel) { return; }
            worst = max(worst, rel);
        }
    }
    let hb = m * HSTRIDE;
    if spec_accepts(m, hb, u32(hist[hb]), worst) { ops[m] = ops[m] & ~3u; }
}

// Before the first iteration: the count of every SPEC member goes to 0; a REACTIVATE
// member's element slots (one per node after the first) evaluate again (frozen scalars,
// or with ops bit 64 the consistent ones).
@compute @workgroup_size(64)
fn spec_reset_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let m = gid.x;
    if m >= prm.n_member { return; }
    if (ops[m] & 16u) != 0u {
        hist[m * HSTRIDE] = 0.0;
        hist[m * HSTRIDE + HSTRIDE - 2u] = 0.0;
    }
    if (ops[m] & 32u) != 0u {
        // (ops bit 64: the inexact strategy's consistent scalars.)
        var v: Real = 1.0;
        if (ops[m] & 64u) != 0u { v = 2.0; }
        set_active(m, v);
    }
}

// After each iteration: device-solved members without SPEC (one iteration asked) stop.
@compute @workgroup_size(64)
fn spec_gate_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= prm.n_member { return; }
    gate(gid.x);
}

fn gate(m: u32) {
    if ops[m] != 0u && (ops[m] & 16u) == 0u {
        ops[m] = 0u;
        deactivate(m);
    }
}

