//! Adapter and device acquisition (kept apart from the kernels so tests can inject a
//! context), whether the adapter is a software rasterizer, and the on-disk pipeline cache.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::shaders::{shader_precision, CACHE_KEYED};
use super::GpuError;

pub use super::shaders::Precision;

/// A headless device and queue on one adapter.
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What wgpu reports about the adapter.
    pub info: wgpu::AdapterInfo,
    /// Precision of the kernels on this device.
    pub precision: Precision,
    /// The device limits (the adapter's own, requested in full).
    pub limits: wgpu::Limits,
    /// Compiled-pipeline cache, where the adapter offers `PIPELINE_CACHE` and a cache
    /// folder is known (see [`pipeline_cache_dir`]).
    cache: Option<Arc<CacheFile>>,
}

/// A wgpu pipeline cache and the file it is loaded from and saved to.
struct CacheFile {
    cache: wgpu::PipelineCache,
    path: PathBuf,
    /// Size of the data last read or written (saved again only when it changed).
    saved: Mutex<usize>,
}

/// The per-user folder of the compiled-pipeline cache: `$COSSERAT_CACHE_DIR`, else
/// `$XDG_CACHE_HOME/cosserat`, else `$HOME/.cache/cosserat`; `None` (no cache) when
/// `COSSERAT_NO_PIPELINE_CACHE` is set or no such variable is. Never an output folder.
pub fn pipeline_cache_dir() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if var("COSSERAT_NO_PIPELINE_CACHE").is_some() {
        return None;
    }
    var("COSSERAT_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("cosserat")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("cosserat")))
}

/// FNV-1a of the crate's shader sources and version: a cache file per shader revision.
fn shader_hash() -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for src in CACHE_KEYED.into_iter().chain([env!("CARGO_PKG_VERSION")]) {
        for b in src.bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// Writes `data` to `path` atomically (a temporary file in the same folder, renamed).
fn write_atomic(path: &Path, data: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let tmp = dir.join(format!(
        ".{}.{}.tmp",
        path.file_name().and_then(|n| n.to_str()).unwrap_or("cache"),
        std::process::id()
    ));
    std::fs::write(&tmp, data)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

fn adapter_line(info: &wgpu::AdapterInfo) -> String {
    format!("{} [{:?}, {:?}]", info.name, info.backend, info.device_type)
}

/// The order in which adapters are preferred (smaller first): adapters with `SHADER_F64`
/// first, then discrete, integrated, virtual, other and software (CPU) adapters. Used by
/// [`GpuContext::new`] and by `cosserat gpu` ([`super::inventory::auto_choice`]).
pub(crate) fn adapter_rank(f64: bool, t: wgpu::DeviceType) -> (bool, u8) {
    let t = match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    (!f64, t)
}

/// `COSSERAT_GPU_NO_F64` (any value) treats every adapter as one without f64: the f32 path
/// and the refusals that depend on it can be exercised on any adapter.
pub(crate) fn env_disables_f64() -> bool {
    std::env::var_os("COSSERAT_GPU_NO_F64").is_some()
}

impl GpuContext {
    /// Opens a device. `filter` picks the first adapter whose name contains it
    /// (case-insensitive); without it, adapters with `SHADER_F64` are preferred, then
    /// discrete over integrated over software. The backends come from `WGPU_BACKEND`
    /// (e.g. `vulkan`, `gl`) when set, else all.
    ///
    /// Compiled pipelines are cached in [`pipeline_cache_dir`] where the adapter supports
    /// it.
    pub fn new(filter: Option<&str>) -> Result<Self, GpuError> {
        Self::with_cache_dir(filter, pipeline_cache_dir())
    }

    /// As [`Self::new`], with the pipeline cache kept in `cache_dir` (`None`: no cache).
    pub fn with_cache_dir(
        filter: Option<&str>,
        cache_dir: Option<PathBuf>,
    ) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(filter, cache_dir))
    }

    async fn new_async(filter: Option<&str>, cache_dir: Option<PathBuf>) -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let mut adapters = instance.enumerate_adapters(wgpu::Backends::all()).await;
        let available: Vec<String> = adapters
            .iter()
            .map(|a| adapter_line(&a.get_info()))
            .collect();
        if let Some(f) = filter {
            let f = f.to_lowercase();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&f));
        }
        adapters.sort_by_key(|a| {
            let f64 = a.features().contains(wgpu::Features::SHADER_F64) && !env_disables_f64();
            adapter_rank(f64, a.get_info().device_type)
        });
        let Some(adapter) = adapters.into_iter().next() else {
            return Err(GpuError::NoAdapter {
                filter: filter.map(str::to_string),
                available,
            });
        };
        let info = adapter.get_info();
        let f64 = adapter.features().contains(wgpu::Features::SHADER_F64) && !env_disables_f64();
        let cache_path = cache_dir
            .filter(|_| adapter.features().contains(wgpu::Features::PIPELINE_CACHE))
            .and_then(|dir| {
                let key = wgpu::util::pipeline_cache_key(&info)?;
                Some(dir.join(format!("{key}_{:016x}.bin", shader_hash())))
            });
        let mut features = wgpu::Features::empty();
        if f64 {
            features |= wgpu::Features::SHADER_F64;
        }
        if cache_path.is_some() {
            features |= wgpu::Features::PIPELINE_CACHE;
        }
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("cosserat"),
                required_features: features,
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device {
                adapter: adapter_line(&info),
                reason: e.to_string(),
            })?;
        let cache = cache_path.map(|path| {
            let data = std::fs::read(&path).ok();
            // SAFETY: `data` is what `save_pipeline_cache` wrote from `get_data` for an
            // adapter with the same `pipeline_cache_key` (the file name); wgpu validates its
            // header (adapter, driver, size) and, with `fallback`, starts empty when the
            // data does not fit.
            let cache = unsafe {
                device.create_pipeline_cache(&wgpu::PipelineCacheDescriptor {
                    label: Some("cosserat"),
                    data: data.as_deref(),
                    fallback: true,
                })
            };
            Arc::new(CacheFile {
                cache,
                path,
                saved: Mutex::new(data.map_or(0, |d| d.len())),
            })
        });
        Ok(Self {
            device,
            queue,
            info,
            precision: if f64 { Precision::F64 } else { Precision::F32 },
            limits,
            cache,
        })
    }

    /// True for a software adapter (wgpu's `DeviceType::Cpu`: lavapipe/llvmpipe, WARP,
    /// SwiftShader), which runs the kernels on the host's cores and is slower than the
    /// CPU path: `--backend auto` must not pick it.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The compiled-pipeline cache to pass to pipeline creation (`None` without one).
    pub fn pipeline_cache(&self) -> Option<&wgpu::PipelineCache> {
        self.cache.as_ref().map(|c| &c.cache)
    }

    /// The file the pipeline cache is kept in (`None` without a cache).
    pub fn pipeline_cache_path(&self) -> Option<&Path> {
        self.cache.as_ref().map(|c| c.path.as_path())
    }

    /// Writes the pipeline cache to its file (atomically) when its data grew or changed
    /// size since it was read or last written. Best effort: a cache that cannot be
    /// written only means the next process compiles again, so errors are ignored.
    pub fn save_pipeline_cache(&self) {
        let Some(c) = &self.cache else { return };
        let Some(data) = c.cache.get_data() else {
            return;
        };
        let mut saved = c.saved.lock().unwrap_or_else(|p| p.into_inner());
        if data.len() != *saved && write_atomic(&c.path, &data).is_ok() {
            *saved = data.len();
        }
    }

    /// The same device, kernels forced to `precision` (f32 on an f64 adapter measures the
    /// fallback's error; f64 on an adapter without `SHADER_F64` fails at pipeline creation).
    pub fn with_precision(&self, precision: Precision) -> Self {
        Self {
            device: self.device.clone(),
            queue: self.queue.clone(),
            info: self.info.clone(),
            precision,
            limits: self.limits.clone(),
            cache: self.cache.clone(),
        }
    }

    /// True when the kernels run in f64.
    pub fn is_f64(&self) -> bool {
        self.precision == Precision::F64
    }

    /// One line naming the adapter, backend, device type and precision, e.g.
    /// `llvmpipe (LLVM 15.0.6, 256 bits) [Vulkan, Cpu], f64`.
    pub fn describe(&self) -> String {
        let p = match self.precision {
            Precision::F64 => "f64",
            Precision::F32 => "f32 (no SHADER_F64)",
        };
        format!("{}, {p}", adapter_line(&self.info))
    }
}

/// A compute pipeline of `src` (entry point `main`, layout from the shader) in the
/// context's precision, through the pipeline cache.
pub(crate) fn compute_pipeline(ctx: &GpuContext, label: &str, src: &str) -> wgpu::ComputePipeline {
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(shader_precision(src, ctx.precision).into()),
        });
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: ctx.pipeline_cache(),
        })
}

/// A bind group of `pipeline`'s group 0 with `buffers` at bindings 0, 1, ….
pub(crate) fn make_bind_group(
    device: &wgpu::Device,
    pipeline: &wgpu::ComputePipeline,
    label: &str,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}
