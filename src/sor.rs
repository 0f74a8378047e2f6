//! Symmetric Gauss-Seidel sweeps (SOR with `omega = 1`) on a point-wise (CSR) matrix, on all threads:
//! the multigrid's smoother (`petsc::smoother`), in place of PETSc's `MatSOR`, which runs on one core.
//!
//! The rows are cut into `parts` contiguous ranges of about equal nonzeros. A sweep updates each part's
//! unknowns in place, forward through its rows and then backward, reading the other parts' unknowns as
//! they stood when the sweep began: Gauss-Seidel inside a part, Jacobi between parts, as PETSc's
//! `SOR_LOCAL_SYMMETRIC_SWEEP` treats the rows of other processes. With one part it is PETSc's symmetric
//! sweep of the whole matrix (`-pc_sor_symmetric`, `omega = 1`, one local iteration), up to the order of
//! the sums: a row is `x_i = (b_i - sum_{j != i} a_ij x_j) / a_ii`, and consecutive rows with the same
//! columns (a grid node's unknowns) are read together. A zero or missing diagonal makes the sweep
//! non-finite, which the Krylov solver meets as a breakdown (as it does a zero pivot).

use rayon::prelude::*;

/// Row boundaries of `parts` contiguous ranges of about equal nonzeros of the CSR row pointers
/// `row_ptr`: `parts + 1` increasing values from 0 to the number of rows (some ranges may be empty).
pub fn part_bounds(row_ptr: &[i32], parts: usize) -> Vec<usize> {
    let rows = row_ptr.len().saturating_sub(1);
    let parts = parts.max(1);
    let total = row_ptr.last().copied().unwrap_or(0) as f64;
    let mut bounds = Vec::with_capacity(parts + 1);
    bounds.push(0);
    let mut r = 0;
    for p in 1..parts {
        let target = total * p as f64 / parts as f64;
        while r < rows && (row_ptr[r] as f64) < target {
            r += 1;
        }
        bounds.push(r);
    }
    bounds.push(rows);
    bounds
}

/// A matrix in CSR form as PETSc's `seqaij` keeps it: row pointers, column indices (sorted in each
/// row) and values.
#[derive(Clone, Copy)]
pub struct Csr<'a> {
    /// `rows + 1` row pointers.
    pub row_ptr: &'a [i32],
    /// Column of each entry.
    pub cols: &'a [i32],
    /// Value of each entry.
    pub vals: &'a [f64],
}

impl Csr<'_> {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.row_ptr.len().saturating_sub(1)
    }
}

/// Largest number of consecutive rows with one column pattern that the sweeps take together.
const MAX_GROUP: usize = 4;

/// A run of consecutive rows of one part with the same columns (the unknowns of one grid node in the
/// Jacobian and the multigrid's Galerkin operators), which the sweeps read together: each column index
/// and each unknown it names loaded once for all of them, as PETSc's `MatSOR_SeqAIJ_Inode` does. Positions
/// are offsets into each row's entries.
#[derive(Debug, Clone, Copy)]
struct Group {
    /// First row.
    row: u32,
    /// Number of rows (1 to [`MAX_GROUP`]).
    len: u8,
    /// The first entry of a column in the rows' part.
    first: u32,
    /// The entry of column `row` (the group's diagonal block starts there, `len` entries wide).
    diag: u32,
    /// The first entry of a column after the part.
    last: u32,
}

/// How the rows of a pattern split for the sweeps on given parts: runs of rows with the same columns
/// ([`Group`]), and in each the entries of columns before the part, of the part before the group's own
/// columns, the group's diagonal block, after it, and after the part. Made once per pattern and parts
/// ([`SweepPlan::new`]); a sweep then sums each range without a branch per entry.
#[derive(Debug, Default)]
pub struct SweepPlan {
    /// Row boundaries of the parts ([`part_bounds`]).
    bounds: Vec<usize>,
    /// The groups of each part, in row order (`parts[p]` indexes `groups`).
    groups: Vec<Group>,
    parts: Vec<std::ops::Range<usize>>,
    /// A row without its diagonal entry: every sweep is then not finite.
    missing_diagonal: bool,
    /// Number of rows and nonzeros of the pattern it was made for.
    size: (usize, usize),
}

impl SweepPlan {
    /// The plan of the pattern of `a` on `parts` parts.
    pub fn new(a: Csr<'_>, parts: usize) -> Self {
        let bounds = part_bounds(a.row_ptr, parts);
        let n = a.rows();
        let cols = |i: usize| &a.cols[a.row_ptr[i] as usize..a.row_ptr[i + 1] as usize];
        let below = |c: usize| move |&j: &i32| (j as usize) < c;
        let (mut groups, mut ranges, mut missing_diagonal) = (Vec::new(), Vec::new(), false);
        for w in bounds.windows(2) {
            let (lo, hi) = (w[0], w[1]);
            let begin = groups.len();
            let mut i = lo;
            while i < hi {
                let row = cols(i);
                let diag = row.partition_point(below(i));
                if row.get(diag).map(|&c| c as usize) != Some(i) {
                    missing_diagonal = true;
                }
                // The following rows with the same columns, whose own columns follow the diagonal.
                let mut len = 1;
                while len < MAX_GROUP
                    && i + len < hi
                    && cols(i + len) == row
                    && row.get(diag + len).map(|&c| c as usize) == Some(i + len)
                {
                    len += 1;
                }
                let first = row.partition_point(below(lo));
                let last = diag + row[diag..].partition_point(below(hi));
                groups.push(Group {
                    row: i as u32,
                    len: len as u8,
                    first: first as u32,
                    diag: diag as u32,
                    last: last as u32,
                });
                i += len;
            }
            ranges.push(begin..groups.len());
        }
        Self {
            bounds,
            groups,
            parts: ranges,
            missing_diagonal,
            size: (n, a.cols.len()),
        }
    }

    /// Whether the plan was made for a pattern of this size on `parts` parts (a pattern PETSc keeps
    /// for the life of a matrix: the caller remakes the plan when the matrix is another).
    pub fn fits(&self, a: Csr<'_>, parts: usize) -> bool {
        self.size == (a.rows(), a.cols.len()) && self.bounds.len() == parts.max(1) + 1
    }
}

/// Work space of the sweeps: the unknowns as a sweep found them, and the forward sweep's partial
/// right-hand sides.
#[derive(Debug, Default)]
pub struct SweepWork {
    before: Vec<f64>,
    partial: Vec<f64>,
}

/// What a sweep of one part reads: the matrix, the right-hand side, the other parts' unknowns as the
/// sweep found them, and the part's first row.
#[derive(Clone, Copy)]
struct Sweep<'a> {
    a: Csr<'a>,
    b: &'a [f64],
    others: &'a [f64],
    lo: usize,
}

impl Sweep<'_> {
    /// `s_k += sum_j v_kj x[c_j - lo]` for the `G` rows from `row` over the entries `range` (offsets
    /// into each row's entries), each unknown loaded once for all rows.
    #[inline(always)]
    fn gather<const G: usize>(
        &self,
        row: usize,
        range: std::ops::Range<usize>,
        lo: usize,
        x: &[f64],
        s: &mut [f64; G],
    ) {
        let starts: [usize; G] = std::array::from_fn(|k| self.a.row_ptr[row + k] as usize);
        let cols = &self.a.cols[starts[0] + range.start..starts[0] + range.end];
        let vals: [&[f64]; G] =
            std::array::from_fn(|k| &self.a.vals[starts[k] + range.start..starts[k] + range.end]);
        // Two sets of running sums (even and odd entries), so that the products do not wait on each
        // other.
        let mut odd = [0.0; G];
        let pairs = cols.chunks_exact(2);
        let rest = pairs.remainder();
        for (j, c) in pairs.enumerate() {
            let (x0, x1) = (x[c[0] as usize - lo], x[c[1] as usize - lo]);
            for k in 0..G {
                s[k] += vals[k][2 * j] * x0;
                odd[k] += vals[k][2 * j + 1] * x1;
            }
        }
        if let Some(&c) = rest.first() {
            let xj = x[c as usize - lo];
            for k in 0..G {
                s[k] += vals[k][cols.len() - 1] * xj;
            }
        }
        for k in 0..G {
            s[k] += odd[k];
        }
    }

    /// The group `g` of rows swept from zero, forward (`partial` keeps `b_i` less the entries left of
    /// each diagonal) or, after it, backward.
    #[inline(always)]
    fn sweep_from_zero<const G: usize>(
        &self,
        g: Group,
        own: &mut [f64],
        partial: &mut [f64],
        forward: bool,
    ) {
        let (lo, r, d) = (self.lo, g.row as usize, g.diag as usize);
        let v = |k: usize, m: usize| self.a.vals[self.a.row_ptr[r + k] as usize + d + m];
        let mut s = [0.0; G];
        if forward {
            self.gather::<G>(r, g.first as usize..d, lo, own, &mut s);
            for k in 0..G {
                let mut t = self.b[r + k] - s[k];
                for m in 0..k {
                    t -= v(k, m) * own[r + m - lo];
                }
                partial[r + k - lo] = t;
                own[r + k - lo] = t / v(k, k);
            }
        } else {
            self.gather::<G>(r, d + G..g.last as usize, lo, own, &mut s);
            for k in (0..G).rev() {
                let mut t = partial[r + k - lo] - s[k];
                for m in k + 1..G {
                    t -= v(k, m) * own[r + m - lo];
                }
                own[r + k - lo] = t / v(k, k);
            }
        }
    }

    /// The group `g` of rows swept from the current unknowns, forward or backward.
    #[inline(always)]
    fn sweep_from_guess<const G: usize>(&self, g: Group, own: &mut [f64], forward: bool) {
        let (lo, r, d) = (self.lo, g.row as usize, g.diag as usize);
        let v = |k: usize, m: usize| self.a.vals[self.a.row_ptr[r + k] as usize + d + m];
        let end = (self.a.row_ptr[r + 1] - self.a.row_ptr[r]) as usize;
        let mut s = [0.0; G];
        self.gather::<G>(r, g.first as usize..d, lo, own, &mut s);
        self.gather::<G>(r, d + G..g.last as usize, lo, own, &mut s);
        if !self.others.is_empty() {
            self.gather::<G>(r, 0..g.first as usize, 0, self.others, &mut s);
            self.gather::<G>(r, g.last as usize..end, 0, self.others, &mut s);
        }
        let mut update = |k: usize| {
            let mut t = self.b[r + k] - s[k];
            for m in (0..G).filter(|&m| m != k) {
                t -= v(k, m) * own[r + m - lo];
            }
            own[r + k - lo] = t / v(k, k);
        };
        if forward {
            (0..G).for_each(&mut update);
        } else {
            (0..G).rev().for_each(&mut update);
        }
    }
}

/// Calls `$f::<G>` for the group's length `G` (1 to [`MAX_GROUP`]).
macro_rules! by_len {
    ($g:expr, $f:ident, $($arg:expr),*) => {
        match $g.len {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            _ => $f::<4>($($arg),*),
        }
    };
}

/// `sweeps` symmetric Gauss-Seidel sweeps of `a x = b` on the parts of `plan` (made for `a`'s
/// pattern), from `x` or, if `zero_guess`, from zero. From zero the first sweep reads each row once, as
/// PETSc's does: forward the entries left of the diagonal (every other unknown is still zero), keeping
/// `b_i` less that sum, backward the entries right of it.
pub fn symmetric_sweeps(
    a: Csr<'_>,
    plan: &SweepPlan,
    b: &[f64],
    x: &mut [f64],
    sweeps: usize,
    zero_guess: bool,
    work: &mut SweepWork,
) {
    let n = a.rows();
    assert!(b.len() == n && x.len() == n, "vectors of the matrix's size");
    assert!(
        plan.size == (n, a.cols.len()),
        "a plan of the matrix's pattern"
    );
    if plan.missing_diagonal {
        x.fill(f64::NAN);
        return;
    }
    let parts = plan.bounds.len() - 1;
    for sweep in 0..sweeps {
        let from_zero = zero_guess && sweep == 0;
        if from_zero {
            x.fill(0.0);
            work.partial.resize(n, 0.0);
        } else if parts > 1 {
            work.before.clear();
            work.before.extend_from_slice(x);
        }
        let others: &[f64] = if parts > 1 { &work.before } else { &[] };
        // Each part's rows with their slices of x (and of the partial sums).
        let mut jobs = Vec::with_capacity(parts);
        let (mut xs, mut ps) = (&mut *x, &mut work.partial[..]);
        for (w, groups) in plan.bounds.windows(2).zip(&plan.parts) {
            let len = w[1] - w[0];
            let (mine, rest) = xs.split_at_mut(len);
            xs = rest;
            let partial = if from_zero {
                let (p, rest) = ps.split_at_mut(len);
                ps = rest;
                p
            } else {
                &mut []
            };
            jobs.push((w[0], &plan.groups[groups.clone()], mine, partial));
        }
        let run = |(lo, groups, own, partial): (usize, &[Group], &mut [f64], &mut [f64])| {
            let sweep = Sweep { a, b, others, lo };
            if from_zero {
                for &g in groups {
                    by_len!(g, zero, &sweep, g, own, partial, true);
                }
                for &g in groups.iter().rev() {
                    by_len!(g, zero, &sweep, g, own, partial, false);
                }
            } else {
                for &g in groups {
                    by_len!(g, guess, &sweep, g, own, true);
                }
                for &g in groups.iter().rev() {
                    by_len!(g, guess, &sweep, g, own, false);
                }
            }
        };
        if parts > 1 {
            jobs.into_par_iter().for_each(run);
        } else {
            jobs.into_iter().for_each(run);
        }
    }
}

/// [`Sweep::sweep_from_zero`] for a group of `G` rows.
#[inline(always)]
fn zero<const G: usize>(
    s: &Sweep<'_>,
    g: Group,
    own: &mut [f64],
    partial: &mut [f64],
    forward: bool,
) {
    s.sweep_from_zero::<G>(g, own, partial, forward);
}

/// [`Sweep::sweep_from_guess`] for a group of `G` rows.
#[inline(always)]
fn guess<const G: usize>(s: &Sweep<'_>, g: Group, own: &mut [f64], forward: bool) {
    s.sweep_from_guess::<G>(g, own, forward);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 1D Laplacian with a mass term, `n` rows: 2 + m on the diagonal, -1 beside it.
    fn laplacian(n: usize, m: f64) -> (Vec<i32>, Vec<i32>, Vec<f64>) {
        let (mut ia, mut ja, mut va) = (vec![0], Vec::new(), Vec::new());
        for i in 0..n {
            for j in i.saturating_sub(1)..(i + 2).min(n) {
                ja.push(j as i32);
                va.push(if i == j { 2.0 + m } else { -1.0 });
            }
            ia.push(ja.len() as i32);
        }
        (ia, ja, va)
    }

    /// A block tridiagonal matrix of `nodes` full `bs x bs` blocks per block row (the rows of a node
    /// share their columns, as the Jacobian's do), not symmetric, diagonally dominant.
    fn blocks(nodes: usize, bs: usize) -> (Vec<i32>, Vec<i32>, Vec<f64>) {
        let (mut ia, mut ja, mut va) = (vec![0], Vec::new(), Vec::new());
        for node in 0..nodes {
            for i in 0..bs {
                let row = node * bs + i;
                for other in node.saturating_sub(1)..(node + 2).min(nodes) {
                    for k in 0..bs {
                        let col = other * bs + k;
                        ja.push(col as i32);
                        va.push(if col == row {
                            8.0 + (row % 3) as f64
                        } else {
                            -0.5 - 0.1 * ((row + 2 * col) % 5) as f64
                        });
                    }
                }
                ia.push(ja.len() as i32);
            }
        }
        (ia, ja, va)
    }

    /// One symmetric sweep as the plan defines it, entry by entry: on each part forward then
    /// backward Gauss-Seidel, the other parts' unknowns as the sweep found them.
    fn reference(a: Csr<'_>, bounds: &[usize], b: &[f64], x: &mut [f64]) {
        let before = x.to_vec();
        for w in bounds.windows(2) {
            let rows: Vec<usize> = (w[0]..w[1]).chain((w[0]..w[1]).rev()).collect();
            for i in rows {
                let (mut s, mut d) = (b[i], 0.0);
                for k in a.row_ptr[i] as usize..a.row_ptr[i + 1] as usize {
                    let c = a.cols[k] as usize;
                    if c == i {
                        d = a.vals[k];
                    } else {
                        s -= a.vals[k]
                            * if (w[0]..w[1]).contains(&c) {
                                x[c]
                            } else {
                                before[c]
                            };
                    }
                }
                x[i] = s / d;
            }
        }
    }

    #[test]
    fn node_rows_swept_together_are_gauss_seidel_row_by_row() {
        for bs in [1, 2, 3, 4, 5] {
            let n = 11 * bs;
            let (ia, ja, va) = blocks(11, bs);
            let a = Csr {
                row_ptr: &ia,
                cols: &ja,
                vals: &va,
            };
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).cos()).collect();
            for parts in [1, 2, 3] {
                let plan = SweepPlan::new(a, parts);
                // The rows of a node go together (up to four; a part may cut a node).
                assert!(
                    plan.groups.len() <= 11 * bs.div_ceil(MAX_GROUP) + parts,
                    "bs {bs}"
                );
                for zero_guess in [true, false] {
                    let guess: Vec<f64> = (0..n).map(|i| 0.1 * i as f64).collect();
                    let mut expected = if zero_guess {
                        vec![0.0; n]
                    } else {
                        guess.clone()
                    };
                    for _ in 0..2 {
                        reference(a, &plan.bounds, &b, &mut expected);
                    }
                    let mut x = guess;
                    symmetric_sweeps(
                        a,
                        &plan,
                        &b,
                        &mut x,
                        2,
                        zero_guess,
                        &mut SweepWork::default(),
                    );
                    let err = x
                        .iter()
                        .zip(&expected)
                        .map(|(u, v)| (u - v).abs())
                        .fold(0.0, f64::max);
                    assert!(
                        err < 1e-13,
                        "bs {bs}, {parts} parts, zero guess {zero_guess}: {err}"
                    );
                }
            }
        }
    }

    #[test]
    fn one_part_is_the_sequential_symmetric_sweep() {
        let (ia, ja, va) = laplacian(7, 0.5);
        let a = Csr {
            row_ptr: &ia,
            cols: &ja,
            vals: &va,
        };
        let b: Vec<f64> = (0..7).map(|i| 1.0 + i as f64).collect();
        // Reference: dense forward then backward Gauss-Seidel from zero.
        let mut r = vec![0.0; 7];
        let dense = |i: usize, j: usize| {
            if i == j {
                2.5
            } else if i.abs_diff(j) == 1 {
                -1.0
            } else {
                0.0
            }
        };
        let order: Vec<usize> = (0..7).chain((0..7).rev()).collect();
        for &i in &order {
            let s: f64 = (0..7).filter(|&j| j != i).map(|j| dense(i, j) * r[j]).sum();
            r[i] = (b[i] - s) / dense(i, i);
        }
        let mut x = vec![9.0; 7];
        let plan = SweepPlan::new(a, 1);
        symmetric_sweeps(a, &plan, &b, &mut x, 1, true, &mut SweepWork::default());
        for (u, v) in x.iter().zip(&r) {
            assert!((u - v).abs() < 1e-14, "{x:?} against {r:?}");
        }
    }

    #[test]
    fn sweeps_converge_to_the_solution_on_several_parts() {
        let n = 200;
        let (ia, ja, va) = laplacian(n, 0.3);
        let a = Csr {
            row_ptr: &ia,
            cols: &ja,
            vals: &va,
        };
        let exact: Vec<f64> = (0..n).map(|i| (i as f64 * 0.1).sin()).collect();
        let b: Vec<f64> = (0..n)
            .map(|i| {
                (ia[i] as usize..ia[i + 1] as usize)
                    .map(|k| va[k] * exact[ja[k] as usize])
                    .sum()
            })
            .collect();
        for parts in [1, 2, 3, 8] {
            let bounds = part_bounds(&ia, parts);
            assert_eq!(bounds.len(), parts + 1);
            assert!(bounds.windows(2).all(|w| w[0] <= w[1]));
            let plan = SweepPlan::new(a, parts);
            assert!(plan.fits(a, parts) && !plan.fits(a, parts + 1));
            let mut x = vec![0.0; n];
            symmetric_sweeps(a, &plan, &b, &mut x, 60, true, &mut SweepWork::default());
            let err = x
                .iter()
                .zip(&exact)
                .map(|(u, v)| (u - v).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-9, "{parts} parts: error {err}");
        }
    }

    #[test]
    fn a_zero_diagonal_is_not_finite() {
        let (ia, ja, mut va) = laplacian(4, 0.0);
        va[ia[2] as usize + 1] = 0.0; // row 2's diagonal
        let a = Csr {
            row_ptr: &ia,
            cols: &ja,
            vals: &va,
        };
        let mut x = vec![0.0; 4];
        let plan = SweepPlan::new(a, 1);
        symmetric_sweeps(
            a,
            &plan,
            &[1.0; 4],
            &mut x,
            1,
            true,
            &mut SweepWork::default(),
        );
        assert!(x.iter().any(|v| !v.is_finite()));
        // Without the entry: every unknown.
        let (ia, mut ja, va) = laplacian(4, 0.0);
        ja[ia[2] as usize + 1] = 3; // row 2's columns 1, 3, 3
        let a = Csr {
            row_ptr: &ia,
            cols: &ja,
            vals: &va,
        };
        let plan = SweepPlan::new(a, 1);
        symmetric_sweeps(
            a,
            &plan,
            &[1.0; 4],
            &mut x,
            1,
            false,
            &mut SweepWork::default(),
        );
        assert!(x.iter().all(|v| v.is_nan()));
    }
}
