//! The element kernel on the GPU: three pipelines built once from `shaders/element.wgsl`
//! (the residual pass, one invocation per element; for the elements that want a tangent,
//! the tangent prep pass, two invocations per element, and the tangent block pass, four), host mirrors of the struct-of-arrays buffers,
//! upload of what changed, one dispatch, readback of what is needed (residual and scales
//! only, or everything with the tangent). The model behind the split is in docs/gpu.md,
//! "Kernels".

use std::time::Instant;

use nalgebra::Vector6;

use super::context::{GpuContext, Precision};
use super::layout::*;
use super::upload::{Block, MirrorRows, Scatter};
use super::GpuError;
use crate::element::{
    ElemMat, ElemVec, ElementData, ElementEval, ElementState, FrozenScalars, Increment, StepConsts,
    NDOF,
};
use crate::integrator::params::Scheme;

pub use super::shaders::ELEMENT_WGSL;
use super::shaders::{real_width, shader_precision};

/// The shader text for a precision: the f32 variant rewrites `Real` and the two constants
/// that do not fit an f32.
pub fn shader_source(p: Precision) -> String {
    shader_precision(ELEMENT_WGSL, p)
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
    /// Host time splitting the read-back assembled buffer into per-member systems.
    pub unpack_s: f64,
    /// Dispatches.
    pub dispatches: u64,
    /// Bytes uploaded.
    pub bytes_up: u64,
    /// Bytes read back.
    pub bytes_down: u64,
    /// Host → device copies (`write_buffer` calls) of the uploads: two per dispatch that
    /// uploads kernel inputs (`gpu::upload`), plus the device solver's operation
    /// words and read-back list when they change.
    pub copies: u64,
    /// Device → host copy commands of the read-backs.
    pub readback_copies: u64,
    /// Element slots dispatched to the tangent pass (four invocations each), summed over
    /// dispatches: the tangent work done (every slot runs the residual pass).
    pub tangent_elements: u64,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    want_tangent: u32,
    mode: u32,
    n_tan: u32,
    per_member: u32,
    /// 1: the advance pass writes records only (`encode_advance`'s `dry`).
    dry: u32,
    pad: [u32; 2],
}

/// The uses of the element kernel's parameters and slot list within one submission
/// (each has its own sources: [`ElementKernel::stage`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Use {
    /// The residual and tangent passes.
    Main = 0,
    /// The advance pass.
    Advance = 1,
    /// The record pass (a dry advance).
    Records = 2,
}

/// Number of [`Use`]s.
const USES: usize = 3;

/// Which element slots the tangent pass evaluates.
#[derive(Clone, Copy, Debug)]
pub(crate) enum TangentSlots<'a> {
    /// None: the residual pass alone runs (no tangent work at all).
    None,
    /// Every slot (the inactive ones return at once).
    All,
    /// These slots.
    List(&'a [u32]),
}

/// A batch of `capacity` element slots on the GPU.
pub struct ElementKernel {
    cap: usize,
    precision: Precision,
    device: wgpu::Device,
    queue: wgpu::Queue,
    residual_pipeline: wgpu::ComputePipeline,
    prep_pipeline: wgpu::ComputePipeline,
    tangent_pipeline: wgpu::ComputePipeline,
    advance_pipeline: wgpu::ComputePipeline,
    record_pipeline: wgpu::ComputePipeline,
    /// The intermediate buffer (residual → tangent passes; advance → record passes).
    tmid: wgpu::Buffer,
    /// Mappable twin of [`Self::tmid`], created by the first [`Self::advance`].
    adv_staging: Option<wgpu::Buffer>,
    bind_group: wgpu::BindGroup,
    bufs: [wgpu::Buffer; 4],
    params: wgpu::Buffer,
    /// Element slots of the tangent, advance or record pass (u32 each).
    tan_list: wgpu::Buffer,
    /// Each [`Use`]'s parameters and slot list, at its own place in these sources, with
    /// the host's copy of what was written there: a pass copies its use's into
    /// [`Self::params`] and [`Self::tan_list`] in command order, so the advance, the
    /// iterations and the records of a dispatch share one submission.
    param_src: wgpu::Buffer,
    list_src: wgpu::Buffer,
    staged: [(Option<Params>, Vec<u32>); USES],
    /// Mappable twin of the output buffer and host copy of the output, created by the
    /// first [`Self::run`] (the batch path reads assembled systems instead and never
    /// allocates them).
    staging: Option<wgpu::Buffer>,
    /// Host mirrors (f64) of the element, state and iteration buffers, slot-major (field
    /// `f` of slot `i` at `i · FIELDS[b] + f`; the device's are field-major, the upload
    /// scatter transposes).
    host: [Vec<f64>; 3],
    /// Per buffer and slot: the slot's fields changed since the last upload (only the
    /// changed slots' ranges are uploaded).
    dirty: [Vec<bool>; 3],
    /// Per slot: the device advanced its state, so the host mirror is stale and the next
    /// state written there goes up whatever it is (a flag, not a mark in the mirror: the
    /// mirror's rows are far apart, the flags are not).
    state_stale: Vec<bool>,
    /// Whether any [`Self::dirty`] flag may be set (a dispatch of device steps and every
    /// iteration after a submission's first skip scanning them).
    maybe_dirty: bool,
    /// First iteration field uploaded from the host: [`I_X`], or [`I_S`] when a pass
    /// before the element pass writes the increments on the device
    /// ([`crate::gpu::Assembler`] gathers them from per-node increments).
    iter_from: usize,
    /// Clean slots between two changed ones that state uploads re-send
    /// ([`Self::set_state_gap`]).
    state_gap: usize,
    out: Vec<f64>,
    /// The uploads of the next dispatch.
    scatter: Scatter,
    /// Stage timers.
    pub timers: KernelTimers,
}

impl ElementKernel {
    /// Bytes per scalar.
    pub(crate) fn width(p: Precision) -> usize {
        real_width(p)
    }

    /// The largest number of element slots one kernel may hold on this device: the
    /// output buffer (`NO` scalars per slot) must fit one storage binding, and the passes'
    /// one row of workgroups (64 invocations each; the tangent pass runs four such rows).
    pub fn max_capacity(ctx: &GpuContext) -> usize {
        let per = (NO * Self::width(ctx.precision)) as u64;
        let lim = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        let groups = ctx.limits.max_compute_workgroups_per_dimension as u64;
        ((lim / per).min(groups * 64)) as usize
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
            label: Some("element"),
            entries: &[
                storage(0, true),
                // The advance pass writes the states.
                storage(1, false),
                // The residual pass freezes the polish round's scalars, the advance pass
                // a dissipative scheme's next ones.
                storage(2, false),
                storage(3, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(5, false),
                storage(6, true),
            ],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("element"),
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
        let residual_pipeline = pipe("residual_main");
        let prep_pipeline = pipe("tangent_prep_main");
        let tangent_pipeline = pipe("tangent_main");
        let advance_pipeline = pipe("advance_main");
        let record_pipeline = pipe("record_main");
        ctx.save_pipeline_cache();
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
            mk("state", NS, input | wgpu::BufferUsages::COPY_SRC),
            mk("iter", NI, input | wgpu::BufferUsages::COPY_SRC),
            mk(
                "out",
                NO,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            ),
        ];
        let tmid = mk(
            "intermediate",
            NT,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        );
        // The node increments' place until an assembler takes it.
        let placeholder = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scatter placeholder"),
            size: 64,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let scatter = Scatter::new(
            ctx,
            [
                bufs[0].clone(),
                bufs[1].clone(),
                bufs[2].clone(),
                placeholder,
            ],
        );
        let tan_list = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tangent slots"),
            size: 4 * cap as u64,
            usage: input,
            mapped_at_creation: false,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let src_usage = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let param_src = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params by use"),
            size: USES as u64 * std::mem::size_of::<Params>() as u64,
            usage: src_usage,
            mapped_at_creation: false,
        });
        let list_src = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("slot lists by use"),
            size: USES as u64 * 4 * cap as u64,
            usage: src_usage,
            mapped_at_creation: false,
        });
        let entries: Vec<wgpu::BindGroupEntry> = bufs
            .iter()
            .chain([&params, &tmid, &tan_list])
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("element"),
            layout: &bgl,
            entries: &entries,
        });
        Ok(Self {
            cap,
            precision: ctx.precision,
            device,
            queue: ctx.queue.clone(),
            residual_pipeline,
            prep_pipeline,
            tangent_pipeline,
            advance_pipeline,
            record_pipeline,
            tmid,
            adv_staging: None,
            bind_group,
            bufs,
            params,
            tan_list,
            param_src,
            list_src,
            staged: Default::default(),
            staging: None,
            host: [
                vec![0.0; NE * cap],
                vec![0.0; NS * cap],
                vec![0.0; NI * cap],
            ],
            dirty: [vec![true; cap], vec![true; cap], vec![true; cap]],
            state_stale: vec![false; cap],
            maybe_dirty: true,
            iter_from: I_X,
            state_gap: SCATTER_GAP,
            out: Vec::new(),
            scatter,
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
        self.host[buf][i * FIELDS[buf] + f] = x;
    }

    #[inline]
    fn put3(&mut self, buf: usize, f: usize, i: usize, v: &crate::model::Vec3) {
        for c in 0..3 {
            self.put(buf, f + c, i, v[c]);
        }
    }

    /// Sets the point masses carried by element slot `i`'s two ends (after
    /// [`Self::set_element`], which clears them): a node's point mass on one end of one of
    /// its elements ([`crate::element::point_mass`]).
    pub fn set_point_masses(&mut self, i: usize, m: [f64; 2]) {
        self.put(0, E_PMASS, i, m[0]);
        self.put(0, E_PMASS + 1, i, m[1]);
    }

    /// Sets the follower line loads of element slot `i` (after [`Self::set_element`], which
    /// clears them): force and moment per unit length in the element's director frame,
    /// their time tables' factors included ([`crate::element::follower`]).
    pub fn set_follower(&mut self, i: usize, fm: &[f64; 6]) {
        for (c, &x) in fm.iter().enumerate() {
            self.put(0, E_FOLLOW + c, i, x);
        }
        self.dirty[0][i] = true;
        self.maybe_dirty = true;
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
        self.put(0, E_DAMP, i, p.damping);
        self.put(0, E_DRAG, i, p.drag);
        // No point mass unless `set_point_masses` says so (a slot's previous element may
        // have carried one).
        self.put(0, E_PMASS, i, 0.0);
        self.put(0, E_PMASS + 1, i, 0.0);
        for c in 0..6 {
            self.put(0, E_FOLLOW + c, i, 0.0);
        }
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
        self.dirty[0][i] = true;
        self.maybe_dirty = true;
    }

    /// Writes the state at `n` of slot `i` (and its cached strains). The slot is uploaded
    /// again only when its state changed (once per step, not per Newton iteration).
    pub fn set_state(&mut self, i: usize, st: &ElementState, eps_n: &Vector6<f64>) {
        let changed = state_row(&mut self.host[1][i * NS..(i + 1) * NS], st, eps_n);
        self.dirty[1][i] |= changed | std::mem::take(&mut self.state_stale[i]);
        self.maybe_dirty |= self.dirty[1][i];
    }

    /// Writes the increment and frozen scalars of slot `i` and marks it active.
    pub fn set_iter(&mut self, i: usize, inc: &Increment, s: &FrozenScalars) {
        let x = inc.to_local();
        for c in 0..NDOF {
            self.put(2, I_X + c, i, x[c]);
        }
        self.set_scalars(i, s);
        self.dirty[2][i] = true;
        self.maybe_dirty = true;
    }

    /// Writes the frozen scalars of slot `i` and marks it active (its increment is written
    /// on the device, see `gather_increments_on_device`); the slot goes up with the
    /// next dispatch only if that changed something (the scalars change once per staggered
    /// round, not per Newton iteration).
    pub fn set_scalars(&mut self, i: usize, s: &FrozenScalars) {
        self.dirty[2][i] |= scalars_row(&mut self.host[2][i * NI..(i + 1) * NI], s, false);
        self.maybe_dirty |= self.dirty[2][i];
    }

    /// [`Self::set_state`] and [`Self::set_scalars`] for whole members at once, in
    /// parallel (a member's slots are contiguous in the host mirrors): member slot `m`
    /// holds element slots `m·per_slot..(m + 1)·per_slot`; `None` leaves it as it is.
    pub(crate) fn pack_members(&mut self, per_slot: usize, members: &[Option<MemberPack<'_>>]) {
        use rayon::prelude::*;
        if members.iter().all(Option::is_none) {
            return;
        }
        self.maybe_dirty = true;
        let [_, states, iters] = &mut self.host;
        let [_, d_states, d_iters] = &mut self.dirty;
        states
            .par_chunks_mut(per_slot * NS)
            .zip(d_states.par_chunks_mut(per_slot))
            .zip(self.state_stale.par_chunks_mut(per_slot))
            .zip(iters.par_chunks_mut(per_slot * NI))
            .zip(d_iters.par_chunks_mut(per_slot))
            .zip(members.par_iter())
            .for_each(|(((((st, d_st), stale), it), d_it), member)| {
                let Some(m) = member else { return };
                if let Some(states) = m.states {
                    let rows = st.chunks_mut(NS).zip(d_st).zip(stale.iter_mut());
                    for (((row, d), stale), (s, eps)) in rows.zip(states) {
                        *d |= state_row(row, s, eps) | std::mem::take(stale);
                    }
                }
                for ((row, d), s) in it.chunks_mut(NI).zip(d_it).zip(m.scalars) {
                    *d |= scalars_row(row, s, m.consistent);
                }
            });
    }

    /// From now on the increments ([`I_X`] fields) are written by a pass on the device
    /// before the element pass; uploads of the iteration buffer skip them.
    pub(crate) fn gather_increments_on_device(&mut self) {
        self.iter_from = I_S;
    }

    /// The iteration buffer (the increment gather pass writes its [`I_X`] fields).
    pub(crate) fn iter_buffer(&self) -> &wgpu::Buffer {
        &self.bufs[2]
    }

    /// Marks slot `i` inactive (the kernel skips it).
    pub fn set_inactive(&mut self, i: usize) {
        if self.host[2][i * NI + I_ACTIVE] != 0.0 {
            self.put(2, I_ACTIVE, i, 0.0);
            self.dirty[2][i] = true;
            self.maybe_dirty = true;
        }
    }

    /// Marks the iteration rows of element slots `lo..hi` for upload with the next
    /// dispatch (a pass on the device changed their activity: `--solve resident`).
    pub(crate) fn touch_iter(&mut self, lo: usize, hi: usize) {
        self.dirty[2][lo..hi.min(self.cap)].fill(true);
        self.maybe_dirty = true;
    }

    /// Records the uploads queued so far (the kernel's changed slots, one block of slots ×
    /// uploaded fields per run, and whatever [`Self::scatter_mut`] queued) as the next pass of `enc`, ahead of the passes that
    /// read them. At most one such pass per command buffer may carry data: its two copies
    /// run at submission, before every pass of the buffer (the assembler flushes ahead of
    /// its gather pass; the flush in [`Self::encode`] then finds nothing queued).
    pub(crate) fn flush_uploads(&mut self, enc: &mut wgpu::CommandEncoder) {
        // The changed slot runs of the element, state and iteration mirrors (the
        // iteration buffer from its first field that changes per iteration).
        let from = [0, 0, self.iter_from];
        let mut rows = Vec::new();
        let scan = std::mem::take(&mut self.maybe_dirty);
        for b in (0..3).filter(|_| scan) {
            let (nf, f0) = (FIELDS[b], from[b]);
            let block = Block {
                target: b,
                cap: self.cap,
                f0,
                nf: nf - f0,
            };
            let gap = if b == 1 { self.state_gap } else { SCATTER_GAP };
            for (lo, hi) in take_runs_gap(&mut self.dirty[b], gap) {
                rows.push(MirrorRows {
                    block,
                    lo,
                    hi,
                    host: &self.host[b],
                    stride: nf,
                });
            }
        }
        let (bytes, copies) = self.scatter.encode(enc, &rows);
        self.timers.bytes_up += bytes;
        self.timers.copies += copies;
    }

    /// The dispatch's pending uploads (target 3 is the assembler's node increments).
    pub(crate) fn scatter_mut(&mut self) -> &mut Scatter {
        &mut self.scatter
    }

    /// The element output buffer (read by the assembly pass).
    pub(crate) fn output_buffer(&self) -> &wgpu::Buffer {
        &self.bufs[3]
    }

    /// Uploads what changed and records the element passes into `enc` (counted as upload
    /// time): the residual pass over every slot, then, unless `tangent` is
    /// [`TangentSlots::None`], the tangent pass over the listed slots (a changed list goes
    /// up as 4 bytes per slot).
    pub(crate) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        mode: KernelMode,
        tangent: TangentSlots<'_>,
    ) {
        let t0 = Instant::now();
        self.flush_uploads(enc);
        let n_tan = match tangent {
            TangentSlots::None => 0,
            TangentSlots::All => self.cap,
            TangentSlots::List(l) => l.len(),
        };
        let list: Option<Vec<u32>> = match tangent {
            TangentSlots::None => None,
            TangentSlots::All if self.staged[Use::Main as usize].1.len() == self.cap => None,
            TangentSlots::All => Some((0..self.cap as u32).collect()),
            // (Compared before copying: the iterations of a submission list the same.)
            TangentSlots::List(l) if l == self.staged[Use::Main as usize].1.as_slice() => None,
            TangentSlots::List(l) => Some(l.to_vec()),
        };
        let prm = Params {
            n: self.cap as u32,
            want_tangent: (n_tan > 0) as u32,
            mode: match mode {
                KernelMode::Frozen => 0,
                KernelMode::Consistent => 1,
            },
            n_tan: n_tan as u32,
            per_member: 0,
            dry: 0,
            pad: [0; 2],
        };
        self.timers.tangent_elements += n_tan as u64;
        self.stage(enc, Use::Main, prm, list, n_tan);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("element"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.residual_pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(self.cap.div_ceil(64) as u32, 1, 1);
        if n_tan > 0 {
            // 64 listed slots per workgroup (x); one row of workgroups per node (y) in the
            // prep pass, per 9×9 node block in the block pass.
            let x = n_tan.div_ceil(64) as u32;
            pass.set_pipeline(&self.prep_pipeline);
            pass.dispatch_workgroups(x, 2, 1);
            pass.set_pipeline(&self.tangent_pipeline);
            pass.dispatch_workgroups(x, 4, 1);
        }
        drop(pass);
        self.timers.upload_s += t0.elapsed().as_secs_f64();
    }

    /// Writes `use_`'s parameters and (when given) slot list to its sources where they
    /// changed, and records their copies into the bound parameters and the first `n`
    /// entries of the bound slot list.
    fn stage(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        use_: Use,
        prm: Params,
        list: Option<Vec<u32>>,
        n: usize,
    ) {
        let k = use_ as usize;
        let psize = std::mem::size_of::<Params>() as u64;
        let lbytes = 4 * self.cap as u64;
        let same = self.staged[k]
            .0
            .is_some_and(|p| bytemuck::bytes_of(&p) == bytemuck::bytes_of(&prm));
        if !same {
            self.queue
                .write_buffer(&self.param_src, k as u64 * psize, bytemuck::bytes_of(&prm));
            self.staged[k].0 = Some(prm);
        }
        if let Some(list) = list.filter(|l| !l.is_empty()) {
            self.queue.write_buffer(
                &self.list_src,
                k as u64 * lbytes,
                bytemuck::cast_slice(&list),
            );
            self.timers.bytes_up += 4 * list.len() as u64;
            self.staged[k].1 = list;
        }
        enc.copy_buffer_to_buffer(&self.param_src, k as u64 * psize, &self.params, 0, psize);
        if n > 0 {
            enc.copy_buffer_to_buffer(
                &self.list_src,
                k as u64 * lbytes,
                &self.tan_list,
                0,
                4 * n as u64,
            );
        }
    }

    /// Records the step's advance into `enc`: for every element slot of `slots` the state
    /// at `n+1` that its increment (iteration buffer) produces with the scalars of `mode`
    /// — the kinematics of the residual pass, as [`crate::integrator::Simulation`]'s
    /// advance — replaces its state at `n` on the device, and its terms of the invariants
    /// at `n+1` and its dissipation go to the intermediate buffer; with `per_member` > 0
    /// the record pass sums them per member slot of `per_member` element slots (over its
    /// active slots: [`MemberRecord`]). The host mirror of the advanced slots' states is
    /// marked stale, so that the next state the host writes there goes up whatever it is.
    ///
    /// The advance and record passes take their parameters and slot lists from sources
    /// of their own ([`Self::stage`]), so they may share a command buffer with the element
    /// passes. `flush`: with the uploads queued so far (else they go with the next
    /// dispatch's, after this advance). `dry`: the
    /// records only, the state at `n` stays (the record pass then sums every element slot
    /// of a member: the fields of the unlisted ones are cleared first).
    pub(crate) fn encode_advance(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        mode: KernelMode,
        slots: &[u32],
        per_member: usize,
        flush: bool,
        dry: bool,
    ) {
        let t0 = Instant::now();
        if flush {
            self.flush_uploads(enc);
        }
        if dry {
            let w = Self::width(self.precision) as u64;
            let cap = self.cap as u64;
            enc.clear_buffer(
                &self.tmid,
                T_ADV as u64 * cap * w,
                Some(N_ADV as u64 * cap * w),
            );
        }
        let use_ = if dry { Use::Records } else { Use::Advance };
        let list = (slots != self.staged[use_ as usize].1.as_slice()).then(|| slots.to_vec());
        let prm = Params {
            n: self.cap as u32,
            want_tangent: 0,
            mode: match mode {
                KernelMode::Frozen => 0,
                KernelMode::Consistent => 1,
            },
            n_tan: slots.len() as u32,
            per_member: per_member as u32,
            dry: u32::from(dry),
            pad: [0; 2],
        };
        self.stage(enc, use_, prm, list, slots.len());
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("advance"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &self.bind_group, &[]);
        if !slots.is_empty() {
            pass.set_pipeline(&self.advance_pipeline);
            pass.dispatch_workgroups(slots.len().div_ceil(64) as u32, 1, 1);
        }
        if let Some(members) = self.cap.checked_div(per_member) {
            pass.set_pipeline(&self.record_pipeline);
            pass.dispatch_workgroups(members.div_ceil(64).max(1) as u32, 1, 1);
        }
        drop(pass);
        if !dry {
            for &i in slots {
                self.state_stale[i as usize] = true;
            }
        }
        self.timers.upload_s += t0.elapsed().as_secs_f64();
    }

    /// Clean slots between two changed ones up to which state uploads re-send them (0
    /// when the device advances states itself: its copy may be newer than the mirror).
    pub(crate) fn set_state_gap(&mut self, gap: usize) {
        self.state_gap = gap;
    }

    /// [`Self::encode_advance`] of element slots `slots` (frozen scalars, no records) in a
    /// submission of its own, ahead of the next dispatch's; nothing waits for it.
    pub(crate) fn submit_advance(&mut self, slots: &[u32]) {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        self.encode_advance(&mut enc, KernelMode::Frozen, slots, 0, false, false);
        crate::gpu::driver::submit(&self.queue, enc.finish());
    }

    /// The intermediate buffer (the records: [`T_REC`]).
    pub(crate) fn tmid_buffer(&self) -> &wgpu::Buffer {
        &self.tmid
    }

    /// Reads `copies` (buffer, byte offset, byte length) of f64 storage buffers in one
    /// submission and wait, through a staging buffer made for it (rare reads: a member's
    /// state handed back to the host). Counts a dispatch and the bytes read.
    pub(crate) fn read_f64(
        &mut self,
        copies: &[(wgpu::Buffer, u64, u64)],
    ) -> Result<Vec<f64>, GpuError> {
        let down: u64 = copies.iter().map(|c| c.2).sum();
        if down == 0 {
            return Ok(Vec::new());
        }
        let t0 = Instant::now();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("state pull staging"),
            size: down,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let mut at = 0u64;
        for (src, off, len) in copies {
            enc.copy_buffer_to_buffer(src, *off, &staging, at, *len);
            at += len;
        }
        crate::gpu::driver::submit(&self.queue, enc.finish());
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        crate::gpu::driver::wait(&self.device)?;
        rx.recv()
            .map_err(|e| GpuError::Kernel(e.to_string()))?
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        let out = {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError::Kernel(e.to_string()))?;
            bytemuck::pod_collect_to_vec(&view)
        };
        staging.unmap();
        self.timers.bytes_down += down;
        self.timers.readback_copies += copies.len() as u64;
        self.timers.readback_s += t0.elapsed().as_secs_f64();
        Ok(out)
    }

    /// The element states of `n` element slots from [`Self::read_f64`]'s output for
    /// [`Self::state_copies`] of those slots.
    pub(crate) fn states_from(v: &[f64], n: usize) -> Vec<(ElementState, Vector6<f64>)> {
        let at = |f: usize, i: usize| v[f * n + i];
        (0..n).map(|i| element_state(&at, i)).collect()
    }

    /// The copies of [`Self::read_f64`] that read the states of element slots `lo..hi`.
    pub(crate) fn state_copies(&self, lo: usize, hi: usize) -> Vec<(wgpu::Buffer, u64, u64)> {
        let cap = self.cap as u64;
        (0..NS as u64)
            .map(|f| {
                (
                    self.bufs[1].clone(),
                    8 * (f * cap + lo as u64),
                    8 * (hi - lo) as u64,
                )
            })
            .collect()
    }

    /// Copies of the frozen scalars (4 per element slot, field after field) of slots
    /// `lo..hi`: those the iteration buffer holds now, or (`saved`) those the advance pass
    /// kept at the start of the last step on the device ([`T_FS`]).
    pub(crate) fn scalar_copies(
        &self,
        lo: usize,
        hi: usize,
        saved: bool,
    ) -> Vec<(wgpu::Buffer, u64, u64)> {
        let cap = self.cap as u64;
        let (buf, first) = if saved {
            (&self.tmid, T_FS)
        } else {
            (&self.bufs[2], I_S)
        };
        (first as u64..first as u64 + 4)
            .map(|f| (buf.clone(), 8 * (f * cap + lo as u64), 8 * (hi - lo) as u64))
            .collect()
    }

    /// The device the kernel runs on.
    pub(crate) fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue the kernel submits to.
    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// `encode_advance` of every active slot, submitted, with the new states and
    /// the records read back (tests of the advance's arithmetic against the CPU's).
    pub fn advance(&mut self, mode: KernelMode, per_member: usize) -> Result<Advanced, GpuError> {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let slots: Vec<u32> = (0..self.cap)
            .filter(|&i| self.host[2][i * NI + I_ACTIVE] != 0.0)
            .map(|i| i as u32)
            .collect();
        self.encode_advance(&mut enc, mode, &slots, per_member, true, false);
        let w = Self::width(self.precision) as u64;
        let cap = self.cap as u64;
        enc.copy_buffer_to_buffer(&self.bufs[1], 0, &self.tmid, 0, NS as u64 * cap * w);
        let staging = self.adv_staging.get_or_insert_with(|| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("advance staging"),
                size: NT as u64 * cap * w,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        let members = self.cap / per_member.max(1);
        // The states (copied into the intermediate buffer's leading fields, which the
        // advance leaves alone) and the records.
        let ranges = [
            (0, NS as u64 * cap * w),
            (T_REC as u64 * cap * w, N_ADV as u64 * cap * w),
        ];
        let mut out = vec![0.0; NT * self.cap];
        let rb = Readback {
            device: &self.device,
            queue: &self.queue,
            src: &self.tmid,
            staging,
            precision: self.precision,
        };
        rb.run(enc, &ranges, &mut out, &mut self.timers)?;
        let at = |f: usize, i: usize| out[f * self.cap + i];
        let records = (0..members)
            .map(|m| {
                let r: Vec<f64> = (0..N_ADV).map(|k| at(T_REC + k, m)).collect();
                MemberRecord::from_fields(&r)
            })
            .collect();
        let states = (0..self.cap).map(|i| element_state(&at, i)).collect();
        Ok(Advanced { states, records })
    }

    /// Evaluates every active slot and reads the raw element output back. Without the
    /// tangent only the residual, scales and scalars come back.
    pub fn run(&mut self, mode: KernelMode, want_tangent: bool) -> Result<(), GpuError> {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let tangent = if want_tangent {
            TangentSlots::All
        } else {
            TangentSlots::None
        };
        self.encode(&mut enc, mode, tangent);
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
        let staging = self.staging.get_or_insert_with(|| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("staging"),
                size: NO as u64 * cap * w,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        self.out.resize(NO * self.cap, 0.0);
        let rb = Readback {
            device: &self.device,
            queue: &self.queue,
            src: &self.bufs[3],
            staging,
            precision: self.precision,
        };
        rb.run(enc, &ranges, &mut self.out, &mut self.timers)
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

pub use crate::integrator::evaluate::MemberRecord;

/// Element slot `i`'s state and strains from a field-major reader `at(field, slot)`.
fn element_state(at: &dyn Fn(usize, usize) -> f64, i: usize) -> (ElementState, Vector6<f64>) {
    let v = |f: usize| crate::model::Vec3::new(at(f, i), at(f + 1, i), at(f + 2, i));
    let d = |l: usize| {
        crate::model::Mat3::from_columns(&[v(S_D + 9 * l), v(S_D + 9 * l + 3), v(S_D + 9 * l + 6)])
    };
    let st = ElementState {
        cfg: crate::element::strain::Config {
            r: [v(S_R), v(S_R + 3)],
            d: [d(0), d(1)],
        },
        v: [v(S_V), v(S_V + 3)],
        vd: [[v(S_VD), v(S_VD + 3)], [v(S_VD + 6), v(S_VD + 9)]],
    };
    (st, Vector6::from_fn(|k, _| at(S_EPS + k, i)))
}

/// What [`ElementKernel::advance`] read back.
#[derive(Clone, Debug)]
pub struct Advanced {
    /// Per element slot: its state at `n+1` and raw strains there (inactive slots: their
    /// state as it was).
    pub states: Vec<(ElementState, Vector6<f64>)>,
    /// Per member slot: its record.
    pub records: Vec<MemberRecord>,
}

/// Clean slots between two changed ones up to which both go up in one copy: each copy
/// has a fixed cost (a staging allocation and a command) worth a few hundred bytes, and
/// the host mirrors of clean slots are current, so re-sending them is harmless.
const MERGE_GAP: usize = 32;

/// The runs `(lo, hi)` of adjacent indices among `indices` (in any order, repeats
/// allowed): one copy per run of member slots.
pub(crate) fn index_runs(indices: impl IntoIterator<Item = usize>) -> Vec<(usize, usize)> {
    let mut sorted: Vec<usize> = indices.into_iter().collect();
    sorted.sort_unstable();
    sorted.dedup();
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for m in sorted {
        match runs.last_mut() {
            Some(last) if last.1 == m => last.1 = m + 1,
            _ => runs.push((m, m + 1)),
        }
    }
    runs
}

/// The runs `(lo, hi)` of set flags, clearing them; runs closer than [`MERGE_GAP`] are
/// merged.
pub(crate) fn take_runs(flags: &mut [bool]) -> Vec<(usize, usize)> {
    take_runs_gap(flags, MERGE_GAP)
}

/// What [`ElementKernel::pack_members`] writes for one member.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MemberPack<'a> {
    /// The element states at `n` and their strains, when they changed.
    pub states: Option<&'a [(ElementState, Vector6<f64>)]>,
    /// The frozen scalars, per element.
    pub scalars: &'a [FrozenScalars],
    /// Evaluate with the scalars consistent with the increment instead (the inexact
    /// strategy's iterations; the frozen ones are ignored then).
    pub consistent: bool,
}

/// Writes the state at `n` and its cached strains into one slot's row of the state
/// mirror; whether anything changed.
fn state_row(row: &mut [f64], st: &ElementState, eps_n: &Vector6<f64>) -> bool {
    let old: [f64; NS] = std::array::from_fn(|f| row[f]);
    let mut put3 = |f: usize, v: &crate::model::Vec3| row[f..f + 3].copy_from_slice(v.as_slice());
    for l in 0..2 {
        put3(S_R + 3 * l, &st.cfg.r[l]);
        put3(S_V + 3 * l, &st.v[l]);
        for c in 0..3 {
            put3(S_D + 9 * l + 3 * c, &st.cfg.d[l].column(c).into_owned());
        }
        for a in 0..2 {
            put3(S_VD + 6 * l + 3 * a, &st.vd[l][a]);
        }
    }
    row[S_EPS..S_EPS + 6].copy_from_slice(eps_n.as_slice());
    *row != old
}

/// Writes the frozen scalars and the active flag (2: evaluate with the consistent scalars
/// instead) into one slot's row of the iteration mirror; whether anything changed (bit for
/// bit).
fn scalars_row(row: &mut [f64], s: &FrozenScalars, consistent: bool) -> bool {
    const _: () = assert!(
        I_ACTIVE == I_S + 4,
        "the active flag follows the four scalars"
    );
    let active = if consistent { 2.0 } else { 1.0 };
    let vals = [s.beta_gamma, s.beta_omega, s.c_v, s.c_nu, active];
    let dst = &mut row[I_S..=I_ACTIVE];
    let changed = dst
        .iter()
        .zip(&vals)
        .any(|(a, b)| a.to_bits() != b.to_bits());
    if changed {
        dst.copy_from_slice(&vals);
    }
    changed
}

/// Fields per slot of the element, state and iteration buffers.
const FIELDS: [usize; 3] = [NE, NS, NI];

/// Clean slots between two changed ones up to which a scatter run re-sends them: a run
/// costs 32 bytes of description.
pub(crate) const SCATTER_GAP: usize = 2;

/// [`take_runs`] merging runs at most `gap` apart.
pub(crate) fn take_runs_gap(flags: &mut [bool], gap: usize) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i < flags.len() {
        if flags[i] {
            let lo = i;
            while i < flags.len() && flags[i] {
                flags[i] = false;
                i += 1;
            }
            match runs.last_mut() {
                Some(last) if lo - last.1 <= gap => last.1 = i,
                _ => runs.push((lo, i)),
            }
        } else {
            i += 1;
        }
    }
    runs
}

/// Submission of an encoded command buffer followed by the readback of byte ranges of one
/// storage buffer through a staging buffer of the same layout.
pub(crate) struct Readback<'a> {
    pub device: &'a wgpu::Device,
    pub queue: &'a wgpu::Queue,
    /// Buffer the ranges are read from.
    pub src: &'a wgpu::Buffer,
    /// Mappable twin of `src`.
    pub staging: &'a wgpu::Buffer,
    pub precision: Precision,
}

impl Readback<'_> {
    /// Copies `ranges` (byte offset, length) of `src` at the end of `enc`, submits, waits,
    /// and converts them into `dst` (scalar index = byte offset / width). Counts the
    /// dispatch, its kernel and readback time and the bytes read.
    pub fn run(
        &self,
        mut enc: wgpu::CommandEncoder,
        ranges: &[(u64, u64)],
        dst: &mut [f64],
        timers: &mut KernelTimers,
    ) -> Result<(), GpuError> {
        let t1 = Instant::now();
        let w = ElementKernel::width(self.precision) as u64;
        for &(off, len) in ranges {
            enc.copy_buffer_to_buffer(self.src, off, self.staging, off, len);
        }
        timers.readback_copies += ranges.len() as u64;
        crate::gpu::driver::submit(self.queue, enc.finish());
        // One mapping covering every copied range (a buffer admits one pending map).
        let end = ranges.iter().map(|&(o, l)| o + l).max().unwrap_or(0);
        if end == 0 {
            // Nothing to read (an empty mapping is an error in wgpu).
            timers.kernel_s += t1.elapsed().as_secs_f64();
            timers.dispatches += 1;
            return Ok(());
        }
        let (tx, rx) = std::sync::mpsc::channel();
        self.staging
            .slice(0..end)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        crate::gpu::driver::wait(self.device)?;
        rx.recv()
            .map_err(|e| GpuError::Kernel(e.to_string()))?
            .map_err(|e| GpuError::Kernel(e.to_string()))?;
        let t2 = Instant::now();
        for &(off, len) in ranges {
            let view = self
                .staging
                .get_mapped_range(off..off + len)
                .map_err(|e| GpuError::Kernel(e.to_string()))?;
            let out = &mut dst[(off / w) as usize..((off + len) / w) as usize];
            match self.precision {
                Precision::F64 => out.copy_from_slice(bytemuck::cast_slice(&view)),
                Precision::F32 => {
                    let src: &[f32] = bytemuck::cast_slice(&view);
                    for (d, s) in out.iter_mut().zip(src) {
                        *d = *s as f64;
                    }
                }
            }
            timers.bytes_down += len;
        }
        self.staging.unmap();
        timers.kernel_s += (t2 - t1).as_secs_f64();
        timers.readback_s += t2.elapsed().as_secs_f64();
        timers.dispatches += 1;
        Ok(())
    }
}
