//! Geometric multigrid on the background grid: the hierarchy of nested grids and the interpolation
//! between neighbouring levels, built from the grid and the step's unknowns alone.
//!
//! The background grid is the same Cartesian grid at every step, which a general finite-element code does
//! not have. Coarsening it by 2 in every direction gives nested grids (cell size `2^l h` on level `l`,
//! level 0 the background grid itself) whose nodes are every second node of the finer grid. A fine node's
//! value is interpolated from the nodes of the coarse cell it lies in with the coarse grid's multilinear hat
//! functions: the weight is a product over the axes of 1 (even lattice index: a coincident coarse line) or
//! 1/2 and 1/2 (odd: halfway between two coarse lines). Each unknown of a node (the components of `du` and
//! `eta_bar`, [`FieldLayout`](crate::dofs::FieldLayout)) takes the same unknown of the coarse nodes, so the
//! interpolation `P` is block-diagonal per node pair and the coarse levels keep the block size; the
//! velocity-field copies of nodes (contact between bodies) interpolate within their own field.
//!
//! Only active nodes carry unknowns on level 0 ([`DofMap`]); a coarse node is active if an active finer
//! node interpolates from it. Constrained unknowns of level 0 (scaled identity rows `s (x - x_D)`) take no
//! coarse correction: their rows of `P` are empty, except for a coarse unknown that no free unknown
//! reaches (a coarse node under a clamped edge), which is interpolated into the constrained rows as usual,
//! so that the Galerkin coarse operator `A_l+1 = P^T A_l P` (formed by PETSc: PCMG, MatPtAP) has no empty
//! row. Processes own contiguous ranges of every level's nodes ([`Hierarchy::owned_starts`]).

use crate::dofs::DofMap;
use crate::grid::Grid;

/// One level of the hierarchy: its grid and its active nodes.
#[derive(Debug, Clone)]
pub struct Level<const D: usize> {
    /// The level's grid (cell size `2^l h`, the origin of the background grid).
    pub grid: Grid<D>,
    /// Active nodes, sorted: node `I` of velocity field `f` is `f N + I` with `N` the grid's node count.
    pub active: Vec<u32>,
}

/// The interpolation `P` from a coarse level to the next finer one, as CSR over the finer level's
/// unknowns (rows) and the coarse level's (columns), both in node order with the unknowns of a node
/// interleaved.
#[derive(Debug, Clone, Default)]
pub struct Interpolation {
    /// Row pointers (one row per finer unknown, plus one).
    pub row_ptr: Vec<usize>,
    /// Coarse unknown of each entry, sorted within a row.
    pub cols: Vec<u32>,
    /// Weight of each entry (-).
    pub weights: Vec<f64>,
}

impl Interpolation {
    /// The entries `(coarse unknown, weight)` of finer unknown `row`.
    pub fn row(&self, row: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.row_ptr[row]..self.row_ptr[row + 1];
        self.cols[r.clone()]
            .iter()
            .zip(&self.weights[r])
            .map(|(&c, &w)| (c as usize, w))
    }

    /// Number of finer unknowns (rows).
    pub fn rows(&self) -> usize {
        self.row_ptr.len() - 1
    }
}

/// The levels of a multigrid hierarchy from the background grid (level 0) to the coarsest, with the
/// interpolation into each level from the next coarser one.
#[derive(Debug, Clone)]
pub struct Hierarchy<const D: usize> {
    /// Unknowns per node (on every level).
    pub unknowns_per_node: usize,
    /// Level 0 (the step's active nodes) to the coarsest.
    pub levels: Vec<Level<D>>,
    /// `interpolations[l]`: from level `l + 1` to level `l`.
    pub interpolations: Vec<Interpolation>,
}

/// A level is not coarsened further once it has at most this many unknowns (a direct solve of that size
/// costs less than a smoothing sweep of the finest level).
pub const COARSEST_UNKNOWNS: usize = 2000;

impl<const D: usize> Hierarchy<D> {
    /// The hierarchy over `grid` for the unknowns of `dofs`, with at most `max_levels` levels (level 0
    /// included); with `None` the grid is coarsened at least once and then until a level has at most
    /// [`COARSEST_UNKNOWNS`] unknowns (a single level would leave PETSc's multigrid with its smoother
    /// alone). Coarsening also stops where a direction has a single cell left.
    pub fn build(grid: &Grid<D>, dofs: &DofMap, max_levels: Option<usize>) -> Self {
        let nf = dofs.unknowns_per_node();
        let mut levels = vec![Level {
            grid: grid.clone(),
            active: dofs.active_nodes().to_vec(),
        }];
        let mut interpolations = Vec::new();
        loop {
            let fine = levels.last().expect("level 0");
            let enough = match max_levels {
                Some(n) => levels.len() >= n,
                None => levels.len() > 1 && fine.active.len() * nf <= COARSEST_UNKNOWNS,
            };
            if enough || fine.grid.cells().iter().any(|&n| n < 2) {
                break;
            }
            let first = levels.len() == 1;
            let (coarse, p) = coarsen(fine, nf, |dof| !first || !dofs.is_constrained(dof));
            levels.push(coarse);
            interpolations.push(p);
        }
        Self {
            unknowns_per_node: nf,
            levels,
            interpolations,
        }
    }

    /// The first node of each process on every level, from level 0's (`starts`: the first active node of
    /// each process, in process order, and the count of active nodes last). A coarse node belongs to the
    /// process whose level-0 range holds the finer node at the same place (the nearest one inside the
    /// finer grid): the nodes are numbered with the slowest axis last on every level, so the ranges stay
    /// contiguous and follow the processes' bands of the background grid.
    pub fn owned_starts(&self, starts: &[usize]) -> Vec<Vec<usize>> {
        let mut all = vec![starts.to_vec()];
        for pair in self.levels.windows(2) {
            let (fine, coarse) = (&pair[0], &pair[1]);
            let fine_starts = all.last().expect("level 0");
            let first_key = |p: usize| fine.active.get(fine_starts[p]).copied();
            let nprocs = fine_starts.len() - 1;
            let owner = |key: u32| {
                let at = injected(fine, coarse, key);
                (1..nprocs)
                    .take_while(|&p| first_key(p).is_some_and(|k| k <= at))
                    .last()
                    .unwrap_or(0)
            };
            let mut cs: Vec<usize> = (0..nprocs)
                .map(|p| coarse.active.partition_point(|&k| owner(k) < p))
                .collect();
            cs.push(coarse.active.len());
            all.push(cs);
        }
        all
    }
}

/// The key of the finer node at the place of coarse node `key` (the nearest one inside the finer grid).
fn injected<const D: usize>(fine: &Level<D>, coarse: &Level<D>, key: u32) -> u32 {
    let (nc, nfine) = (coarse.grid.num_nodes(), fine.grid.num_nodes());
    let (field, node) = (key as usize / nc, key as usize % nc);
    let ijk = coarse.grid.node_lattice(node);
    let cells = fine.grid.cells();
    let at: [usize; D] = std::array::from_fn(|d| (2 * ijk[d]).min(cells[d]));
    (field * nfine + fine.grid.node_at(at)) as u32
}

/// The coarse nodes (lattice index, weight) along one axis of a finer node at lattice index `i`.
fn parents_1d(i: usize) -> [(usize, f64); 2] {
    if i % 2 == 0 {
        [(i / 2, 1.0), (i / 2, 0.0)]
    } else {
        [(i / 2, 0.5), (i / 2 + 1, 0.5)]
    }
}

/// The next coarser level of `fine` and the interpolation from it; `free(unknown)` tells which finer
/// unknowns take a coarse correction (see the module's documentation).
fn coarsen<const D: usize>(
    fine: &Level<D>,
    nf: usize,
    free: impl Fn(usize) -> bool,
) -> (Level<D>, Interpolation) {
    let g = &fine.grid;
    let cells = g.cells().map(|n| n.div_ceil(2));
    let grid = Grid::new(g.origin(), 2.0 * g.cell_size(), cells).expect("a coarser grid is valid");
    let (nfine, ncoarse) = (g.num_nodes(), grid.num_nodes());
    // Each finer node's coarse parents (key, weight), 2^D per node (zero weights dropped later).
    let corners = 1 << D;
    let mut parents = Vec::with_capacity(fine.active.len() * corners);
    for &key in &fine.active {
        let (field, node) = (key as usize / nfine, key as usize % nfine);
        let axes = g.node_lattice(node).map(parents_1d);
        for c in 0..corners {
            let mut ijk = [0; D];
            let mut w = 1.0;
            for d in 0..D {
                let (i, wd) = axes[d][(c >> d) & 1];
                ijk[d] = i;
                w *= wd;
            }
            parents.push(((field * ncoarse + grid.node_at(ijk)) as u32, w));
        }
    }
    let mut active: Vec<u32> = parents
        .iter()
        .filter(|(_, w)| *w > 0.0)
        .map(|&(k, _)| k)
        .collect();
    active.sort_unstable();
    active.dedup();
    let index = |key: u32| active.binary_search(&key).expect("a parent is active");
    // Coarse unknowns that some free finer unknown reaches.
    let mut reached = vec![false; active.len() * nf];
    for (a, ps) in parents.chunks_exact(corners).enumerate() {
        for c in (0..nf).filter(|&c| free(a * nf + c)) {
            for &(k, _) in ps.iter().filter(|(_, w)| *w > 0.0) {
                reached[index(k) * nf + c] = true;
            }
        }
    }
    let mut p = Interpolation {
        row_ptr: vec![0],
        ..Interpolation::default()
    };
    let mut row: Vec<(u32, f64)> = Vec::with_capacity(corners);
    for (a, ps) in parents.chunks_exact(corners).enumerate() {
        for c in 0..nf {
            let own = free(a * nf + c);
            row.clear();
            for &(k, w) in ps.iter().filter(|(_, w)| *w > 0.0) {
                let col = index(k) * nf + c;
                if own || !reached[col] {
                    row.push((col as u32, w));
                }
            }
            row.sort_unstable_by_key(|&(col, _)| col);
            p.cols.extend(row.iter().map(|&(col, _)| col));
            p.weights.extend(row.iter().map(|&(_, w)| w));
            p.row_ptr.push(p.cols.len());
        }
    }
    (Level { grid, active }, p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dofs::FieldLayout;
    use nalgebra::SVector;

    /// All nodes of a `cells` grid active except those with x index below `hole` (2D) / in a corner.
    fn dofs_on<const D: usize>(
        grid: &Grid<D>,
        skip: impl Fn([usize; D]) -> bool,
        nf: usize,
    ) -> DofMap {
        let active: Vec<bool> = (0..grid.num_nodes())
            .map(|n| !skip(grid.node_lattice(n)))
            .collect();
        let mut d = DofMap::default();
        d.rebuild(&active, FieldLayout::new(D, nf > D));
        d
    }

    /// Interpolates the nodal values `f(x)` of the coarse level into the finer one.
    fn prolong<const D: usize>(
        h: &Hierarchy<D>,
        l: usize,
        f: impl Fn(SVector<f64, D>, usize) -> f64,
    ) -> Vec<f64> {
        let nf = h.unknowns_per_node;
        let coarse = &h.levels[l + 1];
        let n = coarse.grid.num_nodes();
        let vc: Vec<f64> = (0..coarse.active.len() * nf)
            .map(|i| {
                let key = coarse.active[i / nf] as usize;
                f(coarse.grid.node_position(key % n), i % nf)
            })
            .collect();
        let p = &h.interpolations[l];
        (0..p.rows())
            .map(|r| p.row(r).map(|(c, w)| w * vc[c]).sum())
            .collect()
    }

    #[test]
    fn the_interpolation_reproduces_linear_fields_and_sums_to_one() {
        // 2D, 3 unknowns per node (du, eta_bar), odd cell counts, a hole of inactive nodes.
        let grid = Grid::new(SVector::from([-1.0, 2.0]), 0.5, [13, 9]).unwrap();
        let dofs = dofs_on(&grid, |[i, j]| i > 4 && i < 8 && j > 3 && j < 6, 3);
        let h = Hierarchy::build(&grid, &dofs, Some(3));
        assert_eq!(h.levels.len(), 3);
        assert_eq!(h.levels[1].grid.cells(), [7, 5]);
        assert_eq!(h.levels[2].grid.cells(), [4, 3]);
        assert_eq!(h.levels[1].grid.cell_size(), 1.0);
        for l in 0..2 {
            let p = &h.interpolations[l];
            assert_eq!(p.rows(), h.levels[l].active.len() * 3);
            for r in 0..p.rows() {
                let sum: f64 = p.row(r).map(|(_, w)| w).sum();
                assert!((sum - 1.0).abs() < 1e-14, "row {r} of level {l}: {sum}");
            }
            let f = |x: SVector<f64, 2>, c: usize| 0.3 + 1.7 * x[0] - 0.9 * x[1] + c as f64;
            let fine = &h.levels[l];
            let n = fine.grid.num_nodes();
            for (i, v) in prolong(&h, l, f).iter().enumerate() {
                let key = fine.active[i / 3] as usize;
                let exact = f(fine.grid.node_position(key % n), i % 3);
                assert!(
                    (v - exact).abs() < 1e-12,
                    "level {l} unknown {i}: {v} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn three_dimensions_and_velocity_fields_interpolate_within_their_field() {
        let grid = Grid::new(SVector::from([0.0, 0.0, 0.0]), 1.0, [4, 5, 3]).unwrap();
        let n = grid.num_nodes();
        // Two velocity fields: field 1 holds copies of the nodes with x index 2.
        let active: Vec<bool> = (0..2 * n)
            .map(|k| k < n || grid.node_lattice(k % n)[0] == 2)
            .collect();
        let mut dofs = DofMap::default();
        dofs.rebuild(&active, FieldLayout::new(3, false));
        let h = Hierarchy::build(&grid, &dofs, Some(2));
        let coarse = &h.levels[1];
        let nc = coarse.grid.num_nodes();
        // Field 1 reaches only the coarse nodes with x index 1.
        let field1: Vec<u32> = coarse
            .active
            .iter()
            .copied()
            .filter(|&k| k as usize >= nc)
            .collect();
        assert!(!field1.is_empty());
        assert!(
            field1
                .iter()
                .all(|&k| coarse.grid.node_lattice(k as usize % nc)[0] == 1)
        );
        let f = |x: SVector<f64, 3>, c: usize| 2.0 * x[0] - x[1] + 0.5 * x[2] + c as f64;
        for (i, v) in prolong(&h, 0, f).iter().enumerate() {
            let key = h.levels[0].active[i / 3] as usize;
            let exact = f(grid.node_position(key % n), i % 3);
            assert!((v - exact).abs() < 1e-12);
        }
    }

    #[test]
    fn constrained_rows_take_only_what_no_free_unknown_reaches() {
        // A clamped left edge (x index 0 and 1, both components) and a roller (y fixed) along j = 0.
        let grid = Grid::new(SVector::from([0.0, 0.0]), 1.0, [8, 4]).unwrap();
        let mut dofs = dofs_on(&grid, |_| false, 2);
        for node in 0..grid.num_nodes() {
            let [i, j] = grid.node_lattice(node);
            if i <= 1 {
                dofs.constrain(node, 0, 0.0);
                dofs.constrain(node, 1, 0.0);
            }
            if j == 0 {
                dofs.constrain(node, 1, 0.0);
            }
        }
        let h = Hierarchy::build(&grid, &dofs, Some(2));
        let p = &h.interpolations[0];
        let coarse = &h.levels[1];
        let mut column_used = vec![false; coarse.active.len() * 2];
        for r in 0..p.rows() {
            let node = h.levels[0].active[r / 2] as usize;
            let [i, _] = grid.node_lattice(node);
            let entries: Vec<_> = p.row(r).collect();
            for &(c, _) in &entries {
                column_used[c] = true;
            }
            if dofs.is_constrained(r) {
                // Node (1, j) halves the coarse edge between coarse x index 0 (clamped only) and 1 (free
                // through node (2, j)): only the clamped coarse node's unknown is interpolated into it.
                if i == 1 && !entries.is_empty() {
                    assert!(entries.iter().all(|&(c, _)| {
                        let key = coarse.active[c / 2] as usize;
                        coarse.grid.node_lattice(key)[0] == 0
                    }));
                }
            } else {
                let sum: f64 = entries.iter().map(|&(_, w)| w).sum();
                assert!((sum - 1.0).abs() < 1e-14);
            }
        }
        assert!(
            column_used.iter().all(|&u| u),
            "every coarse unknown has a row"
        );
    }

    #[test]
    fn processes_own_contiguous_ranges_on_every_level() {
        let grid = Grid::new(SVector::from([0.0, 0.0]), 1.0, [10, 12]).unwrap();
        let dofs = dofs_on(&grid, |[i, j]| i + j < 3, 2);
        let h = Hierarchy::build(&grid, &dofs, Some(3));
        assert_eq!(h.levels.len(), 3);
        // Without a count: coarsened once although level 0 (280 unknowns) is small already.
        assert_eq!(Hierarchy::build(&grid, &dofs, None).levels.len(), 2);
        let n = dofs.num_active();
        let starts = h.owned_starts(&[0, n / 3, n / 3, 2 * n / 3, n]);
        assert_eq!(starts.len(), h.levels.len());
        for (s, level) in starts.iter().zip(&h.levels) {
            assert_eq!(s.len(), 5);
            assert_eq!(*s.last().unwrap(), level.active.len());
            assert!(s.windows(2).all(|w| w[0] <= w[1]), "{s:?}");
        }
        // The empty second process stays empty; the others get part of the first coarse level.
        let l1 = &starts[1];
        assert_eq!(l1[1], l1[2]);
        assert!(l1[1] > 0 && l1[3] > l1[2] && l1[4] > l1[3], "{l1:?}");
        // Serial: one range of everything.
        assert_eq!(
            h.owned_starts(&[0, n])[1],
            vec![0, h.levels[1].active.len()]
        );
    }
}
