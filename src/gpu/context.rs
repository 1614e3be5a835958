//! Adapter and device acquisition (kept apart from the kernels so tests can inject a
//! context).

use super::GpuError;

/// Floating-point precision the kernels run in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// `SHADER_F64`: the CPU kernel's arithmetic to round-off.
    F64,
    /// Fallback on adapters without f64 (error bound in README, "GPU precision").
    F32,
}

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
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

fn adapter_line(info: &wgpu::AdapterInfo) -> String {
    format!("{} [{:?}, {:?}]", info.name, info.backend, info.device_type)
}

fn type_rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

impl GpuContext {
    /// Opens a device. `filter` picks the first adapter whose name contains it
    /// (case-insensitive); without it, adapters with `SHADER_F64` are preferred, then
    /// discrete over integrated over software. The backends come from `WGPU_BACKEND`
    /// (e.g. `vulkan`, `gl`) when set, else all.
    pub fn new(filter: Option<&str>) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(filter))
    }

    async fn new_async(filter: Option<&str>) -> Result<Self, GpuError> {
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
            let f64 = a.features().contains(wgpu::Features::SHADER_F64);
            (!f64, type_rank(a.get_info().device_type))
        });
        let Some(adapter) = adapters.into_iter().next() else {
            return Err(GpuError::NoAdapter {
                filter: filter.map(str::to_string),
                available,
            });
        };
        let info = adapter.get_info();
        let f64 = adapter.features().contains(wgpu::Features::SHADER_F64);
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("cosserat"),
                required_features: if f64 {
                    wgpu::Features::SHADER_F64
                } else {
                    wgpu::Features::empty()
                },
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device {
                adapter: adapter_line(&info),
                reason: e.to_string(),
            })?;
        Ok(Self {
            device,
            queue,
            info,
            precision: if f64 { Precision::F64 } else { Precision::F32 },
            limits,
        })
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
        }
    }

    /// Whether the adapter is a software rasterizer running on the CPU's own cores
    /// (lavapipe, llvmpipe, WARP, SwiftShader: wgpu reports `DeviceType::Cpu`).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
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
