//! The fixed Cartesian background grid of the MPM step (`docs/theory.md`), in `D = 2` or
//! `D = 3` space dimensions.
//!
//! A uniform grid with origin `x_0` (mm), square (cubic) cells of size `h` (mm), `n_1 x .. x n_D` cells and
//! `(n_1 + 1) .. (n_D + 1)` nodes. Node `(i, j[, k])` sits at `x_0 + (i, j[, k]) h` and has the global index
//! `I = i + (n_1 + 1) j` in 2D and `I = i + (n_1 + 1) (k + (n_3 + 1) j)` in 3D: x varies fastest and y
//! slowest in both ([`AXIS_ORDER`]), so that the bands of processes, cut across y ([`crate::partition`]),
//! own contiguous node ranges, also for a plate extruded along z. Cell `(i, j[, k])` spans
//! `x_0 + [i, i + 1] h x [j, j + 1] h [x ..]` and is numbered in the same axis order.
//!
//! The grid functions are the multilinear hat functions
//!
//! ```text
//! N_I(x) = prod_d n((x_d - x_{I,d}) / h),   n(s) = max(0, 1 - |s|)                 [-]
//! (grad N_I(x))_d = n'(s_d) prod_{e != d} n(s_e) / h                                [1/mm]
//! ```
//!
//! On a cell face the gradient is taken from the cell that owns the point: a point belongs to the cell
//! `floor((x - x_0) / h)`, except on the far boundary of the grid, which belongs to the last cell. Every
//! interpolator in [`crate::shape`] is built on [`Grid::cell_weights`]. `Grid` alone is the 2D grid
//! (`Grid<2>`); `Grid<3>` is the 3D one.

use nalgebra::SVector;
use thiserror::Error;

/// Which point of a material point's domain left the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Locus {
    /// The material point position `x_p` (or the support of its GIMP/B-spline function).
    Centre,
    /// Corner `c` (0..2^D, in lattice order from `x_p - r1 - r2 [- r3]`) of the CPDI domain.
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

/// `(x, y)` or `(x, y, z)` with six decimals, for error messages.
fn coords(x: f64, y: f64, z: Option<f64>) -> String {
    match z {
        Some(z) => format!("({x:.6}, {y:.6}, {z:.6})"),
        None => format!("({x:.6}, {y:.6})"),
    }
}

/// `n1 x n2 [x n3]`, for error messages.
fn extent(cells: &[usize; 3], dim: u8) -> String {
    let parts: Vec<String> = cells[..dim as usize].iter().map(usize::to_string).collect();
    parts.join(" x ")
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
    #[error(
        "grid bounds must be finite with min <= max, got min = {:?} mm, max = {:?} mm",
        &min[..*dim as usize], &max[..*dim as usize]
    )]
    InvalidBounds {
        /// Lower corner (mm; unused trailing entries 0).
        min: [f64; 3],
        /// Upper corner (mm; unused trailing entries 0).
        max: [f64; 3],
        /// Space dimension.
        dim: u8,
    },
    /// A grid needs at least one cell in each direction.
    #[error("a grid needs at least one cell per direction, got {}", extent(cells, *dim))]
    NoCells {
        /// Cells per direction (unused trailing entries 1).
        cells: [usize; 3],
        /// Space dimension.
        dim: u8,
    },
    /// The node count does not fit the `u32` node indices of the weight table.
    #[error("a grid of {} cells has too many nodes for 32-bit node indices", extent(cells, *dim))]
    TooLarge {
        /// Cells per direction (unused trailing entries 1).
        cells: [usize; 3],
        /// Space dimension.
        dim: u8,
    },
    /// A material point or one of its CPDI corners lies outside the grid, or so close to its border that the
    /// support of its shape function would leave the grid. Recoverable: report it to SNES as a domain error.
    #[error(
        "material point {particle}: {locus} at {} mm is outside the grid \
         (or its shape-function support leaves it); enlarge the grid margin",
        coords(*x, *y, *z)
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
        /// z coordinate (mm), in 3D.
        z: Option<f64>,
    },
}

impl GridError {
    /// The error for point `particle` whose `locus` at `x` left the grid.
    pub fn outside<const D: usize>(particle: usize, locus: Locus, x: &SVector<f64, D>) -> Self {
        GridError::OutsideGrid {
            particle,
            locus,
            x: x[0],
            y: x[1],
            z: (D > 2).then(|| x[D - 1]),
        }
    }
}

/// Pads a `D`-vector to three entries with `fill`.
fn pad3<T: Copy>(v: impl IntoIterator<Item = T>, fill: T) -> [T; 3] {
    let mut out = [fill; 3];
    for (o, x) in out.iter_mut().zip(v) {
        *o = x;
    }
    out
}

/// Most nodes of one cell (`2^D` for `D <= 3`).
pub const MAX_CELL_NODES: usize = 8;

/// Values and gradients of the `2^D` multilinear hat functions of the cell that owns a point; entries
/// `0..Grid::<D>::CELL_NODES` are used.
///
/// Node `c` of the cell is `(i + c_0, j + c_1[, k + c_2])` with `c_d` bit `d` of `c` (lattice order), except
/// in 2D, where the four nodes run counter-clockwise: `(i, j)`, `(i + 1, j)`, `(i + 1, j + 1)`, `(i, j + 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellWeights<const D: usize = 2> {
    /// Global node indices `I`.
    pub nodes: [u32; MAX_CELL_NODES],
    /// `N_I(x)` [-].
    pub values: [f64; MAX_CELL_NODES],
    /// `grad N_I(x)` [1/mm].
    pub grads: [SVector<f64, D>; MAX_CELL_NODES],
}

/// Uniform Cartesian background grid (lengths in mm) in `D` dimensions; `Grid` is the 2D grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<const D: usize = 2> {
    origin: SVector<f64, D>,
    h: f64,
    cells: [usize; D],
}

/// The axes from the one whose node index varies fastest to the slowest, for `D` = 2 and 3 (the first `D`
/// entries of row `D - 2`): x, y in 2D; x, z, y in 3D.
pub const AXIS_ORDER: [[usize; 3]; 2] = [[0, 1, 2], [0, 2, 1]];

/// The axis whose node index varies slowest (y): the axis across which processes cut their bands.
pub const SLOWEST_AXIS: usize = 1;

/// Axis `k` of [`AXIS_ORDER`] for dimension `D` (0: the fastest).
#[inline]
pub const fn axis<const D: usize>(k: usize) -> usize {
    AXIS_ORDER[D - 2][k]
}

/// Lattice offset `(c_0, .., c_{D-1})` in `{0, 1}^D` of node `c` of a cell ([`CellWeights`] order).
#[inline]
pub fn cell_node_offset<const D: usize>(c: usize) -> [usize; D] {
    // 2D keeps the counter-clockwise order of the quadrilateral: 0, 1, 3, 2 in lattice order.
    let lattice = if D == 2 { [0, 1, 3, 2][c] } else { c };
    std::array::from_fn(|d| (lattice >> d) & 1)
}

impl<const D: usize> Grid<D> {
    /// Nodes of one cell, `2^D`.
    pub const CELL_NODES: usize = 1 << D;

    /// A grid with lowest node `origin` (mm), cell size `h` (mm) and `cells[d]` cells in direction `d`.
    pub fn new(origin: SVector<f64, D>, h: f64, cells: [usize; D]) -> Result<Self, GridError> {
        assert!(D == 2 || D == 3, "grids are 2D or 3D");
        if !(h.is_finite() && h > 0.0) {
            return Err(GridError::InvalidCellSize { h });
        }
        if !origin.iter().all(|c| c.is_finite()) {
            let o = pad3(origin.iter().copied(), 0.0);
            return Err(GridError::InvalidBounds {
                min: o,
                max: o,
                dim: D as u8,
            });
        }
        if cells.contains(&0) {
            return Err(GridError::NoCells {
                cells: pad3(cells, 1),
                dim: D as u8,
            });
        }
        if cells.iter().map(|&n| n as u128 + 1).product::<u128>() > u32::MAX as u128 {
            return Err(GridError::TooLarge {
                cells: pad3(cells, 1),
                dim: D as u8,
            });
        }
        Ok(Self { origin, h, cells })
    }

    /// The smallest grid of cell size `h` whose nodes lie on multiples of `h` (so that geometry on the
    /// lines `k h`, e.g. notch faces at y = 95 and 105 mm with h = 1 mm, stays on grid lines) and that covers
    /// the box `[min, max]` (mm) plus `margin_cells` empty cells on every side, so that shape-function supports
    /// (CPDI corners, GIMP and B-spline supports) do not leave the grid while the body deforms.
    pub fn covering(
        min: SVector<f64, D>,
        max: SVector<f64, D>,
        h: f64,
        margin_cells: usize,
    ) -> Result<Self, GridError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(GridError::InvalidCellSize { h });
        }
        let bounds_ok =
            (0..D).all(|k| min[k].is_finite() && max[k].is_finite() && min[k] <= max[k]);
        if !bounds_ok {
            return Err(GridError::InvalidBounds {
                min: pad3(min.iter().copied(), 0.0),
                max: pad3(max.iter().copied(), 0.0),
                dim: D as u8,
            });
        }
        // Snap with a relative tolerance so that bounds that are multiples of h up to round-off snap onto
        // their own grid line rather than one cell further out.
        let snap_tol = 1e-9;
        let margin = margin_cells as f64;
        let lo = min.map(|c| (c / h + snap_tol).floor() - margin);
        let hi = max.map(|c| (c / h - snap_tol).ceil() + margin);
        let cells = std::array::from_fn(|k| ((hi[k] - lo[k]).max(1.0)) as usize);
        Self::new(lo * h, h, cells)
    }

    /// Lowest node position `x_0` (mm).
    pub fn origin(&self) -> SVector<f64, D> {
        self.origin
    }

    /// Cell size `h` (mm).
    pub fn cell_size(&self) -> f64 {
        self.h
    }

    /// Cells per direction.
    pub fn cells(&self) -> [usize; D] {
        self.cells
    }

    /// Number of cells in x.
    pub fn nx(&self) -> usize {
        self.cells[0]
    }

    /// Number of cells in y.
    pub fn ny(&self) -> usize {
        self.cells[1]
    }

    /// Number of nodes `prod_d (n_d + 1)`.
    pub fn num_nodes(&self) -> usize {
        self.cells.iter().map(|n| n + 1).product()
    }

    /// Number of cells `prod_d n_d`.
    pub fn num_cells(&self) -> usize {
        self.cells.iter().product()
    }

    /// Highest node position (mm).
    pub fn upper(&self) -> SVector<f64, D> {
        self.origin + SVector::<f64, D>::from_fn(|d, _| self.cells[d] as f64) * self.h
    }

    /// Global index of the node at lattice position `ijk` (the module's numbering: x fastest, y slowest).
    #[inline]
    pub fn node_at(&self, ijk: [usize; D]) -> usize {
        (0..D).rev().fold(0, |acc, k| {
            let d = axis::<D>(k);
            acc * (self.cells[d] + 1) + ijk[d]
        })
    }

    /// Global index of the cell at lattice position `ijk` (numbered as the nodes).
    pub fn cell_at(&self, ijk: [usize; D]) -> usize {
        (0..D).rev().fold(0, |acc, k| {
            let d = axis::<D>(k);
            acc * self.cells[d] + ijk[d]
        })
    }

    /// Lattice position of node `I`; the copy `I + f N` of node `I` in velocity field `f`
    /// ([`ShapeTable::offset_fields`](crate::shape::ShapeTable::offset_fields)) maps to node `I`.
    pub fn node_lattice(&self, node: usize) -> [usize; D] {
        let mut rest = node % self.num_nodes();
        let mut ijk = [0; D];
        for k in 0..D {
            let d = axis::<D>(k);
            ijk[d] = rest % (self.cells[d] + 1);
            rest /= self.cells[d] + 1;
        }
        ijk
    }

    /// Position `x_I` of node `I` (mm), also of its copies in other velocity fields.
    pub fn node_position(&self, node: usize) -> SVector<f64, D> {
        let ijk = self.node_lattice(node);
        self.origin + SVector::<f64, D>::from_fn(|d, _| ijk[d] as f64) * self.h
    }

    /// Cell that owns `x`, or `None` outside the closed grid `[x_0, x_0 + n h]`. Points on an interior cell
    /// face belong to the cell above it; points on the far grid boundary belong to the last cell.
    #[inline]
    pub fn cell_of(&self, x: SVector<f64, D>) -> Option<[usize; D]> {
        self.locate(x).map(|(cell, _)| cell)
    }

    /// The cell that owns `x` (as [`Grid::cell_of`]) and the local coordinates `f` in `[0, 1]^D` of `x` in
    /// it; `None` outside the grid (or for NaN). The values-only path of the CPDI interpolators.
    #[inline]
    pub fn locate(&self, x: SVector<f64, D>) -> Option<([usize; D], SVector<f64, D>)> {
        let s = (x - self.origin) / self.h;
        let mut cell = [0; D];
        for d in 0..D {
            let n = self.cells[d];
            // `!(s >= 0)` also rejects NaN.
            if !(s[d] >= 0.0 && s[d] <= n as f64) {
                return None;
            }
            cell[d] = (s[d] as usize).min(n - 1);
        }
        Some((cell, SVector::from_fn(|d, _| s[d] - cell[d] as f64)))
    }

    /// Multilinear hat function `N_I(x)` [-] of node `I`; zero outside its support.
    pub fn hat(&self, node: usize, x: SVector<f64, D>) -> f64 {
        let s = (x - self.node_position(node)) / self.h;
        s.iter().map(|s| (1.0 - s.abs()).max(0.0)).product()
    }

    /// The values `N_c` [-] of the `2^D` hat functions of a cell at local coordinates `f` ([`Grid::locate`]),
    /// in [`CellWeights`] node order.
    #[inline]
    pub fn cell_values(f: &SVector<f64, D>) -> [f64; MAX_CELL_NODES] {
        let mut out = [0.0; MAX_CELL_NODES];
        for (c, o) in out.iter_mut().enumerate().take(Self::CELL_NODES) {
            let off = cell_node_offset::<D>(c);
            *o = (0..D)
                .map(|d| if off[d] == 1 { f[d] } else { 1.0 - f[d] })
                .product();
        }
        out
    }

    /// Global indices of the `2^D` nodes of `cell`, in [`CellWeights`] node order.
    #[inline]
    pub fn cell_nodes(&self, cell: [usize; D]) -> [u32; MAX_CELL_NODES] {
        let mut out = [0; MAX_CELL_NODES];
        for (c, o) in out.iter_mut().enumerate().take(Self::CELL_NODES) {
            let off = cell_node_offset::<D>(c);
            *o = self.node_at(std::array::from_fn(|d| cell[d] + off[d])) as u32;
        }
        out
    }

    /// `N_I(x)` and `grad N_I(x)` for the `2^D` nodes of the cell that owns `x`, or `None` if `x` is outside
    /// the grid. Along a face shared by two cells, values agree and the gradient is the owning cell's.
    #[inline]
    pub fn cell_weights(&self, x: SVector<f64, D>) -> Option<CellWeights<D>> {
        let (cell, f) = self.locate(x)?;
        let inv_h = 1.0 / self.h;
        let mut grads = [SVector::<f64, D>::zeros(); MAX_CELL_NODES];
        for (c, g) in grads.iter_mut().enumerate().take(Self::CELL_NODES) {
            let off = cell_node_offset::<D>(c);
            let factor = |d: usize| if off[d] == 1 { f[d] } else { 1.0 - f[d] };
            let slope = |d: usize| if off[d] == 1 { inv_h } else { -inv_h };
            *g = SVector::from_fn(|d, _| {
                (0..D)
                    .map(|e| if e == d { slope(e) } else { factor(e) })
                    .product()
            });
        }
        Some(CellWeights {
            nodes: self.cell_nodes(cell),
            values: Self::cell_values(&f),
            grads,
        })
    }

    /// Position `s = (x - x_0) / h` of `x` in cell units (lattice coordinates).
    pub fn lattice_coords(&self, x: SVector<f64, D>) -> SVector<f64, D> {
        (x - self.origin) / self.h
    }
}

impl Grid<2> {
    /// Global node index `I = i + j (nx + 1)`.
    pub fn node_index(&self, i: usize, j: usize) -> usize {
        self.node_at([i, j])
    }

    /// Global cell index `i + j nx`.
    pub fn cell_index(&self, i: usize, j: usize) -> usize {
        self.cell_at([i, j])
    }

    /// Lattice indices `(i, j)` of node `I` (see [`Grid::node_lattice`]).
    pub fn node_ij(&self, node: usize) -> (usize, usize) {
        let [i, j] = self.node_lattice(node);
        (i, j)
    }
}

impl Grid<3> {
    /// Number of cells in z.
    pub fn nz(&self) -> usize {
        self.cells[2]
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector2, Vector3};

    fn unit_grid() -> Grid {
        Grid::new(Vector2::new(-2.0, -1.0), 0.5, [8, 6]).unwrap()
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
        assert_eq!(g.cells(), [206, 206]);
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
        assert_eq!(g.cells(), [3, 3]);
    }

    #[test]
    fn grid_rejects_bad_input() {
        let z = Vector2::<f64>::zeros();
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
            Grid::new(z, 1.0, [100_000, 100_000]),
            Err(GridError::TooLarge { .. })
        ));
        assert!(matches!(
            Grid::new(z, 1.0, [0, 3]),
            Err(GridError::NoCells { .. })
        ));
    }

    #[test]
    fn grid_cell_of_edges_and_outside() {
        let g = unit_grid();
        assert_eq!(g.cell_of(Vector2::new(-2.0, -1.0)), Some([0, 0]));
        assert_eq!(g.cell_of(Vector2::new(-1.5, -0.5)), Some([1, 1]));
        assert_eq!(g.cell_of(Vector2::new(2.0, 2.0)), Some([7, 5]));
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
            let sum: f64 = w.values[..4].iter().sum();
            let grad_sum: Vector2<f64> = w.grads[..4].iter().sum();
            assert!((sum - 1.0).abs() < 1e-14);
            assert!(grad_sum.norm() < 1e-13);
            let mut xs = Vector2::zeros();
            let mut grad_x = nalgebra::Matrix2::zeros();
            for k in 0..Grid::<2>::CELL_NODES {
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

    #[test]
    fn grid_3d_numbering_and_trilinear_hats() {
        let g = Grid::<3>::new(Vector3::new(-1.0, 0.0, 2.0), 0.5, [4, 3, 2]).unwrap();
        assert_eq!((g.num_nodes(), g.num_cells()), (5 * 4 * 3, 24));
        assert_eq!(g.nz(), 2);
        // x fastest, then z, y slowest: a y row of nodes is a contiguous range.
        let n = g.node_at([2, 1, 2]);
        assert_eq!(n, 2 + 5 * (2 + 3)); // i + (nx + 1) (k + (nz + 1) j), j = 1
        assert_eq!(g.node_lattice(n), [2, 1, 2]);
        assert_eq!(g.node_position(n), Vector3::new(0.0, 0.5, 3.0));
        assert_eq!(g.cell_at([3, 2, 1]), 3 + 4 * (1 + 2 * 2));
        let row: Vec<usize> = (0..3)
            .flat_map(|k| (0..5).map(move |i| [i, 1, k]))
            .map(|ijk| g.node_at(ijk))
            .collect();
        assert_eq!(row, (15..30).collect::<Vec<_>>());
        for node in 0..g.num_nodes() {
            assert_eq!(g.node_at(g.node_lattice(node)), node);
        }
        assert_eq!(g.upper(), Vector3::new(1.0, 1.5, 3.0));
        assert_eq!(g.cell_of(Vector3::new(1.0, 1.5, 3.0)), Some([3, 2, 1]));
        assert_eq!(g.cell_of(Vector3::new(0.0, 0.0, 1.99)), None);
        for x in [
            Vector3::new(0.123, 0.777, 2.31),
            Vector3::new(-1.0, 0.0, 2.0),
            Vector3::new(0.5, 1.0, 2.5),
            Vector3::new(0.99, 1.49, 2.99),
        ] {
            let w = g.cell_weights(x).unwrap();
            let (mut sum, mut xs) = (0.0, Vector3::zeros());
            let (mut grad_sum, mut grad_x) = (Vector3::zeros(), nalgebra::Matrix3::zeros());
            for k in 0..Grid::<3>::CELL_NODES {
                let xi = g.node_position(w.nodes[k] as usize);
                sum += w.values[k];
                xs += w.values[k] * xi;
                grad_sum += w.grads[k];
                grad_x += xi * w.grads[k].transpose();
                assert!((g.hat(w.nodes[k] as usize, x) - w.values[k]).abs() < 1e-15);
            }
            assert!((sum - 1.0).abs() < 1e-14 && grad_sum.norm() < 1e-12);
            assert!((xs - x).norm() < 1e-13);
            assert!((grad_x - nalgebra::Matrix3::identity()).norm() < 1e-12);
        }
        let e = Grid::<3>::new(Vector3::zeros(), 1.0, [2, 0, 2]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a grid needs at least one cell per direction, got 2 x 0 x 2"
        );
        let e = GridError::outside(4, Locus::Corner(7), &Vector3::new(1.0, 2.0, 3.0));
        assert!(
            e.to_string()
                .contains("CPDI corner 8 at (1.000000, 2.000000, 3.000000) mm"),
            "{e}"
        );
    }
}
