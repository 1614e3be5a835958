// ASSEMBLY PASS: sums the element blocks written by `element.wgsl` into each member's
// block system, so that only the assembled system (or, without the tangent, only the nodal
// residuals and the per-member row-scale maxima) crosses the bus. Bookkeeping only, no
// physics: the element math stays in `element.wgsl`.
//
// Field-major like the element buffers. The assembled buffer (binding 5) holds, with
// NN = node slots, M = member slots, NE = element slots (offsets in `Params`, Rust twin in
// `src/gpu/layout.rs`, `A_*`):
//   [0, 9 NN)            node residual, node-local row k (u0..2 θ0..2 g0..2) of node j at k·NN + j
//   [a_sc, a_sc + 3 M)   per-member max row scale of kind u, θ, g at kind·M + m
//   [a_k, a_k + 81 NN)   node diagonal block (row-major 9×9), entry f of node j at a_k + f·NN + j
//   [a_off, +162 NE)     element off-diagonal blocks (0,1) then (1,0), entry f at a_off + f·NE + e
// The first two ranges are contiguous: a residual-only iteration reads back one range.
//
// Summation order is the CPU scatter's (incidences in increasing element order, starting
// from zero), so the assembled values equal a CPU scatter of the same element blocks
// bit for bit.

alias Real = f64;

// Element output fields (twin of O_* in element.wgsl).
const O_R: u32 = 0u;
const O_SC: u32 = 18u;
const O_K: u32 = 36u;

struct Params {
    // Element slots (stride of the element output).
    n_elem: u32,
    // Node slots.
    n_node: u32,
    // Member slots.
    n_member: u32,
    // Element slots per member.
    per_slot: u32,
    want_tangent: u32,
    a_sc: u32,
    a_k: u32,
    a_off: u32,
}

@group(0) @binding(0) var<storage, read> outp: array<Real>;
// Per node slot: (first incidence, incidence count).
@group(0) @binding(1) var<storage, read> node_inc: array<u32>;
// Incidences: element slot · 2 + end.
@group(0) @binding(2) var<storage, read> inc: array<u32>;
// Per element slot: bit i set when element-local row i is an unknown (removed rows do not
// count towards the row scales, as in the CPU scatter).
@group(0) @binding(3) var<storage, read> row_mask: array<u32>;
// Per member slot: its number of elements.
@group(0) @binding(4) var<storage, read> member_n: array<u32>;
@group(0) @binding(5) var<storage, read_write> asm_out: array<Real>;
@group(0) @binding(6) var<uniform> prm: Params;

// Element-local index of node-local unknown k at element end l (u0 θ0 u1 θ1 g0 g1).
fn loc_idx(l: u32, k: u32) -> u32 {
    if k < 6u { return 6u * l + k; }
    return 6u + 3u * l + k;
}

// Kind of an element-local row: 0 = u, 1 = θ, 2 = g.
fn kind_of(i: u32) -> u32 {
    if i >= 12u { return 2u; }
    if (i >= 3u && i < 6u) || i >= 9u { return 1u; }
    return 0u;
}

fn ld(f: u32, e: u32) -> Real { return outp[f * prm.n_elem + e]; }

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i < prm.n_node {
        let start = node_inc[2u * i];
        let count = node_inc[2u * i + 1u];
        for (var k = 0u; k < 9u; k++) {
            var acc: Real = 0.0;
            for (var c = 0u; c < count; c++) {
                let p = inc[start + c];
                acc += ld(O_R + loc_idx(p & 1u, k), p >> 1u);
            }
            asm_out[k * prm.n_node + i] = acc;
        }
        if prm.want_tangent != 0u {
            for (var a = 0u; a < 9u; a++) {
                for (var b = 0u; b < 9u; b++) {
                    var acc: Real = 0.0;
                    for (var c = 0u; c < count; c++) {
                        let p = inc[start + c];
                        let l = p & 1u;
                        acc += ld(O_K + 18u * loc_idx(l, a) + loc_idx(l, b), p >> 1u);
                    }
                    asm_out[prm.a_k + (9u * a + b) * prm.n_node + i] = acc;
                }
            }
        }
    }
    if prm.want_tangent != 0u && i < prm.n_elem {
        for (var a = 0u; a < 9u; a++) {
            for (var b = 0u; b < 9u; b++) {
                let f = 9u * a + b;
                asm_out[prm.a_off + f * prm.n_elem + i] = ld(O_K + 18u * loc_idx(0u, a) + loc_idx(1u, b), i);
                asm_out[prm.a_off + (81u + f) * prm.n_elem + i] = ld(O_K + 18u * loc_idx(1u, a) + loc_idx(0u, b), i);
            }
        }
    }
    if i < prm.n_member {
        var sc = array<Real, 3>(0.0, 0.0, 0.0);
        for (var e = 0u; e < member_n[i]; e++) {
            let slot = i * prm.per_slot + e;
            let mask = row_mask[slot];
            for (var r = 0u; r < 18u; r++) {
                if (mask & (1u << r)) != 0u {
                    let k = kind_of(r);
                    sc[k] = max(sc[k], ld(O_SC + r, slot));
                }
            }
        }
        for (var k = 0u; k < 3u; k++) {
            asm_out[prm.a_sc + k * prm.n_member + i] = sc[k];
        }
    }
}
