//! The PETSc layer end to end on the lattice problem of `mpm_concrete::app::smoke`: several SNES/KSP/PC
//! combinations chosen through the options database reach the same solution with quadratic Newton
//! convergence; the assembled Jacobian matches finite differences; bad options give clear errors.

use mpm_concrete::app::smoke::{self, SmokeParams};
use mpm_concrete::petsc::{self, Session};

/// `options` (`-name value ...`) with every option name under `prefix`.
fn under_prefix(prefix: &str, options: &str) -> String {
    options
        .split_whitespace()
        .map(|t| match t.strip_prefix('-') {
            Some(name) => format!("-{prefix}{name}"),
            None => t.to_owned(),
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Sets `options` under `prefix` and solves; returns the result.
fn solve_with(prefix: &str, options: &str) -> smoke::SmokeResult {
    let s = Session::get().expect("PETSc session");
    petsc::apply_default_options(&s, &under_prefix(prefix, options)).expect("options");
    smoke::solve(&s, params(), Some(prefix)).unwrap_or_else(|e| panic!("{prefix}: {e}"))
}

fn params() -> SmokeParams {
    SmokeParams {
        n: 10,
        load: 0.001,
        ..SmokeParams::default()
    }
}

/// Newton converges quadratically: once the residual is below 1e-2 of the initial one, each iterate
/// squares it up to a modest constant (r_{k+1}/r0 <= 50 (r_k/r0)^2) — a linearly converging method with
/// rate 0.1 fails this at the last iterations.
fn assert_quadratic(name: &str, norms: &[f64]) {
    assert!(
        norms.len() >= 3,
        "{name}: too few iterations to judge: {norms:?}"
    );
    let r0 = norms[0];
    let e: Vec<f64> = norms.iter().map(|r| r / r0).collect();
    for w in e.windows(2) {
        if w[0] < 1e-2 && w[1] > 1e-13 {
            assert!(w[1] <= 50.0 * w[0] * w[0], "{name}: not quadratic: {e:?}");
        }
    }
    assert!(
        e.last().copied().unwrap_or(1.0) < 1e-10,
        "{name}: did not converge: {e:?}"
    );
}

const COMMON: &str = "-snes_rtol 1e-14 -snes_atol 1e-13 -snes_stol 0 -snes_max_it 30";

#[test]
fn solvers_agree_and_converge_quadratically() {
    let cases = [
        ("lu_", "-ksp_type preonly -pc_type lu"),
        (
            "mumps_",
            "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps",
        ),
        (
            "hypre_",
            "-ksp_type gmres -ksp_rtol 1e-12 -ksp_max_it 500 -pc_type hypre -pc_hypre_type boomeramg",
        ),
        (
            "ilu_",
            "-ksp_type gmres -ksp_rtol 1e-12 -ksp_max_it 500 -pc_type bjacobi -sub_pc_type ilu",
        ),
    ];
    let mut reference: Option<Vec<f64>> = None;
    for (prefix, opts) in cases {
        let r = solve_with(prefix, &format!("{COMMON} {opts}"));
        assert!(
            r.info.converged(),
            "{prefix}: {} after {} its: {:?}",
            r.info.reason_name,
            r.info.iterations,
            r.info.residual_norms
        );
        assert_quadratic(prefix, &r.info.residual_norms);
        let max = r.solution.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(max > 1e-2, "{prefix}: trivial solution");
        match &reference {
            None => reference = Some(r.solution),
            Some(x) => {
                let diff = x
                    .iter()
                    .zip(&r.solution)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(diff < 1e-9 * max, "{prefix}: differs from LU by {diff:e}");
            }
        }
        assert!(
            r.solver
                .contains(opts.split_whitespace().nth(1).unwrap_or("")),
            "{}",
            r.solver
        );
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let s = Session::get().expect("PETSc session");
    let p = SmokeParams { n: 4, ..params() };
    let n = 3 * p.n * p.n;
    // A non-trivial state: deformed lattice, non-zero phi.
    let x0: Vec<f64> = (0..n)
        .map(|i| 0.05 * ((i as f64) * 0.7).sin() + 0.01 * (i % 3) as f64)
        .collect();
    let err = smoke::jacobian_fd_error(&s, p, &x0).expect("fd check");
    assert!(err < 1e-7, "relative Jacobian error {err:e}");
}

#[test]
fn unknown_preconditioner_is_a_clear_error() {
    let s = Session::get().expect("PETSc session");
    petsc::set_option(&s, "bad_pc_type", Some("nonsense")).expect("option");
    let err = smoke::solve(&s, params(), Some("bad_"))
        .err()
        .expect("must fail");
    let msg = err.to_string();
    assert!(
        msg.contains("nonsense"),
        "message does not name the bad value: {msg}"
    );
}

#[test]
fn options_set_in_code_yield_to_the_command_line() {
    let s = Session::get().expect("PETSc session");
    petsc::set_option(&s, "cli_ksp_type", Some("cg")).expect("option");
    petsc::set_default_option(&s, "cli_ksp_type", Some("gmres")).expect("default");
    assert_eq!(
        petsc::option_string(&s, "cli_ksp_type")
            .expect("get")
            .as_deref(),
        Some("cg")
    );
}

/// A block pattern filled through each path (`seqaij` and `seqbaij` in place, `mpiaij` through
/// `MatUpdateMPIAIJWithArray`, `mpibaij` through its diagonal and off-diagonal parts, here on one
/// process with an empty off-diagonal part; on several processes through the solver in
/// `tests/mpi_parallel.rs`) gives the same operator as the dense matrix it describes.
#[test]
fn block_pattern_fills_every_matrix_type_alike() {
    use mpm_concrete::petsc::{BlockCsr, Matrix, Vector};
    let s = Session::get().expect("PETSc session");
    // 4 block rows of size 3 with irregular, sorted block columns.
    let row_ptr = [0, 2, 5, 6, 9];
    let cols = [0u32, 2, 0, 1, 3, 2, 0, 1, 3];
    let p = BlockCsr {
        first: 0,
        bs: 3,
        row_ptr: &row_ptr,
        cols: &cols,
    };
    let n = 12;
    let value = |r: usize, c: usize| 1.0 + r as f64 + 0.01 * c as f64 + (r * c % 7) as f64;
    let mut dense = vec![0.0; n * n];
    for a in 0..4 {
        for &b in p.block_cols(a) {
            for i in 0..3 {
                for k in 0..3 {
                    let (r, c) = (3 * a + i, 3 * b as usize + k);
                    dense[r * n + c] = value(r, c);
                }
            }
        }
    }
    let x: Vec<f64> = (0..n).map(|i| 0.5 + (i as f64).sin()).collect();
    let expected: Vec<f64> = (0..n)
        .map(|r| (0..n).map(|c| dense[r * n + c] * x[c]).sum())
        .collect();
    for mat_type in ["aij", "baij", "mpiaij", "mpibaij"] {
        let mut m = Matrix::with_type(&s, n, 3, mat_type).expect("matrix");
        m.set_block_pattern(&p).expect("pattern");
        m.fill_block_rows(&p, |v, layout| {
            for (a, &start) in row_ptr[..4].iter().enumerate() {
                let bc = p.block_cols(a);
                let base = start * 9;
                for (pos, &b) in bc.iter().enumerate() {
                    for i in 0..3 {
                        for k in 0..3 {
                            let (r, c) = (3 * a + i, 3 * b as usize + k);
                            v[base + layout.offset(bc.len(), 3, i, pos, k)] = value(r, c);
                        }
                    }
                }
            }
        })
        .expect("fill");
        let mut xv = Vector::new(&s, n, 3).expect("x");
        xv.write(|v| v.copy_from_slice(&x)).expect("write");
        let mut y = Vector::new(&s, n, 3).expect("y");
        m.mult(&xv, &mut y).expect("mult");
        let got = y.read(|v| v.to_vec()).expect("read");
        for (g, e) in got.iter().zip(&expected) {
            assert!(
                (g - e).abs() <= 1e-12 * e.abs(),
                "{mat_type}: {got:?} vs {expected:?}"
            );
        }
        // A second fill replaces every value.
        m.fill_block_rows(&p, |v, _| v.fill(0.0)).expect("refill");
        m.mult(&xv, &mut y).expect("mult");
        assert!(
            y.norm2().expect("norm") == 0.0,
            "{mat_type}: values left over"
        );
    }
}

/// New values written in place reach the preconditioner: a factorisation set up for the first values is
/// rebuilt for the second (PETSc rebuilds it only if the matrix's state changed; `MatSeqBAIJRestoreArray`
/// alone does not change it, so a BAIJ Jacobian kept a stale ILU for the whole step and across steps).
#[test]
fn refilled_values_reach_the_preconditioner_for_every_matrix_type() {
    use mpm_concrete::petsc::{BlockCsr, Matrix, Snes, Vector};
    let s = Session::get().expect("PETSc session");
    // 3 block rows of size 3, each coupled to itself only: LU is exact on this pattern.
    let (row_ptr, cols) = ([0, 1, 2, 3], [0u32, 1, 2]);
    let p = BlockCsr {
        first: 0,
        bs: 3,
        row_ptr: &row_ptr,
        cols: &cols,
    };
    let n = 9;
    let block = |scale: f64, v: &mut [f64], layout: mpm_concrete::petsc::BlockLayout| {
        for a in 0..3 {
            for i in 0..3 {
                for k in 0..3 {
                    let diag = if i == k { 4.0 + a as f64 } else { 0.5 };
                    v[a * 9 + layout.offset(1, 3, i, 0, k)] = scale * diag;
                }
            }
        }
    };
    petsc::set_option(&s, "refill_ksp_type", Some("preonly")).expect("option");
    petsc::set_option(&s, "refill_pc_type", Some("lu")).expect("option");
    for mat_type in ["aij", "baij"] {
        let mut m = Matrix::with_type(&s, n, 3, mat_type).expect("matrix");
        m.set_block_pattern(&p).expect("pattern");
        let mut snes = Snes::new(&s, Some("refill_")).expect("snes");
        snes.set_from_options().expect("options");
        let mut rhs = Vector::new(&s, n, 3).expect("rhs");
        rhs.write(|v| {
            v.iter_mut()
                .enumerate()
                .for_each(|(i, r)| *r = 1.0 + i as f64)
        })
        .expect("write");
        let mut solve = |m: &Matrix| {
            let mut x = Vector::new(&s, n, 3).expect("x");
            let r = snes.linear_solve(m, &rhs, &mut x).expect("solve");
            assert!(r.converged(), "{mat_type}: {}", r.reason_name);
            x.read(|v| v.to_vec()).expect("read")
        };
        m.fill_block_rows(&p, |v, l| block(1.0, v, l))
            .expect("fill");
        let x1 = solve(&m);
        m.fill_block_rows(&p, |v, l| block(2.0, v, l))
            .expect("refill");
        let x2 = solve(&m);
        for (a, b) in x1.iter().zip(&x2) {
            assert!(
                (a - 2.0 * b).abs() <= 1e-12 * a.abs(),
                "{mat_type}: the solve after the refill used the old factorisation: {x1:?} vs {x2:?}"
            );
        }
    }
}

#[test]
fn the_threaded_operator_multiplies_as_the_jacobian() {
    use mpm_concrete::petsc::{BlockCsr, Matrix, ThreadedOperator, Vector};
    let s = Session::get().expect("PETSc session");
    // 4 block rows of size 3 with rows of 2-4 blocks.
    let (row_ptr, cols) = ([0, 2, 5, 7, 11], [0u32, 3, 0, 1, 2, 1, 2, 0, 1, 2, 3]);
    let p = BlockCsr {
        first: 0,
        bs: 3,
        row_ptr: &row_ptr,
        cols: &cols,
    };
    let n = 12;
    let value =
        |r: usize, c: usize, scale: f64| scale * (1.0 + 0.37 * r as f64 - 0.11 * (r * c) as f64);
    let fill = |scale: f64, v: &mut [f64], layout: mpm_concrete::petsc::BlockLayout| {
        for a in 0..4 {
            let ncols = row_ptr[a + 1] - row_ptr[a];
            for (pos, &b) in cols[row_ptr[a]..row_ptr[a + 1]].iter().enumerate() {
                for i in 0..3 {
                    for k in 0..3 {
                        let at = row_ptr[a] * 9 + layout.offset(ncols, 3, i, pos, k);
                        v[at] = value(a * 3 + i, b as usize * 3 + k, scale);
                    }
                }
            }
        }
    };
    // One and two threads whatever the machine; `mpiaij` and `mpibaij` on one process: the diagonal
    // part with an empty off-diagonal part and its scatter.
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            for mat_type in ["aij", "baij", "mpiaij", "mpibaij"] {
                let mut m = Matrix::with_type(&s, n, 3, mat_type).expect("matrix");
                m.set_block_pattern(&p).expect("pattern");
                let op = ThreadedOperator::over(&m, &p)
                    .expect("operator")
                    .expect("a CSR type of block size 3");
                let mut x = Vector::new(&s, n, 3).expect("x");
                x.write(|v| {
                    v.iter_mut()
                        .enumerate()
                        .for_each(|(i, r)| *r = 1.0 - 0.2 * i as f64)
                })
                .expect("write");
                for scale in [1.0, -2.5] {
                    // A refill reaches the operator: it reads the Jacobian's current values.
                    m.fill_block_rows(&p, |v, l| fill(scale, v, l))
                        .expect("fill");
                    let (mut y_mat, mut y_op) = (
                        Vector::new(&s, n, 3).expect("y"),
                        Vector::new(&s, n, 3).expect("y"),
                    );
                    m.mult(&x, &mut y_mat).expect("MatMult");
                    op.mult(&x, &mut y_op).expect("shell MatMult");
                    let (a, b) = (
                        y_mat.read(|v| v.to_vec()).expect("read"),
                        y_op.read(|v| v.to_vec()).expect("read"),
                    );
                    for (u, w) in a.iter().zip(&b) {
                        assert!(
                            (u - w).abs() <= 1e-13 * u.abs().max(1.0),
                            "{mat_type}, scale {scale}: {a:?} against {b:?}"
                        );
                    }
                    if mat_type.ends_with("baij") {
                        assert_eq!(
                            a, b,
                            "{mat_type}: the block product sums as PETSc's kernel does"
                        );
                    }
                }
            }
        });
    }
}

/// A 14 x 14 grid of nodes with 3 unknowns each, coupled to the 8 neighbours: the block pattern of a
/// bilinear grid, with fill that ILU(0) drops (row pointers, block columns).
fn grid_pattern() -> (Vec<usize>, Vec<u32>) {
    let side = 14usize;
    let (mut row_ptr, mut cols) = (vec![0usize], Vec::new());
    for a in 0..side * side {
        let (x, y) = (a % side, a / side);
        for yy in y.saturating_sub(1)..(y + 2).min(side) {
            for xx in x.saturating_sub(1)..(x + 2).min(side) {
                cols.push((yy * side + xx) as u32);
            }
        }
        row_ptr.push(cols.len());
    }
    (row_ptr, cols)
}

/// The grid pattern as PETSc's block pattern (one process, blocks of 3).
fn grid_csr<'a>((row_ptr, cols): (&'a [usize], &'a [u32])) -> mpm_concrete::petsc::BlockCsr<'a> {
    mpm_concrete::petsc::BlockCsr {
        first: 0,
        bs: 3,
        row_ptr,
        cols,
    }
}

/// Which values [`fill_grid`] writes.
#[derive(Clone, Copy, PartialEq)]
enum Values {
    /// Diagonally dominant blocks.
    Base,
    /// The same with the diagonal blocks tripled: a factorisation of `Base` preconditions it worse.
    HeavierDiagonal,
    /// `Base` with the diagonal block of the middle node NaN.
    Poisoned,
}

/// Values of the grid pattern in `layout`.
fn fill_grid(
    (row_ptr, cols): (&[usize], &[u32]),
    which: Values,
    v: &mut [f64],
    layout: mpm_concrete::petsc::BlockLayout,
) {
    let nodes = row_ptr.len() - 1;
    for a in 0..nodes {
        let ncols = row_ptr[a + 1] - row_ptr[a];
        for (pos, &b) in cols[row_ptr[a]..row_ptr[a + 1]].iter().enumerate() {
            for i in 0..3 {
                for k in 0..3 {
                    let b = b as usize;
                    let val = if a == b {
                        let d = if i == k { 9.0 + 0.1 * i as f64 } else { 0.4 };
                        match which {
                            Values::HeavierDiagonal => 3.0 * d,
                            Values::Poisoned if a == nodes / 2 => f64::NAN,
                            _ => d,
                        }
                    } else {
                        -0.3 + 0.02 * ((a + 2 * b + i + k) % 7) as f64
                    };
                    v[row_ptr[a] * 9 + layout.offset(ncols, 3, i, pos, k)] = val;
                }
            }
        }
    }
}

/// Sets `options` (`-name value ...`) under `prefix`.
fn set_under(s: &mpm_concrete::petsc::SessionGuard, prefix: &str, options: &str) {
    for t in options.split_whitespace().collect::<Vec<_>>().chunks(2) {
        let name = format!("{prefix}{}", &t[0][1..]);
        petsc::set_option(s, &name, Some(t[1])).expect("option");
    }
}

/// What [`solve_grid`] found: iterations and solution with `Base` and with `HeavierDiagonal` values, and
/// the reason the poisoned solve stopped.
struct GridSolves {
    base: (usize, Vec<f64>),
    heavier: (usize, Vec<f64>),
    poisoned: String,
}

/// Solves the grid system with `snes` four times, refilling `m` in between: `Base` values,
/// `HeavierDiagonal` (a preconditioner not refactored would take other iterations than PETSc's),
/// `Poisoned` (the solve must fail) and `Base` again (it must converge as the first time: a failed
/// factorisation does not fail the solves after it).
fn solve_grid(
    s: &mpm_concrete::petsc::SessionGuard,
    snes: &mut mpm_concrete::petsc::Snes,
    m: &mut mpm_concrete::petsc::Matrix,
    (row_ptr, cols): (&[usize], &[u32]),
    what: &str,
) -> GridSolves {
    use mpm_concrete::petsc::Vector;
    let p = grid_csr((row_ptr, cols));
    let n = (row_ptr.len() - 1) * 3;
    let mut rhs = Vector::new(s, n, 3).expect("rhs");
    rhs.write(|v| {
        v.iter_mut()
            .enumerate()
            .for_each(|(i, r)| *r = 1.0 + (0.3 * i as f64).sin())
    })
    .expect("write");
    let mut solve = |which: Values| {
        m.fill_block_rows(&p, |v, l| fill_grid((row_ptr, cols), which, v, l))
            .expect("fill");
        let mut x = Vector::new(s, n, 3).expect("x");
        let r = snes.linear_solve(m, &rhs, &mut x).expect("solve");
        let x = x.read(|v| v.to_vec()).expect("read");
        (r, x)
    };
    let (r1, x1) = solve(Values::Base);
    assert!(r1.converged(), "{what}: {}", r1.reason_name);
    let (r2, x2) = solve(Values::HeavierDiagonal);
    assert!(r2.converged(), "{what}: {}", r2.reason_name);
    let (r3, _) = solve(Values::Poisoned);
    assert!(
        !r3.converged(),
        "{what}: a NaN diagonal block must fail the solve, got {}",
        r3.reason_name
    );
    let (r4, x4) = solve(Values::Base);
    assert!(
        r4.converged() && r4.iterations == r1.iterations,
        "{what}: after a failed factorisation: {} in {} iterations (first solve: {})",
        r4.reason_name,
        r4.iterations,
        r1.iterations
    );
    for (a, b) in x1.iter().zip(&x4) {
        assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{what}");
    }
    GridSolves {
        base: (r1.iterations, x1),
        heavier: (r2.iterations, x2),
        poisoned: r3.reason_name,
    }
}

/// PETSc's solves against the threaded ILU's: the same solutions and about the same iterations with
/// both sets of values (stale factors of the first values would take other iterations on the second).
fn same_solves(petsc: &GridSolves, ours: &GridSolves, slack: usize, what: &str) {
    same_solve(&petsc.base, &ours.base, slack, what);
    same_solve(&petsc.heavier, &ours.heavier, slack, what);
}

/// The same solution to 1e-8 and iterations within `slack`.
fn same_solve(petsc: &(usize, Vec<f64>), ours: &(usize, Vec<f64>), slack: usize, what: &str) {
    for (a, b) in petsc.1.iter().zip(&ours.1) {
        assert!(
            (a - b).abs() <= 1e-8 * a.abs().max(1.0),
            "{what}: solutions differ: {a} vs {b}"
        );
    }
    assert!(
        ours.0.abs_diff(petsc.0) <= slack,
        "{what}: GMRES iterations: threaded ILU {}, PETSc's {}",
        ours.0,
        petsc.0
    );
}

/// The threaded ILU(0) (`petsc::use_threaded_ilu`: one overlapping subdomain per thread) preconditions
/// GMRES as PETSc's block Jacobi + ILU(0) of the whole matrix does: the same solution, about the same
/// iterations, a refill reaching the factorisation; a singular diagonal block fails the solve (so that
/// a step goes to the fallback solver) instead of returning garbage.
#[test]
fn the_threaded_ilu_preconditions_as_petscs_ilu() {
    use mpm_concrete::petsc::{Matrix, Snes};
    let s = Session::get().expect("PETSc session");
    let (row_ptr, cols) = grid_pattern();
    let p = grid_csr((&row_ptr, &cols));
    let n = (row_ptr.len() - 1) * 3;
    let options = "-ksp_type gmres -ksp_rtol 1e-10 -ksp_max_it 200 -pc_type bjacobi \
         -sub_pc_type ilu -sub_pc_factor_shift_type nonzero";
    for prefix in ["petsc_ilu_", "threaded_ilu_"] {
        set_under(&s, prefix, options);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("thread pool");
    pool.install(|| {
        for mat_type in ["baij", "aij"] {
            let mut results = Vec::new();
            for (prefix, threaded) in [("petsc_ilu_", false), ("threaded_ilu_", true)] {
                let mut m = Matrix::with_type(&s, n, 3, mat_type).expect("matrix");
                m.set_block_pattern(&p).expect("pattern");
                let mut snes = Snes::new(&s, Some(prefix)).expect("snes");
                snes.set_from_options().expect("options");
                if threaded {
                    assert!(
                        petsc::use_threaded_ilu(&snes, &m, &p).expect("shell"),
                        "one process, two threads, blocks of 3: the threaded ILU applies"
                    );
                    assert!(snes.describe().expect("describe").ends_with("shell"));
                }
                let what = format!("{mat_type} {prefix}");
                results.push(solve_grid(&s, &mut snes, &mut m, (&row_ptr, &cols), &what));
            }
            same_solves(&results[0], &results[1], 2, mat_type);
            // The whole-matrix shell reports its failed factorisation as the preconditioner's failure
            // (PETSc's block ILU(0) meets the NaN as `DIVERGED_NANORINF`): it did the factorisations.
            assert_eq!(results[1].poisoned, "DIVERGED_PC_FAILED", "{mat_type}");
        }
    });
}

/// Where the whole-matrix shell declines (one thread here; the matrices of several processes in a run),
/// the threaded ILU(0) takes the place of PETSc's inside the subdomain of block Jacobi and of additive
/// Schwarz (`Snes::use_threaded_ilu_on_subdomains`): with one part it is the subdomain's plain ILU(0), so
/// GMRES takes PETSc's iterations to the same solution, also after a refill with other values; a NaN
/// pivot fails the solve as the preconditioner's failure, and the next good values converge again.
/// Point-wise storage keeps PETSc's ILU.
#[test]
fn the_subdomains_ilu_becomes_the_threaded_one() {
    use mpm_concrete::petsc::{Matrix, Snes};
    let s = Session::get().expect("PETSc session");
    let (row_ptr, cols) = grid_pattern();
    let p = grid_csr((&row_ptr, &cols));
    let n = (row_ptr.len() - 1) * 3;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    pool.install(|| {
        for pc in ["bjacobi", "asm"] {
            let options = format!(
                "-ksp_type gmres -ksp_rtol 1e-10 -ksp_max_it 200 -pc_type {pc} \
                 -sub_pc_type ilu -sub_pc_factor_shift_type nonzero"
            );
            for mat_type in ["baij", "aij"] {
                let mut results = Vec::new();
                for threaded in [false, true] {
                    let prefix = format!("sub_{pc}_{mat_type}_{threaded}_");
                    set_under(&s, &prefix, &options);
                    let mut m = Matrix::with_type(&s, n, 3, mat_type).expect("matrix");
                    m.set_block_pattern(&p).expect("pattern");
                    let mut snes = Snes::new(&s, Some(&prefix)).expect("snes");
                    snes.set_from_options().expect("options");
                    assert!(
                        !petsc::use_threaded_ilu(&snes, &m, &p).expect("shell"),
                        "one thread: the whole-matrix shell declines"
                    );
                    if threaded {
                        snes.use_threaded_ilu_on_subdomains(3);
                    }
                    let what = format!("{pc} {mat_type} threaded {threaded}");
                    results.push(solve_grid(&s, &mut snes, &mut m, (&row_ptr, &cols), &what));
                    let expected = usize::from(threaded && mat_type == "baij");
                    assert_eq!(snes.threaded_preconditioners(), expected, "{what}");
                }
                let what = format!("{pc} {mat_type}");
                if mat_type == "baij" {
                    same_solves(&results[0], &results[1], 0, &what);
                } else {
                    // Point-wise storage keeps PETSc's ILU: the same solves.
                    same_solve(&results[0].base, &results[1].base, 0, &what);
                    assert_eq!(results[0].poisoned, results[1].poisoned, "{what}");
                }
            }
        }
    });
}

/// `R(x) = x - 1` on 9 unknowns with the Jacobian `scale I` (block rows of 3, each coupled to itself).
struct Scaled {
    scale: f64,
}

static ROW_PTR: [usize; 4] = [0, 1, 2, 3];
static COLS: [u32; 3] = [0, 1, 2];

fn diagonal_blocks() -> mpm_concrete::petsc::BlockCsr<'static> {
    mpm_concrete::petsc::BlockCsr {
        first: 0,
        bs: 3,
        row_ptr: &ROW_PTR,
        cols: &COLS,
    }
}

/// `f_i = r(x_i)`: the residual of a problem whose unknowns are uncoupled.
fn pointwise(
    x: &mpm_concrete::petsc::Vector,
    f: &mut mpm_concrete::petsc::Vector,
    r: impl Fn(f64) -> f64,
) -> Result<(), mpm_concrete::petsc::CallbackError> {
    let fatal = |e: petsc::PetscError| mpm_concrete::petsc::CallbackError::Fatal(e.to_string());
    let v = x.read(|v| v.to_vec()).map_err(fatal)?;
    f.write(|out| out.iter_mut().zip(&v).for_each(|(o, &x)| *o = r(x)))
        .map_err(fatal)
}

impl mpm_concrete::petsc::NonlinearProblem for Scaled {
    fn residual(
        &mut self,
        x: &mpm_concrete::petsc::Vector,
        f: &mut mpm_concrete::petsc::Vector,
    ) -> Result<(), mpm_concrete::petsc::CallbackError> {
        pointwise(x, f, |x| x - 1.0)
    }

    fn jacobian(
        &mut self,
        _x: &mpm_concrete::petsc::Vector,
        jac: &mut mpm_concrete::petsc::Matrix,
    ) -> Result<(), mpm_concrete::petsc::CallbackError> {
        let scale = self.scale;
        jac.fill_block_rows(&diagonal_blocks(), |v, layout| {
            for a in 0..3 {
                for i in 0..3 {
                    for k in 0..3 {
                        v[a * 9 + layout.offset(1, 3, i, 0, k)] = if i == k { scale } else { 0.0 };
                    }
                }
            }
        })
        .map_err(|e| mpm_concrete::petsc::CallbackError::Fatal(e.to_string()))
    }
}

/// Newton iterations that leave the residual norm unchanged end the solve as a linear-solver failure
/// (`DIVERGED_LINEAR_SOLVE`, so that the step's fallback solver is tried) instead of running to the
/// iteration limit: here a Jacobian 1e12 times too stiff makes every step change nothing. With the
/// preconditioner rebuilt at every iteration one such iteration ends it; lagged by 3, three in a row (one
/// of them then had a preconditioner built at the stalled state). A Newton that converges slowly (a
/// Jacobian 1.25 times too stiff: the residual falls by 5 per iteration) is not stopped; the trust region
/// (left to PETSc's own test) converges with the test in place.
#[test]
fn newton_iterations_that_change_nothing_end_the_solve() {
    use mpm_concrete::petsc::{Matrix, Snes, Vector};
    let s = Session::get().expect("PETSc session");
    let common = "-ksp_type preonly -pc_type lu -snes_max_it 25 -snes_rtol 1e-8";
    let cases = [
        ("stall1_", "-snes_linesearch_type basic", 1e12, Some(1)),
        (
            "stall3_",
            "-snes_linesearch_type basic -snes_lag_preconditioner 3",
            1e12,
            Some(3),
        ),
        ("slow_", "-snes_linesearch_type basic", 1.25, None),
        ("slowtr_", "-snes_type newtontr", 1.25, None),
    ];
    for (prefix, options, scale, stops_after) in cases {
        let options = under_prefix(prefix, &format!("{common} {options}"));
        petsc::apply_default_options(&s, &options).expect("options");
        let mut jac = Matrix::with_type(&s, 9, 3, "baij").expect("matrix");
        jac.set_block_pattern(&diagonal_blocks()).expect("pattern");
        let mut snes = Snes::new(&s, Some(prefix)).expect("snes");
        snes.set_from_options().expect("options");
        let mut x = Vector::new(&s, 9, 3).expect("x");
        x.set_all(0.0).expect("x");
        let info = snes
            .solve(&mut Scaled { scale }, &mut x, &mut jac)
            .expect("solve");
        match stops_after {
            Some(n) => {
                assert_eq!(
                    info.reason_name, "DIVERGED_LINEAR_SOLVE",
                    "{prefix}: {info:?}"
                );
                assert_eq!(info.iterations, n, "{prefix}: {info:?}");
            }
            None => {
                assert!(info.converged(), "{prefix}: {info:?}");
                assert!(info.iterations > 5, "{prefix}: {info:?}");
            }
        }
    }
}

/// `r_i = x_i + x_i^3 - 2` on three 3-blocks (solution x = 1), its exact Jacobian `1 + 3 x_i^2`, and how
/// many Jacobians were asked.
struct Cubic {
    jacobians: usize,
}

impl mpm_concrete::petsc::NonlinearProblem for Cubic {
    fn residual(
        &mut self,
        x: &mpm_concrete::petsc::Vector,
        f: &mut mpm_concrete::petsc::Vector,
    ) -> Result<(), mpm_concrete::petsc::CallbackError> {
        pointwise(x, f, |x| x + x * x * x - 2.0)
    }

    fn jacobian(
        &mut self,
        x: &mpm_concrete::petsc::Vector,
        jac: &mut mpm_concrete::petsc::Matrix,
    ) -> Result<(), mpm_concrete::petsc::CallbackError> {
        let fatal = |e: petsc::PetscError| mpm_concrete::petsc::CallbackError::Fatal(e.to_string());
        self.jacobians += 1;
        let v = x.read(|v| v.to_vec()).map_err(fatal)?;
        jac.fill_block_rows(&diagonal_blocks(), |values, layout| {
            for a in 0..3 {
                for i in 0..3 {
                    for k in 0..3 {
                        let x = v[a * 3 + i];
                        values[a * 9 + layout.offset(1, 3, i, 0, k)] =
                            if i == k { 1.0 + 3.0 * x * x } else { 0.0 };
                    }
                }
            }
        })
        .map_err(fatal)
    }
}

/// `-mpm_keep_jacobian_below R`: Newton iterations whose residual is below R times the solve's first
/// keep the last Jacobian. On a cubic whose Newton iterates from 0 converge quadratically (to a relative
/// 1e-8 in six iterations) the last iterations keep it: fewer Jacobians than iterations (measured: 5 in 7
/// iterations against 6 in 6), at most one iteration more, the same solution to the tolerance; the second
/// solve of the same SNES starts with a new Jacobian again.
#[test]
fn newton_keeps_the_jacobian_near_the_solution() {
    use mpm_concrete::petsc::{Matrix, Snes, Vector};
    let s = Session::get().expect("PETSc session");
    let common = "-ksp_type preonly -pc_type lu -snes_max_it 25 -snes_rtol 1e-8 -snes_atol 0 \
                  -snes_stol 0 -snes_linesearch_type basic";
    let solve = |prefix: &str, keep: &str| {
        let options = under_prefix(prefix, &format!("{common} {keep}"));
        petsc::apply_default_options(&s, &options).expect("options");
        let mut jac = Matrix::with_type(&s, 9, 3, "baij").expect("matrix");
        jac.set_block_pattern(&diagonal_blocks()).expect("pattern");
        let mut snes = Snes::new(&s, Some(prefix)).expect("snes");
        snes.set_from_options().expect("options");
        let below = petsc::option_string(&s, &format!("{prefix}mpm_keep_jacobian_below"))
            .expect("option")
            .map(|v| v.parse::<f64>().expect("number"));
        snes.set_keep_jacobian_below(below);
        let mut problem = Cubic { jacobians: 0 };
        let mut runs = Vec::new();
        for _ in 0..2 {
            let mut x = Vector::new(&s, 9, 3).expect("x");
            x.set_all(0.0).expect("x");
            let before = problem.jacobians;
            let info = snes.solve(&mut problem, &mut x, &mut jac).expect("solve");
            assert!(info.converged(), "{prefix}: {info:?}");
            let xs = x.read(|v| v.to_vec()).expect("x");
            runs.push((info.iterations, problem.jacobians - before, xs));
        }
        runs
    };
    let every = solve("keep0_", "");
    let kept = solve("keep4_", "-mpm_keep_jacobian_below 1e-4");
    for ((its, jacs, x), (its0, jacs0, x0)) in kept.iter().zip(&every) {
        assert_eq!(jacs0, its0, "without the option a Jacobian per iteration");
        assert!(jacs < its, "kept: {jacs} Jacobians in {its} iterations");
        assert!(
            *jacs >= 3,
            "the far iterations take fresh Jacobians: {jacs}"
        );
        assert!(*its <= its0 + 1, "{its} iterations against {its0}");
        for (a, b) in x.iter().zip(x0) {
            assert!((a - 1.0).abs() < 1e-7 && (b - 1.0).abs() < 1e-7, "{a} {b}");
        }
    }
}
