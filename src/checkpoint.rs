//! Checkpoint and restart: the complete committed state of a run (every particle column, the rigid bodies,
//! the counters) and what its output has recorded so far, in one HDF5 file `checkpoint.h5` written
//! atomically at every output step, when a run is interrupted and when a step fails for good. A resumed run
//! continues bit for bit on the same number of processes: the step is deterministic (assembly by gather,
//! ordered reductions), so it ends with the same results as an uninterrupted one. The checkpoint holds the
//! whole state, so it also resumes on another number of processes (then equal to the solvers' tolerance,
//! docs/theory.md "Processes").
//!
//! A checkpoint proves what it holds: it carries the run's identity ([`RunIdentity`]: the effective
//! configuration, program version and PETSc options) and every dataset carries a CRC-32 of its values in an
//! attribute `crc32`. [`load`] reads and verifies every dataset before it changes anything, so a damaged
//! file is reported as corrupt and never loaded.

use crate::contact::{ContactMemory, ContactRecord};
use crate::io::{Layout, OutputError, RunOutput, SharedCrc, SharedFile, SharedState};
use crate::model::{Counters, EnergyBooks, Method, Model, State};
use crate::output_file::exchange_err;
use crate::rundir::RunIdentity;
use nalgebra::SVector;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// File name of the checkpoint inside the output directory.
pub const FILE: &str = crate::schema::file::CHECKPOINT;

/// Layout version written into `meta` (checkpoints without it predate checksums).
const FORMAT: u64 = 2;

/// A checkpoint that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// There is no checkpoint.
    #[error("{path}: no checkpoint to resume from (start the run without --resume)")]
    Missing {
        /// The expected file.
        path: String,
    },
    /// The file is damaged: unreadable, or a dataset does not match its checksum.
    #[error("{path}: the checkpoint is corrupt ({detail}); nothing was loaded")]
    Corrupt {
        /// The file.
        path: String,
        /// What is wrong.
        detail: String,
    },
    /// The file is intact but cannot be used with this program or configuration.
    #[error("{path}: {detail}")]
    Unusable {
        /// The file.
        path: String,
        /// Why.
        detail: String,
    },
}

/// The state of a rigid body's points that moves with it (the rest comes from the configuration).
const RIGID_COLUMNS: [&str; 2] = ["x", "corners"];

fn flat<const D: usize>(v: &[SVector<f64, D>]) -> Vec<f64> {
    v.iter().flat_map(|x| x.iter().copied()).collect()
}

fn unflat<const D: usize>(f: &[f64]) -> Vec<SVector<f64, D>> {
    f.chunks_exact(D).map(SVector::from_column_slice).collect()
}

/// CRC-32 of the little-endian bytes of `data`.
fn crc_f64(data: &[f64]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    let mut bytes = Vec::with_capacity(8 * 4096);
    for chunk in data.chunks(4096) {
        bytes.clear();
        bytes.extend(chunk.iter().flat_map(|v| v.to_le_bytes()));
        h.update(&bytes);
    }
    h.finalize()
}

/// Writes the state of `shared`, the records of `out` and the run's `identity` to `dir/checkpoint.h5`
/// (through a temporary file, so a failed write leaves the previous checkpoint): every process writes its
/// points' columns, each with its checksum put together from all processes' points; once all agree that
/// their parts are written, process 0 (the one whose `out` writes) adds the rigid bodies, the nodal FEM
/// state and the meta data and renames the file into place. The file is the same whatever the number of
/// processes. Collective.
pub fn save<const D: usize>(
    dir: &Path,
    shared: &SharedState<D>,
    out: &RunOutput,
    identity: &RunIdentity,
) -> Result<(), OutputError> {
    let path = dir.join(FILE);
    let tmp = dir.join(format!("{FILE}.tmp"));
    let (p, rows, session) = (&shared.state.particles, &shared.rows, shared.session);
    // Column by column (one copy of a column at a time); a process that writes no points passes none.
    let mut file = SharedFile::create(session, &tmp, rows);
    let mut crcs = Vec::new();
    for (name, width) in p.state_columns() {
        let values = if rows.order().is_empty() {
            Vec::new()
        } else {
            p.column(name).expect("a listed column")
        };
        let mut crc = SharedCrc::new();
        crc.column(rows, width, &values, f64::to_le_bytes);
        crcs.push((name, crc.finish(session).map_err(exchange_err(&path))?));
        file.column(name, (width, Layout::Flat), &values);
    }
    let written = file.close(session).and_then(|()| {
        if out.writes() {
            describe(&tmp, shared, crcs.into_iter(), out, identity)
        } else {
            Ok(())
        }
    });
    if let Err(e) = written {
        // A full disk leaves no half-written temporary behind (the previous checkpoint stays).
        if out.writes() {
            let _ = std::fs::remove_file(&tmp);
        }
        return Err(OutputError::hdf5(&path, &e));
    }
    if !out.writes() {
        return Ok(());
    }
    std::fs::rename(&tmp, &path).map_err(|source| OutputError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Process 0, after every process has written the points' columns (`crcs`: their checksums) into
/// `path`: the checksums, the rigid bodies and the nodal FEM state (the same on every process) and the
/// meta data (format, identity, datasets, counters, the records of `out`, points).
fn describe<'c, const D: usize>(
    path: &Path,
    shared: &SharedState<D>,
    crcs: impl Iterator<Item = (&'c str, u32)>,
    out: &RunOutput,
    identity: &RunIdentity,
) -> hdf5_metno::Result<()> {
    let f = hdf5_metno::File::open_rw(path)?;
    let put_crc = |ds: &hdf5_metno::Dataset, crc: u32| {
        ds.new_attr::<u32>().create("crc32")?.write_scalar(&crc)
    };
    let mut names = Vec::new();
    for (name, crc) in crcs {
        put_crc(&f.dataset(name)?, crc)?;
        names.push(name.to_owned());
    }
    let mut put = |name: String, data: &[f64]| -> hdf5_metno::Result<()> {
        let ds = f
            .new_dataset_builder()
            .with_data(data)
            .create(name.as_str())?;
        put_crc(&ds, crc_f64(data))?;
        names.push(name);
        Ok(())
    };
    let state = shared.state;
    for (k, rb) in state.rigid.iter().enumerate() {
        for name in RIGID_COLUMNS {
            put(
                format!("rigid{k}_{name}"),
                &rb.column(name).expect("a listed column"),
            )?;
        }
    }
    if let Some((v, a)) = &state.fem_nodal {
        put("fem_nodal_velocity".into(), &flat(v))?;
        put("fem_nodal_acceleration".into(), &flat(a))?;
    }
    let counters = serde_json::to_value(CounterRecord::of(&state.counters))
        .map_err(|e| hdf5_metno::Error::from(e.to_string().as_str()))?;
    let text = serde_json::json!({
        "format": FORMAT,
        "identity": identity,
        "datasets": names,
        "counters": counters,
        "records": out.records_json(),
        "points": shared.rows.total(),
        "history_stride": state.particles.history_stride(),
    })
    .to_string();
    let meta = f
        .new_dataset_builder()
        .with_data(text.as_bytes())
        .create("meta")?;
    put_crc(&meta, crc32fast::hash(text.as_bytes()))?;
    f.flush()
}

/// What a checkpoint says about itself: the identity of the run that wrote it, its counters and the
/// records of its output, verified against the checksum of its `meta` dataset.
#[derive(Debug)]
pub struct Header {
    /// The identity of the run that wrote it.
    pub identity: RunIdentity,
    /// Time, step, time step and accumulated quantities at the checkpoint.
    pub counters: CounterRecord,
    datasets: Vec<String>,
    records: serde_json::Value,
    points: usize,
    history_stride: usize,
}

impl Header {
    /// Restores the records of the output (history rows, snapshots, crack states) into `out`.
    pub fn restore_records(&self, out: &mut RunOutput) -> Result<(), serde_json::Error> {
        out.restore_records(&self.records)
    }
}

/// Opens `dir/checkpoint.h5` and reads and verifies its header.
fn open(dir: &Path) -> Result<(hdf5_metno::File, Header, PathBuf), CheckpointError> {
    let path = dir.join(FILE);
    let shown = path.display().to_string();
    match crate::input::check_input_file(&path, crate::input::DATA_INPUT_MAX) {
        Ok(_) => {}
        Err(e) if e.is_missing() => return Err(CheckpointError::Missing { path: shown }),
        Err(e) => {
            return Err(CheckpointError::Unusable {
                path: shown,
                detail: format!(
                    "{}; a run writes checkpoint.h5 as a file: remove it, or start the run without \
                     --resume",
                    e.reason()
                ),
            });
        }
    }
    let corrupt = |detail: String| CheckpointError::Corrupt {
        path: shown.clone(),
        detail,
    };
    let f =
        hdf5_metno::File::open(&path).map_err(|e| corrupt(format!("not readable as HDF5: {e}")))?;
    let ds = f
        .dataset("meta")
        .map_err(|e| corrupt(format!("no readable `meta` dataset: {e}")))?;
    let bytes: Vec<u8> = ds
        .read_raw()
        .map_err(|e| corrupt(format!("`meta` unreadable: {e}")))?;
    let Ok(crc) = ds.attr("crc32").and_then(|a| a.read_scalar::<u32>()) else {
        return Err(CheckpointError::Unusable {
            path: shown,
            detail:
                "the checkpoint has no checksums (written by an older version of the program), so \
                     what it holds cannot be verified; start the run again with --overwrite"
                    .into(),
        });
    };
    if crc32fast::hash(&bytes) != crc {
        return Err(corrupt("`meta` does not match its checksum".into()));
    }
    let meta: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| corrupt(format!("`meta`: {e}")))?;
    if meta["format"].as_u64() != Some(FORMAT) {
        return Err(CheckpointError::Unusable {
            path: shown,
            detail: format!(
                "checkpoint format {} is not the format {FORMAT} of this program",
                meta["format"]
            ),
        });
    }
    fn field<T: serde::de::DeserializeOwned>(
        meta: &serde_json::Value,
        name: &str,
    ) -> Result<T, String> {
        serde_json::from_value(meta[name].clone()).map_err(|e| format!("meta.{name}: {e}"))
    }
    let header = Header {
        identity: field(&meta, "identity").map_err(corrupt)?,
        counters: field(&meta, "counters").map_err(corrupt)?,
        datasets: field(&meta, "datasets").map_err(corrupt)?,
        points: field(&meta, "points").map_err(corrupt)?,
        history_stride: field(&meta, "history_stride").map_err(corrupt)?,
        records: meta["records"].clone(),
    };
    Ok((f, header, path))
}

/// Reads and verifies the header of `dir/checkpoint.h5` (not the particle data), e.g. to compare its
/// identity with the configuration of a run that wants to resume it.
pub fn read_header(dir: &Path) -> Result<Header, CheckpointError> {
    open(dir).map(|(_, header, _)| header)
}

/// Restores `state` (freshly built from the same configuration as `model`) from `dir/checkpoint.h5`: every
/// dataset is read and checked against its checksum and the configuration before `state` is changed.
/// Returns the header (for the output's records).
pub fn load<const D: usize>(
    dir: &Path,
    model: &Model<D>,
    state: &mut State<D>,
) -> Result<Header, CheckpointError> {
    let (f, header, path) = open(dir)?;
    let shown = path.display().to_string();
    let mut data = read_verified(&f, &header, &shown)?;
    let unusable = |detail: String| CheckpointError::Unusable {
        path: shown.clone(),
        detail,
    };
    let fem = model.params.method == Method::Fem && data.contains_key("fem_nodal_velocity");
    check_fits(&header, &data, model, state, fem).map_err(&unusable)?;
    let mut take = |name: &str| data.remove(name).unwrap_or_default();
    let p = &mut state.particles;
    for (name, _) in p.state_columns() {
        p.set_column(name, &take(name)).map_err(&unusable)?;
    }
    for (k, rb) in state.rigid.iter_mut().enumerate() {
        for name in RIGID_COLUMNS {
            rb.set_column(name, &take(&format!("rigid{k}_{name}")))
                .map_err(&unusable)?;
        }
    }
    if fem {
        state.fem_nodal = Some((
            unflat(&take("fem_nodal_velocity")),
            unflat(&take("fem_nodal_acceleration")),
        ));
    }
    let (nrigid, energy) = (state.rigid.len(), state.counters.initial_energy);
    state.counters = header
        .counters
        .clone()
        .restore(nrigid, energy)
        .map_err(&unusable)?;
    Ok(header)
}

/// Every dataset the header lists, read and checked against its CRC-32 (`shown`: the file, for errors).
fn read_verified<'h>(
    f: &hdf5_metno::File,
    header: &'h Header,
    shown: &str,
) -> Result<HashMap<&'h str, Vec<f64>>, CheckpointError> {
    let corrupt = |detail: String| CheckpointError::Corrupt {
        path: shown.to_owned(),
        detail,
    };
    let mut data = HashMap::new();
    for name in &header.datasets {
        let ds = f
            .dataset(name)
            .map_err(|e| corrupt(format!("dataset `{name}`: {e}")))?;
        let values: Vec<f64> = ds
            .read_raw()
            .map_err(|e| corrupt(format!("dataset `{name}`: {e}")))?;
        let crc = ds
            .attr("crc32")
            .and_then(|a| a.read_scalar::<u32>())
            .map_err(|e| corrupt(format!("dataset `{name}`: checksum unreadable: {e}")))?;
        if crc_f64(&values) != crc {
            return Err(corrupt(format!(
                "dataset `{name}` does not match its checksum"
            )));
        }
        data.insert(name.as_str(), values);
    }
    Ok(data)
}

/// Whether the checkpoint's counters, points and datasets fit the configuration's `model` and `state`
/// (the FEM mode's nodal state too if `fem`); the error says what does not.
fn check_fits<const D: usize>(
    header: &Header,
    data: &HashMap<&str, Vec<f64>>,
    model: &Model<D>,
    state: &State<D>,
    fem: bool,
) -> Result<(), String> {
    let p = &state.particles;
    let n = p.len();
    let c = &header.counters;
    if let Some(l) = c
        .accumulated
        .iter()
        .chain(&c.last_reactions)
        .find(|l| l.len() != D)
    {
        return Err(format!(
            "the checkpoint is of a {}D run, the configuration of a {D}D one",
            l.len()
        ));
    }
    if header.points != n {
        return Err(format!(
            "the checkpoint holds {} material points, the configuration {n}",
            header.points
        ));
    }
    if header.history_stride != p.history_stride() {
        return Err(
            "the checkpoint's material history has a different layout than the configuration"
                .into(),
        );
    }
    let mut expected: Vec<(String, usize)> = p
        .state_columns()
        .into_iter()
        .map(|(name, per)| (name.to_owned(), per * n))
        .collect();
    for (k, rb) in state.rigid.iter().enumerate() {
        for (name, per) in rb.state_columns() {
            if RIGID_COLUMNS.contains(&name) {
                expected.push((format!("rigid{k}_{name}"), per * rb.len()));
            }
        }
    }
    if fem {
        let nodes = model.params.grid.num_nodes();
        expected.push(("fem_nodal_velocity".into(), D * nodes));
        expected.push(("fem_nodal_acceleration".into(), D * nodes));
    }
    for (name, len) in &expected {
        match data.get(name.as_str()) {
            Some(v) if v.len() == *len => {}
            Some(v) => {
                return Err(format!(
                    "dataset `{name}` has {} values, the configuration needs {len}",
                    v.len()
                ));
            }
            None => return Err(format!("dataset `{name}` is missing")),
        }
    }
    Ok(())
}

/// The counters as a checkpoint's header stores them (JSON; one list per constraint set of any length, so
/// that a header can be read before the dimension of the run is known).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CounterRecord {
    /// Time reached (s).
    pub time: f64,
    /// Steps completed.
    pub step: usize,
    /// Time step to try next (s).
    pub dt: f64,
    /// Steps in a row that converged at their first try (0 in checkpoints that predate it).
    #[serde(default)]
    pub calm_steps: usize,
    /// Work of reactions and body forces so far (N mm; in 2D per mm thickness).
    pub external_work: f64,
    /// Kinetic energy at t = 0 (N mm, in 2D per mm thickness; `None` in checkpoints that predate it,
    /// which keep the value the configuration gives).
    #[serde(default)]
    pub initial_energy: Option<f64>,
    /// Accumulated prescribed displacement per constraint set, one value per component (mm).
    pub accumulated: Vec<Vec<f64>>,
    /// Last reactions per constraint set, one value per component (N; in 2D per mm thickness).
    pub last_reactions: Vec<Vec<f64>>,
    /// What the contact sets carry from one step to the next ([`ContactMemory::record`]), its lists
    /// at the top level of the record.
    #[serde(flatten)]
    pub contact: ContactRecord,
    /// The energy books (zero in checkpoints that predate them).
    #[serde(default)]
    pub books: EnergyBooks,
}

impl CounterRecord {
    /// The record of a run's counters.
    pub fn of<const D: usize>(c: &Counters<D>) -> Self {
        Self {
            time: c.time,
            step: c.step,
            dt: c.dt,
            calm_steps: c.calm_steps,
            external_work: c.external_work,
            initial_energy: Some(c.initial_energy),
            accumulated: c.accumulated.iter().map(|a| a.to_vec()).collect(),
            last_reactions: c.last_reactions.iter().map(|f| f.to_vec()).collect(),
            contact: c.contact.record(),
            books: c.books,
        }
    }

    /// The counters of a run with `nrigid` rigid bodies; `initial_energy` is kept where an older
    /// checkpoint has none, the contact memory of an older checkpoint without pins or contact is
    /// completed with that of t = 0 ([`ContactMemory::restore`]). An error says which list does not have `D` components per constraint set.
    fn restore<const D: usize>(
        self,
        nrigid: usize,
        initial_energy: f64,
    ) -> Result<Counters<D>, String> {
        let per_set = |name: &str, lists: &[Vec<f64>]| -> Result<Vec<[f64; D]>, String> {
            lists
                .iter()
                .map(|l| {
                    <[f64; D]>::try_from(l.as_slice()).map_err(|_| {
                        format!(
                            "counters.{name}: {} components per constraint set, this run has {D}",
                            l.len()
                        )
                    })
                })
                .collect()
        };
        Ok(Counters {
            time: self.time,
            step: self.step,
            dt: self.dt,
            calm_steps: self.calm_steps,
            external_work: self.external_work,
            initial_energy: self.initial_energy.unwrap_or(initial_energy),
            accumulated: per_set("accumulated", &self.accumulated)?,
            last_reactions: per_set("last_reactions", &self.last_reactions)?,
            contact: ContactMemory::restore(self.contact, nrigid),
            books: self.books,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::NodeStatus;

    /// Format 2 keeps the contact memory as four lists at the top level of the counters, so that
    /// checkpoints written before [`ContactMemory`] resume.
    #[test]
    fn the_contact_memory_keeps_the_keys_of_format_2() {
        let mut contact = ContactMemory::new(1);
        contact.devices[0].rotation = 0.125;
        contact.devices[0].statuses = vec![(4, NodeStatus::Stick)];
        contact.pairs.closed = vec![9];
        let counters = Counters::<2> {
            time: 1e-6,
            step: 1,
            dt: 1e-6,
            calm_steps: 0,
            external_work: 0.0,
            initial_energy: 0.0,
            accumulated: vec![[0.0; 2]],
            last_reactions: vec![[0.0; 2]],
            contact,
            books: EnergyBooks::default(),
        };
        let json = serde_json::to_value(CounterRecord::of(&counters)).expect("serialized");
        assert_eq!(json["rotations"], serde_json::json!([0.125]));
        assert_eq!(json["rotation_rates"], serde_json::json!([0.0]));
        assert_eq!(
            json["contact_statuses"],
            serde_json::json!([[[4, "Stick"]]])
        );
        assert_eq!(json["closed_pairs"], serde_json::json!([9]));
        let back: CounterRecord = serde_json::from_value(json).expect("deserialized");
        assert_eq!(back.restore::<2>(1, 0.0), Ok(counters));
    }
}
