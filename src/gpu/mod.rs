//! Headless GPU evaluation of the element kernel (wgpu compute, WGSL twin of
//! [`crate::element`]).
//!
//! * [`shaders`]: the WGSL sources of every pass and their f32 rewriting; below all
//!   other modules here.
//! * [`context`]: adapter choice (`--adapter` substring, `WGPU_BACKEND`), device with the
//!   adapter's own limits, `SHADER_F64` detection, a one-line adapter description, whether
//!   the adapter is a software rasterizer, the per-user compiled-pipeline cache.
//! * [`layout`]: the struct-of-arrays buffer layout (field offsets), twin of the constants
//!   at the top of `shaders/element.wgsl`.
//! * [`kernel`]: the element passes (residual; tangent prep and 9×9 tangent blocks for the
//!   elements that want a tangent) built once, host mirrors of the buffers, upload of the
//!   changed slots, dispatch and readback of a batch of elements.
//! * [`assemble`]: the assembly pass run right after the element pass (node blocks,
//!   residuals, off-diagonal blocks, per-member row scales), so that only assembled
//!   systems are read back.
//! * [`blocktri`]: batched block-tridiagonal LU and solve of the assembled systems on the
//!   device (CPU twin: [`crate::linsolve::batched`]).
//! * `upload`: a dispatch's uploads (changed mirror rows, node increments) in two copies
//!   and a scatter pass; `compact`: the solver's reports and iterates packed by a pass
//!   and read back in one copy.
//! * [`driver`]: every submission and wait, with the calling thread's CPU time inside
//!   them accounted (the driver's share of the host thread).
//! * [`inventory`]: what `cosserat gpu` reports: the adapters, the `--backend auto` choice,
//!   and why a host's NVIDIA GPU is not an adapter.
//! * [`reach`]: the routes round a headless host's missing Vulkan adapter (an ICD file
//!   naming the driver's EGL library, then its GLX library by path), tried at start-up.
//!
//! f64 is used whenever the adapter offers `SHADER_F64`; otherwise the same shader runs in
//! f32 ([`Precision::F32`]) and its error is measured by `tests/gpu_kernel.rs` (docs/gpu.md,
//! "Kernels"); callers are told which precision they got, never silently.

pub mod assemble;
pub mod blocktri;
pub(crate) mod compact;
pub mod context;
pub mod driver;
pub mod inventory;
pub mod kernel;
pub mod layout;
pub mod planar;
pub mod reach;
pub mod shaders;
pub(crate) mod upload;

pub use assemble::{Around, Assembler};
pub use blocktri::BlockTriSolver;
pub use context::{GpuContext, Precision};
pub use kernel::ElementKernel;

/// Everything that can go wrong on the GPU path.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter matches (or none exists at all).
    #[error("no GPU adapter{}: available adapters: [{}]", match .filter { Some(f) => format!(" matching `{f}`"), None => String::new() }, .available.join("; "))]
    NoAdapter {
        /// The `--adapter` substring, if any.
        filter: Option<String>,
        /// Names of the adapters that exist.
        available: Vec<String>,
    },
    /// The device could not be created.
    #[error("cannot create a device on {adapter}: {reason}")]
    Device {
        /// Adapter description.
        adapter: String,
        /// wgpu's message.
        reason: String,
    },
    /// A validation, mapping or polling error while running a kernel.
    #[error("GPU kernel failed: {0}")]
    Kernel(String),
    /// A member has more elements or nodes than a batch slot holds.
    #[error("a member of {elements} elements and {nodes} nodes does not fit a batch slot of {per_slot} elements and {nodes_per_slot} nodes")]
    SlotTooSmall {
        /// The member's elements.
        elements: usize,
        /// The member's nodes.
        nodes: usize,
        /// Elements per slot.
        per_slot: usize,
        /// Nodes per slot.
        nodes_per_slot: usize,
    },
    /// The requested batch does not fit the adapter's buffer limits.
    #[error(
        "batch of {elements} elements exceeds the adapter's storage-buffer limit ({max} elements)"
    )]
    TooLarge {
        /// Elements requested.
        elements: usize,
        /// Largest batch that fits.
        max: usize,
    },
    /// The scene uses a feature the GPU kernels do not implement.
    #[error("the GPU path does not support {feature}; run it with --backend cpu")]
    Unsupported {
        /// The feature, by name ([`crate::model::Model::gpu_unsupported`]).
        feature: String,
    },
}

/// Whether tests that need an adapter must fail when none exists (`COSSERAT_REQUIRE_GPU`
/// set, as in CI) rather than print `skipped: no adapter`.
pub fn gpu_required() -> bool {
    std::env::var_os("COSSERAT_REQUIRE_GPU").is_some()
}
