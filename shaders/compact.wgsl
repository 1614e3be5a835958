// READ-BACK COMPACTION PASS, run last before the block solver's read-back copy: the
// device-resident reports (2 scalars per member) and accepted iterates (W scalars and the
// residual work per member) of the listed member slots, spread over the solver's
// member-major buffers, are written one after another into `out`, so that one copy brings
// back exactly what was asked for, in one command whatever the number of members.
// Bookkeeping only, no physics.

alias Real = f64;

// list[0]: reports listed, list[1]: iterates listed, list[2]: W (scalars per member of an
// iterate), list[3]: unused; then the member slots of the reports, then those of the
// iterates. Output: report r at 2 r; iterate j at 2 R + j (W + 1), its residual work last.
@group(0) @binding(0) var<storage, read> list: array<u32>;
@group(0) @binding(1) var<storage, read> report: array<Real>;
@group(0) @binding(2) var<storage, read> q_prev: array<Real>;
@group(0) @binding(3) var<storage, read> rwork: array<Real>;
@group(0) @binding(4) var<storage, read_write> out: array<Real>;

// The first ⌈R / 32⌉ workgroups copy 32 reports each (one scalar per invocation), each
// further workgroup one iterate.
@compute @workgroup_size(64)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = wg.x + wg.y * nwg.x;
    let n_report = list[0];
    let n_fetch = list[1];
    let w = list[2];
    let report_groups = (n_report + 31u) / 32u;
    if k < report_groups {
        let i = 64u * k + li;
        if i < 2u * n_report {
            out[i] = report[2u * list[4u + i / 2u] + i % 2u];
        }
        return;
    }
    let j = k - report_groups;
    if j >= n_fetch {
        return;
    }
    let m = list[4u + n_report + j];
    let base = 2u * n_report + j * (w + 1u);
    for (var i = li; i < w; i += 64u) {
        out[base + i] = q_prev[m * w + i];
    }
    if li == 0u {
        out[base + w] = rwork[m];
    }
}
