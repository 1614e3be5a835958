//! What `cosserat gpu` reports: every adapter wgpu sees, which one `--backend auto` would
//! pick and why, and, on a host with NVIDIA device nodes but no NVIDIA adapter, what is
//! missing and how to fix it.
//!
//! The host facts (device nodes, kernel modules, Vulkan ICD files) are read below a root
//! directory, `/` normally; `COSSERAT_GPU_HOST_ROOT` points it elsewhere, so that the
//! diagnosis can be exercised with fake device nodes (`tests/gpu_inventory.rs`).

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::context::{adapter_rank, env_disables_f64};

/// PCI vendor id of NVIDIA.
pub(crate) const NVIDIA_VENDOR: u32 = 0x10de;

/// One adapter as wgpu reports it, with what the batch path needs of it.
#[derive(Clone, Debug, Serialize)]
pub struct AdapterReport {
    /// Adapter name (e.g. "NVIDIA H100 80GB HBM3", "llvmpipe (LLVM 15.0.6, 256 bits)").
    pub name: String,
    /// Graphics API: "Vulkan", "Gl", "Dx12", "Metal".
    pub backend: String,
    /// wgpu's device type: "DiscreteGpu", "IntegratedGpu", "VirtualGpu", "Cpu", "Other".
    pub device_type: String,
    /// PCI vendor id.
    pub vendor: u32,
    /// Driver name and version, as the driver reports them.
    pub driver: String,
    /// Whether it offers `SHADER_F64` (the batch path needs it; `COSSERAT_GPU_NO_F64`
    /// hides it).
    pub shader_f64: bool,
    /// Whether it offers a compiled-pipeline cache.
    pub pipeline_cache: bool,
    /// A software adapter: runs the kernels on the CPU's own cores.
    pub software: bool,
    /// Largest storage buffer binding, bytes (bounds the members in flight).
    pub max_storage_buffer_binding_size: u64,
    /// Largest buffer, bytes.
    pub max_buffer_size: u64,
    /// Storage buffers one shader stage may bind (the passes bind up to 8).
    pub max_storage_buffers_per_shader_stage: u32,
    /// Workgroups per dispatch dimension (bounds the elements of one dispatch).
    pub max_compute_workgroups_per_dimension: u32,
}

impl AdapterReport {
    fn from_adapter(a: &wgpu::Adapter) -> Self {
        let info = a.get_info();
        let features = a.features();
        let limits = a.limits();
        let driver = [info.driver.as_str(), info.driver_info.as_str()]
            .iter()
            .filter(|s| !s.is_empty())
            .copied()
            .collect::<Vec<_>>()
            .join(" ");
        AdapterReport {
            name: info.name.clone(),
            backend: format!("{:?}", info.backend),
            device_type: format!("{:?}", info.device_type),
            vendor: info.vendor,
            driver,
            shader_f64: features.contains(wgpu::Features::SHADER_F64) && !env_disables_f64(),
            pipeline_cache: features.contains(wgpu::Features::PIPELINE_CACHE),
            software: info.device_type == wgpu::DeviceType::Cpu,
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_buffer_size: limits.max_buffer_size,
            max_storage_buffers_per_shader_stage: limits.max_storage_buffers_per_shader_stage,
            max_compute_workgroups_per_dimension: limits.max_compute_workgroups_per_dimension,
        }
    }

    fn rank(&self) -> (bool, u8) {
        let t = match self.device_type.as_str() {
            "DiscreteGpu" => wgpu::DeviceType::DiscreteGpu,
            "IntegratedGpu" => wgpu::DeviceType::IntegratedGpu,
            "VirtualGpu" => wgpu::DeviceType::VirtualGpu,
            "Cpu" => wgpu::DeviceType::Cpu,
            _ => wgpu::DeviceType::Other,
        };
        adapter_rank(self.shader_f64, t)
    }
}

/// Every adapter wgpu sees (backends from `WGPU_BACKEND` when set, else all).
pub fn list_adapters() -> Vec<AdapterReport> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    adapters.iter().map(AdapterReport::from_adapter).collect()
}

/// What `--backend auto` (without `--adapter`) does with these adapters.
#[derive(Clone, Debug, Serialize)]
pub struct AutoChoice {
    /// Index into the adapter list of the GPU it would use; `None`: the CPU path.
    pub adapter: Option<usize>,
    /// Why, in one sentence.
    pub why: String,
}

/// The choice `Executor::resolve` makes for `--backend auto`: the first adapter in the
/// order `GpuContext::new` sorts them (f64 first, then discrete, integrated, virtual,
/// other, software), used only if it has `SHADER_F64` and is not a software adapter.
pub fn auto_choice(adapters: &[AdapterReport]) -> AutoChoice {
    let first = (0..adapters.len()).min_by_key(|&i| adapters[i].rank());
    match first {
        None => AutoChoice {
            adapter: None,
            why: "the CPU path: wgpu sees no adapter".into(),
        },
        Some(i) if !adapters[i].shader_f64 => AutoChoice {
            adapter: None,
            why: format!(
                "the CPU path: no adapter offers SHADER_F64 (the best, {}, does not; f32 cannot reach the Newton tolerance)",
                adapters[i].name
            ),
        },
        Some(i) if adapters[i].software => AutoChoice {
            adapter: None,
            why: format!(
                "the CPU path: the best adapter with SHADER_F64, {}, is a software adapter, which runs on the CPU's own cores and is slower than the CPU path (name it with --adapter, or use --backend gpu, to use it anyway)",
                adapters[i].name
            ),
        },
        Some(i) => AutoChoice {
            adapter: Some(i),
            why: format!(
                "{}: a {} adapter with SHADER_F64",
                adapters[i].name, adapters[i].device_type
            ),
        },
    }
}

/// A Vulkan ICD manifest found on the host.
#[derive(Clone, Debug, Serialize)]
pub struct IcdFile {
    /// The manifest.
    pub path: PathBuf,
    /// Its `ICD.library_path` (empty when unreadable).
    pub library: String,
}

/// Host facts that decide whether an NVIDIA GPU can appear as a Vulkan adapter.
#[derive(Clone, Debug, Default, Serialize)]
pub struct HostFacts {
    /// `/dev/nvidia*` device nodes.
    pub nvidia_nodes: Vec<String>,
    /// Loaded kernel modules whose name starts with `nvidia` (`/proc/modules`).
    pub nvidia_modules: Vec<String>,
    /// Vulkan ICD manifests in the loader's standard places (and `VK_DRIVER_FILES` /
    /// `VK_ICD_FILENAMES` when set).
    pub icd_files: Vec<IcdFile>,
}

impl HostFacts {
    /// Reads the facts below `root` (`/` on a real host).
    pub fn read(root: &Path) -> Self {
        let under = |p: &str| root.join(p.trim_start_matches('/'));
        let mut nvidia_nodes: Vec<String> = std::fs::read_dir(under("/dev"))
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.starts_with("nvidia"))
                    .collect()
            })
            .unwrap_or_default();
        nvidia_nodes.sort();
        let mut nvidia_modules: Vec<String> = std::fs::read_to_string(under("/proc/modules"))
            .map(|s| {
                s.lines()
                    .filter_map(|l| l.split_whitespace().next())
                    .filter(|m| m.starts_with("nvidia"))
                    .map(str::to_string)
                    .collect()
            })
            .unwrap_or_default();
        nvidia_modules.sort();
        let mut dirs: Vec<PathBuf> = [
            "/etc/vulkan/icd.d",
            "/usr/local/share/vulkan/icd.d",
            "/usr/share/vulkan/icd.d",
        ]
        .iter()
        .map(|d| under(d))
        .collect();
        if let Some(xdg) = std::env::var_os("XDG_DATA_DIRS") {
            for d in std::env::split_paths(&xdg) {
                let d = under(&d.join("vulkan/icd.d").to_string_lossy());
                if !dirs.contains(&d) {
                    dirs.push(d);
                }
            }
        }
        let mut files: Vec<PathBuf> = Vec::new();
        for d in &dirs {
            if let Ok(rd) = std::fs::read_dir(d) {
                let mut here: Vec<PathBuf> = rd
                    .filter_map(|e| e.ok())
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|x| x == "json"))
                    .collect();
                here.sort();
                files.extend(here);
            }
        }
        for var in ["VK_DRIVER_FILES", "VK_ICD_FILENAMES"] {
            if let Some(v) = std::env::var_os(var) {
                for f in std::env::split_paths(&v) {
                    if !files.contains(&f) {
                        files.push(f);
                    }
                }
            }
        }
        let icd_files = files
            .into_iter()
            .map(|path| {
                let library = std::fs::read_to_string(&path)
                    .ok()
                    .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
                    .and_then(|v| v["ICD"]["library_path"].as_str().map(str::to_string))
                    .unwrap_or_default();
                IcdFile { path, library }
            })
            .collect();
        HostFacts {
            nvidia_nodes,
            nvidia_modules,
            icd_files,
        }
    }

    /// The facts of this host (`COSSERAT_GPU_HOST_ROOT` or `/`).
    pub fn of_this_host() -> Self {
        let root = std::env::var_os("COSSERAT_GPU_HOST_ROOT")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("/"));
        Self::read(&root)
    }
}

/// Why an NVIDIA GPU that the host has is not an adapter, and what to do: `None` when the
/// host has no NVIDIA device nodes or an NVIDIA adapter is listed. `loader` is what the
/// Vulkan loader said about the drivers it tried (empty when not captured).
pub fn diagnose(
    facts: &HostFacts,
    adapters: &[AdapterReport],
    loader: &[String],
) -> Option<Vec<String>> {
    let has_gpu_node = facts
        .nvidia_nodes
        .iter()
        .any(|n| n == "nvidiactl" || n.trim_start_matches("nvidia").parse::<u32>().is_ok());
    let nvidia_adapter = adapters
        .iter()
        .any(|a| a.vendor == NVIDIA_VENDOR && a.backend != "Gl");
    if !has_gpu_node || nvidia_adapter {
        return None;
    }
    let mut lines = vec![format!(
        "this host has NVIDIA device nodes ({}) but wgpu lists no NVIDIA Vulkan adapter",
        facts
            .nvidia_nodes
            .iter()
            .map(|n| format!("/dev/{n}"))
            .collect::<Vec<_>>()
            .join(", ")
    )];
    let modeset_module = facts.nvidia_modules.iter().any(|m| m == "nvidia_modeset");
    let modeset_node = facts.nvidia_nodes.iter().any(|n| n == "nvidia-modeset");
    lines.push(format!(
        "kernel modules: {}",
        if facts.nvidia_modules.is_empty() {
            "no nvidia module listed in /proc/modules".to_string()
        } else {
            facts.nvidia_modules.join(", ")
        }
    ));
    let nvidia_icds: Vec<&IcdFile> = facts
        .icd_files
        .iter()
        .filter(|f| f.library.contains("nvidia"))
        .collect();
    if facts.icd_files.is_empty() {
        lines.push("Vulkan ICD files: none found".into());
    } else {
        for f in &facts.icd_files {
            lines.push(format!(
                "Vulkan ICD file: {} -> {}",
                f.path.display(),
                if f.library.is_empty() {
                    "(no library_path)"
                } else {
                    &f.library
                }
            ));
        }
    }
    for l in loader {
        lines.push(format!("Vulkan loader: {l}"));
    }
    if !modeset_module || !modeset_node {
        lines.push(format!(
            "cause: NVIDIA's Vulkan driver needs the nvidia_modeset kernel module and /dev/nvidia-modeset; {} (a compute-only, CUDA setup loads only nvidia and nvidia_uvm)",
            match (modeset_module, modeset_node) {
                (false, false) => "neither is present",
                (false, true) => "the module is not loaded",
                _ => "/dev/nvidia-modeset is missing",
            }
        ));
        lines.push("fix: on the host, `modprobe nvidia_modeset` (as root); in a container, also pass the device `/dev/nvidia-modeset` and set NVIDIA_DRIVER_CAPABILITIES=compute,graphics,utility; then `vulkaninfo --summary` must list the GPU".into());
    } else if nvidia_icds.is_empty() {
        lines.push("cause: no Vulkan ICD file names an NVIDIA library, so the loader does not try the driver".into());
        lines.push("fix: install the driver's Vulkan part (nvidia_icd.json in /usr/share/vulkan/icd.d), or point VK_DRIVER_FILES at an ICD file naming libGLX_nvidia.so.0 or libEGL_nvidia.so.0".into());
    } else {
        lines.push("cause: the loader found the NVIDIA ICD but did not create an instance with it (see the loader's lines above; run with VK_LOADER_DEBUG=driver for all of them)".into());
        lines.push("fix: try VK_DRIVER_FILES pointing at a copy of the ICD file whose library_path is the driver's libEGL_nvidia.so.0 (its headless entry point), then the same with the GLX library by full path; X11/EGL client libraries (libX11, libEGL, GLVND) must be installed for the GLX one".into());
    }
    Some(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adapter(
        name: &str,
        device_type: &str,
        vendor: u32,
        f64: bool,
        backend: &str,
    ) -> AdapterReport {
        AdapterReport {
            name: name.into(),
            backend: backend.into(),
            device_type: device_type.into(),
            vendor,
            driver: String::new(),
            shader_f64: f64,
            pipeline_cache: false,
            software: device_type == "Cpu",
            max_storage_buffer_binding_size: 1 << 27,
            max_buffer_size: 1 << 31,
            max_storage_buffers_per_shader_stage: 8,
            max_compute_workgroups_per_dimension: 65535,
        }
    }

    #[test]
    fn auto_prefers_f64_then_discrete_and_never_a_software_adapter() {
        let lvp = adapter("llvmpipe", "Cpu", 0x10005, true, "Vulkan");
        let h100 = adapter("NVIDIA H100", "DiscreteGpu", NVIDIA_VENDOR, true, "Vulkan");
        let igpu = adapter("Intel UHD", "IntegratedGpu", 0x8086, true, "Vulkan");
        let gl = adapter("NVIDIA H100", "DiscreteGpu", NVIDIA_VENDOR, false, "Gl");
        let none = auto_choice(&[]);
        assert!(
            none.adapter.is_none() && none.why.contains("no adapter"),
            "{none:?}"
        );
        let c = auto_choice(&[lvp.clone(), igpu.clone(), h100.clone()]);
        assert_eq!(c.adapter, Some(2), "{c:?}");
        let c = auto_choice(&[lvp.clone(), igpu.clone()]);
        assert_eq!(c.adapter, Some(1), "{c:?}");
        // An f64 software adapter ranks before a GPU without f64 (as GpuContext::new
        // sorts them), and auto refuses it: the CPU path.
        let c = auto_choice(&[gl.clone(), lvp.clone()]);
        assert!(
            c.adapter.is_none() && c.why.contains("software adapter"),
            "{c:?}"
        );
        let c = auto_choice(&[gl]);
        assert!(c.adapter.is_none() && c.why.contains("SHADER_F64"), "{c:?}");
    }

    fn host(nodes: &[&str], modules: &[&str], icd: &[(&str, &str)]) -> HostFacts {
        HostFacts {
            nvidia_nodes: nodes.iter().map(|s| s.to_string()).collect(),
            nvidia_modules: modules.iter().map(|s| s.to_string()).collect(),
            icd_files: icd
                .iter()
                .map(|(p, l)| IcdFile {
                    path: PathBuf::from(p),
                    library: l.to_string(),
                })
                .collect(),
        }
    }

    #[test]
    fn diagnosis_names_the_missing_piece() {
        let lvp = adapter("llvmpipe", "Cpu", 0x10005, true, "Vulkan");
        let icd = [(
            "/usr/share/vulkan/icd.d/nvidia_icd.json",
            "libGLX_nvidia.so.0",
        )];
        // No NVIDIA nodes: nothing to diagnose.
        assert!(diagnose(&host(&[], &[], &icd), std::slice::from_ref(&lvp), &[]).is_none());
        // `nvidia-caps` alone is not a GPU node.
        assert!(diagnose(&host(&["nvidia-caps"], &[], &[]), &[], &[]).is_none());
        // An NVIDIA Vulkan adapter is listed: nothing to diagnose.
        let h100 = adapter("NVIDIA H100", "DiscreteGpu", NVIDIA_VENDOR, true, "Vulkan");
        let compute = host(
            &["nvidia0", "nvidiactl", "nvidia-uvm"],
            &["nvidia", "nvidia_uvm"],
            &icd,
        );
        assert!(diagnose(&compute, &[h100], &[]).is_none());
        // The lent boxes' state: compute-only modules, no modeset node.
        let loader = ["ERROR: Could not get 'vkCreateInstance'".to_string()];
        let d = diagnose(&compute, std::slice::from_ref(&lvp), &loader)
            .unwrap()
            .join("\n");
        assert!(
            d.contains("/dev/nvidia0") && d.contains("nvidia, nvidia_uvm"),
            "{d}"
        );
        assert!(d.contains("-> libGLX_nvidia.so.0"), "{d}");
        assert!(
            d.contains("Vulkan loader: ERROR: Could not get 'vkCreateInstance'"),
            "{d}"
        );
        assert!(
            d.contains("neither is present") && d.contains("modprobe nvidia_modeset"),
            "{d}"
        );
        // Module loaded, node missing (a container without the device passed in).
        let h = host(
            &["nvidia0", "nvidiactl"],
            &["nvidia", "nvidia_modeset"],
            &icd,
        );
        let d = diagnose(&h, std::slice::from_ref(&lvp), &[])
            .unwrap()
            .join("\n");
        assert!(d.contains("/dev/nvidia-modeset is missing"), "{d}");
        // Modeset present, no ICD naming the driver.
        let h = host(
            &["nvidia0", "nvidia-modeset"],
            &["nvidia", "nvidia_modeset"],
            &[],
        );
        let d = diagnose(&h, std::slice::from_ref(&lvp), &[])
            .unwrap()
            .join("\n");
        assert!(
            d.contains("ICD files: none found")
                && d.contains("no Vulkan ICD file names an NVIDIA library"),
            "{d}"
        );
        // Everything in place and still no adapter: the loader's lines and the ICD routes.
        let h = host(
            &["nvidia0", "nvidia-modeset"],
            &["nvidia", "nvidia_modeset"],
            &icd,
        );
        let d = diagnose(&h, &[lvp], &[]).unwrap().join("\n");
        assert!(
            d.contains("libEGL_nvidia.so.0") && d.contains("VK_DRIVER_FILES"),
            "{d}"
        );
    }

    #[test]
    fn host_facts_are_read_below_the_root() {
        let root = tempfile::tempdir().unwrap();
        let r = root.path();
        std::fs::create_dir_all(r.join("dev")).unwrap();
        std::fs::create_dir_all(r.join("proc")).unwrap();
        std::fs::create_dir_all(r.join("etc/vulkan/icd.d")).unwrap();
        for n in ["nvidia0", "nvidiactl", "null", "nvidia-uvm"] {
            std::fs::write(r.join("dev").join(n), "").unwrap();
        }
        std::fs::write(
            r.join("proc/modules"),
            "nvidia_uvm 1 0 - Live 0x0\nnvidia 2 1 nvidia_uvm, Live 0x0\next4 3 1 - Live 0x0\n",
        )
        .unwrap();
        std::fs::write(
            r.join("etc/vulkan/icd.d/nvidia_icd.json"),
            r#"{"file_format_version":"1.0.0","ICD":{"library_path":"libEGL_nvidia.so.0"}}"#,
        )
        .unwrap();
        std::fs::write(r.join("etc/vulkan/icd.d/broken.json"), "{").unwrap();
        let f = HostFacts::read(r);
        assert_eq!(f.nvidia_nodes, ["nvidia-uvm", "nvidia0", "nvidiactl"]);
        assert_eq!(f.nvidia_modules, ["nvidia", "nvidia_uvm"]);
        let libs: Vec<&str> = f
            .icd_files
            .iter()
            .filter(|i| i.path.starts_with(r))
            .map(|i| i.library.as_str())
            .collect();
        assert_eq!(libs, ["", "libEGL_nvidia.so.0"]);
    }
}
