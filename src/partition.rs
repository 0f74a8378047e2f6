//! Material points owned by processes (`docs/theory.md`, "Processes"): on `P` processes the grid's cell
//! rows (layers of cells across y, the axis whose node index varies slowest in 2D and 3D,
//! [`crate::grid::SLOWEST_AXIS`]) are cut into `P` contiguous bands holding about the same number of points
//! (a plate extruded along z is cut across its height, not its thickness); a process owns the
//! points in its cells and the grid nodes of its node rows (the block rows of the Jacobian it assembles).
//! Every step, points that moved into another process's band migrate to it, and every process receives
//! copies (ghosts) of the other processes' points whose support may reach its node rows, so that it can
//! evaluate its rows completely. The nodal sums of P2G are completed between neighbouring bands only
//! ([`NodalWindows`]): each process reads its own node rows and those its points reach. Points and
//! nodal sums travel as records ([`Particles::pack`]) through a PETSc star forest (`PetscSF`,
//! [`Session::exchange`](crate::petsc::Session::exchange)). Units: mm.

use crate::grid::{Grid, SLOWEST_AXIS};
use crate::particles::Particles;
use crate::petsc::{PetscError, SessionGuard};
use crate::shape::ShapeTable;
use nalgebra::SVector;
use std::ops::Range;

/// Node rows beyond the cell rows of a point's domain that its support may reach: 1 for the linear
/// and CPDI interpolators, up to 2 for GIMP and the quadratic B-spline (support 1.5 cells about the
/// point), plus one of margin. The support is checked against it every step ([`Partition::check_reach`]).
const REACH_ROWS: isize = 3;

/// Cell-row bands of the processes.
#[derive(Debug, Clone, PartialEq)]
pub struct Partition {
    rank: usize,
    /// Process `r` owns cell rows and node rows `cuts[r]..cuts[r + 1]`; the last also node row `ny`.
    cuts: Vec<usize>,
    y0: f64,
    h: f64,
    ny: usize,
    /// Nodes per node row (`nx + 1` in 2D, `(nx + 1)(nz + 1)` in 3D).
    row_nodes: usize,
}

impl Partition {
    /// Bands of about equal point counts for the processes of `session`, from the points of
    /// `particles` (all points if `all_here`, else this process's share: the counts are summed).
    pub fn balanced<const D: usize>(
        session: &SessionGuard,
        grid: &Grid<D>,
        particles: &Particles<D>,
        all_here: bool,
    ) -> Result<Self, String> {
        let axis = SLOWEST_AXIS;
        let ny = grid.cells()[axis];
        let mut counts = vec![0.0; ny];
        let h = grid.cell_size();
        let y0 = grid.origin()[axis];
        for x in &particles.x {
            counts[cell_row(y0, h, ny, x[axis])] += 1.0;
        }
        if !all_here {
            session.sum(&mut counts).map_err(|e| e.to_string())?;
        }
        Self::from_counts(session.rank(), session.size(), grid, &counts)
    }

    /// Bands of about equal sums of `counts` (points per cell row of `grid`, of every process's points)
    /// for the processes of `session`: the bands [`Partition::balanced`] cuts from the same points, known
    /// before the points are seeded ([`Partition::row_of`] finds a point's row).
    pub fn from_row_counts<const D: usize>(
        session: &SessionGuard,
        grid: &Grid<D>,
        counts: &[f64],
    ) -> Result<Self, String> {
        Self::from_counts(session.rank(), session.size(), grid, counts)
    }

    /// The cell row of `grid` at height `y` (mm, along [`SLOWEST_AXIS`]), clamped to the grid: the row
    /// a point at that height is counted in.
    pub fn row_of<const D: usize>(grid: &Grid<D>, y: f64) -> usize {
        let axis = SLOWEST_AXIS;
        cell_row(grid.origin()[axis], grid.cell_size(), grid.cells()[axis], y)
    }

    /// This process's index.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Bands of about equal sums of `counts` (points per cell row) for process `rank` of `size`.
    fn from_counts<const D: usize>(
        rank: usize,
        size: usize,
        grid: &Grid<D>,
        counts: &[f64],
    ) -> Result<Self, String> {
        let axis = SLOWEST_AXIS;
        let ny = grid.cells()[axis];
        if ny < size {
            return Err(format!(
                "{size} processes for a grid of {ny} cell rows: each process needs at least one row"
            ));
        }
        let total: f64 = counts.iter().sum();
        let mut cuts = vec![0; size + 1];
        cuts[size] = ny;
        let mut cumulative = 0.0;
        let mut j = 0;
        for r in 1..size {
            let target = total * r as f64 / size as f64;
            while j < ny && cumulative + counts[j] <= target {
                cumulative += counts[j];
                j += 1;
            }
            cuts[r] = j.max(cuts[r - 1] + 1).min(ny - (size - r));
        }
        Ok(Self {
            rank,
            cuts,
            y0: grid.origin()[axis],
            h: grid.cell_size(),
            ny,
            row_nodes: (0..D)
                .filter(|&d| d != axis)
                .map(|d| grid.cells()[d] + 1)
                .product(),
        })
    }

    /// Cell row of height `y` (mm), clamped to the grid.
    fn cell_row(&self, y: f64) -> usize {
        cell_row(self.y0, self.h, self.ny, y)
    }

    /// The process owning cell row `j`.
    fn owner_of_row(&self, j: usize) -> usize {
        self.cuts.partition_point(|&c| c <= j) - 1
    }

    /// The process owning a point at `x` (mm): the process of its cell.
    pub fn owner<const D: usize>(&self, x: SVector<f64, D>) -> usize {
        self.owner_of_row(self.cell_row(x[SLOWEST_AXIS]))
    }

    /// Node rows of process `r`.
    fn node_rows(&self, r: usize) -> Range<usize> {
        let last = usize::from(r + 1 == self.cuts.len() - 1);
        self.cuts[r]..self.cuts[r + 1] + last
    }

    /// The grid nodes (indices) this process owns: its node rows.
    pub fn owned_nodes(&self) -> Range<usize> {
        let rows = self.node_rows(self.rank);
        rows.start * self.row_nodes..rows.end * self.row_nodes
    }

    /// The node rows point `p`'s support may reach: the cell rows of its position and domain corners,
    /// widened by [`REACH_ROWS`].
    fn reach<const D: usize>(&self, particles: &Particles<D>, p: usize) -> Range<isize> {
        let (lo, hi) = particles
            .corners(p)
            .iter()
            .chain(std::iter::once(&particles.x[p]))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                (lo.min(c[SLOWEST_AXIS]), hi.max(c[SLOWEST_AXIS]))
            });
        let row = |y: f64| ((y - self.y0) / self.h).floor() as isize;
        row(lo) - REACH_ROWS + 1..row(hi) + REACH_ROWS + 1
    }

    /// Processes other than this one whose node rows meet `rows`.
    fn ranks_meeting(&self, rows: &Range<isize>) -> impl Iterator<Item = usize> + '_ {
        let rows = rows.clone();
        (0..self.cuts.len() - 1).filter(move |&r| {
            let own = self.node_rows(r);
            r != self.rank && (own.start as isize) < rows.end && (own.end as isize) > rows.start
        })
    }

    /// Checks that the support of each of the first `owned` points in `table` lies within the node rows
    /// its ghosts were sent for (a domain stretched beyond `REACH_ROWS` rows of its corners would leave
    /// another process without the point).
    pub fn check_reach<const D: usize>(
        &self,
        table: &ShapeTable<D>,
        particles: &Particles<D>,
        owned: usize,
    ) -> Result<(), String> {
        for p in 0..owned {
            let reach = self.reach(particles, p);
            for w in table.weights(p) {
                let row =
                    (w.node as usize % (self.row_nodes * (self.ny + 1)) / self.row_nodes) as isize;
                if !reach.contains(&row) {
                    let x = particles.x[p];
                    return Err(format!(
                        "the point at {:.3?} mm reaches grid node row {row}, beyond the rows \
                         {reach:?} its copies were sent for (a support wider than {REACH_ROWS} cells \
                         beyond its domain)",
                        x.as_slice()
                    ));
                }
            }
        }
        Ok(())
    }
}

impl Partition {
    /// Node row of grid node `node` (a field copy's row is that of its grid node).
    fn node_row(&self, node: usize) -> usize {
        node % (self.row_nodes * (self.ny + 1)) / self.row_nodes
    }

    /// This process's node rows.
    pub fn own_node_rows(&self) -> Range<usize> {
        self.node_rows(self.rank)
    }

    /// The node rows the supports of the points `points` of `table` meet (empty if none).
    pub fn rows_reached<const D: usize>(
        &self,
        table: &ShapeTable<D>,
        points: Range<usize>,
    ) -> Range<usize> {
        let (lo, hi) =
            points
                .flat_map(|p| table.weights(p))
                .fold((usize::MAX, 0), |(lo, hi), w| {
                    let row = self.node_row(w.node as usize);
                    (lo.min(row), hi.max(row + 1))
                });
        if lo < hi { lo..hi } else { 0..0 }
    }

    /// The windows of a step's nodal sums on every process, from this process's `touched` rows (those its
    /// own points reach) and `read` rows (its own node rows and those its own points and ghosts reach,
    /// which hold `touched`). Collective.
    pub fn windows(
        &self,
        session: &SessionGuard,
        touched: Range<usize>,
        read: Range<usize>,
    ) -> Result<NodalWindows, PetscError> {
        let size = session.size();
        let mut ends = vec![0.0; 4 * size];
        let mine = [touched.start, touched.end, read.start, read.end];
        for (k, v) in mine.into_iter().enumerate() {
            ends[4 * self.rank + k] = v as f64;
        }
        session.sum(&mut ends)?;
        let range = |r: usize, k: usize| ends[4 * r + k] as usize..ends[4 * r + k + 1] as usize;
        Ok(NodalWindows {
            rank: self.rank,
            row_nodes: self.row_nodes,
            touched: (0..size).map(|r| range(r, 0)).collect(),
            read: (0..size).map(|r| range(r, 2)).collect(),
        })
    }

    /// Gives every process the flags of the other processes' own nodes: on return `flags` (one per grid
    /// node) holds on every node its owner's flag (this process's own nodes keep theirs). Sent packed,
    /// 32 flags to a value. Collective.
    pub fn share_owned_flags(
        &self,
        session: &SessionGuard,
        flags: &mut [bool],
    ) -> Result<(), PetscError> {
        let size = session.size();
        let nodes = |r: usize| {
            let rows = self.node_rows(r);
            rows.start * self.row_nodes..rows.end * self.row_nodes
        };
        let words = |r: usize| nodes(r).len().div_ceil(FLAGS_PER_VALUE);
        let own: Vec<f64> = flags[nodes(self.rank)]
            .chunks(FLAGS_PER_VALUE)
            .map(|c| {
                c.iter()
                    .rev()
                    .fold(0.0, |w, &f| 2.0 * w + f64::from(u8::from(f)))
            })
            .collect();
        let counts: Vec<usize> = (0..size)
            .map(|r| if r == self.rank { 0 } else { own.len() })
            .collect();
        let send = own.repeat(size - 1);
        let received = session.exchange(1, &counts, &send)?;
        let mut at = 0;
        for r in (0..size).filter(|&r| r != self.rank) {
            let theirs = &received[at..at + words(r)];
            at += words(r);
            for (chunk, &w) in flags[nodes(r)].chunks_mut(FLAGS_PER_VALUE).zip(theirs) {
                let mut bits = w as u64;
                for f in chunk {
                    *f = bits & 1 == 1;
                    bits >>= 1;
                }
            }
        }
        Ok(())
    }
}

/// Flags packed into one value of [`Partition::share_owned_flags`] (exact in a double's mantissa).
const FLAGS_PER_VALUE: usize = 32;

/// The node rows of a step's nodal sums on every process (`docs/theory.md`, "Processes"): the rows each
/// process's own points reach (where its partial sums may be nonzero) and the rows it reads (where it
/// needs them complete). A process sends a neighbour its partial sums on the rows that neighbour reads,
/// so no process ever sends or receives the whole grid.
#[derive(Debug, Clone, PartialEq)]
pub struct NodalWindows {
    rank: usize,
    /// Nodes per node row.
    row_nodes: usize,
    /// Per process: the node rows its own points reach.
    touched: Vec<Range<usize>>,
    /// Per process: the node rows it reads.
    read: Vec<Range<usize>>,
}

impl NodalWindows {
    /// The grid nodes this process reads (and holds complete after [`NodalWindows::sum`]).
    pub fn read_nodes(&self) -> Range<usize> {
        let rows = &self.read[self.rank];
        rows.start * self.row_nodes..rows.end * self.row_nodes
    }

    /// Sums `values` (`width` per grid node: this process's partial sums over its own points) over the
    /// processes on the nodes this process reads, each node's partial sums added in process order from
    /// zero, so that every process reading a node gets the same bits. Collective.
    pub fn sum(
        &self,
        session: &SessionGuard,
        width: usize,
        values: &mut [f64],
    ) -> Result<(), PetscError> {
        let span = |rows: &Range<usize>| {
            rows.start * self.row_nodes * width..rows.end * self.row_nodes * width
        };
        let (mine, read) = (&self.touched[self.rank], &self.read[self.rank]);
        let mut counts = vec![0; self.read.len()];
        let mut send = Vec::new();
        for (r, theirs) in self
            .read
            .iter()
            .enumerate()
            .filter(|&(r, _)| r != self.rank)
        {
            let rows = meet(mine, theirs);
            counts[r] = rows.len() * self.row_nodes;
            send.extend_from_slice(&values[span(&rows)]);
        }
        let received = session.exchange(width, &counts, &send)?;
        let own = values[span(read)].to_vec();
        values[span(read)].fill(0.0);
        let mut at = 0;
        for (r, touched) in self.touched.iter().enumerate() {
            let rows = meet(touched, read);
            let n = span(&rows).len();
            let part = if r == self.rank {
                let from = span(&rows).start - span(read).start;
                &own[from..from + n]
            } else {
                at += n;
                &received[at - n..at]
            };
            for (v, p) in values[span(&rows)].iter_mut().zip(part) {
                *v += p;
            }
        }
        Ok(())
    }
}

/// The rows in both `a` and `b` (empty if they do not meet).
fn meet(a: &Range<usize>, b: &Range<usize>) -> Range<usize> {
    let start = a.start.max(b.start);
    start..a.end.min(b.end).max(start)
}

/// Cell row of height `y` (mm) on a grid of `ny` rows of height `h` from `y0`, clamped to the grid.
fn cell_row(y0: f64, h: f64, ny: usize, y: f64) -> usize {
    (((y - y0) / h).floor().max(0.0) as usize).min(ny - 1)
}

/// Keeps the points of this process from a set every process holds whole.
pub fn keep_own<const D: usize>(partition: &Partition, particles: &mut Particles<D>) {
    let keep: Vec<bool> = particles
        .x
        .iter()
        .map(|&x| partition.owner(x) == partition.rank)
        .collect();
    particles.retain(&keep);
}

/// Records of the chosen points per destination, in process order, with their counts.
fn send_buffer<const D: usize>(
    particles: &Particles<D>,
    size: usize,
    mut destinations: impl FnMut(usize, &mut Vec<usize>),
) -> (Vec<usize>, Vec<f64>) {
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); size];
    let mut counts = vec![0; size];
    let mut to = Vec::new();
    for p in 0..particles.len() {
        to.clear();
        destinations(p, &mut to);
        for &r in &to {
            particles.pack(p, &mut per[r]);
            counts[r] += 1;
        }
    }
    (counts, per.concat())
}

/// Sends every point `p` to the processes `destinations(p, ..)` pushes and returns the number of
/// records sent and the records received. Collective.
fn exchange_points<const D: usize>(
    session: &SessionGuard,
    particles: &Particles<D>,
    destinations: impl FnMut(usize, &mut Vec<usize>),
) -> Result<(usize, Vec<f64>), PetscError> {
    let (counts, send) = send_buffer(particles, session.size(), destinations);
    let received = session.exchange(particles.record_width(), &counts, &send)?;
    Ok((counts.iter().sum(), received))
}

/// Appends the points of `records` (packed by [`Particles::pack`]); returns how many.
fn unpack_all<const D: usize>(particles: &mut Particles<D>, records: &[f64]) -> usize {
    let width = particles.record_width();
    for record in records.chunks_exact(width) {
        particles.unpack(record);
    }
    records.len() / width
}

/// Sends this process's points that moved into another process's band to it and appends the points
/// it receives. Returns the number of points that left.
pub fn migrate<const D: usize>(
    session: &SessionGuard,
    partition: &Partition,
    particles: &mut Particles<D>,
) -> Result<usize, PetscError> {
    let owners: Vec<usize> = particles.x.iter().map(|&x| partition.owner(x)).collect();
    let (sent, received) = exchange_points(session, particles, |p, to| {
        if owners[p] != partition.rank {
            to.push(owners[p]);
        }
    })?;
    if sent > 0 {
        let keep: Vec<bool> = owners.iter().map(|&r| r == partition.rank).collect();
        particles.retain(&keep);
    }
    unpack_all(particles, &received);
    Ok(sent)
}

/// Appends copies of the other processes' points whose support may reach this process's node rows
/// (after this process's own points, which stay first). Returns the number of copies received.
pub fn add_ghosts<const D: usize>(
    session: &SessionGuard,
    partition: &Partition,
    particles: &mut Particles<D>,
) -> Result<usize, PetscError> {
    let (_, received) = exchange_points(session, particles, |p, to| {
        to.extend(partition.ranks_meeting(&partition.reach(particles, p)));
    })?;
    Ok(unpack_all(particles, &received))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::ShapeKind;
    use nalgebra::{Matrix2, Vector2};

    fn grid() -> Grid {
        Grid::new(Vector2::new(-2.0, -4.0), 1.0, [12, 30]).expect("grid")
    }

    #[test]
    fn bands_hold_equal_counts_and_own_every_node_once() {
        let g = grid();
        // Points in rows 0..20 only: 3 processes cut at rows about 7 and 13.
        let counts: Vec<f64> = (0..30).map(|j| if j < 21 { 10.0 } else { 0.0 }).collect();
        let parts: Vec<Partition> = (0..3)
            .map(|r| Partition::from_counts(r, 3, &g, &counts).expect("bands"))
            .collect();
        assert_eq!(parts[0].cuts, vec![0, 7, 14, 30]);
        let mut owner = vec![usize::MAX; g.num_nodes()];
        for (r, p) in parts.iter().enumerate() {
            for n in p.owned_nodes() {
                assert_eq!(owner[n], usize::MAX, "node {n} owned twice");
                owner[n] = r;
            }
        }
        assert!(owner.iter().all(|&r| r != usize::MAX), "every node owned");
        // The owner of a point is the process of its cell, also outside the grid (clamped).
        let p = &parts[1];
        assert_eq!(p.owner(Vector2::new(0.0, -4.0 + 6.99)), 0);
        assert_eq!(p.owner(Vector2::new(0.0, -4.0 + 7.0)), 1);
        assert_eq!(p.owner(Vector2::new(0.0, 100.0)), 2);
        assert_eq!(p.owner(Vector2::new(0.0, -100.0)), 0);
        // More processes than rows: an error, not empty bands.
        assert!(Partition::from_counts(0, 31, &g, &counts).is_err());
        // Empty rows never leave a band empty.
        let few = Partition::from_counts(0, 4, &g, &[0.0; 30]).expect("bands");
        assert!(few.cuts.windows(2).all(|w| w[0] < w[1]), "{:?}", few.cuts);
    }

    #[test]
    fn rows_reached_are_the_node_rows_of_the_supports() {
        let g = grid();
        let part = Partition::from_counts(1, 3, &g, &[1.0; 30]).expect("bands");
        assert_eq!(part.own_node_rows(), 10..20);
        let mut ps = Particles::new();
        ps.push(
            Vector2::new(0.5, -4.0 + 10.5),
            0.25,
            1e-9,
            Matrix2::identity() * 0.25,
            0,
        );
        ps.push(
            Vector2::new(3.5, -4.0 + 25.5),
            0.25,
            1e-9,
            Matrix2::identity() * 0.25,
            0,
        );
        let mut table = ShapeTable::new();
        table.compute(ShapeKind::Linear, &g, &ps).expect("table");
        assert_eq!(part.rows_reached(&table, 0..1), 10..12);
        assert_eq!(part.rows_reached(&table, 0..2), 10..27);
        assert!(part.rows_reached(&table, 0..0).is_empty());
        assert_eq!(meet(&(2..5), &(4..9)), 4..5);
        assert!(meet(&(2..5), &(6..9)).is_empty());
    }

    #[test]
    fn every_support_lies_in_the_reach_its_ghosts_are_sent_for() {
        let g = grid();
        let part = Partition::from_counts(0, 3, &g, &[1.0; 30]).expect("bands");
        let mut ps = Particles::new();
        for k in 0..20 {
            let x = Vector2::new(2.0 + 0.37 * k as f64, 3.0 + 0.61 * k as f64);
            ps.push(x, 0.25, 1e-9, Matrix2::identity() * 0.25, 0);
        }
        // A sheared, stretched CPDI domain (3 cells tall).
        let f = Matrix2::new(1.2, 0.8, 0.1, 6.0);
        ps.set_deformation(5, f);
        for kind in [
            ShapeKind::Linear,
            ShapeKind::Gimp,
            ShapeKind::Cpdi1,
            ShapeKind::Bspline2,
        ] {
            let mut table = ShapeTable::new();
            table.compute(kind, &g, &ps).expect("table");
            part.check_reach(&table, &ps, ps.len())
                .unwrap_or_else(|e| panic!("{}: {e}", kind.name()));
        }
        // The stretched point is sent to every band its domain reaches.
        let reach = part.reach(&ps, 5);
        let to: Vec<usize> = part.ranks_meeting(&reach).collect();
        let rows = |r: usize| part.node_rows(r);
        for r in 1..3 {
            let meets =
                (rows(r).start as isize) < reach.end && (rows(r).end as isize) > reach.start;
            assert_eq!(to.contains(&r), meets, "process {r}");
        }
        assert!(!to.contains(&0), "never to itself");
    }
}
