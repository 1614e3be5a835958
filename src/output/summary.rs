//! `summary.json`: the run's [`RunSummary`] as pretty-printed JSON.

use std::path::Path;

use super::OutputError;
use crate::observe::record::RunSummary;

/// Writes `s` as pretty-printed JSON (with a trailing newline). Non-finite numbers are
/// written as the strings `"NaN"`, `"inf"`, `"-inf"` ([`RunSummary`]), never as `null`.
pub fn write_summary(path: &Path, s: &RunSummary) -> Result<(), OutputError> {
    let mut text = serde_json::to_string_pretty(s).map_err(|error| OutputError::Json {
        path: path.to_path_buf(),
        error,
    })?;
    text.push('\n');
    std::fs::write(path, text).map_err(|e| OutputError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::params::{IntegratorParams, Scheme};
    use crate::observe::record::RunStatus;

    fn summary(status: RunStatus) -> RunSummary {
        RunSummary {
            scene: "scenes/pendulum.toml".into(),
            status,
            t_reached: 1.25,
            steps: 125,
            reason: (status == RunStatus::Failed).then(|| "Newton did not converge".into()),
            failed_step_residuals: vec![1.0, 0.5, f64::NAN],
            wall_s: 0.75,
            scheme: "edmc1".into(),
            params: IntegratorParams::new(
                Scheme::Edmc1 {
                    chi_gamma: 0.1,
                    chi_omega: 0.1,
                    chi_v: 0.0,
                    chi_nu: 0.0,
                },
                0.01,
                2.0,
            ),
            nodes: 11,
            elements: 10,
            dofs: 60,
            newton_iters_total: 400,
            max_rel_dl: 1e-15,
            max_rel_dj: 2e-15,
            energy_balance: Default::default(),
            impulse_balance: Default::default(),
            last_accepted: Default::default(),
            outputs: vec!["history.csv".into()],
            max_link_g: 0.0,
            fallback_steps: 0,
            cutback_steps: 0,
            smallest_substep: None,
            accepted: Default::default(),
            backend: "cpu".into(),
            strategy: Some("monolithic".into()),
            linear_solver: "block-tridiagonal-6".into(),
            solve: "host".into(),
            linear_solver_fallbacks: 0,
            timers: Default::default(),
            energy_initial: 9.166666666666666,
            energy_final: f64::NAN,
        }
    }

    #[test]
    fn summary_has_required_keys() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.json");
        write_summary(&path, &summary(RunStatus::Failed)).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\n  \""), "pretty-printed");
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        for key in [
            "status",
            "t_reached",
            "steps",
            "reason",
            "wall_s",
            "scheme",
            "params",
            "energy_balance",
            "impulse_balance",
            "last_accepted",
            "outputs",
        ] {
            assert!(v.get(key).is_some(), "missing key {key}");
        }
        assert_eq!(v["status"], "failed");
        assert_eq!(v["reason"], "Newton did not converge");
        assert_eq!(v["steps"], 125);
        assert_eq!(v["energy_final"], "NaN");
        assert_eq!(v["energy_initial"], 9.166666666666666);
        assert_eq!(
            v["failed_step_residuals"],
            serde_json::json!([1.0, 0.5, "NaN"])
        );
        assert_eq!(v["params"]["dt"], 0.01);
        assert_eq!(v["params"]["scheme"]["name"], "edmc1");
    }

    #[test]
    fn completed_run_has_null_reason() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.json");
        write_summary(&path, &summary(RunStatus::Completed)).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(v["status"], "completed");
        assert!(v["reason"].is_null());
    }

    #[test]
    fn unwritable_path_names_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no_such_dir").join("summary.json");
        let msg = write_summary(&path, &summary(RunStatus::Completed))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("no_such_dir"), "{msg}");
    }
}
