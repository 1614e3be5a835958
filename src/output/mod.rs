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

pub use history::{read_history, HistoryWriter, HISTORY_COLUMNS};
pub(crate) use plot::{ensure_font, FONT};
pub use plot::{plot_accelerations, plot_comparison, plot_energy, plot_momenta, LabelledHistory};
pub use probes::ProbeWriter;
pub use progress::Progress;
pub use snapshot::{animate_snapshots, plot_snapshots, Snapshot};
pub use summary::write_summary;
pub use trajectory::{CosseratBenchResult, OutputTimes, TrajectoryRecorder};
pub use vtk::VtkSeries;

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
