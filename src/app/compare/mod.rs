//! `mpm-concrete compare`: cross-checks a finished run against reference data and gates scripts by the
//! exit code (0: every relative error within the tolerance, 1: some error above it, 2: bad input).
//!
//! Two kinds of reference file (CSV, `#` comment lines and blank lines allowed anywhere, no quoting),
//! recognised by the header:
//!
//! * history reference, `time,<col>[,<col>...]`: each `<col>` is a column of the run's `history.csv`,
//!   interpolated linearly in time at the reference times;
//! * point reference, `time,x,y,quantity,value`: a point field at a point of the reference (initial)
//!   configuration, taken from the snapshot `fields_NNNNNN.h5` nearest in time and evaluated by a local
//!   linear least-squares fit over the nearest material points (reference positions
//!   `X = position - displacement`), which reproduces a linear field exactly.
//!
//! See `docs/cross-check.md` for the metrics and the rules.

mod csv;
mod metrics;
mod numerics;
mod reference;
mod report;
mod run_data;
#[cfg(test)]
mod tests;

pub use metrics::relative_errors;
pub use numerics::{PointIndex, default_time_tolerance, interpolate, linear_fit};
pub use reference::{
    HistoryReference, POINT_HEADER, PointReference, PointRow, QUANTITIES, Reference,
    parse_reference,
};
pub use report::{
    ColumnReport, GroupReport, HistoryValue, Peak, PointValue, ReferenceReport, Report,
};

use metrics::{compare_history, compare_points};
use run_data::{RunHistory, Snapshots};
use std::path::{Path, PathBuf};

/// Command-line arguments of the `compare` subcommand.
#[derive(clap::Args, Clone, Debug)]
pub struct CompareArgs {
    /// Run directory (`history.csv`, `fields_*.h5`).
    pub run_dir: PathBuf,
    /// Reference files (CSV): `time,<history column>...` or `time,x,y,quantity,value`.
    #[arg(required = true, value_name = "REF.csv")]
    pub references: Vec<PathBuf>,
    /// Largest accepted relative error (relative L2 and relative max of every column or point group).
    #[arg(long, default_value_t = 0.01)]
    pub tolerance: f64,
    /// Also write the metrics to this JSON file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Material points in the local linear fit of point references.
    #[arg(long, default_value_t = 12)]
    pub neighbours: usize,
    /// Largest time difference (s) between a reference time and a snapshot, or beyond the ends of the
    /// history [default: 1e-9 max(1, |t|)].
    #[arg(long, value_name = "SECONDS")]
    pub time_tolerance: Option<f64>,
}

/// Bad input (a missing or malformed file, an unknown column or quantity, ...): one line naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// An [`InputError`] with the message `msg`.
fn bad(msg: impl Into<String>) -> InputError {
    InputError(msg.into())
}

type Result<T> = std::result::Result<T, InputError>;

/// What `compare` needs besides the files.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Largest accepted relative error.
    pub tolerance: f64,
    /// Points in the local fit.
    pub neighbours: usize,
    /// Fixed time tolerance (s); None: [`default_time_tolerance`].
    pub time_tolerance: Option<f64>,
}

impl Settings {
    /// The time tolerance at time `t` (s).
    fn time_tol(&self, t: f64) -> f64 {
        self.time_tolerance
            .unwrap_or_else(|| default_time_tolerance(t))
    }
}

/// Compares the run in `run_dir` with every reference file.
pub fn compare(run_dir: &Path, references: &[PathBuf], s: &Settings) -> Result<Report> {
    check_settings(run_dir, s)?;
    // Read and check every reference before any comparison.
    let parsed = read_references(references)?;
    let mut history: Option<RunHistory> = None;
    let mut snaps = Snapshots::new(run_dir);
    let mut reports = Vec::with_capacity(parsed.len());
    let mut failures = Vec::new();
    let mut checked = 0;
    let tol = s.tolerance;
    for r in &parsed {
        let report = match r {
            Reference::History(h) => {
                let run = match &mut history {
                    Some(run) => run,
                    None => history.insert(RunHistory::read(run_dir)?),
                };
                let columns = compare_history(h, run, s)?;
                let (file, rows) = (h.file.clone(), h.rows.len());
                ReferenceReport::History {
                    file,
                    rows,
                    columns,
                }
            }
            Reference::Point(p) => {
                let groups = compare_points(p, &mut snaps, s)?;
                let (file, rows) = (p.file.clone(), p.rows.len());
                ReferenceReport::Point { file, rows, groups }
            }
        };
        checked += report.checked();
        failures.extend(report.failures(tol));
        reports.push(report);
    }
    Ok(Report {
        run: run_dir.display().to_string(),
        tolerance: tol,
        passed: failures.is_empty(),
        checked,
        references: reports,
        failures,
    })
}

/// Refuses settings out of range and a run directory that is not a directory.
fn check_settings(run_dir: &Path, s: &Settings) -> Result<()> {
    if !(s.tolerance.is_finite() && s.tolerance >= 0.0) {
        return Err(bad(format!(
            "--tolerance {}: a relative error >= 0",
            s.tolerance
        )));
    }
    if s.neighbours < 3 {
        return Err(bad(format!(
            "--neighbours {}: at least 3 points (a plane)",
            s.neighbours
        )));
    }
    if let Some(t) = s.time_tolerance.filter(|t| !(t.is_finite() && *t >= 0.0)) {
        return Err(bad(format!("--time-tolerance {t}: a time >= 0 (s)")));
    }
    if !run_dir.is_dir() {
        return Err(bad(format!(
            "{}: not a directory (expected a run directory with history.csv and fields_*.h5)",
            run_dir.display()
        )));
    }
    Ok(())
}

/// Reads and parses every reference file; the first bad one is the error.
fn read_references(references: &[PathBuf]) -> Result<Vec<Reference>> {
    references
        .iter()
        .map(|p| {
            let text = crate::input::read_text_input(p).map_err(|e| bad(e.to_string()))?;
            parse_reference(&text, &p.display().to_string())
        })
        .collect()
}

/// The `compare` subcommand: prints the table, writes the JSON, returns the exit code (0 pass, 1 fail,
/// 2 bad input). `extra` are arguments that were split off as PETSc options (there must be none).
pub fn run_cli(args: &CompareArgs, extra: &[String]) -> u8 {
    let result = (|| -> Result<Report> {
        if !extra.is_empty() {
            return Err(bad(format!(
                "compare takes no PETSc options (got `{}`)",
                extra.join(" ")
            )));
        }
        let settings = Settings {
            tolerance: args.tolerance,
            neighbours: args.neighbours,
            time_tolerance: args.time_tolerance,
        };
        let report = compare(&args.run_dir, &args.references, &settings)?;
        if let Some(path) = &args.json {
            let text = serde_json::to_string_pretty(&report)
                .map_err(|e| bad(format!("{}: {e}", path.display())))?;
            crate::io::write_atomic(path, text.as_bytes())
                .map_err(|e| bad(format!("cannot write the JSON report: {e}")))?;
        }
        Ok(report)
    })();
    match result {
        Ok(report) => {
            print!("{}", report.table());
            if report.passed { 0 } else { 1 }
        }
        Err(e) => {
            eprintln!("error: {e}");
            2
        }
    }
}
