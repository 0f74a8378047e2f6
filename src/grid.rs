//! The fixed Cartesian background grid of the MPM step (spec `01-model.md`, Sec. 1 and 2).
//!
//! A uniform 2D grid with origin `x_0` (mm), square cells of size `h` (mm), `nx` x `ny` cells and
//! `(nx + 1) (ny + 1)` nodes. Node `(i, j)` sits at `x_0 + (i h, j h)` and has the global index
//! `I = i + j (nx + 1)`; cell `(i, j)` spans `[x_0 + i h, x_0 + (i + 1) h] x [x_0 + j h, x_0 + (j + 1) h]`
//! and has the index `i + j nx`.
//!
//! The grid functions are the bilinear hat functions
//!
//! ```text
//! N_I(x) = n((x - x_I) / h) n((y - y_I) / h),   n(s) = max(0, 1 - |s|)            [-]
//! grad N_I(x) = (n'(sx) n(sy), n(sx) n'(sy)) / h                                   [1/mm]
//! ```
//!
//! On a cell edge the gradient is taken from the cell that owns the point: a point belongs to the cell
//! `floor((x - x_0) / h)`, except on the far boundary of the grid, which belongs to the last cell. Every
//! interpolator in [`crate::shape`] is built on [`Grid::cell_weights`].

use nalgebra::Vector2;
use thiserror::Error;

/// Which point of a material point's domain left the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Locus {
    /// The material point position `x_p` (or the support of its GIMP/B-spline function).
    Centre,
    /// Corner `c` (0..4, counter-clockwise from `x_p - r1 - r2`) of the CPDI domain.
    Corner(u8),
}

impl std::fmt::Display for Locus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Locus::Centre => write!(f, "position"),
            Locus::Corner(c) => write!(f, "CPDI corner {}", c + 1),
        }
    }
}

/// Errors of the background grid.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum GridError {
    /// The cell size must be a positive, finite length.
    #[error("grid cell size h = {h} mm must be positive and finite")]
    InvalidCellSize {
        /// Requested cell size (mm).
        h: f64,
    },
    /// The box to cover must be finite with `min <= max`.
    #[error("grid bounds must be finite with min <= max, got min = {min:?} mm, max = {max:?} mm")]
    InvalidBounds {
        /// Lower-left corner (mm).
        min: [f64; 2],
        /// Upper-right corner (mm).
        max: [f64; 2],
    },
    /// A grid needs at least one cell in each direction.
    #[error("a grid needs at least one cell per direction, got {nx} x {ny}")]
    NoCells {
        /// Cells in x.
        nx: usize,
        /// Cells in y.
        ny: usize,
    },
    /// The node count does not fit the `u32` node indices of the weight table.
    #[error("a grid of {nx} x {ny} cells has too many nodes for 32-bit node indices")]
    TooLarge {
        /// Cells in x.
        nx: usize,
        /// Cells in y.
        ny: usize,
    },
    /// A material point or one of its CPDI corners lies outside the grid, or so close to its border that the
    /// support of its shape function would leave the grid. Recoverable: report it to SNES as a domain error.
    #[error(
        "material point {particle}: {locus} at ({x:.6}, {y:.6}) mm is outside the grid \
         (or its shape-function support leaves it); enlarge the grid margin"
    )]
    OutsideGrid {
        /// Material point index.
        particle: usize,
        /// Which point left the grid.
        locus: Locus,
        /// x coordinate (mm).
        x: f64,
        /// y coordinate (mm).
        y: f64,
    },
}

/// Values and gradients of the four bilinear hat functions of the cell that owns a point.
///
/// Nodes are ordered counter-clockwise: `(i, j)`, `(i + 1, j)`, `(i + 1, j + 1)`, `(i, j + 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellWeights {
    /// Global node indices `I`.
    pub nodes: [u32; 4],
    /// `N_I(x)` [-].
    pub values: [f64; 4],
    /// `grad N_I(x)` [1/mm].
    pub grads: [Vector2<f64>; 4],
}

/// Uniform 2D Cartesian background grid (lengths in mm).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    origin: Vector2<f64>,
    h: f64,
    nx: usize,
    ny: usize,
}

impl Grid {
    /// A grid with lower-left node `origin` (mm), cell size `h` (mm) and `nx` x `ny` cells.
    pub fn new(origin: Vector2<f64>, h: f64, nx: usize, ny: usize) -> Result<Self, GridError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(GridError::InvalidCellSize { h });
        }
        if !(origin.x.is_finite() && origin.y.is_finite()) {
            return Err(GridError::InvalidBounds {
                min: [origin.x, origin.y],
                max: [origin.x, origin.y],
            });
        }
        if nx == 0 || ny == 0 {
            return Err(GridError::NoCells { nx, ny });
        }
        if (nx as u128 + 1) * (ny as u128 + 1) > u32::MAX as u128 {
            return Err(GridError::TooLarge { nx, ny });
        }
        Ok(Self { origin, h, nx, ny })
    }

    /// The smallest grid of cell size `h` whose nodes lie on multiples of `h` (so that geometry on the
    /// lines `k h`, e.g. notch faces at y = 95 and 105 mm with h = 1 mm, stays on grid lines) and that covers
    /// the box `[min, max]` (mm) plus `margin_cells` empty cells on every side, so that shape-function supports
    /// (CPDI corners, GIMP and B-spline supports) do not leave the grid while the body deforms.
    pub fn covering(
        min: Vector2<f64>,
        max: Vector2<f64>,
        h: f64,
        margin_cells: usize,
    ) -> Result<Self, GridError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(GridError::InvalidCellSize { h });
        }
        let bounds_ok =
            (0..2).all(|k| min[k].is_finite() && max[k].is_finite() && min[k] <= max[k]);
        if !bounds_ok {
            return Err(GridError::InvalidBounds {
                min: [min.x, min.y],
                max: [max.x, max.y],
            });
        }
        // Snap with a relative tolerance so that bounds that are multiples of h up to round-off snap onto
        // their own grid line rather than one cell further out.
        let snap_tol = 1e-9;
        let margin = margin_cells as f64;
        let lo = min.map(|c| (c / h + snap_tol).floor() - margin);
        let hi = max.map(|c| (c / h - snap_tol).ceil() + margin);
        let cells = |k: usize| ((hi[k] - lo[k]).max(1.0)) as usize;
        Self::new(lo * h, h, cells(0), cells(1))
    }

    /// Lower-left node position `x_0` (mm).
    pub fn origin(&self) -> Vector2<f64> {
        self.origin
    }

    /// Cell size `h` (mm).
    pub fn cell_size(&self) -> f64 {
        self.h
    }

    /// Number of cells in x.
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// Number of cells in y.
    pub fn ny(&self) -> usize {
        self.ny
    }

    /// Number of nodes `(nx + 1) (ny + 1)`.
    pub fn num_nodes(&self) -> usize {
        (self.nx + 1) * (self.ny + 1)
    }

    /// Number of cells `nx ny`.
    pub fn num_cells(&self) -> usize {
        self.nx * self.ny
    }

    /// Upper-right node position (mm).
    pub fn upper(&self) -> Vector2<f64> {
        self.origin + Vector2::new(self.nx as f64, self.ny as f64) * self.h
    }

    /// Global node index `I = i + j (nx + 1)`.
    pub fn node_index(&self, i: usize, j: usize) -> usize {
        i + j * (self.nx + 1)
    }

    /// Global cell index `i + j nx`.
    pub fn cell_index(&self, i: usize, j: usize) -> usize {
        i + j * self.nx
    }

    /// Lattice indices `(i, j)` of node `I`; the copy `I + f N` of node `I` in velocity field `f`
    /// ([`ShapeTable::offset_fields`](crate::shape::ShapeTable::offset_fields)) maps to node `I`.
    pub fn node_ij(&self, node: usize) -> (usize, usize) {
        let node = node % self.num_nodes();
        (node % (self.nx + 1), node / (self.nx + 1))
    }

    /// Position `x_I` of node `I` (mm), also of its copies in other velocity fields.
    pub fn node_position(&self, node: usize) -> Vector2<f64> {
        let (i, j) = self.node_ij(node);
        self.origin + Vector2::new(i as f64, j as f64) * self.h
    }

    /// Cell `(i, j)` that owns `x`, or `None` outside the closed grid `[x_0, x_0 + (nx, ny) h]`.
    /// Points on an interior cell edge belong to the cell above/right of it; points on the far grid boundary
    /// belong to the last cell.
    #[inline]
    pub fn cell_of(&self, x: Vector2<f64>) -> Option<(usize, usize)> {
        self.locate(x).map(|(cell, _)| cell)
    }

    /// The cell `(i, j)` that owns `x` (as [`Grid::cell_of`]) and the local coordinates `f = (f_x, f_y)` in
    /// `[0, 1]^2` of `x` in it, so that `N = [(1-f_x)(1-f_y), f_x (1-f_y), f_x f_y, (1-f_x) f_y]` for the nodes
    /// of [`CellWeights`]; `None` outside the grid (or for NaN). The values-only path of the CPDI interpolators.
    #[inline]
    pub fn locate(&self, x: Vector2<f64>) -> Option<((usize, usize), Vector2<f64>)> {
        let s = (x - self.origin) / self.h;
        let owner = |s: f64, n: usize| -> Option<usize> {
            // `!(s >= 0)` also rejects NaN.
            if !(s >= 0.0 && s <= n as f64) {
                return None;
            }
            Some((s as usize).min(n - 1))
        };
        let (i, j) = (owner(s.x, self.nx)?, owner(s.y, self.ny)?);
        Some(((i, j), Vector2::new(s.x - i as f64, s.y - j as f64)))
    }

    /// Bilinear hat function `N_I(x)` [-] of node `I`; zero outside its support.
    pub fn hat(&self, node: usize, x: Vector2<f64>) -> f64 {
        let s = (x - self.node_position(node)) / self.h;
        (1.0 - s.x.abs()).max(0.0) * (1.0 - s.y.abs()).max(0.0)
    }

    /// `N_I(x)` and `grad N_I(x)` for the four nodes of the cell that owns `x`, or `None` if `x` is outside the
    /// grid. Along an edge shared by two cells, values agree and the gradient is the owning cell's.
    #[inline]
    pub fn cell_weights(&self, x: Vector2<f64>) -> Option<CellWeights> {
        let ((i, j), f) = self.locate(x)?;
        let (fx, fy) = (f.x, f.y);
        let (gx, gy) = (1.0 - fx, 1.0 - fy);
        let inv_h = 1.0 / self.h;
        let n0 = self.node_index(i, j) as u32;
        let n3 = self.node_index(i, j + 1) as u32;
        Some(CellWeights {
            nodes: [n0, n0 + 1, n3 + 1, n3],
            values: [gx * gy, fx * gy, fx * fy, gx * fy],
            grads: [
                Vector2::new(-gy, -gx) * inv_h,
                Vector2::new(gy, -fx) * inv_h,
                Vector2::new(fy, fx) * inv_h,
                Vector2::new(-fy, gx) * inv_h,
            ],
        })
    }

    /// Position `s = (x - x_0) / h` of `x` in cell units (lattice coordinates).
    pub fn lattice_coords(&self, x: Vector2<f64>) -> Vector2<f64> {
        (x - self.origin) / self.h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_grid() -> Grid {
        Grid::new(Vector2::new(-2.0, -1.0), 0.5, 8, 6).unwrap()
    }

    #[test]
    fn grid_indices_and_positions() {
        let g = unit_grid();
        assert_eq!(g.num_nodes(), 9 * 7);
        assert_eq!(g.num_cells(), 48);
        let n = g.node_index(3, 2);
        assert_eq!(n, 3 + 2 * 9);
        assert_eq!(g.node_ij(n), (3, 2));
        assert_eq!(g.node_position(n), Vector2::new(-0.5, 0.0));
        assert_eq!(g.cell_index(7, 5), 47);
        assert_eq!(g.upper(), Vector2::new(2.0, 2.0));
    }

    #[test]
    fn grid_covering_snaps_to_multiples_of_h_and_adds_margin() {
        let g = Grid::covering(Vector2::new(0.0, 0.0), Vector2::new(200.0, 200.0), 1.0, 3).unwrap();
        assert_eq!(g.origin(), Vector2::new(-3.0, -3.0));
        assert_eq!((g.nx(), g.ny()), (206, 206));
        // Notch faces on grid lines.
        for y in [95.0, 105.0] {
            let s = g.lattice_coords(Vector2::new(0.0, y)).y;
            assert_eq!(s, s.round());
        }
        let g = Grid::covering(Vector2::new(0.3, -1.2), Vector2::new(2.1, 0.4), 0.5, 1).unwrap();
        assert_eq!(g.origin(), Vector2::new(-0.5, -2.0));
        assert_eq!(g.upper(), Vector2::new(3.0, 1.0));
        // Round-off on a bound that is a multiple of h must not add a cell.
        let g = Grid::covering(
            Vector2::new(0.1 + 0.2 - 0.3, 0.0),
            Vector2::new(0.3, 0.3),
            0.1,
            0,
        )
        .unwrap();
        assert_eq!((g.nx(), g.ny()), (3, 3));
    }

    #[test]
    fn grid_rejects_bad_input() {
        let z = Vector2::zeros();
        assert!(matches!(
            Grid::covering(z, z, 0.0, 1),
            Err(GridError::InvalidCellSize { .. })
        ));
        assert!(matches!(
            Grid::covering(Vector2::new(1.0, 0.0), z, 1.0, 1),
            Err(GridError::InvalidBounds { .. })
        ));
        assert!(matches!(
            Grid::covering(Vector2::new(f64::NAN, 0.0), z, 1.0, 1),
            Err(GridError::InvalidBounds { .. })
        ));
        assert!(matches!(
            Grid::new(z, 1.0, 100_000, 100_000),
            Err(GridError::TooLarge { .. })
        ));
        assert!(matches!(
            Grid::new(z, 1.0, 0, 3),
            Err(GridError::NoCells { .. })
        ));
    }

    #[test]
    fn grid_cell_of_edges_and_outside() {
        let g = unit_grid();
        assert_eq!(g.cell_of(Vector2::new(-2.0, -1.0)), Some((0, 0)));
        assert_eq!(g.cell_of(Vector2::new(-1.5, -0.5)), Some((1, 1)));
        assert_eq!(g.cell_of(Vector2::new(2.0, 2.0)), Some((7, 5)));
        assert_eq!(g.cell_of(Vector2::new(2.0 + 1e-12, 0.0)), None);
        assert_eq!(g.cell_of(Vector2::new(0.0, -1.0 - 1e-12)), None);
        assert_eq!(g.cell_of(Vector2::new(f64::NAN, 0.0)), None);
    }

    #[test]
    fn grid_hat_functions_partition_unity_and_reproduce_linear_fields() {
        let g = unit_grid();
        for x in [
            Vector2::new(0.123, 0.777),
            Vector2::new(0.5, 0.25),
            Vector2::new(0.0, 0.0),
            Vector2::new(2.0, 2.0),
            Vector2::new(-2.0, 1.3),
        ] {
            let w = g.cell_weights(x).unwrap();
            let sum: f64 = w.values.iter().sum();
            let grad_sum: Vector2<f64> = w.grads.iter().sum();
            assert!((sum - 1.0).abs() < 1e-14);
            assert!(grad_sum.norm() < 1e-13);
            let mut xs = Vector2::zeros();
            let mut grad_x = nalgebra::Matrix2::zeros();
            for k in 0..4 {
                let xi = g.node_position(w.nodes[k] as usize);
                xs += w.values[k] * xi;
                grad_x += xi * w.grads[k].transpose();
                assert!((g.hat(w.nodes[k] as usize, x) - w.values[k]).abs() < 1e-15);
            }
            assert!((xs - x).norm() < 1e-13);
            assert!((grad_x - nalgebra::Matrix2::identity()).norm() < 1e-13);
        }
        assert!(g.cell_weights(Vector2::new(3.0, 0.0)).is_none());
    }
}
