//! The element kernel on the GPU: pipeline built once, host mirrors of the four
//! struct-of-arrays buffers, upload of what changed, one dispatch, readback of what is
//! needed (residual and scales only, or everything with the tangent).

use std::time::Instant;

use nalgebra::Vector6;

use super::context::{GpuContext, Precision};
use super::layout::*;
use super::GpuError;
use crate::element::{
    ElemMat, ElemVec, ElementData, ElementEval, ElementState, FrozenScalars, Increment, StepConsts,
    NDOF,
};
use crate::integrator::params::Scheme;

/// The WGSL source (f64 version).
pub const ELEMENT_WGSL: &str = include_str!("../../shaders/element.wgsl");

/// The shader text for a precision: the f32 variant rewrites `Real` and the two constants
/// that do not fit an f32.
pub fn shader_source(p: Precision) -> String {
    match p {
        Precision::F64 => ELEMENT_WGSL.to_string(),
        Precision::F32 => ELEMENT_WGSL
            .replace("alias Real = f64;", "alias Real = f32;")
            .replace("const TINY: Real = 1e-300;", "const TINY: Real = 1e-30;")
            .replace(
                "const CNU_TOL: Real = 1e-15;",
                "const CNU_TOL: Real = 1e-7;",
            ),
    }
}

/// How the kernel obtains the dissipation scalars.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelMode {
    /// The frozen scalars of the iteration buffer (staggered strategy, EM).
    Frozen,
    /// The scalars consistent with the increment (DESIGN §4 local law, incl. the EDMC-2
    /// 4×4 solve), as [`crate::element::consistent_scalars`].
    Consistent,
}

/// Accumulated time and traffic of the kernel (per-stage counters).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct KernelTimers {
    /// Host → device copies (incl. f64 → f32 conversion when needed).
    pub upload_s: f64,
    /// Submit + wait for the dispatch and the copy into the staging buffer.
    pub kernel_s: f64,
    /// Map + copy out of the staging buffer.
    pub readback_s: f64,
    /// Dispatches.
    pub dispatches: u64,
    /// Bytes uploaded.
    pub bytes_up: u64,
    /// Bytes read back.
    pub bytes_down: u64,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    want_tangent: u32,
    mode: u32,
    pad: u32,
}

/// A batch of `capacity` element slots on the GPU.
pub struct ElementKernel {
    cap: usize,
    precision: Precision,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    bufs: [wgpu::Buffer; 4],
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// Host mirrors (f64) of the element, state and iteration buffers.
    host: [Vec<f64>; 3],
    dirty: [bool; 3],
    out: Vec<f64>,
    /// Stage timers.
    pub timers: KernelTimers,
}

impl ElementKernel {
    /// Bytes per scalar.
    fn width(p: Precision) -> usize {
        match p {
            Precision::F64 => 8,
            Precision::F32 => 4,
        }
    }

    /// The largest number of element slots one kernel may hold on this device.
    pub fn max_capacity(ctx: &GpuContext) -> usize {
        let per = (NO * Self::width(ctx.precision)) as u64;
        let lim = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        (lim / per) as usize
    }

    /// Builds the pipeline and buffers for `capacity` element slots (all inactive).
    pub fn new(ctx: &GpuContext, capacity: usize) -> Result<Self, GpuError> {
        let max = Self::max_capacity(ctx);
        if capacity > max {
            return Err(GpuError::TooLarge {
                elements: capacity,
                max,
            });
        }
        let cap = capacity.max(1);
        let device = ctx.device.clone();
        let w = Self::width(ctx.precision) as u64;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("element.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader_source(ctx.precision).into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("element"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let mk = |label: &str, fields: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: fields as u64 * cap as u64 * w,
                usage,
                mapped_at_creation: false,
            })
        };
        let input = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let bufs = [
            mk("elem", NE, input),
            mk("state", NS, input),
            mk("iter", NI, input),
            mk(
                "out",
                NO,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            ),
        ];
        let staging = mk(
            "staging",
            NO,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = pipeline.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = bufs
            .iter()
            .chain(std::iter::once(&params))
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("element"),
            layout: &layout,
            entries: &entries,
        });
        Ok(Self {
            cap,
            precision: ctx.precision,
            device,
            queue: ctx.queue.clone(),
            pipeline,
            bind_group,
            bufs,
            params,
            staging,
            host: [
                vec![0.0; NE * cap],
                vec![0.0; NS * cap],
                vec![0.0; NI * cap],
            ],
            dirty: [true; 3],
            out: vec![0.0; NO * cap],
            timers: KernelTimers::default(),
        })
    }

    /// Number of element slots.
    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// Precision the kernel runs in.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    #[inline]
    fn put(&mut self, buf: usize, f: usize, i: usize, x: f64) {
        self.host[buf][f * self.cap + i] = x;
    }

    #[inline]
    fn put3(&mut self, buf: usize, f: usize, i: usize, v: &crate::model::Vec3) {
        for c in 0..3 {
            self.put(buf, f + c, i, v[c]);
        }
    }

    /// Writes the constants of slot `i`: element data, step constants and whether the
    /// translational-dissipation rows exist.
    pub fn set_element(&mut self, i: usize, d: &ElementData, k: &StepConsts, trans_diss: bool) {
        let p = &d.props;
        self.put(0, E_H, i, p.h);
        self.put(0, E_ARHO, i, p.a_rho);
        for a in 0..2 {
            for b in 0..2 {
                self.put(0, E_IRHO + 2 * a + b, i, p.i_rho[(a, b)]);
            }
        }
        self.put3(0, E_CG, i, &p.c_gamma);
        for r in 0..3 {
            for c in 0..3 {
                self.put(0, E_CO + 3 * r + c, i, p.c_omega[(r, c)]);
            }
        }
        for c in 0..6 {
            self.put(0, E_EPS0 + c, i, d.eps0[c]);
        }
        for l in 0..2 {
            self.put(0, E_ROTFREE + l, i, if d.rot_free[l] { 1.0 } else { 0.0 });
        }
        self.put(0, E_DT, i, k.dt);
        self.put(0, E_TRANS, i, if trans_diss { 1.0 } else { 0.0 });
        let (kind, sp) = match k.scheme {
            Scheme::Em => (0.0, [0.0; 4]),
            Scheme::Edmc1 {
                chi_gamma,
                chi_omega,
                chi_v,
                chi_nu,
            } => (1.0, [chi_gamma, chi_omega, chi_v, chi_nu]),
            Scheme::Edmc2 {
                alpha_gv,
                alpha_gn,
                alpha_ov,
                alpha_on,
            } => (2.0, [alpha_gv, alpha_gn, alpha_ov, alpha_on]),
            // `Simulation::set_backend` never attaches these (no GPU kernel).
            Scheme::Midpoint | Scheme::GenAlpha { .. } => {
                unreachable!("scheme {} has no GPU kernel", k.scheme.name())
            }
        };
        self.put(0, E_SCHEME, i, kind);
        for (c, x) in sp.iter().enumerate() {
            self.put(0, E_SP + c, i, *x);
        }
        let dd = if k.scheme.director_dissipation() {
            1.0
        } else {
            0.0
        };
        self.put(0, E_DIRDISS, i, dd);
        self.dirty[0] = true;
    }

    /// Writes the state at `n` of slot `i` (and its cached strains). The state buffer is
    /// uploaded again only when some slot's state changed (once per step, not per Newton
    /// iteration).
    pub fn set_state(&mut self, i: usize, st: &ElementState, eps_n: &Vector6<f64>) {
        let before = self.dirty[1];
        let old: [f64; NS] = std::array::from_fn(|f| self.host[1][f * self.cap + i]);
        self.write_state(i, st, eps_n);
        let changed = (0..NS).any(|f| self.host[1][f * self.cap + i] != old[f]);
        self.dirty[1] = before || changed;
    }

    fn write_state(&mut self, i: usize, st: &ElementState, eps_n: &Vector6<f64>) {
        for l in 0..2 {
            self.put3(1, S_R + 3 * l, i, &st.cfg.r[l]);
            self.put3(1, S_V + 3 * l, i, &st.v[l]);
            for c in 0..3 {
                self.put3(
                    1,
                    S_D + 9 * l + 3 * c,
                    i,
                    &st.cfg.d[l].column(c).into_owned(),
                );
            }
            for a in 0..2 {
                self.put3(1, S_VD + 6 * l + 3 * a, i, &st.vd[l][a]);
            }
        }
        for c in 0..6 {
            self.put(1, S_EPS + c, i, eps_n[c]);
        }
    }

    /// Writes the increment and frozen scalars of slot `i` and marks it active.
    pub fn set_iter(&mut self, i: usize, inc: &Increment, s: &FrozenScalars) {
        let x = inc.to_local();
        for c in 0..NDOF {
            self.put(2, I_X + c, i, x[c]);
        }
        for (c, v) in [s.beta_gamma, s.beta_omega, s.c_v, s.c_nu]
            .iter()
            .enumerate()
        {
            self.put(2, I_S + c, i, *v);
        }
        self.put(2, I_ACTIVE, i, 1.0);
        self.dirty[2] = true;
    }

    /// Marks slot `i` inactive (the kernel skips it).
    pub fn set_inactive(&mut self, i: usize) {
        if self.host[2][I_ACTIVE * self.cap + i] != 0.0 {
            self.put(2, I_ACTIVE, i, 0.0);
            self.dirty[2] = true;
        }
    }

    fn upload(&mut self) {
        for b in 0..3 {
            if !self.dirty[b] {
                continue;
            }
            let bytes = match self.precision {
                Precision::F64 => {
                    self.queue
                        .write_buffer(&self.bufs[b], 0, bytemuck::cast_slice(&self.host[b]));
                    self.host[b].len() * 8
                }
                Precision::F32 => {
                    let v: Vec<f32> = self.host[b].iter().map(|&x| x as f32).collect();
                    self.queue
                        .write_buffer(&self.bufs[b], 0, bytemuck::cast_slice(&v));
                    v.len() * 4
                }
            };
            self.timers.bytes_up += bytes as u64;
            self.dirty[b] = false;
        }
    }

    /// Evaluates every active slot. Without the tangent only the residual, scales and
    /// scalars come back.
    pub fn run(&mut self, mode: KernelMode, want_tangent: bool) -> Result<(), GpuError> {
        let t0 = Instant::now();
        self.upload();
        let prm = Params {
            n: self.cap as u32,
            want_tangent: want_tangent as u32,
            mode: match mode {
                KernelMode::Frozen => 0,
                KernelMode::Consistent => 1,
            },
            pad: 0,
        };
        self.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&prm));
        let t1 = Instant::now();
        let w = Self::width(self.precision) as u64;
        let cap = self.cap as u64;
        // Field-major: the residual and scales are one leading range, the scalars a
        // trailing one; the tangent sits between them.
        let ranges: Vec<(u64, u64)> = if want_tangent {
            vec![(0, NO as u64 * cap * w)]
        } else {
            vec![
                (0, O_K as u64 * cap * w),
                (O_S as u64 * cap * w, 4 * cap * w),
            ]
        };
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("element"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(self.cap.div_ceil(64) as u32, 1, 1);
        }
        for &(off, len) in &ranges {
            enc.copy_buffer_to_buffer(&self.bufs[3], off, &self.staging, off, len);
        }
        self.queue.submit(Some(enc.finish()));
        // One mapping covering every copied range (a buffer admits one pending map).
        let end = ranges.iter().map(|&(o, l)| o + l).max().unwrap_or(0);
        let (tx, rx) = std::sync::mpsc::channel();
        self.staging
            .slice(0..end)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Kernel(e.to_string()))?
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        let t2 = Instant::now();
        for &(off, len) in &ranges {
            let view = self
                .staging
                .get_mapped_range(off..off + len)
                .map_err(|e| GpuError::Kernel(e.to_string()))?;
            let dst = &mut self.out[(off / w) as usize..((off + len) / w) as usize];
            match self.precision {
                Precision::F64 => dst.copy_from_slice(bytemuck::cast_slice(&view)),
                Precision::F32 => {
                    let src: &[f32] = bytemuck::cast_slice(&view);
                    for (d, s) in dst.iter_mut().zip(src) {
                        *d = *s as f64;
                    }
                }
            }
            self.timers.bytes_down += len;
        }
        self.staging.unmap();
        let t3 = Instant::now();
        self.timers.upload_s += (t1 - t0).as_secs_f64();
        self.timers.kernel_s += (t2 - t1).as_secs_f64();
        self.timers.readback_s += (t3 - t2).as_secs_f64();
        self.timers.dispatches += 1;
        Ok(())
    }

    #[inline]
    fn get(&self, f: usize, i: usize) -> f64 {
        self.out[f * self.cap + i]
    }

    /// Result of slot `i` from the last [`Self::run`] (the tangent is zero unless it was
    /// requested).
    pub fn eval(&self, i: usize, with_tangent: bool) -> ElementEval {
        let r = ElemVec::from_fn(|a, _| self.get(O_R + a, i));
        let scale = ElemVec::from_fn(|a, _| self.get(O_SC + a, i));
        let k = if with_tangent {
            ElemMat::from_fn(|a, b| self.get(O_K + NDOF * a + b, i))
        } else {
            ElemMat::zeros()
        };
        ElementEval { r, scale, k }
    }

    /// The dissipation scalars slot `i` used in the last run (its consistent scalars in
    /// [`KernelMode::Consistent`]).
    pub fn scalars(&self, i: usize) -> FrozenScalars {
        FrozenScalars {
            beta_gamma: self.get(O_S, i),
            beta_omega: self.get(O_S + 1, i),
            c_v: self.get(O_S + 2, i),
            c_nu: self.get(O_S + 3, i),
        }
    }
}
