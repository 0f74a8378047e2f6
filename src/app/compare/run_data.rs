//! What `compare` reads of the run: its `history.csv` and its snapshots `fields_*.h5` (listed once,
//! loaded on demand).

use super::csv::Csv;
use super::numerics::PointIndex;
use super::reference::QUANTITIES;
use super::report::short;
use super::{InputError, Result, bad};
use crate::schema::{file, history};
use std::path::{Path, PathBuf};

/// The run's `history.csv`.
pub(super) struct RunHistory {
    /// The table.
    pub(super) csv: Csv,
    /// Its `time` column (s), ascending.
    pub(super) times: Vec<f64>,
}

impl RunHistory {
    /// Reads `history.csv` of the run directory `dir`.
    pub(super) fn read(dir: &Path) -> Result<Self> {
        let csv = Csv::read(&dir.join(file::HISTORY))?;
        let ti = csv.column_index(history::TIME).ok_or_else(|| {
            bad(format!(
                "{}:{}: no `time` column",
                csv.name, csv.header_line
            ))
        })?;
        if csv.rows.is_empty() {
            return Err(bad(format!("{}: no steps recorded", csv.name)));
        }
        let mut times = Vec::with_capacity(csv.rows.len());
        for (line, f) in &csv.rows {
            let t = csv.number(*line, history::TIME, &f[ti])?;
            if times.last().is_some_and(|&p| t < p) {
                return Err(bad(format!(
                    "{}:{line}: time {} s is earlier than the previous row's",
                    csv.name,
                    short(t)
                )));
            }
            times.push(t);
        }
        Ok(Self { csv, times })
    }

    /// A numeric column, or an error naming the reference's header line.
    pub(super) fn column(&self, name: &str, asked_by: &str) -> Result<Vec<f64>> {
        let i = self.csv.column_index(name).ok_or_else(|| {
            bad(format!(
                "{asked_by}: column `{name}` is not in {}; its columns: {}",
                self.csv.name,
                self.csv.header.join(", ")
            ))
        })?;
        self.csv
            .rows
            .iter()
            .map(|(line, f)| {
                self.csv.number(*line, name, &f[i]).map_err(|e| {
                    bad(format!(
                        "{e} (column asked for by {asked_by}; only numeric columns compare)"
                    ))
                })
            })
            .collect()
    }
}

/// A snapshot file and its time.
pub(super) struct SnapshotFile {
    /// Path.
    pub(super) path: PathBuf,
    /// File name.
    pub(super) name: String,
    /// Time (s).
    pub(super) time: f64,
}

/// Maps an HDF5 error on `path` to a message naming the file and `what` was read.
fn h5_err(path: &Path, what: &str) -> impl Fn(hdf5_metno::Error) -> InputError {
    let p = path.display().to_string();
    let what = what.to_owned();
    move |e| bad(format!("{p}: HDF5: {what}: {e}"))
}

/// The snapshots `fields_*.h5` of a run, by time.
fn list_snapshots(dir: &Path) -> Result<Vec<SnapshotFile>> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| bad(format!("{}: cannot list: {e}", dir.display())))?;
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| bad(format!("{}: cannot list: {e}", dir.display())))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !(name.starts_with(file::FIELDS.0) && name.ends_with(file::FIELDS.1)) {
            continue;
        }
        let path = entry.path();
        crate::input::check_input_file(&path, crate::input::DATA_INPUT_MAX)
            .map_err(|e| bad(e.to_string()))?;
        let file = hdf5_metno::File::open(&path).map_err(h5_err(&path, "open"))?;
        let time: f64 = file
            .attr("time_s")
            .and_then(|a| a.read_scalar())
            .map_err(h5_err(&path, "attribute time_s"))?;
        out.push(SnapshotFile { path, name, time });
    }
    if out.is_empty() {
        return Err(bad(format!(
            "{}: no snapshots fields_*.h5 (point references need them)",
            dir.display()
        )));
    }
    out.sort_by(|a, b| a.time.total_cmp(&b.time).then(a.name.cmp(&b.name)));
    Ok(out)
}

/// A loaded snapshot: the reference positions, their index and the quantities read so far.
pub(super) struct Snapshot {
    /// Index of the reference positions (mm).
    pub(super) index: PointIndex,
    /// Per entry of [`QUANTITIES`]: its values once read.
    pub(super) values: Vec<Option<Vec<f64>>>,
}

/// Reads the dataset `name` of a snapshot with `n` rows (any number when `None`): a scalar of shape (N),
/// or with `vector` a vector of shape (N, 3) (runs written before the 3-component output: (N, 2)),
/// returned as x, y pairs.
pub(super) fn read_dataset(
    path: &Path,
    name: &str,
    n: Option<usize>,
    vector: bool,
) -> Result<Vec<f64>> {
    let file = hdf5_metno::File::open(path).map_err(h5_err(path, "open"))?;
    let what = format!("dataset `{name}`");
    let err = h5_err(path, &what);
    let dataset = file.dataset(name).map_err(&err)?;
    let shape = dataset.shape();
    let width = match (vector, shape.as_slice()) {
        (false, [_]) => Some(1),
        (true, [_, w @ (2 | 3)]) => Some(*w),
        _ => None,
    };
    let rows_ok = n.is_none_or(|n| shape.first() == Some(&n));
    let Some(width) = width.filter(|_| rows_ok) else {
        let rows = n.map_or("N".to_owned(), |n| n.to_string());
        return Err(bad(format!(
            "{}: dataset `{name}` has shape {shape:?}, expected ({rows}{})",
            path.display(),
            if vector { ", 3" } else { "" }
        )));
    };
    let data: Vec<f64> = dataset.read_raw().map_err(&err)?;
    Ok(match width {
        1 | 2 => data,
        _ => data
            .chunks_exact(width)
            .flat_map(|c| [c[0], c[1]])
            .collect(),
    })
}

impl Snapshot {
    /// Reads the reference positions of a snapshot; refuses a 3D run.
    fn load(file: &SnapshotFile) -> Result<Self> {
        // Point references are plane: a 3D run (a plate) has every (x, y) once per layer of points.
        let h5 = hdf5_metno::File::open(&file.path).map_err(h5_err(&file.path, "open"))?;
        let raw: Vec<f64> = h5
            .dataset("position")
            .and_then(|d| d.read_raw())
            .map_err(h5_err(&file.path, "dataset `position`"))?;
        let n_raw = h5.dataset("damage").map(|d| d.size()).unwrap_or(0);
        if n_raw > 0 && raw.len() == 3 * n_raw && raw.chunks_exact(3).any(|c| c[2] != 0.0) {
            return Err(bad(format!(
                "{}: a 3D run (its points lie off z = 0): point references compare plane runs; \
                 compare its history (forces are of the whole plate, N)",
                file.path.display()
            )));
        }
        let pos = read_dataset(&file.path, "position", None, true)?;
        let n = pos.len() / 2;
        let disp = read_dataset(&file.path, "displacement", Some(n), true)?;
        let reference: Vec<[f64; 2]> = (0..n)
            .map(|i| [pos[2 * i] - disp[2 * i], pos[2 * i + 1] - disp[2 * i + 1]])
            .collect();
        Ok(Self {
            index: PointIndex::new(reference),
            values: vec![None; QUANTITIES.len()],
        })
    }

    /// The values of quantity `q` (index into [`QUANTITIES`]), read on first use.
    pub(super) fn quantity(&mut self, file: &SnapshotFile, q: usize) -> Result<&[f64]> {
        if self.values[q].is_none() {
            let n = self.index.points().len();
            let (_, dataset, comp) = QUANTITIES[q];
            let v = match comp {
                Some(c) => read_dataset(&file.path, dataset, Some(n), true)?
                    .chunks_exact(2)
                    .map(|p| p[c])
                    .collect(),
                None => read_dataset(&file.path, dataset, Some(n), false)?,
            };
            self.values[q] = Some(v);
        }
        Ok(self.values[q].as_deref().unwrap_or_default())
    }
}

/// Snapshots listed once and loaded on demand.
pub(super) struct Snapshots {
    dir: PathBuf,
    files: Option<Vec<SnapshotFile>>,
    loaded: Vec<Option<Snapshot>>,
}

impl Snapshots {
    /// The snapshots of the run directory `dir`, not listed yet.
    pub(super) fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_owned(),
            files: None,
            loaded: Vec::new(),
        }
    }

    /// The snapshot files, listed on first use.
    fn files(&mut self) -> Result<&[SnapshotFile]> {
        if self.files.is_none() {
            let f = list_snapshots(&self.dir)?;
            self.loaded = (0..f.len()).map(|_| None).collect();
            self.files = Some(f);
        }
        Ok(self.files.as_deref().unwrap_or_default())
    }

    /// The snapshot nearest in time to a reference row's time.
    pub(super) fn find(&mut self, file: &str, line: usize, t: f64, tol: f64) -> Result<usize> {
        let files = self.files()?;
        let k = files.partition_point(|f| f.time < t);
        let best = [k.wrapping_sub(1), k]
            .into_iter()
            .filter(|&i| i < files.len())
            .min_by(|&a, &b| {
                (files[a].time - t)
                    .abs()
                    .total_cmp(&(files[b].time - t).abs())
            })
            .unwrap_or(0);
        if (files[best].time - t).abs() <= tol {
            return Ok(best);
        }
        let listed: Vec<String> = files.iter().take(12).map(|f| short(f.time)).collect();
        Err(bad(format!(
            "{file}:{line}: time {} s: no snapshot within {} s (nearest {} at {} s; snapshots at {}{} s; \
             --time-tolerance widens the match)",
            short(t),
            short(tol),
            files[best].name,
            short(files[best].time),
            listed.join(", "),
            if files.len() > 12 { ", ..." } else { "" }
        )))
    }

    /// Snapshot `i` (an index from [`Snapshots::find`]), loaded on first use.
    pub(super) fn get(&mut self, i: usize) -> Result<(&SnapshotFile, &mut Snapshot)> {
        self.files()?;
        let files = self.files.as_deref().unwrap_or_default();
        if self.loaded[i].is_none() {
            self.loaded[i] = Some(Snapshot::load(&files[i])?);
        }
        match self.loaded[i].as_mut() {
            Some(s) => Ok((&files[i], s)),
            None => Err(bad("snapshot not loaded")),
        }
    }
}
