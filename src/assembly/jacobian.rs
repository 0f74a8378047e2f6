//! The Jacobian's block rows, filled in parallel from the points' cached tangents: for every row (node
//! `I`), the sum over the points `p` its shape functions reach of `V_p^0 G_Ip . A_p . G_Jp` on each
//! support node `J` of `p`, the nonlocal coupling terms, inertia and the constrained rows.

use super::{PointEval, StepInput};
use crate::petsc::BlockLayout;
use nalgebra::SVector;
use std::cell::RefCell;

thread_local! {
    /// Each worker's column positions and scratch for the row it fills ([`RowWorker`]).
    static WORKER: RefCell<RowWorker> = const {
        RefCell::new(RowWorker {
            columns: ColumnSlots::new(),
            scratch: Vec::new(),
        })
    };
}

/// What a worker keeps from row to row: the column positions and, for the [`BlockLayout::Rows`] order,
/// the row summed block by block before it is reordered.
struct RowWorker {
    columns: ColumnSlots,
    scratch: Vec<f64>,
}

/// Per worker, for every grid node: the tag of the last row that placed it among its columns and its
/// position in that row. A row takes a fresh tag, so a node no row has placed since reads as no column
/// (a node without unknowns) without clearing anything between rows.
struct ColumnSlots {
    /// `(tag, position)` per grid node.
    slots: Vec<(u32, u16)>,
    tag: u32,
}

impl ColumnSlots {
    const fn new() -> Self {
        Self {
            slots: Vec::new(),
            tag: 0,
        }
    }

    /// Places the grid nodes `row_nodes` (the row's columns, in order) at their positions under a
    /// fresh tag, which it returns; `grid_nodes` is the number of grid nodes.
    fn place(&mut self, grid_nodes: usize, row_nodes: impl Iterator<Item = usize>) -> u32 {
        if self.slots.len() < grid_nodes {
            self.slots.resize(grid_nodes, (0, 0));
        }
        self.tag = self.tag.wrapping_add(1);
        if self.tag == 0 {
            // After 2^32 rows the tags come round: forget every placement.
            self.slots.fill((0, 0));
            self.tag = 1;
        }
        for (c, g) in row_nodes.enumerate() {
            // At most `MAX_COLUMNS` columns (asserted with the pattern): positions fit a u16.
            debug_assert!(c < u16::MAX as usize, "column position {c}");
            self.slots[g] = (self.tag, c as u16);
        }
        self.tag
    }
}

/// Read-only view of the assembler used by the parallel row filling (the values are borrowed apart).
pub(super) struct AssemblerView<'a, const D: usize> {
    pub(super) inc_offsets: &'a [usize],
    pub(super) inc_entries: &'a [(u32, u8)],
    pub(super) row_ptr: &'a [usize],
    pub(super) cols: &'a [u32],
    pub(super) g0: &'a [SVector<f64, D>],
    pub(super) evals: &'a [PointEval<D>],
}

/// What the row filling reads: the assembler's arrays, the step's input and the value layout.
pub(super) struct JacobianRows<'a, const D: usize> {
    pub(super) asm: AssemblerView<'a, D>,
    pub(super) input: &'a StepInput<'a, D>,
    pub(super) nf: usize,
    pub(super) layout: BlockLayout,
}

/// Fills the block rows `rows` whose values start at `base` in the global value array, splitting the
/// range in two (rayon::join) until it is small: parallel and race-free because block rows own disjoint
/// value ranges; allocation-free once each worker's column slots and scratch have grown to the grid and
/// the widest row.
pub(super) fn fill_rows<const D: usize>(
    ctx: &JacobianRows<'_, D>,
    rows: std::ops::Range<usize>,
    values: &mut [f64],
    base: usize,
    bs2: usize,
) {
    if rows.len() <= 64 {
        for a in rows {
            let lo = ctx.asm.row_ptr[a] * bs2 - base;
            let hi = ctx.asm.row_ptr[a + 1] * bs2 - base;
            fill_row(ctx, a, &mut values[lo..hi]);
        }
        return;
    }
    let mid = rows.start + rows.len() / 2;
    let split = ctx.asm.row_ptr[mid] * bs2 - base;
    let (left, right) = values.split_at_mut(split);
    rayon::join(
        || fill_rows(ctx, rows.start..mid, left, base, bs2),
        || fill_rows(ctx, mid..rows.end, right, base + split, bs2),
    );
}

/// One block row of the Jacobian (active node `a`), ordered by the context's [`BlockLayout`]: the
/// kernel for the row's block size (`D` displacements, and `eta_bar` after them in the nonlocal model).
fn fill_row<const D: usize>(ctx: &JacobianRows<'_, D>, a: usize, row: &mut [f64]) {
    debug_assert!(
        ctx.nf == D || ctx.nf == D + 1,
        "{} unknowns per node",
        ctx.nf
    );
    WORKER.with_borrow_mut(|worker| match ctx.nf {
        2 => fill_row_with::<D, 2>(ctx, a, row, worker),
        3 => fill_row_with::<D, 3>(ctx, a, row, worker),
        4 => fill_row_with::<D, 4>(ctx, a, row, worker),
        nf => unreachable!("{nf} unknowns per node"),
    });
}

/// [`fill_row`] for `NF` unknowns per node with the worker's column positions and scratch. The row is
/// summed block by block, each block column-major (the [`BlockLayout::Blocks`] order: in place for
/// that layout, in the worker's scratch and then reordered for the other), so that a point's
/// contribution to one column node is a handful of adds at fixed places in one `NF x NF` block.
fn fill_row_with<const D: usize, const NF: usize>(
    ctx: &JacobianRows<'_, D>,
    a: usize,
    row: &mut [f64],
    worker: &mut RowWorker,
) {
    let (asm, input) = (&ctx.asm, ctx.input);
    let (table, particles, dofs) = (input.table, input.particles, input.dofs);
    let s = input.row_scale;
    let cols = &asm.cols[asm.row_ptr[a]..asm.row_ptr[a + 1]];
    // Each support node's position in this row, looked up by grid node: `slots[g]` under this row's tag.
    let grid = dofs.active_nodes();
    let RowWorker { columns, scratch } = worker;
    let tag = columns.place(
        dofs.node_indices().len(),
        cols.iter().map(|&c| grid[c as usize] as usize),
    );
    let slots = columns.slots.as_slice();
    let ncols = cols.len();
    let blocks: &mut [f64] = match ctx.layout {
        BlockLayout::Blocks => &mut *row,
        BlockLayout::Rows => {
            scratch.clear();
            scratch.resize(row.len(), 0.0);
            scratch.as_mut_slice()
        }
    };
    blocks.fill(0.0);
    // Entry (i, k) of the block at position `pos`: `blocks[pos * NF * NF + at(i, k)]`.
    let at = |i: usize, k: usize| k * NF + i;
    let bb = NF * NF;
    // `eta_bar` is the unknown after the displacements when the row has one more than `D`.
    let nonlocal = NF > D;
    let node = dofs.node(a);
    let first = asm.inc_offsets[node];
    let diag = cols.binary_search(&(a as u32)).ok();
    for &(p, k) in &asm.inc_entries[first..asm.inc_offsets[node + 1]] {
        let (p, k) = (p as usize, k as usize);
        let ev = &asm.evals[p];
        let ws = table.weights(p);
        if ev.eroded {
            // No stiffness; the lumped anchor of eta_bar on the diagonal (see `Assembler::residual`).
            if let (true, Some(d)) = (nonlocal, diag) {
                blocks[d * bb + at(D, D)] += s * particles.vol[p] * ws[k].value;
            }
            continue;
        }
        let stride = table.stride();
        let g0 = &asm.g0[p * stride..p * stride + ws.len()];
        let gi0 = g0[k];
        let (s_i, gi) = (ws[k].value, ws[k].grad);
        let v0 = particles.vol0[p];
        let vn = particles.vol[p];
        // M[i][k]_L = sum_J G_I,J A_iJkL
        let m: [[SVector<f64, D>; D]; D] =
            std::array::from_fn(|i| std::array::from_fn(|kk| ev.a[i][kk].tr_mul(&gi0)));
        // Factors of the nonlocal terms that do not depend on the column node (grouped as before:
        // `v0 q_i S_J` = `(v0 q_i) S_J`, `s vn (S_I - ..) h_i` = `(s vn (S_I - ..)) h_i`).
        let q = ev.dp_deb * gi0;
        let vq: [f64; D] = std::array::from_fn(|i| v0 * q[i]);
        // Evolving activity: d(c grad S_I . grad eta_bar)/d(unknowns) through c(eta, eta_bar).
        let flux = gi.dot(&ev.grad_eta_bar);
        let (c, dc_deta, dc_deb) = (ev.c, ev.dc_deta * flux, ev.dc_deb * flux);
        let svn = s * vn;
        let coupling = svn * (s_i - dc_deta);
        for (wj, gj0) in ws.iter().zip(g0) {
            let (t, pos) = slots[wj.node as usize];
            if t != tag {
                continue; // a node without unknowns
            }
            let block = &mut blocks[pos as usize * bb..][..bb];
            for kk in 0..D {
                for (i, mi) in m.iter().enumerate() {
                    block[at(i, kk)] += v0 * mi[kk].dot(gj0);
                }
            }
            if nonlocal {
                let (sj, gj) = (wj.value, wj.grad);
                let h = ev.deta_dx * gj;
                for i in 0..D {
                    block[at(i, D)] += vq[i] * sj;
                    block[at(D, i)] -= coupling * h[i];
                }
                block[at(D, D)] += svn * (s_i * sj + c * gi.dot(&gj) + dc_deb * sj);
            }
        }
    }
    // Inertia on the diagonal block, then constraints: identity rows. The columns of constrained unknowns
    // are kept: they are the exact derivative of the free rows, so a Newton step from a guess that does
    // not yet satisfy the constraints carries the prescribed motion into the interior (linear predictor).
    if let (Some(nm), Some(d)) = (input.newmark, diag) {
        let mf = input.mass[node] * nm.mass_factor();
        for i in 0..D {
            blocks[d * bb + at(i, i)] += mf;
        }
    }
    for i in 0..NF {
        if dofs.is_constrained(a * NF + i) {
            for column in blocks.chunks_exact_mut(NF) {
                column[i] = 0.0;
            }
            if let Some(d) = diag {
                blocks[d * bb + at(i, i)] = s;
            }
        }
    }
    if ctx.layout == BlockLayout::Rows {
        for (b, column) in scratch.chunks_exact(NF).enumerate() {
            let (pos, k) = (b / NF, b % NF);
            for (i, &v) in column.iter().enumerate() {
                row[ctx.layout.offset(ncols, NF, i, pos, k)] = v;
            }
        }
    }
}
