//! The metrics `compare` reports (JSON through serde) and their Markdown table.

use serde::Serialize;
use std::fmt::Write as _;

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

impl ReferenceReport {
    /// Relative errors this reference checked: two (L2 and max) per column or group.
    pub(super) fn checked(&self) -> usize {
        match self {
            ReferenceReport::History { columns, .. } => 2 * columns.len(),
            ReferenceReport::Point { groups, .. } => 2 * groups.len(),
        }
    }

    /// The messages of every relative error above `tol`, in the order of the columns or groups.
    pub(super) fn failures(&self, tol: f64) -> Vec<String> {
        match self {
            ReferenceReport::History { file, columns, .. } => columns
                .iter()
                .flat_map(|c| column_failures(file, c, tol))
                .collect(),
            ReferenceReport::Point { file, groups, .. } => groups
                .iter()
                .flat_map(|g| group_failures(file, g, tol))
                .collect(),
        }
    }
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

/// The shorter of `{}` and `{:e}` (0.01, 1e-6).
pub(super) fn short(v: f64) -> String {
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

/// A metric in the table: three significant digits, or `inf`/`NaN` as they are.
fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        format!("{v}")
    }
}

/// `ok` or `FAIL`.
fn ok(passed: bool) -> &'static str {
    if passed { "ok" } else { "FAIL" }
}

/// The failure lines of one history column of `file` (none when both errors are within `tol`).
fn column_failures(file: &str, c: &ColumnReport, tol: f64) -> Vec<String> {
    let mut failures = Vec::new();
    if c.rel_l2 > tol || c.rel_l2.is_nan() {
        failures.push(format!(
            "{}: column `{}`: relative L2 error {} > {}{}",
            file,
            c.column,
            num(c.rel_l2),
            short(tol),
            zero_note(c.rel_l2)
        ));
    }
    if c.rel_max > tol || c.rel_max.is_nan() {
        failures.push(format!(
            "{}: column `{}`: relative max error {} > {} (largest at t = {} s){}",
            file,
            c.column,
            num(c.rel_max),
            short(tol),
            short(c.max_error_time),
            zero_note(c.rel_max)
        ));
    }
    failures
}

/// The failure lines of one point group of `file` (none when both errors are within `tol`).
fn group_failures(file: &str, g: &GroupReport, tol: f64) -> Vec<String> {
    let mut failures = Vec::new();
    let worst = g.points.iter().max_by(|a, b| a.error.total_cmp(&b.error));
    let what = format!(
        "{}: {} at t = {} s ({})",
        file,
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
    failures
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
        for r in &self.references {
            match r {
                ReferenceReport::History {
                    file,
                    rows,
                    columns,
                } => history_table(&mut s, file, *rows, columns),
                ReferenceReport::Point { file, rows, groups } => {
                    point_table(&mut s, file, *rows, groups)
                }
            }
        }
        self.verdict(&mut s);
        s
    }

    /// Appends `PASSED: ...` or `FAILED: ...` with the failure lines.
    fn verdict(&self, s: &mut String) {
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
    }
}

/// Appends a Markdown table: `header` (the line of column names and the rule under it) and one line per
/// row of `rows`, its cells joined by ` | `.
fn markdown_table(s: &mut String, header: &str, rows: impl IntoIterator<Item = Vec<String>>) {
    s.push_str(header);
    for row in rows {
        let _ = writeln!(s, "| {} |", row.join(" | "));
    }
}

/// Appends the table of a history reference: one row per column.
fn history_table(s: &mut String, file: &str, rows: usize, columns: &[ColumnReport]) {
    let _ = writeln!(s, "\n{file}: history reference, {rows} rows\n");
    let header = "| column | rel. L2 | rel. max | largest error at t (s) | peak ref @ t (s) | peak run @ t (s) | |\n|---|---|---|---|---|---|---|\n";
    let at = |p: &Peak| format!("{} @ {}", num(p.value), num(p.time));
    markdown_table(
        s,
        header,
        columns.iter().map(|c| {
            vec![
                c.column.clone(),
                num(c.rel_l2),
                num(c.rel_max),
                num(c.max_error_time),
                at(&c.peak_reference),
                at(&c.peak_run),
                ok(c.passed).into(),
            ]
        }),
    );
}

/// Appends the tables of a point reference: one row per group, then one row per point.
fn point_table(s: &mut String, file: &str, rows: usize, groups: &[GroupReport]) {
    let _ = writeln!(s, "\n{file}: point reference, {rows} rows\n");
    let header = "| quantity | t (s) | snapshot | points | scale | rel. L2 | rel. max | |\n|---|---|---|---|---|---|---|---|\n";
    let group_rows = groups.iter().map(|g| {
        vec![
            g.quantity.clone(),
            num(g.time),
            format!("{} ({} s)", g.snapshot, num(g.snapshot_time)),
            g.points.len().to_string(),
            num(g.scale),
            num(g.rel_l2),
            num(g.rel_max),
            ok(g.passed).into(),
        ]
    });
    markdown_table(s, header, group_rows);
    let header = "\n| quantity | t (s) | x (mm) | y (mm) | reference | run | error / scale |\n|---|---|---|---|---|---|---|\n";
    let point_rows = groups.iter().flat_map(|g| {
        g.points.iter().map(|p| {
            vec![
                g.quantity.clone(),
                num(g.time),
                short(p.x),
                short(p.y),
                num(p.reference),
                num(p.run),
                num(p.error),
            ]
        })
    });
    markdown_table(s, header, point_rows);
}
