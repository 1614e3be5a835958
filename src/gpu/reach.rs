//! Reaching an NVIDIA GPU on a headless compute host where the default Vulkan setup lists
//! none (docs/gpu.md, "A headless NVIDIA compute host often shows no Vulkan adapter").
//!
//! Such a host has NVIDIA device nodes and an ICD manifest naming the driver's
//! `libGLX_nvidia.so.0`, which the Vulkan loader drops without an X11 stack. The routes
//! tried here are the ones `gpu-bench/probe.sh` tries first, in the same order: a manifest
//! naming the driver's headless entry point `libEGL_nvidia.so.0`, then one naming the GLX
//! library by its full path. Each route is a manifest written into the per-user cache
//! folder (never an output folder) and tried in a fresh Vulkan instance through
//! `VK_DRIVER_FILES`; the first that lists a GPU is kept for the process.
//!
//! `COSSERAT_GPU_REACH=off` turns this off. For tests, `COSSERAT_GPU_ICD_LIBS` (a
//! `:`-separated list of libraries) replaces the driver libraries the routes name and
//! `COSSERAT_GPU_REACH_MATCH` names an adapter that counts as reached, so that lavapipe
//! can stand in for the driver (as `PROBE_LIBS` and `PROBE_MATCH` do for probe.sh).

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::inventory::{HostFacts, NVIDIA_VENDOR};

/// One way tried to reach the GPU, and what it gave.
#[derive(Clone, Debug, Serialize)]
pub struct RouteTry {
    /// What the route is, in words.
    pub route: String,
    /// The ICD manifest written for it.
    pub manifest: PathBuf,
    /// The library the manifest names.
    pub library: String,
    /// The Vulkan adapters a fresh instance listed through it.
    pub adapters: Vec<String>,
    /// Whether it reached a GPU (an NVIDIA adapter, or the test's match).
    pub reached: bool,
}

/// What [`reach_nvidia_gpu`] did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Reach {
    /// The routes tried, in order (empty when none was needed or possible).
    pub tries: Vec<RouteTry>,
    /// The manifest now in `VK_DRIVER_FILES`, when a route reached the GPU.
    pub applied: Option<PathBuf>,
    /// Why nothing was tried, when nothing was.
    pub skipped: Option<String>,
}

impl Reach {
    /// One line for stderr: the route applied, or the routes that failed (`None` when
    /// nothing was tried).
    pub fn summary(&self) -> Option<String> {
        if let Some(m) = &self.applied {
            let t = self.tries.iter().find(|t| t.reached)?;
            return Some(format!(
                "GPU reached through {} (VK_DRIVER_FILES={}): {}",
                t.route,
                m.display(),
                t.adapters.join("; ")
            ));
        }
        if self.tries.is_empty() {
            return None;
        }
        Some(format!(
            "no GPU through the default Vulkan setup nor through {} (see `cosserat gpu`)",
            self.tries
                .iter()
                .map(|t| t.route.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    }
}

/// Directories searched for the driver's libraries, below the host root.
const LIB_DIRS: [&str; 4] = [
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/nvidia/lib64",
];

/// The routes for this host: `(route, library)` in the order tried. Empty when the host
/// has no NVIDIA GPU device node or no ICD manifest naming an NVIDIA library (then the
/// driver's Vulkan part is missing, which no manifest can replace).
pub fn routes(facts: &HostFacts, root: &Path) -> Vec<(String, String)> {
    if let Some(libs) = std::env::var_os("COSSERAT_GPU_ICD_LIBS") {
        return std::env::split_paths(&libs)
            .map(|p| {
                let p = p.to_string_lossy().into_owned();
                (format!("an ICD file naming {p}"), p)
            })
            .collect();
    }
    let has_gpu_node = facts
        .nvidia_nodes
        .iter()
        .any(|n| n.trim_start_matches("nvidia").parse::<u32>().is_ok());
    let has_nvidia_icd = facts.icd_files.iter().any(|f| f.library.contains("nvidia"));
    if !has_gpu_node || !has_nvidia_icd {
        return Vec::new();
    }
    let find = |name: &str| {
        LIB_DIRS
            .iter()
            .map(|d| Path::new(d).join(name))
            .find(|p| root.join(p.strip_prefix("/").unwrap_or(p)).exists())
    };
    let mut out = Vec::new();
    let egl = find("libEGL_nvidia.so.0").map_or("libEGL_nvidia.so.0".to_string(), |p| {
        p.to_string_lossy().into_owned()
    });
    out.push((
        "an ICD file naming the driver's headless libEGL_nvidia.so.0".to_string(),
        egl,
    ));
    if let Some(glx) = find("libGLX_nvidia.so.0") {
        out.push((
            "an ICD file naming the GLX library by its full path".to_string(),
            glx.to_string_lossy().into_owned(),
        ));
    }
    out
}

/// Writes the manifest of one route into `dir`.
fn write_manifest(dir: &Path, index: usize, library: &str) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(format!("cosserat_route_{index}_icd.json"));
    let text = serde_json::json!({
        "file_format_version": "1.0.0",
        "ICD": { "library_path": library, "api_version": "1.3.0" }
    });
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&text).unwrap_or_default(),
    )?;
    Ok(path)
}

/// The Vulkan adapters a fresh instance lists, and whether one of them counts as the GPU:
/// an NVIDIA adapter, or through a route (`route`) one named by the test's match.
fn vulkan_adapters(route: bool) -> (Vec<String>, bool) {
    let want = std::env::var("COSSERAT_GPU_REACH_MATCH")
        .ok()
        .filter(|_| route);
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::VULKAN,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
    let mut reached = false;
    let names = adapters
        .iter()
        .map(|a| {
            let info = a.get_info();
            reached |= match &want {
                Some(m) => info.name.to_lowercase().contains(&m.to_lowercase()),
                None => info.vendor == NVIDIA_VENDOR,
            };
            format!("{} [{:?}]", info.name, info.device_type)
        })
        .collect();
    (names, reached)
}

/// Sets the loader's driver list for this process (both the current and the older name).
///
/// # Safety (in spirit)
/// Changes the process environment: call only while the process has one thread.
fn set_driver_files(value: Option<&Path>) {
    for var in ["VK_DRIVER_FILES", "VK_ICD_FILENAMES"] {
        match value {
            Some(v) => std::env::set_var(var, v),
            None => std::env::remove_var(var),
        }
    }
}

/// On a host with NVIDIA device nodes whose default Vulkan setup lists no NVIDIA adapter,
/// tries the routes of [`routes`] one by one and keeps the first that lists the GPU in
/// `VK_DRIVER_FILES` for the rest of the process. Manifests go to `cache_dir/icd`
/// (nothing is tried without a cache folder).
///
/// Changes the process environment: call it first thing, while the process has one
/// thread (the CLI does, for commands that may use a GPU). Does nothing when the user set
/// `VK_DRIVER_FILES` or `VK_ICD_FILENAMES`, or `COSSERAT_GPU_REACH=off`.
pub fn reach_nvidia_gpu(facts: &HostFacts, root: &Path, cache_dir: Option<&Path>) -> Reach {
    let skip = |why: &str| Reach {
        skipped: Some(why.to_string()),
        ..Reach::default()
    };
    if std::env::var("COSSERAT_GPU_REACH").is_ok_and(|v| v == "off") {
        return skip("COSSERAT_GPU_REACH=off");
    }
    if ["VK_DRIVER_FILES", "VK_ICD_FILENAMES"]
        .iter()
        .any(|v| std::env::var_os(v).is_some())
    {
        return skip("VK_DRIVER_FILES or VK_ICD_FILENAMES is set");
    }
    let routes = routes(facts, root);
    if routes.is_empty() {
        return skip("no NVIDIA GPU device node with an NVIDIA ICD file on this host");
    }
    let Some(dir) = cache_dir.map(|d| d.join("icd")) else {
        return skip(
            "no cache folder for the ICD files (COSSERAT_CACHE_DIR, XDG_CACHE_HOME or HOME)",
        );
    };
    if vulkan_adapters(false).1 {
        return skip("the default Vulkan setup lists the GPU");
    }
    let mut reach = Reach::default();
    for (i, (route, library)) in routes.into_iter().enumerate() {
        let manifest = match write_manifest(&dir, i, &library) {
            Ok(m) => m,
            Err(e) => {
                reach.skipped = Some(format!("cannot write {}: {e}", dir.display()));
                break;
            }
        };
        set_driver_files(Some(&manifest));
        let (adapters, reached) = vulkan_adapters(true);
        reach.tries.push(RouteTry {
            route,
            manifest: manifest.clone(),
            library,
            adapters,
            reached,
        });
        if reached {
            reach.applied = Some(manifest);
            return reach;
        }
    }
    set_driver_files(None);
    reach
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::inventory::IcdFile;

    fn host(nodes: &[&str], icd_lib: &str) -> HostFacts {
        HostFacts {
            nvidia_nodes: nodes.iter().map(|s| s.to_string()).collect(),
            nvidia_modules: vec!["nvidia".into(), "nvidia_uvm".into()],
            icd_files: vec![IcdFile {
                path: PathBuf::from("/usr/share/vulkan/icd.d/nvidia_icd.json"),
                library: icd_lib.into(),
            }],
        }
    }

    #[test]
    fn routes_need_a_gpu_node_and_an_nvidia_icd_and_prefer_egl() {
        if std::env::var_os("COSSERAT_GPU_ICD_LIBS").is_some() {
            return;
        }
        let root = tempfile::tempdir().unwrap();
        assert!(routes(&host(&["nvidiactl"], "libGLX_nvidia.so.0"), root.path()).is_empty());
        assert!(routes(&host(&["nvidia0"], "libvulkan_lvp.so"), root.path()).is_empty());
        let r = routes(
            &host(&["nvidia0", "nvidiactl"], "libGLX_nvidia.so.0"),
            root.path(),
        );
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!(r[0].1, "libEGL_nvidia.so.0");
        // With the driver's libraries installed, both routes name them by full path.
        let lib = root.path().join("usr/lib/x86_64-linux-gnu");
        std::fs::create_dir_all(&lib).unwrap();
        for f in ["libEGL_nvidia.so.0", "libGLX_nvidia.so.0"] {
            std::fs::write(lib.join(f), b"").unwrap();
        }
        let r = routes(&host(&["nvidia0"], "libGLX_nvidia.so.0"), root.path());
        assert_eq!(
            r.iter().map(|x| x.1.as_str()).collect::<Vec<_>>(),
            [
                "/usr/lib/x86_64-linux-gnu/libEGL_nvidia.so.0",
                "/usr/lib/x86_64-linux-gnu/libGLX_nvidia.so.0"
            ]
        );
        assert!(r[0].0.contains("libEGL_nvidia"), "{}", r[0].0);
    }

    #[test]
    fn a_manifest_names_its_library() {
        let dir = tempfile::tempdir().unwrap();
        let m = write_manifest(dir.path(), 0, "/x/libEGL_nvidia.so.0").unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(m).unwrap()).unwrap();
        assert_eq!(v["ICD"]["library_path"], "/x/libEGL_nvidia.so.0");
        assert_eq!(v["file_format_version"], "1.0.0");
    }
}
