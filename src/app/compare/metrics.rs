//! The comparison proper: relative errors of history columns and of point groups.

use super::numerics::{interpolate, linear_fit};
use super::reference::{HistoryReference, PointReference, PointRow, QUANTITIES};
use super::report::{ColumnReport, GroupReport, HistoryValue, Peak, PointValue, short};
use super::run_data::{RunHistory, Snapshot, SnapshotFile, Snapshots};
use super::{Result, Settings, bad};

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

/// The sample with the largest `|value|` (the first of equals).
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

/// Relative errors of every column of a history reference.
pub(super) fn compare_history(
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

/// The rows of a point reference grouped by (quantity, snapshot), in the order of their first appearance.
type Groups<'a> = Vec<((usize, usize), Vec<&'a PointRow>)>;

/// Relative errors of every (quantity, snapshot) group of a point reference.
pub(super) fn compare_points(
    r: &PointReference,
    snaps: &mut Snapshots,
    s: &Settings,
) -> Result<Vec<GroupReport>> {
    let groups = group_rows(r, snaps, s)?;
    let mut out = Vec::with_capacity(groups.len());
    for ((q, snap), rows) in groups {
        let (file, snapshot) = snaps.get(snap)?;
        snapshot.quantity(file, q)?;
        let snapshot = &*snapshot;
        let run = rows
            .iter()
            .map(|row| fit_at(r, row, file, snapshot, q, s))
            .collect::<Result<Vec<f64>>>()?;
        out.push(group_report(&rows, &run, file, q, s));
    }
    Ok(out)
}

/// Groups the rows by (quantity, snapshot nearest in time), in the order of their first appearance.
fn group_rows<'a>(
    r: &'a PointReference,
    snaps: &mut Snapshots,
    s: &Settings,
) -> Result<Groups<'a>> {
    let mut groups: Groups<'a> = Vec::new();
    for row in &r.rows {
        let snap = snaps.find(&r.file, row.line, row.time, s.time_tol(row.time))?;
        let key = (row.quantity, snap);
        match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => g.1.push(row),
            None => groups.push((key, vec![row])),
        }
    }
    Ok(groups)
}

/// The run's value of quantity `q` at a row's point: the local linear fit over the nearest material
/// points of the snapshot, refused outside the material.
fn fit_at(
    r: &PointReference,
    row: &PointRow,
    file: &SnapshotFile,
    snapshot: &Snapshot,
    q: usize,
    s: &Settings,
) -> Result<f64> {
    let field = snapshot.values[q].as_deref().unwrap_or_default();
    let reference_points = snapshot.index.points();
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
    linear_fit(&pts, &vals, at).ok_or_else(|| {
        bad(format!(
            "{}:{}: the {} material points nearest to ({}, {}) mm do not span a plane (collinear); \
             a larger --neighbours may help",
            r.file,
            row.line,
            near.len(),
            row.x,
            row.y
        ))
    })
}

/// The metrics of one group from its rows and the run's fitted values.
fn group_report(
    rows: &[&PointRow],
    run: &[f64],
    file: &SnapshotFile,
    q: usize,
    s: &Settings,
) -> GroupReport {
    let reference: Vec<f64> = rows.iter().map(|row| row.value).collect();
    let (rel_l2, rel_max, _) = relative_errors(&reference, run);
    let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let points = rows
        .iter()
        .zip(run)
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
    GroupReport {
        quantity: QUANTITIES[q].0.to_owned(),
        time: rows[0].time,
        snapshot: file.name.clone(),
        snapshot_time: file.time,
        scale,
        rel_l2,
        rel_max,
        passed: rel_l2 <= s.tolerance && rel_max <= s.tolerance,
        points,
    }
}
