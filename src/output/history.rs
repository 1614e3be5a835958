//! `history.csv`: one row per time level, streamed while the run goes on.
//!
//! `t` is `t_0 + step·Δt` exactly; `work_total` and `dissipation_total` are running sums
//! over every accepted step, so even a thinned history (`--every k`) closes the energy
//! balance `total − total₀ = work_total − dissipation_total` row by row.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use super::OutputError;
use crate::model::Vec3;
use crate::observe::record::StepRecord;

/// The header of `history.csv`, in column order.
pub const HISTORY_COLUMNS: &[&str] = &[
    "step",
    "t",
    "kinetic",
    "potential",
    "total",
    "Lx",
    "Ly",
    "Lz",
    "Jx",
    "Jy",
    "Jz",
    "dissipation",
    "external_work",
    "acc_trans",
    "acc_rot",
    "newton_iters",
    "outer_iters",
    "residual",
    "max_link_g",
    "work_total",
    "dissipation_total",
    "fallback",
    "substeps",
    "support_work",
    "friction",
];

/// Streams `history.csv`: the header is written on [`create`](Self::create), one row per
/// [`push`](Self::push), and the file is flushed after every row, so a crash or a failed
/// run keeps every row written so far.
#[derive(Debug)]
pub struct HistoryWriter {
    path: PathBuf,
    out: BufWriter<File>,
    line: String,
}

impl HistoryWriter {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path) -> Result<Self, OutputError> {
        let file = File::create(path).map_err(|e| OutputError::io(path, e))?;
        let mut writer = Self {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            line: String::with_capacity(512),
        };
        writer.line.push_str(&HISTORY_COLUMNS.join(","));
        writer.line.push('\n');
        writer.write_line()?;
        Ok(writer)
    }

    /// Appends one row and flushes it to the operating system.
    pub fn push(&mut self, r: &StepRecord) -> Result<(), OutputError> {
        self.line.clear();
        format_row(r, &mut self.line);
        self.write_line()
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_line(&mut self) -> Result<(), OutputError> {
        self.out
            .write_all(self.line.as_bytes())
            .and_then(|()| self.out.flush())
            .map_err(|e| OutputError::io(&self.path, e))
    }
}

/// Shortest decimal text that parses back to the identical `f64`: plain notation for
/// moderate magnitudes, scientific otherwise (`NaN`, `inf`, `-inf` for non-finite values).
pub(crate) fn fmt_f64(v: f64, out: &mut String) {
    use std::fmt::Write as _;
    let a = v.abs();
    // Both `{}` and `{:e}` print the shortest round-trip representation.
    let _ = if v == 0.0 || !v.is_finite() || (1e-5..1e16).contains(&a) {
        write!(out, "{v}")
    } else {
        write!(out, "{v:e}")
    };
}

/// The values of one record in [`HISTORY_COLUMNS`] order (counts and the fallback flag as
/// exact small integers): the one mapping of a record to the history's columns, for
/// `history.csv` and for callers that tabulate records themselves (the Python bindings).
pub fn history_values(r: &StepRecord) -> [f64; 25] {
    [
        r.step as f64,
        r.t,
        r.kinetic,
        r.potential,
        r.total,
        r.l.x,
        r.l.y,
        r.l.z,
        r.j.x,
        r.j.y,
        r.j.z,
        r.dissipation,
        r.external_work,
        r.acc_trans,
        r.acc_rot,
        r.newton_iters as f64,
        r.outer_iters as f64,
        r.residual,
        r.max_link_g,
        r.work_total,
        r.dissipation_total,
        f64::from(u8::from(r.fallback)),
        r.substeps as f64,
        r.support_work,
        r.friction,
    ]
}

/// One row of `history.csv`. Integers below 2^53 print as integers (`{}` of an integral
/// `f64` has no fraction), so the row is the same text as formatting each field by type.
fn format_row(r: &StepRecord, out: &mut String) {
    for (k, v) in history_values(r).into_iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        fmt_f64(v, out);
    }
    out.push('\n');
}

/// Reads a `history.csv` written by [`HistoryWriter`] back. The header must equal
/// [`HISTORY_COLUMNS`]; errors name the file and the 1-based line.
pub fn read_history(path: &Path) -> Result<Vec<StepRecord>, OutputError> {
    let file = File::open(path).map_err(|e| OutputError::io(path, e))?;
    let parse_err = |line: usize, message: String| OutputError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut records = Vec::new();
    let mut header_seen = false;
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let lineno = i + 1;
        let line = line.map_err(|e| OutputError::io(path, e))?;
        let line = line.trim_end_matches('\r');
        if !header_seen {
            let cols: Vec<&str> = line.split(',').map(str::trim).collect();
            if cols != HISTORY_COLUMNS {
                return Err(parse_err(
                    lineno,
                    format!(
                        "header is not a history.csv header (expected `{}`)",
                        HISTORY_COLUMNS.join(",")
                    ),
                ));
            }
            header_seen = true;
            continue;
        }
        if line.trim().is_empty() {
            continue;
        }
        records.push(parse_row(line).map_err(|m| parse_err(lineno, m))?);
    }
    if !header_seen {
        return Err(parse_err(1, "empty file, no header".into()));
    }
    Ok(records)
}

fn parse_row(line: &str) -> Result<StepRecord, String> {
    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
    if fields.len() != HISTORY_COLUMNS.len() {
        return Err(format!(
            "expected {} fields, found {}",
            HISTORY_COLUMNS.len(),
            fields.len()
        ));
    }
    let int = |k: usize| -> Result<usize, String> {
        fields[k].parse::<usize>().map_err(|e| {
            format!(
                "column {} `{}`: `{}` is not a count ({e})",
                k + 1,
                HISTORY_COLUMNS[k],
                fields[k]
            )
        })
    };
    let flt = |k: usize| -> Result<f64, String> {
        fields[k].parse::<f64>().map_err(|e| {
            format!(
                "column {} `{}`: `{}` is not a number ({e})",
                k + 1,
                HISTORY_COLUMNS[k],
                fields[k]
            )
        })
    };
    Ok(StepRecord {
        step: int(0)?,
        t: flt(1)?,
        kinetic: flt(2)?,
        potential: flt(3)?,
        total: flt(4)?,
        l: Vec3::new(flt(5)?, flt(6)?, flt(7)?),
        j: Vec3::new(flt(8)?, flt(9)?, flt(10)?),
        dissipation: flt(11)?,
        external_work: flt(12)?,
        acc_trans: flt(13)?,
        acc_rot: flt(14)?,
        newton_iters: int(15)?,
        outer_iters: int(16)?,
        residual: flt(17)?,
        max_link_g: flt(18)?,
        work_total: flt(19)?,
        dissipation_total: flt(20)?,
        fallback: match fields[21] {
            "0" => false,
            "1" => true,
            other => return Err(format!("column 22 `fallback`: `{other}` is not 0 or 1")),
        },
        substeps: int(22)?,
        support_work: flt(23)?,
        friction: flt(24)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(step: usize, seed: f64) -> StepRecord {
        StepRecord {
            step,
            t: step as f64 * 0.1,
            kinetic: seed.sin().abs() * 1e-7 + 1.0 / 3.0,
            potential: std::f64::consts::PI * seed,
            total: 9.166666666666666 + seed * 1e-15,
            l: Vec3::new(1e-300 * seed, -0.0, 123456789012345680000.0),
            j: Vec3::new(f64::MIN_POSITIVE, f64::MAX, -seed / 7.0),
            dissipation: 5e-324,
            external_work: -1.0e-5 * seed,
            support_work: 2.5e-7 * seed,
            friction: 4.5e-9 * seed,
            work_total: -3.0e-5 * seed * seed,
            dissipation_total: 0.1 * step as f64 + 1e-17,
            acc_trans: 0.1 + 0.2,
            acc_rot: 1e16 + seed,
            newton_iters: 3 + step,
            outer_iters: 1,
            residual: 1.234e-12 * seed,
            max_link_g: 3e-11 * seed,
            fallback: step % 3 == 1,
            substeps: step % 5,
        }
    }

    fn bits(r: &StepRecord) -> Vec<u64> {
        [
            r.t,
            r.kinetic,
            r.potential,
            r.total,
            r.l.x,
            r.l.y,
            r.l.z,
            r.j.x,
            r.j.y,
            r.j.z,
            r.dissipation,
            r.external_work,
            r.acc_trans,
            r.acc_rot,
            r.residual,
            r.max_link_g,
            r.work_total,
            r.dissipation_total,
        ]
        .iter()
        .map(|v| v.to_bits())
        .collect()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("history.csv");
        let recs: Vec<StepRecord> = (0..50).map(|i| record(i, 0.37 * i as f64 + 0.01)).collect();
        {
            let mut w = HistoryWriter::create(&path).unwrap();
            for r in &recs {
                w.push(r).unwrap();
            }
        }
        let back = read_history(&path).unwrap();
        assert_eq!(back.len(), recs.len());
        for (a, b) in recs.iter().zip(&back) {
            assert_eq!(a.step, b.step);
            assert_eq!(a.newton_iters, b.newton_iters);
            assert_eq!(a.outer_iters, b.outer_iters);
            assert_eq!(bits(a), bits(b), "row {}", a.step);
        }
    }

    #[test]
    fn non_finite_values_survive() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("history.csv");
        let mut r = record(0, 1.0);
        r.kinetic = f64::NAN;
        r.potential = f64::INFINITY;
        r.total = f64::NEG_INFINITY;
        let mut w = HistoryWriter::create(&path).unwrap();
        w.push(&r).unwrap();
        let back = read_history(&path).unwrap();
        assert!(back[0].kinetic.is_nan());
        assert_eq!(back[0].potential, f64::INFINITY);
        assert_eq!(back[0].total, f64::NEG_INFINITY);
    }

    #[test]
    fn header_equals_columns() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("history.csv");
        drop(HistoryWriter::create(&path).unwrap());
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, format!("{}\n", HISTORY_COLUMNS.join(",")));
        assert_eq!(HISTORY_COLUMNS.len(), 25);
        assert!(read_history(&path).unwrap().is_empty());
    }

    #[test]
    fn rows_are_flushed_while_writer_is_alive() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("history.csv");
        let mut w = HistoryWriter::create(&path).unwrap();
        for i in 0..3 {
            w.push(&record(i, 1.0 + i as f64)).unwrap();
            let back = read_history(&path).unwrap();
            assert_eq!(back.len(), i + 1);
            assert_eq!(bits(&back[i]), bits(&record(i, 1.0 + i as f64)));
        }
        drop(w);
    }

    #[test]
    fn errors_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("history.csv");
        let mut w = HistoryWriter::create(&path).unwrap();
        w.push(&record(0, 1.0)).unwrap();
        drop(w);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("1,0.1,abc\n");
        std::fs::write(&path, text).unwrap();
        let msg = read_history(&path).unwrap_err().to_string();
        assert!(msg.contains("history.csv:3:"), "{msg}");

        std::fs::write(&path, "step,t\n").unwrap();
        let msg = read_history(&path).unwrap_err().to_string();
        assert!(msg.contains("history.csv:1:"), "{msg}");

        let missing = dir.path().join("nope.csv");
        let msg = read_history(&missing).unwrap_err().to_string();
        assert!(msg.contains("nope.csv"), "{msg}");

        let bad_field = "1,0.1,abc".to_string() + &",0".repeat(HISTORY_COLUMNS.len() - 3);
        std::fs::write(
            &path,
            format!("{}\n{bad_field}\n", HISTORY_COLUMNS.join(",")),
        )
        .unwrap();
        let msg = read_history(&path).unwrap_err().to_string();
        assert!(msg.contains(":2:") && msg.contains("kinetic"), "{msg}");
    }
}
