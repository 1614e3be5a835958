//! Output writers: `history.csv` (streamed row by row), `summary.json`, `trajectory.npz`,
//! VTK frames, the energy and momentum charts, and the terminal progress bar of the time
//! loop.
//!
//! Every fallible function returns [`OutputError`], which always names the file involved.

use std::path::PathBuf;

mod history;
mod plot;
mod probes;
mod progress;
mod snapshot;
mod summary;
mod trajectory;
mod vtk;

pub use history::{history_values, read_history, HistoryWriter, HISTORY_COLUMNS};
pub(crate) use plot::{ensure_font, FONT};
pub use plot::{plot_accelerations, plot_comparison, plot_energy, plot_momenta, LabelledHistory};
pub use probes::ProbeWriter;
pub use progress::Progress;
pub use snapshot::{animate_snapshots, plot_snapshots, Snapshot};
pub use summary::write_summary;
pub use trajectory::{CosseratBenchOptions, CosseratBenchResult, OutputTimes, TrajectoryRecorder};
pub use vtk::VtkSeries;

/// `v` as the shortest text that reads back as the identical `f64`, in plain notation for
/// magnitudes in `[1e-5, 1e16)` and in scientific notation otherwise (as `history.csv`
/// writes numbers): at most 24 characters, so every number an error message echoes stays
/// short (`5e-324`, not 324 digits).
///
/// ```
/// use cosserat::output::num;
/// assert_eq!(num(0.1), "0.1");
/// assert_eq!(num(5e-324), "5e-324");
/// assert_eq!(num(-1e300), "-1e300");
/// assert_eq!(num(f64::NEG_INFINITY), "-inf");
/// ```
pub fn num(v: f64) -> String {
    let mut s = String::new();
    history::fmt_f64(v, &mut s);
    s
}

/// `text` as one CSV cell (RFC 4180): as is when it holds no `,`, `"`, CR or LF, else in
/// double quotes with every `"` doubled. Every text cell of a CSV file the outputs write
/// goes through here, so a name can never add a column or a row.
///
/// ```
/// use cosserat::output::csv_cell;
/// assert_eq!(csv_cell("tip_x"), "tip_x");
/// assert_eq!(csv_cell("a,b"), "\"a,b\"");
/// assert_eq!(csv_cell("say \"hi\"\r\n"), "\"say \"\"hi\"\"\r\n\"");
/// ```
pub fn csv_cell(text: &str) -> std::borrow::Cow<'_, str> {
    if text.contains([',', '"', '\r', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\"")).into()
    } else {
        text.into()
    }
}

/// Errors of the output writers. Every variant names the file it concerns.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing or reading a file failed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// A `history.csv` could not be parsed.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (1 is the header).
        line: usize,
        /// What is wrong with the line.
        message: String,
    },
    /// Serializing `summary.json` failed.
    #[error("{}: cannot serialize summary: {error}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The underlying serde error.
        error: serde_json::Error,
    },
    /// Writing a `.npz` archive failed.
    #[error("{}: cannot write npz: {message}", path.display())]
    Npz {
        /// The file.
        path: PathBuf,
        /// What the npz writer reported.
        message: String,
    },
    /// Drawing or encoding a chart failed.
    #[error("{}: cannot draw chart: {message}", path.display())]
    Plot {
        /// The file.
        path: PathBuf,
        /// What the plotting library reported.
        message: String,
    },
}

impl OutputError {
    pub(crate) fn io(path: &std::path::Path, error: std::io::Error) -> Self {
        OutputError::Io {
            path: path.to_path_buf(),
            error,
        }
    }
}
