// UPLOAD SCATTER PASS, run first in a dispatch: the host packs every changed run of the
// element kernel's input buffers and of the node increments into one array (`vals`) and
// one run list, uploaded in two copies; each workgroup copies one run into its target
// buffer. Bookkeeping only, no physics.

alias Real = f64;

struct Run {
    // Target buffer (0..3: bindings 2..5).
    dst: u32,
    // First scalar written in the target.
    at: u32,
    // Scalars in the run.
    len: u32,
    // First scalar read from `vals`.
    src: u32,
}

// runs[0].dst is the number of runs that follow; runs[1..] the runs.
@group(0) @binding(0) var<storage, read> runs: array<Run>;
@group(0) @binding(1) var<storage, read> vals: array<Real>;
@group(0) @binding(2) var<storage, read_write> t0: array<Real>;
@group(0) @binding(3) var<storage, read_write> t1: array<Real>;
@group(0) @binding(4) var<storage, read_write> t2: array<Real>;
@group(0) @binding(5) var<storage, read_write> t3: array<Real>;

@compute @workgroup_size(64)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = wg.x + wg.y * nwg.x;
    if k >= runs[0].dst {
        return;
    }
    let r = runs[k + 1u];
    for (var i = li; i < r.len; i += 64u) {
        let v = vals[r.src + i];
        switch r.dst {
            case 0u: { t0[r.at + i] = v; }
            case 1u: { t1[r.at + i] = v; }
            case 2u: { t2[r.at + i] = v; }
            default: { t3[r.at + i] = v; }
        }
    }
}
