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

use crate::schema::{file, history};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Quantities of point references: name, HDF5 dataset, component (None: a scalar dataset).
pub const QUANTITIES: [(&str, &str, Option<usize>); 10] = [
    ("ux", "displacement", Some(0)),
    ("uy", "displacement", Some(1)),
    ("vx", "velocity", Some(0)),
    ("vy", "velocity", Some(1)),
    ("sigma_xx", "sigma_xx", None),
    ("sigma_yy", "sigma_yy", None),
    ("sigma_xy", "sigma_xy", None),
    ("sigma_zz", "sigma_zz", None),
    ("damage", "damage", None),
    ("eta_bar", "eta_bar", None),
];

/// Header of a point reference.
pub const POINT_HEADER: [&str; 5] = ["time", "x", "y", "quantity", "value"];

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

fn bad(msg: impl Into<String>) -> InputError {
    InputError(msg.into())
}

type Result<T> = std::result::Result<T, InputError>;

// ---------------------------------------------------------------------------------------------------
// CSV

/// A small CSV table: header and rows, each with its 1-based line number in the file.
struct Csv {
    name: String,
    header_line: usize,
    header: Vec<String>,
    rows: Vec<(usize, Vec<String>)>,
}

impl Csv {
    /// Parses `text`; `name` (the file) prefixes every message.
    fn parse(text: &str, name: &str) -> Result<Self> {
        let mut header: Option<(usize, Vec<String>)> = None;
        let mut rows = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let fields: Vec<String> = trimmed.split(',').map(|f| f.trim().to_owned()).collect();
            match &header {
                None => header = Some((i + 1, fields)),
                Some((_, h)) => {
                    if fields.len() != h.len() {
                        return Err(bad(format!(
                            "{name}:{}: {} fields, the header has {} ({})",
                            i + 1,
                            fields.len(),
                            h.len(),
                            h.join(",")
                        )));
                    }
                    rows.push((i + 1, fields));
                }
            }
        }
        let (header_line, header) =
            header.ok_or_else(|| bad(format!("{name}: no header line (the file is empty)")))?;
        if let Some(empty) = header.iter().position(|h| h.is_empty()) {
            return Err(bad(format!(
                "{name}:{header_line}: header field {} is empty",
                empty + 1
            )));
        }
        Ok(Self {
            name: name.to_owned(),
            header_line,
            header,
            rows,
        })
    }

    fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| bad(format!("{}: cannot read: {e}", path.display())))?;
        Self::parse(&text, &path.display().to_string())
    }

    fn column_index(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    fn number(&self, line: usize, column: &str, text: &str) -> Result<f64> {
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(bad(format!(
                "{}:{line}: `{column}` = `{text}` is not a finite number",
                self.name
            ))),
        }
    }
}

// ---------------------------------------------------------------------------------------------------
// Reference files

/// A history reference: reference values of history columns at some times.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryReference {
    /// File name (messages, report).
    pub file: String,
    /// Line of the header.
    pub header_line: usize,
    /// History columns compared.
    pub columns: Vec<String>,
    /// Rows: line, time (s), one value per column.
    pub rows: Vec<(usize, f64, Vec<f64>)>,
}

/// One row of a point reference.
#[derive(Debug, Clone, PartialEq)]
pub struct PointRow {
    /// Line in the file.
    pub line: usize,
    /// Time (s).
    pub time: f64,
    /// Position in the reference configuration (mm).
    pub x: f64,
    /// Position in the reference configuration (mm).
    pub y: f64,
    /// Index into [`QUANTITIES`].
    pub quantity: usize,
    /// Reference value.
    pub value: f64,
}

/// A point reference.
#[derive(Debug, Clone, PartialEq)]
pub struct PointReference {
    /// File name (messages, report).
    pub file: String,
    /// Rows.
    pub rows: Vec<PointRow>,
}

/// A parsed reference file.
#[derive(Debug, Clone, PartialEq)]
pub enum Reference {
    /// `time,<col>...`
    History(HistoryReference),
    /// `time,x,y,quantity,value`
    Point(PointReference),
}

fn quantity_names() -> String {
    QUANTITIES.map(|q| q.0).join(", ")
}

/// Parses a reference file's text (`name` names it in messages).
pub fn parse_reference(text: &str, name: &str) -> Result<Reference> {
    let csv = Csv::parse(text, name)?;
    let h = csv.header_line;
    let expected = "expected `time,<history column>[,<history column>...]` (history reference) or \
                    `time,x,y,quantity,value` (point reference)";
    if csv.header.first().map(String::as_str) != Some("time") || csv.header.len() < 2 {
        return Err(bad(format!(
            "{name}:{h}: header `{}`: {expected}",
            csv.header.join(",")
        )));
    }
    if csv.rows.is_empty() {
        return Err(bad(format!(
            "{name}: no data rows after the header (line {h})"
        )));
    }
    if csv.header == POINT_HEADER {
        let mut rows = Vec::with_capacity(csv.rows.len());
        for (line, f) in &csv.rows {
            let quantity = QUANTITIES.iter().position(|q| q.0 == f[3]).ok_or_else(|| {
                bad(format!(
                    "{name}:{line}: quantity `{}` is unknown; allowed: {}",
                    f[3],
                    quantity_names()
                ))
            })?;
            rows.push(PointRow {
                line: *line,
                time: csv.number(*line, "time", &f[0])?,
                x: csv.number(*line, "x", &f[1])?,
                y: csv.number(*line, "y", &f[2])?,
                quantity,
                value: csv.number(*line, "value", &f[4])?,
            });
        }
        return Ok(Reference::Point(PointReference {
            file: name.to_owned(),
            rows,
        }));
    }
    let columns: Vec<String> = csv.header[1..].to_vec();
    for (i, c) in columns.iter().enumerate() {
        if columns[..i].contains(c) || c == "time" {
            return Err(bad(format!(
                "{name}:{h}: column `{c}` appears twice in the header"
            )));
        }
    }
    let mut rows = Vec::with_capacity(csv.rows.len());
    for (line, f) in &csv.rows {
        let t = csv.number(*line, "time", &f[0])?;
        let values = columns
            .iter()
            .zip(&f[1..])
            .map(|(c, s)| csv.number(*line, c, s))
            .collect::<Result<Vec<f64>>>()?;
        rows.push((*line, t, values));
    }
    Ok(Reference::History(HistoryReference {
        file: name.to_owned(),
        header_line: h,
        columns,
        rows,
    }))
}

// ---------------------------------------------------------------------------------------------------
// Numerics: interpolation in time, neighbour search, local linear fit

/// Value at `t` of the piecewise linear curve through `(times[i], values[i])` (times ascending). A time
/// up to `tol` before the first or after the last sample takes the end value; further out: None.
pub fn interpolate(times: &[f64], values: &[f64], t: f64, tol: f64) -> Option<f64> {
    let (&first, &last) = (times.first()?, times.last()?);
    if t <= first {
        return (first - t <= tol).then_some(values[0]);
    }
    if t >= last {
        return (t - last <= tol).then_some(values[times.len() - 1]);
    }
    // first < t < last: times[k - 1] <= t < times[k].
    let k = times.partition_point(|&s| s <= t);
    let (t0, t1) = (times[k - 1], times[k]);
    let w = (t - t0) / (t1 - t0);
    Some(values[k - 1] + w * (values[k] - values[k - 1]))
}

/// Default time tolerance: `1e-9 max(1, |t|)` seconds.
pub fn default_time_tolerance(t: f64) -> f64 {
    1e-9 * t.abs().max(1.0)
}

/// Bucket grid over a point cloud for k-nearest-neighbour queries.
pub struct PointIndex {
    points: Vec<[f64; 2]>,
    lo: [f64; 2],
    cell: f64,
    nx: usize,
    ny: usize,
    /// Bucket `b` holds `order[start[b]..start[b + 1]]`.
    start: Vec<usize>,
    order: Vec<usize>,
}

impl PointIndex {
    /// Builds the index (about two points per bucket).
    pub fn new(points: Vec<[f64; 2]>) -> Self {
        let n = points.len().max(1);
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &points {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if points.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
        let mut cell = if w > 0.0 && h > 0.0 {
            (2.0 * w * h / n as f64).sqrt()
        } else {
            w.max(h) / n as f64
        };
        if !(cell.is_finite() && cell > 0.0) {
            cell = 1.0;
        }
        // At most about 4 n buckets (a long thin cloud).
        while (w / cell + 1.0) * (h / cell + 1.0) > 4.0 * n as f64 + 16.0 {
            cell *= 1.5;
        }
        let nx = (w / cell) as usize + 1;
        let ny = (h / cell) as usize + 1;
        let bucket = |p: &[f64; 2]| {
            let i = (((p[0] - lo[0]) / cell) as usize).min(nx - 1);
            let j = (((p[1] - lo[1]) / cell) as usize).min(ny - 1);
            j * nx + i
        };
        let mut start = vec![0usize; nx * ny + 1];
        for p in &points {
            start[bucket(p) + 1] += 1;
        }
        for b in 0..nx * ny {
            start[b + 1] += start[b];
        }
        let mut fill = start.clone();
        let mut order = vec![0usize; points.len()];
        for (i, p) in points.iter().enumerate() {
            let b = bucket(p);
            order[fill[b]] = i;
            fill[b] += 1;
        }
        Self {
            points,
            lo,
            cell,
            nx,
            ny,
            start,
            order,
        }
    }

    /// The indexed points.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Indices of the `k` points nearest to `q` (fewer if there are fewer points), nearest first (ties by
    /// index).
    pub fn nearest(&self, q: [f64; 2], k: usize) -> Vec<usize> {
        let k = k.min(self.points.len());
        if k == 0 {
            return Vec::new();
        }
        let ci = ((q[0] - self.lo[0]) / self.cell).floor();
        let cj = ((q[1] - self.lo[1]) / self.cell).floor();
        let (nx, ny) = (self.nx as f64, self.ny as f64);
        // Rings of buckets at Chebyshev distance r from the query's bucket (which may lie outside).
        let gap = |c: f64, n: f64| (-c).max(c - (n - 1.0)).max(0.0);
        let r0 = gap(ci, nx).max(gap(cj, ny)) as i64;
        let r_all = (ci.max(nx - 1.0 - ci).max(cj).max(ny - 1.0 - cj)).max(0.0) as i64;
        let (ci, cj) = (ci as i64, cj as i64);
        let mut cand: Vec<(f64, usize)> = Vec::new();
        let mut r = r0;
        loop {
            let mut visit = |i: i64, j: i64| {
                if i < 0 || j < 0 || i >= self.nx as i64 || j >= self.ny as i64 {
                    return;
                }
                let b = j as usize * self.nx + i as usize;
                for &p in &self.order[self.start[b]..self.start[b + 1]] {
                    let d = [self.points[p][0] - q[0], self.points[p][1] - q[1]];
                    cand.push((d[0] * d[0] + d[1] * d[1], p));
                }
            };
            if r == 0 {
                visit(ci, cj);
            } else {
                for i in (ci - r)..=(ci + r) {
                    visit(i, cj - r);
                    visit(i, cj + r);
                }
                for j in (cj - r + 1)..=(cj + r - 1) {
                    visit(ci - r, j);
                    visit(ci + r, j);
                }
            }
            if r >= r_all {
                break;
            }
            if cand.len() >= k {
                cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                cand.truncate(k);
                // Unvisited buckets are at least r cells away.
                let reach = r as f64 * self.cell;
                if cand[k - 1].0 <= reach * reach {
                    break;
                }
            }
            r += 1;
        }
        cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        cand.truncate(k);
        cand.into_iter().map(|c| c.1).collect()
    }
}

/// Value at `at` of the least-squares plane `a + b (x - at_x) + c (y - at_y)` through the samples
/// `(points[i], values[i])`: `a`. Exact for a linear field, also where it extrapolates. None when the
/// points do not span a plane (fewer than 3, collinear or coincident).
pub fn linear_fit(points: &[[f64; 2]], values: &[f64], at: [f64; 2]) -> Option<f64> {
    let n = points.len();
    if n < 3 || values.len() != n {
        return None;
    }
    let scale = points
        .iter()
        .map(|p| (p[0] - at[0]).hypot(p[1] - at[1]))
        .fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let a = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => 1.0,
        1 => (points[i][0] - at[0]) / scale,
        _ => (points[i][1] - at[1]) / scale,
    });
    let svd = a.svd(true, true);
    let (smin, smax) = (svd.singular_values.min(), svd.singular_values.max());
    if smin.is_nan() || smin <= 1e-8 * smax {
        return None;
    }
    let b = DVector::from_column_slice(values);
    let x = svd.solve(&b, 0.0).ok()?;
    Some(x[0])
}

// ---------------------------------------------------------------------------------------------------
// The run

/// The run's `history.csv`.
struct RunHistory {
    csv: Csv,
    times: Vec<f64>,
}

impl RunHistory {
    fn read(dir: &Path) -> Result<Self> {
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
    fn column(&self, name: &str, asked_by: &str) -> Result<Vec<f64>> {
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
struct SnapshotFile {
    path: PathBuf,
    name: String,
    time: f64,
}

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
struct Snapshot {
    index: PointIndex,
    values: Vec<Option<Vec<f64>>>,
}

/// Reads the dataset `name` of a snapshot with `n` rows (any number when `None`): a scalar of shape (N),
/// or with `vector` a vector of shape (N, 3) (runs written before the 3-component output: (N, 2)),
/// returned as x, y pairs.
fn read_dataset(path: &Path, name: &str, n: Option<usize>, vector: bool) -> Result<Vec<f64>> {
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

    fn quantity(&mut self, file: &SnapshotFile, q: usize) -> Result<&[f64]> {
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

// ---------------------------------------------------------------------------------------------------
// Metrics and report

/// A signed value at the peak of `|value|`, and its time.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Peak {
    /// Value (signed) where `|value|` is largest.
    pub value: f64,
    /// Time (s).
    pub time: f64,
}

/// One compared history row.
#[derive(Debug, Clone, Serialize)]
pub struct HistoryValue {
    /// Line in the reference file.
    pub line: usize,
    /// Time (s).
    pub time: f64,
    /// Reference value.
    pub reference: f64,
    /// Run value (interpolated in time).
    pub run: f64,
}

/// Metrics of one history column.
#[derive(Debug, Clone, Serialize)]
pub struct ColumnReport {
    /// History column.
    pub column: String,
    /// `||run - ref||_2 / ||ref||_2` over the reference rows (null in JSON: infinite).
    pub rel_l2: f64,
    /// `max |run - ref| / max |ref|`.
    pub rel_max: f64,
    /// Time of the largest `|run - ref|` (s).
    pub max_error_time: f64,
    /// Peak of the reference.
    pub peak_reference: Peak,
    /// Peak of the run within the reference's time range (its rows and the interpolated values).
    pub peak_run: Peak,
    /// Both errors within the tolerance.
    pub passed: bool,
    /// The compared rows.
    pub values: Vec<HistoryValue>,
}

/// One compared point.
#[derive(Debug, Clone, Serialize)]
pub struct PointValue {
    /// Line in the reference file.
    pub line: usize,
    /// Reference position (mm).
    pub x: f64,
    /// Reference position (mm).
    pub y: f64,
    /// Reference value.
    pub reference: f64,
    /// Run value (local linear fit).
    pub run: f64,
    /// `|run - ref| / scale`.
    pub error: f64,
}

/// Metrics of the points of one quantity at one snapshot.
#[derive(Debug, Clone, Serialize)]
pub struct GroupReport {
    /// Quantity.
    pub quantity: String,
    /// Reference time of the group's first row (s).
    pub time: f64,
    /// Snapshot file.
    pub snapshot: String,
    /// Its time (s).
    pub snapshot_time: f64,
    /// `max |ref|` of the group.
    pub scale: f64,
    /// `||run - ref||_2 / ||ref||_2`.
    pub rel_l2: f64,
    /// `max |run - ref| / max |ref|`.
    pub rel_max: f64,
    /// Both errors within the tolerance.
    pub passed: bool,
    /// The points.
    pub points: Vec<PointValue>,
}

/// Metrics of one reference file.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ReferenceReport {
    /// History reference.
    History {
        /// File.
        file: String,
        /// Reference rows.
        rows: usize,
        /// One entry per column.
        columns: Vec<ColumnReport>,
    },
    /// Point reference.
    Point {
        /// File.
        file: String,
        /// Reference rows.
        rows: usize,
        /// One entry per quantity and snapshot.
        groups: Vec<GroupReport>,
    },
}

/// Everything `compare` measured.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Run directory.
    pub run: String,
    /// Tolerance of the relative errors.
    pub tolerance: f64,
    /// Every relative error within the tolerance.
    pub passed: bool,
    /// Relative errors checked.
    pub checked: usize,
    /// One entry per reference file.
    pub references: Vec<ReferenceReport>,
    /// Errors above the tolerance, one line each.
    pub failures: Vec<String>,
}

/// Relative L2 and max errors of `run` against `reference`, and the index of the largest difference. A
/// zero reference gives 0 when the run is zero too, else infinity.
pub fn relative_errors(reference: &[f64], run: &[f64]) -> (f64, f64, usize) {
    let ratio = |num: f64, den: f64| {
        if den > 0.0 {
            num / den
        } else if num == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    };
    let (mut dd, mut rr, mut dmax, mut rmax, mut at) = (0.0, 0.0, 0.0f64, 0.0f64, 0);
    for (i, (r, m)) in reference.iter().zip(run).enumerate() {
        let d = (m - r).abs();
        dd += d * d;
        rr += r * r;
        if d > dmax || d.is_nan() {
            dmax = d;
            at = i;
        }
        rmax = rmax.max(r.abs());
    }
    (ratio(dd.sqrt(), rr.sqrt()), ratio(dmax, rmax), at)
}

fn peak(samples: impl Iterator<Item = (f64, f64)>) -> Peak {
    let mut best = Peak {
        value: 0.0,
        time: f64::NAN,
    };
    for (t, v) in samples {
        if best.time.is_nan() || v.abs() > best.value.abs() {
            best = Peak { value: v, time: t };
        }
    }
    best
}

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
    fn time_tol(&self, t: f64) -> f64 {
        self.time_tolerance
            .unwrap_or_else(|| default_time_tolerance(t))
    }
}

fn compare_history(
    r: &HistoryReference,
    history: &RunHistory,
    s: &Settings,
) -> Result<Vec<ColumnReport>> {
    let asked_by = format!("{}:{}", r.file, r.header_line);
    let (t_first, t_last) = (history.times[0], history.times[history.times.len() - 1]);
    let mut out = Vec::with_capacity(r.columns.len());
    for (c, name) in r.columns.iter().enumerate() {
        let run_col = history.column(name, &asked_by)?;
        let mut values = Vec::with_capacity(r.rows.len());
        for (line, t, v) in &r.rows {
            let run = interpolate(&history.times, &run_col, *t, s.time_tol(*t)).ok_or_else(|| {
                bad(format!(
                    "{}:{line}: time {} s is outside the run's history ({} .. {} s in {}; it starts at the end \
                     of the first step; --time-tolerance widens the ends)",
                    r.file,
                    short(*t),
                    short(t_first),
                    short(t_last),
                    history.csv.name
                ))
            })?;
            values.push(HistoryValue {
                line: *line,
                time: *t,
                reference: v[c],
                run,
            });
        }
        let reference: Vec<f64> = values.iter().map(|v| v.reference).collect();
        let run: Vec<f64> = values.iter().map(|v| v.run).collect();
        let (rel_l2, rel_max, at) = relative_errors(&reference, &run);
        let (lo, hi) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
                (a.0.min(v.time), a.1.max(v.time))
            });
        let (lo, hi) = (lo - s.time_tol(lo), hi + s.time_tol(hi));
        let peak_run = peak(
            history
                .times
                .iter()
                .zip(&run_col)
                .filter(|(t, _)| (lo..=hi).contains(*t))
                .map(|(t, v)| (*t, *v))
                .chain(values.iter().map(|v| (v.time, v.run))),
        );
        out.push(ColumnReport {
            column: name.clone(),
            rel_l2,
            rel_max,
            max_error_time: values[at].time,
            peak_reference: peak(values.iter().map(|v| (v.time, v.reference))),
            peak_run,
            passed: rel_l2 <= s.tolerance && rel_max <= s.tolerance,
            values,
        });
    }
    Ok(out)
}

/// Snapshots listed once and loaded on demand.
struct Snapshots {
    dir: PathBuf,
    files: Option<Vec<SnapshotFile>>,
    loaded: Vec<Option<Snapshot>>,
}

impl Snapshots {
    fn files(&mut self) -> Result<&[SnapshotFile]> {
        if self.files.is_none() {
            let f = list_snapshots(&self.dir)?;
            self.loaded = (0..f.len()).map(|_| None).collect();
            self.files = Some(f);
        }
        Ok(self.files.as_deref().unwrap_or_default())
    }

    /// The snapshot nearest in time to a reference row's time.
    fn find(&mut self, file: &str, line: usize, t: f64, tol: f64) -> Result<usize> {
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

    fn get(&mut self, i: usize) -> Result<(&SnapshotFile, &mut Snapshot)> {
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

fn compare_points(
    r: &PointReference,
    snaps: &mut Snapshots,
    s: &Settings,
) -> Result<Vec<GroupReport>> {
    // Group the rows by (quantity, snapshot), in the order of their first appearance.
    let mut groups: Vec<((usize, usize), Vec<&PointRow>)> = Vec::new();
    for row in &r.rows {
        let snap = snaps.find(&r.file, row.line, row.time, s.time_tol(row.time))?;
        let key = (row.quantity, snap);
        match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => g.1.push(row),
            None => groups.push((key, vec![row])),
        }
    }
    let mut out = Vec::with_capacity(groups.len());
    for ((q, snap), rows) in groups {
        let (file, snapshot) = snaps.get(snap)?;
        snapshot.quantity(file, q)?;
        let snapshot = &*snapshot;
        let field = snapshot.values[q].as_deref().unwrap_or_default();
        let reference_points = snapshot.index.points();
        let mut run = Vec::with_capacity(rows.len());
        for row in &rows {
            let at = [row.x, row.y];
            let near = snapshot.index.nearest(at, s.neighbours);
            if near.len() < 3 {
                return Err(bad(format!(
                    "{}:{}: {} holds {} material points, a fit needs at least 3",
                    r.file,
                    row.line,
                    file.name,
                    reference_points.len()
                )));
            }
            // The point must lie within the material: no farther from its nearest material point than
            // that point's own fit neighbourhood reaches.
            let p1 = reference_points[near[0]];
            let d1 = (p1[0] - at[0]).hypot(p1[1] - at[1]);
            let around = snapshot.index.nearest(p1, s.neighbours);
            let reach = around.last().map_or(0.0, |&j| {
                let pj = reference_points[j];
                (pj[0] - p1[0]).hypot(pj[1] - p1[1])
            });
            if d1 > reach {
                return Err(bad(format!(
                    "{}:{}: point ({}, {}) mm lies {d1:.4e} mm from the nearest material point of {} \
                     (reference configuration), outside the material: allowed within {reach:.4e} mm",
                    r.file, row.line, row.x, row.y, file.name
                )));
            }
            let pts: Vec<[f64; 2]> = near.iter().map(|&i| reference_points[i]).collect();
            let vals: Vec<f64> = near.iter().map(|&i| field[i]).collect();
            let v = linear_fit(&pts, &vals, at).ok_or_else(|| {
                bad(format!(
                    "{}:{}: the {} material points nearest to ({}, {}) mm do not span a plane (collinear); \
                     a larger --neighbours may help",
                    r.file,
                    row.line,
                    near.len(),
                    row.x,
                    row.y
                ))
            })?;
            run.push(v);
        }
        let reference: Vec<f64> = rows.iter().map(|row| row.value).collect();
        let (rel_l2, rel_max, _) = relative_errors(&reference, &run);
        let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let points = rows
            .iter()
            .zip(&run)
            .map(|(row, &v)| {
                let d = (v - row.value).abs();
                PointValue {
                    line: row.line,
                    x: row.x,
                    y: row.y,
                    reference: row.value,
                    run: v,
                    error: if scale > 0.0 {
                        d / scale
                    } else if d == 0.0 {
                        0.0
                    } else {
                        f64::INFINITY
                    },
                }
            })
            .collect();
        out.push(GroupReport {
            quantity: QUANTITIES[q].0.to_owned(),
            time: rows[0].time,
            snapshot: file.name.clone(),
            snapshot_time: file.time,
            scale,
            rel_l2,
            rel_max,
            passed: rel_l2 <= s.tolerance && rel_max <= s.tolerance,
            points,
        });
    }
    Ok(out)
}

/// Compares the run in `run_dir` with every reference file.
pub fn compare(run_dir: &Path, references: &[PathBuf], s: &Settings) -> Result<Report> {
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
    // Read and check every reference before any comparison.
    let parsed = references
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p)
                .map_err(|e| bad(format!("{}: cannot read: {e}", p.display())))?;
            parse_reference(&text, &p.display().to_string())
        })
        .collect::<Result<Vec<_>>>()?;
    let mut history: Option<RunHistory> = None;
    let mut snaps = Snapshots {
        dir: run_dir.to_owned(),
        files: None,
        loaded: Vec::new(),
    };
    let mut reports = Vec::with_capacity(parsed.len());
    let mut failures = Vec::new();
    let mut checked = 0;
    let tol = s.tolerance;
    for r in &parsed {
        match r {
            Reference::History(h) => {
                let run = match &mut history {
                    Some(run) => run,
                    None => history.insert(RunHistory::read(run_dir)?),
                };
                let columns = compare_history(h, run, s)?;
                for c in &columns {
                    checked += 2;
                    if c.rel_l2 > tol || c.rel_l2.is_nan() {
                        failures.push(format!(
                            "{}: column `{}`: relative L2 error {} > {}{}",
                            h.file,
                            c.column,
                            num(c.rel_l2),
                            short(tol),
                            zero_note(c.rel_l2)
                        ));
                    }
                    if c.rel_max > tol || c.rel_max.is_nan() {
                        failures.push(format!(
                            "{}: column `{}`: relative max error {} > {} (largest at t = {} s){}",
                            h.file,
                            c.column,
                            num(c.rel_max),
                            short(tol),
                            short(c.max_error_time),
                            zero_note(c.rel_max)
                        ));
                    }
                }
                reports.push(ReferenceReport::History {
                    file: h.file.clone(),
                    rows: h.rows.len(),
                    columns,
                });
            }
            Reference::Point(p) => {
                let groups = compare_points(p, &mut snaps, s)?;
                for g in &groups {
                    checked += 2;
                    let worst = g.points.iter().max_by(|a, b| a.error.total_cmp(&b.error));
                    let what = format!(
                        "{}: {} at t = {} s ({})",
                        p.file,
                        g.quantity,
                        short(g.snapshot_time),
                        g.snapshot
                    );
                    if g.rel_l2 > tol || g.rel_l2.is_nan() {
                        failures.push(format!(
                            "{what}: relative L2 error {} > {}{}",
                            num(g.rel_l2),
                            short(tol),
                            zero_note(g.rel_l2)
                        ));
                    }
                    if g.rel_max > tol || g.rel_max.is_nan() {
                        let at = worst.map_or(String::new(), |w| {
                            format!(" (largest at ({}, {}) mm, line {})", w.x, w.y, w.line)
                        });
                        failures.push(format!(
                            "{what}: relative max error {} > {}{at}{}",
                            num(g.rel_max),
                            short(tol),
                            zero_note(g.rel_max)
                        ));
                    }
                }
                reports.push(ReferenceReport::Point {
                    file: p.file.clone(),
                    rows: p.rows.len(),
                    groups,
                });
            }
        }
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

/// The shorter of `{}` and `{:e}` (0.01, 1e-6).
fn short(v: f64) -> String {
    let (a, b) = (format!("{v}"), format!("{v:e}"));
    if b.len() < a.len() { b } else { a }
}

/// ` (the reference is zero: no scale)` for an infinite relative error.
fn zero_note(v: f64) -> &'static str {
    if v.is_infinite() {
        " (the reference is zero everywhere, so there is no scale: only an exactly zero run passes)"
    } else {
        ""
    }
}

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        format!("{v}")
    }
}

impl Report {
    /// The metrics as Markdown tables, followed by the verdict.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "run {}: tolerance {} on every relative error",
            self.run,
            short(self.tolerance)
        );
        let ok = |p: bool| if p { "ok" } else { "FAIL" };
        for r in &self.references {
            match r {
                ReferenceReport::History {
                    file,
                    rows,
                    columns,
                } => {
                    let _ = writeln!(s, "\n{file}: history reference, {rows} rows\n");
                    s.push_str("| column | rel. L2 | rel. max | largest error at t (s) | peak ref @ t (s) | peak run @ t (s) | |\n|---|---|---|---|---|---|---|\n");
                    for c in columns {
                        let _ = writeln!(
                            s,
                            "| {} | {} | {} | {} | {} @ {} | {} @ {} | {} |",
                            c.column,
                            num(c.rel_l2),
                            num(c.rel_max),
                            num(c.max_error_time),
                            num(c.peak_reference.value),
                            num(c.peak_reference.time),
                            num(c.peak_run.value),
                            num(c.peak_run.time),
                            ok(c.passed)
                        );
                    }
                }
                ReferenceReport::Point { file, rows, groups } => {
                    let _ = writeln!(s, "\n{file}: point reference, {rows} rows\n");
                    s.push_str("| quantity | t (s) | snapshot | points | scale | rel. L2 | rel. max | |\n|---|---|---|---|---|---|---|---|\n");
                    for g in groups {
                        let _ = writeln!(
                            s,
                            "| {} | {} | {} ({} s) | {} | {} | {} | {} | {} |",
                            g.quantity,
                            num(g.time),
                            g.snapshot,
                            num(g.snapshot_time),
                            g.points.len(),
                            num(g.scale),
                            num(g.rel_l2),
                            num(g.rel_max),
                            ok(g.passed)
                        );
                    }
                    s.push_str("\n| quantity | t (s) | x (mm) | y (mm) | reference | run | error / scale |\n|---|---|---|---|---|---|---|\n");
                    for g in groups {
                        for p in &g.points {
                            let _ = writeln!(
                                s,
                                "| {} | {} | {} | {} | {} | {} | {} |",
                                g.quantity,
                                num(g.time),
                                short(p.x),
                                short(p.y),
                                num(p.reference),
                                num(p.run),
                                num(p.error)
                            );
                        }
                    }
                }
            }
        }
        if self.passed {
            let _ = writeln!(
                s,
                "\nPASSED: all {} relative errors <= {}",
                self.checked,
                short(self.tolerance)
            );
        } else {
            let _ = writeln!(
                s,
                "\nFAILED: {} of {} relative errors > {}:",
                self.failures.len(),
                self.checked,
                short(self.tolerance)
            );
            for f in &self.failures {
                let _ = writeln!(s, "  {f}");
            }
        }
        s
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_quantity_reads_a_field_the_writer_writes() {
        for (quantity, dataset, component) in QUANTITIES {
            let field = crate::io::FIELDS
                .iter()
                .find(|f| f.name == dataset)
                .unwrap_or_else(|| {
                    panic!("`{quantity}` reads `{dataset}`, which io does not write")
                });
            assert_eq!(
                component.is_some(),
                field.kind == crate::io::Kind::Vector,
                "{quantity}: component of a vector field, none of a scalar"
            );
        }
    }

    /// A regular lattice of points over [0, 10] x [0, 5], spacing 0.5, offset by a quarter spacing (like
    /// material points in their cells).
    fn lattice() -> Vec<[f64; 2]> {
        let mut pts = Vec::new();
        for j in 0..10 {
            for i in 0..20 {
                pts.push([0.125 + 0.5 * i as f64, 0.125 + 0.5 * j as f64]);
            }
        }
        pts
    }

    #[test]
    fn vectors_are_read_as_xy_pairs_from_3_and_2_component_snapshots() {
        let dir = std::env::temp_dir().join(format!("mpmc-compare-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("fields.h5");
        {
            let f = hdf5_metno::File::create(&path).expect("create");
            let put = |name: &str, data: ndarray::ArrayD<f64>| {
                f.new_dataset_builder()
                    .with_data(&data)
                    .create(name)
                    .expect("dataset");
            };
            let xyz = ndarray::arr2(&[[1.0, 2.0, 0.0], [3.0, 4.0, 0.0]]);
            put("xyz", xyz.into_dyn());
            put("xy", ndarray::arr2(&[[1.0, 2.0], [3.0, 4.0]]).into_dyn());
            put("scalar", ndarray::arr1(&[5.0, 6.0]).into_dyn());
        }
        for name in ["xyz", "xy"] {
            let v = read_dataset(&path, name, Some(2), true).expect(name);
            assert_eq!(v, [1.0, 2.0, 3.0, 4.0], "{name}");
        }
        let s = read_dataset(&path, "scalar", None, false).expect("scalar");
        assert_eq!(s, [5.0, 6.0]);
        let e = read_dataset(&path, "xyz", Some(3), true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("shape [2, 3], expected (3, 3)"), "{e}");
        let e = read_dataset(&path, "scalar", None, true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("shape [2], expected (N, 3)"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn fit_reproduces_a_linear_field_inside_and_extrapolated_at_corners() {
        let index = PointIndex::new(lattice());
        let f = |p: [f64; 2]| 3.5 - 0.7 * p[0] + 2.25 * p[1];
        let pts = index.points().to_vec();
        let values: Vec<f64> = pts.iter().map(|&p| f(p)).collect();
        for at in [[0.0, 0.0], [10.0, 5.0], [0.0, 5.0], [4.3, 2.1], [10.0, 2.6]] {
            let near = index.nearest(at, 12);
            assert_eq!(near.len(), 12);
            let p: Vec<[f64; 2]> = near.iter().map(|&i| pts[i]).collect();
            let v: Vec<f64> = near.iter().map(|&i| values[i]).collect();
            let got = linear_fit(&p, &v, at).expect("fit");
            assert!(
                (got - f(at)).abs() <= 1e-12 * f(at).abs().max(1.0),
                "at {at:?}: {got} vs {}",
                f(at)
            );
        }
    }

    #[test]
    fn fit_of_collinear_points_is_refused() {
        let pts: Vec<[f64; 2]> = (0..6).map(|i| [i as f64, 2.0 * i as f64]).collect();
        let vals: Vec<f64> = (0..6).map(|i| i as f64).collect();
        assert_eq!(linear_fit(&pts, &vals, [1.0, 1.0]), None);
        assert_eq!(linear_fit(&pts[..2], &vals[..2], [1.0, 1.0]), None);
    }

    #[test]
    fn nearest_matches_brute_force() {
        // Deterministic scattered points (a linear congruential sequence), some queries outside.
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let pts: Vec<[f64; 2]> = (0..500).map(|_| [100.0 * next(), 20.0 * next()]).collect();
        let index = PointIndex::new(pts.clone());
        let queries = [
            [50.0, 10.0],
            [-30.0, -5.0],
            [130.0, 40.0],
            [0.0, 10.0],
            [99.0, 0.5],
        ];
        for q in queries {
            let got = index.nearest(q, 12);
            let mut all: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2), i))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let want: Vec<usize> = all[..12].iter().map(|a| a.1).collect();
            assert_eq!(got, want, "query {q:?}");
        }
        assert_eq!(index.nearest([0.0, 0.0], 1000).len(), 500);
        assert!(
            PointIndex::new(Vec::new())
                .nearest([0.0, 0.0], 3)
                .is_empty()
        );
    }

    #[test]
    fn interpolation_in_time() {
        let t = [1.0e-6, 2.0e-6, 3.0e-6, 5.0e-6];
        let v = [10.0, 20.0, 40.0, 0.0];
        let tol = 1e-12;
        assert_eq!(interpolate(&t, &v, 2.0e-6, tol), Some(20.0));
        assert_eq!(interpolate(&t, &v, 5.0e-6, tol), Some(0.0));
        let mid = interpolate(&t, &v, 2.5e-6, tol).expect("inside");
        assert!((mid - 30.0).abs() < 1e-9);
        let late = interpolate(&t, &v, 4.5e-6, tol).expect("inside");
        assert!((late - 10.0).abs() < 1e-9);
        // Round-off at the ends is accepted, more is not.
        assert_eq!(interpolate(&t, &v, 5.0e-6 + 1e-13, tol), Some(0.0));
        assert_eq!(interpolate(&t, &v, 1.0e-6 - 1e-13, tol), Some(10.0));
        assert_eq!(interpolate(&t, &v, 5.1e-6, tol), None);
        assert_eq!(interpolate(&t, &v, 0.0, tol), None);
        // A single sample.
        assert_eq!(interpolate(&[4e-3], &[7.0], 4e-3, tol), Some(7.0));
        assert_eq!(interpolate(&[], &[], 0.0, tol), None);
    }

    #[test]
    fn relative_errors_and_zero_references() {
        let (l2, max, at) = relative_errors(&[1.0, -2.0, 2.0], &[1.0, -2.0, 2.2]);
        assert!((l2 - 0.2 / 3.0).abs() < 1e-12);
        assert!((max - 0.1).abs() < 1e-12);
        assert_eq!(at, 2);
        assert_eq!(relative_errors(&[0.0, 0.0], &[0.0, 0.0]).0, 0.0);
        assert_eq!(relative_errors(&[0.0, 0.0], &[0.0, 1e-9]).1, f64::INFINITY);
    }

    #[test]
    fn reference_kinds_and_messages() {
        let h = parse_reference(
            "# a comment\ntime,load_fy\n1e-6,2.0\n\n# more\n2e-6,3.0\n",
            "h.csv",
        )
        .expect("history");
        match h {
            Reference::History(h) => {
                assert_eq!(h.columns, ["load_fy"]);
                assert_eq!(h.rows, vec![(3, 1e-6, vec![2.0]), (6, 2e-6, vec![3.0])]);
            }
            Reference::Point(_) => panic!("not a point reference"),
        }
        let p = parse_reference("time,x,y,quantity,value\n0.1,1,2,sigma_xx,-3.5\n", "p.csv")
            .expect("points");
        assert!(matches!(p, Reference::Point(ref p) if p.rows[0].quantity == 4));
        let err = |text: &str| parse_reference(text, "r.csv").unwrap_err().to_string();
        let e = err("time,x,y,quantity,value\n0.1,1,2,strain,1\n");
        assert!(
            e.starts_with("r.csv:2: quantity `strain` is unknown; allowed: ux, uy"),
            "{e}"
        );
        let e = err("t,load\n1,2\n");
        assert!(e.starts_with("r.csv:1: header `t,load`: expected"), "{e}");
        let e = err("time,a\n1,2\n3\n");
        assert!(e.starts_with("r.csv:3: 1 fields, the header has 2"), "{e}");
        let e = err("time,a\n1,abc\n");
        assert!(
            e.starts_with("r.csv:2: `a` = `abc` is not a finite number"),
            "{e}"
        );
        let e = err("time,a,a\n1,2,3\n");
        assert!(e.contains("appears twice"), "{e}");
        let e = err("# only a comment\n");
        assert!(e.contains("no header"), "{e}");
        let e = err("time,a\n");
        assert!(e.contains("no data rows"), "{e}");
    }
}
