//! `cosserat gpu`: on the software adapter it lists the adapter with its f64 support and
//! says that `--backend auto` would not use it (the same choice `Executor::resolve` makes);
//! on a fake host with NVIDIA device nodes but no `nvidia_modeset` it prints the diagnosis
//! and the fix. Without an adapter the lavapipe part prints `skipped: no adapter` unless
//! `COSSERAT_REQUIRE_GPU` is set.

mod common;

use std::process::Command;

use cosserat::batch::{BackendChoice, Executor};

fn gpu_cmd(root: Option<&std::path::Path>, json: bool) -> (String, i32) {
    gpu_cmd_env(root, json, &[])
}

/// `cosserat gpu` with extra environment; its cache folder (where the start-up writes the
/// ICD files of the routes it tries) is a fresh temporary folder.
fn gpu_cmd_env(root: Option<&std::path::Path>, json: bool, env: &[(&str, &str)]) -> (String, i32) {
    let cache = tempfile::tempdir().unwrap();
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    c.arg("gpu")
        .env("NODEVICE_SELECT", "1")
        .env("COSSERAT_CACHE_DIR", cache.path())
        .env_remove("VK_DRIVER_FILES")
        .env_remove("VK_ICD_FILENAMES");
    for (k, v) in env {
        c.env(k, v);
    }
    if json {
        c.arg("--json");
    }
    if let Some(r) = root {
        c.env("COSSERAT_GPU_HOST_ROOT", r);
    }
    let o = c.output().expect("run cosserat gpu");
    (
        String::from_utf8(o.stdout).unwrap(),
        o.status.code().unwrap_or(-1),
    )
}

#[test]
fn lists_the_software_adapter_and_the_auto_choice() {
    if common::gpu().is_none() {
        return;
    }
    let (out, code) = gpu_cmd(None, true);
    assert_eq!(code, 0, "{out}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let adapters = v["adapters"].as_array().unwrap();
    let vulkan_f64: Vec<&serde_json::Value> = adapters
        .iter()
        .filter(|a| a["shader_f64"] == true)
        .collect();
    assert!(!vulkan_f64.is_empty(), "an f64 adapter is listed: {out}");
    for a in adapters {
        assert!(a["max_storage_buffer_binding_size"].as_u64().unwrap() > 0);
        assert!(a["name"].as_str().is_some_and(|n| !n.is_empty()));
    }
    // The auto choice agrees with what the batch path does.
    let (exec, _) = Executor::resolve(BackendChoice::Auto, None).unwrap();
    match (&exec, v["auto"]["adapter"].as_u64()) {
        (Executor::Cpu, None) => {
            let why = v["auto"]["why"].as_str().unwrap();
            if adapters.iter().all(|a| a["software"] == true) {
                assert!(why.contains("software adapter"), "{why}");
            }
        }
        (Executor::Gpu(c), Some(i)) => {
            assert!(c
                .describe()
                .contains(adapters[i as usize]["name"].as_str().unwrap()));
        }
        (e, a) => panic!(
            "auto: cosserat gpu says {a:?}, the batch path {}",
            e.describe()
        ),
    }
    // The text form names every adapter and the choice.
    let (text, _) = gpu_cmd(None, false);
    for a in adapters {
        assert!(text.contains(a["name"].as_str().unwrap()), "{text}");
    }
    assert!(text.contains("--backend auto would use"), "{text}");
    // This host has no NVIDIA nodes under a root without them: no diagnosis.
    let empty = tempfile::tempdir().unwrap();
    let (out, _) = gpu_cmd(Some(empty.path()), true);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["diagnosis"].is_null(), "{out}");
}

/// A fake host with NVIDIA device nodes, only `nvidia` and `nvidia_uvm` loaded, and the
/// driver's ICD file naming `libGLX_nvidia.so.0` (the lent H100/H200 boxes).
fn compute_only_host() -> tempfile::TempDir {
    let root = tempfile::tempdir().unwrap();
    let r = root.path();
    std::fs::create_dir_all(r.join("dev")).unwrap();
    std::fs::create_dir_all(r.join("proc")).unwrap();
    std::fs::create_dir_all(r.join("usr/share/vulkan/icd.d")).unwrap();
    for n in ["nvidia0", "nvidiactl", "nvidia-uvm"] {
        std::fs::write(r.join("dev").join(n), "").unwrap();
    }
    std::fs::write(
        r.join("proc/modules"),
        "nvidia_uvm 1 0 - Live 0x0\nnvidia 2 1 nvidia_uvm, Live 0x0\n",
    )
    .unwrap();
    std::fs::write(
        r.join("usr/share/vulkan/icd.d/nvidia_icd.json"),
        r#"{"file_format_version":"1.0.0","ICD":{"library_path":"libGLX_nvidia.so.0","api_version":"1.3.289"}}"#,
    )
    .unwrap();
    root
}

#[test]
fn a_compute_only_nvidia_host_gets_the_diagnosis_and_the_fix() {
    let root = compute_only_host();
    let r = root.path();
    let (text, code) = gpu_cmd(Some(r), false);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("NVIDIA GPU not reachable through Vulkan"),
        "{text}"
    );
    assert!(text.contains("/dev/nvidia0"), "{text}");
    assert!(
        text.contains("kernel modules: nvidia, nvidia_uvm"),
        "{text}"
    );
    assert!(
        text.contains("nvidia_icd.json -> libGLX_nvidia.so.0"),
        "{text}"
    );
    assert!(text.contains("modprobe nvidia_modeset"), "{text}");
    assert!(text.contains("/dev/nvidia-modeset"), "{text}");
    // With the module and its node the cause moves on to the loader and the ICD routes.
    std::fs::write(r.join("dev/nvidia-modeset"), "").unwrap();
    std::fs::write(
        r.join("proc/modules"),
        "nvidia_uvm 1 0 - Live 0x0\nnvidia_modeset 1 0 - Live 0x0\nnvidia 2 1 nvidia_uvm, Live 0x0\n",
    )
    .unwrap();
    let (out, _) = gpu_cmd(Some(r), true);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let d: Vec<&str> = v["diagnosis"]
        .as_array()
        .expect("a diagnosis")
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert!(!d.iter().any(|l| l.contains("modprobe")), "{d:?}");
    assert!(d.iter().any(|l| l.contains("libEGL_nvidia.so.0")), "{d:?}");
    assert_eq!(
        v["host"]["nvidia_modules"],
        serde_json::json!(["nvidia", "nvidia_modeset", "nvidia_uvm"])
    );
}

/// On such a host the start-up tries the routes round the missing adapter (an ICD file
/// naming the driver's EGL library first) and applies the first that lists the GPU. Here
/// the driver's libraries are replaced by a missing one and lavapipe's
/// (`COSSERAT_GPU_ICD_LIBS`), and lavapipe counts as the GPU
/// (`COSSERAT_GPU_REACH_MATCH`): the first route lists nothing, the second is applied.
#[test]
fn the_routes_round_a_missing_adapter_are_tried_and_the_first_that_works_is_applied() {
    let root = compute_only_host();
    let r = root.path();
    // The real routes on this host: the EGL library, which is not installed here.
    let (out, _) = gpu_cmd(Some(r), true);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let tries = v["reach"]["tries"].as_array().expect("routes tried");
    assert_eq!(tries.len(), 1, "{out}");
    assert_eq!(tries[0]["library"], "libEGL_nvidia.so.0");
    assert_eq!(tries[0]["reached"], false);
    assert!(v["reach"]["applied"].is_null(), "{out}");
    // The user's own driver list is left alone.
    let mut c = Command::new(env!("CARGO_BIN_EXE_cosserat"));
    let o = c
        .args(["gpu", "--json"])
        .env("COSSERAT_GPU_HOST_ROOT", r)
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["reach"]["tries"].as_array().unwrap().is_empty());
    assert!(v["reach"]["skipped"]
        .as_str()
        .unwrap()
        .contains("VK_DRIVER_FILES"));
    let lvp = "/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so";
    if common::gpu().is_none() || !std::path::Path::new(lvp).exists() {
        return;
    }
    let libs = format!("/nonexistent/libEGL_nvidia.so.0:{lvp}");
    let env = [
        ("COSSERAT_GPU_ICD_LIBS", libs.as_str()),
        ("COSSERAT_GPU_REACH_MATCH", "llvmpipe"),
    ];
    let (out, code) = gpu_cmd_env(Some(r), true, &env);
    assert_eq!(code, 0, "{out}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let tries = v["reach"]["tries"].as_array().unwrap();
    assert_eq!(tries.len(), 2, "{out}");
    assert_eq!(tries[0]["reached"], false);
    assert!(tries[0]["adapters"].as_array().unwrap().is_empty(), "{out}");
    assert_eq!(tries[1]["reached"], true);
    assert_eq!(v["reach"]["applied"], tries[1]["manifest"]);
    // The applied route is what the process then enumerates: lavapipe on Vulkan.
    assert!(v["adapters"]
        .as_array()
        .unwrap()
        .iter()
        .any(|a| a["backend"] == "Vulkan" && a["name"].as_str().unwrap().contains("llvmpipe")));
    let (text, _) = gpu_cmd_env(Some(r), false, &env);
    assert!(
        text.contains("applied for this process: VK_DRIVER_FILES="),
        "{text}"
    );
}
