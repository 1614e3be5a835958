//! The uploads of a dispatch in two copies: the changed runs of the element kernel's input
//! buffers (written straight from its host mirrors into the staging memory, in parallel)
//! and of the node increments are packed into one value array and one run list, copied to
//! the device, and scattered into place by the first pass of the dispatch
//! (`shaders/scatter.wgsl`).
//!
//! A `write_buffer` per run costs a staging allocation, a copy command and their
//! bookkeeping (≈ 2.3 µs each on lavapipe, where a byte costs ≈ 0.1–0.5 ns), and a
//! dispatch of a lockstep batch changes hundreds of field-major runs: a member's state
//! once per step (48 fields), its frozen scalars once per staggered round (5), its
//! increments once per Newton solve (9). Measured on `bench --rods 128 --solve device`:
//! 518 copies per dispatch before, 2 now (docs/gpu.md).

use super::context::{GpuContext, Precision};
use super::shaders::{real_width, shader_precision, SCATTER_WGSL};
use rayon::prelude::*;

/// Scalars per run at most (one workgroup of 64 invocations copies a run; longer runs
/// are split so that no workgroup walks a whole buffer).
const RUN_MAX: usize = 1024;

/// Target buffers of a scatter: the element kernel's element, state and iteration
/// buffers, and the node increments of [`crate::gpu::Assembler`].
pub(crate) const TARGETS: usize = 4;

/// One run: a block of `slots` slots × `nf` fields, slot-major in `vals[src..]`, to
/// fields `f0..f0 + nf` of slots `slot0..slot0 + slots` of the field-major target
/// `dst` (`cap` slots per field).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct Run {
    dst: u32,
    slot0: u32,
    slots: u32,
    src: u32,
    f0: u32,
    nf: u32,
    cap: u32,
    pad: u32,
}

/// Where a block goes: target, its slots per field, and the block's fields.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block {
    /// Target buffer (0..[`TARGETS`]).
    pub target: usize,
    /// Slots per field of the target.
    pub cap: usize,
    /// First field of the block and number of fields.
    pub f0: usize,
    pub nf: usize,
}

/// Rows of a slot-major host mirror to upload (uploaded straight from the mirror by
/// [`Scatter::encode`]): slots `lo..hi`, fields `block.f0..block.f0 + block.nf` of the
/// `stride` values of each slot.
pub(crate) struct MirrorRows<'a> {
    pub block: Block,
    pub lo: usize,
    pub hi: usize,
    pub host: &'a [f64],
    pub stride: usize,
}

/// A disjoint piece of the staging view, to be filled on another thread.
struct Piece<'a>(wgpu::WriteOnly<'a, [u8]>);

// SAFETY: a `WriteOnly<'a, [u8]>` is an exclusive, write-only borrow of bytes, like
// `&'a mut [u8]` (which is `Send`); wgpu 30 implements `Send` for `WriteOnly<T>` only for
// sized `T` (its impl lacks `?Sized`), not for slices. The pieces come from `split_at`, so
// no two overlap.
unsafe impl Send for Piece<'_> {}

/// Writes `vals` into `dst` in the device's precision (`dst` is exactly their size).
fn write_values(dst: &mut wgpu::WriteOnly<'_, [u8]>, vals: &[f64], precision: Precision) {
    match precision {
        Precision::F64 => dst.copy_from_slice(bytemuck::cast_slice(vals)),
        Precision::F32 => {
            let v: Vec<f32> = vals.iter().map(|&x| x as f32).collect();
            dst.copy_from_slice(bytemuck::cast_slice(&v));
        }
    }
}

/// The pending uploads of one dispatch and the pass that scatters them.
pub(crate) struct Scatter {
    device: wgpu::Device,
    queue: wgpu::Queue,
    precision: Precision,
    pipeline: wgpu::ComputePipeline,
    targets: [wgpu::Buffer; TARGETS],
    /// `runs[0]` is the header (its `dst` the number of runs).
    runs: Vec<Run>,
    vals: Vec<f64>,
    run_buf: wgpu::Buffer,
    val_buf: wgpu::Buffer,
    group: Option<wgpu::BindGroup>,
}

impl Scatter {
    /// A scatter into `targets` (a target not yet known is a placeholder: see
    /// [`Self::set_target`]).
    pub(crate) fn new(ctx: &GpuContext, targets: [wgpu::Buffer; TARGETS]) -> Self {
        let device = ctx.device.clone();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("scatter.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader_precision(SCATTER_WGSL, ctx.precision).into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("scatter"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: ctx.pipeline_cache(),
        });
        ctx.save_pipeline_cache();
        let run_buf = Self::buffer(&device, "scatter runs", 64);
        let val_buf = Self::buffer(&device, "scatter values", 64);
        Self {
            device,
            queue: ctx.queue.clone(),
            precision: ctx.precision,
            pipeline,
            targets,
            runs: vec![Run::default()],
            vals: Vec::new(),
            run_buf,
            val_buf,
            group: None,
        }
    }

    fn buffer(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(64),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Replaces target `t`.
    pub(crate) fn set_target(&mut self, t: usize, buf: &wgpu::Buffer) {
        self.targets[t] = buf.clone();
        self.group = None;
    }

    /// Queues the slot-major values `src` (`b.nf` per slot) for slots `slot0..` of block
    /// `b`.
    pub(crate) fn push(&mut self, b: Block, slot0: usize, src: &[f64]) {
        debug_assert_eq!(src.len() % b.nf, 0);
        self.add_runs(b, slot0, src.len() / b.nf, self.vals.len());
        self.vals.extend_from_slice(src);
    }

    /// The run descriptions of `slots` slots of block `b` from slot `slot0`, their values
    /// at `src..` of the value array (split so that no run exceeds [`RUN_MAX`] values).
    fn add_runs(&mut self, b: Block, slot0: usize, slots: usize, src: usize) {
        let per = (RUN_MAX / b.nf).max(1);
        for k in (0..slots).step_by(per) {
            let n = per.min(slots - k);
            self.runs.push(Run {
                dst: b.target as u32,
                slot0: (slot0 + k) as u32,
                slots: n as u32,
                src: (src + k * b.nf) as u32,
                f0: b.f0 as u32,
                nf: b.nf as u32,
                cap: b.cap as u32,
                pad: 0,
            });
        }
    }

    /// Uploads what is queued and the mirror rows `rows` (two copies) and records the
    /// scatter pass into `enc`; returns the bytes uploaded and the copies made (0 and 0
    /// when nothing is queued). The rows are written once, straight into the staging
    /// memory, in parallel over chunks of slots (not copied into the value array first).
    pub(crate) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        rows: &[MirrorRows<'_>],
    ) -> (u64, u64) {
        let queued = self.vals.len();
        let mut at = queued;
        for r in rows {
            self.add_runs(r.block, r.lo, r.hi - r.lo, at);
            at += (r.hi - r.lo) * r.block.nf;
        }
        let n = self.runs.len() - 1;
        if n == 0 {
            return (0, 0);
        }
        self.runs[0].dst = n as u32;
        let w = real_width(self.precision);
        let run_bytes = (std::mem::size_of::<Run>() * self.runs.len()) as u64;
        let val_bytes = (w * at) as u64;
        if run_bytes > self.run_buf.size() {
            self.run_buf =
                Self::buffer(&self.device, "scatter runs", run_bytes.next_power_of_two());
            self.group = None;
        }
        if val_bytes > self.val_buf.size() {
            self.val_buf = Self::buffer(
                &self.device,
                "scatter values",
                val_bytes.next_power_of_two(),
            );
            self.group = None;
        }
        self.queue
            .write_buffer(&self.run_buf, 0, bytemuck::cast_slice(&self.runs));
        if let Some(size) = wgpu::BufferSize::new(val_bytes) {
            let mut view = self
                .queue
                .write_buffer_with(&self.val_buf, 0, size)
                .expect("scatter values: write within the buffer");
            let (mut head, mut rest) = view.slice(..).split_at(w * queued);
            write_values(&mut head, &self.vals, self.precision);
            // Disjoint pieces of at most CHUNK slots, filled in parallel.
            const CHUNK: usize = 32;
            let mut pieces = Vec::new();
            for r in rows {
                for lo in (r.lo..r.hi).step_by(CHUNK) {
                    let hi = (lo + CHUNK).min(r.hi);
                    let (piece, tail) = rest.split_at(w * (hi - lo) * r.block.nf);
                    rest = tail;
                    pieces.push((Piece(piece), r, lo, hi));
                }
            }
            let precision = self.precision;
            pieces
                .into_par_iter()
                .for_each(|(Piece(mut piece), r, lo, hi)| {
                    let (f0, nf, stride) = (r.block.f0, r.block.nf, r.stride);
                    if f0 == 0 && nf == stride {
                        write_values(&mut piece, &r.host[lo * stride..hi * stride], precision);
                    } else {
                        for (k, i) in (lo..hi).enumerate() {
                            let row = &r.host[i * stride + f0..i * stride + f0 + nf];
                            let mut dst = piece.slice(w * k * nf..w * (k + 1) * nf);
                            write_values(&mut dst, row, precision);
                        }
                    }
                });
        }
        let group = self.group.get_or_insert_with(|| {
            let bufs = [&self.run_buf, &self.val_buf]
                .into_iter()
                .chain(self.targets.iter());
            let entries: Vec<wgpu::BindGroupEntry> = bufs
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: b.as_entire_binding(),
                })
                .collect();
            self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("scatter"),
                layout: &self.pipeline.get_bind_group_layout(0),
                entries: &entries,
            })
        });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("scatter"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &*group, &[]);
            let x = n.min(65_535);
            pass.dispatch_workgroups(x as u32, n.div_ceil(x) as u32, 1);
        }
        self.runs.truncate(1);
        self.vals.clear();
        (run_bytes + val_bytes, 2)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::math::rng::Rng;

    fn context() -> Option<GpuContext> {
        match GpuContext::new(None) {
            Ok(c) => Some(c),
            Err(e) if !crate::gpu::gpu_required() => {
                println!("skipped: no adapter ({e})");
                None
            }
            Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no usable adapter: {e}"),
        }
    }

    /// Reads `buf` (`n` scalars of `precision`) back to the host as f64.
    pub(crate) fn read(ctx: &GpuContext, buf: &wgpu::Buffer, n: usize) -> Vec<f64> {
        let w = real_width(ctx.precision);
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (w * n) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buf, 0, &staging, 0, (w * n) as u64);
        ctx.queue.submit([enc.finish()]);
        staging
            .slice(..)
            .map_async(wgpu::MapMode::Read, |r| r.unwrap());
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .unwrap();
        let bytes = staging.slice(..).get_mapped_range().unwrap().to_vec();
        match ctx.precision {
            Precision::F64 => bytemuck::cast_slice::<u8, f64>(&bytes).to_vec(),
            Precision::F32 => bytemuck::cast_slice::<u8, f32>(&bytes)
                .iter()
                .map(|&x| x as f64)
                .collect(),
        }
    }

    fn below(rng: &mut Rng, n: usize) -> usize {
        ((rng.uniform() * n as f64) as usize).min(n - 1)
    }

    /// Blocks of random slot ranges and field ranges (one longer than [`RUN_MAX`],
    /// split) into three field-major targets of different shapes, and rows of a host
    /// mirror (all fields, and a range of fields; over several parallel pieces and runs)
    /// into a fourth, over two dispatches, in f64 and in f32: every queued value lands in
    /// its field and slot, and nothing else changes.
    #[test]
    fn queued_blocks_land_in_their_fields_and_slots_and_nowhere_else() {
        let Some(ctx) = context() else { return };
        scatter_round_trip(&ctx);
        scatter_round_trip(&ctx.with_precision(Precision::F32));
    }

    fn scatter_round_trip(ctx: &GpuContext) {
        let ctx = ctx.with_precision(ctx.precision);
        // (fields, slots per field) of each target.
        // Target 2 gets mirror rows only (written straight from a slot-major host mirror),
        // the others queued blocks.
        let shapes = [(6, 500), (10, 500), (7, 400), (9, 300)];
        let sizes: Vec<usize> = shapes.iter().map(|&(f, c)| f * c).collect();
        let w = real_width(ctx.precision) as u64;
        let targets: [wgpu::Buffer; TARGETS] = std::array::from_fn(|t| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: w * sizes[t] as u64,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        let mut mirror: Vec<Vec<f64>> = sizes.iter().map(|&n| vec![0.0; n]).collect();
        let mut scatter = Scatter::new(&ctx, targets.clone());
        let mut rng = Rng::new(7);
        for dispatch in 0..2 {
            let mut enc = ctx.device.create_command_encoder(&Default::default());
            // Disjoint slot ranges per target, each with a random range of fields.
            let mut runs = 0;
            for (t, &(nfields, cap)) in shapes.iter().enumerate() {
                if t == 2 {
                    continue;
                }
                let mut slot = below(&mut rng, 20);
                let mut first = true;
                while slot < cap {
                    // The first block of target 1 in the first dispatch: 300 slots × 10
                    // fields, split into runs of at most RUN_MAX values.
                    let long = dispatch == 0 && t == 1 && first;
                    first = false;
                    let slots = if long { 300 } else { 1 + below(&mut rng, 30) }.min(cap - slot);
                    let f0 = if long { 0 } else { below(&mut rng, nfields) };
                    let nf = if long {
                        nfields
                    } else {
                        1 + below(&mut rng, nfields - f0)
                    };
                    let vals: Vec<f64> = (0..slots * nf).map(|_| rng.symmetric()).collect();
                    let b = Block {
                        target: t,
                        cap,
                        f0,
                        nf,
                    };
                    scatter.push(b, slot, &vals);
                    for s in 0..slots {
                        for f in 0..nf {
                            mirror[t][(f0 + f) * cap + slot + s] = vals[s * nf + f];
                        }
                    }
                    runs += 1;
                    slot += slots + below(&mut rng, 25);
                }
            }
            assert!(runs > 30, "{runs} runs");
            if dispatch == 0 {
                let split = scatter
                    .runs
                    .iter()
                    .filter(|r| r.dst == 1 && r.nf == 10)
                    .count();
                assert!(split >= 3, "the long block went up as {split} runs");
            }
            // Mirror rows into target 2: all 7 fields of slots 0..200 (1 400 values: split
            // into runs, and into pieces of 32 slots), fields 0..3 of slots 210..240 and
            // fields 3..7 of slots 250..400.
            let (nf2, cap2) = shapes[2];
            let host: Vec<f64> = (0..cap2 * nf2).map(|_| rng.symmetric()).collect();
            let rows = [(0, 200, 0, nf2), (210, 240, 0, 3), (250, 400, 3, nf2 - 3)].map(
                |(lo, hi, f0, nf)| MirrorRows {
                    block: Block {
                        target: 2,
                        cap: cap2,
                        f0,
                        nf,
                    },
                    lo,
                    hi,
                    host: &host,
                    stride: nf2,
                },
            );
            for r in &rows {
                for slot in r.lo..r.hi {
                    for f in r.block.f0..r.block.f0 + r.block.nf {
                        mirror[2][f * cap2 + slot] = host[slot * nf2 + f];
                    }
                }
            }
            let (bytes, copies) = scatter.encode(&mut enc, &rows);
            assert_eq!(copies, 2);
            assert!(bytes > 0);
            ctx.queue.submit([enc.finish()]);
            for (t, &n) in sizes.iter().enumerate() {
                let got = read(&ctx, &targets[t], n);
                for (i, (g, m)) in got.iter().zip(&mirror[t]).enumerate() {
                    let want = match ctx.precision {
                        Precision::F64 => *m,
                        Precision::F32 => *m as f32 as f64,
                    };
                    assert_eq!(*g, want, "dispatch {dispatch}, target {t}, scalar {i}");
                }
            }
        }
        // Nothing queued: no copies, no pass.
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        assert_eq!(scatter.encode(&mut enc, &[]), (0, 0));
    }
}
