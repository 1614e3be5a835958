//! `cosserat reproduce --quick`: every run gets its folder with the run files, snapshots
//! and VTK; the comparison figures and REPORT.md are written; the report has one row per
//! run with the documented columns and embeds figures that exist, and records each run's
//! cut-back steps as its summary.json does.
use std::process::Command;

#[test]
fn reproduce_quick_writes_every_run_figures_vtk_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rep");
    let st = Command::new(env!("CARGO_BIN_EXE_cosserat"))
        .args(["reproduce", "--quick", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let runs = cosserat::reproduce::paper_runs(true);
    for r in &runs {
        let d = out.join(r.scene).join(&r.folder);
        for f in [
            "history.csv",
            "summary.json",
            "energy.png",
            "momenta.png",
            "accelerations.png",
            "snapshots.png",
        ] {
            let len = std::fs::metadata(d.join(f)).map(|m| m.len()).unwrap_or(0);
            assert!(len > 100, "{}/{f}: {len} bytes", d.display());
        }
        let pvd = std::fs::read_to_string(d.join("vtk").join(format!("{}.pvd", r.scene))).unwrap();
        let frames: Vec<&str> = pvd.lines().filter(|l| l.contains("<DataSet")).collect();
        assert!(
            frames.len() >= 2,
            "{}: {} VTK frames",
            d.display(),
            frames.len()
        );
        // Every listed frame exists and is a well-formed line mesh.
        let first = frames[0]
            .split("file=\"")
            .nth(1)
            .unwrap()
            .trim_end_matches("\"/>");
        // Binary appended data: the tags are in the XML head.
        let vtu = String::from_utf8_lossy(&std::fs::read(d.join("vtk").join(first)).unwrap())
            .into_owned();
        for tag in [
            "<Points>",
            "Name=\"velocity\"",
            "Name=\"d1\"",
            "Name=\"d3\"",
            "Name=\"strain_Gamma\"",
            "Name=\"strain_Omega\"",
            "Name=\"N\"",
            "Name=\"M\"",
            "</VTKFile>",
        ] {
            assert!(vtu.contains(tag), "{first}: missing {tag}");
        }
    }
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    for col in [
        "scheme",
        "α",
        "Δt",
        "status",
        "t_reached",
        "max rel. ΔL/step",
        "max rel. ΔJ/step",
        "D = W − ΔH",
        "max \\|g\\|",
        "cut-back steps",
    ] {
        assert!(report.contains(col), "REPORT.md lacks column {col}");
    }
    let rows = report
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| scene"))
        .count();
    assert_eq!(rows, runs.len(), "one row per run");
    // Whether any step was cut back: each row's cell is its summary.json's count, marked
    // `(off)` where cut-back was off (the paper's fixed steps), and the header says so.
    let header: Vec<&str> = report
        .lines()
        .find(|l| l.starts_with("| scene"))
        .unwrap()
        .split(" | ")
        .collect();
    let col = header.iter().position(|c| *c == "cut-back steps").unwrap();
    for r in &runs {
        let link = format!("]({}/{}/)", r.scene, r.folder);
        let row = report.lines().find(|l| l.contains(&link)).unwrap();
        let cell = row.split(" | ").nth(col).unwrap();
        let sm: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(r.scene).join(&r.folder).join("summary.json"))
                .unwrap(),
        )
        .unwrap();
        let n = sm["cutback_steps"].as_u64().unwrap();
        let want = if sm["params"]["cutback"].as_u64().unwrap() == 0 {
            format!("{n} (off)")
        } else {
            n.to_string()
        };
        assert_eq!(cell, want, "{link}: cut-back steps");
    }
    assert!(
        report.contains("no step is cut back (`cutback = 0`)"),
        "the header states the cut-back setting"
    );
    // Every embedded figure exists.
    for part in report.split("](").skip(1) {
        let target = part.split(')').next().unwrap();
        if target.ends_with(".png") {
            assert!(
                out.join(target).exists(),
                "REPORT.md embeds missing {target}"
            );
        }
    }
    // The observed outcomes are in the report, not just the paper's.
    assert!(
        report.contains("**failed**"),
        "the square mechanism's failures at Δt = 0.05 are reported"
    );
}
