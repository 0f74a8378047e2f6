//! Whether the snapshots `crack RUN` reads are the run's own, as written: each snapshot carries the
//! identity of the run that wrote it, its step and a checksum of its point fields (attributes
//! [`RUN_ID_ATTR`], `step`, [`CHECKSUM_ATTR`]), and run.json lists the snapshots written with the same.
//! Snapshots of runs written before (no attributes, no list) are read unverified. A snapshot that HDF5
//! cannot read is corrupt ([`unreadable`]).

use super::{CHECKSUM_ATTR, CONNECTIVITY, FIELDS, RUN_ID_ATTR, fields_checksum};
use crate::output_file::OutputError;
use crate::rundir::{RUN_FILE, RunRecord, SnapshotRecord};
use crate::schema::file;
use hdf5_metno::types::VarLenUnicode;
use std::path::Path;

/// What a run directory says of its snapshots: its run.json, if it is a readable run record.
pub(super) struct Provenance {
    record: Option<RunRecord>,
}

/// The refusal of the snapshot `path`: `what` is wrong with it.
fn refused(path: &Path, what: String) -> OutputError {
    OutputError::Run {
        path: path.display().to_string(),
        message: format!(
            "{what}: not this run's snapshot as written, nothing was re-measured and crack.json is \
             unchanged"
        ),
    }
}

/// The string attribute `name` of `file`, if present.
fn text_attr(file: &hdf5_metno::File, name: &str) -> Option<String> {
    file.attr(name)
        .and_then(|a| a.read_scalar::<VarLenUnicode>())
        .ok()
        .map(|v| v.as_str().to_owned())
}

impl Provenance {
    /// Reads `dir/run.json` (absent or no run record: nothing to check the snapshots against) and checks
    /// that every snapshot it lists is present.
    pub(super) fn of(dir: &Path) -> Result<Self, OutputError> {
        let record: Option<RunRecord> = crate::input::read_text_input(&dir.join(RUN_FILE))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        for s in record.iter().flat_map(|r| r.snapshots.iter().flatten()) {
            let path = dir.join(&s.file);
            if !path.exists() {
                return Err(refused(
                    &path,
                    format!(
                        "missing: {RUN_FILE} lists it as the snapshot of step {}",
                        s.step
                    ),
                ));
            }
        }
        Ok(Self { record })
    }

    /// The file name of the snapshot at `path` and its entry in run.json, if listed.
    fn listed(&self, path: &Path) -> (String, Option<&SnapshotRecord>) {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let entry = self
            .record
            .as_ref()
            .and_then(|r| r.snapshots.as_ref())
            .and_then(|list| list.iter().find(|s| s.file == name));
        (name, entry)
    }

    /// Checks the identity of the snapshot `file` at `path`: the run that wrote it (as run.json lists it,
    /// else the run's identity) and its step (as its name and run.json say).
    pub(super) fn check_identity(
        &self,
        file: &hdf5_metno::File,
        path: &Path,
    ) -> Result<(), OutputError> {
        let (name, listed) = self.listed(path);
        let expected = listed.and_then(|s| s.run.clone()).or_else(|| {
            self.record
                .as_ref()
                .filter(|r| r.snapshots.is_some())
                .map(|r| r.identity.id.clone())
        });
        match (text_attr(file, RUN_ID_ATTR), expected) {
            (Some(id), Some(run)) if id != run => {
                return Err(refused(
                    path,
                    format!("written by another run (run id {id}; this run's is {run})"),
                ));
            }
            (None, Some(run)) if listed.is_some_and(|s| s.run.is_some()) => {
                return Err(refused(
                    path,
                    format!("carries no run id; {RUN_FILE} lists it as written by run {run}"),
                ));
            }
            _ => {}
        }
        let Ok(step) = file.attr("step").and_then(|a| a.read_scalar::<u64>()) else {
            return Ok(());
        };
        let named = name
            .strip_prefix(file::FIELDS.0)
            .and_then(|n| n.strip_suffix(file::FIELDS.1))
            .and_then(|n| n.parse::<u64>().ok());
        if let Some(named) = named.filter(|&n| n != step) {
            return Err(refused(
                path,
                format!("holds step {step}, its name says step {named} (renamed or copied)"),
            ));
        }
        if let Some(listed) = listed.filter(|s| s.step as u64 != step) {
            return Err(refused(
                path,
                format!(
                    "holds step {step}, {RUN_FILE} lists it as step {}",
                    listed.step
                ),
            ));
        }
        Ok(())
    }

    /// Checks the point fields of the snapshot `file` at `path` against the checksum written into it and
    /// the one run.json lists (either absent: not checked against it).
    pub(super) fn check_checksum(
        &self,
        file: &hdf5_metno::File,
        path: &Path,
    ) -> Result<(), OutputError> {
        let in_file = text_attr(file, CHECKSUM_ATTR);
        let in_record = self.listed(path).1.and_then(|s| s.checksum.clone());
        if in_file.is_none() && in_record.is_none() {
            return Ok(());
        }
        let unreadable = |e: hdf5_metno::Error| unreadable(path, &e);
        let connectivity: Vec<i64> = file
            .dataset(CONNECTIVITY.name)
            .and_then(|d| d.read_raw())
            .map_err(unreadable)?;
        let values = FIELDS
            .iter()
            .map(|f| file.dataset(f.name).and_then(|d| d.read_raw::<f64>()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(unreadable)?;
        let fields: Vec<&[f64]> = values.iter().map(Vec::as_slice).collect();
        let now = fields_checksum(&connectivity, &fields);
        for (written, whose) in [(in_file, "the file's"), (in_record, "run.json's")] {
            if let Some(written) = written.filter(|w| *w != now) {
                return Err(refused(
                    path,
                    format!(
                        "its point fields changed after writing (checksum {now}, {whose} record \
                         {written})"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// A snapshot that HDF5 cannot read (not an HDF5 file, a missing dataset or attribute) is corrupt: the
/// error of the snapshot at `path`, as a bad input.
pub(super) fn unreadable(path: &Path, e: &hdf5_metno::Error) -> OutputError {
    let detail = e.to_string().replace('\n', " ");
    OutputError::Run {
        path: path.display().to_string(),
        message: format!(
            "not readable as a snapshot ({}): the snapshot is corrupt, nothing was re-measured and \
             crack.json is unchanged",
            detail.trim()
        ),
    }
}
