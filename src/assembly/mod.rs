//! Residual and consistent Jacobian of one implicit step from per-particle contributions (spec Sec. 1
//! step 5-6 and Sec. 4): the residual summed point by point, one chunk of points per worker, with the
//! nodes where chunks meet gathered node by node; the Jacobian filled row by row (`jacobian.rs`).
//!
//! Unknowns per active node `I`: `du_I` (mm) and, for gradient-enhanced runs, `eta_bar_I` (-). With the
//! start-of-step gradients `g_I = grad_{X_n} S_Ip`, `G_I = F_n^T g_I` (the gradient w.r.t. the initial
//! configuration), `F = (I + sum_J du_J (x) g_J) F_n` (in 2D plane strain, F33 = 1) and the first Piola stress
//! `P(F, eta_bar_p)` of the constitutive law:
//!
//! ```text
//! R^u_I   = m_I a_I^{n+1} + sum_p V_p^0 P_p G_Ip - m_I b                  (N)
//! R^eb_I  = s_eb sum_p V_p^n [ S_Ip (eta_bar_p - eta_p) + c grad_{X_n} S_Ip . grad_{X_n} eta_bar_p ]
//! K^uu    = m_I/(beta dt^2) delta_IJ + sum_p V_p^0 G_Ip . A_p . G_Jp      (A = dP/dF: material + geometric)
//! K^u,eb  = sum_p V_p^0 (dP/d eta_bar . G_Ip) S_Jp
//! K^eb,u  = -s_eb sum_p V_p^n (S_Ip - dc/d eta g_Ip . grad eta_bar_p) (d eta/dF F_n^T) g_Jp
//! K^eb,eb = s_eb sum_p V_p^n (S_Ip S_Jp + c g_Ip . g_Jp + dc/d eta_bar (g_Ip . grad eta_bar_p) S_Jp)
//! ```
//!
//! `c = c_p` is the gradient activity of the point at the iterate (constant `c_0` in the paper; evolving
//! with `eta` or `eta_bar` for the forms of [`crate::material::activity`], whence the `dc/d` terms).
//!
//! `sum_p V^0 P G_I` equals `sum_p v_p sigma_p grad_x S_Ip` of the spec (with `v_p = det F V^0`), and its
//! derivative through `A` contains both the material and the geometric stiffness with gradients on the
//! current iterate, so Newton converges quadratically at finite strain. The Helmholtz terms are evaluated
//! on the configuration at `t_n` (the spec's \[choice\]; `K^eb,eb` is constant within a step); `s_eb`
//! scales those rows to the magnitude of the momentum rows.
//!
//! Assembly is a gather: every active node sums over the particles in its support (the node-to-particle
//! incidence is built once per step), so rows are filled in parallel without races or atomics and
//! results do not depend on the number of threads. The block sparsity pattern (the union of the supports
//! of the particles around each node) is built once per step and reused by every Newton iteration.
//!
//! Everything is generic over the space dimension `D` (2 or 3: `D` displacement unknowns per node, plus
//! `eta_bar`); the constitutive law always sees the 3 x 3 `F` ([`lift3`] in 2D) and the assembly takes the
//! `D x D` blocks of its stress and tangent.

use crate::dofs::{DofMap, FieldLayout};
use crate::material::{Constitutive, Material, MaterialError, PointUpdate, Response};
use crate::particles::Particles;
use crate::petsc::{BlockCsr, BlockLayout};
use crate::shape::ShapeTable;
use crate::space::{det, lift3};
use nalgebra::{Matrix3, SMatrix, SVector};
use rayon::prelude::*;

mod energy;
mod jacobian;
use jacobian::{AssemblerView, JacobianRows, fill_rows};

/// Newmark parameters of the dynamic step; `None` in [`StepInput::newmark`] means quasi-static.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Newmark {
    /// Newmark beta (> 0).
    pub beta: f64,
    /// Newmark gamma.
    pub gamma: f64,
    /// Time step (s).
    pub dt: f64,
}

impl Newmark {
    /// `a^{n+1} = du/(beta dt^2) - v/(beta dt) - (1/(2 beta) - 1) a` (mm/s^2).
    pub fn acceleration<const D: usize>(
        &self,
        du: SVector<f64, D>,
        v: SVector<f64, D>,
        a: SVector<f64, D>,
    ) -> SVector<f64, D> {
        let (b, dt) = (self.beta, self.dt);
        du / (b * dt * dt) - v / (b * dt) - (0.5 / b - 1.0) * a
    }

    /// `d a^{n+1} / d du = 1/(beta dt^2)` (1/s^2).
    pub fn mass_factor(&self) -> f64 {
        1.0 / (self.beta * self.dt * self.dt)
    }
}

/// What the residual and Jacobian of a step read (all fixed during the Newton iterations).
pub struct StepInput<'a, const D: usize = 2> {
    /// Start-of-step shape functions of the deformable particles.
    pub table: &'a ShapeTable<D>,
    /// Committed particle state at `t_n`.
    pub particles: &'a Particles<D>,
    /// Constitutive law per body tag (`particles.body[p]` indexes this slice).
    pub materials: &'a [Material],
    /// Unknown numbering and constraints.
    pub dofs: &'a DofMap,
    /// Nodal mass `m_I` (t), velocity `v_I` (mm/s), acceleration `a_I` (mm/s^2) from P2G, per grid node.
    pub mass: &'a [f64],
    /// Nodal velocity (mm/s).
    pub velocity: &'a [SVector<f64, D>],
    /// Nodal acceleration (mm/s^2).
    pub acceleration: &'a [SVector<f64, D>],
    /// Newmark parameters, or `None` for a quasi-static step.
    pub newmark: Option<Newmark>,
    /// Body force per unit mass `b` (mm/s^2), e.g. gravity times the load factor.
    pub body_force: SVector<f64, D>,
    /// External nodal forces (N; in 2D per mm thickness), one per grid node, or empty for none.
    pub nodal_force: &'a [SVector<f64, D>],
    /// Scale of constrained rows and of the Helmholtz rows (MPa), about the stiffness of the body.
    pub row_scale: f64,
    /// Per node copy, the copy of another velocity field it is paired with in contact between bodies
    /// ([`INACTIVE`](crate::dofs::INACTIVE): none); the block rows of a pair get the union of their
    /// columns, so that contact rows can combine them. Empty: no pairs.
    pub partners: &'a [u32],
}

/// A failed evaluation at a Newton iterate (reported to SNES as a domain error).
#[derive(Debug, thiserror::Error)]
pub enum AssemblyError {
    /// The deformation gradient of a particle is not invertible or inverted.
    #[error("particle {particle}: det F = {det:e} <= 0 (element inversion)")]
    Inverted {
        /// Particle index.
        particle: usize,
        /// det F.
        det: f64,
    },
    /// The constitutive law rejected the state.
    #[error("particle {particle}: {source}")]
    Material {
        /// Particle index.
        particle: usize,
        /// The material's error.
        source: MaterialError,
    },
    /// A residual entry is not finite.
    #[error("non-finite residual at unknown {dof}")]
    NonFinite {
        /// Unknown index.
        dof: usize,
    },
}

/// Block columns of one Jacobian row at most: the fill keeps a column's position in a `u16`.
const MAX_COLUMNS: usize = u16::MAX as usize;

/// Grid nodes per run of [`Assembler::incidence`]'s parallel copy.
const INCIDENCE_RUN: usize = 1024;

/// Cached constitutive evaluation of one particle at the current iterate.
#[derive(Debug, Clone, Copy)]
struct PointEval<const D: usize> {
    /// First Piola stress (MPa), 3 x 3.
    p: Matrix3<f64>,
    /// The `D`-dimensional part of `A_iJkL = dP_iJ/dF_kL` (MPa): `a[i][k][(J, L)]`.
    a: [[SMatrix<f64, D, D>; D]; D],
    /// `D x D` block of `dP/d eta_bar` (MPa).
    dp_deb: SMatrix<f64, D, D>,
    /// `D x D` block of `d eta/dF F_n^T` (for the Helmholtz-displacement coupling).
    deta_dx: SMatrix<f64, D, D>,
    /// Local equivalent strain eta_p.
    eta: f64,
    /// Interpolated eta_bar_p and its gradient w.r.t. X_n.
    eta_bar: f64,
    grad_eta_bar: SVector<f64, D>,
    /// Stored energy density (MPa) and damage of the iterate.
    energy: f64,
    damage: f64,
    /// det F.
    det: f64,
    /// Dissipation density of the step under tensile / compressive plane strain (MPa).
    dissipation: [f64; 2],
    /// Dissipation density of the step by the trapezoidal rule in `psi_0` (MPa).
    dissipation_trapezoidal: f64,
    /// Gradient activity `c_p` (mm^2) and its derivatives `dc/d eta`, `dc/d eta_bar` at the iterate.
    c: f64,
    dc_deta: f64,
    dc_deb: f64,
    /// An eroded point (a void): only the lumped anchor of `eta_bar` (target `eta`) in the Helmholtz rows.
    eroded: bool,
}

impl<const D: usize> Default for PointEval<D> {
    fn default() -> Self {
        Self {
            p: Matrix3::zeros(),
            a: [[SMatrix::zeros(); D]; D],
            dp_deb: SMatrix::zeros(),
            deta_dx: SMatrix::zeros(),
            eta: 0.0,
            eta_bar: 0.0,
            grad_eta_bar: SVector::zeros(),
            energy: 0.0,
            damage: 0.0,
            det: 1.0,
            dissipation: [0.0; 2],
            dissipation_trapezoidal: 0.0,
            c: 0.0,
            dc_deta: 0.0,
            dc_deb: 0.0,
            eroded: false,
        }
    }
}

/// Energies of a committed step over a process's own points (N mm; in 2D per mm thickness).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Committed {
    /// Stored energy `sum_p V^0 Psi_p` at the end of the step.
    pub stored: f64,
    /// Energy released by damage in the step, `sum_p V^0` times the trapezoidal dissipation density
    /// ([`crate::material::Response::dissipation_trapezoidal`]).
    pub dissipated: f64,
    /// Stored energy of the points that reached their material's `erosion_damage` in this step: they
    /// carry no stress from the next step on, so the next step's stored energy lacks it.
    pub eroding: f64,
}

/// Per-step workspace of the assembly: incidence, pattern, cached particle evaluations, trial history.
/// Buffers are reused from step to step; nothing is allocated per Newton iteration.
pub struct Assembler<const D: usize = 2> {
    layout: FieldLayout,
    /// Node -> (particle, slot in its weight list), CSR over grid nodes.
    inc_offsets: Vec<usize>,
    inc_entries: Vec<(u32, u8)>,
    /// Block pattern: for active node a, its column active nodes `cols[row_ptr[a]..row_ptr[a+1]]` (sorted).
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    /// `G = F_n^T g` per table slot.
    g0: Vec<SVector<f64, D>>,
    /// Nodal unknowns of the current iterate, per grid node.
    du: Vec<SVector<f64, D>>,
    eb: Vec<f64>,
    evals: Vec<PointEval<D>>,
    trial_history: Vec<f64>,
    /// The iterate the cache was computed at.
    key: Vec<f64>,
    key_valid: bool,
    /// The cache holds every point (false: only those of `owned_points`).
    key_all: bool,
    /// Per point, whether it supports a block row this process owns ([`Assembler::restrict_to_rows`]);
    /// empty: every point.
    owned_points: Vec<bool>,
    /// The points cut into contiguous chunks, one per worker: each chunk's incidence (merged into the
    /// one above) and the residual's point-wise sums.
    scatter: Vec<ScatterChunk<D>>,
    /// Per grid node, the chunk all of whose points reach it, or [`SEAM`] (points of several chunks, or
    /// none): the residual sums a chunk's nodes point by point and gathers the seams node by node.
    node_chunk: Vec<u32>,
}

/// [`Assembler::node_chunk`] of a node reached by the points of several chunks, or by none.
const SEAM: u32 = u32::MAX;

/// A contiguous range of points, their incidence over the nodes they reach and the internal-force sums
/// they alone make on their nodes.
#[derive(Default)]
struct ScatterChunk<const D: usize> {
    points: std::ops::Range<usize>,
    /// First grid node the chunk's points reach; the sums below are indexed from it.
    first_node: usize,
    /// `sum_p V_p^0 P_p G_Ip` (N) per node from `first_node`.
    force: Vec<SVector<f64, D>>,
    /// The Helmholtz rows' point sums per node from `first_node`.
    helmholtz: Vec<f64>,
    /// The chunk's own incidence, CSR per node from `first_node`: the (point, slot) entries of its
    /// points, in increasing point order.
    inc_offsets: Vec<usize>,
    inc_entries: Vec<(u32, u8)>,
}

impl<const D: usize> ScatterChunk<D> {
    /// The chunk's incidence over its nodes by a counting sort of its points' supports in `table`.
    fn count_incidence(&mut self, table: &ShapeTable<D>) {
        let (first, span) = (self.first_node, self.force.len());
        self.inc_offsets.clear();
        self.inc_offsets.resize(span + 1, 0);
        for p in self.points.clone() {
            for w in table.weights(p) {
                self.inc_offsets[w.node as usize - first + 1] += 1;
            }
        }
        for i in 0..span {
            self.inc_offsets[i + 1] += self.inc_offsets[i];
        }
        self.inc_entries.clear();
        self.inc_entries.resize(self.inc_offsets[span], (0, 0));
        let mut fill = self.inc_offsets[..span].to_vec();
        for p in self.points.clone() {
            for (k, w) in table.weights(p).iter().enumerate() {
                let slot = &mut fill[w.node as usize - first];
                self.inc_entries[*slot] = (p as u32, k as u8);
                *slot += 1;
            }
        }
    }

    /// The chunk's entries on grid node `n` (none outside its span).
    fn entries_of(&self, n: usize) -> &[(u32, u8)] {
        match n.checked_sub(self.first_node) {
            Some(i) if i < self.force.len() => {
                &self.inc_entries[self.inc_offsets[i]..self.inc_offsets[i + 1]]
            }
            _ => &[],
        }
    }
}

impl<const D: usize> Default for Assembler<D> {
    fn default() -> Self {
        Self {
            layout: FieldLayout::default(),
            inc_offsets: Vec::new(),
            inc_entries: Vec::new(),
            row_ptr: Vec::new(),
            cols: Vec::new(),
            g0: Vec::new(),
            du: Vec::new(),
            eb: Vec::new(),
            evals: Vec::new(),
            trial_history: Vec::new(),
            key: Vec::new(),
            key_valid: false,
            key_all: false,
            owned_points: Vec::new(),
            scatter: Vec::new(),
            node_chunk: Vec::new(),
        }
    }
}

impl<const D: usize> Assembler<D> {
    /// An empty workspace.
    pub fn new() -> Self {
        Self::default()
    }

    /// Prepares a step: incidence, block pattern, `G = F_n^T g`. Call after the shape table and the
    /// unknown numbering of the step are known.
    pub fn begin_step(&mut self, input: &StepInput<'_, D>) {
        assert_eq!(
            input.dofs.layout().dim(),
            D,
            "the unknowns' layout has the assembly's dimension"
        );
        let (table, particles, dofs) = (input.table, input.particles, input.dofs);
        self.layout = dofs.layout();
        let nodes = dofs.node_indices().len();
        let np = particles.len();
        self.point_chunks(table, np);
        self.incidence(nodes);
        self.block_pattern_of_step(input);
        let stride = table.stride();
        // G = F_n^T g per slot.
        self.g0.resize(np * stride, SVector::zeros());
        self.g0
            .par_chunks_mut(stride.max(1))
            .enumerate()
            .for_each(|(p, g)| {
                let fnt = particles.f[p].transpose();
                for (k, w) in table.weights(p).iter().enumerate() {
                    g[k] = fnt * w.grad;
                }
            });
        self.evals.resize(np, PointEval::default());
        let hs = particles.history_stride();
        // One slot per particle even for history-free laws, so the parallel zip stays aligned.
        self.trial_history.resize(np * hs.max(1), 0.0);
        self.du.resize(nodes, SVector::zeros());
        self.eb.resize(nodes, 0.0);
        self.key_valid = false;
        self.owned_points.clear();
    }

    /// Cuts the `np` points into one contiguous chunk per worker, each with the span of grid nodes its
    /// points reach and its own incidence over them ([`ScatterChunk::count_incidence`]), in parallel.
    fn point_chunks(&mut self, table: &ShapeTable<D>, np: usize) {
        let chunks = rayon::current_num_threads().clamp(1, np.max(1));
        self.scatter.resize_with(chunks, ScatterChunk::default);
        self.scatter
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, chunk)| {
                chunk.points = c * np / chunks..(c + 1) * np / chunks;
                let reached = chunk
                    .points
                    .clone()
                    .flat_map(|p| table.weights(p).iter().map(|w| w.node as usize));
                let (lo, hi) =
                    reached.fold((usize::MAX, 0), |(lo, hi), n| (lo.min(n), hi.max(n + 1)));
                chunk.first_node = lo.min(hi);
                chunk.force.resize(hi.saturating_sub(lo), SVector::zeros());
                chunk.helmholtz.resize(hi.saturating_sub(lo), 0.0);
                chunk.count_incidence(table);
            });
    }

    /// The incidence node -> (point, slot in the point's weights) over `nodes` grid nodes: each node's
    /// entries from the chunks' own incidences, chunk after chunk, so in increasing point order (what a
    /// counting sort over all points gives); runs of nodes are copied in parallel. With it each node's
    /// chunk: the one chunk whose points reach it, or [`SEAM`].
    fn incidence(&mut self, nodes: usize) {
        let chunks = &self.scatter;
        self.inc_offsets.clear();
        self.inc_offsets.push(0);
        self.node_chunk.clear();
        let mut total = 0;
        for n in 0..nodes {
            // No chunk reaching the node stays a seam, as do two or more.
            let (mut chunk, mut reaching) = (SEAM, 0);
            for (c, entries) in chunks.iter().map(|c| c.entries_of(n).len()).enumerate() {
                if entries > 0 {
                    (chunk, reaching) = (c as u32, reaching + 1);
                    total += entries;
                }
            }
            self.inc_offsets.push(total);
            self.node_chunk
                .push(if reaching == 1 { chunk } else { SEAM });
        }
        self.inc_entries.clear();
        self.inc_entries.resize(total, (0, 0));
        let mut runs = Vec::new();
        let mut rest = self.inc_entries.as_mut_slice();
        for first in (0..nodes).step_by(INCIDENCE_RUN) {
            let last = (first + INCIDENCE_RUN).min(nodes);
            let len = self.inc_offsets[last] - self.inc_offsets[first];
            let (run, tail) = std::mem::take(&mut rest).split_at_mut(len);
            runs.push((first..last, run));
            rest = tail;
        }
        runs.into_par_iter().for_each(|(nodes, out)| {
            let mut at = 0;
            for n in nodes {
                for chunk in chunks {
                    let entries = chunk.entries_of(n);
                    out[at..at + entries.len()].copy_from_slice(entries);
                    at += entries.len();
                }
            }
        });
    }

    /// The block pattern of the step: row pointers and block columns per active node, the sorted union
    /// of the supports of the node's points (and of its contact partner's); from [`Self::incidence`].
    fn block_pattern_of_step(&mut self, input: &StepInput<'_, D>) {
        let (table, dofs) = (input.table, input.dofs);
        let node_index = dofs.node_indices();
        let grid_nodes = node_index.len();
        // Per worker: a stamp per grid node (the row that last saw it) and the row's distinct support
        // nodes; no sorting of the ~300 raw entries of a row, no searching.
        let marker = || (vec![0u32; grid_nodes], Vec::new());
        let (inc_entries, inc_offsets) = (&self.inc_entries, &self.inc_offsets);
        let rows: Vec<Vec<u32>> = dofs
            .active_nodes()
            .par_iter()
            .enumerate()
            .map_init(
                marker,
                |(stamp, unique): &mut (Vec<u32>, Vec<u32>), (a, &node)| {
                    let row = a as u32 + 1;
                    unique.clear();
                    let entries =
                        &inc_entries[inc_offsets[node as usize]..inc_offsets[node as usize + 1]];
                    // A contact pair's rows share the union of their columns.
                    let partner = match input.partners.get(node as usize) {
                        Some(&q) if q != crate::dofs::INACTIVE => {
                            &inc_entries[inc_offsets[q as usize]..inc_offsets[q as usize + 1]]
                        }
                        _ => &[],
                    };
                    for &(p, _) in entries.iter().chain(partner) {
                        for w in table.weights(p as usize) {
                            let g = w.node as usize;
                            if node_index[g] != crate::dofs::INACTIVE && stamp[g] != row {
                                stamp[g] = row;
                                unique.push(w.node);
                            }
                        }
                    }
                    // Active indices increase with the grid index: sorting grid nodes sorts the columns.
                    unique.sort_unstable();
                    unique.iter().map(|&g| node_index[g as usize]).collect()
                },
            )
            .collect();
        self.row_ptr.clear();
        self.row_ptr.push(0);
        self.cols.clear();
        for r in &rows {
            assert!(
                r.len() <= MAX_COLUMNS,
                "a Jacobian row with {} block columns",
                r.len()
            );
            self.cols.extend_from_slice(r);
            self.row_ptr.push(self.cols.len());
        }
    }

    /// Restricts [`Assembler::evaluate_owned`] to the points in the support of the block rows `rows`
    /// (active nodes) until the next [`Assembler::begin_step`]: what a process needs for its own rows of
    /// the residual and the Jacobian. All rows: no restriction.
    pub fn restrict_to_rows(&mut self, input: &StepInput<'_, D>, rows: std::ops::Range<usize>) {
        self.owned_points.clear();
        self.key_valid = false;
        if rows.len() == self.row_ptr.len() - 1 {
            return;
        }
        self.owned_points.resize(input.particles.len(), false);
        for a in rows {
            let node = input.dofs.node(a);
            for &(p, _) in &self.inc_entries[self.inc_offsets[node]..self.inc_offsets[node + 1]] {
                self.owned_points[p as usize] = true;
            }
        }
    }

    /// Number of nonzero entries of the Jacobian (blocks times fields^2).
    pub fn nonzeros(&self) -> usize {
        self.cols.len() * self.layout.per_node() * self.layout.per_node()
    }

    /// The block pattern of the whole Jacobian (block rows and block columns = active nodes in
    /// [`DofMap`] order): the layout of [`Assembler::jacobian_into`] over all rows.
    pub fn block_pattern(&self) -> BlockCsr<'_> {
        BlockCsr {
            first: 0,
            bs: self.layout.per_node(),
            row_ptr: &self.row_ptr,
            cols: &self.cols,
        }
    }

    /// The block rows `rows` of the pattern as a process's own pattern ([`BlockCsr::first`] =
    /// `rows.start`, row pointers from 0, global block columns), copied into `row_ptr` and `cols`.
    pub fn block_rows_pattern(
        &self,
        rows: std::ops::Range<usize>,
        row_ptr: &mut Vec<usize>,
        cols: &mut Vec<u32>,
    ) {
        let base = self.row_ptr[rows.start];
        row_ptr.clear();
        row_ptr.extend(self.row_ptr[rows.start..=rows.end].iter().map(|r| r - base));
        cols.clear();
        cols.extend_from_slice(&self.cols[base..self.row_ptr[rows.end]]);
    }

    /// The pattern as (row, column) pairs in the order of [`Assembler::jacobian_into`]'s values (for
    /// tests and dense checks).
    pub fn pattern(&self) -> (Vec<usize>, Vec<usize>) {
        let nf = self.layout.per_node();
        let n = self.nonzeros();
        let (mut rows, mut cols) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for a in 0..self.row_ptr.len() - 1 {
            let bc = &self.cols[self.row_ptr[a]..self.row_ptr[a + 1]];
            for i in 0..nf {
                for &b in bc {
                    for k in 0..nf {
                        rows.push(a * nf + i);
                        cols.push(b as usize * nf + k);
                    }
                }
            }
        }
        (rows, cols)
    }

    /// Evaluates every particle at the iterate `x` (unknowns in [`DofMap`] order) unless the cache
    /// already holds `x`. Trial history is written to the workspace, never to the particles.
    pub fn evaluate(&mut self, input: &StepInput<'_, D>, x: &[f64]) -> Result<(), AssemblyError> {
        self.evaluate_points(input, x, true)
    }

    /// As [`Assembler::evaluate`] for the points of this process's rows only
    /// ([`Assembler::restrict_to_rows`]; all points without a restriction): enough for those rows of the
    /// residual and the Jacobian. The other points keep stale values until the next full evaluation.
    pub fn evaluate_owned(
        &mut self,
        input: &StepInput<'_, D>,
        x: &[f64],
    ) -> Result<(), AssemblyError> {
        self.evaluate_points(input, x, false)
    }

    fn evaluate_points(
        &mut self,
        input: &StepInput<'_, D>,
        x: &[f64],
        all: bool,
    ) -> Result<(), AssemblyError> {
        if self.key_valid && (self.key_all || !all) && self.key.as_slice() == x {
            return Ok(());
        }
        self.key_valid = false;
        let mask: &[bool] = if all { &[] } else { &self.owned_points };
        let nf = self.layout.per_node();
        let dofs = input.dofs;
        // Scatter the unknowns to grid nodes (inactive nodes stay zero).
        self.du.iter_mut().for_each(|d| *d = SVector::zeros());
        self.eb.iter_mut().for_each(|e| *e = 0.0);
        for (a, &node) in dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            self.du[node] = SVector::from_column_slice(&x[a * nf..a * nf + D]);
            if let Some(e) = self.layout.eta_bar() {
                self.eb[node] = x[a * nf + e];
            }
        }
        let (du, eb) = (&self.du, &self.eb);
        let hs = input.particles.history_stride();
        let nonlocal = self.layout.eta_bar().is_some();
        self.evals
            .par_iter_mut()
            .zip(self.trial_history.par_chunks_mut(hs.max(1)))
            .enumerate()
            .try_for_each(|(p, (ev, h_trial))| {
                if mask.get(p) == Some(&false) {
                    return Ok(());
                }
                *ev = evaluate_point(input, du, eb, nonlocal, p, h_trial)?;
                Ok(())
            })?;
        self.key.clear();
        self.key.extend_from_slice(x);
        self.key_valid = true;
        self.key_all = all || self.owned_points.is_empty();
        Ok(())
    }

    /// Writes the residual at the last evaluated iterate `x` into `out` (same layout). With
    /// `physical = true`, constrained rows hold the unbalanced force instead of `s (x - prescribed)`:
    /// the reaction the constraint exerts (N).
    pub fn residual(
        &mut self,
        input: &StepInput<'_, D>,
        x: &[f64],
        out: &mut [f64],
        physical: bool,
    ) -> Result<(), AssemblyError> {
        let rows = 0..self.row_ptr.len() - 1;
        self.residual_rows(input, x, out, physical, rows)
    }

    /// As [`Assembler::residual`] for the block rows `rows` only (the others are set to zero): after
    /// [`Assembler::evaluate_owned`] with these rows.
    pub fn residual_rows(
        &mut self,
        input: &StepInput<'_, D>,
        x: &[f64],
        out: &mut [f64],
        physical: bool,
        rows: std::ops::Range<usize>,
    ) -> Result<(), AssemblyError> {
        let nf = self.layout.per_node();
        let nonlocal = self.layout.eta_bar().is_some();
        let (table, particles, dofs) = (input.table, input.particles, input.dofs);
        let stride = table.stride();
        let s = input.row_scale;
        let (evals, g0, eb, node_chunk) = (&self.evals, &self.g0, &self.eb, &self.node_chunk);
        // The terms of point p through its support slot k on node `node`: `V_p^0 P_p G_Ip` (N) and the
        // Helmholtz row's `V_p (S_Ip (eta_bar_p - eta_p) + c_p grad S_Ip . grad eta_bar_p)`.
        let terms = |p: usize, k: usize, node: usize| {
            let ev = &evals[p];
            let pp = ev.p.fixed_view::<D, D>(0, 0);
            let force = particles.vol0[p] * (pp * g0[p * stride + k]);
            if !nonlocal {
                return (force, 0.0);
            }
            let w = &table.weights(p)[k];
            let helmholtz = particles.vol[p]
                * if ev.eroded {
                    // Lumped: S_Ip (eta_bar_I - eta_bar_p^n), a positive diagonal wherever eroded
                    // points touch a node. The consistent `S_Ip (eta_bar_p - eta_bar_p^n)` is singular
                    // where fewer eroded points than nodes carry a patch of the grid (the paper-size CT
                    // at 4.3 m/s after 830 us).
                    w.value * (eb[node] - ev.eta)
                } else {
                    w.value * (ev.eta_bar - ev.eta) + ev.c * w.grad.dot(&ev.grad_eta_bar)
                };
            (force, helmholtz)
        };
        // Each chunk sums its points' terms on the nodes only its points reach, point after point: the
        // sums the node-by-node gather below would form, operation for operation, but reading every
        // point once and in order instead of once per node it reaches (the gather's scattered reads of
        // the points' records were 16-19 % of the CT's run).
        self.scatter
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, chunk)| {
                let lo = chunk.first_node;
                chunk.force.fill(SVector::zeros());
                chunk.helmholtz.fill(0.0);
                for p in chunk.points.clone() {
                    for (k, w) in table.weights(p).iter().enumerate() {
                        let node = w.node as usize;
                        if node_chunk[node] == c as u32 {
                            let (f, h) = terms(p, k, node);
                            chunk.force[node - lo] += f;
                            chunk.helmholtz[node - lo] += h;
                        }
                    }
                }
            });
        let scatter = &self.scatter;
        let (inc_entries, inc_offsets) = (&self.inc_entries, &self.inc_offsets);
        out.par_chunks_mut(nf).enumerate().for_each(|(a, r)| {
            if !rows.contains(&a) {
                r.fill(0.0);
                return;
            }
            let node = dofs.node(a);
            let (mut ru, reb) = match scatter.get(node_chunk[node] as usize) {
                Some(chunk) => (
                    chunk.force[node - chunk.first_node],
                    chunk.helmholtz[node - chunk.first_node],
                ),
                None => {
                    let mut sums = (SVector::<f64, D>::zeros(), 0.0);
                    for &(p, k) in &inc_entries[inc_offsets[node]..inc_offsets[node + 1]] {
                        let (f, h) = terms(p as usize, k as usize, node);
                        sums.0 += f;
                        sums.1 += h;
                    }
                    sums
                }
            };
            let m = input.mass[node];
            if let Some(nm) = input.newmark {
                let acc = nm.acceleration(
                    self.du[node],
                    input.velocity[node],
                    input.acceleration[node],
                );
                ru += m * acc;
            }
            ru -= m * input.body_force;
            if let Some(f) = input.nodal_force.get(node) {
                ru -= f;
            }
            r[..D].copy_from_slice(ru.as_slice());
            if let Some(e) = self.layout.eta_bar() {
                r[e] = s * reb;
            }
            if !physical {
                for (c, rc) in r.iter_mut().enumerate() {
                    if let Some(v) = dofs.prescribed(a * nf + c) {
                        *rc = s * (x[a * nf + c] - v);
                    }
                }
            }
        });
        match out.iter().position(|v| !v.is_finite()) {
            Some(dof) => Err(AssemblyError::NonFinite { dof }),
            None => Ok(()),
        }
    }

    /// Writes the block rows `rows` of the Jacobian at the last evaluated iterate into `values` (their
    /// nonzeros, ordered by `layout` as in [`Assembler::block_rows_pattern`]; all rows:
    /// [`Assembler::nonzeros`] values for [`Assembler::block_pattern`]), rows in parallel (rayon).
    pub fn jacobian_into(
        &self,
        input: &StepInput<'_, D>,
        rows: std::ops::Range<usize>,
        values: &mut [f64],
        layout: BlockLayout,
    ) {
        let nf = self.layout.per_node();
        let (lo, hi) = (self.row_ptr[rows.start], self.row_ptr[rows.end]);
        assert_eq!(
            values.len(),
            (hi - lo) * nf * nf,
            "Jacobian value array length"
        );
        let asm = AssemblerView {
            inc_offsets: &self.inc_offsets,
            inc_entries: &self.inc_entries,
            row_ptr: &self.row_ptr,
            cols: &self.cols,
            g0: &self.g0,
            evals: &self.evals,
        };
        let ctx = JacobianRows {
            asm,
            input,
            nf,
            layout,
        };
        fill_rows(&ctx, rows, values, lo * nf * nf, nf * nf);
    }

    /// Commits the converged step's constitutive state into the particles: trial history, Cauchy stress
    /// `sigma = P F^T / det F`, `eta_bar_p`, damage, the dissipation split and the damage gained while
    /// the local `eta < gamma_0` of the point's material. Returns the energies of the first `counted`
    /// points (a process's own; the rest are copies of other processes' points). `particles.f` must
    /// already hold the converged deformation gradients (after G2P).
    pub fn commit(
        &self,
        particles: &mut Particles<D>,
        materials: &[Material],
        counted: usize,
    ) -> Committed {
        let hs = particles.history_stride();
        if hs > 0 {
            let n = particles.len() * hs;
            particles.history.copy_from_slice(&self.trial_history[..n]);
        }
        let mut sums = Committed::default();
        for (p, ev) in self.evals.iter().enumerate() {
            let f3 = lift3(&particles.f[p]);
            particles.stress[p] = ev.p * f3.transpose() / ev.det;
            if !ev.eroded {
                // An eroded point keeps its anchor value.
                particles.eta_bar[p] = ev.eta_bar;
            }
            let material = &materials[particles.body[p] as usize];
            let gained = ev.damage - particles.damage[p];
            if gained > 0.0 && ev.eta < material.gamma_0() {
                particles.nonlocal_damage[p] += gained;
            }
            particles.damage[p] = ev.damage;
            // The split follows the planes' end-point shares, its total the trapezoidal rule of the books.
            let end_point = ev.dissipation[0] + ev.dissipation[1];
            let shares = match end_point > 0.0 {
                true => ev.dissipation.map(|d| d / end_point),
                false => [1.0, 0.0],
            };
            for (acc, share) in particles.dissipated[p].iter_mut().zip(shares) {
                *acc += particles.vol0[p] * share * ev.dissipation_trapezoidal;
            }
            if p < counted {
                let v0 = particles.vol0[p];
                sums.stored += v0 * ev.energy;
                sums.dissipated += v0 * ev.dissipation_trapezoidal;
                if !ev.eroded && material.is_eroded(ev.damage) {
                    sums.eroding += v0 * ev.energy;
                }
            }
        }
        sums
    }

    /// Nodal displacement increment of the last evaluated iterate, per grid node (mm).
    pub fn nodal_du(&self) -> &[SVector<f64, D>] {
        &self.du
    }
}

/// Kinematics and constitutive update of point `p` at the iterate scattered to the nodes (`du`: nodal
/// displacement increments (mm), `eb`: nodal `eta_bar`): `F = (I + grad du) F_n`, the law's `P`, `A` and
/// nonlocal terms; an eroded point keeps its history and carries no stress. Writes the trial history of
/// the point into `h_trial` (one history stride).
fn evaluate_point<const D: usize>(
    input: &StepInput<'_, D>,
    du: &[SVector<f64, D>],
    eb: &[f64],
    nonlocal: bool,
    p: usize,
    h_trial: &mut [f64],
) -> Result<PointEval<D>, AssemblyError> {
    let (table, particles, materials) = (input.table, input.particles, input.materials);
    let hs = particles.history_stride();
    let ws = table.weights(p);
    let mut grad_du = SMatrix::<f64, D, D>::zeros();
    let (mut ebp, mut geb) = (0.0, SVector::<f64, D>::zeros());
    for w in ws {
        let n = w.node as usize;
        grad_du += du[n] * w.grad.transpose();
        ebp += w.value * eb[n];
        geb += w.grad * eb[n];
    }
    let f_n = particles.f[p];
    let material = &materials[particles.body[p] as usize];
    if material.is_eroded(particles.damage[p]) {
        // A void that keeps its mass: no stress or stiffness, F frozen (the solver restores
        // it after G2P), and in the Helmholtz rows a lumped anchor of the nodal eta_bar to
        // `eta_bar_p^n` without diffusion, so the nonlocal field does not spread through the
        // crack (see `Assembler::residual`).
        h_trial[..hs].copy_from_slice(&particles.history(p)[..hs]);
        return Ok(PointEval {
            eta: if nonlocal { particles.eta_bar[p] } else { 0.0 },
            eta_bar: if nonlocal { ebp } else { 0.0 },
            grad_eta_bar: geb,
            damage: particles.damage[p],
            det: det(&f_n),
            eroded: true,
            ..PointEval::default()
        });
    }
    let f = (SMatrix::<f64, D, D>::identity() + grad_du) * f_n;
    let det = det(&f);
    if det.is_nan() || det <= 0.0 {
        return Err(AssemblyError::Inverted { particle: p, det });
    }
    let (f3, f3_n) = (lift3(&f), lift3(&f_n));
    // The point's own law's history: the stride is the longest of all bodies' laws.
    let hl = material.history_len();
    let h_n = &particles.history(p)[..hl];
    let h_trial = &mut h_trial[..hl];
    let mut r = Response::zeros();
    let err = |source| AssemblyError::Material {
        particle: p,
        source,
    };
    if nonlocal {
        material
            .update(
                PointUpdate::new(&f3, ebp, h_n, h_trial)
                    .with_start(&f3_n)
                    .in_plane(D == 2),
                &mut r,
            )
            .map_err(err)?;
    } else {
        local_update(material, (&f3, &f3_n), h_n, h_trial, D == 2, &mut r).map_err(err)?;
        ebp = r.eta;
    }
    Ok(PointEval {
        p: r.p,
        a: tangent_blocks(&r),
        dp_deb: r.dp_deta_bar.fixed_view::<D, D>(0, 0).into_owned(),
        deta_dx: r.deta_df.fixed_view::<D, D>(0, 0) * f_n.transpose(),
        eta: r.eta,
        eta_bar: ebp,
        grad_eta_bar: geb,
        energy: r.energy,
        damage: r.damage,
        det,
        dissipation: r.dissipation,
        dissipation_trapezoidal: r.dissipation_trapezoidal,
        c: r.activity.c,
        dc_deta: r.activity.dc_deta,
        dc_deb: r.activity.dc_deta_bar,
        eroded: false,
    })
}

/// The `D`-dimensional part of the tangent `A` (index `(3i+J, 3k+L)` of [`Response::a`]) as
/// `a[i][k][(J, L)]`.
fn tangent_blocks<const D: usize>(r: &Response) -> [[SMatrix<f64, D, D>; D]; D] {
    std::array::from_fn(|i| {
        std::array::from_fn(|k| SMatrix::from_fn(|j, l| r.a[(3 * i + j, 3 * k + l)]))
    })
}

/// The local model (`eta_bar = eta`, no Helmholtz field): evaluates the law with `eta_bar` set to its
/// own `eta` and completes the tangent with the chain rule `A + dP/d eta_bar (x) d eta/dF` (eta does not
/// depend on eta_bar). Elastic laws return zero for both, so this is exact for them too. `(F, F_n)`: the
/// deformation gradient and its value at the start of the step (for the trapezoidal dissipation);
/// `in_plane`: only the in-plane entries of `A` are needed ([`PointUpdate::in_plane`]).
pub fn local_update(
    material: &Material,
    (f, f_n): (&Matrix3<f64>, &Matrix3<f64>),
    h_n: &[f64],
    h_trial: &mut [f64],
    in_plane: bool,
    out: &mut Response,
) -> Result<(), MaterialError> {
    material.update(
        PointUpdate::new(f, 0.0, h_n, h_trial).in_plane(in_plane),
        out,
    )?;
    if out.dp_deta_bar.iter().all(|v| *v == 0.0) && out.eta == 0.0 {
        return Ok(());
    }
    let eta = out.eta;
    let update = PointUpdate::new(f, eta, h_n, h_trial).with_start(f_n);
    material.update(update.in_plane(in_plane), out)?;
    for ij in 0..9 {
        for kl in 0..9 {
            out.a[(ij, kl)] += out.dp_deta_bar[(ij / 3, ij % 3)] * out.deta_df[(kl / 3, kl % 3)];
        }
    }
    out.dp_deta_bar = Matrix3::zeros();
    Ok(())
}
