//! An adapter without `SHADER_F64` cannot run the batch integrator (f32 cannot reach the
//! Newton tolerance): `--backend gpu` refuses it with exit code 2 and the reason, and
//! `--backend auto` runs on the CPU saying why. `COSSERAT_GPU_NO_F64` makes any adapter
//! look like one without f64. Without an adapter the test prints `skipped`, unless
//! `COSSERAT_REQUIRE_GPU` is set, in which case it fails.

use std::process::Command;

use cosserat::gpu::{gpu_required, GpuContext};

fn cosserat(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(args)
        .env("COSSERAT_GPU_NO_F64", "1")
        .output()
        .unwrap()
}

#[test]
fn an_adapter_without_f64_is_refused_by_name() {
    if let Err(e) = GpuContext::new(None) {
        assert!(
            !gpu_required(),
            "COSSERAT_REQUIRE_GPU is set but no adapter: {e}"
        );
        println!("skipped: no adapter ({e})");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gpu");
    let o = cosserat(&[
        "run",
        "frame",
        "--backend",
        "gpu",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert!(
        err.contains("f32 (no SHADER_F64)")
            && err.contains(
                "the batch integrator needs SHADER_F64 (f32 cannot reach the Newton tolerance)"
            ),
        "stderr: {err}"
    );
    assert!(
        !out.join("history.csv").exists(),
        "a refused run wrote outputs"
    );
    // `auto` falls back to the CPU and says so.
    let auto = dir.path().join("auto");
    let o = cosserat(&[
        "run",
        "frame",
        "--backend",
        "auto",
        "--out",
        auto.to_str().unwrap(),
    ]);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{text}");
    assert!(
        text.contains("needs SHADER_F64"),
        "auto must say why: {text}"
    );
    assert!(auto.join("history.csv").exists());
}
