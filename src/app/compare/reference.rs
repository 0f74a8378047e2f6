//! Reference files: the history reference (`time,<col>...`) and the point reference
//! (`time,x,y,quantity,value`), parsed and checked before any comparison.

use super::csv::Csv;
use super::{Result, bad};

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

/// The names of [`QUANTITIES`], comma-separated.
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
