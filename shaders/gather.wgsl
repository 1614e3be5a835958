// INCREMENT GATHER PASS, run before the element pass: the host uploads the Newton
// increment once per node (9 values, node-local order u0..2 θ0..2 g0..2; removed unknowns
// are zero), and each element slot gathers its two nodes' increments into the
// element-local increment fields (I_X, order u0 θ0 u1 θ1 g0 g1) of the iteration buffer
// that `element.wgsl` reads. Bookkeeping only, no physics.

alias Real = f64;

// Iteration fields (twin of I_X in element.wgsl).
const I_X: u32 = 0u;

struct Params {
    // Element slots (stride of the iteration buffer).
    n_elem: u32,
    // Node slots (stride of the node increments).
    n_node: u32,
    pad0: u32,
    pad1: u32,
}

// Node increments, field-major: component k of node slot j at k·n_node + j.
@group(0) @binding(0) var<storage, read> node_x: array<Real>;
// Per element slot: the node slots of its ends 0 and 1.
@group(0) @binding(1) var<storage, read> elem_nodes: array<u32>;
@group(0) @binding(2) var<storage, read_write> iter: array<Real>;
@group(0) @binding(3) var<uniform> prm: Params;

// Element-local index of node-local unknown k at element end l (as in assemble.wgsl).
fn loc_idx(l: u32, k: u32) -> u32 {
    if k < 6u { return 6u * l + k; }
    return 6u + 3u * l + k;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    if e >= prm.n_elem { return; }
    for (var l = 0u; l < 2u; l++) {
        let j = elem_nodes[2u * e + l];
        for (var k = 0u; k < 9u; k++) {
            iter[(I_X + loc_idx(l, k)) * prm.n_elem + e] = node_x[k * prm.n_node + j];
        }
    }
}
