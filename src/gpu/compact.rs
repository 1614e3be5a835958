//! Read-back compaction (`shaders/compact.wgsl`) for the device block solver: the
//! device-resident reports and accepted iterates of the member slots a dispatch asks for
//! lie spread over member-major buffers; one pass writes them one after another into one
//! buffer, so the read-back is one copy command of exactly the bytes asked for (a copy
//! per run of members cost a command, a barrier and driver bookkeeping each).

use super::context::{compute_pipeline, make_bind_group};
use super::shaders::COMPACT_WGSL;

/// The compaction pass over a solver's report, iterate and residual-work buffers.
pub(crate) struct Compact {
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    list: wgpu::Buffer,
    out: wgpu::Buffer,
    /// Scalars per member of an iterate.
    w: usize,
    host_list: Vec<u32>,
}

impl Compact {
    /// The pass over `members` member slots of `report` (2 f64 each), `q` (`w` f64 each)
    /// and `rwork` (1 f64 each).
    pub(crate) fn new(
        ctx: &super::context::GpuContext,
        members: usize,
        w: usize,
        report: &wgpu::Buffer,
        q: &wgpu::Buffer,
        rwork: &wgpu::Buffer,
    ) -> Self {
        let device = ctx.device.clone();
        let pipeline = compute_pipeline(ctx, "compact", COMPACT_WGSL);
        ctx.save_pipeline_cache();
        let storage = |label: &str, bytes: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (bytes as u64).max(64),
                usage: wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        // A slot can be listed twice (its report and its iterate).
        let list = storage(
            "compact list",
            4 * (4 + 2 * members),
            wgpu::BufferUsages::COPY_DST,
        );
        let out = storage(
            "compacted read-back",
            8 * (2 + w + 1) * members,
            wgpu::BufferUsages::COPY_SRC,
        );
        let group = make_bind_group(
            &device,
            &pipeline,
            "compact",
            &[&list, report, q, rwork, &out],
        );
        Self {
            queue: ctx.queue.clone(),
            pipeline,
            group,
            list,
            out,
            w,
            host_list: Vec::new(),
        }
    }

    /// Uploads the list (one copy, before the next submission) and records the pass into
    /// `enc`: the reports of `report`, then the iterates of `fetch`, into [`Self::out`].
    /// Returns the bytes of the compacted output (`16` per report, `8 (W + 1)` per
    /// iterate) and the bytes uploaded; nothing is recorded when both lists are empty.
    pub(crate) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        report: &[usize],
        fetch: &[usize],
    ) -> (u64, u64) {
        let (nr, nf) = (report.len(), fetch.len());
        if nr + nf == 0 {
            return (0, 0);
        }
        self.host_list.clear();
        self.host_list
            .extend([nr as u32, nf as u32, self.w as u32, 0]);
        self.host_list
            .extend(report.iter().chain(fetch).map(|&m| m as u32));
        self.queue
            .write_buffer(&self.list, 0, bytemuck::cast_slice(&self.host_list));
        let groups = nr.div_ceil(32) + nf;
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("compact"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.group, &[]);
            let x = groups.min(65_535);
            pass.dispatch_workgroups(x as u32, groups.div_ceil(x) as u32, 1);
        }
        (
            8 * (2 * nr + (self.w + 1) * nf) as u64,
            4 * self.host_list.len() as u64,
        )
    }

    /// The compacted output.
    pub(crate) fn out(&self) -> &wgpu::Buffer {
        &self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::context::{GpuContext, Precision};
    use crate::math::rng::Rng;

    fn f64_context() -> Option<GpuContext> {
        match GpuContext::new(None) {
            Ok(c) if c.precision == Precision::F64 => Some(c),
            Ok(_) if !crate::gpu::gpu_required() => {
                println!("skipped: the adapter has no SHADER_F64");
                None
            }
            Err(e) if !crate::gpu::gpu_required() => {
                println!("skipped: no adapter ({e})");
                None
            }
            Ok(_) => panic!("COSSERAT_REQUIRE_GPU is set but the adapter has no SHADER_F64"),
            Err(e) => panic!("COSSERAT_REQUIRE_GPU is set but no usable adapter: {e}"),
        }
    }

    fn filled(ctx: &GpuContext, data: &[f64]) -> wgpu::Buffer {
        let b = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: 8 * data.len() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.queue.write_buffer(&b, 0, bytemuck::cast_slice(data));
        b
    }

    /// 300 member slots of 135 iterate scalars (over two strides of a workgroup); unsorted
    /// lists of 100 reports (four report workgroups) and 50 iterates, one slot in both: the output holds exactly the listed values, reports
    /// first, in list order; then an empty request records nothing.
    #[test]
    fn listed_reports_and_iterates_come_out_packed_in_list_order() {
        let Some(ctx) = f64_context() else { return };
        let (members, w) = (300, 9 * 15);
        let mut rng = Rng::new(11);
        let mut vals = |n: usize| -> Vec<f64> { (0..n).map(|_| rng.symmetric()).collect() };
        let (report, q, rwork) = (vals(2 * members), vals(w * members), vals(members));
        let bufs = [&report, &q, &rwork].map(|v| filled(&ctx, v));
        let mut compact = Compact::new(&ctx, members, w, &bufs[0], &bufs[1], &bufs[2]);
        // Slots in a scrambled order (a stride prime to 300), a few iterates also reported.
        let order: Vec<usize> = (0..members).map(|i| (i * 7 + 3) % members).collect();
        let reports = &order[..100];
        let fetches: Vec<usize> = order[95..145].to_vec();
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        let (bytes, up) = compact.encode(&mut enc, reports, &fetches);
        assert_eq!(bytes, 8 * (2 * 100 + (w + 1) * 50) as u64);
        assert_eq!(up, 4 * (4 + 150) as u64);
        ctx.queue.submit([enc.finish()]);
        let got = crate::gpu::upload::tests::read(&ctx, compact.out(), bytes as usize / 8);
        let mut want = Vec::new();
        for &m in reports {
            want.extend_from_slice(&report[2 * m..2 * m + 2]);
        }
        for &m in &fetches {
            want.extend_from_slice(&q[w * m..w * (m + 1)]);
            want.push(rwork[m]);
        }
        assert_eq!(got, want);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        assert_eq!(compact.encode(&mut enc, &[], &[]), (0, 0));
    }
}
