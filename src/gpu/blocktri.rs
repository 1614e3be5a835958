//! Batched block-tridiagonal LU and solve on the device (`shaders/blocktri.wgsl`; CPU twin
//! [`crate::linsolve::batched`]): one invocation per member, block Thomas with partial
//! pivoting inside the 9×9 node blocks. The system is read from a buffer laid out as the
//! assembly pass's output ([`crate::gpu::layout::AsmLayout`], or any
//! [`BatchLayout`]); the factors stay on the device between solves (modified Newton), and
//! only what the caller asks for comes back: per member a status and a backward error
//! (12 bytes), the solution when wanted.

use super::compact::Compact;
use super::context::{GpuContext, Precision};
use super::kernel::index_runs;
use super::GpuError;
use crate::linsolve::batched::BatchLayout;

pub use super::shaders::BLOCKTRI_WGSL;

/// Nodes per factorization dispatch: lavapipe ends an invocation after 65 535 loop
/// iterations (shaders/blocktri.wgsl, "Chunks"); measured with ill-conditioned members
/// (row interchanges everywhere, `tests/gpu_blocktri.rs`), 32-node chunks factorize
/// exactly as the CPU twin and 64-node chunks are cut short (one invocation per member
/// failed from ≈ 44 nodes).
pub const CHUNK_NODES: usize = 32;

/// Nodes per dispatch of the sweeps and the backward error (≤ 300 loop iterations per
/// node): one dispatch each for members of up to this many nodes.
pub const SWEEP_CHUNK_NODES: usize = 128;

/// Per-member operation bit: factorize.
pub const OP_FACTOR: u32 = 1;
/// Per-member operation bit: solve with the factors.
pub const OP_SOLVE: u32 = 2;
/// Per-member operation bit (device-resident Newton): after the solve, report the
/// relative residual and the solve's outcome and add the correction to the increments
/// the gather pass reads (`update_main` in `shaders/blocktri.wgsl`).
pub const OP_UPDATE: u32 = 4;
/// Per-member operation bit (device-resident Newton): before the gather pass, restore the
/// increments from before the correction that led to the iterate evaluated last
/// (`restore_main`: the device already applied that iterate's own correction).
pub const OP_RESTORE: u32 = 8;
/// Per-member operation bit (`--solve resident`): this member iterates in every Newton
/// iteration of a multi-iteration submission ([`BlockTriSolver::encode_spec_reset`],
/// [`BlockTriSolver::encode_iteration`]), records each iteration's [`Report`] in its history
/// and stops where the host's Newton loop would stop (`spec_record` in
/// `shaders/blocktri.wgsl`).
pub const OP_SPEC: u32 = 16;
/// Per-member operation bit (`--solve whole`, a step on the device): before the first
/// iteration, the member's element slots (one per node after the first) evaluate again
/// (`spec_reset_main` sets their `I_ACTIVE` to 1: frozen scalars), where the last
/// multi-iteration submission stopped them; the host then sends no iteration rows.
pub const OP_REACTIVATE: u32 = 32;
/// Per-member operation bit (with [`OP_REACTIVATE`]): the element slots evaluate with the
/// consistent scalars (`I_ACTIVE` 2: the inexact strategy's iterations).
pub const OP_CONSISTENT: u32 = 64;
/// Per-member operation bit (with [`OP_SPEC`], a step on the device of the inexact
/// strategy): where the consistent-scalar iterations accept an iterate within the
/// tolerance, the member goes on with the polish round, as the host's step does: the
/// element slots freeze the scalars consistent with that iterate (`I_ACTIVE` 3) and the
/// Newton test restarts there with quadratic convergence (`spec_record` in
/// `shaders/blocktri.wgsl`).
pub const OP_POLISH: u32 = 128;

/// Newton iterations one submission holds at most (`KMAX` in `shaders/blocktri.wgsl`).
pub const RESIDENT_MAX_K: usize = 16;
/// Scalars per member of the iteration history: the count, two per iteration, the driven
/// supports' reaction work at the iterate evaluated last (`Σ r · q` over the removed u and
/// θ rows, assembled rows alone), the polish round's first iteration ([`OP_POLISH`]; 0:
/// none) and the work of the dead loads at the iterate evaluated last (`HSTRIDE` in
/// `shaders/blocktri.wgsl`).
pub const HSTRIDE: usize = 4 + 2 * RESIDENT_MAX_K;

/// What the host's Newton loop accepts, per member, for [`OP_SPEC`]'s stopping test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpecParams {
    /// Newton tolerance on the relative residual.
    pub tol: f64,
    /// Quadratic convergence (full or fresh Newton on the frozen-scalar tangent): the
    /// floor test's quadratic sign applies.
    pub quadratic: bool,
    /// Corrections before a residual may be accepted.
    pub min_corrections: usize,
    /// Iterations of this submission.
    pub k: usize,
}

/// What an [`OP_UPDATE`] member reports (16 bytes per member and iteration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report {
    /// `max |R_i| / scale(kind of i)` of the iterate evaluated (`+∞` if not finite).
    pub residual: f64,
    /// [`crate::linsolve::batched::OK`] or the failure status of the solve.
    pub status: u32,
    /// Backward error of the solve (when it succeeded).
    pub berr: f64,
}

impl Report {
    /// A report from its two stored scalars (relative residual, solve outcome).
    pub fn decode(res: f64, code: f64) -> Self {
        let (status, berr) = if code >= 0.0 {
            (crate::linsolve::batched::OK, code)
        } else {
            (-code as u32, f64::NAN)
        };
        Self {
            residual: if res < 0.0 { f64::INFINITY } else { res },
            status,
            berr,
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n_member: u32,
    npn: u32,
    k_start: u32,
    kpm: u32,
    rpm: u32,
    negate: u32,
    lo: u32,
    hi: u32,
}

/// What one [`BlockTriSolver::run`] read back.
#[derive(Clone, Debug, Default)]
pub struct Solved {
    /// Per member slot: [`crate::linsolve::batched::OK`], `1 + i` (singular Schur
    /// complement of node block `i`) or [`crate::linsolve::batched::NONFINITE`].
    pub status: Vec<u32>,
    /// Per member slot: backward error of its last solve.
    pub berr: Vec<f64>,
    /// The solutions (`9 · NPN` per member slot), when asked for.
    pub x: Option<Vec<f64>>,
    /// Per member slot asked for ([`Readback::report`]): its [`Report`].
    pub reports: Vec<(usize, Report)>,
    /// The member slots asked for ([`Readback::fetch`]), in that order.
    pub fetched: Vec<usize>,
    /// Their accepted iterates, packed in the same order: per member `9 · NPN` scalars
    /// (node slots in node-local order, 9 each: the iterate before the last update), then
    /// `Σ |R_i q_i|` of that iterate. See [`Self::iterates`].
    pub iterates: Vec<f64>,
    /// Per member slot asked for ([`Readback::hist`]): the [`Report`]s of the iterations
    /// of its multi-iteration submission, in order, and the work of the dead loads over
    /// the step at the iterate evaluated last (`−Σ extra · q` over the u and θ rows), and
    /// the driven supports' reaction work there (`Σ r · q` over the removed u and θ rows,
    /// the assembled rows without the host's nodal terms).
    pub hist: Vec<(usize, Vec<Report>, f64, f64)>,
    /// Per member slot asked for ([`Readback::rwork`]): `Σ |R_i q_i|` of its last
    /// evaluated iterate.
    pub rwork: Vec<(usize, f64)>,
    /// The scalars of [`Readback::extra`], in order.
    pub extra: Vec<f64>,
}

impl Solved {
    /// The fetched members' accepted iterates: (member slot, `9 · NPN` scalars of the
    /// iterate, its residual work).
    pub fn iterates(&self) -> impl Iterator<Item = (usize, &[f64], f64)> + '_ {
        let w = self
            .iterates
            .len()
            .checked_div(self.fetched.len())
            .unwrap_or(1);
        self.fetched
            .iter()
            .zip(self.iterates.chunks_exact(w))
            .map(move |(&m, f)| (m, &f[..w - 1], f[w - 1]))
    }
}

/// What [`BlockTriSolver::read`] copies back, by member slot.
#[derive(Clone, Debug, Default)]
pub struct Readback {
    /// Status and backward error of every member slot (12 bytes per slot).
    pub status: bool,
    /// Solutions of these slots.
    pub x: Vec<usize>,
    /// [`Report`]s of these slots (16 bytes each).
    pub report: Vec<usize>,
    /// Accepted iterates of these slots ([`Solved::iterates`]).
    pub fetch: Vec<usize>,
    /// Iteration histories of these slots ([`Solved::hist`]; 8 [`HSTRIDE`] bytes each).
    pub hist: Vec<usize>,
    /// Residual work of the last evaluated iterate of these slots ([`Solved::rwork`]; 8
    /// bytes each).
    pub rwork: Vec<usize>,
    /// Further ranges (buffer, byte offset, byte length) of other f64 buffers read in the
    /// same copy and map ([`Solved::extra`]).
    pub extra: Vec<(wgpu::Buffer, u64, u64)>,
}

/// A batch of `members` block-tridiagonal systems on the device.
pub struct BlockTriSolver {
    layout: BatchLayout,
    members: usize,
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// `factor_main`, `forward_main`, `backward_main`, `berr_main`, `restore_main`,
    /// `update_main`, `spec_reset_main`, `spec_gate_main`, `spec_check_main`,
    /// `check_factor_main`, `update_gate_main`.
    pipelines: [wgpu::ComputePipeline; 11],
    /// One bind group per node chunk of the factorization ([`CHUNK_NODES`], each with its
    /// own `lo`, `hi`), then one per chunk of the sweeps ([`SWEEP_CHUNK_NODES`]).
    bind_groups: Vec<wgpu::BindGroup>,
    /// How many of [`Self::bind_groups`] are the factorization's.
    factor_chunks: usize,
    /// `[xs, mask, member_n, ops, status, berr]` (factors and pivots are never read back).
    xs: wgpu::Buffer,
    mask: wgpu::Buffer,
    member_n: wgpu::Buffer,
    ops: wgpu::Buffer,
    status: wgpu::Buffer,
    berr: wgpu::Buffer,
    staging: wgpu::Buffer,
    extra: wgpu::Buffer,
    extra_host: Vec<f64>,
    extra_dirty: Vec<bool>,
    /// Device-resident Newton: `[q_prev, host_scale, report, rwork, q_prev2]`.
    resident: [wgpu::Buffer; 5],
    /// Packs the reports and iterates asked for into one buffer for the read-back.
    compact: Compact,
    /// [`OP_SPEC`]: `[hist, spec]`.
    spec: [wgpu::Buffer; 2],
    spec_host: Vec<f64>,
    spec_dirty: Vec<bool>,
    scale_host: Vec<f64>,
    scale_dirty: Vec<bool>,
    /// Factors, pivots and backward-error terms: only ever touched by the shader (kept
    /// alive with the solver).
    _fac_piv: [wgpu::Buffer; 5],
    mask_host: Vec<u32>,
    n_host: Vec<u32>,
    topo_dirty: bool,
    ops_host: Vec<u32>,
    /// The multi-iteration submission encoded last zeroes every operation word on the
    /// device ([`Self::encode_iteration`]; the next submission's [`Self::begin`] clears the
    /// host's copy: within a submission the words go up once).
    ops_zeroed: bool,
    /// Bytes read back by the last [`Self::run`].
    pub last_bytes_down: u64,
    /// Bytes uploaded since this was last reset (topology, extras, host scales,
    /// operation words).
    pub bytes_up: u64,
    /// Host → device copies (`write_buffer` calls) since this was last reset.
    pub copies_up: u64,
    /// Device → host copy commands recorded by the last [`Self::read_back`].
    pub last_copies_down: u64,
}

/// Writes one member's extra right-hand-side rows (node-major, 9 per node slot); whether
/// anything changed.
fn extra_rows(dst: &mut [f64], rows: &[[f64; 9]]) -> bool {
    let mut changed = false;
    for (d, row) in dst.chunks_mut(9).zip(rows) {
        changed |= *d != row[..];
        d.copy_from_slice(row);
    }
    changed
}

fn storage(
    device: &wgpu::Device,
    label: &str,
    bytes: u64,
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(4),
        usage: wgpu::BufferUsages::STORAGE | extra,
        mapped_at_creation: false,
    })
}

impl BlockTriSolver {
    /// A storage buffer holding `data` (f64), usable as the system of [`Self::new`].
    pub fn system_buffer(ctx: &GpuContext, data: &[f64]) -> wgpu::Buffer {
        let b = storage(
            &ctx.device,
            "block system",
            8 * data.len() as u64,
            wgpu::BufferUsages::COPY_DST,
        );
        ctx.queue.write_buffer(&b, 0, bytemuck::cast_slice(data));
        b
    }

    /// Builds the passes over `members` member slots of the system in `sys`, laid out by
    /// `layout`. Needs `SHADER_F64`. Every member slot starts inactive (no nodes).
    ///
    /// `node_x` holds the Newton increments the device-resident operations ([`OP_UPDATE`],
    /// [`OP_RESTORE`]) update (9 per node slot, field-major over `members · NPN` slots, as
    /// the assembly's gather pass reads them; `None`: a buffer of its own), and the
    /// residual region of each member must then end in its three row scales
    /// (`rpm ≥ 9 NPN + 3`, as [`crate::gpu::layout::AsmLayout`]).
    ///
    /// `kernel`: the element kernel's iteration buffer, its slot count and the element
    /// slots per member; a member that stops in a multi-iteration submission ([`OP_SPEC`])
    /// deactivates its element slots there (`None`: no kernel to skip).
    pub fn new(
        ctx: &GpuContext,
        members: usize,
        layout: BatchLayout,
        sys: &wgpu::Buffer,
        node_x: Option<&wgpu::Buffer>,
        kernel: Option<(&wgpu::Buffer, usize, usize)>,
    ) -> Result<Self, GpuError> {
        if ctx.precision != Precision::F64 {
            return Err(GpuError::Kernel(
                "the device block solver needs an adapter with SHADER_F64".into(),
            ));
        }
        let members = members.max(1);
        let fac_bytes = 8 * (layout.fac_per_member() * members) as u64;
        let lim = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        if fac_bytes > lim {
            return Err(GpuError::TooLarge {
                elements: members * layout.npn,
                max: (lim / (8 * layout.fac_per_member() as u64)) as usize * layout.npn,
            });
        }
        let device = ctx.device.clone();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("blocktri.wgsl"),
            source: wgpu::ShaderSource::Wgsl(BLOCKTRI_WGSL.into()),
        });
        let entry = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let ro = wgpu::BufferBindingType::Storage { read_only: true };
        let rw = wgpu::BufferBindingType::Storage { read_only: false };
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("blocktri"),
            entries: &[
                entry(0, ro),
                entry(1, rw),
                entry(2, rw),
                entry(3, rw),
                entry(4, ro),
                entry(5, ro),
                entry(6, rw),
                entry(7, rw),
                entry(8, rw),
                entry(9, wgpu::BufferBindingType::Uniform),
                entry(10, ro),
                entry(11, rw),
                entry(12, rw),
                entry(13, rw),
                entry(14, ro),
                entry(15, rw),
                entry(16, rw),
                entry(17, rw),
                entry(18, rw),
                entry(19, ro),
                entry(20, rw),
            ],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("blocktri"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let pipe = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pl),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: ctx.pipeline_cache(),
            })
        };
        let pipelines = [
            pipe("factor_main"),
            pipe("forward_main"),
            pipe("backward_main"),
            pipe("berr_main"),
            pipe("restore_main"),
            pipe("update_main"),
            pipe("spec_reset_main"),
            pipe("spec_gate_main"),
            pipe("spec_check_main"),
            pipe("check_factor_main"),
            pipe("update_gate_main"),
        ];
        ctx.save_pipeline_cache();
        let none = wgpu::BufferUsages::empty();
        let dst = wgpu::BufferUsages::COPY_DST;
        let src = wgpu::BufferUsages::COPY_SRC;
        let xn = (layout.x_per_member() * members) as u64;
        let fac = storage(&device, "factors", fac_bytes, none);
        let piv = storage(&device, "pivots", 4 * xn, none);
        let xs = storage(&device, "solutions", 8 * xn, src);
        let mask = storage(&device, "masks", 4 * (layout.npn * members) as u64, dst);
        let member_n = storage(&device, "member nodes", 4 * members as u64, dst);
        let ops = storage(&device, "ops", 4 * members as u64, dst);
        let status = storage(&device, "status", 4 * members as u64, src | dst);
        let berr = storage(&device, "backward errors", 8 * members as u64, src);
        let extra = storage(&device, "rhs extras", 8 * xn, dst);
        ctx.queue
            .write_buffer(&extra, 0, bytemuck::cast_slice(&vec![0.0f64; xn as usize]));
        let own_x = storage(&device, "node increments", 8 * xn, dst);
        let node_x = node_x.unwrap_or(&own_x);
        let resident = [
            storage(&device, "previous iterates", 8 * xn, src),
            storage(&device, "host scales", 24 * members as u64, dst),
            storage(&device, "reports", 16 * members as u64, src),
            storage(&device, "residual work", 8 * members as u64, src),
            storage(&device, "iterates before the previous", 8 * xn, none),
        ];
        let compact = Compact::new(
            ctx,
            members,
            layout.x_per_member(),
            &resident[2],
            &resident[0],
            &resident[3],
        );
        let spec = [
            storage(
                &device,
                "iteration histories",
                (8 * HSTRIDE * members) as u64,
                src,
            ),
            storage(&device, "newton tests", 32 * members as u64 + 16, dst),
        ];
        let (cap, per) = kernel.map_or((0, 0), |k| (k.1, k.2));
        ctx.queue.write_buffer(
            &spec[1],
            32 * members as u64,
            bytemuck::cast_slice(&[cap as f64, per as f64]),
        );
        let own_iter = storage(&device, "no element kernel", 8, none);
        let kiter = kernel.map_or(&own_iter, |k| k.0);
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("blocktri staging"),
            // (+ 128 per member: residual works and records of `--solve whole` steps.)
            size: 16 * xn + 164 * members as u64 + (8 * HSTRIDE * members) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let acc = storage(&device, "backward-error terms", 32 * members as u64, none);
        ctx.queue
            .write_buffer(&status, 0, bytemuck::cast_slice(&vec![0u32; members]));
        let factor_chunks = layout.npn.div_ceil(CHUNK_NODES).max(1);
        let chunks = (0..factor_chunks)
            .map(|c| (c * CHUNK_NODES, (c + 1) * CHUNK_NODES))
            .chain(
                (0..layout.npn.div_ceil(SWEEP_CHUNK_NODES).max(1))
                    .map(|c| (c * SWEEP_CHUNK_NODES, (c + 1) * SWEEP_CHUNK_NODES)),
            );
        let bind_groups = chunks
            .map(|(lo, hi)| {
                let params = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("blocktri params"),
                    size: std::mem::size_of::<Params>() as u64,
                    usage: wgpu::BufferUsages::UNIFORM | dst,
                    mapped_at_creation: false,
                });
                let p = Params {
                    n_member: members as u32,
                    npn: layout.npn as u32,
                    k_start: layout.k_start as u32,
                    kpm: layout.kpm as u32,
                    rpm: layout.rpm as u32,
                    negate: layout.negate as u32,
                    lo: lo as u32,
                    hi: hi as u32,
                };
                ctx.queue.write_buffer(&params, 0, bytemuck::bytes_of(&p));
                let bufs = [
                    sys,
                    &fac,
                    &piv,
                    &xs,
                    &mask,
                    &member_n,
                    &ops,
                    &status,
                    &berr,
                    &params,
                    &extra,
                    &acc,
                    node_x,
                    &resident[0],
                    &resident[1],
                    &resident[2],
                    &resident[3],
                    &resident[4],
                    &spec[0],
                    &spec[1],
                    kiter,
                ];
                let entries: Vec<wgpu::BindGroupEntry> = bufs
                    .iter()
                    .enumerate()
                    .map(|(i, b)| wgpu::BindGroupEntry {
                        binding: i as u32,
                        resource: b.as_entire_binding(),
                    })
                    .collect();
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("blocktri"),
                    layout: &bgl,
                    entries: &entries,
                })
            })
            .collect();
        Ok(Self {
            layout,
            members,
            device,
            queue: ctx.queue.clone(),
            pipelines,
            bind_groups,
            factor_chunks,
            xs,
            mask,
            member_n,
            ops,
            status,
            berr,
            staging,
            _fac_piv: [fac, piv, acc, own_x, own_iter],
            extra,
            extra_host: vec![0.0; xn as usize],
            extra_dirty: vec![false; members],
            resident,
            compact,
            spec,
            spec_host: vec![0.0; 4 * members],
            spec_dirty: vec![false; members],
            scale_host: vec![0.0; 3 * members],
            scale_dirty: vec![false; members],
            mask_host: vec![0; layout.npn * members],
            n_host: vec![0; members],
            topo_dirty: true,
            ops_host: vec![0; members],
            ops_zeroed: false,
            last_bytes_down: 0,
            bytes_up: 0,
            copies_up: 0,
            last_copies_down: 0,
        })
    }

    /// Member slots.
    pub fn members(&self) -> usize {
        self.members
    }

    /// The layout of the system.
    pub fn layout(&self) -> BatchLayout {
        self.layout
    }

    /// Registers member slot `m` with `masks.len()` nodes (≤ NPN; 0 makes it inactive);
    /// `masks[j]` has bit `k` set when node-local unknown `k` of node `j` is an unknown.
    pub fn set_member(&mut self, m: usize, masks: &[u32]) {
        let npn = self.layout.npn;
        assert!(
            masks.len() <= npn,
            "member of {} nodes in slots of {npn}",
            masks.len()
        );
        self.n_host[m] = masks.len() as u32;
        let dst = &mut self.mask_host[m * npn..(m + 1) * npn];
        dst.fill(0);
        dst[..masks.len()].copy_from_slice(masks);
        self.topo_dirty = true;
    }

    /// Sets the values added to member `m`'s stored residual (node-local, one row of 9
    /// per node) before it becomes the right-hand side; uploaded with the next
    /// [`Self::encode`] where they changed.
    pub fn set_extra(&mut self, m: usize, rows: &[[f64; 9]]) {
        let w = 9 * self.layout.npn;
        self.extra_dirty[m] |= extra_rows(&mut self.extra_host[w * m..w * (m + 1)], rows);
    }

    /// [`Self::set_extra`] for many members at once, in parallel: `members[m]` for member
    /// `m`; `None` or no rows leave it as it is.
    pub fn set_extras(&mut self, members: &[Option<&[[f64; 9]]>]) {
        use rayon::prelude::*;
        let w = 9 * self.layout.npn;
        self.extra_host
            .par_chunks_mut(w)
            .zip(self.extra_dirty.par_iter_mut())
            .zip(members.par_iter())
            .for_each(|((dst, dirty), rows)| {
                if let Some(rows) = rows {
                    *dirty |= extra_rows(dst, rows);
                }
            });
    }

    /// Records the factor and solve passes into `enc` for the members of `ops`
    /// (`(slot, OP_FACTOR | OP_SOLVE | OP_UPDATE)`; the others do nothing), then the
    /// device-resident update pass when some member asked for it, uploading what changed.
    pub fn encode(&mut self, enc: &mut wgpu::CommandEncoder, ops: &[(usize, u32)]) {
        self.begin();
        self.encode_passes(enc, ops, false);
    }

    /// [`Self::encode`] for an iteration of a multi-iteration submission (after
    /// [`Self::encode_spec_reset`]): with the check ahead of the factorization — an
    /// [`OP_SPEC`] member whose iterate the host will accept skips its factorization and
    /// solve — and the gate after the update — members without [`OP_SPEC`] stop — each in
    /// the pass of its neighbour where that one runs. After the submission every operation
    /// word on the device is 0 (the [`OP_SPEC`] members stopped by their K at the latest).
    pub fn encode_iteration(&mut self, enc: &mut wgpu::CommandEncoder, ops: &[(usize, u32)]) {
        self.encode_passes(enc, ops, true);
        self.ops_zeroed = true;
    }

    /// At the start of a submission's solver work: the host's copy of the operation words
    /// is 0 where the submission before zeroed them on the device.
    fn begin(&mut self) {
        if std::mem::take(&mut self.ops_zeroed) {
            self.ops_host.fill(0);
        }
    }

    fn encode_passes(&mut self, enc: &mut wgpu::CommandEncoder, ops: &[(usize, u32)], multi: bool) {
        self.prepare(ops);
        let groups = self.members.div_ceil(64) as u32;
        let any = |bit: u32| ops.iter().any(|o| o.1 & bit != 0);
        let (factor, update) = (any(OP_FACTOR), any(OP_UPDATE));
        if multi && !factor {
            self.single_pass(enc, 8);
        }
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("blocktri"),
            timestamp_writes: None,
        });
        let (fc, all) = (self.factor_chunks, self.bind_groups.len());
        let run =
            |pass: &mut wgpu::ComputePass, p: usize, order: &mut dyn Iterator<Item = usize>| {
                pass.set_pipeline(&self.pipelines[p]);
                for c in order {
                    pass.set_bind_group(0, &self.bind_groups[c], &[]);
                    pass.dispatch_workgroups(groups, 1, 1);
                }
            };
        if factor && multi {
            run(&mut pass, 9, &mut (0..1));
            run(&mut pass, 0, &mut (1..fc));
        } else if factor {
            run(&mut pass, 0, &mut (0..fc));
        }
        if any(OP_SOLVE) {
            run(&mut pass, 1, &mut (fc..all));
            run(&mut pass, 2, &mut (fc..all).rev());
            run(&mut pass, 3, &mut (fc..all));
        }
        match (update, multi) {
            (true, true) => run(&mut pass, 10, &mut (0..1)),
            (true, false) => run(&mut pass, 5, &mut (0..1)),
            (false, true) => run(&mut pass, 7, &mut (0..1)),
            (false, false) => {}
        }
    }

    /// Encodes the [`OP_RESTORE`] pass of `ops` (to run before the gather pass that reads
    /// the increments); nothing when no member restores.
    pub fn encode_restore(&mut self, enc: &mut wgpu::CommandEncoder, ops: &[(usize, u32)]) {
        if !ops.iter().any(|o| o.1 & OP_RESTORE != 0) {
            return;
        }
        self.begin();
        self.prepare(ops);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("blocktri restore"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipelines[4]);
        pass.set_bind_group(0, &self.bind_groups[0], &[]);
        pass.dispatch_workgroups(self.members.div_ceil(64) as u32, 1, 1);
    }

    /// Sets member `m`'s Newton test for [`OP_SPEC`]; uploaded with the next operations
    /// when changed.
    pub fn set_spec(&mut self, m: usize, p: SpecParams) {
        let v = [
            p.tol,
            f64::from(u8::from(p.quadratic)),
            p.min_corrections as f64,
            p.k.min(RESIDENT_MAX_K) as f64,
        ];
        let dst = &mut self.spec_host[4 * m..4 * m + 4];
        if dst != v {
            dst.copy_from_slice(&v);
            self.spec_dirty[m] = true;
        }
    }

    /// Encodes the reset of the [`OP_SPEC`] members' iteration counts (before the first
    /// iteration of a multi-iteration submission); uploads what changed first.
    pub fn encode_spec_reset(&mut self, enc: &mut wgpu::CommandEncoder, ops: &[(usize, u32)]) {
        self.begin();
        self.prepare(ops);
        self.single_pass(enc, 6);
    }

    fn single_pass(&self, enc: &mut wgpu::CommandEncoder, p: usize) {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("blocktri spec"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipelines[p]);
        pass.set_bind_group(0, &self.bind_groups[0], &[]);
        pass.dispatch_workgroups(self.members.div_ceil(64) as u32, 1, 1);
    }

    /// Sets member `m`'s host row scales (u, θ, g) of its nodal terms, for
    /// [`OP_UPDATE`]'s relative residual; uploaded with the next operations when changed.
    pub fn set_host_scale(&mut self, m: usize, scale: [f64; 3]) {
        let dst = &mut self.scale_host[3 * m..3 * m + 3];
        if dst != scale {
            dst.copy_from_slice(&scale);
            self.scale_dirty[m] = true;
        }
    }

    /// Uploads what changed: topology, extras, host scales, the operation words.
    fn prepare(&mut self, ops: &[(usize, u32)]) {
        if self.topo_dirty {
            self.queue
                .write_buffer(&self.mask, 0, bytemuck::cast_slice(&self.mask_host));
            self.queue
                .write_buffer(&self.member_n, 0, bytemuck::cast_slice(&self.n_host));
            self.bytes_up += 4 * (self.mask_host.len() + self.n_host.len()) as u64;
            self.copies_up += 2;
            self.topo_dirty = false;
        }
        let w = 9 * self.layout.npn;
        for (lo, hi) in super::kernel::take_runs(&mut self.extra_dirty) {
            self.queue.write_buffer(
                &self.extra,
                8 * (w * lo) as u64,
                bytemuck::cast_slice(&self.extra_host[w * lo..w * hi]),
            );
            self.bytes_up += 8 * (w * (hi - lo)) as u64;
            self.copies_up += 1;
        }
        let mut new = vec![0u32; self.members];
        for &(m, o) in ops {
            new[m] |= o;
        }
        for (lo, hi) in super::kernel::take_runs(&mut self.scale_dirty) {
            self.queue.write_buffer(
                &self.resident[1],
                24 * lo as u64,
                bytemuck::cast_slice(&self.scale_host[3 * lo..3 * hi]),
            );
            self.bytes_up += 24 * (hi - lo) as u64;
            self.copies_up += 1;
        }
        for (lo, hi) in super::kernel::take_runs(&mut self.spec_dirty) {
            self.queue.write_buffer(
                &self.spec[1],
                32 * lo as u64,
                bytemuck::cast_slice(&self.spec_host[4 * lo..4 * hi]),
            );
            self.bytes_up += 32 * (hi - lo) as u64;
            self.copies_up += 1;
        }
        // The operation words that changed, as one span (one copy: a copy per run of
        // changed words cost a staging buffer each).
        let first = (0..new.len()).find(|&i| new[i] != self.ops_host[i]);
        if let Some(lo) = first {
            let hi = (lo..new.len())
                .rfind(|&i| new[i] != self.ops_host[i])
                .unwrap()
                + 1;
            self.queue
                .write_buffer(&self.ops, 4 * lo as u64, bytemuck::cast_slice(&new[lo..hi]));
            self.bytes_up += 4 * (hi - lo) as u64;
            self.copies_up += 1;
            self.ops_host = new;
        }
    }

    /// Encodes, submits and waits; reads back every member's status and backward error
    /// and, with `read_x`, every member's solution.
    pub fn run(&mut self, ops: &[(usize, u32)], read_x: bool) -> Result<Solved, GpuError> {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        self.encode(&mut enc, ops);
        crate::gpu::driver::submit(&self.queue, enc.finish());
        let all: Vec<usize> = if read_x {
            (0..self.members).collect()
        } else {
            Vec::new()
        };
        self.read(&all)
    }

    /// Reads back (after the work encoded with [`Self::encode`] was submitted) every
    /// member's status and backward error (12 bytes per slot) and the solutions of the
    /// member slots `x_of` (72 bytes per node slot); `Solved::x` is `None` when `x_of` is
    /// empty, else holds the whole solution buffer with the other slots left zero.
    pub fn read(&mut self, x_of: &[usize]) -> Result<Solved, GpuError> {
        self.read_back(
            &Readback {
                status: true,
                x: x_of.to_vec(),
                ..Readback::default()
            },
            None,
        )
    }

    /// Reads back what `what` asks for, in one copy and map: statuses and backward errors
    /// of every slot, solutions, device-resident [`Report`]s (16 bytes per slot) and
    /// accepted iterates ([`Solved::iterates`]: 72 bytes per node slot and 8 for the
    /// residual work). The copies go at the end of `enc` when given (work encoded but not
    /// yet submitted, which then goes with them in one submission), else in a command
    /// buffer of their own.
    pub fn read_back(
        &mut self,
        what: &Readback,
        enc: Option<wgpu::CommandEncoder>,
    ) -> Result<Solved, GpuError> {
        use rayon::prelude::*;
        let given = enc.is_some();
        let mut enc = enc.unwrap_or_else(|| {
            self.device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None })
        });
        let mb = self.members as u64;
        let per = 8 * self.layout.x_per_member() as u64;
        // (source, source offset, length) in staging order.
        let mut copies: Vec<(&wgpu::Buffer, u64, u64)> = Vec::new();
        if what.status {
            copies.push((&self.status, 0, 4 * mb));
            copies.push((&self.berr, 0, 8 * mb));
        }
        let x_runs = index_runs(what.x.iter().copied());
        for &(lo, hi) in &x_runs {
            copies.push((&self.xs, per * lo as u64, per * (hi - lo) as u64));
        }
        // Reports and iterates: packed by a pass, then one copy.
        let (packed, up) = self.compact.encode(&mut enc, &what.report, &what.fetch);
        self.bytes_up += up;
        self.copies_up += u64::from(up > 0);
        if packed > 0 {
            copies.push((self.compact.out(), 0, packed));
        }
        let hb = 8 * HSTRIDE as u64;
        let h_runs = index_runs(what.hist.iter().copied());
        for &(lo, hi) in &h_runs {
            copies.push((&self.spec[0], hb * lo as u64, hb * (hi - lo) as u64));
        }
        let w_runs = index_runs(what.rwork.iter().copied());
        for &(lo, hi) in &w_runs {
            copies.push((&self.resident[3], 8 * lo as u64, 8 * (hi - lo) as u64));
        }
        for (b, off, len) in &what.extra {
            copies.push((b, *off, *len));
        }
        let mut out = Solved::default();
        let down: u64 = copies.iter().map(|c| c.2).sum();
        self.last_bytes_down = down;
        self.last_copies_down = copies.len() as u64;
        if down == 0 {
            if given {
                crate::gpu::driver::submit(&self.queue, enc.finish());
            }
            return Ok(out);
        }
        let mut at = 0u64;
        for &(src, off, len) in &copies {
            enc.copy_buffer_to_buffer(src, off, &self.staging, at, len);
            at += len;
        }
        crate::gpu::driver::submit(&self.queue, enc.finish());
        let (tx, rx) = std::sync::mpsc::channel();
        self.staging
            .slice(0..down)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        crate::gpu::driver::wait(&self.device)?;
        rx.recv()
            .map_err(|e| GpuError::Kernel(e.to_string()))?
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        {
            let view = self
                .staging
                .get_mapped_range(0..down)
                .map_err(|e| GpuError::Kernel(e.to_string()))?;
            let bytes: &[u8] = &view;
            let mut pos = 0usize;
            let mut take = |len: usize| {
                let b = &bytes[pos..pos + len];
                pos += len;
                b
            };
            if what.status {
                out.status = bytemuck::pod_collect_to_vec(take(4 * mb as usize));
                out.berr = bytemuck::pod_collect_to_vec(take(8 * mb as usize));
            }
            let w = self.layout.x_per_member();
            if !x_runs.is_empty() {
                let mut x = vec![0.0; w * self.members];
                for &(lo, hi) in &x_runs {
                    let src: Vec<f64> = bytemuck::pod_collect_to_vec(take(8 * w * (hi - lo)));
                    x[w * lo..w * hi].copy_from_slice(&src);
                }
                out.x = Some(x);
            }
            if packed > 0 {
                let nr = what.report.len();
                let reports: Vec<f64> = bytemuck::pod_collect_to_vec(take(16 * nr));
                out.reports.extend(
                    what.report
                        .iter()
                        .zip(reports.chunks_exact(2))
                        .map(|(&m, r)| (m, Report::decode(r[0], r[1]))),
                );
                // Decoded per member by the caller (in parallel), not here.
                out.fetched = what.fetch.clone();
                out.iterates = bytemuck::pod_collect_to_vec(take(packed as usize - 16 * nr));
            }
            for &(lo, hi) in &h_runs {
                // (Per member, in parallel: each history is decoded into its own list.)
                let h: Vec<f64> = bytemuck::pod_collect_to_vec(take(8 * HSTRIDE * (hi - lo)));
                out.hist.par_extend(
                    (lo..hi)
                        .into_par_iter()
                        .zip(h.par_chunks_exact(HSTRIDE))
                        .map(|(m, h)| {
                            let c = (h[0] as usize).min(RESIDENT_MAX_K);
                            let reports = h[1..1 + 2 * c]
                                .chunks_exact(2)
                                .map(|r| Report::decode(r[0], r[1]))
                                .collect();
                            (m, reports, h[HSTRIDE - 1], h[HSTRIDE - 3])
                        }),
                );
            }
            for &(lo, hi) in &w_runs {
                let v: Vec<f64> = bytemuck::pod_collect_to_vec(take(8 * (hi - lo)));
                out.rwork.extend((lo..hi).zip(v));
            }
            for (_, _, len) in &what.extra {
                let v: Vec<f64> = bytemuck::pod_collect_to_vec(take(*len as usize));
                out.extra.extend(v);
            }
        }
        self.staging.unmap();
        Ok(out)
    }
}
