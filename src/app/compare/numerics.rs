//! Numerics of the comparison: interpolation in time, neighbour search, local linear fit.

use nalgebra::{DMatrix, DVector};

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
