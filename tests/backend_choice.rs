//! `--backend auto` never picks a path slower than the CPU: a software adapter (wgpu
//! `DeviceType::Cpu`: lavapipe, llvmpipe, WARP, SwiftShader) is used only when named;
//! `auto` says which path it chose and why.
//!
//! Without an adapter the test checks the CPU fallback only and prints `skipped`, unless
//! `COSSERAT_REQUIRE_GPU` is set, in which case a missing adapter fails it.

use cosserat::batch::{BackendChoice, Executor};
use cosserat::gpu::{gpu_required, GpuContext};

#[test]
fn auto_skips_software_adapters_unless_named() {
    let (exec, note) = Executor::resolve(BackendChoice::Auto, None).unwrap();
    let note = note.expect("auto always says what it chose");
    let ctx = match GpuContext::new(None) {
        Ok(c) => c,
        Err(e) => {
            assert!(
                !gpu_required(),
                "COSSERAT_REQUIRE_GPU is set but no adapter: {e}"
            );
            assert!(
                matches!(exec, Executor::Cpu),
                "no adapter: auto must use the CPU"
            );
            println!("skipped: no adapter ({e})");
            return;
        }
    };
    if ctx.is_software() {
        assert!(
            matches!(exec, Executor::Cpu),
            "auto picked {}",
            exec.describe()
        );
        assert!(note.contains("software adapter"), "note: {note}");
        // Named, the same adapter is used.
        let name = ctx.info.name.clone();
        let (named, _) = Executor::resolve(BackendChoice::Auto, Some(&name)).unwrap();
        assert!(
            matches!(named, Executor::Gpu(_)),
            "auto with --adapter {name} must use it"
        );
        let (gpu, _) = Executor::resolve(BackendChoice::Gpu, None).unwrap();
        assert!(matches!(gpu, Executor::Gpu(_)), "--backend gpu must use it");
    } else if ctx.is_f64() {
        assert!(
            matches!(exec, Executor::Gpu(_)),
            "auto skipped {}",
            ctx.describe()
        );
        assert!(note.contains("using the GPU"), "note: {note}");
    }
}
