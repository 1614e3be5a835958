// UPLOAD SCATTER PASS, run first in a dispatch: the host packs every changed run of the
// element kernel's input buffers and of the node increments into one array (`vals`) and
// one run list, uploaded in two copies; each workgroup copies one run into its target
// buffer, transposing the host's slot-major blocks into the device's field-major layout.
// Bookkeeping only, no physics.

alias Real = f64;

// A block of `slots` slots × `nf` fields: value `s·nf + f` (slot-major, from `src` on)
// goes to field `f0 + f` of slot `slot0 + s` of the target, at `(f0 + f)·cap + slot0 + s`.
struct Run {
    // Target buffer (0..3: bindings 2..5).
    dst: u32,
    slot0: u32,
    slots: u32,
    // First scalar read from `vals`.
    src: u32,
    f0: u32,
    nf: u32,
    // Slots per field of the target.
    cap: u32,
    pad: u32,
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
    let n = r.slots * r.nf;
    for (var i = li; i < n; i += 64u) {
        let v = vals[r.src + i];
        let at = (r.f0 + i % r.nf) * r.cap + r.slot0 + i / r.nf;
        switch r.dst {
            case 0u: { t0[at] = v; }
            case 1u: { t1[at] = v; }
            case 2u: { t2[at] = v; }
            default: { t3[at] = v; }
        }
    }
}
