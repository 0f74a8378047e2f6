//! ILU(0) of a block matrix on overlapping subdomains, one per thread: the restricted additive Schwarz
//! preconditioner that GMRES uses on one process with several threads (`petsc::use_threaded_ilu`).
//!
//! The block rows (grid nodes in [`crate::dofs::DofMap`] order, i.e. row by row of the background grid)
//! are cut into `parts` contiguous ranges of about equal nonzeros. Each part is widened to the
//! contiguous range of all block columns its rows touch (one layer of overlap in the graph of the
//! matrix, about two rows of grid nodes on either side of a cut), and the matrix restricted to that range
//! is factored by ILU(0), the block incomplete LU on the matrix's own pattern, as PETSc's
//! `MatLUFactorNumeric_SeqBAIJ_N` does it (row by row, `L_ik = A_ik U_kk^-1`, the diagonal blocks stored
//! inverted). The preconditioner applies every part's `(L U)^-1` to its widened range of the vector and
//! keeps the result on its own rows only ("restricted"): with one part it is the ILU(0) of the whole
//! matrix. The parts are factored and applied in parallel (rayon), so the factorisation and the
//! triangular solves, which PETSc runs on one core, use all threads; the overlap keeps GMRES's
//! iterations those of the whole matrix's ILU(0) (PETSc's additive Schwarz with the same overlap on two
//! and four processes: `src/solver_defaults.rs`, `INERTIA_PROCESSES`).
//!
//! Values are PETSc's block (BAIJ) storage, one `bs x bs` block per pattern entry, each stored column by
//! column (entry `(i, k)` of a block at `k bs + i`), factored on the node blocks ([`SchwarzIlu::blocks`]);
//! or PETSc's point-wise (AIJ) storage of the same pattern, factored on single unknowns with PETSc's
//! restarted diagonal shift ([`SchwarzIlu::points`], the storage of turned set-ups, whose slivers of
//! support make small pivots).

use rayon::prelude::*;
use thiserror::Error;

/// PETSc's shift amount and zero-pivot tolerance of `-sub_pc_factor_shift_type nonzero` (100 times the
/// machine epsilon): the pivot put in place of an exactly zero pivot of a diagonal block (block storage),
/// the first shift of the diagonal and the relative size below which a point pivot counts as zero (point
/// storage).
const ZERO_PIVOT_SHIFT: f64 = 100.0 * f64::EPSILON;

/// Why a preconditioner cannot be built or factored.
#[derive(Debug, Error, PartialEq)]
pub enum IluError {
    /// A block row without its diagonal block.
    #[error("block row {0} has no diagonal block")]
    NoDiagonal(usize),
    /// A block size without a kernel.
    #[error("block size {0}: the threaded ILU(0) has kernels for 2 to 4 unknowns per node")]
    BlockSize(usize),
    /// A diagonal block whose factorisation is not finite.
    #[error("the diagonal block of row {0} is singular or not finite after elimination")]
    Pivot(usize),
}

/// One subdomain: the block rows `lo..hi` (its own rows `own` and the overlap) with the pattern of the
/// matrix restricted to them, and the factors.
///
/// The factors are stored as the triangular solves read them, as PETSc's `MatSolve_SeqBAIJ_N` does: the
/// `L` blocks of every row one after the other in row order (the forward solve's stream), and for the
/// rows in reverse order each row's inverted diagonal block followed by its `U` blocks (the backward
/// solve's stream). A solve then reads each array once from start to end. Stored row by row with `L`,
/// `D` and `U` side by side, the solves skipped through memory and ran 2.7-2.9x slower once the CPDI
/// pattern had widened (25 blocks per row, `docs/benchmarks.md`).
#[derive(Debug)]
struct Part {
    /// Widened range of block rows and columns.
    lo: usize,
    /// Own block rows (inside `lo..hi`), whose results the preconditioner keeps.
    own: std::ops::Range<usize>,
    /// Row pointers of the forward stream (row `i`'s `L` blocks are `l_ptr[i]..l_ptr[i + 1]`).
    l_ptr: Vec<usize>,
    /// Local block column (`global - lo`) of each `L` block, ascending within each row.
    l_col: Vec<u32>,
    /// Position of each `L` block in the matrix's values (block index of the global pattern).
    l_src: Vec<usize>,
    /// `L` (unit diagonal, not stored), `bs x bs` column-major blocks.
    l: Vec<f64>,
    /// Row pointers of the backward stream: row `i`'s blocks are `u_ptr[t]..u_ptr[t + 1]` with
    /// `t = m - 1 - i`, its diagonal block first.
    u_ptr: Vec<usize>,
    /// Local block column of each block of the backward stream (the row itself for the diagonal).
    u_col: Vec<u32>,
    /// Position of each block of the backward stream in the matrix's values.
    u_src: Vec<usize>,
    /// The inverted diagonal blocks and `U`.
    u: Vec<f64>,
    /// Where each local column sits in the row being factored: an `L` block `q` as `q`, a block `q` of
    /// the backward stream as `l_col.len() + q`, `usize::MAX` if not in the row.
    mark: Vec<usize>,
    /// The local vector of the solves.
    z: Vec<f64>,
}

/// ILU(0) on overlapping subdomains (restricted additive Schwarz), factored and applied in parallel. Built once per pattern ([`SchwarzIlu::blocks`], [`SchwarzIlu::points`]), factored at every preconditioner set-up
/// ([`SchwarzIlu::factor`]), applied at every Krylov iteration ([`SchwarzIlu::apply`]).
#[derive(Debug)]
pub struct SchwarzIlu {
    /// Size of the blocks the factorisation pivots on: the node blocks (2 to 4) or single unknowns (1).
    kernel: usize,
    /// Unknowns (scalar rows) of the matrix.
    unknowns: usize,
    /// Length of the matrix's values array.
    values: usize,
    parts: Vec<Part>,
    /// The last factorisation succeeded.
    factored: bool,
}

impl SchwarzIlu {
    /// Block ILU(0) for PETSc's block (BAIJ) storage: the subdomains of the block pattern `row_ptr` /
    /// `cols` (columns ascending within each row, every row holding its diagonal) cut into at most
    /// `parts` pieces, with block size `bs` (2 to 4). A diagonal block's exactly zero pivot is shifted.
    pub fn blocks(
        bs: usize,
        row_ptr: &[usize],
        cols: &[u32],
        parts: usize,
    ) -> Result<Self, IluError> {
        if !(2..=4).contains(&bs) {
            return Err(IluError::BlockSize(bs));
        }
        Self::build(bs, row_ptr, cols, parts)
    }

    /// Point ILU(0) for PETSc's point-wise (AIJ) storage of the same block pattern (each block row's
    /// scalar rows stored one after the other, columns ascending): the factorisation pivots on single
    /// unknowns and, as PETSc's with `-sub_pc_factor_shift_type nonzero`, starts again with a shift of
    /// the diagonal (100 machine epsilons, doubled at every new start) when a pivot is not larger than
    /// 100 machine epsilons times the sum of its row's other factor entries.
    pub fn points(
        bs: usize,
        row_ptr: &[usize],
        cols: &[u32],
        parts: usize,
    ) -> Result<Self, IluError> {
        let n = row_ptr.len().saturating_sub(1);
        let mut scalar_ptr = Vec::with_capacity(n * bs + 1);
        scalar_ptr.push(0);
        let mut scalar_cols = Vec::with_capacity(row_ptr[n] * bs * bs);
        for a in 0..n {
            for _ in 0..bs {
                for &c in &cols[row_ptr[a]..row_ptr[a + 1]] {
                    for k in 0..bs {
                        scalar_cols.push(c * bs as u32 + k as u32);
                    }
                }
                scalar_ptr.push(scalar_cols.len());
            }
        }
        Self::build(1, &scalar_ptr, &scalar_cols, parts)
    }

    /// The parts of the pattern `row_ptr` / `cols` for factorisation blocks of size `kernel`.
    fn build(
        kernel: usize,
        row_ptr: &[usize],
        cols: &[u32],
        parts: usize,
    ) -> Result<Self, IluError> {
        let n = row_ptr.len().saturating_sub(1);
        let parts = parts.clamp(1, n.max(1));
        // Own ranges of about equal nonzeros.
        let nnz = row_ptr[n];
        let mut cuts = vec![0usize];
        for t in 1..parts {
            let target = nnz * t / parts;
            let r = row_ptr.partition_point(|&p| p < target).min(n);
            cuts.push(r.max(*cuts.last().expect("a first cut")));
        }
        cuts.push(n);
        // The parts' symbolic factors, each on its own worker.
        let out = cuts
            .par_windows(2)
            .filter(|w| w[0] < w[1])
            .map(|w| {
                let own = w[0]..w[1];
                let lo = own
                    .clone()
                    .map(|r| cols[row_ptr[r]] as usize)
                    .min()
                    .unwrap_or(own.start)
                    .min(own.start);
                let hi = own
                    .clone()
                    .map(|r| cols[row_ptr[r + 1] - 1] as usize + 1)
                    .max()
                    .unwrap_or(own.end)
                    .max(own.end);
                Part::new(kernel, row_ptr, cols, lo..hi, own)
            })
            .collect::<Vec<_>>()
            // The first error in the parts' order, whichever worker met it first.
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            kernel,
            unknowns: n * kernel,
            values: nnz * kernel * kernel,
            parts: out,
            factored: false,
        })
    }

    /// Unknowns (scalar rows) of the matrix.
    pub fn rows(&self) -> usize {
        self.unknowns
    }

    /// Length of the matrix's values array.
    pub fn values_len(&self) -> usize {
        self.values
    }

    /// Number of subdomains.
    pub fn parts(&self) -> usize {
        self.parts.len()
    }

    /// Factors every subdomain from the matrix's block values `values` (in the pattern's order), in
    /// parallel. On an error the preconditioner is marked unusable until the next successful
    /// factorisation.
    pub fn factor(&mut self, values: &[f64]) -> Result<(), IluError> {
        let kernel = self.kernel;
        let result = self.parts.par_iter_mut().try_for_each(|p| match kernel {
            1 => p.factor_points(values),
            2 => p.factor::<2>(values, 0.0).map(drop),
            3 => p.factor::<3>(values, 0.0).map(drop),
            4 => p.factor::<4>(values, 0.0).map(drop),
            _ => Err(IluError::BlockSize(kernel)),
        });
        self.factored = result.is_ok();
        result
    }

    /// `y = M^-1 x`: every subdomain's `(L U)^-1` applied to its widened range of `x`, kept on its own
    /// rows; NaN everywhere if the last factorisation failed (so that the Krylov solver stops).
    pub fn apply(&mut self, x: &[f64], y: &mut [f64]) {
        if !self.factored {
            y.fill(f64::NAN);
            return;
        }
        let kernel = self.kernel;
        // Split y into the parts' own rows (contiguous, in order, covering all rows).
        let mut chunks = Vec::with_capacity(self.parts.len());
        let mut rest = y;
        for p in &self.parts {
            let (head, tail) = rest.split_at_mut(p.own.len() * kernel);
            chunks.push(head);
            rest = tail;
        }
        self.parts
            .par_iter_mut()
            .zip(chunks)
            .for_each(|(p, out)| match kernel {
                1 => p.solve::<1>(x, out),
                2 => p.solve::<2>(x, out),
                3 => p.solve::<3>(x, out),
                _ => p.solve::<4>(x, out),
            });
    }
}

impl Part {
    fn new(
        kernel: usize,
        row_ptr: &[usize],
        cols: &[u32],
        range: std::ops::Range<usize>,
        own: std::ops::Range<usize>,
    ) -> Result<Self, IluError> {
        let (lo, hi) = (range.start, range.end);
        let m = hi - lo;
        let (mut l_ptr, mut l_col, mut l_src) = (Vec::with_capacity(m + 1), Vec::new(), Vec::new());
        l_ptr.push(0);
        for r in lo..hi {
            let row = row_ptr[r]..row_ptr[r + 1];
            for (p, &c) in row.clone().zip(&cols[row]) {
                let c = c as usize;
                if c >= r {
                    break;
                }
                if c >= lo {
                    l_col.push((c - lo) as u32);
                    l_src.push(p);
                }
            }
            l_ptr.push(l_col.len());
        }
        let (mut u_ptr, mut u_col, mut u_src) = (Vec::with_capacity(m + 1), Vec::new(), Vec::new());
        u_ptr.push(0);
        for r in (lo..hi).rev() {
            let row = row_ptr[r]..row_ptr[r + 1];
            let d = row
                .clone()
                .find(|&p| cols[p] as usize == r)
                .ok_or(IluError::NoDiagonal(r))?;
            for (p, &c) in (d..row.end).zip(&cols[d..row.end]) {
                let c = c as usize;
                if c < hi {
                    u_col.push((c - lo) as u32);
                    u_src.push(p);
                }
            }
            u_ptr.push(u_col.len());
        }
        let bb = kernel * kernel;
        Ok(Self {
            lo,
            own,
            l: vec![0.0; l_col.len() * bb],
            u: vec![0.0; u_col.len() * bb],
            l_ptr,
            l_col,
            l_src,
            u_ptr,
            u_col,
            u_src,
            mark: vec![usize::MAX; m],
            z: vec![0.0; m * kernel],
        })
    }

    /// Block rows of the subdomain.
    fn rows(&self) -> usize {
        self.l_ptr.len() - 1
    }

    /// The blocks of row `i` in the backward stream (its diagonal block first).
    fn u_row(&self, i: usize) -> std::ops::Range<usize> {
        let t = self.rows() - 1 - i;
        self.u_ptr[t]..self.u_ptr[t + 1]
    }

    /// Point ILU(0) with PETSc's nonzero shift: started again with a larger shift of the diagonal while
    /// a pivot is too small against its row ([`SchwarzIlu::points`]).
    fn factor_points(&mut self, values: &[f64]) -> Result<(), IluError> {
        let mut shift = 0.0;
        while !self.factor::<1>(values, shift)? {
            shift = if shift == 0.0 {
                ZERO_PIVOT_SHIFT
            } else {
                2.0 * shift
            };
            if !shift.is_finite() {
                return Err(IluError::Pivot(self.lo));
            }
        }
        Ok(())
    }

    /// ILU(0) of the local matrix with `shift` added to its diagonal, row by row (PETSc's order): each
    /// block `A_ik` left of the diagonal becomes `L_ik = A_ik U_kk^-1` and is eliminated from the rest of
    /// row `i` where its pattern has room; then the diagonal block is inverted. False (point pivots,
    /// `B = 1`) where a pivot is not larger than [`ZERO_PIVOT_SHIFT`] times the sum of the magnitudes of
    /// its row's other factor entries: the caller starts again with a larger shift.
    fn factor<const B: usize>(&mut self, values: &[f64], shift: f64) -> Result<bool, IluError> {
        let bb = B * B;
        for (q, &s) in self.l_src.iter().enumerate() {
            self.l[q * bb..(q + 1) * bb].copy_from_slice(&values[s * bb..(s + 1) * bb]);
        }
        for (q, &s) in self.u_src.iter().enumerate() {
            self.u[q * bb..(q + 1) * bb].copy_from_slice(&values[s * bb..(s + 1) * bb]);
        }
        let m = self.rows();
        if shift != 0.0 {
            for t in 0..m {
                let d = self.u_ptr[t];
                for r in 0..B {
                    self.u[d * bb + r * B + r] += shift;
                }
            }
        }
        let nl = self.l_col.len();
        for i in 0..m {
            let (ls, le) = (self.l_ptr[i], self.l_ptr[i + 1]);
            let ur = self.u_row(i);
            for q in ls..le {
                self.mark[self.l_col[q] as usize] = q;
            }
            for q in ur.clone() {
                self.mark[self.u_col[q] as usize] = nl + q;
            }
            for q in ls..le {
                let k = self.l_col[q] as usize;
                let uk = self.u_row(k);
                // L_ik = A_ik D_k^-1 (D_k^-1 first in row k's backward stream).
                let l: [f64; 16] = {
                    let mut t = [0.0; 16];
                    mat_mul::<B>(
                        &self.l[q * bb..(q + 1) * bb],
                        &self.u[uk.start * bb..(uk.start + 1) * bb],
                        &mut t[..bb],
                    );
                    t
                };
                self.l[q * bb..(q + 1) * bb].copy_from_slice(&l[..bb]);
                for q2 in uk.start + 1..uk.end {
                    let p = self.mark[self.u_col[q2] as usize];
                    if p == usize::MAX {
                        continue;
                    }
                    if p < nl {
                        let u = &self.u[q2 * bb..(q2 + 1) * bb];
                        mat_mul_sub::<B>(&l, u, &mut self.l[p * bb..(p + 1) * bb]);
                    } else {
                        let (dst, u) = split_pair(&mut self.u, (p - nl) * bb, q2 * bb, bb);
                        mat_mul_sub::<B>(&l, u, dst);
                    }
                }
            }
            for q in ls..le {
                self.mark[self.l_col[q] as usize] = usize::MAX;
            }
            for q in ur.clone() {
                self.mark[self.u_col[q] as usize] = usize::MAX;
            }
            let di = ur.start;
            if B == 1 {
                let others: f64 = self.l[ls..le]
                    .iter()
                    .chain(&self.u[di + 1..ur.end])
                    .map(|v| v.abs())
                    .sum();
                let pivot = self.u[di].abs();
                if pivot <= ZERO_PIVOT_SHIFT * others || pivot == 0.0 {
                    return Ok(false);
                }
            }
            if !invert::<B>(&mut self.u[di * bb..(di + 1) * bb]) {
                return Err(IluError::Pivot(self.lo + i));
            }
        }
        Ok(true)
    }

    /// Forward and backward solves on the widened range of `x`, each reading its stream of factors
    /// once in order; the own rows' results into `out`.
    fn solve<const B: usize>(&mut self, x: &[f64], out: &mut [f64]) {
        let bb = B * B;
        let m = self.rows();
        let z = &mut self.z[..m * B];
        z.copy_from_slice(&x[self.lo * B..(self.lo + m) * B]);
        let mut blocks = self.l.chunks_exact(bb);
        for i in 0..m {
            let mut s = [0.0; B];
            s.copy_from_slice(&z[i * B..(i + 1) * B]);
            // The columns first: `zip` stops on them without taking a block of the next row.
            for (&c, blk) in self.l_col[self.l_ptr[i]..self.l_ptr[i + 1]]
                .iter()
                .zip(blocks.by_ref())
            {
                let c = c as usize * B;
                mat_vec_sub::<B>(blk, &z[c..c + B], &mut s);
            }
            z[i * B..(i + 1) * B].copy_from_slice(&s);
        }
        let mut blocks = self.u.chunks_exact(bb);
        for (t, i) in (0..m).rev().enumerate() {
            let d = blocks.next().expect("a diagonal block in every row");
            let mut s = [0.0; B];
            s.copy_from_slice(&z[i * B..(i + 1) * B]);
            for (&c, blk) in self.u_col[self.u_ptr[t] + 1..self.u_ptr[t + 1]]
                .iter()
                .zip(blocks.by_ref())
            {
                let c = c as usize * B;
                mat_vec_sub::<B>(blk, &z[c..c + B], &mut s);
            }
            for (r, zr) in z[i * B..(i + 1) * B].iter_mut().enumerate() {
                let mut t = d[r] * s[0];
                for (k, sk) in s.iter().enumerate().skip(1) {
                    t += d[k * B + r] * sk;
                }
                *zr = t;
            }
        }
        let first = self.own.start - self.lo;
        out.copy_from_slice(&z[first * B..(first + self.own.len()) * B]);
    }
}

/// Two disjoint blocks of `v`: `(&mut v[a..a + len], &v[b..b + len])`.
#[inline(always)]
fn split_pair(v: &mut [f64], a: usize, b: usize, len: usize) -> (&mut [f64], &[f64]) {
    if a < b {
        let (x, y) = v.split_at_mut(b);
        (&mut x[a..a + len], &y[..len])
    } else {
        let (x, y) = v.split_at_mut(a);
        (&mut y[..len], &x[b..b + len])
    }
}

/// `c = a b` for column-major `B x B` blocks.
#[inline(always)]
fn mat_mul<const B: usize>(a: &[f64], b: &[f64], c: &mut [f64]) {
    block_product::<B>(a, b, c, |c, t| *c = t);
}

/// `c -= a b` for column-major `B x B` blocks.
#[inline(always)]
fn mat_mul_sub<const B: usize>(a: &[f64], b: &[f64], c: &mut [f64]) {
    block_product::<B>(a, b, c, |c, t| *c -= t);
}

/// Each entry `t = (a b)_ik` of the product of column-major `B x B` blocks handed to `store` with the
/// entry `c_ik`.
#[inline(always)]
fn block_product<const B: usize>(
    a: &[f64],
    b: &[f64],
    c: &mut [f64],
    store: impl Fn(&mut f64, f64),
) {
    let (a, b, c) = (&a[..B * B], &b[..B * B], &mut c[..B * B]);
    for k in 0..B {
        for i in 0..B {
            let mut t = 0.0;
            for l in 0..B {
                t += a[l * B + i] * b[k * B + l];
            }
            store(&mut c[k * B + i], t);
        }
    }
}

/// `s -= a x` for a column-major `B x B` block `a` (`B * B` values) and `x` (`B` values): each row's
/// product summed first and then subtracted, as PETSc's `MatSolve_SeqBAIJ_N` kernels do, so that the
/// running sums `s` wait on one operation per block instead of `B`.
#[inline(always)]
fn mat_vec_sub<const B: usize>(a: &[f64], x: &[f64], s: &mut [f64; B]) {
    let (a, x) = (&a[..B * B], &x[..B]);
    for (i, si) in s.iter_mut().enumerate() {
        let mut t = a[i] * x[0];
        for k in 1..B {
            t += a[k * B + i] * x[k];
        }
        *si -= t;
    }
}

/// Inverts a column-major `B x B` block in place (Gauss-Jordan with partial pivoting; an exactly zero
/// pivot is replaced by [`ZERO_PIVOT_SHIFT`]). False if the result is not finite.
fn invert<const B: usize>(a: &mut [f64]) -> bool {
    // Work on [A | I] row-major.
    let mut m = [[0.0; 8]; 4];
    for (r, row) in m.iter_mut().enumerate().take(B) {
        for c in 0..B {
            row[c] = a[c * B + r];
        }
        row[B + r] = 1.0;
    }
    for c in 0..B {
        let p = (c..B)
            .max_by(|&x, &y| m[x][c].abs().total_cmp(&m[y][c].abs()))
            .unwrap_or(c);
        m.swap(c, p);
        if m[c][c] == 0.0 {
            m[c][c] = ZERO_PIVOT_SHIFT;
        }
        let inv = 1.0 / m[c][c];
        for v in m[c].iter_mut().take(2 * B) {
            *v *= inv;
        }
        let pivot_row = m[c];
        for (r, row) in m.iter_mut().enumerate().take(B) {
            let f = row[c];
            if r != c && f != 0.0 {
                for (v, p) in row.iter_mut().zip(&pivot_row).take(2 * B) {
                    *v -= f * p;
                }
            }
        }
    }
    let mut finite = true;
    for r in 0..B {
        for c in 0..B {
            let v = m[r][B + c];
            finite &= v.is_finite();
            a[c * B + r] = v;
        }
    }
    finite
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block tridiagonal-plus matrix on a 1D chain of `n` nodes with couplings to `reach` neighbours
    /// on either side (diagonally dominant), as (row_ptr, cols, values) in BAIJ order.
    fn chain(n: usize, bs: usize, reach: usize) -> (Vec<usize>, Vec<u32>, Vec<f64>) {
        let (mut row_ptr, mut cols, mut vals) = (vec![0], Vec::new(), Vec::new());
        for r in 0..n {
            for c in r.saturating_sub(reach)..(r + reach + 1).min(n) {
                cols.push(c as u32);
                for k in 0..bs {
                    for i in 0..bs {
                        let v = if r == c {
                            if i == k { 10.0 + i as f64 } else { 0.5 }
                        } else {
                            -0.3 - 0.01 * ((r * 7 + c * 3 + i + 2 * k) % 5) as f64
                        };
                        vals.push(v);
                    }
                }
            }
            row_ptr.push(cols.len());
        }
        (row_ptr, cols, vals)
    }

    fn dense(bs: usize, row_ptr: &[usize], cols: &[u32], vals: &[f64]) -> Vec<Vec<f64>> {
        let n = (row_ptr.len() - 1) * bs;
        let mut a = vec![vec![0.0; n]; n];
        for r in 0..row_ptr.len() - 1 {
            for p in row_ptr[r]..row_ptr[r + 1] {
                let c = cols[p] as usize;
                for k in 0..bs {
                    for i in 0..bs {
                        a[r * bs + i][c * bs + k] = vals[p * bs * bs + k * bs + i];
                    }
                }
            }
        }
        a
    }

    /// Asserts that the factored `ilu` applied to `x` gives `y` with `a y = x` to 1e-12: an exact solve.
    fn assert_solves_exactly(ilu: &mut SchwarzIlu, a: &[Vec<f64>], x: &[f64], case: &str) {
        let mut y = vec![0.0; x.len()];
        ilu.apply(x, &mut y);
        for (r, row) in a.iter().enumerate() {
            let ay: f64 = row.iter().zip(&y).map(|(a, y)| a * y).sum();
            assert!((ay - x[r]).abs() < 1e-12, "{case}row {r}: {ay} vs {}", x[r]);
        }
    }

    /// The block pattern of a `nx x ny` grid of nodes numbered row by row, each coupled to the nodes
    /// within `reach` in both directions (a CPDI pattern widened to `2 reach + 1` nodes a side), with
    /// diagonally dominant values in BAIJ order.
    fn grid(nx: usize, ny: usize, bs: usize, reach: usize) -> (Vec<usize>, Vec<u32>, Vec<f64>) {
        let (mut row_ptr, mut cols, mut vals) = (vec![0], Vec::new(), Vec::new());
        for j in 0..ny {
            for i in 0..nx {
                let r = j * nx + i;
                for jj in j.saturating_sub(reach)..(j + reach + 1).min(ny) {
                    for ii in i.saturating_sub(reach)..(i + reach + 1).min(nx) {
                        let c = jj * nx + ii;
                        cols.push(c as u32);
                        for k in 0..bs {
                            for q in 0..bs {
                                vals.push(if r == c {
                                    if q == k { 30.0 + q as f64 } else { 0.4 }
                                } else {
                                    -0.6 + 0.05 * ((3 * r + 5 * c + q + 2 * k) % 7) as f64
                                });
                            }
                        }
                    }
                }
                row_ptr.push(cols.len());
            }
        }
        (row_ptr, cols, vals)
    }

    /// `M^-1 x` for the ILU(0) of the block pattern, computed the plain way: dense `bs x bs` blocks,
    /// `L_ik = A_ik A_kk^-1` and `A_ij -= L_ik A_kj` wherever `(i, j)` is in the pattern, in row order.
    fn reference_ilu0(
        bs: usize,
        row_ptr: &[usize],
        cols: &[u32],
        vals: &[f64],
        x: &[f64],
    ) -> Vec<f64> {
        use nalgebra::{DMatrix, DVector};
        let n = row_ptr.len() - 1;
        let mut a: Vec<DMatrix<f64>> = (0..cols.len())
            .map(|p| DMatrix::from_column_slice(bs, bs, &vals[p * bs * bs..(p + 1) * bs * bs]))
            .collect();
        let at = |i: usize, j: usize| (row_ptr[i]..row_ptr[i + 1]).find(|&p| cols[p] as usize == j);
        let mut inv_d = vec![DMatrix::zeros(bs, bs); n];
        for i in 0..n {
            for q in row_ptr[i]..row_ptr[i + 1] {
                let k = cols[q] as usize;
                if k >= i {
                    break;
                }
                let l = &a[q] * &inv_d[k];
                for q2 in row_ptr[k]..row_ptr[k + 1] {
                    let j = cols[q2] as usize;
                    if j > k {
                        if let Some(p) = at(i, j) {
                            let update = &l * &a[q2];
                            a[p] -= update;
                        }
                    }
                }
                a[q] = l;
            }
            inv_d[i] = a[at(i, i).expect("diagonal")]
                .clone()
                .try_inverse()
                .expect("pivot");
        }
        let block = |v: &[f64], i: usize| DVector::from_column_slice(&v[i * bs..(i + 1) * bs]);
        let mut y = x.to_vec();
        for i in 0..n {
            let mut s = block(&y, i);
            for q in (row_ptr[i]..row_ptr[i + 1]).filter(|&q| (cols[q] as usize) < i) {
                s -= &a[q] * block(&y, cols[q] as usize);
            }
            y[i * bs..(i + 1) * bs].copy_from_slice(s.as_slice());
        }
        for i in (0..n).rev() {
            let mut s = block(&y, i);
            for q in (row_ptr[i]..row_ptr[i + 1]).filter(|&q| (cols[q] as usize) > i) {
                s -= &a[q] * block(&y, cols[q] as usize);
            }
            y[i * bs..(i + 1) * bs].copy_from_slice((&inv_d[i] * s).as_slice());
        }
        y
    }

    /// On a 2D grid pattern ILU(0) drops fill: one part applies the incomplete factors of the plain
    /// block and point algorithms, within rounding (the factors stored as the solves stream them).
    #[test]
    fn one_part_is_the_plain_ilu0_where_fill_is_dropped() {
        for (bs, reach) in [(2, 1), (3, 1), (3, 2), (4, 1)] {
            let (rp, cols, vals) = grid(6, 5, bs, reach);
            let n = (rp.len() - 1) * bs;
            let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.71).cos()).collect();
            let mut ilu = SchwarzIlu::blocks(bs, &rp, &cols, 1).expect("pattern");
            ilu.factor(&vals).expect("factor");
            let mut y = vec![0.0; n];
            ilu.apply(&x, &mut y);
            let want = reference_ilu0(bs, &rp, &cols, &vals, &x);
            let a = dense(bs, &rp, &cols, &vals);
            let residual = (0..n)
                .map(|r| (a[r].iter().zip(&y).map(|(a, y)| a * y).sum::<f64>() - x[r]).abs())
                .fold(0.0, f64::max);
            assert!(
                residual > 1e-6,
                "bs {bs} reach {reach}: fill must be dropped ({residual})"
            );
            for (r, (got, want)) in y.iter().zip(&want).enumerate() {
                assert!(
                    (got - want).abs() < 1e-12,
                    "blocks bs {bs} reach {reach} row {r}: {got} vs {want}"
                );
            }
            // The same matrix stored point-wise, factored on single unknowns.
            let (mut sp, mut sc, mut sv) = (vec![0], Vec::new(), Vec::new());
            for b in 0..rp.len() - 1 {
                for i in 0..bs {
                    for p in rp[b]..rp[b + 1] {
                        for k in 0..bs {
                            sc.push(cols[p] * bs as u32 + k as u32);
                            sv.push(vals[p * bs * bs + k * bs + i]);
                        }
                    }
                    sp.push(sc.len());
                }
            }
            let mut ilu = SchwarzIlu::points(bs, &rp, &cols, 1).expect("pattern");
            ilu.factor(&sv).expect("factor");
            ilu.apply(&x, &mut y);
            let want = reference_ilu0(1, &sp, &sc, &sv, &x);
            for (r, (got, want)) in y.iter().zip(&want).enumerate() {
                assert!(
                    (got - want).abs() < 1e-12,
                    "points bs {bs} reach {reach} row {r}: {got} vs {want}"
                );
            }
        }
    }

    /// With a tridiagonal block pattern ILU(0) has no fill to drop: one part is the exact inverse.
    #[test]
    fn one_part_on_a_pattern_without_fill_is_the_exact_solve() {
        for bs in 2..=4 {
            let (rp, cols, vals) = chain(9, bs, 1);
            let mut ilu = SchwarzIlu::blocks(bs, &rp, &cols, 1).expect("pattern");
            ilu.factor(&vals).expect("factor");
            let a = dense(bs, &rp, &cols, &vals);
            let x: Vec<f64> = (0..9 * bs).map(|i| (i as f64 * 0.37).sin()).collect();
            assert_solves_exactly(&mut ilu, &a, &x, &format!("bs {bs}, "));
        }
    }

    /// Two parts whose overlap covers the whole reach of the matrix solve a pattern without fill
    /// exactly on their own rows, and each part's own rows partition the rows.
    #[test]
    fn parts_partition_the_rows_and_overlap_by_the_reach() {
        let (rp, cols, _) = chain(40, 3, 2);
        let ilu = SchwarzIlu::blocks(3, &rp, &cols, 2).expect("pattern");
        assert_eq!(ilu.parts(), 2);
        let (a, b) = (&ilu.parts[0], &ilu.parts[1]);
        assert_eq!(a.own.start, 0);
        assert_eq!(a.own.end, b.own.start);
        assert_eq!(b.own.end, 40);
        assert_eq!(a.lo, 0);
        assert_eq!(
            a.rows(),
            a.own.end + 2,
            "part 0 reaches 2 rows past its cut"
        );
        assert_eq!(
            b.lo,
            b.own.start - 2,
            "part 1 reaches 2 rows before its cut"
        );
    }

    /// Restricted additive Schwarz with two parts is a good preconditioner: GMRES-free check by a
    /// stationary iteration x <- x + M^-1 (b - A x), which converges fast when M^-1 A is near I.
    #[test]
    fn two_parts_precondition_as_well_as_one() {
        let (rp, cols, vals) = chain(60, 3, 2);
        let a = dense(3, &rp, &cols, &vals);
        let n = a.len();
        let b: Vec<f64> = (0..n).map(|i| 1.0 + (i as f64 * 0.11).cos()).collect();
        let mut errors = Vec::new();
        for parts in [1, 2, 4] {
            let mut ilu = SchwarzIlu::blocks(3, &rp, &cols, parts).expect("pattern");
            ilu.factor(&vals).expect("factor");
            let mut x = vec![0.0; n];
            let (mut r, mut dx) = (vec![0.0; n], vec![0.0; n]);
            for _ in 0..8 {
                for (i, row) in a.iter().enumerate() {
                    r[i] = b[i] - row.iter().zip(&x).map(|(a, x)| a * x).sum::<f64>();
                }
                ilu.apply(&r, &mut dx);
                x.iter_mut().zip(&dx).for_each(|(x, d)| *x += d);
            }
            for (i, row) in a.iter().enumerate() {
                r[i] = b[i] - row.iter().zip(&x).map(|(a, x)| a * x).sum::<f64>();
            }
            errors.push(r.iter().map(|v| v * v).sum::<f64>().sqrt());
        }
        assert!(errors[0] < 1e-10, "{errors:?}");
        assert!(errors[1] < 1e-8 && errors[2] < 1e-8, "{errors:?}");
    }

    #[test]
    fn a_singular_diagonal_block_fails_the_factorisation_and_poisons_the_solve() {
        let (rp, cols, mut vals) = chain(5, 2, 1);
        // Row 2's diagonal block made NaN.
        let d = rp[2] + 1;
        vals[d * 4..d * 4 + 4].fill(f64::NAN);
        let mut ilu = SchwarzIlu::blocks(2, &rp, &cols, 1).expect("pattern");
        assert_eq!(ilu.factor(&vals), Err(IluError::Pivot(2)));
        let mut y = vec![0.0; 10];
        ilu.apply(&[1.0; 10], &mut y);
        assert!(y.iter().all(|v| v.is_nan()));
        assert_eq!(
            SchwarzIlu::blocks(5, &rp, &cols, 1).err(),
            Some(IluError::BlockSize(5))
        );
    }

    /// Point ILU(0) of a block tridiagonal matrix keeps every fill inside the pattern (each scalar row's
    /// pattern is its whole envelope): one part is the exact inverse, as for the blocks.
    #[test]
    fn one_part_of_point_ilu_on_a_block_tridiagonal_pattern_is_the_exact_solve() {
        let bs = 3;
        let (rp, cols, blocks) = chain(8, bs, 1);
        // The same matrix in point-wise storage: scalar rows one after the other.
        let mut points = Vec::with_capacity(blocks.len());
        for a in 0..8 {
            let n = rp[a + 1] - rp[a];
            for i in 0..bs {
                for pos in 0..n {
                    for k in 0..bs {
                        points.push(blocks[(rp[a] + pos) * bs * bs + k * bs + i]);
                    }
                }
            }
        }
        let mut ilu = SchwarzIlu::points(bs, &rp, &cols, 1).expect("pattern");
        assert_eq!(ilu.values_len(), points.len());
        ilu.factor(&points).expect("factor");
        let a = dense(bs, &rp, &cols, &blocks);
        let x: Vec<f64> = (0..8 * bs).map(|i| (i as f64 * 0.37).cos()).collect();
        assert_solves_exactly(&mut ilu, &a, &x, "");
    }

    /// A zero point pivot starts the factorisation again with a shifted diagonal instead of failing.
    #[test]
    fn a_zero_point_pivot_is_shifted() {
        // One node of 2 unknowns: [[0, 1], [1, 0]].
        let (rp, cols) = (vec![0usize, 1], vec![0u32]);
        let mut ilu = SchwarzIlu::points(2, &rp, &cols, 1).expect("pattern");
        ilu.factor(&[0.0, 1.0, 1.0, 0.0])
            .expect("a shifted factorisation");
        let mut y = [0.0; 2];
        ilu.apply(&[1.0, 1.0], &mut y);
        assert!(y.iter().all(|v| v.is_finite()), "{y:?}");
    }

    #[test]
    fn blocks_invert() {
        let mut a = [4.0, 1.0, 0.0, 2.0, 5.0, 1.0, 0.0, 1.0, 3.0];
        let orig = a;
        assert!(invert::<3>(&mut a));
        let mut c = [0.0; 9];
        mat_mul::<3>(&orig, &a, &mut c);
        for k in 0..3 {
            for i in 0..3 {
                let e = if i == k { 1.0 } else { 0.0 };
                assert!((c[k * 3 + i] - e).abs() < 1e-14);
            }
        }
        // A zero pivot with a zero column is shifted, not a division by zero.
        let mut z = [0.0, 0.0, 0.0, 1.0];
        assert!(invert::<2>(&mut z));
    }
}
