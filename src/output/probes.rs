//! `probes.csv`: the `[[probe]]` nodes of a scene, one row per accepted step (every step,
//! whatever `--every` says), flushed row by row like `history.csv`.
//!
//! Columns: `step,t`, then per probe `NAME_x,NAME_y,NAME_z` (position), `NAME_ux,…`
//! (displacement), `NAME_rx,…` (rotation vector of the node triad against its reference),
//! `NAME_vx,…` (velocity).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::history::fmt_f64;
use super::OutputError;
use crate::integrator::state::State;
use crate::model::Model;
use crate::observe::probe::{node_director_ends, probe_values};
use crate::scene::Probe;

/// Streams `probes.csv`.
#[derive(Debug)]
pub struct ProbeWriter {
    path: PathBuf,
    out: BufWriter<File>,
    probes: Vec<(usize, (usize, usize))>,
    line: String,
}

impl ProbeWriter {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path, model: &Model, probes: &[Probe]) -> Result<Self, OutputError> {
        let file = File::create(path).map_err(|e| OutputError::io(path, e))?;
        let (ends, _) = node_director_ends(model);
        let mut line = String::from("step,t");
        for p in probes {
            for q in ["", "u", "r", "v"] {
                for c in ["x", "y", "z"] {
                    line.push(',');
                    line.push_str(&super::csv_cell(&format!("{}_{q}{c}", p.name)));
                }
            }
        }
        line.push('\n');
        let mut w = Self {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            probes: probes.iter().map(|p| (p.node, ends[p.node])).collect(),
            line,
        };
        w.write_line()?;
        Ok(w)
    }

    /// Appends the row of `step` at time `t`.
    pub fn push(
        &mut self,
        step: usize,
        t: f64,
        model: &Model,
        state: &State,
    ) -> Result<(), OutputError> {
        self.line.clear();
        self.line.push_str(&step.to_string());
        self.line.push(',');
        fmt_f64(t, &mut self.line);
        for &(a, end) in &self.probes {
            let v = probe_values(model, state, a, end);
            for x in [v.position, v.displacement, v.rotation, v.velocity] {
                for c in x.iter() {
                    self.line.push(',');
                    fmt_f64(*c, &mut self.line);
                }
            }
        }
        self.line.push('\n');
        self.write_line()
    }

    fn write_line(&mut self) -> Result<(), OutputError> {
        self.out
            .write_all(self.line.as_bytes())
            .and_then(|()| self.out.flush())
            .map_err(|e| OutputError::io(&self.path, e))
    }
}
