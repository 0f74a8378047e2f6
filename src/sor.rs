//! Symmetric block Gauss-Seidel sweeps (SOR with `omega = 1`) on a point-wise (CSR) matrix, on all
//! threads: the multigrid's smoother (`petsc::smoother`), in place of PETSc's `MatSOR`, which runs on one
//! core.
//!
//! Consecutive rows with the same columns (a grid node's unknowns: PETSc's "inodes", at most
//! [`MAX_GROUP`] rows) form a group, whose diagonal block is solved exactly at each visit, as PETSc's
//! `MatSOR_SeqAIJ_Inode` does with `omega = 1`: `x_g = D_g^-1 (b_g - sum_{h != g} A_gh x_h)`. The groups
//! are cut into `parts` contiguous ranges of about equal nonzeros. A sweep updates each part's unknowns in
//! place, forward through its groups and then backward, reading the other parts' unknowns as they stood
//! when the sweep began: Gauss-Seidel inside a part, Jacobi between parts, as PETSc's
//! `SOR_LOCAL_SYMMETRIC_SWEEP` treats the rows of other processes. With one part it is PETSc's symmetric
//! sweep of the whole matrix (`-pc_sor_symmetric`, one local iteration) up to the order of the sums, as
//! long as PETSc groups the same rows. A singular diagonal block or a missing diagonal entry makes the
//! sweep non-finite, which the Krylov solver meets as a breakdown (as it does a zero pivot).

use rayon::prelude::*;

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

    /// The column indices of row `i`.
    fn cols_of(&self, i: usize) -> &[i32] {
        &self.cols[self.row_ptr[i] as usize..self.row_ptr[i + 1] as usize]
    }
}

/// Largest number of consecutive rows with one column pattern that a group takes (PETSc's inode limit).
const MAX_GROUP: usize = 5;

/// A run of consecutive rows with the same columns, whose diagonal block a sweep solves at once; the
/// sweeps also read each column index and each unknown it names once for all its rows. Positions are
/// offsets into each row's entries.
#[derive(Debug, Clone, Copy)]
struct Group {
    /// First row.
    row: u32,
    /// Number of rows (1 to [`MAX_GROUP`]).
    len: u8,
    /// The first entry of a column in the group's part.
    first: u32,
    /// The entry of column `row`: the diagonal block's `len` columns start there.
    diag: u32,
    /// The first entry of a column after the part.
    last: u32,
}

/// How the rows of a pattern split for the sweeps on given parts: the groups of rows ([`Group`]) and
/// in each the entries of columns before the part, of the part before the diagonal block, the block,
/// after it, and after the part. Made once per pattern and parts ([`SweepPlan::new`]); a sweep then sums
/// each range without a branch per entry.
#[derive(Debug)]
pub struct SweepPlan {
    /// Row boundaries of the parts (`parts + 1` values from 0 to the number of rows; at group starts).
    bounds: Vec<usize>,
    /// The groups, in row order; `parts[p]` indexes those of part `p`.
    groups: Vec<Group>,
    parts: Vec<std::ops::Range<usize>>,
    /// A row without its diagonal entry: every sweep is then not finite.
    missing_diagonal: bool,
    /// Number of rows and nonzeros of the pattern it was made for.
    size: (usize, usize),
}

impl SweepPlan {
    /// The plan of the pattern of `a` on `parts` parts of about equal nonzeros, cut between groups.
    pub fn new(a: Csr<'_>, parts: usize) -> Self {
        let n = a.rows();
        let below = |c: usize| move |&j: &i32| (j as usize) < c;
        // The groups: (first row, rows, the diagonal's entry in the first row).
        let (mut runs, mut missing_diagonal) = (Vec::new(), false);
        let mut i = 0;
        while i < n {
            let row = a.cols_of(i);
            let diag = row.partition_point(below(i));
            let mut len = 1;
            if row.get(diag).map(|&c| c as usize) == Some(i) {
                while len < MAX_GROUP
                    && i + len < n
                    && a.cols_of(i + len) == row
                    && row.get(diag + len).map(|&c| c as usize) == Some(i + len)
                {
                    len += 1;
                }
            } else {
                missing_diagonal = true;
            }
            runs.push((i, len, diag));
            i += len;
        }
        // Part bounds at group starts, about equal nonzeros each.
        let parts = parts.max(1);
        let total = a.cols.len() as f64;
        let mut bounds = vec![0];
        let mut next = 1;
        for &(row, _, _) in &runs {
            while next < parts && a.row_ptr[row] as f64 >= total * next as f64 / parts as f64 {
                bounds.push(row);
                next += 1;
            }
        }
        bounds.resize(parts, n);
        bounds.push(n);
        let (mut groups, mut ranges) = (Vec::with_capacity(runs.len()), Vec::new());
        let mut runs = runs.into_iter().peekable();
        for w in bounds.windows(2) {
            let (lo, hi) = (w[0], w[1]);
            let begin = groups.len();
            while let Some((row, len, diag)) = runs.next_if(|r| r.0 < hi) {
                let cols = a.cols_of(row);
                groups.push(Group {
                    row: row as u32,
                    len: len as u8,
                    first: cols.partition_point(below(lo)) as u32,
                    diag: diag as u32,
                    last: (diag + cols[diag..].partition_point(below(hi))) as u32,
                });
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

    /// Whether the plan was made for a pattern of this size on `parts` parts (the caller remakes the
    /// plan when the matrix is another or its pattern changed).
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
            for (k, v) in vals.iter().enumerate() {
                s[k] += v[2 * j] * x0;
                odd[k] += v[2 * j + 1] * x1;
            }
        }
        if let Some(&c) = rest.first() {
            let xj = x[c as usize - lo];
            for (k, v) in vals.iter().enumerate() {
                s[k] += v[cols.len() - 1] * xj;
            }
        }
        for (s, o) in s.iter_mut().zip(odd) {
            *s += o;
        }
    }

    /// `D^-1 r` for the diagonal block `D` of the group `g` (rows `g.row..`, entries `g.diag..` of
    /// each), by elimination with partial pivoting; a singular block gives non-finite values.
    #[inline(always)]
    fn solve<const G: usize>(&self, g: Group, mut r: [f64; G]) -> [f64; G] {
        let (row, d) = (g.row as usize, g.diag as usize);
        let mut m: [[f64; G]; G] = std::array::from_fn(|k| {
            let start = self.a.row_ptr[row + k] as usize + d;
            std::array::from_fn(|j| self.a.vals[start + j])
        });
        for c in 0..G {
            let p = (c..G)
                .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
                .unwrap_or(c);
            m.swap(c, p);
            r.swap(c, p);
            let (pivot, below) = m.split_at_mut(c + 1);
            let pivot = &pivot[c];
            for (i, row) in below.iter_mut().enumerate() {
                let f = row[c] / pivot[c];
                for (v, &p) in row[c..].iter_mut().zip(&pivot[c..]) {
                    *v -= f * p;
                }
                r[c + 1 + i] -= f * r[c];
            }
        }
        for c in (0..G).rev() {
            let mut t = r[c];
            for j in c + 1..G {
                t -= m[c][j] * r[j];
            }
            r[c] = t / m[c][c];
        }
        r
    }

    /// The group `g` swept from zero, forward (`partial` keeps `b` less the entries left of the
    /// diagonal block: every unknown right of it is still zero) or, after it, backward.
    #[inline(always)]
    fn sweep_from_zero<const G: usize>(
        &self,
        g: Group,
        own: &mut [f64],
        partial: &mut [f64],
        forward: bool,
    ) {
        let (lo, r, d) = (self.lo, g.row as usize, g.diag as usize);
        let at = r - lo;
        let mut s = [0.0; G];
        let t: [f64; G] = if forward {
            self.gather::<G>(r, g.first as usize..d, lo, own, &mut s);
            let t = std::array::from_fn(|k| self.b[r + k] - s[k]);
            partial[at..at + G].copy_from_slice(&t);
            t
        } else {
            self.gather::<G>(r, d + G..g.last as usize, lo, own, &mut s);
            std::array::from_fn(|k| partial[at + k] - s[k])
        };
        own[at..at + G].copy_from_slice(&self.solve::<G>(g, t));
    }

    /// The group `g` swept from the current unknowns.
    #[inline(always)]
    fn sweep_from_guess<const G: usize>(&self, g: Group, own: &mut [f64]) {
        let (lo, r, d) = (self.lo, g.row as usize, g.diag as usize);
        let end = (self.a.row_ptr[r + 1] - self.a.row_ptr[r]) as usize;
        let mut s = [0.0; G];
        self.gather::<G>(r, g.first as usize..d, lo, own, &mut s);
        self.gather::<G>(r, d + G..g.last as usize, lo, own, &mut s);
        if !self.others.is_empty() {
            self.gather::<G>(r, 0..g.first as usize, 0, self.others, &mut s);
            self.gather::<G>(r, g.last as usize..end, 0, self.others, &mut s);
        }
        let t = std::array::from_fn(|k| self.b[r + k] - s[k]);
        own[r - lo..r - lo + G].copy_from_slice(&self.solve::<G>(g, t));
    }
}

/// Calls `$f::<G>` for the group's length `G` (1 to [`MAX_GROUP`]).
macro_rules! by_len {
    ($g:expr, $f:ident, $($arg:expr),*) => {
        match $g.len {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            _ => $f::<5>($($arg),*),
        }
    };
}

/// `sweeps` symmetric block Gauss-Seidel sweeps of `a x = b` on the parts of `plan` (made for `a`'s
/// pattern), from `x` or, if `zero_guess`, from zero. From zero the first sweep reads each row once, as
/// PETSc's does: forward the entries left of each diagonal block (every unknown right of it is still
/// zero), keeping `b` less that sum, backward the entries right of it.
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
        // Each part's groups with its slices of x (and of the partial sums).
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
                for &g in groups.iter().chain(groups.iter().rev()) {
                    by_len!(g, guess, &sweep, g, own);
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
fn guess<const G: usize>(s: &Sweep<'_>, g: Group, own: &mut [f64]) {
    s.sweep_from_guess::<G>(g, own);
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

    /// One symmetric sweep as the plan defines it, written out densely: on each part forward then
    /// backward over its groups (consecutive rows with the same columns and their diagonal block, at
    /// most `MAX_GROUP`), each group's block solved by LU, the other parts' unknowns as the sweep found
    /// them.
    fn reference(a: Csr<'_>, bounds: &[usize], b: &[f64], x: &mut [f64]) {
        let before = x.to_vec();
        for w in bounds.windows(2) {
            let mut groups = Vec::new();
            let mut i = w[0];
            while i < w[1] {
                let mut len = 1;
                while len < MAX_GROUP && i + len < w[1] && a.cols_of(i + len) == a.cols_of(i) {
                    len += 1;
                }
                groups.push(i..i + len);
                i += len;
            }
            let order: Vec<_> = groups.iter().chain(groups.iter().rev()).cloned().collect();
            for g in order {
                let m = g.len();
                let mut block = nalgebra::DMatrix::<f64>::zeros(m, m);
                let mut rhs = nalgebra::DVector::<f64>::zeros(m);
                for (r, row) in g.clone().enumerate() {
                    rhs[r] = b[row];
                    for k in a.row_ptr[row] as usize..a.row_ptr[row + 1] as usize {
                        let c = a.cols[k] as usize;
                        if g.contains(&c) {
                            block[(r, c - g.start)] = a.vals[k];
                        } else {
                            let xc = if (w[0]..w[1]).contains(&c) {
                                x[c]
                            } else {
                                before[c]
                            };
                            rhs[r] -= a.vals[k] * xc;
                        }
                    }
                }
                let y = block.lu().solve(&rhs).expect("a regular block");
                for (r, row) in g.enumerate() {
                    x[row] = y[r];
                }
            }
        }
    }

    #[test]
    fn node_rows_are_swept_as_blocks() {
        for bs in [1, 2, 3, 4, 5, 6] {
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
                // A node's rows go together (up to five), and parts are cut between groups.
                let starts: Vec<usize> = plan.groups.iter().map(|g| g.row as usize).collect();
                assert!(
                    plan.bounds[..parts].iter().all(|r| starts.contains(r)),
                    "bs {bs}"
                );
                if bs <= MAX_GROUP {
                    assert!(
                        plan.bounds.iter().all(|&r| r % bs == 0),
                        "bs {bs}: {:?}",
                        plan.bounds
                    );
                }
                assert_eq!(plan.groups.len(), 11 * bs.div_ceil(MAX_GROUP), "bs {bs}");
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
            let plan = SweepPlan::new(a, parts);
            assert_eq!(plan.bounds.len(), parts + 1);
            assert!(plan.bounds.windows(2).all(|w| w[0] <= w[1]));
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
