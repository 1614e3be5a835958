// ASSEMBLY PASS: sums the element blocks written by `element.wgsl` into each member's
// block system, so that only the assembled system (or, without the tangent, only the nodal
// residuals and the per-member row-scale maxima) crosses the bus. Bookkeeping only, no
// physics: the element math stays in `element.wgsl`.
//
// The assembled buffer (binding 5) is member-major, so that the waiting members of a
// dispatch come back as a few contiguous ranges (Rust twin: `AsmLayout` in
// `src/gpu/layout.rs`). With NPN node slots and PS element slots per member:
//   residual region, member m at m·RPM, RPM = 9 NPN + 3:
//     node j's residual (node-local u0..2 θ0..2 g0..2) at 9 j, then the max row scale of
//     kind u, θ, g at 9 NPN + kind;
//   tangent region from k_start, member m at k_start + m·KPM, KPM = 81 (NPN + 2 PS):
//     node j's diagonal block (row-major 9×9) at 81 j, then element e's off-diagonal
//     blocks (0,1) and (1,0) at 81 NPN + 81 (2 e + h).
// Node slot i is node i % NPN of member i / NPN; element slot i is element i % PS of
// member i / PS (the element kernel's slots).
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
    // Node slots per member.
    nodes_per_slot: u32,
    want_tangent: u32,
    // Start of the tangent region.
    k_start: u32,
    pad: u32,
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
// Per member slot: 1 when this dispatch computed (and assembles) its tangent.
@group(0) @binding(7) var<storage, read> member_tan: array<u32>;

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
fn rpm() -> u32 { return 9u * prm.nodes_per_slot + 3u; }
fn kpm() -> u32 { return 81u * (prm.nodes_per_slot + 2u * prm.per_slot); }

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i < prm.n_node {
        let m = i / prm.nodes_per_slot;
        let j = i % prm.nodes_per_slot;
        let r0 = m * rpm() + 9u * j;
        let k0 = prm.k_start + m * kpm() + 81u * j;
        let start = node_inc[2u * i];
        let count = node_inc[2u * i + 1u];
        for (var k = 0u; k < 9u; k++) {
            var acc: Real = 0.0;
            for (var c = 0u; c < count; c++) {
                let p = inc[start + c];
                acc += ld(O_R + loc_idx(p & 1u, k), p >> 1u);
            }
            asm_out[r0 + k] = acc;
        }
        if prm.want_tangent != 0u && member_tan[m] != 0u {
            for (var a = 0u; a < 9u; a++) {
                for (var b = 0u; b < 9u; b++) {
                    var acc: Real = 0.0;
                    for (var c = 0u; c < count; c++) {
                        let p = inc[start + c];
                        let l = p & 1u;
                        acc += ld(O_K + 18u * loc_idx(l, a) + loc_idx(l, b), p >> 1u);
                    }
                    asm_out[k0 + 9u * a + b] = acc;
                }
            }
        }
    }
    if prm.want_tangent != 0u && i < prm.n_elem && member_tan[i / prm.per_slot] != 0u {
        let m = i / prm.per_slot;
        let e = i % prm.per_slot;
        let k0 = prm.k_start + m * kpm() + 81u * (prm.nodes_per_slot + 2u * e);
        for (var a = 0u; a < 9u; a++) {
            for (var b = 0u; b < 9u; b++) {
                let f = 9u * a + b;
                asm_out[k0 + f] = ld(O_K + 18u * loc_idx(0u, a) + loc_idx(1u, b), i);
                asm_out[k0 + 81u + f] = ld(O_K + 18u * loc_idx(1u, a) + loc_idx(0u, b), i);
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
            asm_out[i * rpm() + 9u * prm.nodes_per_slot + k] = sc[k];
        }
    }
}
