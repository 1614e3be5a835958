//! `cosserat gpu`: the adapters wgpu sees, the `--backend auto` choice, and the diagnosis
//! of a host whose NVIDIA GPU is not an adapter.

use std::process::{Command, ExitCode};

use anyhow::Result;
use serde::Serialize;

use cosserat::gpu::inventory::{self, AdapterReport, AutoChoice, HostFacts};
use cosserat::gpu::reach::Reach;

/// Arguments of `cosserat gpu`.
#[derive(clap::Args, Debug)]
pub struct GpuArgs {
    /// Print one JSON object (adapters, auto choice, host facts, diagnosis) instead of text.
    #[arg(long)]
    json: bool,
    /// Internal: only enumerate the adapters (the child process whose Vulkan loader
    /// messages the diagnosis quotes).
    #[arg(long, hide = true)]
    enumerate_only: bool,
}

impl GpuArgs {
    /// The internal child that only enumerates (it inherits the parent's routes).
    pub fn enumerate_only(&self) -> bool {
        self.enumerate_only
    }
}

#[derive(Serialize)]
struct Report {
    adapters: Vec<AdapterReport>,
    auto: AutoChoice,
    host: HostFacts,
    /// The routes tried at start-up round a missing NVIDIA adapter, and the one applied.
    reach: Reach,
    diagnosis: Option<Vec<String>>,
}

/// What the Vulkan loader says while it tries the drivers: a child process enumerates the
/// adapters with `VK_LOADER_DEBUG=error,warn,driver`; the lines about NVIDIA or about a
/// driver it could not use are kept (at most 12).
fn loader_messages() -> Vec<String> {
    let Ok(exe) = std::env::current_exe() else {
        return Vec::new();
    };
    let Ok(out) = Command::new(exe)
        .args(["gpu", "--enumerate-only"])
        .env("VK_LOADER_DEBUG", "error,warn,driver")
        .output()
    else {
        return Vec::new();
    };
    let text =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    let mut kept: Vec<String> = Vec::new();
    for l in text.lines() {
        let low = l.to_lowercase();
        if (low.contains("nvidia") || low.contains("could not") || low.contains("error"))
            && !kept.iter().any(|k| k == l.trim())
        {
            kept.push(l.trim().to_string());
        }
        if kept.len() == 12 {
            break;
        }
    }
    kept
}

/// Bytes as MiB below 1 GiB, else GiB.
fn gib(b: u64) -> String {
    if b < 1 << 30 {
        format!("{} MiB", b >> 20)
    } else {
        format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64)
    }
}

/// Runs `cosserat gpu`.
/// `reach`: what the start-up tried round a missing NVIDIA adapter (already applied).
pub fn gpu_command(a: GpuArgs, reach: Reach) -> Result<ExitCode> {
    let adapters = inventory::list_adapters();
    if a.enumerate_only {
        return Ok(ExitCode::SUCCESS);
    }
    let auto = inventory::auto_choice(&adapters);
    let host = HostFacts::of_this_host();
    let needs_diagnosis = inventory::diagnose(&host, &adapters, &[]).is_some();
    let loader = if needs_diagnosis {
        loader_messages()
    } else {
        Vec::new()
    };
    let diagnosis = inventory::diagnose(&host, &adapters, &loader);
    let report = Report {
        adapters,
        auto,
        host,
        reach,
        diagnosis,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!("adapters wgpu sees: {}", report.adapters.len());
    for (i, r) in report.adapters.iter().enumerate() {
        println!(
            "  [{i}] {}  ({}, {}{})",
            r.name,
            r.backend,
            r.device_type,
            if r.software { ", software" } else { "" }
        );
        println!(
            "      SHADER_F64 {}, pipeline cache {}; driver: {}",
            if r.shader_f64 { "yes" } else { "no" },
            if r.pipeline_cache { "yes" } else { "no" },
            if r.driver.is_empty() { "-" } else { &r.driver }
        );
        println!(
            "      limits: storage binding {}, buffer {}, {} storage buffers per stage, {} workgroups per dimension",
            gib(r.max_storage_buffer_binding_size),
            gib(r.max_buffer_size),
            r.max_storage_buffers_per_shader_stage,
            r.max_compute_workgroups_per_dimension
        );
    }
    println!("--backend auto would use {}", report.auto.why);
    for t in &report.reach.tries {
        println!(
            "route tried: {} ({} -> {}): {}",
            t.route,
            t.manifest.display(),
            t.library,
            if t.reached {
                format!("reached: {}", t.adapters.join("; "))
            } else if t.adapters.is_empty() {
                "no Vulkan adapter".to_string()
            } else {
                format!("not the GPU: {}", t.adapters.join("; "))
            }
        );
    }
    if let Some(m) = &report.reach.applied {
        println!(
            "applied for this process: VK_DRIVER_FILES={} (set it yourself to skip the tries)",
            m.display()
        );
    }
    if let Some(lines) = &report.diagnosis {
        println!("NVIDIA GPU not reachable through Vulkan:");
        for l in lines {
            println!("  {l}");
        }
    }
    Ok(ExitCode::SUCCESS)
}
