//! Particle <-> grid transfers of the MPM step (`docs/theory.md`, "The implicit MPM step", steps 2, 5 and 7).
//!
//! * [`particles_to_grid`] (P2G, eq. 1): lumped nodal mass, mass-weighted velocity and acceleration into a
//!   reusable [`GridState`].
//! * [`grid_to_particles`] (G2P after a converged step): Newmark particle velocity, positions, deformation
//!   gradients, CPDI domains and volumes from the nodal displacement increment and new acceleration.
//! * [`deformation_increment`] and [`interpolate`]: the per-point kinematics as pure functions (G2P uses
//!   the first; the assembly forms `dF` inline for every Newton iterate, together with `eta_bar`).
//! * [`Scatter`]: the one place where per-point contributions are summed onto nodes in parallel.
//!
//! Units: mm, s, t; nodal mass in t, velocities mm/s, accelerations mm/s^2.

use std::ops::{Add, Mul};

use nalgebra::{SMatrix, SVector};
use num_traits::Zero;
use rayon::prelude::*;
use thiserror::Error;

use crate::grid::{Grid, GridError, Locus};
use crate::particles::{Particles, fill_domain_corners};
use crate::shape::{ShapeKind, ShapeTable, Weight};
use crate::space::det;

/// Errors of the transfers (all detected before anything is modified).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TransferError {
    /// An input array has the wrong length.
    #[error("{what} has {found} entries, expected {expected}")]
    SizeMismatch {
        /// Which input.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// The shape table was not computed (or its last computation failed).
    #[error("the shape-function table has not been computed for this step")]
    NoShapeTable,
    /// A tracked CPDI2 corner lies outside the grid.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// Summing the nodal values over the processes failed.
    #[error("summing the nodal P2G values over the processes: {0}")]
    Reduce(String),
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), TransferError> {
    if expected == found {
        Ok(())
    } else {
        Err(TransferError::SizeMismatch {
            what,
            expected,
            found,
        })
    }
}

/// `sum_I S_Ip f_I`: interpolates a nodal field (scalar or vector) to point `p` from its `weights`;
/// `field(I)` returns `f_I`.
#[inline]
pub fn interpolate<T, const D: usize>(weights: &[Weight<D>], field: impl Fn(usize) -> T) -> T
where
    T: Zero + Add<Output = T> + Mul<f64, Output = T>,
{
    weights
        .iter()
        .fold(T::zero(), |acc, w| acc + field(w.node as usize) * w.value)
}

/// Deformation-gradient increment of a point, `dF = I + sum_I du_I (x) grad_{X_n} S_Ip` [-], from its
/// start-of-step `weights` and the nodal displacement increments `du(I)` (mm). Then `F = dF F_n`,
/// `grad_x S = grad_{X_n} S . dF^{-1}` and `v_p = det(F) V_p^0`.
#[inline]
pub fn deformation_increment<const D: usize>(
    weights: &[Weight<D>],
    du: impl Fn(usize) -> SVector<f64, D>,
) -> SMatrix<f64, D, D> {
    weights.iter().fold(SMatrix::identity(), |df, w| {
        df + du(w.node as usize) * w.grad.transpose()
    })
}

/// Number of fixed point ranges of a [`Scatter`]; fixed (not the thread count) so that sums are bitwise
/// reproducible on any number of threads.
const SCATTER_CHUNKS: usize = 32;
/// Nodes per parallel work item of the reduction.
const NODE_BLOCK: usize = 2048;

/// Accumulator of one point range: nodes `lo..=hi`, `W` values per node.
#[derive(Debug, Clone, Default)]
struct ChunkBuffer {
    lo: usize,
    hi: usize,
    data: Vec<f64>,
}

/// Deterministic parallel scatter of per-(point, node) contributions onto grid nodes.
///
/// The points are split into `SCATTER_CHUNKS` fixed contiguous ranges. Each range accumulates, in point
/// order, into its own buffer covering only the node band it touches (points are seeded cell by cell and
/// move little, so bands are narrow); the buffers are then added node by node in range order. The result is
/// therefore independent of the thread count and scheduling. Buffers are kept between calls: no allocation
/// in the steady state.
#[derive(Debug, Clone, Default)]
pub struct Scatter {
    chunks: Vec<ChunkBuffer>,
}

impl Scatter {
    /// An empty scatter (buffers grow on first use).
    pub fn new() -> Self {
        Self::default()
    }

    /// `out_I = sum_p sum_{I in supp(p)} contribution(p, w_Ip)` for the `num_nodes` grid nodes, `W` values per
    /// node, node after node; `out` is resized to `num_nodes W` values and overwritten.
    ///
    /// # Panics
    /// If `table` holds a node index `>= num_nodes` (a table computed on another grid).
    pub fn scatter<const W: usize, const D: usize, F>(
        &mut self,
        table: &ShapeTable<D>,
        num_nodes: usize,
        out: &mut Vec<f64>,
        contribution: F,
    ) where
        F: Fn(usize, &Weight<D>) -> [f64; W] + Sync,
    {
        let n = table.len();
        self.chunks
            .resize_with(SCATTER_CHUNKS, ChunkBuffer::default);
        self.chunks.par_iter_mut().enumerate().for_each(|(k, buf)| {
            let points = k * n / SCATTER_CHUNKS..(k + 1) * n / SCATTER_CHUNKS;
            let (lo, hi) = points
                .clone()
                .flat_map(|p| table.weights(p))
                .fold((usize::MAX, 0), |(lo, hi), w| {
                    (lo.min(w.node as usize), hi.max(w.node as usize))
                });
            buf.data.clear();
            if lo > hi {
                (buf.lo, buf.hi) = (1, 0);
                return;
            }
            (buf.lo, buf.hi) = (lo, hi);
            buf.data.resize((hi - lo + 1) * W, 0.0);
            for p in points {
                for w in table.weights(p) {
                    let c = contribution(p, w);
                    let at = (w.node as usize - lo) * W;
                    for (d, c) in buf.data[at..at + W].iter_mut().zip(c) {
                        *d += c;
                    }
                }
            }
        });
        out.clear();
        out.resize(num_nodes * W, 0.0);
        let chunks = &self.chunks;
        out.par_chunks_mut(NODE_BLOCK * W)
            .enumerate()
            .for_each(|(b, block)| {
                let first = b * NODE_BLOCK;
                let last = first + block.len() / W - 1;
                for buf in chunks
                    .iter()
                    .filter(|c| c.lo <= c.hi && c.lo <= last && c.hi >= first)
                {
                    for node in buf.lo.max(first)..=buf.hi.min(last) {
                        let at = (node - buf.lo) * W;
                        let to = (node - first) * W;
                        for (o, d) in block[to..to + W].iter_mut().zip(&buf.data[at..at + W]) {
                            *o += d;
                        }
                    }
                }
            });
    }
}

/// Nodal state of one step after P2G; reuse it across steps (no allocation in the steady state).
#[derive(Debug, Clone, Default)]
pub struct GridState<const D: usize = 2> {
    /// Lumped nodal mass `m_I` (t; in 2D per mm of thickness).
    pub mass: Vec<f64>,
    /// Nodal velocity `v_I` (mm/s); zero at inactive nodes.
    pub velocity: Vec<SVector<f64, D>>,
    /// Nodal acceleration `a_I` (mm/s^2); zero at inactive nodes.
    pub acceleration: Vec<SVector<f64, D>>,
    /// Whether node `I` carries unknowns (`m_I > tol * max_J m_J`).
    pub active: Vec<bool>,
    /// `[m, m v, m a]` per node, `1 + 2 D` values.
    sums: Vec<f64>,
    scatter: Scatter,
}

impl<const D: usize> GridState<D> {
    /// An empty state (arrays grow on the first P2G).
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of active nodes.
    pub fn num_active(&self) -> usize {
        self.active.iter().filter(|&&a| a).count()
    }
}

/// Default relative tolerance on the nodal mass: nodes with `m_I <= 1e-10 max_J m_J` carry no unknowns.
pub const DEFAULT_RELATIVE_MASS_TOLERANCE: f64 = 1e-10;

/// P2G (eq. 1) with the start-of-step shape functions `S_Ip` of `table`:
///
/// ```text
/// m_I = sum_p S_Ip m_p,   (m v)_I = sum_p S_Ip m_p v_p,   (m a)_I = sum_p S_Ip m_p a_p
/// v_I = (m v)_I / m_I,    a_I = (m a)_I / m_I             if m_I > relative_tolerance * max_J m_J
/// v_I = a_I = 0, node inactive                            otherwise (always if m_I = 0)
/// ```
///
/// Mass and momentum are conserved to round-off: `sum_I m_I = sum_p m_p` and, over active nodes,
/// `sum_I m_I v_I = sum_p m_p v_p` (partition of unity).
pub fn particles_to_grid<const D: usize>(
    table: &ShapeTable<D>,
    particles: &Particles<D>,
    grid: &Grid<D>,
    relative_tolerance: f64,
    state: &mut GridState<D>,
) -> Result<(), TransferError> {
    particles_to_grid_shared(
        table,
        particles,
        particles.len(),
        grid,
        relative_tolerance,
        state,
        (|_: &mut [f64]| Ok(()), Ok),
    )
}

/// P2G as [`particles_to_grid`] for a process holding part of the points: only the first `counted`
/// points contribute (the others are copies of other processes' points), and the nodal sums
/// `[m, m v, m a]` per node (`1 + 2 D` values) pass through `reduce` (the sum over the processes, on the
/// nodes a process reads) before the activity test and the divisions, so that every process gets the
/// same grid state on the nodes it reads; `largest` turns
/// this process's largest nodal mass (t) into the largest over the processes (the identity where
/// `reduce` leaves every process the whole grid).
pub fn particles_to_grid_shared<const D: usize>(
    table: &ShapeTable<D>,
    particles: &Particles<D>,
    counted: usize,
    grid: &Grid<D>,
    relative_tolerance: f64,
    state: &mut GridState<D>,
    (reduce, largest): (
        impl FnOnce(&mut [f64]) -> Result<(), String>,
        impl FnOnce(f64) -> Result<f64, String>,
    ),
) -> Result<(), TransferError> {
    if table.kind().is_none() {
        return Err(TransferError::NoShapeTable);
    }
    check_len("the shape table", particles.len(), table.len())?;
    // All node copies of the table's velocity fields.
    let nodes = grid.num_nodes() * table.fields();
    match D {
        2 => nodal_sums::<D, 5>(table, particles, counted, nodes, state),
        3 => nodal_sums::<D, 7>(table, particles, counted, nodes, state),
        _ => unreachable!("grids are 2D or 3D"),
    }
    reduce(&mut state.sums).map_err(TransferError::Reduce)?;
    let width = 1 + 2 * D;
    let max_mass = state
        .sums
        .chunks_exact(width)
        .fold(0.0_f64, |mx, s| mx.max(s[0]));
    let max_mass = largest(max_mass).map_err(TransferError::Reduce)?;
    let threshold = relative_tolerance * max_mass;
    state.mass.resize(nodes, 0.0);
    state.velocity.resize(nodes, SVector::zeros());
    state.acceleration.resize(nodes, SVector::zeros());
    state.active.resize(nodes, false);
    (
        &mut state.mass,
        &mut state.velocity,
        &mut state.acceleration,
        &mut state.active,
        state.sums.par_chunks_exact(width),
    )
        .into_par_iter()
        .for_each(|(mass, vel, acc, active, s)| {
            *mass = s[0];
            *active = s[0] > threshold && s[0] > 0.0;
            if *active {
                *vel = SVector::from_column_slice(&s[1..1 + D]) / s[0];
                *acc = SVector::from_column_slice(&s[1 + D..]) / s[0];
            } else {
                *vel = SVector::zeros();
                *acc = SVector::zeros();
            }
        });
    Ok(())
}

/// `[m, m v, m a]_I = sum_p S_Ip m_p [1, v_p, a_p]` over the first `counted` points into `state.sums`,
/// `W = 1 + 2 D` values per node.
fn nodal_sums<const D: usize, const W: usize>(
    table: &ShapeTable<D>,
    particles: &Particles<D>,
    counted: usize,
    nodes: usize,
    state: &mut GridState<D>,
) {
    debug_assert_eq!(W, 1 + 2 * D);
    let (m, v, a) = (&particles.mass, &particles.v, &particles.a);
    state
        .scatter
        .scatter(table, nodes, &mut state.sums, |p, w| {
            let mut s = [0.0; W];
            if p >= counted {
                return s;
            }
            let mp = w.value * m[p];
            s[0] = mp;
            for d in 0..D {
                s[1 + d] = mp * v[p][d];
                s[1 + D + d] = mp * a[p][d];
            }
            s
        });
}

/// Converged nodal solution of a step: what G2P needs.
#[derive(Debug, Clone, Copy)]
pub struct StepSolution<'a, const D: usize = 2> {
    /// Nodal displacement increment `du_I` (mm), one per grid node (zero at inactive nodes).
    pub du: &'a [SVector<f64, D>],
    /// New nodal acceleration `a_I^{n+1}` (mm/s^2), one per grid node.
    pub acceleration: &'a [SVector<f64, D>],
    /// Newmark `gamma` [-].
    pub gamma: f64,
    /// Time step `dt` (s).
    pub dt: f64,
}

/// G2P after a converged step, with the start-of-step `S_Ip` of `table` (spec Sec. 1, step 7):
///
/// ```text
/// a_p^{n+1} = sum_I S_Ip a_I^{n+1}
/// v_p^{n+1} = v_p + dt ((1 - gamma) a_p + gamma a_p^{n+1})
/// x_p^{n+1} = x_p + sum_I S_Ip du_I
/// F_p^{n+1} = dF F_p,   dF = I + sum_I du_I (x) grad_{X_n} S_Ip,   v_p = det(F_p^{n+1}) V_p^0
/// CPDI1 (and for output all but CPDI2):  r_p = F_p^{n+1} r_p^0,  corners x_p + r_p s_c
/// CPDI2:  x_c^{n+1} = x_c + sum_I N_I(x_c) du_I   (grid hat functions at the tracked corners)
/// ```
///
/// Material history, stress and `eta_bar_p` are the caller's. Nothing is modified if an error is returned.
pub fn grid_to_particles<const D: usize>(
    table: &ShapeTable<D>,
    grid: &Grid<D>,
    solution: &StepSolution<'_, D>,
    particles: &mut Particles<D>,
) -> Result<(), TransferError> {
    let kind = table.kind().ok_or(TransferError::NoShapeTable)?;
    check_len("the shape table", particles.len(), table.len())?;
    let nodes = grid.num_nodes() * table.fields();
    check_len("du", nodes, solution.du.len())?;
    check_len("the nodal acceleration", nodes, solution.acceleration.len())?;
    // CPDI2 moves the corners with the grid's hat functions of field 0 (the solver rejects CPDI2 with
    // several fields).
    let track_corners = kind == ShapeKind::Cpdi2;
    if track_corners {
        let outside = particles
            .corners
            .par_chunks(Particles::<D>::CORNERS)
            .enumerate()
            .find_first(|(_, cs)| cs.iter().any(|&xc| grid.cell_of(xc).is_none()));
        if let Some((particle, cs)) = outside {
            let c = cs
                .iter()
                .position(|&xc| grid.cell_of(xc).is_none())
                .unwrap_or(0);
            return Err(GridError::outside(particle, Locus::Corner(c as u8), &cs[c]).into());
        }
    }
    let StepSolution {
        du,
        acceleration,
        gamma,
        dt,
    } = *solution;
    let ps = particles;
    (
        &mut ps.x,
        &mut ps.v,
        &mut ps.a,
        &mut ps.f,
        &mut ps.r,
        ps.corners.par_chunks_mut(Particles::<D>::CORNERS),
        &mut ps.vol,
        &ps.r0,
        &ps.vol0,
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(p, (x, v, a, f, r, corners, vol, r0, vol0))| {
            let ws = table.weights(p);
            let a_new = interpolate(ws, |i| acceleration[i]);
            *v += ((1.0 - gamma) * *a + gamma * a_new) * dt;
            *a = a_new;
            *x += interpolate(ws, |i| du[i]);
            *f = deformation_increment(ws, |i| du[i]) * *f;
            *vol = det(f) * vol0;
            *r = *f * r0;
            if track_corners {
                for xc in corners.iter_mut() {
                    // Inside the grid: checked above.
                    if let Some((cell, fc)) = grid.locate(*xc) {
                        let nodes = grid.cell_nodes(cell);
                        let values = Grid::<D>::cell_values(&fc);
                        *xc += (0..Grid::<D>::CELL_NODES)
                            .map(|k| du[nodes[k] as usize] * values[k])
                            .sum::<SVector<f64, D>>();
                    }
                }
            } else {
                fill_domain_corners(x, r, corners);
            }
        });
    Ok(())
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix2, Rotation2, Vector2};
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    use super::*;
    use crate::geometry::Seeding;
    use crate::particles::tests::rect_geometry;

    /// A 6 x 4 mm block of 2 x 2 points per 0.5 mm cell, inside a grid with 4 cells of margin.
    fn setup() -> (Grid, Particles) {
        setup_block([7.0, 6.0], 4)
    }

    /// The block `[1, 2] x max` (mm) with `margin_cells` of grid margin.
    fn setup_block(max: [f64; 2], margin_cells: usize) -> (Grid, Particles) {
        let geometry = rect_geometry([1.0, 2.0], max);
        seed_block(&geometry, margin_cells)
    }

    /// 2^D points per 0.5 mm cell in `body`, inside a grid with `margin_cells` of margin.
    fn seed_block<const D: usize>(
        body: &impl crate::geometry::Body<D>,
        margin_cells: usize,
    ) -> (Grid<D>, Particles<D>) {
        let ps = Particles::seed(
            body,
            &Seeding {
                h: 0.5,
                points_per_cell: 2,
                density: 2.4e-9,
                body: 0,
            },
        )
        .unwrap();
        let (lo, hi) = ps.bounding_box().unwrap();
        (Grid::covering(lo, hi, 0.5, margin_cells).unwrap(), ps)
    }

    fn randomise(ps: &mut Particles, rng: &mut StdRng) {
        for p in 0..ps.len() {
            ps.mass[p] *= rng.random_range(0.5..2.0);
            ps.v[p] = Vector2::new(rng.random_range(-1e3..1e3), rng.random_range(-1e3..1e3));
            ps.a[p] = Vector2::new(rng.random_range(-1e8..1e8), rng.random_range(-1e8..1e8));
            ps.x[p] += Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1));
        }
    }

    #[test]
    fn transfer_p2g_conserves_mass_and_momentum() {
        let (grid, mut ps) = setup();
        randomise(&mut ps, &mut StdRng::seed_from_u64(7));
        let (mut table, mut state) = (ShapeTable::new(), GridState::new());
        for kind in ShapeKind::ALL {
            table.compute(kind, &grid, &ps).unwrap();
            particles_to_grid(&table, &ps, &grid, 0.0, &mut state).unwrap();
            check_conservation(&grid, &ps, &state, kind);
            assert!(
                state
                    .active
                    .iter()
                    .zip(&state.mass)
                    .all(|(&a, &m)| a == (m > 0.0))
            );
            assert!(state.num_active() > 0 && state.num_active() < grid.num_nodes());
        }
    }

    #[test]
    fn transfer_p2g_is_bitwise_reproducible_on_any_thread_count() {
        let (grid, mut ps) = setup();
        randomise(&mut ps, &mut StdRng::seed_from_u64(8));
        let mut table = ShapeTable::new();
        table.compute(ShapeKind::Cpdi1, &grid, &ps).unwrap();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let (mut state, tol) = (GridState::new(), DEFAULT_RELATIVE_MASS_TOLERANCE);
                particles_to_grid(&table, &ps, &grid, tol, &mut state).unwrap();
                (state.mass, state.velocity, state.acceleration)
            })
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
        // The serial reference sum agrees to round-off.
        let mut mass = vec![0.0; grid.num_nodes()];
        for (p, ws) in table.iter() {
            for w in ws {
                mass[w.node as usize] += w.value * ps.mass[p];
            }
        }
        assert!(
            mass.iter()
                .zip(&one.0)
                .all(|(a, b)| (a - b).abs() <= 1e-14 * a.abs())
        );
    }

    #[test]
    fn transfer_p2g_relative_mass_tolerance_deactivates_light_nodes() {
        let (grid, mut ps) = setup();
        ps.v.iter_mut().for_each(|v| *v = Vector2::new(3.0, -4.0));
        // A domain corner barely reaching into a neighbouring cell gives that cell's far nodes a tiny mass.
        ps.x[0] -= Vector2::new(1e-9, 0.0);
        let mut table = ShapeTable::new();
        table.compute(ShapeKind::Cpdi1, &grid, &ps).unwrap();
        let mut state = GridState::new();
        particles_to_grid(&table, &ps, &grid, 0.0, &mut state).unwrap();
        let (all, tol) = (state.num_active(), DEFAULT_RELATIVE_MASS_TOLERANCE);
        particles_to_grid(&table, &ps, &grid, tol, &mut state).unwrap();
        assert!(state.num_active() < all);
        for i in 0..grid.num_nodes() {
            if state.active[i] {
                assert!((state.velocity[i] - Vector2::new(3.0, -4.0)).norm() < 1e-12);
            } else {
                assert_eq!(state.velocity[i], Vector2::zeros());
            }
        }
    }

    /// G2P of a nodal increment that is linear in `x`: `du_I = (R - I)(x_I - x0) + d`.
    fn linear_increment<const D: usize>(
        grid: &Grid<D>,
        rot: SMatrix<f64, D, D>,
        x0: SVector<f64, D>,
        d: SVector<f64, D>,
    ) -> Vec<SVector<f64, D>> {
        (0..grid.num_nodes())
            .map(|i| (rot - SMatrix::identity()) * (grid.node_position(i) - x0) + d)
            .collect()
    }

    /// A converged step with the nodal increment `du` and acceleration `acceleration` (`gamma = 0.5`,
    /// `dt = 1 us`).
    fn solution<'a, const D: usize>(
        du: &'a [SVector<f64, D>],
        acceleration: &'a [SVector<f64, D>],
    ) -> StepSolution<'a, D> {
        StepSolution {
            du,
            acceleration,
            gamma: 0.5,
            dt: 1e-6,
        }
    }

    /// Asserts that P2G into `state` kept the points' mass, momentum and `m a` (kind `kind`).
    fn check_conservation<const D: usize>(
        grid: &Grid<D>,
        ps: &Particles<D>,
        state: &GridState<D>,
        kind: ShapeKind,
    ) {
        let m_p: f64 = ps.mass.iter().sum();
        let mv_p: SVector<f64, D> = (0..ps.len()).map(|p| ps.v[p] * ps.mass[p]).sum();
        let ma_p: SVector<f64, D> = (0..ps.len()).map(|p| ps.a[p] * ps.mass[p]).sum();
        let m_i: f64 = state.mass.iter().sum();
        let mv_i: SVector<f64, D> = (0..grid.num_nodes())
            .map(|i| state.velocity[i] * state.mass[i])
            .sum();
        let ma_i: SVector<f64, D> = (0..grid.num_nodes())
            .map(|i| state.acceleration[i] * state.mass[i])
            .sum();
        assert!((m_i / m_p - 1.0).abs() < 1e-13, "{kind:?}");
        assert!(
            (mv_i - mv_p).norm() < 1e-12 * m_p * 1e3,
            "{kind:?}: {mv_i} vs {mv_p}"
        );
        assert!(
            (ma_i - ma_p).norm() < 1e-12 * m_p * 1e8,
            "{kind:?}: {ma_i} vs {ma_p}"
        );
    }

    /// Asserts that G2P moved the points `ps0` to `ps` by the rigid motion `x -> R (x - x0) + x0 + d`:
    /// centres and corners moved, `F = R`, volume kept (kind `kind`).
    fn check_rigid_motion<const D: usize>(
        ps0: &Particles<D>,
        ps: &Particles<D>,
        rot: SMatrix<f64, D, D>,
        x0: SVector<f64, D>,
        d: SVector<f64, D>,
        kind: ShapeKind,
    ) {
        for p in 0..ps.len() {
            let expected = rot * (ps0.x[p] - x0) + x0 + d;
            assert!((ps.x[p] - expected).norm() < 1e-13, "{kind:?} point {p}");
            assert!(
                (ps.f[p] - rot).norm() < 1e-13,
                "{kind:?} point {p}: F = {}",
                ps.f[p]
            );
            assert!((ps.vol[p] / ps.vol0[p] - 1.0).abs() < 1e-13);
            for (c, (xc, xc0)) in ps.corners(p).iter().zip(ps0.corners(p)).enumerate() {
                let expected = rot * (xc0 - x0) + x0 + d;
                assert!(
                    (xc - expected).norm() < 1e-13,
                    "{kind:?} point {p} corner {c}"
                );
            }
        }
    }

    #[test]
    fn transfer_g2p_rigid_rotation_increment_is_exact() {
        let (grid, ps0) = setup();
        let rot = *Rotation2::new(0.3).matrix();
        let x0 = Vector2::new(4.0, 4.0);
        let d = Vector2::new(0.05, -0.02);
        let du = linear_increment(&grid, rot, x0, d);
        let zero = vec![Vector2::zeros(); grid.num_nodes()];
        let solution = solution(&du, &zero);
        let mut table = ShapeTable::new();
        for kind in ShapeKind::ALL {
            let mut ps = ps0.clone();
            table.compute(kind, &grid, &ps).unwrap();
            grid_to_particles(&table, &grid, &solution, &mut ps).unwrap();
            check_rigid_motion(&ps0, &ps, rot, x0, d, kind);
            for p in 0..ps.len() {
                assert!((ps.r[p] - rot * ps.r0[p]).norm() < 1e-14);
            }
        }
    }

    #[test]
    fn transfer_g2p_newmark_velocity_and_acceleration() {
        let (grid, mut ps) = setup();
        let mut table = ShapeTable::new();
        table.compute(ShapeKind::Gimp, &grid, &ps).unwrap();
        ps.v.iter_mut().for_each(|v| *v = Vector2::new(1.0, 2.0));
        ps.a.iter_mut().for_each(|a| *a = Vector2::new(10.0, 0.0));
        let a_new = vec![Vector2::new(-30.0, 50.0); grid.num_nodes()];
        let du = vec![Vector2::zeros(); grid.num_nodes()];
        let (gamma, dt) = (0.6, 1e-3);
        grid_to_particles(
            &table,
            &grid,
            &StepSolution {
                du: &du,
                acceleration: &a_new,
                gamma,
                dt,
            },
            &mut ps,
        )
        .unwrap();
        let v = Vector2::new(1.0, 2.0)
            + (Vector2::new(10.0, 0.0) * (1.0 - gamma) + Vector2::new(-30.0, 50.0) * gamma) * dt;
        for p in 0..ps.len() {
            assert!((ps.a[p] - Vector2::new(-30.0, 50.0)).norm() < 1e-12);
            assert!((ps.v[p] - v).norm() < 1e-14);
        }
    }

    #[test]
    fn transfer_many_rigid_translation_steps_keep_f_identity() {
        let (grid, ps0) = setup_block([2.5, 3.0], 10);
        // 200 steps of 0.0173 mm x 0.0071 mm: 3.5 mm, i.e. 7 cells in x, crossing many cell boundaries.
        let d = Vector2::new(0.0173, -0.0071);
        let du = vec![d; grid.num_nodes()];
        let zero = vec![Vector2::zeros(); grid.num_nodes()];
        let solution = solution(&du, &zero);
        let mut table = ShapeTable::new();
        for kind in ShapeKind::ALL {
            let mut ps = ps0.clone();
            for _ in 0..200 {
                table.compute(kind, &grid, &ps).unwrap();
                grid_to_particles(&table, &grid, &solution, &mut ps).unwrap();
            }
            for p in 0..ps.len() {
                assert!(
                    (ps.f[p] - Matrix2::identity()).norm() < 1e-12,
                    "{kind:?} point {p}: F = {}",
                    ps.f[p]
                );
                assert!(
                    (ps.x[p] - (ps0.x[p] + d * 200.0)).norm() < 1e-11,
                    "{kind:?} point {p}"
                );
                assert!(
                    (ps.corners(p)[2] - (ps0.corners(p)[2] + d * 200.0)).norm() < 1e-11,
                    "{kind:?}"
                );
            }
        }
    }

    #[test]
    fn transfer_deformation_increment_of_a_linear_field() {
        let (grid, ps) = setup();
        let l = Matrix2::new(0.01, -0.02, 0.03, 0.005);
        let mut table = ShapeTable::new();
        table.compute(ShapeKind::Bspline2, &grid, &ps).unwrap();
        for (_, ws) in table.iter() {
            let df = deformation_increment(ws, |i| l * grid.node_position(i));
            assert!((df - Matrix2::identity() - l).norm() < 1e-14);
            let s: f64 = interpolate(ws, |_| 2.5);
            assert!((s - 2.5).abs() < 1e-14);
        }
    }

    #[test]
    fn transfer_errors_leave_particles_unchanged() {
        let (grid, mut ps) = setup();
        let zero = vec![Vector2::zeros(); grid.num_nodes()];
        let solution = solution(&zero, &zero);
        let mut table = ShapeTable::new();
        assert_eq!(
            grid_to_particles(&table, &grid, &solution, &mut ps),
            Err(TransferError::NoShapeTable)
        );
        table.compute(ShapeKind::Cpdi2, &grid, &ps).unwrap();
        let short = StepSolution {
            du: &zero[1..],
            ..solution
        };
        assert!(matches!(
            grid_to_particles(&table, &grid, &short, &mut ps),
            Err(TransferError::SizeMismatch { what: "du", .. })
        ));
        let mut moved = ps.clone();
        moved.corners_mut(7)[2] = Vector2::new(1e3, 0.0);
        let before = moved.clone();
        let err = grid_to_particles(&table, &grid, &solution, &mut moved).unwrap_err();
        assert!(matches!(
            err,
            TransferError::Grid(GridError::OutsideGrid {
                particle: 7,
                locus: Locus::Corner(2),
                ..
            })
        ));
        assert_eq!(moved, before);
        let mut state = GridState::new();
        let mut fewer = ps.clone();
        fewer.x.pop();
        assert!(matches!(
            particles_to_grid(&table, &fewer, &grid, 0.0, &mut state),
            Err(TransferError::SizeMismatch { .. })
        ));
    }

    /// A 3 x 2 x 2 mm block of 2 x 2 x 2 points per 0.5 mm cell in a 3D grid with 3 cells of margin,
    /// with randomised masses, velocities, accelerations and positions.
    fn setup_3d(rng: &mut StdRng) -> (Grid<3>, Particles<3>) {
        let block = crate::solids::Solids {
            include: vec![crate::solids::Solid::Box {
                min: [1.0, 2.0, 0.0],
                max: [4.0, 4.0, 2.0],
            }],
            exclude: vec![],
        };
        let (grid, mut ps) = seed_block(&block, 3);
        for p in 0..ps.len() {
            ps.mass[p] *= rng.random_range(0.5..2.0);
            ps.v[p] = SVector::from_fn(|_, _| rng.random_range(-1e3..1e3));
            ps.a[p] = SVector::from_fn(|_, _| rng.random_range(-1e8..1e8));
        }
        (grid, ps)
    }

    #[test]
    fn transfer_3d_p2g_conserves_mass_and_momentum_and_g2p_moves_rigidly_exactly() {
        let mut rng = StdRng::seed_from_u64(9);
        let (grid, ps0) = setup_3d(&mut rng);
        let (mut table, mut state) = (ShapeTable::new(), GridState::new());
        let rot = *nalgebra::Rotation3::from_euler_angles(0.2, -0.3, 0.25).matrix();
        let (x0, d) = (
            SVector::from([2.0, 3.0, 1.0]),
            SVector::from([0.05, -0.02, 0.03]),
        );
        let du = linear_increment(&grid, rot, x0, d);
        let zero = vec![SVector::zeros(); grid.num_nodes()];
        let solution = solution(&du, &zero);
        for kind in ShapeKind::ALL {
            table.compute(kind, &grid, &ps0).unwrap();
            particles_to_grid(&table, &ps0, &grid, 0.0, &mut state).unwrap();
            check_conservation(&grid, &ps0, &state, kind);
            let mut ps = ps0.clone();
            grid_to_particles(&table, &grid, &solution, &mut ps).unwrap();
            check_rigid_motion(&ps0, &ps, rot, x0, d, kind);
        }
    }
}
