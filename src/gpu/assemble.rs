//! The assembly pass on the GPU: right after the element pass, in the same command
//! buffer, `shaders/assemble.wgsl` sums each member's element blocks into per-node
//! diagonal blocks and residuals, compacts the element off-diagonal blocks and reduces the
//! row scales per member. Only that assembled system crosses the bus, and without the
//! tangent only the nodal residuals and three scales per member.
//!
//! The increments go up once per node: a gather pass (`shaders/gather.wgsl`) before the
//! element pass copies each element's two node increments into the element kernel's
//! increment fields.

use super::context::{compute_pipeline, make_bind_group, GpuContext, Precision};
use super::kernel::{
    index_runs, take_runs, take_runs_gap, ElementKernel, KernelMode, KernelTimers, Readback,
    TangentSlots, SCATTER_GAP,
};
use super::layout::{AsmLayout, A_NODE};
use super::upload::Block;
use super::GpuError;
use crate::integrator::evaluate::AssembledSystem;

pub use super::shaders::{ASSEMBLE_WGSL, GATHER_WGSL};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GatherParams {
    n_elem: u32,
    n_node: u32,
    pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n_elem: u32,
    n_node: u32,
    n_member: u32,
    per_slot: u32,
    nodes_per_slot: u32,
    want_tangent: u32,
    k_start: u32,
    pad: u32,
}

/// Topology buffers (u32) of the assembly pass, in binding order.
const NODE_INC: usize = 0;
/// The node increments' target in the kernel's upload scatter ([`crate::gpu::upload`]).
const NODE_X_TARGET: usize = 3;
const INC: usize = 1;
const ROW_MASK: usize = 2;
const MEMBER_N: usize = 3;
const ELEM_NODES: usize = 4;
/// Per member slot: 1 when the dispatch assembles its tangent.
const MEMBER_TAN: usize = 5;

/// What [`Assembler::run_with`] records around its own passes, in command order.
pub struct Around<'a> {
    /// First, ahead of the uploads (the advance of the members whose last step the device
    /// solved).
    pub head: &'a mut dyn FnMut(&mut ElementKernel, &mut wgpu::CommandEncoder),
    /// After the uploads, ahead of the first gather pass.
    pub before: &'a mut dyn FnMut(&mut wgpu::CommandEncoder),
    /// After each assembly pass (the device solve).
    pub more: &'a mut dyn FnMut(&mut wgpu::CommandEncoder),
    /// After the last iteration, ahead of the read-back copies (the step's records).
    pub tail: &'a mut dyn FnMut(&mut ElementKernel, &mut wgpu::CommandEncoder),
    /// Hand the command buffer back unsubmitted when nothing is read back: the caller
    /// adds its own read-back and submits it (one submission per dispatch).
    pub keep: bool,
}

/// Assembly of `members` member slots of at most `per_slot` elements and `nodes_per_slot`
/// nodes each, over the element slots of one [`ElementKernel`] (member `m`'s element `e`
/// in kernel slot `m * per_slot + e`).
pub struct Assembler {
    layout: AsmLayout,
    /// Node slots (`members × nodes_per_slot`).
    n_nodes: usize,
    /// Element slots (the kernel's capacity).
    n_elems: usize,
    precision: Precision,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// Topology buffers (the assembly pass binds the first four and the per-member
    /// tangent flags, the gather pass per element slot the node slots of its ends).
    topo: [wgpu::Buffer; 6],
    /// Host mirrors of the topology buffers.
    topo_host: [Vec<u32>; 6],
    /// Element slots of the members that want the tangent (the tangent pass's list).
    tan_slots: Vec<u32>,
    gather_pipeline: wgpu::ComputePipeline,
    gather_group: wgpu::BindGroup,
    /// Node increments (9 per node slot, field-major) on the device, their host mirror
    /// (node-major: a member's node slots contiguous) and which node slots changed since
    /// the last upload.
    node_x: wgpu::Buffer,
    node_x_host: Vec<f64>,
    node_x_dirty: Vec<bool>,
    /// Per node slot: the device owns the increments (device-resident Newton).
    node_x_owned: Vec<bool>,
    asm: wgpu::Buffer,
    staging: wgpu::Buffer,
    params: wgpu::Buffer,
    /// What [`Self::params`] was last written with (written again only when it changes:
    /// the iterations of a submission share it).
    params_host: Option<Params>,
    /// Host copy of the assembled buffer; the last run filled the waiting members'
    /// ranges.
    out: Vec<f64>,
}

impl Assembler {
    /// Scalars of the assembled buffer per member slot.
    fn scalars_per_member(per_slot: usize, nodes_per_slot: usize) -> u64 {
        let one = AsmLayout {
            members: 1,
            nodes_per_slot,
            per_slot,
        };
        one.len() as u64
    }

    /// The largest number of member slots whose assembled buffer fits the device.
    pub fn max_members(ctx: &GpuContext, per_slot: usize, nodes_per_slot: usize) -> usize {
        let per = Self::scalars_per_member(per_slot, nodes_per_slot)
            * ElementKernel::width(ctx.precision) as u64;
        let lim = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        (lim / per.max(1)) as usize
    }

    /// Builds the passes around `kernel` (whose capacity must be `members * per_slot`):
    /// from now on `kernel`'s increments come from the gather pass. Every member slot
    /// starts empty (no elements).
    pub fn new(
        ctx: &GpuContext,
        kernel: &mut ElementKernel,
        members: usize,
        per_slot: usize,
        nodes_per_slot: usize,
    ) -> Result<Self, GpuError> {
        let max = Self::max_members(ctx, per_slot, nodes_per_slot);
        if members > max {
            return Err(GpuError::TooLarge {
                elements: members * per_slot,
                max: max * per_slot,
            });
        }
        let layout = AsmLayout {
            members: members.max(1),
            nodes_per_slot: nodes_per_slot.max(1),
            per_slot: per_slot.max(1),
        };
        let n_nodes = layout.members * layout.nodes_per_slot;
        let n_elems = kernel.capacity();
        let device = ctx.device.clone();
        let w = ElementKernel::width(ctx.precision) as u64;
        let pipeline = compute_pipeline(ctx, "assemble", ASSEMBLE_WGSL);
        let gather_pipeline = compute_pipeline(ctx, "gather", GATHER_WGSL);
        ctx.save_pipeline_cache();
        let topo_host = [
            vec![0u32; 2 * n_nodes],
            vec![0u32; 2 * n_elems],
            vec![0u32; n_elems],
            vec![0u32; layout.members],
            vec![0u32; 2 * n_elems],
            vec![0u32; layout.members],
        ];
        let names = [
            "node_inc",
            "inc",
            "row_mask",
            "member_n",
            "elem_nodes",
            "member_tan",
        ];
        let topo = std::array::from_fn(|b| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(names[b]),
                size: 4 * topo_host[b].len() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        for (buf, host) in topo.iter().zip(&topo_host) {
            ctx.queue
                .write_buffer(buf, 0, bytemuck::cast_slice(host.as_slice()));
        }
        let mk = |label: &str, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: layout.len() as u64 * w,
                usage,
                mapped_at_creation: false,
            })
        };
        let asm = mk(
            "assembled",
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let staging = mk(
            "assembled staging",
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("assemble params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = make_bind_group(
            &device,
            &pipeline,
            "assemble",
            &[
                kernel.output_buffer(),
                &topo[NODE_INC],
                &topo[INC],
                &topo[ROW_MASK],
                &topo[MEMBER_N],
                &asm,
                &params,
                &topo[MEMBER_TAN],
            ],
        );
        let node_x = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("node increments"),
            size: (A_NODE * n_nodes) as u64 * w,
            // (Copied out: `--solve whole` keeps a step's predictor and hands it back.)
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let gather_params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gather params"),
            size: std::mem::size_of::<GatherParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let gp = GatherParams {
            n_elem: n_elems as u32,
            n_node: n_nodes as u32,
            pad: [0; 2],
        };
        ctx.queue
            .write_buffer(&gather_params, 0, bytemuck::bytes_of(&gp));
        let gather_group = make_bind_group(
            &device,
            &gather_pipeline,
            "gather",
            &[
                &node_x,
                &topo[ELEM_NODES],
                kernel.iter_buffer(),
                &gather_params,
            ],
        );
        kernel.gather_increments_on_device();
        kernel.scatter_mut().set_target(NODE_X_TARGET, &node_x);
        Ok(Self {
            layout,
            n_nodes,
            n_elems,
            precision: ctx.precision,
            device,
            queue: ctx.queue.clone(),
            pipeline,
            bind_group,
            topo,
            topo_host,
            tan_slots: Vec::new(),
            gather_pipeline,
            gather_group,
            node_x,
            node_x_host: vec![0.0; A_NODE * n_nodes],
            node_x_dirty: vec![false; n_nodes],
            node_x_owned: vec![false; n_nodes],
            asm,
            staging,
            params,
            params_host: None,
            out: vec![0.0; layout.len()],
        })
    }

    /// The assembled buffer on the device (laid out by [`Self::layout`]).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.asm
    }

    /// The buffer layout.
    pub fn layout(&self) -> AsmLayout {
        self.layout
    }

    /// Registers member slot `m`: `ends[e]` are the member-local nodes of its element `e`,
    /// `row_masks[e]` has bit `i` set when element-local row `i` is an unknown. Builds the
    /// node incidence lists (increasing element order, the CPU scatter's summation order)
    /// and uploads the member's ranges of the topology buffers.
    pub fn set_member(
        &mut self,
        m: usize,
        n_nodes: usize,
        ends: &[[usize; 2]],
        row_masks: &[u32],
    ) -> Result<(), GpuError> {
        let l = self.layout;
        if n_nodes > l.nodes_per_slot || ends.len() > l.per_slot || row_masks.len() != ends.len() {
            return Err(GpuError::SlotTooSmall {
                elements: ends.len(),
                nodes: n_nodes,
                per_slot: l.per_slot,
                nodes_per_slot: l.nodes_per_slot,
            });
        }
        let (nb, eb) = (m * l.nodes_per_slot, m * l.per_slot);
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); n_nodes];
        for (e, nodes) in ends.iter().enumerate() {
            for (l, &a) in nodes.iter().enumerate() {
                lists[a].push((2 * (eb + e) + l) as u32);
            }
        }
        let mut next = 2 * eb;
        for j in 0..l.nodes_per_slot {
            let list = lists.get(j).map(Vec::as_slice).unwrap_or(&[]);
            self.topo_host[NODE_INC][2 * (nb + j)] = next as u32;
            self.topo_host[NODE_INC][2 * (nb + j) + 1] = list.len() as u32;
            self.topo_host[INC][next..next + list.len()].copy_from_slice(list);
            next += list.len();
        }
        self.topo_host[ROW_MASK][eb..eb + row_masks.len()].copy_from_slice(row_masks);
        self.topo_host[MEMBER_N][m] = ends.len() as u32;
        for (e, nodes) in ends.iter().enumerate() {
            for (l, &a) in nodes.iter().enumerate() {
                self.topo_host[ELEM_NODES][2 * (eb + e) + l] = (nb + a) as u32;
            }
        }
        let ranges = [
            (ELEM_NODES, 2 * eb, 2 * (eb + ends.len())),
            (NODE_INC, 2 * nb, 2 * (nb + l.nodes_per_slot)),
            (INC, 2 * eb, next),
            (ROW_MASK, eb, eb + row_masks.len()),
            (MEMBER_N, m, m + 1),
        ];
        for (b, lo, hi) in ranges {
            if hi > lo {
                self.queue.write_buffer(
                    &self.topo[b],
                    4 * lo as u64,
                    bytemuck::cast_slice(&self.topo_host[b][lo..hi]),
                );
            }
        }
        Ok(())
    }

    /// Writes member `m`'s node increments (node-local order, zero for removed unknowns);
    /// only changed node slots are uploaded at the next run.
    pub fn set_increments(&mut self, m: usize, nodes: &[[f64; A_NODE]]) {
        self.write_increments(m, nodes, false);
    }

    /// Writes member `m`'s rows of the increment mirror, marking the changed node slots
    /// (all of them when `forced`).
    fn write_increments(&mut self, m: usize, nodes: &[[f64; A_NODE]], forced: bool) {
        let npn = self.layout.nodes_per_slot;
        increment_rows(
            &mut self.node_x_host[A_NODE * m * npn..A_NODE * (m + 1) * npn],
            &mut self.node_x_dirty[m * npn..(m + 1) * npn],
            nodes,
            forced,
        );
    }

    /// [`Self::set_increments`] (or, where `forced`, [`Self::set_increments_forced`]) for
    /// many members at once, in parallel: `members[m]` for member slot `m`, `None` leaves
    /// it as it is.
    pub(crate) fn pack_increments(&mut self, members: &[Option<MemberIncrements<'_>>]) {
        use rayon::prelude::*;
        let npn = self.layout.nodes_per_slot;
        self.node_x_host
            .par_chunks_mut(A_NODE * npn)
            .zip(self.node_x_dirty.par_chunks_mut(npn))
            .zip(members.par_iter())
            .for_each(|((rows, dirty), member)| {
                if let Some((nodes, forced)) = member {
                    increment_rows(rows, dirty, nodes, *forced);
                }
            });
    }

    /// Runs the gather pass, the element passes of `kernel` (frozen scalars) and the
    /// assembly pass in one command buffer and reads back the assembled systems of the
    /// `pending` member slots: each one's node residuals and scales, and its blocks when it
    /// asked for the tangent (`pending[i].1`). The tangent pass runs only over the
    /// elements of the members that asked for it (not at all when none did), and only
    /// their blocks are assembled. Traffic and time go to `kernel`'s timers.
    pub fn run(
        &mut self,
        kernel: &mut ElementKernel,
        pending: &[(usize, bool)],
    ) -> Result<(), GpuError> {
        self.run_with(
            kernel,
            pending,
            &|_| true,
            &|_| true,
            Around {
                head: &mut |_, _| {},
                before: &mut |_| {},
                more: &mut |_| {},
                tail: &mut |_, _| {},
                keep: false,
            },
            1,
        )
        .map(|_| ())
    }

    /// The node increments on the device (9 per node slot, field-major: component `k` of
    /// node slot `s` at `k · members · nodes_per_slot + s`), as the gather pass reads them.
    pub fn increments_buffer(&self) -> &wgpu::Buffer {
        &self.node_x
    }

    /// [`Self::set_increments`] uploading every node slot of member `m` whatever the host
    /// copy holds (the device may have changed them: device-resident Newton).
    pub fn set_increments_forced(&mut self, m: usize, nodes: &[[f64; A_NODE]]) {
        self.write_increments(m, nodes, true);
    }

    /// Sets removed unknowns of member slot `m` on the device to their prescribed
    /// increments (`--solve whole`: a driven support's, before a step on the device),
    /// uploading only the values that differ from those it holds there (removed unknowns
    /// change only through the host: the host copy of them is current). Their node slots'
    /// other unknowns, the device's own iterate, are left alone.
    pub fn set_prescribed(
        &mut self,
        kernel: &mut ElementKernel,
        m: usize,
        rows: &[crate::integrator::evaluate::Prescribed],
    ) {
        let npn = self.layout.nodes_per_slot;
        // Changed values of consecutive rows of a node go up as one run.
        let mut run: Option<(usize, usize, Vec<f64>)> = None;
        let mut flush = |run: &mut Option<(usize, usize, Vec<f64>)>| {
            if let Some((s, f0, vals)) = run.take() {
                let block = Block {
                    target: NODE_X_TARGET,
                    cap: self.n_nodes,
                    f0,
                    nf: vals.len(),
                };
                kernel.scatter_mut().push(block, s, &vals);
            }
        };
        for p in rows.iter().filter(|p| p.node < npn && p.row < A_NODE) {
            let s = m * npn + p.node;
            let at = A_NODE * s + p.row;
            // (NaN, a forgotten copy, never equals: it goes up.)
            if self.node_x_host[at] == p.value {
                flush(&mut run);
                continue;
            }
            self.node_x_host[at] = p.value;
            match &mut run {
                Some((rs, f0, vals)) if *rs == s && *f0 + vals.len() == p.row => vals.push(p.value),
                _ => {
                    flush(&mut run);
                    run = Some((s, p.row, vec![p.value]));
                }
            }
        }
        flush(&mut run);
    }

    /// Forgets the host copy of member slot `m`'s increments (the device changed them), so
    /// that the next [`Self::set_increments`] uploads every value.
    pub fn invalidate_increments(&mut self, m: usize) {
        let npn = self.layout.nodes_per_slot;
        self.node_x_host[A_NODE * m * npn..A_NODE * (m + 1) * npn].fill(f64::NAN);
    }

    /// Marks member slot `m`'s increments as owned by the device (device-resident Newton
    /// updates them there): uploads of neighbouring slots never re-send them from the host
    /// copy, which is then stale.
    pub fn set_device_owned(&mut self, m: usize, owned: bool) {
        let npn = self.layout.nodes_per_slot;
        self.node_x_owned[m * npn..(m + 1) * npn].fill(owned);
    }

    /// [`Self::run`] with the passes of `around` recorded in the same command buffer (the
    /// device block solver of [`crate::gpu::blocktri`], the advance and records of
    /// `--solve whole`); the tangent blocks of member slot `m` are read back only when
    /// `blocks_back(m)`, its residual region only when `residual_back(m)`. The gather,
    /// element, assembly and `around.more` passes are recorded `repeats` times (several
    /// device-resident Newton iterations in one submission). Returns the command buffer
    /// unsubmitted when `around.keep` and nothing is read back.
    pub fn run_with(
        &mut self,
        kernel: &mut ElementKernel,
        pending: &[(usize, bool)],
        blocks_back: &dyn Fn(usize) -> bool,
        residual_back: &dyn Fn(usize) -> bool,
        around: Around<'_>,
        repeats: usize,
    ) -> Result<Option<wgpu::CommandEncoder>, GpuError> {
        let want_tangent = pending.iter().any(|p| p.1);
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        (around.head)(kernel, &mut enc);
        let l = self.layout;
        let t0 = std::time::Instant::now();
        let nn = self.n_nodes;
        // Clean slots between two dirty ones may go up from the host copy to save runs,
        // except those the device owns (their host copy is stale).
        let dirty = self.node_x_dirty.clone();
        let owned = &self.node_x_owned;
        let runs = take_runs_gap(&mut self.node_x_dirty, SCATTER_GAP)
            .into_iter()
            .flat_map(|(lo, hi)| {
                let mut parts = Vec::new();
                let mut start = None;
                for s in lo..=hi {
                    let send = s < hi && (dirty[s] || !owned[s]);
                    match (send, start) {
                        (true, None) => start = Some(s),
                        (false, Some(a)) => {
                            parts.push((a, s));
                            start = None;
                        }
                        _ => {}
                    }
                }
                parts
            })
            .collect::<Vec<_>>();
        let rows = Block {
            target: NODE_X_TARGET,
            cap: nn,
            f0: 0,
            nf: A_NODE,
        };
        for &(lo, hi) in &runs {
            kernel
                .scatter_mut()
                .push(rows, lo, &self.node_x_host[A_NODE * lo..A_NODE * hi]);
        }
        // The uploads go first: the gather pass reads the node increments.
        kernel.flush_uploads(&mut enc);
        // Per-member tangent flags (uploaded where they changed) and the tangent pass's
        // element list.
        let mut flags = vec![0u32; l.members];
        self.tan_slots.clear();
        for &(m, t) in pending.iter().filter(|p| p.1) {
            flags[m] = t as u32;
            let base = (m * l.per_slot) as u32;
            let n = self.topo_host[MEMBER_N][m];
            self.tan_slots.extend(base..base + n);
        }
        self.tan_slots.sort_unstable();
        let mut changed: Vec<bool> = flags
            .iter()
            .zip(&self.topo_host[MEMBER_TAN])
            .map(|(a, b)| a != b)
            .collect();
        self.topo_host[MEMBER_TAN] = flags;
        for (lo, hi) in take_runs(&mut changed) {
            let src = &self.topo_host[MEMBER_TAN][lo..hi];
            self.queue.write_buffer(
                &self.topo[MEMBER_TAN],
                4 * lo as u64,
                bytemuck::cast_slice(src),
            );
            kernel.timers.bytes_up += 4 * (hi - lo) as u64;
        }
        kernel.timers.upload_s += t0.elapsed().as_secs_f64();
        (around.before)(&mut enc);
        // `repeats` Newton iterations in one submission (`--solve resident`: `more` records
        // the device solve and update after each assembly).
        for _ in 0..repeats.max(1) {
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("gather"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.gather_pipeline);
                pass.set_bind_group(0, &self.gather_group, &[]);
                pass.dispatch_workgroups(self.n_elems.div_ceil(64) as u32, 1, 1);
            }
            let tangent = if want_tangent {
                TangentSlots::List(&self.tan_slots)
            } else {
                TangentSlots::None
            };
            kernel.encode(&mut enc, KernelMode::Frozen, tangent);
            let prm = Params {
                n_elem: self.n_elems as u32,
                n_node: self.n_nodes as u32,
                n_member: l.members as u32,
                per_slot: l.per_slot as u32,
                nodes_per_slot: l.nodes_per_slot as u32,
                want_tangent: want_tangent as u32,
                k_start: l.tangent_start() as u32,
                pad: 0,
            };
            if self
                .params_host
                .is_none_or(|p| bytemuck::bytes_of(&p) != bytemuck::bytes_of(&prm))
            {
                self.queue
                    .write_buffer(&self.params, 0, bytemuck::bytes_of(&prm));
                self.params_host = Some(prm);
            }
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("assemble"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                let threads = self.n_nodes.max(self.n_elems).max(l.members);
                pass.dispatch_workgroups(threads.div_ceil(64) as u32, 1, 1);
            }
            (around.more)(&mut enc);
        }
        (around.tail)(kernel, &mut enc);
        // The waiting members' residual regions, and the tangent regions of those that
        // asked for it: one range per run of adjacent such members.
        let w = ElementKernel::width(self.precision) as u64;
        let (r, k) = (l.residual_per_member(), l.tangent_per_member());
        let residual = index_runs(pending.iter().map(|p| p.0).filter(|&m| residual_back(m)))
            .into_iter()
            .map(|(lo, hi)| ((lo * r) as u64 * w, ((hi - lo) * r) as u64 * w));
        let tangent = index_runs(
            pending
                .iter()
                .filter(|p| p.1 && blocks_back(p.0))
                .map(|p| p.0),
        )
        .into_iter()
        .map(|(lo, hi)| {
            let at = l.tangent_start() + lo * k;
            (at as u64 * w, ((hi - lo) * k) as u64 * w)
        });
        let ranges: Vec<(u64, u64)> = residual.chain(tangent).collect();
        if around.keep && ranges.is_empty() {
            kernel.timers.dispatches += 1;
            return Ok(Some(enc));
        }
        let rb = Readback {
            device: &self.device,
            queue: &self.queue,
            src: &self.asm,
            staging: &self.staging,
            precision: self.precision,
        };
        let timers: &mut KernelTimers = &mut kernel.timers;
        rb.run(enc, &ranges, &mut self.out, timers).map(|()| None)
    }

    /// Member `m`'s assembled system from the last [`Self::run`] (`n_nodes` nodes,
    /// `n_elems` elements; the blocks are left empty without the tangent).
    pub fn system(
        &self,
        m: usize,
        n_nodes: usize,
        n_elems: usize,
        with_tangent: bool,
    ) -> AssembledSystem {
        let (l, o) = (self.layout, &self.out);
        let node_r = (0..n_nodes)
            .map(|j| std::array::from_fn(|k| o[l.node_residual(m, j) + k]))
            .collect();
        let scale = std::array::from_fn(|k| o[l.scales(m) + k]);
        let (node_k, off_k) = if with_tangent {
            let node_k = (0..n_nodes)
                .map(|j| std::array::from_fn(|f| o[l.node_block(m, j) + f]))
                .collect();
            let off_k = (0..n_elems)
                .map(|e| {
                    std::array::from_fn(|h| std::array::from_fn(|f| o[l.off_block(m, e, h) + f]))
                })
                .collect();
            (node_k, off_k)
        } else {
            (Vec::new(), Vec::new())
        };
        AssembledSystem {
            node_r,
            node_k,
            off_k,
            scale,
            solution: None,
            resident: None,
            step: None,
            pulled: None,
        }
    }
}

/// One member's node increments (node-local order) and whether every node slot goes up
/// whatever the host copy holds ([`Assembler::set_increments_forced`]).
pub(crate) type MemberIncrements<'a> = (&'a [[f64; A_NODE]], bool);

/// Writes one member's node increments into its rows of the node-major increment mirror
/// (`A_NODE` values per node slot), marking the node slots that changed, or all of them
/// when `forced`.
fn increment_rows(rows: &mut [f64], dirty: &mut [bool], nodes: &[[f64; A_NODE]], forced: bool) {
    for ((row, d), x) in rows.chunks_mut(A_NODE).zip(dirty.iter_mut()).zip(nodes) {
        let changed = *row != x[..];
        if changed {
            row.copy_from_slice(x);
        }
        *d |= forced || changed;
    }
}
