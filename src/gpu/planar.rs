//! The planar element kernel on the GPU (`shaders/planar.wgsl`): the WGSL twin of
//! [`crate::element::planar`] for frozen dissipation scalars, one invocation per element,
//! residual (10), row scales (10) and tangent (10×10). f64 adapters only. This is the
//! kernel and its parity harness (`tests/gpu_planar_kernel.rs`); the GPU batch path still
//! evaluates planar models with the 3D kernel (docs/gpu.md).

use super::context::{GpuContext, Precision};
use super::GpuError;
use crate::element::planar::{
    PElemMat, PElemVec, PElementEval, PIncrement, PState, PlanarData, NDOF_P,
};
use crate::element::{FrozenScalars, StepConsts, StressRule};
use nalgebra::Vector3;

pub use super::shaders::PLANAR_WGSL;
/// f64 inputs per element (layout: the `I_*` constants of the shader).
const NIN: usize = 56;
/// f64 outputs per element: residual, scales, tangent (row-major).
const NOUT: usize = 120;

/// One element's inputs.
#[derive(Clone, Copy, Debug)]
pub struct PlanarInput {
    /// Constant data.
    pub data: PlanarData,
    /// State at `n`.
    pub st: PState,
    /// Planar strains at `n`.
    pub eps_n: Vector3<f64>,
    /// Increment.
    pub inc: PIncrement,
    /// Frozen scalars.
    pub s: FrozenScalars,
}

/// The compiled planar kernel on one device.
pub struct PlanarKernelGpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    bgl: wgpu::BindGroupLayout,
}

impl PlanarKernelGpu {
    /// Compiles the kernel. Needs an f64 context.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        if ctx.precision != Precision::F64 {
            return Err(GpuError::Kernel(
                "the planar kernel needs an adapter with SHADER_F64".into(),
            ));
        }
        let device = ctx.device.clone();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("planar.wgsl"),
            source: wgpu::ShaderSource::Wgsl(PLANAR_WGSL.into()),
        });
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("planar"),
            entries: &[storage(0, true), storage(1, false)],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("planar"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("planar_main"),
            layout: Some(&pl),
            module: &module,
            entry_point: Some("planar_main"),
            compilation_options: Default::default(),
            cache: ctx.pipeline_cache(),
        });
        ctx.save_pipeline_cache();
        Ok(Self {
            device,
            queue: ctx.queue.clone(),
            pipeline,
            bgl,
        })
    }

    /// Evaluates `elems` in one dispatch (frozen scalars, constants `k`).
    pub fn evaluate(
        &self,
        elems: &[PlanarInput],
        k: &StepConsts,
        trans_diss: bool,
        want_tangent: bool,
    ) -> Result<Vec<PElementEval>, GpuError> {
        if elems.is_empty() {
            return Ok(Vec::new());
        }
        let mut inp = vec![0.0f64; NIN * elems.len()];
        for (x, e) in inp.chunks_exact_mut(NIN).zip(elems) {
            pack(x, e, k, trans_diss, want_tangent);
        }
        let bytes: &[u8] = bytemuck::cast_slice(&inp);
        let out_size = (NOUT * elems.len() * 8) as u64;
        let mk = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let ibuf = mk(
            "planar in",
            bytes.len() as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        let obuf = mk(
            "planar out",
            out_size,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let staging = mk(
            "planar staging",
            out_size,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        self.queue.write_buffer(&ibuf, 0, bytes);
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("planar"),
            layout: &self.bgl,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: ibuf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: obuf.as_entire_binding(),
                },
            ],
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(elems.len().div_ceil(64) as u32, 1, 1);
        }
        enc.copy_buffer_to_buffer(&obuf, 0, &staging, 0, out_size);
        crate::gpu::driver::submit(&self.queue, enc.finish());
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        crate::gpu::driver::wait(&self.device)?;
        rx.recv()
            .map_err(|e| GpuError::Kernel(e.to_string()))?
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        let out: &[f64] = bytemuck::cast_slice(&view);
        let evals = out
            .chunks_exact(NOUT)
            .map(|o| PElementEval {
                r: PElemVec::from_column_slice(&o[..NDOF_P]),
                scale: PElemVec::from_column_slice(&o[NDOF_P..2 * NDOF_P]),
                k: PElemMat::from_row_slice(&o[2 * NDOF_P..]),
            })
            .collect();
        drop(view);
        staging.unmap();
        Ok(evals)
    }
}

/// Writes one element's inputs in the shader's layout.
fn pack(x: &mut [f64], e: &PlanarInput, k: &StepConsts, trans: bool, tangent: bool) {
    let d = &e.data;
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    x[0] = d.h;
    x[1] = d.a_rho;
    x[2] = d.i_s;
    x[3] = d.i_amax;
    x[4..7].copy_from_slice(d.c.as_slice());
    x[7..10].copy_from_slice(d.eps0.as_slice());
    x[10..12].copy_from_slice(&d.kappa);
    x[12] = flag(d.rot_free[0]);
    x[13] = flag(d.rot_free[1]);
    let c = &e.st.cfg;
    let v2 = [
        c.r[0], c.r[1], c.d[0][0], c.d[0][1], c.d[1][0], c.d[1][1], e.st.v[0], e.st.v[1],
        e.st.vs[0], e.st.vs[1],
    ];
    for (j, v) in v2.iter().enumerate() {
        x[14 + 2 * j] = v.x;
        x[15 + 2 * j] = v.y;
    }
    x[34..37].copy_from_slice(e.eps_n.as_slice());
    x[37..47].copy_from_slice(e.inc.to_local().as_slice());
    x[47] = e.s.beta_gamma;
    x[48] = e.s.beta_omega;
    x[49] = e.s.c_v;
    x[50] = e.s.c_nu;
    x[51] = k.dt;
    x[52] = flag(k.scheme.stress_rule() == StressRule::MidpointStrain);
    x[53] = flag(trans);
    x[54] = flag(tangent);
}
