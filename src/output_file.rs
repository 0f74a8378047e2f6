//! Writing an output file whole: [`write_atomic`] (a temporary file renamed into place, never left
//! half-written) and the error of writing the run's files ([`OutputError`], naming the file). Both the
//! run's results (`io`, which re-exports them) and its record (`rundir`) use them: `rundir` writes
//! `run.json` without `io`, which uses `rundir`'s records.

use std::path::{Path, PathBuf};

/// Output failure, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The run directory cannot be re-measured (not a CT run, no snapshots, unreadable config).
    #[error("{path}: {message}")]
    Run {
        /// File or directory.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// HDF5 error.
    #[error("{path}: HDF5: {message}")]
    Hdf5 {
        /// File.
        path: String,
        /// Cause.
        message: String,
    },
    /// The processes could not exchange what a file needs (a collective write of several processes).
    #[error("{path}: between the processes: {message}")]
    Exchange {
        /// File.
        path: String,
        /// Cause.
        message: String,
    },
    /// Plotting error.
    #[error("{path}: {message}")]
    Plot {
        /// File.
        path: String,
        /// Cause.
        message: String,
    },
}

impl OutputError {
    /// An HDF5 error `e` on the file `path`, in one line: a failed write by the system's message (HDF5's
    /// own spans several lines with buffer addresses), other errors with their whitespace collapsed.
    pub fn hdf5(path: &Path, e: &hdf5_metno::Error) -> Self {
        let text = e.to_string();
        let system = text
            .split_once("error message = '")
            .and_then(|(_, rest)| rest.split_once('\''))
            .map(|(m, _)| format!("writing failed: {m}"));
        OutputError::Hdf5 {
            path: path.display().to_string(),
            message: system
                .unwrap_or_else(|| text.split_whitespace().collect::<Vec<_>>().join(" ")),
        }
    }
}

/// The error of an exchange between the processes for the file `path`.
pub(crate) fn exchange_err<E: std::fmt::Display>(
    path: &Path,
) -> impl FnOnce(E) -> OutputError + '_ {
    move |e| OutputError::Exchange {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The error of a file-system operation on `path`.
pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
/// A failed write removes its temporary (a full disk leaves nothing half-written behind).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let tmp = tmp_name(path);
    if let Err(e) = std::fs::write(&tmp, bytes) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_err(path)(e));
    }
    std::fs::rename(&tmp, path).map_err(io_err(path))
}

/// The temporary name `NAME.tmp` under which `path` is written before it is renamed into place.
pub(crate) fn tmp_name(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}
